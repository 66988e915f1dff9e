//! Rods that act on each other: bindings (a guidewire inside a catheter), rod–rod contact and
//! self-contact, solved together in one constraint loop.
//!
//! The paper (section 2.1, "Constraints"; section "Collisions and self-collisions"; sections
//! 3.4 and 3.5) solves distance, binding and contact constraints by local impulses in the same
//! iterations. Rods that do not interact are stepped independently ([`crate::step_rods_batch`],
//! each rod's whole batch in its own working layout); coupled rods cannot be, because a binding
//! or a contact between two rods needs both rods' current velocities in every iteration. So
//! [`step_coupled_batch`] steps a group of rods in lock step:
//!
//! 1. per rod: forces, velocity integration, end conditions, mesh-contact detection (the same
//!    code as a single rod);
//! 2. once: the coupling's detection — nearest outer-centreline point of every inner point of a
//!    binding ([`cosserat_constraints::BindingSet::update`]) and the bounding-sphere broad phase plus
//!    segment–segment narrow phase between and within rods ([`cosserat_collide::RodCollider`]);
//! 3. `iterations` times: each rod's distance sweep and mesh-contact sweep, then the binding
//!    sweeps, then the rod–rod contact sweep, the latter two reaching the rods' velocities
//!    through [`cosserat_constraints::PointVelocities`] in whatever layout the distance solver keeps
//!    them;
//! 4. per rod: reaction at held ends, position integration, divergence check.
//!
//! A simulation without bindings or rod contacts never enters this module.

use crate::reaction::Reactions;
use crate::stepper::{
    BatchConsts, CpuRod, Divergence, SolverSettings, StepStats, after_constraints,
    before_constraints, gauss_seidel_sweep, red_black_of, uses_red_black,
};
use cosserat_collide::{Chain, RodCollider, RodCollisionConfig, RodContact};
use cosserat_constraints::{
    BindingSet, BindingVariant, Friction, PointVelocities, RodContactSet, SegmentContact,
    SoaVelocities, SplitVelocities,
};
use cosserat_model::{Real, Vec3};
pub(crate) use cosserat_problem::CouplingStats;

/// A binding of an inner rod to an outer rod (paper section 3.4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BindingSpec {
    /// Index of the inner rod (the guidewire).
    pub inner: usize,
    /// Index of the outer rod (the catheter).
    pub outer: usize,
    /// v0 (none), v1 (one-way) or v2 (two-way).
    pub variant: BindingVariant,
    /// Inner points farther than this from the outer centreline are free [m]; `None` uses the
    /// outer rod's radius.
    pub capture: Option<f64>,
}

impl BindingSpec {
    /// Checks this spec (the `k`-th) against `rods` and returns its capture distance [m]: both
    /// rods exist and differ, and the capture distance (the outer rod's radius by default) is
    /// finite and positive.
    pub fn checked_capture<T: Real>(&self, k: usize, rods: &[CpuRod<T>]) -> Result<f64, String> {
        let n = rods.len();
        if self.inner >= n || self.outer >= n {
            return Err(format!(
                "binding {k}: rods {} and {} requested, the simulation has {n}",
                self.inner, self.outer
            ));
        }
        if self.inner == self.outer {
            return Err(format!("binding {k}: a rod cannot be bound to itself"));
        }
        let capture = self
            .capture
            .unwrap_or_else(|| rods[self.outer].params.radius.to_f64());
        if !(capture.is_finite() && capture > 0.0) {
            return Err(format!(
                "binding {k}: capture distance {capture} must be > 0"
            ));
        }
        Ok(capture)
    }
}

/// Contact between rods and of each rod with itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodContactSpec {
    /// Whether a rod collides with itself.
    pub self_collisions: bool,
    /// Coulomb friction between rods.
    pub friction: Friction<f64>,
    /// Speculative margin [m]: segments this close get a contact that stops them meeting
    /// within the step.
    pub margin: f64,
    /// Segments per broad-phase bounding sphere.
    pub segments_per_sphere: usize,
}

impl Default for RodContactSpec {
    fn default() -> Self {
        Self {
            self_collisions: true,
            friction: Friction {
                static_coefficient: 0.3,
                kinetic_coefficient: 0.2,
            },
            margin: 1e-4,
            segments_per_sphere: RodCollisionConfig::default().segments_per_sphere,
        }
    }
}

#[derive(Clone, Debug)]
struct Binding<T: Real> {
    inner: usize,
    outer: usize,
    set: BindingSet<T>,
}

#[derive(Clone, Debug)]
struct RodContacts<T: Real> {
    collider: RodCollider,
    friction: Friction<T>,
    margin: f64,
    /// Rod pairs that do not collide (bound to each other).
    excluded: Vec<(usize, usize)>,
    points: Vec<Vec<[f64; 3]>>,
    radii: Vec<f64>,
    found: Vec<RodContact>,
    set: RodContactSet<T>,
}

/// The coupling of a group of rods: its bindings and rod contacts with their scratch.
#[derive(Clone, Debug)]
pub struct Coupling<T: Real> {
    bindings: Vec<Binding<T>>,
    contacts: Option<RodContacts<T>>,
    /// Positions of rods taking part in a binding, as vectors, at step start.
    positions: Vec<Vec<Vec3<T>>>,
    stats: CouplingStats,
}

impl<T: Real> Coupling<T> {
    /// Checks the specs against the rods and prepares the scratch. Bindings of variant
    /// [`BindingVariant::None`] are kept (they cost nothing) so that the variants can be
    /// compared with the same setup.
    pub fn new(
        rods: &[CpuRod<T>],
        bindings: &[BindingSpec],
        contacts: Option<RodContactSpec>,
    ) -> Result<Self, String> {
        let mut out = Vec::new();
        for (k, b) in bindings.iter().enumerate() {
            let capture = b.checked_capture(k, rods)?;
            out.push(Binding {
                inner: b.inner,
                outer: b.outer,
                set: BindingSet::new(b.variant, T::lit(capture), rods[b.inner].elements() + 1),
            });
        }
        let contacts = contacts.map(|c| RodContacts {
            collider: RodCollider::new(RodCollisionConfig {
                segments_per_sphere: c.segments_per_sphere,
                self_collisions: c.self_collisions,
                ..RodCollisionConfig::default()
            }),
            friction: Friction {
                static_coefficient: T::lit(c.friction.static_coefficient),
                kinetic_coefficient: T::lit(c.friction.kinetic_coefficient),
            },
            margin: c.margin,
            excluded: bindings
                .iter()
                .filter(|b| b.variant != BindingVariant::None)
                .map(|b| (b.inner.min(b.outer), b.inner.max(b.outer)))
                .collect(),
            points: vec![Vec::new(); rods.len()],
            radii: rods.iter().map(|r| r.params.radius.to_f64()).collect(),
            found: Vec::new(),
            set: RodContactSet::new(),
        });
        Ok(Self {
            bindings: out,
            contacts,
            positions: vec![Vec::new(); rods.len()],
            stats: CouplingStats::default(),
        })
    }

    /// Whether anything couples the rods at all.
    pub fn is_active(&self) -> bool {
        self.contacts.is_some()
            || self
                .bindings
                .iter()
                .any(|b| b.set.variant != BindingVariant::None)
    }

    /// Measurements since the start.
    pub fn stats(&self) -> CouplingStats {
        self.stats
    }

    /// The rod contacts of the last step, if rod contact is on.
    pub fn rod_contacts(&self) -> Option<&RodContactSet<T>> {
        self.contacts.as_ref().map(|c| &c.set)
    }

    /// Number of points bound by binding `k` at the last step.
    pub fn bound_points(&self, k: usize) -> usize {
        self.bindings.get(k).map_or(0, |b| b.set.bound().len())
    }

    /// Detection at step start: bindings' nearest points and rod contacts.
    fn detect(&mut self, rods: &[CpuRod<T>]) {
        let t0 = std::time::Instant::now();
        let mut bound = 0;
        for b in &mut self.bindings {
            if b.set.variant == BindingVariant::None {
                continue;
            }
            for r in [b.inner, b.outer] {
                let w = &rods[r].work;
                let buf = &mut self.positions[r];
                buf.clear();
                buf.extend((0..w.r.x.len()).map(|i| w.r.get(i)));
            }
            b.set
                .update(&self.positions[b.inner], &self.positions[b.outer]);
            bound += b.set.bound().len();
        }
        self.stats.bound_points = bound;
        if let Some(c) = self.contacts.as_mut() {
            for (r, buf) in rods.iter().zip(&mut c.points) {
                let w = &r.work;
                buf.clear();
                buf.extend(
                    (0..w.r.x.len())
                        .map(|i| [w.r.x[i].to_f64(), w.r.y[i].to_f64(), w.r.z[i].to_f64()]),
                );
            }
            let half = 0.5 * c.margin;
            let chains: Vec<Chain<'_>> = c
                .points
                .iter()
                .zip(&c.radii)
                .map(|(p, &r)| Chain {
                    points: p,
                    radius: r + half,
                })
                .collect();
            c.collider.detect(&chains, &mut c.found);
            c.set.clear();
            for f in &c.found {
                let (a, b) = (f.chain_a as usize, f.chain_b as usize);
                if a != b && c.excluded.contains(&(a.min(b), a.max(b))) {
                    continue;
                }
                let radii = c.radii[a] + c.radii[b];
                if f.distance < self.stats.min_separation {
                    self.stats.min_separation = f.distance;
                    self.stats.min_separation_radii = radii;
                }
                self.stats.min_separation_ratio =
                    self.stats.min_separation_ratio.min(f.distance / radii);
                c.set.push(SegmentContact {
                    rod_a: f.chain_a,
                    segment_a: f.segment_a,
                    s: T::lit(f.s),
                    rod_b: f.chain_b,
                    segment_b: f.segment_b,
                    t: T::lit(f.t),
                    normal: Vec3::new(
                        T::lit(f.normal[0]),
                        T::lit(f.normal[1]),
                        T::lit(f.normal[2]),
                    ),
                    gap: T::lit(f.distance - radii),
                });
            }
            self.stats.contacts = c.set.len();
            self.stats.max_contacts = self.stats.max_contacts.max(c.set.len());
        }
        self.stats.steps += 1;
        self.stats.detection_seconds += t0.elapsed().as_secs_f64();
    }

    /// One sweep of the coupling constraints on the rods' current velocities.
    fn sweep(&mut self, rods: &mut [CpuRod<T>], h: T, red_black: bool) {
        let mut views: Vec<RodVelocities<'_, T>> =
            rods.iter_mut().map(|r| view(r, red_black)).collect();
        for b in &self.bindings {
            if let Ok([inner, outer]) = views.get_disjoint_mut([b.inner, b.outer]) {
                b.set.sweep(h, inner, outer);
            }
        }
        if let Some(c) = self.contacts.as_mut()
            && !c.set.is_empty()
        {
            c.set.sweep(h, &c.friction, &mut views);
        }
    }
}

/// A rod's velocities in the layout its distance solver keeps them in.
enum RodVelocities<'a, T: Real> {
    Split(SplitVelocities<'a, T>),
    Soa(SoaVelocities<'a, T>),
}

fn view<T: Real>(rod: &mut CpuRod<T>, red_black: bool) -> RodVelocities<'_, T> {
    let CpuRod {
        work,
        work_params,
        red_black: solver,
        kinematic,
        ..
    } = rod;
    match solver.as_mut() {
        Some(s) if red_black => RodVelocities::Split(s.velocities(kinematic)),
        _ => RodVelocities::Soa(SoaVelocities {
            v: [&mut work.v.x, &mut work.v.y, &mut work.v.z],
            inv_masses: &work_params.inv_masses,
            held: kinematic,
        }),
    }
}

impl<T: Real> PointVelocities<T> for RodVelocities<'_, T> {
    #[inline(always)]
    fn velocity(&self, i: usize) -> Vec3<T> {
        match self {
            Self::Split(v) => v.velocity(i),
            Self::Soa(v) => v.velocity(i),
        }
    }
    #[inline(always)]
    fn inv_mass(&self, i: usize) -> T {
        match self {
            Self::Split(v) => v.inv_mass(i),
            Self::Soa(v) => v.inv_mass(i),
        }
    }
    #[inline(always)]
    fn apply_impulse(&mut self, i: usize, j: Vec3<T>) {
        match self {
            Self::Split(v) => v.apply_impulse(i, j),
            Self::Soa(v) => v.apply_impulse(i, j),
        }
    }
}

/// Advances a group of coupled rods by `steps` steps in lock step (see the module docs).
///
/// `stats` receives one entry per rod. On a divergence the rods hold the diverged state; the
/// lowest-numbered diverged rod is reported.
pub fn step_coupled_batch<T: Real>(
    rods: &mut [CpuRod<T>],
    coupling: &mut Coupling<T>,
    settings: &SolverSettings<T>,
    time: f64,
    first_step: u64,
    steps: u64,
    stats: &mut Vec<StepStats>,
) -> Result<(), Divergence> {
    let h = settings.dt;
    let consts: Vec<BatchConsts<T>> = rods.iter().map(|r| BatchConsts::new(r, settings)).collect();
    stats.clear();
    stats.resize(
        rods.len(),
        StepStats {
            min_stretch: f64::MAX,
            max_stretch: 0.0,
        },
    );
    for r in rods.iter_mut() {
        r.work.gather(&r.state);
    }
    let red_black = uses_red_black(settings);
    let distance_on = !settings.extensible && settings.iterations > 0;
    // Coupling constraints get at least one sweep, also in extensible mode.
    let iterations = if settings.extensible {
        settings.iterations.max(1)
    } else {
        settings.iterations
    };
    let mut result = Ok(());
    'steps: for k in 0..steps {
        let t = time + k as f64 * h.to_f64();
        for (rod, c) in rods.iter_mut().zip(&consts) {
            before_constraints(rod, settings, c, t);
            rod.end_impulses = [Vec3::zeros(); 2];
        }
        coupling.detect(rods);
        if red_black {
            for rod in rods.iter_mut() {
                let CpuRod {
                    work,
                    work_params,
                    red_black: solver,
                    reaction,
                    ..
                } = rod;
                red_black_of(solver, work_params, reaction.as_deref()).begin_soa(
                    [&work.r.x, &work.r.y, &work.r.z],
                    [&work.v.x, &work.v.y, &work.v.z],
                );
            }
        }
        for _ in 0..iterations {
            for rod in rods.iter_mut() {
                sweep_rod(rod, settings, red_black, distance_on);
            }
            coupling.sweep(rods, h, red_black);
        }
        for (i, (rod, c)) in rods.iter_mut().zip(&consts).enumerate() {
            let distance = if red_black {
                let tracked = rod.reaction.is_some();
                let w = &mut rod.work;
                let solver = rod
                    .red_black
                    .as_mut()
                    .expect("created at the start of the step");
                solver.finish_soa([&mut w.v.x, &mut w.v.y, &mut w.v.z]);
                if tracked {
                    solver.take_end_impulses()
                } else {
                    [Vec3::zeros(); 2]
                }
            } else {
                rod.end_impulses
            };
            match after_constraints(rod, settings, c, distance) {
                Ok((lo, hi)) => {
                    let s = &mut stats[i];
                    s.min_stretch = s.min_stretch.min(lo);
                    s.max_stretch = s.max_stretch.max(hi);
                }
                Err((element, quantity)) => {
                    result = Err(Divergence {
                        rod: i,
                        element,
                        step: first_step + k,
                        quantity,
                    });
                    break 'steps;
                }
            }
        }
    }
    for r in rods.iter_mut() {
        r.work.scatter(&mut r.state);
    }
    result
}

/// One iteration of a rod's own constraints: its distance sweep and its mesh contacts.
#[inline]
fn sweep_rod<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    red_black: bool,
    distance_on: bool,
) {
    let h = settings.dt;
    let track = rod
        .reaction
        .as_deref()
        .map_or([false; 2], |r: &Reactions<T>| r.tracked());
    let CpuRod {
        work: w,
        work_params: p,
        red_black: solver,
        mesh,
        end_impulses,
        ..
    } = rod;
    let contacts = mesh
        .as_mut()
        .filter(|m| !m.contacts.is_empty())
        .map(|m| (&mut m.contacts, &m.friction));
    if red_black {
        let solver = solver.as_mut().expect("created at the start of the step");
        solver.sweep(h);
        if let Some((set, friction)) = contacts {
            solver.sweep_contacts(set, friction, h);
        }
        return;
    }
    if distance_on {
        gauss_seidel_sweep(
            [&w.r.x, &w.r.y, &w.r.z],
            [&mut w.v.x, &mut w.v.y, &mut w.v.z],
            &p.inv_masses,
            &p.rest_lengths,
            h,
            track,
            end_impulses,
        );
    }
    if let Some((set, friction)) = contacts {
        set.sweep_soa(
            h,
            friction,
            &p.inv_masses,
            [&mut w.v.x, &mut w.v.y, &mut w.v.z],
        );
    }
}
