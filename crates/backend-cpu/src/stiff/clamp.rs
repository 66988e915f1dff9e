//! Clamps in the stiff solve.
//!
//! A clamp holds the rod at its end point through a bend–twist node of half an element between
//! its own frame and the rod's end frame (`cosserat_model::rod::EndNode`, `docs/model.md`). The
//! clamp frame is kinematic, so that node acts on one frame only. Rather than a fourth kind of
//! multiplier block in the banded system (whose records hold one stretch–shear and one
//! bend–twist row per element), the node enters the end frame's own equation in primal form:
//! the implicit step's balance of that frame is
//!
//! `K_θ (θ − θ̃) = J_θᵀ λ + h² τ_c(θ)`,
//!
//! with `τ_c` the node's torque (elastic and damping, as in the explicit scheme), and Newton's
//! linearisation `τ_c(θ + Δθ) ≈ τ_c − H Δθ` with the Gauss–Newton stiffness
//! `H = l Jᵀ (K + c/h) J` of the node (`J = ∂Ω/∂θ` of `constraints::bend_twist`). The end
//! frame's inverse `K_θ⁻¹` then becomes the full 3×3 matrix `W = (K_θ + h² H)⁻¹`: the lanes treat
//! the frame as held (`ConstCols::free` is 0) and [`Work::clamp_precondition`],
//! [`Work::clamp_rhs`], [`Work::clamp_apply`] and [`Work::clamp_blocks`] put `W` and `τ_c` in
//! where the lanes had `K_θ⁻¹` and nothing. The fixed point is the exact implicit step; `H`
//! only steers the iteration.
//!
//! The Gauss–Seidel variant (`xpbd.rs`) projects the node as a compliant constraint of its own
//! ([`Work::clamp_sweep`]).

use super::constraints::{BendTwist, bend_twist};
use super::work::Work;
use super::{Consts, apply_rotation, inv_w};

use cosserat_model::quat::exp_rotation;
use cosserat_model::{Quat, Vec3};
use nalgebra::Matrix3;

/// The constants of one clamp (built with [`Consts`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ClampConst {
    /// The end (0: first, 1: last) and the rod's end frame.
    pub(crate) end: usize,
    pub(crate) frame: usize,
    /// The node: stiffness `(EI₁, EI₂, GJ)`, rest Darboux vector, damping and length.
    pub(crate) stiffness: Vec3<f64>,
    pub(crate) rest: Vec3<f64>,
    pub(crate) damping: f64,
    pub(crate) length: f64,
}

/// What one clamp carries through a step (kept in [`Work`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ClampStep {
    /// The clamp frame at the end of the step.
    pub(crate) frame: Quat<f64>,
    /// The node's `Ω − û` at the start of the step (damping).
    omega_start: Vec3<f64>,
    /// The step `h` of the implicit solve.
    h: f64,
    /// The end frame's `K_θ` (inertia and geometric bound) and the `W` of the last
    /// [`Work::clamp_precondition`].
    k_diag: Vec3<f64>,
    w: Matrix3<f64>,
    /// The multiplier of the Gauss–Seidel projection.
    lambda: Vec3<f64>,
}

impl ClampConst {
    /// The node between the clamp frame `clamp` and the end frame `q`, its Jacobian with
    /// respect to the end frame's body rotation.
    fn node(&self, clamp: &Quat<f64>, q: &Quat<f64>) -> (BendTwist<f64>, Matrix3<f64>) {
        if self.end == 0 {
            let b = bend_twist(clamp, q, &self.rest, self.length);
            let j = b.d_theta_b;
            (b, j)
        } else {
            let b = bend_twist(q, clamp, &self.rest, self.length);
            let j = b.d_theta_a;
            (b, j)
        }
    }

    /// The node's torque on the end frame `q` (body axes): `−l Jᵀ (K (Ω − û) + c (Ω − Ω_n)/h)`.
    pub(crate) fn torque(
        &self,
        clamp: &Quat<f64>,
        q: &Quat<f64>,
        start: &Vec3<f64>,
        h: f64,
    ) -> Vec3<f64> {
        let (b, j) = self.node(clamp, q);
        let mut f = self.stiffness.component_mul(&b.value);
        if self.damping > 0.0 {
            f += (b.value - start) * (self.damping / h);
        }
        -(j.transpose() * f) * self.length
    }
}

/// The upper triangle `[00, 01, 02, 11, 12, 22]` of the symmetric `m` added to `e`.
fn add_upper(e: &mut [f64], m: &Matrix3<f64>) {
    for (slot, (r, c)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
        .into_iter()
        .enumerate()
    {
        e[slot] += m[(r, c)];
    }
}

/// `m` added to the rows of an off-diagonal block (rows padded to four) at `e`.
fn add_block(e: &mut [f64], m: &Matrix3<f64>) {
    for r in 0..3 {
        for c in 0..3 {
            e[4 * r + c] += m[(r, c)];
        }
    }
}

impl Work {
    /// At the start of a step of `h` (the implicit solve's) that advances the clock by
    /// `advance` at time `t`, before the prediction: the clamp frames at the end of the step
    /// (turned by the clamps' prescribed angular velocities `omega[e]`, world axes) and, for
    /// damping, each node's value at the start.
    pub(crate) fn clamp_begin(&mut self, k: &Consts, h: f64, advance: f64, omega: [Vec3<f64>; 2]) {
        self.clamps.clear();
        for c in &k.clamps {
            let base = self.clamp_frames[c.end];
            let turned = |by: f64| {
                let r = exp_rotation(&(omega[c.end] * by)) * base;
                r / r.norm()
            };
            let frame = turned(advance);
            let omega_start = if c.damping > 0.0 {
                c.node(&turned(advance - h), &self.q.get(c.frame)).0.value
            } else {
                Vec3::zeros()
            };
            self.clamps.push(ClampStep {
                frame,
                omega_start,
                h,
                k_diag: Vec3::repeat(1.0),
                w: Matrix3::zeros(),
                lambda: Vec3::zeros(),
            });
        }
    }

    /// After an accepted step: the clamp frames are where the step left them.
    pub(crate) fn clamp_finish(&mut self, k: &Consts) {
        for (c, s) in k.clamps.iter().zip(&self.clamps) {
            self.clamp_frames[c.end] = s.frame;
        }
    }

    /// The torque of clamp `i` on its end frame at the current iterate [N m, body axes].
    pub(crate) fn clamp_torque(&self, k: &Consts, i: usize) -> Vec3<f64> {
        let (c, s) = (&k.clamps[i], &self.clamps[i]);
        c.torque(&s.frame, &self.q.get(c.frame), &s.omega_start, s.h)
    }

    /// The end frames' `W = (K_θ + h² H)⁻¹` at the current iterate, from the `K_θ` the lanes
    /// would have used (`sigma` is the geometric bound of each frame, as the lanes computed it).
    pub(crate) fn clamp_precondition(&mut self, k: &Consts, sigma: impl Fn(usize) -> f64) {
        for i in 0..self.clamps.len() {
            let c = k.clamps[i];
            let inertia = k.cols.inertia.get(c.frame);
            let k_diag = inertia.add_scalar(sigma(c.frame));
            // Every clamp on this frame (both, for a clamped rod of one element).
            let mut m = Matrix3::from_diagonal(&k_diag);
            for (d, s) in k.clamps.iter().zip(&self.clamps) {
                if d.frame == c.frame {
                    let (_, j) = d.node(&s.frame, &self.q.get(d.frame));
                    let stiff = d.stiffness.add_scalar(d.damping / s.h);
                    m +=
                        j.transpose() * Matrix3::from_diagonal(&stiff) * j * (d.length * s.h * s.h);
                }
            }
            let w = m.try_inverse().unwrap_or_else(Matrix3::zeros);
            let s = &mut self.clamps[i];
            s.k_diag = k_diag;
            s.w = w;
        }
    }

    /// The clamps whose end frame no earlier clamp has (both clamps of a one-element rod share
    /// it, and its `W` already holds both nodes).
    fn first_of_frame(k: &Consts, i: usize) -> bool {
        k.clamps[..i].iter().all(|d| d.frame != k.clamps[i].frame)
    }

    /// Sets `u_θ = W (K_θ (θ̃ − θ) + J_θᵀ λ + h² τ_c)` for the clamped end frames (after the lanes
    /// set `θ̃ − θ` there).
    pub(crate) fn clamp_rhs(&mut self, k: &Consts) {
        for i in 0..self.clamps.len() {
            if !Self::first_of_frame(k, i) {
                continue;
            }
            let f = k.clamps[i].frame;
            let s = self.q.get(f).conjugate() * self.q_pred.get(f);
            let to_target = s.imag() * (2.0 * inv_w(&s));
            let st = self.clamps[i];
            let mut r = st.k_diag.component_mul(&to_target);
            if !self.lambda_zero {
                r += self.dtheta.get(f);
            }
            for (j, d) in k.clamps.iter().enumerate() {
                if d.frame == f {
                    r += self.clamp_torque(k, j) * (st.h * st.h);
                }
            }
            // External moments on the end frame (`Work::rhs`).
            for &(j, t) in &self.torques {
                if j == f {
                    r += cosserat_model::quat::rotate_inv(&self.q.get(f), &t);
                }
            }
            self.u_th.set(f, &(st.w * r));
        }
    }

    /// Adds `W J_θᵀ Δλ` (in `dtheta`) to the clamped end frames' updates `u_θ`, before the lanes
    /// apply them with `K_θ⁻¹ = 0`.
    pub(crate) fn clamp_apply(&mut self, k: &Consts) {
        for i in 0..self.clamps.len() {
            if Self::first_of_frame(k, i) {
                let f = k.clamps[i].frame;
                let u = self.u_th.get(f) + self.clamps[i].w * self.dtheta.get(f);
                self.u_th.set(f, &u);
            }
        }
    }

    /// Adds the clamped end frames' terms to the blocks the lanes assembled with `K_θ⁻¹ = 0`
    /// for them: `[g]× W [g]×ᵀ` to the end element's stretch–shear block, and through the end
    /// frame's one interior node the node's `A W Aᵀ` and the coupling `[g]× W Aᵀ` (first end) or
    /// `B W [g]×ᵀ` (last end).
    pub(crate) fn clamp_blocks(&self, k: &Consts, out: &mut super::direct::Assembled) {
        use super::direct::Assembled;
        let n = self.n;
        for (i, c) in k.clamps.iter().enumerate() {
            if !Self::first_of_frame(k, i) {
                continue;
            }
            let f = c.frame;
            let w = self.clamps[i].w;
            let gx = (self.gamma.get(f) + Vec3::z()).cross_matrix();
            add_upper(&mut out.records[f], &(gx * w * gx.transpose()));
            if n < 2 {
                continue;
            }
            // The node through the end frame: node 0 (A = ∂Ω/∂θ_a) or node n − 2 (B).
            let node = if f == 0 { 0 } else { n - 2 };
            let s = self.rel.get(node);
            let il = 1.0 / k.lbar[node];
            let sv = (s.imag() * il).cross_matrix();
            let a = Matrix3::from_diagonal_element(s.w * il);
            if f == 0 {
                let da = sv - a;
                let e = &mut out.records[0];
                add_upper(&mut e[Assembled::BEND..], &(da * w * da.transpose()));
                add_block(&mut e[Assembled::NEXT..], &(gx * w * da.transpose()));
            } else {
                let db = sv + a;
                let e = &mut out.records[node];
                add_upper(&mut e[Assembled::BEND..], &(db * w * db.transpose()));
                add_block(
                    &mut e[Assembled::BEND + Assembled::NEXT..],
                    &(db * w * gx.transpose()),
                );
            }
        }
    }

    /// One Gauss–Seidel projection of each clamp's node as a compliant constraint
    /// `Ω − û + α̃ λ = 0` on its end frame (inverse inertia `inv_inertia`); returns the largest
    /// residual met, as an angle.
    pub(crate) fn clamp_sweep(&mut self, k: &Consts) -> f64 {
        let mut worst: f64 = 0.0;
        for i in 0..self.clamps.len() {
            let c = k.clamps[i];
            let s = self.clamps[i];
            let mut q = self.q.get(c.frame);
            let (b, j) = c.node(&s.frame, &q);
            let alpha = c
                .stiffness
                .map(|kk| (1.0 / (kk * c.length)).min(1e300) / (s.h * s.h));
            let r = -(b.value + alpha.component_mul(&s.lambda));
            worst = worst.max(r.amax() * c.length);
            let w = k.inv_inertia[c.frame];
            let mut a = j * Matrix3::from_diagonal(&w) * j.transpose();
            for d in 0..3 {
                a[(d, d)] += alpha[d];
            }
            if let Some(dl) = a.cholesky().map(|ch| ch.solve(&r)) {
                let dth = (j.transpose() * dl).component_mul(&w);
                apply_rotation(&mut q, &dth);
                self.q.set(c.frame, &q);
                self.clamps[i].lambda += dl;
            }
        }
        worst
    }
}
