//! Rod state and per-element parameters as flat arrays.
//!
//! [`RodState`] is what changes every step (positions, velocities, frames, angular velocities);
//! [`RodParams`] is what a scene fixes (rest lengths, rest Darboux vectors, masses, inertias,
//! stiffnesses). Both are structure-of-arrays with one entry per point, element or interior
//! node, so that they map one-to-one onto GPU storage buffers and so that a step is a handful
//! of linear sweeps.

use crate::quat::{frame_from_tangent, rotation_between};
use crate::{Material, Quat, Real, Vec3, darboux};

/// The dynamic state of one rod of `n` elements.
#[derive(Clone, Debug, PartialEq)]
pub struct RodState<T: Real> {
    /// Centreline points `r_0..r_n` [m].
    pub positions: Vec<Vec3<T>>,
    /// Point velocities [m/s].
    pub velocities: Vec<Vec3<T>>,
    /// Material frames `q_0..q_{n-1}` (body → world).
    pub frames: Vec<Quat<T>>,
    /// Frame angular velocities in body coordinates [rad/s].
    pub angular_velocities: Vec<Vec3<T>>,
    /// The frames of the clamps at the first (`[0]`) and last (`[1]`) end point (body →
    /// world): what holds a clamped end, half an element from the rod's end frame, which the
    /// clamp's bend–twist node ([`EndNode`]) ties to it. Moved only by the clamp's prescribed
    /// rotation; unused at free and pinned ends.
    pub clamp_frames: [Quat<T>; 2],
}

impl<T: Real> RodState<T> {
    /// Number of elements `n`.
    pub fn elements(&self) -> usize {
        self.frames.len()
    }

    /// Converts the state to another precision.
    pub fn cast<U: Real>(&self) -> RodState<U> {
        let v = |x: &Vec3<T>| {
            Vec3::new(
                U::lit(x.x.to_f64()),
                U::lit(x.y.to_f64()),
                U::lit(x.z.to_f64()),
            )
        };
        RodState {
            positions: self.positions.iter().map(v).collect(),
            velocities: self.velocities.iter().map(v).collect(),
            frames: self
                .frames
                .iter()
                .map(|q| {
                    Quat::new(
                        U::lit(q.w.to_f64()),
                        U::lit(q.i.to_f64()),
                        U::lit(q.j.to_f64()),
                        U::lit(q.k.to_f64()),
                    )
                })
                .collect(),
            angular_velocities: self.angular_velocities.iter().map(v).collect(),
            clamp_frames: self.clamp_frames.map(|q| cast_quat(&q)),
        }
    }

    /// Closes the clamp of end `end` (0: first, 1: last) on the rod as it is: the clamp frame
    /// continues the rod's current shape to its end point, turned back from the end frame by
    /// the nearest interior node's Darboux vector over the clamp node's length (for a rod of
    /// one element, by the clamp node's rest Darboux vector). A straight rod's clamp is its end
    /// frame; a rod built along a curve is clamped along the curve's tangent at its end point,
    /// to second order.
    pub fn seat_clamp(&mut self, params: &RodParams<T>, end: usize) {
        let n = self.elements();
        let end = end.min(1);
        let (frame, l) = if end == 0 {
            (self.frames[0], params.rest_lengths[0])
        } else {
            (self.frames[n - 1], params.rest_lengths[n - 1])
        };
        let u = if n >= 2 {
            let j = if end == 0 { 0 } else { n - 2 };
            darboux(&self.frames[j], &self.frames[j + 1], params.node_length(j))
        } else {
            params.end_nodes[end].rest_darboux
        };
        self.clamp_frames[end] = clamp_frame_at_rest(&frame, &u, l * T::lit(0.5), end);
    }
}

/// `q` in another precision.
fn cast_quat<T: Real, U: Real>(q: &Quat<T>) -> Quat<U> {
    Quat::new(
        U::lit(q.w.to_f64()),
        U::lit(q.i.to_f64()),
        U::lit(q.j.to_f64()),
        U::lit(q.k.to_f64()),
    )
}

/// The frame of a clamp whose node, of length `l` (half the end element), has the Darboux
/// vector `rest` against the rod's end frame `frame`: the clamp frame `q_c` with
/// `(2/l) Im(q̄_c q_0) = û` at the first end and `(2/l) Im(q̄_{n−1} q_c) = û` at the last.
pub fn clamp_frame_at_rest<T: Real>(frame: &Quat<T>, rest: &Vec3<T>, l: T, end: usize) -> Quat<T> {
    let v = rest * (l * T::lit(0.5));
    let w = (T::one() - v.norm_squared()).max(T::zero()).sqrt();
    let s = Quat::new(w, v.x, v.y, v.z);
    let q = if end == 0 {
        frame * s.conjugate()
    } else {
        frame * s
    };
    q / q.norm()
}

/// The bend–twist node between a clamp and the rod's end frame.
///
/// A clamp holds the rod at its end point, but the rod's first frame sits at the middle of the
/// first element. Holding that frame (as CoRdE and most rod codes do) clamps the rod half an
/// element in from its end, a first-order error in every clamped answer. Instead the clamp has
/// a frame of its own at the end point ([`RodState::clamp_frames`]), tied to the end frame by
/// a bend–twist node of half an element's length: the half cell of the staggered grid, which
/// makes clamped deflections, reactions and frequencies second order in the element length
/// (`docs/model.md`, "Clamps").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EndNode<T: Real> {
    /// Bending/twisting stiffness `(EI₁, EI₂, GJ)` [N m²].
    pub stiffness: Vec3<T>,
    /// Rest Darboux vector `û` (body frame of the lower frame: the clamp's at the first end,
    /// the end frame's at the last) [1/m].
    pub rest_darboux: Vec3<T>,
    /// Rotational internal damping [N m² s].
    pub damping: T,
}

/// The fixed parameters of one rod of `n` elements.
#[derive(Clone, Debug, PartialEq)]
pub struct RodParams<T: Real> {
    /// Rest length `l0_j` of each element [m].
    pub rest_lengths: Vec<T>,
    /// Rest Darboux vector `û` at each interior node (body frame of the lower element) [1/m].
    pub rest_darboux: Vec<Vec3<T>>,
    /// Lumped point masses [kg] (half of each adjacent element).
    pub masses: Vec<T>,
    /// Inverse point masses [1/kg]; zero for points moved kinematically.
    pub inv_masses: Vec<T>,
    /// Principal rotational inertia of each element about its body axes [kg m²].
    pub inertias: Vec<Vec3<T>>,
    /// Bending/twisting stiffness `(EI₁, EI₂, GJ)` at each interior node [N m²].
    pub bend_twist_stiffness: Vec<Vec3<T>>,
    /// Stretching stiffness `EA` of each element [N] (extensible mode).
    pub stretch_stiffness: Vec<T>,
    /// Parallel-constraint penalty `K_p` of each element [N].
    pub parallel_stiffness: Vec<T>,
    /// Rotational internal damping at each interior node [N m² s]: resists the rate of change of
    /// the Darboux vector (relative angular velocity of neighbouring frames).
    pub bend_damping: Vec<T>,
    /// Translational internal damping of each element [N s]: resists the rate of stretching.
    pub stretch_damping: Vec<T>,
    /// Viscous drag rate of the surrounding medium [1/s]: each point feels `−drag · m · v`.
    pub drag: T,
    /// Cross-section radius [m], for collisions and output.
    pub radius: T,
    /// The bend–twist nodes between a clamp and the end frame, at the first (`[0]`) and last
    /// (`[1]`) end; they act only where an end is clamped.
    pub end_nodes: [EndNode<T>; 2],
}

impl<T: Real> RodParams<T> {
    /// Number of elements `n`.
    pub fn elements(&self) -> usize {
        self.rest_lengths.len()
    }

    /// Distance between frames `j` and `j + 1`: the mean of their rest lengths.
    #[inline(always)]
    pub fn node_length(&self, j: usize) -> T {
        (self.rest_lengths[j] + self.rest_lengths[j + 1]) * T::lit(0.5)
    }

    /// Length of the clamp node at end `end` (0: first, 1: last): half the end element, the
    /// distance from the end point to the end frame.
    #[inline(always)]
    pub fn end_node_length(&self, end: usize) -> T {
        let j = if end == 0 { 0 } else { self.elements() - 1 };
        self.rest_lengths[j] * T::lit(0.5)
    }
}

/// Why a rod could not be built from the given geometry.
#[derive(Clone, Debug, PartialEq)]
pub enum RodBuildError {
    /// Fewer than two points (at least one element is needed).
    TooFewPoints(usize),
    /// A point is not finite.
    NonFinitePoint(usize),
    /// Two consecutive points coincide.
    ZeroLengthElement(usize),
    /// The polyline turns back on itself at this interior point (a 180° fold has no unique
    /// frame transport).
    FoldedBack(usize),
    /// The material is invalid.
    Material(crate::MaterialError),
    /// A per-rod coefficient is negative or not finite.
    InvalidCoefficient(&'static str, f64),
    /// A pre-strain that is not finite or not above −1 (a rest length must be positive).
    InvalidPreStrain(f64),
    /// Rest lengths given for another number of elements (given, elements).
    RestLengthCount(usize, usize),
    /// A rest length that is not finite and positive (element, value).
    InvalidRestLength(usize, f64),
    /// A uniform rest curvature that no pair of frames can have at this node: the discrete
    /// Darboux vector `(2/l̄) Im(q̄_j q_{j+1})` has a length of at most `2/l̄` (a relative
    /// rotation of π), so `|û| l̄ / 2` (the second field) must stay below 1.
    UnreachableRestShape(usize, f64),
    /// A uniform rest curvature that bends the rod tighter than its own radius: the bending
    /// part `|(κ₁, κ₂)|` (the first field, 1/m) times the radius (the second field, m) is at
    /// least 1, so the rod's inner side would have a negative length. No material takes that
    /// shape, and the model, a thin rod, says nothing about it (released from straight, such a
    /// rod tears its elements at every step size; `tests/stability.rs`).
    RestCurvatureTighterThanRadius(f64, f64),
}

impl std::fmt::Display for RodBuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::TooFewPoints(n) => write!(f, "a rod needs at least 2 points, got {n}"),
            Self::NonFinitePoint(i) => write!(f, "point {i} is not finite"),
            Self::ZeroLengthElement(j) => write!(
                f,
                "element {j} has zero length (points {j} and {} coincide)",
                j + 1
            ),
            Self::FoldedBack(i) => write!(f, "the polyline folds back on itself at point {i}"),
            Self::Material(e) => write!(f, "{e}"),
            Self::UnreachableRestShape(j, half) => write!(
                f,
                "the rest curvature cannot be reached at node {j}: |κ| l / 2 = {half:.3} (l the \
                 node's length) must be below 1, the discrete Darboux vector's range (a turn of \
                 π per element); use more elements or less curvature"
            ),
            Self::RestCurvatureTighterThanRadius(kappa, r) => write!(
                f,
                "the rest curvature |(κ1, κ2)| = {kappa:.4e} 1/m bends the rod tighter than its \
                 radius: a radius of curvature of {:.4e} m against a rod radius of {r:.4e} m; \
                 expected |(κ1, κ2)| below 1/r = {:.4e} 1/m",
                1.0 / kappa,
                1.0 / r
            ),
            Self::RestLengthCount(got, n) => write!(
                f,
                "{got} rest lengths given for a rod of {n} elements: expected one per element"
            ),
            Self::InvalidRestLength(j, v) => write!(
                f,
                "the rest length of element {j} is {v}: expected a finite length above 0"
            ),
            Self::InvalidPreStrain(v) => write!(
                f,
                "`pre_strain` = {v} is invalid: expected a finite number above -1 (rest length = built length / (1 + pre_strain))"
            ),
            Self::InvalidCoefficient(name, v) => write!(
                f,
                "`{name}` = {v} is invalid: expected a finite number >= 0"
            ),
        }
    }
}

impl std::error::Error for RodBuildError {}

/// The rest shape of a rod: where its rest Darboux vectors come from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RestShape {
    /// Taken from the initial geometry, so the rod starts at rest (its intrinsic shape is the
    /// shape it is built in).
    Initial,
    /// A uniform intrinsic curvature/twist `(κ₁, κ₂, τ)` [1/m] in the body frame; `[0, 0, 0]` is a
    /// straight, untwisted rod.
    Uniform([f64; 3]),
}

/// Everything needed to build a rod besides its geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodSpec {
    /// Material of the whole rod.
    pub material: Material,
    /// Source of the rest Darboux vectors.
    pub rest_shape: RestShape,
    /// `K_p` override [N]; `None` uses the shear stiffness `G A`.
    pub parallel_stiffness: Option<f64>,
    /// Rotational internal damping coefficient [N m² s].
    pub bend_damping: f64,
    /// Translational internal damping coefficient [N s].
    pub stretch_damping: f64,
    /// Viscous drag rate of the surrounding medium [1/s].
    pub drag: f64,
    /// Direction `d1` of the first frame should point to (projected off the tangent).
    pub first_director_hint: [f64; 3],
    /// Strain of the rod as built: every rest length is the built length over `1 + pre_strain`
    /// (0: the rod is built unstretched; 0.01: stretched by 1 %, as a rope hung taut; negative:
    /// compressed). Masses and inertias follow the rest lengths (the material is conserved).
    pub pre_strain: f64,
}

impl RodSpec {
    /// A spec with the given material, a rest shape taken from the geometry, no damping and the
    /// default penalty.
    pub fn new(material: Material) -> Self {
        Self {
            material,
            rest_shape: RestShape::Initial,
            parallel_stiffness: None,
            bend_damping: 0.0,
            stretch_damping: 0.0,
            drag: 0.0,
            first_director_hint: [0.0, 0.0, 1.0],
            pre_strain: 0.0,
        }
    }
}

/// Builds the state and parameters of a rod through the given polyline.
///
/// Frames are adapted to the segments (`d3` along each) and carried from one segment to the
/// next by parallel transport (the rotation of least angle), so a polyline built without twist
/// gets frames without twist.
pub fn build_rod<T: Real>(
    points: &[[f64; 3]],
    spec: &RodSpec,
) -> Result<(RodState<T>, RodParams<T>), RodBuildError> {
    build_rod_with_rest_lengths(points, spec, None)
}

/// [`build_rod`] with the rest length of every element given (`rest_lengths[j]` for the
/// segment `points[j] → points[j + 1]`), for a rod built strained unevenly (a rope hung under
/// its own weight, a cable pulled round a drum); `spec.pre_strain` then applies on top of them.
/// `None` takes the built lengths.
pub fn build_rod_with_rest_lengths<T: Real>(
    points: &[[f64; 3]],
    spec: &RodSpec,
    rest_lengths: Option<&[f64]>,
) -> Result<(RodState<T>, RodParams<T>), RodBuildError> {
    spec.material.validate().map_err(RodBuildError::Material)?;
    if let Some(rest) = rest_lengths {
        let n = points.len().saturating_sub(1);
        if rest.len() != n {
            return Err(RodBuildError::RestLengthCount(rest.len(), n));
        }
        if let Some(j) = rest.iter().position(|l| !(l.is_finite() && *l > 0.0)) {
            return Err(RodBuildError::InvalidRestLength(j, rest[j]));
        }
    }
    for (name, v) in [
        ("bend_damping", spec.bend_damping),
        ("stretch_damping", spec.stretch_damping),
        ("drag", spec.drag),
        ("parallel_stiffness", spec.parallel_stiffness.unwrap_or(0.0)),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(RodBuildError::InvalidCoefficient(name, v));
        }
    }
    if !(spec.pre_strain.is_finite() && spec.pre_strain > -1.0) {
        return Err(RodBuildError::InvalidPreStrain(spec.pre_strain));
    }
    if points.len() < 2 {
        return Err(RodBuildError::TooFewPoints(points.len()));
    }
    let p: Vec<Vec3<f64>> = points.iter().map(|a| Vec3::new(a[0], a[1], a[2])).collect();
    if let Some(i) = p.iter().position(|x| !x.iter().all(|c| c.is_finite())) {
        return Err(RodBuildError::NonFinitePoint(i));
    }
    let n = p.len() - 1;
    let mut lengths = Vec::with_capacity(n);
    let mut tangents = Vec::with_capacity(n);
    for j in 0..n {
        let e = p[j + 1] - p[j];
        let l = e.norm();
        if !(l > 0.0) {
            return Err(RodBuildError::ZeroLengthElement(j));
        }
        let rest = rest_lengths.map_or(l, |r| r[j]);
        lengths.push(rest / (1.0 + spec.pre_strain));
        tangents.push(e / l);
    }
    let hint = Vec3::from(spec.first_director_hint);
    let mut frames: Vec<Quat<f64>> = Vec::with_capacity(n);
    frames.push(frame_from_tangent(&tangents[0], &hint));
    for j in 1..n {
        let transport =
            rotation_between(&tangents[j - 1], &tangents[j]).ok_or(RodBuildError::FoldedBack(j))?;
        let q = transport * frames[j - 1];
        frames.push(q / q.norm());
    }
    let m = &spec.material;
    let rest_darboux: Vec<Vec3<f64>> = match spec.rest_shape {
        RestShape::Initial => (0..n.saturating_sub(1))
            .map(|j| {
                darboux(
                    &frames[j],
                    &frames[j + 1],
                    0.5 * (lengths[j] + lengths[j + 1]),
                )
            })
            .collect(),
        RestShape::Uniform(u) => {
            let bending = u[0].hypot(u[1]);
            if !(bending * m.radius < 1.0) {
                return Err(RodBuildError::RestCurvatureTighterThanRadius(
                    bending, m.radius,
                ));
            }
            let u = Vec3::from(u);
            for j in 0..n.saturating_sub(1) {
                let half = u.norm() * 0.25 * (lengths[j] + lengths[j + 1]);
                if !(half < 1.0) {
                    return Err(RodBuildError::UnreachableRestShape(j, half));
                }
            }
            vec![u; n.saturating_sub(1)]
        }
    };
    let mu = m.linear_density();
    let mut masses = vec![0.0; n + 1];
    for j in 0..n {
        masses[j] += 0.5 * mu * lengths[j];
        masses[j + 1] += 0.5 * mu * lengths[j];
    }
    let ipl = m.inertia_per_length();
    let k = m.bend_twist_stiffness();
    let kp = spec
        .parallel_stiffness
        .unwrap_or_else(|| m.shear_stiffness());
    let t = T::lit;
    let v3 = |v: Vec3<f64>| Vec3::new(t(v.x), t(v.y), t(v.z));
    // The clamp nodes continue the rod's rest shape: the nearest interior node's (none for a
    // single element, which is taken straight unless a uniform shape is given).
    let end_rest = |end: usize| match spec.rest_shape {
        RestShape::Uniform(u) => Vec3::from(u),
        RestShape::Initial if n >= 2 => rest_darboux[if end == 0 { 0 } else { n - 2 }],
        RestShape::Initial => Vec3::zeros(),
    };
    let end_nodes = [0, 1].map(|end| EndNode {
        stiffness: Vec3::new(t(k[0]), t(k[1]), t(k[2])),
        rest_darboux: v3(end_rest(end)),
        damping: t(spec.bend_damping),
    });
    let mut state = RodState {
        positions: p.iter().map(|x| v3(*x)).collect(),
        velocities: vec![Vec3::zeros(); n + 1],
        frames: frames
            .iter()
            .map(|q| Quat::new(t(q.w), t(q.i), t(q.j), t(q.k)))
            .collect(),
        angular_velocities: vec![Vec3::zeros(); n],
        clamp_frames: [Quat::identity(); 2],
    };
    let params = RodParams {
        rest_lengths: lengths.iter().map(|&l| t(l)).collect(),
        rest_darboux: rest_darboux.into_iter().map(v3).collect(),
        masses: masses.iter().map(|&x| t(x)).collect(),
        inv_masses: masses.iter().map(|&x| t(1.0 / x)).collect(),
        inertias: lengths
            .iter()
            .map(|&l| Vec3::new(t(ipl[0] * l), t(ipl[1] * l), t(ipl[2] * l)))
            .collect(),
        bend_twist_stiffness: vec![Vec3::new(t(k[0]), t(k[1]), t(k[2])); n.saturating_sub(1)],
        stretch_stiffness: vec![t(m.stretch_stiffness()); n],
        parallel_stiffness: vec![t(kp); n],
        bend_damping: vec![t(spec.bend_damping); n.saturating_sub(1)],
        stretch_damping: vec![t(spec.stretch_damping); n],
        drag: t(spec.drag),
        radius: t(m.radius),
        end_nodes,
    };
    state.seat_clamp(&params, 0);
    state.seat_clamp(&params, 1);
    Ok((state, params))
}

/// Points of a straight rod from `start` along the unit `direction`, `n` equal elements of total
/// `length`.
pub fn straight_polyline(
    start: [f64; 3],
    direction: [f64; 3],
    length: f64,
    n: usize,
) -> Vec<[f64; 3]> {
    let d = Vec3::from(direction).normalize();
    (0..=n)
        .map(|i| {
            let s = length * i as f64 / n as f64;
            [start[0] + d.x * s, start[1] + d.y * s, start[2] + d.z * s]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mat() -> Material {
        Material::new(1e6, 1e6 / 3.0, 1000.0, 1e-3)
    }

    #[test]
    fn straight_rod_is_at_rest_and_conserves_mass() {
        let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 2.0, 10);
        let (s, p) = build_rod::<f64>(&pts, &RodSpec::new(mat())).unwrap();
        assert_eq!(s.elements(), 10);
        let total: f64 = p.masses.iter().sum();
        assert!((total - mat().linear_density() * 2.0).abs() < 1e-15);
        assert!(p.rest_darboux.iter().all(|u| u.norm() < 1e-12));
        for (j, q) in s.frames.iter().enumerate() {
            assert!((crate::quat::d3(q) - Vec3::x()).norm() < 1e-12, "frame {j}");
        }
    }

    /// A pre-strained rod's rest lengths are its built lengths over `1 + ε`, its mass that of
    /// its rest length, and its stretching energy `½ E A L_rest ε²`; a pre-strain at or below
    /// −1 is refused.
    #[test]
    fn a_pre_strained_rod_rests_shorter_than_it_is_built() {
        let eps = 0.02;
        let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 2.0, 10);
        let mut spec = RodSpec::new(mat());
        spec.pre_strain = eps;
        let (s, p) = build_rod::<f64>(&pts, &spec).unwrap();
        let rest = 2.0 / (1.0 + eps);
        assert!((p.rest_lengths.iter().sum::<f64>() - rest).abs() < 1e-12);
        let total: f64 = p.masses.iter().sum();
        assert!((total - mat().linear_density() * rest).abs() < 1e-12);
        let model = crate::energy::ForceModel {
            extensible: true,
            gravity: Vec3::zeros(),
            clamped: [false; 2],
        };
        let e = crate::energy::energies(&s, &p, &model).stretch;
        let expected = 0.5 * mat().stretch_stiffness() * rest * eps * eps;
        assert!((e / expected - 1.0).abs() < 1e-12, "{e} vs {expected}");
        spec.pre_strain = -1.0;
        assert_eq!(
            build_rod::<f64>(&pts, &spec).unwrap_err(),
            RodBuildError::InvalidPreStrain(-1.0)
        );
    }

    #[test]
    fn bad_geometry_is_rejected() {
        let spec = RodSpec::new(mat());
        assert_eq!(
            build_rod::<f64>(&[[0.0; 3]], &spec).unwrap_err(),
            RodBuildError::TooFewPoints(1)
        );
        assert_eq!(
            build_rod::<f64>(&[[0.0; 3], [0.0; 3]], &spec).unwrap_err(),
            RodBuildError::ZeroLengthElement(0)
        );
        assert_eq!(
            build_rod::<f64>(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0; 3]], &spec).unwrap_err(),
            RodBuildError::FoldedBack(1)
        );
        assert_eq!(
            build_rod::<f64>(&[[0.0; 3], [f64::NAN, 0.0, 0.0]], &spec).unwrap_err(),
            RodBuildError::NonFinitePoint(1)
        );
    }

    /// A uniform rest curvature is accepted while `|κ| l / 2 < 1` (the largest discrete
    /// Darboux vector two frames can have, `2/l`, is a relative turn of π) and rejected beyond,
    /// naming the node; the largest accepted one is reached by frames turned just below π.
    #[test]
    fn unreachable_rest_curvature_is_rejected() {
        let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.2, 2);
        let at = |kappa: f64| {
            let mut spec = RodSpec::new(mat());
            spec.rest_shape = RestShape::Uniform([kappa, 0.0, 0.0]);
            build_rod::<f64>(&pts, &spec)
        };
        let (_, p) = at(19.9).unwrap();
        let turn = crate::quat::exp_rotation(&Vec3::new(2.0 * (19.9_f64 * 0.05).asin(), 0.0, 0.0));
        let reached = crate::darboux::darboux(&Quat::identity(), &turn, 0.1);
        assert!((reached - p.rest_darboux[0]).norm() < 1e-9, "{reached}");
        match at(20.0).unwrap_err() {
            RodBuildError::UnreachableRestShape(0, half) => assert!((half - 1.0).abs() < 1e-12),
            e => panic!("{e}"),
        }
        let msg = at(36.4).unwrap_err().to_string();
        assert!(msg.contains("node 0") && msg.contains("1.820"), "{msg}");
    }

    /// A uniform rest curvature whose bending part curls the rod tighter than its radius is
    /// refused with the curvature and the radius; twist alone is not limited by the radius.
    #[test]
    fn rest_curvature_tighter_than_the_radius_is_rejected() {
        let r = mat().radius;
        let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 1e-3, 2);
        let at = |u: [f64; 3]| {
            let mut spec = RodSpec::new(mat());
            spec.rest_shape = RestShape::Uniform(u);
            build_rod::<f64>(&pts, &spec)
        };
        assert!(at([0.6 / r, 0.79 / r, 0.0]).is_ok());
        assert!(at([0.0, 0.0, 1.5 / r]).is_ok());
        match at([0.6 / r, 0.8 / r, 0.0]).unwrap_err() {
            RodBuildError::RestCurvatureTighterThanRadius(kappa, radius) => {
                assert!((kappa * r - 1.0).abs() < 1e-12 && radius == r)
            }
            e => panic!("{e}"),
        }
        let msg = at([2.0 / r, 0.0, 0.0]).unwrap_err().to_string();
        assert!(msg.contains("tighter than its radius"), "{msg}");
    }
}
