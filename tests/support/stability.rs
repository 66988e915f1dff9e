//! Trial runs for the stable-dt measurements: a rod, a step, a few hundred or thousand steps,
//! and whether the run stayed bounded.

#![allow(dead_code)]

use cosserat::cosserat_model::Material;
use cosserat::cosserat_model::rod::{RestShape, RodSpec};
use cosserat::cosserat_model::stability::{StabilityInput, StableStep, stable_step};
use cosserat::{EndCondition, PrescribedMotion, RodBuilder, SimulationBuilder};

/// A rod for a stability trial.
#[derive(Clone, Debug)]
pub struct TrialRod {
    /// Material.
    pub material: Material,
    /// Number of elements.
    pub elements: usize,
    /// Element length [m].
    pub element_length: f64,
    /// Uniform intrinsic Darboux vector [1/m].
    pub darboux: [f64; 3],
    /// Rotational damping, stretching damping, drag.
    pub damping: [f64; 3],
    /// Extensible mode.
    pub extensible: bool,
    /// Gravity [m/s²].
    pub gravity: [f64; 3],
    /// Clamped start driven with (velocity, angular velocity); `None` pins nothing.
    pub driven_start: Option<([f64; 3], [f64; 3])>,
    /// f64 instead of f32.
    pub double: bool,
    /// Seed of the initial perturbation.
    pub seed: u64,
    /// Step with the stiff solver (default settings) instead of the explicit scheme.
    pub stiff: bool,
    /// Initial angular velocity of every frame about its own axis `d3` [rad/s].
    pub spin: f64,
}

impl TrialRod {
    /// A straight, undamped, free, weightless f64 rod.
    pub fn straight(material: Material, elements: usize, element_length: f64) -> Self {
        Self {
            material,
            elements,
            element_length,
            darboux: [0.0; 3],
            damping: [0.0; 3],
            extensible: false,
            gravity: [0.0; 3],
            driven_start: None,
            double: true,
            seed: 1,
            stiff: false,
            spin: 0.0,
        }
    }

    /// Sets the intrinsic Darboux vector to `u`, scaled down to what a rod can be built with:
    /// at most what the discrete Darboux vector reaches (`|û| l / 2 ≤ 0.9`, short of a turn of
    /// π per element, `RodBuildError::UnreachableRestShape`) and a radius of curvature of at
    /// least `2 r` (a rod curled tighter than its radius is refused at build,
    /// `RodBuildError::RestCurvatureTighterThanRadius`).
    pub fn set_buildable_darboux(&mut self, u: [f64; 3]) {
        let norm = u.iter().map(|x| x * x).sum::<f64>().sqrt();
        let cap = (1.8 / self.element_length).min(0.5 / self.material.radius);
        self.darboux = if norm > cap {
            u.map(|x| x * cap / norm)
        } else {
            u
        };
    }

    /// The points: straight along x with a small pseudo-random transverse perturbation
    /// (1e-3 of an element) that excites every mode, the fastest included.
    fn points(&self) -> Vec<[f64; 3]> {
        let mut state = self
            .seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let l = self.element_length;
        (0..=self.elements)
            .map(|i| [l * i as f64, 1e-3 * l * rnd(), 1e-3 * l * rnd()])
            .collect()
    }

    fn spec(&self) -> RodSpec {
        let mut s = RodSpec::new(self.material);
        s.bend_damping = self.damping[0];
        s.stretch_damping = self.damping[1];
        s.drag = self.damping[2];
        s
    }

    /// The stability estimate for this rod.
    pub fn estimate(&self) -> StableStep {
        stable_step(&self.input())
    }

    /// The estimate's input, as the facade would build it.
    pub fn input(&self) -> StabilityInput {
        StabilityInput::for_rod(&self.spec(), &self.points(), self.extensible)
    }

    /// Runs `steps` steps of `dt`. `Ok(true)`: bounded; `Ok(false)`: the facade reported a
    /// divergence, or the elastic plus kinetic energy exceeded a thousand times what the run
    /// can legitimately hold: its initial energy plus what a driven clamp can inject over the
    /// run (kinetic energy of the rod at the driven speeds, and the bending and twisting energy
    /// of the whole rod turned by the driven angle). An unstable mode grows geometrically from
    /// round-off and passes that within a few dozen steps, then saturates (frame rotations are
    /// bounded), which is why the scale is fixed before the run.
    pub fn stays_bounded(&self, dt: f64, steps: u64) -> Result<bool, String> {
        let mut b = RodBuilder::polyline(self.points(), self.material)
            .rest_shape(RestShape::Uniform(self.darboux))
            .damping(self.damping[0], self.damping[1], self.damping[2]);
        let length = self.element_length * self.elements as f64;
        let mut drive = 0.0;
        if let Some((v, w)) = self.driven_start {
            let motion = PrescribedMotion {
                velocity: v.into(),
                angular_velocity: w.into(),
                start_time: 0.0,
                end_time: f64::INFINITY,
            };
            b = b.start(EndCondition::clamped().driven(motion));
            let (v2, w2) = (
                v.iter().map(|x| x * x).sum::<f64>(),
                w.iter().map(|x| x * x).sum::<f64>(),
            );
            let m = &self.material;
            let angle2 = w2 * (dt * steps as f64).powi(2);
            drive = 0.5 * m.linear_density() * length * (v2 + w2 * length * length)
                + 0.5 * m.inertia_per_length()[2] * length * w2
                + 0.5 * (m.bend_twist_stiffness()[0] + m.bend_twist_stiffness()[2]) * angle2
                    / length;
        }
        // Boundedness is judged by the energy below, not by the facade's runaway-speed check:
        // a stable stiff rod with elements much shorter than its radius (E 2e11, r 5 mm,
        // l 0.1 mm) spins its frames' surfaces faster than that check's 1000 m/s while it
        // oscillates from the initial kinks.
        let stiff = self
            .stiff
            .then(cosserat::cosserat_backend_cpu::StiffSettings::default);
        let mut sim = SimulationBuilder::new()
            .check_stability(false)
            .stiff_solver(stiff)
            .divergence_speed(f64::INFINITY)
            .dt(dt)
            .iterations(10)
            .extensible(self.extensible)
            .gravity(self.gravity)
            .double_precision(self.double)
            .with_rod(b)
            .build()
            .map_err(|e| e.to_string())?;
        if self.spin != 0.0 {
            let h = sim.rods().next().expect("one rod");
            let w = vec![[0.0, 0.0, self.spin]; self.elements];
            sim.write(h, cosserat::StateField::AngularVelocities, &w)
                .map_err(|e| e.to_string())?;
        }
        let energy = |sim: &cosserat::Simulation| {
            let e = sim.energies();
            e.bend_twist + e.parallel + e.stretch + e.kinetic()
        };
        // Gravity's work: the rod's weight falling by up to its length plus the drive's travel.
        let g = self.gravity.iter().map(|x| x * x).sum::<f64>().sqrt();
        let fall = self.material.linear_density()
            * length
            * g
            * (length + (dt * steps as f64).powi(2) * g);
        let limit = 1e3 * (energy(&sim) + drive + fall).max(f64::MIN_POSITIVE);
        for _ in 0..steps {
            if sim.step().is_err() {
                return Ok(false);
            }
            if !(energy(&sim) <= limit) {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// Largest stable step by bisection between `lo` (must be stable) and `hi` (must be
    /// unstable; doubled until it is), to a relative width of `2^-bits`.
    pub fn bisect_stable_dt(&self, steps: u64, bits: u32) -> Result<f64, String> {
        let hc = self.estimate().critical_dt;
        let (mut lo, mut hi) = (0.05 * hc, 2.0 * hc);
        if !self.stays_bounded(lo, steps)? {
            return Err(format!("not stable even at 0.05 h_c = {lo:.3e}"));
        }
        let mut tries = 0;
        while self.stays_bounded(hi, steps)? {
            lo = hi;
            hi *= 2.0;
            tries += 1;
            if tries > 8 {
                return Err("stable up to 512 h_c".into());
            }
        }
        while hi / lo - 1.0 > 0.5f64.powi(bits as i32) {
            let mid = (lo * hi).sqrt();
            if self.stays_bounded(mid, steps)? {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Ok(lo)
    }
}
