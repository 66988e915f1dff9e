//! A point pinned for one step's solve: to a wall's tangent plane, to the crease of two walls,
//! held still, or held on a line. The description is shared by the solve (`work.rs`, which projects the point's inverse
//! mass), by the contacts that decide it (`contact.rs`) and by the bindings (`binding.rs`); it
//! lives apart from all three so that none of them imports another for it.

use cosserat_model::Vec3;

/// The relative change of a pinned point's normal impulse between two rounds of a step above
/// which the step is solved again with the new one (its friction is proportional to it).
pub(crate) const NORMAL_CHANGE: f64 = 0.1;

/// A point held on the mesh's surface for one step's solve.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pinned {
    /// Index of the point.
    pub(crate) point: usize,
    /// Unit normal of the wall, out of the mesh.
    pub(crate) normal: Vec3<f64>,
    /// The normal of a second wall it touches (a crease of the mesh, where the two walls meet
    /// at an angle towards the lumen): it moves only along the crease, `normal × crease`. On
    /// a faceted vessel a point pinned to one face slides into the next at every edge, and put
    /// back on that one slides into the first again.
    pub(crate) crease: Option<Vec3<f64>>,
    /// Held on a line along `normal` (a guide, [`pin_guided`](super::contact::pin_guided)) instead of a plane across it;
    /// the contact updates leave such points alone.
    pub(crate) line: bool,
    /// Held on its side of a rod contact's separating plane (`rod_contact.rs`) rather than on
    /// the mesh: the mesh's updates leave such points alone, and the rod contacts' leave the
    /// mesh's.
    pub(crate) rod: bool,
    /// Its normal impulse times the step, `p_n = n · g` [kg m], at the last update (from the
    /// last step before the first): what its friction is proportional to.
    pub(crate) pn: f64,
    /// Coulomb friction against its motion along the wall (`None`: frictionless, as a guide's
    /// or a binding's line).
    pub(crate) friction: Option<PinFriction>,
    /// With contact rows (`rows.rs`): its normal impulse as a multiplier of the solve (times
    /// the step, as `pn`), its increment of the last iteration, and the plane it was put on
    /// (`n · x ≥ row_offset` for `row_normal`, taken again whenever the contacts move the point
    /// or turn its normal, i.e. the point was last put at `row_x`).
    pub(crate) mult: f64,
    pub(crate) dmult: f64,
    pub(crate) row_offset: f64,
    pub(crate) row_normal: Vec3<f64>,
    pub(crate) row_x: Vec3<f64>,
    /// A self-contact's other side in the same rod (`rod_contact.rs`, contact rows only): the
    /// segment `(j, j + 1)` and the parameter `t` of its closest point. The row then holds the
    /// point's distance from that moving closest point, `n · (x_i − x_m)` with
    /// `x_m = (1 − t) x_j + t x_{j+1}`, and its impulse acts on both sides (`rows.rs`).
    pub(crate) partner: Option<(usize, f64)>,
}

/// Coulomb friction of a pinned point, as a force of the step's own equations rather than a
/// state of the active set.
///
/// The friction impulse (times the step, as XPBD's impulses) against the point's slip `s`
/// (its motion over the step along the wall, relative to the wall, [`start`](Self::start)) is
/// `f(s) = −μ_s p_n s / δ` up to `|s| = δ`, falls linearly to `μ_k p_n` at `2δ` and stays
/// there (`δ` = [`stick_slip`](Self::stick_slip)): static friction as a stiff tangential
/// spring of rest length zero, kinetic friction beyond. The solve evaluates `f` at every
/// iterate (`Work::rhs`), so a converged step satisfies this law exactly for the normal
/// impulse `p_n` of the last update; the Newton matrix carries a linearisation `K_f` of it
/// (its slope, or its secant where a slide starts or reverses) frozen at the last
/// factorisation ([`freeze`](Self::freeze)), a chord approximation like the frames' geometric
/// bound. A point holds (creeps slower than `δ / h`) while what drives it is below
/// `μ_s p_n` and slides against `μ_k p_n` beyond, with no switch of the solve's matrix or
/// targets between the two.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PinFriction {
    /// Where the slip is measured from: the point's place at the start of the step, carried
    /// with the wall (a moving obstacle, the other rod of a rod contact).
    pub(crate) start: Vec3<f64>,
    /// Static coefficient: the largest ratio of friction to normal impulse while it holds.
    pub(crate) mu_s: f64,
    /// Kinetic coefficient, while it slides.
    pub(crate) mu_k: f64,
    /// The slip over the step [m] up to which friction holds, `δ`.
    pub(crate) stick_slip: f64,
    /// The linearisation of the Newton matrix (`K_f = k_along t tᵀ + k_across (P − t tᵀ)` in
    /// the wall's tangent space `P`, [kg]), frozen at the last factorisation: unit slip
    /// direction `t` (zero before any slip), and the stiffnesses along and across it.
    pub(crate) dir: Vec3<f64>,
    pub(crate) k_along: f64,
    pub(crate) k_across: f64,
    /// Whether the last [`freeze`](Self::freeze) found it sliding (beyond the holding slip);
    /// `None` before the step's first.
    sliding: Option<bool>,
}

/// The speed [m/s] below which friction holds a pinned point, `δ / h`
/// ([`PinFriction::stick_slip`]): a point that static friction holds creeps at most this fast
/// (0.1 mm in a second), and the tangential stiffness of a held point, `μ_s p_n / δ`, stays
/// finite (for the nitinol wire pressed on the vessel at 1 ms, about 10⁴ times its mass).
pub const STICK_SPEED: f64 = 1e-4;

impl PinFriction {
    /// Friction of coefficients `mu_s`, `mu_k` on a point whose slip over a step of `h` is
    /// measured from `start` (`None` when both are zero).
    pub(crate) fn new(start: Vec3<f64>, mu_s: f64, mu_k: f64, h: f64) -> Option<Self> {
        (mu_s > 0.0 || mu_k > 0.0).then(|| Self {
            start,
            mu_s: mu_s.max(mu_k),
            mu_k,
            stick_slip: STICK_SPEED * h,
            dir: Vec3::zeros(),
            k_along: 0.0,
            k_across: 0.0,
            sliding: None,
        })
    }

    /// Marks it as sliding along `direction` already (a point that slid at the end of the last
    /// step, along its predicted slip): its first freeze in the step then takes the law's slope
    /// along a slip that goes on that way, as later freezes do, not the secant. With the
    /// secant at every step's first freeze a steady slide ended each step a little short (the
    /// secant under-corrects by `k / (m + k)` and the step stops below the holding slip), and
    /// a rope sliding down a slope fell 1 % behind in 200 steps.
    pub(crate) fn continuing(mut self, direction: &Vec3<f64>) -> Self {
        let n = direction.norm();
        if n > 0.0 {
            self.dir = direction / n;
            self.sliding = Some(true);
        }
        self
    }

    /// Whether a slip `slip` is within what friction holds.
    pub(crate) fn holds(&self, slip: &Vec3<f64>) -> bool {
        slip.norm() <= self.stick_slip
    }

    /// The friction's magnitude over `p_n` at a slip of length `s`, and its derivative.
    fn law(&self, s: f64) -> (f64, f64) {
        let d = self.stick_slip;
        if s <= d {
            (self.mu_s * s / d, self.mu_s / d)
        } else if s < 2.0 * d {
            let slope = (self.mu_k - self.mu_s) / d;
            (self.mu_s + slope * (s - d), slope)
        } else {
            (self.mu_k, 0.0)
        }
    }

    /// The friction impulse (times the step) at slip `slip` under normal impulse `pn`:
    /// against the slip, of the magnitude the law gives.
    pub(crate) fn impulse(&self, slip: &Vec3<f64>, pn: f64) -> Vec3<f64> {
        let s = slip.norm();
        if !(s > 0.0) || !(pn > 0.0) {
            return Vec3::zeros();
        }
        let (mu, _) = self.law(s);
        -slip * (mu * pn / s)
    }

    /// Freezes the matrix's linearisation at slip `slip` and normal impulse `pn`. Within the
    /// holding slip, `μ_s p_n / δ` both ways. Sliding, across the slip `|f| / |s|` (the force
    /// turns with the slip), and along it the law's slope (none on a kinetic slide, where the
    /// force is constant) when it breaks loose from holding or slides on the way it slid at
    /// the last freeze; at the step's first freeze of a slide, or one that reversed, `|f| / |s|`
    /// along it too: the secant, a damper, which never carries the point across `s = 0`, where
    /// the force flips. With the slope at every freeze, Newton carried a point that friction
    /// should stop across `s = 0` and back every iteration (the steel wire at 0.1 ms stalled at
    /// corrections of 1.5e3 `δ` for 8 iterations and 4 rounds); with the secant at every
    /// freeze, a rope breaking loose on a slope took more than a step's 8 iterations to slide.
    pub(crate) fn freeze(&mut self, slip: &Vec3<f64>, pn: f64) {
        let pn = pn.max(0.0);
        let s = slip.norm();
        let (mu, slope) = self.law(s);
        if s <= self.stick_slip {
            self.dir = if s > 0.0 { slip / s } else { Vec3::zeros() };
            self.k_along = slope * pn;
            self.k_across = slope * pn;
            self.sliding = Some(false);
        } else {
            // From holding, or on along its last slide: the slope. At the step's first freeze
            // or after it reversed: the secant.
            let continues = match self.sliding {
                None => false,
                Some(false) => true,
                Some(true) => self.dir.dot(slip) > 0.0,
            };
            self.dir = slip / s;
            self.k_across = mu * pn / s;
            self.k_along = if continues {
                slope.max(0.0) * pn
            } else {
                self.k_across
            };
            self.sliding = Some(true);
        }
    }

    /// The law's own stiffness along a slip `slip` under `pn`: `μ_s p_n / δ` while it holds,
    /// none beyond (the kinetic force is constant; the falling stretch counts as none). A
    /// point's remaining correction is its imbalance over `m` plus this (`Work::rhs`): through
    /// the matrix's secant, a slide's imbalance would look up to `μ_k p_n / (m |s|)` times
    /// smaller than it is.
    pub(crate) fn tangent(&self, slip: &Vec3<f64>, pn: f64) -> f64 {
        if slip.norm() <= self.stick_slip {
            self.mu_s * pn.max(0.0) / self.stick_slip
        } else {
            0.0
        }
    }

    /// Whether the frozen linearisation no longer fits slip `slip` under `pn` for a point of
    /// mass `mass`: its mobility `1 / (m + eᵀ K_f e)` along or across the slip would change by
    /// more than a factor of two. The solve's residual measures a pin's imbalance through that
    /// mobility, so a point frozen as held (stiff) that has started to slide would pass the
    /// tolerance unbalanced: the contacts' updates solve such a step again with the matrix
    /// rebuilt.
    pub(crate) fn stale(&self, slip: &Vec3<f64>, pn: f64, mass: f64) -> bool {
        let mut now = *self;
        now.freeze(slip, pn);
        let t = if now.dir.norm_squared() > 0.5 {
            now.dir
        } else {
            self.dir
        };
        if t.norm_squared() < 0.5 {
            return false;
        }
        let across = if t.x.abs() < 0.9 {
            Vec3::x()
        } else {
            Vec3::y()
        };
        let across = (across - t * t.dot(&across)).normalize();
        [t, across].iter().any(|e| {
            let ratio = (mass + self.stiffness_along(e)) / (mass + now.stiffness_along(e));
            !(0.5..=2.0).contains(&ratio)
        })
    }

    /// `eᵀ K_f e` for a unit vector `e` of the tangent space.
    pub(crate) fn stiffness_along(&self, e: &Vec3<f64>) -> f64 {
        let c = self.dir.dot(e);
        self.k_across + (self.k_along - self.k_across) * c * c
    }
}

impl Pinned {
    /// Point `point` held on a line along the unit vector `direction` (a guide's axis, a
    /// binding's line, a sliding end's axis), free along it.
    pub(crate) fn on_line(point: usize, direction: Vec3<f64>) -> Self {
        Self {
            point,
            normal: direction,
            crease: None,
            line: true,
            rod: false,
            pn: 0.0,
            friction: None,
            mult: 0.0,
            dmult: 0.0,
            row_offset: 0.0,
            row_normal: Vec3::zeros(),
            row_x: Vec3::zeros(),
            partner: None,
        }
    }

    /// Point `point` held on a wall (of the mesh, or a rod contact's plane with `rod`) of unit
    /// normal `normal`, with friction `friction`.
    pub(crate) fn on_wall(
        point: usize,
        normal: Vec3<f64>,
        rod: bool,
        pn: f64,
        friction: Option<PinFriction>,
    ) -> Self {
        Self {
            point,
            normal,
            crease: None,
            line: false,
            rod,
            pn,
            friction,
            mult: 0.0,
            dmult: 0.0,
            row_offset: 0.0,
            row_normal: Vec3::zeros(),
            row_x: Vec3::zeros(),
            partner: None,
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

    /// The part of `v` along which the point may move: along the line (guide) or the crease,
    /// or in the wall's tangent plane.
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

    /// Takes the normal impulse `pn` of a round's solve, at `x`, for a point of inverse mass
    /// `w`. Returns whether the step must be solved again (its friction, proportional to the
    /// normal impulse, changed by more than [`NORMAL_CHANGE`]; or its frozen linearisation no
    /// longer fits, [`friction_stale`](Self::friction_stale)) and whether the matrix must be
    /// rebuilt for it (the latter).
    pub(crate) fn take_normal_impulse(&mut self, pn: f64, x: &Vec3<f64>, w: f64) -> (bool, bool) {
        let moved = self.friction.is_some() && (pn - self.pn).abs() > NORMAL_CHANGE * pn;
        self.pn = pn;
        let stale = self.friction_stale(x, w);
        (moved || stale, stale)
    }

    /// Whether its friction's frozen linearisation no longer fits its slip at `x`
    /// ([`PinFriction::stale`]) for a point of inverse mass `w`.
    pub(crate) fn friction_stale(&self, x: &Vec3<f64>, w: f64) -> bool {
        match (self.friction, self.slip(x)) {
            (Some(f), Some(slip)) if w > 0.0 => f.stale(&slip, self.pn, 1.0 / w),
            _ => false,
        }
    }

    /// Its slip over the step at `x`, if it has friction: its motion along what it slides,
    /// from where the friction measures it.
    #[inline]
    pub(crate) fn slip(&self, x: &Vec3<f64>) -> Option<Vec3<f64>> {
        self.friction.map(|f| self.sliding_part(&(x - f.start)))
    }

    /// The unit directions it moves along: one (a line, a crease) or two (a plane), the
    /// second zero when there is one. With friction, the plane's are the frozen slip
    /// direction and the one across it.
    pub(crate) fn free_directions(&self) -> [Vec3<f64>; 2] {
        if self.line {
            return [self.normal, Vec3::zeros()];
        }
        if let Some(t) = self.crease_direction() {
            return [t, Vec3::zeros()];
        }
        let n = self.normal;
        let first = match self.friction {
            Some(f) if f.dir.norm_squared() > 0.5 => (f.dir - n * n.dot(&f.dir)).normalize(),
            _ => perpendiculars(&n)[0],
        };
        [first, n.cross(&first)]
    }

    /// Its inverse mass in the solve along each of [`free_directions`](Self::free_directions)
    /// for a point of inverse mass `w`: `w` without friction, `1 / (m + eᵀ K_f e)` with it.
    pub(crate) fn mobilities(&self, w: f64) -> [f64; 2] {
        let dirs = self.free_directions();
        dirs.map(|e| match self.friction {
            _ if e == Vec3::zeros() => 0.0,
            Some(f) if w > 0.0 => 1.0 / (1.0 / w + f.stiffness_along(&e)),
            _ => w,
        })
    }

    /// `A v` with `A = Σ_k e_k e_kᵀ c_k`, the pin's inverse mass (`c_k` its
    /// [`mobilities`](Self::mobilities) for a point of inverse mass `w`): the motion it allows
    /// a point of that inverse mass under an impulse `v / w`.
    pub(crate) fn mobility_times(&self, w: f64, v: &Vec3<f64>) -> Vec3<f64> {
        let dirs = self.free_directions();
        let c = self.mobilities(w);
        dirs[0] * (c[0] * dirs[0].dot(v)) + dirs[1] * (c[1] * dirs[1].dot(v))
    }
}

/// Two unit vectors perpendicular to the unit vector `a` and to each other.
pub(crate) fn perpendiculars(a: &Vec3<f64>) -> [Vec3<f64>; 2] {
    // Cross with the axis `a` is least aligned with.
    let pick = if a.x.abs() <= a.y.abs() && a.x.abs() <= a.z.abs() {
        Vec3::x()
    } else if a.y.abs() <= a.z.abs() {
        Vec3::y()
    } else {
        Vec3::z()
    };
    let b = a.cross(&pick).normalize();
    [b, a.cross(&b)]
}
