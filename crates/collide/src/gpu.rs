//! Flat arrays for uploading a mesh and its tree to a GPU.
//!
//! The paper builds the AABB tree on the CPU once and copies "the arrays containing the mesh
//! triangles and the tree structure" to GPU global memory. This module produces exactly those
//! arrays as plain `#[repr(C)]` structs of `f32` and `u32` with 16-byte aligned rows, so a backend
//! can upload them byte for byte (e.g. with `bytemuck::cast_slice` on its side) without
//! re-packing: [`BvhNode`] (32 bytes) and [`GpuTriangle`] (48 bytes, already in leaf order, so a
//! leaf's `first..first + count` indexes the triangle array directly).

use crate::bvh::BvhNode;
use crate::contact::MeshCollider;

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
