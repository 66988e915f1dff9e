//! The procedural vessel: valid mesh, size, orientation, inside/outside behaviour.

use cosserat_collide::vessel::{Centreline, VesselParams, generate};
use cosserat_collide::{Bvh, ContactBuffer, MeshCollider, Vessel};

fn default_vessel() -> (Vessel, MeshCollider) {
    let v = Vessel::default_tree().expect("default vessel must generate");
    let c = MeshCollider::new(v.mesh.clone());
    (v, c)
}

/// Unit vector perpendicular to the centreline tangent at fraction `u`, rotated by `phi`.
fn perp(line: &Centreline, u: f64, phi: f64) -> [f64; 3] {
    let (a, _) = line.sample((u - 0.01).max(0.0));
    let (b, _) = line.sample((u + 0.01).min(1.0));
    let t = nalgebra::Vector3::from(b) - nalgebra::Vector3::from(a);
    let t = t.normalize();
    let trial = if t.x.abs() < 0.9 {
        nalgebra::Vector3::x()
    } else {
        nalgebra::Vector3::y()
    };
    let n = t.cross(&trial).normalize();
    let bn = t.cross(&n);
    (n * phi.cos() + bn * phi.sin()).into()
}

#[test]
fn default_vessel_is_valid_and_paper_sized() {
    let (v, c) = default_vessel();
    let n = v.mesh.triangles().len();
    println!("default vessel: {n} triangles, report {:?}", v.report);
    assert!(
        (23_400..=28_600).contains(&n),
        "triangle count {n} not within 10% of 26000"
    );
    assert_eq!(v.report.degenerate_dropped, 0);
    assert_eq!(v.report.duplicates_dropped, 0);
    assert_eq!(v.report.misoriented_edges, 0, "winding must be consistent");
    // Boundary edges only at the open ends: trunk inlet + outlet + one per branch end.
    let nt_trunk_ring = v.report.boundary_edges;
    assert!(nt_trunk_ring > 0 && nt_trunk_ring < 300, "{nt_trunk_ring}");
    c.bvh().check_invariants(&v.mesh).unwrap();
    // Normals point into the lumen: negative signed volume.
    assert!(v.mesh.signed_volume() < 0.0);
    // Entry at the trunk start, pointing along the trunk.
    assert_eq!(v.entry_point, v.trunk.points[0]);
    let d = nalgebra::Vector3::from(v.entry_direction);
    assert!((d.norm() - 1.0).abs() < 1e-12);
    let ahead = nalgebra::Vector3::from(v.trunk.points[5]) - nalgebra::Vector3::from(v.entry_point);
    assert!(d.dot(&ahead.normalize()) > 0.99);
}

#[test]
fn generation_is_deterministic() {
    let a = generate(&VesselParams::default()).unwrap();
    let b = generate(&VesselParams::default()).unwrap();
    assert_eq!(a.mesh.vertices(), b.mesh.vertices());
    assert_eq!(a.mesh.triangles(), b.mesh.triangles());
}

#[test]
fn target_triangle_count_is_followed() {
    for target in [4_000usize, 12_000] {
        let p = VesselParams {
            target_triangles: target,
            ..VesselParams::default()
        };
        let v = generate(&p).unwrap();
        let n = v.mesh.triangles().len() as f64;
        assert!(
            (n / target as f64 - 1.0).abs() < 0.12,
            "target {target}, got {n}"
        );
        assert_eq!(v.report.misoriented_edges, 0);
        Bvh::build(&v.mesh).check_invariants(&v.mesh).unwrap();
    }
}

#[test]
fn centreline_points_are_inside_without_contacts() {
    let (v, c) = default_vessel();
    let mut lines = vec![&v.trunk];
    lines.extend(v.branches.iter());
    let mut pts = Vec::new();
    for line in lines {
        for k in 1..200 {
            pts.push(line.sample(k as f64 / 200.0).0);
        }
    }
    let mut buf = ContactBuffer::new();
    c.detect(&pts, 0.0005, &mut buf);
    assert_eq!(buf.contacts().len(), 0, "centreline points touch the wall");
    for p in &pts {
        let near = c.nearest(p, f64::INFINITY).unwrap();
        assert!(
            near.signed_distance > 0.0,
            "centreline point {p:?} classified outside: {near:?}"
        );
    }
}

#[test]
fn lumen_points_near_junctions_are_not_escaped() {
    let (v, c) = default_vessel();
    let mut buf = ContactBuffer::new();
    let mut checked = 0;
    for b in &v.branches {
        // From the trunk axis to a few branch radii out along the branch, off-axis too.
        for k in 0..40 {
            let u = k as f64 / 40.0 * 0.4;
            let (p, r) = b.sample(u);
            for j in 0..8 {
                let n = perp(b, u.max(0.02), j as f64 * std::f64::consts::PI / 4.0);
                let q = [
                    p[0] + 0.5 * r * n[0],
                    p[1] + 0.5 * r * n[1],
                    p[2] + 0.5 * r * n[2],
                ];
                let near = c.nearest(&q, f64::INFINITY).unwrap();
                assert!(
                    near.signed_distance > 0.0,
                    "lumen point {q:?} near a junction classified escaped: {near:?}"
                );
                c.detect(&[q], 0.0005, &mut buf);
                assert!(!buf.responses()[0].escaped);
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 4 * 40 * 8);
}

#[test]
fn points_past_the_wall_are_detected() {
    let (v, c) = default_vessel();
    let rod_r = 0.0005;
    let mut buf = ContactBuffer::new();
    let junctions: Vec<f64> = VesselParams::default()
        .branches
        .iter()
        .map(|b| b.at)
        .collect();
    let mut tested = 0;
    for k in 1..20 {
        let u = k as f64 / 20.0;
        // Away from the junction holes (the wall is not there).
        if junctions.iter().any(|a| (a - u).abs() < 0.04) {
            continue;
        }
        let (p, r) = v.trunk.sample(u);
        for j in 0..6 {
            let phi = j as f64 * std::f64::consts::PI / 3.0 + 0.1;
            let n = perp(&v.trunk, u, phi);
            let at = |s: f64| [p[0] + s * n[0], p[1] + s * n[1], p[2] + s * n[2]];
            // Touching from inside: centre 0.3 mm inside the nominal wall.
            let inside = at(r - 0.0003);
            // Poked through: centre 0.2 mm beyond the wall.
            let through = at(r + 0.0002);
            // Far outside: 5 mm beyond the wall.
            let far = at(r + 0.005);
            c.detect(&[inside, through, far], rod_r, &mut buf);
            let [ri, rt, rf] = [buf.responses()[0], buf.responses()[1], buf.responses()[2]];
            assert!(ri.count > 0 && !ri.escaped, "u={u} j={j}: {ri:?}");
            assert!(ri.depth > 0.0 && ri.depth < rod_r);
            let dir = nalgebra::Vector3::from(ri.direction);
            assert!(
                dir.dot(&nalgebra::Vector3::from(n)) < -0.9,
                "response must point inward"
            );
            assert!(rt.count > 0 && rt.escaped, "u={u} j={j}: {rt:?}");
            assert!(rt.depth > rod_r);
            assert_eq!(rf.count, 0);
            let near = c.nearest(&far, 0.01).unwrap();
            assert!(near.signed_distance < 0.0);
            tested += 1;
        }
    }
    assert!(tested >= 60, "{tested}");
}

#[test]
fn bad_parameters_are_errors() {
    let p = VesselParams {
        trunk_length: f64::NAN,
        ..VesselParams::default()
    };
    assert!(generate(&p).is_err());
    let mut p = VesselParams::default();
    p.branches[0].radius_start = 0.05; // far wider than the trunk
    assert!(generate(&p).is_err());
    let mut p = VesselParams::default();
    p.branches[1].at = 0.22; // same place as branch 0
    p.branches[1].azimuth = 0.0;
    assert!(generate(&p).is_err());
}

/// A stenosis and an aneurysm change the trunk's radius where they are and nowhere else: the
/// wall's distance from the centreline at their centres is the radius times their factor.
#[test]
fn bulges_narrow_and_widen_the_trunk_where_they_are() {
    use cosserat_collide::{Bulge, MeshCollider};
    let plain = VesselParams {
        branches: Vec::new(),
        bow: 0.0,
        ..VesselParams::default()
    };
    let bulged = VesselParams {
        bulges: vec![
            Bulge {
                at: 0.3,
                length: 0.04,
                factor: 0.4,
            },
            Bulge {
                at: 0.7,
                length: 0.05,
                factor: 2.0,
            },
        ],
        ..plain.clone()
    };
    let (a, b) = (generate(&plain).unwrap(), generate(&bulged).unwrap());
    let (ca, cb) = (
        MeshCollider::new(a.mesh.clone()),
        MeshCollider::new(b.mesh.clone()),
    );
    for (u, factor) in [(0.3, 0.4), (0.7, 2.0), (0.5, 1.0), (0.1, 1.0)] {
        let (p, r) = a.trunk.sample(u);
        let wall_a = ca.nearest(&p, 1.0).unwrap().distance;
        let wall_b = cb.nearest(&p, 1.0).unwrap().distance;
        // The wall is faceted: within a few per cent of the radius.
        assert!(
            (wall_a - r).abs() < 0.03 * r,
            "u = {u}: plain wall at {wall_a}, radius {r}"
        );
        assert!(
            (wall_b - factor * r).abs() < 0.03 * factor * r,
            "u = {u}: wall at {wall_b}, expected {}",
            factor * r
        );
    }
}

/// Random vessels: every seed of a sample gives a valid tree (consistent winding, normals into
/// the lumen, open only at the inlet, the outlet and each branch's end), the same seed the same
/// mesh, and different seeds different anatomies; the centreline of every branch runs inside
/// its own lumen.
#[test]
fn random_vessels_are_valid_and_reproducible() {
    use cosserat_collide::vessel::generate_random;
    let mut shapes = std::collections::HashSet::new();
    for seed in 0..12u64 {
        let (v, p) = generate_random(seed, 6_000).expect("a valid draw");
        assert_eq!(v.report.misoriented_edges, 0, "seed {seed}");
        assert_eq!(v.report.degenerate_dropped, 0, "seed {seed}");
        assert!(
            v.mesh.signed_volume() < 0.0,
            "seed {seed}: normals into the lumen"
        );
        assert_eq!(v.branches.len(), p.branches.len());
        assert!((2..=4).contains(&p.branches.len()), "seed {seed}");
        let c = MeshCollider::new(v.mesh.clone());
        c.bvh().check_invariants(&v.mesh).unwrap();
        // A branch's far centreline point is inside the wall: its distance to the mesh is about
        // its radius.
        for (b, line) in v.branches.iter().enumerate() {
            let (end, r) = line.sample(0.9);
            let nearest = c.nearest(&end, 1.0).expect("a nearest triangle").distance;
            assert!(
                (nearest / r - 1.0).abs() < 0.2,
                "seed {seed} branch {b}: wall {nearest:e} m from the axis, radius {r:e} m"
            );
        }
        let (again, _) = generate_random(seed, 6_000).unwrap();
        assert_eq!(again.mesh.vertices(), v.mesh.vertices());
        shapes.insert(format!("{:.6}", p.trunk_length));
    }
    assert_eq!(shapes.len(), 12, "twelve seeds, twelve trunks");
}
