//! What is drawn, as plain data, and the triangles made from it on the CPU.
//!
//! A rod arrives as its centreline, its elements' first directors `d1` and its radius (what a
//! trajectory records) and becomes a tube: a ring of [`SIDES`] vertices around every point,
//! turned with the material frame so that the tube twists with the rod, and a cap at each end.
//! Building the tube on the CPU costs about as much as copying the points (a 512-element rod is
//! 6 000 vertices), keeps the shaders trivial, and makes the vertices identical on every
//! adapter; only the rasteriser differs between machines.
//!
//! Colours carry meaning: each rod has its own colour ([`ROD_COLOURS`]), and a point pressed
//! against the wall turns from yellow (a touch) to red (the run's force scale or more).

use bytemuck::{Pod, Zeroable};

use crate::camera::{Bounds, cross, dot, normalize, sub};

/// Vertices around a tube's ring.
pub const SIDES: usize = 12;

/// One rod at one moment.
#[derive(Clone, Copy, Debug)]
pub struct RodPose<'a> {
    /// The `n + 1` centreline points.
    pub points: &'a [[f64; 3]],
    /// The first director `d1` of each of the `n` elements; empty to let the tube choose a
    /// frame of its own (parallel transport from the first point).
    pub d1: &'a [[f64; 3]],
    /// Cross-section radius [m].
    pub radius: f64,
    /// Normal force of the wall on each of the `n + 1` points [N] (zero where a point touches
    /// nothing); `None` when the run recorded no contacts.
    pub contact_force: Option<&'a [f64]>,
}

/// A triangle mesh (the vessel), drawn translucent.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceMesh {
    /// Vertex positions [m].
    pub vertices: Vec<[f64; 3]>,
    /// Vertex indices, counter-clockwise seen from the side the normal points to (the
    /// lumen, for a vessel); that side is drawn, the other culled.
    pub triangles: Vec<[u32; 3]>,
}

impl SurfaceMesh {
    /// Grows `bounds` to hold the mesh.
    pub fn include_in(&self, bounds: &mut Bounds) {
        for &v in &self.vertices {
            bounds.include(v);
        }
    }
}

/// Grows `bounds` to hold the tube of `rod`.
pub fn include_rod(bounds: &mut Bounds, rod: &RodPose<'_>) {
    for &p in rod.points {
        bounds.include_ball(p, rod.radius);
    }
}

/// Base colour of rod `i` is `ROD_COLOURS[i % len]` (linear RGB): the scene's first rod blue,
/// the second orange, then green, purple and grey.
pub const ROD_COLOURS: [[f32; 3]; 5] = [
    [0.10, 0.30, 0.85],
    [0.95, 0.50, 0.10],
    [0.15, 0.60, 0.25],
    [0.55, 0.25, 0.70],
    [0.45, 0.45, 0.45],
];

/// Colour of a point touching a wall lightly.
const TOUCH_COLOUR: [f32; 3] = [1.0, 0.85, 0.05];
/// Colour of a point pressed with the force scale or more.
const PRESSED_COLOUR: [f32; 3] = [0.80, 0.0, 0.0];

/// Colour of the vessel (linear RGB) and its opacity.
pub const MESH_COLOUR: [f32; 4] = [0.75, 0.16, 0.16, 0.38];

/// A vertex as the shaders read it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct Vertex {
    pub(crate) position: [f32; 3],
    pub(crate) normal: [f32; 3],
    pub(crate) colour: [f32; 4],
}

impl Vertex {
    pub(crate) const ATTRIBUTES: [wgpu::VertexAttribute; 3] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x4];
}

/// The colour of a point under `force` [N] on a rod of colour `base`.
fn point_colour(base: [f32; 3], force: f64, force_scale: f64) -> [f32; 4] {
    if force > 0.0 {
        let t = (force / force_scale).clamp(0.0, 1.0) as f32;
        let c: [f32; 3] =
            std::array::from_fn(|k| TOUCH_COLOUR[k] + t * (PRESSED_COLOUR[k] - TOUCH_COLOUR[k]));
        [c[0], c[1], c[2], 1.0]
    } else {
        [base[0], base[1], base[2], 1.0]
    }
}

/// Appends the tube of `rod` (colour `base`, drawn at least `min_radius` thick) to `vertices`
/// and `indices`. A rod of fewer than two points adds nothing.
pub(crate) fn push_tube(
    rod: &RodPose<'_>,
    base: [f32; 3],
    min_radius: f64,
    force_scale: f64,
    vertices: &mut Vec<Vertex>,
    indices: &mut Vec<u32>,
) {
    let p = rod.points;
    let n = p.len();
    if n < 2 {
        return;
    }
    let radius = rod.radius.max(min_radius);
    let first = vertices.len() as u32;
    let mut previous_u: Option<[f64; 3]> = None;
    let mut rings = 0u32;
    let mut ring_frames = Vec::with_capacity(n);
    for i in 0..n {
        let t = normalize(sub(p[(i + 1).min(n - 1)], p[i.saturating_sub(1)]));
        // The material frame's d1 at the point: the mean of its elements' (neighbours of the
        // point), made perpendicular to the tangent; else the last ring's, transported.
        let d1 = match (rod.d1.get(i.wrapping_sub(1)), rod.d1.get(i)) {
            (Some(a), Some(b)) => Some([a[0] + b[0], a[1] + b[1], a[2] + b[2]]),
            (Some(a), None) | (None, Some(a)) => Some(*a),
            (None, None) => None,
        };
        let guess = d1.or(previous_u).unwrap_or_else(|| any_perpendicular(t));
        let mut u = sub(guess, t.map(|x| x * dot(guess, t)));
        if dot(u, u) < 1e-20 {
            u = any_perpendicular(t);
        }
        let u = normalize(u);
        let b = cross(t, u);
        previous_u = Some(u);
        ring_frames.push((t, u, b));
        let force = rod
            .contact_force
            .and_then(|f| f.get(i))
            .copied()
            .unwrap_or(0.0);
        let colour = point_colour(base, force, force_scale);
        for s in 0..SIDES {
            let angle = std::f64::consts::TAU * s as f64 / SIDES as f64;
            let (sin, cos) = angle.sin_cos();
            let normal: [f64; 3] = std::array::from_fn(|k| cos * u[k] + sin * b[k]);
            vertices.push(Vertex {
                position: std::array::from_fn(|k| (p[i][k] + radius * normal[k]) as f32),
                normal: normal.map(|x| x as f32),
                colour,
            });
        }
        rings += 1;
    }
    let sides = SIDES as u32;
    for r in 0..rings - 1 {
        for s in 0..sides {
            let a = first + r * sides + s;
            let b = first + r * sides + (s + 1) % sides;
            let (c, d) = (a + sides, b + sides);
            indices.extend_from_slice(&[a, b, d, a, d, c]);
        }
    }
    // Flat caps: a centre vertex and a fan over the ring, facing out of the rod.
    for (end, ring) in [(0usize, 0u32), (n - 1, rings - 1)] {
        let (t, _, _) = ring_frames[end];
        let out = if end == 0 { t.map(|x| -x) } else { t };
        let centre = vertices.len() as u32;
        let colour = vertices[(first + ring * sides) as usize].colour;
        vertices.push(Vertex {
            position: p[end].map(|x| x as f32),
            normal: out.map(|x| x as f32),
            colour,
        });
        for s in 0..sides {
            let v = vertices[(first + ring * sides + s) as usize];
            vertices.push(Vertex {
                normal: out.map(|x| x as f32),
                ..v
            });
        }
        for s in 0..sides {
            let (a, b) = (centre + 1 + s, centre + 1 + (s + 1) % sides);
            if end == 0 {
                indices.extend_from_slice(&[centre, b, a]);
            } else {
                indices.extend_from_slice(&[centre, a, b]);
            }
        }
    }
}

/// A unit vector perpendicular to the unit vector `t`.
fn any_perpendicular(t: [f64; 3]) -> [f64; 3] {
    let axis = if t[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    normalize(cross(t, axis))
}

/// The mesh's vertices with smooth (area-weighted) normals, in [`MESH_COLOUR`], and its
/// indices. Triangles naming a vertex that does not exist are dropped.
pub(crate) fn mesh_vertices(mesh: &SurfaceMesh) -> (Vec<Vertex>, Vec<u32>) {
    let nv = mesh.vertices.len();
    let mut normals = vec![[0.0f64; 3]; nv];
    let mut indices = Vec::with_capacity(mesh.triangles.len() * 3);
    for t in &mesh.triangles {
        if t.iter().any(|&i| i as usize >= nv) {
            continue;
        }
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let n = cross(sub(b, a), sub(c, a));
        for &i in t {
            let m = &mut normals[i as usize];
            for k in 0..3 {
                m[k] += n[k];
            }
        }
        indices.extend_from_slice(t);
    }
    let vertices = mesh
        .vertices
        .iter()
        .zip(&normals)
        .map(|(p, n)| Vertex {
            position: p.map(|x| x as f32),
            normal: normalize(*n).map(|x| x as f32),
            colour: MESH_COLOUR,
        })
        .collect();
    (vertices, indices)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ring's vertices lie at the radius from their point, perpendicular to the tangent,
    /// with outward unit normals, and the first ring's first vertex lies along `d1`.
    #[test]
    fn a_tube_surrounds_its_centreline() {
        let points = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.0]];
        let d1 = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]];
        let rod = RodPose {
            points: &points,
            d1: &d1,
            radius: 0.1,
            contact_force: Some(&[0.0, 2.0, 0.0]),
        };
        let (mut v, mut i) = (Vec::new(), Vec::new());
        push_tube(&rod, ROD_COLOURS[0], 0.0, 1.0, &mut v, &mut i);
        assert_eq!(v.len(), 3 * SIDES + 2 * (SIDES + 1));
        assert_eq!(i.len(), 2 * SIDES * 6 + 2 * SIDES * 3);
        assert!(i.iter().all(|&k| (k as usize) < v.len()));
        for (r, p) in points.iter().enumerate() {
            for s in 0..SIDES {
                let x = v[r * SIDES + s];
                let off: [f64; 3] = std::array::from_fn(|k| f64::from(x.position[k]) - p[k]);
                let len = dot(off, off).sqrt();
                assert!((len - 0.1).abs() < 1e-6, "ring {r} side {s}: {len}");
                let n = x.normal.map(f64::from);
                assert!((dot(n, n) - 1.0).abs() < 1e-6);
                assert!((dot(n, off) / len - 1.0).abs() < 1e-5);
            }
        }
        assert!((v[0].position[2] - 0.1).abs() < 1e-7, "{:?}", v[0]);
        // The pressed point is red, the others keep the rod's colour.
        assert_eq!(v[SIDES].colour, [0.8, 0.0, 0.0, 1.0]);
        assert_eq!(v[0].colour[..3], ROD_COLOURS[0]);
    }

    #[test]
    fn a_thin_tube_is_drawn_at_the_minimum_radius() {
        let points = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let rod = RodPose {
            points: &points,
            d1: &[],
            radius: 1e-6,
            contact_force: None,
        };
        let (mut v, mut i) = (Vec::new(), Vec::new());
        push_tube(&rod, ROD_COLOURS[1], 0.05, 1.0, &mut v, &mut i);
        let r = v[0].position[1].hypot(v[0].position[2]);
        assert!((r - 0.05).abs() < 1e-6, "{r}");
    }

    #[test]
    fn mesh_normals_follow_the_winding() {
        let mesh = SurfaceMesh {
            vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            triangles: vec![[0, 1, 2], [0, 1, 7]],
        };
        let (v, i) = mesh_vertices(&mesh);
        assert_eq!(i, vec![0, 1, 2], "the triangle naming vertex 7 is dropped");
        assert!(v.iter().all(|x| x.normal == [0.0, 0.0, 1.0]));
    }
}
