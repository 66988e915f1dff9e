//! Rods against static meshes: resting contact, Coulomb friction on an incline, and a wire
//! pushed into a wall.

use cosserat_backend_cpu::{CpuRod, EndCondition, Ordering, SolverSettings, step_rod_batch};
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Vec3};

#[allow(dead_code, unreachable_pub)]
mod support;
use support::{contact, square, wire_pushed_at_a_wall};

fn rod_along(
    start: Vec3<f64>,
    dir: Vec3<f64>,
    length: f64,
    n: usize,
    radius: f64,
    ends: [EndCondition<f64>; 2],
) -> CpuRod<f64> {
    let spec = RodSpec::new(Material::new(1e6, 1e6 / 3.0, 1100.0, radius));
    let (state, params) = build_rod::<f64>(
        &straight_polyline(start.into(), dir.into(), length, n),
        &spec,
    )
    .unwrap();
    CpuRod::new(state, params, ends, vec![])
}

fn settings(gravity: Vec3<f64>) -> SolverSettings<f64> {
    SolverSettings {
        dt: 5e-5,
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible: false,
        gravity,
        divergence_strain: 0.5,
    }
}

#[test]
fn a_rod_resting_on_a_plane_does_not_sink() {
    let r = 2e-3;
    let plane = square(Vec3::zeros(), Vec3::x(), Vec3::y(), 1.0);
    let free = [EndCondition::free(), EndCondition::free()];
    // Dropped from 5 mm above the plane.
    let mut rod = rod_along(Vec3::new(-0.1, 0.0, r + 5e-3), Vec3::x(), 0.2, 20, r, free)
        .with_mesh(contact(plane, 0.5, 0.4));
    let s = settings(Vec3::new(0.0, 0.0, -9.81));
    step_rod_batch(&mut rod, &s, 0.0, 0, 0, 4_000).unwrap(); // falls and settles (0.2 s)
    let before = rod.collision_stats().unwrap();
    assert!(before.contacts > 0, "the rod has landed");
    // Now at rest: measure the penetration over the next 0.3 s only.
    let mut resting = rod.clone().with_mesh(contact(
        square(Vec3::zeros(), Vec3::x(), Vec3::y(), 1.0),
        0.5,
        0.4,
    ));
    step_rod_batch(&mut resting, &s, 0.2, 0, 4_000, 6_000).unwrap();
    let stats = resting.collision_stats().unwrap();
    assert!(
        stats.max_penetration < 0.01 * r,
        "penetration {} m vs 1% of r = {} m",
        stats.max_penetration,
        0.01 * r
    );
    let lowest = resting
        .state
        .positions
        .iter()
        .map(|p| p.z)
        .fold(f64::MAX, f64::min);
    assert!(lowest > r * 0.99, "lowest centre {lowest} m");
    let speed = resting
        .state
        .velocities
        .iter()
        .map(|v| v.norm())
        .fold(0.0, f64::max);
    assert!(speed < 1e-3, "at rest, got {speed} m/s");
}

/// Slides down an incline of angle θ: the centre of mass moves as ½ a t² with
/// a = g (sin θ − μk cos θ) when tan θ > μs, and not at all when tan θ < μs.
#[test]
fn coulomb_friction_on_an_incline() {
    let (mu_s, mu_k, g, r) = (0.5, 0.3, 9.81, 2e-3);
    for (theta_deg, sticks) in [(20.0_f64, true), (35.0, false)] {
        let theta = theta_deg.to_radians();
        // Down-slope direction and plane normal.
        let down = Vec3::new(theta.cos(), 0.0, -theta.sin());
        let normal = Vec3::new(theta.sin(), 0.0, theta.cos());
        let plane = square(Vec3::zeros(), down, Vec3::y(), 2.0);
        assert!((down.cross(&Vec3::y()) - normal).norm() < 1e-12);
        // A rod lying across the slope (along y), its centre line one radius above the plane.
        let start = normal * r - Vec3::y() * 0.05;
        let free = [EndCondition::free(), EndCondition::free()];
        let mut rod =
            rod_along(start, Vec3::y(), 0.1, 10, r, free).with_mesh(contact(plane, mu_s, mu_k));
        let s = settings(Vec3::new(0.0, 0.0, -g));
        let steps = 4_000;
        let t = steps as f64 * s.dt;
        let com0: Vec3<f64> = rod.state.positions.iter().sum::<Vec3<f64>>() / 11.0;
        step_rod_batch(&mut rod, &s, 0.0, 0, 0, steps).unwrap();
        let com: Vec3<f64> = rod.state.positions.iter().sum::<Vec3<f64>>() / 11.0;
        let travelled = (com - com0).dot(&down);
        if sticks {
            assert!(
                travelled.abs() < 1e-6,
                "θ = {theta_deg}°: moved {travelled} m although tan θ < μs"
            );
        } else {
            let a = g * (theta.sin() - mu_k * theta.cos());
            let expected = 0.5 * a * t * t;
            // Semi-implicit Euler moves ½ a t² (1 + h/t): allow that and 1% besides.
            let rel = (travelled - expected).abs() / expected;
            assert!(
                rel < 0.01 + s.dt / t,
                "θ = {theta_deg}°: slid {travelled} m, expected {expected} m (rel. error {rel:.2e})"
            );
        }
    }
}

/// A wire pushed into a wall does not pass through it; it buckles sideways.
#[test]
fn a_wire_pushed_into_a_wall_buckles() {
    let r = 1e-3;
    let mut rod = wire_pushed_at_a_wall(r);
    let mut s = settings(Vec3::zeros());
    s.dt = 2e-5;
    // Push the base 5 cm towards the wall (0.25 s).
    step_rod_batch(&mut rod, &s, 0.0, 0, 0, 12_500).unwrap();
    let stats = rod.collision_stats().unwrap();
    assert!(stats.max_contacts > 0, "the tip touched the wall");
    let furthest = rod
        .state
        .positions
        .iter()
        .map(|p| p.x)
        .fold(f64::MIN, f64::max);
    assert!(
        furthest < 0.2 - r * 0.99,
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

/// A rod dropped across a roof's ridge, the ridge under the middle of an element: the element
/// lands on the ridge and never takes it into its capsule by more than 2 % of the radius
/// (without segment contacts it falls through, its points 3.5 cm from the faces).
#[test]
fn an_element_lands_on_a_ridge_between_its_points() {
    let r = 2e-3;
    let mut rod = support::rod_over_a_ridge(Material::new(1e6, 1e6 / 3.0, 1100.0, r), 2e-3)
        .with_mesh(contact(support::roof(), 0.5, 0.4));
    let s = settings(Vec3::new(0.0, 0.0, -9.81));
    let mut deepest = f64::NEG_INFINITY;
    for k in 0..400 {
        step_rod_batch(&mut rod, &s, k as f64 * 10.0 * s.dt, 0, k * 10, 10).unwrap();
        deepest = deepest.max(support::into_the_roof(&rod));
    }
    let stats = rod.collision_stats().unwrap();
    assert!(stats.segment_contacts > 0, "{stats:?}");
    assert!(deepest <= 0.02 * r, "{deepest} m into the roof");
}
