//! Mesh contact and the introducer guide on the GPU, against the CPU explicit scheme in the same
//! precision and sweep order (its oracle): a rope dragged over a floor with friction, a rope held
//! or sliding on an incline (also against Coulomb's law), and a wire pushed through an introducer
//! into a vessel. Runs on lavapipe in CI (`COSSERAT_REQUIRE_GPU=1`); without an adapter it is
//! skipped unless required.

#[path = "support/pair.rs"]
mod pair;

use cosserat::sim::{RodHandle, Simulation};
use pair::{largest_gap, pair};
use std::path::Path;

/// A rope lying across a floor, one end dragged along it: every point touches, the dragged
/// part slides (kinetic friction), the far part sticks until the tension reaches it.
const FLOOR: &str = r#"
[solver]
dt = 2e-5
iterations = 10
mode = "inextensible"
ordering = "red-black"
precision = "f32"

[environment]
mesh = { kind = "plane", point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0], size = 1.0 }
friction = { static = 0.4, kinetic = 0.3 }
margin = 2e-4

[[rod]]
elements = 40
shape = { kind = "straight", start = [0.0, -0.1, 0.0025], direction = [0.0, 1.0, 0.0], length = 0.2 }
material = { young_modulus = 5e6, poisson_ratio = 0.5, density = 1100.0, radius = 2e-3 }
damping = { drag = 2.0 }
start = { kind = "pinned", velocity = [0.05, 0.0, 0.0], end_time = 1.0 }
"#;

#[test]
fn a_rope_dragged_over_a_floor_moves_as_on_the_cpu() {
    let Some((mut cpu, mut gpu)) = pair(FLOOR, &[]) else {
        return;
    };
    let h = RodHandle(0);
    // 0.1 s in batches, as a user reading the state now and then would.
    for _ in 0..10 {
        cpu.run(500).unwrap_or_else(|e| panic!("cpu: {e}"));
        gpu.run(500).unwrap_or_else(|e| panic!("gpu: {e}"));
    }
    let (c, g) = (cpu.positions(h), gpu.positions(h));
    // The rope settled on the floor and was dragged: its start moved 5 mm.
    assert!((c[0][0] - 0.005).abs() < 1e-6, "cpu start {:?}", c[0]);
    let gap = largest_gap(&c, &g);
    assert!(gap < 2e-5, "GPU and CPU differ by {gap:e} m");
    let (cs, gs) = (
        cpu.stepper().collision_stats(0).expect("cpu stats"),
        gpu.stepper().collision_stats(0).expect("gpu stats"),
    );
    // The rope lies on the floor, on both.
    assert!(cs.contacts > 30, "cpu {cs:?}");
    assert!(
        gs.contacts.abs_diff(cs.contacts) <= 1,
        "gpu {gs:?} cpu {cs:?}"
    );
    assert_eq!(gs.escaped_points, 0, "gpu {gs:?}");
    assert_eq!(gs.steps, cs.steps, "gpu {gs:?} cpu {cs:?}");
    assert!(
        (gs.max_penetration - cs.max_penetration).abs() < 2e-6,
        "penetration gpu {gs:?} cpu {cs:?}"
    );
    // The forces the floor gives the points: the rope's weight, and friction against the drag.
    let (mut fc, mut fg) = (Vec::new(), Vec::new());
    cpu.contacts(h, &mut fc).expect("cpu contacts");
    gpu.contacts(h, &mut fg).expect("gpu contacts");
    assert_eq!(fc.len(), fg.len());
    let total = |f: &[cosserat::ContactSample]| {
        f.iter().fold([0.0; 3], |s, c| {
            [s[0] + c.force[0], s[1] + c.force[1], s[2] + c.force[2]]
        })
    };
    let (tc, tg) = (total(&fc), total(&fg));
    let weight = 0.2 * std::f64::consts::PI * 2e-3f64.powi(2) * 1100.0 * 9.81;
    assert!(tc[2] > 0.5 * weight, "cpu {tc:?}, weight {weight}");
    for k in 0..3 {
        assert!(
            (tg[k] - tc[k]).abs() < 0.02 * weight,
            "force {k}: gpu {tg:?} cpu {tc:?}"
        );
    }
}

/// The insertion scene, short: a wire pushed through an introducer into the procedural vessel,
/// 9 cm of it inside and falling onto the wall, its elements meeting ridges of the wall there.
#[test]
fn a_wire_pushed_through_the_introducer_into_a_vessel_follows_the_cpu() {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/guidewire-insertion.toml"),
    )
    .expect("the insertion scene");
    let Some((mut cpu, mut gpu)) = pair(
        &text,
        &[
            ("rod.0.elements", "96"),
            ("environment.mesh.triangles", "4000"),
            ("rod.0.shape.inserted", "0.09"),
            ("rod.0.start.guide", "0.41"),
            ("solver.gravity", "[40.0, -70.0, 50.0]"),
        ],
    ) else {
        return;
    };
    let h = RodHandle(0);
    for _ in 0..8 {
        cpu.run(1000).unwrap_or_else(|e| panic!("cpu: {e}"));
        gpu.run(1000).unwrap_or_else(|e| panic!("gpu: {e}"));
    }
    let (c, g) = (cpu.positions(h), gpu.positions(h));
    let gap = largest_gap(&c, &g);
    // The wire falls onto the wall at about 2 m/s (gravity raised to 100 m/s² so that it does
    // within the test's 28 ms); the impact amplifies f32 rounding in a different order.
    assert!(gap < 2e-4, "GPU and CPU differ by {gap:e} m");
    let (cs, gs) = (
        cpu.stepper().collision_stats(0).expect("cpu stats"),
        gpu.stepper().collision_stats(0).expect("gpu stats"),
    );
    assert_eq!(gs.escaped_points, 0, "gpu {gs:?}");
    assert_eq!(cs.escaped_points, 0, "cpu {cs:?}");
    assert!(
        cs.max_contacts > 5,
        "the wire barely touched the wall: {cs:?}"
    );
    assert!(cs.segment_contacts > 0, "no ridge contact: {cs:?}");
    assert!(
        gs.contacts.abs_diff(cs.contacts) <= 2 && gs.max_contacts.abs_diff(cs.max_contacts) <= 2,
        "contacts gpu {gs:?} cpu {cs:?}"
    );
    assert!(
        gs.segment_contacts.abs_diff(cs.segment_contacts) <= 2,
        "ridge contacts gpu {gs:?} cpu {cs:?}"
    );
    assert!(
        (gs.max_penetration - cs.max_penetration).abs() < 1e-6,
        "penetration gpu {gs:?} cpu {cs:?}"
    );
}

/// A soft wire bound inside a stiffer catheter whose clamp turns (constraints `binding.rs`;
/// the paper's section 3.4): the catheter sweeps sideways and bends under gravity, the wire,
/// pinned 4.5 cm behind the catheter's hub and reaching past its tip, is held on its
/// centreline in between. The wire's points lie halfway between the catheter's: a point on a
/// joint of the catheter is as near to the segment before it as to the one after it, and
/// which of the two it binds to (whose tangents differ once the catheter bends) is decided by
/// rounding, differently in f32 and f64 (measured: a 6e-5 m gap after 500 steps).
const BOUND: &str = r#"
[solver]
dt = 1e-5
iterations = 10
mode = "inextensible"
ordering = "red-black"
precision = "f32"

[[rod]]
name = "catheter"
elements = 30
shape = { kind = "straight", start = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.3 }
material = { young_modulus = 1e7, density = 1100.0, radius = 2e-3 }
start = { kind = "clamped", angular_velocity = [0.0, 0.0, 3.0] }
damping = { drag = 5.0 }

[[rod]]
name = "wire"
elements = 40
shape = { kind = "straight", start = [-0.045, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.4 }
material = { young_modulus = 1e6, density = 1100.0, radius = 5e-4 }
start = { kind = "pinned" }
damping = { drag = 5.0 }

[[binding]]
inner = 1
outer = 0
variant = "two-way"
"#;

/// Bindings on the GPU follow the CPU's coupled explicit scheme (the same constraints; the GPU
/// sweeps the bound points in one Jacobi pass per iteration where the CPU goes point by point):
/// in both variants the wire's gap between the backends is under 2e-4 of how far the binding
/// moves it (measured: 2.9e-7 m one-way, 3.7e-7 m two-way, of 7.5e-3 m after 4 000 steps), and the catheter is moved by
/// the wire only in the two-way variant.
#[test]
fn a_wire_bound_in_a_turning_catheter_follows_the_cpu() {
    let steps = 4000;
    let mut runs = Vec::new();
    for variant in ["none", "one-way", "two-way"] {
        let quoted = format!("\"{variant}\"");
        let Some((mut cpu, mut gpu)) = pair(BOUND, &[("binding.0.variant", quoted.as_str())])
        else {
            return;
        };
        cpu.run(steps)
            .unwrap_or_else(|e| panic!("cpu {variant}: {e}"));
        gpu.run(steps)
            .unwrap_or_else(|e| panic!("gpu {variant}: {e}"));
        let rods = |s: &Simulation| [s.positions(RodHandle(0)), s.positions(RodHandle(1))];
        runs.push((variant, rods(&cpu), rods(&gpu)));
    }
    let [(_, free, free_gpu), (_, one, one_gpu), (_, two, two_gpu)] = &runs[..] else {
        unreachable!("three variants")
    };
    // Without a binding the backends agree as for free rods.
    assert!(largest_gap(&free[1], &free_gpu[1]) < 1e-5);
    for (name, cpu, gpu) in [("one-way", one, one_gpu), ("two-way", two, two_gpu)] {
        let effect = largest_gap(&cpu[1], &free[1]);
        let gap = largest_gap(&cpu[1], &gpu[1]);
        eprintln!("{name}: the binding moves the wire {effect:.3e} m, GPU against CPU {gap:.3e} m");
        assert!(
            effect > 5e-3,
            "{name}: the binding should hold the wire ({effect} m)"
        );
        assert!(
            gap < 2e-4 * effect,
            "{name}: GPU {gap} m from the CPU, effect {effect} m"
        );
        let catheter = largest_gap(&cpu[0], &gpu[0]);
        assert!(catheter < 2e-4 * effect, "{name}: catheter {catheter} m");
    }
    // One-way: the catheter moves as if alone; two-way: the wire pulls it.
    assert_eq!(largest_gap(&one[0], &free[0]), 0.0);
    assert_eq!(largest_gap(&one_gpu[0], &free_gpu[0]), 0.0);
    assert!(largest_gap(&two[0], &free[0]) > 1e-5);
    assert!(largest_gap(&two_gpu[0], &free_gpu[0]) > 1e-5);
}

/// The hand force of a bound pair includes what the binding does to the held ends, as on the
/// CPU (`KinematicImpulses`): the catheter's clamped hub takes the shares of the wire points
/// bound to its first segment, and the wire, pinned here inside the catheter's first segment,
/// takes its binding's push at its held point. Both held ends' forces agree with the CPU's to
/// within 2e-3 of the largest of them (measured: 4e-5 N of 0.24 N); leaving the binding out of
/// them was off by half the hub's force and all of the wire's.
#[test]
fn held_ends_of_a_bound_pair_feel_the_binding_as_on_the_cpu() {
    let Some((mut cpu, mut gpu)) = pair(
        BOUND,
        &[(
            "rod.1.shape",
            "{ kind = \"straight\", start = [0.005, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.4 }",
        )],
    ) else {
        return;
    };
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    for _ in 0..8 {
        cpu.run(250).unwrap();
        gpu.run(250).unwrap();
        for (rod, end) in [(0, 0), (1, 0)] {
            let c = cpu.end_reaction(RodHandle(rod), end).unwrap().force;
            let g = gpu.end_reaction(RodHandle(rod), end).unwrap().force;
            let d = (0..3).map(|k| (c[k] - g[k]).abs()).fold(0.0, f64::max);
            let size = c.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            worst = worst.max(d);
            largest = largest.max(size);
        }
    }
    assert!(largest > 1e-4, "the held ends carry only {largest} N");
    assert!(
        worst < 2e-3 * largest,
        "held-end forces differ by {worst} N (largest {largest} N)"
    );
}

/// Bound pairs in a batch: every copy's pair shares a workgroup of its own and steps exactly as
/// the scene alone, and a snapshot (with where each bound point was last found) repeats its
/// steps bit for bit.
#[test]
fn bound_pairs_in_a_batch_step_as_the_scene_alone_and_restore_exactly() {
    let Some((_, mut alone)) = pair(BOUND, &[]) else {
        return;
    };
    let Some((_, mut batch)) = pair(BOUND, &[("batch.copies", "3")]) else {
        return;
    };
    alone.run(300).expect("alone");
    batch.run(300).expect("batch");
    for copy in 0..3 {
        for rod in 0..2 {
            assert_eq!(
                batch.positions(RodHandle(2 * copy + rod)),
                alone.positions(RodHandle(rod)),
                "copy {copy}, rod {rod}"
            );
        }
    }
    let snap = batch.snapshot().expect("snapshot");
    batch.run(200).expect("on");
    let after: Vec<_> = (0..6).map(|r| batch.positions(RodHandle(r))).collect();
    batch.restore(&snap).expect("restore");
    batch.run(200).expect("again");
    for (r, want) in after.iter().enumerate() {
        assert_eq!(&batch.positions(RodHandle(r)), want, "rod {r}");
    }
}

/// The paper's knot (`scenes/fishermans-knot.toml`: two strands of 256 elements in a loose
/// double fisherman's knot, self- and rod–rod contact with friction) as its tails start to be
/// pulled: the GPU finds the contacts the CPU finds and keeps every pair of segments 99 % of
/// their radii apart, and the strands move as on the CPU to within 10 % of the tails' travel
/// (measured on lavapipe: 3.7e-2; the GPU resolves contacts sharing points together, the CPU
/// one after another: `crates/backend-gpu/tests/rod_contact.rs`). 600 steps: lavapipe takes
/// ~15 ms a step here.
#[test]
fn the_fishermans_knot_tightens_on_the_gpu_as_on_the_cpu() {
    let text = std::fs::read_to_string("scenes/fishermans-knot.toml").expect("the knot scene");
    let Some((mut cpu, mut gpu)) = pair(&text, &[]) else {
        return;
    };
    let steps = 600;
    cpu.run(steps).unwrap_or_else(|e| panic!("cpu: {e}"));
    gpu.run(steps).unwrap_or_else(|e| panic!("gpu: {e}"));
    let travel = 0.1 * 1e-5 * steps as f64;
    for r in 0..2 {
        let gap = largest_gap(&cpu.positions(RodHandle(r)), &gpu.positions(RodHandle(r)));
        eprintln!(
            "strand {r}: GPU against CPU {gap:.3e} m ({:.2e} of the travel)",
            gap / travel
        );
        assert!(gap < 0.1 * travel, "strand {r}: {gap} m");
    }
    let (c, g) = (
        cpu.coupling_stats().expect("cpu stats"),
        gpu.coupling_stats().expect("gpu stats"),
    );
    eprintln!("cpu {c:?}\ngpu {g:?}");
    assert!(c.max_contacts > 50, "cpu {c:?}");
    assert!(
        g.max_contacts.abs_diff(c.max_contacts) <= c.max_contacts / 20,
        "gpu {g:?} cpu {c:?}"
    );
    assert_eq!(g.steps, c.steps);
    assert_eq!(g.min_separation_radii, c.min_separation_radii);
    assert!(g.min_separation_ratio >= 0.99 && c.min_separation_ratio >= 0.99);
}

/// A rod pressed down onto another right beside the other's held end: half of each contact's
/// push lands on the held point, and the holder's force (what a haptic device would feel)
/// includes it on the GPU as on the CPU, to within 1e-2 of the largest force (measured on
/// lavapipe: 6.6e-4 of 0.46 N; the two solvers share the push among the crossing's contacts
/// differently, see `crates/backend-gpu/tests/rod_contact.rs`).
#[test]
fn a_held_end_feels_a_rod_pressed_onto_it_as_on_the_cpu() {
    const PRESSED: &str = r#"
[solver]
dt = 1e-5
iterations = 10
mode = "inextensible"
ordering = "red-black"
precision = "f32"
gravity = [0.0, 0.0, 0.0]

[rod_contact]
friction = { static = 0.4, kinetic = 0.3 }
margin = 2e-4

[[rod]]
name = "bar"
elements = 25
shape = { kind = "straight", start = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.05 }
material = { young_modulus = 1e6, poisson_ratio = 0.5, density = 1100.0, radius = 1e-3 }
damping = { drag = 10.0 }
start = { kind = "pinned" }
end = { kind = "pinned" }

[[rod]]
name = "presser"
elements = 24
shape = { kind = "straight", start = [1e-3, -0.024, 2.4e-3], direction = [0.0, 1.0, 0.0], length = 0.048 }
material = { young_modulus = 1e6, poisson_ratio = 0.5, density = 1100.0, radius = 1e-3 }
damping = { drag = 10.0 }
start = { kind = "pinned", velocity = [0.0, 0.0, -0.1] }
end = { kind = "pinned", velocity = [0.0, 0.0, -0.1] }
"#;
    let Some((mut cpu, mut gpu)) = pair(PRESSED, &[]) else {
        return;
    };
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    for _ in 0..8 {
        cpu.run(250).unwrap();
        gpu.run(250).unwrap();
        let c = cpu.end_reaction(RodHandle(0), 0).unwrap().force;
        let g = gpu.end_reaction(RodHandle(0), 0).unwrap().force;
        let d = (0..3).map(|k| (c[k] - g[k]).abs()).fold(0.0, f64::max);
        worst = worst.max(d);
        largest = largest.max(c.iter().fold(0.0f64, |m, x| m.max(x.abs())));
        eprintln!("held end: cpu {c:?} gpu {g:?}");
    }
    eprintln!(
        "worst {worst:.3e} N of {largest:.3e} N ({:.2e})",
        worst / largest
    );
    assert!(largest > 1e-3, "the held end carries only {largest} N");
    assert!(
        worst < 1e-2 * largest,
        "held-end forces differ by {worst} N (largest {largest} N)"
    );
}

/// A free rope laid across an incline of slope `tan_theta` (friction 0.4 static, 0.3 kinetic),
/// let go from rest; returns the CPU and GPU runs after `steps` steps of 2e-5 s, and the unit
/// vector down the slope.
fn on_an_incline(tan_theta: f64, steps: u64) -> Option<(Simulation, Simulation, [f64; 3])> {
    let theta = tan_theta.atan();
    let (s, c) = theta.sin_cos();
    let r = 2e-3;
    let scene = format!(
        r#"
[solver]
dt = 5e-5
iterations = 10
mode = "inextensible"
ordering = "red-black"
precision = "f32"

[environment]
mesh = {{ kind = "plane", point = [0.0, 0.0, 0.0], normal = [0.0, {ny}, {nz}], size = 1.0 }}
friction = {{ static = 0.4, kinetic = 0.3 }}
margin = 2e-4

[[rod]]
elements = 10
shape = {{ kind = "straight", start = [-0.05, {y0}, {z0}], direction = [1.0, 0.0, 0.0], length = 0.1 }}
material = {{ young_modulus = 1e6, poisson_ratio = 0.5, density = 1100.0, radius = {r} }}
"#,
        ny = -s,
        nz = c,
        y0 = -s * r,
        z0 = c * r,
    );
    let (mut cpu, mut gpu) = pair(&scene, &[])?;
    for sim in [&mut cpu, &mut gpu] {
        sim.run(steps).unwrap_or_else(|e| panic!("{e}"));
    }
    Some((cpu, gpu, [0.0, -c, -s]))
}

/// How far the rope's centre moved down the slope `down` from where it was laid.
fn slid(sim: &Simulation, down: [f64; 3]) -> f64 {
    let p = sim.positions(RodHandle(0));
    let n = p.len() as f64;
    // Laid with its centre on the slope's line through the origin (at the radius above it).
    let centre: Vec<f64> = (0..3)
        .map(|k| p.iter().map(|q| q[k]).sum::<f64>() / n)
        .collect();
    (0..3).map(|k| centre[k] * down[k]).sum::<f64>()
}

#[test]
fn a_rope_on_an_incline_sticks_below_the_friction_angle_and_slides_above_it_as_coulomb_says() {
    const STEPS: u64 = 2000;
    let t = STEPS as f64 * 5e-5;
    // Below the friction angle (tan θ = 0.3 < μs = 0.4): static friction holds the rope. It
    // settles into the contact over the first steps (micrometres, f32), then does not move.
    let Some((mut cpu, mut gpu, down)) = on_an_incline(0.3, STEPS) else {
        return;
    };
    let (c, g) = (slid(&cpu, down), slid(&gpu, down));
    for sim in [&mut cpu, &mut gpu] {
        sim.run(STEPS).unwrap_or_else(|e| panic!("{e}"));
    }
    let (c2, g2) = (slid(&cpu, down), slid(&gpu, down));
    eprintln!("held: gpu {g:e} then {g2:e} m, cpu {c:e} then {c2:e} m");
    assert!(
        g.abs() < 5e-6,
        "gpu slid {g:e} m down a slope it should hold on"
    );
    assert!(
        (g2 - g).abs() < 1e-8,
        "gpu crept {:e} m in the second 0.1 s",
        g2 - g
    );
    assert!(
        (c2 - c).abs() < 1e-8,
        "cpu crept {:e} m in the second 0.1 s",
        c2 - c
    );
    // Above it (tan θ = 0.6): the rope slides with a = g (sin θ − μk cos θ), its centre by
    // ½ a t² (1 + h/t) as a constant acceleration integrates in steps of h (`tests/validation.rs`).
    let Some((cpu, gpu, down)) = on_an_incline(0.6, STEPS) else {
        return;
    };
    let theta = 0.6f64.atan();
    let a = 9.81 * (theta.sin() - 0.3 * theta.cos());
    let expected = 0.5 * a * t * t * (1.0 + 5e-5 / t);
    let (c, g) = (slid(&cpu, down), slid(&gpu, down));
    eprintln!("slid: gpu {g:e} m, cpu {c:e} m, Coulomb {expected:e} m");
    assert!(
        (g - expected).abs() < 1e-3 * expected,
        "gpu slid {g:e} m, Coulomb {expected:e} m"
    );
    assert!((g - c).abs() < 1e-4 * expected, "gpu {g:e} m, cpu {c:e} m");
    let gap = largest_gap(&cpu.positions(RodHandle(0)), &gpu.positions(RodHandle(0)));
    assert!(gap < 1e-4 * expected, "GPU and CPU differ by {gap:e} m");
}
