//! The direct solve of all constraints of a rod at once (Deul, Kugelstadt, Weiler & Bender
//! 2018, "Direct position-based solver for stiff rods", section 4).
//!
//! One Newton step of XPBD (Macklin et al. 2016, eq. 12 with the Schur complement of eq. 9)
//! solves `(J K⁻¹ Jᵀ + α̃) Δλ = rhs` for every constraint of the rod together (`K` is the
//! mass matrix with the frames' geometric-stiffness bound of `super::Work::precondition`;
//! diagonal per point and per frame). Deul et al. observe that the constraint graph of a rod
//! is a chain, so the matrix is banded along the rod (their eq. 17; they factorise it with a
//! sparse LDLᵀ over the tree, which for a chain is a banded recursion).
//!
//! With the unknowns ordered `(λ_Γ0, λ_Ω0, λ_Γ1, λ_Ω1, …, λ_Γ(n−1))` in 3×3 blocks, every
//! block couples to at most two blocks on either side and one coupling inside that band
//! (`Γ_j`–`Ω_{j+1}`) is zero; [`BlockTridiagonal`] eliminates block by block, inverting each
//! 3×3 pivot in closed form. Both factorisation and solve are `O(n)` and exact, so the number
//! of iterations does not grow with the length of the rod or with its stiffness, which is what
//! Gauss–Seidel cannot offer (`docs/stiff-solver.md` measures both). An earlier version used
//! 6×6 element blocks with a Cholesky factorisation of each (six dependent square roots per
//! element); the 3×3 closed-form pivots measured 2–3× faster (`docs/benchmarks/stiff.md`).
//!
//! Everything here is `f64`: with frame inverse inertias near 1e12 and compliances near 1e-11
//! the matrix spans more than `f32` can resolve.

#[cfg(test)]
use super::constraints::{BendTwist, StretchShear};
use super::lanes::V3s;
use cosserat_model::Vec3;
#[cfg(test)]
use nalgebra::Matrix3;

/// `a diag(w) bᵀ`.
#[cfg(test)]
fn awbt(a: &Matrix3<f64>, w: &Vec3<f64>, b: &Matrix3<f64>) -> M3 {
    let mut c = [[0.0; 3]; 3];
    for r in 0..3 {
        let aw = [a[(r, 0)] * w[0], a[(r, 1)] * w[1], a[(r, 2)] * w[2]];
        for (k, ck) in c[r].iter_mut().enumerate() {
            *ck = aw[0] * b[(k, 0)] + aw[1] * b[(k, 1)] + aw[2] * b[(k, 2)];
        }
    }
    c
}

/// `c + a diag(w) aᵀ` (symmetric: the upper triangle, mirrored).
#[cfg(test)]
fn add_awat(c: &mut M3, a: &Matrix3<f64>, w: &Vec3<f64>) {
    for r in 0..3 {
        let aw = [a[(r, 0)] * w[0], a[(r, 1)] * w[1], a[(r, 2)] * w[2]];
        for k in r..3 {
            c[r][k] += aw[0] * a[(k, 0)] + aw[1] * a[(k, 1)] + aw[2] * a[(k, 2)];
        }
    }
    c[1][0] = c[0][1];
    c[2][0] = c[0][2];
    c[2][1] = c[1][2];
}

/// `[g]× diag(w) [g]×ᵀ` in closed form.
#[cfg(test)]
fn cross_w_cross(g: &Vec3<f64>, w: &Vec3<f64>) -> M3 {
    let (x, y, z) = (g.x, g.y, g.z);
    let (o01, o02, o12) = (-w[2] * x * y, -w[1] * x * z, -w[0] * y * z);
    [
        [w[1] * z * z + w[2] * y * y, o01, o02],
        [o01, w[0] * z * z + w[2] * x * x, o12],
        [o02, o12, w[0] * y * y + w[1] * x * x],
    ]
}

/// What the assembly needs to know about one rod besides its current constraint Jacobians.
#[cfg(test)]
pub(crate) struct Masses<'a> {
    /// Inverse point masses (zero for held points).
    pub(crate) inv_mass: &'a [f64],
    /// Inverse principal inertias of the frames (zero for held frames).
    pub(crate) inv_inertia: &'a V3s,
    /// `α̃ = α / h²` of each stretch–shear constraint.
    pub(crate) alpha_gamma: &'a [Vec3<f64>],
    /// `α̃` of each bend–twist constraint.
    pub(crate) alpha_omega: &'a [Vec3<f64>],
}

/// A 3×3 block, row-major.
type M3 = [[f64; 3]; 3];

/// The inverse of a symmetric positive (semi)definite 3×3 block. Closed form (adjugate) when
/// the determinant is positive; otherwise a Cholesky factorisation whose non-positive pivots
/// get an inverse of zero (a row that no free degree of freedom can change, e.g. an element
/// whose points and frame are all held), which leaves that multiplier unchanged.
#[inline(always)]
fn inverse_spd(a: &M3) -> M3 {
    let c00 = a[1][1] * a[2][2] - a[1][2] * a[2][1];
    let c01 = a[1][2] * a[2][0] - a[1][0] * a[2][2];
    let c02 = a[1][0] * a[2][1] - a[1][1] * a[2][0];
    let det = a[0][0] * c00 + a[0][1] * c01 + a[0][2] * c02;
    if det > 0.0 && a[0][0] > 0.0 && c00 > 0.0 && det.is_finite() {
        let inv = 1.0 / det;
        let c11 = a[0][0] * a[2][2] - a[0][2] * a[2][0];
        let c12 = a[0][2] * a[1][0] - a[0][0] * a[1][2];
        let c22 = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        let (o01, o02, o12) = (c01 * inv, c02 * inv, c12 * inv);
        return [
            [c00 * inv, o01, o02],
            [o01, c11 * inv, o12],
            [o02, o12, c22 * inv],
        ];
    }
    // Cholesky with zero inverse pivots, then A⁺ = L⁻ᵀ L⁻¹.
    let mut l = [[0.0; 3]; 3];
    for j in 0..3 {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        let inv = if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 };
        l[j][j] = inv;
        for i in j + 1..3 {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s * inv;
        }
    }
    // m = L⁻¹ column by column.
    let mut m = [[0.0; 3]; 3];
    for c in 0..3 {
        for i in c..3 {
            let mut s = if i == c { 1.0 } else { 0.0 };
            for k in c..i {
                s -= l[i][k] * m[k][c];
            }
            m[i][c] = s * l[i][i];
        }
    }
    let mut out = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            out[r][c] = (0..3).map(|k| m[k][r] * m[k][c]).sum();
        }
    }
    out
}

/// The diagonal block of the stretch–shear constraint `Γ_j` (points `j`, `j + 1`, frame `j`):
/// `∂Γ/∂θ = [g]×` with `g = Γ + e3` gives `[g]× W_j [g]×ᵀ`; `∂Γ/∂r = ±Rᵀ/l0` gives
/// `(w_j + w_{j+1}) / l0² I` (the squared norm of a row); plus the compliance `α̃`.
#[cfg(test)]
fn gamma_diagonal(j: usize, g: &Vec3<f64>, d_rb: &Matrix3<f64>, m: &Masses<'_>) -> M3 {
    let mut gg = cross_w_cross(g, &m.inv_inertia.get(j));
    let wsum = (m.inv_mass[j] + m.inv_mass[j + 1]) * d_rb.row(0).norm_squared();
    for c in 0..3 {
        gg[c][c] += m.alpha_gamma[j][c] + wsum;
    }
    gg
}

/// Block row `k` of `J K⁻¹ Jᵀ + α̃` in the ordering `(λ_Γ0, λ_Ω0, λ_Γ1, …)`: the diagonal
/// block and the blocks in columns `k + 1` and `k + 2` (zero past the end). The direct
/// products of the Jacobians: the reference of the assembly in `work.rs`.
#[cfg(test)]
pub(crate) fn blocks(
    k: usize,
    ss: &[StretchShear<f64>],
    bt: &[BendTwist<f64>],
    m: &Masses<'_>,
) -> (M3, M3, M3) {
    let zero = [[0.0; 3]; 3];
    let j = k / 2;
    if k.is_multiple_of(2) {
        // Γ_j: points j, j + 1 and frame j.
        let s = &ss[j];
        let wj = &m.inv_inertia.get(j);
        let gg = gamma_diagonal(j, &(s.value + Vec3::z()), &s.d_rb, m);
        if j < bt.len() {
            let a1 = awbt(&s.d_theta, wj, &bt[j].d_theta_a);
            let w = Vec3::repeat(-m.inv_mass[j + 1]);
            let a2 = awbt(&s.d_rb, &w, &ss[j + 1].d_rb);
            (gg, a1, a2)
        } else {
            (gg, zero, zero)
        }
    } else {
        // Ω_j: frames j and j + 1.
        let b = &bt[j];
        let wb = &m.inv_inertia.get(j + 1);
        let mut oo = zero;
        for c in 0..3 {
            oo[c][c] = m.alpha_omega[j][c];
        }
        add_awat(&mut oo, &b.d_theta_a, &m.inv_inertia.get(j));
        add_awat(&mut oo, &b.d_theta_b, wb);
        let a1 = awbt(&b.d_theta_b, wb, &ss[j + 1].d_theta);
        let a2 = if j + 1 < bt.len() {
            awbt(&b.d_theta_b, wb, &bt[j + 1].d_theta_a)
        } else {
            zero
        };
        (oo, a1, a2)
    }
}

/// A row of a 3×3 block padded to four lanes (the fourth is zero), so that the elimination's
/// block products are four-wide multiply–adds (`y[r] = Σ_i a[r][i] · b[i]`, a broadcast and a
/// row) instead of scalar dot products.
type R4 = [f64; 4];
/// A 3×3 block as three padded rows.
type B4 = [R4; 3];

/// `a · b + c`, fused where the target has FMA.
#[inline(always)]
fn fma(a: f64, b: f64, c: f64) -> f64 {
    #[cfg(target_feature = "fma")]
    {
        a.mul_add(b, c)
    }
    #[cfg(not(target_feature = "fma"))]
    {
        a * b + c
    }
}

/// `c + s x`, lane by lane.
#[inline(always)]
fn axpy(c: R4, s: f64, x: &R4) -> R4 {
    [
        fma(s, x[0], c[0]),
        fma(s, x[1], c[1]),
        fma(s, x[2], c[2]),
        fma(s, x[3], c[3]),
    ]
}

#[inline(always)]
fn scale4(x: &R4, s: f64) -> R4 {
    [x[0] * s, x[1] * s, x[2] * s, x[3] * s]
}

#[inline(always)]
fn pad(m: &M3) -> B4 {
    m.map(|r| [r[0], r[1], r[2], 0.0])
}

/// `a b` with `a` given by its 3×3 entries.
#[inline(always)]
fn mul4(a: &M3, b: &B4) -> B4 {
    a.map(|r| axpy(axpy(scale4(&b[0], r[0]), r[1], &b[1]), r[2], &b[2]))
}

/// `c + aᵀ b` (or `aᵀ b` without `c`).
#[inline(always)]
fn tmul4(c: Option<&B4>, a: &B4, b: &B4) -> B4 {
    let mut out = [[0.0; 4]; 3];
    for (r, o) in out.iter_mut().enumerate() {
        let first = match c {
            Some(c) => axpy(c[r], a[0][r], &b[0]),
            None => scale4(&b[0], a[0][r]),
        };
        *o = axpy(axpy(first, a[1][r], &b[1]), a[2][r], &b[2]);
    }
    out
}

/// The blocks of `J K⁻¹ Jᵀ + α̃` of one rod, assembled four elements at a time (`work.rs`),
/// one record per element: the stretch–shear block row (`Γ_j`) then the bend–twist block row
/// (`Ω_j`), each as the upper triangle of its diagonal block (entries 00, 01, 02, 11, 12, 22,
/// then two unused) and its blocks in block columns `k + 1` and `k + 2` as rows padded to four
/// (zero past the end of the rod).
#[derive(Clone, Debug, Default)]
pub(crate) struct Assembled {
    /// Elements.
    n: usize,
    /// One record per element, and padding.
    pub(crate) records: Vec<[f64; Assembled::ENTRIES]>,
}

impl Assembled {
    /// Entries per element: two block rows of 8 + 12 + 12.
    pub(crate) const ENTRIES: usize = 64;
    /// Offset of the bend–twist row's entries.
    pub(crate) const BEND: usize = 32;
    /// Offsets of the off-diagonal blocks' rows within a block row.
    pub(crate) const NEXT: usize = 8;
    pub(crate) const SECOND: usize = 20;

    /// Sizes the records for `n` elements and `len ≥ n` records.
    pub(crate) fn resize(&mut self, n: usize, len: usize) {
        self.n = n;
        self.records.resize(len, [0.0; Self::ENTRIES]);
    }

    /// Block row `k` of the unknowns' order `(λ_Γ0, λ_Ω0, λ_Γ1, …)`.
    #[inline(always)]
    pub(crate) fn block_row(&self, k: usize) -> (M3, B4, B4) {
        let base = if k.is_multiple_of(2) { 0 } else { Self::BEND };
        let e = &self.records[k / 2][base..base + Self::BEND];
        let d = [[e[0], e[1], e[2]], [e[1], e[3], e[4]], [e[2], e[4], e[5]]];
        let row = |o: usize| -> R4 { e[o..o + 4].try_into().expect("four entries") };
        let (a, b) = (Self::NEXT, Self::SECOND);
        (
            d,
            [row(a), row(a + 4), row(a + 8)],
            [row(b), row(b + 4), row(b + 8)],
        )
    }

    /// The records of the blocks `f(k)` of a rod of `n` elements (tests).
    #[cfg(test)]
    pub(crate) fn from_blocks(n: usize, f: impl Fn(usize) -> (M3, M3, M3)) -> Self {
        let mut a = Self::default();
        a.resize(n, n);
        for k in 0..2 * n - 1 {
            let (d, a1, a2) = f(k);
            let base = if k % 2 == 0 { 0 } else { Self::BEND };
            let e = &mut a.records[k / 2][base..];
            for (i, (r, c)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
                .into_iter()
                .enumerate()
            {
                e[i] = d[r][c];
            }
            for r in 0..3 {
                for c in 0..3 {
                    e[Self::NEXT + 4 * r + c] = a1[r][c];
                    e[Self::SECOND + 4 * r + c] = a2[r][c];
                }
            }
        }
        a
    }
}

/// One eliminated 3×3 block row: `P⁻¹` and `P⁻¹ A_{k,k+1}`, `P⁻¹ A_{k,k+2}` (padded rows).
#[derive(Clone, Copy, Debug, Default)]
struct Pivot {
    p_inv: B4,
    y: B4,
    z: B4,
}

/// The factorised `J K⁻¹ Jᵀ + α̃` of one rod, as a block `LDLᵀ` with 3×3 blocks.
///
/// The unknowns are ordered `(λ_Γ0, λ_Ω0, λ_Γ1, λ_Ω1, …, λ_Γ(n−1))` (the last element has no
/// bend–twist constraint): `2n − 1` blocks of 3. Each block couples only to the two blocks on
/// either side (`Γ_j`–`Ω_j` and `Ω_j`–`Γ_{j+1}` through frames `j` and `j + 1`, `Γ_j`–`Γ_{j+1}`
/// through point `j + 1`, `Ω_j`–`Ω_{j+1}` through frame `j + 1`), and `Γ_j`–`Ω_{j+1}` is zero,
/// so the matrix is banded with two 3×3 blocks on each side of the diagonal and the
/// elimination fills nothing outside that band. Eliminating block `k` inverts its pivot in
/// closed form (no chain of square roots) and updates the three blocks below and right of it:
/// about 170 multiply–adds per block, 340 per element; a solve about 80 per element.
#[derive(Clone, Debug, Default)]
pub(crate) struct BlockTridiagonal {
    piv: Vec<Pivot>,
}

impl BlockTridiagonal {
    /// Factorises the assembled `J K⁻¹ Jᵀ + α̃`.
    pub(crate) fn factor(&mut self, blocks: &Assembled) {
        let n = blocks.n;
        if n == 0 {
            self.piv.clear();
            return;
        }
        let count = 2 * n - 1;
        self.piv.resize(count, Pivot::default());
        let zero = [[0.0; 4]; 3];
        // Amounts still to subtract from the next two diagonal blocks and the block between.
        let (mut s11, mut s12, mut s22) = (zero, zero, zero);
        for (k, out) in self.piv.iter_mut().enumerate() {
            let (mut d, mut a1, a2) = blocks.block_row(k);
            // Updates from the blocks eliminated before.
            for r in 0..3 {
                for c in 0..3 {
                    d[r][c] -= s11[r][c];
                }
                for c in 0..4 {
                    a1[r][c] -= s12[r][c];
                }
            }
            // The pivot's adjugate and determinant (`d` is symmetric). The products with the
            // adjugate do not wait for the division, and the Schur complement on the next
            // diagonal block — the only quantity on the dependency chain from one block to
            // the next — is `a1ᵀ adj a1 / det`, one multiply–add after the division.
            let c00 = d[1][1] * d[2][2] - d[1][2] * d[1][2];
            let c01 = d[1][2] * d[0][2] - d[0][1] * d[2][2];
            let c02 = d[0][1] * d[1][2] - d[1][1] * d[0][2];
            let det = d[0][0] * c00 + d[0][1] * c01 + d[0][2] * c02;
            *out = if det > 0.0 && d[0][0] > 0.0 && c00 > 0.0 && det.is_finite() {
                let c11 = d[0][0] * d[2][2] - d[0][2] * d[0][2];
                let c12 = d[0][2] * d[0][1] - d[0][0] * d[1][2];
                let c22 = d[0][0] * d[1][1] - d[0][1] * d[0][1];
                let adj = [[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]];
                let ya = mul4(&adj, &a1);
                let za = mul4(&adj, &a2);
                let t11 = tmul4(None, &a1, &ya);
                let inv = 1.0 / det;
                let y = ya.map(|r| scale4(&r, inv));
                let z = za.map(|r| scale4(&r, inv));
                for r in 0..3 {
                    for c in 0..4 {
                        s11[r][c] = fma(t11[r][c], inv, s22[r][c]);
                    }
                }
                s12 = tmul4(None, &a1, &z);
                s22 = tmul4(None, &a2, &z);
                Pivot {
                    p_inv: pad(&adj).map(|r| scale4(&r, inv)),
                    y,
                    z,
                }
            } else {
                let p_inv = inverse_spd(&d);
                let y = mul4(&p_inv, &a1);
                let z = mul4(&p_inv, &a2);
                s11 = tmul4(Some(&s22), &a1, &y);
                s12 = tmul4(None, &a1, &z);
                s22 = tmul4(None, &a2, &z);
                Pivot {
                    p_inv: pad(&p_inv),
                    y,
                    z,
                }
            };
        }
    }

    /// Solves the factorised system in place: `x` holds the right-hand side on entry and the
    /// solution on return (the bend–twist entries of the last element are set to zero).
    /// The stretch–shear blocks are in `x[0]`, the bend–twist ones in `x[1]`, one entry per
    /// element.
    pub(crate) fn solve(&self, x: &mut [V3s; 2]) {
        let blocks = self.piv.len();
        if blocks == 0 {
            return;
        }
        let n = blocks.div_ceil(2);
        let get = |x: &[V3s; 2], k: usize| -> R4 {
            let c = &x[k % 2];
            let j = k / 2;
            [c.x[j], c.y[j], c.z[j], 0.0]
        };
        let set = |x: &mut [V3s; 2], k: usize, v: &R4| {
            let c = &mut x[k % 2];
            let j = k / 2;
            (c.x[j], c.y[j], c.z[j]) = (v[0], v[1], v[2]);
        };
        // Forward: z_k = b_k − Y_{k−1}ᵀ z_{k−1} − Z_{k−2}ᵀ z_{k−2}; then w_k = P_k⁻¹ z_k
        // (`Yᵀ z = Σ_i z_i · row_i(Y)`; `P⁻¹` is symmetric).
        // The term of block k − 2 is subtracted first: only the term of block k − 1 is on the
        // dependency chain from one block to the next.
        let (mut z1, mut z2) = ([0.0; 4], [0.0; 4]);
        for k in 0..blocks {
            let mut b = get(x, k);
            if k >= 2 {
                let z = &self.piv[k - 2].z;
                b = axpy(axpy(axpy(b, -z2[0], &z[0]), -z2[1], &z[1]), -z2[2], &z[2]);
            }
            if k >= 1 {
                let y = &self.piv[k - 1].y;
                let t = axpy(axpy(scale4(&y[0], z1[0]), z1[1], &y[1]), z1[2], &y[2]);
                for (bl, tl) in b.iter_mut().zip(t) {
                    *bl -= tl;
                }
            }
            z2 = z1;
            z1 = b;
            let p = &self.piv[k].p_inv;
            let w = axpy(axpy(scale4(&p[0], b[0]), b[1], &p[1]), b[2], &p[2]);
            set(x, k, &w);
        }
        // Backward: x_k = w_k − Y_k x_{k+1} − Z_k x_{k+2}.
        let (mut x1, mut x2) = ([0.0; 4], [0.0; 4]);
        for k in (0..blocks).rev() {
            let mut v = get(x, k);
            let pv = &self.piv[k];
            for r in 0..3 {
                let (y, z) = (&pv.y[r], &pv.z[r]);
                let u = fma(z[0], x2[0], fma(z[1], x2[1], z[2] * x2[2]));
                let t = y[0] * x1[0] + y[1] * x1[1] + y[2] * x1[2];
                v[r] = (v[r] - u) - t;
            }
            x2 = x1;
            x1 = v;
            set(x, k, &v);
        }
        x[1].set(n - 1, &Vec3::zeros());
    }

    /// Dense `J K⁻¹ Jᵀ + α̃` (order `6n`, the last element's bend–twist rows as identity
    /// rows), for tests of the assembly.
    #[cfg(test)]
    pub(crate) fn dense(
        ss: &[StretchShear<f64>],
        bt: &[BendTwist<f64>],
        m: &Masses<'_>,
    ) -> Vec<Vec<f64>> {
        let n = ss.len();
        let mut a = vec![vec![0.0; 6 * n]; 6 * n];
        for k in 0..2 * n - 1 {
            let (d, a1, a2) = blocks(k, ss, bt, m);
            for r in 0..3 {
                for c in 0..3 {
                    a[3 * k + r][3 * k + c] = d[r][c];
                    for (off, b) in [(1, &a1), (2, &a2)] {
                        if 3 * (k + off) < 6 * n - 3 {
                            a[3 * k + r][3 * (k + off) + c] = b[r][c];
                            a[3 * (k + off) + c][3 * k + r] = b[r][c];
                        }
                    }
                }
            }
        }
        for r in 6 * n - 3..6 * n {
            a[r][r] = 1.0;
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

    /// Compliances of the stretch–shear and bend–twist rows of a test chain of `n` elements.
    fn compliances(n: usize) -> (Vec<Vec3<f64>>, Vec<Vec3<f64>>) {
        let ag = (0..n)
            .map(|j| Vec3::new(1e-3, 2e-3, j as f64 * 1e-4))
            .collect();
        let ao = (0..n.saturating_sub(1))
            .map(|_| Vec3::new(3e-2, 3e-2, 5e-2))
            .collect();
        (ag, ao)
    }

    /// The block assembly of the reference equals `J M⁻¹ Jᵀ + α̃` built densely from the
    /// constraint Jacobians, and the block factorisation solves it.
    #[test]
    fn block_assembly_and_solve_match_dense() {
        let n = 6;
        let (ss, bt, w, wi) = chain(n);
        let (ag, ao) = compliances(n);
        let wi_col = V3s::from_slice(&wi);
        let m = Masses {
            inv_mass: &w,
            inv_inertia: &wi_col,
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
        check_solve(&ss, &bt, &m, &a);
    }

    /// `factor` and `solve` against the dense matrix.
    fn check_solve(
        ss: &[StretchShear<f64>],
        bt: &[BendTwist<f64>],
        m: &Masses<'_>,
        a: &[Vec<f64>],
    ) {
        let n = ss.len();
        let mut f = BlockTridiagonal::default();
        f.factor(&Assembled::from_blocks(n, |k| blocks(k, ss, bt, m)));
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
        let mut x = [V3s::zeros(n), V3s::zeros(n)];
        for (j, e) in b.iter().enumerate() {
            x[0].set(j, &Vec3::new(e[0], e[1], e[2]));
            x[1].set(j, &Vec3::new(e[3], e[4], e[5]));
        }
        f.solve(&mut x);
        let flat: Vec<f64> = (0..n)
            .flat_map(|j| {
                let (g, o) = (x[0].get(j), x[1].get(j));
                [g.x, g.y, g.z, o.x, o.y, o.z]
            })
            .collect();
        let scale = flat.iter().fold(1.0_f64, |s, v| s.max(v.abs()));
        for r in 0..6 * n {
            let ax: f64 = (0..6 * n).map(|c| a[r][c] * flat[c]).sum();
            let rhs = b[r / 6][r % 6];
            let tol = 1e-9 * a[r].iter().fold(1.0_f64, |s, v| s.max(v.abs())) * scale;
            assert!((ax - rhs).abs() < tol, "n = {n}, row {r}: {ax} vs {rhs}");
        }
    }

    /// The factorisation and solve for short and longer chains against the dense system.
    #[test]
    fn solve_matches_dense_for_every_length() {
        for n in [1, 2, 3, 4, 7, 23] {
            let (ss, bt, w, wi) = chain(n);
            let (ag, ao) = compliances(n);
            let wi_col = V3s::from_slice(&wi);
            let m = Masses {
                inv_mass: &w,
                inv_inertia: &wi_col,
                alpha_gamma: &ag,
                alpha_omega: &ao,
            };
            let a = BlockTridiagonal::dense(&ss, &bt, &m);
            check_solve(&ss, &bt, &m, &a);
        }
    }
}
