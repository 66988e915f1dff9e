//! Shared by `tests/validation.rs` (CI sizes) and `cargo xtask validate` (full sizes): the
//! validation cases, their independent references, and a stepping loop with the direct
//! inextensibility solver.

pub mod cases;
pub mod reference;
pub mod stability;
