//! One time-step of the explicit scheme (paper section 2.1) against one of the stiff scheme
//! (XPBD constraints, direct block-tridiagonal solve), side by side, at 1000 elements, in f32
//! and f64. The rod is a 1 m nitinol guidewire (preset `nitinol`) swinging as a pendulum; each
//! scheme runs at a time step it is stable at (explicit 1e-7 s, stiff 1e-3 s). The cost of an
//! explicit step does not depend on the state; a stiff step's does, through its iteration
//! count (the default settings iterate until the residual is below 1e-5; for the f32 rod, the
//! 1.2e-4 strain its positions resolve; at most 8 iterations). So that the stiff variants
//! measure the same motion whatever number of steps criterion happens to run, each replays the
//! first [`SWING`] steps (3 s) of the release from the horizontal, the rod rebuilt at every
//! restart; the iterations and factorisations per step, the largest strain and residual and
//! the steps left above the tolerance are printed. `stiff_1_iteration` runs exactly one
//! iteration per step (no convergence test). `cargo xtask bench --stiff` runs this bench and
//! checks the stiff step against the target (at most 2× the explicit step).
//!
//! `cargo bench -p cosserat-backend-cpu --bench stiff`; results in `docs/benchmarks/stiff.md`.

use cosserat_backend_cpu::{
    CpuRod, EndCondition, Ordering, Refactor, SolverSettings, StiffScratch, StiffSettings,
    step_rod, step_rod_stiff,
};
use cosserat_model::presets::preset;
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Real, Vec3};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::hint::black_box;

const ELEMENTS: usize = 1000;
/// Steps of the stiff pendulum before it is released again.
const SWING: u64 = 3000;

fn rod<T: Real>() -> CpuRod<T> {
    let spec = RodSpec::new(preset("nitinol").unwrap().material());
    let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 1.0, ELEMENTS);
    let (s, p) = build_rod::<T>(&pts, &spec).unwrap();
    CpuRod::new(s, p, [EndCondition::pinned(), EndCondition::free()], vec![])
}

fn settings<T: Real>(dt: f64) -> SolverSettings<T> {
    SolverSettings {
        dt: T::lit(dt),
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible: false,
        gravity: Vec3::new(T::zero(), T::zero(), T::lit(-9.81)),
        divergence_strain: T::lit(0.1),
    }
}

fn bench_precision<T: Real>(c: &mut Criterion, name: &str) {
    let mut group = c.benchmark_group(format!("stiff_vs_explicit_{name}"));
    let explicit = settings::<T>(1e-7);
    let mut r = rod::<T>();
    let mut step = 0;
    group.bench_function(BenchmarkId::new("explicit", ELEMENTS), |b| {
        b.iter(|| {
            let t = step as f64 * 1e-7;
            black_box(step_rod(&mut r, &explicit, t, 0, step).unwrap());
            step += 1;
        })
    });
    let stiff = settings::<T>(1e-3);
    let variants = [
        ("stiff", StiffSettings::default()),
        (
            "stiff_every_iteration",
            StiffSettings {
                refactor: Refactor::EveryIteration,
                ..StiffSettings::default()
            },
        ),
        (
            "stiff_lagged",
            StiffSettings {
                refactor: Refactor::Lagged,
                ..StiffSettings::default()
            },
        ),
        (
            "stiff_1_iteration",
            StiffSettings {
                iterations: 1,
                tolerance: 0.0,
                ..StiffSettings::default()
            },
        ),
    ];
    for (label, stiff_settings) in variants {
        let mut r = rod::<T>();
        let mut scratch = StiffScratch::new();
        let (mut step, mut iterations, mut factorisations) = (0, 0, 0);
        let (mut unconverged, mut residual, mut strain) = (0, 0.0_f64, 0.0_f64);
        group.bench_function(BenchmarkId::new(label, ELEMENTS), |b| {
            b.iter(|| {
                let k = step % SWING;
                if k == 0 && step > 0 {
                    let report = scratch.report();
                    iterations += report.total_iterations;
                    factorisations += report.factorisations;
                    unconverged += report.unconverged_steps;
                    residual = residual.max(report.max_residual);
                    r = rod::<T>();
                    scratch = StiffScratch::new();
                }
                let t = k as f64 * 1e-3;
                let stats =
                    step_rod_stiff(&mut r, &stiff, &stiff_settings, &mut scratch, t, 0, k, 1)
                        .unwrap();
                strain = strain.max(black_box(stats).max_strain());
                step += 1;
            })
        });
        let report = scratch.report();
        let per_step = |total: u64| total as f64 / step.max(1) as f64;
        // Without a tolerance the residual after the last iteration is not evaluated.
        let (residual, above) = if stiff_settings.tolerance > 0.0 {
            (
                format!("{:.1e}", residual.max(report.max_residual)),
                (unconverged + report.unconverged_steps).to_string(),
            )
        } else {
            ("n/a".into(), "n/a".into())
        };
        // One line per variant, read by `cargo xtask bench --stiff`.
        println!(
            "{label} {name}: {:.2} iterations and {:.2} factorisations per step over {step} steps; \
             max strain {strain:.1e}, max residual {residual}, {above} steps above the tolerance",
            per_step(iterations + report.total_iterations),
            per_step(factorisations + report.factorisations),
        );
    }
    group.finish();
}

fn benches(c: &mut Criterion) {
    bench_precision::<f32>(c, "f32");
    bench_precision::<f64>(c, "f64");
}

criterion_group!(stiff, benches);
criterion_main!(stiff);
