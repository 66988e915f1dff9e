//! Entry ports on real anatomy: the phantom of `data/meshes/` with every open end closed by a
//! fan of triangles (as exported anatomy often is), entered at its small end.

use cosserat_collide::{TriMesh, load_mesh, open_port};
use std::collections::HashMap;

const PHANTOM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/meshes/phantom.obj");

/// The mesh with each boundary loop closed by a fan from the loop's centre, welded to the rim.
/// Built here rather than from `cosserat_collide::opening_caps` (whose fans have vertices of
/// their own): with those the test below passes also with the axis sampled up to the wall, the
/// bug it guards against.
fn closed(mesh: &TriMesh) -> TriMesh {
    let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    // Boundary edges as they run in their triangle, a → b.
    let mut next = HashMap::new();
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if uses[&(a.min(b), a.max(b))] == 1 {
                next.insert(a, b);
            }
        }
    }
    let mut vertices: Vec<[f64; 3]> = mesh.vertices().iter().map(|v| [v.x, v.y, v.z]).collect();
    let mut triangles = mesh.triangles().to_vec();
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen = std::collections::HashSet::new();
    for start in starts {
        let mut ring = Vec::new();
        let mut v = start;
        while seen.insert(v) {
            ring.push(v);
            v = next[&v];
        }
        if ring.len() < 3 {
            continue;
        }
        let centre = ring
            .iter()
            .map(|&v| mesh.vertices()[v as usize])
            .sum::<nalgebra::Vector3<f64>>()
            / ring.len() as f64;
        let c = vertices.len() as u32;
        vertices.push([centre.x, centre.y, centre.z]);
        for k in 0..ring.len() {
            triangles.push([ring[(k + 1) % ring.len()], ring[k], c]);
        }
    }
    TriMesh::new(vertices, triangles, "closed phantom")
        .unwrap()
        .0
}

/// The axis from the scene's entry point meets the cap of the small end; the lumen is just
/// behind it, so the port cuts a hole there. (Sampled up to the wall itself, the axis once took
/// the point on the cap, whose winding number is one half, for the lumen reached through an
/// opening: no hole was cut and the wire was pushed through the cap.)
#[test]
fn a_port_opens_the_closed_end_of_the_phantom() {
    let (open, _) = load_mesh(PHANTOM, 1.0).unwrap();
    let mut mesh = closed(&open);
    mesh.repair_orientation();
    mesh.orient_into_lumen();
    for radius in [None, Some(1.0), Some(2.2)] {
        let (collider, port) =
            open_port(mesh.clone(), [1.0, 0.42, -0.32], [-1.0, 0.0, 0.0], radius).unwrap();
        assert!(port.opened > 0, "radius {radius:?}: no hole cut ({port:?})");
        // The wire's axis passes the cap, and the vessel's side wall beyond it stays.
        assert!(
            collider
                .first_intersection(&[1.0, 0.42, -0.32], &[-2.0, 0.42, -0.32])
                .is_none(),
            "radius {radius:?}: the axis still meets a wall"
        );
        assert!(
            port.opened <= 16,
            "radius {radius:?}: {} triangles opened",
            port.opened
        );
    }
}
