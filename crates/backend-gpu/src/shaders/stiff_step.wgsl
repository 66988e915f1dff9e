// The stiff scheme's step (backend-cpu `stiff`, `docs/stiff-solver.md`) for many rods at once,
// one rod per workgroup, many steps per dispatch (`stiff.rs` says why and what it leaves out).
//
// The rod's elasticity is a set of compliant constraints (stretch–shear per element, bend–twist
// per interior node); each step predicts the inertial targets and takes Newton iterations of
// the full XPBD system `(J K⁻¹ Jᵀ + α̃) Δλ = −(C + α̃ λ + J u)` until every residual is below the
// tolerance. The step is the CPU's `step_fixed` / `solve_step` / `direct_solve` without
// guides, bindings, varying loads and retakes, pass for pass: `constraints`, `precondition`,
// `rhs`, `assemble`, the banded solve, `apply`, `velocities`, the stretch test. With a mesh
// (`//#if MESH`, `stiff_contact.wgsl`), the contacts' passes and the rounds of the solve. Invocation t
// owns elements (and points, and frames) t·EPT … t·EPT + EPT − 1, the slice the partitioned
// banded solve (`banded_partitioned.wgsl`, put after this file) eliminates; the point past the
// last element belongs to the last invocation. Every pass reads its neighbours' values from
// storage written by an earlier pass, after a barrier.
//
// Everything is in f64 (the adapter's SHADER_F64): the stiff scheme's matrices span more than
// f32 resolves, and its state is kept in f64 on the CPU too. Vulkan has no f64 `sin`, `cos` or
// `atan2`, so the few closed forms the CPU takes for rotations past 1e-2 rad are computed here by
// series with argument halving (`sin_cos`) and a Newton step on an f32 first guess (`atan2_64`).
//
// Prepended by `stiff.rs`: PT, EPT, XCH (as the banded solve), NP = PT·EPT (element slots per
// rod), NPT = NP + 1, and the offsets of the columns of `kc` (K_*), `st` (S_*) and `wk` (W_*) with
// their strides per rod (KS, SS, WS), and the report's stride RS. Columns of vectors hold 3 numbers per entry, of
// quaternions 4 ((x, y, z, w): vector part, then scalar), laid out by `at_entry`.

struct StiffShape {
    // Elements per invocation (EPT) and invocations per rod (PT), read by the banded solve.
    per_thread: u32,
    threads: u32,
    // Steps of this dispatch, Newton iterations at most, the refactorisation policy
    // (0 every step, 1 every iteration, 2 lagged: `Refactor`), rods.
    steps: u32,
    iterations: u32,
    refactor: u32,
    rods: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> band_part: StiffShape;
@group(0) @binding(1) var<storage, read_write> band_rows: array<f64>;
@group(0) @binding(3) var<storage, read_write> band_x: array<f64>;
// h, tolerance, geometric, gravity (3), the squared stretches beyond which a step diverged
// (above, below), the index of the dispatch's first step.
@group(0) @binding(4) var<storage, read> glob: array<f64>;
// Per rod: the constants (`K_*`), the state (`S_*`), the working values of a step (`W_*`).
@group(0) @binding(5) var<storage, read> kc: array<f64>;
@group(0) @binding(6) var<storage, read_write> st: array<f64>;
@group(0) @binding(7) var<storage, read_write> wk: array<f64>;
// Per step of the dispatch, rod and end: the held end's velocity and angular velocity over the
// step (8 numbers: v, 0, ω, 0), as the CPU's `velocities_over`.
@group(0) @binding(8) var<storage, read> motion: array<f64>;
// Per rod, RS numbers: the counters (`ST_*`), then the held ends' reactions (`RE_*`).
@group(0) @binding(9) var<storage, read_write> rep: array<f64>;

// The workgroup's reductions and decisions.
var<workgroup> red: array<f64, PT>;
var<workgroup> red_out: f64;
var<workgroup> fail_element: atomic<u32>;
var<workgroup> fail_word: u32;

const NO_FAIL: u32 = 0xffffffffu;
// What a non-finite residual counts as in the reductions (`max` with NaN is not defined).
const HUGE: f64 = 1.0e300lf;

// ---------------------------------------------------------------------------------------------
// Storage access.

// Columns indexed by element or point are laid out as the banded solve's rows are: number `c`
// of entry `j` (slot `e` of invocation `t`'s slice) at `(c · EPT + e) · PT + t`, so that the
// invocations of a workgroup, each at the same slot of its own slice, read one coalesced run;
// the point past the last slot, in the point columns only, follows at `width · NP + c`.
fn at_entry(j: u32, c: u32, width: u32) -> u32 {
    if j >= NP {
        return width * NP + c;
    }
    return (c * EPT + j % EPT) * PT + j / EPT;
}

fn kx(rod: u32, at: u32) -> f64 {
    return kc[rod * KS + at];
}
fn k3(rod: u32, col: u32, j: u32) -> vec3<f64> {
    let b = rod * KS + col;
    return vec3<f64>(kc[b + at_entry(j, 0u, 3u)], kc[b + at_entry(j, 1u, 3u)], kc[b + at_entry(j, 2u, 3u)]);
}
fn k1(rod: u32, col: u32, j: u32) -> f64 {
    return kc[rod * KS + col + at_entry(j, 0u, 1u)];
}
fn s3(rod: u32, col: u32, j: u32) -> vec3<f64> {
    let b = rod * SS + col;
    return vec3<f64>(st[b + at_entry(j, 0u, 3u)], st[b + at_entry(j, 1u, 3u)], st[b + at_entry(j, 2u, 3u)]);
}
fn put_s3(rod: u32, col: u32, j: u32, v: vec3<f64>) {
    let b = rod * SS + col;
    st[b + at_entry(j, 0u, 3u)] = v.x;
    st[b + at_entry(j, 1u, 3u)] = v.y;
    st[b + at_entry(j, 2u, 3u)] = v.z;
}
fn s4(rod: u32, col: u32, j: u32) -> vec4<f64> {
    let b = rod * SS + col;
    return vec4<f64>(st[b + at_entry(j, 0u, 4u)], st[b + at_entry(j, 1u, 4u)], st[b + at_entry(j, 2u, 4u)], st[b + at_entry(j, 3u, 4u)]);
}
fn put_s4(rod: u32, col: u32, j: u32, v: vec4<f64>) {
    let b = rod * SS + col;
    st[b + at_entry(j, 0u, 4u)] = v.x;
    st[b + at_entry(j, 1u, 4u)] = v.y;
    st[b + at_entry(j, 2u, 4u)] = v.z;
    st[b + at_entry(j, 3u, 4u)] = v.w;
}
fn w3(rod: u32, col: u32, j: u32) -> vec3<f64> {
    let b = rod * WS + col;
    return vec3<f64>(wk[b + at_entry(j, 0u, 3u)], wk[b + at_entry(j, 1u, 3u)], wk[b + at_entry(j, 2u, 3u)]);
}
fn put_w3(rod: u32, col: u32, j: u32, v: vec3<f64>) {
    let b = rod * WS + col;
    wk[b + at_entry(j, 0u, 3u)] = v.x;
    wk[b + at_entry(j, 1u, 3u)] = v.y;
    wk[b + at_entry(j, 2u, 3u)] = v.z;
}
fn w4(rod: u32, col: u32, j: u32) -> vec4<f64> {
    let b = rod * WS + col;
    return vec4<f64>(wk[b + at_entry(j, 0u, 4u)], wk[b + at_entry(j, 1u, 4u)], wk[b + at_entry(j, 2u, 4u)], wk[b + at_entry(j, 3u, 4u)]);
}
fn put_w4(rod: u32, col: u32, j: u32, v: vec4<f64>) {
    let b = rod * WS + col;
    wk[b + at_entry(j, 0u, 4u)] = v.x;
    wk[b + at_entry(j, 1u, 4u)] = v.y;
    wk[b + at_entry(j, 2u, 4u)] = v.z;
    wk[b + at_entry(j, 3u, 4u)] = v.w;
}
// The report's numbers (`rep`).
fn r1(rod: u32, at: u32) -> f64 {
    return rep[rod * RS + at];
}
fn put_r1(rod: u32, at: u32, v: f64) {
    rep[rod * RS + at] = v;
}
fn r3(rod: u32, at: u32) -> vec3<f64> {
    let b = rod * RS + at;
    return vec3<f64>(rep[b], rep[b + 1u], rep[b + 2u]);
}
fn put_r3(rod: u32, at: u32, v: vec3<f64>) {
    let b = rod * RS + at;
    rep[b] = v.x;
    rep[b + 1u] = v.y;
    rep[b + 2u] = v.z;
}
// The clamps' columns, indexed by clamp: contiguous.
fn c3(rod: u32, col: u32, k: u32) -> vec3<f64> {
    let b = rod * WS + col + 3u * k;
    return vec3<f64>(wk[b], wk[b + 1u], wk[b + 2u]);
}
fn put_c3(rod: u32, col: u32, k: u32, v: vec3<f64>) {
    let b = rod * WS + col + 3u * k;
    wk[b] = v.x;
    wk[b + 1u] = v.y;
    wk[b + 2u] = v.z;
}
fn c4(rod: u32, col: u32, k: u32) -> vec4<f64> {
    let b = rod * WS + col + 4u * k;
    return vec4<f64>(wk[b], wk[b + 1u], wk[b + 2u], wk[b + 3u]);
}
fn put_c4(rod: u32, col: u32, k: u32, v: vec4<f64>) {
    let b = rod * WS + col + 4u * k;
    wk[b] = v.x;
    wk[b + 1u] = v.y;
    wk[b + 2u] = v.z;
    wk[b + 3u] = v.w;
}
fn sc4(rod: u32, col: u32, k: u32) -> vec4<f64> {
    let b = rod * SS + col + 4u * k;
    return vec4<f64>(st[b], st[b + 1u], st[b + 2u], st[b + 3u]);
}
fn put_sc4(rod: u32, col: u32, k: u32, v: vec4<f64>) {
    let b = rod * SS + col + 4u * k;
    st[b] = v.x;
    st[b + 1u] = v.y;
    st[b + 2u] = v.z;
    st[b + 3u] = v.w;
}
// A clamp's 3×3 matrix in `wk` (9 numbers, column by column; written out: a loop index into a
// private matrix puts it in local memory on NVIDIA GPUs).
fn wm3(rod: u32, col: u32, k: u32) -> mat3x3<f64> {
    return mat3x3<f64>(c3(rod, col + 9u * k, 0u), c3(rod, col + 9u * k + 3u, 0u), c3(rod, col + 9u * k + 6u, 0u));
}
fn put_wm3(rod: u32, col: u32, k: u32, m: mat3x3<f64>) {
    put_c3(rod, col + 9u * k, 0u, m[0]);
    put_c3(rod, col + 9u * k + 3u, 0u, m[1]);
    put_c3(rod, col + 9u * k + 6u, 0u, m[2]);
}
// The step's held-end motion: end `e` of `rod` at step `s` of the dispatch (v, ω).
fn end_velocity(s: u32, rod: u32, e: u32) -> vec3<f64> {
    let b = ((s * band_part.rods + rod) * 2u + e) * 8u;
    return vec3<f64>(motion[b], motion[b + 1u], motion[b + 2u]);
}
fn end_spin(s: u32, rod: u32, e: u32) -> vec3<f64> {
    let b = ((s * band_part.rods + rod) * 2u + e) * 8u + 4u;
    return vec3<f64>(motion[b], motion[b + 1u], motion[b + 2u]);
}

// ---------------------------------------------------------------------------------------------
// Vectors, quaternions, 3×3 blocks in f64 (WGSL's `cross`, `dot` are not defined for f64).

fn dot3(a: vec3<f64>, b: vec3<f64>) -> f64 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}
fn cross3(a: vec3<f64>, b: vec3<f64>) -> vec3<f64> {
    return vec3<f64>(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
fn norm3(a: vec3<f64>) -> f64 {
    return sqrt(dot3(a, a));
}
fn amax3(a: vec3<f64>) -> f64 {
    return max(max(abs(a.x), abs(a.y)), abs(a.z));
}
fn qmul(a: vec4<f64>, b: vec4<f64>) -> vec4<f64> {
    let v = a.w * b.xyz + b.w * a.xyz + cross3(a.xyz, b.xyz);
    return vec4<f64>(v, a.w * b.w - dot3(a.xyz, b.xyz));
}
fn qconj(a: vec4<f64>) -> vec4<f64> {
    return vec4<f64>(-a.xyz, a.w);
}
fn qnormalise(a: vec4<f64>) -> vec4<f64> {
    return a / sqrt(a.x * a.x + a.y * a.y + a.z * a.z + a.w * a.w);
}
// `conj(a) b` with the sign that makes its scalar part non-negative (the shorter way round).
fn relative(a: vec4<f64>, b: vec4<f64>) -> vec4<f64> {
    let s = qmul(qconj(a), b);
    return select(s, -s, s.w < 0.0lf);
}
// The directors (columns of R) of a unit quaternion, as `cosserat_model::quat::directors`.
fn directors(q: vec4<f64>) -> mat3x3<f64> {
    let x = q.x;
    let y = q.y;
    let z = q.z;
    let w = q.w;
    let ww = w * w;
    let xx = x * x;
    let yy = y * y;
    let zz = z * z;
    return mat3x3<f64>(
        vec3<f64>(ww + xx - yy - zz, 2.0lf * (x * y + w * z), 2.0lf * (x * z - w * y)),
        vec3<f64>(2.0lf * (x * y - w * z), ww - xx + yy - zz, 2.0lf * (y * z + w * x)),
        vec3<f64>(2.0lf * (x * z + w * y), 2.0lf * (y * z - w * x), ww - xx - yy + zz),
    );
}
// `sin x`, `cos x` for |x| ≤ 4 in f64: the series at x/8 (error below 1e-17 there), then
// three doublings.
fn sin_cos(x: f64) -> vec2<f64> {
    let y = x * 0.125lf;
    let y2 = y * y;
    var s = y * (1.0lf - y2 / 6.0lf * (1.0lf - y2 / 20.0lf * (1.0lf - y2 / 42.0lf * (1.0lf - y2 / 72.0lf * (1.0lf - y2 / 110.0lf)))));
    var c = 1.0lf - y2 / 2.0lf * (1.0lf - y2 / 12.0lf * (1.0lf - y2 / 30.0lf * (1.0lf - y2 / 56.0lf * (1.0lf - y2 / 90.0lf * (1.0lf - y2 / 132.0lf)))));
    for (var k = 0u; k < 3u; k++) {
        let s2 = 2.0lf * s * c;
        c = c * c - s * s;
        s = s2;
    }
    return vec2<f64>(s, c);
}
// `atan2(y, x)` for y ≥ 0, x ≥ 0 in f64: f32's, then two Newton steps on `y cos θ − x sin θ`.
fn atan2_64(y: f64, x: f64) -> f64 {
    var a = f64(atan2(f32(y), f32(x)));
    for (var k = 0u; k < 2u; k++) {
        let sc = sin_cos(a);
        a += (y * sc.y - x * sc.x) / (y * sc.x + x * sc.y);
    }
    return a;
}
// `exp(v / 2)`, the unit quaternion of the rotation by `v` (as the CPU's `exp_small`: the
// series below 1e-2 rad, the closed form above).
fn exp_rotation(v: vec3<f64>) -> vec4<f64> {
    let a2 = dot3(v, v);
    if a2 < 1.0e-4lf {
        let h2 = 0.25lf * a2;
        let c = 1.0lf - h2 * (0.5lf - h2 * (1.0lf / 24.0lf - h2 / 720.0lf));
        let s = 0.5lf * (1.0lf - h2 * (1.0lf / 6.0lf - h2 * (1.0lf / 120.0lf - h2 / 5040.0lf)));
        return vec4<f64>(v * s, c);
    }
    let a = sqrt(a2);
    let sc = sin_cos(0.5lf * a);
    return vec4<f64>(v * (sc.x / a), sc.y);
}
// For a unit quaternion with s_w ≥ 0: angle / |s_v| (as the CPU's `angle_over_sin_half`).
fn angle_over_sin_half(s: vec4<f64>) -> f64 {
    let sn2 = dot3(s.xyz, s.xyz);
    if sn2 < 1.0e-4lf && abs(s.w * s.w + sn2 - 1.0lf) < 1.0e-12lf {
        return 2.0lf + sn2 * (1.0lf / 3.0lf + sn2 * (0.15lf + sn2 * (5.0lf / 56.0lf + sn2 * (35.0lf / 576.0lf))));
    }
    if sn2 < 1.0e-4lf * s.w * s.w {
        let t2 = sn2 / (s.w * s.w);
        return 2.0lf / s.w * (1.0lf - t2 * (1.0lf / 3.0lf - t2 * (0.2lf - t2 / 7.0lf)));
    }
    let sn = sqrt(sn2);
    return 2.0lf * atan2_64(sn, s.w) / sn;
}
// 1 / s_w of a unit quaternion (as the CPU's `inv_w`).
fn inv_w(s: vec4<f64>) -> f64 {
    let x2 = dot3(s.xyz, s.xyz);
    if x2 < 1.0e-4lf && abs(s.w * s.w + x2 - 1.0lf) < 1.0e-12lf {
        return 1.0lf + x2 * (0.5lf + x2 * (0.375lf + x2 * (0.3125lf + x2 * 0.2734375lf)));
    }
    if abs(s.w) > 1.0e-12lf {
        return 1.0lf / s.w;
    }
    return 1.0lf;
}
// [v]×.
fn cross_m(v: vec3<f64>) -> mat3x3<f64> {
    return mat3x3<f64>(vec3<f64>(0.0lf, v.z, -v.y), vec3<f64>(-v.z, 0.0lf, v.x), vec3<f64>(v.y, -v.x, 0.0lf));
}
// [c]× + a I.
fn cross_plus(c: vec3<f64>, a: f64) -> mat3x3<f64> {
    return mat3x3<f64>(vec3<f64>(a, c.z, -c.y), vec3<f64>(-c.z, a, c.x), vec3<f64>(c.y, -c.x, a));
}
fn diag_m(w: vec3<f64>) -> mat3x3<f64> {
    return mat3x3<f64>(vec3<f64>(w.x, 0.0lf, 0.0lf), vec3<f64>(0.0lf, w.y, 0.0lf), vec3<f64>(0.0lf, 0.0lf, w.z));
}
// a diag(w) bᵀ.
fn awbt(a: mat3x3<f64>, w: vec3<f64>, b: mat3x3<f64>) -> mat3x3<f64> {
    return a * diag_m(w) * transpose(b);
}
// m⁻¹ by cofactors, zero for a singular m (as nalgebra's `try_inverse` falling back to zero).
fn inverse3(m: mat3x3<f64>) -> mat3x3<f64> {
    let c0 = cross3(m[1], m[2]);
    let c1 = cross3(m[2], m[0]);
    let c2 = cross3(m[0], m[1]);
    let det = dot3(m[0], c0);
    if det == 0.0lf {
        return mat3x3<f64>(vec3<f64>(), vec3<f64>(), vec3<f64>());
    }
    return transpose(mat3x3<f64>(c0, c1, c2)) * (1.0lf / det);
}

// ---------------------------------------------------------------------------------------------
// The rod's constants and the slices.

fn elements(rod: u32) -> u32 {
    return u32(kx(rod, K_ROD));
}
// The first element (and point, and frame) of invocation t's slice.
fn first_of(t: u32) -> u32 {
    return t * EPT;
}
// A clamp's constants: frame, end, stiffness, rest Darboux vector, damping, length.
struct Clamp {
    frame: u32,
    end: u32,
    stiffness: vec3<f64>,
    rest: vec3<f64>,
    damping: f64,
    length: f64,
}
// The rod's clamps, copied into workgroup memory at the start of a dispatch
// (`load_clamps`): the passes look them up for every frame.
var<workgroup> wg_clamps: array<Clamp, 2>;
var<workgroup> wg_clamp_count: u32;
fn clamp_count(rod: u32) -> u32 {
    return wg_clamp_count;
}
fn clamp_of(rod: u32, c: u32) -> Clamp {
    return wg_clamps[c];
}
fn load_clamps(rod: u32, t: u32) {
    if t == 0u {
        wg_clamp_count = u32(kx(rod, K_ROD + 5u));
        wg_clamps[0] = stored_clamp(rod, 0u);
        wg_clamps[1] = stored_clamp(rod, 1u);
    }
    workgroupBarrier();
}
fn stored_clamp(rod: u32, c: u32) -> Clamp {
    let b = K_ROD + 8u + 12u * c;
    return Clamp(
        u32(kx(rod, b)),
        u32(kx(rod, b + 1u)),
        vec3<f64>(kx(rod, b + 2u), kx(rod, b + 3u), kx(rod, b + 4u)),
        vec3<f64>(kx(rod, b + 5u), kx(rod, b + 6u), kx(rod, b + 7u)),
        kx(rod, b + 8u),
        kx(rod, b + 9u),
    );
}
// The node between clamp frame `cf` and end frame `q`: its value `Ω − û` and its Jacobian with
// respect to the end frame's body rotation (as `ClampConst::node`).
struct Node {
    value: vec3<f64>,
    jac: mat3x3<f64>,
}
fn clamp_node(c: Clamp, cf: vec4<f64>, q: vec4<f64>) -> Node {
    var s: vec4<f64>;
    if c.end == 0u {
        s = relative(cf, q);
    } else {
        s = relative(q, cf);
    }
    let il = 1.0lf / c.length;
    let cm = cross_m(s.xyz);
    let wi = diag_m(vec3<f64>(s.w, s.w, s.w));
    let value = s.xyz * (2.0lf * il) - c.rest;
    if c.end == 0u {
        return Node(value, (wi + cm) * il);
    }
    return Node(value, (cm - wi) * il);
}
// The clamp's torque on its end frame at the current iterate (body axes).
fn clamp_torque(rod: u32, ci: u32, c: Clamp, q: vec4<f64>, h: f64) -> vec3<f64> {
    let node = clamp_node(c, c4(rod, W_CLAMP_FRAME, ci), q);
    var f = c.stiffness * node.value;
    if c.damping > 0.0lf {
        f += (node.value - c3(rod, W_CLAMP_START, ci)) * (c.damping / h);
    }
    return -(transpose(node.jac) * f) * c.length;
}
// The first clamp on frame j, or 2 for none.
fn clamp_on(rod: u32, j: u32) -> u32 {
    for (var c = 0u; c < clamp_count(rod); c++) {
        if clamp_of(rod, c).frame == j {
            return c;
        }
    }
    return 2u;
}

// ---------------------------------------------------------------------------------------------
// The passes of a step, each over the invocation's own slice.

// `constraints`: Γ, the directors, the relative rotations and Ω − û at the current iterate.
fn constraints(rod: u32, t: u32, n: u32) {
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        if j >= n {
            break;
        }
        let qa = s4(rod, S_Q, j);
        let d = directors(qa);
        let ed = s3(rod, S_X, j + 1u) - s3(rod, S_X, j);
        let il = k1(rod, K_IL, j);
        let g = vec3<f64>(dot3(d[0], ed), dot3(d[1], ed), dot3(d[2], ed)) * il;
        put_w3(rod, W_GAMMA, j, g - vec3<f64>(0.0lf, 0.0lf, 1.0lf));
        put_w3(rod, W_D0, j, d[0]);
        put_w3(rod, W_D1, j, d[1]);
        put_w3(rod, W_D2, j, d[2]);
        if j + 1u < n {
            let s = relative(qa, s4(rod, S_Q, j + 1u));
            put_w4(rod, W_REL, j, s);
            put_w3(rod, W_OMEGA_C, j, s.xyz * (k1(rod, K_ILB, j) * 2.0lf) - k3(rod, K_RU, j));
        } else {
            put_w4(rod, W_REL, j, vec4<f64>(0.0lf, 0.0lf, 0.0lf, 1.0lf));
            put_w3(rod, W_OMEGA_C, j, vec3<f64>());
        }
    }
}

fn keep_constraint_values(rod: u32, t: u32, n: u32) {
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        if j >= n {
            break;
        }
        put_w3(rod, W_COLD_G, j, w3(rod, W_GAMMA, j));
        put_w3(rod, W_COLD_O, j, w3(rod, W_OMEGA_C, j));
    }
}

fn dirs(rod: u32, j: u32) -> mat3x3<f64> {
    return mat3x3<f64>(w3(rod, W_D0, j), w3(rod, W_D1, j), w3(rod, W_D2, j));
}

// |λ_Ω,j| / l̄_j of the multipliers in column `col` (zero past the last node).
fn bend_bound(rod: u32, col: u32, j: u32, n: u32) -> f64 {
    if j + 1u >= n {
        return 0.0lf;
    }
    return norm3(w3(rod, col, j)) * k1(rod, K_ILB, j);
}

// `precondition`: each frame's `K_θ⁻¹` with the geometric bound σ of the multipliers (the
// previous step's with `previous`), and the clamped end frames' `W`.
fn precondition(rod: u32, t: u32, n: u32, previous: bool, h: f64) {
//#if PINS
    freeze_own(rod, t, n);
//#endif
    let geometric = glob[2];
    let cg = select(W_LAM_G, W_LAMP_G, previous);
    let co = select(W_LAM_O, W_LAMP_O, previous);
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        if j >= n {
            break;
        }
        var before = 0.0lf;
        if j > 0u {
            before = bend_bound(rod, co, j - 1u, n);
        }
        let after = bend_bound(rod, co, j, n);
        let g = w3(rod, W_GAMMA, j) + vec3<f64>(0.0lf, 0.0lf, 1.0lf);
        let g_bound = 0.5lf * (1.0lf + dot3(g, g));
        let lg = norm3(w3(rod, cg, j));
        let sigma = geometric * (2.0lf * lg * g_bound + before + after);
        let i = k3(rod, K_IN, j);
        let d = i + vec3<f64>(sigma, sigma, sigma);
        let inv = k1(rod, K_FREE, j) / (d.x * d.y * d.z);
        put_w3(rod, W_INV_K, j, vec3<f64>(d.y * d.z * inv, d.x * d.z * inv, d.x * d.y * inv));
        // A clamped end frame: W = (K_θ + h² Σ l Jᵀ (K + c/h) J)⁻¹ over the clamps on it.
        for (var ci = 0u; ci < clamp_count(rod); ci++) {
            let c = clamp_of(rod, ci);
            if c.frame != j {
                continue;
            }
            var m = diag_m(d);
            let q = s4(rod, S_Q, j);
            for (var di = 0u; di < clamp_count(rod); di++) {
                let dc = clamp_of(rod, di);
                if dc.frame == j {
                    let node = clamp_node(dc, c4(rod, W_CLAMP_FRAME, di), q);
                    let stiff = dc.stiffness + vec3<f64>(1.0lf, 1.0lf, 1.0lf) * (dc.damping / h);
                    m += transpose(node.jac) * diag_m(stiff) * node.jac * (dc.length * h * h);
                }
            }
            put_wm3(rod, W_CLAMP_W, ci, inverse3(m));
            put_c3(rod, W_CLAMP_K, ci, d);
        }
    }
}

// The stretch–shear term `R μ_Γ / l0` of element j (zero outside the rod).
fn point_term(rod: u32, mu_col: u32, j: i32, n: u32, solved: bool) -> vec3<f64> {
    if j < 0 || u32(j) >= n {
        return vec3<f64>();
    }
    let jj = u32(j);
    var mu: vec3<f64>;
    if solved {
        mu = solution(rod, jj).u;
    } else {
        mu = w3(rod, mu_col, jj);
    }
    return dirs(rod, jj) * mu * k1(rod, K_IL, jj);
}

// The solved increments of element j from the banded solve (Γ part `u`, Ω part `v`).
fn solution(rod: u32, j: u32) -> V6 {
    return load_f(rod, j % EPT, j / EPT);
}

// `J_θᵀ μ` on frame j: μ_Γ × g from its element, the bend–twist terms of the nodes j − 1 and j.
fn frame_term(rod: u32, j: u32, n: u32, solved: bool) -> vec3<f64> {
    var mg: vec3<f64>;
    var mo: vec3<f64>;
    var mo_before = vec3<f64>();
    if solved {
        let x = solution(rod, j);
        mg = x.u;
        mo = x.v;
        if j > 0u {
            mo_before = solution(rod, j - 1u).v;
        }
    } else {
        mg = w3(rod, W_LAM_G, j);
        mo = w3(rod, W_LAM_O, j);
        if j > 0u {
            mo_before = w3(rod, W_LAM_O, j - 1u);
        }
    }
    let g = w3(rod, W_GAMMA, j) + vec3<f64>(0.0lf, 0.0lf, 1.0lf);
    var out = cross3(mg, g);
    if j + 1u < n {
        let s = w4(rod, W_REL, j);
        out -= (mo * s.w + cross3(s.xyz, mo)) * k1(rod, K_ILB, j);
    }
    if j > 0u {
        let s = w4(rod, W_REL, j - 1u);
        out += (mo_before * s.w - cross3(s.xyz, mo_before)) * k1(rod, K_ILB, j - 1u);
    }
    return out;
}

// Whether point i is the invocation's (its slice, and the last point for the last one).
fn own_point(t: u32, e: u32, n: u32) -> bool {
    let i = first_of(t) + e;
    if e == EPT {
        return t == PT - 1u && i <= n;
    }
    return i <= n;
}

// `rhs`, first half: `u_x = x̃ − x + M⁻¹ Jᵀ λ`, `u_θ` (the clamped end frames' through `W`).
// With contacts, a pinned point's `u` is its pin's (`pinned_balance`); returns the largest of
// their residuals and of their friction's imbalances.
fn rhs_updates(rod: u32, t: u32, n: u32, lambda_zero: bool, h: f64) -> vec2<f64> {
    var pinned = vec2<f64>();
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        var u = s3(rod, S_X_PRED, i) - s3(rod, S_X, i);
        if !lambda_zero {
            let f = point_term(rod, W_LAM_G, i32(i) - 1, n, false) - point_term(rod, W_LAM_G, i32(i), n, false);
            u += f * k1(rod, K_IM, i);
        }
//#if PINS
        if is_pinned(rod, i) && k1(rod, K_IM, i) > 0.0lf {
            u = pinned_balance(rod, i, n, u, &pinned);
        }
//#endif
        put_w3(rod, W_UX, i, u);
    }
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        if j >= n {
            break;
        }
        let q = s4(rod, S_Q, j);
        let s = qmul(qconj(q), w4(rod, W_Q_PRED, j));
        let to_target = s.xyz * (2.0lf * inv_w(s));
        var dth = vec3<f64>();
        if !lambda_zero {
            dth = frame_term(rod, j, n, false);
        }
        put_w3(rod, W_DTHETA, j, dth);
        var u = to_target + dth * w3(rod, W_INV_K, j);
        let ci = clamp_on(rod, j);
        if ci < 2u {
            var r = c3(rod, W_CLAMP_K, ci) * to_target + dth;
            for (var di = 0u; di < clamp_count(rod); di++) {
                let dc = clamp_of(rod, di);
                if dc.frame == j {
                    r += clamp_torque(rod, di, dc, q, h) * (h * h);
                }
            }
            u = wm3(rod, W_CLAMP_W, ci) * r;
        }
        put_w3(rod, W_UTH, j, u);
    }
    return pinned;
}

// `rhs`, second half: the right-hand side `−(C + α̃ λ − γ C_n + J u)` of every row into the
// banded solve's vector (zero in the padding), and the largest residual of the slice.
fn rhs_rows(rod: u32, t: u32, n: u32) -> f64 {
    var worst = 0.0lf;
    let damped = kx(rod, K_ROD + 2u) > 0.0lf;
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        var rg = vec3<f64>();
        var ro = vec3<f64>();
        if j < n {
            let il = k1(rod, K_IL, j);
            let du = w3(rod, W_UX, j + 1u) - w3(rod, W_UX, j);
            let ua = w3(rod, W_UTH, j);
            let g = w3(rod, W_GAMMA, j) + vec3<f64>(0.0lf, 0.0lf, 1.0lf);
            let d = dirs(rod, j);
            let ju = vec3<f64>(dot3(d[0], du), dot3(d[1], du), dot3(d[2], du)) * il + cross3(g, ua);
            var res = w3(rod, W_GAMMA, j) + k3(rod, K_AG, j) * w3(rod, W_LAM_G, j);
            if damped {
                res -= k3(rod, K_DG, j) * w3(rod, W_COLD_G, j);
            }
            rg = -(res + ju);
            worst = max(worst, max(amax3(res), amax3(ju)));
            if j + 1u < n {
                let ub = w3(rod, W_UTH, j + 1u);
                let s = w4(rod, W_REL, j);
                let jo = ((ub - ua) * s.w + cross3(s.xyz, ua + ub)) * k1(rod, K_ILB, j);
                var reso = w3(rod, W_OMEGA_C, j) + k3(rod, K_AO, j) * w3(rod, W_LAM_O, j);
                if damped {
                    reso -= k3(rod, K_DO, j) * w3(rod, W_COLD_O, j);
                }
                ro = -(reso + jo);
                worst = max(worst, max(amax3(reso), amax3(jo)) * k1(rod, K_LB, j));
            }
        }
        store_x(rod, e, t, V6(rg, ro));
    }
    // NaN anywhere: a residual that fails every test.
    if !(worst <= HUGE) {
        worst = HUGE;
    }
    return worst;
}

// The upper triangle of a symmetric block into the rows (00 01 02 11 12 22) at number q0.
fn put_rows_sym(rod: u32, e: u32, t: u32, q0: u32, m: mat3x3<f64>) {
    let b = (rod * EPT + e) * PQ;
    band_rows[(b + q0) * PT + t] = m[0][0];
    band_rows[(b + q0 + 1u) * PT + t] = m[1][0];
    band_rows[(b + q0 + 2u) * PT + t] = m[2][0];
    band_rows[(b + q0 + 3u) * PT + t] = m[1][1];
    band_rows[(b + q0 + 4u) * PT + t] = m[2][1];
    band_rows[(b + q0 + 5u) * PT + t] = m[2][2];
}
// A block row-major into the rows at number q0.
fn put_rows_block(rod: u32, e: u32, t: u32, q0: u32, m: mat3x3<f64>) {
    let b = (rod * EPT + e) * PQ + q0;
    band_rows[b * PT + t] = m[0][0];
    band_rows[(b + 1u) * PT + t] = m[1][0];
    band_rows[(b + 2u) * PT + t] = m[2][0];
    band_rows[(b + 3u) * PT + t] = m[0][1];
    band_rows[(b + 4u) * PT + t] = m[1][1];
    band_rows[(b + 5u) * PT + t] = m[2][1];
    band_rows[(b + 6u) * PT + t] = m[0][2];
    band_rows[(b + 7u) * PT + t] = m[1][2];
    band_rows[(b + 8u) * PT + t] = m[2][2];
}

// `assemble` (with `clamp_blocks`): `J K⁻¹ Jᵀ + α̃` of the slice's elements, identity rows for
// the padding and the last element's missing bend–twist row.
fn assemble(rod: u32, t: u32, n: u32) {
    let zero = mat3x3<f64>(vec3<f64>(), vec3<f64>(), vec3<f64>());
    let one = diag_m(vec3<f64>(1.0lf, 1.0lf, 1.0lf));
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        if j >= n {
            put_rows_sym(rod, e, t, 0u, one);
            put_rows_block(rod, e, t, 6u, zero);
            put_rows_block(rod, e, t, 15u, zero);
            put_rows_sym(rod, e, t, 24u, one);
            put_rows_block(rod, e, t, 30u, zero);
            put_rows_block(rod, e, t, 39u, zero);
            continue;
        }
        let bends = j + 1u < n;
        let next_bends = j + 2u < n;
        let g = w3(rod, W_GAMMA, j) + vec3<f64>(0.0lf, 0.0lf, 1.0lf);
        let wa = w3(rod, W_INV_K, j);
        let il = k1(rod, K_IL, j);
        let wm = k1(rod, K_IM, j);
        let wm1 = k1(rod, K_IM, j + 1u);
        let d = dirs(rod, j);
        let gx = cross_m(g);
        // Γ_j.
        let d0 = d[0];
        let diag = (wm + wm1) * il * il * dot3(d0, d0);
        var dg = awbt(gx, wa, gx) + diag_m(vec3<f64>(diag, diag, diag) + k3(rod, K_AG, j));
        var gnext = zero;
        var gsecond = zero;
        var odiag = one;
        var onext = zero;
        var osecond = zero;
        if bends {
            let wb = w3(rod, W_INV_K, j + 1u);
            let il1 = k1(rod, K_IL, j + 1u);
            let ilb = k1(rod, K_ILB, j);
            let s = w4(rod, W_REL, j);
            let a = s.w * ilb;
            let cv = s.xyz * ilb;
            let da = cross_plus(cv, -a);
            let db = cross_plus(cv, a);
            let d1 = dirs(rod, j + 1u);
            let g1 = w3(rod, W_GAMMA, j + 1u) + vec3<f64>(0.0lf, 0.0lf, 1.0lf);
            gnext = awbt(gx, wa, da);
            // −w_{j+1} R_jᵀ R_{j+1} / (l0 l0'): entry (r, q) = d_r · d1_q.
            gsecond = transpose(d) * d1 * (-(wm1 * il * il1));
            odiag = awbt(da, wa, da) + awbt(db, wb, db) + diag_m(k3(rod, K_AO, j));
            onext = awbt(db, wb, cross_m(g1));
            if next_bends {
                let ilb1 = k1(rod, K_ILB, j + 1u);
                let s1 = w4(rod, W_REL, j + 1u);
                osecond = awbt(db, wb, cross_plus(s1.xyz * ilb1, -(s1.w * ilb1)));
            }
        }
//#if PINS
        // The pinned points' directions, as the CPU's `pin_blocks` (before the clamps' terms).
        pin_rows(rod, j, n, &dg, &gsecond);
//#endif
        // The clamped end frames' terms (their K_θ⁻¹ above is zero).
        for (var ci = 0u; ci < clamp_count(rod); ci++) {
            let c = clamp_of(rod, ci);
            if clamp_on(rod, c.frame) != ci {
                continue;
            }
            let f = c.frame;
            let w = wm3(rod, W_CLAMP_W, ci);
            if f == j {
                dg += gx * w * transpose(gx);
            }
            if n < 2u {
                continue;
            }
            if f == 0u && j == 0u {
                let s = w4(rod, W_REL, 0u);
                let ilb = k1(rod, K_ILB, 0u);
                let da = cross_plus(s.xyz * ilb, -(s.w * ilb));
                odiag += da * w * transpose(da);
                gnext += gx * w * transpose(da);
            }
            if f == n - 1u && j + 2u == n {
                let s = w4(rod, W_REL, j);
                let ilb = k1(rod, K_ILB, j);
                let db = cross_plus(s.xyz * ilb, s.w * ilb);
                let gf = cross_m(w3(rod, W_GAMMA, f) + vec3<f64>(0.0lf, 0.0lf, 1.0lf));
                odiag += db * w * transpose(db);
                onext += db * w * transpose(gf);
            }
        }
        put_rows_sym(rod, e, t, 0u, dg);
        put_rows_block(rod, e, t, 6u, gnext);
        put_rows_block(rod, e, t, 15u, gsecond);
        put_rows_sym(rod, e, t, 24u, odiag);
        put_rows_block(rod, e, t, 30u, onext);
        put_rows_block(rod, e, t, 39u, osecond);
    }
}

// `apply`: `Δx = u + M⁻¹ Jᵀ Δλ`, `Δθ = u_θ + K_θ⁻¹ J_θᵀ Δλ` (the clamped frames' through `W`),
// `λ += Δλ`. It reads its neighbours' increments from the solve's vector and writes only its
// own slice. With contacts, a pinned point moves as its pin lets it (`pinned_update`), and a
// Newton step that would move some point further than `max_move` is shortened as a whole.
fn apply(rod: u32, t: u32, n: u32, max_move: f64) {
//#if PINS
    var longest = 0.0lf;
//#endif
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        let f = point_term(rod, 0u, i32(i) - 1, n, true) - point_term(rod, 0u, i32(i), n, true);
//#if PINS
        var u = w3(rod, W_UX, i) + f * k1(rod, K_IM, i);
        if is_pinned(rod, i) {
            u = pinned_update(rod, i, w3(rod, W_UX, i), f * k1(rod, K_IM, i));
        }
        put_w3(rod, W_UX, i, u);
        longest = max(longest, dot3(u, u));
//#else
        let u = w3(rod, W_UX, i) + f * k1(rod, K_IM, i);
        put_s3(rod, S_X, i, s3(rod, S_X, i) + u);
//#endif
    }
//#if PINS
    var scale = 1.0lf;
//#if MESH
    let reach = sqrt(workgroup_max(t, longest));
    if reach > max_move {
        scale = max_move / reach;
    }
//#endif
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        put_s3(rod, S_X, i, s3(rod, S_X, i) + w3(rod, W_UX, i) * scale);
    }
//#endif
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        if j >= n {
            break;
        }
        let dth = frame_term(rod, j, n, true);
        var th = w3(rod, W_UTH, j) + dth * w3(rod, W_INV_K, j);
        let ci = clamp_on(rod, j);
        if ci < 2u {
            th = w3(rod, W_UTH, j) + wm3(rod, W_CLAMP_W, ci) * dth;
        }
//#if PINS
        th *= scale;
//#endif
        let q = s4(rod, S_Q, j);
        put_s4(rod, S_Q, j, qnormalise(qmul(q, vec4<f64>(th * 0.5lf, 1.0lf))));
        // The element's own multipliers (no pass of this one reads them).
//#if PINS
        let x = V6(solution(rod, j).u * scale, solution(rod, j).v * scale);
//#else
        let x = solution(rod, j);
//#endif
        put_w3(rod, W_LAM_G, j, w3(rod, W_LAM_G, j) + x.u);
        if j + 1u < n {
            put_w3(rod, W_LAM_O, j, w3(rod, W_LAM_O, j) + x.v);
        }
    }
}

// The reactions at the held ends after an accepted step (the CPU's `record_reactions`): the held
// point's momentum balance `F = m (v − v_start)/h − m g − f_load − J_rᵀ λ / h²` and, for a clamped
// end, the clamp's torque on the end frame in world axes; each filtered as `Reactions::finish`
// does (weights `keep`, `from_old`, `from_new` of `reaction_filter_weights` in `glob`).
fn record_reactions(rod: u32, n: u32, h: f64, holds: vec2<bool>, gravity: vec3<f64>) {
    let keep = glob[9];
    let from_old = glob[10];
    let from_new = glob[11];
    for (var e = 0u; e < 2u; e++) {
        if !holds[e] {
            continue;
        }
        let point = select(n, 0u, e == 0u);
        let m = kx(rod, K_ROD + 6u + e);
        let lam = point_term(rod, W_LAM_G, i32(point) - 1, n, false) - point_term(rod, W_LAM_G, i32(point), n, false);
        let force = gravity * m + k3(rod, K_F, point) + lam / (h * h);
        let v_start = w3(rod, W_V_START, point);
        let raw_f = (s3(rod, S_V, point) - v_start) * (m / h) - force;
        var raw_t = vec3<f64>();
        for (var ci = 0u; ci < clamp_count(rod); ci++) {
            let c = clamp_of(rod, ci);
            if c.end == e {
                let q = s4(rod, S_Q, c.frame);
                raw_t = directors(q) * clamp_torque(rod, ci, c, q, h);
            }
        }
        let b = RE + RE_END * e;
        let old_f = r3(rod, b);
        let old_t = r3(rod, b + 3u);
        let f = r3(rod, b + 6u) * keep + old_f * from_old + raw_f * from_new;
        let tq = r3(rod, b + 9u) * keep + old_t * from_old + raw_t * from_new;
        put_r3(rod, b, raw_f);
        put_r3(rod, b + 3u, raw_t);
        put_r3(rod, b + 6u, f);
        put_r3(rod, b + 9u, tq);
        put_r1(rod, RE_MAX, max(r1(rod, RE_MAX), norm3(f)));
    }
}

// The largest of `v` over the workgroup (every invocation calls it).
fn workgroup_max(t: u32, v: f64) -> f64 {
    red[t] = v;
    workgroupBarrier();
    for (var s = PT / 2u; s > 0u; s /= 2u) {
        if t < s {
            red[t] = max(red[t], red[t + s]);
        }
        workgroupBarrier();
    }
    if t == 0u {
        red_out = red[0];
    }
    return workgroupUniformLoad(&red_out);
}

// The residual of an iteration: the rows' largest, and with contacts the pinned points'
// (`Work::rhs`) and their friction's imbalance times the tolerance (`direct_solve`).
fn residual_of(rows: f64, pinned: vec2<f64>, tolerance: f64) -> f64 {
//#if PINS
    let r = max(rows, max(pinned.x, tolerance * pinned.y));
    if !(r <= HUGE) {
        return HUGE;
    }
    return r;
//#else
    return rows;
//#endif
}

// The bits of `bits` set by any invocation (every invocation calls it).
var<workgroup> or_bits: atomic<u32>;
var<workgroup> or_out: u32;
fn workgroup_or(t: u32, bits: u32) -> u32 {
    if t == 0u {
        atomicStore(&or_bits, 0u);
    }
    workgroupBarrier();
    if bits != 0u {
        atomicOr(&or_bits, bits);
    }
    workgroupBarrier();
    if t == 0u {
        or_out = atomicLoad(&or_bits);
    }
    return workgroupUniformLoad(&or_out);
}

// A barrier for storage and workgroup memory both.
fn sync() {
    storageBarrier();
    workgroupBarrier();
}

// The per-rod counters in `rep`: iterations, factorisations, steps above the
// tolerance, the largest residual, the step it was met at, the last step above the tolerance
// (−1: none), whether the factorisation in `band_rows` fits (1), and a divergence: step,
// element, kind (1 frame not finite, 2 strain, 3 residual not finite, 4 position not finite;
// 0: none), value (the stretch, or the residual).
const ST_ITER: u32 = 0u;
const ST_FACT: u32 = 1u;
const ST_UNCONV: u32 = 2u;
const ST_MAXRES: u32 = 3u;
const ST_WORST: u32 = 4u;
const ST_LASTUN: u32 = 5u;
const ST_VALID: u32 = 6u;
const ST_DSTEP: u32 = 7u;
const ST_DEL: u32 = 8u;
const ST_DKIND: u32 = 9u;
const ST_DVAL: u32 = 10u;
// With contacts: the points pinned at the end of the last step, the most so far, the deepest
// penetration, the most points behind the wall at a step's end, the swept tests' catches, the
// element contacts, the steps counted, and the tree walks of the queries.
const ST_CONT: u32 = 11u;
const ST_MAXC: u32 = 12u;
const ST_PEN: u32 = 13u;
const ST_ESC: u32 = 14u;
const ST_SWEPT: u32 = 15u;
const ST_SEG: u32 = 41u;
const ST_CSTEPS: u32 = 42u;
const ST_WALKS: u32 = 43u;
// Then per end (RE_END numbers each from RE): the raw force and torque of the last step, the
// filtered force and torque; then the largest filtered force so far.
const RE: u32 = 16u;
const RE_END: u32 = 12u;
const RE_MAX: u32 = 40u;

@compute @workgroup_size(PT)
fn stiff_step(@builtin(local_invocation_index) t: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let rod = wid.x;
    load_clamps(rod, t);
    let n = elements(rod);
    let h = glob[0];
    let tolerance = glob[1];
    let gravity = vec3<f64>(glob[3], glob[4], glob[5]);
    let above = glob[6];
    let below = glob[7];
    let first_step = glob[8];
    let damped = kx(rod, K_ROD + 2u) > 0.0lf;
    let drag = 1.0lf / (1.0lf + h * kx(rod, K_ROD + 1u));
    let holds = vec2<bool>(kx(rod, K_ROD + 3u) > 0.0lf, kx(rod, K_ROD + 4u) > 0.0lf);
    // Whether the factorisation (the rows in `band_rows`) fits, kept from the last dispatch,
    // and whether the rod stopped at a divergence (nothing more is stepped until the host
    // writes a state).
    if t == 0u {
        fail_word = u32(r1(rod, ST_VALID)) | select(0u, 2u, r1(rod, ST_DKIND) != 0.0lf);
    }
//#if MESH
    if t == 0u {
        for (var k = 0u; k < 4u; k++) {
            atomicStore(&wg_counts[k], 0u);
        }
    }
//#endif
    let word = workgroupUniformLoad(&fail_word);
    var factor_valid = (word & 1u) != 0u;
    if (word & 2u) != 0u {
        return;
    }
    for (var step = 0u; step < band_part.steps; step++) {
        // 1. Prediction.
        if damped {
            // Each invocation keeps its own slice's values: no barrier between the two.
            constraints(rod, t, n);
            keep_constraint_values(rod, t, n);
        }
        if t == 0u {
            // The clamp frames at the end of the step, and the nodes at its start (damping).
            for (var ci = 0u; ci < clamp_count(rod); ci++) {
                let c = clamp_of(rod, ci);
                let base = sc4(rod, S_CLAMP, c.end);
                let frame = qnormalise(qmul(exp_rotation(end_spin(step, rod, c.end) * h), base));
                put_c4(rod, W_CLAMP_FRAME, ci, frame);
                var start = vec3<f64>();
                if c.damping > 0.0lf {
                    start = clamp_node(c, base, s4(rod, S_Q, c.frame)).value;
                }
                put_c3(rod, W_CLAMP_START, ci, start);
            }
        }
        // (The end frames are read above before the prediction turns them.)
        sync();
        for (var e = 0u; e <= EPT; e++) {
            if !own_point(t, e, n) {
                break;
            }
            let i = first_of(t) + e;
            let x = s3(rod, S_X, i);
            var v = s3(rod, S_V, i);
            put_w3(rod, W_X_OLD, i, x);
            put_w3(rod, W_V_START, i, v);
            put_s3(rod, S_X, i, x + v * h);
            let w = k1(rod, K_IM, i);
            if w > 0.0lf {
                v += gravity * h;
                // Constant point loads, after gravity (as the CPU's `predict`).
                v += k3(rod, K_F, i) * (w * h);
            }
            let end = select(2u, select(1u, 0u, i == 0u), i == 0u || i == n);
            if end < 2u && holds[end] {
                v = end_velocity(step, rod, end);
                put_s3(rod, S_X, i, x + v * h);
            }
            put_s3(rod, S_V, i, v);
            put_s3(rod, S_X_PRED, i, x + v * h);
        }
        for (var e = 0u; e < EPT; e++) {
            let j = first_of(t) + e;
            if j >= n {
                break;
            }
            let q = s4(rod, S_Q, j);
            put_w4(rod, W_Q_OLD, j, q);
            let o = s3(rod, S_OMEGA, j);
            // The gyroscopic term as the exact precession of (ω₁, ω₂) by h (J − I)/I ω₃.
            let tt = h * 0.5lf * o.z * (k3(rod, K_IN, j).z * k3(rod, K_IIO, j).x - 1.0lf);
            let inv = 1.0lf / (tt * tt + 1.0lf);
            let cs = (1.0lf - tt * tt) * inv;
            let sn = (tt + tt) * inv;
            let om = vec3<f64>(cs * o.x - sn * o.y, sn * o.x + cs * o.y, o.z);
            put_s3(rod, S_OMEGA, j, om);
            let qn = qnormalise(qmul(q, exp_rotation(om * h)));
            put_s4(rod, S_Q, j, qn);
            put_w4(rod, W_Q_PRED, j, qn);
            put_w3(rod, W_LAM_G, j, vec3<f64>());
            put_w3(rod, W_LAM_O, j, vec3<f64>());
        }
        sync();
//#if PINS
        clear_pins(rod, t, n);
//#endif
//#if GUIDE
        guide_pins(rod, t, n);
//#endif
//#if MESH
        contact_begin(rod, t, n, h);
        sync();
        let max_move = ITERATION_MOVE * rod_radius(rod);
//#else
        let max_move = HUGE;
//#endif
        // 2. Newton iterations (`direct_solve`), in rounds while the contacts change
        // (`solve_step`): one, and one more each time they change (at most MAX_ROUNDS more),
        // continuing from the multipliers reached; rounds after the first are solved to
        // LOOSE_ROUND times the tolerance, and only one whose contacts then hold still is
        // finished at the tolerance.
        var lambda_zero = true;
        var previous = HUGE * 10.0lf;
        var residual = 0.0lf;
        var used = 0u;
        var first = true;
        var loose = false;
        var round = 0u;
        loop {
            var round_tolerance = tolerance;
//#if MESH
            if loose {
                round_tolerance = LOOSE_ROUND * tolerance;
            }
//#endif
            // Whether the last iteration pinned points (the matrix changed).
            var pins_changed = false;
            for (var it = 0u; it <= band_part.iterations; it++) {
                let last = it == band_part.iterations;
                if last && tolerance <= 0.0lf {
                    break;
                }
                var refactor = !factor_valid || pins_changed || band_part.refactor == 1u || (band_part.refactor == 0u && it == 0u && first);
                constraints(rod, t, n);
                if refactor && !last {
                    // Its own slice's constraints only: no barrier between the two.
                    precondition(rod, t, n, first && it == 0u, h);
                }
                sync();
                var pinned = rhs_updates(rod, t, n, lambda_zero, h);
                sync();
                residual = workgroup_max(t, residual_of(rhs_rows(rod, t, n), pinned, round_tolerance));
                if (residual <= round_tolerance && it > 0u) || last {
                    break;
                }
                if !refactor && residual > 0.25lf * previous {
                    // An iteration that contracted by less than 4×: refactorise with the current
                    // multipliers.
                    precondition(rod, t, n, false, h);
                    sync();
                    pinned = rhs_updates(rod, t, n, lambda_zero, h);
                    sync();
                    residual = workgroup_max(t, residual_of(rhs_rows(rod, t, n), pinned, round_tolerance));
                    refactor = true;
                }
                if refactor {
                    assemble(rod, t, n);
                    factor_valid = true;
                    if t == 0u {
                        put_r1(rod, ST_FACT, r1(rod, ST_FACT) + 1.0lf);
                    }
                }
                previous = residual;
                sync();
                partitioned_solve(rod, t);
                sync();
                apply(rod, t, n, max_move);
                lambda_zero = false;
                used += 1u;
                sync();
//#if MESH
                pins_changed = (workgroup_or(t, catch_penetrations(rod, t, n, h)) & 2u) != 0u;
                sync();
//#endif
            }
            first = false;
//#if MESH
            let update = workgroup_or(t, contact_update(rod, t, n, h));
            sync();
            let resolve = (update & 1u) != 0u;
            let matrix_changed = (update & 2u) != 0u;
            if loose && !resolve && residual <= tolerance {
                break;
            }
            if loose && !resolve {
                // The contacts held still at the loose tolerance: finish the round at the step's
                // own.
                loose = false;
                if matrix_changed {
                    factor_valid = false;
                }
                continue;
            }
            if !resolve || round == MAX_ROUNDS {
                break;
            }
            round += 1u;
            loose = round < MAX_ROUNDS;
            previous = HUGE * 10.0lf;
            if matrix_changed {
                factor_valid = false;
            }
//#else
            break;
//#endif
        }
//#if MESH
        contact_record(rod, t, n);
//#endif
        // 3. The step's record, velocities, the divergence test.
        let global_step = first_step + f64(step);
        let unconverged = tolerance > 0.0lf && !(residual <= tolerance);
        if t == 0u {
            put_r1(rod, ST_ITER, r1(rod, ST_ITER) + f64(used));
            if unconverged {
                put_r1(rod, ST_UNCONV, r1(rod, ST_UNCONV) + 1.0lf);
                put_r1(rod, ST_LASTUN, global_step);
            }
            if residual > r1(rod, ST_MAXRES) {
                put_r1(rod, ST_MAXRES, residual);
                put_r1(rod, ST_WORST, global_step);
            }
            for (var ci = 0u; ci < clamp_count(rod); ci++) {
                put_sc4(rod, S_CLAMP, clamp_of(rod, ci).end, c4(rod, W_CLAMP_FRAME, ci));
            }
            atomicStore(&fail_element, NO_FAIL);
        }
        let scale = drag / h;
        for (var e = 0u; e <= EPT; e++) {
            if !own_point(t, e, n) {
                break;
            }
            let i = first_of(t) + e;
            put_s3(rod, S_V, i, (s3(rod, S_X, i) - w3(rod, W_X_OLD, i)) * scale);
        }
        // The reset of `fail_element` above before any invocation's test below.
        workgroupBarrier();
        for (var e = 0u; e < EPT; e++) {
            let j = first_of(t) + e;
            if j >= n {
                break;
            }
            put_w3(rod, W_LAMP_G, j, w3(rod, W_LAM_G, j));
            put_w3(rod, W_LAMP_O, j, w3(rod, W_LAM_O, j));
            let q = s4(rod, S_Q, j);
            let s = relative(w4(rod, W_Q_OLD, j), q);
            put_s3(rod, S_OMEGA, j, s.xyz * (angle_over_sin_half(s) / h));
            let r2 = dot3(s3(rod, S_X, j + 1u) - s3(rod, S_X, j), s3(rod, S_X, j + 1u) - s3(rod, S_X, j))
                * k1(rod, K_IL, j) * k1(rod, K_IL, j);
            let finite = (q.x + q.y + q.z + q.w) * 0.0lf;
            if !((finite + r2) <= above && r2 >= below) {
                atomicMin(&fail_element, j);
            }
        }
        workgroupBarrier();
        storageBarrier();
        if t == 0u {
            record_reactions(rod, n, h, holds, gravity);
        }
        if t == 0u {
            fail_word = atomicLoad(&fail_element);
            if residual >= HUGE && fail_word == NO_FAIL {
                fail_word = 0u;
            }
        }
        let failed = workgroupUniformLoad(&fail_word);
        if failed != NO_FAIL {
            if t == 0u {
                let q = s4(rod, S_Q, failed);
                let d = s3(rod, S_X, failed + 1u) - s3(rod, S_X, failed);
                let r2 = dot3(d, d) * k1(rod, K_IL, failed) * k1(rod, K_IL, failed);
                var kind = 2.0lf;
                var value = sqrt(r2);
                if !((q.x + q.y + q.z + q.w) * 0.0lf == 0.0lf) {
                    kind = 1.0lf;
                } else if !(r2 <= HUGE) {
                    kind = 4.0lf;
                } else if residual >= HUGE {
                    kind = 3.0lf;
                    value = residual;
                }
                put_r1(rod, ST_DSTEP, global_step);
                put_r1(rod, ST_DEL, f64(failed));
                put_r1(rod, ST_DVAL, value);
                put_r1(rod, ST_DKIND, kind);
                put_r1(rod, ST_VALID, 0.0lf);
            }
            return;
        }
        sync();
    }
    if t == 0u {
        put_r1(rod, ST_VALID, select(0.0lf, 1.0lf, factor_valid));
    }
}
