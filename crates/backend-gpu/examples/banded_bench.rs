//! Times the stiff scheme's banded factorisation and solve on the GPU (`banded.rs`): each
//! strategy (the cyclic reduction, the chain, the partitioned solve), batches of 1 to 4096 rods
//! of 256 elements, in `f64` and `f32`, and reports each one's backward error on a system scaled
//! as the stiff scheme's are.
//!
//! `cargo run --release -p cosserat-backend-gpu --example banded_bench [-- OPTIONS]`
//! prints one JSON object per row: strategy, rods, elements, precision (and the partitioned
//! solve's invocations per rod), the median wall time of one factorisation plus solve (from
//! calls of `repeats` of them, each waited for), and the backward error
//! `max_i |A x − b|_i / (|A| |x| + |b|)_i` of the last solve (componentwise).
//!
//! Options, each optional:
//! - `--elements N` (256);
//! - `--strategy S[,S…]` of `cr`, `chain`, `partitioned` (all three);
//! - `--precision P[,P…]` of `f64`, `f32` (both);
//! - `--rods R[,R…]` (1,64,1024,4096);
//! - `--threads T[,T…]`: the partitioned solve's invocations per rod, a row for each (its own
//!   choice: `banded::PARTITIONED_THREADS`, fewer for short rods);
//! - `--repeats N`: solves per timed call (100; 20 from 1024 rods on) and `--calls N`: timed
//!   calls (7), for a short smoke run.

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

/// The value after `flag`, if given.
fn option<'a>(args: &'a [String], flag: &str) -> Option<&'a str> {
    let i = args.iter().position(|a| a == flag)?;
    Some(
        args.get(i + 1)
            .unwrap_or_else(|| panic!("{flag} needs a value"))
            .as_str(),
    )
}

/// The comma-separated list after `flag`, each item read by `parse`.
fn list<T>(args: &[String], flag: &str, parse: impl Fn(&str) -> Option<T>) -> Option<Vec<T>> {
    option(args, flag).map(|v| {
        v.split(',')
            .map(|s| parse(s.trim()).unwrap_or_else(|| panic!("{flag}: cannot read `{s}`")))
            .collect()
    })
}

fn number<T: std::str::FromStr>(args: &[String], flag: &str) -> Option<T> {
    option(args, flag).map(|v| {
        v.parse()
            .unwrap_or_else(|_| panic!("{flag}: cannot read `{v}`"))
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let elements: usize = number(&args, "--elements").unwrap_or(256);
    let strategies = list(&args, "--strategy", |s| {
        match s.to_ascii_lowercase().as_str() {
            "cr" | "cyclic" | "cyclicreduction" => Some(Strategy::CyclicReduction),
            "chain" => Some(Strategy::Chain),
            "partitioned" => Some(Strategy::Partitioned),
            _ => None,
        }
    })
    .unwrap_or(vec![
        Strategy::CyclicReduction,
        Strategy::Chain,
        Strategy::Partitioned,
    ]);
    let precisions = list(&args, "--precision", |s| {
        match s.to_ascii_lowercase().as_str() {
            "f64" => Some(Precision::F64),
            "f32" => Some(Precision::F32),
            _ => None,
        }
    })
    .unwrap_or(vec![Precision::F64, Precision::F32]);
    let batches =
        list(&args, "--rods", |s| s.parse::<usize>().ok()).unwrap_or(vec![1, 64, 1024, 4096]);
    // `None`: the strategy's own choice.
    let threads: Vec<Option<u32>> = list(&args, "--threads", |s| s.parse::<u32>().ok())
        .map_or(vec![None], |t| t.into_iter().map(Some).collect());
    let repeats: Option<usize> = number(&args, "--repeats");
    let calls: usize = number(&args, "--calls").unwrap_or(7);
    let mut runs = Vec::new();
    for &strategy in &strategies {
        for &precision in &precisions {
            if strategy == Strategy::Partitioned {
                runs.extend(threads.iter().map(|&t| (strategy, precision, t)));
            } else {
                runs.push((strategy, precision, None));
            }
        }
    }
    for (strategy, precision, threads) in runs {
        for &rods in &batches {
            let made = match threads {
                Some(t) => BandedBatch::new_partitioned(
                    &GpuOptions::default(),
                    precision,
                    rods,
                    elements,
                    t,
                ),
                None => {
                    BandedBatch::new(&GpuOptions::default(), precision, strategy, rods, elements)
                }
            };
            let mut batch = match made {
                Ok(b) => b,
                Err(e) => {
                    println!(
                        "{{\"strategy\":\"{strategy:?}\",\"precision\":\"{precision:?}\",\"rods\":{rods},\"error\":{:?}}}",
                        e.to_string()
                    );
                    continue;
                }
            };
            // The partitioned solve's invocations per rod and elements per invocation.
            let partition = batch.partition().map_or(String::new(), |(t, m)| {
                format!(",\"threads\":{t},\"elements_per_thread\":{m}")
            });
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
            let repeats = repeats.unwrap_or(if rods >= 1024 { 20 } else { 100 });
            batch.run(repeats).expect("warm-up");
            let mut times: Vec<f64> = (0..calls.max(1))
                .map(|_| {
                    let t = Instant::now();
                    batch.run(repeats).expect("timed");
                    t.elapsed().as_secs_f64() / repeats as f64
                })
                .collect();
            times.sort_by(f64::total_cmp);
            let median = times[times.len() / 2];
            println!(
                "{{\"strategy\":\"{strategy:?}\",\"precision\":\"{precision:?}\",\"rods\":{rods},\"elements\":{elements}{partition},\"us_per_solve\":{:.2},\"us_per_rod_solve\":{:.4},\"backward_error\":{error:.3e}}}",
                median * 1e6,
                median * 1e6 / rods as f64
            );
        }
    }
}
