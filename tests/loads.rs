//! Moments and time-varying loads, against what they must do: a cantilever with a pure moment
//! at its free end bends into a circular arc of radius `E I / M` (exact, shear or not); a tip
//! force ramped slowly is carried by the clamp as it rises.

use cosserat::cosserat_model::Material;
use cosserat::{
    LoadProfile, PointLoad, RodBuilder, RodHandle, Simulation, SimulationBuilder, StateField,
    StiffSettings,
};

/// The tip of a cantilever of `n` elements, `length` long along x, clamped at the origin, with
/// the moment `m` about y at point `at`, after `seconds`; explicit or stiff scheme.
fn arc_tip(n: usize, at: usize, m: f64, stiff: bool, seconds: f64) -> ([f64; 3], f64) {
    let length: f64 = 0.1;
    let material = Material::new(1e6, 1e6 / 3.0, 1000.0, 2e-3);
    let ei = material.bend_twist_stiffness()[0];
    let omega1 = 3.516 * (ei / (material.linear_density() * length.powi(4))).sqrt();
    let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], length, n, material)
        .damping(0.0, 0.0, 2.0 * omega1)
        .clamp_start()
        .load_with(PointLoad::new(at, [0.0; 3].into()).with_moment([0.0, m, 0.0].into()));
    let dt = if stiff { 1e-3 } else { 5e-5 };
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .gravity([0.0; 3])
        .stiff_solver(stiff.then(StiffSettings::default))
        .dt(dt)
        .with_rod(rod)
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    sim.run((seconds / dt) as u64).unwrap();
    let mut x = vec![[0.0; 3]; n + 1];
    sim.read(h, StateField::Positions, &mut x).unwrap();
    (x[n], ei)
}

/// `rod` alone, weightless, on the stiff scheme at 1 ms, in f64.
fn stiff_weightless(rod: RodBuilder) -> (Simulation, RodHandle) {
    let sim = SimulationBuilder::new()
        .double_precision(true)
        .gravity([0.0; 3])
        .stiff_solver(Some(StiffSettings::default()))
        .dt(1e-3)
        .with_rod(rod)
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    (sim, h)
}

/// `M` about y turns the tip by `θ = M L / (E I)` = 1 rad about y, so it ends at
/// `(R sin θ, 0, −R (1 − cos θ))`, `R = E I / M`: within 1e-3 of `R` with 20 elements (2.0e-4
/// measured), with the explicit scheme and with the stiff scheme at 1 ms (where the moment is a
/// term of the end frame's implicit equation, `stiff/work.rs`).
#[test]
fn an_end_moment_bends_a_cantilever_into_a_circle() {
    let (_, ei) = arc_tip(2, 2, 0.0, false, 0.0);
    let m = ei / 0.1;
    for stiff in [false, true] {
        let (tip, _) = arc_tip(20, 20, m, stiff, 3.0);
        let r = ei / m;
        let expected = [r * 1f64.sin(), 0.0, -r * (1.0 - 1f64.cos())];
        let err = (0..3)
            .map(|c| (tip[c] - expected[c]).abs())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-3 * r,
            "stiff {stiff}: tip {tip:?}, the circle's {expected:?} (error {:.2e} R)",
            err / r
        );
    }
}

/// A moment at an interior point acts half on each frame beside it: the rod beyond it stays
/// straight, the part before it bends into the arc of `R = E I / M` by `M L / (2 E I)` (the
/// clamp's half node, nine whole nodes and half of the node at the point, which carries half
/// the moment), within 1e-3 of `R` (1.4e-4 measured), with both schemes (the stiff one at
/// 1 ms), which agree on the tip within 1e-6 of `R` (5e-8 measured).
#[test]
fn a_moment_at_the_middle_bends_only_the_first_half() {
    let (_, ei) = arc_tip(2, 2, 0.0, false, 0.0);
    let m = ei / 0.1;
    let (explicit, _) = arc_tip(20, 10, m, false, 3.0);
    let (stiff, _) = arc_tip(20, 10, m, true, 3.0);
    let r = ei / m;
    // The first half, 0.05 m, turns by 0.5 rad; the second half goes on straight along its end
    // tangent.
    let (theta, half) = (0.5_f64, 0.05);
    let expected = [
        r * theta.sin() + half * theta.cos(),
        0.0,
        -r * (1.0 - theta.cos()) - half * theta.sin(),
    ];
    let gap = |a: [f64; 3], b: [f64; 3]| (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0, f64::max);
    for (name, tip) in [("explicit", explicit), ("stiff", stiff)] {
        let err = gap(tip, expected);
        assert!(
            err < 1e-3 * r,
            "{name}: tip {tip:?}, expected {expected:?} (error {:.2e} R)",
            err / r
        );
    }
    let apart = gap(explicit, stiff);
    assert!(
        apart < 1e-6 * r,
        "explicit {explicit:?} and stiff {stiff:?} tips {:.2e} R apart",
        apart / r
    );
}

/// A tip force ramped from 0 to 1 N over 4 s is carried by the clamp as it rises: at 1, 2 and
/// 3 s the clamp holds a quarter, a half and three quarters of it (stiff scheme, 1 ms).
#[test]
fn a_ramped_load_is_carried_as_it_rises() {
    let (length, n) = (0.1, 10);
    let material = Material::new(1e9, 1e9 / 3.0, 1000.0, 2e-3);
    let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], length, n, material)
        .damping(0.0, 0.0, 50.0)
        .clamp_start()
        .load_with(
            PointLoad::new(n, [0.0, 0.0, -1.0].into()).with_profile(LoadProfile::Ramp {
                start: 0.0,
                duration: 4.0,
            }),
        );
    let (mut sim, h) = stiff_weightless(rod);
    for quarter in 1..=3 {
        sim.run(1000).unwrap();
        let held = sim.end_reaction(h, 0).unwrap().force[2];
        let expected = 0.25 * quarter as f64;
        assert!(
            (held - expected).abs() < 1e-2 * expected,
            "at {} s the clamp holds {held} N, the load is {expected} N",
            sim.time()
        );
    }
}

/// A uniform load along a cantilever (no gravity) sags it as beam theory says,
/// `q L⁴ / (8 E I)` plus the shear of the parallel penalty `q L² / (2 G A)` (stiff scheme,
/// 40 elements; the small-deflection case of `docs/validation.md`'s cantilever).
#[test]
fn a_distributed_load_sags_a_cantilever_as_beam_theory_says() {
    let (length, n, q) = (0.1, 40, 0.02);
    let material = Material::new(6e10, 6e10 / 2.66, 6450.0, 2e-4);
    let ei = material.bend_twist_stiffness()[0];
    let ga = material.shear_stiffness();
    let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], length, n, material)
        .damping(0.0, 0.0, 30.0)
        .clamp_start()
        .distributed_load(PointLoad::new(0, [0.0, 0.0, -q].into()));
    let (mut sim, h) = stiff_weightless(rod);
    sim.run(3000).unwrap();
    let mut x = vec![[0.0; 3]; n + 1];
    sim.read(h, StateField::Positions, &mut x).unwrap();
    let expected = q * length.powi(4) / (8.0 * ei) + q * length * length / (2.0 * ga);
    assert!(
        (-x[n][2] - expected).abs() < 2e-3 * expected,
        "tip sags {} m, beam theory {expected} m",
        -x[n][2]
    );
    let held = sim.end_reaction(h, 0).unwrap().force[2];
    assert!(
        (held - q * length).abs() < 1e-3 * q * length,
        "the clamp holds {held} N"
    );
}
