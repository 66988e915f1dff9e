//! The time step (paper Fig. 5, without collisions) and its parallel driver.

use crate::guide::Guide;
use crate::mesh_contact::{MeshContactSettings, Motion, RodMeshContact};
use crate::reaction::Reactions;
use crate::soa::{self, SoaParams, SoaState};
use cosserat_constraints::{
    ContactSet, KinematicImpulses, Ordering, RedBlackSolver, solve_distance_gauss_seidel_soa,
};
use cosserat_model::energy::{
    bend_damping_node, clamp_damping, clamp_node_of, stretch_damping_element,
};
use cosserat_model::quat::{exp_rotation, rotate, rotate_inv};
use cosserat_model::{Quat, Real, RodParams, RodState, Vec3};
use cosserat_problem::CollisionStats;
use cosserat_problem::EndCondition;
use cosserat_problem::EndReaction;
pub(crate) use cosserat_problem::{
    DivergedQuantity, Divergence, Par, PointLoad, SolverSettings, StepStats,
};

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
    pub(crate) work: SoaState<T>,
    pub(crate) work_params: SoaParams<T>,
    pub(crate) red_black: Option<RedBlackSolver<T>>,
    pub(crate) mesh: Option<Box<RodMeshContact<T>>>,
    /// Reaction bookkeeping of held ends (`None` when both ends are free).
    pub(crate) reaction: Option<Box<Reactions<T>>>,
    /// Impulses that coupling constraints delivered to the kinematic end points this step.
    pub(crate) kinematic: KinematicImpulses<T>,
    /// Impulses the end distance constraints gave their free neighbours this step
    /// (Gauss–Seidel ordering; the red–black solver keeps its own).
    pub(crate) end_impulses: [Vec3<T>; 2],
    /// The exact inextensibility solver, when chosen instead of the iterative sweeps.
    pub(crate) direct: Option<Box<DirectState<T>>>,
    /// An introducer that keeps the first points on a line (`None`: no guide, no cost).
    pub(crate) guide: Option<Guide>,
    /// Held end points' positions in `f64`, advanced by their prescribed velocity (see
    /// [`HeldPath`]).
    pub(crate) held_path: [HeldPath; 2],
    /// The velocity across its axis that a sliding end's motion prescribes over this step.
    pub(crate) slide_velocity: [Vec3<T>; 2],
    /// A hinged clamp's axis in the clamp's own frame, fixed when the hinge is first stepped
    /// (the condition gives it in the world frame; turning about itself leaves it in place).
    pub(crate) hinge_body: [Option<Vec3<T>>; 2],
}

/// The path of a held end point, accumulated in `f64`.
///
/// Why: in `f32` a point half a metre from the origin has a spacing of 6e-8 m, and a hand pushing
/// at 0.2 m/s moves it by 7e-7 m per step of 3.5 µs, so each coordinate's increment is rounded by
/// up to 4 %, the same way every step. The held point then left its prescribed straight path by
/// millimetres per second (harmless for a free hand, fatal next to a guide that holds the following
/// points on the exact axis). The point is instead set to the `f64` sum after each step. If the
/// stored position was changed from outside, the sum restarts from it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct HeldPath {
    position: Option<[f64; 3]>,
}

impl HeldPath {
    /// The position after a step of `h` at velocity `v`, starting from `current` unless it is
    /// where the last step left it.
    fn advance<T: Real>(&mut self, current: Vec3<T>, v: Vec3<T>, h: T) -> Vec3<T> {
        let start = match self.position {
            Some(p) if Vec3::new(T::lit(p[0]), T::lit(p[1]), T::lit(p[2])) == current => p,
            _ => [current.x.to_f64(), current.y.to_f64(), current.z.to_f64()],
        };
        let h = h.to_f64();
        let p = [
            start[0] + v.x.to_f64() * h,
            start[1] + v.y.to_f64() * h,
            start[2] + v.z.to_f64() * h,
        ];
        self.position = Some(p);
        Vec3::new(T::lit(p[0]), T::lit(p[1]), T::lit(p[2]))
    }
}

/// State of the direct (Newton, tridiagonal) distance-constraint solver of one rod
/// (`cosserat_constraints::direct`): settings, scratch, and array-of-structs copies of the working
/// layout's positions and velocities, which that solver takes.
#[derive(Clone, Debug)]
pub(crate) struct DirectState<T: Real> {
    settings: cosserat_constraints::direct::DirectSettings,
    scratch: cosserat_constraints::direct::DirectScratch,
    r: Vec<Vec3<T>>,
    v: Vec<Vec3<T>>,
}

impl<T: Real> DirectState<T> {
    /// Solves the distance constraints of the working layout's state exactly.
    fn solve(&mut self, w: &mut crate::soa::SoaState<T>, p: &SoaParams<T>, h: T) {
        let n = self.r.len();
        for i in 0..n {
            self.r[i] = w.r.get(i);
            self.v[i] = w.v.get(i);
        }
        cosserat_constraints::direct::solve_distance_direct(
            &self.r,
            &mut self.v,
            &p.inv_masses,
            &p.rest_lengths,
            h,
            &self.settings,
            &mut self.scratch,
        );
        for i in 0..n {
            w.v.set(i, self.v[i]);
        }
    }
}

impl<T: Real> CpuRod<T> {
    /// Prepares a rod for stepping: held end points get zero inverse mass (a sliding one keeps
    /// its mass: it is free along its axis and put back across it, see `hold_sliding_ends`).
    ///
    /// The parameters are read here, once; to change them, build a new `CpuRod`.
    pub fn new(
        state: RodState<T>,
        mut params: RodParams<T>,
        ends: [EndCondition<T>; 2],
        loads: Vec<PointLoad<T>>,
    ) -> Self {
        let n = state.elements();
        for (end, point) in ends.iter().zip([0, n]) {
            if end.holds_point() && end.slide_axis().is_none() {
                params.inv_masses[point] = T::zero();
            }
        }
        let held = [ends[0].holds_point(), ends[1].holds_point()];
        let reaction = (held[0] || held[1]).then(|| {
            Box::new(Reactions::new(
                held,
                [ends[0].holds_frame(), ends[1].holds_frame()],
                [
                    ends[0].slide_axis().is_some(),
                    ends[1].slide_axis().is_some(),
                ],
            ))
        });
        Self {
            work: SoaState::new(n),
            work_params: SoaParams::new(&params),
            state,
            params,
            ends,
            loads,
            red_black: None,
            mesh: None,
            reaction,
            kinematic: [Vec3::zeros(); 2],
            end_impulses: [Vec3::zeros(); 2],
            direct: None,
            guide: None,
            held_path: [HeldPath::default(); 2],
            slide_velocity: [Vec3::zeros(); 2],
            hinge_body: [None; 2],
        }
    }

    /// Feeds the rod through a straight introducer from its first point (see [`crate::guide`]).
    #[must_use]
    pub fn with_guide(mut self, guide: Guide) -> Self {
        self.guide = Some(guide);
        self
    }

    /// The introducer the rod is fed through, if any.
    pub fn guide(&self) -> Option<&Guide> {
        self.guide.as_ref()
    }

    /// What the rod touches, if it has a mesh.
    pub fn mesh_settings(&self) -> Option<&MeshContactSettings> {
        self.mesh.as_ref().map(|m| &m.settings)
    }

    /// Replaces the iterative distance-constraint sweeps by the exact direct solver
    /// (`cosserat_constraints::direct`: Newton iterations on the tridiagonal system `J M⁻¹ Jᵀ λ = b`),
    /// which leaves every segment at its rest length to the solver's tolerance after each
    /// step. Contacts, if any, are then swept `iterations` times. End reactions are not tracked
    /// through it.
    #[must_use]
    pub fn with_direct_solver(
        mut self,
        settings: cosserat_constraints::direct::DirectSettings,
    ) -> Self {
        let n = self.elements();
        self.direct = Some(Box::new(DirectState {
            settings,
            scratch: cosserat_constraints::direct::DirectScratch::new(n),
            r: vec![Vec3::zeros(); n + 1],
            v: vec![Vec3::zeros(); n + 1],
        }));
        self
    }

    /// Sets the cut-off frequency [Hz] of the low-pass filter on the reported end reactions
    /// (default [`crate::reaction::DEFAULT_CUTOFF_HZ`]; `f64::INFINITY` reports the raw value).
    #[must_use]
    pub fn with_reaction_cutoff(mut self, hz: f64) -> Self {
        if let Some(r) = self.reaction.as_mut() {
            r.set_cutoff(hz);
        }
        self
    }

    /// The filtered reaction at a held end (`0`: first, `1`: last) after the last step: the
    /// force and torque the holder applies to the rod (see [`crate::reaction`]). `None` for a
    /// free end.
    pub fn end_reaction(&self, end: usize) -> Option<EndReaction> {
        self.reaction.as_ref().and_then(|r| r.filtered(end.min(1)))
    }

    /// The unfiltered reaction of the last step at a held end.
    pub fn end_reaction_raw(&self, end: usize) -> Option<EndReaction> {
        self.reaction.as_ref().and_then(|r| r.raw(end.min(1)))
    }

    /// Largest filtered reaction force at any held end over all steps so far [N] (`None` when
    /// both ends are free).
    pub fn max_reaction_force(&self) -> Option<f64> {
        self.reaction.as_ref().map(|r| r.max_filtered())
    }

    /// Replaces the condition at end `end` (0: first point, 1: last point). A change of motion
    /// takes effect at the next step; a change of how the end is held (free, pinned, clamped)
    /// also gives the end point back its mass or takes it away, and restarts the reaction
    /// bookkeeping and the constraint solver's cached inverse masses.
    ///
    /// # Panics
    /// If `end > 1`.
    pub fn set_end_condition(&mut self, end: usize, condition: EndCondition<T>) {
        let old = std::mem::replace(&mut self.ends[end], condition);
        let condition = &self.ends[end];
        if old.hinge != condition.hinge || old.kind != condition.kind {
            self.hinge_body[end] = None;
        }
        if old.kind == condition.kind
            && old.slide_axis().is_some() == condition.slide_axis().is_some()
        {
            return;
        }
        if condition.holds_frame() && !old.holds_frame() {
            // The clamp closes on the end frame where it is.
            self.state.seat_clamp(&self.params, end);
        }
        let n = self.elements();
        let point = if end == 0 { 0 } else { n };
        self.params.inv_masses[point] =
            if condition.holds_point() && condition.slide_axis().is_none() {
                T::zero()
            } else {
                T::one() / self.params.masses[point]
            };
        self.work_params = SoaParams::new(&self.params);
        self.red_black = None;
        self.held_path[end] = HeldPath::default();
        let held = [self.ends[0].holds_point(), self.ends[1].holds_point()];
        let cutoff = self.reaction.as_ref().map(|r| r.cutoff());
        self.reaction = (held[0] || held[1]).then(|| {
            let mut r = Reactions::new(
                held,
                [self.ends[0].holds_frame(), self.ends[1].holds_frame()],
                [
                    self.ends[0].slide_axis().is_some(),
                    self.ends[1].slide_axis().is_some(),
                ],
            );
            if let Some(hz) = cutoff {
                r.set_cutoff(hz);
            }
            Box::new(r)
        });
    }

    /// Number of elements.
    pub fn elements(&self) -> usize {
        self.state.elements()
    }

    /// Makes the rod collide with a static mesh.
    #[must_use]
    pub fn with_mesh(mut self, settings: MeshContactSettings) -> Self {
        self.mesh = Some(Box::new(RodMeshContact::new(settings)));
        self
    }

    /// Contact measurements since the last reset, if the rod collides with a mesh.
    pub fn collision_stats(&self) -> Option<CollisionStats> {
        self.mesh.as_ref().map(|m| m.stats)
    }

    /// The contacts of the last step and their accumulated impulses, if the rod collides with a
    /// mesh.
    pub fn contacts(&self) -> Option<&ContactSet<T>> {
        self.mesh.as_ref().map(|m| &m.contacts)
    }
}

/// Advances one rod by one step of `settings.dt` starting at time `time`.
///
/// `rod_index` and `step` only label a [`Divergence`].
pub fn step_rod<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    time: f64,
    rod_index: usize,
    step: u64,
) -> Result<StepStats, Divergence> {
    step_rod_batch(rod, settings, time, rod_index, step, 1)
}

/// Advances one rod by `steps` steps starting at time `time` and step index `first_step`.
///
/// The rod is moved into the backend's working layout once for the whole batch, which is the
/// CPU counterpart of running many time-steps per GPU dispatch. `rod.state` is up to date when
/// this returns, also after a divergence (it then holds the diverged state). The returned stats
/// cover every step of the batch.
pub fn step_rod_batch<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    time: f64,
    rod_index: usize,
    first_step: u64,
    steps: u64,
) -> Result<StepStats, Divergence> {
    let h = settings.dt;
    let consts = BatchConsts::new(rod, settings);
    rod.work.gather(&rod.state);
    let mut stats = StepStats {
        min_stretch: f64::MAX,
        max_stretch: 0.0,
    };
    let mut result = Ok(());
    for k in 0..steps {
        let t = time + k as f64 * h.to_f64();
        before_constraints(rod, settings, &consts, t);
        let distance = solve_constraints(rod, settings);
        match after_constraints(rod, settings, &consts, distance) {
            Ok((lo, hi)) => {
                stats.min_stretch = stats.min_stretch.min(lo);
                stats.max_stretch = stats.max_stretch.max(hi);
            }
            Err((element, quantity)) => {
                result = Err(Divergence {
                    rod: rod_index,
                    element,
                    step: first_step + k,
                    quantity,
                });
                break;
            }
        }
    }
    rod.work.scatter(&mut rod.state);
    result.map(|()| stats)
}

/// What a batch of steps decides once per rod.
pub(crate) struct BatchConsts<T> {
    bend_damping: bool,
    stretch_damping: bool,
    lo2: T,
    hi2: T,
}

impl<T: Real> BatchConsts<T> {
    pub(crate) fn new(rod: &CpuRod<T>, settings: &SolverSettings<T>) -> Self {
        let limit = settings.divergence_strain;
        // A limit of 1 or more bounds compression by nothing (a length cannot go below zero):
        // squared unclamped, it would declare every rod diverged.
        let lo = (T::one() - limit).max(T::zero());
        Self {
            bend_damping: rod.params.bend_damping.iter().any(|&c| c > T::zero()),
            stretch_damping: settings.extensible
                && rod.params.stretch_damping.iter().any(|&c| c > T::zero()),
            lo2: lo * lo,
            hi2: (T::one() + limit) * (T::one() + limit),
        }
    }
}

/// Forces and torques, velocity integration, end conditions (recording what the reaction at a
/// held end needs) and mesh-contact detection: the step up to the constraint iterations.
#[inline(always)]
pub(crate) fn before_constraints<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    consts: &BatchConsts<T>,
    t: f64,
) {
    let h = settings.dt;
    let n = rod.elements();
    let w = &mut rod.work;
    let p = &rod.work_params;
    soa::elastic_forces(w, p, settings.gravity, rod.params.drag, settings.extensible);
    if consts.bend_damping {
        for j in 0..n - 1 {
            let (qa, qb) = (w.frame(j), w.frame(j + 1));
            let (da, db) = bend_damping_node(
                &qa,
                &qb,
                &w.w.get(j),
                &w.w.get(j + 1),
                rod.params.bend_damping[j],
                rod.params.node_length(j),
            );
            w.tq.set(j, w.tq.get(j) + da);
            w.tq.set(j + 1, w.tq.get(j + 1) + db);
        }
    }
    if consts.stretch_damping {
        for j in 0..n {
            let fd = stretch_damping_element(
                &w.r.get(j),
                &w.r.get(j + 1),
                &w.v.get(j),
                &w.v.get(j + 1),
                rod.params.stretch_damping[j],
                rod.params.rest_lengths[j],
            );
            w.f.set(j, w.f.get(j) - fd);
            w.f.set(j + 1, w.f.get(j + 1) + fd);
        }
    }
    // Loads at the middle of the step (a ramp's impulse over the step is then exact); a
    // moment acts half on each frame beside an interior point, all on an end point's frame.
    let mid = t + 0.5 * h.to_f64();
    for load in &rod.loads {
        let factor = T::lit(load.profile.factor(mid));
        w.f.set(load.point, w.f.get(load.point) + load.force * factor);
        if load.moment != Vec3::zeros() {
            for (frame, share) in moment_shares(load.point, n) {
                let body = rotate_inv(&w.frame(frame), &(load.moment * (factor * T::lit(share))));
                w.tq.set(frame, w.tq.get(frame) + body);
            }
        }
    }
    // A clamp holds the end frame through its node (`cosserat_model::rod::EndNode`); the clamp
    // frame then turns with the clamp's prescribed rotation.
    for (e, (end, frame)) in rod.ends.iter().zip([0, n - 1]).enumerate() {
        if end.holds_frame() {
            let mut omega = end.velocities_over(t, h.to_f64()).1;
            if let Some(axis) = end.hinge_axis() {
                let clamp = &mut rod.state.clamp_frames[e];
                let body = *rod.hinge_body[e].get_or_insert_with(|| rotate_inv(clamp, &axis));
                let turn = settle_hinge(clamp, &w.frame(frame), &rod.params, e, &body);
                // The clamp's own turn this step, for the node's damping.
                omega += rotate(clamp, &body) * (turn / h);
            }
            let torque = clamp_torque(w, &rod.state.clamp_frames[e], &rod.params, e, frame, omega);
            w.tq.set(frame, w.tq.get(frame) + torque);
            if let Some(rx) = rod.reaction.as_deref_mut() {
                rx.record_torque(e, rotate(&w.frame(frame), &torque));
            }
            let turned = exp_rotation(&(omega * h)) * rod.state.clamp_frames[e];
            rod.state.clamp_frames[e] = turned / turned.norm();
        }
    }
    soa::integrate_velocities(w, p, h);
    // Held end points follow their prescribed motion exactly; a sliding one only across its
    // axis, keeping along it what its forces gave it.
    for (e, (end, point)) in rod.ends.iter().zip([0, n]).enumerate() {
        if end.holds_point() {
            let mut v = end.velocities_over(t, h.to_f64()).0;
            // A kinematic point's velocity did not take its force; a sliding one's did.
            let mut force = w.f.get(point);
            if let Some(a) = end.slide_axis() {
                rod.slide_velocity[e] = v;
                v += a * a.dot(&w.v.get(point));
                force = Vec3::zeros();
            }
            if let Some(rx) = rod.reaction.as_deref_mut() {
                rx.record_point(e, p.masses[point], force, w.v.get(point), v, h);
            }
            w.v.set(point, v);
        }
    }
    if let Some(guide) = &rod.guide {
        guide.constrain(w);
    }
    if let Some(mesh) = rod.mesh.as_mut() {
        // Moving obstacles where they are at the step's start, as the points are.
        mesh.pose_shapes(t, t, h.to_f64());
        // Swept along the step's predicted motion: a wall the point would cross beyond its
        // sphere's reach becomes a speculative contact.
        mesh.detect(
            &w.r.x,
            &w.r.y,
            &w.r.z,
            rod.params.radius.to_f64(),
            Motion::Velocity([&w.v.x, &w.v.y, &w.v.z], h.to_f64()),
        );
    }
}

/// The frames a moment on `point` of a rod of `n` elements acts on, and each one's share: half
/// on each of an interior point's two frames, all on an end point's one.
pub fn moment_shares(point: usize, n: usize) -> impl Iterator<Item = (usize, f64)> {
    let both = point > 0 && point < n;
    let share = if both { 0.5 } else { 1.0 };
    [point.checked_sub(1), (point < n).then_some(point)]
        .into_iter()
        .flatten()
        .map(move |f| (f, share))
}

/// Turns a hinged clamp (`clamp`, of end `e`) about its hinge axis (`axis`, in its own frame) to
/// where its node's elastic torque about that axis vanishes, the end frame being `q`, and
/// returns the angle it turned by. A hinge is a clamp without inertia about its axis, so it sits
/// where the rod leaves it no moment about the axis, step by step. The torque about the axis is
/// nearly linear in the angle (the node's relative rotation changes by a few milliradians a
/// step), so a few secant steps from the present angle find it to rounding.
fn settle_hinge<T: Real>(
    clamp: &mut Quat<T>,
    q: &Quat<T>,
    params: &RodParams<T>,
    e: usize,
    axis: &Vec3<T>,
) -> T {
    let node = &params.end_nodes[e];
    let l = params.end_node_length(e);
    let turned = |phi: T| {
        let c = *clamp * exp_rotation(&(axis * phi));
        c / c.norm()
    };
    // The node's torque on the clamp (clamp axes) about the hinge axis.
    let moment = |phi: T| clamp_node_of(&turned(phi), q, node, l, e).2.dot(axis);
    let (mut a, mut b) = (T::zero(), T::lit(1e-3));
    let (mut ga, mut gb) = (moment(a), moment(b));
    let at_rest = ga.abs();
    for _ in 0..4 {
        let slope = (gb - ga) / (b - a);
        if !(slope.abs() > T::zero()) || !slope.is_finite() {
            break;
        }
        let next = b - gb / slope;
        (a, ga) = (b, gb);
        b = next;
        gb = moment(b);
    }
    // The better of the last two, unless neither beats not turning (a flat or noisy moment
    // leaves the clamp where it was).
    let (phi, g) = if gb.abs() <= ga.abs() {
        (b, gb)
    } else {
        (a, ga)
    };
    let phi = if g.abs() <= at_rest { phi } else { T::zero() };
    *clamp = turned(phi);
    phi
}

/// The body torque the clamp of end `e` gives the end frame `frame` of the working layout: its
/// node's elasticity and damping against the clamp frame `clamp`, which turns at the world
/// angular velocity `omega`.
#[inline]
fn clamp_torque<T: Real>(
    w: &SoaState<T>,
    clamp: &Quat<T>,
    params: &RodParams<T>,
    e: usize,
    frame: usize,
    omega: Vec3<T>,
) -> Vec3<T> {
    let node = &params.end_nodes[e];
    let l = params.end_node_length(e);
    let q = w.frame(frame);
    let elastic = clamp_node_of(clamp, &q, node, l, e).1;
    if node.damping > T::zero() {
        elastic + clamp_damping(&q, &w.w.get(frame), clamp, &omega, node.damping, l)
    } else {
        elastic
    }
}

/// Whether the red–black solver runs this rod's distance constraints.
#[inline]
pub(crate) fn uses_red_black<T: Real>(settings: &SolverSettings<T>) -> bool {
    !settings.extensible && settings.iterations > 0 && settings.ordering == Ordering::RedBlack
}

/// The rod's red–black solver, created on first use (measuring the end constraints' impulses
/// when an end is held).
#[inline]
pub(crate) fn red_black_of<'a, T: Real>(
    solver: &'a mut Option<RedBlackSolver<T>>,
    p: &SoaParams<T>,
    reaction: Option<&Reactions<T>>,
) -> &'a mut RedBlackSolver<T> {
    solver.get_or_insert_with(|| {
        let mut s = RedBlackSolver::new(&p.inv_masses, &p.rest_lengths);
        if let Some(r) = reaction {
            let [a, b] = r.tracked();
            s.track_ends(a, b);
        }
        s
    })
}

/// The constraint iterations of a rod on its own: distance constraints interleaved with its
/// mesh contacts. Returns the impulses the end distance constraints gave their free
/// neighbours (zero unless an end is held).
#[inline(always)]
fn solve_constraints<T: Real>(rod: &mut CpuRod<T>, settings: &SolverSettings<T>) -> [Vec3<T>; 2] {
    let h = settings.dt;
    let w = &mut rod.work;
    let p = &rod.work_params;
    let track = rod.reaction.as_deref().map_or([false; 2], |r| r.tracked());
    let mut distance = [Vec3::zeros(); 2];
    let mut contacts = rod
        .mesh
        .as_mut()
        .filter(|m| !m.contacts.is_empty())
        .map(|m| (&mut m.contacts, &m.friction));
    if let (false, Some(d)) = (settings.extensible, rod.direct.as_deref_mut()) {
        d.solve(w, p, h);
        if let Some((set, friction)) = contacts.as_mut() {
            for _ in 0..settings.iterations.max(1) {
                set.sweep_soa(
                    h,
                    friction,
                    &p.inv_masses,
                    [&mut w.v.x, &mut w.v.y, &mut w.v.z],
                );
            }
        }
        return distance;
    }
    let r = [&w.r.x[..], &w.r.y[..], &w.r.z[..]];
    if !settings.extensible && settings.iterations > 0 {
        match settings.ordering {
            Ordering::GaussSeidel => {
                for _ in 0..settings.iterations {
                    gauss_seidel_sweep(
                        r,
                        [&mut w.v.x, &mut w.v.y, &mut w.v.z],
                        &p.inv_masses,
                        &p.rest_lengths,
                        h,
                        track,
                        &mut distance,
                    );
                    if let Some((set, friction)) = contacts.as_mut() {
                        set.sweep_soa(
                            h,
                            friction,
                            &p.inv_masses,
                            [&mut w.v.x, &mut w.v.y, &mut w.v.z],
                        );
                    }
                }
            }
            Ordering::RedBlack => {
                let solver = red_black_of(&mut rod.red_black, p, rod.reaction.as_deref());
                solver.solve_soa_with_contacts(
                    r,
                    [&mut w.v.x, &mut w.v.y, &mut w.v.z],
                    h,
                    settings.iterations,
                    contacts,
                );
                if track[0] || track[1] {
                    distance = solver.take_end_impulses();
                }
            }
        }
    } else if let Some((set, friction)) = contacts.as_mut() {
        // Extensible rods have no distance constraints; their contacts still get solved.
        for _ in 0..settings.iterations.max(1) {
            set.sweep_soa(
                h,
                friction,
                &p.inv_masses,
                [&mut w.v.x, &mut w.v.y, &mut w.v.z],
            );
        }
    }
    distance
}

/// Completes the reaction at held ends, integrates positions and frames, and checks for
/// divergence. Returns the smallest and largest length ratio.
#[inline(always)]
pub(crate) fn after_constraints<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    consts: &BatchConsts<T>,
    distance: [Vec3<T>; 2],
) -> Result<(f64, f64), (usize, DivergedQuantity)> {
    let n = rod.elements();
    let mut distance = distance;
    // A sliding end point is put back on its axis: across it, the velocity its motion
    // prescribes; along it, what the forces and constraints gave it. What that removes is the
    // holder's impulse (its reaction: minus what the point received across the axis).
    for (e, point) in [(0, 0), (1, n)] {
        if let Some(a) = rod.ends[e].slide_axis() {
            let v = rod.work.v.get(point);
            let kept = rod.slide_velocity[e] + a * a.dot(&v);
            distance[e] = (kept - v) * rod.work_params.masses[point];
            rod.work.v.set(point, kept);
        }
    }
    if let Some(rx) = rod.reaction.as_deref_mut() {
        rx.finish(distance, rod.kinematic, settings.dt);
        rod.kinematic = [Vec3::zeros(); 2];
    }
    if let Some(guide) = &rod.guide {
        guide.constrain(&mut rod.work);
    }
    let held = [
        (0, rod.ends[0].holds_point()),
        (n, rod.ends[1].holds_point()),
    ];
    let before = held.map(|(i, yes)| yes.then(|| (rod.work.r.get(i), rod.work.v.get(i))));
    soa::integrate_positions(&mut rod.work, &rod.work_params, settings.dt);
    for ((path, (i, _)), b) in rod.held_path.iter_mut().zip(held).zip(before) {
        if let Some((r, v)) = b {
            rod.work.r.set(i, path.advance(r, v, settings.dt));
        }
    }
    check(&rod.work, consts.lo2, consts.hi2)
}

/// One Gauss–Seidel sweep; with an end tracked, its constraint is projected here (the same
/// arithmetic as [`solve_distance_gauss_seidel_soa`]) so that its impulse on the free neighbour
/// can be added to `distance`.
#[inline]
pub(crate) fn gauss_seidel_sweep<T: Real>(
    r: [&[T]; 3],
    v: [&mut [T]; 3],
    inv_masses: &[T],
    rest_lengths: &[T],
    h: T,
    track: [bool; 2],
    distance: &mut [Vec3<T>; 2],
) {
    if !(track[0] || track[1]) {
        solve_distance_gauss_seidel_soa(r, v, inv_masses, rest_lengths, h);
        return;
    }
    let n = rest_lengths.len();
    let [vx, vy, vz] = v;
    let lo = usize::from(track[0] && n > 0);
    let hi = if track[1] { n.saturating_sub(1) } else { n };
    if lo == 1 {
        distance[0] += cosserat_constraints::project_distance_soa(
            r,
            [vx, vy, vz],
            inv_masses,
            rest_lengths[0],
            h,
            0,
        );
    }
    if hi > lo {
        solve_distance_gauss_seidel_soa(
            [&r[0][lo..=hi], &r[1][lo..=hi], &r[2][lo..=hi]],
            [&mut vx[lo..=hi], &mut vy[lo..=hi], &mut vz[lo..=hi]],
            &inv_masses[lo..=hi],
            &rest_lengths[lo..hi],
            h,
        );
    }
    if track[1] && n > 0 && hi >= lo {
        // The impulse on point n − 1 is minus the one on the held point n.
        distance[1] -= cosserat_constraints::project_distance_soa(
            r,
            [vx, vy, vz],
            inv_masses,
            rest_lengths[n - 1],
            h,
            n - 1,
        );
    }
}

/// The divergence check after a step: every frame finite, every length ratio inside the band.
/// Returns the smallest and largest length ratio.
pub(crate) fn check<T: Real>(
    w: &SoaState<T>,
    lo2: T,
    hi2: T,
) -> Result<(f64, f64), (usize, DivergedQuantity)> {
    let qsum = w.q[3].iter().fold(T::zero(), |a, &b| a + b);
    if !qsum.is_finite() {
        let j = w.q[3].iter().position(|x| !x.is_finite()).unwrap_or(0);
        return Err((j, DivergedQuantity::NonFiniteFrame));
    }
    let (mut lo, mut hi) = (T::lit(f64::MAX), T::zero());
    for (j, &r) in w.ratio2.iter().enumerate() {
        if !(r >= lo2 && r <= hi2) {
            if !r.is_finite() {
                return Err((j, DivergedQuantity::NonFinitePosition));
            }
            return Err((
                j,
                DivergedQuantity::Strain((r.sqrt() - T::one()).abs().to_f64()),
            ));
        }
        lo = lo.min(r);
        hi = hi.max(r);
    }
    Ok((lo.sqrt().to_f64(), hi.sqrt().to_f64()))
}

/// Advances many independent rods by one step, serially or in parallel; results are identical.
///
/// On a divergence, rods after the failing one (serial) may not have been advanced.
///
/// Returns each rod's stats, or the divergence of the lowest-numbered rod that diverged.
pub fn step_rods<T: Real>(
    rods: &mut [CpuRod<T>],
    settings: &SolverSettings<T>,
    time: f64,
    step: u64,
    par: Par,
    stats: &mut Vec<StepStats>,
) -> Result<(), Divergence> {
    step_rods_batch(rods, settings, time, step, 1, par, stats)
}

/// Advances many independent rods by `steps` steps each (see [`step_rod_batch`]).
pub fn step_rods_batch<T: Real>(
    rods: &mut [CpuRod<T>],
    settings: &SolverSettings<T>,
    time: f64,
    step: u64,
    steps: u64,
    par: Par,
    stats: &mut Vec<StepStats>,
) -> Result<(), Divergence> {
    step_each(rods, par, stats, |i, rod| {
        step_rod_batch(rod, settings, time, i, step, steps)
    })
}

/// Calls `step(i, &mut items[i])` for every item, serially or spread over rayon's pool, and
/// collects the statistics in item order. Serially it stops at the first divergence; on the
/// pool every item is stepped and the divergence of the lowest index is returned.
pub(crate) fn step_each<I: Send>(
    items: &mut [I],
    par: Par,
    stats: &mut Vec<StepStats>,
    step: impl Fn(usize, &mut I) -> Result<StepStats, Divergence> + Sync,
) -> Result<(), Divergence> {
    stats.clear();
    match par {
        #[cfg(feature = "rayon")]
        Par::Rayon => {
            use rayon::prelude::*;
            let results: Vec<_> = items
                .par_iter_mut()
                .enumerate()
                .map(|(i, item)| step(i, item))
                .collect();
            for r in results {
                stats.push(r?);
            }
        }
        _ => {
            for (i, item) in items.iter_mut().enumerate() {
                stats.push(step(i, item)?);
            }
        }
    }
    Ok(())
}
