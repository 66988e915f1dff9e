//! The discrete CoRdE Cosserat rod (Spillmann & Teschner 2007, as summarised in section 2.1 of
//! Korzeniowski, Hald & Bello): centreline points, one unit-quaternion material frame per
//! element, and the energies that couple them, each with its exact gradient.
//!
//! This crate is pure math. It owns no threads, no GPU resources and does no I/O, so that the
//! CPU backends, the GPU backend (as the reference for its shaders) and the tests all share one
//! definition of the physics. Every function is written once, generic over [`Real`] (`f32` or
//! `f64`).
//!
//! Conventions used everywhere in the workspace (see `docs/model.md`):
//! - a rod of `n` elements has `n + 1` points `r_0..r_n` and `n` frames `q_0..q_{n-1}`;
//!   frame `j` belongs to the segment `r_j → r_{j+1}`;
//! - a quaternion maps body (material) coordinates to world coordinates, so the directors are
//!   `d_k = q e_k q̄` and `d_3` is meant to follow the tangent;
//! - angular velocities and torques of frames are stored in **body** coordinates;
//! - the `n - 1` Darboux vectors live at the interior nodes between frames `j` and `j + 1`.

pub mod darboux;
pub mod energy;
pub mod material;
pub mod presets;
pub mod quat;
pub mod real;
pub mod rod;
pub mod stability;

pub use darboux::darboux;
pub use material::{Material, MaterialError};
pub use real::Real;
pub use rod::{RodBuildError, RodParams, RodState};

/// Three-component vector in the rod's scalar type.
pub type Vec3<T> = nalgebra::Vector3<T>;
/// Quaternion in the rod's scalar type (`coords` = `[x, y, z, w]`, the GPU `vec4` layout).
pub type Quat<T> = nalgebra::Quaternion<T>;
