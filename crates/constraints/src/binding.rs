//! Binding constraints: an inner instrument (a guidewire) held on the centreline of an outer one
//! (a catheter) while it slides inside.
//!
//! The paper (section 2.1, "Constraints") defines binding constraints `C_b` as distance
//! constraints with rest length zero between the two rods, solved by local impulses in the same
//! iterations as the distance and contact constraints; section 3.4 runs them in three variants:
//! no interaction (v0), one-way (v1: the stiff catheter drives the soft wire, the wire does not
//! act back) and two-way (v2: each instrument influences the pair according to its mechanical
//! properties). Here:
//!
//! - Each inner point `i` is bound to the **nearest point of the outer centreline**,
//!   `c = (1 − s) r_j + s r_{j+1}` on outer segment `j`, found again at every step
//!   ([`BindingSet::update`]) by walking from last step's segment, so the wire can be advanced
//!   and retracted. Inner points whose nearest point would lie before the outer rod's first
//!   point or past its last point (the tip) are outside the catheter and free; so are points
//!   farther than `capture` from the centreline.
//! - The constraint removes only the **offset perpendicular to the outer segment**: with the
//!   zero-length vector constraint `p_i − c = 0` at the predicted positions `p = r + h v`, the
//!   component along the catheter would also stop the wire sliding within the step (an infinite
//!   axial friction). The axial direction is left free; friction of the wire in the lumen is
//!   not modelled.
//! - The offset present at step start is removed a fraction per step
//!   ([`DEFAULT_OFFSET_CORRECTION`]), the relative velocity in full.
//! - The impulse is the two-body impulse of a zero-length distance constraint,
//!   `J = −d⊥ / (h W)`, `W = w_i + (1 − s)² w_j + s² w_{j+1}` (`J Mᵀ⁻¹ Jᵀ` of the constraint),
//!   applied `+J` to `i` and `−(1 − s) J`, `−s J` to the outer segment's points (v2). In v1 the
//!   outer points are treated as kinematic for this constraint: `W = w_i` and they receive
//!   nothing. In v0 no binding exists.
//!
//! The clearance between the wire and the catheter's lumen is not modelled: a bound wire point
//! lies on the catheter's centreline at the end of each step.

use crate::velocities::PointVelocities;
use cosserat_model::{Real, Vec3};

/// Default fraction of a bound point's offset from the centreline removed per step.
///
/// A wire point entering the catheter (or re-entering past its tip) can be up to `capture` off
/// the centreline; removing that within one step would be a velocity kick of `offset / h`
/// (~200 m/s for 1 mm at h = 5 µs), which measured as the source of divergence in the
/// catheter–guidewire scene. Removing a fifth per step (Baumgarte-style) pulls it in over a few
/// steps; the relative velocity, which is what makes the wire follow a moving catheter, is
/// removed in full.
pub const DEFAULT_OFFSET_CORRECTION: f64 = 0.2;

/// How a binding couples the two instruments (paper section 3.4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BindingVariant {
    /// v0: no interaction; the instruments pass through each other.
    None,
    /// v1: one-way; the outer instrument moves the inner one and is not affected by it.
    OneWay,
    /// v2: two-way; ordinary two-body impulses, shared by inverse mass.
    #[default]
    TwoWay,
}

/// One bound inner point for the current step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundPoint<T: Real> {
    /// Inner point.
    pub point: u32,
    /// Outer segment (points `segment`, `segment + 1`).
    pub segment: u32,
    /// Parameter of the nearest point along the outer segment, in `[0, 1]`.
    pub s: T,
    /// Unit tangent of the outer segment at step start.
    pub tangent: Vec3<T>,
    /// `r_i − c` at step start.
    pub offset: Vec3<T>,
}

/// The binding between one inner and one outer rod: which points are bound this step, and the
/// nearest-segment cache that lets the search follow a sliding wire.
#[derive(Clone, Debug)]
pub struct BindingSet<T: Real> {
    /// The variant.
    pub variant: BindingVariant,
    /// Inner points farther than this from the outer centreline are not bound [m].
    pub capture: T,
    /// Fraction of the perpendicular offset present at step start that one step removes
    /// ([`DEFAULT_OFFSET_CORRECTION`]); the relative velocity is always removed in full.
    pub offset_correction: T,
    /// Last step's outer segment of each inner point (`u32::MAX`: none yet).
    cache: Vec<u32>,
    bound: Vec<BoundPoint<T>>,
}

/// Unclamped parameter of the projection of `p` onto segment `a → b`, and the segment vector.
#[inline]
fn project(p: Vec3<f64>, a: Vec3<f64>, b: Vec3<f64>) -> (f64, Vec3<f64>) {
    let e = b - a;
    let l2 = e.norm_squared();
    if l2 > 0.0 {
        ((p - a).dot(&e) / l2, e)
    } else {
        (0.0, e)
    }
}

impl<T: Real> BindingSet<T> {
    /// A binding for an inner rod of `inner_points` points.
    pub fn new(variant: BindingVariant, capture: T, inner_points: usize) -> Self {
        Self {
            variant,
            capture,
            offset_correction: T::lit(DEFAULT_OFFSET_CORRECTION),
            cache: vec![u32::MAX; inner_points],
            bound: Vec::new(),
        }
    }

    /// The points bound at the last [`Self::update`].
    pub fn bound(&self) -> &[BoundPoint<T>] {
        &self.bound
    }

    /// Finds, for every inner point, the nearest point on the outer centreline (positions at
    /// step start), and keeps those that are inside the outer rod.
    ///
    /// The search walks from the segment found at the previous step, so its cost is about one
    /// projection per point while the wire slides by less than an element per step; the first
    /// call searches all segments.
    pub fn update(&mut self, inner: &[Vec3<T>], outer: &[Vec3<T>]) {
        self.bound.clear();
        if self.variant == BindingVariant::None || outer.len() < 2 {
            return;
        }
        // In f64: the offset of a bound point from the centreline is tiny next to the
        // coordinates, and in f32 its rounding (~1e-7 m a metre from the origin) would come back
        // as a velocity kick of offset / h every step while the wire slides.
        let f = |v: &Vec3<T>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
        let back = |v: Vec3<f64>| Vec3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z));
        let m = outer.len() - 1;
        let cap2 = self.capture.to_f64() * self.capture.to_f64();
        let o = |k: usize| f(&outer[k]);
        for (i, p) in inner.iter().enumerate() {
            let p = f(p);
            let mut j = match self.cache[i] {
                u32::MAX => nearest_segment(p, outer),
                c => (c as usize).min(m - 1),
            };
            // Walk to the local minimum of the distance along the polyline.
            let (mut u, mut e) = project(p, o(j), o(j + 1));
            let mut steps = 0;
            let s = loop {
                steps += 1;
                if steps > m + 1 {
                    break u.clamp(0.0, 1.0);
                }
                if u > 1.0 && j + 1 < m {
                    let (u2, e2) = project(p, o(j + 1), o(j + 2));
                    if u2 < 0.0 {
                        break 1.0; // at the joint between j and j + 1
                    }
                    (j, u, e) = (j + 1, u2, e2);
                } else if u < 0.0 && j > 0 {
                    let (u2, e2) = project(p, o(j - 1), o(j));
                    if u2 > 1.0 {
                        break 0.0;
                    }
                    (j, u, e) = (j - 1, u2, e2);
                } else {
                    break u;
                }
            };
            self.cache[i] = j as u32;
            // Before the first point or past the tip: outside the outer instrument.
            if !(0.0..=1.0).contains(&s) {
                continue;
            }
            let offset = p - (o(j) + e * s);
            if offset.norm_squared() > cap2 {
                continue;
            }
            let len = e.norm();
            if !(len > 0.0) {
                continue;
            }
            self.bound.push(BoundPoint {
                point: i as u32,
                segment: j as u32,
                s: T::lit(s),
                tangent: back(e / len),
                offset: back(offset),
            });
        }
    }

    /// One sweep over the bound points: removes the perpendicular offset each would have at the
    /// end of the step.
    pub fn sweep<I, O>(&self, h: T, inner: &mut I, outer: &mut O)
    where
        I: PointVelocities<T>,
        O: PointVelocities<T>,
    {
        let two_way = match self.variant {
            BindingVariant::None => return,
            BindingVariant::OneWay => false,
            BindingVariant::TwoWay => true,
        };
        let one = T::one();
        for b in &self.bound {
            let (i, j) = (b.point as usize, b.segment as usize);
            let s = b.s;
            let wi = inner.inv_mass(i);
            let (wa, wb) = if two_way {
                (outer.inv_mass(j), outer.inv_mass(j + 1))
            } else {
                (T::zero(), T::zero())
            };
            let w = wi + (one - s) * (one - s) * wa + s * s * wb;
            if !(w > T::zero()) {
                continue;
            }
            let vc = outer.velocity(j) * (one - s) + outer.velocity(j + 1) * s;
            let d = b.offset * self.offset_correction + (inner.velocity(i) - vc) * h;
            let d_perp = d - b.tangent * b.tangent.dot(&d);
            let impulse = d_perp * (-one / (h * w));
            inner.apply_impulse(i, impulse);
            if two_way {
                outer.apply_impulse(j, impulse * (-(one - s)));
                outer.apply_impulse(j + 1, impulse * (-s));
            } else {
                // The outer point acts as kinematic: what it would have received is recorded
                // nowhere, as the outer instrument is not affected by the inner one.
            }
        }
    }
}

/// The segment of `outer` nearest to `p` (a full search).
fn nearest_segment<T: Real>(p: Vec3<f64>, outer: &[Vec3<T>]) -> usize {
    let f = |v: &Vec3<T>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
    let mut best = (f64::MAX, 0);
    for j in 0..outer.len() - 1 {
        let (a, b) = (f(&outer[j]), f(&outer[j + 1]));
        let (u, e) = project(p, a, b);
        let c = a + e * u.clamp(0.0, 1.0);
        let d2 = (p - c).norm_squared();
        if d2 < best.0 {
            best = (d2, j);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::velocities::{KinematicImpulses, SoaVelocities};

    fn line(n: usize, y: f64, dx: f64, x0: f64) -> Vec<Vec3<f64>> {
        (0..=n)
            .map(|i| Vec3::new(x0 + i as f64 * dx, y, 0.0))
            .collect()
    }

    #[test]
    fn points_past_the_tip_or_before_the_base_are_free() {
        // Outer from x = 0 to 1; inner from x = -0.5 to 1.5, 1 mm off the axis (exact binary steps).
        let outer = line(8, 0.0, 0.125, 0.0);
        let inner = line(16, 1e-3, 0.125, -0.5);
        let mut set = BindingSet::new(BindingVariant::TwoWay, 2e-3, inner.len());
        set.update(&inner, &outer);
        let bound: Vec<u32> = set.bound().iter().map(|b| b.point).collect();
        assert_eq!(bound, (4..=12).collect::<Vec<u32>>());
        for b in set.bound() {
            assert!((b.offset - Vec3::new(0.0, 1e-3, 0.0)).norm() < 1e-12);
        }
        // The wire slides by 2.5 outer segments: the walk follows it.
        let moved: Vec<_> = inner
            .iter()
            .map(|p| p + Vec3::new(0.3125, 0.0, 0.0))
            .collect();
        set.update(&moved, &outer);
        let first = set.bound()[0];
        assert_eq!(first.point, 2);
        assert_eq!(first.segment, 0);
        assert!((first.s - 0.5).abs() < 1e-9);
    }

    /// Two-way: momentum is conserved and the bound points meet at the mass-weighted centre; the
    /// axial relative velocity is untouched (the wire slides).
    #[test]
    fn two_way_binding_shares_by_inverse_mass_and_lets_the_wire_slide() {
        let outer_r = line(1, 0.0, 1.0, 0.0);
        let inner_r = vec![Vec3::new(0.25, 0.01, 0.0)];
        let mut set = BindingSet::new(BindingVariant::TwoWay, 1.0, 1);
        set.offset_correction = 1.0;
        set.update(&inner_r, &outer_r);
        let (wi, wo) = (1.0, 0.25); // the outer points are 4× heavier than the inner one
        let h = 0.01;
        let (mut ix, mut iy, mut iz) = (vec![0.3], vec![0.0], vec![0.0]);
        let (mut ox, mut oy, mut oz) = (vec![0.0; 2], vec![0.0; 2], vec![0.0; 2]);
        let (mut hi, mut ho): (KinematicImpulses<f64>, KinematicImpulses<f64>) =
            ([Vec3::zeros(); 2], [Vec3::zeros(); 2]);
        let (wiv, wov) = (vec![wi], vec![wo, wo]);
        let mut inner = SoaVelocities {
            v: [&mut ix, &mut iy, &mut iz],
            inv_masses: &wiv,
            held: &mut hi,
        };
        let mut outer = SoaVelocities {
            v: [&mut ox, &mut oy, &mut oz],
            inv_masses: &wov,
            held: &mut ho,
        };
        set.sweep(h, &mut inner, &mut outer);
        let vi = inner.velocity(0);
        let (va, vb) = (outer.velocity(0), outer.velocity(1));
        // Momentum along y is conserved.
        let p = vi.y / wi + (va.y + vb.y) / wo;
        assert!(p.abs() < 1e-12, "{p}");
        // The predicted offset vanishes.
        let vc = va * 0.75 + vb * 0.25;
        let gap = 0.01 + (vi.y - vc.y) * h;
        assert!(gap.abs() < 1e-12, "{gap}");
        // The axial velocity of the wire is unchanged.
        assert_eq!(vi.x, 0.3);
        // One-way: the outer points do not move.
        let mut set1 = BindingSet::new(BindingVariant::OneWay, 1.0, 1);
        set1.offset_correction = 1.0;
        set1.update(&inner_r, &outer_r);
        let mut iy1 = vec![0.0];
        let (mut ix1, mut iz1) = (vec![0.0], vec![0.0]);
        let mut oy1 = vec![0.0; 2];
        let (mut ox1, mut oz1) = (vec![0.0; 2], vec![0.0; 2]);
        let mut inner = SoaVelocities {
            v: [&mut ix1, &mut iy1, &mut iz1],
            inv_masses: &wiv,
            held: &mut hi,
        };
        let mut outer = SoaVelocities {
            v: [&mut ox1, &mut oy1, &mut oz1],
            inv_masses: &wov,
            held: &mut ho,
        };
        set1.sweep(h, &mut inner, &mut outer);
        assert!((inner.velocity(0).y + 0.01 / h).abs() < 1e-12);
        assert_eq!(outer.velocity(0), Vec3::zeros());
    }
}
