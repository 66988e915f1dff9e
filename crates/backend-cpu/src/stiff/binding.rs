//! Bindings (a guidewire held inside a catheter, paper section 3.4) in the stiff scheme.
//!
//! The explicit scheme solves a binding by impulses on both rods' velocities inside its
//! constraint iterations (`crate::coupling`). The stiff scheme solves each rod's step as one
//! banded system; a binding between two rods would couple two such systems into one that is no
//! longer banded. So the rods are stepped one after the other, each with the other's answer:
//!
//! 1. at the start of the step, every inner point's nearest point on the outer centreline is
//!    found ([`BindingSet::update`], the explicit scheme's search: points past the outer rod's
//!    tip or farther than the capture distance are free);
//! 2. the rods are stepped in an order in which every outer rod comes before the rods bound
//!    inside it;
//! 3. an inner rod's bound points are held for its solve on the line through their nearest
//!    point of the outer rod's **new** centreline, along that segment's new direction: pinned
//!    like the points of an introducer guide (inverse mass `w t tᵀ` in the Newton matrix and the
//!    updates, `Work::pin_blocks`), so the wire slides freely along the catheter and follows it
//!    sideways within the same step. The offset a point had at the start of the step is
//!    removed by the fraction `offset_correction` of the binding ([`BindingSet`]), as in the
//!    explicit scheme;
//! 4. one-way (v1): that is all, the outer rod does not feel the inner one. Two-way (v2): the
//!    force each line exerted on the inner rod (`M (x − x̃) − Jᵀλ` over `h²` at the pinned
//!    point, the implicit step's own balance) is applied, reversed and split by the segment
//!    parameter, to the outer rod's two points as a load **in its next step**, relaxed
//!    ([`RELAXATION`]).
//!
//! The two-way coupling therefore lags by one step: a partitioned scheme, exact at rest (a
//! static state is a fixed point: the loads no longer change) and first order in `h` in motion,
//! like the step itself. It is stable while the inner rod answers a sideways move of the outer
//! one more weakly than the outer rod resists it (up to five times more strongly with the
//! relaxation); a guidewire is lighter and softer than its catheter, except next to its own
//! held end, so a wire whose hand is pushed into the catheter's hub is not (counted in
//! [`CouplingStats::held_ends_inside`]). Points of an element whose frame is held are not
//! bound at all (see [`pin_on_lines`]). `docs/stiff-solver.md` ("Bindings") has the
//! measurements.
//!
//! A rod may be the inner rod of one binding only (two lines on one point would fight), and
//! bindings may not form a cycle. Rod–rod and self-contact (`rod_contact.rs`) are stepped by the
//! same loop: detected at the start of each step, held inside each rod's solve, their reactions
//! passed on with the same lag.

use super::contact::pin_impulse;
use super::pin::Pinned;
use super::rod_contact::StiffRodContacts;
use super::work::Work;
use super::{Consts, Coupled, LinePin, StiffScratch, StiffSettings, step_rod_stiff};
use crate::coupling::{BindingSpec, CouplingStats, RodContactSpec};
use crate::stepper::{CpuRod, Divergence, SolverSettings, StepStats};
use cosserat_constraints::{BindingSet, BindingVariant};
use cosserat_model::{Real, Vec3};

/// One binding: its spec's rods and the explicit scheme's nearest-point search.
#[derive(Clone, Debug)]
struct Bound<T: Real> {
    inner: usize,
    outer: usize,
    set: BindingSet<T>,
    /// Two-way: the load on each of the outer rod's points for its next step [N] (relaxed,
    /// see [`RELAXATION`]).
    reaction: Vec<Vec3<f64>>,
}

/// The fraction by which the two-way load on the outer rod moves towards the inner rod's latest
/// answer per step, `F ← F + β (F_new − F)`.
///
/// With the full answer (β = 1) the partitioned step is stable only while the inner rod's
/// answer to a sideways move of the outer one is weaker than the outer rod's own resistance to
/// it (gain `g < 1`); near the outer rod's clamp the catheter is locally softer than the wire
/// driven into it, and a nitinol wire pushed into a polymer catheter's clamped hub made it
/// diverge within 60 steps (`docs/stiff-solver.md`, "Bindings"). With β the step is stable for
/// `g < 2/β − 1` (5 at β = 1/3). A static state is the same for any β; in motion the load
/// lags by about `h (1 − β)/β` (two steps).
const RELAXATION: f64 = 1.0 / 3.0;

/// The bindings of a simulation stepped with the stiff scheme ([`step_bound_stiff`]).
#[derive(Clone, Debug)]
pub struct StiffBindings<T: Real> {
    bindings: Vec<Bound<T>>,
    /// Rod indices in stepping order: every outer rod before the rods bound inside it.
    order: Vec<usize>,
    /// Per rod: its force on the points of its outer rod, accumulated (scratch).
    sums: Vec<Vec3<f64>>,
    stats: CouplingStats,
    /// Rod–rod and self-contact, if on.
    contacts: Option<StiffRodContacts>,
}

impl<T: Real> StiffBindings<T> {
    /// Checks the specs against the rods (indices, capture distance, at most one binding per
    /// inner rod, no cycle) and finds the stepping order.
    pub fn new(rods: &[CpuRod<T>], specs: &[BindingSpec]) -> Result<Self, String> {
        let n = rods.len();
        let mut bindings: Vec<Bound<T>> = Vec::new();
        for (k, b) in specs.iter().enumerate() {
            let capture = b.checked_capture(k, rods)?;
            if b.variant == BindingVariant::None {
                continue;
            }
            if bindings.iter().any(|o| o.inner == b.inner) {
                return Err(format!(
                    "binding {k}: rod {} is already the inner rod of another binding; the stiff \
                     scheme holds a point on one line only",
                    b.inner
                ));
            }
            bindings.push(Bound {
                inner: b.inner,
                outer: b.outer,
                set: BindingSet::new(b.variant, T::lit(capture), rods[b.inner].elements() + 1),
                reaction: Vec::new(),
            });
        }
        // Each rod has at most one outer rod: follow the chain to order them.
        let outer_of = |r: usize| bindings.iter().find(|b| b.inner == r).map(|b| b.outer);
        let mut depth = vec![0usize; n];
        for (r, d) in depth.iter_mut().enumerate() {
            let mut at = r;
            while let Some(o) = outer_of(at) {
                *d += 1;
                if *d > n {
                    return Err(format!(
                        "bindings: rod {r} is bound inside itself through a cycle of bindings"
                    ));
                }
                at = o;
            }
        }
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&r| depth[r]);
        Ok(Self {
            bindings,
            order,
            sums: Vec::new(),
            stats: CouplingStats::default(),
            contacts: None,
        })
    }

    /// Adds rod–rod and self-contact among `rods` (`rod_contact.rs`); rods bound to each other
    /// do not touch.
    #[must_use]
    pub fn with_rod_contacts(mut self, rods: &[CpuRod<T>], spec: Option<RodContactSpec>) -> Self {
        self.contacts = spec.map(|spec| {
            let excluded = self
                .bindings
                .iter()
                .map(|b| (b.inner.min(b.outer), b.inner.max(b.outer)))
                .collect();
            StiffRodContacts::new(rods, &spec, excluded)
        });
        self
    }

    /// Measurements since the start: bound points of the last step, steps, the search's time,
    /// and the rod contacts' counts and smallest separation.
    pub fn stats(&self) -> CouplingStats {
        let mut s = self.stats;
        if let Some(c) = &self.contacts {
            let r = &c.stats;
            s.contacts = r.contacts;
            s.max_contacts = r.max_contacts;
            s.min_separation = r.min_separation;
            s.min_separation_radii = r.min_separation_radii;
            s.min_separation_ratio = r.min_separation_ratio;
            s.detection_seconds += r.detection_seconds;
            s.steps = s.steps.max(r.steps);
        }
        s
    }

    /// Number of points bound by the `k`-th binding that is not of variant `None`, at the last
    /// step.
    pub fn bound_points(&self, k: usize) -> usize {
        self.bindings.get(k).map_or(0, |b| b.set.bound().len())
    }
}

/// Advances bound rods by `steps` steps of the stiff scheme, in lock step (see the module
/// docs); `scratches[i]` belongs to `rods[i]`. Fills `stats` with one entry per rod. A rod that
/// diverges stops the batch with its [`Divergence`]; the rods stepped before it in that step
/// keep it.
///
/// # Panics
/// If `scratches` and `rods` differ in length.
pub fn step_bound_stiff<T: Real>(
    rods: &mut [CpuRod<T>],
    scratches: &mut [StiffScratch],
    bindings: &mut StiffBindings<T>,
    settings: &SolverSettings<T>,
    stiff: &StiffSettings,
    time: f64,
    first_step: u64,
    steps: u64,
    stats: &mut Vec<StepStats>,
) -> Result<(), Divergence> {
    assert_eq!(rods.len(), scratches.len(), "one stiff scratch per rod");
    let h = settings.dt.to_f64();
    stats.clear();
    stats.resize(rods.len(), StepStats::none());
    for step in 0..steps {
        let t = time + step as f64 * h;
        // 1. Nearest points at the start of the step.
        let t0 = std::time::Instant::now();
        let mut bound = 0;
        let mut held_inside = false;
        for b in &mut bindings.bindings {
            let inner = &rods[b.inner];
            b.set
                .update(&inner.state.positions, &rods[b.outer].state.positions);
            bound += b.set.bound().len();
            let last = inner.elements() as u32;
            held_inside |= b.set.bound().iter().any(|p| {
                (p.point == 0 && inner.ends[0].holds_point())
                    || (p.point == last && inner.ends[1].holds_point())
            });
        }
        bindings.stats.held_ends_inside += u64::from(held_inside);
        bindings.stats.detection_seconds += t0.elapsed().as_secs_f64();
        bindings.stats.bound_points = bound;
        if let Some(c) = bindings.contacts.as_mut() {
            c.detect(&*rods, scratches, t, h, stiff.contact_rows);
        }
        // 2. Outer rods first.
        for oi in 0..bindings.order.len() {
            let r = bindings.order[oi];
            let coupled = &mut scratches[r].coupled;
            coupled.lines.clear();
            coupled.loads.clear();
            for b in bindings.bindings.iter().filter(|b| b.inner == r) {
                lines_on_outer(&b.set, &rods[b.outer].state.positions, &mut coupled.lines);
            }
            for b in bindings.bindings.iter().filter(|b| b.outer == r) {
                coupled.loads.extend(
                    b.reaction
                        .iter()
                        .enumerate()
                        .filter(|(_, f)| **f != Vec3::zeros())
                        .map(|(i, f)| (i, *f)),
                );
            }
            if let Some(c) = bindings.contacts.as_ref() {
                c.add_loads(r, &mut coupled.loads);
            }
            let s = step_rod_stiff(
                &mut rods[r],
                settings,
                stiff,
                &mut scratches[r],
                t,
                r,
                first_step + step,
                1,
            )?;
            stats[r] = stats[r].merged(s);
            if let Some(c) = bindings.contacts.as_mut() {
                c.collect(&scratches[r].planes);
            }
            // 4. Two-way: the lines' forces, reversed, load the outer rod's next step.
            if let Some(b) = bindings
                .bindings
                .iter_mut()
                .find(|b| b.inner == r && b.set.variant == BindingVariant::TwoWay)
            {
                reaction_on_outer(
                    &b.set,
                    &scratches[r].coupled.line_forces,
                    rods[b.outer].state.positions.len(),
                    &mut bindings.sums,
                );
                b.reaction.resize(bindings.sums.len(), Vec3::zeros());
                for (f, new) in b.reaction.iter_mut().zip(&bindings.sums) {
                    *f += (new - *f) * RELAXATION;
                }
            }
        }
        if let Some(c) = bindings.contacts.as_mut() {
            c.relax();
        }
        bindings.stats.steps += 1;
    }
    Ok(())
}

/// Step 3 of the module docs: the line of every bound point, through its nearest point of the
/// outer centreline `outer` (already stepped) along that segment, shifted by what is left of
/// its offset at the start of the step. One line per bound point, in order (the reaction reads
/// the lines' forces against `set.bound()`).
fn lines_on_outer<T: Real>(set: &BindingSet<T>, outer: &[Vec3<T>], lines: &mut Vec<LinePin>) {
    let f = |v: &Vec3<T>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
    let keep = 1.0 - set.offset_correction.to_f64();
    for b in set.bound() {
        let j = b.segment as usize;
        let (a, c) = (f(&outer[j]), f(&outer[j + 1]));
        let e = c - a;
        let len = e.norm();
        // A segment the step collapsed (it cannot, inextensible; extensible, only by diverging)
        // keeps its direction at the start of the step.
        let t = if len > 0.0 { e / len } else { f(&b.tangent) };
        let s = b.s.to_f64();
        let offset = f(&b.offset);
        let left = (offset - t * t.dot(&offset)) * keep;
        lines.push(LinePin {
            point: b.point as usize,
            origin: a + e * s + left,
            direction: t,
        });
    }
}

/// Step 4 of the module docs: the forces `line_forces` (one per bound point, on the inner rod)
/// reversed and split over the outer segments' points by their parameter, summed per point
/// into `sums` (`points` entries).
fn reaction_on_outer<T: Real>(
    set: &BindingSet<T>,
    line_forces: &[Vec3<f64>],
    points: usize,
    sums: &mut Vec<Vec3<f64>>,
) {
    sums.clear();
    sums.resize(points, Vec3::zeros());
    for (b, force) in set.bound().iter().zip(line_forces) {
        let (j, s) = (b.segment as usize, b.s.to_f64());
        sums[j] -= force * (1.0 - s);
        sums[j + 1] -= force * s;
    }
}

/// Holds the points of `lines` on their lines for a step's solve, from its starting guess: each
/// is put on its line and may move only along it. Points held by their end condition, points
/// of an element whose frame a clamp holds, and points an introducer guide already holds (the
/// pins in `w` so far) are left alone.
pub(super) fn pin_on_lines(w: &mut Work, k: &Consts, lines: &[LinePin]) {
    // The guide's pins, the only ones so far, run from point 1 upward.
    let guided = w.pinned.len();
    // A point of an element whose frame a clamp holds (the element next to a clamped end: its
    // frame is solved outside the lanes, `ConstCols::free` 0, and tied to the clamp by the
    // half-element node, `clamp.rs`) is placed by the clamp through that node and the stiff
    // stretch–shear constraint: a line on it too would be a second, conflicting support, and
    // its force would be that of those stiffnesses, far stiffer than anything the outer rod can
    // answer in one step.
    let n = w.n;
    let clamped = |j: Option<usize>| j.is_some_and(|j| j < n && k.cols.free[j] == 0.0);
    for line in lines {
        let i = line.point;
        if k.inv_mass[i] == 0.0
            || clamped(i.checked_sub(1))
            || clamped(Some(i))
            || w.pinned[..guided]
                .binary_search_by_key(&i, |p| p.point)
                .is_ok()
        {
            continue;
        }
        let x = w.x.get(i);
        let rel = x - line.origin;
        let lateral = rel - line.direction * line.direction.dot(&rel);
        w.x.set(i, &(x - lateral));
        w.pinned.push(Pinned::on_line(i, line.direction));
    }
}

/// After an accepted step of `h`: the force each line of `coupled.lines` exerted on its point,
/// `(M (x − x̃) − J_rᵀ λ) / h²` (the part of the point's momentum balance that the constraints
/// of the rod do not explain), into `coupled.line_forces`; zero for a line that did not hold
/// its point.
pub(super) fn line_forces(w: &Work, k: &Consts, h: f64, coupled: &mut Coupled) {
    let Coupled {
        lines,
        line_forces,
        slot,
        ..
    } = coupled;
    slot.clear();
    slot.resize(w.n + 1, usize::MAX);
    for (s, p) in w.pinned.iter().enumerate() {
        slot[p.point] = s;
    }
    line_forces.clear();
    let inv_h2 = 1.0 / (h * h);
    for l in lines.iter() {
        let i = l.point;
        let held = match slot[i] {
            usize::MAX => false,
            s => w.pinned[s].line && w.pinned[s].normal == l.direction,
        };
        if !held || k.inv_mass[i] == 0.0 {
            line_forces.push(Vec3::zeros());
            continue;
        }
        let g = pin_impulse(w, k, &w.lambda_prev[0], i);
        // Only the part across the line is the line's; along it the balance is zero up to the
        // solve's tolerance.
        let across = g - l.direction * l.direction.dot(&g);
        line_forces.push(across * inv_h2);
    }
}
