//! A procedural vessel tree: an aorta-like trunk with a few branches, as a triangle mesh whose
//! normals point into the lumen.
//!
//! Why: tests and benchmarks need a vessel of a known shape (so "inside the lumen" is known
//! exactly), of the paper's size (~26 000 triangles), deterministic and without external files.
//!
//! Construction:
//! * Each vessel (trunk, branches) is a tube swept along a centreline with parallel-transported
//!   frames; rings of `nθ` vertices, quads split into two triangles wound so that the face normals
//!   point to the axis. The radius varies linearly along each centreline.
//! * The trunk is a gently curved 3-D curve starting at the [`Vessel::entry_point`] and heading
//!   along [`Vessel::entry_direction`]; it stays open at both ends (the inlet where a wire goes in,
//!   and the outlet). Branch ends are open too.
//! * Junctions are made watertight: a hole is cut in the trunk wall (every trunk triangle touching
//!   a vertex within `1.3 rb` of the branch axis), the branch tube starts at its first ring lying
//!   fully outside the trunk (by 15 % of the trunk radius), and the hole's rim is zipped to that
//!   ring by a band of triangles merged in angle order around the branch axis. The result is a
//!   manifold surface with a funnel-shaped junction and no gaps, so the sign of the distance to
//!   the nearest triangle (pseudo-normal rule, see [`crate::contact`]) is right near junctions too.
//! * The edge length is chosen from the target triangle count and the total wall area.

use std::collections::{HashMap, HashSet};
use std::f64::consts::PI;

use nalgebra::Vector3;

use crate::mesh::{MeshError, MeshReport, TriMesh};

type V = Vector3<f64>;

/// One side branch, placed relative to the trunk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BranchParams {
    /// Where it leaves the trunk, as a fraction `0..1` of the trunk length.
    pub at: f64,
    /// Direction around the trunk (radians, in the trunk's transported frame).
    pub azimuth: f64,
    /// Angle between the branch and the trunk tangent (radians).
    pub angle: f64,
    /// Length from the trunk axis (m).
    pub length: f64,
    /// Radius at the start (m); keep it at most about half the local trunk radius.
    pub radius_start: f64,
    /// Radius at the end (m).
    pub radius_end: f64,
}

/// A smooth change of the trunk's radius over a stretch of its length: a stenosis (`factor`
/// below 1) or a fusiform aneurysm (above 1). The radius is multiplied by
/// `1 + (factor − 1) (1 + cos(2π d / length)) / 2` within `length / 2` of its centre `d = 0`.
/// Keep a bulge away from the branches' holes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bulge {
    /// Its centre, as a fraction `0..1` of the trunk length.
    pub at: f64,
    /// Its length along the trunk (m).
    pub length: f64,
    /// The radius at its centre over the radius without it.
    pub factor: f64,
}

impl Bulge {
    /// The factor on the radius at fraction `u` of a trunk of length `trunk_length`.
    fn scale(&self, u: f64, trunk_length: f64) -> f64 {
        let d = (u - self.at) * trunk_length;
        if d.abs() >= 0.5 * self.length {
            1.0
        } else {
            1.0 + (self.factor - 1.0) * 0.5 * (1.0 + (2.0 * PI * d / self.length).cos())
        }
    }
}

/// Parameters of [`generate`].
#[derive(Clone, Debug, PartialEq)]
pub struct VesselParams {
    /// Approximate number of triangles (the result is within a few percent).
    pub target_triangles: usize,
    /// Trunk length (m).
    pub trunk_length: f64,
    /// Trunk radius at the inlet (m).
    pub trunk_radius_start: f64,
    /// Trunk radius at the outlet (m).
    pub trunk_radius_end: f64,
    /// Sideways bow of the trunk centreline (m): `x = bow · sin(πu)`, `y = bow/3 · sin(2πu)`.
    pub bow: f64,
    /// The branches.
    pub branches: Vec<BranchParams>,
    /// Stenoses and aneurysms of the trunk.
    pub bulges: Vec<Bulge>,
}

impl Default for VesselParams {
    /// An aorta-like default: 0.4 m trunk, radius 10 → 6 mm, four branches of radius 5 → 3 mm,
    /// about 26 000 triangles like the paper's phantom (26066).
    fn default() -> Self {
        let deg = PI / 180.0;
        Self {
            target_triangles: 26_000,
            trunk_length: 0.4,
            trunk_radius_start: 0.010,
            trunk_radius_end: 0.006,
            bow: 0.03,
            branches: vec![
                BranchParams {
                    at: 0.22,
                    azimuth: 0.0,
                    angle: 60.0 * deg,
                    length: 0.10,
                    radius_start: 0.005,
                    radius_end: 0.004,
                },
                BranchParams {
                    at: 0.45,
                    azimuth: 2.2,
                    angle: 50.0 * deg,
                    length: 0.10,
                    radius_start: 0.0045,
                    radius_end: 0.0035,
                },
                BranchParams {
                    at: 0.62,
                    azimuth: 4.2,
                    angle: 45.0 * deg,
                    length: 0.09,
                    radius_start: 0.004,
                    radius_end: 0.003,
                },
                BranchParams {
                    at: 0.80,
                    azimuth: 1.0,
                    angle: 40.0 * deg,
                    length: 0.08,
                    radius_start: 0.0035,
                    radius_end: 0.003,
                },
            ],
            bulges: Vec::new(),
        }
    }
}

impl VesselParams {
    /// A random vessel tree of the default's kind, for studies and learning over many
    /// anatomies: trunk length 0.30–0.45 m, inlet radius 8–12 mm narrowing to 55–75 % of it,
    /// a bow of 0–40 mm, and two to four straight branches spread along the trunk (one per
    /// stretch of it, so their junctions do not overlap), leaving at 35–70° in any direction,
    /// 60–110 mm long, 35–50 % of the local trunk radius at their start and 70–90 % of that at
    /// their end. The same seed gives the same parameters. Not every draw makes a valid
    /// surface; [`generate_random`] draws until one does.
    pub fn random(seed: u64, target_triangles: usize) -> Self {
        let mut rng = SplitMix(seed);
        let deg = PI / 180.0;
        let trunk_length = rng.range(0.30, 0.45);
        let trunk_radius_start = rng.range(0.008, 0.012);
        let trunk_radius_end = trunk_radius_start * rng.range(0.55, 0.75);
        let bow = rng.range(0.0, 0.04);
        let count = 2 + (rng.next() * 3.0) as usize;
        let (lo, hi) = (0.15, 0.85);
        let slot = (hi - lo) / count as f64;
        let branches = (0..count)
            .map(|k| {
                let at = lo + slot * (k as f64 + rng.range(0.2, 0.8));
                let trunk_r = trunk_radius_start + (trunk_radius_end - trunk_radius_start) * at;
                let radius_start = trunk_r * rng.range(0.35, 0.5);
                BranchParams {
                    at,
                    azimuth: rng.range(0.0, 2.0 * PI),
                    angle: rng.range(35.0, 70.0) * deg,
                    length: rng.range(0.06, 0.11),
                    radius_start,
                    radius_end: radius_start * rng.range(0.7, 0.9),
                }
            })
            .collect();
        Self {
            target_triangles,
            trunk_length,
            trunk_radius_start,
            trunk_radius_end,
            bow,
            branches,
            bulges: Vec::new(),
        }
    }
}

/// A small deterministic generator (SplitMix64): the same seed gives the same vessel on every
/// platform, without a dependency.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }
}

/// The vessel of the first valid draw of [`VesselParams::random`] from `seed` (draws from a
/// fixed sequence of seeds derived from it, so the result depends on `seed` only), and the
/// parameters it was made from.
pub fn generate_random(
    seed: u64,
    target_triangles: usize,
) -> Result<(Vessel, VesselParams), MeshError> {
    let mut last = None;
    for attempt in 0..64u64 {
        let params = VesselParams::random(
            seed.wrapping_add(attempt.wrapping_mul(0xD1B5_4A32_D192_ED03)),
            target_triangles,
        );
        match generate(&params) {
            Ok(v) => return Ok((v, params)),
            Err(e) => last = Some(e),
        }
    }
    Err(last.unwrap_or_else(|| invalid(format!("no valid random vessel from seed {seed}"))))
}

/// A sampled centreline with its radius.
#[derive(Clone, Debug, PartialEq)]
pub struct Centreline {
    /// Points along the axis (m).
    pub points: Vec<[f64; 3]>,
    /// Lumen radius at each point (m).
    pub radii: Vec<f64>,
}

impl Centreline {
    /// Position and radius at fraction `u ∈ [0, 1]` of the point list (linear interpolation).
    pub fn sample(&self, u: f64) -> ([f64; 3], f64) {
        let n = self.points.len();
        if n == 1 {
            return (self.points[0], self.radii[0]);
        }
        let x = u.clamp(0.0, 1.0) * (n - 1) as f64;
        let i = (x.floor() as usize).min(n - 2);
        let f = x - i as f64;
        let (a, b) = (V::from(self.points[i]), V::from(self.points[i + 1]));
        (
            (a + (b - a) * f).into(),
            self.radii[i] + (self.radii[i + 1] - self.radii[i]) * f,
        )
    }
}

/// A generated vessel tree.
#[derive(Clone, Debug)]
pub struct Vessel {
    /// The wall, normals into the lumen.
    pub mesh: TriMesh,
    /// Validation report of the mesh (expect no repairs, boundary edges only at the open ends).
    pub report: MeshReport,
    /// The trunk centreline, from the inlet.
    pub trunk: Centreline,
    /// The branch centrelines, each from the trunk axis outward.
    pub branches: Vec<Centreline>,
    /// Centre of the inlet ring, where a wire is pushed in.
    pub entry_point: [f64; 3],
    /// Unit direction into the trunk at the inlet.
    pub entry_direction: [f64; 3],
}

impl Vessel {
    /// The default vessel tree ([`VesselParams::default`]).
    pub fn default_tree() -> Result<Self, MeshError> {
        generate(&VesselParams::default())
    }
}

fn trunk_point(p: &VesselParams, u: f64) -> V {
    V::new(
        p.bow * (PI * u).sin(),
        p.bow / 3.0 * (2.0 * PI * u).sin(),
        p.trunk_length * u,
    )
}

fn any_perp(t: &V) -> V {
    let trial = if t.x.abs() < 0.9 { V::x() } else { V::y() };
    t.cross(&trial).normalize()
}

/// Rings of a tube: stations with frames. Returns (centre, tangent, normal, binormal, radius).
struct Station {
    c: V,
    n: V,
    b: V,
    r: f64,
}

fn transport_frames(points: &[V], radii: &[f64], n0: V) -> Vec<Station> {
    let m = points.len();
    let tangent = |i: usize| {
        let (a, b) = if i == 0 {
            (points[0], points[1])
        } else if i == m - 1 {
            (points[m - 2], points[m - 1])
        } else {
            (points[i - 1], points[i + 1])
        };
        (b - a).normalize()
    };
    let mut out = Vec::with_capacity(m);
    let mut t_prev = tangent(0);
    let mut n = (n0 - t_prev * n0.dot(&t_prev)).normalize();
    for i in 0..m {
        let t = tangent(i);
        // Parallel transport: rotate n by the rotation taking t_prev to t.
        let axis = t_prev.cross(&t);
        let s = axis.norm();
        if s > 1e-12 {
            let ang = s.atan2(t_prev.dot(&t));
            let rot =
                nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), ang);
            n = rot * n;
        }
        n = (n - t * n.dot(&t)).normalize();
        let b = t.cross(&n);
        out.push(Station {
            c: points[i],
            n,
            b,
            r: radii[i],
        });
        t_prev = t;
    }
    out
}

/// Appends the ring vertices of `stations` (nθ each) and returns the index of the first.
fn add_rings(verts: &mut Vec<V>, stations: &[Station], nt: usize) -> usize {
    let base = verts.len();
    for s in stations {
        for j in 0..nt {
            let th = 2.0 * PI * j as f64 / nt as f64;
            verts.push(s.c + (s.n * th.cos() + s.b * th.sin()) * s.r);
        }
    }
    base
}

/// Tube triangles between consecutive rings, wound so normals point to the axis.
fn tube_triangles(base: usize, rings: usize, nt: usize) -> Vec<[u32; 3]> {
    let mut tris = Vec::with_capacity(2 * nt * rings.saturating_sub(1));
    for i in 0..rings.saturating_sub(1) {
        for j in 0..nt {
            let a = (base + i * nt + j) as u32;
            let b = (base + (i + 1) * nt + j) as u32;
            let c = (base + i * nt + (j + 1) % nt) as u32;
            let d = (base + (i + 1) * nt + (j + 1) % nt) as u32;
            tris.push([a, b, c]);
            tris.push([b, d, c]);
        }
    }
    tris
}

fn dist_point_polyline(p: &V, line: &[V], radii: &[f64]) -> (f64, f64) {
    let mut best = (f64::INFINITY, 0.0);
    for i in 0..line.len() - 1 {
        let (a, b) = (line[i], line[i + 1]);
        let ab = b - a;
        let t = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
        let d = (p - (a + ab * t)).norm();
        if d < best.0 {
            best = (d, radii[i] + (radii[i + 1] - radii[i]) * t);
        }
    }
    best
}

fn invalid(msg: String) -> MeshError {
    MeshError::Parse {
        path: "generated vessel".into(),
        line: None,
        message: msg,
    }
}

/// Generates the vessel tree. Errors only for parameters that cannot make a valid surface (e.g.
/// a branch too wide for the trunk), reported as [`MeshError`] naming "generated vessel".
pub fn generate(p: &VesselParams) -> Result<Vessel, MeshError> {
    let finite_pos = |x: f64| x.is_finite() && x > 0.0;
    if !(finite_pos(p.trunk_length)
        && finite_pos(p.trunk_radius_start)
        && finite_pos(p.trunk_radius_end)
        && p.bow.is_finite()
        && p.target_triangles >= 100
        && p.bulges
            .iter()
            .all(|b| b.at > 0.0 && b.at < 1.0 && finite_pos(b.length) && finite_pos(b.factor)))
    {
        return Err(invalid(format!("invalid vessel parameters {p:?}")));
    }
    // Edge length from the wall area: triangles ≈ 2 · area / h².
    let mean_r = |a: f64, b: f64| 0.5 * (a + b);
    let mut area = 2.0 * PI * mean_r(p.trunk_radius_start, p.trunk_radius_end) * p.trunk_length;
    for b in &p.branches {
        area += 2.0 * PI * mean_r(b.radius_start, b.radius_end) * b.length;
    }
    let h = (2.0 * area / p.target_triangles as f64).sqrt();

    // Trunk.
    let ns = ((p.trunk_length / h).round() as usize).max(2) + 1;
    let trunk_pts: Vec<V> = (0..ns)
        .map(|i| trunk_point(p, i as f64 / (ns - 1) as f64))
        .collect();
    let trunk_r: Vec<f64> = (0..ns)
        .map(|i| {
            let u = i as f64 / (ns - 1) as f64;
            let bulged: f64 = p
                .bulges
                .iter()
                .map(|b| b.scale(u, p.trunk_length))
                .product();
            (p.trunk_radius_start + (p.trunk_radius_end - p.trunk_radius_start) * u) * bulged
        })
        .collect();
    let t0 = (trunk_pts[1] - trunk_pts[0]).normalize();
    let trunk_st = transport_frames(&trunk_pts, &trunk_r, any_perp(&t0));
    let nt_trunk =
        ((2.0 * PI * mean_r(p.trunk_radius_start, p.trunk_radius_end) / h).round() as usize).max(8);
    let mut verts: Vec<V> = Vec::new();
    let trunk_base = add_rings(&mut verts, &trunk_st, nt_trunk);
    let mut tris = tube_triangles(trunk_base, ns, nt_trunk);
    let trunk_vert_end = verts.len();

    let mut branch_lines = Vec::new();
    let mut removed: HashSet<usize> = HashSet::new();
    let mut bands: Vec<[u32; 3]> = Vec::new();
    for (bi, bp) in p.branches.iter().enumerate() {
        if !(bp.at > 0.0
            && bp.at < 1.0
            && finite_pos(bp.length)
            && finite_pos(bp.radius_start)
            && finite_pos(bp.radius_end)
            && bp.angle.is_finite()
            && bp.azimuth.is_finite())
        {
            return Err(invalid(format!("invalid branch {bi}: {bp:?}")));
        }
        let k = ((bp.at * (ns - 1) as f64).round() as usize).clamp(1, ns - 2);
        let st = &trunk_st[k];
        let tk = st.n.cross(&st.b);
        let c0 = st.c;
        let radial = st.n * bp.azimuth.cos() + st.b * bp.azimuth.sin();
        let d = (tk * bp.angle.cos() + radial * bp.angle.sin()).normalize();
        let rb = |s: f64| bp.radius_start + (bp.radius_end - bp.radius_start) * (s / bp.length);
        // Branch frame at the start: n perpendicular to d, pointing along the trunk tangent side.
        let bn0 = (tk - d * tk.dot(&d))
            .try_normalize(1e-9)
            .unwrap_or_else(|| any_perp(&d));
        let bb0 = d.cross(&bn0);
        let nt_b =
            ((2.0 * PI * mean_r(bp.radius_start, bp.radius_end) / h).round() as usize).max(8);
        // First station whose ring is fully outside the trunk by a margin.
        let step = 0.25 * h;
        let mut s0 = None;
        let mut s = 0.0;
        while s < 0.6 * bp.length {
            let c = c0 + d * s;
            let outside = (0..nt_b).all(|j| {
                let th = 2.0 * PI * j as f64 / nt_b as f64;
                let v = c + (bn0 * th.cos() + bb0 * th.sin()) * rb(s);
                let (dist, rt) = dist_point_polyline(&v, &trunk_pts, &trunk_r);
                dist > 1.15 * rt
            });
            if outside {
                s0 = Some(s);
                break;
            }
            s += step;
        }
        let s0 = s0.ok_or_else(|| {
            invalid(format!(
                "branch {bi} does not leave the trunk within 60% of its length"
            ))
        })?;
        let nsb = (((bp.length - s0) / h).round() as usize).max(1) + 1;
        let bpts: Vec<V> = (0..nsb)
            .map(|i| c0 + d * (s0 + (bp.length - s0) * i as f64 / (nsb - 1) as f64))
            .collect();
        let brad: Vec<f64> = (0..nsb)
            .map(|i| rb(s0 + (bp.length - s0) * i as f64 / (nsb - 1) as f64))
            .collect();
        let bst: Vec<Station> = bpts
            .iter()
            .zip(&brad)
            .map(|(&c, &r)| Station {
                c,
                n: bn0,
                b: bb0,
                r,
            })
            .collect();
        let bbase = add_rings(&mut verts, &bst, nt_b);
        tris.extend(tube_triangles(bbase, nsb, nt_b));

        // Hole in the trunk: vertices within 1.3 rb of the branch axis (on the branch side).
        let hole_r = 1.3 * bp.radius_start;
        let mut hole: HashSet<usize> = (trunk_base..trunk_vert_end)
            .filter(|&i| {
                let v = verts[i] - c0;
                let t = v.dot(&d);
                t > 0.0 && (v - d * t).norm() < hole_r
            })
            .collect();
        if hole.is_empty() {
            return Err(invalid(format!("branch {bi} makes no hole in the trunk")));
        }
        // Rim loop; grow the hole over pinch vertices until the rim is one simple loop.
        let trunk_tri_count = 2 * nt_trunk * (ns - 1);
        let mut rim = None;
        for _ in 0..16 {
            match rim_loop(&tris[..trunk_tri_count], &hole) {
                Ok(l) => {
                    rim = Some(l);
                    break;
                }
                Err(bad) => {
                    hole.extend(bad);
                }
            }
        }
        let rim = rim.ok_or_else(|| {
            invalid(format!(
                "branch {bi}: could not cut a simple hole in the trunk"
            ))
        })?;
        for (ti, t) in tris[..trunk_tri_count].iter().enumerate() {
            if t.iter().any(|&v| hole.contains(&(v as usize))) && !removed.insert(ti) {
                return Err(invalid(format!("branch {bi} overlaps another junction")));
            }
        }
        // Zip the rim (kept-side edges u→v, used reversed) to the first branch ring (j→j+1).
        let angle = |v: &V| {
            let w = v - c0;
            w.dot(&bb0).atan2(w.dot(&bn0))
        };
        let ring: Vec<u32> = (0..nt_b).map(|j| (bbase + j) as u32).collect();
        zip_loops(&rim, &ring, &verts, &angle, &mut bands)
            .map_err(|m| invalid(format!("branch {bi}: {m}")))?;

        branch_lines.push(Centreline {
            points: std::iter::once(c0)
                .chain(bpts.iter().copied())
                .map(Into::into)
                .collect(),
            radii: std::iter::once(trunk_r[k])
                .chain(brad.iter().copied())
                .collect(),
        });
    }
    let mut all: Vec<[u32; 3]> = tris
        .iter()
        .enumerate()
        .filter(|(i, _)| !removed.contains(i))
        .map(|(_, t)| *t)
        .collect();
    all.extend(bands);
    // Compact: drop vertices no longer used (the hole interiors).
    let mut remap = vec![u32::MAX; verts.len()];
    let mut out_v: Vec<[f64; 3]> = Vec::with_capacity(verts.len());
    for t in &mut all {
        for v in t.iter_mut() {
            let i = *v as usize;
            if remap[i] == u32::MAX {
                remap[i] = out_v.len() as u32;
                out_v.push(verts[i].into());
            }
            *v = remap[i];
        }
    }
    let (mesh, report) = TriMesh::new(out_v, all, "generated vessel")?;
    Ok(Vessel {
        mesh,
        report,
        trunk: Centreline {
            points: trunk_pts.iter().map(|&v| v.into()).collect(),
            radii: trunk_r,
        },
        branches: branch_lines,
        entry_point: trunk_pts[0].into(),
        entry_direction: t0.into(),
    })
}

/// The rim of the hole made by removing every triangle touching a `hole` vertex: the directed
/// edges `u → v` of kept triangles whose neighbour across the edge is removed, walked as one loop.
/// `Err` lists vertices to add to the hole when the rim is not one simple loop.
fn rim_loop(tris: &[[u32; 3]], hole: &HashSet<usize>) -> Result<Vec<u32>, Vec<usize>> {
    let removed = |t: &[u32; 3]| t.iter().any(|&v| hole.contains(&(v as usize)));
    let mut removed_edges: HashSet<(u32, u32)> = HashSet::new();
    for t in tris.iter().filter(|t| removed(t)) {
        for k in 0..3 {
            removed_edges.insert((t[k], t[(k + 1) % 3]));
        }
    }
    let mut next: HashMap<u32, u32> = HashMap::new();
    let mut pinch = Vec::new();
    for t in tris.iter().filter(|t| !removed(t)) {
        for k in 0..3 {
            let (u, v) = (t[k], t[(k + 1) % 3]);
            if removed_edges.contains(&(v, u)) && next.insert(u, v).is_some() {
                pinch.push(u as usize);
            }
        }
    }
    if !pinch.is_empty() {
        return Err(pinch);
    }
    let Some(&start) = next.keys().min() else {
        return Err(Vec::new());
    };
    let mut rim = vec![start];
    let mut cur = start;
    loop {
        let Some(&n) = next.get(&cur) else {
            return Err(vec![cur as usize]);
        };
        if n == start {
            break;
        }
        rim.push(n);
        cur = n;
        if rim.len() > next.len() {
            return Err(vec![cur as usize]);
        }
    }
    if rim.len() != next.len() {
        // Several loops: grow over the vertices of the loop(s) not containing `start`.
        let on: HashSet<u32> = rim.iter().copied().collect();
        return Err(next
            .keys()
            .filter(|k| !on.contains(k))
            .map(|&k| k as usize)
            .collect());
    }
    Ok(rim)
}

/// Zips two loops going around the branch axis into a band of triangles, merging them in order of
/// angle. `rim` edges are used reversed (they already belong to the trunk), `ring` edges forward.
fn zip_loops(
    rim: &[u32],
    ring: &[u32],
    verts: &[V],
    angle: &dyn Fn(&V) -> f64,
    out: &mut Vec<[u32; 3]>,
) -> Result<(), String> {
    let unwrap = |ids: &[u32], start: usize, ref_angle: f64| -> Vec<f64> {
        let n = ids.len();
        let mut acc = Vec::with_capacity(n + 1);
        let mut prev = angle(&verts[ids[start] as usize]);
        let mut base = prev - ref_angle;
        base = (base + PI).rem_euclid(2.0 * PI) - PI;
        let mut cur = base;
        acc.push(cur);
        for k in 1..=n {
            let a = angle(&verts[ids[(start + k) % n] as usize]);
            let mut da = a - prev;
            da = (da + PI).rem_euclid(2.0 * PI) - PI;
            cur += da;
            acc.push(cur);
            prev = a;
        }
        acc
    };
    let ref_angle = angle(&verts[ring[0] as usize]);
    let ra = unwrap(ring, 0, ref_angle);
    // Rim start: the rim vertex closest in angle to ring[0].
    let mut start = 0;
    let mut best = f64::INFINITY;
    for (i, &v) in rim.iter().enumerate() {
        let da = ((angle(&verts[v as usize]) - ref_angle + PI).rem_euclid(2.0 * PI) - PI).abs();
        if da < best {
            best = da;
            start = i;
        }
    }
    let rb = unwrap(rim, start, ref_angle);
    let (turn_ring, turn_rim) = (ra[ring.len()] - ra[0], rb[rim.len()] - rb[0]);
    if (turn_ring - 2.0 * PI).abs() > 0.5 || (turn_rim - 2.0 * PI).abs() > 0.5 {
        return Err(format!(
            "junction loops do not wind once around the branch in the same sense (ring {turn_ring:.2} rad, rim {turn_rim:.2} rad)"
        ));
    }
    let (na, nb) = (rim.len(), ring.len());
    let a = |i: usize| rim[(start + i) % na];
    let b = |j: usize| ring[j % nb];
    let (mut i, mut j) = (0usize, 0usize);
    while i < na || j < nb {
        let advance_rim = j == nb || (i < na && rb[i + 1] < ra[j + 1]);
        if advance_rim {
            out.push([a(i + 1), a(i), b(j)]);
            i += 1;
        } else {
            out.push([b(j), b(j + 1), a(i)]);
            j += 1;
        }
    }
    Ok(())
}
