//! The benchmark behind `docs/benchmarks/gpu-contact.md`: the guidewire insertion into the
//! procedural vessel (`scenes/guidewire-insertion.toml`) on the GPU backend, as a user runs it
//! through the facade (wall clock, everything included).
//!
//! - one copy: the scene with neither vessel nor introducer, with the introducer only, and
//!   with both, over the same steps (what the contact code costs, and that a scene without it
//!   keeps the free-space speed);
//! - one copy to full depth (the whole scene, 2.45 s simulated), with the contact report;
//! - one tick: one step and the tip read back, as a haptic loop would;
//! - batches of copies (`[batch] copies`) sharing the vessel, throughput per copy and whether
//!   every copy stayed in the lumen.
//!
//! `cargo run --release --example gpu_contact_bench -- [--quick] [--copies 1024,4096]
//! [--batch-parts] [--gpus 1,2,4] [--batches-only] [--json FILE]`; `--batch-parts` also times
//! the batches without the vessel and without either (what each part costs when the GPU is
//! full); `--gpus` times every batch spread over each number of GPUs (`[batch] gpus`), for the
//! scaling table; `--catheter` also times `scenes/catheter-guidewire.toml` (the bound pair, v0,
//! v1 and v2, and the whole second of v2); `--chunk K` steps the batches in calls of `K` steps (default 500: each call
//! reads every copy back and checks it); `--batches-only` leaves out the single copy.

use cosserat::scene::parse_scene;
use cosserat::sim::{Backend, RodHandle, Simulation};
use std::path::Path;
use std::time::Instant;

const SCENE: &str = include_str!("../scenes/guidewire-insertion.toml");
const CATHETER: &str = include_str!("../scenes/catheter-guidewire.toml");

/// The catheter and its guidewire (paper section 3.4) on the GPU: each binding variant over
/// 20 000 steps from the start, and v2 over the scene's whole second.
fn catheter_section(quick: bool) -> serde_json::Value {
    let build = |variant: &str| {
        let overrides = [("binding.0.variant".to_string(), format!("\"{variant}\""))];
        let (b, _, _) = parse_scene(Path::new("catheter-guidewire.toml"), CATHETER, &overrides)
            .unwrap_or_else(|e| panic!("{e}"));
        b.backend(Backend::Gpu)
            .build()
            .unwrap_or_else(|e| panic!("{e}"))
    };
    let mut out = serde_json::Map::new();
    for variant in ["none", "one-way", "two-way"] {
        let mut sim = build(variant);
        let steps = if quick { 200 } else { 20_000 };
        let per = time_steps(&mut sim, steps, 10_000.min(steps));
        println!("catheter and guidewire, {variant}: {per:.2} µs/step");
        out.insert(variant.into(), per.into());
    }
    let mut sim = build("two-way");
    let full: u64 = if quick { 2_000 } else { 200_000 };
    let per = run_timed(&mut sim, full, 10_000);
    let report = sim.contact_report().expect("a vessel");
    let tips: Vec<[f64; 3]> = (0..2)
        .map(|r| *sim.positions(RodHandle(r)).last().expect("points"))
        .collect();
    println!(
        "catheter and guidewire, two-way, {full} steps: {per:.2} µs/step, escaped {}, max penetration {:.3e} m, tips {tips:?}",
        report.escaped_points, report.max_penetration
    );
    out.insert(
        "two_way_whole".into(),
        serde_json::json!({"steps": full, "us_per_step": per, "escaped_points": report.escaped_points,
            "max_penetration_m": report.max_penetration, "tips": tips}),
    );
    out.into()
}

/// The scene with `overrides`, with or without contact with its vessel and its introducer.
fn build(overrides: &[(&str, String)], vessel: bool, guide: bool) -> Simulation {
    let mut doc: toml::Table = toml::from_str(SCENE).expect("the scene parses");
    if !guide
        && let Some(toml::Value::Array(rods)) = doc.get_mut("rod")
        && let Some(toml::Value::Table(start)) =
            rods[0].as_table_mut().and_then(|r| r.get_mut("start"))
    {
        start.remove("guide");
    }
    let text = toml::to_string(&doc).expect("the scene prints");
    let mut overrides: Vec<(String, String)> = overrides
        .iter()
        .map(|(k, v)| ((*k).to_string(), v.clone()))
        .collect();
    if !vessel {
        // The vessel still places the wire; the wire does not touch it.
        overrides.push(("rod.0.collides".into(), "false".into()));
    }
    let (b, _, _) = parse_scene(Path::new("guidewire-insertion.toml"), &text, &overrides)
        .unwrap_or_else(|e| panic!("{e}"));
    b.backend(Backend::Gpu)
        .build()
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Wall time per step [µs] of `steps` steps taken in calls of `chunk`, after a warm-up call.
fn time_steps(sim: &mut Simulation, steps: u64, chunk: u64) -> f64 {
    sim.run(chunk.min(steps)).expect("warm-up");
    run_timed(sim, steps, chunk)
}

/// Wall time per step [µs] of `steps` steps taken in calls of `chunk`.
fn run_timed(sim: &mut Simulation, steps: u64, chunk: u64) -> f64 {
    let t = Instant::now();
    let mut left = steps;
    while left > 0 {
        let k = left.min(chunk);
        sim.run(k).unwrap_or_else(|e| panic!("{e}"));
        left -= k;
    }
    t.elapsed().as_secs_f64() * 1e6 / steps as f64
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let copies: Vec<usize> = arg("--copies")
        .map(|s| s.split(',').map(|c| c.parse().expect("copies")).collect())
        .unwrap_or_else(|| vec![1024, 4096]);
    let gpus: Vec<usize> = arg("--gpus")
        .map(|s| s.split(',').map(|c| c.parse().expect("gpus")).collect())
        .unwrap_or_else(|| vec![1]);
    let batches_only = args.iter().any(|a| a == "--batches-only");
    let catheter = args.iter().any(|a| a == "--catheter");
    let chunk: u64 = arg("--chunk").map_or(500, |c| c.parse().expect("chunk"));
    let steps: u64 = if quick { 200 } else { 20_000 };
    let mut json = serde_json::Map::new();

    if !batches_only {
        // One copy: without and with the contact code.
        let mut single = serde_json::Map::new();
        for (name, vessel, guide) in [
            ("free", false, false),
            ("guide", false, true),
            ("guide_and_vessel", true, true),
        ] {
            let mut sim = build(&[], vessel, guide);
            let per = median(
                (0..3)
                    .map(|_| time_steps(&mut sim, steps, 10_000.min(steps)))
                    .collect(),
            );
            println!("one copy, {name}: {per:.2} µs/step");
            single.insert(name.into(), per.into());
            if let Some(st) = sim.stepper().collision_stats(0) {
                let q = st.queries as f64 / st.steps.max(1) as f64;
                println!(
                    "  tree walks per step {q:.2}, ridge element contacts {}",
                    st.segment_contacts
                );
                single.insert(format!("{name}_queries_per_step"), q.into());
            }
        }
        json.insert("single_us_per_step".into(), single.into());

        // One copy to full depth.
        let mut sim = build(&[], true, true);
        let full: u64 = if quick {
            2_000
        } else {
            (2.45f64 / 3.5e-6).ceil() as u64
        };
        let per = run_timed(&mut sim, full, 10_000);
        let report = sim.contact_report().expect("a vessel");
        let tip = *sim.positions(RodHandle(0)).last().expect("points");
        let st = sim.stepper().collision_stats(0).expect("stats");
        let queries = st.queries as f64 / st.steps.max(1) as f64;
        println!(
            "  tree walks per step {queries:.2}, most contacts {}, ridge element contacts {}, swept catches {}",
            st.max_contacts, st.segment_contacts, st.swept_catches
        );
        println!(
            "full depth: {full} steps, {per:.2} µs/step, escaped {}, max penetration {:.3e} m, contacts {}, tip {tip:?}",
            report.escaped_points, report.max_penetration, report.contacts
        );
        json.insert(
        "full_depth".into(),
        serde_json::json!({
            "steps": full, "us_per_step": per, "escaped_points": report.escaped_points,
            "max_penetration_m": report.max_penetration, "contacts": report.contacts, "tip": tip,
            "queries_per_step": queries, "max_contacts": st.max_contacts,
            "ridge_contacts": st.segment_contacts, "swept_catches": st.swept_catches,
        }),
    );

        // One tick: a step and the tip read back.
        let mut ticks = Vec::new();
        for _ in 0..if quick { 20 } else { 2000 } {
            let t = Instant::now();
            sim.run(1).unwrap_or_else(|e| panic!("{e}"));
            let tip = *sim.positions(RodHandle(0)).last().expect("points");
            ticks.push(t.elapsed().as_secs_f64() * 1e6);
            std::hint::black_box(tip);
        }
        let tick = median(ticks);
        println!("one tick (a step and the tip): {tick:.1} µs median");
        json.insert("tick_us".into(), tick.into());
    }

    if catheter {
        json.insert("catheter_guidewire".into(), catheter_section(quick));
    }

    // Batches.
    let parts: &[(&str, bool, bool)] = if args.iter().any(|a| a == "--batch-parts") {
        &[
            ("guide_and_vessel", true, true),
            ("guide", false, true),
            ("free", false, false),
        ]
    } else {
        &[("guide_and_vessel", true, true)]
    };
    let mut batches = Vec::new();
    for &n in &copies {
        for &g in &gpus {
            for &(part, vessel, guide) in parts {
                let overrides = [
                    ("batch.copies", n.to_string()),
                    ("batch.gpus", g.to_string()),
                ];
                let mut sim = build(&overrides, vessel, guide);
                let batch_steps: u64 = if quick { 100 } else { 2_000 };
                let per = time_steps(&mut sim, batch_steps, chunk.min(batch_steps));
                // One step of every copy with the whole batch read back and checked: what a
                // vector environment's step costs beyond its physics.
                let tick = median(
                    (0..5)
                        .map(|_| {
                            let t = Instant::now();
                            sim.run(1).unwrap_or_else(|e| panic!("{e}"));
                            t.elapsed().as_secs_f64() * 1e6
                        })
                        .collect(),
                );
                let report = sim.contact_report().expect("a vessel");
                let per_copy = 1e6 / per;
                println!(
                    "{n} copies on {g} GPU(s), {part}: {per:.1} µs/step in calls of {chunk}, {per_copy:.0} steps/s for every copy ({:.2e} element-steps/s), one step read back {tick:.0} µs, escaped {}, max penetration {:.3e} m",
                    per_copy * 512.0 * n as f64,
                    report.escaped_points,
                    report.max_penetration
                );
                batches.push(serde_json::json!({
                    "copies": n, "gpus": g, "part": part, "us_per_step": per,
                    "steps_per_call": chunk, "one_step_read_back_us": tick,
                    "steps_per_s_per_copy": per_copy,
                    "element_steps_per_s": per_copy * 512.0 * n as f64,
                    "escaped_points": report.escaped_points,
                    "max_penetration_m": report.max_penetration, "steps": batch_steps,
                }));
            }
        }
    }
    json.insert("batches".into(), batches.into());
    if let Some(path) = arg("--json") {
        std::fs::write(&path, serde_json::to_string_pretty(&json).expect("json"))
            .unwrap_or_else(|e| panic!("{path}: {e}"));
    }
}
