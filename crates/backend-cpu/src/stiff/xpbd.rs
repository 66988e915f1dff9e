//! XPBD with Gauss–Seidel sweeps: each constraint block solved on its own, in order along the
//! rod, each seeing the corrections of the ones before it (Macklin et al. 2016, eq. 18, with
//! the 3-row blocks of Kugelstadt & Schömer 2016 solved by a 3×3 system per constraint).
//!
//! Kept as the measured alternative to the direct solve: one sweep costs about a third of a
//! direct iteration, but a correction travels one element per sweep, so a long stiff rod needs
//! of the order of `n²` sweeps to feel a load at its far end (`docs/stiff-solver.md`).

use super::constraints::{bend_twist, stretch_shear};
use super::{Consts, Work, apply_rotation};
use nalgebra::Matrix3;

/// `a diag(w) aᵀ`.
#[inline(always)]
fn awat(a: &Matrix3<f64>, w: &nalgebra::Vector3<f64>) -> Matrix3<f64> {
    let mut aw = *a;
    for c in 0..3 {
        for r in 0..3 {
            aw[(r, c)] *= w[c];
        }
    }
    aw * a.transpose()
}

/// One Gauss–Seidel sweep over all constraints; returns the largest residual met (scaled as in
/// `Work::rhs`) before the sweep corrected it.
pub(crate) fn sweep(w: &mut Work, k: &Consts) -> f64 {
    let n = k.l0.len();
    let mut worst: f64 = w.clamp_sweep(k);
    for j in 0..n {
        // Stretch–shear of element j.
        let (xa, xb, mut q) = (w.x.get(j), w.x.get(j + 1), w.q.get(j));
        let s = stretch_shear(&xa, &xb, &q, k.l0[j]);
        let lg = w.lambda[0].get(j);
        let r = -(s.value + k.alpha_gamma[j].component_mul(&lg));
        worst = worst.max(r.amax());
        let wsum = k.inv_mass[j] + k.inv_mass[j + 1];
        let mut a = awat(&s.d_theta, &k.inv_inertia[j]) + s.d_rb * s.d_rb.transpose() * wsum;
        for c in 0..3 {
            a[(c, c)] += k.alpha_gamma[j][c];
        }
        if let Some(dl) = a.cholesky().map(|ch| ch.solve(&r)) {
            let f = s.d_rb.transpose() * dl;
            w.x.set(j, &(xa - f * k.inv_mass[j]));
            w.x.set(j + 1, &(xb + f * k.inv_mass[j + 1]));
            let dth = (s.d_theta.transpose() * dl).component_mul(&k.inv_inertia[j]);
            apply_rotation(&mut q, &dth);
            w.q.set(j, &q);
            w.lambda[0].set(j, &(lg + dl));
        }
        // Bend–twist of the node below element j (between frames j − 1 and j).
        if j >= 1 {
            let i = j - 1;
            let (mut qa, mut qb) = (w.q.get(i), w.q.get(j));
            let b = bend_twist(&qa, &qb, &k.rest_u[i], k.lbar[i]);
            let lo = w.lambda[1].get(i);
            let r = -(b.value + k.alpha_omega[i].component_mul(&lo));
            worst = worst.max(r.amax() * k.lbar[i]);
            let mut a =
                awat(&b.d_theta_a, &k.inv_inertia[i]) + awat(&b.d_theta_b, &k.inv_inertia[j]);
            for c in 0..3 {
                a[(c, c)] += k.alpha_omega[i][c];
            }
            if let Some(dl) = a.cholesky().map(|ch| ch.solve(&r)) {
                let da = (b.d_theta_a.transpose() * dl).component_mul(&k.inv_inertia[i]);
                let db = (b.d_theta_b.transpose() * dl).component_mul(&k.inv_inertia[j]);
                apply_rotation(&mut qa, &da);
                apply_rotation(&mut qb, &db);
                w.q.set(i, &qa);
                w.q.set(j, &qb);
                w.lambda[1].set(i, &(lo + dl));
            }
        }
    }
    worst
}
