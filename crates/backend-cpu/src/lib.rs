//! CPU time stepping of Cosserat rods.
//!
//! One step is the paper's Fig. 5 loop without collisions: forces and torques from the model →
//! integrate velocities (semi-implicit Euler) → apply end conditions → distance-constraint
//! iterations → integrate positions and frames. [`step_rod`] advances one rod and is the
//! reference the other backends are compared with; [`step_rods`] advances many rods, serially
//! or on rayon's pool according to a [`Par`] value, with identical results either way because
//! rods do not interact.
//!
//! Rods that act on each other — a guidewire bound inside a catheter, rod–rod contact,
//! self-contact — are stepped together by [`step_coupled_batch`] ([`coupling`]), whose
//! constraint iterations interleave every rod's distance sweep with the coupling constraints.
//! Held ends report the force and torque the holder applies ([`reaction`]), the signal a
//! haptic device renders.
//!
//! The stepper owns no scene logic: it takes rods whose parameters and end conditions were set
//! up by the caller, and reports divergence as a value naming the rod, element, step and
//! quantity instead of letting NaNs spread.

pub mod coupling;
pub mod guide;
pub mod mesh_contact;
pub mod reaction;
mod soa;
pub mod stepper;
pub mod steppers;
pub mod stiff;

pub use cosserat_problem::{
    Clock, CollisionStats, CouplingStats, DivergedQuantity, Divergence, EndCondition, EndKind,
    EndPath, EndReaction, Integrator, LoadProfile, Ordering, Par, PointLoad, PrescribedMotion,
    Refactor, SolverSettings, StepStats, StiffReport, StiffScheme, StiffSettings,
};
pub use coupling::{BindingSpec, Coupling, RodContactSpec, step_coupled_batch};
pub use guide::Guide;
pub use mesh_contact::{MeshContactSettings, ShapeObstacle, TriangleFriction};
pub use stepper::{CpuRod, step_rod, step_rod_batch, step_rods, step_rods_batch};
pub use steppers::{
    BoundStiff, BoundStiffStepper, Coupled, CoupledStepper, CpuStepper, Explicit, ExplicitStepper,
    Scheme, Stiff, StiffStepper,
};
pub use stiff::{StiffBindings, StiffScratch, step_bound_stiff, step_rod_stiff, step_rods_stiff};
