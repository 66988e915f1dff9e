//! The convenient world: a [`Simulation`] that owns its rods, built with typed handles.
//!
//! Lower crates take their state as arguments (the model computes forces, the backend steps
//! arrays); this module owns that state for users who want to describe rods, press *step* and
//! read results. It picks the precision (`f32` or `f64`) and the backend at run time, so a
//! scene file or a command-line flag can choose them.

use crate::environment::Environment;
pub use backend_cpu::{BindingSpec, CouplingStats, EndReaction, RodContactSpec};
use backend_cpu::{
    CpuRod, Divergence, EndCondition, Guide, Ordering, Par, PointLoad, PrescribedMotion,
    SolverSettings, StepStats,
};
pub use constraints::BindingVariant;
use cosserat_model::energy::{Energies, ForceModel, energies};
use cosserat_model::quat::directors;
use cosserat_model::rod::{RestShape, RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Real, RodBuildError, Vec3};

/// Which backend steps the rods.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Backend {
    /// Serial CPU stepper (the reference).
    #[default]
    Cpu,
    /// CPU, rods stepped in parallel on rayon's pool.
    CpuRayon,
    /// GPU through wgpu (`f32`, many steps per dispatch); needs the `gpu` feature.
    Gpu,
}

impl Backend {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::CpuRayon => "cpu-rayon",
            Backend::Gpu => "gpu",
        }
    }
}

/// A handle to a rod of a [`Simulation`], returned when it is added.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RodHandle(pub usize);

/// Describes one rod before the simulation is built.
#[derive(Clone, Debug)]
#[must_use]
pub struct RodBuilder {
    points: Vec<[f64; 3]>,
    spec: RodSpec,
    ends: [EndCondition<f64>; 2],
    loads: Vec<(usize, [f64; 3])>,
    name: Option<String>,
    collides: bool,
    guide: Option<f64>,
}

impl RodBuilder {
    /// A straight rod of `elements` equal elements from `start` along `direction`.
    pub fn straight(
        start: [f64; 3],
        direction: [f64; 3],
        length: f64,
        elements: usize,
        material: Material,
    ) -> Self {
        Self::polyline(
            straight_polyline(start, direction, length, elements.max(1)),
            material,
        )
    }

    /// A rod through the given points, one element per segment.
    pub fn polyline(points: Vec<[f64; 3]>, material: Material) -> Self {
        Self {
            points,
            spec: RodSpec::new(material),
            ends: [EndCondition::free(); 2],
            loads: Vec::new(),
            name: None,
            collides: true,
            guide: None,
        }
    }

    /// Resamples the polyline by arc length into `n` equal elements. Fails with the index of a
    /// point that coincides with its predecessor.
    pub fn resampled(mut self, n: usize) -> Result<Self, usize> {
        let p: Vec<Vec3<f64>> = self.points.iter().map(|a| Vec3::from(*a)).collect();
        let mut cum = vec![0.0];
        for k in 1..p.len() {
            let l = (p[k] - p[k - 1]).norm();
            if !(l > 0.0) {
                return Err(k);
            }
            cum.push(cum[k - 1] + l);
        }
        let total = *cum.last().unwrap_or(&0.0);
        let mut seg = 0;
        self.points = (0..=n)
            .map(|i| {
                let s = total * i as f64 / n as f64;
                while seg + 2 < cum.len() && cum[seg + 1] < s {
                    seg += 1;
                }
                let t = ((s - cum[seg]) / (cum[seg + 1] - cum[seg])).clamp(0.0, 1.0);
                (p[seg] + (p[seg + 1] - p[seg]) * t).into()
            })
            .collect();
        Ok(self)
    }

    /// Unit tangents of the first and the last element.
    pub fn end_tangents(&self) -> ([f64; 3], [f64; 3]) {
        let p: Vec<Vec3<f64>> = self.points.iter().map(|a| Vec3::from(*a)).collect();
        let unit = |v: Vec3<f64>| {
            let n = v.norm();
            if n > 0.0 { (v / n).into() } else { [0.0; 3] }
        };
        match p.len() {
            0 | 1 => ([0.0; 3], [0.0; 3]),
            k => (unit(p[1] - p[0]), unit(p[k - 1] - p[k - 2])),
        }
    }

    /// Number of elements.
    pub fn element_count(&self) -> usize {
        self.points.len().saturating_sub(1)
    }

    /// Names the rod.
    pub fn name(mut self, name: impl Into<String>) -> Self {
        self.name = Some(name.into());
        self
    }

    /// Sets where the rest curvature and twist come from.
    pub fn rest_shape(mut self, shape: RestShape) -> Self {
        self.spec.rest_shape = shape;
        self
    }

    /// Overrides the parallel-constraint penalty `K_p` [N].
    pub fn parallel_stiffness(mut self, kp: f64) -> Self {
        self.spec.parallel_stiffness = Some(kp);
        self
    }

    /// Sets rotational [N m² s] and stretching [N s] internal damping and the drag rate [1/s].
    pub fn damping(mut self, bend: f64, stretch: f64, drag: f64) -> Self {
        self.spec.bend_damping = bend;
        self.spec.stretch_damping = stretch;
        self.spec.drag = drag;
        self
    }

    /// Direction the first frame's `d1` should point to.
    pub fn first_director(mut self, d: [f64; 3]) -> Self {
        self.spec.first_director_hint = d;
        self
    }

    /// Condition at the first point.
    pub fn start(mut self, c: EndCondition<f64>) -> Self {
        self.ends[0] = c;
        self
    }

    /// Condition at the last point.
    pub fn end(mut self, c: EndCondition<f64>) -> Self {
        self.ends[1] = c;
        self
    }

    /// Clamps the first point and frame in place.
    pub fn clamp_start(self) -> Self {
        self.start(EndCondition::clamped())
    }

    /// Pins the first point in place.
    pub fn pin_start(self) -> Self {
        self.start(EndCondition::pinned())
    }

    /// Whether the rod collides with the simulation's environment (default: yes).
    pub fn collides(mut self, yes: bool) -> Self {
        self.collides = yes;
        self
    }

    /// Feeds the rod through a straight, frictionless introducer of `length` [m] that starts at
    /// the first point and runs along the first element: the points inside it move only along
    /// its axis (see [`backend_cpu::guide`]). Use it with a pushed start to insert a wire
    /// through an entry point without the outside part buckling.
    pub fn guide(mut self, length: f64) -> Self {
        self.guide = Some(length);
        self
    }

    /// Adds a constant force [N] on point `point`.
    pub fn load(mut self, point: usize, force: [f64; 3]) -> Self {
        self.loads.push((point, force));
        self
    }

    fn build<T: Real>(
        &self,
        environment: Option<&Environment>,
    ) -> Result<CpuRod<T>, RodBuildError> {
        let (state, params) = build_rod::<T>(&self.points, &self.spec)?;
        let ends = self.ends.map(cast_end);
        let loads = self
            .loads
            .iter()
            .map(|&(point, f)| PointLoad {
                point,
                force: v3(f),
            })
            .collect();
        let mut rod = CpuRod::new(state, params, ends, loads);
        if let (Some(length), [a, b, ..]) = (self.guide, self.points.as_slice()) {
            let direction = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            if let Some(g) = Guide::new(*a, direction, length, self.spec.material.radius) {
                rod = rod.with_guide(g);
            }
        }
        Ok(match environment {
            Some(env) if self.collides => rod.with_mesh(env.contact_settings()),
            _ => rod,
        })
    }
}

fn v3<T: Real>(a: [f64; 3]) -> Vec3<T> {
    Vec3::new(T::lit(a[0]), T::lit(a[1]), T::lit(a[2]))
}

fn cast_end<T: Real>(e: EndCondition<f64>) -> EndCondition<T> {
    EndCondition {
        kind: e.kind,
        motion: e.motion.map(|m| PrescribedMotion {
            velocity: v3(m.velocity.into()),
            angular_velocity: v3(m.angular_velocity.into()),
            start_time: m.start_time,
            end_time: m.end_time,
        }),
    }
}

/// A simulation that could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// A rod's geometry or material is invalid.
    #[error("rod {rod}: {source}")]
    Rod {
        /// Index of the rod.
        rod: usize,
        /// What is wrong with it.
        source: RodBuildError,
    },
    /// A setting is invalid.
    #[error("{0}")]
    Setting(String),
    /// A point load names a point the rod does not have.
    #[error("rod {rod}: load on point {point}, but the rod has points 0..={last}")]
    LoadPoint {
        /// Index of the rod.
        rod: usize,
        /// Requested point.
        point: usize,
        /// Last valid point.
        last: usize,
    },
}

/// Describes a simulation before it is built.
#[derive(Clone, Debug)]
#[must_use]
pub struct SimulationBuilder {
    rods: Vec<RodBuilder>,
    settings: SolverSettings<f64>,
    double_precision: bool,
    backend: Backend,
    environment: Option<Environment>,
    /// Instruments bound inside each other (paper section 3.4).
    bindings: Vec<BindingSpec>,
    /// Rod–rod and self-contact, if on.
    rod_contact: Option<RodContactSpec>,
    /// The stiff solver (implicit bending, twisting and coupling), instead of the paper's
    /// explicit scheme.
    stiff: Option<backend_cpu::StiffSettings>,
    /// Speed at which a run is declared diverged [m/s].
    divergence_speed: f64,
    /// Whether `build` refuses an explicit time step beyond the estimated stable one.
    check_stability: bool,
    /// Exact (direct) instead of iterative distance constraints.
    direct_constraints: bool,
    /// Cut-off of the low-pass filter on end reactions [Hz]; `None`: the backend's default.
    reaction_cutoff_hz: Option<f64>,
}

impl Default for SimulationBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl SimulationBuilder {
    /// Defaults: `dt = 1e-4` s, 10 red–black sweeps, inextensible, gravity `−9.81 ẑ`, `f32`.
    pub fn new() -> Self {
        Self {
            rods: Vec::new(),
            settings: SolverSettings {
                dt: 1e-4,
                iterations: 10,
                ordering: Ordering::RedBlack,
                extensible: false,
                gravity: Vec3::new(0.0, 0.0, -9.81),
                divergence_strain: 0.5,
            },
            double_precision: false,
            backend: Backend::Cpu,
            environment: None,
            bindings: Vec::new(),
            rod_contact: None,
            reaction_cutoff_hz: None,
            stiff: None,
            divergence_speed: 1e3,
            check_stability: true,
            direct_constraints: false,
        }
    }

    /// Solves the inextensibility constraints exactly with the direct solver
    /// (`constraints::direct`, Newton iterations on the tridiagonal system) instead of the
    /// paper's iterative impulses; segment lengths then hold to ~1e-12 (f64) after every step.
    pub fn direct_constraints(mut self, yes: bool) -> Self {
        self.direct_constraints = yes;
        self
    }

    /// Whether [`SimulationBuilder::build`] refuses a time step beyond the stable step of the
    /// explicit scheme estimated from each rod's fastest mode (`cosserat_model::stability`;
    /// default on). Turn it off only to study instability on purpose.
    pub fn check_stability(mut self, yes: bool) -> Self {
        self.check_stability = yes;
        self
    }

    /// Uses the stiff solver (`docs/stiff-solver.md`) with these settings, or the paper's
    /// explicit scheme with `None` (the default). The stiff solver's stable time step does not
    /// depend on the material, so real guidewires run at haptic rates (1e-3 s).
    pub fn stiff_solver(mut self, settings: Option<backend_cpu::StiffSettings>) -> Self {
        self.stiff = settings;
        self
    }

    /// Binds rod `inner` inside rod `outer` (a guidewire in a catheter) with the given variant:
    /// the inner rod's points inside the outer rod are held on its centreline while they slide
    /// along it (see `constraints::binding`).
    pub fn bind(mut self, inner: RodHandle, outer: RodHandle, variant: BindingVariant) -> Self {
        self.bindings.push(BindingSpec {
            inner: inner.0,
            outer: outer.0,
            variant,
            capture: None,
        });
        self
    }

    /// Adds a binding described in full (indices of the rods, variant, capture distance).
    pub fn bind_with(mut self, spec: BindingSpec) -> Self {
        self.bindings.push(spec);
        self
    }

    /// Turns on rod–rod and self-contact with these settings.
    pub fn rod_contacts(mut self, spec: RodContactSpec) -> Self {
        self.rod_contact = Some(spec);
        self
    }

    /// Cut-off frequency [Hz] of the low-pass filter on the reported end reactions.
    pub fn reaction_cutoff_hz(mut self, hz: f64) -> Self {
        self.reaction_cutoff_hz = Some(hz);
        self
    }

    /// The static mesh the rods collide with.
    pub fn environment(mut self, env: Environment) -> Self {
        self.environment = Some(env);
        self
    }

    /// The environment, if one was set.
    pub fn environment_ref(&self) -> Option<&Environment> {
        self.environment.as_ref()
    }

    /// Time step [s].
    pub fn dt(mut self, dt: f64) -> Self {
        self.settings.dt = dt;
        self
    }
    /// Distance-constraint sweeps per step.
    pub fn iterations(mut self, n: usize) -> Self {
        self.settings.iterations = n;
        self
    }
    /// Extensible (stretch energy) instead of inextensible (distance constraints).
    pub fn extensible(mut self, yes: bool) -> Self {
        self.settings.extensible = yes;
        self
    }
    /// Order of each constraint sweep.
    pub fn ordering(mut self, o: Ordering) -> Self {
        self.settings.ordering = o;
        self
    }
    /// Gravity [m/s²].
    pub fn gravity(mut self, g: [f64; 3]) -> Self {
        self.settings.gravity = g.into();
        self
    }
    /// Runs in `f64` instead of `f32`.
    pub fn double_precision(mut self, yes: bool) -> Self {
        self.double_precision = yes;
        self
    }
    /// Strain at which a run is declared diverged.
    pub fn divergence_strain(mut self, s: f64) -> Self {
        self.settings.divergence_strain = s;
        self
    }
    /// Speed [m/s] at which a run is declared diverged (default 1000 m/s), checked after every
    /// call to [`Simulation::run`]: an explicit step past its stability limit can pump energy
    /// into a rod while its segment lengths still hold.
    pub fn divergence_speed(mut self, v: f64) -> Self {
        self.divergence_speed = v;
        self
    }
    /// The backend that steps the rods.
    pub fn backend(mut self, b: Backend) -> Self {
        self.backend = b;
        self
    }
    /// Adds a rod and returns its handle.
    pub fn add_rod(&mut self, rod: RodBuilder) -> RodHandle {
        self.rods.push(rod);
        RodHandle(self.rods.len() - 1)
    }
    /// Adds a rod, builder style.
    pub fn with_rod(mut self, rod: RodBuilder) -> Self {
        self.add_rod(rod);
        self
    }
    /// Time step of the simulation to be built.
    pub fn time_step(&self) -> f64 {
        self.settings.dt
    }

    /// Checks everything and builds the simulation.
    pub fn build(self) -> Result<Simulation, BuildError> {
        let s = &self.settings;
        if !(s.dt.is_finite() && s.dt > 0.0) {
            return Err(BuildError::Setting(format!(
                "dt = {} is invalid: expected a finite number > 0",
                s.dt
            )));
        }
        if self.rods.is_empty() {
            return Err(BuildError::Setting(
                "a simulation needs at least one rod".into(),
            ));
        }
        for (i, r) in self.rods.iter().enumerate() {
            if let Some(length) = r.guide {
                let rod_length: f64 = r
                    .points
                    .windows(2)
                    .map(|w| (Vec3::from(w[1]) - Vec3::from(w[0])).norm())
                    .sum();
                if !(length > 0.0 && length <= rod_length) {
                    return Err(BuildError::Setting(format!(
                        "rod {i}: guide length {length} m is invalid: expected a number > 0 and at most the rod's length ({rod_length} m)"
                    )));
                }
                if self.backend == Backend::Gpu {
                    return Err(BuildError::Setting(format!(
                        "rod {i}: a guide (introducer) runs on the CPU backends only"
                    )));
                }
            }
            for &(point, _) in &r.loads {
                if point > r.element_count() {
                    return Err(BuildError::LoadPoint {
                        rod: i,
                        point,
                        last: r.element_count(),
                    });
                }
            }
        }
        // The explicit scheme's stable step: refuse a step beyond the estimated critical one,
        // warn between the validated safe fraction of it and the estimate itself (measured
        // stable steps were 0.53–1.19 times the estimate, docs/stability.md).
        let mut warnings = Vec::new();
        if self.check_stability && self.stiff.is_none() {
            use cosserat_model::stability::{StabilityInput, UnstableStep, stable_step};
            for (i, r) in self.rods.iter().enumerate() {
                let limit = stable_step(&StabilityInput::for_rod(&r.spec, &r.points, s.extensible));
                let unstable = UnstableStep { dt: s.dt, limit };
                if s.dt > limit.critical_dt {
                    return Err(BuildError::Setting(format!(
                        "rod {i}: {unstable}; or solver.scheme = \"stiff\""
                    )));
                }
                if s.dt > limit.max_dt {
                    warnings.push(format!(
                        "rod {i}: dt = {:.3e} s is below the estimated critical step {:.3e} s but above the validated safe step {:.3e} s (rods with strong curvature and driven ends have diverged between the two)",
                        s.dt, limit.critical_dt, limit.max_dt
                    ));
                }
            }
        }
        let env = self.environment.as_ref();
        if let Some(hz) = self.reaction_cutoff_hz
            && !(hz > 0.0)
        {
            return Err(BuildError::Setting(format!(
                "reaction cut-off {hz} Hz is invalid: expected a number > 0"
            )));
        }
        let coupled = self.rod_contact.is_some() || !self.bindings.is_empty();
        if coupled && self.backend == Backend::Gpu {
            return Err(BuildError::Setting(
                "bindings and rod contacts run on the CPU backends only".into(),
            ));
        }
        if self.backend == Backend::Gpu && self.direct_constraints {
            return Err(BuildError::Setting(
                "the GPU backend solves constraints iteratively only: use --backend cpu for solver.constraint_solver = \"direct\"".into(),
            ));
        }
        if self.backend == Backend::Gpu && self.stiff.is_some() {
            return Err(BuildError::Setting(
                "the GPU backend runs the explicit scheme only: use --backend cpu for solver.scheme = \"stiff\"".into(),
            ));
        }
        let world = if self.backend == Backend::Gpu {
            gpu_world(
                Rods::build(&self.rods, &cast_settings(s), env)?,
                self.double_precision,
                env.is_some(),
            )?
        } else if self.double_precision {
            World::F64(
                Rods::build(&self.rods, s, env)?
                    .couple(&self)?
                    .stiffen(&self)?,
            )
        } else {
            World::F32(
                Rods::build(&self.rods, &cast_settings(s), env)?
                    .couple(&self)?
                    .stiffen(&self)?,
            )
        };
        Ok(Simulation {
            world,
            names: self
                .rods
                .iter()
                .enumerate()
                .map(|(i, r)| r.name.clone().unwrap_or_else(|| format!("rod{i}")))
                .collect(),
            radii: self.rods.iter().map(|r| r.spec.material.radius).collect(),
            backend: self.backend,
            dt: s.dt,
            time: 0.0,
            steps: 0,
            max_strain: 0.0,
            extensible: s.extensible,
            environment: self.environment,
            divergence_speed: self.divergence_speed,
            warnings,
        })
    }
}

fn cast_settings<T: Real>(s: &SolverSettings<f64>) -> SolverSettings<T> {
    SolverSettings {
        dt: T::lit(s.dt),
        iterations: s.iterations,
        ordering: s.ordering,
        extensible: s.extensible,
        gravity: v3(s.gravity.into()),
        divergence_strain: T::lit(s.divergence_strain),
    }
}

struct Rods<T: Real> {
    rods: Vec<CpuRod<T>>,
    settings: SolverSettings<T>,
    stats: Vec<StepStats>,
    /// Bindings and rod contacts; `None` steps the rods independently.
    coupling: Option<backend_cpu::Coupling<T>>,
    /// The stiff solver's settings and one scratch per rod, when it is used.
    stiff: Option<(backend_cpu::StiffSettings, Vec<backend_cpu::StiffScratch>)>,
    /// Bindings stepped with the stiff solver (which replaces `coupling` then).
    stiff_bindings: Option<backend_cpu::StiffBindings<T>>,
}

impl<T: Real> Rods<T> {
    fn build(
        rods: &[RodBuilder],
        settings: &SolverSettings<T>,
        env: Option<&Environment>,
    ) -> Result<Self, BuildError> {
        let rods = rods
            .iter()
            .enumerate()
            .map(|(i, r)| {
                r.build::<T>(env)
                    .map_err(|source| BuildError::Rod { rod: i, source })
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            rods,
            settings: *settings,
            stats: Vec::new(),
            coupling: None,
            stiff: None,
            stiff_bindings: None,
        })
    }

    /// Switches to the stiff solver, or to direct distance constraints, if the builder asks.
    fn stiffen(mut self, b: &SimulationBuilder) -> Result<Self, BuildError> {
        if b.direct_constraints {
            if self.coupling.is_some() {
                return Err(BuildError::Setting("the direct constraint solver does not handle bindings or rod contact yet: use solver.constraint_solver = \"iterative\"".into()));
            }
            self.rods = std::mem::take(&mut self.rods)
                .into_iter()
                .map(|r| r.with_direct_solver(constraints::direct::DirectSettings::default()))
                .collect();
        }
        if let Some(st) = b.stiff {
            if self.coupling.is_some() {
                if b.rod_contact.is_some() {
                    return Err(BuildError::Setting(
                        "the stiff solver does not handle rod–rod contact yet: use solver.scheme = \"explicit\"".into(),
                    ));
                }
                self.coupling = None;
                self.stiff_bindings = Some(
                    backend_cpu::StiffBindings::new(&self.rods, &b.bindings)
                        .map_err(BuildError::Setting)?,
                );
            }
            if st.scheme == backend_cpu::StiffScheme::GaussSeidel
                && st.integrator == backend_cpu::Integrator::Bdf2
            {
                return Err(BuildError::Setting(
                    "BDF2 runs with the stiff solver's direct variant only".into(),
                ));
            }
            if st.scheme == backend_cpu::StiffScheme::GaussSeidel
                && (b.environment.is_some() || b.rods.iter().any(|r| r.guide.is_some()))
            {
                return Err(BuildError::Setting(
                    "the stiff solver's Gauss–Seidel variant handles neither mesh contact nor guides: use the direct solver".into(),
                ));
            }
            // Sized and built now, so that the first step of a haptic loop costs what the
            // later ones do.
            let scratch = self
                .rods
                .iter()
                .map(|rod| {
                    let mut s = backend_cpu::StiffScratch::new();
                    s.prepare(rod, &self.settings, &st);
                    s
                })
                .collect();
            self.stiff = Some((st, scratch));
        }
        Ok(self)
    }

    /// Applies the builder's bindings, rod contacts and reaction filter.
    fn couple(mut self, b: &SimulationBuilder) -> Result<Self, BuildError> {
        if let Some(hz) = b.reaction_cutoff_hz {
            self.rods = std::mem::take(&mut self.rods)
                .into_iter()
                .map(|r| r.with_reaction_cutoff(hz))
                .collect();
        }
        if b.rod_contact.is_some() || !b.bindings.is_empty() {
            let c = backend_cpu::Coupling::new(&self.rods, &b.bindings, b.rod_contact)
                .map_err(BuildError::Setting)?;
            self.coupling = c.is_active().then_some(c);
        }
        Ok(self)
    }

    /// The stiff solver's reports of all rods together after `steps` steps.
    fn stiff_summary(&self, steps: u64) -> Option<StiffSummary> {
        let (settings, scratch) = self.stiff.as_ref()?;
        let mut s = StiffSummary {
            rod_steps: steps * scratch.len() as u64,
            max_tolerance: settings.tolerance,
            ..StiffSummary::default()
        };
        for r in scratch.iter().map(backend_cpu::StiffScratch::report) {
            s.iterations += r.total_iterations;
            s.factorisations += r.factorisations;
            s.steps_kept += r.steps;
            s.unconverged_steps += r.unconverged_steps;
            s.halved_steps += r.halved_steps;
            s.axial_steps += r.axial_steps;
            s.max_residual = s.max_residual.max(r.max_residual);
            s.max_tolerance = s.max_tolerance.max(r.max_tolerance);
        }
        Some(s)
    }

    /// Steps every rod `n` times on the CPU; returns the largest strain seen.
    fn run(&mut self, time: f64, step: u64, n: u64, par: Par) -> Result<f64, StepError> {
        let (rods, stats, settings) = (&mut self.rods, &mut self.stats, &self.settings);
        match (
            self.stiff.as_mut(),
            self.stiff_bindings.as_mut(),
            self.coupling.as_mut(),
        ) {
            (Some((st, scratch)), Some(bindings), _) => backend_cpu::step_bound_stiff(
                rods, scratch, bindings, settings, st, time, step, n, stats,
            )?,
            (Some((st, scratch)), None, _) => backend_cpu::step_rods_stiff(
                rods, scratch, settings, st, time, step, n, par, stats,
            )?,
            // Coupled rods are stepped together, serially.
            (None, _, Some(c)) => {
                backend_cpu::step_coupled_batch(rods, c, settings, time, step, n, stats)?
            }
            (None, _, None) => {
                backend_cpu::step_rods_batch(rods, settings, time, step, n, par, stats)?
            }
        }
        Ok(self
            .stats
            .iter()
            .map(StepStats::max_strain)
            .fold(0.0, f64::max))
    }
}

enum World {
    F32(Rods<f32>),
    F64(Rods<f64>),
    /// Rods on the GPU, with a CPU-side mirror of their state refreshed after every batch.
    #[cfg(feature = "gpu")]
    Gpu(Box<GpuWorld>),
}

/// Dispatches a generic expression over the precision of the world (reading the GPU world's
/// mirror).
macro_rules! with_rods {
    ($world:expr, $r:ident => $body:expr) => {
        match $world {
            World::F32($r) => $body,
            World::F64($r) => $body,
            #[cfg(feature = "gpu")]
            World::Gpu(g) => {
                let $r = &g.mirror;
                $body
            }
        }
    };
}

/// Why a step failed.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// A rod diverged.
    #[error("{0}")]
    Diverged(#[from] Divergence),
    /// The backend failed for a reason of its own (a GPU device error, a timeout).
    #[error("{0}")]
    Backend(String),
}

impl StepError {
    /// The divergence, if that is what happened.
    pub fn divergence(&self) -> Option<&Divergence> {
        match self {
            StepError::Diverged(d) => Some(d),
            StepError::Backend(_) => None,
        }
    }
}

#[cfg(feature = "gpu")]
struct GpuWorld {
    sim: backend_gpu::GpuSimulation,
    mirror: Rods<f32>,
}

#[cfg(feature = "gpu")]
impl GpuWorld {
    /// Runs `n` steps on the GPU, then refreshes the mirror. Returns the largest strain of the
    /// final state (the GPU checks every step for divergence itself).
    fn run(&mut self, n: u64) -> Result<f64, StepError> {
        let to_step = |e: backend_gpu::GpuError| match e {
            backend_gpu::GpuError::Diverged(d) => StepError::Diverged(d),
            other => StepError::Backend(other.to_string()),
        };
        let mut left = n;
        while left > 0 {
            let k = left.min(u64::from(u32::MAX)) as u32;
            self.sim.step(k).map_err(to_step)?;
            left -= u64::from(k);
        }
        // One round trip: the state and the divergence status come back together.
        let states = self.sim.read_state().map_err(to_step)?;
        let mut worst = 0.0f64;
        for (rod, state) in self.mirror.rods.iter_mut().zip(states) {
            let (lo, hi) = constraints::strain_extremes(&state.positions, &rod.params.rest_lengths);
            worst = worst.max(f64::from(hi) - 1.0).max(1.0 - f64::from(lo));
            rod.state = state;
        }
        Ok(worst)
    }
}

#[cfg(feature = "gpu")]
fn gpu_world(mirror: Rods<f32>, double: bool, environment: bool) -> Result<World, BuildError> {
    if double {
        return Err(BuildError::Setting(
            "the GPU backend runs in f32: set solver.precision = \"f32\" or use --backend cpu"
                .into(),
        ));
    }
    if environment {
        return Err(BuildError::Setting("the GPU backend does not collide with meshes yet: use --backend cpu for scenes with an [environment]".into()));
    }
    let inputs = mirror
        .rods
        .iter()
        .map(|r| backend_gpu::GpuRodInput {
            state: r.state.clone(),
            params: r.params.clone(),
            ends: r.ends,
            loads: r.loads.clone(),
        })
        .collect();
    let sim = backend_gpu::GpuSimulation::new(
        inputs,
        &mirror.settings,
        backend_gpu::GpuOptions::default(),
    )
    .map_err(|e| BuildError::Setting(e.to_string()))?;
    Ok(World::Gpu(Box::new(GpuWorld { sim, mirror })))
}

#[cfg(not(feature = "gpu"))]
fn gpu_world(_: Rods<f32>, _: bool, _: bool) -> Result<World, BuildError> {
    Err(BuildError::Setting(
        "this build has no GPU backend: rebuild with the `gpu` feature, or use --backend cpu"
            .into(),
    ))
}

/// A running simulation: rods, their state and the clock.
pub struct Simulation {
    world: World,
    names: Vec<String>,
    radii: Vec<f64>,
    backend: Backend,
    dt: f64,
    time: f64,
    steps: u64,
    max_strain: f64,
    extensible: bool,
    environment: Option<Environment>,
    divergence_speed: f64,
    warnings: Vec<String>,
}

/// Contact measurements of a whole simulation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactReport {
    /// Largest penetration of any point into the mesh at the start of any step [m].
    pub max_penetration: f64,
    /// Points outside the lumen: the most seen at the start of any step, or found by a full
    /// search of the current state, whichever is larger.
    pub escaped_points: usize,
    /// Points in contact at the last step.
    pub contacts: usize,
    /// Mean wall time of collision detection per step [µs], all rods together.
    pub detection_us_per_step: f64,
}

/// What the stiff solver did since the simulation was built, over all rods
/// (`backend_cpu::StiffReport` summed).
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
}

impl StiffSummary {
    /// Newton iterations per rod-step (0 before the first step).
    pub fn iterations_per_step(&self) -> f64 {
        self.iterations as f64 / self.rod_steps.max(1) as f64
    }

    /// Factorisations per rod-step (0 before the first step).
    pub fn factorisations_per_step(&self) -> f64 {
        self.factorisations as f64 / self.rod_steps.max(1) as f64
    }
}

impl Simulation {
    /// Advances every rod by one time step.
    pub fn step(&mut self) -> Result<(), StepError> {
        self.run(1)
    }

    /// Advances `n` steps, stopping at the first divergence (the state is then the diverged one
    /// and [`Simulation::steps`] counts the steps completed before it).
    ///
    /// The steps are taken in one batch per rod, so a long run costs less per step than single
    /// calls to [`Simulation::step`].
    pub fn run(&mut self, n: u64) -> Result<(), StepError> {
        if n == 0 {
            return Ok(());
        }
        let par = if self.backend == Backend::CpuRayon {
            Par::Rayon
        } else {
            Par::Serial
        };
        let (time, step) = (self.time, self.steps);
        let result: Result<f64, StepError> = match &mut self.world {
            World::F32(w) => w.run(time, step, n, par),
            World::F64(w) => w.run(time, step, n, par),
            #[cfg(feature = "gpu")]
            World::Gpu(g) => g.run(n),
        };
        match &result {
            Ok(worst) => {
                self.max_strain = self.max_strain.max(*worst);
                self.steps += n;
                self.time = self.steps as f64 * self.dt;
                return self.check_speed();
            }
            Err(e) => {
                if let Some(d) = e.divergence() {
                    self.steps = d.step;
                }
            }
        }
        self.time = self.steps as f64 * self.dt;
        result.map(|_| ())
    }

    /// The filtered reaction at end `end` (0: first point, 1: last point) of a rod after the
    /// last step: the force and torque the holder applies to the rod (a haptic device renders
    /// its negative); `None` for a free end, and on the GPU backend, whose kernels do not
    /// compute reactions (its CPU-side mirror of the rods would report zeros). See
    /// `backend_cpu::reaction`.
    pub fn end_reaction(&self, h: RodHandle, end: usize) -> Option<EndReaction> {
        if self.backend == Backend::Gpu {
            return None;
        }
        with_rods!(&self.world, w => w.rods[h.0].end_reaction(end))
    }

    /// Largest filtered reaction force at any held end of any rod so far [N]; `None` when no
    /// end is held, and on the GPU backend ([`end_reaction`](Self::end_reaction)).
    pub fn max_reaction_force(&self) -> Option<f64> {
        if self.backend == Backend::Gpu {
            return None;
        }
        with_rods!(&self.world, w => w.rods.iter().filter_map(|r| r.max_reaction_force()).reduce(f64::max))
    }

    /// Measurements of bindings and rod contacts; `None` when the rods do not interact.
    pub fn coupling_stats(&self) -> Option<CouplingStats> {
        with_rods!(&self.world, w => w
            .coupling
            .as_ref()
            .map(|c| c.stats())
            .or_else(|| w.stiff_bindings.as_ref().map(|b| b.stats())))
    }

    /// The runaway-energy check: the first point of any rod faster than the divergence speed,
    /// or the first frame whose surface (at the rod's radius) spins faster than it. Twisting is
    /// usually the fastest mode, so a frame can spin away while the centreline still looks fine.
    fn check_speed(&self) -> Result<(), StepError> {
        let limit = self.divergence_speed;
        let step = self.steps;
        with_rods!(&self.world, w => {
            for (rod, r) in w.rods.iter().enumerate() {
                let radius = r.params.radius;
                let points = r.state.velocities.iter().map(|v| v.norm());
                let frames = r.state.angular_velocities.iter().map(|w| w.norm() * radius);
                for (element, speed) in points.chain(frames).enumerate() {
                    let element = element % r.state.velocities.len();
                    let speed = speed.to_f64();
                    if !(speed <= limit) {
                        let quantity = if speed.is_finite() {
                            backend_cpu::DivergedQuantity::Speed(speed)
                        } else {
                            backend_cpu::DivergedQuantity::NonFinitePosition
                        };
                        return Err(StepError::Diverged(Divergence { rod, element, step, quantity }));
                    }
                }
            }
            Ok(())
        })
    }

    /// Things the builder accepted but a user should know (a time step close to the stability
    /// limit).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Simulated time [s].
    pub fn time(&self) -> f64 {
        self.time
    }
    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }
    /// Time step [s].
    pub fn dt(&self) -> f64 {
        self.dt
    }
    /// The backend stepping the rods.
    pub fn backend(&self) -> Backend {
        self.backend
    }
    /// Whether the rods are extensible.
    pub fn is_extensible(&self) -> bool {
        self.extensible
    }
    /// Whether the simulation runs in `f64`.
    pub fn is_double_precision(&self) -> bool {
        matches!(self.world, World::F64(_))
    }
    /// Handles of all rods.
    pub fn rods(&self) -> impl Iterator<Item = RodHandle> {
        (0..self.names.len()).map(RodHandle)
    }
    /// A rod's name.
    pub fn rod_name(&self, h: RodHandle) -> &str {
        &self.names[h.0]
    }
    /// A rod's radius [m].
    pub fn rod_radius(&self, h: RodHandle) -> f64 {
        self.radii[h.0]
    }
    /// Total number of elements of all rods.
    pub fn element_count(&self) -> usize {
        with_rods!(&self.world, w => w.rods.iter().map(|r| r.elements()).sum())
    }
    /// Largest `|l/l0 − 1|` of any segment at the end of any step so far.
    pub fn max_strain(&self) -> f64 {
        self.max_strain
    }

    /// What the stiff solver did so far: iterations, steps that ended above the tolerance,
    /// steps retaken in halves or with axial compliance; `None` with the explicit scheme.
    pub fn stiff_summary(&self) -> Option<StiffSummary> {
        let steps = self.steps;
        match &self.world {
            World::F32(r) => r.stiff_summary(steps),
            World::F64(r) => r.stiff_summary(steps),
            #[cfg(feature = "gpu")]
            World::Gpu(_) => None,
        }
    }

    /// Centreline points of a rod [m].
    pub fn positions(&self, h: RodHandle) -> Vec<[f64; 3]> {
        with_rods!(&self.world, w => w.rods[h.0].state.positions.iter().map(|p| [p.x.to_f64(), p.y.to_f64(), p.z.to_f64()]).collect())
    }

    /// Point velocities of a rod [m/s].
    pub fn velocities(&self, h: RodHandle) -> Vec<[f64; 3]> {
        with_rods!(&self.world, w => w.rods[h.0].state.velocities.iter().map(|p| [p.x.to_f64(), p.y.to_f64(), p.z.to_f64()]).collect())
    }

    /// The first director `d1` of each element of a rod.
    pub fn first_directors(&self, h: RodHandle) -> Vec<[f64; 3]> {
        with_rods!(&self.world, w => w.rods[h.0].state.frames.iter().map(|q| { let d = directors(q)[0]; [d.x.to_f64(), d.y.to_f64(), d.z.to_f64()] }).collect())
    }

    /// The environment, if the rods collide with one.
    pub fn environment(&self) -> Option<&Environment> {
        self.environment.as_ref()
    }

    /// Contact measurements since the start, or `None` without an environment.
    pub fn contact_report(&self) -> Option<ContactReport> {
        let env = self.environment.as_ref()?;
        let mut report = ContactReport::default();
        let mut seconds = 0.0;
        let mut steps = 0;
        with_rods!(&self.world, w => {
            for r in &w.rods {
                if let Some(st) = r.collision_stats() {
                    report.max_penetration = report.max_penetration.max(st.max_penetration);
                    report.escaped_points += st.escaped_points;
                    report.contacts += st.contacts;
                    seconds += st.detection_seconds;
                    steps = steps.max(st.steps);
                }
            }
        });
        let now: usize = self
            .rods()
            .map(|h| env.escaped(&self.positions(h), 1.0))
            .sum();
        report.escaped_points = report.escaped_points.max(now);
        report.detection_us_per_step = if steps > 0 {
            seconds * 1e6 / steps as f64
        } else {
            0.0
        };
        Some(report)
    }

    /// Energies summed over all rods.
    pub fn energies(&self) -> Energies {
        with_rods!(&self.world, w => {
            let model = ForceModel { extensible: w.settings.extensible, gravity: w.settings.gravity };
            w.rods.iter().map(|r| energies(&r.state, &r.params, &model)).fold(Energies::default(), |a, b| Energies {
                bend_twist: a.bend_twist + b.bend_twist,
                parallel: a.parallel + b.parallel,
                stretch: a.stretch + b.stretch,
                gravity: a.gravity + b.gravity,
                kinetic_translation: a.kinetic_translation + b.kinetic_translation,
                kinetic_rotation: a.kinetic_rotation + b.kinetic_rotation,
            })
        })
    }
}
