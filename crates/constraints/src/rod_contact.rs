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
///
/// # Solver layout
///
/// The first [`sweep`](Self::sweep) after the contacts change gathers the points they touch
/// into one compact local array (velocity and inverse mass of each point, whatever rod and
/// layout it comes from) and precomputes each contact's row: the local indices of its four
/// points, its weights, `W`, `1 / W` and the bias `−gap / h`. Each sweep then copies the
/// touched points' velocities in, runs the projected Gauss–Seidel pass on the local array, and
/// hands each point the impulse that makes its change of velocity
/// ([`PointVelocities::apply_impulse`]; a kinematic end gets the sum of the impulses it
/// received, which the rod records as its reaction). The rows are ordered by level: a contact
/// comes after every earlier contact it shares a point with, and contacts sharing no point
/// are adjacent, so that consecutive contacts do not wait for each other. Contacts that share
/// a point keep their order, and contacts that share none commute, so the level order gives
/// the same result as the order the contacts were pushed in.
#[derive(Clone, Debug, Default)]
pub struct RodContactSet<T: Real> {
    contacts: Vec<SegmentContact<T>>,
    normal_impulse: Vec<T>,
    tangent_impulse: Vec<Vec3<T>>,
    /// Whether `rows` and `points` match `contacts` (and `h`).
    prepared: bool,
    prepared_h: T,
    /// The touched points: `(rod, point)`.
    points: Vec<(u32, u32)>,
    /// Per rod: point index → local index (`u32::MAX` for none); all `u32::MAX` between calls.
    lookup: Vec<Vec<u32>>,
    /// Local velocities `[x, y, z]` and inverse mass.
    local: Vec<[T; 4]>,
    /// Velocities of the local points at the start of the current sweep.
    start: Vec<[T; 3]>,
    /// Momentum each kinematic local point received in the current sweep (only kept if
    /// `any_kinematic`).
    received: Vec<[T; 3]>,
    any_kinematic: bool,
    /// Level of the last row that used each local point (scratch of the ordering).
    level: Vec<u32>,
    /// Level of each row, and the start of each level (scratch of the ordering).
    row_level: Vec<u32>,
    level_start: Vec<u32>,
    rows: Vec<Row<T>>,
    sorted: Vec<Row<T>>,
}

/// A contact in solver form (see [`RodContactSet`]).
#[derive(Clone, Copy, Debug, Default)]
struct Row<T: Real> {
    /// Index of the contact.
    k: u32,
    /// Local indices of `a0`, `a1`, `b0`, `b1`.
    p: [u32; 4],
    /// `1 − s`, `s`, `1 − t`, `t`.
    c: [T; 4],
    n: [T; 3],
    /// `−gap / h`.
    bias: T,
    w: T,
    inv_w: T,
    /// Whether one of the points is kinematic (its impulses are recorded).
    kinematic: bool,
}

impl<T: Real> RodContactSet<T> {
    /// An empty set.
    pub fn new() -> Self {
        Self {
            contacts: Vec::new(),
            normal_impulse: Vec::new(),
            tangent_impulse: Vec::new(),
            prepared: false,
            prepared_h: T::zero(),
            points: Vec::new(),
            lookup: Vec::new(),
            local: Vec::new(),
            start: Vec::new(),
            received: Vec::new(),
            any_kinematic: false,
            level: Vec::new(),
            row_level: Vec::new(),
            level_start: Vec::new(),
            rows: Vec::new(),
            sorted: Vec::new(),
        }
    }

    /// Removes all contacts, keeping the capacity.
    pub fn clear(&mut self) {
        self.contacts.clear();
        self.normal_impulse.clear();
        self.tangent_impulse.clear();
        self.prepared = false;
    }

    /// Adds a contact with zero accumulated impulse.
    pub fn push(&mut self, c: SegmentContact<T>) {
        self.contacts.push(c);
        self.normal_impulse.push(T::zero());
        self.tangent_impulse.push(Vec3::zeros());
        self.prepared = false;
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

    /// Local index of point `i` of rod `r`, adding it if new.
    fn local_index<V: PointVelocities<T>>(&mut self, rods: &[V], r: u32, i: u32) -> u32 {
        let map = &mut self.lookup[r as usize];
        if map.len() <= i as usize {
            map.resize(i as usize + 1, u32::MAX);
        }
        let slot = &mut map[i as usize];
        if *slot == u32::MAX {
            *slot = self.points.len() as u32;
            self.points.push((r, i));
            let rod = &rods[r as usize];
            let v = rod.velocity(i as usize);
            self.local.push([v.x, v.y, v.z, rod.inv_mass(i as usize)]);
            self.level.push(0);
        }
        *slot
    }

    /// Builds the solver layout (see the type's docs).
    fn prepare<V: PointVelocities<T>>(&mut self, h: T, rods: &[V]) {
        let one = T::one();
        self.points.clear();
        self.local.clear();
        self.level.clear();
        self.rows.clear();
        self.row_level.clear();
        if self.lookup.len() < rods.len() {
            self.lookup.resize(rods.len(), Vec::new());
        }
        let mut levels = 0;
        for k in 0..self.contacts.len() {
            let c = self.contacts[k];
            if c.rod_a as usize >= rods.len() || c.rod_b as usize >= rods.len() {
                continue;
            }
            let (a0, b0) = (c.segment_a, c.segment_b);
            let p = [
                self.local_index(rods, c.rod_a, a0),
                self.local_index(rods, c.rod_a, a0 + 1),
                self.local_index(rods, c.rod_b, b0),
                self.local_index(rods, c.rod_b, b0 + 1),
            ];
            let (s, t) = (c.s, c.t);
            let (sa, sb) = (one - s, one - t);
            let im = |j: usize| self.local[p[j] as usize][3];
            let wa = sa * sa * im(0) + s * s * im(1);
            let wb = sb * sb * im(2) + t * t * im(3);
            let w = wa + wb;
            if !(w > T::zero()) {
                continue;
            }
            let level = p.iter().map(|&j| self.level[j as usize]).max().unwrap_or(0) + 1;
            for &j in &p {
                self.level[j as usize] = level;
            }
            levels = levels.max(level);
            self.row_level.push(level);
            self.rows.push(Row {
                k: k as u32,
                p,
                c: [sa, s, sb, t],
                n: [c.normal.x, c.normal.y, c.normal.z],
                bias: -c.gap / h,
                w,
                inv_w: one / w,
                kinematic: (0..4).any(|j| !(im(j) > T::zero())),
            });
        }
        // Level order, stable within a level: a counting sort on the rows' levels.
        if levels > 1 {
            let start = &mut self.level_start;
            start.clear();
            start.resize(levels as usize + 1, 0);
            for &l in &self.row_level {
                start[l as usize] += 1;
            }
            let mut sum = 0;
            for x in start.iter_mut() {
                (*x, sum) = (sum, sum + *x);
            }
            self.sorted.clear();
            self.sorted.resize(self.rows.len(), Row::default());
            for (r, &l) in self.rows.iter().zip(&self.row_level) {
                let slot = &mut start[l as usize];
                self.sorted[*slot as usize] = *r;
                *slot += 1;
            }
            std::mem::swap(&mut self.rows, &mut self.sorted);
        }
        for &(r, i) in &self.points {
            self.lookup[r as usize][i as usize] = u32::MAX;
        }
        self.any_kinematic = self.rows.iter().any(|r| r.kinematic);
        self.received.clear();
        self.received.resize(self.points.len(), [T::zero(); 3]);
        self.prepared = true;
        self.prepared_h = h;
    }

    /// One sweep over the contacts; `rods[k]` are the velocities of rod `k`.
    pub fn sweep<V: PointVelocities<T>>(&mut self, h: T, friction: &Friction<T>, rods: &mut [V]) {
        if self.contacts.is_empty() {
            return;
        }
        if !self.prepared || self.prepared_h != h {
            self.prepare(h, rods);
        } else {
            for (l, &(r, i)) in self.local.iter_mut().zip(&self.points) {
                let v = rods[r as usize].velocity(i as usize);
                l[0] = v.x;
                l[1] = v.y;
                l[2] = v.z;
            }
        }
        self.start.clear();
        self.start
            .extend(self.local.iter().map(|l| [l[0], l[1], l[2]]));
        if self.any_kinematic {
            self.received.fill([T::zero(); 3]);
        }
        let zero = T::zero();
        let local = &mut self.local[..];
        let received = &mut self.received[..];
        for row in &self.rows {
            let k = row.k as usize;
            let [i0, i1, i2, i3] = row.p.map(|j| j as usize);
            let [sa, s, sb, t] = row.c;
            let n = Vec3::new(row.n[0], row.n[1], row.n[2]);
            let vel = |l: &[T; 4]| Vec3::new(l[0], l[1], l[2]);
            let v = (vel(&local[i0]) * sa + vel(&local[i1]) * s)
                - (vel(&local[i2]) * sb + vel(&local[i3]) * t);
            // Normal: accumulate and clamp to a push (λ_n ≥ 0).
            let old = self.normal_impulse[k];
            let acc = (old + (row.bias - n.dot(&v)) * row.inv_w).max(zero);
            if acc == zero && old == zero {
                // Apart and staying apart: no push, hence no friction either (the tangential
                // impulse is clamped to a zero cone, as it was at the last sweep).
                continue;
            }
            self.normal_impulse[k] = acc;
            let dn = acc - old;
            // Every point has a scalar inverse mass, so an impulse P changes the relative
            // velocity by exactly W P: the friction step can use the velocity after the normal
            // impulse without reading it back, and both go to the points in one application.
            let v = v + n * (dn * row.w);
            let vt = v - n * n.dot(&v);
            let old_t = self.tangent_impulse[k];
            let wanted = old_t - vt * row.inv_w;
            let new_t = friction.clamp(wanted, acc);
            self.tangent_impulse[k] = new_t;
            let p = n * dn + (new_t - old_t);
            if p != Vec3::zeros() {
                for (j, c) in [(i0, sa), (i1, s), (i2, -sb), (i3, -t)] {
                    let q = p * c;
                    let l = &mut local[j];
                    let w = l[3];
                    l[0] += q.x * w;
                    l[1] += q.y * w;
                    l[2] += q.z * w;
                }
                if row.kinematic {
                    for (j, c) in [(i0, sa), (i1, s), (i2, -sb), (i3, -t)] {
                        let q = p * c;
                        let r = &mut received[j];
                        r[0] += q.x;
                        r[1] += q.y;
                        r[2] += q.z;
                    }
                }
            }
        }
        // Hand the points their change: a moving point the impulse that makes it, a kinematic
        // one the impulses it received (recorded as its reaction).
        for (j, &(rod, i)) in self.points.iter().enumerate() {
            let (l, v0) = (&self.local[j], &self.start[j]);
            let w = l[3];
            let impulse = if w > zero {
                [(l[0] - v0[0]) / w, (l[1] - v0[1]) / w, (l[2] - v0[2]) / w]
            } else if self.any_kinematic {
                self.received[j]
            } else {
                continue;
            };
            if impulse != [zero; 3] {
                rods[rod as usize]
                    .apply_impulse(i as usize, Vec3::new(impulse[0], impulse[1], impulse[2]));
            }
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

    /// The sweep as first written: contact by contact in push order, straight on the rods'
    /// velocities.
    fn reference_sweep(
        set: &mut RodContactSet<f64>,
        h: f64,
        friction: &Friction<f64>,
        rods: &mut [SoaVelocities<'_, f64>],
    ) {
        for k in 0..set.contacts.len() {
            let c = set.contacts[k];
            let (a0, b0) = (c.segment_a as usize, c.segment_b as usize);
            let (s, t, n) = (c.s, c.t, c.normal);
            let (sa, sb) = (1.0 - s, 1.0 - t);
            let (ra, rb) = (c.rod_a as usize, c.rod_b as usize);
            let w = sa * sa * rods[ra].inv_mass(a0)
                + s * s * rods[ra].inv_mass(a0 + 1)
                + sb * sb * rods[rb].inv_mass(b0)
                + t * t * rods[rb].inv_mass(b0 + 1);
            if !(w > 0.0) {
                continue;
            }
            let v = (rods[ra].velocity(a0) * sa + rods[ra].velocity(a0 + 1) * s)
                - (rods[rb].velocity(b0) * sb + rods[rb].velocity(b0 + 1) * t);
            let old = set.normal_impulse[k];
            let acc = (old + (-c.gap / h - n.dot(&v)) / w).max(0.0);
            set.normal_impulse[k] = acc;
            let dn = acc - old;
            let v = v + n * (dn * w);
            let vt = v - n * n.dot(&v);
            let old_t = set.tangent_impulse[k];
            let new_t = friction.clamp(old_t - vt / w, acc);
            set.tangent_impulse[k] = new_t;
            let p = n * dn + (new_t - old_t);
            rods[ra].apply_impulse(a0, p * sa);
            rods[ra].apply_impulse(a0 + 1, p * s);
            rods[rb].apply_impulse(b0, p * (-sb));
            rods[rb].apply_impulse(b0 + 1, p * (-t));
        }
    }

    /// Many overlapping contacts within and between three rods (some points kinematic): the
    /// level-ordered sweep on the local layout gives what the contact-by-contact sweep gives,
    /// velocities, impulses and the impulses recorded on held ends alike.
    #[test]
    fn local_level_ordered_sweep_matches_the_sequential_sweep() {
        // A small deterministic generator (no dependency).
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let points = 12;
        let make = |rnd: &mut dyn FnMut() -> f64| -> Vec<Rod> {
            (0..3)
                .map(|r| {
                    let mut rod = Rod::new(Vec3::zeros(), 1.0);
                    rod.v = [0, 1, 2].map(|_| (0..points).map(|_| rnd() - 0.5).collect());
                    rod.w = (0..points)
                        .map(|i| {
                            if r == 1 && (i == 0 || i == points - 1) {
                                0.0
                            } else {
                                0.5 + rnd()
                            }
                        })
                        .collect();
                    rod
                })
                .collect()
        };
        let mut a = make(&mut rnd);
        let mut b: Vec<Rod> = a
            .iter()
            .map(|r| Rod {
                v: r.v.clone(),
                w: r.w.clone(),
                held: r.held,
            })
            .collect();
        let mut set = RodContactSet::new();
        for _ in 0..60 {
            let (ra, rb) = ((rnd() * 3.0) as u32, (rnd() * 3.0) as u32);
            let n = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
            set.push(SegmentContact {
                rod_a: ra,
                segment_a: (rnd() * (points - 1) as f64) as u32,
                s: rnd(),
                rod_b: rb,
                segment_b: (rnd() * (points - 1) as f64) as u32,
                t: rnd(),
                normal: n,
                gap: 2e-3 * (rnd() - 0.7),
            });
        }
        let mut reference = set.clone();
        let friction = Friction {
            static_coefficient: 0.4,
            kinetic_coefficient: 0.3,
        };
        let h = 1e-2;
        let mut va: Vec<_> = a.iter_mut().map(Rod::view).collect();
        let mut vb: Vec<_> = b.iter_mut().map(Rod::view).collect();
        for _ in 0..10 {
            set.sweep(h, &friction, &mut va);
            reference_sweep(&mut reference, h, &friction, &mut vb);
        }
        assert!(set.normal_impulses().iter().any(|&x| x > 0.0));
        for (x, y) in set
            .normal_impulses()
            .iter()
            .zip(reference.normal_impulses())
        {
            assert!((x - y).abs() < 1e-12, "{x} vs {y}");
        }
        for (x, y) in set
            .tangent_impulses()
            .iter()
            .zip(reference.tangent_impulses())
        {
            assert!((x - y).norm() < 1e-12, "{x:?} vs {y:?}");
        }
        for (ra, rb) in va.iter().zip(&vb) {
            for i in 0..points {
                let d = ra.velocity(i) - rb.velocity(i);
                assert!(d.norm() < 1e-12, "{i}: {d:?}");
            }
            for e in 0..2 {
                assert!((ra.held[e] - rb.held[e]).norm() < 1e-12);
            }
        }
        assert!(vb[1].held[0].norm() + vb[1].held[1].norm() > 0.0 || va[1].held[0].norm() == 0.0);
    }
}
