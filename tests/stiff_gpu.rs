//! The stiff scheme on the GPU (`cosserat_backend_gpu::GpuStiffSimulation`) against the CPU's
//! stiff scheme in `f64`, its oracle: the same passes in the same order, so the two agree to
//! rounding, step for step and iteration for iteration. Runs on lavapipe in CI
//! (`COSSERAT_REQUIRE_GPU=1`); without an adapter it is skipped unless required.

#[path = "support/pair.rs"]
mod pair;

use cosserat::sim::{RodHandle, Simulation};
use pair::{gpu_build, largest_gap, pair};

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

/// The contacts' statistics of both, and that they agree: the same points pinned at the end,
/// the same catches and element contacts, penetrations within `tol`.
fn contacts_agree(cpu: &Simulation, gpu: &Simulation, tol: f64) {
    for rod in 0..cpu.stepper().rod_count() {
        let c = cpu.stepper().collision_stats(rod).expect("cpu stats");
        let g = gpu.stepper().collision_stats(rod).expect("gpu stats");
        eprintln!("rod {rod}: cpu {c:?}\n        gpu {g:?}");
        assert_eq!(g.contacts, c.contacts, "rod {rod}: pinned points");
        assert_eq!(
            g.max_contacts, c.max_contacts,
            "rod {rod}: most pinned points"
        );
        assert_eq!(g.swept_catches, c.swept_catches, "rod {rod}: swept catches");
        assert_eq!(
            g.segment_contacts, c.segment_contacts,
            "rod {rod}: element contacts"
        );
        assert_eq!(
            g.escaped_points, c.escaped_points,
            "rod {rod}: escaped points"
        );
        assert!(
            (g.max_penetration - c.max_penetration).abs() < tol,
            "rod {rod}: penetration gpu {} cpu {}",
            g.max_penetration,
            c.max_penetration
        );
        // The wall's force on each point it holds.
        let (mut fc, mut fg) = (Vec::new(), Vec::new());
        cpu.stepper().contacts(rod, &mut fc).expect("cpu contacts");
        gpu.stepper().contacts(rod, &mut fg).expect("gpu contacts");
        fc.sort_by_key(|c| c.point);
        assert_eq!(fg.len(), fc.len(), "rod {rod}: contacts");
        for (a, b) in fc.iter().zip(&fg) {
            assert_eq!(a.point, b.point);
            let scale = a.force.iter().fold(1e-12, |m: f64, x| m.max(x.abs()));
            let (force, normal) = (
                largest_gap(&[a.force], &[b.force]),
                largest_gap(&[a.normal], &[b.normal]),
            );
            assert!(
                force < 1e-6 * scale && normal < 1e-9,
                "rod {rod} point {}: cpu {a:?} gpu {b:?} (force {force:e} N, normal {normal:e})",
                a.point
            );
        }
    }
}

/// The stiff scheme at 1 ms under gravity, contacts as pins and every detection a full query
/// (the GPU's way: it has no contact rows, and the CPU's reuse of a point's last query passes on
/// a bound of its gap, not the gap).
const CONTACT_SOLVER: &str = r#"
[solver]
scheme = "stiff"
dt = 1e-3
precision = "f64"
mode = "inextensible"
gravity = [0.0, 0.0, -9.81]

[solver.stiff]
reuse_contact_queries = false
contact_rows = false
"#;

/// A soft wire lying across a floor, one clamped end dragged along it at 1 ms: the points pinned
/// on the wall, static friction holding the far part and kinetic friction on the dragged part.
const FLOOR: &str = r#"
[environment]
mesh = { kind = "plane", point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0], size = 1.0 }
friction = { static = 0.4, kinetic = 0.3 }
margin = 2e-4

[[rod]]
elements = 40
shape = { kind = "straight", start = [0.0, -0.1, 0.0021], direction = [0.0, 1.0, 0.0], length = 0.2 }
material = { young_modulus = 5e6, poisson_ratio = 0.5, density = 1100.0, radius = 2e-3 }
damping = { drag = 2.0 }
start = { kind = "clamped", velocity = [0.05, 0.0, 0.0], end_time = 1.0 }
"#;

#[test]
fn a_wire_dragged_over_a_floor_moves_as_on_the_cpu() {
    let Some((mut cpu, mut gpu)) = gpu_stiff(&format!("{CONTACT_SOLVER}{FLOOR}")) else {
        return;
    };
    agree(&mut cpu, &mut gpu, 4, 25, 1e-9);
    contacts_agree(&cpu, &gpu, 1e-9);
    let s = gpu.stepper().collision_stats(0).expect("stats");
    assert!(s.contacts > 20, "the wire lies on the floor: {s:?}");
}

/// The same wire at 150 elements: each invocation's slice holds three elements (64 slices,
/// the last 14 of them padding only), where the scenes above give every slice one. Every pass
/// of the step and of the contacts loops over a slice, so this is the kernel's layout at real
/// resolutions (256 elements: four a slice; 96 in a large batch: three).
#[test]
fn a_wire_of_three_elements_a_slice_dragged_over_a_floor_moves_as_on_the_cpu() {
    let scene = format!("{CONTACT_SOLVER}{FLOOR}").replace("elements = 40", "elements = 150");
    let Some((mut cpu, mut gpu)) = gpu_stiff(&scene) else {
        return;
    };
    agree(&mut cpu, &mut gpu, 2, 20, 1e-9);
    contacts_agree(&cpu, &gpu, 1e-9);
    let s = gpu.stepper().collision_stats(0).expect("stats");
    assert!(s.contacts > 75, "the wire lies on the floor: {s:?}");
}

/// The procedural vessel, coarse (4 000 triangles), with the friction of the insertion scenes.
const VESSEL_WALL: &str = r#"
[environment]
mesh = { kind = "vessel", triangles = 4000 }
friction = { static = 0.08, kinetic = 0.05 }
margin = 1e-4
"#;

/// A soft wire pushed by its clamped end into the procedural vessel at 1 ms, without an
/// introducer, sagging onto the wall: every part of the contacts (new contacts and releases,
/// points caught by the swept test, two walls at a crease, elements on ridges, rounds of the
/// solve).
const VESSEL: &str = r#"

[[rod]]
elements = 64
shape = { kind = "insertion", length = 0.3, inserted = 0.05 }
material = { young_modulus = 5e6, poisson_ratio = 0.5, density = 6500.0, radius = 4e-4 }
damping = { drag = 5.0 }
start = { kind = "clamped", axial_speed = 0.5, end_time = 1.0 }
"#;

#[test]
fn a_wire_pushed_into_a_vessel_moves_as_on_the_cpu() {
    let Some((mut cpu, mut gpu)) = gpu_stiff(&format!("{CONTACT_SOLVER}{VESSEL_WALL}{VESSEL}"))
    else {
        return;
    };
    agree(&mut cpu, &mut gpu, 8, 25, 1e-8);
    contacts_agree(&cpu, &gpu, 1e-9);
    let s = cpu.stepper().collision_stats(0).expect("stats");
    assert!(s.max_contacts > 3, "the wire touched the wall: {s:?}");
}

/// The insertion of `scenes/nitinol-guidewire-insertion.toml`, short and coarse: a nitinol wire
/// fed through the introducer (its guided points held on the axis) into the vessel at 1 ms.
const INSERTION: &str = r#"

[[rod]]
elements = 64
shape = { kind = "insertion", length = 0.3, inserted = 0.05 }
material = { preset = "nitinol" }
damping = { drag = 5.0 }
start = { kind = "clamped", axial_speed = 0.5, end_time = 1.0, guide = 0.24 }
"#;

#[test]
fn a_wire_fed_through_the_introducer_moves_as_on_the_cpu() {
    let Some((mut cpu, mut gpu)) = gpu_stiff(&format!("{CONTACT_SOLVER}{VESSEL_WALL}{INSERTION}"))
    else {
        return;
    };
    let hand = gpu.positions(RodHandle(0))[0];
    agree(&mut cpu, &mut gpu, 8, 25, 1e-8);
    contacts_agree(&cpu, &gpu, 1e-9);
    // The hand pushed 0.5 m/s for 0.2 s.
    let moved = largest_gap(&[hand], &[gpu.positions(RodHandle(0))[0]]);
    assert!((moved - 0.1).abs() < 1e-9, "the hand moved {moved} m");
}

/// A rod longer than the kernel's slices hold is refused with its length and the limit, not
/// left to fail in the driver's compiler (the partitioned solve's private arrays hold 16
/// elements an invocation in `f64`; 64 invocations: 1 024 elements).
#[test]
fn a_rod_too_long_for_the_kernels_slices_is_refused_by_name() {
    let scene = PENDULUM.replace("elements = 24", "elements = 1100");
    let Some(built) = gpu_build(&scene, &[]) else {
        return;
    };
    let Err(e) = built else {
        panic!("a rod of 1100 elements was accepted");
    };
    assert!(
        e.contains("1100 elements") && e.contains("up to 1024 elements"),
        "{e}"
    );
}
