//! The problem every stepper solves, in words they all share.
//!
//! A simulation is described once — rods with their end conditions and loads, solver settings,
//! the clock — and stepped by whichever backend the user picks: the explicit scheme on the CPU
//! (serial or on rayon's pool), rods coupled by bindings or rod contact, the stiff scheme, or the
//! GPU. This crate holds that description and the [`Stepper`] trait through which the facade
//! drives any of them, so that backends depend on it and never on each other, and adding a
//! backend means implementing [`Stepper`] and nothing else.
//!
//! What a stepper can do is a [`Capabilities`] value, not a scatter of special cases: the
//! facade compares a scene's needs with the chosen stepper's capabilities in one place and
//! refuses with one error that lists everything missing.
//!
//! Nothing here steps a rod. The crate holds plain data (settings, reports, end conditions),
//! the clock arithmetic and the trait; it depends on the model for its scalar and vector types.

pub mod capabilities;
pub mod clock;
pub mod divergence;
pub mod ends;
pub mod report;
pub mod settings;
pub mod stepper;

pub use capabilities::{Capabilities, Capability};
pub use clock::Clock;
pub use divergence::{DivergedQuantity, Divergence, StepStats};
pub use ends::{EndCondition, EndKind, EndPath, PrescribedMotion};
pub use report::{CollisionStats, CouplingStats, EndReaction, StiffReport, StiffSummary};
pub use settings::{
    Gpus, Integrator, LoadProfile, Ordering, Par, PointLoad, Refactor, SolverSettings, StiffScheme,
    StiffSettings, stiff_compliance, stiff_damped_row,
};
pub use stepper::{
    ContactSample, ControlError, Snapshot, StateField, StepError, Stepper, StepperInfo,
};
