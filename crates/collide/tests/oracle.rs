//! The narrow phase against an independent oracle: parry3d-f64 (dev-dependency only).
//!
//! For random triangle soups, a generated vessel and random spheres, our contacts must be the
//! same triangles parry finds within the radius, with the same distances (1e-6 relative), and
//! the nearest-triangle query must match parry's point projection; on the closed, oriented vessel
//! the escaped/inside sign must match parry's pseudo-normal inside test.

use std::collections::BTreeMap;

use cosserat_collide::vessel::{VesselParams, generate};
use cosserat_collide::{Bvh, ContactBuffer, MeshCollider, TriMesh};
use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::math::Pose;
use parry3d_f64::math::Vector as PV;
use parry3d_f64::query::{PointQuery, Ray, RayCast, distance};
use parry3d_f64::shape::Segment;
use parry3d_f64::shape::{TriMesh as PMesh, TriMeshFlags};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        rng_seed: RngSeed::Fixed(0x00C0_5E11),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn to_parry(mesh: &TriMesh, flags: TriMeshFlags) -> PMesh {
    let v = mesh
        .vertices()
        .iter()
        .map(|p| PV::new(p.x, p.y, p.z))
        .collect();
    PMesh::with_flags(v, mesh.triangles().to_vec(), flags).expect("parry accepts the mesh")
}

/// parry's triangles within `r` of `p`: triangle → distance.
fn parry_within(pm: &PMesh, p: [f64; 3], r: f64) -> BTreeMap<u32, f64> {
    let q = PV::new(p[0], p[1], p[2]);
    let aabb = Aabb::new(q - PV::splat(r), q + PV::splat(r));
    let mut out = BTreeMap::new();
    for t in pm.bvh().intersect_aabb(&aabb) {
        let proj = pm.triangle(t).project_local_point(q, false);
        let d = proj.point.distance(q);
        if d < r {
            out.insert(t, d);
        }
    }
    out
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs()) + 1e-12
}

/// Compares one sphere query; triangles within 1e-9 of the radius are ignored on both sides.
fn compare(c: &MeshCollider, pm: &PMesh, p: [f64; 3], r: f64) -> Result<(), TestCaseError> {
    let mut buf = ContactBuffer::new();
    c.detect(&[p], r, &mut buf);
    let ours: BTreeMap<u32, f64> = buf
        .contacts()
        .iter()
        .map(|k| (k.triangle, k.distance))
        .collect();
    prop_assert_eq!(
        ours.len(),
        buf.contacts().len(),
        "a triangle reported twice"
    );
    let theirs = parry_within(pm, p, r);
    let edge = |d: f64| (d - r).abs() < 1e-9;
    for (t, d) in &theirs {
        if edge(*d) {
            continue;
        }
        let ours_d = ours.get(t).copied();
        prop_assert!(
            ours_d.is_some(),
            "missed triangle {} at distance {} (r = {})",
            t,
            d,
            r
        );
        let od = ours_d.unwrap_or(f64::NAN);
        prop_assert!(
            close(od, *d),
            "triangle {}: distance {} vs parry {}",
            t,
            od,
            d
        );
        prop_assert!(close(r - od, r - d), "penetration differs");
    }
    for (t, d) in &ours {
        prop_assert!(
            theirs.contains_key(t) || edge(*d),
            "extra triangle {} at {}",
            t,
            d
        );
    }
    for k in buf.contacts() {
        prop_assert!(close(k.depth, r - k.signed_distance));
        prop_assert!(k.signed_distance.abs() == k.distance);
        // The feature normal is a unit vector on the side of the signed distance, and
        // `p = closest + |d|·(p − closest)/|d|` with the sign agreeing with the normal.
        let n = nalgebra::Vector3::from(k.normal);
        prop_assert!((n.norm() - 1.0).abs() < 1e-12);
        let diff = nalgebra::Vector3::from(p) - nalgebra::Vector3::from(k.closest);
        prop_assert!(close(diff.norm(), k.distance));
        prop_assert_eq!(diff.dot(&n) >= 0.0, k.signed_distance >= 0.0);
        // Inside the face, the feature normal is the face normal.
        let face = c.mesh().face_normal(k.triangle as usize);
        let along = diff.cross(&face).norm() <= 1e-9 * diff.norm().max(1e-300);
        if along && k.distance > 1e-9 {
            prop_assert!(close(n.dot(&face), 1.0));
        }
    }
    // Nearest triangle: same distance as parry's projection on the whole mesh.
    let q = PV::new(p[0], p[1], p[2]);
    let proj = pm.project_local_point(q, false);
    let near = c.nearest(&p, f64::INFINITY);
    prop_assert!(near.is_some());
    if let Some(near) = near {
        prop_assert!(
            close(near.distance, proj.point.distance(q)),
            "nearest {} vs parry {}",
            near.distance,
            proj.point.distance(q)
        );
    }
    Ok(())
}

fn soup(seed: u64) -> TriMesh {
    let mut rng = StdRng::seed_from_u64(seed);
    let n = rng.random_range(1..80);
    let mut v = Vec::new();
    let mut t = Vec::new();
    for i in 0..n {
        let c = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        let s: f64 = rng.random_range(0.05..0.8);
        for _ in 0..3 {
            v.push([
                c[0] + s * rng.random_range(-1.0..1.0),
                c[1] + s * rng.random_range(-1.0..1.0),
                c[2] + s * rng.random_range(-1.0..1.0),
            ]);
        }
        t.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    TriMesh::new(v, t, "soup").expect("random soup is valid").0
}

proptest! {
    #![proptest_config(config(40))]

    #[test]
    fn soup_contacts_match_parry(seed in any::<u64>(), leaf in 1usize..9) {
        let mesh = soup(seed);
        let bvh = Bvh::build_with_leaf_size(&mesh, leaf);
        prop_assert!(bvh.check_invariants(&mesh).is_ok());
        let pm = to_parry(&mesh, TriMeshFlags::empty());
        let c = MeshCollider::with_bvh(mesh, bvh);
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed);
        for _ in 0..30 {
            let p = [rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5)];
            let r = rng.random_range(0.001..0.6);
            compare(&c, &pm, p, r)?;
        }
    }
}

proptest! {
    #![proptest_config(config(12))]

    #[test]
    fn vessel_contacts_and_sign_match_parry(seed in any::<u64>()) {
        let params = VesselParams { target_triangles: 3000, ..VesselParams::default() };
        let v = generate(&params).expect("vessel");
        let c = MeshCollider::new(v.mesh.clone());
        // parry wants outward normals for its inside test: flip ours (which point into the lumen).
        let mut outward = v.mesh.clone();
        outward.flip_winding();
        let pm = to_parry(&outward, TriMeshFlags::ORIENTED);
        let mut rng = StdRng::seed_from_u64(seed);
        let mut lines = vec![&v.trunk];
        lines.extend(v.branches.iter());
        let (mut inside, mut outside) = (0, 0);
        for _ in 0..40 {
            let line = lines[rng.random_range(0..lines.len())];
            let (p, lr) = line.sample(rng.random_range(0.0..1.0));
            let dir = nalgebra::Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let dir = dir.try_normalize(1e-9).unwrap_or_else(nalgebra::Vector3::x);
            let q = nalgebra::Vector3::from(p) + dir * lr * rng.random_range(0.0..1.4);
            let q: [f64; 3] = q.into();
            let r = rng.random_range(0.0002..0.003);
            compare(&c, &pm, q, r)?;
            // Lumen side (positive) must be parry's inside of the flipped, outward mesh (skip points on the wall).
            let near = c.nearest(&q, f64::INFINITY).expect("non-empty mesh");
            if near.distance > 1e-9 {
                let proj = pm.project_local_point(PV::new(q[0], q[1], q[2]), true);
                prop_assert_eq!(near.signed_distance > 0.0, proj.is_inside, "sign differs at {:?}: {:?}", q, near);
                if proj.is_inside { inside += 1 } else { outside += 1 }
            }
        }
        prop_assert!(inside > 0 && outside > 0, "both sides must be exercised: {} {}", inside, outside);
    }
}

proptest! {
    #![proptest_config(config(12))]

    /// Swept tests: the first wall a segment meets is where parry's ray cast, limited to the
    /// segment, meets it; and a segment from the lumen crosses into the wall exactly when parry
    /// finds its end outside the closed vessel.
    #[test]
    fn segment_crossings_match_parry_ray_casts(seed in any::<u64>()) {
        let params = VesselParams { target_triangles: 3000, ..VesselParams::default() };
        let v = generate(&params).expect("vessel");
        let c = MeshCollider::new(v.mesh.clone());
        let pm = to_parry(&v.mesh, TriMeshFlags::empty());
        let mut rng = StdRng::seed_from_u64(seed);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..60 {
            let (p, lr) = v.trunk.sample(rng.random_range(0.05..0.95));
            let a = nalgebra::Vector3::from(p);
            let dir = nalgebra::Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let b = a + dir * lr * rng.random_range(0.2..3.0);
            let ours = c.first_intersection(&a.into(), &b.into());
            let ray = Ray::new(PV::new(a.x, a.y, a.z), PV::new(b.x - a.x, b.y - a.y, b.z - a.z));
            let theirs = pm.cast_local_ray(&ray, 1.0, false);
            match (ours, theirs) {
                (Some(o), Some(t)) => {
                    prop_assert!((o.fraction - t).abs() < 1e-9, "fraction {} vs parry {}", o.fraction, t);
                    hits += 1;
                }
                (None, None) => misses += 1,
                (o, t) => prop_assert!(false, "ours {:?}, parry {:?} for {:?} → {:?}", o, t, a, b),
            }
            // From the trunk's centreline the first wall met is entered from the lumen side.
            if let Some(o) = ours {
                let into = c.first_crossing(&a.into(), &b.into()).expect("a crossing into the wall");
                prop_assert_eq!(into.triangle, o.triangle);
            }
        }
        prop_assert!(hits > 0 && misses > 0, "both cases must be exercised: {} {}", hits, misses);
    }
}

proptest! {
    #![proptest_config(config(8))]

    /// The nearest triangle to a rod element and its distance, against parry3d-f64's
    /// segment–triangle distance taken over every triangle of the vessel: elements from the
    /// trunk's centreline in random directions, some clear of the wall, some near it, some
    /// through it.
    #[test]
    fn segment_distances_match_parry(seed in any::<u64>()) {
        let params = VesselParams { target_triangles: 2000, ..VesselParams::default() };
        let v = generate(&params).expect("vessel");
        let c = MeshCollider::new(v.mesh.clone());
        let pm = to_parry(&v.mesh, TriMeshFlags::empty());
        let mut rng = StdRng::seed_from_u64(seed);
        let (mut found, mut none) = (0, 0);
        for _ in 0..40 {
            let (p, lr) = v.trunk.sample(rng.random_range(0.05..0.95));
            let a = nalgebra::Vector3::from(p)
                + nalgebra::Vector3::new(rng.random_range(-0.8..0.8), rng.random_range(-0.8..0.8), rng.random_range(-0.8..0.8)) * lr;
            let dir = nalgebra::Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let b = a + dir * lr * rng.random_range(0.1..1.5);
            let reach = 0.3 * lr;
            let seg = Segment::new(PV::new(a.x, a.y, a.z), PV::new(b.x, b.y, b.z));
            let pose = Pose::IDENTITY;
            let theirs = (0..pm.num_triangles() as u32)
                .map(|t| distance(&pose, &seg, &pose, &pm.triangle(t)).unwrap().distance)
                .fold(f64::INFINITY, f64::min);
            match c.segment_nearest(&a.into(), &b.into(), reach) {
                Some(n) => {
                    prop_assert!((n.signed_distance.abs() - theirs).abs() < 1e-9 * lr, "ours {} parry {}", n.signed_distance, theirs);
                    // The reported point on the segment is that far from the reported point of the wall.
                    let at = a + (b - a) * n.fraction;
                    let d = (at - nalgebra::Vector3::from(n.closest)).norm();
                    prop_assert!((d - theirs).abs() < 1e-9 * lr, "{} vs {}", d, theirs);
                    found += 1;
                }
                None => {
                    prop_assert!(theirs >= reach * (1.0 - 1e-9), "parry finds {} within {}", theirs, reach);
                    none += 1;
                }
            }
        }
        prop_assert!(found > 0 && none > 0, "both cases must be exercised: {} {}", found, none);
    }
}
