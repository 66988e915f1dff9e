//! Rod–rod and self-collision between chains of points (rod centrelines).
//!
//! This module knows nothing about rods: a [`Chain`] is a polyline of points with a radius (a
//! guidewire, a catheter, a suture). Two chains touch where their *capsules* (the set of points
//! within `radius` of the polyline) overlap.
//!
//! # Broad phase: bounding spheres over runs of points (paper, Fig. 6)
//!
//! Each run of `k` consecutive segments (`k + 1` points; [`RodCollisionConfig::segments_per_sphere`])
//! is wrapped in one sphere, inflated by the chain radius. Sphere pairs are found either by testing
//! all pairs (what the paper does, [`BroadPhase::AllPairs`]) or by sort-and-sweep along the axis of
//! largest spread ([`BroadPhase::SweepAndPrune`], the default). The benchmark
//! (`benches/detect.rs`, a tightly coiled chain whose turns touch) measured both as equal at 512
//! points and sweep-and-prune about 1.2× faster at 3072 points (the narrow phase dominates there);
//! its advantage grows with the number of spheres that are far apart, since all-pairs is `O(S²)`.
//!
//! # Narrow phase: segment–segment closest distance
//!
//! The paper tests the mass points as spheres, which needs densely overlapping spheres to stop
//! rods slipping through each other between points (the paper doubles its element count for the
//! knot for this reason). We test **segment against segment** instead (closest points of two
//! segments, Ericson 5.1.9): the capsules are continuous, so crossing segments are caught even when
//! all their end points are far apart. A contact reports both segments and the parameters `s`, `t`
//! of the closest points along them, so the solver can share the impulse between each segment's
//! two end points (`1 − s`, `s`).
//!
//! Before the closest-point computation, each pair of overlapping spheres is culled by
//! segment midpoints: a segment lies within half its length `e` of its midpoint `m`, so a
//! segment can only touch the other sphere if `|m − c| < e + r + R`, and two segments only if
//! `|m₁ − m₂| < e₁ + e₂ + r₁ + r₂`. Both tests are conservative (with a relative slack of
//! 1e-9 against rounding), so the contacts are exactly those of testing every segment pair; in
//! a tight knot they skip most of the closest-point computations.
//!
//! # Self-collision
//!
//! Neighbouring segments of one chain always touch (adjacent ones share a point). Segment pairs
//! `i`, `j` of the same chain with `|i − j| ≤ skip` are therefore not tested. By default the skip is
//! `⌊2r / h⌋ + 1` with `h` the chain's mean segment length: on a straight chain the first tested
//! pair is then separated by more than `2r` of arc length, so a straight or gently bent chain
//! reports nothing, while a tight loop or a knot does.

/// A polyline of points (at least one) with a radius. Pure data, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct Chain<'a> {
    /// The points along the centreline.
    pub points: &'a [[f64; 3]],
    /// The radius of the rod.
    pub radius: f64,
}

/// How sphere pairs are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BroadPhase {
    /// Every sphere against every other (the paper's choice): `O(S²)`.
    AllPairs,
    /// Sort the spheres along the axis of largest spread and sweep: `O(S log S + pairs)`.
    #[default]
    SweepAndPrune,
}

/// Settings for [`RodCollider`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodCollisionConfig {
    /// Segments covered by one bounding sphere (the paper's run of points). Default 4.
    pub segments_per_sphere: usize,
    /// Whether a chain is tested against itself. Default `true`.
    pub self_collisions: bool,
    /// Same-chain segment pairs with `|i − j| ≤ skip` are not tested; `None` (default) computes
    /// `⌊2r / h⌋ + 1` per chain (see the module docs).
    pub self_skip: Option<usize>,
    /// Broad-phase algorithm. Default [`BroadPhase::SweepAndPrune`].
    pub broad_phase: BroadPhase,
}

impl Default for RodCollisionConfig {
    fn default() -> Self {
        Self {
            segments_per_sphere: 4,
            self_collisions: true,
            self_skip: None,
            broad_phase: BroadPhase::SweepAndPrune,
        }
    }
}

/// A broad-phase sphere wrapping segments `first .. first + count` of one chain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingSphere {
    /// The chain.
    pub chain: u32,
    /// First segment covered.
    pub first: u32,
    /// Number of segments covered.
    pub count: u32,
    /// Centre.
    pub center: [f64; 3],
    /// Radius, including the chain radius.
    pub radius: f64,
}

/// One contact between two segments (of two chains, or of one chain with itself).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodContact {
    /// First chain.
    pub chain_a: u32,
    /// Segment of the first chain (between points `segment_a` and `segment_a + 1`).
    pub segment_a: u32,
    /// Parameter of the closest point along segment a, in `[0, 1]`.
    pub s: f64,
    /// Second chain (`chain_b >= chain_a`; equal for a self-contact, then `segment_b > segment_a`).
    pub chain_b: u32,
    /// Segment of the second chain.
    pub segment_b: u32,
    /// Parameter of the closest point along segment b, in `[0, 1]`.
    pub t: f64,
    /// Unit normal from the closest point on b to the closest point on a: push a along it, b
    /// against it.
    pub normal: [f64; 3],
    /// Distance between the two closest centreline points.
    pub distance: f64,
    /// Overlap `r_a + r_b − distance` (> 0).
    pub penetration: f64,
}

/// Broad and narrow phase for chains, with reusable buffers (no allocation per call after
/// warm-up, apart from growth).
#[derive(Clone, Debug, Default)]
pub struct RodCollider {
    config: RodCollisionConfig,
    spheres: Vec<BoundingSphere>,
    order: Vec<u32>,
    pairs: Vec<(u32, u32)>,
    skips: Vec<usize>,
    /// Per segment of every chain (chain `c` starts at `seg_start[c]`): midpoint and half length.
    segs: Vec<[f64; 4]>,
    seg_start: Vec<usize>,
}

type V3 = [f64; 3];

#[inline]
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
fn axpy(a: V3, s: f64, d: V3) -> V3 {
    [a[0] + s * d[0], a[1] + s * d[1], a[2] + s * d[2]]
}

/// Closest points of segments `p1q1` and `p2q2` (Ericson, *Real-Time Collision Detection*,
/// 5.1.9): returns `(s, t, c1, c2)` with `c1 = p1 + s (q1 − p1)`, `c2 = p2 + t (q2 − p2)`.
pub fn closest_points_segments(p1: V3, q1: V3, p2: V3, q2: V3) -> (f64, f64, V3, V3) {
    let d1 = sub(q1, p1);
    let d2 = sub(q2, p2);
    let r = sub(p1, p2);
    let a = dot(d1, d1);
    let e = dot(d2, d2);
    let f = dot(d2, r);
    let eps = 1e-300;
    let (s, t);
    if a <= eps && e <= eps {
        return (0.0, 0.0, p1, p2);
    }
    if a <= eps {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = dot(d1, r);
        if e <= eps {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = dot(d1, d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > 0.0 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    (s, t, axpy(p1, s, d1), axpy(p2, t, d2))
}

fn segment(points: &[[f64; 3]], i: usize) -> (V3, V3) {
    if points.len() == 1 {
        (points[0], points[0])
    } else {
        (points[i], points[i + 1])
    }
}

fn segment_count(points: &[[f64; 3]]) -> usize {
    if points.len() <= 1 {
        points.len()
    } else {
        points.len() - 1
    }
}

impl RodCollider {
    /// A collider with the given settings (`segments_per_sphere` is clamped to at least 1).
    pub fn new(mut config: RodCollisionConfig) -> Self {
        config.segments_per_sphere = config.segments_per_sphere.max(1);
        Self {
            config,
            ..Self::default()
        }
    }

    /// The settings.
    pub fn config(&self) -> &RodCollisionConfig {
        &self.config
    }

    /// The bounding spheres of the last [`detect`](Self::detect) call.
    pub fn spheres(&self) -> &[BoundingSphere] {
        &self.spheres
    }

    /// The overlapping sphere pairs (indices into [`spheres`](Self::spheres)) of the last call,
    /// including a sphere paired with itself when its own segments may self-collide.
    pub fn sphere_pairs(&self) -> &[(u32, u32)] {
        &self.pairs
    }

    /// The self-collision skip used for a chain (see the module docs).
    pub fn self_skip_for(&self, chain: &Chain<'_>) -> usize {
        if let Some(s) = self.config.self_skip {
            return s;
        }
        let n = segment_count(chain.points);
        if n == 0 || chain.points.len() < 2 {
            return 1;
        }
        let len: f64 = chain
            .points
            .windows(2)
            .map(|w| dot(sub(w[1], w[0]), sub(w[1], w[0])).sqrt())
            .sum();
        let h = len / n as f64;
        if h.is_nan() || h <= 0.0 || !chain.radius.is_finite() {
            return n;
        }
        ((2.0 * chain.radius / h).floor() as usize + 1).clamp(1, n)
    }

    /// Finds all segment contacts between the chains (and within each chain if enabled). Clears
    /// and fills `out`; contacts come grouped by sphere pair. Chains with no points are ignored;
    /// a one-point chain is a sphere.
    pub fn detect(&mut self, chains: &[Chain<'_>], out: &mut Vec<RodContact>) {
        out.clear();
        self.build_spheres(chains);
        self.build_segments(chains);
        self.skips.clear();
        for c in chains {
            let s = self.self_skip_for(c);
            self.skips.push(s);
        }
        self.find_pairs();
        let segs = Segments {
            segs: &self.segs,
            start: &self.seg_start,
        };
        for &(ia, ib) in &self.pairs {
            let (sa, sb) = (self.spheres[ia as usize], self.spheres[ib as usize]);
            narrow(chains, &segs, &sa, &sb, ia == ib, &self.skips, out);
        }
    }

    /// Midpoint and half length of every segment (a one-point chain: the point, 0).
    fn build_segments(&mut self, chains: &[Chain<'_>]) {
        self.segs.clear();
        self.seg_start.clear();
        for c in chains {
            self.seg_start.push(self.segs.len());
            for i in 0..segment_count(c.points) {
                let (p, q) = segment(c.points, i);
                let d = sub(q, p);
                self.segs.push([
                    0.5 * (p[0] + q[0]),
                    0.5 * (p[1] + q[1]),
                    0.5 * (p[2] + q[2]),
                    0.5 * dot(d, d).sqrt(),
                ]);
            }
        }
    }

    fn build_spheres(&mut self, chains: &[Chain<'_>]) {
        self.spheres.clear();
        let k = self.config.segments_per_sphere;
        for (ci, c) in chains.iter().enumerate() {
            let n = segment_count(c.points);
            let mut first = 0;
            while first < n {
                let count = k.min(n - first);
                let pts = &c.points[first..(first + count + 1).min(c.points.len())];
                let mut lo = pts[0];
                let mut hi = pts[0];
                for p in pts {
                    for a in 0..3 {
                        lo[a] = lo[a].min(p[a]);
                        hi[a] = hi[a].max(p[a]);
                    }
                }
                let center = [
                    0.5 * (lo[0] + hi[0]),
                    0.5 * (lo[1] + hi[1]),
                    0.5 * (lo[2] + hi[2]),
                ];
                let r2 = pts
                    .iter()
                    .map(|p| dot(sub(*p, center), sub(*p, center)))
                    .fold(0.0, f64::max);
                self.spheres.push(BoundingSphere {
                    chain: ci as u32,
                    first: first as u32,
                    count: count as u32,
                    center,
                    radius: r2.sqrt() + c.radius,
                });
                first += count;
            }
        }
    }

    fn wants_pair(&self, a: &BoundingSphere, b: &BoundingSphere) -> bool {
        if a.chain == b.chain {
            if !self.config.self_collisions {
                return false;
            }
            // Skip sphere pairs whose segments are all within the skip distance.
            let skip = self.skips[a.chain as usize] as i64;
            let (a0, a1) = (a.first as i64, (a.first + a.count) as i64 - 1);
            let (b0, b1) = (b.first as i64, (b.first + b.count) as i64 - 1);
            let max_gap = (b1 - a0).abs().max((a1 - b0).abs());
            if max_gap <= skip {
                return false;
            }
        }
        let d = sub(a.center, b.center);
        let rr = a.radius + b.radius;
        dot(d, d) < rr * rr
    }

    fn find_pairs(&mut self) {
        self.pairs.clear();
        let n = self.spheres.len();
        // A sphere against itself: only for self-collision with more than `skip + 1` segments.
        if self.config.self_collisions {
            for i in 0..n {
                let s = &self.spheres[i];
                if s.count as usize > self.skips[s.chain as usize] + 1 {
                    self.pairs.push((i as u32, i as u32));
                }
            }
        }
        match self.config.broad_phase {
            BroadPhase::AllPairs => {
                for i in 0..n {
                    for j in i + 1..n {
                        if self.wants_pair(&self.spheres[i], &self.spheres[j]) {
                            self.pairs.push((i as u32, j as u32));
                        }
                    }
                }
            }
            BroadPhase::SweepAndPrune => {
                let axis = spread_axis(&self.spheres);
                self.order.clear();
                self.order.extend(0..n as u32);
                let sp = &self.spheres;
                let lo = |i: u32| sp[i as usize].center[axis] - sp[i as usize].radius;
                self.order
                    .sort_unstable_by(|&a, &b| lo(a).total_cmp(&lo(b)));
                for oi in 0..n {
                    let i = self.order[oi];
                    let si = &self.spheres[i as usize];
                    let hi = si.center[axis] + si.radius;
                    for &j in &self.order[oi + 1..] {
                        let sj = &self.spheres[j as usize];
                        if sj.center[axis] - sj.radius > hi {
                            break;
                        }
                        if self.wants_pair(si, sj) {
                            self.pairs.push((i.min(j), i.max(j)));
                        }
                    }
                }
            }
        }
    }
}

fn spread_axis(spheres: &[BoundingSphere]) -> usize {
    let n = spheres.len().max(1) as f64;
    let mut mean = [0.0; 3];
    for s in spheres {
        for a in 0..3 {
            mean[a] += s.center[a] / n;
        }
    }
    let mut var = [0.0; 3];
    for s in spheres {
        for a in 0..3 {
            let d = s.center[a] - mean[a];
            var[a] += d * d;
        }
    }
    if var[0] >= var[1] && var[0] >= var[2] {
        0
    } else if var[1] >= var[2] {
        1
    } else {
        2
    }
}

/// Midpoints and half lengths of the segments (see [`RodCollider::build_segments`]).
struct Segments<'a> {
    segs: &'a [[f64; 4]],
    start: &'a [usize],
}

/// Conservative rejection: a segment of midpoint `m` and half length `e` lies within `e` of
/// `m`, so two capsules (or a capsule and a sphere) at midpoint distance `d` can only overlap
/// if `d < e_1 + e_2 + r`. The slack keeps rounding from rejecting a pair the exact test
/// would keep.
#[inline(always)]
fn may_touch(m1: &[f64; 4], m2: [f64; 3], reach: f64) -> bool {
    let d = sub([m1[0], m1[1], m1[2]], m2);
    let r = (m1[3] + reach) * (1.0 + 1e-9) + 1e-300;
    dot(d, d) < r * r
}

fn narrow(
    chains: &[Chain<'_>],
    segs: &Segments<'_>,
    sa: &BoundingSphere,
    sb: &BoundingSphere,
    same_sphere: bool,
    skips: &[usize],
    out: &mut Vec<RodContact>,
) {
    // Order so that (chain, segment) of a comes first.
    let (sa, sb) = if (sa.chain, sa.first) <= (sb.chain, sb.first) {
        (sa, sb)
    } else {
        (sb, sa)
    };
    let ca = &chains[sa.chain as usize];
    let cb = &chains[sb.chain as usize];
    let same_chain = sa.chain == sb.chain;
    let skip = skips[sa.chain as usize];
    let rr = ca.radius + cb.radius;
    let ga = &segs.segs[segs.start[sa.chain as usize]..];
    let gb = &segs.segs[segs.start[sb.chain as usize]..];
    // Segments of each sphere that can reach the other sphere (its radius includes its
    // chain's radius): at most 64 per sphere are filtered, the rest always tested.
    let mut mask_b = u64::MAX;
    if !same_sphere {
        for j in 0..(sb.count as usize).min(64) {
            if !may_touch(&gb[sb.first as usize + j], sa.center, sa.radius + cb.radius) {
                mask_b &= !(1 << j);
            }
        }
    }
    for i in sa.first..sa.first + sa.count {
        let mi = &ga[i as usize];
        if !same_sphere && !may_touch(mi, sb.center, sb.radius + ca.radius) {
            continue;
        }
        let (p1, q1) = segment(ca.points, i as usize);
        let jstart = if same_sphere { i + 1 } else { sb.first };
        for j in jstart..sb.first + sb.count {
            let bit = (j - sb.first) as u64;
            if bit < 64 && mask_b & (1 << bit) == 0 {
                continue;
            }
            if same_chain && (j as i64 - i as i64).unsigned_abs() as usize <= skip {
                continue;
            }
            let mj = &gb[j as usize];
            if !may_touch(mi, [mj[0], mj[1], mj[2]], mj[3] + rr) {
                continue;
            }
            let (p2, q2) = segment(cb.points, j as usize);
            let (s, t, c1, c2) = closest_points_segments(p1, q1, p2, q2);
            let d = sub(c1, c2);
            let d2 = dot(d, d);
            if d2 < rr * rr {
                let dist = d2.sqrt();
                let normal = if dist > 0.0 {
                    [d[0] / dist, d[1] / dist, d[2] / dist]
                } else {
                    fallback_normal(sub(q1, p1), sub(q2, p2))
                };
                out.push(RodContact {
                    chain_a: sa.chain,
                    segment_a: i,
                    s,
                    chain_b: sb.chain,
                    segment_b: j,
                    t,
                    normal,
                    distance: dist,
                    penetration: rr - dist,
                });
            }
        }
    }
}

/// A unit normal for two segments whose centrelines touch exactly: perpendicular to both if they
/// are not parallel, else perpendicular to the first, else +z.
fn fallback_normal(d1: V3, d2: V3) -> V3 {
    let c = [
        d1[1] * d2[2] - d1[2] * d2[1],
        d1[2] * d2[0] - d1[0] * d2[2],
        d1[0] * d2[1] - d1[1] * d2[0],
    ];
    let n = dot(c, c).sqrt();
    if n > 1e-300 {
        return [c[0] / n, c[1] / n, c[2] / n];
    }
    let trial = if d1[0].abs() < 0.9 * dot(d1, d1).sqrt() {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let c = [
        d1[1] * trial[2] - d1[2] * trial[1],
        d1[2] * trial[0] - d1[0] * trial[2],
        d1[0] * trial[1] - d1[1] * trial[0],
    ];
    let n = dot(c, c).sqrt();
    if n > 1e-300 {
        [c[0] / n, c[1] / n, c[2] / n]
    } else {
        [0.0, 0.0, 1.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every segment pair under the same rules as [`RodCollider::detect`], without any culling.
    fn brute(chains: &[Chain<'_>], rc: &RodCollider) -> Vec<(u32, u32, u32, u32)> {
        let mut out = Vec::new();
        for a in 0..chains.len() {
            for b in a..chains.len() {
                let skip = rc.self_skip_for(&chains[a]);
                let rr = chains[a].radius + chains[b].radius;
                for i in 0..segment_count(chains[a].points) {
                    for j in 0..segment_count(chains[b].points) {
                        if a == b && j <= i + skip {
                            continue;
                        }
                        let (p1, q1) = segment(chains[a].points, i);
                        let (p2, q2) = segment(chains[b].points, j);
                        let (_, _, c1, c2) = closest_points_segments(p1, q1, p2, q2);
                        let d = sub(c1, c2);
                        if dot(d, d) < rr * rr {
                            out.push((a as u32, i as u32, b as u32, j as u32));
                        }
                    }
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// Two strands wound tightly round each other and round themselves (turns of a few radii,
    /// neighbouring turns touching, as in a tightened knot), with a margin-sized spread of
    /// radii: the culling by spheres and segment midpoints finds exactly the pairs that testing
    /// every segment pair finds, for every run length and both broad phases.
    #[test]
    fn tight_coils_match_brute_force() {
        let h = 0.98e-3;
        let strand = |phase: f64, n: usize| -> Vec<[f64; 3]> {
            (0..=n)
                .map(|i| {
                    let s = i as f64 * h;
                    let th = s / 3.5e-3 + phase;
                    [
                        3.5e-3 * th.cos(),
                        3.5e-3 * th.sin(),
                        2.1e-3 * th / std::f64::consts::TAU + 1e-3 * (7.0 * th).sin(),
                    ]
                })
                .collect()
        };
        let (a, b) = (strand(0.0, 256), strand(std::f64::consts::PI, 200));
        for radius in [0.9e-3, 1.0e-3, 1.1e-3] {
            let chains = [
                Chain { points: &a, radius },
                Chain {
                    points: &b,
                    radius: radius * 1.05,
                },
            ];
            for k in [1, 3, 4, 7] {
                for broad_phase in [BroadPhase::AllPairs, BroadPhase::SweepAndPrune] {
                    let mut rc = RodCollider::new(RodCollisionConfig {
                        segments_per_sphere: k,
                        broad_phase,
                        ..RodCollisionConfig::default()
                    });
                    let mut out = Vec::new();
                    rc.detect(&chains, &mut out);
                    let mut got: Vec<_> = out
                        .iter()
                        .map(|c| (c.chain_a, c.segment_a, c.chain_b, c.segment_b))
                        .collect();
                    got.sort_unstable();
                    let want = brute(&chains, &rc);
                    assert!(want.len() > 100, "{}", want.len());
                    assert_eq!(got, want, "k = {k}, {broad_phase:?}, r = {radius}");
                }
            }
        }
    }
}
