//! What a run did, as one typed value: the `cosserat run --json` object, built from a
//! [`Simulation`] after its steps and read back typed by whoever consumes it (the command's
//! tests, scripts through serde).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::StiffSummary;
use crate::sim::{RodHandle, Simulation};

/// The report of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// The scene's name.
    pub scene: String,
    /// `cpu`, `cpu-rayon` or `gpu`.
    pub backend: String,
    /// The stepper that ran it ("cpu explicit", "cpu stiff", …).
    pub stepper: String,
    /// `f32` or `f64`.
    pub precision: String,
    /// `inextensible` or `extensible`.
    pub mode: String,
    /// Elements of all rods.
    pub elements: usize,
    /// Steps taken.
    pub steps: u64,
    /// Time step [s].
    pub dt: f64,
    /// Simulated time [s].
    pub simulated_s: f64,
    /// Wall time of the steps [s].
    pub wall_s: f64,
    /// Wall time per step [µs] (`None` for a run of no steps).
    pub us_per_step: Option<f64>,
    /// Largest `|l/l0 − 1|` of any segment over the run.
    pub max_strain: f64,
    /// Kinetic energy at the end [J].
    pub kinetic_energy: f64,
    /// Potential energy at the end [J].
    pub potential_energy: f64,
    /// Last point of the first rod [m].
    pub tip: [f64; 3],
    /// Last point of every rod, by name [m].
    pub tips: BTreeMap<String, [f64; 3]>,
    /// Unit tangent at each rod's last point (the direction of its last element), by name.
    pub tip_tangents: BTreeMap<String, [f64; 3]>,
    /// The filtered reaction at every held end at the end of the run (the wrench the holder
    /// applies to the rod; steppers without reactions give none).
    pub reactions: Vec<EndReactionFigures>,
    /// With `cosserat run --until-static TOL`: the simulated time at which the run was found
    /// settled (`None` without the option, or when it did not settle within the run).
    pub settled_at_s: Option<f64>,
    /// Whether the run stopped on a divergence.
    pub diverged: bool,
    /// Whether the run was stopped from outside (Ctrl-C, SIGTERM) before its last step; the
    /// report then covers the steps taken.
    #[serde(default)]
    pub interrupted: bool,
    /// The divergence, in words.
    pub divergence: Option<String>,
    /// What the builder accepted but a user should know.
    pub warnings: Vec<String>,
    /// What makes the results doubtful ([`run_warnings`]).
    pub run_warnings: Vec<String>,
    /// Step times with `--step-times`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_us: Option<StepTimes>,
    /// Mesh contact, for scenes with an environment.
    #[serde(flatten, default, skip_serializing_if = "Option::is_none")]
    pub contact: Option<ContactFigures>,
    /// Largest filtered reaction force at any held end [N], where reactions are computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_reaction_force: Option<f64>,
    /// What the stiff solver did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiff: Option<StiffFigures>,
    /// Bindings and rod contacts.
    #[serde(flatten, default, skip_serializing_if = "Option::is_none")]
    pub coupling: Option<CouplingFigures>,
}

/// Step times of a run whose steps were timed one by one [µs].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepTimes {
    /// The first step (it also builds what the solver keeps between steps).
    pub first: f64,
    /// Median of the later steps (`None` for a run of one step, as the two below).
    pub median: Option<f64>,
    /// 99th percentile of the later steps (nearest rank).
    pub p99: Option<f64>,
    /// Largest of the later steps.
    pub max: Option<f64>,
}

impl StepTimes {
    /// The first step's time, then the median, 99th percentile and largest of the later
    /// steps' times, from step times in seconds; `None` for no steps.
    pub fn of(seconds: &[f64]) -> Option<Self> {
        let (first, rest) = seconds.split_first()?;
        let mut t: Vec<f64> = rest.iter().map(|s| s * 1e6).collect();
        t.sort_by(f64::total_cmp);
        let rank = |p: f64| {
            (!t.is_empty()).then(|| t[((p * t.len() as f64).ceil() as usize).clamp(1, t.len()) - 1])
        };
        Some(Self {
            first: first * 1e6,
            median: rank(0.5),
            p99: rank(0.99),
            max: t.last().copied(),
        })
    }
}

/// Mesh contact over a run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactFigures {
    /// Triangles of the environment.
    pub triangles: usize,
    /// Largest penetration of a point's sphere into the wall at the start of a step [m].
    pub max_penetration: f64,
    /// Points found outside the lumen.
    pub escaped_points: usize,
    /// Points in contact at the end.
    pub contacts: usize,
    /// Wall time of collision detection per step [µs].
    pub collision_us_per_step: f64,
}

/// The stiff solver over a run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StiffFigures {
    /// Iterations per rod-step.
    pub iterations_per_step: f64,
    /// Factorisations per rod-step.
    pub factorisations_per_step: f64,
    /// Rod-steps kept.
    pub steps_kept: u64,
    /// Rod-steps left above the tolerance.
    pub unconverged_steps: u64,
    /// Rod-steps retaken in halves.
    pub halved_steps: u64,
    /// Rod-steps retaken with axial compliance.
    pub axial_steps: u64,
    /// Largest residual at the end of a rod-step.
    pub max_residual: f64,
    /// Largest tolerance a rod-step was held to.
    pub max_tolerance: f64,
    /// The step (its index) that ended with the largest residual.
    #[serde(default)]
    pub worst_step: u64,
    /// The last step (its index) that ended above its tolerance, if any.
    #[serde(default)]
    pub last_unconverged_step: Option<u64>,
}

/// Bindings and rod contacts over a run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CouplingFigures {
    /// Inner points bound at the end.
    pub bound_points: usize,
    /// Rod–rod and self-contacts at the end.
    pub rod_contacts: usize,
    /// Most rod contacts at any step.
    pub max_rod_contacts: usize,
    /// Smallest centreline distance of two non-neighbouring segments [m] (`None` if none came
    /// within the contact margin).
    pub min_separation: Option<f64>,
    /// Sum of the two radii of that pair [m].
    pub min_separation_radii: f64,
    /// Smallest `distance / (r_a + r_b)` (`None` as `min_separation`).
    pub min_separation_ratio: Option<f64>,
    /// Wall time of the coupling's detection per step [µs].
    pub coupling_detection_us_per_step: f64,
}

/// The reaction at one held end of one rod.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EndReactionFigures {
    /// The rod's name.
    pub rod: String,
    /// 0: first point, 1: last point.
    pub end: usize,
    /// Force on the rod [N], world axes.
    pub force: [f64; 3],
    /// Torque on the rod about the held point [N m], world axes (zero at a pinned end).
    pub torque: [f64; 3],
}

impl RunReport {
    /// The report of `sim` after a run of `steps` steps in `wall_s` seconds.
    pub fn new(
        sim: &Simulation,
        scene: &str,
        steps: u64,
        wall_s: f64,
        divergence: Option<String>,
        step_us: Option<StepTimes>,
    ) -> Self {
        let e = sim.energies();
        let last = |h| sim.positions(h).last().copied().unwrap_or([f64::NAN; 3]);
        let finite = |x: f64| x.is_finite().then_some(x);
        Self {
            scene: scene.to_string(),
            backend: sim.backend().name().to_string(),
            stepper: sim.stepper_info().name.to_string(),
            precision: if sim.is_double_precision() {
                "f64"
            } else {
                "f32"
            }
            .into(),
            mode: if sim.is_extensible() {
                "extensible"
            } else {
                "inextensible"
            }
            .into(),
            elements: sim.element_count(),
            steps,
            dt: sim.dt(),
            simulated_s: sim.time(),
            wall_s,
            us_per_step: (steps > 0).then(|| wall_s * 1e6 / steps as f64),
            max_strain: sim.max_strain(),
            kinetic_energy: e.kinetic(),
            potential_energy: e.potential(),
            tip: last(RodHandle(0)),
            tips: sim
                .rods()
                .map(|h| (sim.rod_name(h).to_string(), last(h)))
                .collect(),
            tip_tangents: sim
                .rods()
                .map(|h| {
                    let p = sim.positions(h);
                    let (a, b) = (p[p.len() - 2], p[p.len() - 1]);
                    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                    let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                    (sim.rod_name(h).to_string(), d.map(|x| x / norm))
                })
                .collect(),
            reactions: sim
                .rods()
                .flat_map(|h| {
                    (0..2).filter_map(move |end| {
                        sim.end_reaction(h, end).map(|r| EndReactionFigures {
                            rod: sim.rod_name(h).to_string(),
                            end,
                            force: r.force,
                            torque: r.torque,
                        })
                    })
                })
                .collect(),
            settled_at_s: None,
            diverged: divergence.is_some(),
            interrupted: false,
            divergence,
            warnings: sim.warnings().to_vec(),
            run_warnings: run_warnings(sim),
            step_us,
            contact: sim.contact_report().map(|c| ContactFigures {
                triangles: sim
                    .obstacles()
                    .iter()
                    .map(|o| match o.geometry() {
                        crate::obstacles::Geometry::Mesh(env) => env.triangles(),
                        crate::obstacles::Geometry::Shape(_) => 0,
                    })
                    .sum(),
                max_penetration: c.max_penetration,
                escaped_points: c.escaped_points,
                contacts: c.contacts,
                collision_us_per_step: c.detection_us_per_step,
            }),
            max_reaction_force: sim.max_reaction_force(),
            stiff: sim.stiff_summary().map(|st| StiffFigures {
                iterations_per_step: st.iterations_per_step(),
                factorisations_per_step: st.factorisations_per_step(),
                steps_kept: st.steps_kept,
                unconverged_steps: st.unconverged_steps,
                halved_steps: st.halved_steps,
                axial_steps: st.axial_steps,
                max_residual: st.max_residual,
                max_tolerance: st.max_tolerance,
                worst_step: st.worst_step,
                last_unconverged_step: st.last_unconverged_step,
            }),
            coupling: sim.coupling_stats().map(|c| CouplingFigures {
                bound_points: c.bound_points,
                rod_contacts: c.contacts,
                max_rod_contacts: c.max_contacts,
                min_separation: finite(c.min_separation),
                min_separation_radii: c.min_separation_radii,
                min_separation_ratio: finite(c.min_separation_ratio),
                coupling_detection_us_per_step: if c.steps > 0 {
                    c.detection_seconds * 1e6 / c.steps as f64
                } else {
                    0.0
                },
            }),
        }
    }
}

/// The stiff solver's steps make a run doubtful when more than 1 % of them ended above their
/// tolerance, or when one ended far from converged (a residual a hundred times the tolerance)
/// and steps were still loose in the last tenth of the run's `steps` (of `dt`). Loose steps
/// only early in a run (a transient the implicit steps then damp) leave a final state that
/// later steps converged to: no warning, and the report's `stiff` figures still say which
/// steps they were.
fn stiff_warning(st: &StiffSummary, steps: u64, dt: f64) -> Option<String> {
    let often = st.unconverged_steps * 100 > st.steps_kept;
    let late = |step: u64| step * 10 >= steps.saturating_sub(1) * 9;
    let far_and_late =
        st.max_residual > 100.0 * st.max_tolerance && st.last_unconverged_step.is_some_and(late);
    if !(often || far_and_late) {
        return None;
    }
    let at = |step: u64| format!("step {step}, t = {:.4e} s", step as f64 * dt);
    let last = st
        .last_unconverged_step
        .map_or(String::new(), |step| format!(", the last at {}", at(step)));
    Some(format!(
        "{} of {} stiff rod-steps ended above their tolerance{last}; the largest residual \
         {:.2e} (against {:.1e}) at {}: the run is not converged (docs/stiff-solver.md)",
        st.unconverged_steps,
        st.steps_kept,
        st.max_residual,
        st.max_tolerance,
        at(st.worst_step)
    ))
}

/// What a finished run did that makes its results doubtful: points found through the mesh's
/// wall, or stiff steps that ended often above their tolerance or far from converged late in
/// the run ([`stiff_warning`]).
pub fn run_warnings(sim: &Simulation) -> Vec<String> {
    let mut warnings = Vec::new();
    if let Some(c) = sim.contact_report()
        && c.escaped_points > 0
    {
        warnings.push(format!(
            "{} points were found behind the mesh's wall at the start of a step: the contacts \
             did not keep the rod inside",
            c.escaped_points
        ));
    }
    if let Some(c) = sim.coupling_stats()
        && c.held_ends_inside > 0
    {
        warnings.push(format!(
            "for {} steps a bound rod's held end was inside the rod it is bound in: the stiff \
             scheme's binding lags a step and can be unstable there; keep the hand behind the \
             hub (docs/stiff-solver.md, \"Bindings\")",
            c.held_ends_inside
        ));
    }
    if let Some(st) = sim.stiff_summary()
        && let Some(warning) = stiff_warning(&st, sim.steps(), sim.dt())
    {
        warnings.push(warning);
    }
    warnings
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run of 10 000 steps of 1e-4 s, one rod, tolerance 1e-5, whose steps all converged
    /// but those `loose` (step index, residual).
    fn summary(loose: &[(u64, f64)]) -> StiffSummary {
        let mut st = StiffSummary {
            rod_steps: 10_000,
            steps_kept: 10_000,
            max_tolerance: 1e-5,
            max_residual: 5e-6,
            ..StiffSummary::default()
        };
        for &(step, residual) in loose {
            st.unconverged_steps += 1;
            st.last_unconverged_step = st.last_unconverged_step.max(Some(step));
            if residual > st.max_residual {
                st.max_residual = residual;
                st.worst_step = step;
            }
        }
        st
    }

    #[test]
    fn one_loose_early_step_does_not_make_the_run_doubtful() {
        assert_eq!(stiff_warning(&summary(&[(3, 4e-2)]), 10_000, 1e-4), None);
        assert_eq!(stiff_warning(&summary(&[]), 10_000, 1e-4), None);
    }

    #[test]
    fn a_step_far_from_converged_at_the_end_makes_the_run_doubtful() {
        let w =
            stiff_warning(&summary(&[(3, 4e-2), (9_950, 4e-3)]), 10_000, 1e-4).expect("a warning");
        assert!(w.contains("not converged"), "{w}");
        // What was loose and when: the largest residual (early) and the last loose step.
        assert!(w.contains("the last at step 9950, t = 9.9500e-1 s"), "{w}");
        assert!(
            w.contains("4.00e-2") && w.contains("step 3, t = 3.0000e-4 s"),
            "{w}"
        );
        // Loose steps, but none far from converged: no reason to doubt.
        assert_eq!(
            stiff_warning(&summary(&[(9_950, 2e-5)]), 10_000, 1e-4),
            None
        );
    }

    #[test]
    fn many_loose_steps_make_the_run_doubtful_wherever_they_are() {
        let early: Vec<(u64, f64)> = (0..200).map(|s| (s, 2e-5)).collect();
        let w = stiff_warning(&summary(&early), 10_000, 1e-4).expect("a warning");
        assert!(w.starts_with("200 of 10000 stiff rod-steps"), "{w}");
    }
}
