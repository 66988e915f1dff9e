//! Collision detection for Cosserat rods (guidewires, catheters, sutures), after the paper's
//! section "Collisions and self-collisions".
//!
//! This crate knows triangles, points and spheres, not rods: the solver hands it slices of points
//! and a radius and gets contacts back as plain data. It depends on no other crate of the
//! workspace, so the CPU solver, the GPU backend and tools can all use it.
//!
//! * [`mesh`]: a validated [`TriMesh`]; bad input is a [`MeshError`] naming the file and the
//!   element, harmless defects are repaired and counted in a [`MeshReport`].
//! * [`io`]: Wavefront OBJ and STL (binary and ASCII) loading with a unit scale (mm → m: `0.001`).
//! * [`bvh`]: the AABB tree built by object partitioning (median split), flat `#[repr(C)]`
//!   `f32`/`u32` arrays usable unchanged on a GPU, iterative traversal with a fixed stack.
//! * [`contact`]: the sphere–triangle narrow phase ([`MeshCollider`]), the paper's per-point
//!   response (penetration-weighted mean of the face normals), escape detection, and a batch API
//!   with reusable buffers ([`ContactBuffer`]).
//! * [`port`]: entry ports ([`open_port`]): where along an entry's axis a wire reaches the
//!   lumen, and a hole opened in a closed wall for it to pass.
//! * [`sweep`]: swept point tests ([`MeshCollider::first_crossing`]): the wall a point crossed
//!   on its way from one place to another, however far it moved.
//! * [`rods`]: rod–rod and self-collision with bounding spheres over runs of points (the paper's
//!   Fig. 6) and a segment–segment narrow phase ([`RodCollider`]).
//! * [`shape`]: analytic obstacles ([`Shape`]): an infinite plane and an infinite cylinder
//!   (a lumen or a solid), with exact signed distances, moved rigidly along a path.
//! * [`vessel`]: a deterministic procedural vessel tree (~26 000 triangles by default, like the
//!   paper's phantom) with an entry point for insertion scenes.
//! * [`gpu`]: the flat arrays for GPU upload.
//!
//! # Units and precision
//!
//! Queries run in `f64` on `f64` vertex data; only the tree boxes are `f32` (rounded outward so
//! they stay conservative), because that is the layout a GPU kernel will read and the CPU
//! traversal uses the very same arrays.
//!
//! # Testing oracle: parry3d-f64 0.31
//!
//! The narrow phase is checked by property tests against [parry](https://parry.rs), an independent
//! and widely used geometry library, as a **dev-dependency only**. We use `parry3d-f64` (not
//! `parry3d`, which is `f32`) so the comparison can be held to 1e-6 relative; and its current
//! release 0.31 even though 0.31 moved from nalgebra to glam types: the oracle never crosses this
//! crate's public API, converting `[f64; 3]` to glam's `DVec3` in the tests is trivial, and a
//! current parry gets the most recent fixes in the very routines used as reference. Older
//! nalgebra-based parry releases would pin an older nalgebra next to the workspace's 0.35 for no
//! benefit.

pub mod bvh;
pub mod contact;
pub mod gpu;
pub mod io;
pub mod mesh;
pub mod port;
pub mod repair;
pub mod rods;
pub mod segment;
pub mod shape;
pub mod sweep;
pub mod vessel;
pub mod winding;

pub use bvh::{Bvh, BvhNode, InvariantViolation, STACK_SIZE};
pub use contact::{Contact, ContactBuffer, MeshCollider, Nearest, PointResponse};
pub use gpu::{GpuMesh, GpuTriangle, GpuWallTriangle, WALL_F64};
pub use io::{load_mesh, load_obj, load_stl, parse_obj, parse_stl};
pub use mesh::{MeshError, MeshReport, TriMesh};
pub use port::{Port, PortError, open_port};
pub use repair::OrientationRepair;
pub use rods::{BroadPhase, Chain, RodCollider, RodCollisionConfig, RodContact};
pub use segment::SegmentNearest;
pub use shape::{Shape, ShapeDistance, Side};
pub use sweep::Crossing;
pub use vessel::{Bulge, Vessel, VesselParams};
pub use winding::{WindingNumber, opening_caps};
