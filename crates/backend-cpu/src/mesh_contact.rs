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

use cosserat_collide::{Contact, Crossing, MeshCollider};
use cosserat_constraints::{ContactSet, Friction, PointContact};
use cosserat_model::{Real, Vec3};
use std::sync::Arc;

pub(crate) use cosserat_problem::CollisionStats;

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

/// How far beyond the query radius the nearest wall is searched for a point's clearance [m].
pub const CLEARANCE_LOOKAHEAD: f64 = 2e-3;

/// The skin of a point's near list as a fraction of the query radius (see the module docs).
const NEAR_SKIN: f64 = 0.5;

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
    /// Scratch: elements nearest a wall between their points: element, the direction from the
    /// wall, the wall's nearest point and the element's gap.
    ridge: Vec<(u32, Vec3<f64>, Vec3<f64>, f64)>,
    /// Per element, the leaf-order slots of the triangles within `reach + skin` of it as it was
    /// at `seg_anchor` (its two ends), and whether that list exists: the elements' near lists,
    /// as the points' (see the module docs).
    seg_near: Vec<Vec<u32>>,
    seg_anchor: Vec<[[f64; 3]; 2]>,
    seg_has_near: Vec<bool>,
    /// Scratch: each point's gap from its own contact (the margin without one), and its
    /// clearance beyond the reach (0 when unknown).
    own_gap: Vec<f64>,
    clearance: Vec<f64>,
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
        let margin = self.settings.margin;
        let reach = radius + margin;
        let skin = NEAR_SKIN * reach;
        let n = x.len().min(y.len()).min(z.len());
        if self.clear2.len() != n {
            self.clear2 = vec![-1.0; n];
            self.clear_at = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
            self.near = vec![Vec::new(); n];
            self.anchor = vec![[0.0; 3]; n];
            self.has_near = vec![false; n];
        }
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
        self.found.clear();
        self.contacts.clear();
        self.sweep(x, y, z, reach, skip, motion);
        let collider = &self.settings.collider;
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
            let dir = dir / len;
            self.contacts.push(PointContact {
                point: i as u32,
                normal: Vec3::new(T::lit(dir.x), T::lit(dir.y), T::lit(dir.z)),
                gap: T::lit(-penetration),
            });
        }
        // A point whose motion crossed into the wall is put back on the wall it crossed: its
        // gap is its distance in front of that triangle's plane less the radius, negative
        // when it ended behind it.
        for &(i, c) in &self.swept {
            let i = i as usize;
            let p = [x[i].to_f64(), y[i].to_f64(), z[i].to_f64()];
            let ahead: f64 = (0..3).map(|k| (p[k] - c.point[k]) * c.normal[k]).sum();
            let gap = ahead - radius;
            escaped += usize::from(ahead < 0.0);
            self.clear2[i] = -1.0;
            self.stats.max_penetration = self.stats.max_penetration.max(-gap);
            self.stats.swept_catches += 1;
            self.contacts.push(PointContact {
                point: i as u32,
                normal: Vec3::new(
                    T::lit(c.normal[0]),
                    T::lit(c.normal[1]),
                    T::lit(c.normal[2]),
                ),
                gap: T::lit(gap),
            });
        }
        self.stats.escaped_points = self.stats.escaped_points.max(escaped);
        self.stats.contacts = self.contacts.len();
        self.stats.max_contacts = self.stats.max_contacts.max(self.contacts.len());
        self.stats.steps += 1;
        self.stats.detection_seconds += t0.elapsed().as_secs_f64();
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
        }
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
                self.settings.collider.segment_near_slots(
                    &a.into(),
                    &b.into(),
                    reach + skin,
                    true,
                    &mut self.seg_near[j],
                );
                self.seg_anchor[j] = [a.into(), b.into()];
                self.seg_has_near[j] = true;
            }
            if self.seg_near[j].is_empty() {
                continue;
            }
            let Some(near) = self.settings.collider.segment_nearest_among(
                &a.into(),
                &b.into(),
                limit,
                &self.seg_near[j],
            ) else {
                continue;
            };
            if !(SEGMENT_END..=1.0 - SEGMENT_END).contains(&near.fraction) {
                continue;
            }
            let normal = Vec3::from(near.normal);
            let on_wall = Vec3::from(near.closest);
            self.ridge
                .push((j as u32, normal, on_wall, near.signed_distance - radius));
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
        let mut pending: Option<(u32, Vec3<f64>, f64)> = None;
        let flush = |p: Option<(u32, Vec3<f64>, f64)>, contacts: &mut ContactSet<T>| {
            if let Some((i, n, gap)) = p {
                let n = n.normalize();
                contacts.set(PointContact {
                    point: i,
                    normal: Vec3::new(T::lit(n.x), T::lit(n.y), T::lit(n.z)),
                    gap: T::lit(gap),
                });
            }
        };
        for &(j, normal, on_wall, gap) in &self.ridge {
            self.stats.max_penetration = self.stats.max_penetration.max(-gap);
            for i in [j, j + 1] {
                let end_gap = normal.dot(&(at(i as usize) - on_wall)) - radius;
                if end_gap >= self.own_gap[i as usize] {
                    continue;
                }
                match &mut pending {
                    Some((p, n, g)) if *p == i => {
                        *n += normal;
                        *g = g.min(end_gap);
                    }
                    _ => {
                        flush(pending.take(), &mut self.contacts);
                        pending = Some((i, normal, end_gap));
                    }
                }
            }
        }
        flush(pending, &mut self.contacts);
        self.stats.segment_contacts += self.ridge.len() as u64;
        self.stats.contacts = self.contacts.len();
        self.stats.max_contacts = self.stats.max_contacts.max(self.contacts.len());
    }

    /// Fills `swept` with the points (not skipped) whose motion over the step crosses into the
    /// wall: those that move more than [`SWEEP_FRACTION`] of `reach`, segment by segment
    /// against the tree ([`MeshCollider::first_crossing`]). A point that moves less costs one
    /// squared distance.
    fn sweep(&mut self, x: &[T], y: &[T], z: &[T], reach: f64, skip: &[bool], motion: Motion<T>) {
        self.swept.clear();
        let far2 = (SWEEP_FRACTION * reach).powi(2);
        let collider = &self.settings.collider;
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
            if let Some(c) = collider.first_crossing(&a, &b) {
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
        let mut rmc = RodMeshContact::<f64>::new(MeshContactSettings {
            collider: Arc::clone(&collider),
            friction: Friction {
                static_coefficient: 0.1,
                kinetic_coefficient: 0.1,
            },
            margin,
        });
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
}
