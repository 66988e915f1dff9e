//! `cargo xtask bench --haptic`: the stiff insertion as a haptic loop sees it, at 1 kHz and at
//! 500 Hz.
//!
//! A haptic loop calls one step per period and must get it back within the period, every
//! time: a median says little, the slow steps (those that re-solve after the contacts changed)
//! are what a user feels. This runs `scenes/stiff-guidewire-insertion.toml` step by step at
//! dt 1 ms and at dt 2 ms (the two ends of the 0.5–1 kHz range haptic devices run at), timing
//! each call, three times each, and the explicit insertion (`scenes/guidewire-insertion.toml`,
//! 700 000 steps) once as the accuracy reference; it writes `docs/benchmarks/haptic.md` with
//! the step-time percentiles, the steps over budget, and the tip's distance from the explicit
//! run's. The exit status says whether the 99th percentile is within the period at both rates
//! on this machine.

use crate::bench::{conditions, machine, root};
use cosserat::scene::load_scene;
use std::fmt::Write as _;
use std::time::Instant;

/// The loop rates measured: the step (and so the time a step may take) [s].
const PERIODS: [f64; 2] = [1e-3, 2e-3];

/// Timed runs of the stiff scene.
const RUNS: usize = 3;

struct Run {
    /// Wall time of every step [µs].
    times: Vec<f64>,
    tip: [f64; 3],
    iterations: f64,
    factorisations: f64,
    unconverged: u64,
    escaped: usize,
}

fn stiff_run(dt: f64) -> Result<Run, String> {
    let path = root().join("scenes/stiff-guidewire-insertion.toml");
    let overrides = [("solver.dt".to_string(), format!("{dt:e}"))];
    let (builder, length, _) = load_scene(&path, &overrides).map_err(|e| e.to_string())?;
    let mut sim = builder.build().map_err(|e| e.to_string())?;
    let mut times = Vec::with_capacity(length.steps as usize);
    for _ in 0..length.steps {
        let t0 = Instant::now();
        sim.step().map_err(|e| e.to_string())?;
        times.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    let rod = sim.rods().next().ok_or("the scene has no rod")?;
    let tip = *sim.positions(rod).last().ok_or("the rod has no points")?;
    let stiff = sim
        .stiff_summary()
        .ok_or("the scene does not use the stiff scheme")?;
    Ok(Run {
        times,
        tip,
        iterations: stiff.iterations_per_step(),
        factorisations: stiff.factorisations_per_step(),
        unconverged: stiff.unconverged_steps,
        escaped: sim.contact_report().map_or(0, |c| c.escaped_points),
    })
}

fn explicit_tip() -> Result<[f64; 3], String> {
    let path = root().join("scenes/guidewire-insertion.toml");
    let (builder, length, _) = load_scene(&path, &[]).map_err(|e| e.to_string())?;
    let mut sim = builder.build().map_err(|e| e.to_string())?;
    sim.run(length.steps).map_err(|e| e.to_string())?;
    let rod = sim.rods().next().ok_or("the scene has no rod")?;
    sim.positions(rod)
        .last()
        .copied()
        .ok_or_else(|| "the rod has no points".into())
}

/// The `q` quantile of sorted values (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

pub(crate) fn run() -> Result<bool, String> {
    let header = format!("Machine: {}; {}.", machine(), conditions());
    println!("running the explicit insertion (the accuracy reference, 700 000 steps)…");
    let reference = explicit_tip()?;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# The stiff insertion as a haptic loop sees it (1 kHz and 500 Hz)\n"
    );
    let _ = writeln!(
        md,
        "{header} Command: `cargo xtask bench --haptic` (`xtask/src/haptic.rs`). \
`scenes/stiff-guidewire-insertion.toml` (512 elements, procedural vessel, friction, guide; \
2.45 s) at dt 1 ms (2450 steps) and 2 ms (1225 steps), stepped one call at a time, each call \
timed, {RUNS} runs each; the tip is compared with the explicit run of \
`scenes/guidewire-insertion.toml` (f32, dt 3.5e-6 s), which ends at ({:.6}, {:.6}, {:.6}) m. \
Budget: a step within the loop's period at the 99th percentile.\n",
        reference[0], reference[1], reference[2]
    );
    let _ = writeln!(
        md,
        "| loop | run | first step [µs] | median [µs] | 99th percentile [µs] | 99.9th [µs] | largest [µs] | steps over the period | iterations / factorisations per step | steps above the tolerance | escaped points | tip from explicit [mm] |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut verdicts = Vec::new();
    for dt in PERIODS {
        let budget = dt * 1e6;
        let rate = format!("{:.0} Hz", 1.0 / dt);
        let mut p99s = Vec::new();
        for k in 1..=RUNS {
            println!("running the stiff insertion at {rate}, step by step ({k} of {RUNS})…");
            let r = stiff_run(dt)?;
            let first = r.times[0];
            let mut rest = r.times[1..].to_vec();
            rest.sort_by(f64::total_cmp);
            let over = rest.iter().filter(|&&t| t > budget).count();
            let p99 = quantile(&rest, 0.99);
            p99s.push(p99);
            let error = 1e3
                * r.tip
                    .iter()
                    .zip(&reference)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
                    .sqrt();
            let _ = writeln!(
                md,
                "| {rate} | {k} | {first:.0} | {:.0} | {p99:.0} | {:.0} | {:.0} | {over} of {} | {:.2} / {:.2} | {} | {} | {error:.3} |",
                quantile(&rest, 0.5),
                quantile(&rest, 0.999),
                rest.last().copied().unwrap_or(0.0),
                rest.len(),
                r.iterations,
                r.factorisations,
                r.unconverged,
                r.escaped,
            );
        }
        p99s.sort_by(f64::total_cmp);
        let median_p99 = p99s[p99s.len() / 2];
        verdicts.push((rate, budget, median_p99, median_p99 <= budget));
    }
    let _ = writeln!(md);
    for (rate, budget, median_p99, met) in &verdicts {
        let _ = writeln!(
            md,
            "- {rate}: budget {budget:.0} µs at the 99th percentile, median of the runs {median_p99:.0} µs: **{}** on this machine.",
            if *met { "met" } else { "not met" }
        );
    }
    let out = root().join("docs/benchmarks/haptic.md");
    std::fs::write(&out, &md).map_err(|e| format!("{}: {e}", out.display()))?;
    print!("{md}");
    Ok(verdicts.iter().all(|v| v.3))
}
