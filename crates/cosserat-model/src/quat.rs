//! Quaternion helpers on raw [`Quat`] values.
//!
//! Frames are stored as raw quaternions rather than `UnitQuaternion` so that state arrays are
//! plain `[x, y, z, w]` data (the GPU layout) and so that the integrator can renormalise
//! explicitly, once per step, where it chooses.

use crate::{Quat, Real, Vec3};

/// Rotates the body-frame vector `v` into world coordinates with the unit quaternion `q`.
#[inline(always)]
pub fn rotate<T: Real>(q: &Quat<T>, v: &Vec3<T>) -> Vec3<T> {
    // v' = v + 2 w (u × v) + 2 u × (u × v), with q = (u, w).
    let u = q.imag();
    let t = u.cross(v) * T::lit(2.0);
    v + t * q.w + u.cross(&t)
}

/// Rotates the world vector `v` into body coordinates (the inverse of [`rotate`]).
#[inline(always)]
pub fn rotate_inv<T: Real>(q: &Quat<T>, v: &Vec3<T>) -> Vec3<T> {
    let u = -q.imag();
    let t = u.cross(v) * T::lit(2.0);
    v + t * q.w + u.cross(&t)
}

/// The three directors `d1, d2, d3` (the body axes in world coordinates) of a frame.
///
/// The diagonal entries use the homogeneous form `w² + x² − y² − z²`, not `1 − 2 (y² + z²)`:
/// for a quaternion normalised in `f32` (`|q|² = 1 + δ`, `δ` a few `1e-8`) the homogeneous
/// matrix is a rotation scaled by `1 + δ`, so the small products the parallel penalty reads
/// (`d1·t`, `d2·t`, the shear) stay small, while `1 − 2 (…)` adds `δ` to them. That `δ`,
/// biased by the normalisation's rounding, made an `f32` cantilever sag 0.54 % deeper than in
/// `f64` at the default penalty (5.4 % at ten times it); with the homogeneous form 0.0005 %
/// (`tests/precision.rs`).
#[inline(always)]
pub fn directors<T: Real>(q: &Quat<T>) -> [Vec3<T>; 3] {
    let (x, y, z, w) = (q.i, q.j, q.k, q.w);
    let two = T::lit(2.0);
    let (ww, xx, yy, zz) = (w * w, x * x, y * y, z * z);
    [
        Vec3::new(
            ww + xx - yy - zz,
            two * (x * y + w * z),
            two * (x * z - w * y),
        ),
        Vec3::new(
            two * (x * y - w * z),
            ww - xx + yy - zz,
            two * (y * z + w * x),
        ),
        Vec3::new(
            two * (x * z + w * y),
            two * (y * z - w * x),
            ww - xx - yy + zz,
        ),
    ]
}

/// The third director `d3 = q e3 q̄`, which the parallel constraint aligns with the tangent (the
/// homogeneous form, see [`directors`]).
#[inline(always)]
pub fn d3<T: Real>(q: &Quat<T>) -> Vec3<T> {
    let (x, y, z, w) = (q.i, q.j, q.k, q.w);
    let two = T::lit(2.0);
    Vec3::new(
        two * (x * z + w * y),
        two * (y * z - w * x),
        w * w - x * x - y * y + z * z,
    )
}

/// The quaternion `exp(v / 2)`: a rotation by the angle `|v|` about `v`.
#[inline(always)]
pub fn exp_rotation<T: Real>(v: &Vec3<T>) -> Quat<T> {
    let angle = v.norm();
    let half = angle * T::lit(0.5);
    // sin(x/2)/x tends to 1/2; the series keeps small rotations exact to rounding.
    let s = if angle < T::lit(1e-4) {
        T::lit(0.5) - angle * angle / T::lit(48.0)
    } else {
        half.sin() / angle
    };
    Quat::new(half.cos(), v.x * s, v.y * s, v.z * s)
}

/// Advances the frame `q` by the body-frame rotation vector `theta` (`q ⊗ exp(θ/2)`) and
/// renormalises.
#[inline(always)]
pub fn rotate_body<T: Real>(q: &Quat<T>, theta: &Vec3<T>) -> Quat<T> {
    let r = q * exp_rotation(theta);
    r / r.norm()
}

/// The unit quaternion of the smallest rotation taking unit vector `a` onto unit vector `b`,
/// or `None` when they are (nearly) opposite and that rotation is not unique.
pub fn rotation_between<T: Real>(a: &Vec3<T>, b: &Vec3<T>) -> Option<Quat<T>> {
    let c = a.dot(b);
    if c < T::lit(-1.0 + 1e-9) {
        return None;
    }
    let axis = a.cross(b);
    let q = Quat::new(T::one() + c, axis.x, axis.y, axis.z);
    Some(q / q.norm())
}

/// A frame whose `d3` is the unit vector `t`, with `d1` as close as possible to `hint`
/// (which must not be parallel to `t`; a perpendicular fallback is chosen if it is).
pub fn frame_from_tangent<T: Real>(t: &Vec3<T>, hint: &Vec3<T>) -> Quat<T> {
    let mut d1 = hint - t * t.dot(hint);
    if d1.norm() < T::lit(1e-6) {
        let alt = if t.x.abs() < T::lit(0.9) {
            Vec3::x()
        } else {
            Vec3::y()
        };
        d1 = alt - t * t.dot(&alt);
    }
    let d1 = d1.normalize();
    let d2 = t.cross(&d1);
    let m = nalgebra::Matrix3::from_columns(&[d1, d2, *t]);
    let r = nalgebra::Rotation3::from_matrix_unchecked(m);
    *nalgebra::UnitQuaternion::from_rotation_matrix(&r).quaternion()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directors_match_rotation_of_axes() {
        let q = Quat::new(0.3_f64, -0.5, 0.7, 0.2);
        let q = q / q.norm();
        let d = directors(&q);
        for (k, e) in [Vec3::x(), Vec3::y(), Vec3::z()].iter().enumerate() {
            assert!((d[k] - rotate(&q, e)).norm() < 1e-14);
        }
        assert!((d3(&q) - d[2]).norm() < 1e-14);
        let v = Vec3::new(0.1, 2.0, -3.0);
        assert!((rotate_inv(&q, &rotate(&q, &v)) - v).norm() < 1e-13);
    }

    #[test]
    fn exp_rotation_is_unit_and_rotates_by_angle() {
        for v in [Vec3::new(1e-7_f64, 0.0, 0.0), Vec3::new(0.3, -0.2, 1.1)] {
            let q = exp_rotation(&v);
            assert!((q.norm() - 1.0).abs() < 1e-14);
            // A vector perpendicular to the axis turns by |v|.
            let axis = v.normalize();
            let p = axis.cross(&Vec3::new(0.3, 0.4, 0.5)).normalize();
            let cos = rotate(&q, &p).dot(&p);
            assert!((cos - v.norm().cos()).abs() < 1e-12);
        }
    }

    #[test]
    fn frame_from_tangent_is_adapted() {
        let t = Vec3::new(1.0_f64, 2.0, -0.5).normalize();
        let q = frame_from_tangent(&t, &Vec3::z());
        let d = directors(&q);
        assert!((d[2] - t).norm() < 1e-12);
        assert!(d[0].dot(&Vec3::z()) > 0.0);
        let q2 = rotation_between(&Vec3::x(), &t).unwrap();
        assert!((rotate(&q2, &Vec3::x()) - t).norm() < 1e-12);
        assert!(rotation_between::<f64>(&Vec3::x(), &(-Vec3::x())).is_none());
    }
}
