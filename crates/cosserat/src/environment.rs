//! What the rods move in: a static triangle mesh (a vessel, an anatomy file, a floor) and the
//! friction between the rods and it.
//!
//! A simulation has at most one environment, shared by all its rods. A scene without one builds
//! no tree and runs no collision code.

use cosserat_backend_cpu::MeshContactSettings;
use cosserat_collide::vessel::Centreline;
use cosserat_collide::{
    MeshCollider, MeshError, MeshReport, OrientationRepair, Port, PortError, TriMesh, Vessel,
    VesselParams, open_port,
};
use cosserat_constraints::Friction;
use std::path::Path;
use std::sync::Arc;

/// The geometry of a generated vessel that scenes can place rods along.
#[derive(Clone, Debug)]
pub struct VesselGeometry {
    /// Where a wire enters the vessel [m].
    pub entry_point: [f64; 3],
    /// Unit direction into the vessel at the entry.
    pub entry_direction: [f64; 3],
    /// The trunk's centreline (known for generated vessels only).
    pub trunk: Option<Centreline>,
    /// The branches' centrelines, each from the trunk's axis outward (generated vessels only).
    pub branches: Vec<Centreline>,
    /// Where along the entry's axis the wire reaches the lumen, and the hole opened for it in a
    /// closed wall (`cosserat_collide::port`); `None` when the axis never reaches the lumen
    /// ([`Environment::entry_problem`] says so).
    pub port: Option<Port>,
}

/// Where a wire enters a mesh file's lumen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    /// The entry point [m].
    pub point: [f64; 3],
    /// The direction into the lumen (any length).
    pub direction: [f64; 3],
    /// The port's radius [m]; `None` takes the opening's radius where the axis enters through
    /// an open end, half the lumen's where it must pass a wall.
    pub radius: Option<f64>,
}

/// An entry whose axis reaches the lumen farther than this from the entry point gets a warning
/// [m]: the wire travels that far outside any wall.
const FAR_ENTRY: f64 = 0.02;

/// A static mesh with friction.
#[derive(Clone, Debug)]
pub struct Environment {
    /// The mesh and its tree.
    pub collider: Arc<MeshCollider>,
    /// Friction between rods and the mesh.
    pub friction: Friction<f64>,
    /// Speculative contact margin [m].
    pub margin: f64,
    /// Present when the mesh is a generated vessel.
    pub vessel: Option<VesselGeometry>,
    /// What loading and repairing the mesh found that a user should know (dropped or welded
    /// triangles, flipped patches, loose fragments); the simulation reports them as warnings.
    pub intake: Vec<String>,
    /// A warning about the entry, if any ([`Self::entry_problem`]).
    entry_note: Option<String>,
    /// Whether a run stops as diverged when a rod's point is found outside the lumen
    /// ([`Environment::outside`]); checked after every call to `Simulation::run`.
    pub stop_outside: bool,
    /// The mesh is a solid the rods stay outside of (a post, a capstan, a bone), its normals
    /// pointing out of it, instead of a lumen they stay inside ([`Environment::into_solid`]).
    pub solid: bool,
}

impl Environment {
    fn with_mesh(mesh: TriMesh, vessel: Option<VesselGeometry>) -> Self {
        Self::with_collider(MeshCollider::new(mesh), vessel)
    }

    fn with_collider(collider: MeshCollider, vessel: Option<VesselGeometry>) -> Self {
        Self {
            collider: Arc::new(collider),
            friction: Friction {
                static_coefficient: 0.1,
                kinetic_coefficient: 0.08,
            },
            margin: 1e-4,
            vessel,
            intake: Vec::new(),
            entry_note: None,
            stop_outside: true,
            solid: false,
        }
    }

    /// `mesh` entered at `entry` through a port (`cosserat_collide::port`): the wall is opened
    /// where the entry's axis must pass it. An axis that never reaches the lumen keeps the mesh
    /// whole and leaves a warning ([`Self::entry_problem`]).
    fn with_entry(
        mesh: TriMesh,
        entry: Entry,
        trunk: Option<Centreline>,
        branches: Vec<Centreline>,
    ) -> Result<Self, MeshError> {
        let name = mesh.name().to_string();
        let direction: [f64; 3] = nalgebra::Vector3::from(entry.direction).normalize().into();
        let geometry = |port| VesselGeometry {
            entry_point: entry.point,
            entry_direction: direction,
            trunk: trunk.clone(),
            branches: branches.clone(),
            port,
        };
        match open_port(mesh.clone(), entry.point, direction, entry.radius) {
            Ok((collider, port)) => {
                let mut env = Self::with_collider(collider, Some(geometry(Some(port))));
                if port.opened > 0 {
                    env.intake.push(format!(
                        "{name}: the entry port opened {} triangles of the wall within {:.3e} m of the entry's axis, {:.3e} m past the entry point, for the wire to pass",
                        port.opened, port.radius, port.crossing
                    ));
                }
                if port.crossing > FAR_ENTRY {
                    env.entry_note = Some(format!(
                        "the entry point {:?} is {:.3e} m from where its axis reaches the lumen: the wire travels that far along the direction {:?} outside any wall before it enters (check the entry's point and the mesh's scale)",
                        entry.point, port.crossing, direction
                    ));
                }
                Ok(env)
            }
            Err(PortError::NoLumen {
                reach,
                nearest_wall,
            }) => {
                let mut env = Self::with_mesh(mesh, Some(geometry(None)));
                env.entry_note = Some(format!(
                    "the entry point {:?} does not lead into the lumen: its axis along {:?} reaches no lumen within {reach:.3e} m, and the nearest wall is {nearest_wall:.3e} m from it; a wire pushed in there stays outside (check the entry's point, direction and the mesh's scale)",
                    entry.point, direction
                ));
                Ok(env)
            }
            Err(PortError::Mesh(e)) => Err(e),
            Err(e @ PortError::BadRadius(_)) => Err(MeshError::Port {
                path: name,
                message: e.to_string(),
            }),
        }
    }

    /// The procedural vessel tree of `cosserat_collide::vessel` with about `triangles` triangles (the
    /// default, 26 000, matches the paper's phantom).
    pub fn vessel(triangles: usize) -> Result<Self, MeshError> {
        Self::vessel_with(&VesselParams {
            target_triangles: triangles,
            ..VesselParams::default()
        })
    }

    /// A procedural vessel tree of any shape (`cosserat_collide::vessel::VesselParams`: trunk
    /// length, radii, bow, branches), entered at its inlet through a port of the inlet's radius.
    pub fn vessel_with(params: &VesselParams) -> Result<Self, MeshError> {
        Self::of_vessel(cosserat_collide::vessel::generate(params)?)
    }

    /// A random vessel tree (`cosserat_collide::vessel::VesselParams::random`): the same `seed`
    /// gives the same anatomy, with about `triangles` triangles.
    pub fn random_vessel(seed: u64, triangles: usize) -> Result<Self, MeshError> {
        Self::of_vessel(cosserat_collide::vessel::generate_random(seed, triangles)?.0)
    }

    fn of_vessel(v: Vessel) -> Result<Self, MeshError> {
        let entry = Entry {
            point: v.entry_point,
            direction: v.entry_direction,
            radius: Some(v.trunk.sample(0.0).1),
        };
        Self::with_entry(v.mesh, entry, Some(v.trunk.clone()), v.branches.clone())
    }

    /// A mesh file (OBJ or STL) with coordinates multiplied by `scale` (0.001 for millimetres),
    /// oriented so that its normals point into the enclosed lumen.
    ///
    /// `entry`, if given, is where and in which direction a wire enters the lumen (for
    /// insertion scenes), in metres; a closed mesh is opened there (see [`Entry`]).
    pub fn from_file(path: &Path, scale: f64, entry: Option<Entry>) -> Result<Self, MeshError> {
        let (mut mesh, report) = cosserat_collide::load_mesh(path, scale)?;
        let repair = mesh.repair_orientation();
        let notes = intake_notes(&path.display().to_string(), &report, &repair);
        let mut env = match entry {
            Some(entry) => Self::with_entry(mesh, entry, None, Vec::new())?,
            None => Self::with_mesh(mesh, None),
        };
        env.intake.splice(0..0, notes);
        Ok(env)
    }

    /// A square floor of side `size` through `point`, facing `normal`.
    pub fn plane(point: [f64; 3], normal: [f64; 3], size: f64) -> Result<Self, MeshError> {
        let (_, u, v) = across(normal);
        let c = nalgebra::Vector3::from(point);
        let h = size / 2.0;
        let corners = [
            c - u * h - v * h,
            c + u * h - v * h,
            c + u * h + v * h,
            c - u * h + v * h,
        ];
        let (mesh, _) = TriMesh::new(
            corners.iter().map(|p| [p.x, p.y, p.z]).collect(),
            vec![[0, 1, 2], [0, 2, 3]],
            "plane",
        )?;
        Ok(Self::with_mesh(mesh, None))
    }

    /// A closed cylinder (a post, a capstan drum) of `radius` and `length` [m] centred on
    /// `center` along `axis`, as a solid the rods stay outside of: `segments` flat faces around
    /// (the faces' sagitta, `radius (1 − cos(π/segments))`, is how far the mesh lies inside the
    /// round surface), closed by flat ends.
    pub fn cylinder(
        center: [f64; 3],
        axis: [f64; 3],
        radius: f64,
        length: f64,
        segments: usize,
    ) -> Result<Self, MeshError> {
        let (a, u, v) = across(axis);
        let c = nalgebra::Vector3::from(center);
        let k = segments as u32;
        let mut vertices = Vec::with_capacity(2 * segments + 2);
        for end in [-0.5, 0.5] {
            for s in 0..segments {
                let phi = 2.0 * std::f64::consts::PI * s as f64 / segments as f64;
                let p = c + a * (end * length) + (u * phi.cos() + v * phi.sin()) * radius;
                vertices.push([p.x, p.y, p.z]);
            }
        }
        for end in [-0.5, 0.5] {
            let p = c + a * (end * length);
            vertices.push([p.x, p.y, p.z]);
        }
        let (bottom, top) = (2 * k, 2 * k + 1);
        let mut triangles = Vec::with_capacity(4 * segments);
        for s in 0..k {
            let t = (s + 1) % k;
            // Around: normals out of the axis.
            triangles.push([s, t, k + t]);
            triangles.push([s, k + t, k + s]);
            // The ends: normals along −axis and +axis.
            triangles.push([bottom, t, s]);
            triangles.push([top, k + s, k + t]);
        }
        Self::solid_of(vertices, triangles, "cylinder")
    }

    /// A sphere of `radius` [m] about `center` as a solid the rods stay outside of: a UV sphere
    /// of `segments` faces around and `segments / 2` rings (its flat faces lie within
    /// `radius (1 − cos(π/segments))` of the round surface).
    pub fn sphere(center: [f64; 3], radius: f64, segments: usize) -> Result<Self, MeshError> {
        let (k, rings) = (segments as u32, (segments / 2).max(2) as u32);
        let c = nalgebra::Vector3::from(center);
        let mut vertices = vec![[c.x, c.y, c.z - radius], [c.x, c.y, c.z + radius]];
        for ring in 1..rings {
            let theta = std::f64::consts::PI * ring as f64 / rings as f64;
            for s in 0..k {
                let phi = 2.0 * std::f64::consts::PI * s as f64 / k as f64;
                let p = c + nalgebra::Vector3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    -theta.cos(),
                ) * radius;
                vertices.push([p.x, p.y, p.z]);
            }
        }
        let at = |ring: u32, s: u32| 2 + (ring - 1) * k + s % k;
        let mut triangles = Vec::new();
        for s in 0..k {
            triangles.push([0, at(1, s + 1), at(1, s)]);
            triangles.push([1, at(rings - 1, s), at(rings - 1, s + 1)]);
            for ring in 1..rings - 1 {
                triangles.push([at(ring, s), at(ring, s + 1), at(ring + 1, s + 1)]);
                triangles.push([at(ring, s), at(ring + 1, s + 1), at(ring + 1, s)]);
            }
        }
        Self::solid_of(vertices, triangles, "sphere")
    }

    /// A capsule, a cylinder of `radius` and `length` [m] between the centres of its two
    /// hemispherical ends, centred on `center` along `axis`, as a solid the rods stay outside
    /// of: `segments` faces around, `segments / 4` rings on each end.
    pub fn capsule(
        center: [f64; 3],
        axis: [f64; 3],
        radius: f64,
        length: f64,
        segments: usize,
    ) -> Result<Self, MeshError> {
        let (a, u, v) = across(axis);
        let c = nalgebra::Vector3::from(center);
        let (k, cap) = (segments as u32, (segments / 4).max(2) as u32);
        // Rings from the −axis pole to the +axis pole: `cap` on the lower end (its equator
        // last), `cap` on the upper end (its equator first).
        let mut vertices = vec![];
        let pole = |s: f64| c + a * (s * (0.5 * length + radius));
        let lower = pole(-1.0);
        vertices.push([lower.x, lower.y, lower.z]);
        let mut rings = 0u32;
        for (end, from, to) in [(-1.0, 1, cap + 1), (1.0, 0, cap)] {
            for ring in from..to {
                // Polar angle from the end's pole (−1) or from its equator (+1).
                let theta = std::f64::consts::FRAC_PI_2 * ring as f64 / cap as f64;
                let (along, out) = if end < 0.0 {
                    (-theta.cos(), theta.sin())
                } else {
                    (theta.sin(), theta.cos())
                };
                let base = c + a * (end * 0.5 * length + along * radius);
                for s in 0..k {
                    let phi = 2.0 * std::f64::consts::PI * s as f64 / k as f64;
                    let p = base + (u * phi.cos() + v * phi.sin()) * (out * radius);
                    vertices.push([p.x, p.y, p.z]);
                }
                rings += 1;
            }
        }
        let upper = pole(1.0);
        vertices.push([upper.x, upper.y, upper.z]);
        let top = 1 + rings * k;
        let at = |ring: u32, s: u32| 1 + ring * k + s % k;
        let mut triangles = Vec::new();
        for s in 0..k {
            triangles.push([0, at(0, s + 1), at(0, s)]);
            triangles.push([top, at(rings - 1, s), at(rings - 1, s + 1)]);
            for ring in 0..rings - 1 {
                triangles.push([at(ring, s), at(ring, s + 1), at(ring + 1, s + 1)]);
                triangles.push([at(ring, s), at(ring + 1, s + 1), at(ring + 1, s)]);
            }
        }
        Self::solid_of(vertices, triangles, "capsule")
    }

    /// A box of `size` [m] (full edge lengths along its own axes) about `center`, turned by the
    /// rotation vector `rotation` [rad], as a solid the rods stay outside of.
    pub fn cuboid(center: [f64; 3], size: [f64; 3], rotation: [f64; 3]) -> Result<Self, MeshError> {
        let r = nalgebra::Rotation3::from_scaled_axis(nalgebra::Vector3::from(rotation));
        let c = nalgebra::Vector3::from(center);
        let vertices = (0..8)
            .map(|i| {
                let corner = nalgebra::Vector3::new(
                    if i & 1 == 0 { -0.5 } else { 0.5 } * size[0],
                    if i & 2 == 0 { -0.5 } else { 0.5 } * size[1],
                    if i & 4 == 0 { -0.5 } else { 0.5 } * size[2],
                );
                let p = c + r * corner;
                [p.x, p.y, p.z]
            })
            .collect();
        // Two triangles per face, corners numbered by their (x, y, z) bits.
        let quads = [
            [0, 2, 6, 4],
            [1, 5, 7, 3],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 1, 3, 2],
            [4, 6, 7, 5],
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Self::solid_of(vertices, triangles, "box")
    }

    /// A closed mesh of `vertices` and `triangles` as a solid: its normals turned out.
    fn solid_of(
        vertices: Vec<[f64; 3]>,
        triangles: Vec<[u32; 3]>,
        name: &str,
    ) -> Result<Self, MeshError> {
        let (mut mesh, _) = TriMesh::new(vertices, triangles, name)?;
        mesh.repair_orientation();
        if mesh.signed_volume() < 0.0 {
            mesh.flip_winding();
        }
        let mut env = Self::with_mesh(mesh, None);
        env.solid = true;
        Ok(env)
    }

    /// This environment's closed mesh as a solid the rods stay outside of: its normals turned
    /// to point out of the volume it encloses, and [`Self::outside`] counting the points inside
    /// it. Errors for a mesh that encloses no volume (a sheet has no inside to stay out of) and
    /// for a generated vessel.
    pub fn into_solid(mut self) -> Result<Self, String> {
        if self.solid {
            return Ok(self);
        }
        if self.vessel.is_some() {
            return Err("a generated vessel is a lumen, not a solid".into());
        }
        if !self.collider.encloses_volume() {
            return Err(format!(
                "mesh `{}` encloses no volume: a solid must be a closed surface",
                self.collider.mesh().name()
            ));
        }
        let mut mesh = self.collider.mesh().clone();
        mesh.flip_winding();
        self.collider = Arc::new(MeshCollider::new(mesh));
        self.solid = true;
        Ok(self)
    }

    /// Number of triangles.
    pub fn triangles(&self) -> usize {
        self.collider.mesh().triangles().len()
    }

    /// What the CPU backend needs to make a rod collide with this environment.
    pub fn contact_settings(&self) -> MeshContactSettings {
        MeshContactSettings::mesh(Arc::clone(&self.collider), self.friction, self.margin)
    }

    /// Points of `points` whose centre lies outside the lumen (inside a solid), and how deep the
    /// deepest is.
    ///
    /// Outside is decided by the lumen's winding number (`MeshCollider::lumen_winding`), which
    /// does not depend on how far the wall is or on which side of it the nearest feature says
    /// the point is, so a point far behind a wall, past a seam or through a flipped patch is
    /// counted. For a generated vessel, the part of a wire that has not yet passed the entry
    /// point is not counted: it has not been inserted. Nor is a point whose nearest feature is
    /// the rim of an open end: it left through the opening. `radius` is the rod's: a point's
    /// depth is its distance behind the wall plus its radius (the penetration of its sphere).
    pub fn outside(&self, points: &[[f64; 3]], radius: f64) -> Outside {
        let mut out = Outside::default();
        self.each_outside(points, radius, |i, depth| out.add(i, depth));
        out
    }

    /// Calls `found(i, depth)` for every point `i` of `points` outside the lumen (inside a
    /// solid), with its depth, as [`Self::outside`] counts them.
    pub fn each_outside(
        &self,
        points: &[[f64; 3]],
        radius: f64,
        mut found: impl FnMut(usize, f64),
    ) {
        // A point not yet past the entry, or in the port's channel before the lumen, is on its
        // way in.
        let inserted = |p: &[f64; 3]| {
            self.vessel.as_ref().is_none_or(|v| match &v.port {
                Some(port) => !port.holds(p),
                None => {
                    (0..3)
                        .map(|k| (p[k] - v.entry_point[k]) * v.entry_direction[k])
                        .sum::<f64>()
                        > 0.0
                }
            })
        };
        let (lo, hi) = self.collider.mesh().bounds();
        // Far enough to reach the wall from anywhere near the mesh.
        let reach = 2.0 * (hi - lo).norm() + 1.0;
        // A sheet (a floor, a wall) encloses nothing: the side of its nearest feature decides.
        let lumen = self.collider.encloses_volume();
        for (i, p) in points.iter().enumerate() {
            if !inserted(p) {
                continue;
            }
            // The winding number of the side the normals point to: 1 in a lumen, 0 outside it;
            // around a solid (normals out), 0 outside it and −1 inside.
            if self.solid {
                if self.collider.lumen_winding(p) > -0.5 {
                    continue;
                }
            } else if lumen && self.collider.lumen_winding(p) >= 0.5 {
                continue;
            }
            let Some(nearest) = self.collider.nearest(p, reach) else {
                continue;
            };
            if nearest.at_opening || (!lumen && nearest.signed_distance >= 0.0) {
                continue;
            }
            found(i, nearest.distance + radius);
        }
    }

    /// A warning about the entry (where a wire is pushed in), if it deserves one: its axis
    /// never reaches the lumen, or reaches it far ([`FAR_ENTRY`]) from the entry point. `None`
    /// for a good entry, and when there is no entry or no lumen to enter (a sheet).
    pub fn entry_problem(&self) -> Option<String> {
        if self.solid || !self.collider.encloses_volume() {
            return None;
        }
        self.entry_note.clone()
    }
}

/// `direction` normalised, and two unit vectors across it that make a right-handed frame with
/// it (`u × v` along `direction`).
fn across(
    direction: [f64; 3],
) -> (
    nalgebra::Vector3<f64>,
    nalgebra::Vector3<f64>,
    nalgebra::Vector3<f64>,
) {
    let n = nalgebra::Vector3::from(direction).normalize();
    let helper = if n.x.abs() < 0.9 {
        nalgebra::Vector3::x()
    } else {
        nalgebra::Vector3::y()
    };
    let u = helper.cross(&n).normalize();
    (n, u, n.cross(&u))
}

/// Points of a rod outside the lumen ([`Environment::outside`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Outside {
    /// How many.
    pub count: usize,
    /// The depth of the deepest: distance behind the wall plus the rod's radius [m] (0 when
    /// none is outside).
    pub deepest: f64,
    /// Index of the deepest point.
    pub deepest_point: Option<usize>,
}

impl Outside {
    /// Counts point `i`, outside by `depth`.
    pub(crate) fn add(&mut self, i: usize, depth: f64) {
        self.count += 1;
        if depth > self.deepest {
            self.deepest = depth;
            self.deepest_point = Some(i);
        }
    }
}

/// What loading (`report`) and repairing (`repair`) the mesh `name` changed or found, as
/// sentences for warnings; empty for a clean mesh.
pub fn intake_notes(name: &str, report: &MeshReport, repair: &OrientationRepair) -> Vec<String> {
    let mut notes = Vec::new();
    if report.short_faces_dropped > 0 {
        notes.push(format!(
            "{name}: dropped {} faces of fewer than three vertices",
            report.short_faces_dropped
        ));
    }
    if report.degenerate_dropped > 0 || report.duplicates_dropped > 0 {
        notes.push(format!(
            "{name}: dropped {} zero-area and {} duplicate triangles of {}",
            report.degenerate_dropped, report.duplicates_dropped, report.input_triangles
        ));
    }
    if repair.flipped > 0 && repair.misoriented_before > 0 {
        notes.push(format!(
            "{name}: {} edges joined triangles wound against each other; {} triangles were turned so that the wall is wound one way and faces the lumen",
            repair.misoriented_before, repair.flipped
        ));
    }
    if repair.misoriented_after > 0 {
        notes.push(format!(
            "{name}: {} edges still join triangles wound against each other (a piece that cannot be oriented): contacts there may push the wrong way",
            repair.misoriented_after
        ));
    }
    if repair.fragments() > 0 {
        notes.push(format!(
            "{name}: {} loose pieces besides the main one ({} triangles in all)",
            repair.fragments(),
            repair.pieces[1..].iter().sum::<usize>()
        ));
    }
    if repair.non_manifold_edges > 0 {
        notes.push(format!(
            "{name}: {} edges are shared by more than two triangles (seams or overlapping pieces)",
            repair.non_manifold_edges
        ));
    }
    notes
}
