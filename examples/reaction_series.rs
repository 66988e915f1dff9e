//! The force a held end applies to its rod, as a haptic device would render it: one line per
//! millisecond of simulated time with the mean of the filtered reaction force at the first
//! rod's start over that millisecond, and the tip's z coordinate.
//!
//! `cargo run --release --example reaction_series -- SCENE [KEY=VALUE ...]`
//! (overrides as `cosserat run --set`); columns: ms, Fx, Fy, Fz [N], tip z [m].
//! `docs/stiff-solver.md` compares the explicit and stiff insertions with it.

use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(scene) = args.get(1) else {
        return Err("usage: reaction_series SCENE [KEY=VALUE ...]".into());
    };
    let overrides = args[2..]
        .iter()
        .map(|a| {
            a.split_once('=')
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .ok_or_else(|| format!("override `{a}` is not KEY=VALUE"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (builder, length, _) = cosserat::scene::load_scene(Path::new(scene), &overrides)?;
    let mut sim = builder.build()?;
    let rod = sim.rods().next().ok_or("the scene has no rod")?;
    let per_ms = ((1e-3 / sim.dt()).round() as u64).max(1);
    for ms in 0..length.steps / per_ms {
        let mut mean = [0.0; 3];
        for _ in 0..per_ms {
            sim.step()?;
            let r = sim
                .end_reaction(rod, 0)
                .ok_or("the first rod's start is not held")?;
            for (m, f) in mean.iter_mut().zip(r.force) {
                *m += f / per_ms as f64;
            }
        }
        let tip = sim.positions(rod).last().copied().unwrap_or_default();
        println!(
            "{} {:.6e} {:.6e} {:.6e} {:.5}",
            ms + 1,
            mean[0],
            mean[1],
            mean[2],
            tip[2]
        );
    }
    Ok(())
}
