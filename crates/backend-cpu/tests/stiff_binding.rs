//! Bindings in the stiff scheme (`stiff/binding.rs`): a nitinol guidewire inside a polymer
//! catheter. Checked against beam theory (the pair bends as one composite beam in the two-way
//! variant, the catheter alone carries the load in the one-way variant), against the catheter
//! stepped alone (one-way), and for a wire pushed through a bent catheter (it follows the
//! centreline and slides freely).

use cosserat_backend_cpu::{
    BindingSpec, CpuRod, EndCondition, Ordering, PointLoad, PrescribedMotion, SolverSettings,
    StepStats, StiffBindings, StiffScratch, StiffSettings, step_bound_stiff,
};
use cosserat_constraints::BindingVariant;
use cosserat_model::presets::{Preset, preset};
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Real, Vec3};

fn settings<T: Real>(dt: f64) -> SolverSettings<T> {
    SolverSettings {
        dt: T::lit(dt),
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible: false,
        gravity: Vec3::zeros(),
        divergence_strain: T::lit(0.01),
    }
}

/// A rod of the preset's material along the polyline `points`, one element per segment.
fn rod<T: Real>(
    p: &Preset,
    points: &[[f64; 3]],
    drag: f64,
    ends: [EndCondition<T>; 2],
    loads: Vec<PointLoad<T>>,
) -> CpuRod<T> {
    let mut spec = RodSpec::new(p.material());
    spec.drag = drag;
    let (s, par) = build_rod::<T>(points, &spec).unwrap();
    CpuRod::new(s, par, ends, loads)
}

fn first_frequency(p: &Preset, length: f64) -> f64 {
    let m = p.material();
    1.87510407_f64.powi(2)
        * (m.bend_twist_stiffness()[0] / (m.linear_density() * length.powi(4))).sqrt()
}

/// Binds rod 1 inside rod 0 with `variant` and steps the pair `steps` times with the default
/// stiff settings; returns the bindings and the rods' scratches.
fn step_pair<T: Real>(
    rods: &mut [CpuRod<T>],
    variant: BindingVariant,
    settings: &SolverSettings<T>,
    steps: u64,
) -> (StiffBindings<T>, Vec<StiffScratch>) {
    let spec = BindingSpec {
        inner: 1,
        outer: 0,
        variant,
        capture: None,
    };
    let mut bindings = StiffBindings::new(rods, &[spec]).unwrap();
    let mut scratches = vec![StiffScratch::new(), StiffScratch::new()];
    let mut stats: Vec<StepStats> = Vec::new();
    step_bound_stiff(
        rods,
        &mut scratches,
        &mut bindings,
        settings,
        &StiffSettings::default(),
        0.0,
        0,
        steps,
        &mut stats,
    )
    .unwrap();
    (bindings, scratches)
}

/// Steps the rods bound by `variant` (rod 1 inside rod 0), checks that every step converged and
/// returns them.
fn run_bound<T: Real>(
    mut rods: Vec<CpuRod<T>>,
    variant: BindingVariant,
    dt: f64,
    steps: u64,
) -> Vec<CpuRod<T>> {
    let (_, scratches) = step_pair(&mut rods, variant, &settings::<T>(dt), steps);
    for s in &scratches {
        let r = s.report();
        assert_eq!(r.unconverged_steps, 0, "{r:?}");
    }
    rods
}

/// A catheter (`catheter-polymer`, length `L`) and a nitinol wire inside it along its first
/// three quarters, both clamped at the origin, a force `F` down on the catheter's tip; settled.
/// Returns the settled rods.
fn composite_rods(
    n: usize,
    variant: BindingVariant,
    dt: f64,
    force: f64,
    length: f64,
) -> Vec<CpuRod<f64>> {
    let (catheter, wire) = (
        preset("catheter-polymer").unwrap(),
        preset("nitinol").unwrap(),
    );
    let omega = first_frequency(catheter, length);
    let outer = rod::<f64>(
        catheter,
        &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], length, n),
        2.0 * omega,
        [EndCondition::clamped(), EndCondition::free()],
        vec![PointLoad::new(n, Vec3::new(0.0, 0.0, -force))],
    );
    let inner = rod::<f64>(
        wire,
        &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.75 * length, 3 * n / 4),
        2.0 * omega,
        [EndCondition::clamped(), EndCondition::free()],
        vec![],
    );
    let steps = (40.0 / omega / dt).ceil().max(100.0) as u64;
    run_bound(vec![outer, inner], variant, dt, steps)
}

/// The tip deflection of [`composite_rods`].
fn composite_tip(n: usize, variant: BindingVariant, dt: f64, force: f64, length: f64) -> f64 {
    -composite_rods(n, variant, dt, force, length)[0]
        .state
        .positions[n]
        .z
}

/// Two-way, the catheter and the wire bend together where the wire is: the tip deflection of
/// a cantilever whose bending stiffness is `EI_c + EI_w` over `[0, L_w]` and `EI_c` beyond,
/// `F/3 ((L³ − (L − L_w)³)/(EI_c + EI_w) + (L − L_w)³/EI_c)`. One-way, the catheter alone:
/// `F L³/(3 EI_c)`. The clamp makes the discrete rods first-order accurate in the element
/// length; the Richardson extrapolation of 20 and 40 elements must match within 2e-3, at dt
/// 1e-3 and 1e-4 (the two-way coupling lags a step, which at rest changes nothing).
#[test]
fn a_wire_stiffens_its_catheter_two_way_and_not_one_way() {
    let ei_c = preset("catheter-polymer")
        .unwrap()
        .material()
        .bend_twist_stiffness()[0];
    let ei_w = preset("nitinol").unwrap().material().bend_twist_stiffness()[0];
    let length = 0.1;
    // Deflection 0.1 % of the length.
    let force = 1e-3 * 3.0 * ei_c / (length * length);
    let rest = 0.25 * length;
    let two_way =
        force / 3.0 * ((length.powi(3) - rest.powi(3)) / (ei_c + ei_w) + rest.powi(3) / ei_c);
    let one_way = force * length.powi(3) / (3.0 * ei_c);
    // The two answers differ by far more than the tolerance.
    assert!(one_way / two_way - 1.0 > 0.05);
    for dt in [1e-3, 1e-4] {
        for (variant, expected) in [
            (BindingVariant::TwoWay, two_way),
            (BindingVariant::OneWay, one_way),
        ] {
            let (coarse, fine) = (
                composite_tip(20, variant, dt, force, length),
                composite_tip(40, variant, dt, force, length),
            );
            let extrapolated = 2.0 * fine - coarse;
            let err = extrapolated / expected - 1.0;
            assert!(
                err.abs() < 2e-3,
                "{variant:?} dt {dt}: tips {coarse:e}, {fine:e}, extrapolated {extrapolated:e} \
                 vs {expected:e} ({err:e})"
            );
        }
    }
}

/// One-way, the catheter does not feel the wire: it moves exactly as when stepped alone, bit
/// for bit, while the wire inside it follows.
#[test]
fn one_way_leaves_the_catheter_as_it_is_alone() {
    let (catheter, wire) = (
        preset("catheter-polymer").unwrap(),
        preset("nitinol").unwrap(),
    );
    let n = 30;
    // Pinned at its start and released horizontal under gravity: it swings.
    let make_outer = || {
        rod::<f64>(
            catheter,
            &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.3, n),
            0.0,
            [EndCondition::pinned(), EndCondition::free()],
            vec![],
        )
    };
    let inner = rod::<f64>(
        wire,
        &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.2, 25),
        0.0,
        [EndCondition::free(), EndCondition::free()],
        vec![],
    );
    let gravity = Vec3::new(0.0, 0.0, -9.81);
    let s = SolverSettings {
        gravity,
        ..settings::<f64>(1e-3)
    };
    let stiff = StiffSettings::default();
    let mut rods = vec![make_outer(), inner];
    let (bindings, _) = step_pair(&mut rods, BindingVariant::OneWay, &s, 200);
    let mut alone = make_outer();
    cosserat_backend_cpu::step_rod_stiff(
        &mut alone,
        &s,
        &stiff,
        &mut StiffScratch::new(),
        0.0,
        0,
        0,
        200,
    )
    .unwrap();
    assert_eq!(rods[0].state.positions, alone.state.positions);
    assert_eq!(rods[0].state.frames, alone.state.frames);
    // The catheter has swung down by a good part of its length; the wire went with it and
    // lies on its centreline.
    assert!(
        alone.state.positions[n].z < -0.05,
        "{}",
        alone.state.positions[n]
    );
    assert_eq!(bindings.bound_points(0), 26);
    // The wire's ends are free: nothing to warn about.
    assert_eq!(bindings.stats().held_ends_inside, 0);
    let gap = largest_offset(&rods[1].state.positions, &rods[0].state.positions);
    assert!(gap < 1e-3 * 0.2 / 25.0, "largest offset {gap:e} m");
}

/// The largest distance of a point of `inner` from the polyline `outer` [m].
fn largest_offset<T: Real>(inner: &[Vec3<T>], outer: &[Vec3<T>]) -> f64 {
    let f = |v: &Vec3<T>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
    inner
        .iter()
        .map(|p| {
            let p = f(p);
            outer
                .windows(2)
                .map(|s| {
                    let (a, b) = (f(&s[0]), f(&s[1]));
                    let e = b - a;
                    let u = ((p - a).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
                    (p - (a + e * u)).norm()
                })
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max)
}

/// The point at arc length `at` along the polyline `line` [m].
fn along<T: Real>(line: &[Vec3<T>], mut at: f64) -> Vec3<f64> {
    let f = |v: &Vec3<T>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
    for s in line.windows(2) {
        let (a, b) = (f(&s[0]), f(&s[1]));
        let l = (b - a).norm();
        if at <= l {
            return a + (b - a) * (at / l);
        }
        at -= l;
    }
    f(line.last().unwrap())
}

/// A wire pushed at 5 cm/s into a catheter held at both ends, straight for 5 cm and then bent
/// through 60° on a radius of 5 cm, slides through it: after 1.2 s its held end has advanced
/// 6 cm (still outside the catheter, as a hand at the hub) and its tip, which started 4 cm
/// along the catheter, is 10 cm along it, 5 cm into the bend (the wire is inextensible and
/// follows the centreline); every point inside lies on the centreline. In f32 and f64, at
/// 1 ms, two-way (the wire bends the catheter a little).
#[test]
fn a_pushed_wire_slides_through_a_bent_catheter() {
    fn run<T: Real>() {
        let (catheter, wire) = (
            preset("catheter-polymer").unwrap(),
            preset("nitinol").unwrap(),
        );
        // Catheter: elements of 2.5 mm; 5 cm along x, the arc, 5 cm straight.
        let (radius, dl) = (0.05, 2.5e-3);
        let mut pts: Vec<[f64; 3]> = (0..=20).map(|i| [i as f64 * dl, 0.0, 0.0]).collect();
        let arc = radius * std::f64::consts::FRAC_PI_3;
        let steps = (arc / dl).round() as usize;
        for i in 1..=steps {
            let phi = std::f64::consts::FRAC_PI_3 * i as f64 / steps as f64;
            pts.push([0.05 + radius * phi.sin(), radius * (1.0 - phi.cos()), 0.0]);
        }
        let end = pts[pts.len() - 1];
        let dir = [0.5, 3.0_f64.sqrt() / 2.0];
        pts.extend((1..=20).map(|i| {
            let d = i as f64 * dl;
            [end[0] + d * dir[0], end[1] + d * dir[1], 0.0]
        }));
        let outer = {
            let mut spec = RodSpec::new(catheter.material());
            spec.rest_shape = cosserat_model::rod::RestShape::Initial;
            let (st, par) = build_rod::<T>(&pts, &spec).unwrap();
            CpuRod::new(
                st,
                par,
                [EndCondition::clamped(), EndCondition::clamped()],
                vec![],
            )
        };
        // Wire: 11 cm along x from 7 cm behind the catheter's start, 110 elements of 1 mm,
        // pushed at its start.
        let motion = PrescribedMotion {
            velocity: Vec3::new(T::lit(0.05), T::zero(), T::zero()),
            angular_velocity: Vec3::zeros(),
            start_time: 0.0,
            end_time: f64::INFINITY,
        };
        let inner = rod::<T>(
            wire,
            &straight_polyline([-0.07, 0.0, 0.0], [1.0, 0.0, 0.0], 0.11, 110),
            5.0,
            [EndCondition::clamped().driven(motion), EndCondition::free()],
            vec![],
        );
        let rods = run_bound(vec![outer, inner], BindingVariant::TwoWay, 1e-3, 1200);
        let (cat, w) = (&rods[0].state.positions, &rods[1].state.positions);
        let f = |v: &Vec3<T>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
        assert!((f(&w[0]).x + 0.01).abs() < 1e-6, "{}", f(&w[0]));
        let tip = f(&w[110]);
        let expected = along(cat, 0.10);
        // Into the bend: the catheter turned the wire by about a radian.
        assert!(expected.y > 0.02, "{expected}");
        assert!(
            (tip - expected).norm() < 5e-5,
            "tip {tip}, expected {expected}"
        );
        // Every point inside (past the catheter's start) lies on its centreline.
        let inside: Vec<_> = w.iter().filter(|p| f(p).x > 1e-3).copied().collect();
        let gap = largest_offset(&inside, cat);
        assert!(gap < 2e-5, "largest offset {gap:e} m");
    }
    run::<f64>();
    run::<f32>();
}

/// A wire clamped at its catheter's clamp has its held end inside the catheter at every step,
/// the configuration in which the two-way coupling can be unstable: the bindings count those
/// steps (the command line turns the count into a warning).
#[test]
fn a_held_end_inside_the_catheter_is_counted() {
    let (catheter, wire) = (
        preset("catheter-polymer").unwrap(),
        preset("nitinol").unwrap(),
    );
    let outer = rod::<f64>(
        catheter,
        &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.1, 20),
        0.0,
        [EndCondition::clamped(), EndCondition::free()],
        vec![],
    );
    let inner = rod::<f64>(
        wire,
        &straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.05, 10),
        0.0,
        [EndCondition::clamped(), EndCondition::free()],
        vec![],
    );
    let mut rods = vec![outer, inner];
    let (bindings, _) = step_pair(&mut rods, BindingVariant::TwoWay, &settings::<f64>(1e-3), 5);
    assert_eq!(bindings.stats().held_ends_inside, 5);
    assert_eq!(bindings.stats().steps, 5);
}

/// What the hands feel: at rest, two-way, the clamps of the catheter and of the wire bound in
/// it together hold the catheter's tip load, `F_c + F_w = −F_tip`, and its moment about their
/// common clamp point, and the wire's clamp takes a real share (the lines pass it from the
/// catheter to the wire). One-way the catheter does not feel the wire, so its clamp alone holds
/// the load and its moment (the wire's clamp then holds the wire against the lines, a force
/// that acts on nothing else). Fails if the binding's loads on the catheter are not those the
/// lines put on the wire, or are left out of the clamp's reaction.
#[test]
fn the_clamps_of_a_bound_pair_hold_the_load_together() {
    let length = 0.1;
    let ei_c = preset("catheter-polymer")
        .unwrap()
        .material()
        .bend_twist_stiffness()[0];
    let force = 1e-3 * 3.0 * ei_c / (length * length);
    for variant in [BindingVariant::TwoWay, BindingVariant::OneWay] {
        let rods = composite_rods(20, variant, 1e-3, force, length);
        let reaction = |r: &CpuRod<f64>| r.end_reaction_raw(0).expect("a clamped end");
        let (c, w) = (reaction(&rods[0]), reaction(&rods[1]));
        let (force_held, torque_held) = match variant {
            BindingVariant::TwoWay => (
                [0, 1, 2].map(|k| c.force[k] + w.force[k]),
                c.torque[1] + w.torque[1],
            ),
            _ => (c.force, c.torque[1]),
        };
        // The holder pushes up by the load ...
        let expected = [0.0, 0.0, force];
        for k in 0..3 {
            assert!(
                (force_held[k] - expected[k]).abs() < 1e-6 * force,
                "{variant:?}: clamp forces {:?}, {:?}: held {force_held:?}, expected {expected:?}",
                c.force,
                w.force
            );
        }
        // ... and balances the load's moment about the clamps, `(r_tip × (−F ẑ))_y = x_tip F`.
        let tip = rods[0].state.positions[20];
        let moment = -tip.x * force;
        assert!(
            (torque_held - moment).abs() < 1e-4 * moment.abs(),
            "{variant:?}: clamp torques {:?}, {:?}: held {torque_held}, expected {moment}",
            c.torque,
            w.torque
        );
        if variant == BindingVariant::TwoWay {
            let share = w.force[2] / force;
            assert!(share > 0.01, "the wire's clamp holds {share} of the load");
        }
    }
}
