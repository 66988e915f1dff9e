//! Entry ports: where a wire enters the lumen, and an opening in the wall where it must pass
//! through one.
//!
//! An insertion scene names an entry: a point and a direction along which the wire is pushed
//! in. Two things depend on where, along that axis, the wire actually reaches the lumen:
//! - **counting escapes**: between the entry point and the lumen (an introducer in front of an
//!   open vessel end) the wire is outside the lumen without having left it;
//! - **closed meshes**: an anatomy whose vessel ends are rounded shut (or a whole organ) has no
//!   opening; the wire must pass through the wall, so the port cuts a hole there: the triangles
//!   within the port's radius of the axis, around where it crosses the wall, that face the axis
//!   (within 60°) are removed; a vessel's side wall beyond the end stays. The
//!   hole's rim is an opening like any other: the inside test caps it
//!   ([`crate::winding`]), contacts see its rim.
//!
//! [`open_port`] walks the axis from the entry point: where the lumen's winding number first
//! reaches one half (bisected to a thousandth of the port's radius), before any wall, the axis
//! enters through an opening; if it meets a triangle first and the lumen lies just behind it,
//! it enters through the wall, which is opened.

use nalgebra::Vector3;

use crate::contact::MeshCollider;
use crate::mesh::{MeshError, TriMesh};
use crate::segment::segment_triangle_distance2;

/// Samples of the winding number along the axis before the first wall.
const AXIS_SAMPLES: usize = 256;

/// Without a given radius, a port through a wall opens this fraction of the lumen's largest
/// radius found just behind the wall (within [`LUMEN_PROBE`] of it).
const DEFAULT_RADIUS_FRACTION: f64 = 0.5;

/// A triangle the port opens faces its axis: the cosine of the angle between its normal and
/// the axis is at least this (within 60°).
const FACING: f64 = 0.5;

/// How far behind the wall the lumen's radius is probed for the default port radius [m].
const LUMEN_PROBE: f64 = 0.01;

/// Where a wire enters the lumen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Port {
    /// The entry point [m].
    pub point: [f64; 3],
    /// Unit direction into the lumen.
    pub direction: [f64; 3],
    /// The port's radius [m]: the channel around the axis in which a wire that has not yet
    /// reached the lumen is not outside it, and the hole opened in a wall.
    pub radius: f64,
    /// Distance along the axis from the entry point to where it reaches the lumen [m].
    pub crossing: f64,
    /// Triangles removed to open the wall (0 when the axis enters through an opening).
    pub opened: usize,
}

impl Port {
    /// Whether `p` is in the port's channel: not past the entry point, or up to the crossing
    /// (and a radius beyond it) within the port's radius of the axis. A point there is on its
    /// way in, not outside the lumen.
    pub fn holds(&self, p: &[f64; 3]) -> bool {
        let rel = Vector3::from(*p) - Vector3::from(self.point);
        let d = Vector3::from(self.direction);
        let s = rel.dot(&d);
        s <= 0.0 || (s <= self.crossing + self.radius && (rel - d * s).norm() <= self.radius)
    }
}

/// Why a port could not be placed.
#[derive(Debug)]
pub enum PortError {
    /// The axis never reaches the lumen within `reach` of the entry point.
    NoLumen {
        /// How far the axis was followed [m].
        reach: f64,
        /// Distance from the entry point to the nearest wall [m].
        nearest_wall: f64,
    },
    /// The port's radius is not a positive finite number.
    BadRadius(f64),
    /// The mesh without the opened triangles is not a valid mesh.
    Mesh(MeshError),
}

impl std::fmt::Display for PortError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoLumen {
                reach,
                nearest_wall,
            } => write!(
                f,
                "the entry's axis does not reach the lumen within {reach:.3e} m (the nearest wall is {nearest_wall:.3e} m from the entry point)"
            ),
            Self::BadRadius(r) => write!(f, "the port radius {r} is not a positive length"),
            Self::Mesh(e) => write!(f, "opening the wall: {e}"),
        }
    }
}

impl std::error::Error for PortError {}

/// Places a port on `mesh` at `point` along `direction` (any length), with `radius` or, without
/// one, a radius found from the mesh: the opening's (the distance from the crossing to the
/// nearest wall) when the axis enters through one, half the lumen's just behind the wall when it
/// enters through the wall. Returns the collider to use (rebuilt without the opened triangles
/// when a wall was opened) and the port.
pub fn open_port(
    mesh: TriMesh,
    point: [f64; 3],
    direction: [f64; 3],
    radius: Option<f64>,
) -> Result<(MeshCollider, Port), PortError> {
    if let Some(r) = radius
        && !(r > 0.0 && r.is_finite())
    {
        return Err(PortError::BadRadius(r));
    }
    let e = Vector3::from(point);
    let d = Vector3::from(direction).normalize();
    let collider = MeshCollider::new(mesh);
    let (lo, hi) = collider.mesh().bounds();
    let box_distance = (0..3)
        .map(|k| (lo[k] - e[k]).max(e[k] - hi[k]).max(0.0).powi(2))
        .sum::<f64>()
        .sqrt();
    let reach = box_distance + (hi - lo).norm();
    let at = |s: f64| -> [f64; 3] { (e + d * s).into() };
    let inside = |s: f64| collider.lumen_winding(&at(s)) >= 0.5;
    let wall = collider.first_intersection(&point, &at(reach));
    let end = wall.map_or(reach, |w| w.fraction * reach);
    // Through an opening: the lumen is reached before any wall. (Not at the wall itself: a
    // point on the wall has a winding number of one half, inside by rounding as often as not.)
    let ds = end / AXIS_SAMPLES as f64;
    let first_inside = (0..AXIS_SAMPLES)
        .map(|k| k as f64 * ds)
        .find(|&s| inside(s));
    let nearest_wall = |s: f64| {
        collider
            .nearest(&at(s), f64::INFINITY)
            .map_or(f64::INFINITY, |n| n.distance)
    };
    if let Some(s_in) = first_inside {
        let (mut a, mut b) = ((s_in - ds).max(0.0), s_in);
        let tol = 1e-3 * radius.unwrap_or(ds.max(1e-6));
        while b - a > tol && s_in > 0.0 {
            let m = 0.5 * (a + b);
            if inside(m) { b = m } else { a = m }
        }
        let crossing = if s_in > 0.0 { b } else { 0.0 };
        let radius = radius.unwrap_or_else(|| nearest_wall(crossing));
        return Ok((
            collider,
            Port {
                point,
                direction: d.into(),
                radius,
                crossing,
                opened: 0,
            },
        ));
    }
    let no_lumen = || PortError::NoLumen {
        reach,
        nearest_wall: nearest_wall(0.0),
    };
    // Through the wall: the lumen must lie just behind the first triangle met.
    if wall.is_none() {
        return Err(no_lumen());
    }
    let s_hit = end;
    let behind = (1..=64)
        .map(|k| s_hit + LUMEN_PROBE * k as f64 / 64.0)
        .take_while(|&s| s < reach)
        .filter(|&s| inside(s))
        .map(nearest_wall)
        .collect::<Vec<_>>();
    if !inside(s_hit + 1e-4 * (hi - lo).norm()) || behind.is_empty() {
        return Err(no_lumen());
    }
    let radius = radius
        .unwrap_or_else(|| DEFAULT_RADIUS_FRACTION * behind.iter().copied().fold(0.0, f64::max));
    // Open the wall: every triangle within the radius of the axis, within two radii of the
    // crossing along it, that faces the axis (the wall it passes through, not the side wall of
    // a vessel beyond it: a port as wide as the vessel would cut that away too).
    let (a, b) = (
        e + d * (s_hit - 2.0 * radius),
        e + d * (s_hit + 2.0 * radius),
    );
    let mesh = collider.mesh();
    let kept: Vec<[u32; 3]> = (0..mesh.triangles().len())
        .filter(|&t| {
            let [p, q, r] = mesh.triangle(t);
            mesh.face_normal(t).dot(&d).abs() < FACING
                || segment_triangle_distance2(&a, &(b - a), &p, &q, &r).0 >= radius * radius
        })
        .map(|t| mesh.triangles()[t])
        .collect();
    let opened = mesh.triangles().len() - kept.len();
    let vertices: Vec<[f64; 3]> = mesh.vertices().iter().map(|v| (*v).into()).collect();
    let (opened_mesh, _) = TriMesh::new(vertices, kept, mesh.name()).map_err(PortError::Mesh)?;
    Ok((
        MeshCollider::new(opened_mesh),
        Port {
            point,
            direction: d.into(),
            radius,
            crossing: s_hit,
            opened,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed box `[0, 1]³` with welded corners, normals inward (its inside is the lumen),
    /// 2·n² triangles a side.
    fn closed_box(n: usize) -> TriMesh {
        let faces: [([f64; 3], [f64; 3], [f64; 3]); 6] = [
            ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
            ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]),
            ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
            ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
        ];
        let mut index = std::collections::HashMap::new();
        let (mut v, mut t) = (Vec::new(), Vec::new());
        for (o, u, w) in faces {
            let patch = TriMesh::patch(o, u, w, n, "face").expect("patch");
            let ids: Vec<u32> = patch
                .vertices()
                .iter()
                .map(|p| {
                    let key = [p.x, p.y, p.z].map(|c| (c * n as f64).round() as i64);
                    *index.entry(key).or_insert_with(|| {
                        v.push([p.x, p.y, p.z]);
                        v.len() as u32 - 1
                    })
                })
                .collect();
            t.extend(patch.triangles().iter().map(|f| f.map(|i| ids[i as usize])));
        }
        let (mut mesh, _) = TriMesh::new(v, t, "box").expect("valid");
        mesh.repair_orientation();
        mesh.orient_into_lumen();
        mesh
    }

    #[test]
    fn a_port_through_a_closed_wall_opens_a_hole_of_its_radius() {
        let (collider, port) =
            open_port(closed_box(20), [-0.5, 0.5, 0.5], [1.0, 0.0, 0.0], Some(0.1)).expect("port");
        assert!((port.crossing - 0.5).abs() < 1e-12, "{}", port.crossing);
        assert!(port.opened > 0);
        // The axis now passes the wall; a point off the axis by more than the radius still hits
        // it.
        assert!(
            collider
                .first_intersection(&[-0.5, 0.5, 0.5], &[0.5, 0.5, 0.5])
                .is_none()
        );
        assert!(
            collider
                .first_intersection(&[-0.5, 0.5, 0.7], &[0.5, 0.5, 0.7])
                .is_some()
        );
        // Inside is still inside (the hole is capped for the inside test).
        assert!(collider.lumen_winding(&[0.5, 0.5, 0.5]) > 0.9);
        assert!(port.holds(&[-0.2, 0.5, 0.55]));
        assert!(!port.holds(&[0.2, 0.5, 0.9]));
    }

    /// A port as wide as the vessel opens the end wall it passes through, not the side walls
    /// beyond it.
    #[test]
    fn a_port_as_wide_as_the_vessel_leaves_its_side_walls() {
        let (collider, port) =
            open_port(closed_box(10), [-0.5, 0.5, 0.5], [1.0, 0.0, 0.0], Some(0.6)).expect("port");
        assert!(port.opened > 0);
        assert!(
            collider
                .first_intersection(&[-0.5, 0.5, 0.5], &[0.5, 0.5, 0.5])
                .is_none()
        );
        for to in [
            [0.1, -0.5, 0.5],
            [0.1, 1.5, 0.5],
            [0.1, 0.5, -0.5],
            [0.1, 0.5, 1.5],
        ] {
            assert!(
                collider.first_intersection(&[0.1, 0.5, 0.5], &to).is_some(),
                "no side wall towards {to:?}"
            );
        }
    }

    #[test]
    fn a_port_in_front_of_an_opening_finds_where_the_lumen_begins_and_cuts_nothing() {
        // The box without its x = 0 face: an open end.
        let closed = closed_box(10);
        let keep: Vec<[u32; 3]> = (0..closed.triangles().len())
            .filter(|&t| closed.triangle(t).iter().any(|p| p.x > 1e-12))
            .map(|t| closed.triangles()[t])
            .collect();
        let vertices = closed.vertices().iter().map(|p| [p.x, p.y, p.z]).collect();
        let (open, _) = TriMesh::new(vertices, keep, "open box").expect("valid");
        let (_, port) = open_port(open, [-0.2, 0.5, 0.5], [1.0, 0.0, 0.0], None).expect("port");
        assert_eq!(port.opened, 0);
        assert!((port.crossing - 0.2).abs() < 0.01, "{}", port.crossing);
        assert!((port.radius - 0.5).abs() < 0.02, "{}", port.radius);
    }

    #[test]
    fn an_axis_that_misses_the_lumen_is_an_error() {
        let err = open_port(closed_box(4), [-0.5, 0.5, 0.5], [-1.0, 0.0, 0.0], None);
        assert!(matches!(err, Err(PortError::NoLumen { .. })), "{err:?}");
        let err = open_port(closed_box(4), [-0.5, 0.5, 0.5], [1.0, 0.0, 0.0], Some(-1.0));
        assert!(matches!(err, Err(PortError::BadRadius(_))));
    }
}
