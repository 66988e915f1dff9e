//! The CPU backend's working layout: structure-of-arrays, one slice per coordinate.
//!
//! The model's [`RodState`] stores vectors and quaternions as arrays of structs, which is the
//! natural shape for the API, for the GPU upload and for the reference implementation of the
//! energies. Loops over arrays of structs do not vectorise, though, and one CoRdE step is a few
//! hundred flops per element, so the CPU backend copies a rod into the layout below once per
//! batch of steps, runs every phase as a loop over contiguous slices with no dependency between
//! iterations (which the compiler turns into AVX2 code), and copies back. The arithmetic is the
//! same as `cosserat_model::energy::accumulate_forces` and `cosserat_constraints::distance`; the tests
//! in `stepper.rs` hold the two to agreement.

use cosserat_model::{Quat, Real, RodParams, RodState, Vec3};

/// Three coordinate slices of a vector field.
#[derive(Clone, Debug, Default)]
pub(crate) struct V3<T> {
    pub(crate) x: Vec<T>,
    pub(crate) y: Vec<T>,
    pub(crate) z: Vec<T>,
}

impl<T: Real> V3<T> {
    pub(crate) fn zeros(n: usize) -> Self {
        Self {
            x: vec![T::zero(); n],
            y: vec![T::zero(); n],
            z: vec![T::zero(); n],
        }
    }
    pub(crate) fn gather(&mut self, src: &[Vec3<T>]) {
        for (i, v) in src.iter().enumerate() {
            self.x[i] = v.x;
            self.y[i] = v.y;
            self.z[i] = v.z;
        }
    }
    pub(crate) fn scatter(&self, dst: &mut [Vec3<T>]) {
        for (i, v) in dst.iter_mut().enumerate() {
            *v = Vec3::new(self.x[i], self.y[i], self.z[i]);
        }
    }
    pub(crate) fn get(&self, i: usize) -> Vec3<T> {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }
    pub(crate) fn set(&mut self, i: usize, v: Vec3<T>) {
        self.x[i] = v.x;
        self.y[i] = v.y;
        self.z[i] = v.z;
    }
}

/// Constant per-rod data in the working layout, derived once from [`RodParams`].
#[derive(Clone, Debug)]
pub(crate) struct SoaParams<T> {
    pub(crate) rest_lengths: Vec<T>,
    /// `K_p l0` per element.
    pub(crate) parallel: Vec<T>,
    /// `K_s` per element.
    pub(crate) stretch: Vec<T>,
    /// `2 / l̄` per node.
    pub(crate) two_over_l: Vec<T>,
    /// `(K1, K2, K3)` per node.
    pub(crate) bend: V3<T>,
    /// Rest Darboux vector per node.
    pub(crate) rest_u: V3<T>,
    pub(crate) masses: Vec<T>,
    pub(crate) inv_masses: Vec<T>,
    pub(crate) inertia: V3<T>,
    pub(crate) inv_inertia: V3<T>,
}

impl<T: Real> SoaParams<T> {
    pub(crate) fn new(p: &RodParams<T>) -> Self {
        let n = p.elements();
        let from = |v: &[Vec3<T>]| {
            let mut s = V3::zeros(v.len());
            s.gather(v);
            s
        };
        let inv_inertia: Vec<Vec3<T>> =
            p.inertias.iter().map(|i| i.map(|x| T::one() / x)).collect();
        Self {
            rest_lengths: p.rest_lengths.clone(),
            parallel: (0..n)
                .map(|j| p.parallel_stiffness[j] * p.rest_lengths[j])
                .collect(),
            stretch: p.stretch_stiffness.clone(),
            two_over_l: (0..n.saturating_sub(1))
                .map(|j| T::lit(2.0) / p.node_length(j))
                .collect(),
            bend: from(&p.bend_twist_stiffness),
            rest_u: from(&p.rest_darboux),
            masses: p.masses.clone(),
            inv_masses: p.inv_masses.clone(),
            inertia: from(&p.inertias),
            inv_inertia: from(&inv_inertia),
        }
    }
}

/// A rod's state and scratch in the working layout.
#[derive(Clone, Debug)]
pub(crate) struct SoaState<T> {
    pub(crate) r: V3<T>,
    pub(crate) v: V3<T>,
    pub(crate) q: [Vec<T>; 4],
    pub(crate) w: V3<T>,
    /// Forces on points.
    pub(crate) f: V3<T>,
    /// Body torques on frames.
    pub(crate) tq: V3<T>,
    /// Force of each element on its end point.
    pub(crate) fe: V3<T>,
    /// Bending torques of each node on its lower and upper frame.
    pub(crate) ta: V3<T>,
    pub(crate) tb: V3<T>,
    /// Squared length ratios of the elements after the last step.
    pub(crate) ratio2: Vec<T>,
}

impl<T: Real> SoaState<T> {
    pub(crate) fn new(n: usize) -> Self {
        let nodes = n.saturating_sub(1);
        Self {
            r: V3::zeros(n + 1),
            v: V3::zeros(n + 1),
            q: [
                vec![T::zero(); n],
                vec![T::zero(); n],
                vec![T::zero(); n],
                vec![T::zero(); n],
            ],
            w: V3::zeros(n),
            f: V3::zeros(n + 1),
            tq: V3::zeros(n),
            fe: V3::zeros(n),
            ta: V3::zeros(nodes),
            tb: V3::zeros(nodes),
            ratio2: vec![T::zero(); n],
        }
    }

    pub(crate) fn gather(&mut self, s: &RodState<T>) {
        self.r.gather(&s.positions);
        self.v.gather(&s.velocities);
        self.w.gather(&s.angular_velocities);
        for (j, q) in s.frames.iter().enumerate() {
            self.q[0][j] = q.i;
            self.q[1][j] = q.j;
            self.q[2][j] = q.k;
            self.q[3][j] = q.w;
        }
    }

    pub(crate) fn scatter(&self, s: &mut RodState<T>) {
        self.r.scatter(&mut s.positions);
        self.v.scatter(&mut s.velocities);
        self.w.scatter(&mut s.angular_velocities);
        for (j, q) in s.frames.iter_mut().enumerate() {
            *q = Quat::new(self.q[3][j], self.q[0][j], self.q[1][j], self.q[2][j]);
        }
    }

    pub(crate) fn frame(&self, j: usize) -> Quat<T> {
        Quat::new(self.q[3][j], self.q[0][j], self.q[1][j], self.q[2][j])
    }
}

/// Elastic forces and torques of the parallel penalty, stretching (when `extensible`) and
/// bending/twisting, plus gravity and drag. Overwrites `s.f` and `s.tq`.
///
/// Kept out of line: inlined into the stepper, LLVM has compiled its loops without
/// vectorising them (the explicit step 15–25 % slower in `benches/stiff.rs`).
#[inline(never)]
pub(crate) fn elastic_forces<T: Real>(
    s: &mut SoaState<T>,
    p: &SoaParams<T>,
    gravity: Vec3<T>,
    drag: T,
    extensible: bool,
) {
    let n = p.rest_lengths.len();
    let (one, two, zero) = (T::one(), T::lit(2.0), T::zero());
    {
        let (rx0, rx1) = (&s.r.x[..n], &s.r.x[1..n + 1]);
        let (ry0, ry1) = (&s.r.y[..n], &s.r.y[1..n + 1]);
        let (rz0, rz1) = (&s.r.z[..n], &s.r.z[1..n + 1]);
        let [qx, qy, qz, qw] = &s.q;
        let (qx, qy, qz, qw) = (&qx[..n], &qy[..n], &qz[..n], &qw[..n]);
        let (kp, ks, l0) = (&p.parallel[..n], &p.stretch[..n], &p.rest_lengths[..n]);
        let (fex, fey, fez) = (&mut s.fe.x[..n], &mut s.fe.y[..n], &mut s.fe.z[..n]);
        let (tx, ty, tz) = (&mut s.tq.x[..n], &mut s.tq.y[..n], &mut s.tq.z[..n]);
        let stretch_on = if extensible { one } else { zero };
        for j in 0..n {
            let (ex, ey, ez) = (rx1[j] - rx0[j], ry1[j] - ry0[j], rz1[j] - rz0[j]);
            let len = (ex * ex + ey * ey + ez * ez).sqrt();
            let inv_len = one / len;
            let (t0, t1, t2) = (ex * inv_len, ey * inv_len, ez * inv_len);
            let (x, y, z, w) = (qx[j], qy[j], qz[j], qw[j]);
            // Directors d1, d2, d3 of the frame.
            // Directors in the homogeneous form (`cosserat_model::quat::directors` says why).
            let (ww, xx, yy, zz) = (w * w, x * x, y * y, z * z);
            let d1 = (
                ww + xx - yy - zz,
                two * (x * y + w * z),
                two * (x * z - w * y),
            );
            let d2 = (
                two * (x * y - w * z),
                ww - xx + yy - zz,
                two * (y * z + w * x),
            );
            let d3 = (
                two * (x * z + w * y),
                two * (y * z - w * x),
                ww - xx - yy + zz,
            );
            let t_d3 = t0 * d3.0 + t1 * d3.1 + t2 * d3.2;
            let c = kp[j];
            let g = c * inv_len;
            let strain = (len / l0[j] - one) * ks[j] * stretch_on;
            fex[j] = (d3.0 - t0 * t_d3) * g - t0 * strain;
            fey[j] = (d3.1 - t1 * t_d3) * g - t1 * strain;
            fez[j] = (d3.2 - t2 * t_d3) * g - t2 * strain;
            // Torque c (e3 × Rᵀt) in the body frame, with Rᵀt = (d1·t, d2·t, d3·t).
            tx[j] = -c * (d2.0 * t0 + d2.1 * t1 + d2.2 * t2);
            ty[j] = c * (d1.0 * t0 + d1.1 * t1 + d1.2 * t2);
            tz[j] = zero;
        }
    }
    let m = n.saturating_sub(1);
    {
        let [qx, qy, qz, qw] = &s.q;
        let (ax, ay, az, aw) = (&qx[..m], &qy[..m], &qz[..m], &qw[..m]);
        let (bx, by, bz, bw) = (&qx[1..m + 1], &qy[1..m + 1], &qz[1..m + 1], &qw[1..m + 1]);
        let (k1, k2, k3) = (&p.bend.x[..m], &p.bend.y[..m], &p.bend.z[..m]);
        let (u1, u2, u3) = (&p.rest_u.x[..m], &p.rest_u.y[..m], &p.rest_u.z[..m]);
        let tl = &p.two_over_l[..m];
        let (tax, tay, taz) = (&mut s.ta.x[..m], &mut s.ta.y[..m], &mut s.ta.z[..m]);
        let (tbx, tby, tbz) = (&mut s.tb.x[..m], &mut s.tb.y[..m], &mut s.tb.z[..m]);
        for j in 0..m {
            // rel = conj(a) ⊗ b, taken the short way round.
            let rw0 = aw[j] * bw[j] + ax[j] * bx[j] + ay[j] * by[j] + az[j] * bz[j];
            let rx0 = aw[j] * bx[j] - bw[j] * ax[j] - (ay[j] * bz[j] - az[j] * by[j]);
            let ry0 = aw[j] * by[j] - bw[j] * ay[j] - (az[j] * bx[j] - ax[j] * bz[j]);
            let rz0 = aw[j] * bz[j] - bw[j] * az[j] - (ax[j] * by[j] - ay[j] * bx[j]);
            let sign = if rw0 < zero { -one } else { one };
            let (rw, rx, ry, rz) = (rw0 * sign, rx0 * sign, ry0 * sign, rz0 * sign);
            let f1 = k1[j] * (rx * tl[j] - u1[j]);
            let f2 = k2[j] * (ry * tl[j] - u2[j]);
            let f3 = k3[j] * (rz * tl[j] - u3[j]);
            let (cx, cy, cz) = (ry * f3 - rz * f2, rz * f1 - rx * f3, rx * f2 - ry * f1);
            tax[j] = f1 * rw + cx;
            tay[j] = f2 * rw + cy;
            taz[j] = f3 * rw + cz;
            tbx[j] = cx - f1 * rw;
            tby[j] = cy - f2 * rw;
            tbz[j] = cz - f3 * rw;
        }
    }
    for (t, (a, b)) in [
        (&mut s.tq.x, (&s.ta.x, &s.tb.x)),
        (&mut s.tq.y, (&s.ta.y, &s.tb.y)),
        (&mut s.tq.z, (&s.ta.z, &s.tb.z)),
    ] {
        for j in 0..m {
            t[j] += a[j];
        }
        for j in 0..m {
            t[j + 1] += b[j];
        }
    }
    for (f, (v, (fe, g))) in [
        (&mut s.f.x, (&s.v.x, (&s.fe.x, gravity.x))),
        (&mut s.f.y, (&s.v.y, (&s.fe.y, gravity.y))),
        (&mut s.f.z, (&s.v.z, (&s.fe.z, gravity.z))),
    ] {
        let (f, v, ms) = (&mut f[..n + 1], &v[..n + 1], &p.masses[..n + 1]);
        for i in 0..=n {
            f[i] = (g - v[i] * drag) * ms[i];
        }
        for j in 0..n {
            f[j] -= fe[j];
        }
        for j in 0..n {
            f[j + 1] += fe[j];
        }
    }
}

/// Semi-implicit Euler update of velocities from forces, and Euler's equations for the frames.
///
/// A frame's angular velocity takes its torque as two half kicks around the gyroscopic term,
/// which for the rod's axisymmetric sections (`I₁ = I₂ = I`, `I₃ = J`) is an exact rotation of
/// the transverse part `(ω₁, ω₂)` by `h (J − I)/I ω₃`, applied as a Cayley rotation (norm
/// preserving, one division). Taken explicitly (`ω += −h I⁻¹ (ω × Iω)`), that term destroys the
/// scheme's stability near its limit as soon as frames spin: a rod spinning at 5 rad/s about its
/// axis was stable only to 0.77 of the critical step, at 100 rad/s to 0.22; split this way it
/// keeps the whole step (`docs/stability.md`).
pub(crate) fn integrate_velocities<T: Real>(s: &mut SoaState<T>, p: &SoaParams<T>, h: T) {
    for (v, f) in [
        (&mut s.v.x, &s.f.x),
        (&mut s.v.y, &s.f.y),
        (&mut s.v.z, &s.f.z),
    ] {
        for ((v, f), w) in v.iter_mut().zip(f).zip(&p.inv_masses) {
            *v += *f * (h * *w);
        }
    }
    let n = s.w.x.len();
    let (wx, wy, wz) = (&mut s.w.x[..n], &mut s.w.y[..n], &mut s.w.z[..n]);
    let (tx, ty, tz) = (&s.tq.x[..n], &s.tq.y[..n], &s.tq.z[..n]);
    let iz = &p.inertia.z[..n];
    let (jx, jy, jz) = (
        &p.inv_inertia.x[..n],
        &p.inv_inertia.y[..n],
        &p.inv_inertia.z[..n],
    );
    let hh = h * T::lit(0.5);
    for j in 0..n {
        let (kx, ky) = (hh * jx[j] * tx[j], hh * jy[j] * ty[j]);
        let kz = hh * jz[j] * tz[j];
        let (a, b, c) = (wx[j] + kx, wy[j] + ky, wz[j] + kz);
        let (cos, sin) = gyroscopic_rotation(hh * (iz[j] * jx[j] - T::one()) * c);
        wx[j] = cos * a - sin * b + kx;
        wy[j] = sin * a + cos * b + ky;
        wz[j] = c + kz;
    }
}

/// Cosine and sine of the Cayley rotation whose half-angle tangent is `t`: the gyroscopic
/// precession `(J − I)/I ω₃ h` of a step, with `t` half of it (exact to third order in the angle).
#[inline(always)]
pub(crate) fn gyroscopic_rotation<T: Real>(t: T) -> (T, T) {
    let inv = T::one() / (T::one() + t * t);
    ((T::one() - t * t) * inv, (t + t) * inv)
}

/// `r += h v`; `q ← normalise(q + q ⊗ (0, h ω / 2))`; squared length ratios into `s.ratio2`.
pub(crate) fn integrate_positions<T: Real>(s: &mut SoaState<T>, p: &SoaParams<T>, h: T) {
    for (r, v) in [
        (&mut s.r.x, &s.v.x),
        (&mut s.r.y, &s.v.y),
        (&mut s.r.z, &s.v.z),
    ] {
        for (r, v) in r.iter_mut().zip(v) {
            *r += *v * h;
        }
    }
    let n = s.w.x.len();
    let hh = h * T::lit(0.5);
    let [qx, qy, qz, qw] = &mut s.q;
    let (qx, qy, qz, qw) = (&mut qx[..n], &mut qy[..n], &mut qz[..n], &mut qw[..n]);
    let (wx, wy, wz) = (&s.w.x[..n], &s.w.y[..n], &s.w.z[..n]);
    for j in 0..n {
        let (x, y, z, w) = (qx[j], qy[j], qz[j], qw[j]);
        let (a, b, c) = (wx[j] * hh, wy[j] * hh, wz[j] * hh);
        // q ⊗ (0, a, b, c)
        let nw = w - (x * a + y * b + z * c);
        let nx = x + (w * a + y * c - z * b);
        let ny = y + (w * b + z * a - x * c);
        let nz = z + (w * c + x * b - y * a);
        let inv = T::one() / (nw * nw + nx * nx + ny * ny + nz * nz).sqrt();
        qx[j] = nx * inv;
        qy[j] = ny * inv;
        qz[j] = nz * inv;
        qw[j] = nw * inv;
    }
    let rx = &s.r.x;
    let ry = &s.r.y;
    let rz = &s.r.z;
    let (l0, out) = (&p.rest_lengths[..n], &mut s.ratio2[..n]);
    let (rx0, rx1, ry0, ry1, rz0, rz1) = (
        &rx[..n],
        &rx[1..n + 1],
        &ry[..n],
        &ry[1..n + 1],
        &rz[..n],
        &rz[1..n + 1],
    );
    for j in 0..n {
        let (ex, ey, ez) = (rx1[j] - rx0[j], ry1[j] - ry0[j], rz1[j] - rz0[j]);
        out[j] = (ex * ex + ey * ey + ez * ez) / (l0[j] * l0[j]);
    }
}
