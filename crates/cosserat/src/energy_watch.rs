//! Energy that appears from nowhere: a run whose total energy grows beyond the work its loads
//! and driven ends could have done has blown up, even while its speeds, strains and reactions
//! still look plausible.
//!
//! Every [`CHECK_EVERY`] steps (at the end of the `Simulation::run` call that passes them) the
//! total energy `E` (kinetic, elastic and gravitational: `Stepper::energies`) is compared with
//! its value `E₀` when watching began. The work done on the rods since is bounded from above:
//! - a held end that moved by `Δx` and turned by `Δθ` between two checks did at most
//!   `F Δx + M Δθ`, with `F`, `M` the largest force and torque measured at that end over the
//!   calls in between (`Stepper::end_reaction`);
//! - a point load `f` on a point that moved by `Δx` did at most `|f| |Δx|`, and its moment
//!   `m` at most `|m| Δθ`, `Δθ` the angle the frame beside the point turned by (both at the
//!   largest factor of the load's profile);
//! - contacts, friction and damping only take energy out.
//!
//! A driven end also gives the rod kinetic energy in jumps (an end set moving from one step to
//! the next pulls its neighbours along through the constraints within the step, an impulse the
//! filtered reactions do not see): each end may have given at most the kinetic energy of the
//! whole rod moving with it, `½ M (|v| + |ω| L)²`, with its speed and turning rate between the
//! two checks, `M` and `L` the rod's mass and length; `D` is the largest of these seen.
//!
//! The run has diverged when `E − E₀ > 2 W + D + max(K + U_el) + floor`, with `W` the bound on
//! the work and `max(K + U_el)` the largest kinetic plus elastic energy seen at the earlier
//! checks (the schemes do not conserve energy exactly: the explicit scheme's energy swings by a
//! part of the energy in motion, the more the nearer its step is to the stable limit). A run
//! that blows up more than doubles its energy between two checks, and is caught; `SimulationBuilder::energy_check(false)` (or
//! `solver.energy_check = false`) lets it go on.
//!
//! The explicit schemes are watched (on the CPU, coupled or not, and on the GPU); the stiff
//! scheme is not. Its steps are implicit and do not blow up (a step that fails to converge is
//! reported as such), and the model's energy of its states is not a quantity its steps bound:
//! a two-element `f32` rod released from a curved rest shape at 1 ms steps reached three times
//! its initial energy within 129 steps (a case of `tests/stability.rs`), while staying far
//! below any blow-up.
//!
//! A moving obstacle (`crate::obstacles`) does work on the rods through its contacts, which
//! nothing measures (a conveyor gives a rope its speed, a rising floor lifts it): a scene with
//! one is not watched.
//!
//! A held end that moves where the stepper measures no reaction makes the work unknown: the
//! watch stops until it is reset. Writing the state, restoring a snapshot or changing an end's
//! condition resets it (the energy then is the user's, not the run's).

use cosserat_problem::{PointLoad, StateField, Stepper};

/// Steps between two checks. A check costs one pass over the rods (energies) and a read of
/// their points and frames; every 64 steps it is a small fraction of a step's cost.
pub const CHECK_EVERY: u64 = 64;

/// Fraction of the largest kinetic plus elastic energy seen at earlier checks by which the total
/// may grow unexplained. The explicit scheme's energy is that of a nearby ("shadow")
/// Hamiltonian: near its stable step it swings by up to the whole energy in motion (a straight
/// rod at rest at half its critical step swung by 12 % of it), so only a doubling is a
/// blow-up.
const WANDER: f64 = 1.0;

/// Where a held end was: its point and its frame's first and third directors.
type EndMark = ([f64; 3], [f64; 3], [f64; 3]);

/// Where a rod's held ends and loaded points were at the last check.
#[derive(Clone, Debug, Default)]
struct RodMarks {
    /// Per held end: where it was.
    ends: [Option<EndMark>; 2],
    /// Per end: the largest force [N] and torque [N m] measured since the last check.
    peak: [(f64, f64); 2],
    /// Per end: whether the stepper measured a reaction since the last check.
    measured: [bool; 2],
    /// Per load: where its point was and how the frame beside it was turned.
    loads: Vec<EndMark>,
}

/// The watch over one simulation's energy.
#[derive(Clone, Debug)]
pub(crate) struct EnergyWatch {
    pub(crate) enabled: bool,
    /// Whether a baseline is set (`None` until the first check after a reset).
    baseline: Option<f64>,
    /// Gravity's part of the baseline, for the floor (rounding of a large potential).
    gravity0: f64,
    /// Largest kinetic plus elastic energy seen [J].
    in_motion: f64,
    /// The bound on the work done since the baseline [J].
    work: f64,
    /// The most kinetic energy the driven ends can have given the rods in jumps [J].
    drive: f64,
    /// Per rod: its mass [kg] and length [m].
    rod_sizes: Vec<(f64, f64)>,
    /// Time of the last check [s].
    last_time: f64,
    /// The work cannot be bounded (an end moved without a measured reaction).
    blind: bool,
    next_check: u64,
    rods: Vec<RodMarks>,
    points: Vec<[f64; 3]>,
    d1: Vec<[f64; 3]>,
    d3: Vec<[f64; 3]>,
}

/// What a failed check found.
pub(crate) struct Growth {
    pub(crate) growth: f64,
    pub(crate) allowed: f64,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    let c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (norm(a) * norm(b));
    c.clamp(-1.0, 1.0).acos()
}

impl EnergyWatch {
    /// `rod_sizes`: each rod's mass [kg] and length [m].
    pub(crate) fn new(enabled: bool, rod_sizes: Vec<(f64, f64)>) -> Self {
        Self {
            enabled,
            drive: 0.0,
            rod_sizes,
            last_time: 0.0,
            baseline: None,
            gravity0: 0.0,
            in_motion: 0.0,
            work: 0.0,
            blind: false,
            next_check: 0,
            rods: Vec::new(),
            points: Vec::new(),
            d1: Vec::new(),
            d3: Vec::new(),
        }
    }

    /// Stops watching for good (an obstacle set moving: its work is not measured).
    pub(crate) fn disable(&mut self) {
        self.enabled = false;
    }

    /// Forgets the baseline: the next check starts watching anew.
    pub(crate) fn reset(&mut self) {
        self.baseline = None;
        self.blind = false;
    }

    /// Records the reactions measured after a call to `run` (the peaks between two checks).
    pub(crate) fn record_reactions(&mut self, stepper: &dyn Stepper) {
        if !self.enabled || self.baseline.is_none() {
            return;
        }
        for (rod, marks) in self.rods.iter_mut().enumerate() {
            for end in 0..2 {
                if let Some(r) = stepper.end_reaction(rod, end) {
                    let p = &mut marks.peak[end];
                    p.0 = p.0.max(r.force_norm());
                    p.1 = p.1.max(r.torque_norm());
                    marks.measured[end] = true;
                }
            }
        }
    }

    /// Reads where the held ends and loaded points of `rod` are.
    fn mark(&mut self, stepper: &dyn Stepper, rod: usize, loads: &[PointLoad<f64>]) -> RodMarks {
        let held = [0, 1].map(|end| {
            stepper
                .end_condition(rod, end)
                .is_ok_and(|c| c.holds_point())
        });
        let n = stepper.elements(rod).unwrap_or(0);
        let mut marks = RodMarks::default();
        // A free rod without loads has nothing to mark: no reads.
        if n == 0 || (held == [false; 2] && loads.is_empty()) {
            return marks;
        }
        self.points.resize(n + 1, [0.0; 3]);
        self.d1.resize(n, [0.0; 3]);
        self.d3.resize(n, [0.0; 3]);
        let ok = stepper
            .read(rod, StateField::Positions, &mut self.points)
            .is_ok()
            && stepper
                .read(rod, StateField::Director(0), &mut self.d1)
                .is_ok()
            && stepper
                .read(rod, StateField::Director(2), &mut self.d3)
                .is_ok();
        if !ok {
            return marks;
        }
        for (end, (point, frame)) in [(0, 0), (n, n - 1)].into_iter().enumerate() {
            if held[end] {
                marks.ends[end] = Some((self.points[point], self.d1[frame], self.d3[frame]));
            }
        }
        marks.loads = loads
            .iter()
            .map(|l| {
                let frame = l.point.min(n - 1);
                (
                    self.points.get(l.point).copied().unwrap_or([0.0; 3]),
                    self.d1[frame],
                    self.d3[frame],
                )
            })
            .collect();
        marks
    }

    /// Checks if `steps` has reached the next check. `loads[rod]` are the point loads. `Err`
    /// when the energy grew beyond what the work explains.
    pub(crate) fn check(
        &mut self,
        stepper: &dyn Stepper,
        steps: u64,
        time: f64,
        loads: &[Vec<PointLoad<f64>>],
    ) -> Result<(), Growth> {
        if !self.enabled || self.blind || steps < self.next_check {
            return Ok(());
        }
        self.next_check = steps + CHECK_EVERY;
        let e = stepper.energies();
        let total = e.potential() + e.kinetic();
        let moving = e.kinetic() + e.potential() - e.gravity;
        let rods = stepper.rod_count();
        let no_loads = Vec::new();
        let mut marks = Vec::with_capacity(rods);
        for rod in 0..rods {
            let l = loads.get(rod).unwrap_or(&no_loads);
            marks.push(self.mark(stepper, rod, l));
        }
        let Some(baseline) = self.baseline else {
            self.baseline = Some(total);
            self.gravity0 = e.gravity;
            self.in_motion = moving;
            self.work = 0.0;
            self.drive = 0.0;
            self.last_time = time;
            self.rods = marks;
            return Ok(());
        };
        let elapsed = time - self.last_time;
        self.last_time = time;
        for (rod, (old, new)) in self.rods.iter().zip(&marks).enumerate() {
            for end in 0..2 {
                if let (Some(a), Some(b)) = (old.ends[end], new.ends[end]) {
                    let (dx, dtheta) = (norm(sub(b.0, a.0)), angle(a.1, b.1) + angle(a.2, b.2));
                    if dx + dtheta > 0.0 && !old.measured[end] {
                        self.blind = true;
                        return Ok(());
                    }
                    let (f, m) = old.peak[end];
                    self.work += f * dx + m * dtheta;
                    if elapsed > 0.0 {
                        let (mass, length) = self.rod_sizes.get(rod).copied().unwrap_or_default();
                        let speed = (dx + dtheta * length) / elapsed;
                        self.drive = self.drive.max(0.5 * mass * speed * speed);
                    }
                }
            }
            let l = loads.get(rod).unwrap_or(&no_loads);
            for ((load, a), b) in l.iter().zip(&old.loads).zip(&new.loads) {
                let most = load.profile.max_factor();
                let dx = norm(sub(b.0, a.0));
                let dtheta = angle(a.1, b.1) + angle(a.2, b.2);
                self.work +=
                    most * (norm(load.force.into()) * dx + norm(load.moment.into()) * dtheta);
            }
        }
        self.rods = marks;
        let growth = total - baseline;
        let floor = 1e-9 + 1e-6 * self.gravity0.abs();
        let allowed = 2.0 * self.work.max(0.0) + self.drive + WANDER * self.in_motion + floor;
        self.in_motion = self.in_motion.max(moving);
        if growth > allowed || !growth.is_finite() {
            self.blind = true;
            return Err(Growth { growth, allowed });
        }
        Ok(())
    }
}
