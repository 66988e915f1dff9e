//! `cosserat::convergence`: the error a study estimates for each run, against the error measured
//! against a much finer run of the same scene.

use cosserat::Simulation;
use cosserat::convergence::{Convergence, Refinement, StudyError, study};
use cosserat::scene::load_scene;
use std::path::PathBuf;

fn pendulum_scene() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/pendulum.toml")
}

/// The shipped pendulum with `sets` (scene keys and TOML values) applied, in `f64`.
fn pendulum(sets: &[(&str, String)]) -> Result<Simulation, String> {
    let mut overrides: Vec<(String, String)> = vec![("solver.precision".into(), "\"f64\"".into())];
    overrides.extend(sets.iter().map(|(k, v)| (k.to_string(), v.clone())));
    let (builder, _, _) = load_scene(&pendulum_scene(), &overrides).map_err(|e| e.to_string())?;
    builder.build().map_err(|e| e.to_string())
}

fn run_to_end(sim: Simulation, steps: u64) -> Vec<[f64; 3]> {
    run_through(sim, steps, 1).pop().unwrap()
}

/// The rod's points after each of `checkpoints` equal parts of `steps`.
fn run_through(mut sim: Simulation, steps: u64, checkpoints: u64) -> Vec<Vec<[f64; 3]>> {
    (0..checkpoints)
        .map(|_| {
            sim.run(steps / checkpoints)
                .expect("the reference run does not diverge");
            sim.positions(cosserat::RodHandle(0))
        })
        .collect()
}

/// Largest distance between `coarse` and the points `stride·j` of `fine`.
fn largest_distance(coarse: &[[f64; 3]], fine: &[[f64; 3]], stride: usize) -> f64 {
    coarse
        .iter()
        .enumerate()
        .map(|(j, a)| {
            let b = fine[j * stride];
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

/// A study's estimated error of run `k` is within 15 % of `measured(k)`, its largest distance
/// from a much finer run.
fn assert_estimates(what: &str, q: &Convergence, mut measured: impl FnMut(usize) -> f64) {
    let estimates = q.estimated_errors.as_ref().expect("asymptotic");
    for (k, estimate) in estimates.iter().enumerate() {
        let actual = measured(k);
        let ratio = estimate / actual;
        assert!(
            (0.85..1.15).contains(&ratio),
            "{what}, run {k}: estimated {estimate:e}, measured {actual:e} (order {:?})",
            q.grid.observed_order
        );
    }
}

/// Halving the explicit scheme's step: the estimated error of every run is within 15 % of its
/// largest distance, over five checkpoints, from a run at a 64th of the first step (whose own
/// error is about 1/64 of the first run's).
#[test]
fn time_refinement_estimates_the_error_of_every_run() {
    let (dt, steps, elements, checkpoints) = (5e-5, 1000u64, 20usize, 5u64);
    let base = [
        ("rod.0.elements", elements.to_string()),
        ("solver.scheme", "\"explicit\"".to_string()),
    ];
    let at = |factor: u32| {
        let mut sets = base.to_vec();
        sets.push(("solver.dt", format!("{:e}", dt / f64::from(factor))));
        pendulum(&sets)
    };
    let s = study(Refinement::Time, 3, steps, checkpoints as usize, at).unwrap();
    let times: Vec<f64> = (1..=5).map(|c| c as f64 * 0.01).collect();
    assert_eq!(s.checkpoint_times.len(), 5);
    for (t, expected) in s.checkpoint_times.iter().zip(&times) {
        assert!((t - expected).abs() < 1e-12, "{:?}", s.checkpoint_times);
    }
    let reference = run_through(at(64).unwrap(), steps * 64, checkpoints);
    let rod = &s.rods[0].positions;
    let p = rod.grid.observed_order.unwrap();
    assert!((0.8..1.2).contains(&p), "observed order {p}");
    assert_estimates("positions", rod, |k| {
        let run = run_through(at(1 << k).unwrap(), steps << k, checkpoints);
        run.iter()
            .zip(&reference)
            .map(|(a, b)| largest_distance(a, b, 1))
            .fold(0.0, f64::max)
    });
    assert!(s.levels.iter().all(|l| (l.time - 0.05).abs() < 1e-12));
}

/// Doubling the elements of a stiff-scheme pendulum at dt 1 ms: the same check against a run
/// with 16 times the elements.
#[test]
fn space_refinement_estimates_the_error_of_every_run() {
    let (coarse, steps) = (16usize, 100u64);
    let at = |elements: usize| {
        pendulum(&[
            ("rod.0.elements", elements.to_string()),
            ("solver.scheme", "\"stiff\"".to_string()),
            ("solver.dt", "1e-3".to_string()),
        ])
    };
    let s = study(Refinement::Space, 3, steps, 1, |factor| {
        at(coarse * factor as usize)
    })
    .unwrap();
    let reference = run_to_end(at(coarse * 16).unwrap(), steps);
    let rod = &s.rods[0].positions;
    assert_eq!(s.rods[0].points, coarse + 1);
    assert_estimates("positions", rod, |k| {
        let run = run_to_end(at(coarse << k).unwrap(), steps);
        largest_distance(&run, &reference, 16 >> k)
    });
}

/// A refined run the scheme cannot take is reported with its index: the explicit scheme's
/// stable step shrinks with the element length, and the builder refuses a step above it.
#[test]
fn a_refined_run_the_scheme_cannot_take_says_which() {
    let err = study(Refinement::Space, 3, 100, 1, |factor| {
        pendulum(&[
            ("rod.0.elements", (40 * factor).to_string()),
            ("solver.scheme", "\"explicit\"".to_string()),
            ("solver.dt", "2e-4".to_string()),
        ])
    })
    .unwrap_err();
    assert!(
        matches!(
            err,
            StudyError::Build {
                level: 2,
                factor: 4,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("stability limit"), "{err}");
}

/// A build that ignores the refinement is refused before it runs.
#[test]
fn a_build_that_ignores_the_refinement_is_refused() {
    let mut built = 0;
    let err = study(Refinement::Space, 3, 10, 1, |_| {
        built += 1;
        pendulum(&[("rod.0.elements", "10".to_string())])
    })
    .unwrap_err();
    assert_eq!(built, 2, "the third run is not built");
    assert!(
        matches!(err, StudyError::Mismatch { level: 1, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("expected [20]"), "{err}");
    let err = study(Refinement::Time, 2, 10, 1, |_| pendulum(&[])).unwrap_err();
    assert!(err.to_string().contains("time step"), "{err}");
}

/// A rod that does not move (no gravity) gives identical runs: nothing to measure, and the
/// study says so rather than reporting an order.
#[test]
fn runs_that_agree_exactly_are_negligible() {
    let s = study(Refinement::Time, 3, 50, 4, |factor| {
        pendulum(&[
            ("rod.0.elements", "10".to_string()),
            ("solver.gravity", "[0.0, 0.0, 0.0]".to_string()),
            ("solver.dt", format!("{:e}", 1e-4 / f64::from(factor))),
        ])
    })
    .unwrap();
    let rod = &s.rods[0].positions;
    assert!(rod.negligible(), "{rod:?}");
    assert!(!rod.asymptotic(), "{rod:?}");
    assert!((rod.scale - 1.0).abs() < 1e-9, "{rod:?}");
}

/// The filtered force at the pinned end of a stiff-scheme pendulum (what a haptic device would
/// render): its estimated error for every run is within 15 % of its largest difference, over
/// four checkpoints, from a run at a 256th of the step; the free end has no force to compare.
#[test]
fn the_force_at_a_held_end_is_estimated_too() {
    let (dt, steps, checkpoints) = (1e-3, 200u64, 4u64);
    let at = |factor: u32| {
        pendulum(&[
            ("rod.0.elements", "20".to_string()),
            ("solver.scheme", "\"stiff\"".to_string()),
            ("solver.dt", format!("{:e}", dt / f64::from(factor))),
        ])
    };
    let force_through = |mut sim: Simulation, steps: u64| -> Vec<[f64; 3]> {
        (0..checkpoints)
            .map(|_| {
                sim.run(steps / checkpoints).unwrap();
                sim.end_reaction(cosserat::RodHandle(0), 0).unwrap().force
            })
            .collect()
    };
    let s = study(Refinement::Time, 3, steps, checkpoints as usize, at).unwrap();
    let forces = &s.rods[0].end_forces;
    assert_eq!(forces.len(), 1, "only the pinned first end is held");
    let (end, force) = &forces[0];
    assert_eq!(*end, 0);
    let reference = force_through(at(256).unwrap(), steps * 256);
    assert_estimates("force", force, |k| {
        let run = force_through(at(1 << k).unwrap(), steps << k);
        run.iter()
            .zip(&reference)
            .map(|(a, b)| largest_distance(&[*a], &[*b], 1))
            .fold(0.0, f64::max)
    });
}

#[test]
fn the_number_of_runs_and_steps_is_checked_before_anything_runs() {
    let mut built = 0;
    for levels in [0, 1, 13] {
        let err = study(Refinement::Time, levels, 10, 1, |_| {
            built += 1;
            pendulum(&[])
        })
        .unwrap_err();
        assert!(matches!(err, StudyError::Levels(n) if n == levels), "{err}");
    }
    let err = study(Refinement::Time, 3, u64::MAX / 2, 1, |_| {
        built += 1;
        pendulum(&[])
    })
    .unwrap_err();
    assert!(
        matches!(err, StudyError::TooManySteps { factor: 4, .. }),
        "{err}"
    );
    assert_eq!(built, 0);
}

/// The stiff scheme with BDF2 (`solver.stiff.integrator = "bdf2"`) converges at second order
/// in time, in its positions and in the filtered force at its pin; implicit Euler at first.
/// BDF2's estimated errors are within 15 % of the distances from a run at a 16th of the step
/// (at finer steps the force reaches a floor of about 2e-6 N, `docs/stiff-solver.md`).
#[test]
fn bdf2_is_second_order_in_positions_and_in_the_pin_force() {
    let (dt, steps, checkpoints) = (1e-3, 200u64, 4u64);
    let at = |integrator: &'static str| {
        move |factor: u32| {
            pendulum(&[
                ("rod.0.elements", "20".to_string()),
                ("solver.scheme", "\"stiff\"".to_string()),
                ("solver.stiff.integrator", format!("\"{integrator}\"")),
                ("solver.dt", format!("{:e}", dt / f64::from(factor))),
            ])
        }
    };
    let c = checkpoints as usize;
    let euler = study(Refinement::Time, 3, steps, c, at("implicit-euler")).unwrap();
    let bdf2 = study(Refinement::Time, 3, steps, c, at("bdf2")).unwrap();
    let order = |q: &cosserat::convergence::Convergence| q.grid.observed_order.unwrap();
    let rod = &euler.rods[0];
    for q in [&rod.positions, &rod.end_forces[0].1] {
        assert!((0.8..1.2).contains(&order(q)), "implicit Euler: {q:?}");
    }
    let rod = &bdf2.rods[0];
    for q in [&rod.positions, &rod.end_forces[0].1] {
        assert!((1.8..2.2).contains(&order(q)), "BDF2: {q:?}");
    }
    // BDF2 at 1 ms is more accurate than implicit Euler at a quarter of it.
    let first = |s: &cosserat::convergence::Study, k: usize| {
        s.rods[0].positions.estimated_errors.as_ref().unwrap()[k]
    };
    assert!(first(&bdf2, 0) < first(&euler, 2) / 4.0);
    let build = at("bdf2");
    let reference = run_through(build(16).unwrap(), steps * 16, checkpoints);
    let reference_force = {
        let mut sim = build(16).unwrap();
        (0..checkpoints)
            .map(|_| {
                sim.run(steps * 16 / checkpoints).unwrap();
                sim.end_reaction(cosserat::RodHandle(0), 0).unwrap().force
            })
            .collect::<Vec<_>>()
    };
    // The largest distances of each run from the reference, positions and force.
    let (mut measured, mut measured_force) = (Vec::new(), Vec::new());
    for k in 0..3 {
        let mut sim = build(1 << k).unwrap();
        let (mut actual, mut actual_force) = (0.0_f64, 0.0_f64);
        for c in 0..checkpoints as usize {
            sim.run((steps << k) / checkpoints).unwrap();
            let points = sim.positions(cosserat::RodHandle(0));
            actual = actual.max(largest_distance(&points, &reference[c], 1));
            let f = sim.end_reaction(cosserat::RodHandle(0), 0).unwrap().force;
            actual_force = actual_force.max(largest_distance(&[f], &[reference_force[c]], 1));
        }
        measured.push(actual);
        measured_force.push(actual_force);
    }
    assert_estimates("BDF2 positions", &rod.positions, |k| measured[k]);
    assert_estimates("BDF2 force", &rod.end_forces[0].1, |k| measured_force[k]);
}
