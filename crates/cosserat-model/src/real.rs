//! The scalar type of the CPU model.
//!
//! The model is written once and instantiated for `f32` (the GPU's precision and the fast CPU
//! path) and `f64` (the reference for validation). [`Real`] gathers the bounds the math needs so
//! that generic code stays readable.

use nalgebra::RealField;

/// A floating-point scalar the model can run in: implemented for `f32` and `f64`.
pub trait Real: RealField + Copy + Send + Sync + Default + std::fmt::Debug + 'static {
    /// Converts an `f64` constant or parameter into this precision (rounding for `f32`).
    fn lit(x: f64) -> Self;
    /// Converts this value to `f64` (exact).
    fn to_f64(self) -> f64;
}

impl Real for f32 {
    #[inline(always)]
    fn lit(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
}

impl Real for f64 {
    #[inline(always)]
    fn lit(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
}
