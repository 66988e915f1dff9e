//! Guidewire insertion (paper section 3.3): wall time per step against insertion depth.
//!
//! Runs `scenes/guidewire-insertion.toml` (procedural vessel) and, when the mesh is present,
//! `scenes/phantom-insertion.toml` (the real phantom) over their whole duration (to full depth),
//! in windows of [`WINDOW_S`] of simulated time, and prints one Markdown row per window: depth
//! of the tip past the entry, µs per step (all of it), µs per step in collision detection, points
//! in contact at the end of the window, largest penetration and escaped points so far. A last
//! table compares the cost per step at full depth with the goal: the last whole window (the
//! deepest 0.2 s of pushing) and the short window that ends the run (in
//! `guidewire-insertion.toml` the hand stops at 2.4 s and holds; the phantom is pushed to the
//! end).
//! Run with `cargo bench --bench insertion`; `cargo xtask bench` stores the tables in
//! `docs/benchmarks/insertion.md`.

use cosserat::scene::load_scene;
use cosserat::{RodHandle, Simulation};
use std::path::Path;
use std::time::Instant;

/// Length of a window of simulated time [s]; the last window of a run takes what is left
/// (2.40–2.45 s for the 2.45 s scenes).
const WINDOW_S: f64 = 0.2;

/// The goal at full depth on the 2-core machine [µs/step] (issue 5).
const GOAL_US: f64 = 150.0;

/// Depth of the tip past the entry point along the entry direction [m].
fn depth(sim: &Simulation) -> f64 {
    let Some(v) = sim.environment().and_then(|e| e.vessel.as_ref()) else {
        return f64::NAN;
    };
    let tip = *sim
        .positions(RodHandle(0))
        .last()
        .expect("a rod has points");
    (0..3)
        .map(|k| (tip[k] - v.entry_point[k]) * v.entry_direction[k])
        .sum()
}

/// One window of a run.
#[derive(Clone, Copy)]
struct Window {
    start: f64,
    end: f64,
    depth_mm: f64,
    us_per_step: f64,
    detection_us: f64,
    contacts: usize,
}

/// What a run ends with: the last whole window, the last window and the mean over the run.
struct FullDepth {
    name: String,
    whole: Window,
    last: Window,
    mean_us_per_step: f64,
}

fn run(scene: &Path) -> Option<FullDepth> {
    let (builder, length, name) = match load_scene(scene, &[]) {
        Ok(x) => x,
        Err(e) => {
            println!("\n{}: skipped ({e})", scene.display());
            return None;
        }
    };
    let mut sim = builder.build().expect("the scene builds");
    println!(
        "\n### {name}: {} elements, dt = {:.1e} s, {} triangles, {} steps\n",
        sim.element_count(),
        sim.dt(),
        sim.environment().map_or(0, |e| e.triangles()),
        length.steps
    );
    println!(
        "| simulated s | tip depth [mm] | µs/step | detection µs/step | contacts | max penetration [µm] | escaped |"
    );
    println!("|---|---|---|---|---|---|---|");
    let detection_total = |sim: &Simulation| {
        sim.contact_report()
            .map_or(0.0, |c| c.detection_us_per_step * sim.steps() as f64)
    };
    let per_window = (WINDOW_S / sim.dt()).round() as u64;
    let (mut wall_total, mut windows) = (0.0, Vec::new());
    while sim.steps() < length.steps {
        let n = per_window.min(length.steps - sim.steps());
        let start = sim.time();
        let before = detection_total(&sim);
        let t0 = Instant::now();
        if let Err(e) = sim.run(n) {
            println!("| diverged: {e} |");
            return None;
        }
        let wall = t0.elapsed().as_secs_f64();
        wall_total += wall;
        let c = sim
            .contact_report()
            .expect("an insertion scene has an environment");
        let w = Window {
            start,
            end: sim.time(),
            depth_mm: depth(&sim) * 1e3,
            us_per_step: wall * 1e6 / n as f64,
            detection_us: (detection_total(&sim) - before) / n as f64,
            contacts: c.contacts,
        };
        println!(
            "| {:.2} | {:.1} | {:.1} | {:.1} | {} | {:.2} | {} |",
            w.end,
            w.depth_mm,
            w.us_per_step,
            w.detection_us,
            w.contacts,
            c.max_penetration * 1e6,
            c.escaped_points
        );
        windows.push((n, w));
    }
    let last = windows.last()?.1;
    let whole = windows
        .iter()
        .rev()
        .find(|(n, _)| *n == per_window)
        .map_or(last, |w| w.1);
    Some(FullDepth {
        name,
        whole,
        last,
        mean_us_per_step: wall_total * 1e6 / sim.steps() as f64,
    })
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is read.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let full: Vec<FullDepth> = ["guidewire-insertion", "phantom-insertion"]
        .iter()
        .filter_map(|s| run(&root.join(format!("scenes/{s}.toml"))))
        .collect();
    println!(
        "\n### At full depth against the goal (≤ {GOAL_US:.0} µs/step; paper: 1645 µs/step CPU, 188 µs/step GPU)\n"
    );
    println!(
        "| scene | window [s] | tip depth [mm] | µs/step | detection µs/step | contacts | goal met |"
    );
    println!("|---|---|---|---|---|---|---|");
    for f in &full {
        for w in [f.whole, f.last] {
            println!(
                "| {} | {:.2}–{:.2} | {:.1} | {:.1} | {:.1} | {} | {} |",
                f.name,
                w.start,
                w.end,
                w.depth_mm,
                w.us_per_step,
                w.detection_us,
                w.contacts,
                if w.us_per_step <= GOAL_US {
                    "yes"
                } else {
                    "no"
                }
            );
        }
        println!(
            "| {} | whole run (mean) | | {:.1} | | | |",
            f.name, f.mean_us_per_step
        );
    }
}
