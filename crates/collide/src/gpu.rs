//! Flat arrays for uploading a mesh and its tree to a GPU.
//!
//! The paper builds the AABB tree on the CPU once and copies "the arrays containing the mesh
//! triangles and the tree structure" to GPU global memory. This module produces exactly those
//! arrays as plain `#[repr(C)]` structs of `f32` and `u32` with 16-byte aligned rows, so a backend
//! can upload them byte for byte (e.g. with `bytemuck::cast_slice` on its side) without
//! re-packing: [`BvhNode`] (32 bytes) and [`GpuTriangle`] (48 bytes, already in leaf order, so a
//! leaf's `first..first + count` indexes the triangle array directly).

use crate::bvh::BvhNode;
use crate::contact::{Feature, MeshCollider};

/// One triangle in leaf order, 48 bytes: three `f32` corners, each padded to 16 bytes, the first
/// pad holding the original triangle index.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuTriangle {
    /// Corner a.
    pub a: [f32; 3],
    /// Index of this triangle in the source mesh.
    pub index: u32,
    /// Corner b.
    pub b: [f32; 3],
    /// Padding (0).
    pub pad0: u32,
    /// Corner c.
    pub c: [f32; 3],
    /// Padding (0).
    pub pad1: u32,
}

/// The GPU-ready arrays of a [`MeshCollider`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GpuMesh {
    /// The tree nodes, root first (identical to [`crate::Bvh::nodes`]).
    pub nodes: Vec<BvhNode>,
    /// The triangles in leaf order: leaf `first..first + count` indexes this array.
    pub triangles: Vec<GpuTriangle>,
    /// Tree depth: the traversal stack needs this many entries.
    pub depth: u32,
}

impl MeshCollider {
    /// Packs the tree and the leaf-ordered triangles for GPU upload.
    pub fn to_gpu(&self) -> GpuMesh {
        let f = |v: nalgebra::Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32];
        let triangles = self
            .bvh()
            .tri_indices()
            .iter()
            .map(|&t| {
                let [a, b, c] = self.mesh().triangle(t as usize);
                GpuTriangle {
                    a: f(a),
                    index: t,
                    b: f(b),
                    pad0: 0,
                    c: f(c),
                    pad1: 0,
                }
            })
            .collect();
        GpuMesh {
            nodes: self.bvh().nodes().to_vec(),
            triangles,
            depth: self.bvh().depth() as u32,
        }
    }
}

/// One triangle in leaf order with what a contact query needs on the GPU, 160 bytes of `f32`
/// and `u32` rows: the corners, the unit face normal (into the lumen), and the pseudo-normals of
/// its three edges and three corners ([`crate::contact`]: the normal of the feature holding the
/// closest point decides the side and the push).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuWallTriangle {
    /// Corner a.
    pub a: [f32; 3],
    /// Which edges (bits 0–2, edge `k` from corner `k` to `k + 1`) and corners (bits 3–5) lie
    /// on the mesh's boundary; bit 6: the triangle borders a ridge (an edge where the lumen is
    /// not convex, where an element can come nearer the wall between its points than at them).
    pub boundary: u32,
    /// Corner b.
    pub b: [f32; 3],
    /// Index of this triangle in the source mesh.
    pub index: u32,
    /// Corner c.
    pub c: [f32; 3],
    /// Padding (0).
    pub pad: u32,
    /// Unit face normal (`w` = 0).
    pub normal: [f32; 4],
    /// Pseudo-normals of edges 0, 1, 2 (`w` = 0).
    pub edge_normals: [[f32; 4]; 3],
    /// Pseudo-normals of corners 0, 1, 2 (`w` = 0).
    pub vertex_normals: [[f32; 4]; 3],
}

impl MeshCollider {
    /// The triangles in leaf order with their pseudo-normals and boundary bits, for contact
    /// queries on the GPU against [`Self::to_gpu`]'s nodes.
    pub fn wall_triangles(&self) -> Vec<GpuWallTriangle> {
        let f3 = |v: nalgebra::Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32];
        let f4 = |v: nalgebra::Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32, 0.0];
        self.bvh()
            .tri_indices()
            .iter()
            .enumerate()
            .map(|(slot, &t)| {
                let [a, b, c] = self.mesh().triangle(t as usize);
                GpuWallTriangle {
                    a: f3(a),
                    boundary: self.boundary_bits(slot),
                    b: f3(b),
                    index: t,
                    c: f3(c),
                    pad: 0,
                    normal: f4(self.pseudo_normal(slot, Feature::Face)),
                    edge_normals: [0, 1, 2].map(|k| f4(self.pseudo_normal(slot, Feature::Edge(k)))),
                    vertex_normals: [0, 1, 2]
                        .map(|k| f4(self.pseudo_normal(slot, Feature::Vertex(k)))),
                }
            })
            .collect()
    }

    /// The triangles in leaf order for contact queries in `f64` (the GPU's stiff scheme, which
    /// answers the CPU's queries to rounding): [`WALL_F64`] numbers per slot, the corners a, b,
    /// c, the unit face normal, the pseudo-normals of edges 0–2 and corners 0–2 (three numbers
    /// each, the values the CPU's queries use), then the boundary and ridge bits of
    /// [`GpuWallTriangle::boundary`] and the triangle's index in the mesh.
    pub fn wall_triangles_f64(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.bvh().tri_indices().len() * WALL_F64);
        for (slot, &t) in self.bvh().tri_indices().iter().enumerate() {
            let [a, b, c] = self.mesh().triangle(t as usize);
            let normals = [Feature::Face]
                .into_iter()
                .chain((0..3).map(Feature::Edge))
                .chain((0..3).map(Feature::Vertex))
                .map(|f| self.pseudo_normal(slot, f));
            for v in [a, b, c].into_iter().chain(normals) {
                out.extend([v.x, v.y, v.z]);
            }
            out.extend([f64::from(self.boundary_bits(slot)), f64::from(t)]);
        }
        out
    }

    /// The boundary and ridge bits of the triangle in leaf-order `slot`
    /// ([`GpuWallTriangle::boundary`]).
    fn boundary_bits(&self, slot: usize) -> u32 {
        let mut bits = 0u32;
        for k in 0..3u8 {
            if self.on_boundary(slot, Feature::Edge(k)) {
                bits |= 1 << k;
            }
            if self.on_boundary(slot, Feature::Vertex(k)) {
                bits |= 1 << (3 + k);
            }
        }
        if self.ridges[slot] {
            bits |= 1 << 6;
        }
        bits
    }
}

/// Numbers per triangle of [`MeshCollider::wall_triangles_f64`].
pub const WALL_F64: usize = 32;
