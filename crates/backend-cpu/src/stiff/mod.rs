//! A stiffness-independent time step: the rod's elasticity as compliant constraints (XPBD),
//! solved directly along the rod.
//!
//! The explicit scheme of the reference paper (section 2.1, `crate::stepper`) integrates forces
//! from the energies with semi-implicit Euler. Its stable step is bounded by the fastest
//! elastic mode, which for a thin stiff wire is the rotation of a frame (inertia `ρ I l`)
//! against the bending, torsion and parallel-penalty springs: `h ≲ l √(ρ/E)` and
//! `h ≲ r √(ρ/G)` (`cosserat_model::stability`), microseconds for nitinol, steel or a suture at
//! a millimetre per element. A haptic loop needs 0.1–1 ms.
//!
//! This module takes the same discrete rod (same state, parameters, end conditions and loads)
//! and moves its elastic energies into constraints with compliance, after
//! - Kugelstadt & Schömer (2016), *Position and orientation based Cosserat rods*: a
//!   stretch–shear constraint between the centreline and `d3` of each frame and a bend–twist
//!   constraint on the Darboux vector of neighbouring frames (their eqs. 31, 32; our
//!   [`constraints`]);
//! - Macklin, Müller & Chentanez (2016), *XPBD*: a constraint `C` with compliance `α` stands
//!   for the potential `½ Cᵀ α⁻¹ C`; with `α̃ = α / h²` each Newton step solves
//!   `(J M⁻¹ Jᵀ + α̃) Δλ = −(C + α̃ λ)` (their eqs. 9–12) and the step is implicit Euler in
//!   the positions, so no stiffness limits `h`;
//! - Deul, Kugelstadt, Weiler & Bender (2018), *Direct position-based solver for stiff rods*:
//!   that system is banded along a rod and is solved exactly in `O(n)` (`direct.rs`),
//!   which keeps the iteration count independent of the rod's length and stiffness.
//!
//! **Compliances** follow from the energies of `docs/model.md`, so a converged step has the
//! same static equilibrium as the explicit scheme: for element `j` with rest length `l0`,
//! `α_Γ = diag(1/(K_p l0), 1/(K_p l0), 1/(K_s l0))` (`K_p` is `G A` by default, `K_s = E A`);
//! in inextensible mode the third entry is zero, an exact constraint `d3 · e = l0` that is the
//! inextensibility condition up to the squared shear angle. For node `j` with length `l̄`,
//! `α_Ω = diag(1/(l̄ E I), 1/(l̄ E I), 1/(l̄ G J))`.
//!
//! **One step** (XPBD, Macklin et al. Algorithm 1, with rotations as in Kugelstadt & Schömer):
//! 1. predict `v += h (g + f/m)`, `v /= 1 + h γ` (drag, implicit), `x̃ = x + h v`; frames
//!    `ω += −h I⁻¹ (ω × I ω)`, `q̃ = q ⊗ exp(h ω / 2)`; held ends follow their prescribed
//!    motion;
//! 2. from `λ = 0`, iterate the constraint solve (direct or Gauss–Seidel), updating points by
//!    `u + M⁻¹ Jᵀ Δλ` and frames by the body rotation `u_θ + K_θ⁻¹ J_θᵀ Δλ` (the direct
//!    solver's Newton step, `Work::rhs`; `K_θ` is the frame inertia plus a bound of the
//!    constraints' geometric stiffness, [`StiffSettings::geometric`]), until the residual is
//!    below [`StiffSettings::tolerance`];
//! 3. `v = (x − x_old)/(h (1 + h γ))` (drag `γ` of the medium, implicit, after the solve so
//!    that it does not weaken static loads), `ω = log(q̄_old q)/h`.
//!
//! The solve always runs in `f64`, whatever the rod's precision; see `direct.rs` for why.
//!
//! **Internal damping** (`bend_damping`, `stretch_damping` of `RodParams`) enters the XPBD way
//! (Macklin et al. 2016, eq. 26): each constraint row with compliance `α` gets the Rayleigh
//! dissipation `½ β Ċ²` of the model's definition (`β = c_b l̄` on the bend–twist rows,
//! `β = c_s l0` on the stretch row in extensible mode) and solves
//! `C + α̃ λ + γ (C − C_n) = 0`, `γ = α β / h` (details in `Consts::rebuild`): implicit
//! Euler of the elastic and damping forces. `damping_tests.rs` checks the decay of a
//! cantilever's first bending mode and of a bar's first axial mode against the damped
//! oscillator of the model's definition. The Gauss–Seidel variant ([`StiffScheme::GaussSeidel`])
//! does not apply internal damping. Drag is applied to the solved velocities.

pub mod constraints;
mod direct;
mod xpbd;

use crate::ends::EndKind;
use crate::stepper::{CpuRod, DivergedQuantity, Divergence, SolverSettings, StepStats};
use constraints::{BendTwist, StretchShear, bend_twist, stretch_shear};
use cosserat_model::darboux::relative_rotation;
use cosserat_model::quat::exp_rotation;
use cosserat_model::{Quat, Real, Vec3};
use direct::{BlockTridiagonal, Masses};

/// How the constraints of a step are solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StiffScheme {
    /// All constraints of a rod at once, by the block-tridiagonal factorisation of Deul et al.
    /// (2018). Converges in a few iterations whatever the stiffness and length.
    #[default]
    Direct,
    /// XPBD with Gauss–Seidel sweeps, one constraint at a time (Macklin et al. 2016). Cheap per
    /// sweep, but needs many sweeps on long stiff rods; kept for comparison.
    GaussSeidel,
}

/// When the direct solver refactorises `J M⁻¹ Jᵀ + α̃`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Refactor {
    /// At every iteration: Newton's method, as Deul et al. do.
    EveryIteration,
    /// At the first iteration of every step, reused by the later ones (a chord method).
    #[default]
    EveryStep,
    /// Kept across steps and rebuilt only when an iteration fails to reduce the residual by a
    /// factor of 4. The matrix is written in body frames, so it depends only on the relative
    /// rotations of neighbouring frames and on the strains, not on the rod's rigid motion.
    Lagged,
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
    /// that part per frame from the multipliers (the previous step's on the first iteration);
    /// it steers the iteration only, the converged step does not depend on it. Measured in
    /// `docs/stiff-solver.md`: half the iterations for the same tolerance.
    pub geometric: f64,
    /// How many times a step that diverges may be split in two halves (recursively) before
    /// the divergence is reported; 0 reports it at once. A rod released far from its rest
    /// shape (a J-tip wire built straight: 0.3 rad of rest turn per 1 mm element of nitinol)
    /// moves so far in its first 1 ms step that the linearised step overshoots; its first steps
    /// are then taken in halves, quarters, …, and the rest at the full step.
    pub max_halvings: u32,
}

impl Default for StiffSettings {
    /// Direct solve, Newton (a factorisation per iteration) with the geometric bound of the
    /// frames, iterating until the residual is at most 1e-5 (at most 4 iterations, at least
    /// one), the model's own frame inertia: the settings measured in `docs/stiff-solver.md`.
    fn default() -> Self {
        Self {
            scheme: StiffScheme::Direct,
            iterations: 4,
            tolerance: 1e-5,
            refactor: Refactor::EveryIteration,
            inertia_floor: 0.0,
            geometric: 1.0,
            max_halvings: 8,
        }
    }
}

/// What the last step did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StiffReport {
    /// Iterations (or sweeps) run in the last step.
    pub iterations: usize,
    /// Largest residual at the last evaluation of the last step (see
    /// [`StiffSettings::tolerance`]); with `tolerance = 0` this is the residual before the
    /// last iteration.
    pub residual: f64,
    /// Factorisations since the scratch was created.
    pub factorisations: u64,
    /// Iterations (or sweeps) since the scratch was created.
    pub total_iterations: u64,
}

/// Per-rod constants of the stiff scheme, in `f64`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Consts {
    pub(crate) l0: Vec<f64>,
    inv_l0_sq: Vec<f64>,
    /// `1 / min l0`.
    inv_l0_max: f64,
    pub(crate) lbar: Vec<f64>,
    inv_lbar: Vec<f64>,
    pub(crate) rest_u: Vec<Vec3<f64>>,
    pub(crate) inv_mass: Vec<f64>,
    pub(crate) mass: Vec<f64>,
    pub(crate) inertia: Vec<Vec3<f64>>,
    pub(crate) inv_inertia: Vec<Vec3<f64>>,
    /// `1 / inertia` also for held frames (the gyroscopic term of the prediction).
    inv_inertia_own: Vec<Vec3<f64>>,
    pub(crate) alpha_gamma: Vec<Vec3<f64>>,
    pub(crate) alpha_omega: Vec<Vec3<f64>>,
    /// Internal damping (Macklin et al. 2016, eq. 26) with `γ = α β / h` per constraint row
    /// (`β` the damping of the constraint's rate, see [`Consts::rebuild`]): `γ / (1 + γ)`.
    damp_gamma: Vec<Vec3<f64>>,
    damp_omega: Vec<Vec3<f64>>,
    /// The compliances of the (row-scaled) damped Newton system, `α̃ / (1 + γ)`; equal to
    /// `alpha_gamma`, `alpha_omega` without damping.
    alpha_gamma_matrix: Vec<Vec3<f64>>,
    alpha_omega_matrix: Vec<Vec3<f64>>,
    /// Whether any damping coefficient is positive.
    damped: bool,
    key: Option<(usize, u64, bool, [EndKind; 2])>,
}

/// The working state of a step, in `f64`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Work {
    pub(crate) x: Vec<Vec3<f64>>,
    v: Vec<Vec3<f64>>,
    x_old: Vec<Vec3<f64>>,
    pub(crate) q: Vec<Quat<f64>>,
    q_old: Vec<Quat<f64>>,
    omega: Vec<Vec3<f64>>,
    force: Vec<Vec3<f64>>,
    /// Inertial targets `x̃`, `q̃` of the step.
    x_pred: Vec<Vec3<f64>>,
    q_pred: Vec<Quat<f64>>,
    /// `M⁻¹ g`-corrected displacements towards the targets (see [`Work::rhs`]).
    u_x: Vec<Vec3<f64>>,
    u_th: Vec<Vec3<f64>>,
    pub(crate) lambda: Vec<[f64; 6]>,
    ss: Vec<StretchShear<f64>>,
    bt: Vec<BendTwist<f64>>,
    rhs: Vec<[f64; 6]>,
    dtheta: Vec<Vec3<f64>>,
    inv_k: Vec<Vec3<f64>>,
    lambda_prev: Vec<[f64; 6]>,
    /// Whether every multiplier is zero (the first iteration of a step).
    lambda_zero: bool,
    /// Constraint values `(Γ, Ω)` at the start of the step (for damping only).
    c_old: Vec<[f64; 6]>,
    /// Whether `x`, `v`, `q`, `omega` hold the state the last step left (in `f64`); the next
    /// step continues from them when the rod's state is still their rounding to its precision,
    /// so that an `f32` rod is not re-rounded between steps (see [`step_rod_stiff`]).
    shadow: bool,
}

/// Scratch memory and cached constants of the stiff scheme for one rod; the caller owns one per
/// rod and passes it to every [`step_rod_stiff`] call. It sizes itself on first use, and
/// rebuilds its constants when the element count, `dt`, the mode or the kinds of end change.
/// Create a fresh one if a rod's parameters change in any other way.
#[derive(Clone, Debug, Default)]
pub struct StiffScratch {
    k: Consts,
    w: Work,
    factor: BlockTridiagonal,
    factor_valid: bool,
    report: StiffReport,
}

impl StiffScratch {
    /// Empty scratch; sized on the first step.
    pub fn new() -> Self {
        Self::default()
    }

    /// What the last step did.
    pub fn report(&self) -> StiffReport {
        self.report
    }
}

/// `q ← normalise(q ⊗ (1, θ/2))`: a body-frame rotation by `θ`, to first order (the Newton
/// iteration evaluates its residual exactly, so the map only has to be consistent).
#[inline(always)]
pub(crate) fn apply_rotation(q: &mut Quat<f64>, theta: &Vec3<f64>) {
    let r = *q * Quat::new(1.0, 0.5 * theta.x, 0.5 * theta.y, 0.5 * theta.z);
    *q = r / r.norm();
}

/// `exp(v / 2)` as [`exp_rotation`], by its Taylor series below 1e-2 rad (error below 1e-20,
/// no `sin`/`cos`: a frame turns by milliradians per step).
#[inline(always)]
fn exp_small(v: &Vec3<f64>) -> Quat<f64> {
    let a2 = v.norm_squared();
    if a2 >= 1e-4 {
        return exp_rotation(v);
    }
    let h2 = 0.25 * a2;
    let c = 1.0 - h2 * (0.5 - h2 * (1.0 / 24.0 - h2 / 720.0));
    let s = 0.5 * (1.0 - h2 * (1.0 / 6.0 - h2 * (1.0 / 120.0 - h2 / 5040.0)));
    Quat::new(c, v.x * s, v.y * s, v.z * s)
}

/// For a unit quaternion `s` with `s_w ≥ 0`: `angle / |s_v|` with `angle = 2 atan2(|s_v|, s_w)`,
/// so that `s_v · angle / |s_v|` is its rotation vector; a series below 1e-2 rad.
#[inline(always)]
fn angle_over_sin_half(s: &Quat<f64>) -> f64 {
    let sn2 = s.imag().norm_squared();
    if sn2 < 1e-4 && (s.w * s.w + sn2 - 1.0).abs() < 1e-12 {
        // For a unit quaternion angle = 2 asin|s_v|, and 2 asin(x)/x = 2 (1 + x²/6 + 3x⁴/40
        // + 5x⁶/112 + 35x⁸/1152 + O(x¹⁰)): no division.
        return 2.0 + sn2 * (1.0 / 3.0 + sn2 * (0.15 + sn2 * (5.0 / 56.0 + sn2 * (35.0 / 576.0))));
    }
    if sn2 < 1e-4 * s.w * s.w {
        // atan(t)/t = 1 − t²/3 + t⁴/5 − t⁶/7 + O(t⁸), t = |s_v| / s_w.
        let t2 = sn2 / (s.w * s.w);
        return 2.0 / s.w * (1.0 - t2 * (1.0 / 3.0 - t2 * (0.2 - t2 / 7.0)));
    }
    let sn = sn2.sqrt();
    2.0 * sn.atan2(s.w) / sn
}

/// `r / |r|` for a quaternion whose norm is 1 up to rounding: one Newton step of `1/√x` at
/// 1 (relative error `3/8 ε²` for `|r|² = 1 + ε`), the exact division otherwise.
#[inline(always)]
fn renormalise(r: Quat<f64>) -> Quat<f64> {
    let e = r.norm_squared() - 1.0;
    if e.abs() < 1e-7 {
        r * (1.0 - 0.5 * e)
    } else {
        r / r.norm()
    }
}

/// [`apply_rotation`] without a square root or division for rotations below 2e-2 rad: the
/// rotation `(1, θ/2)` scaled by the series of `1/√(1 + |θ|²/4)` (error below 1e-16), then
/// [`renormalise`].
#[inline(always)]
fn apply_small_rotation(q: &mut Quat<f64>, theta: &Vec3<f64>) {
    let a = 0.25 * theta.norm_squared();
    if a >= 1e-4 {
        return apply_rotation(q, theta);
    }
    let s = 1.0 - a * (0.5 - a * (0.375 - a * 0.3125));
    let hs = 0.5 * s;
    *q = renormalise(*q * Quat::new(s, hs * theta.x, hs * theta.y, hs * theta.z));
}

/// `1 / s_w` for a unit quaternion by the series of `(1 − |s_v|²)^(−1/2)` when `|s_v|² < 1e-4`
/// (error below 1e-20), by division otherwise (and 1 when `s_w` is nearly zero).
#[inline(always)]
fn inv_w(s: &Quat<f64>) -> f64 {
    let x2 = s.imag().norm_squared();
    if x2 < 1e-4 && (s.w * s.w + x2 - 1.0).abs() < 1e-12 {
        return 1.0 + x2 * (0.5 + x2 * (0.375 + x2 * (0.3125 + x2 * 0.2734375)));
    }
    if s.w.abs() > 1e-12 { 1.0 / s.w } else { 1.0 }
}

fn v64<T: Real>(v: &Vec3<T>) -> Vec3<f64> {
    Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64())
}

fn vt<T: Real>(v: &Vec3<f64>) -> Vec3<T> {
    Vec3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z))
}

fn qt<T: Real>(q: &Quat<f64>) -> Quat<T> {
    Quat::new(T::lit(q.w), T::lit(q.i), T::lit(q.j), T::lit(q.k))
}

/// Whether the rod's state is exactly the rounding of the scratch's `f64` state.
fn shadow_matches<T: Real>(rod: &CpuRod<T>, w: &Work) -> bool {
    let s = &rod.state;
    s.positions.len() == w.x.len()
        && s.frames.len() == w.q.len()
        && (0..w.x.len())
            .all(|i| vt::<T>(&w.x[i]) == s.positions[i] && vt::<T>(&w.v[i]) == s.velocities[i])
        && (0..w.q.len()).all(|j| {
            qt::<T>(&w.q[j]) == s.frames[j] && vt::<T>(&w.omega[j]) == s.angular_velocities[j]
        })
}

impl Consts {
    fn rebuild<T: Real>(&mut self, rod: &CpuRod<T>, h: f64, extensible: bool, floor: f64) {
        let n = rod.elements();
        let key = (
            n,
            h.to_bits() ^ floor.to_bits().rotate_left(17),
            extensible,
            [rod.ends[0].kind, rod.ends[1].kind],
        );
        if self.key == Some(key) {
            return;
        }
        let p = &rod.params;
        let h2 = h * h;
        // A zero stiffness means no constraint: a compliance so large that λ stays zero.
        let compliance = |k: f64, l: f64| (1.0 / (k * l)).min(1e300) / h2;
        self.l0 = p.rest_lengths.iter().map(|l| l.to_f64()).collect();
        self.inv_l0_sq = self.l0.iter().map(|l| 1.0 / (l * l)).collect();
        self.inv_l0_max = self.l0.iter().fold(0.0, |m, l| m.max(1.0 / l));
        self.lbar = (0..n.saturating_sub(1))
            .map(|j| p.node_length(j).to_f64())
            .collect();
        self.inv_lbar = self.lbar.iter().map(|l| 1.0 / l).collect();
        self.rest_u = p.rest_darboux.iter().map(v64).collect();
        self.inv_mass = p.inv_masses.iter().map(|w| w.to_f64()).collect();
        self.mass = p.masses.iter().map(|m| m.to_f64()).collect();
        self.inertia = (0..n)
            .map(|j| {
                let l = self.l0[j];
                let own = v64(&p.inertias[j]);
                // Element mass ρ A l = ρ I l · 4 / r² for the solid circular section.
                let r = p.radius.to_f64();
                let bar = floor * own.x * 4.0 / (r * r) * l * l / 12.0;
                own.map(|i| i.max(bar))
            })
            .collect();
        self.inv_inertia = self.inertia.iter().map(|i| i.map(|x| 1.0 / x)).collect();
        self.inv_inertia_own = self.inv_inertia.clone();
        if rod.ends[0].holds_frame() {
            self.inv_inertia[0] = Vec3::zeros();
        }
        if rod.ends[1].holds_frame() {
            self.inv_inertia[n - 1] = Vec3::zeros();
        }
        self.alpha_gamma = (0..n)
            .map(|j| {
                let (l, kp) = (self.l0[j], p.parallel_stiffness[j].to_f64());
                let stretch = if extensible {
                    compliance(p.stretch_stiffness[j].to_f64(), l)
                } else {
                    0.0
                };
                Vec3::new(compliance(kp, l), compliance(kp, l), stretch)
            })
            .collect();
        self.alpha_omega = (0..n.saturating_sub(1))
            .map(|j| {
                let k = v64(&p.bend_twist_stiffness[j]);
                let l = self.lbar[j];
                Vec3::new(compliance(k.x, l), compliance(k.y, l), compliance(k.z, l))
            })
            .collect();
        // Internal damping, the XPBD way (Macklin et al. 2016, eq. 26): a constraint `C` with
        // compliance `α` and a Rayleigh dissipation `½ Ċᵀ β Ċ` solves
        // `C + α̃ λ + γ (C − C_n) = 0` with `γ = α β / h`, `C_n` its value at the start of the
        // step: implicit Euler of the elastic force plus the damping force `−Jᵀ β Ċ` with the
        // rate `Ċ = (C − C_n)/h`. The model's dissipation (`cosserat_model::energy`) is
        // `½ c_b |ω_b − ω_a|² / l̄` per node, and `Ω̇ = (ω_b − ω_a)/l̄` (body components) to first
        // order in the relative rotation, so `β_Ω = c_b l̄` on all three rows and
        // `γ = c_b / (K_k h)`; stretching (extensible mode only, as in the model) is
        // `½ c_s l0 ε̇²` with `ε̇ = Γ̇₃` to first order in the shear, so `β = c_s l0` on the third
        // row of `Γ` and `γ = c_s / (K_s h)`. The shear rows carry no damping (the model has
        // none).
        // Per row: (γ/(1 + γ), α̃/(1 + γ)) from α̃ and β, finite also for a row without
        // stiffness (α̃ huge, γ infinite) or an exact constraint (α̃ = 0).
        let damp = |alpha: f64, beta: f64| -> (f64, f64) {
            if beta > 0.0 {
                let g = alpha * h * beta;
                let frac = if g.is_finite() { g / (1.0 + g) } else { 1.0 };
                (frac, 1.0 / (1.0 / alpha + h * beta))
            } else {
                (0.0, alpha)
            }
        };
        let (mut dg, mut ag) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for j in 0..n {
            let beta = if extensible {
                p.stretch_damping[j].to_f64() * self.l0[j]
            } else {
                0.0
            };
            let a = self.alpha_gamma[j];
            let (f, m) = damp(a.z, beta);
            dg.push(Vec3::new(0.0, 0.0, f));
            ag.push(Vec3::new(a.x, a.y, m));
        }
        let (mut dw, mut aw) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for j in 0..n.saturating_sub(1) {
            let beta = p.bend_damping[j].to_f64() * self.lbar[j];
            let a = self.alpha_omega[j];
            let r = [damp(a.x, beta), damp(a.y, beta), damp(a.z, beta)];
            dw.push(Vec3::new(r[0].0, r[1].0, r[2].0));
            aw.push(Vec3::new(r[0].1, r[1].1, r[2].1));
        }
        self.damped = dg.iter().chain(&dw).any(|d| d.amax() > 0.0);
        (self.damp_gamma, self.alpha_gamma_matrix) = (dg, ag);
        (self.damp_omega, self.alpha_omega_matrix) = (dw, aw);
        self.key = Some(key);
    }
}

impl Work {
    fn resize(&mut self, n: usize) {
        if self.q.len() == n && self.x.len() == n + 1 {
            return;
        }
        self.shadow = false;
        let z = Vec3::zeros();
        self.x = vec![z; n + 1];
        self.v = vec![z; n + 1];
        self.x_old = vec![z; n + 1];
        self.force = vec![z; n + 1];
        self.x_pred = vec![z; n + 1];
        self.u_x = vec![z; n + 1];
        self.u_th = vec![z; n];
        self.q_pred = vec![Quat::identity(); n];
        self.q = vec![Quat::identity(); n];
        self.q_old = vec![Quat::identity(); n];
        self.omega = vec![z; n];
        self.dtheta = vec![z; n];
        self.lambda = vec![[0.0; 6]; n];
        self.lambda_prev = vec![[0.0; 6]; n];
        self.inv_k = vec![z; n];
        self.rhs = vec![[0.0; 6]; n];
        self.c_old = vec![[0.0; 6]; n];
        let m = nalgebra::Matrix3::zeros();
        self.ss = vec![
            StretchShear {
                value: z,
                d_rb: m,
                d_theta: m
            };
            n
        ];
        self.bt = vec![
            BendTwist {
                value: z,
                d_theta_a: m,
                d_theta_b: m
            };
            n.saturating_sub(1)
        ];
    }

    /// Evaluates every constraint and its Jacobian at the current iterate.
    fn constraints(&mut self, k: &Consts) {
        let n = k.l0.len();
        for j in 0..n {
            self.ss[j] = stretch_shear(&self.x[j], &self.x[j + 1], &self.q[j], k.l0[j]);
        }
        for j in 0..n.saturating_sub(1) {
            self.bt[j] = bend_twist(&self.q[j], &self.q[j + 1], &k.rest_u[j], k.lbar[j]);
        }
    }

    /// The frames' block `K_θ` of the Newton matrix: inertia plus an isotropic bound `σ_j` of
    /// the geometric stiffness `Σ λ ∇²_θθ C` that the constraints through frame `j` give it at
    /// the multipliers `lambda` (see [`StiffSettings::geometric`]); stores `K_θ⁻¹` in `inv_k`.
    ///
    /// Bounds, per unit multiplier, from the second derivatives of the constraints under
    /// body rotations: stretch–shear `½(λ gᵀ + g λᵀ) − (λ·g) I`, at most `2 |λ| |g|`;
    /// bend–twist, own frame `(λ·s_v)/(2 l̄)` and the neighbour coupling at most
    /// `|λ| (1 + 2|s_v|)/(2 l̄)`, together at most `|λ| / l̄` for small relative rotations.
    fn precondition(&mut self, k: &Consts, geometric: f64, use_previous: bool) {
        let n = k.l0.len();
        let lam = if use_previous {
            &self.lambda_prev
        } else {
            &self.lambda
        };
        let norm = |l: &[f64]| (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        // Bend–twist bound of the node before frame j.
        let mut before = 0.0;
        for j in 0..n {
            let l = &lam[j];
            let after = if j + 1 < n {
                norm(&l[3..]) * k.inv_lbar[j]
            } else {
                0.0
            };
            // |g| ≤ (1 + |g|²)/2, equal to second order in the strain (|g| = |e|/l0).
            let g = self.ss[j].value + Vec3::z();
            let g_bound = 0.5 * (1.0 + g.norm_squared());
            let sigma = geometric * (2.0 * norm(&l[..3]) * g_bound + before + after);
            before = after;
            self.inv_k[j] = if k.inv_inertia[j].x == 0.0 {
                Vec3::zeros()
            } else {
                // One division for the three inverses.
                let d = k.inertia[j].add_scalar(sigma);
                let inv = 1.0 / (d.x * d.y * d.z);
                Vec3::new(d.y * d.z * inv, d.x * d.z * inv, d.x * d.y * inv)
            };
        }
    }

    /// The right-hand side of one Newton step of the full XPBD system (Macklin et al. 2016,
    /// eqs. 9–11) at the constraints of the last [`constraints`](Self::constraints) call:
    ///
    /// `g = M (x − x̃) − Jᵀ λ`, `u = −K⁻¹ g`, `(J K⁻¹ Jᵀ + α̃) Δλ = −(C + α̃ λ + J u)`,
    /// `Δx = u + K⁻¹ Jᵀ Δλ`,
    ///
    /// with `K = M` for points and `K_θ = I + σ` for frames ([`precondition`](Self::precondition)).
    /// `K` only steers the iteration: its fixed point `g = 0`, `C + α̃ λ = 0` does not depend
    /// on it. Keeping `g` (which the simplified XPBD update drops) makes that fixed point the
    /// exact implicit-Euler step `M (x − x̃) = J(x)ᵀ λ` whatever the starting guess, so the
    /// iteration can start from the positions the velocities alone would reach and loads need
    /// not be folded into a far-away first guess. For frames, `x − x̃` is the body rotation
    /// from `q̃` to `q` in the first-order map of [`apply_rotation`].
    ///
    /// Stores the right-hand side in `rhs` and returns the largest of `|C + α̃ λ|` and `|J u|`
    /// (strains, and bend–twist as angles `l̄ |ΔΩ|`).
    fn rhs(&mut self, k: &Consts) -> f64 {
        let n = k.l0.len();
        // u = x̃ − x + M⁻¹ Jᵀ λ.
        for i in 0..=n {
            self.u_x[i] = self.x_pred[i] - self.x[i];
        }
        if self.lambda_zero {
            self.dtheta.fill(Vec3::zeros());
        } else {
            add_jt(
                &self.ss,
                &self.bt,
                &self.lambda,
                &k.inv_mass,
                &mut self.u_x,
                &mut self.dtheta,
            );
        }
        for j in 0..n {
            let s = self.q[j].conjugate() * self.q_pred[j];
            let to_target = s.imag() * (2.0 * inv_w(&s));
            self.u_th[j] = to_target + self.dtheta[j].component_mul(&self.inv_k[j]);
        }
        // One pass per element; the largest residual per element first, so that the running
        // maximum is one dependent operation per element.
        let mut worst: f64 = 0.0;
        for j in 0..n {
            let s = &self.ss[j];
            let ju = s.d_rb * (self.u_x[j + 1] - self.u_x[j]) + s.d_theta * self.u_th[j];
            let (lam, a) = (&self.lambda[j], &k.alpha_gamma_matrix[j]);
            let r = &mut self.rhs[j];
            let mut local: f64 = 0.0;
            for c in 0..3 {
                let mut res = s.value[c] + a[c] * lam[c];
                if k.damped {
                    // (C + α̃λ + γ (C − C_n)) / (1 + γ) = C + α̃λ/(1 + γ) − γ/(1 + γ) C_n: the
                    // damped residual, its rows scaled as the Newton matrix's (see
                    // `Consts::rebuild`).
                    res -= k.damp_gamma[j][c] * self.c_old[j][c];
                }
                r[c] = -(res + ju[c]);
                local = local.max(res.abs()).max(ju[c].abs());
            }
            if j + 1 < n {
                let b = &self.bt[j];
                let ju = b.d_theta_a * self.u_th[j] + b.d_theta_b * self.u_th[j + 1];
                let a = &k.alpha_omega_matrix[j];
                let mut bend: f64 = 0.0;
                for c in 0..3 {
                    let mut res = b.value[c] + a[c] * lam[3 + c];
                    if k.damped {
                        res -= k.damp_omega[j][c] * self.c_old[j][3 + c];
                    }
                    r[3 + c] = -(res + ju[c]);
                    bend = bend.max(res.abs()).max(ju[c].abs());
                }
                local = local.max(bend * k.lbar[j]);
            }
            worst = worst.max(local);
        }
        if n > 0 {
            self.rhs[n - 1][3..].fill(0.0);
        }
        worst
    }

    /// Applies the multiplier increments in `rhs` through the Jacobians of the last
    /// [`constraints`](Self::constraints): `Δx = u + M⁻¹ Jᵀ Δλ`, `Δθ = u_θ + K_θ⁻¹ J_θᵀ Δλ`; adds them
    /// to `λ`.
    fn apply(&mut self, k: &Consts) {
        let n = k.l0.len();
        add_jt(
            &self.ss,
            &self.bt,
            &self.rhs,
            &k.inv_mass,
            &mut self.u_x,
            &mut self.dtheta,
        );
        self.lambda_zero = false;
        for i in 0..=n {
            self.x[i] += self.u_x[i];
        }
        for j in 0..n {
            let th = self.u_th[j] + self.dtheta[j].component_mul(&self.inv_k[j]);
            apply_small_rotation(&mut self.q[j], &th);
            for c in 0..6 {
                self.lambda[j][c] += self.rhs[j][c];
            }
        }
    }
}

/// `u_x += M⁻¹ J_rᵀ μ` for the points and `dtheta = J_θᵀ μ` for the frames, in one pass along
/// the rod (`μ` per element: stretch–shear then bend–twist multipliers).
fn add_jt(
    ss: &[StretchShear<f64>],
    bt: &[BendTwist<f64>],
    mu: &[[f64; 6]],
    inv_mass: &[f64],
    u_x: &mut [Vec3<f64>],
    dtheta: &mut [Vec3<f64>],
) {
    let n = ss.len();
    // The bend–twist term of node j − 1 on frame j, carried to element j.
    let mut carry = Vec3::zeros();
    for j in 0..n {
        let m = &mu[j];
        let s = &ss[j];
        let lg = Vec3::new(m[0], m[1], m[2]);
        let f = s.d_rb.tr_mul(&lg);
        u_x[j] -= f * inv_mass[j];
        u_x[j + 1] += f * inv_mass[j + 1];
        let mut th = s.d_theta.tr_mul(&lg) + carry;
        if j + 1 < n {
            let lo = Vec3::new(m[3], m[4], m[5]);
            let b = &bt[j];
            th += b.d_theta_a.tr_mul(&lo);
            carry = b.d_theta_b.tr_mul(&lo);
        }
        dtheta[j] = th;
    }
}

/// Advances one rod by `steps` steps of `settings.dt` with the stiff scheme, starting at time
/// `time` and step index `first_step` (which only labels a [`Divergence`]).
///
/// Uses `rod.state`, `rod.params`, `rod.ends` and `rod.loads` exactly as
/// [`step_rod_batch`](crate::step_rod_batch) does; `settings.iterations` and
/// `settings.ordering` are the explicit scheme's and are ignored. `rod.state` is up to date when
/// this returns, also after a divergence. Bend and stretch damping are applied by the direct
/// solver (see the module docs).
///
/// A step that diverges is taken again as two half steps, recursively up to
/// [`StiffSettings::max_halvings`] times; the batch then continues at the full step. Only a
/// step that still diverges at the finest split is reported.
pub fn step_rod_stiff<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    stiff: &StiffSettings,
    scratch: &mut StiffScratch,
    time: f64,
    rod_index: usize,
    first_step: u64,
    steps: u64,
) -> Result<StepStats, Divergence> {
    let window = Window {
        time,
        rod_index,
        first_step,
        steps,
    };
    step_with_retries(rod, settings, stiff, scratch, window)
}

/// The steps of a call to [`step_rod_stiff`]: from `time`, step indices `first_step…` (which
/// only label a [`Divergence`]), `steps` of them.
#[derive(Clone, Copy, Debug)]
struct Window {
    time: f64,
    rod_index: usize,
    first_step: u64,
    steps: u64,
}

impl Window {
    /// `count` steps of `h` starting `skip` steps into this window.
    fn part(self, skip: u64, count: u64, h: f64) -> Self {
        Self {
            time: self.time + skip as f64 * h,
            first_step: self.first_step + skip,
            steps: count,
            ..self
        }
    }
}

/// [`step_rod_stiff`]: a batch that diverges is retaken from its start, the steps before the
/// failed one as before, the failed one in halves, the rest at the full step again.
fn step_with_retries<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    stiff: &StiffSettings,
    scratch: &mut StiffScratch,
    window: Window,
) -> Result<StepStats, Divergence> {
    let retry = stiff.max_halvings > 0 && window.steps > 0;
    let d = match step_fixed(rod, settings, stiff, scratch, window, retry) {
        Err(d) if retry => d,
        other => return other,
    };
    let failed = d
        .step
        .saturating_sub(window.first_step)
        .min(window.steps - 1);
    let h = settings.dt.to_f64();
    let mut stats = StepStats::none();
    if failed > 0 {
        let before = window.part(0, failed, h);
        stats = stats.merged(step_with_retries(rod, settings, stiff, scratch, before)?);
    }
    let at = window.part(failed, 1, h);
    stats = stats.merged(step_in_halves(rod, settings, stiff, scratch, at, 1)?);
    let rest = window.steps - failed - 1;
    if rest > 0 {
        let after = window.part(failed + 1, rest, h);
        stats = stats.merged(step_with_retries(rod, settings, stiff, scratch, after)?);
    }
    Ok(stats)
}

/// The one step of `window` (of `settings.dt`) taken as two halves, each split again if it
/// diverges, down to `2^-max_halvings` of the step. A divergence is reported at the step's
/// index.
fn step_in_halves<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    stiff: &StiffSettings,
    scratch: &mut StiffScratch,
    window: Window,
    depth: u32,
) -> Result<StepStats, Divergence> {
    let half = SolverSettings {
        dt: settings.dt / T::lit(2.0),
        ..*settings
    };
    let last = depth >= stiff.max_halvings;
    let both = Window { steps: 2, ..window };
    match step_fixed(rod, &half, stiff, scratch, both, !last) {
        Err(mut d) if last => {
            d.step = window.first_step;
            Err(d)
        }
        Err(_) => {
            let h = half.dt.to_f64();
            let a = step_in_halves(rod, &half, stiff, scratch, window, depth + 1)?;
            let later = Window {
                time: window.time + h,
                ..window
            };
            let b = step_in_halves(rod, &half, stiff, scratch, later, depth + 1)?;
            Ok(a.merged(b))
        }
        ok => ok,
    }
}

/// [`step_rod_stiff`] at the fixed step `settings.dt`. With `keep_start_on_divergence`, a
/// batch that diverges leaves `rod.state` as it was at its start (the state is written back
/// only at the end of a batch), so that it can be retaken without a copy.
fn step_fixed<T: Real>(
    rod: &mut CpuRod<T>,
    settings: &SolverSettings<T>,
    stiff: &StiffSettings,
    scratch: &mut StiffScratch,
    window: Window,
    keep_start_on_divergence: bool,
) -> Result<StepStats, Divergence> {
    let Window {
        time,
        rod_index,
        first_step,
        steps,
    } = window;
    let h = settings.dt.to_f64();
    let n = rod.elements();
    scratch
        .k
        .rebuild(rod, h, settings.extensible, stiff.inertia_floor);
    let StiffScratch {
        k,
        w,
        factor,
        factor_valid,
        report,
    } = scratch;
    w.resize(n);
    // Continue from the f64 state of the last step if the rod still holds its rounding (no
    // one changed the state in between): rounding an f32 state at every step would leave a
    // residual of the order of f32's resolution that the tolerance sees as unconverged.
    if !(w.shadow && shadow_matches(rod, w)) {
        for i in 0..=n {
            w.x[i] = v64(&rod.state.positions[i]);
            w.v[i] = v64(&rod.state.velocities[i]);
        }
        for j in 0..n {
            let q = &rod.state.frames[j];
            w.q[j] = Quat::new(q.w.to_f64(), q.i.to_f64(), q.j.to_f64(), q.k.to_f64());
            w.omega[j] = v64(&rod.state.angular_velocities[j]);
        }
    }
    w.force.fill(Vec3::zeros());
    for load in &rod.loads {
        w.force[load.point] += v64(&load.force);
    }
    let gravity = v64(&settings.gravity);
    let precision = T::default_epsilon().to_f64();
    let drag = 1.0 / (1.0 + h * rod.params.drag.to_f64());
    let limit = settings.divergence_strain.to_f64();
    let mut stats = StepStats::none();
    let mut result = Ok(());
    let held_points = [(0, &rod.ends[0]), (n, &rod.ends[1])];
    let held_frames = [(0, &rod.ends[0]), (n - 1, &rod.ends[1])];
    for step in 0..steps {
        let t = time + step as f64 * h;
        // 1. Prediction: inertial targets x̃, q̃, and the starting guess of the iteration.
        let direct = stiff.scheme == StiffScheme::Direct;
        if k.damped {
            // The constraints at the start of the step, for the damping's rate `(C − C_n)/h`.
            for j in 0..n {
                let c = &mut w.c_old[j];
                let g = stretch_shear(&w.x[j], &w.x[j + 1], &w.q[j], k.l0[j]).value;
                c[..3].copy_from_slice(g.as_slice());
                if j + 1 < n {
                    let o = bend_twist(&w.q[j], &w.q[j + 1], &k.rest_u[j], k.lbar[j]).value;
                    c[3..].copy_from_slice(o.as_slice());
                }
            }
        }
        for i in 0..=n {
            w.x_old[i] = w.x[i];
            // The direct solver starts where the velocities alone lead (the full Newton system
            // pulls it to the target); Gauss–Seidel XPBD has no `g` term and must start at x̃.
            if direct {
                w.x[i] += w.v[i] * h;
            }
            if k.inv_mass[i] > 0.0 {
                w.v[i] += (gravity + w.force[i] * k.inv_mass[i]) * h;
            }
        }
        for (i, end) in held_points {
            if end.holds_point() {
                w.v[i] = v64(&end.velocities_at(t).0);
                if direct {
                    w.x[i] = w.x_old[i] + w.v[i] * h;
                }
            }
        }
        for i in 0..=n {
            w.x_pred[i] = w.x_old[i] + w.v[i] * h;
            if !direct {
                w.x[i] = w.x_pred[i];
            }
        }
        for j in 0..n {
            w.q_old[j] = w.q[j];
            let (o, inertia) = (w.omega[j], k.inertia[j]);
            let gyro = o
                .cross(&inertia.component_mul(&o))
                .component_mul(&k.inv_inertia_own[j]);
            w.omega[j] = o - gyro * h;
            w.q[j] = renormalise(w.q[j] * exp_small(&(w.omega[j] * h)));
        }
        for (j, end) in held_frames {
            if end.holds_frame() {
                let omega = v64(&end.velocities_at(t).1);
                let r = exp_rotation(&(omega * h)) * w.q_old[j];
                w.q[j] = r / r.norm();
            }
        }
        w.q_pred.copy_from_slice(&w.q);
        // The tolerance, raised to the strain the rod's own precision resolves: an `f32` rod
        // stores positions to `ε |x|` (ε = 2⁻²³), i.e. strains to `ε max|x| / min l0` (1.2e-4
        // for a metre-long rod of millimetre elements); iterating below that changes nothing
        // the rod can hold. No change for `f64` (ε = 2.2e-16).
        let tolerance = if stiff.tolerance > 0.0 && precision > 1e-10 {
            let extent = w.x.iter().fold(0.0_f64, |m, x| m.max(x.amax()));
            stiff.tolerance.max(precision * extent * k.inv_l0_max)
        } else {
            stiff.tolerance
        };
        // 2. Constraint solve.
        w.lambda.fill([0.0; 6]);
        w.lambda_zero = true;
        let mut used = 0;
        let mut residual = f64::NAN;
        match stiff.scheme {
            StiffScheme::Direct => {
                let mut previous = f64::INFINITY;
                for it in 0..=stiff.iterations {
                    let last = it == stiff.iterations;
                    if last && stiff.tolerance <= 0.0 {
                        break;
                    }
                    w.constraints(k);
                    let mut refactor = !*factor_valid
                        || match stiff.refactor {
                            Refactor::EveryIteration => true,
                            Refactor::EveryStep => it == 0,
                            Refactor::Lagged => false,
                        };
                    if refactor && !last {
                        w.precondition(k, stiff.geometric, it == 0);
                    }
                    residual = w.rhs(k);
                    // At least one iteration: with λ = 0 the residual `C` of a compliant
                    // constraint is its strain, not the imbalance of its force, so a gently
                    // bent rod would pass the test without being solved at all.
                    if (residual <= tolerance && it > 0) || last {
                        break;
                    }
                    if !refactor && stiff.refactor == Refactor::Lagged && residual > 0.25 * previous
                    {
                        w.precondition(k, stiff.geometric, it == 0);
                        residual = w.rhs(k);
                        refactor = true;
                    }
                    if refactor {
                        let m = Masses {
                            inv_mass: &k.inv_mass,
                            inv_inertia: &w.inv_k,
                            alpha_gamma: &k.alpha_gamma_matrix,
                            alpha_omega: &k.alpha_omega_matrix,
                        };
                        factor.factor(&w.ss, &w.bt, &m);
                        *factor_valid = true;
                        report.factorisations += 1;
                    }
                    previous = residual;
                    factor.solve(&mut w.rhs);
                    w.apply(k);
                    used += 1;
                }
            }
            StiffScheme::GaussSeidel => {
                for _ in 0..stiff.iterations {
                    residual = xpbd::sweep(w, k);
                    used += 1;
                    if residual <= stiff.tolerance {
                        break;
                    }
                }
            }
        }
        w.lambda_prev.copy_from_slice(&w.lambda);
        report.iterations = used;
        report.total_iterations += used as u64;
        report.residual = residual;
        // 3. Velocities from the positions and frames.
        let inv_h = 1.0 / h;
        // Drag of the medium, implicit (`v (1 + h γ) = v_solved`) and applied after the solve so
        // that it removes kinetic energy without changing static equilibria.
        for i in 0..=n {
            w.v[i] = (w.x[i] - w.x_old[i]) * (inv_h * drag);
        }
        for j in 0..n {
            let s = relative_rotation(&w.q_old[j], &w.q[j]);
            let sv = s.imag();
            w.omega[j] = sv * (angle_over_sin_half(&s) * inv_h);
        }
        // Divergence check, as the explicit stepper's, on squared stretches (`|r − 1| > limit`
        // is `r² > (1 + limit)²` or `r² < (1 − limit)²`).
        let (mut lo, mut hi) = (f64::MAX, 0.0_f64);
        let (above, below) = ((1.0 + limit).powi(2), (1.0 - limit).max(0.0).powi(2));
        let mut bad = None;
        for j in 0..n {
            if !w.q[j].coords.iter().all(|c| c.is_finite()) {
                bad = Some((j, DivergedQuantity::NonFiniteFrame));
                break;
            }
            let r2 = (w.x[j + 1] - w.x[j]).norm_squared() * k.inv_l0_sq[j];
            if !r2.is_finite() {
                bad = Some((j, DivergedQuantity::NonFinitePosition));
                break;
            }
            if r2 > above || r2 < below {
                bad = Some((j, DivergedQuantity::Strain((r2.sqrt() - 1.0).abs())));
                break;
            }
            lo = lo.min(r2);
            hi = hi.max(r2);
        }
        let (lo, hi) = (lo.sqrt(), hi.sqrt());
        if let Some((element, quantity)) = bad {
            *factor_valid = false;
            result = Err(Divergence {
                rod: rod_index,
                element,
                step: first_step + step,
                quantity,
            });
            break;
        }
        stats.min_stretch = stats.min_stretch.min(lo);
        stats.max_stretch = stats.max_stretch.max(hi);
    }
    if result.is_err() && keep_start_on_divergence {
        // The caller retakes the batch from its start, which `rod.state` still holds.
        w.shadow = false;
        return result.map(|()| stats);
    }
    for i in 0..=n {
        rod.state.positions[i] = vt(&w.x[i]);
        rod.state.velocities[i] = vt(&w.v[i]);
    }
    for j in 0..n {
        rod.state.frames[j] = qt(&w.q[j]);
        rod.state.angular_velocities[j] = vt(&w.omega[j]);
    }
    w.shadow = true;
    result.map(|()| stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The series of the prediction and of the angular velocity equal the closed forms to
    /// rounding, on both sides of their switch.
    #[test]
    fn small_angle_series_match_closed_forms() {
        for a in [0.0, 1e-9, 1e-5, 3e-3, 9.9e-3, 1.01e-2, 0.3, 2.0] {
            let v = Vec3::new(0.6, -0.48, 0.64) * a;
            let (q, e) = (exp_small(&v), exp_rotation(&v));
            assert!((q.coords - e.coords).amax() < 1e-16, "exp at {a}");
            let s = relative_rotation(&Quat::identity(), &e);
            let rv = s.imag() * angle_over_sin_half(&s);
            assert!(
                (rv - v).amax() < 1e-15 * (1.0 + a),
                "log at {a}: {rv} vs {v}"
            );
            // The division-free forms used by the direct solver.
            let q0 = exp_rotation(&Vec3::new(0.3, -1.2, 0.7));
            let (mut fast, mut exact) = (q0, q0);
            apply_small_rotation(&mut fast, &v);
            apply_rotation(&mut exact, &v);
            assert!(
                (fast.coords - exact.coords).amax() < 1e-15,
                "rotation at {a}"
            );
            assert!((fast.norm() - 1.0).abs() < 1e-15, "norm at {a}");
            let s = q0.conjugate() * fast;
            assert!(
                (s.imag() * (2.0 * inv_w(&s)) - v).amax() < 1e-15 * (1.0 + a),
                "inverse map at {a}"
            );
        }
    }
}

#[cfg(test)]
mod damping_tests;
