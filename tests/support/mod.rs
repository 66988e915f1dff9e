//! Shared by `tests/validation.rs` (CI sizes) and `cargo xtask validate` (full sizes): the
//! validation cases, their independent references, and a stepping loop with the direct
//! inextensibility solver.
//!
//! The same files are compiled into the test binaries and into `xtask`; their items are `pub`
//! for `xtask`, which the test binaries see as unreachable.
#![allow(unreachable_pub)]

pub mod cases;
pub mod direct_stepper;
pub mod reference;
pub mod stability;
