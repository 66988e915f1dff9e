//! Named materials of common instruments, usable from scenes (`material = { preset = "nitinol" }`).
//!
//! Every value is SI. A preset gives Young's modulus, Poisson's ratio (the shear modulus is
//! `G = E / (2 (1 + ν))`), density and a typical radius; a scene may override the radius.
//! Where each number comes from is in `docs/stiff-solver.md` ("Material presets") and in
//! [`Preset::source`]. The cross-section is always a solid circle (`docs/model.md`); tubes such
//! as catheters are approximated by a solid rod of the same outer radius, which overestimates
//! their bending stiffness and mass.

use crate::Material;

/// A named material with a typical cross-section radius.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Preset {
    /// Name used in scene files.
    pub name: &'static str,
    /// Young's modulus `E` [Pa].
    pub young_modulus: f64,
    /// Poisson's ratio `ν`.
    pub poisson_ratio: f64,
    /// Density `ρ` [kg/m³].
    pub density: f64,
    /// Typical radius [m] of an instrument made of it.
    pub radius: f64,
    /// Where the numbers come from.
    pub source: &'static str,
}

impl Preset {
    /// Shear modulus `G = E / (2 (1 + ν))` [Pa].
    pub fn shear_modulus(&self) -> f64 {
        self.young_modulus / (2.0 * (1.0 + self.poisson_ratio))
    }

    /// The material at the preset's typical radius.
    pub fn material(&self) -> Material {
        self.material_with_radius(self.radius)
    }

    /// The material with another radius [m].
    pub fn material_with_radius(&self, radius: f64) -> Material {
        Material::new(
            self.young_modulus,
            self.shear_modulus(),
            self.density,
            radius,
        )
    }
}

/// Every preset, by name.
pub const PRESETS: [Preset; 4] = [
    Preset {
        name: "nitinol",
        young_modulus: 50e9,
        poisson_ratio: 0.33,
        density: 6450.0,
        radius: 0.178e-3,
        source: "NiTi: density 6.45 g/cm3, Poisson 0.33, E 75-83 GPa austenite / 28-41 GPa \
                 martensite (Johnson Matthey, Nitinol technical properties); 50 GPa as an \
                 effective superelastic modulus; radius of a 0.014-inch guidewire",
    },
    Preset {
        name: "steel",
        young_modulus: 200e9,
        poisson_ratio: 0.3,
        density: 7900.0,
        radius: 0.445e-3,
        source: "stainless steel (AISI 304): E 193-200 GPa, Poisson 0.29-0.30, density \
                 7.9-8.0 g/cm3 (AK Steel 304/304L product data bulletin); radius of a \
                 0.035-inch guidewire",
    },
    Preset {
        name: "catheter-polymer",
        young_modulus: 0.5e9,
        poisson_ratio: 0.45,
        density: 1010.0,
        radius: 1.0e-3,
        source: "polyether block amide, Pebax 72D class (Arkema Pebax 7233 datasheet: flexural \
                 modulus about 0.5 GPa, density 1.01 g/cm3); Poisson 0.45 assumed for a \
                 thermoplastic elastomer; radius of a 6 Fr (2 mm) catheter, as a solid rod",
    },
    Preset {
        name: "suture",
        young_modulus: 0.75e9,
        poisson_ratio: 0.45,
        density: 905.0,
        radius: 0.1e-3,
        source: "polypropylene monofilament: E 0.75 GPa (issue 4's value; tensile tests of \
                 polypropylene monofilament sutures measure more, e.g. 4.0 GPa in Nindhia et \
                 al. 2021, Int J Appl Pharm 13(S1), doi 10.22159/ijap.2021.v13s1.Y1025: set \
                 the modulus of a specific suture in the scene), density 0.90-0.91 g/cm3 \
                 (polypropylene), Poisson 0.45 assumed; radius of USP size 4-0 (0.150-0.199 mm \
                 diameter)",
    },
];

/// The preset called `name`, if there is one.
pub fn preset(name: &str) -> Option<&'static Preset> {
    PRESETS.iter().find(|p| p.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_found_by_name() {
        for p in &PRESETS {
            assert!(p.material().validate().is_ok(), "{}", p.name);
            assert_eq!(preset(p.name), Some(p));
            assert!(p.shear_modulus() < p.young_modulus / 2.0);
        }
        assert!(preset("unobtainium").is_none());
        let m = preset("nitinol").unwrap().material_with_radius(0.2e-3);
        assert_eq!(m.radius, 0.2e-3);
    }
}
