//! Validated triangle meshes.
//!
//! Everything downstream (the AABB tree, the narrow phase, the GPU upload) assumes a clean mesh:
//! finite coordinates, indices in range, no zero-area or repeated triangles, and at most two
//! triangles per edge. Checking that once, here, at load time, keeps the hot query loops free of
//! defensive code and turns a broken input file into a clear error that names the file and the
//! offending triangle or vertex, instead of a NaN contact normal many steps later.
//!
//! Problems that have an obvious, lossless repair (degenerate and duplicate triangles, which add no
//! surface) are repaired and counted in a [`MeshReport`]; problems that do not (non-finite
//! coordinates, out-of-range indices, non-manifold edges) are errors ([`MeshError`]).
//!
//! Winding convention: a triangle `[a, b, c]` has the face normal `(b - a) × (c - a)` normalised.
//! For a vessel the normals must point *into the lumen* (towards where the rod lives); see
//! [`TriMesh::orient_into_lumen`].

use std::collections::HashMap;

use nalgebra::Vector3;

/// Why a mesh could not be loaded or built.
///
/// Every variant names the mesh (its file path, or the name given to [`TriMesh::new`]) and, where
/// it applies, the line, vertex or triangle index and the offending value.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be read.
    #[error("{path}: cannot read mesh file: {source}")]
    Io {
        /// The file.
        path: String,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid OBJ or STL.
    #[error("{path}{}: {message}", line_suffix(*.line))]
    Parse {
        /// The file.
        path: String,
        /// 1-based line number for text formats, `None` for binary STL.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// The unit scale factor is not a finite positive number.
    #[error("{path}: invalid unit scale factor {scale} (must be finite and > 0)")]
    InvalidScale {
        /// The file.
        path: String,
        /// The rejected scale.
        scale: f64,
    },
    /// No usable triangles (none in the input, or all were degenerate or duplicates).
    #[error(
        "{path}: mesh has no usable triangles ({vertices} vertices, {dropped} triangles dropped as degenerate or duplicate)"
    )]
    Empty {
        /// The file.
        path: String,
        /// Vertex count of the input.
        vertices: usize,
        /// Triangles that existed but were dropped.
        dropped: usize,
    },
    /// A vertex coordinate is NaN or infinite (after scaling).
    #[error("{path}{}: vertex {vertex} has a non-finite coordinate {value}", line_suffix(*.line))]
    NonFiniteVertex {
        /// The file.
        path: String,
        /// 1-based line number where the vertex was read, if known.
        line: Option<usize>,
        /// 0-based vertex index.
        vertex: usize,
        /// The bad coordinate value.
        value: f64,
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("{path}{}: triangle {triangle} refers to vertex index {index}, but the mesh has {vertex_count} vertices", line_suffix(*.line))]
    IndexOutOfRange {
        /// The file.
        path: String,
        /// 1-based line number where the face was read, if known.
        line: Option<usize>,
        /// 0-based triangle index.
        triangle: usize,
        /// The bad index as written (OBJ: 1-based or negative-relative; otherwise 0-based).
        index: i64,
        /// Number of vertices available.
        vertex_count: usize,
    },
    /// An edge is shared by more than two triangles.
    #[error(
        "{path}: non-manifold edge between vertices {a} and {b}: shared by {count} triangles (triangle {triangle} is one of them)"
    )]
    NonManifoldEdge {
        /// The file.
        path: String,
        /// One end vertex of the edge.
        a: u32,
        /// The other end vertex.
        b: u32,
        /// How many triangles share it.
        count: usize,
        /// 0-based index (in the input) of a triangle using the edge.
        triangle: usize,
    },
    /// The entry port could not be placed (its radius is not a length, or opening the wall left
    /// no valid mesh).
    #[error("{path}: entry port: {message}")]
    Port {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The mesh has more vertices or triangles than fit the `u32` indices of the flat arrays.
    #[error("{path}: too many elements ({count}) for 32-bit indices")]
    TooLarge {
        /// The file.
        path: String,
        /// The element count.
        count: usize,
    },
}

fn line_suffix(line: Option<usize>) -> String {
    match line {
        Some(l) => format!(":{l}"),
        None => String::new(),
    }
}

/// What validation found and repaired while building a [`TriMesh`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MeshReport {
    /// Triangles in the input (after polygon fan triangulation).
    pub input_triangles: usize,
    /// Triangles dropped because they had zero area (repeated vertex or collinear corners).
    pub degenerate_dropped: usize,
    /// Faces of the file dropped because they had fewer than three vertices (OBJ).
    pub short_faces_dropped: usize,
    /// Triangles dropped because another triangle used the same three vertices.
    pub duplicates_dropped: usize,
    /// Vertices merged because they had bit-identical coordinates (STL stores each corner separately).
    pub welded_vertices: usize,
    /// Edges used by one triangle only (holes, open ends such as the vessel inlet). Not an error.
    pub boundary_edges: usize,
    /// Edges whose two triangles traverse them in the same direction (inconsistent winding).
    pub misoriented_edges: usize,
}

/// A validated triangle mesh: `f64` vertices and `u32` triangle indices.
#[derive(Clone, Debug)]
pub struct TriMesh {
    vertices: Vec<Vector3<f64>>,
    triangles: Vec<[u32; 3]>,
    name: String,
}

/// Relative threshold for zero-area triangles: `|e1 × e2| <= DEGENERATE_REL * longest_edge²`.
const DEGENERATE_REL: f64 = 1e-12;

impl TriMesh {
    /// Validates and builds a mesh from vertices and 0-based triangle indices.
    ///
    /// `name` is used in error messages (a file path, or any label). Degenerate and duplicate
    /// triangles are dropped and counted in the returned [`MeshReport`]; everything else that is
    /// wrong is a [`MeshError`].
    pub fn new(
        vertices: Vec<[f64; 3]>,
        triangles: Vec<[u32; 3]>,
        name: &str,
    ) -> Result<(Self, MeshReport), MeshError> {
        let tris: Vec<[i64; 3]> = triangles
            .iter()
            .map(|t| [t[0] as i64, t[1] as i64, t[2] as i64])
            .collect();
        build(vertices, &tris, None, name, 0)
    }

    /// A flat parallelogram `corner + s u + t v` (`s, t ∈ [0, 1]`) of `2 n²` triangles whose
    /// normals point along `u × v`: a floor, a wall or an incline. Fails like [`Self::new`] for
    /// a degenerate patch (parallel or zero `u`, `v`, non-finite input, `n = 0`).
    pub fn patch(
        corner: [f64; 3],
        u: [f64; 3],
        v: [f64; 3],
        n: usize,
        name: &str,
    ) -> Result<Self, MeshError> {
        let mut vertices = Vec::with_capacity((n + 1) * (n + 1));
        for i in 0..=n {
            for j in 0..=n {
                let (s, t) = (i as f64 / n.max(1) as f64, j as f64 / n.max(1) as f64);
                vertices.push(std::array::from_fn(|c| corner[c] + s * u[c] + t * v[c]));
            }
        }
        let id = |i: usize, j: usize| (i * (n + 1) + j) as u32;
        let mut triangles = Vec::with_capacity(2 * n * n);
        for i in 0..n {
            for j in 0..n {
                triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        Self::new(vertices, triangles, name).map(|(mesh, _)| mesh)
    }

    /// The vertices.
    pub fn vertices(&self) -> &[Vector3<f64>] {
        &self.vertices
    }

    /// The triangles as vertex indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The name given at construction (usually the file path).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The three corners of triangle `t`.
    pub fn triangle(&self, t: usize) -> [Vector3<f64>; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Unit face normal of triangle `t`, `(b - a) × (c - a)` normalised (by winding).
    pub fn face_normal(&self, t: usize) -> Vector3<f64> {
        let [a, b, c] = self.triangle(t);
        (b - a).cross(&(c - a)).normalize()
    }

    /// Axis-aligned bounds `(min, max)` of all vertices.
    pub fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for v in &self.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        (lo, hi)
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.triangle(t);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    /// Signed enclosed volume (divergence theorem). Positive when the normals point outward of a
    /// closed surface; for an open vessel (open inlet and outlets) it is still a reliable
    /// indicator of which way the normals point as long as the openings are small.
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.triangle(t);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Replaces the triangles by the same triangles wound otherwise (the repair's result).
    pub(crate) fn set_triangles_same_vertices(&mut self, triangles: Vec<[u32; 3]>) {
        debug_assert_eq!(triangles.len(), self.triangles.len());
        self.triangles = triangles;
    }

    /// Reverses the winding of every triangle (flips all normals).
    pub fn flip_winding(&mut self) {
        for t in &mut self.triangles {
            t.swap(1, 2);
        }
    }

    /// Makes the normals point into the enclosed volume (the lumen of a vessel), which is what
    /// the contact response expects. Uses the sign of [`signed_volume`](Self::signed_volume);
    /// returns `true` if the winding was flipped.
    pub fn orient_into_lumen(&mut self) -> bool {
        if self.signed_volume() > 0.0 {
            self.flip_winding();
            true
        } else {
            false
        }
    }
}

/// Shared validation for all front ends. `tris` holds raw indices (already 0-based); `lines`, when
/// given, holds the source line of each triangle and of each vertex for error messages.
pub(crate) fn build(
    vertices: Vec<[f64; 3]>,
    tris: &[[i64; 3]],
    lines: Option<(&[usize], &[usize])>,
    name: &str,
    welded_vertices: usize,
) -> Result<(TriMesh, MeshReport), MeshError> {
    let path = || name.to_string();
    if vertices.len() > u32::MAX as usize {
        return Err(MeshError::TooLarge {
            path: path(),
            count: vertices.len(),
        });
    }
    if tris.len() > u32::MAX as usize {
        return Err(MeshError::TooLarge {
            path: path(),
            count: tris.len(),
        });
    }
    if tris.is_empty() {
        return Err(MeshError::Empty {
            path: path(),
            vertices: vertices.len(),
            dropped: 0,
        });
    }
    for (i, v) in vertices.iter().enumerate() {
        if let Some(&value) = v.iter().find(|x| !x.is_finite()) {
            return Err(MeshError::NonFiniteVertex {
                path: path(),
                line: lines.map(|(_, vl)| vl[i]),
                vertex: i,
                value,
            });
        }
    }
    let n = vertices.len();
    let mut report = MeshReport {
        input_triangles: tris.len(),
        welded_vertices,
        ..MeshReport::default()
    };
    let verts: Vec<Vector3<f64>> = vertices.iter().map(|v| Vector3::from(*v)).collect();
    let mut kept: Vec<[u32; 3]> = Vec::with_capacity(tris.len());
    let mut kept_src: Vec<usize> = Vec::with_capacity(tris.len());
    let mut seen: HashMap<[u32; 3], usize> = HashMap::with_capacity(tris.len());
    for (ti, t) in tris.iter().enumerate() {
        let mut idx = [0u32; 3];
        for k in 0..3 {
            if t[k] < 0 || t[k] as usize >= n {
                return Err(MeshError::IndexOutOfRange {
                    path: path(),
                    line: lines.map(|(tl, _)| tl[ti]),
                    triangle: ti,
                    index: t[k],
                    vertex_count: n,
                });
            }
            idx[k] = t[k] as u32;
        }
        if is_degenerate(&verts, idx) {
            report.degenerate_dropped += 1;
            continue;
        }
        let mut key = idx;
        key.sort_unstable();
        if seen.insert(key, ti).is_some() {
            report.duplicates_dropped += 1;
            continue;
        }
        kept.push(idx);
        kept_src.push(ti);
    }
    if kept.is_empty() {
        return Err(MeshError::Empty {
            path: path(),
            vertices: n,
            dropped: report.degenerate_dropped + report.duplicates_dropped,
        });
    }
    // Edge use: undirected count, and directed count for the winding check.
    let mut edges: HashMap<(u32, u32), (u32, u32, usize)> = HashMap::with_capacity(kept.len() * 2);
    for (k, t) in kept.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            let key = (a.min(b), a.max(b));
            let entry = edges.entry(key).or_insert((0, 0, kept_src[k]));
            if a < b {
                entry.0 += 1;
            } else {
                entry.1 += 1;
            }
        }
    }
    // Report the non-manifold edge with the smallest vertex pair for a deterministic message.
    let mut worst: Option<((u32, u32), usize, usize)> = None;
    for (&key, &(fwd, bwd, src)) in &edges {
        let count = (fwd + bwd) as usize;
        if count > 2 {
            if worst.is_none_or(|w| key < w.0) {
                worst = Some((key, count, src));
            }
        } else if count == 1 {
            report.boundary_edges += 1;
        } else if fwd != bwd {
            report.misoriented_edges += 1;
        }
    }
    if let Some(((a, b), count, triangle)) = worst {
        return Err(MeshError::NonManifoldEdge {
            path: path(),
            a,
            b,
            count,
            triangle,
        });
    }
    Ok((
        TriMesh {
            vertices: verts,
            triangles: kept,
            name: name.to_string(),
        },
        report,
    ))
}

fn is_degenerate(v: &[Vector3<f64>], t: [u32; 3]) -> bool {
    if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
        return true;
    }
    let (a, b, c) = (v[t[0] as usize], v[t[1] as usize], v[t[2] as usize]);
    let e = [b - a, c - b, a - c];
    let longest = e.iter().map(|x| x.norm_squared()).fold(0.0, f64::max);
    let cross = e[0].cross(&e[2]).norm();
    longest == 0.0 || cross <= DEGENERATE_REL * longest
}
