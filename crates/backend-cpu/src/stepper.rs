//! The time step (paper Fig. 5, without collisions) and its parallel driver.

use crate::ends::EndCondition;
use constraints::{Ordering, solve_distance_iteration};
use cosserat_model::energy::{ForceModel, accumulate_forces};
use cosserat_model::quat::rotate_inv;
use cosserat_model::{Quat, Real, RodParams, RodState, Vec3};

/// Serial or parallel execution, chosen at run time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Par {
    /// One thread.
    #[default]
    Serial,
    /// Rods spread over rayon's thread pool (serial when the `rayon` feature is off).
    Rayon,
}

/// Solver settings shared by every rod of a simulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverSettings<T: Real> {
    /// Time step `h` [s].
    pub dt: T,
    /// Distance-constraint sweeps per step (the paper uses 10).
    pub iterations: usize,
    /// Order of each sweep.
    pub ordering: Ordering,
    /// Extensible mode (stretch energy, no distance constraints) instead of inextensible.
    pub extensible: bool,
    /// Gravitational acceleration [m/s²].
    pub gravity: Vec3<T>,
    /// A segment stretched or compressed by more than this fraction of its rest length means the
    /// simulation has diverged.
    pub divergence_strain: T,
}

/// A constant external force on one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLoad<T: Real> {
    /// Index of the point.
    pub point: usize,
    /// Force [N], world frame.
    pub force: Vec3<T>,
}

/// One rod as the CPU backend steps it: state, parameters, end conditions, loads and scratch.
#[derive(Clone, Debug)]
pub struct CpuRod<T: Real> {
    /// The dynamic state.
    pub state: RodState<T>,
    /// Parameters; inverse masses of held points are zero.
    pub params: RodParams<T>,
    /// Conditions at the first (`[0]`) and last (`[1]`) end.
    pub ends: [EndCondition<T>; 2],
    /// External point forces.
    pub loads: Vec<PointLoad<T>>,
    inv_inertias: Vec<Vec3<T>>,
    forces: Vec<Vec3<T>>,
    torques: Vec<Vec3<T>>,
}

impl<T: Real> CpuRod<T> {
    /// Prepares a rod for stepping: held end points get zero inverse mass.
    pub fn new(state: RodState<T>, mut params: RodParams<T>, ends: [EndCondition<T>; 2], loads: Vec<PointLoad<T>>) -> Self {
        let n = state.elements();
        if ends[0].holds_point() {
            params.inv_masses[0] = T::zero();
        }
        if ends[1].holds_point() {
            params.inv_masses[n] = T::zero();
        }
        let inv_inertias = params.inertias.iter().map(|i| i.map(|x| T::one() / x)).collect();
        Self {
            state,
            params,
            ends,
            loads,
            inv_inertias,
            forces: vec![Vec3::zeros(); n + 1],
            torques: vec![Vec3::zeros(); n],
        }
    }

    /// Number of elements.
    pub fn elements(&self) -> usize {
        self.state.elements()
    }
}

/// What went wrong when a rod diverged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DivergedQuantity {
    /// A point position became NaN or infinite.
    NonFinitePosition,
    /// A frame became NaN, infinite or degenerate.
    NonFiniteFrame,
    /// A segment's length ratio `l / l0` left the allowed band.
    Strain(f64),
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
            DivergedQuantity::Strain(s) => format!("strain |l/l0 - 1| = {s:.3e} exceeds the divergence limit"),
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
    /// Largest `|l / l0 − 1|`.
    pub fn max_strain(&self) -> f64 {
        (self.max_stretch - 1.0).max(1.0 - self.min_stretch)
    }
}

/// Advances one rod by one step of `settings.dt` starting at time `time`.
///
/// `rod_index` and `step` only label a [`Divergence`].
pub fn step_rod<T: Real>(rod: &mut CpuRod<T>, settings: &SolverSettings<T>, time: f64, rod_index: usize, step: u64) -> Result<StepStats, Divergence> {
    let h = settings.dt;
    let n = rod.elements();
    let model = ForceModel { extensible: settings.extensible, gravity: settings.gravity };
    accumulate_forces(&rod.state, &rod.params, &model, &mut rod.forces, &mut rod.torques);
    for load in &rod.loads {
        rod.forces[load.point] += load.force;
    }

    // Integrate velocities (semi-implicit Euler): v += h f / m, and Euler's equations for frames.
    let s = &mut rod.state;
    for ((v, f), &w) in s.velocities.iter_mut().zip(&rod.forces).zip(&rod.params.inv_masses) {
        *v += f * (h * w);
    }
    for (((om, tq), inertia), inv) in s.angular_velocities.iter_mut().zip(&rod.torques).zip(&rod.params.inertias).zip(&rod.inv_inertias) {
        let gyro = om.cross(&inertia.component_mul(om));
        *om += (tq - gyro).component_mul(inv) * h;
    }

    // Held ends follow their prescribed motion exactly.
    for (end, (point, frame)) in rod.ends.iter().zip([(0, 0), (n, n - 1)]) {
        if end.holds_point() {
            let (v, w) = end.velocities_at(time);
            s.velocities[point] = v;
            if end.holds_frame() {
                s.angular_velocities[frame] = rotate_inv(&s.frames[frame], &w);
            }
        }
    }

    if !settings.extensible {
        for _ in 0..settings.iterations {
            solve_distance_iteration(&s.positions, &mut s.velocities, &rod.params.inv_masses, &rod.params.rest_lengths, h, settings.ordering);
        }
    }

    integrate_positions(s, &rod.params, h, settings.divergence_strain).map_err(|(element, quantity)| Divergence { rod: rod_index, element, step, quantity })
}

/// `r += h v`, `q ← normalise(q ⊗ (1, h ω / 2))`, and the length-ratio check, in one sweep.
fn integrate_positions<T: Real>(s: &mut RodState<T>, p: &RodParams<T>, h: T, limit: T) -> Result<StepStats, (usize, DivergedQuantity)> {
    let n = s.elements();
    let half_h = h * T::lit(0.5);
    for (q, w) in s.frames.iter_mut().zip(&s.angular_velocities) {
        // First-order quaternion update followed by renormalisation; the rotation per step is
        // small, and this avoids a sine and cosine per frame.
        let dq = *q * Quat::from_parts(T::zero(), w * half_h);
        let next = *q + dq;
        *q = next;
    }
    for (j, q) in s.frames.iter_mut().enumerate() {
        let n2 = q.norm_squared();
        if !(n2 > T::zero() && n2.is_finite()) {
            return Err((j, DivergedQuantity::NonFiniteFrame));
        }
        *q /= n2.sqrt();
    }
    s.positions[0] += s.velocities[0] * h;
    let (lo2, hi2) = ((T::one() - limit) * (T::one() - limit), (T::one() + limit) * (T::one() + limit));
    let (mut min_r, mut max_r) = (T::lit(f64::MAX), T::zero());
    for j in 0..n {
        let next = s.positions[j + 1] + s.velocities[j + 1] * h;
        s.positions[j + 1] = next;
        let l0 = p.rest_lengths[j];
        let r = (next - s.positions[j]).norm_squared() / (l0 * l0);
        if !(r >= lo2 && r <= hi2) {
            if !r.is_finite() {
                return Err((j, DivergedQuantity::NonFinitePosition));
            }
            return Err((j, DivergedQuantity::Strain((r.sqrt() - T::one()).abs().to_f64())));
        }
        min_r = min_r.min(r);
        max_r = max_r.max(r);
    }
    Ok(StepStats { min_stretch: min_r.sqrt().to_f64(), max_stretch: max_r.sqrt().to_f64() })
}

/// Advances many independent rods by one step, serially or in parallel; results are identical.
///
/// Returns each rod's stats, or the divergence of the lowest-numbered rod that diverged.
pub fn step_rods<T: Real>(rods: &mut [CpuRod<T>], settings: &SolverSettings<T>, time: f64, step: u64, par: Par, stats: &mut Vec<StepStats>) -> Result<(), Divergence> {
    stats.clear();
    match par {
        #[cfg(feature = "rayon")]
        Par::Rayon => {
            use rayon::prelude::*;
            let results: Vec<_> = rods.par_iter_mut().enumerate().map(|(i, rod)| step_rod(rod, settings, time, i, step)).collect();
            for r in results {
                stats.push(r?);
            }
        }
        _ => {
            for (i, rod) in rods.iter_mut().enumerate() {
                stats.push(step_rod(rod, settings, time, i, step)?);
            }
        }
    }
    Ok(())
}
