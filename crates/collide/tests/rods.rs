//! Rod–rod and self-collision: against brute force, and on known configurations.

use cosserat_collide::rods::closest_points_segments;
use cosserat_collide::{BroadPhase, Chain, RodCollider, RodCollisionConfig, RodContact};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn line(n: usize, start: [f64; 3], step: [f64; 3]) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            [
                start[0] + i as f64 * step[0],
                start[1] + i as f64 * step[1],
                start[2] + i as f64 * step[2],
            ]
        })
        .collect()
}

#[test]
fn crossing_rods_touch_at_the_crossing() {
    let a = line(21, [-1.0, 0.0, 0.0], [0.1, 0.0, 0.0]);
    let b = line(21, [0.05, -1.0, 0.015], [0.0, 0.1, 0.0]);
    let chains = [
        Chain {
            points: &a,
            radius: 0.01,
        },
        Chain {
            points: &b,
            radius: 0.01,
        },
    ];
    let mut rc = RodCollider::new(RodCollisionConfig::default());
    let mut out = Vec::new();
    rc.detect(&chains, &mut out);
    // Only the segments at the crossing: a's segment 10 (x from 0 to 0.1), b's segments 9 and 10
    // share the point y = 0.
    assert!(!out.is_empty());
    for c in &out {
        assert_eq!((c.chain_a, c.chain_b), (0, 1));
        assert_eq!(c.segment_a, 10);
        assert!((c.distance - 0.015).abs() < 1e-12, "{c:?}");
        assert!((c.penetration - 0.005).abs() < 1e-12);
        // a is below b: push a down.
        assert!((c.normal[2] + 1.0).abs() < 1e-12);
        assert!((c.s - 0.5).abs() < 1e-12);
    }
    // Moved apart: nothing.
    let b2 = line(21, [0.05, -1.0, 0.03], [0.0, 0.1, 0.0]);
    rc.detect(
        &[
            chains[0],
            Chain {
                points: &b2,
                radius: 0.01,
            },
        ],
        &mut out,
    );
    assert!(out.is_empty());
}

#[test]
fn crossing_between_points_is_found_by_segments() {
    // Two long segments crossing in the middle: all four end points are far apart, which a
    // point-sphere narrow phase would miss.
    let a = [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    let b = [[0.0, -1.0, 0.001], [0.0, 1.0, 0.001]];
    let mut rc = RodCollider::new(RodCollisionConfig::default());
    let mut out = Vec::new();
    rc.detect(
        &[
            Chain {
                points: &a,
                radius: 0.01,
            },
            Chain {
                points: &b,
                radius: 0.01,
            },
        ],
        &mut out,
    );
    assert_eq!(out.len(), 1);
    assert!((out[0].s - 0.5).abs() < 1e-12 && (out[0].t - 0.5).abs() < 1e-12);
}

#[test]
fn straight_and_gently_curved_chains_do_not_self_collide() {
    let mut rc = RodCollider::new(RodCollisionConfig::default());
    let mut out = Vec::new();
    // Spacing equal to the radius: the auto skip must hide neighbours within 2 radii.
    let r = 0.001;
    let straight = line(200, [0.0; 3], [r, 0.0, 0.0]);
    rc.detect(
        &[Chain {
            points: &straight,
            radius: r,
        }],
        &mut out,
    );
    assert!(out.is_empty(), "{:?}", out.first());
    assert_eq!(
        rc.self_skip_for(&Chain {
            points: &straight,
            radius: r
        }),
        3
    );
    let arc: Vec<[f64; 3]> = (0..200)
        .map(|i| {
            let th = i as f64 * 0.01;
            [th.cos(), th.sin(), 0.0]
        })
        .collect();
    rc.detect(
        &[Chain {
            points: &arc,
            radius: 0.004,
        }],
        &mut out,
    );
    assert!(out.is_empty(), "{:?}", out.first());
}

#[test]
fn tight_loop_self_collides_unless_disabled() {
    // A helix with pitch below the diameter: turns touch each other.
    let r = 0.01;
    let pts: Vec<[f64; 3]> = (0..300)
        .map(|i| {
            let th = i as f64 * 0.1;
            [
                0.2 * th.cos(),
                0.2 * th.sin(),
                0.015 * th / (2.0 * std::f64::consts::PI),
            ]
        })
        .collect();
    let mut rc = RodCollider::new(RodCollisionConfig::default());
    let mut out = Vec::new();
    rc.detect(
        &[Chain {
            points: &pts,
            radius: r,
        }],
        &mut out,
    );
    assert!(!out.is_empty());
    for c in &out {
        assert_eq!((c.chain_a, c.chain_b), (0, 0));
        assert!(c.segment_b > c.segment_a + 1);
        // Turns are ~63 segments apart.
        assert!((c.segment_b - c.segment_a) > 50, "{c:?}");
        assert!((c.distance - 0.015).abs() < 2e-3, "{c:?}");
    }
    let mut rc = RodCollider::new(RodCollisionConfig {
        self_collisions: false,
        ..Default::default()
    });
    rc.detect(
        &[Chain {
            points: &pts,
            radius: r,
        }],
        &mut out,
    );
    assert!(out.is_empty());
}

#[test]
fn degenerate_chains_do_not_panic() {
    let one = [[0.0, 0.0, 0.0]];
    let dup = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
    let empty: [[f64; 3]; 0] = [];
    let mut rc = RodCollider::new(RodCollisionConfig {
        segments_per_sphere: 0,
        ..Default::default()
    });
    let mut out = Vec::new();
    rc.detect(
        &[
            Chain {
                points: &one,
                radius: 0.1,
            },
            Chain {
                points: &dup,
                radius: 0.1,
            },
            Chain {
                points: &empty,
                radius: 0.1,
            },
        ],
        &mut out,
    );
    // The point and the collapsed chain coincide: contacts with a unit normal.
    assert!(!out.is_empty());
    for c in &out {
        let n = (c.normal[0].powi(2) + c.normal[1].powi(2) + c.normal[2].powi(2)).sqrt();
        assert!((n - 1.0).abs() < 1e-12);
    }
    let (s, t, _, _) =
        closest_points_segments([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]);
    assert!(s.is_finite() && t.is_finite());
}

/// Brute force: every segment pair, same rules.
fn brute(chains: &[Chain<'_>], rc: &RodCollider) -> Vec<(u32, u32, u32, u32, u64)> {
    let mut out = Vec::new();
    let seg = |c: &Chain<'_>, i: usize| {
        if c.points.len() == 1 {
            (c.points[0], c.points[0])
        } else {
            (c.points[i], c.points[i + 1])
        }
    };
    let nseg = |c: &Chain<'_>| c.points.len().saturating_sub(1).max(c.points.len().min(1));
    for a in 0..chains.len() {
        for b in a..chains.len() {
            let skip = rc.self_skip_for(&chains[a]);
            for i in 0..nseg(&chains[a]) {
                for j in 0..nseg(&chains[b]) {
                    if a == b && j <= i + skip {
                        continue;
                    }
                    let (p1, q1) = seg(&chains[a], i);
                    let (p2, q2) = seg(&chains[b], j);
                    let (_, _, c1, c2) = closest_points_segments(p1, q1, p2, q2);
                    let d = ((c1[0] - c2[0]).powi(2)
                        + (c1[1] - c2[1]).powi(2)
                        + (c1[2] - c2[2]).powi(2))
                    .sqrt();
                    if d < chains[a].radius + chains[b].radius {
                        out.push((
                            a as u32,
                            i as u32,
                            b as u32,
                            j as u32,
                            (d * 1e9).round() as u64,
                        ));
                    }
                }
            }
        }
    }
    out.sort_unstable();
    out
}

fn key(c: &RodContact) -> (u32, u32, u32, u32, u64) {
    (
        c.chain_a,
        c.segment_a,
        c.chain_b,
        c.segment_b,
        (c.distance * 1e9).round() as u64,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, rng_seed: RngSeed::Fixed(0x0520D5), failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn broad_phases_match_brute_force(seed in any::<u64>(), k in 1usize..9, all_pairs in any::<bool>(), skip in prop::option::of(1usize..4)) {
        let mut rng = StdRng::seed_from_u64(seed);
        let nchains = rng.random_range(1..4);
        let data: Vec<Vec<[f64; 3]>> = (0..nchains)
            .map(|_| {
                // Random walks in a small box so that chains cross themselves and each other.
                let mut p = [rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2)];
                (0..rng.random_range(1..60))
                    .map(|_| {
                        for x in &mut p {
                            *x += rng.random_range(-0.05..0.05);
                        }
                        p
                    })
                    .collect()
            })
            .collect();
        let chains: Vec<Chain<'_>> = data.iter().map(|d| Chain { points: d, radius: rng.random_range(0.005..0.03) }).collect();
        let config = RodCollisionConfig {
            segments_per_sphere: k,
            self_skip: skip,
            broad_phase: if all_pairs { BroadPhase::AllPairs } else { BroadPhase::SweepAndPrune },
            ..RodCollisionConfig::default()
        };
        let mut rc = RodCollider::new(config);
        let mut out = Vec::new();
        rc.detect(&chains, &mut out);
        let mut got: Vec<_> = out.iter().map(key).collect();
        got.sort_unstable();
        prop_assert_eq!(got, brute(&chains, &rc));
        for c in &out {
            prop_assert!(c.penetration > 0.0 && (0.0..=1.0).contains(&c.s) && (0.0..=1.0).contains(&c.t));
        }
    }
}
