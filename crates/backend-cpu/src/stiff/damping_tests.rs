//! Internal damping of the stiff scheme against the damped oscillator that the model's
//! damping definition gives the first bending mode of a cantilever (and the first axial mode
//! of a bar), discretised by implicit Euler as the scheme is.
//!
//! The model (`cosserat_model::energy`) dissipates `½ c_b |ω_b − ω_a|² / l̄` per node and
//! `½ c_s l0 ε̇²` per element: a Kelvin–Voigt rod whose bending moment is `EI κ + c_b κ̇` and
//! axial force `K_s ε + c_s ε̇`. Each mode of frequency `ω` is then an oscillator
//! `q̈ + 2σ q̇ + ω² q = 0` with `σ = c ω² / (2 K)` (`K = EI` or `K_s`). Implicit Euler
//! (`v' = v + h a(x', v')`, `x' = x + h v'`) maps such an oscillator by a matrix of
//! determinant `1 / (1 + 2σh + h²ω²)`, so the amplitude decays at the rate
//! `ln(1 + 2σh + h²ω²) / (2h)` per second: the damping plus the scheme's own dissipation.

use super::*;
use crate::Ordering;
use crate::stepper::PointLoad;
use cosserat_model::presets::preset;
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_problem::ends::EndCondition;

fn settings(dt: f64, extensible: bool) -> SolverSettings<f64> {
    SolverSettings {
        dt,
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible,
        gravity: Vec3::zeros(),
        divergence_strain: 0.01,
    }
}

/// Decay rate [1/s] and angular frequency of the tip's motion along `axis` about `rest`,
/// from the extrema of one sign after the first `skip` of them (higher modes die first).
fn decay(tip: &[f64], rest: f64, dt: f64, skip: usize) -> (f64, f64) {
    let d: Vec<f64> = tip.iter().map(|z| z - rest).collect();
    // Extrema of the first sample's sign (the release), at the sample (the period is
    // hundreds of steps).
    let sign = d[0].signum();
    let peaks: Vec<(f64, f64)> = (1..d.len() - 1)
        .filter(|&k| {
            let (a, b, c) = (sign * d[k - 1], sign * d[k], sign * d[k + 1]);
            b > 0.0 && b >= a && b > c
        })
        .map(|k| {
            // Parabola through the three samples.
            let (a, b, c) = (d[k - 1], d[k], d[k + 1]);
            let den = a - 2.0 * b + c;
            let off = if den != 0.0 { 0.5 * (a - c) / den } else { 0.0 };
            ((k as f64 + off) * dt, (b - 0.25 * (a - c) * off).abs())
        })
        .collect();
    assert!(peaks.len() >= skip + 2, "{} extrema", peaks.len());
    let (first, last) = (peaks[skip], peaks[peaks.len() - 1]);
    let periods = (peaks.len() - 1 - skip) as f64;
    let rate = (first.1 / last.1).ln() / (last.0 - first.0);
    (
        rate,
        2.0 * std::f64::consts::PI * periods / (last.0 - first.0),
    )
}

/// Implicit Euler's decay rate of `q̈ + 2σ q̇ + ω² q = 0` at step `h`.
fn implicit_euler_rate(sigma: f64, omega: f64, h: f64) -> f64 {
    (1.0 + 2.0 * sigma * h + h * h * omega * omega).ln() / (2.0 * h)
}

/// Which first mode of a steel rod (0.5 m, 20 elements, clamped at one end, free at the
/// other) is released.
#[derive(Clone, Copy)]
enum Mode {
    /// Bending, released from a tip-load deflection; inextensible.
    Bending,
    /// Axial (extensible mode), released from a tip pull.
    Axial,
}

/// Runs the rod released from a static tip load with damping coefficient `c` (`c_b` or
/// `c_s`), settled at step `settle_dt` (statics do not depend on the step) and released at
/// `dt`; returns the measured decay rate and angular frequency of the tip, and the stiffness
/// `K` of the mode (`EI` or `K_s`).
fn released_decay(mode: Mode, c: f64, settle_dt: f64, dt: f64) -> (f64, f64, f64) {
    let p = preset("steel").unwrap();
    let m = p.material();
    let (length, n): (f64, usize) = (0.5, 20);
    let (k, omega) = match mode {
        Mode::Bending => {
            let ei = m.bend_twist_stiffness()[0];
            let w = 1.87510407_f64.powi(2) * (ei / (m.linear_density() * length.powi(4))).sqrt();
            (ei, w)
        }
        Mode::Axial => {
            let ks = m.stretch_stiffness();
            let w = 0.5 * std::f64::consts::PI / length * (ks / m.linear_density()).sqrt();
            (ks, w)
        }
    };
    let mut spec = RodSpec::new(m);
    spec.drag = 4.0 * omega;
    match mode {
        Mode::Bending => spec.bend_damping = c,
        Mode::Axial => spec.stretch_damping = c,
    }
    let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], length, n);
    let (s, par) = build_rod::<f64>(&pts, &spec).unwrap();
    let force = match mode {
        Mode::Bending => Vec3::new(0.0, 0.0, -1e-3 * 3.0 * k / (length * length)),
        Mode::Axial => Vec3::new(1e-4 * k, 0.0, 0.0),
    };
    let load = PointLoad::new(n, force);
    let ends = [EndCondition::clamped(), EndCondition::free()];
    let mut rod = CpuRod::new(s, par, ends, vec![load]);
    let extensible = matches!(mode, Mode::Axial);
    let stiff = StiffSettings::default();
    let mut scratch = StiffScratch::new();
    let settle = (20.0 / omega / settle_dt).ceil() as u64;
    let s = settings(settle_dt, extensible);
    step_rod_stiff(&mut rod, &s, &stiff, &mut scratch, 0.0, 0, 0, settle).unwrap();
    let s = settings(dt, extensible);
    rod.loads.clear();
    rod.params.drag = 0.0;
    let period = 2.0 * std::f64::consts::PI / omega;
    let steps = (4.0 * period / dt).ceil() as u64;
    let tip = |rod: &CpuRod<f64>| match mode {
        Mode::Bending => rod.state.positions[n].z,
        Mode::Axial => rod.state.positions[n].x,
    };
    let mut z = vec![tip(&rod)];
    for step in 0..steps {
        step_rod_stiff(&mut rod, &s, &stiff, &mut scratch, 0.0, 0, step, 1).unwrap();
        z.push(tip(&rod));
    }
    let rest = match mode {
        Mode::Bending => 0.0,
        Mode::Axial => length,
    };
    let (rate, w) = decay(&z, rest, dt, 1);
    (rate, w, k)
}

/// Checks the decay of `mode` with damping ratio 0.05 at step `dt` against
/// `σ = c ω² / (2K)` through implicit Euler, with `ω` the frequency measured on the undamped
/// rod (the discrete rod's) at the step `undamped_dt`; with `check_undamped`, also that
/// undamped rod's decay (the scheme's own dissipation) against implicit Euler's at
/// `undamped_dt`. Both rods settle at `undamped_dt`.
fn check(mode: Mode, undamped_dt: f64, dt: f64, check_undamped: bool, tolerance: f64) {
    let (rate0, omega, k) = released_decay(mode, 0.0, undamped_dt, undamped_dt);
    let expected0 = implicit_euler_rate(0.0, omega, undamped_dt);
    let c = 2.0 * 0.05 * k / omega;
    let (rate, _, _) = released_decay(mode, c, undamped_dt, dt);
    let sigma = c * omega * omega / (2.0 * k);
    let expected = implicit_euler_rate(sigma, omega, dt);
    let name = match mode {
        Mode::Bending => "bending",
        Mode::Axial => "axial",
    };
    eprintln!(
        "{name} dt {dt:e}: ω {omega:.2}; undamped rate at dt {undamped_dt:e} {rate0:.4} \
         (implicit Euler {expected0:.4}), \
         damped {rate:.4} (expected {expected:.4}, of which damping σ = {sigma:.4})"
    );
    if check_undamped {
        assert!(
            (rate0 / expected0 - 1.0).abs() < 0.05,
            "{name}: undamped decay {rate0} vs {expected0}"
        );
    }
    assert!(
        (rate / expected - 1.0).abs() < tolerance,
        "{name}: damped decay {rate} vs {expected}"
    );
}

/// Bending damping (`c_b`): the first mode of a released cantilever decays at the rate of the
/// model's definition through implicit Euler. At `dt = 1e-3` (`hω = 0.016`) the scheme's own
/// dissipation is about a seventh of the total and is checked too; at `dt = 2e-4` it is 3 %
/// of the total (the undamped rod's decay over four periods would be too small to measure
/// against its higher modes: `ω` is taken from the run at 1e-3).
#[test]
fn bending_damping_decays_the_first_mode_at_the_model_rate() {
    check(Mode::Bending, 1e-3, 1e-3, true, 0.02);
    check(Mode::Bending, 1e-3, 2e-4, false, 0.02);
}

/// Stretching damping (`c_s`, extensible mode): the first axial mode of a bar released from a
/// tip pull decays at the rate of the model's definition through implicit Euler. A tip pull
/// (uniform strain) carries a ninth of the first mode's amplitude in the second (`3ω`); with
/// damping it decays nine times faster than the first and is gone after the skipped period,
/// without it it is not (the undamped rod's decay is printed, not checked).
#[test]
fn stretch_damping_decays_the_first_axial_mode_at_the_model_rate() {
    check(Mode::Axial, 1e-6, 1e-6, false, 0.02);
}
