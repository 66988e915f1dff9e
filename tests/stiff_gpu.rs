//! The stiff scheme on the GPU (`cosserat_backend_gpu::GpuStiffSimulation`) against the CPU's
//! stiff scheme in `f64`, its oracle: the same passes in the same order, so the two agree to
//! rounding, step for step and iteration for iteration. Runs on lavapipe in CI
//! (`COSSERAT_REQUIRE_GPU=1`); without an adapter it is skipped unless required.

#[path = "support/pair.rs"]
mod pair;

use cosserat::sim::{RodHandle, Simulation};
use pair::{largest_gap, pair};

/// The scene built for the CPU and the GPU, the GPU's stepper the stiff one.
fn gpu_stiff(text: &str) -> Option<(Simulation, Simulation)> {
    let (cpu, gpu) = pair(text, &[])?;
    assert_eq!(gpu.stepper().info().name, "gpu stiff");
    Some((cpu, gpu))
}

/// Runs both `steps` steps in `batches` and checks positions, frames and the solver's counts.
fn agree(cpu: &mut Simulation, gpu: &mut Simulation, batches: u64, steps: u64, tol: f64) {
    for _ in 0..batches {
        cpu.run(steps).unwrap_or_else(|e| panic!("cpu: {e}"));
        gpu.run(steps).unwrap_or_else(|e| panic!("gpu: {e}"));
    }
    for rod in 0..cpu.stepper().rod_count() {
        let h = RodHandle(rod);
        let (c, g) = (cpu.positions(h), gpu.positions(h));
        let gap = largest_gap(&c, &g);
        assert!(gap < tol, "rod {rod}: GPU and CPU differ by {gap:e} m");
        let n = c.len() - 1;
        let (mut fc, mut fg) = (vec![[0.0; 4]; n], vec![[0.0; 4]; n]);
        cpu.stepper().read_frames(rod, &mut fc).expect("cpu frames");
        gpu.stepper().read_frames(rod, &mut fg).expect("gpu frames");
        let turn = fc
            .iter()
            .zip(&fg)
            .map(|(a, b)| {
                // Twice the distance of the unit quaternions (with the sign that brings them
                // together): the angle between the frames to first order.
                let d: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
                let s = d.signum();
                2.0 * a
                    .iter()
                    .zip(b)
                    .map(|(x, y)| (x - s * y).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(0.0, f64::max);
        assert!(turn < tol, "rod {rod}: frames differ by {turn:e} rad");
        eprintln!("rod {rod}: positions within {gap:.1e} m, frames within {turn:.1e} rad");
    }
    // The held ends' filtered reactions (force and torque).
    for rod in 0..cpu.stepper().rod_count() {
        for end in 0..2 {
            let (c, g) = (
                cpu.end_reaction(RodHandle(rod), end),
                gpu.end_reaction(RodHandle(rod), end),
            );
            assert_eq!(c.is_some(), g.is_some(), "rod {rod} end {end}");
            let (Some(c), Some(g)) = (c, g) else { continue };
            let scale = c
                .force
                .iter()
                .chain(&c.torque)
                .fold(1e-9, |m: f64, x| m.max(x.abs()));
            let gap = (0..3)
                .map(|k| {
                    (c.force[k] - g.force[k])
                        .abs()
                        .max((c.torque[k] - g.torque[k]).abs())
                })
                .fold(0.0, f64::max);
            assert!(
                gap < 1e-7 * scale,
                "rod {rod} end {end}: reactions differ by {gap:e} (cpu {c:?}, gpu {g:?})"
            );
            eprintln!(
                "rod {rod} end {end}: reaction within {:.1e} of {scale:.2e}",
                gap
            );
        }
    }
    let (sc, sg) = (
        cpu.stiff_summary().expect("cpu summary"),
        gpu.stiff_summary().expect("gpu summary"),
    );
    assert_eq!(sg.rod_steps, sc.rod_steps);
    assert_eq!(sg.iterations, sc.iterations, "gpu {sg:?}\ncpu {sc:?}");
    assert_eq!(
        sg.factorisations, sc.factorisations,
        "gpu {sg:?}\ncpu {sc:?}"
    );
    assert_eq!(sg.unconverged_steps, sc.unconverged_steps);
}

/// A nitinol wire pinned at one end swinging under gravity, with internal damping, at 1 ms.
const PENDULUM: &str = r#"
[solver]
scheme = "stiff"
dt = 1e-3
precision = "f64"
mode = "inextensible"
gravity = [0.0, 0.0, -9.81]

[[rod]]
elements = 24
shape = { kind = "straight", start = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.3 }
material = { preset = "nitinol" }
damping = { bend = 1e-7, drag = 0.5 }
start = { kind = "pinned" }
"#;

#[test]
fn a_stiff_pendulum_swings_as_on_the_cpu() {
    let Some((mut cpu, mut gpu)) = gpu_stiff(PENDULUM) else {
        return;
    };
    agree(&mut cpu, &mut gpu, 4, 50, 1e-9);
    // It swung: the tip fell.
    let tip = gpu.positions(RodHandle(0))[24];
    assert!(tip[2] < -0.05, "tip {tip:?}");
}

/// Two extensible catheters side by side, each clamped at one end that turns and moves, pulled at
/// the other (pinned, moving) end, with stretch damping and a point load: every term of the
/// step (clamps, held points, loads, damping, extensible rows) and rods of different lengths in
/// one dispatch.
const CLAMPED: &str = r#"
[solver]
scheme = "stiff"
dt = 5e-4
precision = "f64"
mode = "extensible"
gravity = [0.0, -9.81, 0.0]

[[rod]]
elements = 30
shape = { kind = "straight", start = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.2 }
material = { preset = "catheter-polymer" }
damping = { bend = 1e-5, stretch = 1e-3 }
start = { kind = "clamped", angular_velocity = [3.0, 0.0, 1.0], end_time = 0.05 }
end = { kind = "pinned", velocity = [0.0, 0.0, 0.1], end_time = 0.05 }
load = [{ point = 15, force = [0.0, 0.0, 0.02] }]

[[rod]]
elements = 17
shape = { kind = "straight", start = [0.0, 0.05, 0.0], direction = [1.0, 0.0, 0.0], length = 0.15 }
material = { preset = "catheter-polymer" }
start = { kind = "clamped", velocity = [0.0, 0.0, -0.05], end_time = 0.05 }
"#;

#[test]
fn clamped_driven_loaded_rods_move_as_on_the_cpu() {
    let Some((mut cpu, mut gpu)) = gpu_stiff(CLAMPED) else {
        return;
    };
    agree(&mut cpu, &mut gpu, 3, 40, 1e-9);
}
