//! Materials and the section properties derived from them.
//!
//! A rod's cross-section is a solid circle of radius `r`. The stiffnesses follow elementary
//! beam theory: bending `E·I` with the second moment of area `I = π r⁴ / 4`, torsion `G·J` with
//! the polar moment `J = π r⁴ / 2`, stretching `E·A` with `A = π r²`. Section 2.1 of the
//! reference paper prints `π r² / 4` and `π r² / 2` for the first two; those have the units of
//! an area, not of a second moment of area, and would make a thin wire orders of magnitude too
//! stiff in bending. `docs/model.md` records the choice.

use serde::{Deserialize, Serialize};

/// Elastic and inertial properties of a solid circular rod, in SI units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Young's modulus `E` [Pa], for bending and stretching.
    pub young_modulus: f64,
    /// Shear modulus `G` [Pa], for torsion and (by default) the parallel-constraint penalty.
    pub shear_modulus: f64,
    /// Mass density `ρ` [kg/m³].
    pub density: f64,
    /// Cross-section radius `r` [m].
    pub radius: f64,
}

/// Why a [`Material`] was rejected.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialError {
    /// The offending field.
    pub field: &'static str,
    /// Its value.
    pub value: f64,
    /// What a valid value looks like.
    pub expected: &'static str,
}

impl std::fmt::Display for MaterialError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "`{}` = {} is invalid: expected {}",
            self.field, self.value, self.expected
        )
    }
}

impl std::error::Error for MaterialError {}

impl Material {
    /// A material from `E`, `G`, `ρ` and `r`.
    pub fn new(young_modulus: f64, shear_modulus: f64, density: f64, radius: f64) -> Self {
        Self {
            young_modulus,
            shear_modulus,
            density,
            radius,
        }
    }

    /// Checks that every property is finite and positive.
    pub fn validate(&self) -> Result<(), MaterialError> {
        let check = |field, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(MaterialError {
                    field,
                    value,
                    expected: "a finite number > 0",
                })
            }
        };
        check("young_modulus", self.young_modulus)?;
        check("shear_modulus", self.shear_modulus)?;
        check("density", self.density)?;
        check("radius", self.radius)
    }

    /// Cross-section area `A = π r²` [m²].
    pub fn area(&self) -> f64 {
        std::f64::consts::PI * self.radius * self.radius
    }

    /// Second moment of area `I = π r⁴ / 4` [m⁴] about either bending axis.
    pub fn second_moment(&self) -> f64 {
        std::f64::consts::PI * self.radius.powi(4) / 4.0
    }

    /// Polar moment `J = π r⁴ / 2` [m⁴].
    pub fn polar_moment(&self) -> f64 {
        std::f64::consts::PI * self.radius.powi(4) / 2.0
    }

    /// Bending and twisting stiffnesses `(E I, E I, G J)` [N m²], the `K_k` of the bending energy.
    pub fn bend_twist_stiffness(&self) -> [f64; 3] {
        let ei = self.young_modulus * self.second_moment();
        [ei, ei, self.shear_modulus * self.polar_moment()]
    }

    /// Stretching stiffness `E A` [N], the `K_s` of the stretch energy.
    pub fn stretch_stiffness(&self) -> f64 {
        self.young_modulus * self.area()
    }

    /// Shear stiffness `G A` [N], the default `K_p` of the parallel-constraint penalty.
    ///
    /// With this choice the penalty energy is the shear energy of a Timoshenko rod, so the
    /// coupling of frames to the centreline has a physical meaning instead of a tuned constant.
    pub fn shear_stiffness(&self) -> f64 {
        self.shear_modulus * self.area()
    }

    /// Mass per unit length `ρ A` [kg/m].
    pub fn linear_density(&self) -> f64 {
        self.density * self.area()
    }

    /// Rotational inertia per unit length about the body axes `ρ (I, I, J)` [kg m].
    pub fn inertia_per_length(&self) -> [f64; 3] {
        let i = self.density * self.second_moment();
        [i, i, self.density * self.polar_moment()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn section_properties() {
        let m = Material::new(2e11, 8e10, 7850.0, 1e-3);
        let pi = std::f64::consts::PI;
        assert!((m.second_moment() - pi * 1e-12 / 4.0).abs() < 1e-24);
        assert!((m.bend_twist_stiffness()[2] - 8e10 * pi * 1e-12 / 2.0).abs() < 1e-12);
        assert!(m.validate().is_ok());
        let bad = Material::new(2e11, 8e10, f64::NAN, 1e-3);
        assert_eq!(bad.validate().unwrap_err().field, "density");
    }
}
