//! `cargo xtask bench --haptic`: guidewire insertions as a haptic loop sees them.
//!
//! A haptic loop calls the simulation once per tick and must get it back within the tick,
//! every time: a median says little, the slow ticks (steps that re-solve after the contacts
//! changed) are what a user feels. This steps its loops call by call, timing every tick,
//! three times each:
//! - the soft wire of `scenes/stiff-guidewire-insertion.toml` at 1 kHz (one step of 1 ms per
//!   tick) and at 500 Hz (one step of 2 ms), the two ends of the range haptic devices run at;
//! - the real guidewire of `scenes/nitinol-guidewire-insertion.toml` (the `nitinol` preset),
//!   which needs steps of 0.1 ms in the vessel, at 1 kHz as ten steps per tick, with 256
//!   elements (2 mm, the resolution a haptic scene would use);
//! - that guidewire bound inside a `catheter-polymer` catheter
//!   (`scenes/stiff-catheter-guidewire.toml`), 256 elements each, at 1 kHz as five steps of
//!   0.2 ms per tick;
//! - the soft wire at 1 kHz and the nitinol wire at 1 kHz again with the second-order
//!   integrator (`solver.stiff.integrator = "bdf2"`), which costs more per step;
//! - the nitinol wire and the same wire in the `steel` preset at 1 kHz as one step of 1 ms per
//!   tick, 256 elements.
//!
//! Each loop's tips (every rod's) are compared with a reference run to the same end: the
//! explicit insertion (`scenes/guidewire-insertion.toml`, 700 000 steps) for the soft wire, the
//! nitinol scenes (and the steel wire's) at dt 5e-5 s with 512 elements per rod for the others. It writes `docs/benchmarks/haptic.md`; the
//! exit status says whether every loop's 99th percentile is within its tick on this machine.

use crate::bench::{conditions, machine, root};
use cosserat::scene::load_scene;
use std::fmt::Write as _;
use std::time::Instant;

/// Timed runs of each loop.
const RUNS: usize = 3;

/// A scene with `--set` style overrides.
type SceneWith = (&'static str, &'static [(&'static str, &'static str)]);

/// One haptic loop: a scene stepped `steps_per_tick` times per tick of `period` seconds.
struct Loop {
    label: &'static str,
    scene: SceneWith,
    steps_per_tick: u64,
    period: f64,
    /// The run whose final tip the loop's is compared with, and what it is.
    reference: (SceneWith, &'static str),
}

const SOFT_REFERENCE: (SceneWith, &str) = (
    ("scenes/guidewire-insertion.toml", &[]),
    "the explicit run of `scenes/guidewire-insertion.toml` (f32, dt 3.5e-6 s)",
);
const NITINOL_REFERENCE: (SceneWith, &str) = (
    (
        "scenes/nitinol-guidewire-insertion.toml",
        &[("solver.dt", "5e-5")],
    ),
    "`scenes/nitinol-guidewire-insertion.toml` at dt 5e-5 s (512 elements)",
);

const STEEL_REFERENCE: (SceneWith, &str) = (
    (
        "scenes/nitinol-guidewire-insertion.toml",
        &[("solver.dt", "5e-5"), ("rod.0.material.preset", "steel")],
    ),
    "`scenes/nitinol-guidewire-insertion.toml` with the `steel` preset at dt 5e-5 s (512 elements)",
);

const PAIR_REFERENCE: (SceneWith, &str) = (
    (
        "scenes/stiff-catheter-guidewire.toml",
        &[("solver.dt", "5e-5")],
    ),
    "`scenes/stiff-catheter-guidewire.toml` at dt 5e-5 s (512 elements each)",
);

const LOOPS: [Loop; 8] = [
    Loop {
        label: "soft wire, 1 kHz (1 × 1 ms)",
        scene: ("scenes/stiff-guidewire-insertion.toml", &[]),
        steps_per_tick: 1,
        period: 1e-3,
        reference: SOFT_REFERENCE,
    },
    Loop {
        label: "soft wire, 500 Hz (1 × 2 ms)",
        scene: (
            "scenes/stiff-guidewire-insertion.toml",
            &[("solver.dt", "2e-3")],
        ),
        steps_per_tick: 1,
        period: 2e-3,
        reference: SOFT_REFERENCE,
    },
    Loop {
        label: "nitinol wire, 256 elements, 1 kHz (10 × 0.1 ms)",
        scene: (
            "scenes/nitinol-guidewire-insertion.toml",
            &[("rod.0.elements", "256")],
        ),
        steps_per_tick: 10,
        period: 1e-3,
        reference: NITINOL_REFERENCE,
    },
    Loop {
        label: "soft wire, BDF2, 1 kHz (1 × 1 ms)",
        scene: (
            "scenes/stiff-guidewire-insertion.toml",
            &[("solver.stiff.integrator", "bdf2")],
        ),
        steps_per_tick: 1,
        period: 1e-3,
        reference: SOFT_REFERENCE,
    },
    Loop {
        label: "nitinol wire, 256 elements, BDF2, 1 kHz (10 × 0.1 ms)",
        scene: (
            "scenes/nitinol-guidewire-insertion.toml",
            &[
                ("rod.0.elements", "256"),
                ("solver.stiff.integrator", "bdf2"),
            ],
        ),
        steps_per_tick: 10,
        period: 1e-3,
        reference: NITINOL_REFERENCE,
    },
    Loop {
        label: "nitinol wire in a catheter, 256 elements each, 1 kHz (5 × 0.2 ms)",
        scene: (
            "scenes/stiff-catheter-guidewire.toml",
            &[
                ("rod.0.elements", "256"),
                ("rod.1.elements", "256"),
                ("solver.dt", "2e-4"),
            ],
        ),
        steps_per_tick: 5,
        period: 1e-3,
        reference: PAIR_REFERENCE,
    },
    Loop {
        label: "nitinol wire, 256 elements, 1 kHz (1 × 1 ms)",
        scene: (
            "scenes/nitinol-guidewire-insertion.toml",
            &[("rod.0.elements", "256"), ("solver.dt", "1e-3")],
        ),
        steps_per_tick: 1,
        period: 1e-3,
        reference: NITINOL_REFERENCE,
    },
    Loop {
        label: "steel wire, 256 elements, 1 kHz (1 × 1 ms)",
        scene: (
            "scenes/nitinol-guidewire-insertion.toml",
            &[
                ("rod.0.elements", "256"),
                ("solver.dt", "1e-3"),
                ("rod.0.material.preset", "steel"),
            ],
        ),
        steps_per_tick: 1,
        period: 1e-3,
        reference: STEEL_REFERENCE,
    },
];

struct Run {
    /// Wall time of every tick [µs].
    times: Vec<f64>,
    tips: Vec<[f64; 3]>,
    iterations: f64,
    factorisations: f64,
    unconverged: u64,
    escaped: usize,
}

fn load((scene, set): SceneWith) -> Result<(cosserat::Simulation, u64), String> {
    let path = root().join(scene);
    let overrides: Vec<_> = set
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let (builder, length, _) = load_scene(&path, &overrides).map_err(|e| e.to_string())?;
    let sim = builder.build().map_err(|e| e.to_string())?;
    Ok((sim, length.steps))
}

/// The last point of every rod.
fn tips(sim: &cosserat::Simulation) -> Result<Vec<[f64; 3]>, String> {
    sim.rods()
        .map(|rod| {
            sim.positions(rod)
                .last()
                .copied()
                .ok_or_else(|| "a rod has no points".to_string())
        })
        .collect()
}

fn timed_run(l: &Loop) -> Result<Run, String> {
    let (mut sim, steps) = load(l.scene)?;
    let ticks = steps / l.steps_per_tick;
    let mut times = Vec::with_capacity(ticks as usize);
    for _ in 0..ticks {
        let t0 = Instant::now();
        for _ in 0..l.steps_per_tick {
            sim.step().map_err(|e| e.to_string())?;
        }
        times.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    let stiff = sim
        .stiff_summary()
        .ok_or("the scene does not use the stiff scheme")?;
    Ok(Run {
        times,
        tips: tips(&sim)?,
        iterations: stiff.iterations_per_step(),
        factorisations: stiff.factorisations_per_step(),
        unconverged: stiff.unconverged_steps,
        escaped: sim.contact_report().map_or(0, |c| c.escaped_points),
    })
}

fn reference_tips(scene: SceneWith) -> Result<Vec<[f64; 3]>, String> {
    let (mut sim, steps) = load(scene)?;
    sim.run(steps).map_err(|e| e.to_string())?;
    tips(&sim)
}

/// The `q` quantile of sorted values (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

pub(crate) fn run() -> Result<bool, String> {
    let header = format!("Machine: {}; {}.", machine(), conditions());
    let mut references: Vec<(&str, Vec<[f64; 3]>)> = Vec::new();
    for l in &LOOPS {
        let (scene, what) = l.reference;
        if !references.iter().any(|(w, _)| *w == what) {
            println!("running the reference: {what}…");
            references.push((what, reference_tips(scene)?));
        }
    }
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Guidewire and catheter insertions as a haptic loop sees them\n"
    );
    let _ = writeln!(
        md,
        "{header} Command: `cargo xtask bench --haptic` (`xtask/src/haptic.rs`). Each loop \
steps its scene to the end (2.45 s, full depth; 2.4 s for the catheter) one tick at a time, \
each tick timed (the first tick apart), {RUNS} runs each. Budget: a tick within the loop's \
period at the 99th percentile. Tips (of every rod; the largest distance is listed) are \
compared with reference runs to the same end:\n"
    );
    for (what, tips) in &references {
        let list: Vec<_> = tips
            .iter()
            .map(|t| format!("({:.6}, {:.6}, {:.6})", t[0], t[1], t[2]))
            .collect();
        let _ = writeln!(md, "- {what}: {} m", list.join(", "));
    }
    let _ = writeln!(
        md,
        "\n| loop | run | first tick [µs] | median [µs] | 99th percentile [µs] | 99.9th [µs] | largest [µs] | ticks over the period | iterations / factorisations per step | steps above the tolerance | escaped points | tip from the reference [mm] |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut verdicts = Vec::new();
    for l in &LOOPS {
        let budget = l.period * 1e6;
        let reference = references
            .iter()
            .find(|(w, _)| *w == l.reference.1)
            .map(|r| r.1.clone())
            .ok_or("reference not run")?;
        let mut p99s = Vec::new();
        for k in 1..=RUNS {
            println!("running {}, tick by tick ({k} of {RUNS})…", l.label);
            let r = timed_run(l)?;
            let first = r.times[0];
            let mut rest = r.times[1..].to_vec();
            rest.sort_by(f64::total_cmp);
            let over = rest.iter().filter(|&&t| t > budget).count();
            let p99 = quantile(&rest, 0.99);
            p99s.push(p99);
            if r.tips.len() != reference.len() {
                return Err(format!("{}: rods differ from the reference's", l.label));
            }
            let error = 1e3
                * r.tips
                    .iter()
                    .zip(&reference)
                    .map(|(t, u)| {
                        t.iter()
                            .zip(u)
                            .map(|(a, b)| (a - b).powi(2))
                            .sum::<f64>()
                            .sqrt()
                    })
                    .fold(0.0, f64::max);
            let _ = writeln!(
                md,
                "| {} | {k} | {first:.0} | {:.0} | {p99:.0} | {:.0} | {:.0} | {over} of {} | {:.2} / {:.2} | {} | {} | {error:.3} |",
                l.label,
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
        verdicts.push((l.label, budget, median_p99, median_p99 <= budget));
    }
    let _ = writeln!(md);
    for (label, budget, median_p99, met) in &verdicts {
        let _ = writeln!(
            md,
            "- {label}: budget {budget:.0} µs at the 99th percentile, median of the runs {median_p99:.0} µs: **{}** on this machine.",
            if *met { "met" } else { "not met" }
        );
    }
    let out = root().join("docs/benchmarks/haptic.md");
    std::fs::write(&out, &md).map_err(|e| format!("{}: {e}", out.display()))?;
    print!("{md}");
    Ok(verdicts.iter().all(|v| v.3))
}
