//! Times the stiff scheme's banded factorisation and solve on the GPU (`banded.rs`): one rod per
//! invocation, batches of 1 to 4096 rods of 256 elements, in `f64` and `f32`, and reports each
//! precision's backward error on a system scaled as the stiff scheme's are.
//!
//! `cargo run --release -p cosserat-backend-gpu --example banded_bench [-- --elements N]`
//! prints one JSON object per row: rods, elements, precision, the median wall time of one
//! factorisation plus solve (from calls of `repeats` of them, each waited for), and the backward
//! error `max_i |A x − b|_i / (|A| |x| + |b|)_i` of the last solve (componentwise).

use cosserat_backend_gpu::GpuOptions;
use cosserat_backend_gpu::banded::{BLOCK_ROW, BandedBatch, Precision, Strategy, backward_error};
use std::time::Instant;

/// Deterministic numbers in `[-1, 1)`: the fractional part of a scaled sine.
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> f64 {
        self.0 += 1;
        ((self.0 as f64 * 12.9898).sin() * 43758.5453).fract()
    }
}

/// A diagonally dominant block-banded system with alternating scales (points against frames,
/// six orders of magnitude apart) and a compliance far below both: `count` block rows.
fn system(rng: &mut Noise, count: usize) -> Vec<[f64; BLOCK_ROW]> {
    let scale = |k: usize| -> f64 { if k.is_multiple_of(2) { 1.0 } else { 1e6 } };
    (0..count)
        .map(|k| {
            let mut row = [0.0; BLOCK_ROW];
            for (off, at) in [(1usize, 6usize), (2, 15)] {
                if k + off < count {
                    let s = (scale(k) * scale(k + off)).sqrt() * 0.15;
                    for v in &mut row[at..at + 9] {
                        *v = rng.next() * s;
                    }
                }
            }
            let d = scale(k) * (2.0 + 1e-11);
            row[0] = d;
            row[3] = d;
            row[5] = d;
            row[1] = rng.next() * 0.1 * scale(k);
            row[2] = rng.next() * 0.1 * scale(k);
            row[4] = rng.next() * 0.1 * scale(k);
            row
        })
        .collect()
}

fn main() {
    let mut elements = 256;
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--elements") {
        elements = args[i + 1].parse().expect("--elements N");
    }
    let strategies = [Strategy::CyclicReduction, Strategy::Chain];
    let runs = strategies
        .iter()
        .flat_map(|s| [(*s, Precision::F64), (*s, Precision::F32)]);
    for (strategy, precision) in runs {
        for rods in [1usize, 64, 1024, 4096] {
            let mut batch = match BandedBatch::new(
                &GpuOptions::default(),
                precision,
                strategy,
                rods,
                elements,
            ) {
                Ok(b) => b,
                Err(e) => {
                    println!(
                        "{{\"strategy\":\"{strategy:?}\",\"precision\":\"{precision:?}\",\"rods\":{rods},\"error\":\"{e}\"}}"
                    );
                    continue;
                }
            };
            let count = batch.block_rows();
            let mut rng = Noise(1);
            let rows: Vec<_> = (0..rods).map(|_| system(&mut rng, count)).collect();
            let rhs: Vec<Vec<[f64; 3]>> = (0..rods)
                .map(|_| {
                    (0..count)
                        .map(|_| [rng.next(), rng.next(), rng.next()])
                        .collect()
                })
                .collect();
            batch.set_rows(&rows).expect("rows");
            batch.set_rhs(&rhs).expect("rhs");
            batch.run(1).expect("solve");
            let x = batch.solution().expect("read back");
            let error = rows
                .iter()
                .zip(&x)
                .zip(&rhs)
                .map(|((a, x), b)| backward_error(a, x, b))
                .fold(0.0, f64::max);
            // Calls of `repeats` solves, waited for; the median of the per-solve times.
            let repeats = if rods >= 1024 { 20 } else { 100 };
            batch.run(repeats).expect("warm-up");
            let mut times: Vec<f64> = (0..7)
                .map(|_| {
                    let t = Instant::now();
                    batch.run(repeats).expect("timed");
                    t.elapsed().as_secs_f64() / repeats as f64
                })
                .collect();
            times.sort_by(f64::total_cmp);
            let median = times[times.len() / 2];
            println!(
                "{{\"strategy\":\"{strategy:?}\",\"precision\":\"{precision:?}\",\"rods\":{rods},\"elements\":{elements},\"us_per_solve\":{:.2},\"us_per_rod_solve\":{:.4},\"backward_error\":{error:.3e}}}",
                median * 1e6,
                median * 1e6 / rods as f64
            );
        }
    }
}
