//! A straight introducer: the points of a rod inside it move only along its axis.
//!
//! Why: a guidewire is not pushed into a vessel from half a metre away through free space. The
//! hand feeds it through an introducer sheath whose tip sits at the entry point, so the part
//! still outside cannot buckle sideways. Without it, a wire whose tip meets resistance folds
//! between the hand and the entry, loops back over the rim of the vessel's inlet, and the
//! insertion cannot reach full depth.
//!
//! The guide is frictionless and lateral only: it removes the sideways velocity of the points
//! between the rod's first point and the guide's far end and puts them back on the axis, and
//! nothing else. The push still reaches the rod through its held first point and its distance
//! constraints, so the reaction at that end is still the force the hand feels. Frames are left
//! free: the wire can turn inside the sheath, and twist is transmitted by the rod itself.
//!
//! Points are guided from the first point on while they are behind the guide's far end and
//! within the guide's clearance of the axis; the first point that is not ends the guided run (so a
//! retracted wire re-enters the guide only where it is already nearly on the axis, never with a
//! sideways jump larger than the clearance). Distance impulses between guided points are along
//! the axis (the points are collinear), so the only sideways impulse a guided point receives in
//! the constraint iterations comes from the element leaving the guide; it is removed before
//! positions are integrated.

use crate::soa::SoaState;
use cosserat_model::{Real, Vec3};
use nalgebra::Vector3;

/// A straight, frictionless introducer starting at a rod's first point. Kept in `f64` whatever
/// the rod's precision (see [`Guide::constrain`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Guide {
    origin: Vector3<f64>,
    axis: Vector3<f64>,
    length: f64,
    clearance: f64,
}

impl Guide {
    /// A guide of `length` [m] from `origin` along `direction` (normalised here) that takes in
    /// points within `clearance` [m] of its axis (the sheath's free play; the rod's radius is a
    /// good value). `None` when the direction has no length or a value is not finite and
    /// positive.
    pub fn new(origin: [f64; 3], direction: [f64; 3], length: f64, clearance: f64) -> Option<Self> {
        let (origin, direction) = (Vector3::from(origin), Vector3::from(direction));
        let norm = direction.norm();
        let finite = origin.iter().chain(direction.iter()).all(|c| c.is_finite());
        let positive = |x: f64| x.is_finite() && x > 0.0;
        (finite && norm > 0.0 && positive(length) && positive(clearance)).then(|| Self {
            origin,
            axis: direction / norm,
            length,
            clearance,
        })
    }

    /// For a point at `r`: its sideways offset from the axis if the guide holds it (behind the
    /// far end and within the clearance), else `None`. The stiff scheme pins the run of guided
    /// points from index 1 to the axis (`crate::stiff`).
    pub(crate) fn lateral_offset(&self, r: &Vector3<f64>) -> Option<Vector3<f64>> {
        let rel = r - self.origin;
        let along = rel.dot(&self.axis);
        let lateral = rel - self.axis * along;
        (along < self.length && lateral.norm() <= self.clearance).then_some(lateral)
    }

    /// The unit axis.
    pub fn axis(&self) -> Vector3<f64> {
        self.axis
    }

    /// Where the axis starts.
    pub fn origin(&self) -> Vector3<f64> {
        self.origin
    }

    /// Length along the axis [m].
    pub fn length(&self) -> f64 {
        self.length
    }

    /// Largest distance from the axis of a point the guide holds [m].
    pub fn clearance(&self) -> f64 {
        self.clearance
    }

    /// Puts the guided points (from index 1, the first point being held) on the axis and
    /// removes their sideways velocity.
    ///
    /// The arithmetic is in `f64` and only the sideways parts are subtracted: recomputing a point
    /// as `origin + axis·along` in `f32`, where `|axis|` is 1 only to rounding, pulled every guided
    /// point towards the origin by about 1e-7 of its distance twice per step, which the distance
    /// constraints could not keep up with over 10⁵ steps.
    pub(crate) fn constrain<T: Real>(&self, w: &mut SoaState<T>) {
        let n = w.r.x.len();
        let f = |v: Vec3<T>| Vector3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
        let back = |v: Vector3<f64>| Vec3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z));
        for i in 1..n {
            let r = f(w.r.get(i));
            let rel = r - self.origin;
            let along = rel.dot(&self.axis);
            let lateral = rel - self.axis * along;
            if along >= self.length || lateral.norm() > self.clearance {
                break;
            }
            w.r.set(i, back(r - lateral));
            let v = f(w.v.get(i));
            w.v.set(i, back(self.axis * v.dot(&self.axis)));
        }
    }
}
