// Rod–rod and self-contact (RODC): composed by src/shader.rs after common.wgsl into the step
// kernels of scenes with rod contacts only, with the sizes RC_PTS (points of a group's rods),
// RC_SPH (their bounding spheres), RC_K (segments per sphere), RC_PAIRS (overlapping sphere
// pairs a step can hold) and RC_CAP (contacts a thread can hold) in the prelude.
//
// The model is the CPU's (backend-cpu coupling.rs): at the start of each step the rods' capsules
// (radius r + margin / 2) are tested against each other and themselves with collide rods.rs'
// broad phase (bounding spheres over runs of RC_K segments, the same pair rules) and its
// segment–segment narrow phase (closest points, Ericson 5.1.9), and every contact becomes a
// four-point constraint with Coulomb friction (constraints rod_contact.rs): non-penetration
// `n · (v_a − v_b) >= −gap / h` with the barycentric weights (1 − s, s, 1 − t, t), and the
// tangential impulse kept in the static cone, else on the kinetic one. The rods of a group share
// one workgroup (as bindings do, `Item::lane0`), so every phase is a pass over workgroup memory:
//
//   1. each thread publishes its points (position, inverse mass) in `rcw_x`;
//   2. the spheres, dealt out over all threads of the workgroup, in `rcw_s`;
//   3. the sphere pairs (every pair, as the CPU's `AllPairs`: the same pairs as its sweep and
//      prune), appended to `rcw_pairs`;
//   4. the segment pairs of each sphere pair, one thread a pair (`rc_pair`), culled by the
//      segments' reach as on the CPU; the contacts are listed in storage (`rc_list`, one
//      region per workgroup) and each counts itself on its four points (`rcw_cnt`);
//   5. the list is dealt out over the threads in turn, each keeping its share (at most RC_CAP)
//      in registers for the step's sweeps.
//
// Where the CPU resolves the contacts one after another (projected Gauss–Seidel), the GPU
// resolves them all at once after every constraint iteration (Jacobi), each contact seeing its
// points' velocities of the iteration's start. So that contacts sharing a point do not each
// remove the same approach (and overshoot together), a point in m contacts takes part in each
// with m times its inverse mass (mass splitting, Tonge, Coumans & Bender 2012): a contact's
// effective inverse mass is W = Σ c_j² w_j m_j. The impulses are summed per point (`rcw_j`),
// the whole impulse applied, so momentum is conserved and a contact's accumulated impulse is
// what its points received, which keeps the clamping to a push and to the friction cones
// exact. The sums are of integers (fixed point, `RC_FIX`), so they do not depend on the order in
// which the threads add: a step is the same on every run, and a restored snapshot repeats its
// steps bit for bit, as on every other kernel. The fixed point is the CPU's; with few
// iterations the two differ by what each has not yet converged (tests/rod_contact.rs states by
// how much).

// A rod's part in rod contact (layout.rs `StrandG`).
struct Strand {
    xp: u32,
    xs: u32,
    spheres: u32,
    skip: u32,
    radius: f32,
    half_margin: f32,
    mu_s: f32,
    mu_k: f32,
}

@group(0) @binding(29) var<storage, read> strands: array<Strand>;
// The contacts of the step, per workgroup RC_LIST of three words each: (a0, b0, s, t), (n,
// −gap / h), (distance, radii, 0, 0), floats as bits.
@group(0) @binding(32) var<storage, read_write> rc_list: array<vec4<u32>>;
// Contacts a workgroup can list in a step.
const RC_LIST: u32 = WG * RC_CAP;
// Per group, RC_STATS words (sim.rs `RodcBuffers::stats`).
@group(0) @binding(30) var<storage, read_write> rc_stats: array<atomic<u32>>;

const RC_STATS: u32 = 8u;
// Words of `rcw_stat`: the smallest distance of the dispatch and the radii of that pair (f32
// bits), the smallest distance over the radii, contacts and sphere pairs dropped.
const RCW_MIND: u32 = 2u;
const RCW_RAD: u32 = 3u;
const RCW_MINR: u32 = 4u;
const RCW_DROP: u32 = 5u;

// The group's points at the step's start (position; w the inverse mass, or minus the mass of a
// held point), then their velocities at the start of each contact sweep.
var<workgroup> rcw_x: array<vec4<f32>, RC_PTS>;
// Contacts touching each point this step.
var<workgroup> rcw_cnt: array<atomic<u32>, RC_PTS>;
// What each point receives in a sweep, as the velocity change it makes (a held point: the
// impulse over its mass), in units of 1 / RC_FIX m/s: integers, whose sums do not depend on the
// order of the additions.
var<workgroup> rcw_j: array<atomic<i32>, 3 * RC_PTS>;
// 2^20 units per m/s: 9.5e-7 m/s resolution (a point's position moves 1e-11 m per step of 10 µs
// by it), ±2048 m/s range (a contact asking more has diverged).
const RC_FIX: f32 = 1048576.0;
// Bounding spheres: centre, radius (with the rod's radius and half the margin); and which
// segments each covers (`rc_sphere`, as `item`, `first | count << 16`), so that the pair and
// narrow phases look them up in workgroup memory.
var<workgroup> rcw_s: array<vec4<f32>, RC_SPH>;
var<workgroup> rcw_m: array<vec2<u32>, RC_SPH>;
// Overlapping sphere pairs of the step, `i << 16 | j` with i <= j, and their number.
var<workgroup> rcw_pairs: array<u32, RC_PAIRS>;
var<workgroup> rcw_np: atomic<u32>;
// Contacts listed this step.
var<workgroup> rcw_nc: atomic<u32>;
var<workgroup> rcw_stat: array<atomic<u32>, 8>;

// Sphere `q` of the group whose items start at `first`: its item, first segment and segments
// (from the strands; the sphere phase records them in `rcw_m`).
struct RcSphere {
    item: u32,
    first: u32,
    count: u32,
}

fn rc_sphere_of_strands(q: u32, first: u32, count: u32) -> RcSphere {
    var item = first;
    for (var k = 1u; k < count; k++) {
        if q >= strands[first + k].xs {
            item = first + k;
        }
    }
    let seg0 = (q - strands[item].xs) * RC_K;
    return RcSphere(item, seg0, min(RC_K, items[item].n - seg0));
}

// Sphere `q` as the sphere phase recorded it.
fn rc_sphere(q: u32) -> RcSphere {
    let m = rcw_m[q];
    return RcSphere(m.x, m.y & 0xffffu, m.y >> 16u);
}

// Closest points of the segments p1q1 and p2q2 (collide rods.rs `closest_points_segments`,
// Ericson 5.1.9): the parameters (s, t) along each.
fn rc_closest(p1: vec3<f32>, q1: vec3<f32>, p2: vec3<f32>, q2: vec3<f32>) -> vec2<f32> {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = dot(d1, d1);
    let e = dot(d2, d2);
    let f = dot(d2, r);
    let eps = 1.0e-30;
    if a <= eps && e <= eps {
        return vec2<f32>(0.0);
    }
    if a <= eps {
        return vec2<f32>(0.0, clamp(f / e, 0.0, 1.0));
    }
    let c = dot(d1, r);
    if e <= eps {
        return vec2<f32>(clamp(-c / a, 0.0, 1.0), 0.0);
    }
    let b = dot(d1, d2);
    let denom = a * e - b * b;
    var s = 0.0;
    if denom > 0.0 {
        s = clamp((b * f - c * e) / denom, 0.0, 1.0);
    }
    var t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = clamp(-c / a, 0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = clamp((b - c) / a, 0.0, 1.0);
    }
    return vec2<f32>(s, t);
}

// A unit normal for two segments whose centrelines touch exactly (rods.rs `fallback_normal`):
// perpendicular to both if they are not parallel, else to the first, else +z.
fn rc_fallback_normal(d1: vec3<f32>, d2: vec3<f32>) -> vec3<f32> {
    let c = cross(d1, d2);
    let n = length(c);
    if n > 1.0e-30 {
        return c / n;
    }
    let trial = select(vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), abs(d1.x) < 0.9 * length(d1));
    let c2 = cross(d1, trial);
    let n2 = length(c2);
    if n2 > 1.0e-30 {
        return c2 / n2;
    }
    return vec3<f32>(0.0, 0.0, 1.0);
}

// Whether segment pq can come within `reach` of `c` (rods.rs `may_touch`): it lies within half
// its length of its midpoint; conservative, with a slack against rounding.
fn rc_may_touch(p: vec3<f32>, q: vec3<f32>, c: vec3<f32>, reach: f32) -> bool {
    let d = 0.5 * (p + q) - c;
    let r = (0.5 * length(q - p) + reach) * (1.0 + 1.0e-6);
    return dot(d, d) < r * r;
}

// Lists a contact of the step: its points' group entries, parameters, normal and bias, distance
// and radii; counts it on its four points and in the nearest-pair statistics.
fn rc_push(ia: u32, ib: u32, st: vec2<f32>, n: vec3<f32>, dist: f32, radii: f32, list: u32, inv_h: f32) {
    let k = atomicAdd(&rcw_nc, 1u);
    atomicMin(&rcw_stat[RCW_MIND], bitcast<u32>(dist));
    atomicMin(&rcw_stat[RCW_MINR], bitcast<u32>(dist / radii));
    if k >= RC_LIST {
        return;
    }
    let o = list + 3u * k;
    rc_list[o] = vec4<u32>(ia, ib, bitcast<u32>(st.x), bitcast<u32>(st.y));
    rc_list[o + 1u] = bitcast<vec4<u32>>(vec4<f32>(n, (radii - dist) * inv_h));
    rc_list[o + 2u] = vec4<u32>(bitcast<u32>(dist), bitcast<u32>(radii), 0u, 0u);
    atomicAdd(&rcw_cnt[ia], 1u);
    atomicAdd(&rcw_cnt[ia + 1u], 1u);
    atomicAdd(&rcw_cnt[ib], 1u);
    atomicAdd(&rcw_cnt[ib + 1u], 1u);
}

// The segment pairs of the step's sphere pair `q` (rods.rs `narrow`): a sphere with itself only
// j > i, a rod with itself only |i − j| > skip; a segment tested only if it can reach the other
// sphere, a pair only if their midpoints are near enough (all conservative, as there), then
// closest points; a contact where the capsules of radius r + margin / 2 overlap, listed from
// `list` on.
fn rc_pair(q: u32, list: u32, inv_h: f32) {
    let pair = rcw_pairs[q];
    let i = pair >> 16u;
    let j = pair & 0xffffu;
    let sa = rc_sphere(i);
    let sb = rc_sphere(j);
    let ka = strands[sa.item];
    let kb = strands[sb.item];
    let ca = rcw_s[i];
    let cb = rcw_s[j];
    let ra = ka.radius + ka.half_margin;
    let rb = kb.radius + kb.half_margin;
    let rr = ra + rb;
    // The segments of b that can reach sphere a.
    var mask_b = 0u;
    for (var jj = 0u; jj < sb.count; jj++) {
        let ib = kb.xp + sb.first + jj;
        if i == j || rc_may_touch(rcw_x[ib].xyz, rcw_x[ib + 1u].xyz, ca.xyz, ca.w + rb) {
            mask_b |= 1u << jj;
        }
    }
    for (var ii = 0u; ii < sa.count; ii++) {
        let seg_a = sa.first + ii;
        let ia = ka.xp + seg_a;
        let p1 = rcw_x[ia].xyz;
        let q1 = rcw_x[ia + 1u].xyz;
        if i != j && !rc_may_touch(p1, q1, cb.xyz, cb.w + ra) {
            continue;
        }
        let m1 = 0.5 * (p1 + q1);
        let e1 = 0.5 * length(q1 - p1);
        var jj = select(0u, ii + 1u, i == j);
        for (; jj < sb.count; jj++) {
            let seg_b = sb.first + jj;
            // Same rod: b comes after a, so the difference is seg_b − seg_a.
            if (mask_b & (1u << jj)) == 0u || (sa.item == sb.item && seg_b - seg_a <= ka.skip) {
                continue;
            }
            let ib = kb.xp + seg_b;
            let p2 = rcw_x[ib].xyz;
            let q2 = rcw_x[ib + 1u].xyz;
            if !rc_may_touch(p2, q2, m1, e1 + rr) {
                continue;
            }
            let st = rc_closest(p1, q1, p2, q2);
            let d = (p1 + (q1 - p1) * st.x) - (p2 + (q2 - p2) * st.y);
            let d2 = dot(d, d);
            if d2 >= rr * rr {
                continue;
            }
            let dist = sqrt(d2);
            var n = vec3<f32>(0.0);
            if dist > 0.0 {
                n = d / dist;
            } else {
                n = rc_fallback_normal(q1 - p1, q2 - p2);
            }
            rc_push(ia, ib, st, n, dist, ka.radius + kb.radius, list, inv_h);
        }
    }
}

// Adds a contact's impulse `p`, shared by the weights `c` (b's negative), to what its four points
// a0, a0 + 1, b0, b0 + 1 receive in this sweep, as velocity changes: `f` holds each point's
// inverse mass, or for a held point one over its mass (what its thread multiplies back into
// the held end's reaction).
fn rc_add4(ia: u32, ib: u32, c: vec4<f32>, f: vec4<f32>, p: vec3<f32>) {
    let pts = vec4<u32>(ia, ia + 1u, ib, ib + 1u);
    for (var j = 0u; j < 4u; j++) {
        let q = p * (c[j] * f[j] * RC_FIX);
        atomicAdd(&rcw_j[3u * pts[j]], i32(round(q.x)));
        atomicAdd(&rcw_j[3u * pts[j] + 1u], i32(round(q.y)));
        atomicAdd(&rcw_j[3u * pts[j] + 2u], i32(round(q.z)));
    }
}

// Takes what point `k` received in this sweep (a velocity change, m/s) and clears it for the
// next.
fn rc_take(k: u32) -> vec3<f32> {
    return vec3<f32>(
        f32(atomicExchange(&rcw_j[3u * k], 0)),
        f32(atomicExchange(&rcw_j[3u * k + 1u], 0)),
        f32(atomicExchange(&rcw_j[3u * k + 2u], 0)),
    ) * (1.0 / RC_FIX);
}

struct RcResolved {
    // The impulse of this sweep (normal and friction), momentum [N s].
    p: vec3<f32>,
    ln: f32,
    lt: vec3<f32>,
}

// One contact on the relative velocity `v` of its two closest points (rod_contact.rs
// `RodContactSet::sweep`): the accumulated normal impulse `ln` clamped to a push that ends the
// step touching (`bias` = −gap / h), then the accumulated friction impulse `lt` that stops the
// sliding, kept in the static cone, else scaled onto the kinetic one; `w` is the contact's
// (split) effective inverse mass.
fn rc_resolve(v: vec3<f32>, n: vec3<f32>, bias: f32, w: f32, inv_w: f32, ln: f32, lt: vec3<f32>, mu_s: f32, mu_k: f32) -> RcResolved {
    let acc = max(ln + (bias - dot(n, v)) * inv_w, 0.0);
    if acc == 0.0 && ln == 0.0 {
        // Apart and staying apart: no push, and no friction (its cone is empty).
        return RcResolved(vec3<f32>(0.0), 0.0, lt);
    }
    let dn = acc - ln;
    let x = v + n * (dn * w);
    let vt = x - n * dot(n, x);
    let want = lt - vt * inv_w;
    let norm = length(want);
    var nt = vec3<f32>(0.0);
    if norm <= mu_s * acc {
        nt = want;
    } else if norm > 0.0 {
        nt = want * (mu_k * acc / norm);
    }
    return RcResolved(n * dn + (nt - lt), acc, nt);
}
