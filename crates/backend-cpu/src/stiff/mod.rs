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
//!    precess by the gyroscopic term (`(ω₁, ω₂)` turned by `h (J − I)/I ω₃`),
//!    `q̃ = q ⊗ exp(h ω / 2)`; held ends follow their prescribed motion;
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

mod binding;
mod clamp;
pub mod constraints;
mod contact;
mod direct;
mod lanes;
mod pin;
mod rod_contact;
mod rows;
mod work;
mod xpbd;

use crate::stepper::{
    CpuRod, DivergedQuantity, Divergence, Par, SolverSettings, StepStats, step_each,
};
use contact::StiffContacts;
use cosserat_model::quat::{exp_rotation, rotate};
use cosserat_model::{Quat, Real, Vec3};
use cosserat_problem::ends::EndKind;
use direct::{Assembled, BlockTridiagonal};
use lanes::{V3s, padded};
use rod_contact::RodPlanes;
use work::Work;

pub(crate) use cosserat_problem::{Integrator, Refactor, StiffReport, StiffScheme, StiffSettings};
pub use pin::STICK_SPEED;

pub use binding::{StiffBindings, step_bound_stiff};

/// Per-rod constants of the stiff scheme, in `f64`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Consts {
    pub(crate) l0: Vec<f64>,
    /// `1 / min l0`.
    inv_l0_max: f64,
    pub(crate) lbar: Vec<f64>,
    pub(crate) rest_u: Vec<Vec3<f64>>,
    pub(crate) inv_mass: Vec<f64>,
    /// Inverse inertias of the frames.
    pub(crate) inv_inertia: Vec<Vec3<f64>>,
    /// The clamps (`clamp.rs`), none for a rod without a clamped end.
    pub(crate) clamps: Vec<clamp::ClampConst>,
    /// Compliances `α̃` of the stretch–shear and bend–twist rows.
    pub(crate) alpha_gamma: Vec<Vec3<f64>>,
    pub(crate) alpha_omega: Vec<Vec3<f64>>,
    /// Whether any damping coefficient is positive.
    damped: bool,
    /// The constants of the element-wise passes as padded columns (`lanes.rs`).
    pub(crate) cols: ConstCols,
    key: Option<ConstsKey>,
}

/// What [`Consts`] were built for: elements, step (and inertia floor), extensible mode, the kinds
/// of end, and which end points slide.
type ConstsKey = (usize, u64, bool, [EndKind; 2], [bool; 2]);

/// [`Consts`] as the element-wise passes read them: padded columns (`lanes.rs`) whose padding
/// keeps the extra lanes finite (unit lengths and inertias, zero inverse masses).
#[derive(Clone, Debug, Default)]
pub(crate) struct ConstCols {
    /// Per point.
    pub(crate) inv_mass: Vec<f64>,
    /// Per element.
    pub(crate) inv_l0: Vec<f64>,
    pub(crate) inv_l0_sq: Vec<f64>,
    /// Per node (`n − 1` entries; the last element's lane is padding).
    pub(crate) lbar: Vec<f64>,
    pub(crate) inv_lbar: Vec<f64>,
    pub(crate) rest_u: V3s,
    /// The compliances of the (row-scaled) damped Newton system, `α̃ / (1 + γ)` (equal to
    /// `alpha_gamma`, `alpha_omega` without damping), and the damping fractions `γ / (1 + γ)`
    /// with `γ = α β / h` per constraint row (Macklin et al. 2016, eq. 26; `β` the damping of
    /// the constraint's rate, see [`Consts::rebuild`]).
    pub(crate) alpha_g: V3s,
    pub(crate) alpha_o: V3s,
    pub(crate) damp_g: V3s,
    pub(crate) damp_o: V3s,
    /// Per frame: the inertia, its own inverse (also for held frames: the gyroscopic term of
    /// the prediction), and 1 for a free frame, 0 for a held one.
    pub(crate) inertia: V3s,
    pub(crate) inv_inertia_own: V3s,
    pub(crate) free: Vec<f64>,
}

/// `v` as a column of `len ≥ v.len()` entries (padded, see `lanes.rs`), the rest `pad`.
fn column(v: &[f64], len: usize, pad: f64) -> Vec<f64> {
    let mut c = vec![pad; padded(len)];
    c[..v.len()].copy_from_slice(v);
    c
}

/// Scratch memory and cached constants of the stiff scheme for one rod; the caller owns one per
/// rod and passes it to every [`step_rod_stiff`] call. It sizes itself on first use, and
/// rebuilds its constants when the element count, `dt`, the mode or the kinds of end change.
/// Create a fresh one if a rod's parameters change in any other way.
#[derive(Clone, Debug, Default)]
pub struct StiffScratch {
    k: Consts,
    /// The constants for BDF2's implicit step of `2h/3` (`Integrator::Bdf2`), kept beside those
    /// for `h` so that neither is rebuilt as a run alternates between them.
    k_bdf2: Consts,
    w: Work,
    /// The constants of the extensible model, for steps retaken with the axial compliance.
    axial: Option<Consts>,
    assembled: Assembled,
    factor: BlockTridiagonal,
    factor_valid: bool,
    report: StiffReport,
    /// Contact with the rod's mesh, if it has one (`contact.rs`).
    contacts: Option<StiffContacts>,
    /// What a coupling (`binding.rs`) asks of the next step, and what it gets back.
    coupled: Coupled,
    /// The rod's rod-contact planes for the next step (`rod_contact.rs`); none without rod
    /// contacts.
    planes: RodPlanes,
}

/// A point held on a line for a step's solve: a guidewire point on the centreline of the
/// catheter it is bound in (`binding.rs`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LinePin {
    pub(crate) point: usize,
    /// A point of the line [m].
    pub(crate) origin: Vec3<f64>,
    /// Unit direction of the line.
    pub(crate) direction: Vec3<f64>,
}

/// The coupling's share of a step: lines to hold points on and forces to add, set before the
/// step; the force each line exerted, read after it. Empty for a rod that is not coupled, which
/// then pays nothing.
#[derive(Clone, Debug, Default)]
pub(crate) struct Coupled {
    pub(crate) lines: Vec<LinePin>,
    /// Forces on points [N], added to the rod's own loads.
    pub(crate) loads: Vec<(usize, Vec3<f64>)>,
    /// After an accepted step: the force [N] each entry of `lines` exerted on its point (zero
    /// for a point the line did not hold: a held end, or one an introducer guide holds).
    pub(crate) line_forces: Vec<Vec3<f64>>,
    /// Per point: its entry in `Work::pinned` (scratch of `binding::line_forces`).
    pub(crate) slot: Vec<usize>,
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

    /// The mesh's force on each point it held in the last step: point, unit normal into the
    /// lumen, force [N] (normal and friction); empty for a rod without a mesh.
    pub fn contact_forces(&self) -> impl Iterator<Item = (usize, [f64; 3], [f64; 3])> + '_ {
        self.contacts
            .iter()
            .flat_map(|c| c.forces())
            .map(|&(i, n, f)| (i, n.into(), f.into()))
    }

    /// Sizes the scratch for `rod` and builds its constants, so that the first step costs what
    /// the later ones do (a haptic loop's first tick; sizing and building on the first step
    /// took 1–2 ms at 1000 elements against 0.13–0.2 ms for a step). It takes one step of a
    /// copy of the rod (two with BDF2, whose second step is the first of `2h/3` and has
    /// constants of its own), which touches every buffer the step uses, and then forgets them:
    /// the steps that follow are bit for bit those of a fresh scratch. A step of the copy that
    /// diverges is ignored here (the real step reports it).
    pub fn prepare<T: Real>(
        &mut self,
        rod: &CpuRod<T>,
        settings: &SolverSettings<T>,
        stiff: &StiffSettings,
    ) {
        let mut copy = rod.clone();
        // BDF2's second step is its first of `2h/3`: built now too.
        let steps = if stiff.integrator == Integrator::Bdf2 {
            2
        } else {
            1
        };
        let _ = step_rod_stiff(&mut copy, settings, stiff, self, 0.0, 0, 0, steps);
        // What a step hands to the next: the shadow state, the multipliers that start the
        // geometric bound, a factorisation a lagged policy would reuse, and the counters.
        self.w.shadow = false;
        for l in &mut self.w.lambda_prev {
            l.fill_zero();
        }
        self.factor_valid = false;
        self.report = StiffReport::default();
        if let Some(c) = self.contacts.as_mut() {
            c.reset();
        }
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
pub(crate) fn angle_over_sin_half(s: &Quat<f64>) -> f64 {
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

/// The rotation from unit quaternion `from` to `to` in `from`'s body axes, `s = from̄ ⊗ to`,
/// with `s_w ≥ 0` (the shorter way round); its rotation vector is
/// `s_v · angle_over_sin_half(s)`.
pub(crate) fn relative_rotation(from: &Quat<f64>, to: &Quat<f64>) -> Quat<f64> {
    let s = from.conjugate() * to;
    if s.w < 0.0 { -s } else { s }
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

/// Whether the rod's state is exactly the rounding of the scratch's `f64` state.
fn shadow_matches<T: Real>(rod: &CpuRod<T>, w: &Work) -> bool {
    let s = &rod.state;
    s.frames.len() == w.n
        && s.positions.len() == w.n + 1
        && w.x.rounds_to(&s.positions)
        && w.v.rounds_to(&s.velocities)
        && w.q.rounds_to(&s.frames)
        && w.omega.rounds_to(&s.angular_velocities)
        && (0..2).all(|e| {
            let (a, b) = (&w.clamp_frames[e], &s.clamp_frames[e]);
            [a.w, a.i, a.j, a.k]
                .iter()
                .zip([b.w, b.i, b.j, b.k])
                .all(|(x, y)| T::lit(*x) == y)
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
            // A sliding end point keeps its mass (`CpuRod::new`).
            [0, 1].map(|e| rod.ends[e].slide_axis().is_some()),
        );
        if self.key == Some(key) {
            return;
        }
        let p = &rod.params;
        // A zero stiffness means no constraint: a compliance so large that λ stays zero.
        let compliance = |k: f64, l: f64| cosserat_problem::stiff_compliance(k, l, h);
        self.l0 = p.rest_lengths.iter().map(|l| l.to_f64()).collect();
        self.inv_l0_max = self.l0.iter().fold(0.0, |m, l| m.max(1.0 / l));
        self.lbar = (0..n.saturating_sub(1))
            .map(|j| p.node_length(j).to_f64())
            .collect();
        self.rest_u = p.rest_darboux.iter().map(v64).collect();
        self.inv_mass = p.inv_masses.iter().map(|w| w.to_f64()).collect();
        let inertia: Vec<Vec3<f64>> = (0..n)
            .map(|j| {
                let l = self.l0[j];
                let own = v64(&p.inertias[j]);
                // Element mass ρ A l = ρ I l · 4 / r² for the solid circular section.
                let r = p.radius.to_f64();
                let bar = floor * own.x * 4.0 / (r * r) * l * l / 12.0;
                own.map(|i| i.max(bar))
            })
            .collect();
        let inv_inertia_own: Vec<Vec3<f64>> = inertia.iter().map(|i| i.map(|x| 1.0 / x)).collect();
        self.inv_inertia = inv_inertia_own.clone();
        self.clamps.clear();
        for (end, frame) in [(0, 0), (1, n - 1)] {
            if rod.ends[end].holds_frame() {
                let node = &p.end_nodes[end];
                self.clamps.push(clamp::ClampConst {
                    end,
                    frame,
                    stiffness: v64(&node.stiffness),
                    rest: v64(&node.rest_darboux),
                    damping: node.damping.to_f64(),
                    length: p.end_node_length(end).to_f64(),
                });
            }
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
        let damp = |alpha: f64, beta: f64| cosserat_problem::stiff_damped_row(alpha, beta, h);
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
        // The columns of the lane passes; padding with unit lengths and inertias.
        let mut inertia = V3s::from_slice(&inertia);
        for i in n..inertia.x.len() {
            inertia.set(i, &Vec3::repeat(1.0));
        }
        let mut free = vec![0.0; padded(n)];
        // A clamped end frame is solved outside the lanes (`clamp.rs`).
        for (j, (f, w)) in free.iter_mut().zip(&self.inv_inertia).enumerate() {
            let clamped = self.clamps.iter().any(|c| c.frame == j);
            *f = if w.x == 0.0 || clamped { 0.0 } else { 1.0 };
        }
        let inv = |v: &[f64]| v.iter().map(|l| 1.0 / l).collect::<Vec<_>>();
        let inv_l0 = inv(&self.l0);
        let inv_l0_sq: Vec<f64> = inv_l0.iter().map(|i| i * i).collect();
        self.cols = ConstCols {
            inv_mass: column(&self.inv_mass, n + 1, 0.0),
            inv_l0: column(&inv_l0, n, 1.0),
            inv_l0_sq: column(&inv_l0_sq, n, 1.0),
            // Per node: the last element's lane is padding.
            lbar: column(&self.lbar, n, 0.0),
            inv_lbar: column(&inv(&self.lbar), n, 1.0),
            rest_u: V3s::from_slice(&self.rest_u),
            alpha_g: V3s::from_slice(&ag),
            alpha_o: V3s::from_slice(&aw),
            damp_g: V3s::from_slice(&dg),
            damp_o: V3s::from_slice(&dw),
            inertia,
            inv_inertia_own: V3s::from_slice(&inv_inertia_own),
            free,
        };
        self.key = Some(key);
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

/// Advances every rod by `steps` steps with the stiff scheme, each with its own scratch
/// (`scratches[i]` belongs to `rods[i]`), serially or spread over rayon's thread pool; the
/// rods do not interact, so both give the same states bit for bit. Fills `stats` with one
/// entry per rod. On divergence, returns that of the rod with the lowest index (with
/// [`Par::Rayon`] the other rods have still taken their steps).
///
/// # Panics
/// If `scratches` and `rods` differ in length.
pub fn step_rods_stiff<T: Real>(
    rods: &mut [CpuRod<T>],
    scratches: &mut [StiffScratch],
    settings: &SolverSettings<T>,
    stiff: &StiffSettings,
    time: f64,
    first_step: u64,
    steps: u64,
    par: Par,
    stats: &mut Vec<StepStats>,
) -> Result<(), Divergence> {
    assert_eq!(rods.len(), scratches.len(), "one stiff scratch per rod");
    if cfg!(feature = "rayon") && par == Par::Rayon {
        let mut pairs: Vec<_> = rods.iter_mut().zip(scratches.iter_mut()).collect();
        return step_each(&mut pairs, par, stats, |i, (rod, sc)| {
            step_rod_stiff(rod, settings, stiff, sc, time, i, first_step, steps)
        });
    }
    // Serially without collecting the pairs: nothing is allocated per call (a haptic loop
    // calls this every tick).
    stats.clear();
    for (i, (rod, sc)) in rods.iter_mut().zip(scratches).enumerate() {
        stats.push(step_rod_stiff(
            rod, settings, stiff, sc, time, i, first_step, steps,
        )?);
    }
    Ok(())
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
    scratch.report.halved_steps += 1;
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
    if scratch.contacts.is_none()
        && let Some(mesh) = rod.mesh.as_ref()
    {
        let radius = rod.params.radius.to_f64();
        scratch.contacts = Some(StiffContacts::new(mesh.settings.clone(), radius));
    }
    let StiffScratch {
        k: k_full,
        k_bdf2,
        w,
        axial,
        assembled,
        factor,
        factor_valid,
        report,
        contacts,
        coupled,
        planes,
    } = scratch;
    // Only a rod with a mesh (and the direct solver) pays for contacts.
    let mut contacts = contacts
        .as_mut()
        .filter(|_| rod.mesh.is_some() && stiff.scheme == StiffScheme::Direct);
    w.resize(n);
    // Continue from the f64 state of the last step if the rod still holds its rounding (no
    // one changed the state in between): rounding an f32 state at every step would leave a
    // residual of the order of f32's resolution that the tolerance sees as unconverged.
    if !(w.shadow && shadow_matches(rod, w)) {
        w.history = None;
        for i in 0..=n {
            w.x.set(i, &v64(&rod.state.positions[i]));
            w.v.set(i, &v64(&rod.state.velocities[i]));
        }
        for j in 0..n {
            let q = &rod.state.frames[j];
            let q = Quat::new(q.w.to_f64(), q.i.to_f64(), q.j.to_f64(), q.k.to_f64());
            w.q.set(j, &q);
            w.omega.set(j, &v64(&rod.state.angular_velocities[j]));
        }
        w.clamp_frames = rod
            .state
            .clamp_frames
            .map(|q| Quat::new(q.w.to_f64(), q.i.to_f64(), q.j.to_f64(), q.k.to_f64()));
    }
    let gravity = v64(&settings.gravity);
    let precision = T::default_epsilon().to_f64();
    let drag_rate = rod.params.drag.to_f64();
    let limit = settings.divergence_strain.to_f64();
    let bdf2 = stiff.integrator == Integrator::Bdf2 && stiff.scheme == StiffScheme::Direct;
    let mut stats = StepStats::none();
    let mut result = Ok(());
    // What the batch's steps report, added to `report` only if the batch is kept.
    let mut kept = StiffReport::default();
    if let Some(c) = contacts.as_deref_mut() {
        c.checkpoint();
    }
    for step in 0..steps {
        let t = time + step as f64 * h;
        // The step the implicit solve takes: `h`, or `2h/3` for a BDF2 step with history.
        let hs = if !bdf2 {
            h
        } else if w.history == Some(h) {
            w.extrapolate_bdf2();
            place_held_ends(w, rod, t, h, h - 2.0 * h / 3.0);
            2.0 * h / 3.0
        } else {
            w.keep_history();
            w.history = Some(h);
            h
        };
        if w.solved_with != Some(hs) {
            // A changed step changes the matrix a lagged factorisation was kept for.
            if w.solved_with.is_some() {
                *factor_valid = false;
            }
            w.solved_with = Some(hs);
        }
        let k: &mut Consts = if hs == h { k_full } else { k_bdf2 };
        // A no-op when the constants already are for this step and rod.
        k.rebuild(rod, hs, settings.extensible, stiff.inertia_floor);
        let drag = 1.0 / (1.0 + hs * drag_rate);
        let ctx = StepContext {
            rod,
            stiff,
            h: hs,
            advance: h,
            t,
            gravity: &gravity,
            precision,
            lines: &coupled.lines,
            loads: &coupled.loads,
        };
        let (mut residual, mut tolerance) = solve_step(
            &ctx,
            k,
            w,
            assembled,
            factor,
            factor_valid,
            report,
            contacts.as_deref_mut(),
            planes,
        );
        let unconverged = stiff.tolerance > 0.0 && !(residual <= tolerance);
        if unconverged
            && !settings.extensible
            && stiff.axial_fallback
            && stiff.scheme == StiffScheme::Direct
            && stretched_beyond(w, k, tolerance)
        {
            // The inextensible step has no solution (or Newton did not find it) and has left
            // the rod stretched or compressed beyond the tolerance: retake it with the
            // material's axial compliance (see `StiffSettings::axial_fallback`).
            w.restore_step_start();
            let ka = axial.get_or_insert_with(Consts::default);
            ka.rebuild(rod, hs, true, stiff.inertia_floor);
            *factor_valid = false;
            (residual, tolerance) = solve_step(
                &ctx,
                ka,
                w,
                assembled,
                factor,
                factor_valid,
                report,
                contacts.as_deref_mut(),
                planes,
            );
            *factor_valid = false;
            kept.axial_steps += 1;
        }
        if stiff.tolerance > 0.0
            && stiff.scheme == StiffScheme::Direct
            && !(residual <= stiff.halve_above.max(tolerance))
        {
            // Far from converged: not an answer. Retaken in halves by the caller, or
            // reported at the finest split.
            *factor_valid = false;
            w.history = None;
            result = Err(Divergence {
                rod: rod_index,
                element: worst_element(w, k),
                step: first_step + step,
                quantity: DivergedQuantity::Unconverged(residual),
            });
            break;
        }
        // The multipliers of the accepted step start the next one's geometric bound (a
        // retaken step starts from the same ones as its first try); the next step sets `lambda`
        // to zero before reading it.
        std::mem::swap(&mut w.lambda_prev, &mut w.lambda);
        if let Some(c) = contacts.as_deref_mut() {
            c.end_step(w, k);
        }
        w.clamp_finish(k);
        kept.steps += 1;
        if stiff.tolerance > 0.0 && !(residual <= tolerance) {
            kept.unconverged_steps += 1;
            kept.last_unconverged_step = Some(first_step + step);
        }
        kept.max_tolerance = kept.max_tolerance.max(tolerance);
        if residual > kept.max_residual {
            kept.max_residual = residual;
            kept.worst_step = first_step + step;
        }
        // 3. Velocities from the positions and frames. Drag of the medium, implicit
        // (`v (1 + h γ) = v_solved`) and applied after the solve so that it removes kinetic
        // energy without changing static equilibria.
        w.velocities(hs, drag);
        if rod.reaction.is_some() {
            record_reactions(rod, w, k, hs, h, t + 0.5 * h, &gravity, &coupled.loads);
        }
        if let Some(c) = contacts.as_deref_mut() {
            c.record_forces(w, k, &w.lambda_prev[0], hs);
        }
        if planes.is_active() {
            planes.record_forces(w, k, &w.lambda_prev[0], hs);
        }
        if !coupled.lines.is_empty() {
            binding::line_forces(w, k, hs, coupled);
        }
        // Divergence check, as the explicit stepper's, on squared stretches (`|r − 1| > limit`
        // is `r² > (1 + limit)²` or `r² < (1 − limit)²`).
        let (above, below) = ((1.0 + limit).powi(2), (1.0 - limit).max(0.0).powi(2));
        match w.stretch_range(k, above, below) {
            Ok((lo, hi)) => {
                stats.min_stretch = stats.min_stretch.min(lo.sqrt());
                stats.max_stretch = stats.max_stretch.max(hi.sqrt());
            }
            Err((element, r2)) => {
                let quantity = match r2 {
                    None => DivergedQuantity::NonFiniteFrame,
                    Some(r2) if !r2.is_finite() => DivergedQuantity::NonFinitePosition,
                    Some(r2) => DivergedQuantity::Strain((r2.sqrt() - 1.0).abs()),
                };
                *factor_valid = false;
                w.history = None;
                result = Err(Divergence {
                    rod: rod_index,
                    element,
                    step: first_step + step,
                    quantity,
                });
                break;
            }
        }
    }
    if result.is_err() && keep_start_on_divergence {
        // The caller retakes the batch from its start, which `rod.state` still holds.
        w.shadow = false;
        if let Some(c) = contacts.as_deref_mut() {
            c.restore();
        }
        return result.map(|()| stats);
    }
    report.steps += kept.steps;
    report.unconverged_steps += kept.unconverged_steps;
    report.axial_steps += kept.axial_steps;
    report.max_tolerance = report.max_tolerance.max(kept.max_tolerance);
    if kept.max_residual > report.max_residual {
        report.max_residual = kept.max_residual;
        report.worst_step = kept.worst_step;
    }
    report.last_unconverged_step = report.last_unconverged_step.max(kept.last_unconverged_step);
    w.x.write_to(&mut rod.state.positions);
    w.v.write_to(&mut rod.state.velocities);
    w.q.write_to(&mut rod.state.frames);
    w.omega.write_to(&mut rod.state.angular_velocities);
    for (out, q) in rod.state.clamp_frames.iter_mut().zip(&w.clamp_frames) {
        *out = Quat::new(T::lit(q.w), T::lit(q.i), T::lit(q.j), T::lit(q.k));
    }
    w.shadow = true;
    if let (Some(c), Some(mesh)) = (contacts, rod.mesh.as_mut()) {
        mesh.stats = c.stats;
    }
    result.map(|()| stats)
}

/// The reaction at the rod's held ends after an accepted step (see [`crate::reaction`]): the
/// held point's momentum balance `F = m (v − v_start)/h − m g − f_load − (J_rᵀ λ)/h²`, with
/// `Jᵀ λ / h²` the constraint forces of the implicit step (XPBD's multipliers are impulses
/// times the step), and for a clamped end the frame's, `τ = I (ω − ω_start)/h − (J_θᵀ λ)/h²`
/// in body axes. Uses this step's multipliers (`lambda_prev` once the step is accepted) and the
/// Jacobians of the last constraint evaluation. `h` is the implicit step, `advance` the time the
/// step advances the clock by (they differ for BDF2), over which the reaction is filtered.
fn record_reactions<T: Real>(
    rod: &mut CpuRod<T>,
    w: &Work,
    k: &Consts,
    h: f64,
    advance: f64,
    mid: f64,
    gravity: &Vec3<f64>,
    coupling_loads: &[(usize, Vec3<f64>)],
) {
    let n = w.n;
    let lam = &w.lambda_prev;
    let lit = |v: Vec3<f64>| Vec3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z));
    let h2 = h * h;
    let loads: [Vec3<f64>; 2] = [0, n].map(|p| {
        let own = rod
            .loads
            .iter()
            .filter(|l| l.point == p)
            .fold(Vec3::zeros(), |a, l| {
                a + v64(&l.force) * l.profile.factor(mid)
            });
        coupling_loads
            .iter()
            .filter(|l| l.0 == p)
            .fold(own, |a, l| a + l.1)
    });
    let Some(rx) = rod.reaction.as_deref_mut() else {
        return;
    };
    let ht = T::lit(h);
    for (e, (point, frame)) in [(0, 0), (n, n - 1)].into_iter().enumerate() {
        if !rx.held[e] {
            continue;
        }
        let m = rod.params.masses[point].to_f64();
        // `record_point` takes the force on the point (here gravity, loads and the
        // constraints') and the velocities before and after.
        let force = gravity * m + loads[e] + contact::constraint_impulse(w, k, &lam[0], point) / h2;
        rx.record_point(
            e,
            T::lit(m),
            lit(force),
            lit(w.v_start.get(point)),
            lit(w.v.get(point)),
            ht,
        );
        if rx.clamped[e]
            && let Some(i) = k.clamps.iter().position(|c| c.end == e)
        {
            let q = w.q.get(frame);
            rx.record_torque(e, lit(rotate(&q, &w.clamp_torque(k, i))));
        }
    }
    rx.finish([Vec3::zeros(); 2], [Vec3::zeros(); 2], T::lit(advance));
}

/// After BDF2's extrapolation (`Work::extrapolate_bdf2`, which leaves the state before it in
/// `x_prev`, `q_prev`): puts each held point at `x_n + lead V(t)` and each held frame at
/// `exp(lead Ω(t)) q_n`, `lead = h − 2h/3`, so that the implicit step of `2h/3`, which moves
/// them by their prescribed velocities (`solve_step`), ends where a step of `h` does. An
/// extrapolated held end would keep moving by a third of its last step after its motion stops.
fn place_held_ends<T: Real>(w: &mut Work, rod: &CpuRod<T>, t: f64, h: f64, lead: f64) {
    let n = w.n;
    for (i, end) in [(0, &rod.ends[0]), (n, &rod.ends[1])] {
        if end.holds_point() {
            let v = v64(&end.velocities_over(t, h).0);
            let mut x = w.x_prev.get(i) + v * lead;
            // A sliding end keeps its extrapolated motion along its axis.
            if let Some(a) = end.slide_axis() {
                let a = v64(&a);
                x += a * a.dot(&(w.x.get(i) - x));
            }
            w.x.set(i, &x);
        }
    }
}

/// Holds each sliding end point (`EndCondition::slide`) on the line along its axis through its
/// starting guess for the step's solve, as a guided point is held on the guide's axis: its
/// inverse mass in the updates and the banded matrix becomes `w a aᵀ` (`Work::pin_blocks`), so
/// the rod and its loads move it along the axis and the prescribed motion across it. What holds
/// it there is the holder's reaction (`record_reactions`: the point's momentum balance, which
/// along a free axis is zero). A point another pin already holds is left to it.
fn pin_sliding_ends<T: Real>(w: &mut Work, rod: &CpuRod<T>) {
    let n = w.n;
    for (i, end) in [(0, &rod.ends[0]), (n, &rod.ends[1])] {
        let Some(a) = end.slide_axis() else { continue };
        if w.pinned.iter().any(|p| p.point == i) {
            continue;
        }
        w.pinned.push(pin::Pinned::on_line(i, v64(&a).normalize()));
    }
}

/// The element with the largest entry of the last right-hand side (bend–twist rows as angles,
/// as the residual measures them): where an unconverged step is furthest from its solution.
fn worst_element(w: &Work, k: &Consts) -> usize {
    let mut worst = (0, -1.0);
    for j in 0..w.n {
        let gamma = w.rhs[0].get(j).amax();
        let omega = k.lbar.get(j).map_or(0.0, |l| w.rhs[1].get(j).amax() * l);
        let v = gamma.max(omega);
        // NaN counts as the worst.
        if !(v <= worst.1) {
            worst = (j, if v.is_nan() { f64::INFINITY } else { v });
        }
    }
    worst.0
}

/// Whether some element of `w` is stretched or compressed by more than `strain` (or is not
/// finite).
fn stretched_beyond(w: &Work, k: &Consts, strain: f64) -> bool {
    match w.stretch_range(k, f64::INFINITY, 0.0) {
        Ok((lo, hi)) => 1.0 - lo.sqrt() > strain || hi.sqrt() - 1.0 > strain,
        Err(_) => true,
    }
}

/// What one step needs to know besides the scratch.
struct StepContext<'a, T: Real> {
    rod: &'a CpuRod<T>,
    stiff: &'a StiffSettings,
    h: f64,
    /// The time the step advances the clock by (`h` but for BDF2's steps of `2h/3`).
    advance: f64,
    /// Time at the start of the step.
    t: f64,
    gravity: &'a Vec3<f64>,
    /// Machine epsilon of the rod's precision.
    precision: f64,
    /// Lines a coupling holds points on, and forces it adds ([`Coupled`]).
    lines: &'a [LinePin],
    loads: &'a [(usize, Vec3<f64>)],
}

impl<T: Real> StepContext<'_, T> {
    /// The tolerance, raised to the strain the rod's own precision resolves: an `f32` rod
    /// stores positions to `ε |x|` (ε = 2⁻²³), i.e. strains to `ε max|x| / min l0` (1.2e-4
    /// for a metre-long rod of millimetre elements); iterating below that changes nothing
    /// the rod can hold. No change for `f64` (ε = 2.2e-16).
    fn tolerance(&self, k: &Consts, w: &Work) -> f64 {
        let stiff = self.stiff;
        if stiff.tolerance > 0.0 && self.precision > 1e-10 {
            let extent = (0..=w.n).fold(0.0_f64, |m, i| m.max(w.x.get(i).amax()));
            stiff.tolerance.max(self.precision * extent * k.inv_l0_max)
        } else {
            stiff.tolerance
        }
    }
}

/// Steps 1 and 2 of the module docs for one step: the prediction from the state in `w` and
/// the constraint solve with the constants `k`. Returns the last residual and the tolerance it
/// was held to.
fn solve_step<T: Real>(
    ctx: &StepContext<'_, T>,
    k: &Consts,
    w: &mut Work,
    assembled: &mut Assembled,
    factor: &mut BlockTridiagonal,
    factor_valid: &mut bool,
    report: &mut StiffReport,
    mut contacts: Option<&mut StiffContacts>,
    planes: &mut RodPlanes,
) -> (f64, f64) {
    let StepContext {
        rod,
        stiff,
        h,
        t,
        gravity,
        ..
    } = *ctx;
    let n = w.n;
    let direct = stiff.scheme == StiffScheme::Direct;
    // 1. Prediction: inertial targets x̃, q̃, and the starting guess of the iteration.
    if k.damped {
        // The constraints at the start of the step, for the damping's rate `(C − C_n)/h`.
        w.constraints(k);
        w.keep_constraint_values();
    }
    // Loads at the middle of the step, as the explicit scheme's.
    let mid = t + 0.5 * h;
    let loads = rod
        .loads
        .iter()
        .map(|l| (l.point, v64(&l.force) * l.profile.factor(mid)))
        .chain(ctx.loads.iter().copied());
    let ends = &rod.ends;
    // Also without clamps: a clamp released since the last step leaves none behind.
    let omega = [0, 1].map(|e| v64(&ends[e].velocities_over(t, h).1));
    w.clamp_begin(k, h, ctx.advance, omega);
    // Point moments enter the frames' implicit equations (`Work::rhs`), not their velocities.
    w.torques.clear();
    for l in rod.loads.iter().filter(|l| l.turns()) {
        let m = v64(&l.moment) * (l.profile.factor(mid) * h * h);
        for (frame, share) in crate::stepper::moment_shares(l.point, n) {
            w.torques.push((frame, m * share));
        }
    }
    w.predict(k, h, gravity, loads, direct, |w| {
        for (i, end) in [(0, &ends[0]), (n, &ends[1])] {
            if end.holds_point() {
                let mut v = v64(&end.velocities_over(t, h).0);
                // A sliding end keeps along its axis what gravity and its loads gave it; the
                // solve moves it along the axis only (`pin_sliding_ends`).
                if let Some(a) = end.slide_axis() {
                    let a = v64(&a);
                    v += a * a.dot(&w.v.get(i));
                }
                w.v.set(i, &v);
                // The direct solver starts where the velocities alone lead (the full
                // Newton system pulls it to the target); Gauss–Seidel XPBD has no `g`
                // term and starts at x̃.
                if direct {
                    w.x.set(i, &(w.x_old.get(i) + v * h));
                }
            }
        }
    });
    let tolerance = ctx.tolerance(k, w);
    if let Some(g) = rod.guide.as_ref() {
        contact::pin_guided(w, k, g);
    } else {
        w.pinned.clear();
    }
    if !ctx.lines.is_empty() {
        binding::pin_on_lines(w, k, ctx.lines);
    }
    pin_sliding_ends(w, rod);
    if let Some(c) = contacts.as_deref_mut() {
        c.begin_step(w, k, (t, h), rod.mesh.as_ref().map(|m| m.shapes()));
    }
    let planes_active = planes.is_active() && direct;
    if planes_active {
        planes.begin_step(w, k, h);
    }
    // 2. Constraint solve.
    w.contact_rows = stiff.contact_rows && direct;
    w.rows.valid = false;
    for c in &mut w.lambda {
        c.fill_zero();
    }
    w.lambda_zero = true;
    let mut used = 0;
    let mut residual = f64::NAN;
    match stiff.scheme {
        StiffScheme::Direct => {
            // Rounds of the solve: one, and one more each time the contacts change (at most
            // `contact::MAX_ROUNDS` more), continuing from the multipliers reached.
            // Each round after the first is solved to `contact::LOOSE_ROUND` times the
            // tolerance; only one whose contacts then hold still is finished at the tolerance
            // itself.
            let loosen = contacts.is_some() || planes_active;
            let mut loose = false;
            let mut first = true;
            let mut round = 0;
            // The residual before the last iteration: a round finished at the tolerance goes
            // on from the loose one's, so that a factorisation that no longer fits (an
            // iteration that reduced the residual by less than 4×) is still caught; a new
            // round starts afresh.
            let mut previous = f64::INFINITY;
            loop {
                let round_tolerance = if loose {
                    contact::LOOSE_ROUND * tolerance
                } else {
                    tolerance
                };
                let (r, u) = direct_solve(
                    stiff,
                    k,
                    w,
                    assembled,
                    factor,
                    factor_valid,
                    report,
                    round_tolerance,
                    first,
                    contacts.as_deref_mut(),
                    planes_active.then_some(&mut *planes),
                    &mut previous,
                );
                first = false;
                residual = r;
                used += u;
                if contacts.is_none() && !planes_active {
                    break;
                }
                let mut update = contact::Update {
                    resolve: false,
                    matrix_changed: false,
                };
                if let Some(c) = contacts.as_deref_mut() {
                    let reuse = stiff.reuse_contact_queries;
                    update = c.update(w, k, reuse);
                }
                if planes_active {
                    let u = planes.update(w, k);
                    update.resolve |= u.resolve;
                    update.matrix_changed |= u.matrix_changed;
                }
                if loose && !update.resolve && r <= tolerance {
                    break;
                }
                if loose && !update.resolve {
                    // The contacts held still at the loose tolerance: finish the round at the
                    // step's own. (The last round is never loose.)
                    loose = false;
                    if update.matrix_changed {
                        *factor_valid = false;
                    }
                    continue;
                }
                if !update.resolve || round == contact::MAX_ROUNDS {
                    break;
                }
                round += 1;
                loose = loosen && round < contact::MAX_ROUNDS;
                previous = f64::INFINITY;
                // A round that only changed the kinetic friction (the inertial targets) keeps
                // the factorisation; the iterations refactorise if they stall.
                if update.matrix_changed {
                    *factor_valid = false;
                }
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
    report.iterations = used;
    report.total_iterations += used as u64;
    report.residual = residual;
    (residual, tolerance)
}

/// The Newton iterations of one round of the direct solve (step 2 of the module docs), from
/// the multipliers in `w`; `first` for the first round of a step (the frames' geometric bound
/// then starts from the previous step's multipliers). Returns the last residual and the
/// iterations run.
fn direct_solve(
    stiff: &StiffSettings,
    k: &Consts,
    w: &mut Work,
    assembled: &mut Assembled,
    factor: &mut BlockTridiagonal,
    factor_valid: &mut bool,
    report: &mut StiffReport,
    tolerance: f64,
    first: bool,
    mut contacts: Option<&mut StiffContacts>,
    mut planes: Option<&mut RodPlanes>,
    previous: &mut f64,
) -> (f64, usize) {
    let mut used = 0;
    let mut residual = f64::NAN;
    // Whether the last iteration pinned points (the matrix changed).
    let mut pins_changed = false;
    for it in 0..=stiff.iterations {
        let last = it == stiff.iterations;
        if last && stiff.tolerance <= 0.0 {
            break;
        }
        w.constraints(k);
        let mut refactor = !*factor_valid
            || pins_changed
            || match stiff.refactor {
                Refactor::EveryIteration => true,
                Refactor::EveryStep => it == 0 && first,
                Refactor::Lagged => false,
            };
        if refactor && !last {
            w.precondition(k, stiff.geometric, first && it == 0);
        }
        residual = w.rhs(k).max(tolerance * w.friction_imbalance);
        // At least one iteration in every call, later rounds' too: with λ = 0 the
        // residual `C` of a compliant constraint is its strain, not the imbalance of its
        // force, so a gently bent rod would pass the test without being solved at all; and
        // the friction's imbalance is measured by an iteration's correction, so a round
        // after new normal impulses that stopped before iterating would keep the last
        // round's (a rope sliding down 35° at 0.1 ms fell 0.26 % behind the analytic slide).
        if (residual <= tolerance && it > 0) || last {
            break;
        }
        // An iteration that reduced the residual by less than 4×: a reused
        // factorisation no longer fits (the multipliers, hence the frames' geometric
        // bound, moved); refactorise with the current ones, as Newton would.
        if !refactor && residual > 0.25 * *previous {
            w.precondition(k, stiff.geometric, false);
            residual = w.rhs(k).max(tolerance * w.friction_imbalance);
            refactor = true;
        }
        if refactor {
            w.assemble(k, assembled);
            if !w.pinned.is_empty() {
                w.pin_blocks(k, assembled);
            }
            if !w.clamps.is_empty() {
                w.clamp_blocks(k, assembled);
            }
            factor.factor(assembled);
            *factor_valid = true;
            report.factorisations += 1;
            if w.contact_rows {
                let mut rows = std::mem::take(&mut w.rows);
                rows.build(w, k, factor);
                w.rows = rows;
            }
        }
        *previous = residual;
        factor.solve(&mut w.rhs);
        if w.contact_rows {
            // The contacts' impulses and `Δλ` together (`rows.rs`); rows built for other pins
            // (a round changed them without a new factorisation) are built again first.
            let mut rows = std::mem::take(&mut w.rows);
            if !rows.fits(w, k) {
                rows.build(w, k, factor);
            }
            rows.solve(w);
            w.rows = rows;
        }
        let max_move = contacts
            .as_deref()
            .map_or(f64::INFINITY, |c| c.max_iteration_move())
            .min(
                planes
                    .as_deref()
                    .map_or(f64::INFINITY, |p| p.max_iteration_move()),
            );
        w.apply(k, max_move);
        used += 1;
        pins_changed = contacts.as_deref_mut().is_some_and(|c| {
            c.catch_penetrations(w, k, stiff.reuse_contact_queries)
                .matrix_changed
        });
        if let Some(p) = planes.as_deref_mut() {
            pins_changed |= p.catch_penetrations(w, k).matrix_changed;
        }
    }
    (residual, used)
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
            let s = cosserat_model::darboux::relative_rotation(&Quat::identity(), &e);
            let rv = s.imag() * angle_over_sin_half(&s);
            assert!(
                (rv - v).amax() < 1e-15 * (1.0 + a),
                "log at {a}: {rv} vs {v}"
            );
            // The inverse of the first-order map of `apply_rotation`.
            let q0 = exp_rotation(&Vec3::new(0.3, -1.2, 0.7));
            let mut turned = q0;
            apply_rotation(&mut turned, &v);
            let s = q0.conjugate() * turned;
            assert!(
                (s.imag() * (2.0 * inv_w(&s)) - v).amax() < 1e-15 * (1.0 + a),
                "inverse map at {a}"
            );
        }
    }
}

#[cfg(test)]
mod damping_tests;
#[cfg(test)]
mod precision_tests;
