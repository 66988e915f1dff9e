//! Contact of rod points with a static surface: non-penetration with Coulomb friction.
//!
//! The collision stage reports, per point in contact, the direction to push it (the
//! penetration-weighted mean of the normals of the triangles it touches, as in the paper) and
//! its signed gap to the surface (negative when it penetrates). Inside the constraint iterations
//! (paper Fig. 5) each contact is a velocity-level constraint on one point:
//!
//! - non-penetration: `n · v ≥ −gap / h`, i.e. at the end of the step the point touches or is
//!   clear of the surface; a speculative contact (positive gap) lets the point approach up to the
//!   surface but not past it, which stops fast points tunnelling through thin walls;
//! - friction: the tangential velocity is removed while the accumulated tangential impulse stays
//!   inside the static cone `μ_s · λ_n` (stick); outside it the impulse is clamped to the kinetic
//!   cone `μ_k · λ_n` (slip).
//!
//! Impulses are accumulated over the iterations and clamped (projected Gauss–Seidel), so the
//! result does not depend on how the normal impulse was split between iterations. The surface is
//! static (infinite mass), so an impulse changes only the point's velocity and can be expressed
//! in velocity units; each contact touches one point and the contacts of a sweep are independent
//! of each other except through shared points of the rod, which the distance constraints couple.

use cosserat_model::{Real, Vec3};

/// Coulomb friction coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Friction<T: Real> {
    /// Static coefficient `μ_s`: sticking holds while `|λ_t| ≤ μ_s λ_n`.
    pub static_coefficient: T,
    /// Kinetic coefficient `μ_k ≤ μ_s`: sliding friction `|λ_t| = μ_k λ_n`.
    pub kinetic_coefficient: T,
}

impl<T: Real> Friction<T> {
    /// The accumulated tangential impulse after one projection: the impulse `wanted` that would
    /// stop the sliding is kept while it lies inside the static cone `μ_s λ_n` (stick), and is
    /// otherwise scaled onto the kinetic cone `μ_k λ_n` (slip).
    #[inline]
    pub fn clamp(&self, wanted: Vec3<T>, normal_impulse: T) -> Vec3<T> {
        let norm = wanted.norm();
        if norm <= self.static_coefficient * normal_impulse {
            wanted
        } else if norm > T::zero() {
            wanted * (self.kinetic_coefficient * normal_impulse / norm)
        } else {
            Vec3::zeros()
        }
    }
}

/// One point in contact with the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointContact<T: Real> {
    /// Index of the point in the rod.
    pub point: u32,
    /// Unit direction that moves the point out of the surface.
    pub normal: Vec3<T>,
    /// Signed distance to the surface minus the radius [m]; negative when penetrating.
    pub gap: T,
}

/// The contacts of one rod for one step, with their accumulated impulses.
#[derive(Clone, Debug, Default)]
pub struct ContactSet<T: Real> {
    contacts: Vec<PointContact<T>>,
    normal_impulse: Vec<T>,
    tangent_impulse: Vec<Vec3<T>>,
}

impl<T: Real> ContactSet<T> {
    /// An empty set.
    pub fn new() -> Self {
        Self {
            contacts: Vec::new(),
            normal_impulse: Vec::new(),
            tangent_impulse: Vec::new(),
        }
    }

    /// Removes all contacts, keeping the capacity.
    pub fn clear(&mut self) {
        self.contacts.clear();
        self.normal_impulse.clear();
        self.tangent_impulse.clear();
    }

    /// Adds a contact with zero accumulated impulse.
    pub fn push(&mut self, c: PointContact<T>) {
        self.contacts.push(c);
        self.normal_impulse.push(T::zero());
        self.tangent_impulse.push(Vec3::zeros());
    }

    /// The contacts.
    pub fn contacts(&self) -> &[PointContact<T>] {
        &self.contacts
    }

    /// Number of contacts.
    pub fn len(&self) -> usize {
        self.contacts.len()
    }

    /// Whether there are no contacts.
    pub fn is_empty(&self) -> bool {
        self.contacts.is_empty()
    }

    /// Accumulated normal impulse of each contact, as a velocity change [m/s]; multiply by the
    /// point's mass and divide by the step for the contact force.
    pub fn normal_impulses(&self) -> &[T] {
        &self.normal_impulse
    }

    /// Accumulated tangential (friction) impulse of each contact, as a velocity change [m/s].
    pub fn tangent_impulses(&self) -> &[Vec3<T>] {
        &self.tangent_impulse
    }

    /// The velocity of contact `k`'s point after resolving that contact once.
    #[inline]
    fn resolve(&mut self, k: usize, mut v: Vec3<T>, h: T, friction: &Friction<T>) -> Vec3<T> {
        let c = &self.contacts[k];
        let n = c.normal;
        // Normal: accumulate and clamp to a push (λ_n ≥ 0).
        let target = -c.gap / h;
        let old = self.normal_impulse[k];
        let acc = (old + (target - n.dot(&v))).max(T::zero());
        self.normal_impulse[k] = acc;
        v += n * (acc - old);
        // Friction: cancel the tangential velocity inside the static cone, else slide.
        let vt = v - n * n.dot(&v);
        let old_t = self.tangent_impulse[k];
        let wanted = old_t - vt;
        let new_t = friction.clamp(wanted, acc);
        self.tangent_impulse[k] = new_t;
        v + (new_t - old_t)
    }

    /// One sweep over the contacts, on coordinate slices of all points' velocities
    /// (`[x, y, z]`). Points with zero inverse mass are kinematic and left alone.
    pub fn sweep_soa(
        &mut self,
        h: T,
        friction: &Friction<T>,
        inv_masses: &[T],
        velocities: [&mut [T]; 3],
    ) {
        let [vx, vy, vz] = velocities;
        for k in 0..self.contacts.len() {
            let i = self.contacts[k].point as usize;
            if inv_masses[i] <= T::zero() {
                continue;
            }
            let v = self.resolve(k, Vec3::new(vx[i], vy[i], vz[i]), h, friction);
            (vx[i], vy[i], vz[i]) = (v.x, v.y, v.z);
        }
    }

    /// One sweep with the velocities split into even and odd points (the layout of
    /// [`crate::RedBlackSolver`]): point `i` is entry `i / 2` of `even` or `odd`.
    pub fn sweep_split(
        &mut self,
        h: T,
        friction: &Friction<T>,
        even_w: &[T],
        odd_w: &[T],
        even: &mut [Vec<T>; 3],
        odd: &mut [Vec<T>; 3],
    ) {
        for k in 0..self.contacts.len() {
            let i = self.contacts[k].point as usize;
            let (w, buf) = if i.is_multiple_of(2) {
                (even_w, &mut *even)
            } else {
                (odd_w, &mut *odd)
            };
            let j = i / 2;
            if w[j] <= T::zero() {
                continue;
            }
            let v = self.resolve(k, Vec3::new(buf[0][j], buf[1][j], buf[2][j]), h, friction);
            (buf[0][j], buf[1][j], buf[2][j]) = (v.x, v.y, v.z);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(gap: f64, v: Vec3<f64>, mu: (f64, f64), iterations: usize) -> (Vec3<f64>, f64) {
        let mut set = ContactSet::new();
        set.push(PointContact {
            point: 0,
            normal: Vec3::z(),
            gap,
        });
        let (mut x, mut y, mut z) = (vec![v.x], vec![v.y], vec![v.z]);
        let f = Friction {
            static_coefficient: mu.0,
            kinetic_coefficient: mu.1,
        };
        for _ in 0..iterations {
            set.sweep_soa(0.01, &f, &[1.0], [&mut x, &mut y, &mut z]);
        }
        (Vec3::new(x[0], y[0], z[0]), set.normal_impulses()[0])
    }

    #[test]
    fn a_penetrating_point_is_pushed_out_in_one_step() {
        let (v, ln) = one(-0.001, Vec3::new(0.0, 0.0, -1.0), (0.0, 0.0), 3);
        assert!((v.z - 0.1).abs() < 1e-12, "{v:?}");
        assert!((ln - 1.1).abs() < 1e-12);
    }

    #[test]
    fn a_separating_point_is_left_alone() {
        let (v, ln) = one(0.0, Vec3::new(0.3, 0.0, 2.0), (0.5, 0.4), 3);
        assert_eq!(v, Vec3::new(0.3, 0.0, 2.0));
        assert_eq!(ln, 0.0);
    }

    #[test]
    fn a_speculative_contact_allows_approach_up_to_the_surface() {
        // 1 mm away, moving at 1 m/s for 10 ms: it may only close the gap (0.1 m/s).
        let (v, _) = one(0.001, Vec3::new(0.0, 0.0, -1.0), (0.0, 0.0), 2);
        assert!((v.z + 0.1).abs() < 1e-12, "{v:?}");
    }

    #[test]
    fn friction_sticks_inside_the_cone_and_slides_outside() {
        // Normal impulse 1 m/s (stopping the fall), tangential 0.2: μs = 0.5 sticks.
        let (v, _) = one(0.0, Vec3::new(0.2, 0.0, -1.0), (0.5, 0.4), 5);
        assert!(v.x.abs() < 1e-12, "{v:?}");
        // Tangential 2.0 exceeds μs·1: slides, slowed by exactly μk · λn = 0.4.
        let (v, _) = one(0.0, Vec3::new(2.0, 0.0, -1.0), (0.5, 0.4), 5);
        assert!((v.x - 1.6).abs() < 1e-12, "{v:?}");
    }
}
