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

use nalgebra::Vector3;

use crate::contact::{MeshCollider, TriData, closest_point_triangle};
use crate::rods::closest_points_segments;

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

/// The distance from the segment `p + s d` (`0 ≤ s ≤ 1`) to triangle `t`, and `s` at the
/// nearest point: `(distance², s)`. Zero where the segment passes through the triangle.
pub(crate) fn segment_triangle_distance2(
    p: &Vector3<f64>,
    d: &Vector3<f64>,
    t: &TriData,
) -> (f64, f64) {
    if let Some(s) = crossing(p, d, t) {
        return (0.0, s);
    }
    let q = p + d;
    let mut best = (f64::INFINITY, 0.0);
    for (s, end) in [(0.0, p), (1.0, &q)] {
        let (c, _) = closest_point_triangle(end, &t.a, &t.b, &t.c);
        let d2 = (end - c).norm_squared();
        if d2 < best.0 {
            best = (d2, s);
        }
    }
    for (a, b) in [(&t.a, &t.b), (&t.b, &t.c), (&t.c, &t.a)] {
        let (s, _, c1, c2) =
            closest_points_segments((*p).into(), q.into(), (*a).into(), (*b).into());
        let d2 = (Vector3::from(c1) - Vector3::from(c2)).norm_squared();
        if d2 < best.0 {
            best = (d2, s);
        }
    }
    best
}

/// Where the segment `p + s d` passes through triangle `t` (either side), if it does.
fn crossing(p: &Vector3<f64>, d: &Vector3<f64>, t: &TriData) -> Option<f64> {
    let e1 = t.b - t.a;
    let e2 = t.c - t.a;
    let h = d.cross(&e2);
    let det = e1.dot(&h);
    if det.abs() <= 1e-300 {
        return None;
    }
    let inv = 1.0 / det;
    let o = p - t.a;
    let u = o.dot(&h) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let k = o.cross(&e1);
    let v = d.dot(&k) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let s = e2.dot(&k) * inv;
    (0.0..=1.0).contains(&s).then_some(s)
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
        DBG[0].fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let p = Vector3::from(*from);
        let d = Vector3::from(*to) - p;
        let mid = p + d * 0.5;
        let mut best: Option<(f64, f64, usize)> = None;
        let reach2 = reach * reach;
        self.bvh()
            .for_each_near(&mid.into(), 0.5 * d.norm() + reach, |slot| {
                DBG[1].fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let t = &self.tris[slot];
                // Both ends farther than `reach` on one side of the triangle's plane: so is the
                // whole segment (two multiply–adds before the exact distance).
                let (h0, h1) = (t.n.dot(&(p - t.a)), t.n.dot(&(p + d - t.a)));
                if (h0 > reach && h1 > reach) || (h0 < -reach && h1 < -reach) {
                    return;
                }
                DBG[2].fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let (d2, s) = segment_triangle_distance2(&p, &d, t);
                if d2 < reach2 && best.is_none_or(|(b, _, _)| d2 < b) {
                    best = Some((d2, s, slot));
                }
            });
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

pub static DBG: [std::sync::atomic::AtomicU64; 4] = [const { std::sync::atomic::AtomicU64::new(0) }; 4];
