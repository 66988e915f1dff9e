//! Sphere–triangle narrow phase against a mesh, and the per-point contact response.
//!
//! A rod mass point is a sphere of radius `r`. For each point, the AABB tree yields the leaves
//! within `r`, and every triangle there is tested exactly (closest point on the triangle, Ericson's
//! Voronoi-region method, in `f64`). A triangle is *in contact* when its closest point is closer
//! than `r`.
//!
//! # Orientation and depth
//!
//! The mesh normals point into the lumen (see [`TriMesh::orient_into_lumen`]). Each contact has
//! a **feature normal** `n`: the face normal when the closest point `c` lies inside the face, as
//! in the paper, and the angle-weighted pseudo-normal of the edge or vertex otherwise (Bærentzen &
//! Aanæs 2005; on a flat wall all three are the face normal). The signed distance is
//! `s = ±|p − c|`, positive when `(p − c)·n ≥ 0`, and the penetration depth is `r − s`: between
//! 0 and `r` while the centre is still inside, above `r` once the centre has crossed the wall.
//!
//! Why not the face normal everywhere: near a ridge of the surface (the rim of a branch junction)
//! a centre in the lumen can lie behind the *plane* of a triangle whose closest point is an edge.
//! Signed by the face, that triangle entered the sphere with depth `r + |p − c|` ≈ 2r in a single
//! step, and the contact impulse threw the point out at 2r/h (hundreds of m/s at haptic steps).
//! Signed by the feature, depths grow continuously from 0 as triangles enter the sphere. For the
//! same reason, a point whose nearest feature says it is in the lumen ignores contacts seen from
//! behind (a fold or thin wall).
//!
//! # Point response
//!
//! As in the paper, a point's response is the penetration-weighted average of the normals of the
//! triangles it touches: `dir = normalize(Σ dᵢ nᵢ)`, and we report the depth as the same weighted
//! mean of the depths, `Σ dᵢ² / Σ dᵢ` (never above the largest one, which is reported too and is
//! what the solver uses).
//!
//! # Escaped points
//!
//! A point whose centre has crossed the wall is *escaped*. Testing the sign against every touched
//! face is unreliable near non-convex parts (junctions), so the sign is taken at the **nearest**
//! triangle only, against the *angle-weighted pseudo-normal* of the feature (face, edge or vertex)
//! holding the closest point (Bærentzen & Aanæs 2005). For a closed manifold surface this sign is
//! exact; for open ends it falls back to the face normal at boundary edges. `detect` only sees
//! triangles within `r`, so a point that has moved further than `r` beyond the wall has no
//! contacts; use [`MeshCollider::nearest`] with a larger search distance (e.g. the largest
//! per-step displacement) to classify such points.

use std::collections::HashMap;

use nalgebra::Vector3;

use crate::bvh::{Bvh, STACK_SIZE};
use crate::mesh::TriMesh;

/// One sphere–triangle contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Index of the query point in the batch.
    pub point: u32,
    /// Triangle index in the mesh.
    pub triangle: u32,
    /// Closest point on the triangle.
    pub closest: [f64; 3],
    /// Unsigned distance from the sphere centre to the triangle (`< r`).
    pub distance: f64,
    /// `±distance`, positive on the lumen side of the closest feature.
    pub signed_distance: f64,
    /// Penetration depth `r − signed_distance` (> 0).
    pub depth: f64,
    /// Unit feature normal (into the lumen): the face normal, or the pseudo-normal of the edge or
    /// vertex holding the closest point; the direction to push the point.
    pub normal: [f64; 3],
}

/// The aggregated response of one point (all its contacts).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PointResponse {
    /// Unit response direction, the depth-weighted mean of the contact normals; zero if no contact
    /// acts (none, only triangles seen from behind by a point in the lumen, or normals that cancel
    /// exactly).
    pub direction: [f64; 3],
    /// Depth-weighted mean depth `Σ dᵢ² / Σ dᵢ`; 0 if no contact.
    pub depth: f64,
    /// Largest single-contact depth; 0 if no contact.
    pub max_depth: f64,
    /// Index of the first contact of this point in [`ContactBuffer::contacts`].
    pub first: u32,
    /// Number of contacts of this point.
    pub count: u32,
    /// `true` if the centre is behind the nearest triangle (see the module docs).
    pub escaped: bool,
}

/// The nearest triangle in contact seen so far by a sphere query, and the nearest of all
/// triangles tested.
#[derive(Clone, Copy, Debug)]
struct Nearest2 {
    /// Squared distance of the nearest triangle in contact.
    d2: f64,
    /// Its signed distance.
    signed: f64,
    /// Whether its closest feature lies on the mesh boundary.
    at_boundary: bool,
    /// Squared distance of the nearest triangle tested, in contact or not.
    any_d2: f64,
}

impl Default for Nearest2 {
    fn default() -> Self {
        Self {
            d2: f64::INFINITY,
            signed: 0.0,
            at_boundary: false,
            any_d2: f64::INFINITY,
        }
    }
}

/// Reusable output of [`MeshCollider::detect`]: all contacts, grouped by point, and one response
/// per point. Clearing keeps the capacity, so after warm-up a detection allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct ContactBuffer {
    contacts: Vec<Contact>,
    responses: Vec<PointResponse>,
}

impl ContactBuffer {
    /// An empty buffer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Empties the buffer, keeping its allocations.
    pub fn clear(&mut self) {
        self.contacts.clear();
        self.responses.clear();
    }

    /// All contacts, grouped by point in point order.
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts
    }

    /// One response per query point, in point order.
    pub fn responses(&self) -> &[PointResponse] {
        &self.responses
    }

    /// The contacts of point `i`.
    pub fn contacts_of(&self, i: usize) -> &[Contact] {
        let r = &self.responses[i];
        &self.contacts[r.first as usize..(r.first + r.count) as usize]
    }

    /// Number of points with at least one contact.
    pub fn points_in_contact(&self) -> usize {
        self.responses.iter().filter(|r| r.count > 0).count()
    }
}

/// Which feature of a triangle holds the closest point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feature {
    /// The interior of the face.
    Face,
    /// Edge `k` from corner `k` to corner `(k + 1) % 3`.
    Edge(u8),
    /// Corner `k`.
    Vertex(u8),
}

/// Closest point on triangle `abc` to `p`, and the feature holding it (Ericson, *Real-Time
/// Collision Detection*, 5.1.5).
#[inline]
pub fn closest_point_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> (Vector3<f64>, Feature) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, Feature::Vertex(0));
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, Feature::Edge(0));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, Feature::Edge(1));
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (a + ab * v + ac * w, Feature::Face)
}

/// A triangle whose plane is farther than `r` from a point cannot touch the point's sphere; the
/// test asks for the squared plane distance to exceed `r²` by this factor, so that rounding never
/// drops a triangle that the exact test would have kept at a distance of just under `r`.
const PLANE_REJECT: f64 = 1.0 + 1e-9;

/// Per-triangle data in leaf order, so a leaf's triangles are contiguous in memory.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriData {
    pub(crate) a: Vector3<f64>,
    pub(crate) b: Vector3<f64>,
    pub(crate) c: Vector3<f64>,
    pub(crate) n: Vector3<f64>,
}

impl TriData {
    /// The squared distance from `p` to the triangle's plane when it exceeds `r2` (times
    /// [`PLANE_REJECT`]): the triangle is then farther than `r` from `p`, a test of three
    /// multiply–adds before the exact closest point. `None` when the plane is within reach.
    #[inline(always)]
    fn beyond_plane(&self, p: &Vector3<f64>, r2: f64) -> Option<f64> {
        let plane = self.n.dot(&(p - self.a));
        let d2 = plane * plane;
        (d2 > r2 * PLANE_REJECT).then_some(d2)
    }
}

/// [`MeshCollider::ridges`] for the triangles of `mesh` in the leaf order of `bvh`, with their
/// unit normals `face` (into the lumen).
fn ridge_slots(mesh: &TriMesh, bvh: &Bvh, face: &[Vector3<f64>]) -> Vec<bool> {
    let mut by_edge: HashMap<(u32, u32), Vec<u32>> =
        HashMap::with_capacity(mesh.triangles().len() * 2);
    for (t, tri) in mesh.triangles().iter().enumerate() {
        for k in 0..3 {
            let (u, v) = (tri[k], tri[(k + 1) % 3]);
            by_edge
                .entry((u.min(v), u.max(v)))
                .or_default()
                .push(t as u32);
        }
    }
    let mut ridge = vec![false; mesh.triangles().len()];
    for ((u, v), tris) in &by_edge {
        let reflex = match tris[..] {
            [a, b] => {
                // The corner of `b` off the edge, against `a`'s plane (and the other way).
                let off = |t: u32, other: u32| {
                    let tri = mesh.triangles()[other as usize];
                    let w = tri.into_iter().find(|x| x != u && x != v).unwrap_or(*u);
                    let p = mesh.vertices();
                    let e = p[w as usize] - p[*u as usize];
                    face[t as usize].dot(&e) < -1e-9 * e.norm()
                };
                off(a, b) || off(b, a)
            }
            _ => true,
        };
        if reflex {
            for &t in tris {
                ridge[t as usize] = true;
            }
        }
    }
    bvh.tri_indices()
        .iter()
        .map(|&t| ridge[t as usize])
        .collect()
}

/// The result of a nearest-triangle query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nearest {
    /// Triangle index in the mesh.
    pub triangle: u32,
    /// Closest point on the mesh.
    pub closest: [f64; 3],
    /// Unsigned distance.
    pub distance: f64,
    /// Distance signed by the pseudo-normal of the closest feature: positive in the lumen.
    pub signed_distance: f64,
    /// The closest feature is an edge or vertex of the mesh's boundary (the rim of an open end):
    /// a point outside there may have left through the opening rather than through the wall.
    pub at_opening: bool,
}

/// A mesh with its AABB tree and the data for fast sphere queries. Immutable after build, so one
/// collider can be shared by threads.
#[derive(Clone, Debug)]
pub struct MeshCollider {
    mesh: TriMesh,
    bvh: Bvh,
    /// Far-field data for inside/outside queries ([`MeshCollider::lumen_winding`]).
    winding: crate::winding::WindingNumber,
    pub(crate) tris: Vec<TriData>,
    /// Angle-weighted vertex pseudo-normals (by mesh vertex).
    vertex_normals: Vec<Vector3<f64>>,
    /// Edge pseudo-normals, 3 per triangle in leaf order (edge k = corner k → k+1).
    edge_normals: Vec<[Vector3<f64>; 3]>,
    /// Whether each of those edges lies on the mesh's boundary (belongs to one triangle only).
    edge_on_boundary: Vec<[bool; 3]>,
    /// Per leaf-order slot: whether the triangle has an edge where the lumen is not convex (a
    /// ridge: the neighbour across it falls away behind its plane), a boundary edge or an edge
    /// of more than two triangles. Only near such triangles can a segment in the lumen be
    /// nearer the wall between its ends than at them (see [`crate::segment`]).
    pub(crate) ridges: Vec<bool>,
    /// Whether each mesh vertex lies on the boundary.
    vertex_on_boundary: Vec<bool>,
}

impl MeshCollider {
    /// Builds the tree (default leaf size) and the query data for `mesh`.
    pub fn new(mesh: TriMesh) -> Self {
        let bvh = Bvh::build(&mesh);
        Self::with_bvh(mesh, bvh)
    }

    /// Uses an already built tree (e.g. with another leaf size). The tree must belong to `mesh`.
    pub fn with_bvh(mesh: TriMesh, bvh: Bvh) -> Self {
        let nt = mesh.triangles().len();
        let face: Vec<Vector3<f64>> = (0..nt).map(|t| mesh.face_normal(t)).collect();
        let mut vertex_normals = vec![Vector3::zeros(); mesh.vertices().len()];
        let mut edge_map: HashMap<(u32, u32), (Vector3<f64>, u32)> = HashMap::with_capacity(nt * 2);
        for (t, tri) in mesh.triangles().iter().enumerate() {
            let p = mesh.triangle(t);
            for k in 0..3 {
                let e1 = p[(k + 1) % 3] - p[k];
                let e2 = p[(k + 2) % 3] - p[k];
                let angle = e1.angle(&e2);
                vertex_normals[tri[k] as usize] += face[t] * angle;
                let (u, v) = (tri[k], tri[(k + 1) % 3]);
                let e = edge_map
                    .entry((u.min(v), u.max(v)))
                    .or_insert_with(|| (Vector3::zeros(), 0));
                e.0 += face[t];
                e.1 += 1;
            }
        }
        for n in &mut vertex_normals {
            *n = n.try_normalize(0.0).unwrap_or_else(Vector3::zeros);
        }
        let mut vertex_on_boundary = vec![false; mesh.vertices().len()];
        for (&(u, v), &(_, count)) in &edge_map {
            if count == 1 {
                vertex_on_boundary[u as usize] = true;
                vertex_on_boundary[v as usize] = true;
            }
        }
        let mut tris = Vec::with_capacity(nt);
        let mut edge_normals = Vec::with_capacity(nt);
        let mut edge_on_boundary = Vec::with_capacity(nt);
        for &t in bvh.tri_indices() {
            let t = t as usize;
            let [a, b, c] = mesh.triangle(t);
            tris.push(TriData {
                a,
                b,
                c,
                n: face[t],
            });
            let tri = mesh.triangles()[t];
            let mut en = [Vector3::zeros(); 3];
            let mut boundary = [false; 3];
            for k in 0..3 {
                let (u, v) = (tri[k], tri[(k + 1) % 3]);
                let (sum, count) = edge_map[&(u.min(v), u.max(v))];
                en[k] = sum.try_normalize(0.0).unwrap_or(face[t]);
                boundary[k] = count == 1;
            }
            edge_normals.push(en);
            edge_on_boundary.push(boundary);
        }
        let ridges = ridge_slots(&mesh, &bvh, &face);
        let winding = crate::winding::WindingNumber::new(&mesh, &bvh);
        Self {
            winding,
            ridges,
            mesh,
            bvh,
            tris,
            vertex_normals,
            edge_normals,
            edge_on_boundary,
            vertex_on_boundary,
        }
    }

    /// The winding number of the lumen at `p` ([`crate::winding`]): about 1 inside the lumen
    /// (the side the normals point to), about 0 outside, whatever the distance to the wall.
    pub fn lumen_winding(&self, p: &[f64; 3]) -> f64 {
        self.winding.lumen(&self.mesh, &self.bvh, p)
    }

    /// Whether the mesh, its openings closed, encloses a volume (a lumen), so that
    /// [`Self::lumen_winding`] tells inside from outside; a sheet does not.
    pub fn encloses_volume(&self) -> bool {
        self.winding.encloses_volume(&self.mesh)
    }

    /// The mesh.
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// The tree.
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Whether `feature` of the triangle in leaf-order slot `slot` lies on the mesh's boundary.
    pub(crate) fn on_boundary(&self, slot: usize, feature: Feature) -> bool {
        match feature {
            Feature::Face => false,
            Feature::Edge(k) => self.edge_on_boundary[slot][k as usize],
            Feature::Vertex(k) => {
                let t = self.bvh.tri_indices()[slot] as usize;
                self.vertex_on_boundary[self.mesh.triangles()[t][k as usize] as usize]
            }
        }
    }

    /// The number of triangle edges on the mesh's boundary.
    #[cfg(test)]
    pub(crate) fn edge_on_boundary_count(&self) -> usize {
        self.edge_on_boundary
            .iter()
            .flatten()
            .filter(|&&b| b)
            .count()
    }

    /// The pseudo-normal of `feature` of the triangle in leaf-order slot `slot`.
    pub(crate) fn pseudo_normal(&self, slot: usize, feature: Feature) -> Vector3<f64> {
        match feature {
            Feature::Face => self.tris[slot].n,
            Feature::Edge(k) => self.edge_normals[slot][k as usize],
            Feature::Vertex(k) => {
                let t = self.bvh.tri_indices()[slot] as usize;
                self.vertex_normals[self.mesh.triangles()[t][k as usize] as usize]
            }
        }
    }

    /// Contacts of one sphere (centre `p`, radius `r`), appended to `out` tagged with `point`;
    /// returns the point's response. Triangles are reported in leaf order.
    pub fn query_sphere(
        &self,
        p: &[f64; 3],
        r: f64,
        point: u32,
        out: &mut Vec<Contact>,
    ) -> PointResponse {
        let first = out.len();
        let pv = Vector3::from(*p);
        let mut nearest = Nearest2::default();
        self.bvh.for_each_near(p, r, |slot| {
            self.test_slot(&pv, r, point, slot, out, &mut nearest);
        });
        self.respond(first, &nearest, out)
    }

    /// The leaf-order slots (see [`Bvh::tri_indices`]) of the triangles closer than `r` to `p`,
    /// in leaf order, written to `out` (cleared first).
    ///
    /// A sphere of radius `r' ≤ r − |p' − p|` around a point `p'` can only touch these
    /// triangles, so a slowly moving point can query this list ([`Self::query_sphere_among`])
    /// instead of the tree until it has moved `r − r'`.
    pub fn near_slots(&self, p: &[f64; 3], r: f64, out: &mut Vec<u32>) {
        out.clear();
        let pv = Vector3::from(*p);
        let r2 = r * r;
        self.bvh.for_each_near(p, r, |slot| {
            let t = &self.tris[slot];
            if t.beyond_plane(&pv, r2).is_some() {
                return;
            }
            let (c, _) = closest_point_triangle(&pv, &t.a, &t.b, &t.c);
            if (pv - c).norm_squared() < r2 {
                out.push(slot as u32);
            }
        });
    }

    /// [`Self::query_sphere`] restricted to the triangles in leaf-order `slots` (from
    /// [`Self::near_slots`]); also returns the distance from `p` to the nearest of them
    /// (infinite if `slots` is empty). When `slots` holds every triangle within `r` of `p` and
    /// is in leaf order, the contacts and the response are exactly those of `query_sphere`.
    pub fn query_sphere_among(
        &self,
        p: &[f64; 3],
        r: f64,
        point: u32,
        slots: &[u32],
        out: &mut Vec<Contact>,
    ) -> (PointResponse, f64) {
        let first = out.len();
        let pv = Vector3::from(*p);
        let mut nearest = Nearest2::default();
        for &slot in slots {
            self.test_slot(&pv, r, point, slot as usize, out, &mut nearest);
        }
        (self.respond(first, &nearest, out), nearest.any_d2.sqrt())
    }

    /// The exact sphere–triangle test of one leaf-order slot: a contact is appended to `out`
    /// when the triangle is closer than `r`; `nearest` tracks the nearest feature.
    #[inline(always)]
    fn test_slot(
        &self,
        pv: &Vector3<f64>,
        r: f64,
        point: u32,
        slot: usize,
        out: &mut Vec<Contact>,
        nearest: &mut Nearest2,
    ) {
        let t = &self.tris[slot];
        // The distance to the triangle's plane bounds the distance to the triangle from below:
        // a plane at least `r` away rules the triangle out, and its distance stands in for the
        // triangle's in `any_d2` (a lower bound, as its callers use it: a clearance that is
        // never too large).
        if let Some(plane2) = t.beyond_plane(pv, r * r) {
            nearest.any_d2 = nearest.any_d2.min(plane2);
            return;
        }
        let (c, feature) = closest_point_triangle(pv, &t.a, &t.b, &t.c);
        let diff = pv - c;
        let d2 = diff.norm_squared();
        nearest.any_d2 = nearest.any_d2.min(d2);
        if d2 < r * r {
            let d = d2.sqrt();
            let n = self.pseudo_normal(slot, feature);
            let sd = if diff.dot(&n) >= 0.0 { d } else { -d };
            if d2 < nearest.d2 {
                *nearest = Nearest2 {
                    d2,
                    signed: sd,
                    at_boundary: self.on_boundary(slot, feature),
                    any_d2: nearest.any_d2,
                };
            }
            out.push(Contact {
                point,
                triangle: self.bvh.tri_indices()[slot],
                closest: c.into(),
                distance: d,
                signed_distance: sd,
                depth: r - sd,
                normal: n.into(),
            });
        }
    }

    /// The response of the point whose contacts are `out[first..]`.
    fn respond(&self, first: usize, nearest: &Nearest2, out: &[Contact]) -> PointResponse {
        if out.len() == first {
            return PointResponse {
                first: first as u32,
                ..PointResponse::default()
            };
        }
        // The nearest feature decides the side (exact for a closed manifold). A centre in the lumen
        // that sees some other triangle from behind (a fold, a thin wall, the far side of a
        // junction's rim) is not pushed through that triangle: such a contact would enter the
        // sphere with a depth of 2r in one step, a kick of 2r/h. It stays in the contact list
        // (the geometric query is complete) but not in the response.
        // Behind the rim of an open end is outside the mesh but not through its wall.
        let escaped = nearest.signed < 0.0 && !nearest.at_boundary;
        let mut sum_n = Vector3::zeros();
        let (mut sum_w, mut sum_w2, mut max_d) = (0.0, 0.0, 0.0f64);
        for k in out[first..]
            .iter()
            .filter(|k| escaped || k.signed_distance >= 0.0)
        {
            sum_n += Vector3::from(k.normal) * k.depth;
            sum_w += k.depth;
            sum_w2 += k.depth * k.depth;
            max_d = max_d.max(k.depth);
        }
        let count = (out.len() - first) as u32;
        if !(sum_w > 0.0) {
            return PointResponse {
                first: first as u32,
                count,
                ..PointResponse::default()
            };
        }
        let direction = sum_n.try_normalize(0.0).unwrap_or_else(Vector3::zeros);
        PointResponse {
            direction: direction.into(),
            depth: sum_w2 / sum_w,
            max_depth: max_d,
            first: first as u32,
            count,
            escaped,
        }
    }

    /// Batch detection for rod points of one radius: clears `out`, then fills one
    /// [`PointResponse`] per point and all contacts. Allocation-free once `out` has grown.
    pub fn detect(&self, points: &[[f64; 3]], radius: f64, out: &mut ContactBuffer) {
        out.clear();
        out.responses.reserve(points.len());
        for (i, p) in points.iter().enumerate() {
            let resp = self.query_sphere(p, radius, i as u32, &mut out.contacts);
            out.responses.push(resp);
        }
    }

    /// Like [`detect`](Self::detect) with one radius per point (`radii.len()` must equal
    /// `points.len()`; extra entries of the longer slice are ignored).
    pub fn detect_with_radii(&self, points: &[[f64; 3]], radii: &[f64], out: &mut ContactBuffer) {
        out.clear();
        out.responses.reserve(points.len());
        for (i, (p, &r)) in points.iter().zip(radii).enumerate() {
            let resp = self.query_sphere(p, r, i as u32, &mut out.contacts);
            out.responses.push(resp);
        }
    }

    /// The nearest triangle to `p` within `max_distance` (use `f64::INFINITY` for no limit), with
    /// the distance signed by the closest feature's pseudo-normal (positive in the lumen, negative
    /// for an escaped point). `None` if no triangle is that close.
    pub fn nearest(&self, p: &[f64; 3], max_distance: f64) -> Option<Nearest> {
        let pv = Vector3::from(*p);
        let nodes = self.bvh.nodes();
        let mut best_d2 = max_distance * max_distance;
        let mut best: Option<(usize, Vector3<f64>, Feature)> = None;
        let mut stack = [(0u32, 0.0f64); STACK_SIZE];
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let (ni, d2) = stack[sp];
            if d2 > best_d2 {
                continue;
            }
            let n = &nodes[ni as usize];
            if n.is_leaf() {
                for slot in n.first as usize..(n.first + n.count) as usize {
                    let t = &self.tris[slot];
                    let (c, f) = closest_point_triangle(&pv, &t.a, &t.b, &t.c);
                    let d2 = (pv - c).norm_squared();
                    if d2 <= best_d2 {
                        best_d2 = d2;
                        best = Some((slot, c, f));
                    }
                }
            } else {
                let (l, r) = (n.first, n.first + 1);
                let dl = nodes[l as usize].distance_squared(p);
                let dr = nodes[r as usize].distance_squared(p);
                // Push the farther child first so the nearer one is explored first.
                let (near, far) = if dl <= dr {
                    ((l, dl), (r, dr))
                } else {
                    ((r, dr), (l, dl))
                };
                if far.1 <= best_d2 {
                    stack[sp] = far;
                    sp += 1;
                }
                if near.1 <= best_d2 {
                    stack[sp] = near;
                    sp += 1;
                }
            }
        }
        let (slot, c, f) = best?;
        let diff = pv - c;
        let d = diff.norm();
        let sign = if diff.dot(&self.pseudo_normal(slot, f)) >= 0.0 {
            1.0
        } else {
            -1.0
        };
        Some(Nearest {
            triangle: self.bvh.tri_indices()[slot],
            closest: c.into(),
            distance: d,
            signed_distance: sign * d,
            at_opening: self.on_boundary(slot, f),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square floor at z = 0 of 2·n² triangles, normals +z (the "lumen" is above).
    fn floor(n: usize) -> MeshCollider {
        MeshCollider::new(
            TriMesh::patch([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], n, "floor").expect("valid"),
        )
    }

    #[test]
    fn flat_wall_response_and_escape() {
        let c = floor(10);
        let mut buf = ContactBuffer::new();
        let pts = [[0.53, 0.47, 0.02], [0.5, 0.5, -0.01], [0.31, 0.62, 0.2]];
        c.detect(&pts, 0.05, &mut buf);
        let r = buf.responses();
        assert_eq!(r.len(), 3);
        // Above the floor: pushed up by r - d.
        assert!(r[0].count >= 2 && !r[0].escaped);
        // The triangle under the point gives r - d; those beside it are farther (less deep).
        assert!((r[0].max_depth - 0.03).abs() < 1e-12);
        assert!(r[0].depth > 0.0 && r[0].depth <= r[0].max_depth);
        assert!((r[0].direction[2] - 1.0).abs() < 1e-12);
        // Below the floor (centre crossed the wall): escaped, depth r + d, still pushed up.
        assert!(r[1].escaped && (r[1].max_depth - 0.06).abs() < 1e-12);
        assert!((r[1].direction[2] - 1.0).abs() < 1e-12);
        // Far above: nothing.
        assert_eq!(r[2].count, 0);
        assert_eq!(r[2].direction, [0.0; 3]);
        // Grouping: contacts_of(i) are point i's, and cover all contacts in order.
        let total: usize = (0..3).map(|i| buf.contacts_of(i).len()).sum();
        assert_eq!(total, buf.contacts().len());
        assert!(
            buf.contacts_of(1)
                .iter()
                .all(|k| k.point == 1 && k.signed_distance < 0.0)
        );
        assert_eq!(buf.points_in_contact(), 2);
        // Nearest: signed by the pseudo-normal; an unlimited search always finds one.
        let n = c.nearest(&[0.5, 0.5, -0.3], f64::INFINITY).unwrap();
        assert!((n.signed_distance + 0.3).abs() < 1e-12);
        assert!(c.nearest(&[0.5, 0.5, -0.3], 0.1).is_none());
        // Per-point radii.
        c.detect_with_radii(&pts, &[0.01, 0.05, 0.5], &mut buf);
        assert_eq!(buf.responses()[0].count, 0);
        assert!(buf.responses()[2].count > 0);
    }

    #[test]
    fn batch_detection_reuses_buffers() {
        let c = floor(20);
        let pts: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                [
                    (i % 25) as f64 / 25.0,
                    (i / 25) as f64 / 20.0,
                    0.01 * (i % 7) as f64 - 0.02,
                ]
            })
            .collect();
        let mut buf = ContactBuffer::new();
        c.detect(&pts, 0.03, &mut buf);
        let first: Vec<Contact> = buf.contacts().to_vec();
        let caps = (buf.contacts.capacity(), buf.responses.capacity());
        let ptrs = (buf.contacts.as_ptr(), buf.responses.as_ptr());
        c.detect(&pts, 0.03, &mut buf);
        assert_eq!(buf.contacts(), &first[..]);
        assert_eq!((buf.contacts.capacity(), buf.responses.capacity()), caps);
        assert_eq!((buf.contacts.as_ptr(), buf.responses.as_ptr()), ptrs);
    }

    #[test]
    fn gpu_export_matches_the_tree() {
        let c = floor(8);
        let g = c.to_gpu();
        assert_eq!(std::mem::size_of::<crate::GpuTriangle>(), 48);
        assert_eq!(g.nodes, c.bvh().nodes());
        assert_eq!(g.triangles.len(), c.mesh().triangles().len());
        for (slot, gt) in g.triangles.iter().enumerate() {
            assert_eq!(gt.index, c.bvh().tri_indices()[slot]);
            let [a, _, _] = c.mesh().triangle(gt.index as usize);
            assert_eq!(gt.a, [a.x as f32, a.y as f32, a.z as f32]);
        }
        assert_eq!(g.depth as usize, c.bvh().depth());
    }

    /// A ridge seen from the lumen: a floor `z = 0` for `x < 0` (normal +z) bent down into a wall
    /// `x = 0` for `z < 0` (normal +x). The lumen wraps round the edge on the y axis, like the
    /// rim of a branch junction.
    fn ridge() -> MeshCollider {
        let v = vec![
            [-1.0, -1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
            [0.0, -1.0, -1.0],
            [0.0, 1.0, -1.0],
        ];
        let t = vec![[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]];
        MeshCollider::new(TriMesh::new(v, t, "ridge").expect("valid").0)
    }

    #[test]
    fn a_point_beside_a_ridge_is_not_pushed_through_the_other_face() {
        let c = ridge();
        assert!((c.mesh().face_normal(0).z - 1.0).abs() < 1e-12);
        assert!((c.mesh().face_normal(2).x - 1.0).abs() < 1e-12);
        let r = 0.1;
        let mut buf = ContactBuffer::new();
        // Above the floor, just short of the edge: 0.5 r above the floor, 0.1 r behind the
        // plane of the wall. The wall's closest point is on the shared edge.
        let p = [-0.01, 0.0, 0.05];
        c.detect(&[p], r, &mut buf);
        let resp = buf.responses()[0];
        assert!(!resp.escaped);
        let wall = buf.contacts().iter().filter(|k| k.triangle >= 2).count();
        assert!(resp.count >= 2 && wall >= 1, "{:?}", buf.contacts());
        // The floor gives r − 0.5 r; every other contact is shallower. Signed by the wall's face
        // normal, the wall triangles would report r + |p − edge| ≈ 1.5 r.
        assert!((resp.max_depth - 0.5 * r).abs() < 1e-12, "{resp:?}");
        for k in buf.contacts() {
            assert!(
                k.signed_distance > 0.0 && k.depth <= 0.5 * r + 1e-12,
                "{k:?}"
            );
        }
        // Pushed up and out over the edge, never into the wall's side.
        assert!(
            resp.direction[2] > 0.7 && resp.direction[0] > 0.0,
            "{resp:?}"
        );
        // Past the wall's plane and beside it: the mirror case.
        c.detect(&[[0.05, 0.0, -0.01]], r, &mut buf);
        let resp = buf.responses()[0];
        assert!(!resp.escaped && (resp.max_depth - 0.5 * r).abs() < 1e-12);
        assert!(
            resp.direction[0] > 0.7 && resp.direction[2] > 0.0,
            "{resp:?}"
        );
        // Inside the solid below the floor and behind the wall: escaped, pushed back out.
        c.detect(&[[-0.02, 0.0, -0.03]], r, &mut buf);
        let resp = buf.responses()[0];
        assert!(resp.escaped && resp.max_depth > r, "{resp:?}");
    }
}
