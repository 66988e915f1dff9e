//! How accurate was a run? A scene's discretisation error, estimated by running it again
//! refined.
//!
//! The validation cases (`cargo xtask validate`) measure the schemes against analytic answers,
//! but a user's own scene (a wire in a vessel, a catheter with its guidewire) has none. Running
//! it again at half the step (or with twice the elements), and again, shows how far each run
//! is from the answer the refinements converge to, as long as the runs are in their
//! asymptotic range, which the observed order of convergence shows. The estimates are
//! Richardson's; the bound on the finest run is Roache's grid convergence index (GCI), the
//! judgement the validation cases use too.
//!
//! What is compared: every rod's centreline at evenly spaced checkpoints and at the end of the
//! run, point by point at the coarsest run's points. Rods are resampled uniformly by arc length, so point `f·j` of a rod
//! with `f` times the elements sits at the arc length of point `j` of the coarse rod. A run
//! whose outcome is a bifurcation (a column that buckles one way or the other) or chaotic has no
//! asymptotic range: its observed order falls outside it, and the study gives the distances
//! between the runs but no error estimate.

use crate::Simulation;
use std::time::Instant;

/// What is refined from one run to the next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refinement {
    /// The time step is halved (and the steps doubled, so that every run ends at the same time).
    Time,
    /// Every rod's element count is doubled, at the same time step.
    Space,
}

impl Refinement {
    /// `time` or `space`.
    pub fn name(self) -> &'static str {
        match self {
            Refinement::Time => "time",
            Refinement::Space => "space",
        }
    }

    /// The lowest order of convergence the schemes have in this refinement, which the GCI
    /// uses when the observed order is higher or unknown: the explicit scheme (symplectic
    /// Euler) and the stiff scheme's default (implicit Euler) are first order in time (its BDF2
    /// is second order, for which this bound is then conservative); in space rods converge at
    /// second order, clamped ones included (`docs/validation.md`), but a free end bound inside
    /// another rod (a wire's tip in a catheter) is first order, and so is a contact that moves
    /// by whole elements, so 1 is the bound that holds for every scene.
    pub fn formal_order(self) -> f64 {
        1.0
    }
}

/// Roache's grid convergence judgement of a quantity computed at resolutions `r, 2r, 4r, …`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridConvergence {
    /// `log2(d_coarser / d_finest)` from the differences of the three finest runs; `None` with
    /// fewer runs, or when a difference vanishes.
    pub observed_order: Option<f64>,
    /// Bound on the finest run's error: `F_s d_finest / (2^p − 1)`, with `p` the smaller of the
    /// observed and the formal order and `F_s = 1.25` when the observed order is within
    /// [`ASYMPTOTIC_ORDERS`]; otherwise the formal order and `F_s = 3` (Roache's choices for two
    /// resolutions).
    pub gci: f64,
    /// The `F_s` used: 1.25 or 3.
    pub safety_factor: f64,
}

/// [`GridConvergence`] from the difference between the two finest runs and, with three or
/// more runs, the difference between the two before them (pass `None` where the differences
/// change sign: a scalar that does not converge monotonically has no observed order).
pub fn grid_convergence(
    coarser_difference: Option<f64>,
    finest_difference: f64,
    formal_order: f64,
) -> GridConvergence {
    let observed_order = coarser_difference
        .filter(|_| finest_difference > 0.0)
        .map(|d| (d / finest_difference).log2())
        .filter(|p| p.is_finite());
    // Roache's 1.25 only where the runs look asymptotic: an observed order above the
    // asymptotic range (a lucky cancellation, or differences at the level of other errors)
    // says as little about the error as a low one.
    let (fs, p) = match observed_order {
        Some(p) if p > ASYMPTOTIC_ORDERS.0 && p < ASYMPTOTIC_ORDERS.1 => {
            (1.25, p.min(formal_order))
        }
        _ => (3.0, formal_order),
    };
    GridConvergence {
        observed_order,
        gci: fs * finest_difference / (2f64.powf(p) - 1.0),
        safety_factor: fs,
    }
}

/// The range of observed orders in which the runs are taken to be asymptotic, so that
/// Richardson's estimates hold: below 0.5 the differences barely shrink (a run not converging,
/// or dominated by something the refinement does not reach); above 3 they collapse faster than
/// either scheme converges (differences at the rounding level, or a lucky cancellation).
pub const ASYMPTOTIC_ORDERS: (f64, f64) = (0.5, 3.0);

/// The most runs a study takes: the last is `2^11 = 2048` times finer than the first.
pub const MAX_LEVELS: usize = 12;

/// One run of a study.
#[derive(Clone, Debug)]
pub struct Level {
    /// How many times finer than the first run (1, 2, 4, …).
    pub factor: u32,
    /// Time step [s].
    pub dt: f64,
    /// Elements of every rod.
    pub elements: Vec<usize>,
    /// Steps run.
    pub steps: u64,
    /// Simulated time at the end [s].
    pub time: f64,
    /// Wall time of the steps [s].
    pub wall_s: f64,
    /// Largest `|l/l0 − 1|` of any segment over the run.
    pub max_strain: f64,
}

/// How one quantity of a rod converged: its centreline, or the force at a held end.
#[derive(Clone, Debug)]
pub struct Convergence {
    /// Largest difference between runs `k` and `k + 1` (a distance [m], or the size of a
    /// force's difference [N]) over the checkpoints (and, for the centreline, the coarsest
    /// run's points), for `k = 0, 1, …`.
    pub differences: Vec<f64>,
    /// Where each of those differences is largest: the point of the coarsest run (for a force,
    /// the end: 0 first, 1 last) and the time [s].
    pub worst: Vec<(usize, f64)>,
    /// The size the differences are judged against: the rod's length [m] (of its centreline at
    /// the end of the first run), or the largest force of the first run at the checkpoints [N].
    pub scale: f64,
    /// The GCI judgement of the finest run.
    pub grid: GridConvergence,
    /// Estimated error of every run (largest over the checkpoints and points), when the
    /// observed order is in [`ASYMPTOTIC_ORDERS`]: run `k`'s is the measured differences from
    /// it to the finest run plus Richardson's extrapolation of the rest, `d_last / (2^p − 1)`.
    pub estimated_errors: Option<Vec<f64>>,
}

impl Convergence {
    fn new(differences: Vec<f64>, worst: Vec<(usize, f64)>, scale: f64, formal: f64) -> Self {
        let runs = differences.len() + 1;
        let last = differences[runs - 2];
        let before = (runs >= 3).then(|| differences[runs - 3]);
        let grid = grid_convergence(before, last, formal);
        let estimated_errors = grid
            .observed_order
            .filter(|p| (ASYMPTOTIC_ORDERS.0..=ASYMPTOTIC_ORDERS.1).contains(p))
            .map(|p| {
                let tail = last / (2f64.powf(p) - 1.0);
                (0..runs)
                    .map(|k| differences[k..].iter().sum::<f64>() + tail)
                    .collect()
            });
        Self {
            differences,
            worst,
            scale,
            grid,
            estimated_errors,
        }
    }

    /// Whether the observed order is in [`ASYMPTOTIC_ORDERS`].
    pub fn asymptotic(&self) -> bool {
        self.estimated_errors.is_some()
    }

    /// Whether the two finest runs agree to within [`NEGLIGIBLE`] of the scale: then nothing
    /// is left for the refinement to measure (a motion the step reproduces exactly, such as a
    /// straight wire pushed along its axis), and an observed order from such differences is
    /// noise.
    pub fn negligible(&self) -> bool {
        self.differences
            .last()
            .is_some_and(|d| *d <= NEGLIGIBLE * self.scale)
    }
}

/// What a study found for one rod.
#[derive(Clone, Debug)]
pub struct RodConvergence {
    /// The rod's name.
    pub name: String,
    /// Points compared (those of the coarsest run).
    pub points: usize,
    /// Its centreline.
    pub positions: Convergence,
    /// The filtered force at each held end (`Simulation::end_reaction`, what a haptic device
    /// renders), with the end's index (0 first, 1 last).
    pub end_forces: Vec<(usize, Convergence)>,
}

/// Differences between runs below this fraction of a quantity's scale are taken as agreement
/// (see [`Convergence::negligible`]): well above the rounding an `f64` run accumulates over
/// thousands of steps, and below any discretisation error worth reporting.
pub const NEGLIGIBLE: f64 = 1e-9;

/// The result of [`study`].
#[derive(Clone, Debug)]
pub struct Study {
    /// What was refined.
    pub refinement: Refinement,
    /// The runs, coarsest first.
    pub levels: Vec<Level>,
    /// The times [s] at which the runs were compared; the last is the end.
    pub checkpoint_times: Vec<f64>,
    /// Per rod, in the simulation's order.
    pub rods: Vec<RodConvergence>,
}

/// Why a study could not be completed.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// Fewer than two or more than [`MAX_LEVELS`] runs were asked for.
    #[error("a convergence study takes 2 to {MAX_LEVELS} runs, got {0}")]
    Levels(usize),
    /// The finest run would take more steps than can be counted.
    #[error("{steps} steps refined {factor} times is more steps than can be counted")]
    TooManySteps {
        /// Steps of the first run.
        steps: u64,
        /// The finest run's refinement.
        factor: u32,
    },
    /// A run could not be built.
    #[error("run {level} ({factor}× finer): {message}")]
    Build {
        /// Index of the run.
        level: usize,
        /// How many times finer than the first.
        factor: u32,
        /// What the builder said.
        message: String,
    },
    /// A run diverged.
    #[error(
        "run {level} ({factor}× finer, dt {dt:e} s, elements {elements:?}) diverged: {message}"
    )]
    Diverged {
        /// Index of the run.
        level: usize,
        /// How many times finer than the first.
        factor: u32,
        /// Its time step.
        dt: f64,
        /// Its element counts.
        elements: Vec<usize>,
        /// The divergence.
        message: String,
    },
    /// A refined run does not have the rods or points the refinement implies.
    #[error("run {level} ({factor}× finer): {message}")]
    Mismatch {
        /// Index of the run.
        level: usize,
        /// How many times finer than the first.
        factor: u32,
        /// What does not match.
        message: String,
    },
}

/// Runs a scene `levels` times, each `2×` finer than the one before, and compares their
/// states at `checkpoints` evenly spaced times (the last at the end of the run).
///
/// `build(factor)` builds the simulation `factor` times finer than the first run (`factor` =
/// 1, 2, 4, …): with [`Refinement::Time`] at `dt / factor`, with [`Refinement::Space`] with
/// `factor` times the elements of every rod. The first run takes `steps` steps; with time
/// refinement run `k` takes `steps · factor`, so that every run ends at the same time and passes
/// the same checkpoints. Comparing along the way, not only at the end, catches runs that part
/// and meet again (a wire that bows one way and straightens, a pendulum whose phase error
/// crosses zero at the end).
pub fn study(
    refinement: Refinement,
    levels: usize,
    steps: u64,
    checkpoints: usize,
    mut build: impl FnMut(u32) -> Result<Simulation, String>,
) -> Result<Study, StudyError> {
    if !(2..=MAX_LEVELS).contains(&levels) {
        return Err(StudyError::Levels(levels));
    }
    let finest = 1u32 << (levels - 1);
    if refinement == Refinement::Time && steps.checked_mul(u64::from(finest)).is_none() {
        return Err(StudyError::TooManySteps {
            steps,
            factor: finest,
        });
    }
    // Steps of the first run at which the states are compared (distinct, the last = steps).
    let count = (checkpoints.max(1) as u64).min(steps.max(1));
    let marks: Vec<u64> = (1..=count)
        .map(|c| {
            ((u128::from(c) * u128::from(steps) + u128::from(count / 2)) / u128::from(count)) as u64
        })
        .collect();
    let mut runs = Vec::with_capacity(levels);
    // states[level][checkpoint][rod]: the points, and the force at each end when it is held.
    let mut states: Vec<Vec<Vec<RodState>>> = Vec::with_capacity(levels);
    let mut times = Vec::new();
    let mut names = Vec::new();
    for level in 0..levels {
        let factor = 1u32 << level;
        let mut sim = build(factor).map_err(|message| StudyError::Build {
            level,
            factor,
            message,
        })?;
        let elements: Vec<usize> = sim
            .rods()
            .map(|h| sim.positions(h).len().saturating_sub(1))
            .collect();
        if let Some(first) = runs.first() {
            check_refined(refinement, first, level, factor, &elements, sim.dt())?;
        }
        let per_step = match refinement {
            Refinement::Time => u64::from(factor),
            Refinement::Space => 1,
        };
        let mut wall_s = 0.0;
        let mut at = Vec::with_capacity(marks.len());
        let mut done = 0;
        for &mark in &marks {
            let start = Instant::now();
            let result = sim.run((mark - done) * per_step);
            wall_s += start.elapsed().as_secs_f64();
            done = mark;
            if let Err(e) = result {
                return Err(StudyError::Diverged {
                    level,
                    factor,
                    dt: sim.dt(),
                    elements,
                    message: e.to_string(),
                });
            }
            at.push(
                sim.rods()
                    .map(|h| RodState {
                        points: sim.positions(h),
                        forces: [0, 1].map(|end| sim.end_reaction(h, end).map(|r| r.force)),
                    })
                    .collect(),
            );
            if level == 0 {
                times.push(sim.time());
            }
        }
        if level == 0 {
            names = sim.rods().map(|h| sim.rod_name(h).to_string()).collect();
        }
        states.push(at);
        runs.push(Level {
            factor,
            dt: sim.dt(),
            elements,
            steps: steps * per_step,
            time: sim.time(),
            wall_s,
            max_strain: sim.max_strain(),
        });
    }
    let stride = |level: usize| match refinement {
        Refinement::Time => 1,
        Refinement::Space => 1usize << level,
    };
    let formal = refinement.formal_order();
    let rods = names
        .into_iter()
        .enumerate()
        .map(|(r, name)| {
            let end = &states[0][marks.len() - 1][r].points;
            let points = end.len();
            let length = end.windows(2).map(|w| distance(w[0], w[1])).sum();
            // The largest difference between runs k and k + 1 of `value(run, checkpoint, i)`
            // over the checkpoints and `i < count`, with its `i` and time.
            let compare = |count: usize, value: &dyn Fn(usize, usize, usize) -> [f64; 3]| {
                (0..levels - 1)
                    .map(|k| {
                        let mut largest = (0.0, 0, 0);
                        for c in 0..marks.len() {
                            for i in 0..count {
                                let d = distance(value(k, c, i), value(k + 1, c, i));
                                if d > largest.0 {
                                    largest = (d, i, c);
                                }
                            }
                        }
                        (largest.0, (largest.1, times[largest.2]))
                    })
                    .unzip()
            };
            let (differences, worst) =
                compare(points, &|k, c, j| states[k][c][r].points[j * stride(k)]);
            let positions = Convergence::new(differences, worst, length, formal);
            let end_forces = (0..2)
                .filter(|&e| states.iter().flatten().all(|at| at[r].forces[e].is_some()))
                .map(|e| {
                    let force = |k: usize, c: usize| states[k][c][r].forces[e].unwrap_or_default();
                    let (differences, worst): (Vec<f64>, Vec<(usize, f64)>) =
                        compare(1, &|k, c, _| force(k, c));
                    let worst = worst.into_iter().map(|(_, t)| (e, t)).collect();
                    let scale = (0..marks.len())
                        .map(|c| distance(force(0, c), [0.0; 3]))
                        .fold(0.0, f64::max);
                    (e, Convergence::new(differences, worst, scale, formal))
                })
                .collect();
            RodConvergence {
                name,
                points,
                positions,
                end_forces,
            }
        })
        .collect();
    Ok(Study {
        refinement,
        levels: runs,
        checkpoint_times: times,
        rods,
    })
}

/// A refined run, built and not yet run, has the first run's rods with the element counts and
/// the time step the refinement implies (so that, with its steps, it ends at the first run's
/// time and passes the same checkpoints).
fn check_refined(
    refinement: Refinement,
    first: &Level,
    level: usize,
    factor: u32,
    elements: &[usize],
    dt: f64,
) -> Result<(), StudyError> {
    let mismatch = |message: String| StudyError::Mismatch {
        level,
        factor,
        message,
    };
    let expected: Vec<usize> = match refinement {
        Refinement::Time => first.elements.clone(),
        Refinement::Space => first.elements.iter().map(|n| n * factor as usize).collect(),
    };
    if elements != expected {
        return Err(mismatch(format!(
            "its rods have {elements:?} elements, expected {expected:?}"
        )));
    }
    let expected = match refinement {
        Refinement::Time => first.dt / f64::from(factor),
        Refinement::Space => first.dt,
    };
    if (dt - expected).abs() > 1e-12 * expected {
        return Err(mismatch(format!(
            "its time step is {dt:e} s, expected {expected:e} s"
        )));
    }
    Ok(())
}

/// One rod at one checkpoint of one run.
struct RodState {
    points: Vec<[f64; 3]>,
    /// The filtered force at the first and the last end, where held.
    forces: [Option<[f64; 3]>; 2],
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values converging as `v* + C h^p` give back `p`; for `p ≤ 1` the GCI is 1.25 times the
    /// finest value's exact error, above it the formal order 1 makes it larger.
    #[test]
    fn observed_order_and_gci_of_an_exact_power_law() {
        for p in [0.8, 1.0, 1.7] {
            let v: Vec<f64> = (0..3)
                .map(|k| 2.0 + 0.3 * 0.5f64.powf(p * k as f64))
                .collect();
            let g = grid_convergence(Some(v[0] - v[1]), v[1] - v[2], 1.0);
            let observed = g.observed_order.unwrap();
            assert!((observed - p).abs() < 1e-12, "{observed} vs {p}");
            let exact_error = v[2] - 2.0;
            let expected = 1.25 * (v[1] - v[2]) / (2f64.powf(p.min(1.0)) - 1.0);
            assert!((g.gci - expected).abs() < 1e-12 * expected);
            if p <= 1.0 {
                assert!(
                    (g.gci / exact_error - 1.25).abs() < 1e-9,
                    "{}",
                    g.gci / exact_error
                );
            } else {
                assert!(g.gci > 1.25 * exact_error, "the formal order caps p");
            }
        }
    }

    #[test]
    fn two_runs_or_no_shrinking_use_the_formal_order_and_safety_three() {
        let two = grid_convergence(None, 1e-3, 1.0);
        assert_eq!(two.observed_order, None);
        assert!((two.gci - 3e-3).abs() < 1e-15);
        let growing = grid_convergence(Some(1e-3), 2e-3, 1.0);
        assert!(growing.observed_order.unwrap() < 0.0);
        assert!((growing.gci - 6e-3).abs() < 1e-15);
        let exact = grid_convergence(Some(1e-3), 0.0, 1.0);
        assert_eq!(exact.observed_order, None);
        assert_eq!(exact.gci, 0.0);
    }
}
