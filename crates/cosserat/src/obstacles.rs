//! Several obstacles in one scene: meshes (files, generated vessels, the built-in solids) and
//! analytic shapes (a half-space, an infinite cylinder), each with its own friction and side,
//! and shapes that move along a keyframed path.
//!
//! Why they are joined before any step: a rod's contact query should cost what one obstacle
//! costs, whatever their number. So every mesh obstacle (and the `[environment]`'s mesh, if
//! any) is joined into **one** triangle mesh with one tree, and each triangle remembers which
//! obstacle it came from (`TriangleFriction`), so a contact takes that obstacle's friction; the
//! clearance, near lists, ridge and swept tests of the mesh contact then serve all of them at
//! once. Each mesh is oriented before it is joined (a lumen's normals inward, a solid's
//! outward), so the joined mesh's normals point everywhere to the side the rods stay on. The
//! analytic shapes are not meshed: each point is tested against each shape's exact distance (a
//! few multiply–adds), and a moving shape is posed once a step from its path. A scene of one
//! mesh and no shapes keeps that mesh's own tree, and a scene without obstacles builds no tree
//! and runs no collision code.
//!
//! The inside test that reports points outside (`Simulation::check_lumen`) runs per obstacle,
//! each on its own mesh or shape: a point counts once when it is outside a lumen or inside a
//! solid (or behind a half-space), at whatever depth the deepest of them says.

use crate::environment::{Environment, Outside};
use cosserat_backend_cpu::{MeshContactSettings, ShapeObstacle, TriangleFriction};
use cosserat_collide::{MeshCollider, TriMesh};
use cosserat_constraints::Friction;
use cosserat_problem::EndPath;
use std::sync::Arc;

pub use cosserat_collide::{Shape, Side};

/// The friction an obstacle gets when none is given (the environment's default).
pub const DEFAULT_FRICTION: Friction<f64> = Friction {
    static_coefficient: 0.1,
    kinetic_coefficient: 0.08,
};

/// What an obstacle is made of.
#[derive(Clone, Debug)]
pub enum Geometry {
    /// A triangle mesh: a lumen or a solid ([`Environment::into_solid`] and the built-in
    /// solids), with its own friction ([`Environment::friction`]).
    Mesh(Box<Environment>),
    /// An analytic shape.
    Shape(Shape),
}

/// One obstacle of a scene ([`crate::SimulationBuilder::obstacle`]).
#[derive(Clone, Debug)]
#[must_use]
pub struct Obstacle {
    geometry: Geometry,
    friction: Friction<f64>,
    path: Option<EndPath>,
}

impl Obstacle {
    /// A mesh obstacle, with the environment's friction.
    pub fn mesh(env: Environment) -> Self {
        let friction = env.friction;
        Self {
            geometry: Geometry::Mesh(Box::new(env)),
            friction,
            path: None,
        }
    }

    /// An analytic obstacle, with [`DEFAULT_FRICTION`].
    pub fn shape(shape: Shape) -> Self {
        Self {
            geometry: Geometry::Shape(shape),
            friction: DEFAULT_FRICTION,
            path: None,
        }
    }

    /// The half-space behind the infinite plane through `point` facing `normal` (the rods stay
    /// on the side it points to). Errors for a zero or non-finite normal.
    pub fn half_space(point: [f64; 3], normal: [f64; 3]) -> Result<Self, String> {
        Ok(Self::shape(Shape::half_space(point, normal)?))
    }

    /// The infinite cylinder of `radius` about the axis through `point` along `axis`: a tube
    /// the rods stay in ([`Side::Lumen`]) or a post they stay out of ([`Side::Solid`]).
    pub fn cylinder(
        point: [f64; 3],
        axis: [f64; 3],
        radius: f64,
        side: Side,
    ) -> Result<Self, String> {
        Ok(Self::shape(Shape::cylinder(point, axis, radius, side)?))
    }

    /// The same obstacle with Coulomb friction `static_coefficient` (sticking) and
    /// `kinetic_coefficient` (sliding, at most the static one).
    pub fn friction(mut self, static_coefficient: f64, kinetic_coefficient: f64) -> Self {
        self.friction = Friction {
            static_coefficient,
            kinetic_coefficient,
        };
        if let Geometry::Mesh(env) = &mut self.geometry {
            env.friction = self.friction;
        }
        self
    }

    /// The same obstacle moving rigidly along `path`: its anchor (the plane's or the axis's
    /// point) displaced and the shape turned about it, as a held rod end follows an
    /// [`EndPath`]. Its contacts' friction acts on the rods' motion relative to its surface.
    /// Errors for a mesh: meshes stay put (their tree is built once).
    pub fn following(mut self, path: EndPath) -> Result<Self, String> {
        if let Geometry::Mesh(_) = self.geometry {
            return Err(
                "a mesh obstacle cannot move: only analytic shapes (half-space, cylinder) follow a path"
                    .into(),
            );
        }
        self.path = Some(path);
        Ok(self)
    }

    /// A shape put where it is at time `now` and set to follow `path` from there (what
    /// `Simulation::set_obstacle_path` does to it); a mesh unchanged.
    pub(crate) fn rebased(mut self, now: f64, path: Option<EndPath>) -> Self {
        if let Some(here) = self.shape_at(now) {
            self.geometry = Geometry::Shape(here);
            self.path = path;
        }
        self
    }

    /// What the obstacle is made of.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// Its friction.
    pub fn friction_coefficients(&self) -> Friction<f64> {
        self.friction
    }

    /// Its path, if it moves.
    pub fn path(&self) -> Option<&EndPath> {
        self.path.as_ref()
    }

    /// The shape where its path has it at time `t` [s] (as built for a static one); `None`
    /// for a mesh.
    pub fn shape_at(&self, t: f64) -> Option<Shape> {
        let Geometry::Shape(shape) = self.geometry else {
            return None;
        };
        Some(match &self.path {
            None => shape,
            Some(path) => {
                let (d, r) = path.pose(t);
                shape.moved(
                    d,
                    &nalgebra::Rotation3::from_scaled_axis(nalgebra::Vector3::from(r)),
                )
            }
        })
    }

    /// The points of `points` (spheres of `radius`) on the wrong side of this obstacle at
    /// time `t` ([`Self::each_outside`]): for a mesh, [`Environment::outside`].
    pub fn each_outside_count(&self, points: &[[f64; 3]], radius: f64, t: f64) -> Outside {
        let mut out = Outside::default();
        self.each_outside(points, radius, t, |i, depth| out.add(i, depth));
        out
    }

    /// Calls `found(i, depth)` for every point `i` of `points` (spheres of `radius`) on the
    /// wrong side of this obstacle at time `t`: outside its lumen, inside its solid, behind its
    /// plane; `depth` is the distance behind the surface plus the radius.
    pub fn each_outside(
        &self,
        points: &[[f64; 3]],
        radius: f64,
        t: f64,
        mut found: impl FnMut(usize, f64),
    ) {
        match &self.geometry {
            Geometry::Mesh(env) => env.each_outside(points, radius, found),
            Geometry::Shape(_) => {
                let Some(shape) = self.shape_at(t) else {
                    return;
                };
                for (i, p) in points.iter().enumerate() {
                    let sd = shape.distance(p).signed_distance;
                    if sd < 0.0 {
                        found(i, radius - sd);
                    }
                }
            }
        }
    }
}

/// Points of `points` on the wrong side of any of `obstacles` at time `t`
/// ([`Obstacle::each_outside`]), each counted once at its greatest depth.
pub fn outside_any(obstacles: &[&Obstacle], points: &[[f64; 3]], radius: f64, t: f64) -> Outside {
    let mut depth = vec![0.0_f64; points.len()];
    for o in obstacles {
        o.each_outside(points, radius, t, |i, d| depth[i] = depth[i].max(d));
    }
    let mut out = Outside::default();
    for (i, &d) in depth.iter().enumerate() {
        if d > 0.0 {
            out.add(i, d);
        }
    }
    out
}

/// What every colliding rod touches: the obstacles' meshes joined into one (see the module
/// docs) and their shapes; `None` without any. `margin` is the speculative contact margin.
pub(crate) fn contact_settings(
    obstacles: &[&Obstacle],
    margin: f64,
) -> Result<Option<MeshContactSettings>, String> {
    let meshes: Vec<(&Environment, Friction<f64>)> = obstacles
        .iter()
        .filter_map(|o| match &o.geometry {
            Geometry::Mesh(env) => Some((env.as_ref(), o.friction)),
            Geometry::Shape(_) => None,
        })
        .collect();
    let shapes: Arc<[ShapeObstacle]> = obstacles
        .iter()
        .filter_map(|o| match o.geometry {
            Geometry::Shape(shape) => Some(ShapeObstacle {
                shape,
                friction: o.friction,
                path: o.path.clone(),
            }),
            Geometry::Mesh(_) => None,
        })
        .collect();
    let friction = meshes
        .first()
        .map(|m| m.1)
        .or_else(|| shapes.first().map(|s| s.friction))
        .unwrap_or(DEFAULT_FRICTION);
    let (collider, triangle_friction) = match meshes.as_slice() {
        [] if shapes.is_empty() => return Ok(None),
        [] => (None, None),
        [(env, _)] => (Some(Arc::clone(&env.collider)), None),
        several => {
            let (collider, of_triangle) = join(several.iter().map(|m| m.0.collider.mesh()))?;
            let frictions: Vec<Friction<f64>> = several.iter().map(|m| m.1).collect();
            let triangle_friction = (frictions.iter().any(|f| *f != frictions[0])).then(|| {
                Arc::new(TriangleFriction {
                    of_triangle,
                    frictions,
                })
            });
            (Some(Arc::new(collider)), triangle_friction)
        }
    };
    Ok(Some(MeshContactSettings {
        collider,
        friction,
        margin,
        triangle_friction,
        shapes,
    }))
}

/// The mesh obstacles of `obstacles` joined into one collider, as the rods see them (see the
/// module docs); for measurements and tools. Errors without any mesh.
pub fn joined_collider(obstacles: &[&Obstacle]) -> Result<MeshCollider, String> {
    let meshes: Vec<&TriMesh> = obstacles
        .iter()
        .filter_map(|o| match &o.geometry {
            Geometry::Mesh(env) => Some(env.collider.mesh()),
            Geometry::Shape(_) => None,
        })
        .collect();
    if meshes.is_empty() {
        return Err("no mesh obstacle".into());
    }
    Ok(join(meshes.into_iter())?.0)
}

/// The meshes as one, with one tree, and for each triangle the index of the mesh it came
/// from. Each keeps its orientation.
fn join<'a>(meshes: impl Iterator<Item = &'a TriMesh>) -> Result<(MeshCollider, Vec<u16>), String> {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut of_triangle = Vec::new();
    for (k, mesh) in meshes.enumerate() {
        let k = u16::try_from(k).map_err(|_| "more than 65 535 mesh obstacles".to_string())?;
        let offset = vertices.len() as u32;
        vertices.extend(mesh.vertices().iter().map(|v| [v.x, v.y, v.z]));
        triangles.extend(
            mesh.triangles()
                .iter()
                .map(|t| t.map(|corner| corner + offset)),
        );
        of_triangle.extend(std::iter::repeat_n(k, mesh.triangles().len()));
    }
    let expected = triangles.len();
    let (mesh, _) = TriMesh::new(vertices, triangles, "obstacles").map_err(|e| e.to_string())?;
    if mesh.triangles().len() != expected {
        return Err(format!(
            "the mesh obstacles share {} triangles (two obstacles in the same place): each must have its own surface",
            expected - mesh.triangles().len()
        ));
    }
    Ok((MeshCollider::new(mesh), of_triangle))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joined_meshes_keep_their_triangles_in_order_and_their_orientation() {
        let a = Environment::cuboid([0.0; 3], [1.0; 3], [0.0; 3]).unwrap();
        let b = Environment::cuboid([3.0, 0.0, 0.0], [1.0; 3], [0.0; 3]).unwrap();
        let (joined, of) = join([a.collider.mesh(), b.collider.mesh()].into_iter()).unwrap();
        assert_eq!(joined.mesh().triangles().len(), 24);
        assert_eq!(of[..12], [0; 12]);
        assert_eq!(of[12..], [1; 12]);
        for t in 0..12 {
            let na = a.collider.mesh().face_normal(t);
            assert!((joined.mesh().face_normal(t) - na).norm() < 1e-12);
            let nb = b.collider.mesh().face_normal(t);
            assert!((joined.mesh().face_normal(12 + t) - nb).norm() < 1e-12);
        }
        // Two solids: outside both the free side, inside either the wrong one.
        let obstacles = [Obstacle::mesh(a), Obstacle::mesh(b)];
        let refs: Vec<&Obstacle> = obstacles.iter().collect();
        let out = outside_any(
            &refs,
            &[[0.0; 3], [1.5, 0.0, 0.0], [3.2, 0.0, 0.0], [0.0, 0.0, 0.7]],
            0.01,
            0.0,
        );
        assert_eq!(out.count, 2);
        assert_eq!(out.deepest_point, Some(0));
        assert!((out.deepest - 0.51).abs() < 1e-9);
    }

    #[test]
    fn one_mesh_keeps_its_own_tree_and_none_builds_nothing() {
        let env = Environment::sphere([0.0; 3], 0.1, 16).unwrap();
        let collider = Arc::clone(&env.collider);
        let one = [Obstacle::mesh(env)];
        let s = contact_settings(&one.iter().collect::<Vec<_>>(), 1e-4)
            .unwrap()
            .unwrap();
        assert!(Arc::ptr_eq(s.collider.as_ref().unwrap(), &collider));
        assert!(s.triangle_friction.is_none() && s.shapes.is_empty());
        assert!(contact_settings(&[], 1e-4).unwrap().is_none());
    }

    #[test]
    fn a_mesh_cannot_follow_a_path_and_a_moving_shape_is_posed_by_it() {
        let path = EndPath::new(
            0.0,
            vec![0.0, 1.0],
            vec![[0.0; 3], [0.0, 0.0, 0.5]],
            vec![[0.0; 3]; 2],
        )
        .unwrap();
        let env = Environment::sphere([0.0; 3], 0.1, 16).unwrap();
        let e = Obstacle::mesh(env).following(path.clone()).unwrap_err();
        assert!(e.contains("cannot move"), "{e}");
        let floor = Obstacle::half_space([0.0; 3], [0.0, 0.0, 1.0])
            .unwrap()
            .following(path)
            .unwrap();
        let out = outside_any(&[&floor], &[[0.0, 0.0, 0.3]], 0.01, 0.5);
        assert_eq!(out.count, 0);
        let out = outside_any(&[&floor], &[[0.0, 0.0, 0.3]], 0.01, 1.0);
        assert_eq!(out.count, 1);
        assert!((out.deepest - 0.21).abs() < 1e-12);
    }
}
