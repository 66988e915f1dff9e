//! Interacting instruments: bindings (paper section 3.4), self-contact (section 3.5) and the
//! reaction force at held ends.

use cosserat_backend_cpu::{
    BindingSpec, Coupling, CpuRod, EndCondition, MeshContactSettings, Ordering, PrescribedMotion,
    RodContactSpec, SolverSettings, StepStats, step_coupled_batch, step_rod,
};
use cosserat_collide::MeshCollider;
use cosserat_constraints::{BindingVariant, Friction};
use cosserat_model::rod::{RestShape, RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Vec3};
use std::sync::Arc;

#[allow(dead_code, unreachable_pub)]
mod support;
use support::square;

fn settings(dt: f64, gravity: Vec3<f64>, ordering: Ordering) -> SolverSettings<f64> {
    SolverSettings {
        dt,
        iterations: 10,
        ordering,
        extensible: false,
        gravity,
        divergence_strain: 0.5,
    }
}

fn rod(points: &[[f64; 3]], spec: &RodSpec, ends: [EndCondition<f64>; 2]) -> CpuRod<f64> {
    let (state, params) = build_rod::<f64>(points, spec).unwrap();
    CpuRod::new(state, params, ends, vec![])
}

fn momentum(r: &CpuRod<f64>) -> Vec3<f64> {
    r.state
        .velocities
        .iter()
        .zip(&r.params.masses)
        .map(|(v, m)| v * *m)
        .sum()
}

fn v3(a: [f64; 3]) -> Vec3<f64> {
    Vec3::from(a)
}

/// A clamped cantilever under gravity. At every step the raw reaction closes the momentum
/// balance of the whole rod exactly (`F + M g = ΔP / h`, to rounding), for either ordering; at
/// rest the filtered reaction is the total weight, and the torque is the weight times the lever
/// arm of the centre of mass.
#[test]
fn cantilever_reaction_is_weight_and_weight_times_lever_arm() {
    let g = Vec3::new(0.0, 0.0, -9.81);
    for ordering in [Ordering::RedBlack, Ordering::GaussSeidel] {
        let mut spec = RodSpec::new(Material::new(1e6, 1e6 / 3.0, 1100.0, 2e-3));
        // About critical damping of the first bending mode (ω1 ≈ 42 rad/s).
        spec.drag = 85.0;
        let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.05, 10);
        let mut r = rod(&pts, &spec, [EndCondition::clamped(), EndCondition::free()])
            .with_reaction_cutoff(20.0);
        let s = settings(2e-5, g, ordering);
        let total_mass: f64 = r.params.masses.iter().sum();
        let weight = total_mass * 9.81;
        // Momentum balance, step by step, while the cantilever swings down.
        for k in 0..200 {
            let p0 = momentum(&r);
            step_rod(&mut r, &s, k as f64 * s.dt, 0, k).unwrap();
            let f = v3(r.end_reaction_raw(0).unwrap().force);
            // Gravity and the drag of the medium are the external forces besides the clamp.
            let expected = (momentum(&r) - p0) / s.dt - g * total_mass + p0 * spec.drag;
            assert!(
                (f - expected).norm() < 1e-9 * weight,
                "{ordering:?} step {k}: F = {f:?}, ΔP/h − Mg = {expected:?}"
            );
        }
        // Settle (0.25 s), then compare with statics.
        for k in 200..12_500 {
            step_rod(&mut r, &s, k as f64 * s.dt, 0, k).unwrap();
        }
        let reaction = r.end_reaction(0).unwrap();
        let f = v3(reaction.force);
        let r0 = r.state.positions[0];
        let moment: Vec3<f64> = r
            .state
            .positions
            .iter()
            .zip(&r.params.masses)
            .map(|(p, m)| (p - r0).cross(&(g * *m)))
            .sum();
        let torque = v3(reaction.torque);
        let speed = r
            .state
            .velocities
            .iter()
            .map(|v| v.norm())
            .fold(0.0, f64::max);
        assert!(speed < 1e-4, "{ordering:?}: not at rest, {speed} m/s");
        // 0.1 %: what is left of the motion after 0.25 s of damping, and the filter's lag.
        let tol = 1e-3;
        assert!(
            (f - Vec3::new(0.0, 0.0, weight)).norm() < tol * weight,
            "{ordering:?}: F = {f:?}, weight {weight}"
        );
        assert!(
            (torque + moment).norm() < tol * moment.norm(),
            "{ordering:?}: M = {torque:?}, expected {:?}",
            -moment
        );
    }
}

/// A wall at `x` facing −x.
fn wall(x: f64) -> Arc<MeshCollider> {
    square(Vec3::new(x, 0.0, 0.0), Vec3::z(), Vec3::y(), 0.5)
}

/// A wire pushed into a wall with friction, then held: at every step the pushing force plus the
/// contact and friction forces close the momentum balance; at rest the pushing force equals
/// minus the sum of the contact and friction forces along the rod.
#[test]
fn pushed_end_reaction_balances_contact_and_friction() {
    let r_wire = 1e-3;
    let push = PrescribedMotion {
        end_time: 0.06, // 2 mm past first touch
        ..PrescribedMotion::push(Vec3::new(0.2, 0.0, 0.0))
    };
    let mut spec = RodSpec::new(Material::new(1e6, 1e6 / 3.0, 1100.0, r_wire));
    spec.drag = 60.0;
    let pts: Vec<[f64; 3]> = (0..=20)
        .map(|i| {
            let s = i as f64 / 20.0;
            [0.19 * s, 1e-3 * (std::f64::consts::PI * s).sin(), 0.0]
        })
        .collect();
    let mut r = rod(
        &pts,
        &spec,
        [EndCondition::clamped().driven(push), EndCondition::free()],
    )
    .with_mesh(MeshContactSettings::mesh(
        wall(0.2),
        Friction {
            static_coefficient: 0.3,
            kinetic_coefficient: 0.2,
        },
        1e-4,
    ))
    .with_reaction_cutoff(20.0);
    let s = settings(2e-5, Vec3::zeros(), Ordering::RedBlack);
    let contact_force = |r: &CpuRod<f64>| -> Vec3<f64> {
        let set = r.contacts().unwrap();
        set.contacts()
            .zip(set.normal_impulses().iter().zip(set.tangent_impulses()))
            .map(|(c, (ln, lt))| (c.normal * *ln + lt) * (r.params.masses[c.point as usize] / s.dt))
            .sum()
    };
    let mut worst: f64 = 0.0;
    let steps = 25_000; // 0.06 s of pushing, 0.44 s held
    let average_over = 2_500; // the last 0.05 s
    let (mut f_mean, mut c_mean) = (Vec3::zeros(), Vec3::zeros());
    for k in 0..steps {
        let p0 = momentum(&r);
        step_rod(&mut r, &s, k as f64 * s.dt, 0, k).unwrap();
        let f = v3(r.end_reaction_raw(0).unwrap().force);
        let c = contact_force(&r);
        let residual = f + c - p0 * spec.drag - (momentum(&r) - p0) / s.dt;
        worst = worst.max(residual.norm() / f.norm().max(1e-6));
        if k >= steps - average_over {
            f_mean += f / average_over as f64;
            c_mean += c / average_over as f64;
        }
    }
    assert!(worst < 1e-6, "momentum balance residual {worst:e} of |F|");
    let stats = r.collision_stats().unwrap();
    assert!(stats.contacts > 0, "the wire rests against the wall");
    // Contact impulses of a resting contact alternate between steps; compare time averages.
    let (f, c) = (f_mean, c_mean);
    assert!(f.x > 1e-4, "the wire pushes: F = {f:?}");
    // Along the push, 1 %: residual motion after 0.44 s of damping. Sideways the buckled
    // wire has not come to rest by then (its drag still carries ~1e-4 N); the per-step
    // balance above covers that direction exactly.
    assert!(
        (f.x + c.x).abs() < 0.01 * f.x,
        "pushing force {f:?} vs contact and friction {c:?}"
    );
}

/// A catheter (outer) and a guidewire (inner, softer) along x; the catheter's base is clamped
/// and a load at its tip bends it.
fn catheter_and_wire(
    variant: BindingVariant,
    ordering: Ordering,
) -> (Vec<CpuRod<f64>>, Coupling<f64>, SolverSettings<f64>) {
    let mut cath = RodSpec::new(Material::new(2e6, 2e6 / 3.0, 1100.0, 1.5e-3));
    cath.drag = 30.0;
    let mut wire = RodSpec::new(Material::new(2e5, 2e5 / 3.0, 1100.0, 1.5e-3));
    wire.drag = 30.0;
    let outer_pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.1, 20);
    // The wire starts 2 cm behind the catheter's base and ends 1 cm inside its tip.
    let inner_pts = straight_polyline([-0.02, 0.0, 0.0], [1.0, 0.0, 0.0], 0.11, 22);
    let mut outer = rod(
        &outer_pts,
        &cath,
        [EndCondition::clamped(), EndCondition::free()],
    );
    outer.loads.push(cosserat_backend_cpu::PointLoad::new(
        20,
        Vec3::new(0.0, 2e-4, 0.0),
    ));
    let inner = rod(
        &inner_pts,
        &wire,
        [EndCondition::free(), EndCondition::free()],
    );
    let rods = vec![outer, inner];
    let coupling = Coupling::new(
        &rods,
        &[BindingSpec {
            inner: 1,
            outer: 0,
            variant,
            capture: None,
        }],
        None,
    )
    .unwrap();
    (rods, coupling, settings(2e-5, Vec3::zeros(), ordering))
}

/// Distance of `p` from the polyline `line`.
fn distance_to(line: &[Vec3<f64>], p: Vec3<f64>) -> f64 {
    line.windows(2)
        .map(|w| {
            let e = w[1] - w[0];
            let u = ((p - w[0]).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
            (p - (w[0] + e * u)).norm()
        })
        .fold(f64::MAX, f64::min)
}

/// v1 and v2: the wire inside a straight catheter follows it when the catheter bends; v0: it
/// does not.
#[test]
fn a_bound_wire_follows_a_bending_catheter() {
    for (variant, ordering) in [
        (BindingVariant::OneWay, Ordering::RedBlack),
        (BindingVariant::TwoWay, Ordering::RedBlack),
        (BindingVariant::TwoWay, Ordering::GaussSeidel),
        (BindingVariant::None, Ordering::RedBlack),
    ] {
        let (mut rods, mut coupling, s) = catheter_and_wire(variant, ordering);
        let mut stats: Vec<StepStats> = Vec::new();
        step_coupled_batch(&mut rods, &mut coupling, &s, 0.0, 0, 5_000, &mut stats).unwrap();
        let outer = &rods[0].state.positions;
        let tip_y = outer[20].y;
        assert!(tip_y > 1e-3, "{variant:?}: the catheter bent ({tip_y} m)");
        // Wire points inside the catheter (points 4..=22 start at x = 0 ..= 0.09).
        let inside: Vec<Vec3<f64>> = rods[1].state.positions[4..=22].to_vec();
        let off = inside
            .iter()
            .map(|p| distance_to(outer, *p))
            .fold(0.0, f64::max);
        if variant == BindingVariant::None {
            assert!(off > 0.5 * tip_y, "{variant:?}: unbound wire stays: {off}");
        } else {
            // 1 % of the catheter's radius.
            assert!(off < 1.5e-5, "{variant:?}: wire {off} m off the centreline");
            // The part behind the base is outside the catheter and free (points 0..=3); the
            // point at the base itself may slide out of it.
            let bound = coupling.bound_points(0);
            assert!((18..=19).contains(&bound), "{variant:?}: {bound} bound");
        }
    }
}

/// Turning angle between elements `i` and `j > i`, over the arc between their middles.
fn curvature(points: &[Vec3<f64>], i: usize, j: usize) -> f64 {
    let (a, b) = (points[i + 1] - points[i], points[j + 1] - points[j]);
    let angle = a.normalize().dot(&b.normalize()).clamp(-1.0, 1.0).acos();
    let arc: f64 = points[i..=j + 1]
        .windows(2)
        .map(|w| (w[1] - w[0]).norm())
        .sum();
    angle / (arc - 0.5 * (a.norm() + b.norm()))
}

/// v2: a catheter with an intrinsic curvature κc and a straight wire bound inside it (all but
/// its end elements) settle at the curvature where their bending moments balance,
/// `κ = κc · EIc / (EIc + EIw)`: a stiff wire (EIw = 9 EIc) straightens the catheter to
/// 0.1 κc, a soft one (EIw = EIc / 9) leaves it at 0.9 κc. v1: the catheter ignores the wire.
#[test]
fn two_way_binding_bends_the_pair_in_proportion_to_stiffness() {
    let kappa_c = 10.0;
    let e_c = 1e5;
    for (variant, ratio) in [
        (BindingVariant::TwoWay, 9.0),
        (BindingVariant::TwoWay, 1.0 / 9.0),
        (BindingVariant::OneWay, 9.0),
    ] {
        let r = 2e-3;
        let mut cath = RodSpec::new(Material::new(e_c, e_c / 3.0, 1100.0, r));
        cath.rest_shape = RestShape::Uniform([kappa_c, 0.0, 0.0]);
        cath.drag = 30.0;
        let e_w = e_c * ratio;
        let mut wire = RodSpec::new(Material::new(e_w, e_w / 3.0, 1100.0, r));
        wire.rest_shape = RestShape::Uniform([0.0; 3]);
        wire.drag = 30.0;
        let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.1, 10);
        let wire_pts = straight_polyline([0.01, 0.0, 0.0], [1.0, 0.0, 0.0], 0.08, 8);
        let free = [EndCondition::free(), EndCondition::free()];
        let mut rods = vec![rod(&pts, &cath, free.clone()), rod(&wire_pts, &wire, free)];
        let mut coupling = Coupling::new(
            &rods,
            &[BindingSpec {
                inner: 1,
                outer: 0,
                variant,
                capture: Some(0.01),
            }],
            None,
        )
        .unwrap();
        let s = settings(4e-5, Vec3::zeros(), Ordering::RedBlack);
        let mut stats = Vec::new();
        step_coupled_batch(&mut rods, &mut coupling, &s, 0.0, 0, 12_500, &mut stats).unwrap();
        // Away from the wire's free ends, where the moments balance.
        let kappa = curvature(&rods[0].state.positions, 2, 7);
        let expected = match variant {
            BindingVariant::TwoWay => kappa_c / (1.0 + ratio),
            _ => kappa_c,
        };
        // 3 % of κc: the discrete curvature of 20 elements and the residual motion.
        assert!(
            (kappa - expected).abs() < 0.03 * kappa_c,
            "{variant:?}, EIw/EIc = {ratio}: κ = {kappa}, expected {expected}"
        );
    }
}

/// A rod whose rest shape is a flat double circle, started as a two-turn helix of pitch 4r:
/// the turns press onto each other. With self-contact no two non-neighbouring segments come
/// closer than the sum of the radii less 2 %; without, the turns pass through each other.
#[test]
fn a_tightly_wound_rod_does_not_pass_through_itself() {
    let r = 1e-3;
    let radius = 0.01;
    let n = 60;
    let helix = |pitch: f64| -> Vec<[f64; 3]> {
        (0..=n)
            .map(|i| {
                let phi = 4.0 * std::f64::consts::PI * i as f64 / n as f64;
                [
                    radius * phi.cos(),
                    radius * phi.sin(),
                    pitch * phi / (2.0 * std::f64::consts::PI),
                ]
            })
            .collect()
    };
    let mut spec = RodSpec::new(Material::new(1e6, 1e6 / 3.0, 1100.0, r));
    spec.drag = 20.0;
    // The rest Darboux vectors of the flat double circle (pitch 0).
    let (_, flat) = build_rod::<f64>(&helix(0.0), &spec).unwrap();
    let s = settings(2e-5, Vec3::zeros(), Ordering::RedBlack);
    for self_contact in [true, false] {
        let (state, mut params) = build_rod::<f64>(&helix(4.0 * r), &spec).unwrap();
        params.rest_darboux.clone_from(&flat.rest_darboux);
        let free = [EndCondition::free(), EndCondition::free()];
        let mut rods = vec![CpuRod::new(state, params, free, vec![])];
        let contact = self_contact.then(|| RodContactSpec {
            friction: Friction {
                static_coefficient: 0.2,
                kinetic_coefficient: 0.1,
            },
            ..RodContactSpec::default()
        });
        let mut coupling = Coupling::new(&rods, &[], contact).unwrap();
        let mut stats = Vec::new();
        let mut min_ratio = f64::MAX;
        for k in 0..50 {
            step_coupled_batch(
                &mut rods,
                &mut coupling,
                &s,
                k as f64 * 2e-3,
                k * 100,
                100,
                &mut stats,
            )
            .unwrap();
            min_ratio = min_ratio.min(min_pair_distance(&rods[0].state.positions, 2) / (2.0 * r));
        }
        if self_contact {
            let st = coupling.stats();
            // The same start without self-contact interpenetrates (below): these contacts are
            // what keeps the turns apart.
            assert!(st.max_contacts > 0, "the turns touch: {st:?}");
            assert!(
                min_ratio > 0.98,
                "closest non-neighbours at {min_ratio} × 2r"
            );
            assert!(st.min_separation_ratio > 0.98, "{st:?}");
        } else {
            assert!(min_ratio < 0.5, "without self-contact: {min_ratio} × 2r");
        }
    }
}

/// Smallest distance between segments `i`, `j` with `|i − j| > skip`.
fn min_pair_distance(p: &[Vec3<f64>], skip: usize) -> f64 {
    let a: Vec<[f64; 3]> = p.iter().map(|v| [v.x, v.y, v.z]).collect();
    let mut best = f64::MAX;
    for i in 0..a.len() - 1 {
        for j in i + skip + 1..a.len() - 1 {
            let (_, _, c1, c2) =
                cosserat_collide::rods::closest_points_segments(a[i], a[i + 1], a[j], a[j + 1]);
            let d = ((c1[0] - c2[0]).powi(2) + (c1[1] - c2[1]).powi(2) + (c1[2] - c2[2]).powi(2))
                .sqrt();
            best = best.min(d);
        }
    }
    best
}
