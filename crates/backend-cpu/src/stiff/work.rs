//! The working state of a stiff step and its element-wise passes, four elements at a time
//! (`lanes.rs`). The formulas are those of `constraints.rs` and of the module docs of `stiff`;
//! `tests` at the bottom compares every pass with them, element by element.

use super::Consts;
use super::direct::Assembled;
use super::lanes::{F, Q, Q4s, V, V3s, below, load, mask_ge, padded, store};
use super::pin::{Pinned, perpendiculars};
use super::{angle_over_sin_half, exp_small, inv_w, relative_rotation};
use cosserat_model::Vec3;

/// The working state of a step, in `f64`, as padded columns.
#[derive(Clone, Debug, Default)]
pub(crate) struct Work {
    /// Elements.
    pub(crate) n: usize,
    pub(crate) x: V3s,
    pub(crate) v: V3s,
    pub(crate) x_old: V3s,
    pub(crate) q: Q4s,
    pub(crate) q_old: Q4s,
    pub(crate) omega: V3s,
    /// Velocities and angular velocities at the start of the step (for a retake).
    pub(crate) v_start: V3s,
    pub(crate) omega_start: V3s,
    /// Inertial targets `x̃`, `q̃` of the step.
    pub(crate) x_pred: V3s,
    pub(crate) q_pred: Q4s,
    /// `M⁻¹ g`-corrected displacements towards the targets (see [`Work::rhs`]).
    u_x: V3s,
    pub(crate) u_th: V3s,
    /// `J_θᵀ μ` per frame.
    pub(crate) dtheta: V3s,
    /// `K_θ⁻¹` per frame (see [`Work::precondition`]).
    pub(crate) inv_k: V3s,
    /// Per element at the current iterate: `Γ`, the directors (rows of `Rᵀ`), `Ω − û` and the
    /// relative rotation `s = q̄_j q_{j+1}` (`s_w ≥ 0`); the last element's `Ω`, `s` are unused.
    pub(crate) gamma: V3s,
    pub(crate) dirs: [V3s; 3],
    pub(crate) omega_c: V3s,
    pub(crate) rel: Q4s,
    /// Multipliers `(λ_Γ, λ_Ω)` per element, those of the previous step, the right-hand side
    /// (and, after the solve, the increments), and the constraint values at the start of the
    /// step (for damping only).
    pub(crate) lambda: [V3s; 2],
    pub(crate) lambda_prev: [V3s; 2],
    pub(crate) rhs: [V3s; 2],
    pub(crate) c_old: [V3s; 2],
    /// Whether every multiplier is zero (the first iteration of a step).
    pub(crate) lambda_zero: bool,
    /// Scratch of `add_jt`: the point term of element `j − 1` at `j` (`R μ_Γ / l0`), and the
    /// bend–twist term of node `j − 1` on frame `j`; of `precondition`: the bend–twist bound of
    /// node `j − 1` at `j`.
    f_before: V3s,
    tb_before: V3s,
    bound_before: Vec<f64>,
    /// Whether `x`, `v`, `q`, `omega` hold the state the last step left (see `step_fixed`).
    pub(crate) shadow: bool,
    /// BDF2's history (`Integrator::Bdf2`): the state one step before `x`, `v`, `q`, `omega`,
    /// and the step between them; `None` when there is none (the next step is implicit Euler).
    pub(crate) x_prev: V3s,
    pub(crate) v_prev: V3s,
    pub(crate) q_prev: Q4s,
    pub(crate) omega_prev: V3s,
    pub(crate) history: Option<f64>,
    /// The step the constants and the factorisation were last built for (`step_fixed`).
    pub(crate) solved_with: Option<f64>,
    /// Points held on a wall, a guide's axis or a line in this step (`contact.rs`,
    /// `rod_contact.rs`, `binding.rs`): their displacements are confined to what the pin
    /// allows (and, with friction, weighed by its tangential stiffness) in every update, and
    /// the Newton matrix is assembled with the same inverse masses
    /// ([`pin_blocks`](Self::pin_blocks)). Empty without any.
    pub(crate) pinned: Vec<Pinned>,
    /// Scratch of [`apply`](Self::apply): the pinned points' displacements before the update.
    pin_u: Vec<Vec3<f64>>,
    /// The largest correction a pinned point with friction still needs (its imbalance over its
    /// mass plus the law's own stiffness, `PinFriction::tangent`) over its holding slip `δ`,
    /// at the last [`rhs`](Self::rhs): a step has converged only when it is at most 1
    /// (`direct_solve`).
    /// The tolerance on strains alone leaves a slip well below an element's length unresolved
    /// (at 0.1 ms a rope's first step down a slope, 3e-8 m, is a strain of 3e-6 of its 1 cm
    /// elements), and with it whether friction holds or slides.
    pub(crate) friction_imbalance: f64,
    /// The clamp frames at the start of the step (`RodState::clamp_frames` in `f64`), and what
    /// each clamp carries through the step (`clamp.rs`; empty without clamps).
    pub(crate) clamp_frames: [cosserat_model::Quat<f64>; 2],
    pub(crate) clamps: Vec<super::clamp::ClampStep>,
    /// External moments of the step on frames, as (frame, `h² τ`) with `τ` [N m] in the world
    /// frame: generalised forces of the frames' implicit equations (see [`rhs`](Self::rhs)).
    /// Empty without point moments.
    pub(crate) torques: Vec<(usize, Vec3<f64>)>,
    /// Whether contacts on one plane are rows of the solve with multipliers of their own
    /// (`StiffSettings::contact_rows`, `rows.rs`) rather than pins of projected inverse mass.
    pub(crate) contact_rows: bool,
    /// Their Schur complement at the last factorisation.
    pub(crate) rows: super::rows::ContactRows,
}

/// `(1 − t) v_j + t v_{j+1}` for `(j, t)`.
fn lerp_points(v: &V3s, (j, t): (usize, f64)) -> Vec3<f64> {
    v.get(j) * (1.0 - t) + v.get(j + 1) * t
}

/// The starts `0, 4, 8, …` of the four-lane chunks below `end`.
fn chunks(end: usize) -> impl Iterator<Item = usize> {
    (0..end).step_by(4)
}

/// Calls `f(j + lane)` for each lane set in `bits` whose element is below `end`: the scalar
/// redo of the rare lanes a series does not cover.
#[inline(always)]
fn for_lanes(bits: u32, j: usize, end: usize, mut f: impl FnMut(usize)) {
    if bits & 0xf == 0 {
        return;
    }
    for lane in 0..4 {
        if bits & (1 << lane) != 0 && j + lane < end {
            f(j + lane);
        }
    }
}

impl Work {
    /// Whether pin `p` is a contact row (`rows.rs`): contact rows are on, and it is held on one
    /// plane (not a line or a crease).
    #[inline]
    pub(crate) fn is_row(&self, p: &Pinned) -> bool {
        self.contact_rows && !p.line && p.crease.is_none()
    }

    /// The normal impulse of pin `p` as the solve carries it, for a contact row the solve has
    /// held since its point last moved (`rows.rs`): its multiplier, exactly zero where the
    /// solve left it free. Its wall impulse `n · g` equals the multiplier only to rounding,
    /// and for a free row that rounding has either sign: read as a normal impulse, it let a
    /// free row stay pinned with an impulse of 1e-20 whose relative change from round to round
    /// asked for another round (`pin::NORMAL_CHANGE`). `None` for pins, and for a row put
    /// back on a wall since (its multiplier is the old wall's).
    pub(crate) fn row_impulse(&self, p: &Pinned) -> Option<f64> {
        (self.is_row(p) && p.row_normal == p.normal && p.row_x == self.x.get(p.point))
            .then_some(p.mult)
    }

    /// Whether letting go of pin `p` leaves the solve as it is: a contact row whose impulse
    /// the solve left at zero and whose friction has no normal impulse to act with.
    pub(crate) fn quietly_free(&self, p: &Pinned) -> bool {
        self.is_row(p) && p.mult == 0.0 && (p.friction.is_none() || p.pn == 0.0)
    }

    /// Per pin: `n · u` of its point (the normal part of its correction), for `rows.rs`.
    pub(crate) fn pin_normal_u(&self) -> Vec<f64> {
        self.pinned
            .iter()
            .map(|p| {
                let u = self.u_x.get(p.point);
                match p.partner {
                    Some(partner) if self.is_row(p) => {
                        p.normal.dot(&(u - lerp_points(&self.u_x, partner)))
                    }
                    _ => p.normal.dot(&u),
                }
            })
            .collect()
    }

    /// The closest point of a self-contact row's other side (`Pinned::partner`) at the
    /// current iterate.
    pub(crate) fn partner_x(&self, partner: (usize, f64)) -> Vec3<f64> {
        lerp_points(&self.x, partner)
    }

    /// Adds `−w_m c_m n p` to the corrections `u_x` of the other side's two points of every
    /// self-contact row (`Pinned::partner`), `p` its multiplier (`increment` false) or its
    /// last increment (`true`): the row's impulse on that side, split by the closest point's
    /// parameter (`c` = `1 − t`, `t`). With the multiplier (at each residual) also the
    /// reaction of the row's friction, and its slip is measured against the other side's
    /// motion at the iterate (the friction's start carried with it).
    fn partner_impulses(&mut self, k: &Consts, increment: bool) {
        if !self.contact_rows {
            return;
        }
        for s in 0..self.pinned.len() {
            let p = self.pinned[s];
            let Some((j, t)) = p.partner else { continue };
            if !self.is_row(&p) || k.inv_mass[p.point] == 0.0 {
                continue;
            }
            let mut push = p.normal * if increment { p.dmult } else { p.mult };
            if !increment && let Some(f) = p.friction {
                let moved = lerp_points(&self.x, (j, t)) - lerp_points(&self.x_old, (j, t));
                let start = self.x_old.get(p.point) + moved;
                if let Some(f) = self.pinned[s].friction.as_mut() {
                    f.start = start;
                }
                let slip = p.sliding_part(&(self.x.get(p.point) - start));
                push += f.impulse(&slip, p.pn);
            }
            if push == Vec3::zeros() {
                continue;
            }
            for (m, c) in [(j, 1.0 - t), (j + 1, t)] {
                let u = self.u_x.get(m) - push * (k.inv_mass[m] * c);
                self.u_x.set(m, &u);
            }
        }
    }

    /// Sizes the columns for `n` elements (a new state; nothing is kept) unless they already
    /// are.
    pub(crate) fn resize(&mut self, n: usize) {
        if self.n == n && !self.q.w.is_empty() {
            return;
        }
        self.n = n;
        self.shadow = false;
        let points = || V3s::zeros(n + 1);
        let frames = || V3s::zeros(n);
        self.x = points();
        self.v = points();
        self.x_old = points();
        self.v_start = points();
        self.omega_start = frames();
        self.x_pred = points();
        self.u_x = points();
        self.f_before = V3s::zeros(n + 2);
        self.q = Q4s::identities(n);
        self.q_old = Q4s::identities(n);
        self.q_pred = Q4s::identities(n);
        self.omega = frames();
        self.u_th = frames();
        self.dtheta = frames();
        self.inv_k = frames();
        self.tb_before = V3s::zeros(n + 1);
        self.bound_before = vec![0.0; padded(n + 1)];
        self.gamma = frames();
        self.dirs = [frames(), frames(), frames()];
        self.omega_c = frames();
        self.rel = Q4s::identities(n);
        self.lambda = [frames(), frames()];
        self.lambda_prev = [frames(), frames()];
        self.rhs = [frames(), frames()];
        self.c_old = [frames(), frames()];
        self.x_prev = points();
        self.v_prev = points();
        self.q_prev = Q4s::identities(n);
        self.omega_prev = frames();
        self.history = None;
        self.solved_with = None;
    }

    /// Keeps the current state as BDF2's history of the next step.
    pub(crate) fn keep_history(&mut self) {
        self.x_prev.copy_from(&self.x);
        self.v_prev.copy_from(&self.v);
        self.q_prev.copy_from(&self.q);
        self.omega_prev.copy_from(&self.omega);
    }

    /// A BDF2 step's start (`Integrator::Bdf2`): replaces the state `(x_n, v_n, q_n, ω_n)` by
    /// `x* = (4 x_n − x_{n−1})/3`, `v* = (4 v_n − v_{n−1})/3`, `q* = q_n ⊗ exp(φ/3)` with `φ`
    /// the body rotation from `q_{n−1}` to `q_n`, `ω* = (4 ω_n − ω_{n−1})/3`, and keeps
    /// `(x_n, v_n, q_n, ω_n)` as the history of the next step.
    pub(crate) fn extrapolate_bdf2(&mut self) {
        let n = self.n;
        let (four_thirds, minus_third) = (F::splat(4.0 / 3.0), F::splat(-1.0 / 3.0));
        let blend = |now: V, before: V| now.scale(four_thirds).add_scaled(before, minus_third);
        for i in chunks(n + 1) {
            let (x, v) = (self.x.load(i), self.v.load(i));
            self.x.store(i, blend(x, self.x_prev.load(i)));
            self.v.store(i, blend(v, self.v_prev.load(i)));
            self.x_prev.store(i, x);
            self.v_prev.store(i, v);
        }
        for j in chunks(n) {
            let (q, omega) = (self.q.load(j), self.omega.load(j));
            let s = self.q_prev.load(j).conj_mul(q).positive();
            // Lanes past 1e-2 rad are redone below.
            let (series, ok) = small_log(s);
            let turned = q.mul(small_exp(s.v.scale(series * F::splat(1.0 / 3.0))));
            // Other lanes: the closed forms, from the states before they are overwritten.
            let mut redone = [None; 4];
            for_lanes(!ok.to_bitmask(), j, n, |e| {
                let q = self.q.get(e);
                let s = relative_rotation(&self.q_prev.get(e), &q);
                let phi = s.imag() * angle_over_sin_half(&s);
                let r = q * exp_small(&(phi * (1.0 / 3.0)));
                redone[e - j] = Some(r / r.norm());
            });
            self.q.store(j, turned.normalised());
            self.omega.store(j, blend(omega, self.omega_prev.load(j)));
            self.q_prev.store(j, q);
            self.omega_prev.store(j, omega);
            for (k, r) in redone.iter().enumerate() {
                if let Some(r) = r {
                    self.q.set(j + k, r);
                }
            }
        }
    }

    /// Evaluates every constraint and its Jacobian at the current iterate.
    pub(crate) fn constraints(&mut self, k: &Consts) {
        let c = &k.cols;
        let e3 = V::splat(&Vec3::z());
        for j in chunks(self.n) {
            let (qa, qb) = (self.q.load(j), self.q.load(j + 1));
            let d = qa.directors();
            let e = self.x.load(j + 1) - self.x.load(j);
            let il = load(&c.inv_l0, j);
            let g = V {
                x: d[0].dot(e),
                y: d[1].dot(e),
                z: d[2].dot(e),
            }
            .scale(il);
            self.gamma.store(j, g - e3);
            for (col, dk) in self.dirs.iter_mut().zip(d) {
                col.store(j, dk);
            }
            let s = qa.conj_mul(qb).positive();
            self.rel.store(j, s);
            let two_over_l = load(&c.inv_lbar, j) * F::splat(2.0);
            self.omega_c
                .store(j, s.v.scale(two_over_l) - c.rest_u.load(j));
        }
    }

    /// Copies the constraint values of the last [`constraints`](Self::constraints) call into
    /// `c_old`.
    pub(crate) fn keep_constraint_values(&mut self) {
        self.c_old[0].copy_from(&self.gamma);
        self.c_old[1].copy_from(&self.omega_c);
    }

    /// The frames' block `K_θ` of the Newton matrix: inertia plus an isotropic bound `σ_j` of
    /// the geometric stiffness `Σ λ ∇²_θθ C` that the constraints through frame `j` give it at
    /// the multipliers `lambda` (see [`StiffSettings::geometric`](super::StiffSettings));
    /// stores `K_θ⁻¹` in `inv_k`.
    ///
    /// Bounds, per unit multiplier, from the second derivatives of the constraints under
    /// body rotations: stretch–shear `½(λ gᵀ + g λᵀ) − (λ·g) I`, at most `2 |λ| |g|`;
    /// bend–twist, own frame `(λ·s_v)/(2 l̄)` and the neighbour coupling at most
    /// `|λ| (1 + 2|s_v|)/(2 l̄)`, together at most `|λ| / l̄` for small relative rotations.
    ///
    /// The pinned points' friction is linearised here too ([`freeze_friction`](Self::freeze_friction)):
    /// both are the parts of the matrix taken from the current iterate.
    pub(crate) fn precondition(&mut self, k: &Consts, geometric: f64, use_previous: bool) {
        self.freeze_friction();
        let c = &k.cols;
        let lam = if use_previous {
            &self.lambda_prev
        } else {
            &self.lambda
        };
        let geometric_scalar = geometric;
        let geometric = F::splat(geometric);
        // The bend–twist bound of node j, |λ_Ω| / l̄, stored at j + 1 (zero for the last
        // element, whose λ_Ω is zero).
        for j in chunks(self.n) {
            let after = lam[1].load(j).norm2().sqrt() * load(&c.inv_lbar, j);
            store(&mut self.bound_before, j + 1, after);
        }
        let (half, one, e3) = (F::splat(0.5), F::ONE, V::splat(&Vec3::z()));
        for j in chunks(self.n) {
            let before = load(&self.bound_before, j);
            let after = load(&self.bound_before, j + 1);
            // |g| ≤ (1 + |g|²)/2, equal to second order in the strain (|g| = |e|/l0).
            let g = self.gamma.load(j) + e3;
            let g_bound = half * (one + g.norm2());
            let lg = lam[0].load(j).norm2().sqrt();
            let sigma = geometric * (F::splat(2.0) * lg * g_bound + before + after);
            // One division for the three inverses; zero for held frames.
            let i = c.inertia.load(j);
            let d = V {
                x: i.x + sigma,
                y: i.y + sigma,
                z: i.z + sigma,
            };
            let inv = load(&c.free, j) / (d.x * d.y * d.z);
            self.inv_k.store(
                j,
                V {
                    x: d.y * d.z * inv,
                    y: d.x * d.z * inv,
                    z: d.x * d.y * inv,
                },
            );
        }
        if !self.clamps.is_empty() {
            // The lanes' bound, in scalar, for the clamped end frames.
            let mut sigmas = [(usize::MAX, 0.0); 2];
            for (slot, cl) in sigmas.iter_mut().zip(&k.clamps) {
                let j = cl.frame;
                let g = self.gamma.get(j) + Vec3::z();
                let g_bound = 0.5 * (1.0 + g.norm_squared());
                let before = self.bound_before[j] + self.bound_before[j + 1];
                *slot = (
                    j,
                    geometric_scalar * (2.0 * lam[0].get(j).norm() * g_bound + before),
                );
            }
            self.clamp_precondition(k, |f| sigmas.iter().find(|s| s.0 == f).map_or(0.0, |s| s.1));
        }
    }

    /// `u_x += M⁻¹ J_rᵀ μ` for the points and `dtheta = J_θᵀ μ` for the frames (`μ` per
    /// element: stretch–shear in `mu[0]`, bend–twist in `mu[1]`; the last element's bend–twist
    /// entry is zero), with the Jacobians of the last [`constraints`](Self::constraints) call.
    ///
    /// `J_rᵀ μ_Γ = ∓ R μ_Γ / l0` on points `j`, `j + 1`; `J_θᵀ μ_Γ = [g]×ᵀ μ_Γ = μ_Γ × g`;
    /// bend–twist on frame `j`: `−(s_w μ + s_v × μ)/l̄`, on frame `j + 1`: `(s_w μ − s_v × μ)/l̄`.
    fn add_jt(&mut self, k: &Consts, mu: &[V3s; 2]) {
        let c = &k.cols;
        let e3 = V::splat(&Vec3::z());
        for j in chunks(self.n) {
            let (mg, mo) = (mu[0].load(j), mu[1].load(j));
            let il = load(&c.inv_l0, j);
            let d = [
                self.dirs[0].load(j),
                self.dirs[1].load(j),
                self.dirs[2].load(j),
            ];
            let f = d[0]
                .scale(mg.x)
                .add_scaled(d[1], mg.y)
                .add_scaled(d[2], mg.z)
                .scale(il);
            self.f_before.store(j + 1, f);
            let g = self.gamma.load(j) + e3;
            let s = self.rel.load(j);
            let ilb = load(&c.inv_lbar, j);
            let (sw_mu, sv_mu) = (mo.scale(s.w), s.v.cross(mo));
            let ta = (sw_mu + sv_mu).scale(-ilb);
            let tb = (sw_mu - sv_mu).scale(ilb);
            self.tb_before.store(j + 1, tb);
            self.dtheta.store(j, mg.cross(g) + ta);
        }
        for i in chunks(self.n + 1) {
            let w = load(&c.inv_mass, i);
            let f = self.f_before.load(i) - self.f_before.load(i + 1);
            let u = self.u_x.load(i).add_scaled(f, w);
            self.u_x.store(i, u);
        }
        for j in chunks(self.n) {
            let t = self.dtheta.load(j) + self.tb_before.load(j);
            self.dtheta.store(j, t);
        }
    }

    /// The right-hand side of one Newton step of the full XPBD system (Macklin et al. 2016,
    /// eqs. 9–11) at the constraints of the last [`constraints`](Self::constraints) call:
    ///
    /// `g = M (x − x̃) − Jᵀ λ`, `u = −K⁻¹ g`, `(J K⁻¹ Jᵀ + α̃) Δλ = −(C + α̃ λ + J u)`,
    /// `Δx = u + K⁻¹ Jᵀ Δλ`,
    ///
    /// with `K = M` for points and `K_θ = I + σ` for frames ([`precondition`](Self::precondition)).
    /// For the points `K` only steers the iteration: its fixed point `g = 0`, `C + α̃ λ = 0`
    /// does not depend on it. For the frames, `u_θ = (θ̃ − θ) + K_θ⁻¹ J_θᵀ λ` (rather than
    /// `K_θ⁻¹ (I (θ̃ − θ) + J_θᵀ λ)`) converges to `(I + σ)(θ − θ̃) = J_θᵀ λ`: `σ` adds a
    /// rotational inertia of order `h²` (`docs/stiff-solver.md`, item 6, says why the exact
    /// balance was not kept). Keeping `g` (which the simplified XPBD update drops) makes the
    /// fixed point the implicit-Euler step `M (x − x̃) = J(x)ᵀ λ` whatever the starting
    /// guess, so the iteration can start from the positions the velocities alone would reach
    /// and loads need not be folded into a far-away first guess. For frames, `x − x̃` is the
    /// body rotation from `q̃` to `q` in the first-order map of
    /// [`apply_rotation`](super::apply_rotation).
    ///
    /// Stores the right-hand side in `rhs` and returns the largest of `|C + α̃ λ|` and `|J u|`
    /// (strains, and bend–twist as angles `l̄ |ΔΩ|`).
    pub(crate) fn rhs(&mut self, k: &Consts) -> f64 {
        let n = self.n;
        let c = &k.cols;
        // u = x̃ − x + M⁻¹ Jᵀ λ.
        for i in chunks(n + 1) {
            self.u_x.store(i, self.x_pred.load(i) - self.x.load(i));
        }
        // With λ = 0, `Jᵀ λ` is zero: `dtheta` is not read below (nor computed).
        let lambda_zero = self.lambda_zero;
        if !lambda_zero {
            let lambda = std::mem::take(&mut self.lambda);
            self.add_jt(k, &lambda);
            self.lambda = lambda;
        }
        let pinned = self.pinned_balance(k);
        for j in chunks(n) {
            let s = self.q.load(j).conj_mul(self.q_pred.load(j));
            // 1/s_w by the series of (1 − |s_v|²)^(−1/2) where it applies (as `inv_w`).
            let x2 = s.v.norm2();
            let series = F::ONE
                + x2 * (F::splat(0.5)
                    + x2 * (F::splat(0.375) + x2 * (F::splat(0.3125) + x2 * F::splat(0.2734375))));
            let norm_err = (s.w.mul_add(s.w, x2) - F::ONE).abs();
            let off = x2.simd_lt(F::splat(1e-4)) & norm_err.simd_lt(F::splat(1e-12));
            let to_target = s.v.scale(F::splat(2.0) * series);
            let u = if lambda_zero {
                to_target
            } else {
                to_target + self.dtheta.load(j).mul(self.inv_k.load(j))
            };
            self.u_th.store(j, u);
            // Lanes outside the series: 1/s_w exactly, as `inv_w`.
            for_lanes(!off.to_bitmask(), j, n, |e| {
                let s = self.q.get(e).conjugate() * self.q_pred.get(e);
                let mut u = s.imag() * (2.0 * inv_w(&s));
                if !lambda_zero {
                    u += self.dtheta.get(e).component_mul(&self.inv_k.get(e));
                }
                self.u_th.set(e, &u);
            });
        }
        // External moments: `I (θ − θ̃) = J_θᵀ λ + h² τ` (body components of `τ` at the current
        // iterate), the moment a term of the frame's own implicit equation rather than a kick of
        // its velocity before the solve: kicked into a frame's tiny inertia at a haptic step, it
        // turned the frame by radians before the solve saw it.
        for &(j, t) in &self.torques {
            if k.cols.free[j] != 0.0 {
                let body = cosserat_model::quat::rotate_inv(&self.q.get(j), &t);
                let u = self.u_th.get(j) + body.component_mul(&self.inv_k.get(j));
                self.u_th.set(j, &u);
            }
        }
        if !self.clamps.is_empty() {
            self.clamp_rhs(k);
        }
        // One pass per element; the largest residual per lane.
        let mut worst = F::ZERO;
        let e3 = V::splat(&Vec3::z());
        for j in chunks(n) {
            let il = load(&c.inv_l0, j);
            let du = self.u_x.load(j + 1) - self.u_x.load(j);
            let (ua, ub) = (self.u_th.load(j), self.u_th.load(j + 1));
            let g = self.gamma.load(j) + e3;
            let ju = V {
                x: self.dirs[0].load(j).dot(du),
                y: self.dirs[1].load(j).dot(du),
                z: self.dirs[2].load(j).dot(du),
            }
            .scale(il)
                + g.cross(ua);
            let mut res = self.gamma.load(j) + c.alpha_g.load(j).mul(self.lambda[0].load(j));
            if k.damped {
                // (C + α̃λ + γ (C − C_n)) / (1 + γ) = C + α̃λ/(1 + γ) − γ/(1 + γ) C_n: the
                // damped residual, its rows scaled as the Newton matrix's (see
                // `Consts::rebuild`).
                res = res - c.damp_g.load(j).mul(self.c_old[0].load(j));
            }
            let valid = below(j, n);
            self.rhs[0].store(j, (res + ju).scale(-valid));
            let local = res.abs_max().max(ju.abs_max()) * valid;
            // Bend–twist: J u = (s_w (u_b − u_a) + s_v × (u_a + u_b)) / l̄.
            let s = self.rel.load(j);
            let ju = ((ub - ua).scale(s.w) + s.v.cross(ua + ub)).scale(load(&c.inv_lbar, j));
            let mut res = self.omega_c.load(j) + c.alpha_o.load(j).mul(self.lambda[1].load(j));
            if k.damped {
                res = res - c.damp_o.load(j).mul(self.c_old[1].load(j));
            }
            let bends = below(j, n.saturating_sub(1));
            self.rhs[1].store(j, (res + ju).scale(-bends));
            let bend = res.abs_max().max(ju.abs_max()) * load(&c.lbar, j) * bends;
            worst = worst.max(local.max(bend));
        }
        worst.to_array().into_iter().fold(pinned, f64::max)
    }

    /// Applies the multiplier increments in `rhs` through the Jacobians of the last
    /// [`constraints`](Self::constraints): `Δx = u + M⁻¹ Jᵀ Δλ`, `Δθ = u_θ + K_θ⁻¹ J_θᵀ Δλ`
    /// (the frames turned by `q ← normalise(q ⊗ (1, Δθ/2))`); adds them to `λ`.
    ///
    /// A Newton step that would move some point further than `max_move` is shortened, the
    /// whole step (points, frames and multipliers) by one factor, so that no point moves
    /// more than that: a damped Newton step along the same direction. With contacts the solve
    /// passes the rod's radius (`StiffContacts::max_iteration_move`): an iterate that leaps
    /// (a stiff wire's solve right after its pinned points changed) would otherwise carry
    /// points millimetres through walls and ridges, where the contact queries then pinned
    /// them, and the step converged to a state that whipped the wire (the phantom's steel wire
    /// at 5e-5 s reached 1000 m/s; `docs/stiff-solver.md`).
    pub(crate) fn apply(&mut self, k: &Consts, max_move: f64) {
        let n = self.n;
        let mut rhs = std::mem::take(&mut self.rhs);
        let mut before = std::mem::take(&mut self.pin_u);
        before.clear();
        before.extend(self.pinned.iter().map(|p| self.u_x.get(p.point)));
        self.add_jt(k, &rhs);
        self.pinned_update(k, &before);
        self.pin_u = before;
        if !self.clamps.is_empty() {
            self.clamp_apply(k);
        }
        self.lambda_zero = false;
        let longest = (0..=n)
            .map(|i| self.u_x.get(i).norm_squared())
            .fold(0.0_f64, f64::max)
            .sqrt();
        let scale = if longest > max_move {
            max_move / longest
        } else {
            1.0
        };
        let fs = F::splat(scale);
        if scale < 1.0 {
            for d in rhs.iter_mut() {
                for j in chunks(n) {
                    d.store(j, d.load(j).scale(fs));
                }
            }
        }
        for i in chunks(n + 1) {
            self.x.store(i, self.x.load(i) + self.u_x.load(i).scale(fs));
        }
        if self.contact_rows {
            for p in &mut self.pinned {
                if !p.line && p.crease.is_none() {
                    p.mult += scale * p.dmult;
                    p.dmult = 0.0;
                    p.row_x = self.x.get(p.point);
                }
            }
        }
        let half = F::splat(0.5);
        for j in chunks(n) {
            let th = (self.u_th.load(j) + self.dtheta.load(j).mul(self.inv_k.load(j))).scale(fs);
            let r = self.q.load(j).mul(Q {
                w: F::ONE,
                v: th.scale(half),
            });
            self.q.store(j, r.normalised());
            for (l, d) in self.lambda.iter_mut().zip(&rhs) {
                l.store(j, l.load(j) + d.load(j));
            }
        }
        self.rhs = rhs;
    }

    /// Assembles `J K⁻¹ Jᵀ + α̃` (Deul et al. 2018, eq. 17; `direct.rs`) at the Jacobians of the
    /// last [`constraints`](Self::constraints) call and the frames' `K_θ⁻¹` of the last
    /// [`precondition`](Self::precondition), block rows of four elements at a time:
    ///
    /// - `Γ_j`: diagonal `[g]× W_j [g]×ᵀ + (w_j + w_{j+1}) |d_1|²/l0² I + α̃`, coupling to `Ω_j`
    ///   `[g]× W_j (∂Ω_j/∂θ_j)ᵀ`, to `Γ_{j+1}` `−w_{j+1} R_jᵀ R_{j+1} / (l0_j l0_{j+1})`;
    /// - `Ω_j`: diagonal `A W_j Aᵀ + B W_{j+1} Bᵀ + α̃` (`A`, `B` = `∂Ω_j/∂θ_j`, `∂Ω_j/∂θ_{j+1}`),
    ///   coupling to `Γ_{j+1}` `B W_{j+1} [g_{j+1}]×ᵀ`, to `Ω_{j+1}` `B W_{j+1} (∂Ω_{j+1}/∂θ_{j+1})ᵀ`,
    ///
    /// with `W` the frames' `K_θ⁻¹`, `w` the inverse point masses and the damped compliances
    /// of `Consts`; blocks past the end of the rod are zero.
    pub(crate) fn assemble(&self, k: &Consts, out: &mut Assembled) {
        let n = self.n;
        let c = &k.cols;
        out.resize(n, self.gamma.x.len());
        let (next, second) = (Assembled::NEXT, Assembled::SECOND);
        let e3 = V::splat(&Vec3::z());
        for j in chunks(n) {
            let (g, g1) = (self.gamma.load(j) + e3, self.gamma.load(j + 1) + e3);
            let (wa, wb) = (self.inv_k.load(j), self.inv_k.load(j + 1));
            let (il, il1) = (load(&c.inv_l0, j), load(&c.inv_l0, j + 1));
            let (ilb, ilb1) = (load(&c.inv_lbar, j), load(&c.inv_lbar, j + 1));
            let (wm, wm1) = (load(&c.inv_mass, j), load(&c.inv_mass, j + 1));
            let d = [
                self.dirs[0].load(j),
                self.dirs[1].load(j),
                self.dirs[2].load(j),
            ];
            let d1 = [
                self.dirs[0].load(j + 1),
                self.dirs[1].load(j + 1),
                self.dirs[2].load(j + 1),
            ];
            let (s, s1) = (self.rel.load(j), self.rel.load(j + 1));
            let bends = below(j, n.saturating_sub(1));
            let next_bends = below(j + 1, n.saturating_sub(1));
            // ∂Ω_j/∂θ_j = [c]× − a I, ∂Ω_j/∂θ_{j+1} = [c]× + a I with (a, c) = (s_w, s_v) / l̄.
            let (a, cv) = (s.w * ilb, s.v.scale(ilb));
            let (da, db) = (cross_plus(cv, -a), cross_plus(cv, a));
            let da1 = cross_plus(s1.v.scale(ilb1), -(s1.w * ilb1));
            // Four entries of four elements at a time, transposed to one record per element
            // (a group of four entries straight to the records: no record-sized scratch).
            let records = &mut out.records[j..j + 4];
            let mut emit = |entry: usize, quad: [F; 4]| {
                for (record, v) in records.iter_mut().zip(F::transpose(quad)) {
                    record[entry..entry + 4].copy_from_slice(&v.to_array());
                }
            };
            // Γ_j.
            let gg = cross_w_cross(g, wa);
            let diag = (wm + wm1) * il * il * d[0].norm2();
            let alpha = c.alpha_g.load(j);
            let scale = -(wm1 * il * il1) * bends;
            let second_block = [0, 1, 2].map(|r| [0, 1, 2].map(|q| d[r].dot(d1[q])));
            put(&mut emit, next, awbt(&cross(g), wa, &da), bends);
            put(&mut emit, second, second_block, scale);
            emit(
                0,
                [gg[0] + diag + alpha.x, gg[1], gg[2], gg[3] + diag + alpha.y],
            );
            emit(4, [gg[4], gg[5] + diag + alpha.z, F::ZERO, F::ZERO]);
            // Ω_j: A W_a Aᵀ + B W_b Bᵀ with A, B = [c]× ∓ a I is, in closed form,
            // [c]× (W_a + W_b) [c]×ᵀ + a S(c, W_b − W_a) + a² (W_a + W_b) with
            // S(c, W)_{rk} = [c]×_{rk} (W_k − W_r) (off-diagonal only).
            let (wsum, wdiff) = (wa + wb, wb - wa);
            let cc = cross_w_cross(cv, wsum);
            let s01 = -(a * cv.z) * (wdiff.y - wdiff.x);
            let s02 = a * cv.y * (wdiff.z - wdiff.x);
            let s12 = -(a * cv.x) * (wdiff.z - wdiff.y);
            let a2 = a * a;
            let alpha = c.alpha_o.load(j);
            let b = Assembled::BEND;
            put(&mut emit, b + next, awbt(&db, wb, &cross(g1)), bends);
            put(&mut emit, b + second, awbt(&db, wb, &da1), next_bends);
            emit(
                b,
                [
                    cc[0] + a2.mul_add(wsum.x, alpha.x),
                    cc[1] + s01,
                    cc[2] + s02,
                    cc[3] + a2.mul_add(wsum.y, alpha.y),
                ],
            );
            emit(
                b + 4,
                [
                    cc[4] + s12,
                    cc[5] + a2.mul_add(wsum.z, alpha.z),
                    F::ZERO,
                    F::ZERO,
                ],
            );
        }
    }

    /// The pinned points' rows of `u = K⁻¹ (M (x̃ − x) + Jᵀ λ + f)`, from `u_x = x̃ − x + M⁻¹ Jᵀ λ`
    /// as the free points have it: a pin without friction keeps the part of it the pin allows
    /// (`K⁻¹` is the projected `M⁻¹`); one with friction adds the friction impulse `f` at the
    /// current iterate ([`PinFriction`](super::pin::PinFriction)) and applies its inverse mass
    /// `(M + K_f)⁻¹` in the directions it may move.
    ///
    /// Returns the largest such `|u|` of a point with friction over the shorter rest length of
    /// its elements, a strain like the constraint rows' residuals: the rows see `J u`, which a
    /// motion shared by neighbouring points leaves out (a rope sliding down a slope as a whole
    /// would pass the tolerance with its friction unbalanced).
    fn pinned_balance(&mut self, k: &Consts) -> f64 {
        self.partner_impulses(k, false);
        let mut worst = 0.0_f64;
        let mut imbalance = 0.0_f64;
        for p in &self.pinned {
            let i = p.point;
            let w = k.inv_mass[i];
            // A contact row keeps its normal part, with the normal impulse it carries.
            let row = self.contact_rows && !p.line && p.crease.is_none() && w > 0.0;
            let u = self.u_x.get(i) + p.normal * (if row { w * p.mult } else { 0.0 });
            let normal = if row {
                p.normal * p.normal.dot(&u)
            } else {
                Vec3::zeros()
            };
            let u = normal
                + match (p.friction, p.slip(&self.x.get(i))) {
                    (Some(f), Some(slip)) if w > 0.0 => {
                        let imbalance_impulse = p.sliding_part(&(u / w + f.impulse(&slip, p.pn)));
                        let correction =
                            imbalance_impulse.norm() / (1.0 / w + f.tangent(&slip, p.pn));
                        let u = p.mobility_times(w, &imbalance_impulse);
                        let il = [i.checked_sub(1), (i < self.n).then_some(i)]
                            .into_iter()
                            .flatten()
                            .fold(0.0_f64, |m, j| m.max(k.cols.inv_l0[j]));
                        worst = worst.max(u.norm() * il);
                        imbalance = imbalance.max(correction / f.stick_slip);
                        u
                    }
                    _ => p.sliding_part(&u),
                };
            self.u_x.set(i, &u);
        }
        self.friction_imbalance = imbalance;
        worst
    }

    /// The pinned points' rows of the update `Δx = u + K⁻¹ Jᵀ Δλ`, where `u_x` holds
    /// `u + M⁻¹ Jᵀ Δλ` and `before` the pinned points' `u` (in `pinned`'s order).
    fn pinned_update(&mut self, k: &Consts, before: &[Vec3<f64>]) {
        self.partner_impulses(k, true);
        for (p, u) in self.pinned.iter().zip(before) {
            let i = p.point;
            let w = k.inv_mass[i];
            let added = self.u_x.get(i) - u;
            let d = if p.friction.is_some() && w > 0.0 {
                p.mobility_times(w, &(added / w))
            } else {
                p.sliding_part(&added)
            };
            let d = if self.contact_rows && !p.line && p.crease.is_none() && w > 0.0 {
                d + p.normal * (p.normal.dot(&added) + w * p.dmult)
            } else {
                d
            };
            self.u_x.set(i, &(u + d));
        }
    }

    /// Freezes the friction of the pinned points for the Newton matrix at the current iterate
    /// (`PinFriction::freeze`): called whenever the matrix is rebuilt, with the frames' bound.
    pub(crate) fn freeze_friction(&mut self) {
        for p in &mut self.pinned {
            if let Some(slip) = p.slip(&self.x.get(p.point))
                && let Some(f) = p.friction.as_mut()
            {
                f.freeze(&slip, p.pn);
            }
        }
    }

    /// Corrects the blocks of [`assemble`](Self::assemble) for the pinned points: point `i`
    /// enters `J K⁻¹ Jᵀ` through `Γ_{i−1}` (as its end, `∂Γ/∂r = D_{i−1}/l0`) and `Γ_i` (as its
    /// start, `−D_i/l0`) with inverse mass `w I`; pinned, it has `w I − Σ_k c_k e_k e_kᵀ`
    /// less: weight `c_k = w` along each direction the pin holds (its wall's normal, the two
    /// across a guide's axis or a crease), and `c_k = w − 1/(m + e_kᵀ K_f e_k)` along each
    /// direction it moves in with friction ([`Pinned::mobilities`]). So, per direction,
    /// with `a = D_{i−1} e_k / l0_{i−1}` and `b = D_i e_k / l0_i`: `c_k a aᵀ` comes off the
    /// diagonal block of `Γ_{i−1}`, `c_k b bᵀ` off that of `Γ_i`, and `c_k a bᵀ` is added to
    /// their coupling (which holds `−w D_{i−1} D_iᵀ / (l0 l0')`).
    pub(crate) fn pin_blocks(&self, k: &Consts, out: &mut Assembled) {
        let n = self.n;
        let project = |j: usize, v: &Vec3<f64>| {
            let il = k.cols.inv_l0[j];
            Vec3::new(
                self.dirs[0].get(j).dot(v),
                self.dirs[1].get(j).dot(v),
                self.dirs[2].get(j).dot(v),
            ) * il
        };
        let upper = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
        for p in &self.pinned {
            let i = p.point;
            let w = k.inv_mass[i];
            if w == 0.0 {
                continue;
            }
            let held = if self.is_row(p) {
                [Vec3::zeros(), Vec3::zeros()]
            } else if p.line {
                perpendiculars(&p.normal)
            } else if let Some(t) = p.crease_direction() {
                perpendiculars(&t)
            } else {
                [p.normal, Vec3::zeros()]
            };
            let free = p.free_directions();
            let mobile = p.mobilities(w);
            let removed = [
                (held[0], w),
                (held[1], w),
                (free[0], w - mobile[0]),
                (free[1], w - mobile[1]),
            ];
            for (e, c) in removed {
                if c == 0.0 || e == Vec3::zeros() {
                    continue;
                }
                let a = (i >= 1).then(|| project(i - 1, &e));
                let b = (i < n).then(|| project(i, &e));
                for (j, v) in [(i.wrapping_sub(1), a), (i, b)] {
                    if let Some(v) = v {
                        let r = &mut out.records[j];
                        for (slot, (x, y)) in upper.iter().enumerate() {
                            r[slot] -= c * v[*x] * v[*y];
                        }
                    }
                }
                if let (Some(a), Some(b)) = (a, b) {
                    let r = &mut out.records[i - 1];
                    for x in 0..3 {
                        for y in 0..3 {
                            r[Assembled::SECOND + 4 * x + y] += c * a[x] * b[y];
                        }
                    }
                }
            }
        }
    }

    /// Step 1 of the module docs for the free points and frames: `x_old = x`, `v += h (g + f/m)`,
    /// `x̃ = x_old + h v` (and `x = x_old + h v_old` as the starting guess of the direct
    /// solver, `x = x̃` for Gauss–Seidel); frames precess by the gyroscopic term,
    /// `q = q̃ = q ⊗ exp(h ω / 2)`. `held` is called between the velocities and the targets,
    /// to set the held points' and frames' velocities and positions.
    pub(crate) fn predict(
        &mut self,
        k: &Consts,
        h: f64,
        gravity: &Vec3<f64>,
        loads: impl Iterator<Item = (usize, Vec3<f64>)>,
        direct: bool,
        held: impl FnOnce(&mut Work),
    ) {
        let n = self.n;
        let c = &k.cols;
        let hf = F::splat(h);
        let gh = V::splat(&(gravity * h));
        for i in chunks(n + 1) {
            let (x, v) = (self.x.load(i), self.v.load(i));
            self.x_old.store(i, x);
            self.v_start.store(i, v);
            if direct {
                self.x.store(i, x.add_scaled(v, hf));
            }
            let free = load(&c.inv_mass, i)
                .simd_gt(F::ZERO)
                .select(F::ONE, F::ZERO);
            self.v.store(i, v.add_scaled(gh, free));
        }
        for (p, f) in loads {
            let w = k.inv_mass[p];
            if w > 0.0 {
                let v = self.v.get(p) + f * (w * h);
                self.v.set(p, &v);
            }
        }
        for j in chunks(n) {
            let q = self.q.load(j);
            self.q_old.store(j, q);
            let o = self.omega.load(j);
            self.omega_start.store(j, o);
            // The gyroscopic term as the exact precession of (ω₁, ω₂) by h (J − I)/I ω₃, a Cayley
            // rotation (`soa::integrate_velocities` says why not `ω += −h I⁻¹ (ω × Iω)`).
            let t = hf
                * F::splat(0.5)
                * o.z
                * (c.inertia.load(j).z * c.inv_inertia_own.load(j).x - F::ONE);
            let inv = F::ONE / t.mul_add(t, F::ONE);
            let (cs, sn) = ((F::ONE - t * t) * inv, (t + t) * inv);
            let o = V {
                x: cs.mul_sub(o.x, sn * o.y),
                y: sn.mul_add(o.x, cs * o.y),
                z: o.z,
            };
            self.omega.store(j, o);
            // Lanes past 1e-2 rad are redone.
            let v = o.scale(hf);
            let a2 = v.norm2();
            self.q.store(j, q.mul(small_exp(v)).normalised());
            // Lanes past 1e-2 rad: the closed form, as `exp_small`.
            for_lanes(mask_ge(a2, F::splat(1e-4)), j, n, |e| {
                let r = self.q_old.get(e) * exp_small(&(self.omega.get(e) * h));
                self.q.set(e, &(r / r.norm()));
            });
        }
        held(self);
        for i in chunks(n + 1) {
            let target = self.x_old.load(i).add_scaled(self.v.load(i), hf);
            self.x_pred.store(i, target);
            if !direct {
                self.x.store(i, target);
            }
        }
        self.q_pred.copy_from(&self.q);
    }

    /// Puts back the state at the start of the step (before [`predict`](Self::predict)), so
    /// that the step can be taken again.
    pub(crate) fn restore_step_start(&mut self) {
        self.x.copy_from(&self.x_old);
        self.q.copy_from(&self.q_old);
        self.v.copy_from(&self.v_start);
        self.omega.copy_from(&self.omega_start);
    }

    /// Step 3 of the module docs: `v = (x − x_old) / (h (1 + h γ))` (`drag = 1/(1 + hγ)`) and
    /// `ω = log(q̄_old q) / h`.
    pub(crate) fn velocities(&mut self, h: f64, drag: f64) {
        let n = self.n;
        let scale = F::splat(drag / h);
        for i in chunks(n + 1) {
            let v = (self.x.load(i) - self.x_old.load(i)).scale(scale);
            self.v.store(i, v);
        }
        let inv_h = F::splat(1.0 / h);
        for j in chunks(n) {
            let s = self.q_old.load(j).conj_mul(self.q.load(j)).positive();
            // Lanes past 1e-2 rad are redone.
            let (series, ok) = small_log(s);
            self.omega.store(j, s.v.scale(series * inv_h));
            // Other lanes: the closed form, as `angle_over_sin_half`.
            for_lanes(!ok.to_bitmask(), j, n, |e| {
                let s = relative_rotation(&self.q_old.get(e), &self.q.get(e));
                self.omega
                    .set(e, &(s.imag() * (angle_over_sin_half(&s) / h)));
            });
        }
    }

    /// The divergence test of a step: the first element (in order) whose frame is not finite,
    /// whose length is not finite, or whose squared stretch `|e|² / l0²` is above `above` or
    /// below `below`; otherwise the smallest and largest squared stretch.
    pub(crate) fn stretch_range(
        &self,
        k: &Consts,
        above: f64,
        below_sq: f64,
    ) -> Result<(f64, f64), (usize, Option<f64>)> {
        let n = self.n;
        let c = &k.cols;
        let (mut lo, mut hi) = (F::splat(f64::MAX), F::ZERO);
        let (up, down) = (F::splat(above), F::splat(below_sq));
        for j in chunks(n) {
            let q = self.q.load(j);
            let r2 = (self.x.load(j + 1) - self.x.load(j)).norm2() * load(&c.inv_l0_sq, j);
            // NaN or infinity anywhere makes `finite` NaN, which fails both (ordered)
            // comparisons.
            let finite = (q.w + q.v.x + q.v.y + q.v.z) * F::ZERO;
            let good = (finite + r2).simd_le(up) & r2.simd_ge(down);
            let valid = below(j, n).simd_gt(F::ZERO);
            if (!good & valid).any() {
                for e in j..(j + 4).min(n) {
                    let q = self.q.get(e);
                    if !q.coords.iter().all(|x| x.is_finite()) {
                        return Err((e, None));
                    }
                    let r2 = (self.x.get(e + 1) - self.x.get(e)).norm_squared() * c.inv_l0_sq[e];
                    if !r2.is_finite() || r2 > above || r2 < below_sq {
                        return Err((e, Some(r2)));
                    }
                }
            }
            lo = valid.select(lo.min(r2), lo);
            hi = valid.select(hi.max(r2), hi);
        }
        let lo = lo.to_array().into_iter().fold(f64::MAX, f64::min);
        let hi = hi.to_array().into_iter().fold(0.0, f64::max);
        Ok((lo, hi))
    }
}

/// A 3×3 matrix per lane, row-major.
type M = [[F; 3]; 3];

/// `angle / |s_v|` of unit quaternions `s` with `s_w ≥ 0` by the series of `2 asin(x)/x` (as
/// `angle_over_sin_half`; `s_v` times it is the rotation vector), and the mask of the lanes
/// where that series applies (`|s_v|² < 1e-4` and `s` of unit norm to 1e-12); other lanes must
/// be redone with the closed form.
#[inline(always)]
fn small_log(s: Q) -> (F, F) {
    let sn2 = s.v.norm2();
    let series = F::splat(2.0)
        + sn2
            * (F::splat(1.0 / 3.0)
                + sn2
                    * (F::splat(0.15)
                        + sn2 * (F::splat(5.0 / 56.0) + sn2 * F::splat(35.0 / 576.0))));
    let norm_err = (s.w.mul_add(s.w, sn2) - F::ONE).abs();
    let ok = sn2.simd_lt(F::splat(1e-4)) & norm_err.simd_lt(F::splat(1e-12));
    (series, ok)
}

/// `exp(v / 2)`, the quaternion of a rotation by `v`, by the series of `cos` and `sin` (as
/// `exp_small`); for `|v|² < 1e-4` (error below 1e-20), other lanes must be redone.
#[inline(always)]
fn small_exp(v: V) -> Q {
    let h2 = F::splat(0.25) * v.norm2();
    let cos =
        F::ONE - h2 * (F::splat(0.5) - h2 * (F::splat(1.0 / 24.0) - h2 * F::splat(1.0 / 720.0)));
    let sin = F::splat(0.5)
        * (F::ONE
            - h2 * (F::splat(1.0 / 6.0)
                - h2 * (F::splat(1.0 / 120.0) - h2 * F::splat(1.0 / 5040.0))));
    Q {
        w: cos,
        v: v.scale(sin),
    }
}

/// `[v]×`.
#[inline(always)]
fn cross(v: V) -> M {
    let z = F::ZERO;
    [[z, -v.z, v.y], [v.z, z, -v.x], [-v.y, v.x, z]]
}

/// `[c]× + a I`.
#[inline(always)]
fn cross_plus(c: V, a: F) -> M {
    [[a, -c.z, c.y], [c.z, a, -c.x], [-c.y, c.x, a]]
}

/// `[g]× diag(w) [g]×ᵀ` (upper triangle 00, 01, 02, 11, 12, 22) in closed form.
#[inline(always)]
fn cross_w_cross(g: V, w: V) -> [F; 6] {
    let (x, y, z) = (g.x, g.y, g.z);
    [
        w.y * z * z + w.z * y * y,
        -(w.z * x * y),
        -(w.y * x * z),
        w.x * z * z + w.z * x * x,
        -(w.x * y * z),
        w.x * y * y + w.y * x * x,
    ]
}

/// `a diag(w) bᵀ`.
#[inline(always)]
fn awbt(a: &M, w: V, b: &M) -> M {
    let mut out = [[F::ZERO; 3]; 3];
    for (r, o) in out.iter_mut().enumerate() {
        let aw = [a[r][0] * w.x, a[r][1] * w.y, a[r][2] * w.z];
        for (q, oq) in o.iter_mut().enumerate() {
            *oq = aw[2].mul_add(b[q][2], aw[1].mul_add(b[q][1], aw[0] * b[q][0]));
        }
    }
    out
}

/// The rows of `m · mask`, padded to four with zeros, to `emit` at `entry`, `entry + 4` and
/// `entry + 8`.
#[inline(always)]
fn put(emit: &mut impl FnMut(usize, [F; 4]), entry: usize, m: M, mask: F) {
    for (r, row) in m.iter().enumerate() {
        emit(
            entry + 4 * r,
            [row[0] * mask, row[1] * mask, row[2] * mask, F::ZERO],
        );
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::stepper::CpuRod;
    use crate::stiff::constraints::{BendTwist, StretchShear, bend_twist, stretch_shear};
    use crate::stiff::direct::{Masses, blocks};
    use crate::stiff::pin::PinFriction;
    use cosserat_model::Quat;
    use cosserat_model::presets::preset;
    use cosserat_model::quat::exp_rotation;
    use cosserat_model::rod::{RodSpec, build_rod};
    use cosserat_problem::ends::EndCondition;

    /// A curved, twisted rod of `n` elements (not a multiple of four, so that the last chunk
    /// is partial) with a clamped start and a free end, its constants, and a working state
    /// whose points and frames are perturbed so that every constraint is violated.
    pub(crate) fn setup(n: usize) -> (Consts, Work) {
        let pts: Vec<[f64; 3]> = (0..=n)
            .map(|i| {
                let t = i as f64 * 0.01;
                [t, 0.2 * (3.0 * t).sin(), 0.1 * t * t]
            })
            .collect();
        let spec = RodSpec::new(preset("nitinol").unwrap().material());
        let (s, p) = build_rod::<f64>(&pts, &spec).unwrap();
        let rod = CpuRod::new(
            s,
            p,
            [EndCondition::clamped(), EndCondition::free()],
            vec![],
        );
        let mut k = Consts::default();
        k.rebuild(&rod, 1e-3, true, 0.0);
        let mut w = Work::default();
        w.resize(n);
        for i in 0..=n {
            let x = rod.state.positions[i] + Vec3::new(1e-4, -2e-4, 3e-5) * (i as f64).sin();
            w.x.set(i, &x);
        }
        for j in 0..n {
            let turn = exp_rotation(&Vec3::new(0.01, -0.02, 0.03 * (j as f64).cos()));
            w.q.set(j, &(rod.state.frames[j] * turn));
        }
        (k, w)
    }

    /// The reference structures of `constraints.rs` at the working state.
    fn reference(k: &Consts, w: &Work) -> (Vec<StretchShear<f64>>, Vec<BendTwist<f64>>) {
        let n = w.n;
        let ss = (0..n)
            .map(|j| stretch_shear(&w.x.get(j), &w.x.get(j + 1), &w.q.get(j), k.l0[j]))
            .collect();
        let bt = (0..n - 1)
            .map(|j| bend_twist(&w.q.get(j), &w.q.get(j + 1), &k.rest_u[j], k.lbar[j]))
            .collect();
        (ss, bt)
    }

    fn close(a: &Vec3<f64>, b: &Vec3<f64>, scale: f64, what: &str) {
        assert!(
            (a - b).amax() <= 1e-12 * scale.max(b.amax()),
            "{what}: {a} vs {b}"
        );
    }

    /// Constraint values, the assembled blocks of `J K⁻¹ Jᵀ + α̃`, `Jᵀ μ` and the right-hand
    /// side of the lanes against the scalar formulas of `constraints.rs` and `direct::blocks`.
    /// BDF2's extrapolation against its formulas, element by element: `(4 a_n − a_{n−1})/3` for
    /// positions, velocities and angular velocities, and each frame turned past `q_n` by a third
    /// of the body rotation from `q_{n−1}` to `q_n` (the rotation vector's exponential, checked
    /// by turning three times: `q_n ⊗ r³ = q_n ⊗ (q̄_{n−1} q_n)`), for small turns (the series)
    /// and large ones (the closed forms), on every lane.
    #[test]
    fn bdf2_extrapolation_matches_its_formulas() {
        let n = 9;
        let (_, mut w) = setup(n);
        let before = w.clone();
        for i in 0..=n {
            let f = i as f64;
            w.x_prev
                .set(i, &(w.x.get(i) - Vec3::new(1e-3, -2e-3 * f, 5e-4)));
            w.v.set(i, &Vec3::new(f.sin(), 0.3, -f.cos()));
            w.v_prev.set(i, &Vec3::new(0.1, f.cos(), 0.2 * f));
        }
        for j in 0..n {
            let f = j as f64;
            // Turns of 1e-4 to 0.5 rad between the two states.
            let angle = 1e-4 * 5f64.powi(j as i32 % 6);
            let axis = Vec3::new(f.cos(), 0.4, f.sin()).normalize();
            w.q_prev
                .set(j, &(before.q.get(j) * exp_rotation(&(-axis * angle))));
            w.omega.set(j, &Vec3::new(0.5, -f, 2.0));
            w.omega_prev.set(j, &Vec3::new(f, 0.1, -0.3));
        }
        let old = w.clone();
        w.extrapolate_bdf2();
        let blend = |a: Vec3<f64>, b: Vec3<f64>| (a * 4.0 - b) / 3.0;
        for i in 0..=n {
            close(
                &w.x.get(i),
                &blend(old.x.get(i), old.x_prev.get(i)),
                1.0,
                "x*",
            );
            close(
                &w.v.get(i),
                &blend(old.v.get(i), old.v_prev.get(i)),
                1.0,
                "v*",
            );
            assert_eq!(w.x_prev.get(i), old.x.get(i));
            assert_eq!(w.v_prev.get(i), old.v.get(i));
        }
        for j in 0..n {
            let (q, qp) = (old.q.get(j), old.q_prev.get(j));
            let r = q.conjugate() * w.q.get(j);
            let thrice = q * r * r * r;
            let step = q * (qp.conjugate() * q);
            let diff = (thrice.coords - step.coords)
                .norm()
                .min((thrice.coords + step.coords).norm());
            assert!(diff < 1e-12, "frame {j}: {thrice:?} vs {step:?}");
            close(
                &w.omega.get(j),
                &blend(old.omega.get(j), old.omega_prev.get(j)),
                1.0,
                "ω*",
            );
            assert_eq!(w.q_prev.get(j), q);
        }
    }

    #[test]
    fn lane_passes_match_the_scalar_formulas() {
        let n = 11;
        let (k, mut w) = setup(n);
        w.constraints(&k);
        let (ss, bt) = reference(&k, &w);
        for j in 0..n {
            close(&w.gamma.get(j), &ss[j].value, 1.0, "Γ");
            if j + 1 < n {
                close(&w.omega_c.get(j), &bt[j].value, 1.0, "Ω");
            }
        }
        // Assembly, with the geometric bound of some multipliers in K_θ.
        for j in 0..n {
            let f = j as f64;
            w.lambda_prev[0].set(j, &Vec3::new(0.3 * f.sin(), -0.2, 5.0 + f));
            let bend = if j + 1 < n { 1e-3 * f.cos() } else { 0.0 };
            w.lambda_prev[1].set(j, &Vec3::new(bend, 2.0 * bend, -bend));
        }
        w.precondition(&k, 1.0, true);
        let mut asm = Assembled::default();
        w.assemble(&k, &mut asm);
        let reference_asm = {
            let alpha_gamma: Vec<_> = (0..n).map(|j| k.cols.alpha_g.get(j)).collect();
            let alpha_omega: Vec<_> = (0..n - 1).map(|j| k.cols.alpha_o.get(j)).collect();
            let m = Masses {
                inv_mass: &k.inv_mass,
                inv_inertia: &w.inv_k,
                alpha_gamma: &alpha_gamma,
                alpha_omega: &alpha_omega,
            };
            Assembled::from_blocks(n, |b| blocks(b, &ss, &bt, &m))
        };
        for j in 0..n {
            let (a, b) = (&asm.records[j], &reference_asm.records[j]);
            let last = if j + 1 < n {
                Assembled::ENTRIES
            } else {
                Assembled::BEND
            };
            for e in 0..last {
                // Relative to the largest entry of the same 3×3 block (exactly zero past the
                // end of the rod).
                let (row, off) = (e - e % Assembled::BEND, e % Assembled::BEND);
                let block = match off {
                    0..8 => row..row + 8,
                    8..20 => row + 8..row + 20,
                    _ => row + 20..row + 32,
                };
                let scale = b[block].iter().fold(0.0_f64, |s, v| s.max(v.abs()));
                assert!(
                    (a[e] - b[e]).abs() <= 1e-12 * scale,
                    "element {j}, entry {e}: {} vs {}",
                    a[e],
                    b[e]
                );
            }
        }
        // Jᵀ μ against the reference Jacobians.
        let mu: [V3s; 2] = {
            let mut m = [V3s::zeros(n), V3s::zeros(n)];
            for j in 0..n {
                let f = j as f64;
                m[0].set(j, &Vec3::new(f.sin(), 0.5, -f.cos()));
                if j + 1 < n {
                    m[1].set(j, &Vec3::new(0.1 * f, -0.3, 0.7));
                }
            }
            m
        };
        w.u_x.fill_zero();
        w.add_jt(&k, &mu);
        for i in 0..=n {
            let mut f = Vec3::zeros();
            if i < n {
                f -= ss[i].d_rb.transpose() * mu[0].get(i);
            }
            if i > 0 {
                f += ss[i - 1].d_rb.transpose() * mu[0].get(i - 1);
            }
            close(&w.u_x.get(i), &(f * k.inv_mass[i]), 1e-9, "M⁻¹ J_rᵀ μ");
        }
        for j in 0..n {
            let mut t = ss[j].d_theta.transpose() * mu[0].get(j);
            if j + 1 < n {
                t += bt[j].d_theta_a.transpose() * mu[1].get(j);
            }
            if j > 0 {
                t += bt[j - 1].d_theta_b.transpose() * mu[1].get(j - 1);
            }
            close(&w.dtheta.get(j), &t, 1.0, "J_θᵀ μ");
        }
        // Right-hand side at λ = 0 towards displaced targets: −(C + J u).
        let mut u_th = Vec::new();
        for i in 0..=n {
            let d = Vec3::new(2e-6, -1e-6, 3e-6) * (1.0 + (i as f64).cos());
            w.x_pred.set(i, &(w.x.get(i) + d));
        }
        for j in 0..n {
            let th = Vec3::new(1e-4, 2e-4 * (j as f64).sin(), -5e-5);
            let q: Quat<f64> = w.q.get(j) * exp_rotation(&th);
            w.q_pred.set(j, &q);
            let s = w.q.get(j).conjugate() * q;
            u_th.push(s.imag() * (2.0 / s.w));
        }
        w.lambda_zero = true;
        for c in &mut w.lambda {
            c.fill_zero();
        }
        let worst = w.rhs(&k);
        let mut expected_worst: f64 = 0.0;
        for j in 0..n {
            let du = (w.x_pred.get(j + 1) - w.x.get(j + 1)) - (w.x_pred.get(j) - w.x.get(j));
            let ju = ss[j].d_rb * du + ss[j].d_theta * u_th[j];
            close(&w.rhs[0].get(j), &-(ss[j].value + ju), 1e-6, "Γ rows");
            expected_worst = expected_worst.max(ss[j].value.amax()).max(ju.amax());
            if j + 1 < n {
                let ju = bt[j].d_theta_a * u_th[j] + bt[j].d_theta_b * u_th[j + 1];
                close(&w.rhs[1].get(j), &-(bt[j].value + ju), 1e-3, "Ω rows");
                let bend = bt[j].value.amax().max(ju.amax()) * k.lbar[j];
                expected_worst = expected_worst.max(bend);
            } else {
                assert_eq!(w.rhs[1].get(j), Vec3::zeros());
            }
        }
        assert!((worst - expected_worst).abs() <= 1e-12 * expected_worst);
    }

    /// The pinned points' corrections of the Newton matrix against `J K⁻¹ Jᵀ + α̃` built
    /// densely with each pinned point's inverse mass: `w (I − n nᵀ)` on a frictionless wall,
    /// `w a aᵀ` on a line, `(m I + K_f)⁻¹` on the wall's plane with friction (sliding, and held
    /// within the holding slip); and the update `Δx = K⁻¹ Jᵀ μ` of those points.
    /// A Newton step that would move a point further than the limit is shortened as a whole:
    /// every point's move, every frame's turn and every multiplier's increment is the full
    /// step's times one factor, and the farthest point moves exactly the limit.
    #[test]
    fn a_limited_newton_step_is_the_full_step_shortened() {
        let n = 11;
        let (k, mut w) = setup(n);
        w.constraints(&k);
        w.precondition(&k, 1.0, true);
        w.rhs(&k);
        let mut asm = Assembled::default();
        w.assemble(&k, &mut asm);
        let mut factor = crate::stiff::direct::BlockTridiagonal::default();
        factor.factor(&asm);
        factor.solve(&mut w.rhs);
        let start = w.clone();
        let mut full = w.clone();
        full.apply(&k, f64::INFINITY);
        let moved = |a: &Work, i: usize| a.x.get(i) - start.x.get(i);
        let longest = (0..=n).map(|i| moved(&full, i).norm()).fold(0.0, f64::max);
        assert!(longest > 0.0);
        let limit = 0.3 * longest;
        w.apply(&k, limit);
        let scale = limit / longest;
        let farthest = (0..=n).map(|i| moved(&w, i).norm()).fold(0.0, f64::max);
        assert!(
            (farthest - limit).abs() <= 1e-12 * limit,
            "{farthest} vs {limit}"
        );
        for i in 0..=n {
            close(&moved(&w, i), &(moved(&full, i) * scale), longest, "point");
        }
        // The frames turn by `q ← normalise(q ⊗ (1, Δθ/2))`: `Δθ = 2 v / w` of `q̄_start q`.
        let turn = |a: &Work, j: usize| {
            let r = start.q.get(j).conjugate() * a.q.get(j);
            r.imag() * (2.0 / r.w)
        };
        for j in 0..n {
            let (t, tf) = (turn(&w, j), turn(&full, j) * scale);
            assert!(
                (t - tf).norm() <= 1e-9 * tf.norm(),
                "frame {j}: {t} vs {tf}"
            );
            for c in 0..2 {
                let (l, lf) = (w.lambda[c].get(j), full.lambda[c].get(j) * scale);
                close(&l, &lf, lf.amax(), "multiplier");
            }
        }
        // Within the limit the step is the full one.
        let mut within = start.clone();
        within.apply(&k, 2.0 * longest);
        for i in 0..=n {
            close(
                &moved(&within, i),
                &moved(&full, i),
                longest,
                "unlimited point",
            );
        }
    }

    #[test]
    fn pinned_points_enter_the_newton_matrix_with_projected_inverse_masses() {
        let n = 9;
        let (k, mut w) = setup(n);
        w.constraints(&k);
        w.precondition(&k, 1.0, true);
        let (ss, bt) = reference(&k, &w);
        let normal = Vec3::new(0.3, -0.5, 0.8).normalize();
        // With friction frozen as a slip across the wall (anisotropic) or within the holding
        // slip (isotropic, a stiff spring).
        let friction = |slip: Vec3<f64>, pn: f64| {
            let mut f = PinFriction::new(Vec3::zeros(), 0.4, 0.3, 1e-3).unwrap();
            f.freeze(&(slip - normal * normal.dot(&slip)), pn);
            f
        };
        let slide = Vec3::new(1e-6, 2e-6, 0.0);
        // A slide's first freeze is the secant both ways; frozen again sliding the same way,
        // the law's slope along it (none).
        let mut sliding = friction(slide, 3e-9);
        assert!(sliding.k_along == sliding.k_across && sliding.k_across > 0.0);
        sliding.freeze(&(slide - normal * normal.dot(&slide)), 3e-9);
        let held = friction(Vec3::new(1e-9, 0.0, 0.0), 3e-9);
        assert!(sliding.k_along == 0.0 && sliding.k_across > 0.0);
        assert!(held.k_along > 0.0 && held.k_across == held.k_along);
        let pin = |point, friction| Pinned::on_wall(point, normal, false, 3e-9, friction);
        // On a line, sliding without and with friction, held by friction inside and at the
        // free end.
        w.pinned = vec![
            Pinned::on_line(1, normal),
            pin(3, None),
            pin(4, Some(sliding)),
            pin(6, Some(held)),
            pin(9, Some(held)),
        ];
        let mut asm = Assembled::default();
        w.assemble(&k, &mut asm);
        w.pin_blocks(&k, &mut asm);
        // Dense J (6n rows: Γ_j then Ω_j per element; 3(n + 1) point and 3n frame columns).
        let (rows, cols) = (6 * n, 3 * (n + 1) + 3 * n);
        let mut jac = vec![vec![0.0; cols]; rows];
        let frame = |j: usize| 3 * (n + 1) + 3 * j;
        for j in 0..n {
            for r in 0..3 {
                for c in 0..3 {
                    jac[6 * j + r][3 * (j + 1) + c] = ss[j].d_rb[(r, c)];
                    jac[6 * j + r][3 * j + c] = -ss[j].d_rb[(r, c)];
                    jac[6 * j + r][frame(j) + c] = ss[j].d_theta[(r, c)];
                    if j + 1 < n {
                        jac[6 * j + 3 + r][frame(j) + c] = bt[j].d_theta_a[(r, c)];
                        jac[6 * j + 3 + r][frame(j + 1) + c] = bt[j].d_theta_b[(r, c)];
                    }
                }
            }
        }
        // K⁻¹, block diagonal.
        let mut kinv = vec![vec![0.0; cols]; cols];
        for i in 0..=n {
            let wi = k.inv_mass[i];
            let m = match w.pinned.iter().find(|p| p.point == i) {
                Some(p) if p.line => p.normal * p.normal.transpose() * wi,
                Some(p) if p.friction.is_some() => {
                    // `(m I + K_f)⁻¹` on the tangent plane, from the friction's own terms.
                    let f = p.friction.unwrap();
                    let t = f.dir;
                    let across = normal.cross(&t);
                    t * t.transpose() / (1.0 / wi + f.k_along)
                        + across * across.transpose() / (1.0 / wi + f.k_across)
                }
                Some(p) => (nalgebra::Matrix3::identity() - p.normal * p.normal.transpose()) * wi,
                None => nalgebra::Matrix3::identity() * wi,
            };
            for r in 0..3 {
                for c in 0..3 {
                    kinv[3 * i + r][3 * i + c] = m[(r, c)];
                }
            }
        }
        for j in 0..n {
            let d = w.inv_k.get(j);
            for r in 0..3 {
                kinv[frame(j) + r][frame(j) + r] = d[r];
            }
        }
        let entry = |a: usize, b: usize| -> f64 {
            let mut s = 0.0;
            for p in 0..cols {
                if jac[a][p] == 0.0 {
                    continue;
                }
                for q in 0..cols {
                    s += jac[a][p] * kinv[p][q] * jac[b][q];
                }
            }
            s
        };
        // Expected α̃ on the diagonal (the lanes' damped compliances) and the regularisation.
        let mut alpha = vec![0.0; rows];
        for j in 0..n {
            let ag = k.cols.alpha_g.get(j);
            for r in 0..3 {
                alpha[6 * j + r] = ag[r];
            }
            if j + 1 < n {
                let ao = k.cols.alpha_o.get(j);
                for r in 0..3 {
                    alpha[6 * j + 3 + r] = ao[r];
                }
            }
        }
        // The record entries of a Γ block row: diagonal upper triangle, then the blocks with
        // Ω_j (NEXT) and Γ_{j+1} (SECOND).
        let upper = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
        for j in 0..n {
            let rec = &asm.records[j];
            let g = 6 * j;
            let scale = (0..3)
                .map(|r| entry(g + r, g + r).abs())
                .fold(0.0, f64::max);
            let check = |got: f64, want: f64, what: &str| {
                assert!(
                    (got - want).abs() <= 1e-10 * scale,
                    "element {j}, {what}: {got} vs {want}"
                );
            };
            for (slot, (r, c)) in upper.iter().enumerate() {
                let want = entry(g + r, g + c) + if r == c { alpha[g + r] } else { 0.0 };
                check(rec[slot], want, "Γ diagonal");
            }
            for r in 0..3 {
                for c in 0..3 {
                    if j + 1 < n {
                        check(
                            rec[Assembled::NEXT + 4 * r + c],
                            entry(g + r, g + 3 + c),
                            "Γ–Ω",
                        );
                        check(
                            rec[Assembled::SECOND + 4 * r + c],
                            entry(g + r, g + 6 + c),
                            "Γ–Γ next",
                        );
                    }
                }
            }
        }
        // The update of the pinned points: K⁻¹ Jᵀ μ with the projected inverse masses.
        let mu: [V3s; 2] = {
            let mut m = [V3s::zeros(n), V3s::zeros(n)];
            for j in 0..n {
                let f = j as f64;
                m[0].set(j, &Vec3::new(f.sin(), 0.5, -f.cos()));
            }
            m
        };
        w.u_x.fill_zero();
        w.add_jt(&k, &mu);
        let raw = w.u_x.clone();
        let before = vec![Vec3::zeros(); w.pinned.len()];
        w.pinned_update(&k, &before);
        for p in &w.pinned {
            let u = w.u_x.get(p.point);
            if let Some(f) = p.friction {
                // `(m I + K_f)⁻¹ P` times the impulse `m u_raw`: along the slip the point's own
                // mobility (sliding) or the spring's (held), across it the spring's.
                let (t, r) = (f.dir, raw.get(p.point));
                let across = normal.cross(&t);
                let wi = k.inv_mass[p.point];
                let want = t * (t.dot(&r) / (1.0 + wi * f.k_along))
                    + across * (across.dot(&r) / (1.0 + wi * f.k_across));
                assert!((u - want).norm() <= 1e-12 * r.norm(), "{u} vs {want}");
                assert!(u.norm() > 0.0);
            } else if p.line {
                assert!(u.cross(&p.normal).norm() <= 1e-12 * u.norm(), "{u}");
                assert!(u.norm() > 0.0);
            } else {
                assert!(u.dot(&p.normal).abs() <= 1e-12 * u.norm(), "{u}");
                assert!(u.norm() > 0.0);
            }
        }
    }
}
