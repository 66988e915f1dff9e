//! The CPU stepper against the model's reference definitions, and its own invariants.

use cosserat_backend_cpu::{
    CpuRod, DivergedQuantity, EndCondition, Ordering, Par, PrescribedMotion, SolverSettings,
    step_rod, step_rod_batch, step_rods,
};
use cosserat_model::energy::{ForceModel, accumulate_forces};
use cosserat_model::quat::{directors, rotate_body};
use cosserat_model::rod::{RestShape, RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Vec3};
use rand::{Rng, SeedableRng, rngs::StdRng};

fn settings(extensible: bool, ordering: Ordering, iterations: usize) -> SolverSettings<f64> {
    SolverSettings {
        dt: 1e-5,
        iterations,
        ordering,
        extensible,
        gravity: Vec3::new(0.5, -1.0, -9.81),
        divergence_strain: 0.5,
    }
}

/// A curved, twisted rod with perturbed frames: every force term is active.
fn random_rod(seed: u64, n: usize, bend_damping: f64) -> CpuRod<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut pts = vec![[0.0; 3]];
    let mut dir = Vec3::new(1.0, 0.0, 0.0);
    for _ in 0..n {
        dir = (dir
            + Vec3::new(
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
            ))
        .normalize();
        let last = Vec3::from(*pts.last().unwrap());
        pts.push((last + dir * rng.random_range(0.008..0.012)).into());
    }
    let mut spec = RodSpec::new(Material::new(5e6, 2e6, 1100.0, 2e-3));
    spec.rest_shape = RestShape::Uniform([3.0, -2.0, 1.0]);
    spec.bend_damping = bend_damping;
    spec.drag = 0.3;
    let (mut state, params) = build_rod::<f64>(&pts, &spec).unwrap();
    for q in state.frames.iter_mut() {
        *q = rotate_body(
            q,
            &Vec3::new(
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.2..0.2),
            ),
        );
    }
    CpuRod::new(
        state,
        params,
        [EndCondition::free(), EndCondition::free()],
        vec![],
    )
}

/// One step from rest with no constraints changes velocities by exactly `h f / m` and angular
/// velocities by two half kicks `½ h I⁻¹ τ` around the gyroscopic precession of the first one
/// (`(ω₁, ω₂)` turned by `h (J − I)/I ω₃`, a Cayley rotation), with `f`, `τ` from the model's
/// reference `accumulate_forces`.
#[test]
fn one_step_applies_the_reference_forces_and_torques() {
    for extensible in [false, true] {
        let mut rod = random_rod(11, 40, 0.0);
        let s = settings(extensible, Ordering::GaussSeidel, 0);
        let n = rod.elements();
        let (mut f, mut t) = (vec![Vec3::zeros(); n + 1], vec![Vec3::zeros(); n]);
        accumulate_forces(
            &rod.state,
            &rod.params,
            &ForceModel {
                extensible,
                gravity: s.gravity,
                clamped: [false; 2],
            },
            &mut f,
            &mut t,
        );
        let p = rod.params.clone();
        step_rod(&mut rod, &s, 0.0, 0, 0).unwrap();
        let scale_f = f.iter().map(|x| x.norm()).fold(0.0, f64::max);
        for i in 0..=n {
            let expected = f[i] * (s.dt * p.inv_masses[i]);
            let got = rod.state.velocities[i];
            assert!(
                (got - expected).norm() <= 1e-10 * scale_f * s.dt * p.inv_masses[i],
                "point {i}: {got:?} vs {expected:?}"
            );
        }
        let scale_t = t.iter().map(|x| x.norm()).fold(0.0, f64::max);
        for j in 0..n {
            let inertia = p.inertias[j];
            let half = t[j].component_div(&inertia) * (0.5 * s.dt);
            let tan = 0.5 * s.dt * (inertia.z / inertia.x - 1.0) * half.z;
            let (cos, sin) = (
                (1.0 - tan * tan) / (1.0 + tan * tan),
                2.0 * tan / (1.0 + tan * tan),
            );
            let expected = Vec3::new(
                cos * half.x - sin * half.y,
                sin * half.x + cos * half.y,
                half.z,
            ) + half;
            let got = rod.state.angular_velocities[j];
            let tol = 1e-10 * scale_t * s.dt / p.inertias[j].min();
            assert!(
                (got - expected).norm() <= tol,
                "frame {j}: {got:?} vs {expected:?}"
            );
        }
    }
}

/// A batch of k steps is bitwise the same as k single steps, with or without damping.
#[test]
fn batches_equal_single_steps() {
    for ordering in [Ordering::GaussSeidel, Ordering::RedBlack] {
        let s = settings(false, ordering, 10);
        let mut a = random_rod(3, 33, 1e-8);
        let mut b = a.clone();
        step_rod_batch(&mut a, &s, 0.0, 0, 0, 25).unwrap();
        for k in 0..25 {
            step_rod(&mut b, &s, k as f64 * s.dt, 0, k).unwrap();
        }
        assert_eq!(a.state, b.state, "{ordering:?}");
    }
}

/// Rods do not interact, so stepping them serially or on rayon's pool gives identical states.
#[test]
fn serial_and_parallel_agree_bitwise() {
    let s = settings(false, Ordering::RedBlack, 10);
    let mut serial: Vec<_> = (0..6)
        .map(|i| random_rod(i, 20 + 7 * i as usize, 1e-8))
        .collect();
    let mut parallel = serial.clone();
    let mut stats = Vec::new();
    for k in 0..20 {
        step_rods(&mut serial, &s, k as f64 * s.dt, k, Par::Serial, &mut stats).unwrap();
        step_rods(
            &mut parallel,
            &s,
            k as f64 * s.dt,
            k,
            Par::Rayon,
            &mut stats,
        )
        .unwrap();
    }
    for (a, b) in serial.iter().zip(&parallel) {
        assert_eq!(a.state, b.state);
    }
}

/// The vectorised red–black sweeps and the Gauss–Seidel sweeps both hold the pendulum's
/// segments to their rest lengths.
#[test]
fn both_orderings_keep_a_pendulum_inextensible() {
    for ordering in [Ordering::GaussSeidel, Ordering::RedBlack] {
        let spec = RodSpec::new(Material::new(1e6, 3.3e5, 1100.0, 5e-3));
        let (state, params) = build_rod::<f64>(
            &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 1.0, 50),
            &spec,
        )
        .unwrap();
        let mut rod = CpuRod::new(
            state,
            params,
            [EndCondition::pinned(), EndCondition::free()],
            vec![],
        );
        let mut s = settings(false, ordering, 10);
        s.dt = 1e-4;
        let stats = step_rod_batch(&mut rod, &s, 0.0, 0, 0, 4000).unwrap();
        assert!(
            stats.max_strain() < 1e-3,
            "{ordering:?}: max strain {}",
            stats.max_strain()
        );
        // It swung: after 0.4 s the free end has fallen well below the pivot.
        assert!(rod.state.positions[50].z < -0.3);
        assert_eq!(
            rod.state.positions[0],
            Vec3::zeros(),
            "the pinned end stays"
        );
    }
}

/// A clamped end driven with angular velocity ω about the rod's axis turns its clamp by ω t, and
/// the end frame with it.
#[test]
fn a_driven_clamp_twists_the_end_frame() {
    let spec = RodSpec::new(Material::new(1e6, 3.3e5, 1100.0, 5e-3));
    let (state, params) = build_rod::<f64>(
        &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.2, 20),
        &spec,
    )
    .unwrap();
    let omega = 3.0;
    let drive = PrescribedMotion {
        velocity: Vec3::zeros(),
        angular_velocity: Vec3::new(omega, 0.0, 0.0),
        start_time: 0.0,
        end_time: f64::INFINITY,
    };
    let mut rod = CpuRod::new(
        state,
        params,
        [EndCondition::clamped().driven(drive), EndCondition::free()],
        vec![],
    );
    let mut s = settings(false, Ordering::GaussSeidel, 10);
    s.gravity = Vec3::zeros();
    s.dt = 1e-5;
    let steps = 20_000;
    step_rod_batch(&mut rod, &s, 0.0, 0, 0, steps).unwrap();
    let d1 = directors(&rod.state.clamp_frames[0])[0];
    let angle = d1.z.atan2(d1.y);
    let end = directors(&rod.state.frames[0])[0];
    let lag = (angle - end.z.atan2(end.y)).rem_euclid(std::f64::consts::TAU);
    // Compare with the angle of d1 in the y–z plane before the drive started.
    let start = directors(
        &build_rod::<f64>(
            &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.2, 20),
            &spec,
        )
        .unwrap()
        .0
        .frames[0],
    )[0];
    let start_angle = start.z.atan2(start.y);
    let turned = (angle - start_angle).rem_euclid(std::f64::consts::TAU);
    let expected = (omega * steps as f64 * s.dt).rem_euclid(std::f64::consts::TAU);
    assert!(
        (turned - expected).abs() < 1e-6,
        "clamp turned {turned} rad, expected {expected}"
    );
    // The end frame follows through the clamp's node.
    assert!(
        lag.min(std::f64::consts::TAU - lag) < 1e-2,
        "end frame {lag} rad behind"
    );
}

/// A time step far beyond the stable limit is caught, with the rod, element and step named.
#[test]
fn divergence_is_reported_not_propagated() {
    let spec = RodSpec::new(Material::new(2e11, 8e10, 7800.0, 1e-3));
    let (state, params) = build_rod::<f64>(
        &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 1.0, 100),
        &spec,
    )
    .unwrap();
    let mut rod = CpuRod::new(
        state,
        params,
        [EndCondition::clamped(), EndCondition::free()],
        vec![],
    );
    let mut s = settings(true, Ordering::GaussSeidel, 0);
    s.dt = 1e-3;
    let err = step_rod_batch(&mut rod, &s, 0.0, 7, 0, 10_000).unwrap_err();
    assert_eq!(err.rod, 7);
    assert!(err.step < 10_000);
    assert!(err.element < 100);
    assert!(matches!(
        err.quantity,
        DivergedQuantity::Strain(_)
            | DivergedQuantity::NonFinitePosition
            | DivergedQuantity::NonFiniteFrame
    ));
    let msg = err.to_string();
    assert!(
        msg.contains("rod 7") && msg.contains(&format!("step {}", err.step)),
        "{msg}"
    );
}
