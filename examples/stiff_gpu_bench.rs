//! The benchmark behind the "stiff step on the GPU" section of `docs/benchmarks/stiff-gpu.md`:
//! a real guidewire (the `nitinol` preset, 256 elements over 0.5 m) stepped by the stiff scheme
//! at 0.1 ms, run as a user runs it through the facade (wall clock, everything included). Two
//! scenes (`--scene`): `free`, its clamped hand end moving sideways and twisting under gravity in
//! free space; `insertion`, `scenes/nitinol-guidewire-insertion.toml` (pushed through the
//! introducer into the 26 000-triangle vessel) at `--elements` and `--dt`; `guide`, the same
//! without the vessel, and `bare`, without the vessel and the introducer (what the contacts and
//! the guide each cost); `navigation`, the scene of `cosserat.gym`'s navigation environment
//! (`--elements 96 --dt 1e-3` are its defaults), pushed at its largest speed, and
//! `navigation-guide`, `navigation-bare` as `guide` and `bare` are to `insertion`, and
//! `navigation-far`, the wire of `navigation-guide` a metre from the vessel (the contacts'
//! code runs, no point comes near a wall).
//!
//! - one copy as a 1 kHz haptic loop would call it: ten 0.1 ms steps and the tip read back per
//!   tick, on the GPU and on the CPU (one core) of the same machine, with the tips compared;
//! - batches of copies (`[batch] copies`): steps per second of every copy, and the largest
//!   distance between any copy's tip and the first copy's (they start alike, so it is zero when
//!   every copy is stepped alike).
//!
//! `cargo run --release --example stiff_gpu_bench -- [--scene SCENE] [--ticks N]
//! [--copies 1,64,1024,4096] [--steps N] [--elements N] [--dt S] [--warm S] [--batches-only]`;
//! `--batches-only` leaves out the single copy's ticks; `--warm` runs
//! that much simulated time before anything is timed (the insertion's wire reaches the vessel's
//! walls after a few centimetres). Prints one JSON object per
//! line; with contacts, each row also gives the deepest penetration and the most points behind
//! the wall of any copy.

use cosserat::scene::parse_scene;
use cosserat::sim::{Backend, RodHandle, Simulation};
use std::path::Path;
use std::time::Instant;

/// The `[solver]` table of the stiff scheme in `f64` at `dt`, under `gravity`.
fn stiff_solver(dt: f64, gravity: f64) -> String {
    format!(
        r#"
[solver]
scheme = "stiff"
dt = {dt:e}
precision = "f64"
mode = "inextensible"
gravity = [0.0, 0.0, {gravity:?}]
"#
    )
}

fn scene(elements: usize, dt: f64) -> String {
    let solver = stiff_solver(dt, -9.81);
    format!(
        r#"{solver}
[[rod]]
elements = {elements}
shape = {{ kind = "straight", start = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.5 }}
material = {{ preset = "nitinol" }}
damping = {{ drag = 5.0 }}
start = {{ kind = "clamped", velocity = [0.0, 0.2, 0.0], angular_velocity = [6.0, 0.0, 0.0], end_time = 10.0 }}
"#
    )
}

/// `scenes/nitinol-guidewire-insertion.toml` at `elements` and `dt`.
fn insertion(elements: usize, dt: f64) -> String {
    include_str!("../scenes/nitinol-guidewire-insertion.toml")
        .replace("elements = 512", &format!("elements = {elements}"))
        .replace("dt = 1e-4", &format!("dt = {dt:e}"))
}

/// The scene of `cosserat.gym`'s `GuidewireNavigation-v0` at its defaults (a soft wire of 96
/// elements over 0.6 m through the introducer into the 8 000-triangle vessel of seed 0, the
/// stiff scheme at `dt`), the hand pushing at the environment's largest push speed (0.1 m/s).
fn navigation(elements: usize, dt: f64) -> String {
    let solver = stiff_solver(dt, 0.0);
    format!(
        r#"{solver}
[environment]
mesh = {{ kind = "vessel", triangles = 8000, seed = 0 }}
friction = {{ static = 0.08, kinetic = 0.05 }}
margin = 1e-4
stop_outside = false

[[rod]]
elements = {elements}
shape = {{ kind = "insertion", length = 0.6, inserted = 0.01 }}
material = {{ young_modulus = 5e6, poisson_ratio = 0.5, density = 1100.0, radius = 4e-4 }}
damping = {{ drag = 5.0 }}
start = {{ kind = "clamped", guide = 0.59, axial_speed = 0.1, end_time = 100.0 }}
"#
    )
}

/// `text` with its insertion's shape (which lies along the vessel's entry) replaced by a straight
/// wire of the same length from `start` along x.
fn straightened(text: &str, start: [f64; 3]) -> String {
    text.lines()
        .map(|line| match line.strip_prefix(r#"shape = { kind = "insertion", length = "#) {
            Some(rest) => {
                let length = rest.split(',').next().expect("a length");
                format!(
                    r#"shape = {{ kind = "straight", start = {start:?}, direction = [1.0, 0.0, 0.0], length = {length} }}"#
                )
            }
            None => line.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The insertion `text` without its vessel, and without its introducer unless `guide`: what
/// the step costs without mesh contacts (`guide`) and without any pinned point (`bare`).
fn without_vessel(text: &str, guide: bool) -> String {
    let start = text.find("[environment]").expect("an environment");
    let end = text.find("[[rod]]").expect("a rod");
    let text = straightened(&format!("{}{}", &text[..start], &text[end..]), [0.0; 3]);
    if guide {
        text
    } else {
        let at = text.find(", guide = ").expect("a guide");
        let number = at + ", guide = ".len();
        let end = number
            + text[number..]
                .find(|c: char| !(c.is_ascii_digit() || c == '.'))
                .expect("the guide's length");
        format!("{}{}", &text[..at], &text[end..])
    }
}

/// The insertion `text` with its wire straight and a metre from its vessel: the contacts' code
/// compiled and run, no wall within reach.
fn out_of_reach(text: &str) -> String {
    straightened(text, [0.0, 1.0, 0.0])
}

/// The deepest penetration and the most points behind the wall of any rod (zero without
/// contacts).
fn walls(sim: &Simulation) -> (f64, usize) {
    (0..sim.stepper().rod_count())
        .filter_map(|r| sim.stepper().collision_stats(r))
        .fold((0.0, 0), |(d, e), s| {
            (d.max(s.max_penetration), e.max(s.escaped_points))
        })
}

/// Tree walks per step of the first rod's contact queries (zero without contacts).
fn walks_per_step(sim: &Simulation) -> f64 {
    sim.stepper()
        .collision_stats(0)
        .map_or(0.0, |s| s.queries as f64 / s.steps.max(1) as f64)
}

fn build(text: &str, backend: Backend, copies: usize) -> Simulation {
    let overrides = [("batch.copies".to_string(), copies.to_string())];
    let (b, _, _) = parse_scene(Path::new("stiff-gpu-bench.toml"), text, &overrides)
        .unwrap_or_else(|e| panic!("{e}"));
    b.backend(backend)
        .build()
        .unwrap_or_else(|e| panic!("{backend:?}: {e}"))
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// `ticks` ticks of `per_tick` steps, each with the tip read back: (median, p99, largest) in µs,
/// and the tip at the end.
fn ticks(sim: &mut Simulation, ticks: usize, per_tick: u64) -> ([f64; 3], [f64; 3]) {
    // One tick first (the pipeline's compilation, the first dispatch).
    sim.run(per_tick).unwrap_or_else(|e| panic!("{e}"));
    let mut times = Vec::with_capacity(ticks);
    let mut tip = [0.0; 3];
    for _ in 0..ticks {
        let t = Instant::now();
        sim.run(per_tick).unwrap_or_else(|e| panic!("{e}"));
        tip = *sim.positions(RodHandle(0)).last().expect("points");
        times.push(t.elapsed().as_secs_f64() * 1e6);
    }
    times.sort_by(f64::total_cmp);
    (
        [
            quantile(&times, 0.5),
            quantile(&times, 0.99),
            *times.last().expect("ticks"),
        ],
        tip,
    )
}

/// Iterations per step and unconverged steps of the stiff scheme.
fn summary(s: &Simulation) -> (f64, u64) {
    let st = s.stiff_summary().expect("stiff");
    (st.iterations_per_step(), st.unconverged_steps)
}

/// One copy as a haptic loop calls it, on the GPU and on the CPU: one JSON row.
fn tick_row(text: &str, warm: f64, elements: usize, dt: f64, per_tick: u64, n_ticks: usize) {
    let warm_steps = (warm / dt).round() as u64;
    let mut gpu = build(text, Backend::Gpu, 1);
    let mut cpu = build(text, Backend::Cpu, 1);
    gpu.run(warm_steps).unwrap_or_else(|e| panic!("{e}"));
    cpu.run(warm_steps).unwrap_or_else(|e| panic!("{e}"));
    let (g, gtip) = ticks(&mut gpu, n_ticks, per_tick);
    let (c, ctip) = ticks(&mut cpu, n_ticks, per_tick);
    let gap = (0..3)
        .map(|k| (gtip[k] - ctip[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    println!(
        "{}",
        serde_json::json!({
            "case": "tick",
            "warm_s": warm,
            "elements": elements,
            "dt": dt,
            "steps_per_tick": per_tick,
            "ticks": n_ticks,
            "gpu_us": {"median": g[0], "p99": g[1], "max": g[2]},
            "cpu_us": {"median": c[0], "p99": c[1], "max": c[2]},
            "tip_gap_m": gap,
            "gpu_iterations_per_step": summary(&gpu).0,
            "cpu_iterations_per_step": summary(&cpu).0,
            "gpu_unconverged": summary(&gpu).1,
            "cpu_unconverged": summary(&cpu).1,
            "gpu_penetration_m": walls(&gpu).0,
            "cpu_penetration_m": walls(&cpu).0,
            "gpu_escaped": walls(&gpu).1,
            "gpu_walks_per_step": walks_per_step(&gpu),
            "cpu_escaped": walls(&cpu).1,
            "gpu_hand_force_n": gpu.end_reaction(RodHandle(0), 0).map(|r| r.force),
            "cpu_hand_force_n": cpu.end_reaction(RodHandle(0), 0).map(|r| r.force),
        })
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let n_ticks: usize = value("--ticks").map_or(500, |v| v.parse().expect("--ticks N"));
    let steps: u64 = value("--steps").map_or(2000, |v| v.parse().expect("--steps N"));
    let elements: usize = value("--elements").map_or(256, |v| v.parse().expect("--elements N"));
    let dt: f64 = value("--dt").map_or(1e-4, |v| v.parse().expect("--dt S"));
    let copies: Vec<usize> = value("--copies").map_or(vec![1, 64, 1024, 4096], |v| {
        v.split(',')
            .map(|c| c.parse().expect("--copies N,N"))
            .collect()
    });
    let text = match value("--scene").as_deref() {
        None | Some("free") => scene(elements, dt),
        Some("insertion") => insertion(elements, dt),
        Some("guide") => without_vessel(&insertion(elements, dt), true),
        Some("bare") => without_vessel(&insertion(elements, dt), false),
        Some("navigation") => navigation(elements, dt),
        Some("navigation-guide") => without_vessel(&navigation(elements, dt), true),
        Some("navigation-bare") => without_vessel(&navigation(elements, dt), false),
        Some("navigation-far") => out_of_reach(&navigation(elements, dt)),
        Some(other) => panic!(
            "--scene free|insertion|guide|bare|navigation|navigation-guide|navigation-bare|navigation-far, got {other}"
        ),
    };
    let per_tick = (1e-3 / dt).round().max(1.0) as u64;
    let warm: f64 = value("--warm").map_or(0.0, |v| v.parse().expect("--warm S"));
    let warm_steps = (warm / dt).round() as u64;
    if !args.iter().any(|a| a == "--batches-only") {
        tick_row(&text, warm, elements, dt, per_tick, n_ticks);
    }
    for &n in &copies {
        let mut sim = build(&text, Backend::Gpu, n);
        // Warm-up (pipeline, first dispatch), and the simulated time asked for.
        sim.run(per_tick + warm_steps)
            .unwrap_or_else(|e| panic!("{e}"));
        let t = Instant::now();
        sim.run(steps).unwrap_or_else(|e| panic!("{e}"));
        let wall = t.elapsed().as_secs_f64();
        let first = *sim.positions(RodHandle(0)).last().expect("points");
        let spread = (0..n)
            .map(|r| {
                let p = *sim.positions(RodHandle(r)).last().expect("points");
                (0..3)
                    .map(|k| (p[k] - first[k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(0.0, f64::max);
        let (its, unconverged) = summary(&sim);
        println!(
            "{}",
            serde_json::json!({
                "case": "batch",
                "warm_s": warm,
                "copies": n,
                "elements": elements,
                "dt": dt,
                "steps": steps,
                "wall_s": wall,
                "steps_per_s_each": steps as f64 / wall,
                "element_steps_per_s": (steps as f64 * (n * elements) as f64) / wall,
                "iterations_per_step": its,
                "unconverged_steps": unconverged,
                "tip_spread_m": spread,
                "penetration_m": walls(&sim).0,
                "escaped": walls(&sim).1,
                "walks_per_step": walks_per_step(&sim),
            })
        );
    }
}
