//! Mesh loading and validation: every error case, the repairs, and the real meshes.

use cosserat_collide::{
    Bvh, MeshCollider, MeshError, TriMesh, load_mesh, load_obj, load_stl, parse_obj, parse_stl,
};
use std::io::Write;

const TETRA_OBJ: &str =
    "# tetrahedron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n";

fn msg(e: &MeshError) -> String {
    e.to_string()
}

#[test]
fn obj_tetrahedron_loads_scaled() {
    let (m, r) = parse_obj(TETRA_OBJ, "tetra.obj", 0.001).unwrap();
    assert_eq!(m.triangles().len(), 4);
    assert_eq!(m.vertices()[1].x, 0.001);
    assert_eq!(r.boundary_edges, 0);
    assert_eq!(r.misoriented_edges, 0);
    // Outward winding: positive volume; flipping makes normals point inside.
    assert!((m.signed_volume() - 1e-9 / 6.0).abs() < 1e-20);
    let mut m2 = m.clone();
    assert!(m2.orient_into_lumen());
    assert!(m2.signed_volume() < 0.0);
}

#[test]
fn obj_faces_with_slashes_negative_indices_and_polygons() {
    let text =
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3//1 4\nf -4 -2 -1\n";
    // The quad becomes 2 triangles; the last face duplicates the quad's second triangle.
    let (m, r) = parse_obj(text, "q.obj", 1.0).unwrap();
    assert_eq!(r.input_triangles, 3);
    assert_eq!(r.duplicates_dropped, 1);
    assert_eq!(m.triangles(), &[[0, 1, 2], [0, 2, 3]]);
}

#[test]
fn obj_errors_name_file_line_and_value() {
    let e = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "bad.obj", 1.0).unwrap_err();
    assert!(
        matches!(
            e,
            MeshError::IndexOutOfRange {
                line: Some(4),
                index: 7,
                vertex_count: 3,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        msg(&e).contains("bad.obj:4") && msg(&e).contains('7'),
        "{e}"
    );

    let e = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "zero.obj", 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::IndexOutOfRange { index: 0, .. }),
        "{e:?}"
    );

    let e = parse_obj("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "nan.obj", 1.0).unwrap_err();
    assert!(
        matches!(
            e,
            MeshError::NonFiniteVertex {
                line: Some(2),
                vertex: 1,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        msg(&e).contains("nan.obj:2") && msg(&e).contains("NaN"),
        "{e}"
    );

    let e = parse_obj("v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "inf.obj", 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::NonFiniteVertex { value, .. } if value.is_infinite()),
        "{e:?}"
    );

    // Overflow through the scale factor is caught too.
    let e = parse_obj(
        "v 1e308 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "big.obj",
        1000.0,
    )
    .unwrap_err();
    assert!(matches!(e, MeshError::NonFiniteVertex { .. }), "{e:?}");

    let e = parse_obj("v 0 0 zz\n", "tok.obj", 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::Parse { line: Some(1), .. }) && msg(&e).contains("zz"),
        "{e}"
    );

    let e = parse_obj("v 0 0\n", "short.obj", 1.0).unwrap_err();
    assert!(msg(&e).contains("short.obj:1"), "{e}");

    // A face of two vertices is dropped (see below): nothing is left.
    let e = parse_obj("v 0 0 0\nv 1 0 0\nf 1 2\n", "face2.obj", 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::Empty { .. }) && msg(&e).contains("face2.obj"),
        "{e:?}"
    );

    let e = parse_obj("# nothing\nv 0 0 0\n", "empty.obj", 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::Empty { .. }) && msg(&e).contains("empty.obj"),
        "{e}"
    );

    let e = parse_obj(TETRA_OBJ, "t.obj", 0.0).unwrap_err();
    assert!(matches!(e, MeshError::InvalidScale { .. }), "{e:?}");
    let e = parse_obj(TETRA_OBJ, "t.obj", f64::NAN).unwrap_err();
    assert!(matches!(e, MeshError::InvalidScale { .. }), "{e:?}");
}

#[test]
fn degenerate_and_duplicate_triangles_are_dropped_and_counted() {
    let verts = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [2.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let tris = vec![
        [0, 1, 2],
        [0, 0, 2], // repeated vertex
        [0, 1, 3], // collinear
        [2, 1, 0], // duplicate (other winding)
        [0, 1, 4],
    ];
    let (m, r) = TriMesh::new(verts, tris, "soup").unwrap();
    assert_eq!(r.input_triangles, 5);
    assert_eq!(r.degenerate_dropped, 2);
    assert_eq!(r.duplicates_dropped, 1);
    assert_eq!(m.triangles(), &[[0, 1, 2], [0, 1, 4]]);

    // Only degenerate triangles: an error naming the counts.
    let e = TriMesh::new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        vec![[0, 1, 2]],
        "line",
    )
    .unwrap_err();
    assert!(matches!(e, MeshError::Empty { dropped: 1, .. }), "{e:?}");
}

#[test]
fn non_manifold_edge_is_an_error() {
    let verts = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let tris = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
    let e = TriMesh::new(verts, tris, "fan").unwrap_err();
    assert!(
        matches!(
            e,
            MeshError::NonManifoldEdge {
                a: 0,
                b: 1,
                count: 3,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        msg(&e).contains("fan") && msg(&e).contains("vertices 0 and 1"),
        "{e}"
    );
}

#[test]
fn misoriented_edges_are_reported() {
    let verts = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let (_, ok) = TriMesh::new(verts.clone(), vec![[0, 1, 2], [1, 3, 2]], "ok").unwrap();
    assert_eq!(ok.misoriented_edges, 0);
    assert_eq!(ok.boundary_edges, 4);
    let (_, bad) = TriMesh::new(verts, vec![[0, 1, 2], [1, 2, 3]], "flip").unwrap();
    assert_eq!(bad.misoriented_edges, 1);
}

fn binary_stl(tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b.extend((tris.len() as u32).to_le_bytes());
    for t in tris {
        b.extend([0u8; 12]);
        for v in t {
            for x in v {
                b.extend(x.to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    b
}

const TETRA: [[[f32; 3]; 3]; 4] = [
    [[0., 0., 0.], [0., 1., 0.], [1., 0., 0.]],
    [[0., 0., 0.], [1., 0., 0.], [0., 0., 1.]],
    [[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
    [[0., 1., 0.], [0., 0., 0.], [0., 0., 1.]],
];

#[test]
fn binary_stl_welds_corners() {
    let (m, r) = parse_stl(&binary_stl(&TETRA), "t.stl", 0.001).unwrap();
    assert_eq!(m.vertices().len(), 4);
    assert_eq!(r.welded_vertices, 8);
    assert_eq!(r.boundary_edges, 0);
    assert_eq!(r.misoriented_edges, 0);
    assert!(m.signed_volume() > 0.0);
}

#[test]
fn binary_stl_errors() {
    let mut b = binary_stl(&TETRA);
    b.truncate(b.len() - 7);
    let e = parse_stl(&b, "trunc.stl", 1.0).unwrap_err();
    assert!(
        msg(&e).contains("trunc.stl") && msg(&e).contains("announces 4 triangles"),
        "{e}"
    );

    let e = parse_stl(&[1, 2, 3], "tiny.stl", 1.0).unwrap_err();
    assert!(
        msg(&e).contains("tiny.stl") && msg(&e).contains("3 bytes"),
        "{e}"
    );

    let mut t = TETRA;
    t[2][1][1] = f32::NAN;
    let e = parse_stl(&binary_stl(&t), "nan.stl", 1.0).unwrap_err();
    assert!(
        msg(&e).contains("nan.stl") && msg(&e).contains("triangle 2"),
        "{e}"
    );

    let e = parse_stl(&binary_stl(&[]), "none.stl", 1.0).unwrap_err();
    assert!(matches!(e, MeshError::Empty { .. }), "{e:?}");
}

fn ascii_stl(tris: &[[[f32; 3]; 3]]) -> String {
    let mut s = String::from("solid test\n");
    for t in tris {
        s.push_str("  facet normal 0 0 0\n    outer loop\n");
        for v in t {
            s.push_str(&format!("      vertex {} {} {}\n", v[0], v[1], v[2]));
        }
        s.push_str("    endloop\n  endfacet\n");
    }
    s.push_str("endsolid test\n");
    s
}

#[test]
fn ascii_stl_loads_and_reports_errors_with_lines() {
    let (m, _) = parse_stl(ascii_stl(&TETRA).as_bytes(), "a.stl", 1.0).unwrap();
    assert_eq!(m.triangles().len(), 4);
    assert_eq!(m.vertices().len(), 4);

    let bad = ascii_stl(&TETRA).replacen("vertex 0 1 0", "vertex 0 x 0", 1);
    let e = parse_stl(bad.as_bytes(), "a.stl", 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::Parse { line: Some(5), .. }) && msg(&e).contains("\"x\""),
        "{e}"
    );

    let bad = ascii_stl(&TETRA).replacen("vertex 0 1 0", "vertex 0 inf 0", 1);
    let e = parse_stl(bad.as_bytes(), "a.stl", 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::NonFiniteVertex { line: Some(5), .. }),
        "{e:?}"
    );

    let bad = ascii_stl(&TETRA[..1]).replacen("      vertex 1 0 0\n", "", 1);
    let e = parse_stl(bad.as_bytes(), "a.stl", 1.0).unwrap_err();
    assert!(msg(&e).contains("facet has 2 vertices"), "{e}");
}

#[test]
fn files_by_extension_and_io_errors() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("t.OBJ");
    std::fs::write(&obj, TETRA_OBJ).unwrap();
    let stl = dir.path().join("t.stl");
    std::fs::File::create(&stl)
        .unwrap()
        .write_all(&binary_stl(&TETRA))
        .unwrap();
    let other = dir.path().join("t.mesh");
    std::fs::write(&other, TETRA_OBJ).unwrap();
    assert_eq!(load_mesh(&obj, 1.0).unwrap().0.triangles().len(), 4);
    assert_eq!(load_mesh(&stl, 1.0).unwrap().0.triangles().len(), 4);
    assert_eq!(load_mesh(&other, 1.0).unwrap().0.triangles().len(), 4);
    assert_eq!(load_obj(&obj, 1.0).unwrap().0.triangles().len(), 4);
    assert_eq!(load_stl(&stl, 1.0).unwrap().0.triangles().len(), 4);

    let missing = dir.path().join("missing.obj");
    let e = load_mesh(&missing, 1.0).unwrap_err();
    assert!(
        matches!(e, MeshError::Io { .. }) && msg(&e).contains("missing.obj"),
        "{e}"
    );

    let bin = dir.path().join("bin.obj");
    std::fs::write(&bin, [0xffu8, 0xfe, 0x00, 0x10]).unwrap();
    let e = load_mesh(&bin, 1.0).unwrap_err();
    assert!(
        msg(&e).contains("bin.obj:1") && msg(&e).contains("UTF-8"),
        "{e}"
    );
}

const PHANTOM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/meshes/phantom.obj");
const CAROTIDS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../data/meshes/carotids.stl"
);

fn check_real(path: &str, triangles: usize) {
    let (mut mesh, report) = load_mesh(path, 0.001).unwrap();
    println!("{path}: {report:?}");
    assert_eq!(mesh.triangles().len(), triangles);
    assert_eq!(report.degenerate_dropped + report.duplicates_dropped, 0);
    assert_eq!(report.misoriented_edges, 0);
    mesh.orient_into_lumen();
    let (lo, hi) = mesh.bounds();
    // Millimetres scaled to metres: a few centimetres to decimetres.
    assert!((hi - lo).max() > 0.01 && (hi - lo).max() < 1.0);
    let bvh = Bvh::build(&mesh);
    bvh.check_invariants(&mesh).unwrap();
    assert!(bvh.depth() <= 16, "depth {}", bvh.depth());
    // A point on a vertex, with a radius: at least the triangles around it are in contact.
    let c = MeshCollider::new(mesh.clone());
    let v: [f64; 3] = mesh.vertices()[mesh.triangles()[0][0] as usize].into();
    let mut buf = cosserat_collide::ContactBuffer::new();
    c.detect(&[v], 1e-4, &mut buf);
    assert!(buf.contacts().len() >= 3);
}

#[test]
fn real_phantom_obj_loads() {
    check_real(PHANTOM, 6392);
}

#[test]
fn real_carotids_stl_loads() {
    check_real(CAROTIDS, 2289);
}

#[test]
fn a_patch_spans_its_parallelogram_with_normals_along_u_cross_v() {
    let (u, v) = ([0.3, 0.0, 0.1], [0.0, 0.2, 0.0]);
    let mesh = TriMesh::patch([1.0, 2.0, 3.0], u, v, 5, "incline").expect("valid");
    assert_eq!(mesh.triangles().len(), 2 * 5 * 5);
    let n = nalgebra::Vector3::from(u).cross(&nalgebra::Vector3::from(v));
    assert!((mesh.area() - n.norm()).abs() < 1e-12 * n.norm());
    for t in 0..mesh.triangles().len() {
        assert!((mesh.face_normal(t) - n.normalize()).norm() < 1e-12);
    }
    // Parallel edges span nothing: an error naming the patch, not a panic.
    let err = TriMesh::patch([0.0; 3], u, u, 3, "flat").unwrap_err();
    assert!(err.to_string().contains("flat"), "{err}");
}

/// Faces of one or two vertices (found in exported anatomy) are dropped and counted, not an
/// error: the rest of the mesh loads.
#[test]
fn obj_faces_of_fewer_than_three_vertices_are_dropped_and_reported() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2\nf 4\nf 1 2 4\n";
    let (mesh, report) = parse_obj(text, "short.obj", 1.0).unwrap();
    assert_eq!(report.short_faces_dropped, 2);
    assert_eq!(mesh.triangles().len(), 2);
}
