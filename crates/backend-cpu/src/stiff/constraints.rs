//! The two constraint functions of a position-and-orientation based Cosserat rod and their
//! exact Jacobians.
//!
//! After Kugelstadt & Schömer (2016, "Position and orientation based Cosserat rods", eqs. 31
//! and 32) with the compliance of XPBD (Macklin, Müller & Chentanez 2016, eq. 4), written in the
//! conventions of this workspace (`docs/model.md`):
//!
//! - **stretch–shear**, one per element `j`, in the body frame of `q_j`:
//!   `Γ_j = R_jᵀ (r_{j+1} − r_j) / l0_j − e3`.
//!   Its first two components are the shear of the element (the angle between the tangent and
//!   `d3`), the third its stretch `d3 · e / l0 − 1`. Its potential `½ l0 Γᵀ diag(K_p, K_p, K_s) Γ`
//!   equals the model's parallel penalty `½ K_p l0 |t − d3|²` plus stretch energy
//!   `½ K_s l0 (|e|/l0 − 1)²` up to terms of fourth order in the shear angle `φ`
//!   (`|t − d3|² = 4 sin²(φ/2)`, `Γ₁² + Γ₂² = (|e|/l0)² sin² φ`), i.e. a relative difference of
//!   order `φ²` (below 1e-10 for the wires and loads of `docs/stiff-solver.md`).
//! - **bend–twist**, one per interior node `j`, between frames `j` and `j + 1`:
//!   `Ω_j = (2 / l̄_j) Im(q̄_j q_{j+1}) − û_j`, exactly the discrete Darboux vector of
//!   `cosserat_model::darboux` minus its rest value, so its potential
//!   `½ l̄ Ωᵀ diag(K1, K2, K3) Ω` *is* the model's bending and twisting energy (paper eq. 3).
//!
//! Jacobians are taken with respect to point positions and to **body-frame** rotations
//! `q → q ⊗ exp(θ/2)`, the same variations as the torques of `cosserat_model::energy`:
//!
//! - `∂Γ_j/∂r_{j+1} = R_jᵀ / l0`, `∂Γ_j/∂r_j = −R_jᵀ / l0`, `∂Γ_j/∂θ_j = [g_j]×` with
//!   `g_j = R_jᵀ e_j / l0 = Γ_j + e3` (from `(R (I + [θ]×))ᵀ e = Rᵀe + [Rᵀe]× θ`);
//! - with `s = q̄_j q_{j+1}` (sign chosen so that `s_w ≥ 0`):
//!   `∂Ω_j/∂θ_j = −(s_w I − [s_v]×) / l̄`, `∂Ω_j/∂θ_{j+1} = (s_w I + [s_v]×) / l̄`
//!   (`d(q̄_a q_b) = s ⊗ (0, θ_b/2)` and `(0, −θ_a/2) ⊗ s`).
//!
//! `tests/stiff.rs` checks every block against central finite differences.

use cosserat_model::darboux::relative_rotation;
use cosserat_model::{Quat, Real, Vec3};
use nalgebra::Matrix3;

/// The cross-product matrix `[a]×` with `[a]× b = a × b`.
#[inline(always)]
pub fn cross_matrix<T: Real>(a: &Vec3<T>) -> Matrix3<T> {
    let z = T::zero();
    Matrix3::new(z, -a.z, a.y, a.z, z, -a.x, -a.y, a.x, z)
}

/// The transpose `Rᵀ` of the rotation matrix of the unit quaternion `q` (world → body).
#[inline(always)]
pub fn rotation_transpose<T: Real>(q: &Quat<T>) -> Matrix3<T> {
    let d = cosserat_model::quat::directors(q);
    // Rows of Rᵀ are the directors.
    Matrix3::new(
        d[0].x, d[0].y, d[0].z, d[1].x, d[1].y, d[1].z, d[2].x, d[2].y, d[2].z,
    )
}

/// The stretch–shear constraint of one element and its Jacobian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StretchShear<T: Real> {
    /// `Γ = Rᵀ (r_b − r_a) / l0 − e3` (body frame; dimensionless).
    pub value: Vec3<T>,
    /// `∂Γ/∂r_b = Rᵀ / l0`; `∂Γ/∂r_a` is its negative.
    pub d_rb: Matrix3<T>,
    /// `∂Γ/∂θ = [Γ + e3]×` for a body-frame rotation of the element's frame.
    pub d_theta: Matrix3<T>,
}

/// Evaluates the stretch–shear constraint of the element `r_a → r_b` with frame `q` and rest
/// length `l0`.
#[inline(always)]
pub fn stretch_shear<T: Real>(ra: &Vec3<T>, rb: &Vec3<T>, q: &Quat<T>, l0: T) -> StretchShear<T> {
    let rt = rotation_transpose(q);
    let inv_l = T::one() / l0;
    let g = rt * (rb - ra) * inv_l;
    StretchShear {
        value: Vec3::new(g.x, g.y, g.z - T::one()),
        d_rb: rt * inv_l,
        d_theta: cross_matrix(&g),
    }
}

/// The bend–twist constraint of one interior node and its Jacobian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BendTwist<T: Real> {
    /// `Ω − û` with `Ω = (2/l̄) Im(q̄_a q_b)` (body frame of `q_a`; 1/m).
    pub value: Vec3<T>,
    /// `∂Ω/∂θ_a`.
    pub d_theta_a: Matrix3<T>,
    /// `∂Ω/∂θ_b`.
    pub d_theta_b: Matrix3<T>,
}

/// Evaluates the bend–twist constraint between frames `qa` and `qb` a distance `l` apart, with
/// rest Darboux vector `rest`.
#[inline(always)]
pub fn bend_twist<T: Real>(qa: &Quat<T>, qb: &Quat<T>, rest: &Vec3<T>, l: T) -> BendTwist<T> {
    let s = relative_rotation(qa, qb);
    let sv = s.imag();
    let inv_l = T::one() / l;
    let c = cross_matrix(&sv);
    let w = Matrix3::from_diagonal_element(s.w);
    BendTwist {
        value: sv * (T::lit(2.0) * inv_l) - rest,
        d_theta_a: (c - w) * inv_l,
        d_theta_b: (w + c) * inv_l,
    }
}
