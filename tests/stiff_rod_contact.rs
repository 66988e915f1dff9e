//! Rod–rod contact in the stiff scheme (`crates/backend-cpu/src/stiff/rod_contact.rs`) at a
//! haptic step (1 ms): two rods crossing at right angles, against force balance and
//! non-interpenetration. Small rods, fast in a debug build.

use cosserat::Simulation;
use cosserat::scene::parse_scene;
use std::path::Path;

/// Two cantilevers of 9 elements and 0.1 m crossing at right angles at their middles (the
/// crossing falls in the middle of an element of each), `r = 1 mm`, the `catheter-polymer`
/// preset's material: `beam` along x clamped at its start; `rod` along y, `z0` above it, with
/// the ends `rod_ends`; friction `mu` (static and kinetic). Built, not run.
fn crossing(z0: f64, rod_ends: &str, gravity: f64, mu: f64) -> Simulation {
    let text = format!(
        r#"
[solver]
scheme = "stiff"
dt = 1e-3
precision = "f64"
gravity = [0.0, 0.0, {gravity}]

[rod_contact]
self_collisions = false
friction = {{ static = {mu}, kinetic = {mu} }}
margin = 1e-4

[[rod]]
name = "beam"
elements = 9
shape = {{ kind = "straight", start = [-0.05, 0, 0], direction = [1, 0, 0], length = 0.1 }}
material = {{ preset = "catheter-polymer" }}
damping = {{ drag = 20.0 }}
start = {{ kind = "clamped" }}

[[rod]]
name = "rod"
elements = 9
shape = {{ kind = "straight", start = [0, -0.05, {z0}], direction = [0, 1, 0], length = 0.1 }}
material = {{ preset = "catheter-polymer" }}
damping = {{ drag = 20.0 }}
{rod_ends}
"#
    );
    let (builder, _, _) = parse_scene(Path::new("crossing.toml"), &text, &[]).unwrap();
    builder.build().unwrap()
}

type P = [f64; 3];

fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: P, b: P) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn at(a: P, d: P, s: f64) -> P {
    [a[0] + d[0] * s, a[1] + d[1] * s, a[2] + d[2] * s]
}

/// The closest points of segments `a0 a1` and `b0 b1`: minimise `|a(s) − b(t)|²` over the unit
/// square (the interior stationary point if it lies inside, else the best of the four edges,
/// each a clamped one-dimensional minimum).
fn closest(a0: P, a1: P, b0: P, b1: P) -> (P, P) {
    let (da, db, r) = (sub(a1, a0), sub(b1, b0), sub(a0, b0));
    let (aa, bb, ab, ar, br) = (
        dot(da, da),
        dot(db, db),
        dot(da, db),
        dot(da, r),
        dot(db, r),
    );
    let clamp = |x: f64| x.clamp(0.0, 1.0);
    let mut candidates = Vec::new();
    let det = aa * bb - ab * ab;
    if det > 1e-14 * aa * bb {
        candidates.push(((ab * br - bb * ar) / det, (aa * br - ab * ar) / det));
    }
    for s in [0.0, 1.0] {
        candidates.push((s, clamp((br + s * ab) / bb)));
    }
    for t in [0.0, 1.0] {
        candidates.push((clamp((t * ab - ar) / aa), t));
    }
    candidates
        .into_iter()
        .filter(|(s, t)| (0.0..=1.0).contains(s) && (0.0..=1.0).contains(t))
        .map(|(s, t)| (at(a0, da, s), at(b0, db, t)))
        .min_by(|x, y| {
            let d = |p: &(P, P)| dot(sub(p.0, p.1), sub(p.0, p.1));
            d(x).total_cmp(&d(y))
        })
        .unwrap()
}

/// The closest approach of the two rods' centrelines, and how far the `rod`'s closest point is
/// above the `beam`'s (negative once it has passed through).
fn approach(sim: &Simulation) -> (f64, f64) {
    let mut rods = sim.rods();
    let (beam, rod) = (
        sim.positions(rods.next().unwrap()),
        sim.positions(rods.next().unwrap()),
    );
    let mut best = (f64::INFINITY, 0.0);
    for a in beam.windows(2) {
        for b in rod.windows(2) {
            let (p, q) = closest(a[0], a[1], b[0], b[1]);
            let d = dot(sub(p, q), sub(p, q)).sqrt();
            if d < best.0 {
                best = (d, q[2] - p[2]);
            }
        }
    }
    best
}

const RADIUS: f64 = 1e-3;
const DENSITY: f64 = 1010.0;

/// The vertical force a rod's clamp holds, averaged over `steps` steps (the filtered reaction
/// read after each): the partitioned transfer of the contact force (a step late, relaxed)
/// leaves a small ripple at rest, a few per cent of the force, and a momentum balance holds on
/// average.
fn mean_clamp_forces(sim: &mut Simulation, steps: u64) -> [f64; 2] {
    let handles: Vec<_> = sim.rods().collect();
    let mut sum = [0.0; 2];
    for _ in 0..steps {
        sim.run(1).unwrap();
        for (s, &h) in sum.iter_mut().zip(&handles) {
            *s += sim.end_reaction(h, 0).map_or(0.0, |r| r.force[2]) / steps as f64;
        }
    }
    sum
}

/// A free rod dropped across a cantilever comes to rest on it, its weight carried through the
/// contact: the cantilever's clamp holds the weight of both rods (within 1 %, averaged over the
/// last 0.3 s), the rod rests one summed radius above the beam, and no step brought the two
/// closer than 99 % of it. Frictionless, so that nothing but the contact's normal force holds
/// the rod up.
#[test]
fn a_rod_lying_across_another_is_carried_by_it() {
    let g = 9.81;
    let mut sim = crossing(2.0 * RADIUS + 5e-4, "", -g, 0.0);
    sim.run(700).unwrap();
    let [held, _] = mean_clamp_forces(&mut sim, 300);
    let stats = sim.coupling_stats().unwrap();
    assert!(
        stats.min_separation_ratio >= 0.99,
        "closest approach {} of the summed radii",
        stats.min_separation_ratio
    );
    let (distance, above) = approach(&sim);
    assert!(
        (distance - 2.0 * RADIUS).abs() < 0.01 * 2.0 * RADIUS && above > 0.0,
        "the rod rests {distance} m from the beam ({above} m above it)"
    );
    let mass = 2.0 * DENSITY * std::f64::consts::PI * RADIUS * RADIUS * 0.1;
    assert!(
        (held.abs() - mass * g).abs() < 0.01 * mass * g,
        "the beam's clamp holds {held} N, the two rods weigh {} N",
        mass * g
    );
}

/// A second cantilever, its clamp driven down at 2 m/s (the summed radii, 2 mm, in every step)
/// for 5 ms, meets the beam after a 2 mm fall and pushes on for 8 mm, bending both; then held.
/// With friction (0.3) and without, the rod never passes the beam: its centreline stays above
/// the beam's by 99 % of the summed radii after every step, not only at the end. Without
/// friction, once both are at rest, the force the rod's clamp pushes with is the force the
/// beam's clamp resists with (within 1 %, averaged over the last 0.2 s): action and reaction
/// through the contact.
#[test]
fn a_rod_driven_through_another_pushes_it_instead() {
    let ends = "start = { kind = \"clamped\", velocity = [0.0, 0.0, -2.0], end_time = 0.005 }";
    for mu in [0.3, 0.0] {
        let mut lowest: f64 = f64::INFINITY;
        let mut sim = crossing(2.0 * RADIUS + 2e-3, ends, 0.0, mu);
        for _ in 0..400 {
            sim.run(1).unwrap();
            let (distance, above) = approach(&sim);
            lowest = lowest.min(if above > 0.0 { distance } else { -distance });
        }
        assert!(
            lowest >= 0.99 * 2.0 * RADIUS,
            "friction {mu}: the rod came within {lowest} m of the beam (summed radii {} m)",
            2.0 * RADIUS
        );
        let stats = sim.coupling_stats().unwrap();
        assert!(stats.min_separation_ratio >= 0.99, "{stats:?}");
        if mu > 0.0 {
            continue;
        }
        let [on_beam, on_rod] = mean_clamp_forces(&mut sim, 200);
        // The beam was bent: a real force, not a graze.
        assert!(on_beam.abs() > 1e-2, "beam clamp {on_beam} N");
        assert!(
            (on_beam + on_rod).abs() < 0.01 * on_beam.abs(),
            "beam clamp {on_beam} N, rod clamp {on_rod} N"
        );
    }
}
