//! `cargo xtask validate --timings`: the paper's free-space test (`scenes/pendulum.toml`: a rod
//! pinned at one end, released horizontally, 10 constraint sweeps per step) at 100 and 1000
//! elements on the CPU backend, next to every published row of `xtask/data/literature-timings.toml`.
//!
//! Ratios are `published / ours` (above 1: we are faster). The published figures come from
//! other hardware (2007–2013 CPUs and GPUs), so a ratio is a statement about this machine, not
//! about the algorithms alone; the hardware of each row is printed with it.

use crate::support::cases::{pendulum, workspace_file};
use cosserat::Backend;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::time::Instant;

#[derive(Deserialize)]
struct Literature {
    hardware: BTreeMap<String, String>,
    free_space: Vec<FreeSpaceRow>,
}

#[derive(Deserialize)]
struct FreeSpaceRow {
    implementation: String,
    hardware: String,
    inextensible: bool,
    #[serde(default)]
    approximate: bool,
    ms_per_step: PerSize,
}

#[derive(Deserialize)]
struct PerSize {
    n100: f64,
    n1000: f64,
}

/// Milliseconds per step of the pendulum scene, median of five timed batches.
fn ms_per_step(elements: usize, extensible: bool, backend: Backend) -> Result<f64, String> {
    let mode = if extensible {
        "extensible"
    } else {
        "inextensible"
    };
    let b = pendulum(&[
        ("rod.0.elements", elements.to_string()),
        ("solver.mode", mode.into()),
    ])?;
    let mut sim = b.backend(backend).build().map_err(|e| e.to_string())?;
    let batch = (200_000 / elements).max(50) as u64;
    sim.run(batch / 4).map_err(|e| e.to_string())?;
    let mut samples = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        sim.run(batch).map_err(|e| e.to_string())?;
        samples.push(t.elapsed().as_secs_f64() * 1e3 / batch as f64);
    }
    samples.sort_by(f64::total_cmp);
    Ok(samples[2])
}

fn cpu_name() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}

pub(crate) fn run() -> Result<bool, String> {
    let path = workspace_file("xtask/data/literature-timings.toml");
    let lit: Literature = toml::from_str(
        &std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?,
    )
    .map_err(|e| format!("{}: {e}", path.display()))?;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "ours: {} ({threads} hardware threads), scene scenes/pendulum.toml (f32, dt 2e-5, 10 Gauss–Seidel sweeps), release build\n",
        cpu_name()
    );
    let mut ours = BTreeMap::new();
    for extensible in [false, true] {
        for (name, backend) in [("serial", Backend::Cpu), ("rayon", Backend::CpuRayon)] {
            for n in [100, 1000] {
                let ms = ms_per_step(n, extensible, backend)?;
                println!(
                    "ours, {} {name}, {n} elements: {ms:.4} ms/step",
                    if extensible {
                        "extensible"
                    } else {
                        "inextensible"
                    }
                );
                ours.insert((extensible, name, n), ms);
            }
        }
    }
    println!(
        "\n| published implementation | hardware | inext. | 100 el. ms | ours serial | ratio | ours rayon | ratio | 1000 el. ms | ours serial | ratio | ours rayon | ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &lit.free_space {
        let hw = lit
            .hardware
            .get(&r.hardware)
            .cloned()
            .unwrap_or_else(|| r.hardware.clone());
        let ext = !r.inextensible;
        let cell = |published: f64, n: usize| {
            let s = ours[&(ext, "serial", n)];
            let p = ours[&(ext, "rayon", n)];
            format!(
                "{published}{} | {s:.4} | {:.2} | {p:.4} | {:.2}",
                if r.approximate { "*" } else { "" },
                published / s,
                published / p
            )
        };
        println!(
            "| {} | {hw} | {} | {} | {} |",
            r.implementation,
            if r.inextensible { "yes" } else { "no" },
            cell(r.ms_per_step.n100, 100),
            cell(r.ms_per_step.n1000, 1000)
        );
    }
    println!(
        "\nratio = published / ours (> 1: ours faster); * = approximated by the paper's authors. A single rod: the rayon backend parallelises over rods, so one rod runs serially there too."
    );
    Ok(true)
}
