//! A point pinned for one step's solve: to a wall's tangent plane, held still, or held on a
//! line. The description is shared by the solve (`work.rs`, which projects the point's inverse
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
    /// Held on a line along `normal` (a guide, [`pin_guided`](super::contact::pin_guided)) instead of a plane across it;
    /// the contact updates leave such points alone.
    pub(crate) line: bool,
    /// Kinetic friction of a sliding point as the shift it gives the inertial target `x̃`
    /// (`μ_k p_n t / m` for a unit direction `t` against the slip), already added to `x_pred`.
    pub(crate) push: Vec3<f64>,
    /// Its normal impulse times the step, `p_n = n · g` [kg m], at the last update (from the
    /// last step before the first).
    pub(crate) pn: f64,
}
