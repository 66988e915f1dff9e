//! A loop of stiff steps for profiling (`perf record`) and for timing variants against each
//! other in one process: the bench's rod (nitinol, 1 m, 1000 elements, pendulum, dt 1e-3).
//!
//! `cargo run --release -p cosserat-backend-cpu --example stiff_profile -- [f32|f64] [STEPS]`;
//! `N` (elements, default 1000), `ITERS`, `TOL`, `GEOM`, `REFACTOR` (`newton`, `step`, `lag`) override the stiff settings (default settings otherwise).

use cosserat_backend_cpu::{
    CpuRod, EndCondition, Ordering, SolverSettings, StiffScratch, StiffSettings,
};
use cosserat_backend_cpu::{step_rod, step_rod_stiff};
use cosserat_model::presets::preset;
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Real, Vec3};
use std::time::Instant;

fn rod<T: Real>(n: usize) -> CpuRod<T> {
    let spec = RodSpec::new(preset("nitinol").unwrap().material());
    let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 1.0, n);
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

fn run<T: Real>(steps: u64) {
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    let mut st = StiffSettings::default();
    if let Some(i) = env("ITERS") {
        st.iterations = i as usize;
    }
    if let Some(t) = env("TOL") {
        st.tolerance = t;
    }
    if let Some(g) = env("GEOM") {
        st.geometric = g;
    }
    match std::env::var("REFACTOR").as_deref() {
        Ok("step") => st.refactor = cosserat_backend_cpu::Refactor::EveryStep,
        Ok("lag") => st.refactor = cosserat_backend_cpu::Refactor::Lagged,
        Ok("newton") => st.refactor = cosserat_backend_cpu::Refactor::EveryIteration,
        _ => {}
    }
    let n = env("N").map_or(1000, |v| v as usize);
    let mut times = Vec::new();
    let mut r = rod::<T>(n);
    let s = settings::<T>(1e-7);
    for k in 0..steps.min(20000) {
        let t0 = Instant::now();
        step_rod(&mut r, &s, k as f64 * 1e-7, 0, k).unwrap();
        times.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    let explicit = summary(&mut times);
    let mut r = rod::<T>(n);
    let s = settings::<T>(1e-3);
    let mut scratch = StiffScratch::new();
    let mut times = Vec::new();
    for k in 0..steps {
        let t0 = Instant::now();
        step_rod_stiff(&mut r, &s, &st, &mut scratch, k as f64 * 1e-3, 0, k, 1).unwrap();
        times.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    let stiff = summary(&mut times);
    let it = scratch.report().total_iterations as f64 / steps as f64;
    let fac = scratch.report().factorisations as f64 / steps as f64;
    println!("factorisations per step {fac:.3}");
    println!(
        "{}: explicit median {:.1} min {:.1} mean {:.1} us; stiff median {:.1} min {:.1} mean {:.1} us ({it:.2} it/step); ratio of means {:.2}",
        std::any::type_name::<T>(),
        explicit.0,
        explicit.1,
        explicit.2,
        stiff.0,
        stiff.1,
        stiff.2,
        stiff.2 / explicit.2
    );
}

/// Median, minimum and mean of per-step times.
fn summary(t: &mut [f64]) -> (f64, f64, f64) {
    let mean = t.iter().sum::<f64>() / t.len() as f64;
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[0], mean)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2000);
    match args.get(1).map(String::as_str) {
        Some("f32") => run::<f32>(steps),
        Some("f64") => run::<f64>(steps),
        _ => {
            run::<f32>(steps);
            run::<f64>(steps);
        }
    }
}
