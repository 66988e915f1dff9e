//! Four elements at a time: the element-wise passes of the stiff step on `f64x4` lanes.
//!
//! Every pass of a stiff step except the factorisation and the solve is independent per
//! element, point or frame (it reads at most the next element's data). Written on scalars
//! with `nalgebra` types in an array of structures, each of those passes ran at one element at
//! a time and together they cost more than the factorisation (`docs/benchmarks/stiff.md`).
//! Here each quantity is a column of `f64` (structure of arrays) and a pass loads four
//! consecutive elements into the lanes of an AVX register, so the same formulas run on four
//! elements per instruction.
//!
//! Columns are padded past their last entry to a multiple of four plus four, so that a pass
//! may load `j + 1` of the last chunk; the padding holds benign values (zero vectors, identity
//! rotations) that keep the extra lanes finite, and every reduction masks them out.

use cosserat_model::{Quat, Real, Vec3};
use wide::f64x4;

/// Four lanes of `f64`.
pub(crate) type F = f64x4;

/// The padded length of a column holding `len` entries.
pub(crate) fn padded(len: usize) -> usize {
    len.div_ceil(4) * 4 + 4
}

/// `[j, j + 1, j + 2, j + 3]` as lanes.
#[inline(always)]
pub(crate) fn lane_indices(j: usize) -> F {
    let j = j as f64;
    F::from([j, j + 1.0, j + 2.0, j + 3.0])
}

/// Lanes set to 1 where the lane's index (`j + lane`) is below `end`, 0 elsewhere.
#[inline(always)]
pub(crate) fn below(j: usize, end: usize) -> F {
    lane_indices(j)
        .simd_lt(F::splat(end as f64))
        .select(F::ONE, F::ZERO)
}

/// Four lanes loaded from `c[j..j + 4]`.
#[inline(always)]
pub(crate) fn load(c: &[f64], j: usize) -> F {
    let a: [f64; 4] = c[j..j + 4].try_into().expect("four lanes");
    F::from(a)
}

/// Stores four lanes to `c[j..j + 4]`.
#[inline(always)]
pub(crate) fn store(c: &mut [f64], j: usize, v: F) {
    c[j..j + 4].copy_from_slice(&v.to_array());
}

/// A 3-vector per lane.
#[derive(Clone, Copy, Debug)]
pub(crate) struct V {
    pub(crate) x: F,
    pub(crate) y: F,
    pub(crate) z: F,
}

impl V {
    #[inline(always)]
    pub(crate) fn splat(v: &Vec3<f64>) -> V {
        V {
            x: F::splat(v.x),
            y: F::splat(v.y),
            z: F::splat(v.z),
        }
    }
    #[inline(always)]
    pub(crate) fn dot(self, o: V) -> F {
        self.z.mul_add(o.z, self.y.mul_add(o.y, self.x * o.x))
    }
    #[inline(always)]
    pub(crate) fn norm2(self) -> F {
        self.dot(self)
    }
    #[inline(always)]
    pub(crate) fn cross(self, o: V) -> V {
        V {
            x: self.y.mul_sub(o.z, self.z * o.y),
            y: self.z.mul_sub(o.x, self.x * o.z),
            z: self.x.mul_sub(o.y, self.y * o.x),
        }
    }
    #[inline(always)]
    pub(crate) fn scale(self, s: F) -> V {
        V {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
    /// `self + a s`.
    #[inline(always)]
    pub(crate) fn add_scaled(self, a: V, s: F) -> V {
        V {
            x: a.x.mul_add(s, self.x),
            y: a.y.mul_add(s, self.y),
            z: a.z.mul_add(s, self.z),
        }
    }
    /// Component-wise product.
    #[inline(always)]
    pub(crate) fn mul(self, o: V) -> V {
        V {
            x: self.x * o.x,
            y: self.y * o.y,
            z: self.z * o.z,
        }
    }
    #[inline(always)]
    pub(crate) fn abs_max(self) -> F {
        self.x.abs().max(self.y.abs()).max(self.z.abs())
    }
}

impl std::ops::Add for V {
    type Output = V;
    #[inline(always)]
    fn add(self, o: V) -> V {
        V {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl std::ops::Sub for V {
    type Output = V;
    #[inline(always)]
    fn sub(self, o: V) -> V {
        V {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

impl std::ops::Neg for V {
    type Output = V;
    #[inline(always)]
    fn neg(self) -> V {
        V {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// A quaternion per lane (`w` scalar part).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Q {
    pub(crate) w: F,
    pub(crate) v: V,
}

impl Q {
    /// The Hamilton product `self ⊗ o`.
    #[inline(always)]
    pub(crate) fn mul(self, o: Q) -> Q {
        let (a, b) = (self.v, o.v);
        Q {
            w: self.w.mul_sub(o.w, a.dot(b)),
            v: a.cross(b).add_scaled(b, self.w).add_scaled(a, o.w),
        }
    }
    /// `conj(self) ⊗ o`.
    #[inline(always)]
    pub(crate) fn conj_mul(self, o: Q) -> Q {
        Q {
            w: self.w,
            v: -self.v,
        }
        .mul(o)
    }
    #[inline(always)]
    pub(crate) fn norm2(self) -> F {
        self.w.mul_add(self.w, self.v.norm2())
    }
    #[inline(always)]
    pub(crate) fn scale(self, s: F) -> Q {
        Q {
            w: self.w * s,
            v: self.v.scale(s),
        }
    }
    /// `self` or `−self`, whichever has a non-negative scalar part.
    #[inline(always)]
    pub(crate) fn positive(self) -> Q {
        let sign = self.w.simd_lt(F::ZERO).select(F::splat(-1.0), F::ONE);
        self.scale(sign)
    }
    /// `self / |self|`.
    #[inline(always)]
    pub(crate) fn normalised(self) -> Q {
        self.scale(F::ONE / self.norm2().sqrt())
    }
    /// The directors `d1, d2, d3` (columns of the rotation matrix) of a unit quaternion.
    #[inline(always)]
    pub(crate) fn directors(self) -> [V; 3] {
        let (w, x, y, z) = (self.w, self.v.x, self.v.y, self.v.z);
        let two = F::splat(2.0);
        let (xx, yy, zz) = (x * x * two, y * y * two, z * z * two);
        let (xy, xz, yz) = (x * y * two, x * z * two, y * z * two);
        let (wx, wy, wz) = (w * x * two, w * y * two, w * z * two);
        let one = F::ONE;
        [
            V {
                x: one - yy - zz,
                y: xy + wz,
                z: xz - wy,
            },
            V {
                x: xy - wz,
                y: one - xx - zz,
                z: yz + wx,
            },
            V {
                x: xz + wy,
                y: yz - wx,
                z: one - xx - yy,
            },
        ]
    }
}

/// Lanes where `x >= limit` as a bit mask (bit `i` for lane `i`).
#[inline(always)]
pub(crate) fn mask_ge(x: F, limit: F) -> u32 {
    x.simd_ge(limit).to_bitmask()
}

/// A column of 3-vectors, padded (see the module docs).
#[derive(Clone, Debug, Default)]
pub(crate) struct V3s {
    pub(crate) x: Vec<f64>,
    pub(crate) y: Vec<f64>,
    pub(crate) z: Vec<f64>,
}

impl V3s {
    /// `len` zero vectors (plus padding).
    pub(crate) fn zeros(len: usize) -> Self {
        let p = padded(len);
        Self {
            x: vec![0.0; p],
            y: vec![0.0; p],
            z: vec![0.0; p],
        }
    }
    /// The vectors of `v` (plus zero padding).
    pub(crate) fn from_slice(v: &[Vec3<f64>]) -> Self {
        let mut c = Self::zeros(v.len());
        for (i, a) in v.iter().enumerate() {
            c.set(i, a);
        }
        c
    }
    #[inline(always)]
    pub(crate) fn get(&self, i: usize) -> Vec3<f64> {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }
    #[inline(always)]
    pub(crate) fn set(&mut self, i: usize, v: &Vec3<f64>) {
        self.x[i] = v.x;
        self.y[i] = v.y;
        self.z[i] = v.z;
    }
    #[inline(always)]
    pub(crate) fn load(&self, j: usize) -> V {
        V {
            x: load(&self.x, j),
            y: load(&self.y, j),
            z: load(&self.z, j),
        }
    }
    #[inline(always)]
    pub(crate) fn store(&mut self, j: usize, v: V) {
        store(&mut self.x, j, v.x);
        store(&mut self.y, j, v.y);
        store(&mut self.z, j, v.z);
    }
    pub(crate) fn fill_zero(&mut self) {
        for c in [&mut self.x, &mut self.y, &mut self.z] {
            c.fill(0.0);
        }
    }
    pub(crate) fn copy_from(&mut self, o: &V3s) {
        self.x.copy_from_slice(&o.x);
        self.y.copy_from_slice(&o.y);
        self.z.copy_from_slice(&o.z);
    }
    /// The first `out.len()` entries, rounded to `T`, into `out` (one pass without bounds
    /// checks, which the compiler vectorises).
    pub(crate) fn write_to<T: Real>(&self, out: &mut [Vec3<T>]) {
        let columns = self.x.iter().zip(&self.y).zip(&self.z);
        for (o, ((x, y), z)) in out.iter_mut().zip(columns) {
            *o = Vec3::new(T::lit(*x), T::lit(*y), T::lit(*z));
        }
    }
    /// Whether `v` holds exactly the first `v.len()` entries rounded to `T`.
    pub(crate) fn rounds_to<T: Real>(&self, v: &[Vec3<T>]) -> bool {
        let columns = self.x.iter().zip(&self.y).zip(&self.z);
        v.len() <= self.x.len()
            && v.iter().zip(columns).fold(true, |same, (a, ((x, y), z))| {
                same & (T::lit(*x) == a.x) & (T::lit(*y) == a.y) & (T::lit(*z) == a.z)
            })
    }
}

/// A column of quaternions, padded with identities.
#[derive(Clone, Debug, Default)]
pub(crate) struct Q4s {
    pub(crate) w: Vec<f64>,
    pub(crate) v: V3s,
}

impl Q4s {
    /// `len` identity rotations (plus padding).
    pub(crate) fn identities(len: usize) -> Self {
        Self {
            w: vec![1.0; padded(len)],
            v: V3s::zeros(len),
        }
    }
    #[inline(always)]
    pub(crate) fn get(&self, i: usize) -> Quat<f64> {
        Quat::new(self.w[i], self.v.x[i], self.v.y[i], self.v.z[i])
    }
    #[inline(always)]
    pub(crate) fn set(&mut self, i: usize, q: &Quat<f64>) {
        self.w[i] = q.w;
        self.v.set(i, &q.imag());
    }
    #[inline(always)]
    pub(crate) fn load(&self, j: usize) -> Q {
        Q {
            w: load(&self.w, j),
            v: self.v.load(j),
        }
    }
    #[inline(always)]
    pub(crate) fn store(&mut self, j: usize, q: Q) {
        store(&mut self.w, j, q.w);
        self.v.store(j, q.v);
    }
    pub(crate) fn copy_from(&mut self, o: &Q4s) {
        self.w.copy_from_slice(&o.w);
        self.v.copy_from(&o.v);
    }
    /// As [`V3s::write_to`].
    pub(crate) fn write_to<T: Real>(&self, out: &mut [Quat<T>]) {
        let columns = self.w.iter().zip(&self.v.x).zip(&self.v.y).zip(&self.v.z);
        for (o, (((w, x), y), z)) in out.iter_mut().zip(columns) {
            *o = Quat::new(T::lit(*w), T::lit(*x), T::lit(*y), T::lit(*z));
        }
    }
    /// As [`V3s::rounds_to`].
    pub(crate) fn rounds_to<T: Real>(&self, q: &[Quat<T>]) -> bool {
        let columns = self.w.iter().zip(&self.v.x).zip(&self.v.y).zip(&self.v.z);
        q.len() <= self.w.len()
            && q.iter()
                .zip(columns)
                .fold(true, |same, (a, (((w, x), y), z))| {
                    same & (T::lit(*w) == a.w)
                        & (T::lit(*x) == a.i)
                        & (T::lit(*y) == a.j)
                        & (T::lit(*z) == a.k)
                })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cosserat_model::quat::{directors, exp_rotation};

    fn lane(f: F, i: usize) -> f64 {
        f.to_array()[i]
    }

    /// The lane formulas against nalgebra's, lane by lane.
    #[test]
    fn lane_quaternion_algebra_matches_nalgebra() {
        let qs: Vec<Quat<f64>> = (0..4)
            .map(|i| exp_rotation(&Vec3::new(0.3 * i as f64, -0.7, 1.1 + 0.2 * i as f64)))
            .collect();
        let ps: Vec<Quat<f64>> = (0..4)
            .map(|i| exp_rotation(&Vec3::new(-0.4, 0.5 * i as f64, 2.0)))
            .collect();
        let mut a = Q4s::identities(4);
        let mut b = Q4s::identities(4);
        for i in 0..4 {
            a.set(i, &qs[i]);
            b.set(i, &ps[i]);
        }
        let (qa, qb) = (a.load(0), b.load(0));
        let prod = qa.mul(qb);
        let rel = qa.conj_mul(qb).positive();
        let d = qa.directors();
        for i in 0..4 {
            let p = qs[i] * ps[i];
            let mut r = qs[i].conjugate() * ps[i];
            if r.w < 0.0 {
                r = -r;
            }
            let dd = directors(&qs[i]);
            let close = |x: f64, y: f64| assert!((x - y).abs() < 1e-15, "{x} vs {y}");
            close(lane(prod.w, i), p.w);
            close(lane(prod.v.x, i), p.i);
            close(lane(prod.v.y, i), p.j);
            close(lane(prod.v.z, i), p.k);
            close(lane(rel.w, i), r.w);
            close(lane(rel.v.z, i), r.k);
            for k in 0..3 {
                close(lane(d[k].x, i), dd[k].x);
                close(lane(d[k].y, i), dd[k].y);
                close(lane(d[k].z, i), dd[k].z);
            }
        }
        let u = V::splat(&Vec3::new(1.0, 2.0, 3.0));
        let v = V::splat(&Vec3::new(-0.5, 0.25, 4.0));
        let c = u.cross(v);
        let e = Vec3::new(1.0, 2.0, 3.0).cross(&Vec3::new(-0.5, 0.25, 4.0));
        assert_eq!([lane(c.x, 2), lane(c.y, 2), lane(c.z, 2)], [e.x, e.y, e.z]);
        assert_eq!(below(4, 6).to_array(), [1.0, 1.0, 0.0, 0.0]);
    }
}
