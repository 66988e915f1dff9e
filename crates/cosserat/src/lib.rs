//! `cosserat`: fast, accurate Cosserat rods for guidewires, catheters, sutures, cables and hair.
//!
//! This facade ties the workspace together: [`Simulation`] owns rods built with
//! [`RodBuilder`]s through typed [`RodHandle`]s, [`scene`] loads TOML scene files, and
//! [`output`] writes trajectories for NumPy and ParaView. The physics lives in
//! [`cosserat_model`] (energies), [`cosserat_constraints`] (impulse solver) and [`cosserat_backend_cpu`]
//! (stepping); they are re-exported for users who want the explicit pipeline.
//!
//! ```
//! use cosserat::{Material, RodBuilder, SimulationBuilder};
//! // A 0.5 m rubber-like rod clamped at one end, drooping under gravity.
//! let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], 0.5, 50, Material::new(1e7, 3.3e6, 1100.0, 2e-3))
//!     .clamp_start()
//!     .damping(0.0, 0.0, 1.0);
//! let mut sim = SimulationBuilder::new().dt(2e-5).with_rod(rod).build()?;
//! sim.run(100)?;
//! let tip = *sim.positions(cosserat::RodHandle(0)).last().unwrap();
//! assert!(tip[2] < 0.0, "the free end falls");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod convergence;
pub mod energy_watch;
pub mod environment;
pub mod obstacles;
pub mod output;
pub mod report;
pub mod scene;
pub mod sim;

pub use cosserat_backend_cpu::{
    self, Divergence, EndCondition, EndKind, EndPath, LoadProfile, Ordering, PointLoad,
    PrescribedMotion,
};
pub use cosserat_collide;
pub use cosserat_constraints;
pub use cosserat_model::{self, Material};
pub use environment::{Entry, Environment};
pub use obstacles::Obstacle;
pub use sim::{
    Backend, BuildError, Capabilities, Capability, ContactReport, ContactSample, ControlError,
    Gpus, RodBuilder, RodContactSpec, RodHandle, Simulation, SimulationBuilder, SimulationSnapshot,
    StateField, StepError, Stepper, StepperInfo, StiffSettings, StiffSummary,
};
