//! Several obstacles in one scene (`[[obstacles]]`, `SimulationBuilder::obstacle`): analytic
//! half-spaces and infinite cylinders, meshes of their own friction, and shapes moving along a
//! path, checked against what mechanics says independently of the code: a rope resting on a
//! plane carries its weight one radius above it, a rope on an incline sticks or slides as
//! `tan θ` compares with `μ`, a moving floor lifts a rope at its speed and drags one at `μ g`.
//! (The capstan ratio on the analytic cylinder: `tests/solid_obstacles.rs`.)

use cosserat::cosserat_model::Material;
use cosserat::obstacles::Side;
use cosserat::{
    Backend, ContactSample, EndPath, Environment, Obstacle, RodBuilder, RodHandle,
    SimulationBuilder, StateField, StiffSettings,
};

const R: f64 = 1e-3;
const G: f64 = 9.81;

fn material() -> Material {
    Material::new(3e5, 1e5, 1000.0, R)
}

/// A rope along x from `start`.
fn rope(start: [f64; 3], length: f64, elements: usize) -> RodBuilder {
    RodBuilder::straight(start, [1.0, 0.0, 0.0], length, elements, material())
}

/// Mass per length of the rope [kg/m].
fn line_density() -> f64 {
    1000.0 * std::f64::consts::PI * R * R
}

fn positions(sim: &cosserat::Simulation, h: RodHandle) -> Vec<[f64; 3]> {
    let n = sim.positions(h).len();
    let mut x = vec![[0.0; 3]; n];
    sim.read(h, StateField::Positions, &mut x).unwrap();
    x
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    v.iter().sum::<f64>() / v.len() as f64
}

/// A rope dropped on a half-space comes to rest one radius above the plane, and the plane's
/// forces on it add up to its weight.
#[test]
fn a_rope_on_a_half_space_rests_one_radius_above_it_and_carries_its_weight() {
    let length = 0.2;
    let rod = RodBuilder::straight(
        [-0.1, 0.0, R + 2e-3],
        [1.0, 0.0, 0.0],
        length,
        40,
        material(),
    )
    .damping(0.0, 0.0, 20.0);
    let floor = Obstacle::half_space([0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(5e-5)
        .obstacle(floor)
        .with_rod(rod)
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    sim.run(10_000).unwrap();
    let x = positions(&sim, h);
    for p in &x {
        assert!((p[2] - R).abs() < 0.05 * R, "a point rests at {} m", p[2]);
    }
    let mut samples: Vec<ContactSample> = Vec::new();
    sim.contacts(h, &mut samples).unwrap();
    let lift: f64 = samples.iter().map(|s| s.force[2]).sum();
    let weight = line_density() * length * G;
    assert!(
        (lift - weight).abs() < 0.02 * weight,
        "the floor carries {lift} N of a weight of {weight} N"
    );
    let report = sim.contact_report().unwrap();
    assert_eq!(report.contacts, 41);
    assert_eq!(sim.check_lumen().unwrap().count, 0);
}

/// A rope dropped across a frictionless infinite cylinder rests where it rests on a finely
/// meshed one (without friction, where a rope comes to rest does not depend on how it got
/// there).
#[test]
fn a_rope_rests_on_an_infinite_cylinder_as_on_a_meshed_one() {
    let rest = |obstacle: Obstacle| {
        let rod = rope([-0.1, 0.0, 0.06], 0.2, 40).damping(0.0, 0.0, 20.0);
        let mut sim = SimulationBuilder::new()
            .double_precision(true)
            .dt(5e-5)
            .obstacle(obstacle)
            .with_rod(rod)
            .build()
            .unwrap();
        let h = sim.rods().next().unwrap();
        sim.run(8_000).unwrap();
        assert_eq!(sim.check_lumen().unwrap().count, 0);
        positions(&sim, h)
    };
    let exact = rest(
        Obstacle::cylinder([0.0; 3], [0.0, 1.0, 0.0], 0.05, Side::Solid)
            .unwrap()
            .friction(0.0, 0.0),
    );
    let meshed = rest(
        Obstacle::mesh(Environment::cylinder([0.0; 3], [0.0, 1.0, 0.0], 0.05, 0.2, 256).unwrap())
            .friction(0.0, 0.0),
    );
    // Where the rope wraps the cylinder (its ends still swing), it rests about a radius above
    // the round surface (its points, joined by chords, leave it where it lifts off), and within 0.15 of a radius of where it rests on the mesh (whose
    // ridges hold it up to 0.1 R higher).
    let mut wrapped = 0;
    for (a, b) in exact.iter().zip(&meshed).filter(|(a, _)| a[2] > 0.01) {
        let above = (a[0] * a[0] + a[2] * a[2]).sqrt() - 0.05;
        assert!(
            (above - R).abs() < 0.1 * R,
            "a point rests {above} m above the cylinder"
        );
        let apart = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
        assert!(apart < 0.15 * R, "the ropes are {apart} m apart at {a:?}");
        wrapped += 1;
    }
    assert!(wrapped > 15, "only {wrapped} points on the cylinder");
    // The middle, at the top, exactly a radius above it.
    assert!(
        (exact[20][2] - 0.05 - R).abs() < 0.01 * R,
        "{:?}",
        exact[20]
    );
}

/// Two ropes on two boxes of different friction under gravity tilted by `θ` from the boxes'
/// normal (an incline): the rope on the box with `μ > tan θ` stays, the one with `μ < tan θ`
/// slides at `g (sin θ − μ cos θ)`. Returns each rope's displacement down the incline after
/// `seconds`.
fn incline(stiff: bool, seconds: f64) -> [f64; 2] {
    let tan = 0.3_f64;
    let theta = tan.atan();
    let boxes = [(-0.05, 0.33), (0.05, 0.27)].map(|(y, mu)| {
        Obstacle::mesh(Environment::cuboid([0.0, y, -0.05], [1.0, 0.05, 0.1], [0.0; 3]).unwrap())
            .friction(mu, mu)
    });
    let dt = if stiff { 1e-3 } else { 5e-5 };
    let mut b = SimulationBuilder::new()
        .double_precision(true)
        .dt(dt)
        .gravity([G * theta.sin(), 0.0, -G * theta.cos()])
        .stiff_solver(stiff.then(StiffSettings::default));
    for [_, y] in [[0.0, -0.05], [0.0, 0.05]] {
        b = b.with_rod(rope([-0.05, y, R], 0.1, 10));
    }
    for o in boxes {
        b = b.obstacle(o);
    }
    let mut sim = b.build().unwrap();
    let handles: Vec<RodHandle> = sim.rods().collect();
    let start: Vec<f64> = handles.iter().map(|&h| positions(&sim, h)[5][0]).collect();
    sim.run((seconds / dt).round() as u64).unwrap();
    assert_eq!(sim.check_lumen().unwrap().count, 0);
    [0, 1].map(|k| positions(&sim, handles[k])[5][0] - start[k])
}

fn check_incline(stiff: bool) {
    let t = 0.2;
    let [held, slid] = incline(stiff, t);
    let theta = 0.3_f64.atan();
    let expected = 0.5 * G * (theta.sin() - 0.27 * theta.cos()) * t * t;
    assert!(
        held.abs() < 1e-4,
        "the rope on μ = 0.33 > tan θ moved {held} m"
    );
    assert!(
        (slid - expected).abs() < 0.05 * expected,
        "the rope on μ = 0.27 < tan θ slid {slid} m, expected {expected} m"
    );
}

#[test]
fn each_obstacle_has_its_own_friction_on_an_incline() {
    check_incline(false);
}

#[test]
fn each_obstacle_has_its_own_friction_on_an_incline_with_the_stiff_scheme() {
    check_incline(true);
}

/// A rope dropped across a box and an infinite cylinder side by side rests on both, sagging
/// between them, no point inside either.
#[test]
fn a_rope_drapes_over_two_solids() {
    let rod = rope([-0.1, 0.0, R + 1e-3], 0.2, 40).damping(0.0, 0.0, 20.0);
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(5e-5)
        .obstacle(
            Obstacle::mesh(
                Environment::cuboid([-0.065, 0.0, -0.05], [0.07, 0.1, 0.1], [0.0; 3]).unwrap(),
            )
            .friction(0.5, 0.5),
        )
        .obstacle(
            Obstacle::cylinder([0.065, 0.0, -0.035], [0.0, 1.0, 0.0], 0.035, Side::Solid)
                .unwrap()
                .friction(0.5, 0.5),
        )
        .with_rod(rod)
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    sim.run(8_000).unwrap();
    let x = positions(&sim, h);
    assert_eq!(sim.check_lumen().unwrap().count, 0);
    // On the box's top and the cylinder's top, a radius above them; sagging between.
    assert!((x[8][2] - R).abs() < 0.1 * R, "over the box: {:?}", x[8]);
    let above_cylinder = ((x[32][0] - 0.065).powi(2) + (x[32][2] + 0.035).powi(2)).sqrt() - 0.035;
    assert!(
        (above_cylinder - R).abs() < 0.1 * R,
        "over the cylinder: {:?}",
        x[32]
    );
    assert!(x[20][2] < -5e-3, "the middle does not sag: {:?}", x[20]);
    let mut samples = Vec::new();
    sim.contacts(h, &mut samples).unwrap();
    assert!(samples.iter().any(|s| s.point < 20) && samples.iter().any(|s| s.point > 20));
}

/// A floor at `z = 0` moving along `path`, a 10 cm rope resting on it; friction `mu`.
fn on_moving_floor(path: EndPath, mu: f64, stiff: bool) -> (cosserat::Simulation, f64) {
    let floor = Obstacle::half_space([0.0; 3], [0.0, 0.0, 1.0])
        .unwrap()
        .friction(mu, mu)
        .following(path)
        .unwrap();
    let dt = if stiff { 1e-3 } else { 5e-5 };
    let sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(dt)
        .stiff_solver(stiff.then(StiffSettings::default))
        .obstacle(floor)
        .with_rod(rope([-0.05, 0.0, R], 0.1, 10))
        .build()
        .unwrap();
    (sim, dt)
}

/// A floor rising at 0.1 m/s from 0.1 s to 0.3 s lifts a rope resting on it with its speed.
#[test]
fn a_rising_floor_lifts_a_rope_with_its_speed() {
    for stiff in [false, true] {
        let path = EndPath::new(
            0.0,
            vec![0.0, 0.1, 0.3],
            vec![[0.0; 3], [0.0; 3], [0.0, 0.0, 0.02]],
            vec![[0.0; 3]; 3],
        )
        .unwrap();
        let (mut sim, dt) = on_moving_floor(path, 0.3, stiff);
        let h = sim.rods().next().unwrap();
        sim.run((0.25 / dt).round() as u64).unwrap();
        let z = mean(positions(&sim, h).iter().map(|p| p[2]));
        let vz = mean(sim.velocities(h).iter().map(|v| v[2]));
        assert!(
            (z - 0.015 - R).abs() < 0.1 * R,
            "stiff {stiff}: the rope is at {z} m"
        );
        assert!(
            (vz - 0.1).abs() < 0.005,
            "stiff {stiff}: it rises at {vz} m/s"
        );
        assert_eq!(sim.check_lumen().unwrap().count, 0);
    }
}

/// A floor moving along x at 0.5 m/s (a conveyor) drags a rope resting on it at `μ g` until
/// the rope moves with it.
#[test]
fn a_conveyor_drags_a_rope_at_mu_g_until_it_moves_with_it() {
    let mu = 0.3;
    for stiff in [false, true] {
        let path = EndPath::new(
            0.0,
            vec![0.0, 10.0],
            vec![[0.0; 3], [5.0, 0.0, 0.0]],
            vec![[0.0; 3]; 2],
        )
        .unwrap();
        let (mut sim, dt) = on_moving_floor(path, mu, stiff);
        let h = sim.rods().next().unwrap();
        sim.run((0.1 / dt).round() as u64).unwrap();
        let vx = mean(sim.velocities(h).iter().map(|v| v[0]));
        let expected = mu * G * 0.1;
        assert!(
            (vx - expected).abs() < 0.03 * expected,
            "stiff {stiff}: after 0.1 s the rope moves at {vx} m/s, expected {expected} m/s"
        );
        sim.run((0.2 / dt).round() as u64).unwrap();
        let vx = mean(sim.velocities(h).iter().map(|v| v[0]));
        assert!((vx - 0.5).abs() < 0.01, "stiff {stiff}: then at {vx} m/s");
    }
}

/// The GPU backend has no analytic shapes and no moving obstacles: it says so by name before
/// it looks for a device.
#[test]
fn the_gpu_refuses_shapes_by_name() {
    let e = SimulationBuilder::new()
        .backend(Backend::Gpu)
        .dt(5e-5)
        .obstacle(Obstacle::half_space([0.0; 3], [0.0, 0.0, 1.0]).unwrap())
        .with_rod(rope([0.0; 3], 0.1, 10))
        .build()
        .err()
        .expect("the GPU refused nothing");
    let e = e.to_string();
    if cfg!(feature = "gpu") {
        assert!(e.contains("several obstacles or analytic shapes"), "{e}");
    } else {
        // A build without the GPU backend refuses it before looking at the scene.
        assert!(e.contains("no GPU backend"), "{e}");
    }
}

fn scene_error(obstacle: &str) -> String {
    let text = format!(
        "[[rod]]\nshape = {{ kind = \"straight\", start = [0, 0, 0], direction = [1, 0, 0], length = 0.1 }}\nelements = 10\nmaterial = {{ young_modulus = 3e5, poisson_ratio = 0.5, density = 1000, radius = 1e-3 }}\n\n[[obstacles]]\n{obstacle}\n"
    );
    match cosserat::scene::parse_scene(std::path::Path::new("bad.toml"), &text, &[]) {
        Ok(_) => panic!("accepted: {obstacle}"),
        Err(e) => e.to_string(),
    }
}

/// Bad obstacles are refused with the file, the field and the value.
#[test]
fn bad_obstacles_name_file_field_and_value() {
    let e = scene_error("shape = { kind = \"cone\", point = [0, 0, 0] }");
    assert!(e.contains("bad.toml") && e.contains("cone"), "{e}");
    let e = scene_error(
        "shape = { kind = \"cylinder\", point = [0, 0, 0], axis = [0, 1, 0], radius = -0.1 }",
    );
    assert!(
        e.contains("bad.toml") && e.contains("obstacles[0].shape.radius") && e.contains("-0.1"),
        "{e}"
    );
    let e = scene_error("shape = { kind = \"half-space\", point = [0, 0, 0], normal = [0, 0, 0] }");
    assert!(
        e.contains("bad.toml")
            && e.contains("obstacles[0].shape.normal")
            && e.contains("[0.0, 0.0, 0.0]"),
        "{e}"
    );
    let e = scene_error(
        "shape = { kind = \"half-space\", point = [0, 0, 0], normal = [0, 0, 1] }\nside = \"lumen\"",
    );
    assert!(
        e.contains("obstacles[0].side") && e.contains("lumen"),
        "{e}"
    );
    let e = scene_error(
        "mesh = { kind = \"sphere\", center = [0, 0, 0], radius = 0.1 }\npath = { times = [0, 1], displacement = [[0, 0, 0], [0, 0, 1]] }",
    );
    assert!(
        e.contains("obstacles[0].path") && e.contains("cannot move"),
        "{e}"
    );
    let e = scene_error(
        "friction = { static = 0.1, kinetic = 0.2 }\nshape = { kind = \"half-space\", point = [0, 0, 0], normal = [0, 0, 1] }",
    );
    assert!(
        e.contains("obstacles[0].friction.kinetic") && e.contains("0.2"),
        "{e}"
    );
    let e = scene_error("side = \"solid\"");
    assert!(
        e.contains("obstacles[0]") && e.contains("neither a mesh nor a shape"),
        "{e}"
    );
}

/// What one tree over all meshes saves over a list of trees, and what a step costs with each
/// kind of obstacle (run with `cargo test --release --test obstacles -- --ignored --nocapture`;
/// figures in `docs/collide.md`).
#[test]
#[ignore = "a timing: run in release"]
fn timings_of_joined_trees_and_shapes() {
    use cosserat::cosserat_collide::MeshCollider;
    use std::time::Instant;
    // Eight spheres of about 8 000 triangles each in a row, and points near them.
    let spheres: Vec<Environment> = (0..8)
        .map(|k| Environment::sphere([0.1 * k as f64, 0.0, 0.0], 0.04, 128).unwrap())
        .collect();
    let obstacles: Vec<Obstacle> = spheres.iter().cloned().map(Obstacle::mesh).collect();
    let points: Vec<[f64; 3]> = (0..20_000)
        .map(|i| {
            let t = i as f64 * 0.618_033_988_75;
            let k = (i % 8) as f64;
            let (theta, phi) = (
                t.fract() * std::f64::consts::PI,
                (t * 7.0).fract() * std::f64::consts::TAU,
            );
            let r = 0.041 + 0.002 * (t * 13.0).fract();
            [
                0.1 * k + r * theta.sin() * phi.cos(),
                r * theta.sin() * phi.sin(),
                r * theta.cos(),
            ]
        })
        .collect();
    let joined: Vec<&MeshCollider> = {
        let settings =
            cosserat::obstacles::joined_collider(&obstacles.iter().collect::<Vec<_>>()).unwrap();
        vec![Box::leak(Box::new(settings))]
    };
    let list: Vec<&MeshCollider> = spheres.iter().map(|e| e.collider.as_ref()).collect();
    let reach = R + 2e-3;
    for (name, colliders) in [("one joined tree", &joined), ("a list of 8 trees", &list)] {
        let t0 = Instant::now();
        let mut found = 0;
        for _ in 0..5 {
            for p in &points {
                found += colliders.iter().filter_map(|c| c.nearest(p, reach)).count();
            }
        }
        let us = t0.elapsed().as_secs_f64() * 1e6 / (5.0 * points.len() as f64);
        println!("{name}: {us:.3} µs per point query ({found} hits)");
    }
    // A 200-element rope resting on: nothing, a half-space, a mesh floor, a mesh floor joined
    // with eight far spheres.
    let step_us = |obstacles: Vec<Obstacle>| {
        let mut b = SimulationBuilder::new().dt(2e-5);
        for o in obstacles {
            b = b.obstacle(o);
        }
        let rod = rope([-0.5, 0.5, R], 1.0, 200).damping(0.0, 0.0, 2.0);
        let mut sim = b.with_rod(rod).build().unwrap();
        sim.run(2_000).unwrap();
        let t0 = Instant::now();
        sim.run(10_000).unwrap();
        t0.elapsed().as_secs_f64() * 1e6 / 10_000.0
    };
    let floor =
        || Obstacle::mesh(Environment::plane([0.0, 0.5, 0.0], [0.0, 0.0, 1.0], 2.0).unwrap());
    let far = || {
        (0..8).map(|k| {
            Obstacle::mesh(Environment::sphere([0.1 * k as f64, -0.5, 0.2], 0.04, 128).unwrap())
                .friction(0.3, 0.2)
        })
    };
    let rows = [
        ("no obstacle", vec![]),
        (
            "half-space",
            vec![Obstacle::half_space([0.0; 3], [0.0, 0.0, 1.0]).unwrap()],
        ),
        (
            "moving half-space",
            vec![
                Obstacle::half_space([0.0; 3], [0.0, 0.0, 1.0])
                    .unwrap()
                    .following(
                        EndPath::new(
                            0.0,
                            vec![0.0, 100.0],
                            vec![[0.0; 3], [1.0, 0.0, 0.0]],
                            vec![[0.0; 3]; 2],
                        )
                        .unwrap(),
                    )
                    .unwrap(),
            ],
        ),
        ("mesh floor", vec![floor()]),
        (
            "mesh floor + 8 spheres (one tree)",
            std::iter::once(floor()).chain(far()).collect(),
        ),
        (
            "mesh floor + half-space + infinite cylinder",
            vec![
                floor(),
                Obstacle::half_space([0.0, 0.0, -0.01], [0.0, 0.0, 1.0]).unwrap(),
                Obstacle::cylinder([0.0, -0.5, 0.0], [1.0, 0.0, 0.0], 0.1, Side::Solid).unwrap(),
            ],
        ),
    ];
    for (name, obstacles) in rows {
        println!("{name}: {:.2} µs per step", step_us(obstacles));
    }
}

/// A floor set moving by the control call lifts the rope resting on it from where the floor
/// is; a snapshot taken before the call brings back the floor that stood still; a mesh refuses
/// to move.
#[test]
fn a_floor_set_moving_by_a_control_call_lifts_the_rope() {
    for stiff in [false, true] {
        let (mut sim, dt) = on_moving_floor(
            EndPath::new(0.0, vec![0.0, 1.0], vec![[0.0; 3]; 2], vec![[0.0; 3]; 2]).unwrap(),
            0.3,
            stiff,
        );
        let h = sim.rods().next().unwrap();
        sim.run((0.05 / dt).round() as u64).unwrap();
        let still = sim.snapshot().unwrap();
        let rise = EndPath::new(
            sim.time(),
            vec![0.0, 0.1],
            vec![[0.0; 3], [0.0, 0.0, 0.01]],
            vec![[0.0; 3]; 2],
        )
        .unwrap();
        sim.set_obstacle_path(0, Some(rise)).unwrap();
        sim.run((0.15 / dt).round() as u64).unwrap();
        let z = mean(positions(&sim, h).iter().map(|p| p[2]));
        assert!(
            (z - 0.01 - R).abs() < 0.1 * R,
            "stiff {stiff}: the rope is at {z} m"
        );
        sim.restore(&still).unwrap();
        sim.run((0.15 / dt).round() as u64).unwrap();
        let z = mean(positions(&sim, h).iter().map(|p| p[2]));
        assert!(
            (z - R).abs() < 0.1 * R,
            "stiff {stiff}: restored, the rope is at {z} m"
        );
        assert_eq!(sim.check_lumen().unwrap().count, 0);
    }
    let mut sim = SimulationBuilder::new()
        .dt(5e-5)
        .obstacle(Obstacle::mesh(
            Environment::sphere([0.0; 3], 0.05, 32).unwrap(),
        ))
        .with_rod(rope([0.0, 0.0, 0.1], 0.1, 10))
        .build()
        .unwrap();
    let e = sim.set_obstacle_path(0, None).unwrap_err().to_string();
    assert!(e.contains("meshes do not move"), "{e}");
}
