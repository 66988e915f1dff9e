//! Contact between two segments of rods (rod–rod and self-contact) with Coulomb friction.
//!
//! The paper (section "Collisions and self-collisions") finds touching parts of rods with a
//! bounding-sphere broad phase and solves the contacts as constraints with Coulomb friction in
//! the constraint iterations. The collision crate reports a contact between segment `a` (points
//! `a0 = segment_a`, `a1 = a0 + 1`) and segment `b` at the parameters `s`, `t` of their closest
//! points, `x_a = (1 − s) r_a0 + s r_a1`, `x_b = (1 − t) r_b0 + t r_b1`, with the unit normal
//! `n` from `x_b` to `x_a`. That is a constraint between four points, with the barycentric
//! weights as its Jacobian:
//!
//! - non-penetration `n · (v_a − v_b) ≥ −gap / h`, where `v_a = (1 − s) v_a0 + s v_a1` and
//!   `gap = |x_a − x_b| − (r_a + r_b)` at step start: at the end of the step the capsules touch
//!   or are apart. A speculative contact (positive gap, found with a margin) lets the segments
//!   approach up to touching but not past it, which is what keeps a tightly wound knot from
//!   slipping through itself between two detections.
//! - friction: the relative tangential velocity is removed while the accumulated tangential
//!   impulse stays in the static cone `μ_s λ_n`, else it is clamped to the kinetic cone
//!   `μ_k λ_n`.
//!
//! The effective inverse mass is `W = (1 − s)² w_a0 + s² w_a1 + (1 − t)² w_b0 + t² w_b1`, and
//! an impulse `P` [N s] goes `(1 − s) P`, `s P` to `a0`, `a1` and `−(1 − t) P`, `−t P` to `b0`,
//! `b1`: ordinary two-body impulses, so momentum is conserved and the lighter or softer rod
//! yields more. Impulses are accumulated over the iterations and clamped (projected
//! Gauss–Seidel), as for contacts with a mesh ([`crate::contact`]).

use crate::contact::Friction;
use crate::velocities::PointVelocities;
use cosserat_model::{Real, Vec3};

/// One contact between segment `segment_a` of rod `rod_a` and segment `segment_b` of rod
/// `rod_b` (the same rod for a self-contact).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentContact<T: Real> {
    /// First rod.
    pub rod_a: u32,
    /// Its segment (points `segment_a`, `segment_a + 1`).
    pub segment_a: u32,
    /// Parameter of the closest point along segment a.
    pub s: T,
    /// Second rod.
    pub rod_b: u32,
    /// Its segment.
    pub segment_b: u32,
    /// Parameter of the closest point along segment b.
    pub t: T,
    /// Unit normal from b to a.
    pub normal: Vec3<T>,
    /// Distance of the centrelines minus the sum of the radii at step start [m].
    pub gap: T,
}

/// The rod–rod contacts of one step with their accumulated impulses.
#[derive(Clone, Debug, Default)]
pub struct RodContactSet<T: Real> {
    contacts: Vec<SegmentContact<T>>,
    normal_impulse: Vec<T>,
    tangent_impulse: Vec<Vec3<T>>,
}

impl<T: Real> RodContactSet<T> {
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
    pub fn push(&mut self, c: SegmentContact<T>) {
        self.contacts.push(c);
        self.normal_impulse.push(T::zero());
        self.tangent_impulse.push(Vec3::zeros());
    }

    /// The contacts.
    pub fn contacts(&self) -> &[SegmentContact<T>] {
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

    /// Accumulated normal impulse of each contact [N s].
    pub fn normal_impulses(&self) -> &[T] {
        &self.normal_impulse
    }

    /// Accumulated friction impulse of each contact [N s].
    pub fn tangent_impulses(&self) -> &[Vec3<T>] {
        &self.tangent_impulse
    }

    /// One sweep over the contacts; `rods[k]` are the velocities of rod `k`.
    pub fn sweep<V: PointVelocities<T>>(&mut self, h: T, friction: &Friction<T>, rods: &mut [V]) {
        for k in 0..self.contacts.len() {
            let c = self.contacts[k];
            let (a, b) = (c.rod_a as usize, c.rod_b as usize);
            if a == b {
                self.resolve(k, h, friction, &mut rods[a], None);
            } else if let Ok([ra, rb]) = rods.get_disjoint_mut([a, b]) {
                self.resolve(k, h, friction, ra, Some(rb));
            }
        }
    }

    /// Resolves contact `k` once; `rb` is `None` for a self-contact (both segments in `ra`).
    #[inline(always)]
    fn resolve<V: PointVelocities<T>>(
        &mut self,
        k: usize,
        h: T,
        friction: &Friction<T>,
        ra: &mut V,
        mut rb: Option<&mut V>,
    ) {
        let c = self.contacts[k];
        let one = T::one();
        let (a0, b0) = (c.segment_a as usize, c.segment_b as usize);
        let (s, t, n) = (c.s, c.t, c.normal);
        let (sa, sb) = (one - s, one - t);
        macro_rules! rod_b {
            () => {
                match rb.as_deref_mut() {
                    Some(r) => r,
                    None => &mut *ra,
                }
            };
        }
        let wa = sa * sa * ra.inv_mass(a0) + s * s * ra.inv_mass(a0 + 1);
        let wb = {
            let r = rod_b!();
            sb * sb * r.inv_mass(b0) + t * t * r.inv_mass(b0 + 1)
        };
        let w = wa + wb;
        if !(w > T::zero()) {
            return;
        }
        let inv_w = one / w;
        let rel = |ra: &V, rb: &V| {
            (ra.velocity(a0) * sa + ra.velocity(a0 + 1) * s)
                - (rb.velocity(b0) * sb + rb.velocity(b0 + 1) * t)
        };
        let apply = |ra: &mut V, rb: Option<&mut V>, p: Vec3<T>| {
            ra.apply_impulse(a0, p * sa);
            ra.apply_impulse(a0 + 1, p * s);
            let r = match rb {
                Some(r) => r,
                None => ra,
            };
            r.apply_impulse(b0, p * (-sb));
            r.apply_impulse(b0 + 1, p * (-t));
        };
        // Normal: accumulate and clamp to a push (λ_n ≥ 0).
        let v = match rb.as_deref() {
            Some(r) => rel(ra, r),
            None => rel(ra, ra),
        };
        let old = self.normal_impulse[k];
        let acc = (old + (-c.gap / h - n.dot(&v)) * inv_w).max(T::zero());
        self.normal_impulse[k] = acc;
        let dn = acc - old;
        // Every point has a scalar inverse mass, so an impulse P changes the relative velocity
        // by exactly W P: the friction step can use the velocity after the normal impulse
        // without reading it back, and both go to the points in one application.
        let v = v + n * (dn * w);
        let vt = v - n * n.dot(&v);
        let old_t = self.tangent_impulse[k];
        let wanted = old_t - vt * inv_w;
        let new_t = friction.clamp(wanted, acc);
        self.tangent_impulse[k] = new_t;
        let p = n * dn + (new_t - old_t);
        if p != Vec3::zeros() {
            apply(ra, rb, p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::velocities::{KinematicImpulses, SoaVelocities};

    struct Rod {
        v: [Vec<f64>; 3],
        w: Vec<f64>,
        held: KinematicImpulses<f64>,
    }

    impl Rod {
        fn new(v: Vec3<f64>, w: f64) -> Self {
            Self {
                v: [vec![v.x; 2], vec![v.y; 2], vec![v.z; 2]],
                w: vec![w; 2],
                held: [Vec3::zeros(); 2],
            }
        }
        fn view(&mut self) -> SoaVelocities<'_, f64> {
            let [x, y, z] = &mut self.v;
            SoaVelocities {
                v: [x, y, z],
                inv_masses: &self.w,
                held: &mut self.held,
            }
        }
    }

    /// Two crossing segments approaching head-on: after the sweeps they just touch at the end
    /// of the step, momentum is conserved, and the heavier rod yields less.
    #[test]
    fn two_body_contact_conserves_momentum_and_shares_by_mass() {
        let friction = Friction {
            static_coefficient: 0.0,
            kinetic_coefficient: 0.0,
        };
        let (h, gap) = (1e-3, 1e-4);
        let (wa, wb) = (1.0, 0.25);
        let mut a = Rod::new(Vec3::new(0.0, 0.0, -1.0), wa);
        let mut b = Rod::new(Vec3::new(0.0, 0.0, 1.0), wb);
        let mut set = RodContactSet::new();
        set.push(SegmentContact {
            rod_a: 0,
            segment_a: 0,
            s: 0.5,
            rod_b: 1,
            segment_b: 0,
            t: 0.25,
            normal: Vec3::z(),
            gap,
        });
        let mut views = [a.view(), b.view()];
        for _ in 0..20 {
            set.sweep(h, &friction, &mut views);
        }
        let va = views[0].velocity(0) * 0.5 + views[0].velocity(1) * 0.5;
        let vb = views[1].velocity(0) * 0.75 + views[1].velocity(1) * 0.25;
        // Touching at the end of the step.
        assert!(((va.z - vb.z) * h + gap).abs() < 1e-12, "{va:?} {vb:?}");
        let momentum: f64 = (0..2)
            .map(|i| views[0].velocity(i).z / wa + views[1].velocity(i).z / wb)
            .sum();
        // Initially 2 × (−1) / wa + 2 × 1 / wb.
        let initial = -2.0 / wa + 2.0 / wb;
        assert!(
            (momentum - initial).abs() < 1e-12,
            "{momentum} vs {initial}"
        );
        let dva = (views[0].velocity(0).z + 1.0).abs();
        let dvb = (views[1].velocity(0).z - 1.0).abs();
        assert!(dva > dvb, "the lighter rod yields more: {dva} vs {dvb}");
    }

    /// Friction of a sliding pair: the relative tangential impulse is the kinetic cone.
    #[test]
    fn sliding_friction_is_the_kinetic_cone() {
        let friction = Friction {
            static_coefficient: 0.5,
            kinetic_coefficient: 0.4,
        };
        let h = 1e-3;
        let mut a = Rod::new(Vec3::new(2.0, 0.0, -1.0), 1.0);
        let mut b = Rod::new(Vec3::zeros(), 0.0); // kinematic
        let mut set = RodContactSet::new();
        set.push(SegmentContact {
            rod_a: 0,
            segment_a: 0,
            s: 0.5,
            rod_b: 1,
            segment_b: 0,
            t: 0.5,
            normal: Vec3::z(),
            gap: 0.0,
        });
        let mut views = [a.view(), b.view()];
        for _ in 0..30 {
            set.sweep(h, &friction, &mut views);
        }
        let ln = set.normal_impulses()[0];
        let lt = set.tangent_impulses()[0].norm();
        assert!((lt - 0.4 * ln).abs() < 1e-9 * ln, "{lt} vs {ln}");
        assert!(views[0].velocity(0).x < 2.0);
        // The kinematic rod took the opposite impulses on its end points.
        let held = views[1].held[0] + views[1].held[1];
        let on_a = (views[0].velocity(0) + views[0].velocity(1) - Vec3::new(4.0, 0.0, -2.0)) / 1.0;
        assert!((held + on_a).norm() < 1e-9, "{held:?} vs {on_a:?}");
    }
}
