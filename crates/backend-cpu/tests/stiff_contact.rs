//! The stiff scheme against static meshes at haptic steps (1 ms): the same cases as
//! `contact.rs` for the explicit scheme (resting contact, Coulomb friction on an incline
//! against its analytic motion, a wire pushed into a wall), and a stiff guidewire on a floor.

use cosserat_backend_cpu::stiff::STICK_SPEED;
use cosserat_backend_cpu::{
    CpuRod, EndCondition, Ordering, SolverSettings, StiffScratch, StiffSettings, step_rod_stiff,
};
use cosserat_collide::{MeshCollider, TriMesh};
use cosserat_model::presets::preset;
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Vec3};
use std::sync::Arc;

#[allow(dead_code, unreachable_pub)]
mod support;
use support::{contact, soft, square, wire_pushed_at_a_wall};

fn rod_along(
    material: Material,
    start: Vec3<f64>,
    dir: Vec3<f64>,
    length: f64,
    n: usize,
    ends: [EndCondition<f64>; 2],
) -> CpuRod<f64> {
    let spec = RodSpec::new(material);
    let (state, params) = build_rod::<f64>(
        &straight_polyline(start.into(), dir.into(), length, n),
        &spec,
    )
    .unwrap();
    CpuRod::new(state, params, ends, vec![])
}

fn settings(dt: f64, gravity: Vec3<f64>) -> SolverSettings<f64> {
    SolverSettings {
        dt,
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible: false,
        gravity,
        divergence_strain: 0.05,
    }
}

/// Steps `rod` `steps` times from `time` with a fresh scratch per call sequence.
fn run(
    rod: &mut CpuRod<f64>,
    s: &SolverSettings<f64>,
    sc: &mut StiffScratch,
    time: f64,
    steps: u64,
) {
    step_rod_stiff(rod, s, &StiffSettings::default(), sc, time, 0, 0, steps).unwrap();
}

fn lowest(rod: &CpuRod<f64>) -> f64 {
    rod.state
        .positions
        .iter()
        .map(|p| p.z)
        .fold(f64::MAX, f64::min)
}

fn centre_of_mass(rod: &CpuRod<f64>) -> Vec3<f64> {
    let p = &rod.state.positions;
    p.iter().sum::<Vec3<f64>>() / p.len() as f64
}

fn fastest(rod: &CpuRod<f64>) -> f64 {
    rod.state
        .velocities
        .iter()
        .map(|v| v.norm())
        .fold(0.0, f64::max)
}

/// Dropped from 5 mm onto a plane at dt 1 ms: lands, never sinks into it and comes to rest
/// one radius above it; a nitinol guidewire (E 50 GPa, r 0.18 mm, 2 mm elements) as well as
/// the soft rod of the explicit scheme's test.
#[test]
fn a_rod_dropped_on_a_plane_rests_on_it_at_a_millisecond() {
    let nitinol = preset("nitinol").unwrap().material();
    for (material, length, n) in [(soft(2e-3), 0.2, 20), (nitinol, 0.2, 100)] {
        let r = material.radius;
        let plane = square(Vec3::zeros(), Vec3::x(), Vec3::y(), 1.0);
        let free = [EndCondition::free(), EndCondition::free()];
        let mut rod = rod_along(
            material,
            Vec3::new(-0.1, 0.0, r + 5e-3),
            Vec3::x(),
            length,
            n,
            free,
        )
        .with_mesh(contact(plane, 0.5, 0.4));
        let s = settings(1e-3, Vec3::new(0.0, 0.0, -9.81));
        let mut sc = StiffScratch::new();
        let mut low = f64::MAX;
        for step in 0..300 {
            run(&mut rod, &s, &mut sc, step as f64 * 1e-3, 1);
            low = low.min(lowest(&rod));
        }
        let stats = rod.collision_stats().unwrap();
        assert_eq!(
            stats.contacts,
            n + 1,
            "r = {r}: every point rests on the plane"
        );
        assert!(
            low > r * (1.0 - 1e-3),
            "r = {r}: lowest centre {low} m, radius {r} m"
        );
        assert!(
            stats.max_penetration <= 1e-3 * r,
            "r = {r}: penetration after the solve {} m",
            stats.max_penetration
        );
        let speed = fastest(&rod);
        assert!(speed < 1e-6, "r = {r}: at rest, got {speed} m/s");
        let report = sc.report();
        assert_eq!(report.unconverged_steps, 0, "r = {r}: {report:?}");
    }
}

/// Slides down an incline of angle θ at dt 1 ms: the centre of mass moves as ½ a t² (1 + h/t)
/// (implicit Euler of a constant acceleration) with a = g (sin θ − μk cos θ) when
/// tan θ > μs, and not at all when tan θ < μs.
#[test]
fn coulomb_friction_on_an_incline_at_a_millisecond() {
    let (mu_s, mu_k, g) = (0.5, 0.3, 9.81);
    let nitinol = preset("nitinol").unwrap().material();
    for material in [soft(2e-3), nitinol] {
        let r = material.radius;
        for (theta_deg, sticks) in [(20.0_f64, true), (35.0, false)] {
            let theta = theta_deg.to_radians();
            let down = Vec3::new(theta.cos(), 0.0, -theta.sin());
            let normal = Vec3::new(theta.sin(), 0.0, theta.cos());
            let plane = square(Vec3::zeros(), down, Vec3::y(), 2.0);
            // Across the slope (along y), one radius above the plane.
            let start = normal * r - Vec3::y() * 0.05;
            let free = [EndCondition::free(), EndCondition::free()];
            let mut rod = rod_along(material, start, Vec3::y(), 0.1, 10, free)
                .with_mesh(contact(plane, mu_s, mu_k));
            let s = settings(1e-3, Vec3::new(0.0, 0.0, -g));
            let steps = 200;
            let t = steps as f64 * s.dt;
            let com0 = centre_of_mass(&rod);
            let mut sc = StiffScratch::new();
            run(&mut rod, &s, &mut sc, 0.0, steps);
            let travelled = (centre_of_mass(&rod) - com0).dot(&down);
            let off_plane = (centre_of_mass(&rod) - com0).dot(&normal);
            assert!(
                off_plane.abs() < 1e-3 * r,
                "θ = {theta_deg}°: left the plane by {off_plane} m"
            );
            if sticks {
                // Static friction holds it as a stiff spring: it creeps at
                // `STICK_SPEED · tan θ / μ_s` (what drives it over what can hold it).
                let creep = STICK_SPEED * t * theta.tan() / mu_s;
                assert!(
                    travelled.abs() <= 1.01 * creep,
                    "θ = {theta_deg}°, r = {r}: moved {travelled} m although tan θ < μs (creep {creep} m)"
                );
            } else {
                let a = g * (theta.sin() - mu_k * theta.cos());
                let expected = 0.5 * a * t * t * (1.0 + s.dt / t);
                let rel = (travelled - expected).abs() / expected;
                assert!(
                    rel < 1e-3,
                    "θ = {theta_deg}°, r = {r}: slid {travelled} m, expected {expected} m (rel. error {rel:.2e})"
                );
            }
        }
    }
}

/// A wire pushed into a wall at dt 1 ms does not pass through it (by more than the contact
/// tolerance); it buckles sideways (the explicit scheme's test, at fifty times its step).
#[test]
fn a_wire_pushed_into_a_wall_buckles_at_a_millisecond() {
    let r = 1e-3;
    let mut rod = wire_pushed_at_a_wall(r);
    let s = settings(1e-3, Vec3::zeros());
    let mut sc = StiffScratch::new();
    let mut furthest = f64::MIN;
    for step in 0..250 {
        run(&mut rod, &s, &mut sc, step as f64 * 1e-3, 1);
        furthest = rod
            .state
            .positions
            .iter()
            .map(|p| p.x)
            .fold(furthest, f64::max);
    }
    let stats = rod.collision_stats().unwrap();
    assert!(stats.max_contacts > 0, "the tip touched the wall");
    // Within the contact's penetration tolerance, 2 % of the radius (`stiff/contact.rs`).
    assert!(
        furthest <= 0.2 - r * (1.0 - 0.02),
        "a point passed the wall: x = {furthest}"
    );
    let lateral = rod
        .state
        .positions
        .iter()
        .map(|p| p.y.abs())
        .fold(0.0, f64::max);
    assert!(
        lateral > 0.01,
        "the wire buckled sideways by only {lateral} m"
    );
}

/// Answering the queries of touching points that barely moved from their last query (the
/// default, `StiffSettings::reuse_contact_queries`) gives the same steps, bit for bit, as
/// querying every point after every iteration: a soft wire pushed at 0.2 m/s into the
/// procedural vessel, whose tip meets the curved wall and slides along it with friction, at
/// dt 1 ms.
#[test]
fn reused_contact_queries_give_the_steps_of_full_queries() {
    use cosserat_backend_cpu::PrescribedMotion;
    use cosserat_collide::{MeshCollider, Vessel};
    let vessel = Vessel::default_tree().unwrap();
    let collider = std::sync::Arc::new(MeshCollider::new(vessel.mesh.clone()));
    let entry = Vec3::from(vessel.entry_point);
    let along = Vec3::from(vessel.entry_direction);
    let push = PrescribedMotion::push(along * 0.2);
    let wire = || {
        let ends = [EndCondition::clamped().driven(push), EndCondition::free()];
        let material = Material::new(5e6, 5e6 / 3.0, 1100.0, 4e-4);
        rod_along(material, entry, along, 0.2, 80, ends).with_mesh(contact(
            collider.clone(),
            0.08,
            0.05,
        ))
    };
    let s = settings(1e-3, Vec3::zeros());
    let steps = 300;
    let mut runs = Vec::new();
    for reuse in [true, false] {
        let mut rod = wire();
        let stiff = StiffSettings {
            reuse_contact_queries: reuse,
            ..StiffSettings::default()
        };
        let mut sc = StiffScratch::new();
        for step in 0..steps {
            step_rod_stiff(
                &mut rod,
                &s,
                &stiff,
                &mut sc,
                step as f64 * 1e-3,
                0,
                step,
                1,
            )
            .unwrap();
        }
        runs.push((rod.state.positions.clone(), rod.collision_stats().unwrap()));
    }
    let (reused, full) = (&runs[0], &runs[1]);
    assert!(
        full.1.max_contacts >= 3,
        "the wire met the wall: {:?}",
        full.1
    );
    assert!(
        reused.1.reused_queries > 0,
        "queries were reused: {:?}",
        reused.1
    );
    assert_eq!(full.1.reused_queries, 0);
    assert_eq!(reused.0, full.0, "the same positions after {steps} steps");
    assert_eq!(reused.1.max_contacts, full.1.max_contacts);
    assert_eq!(reused.1.escaped_points, full.1.escaped_points);
}

/// A nitinol wire lying on a floor, pushed slowly along its axis from a clamped end (3 mm/s,
/// `μ_s = 0.5`, `μ_k = 0.3`, gravity, dt 1 ms), slides as a whole: every point moves with the
/// hand and the wire stays unstrained. Each of its points slips only micrometres per step, so
/// static friction could hold any one of them alone; putting such a point back where its step
/// began would strain its elements by its slip (3e-3 of a 1 mm element) against the push of
/// its neighbours. Points that slipped further than `STICK_JUMP` of an element stick where
/// they are instead (`stiff/contact.rs`).
#[test]
fn a_wire_pushed_along_a_floor_slides_as_a_whole() {
    let nitinol = preset("nitinol").unwrap().material();
    let r = nitinol.radius;
    let floor = square(Vec3::zeros(), Vec3::x(), Vec3::y(), 1.0);
    let speed = 3e-3;
    let push = cosserat_backend_cpu::PrescribedMotion::push(Vec3::x() * speed);
    let ends = [EndCondition::clamped().driven(push), EndCondition::free()];
    let start = Vec3::new(-0.025, 0.0, r);
    let mut rod =
        rod_along(nitinol, start, Vec3::x(), 0.05, 50, ends).with_mesh(contact(floor, 0.5, 0.3));
    let s = settings(1e-3, Vec3::new(0.0, 0.0, -9.81));
    let mut sc = StiffScratch::new();
    let steps = 500;
    let tip0 = *rod.state.positions.last().unwrap();
    let mut largest_strain = 0.0_f64;
    for step in 0..steps {
        run(&mut rod, &s, &mut sc, step as f64 * 1e-3, 1);
        let p = &rod.state.positions;
        for j in 0..p.len() - 1 {
            let strain = ((p[j + 1] - p[j]).norm() / rod.params.rest_lengths[j] - 1.0).abs();
            largest_strain = largest_strain.max(strain);
        }
    }
    let report = sc.report();
    let moved = rod.state.positions.last().unwrap().x - tip0.x;
    let expected = speed * steps as f64 * 1e-3;
    assert!(
        (moved - expected).abs() < 1e-3 * expected,
        "the free end moved {moved} m, the hand {expected} m"
    );
    assert!(
        largest_strain < 1e-4,
        "largest strain {largest_strain}, {report:?}"
    );
    assert_eq!(report.unconverged_steps, 0, "{report:?}");
    assert_eq!(report.axial_steps, 0, "{report:?}");
    assert!(lowest(&rod) > r * (1.0 - 1e-3), "stays on the floor");
}

/// A rod in a right-angled V-groove inclined at α along its axis, at dt 1 ms, rests on both
/// walls at once, in their crease (`stiff/contact.rs`: `two_walls`, `back_on_walls`), so the
/// walls' normal forces add up to `√2 m g cos α` (the wedge effect): the centre of mass moves as
/// ½ a t² (1 + h/t) with `a = g (sin α − √2 μk cos α)` when `tan α > √2 μs`, and not at all when
/// `tan α < √2 μs` (a rod on one wall under the mean normal, `μ m g cos α`, slides at 30°).
/// Never more than the contact tolerance (2 % of the radius) into either wall, never off the
/// groove's axis, every step converged.
#[test]
fn coulomb_friction_in_an_inclined_v_groove_at_a_millisecond() {
    let (mu_s, mu_k, g) = (0.5, 0.3, 9.81);
    let nitinol = preset("nitinol").unwrap().material();
    for material in [soft(2e-3), nitinol] {
        let r = material.radius;
        for (alpha_deg, sticks) in [(30.0_f64, true), (45.0, false)] {
            let alpha = alpha_deg.to_radians();
            let down = Vec3::new(alpha.cos(), 0.0, -alpha.sin());
            let up = Vec3::new(alpha.sin(), 0.0, alpha.cos());
            // The walls rise at 45° on either side of the groove's bottom line; each one's
            // normal (into the groove) is the other's direction of rise.
            let rise = [(up + Vec3::y()).normalize(), (up - Vec3::y()).normalize()];
            let mut vertices = Vec::new();
            let mut triangles = Vec::new();
            for (k, side) in rise.iter().enumerate() {
                let corners = [-down, down, down + side * 0.05, -down + side * 0.05];
                let base = vertices.len() as u32;
                vertices.extend(corners.iter().map(|c| [c.x, c.y, c.z]));
                let normal = (corners[1] - corners[0]).cross(&(corners[2] - corners[0]));
                if normal.dot(&rise[1 - k]) > 0.0 {
                    triangles.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
                } else {
                    triangles.extend([[base, base + 2, base + 1], [base, base + 3, base + 2]]);
                }
            }
            let (mesh, _) = TriMesh::new(vertices, triangles, "groove").unwrap();
            let groove = Arc::new(MeshCollider::new(mesh));
            // Along the groove, touching both walls.
            let start = up * (r * 2.0_f64.sqrt()) - down * 0.05;
            let free = [EndCondition::free(), EndCondition::free()];
            let mut rod = rod_along(material, start, down, 0.1, 10, free)
                .with_mesh(contact(groove, mu_s, mu_k));
            let s = settings(1e-3, Vec3::new(0.0, 0.0, -g));
            let steps = 200;
            let t = steps as f64 * s.dt;
            let com0 = centre_of_mass(&rod);
            let mut sc = StiffScratch::new();
            let mut deepest = 0.0_f64;
            for step in 0..steps {
                run(&mut rod, &s, &mut sc, step as f64 * s.dt, 1);
                for p in &rod.state.positions {
                    for n in &rise {
                        // Wall k's normal is rise[1 − k]; both walls pass through the origin.
                        deepest = deepest.max(r - p.dot(n));
                    }
                }
            }
            let moved = centre_of_mass(&rod) - com0;
            let along = moved.dot(&down);
            let label = format!("α = {alpha_deg}°, r = {r}");
            assert!(deepest <= 0.02 * r, "{label}: {deepest} m into a wall");
            assert_eq!(
                sc.report().unconverged_steps,
                0,
                "{label}: {:?}",
                sc.report()
            );
            assert!(
                (moved - down * along).norm() < 0.02 * r,
                "{label}: drifted {} m off the groove's axis",
                (moved - down * along).norm()
            );
            if sticks {
                let creep = STICK_SPEED * t * alpha.tan() / (2.0_f64.sqrt() * mu_s);
                assert!(
                    along.abs() <= 1.01 * creep,
                    "{label}: moved {along} m although tan α < √2 μs (creep {creep} m)"
                );
            } else {
                let a = g * (alpha.sin() - 2.0_f64.sqrt() * mu_k * alpha.cos());
                let expected = 0.5 * a * t * t * (1.0 + s.dt / t);
                let rel = (along - expected).abs() / expected;
                assert!(
                    rel < 1e-3,
                    "{label}: slid {along} m, expected {expected} m (rel. error {rel:.2e})"
                );
            }
        }
    }
}

/// The explicit scheme's ridge test (`contact.rs`) at dt 1 ms: the element lands on the ridge
/// under its middle and never takes it into its capsule by more than 2 % of the radius.
#[test]
fn an_element_lands_on_a_ridge_between_its_points_at_a_millisecond() {
    let nitinol = preset("nitinol").unwrap().material();
    for material in [soft(2e-3), nitinol] {
        let r = material.radius;
        let mut rod =
            support::rod_over_a_ridge(material, 2e-3).with_mesh(contact(support::roof(), 0.5, 0.4));
        let s = settings(1e-3, Vec3::new(0.0, 0.0, -9.81));
        let mut sc = StiffScratch::new();
        let mut deepest = f64::NEG_INFINITY;
        for step in 0..200 {
            run(&mut rod, &s, &mut sc, step as f64 * 1e-3, 1);
            deepest = deepest.max(support::into_the_roof(&rod));
        }
        let stats = rod.collision_stats().unwrap();
        assert!(stats.segment_contacts > 0, "r = {r}: {stats:?}");
        assert!(deepest <= 0.02 * r, "r = {r}: {deepest} m into the roof");
    }
}

/// The statistics' `max_penetration` is the deepest any point's sphere reached into the wall at
/// the end of any step, as the oracle measures it after every step (the point's distance from
/// the mesh by a nearest-triangle query, inside the lumen by the winding number): a soft wire
/// (10 cm) pushed at 0.2 m/s into the procedural vessel's curved wall at dt 1 ms, with the
/// contact queries' reuse (the default), whose gaps are only bounds. The held point is left out
/// of both (the hand answers for it). Before the exact measure, the statistics reported 7.4 µm
/// where the oracle found 1.8 (the bounds of the reused queries).
#[test]
fn max_penetration_is_the_deepest_sphere_the_oracle_finds() {
    use cosserat_backend_cpu::PrescribedMotion;
    use cosserat_collide::Vessel;
    let vessel = Vessel::default_tree().unwrap();
    let collider = Arc::new(MeshCollider::new(vessel.mesh.clone()));
    let entry = Vec3::from(vessel.entry_point);
    let along = Vec3::from(vessel.entry_direction);
    let push = PrescribedMotion::push(along * 0.2);
    let ends = [EndCondition::clamped().driven(push), EndCondition::free()];
    let material = Material::new(5e6, 5e6 / 3.0, 1100.0, 4e-4);
    let r = material.radius;
    let mut rod = rod_along(material, entry, along, 0.1, 40, ends).with_mesh(contact(
        collider.clone(),
        0.08,
        0.05,
    ));
    let s = settings(1e-3, Vec3::zeros());
    let mut sc = StiffScratch::new();
    let mut oracle = 0.0_f64;
    for step in 0..500 {
        run(&mut rod, &s, &mut sc, step as f64 * 1e-3, 1);
        for p in &rod.state.positions[1..] {
            let p = [p.x, p.y, p.z];
            assert!(
                collider.lumen_winding(&p) >= 0.5,
                "step {step}: a point outside"
            );
            if let Some(near) = collider.nearest(&p, r) {
                oracle = oracle.max(r - near.distance);
            }
        }
    }
    let stats = rod.collision_stats().unwrap();
    assert!(stats.max_contacts >= 3, "the wire met the wall: {stats:?}");
    assert!(oracle > 0.0, "the wire pressed on the wall");
    assert!(stats.reused_queries > 0, "{stats:?}");
    assert_eq!(
        stats.steps,
        sc.report().steps,
        "the statistics count the kept steps"
    );
    assert_eq!(stats.escaped_points, 0);
    assert!(
        (stats.max_penetration - oracle).abs() <= 1e-12,
        "statistics {} m, oracle {oracle} m",
        stats.max_penetration
    );
}
