//! Contact of a rod with a static triangle mesh (a vessel wall, a floor).
//!
//! Once per step the rod's points are tested against the mesh as spheres of the rod's radius
//! plus a small speculative margin ([`collide::MeshCollider::detect`]); each point in contact
//! becomes one [`PointContact`] whose direction is the paper's penetration-weighted mean of the
//! touched triangles' normals. The contacts are then solved inside the constraint iterations
//! together with the distance constraints. A rod without a mesh carries `None` here and runs
//! none of this code.

use collide::{ContactBuffer, MeshCollider};
use constraints::{ContactSet, Friction, PointContact};
use cosserat_model::{Real, Vec3};
use std::sync::Arc;

/// What a rod touches and how.
#[derive(Clone, Debug)]
pub struct MeshContactSettings {
    /// The mesh, shared between rods.
    pub collider: Arc<MeshCollider>,
    /// Coulomb friction with the mesh.
    pub friction: Friction<f64>,
    /// Speculative margin [m]: points this close to the surface get a contact that stops them
    /// reaching it within the step.
    pub margin: f64,
}

/// Measurements of a rod's contact with the mesh since the last reset.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CollisionStats {
    /// Largest penetration of a point's sphere into the surface at the start of any step [m].
    pub max_penetration: f64,
    /// Largest number of points whose centre was behind the wall at the start of a step.
    pub escaped_points: usize,
    /// Points in contact at the last step.
    pub contacts: usize,
    /// Most points in contact at any step.
    pub max_contacts: usize,
    /// Wall time spent in collision detection [s].
    pub detection_seconds: f64,
    /// Steps with collision detection.
    pub steps: u64,
}

/// Per-rod collision state: settings, scratch and statistics.
#[derive(Clone, Debug)]
pub(crate) struct RodMeshContact<T: Real> {
    pub(crate) settings: MeshContactSettings,
    pub(crate) friction: Friction<T>,
    points: Vec<[f64; 3]>,
    buffer: ContactBuffer,
    pub(crate) contacts: ContactSet<T>,
    pub(crate) stats: CollisionStats,
}

impl<T: Real> RodMeshContact<T> {
    pub(crate) fn new(settings: MeshContactSettings) -> Self {
        let friction = Friction {
            static_coefficient: T::lit(settings.friction.static_coefficient),
            kinetic_coefficient: T::lit(settings.friction.kinetic_coefficient),
        };
        Self {
            settings,
            friction,
            points: Vec::new(),
            buffer: ContactBuffer::new(),
            contacts: ContactSet::new(),
            stats: CollisionStats::default(),
        }
    }

    /// Detects contacts of the points `(x, y, z)` as spheres of `radius`.
    pub(crate) fn detect(&mut self, x: &[T], y: &[T], z: &[T], radius: f64) {
        let t0 = std::time::Instant::now();
        self.points.clear();
        self.points.extend(
            x.iter()
                .zip(y)
                .zip(z)
                .map(|((a, b), c)| [a.to_f64(), b.to_f64(), c.to_f64()]),
        );
        let margin = self.settings.margin;
        self.settings
            .collider
            .detect(&self.points, radius + margin, &mut self.buffer);
        self.contacts.clear();
        let mut escaped = 0;
        for (i, r) in self.buffer.responses().iter().enumerate() {
            if r.count == 0 {
                continue;
            }
            escaped += usize::from(r.escaped);
            let n = Vec3::from(r.direction);
            let len = n.norm();
            if !(len > 0.0) {
                continue;
            }
            // Depths are measured against the inflated sphere; remove the margin again.
            let penetration = r.max_depth - margin;
            self.stats.max_penetration = self.stats.max_penetration.max(penetration);
            let n = n / len;
            self.contacts.push(PointContact {
                point: i as u32,
                normal: Vec3::new(T::lit(n.x), T::lit(n.y), T::lit(n.z)),
                gap: T::lit(-penetration),
            });
        }
        self.stats.escaped_points = self.stats.escaped_points.max(escaped);
        self.stats.contacts = self.contacts.len();
        self.stats.max_contacts = self.stats.max_contacts.max(self.contacts.len());
        self.stats.steps += 1;
        self.stats.detection_seconds += t0.elapsed().as_secs_f64();
    }
}
