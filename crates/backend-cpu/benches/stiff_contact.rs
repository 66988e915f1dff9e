//! The stiff scheme with mesh contacts: a soft wire (E 5 MPa, r 0.4 mm, 80 elements over
//! 0.2 m) pushed at 0.2 m/s into the procedural vessel at dt 1 ms, its tip pressed and sliding
//! along the curved wall with friction 0.08 / 0.05. Both variants replay the same 100 steps
//! from the state after 0.2 s of pushing: with the contact queries of touching points reused
//! between iterations (`StiffSettings::reuse_contact_queries`, the default) and with every
//! point queried after every iteration. The two must end in the same state bit for bit; the
//! bench prints the largest position difference (its error figure) and the contacts.
//!
//! `cargo bench -p cosserat-backend-cpu --bench stiff_contact`; results in
//! `docs/benchmarks/stiff-insertion.md`.

use cosserat_backend_cpu::{
    CpuRod, EndCondition, MeshContactSettings, Ordering, PrescribedMotion, SolverSettings,
    StiffScratch, StiffSettings, step_rod_stiff,
};
use cosserat_collide::{MeshCollider, Vessel};
use cosserat_constraints::Friction;
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Vec3};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use std::sync::Arc;

const DT: f64 = 1e-3;
/// Steps pushed before the measured window, and steps in it.
const WARM: u64 = 200;
const WINDOW: u64 = 100;

fn settings() -> SolverSettings<f64> {
    SolverSettings {
        dt: DT,
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible: false,
        gravity: Vec3::zeros(),
        divergence_strain: 0.05,
    }
}

fn pushed_wire() -> CpuRod<f64> {
    let vessel = Vessel::default_tree().unwrap();
    let collider = Arc::new(MeshCollider::new(vessel.mesh.clone()));
    let along = Vec3::from(vessel.entry_direction);
    let push = PrescribedMotion::push(along * 0.2);
    let spec = RodSpec::new(Material::new(5e6, 5e6 / 3.0, 1100.0, 4e-4));
    let pts = straight_polyline(vessel.entry_point, along.into(), 0.2, 80);
    let (state, params) = build_rod::<f64>(&pts, &spec).unwrap();
    let ends = [EndCondition::clamped().driven(push), EndCondition::free()];
    CpuRod::new(state, params, ends, vec![]).with_mesh(MeshContactSettings::mesh(
        collider,
        Friction {
            static_coefficient: 0.08,
            kinetic_coefficient: 0.05,
        },
        1e-4,
    ))
}

fn run(rod: &mut CpuRod<f64>, sc: &mut StiffScratch, stiff: &StiffSettings, from: u64, n: u64) {
    step_rod_stiff(rod, &settings(), stiff, sc, from as f64 * DT, 0, from, n).unwrap();
}

fn benches(c: &mut Criterion) {
    let mut start = pushed_wire();
    let mut start_scratch = StiffScratch::new();
    run(
        &mut start,
        &mut start_scratch,
        &StiffSettings::default(),
        0,
        WARM,
    );
    let variants = [("reused_queries", true), ("full_queries", false)];
    let mut ends = Vec::new();
    let mut group = c.benchmark_group(format!("stiff_contact_{WINDOW}_steps"));
    for (label, reuse) in variants {
        let stiff = StiffSettings {
            reuse_contact_queries: reuse,
            ..StiffSettings::default()
        };
        group.bench_function(label, |b| {
            b.iter_batched(
                || (start.clone(), start_scratch.clone()),
                |(mut rod, mut sc)| {
                    run(&mut rod, &mut sc, &stiff, WARM, WINDOW);
                    rod
                },
                BatchSize::LargeInput,
            )
        });
        let (mut rod, mut sc) = (start.clone(), start_scratch.clone());
        run(&mut rod, &mut sc, &stiff, WARM, WINDOW);
        ends.push(rod);
    }
    group.finish();
    let difference = ends[0]
        .state
        .positions
        .iter()
        .zip(&ends[1].state.positions)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    let stats = ends[0].collision_stats().unwrap();
    let before = start.collision_stats().unwrap().reused_queries;
    println!(
        "stiff_contact: largest position difference between the variants after {WINDOW} steps \
         {difference:e} m; {} points in contact at the end ({} at most since the start), {} \
         queries reused in the window",
        stats.contacts,
        stats.max_contacts,
        stats.reused_queries - before
    );
}

criterion_group!(stiff_contact, benches);
criterion_main!(stiff_contact);
