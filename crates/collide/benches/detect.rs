//! Collision detection benchmarks (serial, CPU).
//!
//! * `detect/N`: N rod points of radius 0.5 mm spread along the trunk centreline of the default
//!   ~26k-triangle vessel, every 16th point pushed to 0.3 mm from the wall so contacts exist; one
//!   batch `MeshCollider::detect` call (the paper's Fig. 11 measures 512 points: 1.17 ms on CPU).
//! * `build/tree`: building the AABB tree and query data of the default vessel.
//! * `winding/N`: the inside test (`MeshCollider::lumen_winding`) of the same N points, as a
//!   simulation runs it after every batch of steps.
//! * `rods/{all_pairs,sweep}/N`: self-collision of one N-point coiled chain, both broad phases.

use std::hint::black_box;

use cosserat_collide::{
    BroadPhase, Chain, ContactBuffer, MeshCollider, RodCollider, RodCollisionConfig, Vessel,
};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;

const ROD_RADIUS: f64 = 0.0005;

fn trunk_points(v: &Vessel, n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let u = 0.02 + 0.96 * i as f64 / (n - 1) as f64;
            let (p, r) = v.trunk.sample(u);
            if i % 16 == 5 {
                // Near the wall: along a direction perpendicular to the local tangent.
                let (a, _) = v.trunk.sample(u - 0.005);
                let (b, _) = v.trunk.sample(u + 0.005);
                let t = (Vector3::from(b) - Vector3::from(a)).normalize();
                let side = t.cross(&Vector3::y()).normalize();
                (Vector3::from(p) + side * (r - 0.0003)).into()
            } else {
                p
            }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let vessel = Vessel::default_tree().expect("default vessel");
    let collider = MeshCollider::new(vessel.mesh.clone());
    let mut group = c.benchmark_group("detect");
    for n in [128usize, 256, 512, 1024, 2048, 3072] {
        let pts = trunk_points(&vessel, n);
        let mut buf = ContactBuffer::new();
        collider.detect(&pts, ROD_RADIUS, &mut buf);
        assert!(buf.points_in_contact() > 0);
        group.bench_with_input(BenchmarkId::from_parameter(n), &pts, |b, pts| {
            b.iter(|| {
                collider.detect(black_box(pts), ROD_RADIUS, &mut buf);
                black_box(buf.contacts().len())
            })
        });
    }
    group.finish();

    let mut group = c.benchmark_group("winding");
    for n in [128usize, 512] {
        let pts = trunk_points(&vessel, n);
        assert!(pts.iter().all(|p| collider.lumen_winding(p) > 0.5));
        group.bench_with_input(BenchmarkId::from_parameter(n), &pts, |b, pts| {
            b.iter(|| {
                black_box(pts)
                    .iter()
                    .filter(|p| collider.lumen_winding(p) < 0.5)
                    .count()
            })
        });
    }
    group.finish();

    c.bench_function("build/tree", |b| {
        b.iter(|| MeshCollider::new(black_box(vessel.mesh.clone())))
    });

    let mut group = c.benchmark_group("rods");
    for n in [512usize, 3072] {
        // A coil whose turns touch: realistic contact counts for a knot-like configuration.
        let pts: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let th = i as f64 * 0.05;
                [
                    0.02 * th.cos(),
                    0.02 * th.sin(),
                    0.0009 * th / std::f64::consts::TAU,
                ]
            })
            .collect();
        for (name, bp) in [
            ("all_pairs", BroadPhase::AllPairs),
            ("sweep", BroadPhase::SweepAndPrune),
        ] {
            let mut rc = RodCollider::new(RodCollisionConfig {
                broad_phase: bp,
                ..Default::default()
            });
            let mut out = Vec::new();
            let chains = [Chain {
                points: &pts,
                radius: ROD_RADIUS,
            }];
            rc.detect(&chains, &mut out);
            assert!(!out.is_empty());
            group.bench_with_input(BenchmarkId::new(name, n), &chains, |b, chains| {
                b.iter(|| {
                    rc.detect(black_box(chains), &mut out);
                    black_box(out.len())
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
