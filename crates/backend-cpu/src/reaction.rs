//! Reaction force and torque at held ends: what a haptic device renders.
//!
//! A held end is kinematic (zero inverse mass, prescribed velocity; see [`crate::ends`]). The
//! paper's interactive setting (section 2.1: "after a force is applied to the rod by a user
//! manipulating it, for example with a haptic device") needs the force the user's hand
//! exerts through that end, at every step. It follows from the momentum balance of the held
//! point over one step `h`: the hand supplies whatever the point's prescribed motion needs
//! beyond the forces and impulses it receives from the rod,
//!
//! `F = m_k (v_prescribed − v_before) / h − f_k − Σ_c J_{c,k} / h`,
//!
//! where `f_k` is the force computed on point `k` (elasticity, gravity, drag, damping, loads)
//! and `J_{c,k}` is the impulse constraint `c` would have given the point had it been free: for
//! the end's distance constraint that is minus the impulse it gave its other point (measured
//! inside the red–black or Gauss–Seidel sweeps), for a binding or rod–rod contact it is the
//! kinematic point's share, recorded by [`cosserat_constraints::PointVelocities`]. A clamp holds
//! the end frame through its node (`cosserat_model::rod::EndNode`); its torque is the one that
//! node gives the end frame, in world coordinates.
//!
//! [`EndReaction`] is the wrench the holder applies *to the rod* (the support reaction of
//! statics: a clamped cantilever under gravity gets `+W` upwards); a haptic device renders its
//! negative. The torque is about the held point.
//!
//! A haptic device takes the force through its own control loop, which cannot follow the
//! step-to-step noise of an explicit integrator with iterative constraints; the reported value
//! is therefore low-pass filtered, `ẏ = a (x − y)` with `a = 2π f_c` at a configurable cut-off
//! `f_c` ([`DEFAULT_CUTOFF_HZ`]), integrated exactly over each step for an input that runs
//! linearly from the last step's raw value to this one's (a first-order hold):
//! `y ← E y + (1 − E) x_old + (1 − (1 − E)/(a h)) (x − x_old)`, `E = exp(−a h)`. Holding each
//! value over the step before it instead (`y ← y + (1 − E)(x − y)`) delays the output by half
//! a step, an error of first order in `h` that the second-order stiff integrator
//! (`Integrator::Bdf2`) would otherwise keep in its forces. The raw per-step value is available
//! too.

use cosserat_constraints::KinematicImpulses;
use cosserat_model::{Real, Vec3};
pub use cosserat_problem::EndReaction;
pub use cosserat_problem::report::DEFAULT_CUTOFF_HZ;
use cosserat_problem::report::reaction_filter_weights;

fn to_f64<T: Real>(v: Vec3<T>) -> [f64; 3] {
    [v.x.to_f64(), v.y.to_f64(), v.z.to_f64()]
}

/// Per-rod reaction bookkeeping; present only on rods with a held end.
#[derive(Clone, Debug)]
pub(crate) struct Reactions<T: Real> {
    /// Which ends hold their point / their frame.
    pub(crate) held: [bool; 2],
    pub(crate) clamped: [bool; 2],
    /// Which held points slide along an axis: they keep their mass, so the constraints move
    /// them, and their reaction is what puts them back on their axis (`sliding_impulse`).
    pub(crate) sliding: [bool; 2],
    cutoff_hz: f64,
    /// The part of the force known before the constraints: `m (v_p − v) / h − f_k`.
    force_pre: [Vec3<T>; 2],
    /// World torque of a clamped end.
    torque: [Vec3<T>; 2],
    raw: [EndReaction; 2],
    filtered: [EndReaction; 2],
    max_filtered: f64,
}

impl<T: Real> Reactions<T> {
    pub(crate) fn new(held: [bool; 2], clamped: [bool; 2], sliding: [bool; 2]) -> Self {
        Self {
            held,
            clamped,
            sliding,
            cutoff_hz: DEFAULT_CUTOFF_HZ,
            force_pre: [Vec3::zeros(); 2],
            torque: [Vec3::zeros(); 2],
            raw: [EndReaction::default(); 2],
            filtered: [EndReaction::default(); 2],
            max_filtered: 0.0,
        }
    }

    pub(crate) fn set_cutoff(&mut self, hz: f64) {
        self.cutoff_hz = hz;
    }

    pub(crate) fn cutoff(&self) -> f64 {
        self.cutoff_hz
    }

    /// Which ends' distance constraints the sweeps measure (held ends that do not slide: a
    /// sliding end point moves under its constraint like a free one).
    pub(crate) fn tracked(&self) -> [bool; 2] {
        [0, 1].map(|e| self.held[e] && !self.sliding[e])
    }

    /// Before the end conditions overwrite the velocities: the force on the held point, its
    /// mass and velocity, and the prescribed velocity.
    #[inline]
    pub(crate) fn record_point(
        &mut self,
        end: usize,
        mass: T,
        force: Vec3<T>,
        v_before: Vec3<T>,
        v_prescribed: Vec3<T>,
        h: T,
    ) {
        self.force_pre[end] = (v_prescribed - v_before) * (mass / h) - force;
    }

    /// A clamped end's torque on the rod (world frame): what its clamp node gives the end
    /// frame.
    #[inline]
    pub(crate) fn record_torque(&mut self, end: usize, torque: Vec3<T>) {
        self.torque[end] = torque;
    }

    /// After the constraints: `distance[e]` is the impulse the end's distance constraint gave
    /// its other point, `kinematic[e]` what coupling constraints gave the held point itself.
    /// Completes the step's reaction and filters it.
    pub(crate) fn finish(&mut self, distance: [Vec3<T>; 2], kinematic: KinematicImpulses<T>, h: T) {
        // Weights of the last output, the last raw value and this one (module docs).
        let (keep, from_old, from_new) = reaction_filter_weights(self.cutoff_hz, h.to_f64());
        for e in 0..2 {
            if !self.held[e] {
                continue;
            }
            let f = self.force_pre[e] + (distance[e] - kinematic[e]) / h;
            let raw = EndReaction {
                force: to_f64(f),
                torque: if self.clamped[e] {
                    to_f64(self.torque[e])
                } else {
                    [0.0; 3]
                },
            };
            // The device starts at rest with no force: the filter, and the raw value before the
            // first step, start at zero.
            let old = std::mem::replace(&mut self.raw[e], raw);
            let y = &mut self.filtered[e];
            for k in 0..3 {
                y.force[k] = keep * y.force[k] + from_old * old.force[k] + from_new * raw.force[k];
                y.torque[k] =
                    keep * y.torque[k] + from_old * old.torque[k] + from_new * raw.torque[k];
            }
            self.max_filtered = self.max_filtered.max(y.force_norm());
        }
    }

    pub(crate) fn filtered(&self, end: usize) -> Option<EndReaction> {
        self.held[end].then_some(self.filtered[end])
    }

    pub(crate) fn raw(&self, end: usize) -> Option<EndReaction> {
        self.held[end].then_some(self.raw[end])
    }

    pub(crate) fn max_filtered(&self) -> f64 {
        self.max_filtered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The filter's output for a raw force `sin(ω t)` sampled at the end of each step, against
    /// the exact solution of `ẏ = a (sin ω t − y)`, `y(0) = 0`: second order in the step (the
    /// error falls fourfold when the step is halved; holding each sample over the step before
    /// it, the error would only halve).
    #[test]
    fn the_filter_is_second_order_for_a_smooth_force() {
        let (fc, omega, end) = (50.0, 2.0 * std::f64::consts::PI * 20.0, 0.1);
        let a = 2.0 * std::f64::consts::PI * fc;
        let exact = |t: f64| {
            let d = a * a + omega * omega;
            a / d * (a * (omega * t).sin() - omega * (omega * t).cos())
                + a * omega / d * (-a * t).exp()
        };
        let error = |steps: usize| {
            let h = end / steps as f64;
            let mut r = Reactions::<f64>::new([true, false], [false, false], [false, false]);
            r.set_cutoff(fc);
            let mut worst = 0.0_f64;
            for k in 1..=steps {
                let t = k as f64 * h;
                let x = Vec3::new((omega * t).sin(), 0.0, 0.0);
                // force_pre = m (v_p − v)/h − f = x with m = 0 and f = −x.
                r.record_point(0, 0.0, -x, Vec3::zeros(), Vec3::zeros(), h);
                r.finish([Vec3::zeros(); 2], [Vec3::zeros(); 2], h);
                let y = r.filtered(0).unwrap().force[0];
                worst = worst.max((y - exact(t)).abs());
            }
            worst
        };
        let (coarse, fine) = (error(200), error(400));
        let order = (coarse / fine).log2();
        assert!(
            (1.9..2.1).contains(&order),
            "order {order} ({coarse:e}, {fine:e})"
        );
    }
}
