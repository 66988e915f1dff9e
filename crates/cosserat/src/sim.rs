//! The convenient world: a [`Simulation`] that owns its rods, built with typed handles.
//!
//! Lower crates take their state as arguments (the model computes forces, the backend steps
//! arrays); this module owns that state for users who want to describe rods, press *step* and
//! read results. It picks the precision (`f32` or `f64`) and the backend at run time, so a
//! scene file or a command-line flag can choose them.

use crate::energy_watch::EnergyWatch;
use crate::environment::{Environment, Outside};
use crate::obstacles::Obstacle;
use cosserat_backend_cpu::MeshContactSettings;
pub use cosserat_backend_cpu::{BindingSpec, RodContactSpec};
use cosserat_backend_cpu::{CpuRod, CpuStepper, Guide};
pub use cosserat_constraints::BindingVariant;
use cosserat_model::energy::Energies;
use cosserat_model::rod::{RestShape, RodSpec, build_rod_with_rest_lengths, straight_polyline};
use cosserat_model::{Material, Quat, Real, RodBuildError, Vec3};
pub use cosserat_problem::{
    Capabilities, Capability, ContactSample, ControlError, CouplingStats, EndCondition, EndKind,
    EndReaction, Gpus, Integrator, Ordering, Par, PointLoad, PrescribedMotion, SolverSettings,
    StateField, StepError, Stepper, StepperInfo, StiffScheme, StiffSettings, StiffSummary,
};
use cosserat_problem::{EndPath, Snapshot};

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
    loads: Vec<PointLoad<f64>>,
    /// Loads per unit length (force [N/m] and moment [N m/m] as a [`PointLoad`] whose point is
    /// unused), lumped onto the points when the rod is built.
    distributed: Vec<PointLoad<f64>>,
    name: Option<String>,
    collides: bool,
    guide: Option<f64>,
    rest_lengths: Option<Vec<f64>>,
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
            ends: [EndCondition::free(), EndCondition::free()],
            loads: Vec::new(),
            distributed: Vec::new(),
            name: None,
            collides: true,
            guide: None,
            rest_lengths: None,
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
    /// its axis (see [`cosserat_backend_cpu::guide`]). Use it with a pushed start to insert a wire
    /// through an entry point without the outside part buckling.
    pub fn guide(mut self, length: f64) -> Self {
        self.guide = Some(length);
        self
    }

    /// Builds the rod stretched by `strain` over its rest length (rest lengths are the built
    /// lengths over `1 + strain`; `cosserat_model::rod::RodSpec::pre_strain`).
    pub fn pre_strain(mut self, strain: f64) -> Self {
        self.spec.pre_strain = strain;
        self
    }

    /// The rest length of every element (one per element of the rod as it is built), for a
    /// rod that starts strained unevenly; see
    /// `cosserat_model::rod::build_rod_with_rest_lengths`.
    pub fn rest_lengths(mut self, lengths: Vec<f64>) -> Self {
        self.rest_lengths = Some(lengths);
        self
    }

    /// The length of the polyline the rod is built along [m].
    pub fn built_length(&self) -> f64 {
        self.points
            .windows(2)
            .map(|w| {
                (0..3)
                    .map(|k| (w[1][k] - w[0][k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum()
    }

    /// Adds a constant force [N] on point `point`.
    pub fn load(mut self, point: usize, force: [f64; 3]) -> Self {
        self.loads.push(PointLoad::new(point, force.into()));
        self
    }

    /// Adds a load: a force and a moment on a point, constant or varying in time
    /// ([`PointLoad`], [`cosserat_problem::LoadProfile`]).
    pub fn load_with(mut self, load: PointLoad<f64>) -> Self {
        self.loads.push(load);
        self
    }

    /// Adds a load spread along the whole rod: `per_length`'s force [N/m] and moment [N m/m]
    /// (its `point` is not used) and profile. When the rod is built it becomes one point load per
    /// point, of the load per length times the point's share of the rod (half of each element
    /// beside it), so that it follows `--elements`.
    pub fn distributed_load(mut self, per_length: PointLoad<f64>) -> Self {
        self.distributed.push(per_length);
        self
    }

    /// The point loads and the distributed loads lumped onto the points.
    fn point_loads(&self) -> Vec<PointLoad<f64>> {
        let n = self.points.len().saturating_sub(1);
        let segment = |j: usize| -> f64 {
            (0..3)
                .map(|k| (self.points[j + 1][k] - self.points[j][k]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let mut out = self.loads.clone();
        for d in &self.distributed {
            for i in 0..=n {
                let share = 0.5
                    * (i.checked_sub(1).map_or(0.0, segment)
                        + if i < n { segment(i) } else { 0.0 });
                out.push(PointLoad {
                    point: i,
                    force: d.force * share,
                    moment: d.moment * share,
                    profile: d.profile.clone(),
                });
            }
        }
        out
    }

    fn build<T: Real>(
        &self,
        contact: Option<&MeshContactSettings>,
    ) -> Result<CpuRod<T>, RodBuildError> {
        let (state, params) = build_rod_with_rest_lengths::<T>(
            &self.points,
            &self.spec,
            self.rest_lengths.as_deref(),
        )?;
        let ends = self.ends.each_ref().map(|e| e.cast());
        let loads = self.point_loads().iter().map(PointLoad::cast).collect();
        let mut rod = CpuRod::new(state, params, ends, loads);
        if let (Some(length), [a, b, ..]) = (self.guide, self.points.as_slice()) {
            let direction = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            if let Some(g) = Guide::new(*a, direction, length, self.spec.material.radius) {
                rod = rod.with_guide(g);
            }
        }
        Ok(match contact {
            Some(c) if self.collides => rod.with_mesh(c.clone()),
            _ => rod,
        })
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
    /// Obstacles besides the environment ([`SimulationBuilder::obstacle`]).
    obstacles: Vec<Obstacle>,
    /// Instruments bound inside each other (paper section 3.4).
    bindings: Vec<BindingSpec>,
    /// Rod–rod and self-contact, if on.
    rod_contact: Option<RodContactSpec>,
    /// The stiff solver (implicit bending, twisting and coupling), instead of the paper's
    /// explicit scheme.
    stiff: Option<StiffSettings>,
    /// Speed at which a run is declared diverged [m/s].
    divergence_speed: f64,
    /// Whether `build` refuses an explicit time step beyond the estimated stable one.
    check_stability: bool,
    stability_safety: f64,
    /// Exact (direct) instead of iterative distance constraints.
    direct_constraints: bool,
    /// Cut-off of the low-pass filter on end reactions [Hz]; `None`: the backend's default.
    reaction_cutoff_hz: Option<f64>,
    /// The largest force at a held end, as a multiple of the rod's `E A`.
    reaction_limit: f64,
    /// Whether a run whose energy grows beyond the work done on it stops as diverged.
    energy_check: bool,
    /// Independent copies of the rods (and their bindings) stepped together; 1: the scene as
    /// given.
    copies: usize,
    /// The GPUs the GPU backend spreads the rods over.
    gpus: Gpus,
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
            settings: SolverSettings::default(),
            double_precision: false,
            backend: Backend::Cpu,
            environment: None,
            obstacles: Vec::new(),
            bindings: Vec::new(),
            rod_contact: None,
            reaction_cutoff_hz: None,
            stiff: None,
            divergence_speed: 1e3,
            check_stability: true,
            stability_safety: cosserat_model::stability::SAFETY,
            direct_constraints: false,
            reaction_limit: 1000.0,
            energy_check: true,
            copies: 1,
            gpus: Gpus::default(),
        }
    }

    /// The largest force a held end may take before the run is stopped as diverged, as a
    /// multiple of the rod's `E A` (default 1000). `E A` would stretch a real rod to twice its
    /// length; an inextensible rod driven hard can see forces above it for a step (a hand
    /// jerked at 100 m/s), but a thousand times it only comes from a step that blew up (the
    /// reactions of 1e20 N seen in real anatomy).
    pub fn reaction_limit(mut self, multiple_of_ea: f64) -> Self {
        self.reaction_limit = multiple_of_ea;
        self
    }

    /// Whether a run of the explicit scheme whose total energy grows beyond the work its loads
    /// and driven ends could have done stops as diverged (default: yes; `crate::energy_watch`
    /// says how it is checked, every 64 steps, and why the stiff scheme is not).
    pub fn energy_check(mut self, yes: bool) -> Self {
        self.energy_check = yes;
        self
    }

    /// Solves the inextensibility constraints exactly with the direct solver
    /// (`cosserat_constraints::direct`, Newton iterations on the tridiagonal system) instead of the
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

    /// The fraction of the explicit scheme's estimated critical step below which a step is
    /// accepted without a warning (default [`cosserat_model::stability::SAFETY`], 0.9; in
    /// `(0, 1]`). Every rod of the measured map (straight, curved and twisted rods released
    /// straight, driven clamps, spinning frames) was stable to at least 0.99 of the estimate
    /// (`docs/stability.md`); the default leaves a margin for contacts and bindings, which the
    /// map does not contain. A step above the estimate itself is refused whatever this is.
    pub fn stability_safety(mut self, fraction: f64) -> Self {
        self.stability_safety = fraction;
        self
    }

    /// Uses the stiff solver (`docs/stiff-solver.md`) with these settings, or the paper's
    /// explicit scheme with `None` (the default). The stiff solver's stable time step does not
    /// depend on the material, so real guidewires run at haptic rates (1e-3 s).
    pub fn stiff_solver(mut self, settings: Option<StiffSettings>) -> Self {
        self.stiff = settings;
        self
    }

    /// Binds rod `inner` inside rod `outer` (a guidewire in a catheter) with the given variant:
    /// the inner rod's points inside the outer rod are held on its centreline while they slide
    /// along it (see `cosserat_constraints::binding`).
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

    /// One more obstacle the rods collide with, besides the environment and the obstacles
    /// added before: a mesh, a half-space or an infinite cylinder, each with its own friction
    /// and side, a shape possibly moving along a path (`crate::obstacles`).
    pub fn obstacle(mut self, obstacle: Obstacle) -> Self {
        self.obstacles.push(obstacle);
        self
    }

    /// The obstacles added with [`Self::obstacle`].
    pub fn obstacles_ref(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// Everything the rods collide with: the environment first, then the obstacles.
    fn all_obstacles(&self) -> Vec<Obstacle> {
        self.environment
            .iter()
            .cloned()
            .map(Obstacle::mesh)
            .chain(self.obstacles.iter().cloned())
            .collect()
    }

    /// What every colliding rod touches: the environment's own settings when it is alone (so
    /// a scene of one mesh steps as it always did), else all obstacles joined
    /// (`crate::obstacles`); `None` without any.
    fn contact_settings(&self) -> Result<Option<MeshContactSettings>, BuildError> {
        if self.obstacles.is_empty() {
            return Ok(self.environment.as_ref().map(Environment::contact_settings));
        }
        let margin = self.environment.as_ref().map_or(1e-4, |e| e.margin);
        let all = self.all_obstacles();
        crate::obstacles::contact_settings(&all.iter().collect::<Vec<_>>(), margin)
            .map_err(BuildError::Setting)
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
        let this = self.expand_copies()?;
        this.build_expanded()
    }

    /// Steps `n` independent copies of the scene's rods (with their bindings, ends, loads and
    /// guides) together, sharing the environment: copy `c` holds rods `c · k .. (c + 1) · k` of
    /// the `k` the scene describes, and every report is per rod, so per copy. On the GPU the
    /// copies are one dispatch (one workgroup each); on the CPU with rayon they are stepped in
    /// parallel. Copies never touch each other, so rod–rod contact is refused with more than
    /// one copy. `n` = 0 is refused when the simulation is built.
    pub fn copies(mut self, n: usize) -> Self {
        self.copies = n;
        self
    }

    /// Spreads the rods over several GPUs (GPU backend; the other backends ignore it): each
    /// device steps a contiguous share of the rods, balanced by their points, with no round trip
    /// between devices during a batch of steps. Meant for batches ([`Self::copies`]): the GPU
    /// couples no rods, so any split steps each rod as one device would.
    pub fn gpus(mut self, gpus: Gpus) -> Self {
        self.gpus = gpus;
        self
    }

    /// This builder with its copies laid out as rods and bindings.
    fn expand_copies(mut self) -> Result<Self, BuildError> {
        let n = self.copies;
        if n == 0 {
            return Err(BuildError::Setting(
                "batch.copies = 0: a batch needs at least one copy".into(),
            ));
        }
        if n == 1 {
            return Ok(self);
        }
        if self.rod_contact.is_some() {
            return Err(BuildError::Setting(format!(
                "batch.copies = {n} with rod contact: copies are independent and share one space, so their rods would touch each other; use one copy per simulation"
            )));
        }
        let k = self.rods.len();
        let rods = std::mem::take(&mut self.rods);
        self.rods = (0..n).flat_map(|_| rods.iter().cloned()).collect();
        let bindings = std::mem::take(&mut self.bindings);
        self.bindings = (0..n)
            .flat_map(|c| {
                bindings.iter().map(move |b| BindingSpec {
                    inner: b.inner + c * k,
                    outer: b.outer + c * k,
                    ..*b
                })
            })
            .collect();
        self.copies = 1;
        Ok(self)
    }

    fn build_expanded(self) -> Result<Simulation, BuildError> {
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
        // A simulation that cannot fit is refused here, with the numbers, instead of being
        // killed by the kernel half-way through building.
        if let Some(available) = available_memory() {
            let needed = self.memory_estimate();
            if needed > available {
                let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
                return Err(BuildError::Setting(format!(
                    "the simulation needs about {:.1} GiB ({} elements, {} scheme, {}), but this machine has {:.1} GiB available: use fewer elements{}",
                    gib(needed),
                    self.rods
                        .iter()
                        .map(RodBuilder::element_count)
                        .sum::<usize>(),
                    if self.stiff.is_some() {
                        "stiff"
                    } else {
                        "explicit"
                    },
                    if self.double_precision { "f64" } else { "f32" },
                    gib(available),
                    if self.stiff.is_some() {
                        " or the explicit scheme"
                    } else {
                        ""
                    }
                )));
            }
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
            }
            for &PointLoad { point, .. } in &r.loads {
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
        // stable steps were 0.99–2.0 times the estimate, docs/stability.md).
        let mut warnings = Vec::new();
        let safety = self.stability_safety;
        if !(safety > 0.0 && safety <= 1.0) {
            return Err(BuildError::Setting(format!(
                "stability safety {safety} is invalid: expected a fraction in (0, 1] of the \
                 estimated critical step"
            )));
        }
        if self.check_stability && self.stiff.is_none() {
            use cosserat_model::stability::{StabilityInput, UnstableStep, stable_step};
            for (i, r) in self.rods.iter().enumerate() {
                let mut limit =
                    stable_step(&StabilityInput::for_rod(&r.spec, &r.points, s.extensible));
                limit.max_dt = safety * limit.critical_dt;
                let unstable = UnstableStep { dt: s.dt, limit };
                if s.dt > limit.critical_dt {
                    return Err(BuildError::Setting(format!(
                        "rod {i}: {unstable}; or solver.scheme = \"stiff\""
                    )));
                }
                if s.dt > limit.max_dt {
                    warnings.push(format!(
                        "rod {i}: dt = {:.3e} s is below the estimated critical step {:.3e} s but above {safety} of it, {:.3e} s (the margin kept for contacts and bindings; solver.stability_safety sets the fraction)",
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
        if let Some(st) = self.stiff {
            if st.scheme == StiffScheme::GaussSeidel && st.integrator == Integrator::Bdf2 {
                return Err(BuildError::Setting(
                    "BDF2 runs with the stiff solver's direct variant only".into(),
                ));
            }
            if st.scheme == StiffScheme::GaussSeidel
                && (env.is_some()
                    || !self.obstacles.is_empty()
                    || self.rods.iter().any(|r| r.guide.is_some()))
            {
                return Err(BuildError::Setting(
                    "the stiff solver's Gauss–Seidel variant handles neither mesh contact nor guides: use the direct solver".into(),
                ));
            }
        }
        if let Some(env) = &self.environment {
            warnings.extend(env.intake.iter().cloned());
            warnings.extend(env.entry_problem());
        }
        if self.backend == Backend::Gpu
            && self.stiff.is_some_and(|st| st.contact_rows)
            && (self.environment.is_some() || !self.obstacles.is_empty())
        {
            warnings.push(
                "the GPU's stiff scheme resolves mesh contacts as pins (solver.stiff.contact_rows = false); contact rows run on the CPU"
                    .into(),
            );
        }
        let needs = self.needs();
        let stepper = match self.backend {
            Backend::Gpu => gpu_stepper(&self, needs)?,
            Backend::Cpu | Backend::CpuRayon if self.double_precision => {
                cpu_stepper::<f64>(&self, needs)?
            }
            Backend::Cpu | Backend::CpuRayon => cpu_stepper::<f32>(&self, needs)?,
        };
        Ok(Simulation {
            stepper,
            names: self
                .rods
                .iter()
                .enumerate()
                .map(|(i, r)| r.name.clone().unwrap_or_else(|| format!("rod{i}")))
                .collect(),
            radii: self.rods.iter().map(|r| r.spec.material.radius).collect(),
            reaction_bounds: self
                .rods
                .iter()
                .map(|r| self.reaction_limit * r.spec.material.stretch_stiffness())
                .collect(),
            backend: self.backend,
            max_strain: 0.0,
            extensible: s.extensible,
            obstacles: self.all_obstacles(),
            stop_outside: self.environment.as_ref().is_none_or(|e| e.stop_outside),
            environment: self.environment,
            divergence_speed: self.divergence_speed,
            warnings,
            scratch: Vec::new(),
            collides: self.rods.iter().map(|r| r.collides).collect(),
            loads: self.rods.iter().map(RodBuilder::point_loads).collect(),
            // The stiff scheme is not watched, nor a scene with moving obstacles
            // (`crate::energy_watch` says why).
            energy: EnergyWatch::new(
                self.energy_check
                    && self.stiff.is_none()
                    && self.obstacles.iter().all(|o| o.path().is_none()),
                self.rods
                    .iter()
                    .map(|r| {
                        let length = r.built_length();
                        let m = &r.spec.material;
                        (
                            m.density * std::f64::consts::PI * m.radius * m.radius * length,
                            length,
                        )
                    })
                    .collect(),
            ),
            outside: (0, 0.0),
            rest_lengths: self
                .rods
                .iter()
                .map(|r| {
                    build_rod_with_rest_lengths::<f64>(
                        &r.points,
                        &r.spec,
                        r.rest_lengths.as_deref(),
                    )
                    .map(|(_, params)| params.rest_lengths)
                    .unwrap_or_default()
                })
                .collect(),
        })
    }

    /// Memory the simulation will take [bytes], estimated from its elements: per element, about
    /// 350 B for the explicit scheme in `f32` and 700 B in `f64`, and 2.8 kB more for the stiff
    /// scheme (maximum resident sizes of `cosserat run` measured at 10⁵–10⁶ elements, with a
    /// quarter added), plus 16 MiB. Meshes are not counted (they are built before).
    pub fn memory_estimate(&self) -> u64 {
        let elements: u64 = self.rods.iter().map(|r| r.element_count() as u64).sum();
        let explicit = if self.double_precision { 700 } else { 350 };
        let stiff = if self.stiff.is_some() { 2800 } else { 0 };
        (elements * (explicit + stiff)) * 5 / 4 + (16 << 20)
    }

    /// Whether the obstacles are more than one mesh of one friction (what every backend with
    /// mesh contact runs).
    fn needs_obstacles(&self) -> bool {
        let all = self.all_obstacles();
        let shapes = all
            .iter()
            .any(|o| matches!(o.geometry(), crate::obstacles::Geometry::Shape(_)));
        shapes || all.len() > 1
    }

    /// What the scene asks of its stepper.
    fn needs(&self) -> Capabilities {
        // Reactions are not a need: a stepper without them runs held ends and reports no force
        // (`Simulation::end_reaction` is `None`).
        Capabilities::NONE
            .with_if(
                Capability::MeshContact,
                (self.environment.is_some() || !self.obstacles.is_empty())
                    && self.rods.iter().any(|r| r.collides),
            )
            .with_if(Capability::Obstacles, self.needs_obstacles())
            .with_if(
                Capability::MovingObstacles,
                self.obstacles.iter().any(|o| o.path().is_some()),
            )
            .with_if(
                Capability::Guide,
                self.rods.iter().any(|r| r.guide.is_some()),
            )
            .with_if(Capability::Bindings, !self.bindings.is_empty())
            .with_if(Capability::RodContact, self.rod_contact.is_some())
            .with_if(Capability::StiffScheme, self.stiff.is_some())
            .with_if(Capability::DirectConstraints, self.direct_constraints)
            .with_if(Capability::DoublePrecision, self.double_precision)
            .union(
                self.rods
                    .iter()
                    .map(|r| PointLoad::needs(&r.point_loads()))
                    .fold(Capabilities::NONE, Capabilities::union),
            )
            .union(
                self.rods
                    .iter()
                    .flat_map(|r| &r.ends)
                    .map(cosserat_problem::stepper::condition_needs)
                    .fold(Capabilities::NONE, Capabilities::union),
            )
    }
}

/// The one place where a scene's needs meet a stepper's capabilities: everything missing, in
/// one error, with what to change.
fn require(
    stepper: &str,
    has: Capabilities,
    needs: Capabilities,
    instead: &str,
) -> Result<(), BuildError> {
    let missing = has.missing(needs);
    if missing.is_empty() {
        return Ok(());
    }
    let list: Vec<&str> = missing.iter().map(|c| c.describe()).collect();
    Err(BuildError::Setting(format!(
        "the {stepper} stepper cannot run this scene: it lacks {}; {instead}",
        list.join(", ")
    )))
}

/// The rods of the builder in precision `T`, with their guides, meshes, reaction filters and
/// constraint solvers.
fn cpu_rods<T: Real>(b: &SimulationBuilder) -> Result<Vec<CpuRod<T>>, BuildError> {
    let contact = b.contact_settings()?;
    b.rods
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let mut rod = r
                .build::<T>(contact.as_ref())
                .map_err(|source| BuildError::Rod { rod: i, source })?;
            if let Some(hz) = b.reaction_cutoff_hz {
                rod = rod.with_reaction_cutoff(hz);
            }
            if b.direct_constraints {
                rod =
                    rod.with_direct_solver(cosserat_constraints::direct::DirectSettings::default());
            }
            Ok(rod)
        })
        .collect()
}

/// The CPU stepper the scene needs: the stiff scheme (bound or not) or the explicit one
/// (coupled or not).
fn cpu_stepper<T: Real>(
    b: &SimulationBuilder,
    needs: Capabilities,
) -> Result<Box<dyn Stepper>, BuildError> {
    use cosserat_backend_cpu::{BoundStiff, Coupled, Explicit, Scheme, Stiff};
    let settings: SolverSettings<T> = b.settings.cast();
    let par = if b.backend == Backend::CpuRayon {
        Par::Rayon
    } else {
        Par::Serial
    };
    let needs = needs.with_if(Capability::DoublePrecision, false);
    let rods = cpu_rods::<T>(b)?;
    let coupled = b.rod_contact.is_some() || !b.bindings.is_empty();
    let to_explicit = "use solver.scheme = \"explicit\"";
    Ok(match (b.stiff, coupled) {
        (Some(st), true) => {
            require(
                <BoundStiff<T> as Scheme<T>>::NAME,
                <BoundStiff<T> as Scheme<T>>::capabilities(),
                needs,
                to_explicit,
            )?;
            let bindings = cosserat_backend_cpu::StiffBindings::new(&rods, &b.bindings)
                .map_err(BuildError::Setting)?
                .with_rod_contacts(&rods, b.rod_contact);
            Box::new(CpuStepper::bound_stiff(rods, settings, st, bindings))
        }
        (Some(st), false) => {
            require(
                <Stiff as Scheme<T>>::NAME,
                <Stiff as Scheme<T>>::capabilities(),
                needs,
                to_explicit,
            )?;
            Box::new(CpuStepper::stiff(rods, settings, st, par))
        }
        (None, true) => {
            require(
                <Coupled<T> as Scheme<T>>::NAME,
                <Coupled<T> as Scheme<T>>::capabilities(),
                needs,
                "use solver.constraint_solver = \"iterative\"",
            )?;
            let c = cosserat_backend_cpu::Coupling::new(&rods, &b.bindings, b.rod_contact)
                .map_err(BuildError::Setting)?;
            if c.is_active() {
                Box::new(CpuStepper::with_scheme(rods, settings, par, Coupled(c)))
            } else {
                Box::new(CpuStepper::explicit(rods, settings, par))
            }
        }
        (None, false) => {
            require(
                <Explicit as Scheme<T>>::NAME,
                <Explicit as Scheme<T>>::capabilities(),
                needs,
                "use --backend cpu",
            )?;
            Box::new(CpuStepper::explicit(rods, settings, par))
        }
    })
}

#[cfg(feature = "gpu")]
fn gpu_stepper(b: &SimulationBuilder, needs: Capabilities) -> Result<Box<dyn Stepper>, BuildError> {
    if let Some(stiff) = b.stiff {
        return gpu_stiff_stepper(b, needs, &stiff);
    }
    require(
        "gpu explicit",
        cosserat_backend_gpu::GpuStepper::supported(),
        needs,
        "use --backend cpu",
    )?;
    let rods = cpu_rods::<f32>(b)?;
    // Bindings: each inner rod names its outer rod (v0 binds nothing).
    let mut bound: Vec<Option<cosserat_backend_gpu::GpuBinding>> = vec![None; rods.len()];
    for (k, spec) in b.bindings.iter().enumerate() {
        let two_way = match spec.variant {
            BindingVariant::None => continue,
            BindingVariant::OneWay => false,
            BindingVariant::TwoWay => true,
        };
        let capture = spec
            .checked_capture(k, &rods)
            .map_err(BuildError::Setting)?;
        let slot = &mut bound[spec.inner];
        if slot.is_some() {
            return Err(BuildError::Setting(format!(
                "binding {k}: rod {} is already bound inside another rod; the GPU binds a rod inside one rod only (use --backend cpu)",
                spec.inner
            )));
        }
        *slot = Some(cosserat_backend_gpu::GpuBinding {
            outer: spec.outer,
            two_way,
            capture: capture as f32,
            offset_correction: cosserat_constraints::binding::DEFAULT_OFFSET_CORRECTION as f32,
        });
    }
    // Rod contact: every rod touches every other and itself, as on the CPU.
    let rod_contact = b.rod_contact.map(|c| cosserat_backend_gpu::GpuRodContact {
        self_collisions: c.self_collisions,
        static_friction: c.friction.static_coefficient as f32,
        kinetic_friction: c.friction.kinetic_coefficient as f32,
        margin: c.margin as f32,
    });
    let inputs = rods
        .into_iter()
        .zip(bound)
        .map(|(r, binding)| {
            // Obstacles beyond one mesh of one friction were refused by `require`.
            let wall = r.mesh_settings().and_then(|m| {
                Some(cosserat_backend_gpu::GpuWall {
                    collider: m.collider.clone()?,
                    static_friction: m.friction.static_coefficient as f32,
                    kinetic_friction: m.friction.kinetic_coefficient as f32,
                    margin: m.margin as f32,
                })
            });
            let guide = r.guide().map(|g| cosserat_backend_gpu::GpuGuide {
                origin: g.origin().into(),
                axis: g.axis().into(),
                length: g.length(),
                clearance: g.clearance(),
            });
            cosserat_backend_gpu::GpuRodInput {
                state: r.state,
                params: r.params,
                ends: r.ends,
                loads: r.loads,
                wall,
                guide,
                binding,
                rod_contact,
            }
        })
        .collect();
    let mut options = cosserat_backend_gpu::GpuOptions::default();
    if let Some(hz) = b.reaction_cutoff_hz {
        options.reaction_cutoff_hz = hz;
    }
    let stepper =
        cosserat_backend_gpu::GpuStepper::on_gpus(inputs, &b.settings.cast(), options, b.gpus)
            .map_err(|e| BuildError::Setting(e.to_string()))?;
    Ok(Box::new(stepper))
}

/// The stiff scheme on the GPU (`cosserat_backend_gpu::GpuStiffStepper`): rods in `f64`, in
/// contact with one static mesh they all share, or free.
#[cfg(feature = "gpu")]
fn gpu_stiff_stepper(
    b: &SimulationBuilder,
    needs: Capabilities,
    stiff: &StiffSettings,
) -> Result<Box<dyn Stepper>, BuildError> {
    require(
        "gpu stiff",
        cosserat_backend_gpu::GpuStiffStepper::supported(),
        needs,
        "use --backend cpu",
    )?;
    let rods = cpu_rods::<f64>(b)?;
    let loads: Vec<Vec<PointLoad<f64>>> = b.rods.iter().map(RodBuilder::point_loads).collect();
    // One mesh of one friction for every rod (more obstacles, or another friction per triangle,
    // were refused by `require`).
    let walls: Vec<_> = rods
        .iter()
        .map(|r| {
            r.mesh_settings().and_then(|m| {
                Some(cosserat_backend_gpu::GpuStiffWall {
                    collider: m.collider.clone()?,
                    static_friction: m.friction.static_coefficient,
                    kinetic_friction: m.friction.kinetic_coefficient,
                    margin: m.margin,
                })
            })
        })
        .collect();
    let wall = walls.first().cloned().flatten();
    let shared = walls.iter().all(|w| match (w, &wall) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            std::sync::Arc::ptr_eq(&a.collider, &b.collider)
                && (a.static_friction, a.kinetic_friction, a.margin)
                    == (b.static_friction, b.kinetic_friction, b.margin)
        }
        _ => false,
    });
    if !shared {
        return Err(BuildError::Setting(
            "the GPU's stiff scheme runs rods that all touch the same mesh, or none (use --backend cpu)"
                .into(),
        ));
    }
    let rods = rods
        .into_iter()
        .map(|r| {
            let guide = r.guide().map(|g| cosserat_backend_gpu::GpuGuide {
                origin: g.origin().into(),
                axis: g.axis().into(),
                length: g.length(),
                clearance: g.clearance(),
            });
            (r.state, r.params, r.ends, guide)
        })
        .collect();
    // Contacts as pins: the GPU has no contact rows (the build warns).
    let stiff = StiffSettings {
        contact_rows: false,
        ..*stiff
    };
    let stepper = cosserat_backend_gpu::GpuStiffStepper::new(
        rods,
        loads,
        &b.settings,
        &stiff,
        b.reaction_cutoff_hz
            .unwrap_or(cosserat_problem::report::DEFAULT_CUTOFF_HZ),
        &cosserat_backend_gpu::GpuOptions::default(),
        wall,
    )
    .map_err(|e| BuildError::Setting(format!("the GPU's stiff scheme: {e}")))?;
    Ok(Box::new(stepper))
}

#[cfg(not(feature = "gpu"))]
fn gpu_stepper(_: &SimulationBuilder, _: Capabilities) -> Result<Box<dyn Stepper>, BuildError> {
    Err(BuildError::Setting(
        "this build has no GPU backend: rebuild with the `gpu` feature, or use --backend cpu"
            .into(),
    ))
}

/// A simulation's state at one step, to return to with [`Simulation::restore`].
#[derive(Debug)]
pub struct SimulationSnapshot {
    inner: Snapshot,
    max_strain: f64,
    outside: (usize, f64),
    /// The obstacles (their paths, which `Simulation::set_obstacle_path` changes).
    obstacles: Vec<Obstacle>,
}

impl SimulationSnapshot {
    /// Steps taken when it was made.
    pub fn steps(&self) -> u64 {
        self.inner.clock().step
    }
}

/// A running simulation: rods, their state and the clock, stepped by one [`Stepper`].
pub struct Simulation {
    stepper: Box<dyn Stepper>,
    names: Vec<String>,
    radii: Vec<f64>,
    backend: Backend,
    max_strain: f64,
    extensible: bool,
    environment: Option<Environment>,
    /// Everything the rods collide with: the environment (as an obstacle) and the obstacles.
    obstacles: Vec<Obstacle>,
    /// Whether a point found outside stops the run ([`Simulation::check_lumen`]).
    stop_outside: bool,
    divergence_speed: f64,
    warnings: Vec<String>,
    /// Reused by the allocating getters ([`Simulation::positions`] and friends).
    scratch: Vec<[f64; 3]>,
    /// Which rods collide with the environment.
    collides: Vec<bool>,
    /// Per rod, the largest force a held end may take [N]
    /// ([`SimulationBuilder::reaction_limit`] times `E A`). Beyond it the step has blown up.
    reaction_bounds: Vec<f64>,
    /// Most points found outside the lumen after any call to [`Simulation::run`], and the
    /// deepest of them [m].
    outside: (usize, f64),
    /// Per rod, its point loads (for the energy watch's bound on their work).
    loads: Vec<Vec<PointLoad<f64>>>,
    /// Energy that grows beyond the work done on the rods ([`crate::energy_watch`]).
    energy: EnergyWatch,
    /// Per rod, the rest length of each element [m] (for [`Simulation::strains`]).
    rest_lengths: Vec<Vec<f64>>,
}

/// Contact measurements of a whole simulation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactReport {
    /// Largest penetration of any point's sphere into the wall [m]: found by the contact
    /// queries at the start of a step, or, at any depth, by the inside test
    /// ([`Simulation::check_lumen`]; a point behind the wall counts its distance plus its
    /// radius).
    pub max_penetration: f64,
    /// Points outside the lumen: the most seen by the contact queries at the start of a step or
    /// by the inside test ([`Simulation::check_lumen`]).
    pub escaped_points: usize,
    /// Points in contact at the last step.
    pub contacts: usize,
    /// Mean wall time of collision detection per step [µs], all rods together.
    pub detection_us_per_step: f64,
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
        let worst = self.stepper.advance(n)?;
        self.max_strain = self.max_strain.max(worst);
        self.stepper
            .check_speed(self.divergence_speed)
            .map_err(StepError::Diverged)?;
        self.check_reactions()?;
        self.check_energy()
    }

    /// The energy watch ([`crate::energy_watch`]) after a call to `run`: records the reactions,
    /// and every 64 steps compares the energy's growth with the work done. Blames the fastest
    /// point, where the energy went.
    fn check_energy(&mut self) -> Result<(), StepError> {
        if !self.energy.enabled {
            return Ok(());
        }
        self.energy.record_reactions(self.stepper.as_ref());
        let steps = self.steps();
        let time = self.time();
        let Err(growth) = self
            .energy
            .check(self.stepper.as_ref(), steps, time, &self.loads)
        else {
            return Ok(());
        };
        let (mut rod, mut element, mut fastest) = (0, 0, -1.0);
        for r in 0..self.stepper.rod_count() {
            let n = self.stepper.elements(r).unwrap_or(0);
            self.scratch.resize(n + 1, [0.0; 3]);
            if self
                .stepper
                .read(r, StateField::Velocities, &mut self.scratch)
                .is_err()
            {
                continue;
            }
            for (i, v) in self.scratch.iter().enumerate() {
                let speed = v.iter().map(|x| x * x).sum::<f64>();
                if speed > fastest {
                    (rod, element, fastest) = (r, i, speed);
                }
            }
        }
        Err(StepError::Diverged(cosserat_problem::Divergence {
            rod,
            element,
            step: steps,
            quantity: cosserat_problem::DivergedQuantity::EnergyGrowth(
                growth.growth,
                growth.allowed,
            ),
        }))
    }

    /// The force at every held end against its rod's bound (a multiple of `E A`): a reaction of
    /// 1e20 N is a step that blew up, not a result. Two reads per rod; nothing where reactions are not
    /// computed.
    fn check_reactions(&self) -> Result<(), StepError> {
        for (rod, &bound) in self.reaction_bounds.iter().enumerate() {
            for end in 0..2 {
                let Some(r) = self.stepper.end_reaction(rod, end) else {
                    continue;
                };
                let force = r.force_norm();
                if !(force <= bound) {
                    let n = self.stepper.elements(rod).unwrap_or(0);
                    return Err(StepError::Diverged(cosserat_problem::Divergence {
                        rod,
                        element: if end == 0 { 0 } else { n },
                        step: self.steps(),
                        quantity: cosserat_problem::DivergedQuantity::Reaction(force, bound),
                    }));
                }
            }
        }
        Ok(())
    }

    /// The inside test of the rods' points against the environment's lumen
    /// ([`Environment::outside`]): counts the points outside, at any depth, keeps the most and
    /// the deepest for [`Simulation::contact_report`], and returns the deepest as a divergence
    /// unless the environment says to go on (`environment.stop_outside = false`). Returns what
    /// it found now, all rods together (the deepest point is the first rod's with any outside).
    ///
    /// It is not run by [`Simulation::run`]: it costs about 3 µs per point on the generated
    /// 26 000-triangle vessel (`cargo bench -p cosserat-collide --bench detect -- winding`),
    /// more than a haptic tick can spare for every point. The `cosserat` command runs it every
    /// few thousand steps and after the last; a program calls it as often as it can afford.
    pub fn check_lumen(&mut self) -> Result<Outside, StepError> {
        if self.obstacles.is_empty() {
            return Ok(Outside::default());
        }
        let t = self.time();
        let obstacles: Vec<&Obstacle> = self.obstacles.iter().collect();
        let mut first = None;
        let mut count = 0;
        let mut deepest: f64 = 0.0;
        for rod in 0..self.stepper.rod_count() {
            if !self.collides[rod] {
                continue;
            }
            let n = self.stepper.elements(rod).unwrap_or(0);
            self.scratch.resize(n + 1, [0.0; 3]);
            if self
                .stepper
                .read(rod, StateField::Positions, &mut self.scratch)
                .is_err()
            {
                continue;
            }
            let out = match obstacles.as_slice() {
                [one] => one.each_outside_count(&self.scratch, self.radii[rod], t),
                all => crate::obstacles::outside_any(all, &self.scratch, self.radii[rod], t),
            };
            count += out.count;
            deepest = deepest.max(out.deepest);
            self.outside.1 = self.outside.1.max(out.deepest);
            if let (None, Some(point)) = (first, out.deepest_point) {
                first = Some((rod, point, out.deepest));
            }
        }
        self.outside.0 = self.outside.0.max(count);
        match first {
            Some((rod, element, depth)) if self.stop_outside => {
                Err(StepError::Diverged(cosserat_problem::Divergence {
                    rod,
                    element,
                    step: self.steps(),
                    quantity: cosserat_problem::DivergedQuantity::OutsideLumen(depth),
                }))
            }
            _ => Ok(Outside {
                count,
                deepest,
                deepest_point: first.map(|(_, point, _)| point),
            }),
        }
    }

    /// The stepper: its name, precision and capabilities, and the whole control interface.
    pub fn stepper(&self) -> &dyn Stepper {
        self.stepper.as_ref()
    }

    /// What the stepper can do.
    pub fn capabilities(&self) -> Capabilities {
        self.stepper.capabilities()
    }

    /// The stepper's name and precision.
    pub fn stepper_info(&self) -> StepperInfo {
        self.stepper.info()
    }

    /// The condition at end `end` (0: first point, 1: last point) of a rod.
    pub fn end_condition(
        &self,
        h: RodHandle,
        end: usize,
    ) -> Result<EndCondition<f64>, ControlError> {
        self.stepper.end_condition(h.0, end)
    }

    /// Replaces the condition at end `end` of a rod from the next step on (see
    /// [`Stepper::set_end_condition`]).
    pub fn set_end_condition(
        &mut self,
        h: RodHandle,
        end: usize,
        condition: EndCondition<f64>,
    ) -> Result<(), ControlError> {
        let before = self.stepper.end_condition(h.0, end)?;
        let changed = condition.kind != before.kind || condition.slide != before.slide;
        self.stepper.set_end_condition(h.0, end, condition)?;
        // Holding or releasing an end changes what does work on the rod: watch anew.
        if changed {
            self.energy.reset();
        }
        Ok(())
    }

    /// Makes obstacle `obstacle` (its index in [`Simulation::obstacles`]: the environment, if
    /// any, is 0) follow `path` from where it is now: the path's displacement and rotation (about
    /// the shape's point) are taken from the obstacle's present pose, its times from
    /// `path.start_time()`; `None` stops it where it is. Analytic shapes only (meshes do not
    /// move), on the CPU schemes. The energy watch stops: nothing measures the obstacle's work.
    pub fn set_obstacle_path(
        &mut self,
        obstacle: usize,
        path: Option<EndPath>,
    ) -> Result<(), ControlError> {
        let info = self.stepper.info();
        let Some(o) = self.obstacles.get(obstacle) else {
            return Err(ControlError::Unsupported {
                stepper: info.name,
                what: format!(
                    "move obstacle {obstacle}: there are {} obstacles",
                    self.obstacles.len()
                ),
            });
        };
        if let crate::obstacles::Geometry::Mesh(_) = o.geometry() {
            return Err(ControlError::Unsupported {
                stepper: info.name,
                what: format!(
                    "move obstacle {obstacle}: it is a mesh, and meshes do not move (only half-spaces and cylinders do)"
                ),
            });
        }
        let shape = self.obstacles[..obstacle]
            .iter()
            .filter(|o| matches!(o.geometry(), crate::obstacles::Geometry::Shape(_)))
            .count();
        self.stepper.set_obstacle_path(shape, path.clone())?;
        let now = self.time();
        let o = &mut self.obstacles[obstacle];
        *o = o.clone().rebased(now, path);
        self.energy.disable();
        Ok(())
    }

    /// Drives a held end at a constant velocity [m/s] and angular velocity [rad/s] (world frame)
    /// from now until changed: a haptic hand's push or pull and twist at one tick.
    pub fn set_end_velocity(
        &mut self,
        h: RodHandle,
        end: usize,
        velocity: [f64; 3],
        angular_velocity: [f64; 3],
    ) -> Result<(), ControlError> {
        let mut c = self.stepper.end_condition(h.0, end)?;
        c.motion = Some(PrescribedMotion::constant(
            velocity.into(),
            angular_velocity.into(),
            self.time(),
        ));
        self.stepper.set_end_condition(h.0, end, c)
    }

    /// Moves a held end to `position` [m] (and, for a clamped end, its frame to `frame`, a unit
    /// quaternion `[w, x, y, z]`) in `duration` seconds, rounded to whole steps (at least one),
    /// at constant velocity, and holds it there.
    pub fn move_end_to(
        &mut self,
        h: RodHandle,
        end: usize,
        position: [f64; 3],
        frame: Option<[f64; 4]>,
        duration: f64,
    ) -> Result<(), ControlError> {
        let mut c = self.stepper.end_condition(h.0, end)?;
        if !c.holds_point() {
            return Err(ControlError::Value {
                field: "end",
                why: format!("end {end} of rod {} is free: hold it first", h.0),
            });
        }
        if !(duration.is_finite() && duration >= 0.0 && position.iter().all(|x| x.is_finite())) {
            return Err(ControlError::Value {
                field: "move",
                why: format!("duration {duration} s and position must be finite, duration ≥ 0"),
            });
        }
        let clock = self.stepper.clock();
        let steps = ((duration / clock.dt).round() as u64).max(1);
        let seconds = steps as f64 * clock.dt;
        let n = self.stepper.elements(h.0)?;
        let point = if end == 0 { 0 } else { n };
        self.read_into_scratch(h, StateField::Positions)?;
        let here = Vec3::from(self.scratch[point]);
        let velocity = (Vec3::from(position) - here) / seconds;
        let mut angular_velocity = Vec3::zeros();
        if let Some(q) = frame {
            let mut frames = vec![[0.0; 4]; n];
            self.stepper.read_frames(h.0, &mut frames)?;
            let now = frames[if end == 0 { 0 } else { n - 1 }];
            let now = Quat::new(now[0], now[1], now[2], now[3]);
            let target = Quat::new(q[0], q[1], q[2], q[3]);
            if !(target.norm() > 1e-9) {
                return Err(ControlError::Value {
                    field: "frame",
                    why: "the target frame is not a rotation".into(),
                });
            }
            // The world-frame rotation that takes the current frame to the target one.
            let mut turn = (target / target.norm()) * now.conjugate();
            if turn.w < 0.0 {
                turn = -turn;
            }
            let s = turn.imag().norm();
            let angle = 2.0 * s.atan2(turn.w);
            if s > 0.0 {
                angular_velocity = turn.imag() * (angle / s / seconds);
            }
        }
        c.motion = Some(PrescribedMotion {
            velocity,
            angular_velocity,
            start_time: clock.time(),
            // Half a step before the last step's end: the motion covers exactly `steps` steps.
            end_time: clock.time_of(steps) - 0.5 * clock.dt,
        });
        self.stepper.set_end_condition(h.0, end, c)
    }

    /// Holds end `end` of a rod (`EndKind::Pinned` or `EndKind::Clamped`) where it is, or frees
    /// it (`EndKind::Free`).
    pub fn hold_end(
        &mut self,
        h: RodHandle,
        end: usize,
        kind: EndKind,
    ) -> Result<(), ControlError> {
        self.set_end_condition(
            h,
            end,
            EndCondition {
                kind,
                ..EndCondition::default()
            },
        )
    }

    /// Replaces the point loads of a rod: `(point, force [N])` pairs; an empty slice removes
    /// them.
    pub fn set_loads(
        &mut self,
        h: RodHandle,
        loads: &[(usize, [f64; 3])],
    ) -> Result<(), ControlError> {
        let new: Vec<PointLoad<f64>> = loads
            .iter()
            .map(|&(point, f)| PointLoad::new(point, f.into()))
            .collect();
        self.set_point_loads(h, &new)
    }

    /// Replaces the loads of a rod with forces and moments, constant or varying in time
    /// ([`PointLoad`]); an empty slice removes them.
    pub fn set_point_loads(
        &mut self,
        h: RodHandle,
        loads: &[PointLoad<f64>],
    ) -> Result<(), ControlError> {
        self.stepper.set_loads(h.0, loads)?;
        if let Some(l) = self.loads.get_mut(h.0) {
            *l = loads.to_vec();
        }
        Ok(())
    }

    /// Copies a field of a rod's state into `out` (length [`StateField::len`] of its element
    /// count); allocates nothing.
    pub fn read(
        &self,
        h: RodHandle,
        field: StateField,
        out: &mut [[f64; 3]],
    ) -> Result<(), ControlError> {
        self.stepper.read(h.0, field, out)
    }

    /// Copies a rod's frames into `out` as `[w, x, y, z]`.
    pub fn read_frames(&self, h: RodHandle, out: &mut [[f64; 4]]) -> Result<(), ControlError> {
        self.stepper.read_frames(h.0, out)
    }

    /// Overwrites a field of a rod's state.
    pub fn write(
        &mut self,
        h: RodHandle,
        field: StateField,
        values: &[[f64; 3]],
    ) -> Result<(), ControlError> {
        self.stepper.write(h.0, field, values)?;
        self.energy.reset();
        Ok(())
    }

    /// Overwrites a rod's frames (`[w, x, y, z]`).
    pub fn write_frames(&mut self, h: RodHandle, values: &[[f64; 4]]) -> Result<(), ControlError> {
        self.stepper.write_frames(h.0, values)?;
        self.energy.reset();
        Ok(())
    }

    /// Replaces `out` with a rod's contacts at the last step.
    pub fn contacts(&self, h: RodHandle, out: &mut Vec<ContactSample>) -> Result<(), ControlError> {
        self.stepper.contacts(h.0, out)
    }

    /// The whole state, to come back to with [`Simulation::restore`].
    pub fn snapshot(&mut self) -> Result<SimulationSnapshot, StepError> {
        Ok(SimulationSnapshot {
            inner: self.stepper.snapshot()?,
            max_strain: self.max_strain,
            outside: self.outside,
            obstacles: self.obstacles.clone(),
        })
    }

    /// Returns to a snapshot of this simulation: the steps that follow are, bit for bit, those
    /// that followed the snapshot.
    pub fn restore(&mut self, snapshot: &SimulationSnapshot) -> Result<(), ControlError> {
        self.stepper.restore(&snapshot.inner)?;
        self.energy.reset();
        self.max_strain = snapshot.max_strain;
        self.outside = snapshot.outside;
        self.obstacles.clone_from(&snapshot.obstacles);
        Ok(())
    }

    /// The filtered reaction at end `end` (0: first point, 1: last point) of a rod after the
    /// last step: the force and torque the holder applies to the rod (a haptic device renders
    /// its negative); `None` for a free end, and on the GPU backend, whose kernels do not
    /// compute reactions. See `cosserat_backend_cpu::reaction`.
    pub fn end_reaction(&self, h: RodHandle, end: usize) -> Option<EndReaction> {
        self.stepper.end_reaction(h.0, end)
    }

    /// Largest filtered reaction force at any held end of any rod so far [N]; `None` when no
    /// end is held, and on the GPU backend ([`end_reaction`](Self::end_reaction)).
    pub fn max_reaction_force(&self) -> Option<f64> {
        self.stepper.max_reaction_force()
    }

    /// Measurements of bindings and rod contacts; `None` when the rods do not interact.
    pub fn coupling_stats(&self) -> Option<CouplingStats> {
        self.stepper.coupling_stats()
    }

    /// Things the builder accepted but a user should know (a time step close to the stability
    /// limit).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Simulated time [s].
    pub fn time(&self) -> f64 {
        self.stepper.clock().time()
    }
    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.stepper.clock().step
    }
    /// Time step [s].
    pub fn dt(&self) -> f64 {
        self.stepper.clock().dt
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
        self.stepper.info().double_precision
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
        (0..self.stepper.rod_count())
            .map(|r| self.stepper.elements(r).unwrap_or(0))
            .sum()
    }
    /// Largest `|l/l0 − 1|` of any segment at the end of any step so far.
    pub fn max_strain(&self) -> f64 {
        self.max_strain
    }

    /// What the stiff solver did so far: iterations, steps that ended above the tolerance,
    /// steps retaken in halves or with axial compliance; `None` with the explicit scheme.
    pub fn stiff_summary(&self) -> Option<StiffSummary> {
        self.stepper.stiff_summary()
    }

    fn read_into_scratch(&mut self, h: RodHandle, field: StateField) -> Result<(), ControlError> {
        let n = self.stepper.elements(h.0)?;
        self.scratch.resize(field.len(n), [0.0; 3]);
        self.stepper.read(h.0, field, &mut self.scratch)
    }

    fn field(&self, h: RodHandle, field: StateField) -> Vec<[f64; 3]> {
        let n = self.stepper.elements(h.0).unwrap_or(0);
        let mut out = vec![[0.0; 3]; field.len(n)];
        if let Err(e) = self.stepper.read(h.0, field, &mut out) {
            panic!("rod {}: {e}", h.0);
        }
        out
    }

    /// Centreline points of a rod [m] (allocates; [`Simulation::read`] does not).
    pub fn positions(&self, h: RodHandle) -> Vec<[f64; 3]> {
        self.field(h, StateField::Positions)
    }

    /// Point velocities of a rod [m/s] (allocates; [`Simulation::read`] does not).
    pub fn velocities(&self, h: RodHandle) -> Vec<[f64; 3]> {
        self.field(h, StateField::Velocities)
    }

    /// The first director `d1` of each element of a rod (allocates; [`Simulation::read`] does
    /// not).
    pub fn first_directors(&self, h: RodHandle) -> Vec<[f64; 3]> {
        self.field(h, StateField::Director(0))
    }

    /// The rest length of each element of a rod [m].
    pub fn rest_lengths(&self, h: RodHandle) -> &[f64] {
        &self.rest_lengths[h.0]
    }

    /// The axial strain `l / l0 - 1` of each element of a rod now (allocates).
    pub fn strains(&self, h: RodHandle) -> Vec<f64> {
        let p = self.positions(h);
        p.windows(2)
            .zip(self.rest_lengths(h))
            .map(|(w, l0)| {
                let l = (0..3)
                    .map(|k| (w[1][k] - w[0][k]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                l / l0 - 1.0
            })
            .collect()
    }

    /// The environment, if the rods collide with one.
    pub fn environment(&self) -> Option<&Environment> {
        self.environment.as_ref()
    }

    /// Everything the rods collide with: the environment (first, as an obstacle) and the
    /// obstacles ([`SimulationBuilder::obstacle`]).
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// Contact measurements since the start, or `None` without an environment or obstacles.
    pub fn contact_report(&self) -> Option<ContactReport> {
        if self.obstacles.is_empty() {
            return None;
        }
        let mut report = ContactReport::default();
        let mut seconds = 0.0;
        let mut steps = 0;
        for rod in 0..self.stepper.rod_count() {
            if let Some(st) = self.stepper.collision_stats(rod) {
                report.max_penetration = report.max_penetration.max(st.max_penetration);
                report.escaped_points += st.escaped_points;
                report.contacts += st.contacts;
                seconds += st.detection_seconds;
                steps = steps.max(st.steps);
            }
        }
        // The inside test (`check_lumen`) sees points at any depth, which the contact queries,
        // limited to their reach, do not.
        report.escaped_points = report.escaped_points.max(self.outside.0);
        report.max_penetration = report.max_penetration.max(self.outside.1);
        report.detection_us_per_step = if steps > 0 {
            seconds * 1e6 / steps as f64
        } else {
            0.0
        };
        Some(report)
    }

    /// Energies summed over all rods.
    pub fn energies(&self) -> Energies {
        self.stepper.energies()
    }
}

/// Memory the system can still give [bytes] (`MemAvailable` of `/proc/meminfo`); `None` where
/// that is not known.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
