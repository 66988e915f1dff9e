//! The direct solve of all constraints of a rod at once (Deul, Kugelstadt, Weiler & Bender
//! 2018, "Direct position-based solver for stiff rods", section 4).
//!
//! One Newton step of XPBD (Macklin et al. 2016, eq. 12 with the Schur complement of eq. 9)
//! solves `(J M⁻¹ Jᵀ + α̃) Δλ = −(C + α̃ λ)` for every constraint of the rod together. Deul et
//! al. observe that the constraint graph of a rod is a chain, so with the unknowns ordered
//! element by element, `(λ_Γ0, λ_Ω0, λ_Γ1, λ_Ω1, …)`, the matrix is block tridiagonal with 6×6
//! blocks (their eq. 17; they factorise it with a sparse LDLᵀ over the tree, which for a chain
//! is this recursion). Block `j` couples to block `j + 1` through point `r_{j+1}` (shared by
//! `Γ_j` and `Γ_{j+1}`) and frame `q_{j+1}` (shared by `Ω_j`, `Ω_{j+1}` and `Γ_{j+1}`).
//!
//! The block Cholesky factorisation `S'_0 = D_0`, `S'_j = D_j − U_{j−1}ᵀ U_{j−1}`,
//! `S'_j = L_j L_jᵀ`, `U_j = L_j⁻¹ E_j` costs about 500 multiply–adds per element, a solve with
//! it about 115; both are `O(n)` and exact, so the number of iterations does not grow with the
//! length of the rod or with its stiffness, which is what Gauss–Seidel cannot offer
//! (`docs/stiff-solver.md` measures both).
//!
//! The last element has no bend–twist constraint; its three `Ω` rows are identity rows with a
//! zero right-hand side, which keeps every block 6×6.
//!
//! Everything here is `f64`: with frame inverse inertias near 1e12 and compliances near 1e-11
//! the matrix spans more than `f32` can resolve.

use super::constraints::{BendTwist, StretchShear};
use cosserat_model::Vec3;
use nalgebra::Matrix3;

/// A dense 6×6 block, row-major.
pub(crate) type M6 = [[f64; 6]; 6];

/// `a diag(w) bᵀ`.
#[inline(always)]
fn mwmt(a: &Matrix3<f64>, w: &Vec3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let mut aw = *a;
    for c in 0..3 {
        for r in 0..3 {
            aw[(r, c)] *= w[c];
        }
    }
    aw * b.transpose()
}

#[inline(always)]
fn put(m: &mut M6, r0: usize, c0: usize, b: &Matrix3<f64>) {
    for r in 0..3 {
        for c in 0..3 {
            m[r0 + r][c0 + c] = b[(r, c)];
        }
    }
}

/// In-place Cholesky of the lower triangle; the diagonal holds the inverse pivots. A pivot that
/// is not positive (a row no free degree of freedom can change, e.g. an element whose points and
/// frame are all held) gets an inverse of zero, which leaves its multiplier unchanged.
#[inline(always)]
fn chol6(a: &mut M6) {
    for j in 0..6 {
        let mut d = a[j][j];
        for k in 0..j {
            d -= a[j][k] * a[j][k];
        }
        let inv = if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 };
        a[j][j] = inv;
        for i in j + 1..6 {
            let mut s = a[i][j];
            for k in 0..j {
                s -= a[i][k] * a[j][k];
            }
            a[i][j] = s * inv;
        }
    }
}

/// `b ← L⁻¹ b`.
#[inline(always)]
fn forward6(l: &M6, b: &mut [f64; 6]) {
    for i in 0..6 {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * b[k];
        }
        b[i] = s * l[i][i];
    }
}

/// `b ← L⁻ᵀ b`.
#[inline(always)]
fn backward6(l: &M6, b: &mut [f64; 6]) {
    for i in (0..6).rev() {
        let mut s = b[i];
        for k in i + 1..6 {
            s -= l[k][i] * b[k];
        }
        b[i] = s * l[i][i];
    }
}

/// What the assembly needs to know about one rod besides its current constraint Jacobians.
pub(crate) struct Masses<'a> {
    /// Inverse point masses (zero for held points).
    pub(crate) inv_mass: &'a [f64],
    /// Inverse principal inertias of the frames (zero for held frames).
    pub(crate) inv_inertia: &'a [Vec3<f64>],
    /// `α̃ = α / h²` of each stretch–shear constraint.
    pub(crate) alpha_gamma: &'a [Vec3<f64>],
    /// `α̃` of each bend–twist constraint.
    pub(crate) alpha_omega: &'a [Vec3<f64>],
}

/// The diagonal block `D_j` of `J M⁻¹ Jᵀ + α̃`.
fn diagonal_block(j: usize, ss: &[StretchShear<f64>], bt: &[BendTwist<f64>], m: &Masses<'_>) -> M6 {
    let mut d = [[0.0; 6]; 6];
    let s = &ss[j];
    let wj = &m.inv_inertia[j];
    let wsum = m.inv_mass[j] + m.inv_mass[j + 1];
    let mut gg = mwmt(&s.d_theta, wj, &s.d_theta) + s.d_rb * s.d_rb.transpose() * wsum;
    for k in 0..3 {
        gg[(k, k)] += m.alpha_gamma[j][k];
    }
    put(&mut d, 0, 0, &gg);
    if j < bt.len() {
        let b = &bt[j];
        let go = mwmt(&s.d_theta, wj, &b.d_theta_a);
        let mut oo = mwmt(&b.d_theta_a, wj, &b.d_theta_a)
            + mwmt(&b.d_theta_b, &m.inv_inertia[j + 1], &b.d_theta_b);
        for k in 0..3 {
            oo[(k, k)] += m.alpha_omega[j][k];
        }
        put(&mut d, 0, 3, &go);
        put(&mut d, 3, 0, &go.transpose());
        put(&mut d, 3, 3, &oo);
    } else {
        for k in 3..6 {
            d[k][k] = 1.0;
        }
    }
    d
}

/// The off-diagonal block `E_j` (rows of element `j`, columns of element `j + 1`).
fn off_diagonal_block(
    j: usize,
    ss: &[StretchShear<f64>],
    bt: &[BendTwist<f64>],
    m: &Masses<'_>,
) -> M6 {
    let mut e = [[0.0; 6]; 6];
    let w = m.inv_mass[j + 1];
    put(
        &mut e,
        0,
        0,
        &(ss[j].d_rb * ss[j + 1].d_rb.transpose() * (-w)),
    );
    let b = &bt[j];
    let wb = &m.inv_inertia[j + 1];
    put(&mut e, 3, 0, &mwmt(&b.d_theta_b, wb, &ss[j + 1].d_theta));
    if j + 1 < bt.len() {
        put(&mut e, 3, 3, &mwmt(&b.d_theta_b, wb, &bt[j + 1].d_theta_a));
    }
    e
}

/// The factorised block tridiagonal matrix of one rod.
#[derive(Clone, Debug, Default)]
pub(crate) struct BlockTridiagonal {
    l: Vec<M6>,
    u: Vec<M6>,
}

impl BlockTridiagonal {
    /// Assembles `J M⁻¹ Jᵀ + α̃` at the configuration the Jacobians were evaluated at and
    /// factorises it.
    pub(crate) fn factor(
        &mut self,
        ss: &[StretchShear<f64>],
        bt: &[BendTwist<f64>],
        m: &Masses<'_>,
    ) {
        let n = ss.len();
        self.l.resize(n, [[0.0; 6]; 6]);
        self.u.resize(n.saturating_sub(1), [[0.0; 6]; 6]);
        for j in 0..n {
            let mut d = diagonal_block(j, ss, bt, m);
            if j > 0 {
                let u = &self.u[j - 1];
                for r in 0..6 {
                    for c in 0..=r {
                        let mut s = 0.0;
                        for k in 0..6 {
                            s += u[k][r] * u[k][c];
                        }
                        d[r][c] -= s;
                    }
                }
            }
            chol6(&mut d);
            self.l[j] = d;
            if j + 1 < n {
                let e = off_diagonal_block(j, ss, bt, m);
                let mut u = [[0.0; 6]; 6];
                for c in 0..6 {
                    let mut col = [e[0][c], e[1][c], e[2][c], e[3][c], e[4][c], e[5][c]];
                    forward6(&self.l[j], &mut col);
                    for r in 0..6 {
                        u[r][c] = col[r];
                    }
                }
                self.u[j] = u;
            }
        }
    }

    /// Solves the factorised system in place: `x` holds the right-hand side on entry and the
    /// solution on return.
    pub(crate) fn solve(&self, x: &mut [[f64; 6]]) {
        let n = self.l.len();
        debug_assert_eq!(x.len(), n);
        for j in 0..n {
            if j > 0 {
                let (prev, cur) = x.split_at_mut(j);
                let (y, u) = (&prev[j - 1], &self.u[j - 1]);
                for r in 0..6 {
                    let mut s = 0.0;
                    for k in 0..6 {
                        s += u[k][r] * y[k];
                    }
                    cur[0][r] -= s;
                }
            }
            forward6(&self.l[j], &mut x[j]);
        }
        for j in (0..n).rev() {
            if j + 1 < n {
                let (cur, next) = x.split_at_mut(j + 1);
                let (z, u) = (&next[0], &self.u[j]);
                for r in 0..6 {
                    let mut s = 0.0;
                    for k in 0..6 {
                        s += u[r][k] * z[k];
                    }
                    cur[j][r] -= s;
                }
            }
            backward6(&self.l[j], &mut x[j]);
        }
    }

    /// Dense `J M⁻¹ Jᵀ + α̃` (order `6n`), for tests of the assembly.
    #[cfg(test)]
    pub(crate) fn dense(
        ss: &[StretchShear<f64>],
        bt: &[BendTwist<f64>],
        m: &Masses<'_>,
    ) -> Vec<Vec<f64>> {
        let n = ss.len();
        let mut a = vec![vec![0.0; 6 * n]; 6 * n];
        for j in 0..n {
            let d = diagonal_block(j, ss, bt, m);
            for r in 0..6 {
                for c in 0..6 {
                    a[6 * j + r][6 * j + c] = d[r][c];
                }
            }
            if j + 1 < n {
                let e = off_diagonal_block(j, ss, bt, m);
                for r in 0..6 {
                    for c in 0..6 {
                        a[6 * j + r][6 * (j + 1) + c] = e[r][c];
                        a[6 * (j + 1) + c][6 * j + r] = e[r][c];
                    }
                }
            }
        }
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stiff::constraints::{bend_twist, stretch_shear};
    use cosserat_model::Quat;
    use cosserat_model::quat::exp_rotation;

    /// Constraints, inverse masses and inertias of a test chain.
    type Chain = (
        Vec<StretchShear<f64>>,
        Vec<BendTwist<f64>>,
        Vec<f64>,
        Vec<Vec3<f64>>,
    );

    /// A curved, twisted, slightly sheared and stretched chain with one held point and one held
    /// frame, and its constraints.
    fn chain(n: usize) -> Chain {
        let mut x = vec![Vec3::zeros()];
        let mut q = Vec::new();
        let mut frame = Quat::identity();
        for j in 0..n {
            let fj = j as f64;
            frame *= exp_rotation(&Vec3::new(0.2 * fj.sin(), 0.1, -0.15 * fj.cos()));
            q.push(frame);
            let d3 = cosserat_model::quat::d3(&frame);
            let e = d3 * 0.01 * (1.0 + 0.01 * fj.cos()) + Vec3::new(1e-4, -2e-4, 5e-5);
            x.push(x[j] + e);
        }
        let ss = (0..n)
            .map(|j| stretch_shear(&x[j], &x[j + 1], &q[j], 0.01))
            .collect();
        let bt = (0..n - 1)
            .map(|j| bend_twist(&q[j], &q[j + 1], &Vec3::new(0.5, -1.0, 2.0), 0.01))
            .collect();
        let mut w: Vec<f64> = (0..=n).map(|i| 1e3 * (1.0 + 0.1 * i as f64)).collect();
        w[0] = 0.0;
        let mut wi: Vec<Vec3<f64>> = (0..n)
            .map(|j| Vec3::new(1e8, 1.1e8, 0.5e8) * (1.0 + 0.05 * j as f64))
            .collect();
        wi[n - 1] = Vec3::zeros();
        (ss, bt, w, wi)
    }

    /// The block assembly equals `J M⁻¹ Jᵀ + α̃` built densely from the constraint Jacobians,
    /// and the block factorisation solves it.
    #[test]
    fn block_assembly_and_solve_match_dense() {
        let n = 6;
        let (ss, bt, w, wi) = chain(n);
        let ag: Vec<_> = (0..n)
            .map(|j| Vec3::new(1e-3, 2e-3, j as f64 * 1e-4))
            .collect();
        let ao: Vec<_> = (0..n - 1).map(|_| Vec3::new(3e-2, 3e-2, 5e-2)).collect();
        let m = Masses {
            inv_mass: &w,
            inv_inertia: &wi,
            alpha_gamma: &ag,
            alpha_omega: &ao,
        };
        // Dense J: rows 6 per element, columns 3 per point then 3 per frame.
        let cols = 3 * (n + 1) + 3 * n;
        let mut jac = vec![vec![0.0; cols]; 6 * n];
        let mut put = |r0: usize, c0: usize, b: &Matrix3<f64>| {
            for r in 0..3 {
                for c in 0..3 {
                    jac[r0 + r][c0 + c] += b[(r, c)];
                }
            }
        };
        let fr = |j: usize| 3 * (n + 1) + 3 * j;
        for j in 0..n {
            put(6 * j, 3 * (j + 1), &ss[j].d_rb);
            put(6 * j, 3 * j, &(-ss[j].d_rb));
            put(6 * j, fr(j), &ss[j].d_theta);
            if j + 1 < n {
                put(6 * j + 3, fr(j), &bt[j].d_theta_a);
                put(6 * j + 3, fr(j + 1), &bt[j].d_theta_b);
            }
        }
        let minv: Vec<f64> = (0..cols)
            .map(|c| {
                if c < 3 * (n + 1) {
                    w[c / 3]
                } else {
                    let k = c - 3 * (n + 1);
                    wi[k / 3][k % 3]
                }
            })
            .collect();
        let a = BlockTridiagonal::dense(&ss, &bt, &m);
        let mut worst: f64 = 0.0;
        let scale = a.iter().flatten().fold(0.0_f64, |s, v| s.max(v.abs()));
        for r in 0..6 * n {
            for c in 0..6 * n {
                let mut s: f64 = (0..cols).map(|k| jac[r][k] * minv[k] * jac[c][k]).sum();
                if r == c {
                    let (j, k) = (r / 6, r % 6);
                    s += if k < 3 {
                        ag[j][k]
                    } else if j + 1 < n {
                        ao[j][k - 3]
                    } else {
                        1.0
                    };
                }
                worst = worst.max((s - a[r][c]).abs());
            }
        }
        assert!(
            worst < 1e-12 * scale,
            "assembly error {worst} (scale {scale})"
        );
        let mut f = BlockTridiagonal::default();
        f.factor(&ss, &bt, &m);
        let b: Vec<[f64; 6]> = (0..n)
            .map(|j| {
                let mut v = [0.0; 6];
                for (k, x) in v.iter_mut().enumerate() {
                    *x = ((6 * j + k) as f64 * 0.37).sin();
                }
                if j + 1 == n {
                    v[3..].fill(0.0);
                }
                v
            })
            .collect();
        let mut x = b.clone();
        f.solve(&mut x);
        let flat: Vec<f64> = x.iter().flatten().copied().collect();
        for r in 0..6 * n {
            let ax: f64 = (0..6 * n).map(|c| a[r][c] * flat[c]).sum();
            let rhs = b[r / 6][r % 6];
            assert!((ax - rhs).abs() < 1e-9, "row {r}: {ax} vs {rhs}");
        }
    }
}
