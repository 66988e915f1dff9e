//! A vectorisable red–black distance solver.
//!
//! Red constraints (even elements) share no point, nor do black ones (odd elements). Storing the
//! velocities of even and odd points in separate structure-of-arrays buffers makes every
//! half-sweep a loop over contiguous slices with no dependency between iterations, which the
//! compiler turns into SIMD code: constraint `2k` couples even point `k` with odd point `k`,
//! constraint `2k + 1` couples odd point `k` with even point `k + 1`.
//!
//! The arithmetic is the impulse of [`crate::distance`] (same constraint, same predicted
//! positions), with one refinement for single precision: the element vector at the end of the
//! step is formed as `(r_b − r_a) + h (v_b − v_a)` from element vectors computed once per step,
//! rather than as the difference of two predicted absolute positions, which in `f32` would lose
//! most of the digits of a millimetre element a metre away from the origin.

use crate::contact::{ContactSet, Friction};
use crate::velocities::{KinematicImpulses, PointVelocities, record_kinematic};
use cosserat_model::{Real, Vec3};

/// Structure-of-arrays scratch for one rod, sized once and reused every step.
#[derive(Clone, Debug, Default)]
pub struct RedBlackSolver<T: Real> {
    /// Velocities of even points `[x, y, z]`.
    even_v: [Vec<T>; 3],
    /// Velocities of odd points.
    odd_v: [Vec<T>; 3],
    /// Element vectors at step start, red elements then black, per coordinate.
    red_e: [Vec<T>; 3],
    black_e: [Vec<T>; 3],
    /// Inverse masses of even and odd points.
    even_w: Vec<T>,
    odd_w: Vec<T>,
    /// Per constraint: rest length, and `1 / (w_a + w_b)` (zero when both are kinematic).
    red_l0: Vec<T>,
    red_inv_w: Vec<T>,
    black_l0: Vec<T>,
    black_inv_w: Vec<T>,
    /// Whether the impulses of the first / last distance constraint are measured (a held end
    /// whose reaction is reported).
    track: [bool; 2],
    /// Sum of the velocity changes the first / last constraint gave its free point.
    end_dv: [Vec3<T>; 2],
}

impl<T: Real> RedBlackSolver<T> {
    /// Prepares the solver for a rod with these inverse masses and rest lengths.
    pub fn new(inv_masses: &[T], rest_lengths: &[T]) -> Self {
        let n = rest_lengths.len();
        assert_eq!(inv_masses.len(), n + 1, "one inverse mass per point");
        let even_w: Vec<T> = inv_masses.iter().copied().step_by(2).collect();
        let odd_w: Vec<T> = inv_masses.iter().copied().skip(1).step_by(2).collect();
        let inv = |a: T, b: T| {
            if a + b > T::zero() {
                T::one() / (a + b)
            } else {
                T::zero()
            }
        };
        let red_l0: Vec<T> = rest_lengths.iter().copied().step_by(2).collect();
        let black_l0: Vec<T> = rest_lengths.iter().copied().skip(1).step_by(2).collect();
        let red_inv_w = (0..red_l0.len())
            .map(|k| inv(even_w[k], odd_w[k]))
            .collect();
        let black_inv_w = (0..black_l0.len())
            .map(|k| inv(odd_w[k], even_w[k + 1]))
            .collect();
        let z = |len: usize| {
            [
                vec![T::zero(); len],
                vec![T::zero(); len],
                vec![T::zero(); len],
            ]
        };
        Self {
            even_v: z(even_w.len()),
            odd_v: z(odd_w.len()),
            red_e: z(red_l0.len()),
            black_e: z(black_l0.len()),
            even_w,
            odd_w,
            red_l0,
            red_inv_w,
            black_l0,
            black_inv_w,
            track: [false; 2],
            end_dv: [Vec3::zeros(); 2],
        }
    }

    /// Measures the impulses of the first (`first`) and last (`last`) distance constraint, which
    /// are what a held end point delivers to the rod (see [`Self::take_end_impulses`]).
    pub fn track_ends(&mut self, first: bool, last: bool) {
        self.track = [first, last];
    }

    /// The impulses [N s] the first and the last distance constraint delivered to their
    /// *other* point (point 1 and point `n − 1`) since the last call, and resets them. The
    /// held end point received the opposite impulse. Zero for an end that is not tracked.
    pub fn take_end_impulses(&mut self) -> [Vec3<T>; 2] {
        let n = self.red_l0.len() + self.black_l0.len();
        let (first, last) = (
            self.point_slot(1.min(n)),
            self.point_slot(n.saturating_sub(1)),
        );
        let mass = |(odd, k): (bool, usize)| {
            let w = if odd { self.odd_w[k] } else { self.even_w[k] };
            if w > T::zero() {
                T::one() / w
            } else {
                T::zero()
            }
        };
        let out = [self.end_dv[0] * mass(first), self.end_dv[1] * mass(last)];
        self.end_dv = [Vec3::zeros(); 2];
        out
    }

    /// (is odd, index in its buffer) of point `i`.
    #[inline]
    fn point_slot(&self, i: usize) -> (bool, usize) {
        (!i.is_multiple_of(2), i / 2)
    }

    #[inline]
    fn split_velocity(&self, (odd, k): (bool, usize)) -> Vec3<T> {
        let b = if odd { &self.odd_v } else { &self.even_v };
        Vec3::new(b[0][k], b[1][k], b[2][k])
    }

    /// Loads the velocities (`[x, y, z]`) and the element vectors of the step into the solver's
    /// layout; the first half of [`Self::solve_soa_with_contacts`], for callers that interleave
    /// their own sweeps ([`Self::sweep`], [`Self::sweep_contacts`], coupling constraints through
    /// [`Self::velocities`]) before [`Self::finish_soa`].
    pub fn begin_soa(&mut self, positions: [&[T]; 3], velocities: [&[T]; 3]) {
        let n = self.red_l0.len() + self.black_l0.len();
        for c in 0..3 {
            let (r, v) = (&positions[c][..n + 1], &velocities[c][..n + 1]);
            for (k, x) in v.iter().step_by(2).enumerate() {
                self.even_v[c][k] = *x;
            }
            for (k, x) in v.iter().skip(1).step_by(2).enumerate() {
                self.odd_v[c][k] = *x;
            }
            for k in 0..self.red_l0.len() {
                self.red_e[c][k] = r[2 * k + 1] - r[2 * k];
            }
            for k in 0..self.black_l0.len() {
                self.black_e[c][k] = r[2 * k + 2] - r[2 * k + 1];
            }
        }
    }

    /// One red–black sweep of the distance constraints.
    pub fn sweep(&mut self, h: T) {
        self.sweeps(h, 1);
    }

    /// One sweep over point contacts, on the solver's velocities.
    pub fn sweep_contacts(&mut self, set: &mut ContactSet<T>, friction: &Friction<T>, h: T) {
        set.sweep_split(
            h,
            friction,
            &self.even_w,
            &self.odd_w,
            &mut self.even_v,
            &mut self.odd_v,
        );
    }

    /// Writes the solver's velocities back (`[x, y, z]`); the end of [`Self::begin_soa`].
    pub fn finish_soa(&self, velocities: [&mut [T]; 3]) {
        for (c, v) in velocities.into_iter().enumerate() {
            for (k, x) in v.iter_mut().step_by(2).enumerate() {
                *x = self.even_v[c][k];
            }
            for (k, x) in v.iter_mut().skip(1).step_by(2).enumerate() {
                *x = self.odd_v[c][k];
            }
        }
    }

    /// The solver's velocities as [`PointVelocities`], for coupling constraints between
    /// [`Self::begin_soa`] and [`Self::finish_soa`]. Impulses on kinematic end points go to
    /// `held`.
    pub fn velocities<'a>(
        &'a mut self,
        held: &'a mut KinematicImpulses<T>,
    ) -> SplitVelocities<'a, T> {
        let last = self.red_l0.len() + self.black_l0.len();
        SplitVelocities {
            even: &mut self.even_v,
            odd: &mut self.odd_v,
            even_w: &self.even_w,
            odd_w: &self.odd_w,
            last,
            held,
        }
    }

    /// Runs `iterations` red–black sweeps on `velocities` (updated in place).
    pub fn solve(
        &mut self,
        positions: &[Vec3<T>],
        velocities: &mut [Vec3<T>],
        h: T,
        iterations: usize,
    ) {
        if iterations == 0 {
            return;
        }
        let n = self.red_l0.len() + self.black_l0.len();
        assert_eq!(positions.len(), n + 1);
        assert_eq!(velocities.len(), n + 1);
        for (i, v) in velocities.iter().enumerate() {
            let (buf, k) = if i.is_multiple_of(2) {
                (&mut self.even_v, i / 2)
            } else {
                (&mut self.odd_v, i / 2)
            };
            buf[0][k] = v.x;
            buf[1][k] = v.y;
            buf[2][k] = v.z;
        }
        for j in 0..n {
            let e = positions[j + 1] - positions[j];
            let (buf, k) = if j.is_multiple_of(2) {
                (&mut self.red_e, j / 2)
            } else {
                (&mut self.black_e, j / 2)
            };
            buf[0][k] = e.x;
            buf[1][k] = e.y;
            buf[2][k] = e.z;
        }
        self.sweeps(h, iterations);
        for (i, v) in velocities.iter_mut().enumerate() {
            let (buf, k) = if i.is_multiple_of(2) {
                (&self.even_v, i / 2)
            } else {
                (&self.odd_v, i / 2)
            };
            *v = Vec3::new(buf[0][k], buf[1][k], buf[2][k]);
        }
    }

    /// [`Self::solve`] on coordinate slices (`[x, y, z]`) instead of vectors.
    pub fn solve_soa(
        &mut self,
        positions: [&[T]; 3],
        velocities: [&mut [T]; 3],
        h: T,
        iterations: usize,
    ) {
        self.solve_soa_with_contacts(positions, velocities, h, iterations, None);
    }

    /// [`Self::solve_soa`] with a sweep over `contacts` after each distance sweep, as in the
    /// constraint loop of the paper's Fig. 5.
    pub fn solve_soa_with_contacts(
        &mut self,
        positions: [&[T]; 3],
        velocities: [&mut [T]; 3],
        h: T,
        iterations: usize,
        mut contacts: Option<(&mut ContactSet<T>, &Friction<T>)>,
    ) {
        if iterations == 0 {
            return;
        }
        let [vx, vy, vz] = velocities;
        self.begin_soa(positions, [&*vx, &*vy, &*vz]);
        for _ in 0..iterations {
            self.sweeps(h, 1);
            if let Some((set, friction)) = contacts.as_mut() {
                self.sweep_contacts(set, friction, h);
            }
        }
        self.finish_soa([vx, vy, vz]);
    }

    fn sweeps(&mut self, h: T, iterations: usize) {
        let nr = self.red_l0.len();
        let nb = self.black_l0.len();
        let n = nr + nb;
        // The free neighbour of each held end, and whether its end constraint is red.
        let tracked = self.track[0] || self.track[1];
        let first = self.point_slot(1.min(n));
        let last = self.point_slot(n.saturating_sub(1));
        let last_red = (n.saturating_sub(1)).is_multiple_of(2);
        for _ in 0..iterations {
            let before = if tracked {
                [self.split_velocity(first), self.split_velocity(last)]
            } else {
                [Vec3::zeros(); 2]
            };
            {
                // Red: even point k (a) with odd point k (b).
                let [ex, ey, ez] = &mut self.even_v;
                let [ox, oy, oz] = &mut self.odd_v;
                half_sweep(
                    [&mut ex[..nr], &mut ey[..nr], &mut ez[..nr]],
                    [&mut ox[..nr], &mut oy[..nr], &mut oz[..nr]],
                    &self.even_w[..nr],
                    &self.odd_w[..nr],
                    [&self.red_e[0], &self.red_e[1], &self.red_e[2]],
                    &self.red_l0,
                    &self.red_inv_w,
                    h,
                );
            }
            if tracked {
                if self.track[0] {
                    self.end_dv[0] += self.split_velocity(first) - before[0];
                }
                if self.track[1] && last_red {
                    self.end_dv[1] += self.split_velocity(last) - before[1];
                }
            }
            let before_black = if tracked && self.track[1] && !last_red {
                self.split_velocity(last)
            } else {
                Vec3::zeros()
            };
            {
                // Black: odd point k (a) with even point k + 1 (b).
                let [ex, ey, ez] = &mut self.even_v;
                let [ox, oy, oz] = &mut self.odd_v;
                half_sweep(
                    [&mut ox[..nb], &mut oy[..nb], &mut oz[..nb]],
                    [&mut ex[1..nb + 1], &mut ey[1..nb + 1], &mut ez[1..nb + 1]],
                    &self.odd_w[..nb],
                    &self.even_w[1..nb + 1],
                    [&self.black_e[0], &self.black_e[1], &self.black_e[2]],
                    &self.black_l0,
                    &self.black_inv_w,
                    h,
                );
            }
            if tracked && self.track[1] && !last_red {
                self.end_dv[1] += self.split_velocity(last) - before_black;
            }
        }
    }
}

/// The velocities of a [`RedBlackSolver`] as [`PointVelocities`] (point `i` is entry `i / 2` of
/// the even or odd buffer).
pub struct SplitVelocities<'a, T: Real> {
    even: &'a mut [Vec<T>; 3],
    odd: &'a mut [Vec<T>; 3],
    even_w: &'a [T],
    odd_w: &'a [T],
    last: usize,
    held: &'a mut KinematicImpulses<T>,
}

impl<T: Real> PointVelocities<T> for SplitVelocities<'_, T> {
    #[inline(always)]
    fn velocity(&self, i: usize) -> Vec3<T> {
        let (b, k) = if i.is_multiple_of(2) {
            (&*self.even, i / 2)
        } else {
            (&*self.odd, i / 2)
        };
        Vec3::new(b[0][k], b[1][k], b[2][k])
    }
    #[inline(always)]
    fn inv_mass(&self, i: usize) -> T {
        if i.is_multiple_of(2) {
            self.even_w[i / 2]
        } else {
            self.odd_w[i / 2]
        }
    }
    #[inline(always)]
    fn apply_impulse(&mut self, i: usize, j: Vec3<T>) {
        let (b, w, k) = if i.is_multiple_of(2) {
            (&mut *self.even, self.even_w, i / 2)
        } else {
            (&mut *self.odd, self.odd_w, i / 2)
        };
        let w = w[k];
        if w > T::zero() {
            b[0][k] += j.x * w;
            b[1][k] += j.y * w;
            b[2][k] += j.z * w;
        } else {
            record_kinematic(self.held, self.last, i, j);
        }
    }
}

/// One colour: constraint `k` couples point `a[k]` with point `b[k]`; no two share a point.
#[inline(always)]
fn half_sweep<T: Real>(
    a: [&mut [T]; 3],
    b: [&mut [T]; 3],
    wa: &[T],
    wb: &[T],
    e: [&[T]; 3],
    l0: &[T],
    inv_w: &[T],
    h: T,
) {
    let [ax, ay, az] = a;
    let [bx, by, bz] = b;
    let m = l0.len();
    let (ax, ay, az, bx, by, bz) = (
        &mut ax[..m],
        &mut ay[..m],
        &mut az[..m],
        &mut bx[..m],
        &mut by[..m],
        &mut bz[..m],
    );
    let (wa, wb, inv_w) = (&wa[..m], &wb[..m], &inv_w[..m]);
    let (ex, ey, ez) = (&e[0][..m], &e[1][..m], &e[2][..m]);
    let inv_h = T::one() / h;
    for k in 0..m {
        let dx = ex[k] + h * (bx[k] - ax[k]);
        let dy = ey[k] + h * (by[k] - ay[k]);
        let dz = ez[k] + h * (bz[k] - az[k]);
        let len = (dx * dx + dy * dy + dz * dz).sqrt();
        // Velocity impulse per unit of d: (l0 − |d|) / (h (w_a + w_b) |d|).
        let s = (l0[k] - len) * inv_w[k] * inv_h / len;
        let (sa, sb) = (s * wa[k], s * wb[k]);
        ax[k] -= dx * sa;
        ay[k] -= dy * sa;
        az[k] -= dz * sa;
        bx[k] += dx * sb;
        by[k] += dy * sb;
        bz[k] += dz * sb;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distance::{Ordering, solve_distance_iteration};

    /// The SoA solver performs exactly the red–black sweeps of the reference solver (up to the
    /// rounding of how the predicted element vector is formed).
    #[test]
    fn matches_the_reference_red_black_sweeps() {
        for n in [1, 2, 7, 64, 65] {
            let pos: Vec<Vec3<f64>> = (0..=n)
                .map(|i| Vec3::new(i as f64 * 0.01, 0.003 * (i as f64).sin(), 0.0))
                .collect();
            let vel: Vec<Vec3<f64>> = (0..=n)
                .map(|i| Vec3::new((i as f64 * 0.7).cos(), (i as f64 * 1.3).sin(), 0.3))
                .collect();
            let mut inv: Vec<f64> = (0..=n).map(|i| 1.0 / (1.0 + 0.1 * i as f64)).collect();
            inv[0] = 0.0;
            let l0 = vec![0.01; n];
            let h = 1e-3;
            let mut reference = vel.clone();
            for _ in 0..7 {
                solve_distance_iteration(&pos, &mut reference, &inv, &l0, h, Ordering::RedBlack);
            }
            let mut fast = vel.clone();
            RedBlackSolver::new(&inv, &l0).solve(&pos, &mut fast, h, 7);
            for (a, b) in reference.iter().zip(&fast) {
                assert!((a - b).norm() < 1e-9, "n = {n}: {a:?} vs {b:?}");
            }
            assert_eq!(fast[0], vel[0], "a kinematic point is not moved");
        }
    }
}
