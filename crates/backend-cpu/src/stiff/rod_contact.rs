//! Rod–rod and self-contact in the stiff scheme: separating planes held inside each rod's solve,
//! the force between the two sides passed on a step late.
//!
//! The explicit scheme answers a contact between two segments with two-body impulses inside its
//! constraint sweeps (`crate::coupling`). The stiff scheme solves each rod's step as one banded
//! system; a contact between two rods (or two distant parts of one rod) would couple rows far
//! from the band. So, as for bindings (`binding.rs`), the contact is split:
//!
//! 1. **Detection, at the start of the step** (`StiffRodContacts::detect`): the explicit scheme's
//!    broad and narrow phase (`cosserat_collide::RodCollider`: bounding spheres, segment–segment
//!    closest points, neighbours of one rod skipped) on the positions at the start of the step,
//!    each rod's radius inflated by half the margin and by how far its fastest point moves in a
//!    step (at its velocity at the start, or its held end's prescribed one), so that no pair
//!    that can meet within the step is missed.
//! 2. **Half-spaces per pair.** Segments `a` and `b` whose closest centreline points `p_a`,
//!    `p_b` are `d` apart along the unit normal `n` (from `b` to `a`) share the plane through
//!    the middle of their gap, `o = p_b + n (r_b + (d − r_a − r_b)/2)`, moved over the step by
//!    the mean of the two closest points' velocities (a pair moving together keeps its plane).
//!    Side `a` (the lower rod, or the lower segment of one rod) is the pair's **slave**: each of
//!    its two end points must stay at least `r_a` on its side of that plane, and at least
//!    `r_a + r_b` beyond where `b`'s closest point goes at its own velocity (the master's
//!    surface, as the step would leave it without the contact). Side `b`, the **master**, is
//!    not held by the contact, except that its two points may not pass the middle plane by more
//!    than [`BACKSTOP`] of the summed radii. A segment whose two end points are on one side of
//!    a plane lies wholly on that side, so the two segments cannot pass through each other in
//!    the step, however far they move in it: no crossing between steps without a swept test.
//!
//!    **A self-contact with contact rows** (`StiffSettings::contact_rows`, the default) is not
//!    split: both sides are points of the same solve. Each of the slave segment's two end
//!    points gets one row holding its distance from the master's closest point at the
//!    iterate, `n · (x − x_m) ≥ r_a + r_b` with `x_m = (1 − t) x_j + t x_{j+1}`
//!    (`Pinned::partner`); its impulse pushes the slave point along `n` and the master's two
//!    points back along `−n`, split by `t`, in the same Newton iteration (`rows.rs`, the
//!    Schur complement with both sides' columns), and its friction acts on the slip relative
//!    to the master's motion at the iterate, its reaction on the master's two points
//!    (`Work::partner_impulses`). Such a pair has no master planes and passes no load on. The
//!    rows hold the slave's end points off the master's closest point only, not both
//!    segments' end points on the two sides of one plane, so a master segment that turns
//!    through a large angle within a step is not stopped by them. In
//!    the knot of `scenes/fishermans-knot-stiff.toml` every contact up to the breakdown was
//!    a self-contact (the turns of one strand's coil pressed together), held as a slave on a
//!    frozen plane against a master on its backstop (`docs/stiff-solver.md`).
//! 3. **Inside the solve**, the half-spaces are contacts as the mesh's walls are
//!    (`contact.rs`): a point on or behind one of its planes at the solve's starting guess is put
//!    on it and pinned to it (inverse mass `w (I − n nᵀ)` in the updates and the banded matrix,
//!    `Work::pin_blocks`); an iterate that carries a free point behind one of its planes pins it
//!    there; a pinned point pushed behind another of its planes is moved onto that one
//!    ([`RodPlanes`]'s `second_plane` says why not onto their crease); after each round a
//!    point its plane would have to pull is let go. Coulomb friction acts on the slip relative
//!    to the other side's motion as the mesh's does (`pin::PinFriction`: a force of the
//!    solve, held within a small slip, kinetic beyond), with the normal impulse of the last
//!    round. A point friction held at the end of a step starts the next one where the other
//!    side carries it.
//! 4. **Action and reaction, a step late.** The slave's plane is fixed for the step, so the
//!    master does not feel it within the step. After every rod has taken its step, the force
//!    the slave's planes exerted on its points (normal and friction, from the pins' impulses
//!    `M (x − x̃) − Jᵀ λ`) is applied, reversed and split by the closest point's parameter, to
//!    the master's two points as a load in the next steps, relaxed as a two-way binding's
//!    reaction ([`RELAXATION`]). At rest the slave sits on the master's surface and the load is
//!    its force: a rod lying on another is carried by it, two rods pressed together feel the
//!    same force. What the backstop holds is not passed on; at rest the master never reaches
//!    it. Both sides held on the middle plane, each passing on the difference of their forces
//!    (accumulated), was tried first: a cantilever pushed onto another oscillated by ±25 % of
//!    the force (`docs/stiff-solver.md`).
//!
//! The transfer of step 4 is partitioned and first order in `h`, like the bindings'; it is
//! exact at rest (a fixed point of the loads) and stable while the side that is loaded answers
//! more weakly than the relaxation allows (`binding.rs` gives the bound). A point held by the
//! mesh (or a guide, or a binding's line) is left to them; a rod-contact plane never replaces
//! a mesh contact within a step. Only the direct solver takes rod contacts.

use super::contact::{Update, pin_impulse};
use super::lanes::V3s;
use super::pin::{PinFriction, Pinned};
use super::work::Work;
use super::{Consts, StiffScratch};
use crate::coupling::{CouplingStats, RodContactSpec};
use crate::stepper::CpuRod;
use cosserat_collide::{Chain, RodCollider, RodCollisionConfig, RodContact};
use cosserat_constraints::Friction;
use cosserat_model::{Real, Vec3};

/// Penetration of a point behind its plane tolerated without a change of the active set, as a
/// fraction of the rod's radius (and the gap within which a point at the solve's starting guess
/// touches). Two sides each within it of their plane are at least `1 − 2·1e-3` of their summed
/// radii apart; the knot of `scenes/fishermans-knot-stiff.toml` asks for 99 %.
const DEPTH_TOLERANCE: f64 = 1e-3;

/// The fraction by which a rod contact's load moves towards its latest target per step (see the
/// module docs, step 4; the same relaxation as a two-way binding's, `binding::RELAXATION`).
const RELAXATION: f64 = 1.0 / 3.0;

/// How far, as a fraction of the summed radii, the master side of a pair may pass the middle
/// plane of its gap before that plane holds it (module docs, step 2): far enough that a master
/// pressing on a slave at rest never reaches it (the slave is held on the master's surface),
/// near enough that two segments never come closer than 99 % of their summed radii.
const BACKSTOP: f64 = 5e-3;

/// A half-space a point must stay in for one step's solve, `normal · x ≥ offset`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct HalfSpace {
    pub(crate) point: usize,
    /// Unit normal, pointing to the point's side of the plane.
    pub(crate) normal: Vec3<f64>,
    pub(crate) offset: f64,
    /// The offset of the pair's middle plane alone (`offset` without the slave's hold beyond
    /// the master's surface, see [`RodPlanes::set`]).
    mid: f64,
    /// How far the other side's closest point moves in the step (at its velocity at the start):
    /// the slip the friction opposes is the point's motion less this.
    pub(crate) carried: Vec3<f64>,
    /// The pair it comes from (`StiffRodContacts::pairs`), and whether this rod is its slave
    /// side (whose force on the plane the other side is loaded with) rather than its master.
    pub(crate) pair: usize,
    pub(crate) slave: bool,
    /// For a self-contact with contact rows: the other side's segment and closest-point
    /// parameter (`Pinned::partner`); `offset` is then the distance required from that
    /// point, `n · (x − x_m) ≥ offset`, and the row acts on both sides within the solve.
    pub(crate) partner: Option<(usize, f64)>,
}

impl HalfSpace {
    /// How far `x` is behind it, `offset − n · x` (for a self-contact's, `offset − n · (x −
    /// x_m)` with its other side's closest point at the iterate of `w`).
    fn violation(&self, w: &Work, x: &Vec3<f64>) -> f64 {
        let rel = match self.partner {
            Some(q) => x - w.partner_x(q),
            None => *x,
        };
        self.offset - self.normal.dot(&rel)
    }
}

/// One rod's rod-contact planes for a step, and what its pins did (a part of the rod's scratch,
/// `StiffScratch`). Empty for a rod without rod contacts, which then pays nothing.
#[derive(Clone, Debug)]
pub(crate) struct RodPlanes {
    /// The half-spaces of this step, sorted by point.
    pub(crate) planes: Vec<HalfSpace>,
    /// Per point `i`: its half-spaces are `planes[first[i]..first[i + 1]]`.
    first: Vec<usize>,
    /// Per point: its entry in `Work::pinned`, or `usize::MAX` (scratch, rebuilt per use).
    slot: Vec<usize>,
    /// Per point: its normal impulse times the step `p_n` [kg m] at the end of the last step
    /// (0 when it was free), which starts its kinetic friction in the next.
    last_pn: Vec<f64>,
    /// Per point: whether friction held it at the end of the last step.
    last_stick: Vec<bool>,
    /// The step being taken [s] (the friction's holding slip, `PinFriction`).
    h: f64,
    /// After an accepted step: the force [N] each pinned slave point's plane exerted (normal
    /// and friction), as (index into `planes`, force).
    pub(crate) forces: Vec<(usize, Vec3<f64>)>,
    /// Coulomb friction of rod contacts.
    friction: Friction<f64>,
    radius: f64,
}

impl Default for RodPlanes {
    fn default() -> Self {
        Self {
            planes: Vec::new(),
            first: Vec::new(),
            slot: Vec::new(),
            last_pn: Vec::new(),
            last_stick: Vec::new(),
            h: 0.0,
            forces: Vec::new(),
            friction: Friction {
                static_coefficient: 0.0,
                kinetic_coefficient: 0.0,
            },
            radius: 0.0,
        }
    }
}

impl RodPlanes {
    /// Takes the step's half-spaces (any order; `planes` is left with the last step's) for a rod
    /// of `points` points and `radius`.
    pub(crate) fn set(
        &mut self,
        planes: &mut Vec<HalfSpace>,
        points: usize,
        radius: f64,
        friction: Friction<f64>,
    ) {
        std::mem::swap(&mut self.planes, planes);
        let planes = &mut self.planes;
        planes.sort_by_key(|p| p.point);
        self.first.clear();
        self.first.resize(points + 1, 0);
        for p in planes.iter() {
            self.first[p.point + 1] += 1;
        }
        for i in 0..points {
            self.first[i + 1] += self.first[i];
        }
        // A point between two sides that face each other (a strand squeezed between two
        // others) must be able to satisfy both: at the start of the step it is within both
        // middle planes, but held beyond two masters' surfaces as they move in it may have
        // nowhere to go, and put back on one plane it leaves the other, at every iteration.
        // Such a point is held by the middle planes only.
        for i in 0..points {
            let run = &mut planes[self.first[i]..self.first[i + 1]];
            for a in 0..run.len() {
                for b in a + 1..run.len() {
                    if run[a].normal.dot(&run[b].normal) < -0.5 {
                        run[a].offset = run[a].mid;
                        run[b].offset = run[b].mid;
                    }
                }
            }
        }
        self.radius = radius;
        self.friction = friction;
        self.forces.clear();
        if self.last_pn.len() != points {
            self.last_pn = vec![0.0; points];
            self.last_stick = vec![false; points];
        }
    }

    /// Whether this step has any plane.
    pub(crate) fn is_active(&self) -> bool {
        !self.planes.is_empty()
    }

    fn tolerance(&self) -> f64 {
        DEPTH_TOLERANCE * self.radius
    }

    /// The farthest one iteration of the solve may move a point (see `Work::apply`): the rod's
    /// radius, as with the mesh's contacts.
    pub(crate) fn max_iteration_move(&self) -> f64 {
        self.radius
    }

    fn of(&self, i: usize) -> &[HalfSpace] {
        match (self.first.get(i), self.first.get(i + 1)) {
            (Some(&a), Some(&b)) => &self.planes[a..b],
            _ => &[],
        }
    }

    /// The half-space of point `i` with the largest violation `offset − n · x` at `x` (for a
    /// self-contact's, `offset − n · (x − x_m)` with the other side at the iterate of `w`).
    fn deepest(&self, i: usize, w: &Work, x: &Vec3<f64>) -> Option<(usize, f64)> {
        let base = self.first.get(i).copied()?;
        self.of(i)
            .iter()
            .enumerate()
            .map(|(k, h)| (base + k, h.violation(w, x)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    fn reindex(&mut self, w: &Work) {
        self.slot.clear();
        self.slot.resize(w.n + 1, usize::MAX);
        for (s, p) in w.pinned.iter().enumerate() {
            self.slot[p.point] = s;
        }
    }

    /// Pins point `i` on plane `h` (violated by `depth`), from where it is, with the friction of
    /// rod contacts against its slip relative to the other side and the normal impulse of its
    /// last step. At the start of a step (`first`) a point that friction held at the end of the
    /// last one starts where the other side carries it.
    fn pin(&mut self, w: &mut Work, i: usize, h: usize, depth: f64, first: bool) {
        let hs = self.planes[h];
        let start = w.x_old.get(i) + hs.carried;
        let x = if first && self.last_stick[i] {
            start + hs.normal * hs.violation(w, &start).max(0.0)
        } else {
            w.x.get(i) + hs.normal * depth
        };
        w.x.set(i, &x);
        let Friction {
            static_coefficient: mu_s,
            kinetic_coefficient: mu_k,
        } = self.friction;
        let mut friction = PinFriction::new(start, mu_s, mu_k, self.h);
        if self.last_pn[i] > 0.0
            && !self.last_stick[i]
            && let Some(f) = friction
        {
            let predicted = w.x_pred.get(i) - start;
            friction = Some(f.continuing(&(predicted - hs.normal * hs.normal.dot(&predicted))));
        }
        self.slot[i] = w.pinned.len();
        let mut p = Pinned::on_wall(i, hs.normal, true, self.last_pn[i], friction);
        p.partner = hs.partner;
        w.pinned.push(p);
    }

    /// Step 3 of the module docs, before the solve of a step of `h`: pins the points on or
    /// behind one of their planes at the solve's starting guess (points another pin already
    /// holds are left to it).
    pub(crate) fn begin_step(&mut self, w: &mut Work, k: &Consts, h: f64) {
        self.h = h;
        self.reindex(w);
        let tol = self.tolerance();
        for i in 0..=w.n {
            if k.inv_mass[i] == 0.0 || self.slot[i] != usize::MAX {
                continue;
            }
            let Some((plane, depth)) = self.deepest(i, w, &w.x.get(i)) else {
                continue;
            };
            if depth < -tol {
                continue;
            }
            self.pin(w, i, plane, depth, true);
            self.second_plane(w, i);
        }
    }

    /// Puts pinned point `i`, if it is behind another of its planes by more than the tolerance,
    /// on the plane it is deepest behind instead (moved out along that plane's normal, which
    /// takes it off a plane facing it). Returns (changed, matrix changed). Unlike the mesh's
    /// walls, two planes do not make a crease the point slides along: a strand wrapped around
    /// another has a plane per neighbouring pair, a few degrees apart, and each point of a
    /// chain held on a line fixes the chain's length between them; with creases the knot of
    /// `scenes/fishermans-knot-stiff.toml` stalled at strains of 1e-2 where it did not blow up
    /// (`docs/stiff-solver.md`). With one plane per point it still breaks down there.
    fn second_plane(&mut self, w: &mut Work, i: usize) -> (bool, bool) {
        let s = self.slot[i];
        let x = w.x.get(i);
        let Some((h, depth)) = self.deepest(i, w, &x) else {
            return (false, false);
        };
        if depth <= self.tolerance() {
            return (false, false);
        }
        let (normal, carried) = (self.planes[h].normal, self.planes[h].carried);
        let start = w.x_old.get(i) + carried;
        let p = &mut w.pinned[s];
        p.normal = normal;
        p.crease = None;
        p.partner = self.planes[h].partner;
        if let Some(f) = p.friction.as_mut() {
            f.start = start;
        }
        w.x.set(i, &(x + normal * depth));
        (true, true)
    }

    /// After an iteration of the solve: pins the free points it carried behind one of their
    /// planes, and puts pinned points back on planes they slid behind.
    pub(crate) fn catch_penetrations(&mut self, w: &mut Work, k: &Consts) -> Update {
        self.reindex(w);
        let tol = self.tolerance();
        let (mut changed, mut matrix_changed) = (false, false);
        for i in 0..=w.n {
            if k.inv_mass[i] == 0.0 || self.first[i] == self.first[i + 1] {
                continue;
            }
            let s = self.slot[i];
            if s == usize::MAX {
                let Some((h, depth)) = self.deepest(i, w, &w.x.get(i)) else {
                    continue;
                };
                if depth > tol {
                    self.pin(w, i, h, depth, false);
                    self.second_plane(w, i);
                    changed = true;
                    matrix_changed = true;
                }
            } else if w.pinned[s].rod {
                let (c, m) = self.second_plane(w, i);
                changed |= c;
                matrix_changed |= m;
            }
        }
        Update {
            resolve: changed,
            matrix_changed,
        }
    }

    /// After a round of the solve: lets go of points their planes would have to pull, gives the
    /// others this solve's normal impulse for their friction (step 3 of the module docs).
    pub(crate) fn update(&mut self, w: &mut Work, k: &Consts) -> Update {
        let (mut changed, mut released, mut matrix_changed) = (false, false, false);
        for s in 0..w.pinned.len() {
            let mut p = w.pinned[s];
            if !p.rod {
                continue;
            }
            // A rod-contact pin is on one plane (no crease, see `second_plane`).
            let pn = w
                .row_impulse(&p)
                .unwrap_or_else(|| p.normal.dot(&pin_impulse(w, k, &w.lambda[0], p.point)));
            if !(pn > 0.0) {
                // As the mesh's: a contact row left free by the solve goes quietly.
                released |= !w.quietly_free(&p);
                p.point = usize::MAX;
                w.pinned[s] = p;
                continue;
            }
            // As the mesh's points (`contact.rs`): solved again for a new normal impulse.
            let (resolve, rebuild) =
                p.take_normal_impulse(pn, &w.x.get(p.point), k.inv_mass[p.point]);
            changed |= resolve;
            matrix_changed |= rebuild;
            w.pinned[s] = p;
        }
        if w.pinned.iter().any(|p| p.point == usize::MAX) {
            w.pinned.retain(|p| p.point != usize::MAX);
            changed |= released;
        }
        let caught = self.catch_penetrations(w, k);
        Update {
            resolve: changed || caught.resolve,
            matrix_changed: released || matrix_changed || caught.matrix_changed,
        }
    }

    /// After an accepted step of `h` with multipliers `lambda`: the force each pinned point's
    /// plane exerted, into `forces` for slave planes, and its normal impulse and whether it
    /// stuck, for the next step.
    pub(crate) fn record_forces(&mut self, w: &Work, k: &Consts, lambda: &V3s, h: f64) {
        self.forces.clear();
        self.last_pn.iter_mut().for_each(|p| *p = 0.0);
        self.last_stick.iter_mut().for_each(|s| *s = false);
        let inv_h2 = 1.0 / (h * h);
        for p in w.pinned.iter().filter(|p| p.rod) {
            let i = p.point;
            let g = pin_impulse(w, k, lambda, i);
            self.last_pn[i] = p.normal.dot(&g).max(0.0);
            self.last_stick[i] = p
                .friction
                .zip(p.slip(&w.x.get(i)))
                .is_some_and(|(f, slip)| f.holds(&slip));
            let base = self.first[i];
            if let Some(h) = self.of(i).iter().position(|hs| hs.normal == p.normal)
                && self.planes[base + h].slave
            {
                self.forces.push((base + h, g * inv_h2));
            }
        }
    }
}

/// The rod–rod and self-contacts of the rods of a simulation stepped with the stiff scheme
/// (steps 1, 2 and 4 of the module docs; step 3 is each rod's [`RodPlanes`]).
#[derive(Clone, Debug)]
pub(crate) struct StiffRodContacts {
    collider: RodCollider,
    friction: Friction<f64>,
    margin: f64,
    /// Rod pairs that do not collide (bound to each other).
    excluded: Vec<(usize, usize)>,
    radii: Vec<f64>,
    points: Vec<Vec<[f64; 3]>>,
    velocities: Vec<Vec<[f64; 3]>>,
    found: Vec<RodContact>,
    /// Per rod: its half-spaces of the step being gathered (scratch).
    per_rod: Vec<Vec<HalfSpace>>,
    /// The pairs of the step.
    pairs: Vec<RodContact>,
    /// Per pair: the force [N] its plane exerted on its slave side in the step.
    sides: Vec<Vec3<f64>>,
    /// Per rod and point: the relaxed load [N] the contacts put on it, and this step's target.
    loads: Vec<Vec<Vec3<f64>>>,
    targets: Vec<Vec<Vec3<f64>>>,
    pub(crate) stats: CouplingStats,
}

/// `a + (b − a) s` for points given as arrays.
fn lerp(a: &[f64; 3], b: &[f64; 3], s: f64) -> Vec3<f64> {
    let (a, b) = (Vec3::from(*a), Vec3::from(*b));
    a + (b - a) * s
}

impl StiffRodContacts {
    /// The contacts of `spec` among `rods`; pairs of rods in `excluded` (bound to each other) do
    /// not touch.
    pub(crate) fn new<T: Real>(
        rods: &[CpuRod<T>],
        spec: &RodContactSpec,
        excluded: Vec<(usize, usize)>,
    ) -> Self {
        Self {
            collider: RodCollider::new(RodCollisionConfig {
                segments_per_sphere: spec.segments_per_sphere,
                self_collisions: spec.self_collisions,
                ..RodCollisionConfig::default()
            }),
            friction: spec.friction,
            margin: spec.margin,
            excluded,
            radii: rods.iter().map(|r| r.params.radius.to_f64()).collect(),
            points: vec![Vec::new(); rods.len()],
            velocities: vec![Vec::new(); rods.len()],
            found: Vec::new(),
            per_rod: vec![Vec::new(); rods.len()],
            pairs: Vec::new(),
            sides: Vec::new(),
            loads: rods
                .iter()
                .map(|r| vec![Vec3::zeros(); r.elements() + 1])
                .collect(),
            targets: rods
                .iter()
                .map(|r| vec![Vec3::zeros(); r.elements() + 1])
                .collect(),
            stats: CouplingStats::default(),
        }
    }

    /// Steps 1 and 2 of the module docs at the start of a step of `h` at time `t`: finds the
    /// pairs on the rods' positions and sets every rod's planes (`scratches[r].planes`).
    pub(crate) fn detect<T: Real>(
        &mut self,
        rods: &[CpuRod<T>],
        scratches: &mut [StiffScratch],
        t: f64,
        h: f64,
        coupled: bool,
    ) {
        let t0 = std::time::Instant::now();
        let f = |v: &Vec3<T>| [v.x.to_f64(), v.y.to_f64(), v.z.to_f64()];
        self.velocities.resize(rods.len(), Vec::new());
        let mut reach = Vec::with_capacity(rods.len());
        for ((r, x), v) in rods.iter().zip(&mut self.points).zip(&mut self.velocities) {
            x.clear();
            x.extend(r.state.positions.iter().map(f));
            v.clear();
            v.extend(r.state.velocities.iter().map(f));
            // How far the rod's fastest point moves in the step: pairs that far apart can meet.
            let driven = r.ends.iter().filter(|e| e.holds_point()).map(|e| {
                let v = e.velocities_over(t, h).0;
                Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64()).norm()
            });
            let fastest = v
                .iter()
                .map(|v| Vec3::from(*v).norm())
                .chain(driven)
                .fold(0.0, f64::max);
            reach.push(0.5 * self.margin + fastest * h);
        }
        let chains: Vec<Chain<'_>> = self
            .points
            .iter()
            .zip(&self.radii)
            .zip(&reach)
            .map(|((p, &r), &e)| Chain {
                points: p,
                radius: r + e,
            })
            .collect();
        self.collider.detect(&chains, &mut self.found);
        self.pairs.clear();
        for buf in &mut self.per_rod {
            buf.clear();
        }
        self.per_rod.resize(rods.len(), Vec::new());
        let mut touching = 0;
        for c in &self.found {
            let (a, b) = (c.chain_a as usize, c.chain_b as usize);
            if a != b && self.excluded.contains(&(a.min(b), a.max(b))) {
                continue;
            }
            let (ra, rb) = (self.radii[a], self.radii[b]);
            let radii = ra + rb;
            if c.distance < radii + self.margin {
                touching += 1;
            }
            let s = &mut self.stats;
            if c.distance < s.min_separation {
                s.min_separation = c.distance;
                s.min_separation_radii = radii;
            }
            s.min_separation_ratio = s.min_separation_ratio.min(c.distance / radii);
            let (i, j) = (c.segment_a as usize, c.segment_b as usize);
            let n = Vec3::from(c.normal);
            let xb = &self.points[b];
            let (va, vb) = (&self.velocities[a], &self.velocities[b]);
            let pb = lerp(&xb[j], &xb[j + 1], c.t);
            let (ua, ub) = (
                lerp(&va[i], &va[i + 1], c.s) * h,
                lerp(&vb[j], &vb[j + 1], c.t) * h,
            );
            let gap = c.distance - radii;
            // The plane through the middle of the gap, moved with the pair.
            let o = pb + n * (rb + 0.5 * gap) + (ua + ub) * 0.5;
            // Where the master's surface goes without the contact: the slave is held beyond it.
            let ahead = n.dot(&(pb + ub)) + rb + ra;
            let pair = self.pairs.len();
            self.pairs.push(*c);
            if coupled && a == b {
                // Both sides in one solve: one row per slave point holds its distance from the
                // master's closest point, and acts on both.
                for p in [i, i + 1] {
                    self.per_rod[a].push(HalfSpace {
                        point: p,
                        normal: n,
                        offset: radii,
                        mid: radii,
                        carried: ub,
                        pair,
                        slave: false,
                        partner: Some((j, c.t)),
                    });
                }
                continue;
            }
            for p in [i, i + 1] {
                self.per_rod[a].push(HalfSpace {
                    point: p,
                    normal: n,
                    offset: (n.dot(&o) + ra).max(ahead),
                    mid: n.dot(&o) + ra,
                    carried: ub,
                    pair,
                    slave: true,
                    partner: None,
                });
            }
            for p in [j, j + 1] {
                self.per_rod[b].push(HalfSpace {
                    point: p,
                    normal: -n,
                    offset: -n.dot(&o) + rb - BACKSTOP * radii,
                    mid: -n.dot(&o) + rb - BACKSTOP * radii,
                    carried: ua,
                    pair,
                    slave: false,
                    partner: None,
                });
            }
        }
        for (r, (rod, sc)) in rods.iter().zip(scratches.iter_mut()).enumerate() {
            sc.planes.set(
                &mut self.per_rod[r],
                rod.elements() + 1,
                self.radii[r],
                self.friction,
            );
        }
        self.sides.clear();
        self.sides.resize(self.pairs.len(), Vec3::zeros());
        let s = &mut self.stats;
        s.contacts = touching;
        s.max_contacts = s.max_contacts.max(touching);
        s.steps += 1;
        s.detection_seconds += t0.elapsed().as_secs_f64();
    }

    /// Appends rod `r`'s contact loads (the relaxed transfer of step 4) to `loads`.
    pub(crate) fn add_loads(&self, r: usize, loads: &mut Vec<(usize, Vec3<f64>)>) {
        loads.extend(
            self.loads[r]
                .iter()
                .enumerate()
                .filter(|(_, f)| **f != Vec3::zeros())
                .map(|(i, f)| (i, *f)),
        );
    }

    /// After rod `r`'s step: adds the forces its slave planes exerted to their pairs.
    pub(crate) fn collect(&mut self, planes: &RodPlanes) {
        for &(h, force) in &planes.forces {
            self.sides[planes.planes[h].pair] += force;
        }
    }

    /// Step 4 of the module docs after every rod's step: each pair's force on its slave side,
    /// reversed, becomes the target load of its master side's two points (split by the closest
    /// point's parameter); every load moves towards its target by [`RELAXATION`].
    pub(crate) fn relax(&mut self) {
        for t in &mut self.targets {
            t.iter_mut().for_each(|f| *f = Vec3::zeros());
        }
        for (c, force) in self.pairs.iter().zip(&self.sides) {
            let (rod, j) = (c.chain_b as usize, c.segment_b as usize);
            self.targets[rod][j] -= force * (1.0 - c.t);
            self.targets[rod][j + 1] -= force * c.t;
        }
        for (loads, targets) in self.loads.iter_mut().zip(&self.targets) {
            for (l, t) in loads.iter_mut().zip(targets) {
                *l += (t - *l) * RELAXATION;
                // A load that has decayed to nothing is dropped from the rods' load lists.
                if l.norm_squared() < 1e-40 {
                    *l = Vec3::zeros();
                }
            }
        }
    }
}
