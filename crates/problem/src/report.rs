//! Measurements a stepper reports besides the state: reactions at held ends, contact and
//! coupling statistics, what the stiff solver did.

/// Default cut-off of the low-pass filter on reported end reactions [Hz]: well below a haptic
/// loop's 1 kHz and above the few hertz of deliberate hand motion.
pub const DEFAULT_CUTOFF_HZ: f64 = 50.0;

/// The weights `(keep, from_old, from_new)` of one step `h` of the reactions' first-order
/// low-pass filter at `cutoff_hz`: `y ← keep y + from_old x_old + from_new x`, the exact
/// solution of `ẏ = a (x − y)`, `a = 2π f_c`, over a step whose input runs linearly from the
/// last raw value `x_old` to this one `x` (a first-order hold; `cosserat_backend_cpu`'s
/// `reaction` module says why). Without a finite positive cut-off the output is the raw value.
pub fn reaction_filter_weights(cutoff_hz: f64, h: f64) -> (f64, f64, f64) {
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0) {
        return (0.0, 0.0, 1.0);
    }
    let ah = 2.0 * std::f64::consts::PI * cutoff_hz * h;
    let e = (-ah).exp();
    // (1 − E)/(a h) by its series where a h is tiny (no cancellation).
    let mean = if ah < 1e-4 {
        1.0 - ah * (0.5 - ah / 6.0)
    } else {
        (1.0 - e) / ah
    };
    (e, mean - e, 1.0 - mean)
}

/// Force and torque applied by the holder of an end to the rod.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EndReaction {
    /// Force [N], world frame.
    pub force: [f64; 3],
    /// Torque about the held point [N m], world frame (zero for a pinned end).
    pub torque: [f64; 3],
}

impl EndReaction {
    /// `|force|` [N].
    pub fn force_norm(&self) -> f64 {
        self.force.iter().map(|x| x * x).sum::<f64>().sqrt()
    }
    /// `|torque|` [N m].
    pub fn torque_norm(&self) -> f64 {
        self.torque.iter().map(|x| x * x).sum::<f64>().sqrt()
    }
}

/// Measurements of a rod's contact with the mesh since the last reset.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CollisionStats {
    /// Largest penetration of a point's sphere into the surface at the start of any step [m].
    pub max_penetration: f64,
    /// Largest number of points whose centre was behind the wall at the start of a step.
    pub escaped_points: usize,
    /// Points in contact at the last step.
    pub contacts: usize,
    /// Most points in contact at any step.
    pub max_contacts: usize,
    /// Wall time spent in collision detection [s].
    pub detection_seconds: f64,
    /// Steps with collision detection.
    pub steps: u64,
    /// Stiff scheme: point queries between the iterations of a step answered from the point's
    /// last query instead of the mesh ([`StiffSettings::reuse_contact_queries`](crate::StiffSettings::reuse_contact_queries)).
    pub reused_queries: u64,
    /// Points whose motion over a step crossed into the wall beyond the reach of their sphere
    /// query, caught by the swept test and put back on the wall they crossed (counted per
    /// detection).
    pub swept_catches: u64,
    /// Elements whose segment came nearer a wall between its two points than either point's
    /// sphere (a ridge or a vertex of the wall between them): each gives its two points a
    /// contact on the plane across the ridge's normal (counted per detection).
    pub segment_contacts: u64,
    /// Sphere queries run against the mesh (points whose clearance from the wall had run out),
    /// counted per detection: what the detection cost, next to `steps` times the points.
    pub queries: u64,
}

/// Measurements of the coupling since the start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CouplingStats {
    /// Inner points bound at the last step (all bindings).
    pub bound_points: usize,
    /// Rod–rod and self-contacts at the last step.
    pub contacts: usize,
    /// Most contacts at any step.
    pub max_contacts: usize,
    /// Smallest centreline distance of any two non-neighbouring segments seen at the start of
    /// any step [m] (`f64::INFINITY` if none came within the contact margin).
    pub min_separation: f64,
    /// Sum of the two radii of that pair [m].
    pub min_separation_radii: f64,
    /// Smallest `distance / (r_a + r_b)` of any pair seen.
    pub min_separation_ratio: f64,
    /// Wall time of the coupling's detection (bindings and rod contacts) [s].
    pub detection_seconds: f64,
    /// Steps taken.
    pub steps: u64,
    /// Steps at which a held end point of an inner rod was bound inside its outer rod (counted
    /// by the stiff scheme only, whose partitioned binding can be unstable there:
    /// `stiff/binding.rs`).
    pub held_ends_inside: u64,
}

impl Default for CouplingStats {
    fn default() -> Self {
        Self {
            bound_points: 0,
            contacts: 0,
            max_contacts: 0,
            min_separation: f64::INFINITY,
            min_separation_radii: 0.0,
            min_separation_ratio: f64::INFINITY,
            detection_seconds: 0.0,
            steps: 0,
            held_ends_inside: 0,
        }
    }
}

/// What the last step did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StiffReport {
    /// Iterations (or sweeps) run in the last step.
    pub iterations: usize,
    /// Largest residual at the last evaluation of the last step (see
    /// [`StiffSettings::tolerance`](crate::StiffSettings::tolerance)); with `tolerance = 0` this is the residual before the
    /// last iteration.
    pub residual: f64,
    /// Factorisations since the scratch was created (work: also those of steps retaken).
    pub factorisations: u64,
    /// Iterations (or sweeps) since the scratch was created (work: also those of steps
    /// retaken).
    pub total_iterations: u64,
    /// Steps since the scratch was created, each half of a step retaken in halves counted as
    /// a step (a step that was retaken is counted once, as taken in the end).
    pub steps: u64,
    /// Steps (of [`steps`](Self::steps)) whose residual was still above the tolerance after
    /// the last iteration (also after the axial retry).
    pub unconverged_steps: u64,
    /// Steps of the caller's `dt` that diverged or ended far from converged
    /// ([`StiffSettings::halve_above`](crate::StiffSettings::halve_above)) and were retaken in halves.
    pub halved_steps: u64,
    /// Steps of an inextensible rod retaken with the material's axial compliance
    /// ([`StiffSettings::axial_fallback`](crate::StiffSettings::axial_fallback)) since the scratch was created.
    pub axial_steps: u64,
    /// Largest residual at the end of a step since the scratch was created (of the steps
    /// kept: a step retaken in halves counts with its halves).
    pub max_residual: f64,
    /// The largest tolerance a step was held to since the scratch was created:
    /// [`StiffSettings::tolerance`](crate::StiffSettings::tolerance), raised for an `f32` rod to the strain its positions
    /// resolve (which depends on how far the rod is from the origin).
    pub max_tolerance: f64,
    /// The step (its index) that ended with [`max_residual`](Self::max_residual).
    pub worst_step: u64,
    /// The last step (its index) that ended above its tolerance, if any.
    pub last_unconverged_step: Option<u64>,
}

/// What the stiff solver did since the simulation was built, over all rods
/// ([`StiffReport`] summed).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StiffSummary {
    /// Rod-steps taken (steps × rods).
    pub rod_steps: u64,
    /// Newton iterations, all rods together.
    pub iterations: u64,
    /// Factorisations of the direct solve's matrix, all rods together (each iteration after
    /// the first of a step reuses the last one unless the step's settings or a change of
    /// its contacts ask for a new one).
    pub factorisations: u64,
    /// Rod-steps kept, each half of a step retaken in halves counted as a rod-step.
    pub steps_kept: u64,
    /// Rod-steps (of `steps_kept`) whose residual was still above the tolerance after the
    /// last iteration.
    pub unconverged_steps: u64,
    /// Rod-steps that diverged or ended far from converged and were retaken in halves
    /// (`StiffSettings::halve_above`, `max_halvings`).
    pub halved_steps: u64,
    /// Rod-steps of inextensible rods retaken with the material's axial compliance
    /// (`StiffSettings::axial_fallback`).
    pub axial_steps: u64,
    /// Largest residual at the end of any rod-step.
    pub max_residual: f64,
    /// The largest residual tolerance a rod-step was held to (the settings', raised for `f32`
    /// rods to the strain their positions resolve).
    pub max_tolerance: f64,
    /// The step (its index, of the simulation's steps) at which a rod ended with
    /// [`max_residual`](Self::max_residual).
    pub worst_step: u64,
    /// The last step (its index) at which a rod ended above its tolerance, if any: a run
    /// whose only loose steps were early transients ends converged.
    pub last_unconverged_step: Option<u64>,
}

impl StiffSummary {
    /// The reports of every rod summed, after `steps` steps of them all, with the settings'
    /// `tolerance` as the least of [`max_tolerance`](Self::max_tolerance).
    pub fn of_reports(
        reports: impl IntoIterator<Item = StiffReport>,
        steps: u64,
        tolerance: f64,
    ) -> Self {
        let mut s = StiffSummary {
            max_tolerance: tolerance,
            ..StiffSummary::default()
        };
        for r in reports {
            s.rod_steps += steps;
            s.iterations += r.total_iterations;
            s.factorisations += r.factorisations;
            s.steps_kept += r.steps;
            s.unconverged_steps += r.unconverged_steps;
            s.halved_steps += r.halved_steps;
            s.axial_steps += r.axial_steps;
            if r.max_residual > s.max_residual {
                s.max_residual = r.max_residual;
                s.worst_step = r.worst_step;
            }
            s.max_tolerance = s.max_tolerance.max(r.max_tolerance);
            s.last_unconverged_step = s.last_unconverged_step.max(r.last_unconverged_step);
        }
        s
    }

    /// Newton iterations per rod-step (0 before the first step).
    pub fn iterations_per_step(&self) -> f64 {
        self.iterations as f64 / self.rod_steps.max(1) as f64
    }

    /// Factorisations per rod-step (0 before the first step).
    pub fn factorisations_per_step(&self) -> f64 {
        self.factorisations as f64 / self.rod_steps.max(1) as f64
    }
}
