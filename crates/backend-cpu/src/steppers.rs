//! The CPU's ways of stepping, each a [`Stepper`]: the explicit scheme, rods coupled by
//! bindings or rod contact, the stiff scheme, and bound rods with the stiff scheme.
//!
//! They share everything but the step itself: the rods, the settings, the clock, the control
//! calls, reading and writing state, snapshots. So there is one type, [`CpuStepper`], generic
//! over the precision and over a [`Scheme`] that owns what only its way of stepping needs
//! (the coupling, the stiff solver's scratch) and takes the steps. Rayon is a [`Par`] value
//! given to the stepper, not a stepper of its own.

use cosserat_model::energy::{Energies, ForceModel, energies};
use cosserat_model::{Quat, Real, Vec3};
use cosserat_problem::divergence::first_too_fast;
use cosserat_problem::ends::cast_vec;
use cosserat_problem::stepper::{
    check_capabilities, check_condition, check_end, check_loads, check_rod, check_write,
    condition_needs, read_state_field, read_state_frames, unit_frames,
};
use cosserat_problem::{
    Capabilities, Capability, Clock, CollisionStats, ContactSample, ControlError, CouplingStats,
    Divergence, EndCondition, EndPath, EndReaction, Par, PointLoad, Snapshot, SolverSettings,
    StateField, StepError, StepStats, Stepper, StepperInfo, StiffSettings, StiffSummary,
};

use crate::coupling::{Coupling, step_coupled_batch};
use crate::stepper::{CpuRod, step_rods_batch};
use crate::stiff::{StiffBindings, StiffScratch, step_bound_stiff, step_rods_stiff};

/// How a [`CpuStepper`] takes its steps, and what that needs besides the rods.
pub trait Scheme<T: Real>: Clone + Send + Sync + 'static {
    /// The stepper's name in reports.
    const NAME: &'static str;

    /// What a stepper with this scheme can do (in `f64`; `f32` steppers lack
    /// [`Capability::DoublePrecision`]).
    fn capabilities() -> Capabilities;

    /// Takes `steps` steps of all rods from `clock`, filling `stats` with one entry per rod.
    fn advance(
        &mut self,
        rods: &mut [CpuRod<T>],
        settings: &SolverSettings<T>,
        clock: Clock,
        steps: u64,
        par: Par,
        stats: &mut Vec<StepStats>,
    ) -> Result<(), Divergence>;

    /// What the stiff solver did over `steps` steps (stiff schemes only).
    fn stiff_summary(&self, _steps: u64) -> Option<StiffSummary> {
        None
    }

    /// Measurements of the coupling (coupled schemes only).
    fn coupling_stats(&self) -> Option<CouplingStats> {
        None
    }

    /// Whether an end may change between free, pinned and clamped while the rods are stepped.
    /// Coupled schemes keep per-rod data built from how the ends were held, so they refuse it.
    fn allows_kind_changes(&self) -> bool {
        true
    }

    /// The mesh's forces on rod `rod`'s points at the last step, when this scheme keeps them
    /// itself (the stiff schemes); `None`: they are the rod's explicit contact set.
    fn contact_forces(&self, _rod: usize, _out: &mut Vec<ContactSample>) -> Option<()> {
        None
    }
}

/// What every CPU scheme can do: mesh contact, several obstacles (moving ones too), the guide,
/// reactions at held ends, `f64`, held ends along keyframed paths.
fn cpu_base() -> Capabilities {
    Capabilities::of(&[
        Capability::MeshContact,
        Capability::Guide,
        Capability::Reactions,
        Capability::DoublePrecision,
        Capability::EndPaths,
        Capability::VaryingLoads,
        Capability::Obstacles,
        Capability::MovingObstacles,
    ])
}

/// The paper's explicit scheme, each rod on its own (serially or spread over rayon's pool).
#[derive(Clone, Debug, Default)]
pub struct Explicit;

impl<T: Real> Scheme<T> for Explicit {
    const NAME: &'static str = "cpu explicit";

    fn capabilities() -> Capabilities {
        cpu_base()
            .with(Capability::DirectConstraints)
            .with(Capability::SlidingEnds)
            .with(Capability::HingedEnds)
            .with(Capability::Moments)
    }

    fn advance(
        &mut self,
        rods: &mut [CpuRod<T>],
        settings: &SolverSettings<T>,
        clock: Clock,
        steps: u64,
        par: Par,
        stats: &mut Vec<StepStats>,
    ) -> Result<(), Divergence> {
        step_rods_batch(rods, settings, clock.time(), clock.step, steps, par, stats)
    }
}

/// The explicit scheme with rods that act on each other (bindings, rod–rod and self-contact),
/// stepped in lock step ([`step_coupled_batch`]).
#[derive(Clone, Debug)]
pub struct Coupled<T: Real>(pub Coupling<T>);

impl<T: Real> Scheme<T> for Coupled<T> {
    const NAME: &'static str = "cpu coupled";

    fn capabilities() -> Capabilities {
        cpu_base()
            .with(Capability::Bindings)
            .with(Capability::RodContact)
            .with(Capability::SlidingEnds)
            .with(Capability::HingedEnds)
            .with(Capability::Moments)
    }

    fn advance(
        &mut self,
        rods: &mut [CpuRod<T>],
        settings: &SolverSettings<T>,
        clock: Clock,
        steps: u64,
        _par: Par,
        stats: &mut Vec<StepStats>,
    ) -> Result<(), Divergence> {
        step_coupled_batch(
            rods,
            &mut self.0,
            settings,
            clock.time(),
            clock.step,
            steps,
            stats,
        )
    }

    fn coupling_stats(&self) -> Option<CouplingStats> {
        Some(self.0.stats())
    }

    fn allows_kind_changes(&self) -> bool {
        false
    }
}

/// The stiff scheme, each rod on its own with its own scratch.
#[derive(Clone, Debug)]
pub struct Stiff {
    /// The scheme's settings.
    pub settings: StiffSettings,
    /// One scratch per rod.
    pub scratch: Vec<StiffScratch>,
}

impl<T: Real> Scheme<T> for Stiff {
    const NAME: &'static str = "cpu stiff";

    fn capabilities() -> Capabilities {
        cpu_base()
            .with(Capability::StiffScheme)
            .with(Capability::Moments)
            .with(Capability::SlidingEnds)
    }

    fn advance(
        &mut self,
        rods: &mut [CpuRod<T>],
        settings: &SolverSettings<T>,
        clock: Clock,
        steps: u64,
        par: Par,
        stats: &mut Vec<StepStats>,
    ) -> Result<(), Divergence> {
        step_rods_stiff(
            rods,
            &mut self.scratch,
            settings,
            &self.settings,
            clock.time(),
            clock.step,
            steps,
            par,
            stats,
        )
    }

    fn stiff_summary(&self, steps: u64) -> Option<StiffSummary> {
        Some(summarise(&self.settings, &self.scratch, steps))
    }

    fn contact_forces(&self, rod: usize, out: &mut Vec<ContactSample>) -> Option<()> {
        out.extend(
            self.scratch
                .get(rod)?
                .contact_forces()
                .map(|(point, normal, force)| ContactSample {
                    point,
                    normal,
                    force,
                }),
        );
        Some(())
    }
}

/// The stiff scheme with rods bound inside each other, stepped one after the other
/// ([`step_bound_stiff`]).
#[derive(Clone, Debug)]
pub struct BoundStiff<T: Real> {
    /// The stiff scheme and its scratch.
    pub stiff: Stiff,
    /// The bindings.
    pub bindings: StiffBindings<T>,
}

impl<T: Real> Scheme<T> for BoundStiff<T> {
    const NAME: &'static str = "cpu stiff bound";

    /// The stiff scheme's, bindings, and rod–rod and self-contact.
    fn capabilities() -> Capabilities {
        <Stiff as Scheme<T>>::capabilities()
            .with(Capability::Bindings)
            .with(Capability::RodContact)
    }

    fn advance(
        &mut self,
        rods: &mut [CpuRod<T>],
        settings: &SolverSettings<T>,
        clock: Clock,
        steps: u64,
        _par: Par,
        stats: &mut Vec<StepStats>,
    ) -> Result<(), Divergence> {
        step_bound_stiff(
            rods,
            &mut self.stiff.scratch,
            &mut self.bindings,
            settings,
            &self.stiff.settings,
            clock.time(),
            clock.step,
            steps,
            stats,
        )
    }

    fn stiff_summary(&self, steps: u64) -> Option<StiffSummary> {
        Some(summarise(&self.stiff.settings, &self.stiff.scratch, steps))
    }

    fn contact_forces(&self, rod: usize, out: &mut Vec<ContactSample>) -> Option<()> {
        <Stiff as Scheme<T>>::contact_forces(&self.stiff, rod, out)
    }

    fn coupling_stats(&self) -> Option<CouplingStats> {
        Some(self.bindings.stats())
    }

    fn allows_kind_changes(&self) -> bool {
        false
    }
}

/// The stiff solver's reports of all rods together after `steps` steps.
fn summarise(settings: &StiffSettings, scratch: &[StiffScratch], steps: u64) -> StiffSummary {
    StiffSummary::of_reports(
        scratch.iter().map(StiffScratch::report),
        steps,
        settings.tolerance,
    )
}

/// The explicit scheme's stepper.
pub type ExplicitStepper<T> = CpuStepper<T, Explicit>;
/// The stepper of coupled rods (explicit scheme).
pub type CoupledStepper<T> = CpuStepper<T, Coupled<T>>;
/// The stiff scheme's stepper.
pub type StiffStepper<T> = CpuStepper<T, Stiff>;
/// The stepper of bound rods with the stiff scheme.
pub type BoundStiffStepper<T> = CpuStepper<T, BoundStiff<T>>;

/// Rods stepped on the CPU with the scheme `S`, in precision `T`.
#[derive(Clone, Debug)]
pub struct CpuStepper<T: Real, S: Scheme<T>> {
    rods: Vec<CpuRod<T>>,
    settings: SolverSettings<T>,
    clock: Clock,
    par: Par,
    stats: Vec<StepStats>,
    scheme: S,
}

/// What a CPU stepper's snapshot holds: all of it.
type CpuSnapshot<T, S> = CpuStepper<T, S>;

impl<T: Real> CpuStepper<T, Explicit> {
    /// The explicit scheme over `rods`.
    pub fn explicit(rods: Vec<CpuRod<T>>, settings: SolverSettings<T>, par: Par) -> Self {
        Self::with_scheme(rods, settings, par, Explicit)
    }
}

impl<T: Real> CpuStepper<T, Stiff> {
    /// The stiff scheme over `rods`, its scratch sized and built now so that the first step of
    /// a haptic loop costs what the later ones do.
    pub fn stiff(
        rods: Vec<CpuRod<T>>,
        settings: SolverSettings<T>,
        stiff: StiffSettings,
        par: Par,
    ) -> Self {
        let scratch = prepared_scratch(&rods, &settings, &stiff);
        Self::with_scheme(
            rods,
            settings,
            par,
            Stiff {
                settings: stiff,
                scratch,
            },
        )
    }
}

impl<T: Real> CpuStepper<T, BoundStiff<T>> {
    /// Bound rods with the stiff scheme (`bindings` built from `rods`).
    pub fn bound_stiff(
        rods: Vec<CpuRod<T>>,
        settings: SolverSettings<T>,
        stiff: StiffSettings,
        bindings: StiffBindings<T>,
    ) -> Self {
        let scratch = prepared_scratch(&rods, &settings, &stiff);
        Self::with_scheme(
            rods,
            settings,
            Par::Serial,
            BoundStiff {
                stiff: Stiff {
                    settings: stiff,
                    scratch,
                },
                bindings,
            },
        )
    }
}

fn prepared_scratch<T: Real>(
    rods: &[CpuRod<T>],
    settings: &SolverSettings<T>,
    stiff: &StiffSettings,
) -> Vec<StiffScratch> {
    rods.iter()
        .map(|rod| {
            let mut s = StiffScratch::new();
            s.prepare(rod, settings, stiff);
            s
        })
        .collect()
}

impl<T: Real, S: Scheme<T>> CpuStepper<T, S> {
    /// `rods` stepped with `scheme`.
    pub fn with_scheme(
        rods: Vec<CpuRod<T>>,
        settings: SolverSettings<T>,
        par: Par,
        scheme: S,
    ) -> Self {
        Self {
            clock: Clock::start(settings.dt.to_f64()),
            rods,
            settings,
            par,
            stats: Vec::new(),
            scheme,
        }
    }

    /// The rods.
    pub fn rods(&self) -> &[CpuRod<T>] {
        &self.rods
    }

    /// The settings.
    pub fn settings(&self) -> &SolverSettings<T> {
        &self.settings
    }

    /// The scheme and what it owns.
    pub fn scheme(&self) -> &S {
        &self.scheme
    }

    fn rod(&self, rod: usize) -> Result<&CpuRod<T>, ControlError> {
        check_rod(rod, self.rods.len())?;
        Ok(&self.rods[rod])
    }

    fn rod_mut(&mut self, rod: usize) -> Result<&mut CpuRod<T>, ControlError> {
        check_rod(rod, self.rods.len())?;
        Ok(&mut self.rods[rod])
    }
}

fn in3<T: Real>(a: &[f64; 3]) -> Vec3<T> {
    Vec3::new(T::lit(a[0]), T::lit(a[1]), T::lit(a[2]))
}

impl<T: Real, S: Scheme<T>> Stepper for CpuStepper<T, S> {
    fn info(&self) -> StepperInfo {
        StepperInfo {
            name: S::NAME,
            double_precision: T::lit(1.0 + 1e-12) != T::one(),
        }
    }

    fn capabilities(&self) -> Capabilities {
        let all = S::capabilities();
        if self.info().double_precision {
            all
        } else {
            Capability::ALL
                .into_iter()
                .filter(|&c| c != Capability::DoublePrecision && all.contains(c))
                .fold(Capabilities::NONE, Capabilities::with)
        }
    }

    fn clock(&self) -> Clock {
        self.clock
    }

    fn advance(&mut self, steps: u64) -> Result<f64, StepError> {
        if steps == 0 {
            return Ok(0.0);
        }
        let result = self.scheme.advance(
            &mut self.rods,
            &self.settings,
            self.clock,
            steps,
            self.par,
            &mut self.stats,
        );
        match result {
            Ok(()) => {
                self.clock = self.clock.advanced(steps);
                Ok(self
                    .stats
                    .iter()
                    .map(StepStats::max_strain)
                    .fold(0.0, f64::max))
            }
            Err(d) => {
                self.clock.step = d.step;
                Err(StepError::Diverged(d))
            }
        }
    }

    fn rod_count(&self) -> usize {
        self.rods.len()
    }

    fn elements(&self, rod: usize) -> Result<usize, ControlError> {
        Ok(self.rod(rod)?.elements())
    }

    fn read(
        &self,
        rod: usize,
        field: StateField,
        out: &mut [[f64; 3]],
    ) -> Result<(), ControlError> {
        read_state_field(&self.rod(rod)?.state, field, out)
    }

    fn read_frames(&self, rod: usize, out: &mut [[f64; 4]]) -> Result<(), ControlError> {
        read_state_frames(&self.rod(rod)?.state, out)
    }

    fn write(
        &mut self,
        rod: usize,
        field: StateField,
        values: &[[f64; 3]],
    ) -> Result<(), ControlError> {
        let r = self.rod_mut(rod)?;
        check_write(field, r.elements(), values)?;
        let s = &mut r.state;
        let target = match field {
            StateField::Positions => &mut s.positions,
            StateField::Velocities => &mut s.velocities,
            _ => &mut s.angular_velocities,
        };
        target.iter_mut().zip(values).for_each(|(t, v)| *t = in3(v));
        Ok(())
    }

    fn write_frames(&mut self, rod: usize, values: &[[f64; 4]]) -> Result<(), ControlError> {
        let r = self.rod_mut(rod)?;
        let frames = unit_frames(r.elements(), values)?;
        for (t, q) in r.state.frames.iter_mut().zip(frames) {
            *t = Quat::new(T::lit(q[0]), T::lit(q[1]), T::lit(q[2]), T::lit(q[3]));
        }
        // A clamp closes on the written end frame, as a held point follows a written position.
        for end in 0..2 {
            if r.ends[end].holds_frame() {
                r.state.seat_clamp(&r.params, end);
            }
        }
        Ok(())
    }

    fn end_condition(&self, rod: usize, end: usize) -> Result<EndCondition<f64>, ControlError> {
        check_end(end)?;
        Ok(self.rod(rod)?.ends[end].cast())
    }

    fn set_end_condition(
        &mut self,
        rod: usize,
        end: usize,
        condition: EndCondition<f64>,
    ) -> Result<(), ControlError> {
        check_end(end)?;
        check_condition(&condition)?;
        check_capabilities(
            S::NAME,
            S::capabilities(),
            condition_needs(&condition),
            "drive an end with",
        )?;
        let allows = self.scheme.allows_kind_changes();
        let r = self.rod_mut(rod)?;
        if r.ends[end].kind != condition.kind && !allows {
            return Err(ControlError::Unsupported {
                stepper: S::NAME,
                what: format!(
                    "change how an end is held ({:?} to {:?}) while rods are coupled; change its motion instead",
                    r.ends[end].kind, condition.kind
                ),
            });
        }
        r.set_end_condition(end, condition.cast());
        Ok(())
    }

    fn set_loads(&mut self, rod: usize, loads: &[PointLoad<f64>]) -> Result<(), ControlError> {
        let r = self.rod_mut(rod)?;
        check_loads(S::NAME, S::capabilities(), rod, r.elements(), loads)?;
        r.loads.clear();
        r.loads.extend(loads.iter().map(PointLoad::cast));
        Ok(())
    }

    fn end_reaction(&self, rod: usize, end: usize) -> Option<EndReaction> {
        self.rods.get(rod)?.end_reaction(end.min(1))
    }

    fn max_reaction_force(&self) -> Option<f64> {
        self.rods
            .iter()
            .filter_map(CpuRod::max_reaction_force)
            .reduce(f64::max)
    }

    fn contacts(&self, rod: usize, out: &mut Vec<ContactSample>) -> Result<(), ControlError> {
        let r = self.rod(rod)?;
        out.clear();
        if self.scheme.contact_forces(rod, out).is_some() {
            return Ok(());
        }
        let Some(set) = r.contacts() else {
            return Ok(());
        };
        let h = self.settings.dt.to_f64();
        for ((c, pn), pt) in set
            .contacts()
            .zip(set.normal_impulses())
            .zip(set.tangent_impulses())
        {
            // The set keeps its impulses as velocity changes: times the point's mass, over the
            // step, they are the force.
            let point = c.point as usize;
            let normal: Vec3<f64> = cast_vec(&c.normal);
            let dv = normal * pn.to_f64() + cast_vec::<T, f64>(&pt);
            let mass = r.params.masses[point].to_f64();
            out.push(ContactSample {
                point,
                normal: normal.into(),
                force: (dv * (mass / h)).into(),
            });
        }
        Ok(())
    }

    fn collision_stats(&self, rod: usize) -> Option<CollisionStats> {
        self.rods.get(rod)?.collision_stats()
    }

    fn coupling_stats(&self) -> Option<CouplingStats> {
        self.scheme.coupling_stats()
    }

    fn stiff_summary(&self) -> Option<StiffSummary> {
        self.scheme.stiff_summary(self.clock.step)
    }

    fn energies(&self) -> Energies {
        self.rods
            .iter()
            .map(|r| {
                let model = ForceModel {
                    extensible: self.settings.extensible,
                    gravity: self.settings.gravity,
                    clamped: r.ends.each_ref().map(|e| e.holds_frame()),
                };
                energies(&r.state, &r.params, &model)
            })
            .fold(Energies::default(), Energies::sum)
    }

    fn check_speed(&self, limit: f64) -> Result<(), Divergence> {
        first_too_fast(
            self.rods.iter().map(|r| (&r.state, r.params.radius)),
            limit,
            self.clock.step,
        )
    }

    fn snapshot(&mut self) -> Result<Snapshot, StepError> {
        Ok(Snapshot::new(
            S::NAME,
            self.clock,
            Box::new(CpuSnapshot::<T, S>::clone(self)),
        ))
    }

    fn set_obstacle_path(
        &mut self,
        shape: usize,
        path: Option<EndPath>,
    ) -> Result<(), ControlError> {
        let now = self.clock.time();
        let mut found = false;
        for r in &mut self.rods {
            if let Some(m) = r.mesh.as_mut() {
                found |= m.set_shape_path(shape, path.clone(), now);
            }
        }
        if found {
            Ok(())
        } else {
            Err(ControlError::Unsupported {
                stepper: S::NAME,
                what: format!("move obstacle shape {shape}: no rod touches such a shape"),
            })
        }
    }

    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), ControlError> {
        let Some(saved) = snapshot.data::<CpuSnapshot<T, S>>() else {
            return Err(ControlError::Snapshot(format!(
                "it was taken by the {} stepper, this is the {} stepper in {}",
                snapshot.stepper(),
                S::NAME,
                if self.info().double_precision {
                    "f64"
                } else {
                    "f32"
                }
            )));
        };
        let same_rods = saved.rods.len() == self.rods.len()
            && saved
                .rods
                .iter()
                .zip(&self.rods)
                .all(|(a, b)| a.elements() == b.elements());
        if !same_rods {
            return Err(ControlError::Snapshot(
                "it holds other rods than this simulation".into(),
            ));
        }
        self.clone_from(saved);
        Ok(())
    }
}
