//! The inside test (generalised winding number) against independent answers: the analytic
//! inside of a sphere, parry's pseudo-normal inside test on the same closed mesh, the exact
//! sum over every triangle, and the centrelines of the generated vessel.

use cosserat_collide::vessel::{VesselParams, generate};
use cosserat_collide::{MeshCollider, TriMesh, WindingNumber};
use parry3d_f64::math::Vector as PV;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::{TriMesh as PMesh, TriMeshFlags};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A closed UV sphere of radius `r`, normals out.
fn sphere(r: f64, rings: usize, segments: usize) -> TriMesh {
    let mut v = vec![[0.0, 0.0, r]];
    for i in 1..rings {
        let th = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..segments {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / segments as f64;
            v.push([
                r * th.sin() * ph.cos(),
                r * th.sin() * ph.sin(),
                r * th.cos(),
            ]);
        }
    }
    v.push([0.0, 0.0, -r]);
    let south = (v.len() - 1) as u32;
    let at = |i: usize, j: usize| (1 + (i - 1) * segments + j % segments) as u32;
    let mut t = Vec::new();
    for j in 0..segments {
        t.push([0, at(1, j), at(1, j + 1)]);
        t.push([south, at(rings - 1, j + 1), at(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segments {
            t.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            t.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let (mesh, _) = TriMesh::new(v, t, "sphere").expect("a valid sphere");
    mesh
}

#[test]
fn a_closed_sphere_is_one_inside_and_zero_outside_as_parry_and_geometry_say() {
    let mesh = sphere(1.0, 24, 48);
    assert!(
        mesh.signed_volume() > 0.0,
        "the test sphere's normals point out"
    );
    let verts: Vec<PV> = mesh
        .vertices()
        .iter()
        .map(|p| PV::new(p.x, p.y, p.z))
        .collect();
    let parry = PMesh::with_flags(verts, mesh.triangles().to_vec(), TriMeshFlags::ORIENTED)
        .expect("parry accepts the sphere");
    // As a lumen, the sphere's inside is the side its normals point away from: flip it.
    let mut lumen_mesh = mesh.clone();
    lumen_mesh.flip_winding();
    let collider = MeshCollider::new(lumen_mesh);
    let mut rng = StdRng::seed_from_u64(7);
    let mut worst_far_field: f64 = 0.0;
    for _ in 0..400 {
        let p: [f64; 3] = [
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
        ];
        let radius = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        // The facets lie up to 1 - cos(π/24) ≈ 0.9 % inside the unit sphere.
        if (radius - 1.0).abs() < 0.02 {
            continue;
        }
        let w = collider.lumen_winding(&p);
        let exact = -WindingNumber::exact_outward(collider.mesh(), &p);
        worst_far_field = worst_far_field.max((w - exact).abs());
        let inside = radius < 1.0;
        assert_eq!(w > 0.5, inside, "p = {p:?}: w = {w}");
        assert!(
            (w - if inside { 1.0 } else { 0.0 }).abs() < 0.05,
            "p = {p:?}: w = {w}"
        );
        let q = PV::new(p[0], p[1], p[2]);
        assert_eq!(
            parry.contains_point(&Default::default(), q),
            inside,
            "parry at {p:?}"
        );
    }
    assert!(worst_far_field < 0.05, "far field off by {worst_far_field}");
}

#[test]
fn the_generated_vessel_is_inside_along_its_centrelines_and_outside_beyond_its_walls() {
    let vessel = generate(&VesselParams::default()).expect("the default vessel");
    let collider = MeshCollider::new(vessel.mesh.clone());
    let mut checked = 0;
    for line in std::iter::once(&vessel.trunk).chain(&vessel.branches) {
        // All along, up to a twentieth of the line from the open ends (the ends themselves lie
        // on the caps, where the winding number is not defined).
        for k in 1..=19 {
            let (p, r) = line.sample(k as f64 / 20.0);
            let w = collider.lumen_winding(&p);
            assert!(
                w > 0.75,
                "centreline point {p:?} (lumen radius {r}): w = {w}"
            );
            checked += 1;
        }
    }
    // Points far outside the whole tree.
    let (lo, hi) = vessel.mesh.bounds();
    for corner in 0..8 {
        let p: [f64; 3] = std::array::from_fn(|k| {
            let span = hi[k] - lo[k];
            if corner >> k & 1 == 0 {
                lo[k] - 0.5 * span
            } else {
                hi[k] + 0.5 * span
            }
        });
        let w = collider.lumen_winding(&p);
        assert!(w.abs() < 0.05, "far point {p:?}: w = {w}");
    }
    // Beside the trunk, two lumen radii off its axis, across the wall: outside.
    let (a, r) = vessel.trunk.sample(0.3);
    let (b, _) = vessel.trunk.sample(0.31);
    let axis: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
    let side = if axis[0].abs() < 0.9 * (axis[1].abs() + axis[2].abs()) {
        [0.0, axis[2], -axis[1]]
    } else {
        [axis[1], -axis[0], 0.0]
    };
    let n = (side[0] * side[0] + side[1] * side[1] + side[2] * side[2]).sqrt();
    let off: [f64; 3] = std::array::from_fn(|k| a[k] + 2.0 * r * side[k] / n);
    let w = collider.lumen_winding(&off);
    assert!(w < 0.5, "two radii beside the trunk at {off:?}: w = {w}");
    assert!(checked > 40);
    // Just inside the inlet, on its axis, and just outside it.
    let e = vessel.entry_point;
    let d = vessel.entry_direction;
    let inside: [f64; 3] = std::array::from_fn(|k| e[k] + 1e-3 * d[k]);
    let before: [f64; 3] = std::array::from_fn(|k| e[k] - 1e-3 * d[k]);
    let (wi, wb) = (
        collider.lumen_winding(&inside),
        collider.lumen_winding(&before),
    );
    assert!(wi > 0.9, "1 mm into the inlet: w = {wi}");
    assert!(wb < 0.1, "1 mm before the inlet: w = {wb}");
}

#[test]
fn a_vessel_and_a_sphere_enclose_a_volume_and_a_floor_does_not() {
    let vessel = generate(&VesselParams::default()).expect("the default vessel");
    assert!(MeshCollider::new(vessel.mesh).encloses_volume());
    assert!(MeshCollider::new(sphere(0.5, 12, 24)).encloses_volume());
    let floor = TriMesh::patch(
        [-1.0, -1.0, 0.0],
        [2.0, 0.0, 0.0],
        [0.0, 2.0, 0.0],
        8,
        "floor",
    )
    .expect("a floor");
    assert!(!MeshCollider::new(floor).encloses_volume());
}

#[test]
fn flipped_winding_flips_the_answer() {
    // The same sphere wound the other way reads the opposite everywhere (to the far field's
    // rounding, which sees the centroids summed in another order).
    let mesh = sphere(0.5, 12, 24);
    let outward = MeshCollider::new(mesh.clone());
    let mut flipped = mesh;
    flipped.flip_winding();
    let inward = MeshCollider::new(flipped);
    for p in [[0.0, 0.0, 0.0], [0.2, -0.1, 0.1], [2.0, 0.0, 0.0]] {
        let (a, b) = (outward.lumen_winding(&p), inward.lumen_winding(&p));
        assert!((a + b).abs() < 1e-3, "{p:?}: {a} and {b}");
        let inside = p[0].abs() < 0.5;
        assert!(
            (b - if inside { 1.0 } else { 0.0 }).abs() < 0.05,
            "{p:?}: {b}"
        );
    }
}
