//! Segment queries: how close does an element of a rod (the capsule between two points) come to
//! the wall?
//!
//! The sphere queries of [`crate::contact`] test the rod's points. A wall that bulges into the
//! lumen between two points (the ridge of a bifurcation, a fold, a sharp vertex) can reach
//! into the capsule of the element joining them while both spheres stay clear: the points'
//! queries see nothing, and the element passes through the ridge. The segment query finds the
//! triangle nearest to the element's segment, and where on the segment it is nearest, so that
//! a caller can push the element off the ridge.
//!
//! The segment–triangle distance is exact: zero where the segment passes through the triangle,
//! else the least of the segment's distances to the triangle's three edges (segment–segment,
//! [`crate::rods::closest_points_segments`]) and of its two ends' distances to the triangle
//! ([`crate::contact::closest_point_triangle`]); the minimum of a convex distance is reached at
//! one of those. The tree is searched with the sphere around the segment's midpoint that holds
//! the capsule.
//!
//! **Only ridges matter.** Where the lumen is convex (inside a straight or gently curved tube,
//! at every crease of its facets), the distance to the wall is a concave function of the
//! position (the distance to the boundary of a convex set is concave inside it), so along a
//! segment it is smallest at an end, which the point queries see. The interior of a segment
//! can only be nearer where the lumen is not convex: at a ridge edge, whose neighbouring
//! triangle falls away behind the plane of the other (the carina of a bifurcation, the inner
//! wall of a bend), or at the rim of an opening. [`MeshCollider`] marks the triangles with such
//! an edge once, and a rod's element queries list only those
//! ([`MeshCollider::segment_near_slots`] with `ridges_only`): in a tube they find nothing and
//! cost a list check.

use nalgebra::Vector3;

use crate::contact::{MeshCollider, TriData, closest_point_triangle};
use crate::rods::closest_points_segments;
use crate::sweep::segment_triangle;

/// The part of a segment nearest to the wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentNearest {
    /// Triangle index in the mesh.
    pub triangle: u32,
    /// Where on the segment, as a fraction (0 at its start, 1 at its end).
    pub fraction: f64,
    /// The closest point of the triangle.
    pub closest: [f64; 3],
    /// Distance from the segment to the triangle, signed by the pseudo-normal of the
    /// triangle's closest feature: negative where the segment's nearest point is behind the
    /// wall (or passes through it).
    pub signed_distance: f64,
    /// Unit direction from the wall to the segment's nearest point, on the lumen side: the
    /// direction to push the segment. The face normal where the segment passes through the
    /// triangle.
    pub normal: [f64; 3],
}

/// The distance from the segment `p + s d` (`0 ≤ s ≤ 1`) to the triangle `abc`, and `s` at
/// the nearest point: `(distance², s)`. Zero where the segment passes through the triangle.
pub(crate) fn segment_triangle_distance2(
    p: &Vector3<f64>,
    d: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> (f64, f64) {
    if let Some(s) = segment_triangle(p, d, a, b, c) {
        return (0.0, s);
    }
    let q = p + d;
    let mut best = (f64::INFINITY, 0.0);
    for (s, end) in [(0.0, p), (1.0, &q)] {
        let (x, _) = closest_point_triangle(end, a, b, c);
        let d2 = (end - x).norm_squared();
        if d2 < best.0 {
            best = (d2, s);
        }
    }
    for (u, v) in [(a, b), (b, c), (c, a)] {
        let (s, _, c1, c2) =
            closest_points_segments((*p).into(), q.into(), (*u).into(), (*v).into());
        let d2 = (Vector3::from(c1) - Vector3::from(c2)).norm_squared();
        if d2 < best.0 {
            best = (d2, s);
        }
    }
    best
}

/// Whether the segment `p + s d` comes closer than `√r2` to the triangle `abc`:
/// [`segment_triangle_distance2`] below `r2`, from the same candidate distances, stopping at
/// the first one below (an end's, the cheapest, first).
fn segment_triangle_within(
    p: &Vector3<f64>,
    d: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
    r2: f64,
) -> bool {
    let q = p + d;
    for end in [p, &q] {
        let (x, _) = closest_point_triangle(end, a, b, c);
        if (end - x).norm_squared() < r2 {
            return true;
        }
    }
    // A segment through the triangle is at distance 0 from it (and `r2` is positive).
    if segment_triangle(p, d, a, b, c).is_some() {
        return 0.0 < r2;
    }
    [(a, b), (b, c), (c, a)].into_iter().any(|(u, v)| {
        let (_, _, c1, c2) =
            closest_points_segments((*p).into(), q.into(), (*u).into(), (*v).into());
        (Vector3::from(c1) - Vector3::from(c2)).norm_squared() < r2
    })
}

impl MeshCollider {
    /// The triangle nearest to the segment `from → to` among those closer than `reach`, and
    /// where (see [`SegmentNearest`]); `None` when none is that close.
    pub fn segment_nearest(
        &self,
        from: &[f64; 3],
        to: &[f64; 3],
        reach: f64,
    ) -> Option<SegmentNearest> {
        let (p, d) = (
            Vector3::from(*from),
            Vector3::from(*to) - Vector3::from(*from),
        );
        let mut best = None;
        self.bvh()
            .for_each_near(&(p + d * 0.5).into(), 0.5 * d.norm() + reach, |slot| {
                self.consider(&p, &d, reach, slot, &mut best);
            });
        self.answer(&p, &d, best)
    }

    /// The leaf-order slots of the triangles closer than `r` to the segment `from → to`,
    /// written to `out` (cleared first). A segment whose ends are each within `r − r'` of this
    /// one's can only come within `r'` of these triangles (every point of it is that close to
    /// the matching point of this one), so a slowly moving element can query this list
    /// ([`Self::segment_nearest_among`]) instead of the tree.
    ///
    /// With `ridges_only`, only triangles that have a ridge edge (where the lumen is not
    /// convex, see the module docs) are listed: the only ones a segment in the lumen can be
    /// nearer to between its ends than at them.
    pub fn segment_near_slots(
        &self,
        from: &[f64; 3],
        to: &[f64; 3],
        r: f64,
        ridges_only: bool,
        out: &mut Vec<u32>,
    ) {
        out.clear();
        let (p, d) = (
            Vector3::from(*from),
            Vector3::from(*to) - Vector3::from(*from),
        );
        self.bvh().for_each_near_segment(from, to, r, |slot| {
            if self.segment_within(&p, &d, r, ridges_only, slot) {
                out.push(slot as u32);
            }
        });
    }

    /// [`Self::segment_near_slots`] among the leaf-order `slots`: the same list when `slots`
    /// holds, in leaf order, every triangle within `r` of the segment (the list
    /// [`Self::segment_near_slots`] made with a larger radius for a segment whose ends are each
    /// within the difference of the radii of this one's), without the tree walk.
    pub fn segment_near_slots_among(
        &self,
        from: &[f64; 3],
        to: &[f64; 3],
        r: f64,
        ridges_only: bool,
        slots: &[u32],
        out: &mut Vec<u32>,
    ) {
        out.clear();
        let (p, d) = (
            Vector3::from(*from),
            Vector3::from(*to) - Vector3::from(*from),
        );
        out.extend(
            slots
                .iter()
                .filter(|&&slot| self.segment_within(&p, &d, r, ridges_only, slot as usize)),
        );
    }

    /// Whether the triangle of `slot` is closer than `r` to the segment `p + s d` (and, with
    /// `ridges_only`, a ridge triangle): the test of [`Self::segment_near_slots`].
    #[inline]
    fn segment_within(
        &self,
        p: &Vector3<f64>,
        d: &Vector3<f64>,
        r: f64,
        ridges_only: bool,
        slot: usize,
    ) -> bool {
        let t = &self.tris[slot];
        if (ridges_only && !self.ridges[slot])
            || beyond_plane(p, d, t, r)
            || beyond_sides(p, d, t, r)
        {
            return false;
        }
        segment_triangle_within(p, d, &t.a, &t.b, &t.c, r * r)
    }

    /// [`Self::segment_nearest`] among the triangles in leaf-order `slots` (from
    /// [`Self::segment_near_slots`]): the same answer when `slots` holds every triangle within
    /// `reach` of the segment.
    pub fn segment_nearest_among(
        &self,
        from: &[f64; 3],
        to: &[f64; 3],
        reach: f64,
        slots: &[u32],
    ) -> Option<SegmentNearest> {
        let (p, d) = (
            Vector3::from(*from),
            Vector3::from(*to) - Vector3::from(*from),
        );
        let mut best = None;
        for &slot in slots {
            self.consider(&p, &d, reach, slot as usize, &mut best);
        }
        self.answer(&p, &d, best)
    }

    /// Keeps in `best` (squared distance, fraction, slot) the nearer of it and the triangle of
    /// `slot`, if that one is within `reach` of the segment `p + s d`.
    #[inline]
    fn consider(
        &self,
        p: &Vector3<f64>,
        d: &Vector3<f64>,
        reach: f64,
        slot: usize,
        best: &mut Option<(f64, f64, usize)>,
    ) {
        let t = &self.tris[slot];
        if beyond_plane(p, d, t, reach) || beyond_sides(p, d, t, reach) {
            return;
        }
        let (d2, s) = segment_triangle_distance2(p, d, &t.a, &t.b, &t.c);
        if d2 < reach * reach && best.is_none_or(|(b, _, _)| d2 < b) {
            *best = Some((d2, s, slot));
        }
    }

    /// The [`SegmentNearest`] of what [`Self::consider`] kept.
    fn answer(
        &self,
        p: &Vector3<f64>,
        d: &Vector3<f64>,
        best: Option<(f64, f64, usize)>,
    ) -> Option<SegmentNearest> {
        let (d2, s, slot) = best?;
        let t = &self.tris[slot];
        let at = p + d * s;
        let (c, feature) = closest_point_triangle(&at, &t.a, &t.b, &t.c);
        let diff = at - c;
        let distance = d2.sqrt();
        let pseudo = self.pseudo_normal(slot, feature);
        let (signed_distance, normal) = if distance > 0.0 {
            let side = if diff.dot(&pseudo) >= 0.0 { 1.0 } else { -1.0 };
            (side * distance, diff * (side / distance))
        } else {
            (0.0, t.n)
        };
        Some(SegmentNearest {
            triangle: self.bvh().tri_indices()[slot],
            fraction: s,
            closest: c.into(),
            signed_distance,
            normal: normal.into(),
        })
    }
}

/// Whether both ends of the segment `p + s d` are farther than `r` on one side of triangle
/// `t`'s plane: then so is the whole segment (two multiply–adds before the exact distance).
#[inline]
fn beyond_plane(p: &Vector3<f64>, d: &Vector3<f64>, t: &TriData, r: f64) -> bool {
    let (h0, h1) = (t.n.dot(&(p - t.a)), t.n.dot(&(p + d - t.a)));
    (h0 > r && h1 > r) || (h0 < -r && h1 < -r)
}

/// How much farther than `r` (relatively) [`beyond_sides`] asks a triangle to be: the rounding
/// of its projections must never rule out one the exact distance would keep.
const SIDES_ROUNDING: f64 = 1e-9;

/// Whether triangle `t` lies wholly before the start or past the end of the segment `p + s d`
/// by more than `r` along it, or wholly farther than `r` to one side of the line across it in
/// the triangle's plane (along `d × n`): then so is every point of it from the segment. Two
/// separating directions at a few multiply–adds each, for the triangles beside or ahead of an
/// element lying along a wall, whose planes [`beyond_plane`] cannot rule out.
#[inline]
fn beyond_sides(p: &Vector3<f64>, d: &Vector3<f64>, t: &TriData, r: f64) -> bool {
    let len = d.norm();
    if !(len > 0.0) {
        return false;
    }
    let r = r * (1.0 + SIDES_ROUNDING);
    let (a, b, c) = (t.a - p, t.b - p, t.c - p);
    // Projections onto a unit direction relative to `p`, separated from `[lo, hi]` by more
    // than `r`.
    let apart = |axis: &Vector3<f64>, lo: f64, hi: f64| {
        let (x, y, z) = (axis.dot(&a), axis.dot(&b), axis.dot(&c));
        x.min(y).min(z) > hi + r || x.max(y).max(z) < lo - r
    };
    let along = d / len;
    if apart(&along, 0.0, len) {
        return true;
    }
    let across = d.cross(&t.n);
    let width = across.norm();
    width > 1e-9 * len && apart(&(across / width), 0.0, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;

    /// A roof ridge along y at z = 0: two faces falling away from it at a slope of ½ on either
    /// side, normals up (into the lumen above).
    fn ridge() -> MeshCollider {
        let v = vec![
            [0.0, -1.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, -1.0, -0.5],
            [1.0, 1.0, -0.5],
            [-1.0, -1.0, -0.5],
            [-1.0, 1.0, -0.5],
        ];
        let t = vec![[0, 2, 3], [0, 3, 1], [0, 1, 5], [0, 5, 4]];
        let (mesh, _) = TriMesh::new(v, t, "ridge").unwrap();
        MeshCollider::new(mesh)
    }

    /// An element lying across the ridge just above it touches it at its middle, where
    /// neither end's sphere reaches.
    #[test]
    fn an_element_across_a_ridge_is_nearest_at_the_ridge() {
        let c = ridge();
        let near = c
            .segment_nearest(&[-0.5, 0.2, 0.01], &[0.5, 0.2, 0.01], 0.05)
            .unwrap();
        assert!((near.fraction - 0.5).abs() < 1e-12, "{near:?}");
        assert!((near.signed_distance - 0.01).abs() < 1e-12, "{near:?}");
        assert!((Vector3::from(near.normal) - Vector3::z()).norm() < 1e-12);
        // Each end is 0.26 / √1.25 ≈ 0.23 from its face: far out of reach.
        for end in [[-0.5, 0.2, 0.01], [0.5, 0.2, 0.01]] {
            assert!(c.nearest(&end, 0.05).is_none());
        }
    }

    /// An element through the ridge (both ends below it, in the lumen's sense behind it) is
    /// found with a negative distance and pushed up.
    #[test]
    fn an_element_through_a_ridge_is_behind_it() {
        let c = ridge();
        let near = c
            .segment_nearest(&[-0.5, 0.0, -0.1], &[0.5, 0.0, -0.1], 0.05)
            .unwrap();
        assert!(near.signed_distance <= 0.0, "{near:?}");
        assert!(near.normal[2] > 0.0, "{near:?}");
    }

    /// The near list of an element answers as the tree does for the element moved within the
    /// list's skin.
    #[test]
    fn a_near_list_answers_as_the_tree() {
        let c = ridge();
        let (from, to) = ([-0.5, 0.2, 0.01], [0.5, 0.2, 0.01]);
        let mut slots = Vec::new();
        c.segment_near_slots(&from, &to, 0.05 + 0.02, true, &mut slots);
        assert!(!slots.is_empty() && slots.len() < 4, "{slots:?}");
        for shift in [[0.0, 0.0, 0.0], [0.01, -0.01, 0.015], [0.0, 0.019, -0.005]] {
            let a = [from[0] + shift[0], from[1] + shift[1], from[2] + shift[2]];
            let b = [to[0] - shift[1], to[1] + shift[0], to[2] + shift[2]];
            assert_eq!(
                c.segment_nearest_among(&a, &b, 0.05, &slots),
                c.segment_nearest(&a, &b, 0.05)
            );
        }
    }

    /// The cheap tests that rule a triangle out never rule out one the exact distance keeps,
    /// and the early-stopping test agrees with the exact distance, over random segments and
    /// triangles around a unit cube (a fixed xorshift sequence).
    #[test]
    fn cheap_rejections_agree_with_the_exact_distance() {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut sides, mut kept) = (0, 0);
        for _ in 0..20_000 {
            let v: Vec<Vector3<f64>> = (0..5)
                .map(|_| Vector3::new(next(), next(), next()))
                .collect();
            let (p, d, [a, b, c]) = (v[0], (v[1] - v[0]) * 0.5, [v[2], v[3], v[4]]);
            let Some(n) = (b - a).cross(&(c - a)).try_normalize(1e-12) else {
                continue;
            };
            let t = TriData { a, b, c, n };
            let r = 0.3 * next();
            let (d2, _) = segment_triangle_distance2(&p, &d, &a, &b, &c);
            assert_eq!(
                segment_triangle_within(&p, &d, &a, &b, &c, r * r),
                d2 < r * r
            );
            if beyond_sides(&p, &d, &t, r) {
                sides += 1;
                assert!(d2 >= r * r, "{p:?} {d:?} {t:?} {r}");
            } else {
                kept += 1;
            }
        }
        assert!(
            sides > 1000 && kept > 1000,
            "{sides} ruled out, {kept} kept"
        );
    }

    /// A near list made from a wider list is the tree's list.
    #[test]
    fn a_near_list_from_a_wider_list_is_the_trees() {
        let c = ridge();
        let (from, to) = ([-0.5, 0.2, 0.01], [0.5, 0.2, 0.01]);
        let mut wide = Vec::new();
        c.segment_near_slots(&from, &to, 0.3, true, &mut wide);
        let (mut among, mut tree) = (Vec::new(), Vec::new());
        for shift in [[0.0, 0.0, 0.0], [0.1, -0.05, 0.15], [0.0, 0.19, -0.05]] {
            let a = [from[0] + shift[0], from[1] + shift[1], from[2] + shift[2]];
            let b = [to[0] - shift[1], to[1] + shift[0], to[2] + shift[2]];
            c.segment_near_slots_among(&a, &b, 0.1, true, &wide, &mut among);
            c.segment_near_slots(&a, &b, 0.1, true, &mut tree);
            assert_eq!(among, tree);
        }
    }

    /// Every edge of the roof's ridge falls away from the lumen: all four triangles are ridge
    /// triangles. Inside a straight tube no edge does: only the triangles at its open ends
    /// (boundary edges) are marked.
    #[test]
    fn ridges_are_where_the_lumen_is_not_convex() {
        assert!(ridge().ridges.iter().all(|&r| r));
        let tube = crate::vessel::generate(&crate::vessel::VesselParams {
            branches: Vec::new(),
            bow: 0.0,
            target_triangles: 2000,
            ..Default::default()
        })
        .unwrap();
        let c = MeshCollider::new(tube.mesh.clone());
        let marked = c.ridges.iter().filter(|&&r| r).count();
        let boundary = c.edge_on_boundary_count();
        assert!(
            marked > 0 && marked <= boundary,
            "{marked} marked, {boundary} boundary edges"
        );
    }

    /// Far from the mesh nothing is found.
    #[test]
    fn a_distant_element_finds_nothing() {
        let c = ridge();
        assert!(
            c.segment_nearest(&[0.0, 0.0, 1.0], &[0.5, 0.0, 1.0], 0.05)
                .is_none()
        );
    }
}
