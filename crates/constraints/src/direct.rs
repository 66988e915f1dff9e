//! Exact inextensibility: the distance constraints solved globally with Lagrange multipliers.
//!
//! [`solve_distance_iteration`](crate::solve_distance_iteration) removes the constraint error one
//! element at a time; a few sweeps leave a residual stretch that grows with the number of
//! elements (Gauss–Seidel spreads a correction by one element per sweep). This module solves
//! the same constraints all at once, as the inextensible CoRdE of Spillmann & Teschner (2008)
//! does ("constrained Lagrange mechanics", paper section 2.1), so that after the step every
//! segment has its rest length to round-off.
//!
//! **Contract** (the same as the iterative solver): `positions` are the points at the start of
//! the step, `velocities` the integrated velocities, updated in place, `inv_masses` the inverse
//! point masses (zero = kinematic, never moved), `rest_lengths` one per element, `h` the step.
//!
//! **Method.** Let `p = r + h v` be the predicted end-of-step positions and
//! `C_j(p) = |p_{j+1} − p_j| − l0_j`. One Newton step linearises `C` at the current `p`
//! with the constraint Jacobian `J` (row `j` is `−u_j` at point `j` and `+u_j` at `j + 1`, with
//! `u_j` the unit segment direction) and moves the points along the constraint normals,
//! weighted by the inverse masses:
//!
//! `(J M⁻¹ Jᵀ) Δλ = −C`,  `p ← p + M⁻¹ Jᵀ Δλ`.
//!
//! This is the "fast projection" of Goldenthal et al. (2007): each iteration is a mass-weighted
//! least-change projection, it converges quadratically (three or four iterations reach 1e-12
//! from a step's worth of drift), and because every column of `Jᵀ` sums to zero over the points
//! it conserves linear momentum exactly. Finally `v = (p − r)/h`, so the position update of the
//! stepper lands on `p`.
//!
//! For one rod `J M⁻¹ Jᵀ` is tridiagonal, with diagonal `w_j + w_{j+1}` and off-diagonal
//! `−w_{j+1} u_j·u_{j+1}`; it is symmetric positive definite (weakly diagonally dominant), so
//! the Thomas algorithm solves it in `O(n)` without pivoting: [`solve_distance_direct`]. Once
//! rods are coupled (a binding constraint between two rods, a catheter and its guidewire) the
//! matrix is a general sparse SPD matrix: [`CoupledDirectSolver`] analyses its pattern once
//! (faer's sparse Cholesky with an AMD ordering) and refactorises only the values each Newton
//! iteration, into buffers allocated when the solver is built.
//!
//! The Newton iteration always runs in `f64`, whatever the precision of the rod: in `f32` the
//! final lengths are then exact to `f32` round-off of the positions.

use cosserat_model::{Real, Vec3};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

/// Convergence settings of the Newton iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectSettings {
    /// Stop when every `|l/l0 − 1|` of the predicted positions is at most this.
    pub tolerance: f64,
    /// Stop after this many Newton iterations even if the tolerance is not met.
    pub max_iterations: usize,
}

impl Default for DirectSettings {
    /// `1e-12` relative length error, at most 20 iterations (quadratic convergence needs 3–5).
    fn default() -> Self {
        Self {
            tolerance: 1e-12,
            max_iterations: 20,
        }
    }
}

/// What one direct solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DirectReport {
    /// Newton iterations taken (linear solves).
    pub iterations: usize,
    /// Largest `|l/l0 − 1|` of the predicted positions when the iteration stopped.
    pub residual: f64,
}

/// Buffers for [`solve_distance_direct`], grown on first use and reused afterwards so that a
/// step allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct DirectScratch {
    predicted: Vec<Vec3<f64>>,
    normals: Vec<Vec3<f64>>,
    diag: Vec<f64>,
    upper: Vec<f64>,
    rhs: Vec<f64>,
}

impl DirectScratch {
    /// Scratch sized for rods of up to `elements` elements.
    pub fn new(elements: usize) -> Self {
        let mut s = Self::default();
        s.reserve(elements);
        s
    }

    fn reserve(&mut self, n: usize) {
        self.predicted.resize(n + 1, Vec3::zeros());
        self.normals.resize(n, Vec3::zeros());
        self.diag.resize(n, 0.0);
        self.upper.resize(n, 0.0);
        self.rhs.resize(n, 0.0);
    }
}

fn to64<T: Real>(v: &Vec3<T>) -> Vec3<f64> {
    Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64())
}

/// Solves the distance constraints of one rod exactly (to `settings.tolerance`) and updates the
/// velocities so that `r + h v` satisfies them.
///
/// Elements whose two points are both kinematic are left alone (their length is prescribed by
/// the caller's motion). Returns the number of Newton iterations and the final residual.
pub fn solve_distance_direct<T: Real>(
    positions: &[Vec3<T>],
    velocities: &mut [Vec3<T>],
    inv_masses: &[T],
    rest_lengths: &[T],
    h: T,
    settings: &DirectSettings,
    scratch: &mut DirectScratch,
) -> DirectReport {
    let n = rest_lengths.len();
    debug_assert_eq!(positions.len(), n + 1);
    debug_assert_eq!(velocities.len(), n + 1);
    debug_assert_eq!(inv_masses.len(), n + 1);
    if scratch.predicted.len() < n + 1 {
        scratch.reserve(n);
    }
    let hf = h.to_f64();
    let DirectScratch {
        predicted: p,
        normals: u,
        diag,
        upper,
        rhs,
    } = scratch;
    for i in 0..=n {
        p[i] = to64(&positions[i]) + to64(&velocities[i]) * hf;
    }
    let w = |i: usize| inv_masses[i].to_f64();
    let mut report = DirectReport::default();
    loop {
        // Residuals and normals at the current predicted positions.
        let mut residual = 0.0_f64;
        for j in 0..n {
            let e = p[j + 1] - p[j];
            let len = e.norm();
            let l0 = rest_lengths[j].to_f64();
            let c = len - l0;
            u[j] = e / len;
            rhs[j] = -c;
            if w(j) + w(j + 1) > 0.0 {
                residual = residual.max((c / l0).abs());
            }
        }
        report.residual = residual;
        if !(residual > settings.tolerance) || report.iterations >= settings.max_iterations {
            break;
        }
        report.iterations += 1;
        // Tridiagonal J M⁻¹ Jᵀ, factorised and solved in place (Thomas algorithm).
        for j in 0..n {
            diag[j] = w(j) + w(j + 1);
            upper[j] = if j + 1 < n {
                -w(j + 1) * u[j].dot(&u[j + 1])
            } else {
                0.0
            };
            if diag[j] == 0.0 {
                // Both ends kinematic: the row is empty; λ_j = 0.
                diag[j] = 1.0;
                rhs[j] = 0.0;
            }
        }
        for j in 1..n {
            let m = upper[j - 1] / diag[j - 1];
            diag[j] -= m * upper[j - 1];
            rhs[j] -= m * rhs[j - 1];
        }
        rhs[n - 1] /= diag[n - 1];
        for j in (0..n - 1).rev() {
            rhs[j] = (rhs[j] - upper[j] * rhs[j + 1]) / diag[j];
        }
        // p ← p + M⁻¹ Jᵀ λ.
        for j in 0..n {
            let d = u[j] * rhs[j];
            p[j] -= d * w(j);
            p[j + 1] += d * w(j + 1);
        }
    }
    let inv_h = 1.0 / hf;
    for i in 0..=n {
        if w(i) > 0.0 {
            let v = (p[i] - to64(&positions[i])) * inv_h;
            velocities[i] = Vec3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z));
        }
    }
    report
}

/// A distance constraint between two points of a global point array (for coupled rods).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DistanceConstraint {
    /// First point.
    pub a: usize,
    /// Second point.
    pub b: usize,
    /// Rest distance [m]; must be positive (the constraint normal is undefined at zero).
    pub rest_length: f64,
}

/// Why a [`CoupledDirectSolver`] could not be built or could not solve.
#[derive(Clone, Debug, PartialEq)]
pub enum DirectError {
    /// A constraint names a point outside the array, joins a point to itself, or has a rest
    /// length that is not a positive finite number.
    BadConstraint(usize),
    /// The symbolic analysis failed (out of memory).
    Analysis(String),
    /// `J M⁻¹ Jᵀ` was not numerically positive definite: the constraints are redundant (e.g. a
    /// closed loop of constraints on kinematic points).
    NotPositiveDefinite,
}

impl std::fmt::Display for DirectError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BadConstraint(k) => write!(
                f,
                "distance constraint {k} is invalid (point out of range, a point joined to itself, or rest length not > 0)"
            ),
            Self::Analysis(e) => write!(f, "sparse analysis of the constraint system failed: {e}"),
            Self::NotPositiveDefinite => write!(
                f,
                "the constraint system is singular (redundant constraints)"
            ),
        }
    }
}

impl std::error::Error for DirectError {}

/// The direct solver for constraints that couple several rods: the same Newton iteration as
/// [`solve_distance_direct`], with the sparse SPD system `J M⁻¹ Jᵀ` factorised by faer's sparse
/// Cholesky. The pattern is analysed once in [`CoupledDirectSolver::new`]; a solve only
/// refills values, so it allocates nothing.
pub struct CoupledDirectSolver {
    constraints: Vec<DistanceConstraint>,
    points: usize,
    /// Upper-triangular CSC pattern of `J M⁻¹ Jᵀ` (one column per constraint).
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<f64>,
    /// `(slot, point, sign, i, j)`: `values[slot] += sign · w_point · u_i·u_j`.
    contributions: Vec<(usize, usize, f64, usize, usize)>,
    diag_slot: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
    predicted: Vec<Vec3<f64>>,
    normals: Vec<Vec3<f64>>,
    rhs: Vec<f64>,
}

impl std::fmt::Debug for CoupledDirectSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CoupledDirectSolver")
            .field("constraints", &self.constraints.len())
            .field("points", &self.points)
            .field("nnz", &self.values.len())
            .finish()
    }
}

impl CoupledDirectSolver {
    /// Analyses the constraint graph over `points` points.
    pub fn new(points: usize, constraints: Vec<DistanceConstraint>) -> Result<Self, DirectError> {
        let m = constraints.len();
        for (k, c) in constraints.iter().enumerate() {
            if c.a >= points
                || c.b >= points
                || c.a == c.b
                || !(c.rest_length.is_finite() && c.rest_length > 0.0)
            {
                return Err(DirectError::BadConstraint(k));
            }
        }
        // Constraints touching each point, with the sign of their Jacobian there.
        let mut touching: Vec<Vec<(usize, f64)>> = vec![Vec::new(); points];
        for (k, c) in constraints.iter().enumerate() {
            touching[c.a].push((k, -1.0));
            touching[c.b].push((k, 1.0));
        }
        let mut entries: Vec<(usize, usize)> = Vec::new(); // (col, row), row <= col
        let mut raw: Vec<((usize, usize), usize, f64)> = Vec::new();
        for (k, list) in touching.iter().enumerate() {
            for &(i, si) in list {
                for &(j, sj) in list {
                    if i <= j {
                        entries.push((j, i));
                        raw.push(((j, i), k, si * sj));
                    }
                }
            }
        }
        entries.sort_unstable();
        entries.dedup();
        let mut col_ptr = vec![0usize; m + 1];
        for &(c, _) in &entries {
            col_ptr[c + 1] += 1;
        }
        for c in 0..m {
            col_ptr[c + 1] += col_ptr[c];
        }
        let row_idx: Vec<usize> = entries.iter().map(|&(_, r)| r).collect();
        let slot = |c: usize, r: usize| {
            col_ptr[c]
                + row_idx[col_ptr[c]..col_ptr[c + 1]]
                    .binary_search(&r)
                    .expect("entry in pattern")
        };
        let contributions = raw
            .iter()
            .map(|&((c, r), k, s)| (slot(c, r), k, s, r, c))
            .collect();
        let diag_slot = (0..m).map(|c| slot(c, c)).collect();
        let sym = SymbolicSparseColMatRef::new_checked(m, m, &col_ptr, None, &row_idx);
        let symbolic = factorize_symbolic_cholesky(
            sym,
            Side::Upper,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| DirectError::Analysis(format!("{e:?}")))?;
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        let mem = MemBuffer::new(req);
        let l_values = vec![0.0; symbolic.len_val()];
        let nnz = row_idx.len();
        Ok(Self {
            constraints,
            points,
            col_ptr,
            row_idx,
            values: vec![0.0; nnz],
            contributions,
            diag_slot,
            symbolic,
            l_values,
            mem,
            predicted: vec![Vec3::zeros(); points],
            normals: vec![Vec3::zeros(); m],
            rhs: vec![0.0; m],
        })
    }

    /// Number of constraints.
    pub fn constraint_count(&self) -> usize {
        self.constraints.len()
    }

    /// Solves all constraints over the global arrays (same contract as
    /// [`solve_distance_direct`], with the rest lengths taken from the constraints).
    pub fn solve<T: Real>(
        &mut self,
        positions: &[Vec3<T>],
        velocities: &mut [Vec3<T>],
        inv_masses: &[T],
        h: T,
        settings: &DirectSettings,
    ) -> Result<DirectReport, DirectError> {
        assert_eq!(positions.len(), self.points);
        assert_eq!(velocities.len(), self.points);
        assert_eq!(inv_masses.len(), self.points);
        let hf = h.to_f64();
        for i in 0..self.points {
            self.predicted[i] = to64(&positions[i]) + to64(&velocities[i]) * hf;
        }
        let w = |i: usize| inv_masses[i].to_f64();
        let mut report = DirectReport::default();
        loop {
            let mut residual = 0.0_f64;
            for (k, c) in self.constraints.iter().enumerate() {
                let e = self.predicted[c.b] - self.predicted[c.a];
                let len = e.norm();
                self.normals[k] = e / len;
                self.rhs[k] = c.rest_length - len;
                if w(c.a) + w(c.b) > 0.0 {
                    residual = residual.max(((len - c.rest_length) / c.rest_length).abs());
                }
            }
            report.residual = residual;
            if !(residual > settings.tolerance) || report.iterations >= settings.max_iterations {
                break;
            }
            report.iterations += 1;
            self.values.fill(0.0);
            for &(slot, point, sign, i, j) in &self.contributions {
                self.values[slot] += sign * w(point) * self.normals[i].dot(&self.normals[j]);
            }
            for (k, &d) in self.diag_slot.iter().enumerate() {
                if self.values[d] == 0.0 {
                    self.values[d] = 1.0;
                    self.rhs[k] = 0.0;
                }
            }
            let m = self.constraints.len();
            let sym =
                SymbolicSparseColMatRef::new_checked(m, m, &self.col_ptr, None, &self.row_idx);
            let a = SparseColMatRef::new(sym, &self.values);
            let stack = MemStack::new(&mut self.mem);
            let llt = self
                .symbolic
                .factorize_numeric_llt(
                    &mut self.l_values,
                    a,
                    Side::Upper,
                    LltRegularization::default(),
                    Par::Seq,
                    stack,
                    Default::default(),
                )
                .map_err(|_| DirectError::NotPositiveDefinite)?;
            let stack = MemStack::new(&mut self.mem);
            llt.solve_in_place_with_conj(
                Conj::No,
                MatMut::from_column_major_slice_mut(&mut self.rhs, m, 1),
                Par::Seq,
                stack,
            );
            for (k, c) in self.constraints.iter().enumerate() {
                let d = self.normals[k] * self.rhs[k];
                self.predicted[c.a] -= d * w(c.a);
                self.predicted[c.b] += d * w(c.b);
            }
        }
        let inv_h = 1.0 / hf;
        for i in 0..self.points {
            if w(i) > 0.0 {
                let v = (self.predicted[i] - to64(&positions[i])) * inv_h;
                velocities[i] = Vec3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z));
            }
        }
        Ok(report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Ordering, solve_distance_iteration};

    /// A wavy rod with varied masses and a velocity field far from the constraint manifold.
    /// Positions, velocities, inverse masses, rest lengths.
    type Chain = (Vec<Vec3<f64>>, Vec<Vec3<f64>>, Vec<f64>, Vec<f64>);

    fn wobbly(n: usize) -> Chain {
        let l0: Vec<f64> = (0..n)
            .map(|j| 0.01 * (1.0 + 0.2 * (j as f64 * 0.9).sin()))
            .collect();
        let mut pos = vec![Vec3::zeros()];
        for j in 0..n {
            let a = 0.4 * (j as f64 * 0.5).sin();
            let last = pos[j];
            pos.push(last + Vec3::new(a.cos(), a.sin(), 0.1 * a).normalize() * l0[j]);
        }
        let vel: Vec<_> = (0..=n)
            .map(|i| Vec3::new((i as f64 * 0.7).cos(), (i as f64 * 1.3).sin(), 0.3))
            .collect();
        let inv: Vec<_> = (0..=n).map(|i| 1.0 / (1.0 + 0.1 * i as f64)).collect();
        (pos, vel, inv, l0)
    }

    fn max_length_error(pos: &[Vec3<f64>], vel: &[Vec3<f64>], l0: &[f64], h: f64) -> f64 {
        (0..l0.len())
            .map(|j| {
                (((pos[j + 1] + vel[j + 1] * h) - (pos[j] + vel[j] * h)).norm() / l0[j] - 1.0).abs()
            })
            .fold(0.0, f64::max)
    }

    fn momentum(v: &[Vec3<f64>], inv: &[f64]) -> Vec3<f64> {
        v.iter()
            .zip(inv)
            .filter(|(_, w)| **w > 0.0)
            .map(|(v, w)| v / *w)
            .sum()
    }

    #[test]
    fn lengths_are_exact_and_momentum_is_conserved() {
        let (pos, mut vel, inv, l0) = wobbly(200);
        let h = 1e-3;
        let p0 = momentum(&vel, &inv);
        assert!(max_length_error(&pos, &vel, &l0, h) > 1e-2);
        let mut scratch = DirectScratch::new(200);
        let r = solve_distance_direct(
            &pos,
            &mut vel,
            &inv,
            &l0,
            h,
            &DirectSettings::default(),
            &mut scratch,
        );
        assert!(r.residual <= 1e-12, "{r:?}");
        assert!(
            r.iterations <= 8,
            "Newton should converge quadratically: {r:?}"
        );
        // Measured on the positions the stepper will compute, r + h v.
        assert!(max_length_error(&pos, &vel, &l0, h) < 1e-12);
        assert!((momentum(&vel, &inv) - p0).norm() <= 1e-12 * p0.norm());
    }

    #[test]
    fn agrees_with_many_gauss_seidel_sweeps() {
        // A realistic step: velocities of 1 cm/s against 1 cm elements and h = 1 ms leave a
        // predicted length error of order 1e-3.
        let (pos, vel, mut inv, l0) = wobbly(30);
        let vel: Vec<_> = vel.iter().map(|v| v * 0.01).collect();
        inv[0] = 0.0;
        let h = 1e-3;
        let e0 = max_length_error(&pos, &vel, &l0, h);
        let (mut v_gs, mut v_direct) = (vel.clone(), vel.clone());
        for _ in 0..20_000 {
            solve_distance_iteration(&pos, &mut v_gs, &inv, &l0, h, Ordering::GaussSeidel);
        }
        assert!(
            max_length_error(&pos, &v_gs, &l0, h) < 1e-12,
            "Gauss–Seidel did not converge"
        );
        solve_distance_direct(
            &pos,
            &mut v_direct,
            &inv,
            &l0,
            h,
            &DirectSettings::default(),
            &mut DirectScratch::default(),
        );
        // Both solve the same linearised projection J M⁻¹ Jᵀ λ = −C (Gauss–Seidel iterates on it,
        // the direct solver factorises it); they differ only through the curvature of the
        // constraints, i.e. by a fraction of the correction of the order of the strain error e0
        // (second order; the next test checks that scaling, the constant depends on the shape).
        let correction = vel
            .iter()
            .zip(&v_direct)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        let diff = v_gs
            .iter()
            .zip(&v_direct)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            diff <= 10.0 * e0 * correction,
            "direct and Gauss–Seidel differ by {diff} (correction {correction}, e0 {e0})"
        );
        assert_eq!(v_direct[0], vel[0], "a kinematic point moved");
    }

    #[test]
    fn converges_to_the_same_projection_as_gauss_seidel_near_the_manifold() {
        // Close to the manifold both methods compute the same mass-weighted projection: the
        // difference is second order in the constraint error.
        let (pos, _, inv, l0) = wobbly(30);
        let h = 1e-3;
        let mut errs = Vec::new();
        for scale in [1e-2, 1e-3] {
            let vel: Vec<_> = (0..=30)
                .map(|i| Vec3::new((i as f64).cos(), (2.0 * i as f64).sin(), 0.0) * scale)
                .collect();
            let (mut v_gs, mut v_d) = (vel.clone(), vel.clone());
            for _ in 0..20_000 {
                solve_distance_iteration(&pos, &mut v_gs, &inv, &l0, h, Ordering::GaussSeidel);
            }
            solve_distance_direct(
                &pos,
                &mut v_d,
                &inv,
                &l0,
                h,
                &DirectSettings::default(),
                &mut DirectScratch::default(),
            );
            errs.push(
                v_gs.iter()
                    .zip(&v_d)
                    .map(|(a, b)| (a - b).norm())
                    .fold(0.0, f64::max)
                    / scale,
            );
        }
        // Relative difference shrinks (at least) linearly with the perturbation.
        assert!(errs[1] < 0.2 * errs[0], "relative differences {errs:?}");
    }

    #[test]
    fn f32_rods_reach_f32_round_off() {
        let (pos, vel, inv, l0) = wobbly(50);
        let c = |v: &Vec<Vec3<f64>>| v.iter().map(|x| x.cast::<f32>()).collect::<Vec<_>>();
        let (pos32, mut vel32) = (c(&pos), c(&vel));
        let inv32: Vec<f32> = inv.iter().map(|&x| x as f32).collect();
        let l032: Vec<f32> = l0.iter().map(|&x| x as f32).collect();
        solve_distance_direct(
            &pos32,
            &mut vel32,
            &inv32,
            &l032,
            1e-3,
            &DirectSettings::default(),
            &mut DirectScratch::default(),
        );
        let err = (0..50)
            .map(|j| {
                ((pos32[j + 1] + vel32[j + 1] * 1e-3 - pos32[j] - vel32[j] * 1e-3).norm() / l032[j]
                    - 1.0)
                    .abs()
            })
            .fold(0.0f32, f32::max);
        assert!(err < 1e-5, "f32 residual {err}");
    }

    #[test]
    fn coupled_solver_matches_the_tridiagonal_one_and_couples_rods() {
        // Two rods of 20 elements, the tip of the first tied to the start of the second by a
        // third-rod-like link; rod 0 pinned at its start.
        let (pa, va, mut ia, la) = wobbly(20);
        ia[0] = 0.0;
        let h = 1e-3;
        // Single rod: sparse path equals the Thomas path.
        let cons: Vec<_> = (0..20)
            .map(|j| DistanceConstraint {
                a: j,
                b: j + 1,
                rest_length: la[j],
            })
            .collect();
        let mut solver = CoupledDirectSolver::new(21, cons.clone()).unwrap();
        let (mut v1, mut v2) = (va.clone(), va.clone());
        solver
            .solve(&pa, &mut v1, &ia, h, &DirectSettings::default())
            .unwrap();
        solve_distance_direct(
            &pa,
            &mut v2,
            &ia,
            &la,
            h,
            &DirectSettings::default(),
            &mut DirectScratch::default(),
        );
        let d = v1
            .iter()
            .zip(&v2)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(d < 1e-9, "sparse and tridiagonal solutions differ by {d}");
        // Coupled: second rod shifted, joined to the first by one link constraint.
        let shift = Vec3::new(0.0, 0.02, 0.0);
        let mut pos = pa.clone();
        pos.extend(pa.iter().map(|p| p + shift));
        let mut vel = va.clone();
        vel.extend(va.iter().map(|v| -v));
        let mut inv = ia.clone();
        inv.extend(ia.iter().map(|w| if *w == 0.0 { 0.5 } else { *w }));
        let mut all = cons.clone();
        all.extend(cons.iter().map(|c| DistanceConstraint {
            a: c.a + 21,
            b: c.b + 21,
            rest_length: c.rest_length,
        }));
        all.push(DistanceConstraint {
            a: 20,
            b: 41,
            rest_length: 0.02,
        });
        let mut coupled = CoupledDirectSolver::new(42, all.clone()).unwrap();
        let r = coupled
            .solve(&pos, &mut vel, &inv, h, &DirectSettings::default())
            .unwrap();
        assert!(r.residual <= 1e-12, "{r:?}");
        for c in &all {
            let l = ((pos[c.b] + vel[c.b] * h) - (pos[c.a] + vel[c.a] * h)).norm();
            assert!((l / c.rest_length - 1.0).abs() < 1e-12);
        }
        // With point 0 kinematic the pin absorbs momentum; on the free system it is conserved.
        let mut free_inv = inv.clone();
        free_inv[0] = 1.0;
        let mut vel = va.clone();
        vel.extend(va.iter().map(|v| -v));
        let p0 = momentum(&vel, &free_inv);
        coupled
            .solve(&pos, &mut vel, &free_inv, h, &DirectSettings::default())
            .unwrap();
        assert!((momentum(&vel, &free_inv) - p0).norm() < 1e-12 * (1.0 + p0.norm()));
    }

    #[test]
    fn bad_constraints_are_rejected() {
        let c = |a, b, l| DistanceConstraint {
            a,
            b,
            rest_length: l,
        };
        assert_eq!(
            CoupledDirectSolver::new(3, vec![c(0, 1, 1.0), c(1, 3, 1.0)]).unwrap_err(),
            DirectError::BadConstraint(1)
        );
        assert_eq!(
            CoupledDirectSolver::new(3, vec![c(1, 1, 1.0)]).unwrap_err(),
            DirectError::BadConstraint(0)
        );
        assert_eq!(
            CoupledDirectSolver::new(3, vec![c(0, 1, 0.0)]).unwrap_err(),
            DirectError::BadConstraint(0)
        );
    }
}
