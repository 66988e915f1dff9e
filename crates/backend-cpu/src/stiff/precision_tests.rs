//! How much precision the banded solve needs, measured on the matrices real instruments make.
//!
//! `direct.rs` solves in `f64` because the matrices span more than `f32` resolves (frame
//! inverse inertias near 1e12 against compliances near 1e-11). On a GPU, `f32` would halve the
//! registers and workgroup memory a rod's system takes (`docs/benchmarks/stiff-gpu.md`). What
//! decides whether it can serve is not the span but the error of the solution: a factorisation in
//! `f32` followed by iterative refinement with residuals in `f64` converges to the `f64` solution
//! when that error is well below one. These tests take the matrix of the last Newton iteration of
//! a stiff step of each material preset's wire (256 elements, clamped, bent under gravity at
//! 1e-4 s), solve it with the production `f64` factorisation (the reference) and with the same
//! block elimination in `f32`, with and without a symmetric diagonal scaling, and refine.

use super::*;
use crate::Ordering;
use cosserat_model::presets::preset;
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_problem::ends::EndCondition;

/// A block row in `f64`: the diagonal block and the blocks in the next two block columns.
type Row = ([[f64; 3]; 3], [[f64; 3]; 3], [[f64; 3]; 3]);

/// The assembled matrix of a stiff step of a 256-element wire of `material`, as block rows.
fn wire_matrix(material: &str) -> Vec<Row> {
    let m = preset(material).unwrap().material();
    let (length, n) = (1.0, 256);
    let spec = RodSpec::new(m);
    let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], length, n);
    let (state, params) = build_rod::<f64>(&pts, &spec).unwrap();
    let ends = [EndCondition::clamped(), EndCondition::free()];
    let mut rod = CpuRod::new(state, params, ends, vec![]);
    let settings = SolverSettings {
        dt: 1e-4,
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible: false,
        gravity: Vec3::new(0.0, 0.0, -9.81),
        divergence_strain: 0.05,
    };
    let stiff = StiffSettings::default();
    let mut scratch = StiffScratch::new();
    step_rod_stiff(&mut rod, &settings, &stiff, &mut scratch, 0.0, 0, 0, 40).unwrap();
    (0..2 * n - 1)
        .map(|k| {
            let (d, a1, a2) = scratch.assembled.block_row(k);
            let cut = |b: [[f64; 4]; 3]| b.map(|r| [r[0], r[1], r[2]]);
            (d, cut(a1), cut(a2))
        })
        .collect()
}

/// `A x` in `f64`.
fn apply(a: &[Row], x: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = a.len();
    let mut y = vec![[0.0; 3]; n];
    for (k, (d, a1, a2)) in a.iter().enumerate() {
        for i in 0..3 {
            for j in 0..3 {
                y[k][i] += d[i][j] * x[k][j];
            }
        }
        for (off, b) in [(1, a1), (2, a2)] {
            if k + off < n {
                for i in 0..3 {
                    for j in 0..3 {
                        y[k][i] += b[i][j] * x[k + off][j];
                        y[k + off][j] += b[i][j] * x[k][i];
                    }
                }
            }
        }
    }
    y
}

/// The production factorisation's solution (`f64`).
fn solve_f64(a: &[Row], b: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = a.len().div_ceil(2);
    let assembled = Assembled::from_blocks(n, |k| a[k]);
    let mut factor = BlockTridiagonal::default();
    factor.factor(&assembled);
    let mut x = [V3s::zeros(n), V3s::zeros(n)];
    for (k, v) in b.iter().enumerate() {
        x[k % 2].set(k / 2, &Vec3::new(v[0], v[1], v[2]));
    }
    factor.solve(&mut x);
    (0..a.len())
        .map(|k| {
            let v = x[k % 2].get(k / 2);
            [v.x, v.y, v.z]
        })
        .collect()
}

type M = [[f32; 3]; 3];

fn mul(a: &M, b: &M) -> M {
    let mut c = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            c[r][k] = (0..3).map(|i| a[r][i] * b[i][k]).sum();
        }
    }
    c
}

fn tmul(a: &M, b: &M) -> M {
    let mut c = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            c[r][k] = (0..3).map(|i| a[i][r] * b[i][k]).sum();
        }
    }
    c
}

fn sub(a: &M, b: &M) -> M {
    let mut c = *a;
    for r in 0..3 {
        for k in 0..3 {
            c[r][k] -= b[r][k];
        }
    }
    c
}

/// The inverse of a 3×3 block by its adjugate (zero if it is not positive definite).
fn inverse(d: &M) -> M {
    let c00 = d[1][1] * d[2][2] - d[1][2] * d[2][1];
    let c01 = d[1][2] * d[2][0] - d[1][0] * d[2][2];
    let c02 = d[1][0] * d[2][1] - d[1][1] * d[2][0];
    let det = d[0][0] * c00 + d[0][1] * c01 + d[0][2] * c02;
    if !(det > 0.0 && det.is_finite()) {
        return [[0.0; 3]; 3];
    }
    let c11 = d[0][0] * d[2][2] - d[0][2] * d[2][0];
    let c12 = d[0][2] * d[1][0] - d[0][0] * d[1][2];
    let c22 = d[0][0] * d[1][1] - d[0][1] * d[1][0];
    let i = 1.0 / det;
    [
        [c00 * i, c01 * i, c02 * i],
        [c01 * i, c11 * i, c12 * i],
        [c02 * i, c12 * i, c22 * i],
    ]
}

/// The block elimination of `direct.rs` in `f32`, its matrix scaled symmetrically by `s` (one
/// factor per unknown) before rounding: `(S A S) y = S b`, `x = S y`.
struct F32Factor {
    p: Vec<M>,
    y: Vec<M>,
    z: Vec<M>,
    s: Vec<[f64; 3]>,
}

impl F32Factor {
    fn new(a: &[Row], scale: bool) -> Self {
        let s: Vec<[f64; 3]> = a
            .iter()
            .map(|(d, _, _)| {
                [0, 1, 2].map(|i| {
                    if scale && d[i][i] > 0.0 {
                        1.0 / d[i][i].sqrt()
                    } else {
                        1.0
                    }
                })
            })
            .collect();
        let n = a.len();
        let round = |b: &[[f64; 3]; 3], k: usize, m: usize| -> M {
            let mut c = [[0.0f32; 3]; 3];
            for r in 0..3 {
                for q in 0..3 {
                    let v = if m < n {
                        b[r][q] * s[k][r] * s[m][q]
                    } else {
                        0.0
                    };
                    c[r][q] = v as f32;
                }
            }
            c
        };
        let zero = [[0.0f32; 3]; 3];
        let (mut s11, mut s12, mut s22) = (zero, zero, zero);
        let (mut p, mut y, mut z) = (Vec::new(), Vec::new(), Vec::new());
        for (k, (d, a1, a2)) in a.iter().enumerate() {
            let d = sub(&round(d, k, k), &s11);
            let a1 = sub(&round(a1, k, k + 1), &s12);
            let a2 = round(a2, k, k + 2);
            let pk = inverse(&d);
            let yk = mul(&pk, &a1);
            let zk = mul(&pk, &a2);
            let t = tmul(&a1, &yk);
            for r in 0..3 {
                for q in 0..3 {
                    s11[r][q] = t[r][q] + s22[r][q];
                }
            }
            s12 = tmul(&a1, &zk);
            s22 = tmul(&a2, &zk);
            p.push(pk);
            y.push(yk);
            z.push(zk);
        }
        Self { p, y, z, s }
    }

    fn solve(&self, b: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let n = b.len();
        let mv = |m: &M, v: &[f32; 3], t: bool| -> [f32; 3] {
            [0, 1, 2].map(|r| {
                (0..3)
                    .map(|i| if t { m[i][r] * v[i] } else { m[r][i] * v[i] })
                    .sum()
            })
        };
        let mut w = vec![[0.0f32; 3]; n];
        let (mut z1, mut z2) = ([0.0f32; 3], [0.0f32; 3]);
        for k in 0..n {
            let mut v = [0, 1, 2].map(|i| (b[k][i] * self.s[k][i]) as f32);
            if k >= 2 {
                let t = mv(&self.z[k - 2], &z2, true);
                v = [0, 1, 2].map(|i| v[i] - t[i]);
            }
            if k >= 1 {
                let t = mv(&self.y[k - 1], &z1, true);
                v = [0, 1, 2].map(|i| v[i] - t[i]);
            }
            z2 = z1;
            z1 = v;
            w[k] = mv(&self.p[k], &v, false);
        }
        let (mut x1, mut x2) = ([0.0f32; 3], [0.0f32; 3]);
        let mut x = vec![[0.0; 3]; n];
        for k in (0..n).rev() {
            let u = mv(&self.z[k], &x2, false);
            let t = mv(&self.y[k], &x1, false);
            let v = [0, 1, 2].map(|i| w[k][i] - u[i] - t[i]);
            x2 = x1;
            x1 = v;
            x[k] = [0, 1, 2].map(|i| f64::from(v[i]) * self.s[k][i]);
        }
        x
    }
}

/// The largest error of `x` against `reference` on the stretch–shear (even block rows) and the
/// bend–twist (odd) unknowns, each relative to that kind's largest reference value.
fn relative_errors(x: &[[f64; 3]], reference: &[[f64; 3]]) -> [f64; 2] {
    [0, 1].map(|kind| {
        let rows = || (kind..x.len()).step_by(2);
        let size = rows()
            .flat_map(|k| reference[k])
            .fold(0.0f64, |m, v| m.max(v.abs()));
        let err = rows()
            .flat_map(|k| (0..3).map(move |i| (k, i)))
            .fold(0.0f64, |m, (k, i)| m.max((x[k][i] - reference[k][i]).abs()));
        err / size
    })
}

/// Errors of the `f32` solve (and after `refinements` rounds of refinement with `f64`
/// residuals) against the `f64` solution, for a right-hand side shaped as the stiff scheme's
/// (a constraint residual along the whole rod).
fn study(material: &str, scale: bool, refinements: usize) -> Vec<[f64; 2]> {
    let a = wire_matrix(material);
    let b: Vec<[f64; 3]> = (0..a.len())
        .map(|k| {
            let t = k as f64;
            [(0.3 * t).sin(), (0.7 * t).cos(), 0.5 + (1.1 * t).sin()].map(|v| v * 1e-6)
        })
        .collect();
    let reference = solve_f64(&a, &b);
    let f = F32Factor::new(&a, scale);
    let mut x = f.solve(&b);
    let mut out = vec![relative_errors(&x, &reference)];
    for _ in 0..refinements {
        let ax = apply(&a, &x);
        let r: Vec<[f64; 3]> = b
            .iter()
            .zip(&ax)
            .map(|(p, q)| [p[0] - q[0], p[1] - q[1], p[2] - q[2]])
            .collect();
        let d = f.solve(&r);
        for (xk, dk) in x.iter_mut().zip(&d) {
            for i in 0..3 {
                xk[i] += dk[i];
            }
        }
        out.push(relative_errors(&x, &reference));
    }
    out
}

/// An `f32` factorisation of a real wire's matrix, scaled symmetrically by its diagonal, solves
/// it to a few parts in 10⁴ and reaches the `f64` solution by iterative refinement with `f64`
/// residuals, for every preset; unscaled, its bend–twist unknowns are wrong outright (printed,
/// not asserted). So a GPU solve can factorise in `f32` once the matrix is scaled. (Printed with
/// `--nocapture`: the table of `docs/benchmarks/stiff-gpu.md`.)
#[test]
fn a_scaled_f32_factorisation_with_f64_refinement_reaches_the_f64_solution() {
    for material in ["nitinol", "steel", "catheter-polymer", "suture"] {
        for scale in [false, true] {
            let e = study(material, scale, 3);
            println!(
                "{material:>17} scaled {scale:>5}: stretch–shear / bend–twist error {}",
                e.iter()
                    .map(|[g, o]| format!("{g:.1e} / {o:.1e}"))
                    .collect::<Vec<_>>()
                    .join(" → ")
            );
            if scale {
                let worst: Vec<f64> = e.iter().map(|[g, o]| g.max(*o)).collect();
                assert!(
                    worst[0] < 2e-3,
                    "{material}: f32 solve error {:e}",
                    worst[0]
                );
                assert!(
                    worst[2] < 1e-5,
                    "{material}: after two rounds {:e}",
                    worst[2]
                );
                assert!(
                    worst[3] < 1e-10,
                    "{material}: after three rounds {:e}",
                    worst[3]
                );
            }
        }
    }
}
