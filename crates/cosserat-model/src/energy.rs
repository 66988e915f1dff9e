//! Energies of the discrete rod and their exact gradients, as forces and torques.
//!
//! Each term is a small kernel over one element or one interior node that returns its energy
//! together with the negative gradient: forces on the points and torques on the frames. A
//! torque on a frame is the negative gradient of the energy with respect to a small body-frame
//! rotation `q → q ⊗ exp(θ/2)`, expressed in body coordinates, which is what Euler's equations
//! of the frame take. The unit tests check every kernel against central finite differences of
//! its own energy.
//!
//! Terms (paper section 2.1, discretised per element of rest length `l0` or per node of length
//! `l̄`):
//! - bending and twisting: `½ l̄ Σ_k K_k (u_k − û_k)²` with the discrete Darboux vector `u`;
//! - parallel-constraint penalty (eq. 8): `½ K_p l0 |t − d3|²` with the unit tangent `t`;
//! - stretching (eq. 2, extensible mode only): `½ K_s l0 (|e|/l0 − 1)²`;
//! - internal damping as Rayleigh dissipation of the stretching rate and of the rate of change of
//!   the Darboux vector, so that rigid motions are not damped;
//! - gravity and a mass-proportional drag of the surrounding medium.

use crate::darboux::relative_rotation;
use crate::quat::{d3, rotate, rotate_inv};
use crate::rod::EndNode;
use crate::{Quat, Real, RodParams, RodState, Vec3};

/// Bending/twisting energy at one node and the body-frame torques on its two frames.
///
/// Returns `(energy, torque on qa in qa's body frame, torque on qb in qb's body frame)`.
#[inline(always)]
pub fn bend_twist_node<T: Real>(
    qa: &Quat<T>,
    qb: &Quat<T>,
    rest: &Vec3<T>,
    k: &Vec3<T>,
    l: T,
) -> (T, Vec3<T>, Vec3<T>) {
    let s = relative_rotation(qa, qb);
    let sv = s.imag();
    let delta = sv * (T::lit(2.0) / l) - rest;
    let f = k.component_mul(&delta);
    let energy = T::lit(0.5) * l * f.dot(&delta);
    let svxf = sv.cross(&f);
    let fw = f * s.w;
    (energy, fw + svxf, svxf - fw)
}

/// Bending/twisting energy of the clamp node at end `end` (0: first, 1: last; see
/// [`crate::rod::EndNode`]) and the body-frame torques on the rod's end frame and on the clamp
/// frame: `(energy, torque on the end frame, torque on the clamp frame)`.
#[inline(always)]
pub fn clamp_node<T: Real>(s: &RodState<T>, p: &RodParams<T>, end: usize) -> (T, Vec3<T>, Vec3<T>) {
    let frame = if end == 0 { 0 } else { s.elements() - 1 };
    clamp_node_of(
        &s.clamp_frames[end],
        &s.frames[frame],
        &p.end_nodes[end],
        p.end_node_length(end),
        end,
    )
}

/// [`clamp_node`] of the clamp frame `clamp` and the end frame `q` at end `end`, for a node
/// `node` of length `l`: `(energy, torque on the end frame, torque on the clamp frame)`. The
/// clamp is the node's lower frame at the first end and its upper frame at the last.
#[inline(always)]
pub fn clamp_node_of<T: Real>(
    clamp: &Quat<T>,
    q: &Quat<T>,
    node: &EndNode<T>,
    l: T,
    end: usize,
) -> (T, Vec3<T>, Vec3<T>) {
    if end == 0 {
        let (e, tc, tf) = bend_twist_node(clamp, q, &node.rest_darboux, &node.stiffness, l);
        (e, tf, tc)
    } else {
        bend_twist_node(q, clamp, &node.rest_darboux, &node.stiffness, l)
    }
}

/// Damping torque (body frame) on the rod's end frame `q` turning at body angular velocity `w`
/// relative to the clamp frame `clamp` turning at world angular velocity `clamp_omega`, over
/// the clamp node of length `l` with coefficient `c`: the interior nodes' dissipation
/// ([`bend_damping_node`]) with the clamp as the other frame.
#[inline(always)]
pub fn clamp_damping<T: Real>(
    q: &Quat<T>,
    w: &Vec3<T>,
    clamp: &Quat<T>,
    clamp_omega: &Vec3<T>,
    c: T,
    l: T,
) -> Vec3<T> {
    let body = rotate_inv(clamp, clamp_omega);
    bend_damping_node(clamp, q, &body, w, c, l).1
}

/// Parallel-constraint penalty of one element and its forces and torque.
///
/// Returns `(energy, force on r_{j+1}, body-frame torque on q_j)`; the force on `r_j` is the
/// negative of the one on `r_{j+1}`.
#[inline(always)]
pub fn parallel_element<T: Real>(
    ra: &Vec3<T>,
    rb: &Vec3<T>,
    q: &Quat<T>,
    kp: T,
    l0: T,
) -> (T, Vec3<T>, Vec3<T>) {
    let e = rb - ra;
    let len = e.norm();
    let t = e / len;
    let d = d3(q);
    let diff = t - d;
    let c = kp * l0;
    let energy = T::lit(0.5) * c * diff.norm_squared();
    let force_b = (d - t * t.dot(&d)) * (c / len);
    let tb = rotate_inv(q, &t);
    let torque = Vec3::new(-tb.y, tb.x, T::zero()) * c;
    (energy, force_b, torque)
}

/// Stretching energy of one element (extensible mode) and the force on `r_{j+1}` (the force on
/// `r_j` is its negative).
#[inline(always)]
pub fn stretch_element<T: Real>(ra: &Vec3<T>, rb: &Vec3<T>, ks: T, l0: T) -> (T, Vec3<T>) {
    let e = rb - ra;
    let len = e.norm();
    let strain = len / l0 - T::one();
    (
        T::lit(0.5) * ks * l0 * strain * strain,
        e * (-ks * strain / len),
    )
}

/// Dissipation force on `r_{j+1}` from the stretching rate of one element (its negative acts on
/// `r_j`). Only the component of the relative velocity along the element is resisted.
#[inline(always)]
pub fn stretch_damping_element<T: Real>(
    ra: &Vec3<T>,
    rb: &Vec3<T>,
    va: &Vec3<T>,
    vb: &Vec3<T>,
    c: T,
    l0: T,
) -> Vec3<T> {
    let e = rb - ra;
    let len2 = e.norm_squared();
    // Force −c ε̇ t with ε̇ = t·(v_b − v_a)/l0, written without a square root.
    e * (-c * e.dot(&(vb - va)) / (l0 * len2))
}

/// Dissipation torques from the relative angular velocity of two neighbouring frames.
///
/// `wa`, `wb` are body-frame angular velocities; returns the body-frame torques on `qa` and
/// `qb`. Equal world-frame angular velocities (a rigid rotation) give no torque.
#[inline(always)]
pub fn bend_damping_node<T: Real>(
    qa: &Quat<T>,
    qb: &Quat<T>,
    wa: &Vec3<T>,
    wb: &Vec3<T>,
    c: T,
    l: T,
) -> (Vec3<T>, Vec3<T>) {
    let rel = rotate(qb, wb) - rotate(qa, wa);
    let tw = rel * (c / l);
    (rotate_inv(qa, &tw), -rotate_inv(qb, &tw))
}

/// Which terms act on a rod, besides bending and the parallel penalty which always do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceModel<T: Real> {
    /// Extensible mode (the original CoRdE): stretching is an energy. Otherwise stretching is
    /// removed by distance constraints and contributes no force.
    pub extensible: bool,
    /// Gravitational acceleration [m/s²].
    pub gravity: Vec3<T>,
    /// Which ends are clamped (`[first, last]`): their clamp nodes act.
    pub clamped: [bool; 2],
}

/// Energies of one rod, split by term [J].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Energies {
    /// Bending and twisting.
    pub bend_twist: f64,
    /// Parallel-constraint penalty.
    pub parallel: f64,
    /// Stretching (zero unless extensible).
    pub stretch: f64,
    /// Gravitational potential relative to the origin.
    pub gravity: f64,
    /// Translational kinetic energy.
    pub kinetic_translation: f64,
    /// Rotational kinetic energy of the frames.
    pub kinetic_rotation: f64,
}

impl Energies {
    /// The energies of two rods together.
    #[must_use]
    pub fn sum(self, other: Self) -> Self {
        Self {
            bend_twist: self.bend_twist + other.bend_twist,
            parallel: self.parallel + other.parallel,
            stretch: self.stretch + other.stretch,
            gravity: self.gravity + other.gravity,
            kinetic_translation: self.kinetic_translation + other.kinetic_translation,
            kinetic_rotation: self.kinetic_rotation + other.kinetic_rotation,
        }
    }

    /// Elastic plus gravitational potential energy.
    pub fn potential(&self) -> f64 {
        self.bend_twist + self.parallel + self.stretch + self.gravity
    }
    /// Total kinetic energy.
    pub fn kinetic(&self) -> f64 {
        self.kinetic_translation + self.kinetic_rotation
    }
}

/// All energies of a rod, accumulated in `f64`.
pub fn energies<T: Real>(s: &RodState<T>, p: &RodParams<T>, model: &ForceModel<T>) -> Energies {
    let n = s.elements();
    let mut e = Energies::default();
    for j in 0..n.saturating_sub(1) {
        let (eb, _, _) = bend_twist_node(
            &s.frames[j],
            &s.frames[j + 1],
            &p.rest_darboux[j],
            &p.bend_twist_stiffness[j],
            p.node_length(j),
        );
        e.bend_twist += eb.to_f64();
    }
    for end in (0..2).filter(|&e| model.clamped[e]) {
        e.bend_twist += clamp_node(s, p, end).0.to_f64();
    }
    for j in 0..n {
        let (ra, rb) = (&s.positions[j], &s.positions[j + 1]);
        e.parallel += parallel_element(
            ra,
            rb,
            &s.frames[j],
            p.parallel_stiffness[j],
            p.rest_lengths[j],
        )
        .0
        .to_f64();
        if model.extensible {
            e.stretch += stretch_element(ra, rb, p.stretch_stiffness[j], p.rest_lengths[j])
                .0
                .to_f64();
        }
        let w = s.angular_velocities[j];
        e.kinetic_rotation += 0.5 * w.dot(&p.inertias[j].component_mul(&w)).to_f64();
    }
    for i in 0..=n {
        let m = p.masses[i].to_f64();
        e.gravity -= m * model.gravity.dot(&s.positions[i]).to_f64();
        e.kinetic_translation += 0.5 * m * s.velocities[i].norm_squared().to_f64();
    }
    e
}

/// Accumulates every force and torque on a rod into `forces` (one per point, world frame) and
/// `torques` (one per element, body frame). Both are overwritten.
///
/// This is the reference definition of the right-hand side of the equations of motion; the
/// backends either call it or are tested against it.
pub fn accumulate_forces<T: Real>(
    s: &RodState<T>,
    p: &RodParams<T>,
    model: &ForceModel<T>,
    forces: &mut [Vec3<T>],
    torques: &mut [Vec3<T>],
) {
    let n = s.elements();
    debug_assert_eq!(forces.len(), n + 1);
    debug_assert_eq!(torques.len(), n);
    for i in 0..=n {
        forces[i] = (model.gravity - s.velocities[i] * p.drag) * p.masses[i];
    }
    torques.fill(Vec3::zeros());
    for j in 0..n {
        let (ra, rb) = (&s.positions[j], &s.positions[j + 1]);
        let l0 = p.rest_lengths[j];
        let (_, mut fb, tq) = parallel_element(ra, rb, &s.frames[j], p.parallel_stiffness[j], l0);
        if model.extensible {
            fb += stretch_element(ra, rb, p.stretch_stiffness[j], l0).1;
            if p.stretch_damping[j] > T::zero() {
                fb += stretch_damping_element(
                    ra,
                    rb,
                    &s.velocities[j],
                    &s.velocities[j + 1],
                    p.stretch_damping[j],
                    l0,
                );
            }
        }
        forces[j] -= fb;
        forces[j + 1] += fb;
        // The gyroscopic term ω × Iω is part of Euler's equations, applied by the integrator.
        torques[j] += tq;
    }
    for j in 0..n.saturating_sub(1) {
        let (_, ta, tb) = bend_twist_node(
            &s.frames[j],
            &s.frames[j + 1],
            &p.rest_darboux[j],
            &p.bend_twist_stiffness[j],
            p.node_length(j),
        );
        torques[j] += ta;
        torques[j + 1] += tb;
    }
    for end in (0..2).filter(|&e| model.clamped[e]) {
        let frame = if end == 0 { 0 } else { n - 1 };
        torques[frame] += clamp_node(s, p, end).1;
    }
    // A rod without rotational damping pays nothing for it.
    if p.bend_damping.iter().any(|&c| c > T::zero()) {
        for j in 0..n.saturating_sub(1) {
            let (qa, qb) = (&s.frames[j], &s.frames[j + 1]);
            let (da, db) = bend_damping_node(
                qa,
                qb,
                &s.angular_velocities[j],
                &s.angular_velocities[j + 1],
                p.bend_damping[j],
                p.node_length(j),
            );
            torques[j] += da;
            torques[j + 1] += db;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Material;
    use crate::quat::rotate_body;
    use crate::rod::{RestShape, RodSpec, build_rod};
    use rand::{Rng, SeedableRng, rngs::StdRng};

    /// A random, curved and twisted rod with random rest shape and velocities.
    fn random_rod(seed: u64, n: usize) -> (RodState<f64>, RodParams<f64>) {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut pts = vec![[0.0; 3]];
        let mut dir = Vec3::new(1.0, 0.0, 0.0);
        for _ in 0..n {
            dir = (dir
                + Vec3::new(
                    rng.random_range(-0.4..0.4),
                    rng.random_range(-0.4..0.4),
                    rng.random_range(-0.4..0.4),
                ))
            .normalize();
            let l = rng.random_range(0.008..0.012);
            let last = Vec3::from(*pts.last().unwrap());
            pts.push((last + dir * l).into());
        }
        let mut spec = RodSpec::new(Material::new(
            rng.random_range(1e5..1e7),
            rng.random_range(1e5..1e7),
            1100.0,
            2e-3,
        ));
        spec.rest_shape = RestShape::Uniform([
            rng.random_range(-5.0..5.0),
            rng.random_range(-5.0..5.0),
            rng.random_range(-5.0..5.0),
        ]);
        spec.bend_damping = 1e-3;
        spec.stretch_damping = 0.5;
        let (mut s, mut p) = build_rod::<f64>(&pts, &spec).unwrap();
        // Perturb frames and positions off the adapted configuration and give them velocities.
        for q in s.frames.iter_mut() {
            *q = rotate_body(
                q,
                &Vec3::new(
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                ),
            );
        }
        for r in s.positions.iter_mut() {
            *r += Vec3::new(
                rng.random_range(-1e-3..1e-3),
                rng.random_range(-1e-3..1e-3),
                rng.random_range(-1e-3..1e-3),
            );
        }
        for v in s.velocities.iter_mut() {
            *v = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
        }
        for w in s.angular_velocities.iter_mut() {
            *w = Vec3::new(
                rng.random_range(-5.0..5.0),
                rng.random_range(-5.0..5.0),
                rng.random_range(-5.0..5.0),
            );
        }
        // Clamps turned away from their rest against the end frames.
        let n = s.elements();
        for (end, frame) in [(0, 0), (1, n - 1)] {
            let turn = Vec3::new(
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
            );
            s.clamp_frames[end] = rotate_body(&s.frames[frame], &turn);
            p.end_nodes[end].rest_darboux = Vec3::new(rng.random_range(-3.0..3.0), 1.0, -2.0);
        }
        (s, p)
    }

    fn model(extensible: bool) -> ForceModel<f64> {
        ForceModel {
            extensible,
            gravity: Vec3::new(0.3, -9.81, 0.1),
            clamped: [true, true],
        }
    }

    fn potential(s: &RodState<f64>, p: &RodParams<f64>, m: &ForceModel<f64>) -> f64 {
        energies(s, p, m).potential()
    }

    /// Conservative forces and torques equal minus the central finite-difference gradient of the
    /// potential energy, for every point coordinate and every frame's body rotation.
    #[test]
    fn forces_and_torques_are_exact_energy_gradients() {
        for seed in 0..4 {
            for extensible in [false, true] {
                let (mut s, mut p) = random_rod(seed, 12);
                // Remove dissipation and velocities so only conservative terms remain.
                p.drag = 0.0;
                s.velocities.iter_mut().for_each(|v| *v = Vec3::zeros());
                s.angular_velocities
                    .iter_mut()
                    .for_each(|w| *w = Vec3::zeros());
                let m = model(extensible);
                let n = s.elements();
                let (mut f, mut t) = (vec![Vec3::zeros(); n + 1], vec![Vec3::zeros(); n]);
                accumulate_forces(&s, &p, &m, &mut f, &mut t);
                let h = 1e-6;
                let scale = f
                    .iter()
                    .chain(t.iter())
                    .map(|x| x.norm())
                    .fold(0.0, f64::max);
                for i in 0..=n {
                    for c in 0..3 {
                        let (mut sp, mut sm) = (s.clone(), s.clone());
                        sp.positions[i][c] += h;
                        sm.positions[i][c] -= h;
                        let g = (potential(&sp, &p, &m) - potential(&sm, &p, &m)) / (2.0 * h);
                        assert!(
                            (f[i][c] + g).abs() < 1e-6 * scale,
                            "seed {seed} point {i}.{c}: force {} vs -dE {}",
                            f[i][c],
                            -g
                        );
                    }
                }
                for j in 0..n {
                    for c in 0..3 {
                        let mut th = Vec3::zeros();
                        th[c] = h;
                        let (mut sp, mut sm) = (s.clone(), s.clone());
                        sp.frames[j] = rotate_body(&s.frames[j], &th);
                        sm.frames[j] = rotate_body(&s.frames[j], &(-th));
                        let g = (potential(&sp, &p, &m) - potential(&sm, &p, &m)) / (2.0 * h);
                        assert!(
                            (t[j][c] + g).abs() < 1e-6 * scale,
                            "seed {seed} frame {j}.{c}: torque {} vs -dE {}",
                            t[j][c],
                            -g
                        );
                    }
                }
            }
        }
    }

    /// Rayleigh dissipation `D = Σ ½ c |Δω|²/l + ½ c_s (t·Δv)²/l0 + ½ drag m v²`: the damping
    /// forces are `−∂D/∂v` and the damping torques `−∂D/∂ω`.
    #[test]
    fn damping_is_the_gradient_of_a_dissipation_function() {
        let (s, p) = random_rod(7, 9);
        let n = s.elements();
        let dissipation = |s: &RodState<f64>| {
            let mut d = 0.0;
            for j in 0..n - 1 {
                let rel = rotate(&s.frames[j + 1], &s.angular_velocities[j + 1])
                    - rotate(&s.frames[j], &s.angular_velocities[j]);
                d += 0.5 * p.bend_damping[j] * rel.norm_squared() / p.node_length(j);
            }
            for j in 0..n {
                let e = s.positions[j + 1] - s.positions[j];
                let rate =
                    e.normalize().dot(&(s.velocities[j + 1] - s.velocities[j])) / p.rest_lengths[j];
                d += 0.5 * p.stretch_damping[j] * p.rest_lengths[j] * rate * rate;
            }
            for i in 0..=n {
                d += 0.5 * p.drag * p.masses[i] * s.velocities[i].norm_squared();
            }
            d
        };
        let m = model(true);
        let (mut f0, mut t0) = (vec![Vec3::zeros(); n + 1], vec![Vec3::zeros(); n]);
        let (mut f, mut t) = (f0.clone(), t0.clone());
        let mut rest = s.clone();
        rest.velocities.iter_mut().for_each(|v| *v = Vec3::zeros());
        rest.angular_velocities
            .iter_mut()
            .for_each(|w| *w = Vec3::zeros());
        accumulate_forces(&rest, &p, &m, &mut f0, &mut t0);
        accumulate_forces(&s, &p, &m, &mut f, &mut t);
        let h = 1e-6;
        for i in 0..=n {
            for c in 0..3 {
                let (mut sp, mut sm) = (s.clone(), s.clone());
                sp.velocities[i][c] += h;
                sm.velocities[i][c] -= h;
                let g = (dissipation(&sp) - dissipation(&sm)) / (2.0 * h);
                assert!(
                    (f[i][c] - f0[i][c] + g).abs() < 1e-6 * (1.0 + g.abs()),
                    "point {i}.{c}"
                );
            }
        }
        for j in 0..n {
            for c in 0..3 {
                let (mut sp, mut sm) = (s.clone(), s.clone());
                sp.angular_velocities[j][c] += h;
                sm.angular_velocities[j][c] -= h;
                let g = (dissipation(&sp) - dissipation(&sm)) / (2.0 * h);
                assert!(
                    (t[j][c] - t0[j][c] + g).abs() < 1e-6 * (1.0 + g.abs()),
                    "frame {j}.{c}"
                );
            }
        }
    }

    /// Elastic energies do not change under a rigid rotation and translation of the whole rod,
    /// and the elastic forces and torques sum to zero net force and net moment.
    #[test]
    fn energies_are_invariant_under_rigid_motions() {
        let (s, p) = random_rod(3, 15);
        let m = ForceModel {
            extensible: true,
            gravity: Vec3::zeros(),
            clamped: [true, true],
        };
        let e0 = energies(&s, &p, &m);
        let rot = crate::quat::exp_rotation(&Vec3::new(0.7, -1.3, 2.1));
        let shift = Vec3::new(3.0, -1.0, 0.5);
        let mut moved = s.clone();
        for r in moved.positions.iter_mut() {
            *r = rotate(&rot, r) + shift;
        }
        for q in moved.frames.iter_mut().chain(moved.clamp_frames.iter_mut()) {
            *q = rot * *q;
        }
        let e1 = energies(&moved, &p, &m);
        for (a, b) in [
            (e0.bend_twist, e1.bend_twist),
            (e0.parallel, e1.parallel),
            (e0.stretch, e1.stretch),
        ] {
            assert!((a - b).abs() <= 1e-10 * a.abs().max(1e-12), "{a} vs {b}");
        }
        let mut rest = s.clone();
        rest.velocities.iter_mut().for_each(|v| *v = Vec3::zeros());
        rest.angular_velocities
            .iter_mut()
            .for_each(|w| *w = Vec3::zeros());
        let mut p0 = p.clone();
        p0.drag = 0.0;
        let n = s.elements();
        let (mut f, mut t) = (vec![Vec3::zeros(); n + 1], vec![Vec3::zeros(); n]);
        accumulate_forces(&rest, &p0, &m, &mut f, &mut t);
        let net: Vec3<f64> = f.iter().sum();
        let mut moment: Vec3<f64> = rest.positions.iter().zip(&f).map(|(r, f)| r.cross(f)).sum();
        for j in 0..n {
            moment += rotate(&rest.frames[j], &t[j]);
        }
        // The clamps take the opposite of what their nodes give the rod.
        for end in 0..2 {
            moment += rotate(&rest.clamp_frames[end], &clamp_node(&rest, &p0, end).2);
        }
        let scale = f.iter().map(|x| x.norm()).fold(0.0, f64::max);
        assert!(net.norm() < 1e-9 * scale);
        assert!(moment.norm() < 1e-9 * scale);
    }
}
