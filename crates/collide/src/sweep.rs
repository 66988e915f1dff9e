//! Swept point tests: did a point that moved along a segment cross the wall on its way?
//!
//! The sphere queries of [`crate::contact`] see a wall only within a point's radius of where the
//! point *is*. A point that moves farther than its radius in one step (a stiff wire snapping
//! sideways, a large step) can end beyond a wall, or beyond a thin ridge, with no triangle
//! within reach, or with the far side's triangles nearest and its sign wrong. The swept test
//! closes that gap: the segment from where the point was (known to be in the lumen) to where it
//! is now is intersected with every triangle whose tree box it passes through, and the first
//! triangle it enters from the lumen side (against the face normal, which points into the lumen)
//! is reported with where it was crossed. Nothing a segment passes through is missed, however
//! long the step: there is no sampling.
//!
//! The segment–triangle test is Möller and Trumbore's (1997), in `f64`, with the barycentric
//! bounds widened by [`EDGE_SLACK`] so that a segment through an edge or a vertex shared by
//! several triangles hits at least one of them (a watertight wall stays watertight under
//! rounding). The tree's `f32` boxes are rounded outward, so the box test is conservative.

use nalgebra::Vector3;

use crate::bvh::STACK_SIZE;
use crate::contact::MeshCollider;

/// Relative slack of the barycentric bounds: a segment passing within this fraction of a
/// triangle's size outside an edge still hits it.
const EDGE_SLACK: f64 = 1e-9;

/// How much nearer than its radius (relatively) to a near list's centre both ends of a
/// segment must be for [`MeshCollider::first_crossing_among`] to search that list: far more
/// than [`EDGE_SLACK`] lets a crossing lie outside its triangle.
pub const AMONG_SLACK: f64 = 1e-6;

/// Where a moving point crossed the wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crossing {
    /// Triangle index in the mesh.
    pub triangle: u32,
    /// Fraction of the segment at the crossing (0 at its start, 1 at its end).
    pub fraction: f64,
    /// The crossing point on the triangle.
    pub point: [f64; 3],
    /// The triangle's unit face normal (into the lumen).
    pub normal: [f64; 3],
}

/// Which crossings a query reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Facing {
    /// Entering the wall from the lumen side (moving against the face normal).
    IntoWall,
    /// Either way.
    Any,
}

/// The fraction along `from + s d` (`0 ≤ s ≤ 1`) at which the segment meets the triangle, if
/// it does.
#[inline]
pub(crate) fn segment_triangle(
    from: &Vector3<f64>,
    d: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> Option<f64> {
    let e1 = b - a;
    let e2 = c - a;
    let p = d.cross(&e2);
    let det = e1.dot(&p);
    // Parallel to the plane (or degenerate): a segment grazing a wall in its plane does not
    // cross it.
    if det.abs() <= 1e-300 {
        return None;
    }
    let inv = 1.0 / det;
    let s = from - a;
    let u = s.dot(&p) * inv;
    if !(-EDGE_SLACK..=1.0 + EDGE_SLACK).contains(&u) {
        return None;
    }
    let q = s.cross(&e1);
    let v = d.dot(&q) * inv;
    if v < -EDGE_SLACK || u + v > 1.0 + EDGE_SLACK {
        return None;
    }
    let f = e2.dot(&q) * inv;
    (0.0..=1.0).contains(&f).then_some(f)
}

/// Whether the segment `from + s d`, `0 ≤ s ≤ 1`, passes through the box `[lo, hi]`.
#[inline]
fn segment_box(from: &Vector3<f64>, d: &Vector3<f64>, lo: &[f32; 3], hi: &[f32; 3]) -> bool {
    let (mut enter, mut leave) = (0.0_f64, 1.0_f64);
    for k in 0..3 {
        let (l, h) = (f64::from(lo[k]), f64::from(hi[k]));
        if d[k] == 0.0 {
            if from[k] < l || from[k] > h {
                return false;
            }
            continue;
        }
        let inv = 1.0 / d[k];
        let (mut t0, mut t1) = ((l - from[k]) * inv, (h - from[k]) * inv);
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        enter = enter.max(t0);
        leave = leave.min(t1);
        if enter > leave {
            return false;
        }
    }
    true
}

impl MeshCollider {
    /// The first triangle that a point moving from `from` to `to` enters from the lumen side
    /// (against its face normal), and where: the wall the point crossed. `None` if the segment
    /// crosses no triangle that way (it stays on the lumen side, or only comes back into the
    /// lumen).
    pub fn first_crossing(&self, from: &[f64; 3], to: &[f64; 3]) -> Option<Crossing> {
        self.first_hit(from, to, Facing::IntoWall)
    }

    /// [`Self::first_crossing`] among the triangles in leaf-order `slots`: the same crossing
    /// when `slots` holds every triangle the segment meets, as the list of
    /// [`Self::near_slots`] does for a segment whose ends are both closer to that list's centre
    /// than its radius (less [`AMONG_SLACK`] of it: a crossing may lie that much outside its
    /// triangle), without the tree walk. Of two triangles crossed at exactly the same fraction
    /// (through their shared edge), the tree and the list may report either.
    pub fn first_crossing_among(
        &self,
        from: &[f64; 3],
        to: &[f64; 3],
        slots: &[u32],
    ) -> Option<Crossing> {
        let a = Vector3::from(*from);
        let d = Vector3::from(*to) - a;
        if d == Vector3::zeros() {
            return None;
        }
        let mut best = None;
        for &slot in slots {
            self.hit_slot(&a, &d, Facing::IntoWall, slot as usize, &mut best);
        }
        self.crossing(&a, &d, best)
    }

    /// The first triangle the segment from `from` to `to` meets, whichever way it crosses it
    /// (a ray cast limited to the segment).
    pub fn first_intersection(&self, from: &[f64; 3], to: &[f64; 3]) -> Option<Crossing> {
        self.first_hit(from, to, Facing::Any)
    }

    fn first_hit(&self, from: &[f64; 3], to: &[f64; 3], facing: Facing) -> Option<Crossing> {
        let a = Vector3::from(*from);
        let d = Vector3::from(*to) - a;
        if d == Vector3::zeros() {
            return None;
        }
        let nodes = self.bvh().nodes();
        let mut best: Option<(f64, usize)> = None;
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let n = &nodes[stack[sp] as usize];
            if !segment_box(&a, &d, &n.min, &n.max) {
                continue;
            }
            if n.is_leaf() {
                for slot in n.first as usize..(n.first + n.count) as usize {
                    self.hit_slot(&a, &d, facing, slot, &mut best);
                }
            } else {
                stack[sp] = n.first;
                stack[sp + 1] = n.first + 1;
                sp += 2;
            }
        }
        self.crossing(&a, &d, best)
    }

    /// Keeps in `best` (fraction, slot) the earlier of it and the triangle of `slot`'s
    /// crossing by the segment `a + s d`, if it crosses it as `facing` asks.
    #[inline]
    fn hit_slot(
        &self,
        a: &Vector3<f64>,
        d: &Vector3<f64>,
        facing: Facing,
        slot: usize,
        best: &mut Option<(f64, usize)>,
    ) {
        let t = &self.tris[slot];
        if facing == Facing::IntoWall && t.n.dot(d) >= 0.0 {
            return;
        }
        if let Some(f) = segment_triangle(a, d, &t.a, &t.b, &t.c)
            && best.is_none_or(|(b, _)| f < b)
        {
            *best = Some((f, slot));
        }
    }

    /// The [`Crossing`] of what [`Self::hit_slot`] kept.
    fn crossing(
        &self,
        a: &Vector3<f64>,
        d: &Vector3<f64>,
        best: Option<(f64, usize)>,
    ) -> Option<Crossing> {
        let (f, slot) = best?;
        Some(Crossing {
            triangle: self.bvh().tri_indices()[slot],
            fraction: f,
            point: (a + d * f).into(),
            normal: self.tris[slot].n.into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TriMesh;

    /// A unit square in the plane z = 0, normal +z (the lumen above it).
    fn floor() -> MeshCollider {
        let (mesh, _) = TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
            "floor",
        )
        .expect("valid");
        MeshCollider::new(mesh)
    }

    #[test]
    fn a_point_moving_down_through_the_floor_crosses_it_where_expected() {
        let c = floor();
        let hit = c
            .first_crossing(&[0.3, 0.6, 0.25], &[0.3, 0.6, -0.75])
            .expect("crosses");
        assert!((hit.fraction - 0.25).abs() < 1e-12);
        assert!((hit.point[2]).abs() < 1e-12);
        assert_eq!(hit.normal, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn coming_back_into_the_lumen_is_not_a_crossing_into_the_wall() {
        let c = floor();
        assert!(
            c.first_crossing(&[0.3, 0.6, -0.5], &[0.3, 0.6, 0.5])
                .is_none()
        );
        assert!(
            c.first_intersection(&[0.3, 0.6, -0.5], &[0.3, 0.6, 0.5])
                .is_some()
        );
    }

    #[test]
    fn the_shared_diagonal_is_watertight() {
        let c = floor();
        // Through the diagonal x = y shared by the two triangles.
        for k in 1..100 {
            let s = k as f64 / 100.0;
            assert!(
                c.first_crossing(&[s, s, 1e-3], &[s, s, -1e-3]).is_some(),
                "slipped through at {s}"
            );
        }
    }

    /// A motion within a near list's radius of its centre crosses in the list what it crosses
    /// in the tree: a finer floor, motions down through it and back up in every direction.
    #[test]
    fn a_near_list_holds_every_crossing_of_a_motion_within_its_radius() {
        let mesh = TriMesh::patch([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 20, "floor");
        let c = MeshCollider::new(mesh.expect("valid"));
        let (centre, r) = ([0.43, 0.51, 0.02], 0.1);
        let mut slots = Vec::new();
        c.near_slots(&centre, r, &mut slots);
        assert!(slots.len() > 4 && slots.len() < 100, "{}", slots.len());
        let mut crossed = 0;
        for k in 0..200 {
            let a = k as f64 * 0.7;
            let (s, t) = (a.cos() * 0.06, a.sin() * 0.06);
            let from = [centre[0] + s, centre[1] + t, centre[2] + 0.03 * a.sin()];
            let to = [
                centre[0] - t,
                centre[1] + s,
                centre[2] - 0.05 * a.cos().abs(),
            ];
            let tree = c.first_crossing(&from, &to);
            crossed += usize::from(tree.is_some());
            assert_eq!(c.first_crossing_among(&from, &to, &slots), tree, "{k}");
        }
        assert!(crossed > 20, "{crossed}");
    }

    #[test]
    fn segments_that_stop_short_or_pass_beside_do_not_cross() {
        let c = floor();
        assert!(
            c.first_crossing(&[0.3, 0.6, 0.5], &[0.3, 0.6, 0.01])
                .is_none()
        );
        assert!(
            c.first_crossing(&[1.3, 0.6, 0.5], &[1.3, 0.6, -0.5])
                .is_none()
        );
        assert!(
            c.first_crossing(&[0.3, 0.6, 0.5], &[0.3, 0.6, 0.5])
                .is_none()
        );
    }
}
