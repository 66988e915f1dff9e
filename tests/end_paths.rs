//! Held ends driven along keyframed paths, and held ends that slide along an axis, checked
//! against what they must do: a path is followed exactly whatever the step; a roller (an end
//! held across an axis, free along it) carries the beam-theory reaction of a propped
//! cantilever; a sliding clamp under a load stretches the rod by `F L / (E A)` and passes the
//! load to the other clamp; with the explicit scheme and with the stiff scheme at 1 ms. A free
//! end cannot slide.

use cosserat::cosserat_model::Material;
use cosserat::{EndCondition, EndPath, RodBuilder, SimulationBuilder, StateField, StiffSettings};

/// A clamped end follows a path that moves it across and turns it about the rod's axis, at two
/// steps that do not divide the keyframe times: at every step it is where the path says, and
/// after the last keyframe it holds still.
#[test]
fn a_clamped_end_follows_its_path_exactly() {
    let times = vec![0.0, 0.013, 0.05, 0.08];
    let displacement = vec![
        [0.0; 3],
        [0.0, 2e-3, 0.0],
        [0.0, 5e-3, -1e-3],
        [0.0, 5e-3, -1e-3],
    ];
    let rotation = vec![[0.0; 3], [0.3, 0.0, 0.0], [0.9, 0.0, 0.1], [1.2, 0.0, 0.1]];
    let path = EndPath::new(0.01, times, displacement, rotation).unwrap();
    for dt in [1e-4, 7e-5] {
        let rod = RodBuilder::straight(
            [0.0; 3],
            [1.0, 0.0, 0.0],
            0.2,
            10,
            Material::new(1e6, 1e6 / 3.0, 1000.0, 2e-3),
        )
        .damping(1e-10, 0.0, 5.0)
        .end(EndCondition::clamped().following(path.clone()));
        let mut sim = SimulationBuilder::new()
            .double_precision(true)
            .dt(dt)
            .gravity([0.0; 3])
            .with_rod(rod)
            .build()
            .unwrap();
        let h = sim.rods().next().unwrap();
        let mut d1 = vec![[0.0; 3]; 10];
        sim.read(h, StateField::Director(0), &mut d1).unwrap();
        let start = nalgebra::Vector3::from(d1[9]);
        let mut x = vec![[0.0; 3]; 11];
        let steps = (0.12 / dt) as u64;
        for _ in 0..steps {
            sim.step().unwrap();
            sim.read(h, StateField::Positions, &mut x).unwrap();
            let (d, _) = path.pose(sim.time());
            let expected = [0.2 + d[0], d[1], d[2]];
            let err = (0..3)
                .map(|c| (x[10][c] - expected[c]).abs())
                .fold(0.0, f64::max);
            assert!(
                err < 1e-12,
                "dt {dt}: end at {:?}, path says {expected:?} at t = {}",
                x[10],
                sim.time()
            );
        }
        // The clamp turned by the path's last rotation, and the rod's end frame, held by it,
        // with it.
        sim.read(h, StateField::Director(0), &mut d1).unwrap();
        let r = nalgebra::Rotation3::from_scaled_axis(nalgebra::Vector3::new(1.2, 0.0, 0.1));
        let expected = r * start;
        let got = nalgebra::Vector3::from(d1[9]);
        // The end frame sits half an element in from the clamp and follows it through the
        // clamp's node; with damping it has settled to within a few milliradians.
        assert!(
            got.angle(&expected) < 5e-3,
            "dt {dt}: end frame d1 {got:?}, clamp turned to {expected:?}"
        );
    }
}

/// A cantilever whose far end rests on a roller (held across the rod, free along it) under its
/// own weight: the roller carries 3/8 of the weight and the clamp the rest with a moment of
/// `w L² / 8` (Euler–Bernoulli; the rod is slender and stiff, so neither shear nor its sag of
/// 2e-4 of its length changes them). Explicit scheme at 8e-7 s, and the stiff scheme at 1 ms
/// (the roller's point held on its axis inside the solve, `stiff::pin_sliding_ends`).
#[test]
fn a_roller_carries_three_eighths_of_a_propped_cantilevers_weight() {
    let (length, n) = (0.1, 20);
    let m = Material::new(1e9, 1e9 / 3.0, 1000.0, 1e-3);
    let weight = m.linear_density() * length * 9.81;
    let omega1 =
        15.42 * (m.bend_twist_stiffness()[0] / (m.linear_density() * length.powi(4))).sqrt();
    for stiff in [false, true] {
        let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], length, n, m)
            .damping(0.0, 0.0, 2.0 * omega1)
            .clamp_start()
            .end(EndCondition::pinned().sliding_along([1.0, 0.0, 0.0].into()));
        let dt = if stiff { 1e-3 } else { 8e-7 };
        let mut sim = SimulationBuilder::new()
            .double_precision(true)
            .dt(dt)
            .gravity([0.0, 0.0, -9.81])
            .stiff_solver(stiff.then(StiffSettings::default))
            .with_rod(rod)
            .build()
            .unwrap();
        let h = sim.rods().next().unwrap();
        // 30 time constants of the first mode and 8 of the reported reaction's 50 Hz filter
        // (0.2 s at 1 ms, which the filter needs).
        let seconds = if stiff { 0.2 } else { 30.0 / omega1 };
        sim.run((seconds / dt) as u64).unwrap();
        let roller = sim.end_reaction(h, 1).unwrap();
        let clamp = sim.end_reaction(h, 0).unwrap();
        let share = roller.force[2] / weight;
        assert!(
            (share - 0.375).abs() < 0.375 * 5e-3,
            "stiff {stiff}: roller carries {share} of the weight (3/8 = 0.375)"
        );
        assert!(
            roller.force[0].abs() < 1e-6 * weight,
            "stiff {stiff}: the roller took an axial force {} N",
            roller.force[0]
        );
        let total = (roller.force[2] + clamp.force[2]) / weight;
        assert!(
            (total - 1.0).abs() < 1e-3,
            "stiff {stiff}: supports carry {total} of the weight"
        );
    }
}

/// An extensible rod between a clamp and a clamp that slides along the rod, pulled by a load on
/// the sliding end: it stretches by `F L / (E A)` and the fixed clamp holds `−F` (explicit
/// scheme at 2e-5 s, stiff scheme at 1 ms).
#[test]
fn a_sliding_clamp_passes_its_load_to_the_rod() {
    for stiff in [false, true] {
        sliding_clamp(stiff);
    }
}

fn sliding_clamp(stiff: bool) {
    let (length, n, force) = (0.5, 16, 0.03);
    let m = Material::new(1e6, 1e6 / 3.0, 1000.0, 1e-3);
    let ea = m.young_modulus * std::f64::consts::PI * 1e-6;
    let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], length, n, m)
        .damping(0.0, 0.0, 200.0)
        .clamp_start()
        .end(EndCondition::clamped().sliding_along([1.0, 0.0, 0.0].into()))
        .load(n, [force, 0.0, 0.0]);
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(if stiff { 1e-3 } else { 2e-5 })
        .stiff_solver(stiff.then(StiffSettings::default))
        .extensible(true)
        .gravity([0.0; 3])
        .with_rod(rod)
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    sim.run(if stiff { 400 } else { 20_000 }).unwrap();
    let mut x = vec![[0.0; 3]; n + 1];
    sim.read(h, StateField::Positions, &mut x).unwrap();
    let stretch = x[n][0] - length;
    let expected = force * length / ea;
    assert!(
        (stretch - expected).abs() < 1e-3 * expected,
        "stiff {stiff}: stretched by {stretch} m, F L / (E A) = {expected} m"
    );
    assert!(x[n][1].abs() < 1e-12 && x[n][2].abs() < 1e-12);
    let fixed = sim.end_reaction(h, 0).unwrap();
    assert!(
        (fixed.force[0] + force).abs() < 1e-3 * force,
        "stiff {stiff}: the fixed clamp holds {} N against the load's {force} N",
        fixed.force[0]
    );
}

/// The stiff scheme takes a sliding end through the control API, and follows a path; a free
/// end cannot slide.
#[test]
fn a_free_end_cannot_slide() {
    let m = Material::new(1e6, 1e6 / 3.0, 1000.0, 1e-3);
    let rod = || RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], 0.2, 8, m).clamp_start();
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(1e-3)
        .stiff_solver(Some(StiffSettings::default()))
        .with_rod(rod().end(EndCondition::pinned()))
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    sim.set_end_condition(
        h,
        1,
        EndCondition::pinned().sliding_along([1.0, 0.0, 0.0].into()),
    )
    .unwrap();
    sim.run(10).unwrap();
    let path = EndPath::new(
        0.0,
        vec![0.0, 1.0],
        vec![[0.0; 3], [0.0, 0.01, 0.0]],
        vec![[0.0; 3]; 2],
    )
    .unwrap();
    sim.set_end_condition(h, 1, EndCondition::pinned().following(path))
        .unwrap();
    sim.run(10).unwrap();
    let e = sim
        .set_end_condition(
            h,
            1,
            EndCondition::free().sliding_along([1.0, 0.0, 0.0].into()),
        )
        .unwrap_err()
        .to_string();
    assert!(e.contains("free end"), "{e}");
}

/// A path's keyframes are checked when it is made, with messages that say what is wrong.
#[test]
fn bad_paths_are_refused_with_the_reason() {
    let z = [0.0; 3];
    let cases = [
        (vec![0.0], vec![z], vec![z], "at least two"),
        (vec![0.1, 1.0], vec![z, z], vec![z, z], "starts at 0"),
        (vec![0.0, 0.0], vec![z, z], vec![z, z], "must increase"),
        (vec![0.0, 1.0], vec![z], vec![z, z], "one of each"),
        (vec![0.0, 1.0], vec![[1.0, 0.0, 0.0], z], vec![z, z], "zero"),
        (
            vec![0.0, 1.0],
            vec![z, [f64::NAN, 0.0, 0.0]],
            vec![z, z],
            "not finite",
        ),
    ];
    for (times, d, r, why) in cases {
        let e = EndPath::new(0.0, times.clone(), d, r).unwrap_err();
        assert!(e.contains(why), "{times:?}: {e}");
    }
}
