//! End conditions: what holds each end of a rod, and how it is driven.
//!
//! A held end is kinematic: its point (and for a clamp, its frame) has infinite mass and moves
//! only as prescribed. That is how a user's hand or a haptic device pushes and twists a
//! guidewire: the driven end follows the device exactly and the rod responds.
//!
//! A held end is driven either by a [`PrescribedMotion`] (a constant velocity and angular
//! velocity over a time window: what a haptic hand sets at each tick) or by an [`EndPath`] (a
//! table of poses over time, followed exactly: ramps, easing, a twist held at a level, a
//! recorded hand motion). A held end may also slide along a fixed axis ([`EndCondition::slide`]):
//! its point is then free along that axis, moved there by the rod and by loads on it, and held
//! across it (a prismatic clamp, or a pin on a rail). That is how a rod is twisted or pulled
//! under a given tension rather than a given length. A clamp may also turn freely about an
//! axis ([`EndCondition::hinge`]): a revolute joint, which with a slide along the same axis is a
//! cylindrical one.

use cosserat_model::{Real, Vec3};
use nalgebra::UnitQuaternion;
use std::sync::Arc;

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

/// A keyframed path of a held end: at each of `times` (seconds after `start_time`) the end has
/// moved by `displacement` and turned by `rotation` (a rotation vector, axis times angle, both
/// in the world frame) from where it was at `start_time`. Between keyframes both are
/// interpolated linearly; before the first and after the last the end holds still.
///
/// A step of `h` from `t` moves the end by exactly the path's displacement over `[t, t + h]` and
/// turns it by exactly the path's rotation over it ([`EndPath::velocities_over`]), so the end
/// is where the path says at every step, whatever the step. Sample a smooth motion finely
/// enough that the corners between keyframes do not matter.
#[derive(Clone, Debug, PartialEq)]
pub struct EndPath {
    start_time: f64,
    times: Vec<f64>,
    displacement: Vec<[f64; 3]>,
    rotation: Vec<[f64; 3]>,
}

impl EndPath {
    /// A path from `start_time` [s] through the keyframes. Errors (as text naming what is
    /// wrong and its value) unless there are at least two keyframes, the times start at 0 and
    /// increase, the three lists have the same length, every value is finite and the first
    /// displacement and rotation are zero.
    pub fn new(
        start_time: f64,
        times: Vec<f64>,
        displacement: Vec<[f64; 3]>,
        rotation: Vec<[f64; 3]>,
    ) -> Result<Self, String> {
        if !start_time.is_finite() {
            return Err(format!("start time {start_time} is not finite"));
        }
        if times.len() < 2 {
            return Err(format!(
                "{} keyframe(s): a path needs at least two",
                times.len()
            ));
        }
        if displacement.len() != times.len() || rotation.len() != times.len() {
            return Err(format!(
                "{} times, {} displacements and {} rotations: one of each per keyframe",
                times.len(),
                displacement.len(),
                rotation.len()
            ));
        }
        if times[0] != 0.0 {
            return Err(format!(
                "the first time is {}: a path starts at 0",
                times[0]
            ));
        }
        if let Some(k) =
            (1..times.len()).find(|&k| !(times[k] > times[k - 1] && times[k].is_finite()))
        {
            return Err(format!(
                "time {k} is {} after {}: times must increase",
                times[k],
                times[k - 1]
            ));
        }
        let finite = |v: &[f64; 3]| v.iter().all(|c| c.is_finite());
        if let Some(k) = displacement.iter().position(|v| !finite(v)) {
            return Err(format!(
                "displacement {k} is {:?}: not finite",
                displacement[k]
            ));
        }
        if let Some(k) = rotation.iter().position(|v| !finite(v)) {
            return Err(format!("rotation {k} is {:?}: not finite", rotation[k]));
        }
        if displacement[0] != [0.0; 3] || rotation[0] != [0.0; 3] {
            return Err(format!(
                "the first keyframe is displacement {:?}, rotation {:?}: a path starts where the end is (zero)",
                displacement[0], rotation[0]
            ));
        }
        Ok(Self {
            start_time,
            times,
            displacement,
            rotation,
        })
    }

    /// When the path starts [s].
    pub fn start_time(&self) -> f64 {
        self.start_time
    }

    /// When the path ends and the end holds still [s].
    pub fn end_time(&self) -> f64 {
        self.start_time + self.times[self.times.len() - 1]
    }

    /// The keyframes' times [s after the start], displacements [m] and rotation vectors [rad].
    pub fn keyframes(&self) -> (&[f64], &[[f64; 3]], &[[f64; 3]]) {
        (&self.times, &self.displacement, &self.rotation)
    }

    /// The same keyframes from another start time.
    #[must_use]
    pub fn starting_at(mut self, start_time: f64) -> Self {
        self.start_time = start_time;
        self
    }

    /// Displacement and rotation vector at time `t` [s].
    pub fn pose(&self, t: f64) -> ([f64; 3], [f64; 3]) {
        let tau = t - self.start_time;
        let last = self.times.len() - 1;
        if !(tau > 0.0) {
            return ([0.0; 3], [0.0; 3]);
        }
        if tau >= self.times[last] {
            return (self.displacement[last], self.rotation[last]);
        }
        let k = self.times.partition_point(|&x| x <= tau) - 1;
        let f = (tau - self.times[k]) / (self.times[k + 1] - self.times[k]);
        let lerp = |a: &[f64; 3], b: &[f64; 3]| std::array::from_fn(|c| a[c] + f * (b[c] - a[c]));
        (
            lerp(&self.displacement[k], &self.displacement[k + 1]),
            lerp(&self.rotation[k], &self.rotation[k + 1]),
        )
    }

    /// The constant velocity [m/s] and world angular velocity [rad/s] that take the end from
    /// its pose at `t` to its pose at `t + h`.
    pub fn velocities_over(&self, t: f64, h: f64) -> ([f64; 3], [f64; 3]) {
        if !(h > 0.0) || t + h <= self.start_time || t >= self.end_time() {
            return ([0.0; 3], [0.0; 3]);
        }
        let (d0, r0) = self.pose(t);
        let (d1, r1) = self.pose(t + h);
        let v = std::array::from_fn(|c| (d1[c] - d0[c]) / h);
        let q = |r: [f64; 3]| UnitQuaternion::from_scaled_axis(nalgebra::Vector3::from(r));
        let turn = (q(r1) * q(r0).inverse()).scaled_axis() / h;
        (v, [turn.x, turn.y, turn.z])
    }
}

/// The condition at one end of a rod.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EndCondition<T: Real> {
    /// How the end is held.
    pub kind: EndKind,
    /// How it is driven by a constant velocity; `None` holds it still (unless `path` is set).
    pub motion: Option<PrescribedMotion<T>>,
    /// How it is driven along a keyframed path (takes the place of `motion`).
    pub path: Option<Arc<EndPath>>,
    /// A unit axis (world frame) along which a held end point is free: the rod and the loads on
    /// the end point move it along the axis, the motion or path only across it. `None`: held
    /// in every direction.
    pub slide: Option<Vec3<T>>,
    /// A unit axis (world frame when the condition is set) about which a clamp turns freely: a
    /// hinge. The clamp holds the end frame in every other direction; the axis turns with the
    /// clamp's prescribed rotation. `None`: held in every direction. Only a clamped end has a
    /// frame to hinge.
    pub hinge: Option<Vec3<T>>,
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
            ..Self::default()
        }
    }
    /// An end point and frame held in place.
    pub fn clamped() -> Self {
        Self {
            kind: EndKind::Clamped,
            ..Self::default()
        }
    }
    /// This condition, driven with `motion` (replacing any path).
    #[must_use]
    pub fn driven(mut self, motion: PrescribedMotion<T>) -> Self {
        self.motion = Some(motion);
        self.path = None;
        self
    }
    /// This condition, driven along `path` (replacing any motion).
    #[must_use]
    pub fn following(mut self, path: EndPath) -> Self {
        self.path = Some(Arc::new(path));
        self.motion = None;
        self
    }
    /// This condition with its point free along `axis` (normalised here; a zero axis holds the
    /// point in every direction).
    #[must_use]
    pub fn sliding_along(mut self, axis: Vec3<T>) -> Self {
        let norm = axis.norm();
        self.slide = (norm > T::zero()).then(|| axis / norm);
        self
    }
    /// This condition with its clamp free to turn about `axis` (normalised here; a zero axis
    /// holds the frame in every direction).
    #[must_use]
    pub fn hinged_about(mut self, axis: Vec3<T>) -> Self {
        let norm = axis.norm();
        self.hinge = (norm > T::zero()).then(|| axis / norm);
        self
    }
    /// The same condition in another precision.
    pub fn cast<U: Real>(&self) -> EndCondition<U> {
        EndCondition {
            kind: self.kind,
            motion: self.motion.map(|m| m.cast()),
            path: self.path.clone(),
            slide: self.slide.map(|a| cast_vec(&a)),
            hinge: self.hinge.map(|a| cast_vec(&a)),
        }
    }
    /// The hinge axis of a clamp, if it turns about one.
    pub fn hinge_axis(&self) -> Option<Vec3<T>> {
        self.hinge.filter(|_| self.holds_frame())
    }
    /// The slide axis of a held end point, if it slides.
    pub fn slide_axis(&self) -> Option<Vec3<T>> {
        self.slide.filter(|_| self.holds_point())
    }
    /// Whether the end point is kinematic.
    pub fn holds_point(&self) -> bool {
        self.kind != EndKind::Free
    }
    /// Whether the end frame is kinematic.
    pub fn holds_frame(&self) -> bool {
        self.kind == EndKind::Clamped
    }
    /// Prescribed (velocity, angular velocity) over the step `[t, t + h]`; zero when held
    /// still. A sliding end's velocity is only the part across its axis (the motion or path
    /// does not move it along the axis).
    pub fn velocities_over(&self, t: f64, h: f64) -> (Vec3<T>, Vec3<T>) {
        let (v, w) = if let Some(path) = &self.path {
            let (v, w) = path.velocities_over(t, h);
            (
                Vec3::new(T::lit(v[0]), T::lit(v[1]), T::lit(v[2])),
                Vec3::new(T::lit(w[0]), T::lit(w[1]), T::lit(w[2])),
            )
        } else {
            self.motion
                .map_or((Vec3::zeros(), Vec3::zeros()), |m| m.at(t))
        };
        match self.slide_axis() {
            Some(a) => (v - a * a.dot(&v), w),
            None => (v, w),
        }
    }
    /// Whether the end is driven (by a motion or a path) at any time.
    pub fn is_driven(&self) -> bool {
        self.motion.is_some() || self.path.is_some()
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
