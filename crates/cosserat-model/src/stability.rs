//! The largest stable time step of the explicit (semi-implicit Euler) scheme.
//!
//! The stepper integrates `v += h M⁻¹ f(x, v)` then `x += h v`. For a linear oscillator
//! `ẍ = −ω² x − γ ẋ` this map is stable exactly when `h² ω² + 2 h γ < 4`, i.e. when
//!
//! `h < h_c(ω, γ) = (√(γ² + 4ω²) − γ) / ω²`  (`= 2/ω` without damping).
//!
//! A rod is a set of coupled oscillators; what limits `h` is its fastest mode. Linearised about a
//! straight rod, the modes split into independent blocks, and the highest frequency of each is
//! bounded (Weyl's inequality: the largest eigenvalue of a sum is at most the sum of the largest
//! eigenvalues) by adding up the terms acting on it. With element length `l`, density `ρ`,
//! section area `A = π r²`, second moments `I = π r⁴/4`, `J = 2I`, and parallel penalty `K_p`
//! (default `G A`):
//!
//! - **bending and shear** (frame rotation about `d1`/`d2` and transverse point motion). The
//!   bending springs `E I / l` between frames of inertia `ρ I l` give at most `4 E / (ρ l²)`
//!   (alternating frames); the parallel penalty `½ K_p l (Δδ/l − θ)²` couples each frame to its
//!   element's points, and its zig-zag mode has `ω² = (K_p/ρ) (4/(A l²) + 1/I)`, which for
//!   `K_p = G A` is `4 (G/ρ) (1/l² + 1/r²)`. The penalty on the frame inertia `ρ I l` is what
//!   makes thick rods and short elements stiff: `h ≲ r √(ρ/G)`.
//! - **torsion** (frame rotation about `d3`): `4 G / (ρ l²)`.
//! - **stretching** (axial point motion), extensible mode only: `4 E / (ρ l²)`. In inextensible
//!   mode these modes are removed by the distance constraints.
//!
//! Damping adds rates `γ` to the same blocks: drag (per second) on points, rotational damping
//! `c_b` as `4 c_b / (ρ I l²)` (or `ρ J` for torsion), stretching damping `c_s` as
//! `4 c_s / (ρ A l²)`.
//!
//! The bound is not the whole story: gravity, large curvature and driven ends shift the
//! spectrum a little, and bounds add up modes that do not quite coincide. (Spinning frames do
//! not: the stepper takes the gyroscopic term as a rotation between two half kicks of the
//! torque, which keeps the whole step.) A step above the critical step `h_c` of the fastest
//! block is refused, one above [`SAFETY`] `· h_c` warned about; `cargo xtask validate`
//! re-measures the limit and fails if it falls below `SAFETY · h_c` (`docs/stability.md` has
//! the map).

use crate::Material;
use crate::rod::RodSpec;

/// Fraction of the estimated critical step that is accepted without a warning.
///
/// Measured by bisection (`cargo xtask validate`, `docs/stability.md`): for 64 straight rods
/// over E = 1e3…2e11 Pa, r = 0.05…10 mm and element lengths 0.1…100 mm, 40 random rods
/// (intrinsic curvature and twist released from straight, damping, driven clamps, extensible,
/// f32) and 12 rods whose frames spin about their axes, the largest stable step was 0.99–2.0
/// times the estimate `h_c` (0.99 is the bisection's 1.6 % resolution). 0.9 leaves a margin for
/// what the map does not contain (contacts, bindings, guides).
pub const SAFETY: f64 = 0.9;

/// What the estimate needs to know about one rod.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StabilityInput {
    /// Young's modulus `E` [Pa].
    pub young_modulus: f64,
    /// Shear modulus `G` [Pa].
    pub shear_modulus: f64,
    /// Density `ρ` [kg/m³].
    pub density: f64,
    /// Cross-section radius `r` [m].
    pub radius: f64,
    /// The shortest element length `l` [m].
    pub element_length: f64,
    /// Parallel-constraint penalty `K_p` [N].
    pub parallel_stiffness: f64,
    /// Rotational internal damping `c_b` [N m² s].
    pub bend_damping: f64,
    /// Stretching internal damping `c_s` [N s] (acts only in extensible mode).
    pub stretch_damping: f64,
    /// Drag rate [1/s].
    pub drag: f64,
    /// Extensible mode (stretch energy) instead of distance constraints.
    pub extensible: bool,
}

impl StabilityInput {
    /// An undamped rod of `material` with elements of length `element_length` and the default
    /// penalty `K_p = G A`.
    pub fn new(material: &Material, element_length: f64, extensible: bool) -> Self {
        Self {
            young_modulus: material.young_modulus,
            shear_modulus: material.shear_modulus,
            density: material.density,
            radius: material.radius,
            element_length,
            parallel_stiffness: material.shear_stiffness(),
            bend_damping: 0.0,
            stretch_damping: 0.0,
            drag: 0.0,
            extensible,
        }
    }

    /// The input for a rod built by [`crate::rod::build_rod`] from `points` and `spec`: shortest
    /// segment, the spec's penalty and damping.
    pub fn for_rod(spec: &RodSpec, points: &[[f64; 3]], extensible: bool) -> Self {
        let shortest = points
            .windows(2)
            .map(|w| {
                ((w[1][0] - w[0][0]).powi(2)
                    + (w[1][1] - w[0][1]).powi(2)
                    + (w[1][2] - w[0][2]).powi(2))
                .sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        let mut s = Self::new(&spec.material, shortest, extensible);
        if let Some(kp) = spec.parallel_stiffness {
            s.parallel_stiffness = kp;
        }
        s.bend_damping = spec.bend_damping;
        s.stretch_damping = spec.stretch_damping;
        s.drag = spec.drag;
        s
    }
}

/// The family of modes that limits the step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Frame rotation about the bending axes coupled to transverse point motion by the parallel
    /// penalty.
    BendingShear,
    /// Frame rotation about the rod axis.
    Torsion,
    /// Axial point motion (extensible mode).
    Stretching,
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Mode::BendingShear => {
                "bending/parallel-penalty (frame rotation, ~ r·sqrt(ρ/G) and l·sqrt(ρ/E))"
            }
            Mode::Torsion => "torsion (~ l·sqrt(ρ/G))",
            Mode::Stretching => "stretching (~ l·sqrt(ρ/E))",
        })
    }
}

/// The estimate for one rod.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StableStep {
    /// Critical step `h_c` of the fastest block [s]: the linearised scheme is unstable above it.
    pub critical_dt: f64,
    /// Largest accepted step, `SAFETY · h_c` [s].
    pub max_dt: f64,
    /// The block that limits the step.
    pub mode: Mode,
    /// Its highest angular frequency bound [rad/s].
    pub omega: f64,
    /// Its damping rate bound [1/s].
    pub damping_rate: f64,
}

/// `h_c(ω, γ) = (√(γ² + 4ω²) − γ)/ω²`, the stability limit of semi-implicit Euler for
/// `ẍ = −ω² x − γ ẋ` (written to avoid cancellation when `γ ≫ ω`).
pub fn critical_step(omega: f64, gamma: f64) -> f64 {
    if omega == 0.0 {
        return if gamma > 0.0 {
            2.0 / gamma
        } else {
            f64::INFINITY
        };
    }
    4.0 / ((gamma * gamma + 4.0 * omega * omega).sqrt() + gamma)
}

/// Estimates the largest stable step of one rod.
pub fn stable_step(s: &StabilityInput) -> StableStep {
    let pi = std::f64::consts::PI;
    let (rho, l) = (s.density, s.element_length);
    let area = pi * s.radius * s.radius;
    let i = pi * s.radius.powi(4) / 4.0;
    let j = 2.0 * i;
    let bend_w2 = 4.0 * s.young_modulus / (rho * l * l)
        + s.parallel_stiffness / rho * (4.0 / (area * l * l) + 1.0 / i);
    let bend_g = s.drag + 4.0 * s.bend_damping / (rho * i * l * l);
    let mut blocks = vec![
        (Mode::BendingShear, bend_w2, bend_g),
        (
            Mode::Torsion,
            4.0 * s.shear_modulus / (rho * l * l),
            4.0 * s.bend_damping / (rho * j * l * l),
        ),
    ];
    if s.extensible {
        blocks.push((
            Mode::Stretching,
            4.0 * s.young_modulus / (rho * l * l),
            s.drag + 4.0 * s.stretch_damping / (rho * area * l * l),
        ));
    } else {
        // Inextensible: axial motion is constrained, but drag still acts on the points.
        blocks.push((Mode::Stretching, 0.0, s.drag));
    }
    let (mode, w2, g) = blocks
        .into_iter()
        .map(|(m, w2, g)| (m, w2, g, critical_step(w2.sqrt(), g)))
        .min_by(|a, b| a.3.total_cmp(&b.3))
        .map(|(m, w2, g, _)| (m, w2, g))
        .expect("at least one block");
    let critical_dt = critical_step(w2.sqrt(), g);
    StableStep {
        critical_dt,
        max_dt: SAFETY * critical_dt,
        mode,
        omega: w2.sqrt(),
        damping_rate: g,
    }
}

/// A time step outside the estimated stable region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnstableStep {
    /// The requested step [s].
    pub dt: f64,
    /// The estimate that refused it.
    pub limit: StableStep,
}

impl std::fmt::Display for UnstableStep {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "dt = {:.3e} s is above the explicit stability limit of the {} mode: critical dt ≈ {:.3e} s (ω ≈ {:.3e} rad/s); use dt <= {:.3e} s, or fewer/longer elements, a thinner or softer rod",
            self.dt, self.limit.mode, self.limit.critical_dt, self.limit.omega, self.limit.max_dt
        )
    }
}

impl std::error::Error for UnstableStep {}

/// Accepts `dt` if it is at most `SAFETY` times the estimated critical step.
pub fn check(input: &StabilityInput, dt: f64) -> Result<StableStep, UnstableStep> {
    let limit = stable_step(input);
    if dt <= limit.max_dt {
        Ok(limit)
    } else {
        Err(UnstableStep { dt, limit })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undamped_oscillator_limit_is_two_over_omega() {
        assert!((critical_step(100.0, 0.0) - 0.02).abs() < 1e-15);
        // With damping the limit shrinks, and satisfies h²ω² + 2hγ = 4.
        let h = critical_step(100.0, 50.0);
        assert!((h * h * 1e4 + 2.0 * h * 50.0 - 4.0).abs() < 1e-12);
        assert!((critical_step(0.0, 10.0) - 0.2).abs() < 1e-15);
    }

    /// The estimate reproduces the two textbook limits: a thick rod is limited by the frame
    /// penalty, `h ≈ r √(ρ/G)`, a thin one with short elements by bending, `h ≈ l √(ρ/E)/…`.
    #[test]
    fn limits_scale_as_documented() {
        let m = Material::new(1e7, 1e7 / 3.0, 1000.0, 1e-3);
        let thick = stable_step(&StabilityInput::new(&m, 1e-1, false));
        assert_eq!(thick.mode, Mode::BendingShear);
        let expected = m.radius * (m.density / m.shear_modulus).sqrt();
        assert!(
            (thick.critical_dt / expected - 1.0).abs() < 0.01,
            "{} vs {expected}",
            thick.critical_dt
        );
        // Halving the radius halves the step when the penalty dominates.
        let thinner = stable_step(&StabilityInput::new(
            &Material { radius: 5e-4, ..m },
            1e-1,
            false,
        ));
        assert!((thinner.critical_dt / thick.critical_dt - 0.5).abs() < 0.01);
        // Stiffer material: the step scales as 1/sqrt(E).
        let stiff = stable_step(&StabilityInput::new(
            &Material {
                young_modulus: 4e7,
                shear_modulus: 4e7 / 3.0,
                ..m
            },
            1e-1,
            false,
        ));
        assert!((stiff.critical_dt / thick.critical_dt - 0.5).abs() < 1e-9);
        assert!(check(&StabilityInput::new(&m, 1e-1, false), thick.max_dt).is_ok());
        let err = check(&StabilityInput::new(&m, 1e-1, false), 2.0 * thick.max_dt).unwrap_err();
        assert!(err.to_string().contains("use dt <="), "{err}");
    }
}
