//! Guidewire insertion (paper section 3.3): wall time per step against insertion depth.
//!
//! Runs `scenes/guidewire-insertion.toml` (procedural vessel) and, when the mesh is present,
//! `scenes/phantom-insertion.toml` (the real phantom), in windows of simulated time, and prints
//! one Markdown row per window: depth of the tip past the entry, µs per step (all of it), µs per
//! step in collision detection, points in contact, largest penetration and escaped points.
//! Run with `cargo bench --bench insertion`; `cargo xtask bench` stores the table in
//! `docs/benchmarks/`.

use cosserat::scene::load_scene;
use cosserat::{RodHandle, Simulation};
use std::path::Path;
use std::time::Instant;

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

fn run(scene: &Path, windows: usize) {
    let (builder, length, name) = match load_scene(scene, &[]) {
        Ok(x) => x,
        Err(e) => {
            println!("\n{}: skipped ({e})", scene.display());
            return;
        }
    };
    let mut sim = builder.build().expect("the scene builds");
    let per_window = length.steps / windows as u64;
    println!(
        "\n### {name}: {} elements, dt = {:.1e} s, {} triangles\n",
        sim.element_count(),
        sim.dt(),
        sim.environment().map_or(0, |e| e.triangles())
    );
    println!(
        "| simulated s | tip depth [mm] | µs/step | detection µs/step | contacts | max penetration [µm] | escaped |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut last_detection = 0.0;
    for _ in 0..windows {
        let before = sim
            .contact_report()
            .map_or(0.0, |c| c.detection_us_per_step * sim.steps() as f64);
        let t0 = Instant::now();
        if let Err(e) = sim.run(per_window) {
            println!("| diverged: {e} |");
            return;
        }
        let wall = t0.elapsed().as_secs_f64();
        let c = sim
            .contact_report()
            .expect("an insertion scene has an environment");
        let detection_total = c.detection_us_per_step * sim.steps() as f64;
        let detection = (detection_total - before.max(last_detection)) / per_window as f64;
        last_detection = detection_total;
        println!(
            "| {:.2} | {:.1} | {:.1} | {:.1} | {} | {:.2} | {} |",
            sim.time(),
            depth(&sim) * 1e3,
            wall * 1e6 / per_window as f64,
            detection,
            c.contacts,
            c.max_penetration * 1e6,
            c.escaped_points
        );
    }
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is read.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    run(&root.join("scenes/guidewire-insertion.toml"), 7);
    run(&root.join("scenes/phantom-insertion.toml"), 5);
}
