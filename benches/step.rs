//! One time-step of the paper's free-space pendulum (section 3.1) on the CPU.
//!
//! Sizes 128, 512, 1000 and 3072 elements, `f32` and `f64`, the serial and the rayon backend,
//! 10 red–black constraint sweeps per step. Two shapes of call are measured: a single
//! `Simulation::step` (what a haptic loop does every millisecond, including the copy into and
//! out of the working layout), and the cost per step inside a batch of 100 (`Simulation::run`).
//! Many rods at once show what the rayon backend is for. `cargo xtask bench` runs this and
//! writes the medians to `docs/benchmarks/cpu.md`.

use cosserat::{Backend, Material, RodBuilder, Simulation, SimulationBuilder};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;

/// The scene's step, 2e-5 s, shortened in proportion to the element length above 1000 elements
/// so that it stays inside the explicit scheme's stable step (the cost of a step does not
/// depend on it).
fn pendulum_dt(elements: usize) -> f64 {
    2e-5 * (1000.0 / elements as f64).min(1.0)
}

/// The pendulum of `scenes/pendulum.toml`, built in code, with `rods` copies side by side.
fn pendulum(elements: usize, rods: usize, double: bool, backend: Backend) -> Simulation {
    let material = Material::new(1.0e6, 1.0e6 / 3.0, 1100.0, 0.005);
    let mut b = SimulationBuilder::new()
        .dt(pendulum_dt(elements))
        .iterations(10)
        .double_precision(double)
        .backend(backend)
        .gravity([0.0, 0.0, -9.81]);
    for r in 0..rods {
        b.add_rod(
            RodBuilder::straight(
                [0.0, 0.05 * r as f64, 0.0],
                [1.0, 0.0, 0.0],
                1.0,
                elements,
                material,
            )
            .pin_start(),
        );
    }
    let mut sim = b.build().expect("valid pendulum");
    // Start from a swinging state rather than the exactly straight initial one.
    sim.run(200).expect("stable");
    sim
}

fn single_rod(c: &mut Criterion) {
    let mut g = c.benchmark_group("pendulum_step");
    g.warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(30);
    for &n in &[128usize, 512, 1000, 3072] {
        for (precision, double) in [("f32", false), ("f64", true)] {
            for backend in [Backend::Cpu, Backend::CpuRayon] {
                let id = format!("{precision}/{}", backend.name());
                let mut sim = pendulum(n, 1, double, backend);
                g.bench_with_input(BenchmarkId::new(format!("single/{id}"), n), &n, |b, _| {
                    b.iter(|| black_box(sim.step()).expect("stable"))
                });
                let mut sim = pendulum(n, 1, double, backend);
                g.bench_with_input(BenchmarkId::new(format!("batch100/{id}"), n), &n, |b, _| {
                    b.iter(|| black_box(sim.run(100)).expect("stable"))
                });
            }
        }
    }
    g.finish();
}

fn many_rods(c: &mut Criterion) {
    let mut g = c.benchmark_group("pendulum_many_rods");
    g.warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(20);
    for backend in [Backend::Cpu, Backend::CpuRayon] {
        let mut sim = pendulum(256, 16, false, backend);
        g.bench_function(
            BenchmarkId::new(format!("16x256/f32/{}", backend.name()), 16),
            |b| b.iter(|| black_box(sim.run(10)).expect("stable")),
        );
    }
    g.finish();
}

criterion_group!(benches, single_rod, many_rods);
criterion_main!(benches);
