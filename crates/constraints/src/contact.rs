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
///
/// Each contact moves only its own point and a point has at most one contact, so the contacts
/// of a sweep do not interact: a sweep gathers the velocities of the contact points into
/// contiguous arrays, resolves all contacts in one branch-free loop that the compiler turns
/// into SIMD code, and scatters the velocities back. The result is that of resolving the
/// contacts one after another.
#[derive(Clone, Debug, Default)]
pub struct ContactSet<T: Real> {
    /// The point of each contact.
    point: Vec<u32>,
    /// Normals, coordinate by coordinate.
    normal: [Vec<T>; 3],
    gap: Vec<T>,
    normal_impulse: Vec<T>,
    /// Accumulated tangential impulses, coordinate by coordinate.
    tangent_impulse: [Vec<T>; 3],
    /// Scratch of a sweep: the contact points' velocities and inverse masses.
    v: [Vec<T>; 3],
    inv_mass: Vec<T>,
    /// Whether the contacts carry surfaces of their own ([`Self::push_on`]): then `mu_s`,
    /// `mu_k` and `wall` hold one entry per contact (a NaN friction: the sweep's).
    surfaces: bool,
    mu_s: Vec<T>,
    mu_k: Vec<T>,
    /// The velocity of the surface under each contact, coordinate by coordinate [m/s].
    wall: [Vec<T>; 3],
}

impl<T: Real> ContactSet<T> {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Removes all contacts, keeping the capacity.
    pub fn clear(&mut self) {
        self.point.clear();
        self.gap.clear();
        self.normal_impulse.clear();
        for c in 0..3 {
            self.normal[c].clear();
            self.tangent_impulse[c].clear();
            self.wall[c].clear();
        }
        self.mu_s.clear();
        self.mu_k.clear();
        self.surfaces = false;
    }

    /// Adds a contact with zero accumulated impulse, on a static surface with the sweep's
    /// friction.
    pub fn push(&mut self, c: PointContact<T>) {
        self.point.push(c.point);
        self.gap.push(c.gap);
        self.normal_impulse.push(T::zero());
        for k in 0..3 {
            self.normal[k].push(c.normal[k]);
            self.tangent_impulse[k].push(T::zero());
        }
        if self.surfaces {
            self.push_surface(None, Vec3::zeros());
        }
    }

    /// Adds a contact with zero accumulated impulse on a surface of its own: its `friction`
    /// (instead of the sweep's) and the surface's velocity `wall` at the contact [m/s]. The
    /// contact then constrains the point's velocity relative to the surface: it may not
    /// approach it faster than its gap allows, and friction acts against its sliding on it (a
    /// moving floor drags a resting rod along).
    pub fn push_on(&mut self, c: PointContact<T>, friction: Friction<T>, wall: Vec3<T>) {
        self.enable_surfaces();
        self.push(c);
        self.put_surface(self.point.len() - 1, friction, wall);
    }

    /// [`Self::set`] on a surface of its own (as [`Self::push_on`]).
    pub fn set_on(&mut self, c: PointContact<T>, friction: Friction<T>, wall: Vec3<T>) {
        self.enable_surfaces();
        self.set(c);
        if let Some(k) = self.point.iter().position(|&p| p == c.point) {
            self.put_surface(k, friction, wall);
        }
    }

    /// Gives every contact so far the sweep's surface, and later ones a surface each.
    fn enable_surfaces(&mut self) {
        if !self.surfaces {
            self.surfaces = true;
            for _ in 0..self.point.len() {
                self.push_surface(None, Vec3::zeros());
            }
        }
    }

    fn put_surface(&mut self, k: usize, friction: Friction<T>, wall: Vec3<T>) {
        self.mu_s[k] = friction.static_coefficient;
        self.mu_k[k] = friction.kinetic_coefficient;
        for c in 0..3 {
            self.wall[c][k] = wall[c];
        }
    }

    fn push_surface(&mut self, friction: Option<Friction<T>>, wall: Vec3<T>) {
        let nan = T::lit(f64::NAN);
        self.mu_s
            .push(friction.map_or(nan, |f| f.static_coefficient));
        self.mu_k
            .push(friction.map_or(nan, |f| f.kinetic_coefficient));
        for c in 0..3 {
            self.wall[c].push(wall[c]);
        }
    }

    /// Makes `c` the contact of its point: replaces the point's contact (its impulses reset)
    /// if it has one, else pushes it.
    pub fn set(&mut self, c: PointContact<T>) {
        let Some(i) = self.point.iter().position(|&p| p == c.point) else {
            self.push(c);
            return;
        };
        self.gap[i] = c.gap;
        self.normal_impulse[i] = T::zero();
        for k in 0..3 {
            self.normal[k][i] = c.normal[k];
            self.tangent_impulse[k][i] = T::zero();
        }
    }

    /// The contacts, in the order they were pushed.
    pub fn contacts(&self) -> impl ExactSizeIterator<Item = PointContact<T>> + '_ {
        let [x, y, z] = &self.normal;
        (0..self.point.len()).map(|k| PointContact {
            point: self.point[k],
            normal: Vec3::new(x[k], y[k], z[k]),
            gap: self.gap[k],
        })
    }

    /// Number of contacts.
    pub fn len(&self) -> usize {
        self.point.len()
    }

    /// Whether there are no contacts.
    pub fn is_empty(&self) -> bool {
        self.point.is_empty()
    }

    /// Accumulated normal impulse of each contact, as a velocity change [m/s]; multiply by the
    /// point's mass and divide by the step for the contact force.
    pub fn normal_impulses(&self) -> &[T] {
        &self.normal_impulse
    }

    /// Accumulated tangential (friction) impulse of each contact, as a velocity change [m/s].
    pub fn tangent_impulses(&self) -> impl ExactSizeIterator<Item = Vec3<T>> + '_ {
        let [x, y, z] = &self.tangent_impulse;
        (0..x.len()).map(|k| Vec3::new(x[k], y[k], z[k]))
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
        let m = inv_masses.len();
        let (vx, vy, vz) = (&mut vx[..m], &mut vy[..m], &mut vz[..m]);
        let n = self.start_sweep();
        for k in 0..n {
            let i = self.point[k] as usize;
            self.inv_mass[k] = inv_masses[i];
            (self.v[0][k], self.v[1][k], self.v[2][k]) = (vx[i], vy[i], vz[i]);
        }
        self.resolve_all(h, friction);
        for k in 0..n {
            let i = self.point[k] as usize;
            (vx[i], vy[i], vz[i]) = (self.v[0][k], self.v[1][k], self.v[2][k]);
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
        let (me, mo) = (even_w.len(), odd_w.len());
        let [ex, ey, ez] = even;
        let (ex, ey, ez) = (&mut ex[..me], &mut ey[..me], &mut ez[..me]);
        let [ox, oy, oz] = odd;
        let (ox, oy, oz) = (&mut ox[..mo], &mut oy[..mo], &mut oz[..mo]);
        let n = self.start_sweep();
        for k in 0..n {
            let i = self.point[k] as usize;
            let j = i / 2;
            let (w, x, y, z) = if i.is_multiple_of(2) {
                (even_w[j], ex[j], ey[j], ez[j])
            } else {
                (odd_w[j], ox[j], oy[j], oz[j])
            };
            self.inv_mass[k] = w;
            (self.v[0][k], self.v[1][k], self.v[2][k]) = (x, y, z);
        }
        self.resolve_all(h, friction);
        for k in 0..n {
            let i = self.point[k] as usize;
            let j = i / 2;
            let v = (self.v[0][k], self.v[1][k], self.v[2][k]);
            if i.is_multiple_of(2) {
                (ex[j], ey[j], ez[j]) = v;
            } else {
                (ox[j], oy[j], oz[j]) = v;
            }
        }
    }

    /// Sizes the sweep's scratch to the contacts; returns their number.
    fn start_sweep(&mut self) -> usize {
        let n = self.point.len();
        self.inv_mass.resize(n, T::zero());
        for c in &mut self.v {
            c.resize(n, T::zero());
        }
        n
    }

    /// Resolves every contact once on the gathered velocities.
    ///
    /// Normal: the accumulated impulse is clamped to a push (`λ_n ≥ 0`). Friction: the
    /// tangential velocity is cancelled inside the static cone, else the impulse slides on the
    /// kinetic cone ([`Friction::clamp`], written here without branches). A kinematic point
    /// (zero inverse mass) keeps its velocity and its contact's impulses stay zero.
    ///
    /// Contacts on surfaces of their own ([`Self::push_on`]) are resolved on the velocities
    /// relative to their surface, with their own friction.
    fn resolve_all(&mut self, h: T, friction: &Friction<T>) {
        let n = self.point.len();
        let surfaces = self.surfaces;
        if surfaces {
            for c in 0..3 {
                for (v, w) in self.v[c][..n].iter_mut().zip(&self.wall[c][..n]) {
                    *v -= *w;
                }
            }
        }
        let (fs, fk) = (friction.static_coefficient, friction.kinetic_coefficient);
        let zero = T::zero();
        let one = T::one();
        let [nx, ny, nz] = &self.normal;
        let (nx, ny, nz, gap) = (&nx[..n], &ny[..n], &nz[..n], &self.gap[..n]);
        let inv_mass = &self.inv_mass[..n];
        let ln = &mut self.normal_impulse[..n];
        let [tx, ty, tz] = &mut self.tangent_impulse;
        let (tx, ty, tz) = (&mut tx[..n], &mut ty[..n], &mut tz[..n]);
        let [vx, vy, vz] = &mut self.v;
        let (vx, vy, vz) = (&mut vx[..n], &mut vy[..n], &mut vz[..n]);
        for k in 0..n {
            let (mu_s, mu_k) = if surfaces && self.mu_s[k] >= zero {
                (self.mu_s[k], self.mu_k[k])
            } else {
                (fs, fk)
            };
            let active = inv_mass[k] > zero;
            let (x, y, z) = (vx[k], vy[k], vz[k]);
            let (ax, ay, az) = (nx[k], ny[k], nz[k]);
            // Normal: accumulate and clamp to a push.
            let target = -gap[k] / h;
            let old = ln[k];
            let vn = ax * x + ay * y + az * z;
            let pushed = (old + (target - vn)).max(zero);
            let acc = if active { pushed } else { old };
            ln[k] = acc;
            let d = acc - old;
            let (x, y, z) = (x + ax * d, y + ay * d, z + az * d);
            // Friction: the impulse that would stop the sliding, kept inside the static cone,
            // else scaled onto the kinetic cone.
            let vn = ax * x + ay * y + az * z;
            let (ux, uy, uz) = (x - ax * vn, y - ay * vn, z - az * vn);
            let (ox, oy, oz) = (tx[k], ty[k], tz[k]);
            let (wx, wy, wz) = (ox - ux, oy - uy, oz - uz);
            let norm = (wx * wx + wy * wy + wz * wz).sqrt();
            let scale = if norm <= mu_s * acc {
                one
            } else {
                mu_k * acc / norm
            };
            let (px, py, pz) = if active {
                (wx * scale, wy * scale, wz * scale)
            } else {
                (ox, oy, oz)
            };
            (tx[k], ty[k], tz[k]) = (px, py, pz);
            (vx[k], vy[k], vz[k]) = (x + (px - ox), y + (py - oy), z + (pz - oz));
        }
        if surfaces {
            for c in 0..3 {
                for (v, w) in self.v[c][..n].iter_mut().zip(&self.wall[c][..n]) {
                    *v += *w;
                }
            }
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

    /// Resolves the contacts one at a time, written directly from the definition: the oracle
    /// for the branch-free sweep.
    fn sequential_sweep(
        contacts: &[PointContact<f64>],
        impulses: &mut [(f64, Vec3<f64>)],
        h: f64,
        friction: &Friction<f64>,
        inv_masses: &[f64],
        v: &mut [Vec3<f64>],
    ) {
        for (c, (ln, lt)) in contacts.iter().zip(impulses) {
            let i = c.point as usize;
            if inv_masses[i] <= 0.0 {
                continue;
            }
            let n = c.normal;
            let old = *ln;
            *ln = (old + (-c.gap / h - n.dot(&v[i]))).max(0.0);
            v[i] += n * (*ln - old);
            let vt = v[i] - n * n.dot(&v[i]);
            let new_t = friction.clamp(*lt - vt, *ln);
            v[i] += new_t - *lt;
            *lt = new_t;
        }
    }

    #[test]
    fn the_sweep_matches_resolving_contacts_one_at_a_time() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let friction = Friction {
            static_coefficient: 0.3,
            kinetic_coefficient: 0.2,
        };
        let h = 1e-4;
        for trial in 0..20 {
            let points = 64;
            let mut inv_masses: Vec<f64> =
                (0..points).map(|_| rng.random_range(0.5..2.0)).collect();
            inv_masses[0] = 0.0;
            inv_masses[points - 1] = 0.0;
            let mut v: Vec<Vec3<f64>> = (0..points)
                .map(|_| Vec3::from_fn(|_, _| rng.random_range(-1.0..1.0)))
                .collect();
            let mut set = ContactSet::new();
            for i in 0..points {
                if rng.random_bool(0.6) {
                    set.push(PointContact {
                        point: i as u32,
                        normal: Vec3::from_fn(|_, _| rng.random_range(-1.0..1.0)).normalize(),
                        gap: rng.random_range(-2e-4..1e-4),
                    });
                }
            }
            let mut expected_v = v.clone();
            let mut impulses = vec![(0.0, Vec3::zeros()); set.len()];
            let split = trial % 2 == 1;
            let (mut even, mut odd) = (
                [
                    vec![0.0; points / 2],
                    vec![0.0; points / 2],
                    vec![0.0; points / 2],
                ],
                [
                    vec![0.0; points / 2],
                    vec![0.0; points / 2],
                    vec![0.0; points / 2],
                ],
            );
            let even_w: Vec<f64> = inv_masses.iter().step_by(2).copied().collect();
            let odd_w: Vec<f64> = inv_masses.iter().skip(1).step_by(2).copied().collect();
            for _ in 0..5 {
                sequential_sweep(
                    &set.contacts().collect::<Vec<_>>(),
                    &mut impulses,
                    h,
                    &friction,
                    &inv_masses,
                    &mut expected_v,
                );
                if split {
                    for (i, w) in v.iter().enumerate() {
                        let buf = if i % 2 == 0 { &mut even } else { &mut odd };
                        for c in 0..3 {
                            buf[c][i / 2] = w[c];
                        }
                    }
                    set.sweep_split(h, &friction, &even_w, &odd_w, &mut even, &mut odd);
                    for (i, w) in v.iter_mut().enumerate() {
                        let buf = if i % 2 == 0 { &even } else { &odd };
                        *w = Vec3::new(buf[0][i / 2], buf[1][i / 2], buf[2][i / 2]);
                    }
                } else {
                    let mut x: Vec<f64> = v.iter().map(|w| w.x).collect();
                    let mut y: Vec<f64> = v.iter().map(|w| w.y).collect();
                    let mut z: Vec<f64> = v.iter().map(|w| w.z).collect();
                    set.sweep_soa(h, &friction, &inv_masses, [&mut x, &mut y, &mut z]);
                    for (i, w) in v.iter_mut().enumerate() {
                        *w = Vec3::new(x[i], y[i], z[i]);
                    }
                }
                // Move the velocities a little, as the distance constraints would.
                for w in v.iter_mut().chain(expected_v.iter_mut()) {
                    *w *= 0.97;
                }
            }
            for (a, b) in v.iter().zip(&expected_v) {
                assert!((a - b).norm() <= 1e-12 * (1.0 + b.norm()), "{a:?} vs {b:?}");
            }
            for (k, ((ln, lt), t)) in impulses.iter().zip(set.tangent_impulses()).enumerate() {
                assert!((set.normal_impulses()[k] - ln).abs() <= 1e-12 * (1.0 + ln.abs()));
                assert!((t - lt).norm() <= 1e-12 * (1.0 + lt.norm()));
            }
            assert!(impulses.iter().any(|(ln, lt)| *ln > 0.0 && lt.norm() > 0.0));
        }
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

    #[test]
    fn a_contact_on_a_moving_surface_of_its_own_friction_acts_on_the_relative_velocity() {
        let sweep_friction = Friction {
            static_coefficient: 0.0,
            kinetic_coefficient: 0.0,
        };
        let sticky = Friction {
            static_coefficient: 1.0,
            kinetic_coefficient: 1.0,
        };
        let h = 1e-3;
        // A point at rest on a floor rising at 0.3 m/s and moving along x at 0.2 m/s, with a
        // static contact beside it (the sweep's frictionless surface) on point 1 sliding at 1 m/s.
        let mut set = ContactSet::new();
        set.push(PointContact {
            point: 1,
            normal: Vec3::z(),
            gap: 0.0,
        });
        set.push_on(
            PointContact {
                point: 0,
                normal: Vec3::z(),
                gap: 0.0,
            },
            sticky,
            Vec3::new(0.2, 0.0, 0.3),
        );
        let (mut x, mut y, mut z) = (vec![0.0_f64, 1.0], vec![0.0, 0.0], vec![0.0_f64, -0.5]);
        for _ in 0..3 {
            set.sweep_soa(h, &sweep_friction, &[1.0, 1.0], [&mut x, &mut y, &mut z]);
        }
        // Lifted with the floor and carried along: static friction holds it (|Δv_t| = 0.2
        // within μ_s times the normal push 0.3).
        assert!(
            (z[0] - 0.3).abs() < 1e-12 && (x[0] - 0.2).abs() < 1e-12,
            "{x:?} {z:?}"
        );
        // The other contact keeps the sweep's (frictionless, static) surface.
        assert!(
            z[1].abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12,
            "{x:?} {z:?}"
        );
        // Too little friction to carry it: it slides at the kinetic cone.
        let slippery = Friction {
            static_coefficient: 0.5,
            kinetic_coefficient: 0.5,
        };
        set.clear();
        set.push_on(
            PointContact {
                point: 0,
                normal: Vec3::z(),
                gap: 0.0,
            },
            slippery,
            Vec3::new(0.2, 0.0, 0.3),
        );
        let (mut x, mut y, mut z) = (vec![0.0_f64], vec![0.0], vec![0.0_f64]);
        set.sweep_soa(h, &sweep_friction, &[1.0], [&mut x, &mut y, &mut z]);
        // (μ_k times the push 0.3 is 0.15 of the 0.2 it would need.)
        assert!(
            (z[0] - 0.3).abs() < 1e-12 && (x[0] - 0.15).abs() < 1e-12,
            "{x:?} {z:?}"
        );
    }
}
