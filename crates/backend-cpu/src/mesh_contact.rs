//! Contact of a rod with a static triangle mesh (a vessel wall, a floor).
//!
//! Once per step the rod's points are tested against the mesh as spheres of the rod's radius
//! plus a small speculative margin ([`cosserat_collide::MeshCollider::detect`]); each point in contact
//! becomes one [`PointContact`] whose direction is the paper's penetration-weighted mean of the
//! touched triangles' normals. The contacts are then solved inside the constraint iterations
//! together with the distance constraints. A rod without a mesh carries `None` here and runs
//! none of this code.
//!
//! **Clearance.** Most points of a wire inside a vessel are millimetres from any wall, and a
//! tree walk per point per step finds nothing for them. After a query that finds no contact, a
//! point gets a clearance: its distance to the nearest triangle (searched up to
//! [`CLEARANCE_LOOKAHEAD`]) minus the query radius. While the point stays closer than that to
//! where it was measured it cannot touch the mesh, so it is not queried; the contacts found are
//! exactly those of a full query every step. A point outside the mesh's bounding box takes its
//! distance to the box as clearance, so a rod far from the mesh costs one squared distance per
//! point and step (a loop the compiler vectorises).
//!
//! **Ridges between points.** A wall that bulges into the lumen between two points (the ridge
//! of a bifurcation, a fold) can reach into the element joining them while both spheres are
//! clear of it. Every element near the mesh (its points' clearances adding up to less than its
//! length) is tested as a segment against the ridge triangles near it (where the lumen is not
//! convex, the only place this can happen: `cosserat_collide::segment`), kept in a near list
//! as the points' are ([`MeshCollider::segment_near_slots`]); where it is nearer a
//! wall than both its points, its two points get a contact on the plane through the wall's
//! nearest point, across the direction from the wall to the element, at the element's gap: the
//! element is kept off the ridge as if the ridge were that plane, in both schemes, with the
//! point contacts they already solve.
//!
//! **Near lists.** A point close to a wall (most of a wire pressed along a vessel) is queried
//! every step, and a tree walk from the root visits every leaf box near it. Instead, such a point
//! keeps the list of triangles within `reach + skin` of where the list was made
//! ([`MeshCollider::near_slots`]); while it stays within `skin` of that place, every triangle it
//! can touch is in the list, which is tested in leaf order, so the contacts and the response are
//! exactly those of the tree query. The skin is half the query radius: a wire sliding at
//! 0.2 m/s with steps of a few microseconds remakes its lists every few hundred steps.
//!
//! At a haptic step of 1 ms the same wire moves 0.2 mm a step, more than that skin (0.14 mm for
//! the `nitinol` preset), and nearly every element near a wall remade its list every step, a
//! tree walk each. An element's list is therefore remade from a second, wider list of its own
//! instead of the tree: the same list, in the same order, without the walk. A wire slides along
//! itself, so the wider list is that of the element lengthened by [`OUTER_ALONG`] of its length
//! at both ends, with [`OUTER_SKIN`] query radii more; it is remade by the tree when an end
//! has left that much of the lengthened element (every point of the element is then as near to
//! it, the distance to a segment being convex). A larger skin for the near lists themselves
//! would do the same walks less often, but every query would then test the longer lists.

use cosserat_collide::sweep::AMONG_SLACK;
use cosserat_collide::{Contact, Crossing, MeshCollider, Shape};
use cosserat_constraints::{ContactSet, Friction, PointContact};
use cosserat_model::{Real, Vec3};
use cosserat_problem::EndPath;
use std::sync::Arc;

pub(crate) use cosserat_problem::CollisionStats;

/// What a rod touches and how: a mesh (one or several obstacles joined in one tree), analytic
/// shapes, or both.
#[derive(Clone, Debug)]
pub struct MeshContactSettings {
    /// The mesh, shared between rods; `None` when the rod touches analytic shapes only.
    pub collider: Option<Arc<MeshCollider>>,
    /// Coulomb friction with the mesh (with every triangle, unless `triangle_friction` says
    /// otherwise).
    pub friction: Friction<f64>,
    /// Speculative margin [m]: points this close to the surface get a contact that stops them
    /// reaching it within the step.
    pub margin: f64,
    /// The friction of each triangle, when the mesh joins obstacles of different friction.
    pub triangle_friction: Option<Arc<TriangleFriction>>,
    /// Analytic obstacles (see [`ShapeObstacle`]).
    pub shapes: Arc<[ShapeObstacle]>,
}

impl MeshContactSettings {
    /// Contact with one mesh of one friction.
    pub fn mesh(collider: Arc<MeshCollider>, friction: Friction<f64>, margin: f64) -> Self {
        Self {
            collider: Some(collider),
            friction,
            margin,
            triangle_friction: None,
            shapes: Arc::new([]),
        }
    }

    /// Whether any obstacle moves.
    pub fn moves(&self) -> bool {
        self.shapes.iter().any(|s| s.path.is_some())
    }
}

/// The friction of each triangle of a mesh that joins several obstacles: triangle `t` (in the
/// mesh's order) has `frictions[of_triangle[t]]`.
#[derive(Clone, Debug)]
pub struct TriangleFriction {
    /// Per triangle, its obstacle's entry in `frictions`.
    pub of_triangle: Vec<u16>,
    /// The obstacles' frictions.
    pub frictions: Vec<Friction<f64>>,
}

/// An analytic obstacle ([`Shape`]): a half-space or an infinite cylinder, static or moving
/// rigidly along a keyframed path (displacement of its anchor and rotation about it,
/// [`EndPath`]). Its contacts take its own friction, relative to its surface's velocity.
#[derive(Clone, Debug)]
pub struct ShapeObstacle {
    /// The shape where its path starts.
    pub shape: Shape,
    /// Coulomb friction with it.
    pub friction: Friction<f64>,
    /// The path it follows; `None`: it stays put.
    pub path: Option<EndPath>,
}

/// A shape where it is at the time of a detection, and how its surface moves over the step.
#[derive(Clone, Copy, Debug)]
struct Posed {
    shape: Shape,
    /// Velocity of its anchor [m/s] and its angular velocity [rad/s] over the step.
    velocity: Vec3<f64>,
    omega: Vec3<f64>,
    anchor: Vec3<f64>,
}

impl Posed {
    fn at_rest(shape: Shape) -> Self {
        Self {
            shape,
            velocity: Vec3::zeros(),
            omega: Vec3::zeros(),
            anchor: Vec3::from(shape.anchor()),
        }
    }

    /// The velocity of the shape's surface (moved with it rigidly) at `p` [m/s].
    fn surface_velocity(&self, p: &Vec3<f64>) -> Vec3<f64> {
        self.velocity + self.omega.cross(&(p - self.anchor))
    }
}

/// An element nearest a wall between its points (see the module docs).
#[derive(Clone, Copy, Debug)]
struct Ridge {
    element: u32,
    /// The direction from the wall to the element.
    normal: Vec3<f64>,
    /// The wall's nearest point.
    on_wall: Vec3<f64>,
    /// The element's gap.
    gap: f64,
    /// The wall's source (see `RodMeshContact::surfaces`).
    source: u32,
}

/// A contact found before the contacts of one point are merged (see
/// [`RodMeshContact::merge_candidates`]).
#[derive(Clone, Copy, Debug)]
struct Candidate {
    point: u32,
    normal: Vec3<f64>,
    gap: f64,
    /// Where its friction and velocity come from (see `RodMeshContact::surfaces`).
    source: u32,
}

/// How far beyond the query radius the nearest wall is searched for a point's clearance [m].
pub const CLEARANCE_LOOKAHEAD: f64 = 2e-3;

/// The skin of a point's near list as a fraction of the query radius (see the module docs).
const NEAR_SKIN: f64 = 0.5;

/// How far an element's wider list reaches beyond its ends, along it, as a fraction of its
/// length (see the module docs): a wire sliding along itself keeps such a list while it slides
/// that far.
const OUTER_ALONG: f64 = 1.0;

/// How far an element's ends may leave the line of its wider list before the list is remade,
/// as a multiple of the query radius.
const OUTER_SKIN: f64 = 1.0;

/// The wider lists are made this much (relatively) wider still, so that rounding in the
/// distances never leaves out a triangle the near list must hold.
const OUTER_ROUNDING: f64 = 1e-9;

/// A point is swept (tested for walls crossed over the step) when it moves more than this
/// fraction of its query radius: one that moves less ends within reach of any wall it could
/// have crossed, which its sphere query then sees.
const SWEEP_FRACTION: f64 = 0.5;

/// An element's nearest point to the wall is a ridge between its points only this far (as a
/// fraction of the element) from both: nearer an end, that end's sphere query has the wall.
const SEGMENT_END: f64 = 1e-6;

/// An element's gap must be smaller than both its points' own by this fraction of the radius
/// to give them its contact: along a flat or concave wall the element is never nearer the wall
/// than its points, and rounding must not make it so.
const SEGMENT_TOLERANCE: f64 = 0.02;

/// How the points move over the step, for the swept test (see the module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Motion<'a, T> {
    /// The points are queried where they end the step; they started it at these positions
    /// (coordinate by coordinate), in the lumen.
    From([&'a [T]; 3]),
    /// The points are queried where they start the step; they will move with these velocities
    /// for this step [s].
    Velocity([&'a [T]; 3], f64),
}

/// Per-rod collision state: settings, scratch and statistics.
#[derive(Clone, Debug)]
pub(crate) struct RodMeshContact<T: Real> {
    pub(crate) settings: MeshContactSettings,
    pub(crate) friction: Friction<T>,
    /// Per point, where its clearance was measured (coordinate by coordinate) and the squared
    /// clearance; a point closer than that to where it was measured cannot touch the mesh (see
    /// the module docs). Negative: query the point at the next step.
    clear_at: [Vec<f64>; 3],
    clear2: Vec<f64>,
    /// Scratch: the points queried this step.
    due: Vec<u32>,
    /// Per point, the leaf-order slots of the triangles within `reach + skin` of `anchor`, and
    /// whether that list exists.
    near: Vec<Vec<u32>>,
    anchor: Vec<[f64; 3]>,
    has_near: Vec<bool>,
    found: Vec<Contact>,
    /// Scratch: the points whose motion crossed into the wall, and where.
    swept: Vec<(u32, Crossing)>,
    /// Scratch: elements nearest a wall between their points.
    ridge: Vec<Ridge>,
    /// Per element, the leaf-order slots of the triangles within `reach + skin` of it as it was
    /// at `seg_anchor` (its two ends), and whether that list exists: the elements' near lists,
    /// as the points' (see the module docs).
    seg_near: Vec<Vec<u32>>,
    seg_anchor: Vec<[[f64; 3]; 2]>,
    seg_has_near: Vec<bool>,
    /// Per element, the wider list its near list is remade from (the triangles within
    /// `reach + skin + OUTER_SKIN · reach` of the segment `seg_outer_anchor`, the element
    /// lengthened by [`OUTER_ALONG`] at both ends where the list was made), and whether it
    /// exists.
    seg_outer: Vec<Vec<u32>>,
    seg_outer_anchor: Vec<[[f64; 3]; 2]>,
    seg_has_outer: Vec<bool>,
    /// Scratch: each point's gap from its own contact (the margin without one), and its
    /// clearance beyond the reach (0 when unknown).
    own_gap: Vec<f64>,
    clearance: Vec<f64>,
    pub(crate) contacts: ContactSet<T>,
    pub(crate) stats: CollisionStats,
    /// The frictions of the contacts' sources: 0 the settings' own, then those of
    /// `triangle_friction`, then one per shape (from `first_shape`).
    surfaces: Vec<Friction<f64>>,
    first_shape: u32,
    /// Whether contacts carry sources of their own (several frictions, or shapes): they are
    /// then gathered as candidates and merged, one contact per point.
    varied: bool,
    /// The shapes where they are at the detection (see [`Self::pose_shapes`]).
    posed: Vec<Posed>,
    /// Per point, the source of its contact at its last query.
    source: Vec<u32>,
    candidates: Vec<Candidate>,
}

impl<T: Real> RodMeshContact<T> {
    pub(crate) fn new(settings: MeshContactSettings) -> Self {
        let friction = cast_friction(&settings.friction);
        let mut surfaces = vec![settings.friction];
        if let Some(tf) = &settings.triangle_friction {
            surfaces.extend(&tf.frictions);
        }
        let first_shape = surfaces.len() as u32;
        surfaces.extend(settings.shapes.iter().map(|s| s.friction));
        let varied = surfaces.len() > 1;
        let posed = settings
            .shapes
            .iter()
            .map(|s| Posed::at_rest(s.shape))
            .collect();
        Self {
            surfaces,
            first_shape,
            varied,
            posed,
            source: Vec::new(),
            candidates: Vec::new(),
            settings,
            friction,
            clear_at: [Vec::new(), Vec::new(), Vec::new()],
            clear2: Vec::new(),
            due: Vec::new(),
            near: Vec::new(),
            anchor: Vec::new(),
            has_near: Vec::new(),
            found: Vec::new(),
            swept: Vec::new(),
            ridge: Vec::new(),
            seg_near: Vec::new(),
            seg_anchor: Vec::new(),
            seg_has_near: Vec::new(),
            seg_outer: Vec::new(),
            seg_outer_anchor: Vec::new(),
            seg_has_outer: Vec::new(),
            own_gap: Vec::new(),
            clearance: Vec::new(),
            contacts: ContactSet::new(),
            stats: CollisionStats::default(),
        }
    }

    /// Detects contacts of the points `(x, y, z)` as spheres of `radius`.
    /// With a `motion`, points that moved far over the step are also swept (see the module
    /// docs).
    pub(crate) fn detect(&mut self, x: &[T], y: &[T], z: &[T], radius: f64, motion: Motion<T>) {
        self.detect_except(x, y, z, radius, &[], motion);
        self.segment_contacts(x, y, z, radius);
    }

    /// [`detect`](Self::detect) without the elements' contacts ([`Self::segment_contacts`],
    /// which the caller adds once the points' contacts are complete), leaving out the points
    /// `i` with `skip[i]` (those past the end of `skip` are detected): they are not queried and
    /// get no contact.
    pub(crate) fn detect_except(
        &mut self,
        x: &[T],
        y: &[T],
        z: &[T],
        radius: f64,
        skip: &[bool],
        motion: Motion<T>,
    ) {
        let t0 = std::time::Instant::now();
        let n = x.len().min(y.len()).min(z.len());
        if self.clear2.len() != n {
            self.clear2 = vec![-1.0; n];
            self.clear_at = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
            self.near = vec![Vec::new(); n];
            self.anchor = vec![[0.0; 3]; n];
            self.has_near = vec![false; n];
            self.source = vec![0; n];
        }
        self.found.clear();
        self.contacts.clear();
        self.candidates.clear();
        let mut escaped = 0;
        if let Some(collider) = self.settings.collider.clone() {
            escaped += self.mesh_points(&collider, x, y, z, radius, skip, motion);
        }
        if !self.posed.is_empty() {
            escaped += self.shape_points(x, y, z, radius, skip, motion);
        }
        if self.varied {
            self.merge_candidates(x, y, z);
        }
        self.stats.escaped_points = self.stats.escaped_points.max(escaped);
        self.stats.contacts = self.contacts.len();
        self.stats.max_contacts = self.stats.max_contacts.max(self.contacts.len());
        self.stats.steps += 1;
        self.stats.detection_seconds += t0.elapsed().as_secs_f64();
    }

    /// A contact of point `i` from `source`: pushed as is when all contacts share one surface,
    /// else kept as a candidate for [`Self::merge_candidates`].
    fn emit(&mut self, i: u32, normal: Vec3<f64>, gap: f64, source: u32) {
        if self.varied {
            self.candidates.push(Candidate {
                point: i,
                normal,
                gap,
                source,
            });
        } else {
            self.contacts.push(PointContact {
                point: i,
                normal: Vec3::new(T::lit(normal.x), T::lit(normal.y), T::lit(normal.z)),
                gap: T::lit(gap),
            });
        }
    }

    /// The source (see `surfaces`) of mesh triangle `t`.
    fn triangle_source(&self, t: u32) -> u32 {
        self.settings
            .triangle_friction
            .as_ref()
            .and_then(|tf| tf.of_triangle.get(t as usize))
            .map_or(0, |&o| 1 + u32::from(o))
    }

    /// The mesh's contacts of the points not skipped (the clearance, near lists and swept test
    /// of the module docs). Returns how many points it found behind the wall.
    #[allow(clippy::too_many_arguments)]
    fn mesh_points(
        &mut self,
        collider: &MeshCollider,
        x: &[T],
        y: &[T],
        z: &[T],
        radius: f64,
        skip: &[bool],
        motion: Motion<T>,
    ) -> usize {
        let margin = self.settings.margin;
        let reach = radius + margin;
        let skin = NEAR_SKIN * reach;
        let n = x.len().min(y.len()).min(z.len());
        // Which points may touch the mesh: one squared distance each.
        self.due.clear();
        let [cx, cy, cz] = &self.clear_at;
        let (cx, cy, cz, c2) = (&cx[..n], &cy[..n], &cz[..n], &self.clear2[..n]);
        for i in 0..n {
            let d2 = (x[i].to_f64() - cx[i]).powi(2)
                + (y[i].to_f64() - cy[i]).powi(2)
                + (z[i].to_f64() - cz[i]).powi(2);
            if !(d2 < c2[i]) && !skip.get(i).is_some_and(|&s| s) {
                self.due.push(i as u32);
            }
        }
        self.sweep(collider, x, y, z, reach, skip, motion);
        let root = &collider.bvh().nodes()[0];
        let mut escaped = 0;
        let distance = |a: &[f64; 3], b: &[f64; 3]| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        for k in 0..self.due.len() {
            let i = self.due[k] as usize;
            if self.swept.iter().any(|&(j, _)| j as usize == i) {
                continue;
            }
            let p = [x[i].to_f64(), y[i].to_f64(), z[i].to_f64()];
            let mut from_anchor = distance(&p, &self.anchor[i]);
            if !self.has_near[i] || from_anchor > skin {
                collider.near_slots(&p, reach + skin, &mut self.near[i]);
                self.anchor[i] = p;
                self.has_near[i] = true;
                from_anchor = 0.0;
            }
            self.stats.queries += 1;
            let first = self.found.len();
            let (r, nearest) =
                collider.query_sphere_among(&p, reach, i as u32, &self.near[i], &mut self.found);
            if r.count == 0 {
                // The list holds every triangle closer than `horizon`; beyond it, the mesh's
                // bounding box bounds the distance from below, and else the tree is asked.
                let horizon = reach + skin - from_anchor;
                let lookahead = reach + CLEARANCE_LOOKAHEAD;
                let outside = root.distance_squared(&p).sqrt();
                let d = if nearest < horizon {
                    nearest
                } else if outside >= lookahead {
                    outside
                } else {
                    collider
                        .nearest(&p, lookahead)
                        .map_or(lookahead, |n| n.distance)
                };
                // Rounding of the distances above must not open a gap.
                let clearance = d - reach - 1e-9;
                self.clear2[i] = if clearance > 0.0 {
                    clearance * clearance
                } else {
                    -1.0
                };
                for c in 0..3 {
                    self.clear_at[c][i] = p[c];
                }
                continue;
            }
            self.clear2[i] = -1.0;
            escaped += usize::from(r.escaped);
            let dir = Vec3::from(r.direction);
            let len = dir.norm();
            if !(len > 0.0) {
                continue;
            }
            // Depths are measured against the inflated sphere; remove the margin again.
            let penetration = r.max_depth - margin;
            self.stats.max_penetration = self.stats.max_penetration.max(penetration);
            // The friction of the triangle it is deepest in.
            let source = if self.varied {
                let deepest = self.found[first..]
                    .iter()
                    .max_by(|a, b| a.depth.total_cmp(&b.depth))
                    .map_or(0, |c| c.triangle);
                self.triangle_source(deepest)
            } else {
                0
            };
            self.emit(i as u32, dir / len, -penetration, source);
        }
        // A point whose motion crossed into the wall is put back on the wall it crossed: its
        // gap is its distance in front of that triangle's plane less the radius, negative
        // when it ended behind it.
        for k in 0..self.swept.len() {
            let (i, c) = self.swept[k];
            let i = i as usize;
            let p = [x[i].to_f64(), y[i].to_f64(), z[i].to_f64()];
            let ahead: f64 = (0..3).map(|k| (p[k] - c.point[k]) * c.normal[k]).sum();
            let gap = ahead - radius;
            escaped += usize::from(ahead < 0.0);
            self.clear2[i] = -1.0;
            self.stats.max_penetration = self.stats.max_penetration.max(-gap);
            self.stats.swept_catches += 1;
            let source = self.triangle_source(c.triangle);
            self.emit(i as u32, Vec3::from(c.normal), gap, source);
        }
        escaped
    }

    /// The shapes' contacts of the points not skipped: every point against every shape, an
    /// exact distance each (a few multiply–adds). A point within reach of a shape's surface,
    /// or (with a predicted motion) one that would cross it within the step, gets a contact
    /// on it; a shape's distance is exact at any depth, so a point behind its surface is
    /// found however far it went. Returns how many points are behind a surface.
    fn shape_points(
        &mut self,
        x: &[T],
        y: &[T],
        z: &[T],
        radius: f64,
        skip: &[bool],
        motion: Motion<T>,
    ) -> usize {
        let margin = self.settings.margin;
        let reach = radius + margin;
        let n = x.len().min(y.len()).min(z.len());
        let mut escaped = 0;
        for i in 0..n {
            if skip.get(i).is_some_and(|&s| s) {
                continue;
            }
            let p = Vec3::new(x[i].to_f64(), y[i].to_f64(), z[i].to_f64());
            let mut behind = false;
            for k in 0..self.posed.len() {
                let posed = self.posed[k];
                let d = posed.shape.distance(&p.into());
                let sd = d.signed_distance;
                let mut within = sd < reach;
                if let (false, Motion::Velocity([vx, vy, vz], h)) = (within, motion) {
                    // Where the point would be, relative to the surface, at the step's end.
                    let v = Vec3::new(vx[i].to_f64(), vy[i].to_f64(), vz[i].to_f64());
                    let q = p + (v - posed.surface_velocity(&p)) * h;
                    within = posed.shape.distance(&q.into()).signed_distance < reach;
                }
                if !within {
                    continue;
                }
                let normal = Vec3::from(d.normal);
                behind |= sd < 0.0;
                self.stats.max_penetration = self.stats.max_penetration.max(radius - sd);
                if sd < reach {
                    // For the stiff scheme's walls (`Self::walls_of`).
                    let closest = p - normal * sd;
                    self.found.push(Contact {
                        point: i as u32,
                        triangle: u32::MAX,
                        closest: closest.into(),
                        distance: sd.abs(),
                        signed_distance: sd,
                        depth: reach - sd,
                        normal: d.normal,
                    });
                }
                self.emit(i as u32, normal, sd - radius, self.first_shape + k as u32);
            }
            escaped += usize::from(behind);
        }
        escaped
    }

    /// Makes one contact per point of the candidates (several when a point touches more than
    /// one obstacle): the normal is the mean of theirs weighted by how far each reaches into
    /// the point's inflated sphere (the paper's rule for the triangles a point touches), the
    /// gap the least of theirs, and the friction and surface velocity those of the nearest.
    fn merge_candidates(&mut self, x: &[T], y: &[T], z: &[T]) {
        let margin = self.settings.margin;
        self.candidates.sort_by_key(|c| c.point);
        let mut k = 0;
        while k < self.candidates.len() {
            let first = self.candidates[k];
            let mut end = k + 1;
            let mut sum = first.normal * (margin - first.gap).max(0.0);
            let mut nearest = first;
            while end < self.candidates.len() && self.candidates[end].point == first.point {
                let c = self.candidates[end];
                sum += c.normal * (margin - c.gap).max(0.0);
                if c.gap < nearest.gap {
                    nearest = c;
                }
                end += 1;
            }
            let normal = if end - k > 1 {
                sum.try_normalize(0.0).unwrap_or(nearest.normal)
            } else {
                first.normal
            };
            let i = first.point as usize;
            self.source[i] = nearest.source;
            let p = Vec3::new(x[i].to_f64(), y[i].to_f64(), z[i].to_f64());
            let wall = self.wall_velocity(nearest.source, &p);
            self.contacts.push_on(
                PointContact {
                    point: first.point,
                    normal: Vec3::new(T::lit(normal.x), T::lit(normal.y), T::lit(normal.z)),
                    gap: T::lit(nearest.gap),
                },
                cast_friction(&self.surfaces[nearest.source as usize]),
                Vec3::new(T::lit(wall.x), T::lit(wall.y), T::lit(wall.z)),
            );
            k = end;
        }
    }

    /// The velocity of the surface of `source` at `p`: zero but on a moving shape.
    fn wall_velocity(&self, source: u32, p: &Vec3<f64>) -> Vec3<f64> {
        source
            .checked_sub(self.first_shape)
            .and_then(|k| self.posed.get(k as usize))
            .map_or_else(Vec3::zeros, |s| s.surface_velocity(p))
    }

    /// Puts the moving shapes where their paths have them at time `at` [s], with the surface
    /// velocities that carry them from `t` to `t + h`. Static shapes stay as built.
    pub(crate) fn pose_shapes(&mut self, at: f64, t: f64, h: f64) {
        for (posed, s) in self.posed.iter_mut().zip(self.settings.shapes.iter()) {
            let Some(path) = &s.path else { continue };
            let (d, r) = path.pose(at);
            let rot = nalgebra::Rotation3::from_scaled_axis(Vec3::from(r));
            let (v, w) = path.velocities_over(t, h);
            posed.shape = s.shape.moved(d, &rot);
            posed.velocity = Vec3::from(v);
            posed.omega = Vec3::from(w);
            posed.anchor = Vec3::from(posed.shape.anchor());
        }
    }

    /// Makes shape `k` follow `path` from where it is at time `now` [s] (see
    /// `Stepper::set_obstacle_path`). Returns false when there is no shape `k`.
    pub(crate) fn set_shape_path(&mut self, k: usize, path: Option<EndPath>, now: f64) -> bool {
        let Some(old) = self.settings.shapes.get(k) else {
            return false;
        };
        let here = match &old.path {
            None => old.shape,
            Some(p) => {
                let (d, r) = p.pose(now);
                old.shape
                    .moved(d, &nalgebra::Rotation3::from_scaled_axis(Vec3::from(r)))
            }
        };
        let mut shapes = self.settings.shapes.to_vec();
        shapes[k] = ShapeObstacle {
            shape: here,
            friction: old.friction,
            path,
        };
        self.settings.shapes = shapes.into();
        self.posed[k] = Posed::at_rest(here);
        true
    }

    /// The shapes as the rod's settings have them now (a stiff scheme's copy of the settings
    /// follows them with [`Self::follow_shapes`]).
    pub(crate) fn shapes(&self) -> &Arc<[ShapeObstacle]> {
        &self.settings.shapes
    }

    /// Takes `shapes` (the rod's, which a control call may have changed) as this copy's.
    pub(crate) fn follow_shapes(&mut self, shapes: &Arc<[ShapeObstacle]>) {
        if !Arc::ptr_eq(&self.settings.shapes, shapes) {
            self.settings.shapes = Arc::clone(shapes);
            self.posed = shapes.iter().map(|s| Posed::at_rest(s.shape)).collect();
        }
    }

    /// The friction of the surface point `i` touched at its last query (the mesh's own for a
    /// point that touched nothing).
    pub(crate) fn friction_at(&self, i: usize) -> Friction<f64> {
        let s = self.source.get(i).copied().unwrap_or(0) as usize;
        self.surfaces[s]
    }

    /// How far the surface point `i` touched at its last query moves over a step of `h` at
    /// `p`: zero but on a moving shape.
    pub(crate) fn wall_shift(&self, i: usize, p: &Vec3<f64>, h: f64) -> Vec3<f64> {
        self.wall_velocity(self.source.get(i).copied().unwrap_or(0), p) * h
    }

    /// The shapes' deepest reach into a sphere of `radius` at `p` (its radius less its
    /// distance from the surface, plus the distance behind it), and whether `p` is behind any
    /// shape's surface; `None` without shapes or when no shape reaches the sphere.
    pub(crate) fn shape_depth(&self, p: &Vec3<f64>, radius: f64) -> Option<(f64, bool)> {
        self.posed
            .iter()
            .map(|s| s.shape.distance(&(*p).into()).signed_distance)
            .filter(|&sd| sd < radius)
            .map(|sd| (radius - sd, sd < 0.0))
            .reduce(|a, b| (a.0.max(b.0), a.1 || b.1))
    }
}

/// The distance from `p` to the segment `a → b`.
fn off_segment(p: &Vec3<f64>, a: &Vec3<f64>, b: &Vec3<f64>) -> f64 {
    let d = b - a;
    let len2 = d.norm_squared();
    let s = if len2 > 0.0 {
        ((p - a).dot(&d) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + d * s)).norm()
}

/// `f` in the precision `T`.
fn cast_friction<T: Real>(f: &Friction<f64>) -> Friction<T> {
    Friction {
        static_coefficient: T::lit(f.static_coefficient),
        kinetic_coefficient: T::lit(f.kinetic_coefficient),
    }
}

impl<T: Real> RodMeshContact<T> {
    /// The walls the sphere of point `i` touched at the last detection (its contacts on the
    /// lumen side, one per triangle): unit normal of the closest feature (into the lumen) and
    /// gap (distance less `radius`). Empty for a point that was not queried.
    pub(crate) fn walls_of(
        &self,
        i: usize,
        radius: f64,
    ) -> impl Iterator<Item = (Vec3<f64>, f64)> + '_ {
        self.found
            .iter()
            .filter(move |c| c.point as usize == i && c.signed_distance >= 0.0)
            .map(move |c| (Vec3::from(c.normal), c.signed_distance - radius))
    }

    /// Whether element `j`, from `a` to `b`, certainly gets no element contact from
    /// [`Self::segment_contacts`] whatever its points' gaps: its near list of ridge triangles
    /// exists, is still valid where the element is, and is empty. A caller that reuses a point's
    /// last contact instead of querying it (`crate::stiff`) may do so only next to such elements,
    /// since an element's contact depends on its points' exact gaps.
    pub(crate) fn no_ridge_near(&self, j: usize, a: Vec3<f64>, b: Vec3<f64>, radius: f64) -> bool {
        let skin = NEAR_SKIN * (radius + self.settings.margin);
        let (Some(&has), Some(near), Some([from, to])) = (
            self.seg_has_near.get(j),
            self.seg_near.get(j),
            self.seg_anchor.get(j),
        ) else {
            return false;
        };
        has && near.is_empty()
            && (a - Vec3::from(*from)).norm() <= skin
            && (b - Vec3::from(*to)).norm() <= skin
    }

    /// Adds the contacts of elements that come nearer a wall between their points than at
    /// them (see the module docs): each such element's two points get a contact on the plane
    /// through the wall's nearest point across the direction from it to the element, at the
    /// distance the element has from it, unless their own contact is nearer. Elements whose
    /// points' clearances add up to the element's length or more cannot reach the mesh and
    /// are not queried.
    pub(crate) fn segment_contacts(&mut self, x: &[T], y: &[T], z: &[T], radius: f64) {
        let t0 = std::time::Instant::now();
        self.segment_queries(x, y, z, radius);
        self.stats.detection_seconds += t0.elapsed().as_secs_f64();
    }

    /// [`Self::segment_contacts`] less its timing.
    fn segment_queries(&mut self, x: &[T], y: &[T], z: &[T], radius: f64) {
        let n = x.len().min(y.len()).min(z.len()).min(self.clear2.len());
        let Some(collider) = self.settings.collider.clone() else {
            return;
        };
        if n < 2 {
            return;
        }
        let margin = self.settings.margin;
        let reach = radius + margin;
        let skin = NEAR_SKIN * reach;
        let at = |i: usize| Vec3::new(x[i].to_f64(), y[i].to_f64(), z[i].to_f64());
        // The least distance beyond `reach` of each point from the mesh (0 when unknown), in
        // one pass.
        self.clearance.clear();
        let [cx, cy, cz] = &self.clear_at;
        self.clearance.extend((0..n).map(|i| {
            let c2 = self.clear2[i];
            if c2 > 0.0 {
                let moved2 = (x[i].to_f64() - cx[i]).powi(2)
                    + (y[i].to_f64() - cy[i]).powi(2)
                    + (z[i].to_f64() - cz[i]).powi(2);
                (c2.sqrt() - moved2.sqrt()).max(0.0)
            } else {
                0.0
            }
        }));
        // Each point's own gap: its contact's, or at least the margin.
        self.own_gap.clear();
        self.own_gap.resize(n, margin);
        for c in self.contacts.contacts() {
            if let Some(g) = self.own_gap.get_mut(c.point as usize) {
                *g = c.gap.to_f64();
            }
        }
        self.ridge.clear();
        if self.seg_near.len() != n - 1 {
            self.seg_near = vec![Vec::new(); n - 1];
            self.seg_anchor = vec![[[0.0; 3]; 2]; n - 1];
            self.seg_has_near = vec![false; n - 1];
            self.seg_outer = vec![Vec::new(); n - 1];
            self.seg_outer_anchor = vec![[[0.0; 3]; 2]; n - 1];
            self.seg_has_outer = vec![false; n - 1];
        }
        let outer = OUTER_SKIN * reach;
        for j in 0..n - 1 {
            let (a, b) = (at(j), at(j + 1));
            let clear = self.clearance[j] + self.clearance[j + 1];
            if clear * clear >= (b - a).norm_squared() {
                continue;
            }
            // Only a wall nearer than both points' own, by the tolerance, makes a ridge
            // contact: the distance it must come within. A wall the element runs along at
            // its points' distance is beyond it, and its plane rules it out cheaply.
            let limit =
                self.own_gap[j].min(self.own_gap[j + 1]) + radius - SEGMENT_TOLERANCE * radius;
            if !(limit > 0.0) {
                continue;
            }
            // The element's near list, remade when an end has moved more than the skin.
            let [from, to] = self.seg_anchor[j];
            if !self.seg_has_near[j]
                || (a - Vec3::from(from)).norm() > skin
                || (b - Vec3::from(to)).norm() > skin
            {
                // From the wider list, itself remade when an end has moved more than its
                // skin: the same list as the tree's, without its walk.
                let [from, to] = self.seg_outer_anchor[j].map(Vec3::from);
                if !self.seg_has_outer[j]
                    || off_segment(&a, &from, &to) > outer
                    || off_segment(&b, &from, &to) > outer
                {
                    let (from, to) = (a - (b - a) * OUTER_ALONG, b + (b - a) * OUTER_ALONG);
                    collider.segment_near_slots(
                        &from.into(),
                        &to.into(),
                        (reach + skin + outer) * (1.0 + OUTER_ROUNDING),
                        true,
                        &mut self.seg_outer[j],
                    );
                    self.seg_outer_anchor[j] = [from.into(), to.into()];
                    self.seg_has_outer[j] = true;
                }
                collider.segment_near_slots_among(
                    &a.into(),
                    &b.into(),
                    reach + skin,
                    true,
                    &self.seg_outer[j],
                    &mut self.seg_near[j],
                );
                self.seg_anchor[j] = [a.into(), b.into()];
                self.seg_has_near[j] = true;
            }
            if self.seg_near[j].is_empty() {
                continue;
            }
            let Some(near) =
                collider.segment_nearest_among(&a.into(), &b.into(), limit, &self.seg_near[j])
            else {
                continue;
            };
            if !(SEGMENT_END..=1.0 - SEGMENT_END).contains(&near.fraction) {
                continue;
            }
            let normal = Vec3::from(near.normal);
            let on_wall = Vec3::from(near.closest);
            let source = self.triangle_source(near.triangle);
            self.ridge.push(Ridge {
                element: j as u32,
                normal,
                on_wall,
                gap: near.signed_distance - radius,
                source,
            });
        }
        if self.ridge.is_empty() {
            return;
        }
        // A point between two ridge elements takes both planes' contacts as one: the mean of
        // their normals and the lesser gap. Taking either (the later element's, say) would tilt
        // every such point's normal the same way along the rod, half an element's turn: a push
        // along the wall that, over a convex solid (where every element is a ridge), lowers the
        // friction a wrapped rope can hold (a rope over a cylinder at 0.1 rad per element slid
        // from 0.87 of the capstan ratio instead of 1).
        let mut pending: Option<(u32, Vec3<f64>, f64, u32)> = None;
        let (varied, surfaces) = (self.varied, &self.surfaces);
        let flush = |p: Option<(u32, Vec3<f64>, f64, u32)>,
                     contacts: &mut ContactSet<T>,
                     sources: &mut [u32]| {
            if let Some((i, n, gap, source)) = p {
                let n = n.normalize();
                let c = PointContact {
                    point: i,
                    normal: Vec3::new(T::lit(n.x), T::lit(n.y), T::lit(n.z)),
                    gap: T::lit(gap),
                };
                if varied {
                    // The mesh is static: its surface does not move.
                    contacts.set_on(c, cast_friction(&surfaces[source as usize]), Vec3::zeros());
                    sources[i as usize] = source;
                } else {
                    contacts.set(c);
                }
            }
        };
        for &Ridge {
            element: j,
            normal,
            on_wall,
            gap,
            source,
        } in &self.ridge
        {
            self.stats.max_penetration = self.stats.max_penetration.max(-gap);
            for i in [j, j + 1] {
                let end_gap = normal.dot(&(at(i as usize) - on_wall)) - radius;
                if end_gap >= self.own_gap[i as usize] {
                    continue;
                }
                match &mut pending {
                    Some((p, n, g, _)) if *p == i => {
                        *n += normal;
                        *g = g.min(end_gap);
                    }
                    _ => {
                        flush(pending.take(), &mut self.contacts, &mut self.source);
                        pending = Some((i, normal, end_gap, source));
                    }
                }
            }
        }
        flush(pending, &mut self.contacts, &mut self.source);
        self.stats.segment_contacts += self.ridge.len() as u64;
        self.stats.contacts = self.contacts.len();
        self.stats.max_contacts = self.stats.max_contacts.max(self.contacts.len());
    }

    /// Fills `swept` with the points (not skipped) whose motion over the step crosses into the
    /// wall: those that move more than [`SWEEP_FRACTION`] of `reach`, segment by segment
    /// against the tree ([`MeshCollider::first_crossing`]). A point that moves less costs one
    /// squared distance, and so does one whose motion stays within the mesh-free ball of its
    /// last clearance (the ball of radius clearance plus `reach` around where it was measured:
    /// a segment whose two ends are in that ball lies in it): in the stiff scheme every
    /// detection of a step sweeps from the step's start, and a wire pushed at 0.2 m/s moves
    /// about its radius per millisecond, so every point of it was cast through the tree after
    /// every iteration. A motion that stays within the radius of the point's near list is cast
    /// through that list instead of the tree (at a 1 ms step most of them: the wire moves 0.2
    /// mm a step, the lists reach 0.42 mm for the `nitinol` preset).
    #[allow(clippy::too_many_arguments)]
    fn sweep(
        &mut self,
        collider: &MeshCollider,
        x: &[T],
        y: &[T],
        z: &[T],
        reach: f64,
        skip: &[bool],
        motion: Motion<T>,
    ) {
        self.swept.clear();
        let far2 = (SWEEP_FRACTION * reach).powi(2);
        let listed2 = ((reach + NEAR_SKIN * reach) * (1.0 - AMONG_SLACK)).powi(2);
        let n = x.len().min(y.len()).min(z.len());
        let at = |i: usize| [x[i].to_f64(), y[i].to_f64(), z[i].to_f64()];
        for i in 0..n {
            let (a, b) = match motion {
                Motion::From([sx, sy, sz]) => {
                    ([sx[i].to_f64(), sy[i].to_f64(), sz[i].to_f64()], at(i))
                }
                Motion::Velocity([vx, vy, vz], h) => {
                    let p = at(i);
                    (
                        p,
                        [
                            p[0] + h * vx[i].to_f64(),
                            p[1] + h * vy[i].to_f64(),
                            p[2] + h * vz[i].to_f64(),
                        ],
                    )
                }
            };
            let d2 = (0..3).map(|k| (b[k] - a[k]).powi(2)).sum::<f64>();
            if d2 <= far2 || skip.get(i).is_some_and(|&s| s) {
                continue;
            }
            if self.clear2[i] > 0.0 {
                let free = (self.clear2[i].sqrt() + reach).powi(2);
                let centre = [
                    self.clear_at[0][i],
                    self.clear_at[1][i],
                    self.clear_at[2][i],
                ];
                let inside =
                    |p: &[f64; 3]| (0..3).map(|k| (p[k] - centre[k]).powi(2)).sum::<f64>() < free;
                if inside(&a) && inside(&b) {
                    continue;
                }
            }
            // Every triangle the motion crosses is in the point's near list when both its ends
            // are within the list's radius of where the list was made.
            let within = |p: &[f64; 3]| {
                let anchor = &self.anchor[i];
                (0..3).map(|k| (p[k] - anchor[k]).powi(2)).sum::<f64>() < listed2
            };
            let crossing = if self.has_near[i] && within(&a) && within(&b) {
                collider.first_crossing_among(&a, &b, &self.near[i])
            } else {
                collider.first_crossing(&a, &b)
            };
            if let Some(c) = crossing {
                self.swept.push((i as u32, c));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cosserat_collide::{ContactBuffer, TriMesh};

    /// A 1 m square floor at z = 0 of 2·20² triangles, normals +z.
    fn floor() -> Arc<MeshCollider> {
        let mesh = TriMesh::patch([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 20, "floor");
        Arc::new(MeshCollider::new(mesh.expect("valid")))
    }

    #[test]
    fn clearance_and_near_lists_find_exactly_the_contacts_of_a_full_query() {
        let collider = floor();
        let (radius, margin) = (0.01, 0.002);
        let mut rmc = RodMeshContact::<f64>::new(MeshContactSettings::mesh(
            Arc::clone(&collider),
            Friction {
                static_coefficient: 0.1,
                kinetic_coefficient: 0.1,
            },
            margin,
        ));
        let mut full = ContactBuffer::new();
        let mut skipped_some = false;
        let mut reused_list = false;
        // 40 points bobbing up and down through the contact band at different phases and
        // speeds, drifting sideways over triangle edges.
        for step in 0..400 {
            let t = step as f64 * 0.01;
            let pts: Vec<[f64; 3]> = (0..40)
                .map(|i| {
                    let k = i as f64;
                    [
                        0.1 + 0.02 * k + 0.05 * t,
                        0.3 + 0.01 * (t * (1.0 + 0.1 * k)).sin(),
                        0.02 + 0.025 * (t * (0.5 + 0.07 * k) + k).sin(),
                    ]
                })
                .collect();
            let (x, y, z): (Vec<f64>, Vec<f64>, Vec<f64>) =
                pts.iter().map(|p| (p[0], p[1], p[2])).fold(
                    (Vec::new(), Vec::new(), Vec::new()),
                    |(mut a, mut b, mut c), p| {
                        a.push(p.0);
                        b.push(p.1);
                        c.push(p.2);
                        (a, b, c)
                    },
                );
            // Not moving (the sweep is tested on its own).
            rmc.detect(&x, &y, &z, radius, Motion::From([&x, &y, &z]));
            skipped_some |= rmc.clear2.iter().any(|&c| c > 0.0);
            reused_list |=
                (0..40).any(|i| rmc.clear2[i] <= 0.0 && rmc.has_near[i] && rmc.anchor[i] != pts[i]);
            collider.detect(&pts, radius + margin, &mut full);
            let expected: Vec<(u32, f64, Vec3<f64>)> = full
                .responses()
                .iter()
                .enumerate()
                .filter(|(_, r)| r.count > 0)
                .map(|(i, r)| {
                    let n = Vec3::from(r.direction);
                    (i as u32, -(r.max_depth - margin), n / n.norm())
                })
                .collect();
            let got: Vec<(u32, f64, Vec3<f64>)> = rmc
                .contacts
                .contacts()
                .map(|c| (c.point, c.gap, c.normal))
                .collect();
            assert_eq!(got, expected, "step {step}");
        }
        assert!(skipped_some, "no point was ever skipped");
        assert!(reused_list, "no point ever reused its near list");
    }

    #[test]
    fn a_point_touching_two_shapes_gets_one_contact_with_the_nearest_ones_surface() {
        let f = |mu: f64| Friction {
            static_coefficient: mu,
            kinetic_coefficient: mu,
        };
        // A floor z = 0 (μ 0.2) and a wall x = 0 (μ 0.6) moving along z at 1 m/s.
        let path = EndPath::new(
            0.0,
            vec![0.0, 1.0],
            vec![[0.0; 3], [0.0, 0.0, 1.0]],
            vec![[0.0; 3]; 2],
        )
        .unwrap();
        let shapes: Arc<[ShapeObstacle]> = Arc::new([
            ShapeObstacle {
                shape: Shape::half_space([0.0; 3], [0.0, 0.0, 1.0]).unwrap(),
                friction: f(0.2),
                path: None,
            },
            ShapeObstacle {
                shape: Shape::half_space([0.0; 3], [1.0, 0.0, 0.0]).unwrap(),
                friction: f(0.6),
                path: Some(path),
            },
        ]);
        let settings = MeshContactSettings {
            collider: None,
            friction: f(0.2),
            margin: 1e-4,
            triangle_friction: None,
            shapes,
        };
        let mut rmc = RodMeshContact::<f64>::new(settings);
        rmc.pose_shapes(0.5, 0.5, 1e-3);
        let r = 0.01;
        // Point 0 in the corner, nearer the wall; point 1 on the floor only; point 2 free.
        let (x, y, z) = (
            vec![0.009, 0.5, 0.5],
            vec![0.0; 3],
            vec![0.0095, 0.0099, 0.5],
        );
        rmc.detect(&x, &y, &z, r, Motion::From([&x, &y, &z]));
        let got: Vec<PointContact<f64>> = rmc.contacts.contacts().collect();
        assert_eq!(got.len(), 2, "{got:?}");
        // The corner: the mean of both normals weighted by their reach into the inflated
        // sphere (1.1e-3 and 6e-4), the wall's gap, and the wall's friction and speed.
        let (dw, df) = (1e-4 + 1e-3, 1e-4 + 5e-4);
        let n = Vec3::new(dw, 0.0, df).normalize();
        assert!((got[0].normal - n).norm() < 1e-12, "{:?}", got[0]);
        assert!((got[0].gap + 1e-3).abs() < 1e-12);
        assert_eq!(rmc.friction_at(0).static_coefficient, 0.6);
        assert_eq!(rmc.friction_at(1).static_coefficient, 0.2);
        let shift = rmc.wall_shift(0, &Vec3::new(x[0], y[0], z[0]), 1e-3);
        assert!(
            (shift - Vec3::new(0.0, 0.0, 1e-3)).norm() < 1e-12,
            "{shift:?}"
        );
        assert!(rmc.wall_shift(1, &Vec3::zeros(), 1e-3).norm() == 0.0);
        assert_eq!(got[1].point, 1);
        assert!((got[1].gap + 1e-4).abs() < 1e-12);
        // A point behind a shape's surface is escaped, at any depth.
        let (x, z) = (vec![0.5], vec![-0.3]);
        rmc.detect(&x, &[0.0], &z, r, Motion::From([&x, &[0.0], &z]));
        assert_eq!(rmc.stats.escaped_points, 1);
        assert!((rmc.stats.max_penetration - 0.31).abs() < 1e-12);
    }
}
