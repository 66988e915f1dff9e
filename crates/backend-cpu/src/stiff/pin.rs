//! A point pinned for one step's solve: to a wall's tangent plane, to the crease of two walls,
//! held still, or held on a line. The description is shared by the solve (`work.rs`, which projects the point's inverse
//! mass), by the contacts that decide it (`contact.rs`) and by the bindings (`binding.rs`); it
//! lives apart from all three so that none of them imports another for it.

use cosserat_model::Vec3;

/// A point held on the mesh's surface for one step's solve.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pinned {
    /// Index of the point.
    pub(crate) point: usize,
    /// Unit normal of the wall, out of the mesh.
    pub(crate) normal: Vec3<f64>,
    /// Sticking (no motion), or sliding in the tangent plane.
    pub(crate) stick: bool,
    /// The normal of a second wall it touches (a crease of the mesh, where the two walls meet
    /// at an angle towards the lumen): sliding, it moves only along the crease,
    /// `normal × crease`. On a faceted vessel a point pinned to one face slides into the next
    /// at every edge, and put back on that one slides into the first again.
    pub(crate) crease: Option<Vec3<f64>>,
    /// Held on a line along `normal` (a guide, [`pin_guided`](super::contact::pin_guided)) instead of a plane across it;
    /// the contact updates leave such points alone.
    pub(crate) line: bool,
    /// Held on its side of a rod contact's separating plane (`rod_contact.rs`) rather than on
    /// the mesh: the mesh's updates leave such points alone, and the rod contacts' leave the
    /// mesh's.
    pub(crate) rod: bool,
    /// Kinetic friction of a sliding point as the shift it gives the inertial target `x̃`
    /// (`μ_k p_n t / m` for a unit direction `t` against the slip), already added to `x_pred`.
    pub(crate) push: Vec3<f64>,
    /// Its normal impulse times the step, `p_n = n · g` [kg m], at the last update (from the
    /// last step before the first).
    pub(crate) pn: f64,
    /// It stuck earlier in this step and static friction could not hold it: it slides for
    /// the rest of the step (an active set that lets a point stick and slip in turn within
    /// one step need not settle).
    pub(crate) came_loose: bool,
}

impl Pinned {
    /// Point `point` held on a line along the unit vector `direction` (a guide's axis, a
    /// binding's line, a sliding end's axis), free along it.
    pub(crate) fn on_line(point: usize, direction: Vec3<f64>) -> Self {
        Self {
            point,
            normal: direction,
            stick: false,
            crease: None,
            line: true,
            rod: false,
            push: Vec3::zeros(),
            pn: 0.0,
            came_loose: false,
        }
    }

    /// Whether the mesh holds it (`contact.rs`): neither a line (guide, binding) nor a rod
    /// contact's plane.
    #[inline]
    pub(crate) fn on_mesh(&self) -> bool {
        !self.line && !self.rod
    }

    /// The direction of the crease a sliding point moves along, if it is in one.
    #[inline]
    pub(crate) fn crease_direction(&self) -> Option<Vec3<f64>> {
        let along = self.normal.cross(&self.crease?);
        let norm = along.norm();
        (norm > 0.0).then(|| along / norm)
    }

    /// The part of a motion `v` the pin allows: none when sticking, else its
    /// [`sliding_part`](Self::sliding_part).
    #[inline]
    pub(crate) fn allowed(&self, v: &Vec3<f64>) -> Vec3<f64> {
        if self.stick {
            Vec3::zeros()
        } else {
            self.sliding_part(v)
        }
    }

    /// The part of `v` along which the point slides, sticking or not: along the line (guide)
    /// or the crease, or in the wall's tangent plane.
    #[inline]
    pub(crate) fn sliding_part(&self, v: &Vec3<f64>) -> Vec3<f64> {
        if self.line {
            self.normal * self.normal.dot(v)
        } else if let Some(t) = self.crease_direction() {
            t * t.dot(v)
        } else {
            v - self.normal * self.normal.dot(v)
        }
    }
}
