//! The discrete Darboux vector of two neighbouring frames.
//!
//! CoRdE's strain rates are `u_k = 2 B_k q · q'` (paper eq. 6) with `q' = (q_{j+1} − q_j)/l`
//! (eq. 5). Because `B_k q_j · q_j = 0`, this equals `(2/l) Im(q̄_j q_{j+1})`: twice the
//! imaginary part of the relative rotation, divided by the distance between the frames. It is
//! expressed in the body frame of `q_j`, is invariant under rigid rotations of the rod, and
//! differs from the exact rotation rate only by the factor `sin(θ/2)/(θ/2)` of the angle `θ`
//! between the frames (second order in the element length).
//!
//! A quaternion and its negative are the same rotation. To keep the energy continuous we take
//! the sign of the relative rotation with a non-negative real part, i.e. the short way round.

use crate::{Quat, Real, Vec3};

/// The relative rotation `q̄_a q_b`, with its sign chosen so that its real part is ≥ 0.
#[inline(always)]
pub fn relative_rotation<T: Real>(qa: &Quat<T>, qb: &Quat<T>) -> Quat<T> {
    let s = qa.conjugate() * qb;
    if s.w < T::zero() { -s } else { s }
}

/// The discrete Darboux vector `(2/l) Im(q̄_a q_b)` in the body frame of `qa`, for frames a
/// distance `l` apart along the rod.
#[inline(always)]
pub fn darboux<T: Real>(qa: &Quat<T>, qb: &Quat<T>, l: T) -> Vec3<T> {
    relative_rotation(qa, qb).imag() * (T::lit(2.0) / l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quat::{exp_rotation, frame_from_tangent};

    /// Frenet frames of the helix `(R cos s/c, R sin s/c, h s/c)` with `c = √(R² + h²)` have
    /// Darboux vector `(0, κ, τ)` in the basis `(N, B, T)`, with `κ = R/c²` and `τ = h/c²`.
    #[test]
    fn helix_darboux_matches_curvature_and_torsion() {
        let (radius, pitch_h) = (0.05_f64, 0.02_f64);
        let c = (radius * radius + pitch_h * pitch_h).sqrt();
        let (kappa, tau) = (radius / (c * c), pitch_h / (c * c));
        let frame = |s: f64| {
            let a = s / c;
            let t = Vec3::new(-radius * a.sin(), radius * a.cos(), pitch_h) / c;
            let n = Vec3::new(-a.cos(), -a.sin(), 0.0);
            // Frenet frame as (d1, d2, d3) = (N, B, T).
            frame_from_tangent(&t, &n)
        };
        for l in [1e-2, 5e-3, 2.5e-3] {
            let u = darboux(&frame(0.3), &frame(0.3 + l), l);
            // Exact up to the factor sin(θ/2)/(θ/2), θ = |u| l.
            let theta = (kappa * kappa + tau * tau).sqrt() * l;
            let factor = (theta / 2.0).sin() / (theta / 2.0);
            assert!(u.x.abs() < 1e-9, "u1 = {}", u.x);
            assert!((u.y - kappa * factor).abs() < 1e-9 * kappa);
            assert!((u.z - tau * factor).abs() < 1e-9 * tau);
            // And it converges to (0, κ, τ) at second order.
            assert!((u.y - kappa).abs() <= kappa * theta * theta / 20.0);
        }
    }

    #[test]
    fn darboux_is_invariant_under_rigid_rotation_and_sign() {
        let qa = Quat::new(0.9_f64, 0.1, -0.2, 0.3).normalize();
        let qb = qa * exp_rotation(&Vec3::new(0.01, 0.02, -0.03));
        let rot = exp_rotation(&Vec3::new(1.0, -2.0, 0.5));
        let u = darboux(&qa, &qb, 0.01);
        assert!((darboux(&(rot * qa), &(rot * qb), 0.01) - u).norm() < 1e-10);
        assert!((darboux(&qa, &(-qb), 0.01) - u).norm() < 1e-10);
        assert!((u - Vec3::new(1.0, 2.0, -3.0)).norm() < 1e-3);
    }
}
