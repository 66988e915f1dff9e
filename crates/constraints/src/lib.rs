//! Iterative impulse-based constraints for Cosserat rods (paper section 2.1, "Constraints").
//!
//! The paper replaces the stiff stretching energy of the original CoRdE by hard distance
//! constraints between neighbouring points and solves them locally, one impulse at a time,
//! inside the time step (its Fig. 5): after the velocities have been integrated from the forces
//! and before the positions are. Local impulses keep every constraint independent of all but
//! its neighbours, which is what lets the same solver run serially, over a red–black colouring
//! on many threads, or on the GPU.
//!
//! This crate knows rods only as arrays of points, velocities, inverse masses and rest lengths;
//! it has no notion of frames, forces, threads or devices. Constraints between two rods —
//! binding an inner instrument to an outer one ([`binding`]) and rod–rod or self-contact
//! ([`rod_contact`]) — reach the rods' points through [`PointVelocities`], whatever layout the
//! distance solver keeps them in.

pub mod binding;
pub mod contact;
pub mod direct;
pub mod distance;
pub mod red_black;
pub mod rod_contact;
pub mod velocities;

pub use binding::{BindingSet, BindingVariant, BoundPoint};
pub use contact::{ContactSet, Friction, PointContact};
pub use distance::{
    Ordering, project_distance_soa, solve_distance_gauss_seidel_soa, solve_distance_iteration,
    strain_extremes,
};
pub use red_black::{RedBlackSolver, SplitVelocities};
pub use rod_contact::{RodContactSet, SegmentContact};
pub use velocities::{KinematicImpulses, PointVelocities, SoaVelocities};
