//! Settings of a simulation: the explicit scheme's and the stiff scheme's, and how it runs.

use cosserat_model::{Real, Vec3};
use std::sync::Arc;

use crate::ends::cast_vec;

/// Serial or parallel execution, chosen at run time: a value a stepper is given, like faer's
/// `Par`, not a backend of its own.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Par {
    /// One thread.
    #[default]
    Serial,
    /// Rods spread over rayon's thread pool (serial where the backend has no pool).
    Rayon,
}

/// The order in which the distance constraints of one sweep are visited.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Ordering {
    /// Elements `0, 1, 2, …` in turn, each seeing the previous one's impulse: the fastest
    /// convergence per sweep; inherently serial.
    #[default]
    GaussSeidel,
    /// All even elements, then all odd ones. Constraints of one colour share no point, so each
    /// half-sweep can run in parallel (threads, SIMD lanes or GPU invocations) with the same
    /// result in any order.
    RedBlack,
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

impl<T: Real> Default for SolverSettings<T> {
    /// `dt = 1e-4` s, 10 red–black sweeps, inextensible, gravity `−9.81 ẑ`, divergence at a
    /// strain of 0.5.
    fn default() -> Self {
        Self {
            dt: T::lit(1e-4),
            iterations: 10,
            ordering: Ordering::RedBlack,
            extensible: false,
            gravity: Vec3::new(T::zero(), T::zero(), T::lit(-9.81)),
            divergence_strain: T::lit(0.5),
        }
    }
}

impl<T: Real> SolverSettings<T> {
    /// The same settings in another precision.
    pub fn cast<U: Real>(&self) -> SolverSettings<U> {
        SolverSettings {
            dt: U::lit(self.dt.to_f64()),
            iterations: self.iterations,
            ordering: self.ordering,
            extensible: self.extensible,
            gravity: cast_vec(&self.gravity),
            divergence_strain: U::lit(self.divergence_strain.to_f64()),
        }
    }
}

/// How a load varies in time: the factor its force and moment are multiplied by.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum LoadProfile {
    /// 1 at all times.
    #[default]
    Constant,
    /// 0 until `start` [s], rising linearly to 1 over `duration` [s], 1 after.
    Ramp {
        /// When the ramp starts [s].
        start: f64,
        /// How long it takes [s] (0: a step at `start`).
        duration: f64,
    },
    /// `offset + amplitude sin(2π frequency t + phase)`.
    Sine {
        /// Mean factor.
        offset: f64,
        /// Amplitude of the factor.
        amplitude: f64,
        /// Frequency [Hz].
        frequency: f64,
        /// Phase [rad].
        phase: f64,
    },
    /// Linear between `(time [s], factor)` points, held before the first and after the last
    /// ([`LoadProfile::table`]).
    Table(Arc<[[f64; 2]]>),
}

impl LoadProfile {
    /// A piecewise-linear profile through `(time, factor)` points: at least one, times
    /// increasing, every value finite; errors say which point is wrong.
    pub fn table(points: Vec<[f64; 2]>) -> Result<Self, String> {
        if points.is_empty() {
            return Err("a table needs at least one (time, factor) point".into());
        }
        if let Some(k) = points
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(format!("point {k} is {:?}: not finite", points[k]));
        }
        if let Some(k) = (1..points.len()).find(|&k| !(points[k][0] > points[k - 1][0])) {
            return Err(format!(
                "point {k} is at {} s after {} s: times must increase",
                points[k][0],
                points[k - 1][0]
            ));
        }
        Ok(Self::Table(points.into()))
    }

    /// The factor at time `t` [s].
    pub fn factor(&self, t: f64) -> f64 {
        match self {
            Self::Constant => 1.0,
            Self::Ramp { start, duration } => {
                if t < *start {
                    0.0
                } else if t >= start + duration {
                    1.0
                } else {
                    (t - start) / duration
                }
            }
            Self::Sine {
                offset,
                amplitude,
                frequency,
                phase,
            } => offset + amplitude * (2.0 * std::f64::consts::PI * frequency * t + phase).sin(),
            Self::Table(points) => {
                let k = points.partition_point(|p| p[0] <= t);
                if k == 0 {
                    points[0][1]
                } else if k == points.len() {
                    points[k - 1][1]
                } else {
                    let ([t0, f0], [t1, f1]) = (points[k - 1], points[k]);
                    f0 + (f1 - f0) * (t - t0) / (t1 - t0)
                }
            }
        }
    }

    /// The largest magnitude the factor takes.
    pub fn max_factor(&self) -> f64 {
        match self {
            Self::Constant | Self::Ramp { .. } => 1.0,
            Self::Sine {
                offset, amplitude, ..
            } => offset.abs() + amplitude.abs(),
            Self::Table(points) => points.iter().fold(0.0, |m, p| m.max(p[1].abs())),
        }
    }
}

/// An external force and moment on one point, constant or varying in time.
///
/// The moment acts on the material frames beside the point: half on each of an interior
/// point's two frames, all of it on an end point's one (a clamp's, a hand's or a load's
/// torque on the rod's end).
#[derive(Clone, Debug, PartialEq)]
pub struct PointLoad<T: Real> {
    /// Index of the point.
    pub point: usize,
    /// Force [N], world frame.
    pub force: Vec3<T>,
    /// Moment [N m], world frame.
    pub moment: Vec3<T>,
    /// How force and moment vary in time.
    pub profile: LoadProfile,
}

impl<T: Real> PointLoad<T> {
    /// A constant force on `point`.
    pub fn new(point: usize, force: Vec3<T>) -> Self {
        Self {
            point,
            force,
            moment: Vec3::zeros(),
            profile: LoadProfile::Constant,
        }
    }

    /// This load with a moment [N m] (world frame).
    #[must_use]
    pub fn with_moment(mut self, moment: Vec3<T>) -> Self {
        self.moment = moment;
        self
    }

    /// This load varying in time as `profile`.
    #[must_use]
    pub fn with_profile(mut self, profile: LoadProfile) -> Self {
        self.profile = profile;
        self
    }

    /// The same load in another precision.
    pub fn cast<U: Real>(&self) -> PointLoad<U> {
        PointLoad {
            point: self.point,
            force: cast_vec(&self.force),
            moment: cast_vec(&self.moment),
            profile: self.profile.clone(),
        }
    }

    /// Whether it varies in time.
    pub fn varies(&self) -> bool {
        self.profile != LoadProfile::Constant
    }

    /// Whether it has a moment.
    pub fn turns(&self) -> bool {
        self.moment != Vec3::zeros()
    }

    /// What a stepper needs beyond constant forces to apply these loads.
    pub fn needs(loads: &[Self]) -> crate::Capabilities {
        use crate::Capability;
        crate::Capabilities::NONE
            .with_if(Capability::VaryingLoads, loads.iter().any(Self::varies))
            .with_if(Capability::Moments, loads.iter().any(Self::turns))
    }
}

/// How the constraints of a step are solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StiffScheme {
    /// All constraints of a rod at once, by the block-tridiagonal factorisation of Deul et al.
    /// (2018). Converges in a few iterations whatever the stiffness and length.
    #[default]
    Direct,
    /// XPBD with Gauss–Seidel sweeps, one constraint at a time (Macklin et al. 2016). Cheap per
    /// sweep, but needs many sweeps on long stiff rods; kept for comparison. It ignores
    /// internal damping, mesh contacts and guides.
    GaussSeidel,
}

/// When the direct solver refactorises `J K⁻¹ Jᵀ + α̃`. With every policy, an iteration that
/// reduced the residual by less than a factor of 4 refactorises with the current multipliers
/// (a Newton iteration), so a factorisation that no longer fits is given up after one poor
/// iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Refactor {
    /// At every iteration: Newton's method, as Deul et al. do.
    EveryIteration,
    /// At the first iteration of every step, reused by the later ones (a chord method); the
    /// default. On the bench's swinging nitinol pendulum it needed 1.26 iterations per step
    /// against Newton's 1.54 and took 22–26 % less time in three runs
    /// (`docs/benchmarks/stiff.md`).
    #[default]
    EveryStep,
    /// Kept across steps and rebuilt only when an iteration fails to reduce the residual by a
    /// factor of 4. The matrix is written in body frames, so it depends only on the relative
    /// rotations of neighbouring frames and on the strains, not on the rod's rigid motion.
    Lagged,
}

/// Time integration of the stiff scheme.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integrator {
    /// Implicit (backward) Euler, as XPBD: first order and L-stable. It damps a vibration of
    /// frequency `ω` by about `(ω h)² / 2` of its amplitude per step, which at haptic steps
    /// is most of the error of a swinging rod (`docs/stiff-solver.md`).
    #[default]
    ImplicitEuler,
    /// BDF2, the two-step backward differentiation formula: second order and still L-stable,
    /// with a numerical damping of order `(ω h)⁴` per step. A BDF2 step of `h` is an implicit
    /// Euler step of `2h/3` taken from the state extrapolated from the last two,
    /// `x* = (4 x_n − x_{n−1})/3`, `v* = (4 v_n − v_{n−1})/3` (frames: a third of the last
    /// step's rotation past `q_n`, `ω* = (4 ω_n − ω_{n−1})/3`); its velocities are then
    /// `(x_{n+1} − x*)/(2h/3)`, which is BDF2's `(3 x_{n+1} − 4 x_n + x_{n−1})/(2h)`. So
    /// contacts, guides, bindings, damping and the reactions at held ends work unchanged; held
    /// ends are placed so that the step moves them by their prescribed motion over `h`. The
    /// medium's drag, applied to the velocities after the solve, stays first order. The first
    /// step of a run, the first step after a change of step (a step retaken in halves, and the
    /// first full step after it), the steps of a batch retaken after a divergence and a step
    /// after the rod's state was changed from outside have no history and are implicit Euler
    /// steps. Direct solver only.
    Bdf2,
}

/// Settings of the stiff scheme (the rest — `dt`, gravity, extensibility, divergence limit —
/// comes from the shared [`SolverSettings`]; its `iterations` and `ordering` belong to the
/// explicit scheme's distance constraints and are not used here).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StiffSettings {
    /// Solver of the constraint system.
    pub scheme: StiffScheme,
    /// Largest number of iterations (direct) or sweeps (Gauss–Seidel) per step.
    pub iterations: usize,
    /// Stop iterating once every residual `|C + α̃ λ|` and `|J u|` is at most this (strains,
    /// and angles `l̄ |ΔΩ|` for bend–twist), checked after each iteration; the first always
    /// runs. Zero always runs `iterations`. For an `f32` rod the tolerance used is at least
    /// the strain its positions resolve, `2⁻²³ max|x| / min l0` (the step itself runs in
    /// `f64`).
    pub tolerance: f64,
    /// Refactorisation policy of the direct solver.
    pub refactor: Refactor,
    /// Lower bound of each frame's rotational inertia, as a multiple of `m l² / 12` (the
    /// inertia of its element, mass `m = ρ A l`, as a bar about its centre); 0 keeps the
    /// model's `ρ l (I, I, J)`.
    ///
    /// A thin rod's frames are nearly massless (`ρ I l / (m l²) = r² / (4 l²)`, 1e-3 to 1e-2
    /// here). A floor helped the first version (two chord iterations, no geometric bound)
    /// converge; with [`geometric`](Self::geometric) it is not needed and the default is 0. It
    /// changes no static equilibrium and leaves bending dynamics alone up to `(l/λ)²`, but
    /// slows torsion waves by up to `√(l² / (6 r²))` (`docs/stiff-solver.md`).
    pub inertia_floor: f64,
    /// Multiplier of the geometric-stiffness bound `σ` added to each frame's block of the
    /// Newton matrix (`K_θ = I + geometric · σ`; 0 turns it off, giving XPBD's `K = M`).
    ///
    /// XPBD approximates the Hessian `M − Σ λ ∇²C` by `M`; for a thin rod's frames the
    /// geometric part (tension through stretch–shear, moments through bend–twist) exceeds the
    /// inertia by orders of magnitude, and the iteration then over-rotates them. `σ` bounds
    /// that part per frame from the multipliers (the previous step's on the first iteration).
    /// It steers the points' iteration only; for the frames it also acts as an added
    /// rotational inertia of order `h²` (`σ ∝ λ ∝ h²`), a consistent perturbation of the step.
    /// Measured in `docs/stiff-solver.md` (item 6): half the iterations for the same
    /// tolerance, and the step's dependence on `σ`.
    pub geometric: f64,
    /// How many times a step that diverges may be split in two halves (recursively) before
    /// the divergence is reported; 0 reports it at once. A rod released far from its rest
    /// shape (a J-tip wire built straight: 0.3 rad of rest turn per 1 mm element of nitinol)
    /// moves so far in its first 1 ms step that the linearised step overshoots; its first steps
    /// are then taken in halves, quarters, …, and the rest at the full step.
    pub max_halvings: u32,
    /// A step still unconverged after [`iterations`](Self::iterations) (and the axial retry)
    /// with a residual above this is retaken in halves, as a diverging one is
    /// ([`max_halvings`](Self::max_halvings)); at the finest split the run stops with
    /// [`DivergedQuantity::Unconverged`](crate::DivergedQuantity::Unconverged). Steps between
    /// the tolerance and this are kept and counted in [`StiffReport::unconverged_steps`](crate::StiffReport::unconverged_steps).
    /// Direct solver only; with a tolerance of 0 nothing is checked.
    ///
    /// The default, `f64::INFINITY`, keeps every step that does not diverge, converged or
    /// not. 1e-3 (a strain, or a bend–twist angle per element, of 0.1 %) turns a step that far
    /// from its solution into smaller steps or, where none converges, into an error instead
    /// of an answer: above the haptic range (dt 1e-2 to 1e-1 s) every run of
    /// `docs/stiff-solver.md` then stays within 1e-3, but a driven rod whose relative frame
    /// rotations cross π (the discrete Darboux vector's limit, where the bend–twist constraint
    /// jumps) stops, where by default it continues with steps far from converged. Not the
    /// default because a haptic loop is better served by a step that is reported as
    /// unconverged than by a stop or by a step that takes 2⁸ times as long.
    pub halve_above: f64,
    /// Retake a step of an inextensible rod that ends unconverged (residual above the
    /// tolerance after [`iterations`](Self::iterations); direct solver only) with some element
    /// stretched or compressed beyond the tolerance, with the material's axial compliance
    /// `1/(E A)` instead of the exact inextensibility constraint. A straight inextensible rod
    /// pushed along its axis against a held far end has no solution (it can only shorten by
    /// buckling, which the linearised step does not produce): without the retry its steps end
    /// unconverged, with strains of several per cent, or diverge. Counted in
    /// [`StiffReport::axial_steps`](crate::StiffReport::axial_steps).
    pub axial_fallback: bool,
    /// Between the iterations of a step with mesh contacts, answer the query of a point that
    /// touched the mesh at its last query from that query when the point has moved too little
    /// since to change any decision about its contact (`stiff/contact.rs`, `detect`): the
    /// steps are the same as with every point queried after every iteration, and on the
    /// insertion scene the detection costs half of what it did at dt 1e-3 and a fifth at 1e-4
    /// (`docs/benchmarks/stiff-insertion.md`). `false` queries every point every time, for
    /// checking.
    pub reuse_contact_queries: bool,
    /// Contacts with the mesh and rod contacts' planes as unilateral rows of the Newton system,
    /// with normal impulses of their own (`stiff/rows.rs`; the default): each iteration solves
    /// the banded system with the contact points' full normal mobility and, through the Schur
    /// complement on the contact rows (one banded solve per contact at each factorisation), the
    /// complementarity of gaps and impulses, so no wall pulls within a solve. `false` holds
    /// contact points as pins of projected inverse mass `w (I − n nᵀ)` whose walls may pull
    /// within a round and are let go between rounds: on a stiff wire pressed on many
    /// neighbouring points at 1 ms the pulls alternate with pushes and the steps do not converge
    /// (the steel wire of the insertion at 1 mm elements: 640 of 2450 steps unconverged with
    /// pins, 1 with rows). Measured in `docs/stiff-solver.md` ("Contacts as rows of the
    /// solve"); TOML: `[solver.stiff] contact_rows = false` for pins.
    pub contact_rows: bool,
    /// Time integration: implicit Euler (the default) or BDF2 ([`Integrator`]).
    pub integrator: Integrator,
}

/// The compliance `α̃ = α / h²` of a constraint row of the stiff scheme with stiffness
/// `stiffness` over `length` (`α = 1/(k l)`), at step `h`; a zero stiffness gives a compliance so
/// large that the row's multiplier stays zero.
pub fn stiff_compliance(stiffness: f64, length: f64, h: f64) -> f64 {
    (1.0 / (stiffness * length)).min(1e300) / (h * h)
}

/// A row of the stiff scheme with compliance `alpha` (`α̃`) and Rayleigh damping `beta` of its
/// rate, at step `h` (Macklin et al. 2016, eq. 26): `(γ/(1 + γ), α̃/(1 + γ))` with `γ = α̃ h β`,
/// the damping fraction and the compliance of the row-scaled damped system, finite also for a
/// row without stiffness (α̃ huge, γ infinite) or an exact constraint (α̃ = 0); `(0, α̃)` without
/// damping.
pub fn stiff_damped_row(alpha: f64, beta: f64, h: f64) -> (f64, f64) {
    if beta > 0.0 {
        let g = alpha * h * beta;
        let frac = if g.is_finite() { g / (1.0 + g) } else { 1.0 };
        (frac, 1.0 / (1.0 / alpha + h * beta))
    } else {
        (0.0, alpha)
    }
}

impl Default for StiffSettings {
    /// Direct solve, one factorisation per step reused by its later iterations (falling back
    /// to Newton when an iteration contracts poorly, [`Refactor`]), with the geometric bound of
    /// the frames, iterating until the residual is at most 1e-5 (at most 8 iterations, at
    /// least one), the model's own frame inertia, contacts as rows of the solve: the settings
    /// measured in `docs/stiff-solver.md`. Steps that converge take 1–2 iterations; the cap of 8 (4
    /// before) lets the few that need more reach the tolerance: with 4 (and Newton), 17 of the
    /// suture's 10 000 pushed-and-twisted steps at 1e-3 ended above it (largest residual
    /// 1.4e-4); with 8, one did (1.6e-5).
    fn default() -> Self {
        Self {
            scheme: StiffScheme::Direct,
            iterations: 8,
            tolerance: 1e-5,
            refactor: Refactor::EveryStep,
            inertia_floor: 0.0,
            geometric: 1.0,
            max_halvings: 8,
            halve_above: f64::INFINITY,
            axial_fallback: true,
            reuse_contact_queries: true,
            contact_rows: true,
            integrator: Integrator::ImplicitEuler,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::LoadProfile;

    #[test]
    fn profiles_give_their_factors() {
        let ramp = LoadProfile::Ramp {
            start: 1.0,
            duration: 2.0,
        };
        assert_eq!(
            [0.5, 1.0, 2.0, 3.0, 9.0].map(|t| ramp.factor(t)),
            [0.0, 0.0, 0.5, 1.0, 1.0]
        );
        let sine = LoadProfile::Sine {
            offset: 0.5,
            amplitude: 2.0,
            frequency: 0.25,
            phase: 0.0,
        };
        assert!((sine.factor(1.0) - 2.5).abs() < 1e-15 && (sine.factor(3.0) + 1.5).abs() < 1e-15);
        assert_eq!(sine.max_factor(), 2.5);
        let table = LoadProfile::table(vec![[1.0, 2.0], [3.0, -2.0]]).unwrap();
        assert_eq!(
            [0.0, 1.0, 1.5, 3.0, 5.0].map(|t| table.factor(t)),
            [2.0, 2.0, 1.0, -2.0, -2.0]
        );
        assert_eq!(table.max_factor(), 2.0);
        for (bad, why) in [
            (vec![], "at least one"),
            (vec![[0.0, 1.0], [0.0, 2.0]], "must increase"),
            (vec![[0.0, f64::NAN]], "not finite"),
        ] {
            let e = LoadProfile::table(bad).unwrap_err();
            assert!(e.contains(why), "{e}");
        }
    }
}

/// How many GPUs a GPU backend spreads a simulation's rods over (each device steps a contiguous
/// share of the rods; no rod couples to a rod of another share).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gpus {
    /// This many distinct adapters; building fails if there are fewer, or fewer rods.
    Count(usize),
    /// Every distinct hardware adapter (or the software one where there is none), at most one
    /// per rod.
    All,
}

impl Default for Gpus {
    fn default() -> Self {
        Self::Count(1)
    }
}

impl std::fmt::Display for Gpus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Count(n) => write!(f, "{n}"),
            Self::All => f.write_str("all"),
        }
    }
}
