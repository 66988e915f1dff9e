//! Inextensibility as velocity-level distance constraints with position-drift correction.
//!
//! For the element between points `a` and `b` with rest length `l0`, let `p = r + h v` be the
//! positions the current velocities would reach at the end of the step `h`. The constraint is
//! `C = |p_b − p_a| − l0 = 0`. One impulse changes the velocities along `n = (p_b − p_a)/|…|`,
//! in proportion to the inverse masses, by exactly what removes `C` to first order:
//!
//! `λ = −C / (h (w_a + w_b))`, `v_a −= w_a λ n`, `v_b += w_b λ n`.
//!
//! Because `C` is measured at the predicted positions, an impulse removes both the velocity
//! that would stretch the element and any length error already present, so lengths do not
//! creep over long runs (no separate Baumgarte term is needed), and the impulses conserve linear
//! momentum exactly. Repeating the sweep is a nonlinear Gauss–Seidel (or red–black) iteration
//! that converges to exact inextensibility at the end of the step.
//!
//! Kinematic points (pinned or driven ends) have zero inverse mass and are never moved.

use cosserat_model::{Real, Vec3};

pub use cosserat_problem::Ordering;

/// Applies the impulse of the distance constraint between points `a` and `a + 1`.
#[inline(always)]
fn project<T: Real>(
    positions: &[Vec3<T>],
    velocities: &mut [Vec3<T>],
    inv_masses: &[T],
    l0: T,
    h: T,
    a: usize,
) {
    let b = a + 1;
    let (wa, wb) = (inv_masses[a], inv_masses[b]);
    let w = wa + wb;
    if w <= T::zero() {
        return;
    }
    // Element vector first, then the velocity term: in f32 the difference of two predicted
    // absolute positions would lose most digits of a short element far from the origin.
    let d = (positions[b] - positions[a]) + (velocities[b] - velocities[a]) * h;
    let len2 = d.norm_squared();
    let len = len2.sqrt();
    // λ/len folds the normalisation of d into the impulse.
    let s = (l0 - len) / (h * w * len);
    velocities[a] -= d * (s * wa);
    velocities[b] += d * (s * wb);
}

/// One sweep over the distance constraints of a rod.
///
/// `positions` are the positions at the start of the step, `velocities` the integrated
/// velocities (updated in place), `h` the time step.
pub fn solve_distance_iteration<T: Real>(
    positions: &[Vec3<T>],
    velocities: &mut [Vec3<T>],
    inv_masses: &[T],
    rest_lengths: &[T],
    h: T,
    ordering: Ordering,
) {
    let n = rest_lengths.len();
    debug_assert_eq!(positions.len(), n + 1);
    debug_assert_eq!(velocities.len(), n + 1);
    match ordering {
        Ordering::GaussSeidel => {
            for j in 0..n {
                project(positions, velocities, inv_masses, rest_lengths[j], h, j);
            }
        }
        Ordering::RedBlack => {
            for start in [0, 1] {
                for j in (start..n).step_by(2) {
                    project(positions, velocities, inv_masses, rest_lengths[j], h, j);
                }
            }
        }
    }
}

/// The impulse of the distance constraint between points `a` and `a + 1`, on coordinate
/// slices (`[x, y, z]`): the arithmetic of [`solve_distance_iteration`]. Returns the impulse
/// [N s] given to point `a + 1` (its negative went to `a`); zero when both are kinematic.
#[inline(always)]
pub fn project_distance_soa<T: Real>(
    positions: [&[T]; 3],
    velocities: [&mut [T]; 3],
    inv_masses: &[T],
    l0: T,
    h: T,
    a: usize,
) -> Vec3<T> {
    let [rx, ry, rz] = positions;
    let [vx, vy, vz] = velocities;
    let b = a + 1;
    let (wa, wb) = (inv_masses[a], inv_masses[b]);
    let w = wa + wb;
    if w <= T::zero() {
        return Vec3::zeros();
    }
    let dx = (rx[b] - rx[a]) + (vx[b] - vx[a]) * h;
    let dy = (ry[b] - ry[a]) + (vy[b] - vy[a]) * h;
    let dz = (rz[b] - rz[a]) + (vz[b] - vz[a]) * h;
    let len = (dx * dx + dy * dy + dz * dz).sqrt();
    let s = (l0 - len) / (h * w * len);
    let (sa, sb) = (s * wa, s * wb);
    vx[a] -= dx * sa;
    vy[a] -= dy * sa;
    vz[a] -= dz * sa;
    vx[b] += dx * sb;
    vy[b] += dy * sb;
    vz[b] += dz * sb;
    Vec3::new(dx, dy, dz) * s
}

/// One Gauss–Seidel sweep of [`solve_distance_iteration`] on coordinate slices (`[x, y, z]`).
pub fn solve_distance_gauss_seidel_soa<T: Real>(
    positions: [&[T]; 3],
    velocities: [&mut [T]; 3],
    inv_masses: &[T],
    rest_lengths: &[T],
    h: T,
) {
    let [vx, vy, vz] = velocities;
    for (j, &l0) in rest_lengths.iter().enumerate() {
        project_distance_soa(
            positions,
            [&mut *vx, &mut *vy, &mut *vz],
            inv_masses,
            l0,
            h,
            j,
        );
    }
}

/// The smallest and largest of `|r_{j+1} − r_j| / l0_j` over a rod, from squared lengths (one
/// square root per call, not per element).
pub fn strain_extremes<T: Real>(positions: &[Vec3<T>], rest_lengths: &[T]) -> (T, T) {
    let mut lo = T::max_value().unwrap_or(T::lit(f64::MAX));
    let mut hi = T::zero();
    for (j, &l0) in rest_lengths.iter().enumerate() {
        let r = (positions[j + 1] - positions[j]).norm_squared() / (l0 * l0);
        lo = lo.min(r);
        hi = hi.max(r);
    }
    (lo.sqrt(), hi.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Positions, velocities, inverse masses and rest lengths of a test chain.
    type Chain = (Vec<Vec3<f64>>, Vec<Vec3<f64>>, Vec<f64>, Vec<f64>);

    fn wobbly(n: usize) -> Chain {
        let pos: Vec<_> = (0..=n)
            .map(|i| Vec3::new(i as f64 * 0.01, 0.002 * (i as f64).sin(), 0.0))
            .collect();
        let vel: Vec<_> = (0..=n)
            .map(|i| Vec3::new((i as f64 * 0.7).cos(), (i as f64 * 1.3).sin(), 0.3))
            .collect();
        let inv: Vec<_> = (0..=n).map(|i| 1.0 / (1.0 + 0.1 * i as f64)).collect();
        let l0 = vec![0.01; n];
        (pos, vel, inv, l0)
    }

    fn predicted_lengths_error(pos: &[Vec3<f64>], vel: &[Vec3<f64>], l0: &[f64], h: f64) -> f64 {
        (0..l0.len())
            .map(|j| {
                (((pos[j + 1] + vel[j + 1] * h) - (pos[j] + vel[j] * h)).norm() - l0[j]).abs()
                    / l0[j]
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn sweeps_converge_to_rest_lengths_and_conserve_momentum() {
        for ordering in [Ordering::GaussSeidel, Ordering::RedBlack] {
            let (pos, mut vel, inv, l0) = wobbly(40);
            let h = 1e-3;
            let momentum =
                |v: &[Vec3<f64>]| -> Vec3<f64> { v.iter().zip(&inv).map(|(v, w)| v / *w).sum() };
            let p0 = momentum(&vel);
            let e0 = predicted_lengths_error(&pos, &vel, &l0, h);
            assert!(
                e0 > 1e-2,
                "the test must start far from the constraint, e0 = {e0}"
            );
            for _ in 0..2000 {
                solve_distance_iteration(&pos, &mut vel, &inv, &l0, h, ordering);
            }
            let e = predicted_lengths_error(&pos, &vel, &l0, h);
            assert!(e < 1e-9, "{ordering:?}: residual strain {e}");
            assert!((momentum(&vel) - p0).norm() < 1e-9 * p0.norm());
        }
    }

    #[test]
    fn kinematic_points_are_not_moved() {
        let (pos, mut vel, mut inv, l0) = wobbly(10);
        inv[0] = 0.0;
        let v0 = vel[0];
        for _ in 0..50 {
            solve_distance_iteration(&pos, &mut vel, &inv, &l0, 1e-3, Ordering::GaussSeidel);
        }
        assert_eq!(vel[0], v0);
    }

    #[test]
    fn strain_extremes_of_a_stretched_rod() {
        let pos = vec![
            Vec3::new(0.0_f64, 0.0, 0.0),
            Vec3::new(1.1, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
        ];
        let (lo, hi) = strain_extremes(&pos, &[1.0, 1.0]);
        assert!((lo - 0.9).abs() < 1e-12 && (hi - 1.1).abs() < 1e-12);
    }
}
