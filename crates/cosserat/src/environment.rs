//! What the rods move in: a static triangle mesh (a vessel, an anatomy file, a floor) and the
//! friction between the rods and it.
//!
//! A simulation has at most one environment, shared by all its rods. A scene without one builds
//! no tree and runs no collision code.

use cosserat_backend_cpu::MeshContactSettings;
use cosserat_collide::vessel::Centreline;
use cosserat_collide::{MeshCollider, MeshError, TriMesh, Vessel, VesselParams};
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
}

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
}

impl Environment {
    fn with_mesh(mesh: TriMesh, vessel: Option<VesselGeometry>) -> Self {
        Self {
            collider: Arc::new(MeshCollider::new(mesh)),
            friction: Friction {
                static_coefficient: 0.1,
                kinetic_coefficient: 0.08,
            },
            margin: 1e-4,
            vessel,
        }
    }

    /// The procedural vessel tree of `cosserat_collide::vessel` with about `triangles` triangles (the
    /// default, 26 000, matches the paper's phantom).
    pub fn vessel(triangles: usize) -> Result<Self, MeshError> {
        let v: Vessel = cosserat_collide::vessel::generate(&VesselParams {
            target_triangles: triangles,
            ..VesselParams::default()
        })?;
        let geometry = VesselGeometry {
            entry_point: v.entry_point,
            entry_direction: v.entry_direction,
            trunk: Some(v.trunk.clone()),
        };
        Ok(Self::with_mesh(v.mesh, Some(geometry)))
    }

    /// A mesh file (OBJ or STL) with coordinates multiplied by `scale` (0.001 for millimetres),
    /// oriented so that its normals point into the enclosed lumen.
    ///
    /// `entry`, if given, is where and in which direction a wire enters the lumen (for
    /// insertion scenes).
    pub fn from_file(
        path: &Path,
        scale: f64,
        entry: Option<([f64; 3], [f64; 3])>,
    ) -> Result<Self, MeshError> {
        let (mut mesh, _report) = cosserat_collide::load_mesh(path, scale)?;
        mesh.orient_into_lumen();
        let vessel = entry.map(|(point, dir)| VesselGeometry {
            entry_point: point,
            entry_direction: nalgebra::Vector3::from(dir).normalize().into(),
            trunk: None,
        });
        Ok(Self::with_mesh(mesh, vessel))
    }

    /// A square floor of side `size` through `point`, facing `normal`.
    pub fn plane(point: [f64; 3], normal: [f64; 3], size: f64) -> Result<Self, MeshError> {
        let n = nalgebra::Vector3::from(normal).normalize();
        let helper = if n.x.abs() < 0.9 {
            nalgebra::Vector3::x()
        } else {
            nalgebra::Vector3::y()
        };
        let u = helper.cross(&n).normalize();
        let v = n.cross(&u);
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

    /// Number of triangles.
    pub fn triangles(&self) -> usize {
        self.collider.mesh().triangles().len()
    }

    /// What the CPU backend needs to make a rod collide with this environment.
    pub fn contact_settings(&self) -> MeshContactSettings {
        MeshContactSettings {
            collider: Arc::clone(&self.collider),
            friction: self.friction,
            margin: self.margin,
        }
    }

    /// Points of `points` whose centre lies outside the lumen (behind the nearest wall),
    /// searching up to `reach` metres for the wall. For a generated vessel, the part of a wire
    /// that has not yet passed the entry point is not counted: it has not been inserted. Nor is a
    /// point whose nearest feature is the rim of an open end: it left through the opening.
    pub fn escaped(&self, points: &[[f64; 3]], reach: f64) -> usize {
        let inserted = |p: &[f64; 3]| {
            self.vessel.as_ref().is_none_or(|v| {
                (0..3)
                    .map(|k| (p[k] - v.entry_point[k]) * v.entry_direction[k])
                    .sum::<f64>()
                    > 0.0
            })
        };
        points
            .iter()
            .filter(|p| {
                inserted(p)
                    && self
                        .collider
                        .nearest(p, reach)
                        .is_some_and(|n| n.signed_distance < 0.0 && !n.at_opening)
            })
            .count()
    }
}
