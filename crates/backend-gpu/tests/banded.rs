//! The stiff scheme's banded solve on the GPU (`banded.rs`) against the matrices it was given:
//! the residual `‖A x − b‖` computed from the block rows on the host, for systems shaped as the
//! stiff scheme's (`J K⁻¹ Jᵀ + α̃` of a chain), for many rods at once, for rods of different
//! scales in one batch, and for rows no free degree of freedom reaches (a singular pivot, which
//! keeps its multiplier unchanged).

use cosserat_backend_gpu::GpuOptions;
use cosserat_backend_gpu::banded::{BLOCK_ROW, BandedBatch, Precision, Strategy, backward_error};

const STRATEGIES: [Strategy; 2] = [Strategy::Chain, Strategy::CyclicReduction];

type M3 = [[f64; 3]; 3];

/// A small deterministic generator (no dependency): uniform in `[-1, 1)`.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
    fn block(&mut self) -> M3 {
        [(); 3].map(|_| [(); 3].map(|_| self.next()))
    }
}

fn mul_t(a: &M3, b: &M3) -> M3 {
    // a bᵀ
    let mut c = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            c[r][k] = (0..3).map(|i| a[r][i] * b[k][i]).sum();
        }
    }
    c
}

/// `A = G Gᵀ + diag(alpha)` with `G` a random chain Jacobian: block row `k` of `G` touches the
/// degrees of freedom `k` and `k + 1` (as a constraint touches the points and frames beside
/// it), scaled by `scale[k]`, so `A` is banded with two blocks on each side (the fill of the
/// stiff scheme's ordering). Returns the block rows (`BLOCK_ROW` numbers each) and `A` dense.
fn chain_system(rng: &mut Lcg, count: usize, scale: &[f64], alpha: f64) -> Vec<[f64; BLOCK_ROW]> {
    // G_k = [L_k at dof k, R_k at dof k + 1, S_k at dof k + 2].
    let g: Vec<[M3; 3]> = (0..count)
        .map(|k| {
            let s = scale[k];
            [rng.block(), rng.block(), rng.block()].map(|b| b.map(|r| r.map(|x| x * s)))
        })
        .collect();
    // A_{k,m} = Σ_dof G_k(dof) G_m(dof)ᵀ over shared dofs.
    let block = |k: usize, m: usize| -> M3 {
        let mut c = [[0.0; 3]; 3];
        for (i, gk) in g[k].iter().enumerate() {
            let dof = k + i;
            if dof < m || dof > m + 2 {
                continue;
            }
            let p = mul_t(gk, &g[m][dof - m]);
            for r in 0..3 {
                for q in 0..3 {
                    c[r][q] += p[r][q];
                }
            }
        }
        c
    };
    (0..count)
        .map(|k| {
            let mut row = [0.0; BLOCK_ROW];
            let mut d = block(k, k);
            for (i, r) in d.iter_mut().enumerate() {
                r[i] += alpha;
            }
            row[..6].copy_from_slice(&[d[0][0], d[0][1], d[0][2], d[1][1], d[1][2], d[2][2]]);
            for (off, at) in [(1, 6), (2, 15)] {
                if k + off < count {
                    let b = block(k, k + off);
                    for r in 0..3 {
                        for c in 0..3 {
                            row[at + 3 * r + c] = b[r][c];
                        }
                    }
                }
            }
            row
        })
        .collect()
}

/// `A x` from the block rows (symmetric: the blocks below the diagonal are the transposes).
fn apply(rows: &[[f64; BLOCK_ROW]], x: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = rows.len();
    let mut y = vec![[0.0; 3]; n];
    for k in 0..n {
        let r = &rows[k];
        let d = [[r[0], r[1], r[2]], [r[1], r[3], r[4]], [r[2], r[4], r[5]]];
        for i in 0..3 {
            y[k][i] += (0..3).map(|j| d[i][j] * x[k][j]).sum::<f64>();
        }
        for (off, at) in [(1, 6), (2, 15)] {
            if k + off >= n {
                continue;
            }
            for i in 0..3 {
                for j in 0..3 {
                    let b = r[at + 3 * i + j];
                    y[k][i] += b * x[k + off][j];
                    y[k + off][j] += b * x[k][i];
                }
            }
        }
    }
    y
}

fn norm(v: &[[f64; 3]]) -> f64 {
    v.iter().flatten().map(|x| x * x).sum::<f64>().sqrt()
}

/// The batch, or `None` where no adapter is present and `COSSERAT_REQUIRE_GPU` is unset.
fn batch(
    precision: Precision,
    strategy: Strategy,
    rods: usize,
    elements: usize,
) -> Option<BandedBatch> {
    match BandedBatch::new(&GpuOptions::default(), precision, strategy, rods, elements) {
        Ok(b) => Some(b),
        Err(e) => {
            if std::env::var_os("COSSERAT_REQUIRE_GPU").is_some() {
                panic!("COSSERAT_REQUIRE_GPU is set but the banded batch failed: {e}");
            }
            eprintln!("skipping: {e}");
            None
        }
    }
}

/// Solves and returns each rod's componentwise backward error (`banded::backward_error`): what
/// a stable factorisation keeps near the arithmetic's resolution however badly `A` is scaled
/// (the relative residual `‖A x − b‖ / ‖b‖` grows with the condition number instead).
fn backward_errors(
    b: &mut BandedBatch,
    rows: &[Vec<[f64; BLOCK_ROW]>],
    rhs: &[Vec<[f64; 3]>],
) -> Vec<f64> {
    b.set_rows(rows).unwrap();
    b.set_rhs(rhs).unwrap();
    b.run(1).unwrap();
    let x = b.solution().unwrap();
    rows.iter()
        .zip(rhs)
        .zip(&x)
        .map(|((a, f), x)| backward_error(a, x, f))
        .collect()
}

#[test]
fn solves_a_batch_of_chain_systems_to_double_precision() {
    // 37 elements: not a power of two, so the cyclic reduction's last levels have rows with
    // one neighbour only.
    for strategy in STRATEGIES {
        solve_chain_systems(Precision::F64, strategy, 5, 37);
        solve_chain_systems(Precision::F64, strategy, 2, 1);
        solve_chain_systems(Precision::F64, strategy, 2, 2);
        // The single-precision kernels keep a backward error of single precision's order.
        // (Whether their solution is accurate is a question of the matrix's conditioning, which
        // backend-cpu `stiff/precision_tests.rs` answers on real wires' matrices.)
        solve_chain_systems(Precision::F32, strategy, 5, 37);
    }
}

fn solve_chain_systems(precision: Precision, strategy: Strategy, rods: usize, elements: usize) {
    let Some(mut b) = batch(precision, strategy, rods, elements) else {
        return;
    };
    let count = b.block_rows();
    let mut rng = Lcg(7);
    // Rods of very different scales in one batch, and scales varying along a rod by twelve
    // orders of magnitude (frames' inverse inertias against points' inverse masses), with a
    // compliance far below them: the spans the stiff scheme's matrices have.
    let rows: Vec<_> = (0..rods)
        .map(|rod| {
            let base = 10f64.powi(rod as i32 % 9 - 4);
            let scale: Vec<f64> = (0..count)
                .map(|k| base * if k % 2 == 0 { 1.0 } else { 1e6 })
                .collect();
            chain_system(&mut rng, count, &scale, 1e-11 * base * base)
        })
        .collect();
    let rhs: Vec<Vec<[f64; 3]>> = (0..rods)
        .map(|_| {
            (0..count)
                .map(|_| [rng.next(), rng.next(), rng.next()])
                .collect()
        })
        .collect();
    let res = backward_errors(&mut b, &rows, &rhs);
    let worst = res.iter().cloned().fold(0.0, f64::max);
    assert!(
        worst
            < if precision == Precision::F64 {
                1e-12
            } else {
                1e-5
            },
        "{precision:?} {strategy:?}, {rods} rods of {elements} elements: backward error {worst:e}"
    );
}

#[test]
fn rows_no_free_degree_reaches_keep_a_zero_multiplier() {
    for strategy in STRATEGIES {
        singular_rows(strategy);
    }
}

fn singular_rows(strategy: Strategy) {
    // Block rows 4 and 5 are zero (an element whose points and frame are all held): their
    // pivots are singular, the rest of the system is solved and their unknowns stay zero.
    let (rods, elements) = (3, 10);
    let Some(mut b) = batch(Precision::F64, strategy, rods, elements) else {
        return;
    };
    let count = b.block_rows();
    let mut rng = Lcg(11);
    let rows: Vec<_> = (0..rods)
        .map(|_| {
            let scale: Vec<f64> = (0..count)
                .map(|k| if k == 4 || k == 5 { 0.0 } else { 1.0 })
                .collect();
            chain_system(&mut rng, count, &scale, 0.0)
        })
        .collect();
    let rhs: Vec<Vec<[f64; 3]>> = (0..rods)
        .map(|_| {
            (0..count)
                .map(|k| {
                    if k == 4 || k == 5 {
                        [0.0; 3]
                    } else {
                        [rng.next(), rng.next(), rng.next()]
                    }
                })
                .collect()
        })
        .collect();
    b.set_rows(&rows).unwrap();
    b.set_rhs(&rhs).unwrap();
    b.run(1).unwrap();
    let x = b.solution().unwrap();
    for (rod, xs) in x.iter().enumerate() {
        for k in [4, 5] {
            assert_eq!(xs[k], [0.0; 3], "{strategy:?}: rod {rod}, block row {k}");
        }
        let ax = apply(&rows[rod], xs);
        let r: Vec<[f64; 3]> = ax
            .iter()
            .zip(&rhs[rod])
            .map(|(p, q)| [p[0] - q[0], p[1] - q[1], p[2] - q[2]])
            .collect();
        let rel = norm(&r) / norm(&rhs[rod]);
        assert!(
            rel < 1e-10,
            "{strategy:?}: rod {rod}: relative residual {rel:e}"
        );
    }
}

#[test]
fn mismatched_input_is_refused_with_the_sizes() {
    let Some(mut b) = batch(Precision::F64, Strategy::Chain, 2, 4) else {
        return;
    };
    let e = b.set_rows(&[vec![[0.0; BLOCK_ROW]; 7]]).unwrap_err();
    assert!(
        e.to_string()
            .contains("1 rods' rows given, the batch has 2"),
        "{e}"
    );
    let e = b
        .set_rhs(&[vec![[0.0; 3]; 7], vec![[0.0; 3]; 6]])
        .unwrap_err();
    assert!(
        e.to_string().contains("rod 1: 6 right-hand-side blocks"),
        "{e}"
    );
    let none = BandedBatch::new(
        &GpuOptions::default(),
        Precision::F64,
        Strategy::Chain,
        0,
        4,
    );
    assert!(none.is_err());
}
