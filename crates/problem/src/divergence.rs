//! What a stepper reports when a rod leaves the bounds of a sane simulation, and what it measured
//! of the steps that went well.

/// What went wrong when a rod diverged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DivergedQuantity {
    /// A point position became NaN or infinite.
    NonFinitePosition,
    /// A frame became NaN, infinite or degenerate.
    NonFiniteFrame,
    /// A segment's length ratio `l / l0` left the allowed band.
    Strain(f64),
    /// A point moved faster than the allowed speed [m/s]: energy is running away while the
    /// lengths still hold (an explicit scheme past its stable step).
    Speed(f64),
    /// The stiff solver's step ended with this residual (a strain, or a bend–twist angle per
    /// element), far above its tolerance (`StiffSettings::halve_above`), also in halves.
    Unconverged(f64),
    /// A point is outside the lumen of the mesh it collides with, this deep behind the wall
    /// (distance plus the rod's radius) [m]: the contacts did not hold it.
    OutsideLumen(f64),
    /// The force at a held end [N] is beyond the bound given second [N] (a multiple of the rod's
    /// `E A`, `SimulationBuilder::reaction_limit` in the facade).
    Reaction(f64, f64),
    /// The total energy grew by the first amount [J], beyond the second: what the loads and
    /// driven ends could have done, plus the schemes' wander (`cosserat::energy_watch`).
    EnergyGrowth(f64, f64),
}

/// A rod that diverged: which one, where, when, and what.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Divergence {
    /// Index of the rod in the simulation.
    pub rod: usize,
    /// The first offending element (or point, for positions).
    pub element: usize,
    /// Step index at which it was detected.
    pub step: u64,
    /// The quantity that left its bounds.
    pub quantity: DivergedQuantity,
}

impl std::fmt::Display for Divergence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let what = match self.quantity {
            DivergedQuantity::NonFinitePosition => "position is not finite".to_string(),
            DivergedQuantity::NonFiniteFrame => "frame is not finite".to_string(),
            DivergedQuantity::Strain(s) => {
                format!("strain |l/l0 - 1| = {s:.3e} exceeds the divergence limit")
            }
            DivergedQuantity::Speed(v) => {
                format!("speed {v:.3e} m/s exceeds the divergence limit")
            }
            DivergedQuantity::Unconverged(r) => {
                format!("the stiff solver's step ended at residual {r:.3e}, far from converged")
            }
            DivergedQuantity::Reaction(force, bound) => format!(
                "the force at the held end, {force:.3e} N, is beyond the bound of {bound:.3e} N (a multiple of the rod's E A)"
            ),
            DivergedQuantity::EnergyGrowth(growth, allowed) => format!(
                "the total energy grew by {growth:.3e} J, beyond the {allowed:.3e} J that the loads and driven ends could have put in (set solver.energy_check = false to go on)"
            ),
            DivergedQuantity::OutsideLumen(depth) => format!(
                "the point is outside the lumen, {depth:.3e} m behind the wall (set environment.stop_outside = false to go on)"
            ),
        };
        write!(
            f,
            "simulation diverged: rod {}, element {}, step {}: {what} (reduce dt or raise the damping)",
            self.rod, self.element, self.step
        )
    }
}

impl std::error::Error for Divergence {}

/// Per-step measurements of one rod.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepStats {
    /// Smallest segment length ratio `l / l0` after the step.
    pub min_stretch: f64,
    /// Largest segment length ratio `l / l0` after the step.
    pub max_stretch: f64,
}

impl StepStats {
    /// The statistics of no step (the identity of [`Self::merged`]).
    pub fn none() -> Self {
        Self {
            min_stretch: f64::MAX,
            max_stretch: 0.0,
        }
    }

    /// The statistics of two runs together.
    pub fn merged(self, other: Self) -> Self {
        Self {
            min_stretch: self.min_stretch.min(other.min_stretch),
            max_stretch: self.max_stretch.max(other.max_stretch),
        }
    }

    /// Largest `|l / l0 − 1|`.
    pub fn max_strain(&self) -> f64 {
        (self.max_stretch - 1.0).max(1.0 - self.min_stretch)
    }
}

/// The first point of any rod faster than `limit` [m/s], or frame whose surface (at the rod's
/// radius) spins faster: the runaway-energy check every stepper runs on its state. Twisting is
/// usually the fastest mode, so a frame can spin away while the centreline still looks fine.
/// `rods` yields each rod's state and radius, in rod order; `step` labels the report.
pub fn first_too_fast<'a, T: cosserat_model::Real>(
    rods: impl Iterator<Item = (&'a cosserat_model::RodState<T>, T)>,
    limit: f64,
    step: u64,
) -> Result<(), Divergence> {
    for (rod, (state, radius)) in rods.enumerate() {
        let points = state.velocities.iter().map(|v| v.norm());
        let frames = state.angular_velocities.iter().map(|w| w.norm() * radius);
        for (element, speed) in points.chain(frames).enumerate() {
            let element = element % state.velocities.len();
            let speed = speed.to_f64();
            if !(speed <= limit) {
                let quantity = if speed.is_finite() {
                    DivergedQuantity::Speed(speed)
                } else {
                    DivergedQuantity::NonFinitePosition
                };
                return Err(Divergence {
                    rod,
                    element,
                    step,
                    quantity,
                });
            }
        }
    }
    Ok(())
}
