//! Solid obstacles: closed meshes the rods stay outside of. A rope over a cylinder holds two
//! loads whose ratio is below the capstan ratio `e^{μθ}` and slips beyond it; a mesh file can be
//! made a solid; what cannot be one is refused by name.

use cosserat::cosserat_constraints::Friction;
use cosserat::cosserat_model::Material;
use cosserat::obstacles::Side;
use cosserat::{Environment, Obstacle, RodBuilder, SimulationBuilder, StateField};

const WRAP: f64 = 0.05 + 1e-3;

/// A weightless rope over the top half of a cylinder of radius 5 cm (axis y), hanging 10 cm on
/// each side, its ends pulled down by `light` and `heavy` newtons; friction `mu`; the explicit
/// scheme. `cylinder` is the meshed (closed, 0.1 m long) or the analytic (infinite) one.
/// Returns how far the heavy end went down in `seconds`.
fn capstan_slide(analytic: bool, light: f64, heavy: f64, mu: f64, seconds: f64) -> f64 {
    let hang = 0.1;
    let mut points = Vec::new();
    // Elements of 5 mm, 0.1 rad of the wrap each (with 2.5 mm the rope holds and slides at the
    // same ratios).
    let step = 5e-3;
    let straight = (hang / step) as usize;
    for k in 0..straight {
        points.push([-WRAP, 0.0, -hang + k as f64 * step]);
    }
    let arc = (std::f64::consts::PI * WRAP / step).round() as usize;
    // Points a hair outside the wrap radius, so that the chords between them rest on the
    // cylinder rather than cut into it.
    let bulge = WRAP / (std::f64::consts::PI / arc as f64 / 2.0).cos();
    for k in 0..=arc {
        let phi = std::f64::consts::PI * k as f64 / arc as f64;
        points.push([-bulge * phi.cos(), 0.0, bulge * phi.sin()]);
    }
    for k in 1..=straight {
        points.push([WRAP, 0.0, -(k as f64) * step]);
    }
    let n = points.len() - 1;
    let material = Material::new(3e5, 1e5, 1000.0, 1e-3);
    let rod = RodBuilder::polyline(points, material)
        .damping(0.0, 0.0, 20.0)
        .load(0, [0.0, 0.0, -light])
        .load(n, [0.0, 0.0, -heavy]);
    let cylinder = if analytic {
        Obstacle::cylinder([0.0; 3], [0.0, 1.0, 0.0], 0.05, Side::Solid).unwrap()
    } else {
        let mut env = Environment::cylinder([0.0; 3], [0.0, 1.0, 0.0], 0.05, 0.1, 256).unwrap();
        env.friction = Friction {
            static_coefficient: mu,
            kinetic_coefficient: mu,
        };
        Obstacle::mesh(env)
    };
    let dt = 5e-5;
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(dt)
        .gravity([0.0; 3])
        .obstacle(cylinder.friction(mu, mu))
        .with_rod(rod)
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    let mut x = vec![[0.0; 3]; n + 1];
    sim.read(h, StateField::Positions, &mut x).unwrap();
    let start = x[n][2];
    sim.run((seconds / dt) as u64).unwrap();
    sim.read(h, StateField::Positions, &mut x).unwrap();
    let outside = sim.check_lumen().unwrap().count;
    assert_eq!(outside, 0, "{outside} points inside the cylinder");
    start - x[n][2]
}

/// The capstan equation: over half a turn with μ = 0.3 the rope holds a load ratio of
/// `e^{0.3π}` = 2.566 and no more: it holds 0.98 of it and slides at 1.02. (Before the points
/// between two ridge elements took the mean of both planes, `mesh_contact.rs`, it crept from
/// 0.9 of it at this resolution.) The same on the analytic infinite cylinder
/// (`[[obstacles]]`, `crate::obstacles`).
#[test]
fn a_rope_over_a_cylinder_holds_up_to_the_capstan_ratio() {
    let mu = 0.3;
    let ratio = (mu * std::f64::consts::PI).exp();
    let light = 0.02;
    for analytic in [false, true] {
        let held = capstan_slide(analytic, light, 0.9 * ratio * light, mu, 0.2);
        let slipped = capstan_slide(analytic, light, 1.1 * ratio * light, mu, 0.2);
        assert!(
            held < 1e-3,
            "analytic {analytic}: at 0.9 of the capstan ratio the rope slid {held} m"
        );
        assert!(
            slipped > 1e-2,
            "analytic {analytic}: at 1.1 of the capstan ratio the rope slid only {slipped} m"
        );
    }
}

/// A closed mesh becomes a solid with its normals turned out; a sheet cannot be one.
#[test]
fn a_solid_must_enclose_a_volume() {
    let floor = Environment::plane([0.0; 3], [0.0, 0.0, 1.0], 1.0).unwrap();
    let e = floor.into_solid().unwrap_err();
    assert!(e.contains("encloses no volume"), "{e}");
    let drum = Environment::cylinder([0.0; 3], [0.0, 0.0, 1.0], 0.1, 0.2, 64).unwrap();
    assert!(drum.solid);
    // Inside the drum is inside the solid; beside it is free space.
    let out = drum.outside(&[[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]], 1e-3);
    assert_eq!((out.count, out.deepest_point), (1, Some(0)));
    // A capsule's ends are inside it up to its radius beyond the cylinder's length.
    let pill = Environment::capsule([0.0; 3], [0.0, 0.0, 1.0], 0.1, 0.2, 64).unwrap();
    let out = pill.outside(
        &[[0.0, 0.0, 0.19], [0.0, 0.0, 0.21], [0.0, 0.0, -0.19]],
        1e-3,
    );
    assert_eq!(out.count, 2);
    assert!(
        (out.deepest - 0.011).abs() < 1e-3,
        "deepest {}",
        out.deepest
    );
}

/// A rope dropped across a sphere, a turned box and a capsule comes to rest on top of it, its
/// middle one rope radius above the top, no point inside.
#[test]
fn a_rope_rests_on_a_sphere_and_on_a_box() {
    let r = 1e-3;
    let cases = [
        (Environment::sphere([0.0; 3], 0.05, 64).unwrap(), 0.05),
        (
            Environment::cuboid([0.0; 3], [0.1, 0.1, 0.1], [0.0, 0.0, 0.3]).unwrap(),
            0.05,
        ),
        (
            Environment::capsule([0.0; 3], [0.0, 1.0, 0.0], 0.03, 0.1, 64).unwrap(),
            0.03,
        ),
    ];
    for (env, top) in cases {
        let n = 40;
        let material = Material::new(3e5, 1e5, 1000.0, r);
        let rod = RodBuilder::straight([-0.1, 0.0, top + 0.01], [1.0, 0.0, 0.0], 0.2, n, material)
            .damping(0.0, 0.0, 20.0);
        let mut sim = SimulationBuilder::new()
            .double_precision(true)
            .dt(5e-5)
            .gravity([0.0, 0.0, -9.81])
            .environment(env)
            .with_rod(rod)
            .build()
            .unwrap();
        let h = sim.rods().next().unwrap();
        sim.run(10_000).unwrap();
        let mut x = vec![[0.0; 3]; n + 1];
        sim.read(h, StateField::Positions, &mut x).unwrap();
        let rest = x[n / 2][2] - top;
        assert!(
            (rest - r).abs() < 0.2 * r,
            "the rope's middle rests {rest} m above the top (radius {r})"
        );
        let inside = sim.environment().unwrap().outside(&x, r).count;
        assert_eq!(inside, 0, "{inside} points inside the solid");
    }
}
