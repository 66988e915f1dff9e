//! Orientation repair on real anatomy with injected defects: flipped patches, a loose fragment,
//! the whole mesh turned inside out. The answer is known: the phantom as shipped is wound
//! consistently, so every injected flip must be undone and nothing else changed.

use cosserat_collide::{MeshCollider, TriMesh, load_mesh};

const PHANTOM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/meshes/phantom.obj");

/// Whether two windings of the same corners go the same way round.
fn same_turn(a: [u32; 3], b: [u32; 3]) -> bool {
    (0..3).any(|k| [b[k], b[(k + 1) % 3], b[(k + 2) % 3]] == a)
}

fn phantom() -> TriMesh {
    let (mut mesh, _) = load_mesh(PHANTOM, 0.001).expect("the phantom");
    let first = mesh.repair_orientation();
    assert_eq!(first.misoriented_after, 0, "{first:?}");
    mesh
}

/// `mesh` with the triangles of `flip` wound the other way (through the public API: a mesh
/// rebuilt from its vertices and edited triangles).
fn with_flipped(mesh: &TriMesh, flip: impl Fn(usize, [u32; 3]) -> bool) -> TriMesh {
    let verts: Vec<[f64; 3]> = mesh.vertices().iter().map(|v| [v.x, v.y, v.z]).collect();
    let tris = mesh
        .triangles()
        .iter()
        .enumerate()
        .map(|(t, &tri)| {
            if flip(t, tri) {
                [tri[0], tri[2], tri[1]]
            } else {
                tri
            }
        })
        .collect();
    TriMesh::new(verts, tris, "edited").expect("still valid").0
}

#[test]
fn flipped_patches_of_the_phantom_are_wound_back() {
    let good = phantom();
    // A patch: every triangle with a corner in a slab across the mesh, plus scattered ones.
    let slab = |tri: [u32; 3]| {
        tri.iter()
            .any(|&v| (-0.2..-0.15).contains(&good.vertices()[v as usize].x))
    };
    let mut bad = with_flipped(&good, |t, tri| slab(tri) || t % 97 == 3);
    let report = bad.repair_orientation();
    assert!(report.misoriented_before > 100, "{report:?}");
    assert_eq!(report.misoriented_after, 0, "{report:?}");
    let wrong = bad
        .triangles()
        .iter()
        .zip(good.triangles())
        .filter(|(a, b)| !same_turn(**a, **b))
        .count();
    assert_eq!(
        wrong, 0,
        "{wrong} triangles still differ from the phantom as shipped"
    );
    assert!(report.lumen_volume > 0.0);
    assert!(report.openings >= 1, "{report:?}");
}

#[test]
fn a_mesh_turned_inside_out_is_turned_back_and_the_lumen_stays_inside() {
    let good = phantom();
    let mut bad = good.clone();
    bad.flip_winding();
    let report = bad.repair_orientation();
    assert_eq!(report.flipped, good.triangles().len(), "{report:?}");
    assert_eq!(bad.triangles(), good.triangles());
    // The inside test agrees: the centroid of a triangle pushed a little along its normal is in
    // the lumen, and pushed against it is not.
    let collider = MeshCollider::new(bad);
    let mesh = collider.mesh();
    let mut inside = 0;
    for t in (0..mesh.triangles().len()).step_by(200) {
        let [a, b, c] = mesh.triangle(t);
        let centre = (a + b + c) / 3.0;
        let n = mesh.face_normal(t);
        let into = centre + n * 2e-4;
        let away = centre - n * 2e-4;
        if collider.lumen_winding(&into.into()) > 0.5 && collider.lumen_winding(&away.into()) < 0.5
        {
            inside += 1;
        }
    }
    let sampled = mesh.triangles().len().div_ceil(200);
    assert!(inside * 10 >= sampled * 9, "{inside} of {sampled}");
}

#[test]
fn a_loose_fragment_is_a_piece_of_its_own() {
    let good = phantom();
    let mut verts: Vec<[f64; 3]> = good.vertices().iter().map(|v| [v.x, v.y, v.z]).collect();
    let mut tris = good.triangles().to_vec();
    // A small tetrahedron far from the phantom, one face wound the wrong way.
    let base = verts.len() as u32;
    verts.extend([
        [1.0, 1.0, 1.0],
        [1.01, 1.0, 1.0],
        [1.0, 1.01, 1.0],
        [1.0, 1.0, 1.01],
    ]);
    tris.extend([
        [base, base + 2, base + 1],
        [base, base + 1, base + 3],
        [base, base + 3, base + 2],
        [base + 1, base + 3, base + 2],
    ]);
    let (mut mesh, _) = TriMesh::new(verts, tris, "with fragment").expect("valid");
    let report = mesh.repair_orientation();
    assert_eq!(report.pieces.len(), 2, "{report:?}");
    assert_eq!(report.fragments(), 1);
    assert_eq!(report.pieces[1], 4);
    assert_eq!(report.misoriented_after, 0, "{report:?}");
}
