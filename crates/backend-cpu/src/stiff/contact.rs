//! Contact of a rod with a static mesh in the stiff scheme, resolved inside the step's solve.
//!
//! The explicit scheme answers contacts with impulses after its elastic update
//! (`crate::mesh_contact`); that works because its steps are microseconds long and a point
//! moves a fraction of its radius per step. At a haptic step (1 ms) the elastic solve of a
//! stiff wire moves its points by millimetres: a wire pressed against a wall would be pushed
//! through it by the solve and pulled back by a projection afterwards, every step. So here the
//! wall is part of the implicit step: a point in contact is **pinned** to the wall's tangent
//! plane for the solve (its inverse mass loses the normal direction, `Work::pin_blocks` and
//! `Work::rhs`, `Work::apply`), which keeps the system banded and costs nothing where no point
//! touches.
//!
//! Which points are pinned is an active set found per step; **friction is not part of it**. A
//! pinned point carries Coulomb friction as a force of the step's own equations
//! ([`PinFriction`]): against its slip over the step (relative to its obstacle's surface), a
//! stiff tangential spring `μ_s p_n / δ` up to a slip `δ` of [`STICK_SPEED`](super::pin::STICK_SPEED)
//! times the step (static friction: the point holds, creeping at most that fast), kinetic
//! friction `μ_k p_n` beyond, evaluated at every iterate of the solve, a frozen
//! linearisation of it in the Newton matrix. Earlier versions switched each point between sticking (pinned still) and
//! sliding (kinetic friction as a shift of its inertial target) between rounds of the solve;
//! a stiff wire pressed on the vessel at 1 ms then had no stable active set (a point's own
//! share of the impulse that held it said nothing of its neighbours' push), its steps ended
//! unconverged with residuals of 1e1–1e4 and strains of 20–50 % (`docs/stiff-solver.md`).
//! 1. before the solve, the points at the solve's starting guess (`x + h v`) are tested as
//!    spheres against the mesh; those touching or penetrating are put on the wall and pinned,
//!    except points that were free at the end of the last step, are moving off the wall and
//!    are within the tolerance of it (left to step 2, which pins them if the solve pushes them
//!    in: pinned first, most of them were let go after the first solve). A point friction held
//!    at the end of the last step starts at its start-of-step place, projected onto the wall;
//!    each starts with the normal impulse of its last step (none for a new contact). A point
//!    touching two walls at an angle (a groove, the crease of two facets) is put on both and
//!    pinned to their crease, each wall with its own normal force: pinned to one plane under
//!    the mean normal, a rod in a right-angled groove felt `μ m g cos α` of friction instead of
//!    the wedge's `√2 μ m g cos α` and slid where it should stick;
//! 2. after every iteration of the solve, points the iterate pushed into the mesh are put back
//!    on the wall and pinned, so that no iterate travels far into a wall before the rest of
//!    the rod learns of it (a wire snapping sideways moves millimetres in one step). A pinned
//!    point that slid into a second wall turned towards the lumen (every edge of a faceted
//!    vessel, seen from inside) is put on both and slides along their crease
//!    ([`back_on_walls`]): put back on the second wall alone, it slid into the first again at
//!    the next iteration, a new factorisation each time (the phantom's steel wire took 41
//!    iterations and 36 factorisations a step, most steps unconverged). One that slid off a wall
//!    turned away stays on its plane, in the lumen;
//! 3. after the solve, each pinned point's wall impulse `g = M (x − x̃) − Jᵀ λ` (normal and
//!    friction) is read: a point the wall would have to pull (`n·g ≤ 0`) is released; the
//!    others take their new normal impulse `p_n = n·g` for their friction. A contact row
//!    (`rows.rs`) gives its multiplier instead, which `n·g` equals to rounding but for the sign
//!    of that rounding where the solve left the row free (`Work::row_impulse`);
//! 4. if a point was released or caught, or a normal impulse changed by more than
//!    [`NORMAL_CHANGE`](super::pin::NORMAL_CHANGE), the solve continues from its current multipliers, for at most
//!    [`MAX_ROUNDS`] rounds, with a new factorisation if the pinned points or their directions
//!    changed; positions a last change moves onto the wall are not solved again (the next
//!    step does). Each round after the first is solved first to [`LOOSE_ROUND`] times the
//!    step's tolerance; steps 3 and 4 run then, and only a round whose contacts hold still is
//!    finished at the tolerance itself, so the iterations that would converge a round the
//!    contacts are about to change are not spent.

use super::Consts;
use super::lanes::V3s;
use super::pin::{PinFriction, Pinned, STICK_SPEED};
use super::work::Work;
use crate::guide::Guide;
use crate::mesh_contact::{
    CollisionStats, MeshContactSettings, Motion, RodMeshContact, ShapeObstacle,
};
use cosserat_constraints::{Friction, PointContact};
use cosserat_model::Vec3;
use std::sync::Arc;

/// Largest number of re-solves per step after the active set changed.
pub(crate) const MAX_ROUNDS: usize = 4;

/// The residual, as a multiple of the step's tolerance, to which a round of the solve after
/// the first is taken before its contacts are updated. Once the contacts have changed in a
/// step they tend to change again (contacts peeling off a bend one layer a round), and each
/// round starts where the last one stopped, so converging a round further first would spend
/// iterations on an active set about to change. The first round is solved to the tolerance:
/// most steps end there, and a step that ends at the tolerance rather than well below it
/// leaves the next one further to go (measured in `docs/stiff-solver.md`, "Rounds after the
/// first solved loosely").
pub(crate) const LOOSE_ROUND: f64 = 30.0;

/// Penetration tolerated without a change of the active set, as a fraction of the rod's radius
/// (and the gap within which a point at the solve's starting guess touches). At 1e-3 the
/// phantom's wires were put back on facets after most iterations, each time a new
/// factorisation; at 2e-2 (9 µm for the `steel` preset) the torture suite's stiff steps cost
/// 20–35 % less in the phantom (`docs/benchmarks/torture.md`, `docs/stiff-solver.md`).
const DEPTH_TOLERANCE: f64 = 2e-2;

/// The farthest one iteration of the solve may move a point, as a fraction of the rod's radius.
const ITERATION_MOVE: f64 = 1.0;

/// How far a touching point may move between two detections of one step before it is queried
/// again, as a fraction of the penetration tolerance (see `StiffContacts::detect`).
const REUSE_DISTANCE: f64 = 0.5;

/// The largest turn [rad] of a pinned point's wall normal that keeps the step's factorisation:
/// a chord iteration with the old normal's projection still converges, and one that does not
/// refactorises (`direct_solve`).
const NORMAL_TURN: f64 = 0.1;

/// Two walls meet in a crease a point slides along when the cosine of the angle between their
/// normals is at most this in magnitude: nearer to parallel (or to facing each other), the
/// crease is far from the point (a point moved onto both walls moves `|gap| / sin θ`).
const CREASE_COS: f64 = 0.95;

/// What [`StiffContacts::update`] changed.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Update {
    /// Something the solve must take into account: solve again.
    pub(crate) resolve: bool,
    /// The matrix of the solve (which points are pinned, how, or along which normal), rather
    /// than only the inertial targets: factorise again.
    pub(crate) matrix_changed: bool,
}

/// How a point touched the mesh at the end of the last step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
enum Touch {
    #[default]
    Free,
    /// Held by friction (it slipped less than `PinFriction::stick_slip`), with its normal
    /// impulse times the step `p_n` [kg m].
    Stick(f64),
    /// Sliding, with its normal impulse times the step.
    Slide(f64),
}

/// The mesh contact state of one rod in the stiff scheme.
#[derive(Clone, Debug)]
pub(crate) struct StiffContacts {
    mesh: RodMeshContact<f64>,
    radius: f64,
    /// The step being taken [s] (a moving wall's shift over it, [`Self::wall_shift`]).
    h: f64,
    /// Per point: how it touched at the end of the last step.
    last: Vec<Touch>,
    /// Per point: its entry in `Work::pinned`, or `usize::MAX`.
    slot: Vec<usize>,
    /// Per point: whether the last detection found it (scratch of `update`).
    found: Vec<bool>,
    /// Per point: its normal and gap at its last query if it touched (see `detect`), where it
    /// was then, and whether the current detection leaves it out (scratch).
    cached: Vec<Option<(Vec3<f64>, f64)>>,
    queried_at: Vec<Vec3<f64>>,
    skip: Vec<bool>,
    /// The wall's force on each point it held in the last accepted step: point, unit normal
    /// into the lumen, force [N] (normal and friction).
    forces: Vec<(usize, Vec3<f64>, Vec3<f64>)>,
    pub(crate) stats: CollisionStats,
    /// `last` and `stats` where the current batch of steps began ([`Self::checkpoint`]).
    last_at_start: Vec<Touch>,
    stats_at_start: CollisionStats,
}

impl StiffContacts {
    pub(crate) fn new(settings: MeshContactSettings, radius: f64) -> Self {
        Self {
            mesh: RodMeshContact::new(settings),
            radius,
            h: 0.0,
            last: Vec::new(),
            slot: Vec::new(),
            found: Vec::new(),
            cached: Vec::new(),
            queried_at: Vec::new(),
            skip: Vec::new(),
            forces: Vec::new(),
            stats: CollisionStats::default(),
            last_at_start: Vec::new(),
            stats_at_start: CollisionStats::default(),
        }
    }

    /// Records the wall's force on every point it held in the step just accepted: the pin's
    /// impulse `M (x − x̃) − Jᵀ λ` ([`pin_impulse`], with the step's multipliers `lambda`) over
    /// the implicit step `h`, squared (XPBD's impulses are forces times the step squared).
    pub(crate) fn record_forces(&mut self, w: &Work, k: &Consts, lambda: &V3s, h: f64) {
        self.forces.clear();
        for p in &w.pinned {
            if !p.on_mesh() || p.point == usize::MAX {
                continue;
            }
            let g = pin_impulse(w, k, lambda, p.point);
            self.forces.push((p.point, p.normal, g / (h * h)));
        }
    }

    /// The forces [`Self::record_forces`] recorded.
    pub(crate) fn forces(&self) -> &[(usize, Vec3<f64>, Vec3<f64>)] {
        &self.forces
    }

    /// Keeps what a batch of steps changes in the contact state that outlives a step: how each
    /// point touched at the end of the last step, and the statistics. A batch that diverges and
    /// is retaken from its start ([`Self::restore`]) must not leave its discarded steps in
    /// them: a failed try's penetration is no state the run was ever in, and its touches would
    /// start the retaken step. Kept in buffers of its own: no allocation per batch.
    pub(crate) fn checkpoint(&mut self) {
        self.last_at_start.clone_from(&self.last);
        self.stats_at_start = self.stats;
    }

    /// Puts back what [`Self::checkpoint`] kept.
    pub(crate) fn restore(&mut self) {
        self.last.clone_from(&self.last_at_start);
        self.stats = self.stats_at_start;
    }

    /// Forgets the contacts of earlier steps and the statistics (see `StiffScratch::prepare`).
    pub(crate) fn reset(&mut self) {
        self.last.iter_mut().for_each(|t| *t = Touch::Free);
        self.stats = CollisionStats::default();
        self.mesh.stats = CollisionStats::default();
    }

    /// The farthest one iteration of the solve may move a point (see `Work::apply`).
    pub(crate) fn max_iteration_move(&self) -> f64 {
        ITERATION_MOVE * self.radius
    }

    fn tolerance(&self) -> f64 {
        DEPTH_TOLERANCE * self.radius
    }

    /// How far the wall point `i` touches moves over the step, at the point's start: zero but
    /// on a moving obstacle, where friction acts on the motion relative to it.
    fn wall_shift(&self, i: usize, w: &Work) -> Vec3<f64> {
        self.mesh.wall_shift(i, &w.x_old.get(i), self.h)
    }

    /// Rebuilds `slot` from `w.pinned`.
    fn reindex(&mut self, w: &Work) {
        self.slot.clear();
        self.slot.resize(w.n + 1, usize::MAX);
        for (s, p) in w.pinned.iter().enumerate() {
            self.slot[p.point] = s;
        }
    }

    /// Detects at the current positions of `w`. With `reuse`, a point found touching at its
    /// last query that has moved less than [`REUSE_DISTANCE`] (as a fraction of the tolerance)
    /// since, and whose last gap is far enough from every threshold of
    /// [`catch_penetrations`](Self::catch_penetrations) that no move that short can change what
    /// that function does with it, is not queried: it keeps its last normal, and its last gap
    /// less the distance it moved. The gap is a distance to the mesh, which changes no faster
    /// than the point moves, so the gap passed on is a lower bound (the penetration statistics
    /// an upper bound) and on the same side of every threshold as the exact one. Between the
    /// iterations of a solve the points move little, so most contacts are not queried again,
    /// and the decisions are those of a full query. Points next to an element that may touch a
    /// ridge are always queried: an element's contact depends on its points' exact gaps
    /// ([`RodMeshContact::no_ridge_near`]).
    fn detect(&mut self, w: &Work, k: &Consts, reuse: bool) {
        let m = w.n + 1;
        if self.cached.len() != m {
            self.cached = vec![None; m];
            self.queried_at = vec![Vec3::zeros(); m];
            self.skip = vec![false; m];
        }
        let tol = self.tolerance();
        let reach = REUSE_DISTANCE * tol;
        let margin = self.mesh.settings.margin;
        let no_ridge = |j: usize| {
            self.mesh
                .no_ridge_near(j, w.x.get(j), w.x.get(j + 1), self.radius)
        };
        for i in 0..m {
            self.skip[i] = reuse
                && self.cached[i].is_some_and(|(_, gap)| {
                    let held = k.inv_mass[i] == 0.0;
                    let stays = match self.slot[i] {
                        s if s != usize::MAX && !w.pinned[s].on_mesh() => true,
                        _ => gap - reach >= -tol,
                    };
                    gap + reach < margin
                        && gap - reach > -self.radius
                        && (held || stays)
                        && (w.x.get(i) - self.queried_at[i]).norm() < reach
                })
                && (i == 0 || no_ridge(i - 1))
                && (i == w.n || no_ridge(i));
        }
        // Swept from where the step began (in the lumen): a point the solve moved across a
        // wall, beyond its sphere's reach, is caught where it crossed.
        self.mesh.detect_except(
            &w.x.x[..m],
            &w.x.y[..m],
            &w.x.z[..m],
            self.radius,
            &self.skip,
            Motion::From([&w.x_old.x[..m], &w.x_old.y[..m], &w.x_old.z[..m]]),
        );
        for i in (0..m).filter(|&i| !self.skip[i]) {
            self.cached[i] = None;
            self.queried_at[i] = w.x.get(i);
        }
        for c in self.mesh.contacts.contacts() {
            self.cached[c.point as usize] = Some((c.normal, c.gap));
        }
        for i in (0..m).filter(|&i| self.skip[i]) {
            if let Some((normal, gap)) = self.cached[i] {
                self.stats.reused_queries += 1;
                // Deeper by the distance moved at most: the gap passed on bounds the
                // penetration from above (the statistics), and keeps it within the thresholds
                // checked above (the decisions).
                let moved = (w.x.get(i) - self.queried_at[i]).norm();
                self.mesh.contacts.push(PointContact {
                    point: i as u32,
                    normal,
                    gap: gap - moved,
                });
            }
        }
        // Elements nearer a wall than their points, once every point has its contact.
        self.mesh
            .segment_contacts(&w.x.x[..m], &w.x.y[..m], &w.x.z[..m], self.radius);
    }

    /// Step 1 of the module docs, after the prediction: pins the points touching the mesh at
    /// the solve's starting guess.
    ///
    /// Moving obstacles (the rod's `shapes`, which a control call may have set moving) are put
    /// where they are at the step's end, `t + h`.
    pub(crate) fn begin_step(
        &mut self,
        w: &mut Work,
        k: &Consts,
        (t, h): (f64, f64),
        shapes: Option<&Arc<[ShapeObstacle]>>,
    ) {
        if let Some(shapes) = shapes {
            self.mesh.follow_shapes(shapes);
        }
        self.mesh.pose_shapes(t + h, t, h);
        self.h = h;
        let m = w.n + 1;
        if self.last.len() != m {
            self.last = vec![Touch::Free; m];
        }
        self.reindex(w);
        self.detect(w, k, false);
        let tol = self.tolerance();
        let found = std::mem::take(&mut self.mesh.contacts);
        for c in found.contacts() {
            let (i, normal, gap) = (c.point as usize, c.normal, c.gap);
            if k.inv_mass[i] == 0.0 || gap > tol || self.slot[i] != usize::MAX {
                continue;
            }
            // A point that was free at the end of the last step and is within the tolerance of
            // the wall stays free if it moves off the wall or slides along it; the iterations
            // pin it if they push it further in. Pinned here whenever it touched and was not
            // moving off the wall, a stiff wire sliding along a bend of the vessel had a run of
            // neighbouring points pinned on the curved wall, with wall impulses of alternating
            // sign (a beam over too many supports): the steel wire of the insertion at 1 ms
            // took 9.9 iterations a step and ended 82 of 2450 steps above the tolerance, 3.7
            // and 29 with them left free. One at rest on the wall, or moving into it without
            // sliding, is pinned here: left free within the tolerance it would sink through it
            // with no friction to hold it.
            let v = w.x_pred.get(i) - w.x_old.get(i) - self.wall_shift(i, w);
            let towards = normal.dot(&v);
            let along = w.v_start.get(i) * self.h - self.wall_shift(i, w);
            let slides = (along - normal * normal.dot(&along)).norm() > STICK_SPEED * self.h;
            if self.last[i] == Touch::Free && gap >= -tol && (towards > 0.0 || slides) {
                continue;
            }
            // Touching two walls that meet at an angle (a groove, the crease of two facets):
            // on both, sliding along their crease, each wall's normal force its own.
            let crease = self.two_walls(i, tol);
            self.pin_touching(w, k, i, (normal, gap), crease);
        }
        self.mesh.contacts = found;
    }

    /// Pins point `i`, touching the wall of `(normal, gap)` (and the second of `crease`, if
    /// any), for the solve. Its friction acts from the start, with the normal impulse of the
    /// last step. A new contact that comes to the wall without sliding along it (a rope laid on
    /// a slope) starts held, with the normal impulse that stops its own approach: from sliding,
    /// Newton stays on the law's sliding branch wherever both exist (`PinFriction`).
    fn pin_touching(
        &mut self,
        w: &mut Work,
        k: &Consts,
        i: usize,
        (normal, gap): (Vec3<f64>, f64),
        crease: Option<[(Vec3<f64>, f64); 2]>,
    ) {
        let (normal, gap) = crease.map_or((normal, gap), |[a, _]| a);
        let before = w.x.get(i);
        let (stick, pn) = match self.last[i] {
            Touch::Stick(pn) => (true, Some(pn)),
            Touch::Slide(pn) => (false, Some(pn)),
            Touch::Free => {
                let along = w.v_start.get(i) * self.h - self.wall_shift(i, w);
                let tangential = along - normal * normal.dot(&along);
                (tangential.norm() <= STICK_SPEED * self.h, None)
            }
        };
        self.pin(w, i, normal, gap, stick, pn.unwrap_or(0.0));
        let s = self.slot[i];
        if let Some([_, (other, other_gap)]) = crease {
            // Its gap to the second wall from where the first put it.
            let moved = w.x.get(i) - before;
            back_on_walls(w, s, other, other_gap + other.dot(&moved), self.radius);
        }
        if pn.is_none() {
            let stops = (w.x.get(i) - w.x_pred.get(i)) / k.inv_mass[i];
            let p = &mut w.pinned[s];
            p.pn = walls_impulse(p, &stops).0.max(0.0);
        }
    }

    /// The two walls point `i` touches (within `tol`) at the last detection, when it touches
    /// two whose normals are far enough from parallel for a crease near it ([`CREASE_COS`]):
    /// the nearest, and the nearest of those at an angle to it, each as normal and gap.
    fn two_walls(&self, i: usize, tol: f64) -> Option<[(Vec3<f64>, f64); 2]> {
        let nearest = |skip: Option<Vec3<f64>>| {
            self.mesh
                .walls_of(i, self.radius)
                .filter(|&(_, gap)| gap <= tol)
                .filter(|(n, _)| skip.is_none_or(|a| a.dot(n).abs() <= CREASE_COS))
                .min_by(|a, b| a.1.total_cmp(&b.1))
        };
        let first = nearest(None)?;
        Some([first, nearest(Some(first.0))?])
    }

    /// Pins point `i` on the plane through its wall point (normal `normal`, the sphere `gap`
    /// away from it), with the friction of the obstacle it touches under the normal impulse
    /// `pn`: from where it is, projected, or (`stick`: friction held it at the end of the last
    /// step) from its place at the start of the step, projected.
    fn pin(&mut self, w: &mut Work, i: usize, normal: Vec3<f64>, gap: f64, stick: bool, pn: f64) {
        let x = w.x.get(i);
        // A point of the plane on which the sphere touches the wall.
        let on_wall = x - normal * gap;
        let start = w.x_old.get(i) + self.wall_shift(i, w);
        let from = if stick { start } else { x };
        let placed = from - normal * normal.dot(&(from - on_wall));
        w.x.set(i, &placed);
        self.slot[i] = w.pinned.len();
        let Friction {
            static_coefficient: mu_s,
            kinetic_coefficient: mu_k,
        } = self.mesh.friction_at(i);
        let mut friction = PinFriction::new(start, mu_s, mu_k, self.h);
        if let (Touch::Slide(_), Some(f)) = (self.last[i], friction) {
            let predicted = w.x_pred.get(i) - start;
            friction = Some(f.continuing(&(predicted - normal * normal.dot(&predicted))));
        }
        w.pinned
            .push(Pinned::on_wall(i, normal, false, pn, friction));
    }

    /// Steps 2 and 3 of the module docs after a solve: lets go of the points the wall would
    /// have to pull, gives the others the normal impulse of this solve for their friction,
    /// and moves newly pinned points onto the wall (`reuse` as in [`detect`](Self::detect)).
    /// Returns what changed that the solve should take into account.
    pub(crate) fn update(&mut self, w: &mut Work, k: &Consts, reuse: bool) -> Update {
        let mut changed = false;
        let mut released = false;
        let mut matrix_changed = false;
        for s in 0..w.pinned.len() {
            let mut p = w.pinned[s];
            if !p.on_mesh() {
                continue;
            }
            let i = p.point;
            let (pn, off_crease) = match w.row_impulse(&p) {
                Some(pn) => (pn, None),
                None => walls_impulse(&p, &pin_impulse(w, k, &w.lambda[0], i)),
            };
            if let Some(normal) = off_crease {
                // One wall would have to pull: the point slides on the other.
                p.normal = normal;
                p.crease = None;
                matrix_changed = true;
                changed = true;
            }
            if !(pn > 0.0) {
                // The wall would have to pull: let go. A contact row the solve already left
                // free (no impulse, no friction) changes nothing by going.
                released |= !w.quietly_free(&p);
                p.point = usize::MAX;
                w.pinned[s] = p;
                continue;
            }
            let (resolve, rebuild) = p.take_normal_impulse(pn, &w.x.get(i), k.inv_mass[i]);
            changed |= resolve;
            matrix_changed |= rebuild;
            w.pinned[s] = p;
        }
        if w.pinned.iter().any(|p| p.point == usize::MAX) {
            w.pinned.retain(|p| p.point != usize::MAX);
            self.reindex(w);
            changed |= released;
        }
        let caught = self.catch_penetrations(w, k, reuse);
        Update {
            resolve: caught.resolve || changed,
            // A new normal impulse changes the friction's stiffness in the matrix, which the
            // iterations refactorise for if they stall; points let go or moved off a crease
            // change the matrix itself.
            matrix_changed: released || matrix_changed || caught.matrix_changed,
        }
    }

    /// Pins the points an iterate has pushed into the mesh (onto the wall), puts pinned points
    /// that left their plane (a curved wall) back on the wall, and lets go of pinned points the
    /// detection no longer sees. Returns whether anything changed. Run after every iteration
    /// of the solve, so that an iterate never travels far into a wall before the rest of the
    /// rod learns of it. `reuse` as in [`detect`](Self::detect).
    pub(crate) fn catch_penetrations(&mut self, w: &mut Work, k: &Consts, reuse: bool) -> Update {
        let mut changed = false;
        let mut matrix_changed = false;
        // Points the solve pushed into the mesh, and pinned points that left their plane (a
        // curved wall).
        self.detect(w, k, reuse);
        let tol = self.tolerance();
        self.found.clear();
        self.found.resize(w.n + 1, false);
        let touching = std::mem::take(&mut self.mesh.contacts);
        for c in touching.contacts() {
            let (i, normal, gap) = (c.point as usize, c.normal, c.gap);
            self.found[i] = true;
            // Held points (the hand) and guided ones (in the guide, outside the body) are
            // where their holders put them: not the wall's to answer for.
            if k.inv_mass[i] == 0.0 {
                continue;
            }
            let s = self.slot[i];
            if s != usize::MAX {
                if !w.pinned[s].on_mesh() {
                    continue;
                }
                if gap < -tol {
                    matrix_changed |= back_on_walls(w, s, normal, gap, self.radius);
                    changed = true;
                }
                // Else on the wall, or off a wall that turns away from its plane: the plane
                // keeps it in the lumen, and the update lets it go if the plane would have to
                // pull it.
            } else if gap < -tol {
                let crease = self.two_walls(i, tol);
                self.pin_touching(w, k, i, (normal, gap), crease);
                changed = true;
                matrix_changed = true;
            }
        }
        self.mesh.contacts = touching;
        // Pinned points the detection no longer sees have left the wall.
        let before = w.pinned.len();
        let found = &self.found;
        w.pinned.retain(|p| !p.on_mesh() || found[p.point]);
        if w.pinned.len() != before {
            self.reindex(w);
            changed = true;
            matrix_changed = true;
        }
        Update {
            resolve: changed,
            matrix_changed,
        }
    }

    /// How deep the accepted step leaves the rod in the mesh, for the statistics: the deepest
    /// any point's sphere reaches into the wall (its radius less its distance from the mesh,
    /// points in the lumen; radius plus distance, points outside), and the points outside the
    /// lumen (by [`cosserat_collide::MeshCollider::lumen_winding`] where the mesh encloses a volume, by the
    /// nearest feature's side otherwise), measured exactly at the step's end positions for
    /// every point whose bound could raise them. A point's last detection bounds its gap from
    /// below (its gap then, less how far it moved since: the gap changes no faster than the
    /// point moves), so only points whose bound is deeper than the deepest so far, or behind
    /// the wall, are measured: a few distance queries a step. Held and guided points are not
    /// the wall's to answer for and are left out. The bounds alone overstated the depth up to
    /// the penetration tolerance (2 % of the radius) where the inside test found 0.01 µm
    /// (`docs/benchmarks/torture.md`).
    fn penetration(&self, w: &Work, k: &Consts) -> (f64, usize) {
        let collider = self.mesh.settings.collider.as_deref();
        let radius = self.radius;
        let mut deepest = self.stats.max_penetration.max(0.0);
        let mut outside = 0;
        for (i, cached) in self.cached.iter().enumerate() {
            let Some((_, gap)) = *cached else { continue };
            if k.inv_mass[i] == 0.0
                || (self.slot[i] != usize::MAX && !w.pinned[self.slot[i]].on_mesh())
            {
                continue;
            }
            let x = w.x.get(i);
            let bound = gap - (x - self.queried_at[i]).norm();
            if -bound <= deepest && bound >= -radius {
                continue;
            }
            let p = [x.x, x.y, x.z];
            // Behind the wall by its bound: the inside test says whether it is. One distance
            // query either way.
            let (near, mut out) = match collider {
                Some(collider) if bound < -radius => {
                    let near = collider.nearest(&p, f64::INFINITY);
                    let out = if collider.encloses_volume() {
                        collider.lumen_winding(&p) < 0.5
                    } else {
                        near.is_some_and(|n| n.signed_distance < 0.0)
                    };
                    (near, out)
                }
                Some(collider) => (collider.nearest(&p, radius - deepest), false),
                None => (None, false),
            };
            if let Some(near) = near {
                let depth = if out {
                    radius + near.distance
                } else {
                    radius - near.distance
                };
                deepest = deepest.max(depth);
            }
            // Analytic shapes: exact at any depth.
            if let Some((depth, behind)) = self.mesh.shape_depth(&x, radius) {
                deepest = deepest.max(depth);
                out |= behind;
            }
            outside += usize::from(out);
        }
        (deepest, outside)
    }

    /// Records how each point touches at the end of an accepted step, for the next step and
    /// for the statistics.
    pub(crate) fn end_step(&mut self, w: &Work, k: &Consts) {
        self.last.iter_mut().for_each(|t| *t = Touch::Free);
        for p in w.pinned.iter().filter(|p| p.on_mesh()) {
            let holds = p
                .friction
                .zip(p.slip(&w.x.get(p.point)))
                .is_some_and(|(f, slip)| f.holds(&slip));
            self.last[p.point] = if holds {
                Touch::Stick(p.pn)
            } else {
                Touch::Slide(p.pn)
            };
        }
        let (deepest, outside) = self.penetration(w, k);
        let s = &mut self.stats;
        s.max_penetration = s.max_penetration.max(deepest);
        s.contacts = w.pinned.iter().filter(|p| p.on_mesh()).count();
        s.max_contacts = s.max_contacts.max(s.contacts);
        s.steps += 1;
        s.escaped_points = s.escaped_points.max(outside);
        s.swept_catches = self.mesh.stats.swept_catches;
        s.segment_contacts = self.mesh.stats.segment_contacts;
        s.detection_seconds = self.mesh.stats.detection_seconds;
    }
}

/// The normal impulse the walls of pin `p` exert within its impulse `g` (times the step): on
/// one wall `n · g`; in a crease the sum of the two walls' shares of `g = a n + b m + (along
/// the crease)`, or, when one of them would have to pull, the other's share and the normal of
/// the wall the point stays on (it leaves the crease).
fn walls_impulse(p: &Pinned, g: &Vec3<f64>) -> (f64, Option<Vec3<f64>>) {
    let pn = p.normal.dot(g);
    let Some(m) = p.crease else {
        return (pn, None);
    };
    let (gm, c) = (m.dot(g), p.normal.dot(&m));
    let det = 1.0 - c * c;
    let (a, b) = ((pn - c * gm) / det, (gm - c * pn) / det);
    if a > 0.0 && b > 0.0 {
        (a + b, None)
    } else if a > 0.0 {
        (a, Some(p.normal))
    } else if b > 0.0 {
        (b, Some(m))
    } else {
        (0.0, None)
    }
}

/// Puts pinned point `w.pinned[s]`, found `gap < 0` behind the wall of normal `normal`, back
/// on it. Slid into a wall that turns towards the lumen (a crease of the mesh, or a curved
/// wall), the point would slide into the first wall again if only moved out of the second: it
/// is moved onto both (out along `normal`, staying on the plane of the wall it slid on) and
/// slides along their crease from then on. A wall barely turned from the one it slides on
/// (within [`NORMAL_TURN`]) replaces it; a third wall makes a crease with the first. Returns
/// whether the matrix of the solve changed (the factorisation is kept for a turn within
/// `NORMAL_TURN`: the iterations refactorise if they stall). A point more than its radius
/// behind the new wall (caught by the swept test) is only moved out along its normal: the
/// crease of two planes may lie far from such a point.
fn back_on_walls(w: &mut Work, s: usize, normal: Vec3<f64>, gap: f64, radius: f64) -> bool {
    let parallel = NORMAL_TURN.cos();
    let p = &mut w.pinned[s];
    let x = w.x.get(p.point);
    let near = |a: &Vec3<f64>| a.dot(&normal) >= parallel;
    // The wall the point stays on while it is moved out of the new one, and whether the
    // matrix changed.
    let (stay, turned) = match p.crease {
        // Deep behind the new wall (a crossing the swept test caught): the crease of its plane
        // with the old one may be far from the point. Out along the new wall's normal only.
        _ if -gap > radius => {
            let turned = p.crease.is_some() || !near(&p.normal);
            p.normal = normal;
            p.crease = None;
            (None, turned)
        }
        Some(m) if near(&m) => {
            p.crease = Some(normal);
            (Some(p.normal), false)
        }
        Some(m) if near(&p.normal) => {
            p.normal = normal;
            (Some(m), false)
        }
        None if near(&p.normal) => {
            p.normal = normal;
            (None, false)
        }
        // A new wall: the crease of the wall the point slides on with it, unless the two are
        // too close to parallel (or face each other) for their crease to be near the point.
        _ if p.normal.dot(&normal).abs() <= CREASE_COS => {
            p.crease = Some(normal);
            (Some(p.normal), true)
        }
        _ => {
            p.normal = normal;
            p.crease = None;
            (None, true)
        }
    };
    // `y = x + α k + β n` with `k·(y − x) = 0` (on the wall it stays on) and
    // `n·(y − x) = −gap` (out of the new one).
    let moved = match stay {
        Some(k) if 1.0 - k.dot(&normal).powi(2) > 1e-6 => {
            let c = k.dot(&normal);
            let beta = -gap / (1.0 - c * c);
            normal * beta - k * (c * beta)
        }
        _ => -normal * gap,
    };
    w.x.set(p.point, &(x + moved));
    turned
}

/// Pins the run of points a guide holds (from index 1 on, the first point being held by the
/// hand; see [`crate::guide`]) to its axis for the step's solve, starting from the solve's
/// starting guess: each is put on the axis and may move only along it. Replaces every pin of
/// `w`.
pub(crate) fn pin_guided(w: &mut Work, k: &Consts, guide: &Guide) {
    w.pinned.clear();
    let axis = guide.axis();
    for i in 1..=w.n {
        let x = w.x.get(i);
        let Some(lateral) = guide.lateral_offset(&x) else {
            break;
        };
        if k.inv_mass[i] == 0.0 {
            continue;
        }
        w.x.set(i, &(x - lateral));
        w.pinned.push(Pinned::on_line(i, axis));
    }
}

/// `M (x − x̃) − (J_rᵀ λ)_i`: the impulse (times the step) that holds point `i` where it is
/// beyond what the multipliers `lambda` explain, i.e. what its pin (a wall, a guide, a binding's
/// line) exerts on it. Free points of a converged step have none.
pub(crate) fn pin_impulse(w: &Work, k: &Consts, lambda: &V3s, i: usize) -> Vec3<f64> {
    let mass = 1.0 / k.inv_mass[i];
    (w.x.get(i) - w.x_pred.get(i)) * mass - constraint_impulse(w, k, lambda, i)
}

/// `(J_rᵀ λ)_i`: the impulse (times the step) the stretch–shear multipliers `lambda` give
/// point `i`, at the Jacobians of the last `Work::constraints`.
pub(crate) fn constraint_impulse(w: &Work, k: &Consts, lambda: &V3s, i: usize) -> Vec3<f64> {
    let term = |j: usize| {
        let l = lambda.get(j);
        (w.dirs[0].get(j) * l.x + w.dirs[1].get(j) * l.y + w.dirs[2].get(j) * l.z)
            * k.cols.inv_l0[j]
    };
    let mut f = Vec3::zeros();
    if i >= 1 {
        f += term(i - 1);
    }
    if i < w.n {
        f -= term(i);
    }
    f
}
