//! End conditions: what holds each end of a rod, and how it is driven.
//!
//! A held end is kinematic: its point (and for a clamp, its frame) has infinite mass and moves
//! only as prescribed. That is how a user's hand or a haptic device pushes and twists a
//! guidewire: the driven end follows the device exactly and the rod responds.

use cosserat_model::{Real, Vec3};

/// How an end of a rod is held.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EndKind {
    /// Nothing holds the end.
    #[default]
    Free,
    /// The end point is held in place (or moved as prescribed); its frame may turn.
    Pinned,
    /// The end point and the end frame are both held (or moved as prescribed).
    Clamped,
}

/// A prescribed rigid motion of a held end: constant linear and angular velocity between two
/// times, at rest outside them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrescribedMotion<T: Real> {
    /// Velocity of the end point [m/s], world frame.
    pub velocity: Vec3<T>,
    /// Angular velocity of the end frame [rad/s], world frame (used by clamped ends).
    pub angular_velocity: Vec3<T>,
    /// Time the motion starts [s].
    pub start_time: f64,
    /// Time the motion stops [s] (`f64::INFINITY` for never).
    pub end_time: f64,
}

impl<T: Real> PrescribedMotion<T> {
    /// A push at the constant `velocity`, without rotation, from time 0 on.
    pub fn push(velocity: Vec3<T>) -> Self {
        Self {
            velocity,
            angular_velocity: Vec3::zeros(),
            start_time: 0.0,
            end_time: f64::INFINITY,
        }
    }

    /// A constant velocity and angular velocity from time `from` on, until replaced: what a
    /// haptic hand or a controller sets at a tick.
    pub fn constant(velocity: Vec3<T>, angular_velocity: Vec3<T>, from: f64) -> Self {
        Self {
            velocity,
            angular_velocity,
            start_time: from,
            end_time: f64::INFINITY,
        }
    }

    /// The same motion in another precision.
    pub fn cast<U: Real>(&self) -> PrescribedMotion<U> {
        PrescribedMotion {
            velocity: cast_vec(&self.velocity),
            angular_velocity: cast_vec(&self.angular_velocity),
            start_time: self.start_time,
            end_time: self.end_time,
        }
    }

    /// Velocity and angular velocity in effect at time `t`.
    pub fn at(&self, t: f64) -> (Vec3<T>, Vec3<T>) {
        if t >= self.start_time && t < self.end_time {
            (self.velocity, self.angular_velocity)
        } else {
            (Vec3::zeros(), Vec3::zeros())
        }
    }
}

/// The condition at one end of a rod.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EndCondition<T: Real> {
    /// How the end is held.
    pub kind: EndKind,
    /// How it is driven; `None` holds it still.
    pub motion: Option<PrescribedMotion<T>>,
}

impl<T: Real> EndCondition<T> {
    /// A free end.
    pub fn free() -> Self {
        Self::default()
    }
    /// An end point held in place.
    pub fn pinned() -> Self {
        Self {
            kind: EndKind::Pinned,
            motion: None,
        }
    }
    /// An end point and frame held in place.
    pub fn clamped() -> Self {
        Self {
            kind: EndKind::Clamped,
            motion: None,
        }
    }
    /// This condition, driven with `motion`.
    #[must_use]
    pub fn driven(mut self, motion: PrescribedMotion<T>) -> Self {
        self.motion = Some(motion);
        self
    }
    /// The same condition in another precision.
    pub fn cast<U: Real>(&self) -> EndCondition<U> {
        EndCondition {
            kind: self.kind,
            motion: self.motion.map(|m| m.cast()),
        }
    }
    /// Whether the end point is kinematic.
    pub fn holds_point(&self) -> bool {
        self.kind != EndKind::Free
    }
    /// Whether the end frame is kinematic.
    pub fn holds_frame(&self) -> bool {
        self.kind == EndKind::Clamped
    }
    /// Prescribed (velocity, angular velocity) at time `t`; zero when held still.
    pub fn velocities_at(&self, t: f64) -> (Vec3<T>, Vec3<T>) {
        self.motion
            .map_or((Vec3::zeros(), Vec3::zeros()), |m| m.at(t))
    }
}

/// `v` in another precision.
pub fn cast_vec<T: Real, U: Real>(v: &Vec3<T>) -> Vec3<U> {
    Vec3::new(
        U::lit(v.x.to_f64()),
        U::lit(v.y.to_f64()),
        U::lit(v.z.to_f64()),
    )
}
