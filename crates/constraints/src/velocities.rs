//! How the constraints that couple rods see the points of a rod.
//!
//! A distance constraint lives inside one rod, so its solvers own the rod's velocities in
//! whatever layout is fastest (plain coordinate slices, or the even/odd split of
//! [`crate::RedBlackSolver`]). Binding constraints ([`crate::binding`]) and rod–rod contacts
//! ([`crate::rod_contact`]) act between points of two rods (paper section 2.1, "Constraints":
//! binding and contact constraints are solved by the same local impulses as the distance
//! constraints, inside the same iterations). They reach each rod's points through
//! [`PointVelocities`], which hides the layout, so the coupling sweeps can run between the
//! distance sweeps of the coupled rods without copying velocities back and forth.
//!
//! Impulses are in momentum units [N s] here: two rods of different materials exchange equal
//! and opposite momenta, which a velocity-unit impulse could not express.
//!
//! A point with zero inverse mass is kinematic (a held end): an impulse on it changes nothing in
//! the rod, but it is exactly what the hand holding that end must absorb. Implementations record
//! the impulses on the first and the last point of the rod, so that the end's reaction force
//! can be reported (see `backend-cpu`'s reaction module).

use cosserat_model::{Real, Vec3};

/// Read and change the velocities of one rod's points.
pub trait PointVelocities<T: Real> {
    /// Velocity of point `i` [m/s].
    fn velocity(&self, i: usize) -> Vec3<T>;
    /// Inverse mass of point `i` [1/kg]; zero for a kinematic point.
    fn inv_mass(&self, i: usize) -> T;
    /// Applies the impulse `j` [N s] to point `i` (`v += w j`). On a kinematic end point the
    /// impulse is recorded instead (see [`KinematicImpulses`]).
    fn apply_impulse(&mut self, i: usize, j: Vec3<T>);
}

/// Impulses delivered to the kinematic first (`[0]`) and last (`[1]`) point of a rod during one
/// step, accumulated over the iterations [N s].
pub type KinematicImpulses<T> = [Vec3<T>; 2];

/// Records `j` on point `i` if `i` is an end point; other kinematic points are not tracked.
#[inline]
pub(crate) fn record_kinematic<T: Real>(
    held: &mut KinematicImpulses<T>,
    last: usize,
    i: usize,
    j: Vec3<T>,
) {
    if i == 0 {
        held[0] += j;
    } else if i == last {
        held[1] += j;
    }
}

/// [`PointVelocities`] over plain coordinate slices `[x, y, z]` (the Gauss–Seidel and
/// extensible layouts).
pub struct SoaVelocities<'a, T: Real> {
    /// Velocity coordinates.
    pub v: [&'a mut [T]; 3],
    /// Inverse masses, one per point.
    pub inv_masses: &'a [T],
    /// Where impulses on kinematic end points go.
    pub held: &'a mut KinematicImpulses<T>,
}

impl<T: Real> PointVelocities<T> for SoaVelocities<'_, T> {
    #[inline(always)]
    fn velocity(&self, i: usize) -> Vec3<T> {
        Vec3::new(self.v[0][i], self.v[1][i], self.v[2][i])
    }
    #[inline(always)]
    fn inv_mass(&self, i: usize) -> T {
        self.inv_masses[i]
    }
    #[inline(always)]
    fn apply_impulse(&mut self, i: usize, j: Vec3<T>) {
        let w = self.inv_masses[i];
        if w > T::zero() {
            self.v[0][i] += j.x * w;
            self.v[1][i] += j.y * w;
            self.v[2][i] += j.z * w;
        } else {
            record_kinematic(self.held, self.inv_masses.len() - 1, i, j);
        }
    }
}
