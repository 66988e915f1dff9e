//! "A scene pays only for what it uses" (issue 5): the free-space step with and without the
//! collision code in play.
//!
//! The same 512-element pendulum as `benches/step.rs` (f32, serial, 10 red–black sweeps, dt =
//! 2e-5 s, gravity), built three ways in one run:
//! - `no-environment`: the simulation has no mesh at all;
//! - `collides-false`: the simulation has the default procedural vessel (~26 000 triangles) but
//!   the rod is built with `RodBuilder::collides(false)`, so it carries no mesh contact;
//! - `far-away`: the rod collides with the vessel but swings more than 1 m away from every triangle, so
//!   detection runs every step and finds nothing (each point's clearance from the mesh's bounding
//!   box keeps it from querying the tree).
//!
//! The rod hangs at the same place in all three, so the physics is the same.
//!
//! Each is measured as one `Simulation::step` and per step inside `Simulation::run(100)`.
//! `cargo xtask bench` reads the medians and writes the ratios to
//! `docs/benchmarks/insertion.md`.

use cosserat::{Backend, Environment, Material, RodBuilder, Simulation, SimulationBuilder};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;

const ELEMENTS: usize = 512;

/// The three ways of building the pendulum, by the name criterion stores them under.
const CASES: [&str; 3] = ["no-environment", "collides-false", "far-away"];

fn pendulum(case: &str, vessel: &Environment) -> Simulation {
    let material = Material::new(1.0e6, 1.0e6 / 3.0, 1100.0, 0.005);
    // The same place in all three cases: 2 m beyond the far corner of the vessel's bounding
    // box, so the 1 m rod never comes within 1 m of a triangle.
    let (_, max) = vessel.collider.mesh().bounds();
    let start = [max.x + 2.0, max.y + 2.0, max.z + 2.0];
    let rod = RodBuilder::straight(start, [1.0, 0.0, 0.0], 1.0, ELEMENTS, material)
        .pin_start()
        .collides(case != "collides-false");
    let mut b = SimulationBuilder::new()
        .dt(2e-5)
        .iterations(10)
        .double_precision(false)
        .backend(Backend::Cpu)
        .gravity([0.0, 0.0, -9.81])
        .with_rod(rod);
    if case != "no-environment" {
        b = b.environment(vessel.clone());
    }
    let mut sim = b.build().expect("valid pendulum");
    // Start from a swinging state rather than the exactly straight initial one.
    sim.run(200).expect("stable");
    // The case is what it says: detection runs only for `far-away`, and finds nothing.
    match (case, sim.contact_report()) {
        ("no-environment", None) => {}
        ("collides-false", Some(c)) => assert_eq!(c.detection_us_per_step, 0.0),
        ("far-away", Some(c)) => {
            assert!(c.detection_us_per_step > 0.0, "detection did not run");
            assert_eq!(c.contacts, 0);
        }
        (case, report) => panic!("{case}: unexpected contact report {report:?}"),
    }
    sim
}

fn free_space(c: &mut Criterion) {
    let vessel = Environment::vessel(26_000).expect("the default vessel");
    let mut g = c.benchmark_group("free_space");
    g.warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4))
        .sample_size(40);
    for case in CASES {
        let mut sim = pendulum(case, &vessel);
        g.bench_function(BenchmarkId::new("single", case), |b| {
            b.iter(|| black_box(sim.step()).expect("stable"))
        });
        let mut sim = pendulum(case, &vessel);
        g.bench_function(BenchmarkId::new("batch100", case), |b| {
            b.iter(|| black_box(sim.run(100)).expect("stable"))
        });
    }
    g.finish();
}

criterion_group!(benches, free_space);
criterion_main!(benches);
