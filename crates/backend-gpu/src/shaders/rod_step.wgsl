// The CoRdE time-step (paper Fig. 5 without collisions) for one window of one rod per workgroup,
// or (SUBGROUP) for one rod per subgroup, several rods per workgroup.
//
// Composed by src/shader.rs as: a prelude of constants (WG, EPT, ITER, HALO, XS, SPIN_CAP, SG), then
// common.wgsl, then this file, with the `//#if FLAG` / `//#else` / `//#endif` lines resolved
// on the host so that a scene compiles only the terms it uses. Flags:
//   EXTENSIBLE    stretch energy instead of distance constraints
//   STRETCH_DAMP  stretching-rate damping (extensible only)
//   BEND_DAMP     relative-angular-velocity damping
//   DRAG          medium drag -drag*m*v
//   LOADS         constant point loads
//   CLAMP         clamped ends: a clamp frame per clamped end (state, in `clamps`) turned by the
//                 end's prescribed angular velocity, acting on the rod's end frame through its
//                 bend–twist node (cosserat_model::rod::EndNode)
//   REACT         held ends report the wrench their holder applies (backend-cpu reaction.rs):
//                 the momentum balance of the held point (its force, the velocity change its
//                 motion needs, the impulses its distance constraint gives its neighbour) and
//                 a clamp's torque, low-pass filtered at every step, kept in `clamps` (every
//                 kernel with CLAMP has REACT)
//   MESH          contact with a static triangle mesh (wall_contact.wgsl): points detected once
//                 per step (swept test, then sphere query unless the point's clearance from the
//                 wall has not run out), each contact resolved with Coulomb friction after every
//                 distance sweep, as the CPU's mesh_contact.rs and ContactSet (workgroup layout
//                 of the single-workgroup path only)
//   GUIDE         a straight introducer: the points from 1 up to the first one outside it are
//                 held on its axis before the sweeps, their velocities along it after them
//                 (backend-cpu guide.rs; workgroup layout of the single-workgroup path only)
//   BIND          bindings (an inner rod held on an outer one's centreline, constraints
//                 binding.rs): the rods a binding couples share one workgroup, each on its own
//                 run of threads (`Item::lane0`, `groups`); the binding sweep follows each
//                 constraint iteration, the outer rods' points and impulses exchanged in
//                 workgroup memory (single-workgroup workgroup layout only, inextensible rods)
//#if RODC
// (Kernels without RODC and GROUP are composed without these lines, so that their text stays
// what it was before rod contact existed: shader.rs checks their digests.)
//   RODC          rod–rod and self-contact with friction (rod_contact.wgsl; collide rods.rs,
//                 constraints rod_contact.rs): the rods share one workgroup as with BIND; each
//                 step publishes their points, builds bounding spheres, finds overlapping
//                 sphere pairs and tests their segments; after every constraint iteration the
//                 contacts are resolved as one split-mass Jacobi pass through workgroup memory
//                 (single-workgroup workgroup layout only, inextensible rods)
//   GROUP         (implied by BIND and RODC) several rods per workgroup, each on its own run
//                 of threads
//#endif
//   GRID          several co-resident workgroups per rod, one grid barrier per step
//   PERSTEP       one dispatch per step, reading src_* and writing the state buffers
//   SUBGROUP      one rod per group of SG invocations (one whole subgroup); neighbours exchange
//                 through subgroup shuffles and the kernel has no workgroup barrier at all
//   SHFL          neighbours exchange through subgroup shuffles (with SUBGROUP, or a workgroup
//                 that is one subgroup, WG == SG); no workgroup memory for the exchange
//   NBR_SYNC      (GRID) each workgroup waits only for its two neighbours' per-item flags
//                 instead of a grid-wide arrival counter
//   REGC          per-point and per-element parameters kept in registers for the dispatch
//                 instead of being read from storage in every step
//   COHERENT      (GRID) halos exchanged as vec4s through a `@coherent` buffer instead of
//                 single words through atomics
//   FAST          the impulse from one inverseSqrt with the constants w/(w_a + w_b)/h folded
//                 into registers: t = l0/|d| - 1, v_a -= d t k_a, v_b += d t k_b
//   SWEEP_LOADS   (measurement variant) read l0 and the inverse masses from storage in every
//                 constraint sweep instead of keeping them in registers
//   RSQRT         (measurement variant) the impulse from one inverseSqrt, (l0/|d| - 1), instead
//                 of the CPU's sqrt and division, (l0 - |d|)/|d|
//
// `//#for V A B [S]` … `//#endfor` blocks are per-thread loops over a thread's points or
// elements with compile-time bounds. The host unrolls them (every `{V}`, `{V+k}` becomes a
// literal index), so that the per-thread arrays below are only ever indexed by constants and
// the driver keeps them in registers; dynamically indexed private arrays are placed in local
// memory, which made every half-sweep a chain of dependent local-memory loads and stores. The
// host can also emit them as plain loops (a measurement variant).
//
// Layout: thread `lid` (SUBGROUP: lane) owns the EPT consecutive window points (and elements)
// with local index lid*EPT .. lid*EPT+EPT-1 and keeps them in registers for the whole dispatch.
// Element j is the segment from point j to point j+1 and carries frame j. Neighbouring threads
// exchange only their first and last point. EPT and the window start are even, so a thread's
// boundary constraints (its left element lid*EPT-1 and its right element lid*EPT+EPT-1) are
// both odd: the red (even) half-sweep touches only a thread's own points and needs no exchange;
// only the black half-sweep does. Boundary constraints are evaluated by both threads from the
// same values, each applying its own half of the impulse, so the result equals the CPU's
// red–black sweep.

struct Params {
    // xyz gravity, w time step h.
    gravity: vec4<f32>,
    // Allowed band of squared length ratios (l/l0)^2.
    lo2: f32,
    hi2: f32,
    // Index of the first step of this submission.
    base_step: u32,
    // Number of work items in this dispatch.
    num_items: u32,
    // GRID: halo exchanges since the synchronisation words were last cleared.
    epoch0: u32,
    // REACT: the reaction filter's weights of its last output, the last raw value and this
    // step's (reaction.rs `Reactions::finish`).
    rf_keep: f32,
    rf_old: f32,
    rf_new: f32,
}

// One 256-byte entry per dispatch of a submission (dynamic uniform offset).
struct Chunk {
    // First step of this dispatch relative to base_step, and its number of steps.
    offset: u32,
    count: u32,
    // GRID: halo exchanges of the submission's earlier dispatches.
    sync_base: u32,
    pad1: u32,
}

// Per-point and per-element parameters; slot i holds point i, element i and node i of a rod.
struct Slot {
    // l0 (element), inverse mass (point), mass (point), Kp (element)
    a: vec4<f32>,
    // inertia (element), Ks (element)
    b: vec4<f32>,
    // inverse inertia (element), stretch damping (element)
    c: vec4<f32>,
    // rest Darboux vector (node), node length (node)
    d: vec4<f32>,
    // bend/twist stiffness (node), bend damping (node)
    e: vec4<f32>,
}

// One work item's share of a rod: the window of points it steps and the part it owns.
struct Item {
    rod: u32,
    // Slot of the rod's point 0.
    base: u32,
    // Elements of the rod.
    n: u32,
    // bit0 end 0 holds its point, bit1 it is clamped (CLAMP), bit2 end 1 holds its point, bit3
    // it is clamped.
    flags: u32,
    // Window [w0, w1) and owned range [o0, o1) of point indices.
    w0: u32,
    w1: u32,
    o0: u32,
    o1: u32,
    // Neighbouring items of the same rod (GRID), or 0xffffffff.
    left: u32,
    right: u32,
    drag: f32,
    // BIND: the item's first thread in its workgroup.
    lane0: u32,
}

// Prescribed motion of one end: velocity, angular velocity (world), active steps [x, y).
// A held end's prescribed motion: velocity `v` and angular velocity `w` during steps
// [window.x, window.y); the point's position after step s is `origin` plus `v h` times the steps
// of the window in [window.z, s] (`origin`: its position before step window.z, tracked in f64
// by the host). `w` turns the clamp of a clamped end (CLAMP).
struct Drive {
    v: vec4<f32>,
    w: vec4<f32>,
    window: vec4<u32>,
    origin: vec4<f32>,
}

// A held end, per rod and end. A clamped one (CLAMP): the clamp's frame `q` (xyzw; state,
// turned by the end's prescribed angular velocity every step) and its bend–twist node to the
// rod's end frame: rest Darboux vector and length (half the end element) in `d`, stiffness and
// damping in `e`, as a Slot's node. Its reaction (REACT, state): the filtered force `rf` (w:
// the largest filtered force so far) and torque `rt` (world), and last step's raw force `xf`
// and torque `xt`.
struct Clamp {
    q: vec4<f32>,
    d: vec4<f32>,
    e: vec4<f32>,
    rf: vec4<f32>,
    rt: vec4<f32>,
    xf: vec4<f32>,
    xt: vec4<f32>,
}

// What a rod touches (MESH, GUIDE): `wall` = (static friction, kinetic friction, margin,
// radius); the guide's origin and length, axis and clearance; `on` = (has a wall, has a guide,
// contact sweeps when there are no distance sweeps, 0).
struct Touch {
    wall: vec4<f32>,
    guide_o: vec4<f32>,
    guide_a: vec4<f32>,
    on: vec4<u32>,
}

// A rod's part in a binding (BIND; constraints binding.rs: an inner rod, a guidewire, held on
// the centreline of an outer one, a catheter, in the same workgroup), per item: `outer` the
// outer rod's item (NONE: the item is no inner rod), `role` bit 0 inner, bit 1 outer (publishes
// its points), bit 2 the binding is two-way (the outer rod takes its share); the capture
// distance and the fraction of the offset removed per step; an outer rod's first entry in the
// workgroup's outer exchange arrays (`xo`), an inner rod's in the inner one (`xi`).
struct Coupling {
    outer: u32,
    role: u32,
    capture: f32,
    correction: f32,
    xo: u32,
    xi: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<uniform> chunk: Chunk;
@group(0) @binding(2) var<storage, read> slots: array<Slot>;
@group(0) @binding(3) var<storage, read> items: array<Item>;
@group(0) @binding(4) var<storage, read> drives: array<Drive>;
@group(0) @binding(5) var<storage, read_write> pos: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> vel: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> frm: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> omg: array<vec4<f32>>;
// Per item: code (0 ok, 1 frame not finite, 2 position not finite, 3 strain), element, step,
// bits of the length ratio.
@group(0) @binding(9) var<storage, read_write> status: array<atomic<u32>>;
//#if LOADS
@group(0) @binding(10) var<storage, read> loads: array<vec4<f32>>;
//#endif
//#if REACT
// Read at the start of a dispatch and written at its end only by the thread that steps the
// end frame (clamp, torque) or the end point (force) in the item that owns it, so one copy
// serves every path.
@group(0) @binding(17) var<storage, read_write> clamps: array<Clamp>;
//#endif
//#if MESH
@group(0) @binding(20) var<storage, read> touch: array<Touch>;
// Per rod, WALL_STATS words: 0 largest penetration (f32 bits), 1 most escaped points in a step,
// 2 contacts at the last step, 3 most contacts in a step, 4 steps with detection, 5 swept
// catches, 6 tree walks of points, 7 walks that overflowed their stack, 8 ridge (segment)
// contacts, 9 point queries answered from near lists, 10 tree walks of elements.
@group(0) @binding(21) var<storage, read_write> wall_stats: array<atomic<u32>>;
// Per slot, two vec4: the contact's normal (w 1 in contact, 0 not) and the impulse the wall gave
// the point in the last step as a velocity change (normal and friction).
@group(0) @binding(22) var<storage, read_write> contact_out: array<vec4<f32>>;
// Contacts and escaped points of the step, double-buffered by the step's parity.
var<workgroup> wg_count: array<atomic<u32>, 4 * GROUP_MAX>;
// Each thread's first and last point's own gap and clearance, for the elements between threads.
var<workgroup> sh_g: array<vec2<f32>, 2 * WG>;
//#else
//#if GUIDE
@group(0) @binding(20) var<storage, read> touch: array<Touch>;
//#endif
//#endif
//#if GROUP
// Per workgroup: its first item and number of items.
@group(0) @binding(27) var<storage, read> groups: array<vec2<u32>>;
//#endif
//#if BIND
@group(0) @binding(28) var<storage, read> couplings: array<Coupling>;
// Per point of the group's outer rods (an outer rod's from its `Coupling::xo`): the point at the
// step's start, then its velocity after each sweep, with its inverse mass in w, published for
// the inner rods.
var<workgroup> wb_x: array<vec4<f32>, BIND_PTS>;
// Per outer segment (the entry of its first point): the first and last inner entries bound to
// it this step, where the outer rod looks for the shares of its two segments.
var<workgroup> wb_lo: array<atomic<u32>, BIND_PTS>;
var<workgroup> wb_hi: array<atomic<u32>, BIND_PTS>;
// Per point of the group's inner rods (from `Coupling::xi`): the impulse of its binding in the
// sweep (f32 bits) and its outer segment and parameter (`bind_code`).
var<workgroup> wb_i: array<vec4<u32>, BIND_IN>;
// Per slot of an inner rod: the outer segment its point was last bound to (where the next
// search walks from), NONE before the first.
@group(0) @binding(31) var<storage, read_write> bind_seg: array<u32>;
//#endif
//#if GROUP
const GROUP_MAX: u32 = 4u;
//#else
const GROUP_MAX: u32 = 1u;
//#endif
//#if GUIDE
// The first point (from 1) outside the guide, double-buffered by the step's parity.
var<workgroup> wg_guide: array<atomic<u32>, 2 * GROUP_MAX>;
//#endif
//#if PERSTEP
@group(0) @binding(11) var<storage, read> src_pos: array<vec4<f32>>;
@group(0) @binding(12) var<storage, read> src_vel: array<vec4<f32>>;
@group(0) @binding(13) var<storage, read> src_frm: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read> src_omg: array<vec4<f32>>;
//#endif
//#if GRID
// [0]: arrivals at the grid barrier (low 30 bits), bit 31 abort (divergence), bit 30 timeout.
// NBR_SYNC: [1 + item]: the item's last published exchange (low 30 bits), bit 31 stopped,
// bit 30 timed out.
@group(0) @binding(15) var<storage, read_write> sync: array<atomic<u32>>;
// Halo exchange: per parity, item and side, a slab of HALO points. Component-major, so that
// the threads of a warp touch consecutive addresses: component c of slab point k at
// slab * 13 * HALO + c * HALO + k (words r.xyz, v.xyz, q.xyzw, ω.xyz), written and read only
// through atomics, since plain loads of another workgroup's stores can be stale (GPU.md); with
// COHERENT, vec4 r, v, q, ω at slab * 4 * HALO + c * HALO + k in a `@coherent` buffer, whose
// loads bypass the incoherent L1 (GPU.md: no stale read in 2.7·10⁹).
//#if COHERENT
@coherent @group(0) @binding(16) var<storage, read_write> xch: array<vec4<f32>>;
//#else
@group(0) @binding(16) var<storage, read_write> xch: array<atomic<u32>>;
//#endif
//#endif

//#if !SHFL
// Neighbour exchange: 2*lid holds a thread's first point, 2*lid+1 its last.
var<workgroup> sh_r: array<vec4<f32>, 2 * WG>;
var<workgroup> sh_q: array<vec4<f32>, 2 * WG>;
//#if BEND_DAMP
var<workgroup> sh_w: array<vec4<f32>, 2 * WG>;
//#endif
//#if !EXTENSIBLE
// Double-buffered velocities: consecutive exchanges alternate, so one barrier per exchange.
var<workgroup> sh_v: array<vec4<f32>, 4 * WG>;
//#else
//#if STRETCH_DAMP
var<workgroup> sh_v: array<vec4<f32>, 4 * WG>;
//#endif
//#endif
//#endif
//#if !SUBGROUP
// Earliest divergence in this dispatch: (relative step << 16) | (local element << 2) | code.
var<workgroup> wg_key: atomic<u32>;
// Nonzero once the workgroup must stop (divergence here or, with GRID, anywhere).
var<workgroup> wg_stop: u32;
//#endif

const NONE: u32 = 0xffffffffu;
const XP: u32 = EPT + 2u;
const WALL_STATS: u32 = 11u;
// The skin of the near lists as a fraction of the reach: a point's list holds the triangles
// within reach + skin of its anchor, and serves while the point stays within the skin of it;
// an element's, the ridge triangles within reach + RIDGE_SKIN of it. Measured on the H100
// (docs/benchmarks/gpu-contact.md): ridge skins of 0.25 / 0.5 / 2 reaches gave 62 / 57 / 323
// µs per step to full depth (a wide one overflows the lists at bifurcations, and those
// elements then walk the tree at every step).
const WALL_SKIN: f32 = 0.5;
const RIDGE_SKIN: f32 = 0.5;

//#if MESH
struct Resolved {
    v: vec3<f32>,
    ln: f32,
    lt: vec3<f32>,
}

// One contact resolved on its point's velocity `v` (constraints ContactSet::resolve_all): the
// accumulated normal impulse `ln` clamped to a push that ends the step at the wall (`rate`: the
// gap over the step), then the accumulated friction impulse `lt` that would stop the sliding,
// kept inside the static cone, else scaled onto the kinetic cone. Impulses are velocity changes.
fn resolve_contact(v: vec3<f32>, n: vec3<f32>, rate: f32, ln: f32, lt: vec3<f32>, mu_s: f32, mu_k: f32) -> Resolved {
    let acc = max(ln + (-rate - dot(n, v)), 0.0);
    let x = v + n * (acc - ln);
    let want = lt - (x - n * dot(n, x));
    let norm = length(want);
    let friction = want * select(mu_k * acc / norm, 1.0, norm <= mu_s * acc);
    return Resolved(x + (friction - lt), acc, friction);
}
//#endif

//#if GUIDE
// The lateral offset of `p` from the guide's axis, or w = -1 when `p` is outside the guide (past
// its end or farther from the axis than the clearance).
fn guide_offset(t: Touch, p: vec3<f32>) -> vec4<f32> {
    let rel = p - t.guide_o.xyz;
    let along = dot(rel, t.guide_a.xyz);
    let lateral = rel - t.guide_a.xyz * along;
    let inside = along < t.guide_o.w && dot(lateral, lateral) <= t.guide_a.w * t.guide_a.w;
    return vec4<f32>(lateral, select(-1.0, 1.0, inside));
}
//#endif

//#if REACT
// One step of a reaction's low-pass filter (reaction.rs): the new output from the last one
// (`y`, w the largest output norm so far), the last raw value and this step's.
fn low_pass(y: vec4<f32>, old: vec3<f32>, raw: vec3<f32>) -> vec4<f32> {
    let out = y.xyz * params.rf_keep + old * params.rf_old + raw * params.rf_new;
    return vec4<f32>(out, max(y.w, length(out)));
}
//#endif

//#if BIND
// A bound point (binding.rs `BoundPoint`): its outer segment, the parameter along it, the
// segment's unit tangent and the point's offset from the centreline at the step's start; `on`
// false for a free point (whose `seg` still says where the next search starts).
struct Bound {
    seg: u32,
    s: f32,
    t: vec3<f32>,
    off: vec3<f32>,
    on: bool,
}

// The published points a and b - a of outer segment j of the rod whose exchange entries start
// at `base`.
fn bind_segment(base: u32, j: u32) -> array<vec3<f32>, 2> {
    let a = wb_x[base + j].xyz;
    return array<vec3<f32>, 2>(a, wb_x[base + j + 1u].xyz - a);
}

// Unclamped parameter of the projection of `p` onto outer segment j.
fn bind_param(p: vec3<f32>, base: u32, j: u32) -> f32 {
    let g = bind_segment(base, j);
    let l2 = dot(g[1], g[1]);
    return select(0.0, dot(p - g[0], g[1]) / l2, l2 > 0.0);
}

// The nearest point to `p` of the outer centreline (`m` segments from slot `base`), walking
// from segment `start` along the polyline to the local minimum of the distance (NONE: the
// nearest of all segments first), as `BindingSet::update`: a point whose nearest point lies
// before the outer rod's first point or past its tip, or farther than `capture`, is free. The
// offset is taken from the segment's start point, so that f32 coordinates far from the origin
// do not round it.
fn bind_nearest(p: vec3<f32>, start: u32, base: u32, m: u32, capture: f32) -> Bound {
    var j = start;
    if j == NONE {
        var best = 3.0e38;
        j = 0u;
        for (var k = 0u; k < m; k++) {
            let g = bind_segment(base, k);
            let l2 = dot(g[1], g[1]);
            let u = clamp(select(0.0, dot(p - g[0], g[1]) / l2, l2 > 0.0), 0.0, 1.0);
            let d = p - g[0] - g[1] * u;
            if dot(d, d) < best {
                best = dot(d, d);
                j = k;
            }
        }
    }
    j = min(j, m - 1u);
    var u = bind_param(p, base, j);
    var s = clamp(u, 0.0, 1.0);
    var walking = true;
    for (var steps = 0u; steps <= m && walking; steps++) {
        if u > 1.0 && j + 1u < m {
            let u2 = bind_param(p, base, j + 1u);
            if u2 < 0.0 {
                // At the joint between j and j + 1.
                s = 1.0;
                walking = false;
            } else {
                j += 1u;
                u = u2;
                s = clamp(u, 0.0, 1.0);
            }
        } else if u < 0.0 && j > 0u {
            let u2 = bind_param(p, base, j - 1u);
            if u2 > 1.0 {
                s = 0.0;
                walking = false;
            } else {
                j -= 1u;
                u = u2;
                s = clamp(u, 0.0, 1.0);
            }
        } else {
            s = u;
            walking = false;
        }
    }
    var out: Bound;
    out.seg = j;
    out.on = false;
    if s < 0.0 || s > 1.0 {
        return out;
    }
    // The parameter as both rods read it (`bind_code`).
    s = bind_param_of(bind_code(0u, s));
    let g = bind_segment(base, j);
    let off = (p - g[0]) - g[1] * s;
    let len = length(g[1]);
    if dot(off, off) > capture * capture || !(len > 0.0) {
        return out;
    }
    out.s = s;
    out.t = g[1] / len;
    out.off = off;
    out.on = true;
    return out;
}

// A bound point's outer segment and parameter in one word (`segment << 16 | s · 65535`; the
// parameter is kept to 1/65535 of a segment, so that the inner and the outer rod read the same
// one), or BIND_FREE.
const BIND_FREE: u32 = 0xffffffffu;

fn bind_code(seg: u32, s: f32) -> u32 {
    return (seg << 16u) | u32(round(s * 65535.0));
}

fn bind_param_of(code: u32) -> f32 {
    return f32(code & 0xffffu) / 65535.0;
}

// What the inner points bound to outer segment `seg` (entries `seg_entry` in the exchange)
// hand the segment's point at its start (`end` 0, a share 1 - s) or its end (1, a share s) in
// this sweep, summed in the inner points' order.
fn bind_gather(seg_entry: u32, seg: u32, end: u32) -> vec3<f32> {
    var acc = vec3<f32>(0.0);
    let lo = atomicLoad(&wb_lo[seg_entry]);
    let hi = atomicLoad(&wb_hi[seg_entry]);
    for (var i = lo; i <= hi; i++) {
        let q = wb_i[i];
        if (q.w >> 16u) == seg {
            let s = bind_param_of(q.w);
            acc -= bitcast<vec3<f32>>(q.xyz) * select(1.0 - s, s, end == 1u);
        }
    }
    return acc;
}
//#endif

fn key_of(rel_step: u32, local_elem: u32, code: u32) -> u32 {
    return (rel_step << 16u) | (local_elem << 2u) | code;
}

//#if GRID
//#if COHERENT
const XCH_COMPONENTS: u32 = 4u;
//#else
const XCH_COMPONENTS: u32 = 13u;
//#endif

// First entry of point k of a slab; component c is at + c * HALO.
fn xch_index(parity: u32, item: u32, side: u32, k: u32) -> u32 {
    return ((parity * params.num_items + item) * 2u + side) * XCH_COMPONENTS * HALO + k;
}

//#if COHERENT
fn xch_store(i: u32, r: vec3<f32>, v: vec3<f32>, q: vec4<f32>, w: vec3<f32>) {
    xch[i] = vec4<f32>(r, 0.0);
    xch[i + HALO] = vec4<f32>(v, 0.0);
    xch[i + 2u * HALO] = q;
    xch[i + 3u * HALO] = vec4<f32>(w, 0.0);
}
//#else
fn xch_put(i: u32, x: f32) {
    atomicStore(&xch[i], bitcast<u32>(x));
}

fn xch_get(i: u32) -> f32 {
    return bitcast<f32>(atomicLoad(&xch[i]));
}

fn xch_store(i: u32, r: vec3<f32>, v: vec3<f32>, q: vec4<f32>, w: vec3<f32>) {
    xch_put(i, r.x);
    xch_put(i + HALO, r.y);
    xch_put(i + 2u * HALO, r.z);
    xch_put(i + 3u * HALO, v.x);
    xch_put(i + 4u * HALO, v.y);
    xch_put(i + 5u * HALO, v.z);
    xch_put(i + 6u * HALO, q.x);
    xch_put(i + 7u * HALO, q.y);
    xch_put(i + 8u * HALO, q.z);
    xch_put(i + 9u * HALO, q.w);
    xch_put(i + 10u * HALO, w.x);
    xch_put(i + 11u * HALO, w.y);
    xch_put(i + 12u * HALO, w.z);
}
//#endif
//#endif

@compute @workgroup_size(WG)
fn main(@builtin(local_invocation_index) lid_wg: u32, @builtin(workgroup_id) wid: vec3<u32>) {
//#if SUBGROUP
    // SG consecutive invocations (one subgroup) per rod, WG / SG rods per workgroup. A group
    // without a rod leaves as a whole: no barrier waits for it.
    let lid = lid_wg % SG;
    let item_index = wid.x * (WG / SG) + lid_wg / SG;
    if item_index >= params.num_items {
        return;
    }
    let has_right = lid + 1u < SG;
    var stop = false;
    let gi = 0u;
//#else
    // `tid` indexes the workgroup's exchange arrays, `lid` is the thread's place in its rod.
    let tid = lid_wg;
//#if GROUP
    // A group of rods per workgroup (those a binding couples), each on its own run of threads
    // from its item's `lane0`; threads past the last rod's points idle through the barriers.
    let grp = groups[wid.x];
    var item_index = grp.x;
    for (var k = 1u; k < grp.y; k++) {
        if lid_wg >= items[grp.x + k].lane0 {
            item_index = grp.x + k;
        }
    }
    let lid = lid_wg - items[item_index].lane0;
    let gi = item_index - grp.x;
    var lane_end = WG;
    if gi + 1u < grp.y {
        lane_end = items[item_index + 1u].lane0;
    }
    let has_right = lid_wg + 1u < lane_end;
//#else
    let lid = lid_wg;
    let item_index = wid.x;
    let gi = 0u;
    let has_right = lid + 1u < WG;
//#endif
//#endif
    let has_left = lid > 0u;
    // The rod's share of the workgroup's per-rod counters.
    let wc = gi * 4u;
    let wgd = gi * 2u;
    let it = items[item_index];
    let h = params.gravity.w;
    let inv_h = 1.0 / h;
    let g = params.gravity.xyz;
    let b0 = lid * EPT;
    let end_elem = it.w1 - 1u;  // window elements are [w0, w1 - 1)

    // Registers: the thread's points, velocities, frames and angular velocities.
    var r: array<vec3<f32>, EPT>;
    var v: array<vec3<f32>, EPT>;
    var q: array<vec4<f32>, EPT>;
    var w: array<vec3<f32>, EPT>;
//#for e 0 EPT
    {
        let gp = it.w0 + b0 + {e};
        if gp < it.w1 {
            let s = it.base + gp;
//#if PERSTEP
            r[{e}] = src_pos[s].xyz;
            v[{e}] = src_vel[s].xyz;
            q[{e}] = src_frm[s];
            w[{e}] = src_omg[s].xyz;
//#else
            r[{e}] = pos[s].xyz;
            v[{e}] = vel[s].xyz;
            q[{e}] = frm[s];
            w[{e}] = omg[s].xyz;
//#endif
        } else {
            q[{e}] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        }
    }
//#endfor

//#if CLAMP
    // The clamps of this thread's end frames, in registers for the dispatch: c0 when the thread
    // steps frame 0 of a clamped first end in the item that owns it, c1 the same for frame n - 1
    // of a clamped last end. A window that reaches an end frame it does not own (a halo) leaves
    // the clamp out there: like any halo edge, that error cannot reach the points it owns
    // before their next exchange.
    let c0 = (it.flags & 2u) != 0u && it.o0 == 0u && lid == 0u;
    let f1 = it.n - 1u;
    let c1 = (it.flags & 8u) != 0u && f1 >= it.o0 && f1 < it.o1 && (f1 - it.w0) / EPT == lid;
    var qc0 = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    var qc1 = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    if c0 {
        qc0 = clamps[2u * it.rod].q;
    }
    if c1 {
        qc1 = clamps[2u * it.rod + 1u].q;
    }
//#endif
//#if REACT
    // The held end points' reactions: the thread that owns a held end point in the item that
    // owns it keeps the end's force filter in registers for the dispatch; the thread that
    // steps a clamped end frame keeps its torque filter (c0, c1). The constraint between the
    // end point and its neighbour is the thread's extended constraint 1 (first end) or rj1
    // (last end).
    let react0 = (it.flags & 1u) != 0u && it.o0 == 0u && lid == 0u;
    let ln1 = it.n - it.w0;
    let react1 = (it.flags & 4u) != 0u && it.n >= it.o0 && it.n < it.o1 && ln1 / EPT == lid;
    let rj1 = select(NONE, ln1 % EPT, react1);
    var rf0 = vec4<f32>(0.0);
    var xf0 = vec3<f32>(0.0);
    var rf1 = vec4<f32>(0.0);
    var xf1 = vec3<f32>(0.0);
    if react0 {
        rf0 = clamps[2u * it.rod].rf;
        xf0 = clamps[2u * it.rod].xf.xyz;
    }
    if react1 {
        rf1 = clamps[2u * it.rod + 1u].rf;
        xf1 = clamps[2u * it.rod + 1u].xf.xyz;
    }
//#if CLAMP
    var rt0 = vec4<f32>(0.0);
    var xt0 = vec3<f32>(0.0);
    var rt1 = vec4<f32>(0.0);
    var xt1 = vec3<f32>(0.0);
    if c0 {
        rt0 = clamps[2u * it.rod].rt;
        xt0 = clamps[2u * it.rod].xt.xyz;
    }
    if c1 {
        rt1 = clamps[2u * it.rod + 1u].rt;
        xt1 = clamps[2u * it.rod + 1u].xt.xyz;
    }
//#endif
//#endif

//#if !EXTENSIBLE
    // Constraint constants for the whole dispatch: constraint x joins extended points x and
    // x + 1 (local element b0 - 1 + x). wm: inverse masses of the extended points; cl0 / cinv:
    // rest length and 1 / (w_a + w_b) as the CPU's red–black solver keeps them; cok: the
    // constraint exists in this window.
    var wm: array<f32, XP>;
    var cl0: array<f32, XP>;
    var cinv: array<f32, XP>;
    var cok: array<bool, XP>;
//#for x 0 XP
    {
        let lp = b0 + {x};  // local point + 1
        let gp = it.w0 + lp - 1u;
        wm[{x}] = 0.0;
        if lp >= 1u && gp < it.w1 {
            wm[{x}] = slots[it.base + gp].a.y;
        }
    }
//#endfor
//#for x 0 EPT+1
    {
        let le = b0 + {x};  // local element + 1
        let ge = it.w0 + le - 1u;
        cok[{x}] = le >= 1u && it.w0 + le - 1u < end_elem;
        cl0[{x}] = 1.0;
        cinv[{x}] = 0.0;
        if cok[{x}] {
            cl0[{x}] = slots[it.base + ge].a.x;
            let ws = wm[{x}] + wm[{x+1}];
            cinv[{x}] = select(0.0, 1.0 / ws, ws > 0.0);
        }
    }
//#endfor
//#if FAST
    // k_a, k_b: the share of the impulse each end takes, w / (w_a + w_b) / h.
    var cka: array<f32, XP>;
    var ckb: array<f32, XP>;
//#for x 0 EPT+1
    cka[{x}] = wm[{x}] * cinv[{x}] * inv_h;
    ckb[{x}] = wm[{x+1}] * cinv[{x}] * inv_h;
//#endfor
//#endif
//#endif
//#if REGC
    // Parameters of element / node / point x (local index b0 - 1 + x), loaded once.
    var ks: array<Slot, XP>;
//#for x 0 EPT+1
    {
        let le = b0 + {x};
        if le >= 1u && it.w0 + le - 1u < it.w1 {
            ks[{x}] = slots[it.base + it.w0 + le - 1u];
        }
    }
//#endfor
//#endif

//#if BIND
    // This rod's part in a binding: the outer rod's first slot and segments (inner rods), and
    // each point's last outer segment, in registers for the dispatch.
    let cp = couplings[item_index];
    let b_inner = (cp.role & 1u) != 0u;
    let b_outer = (cp.role & 2u) != 0u;
    let b_two = (cp.role & 4u) != 0u;
    // An outer rod's first exchange entry; an inner rod's own, its outer rod's, and its
    // outer rod's segments.
    let xo = cp.xo;
    let xi = cp.xi;
    var oxo = 0u;
    var om = 1u;
    if b_inner {
        oxo = couplings[cp.outer].xo;
        om = items[cp.outer].n;
    }
    var bseg: array<u32, EPT>;
//#for e 0 EPT
    bseg[{e}] = NONE;
    if b_inner && it.w0 + b0 + {e} < it.w1 {
        bseg[{e}] = bind_seg[it.base + it.w0 + b0 + {e}];
    }
//#endfor
//#endif
//#if RODC
    // Rod contact (rod_contact.wgsl): this rod's part and the group's spheres; the contacts
    // this thread finds at a step's start stay in its registers for the step's sweeps: the
    // group entries of their first points, their parameters, normal and bias (−gap / h), split
    // effective inverse mass and its inverse, and accumulated friction and normal impulses; the
    // workgroup's region of the step's contact list.
    let rc_grp = groups[wid.x];
    let sd = strands[item_index];
    let rc_last = strands[rc_grp.x + rc_grp.y - 1u];
    let rc_spheres = rc_last.xs + rc_last.spheres;
    var rc_ia: array<u32, RC_CAP>;
    var rc_ib: array<u32, RC_CAP>;
    var rc_st: array<vec2<f32>, RC_CAP>;
    var rc_nb: array<vec4<f32>, RC_CAP>;
    var rc_w: array<vec2<f32>, RC_CAP>;
    var rc_l: array<vec4<f32>, RC_CAP>;
    var rc_count = 0u;
    var rc_max = 0u;
    let rc_list0 = wid.x * 3u * RC_LIST;
    // Each point's inverse mass, or minus its mass where it is held (`rcw_x`'s w).
    var rc_m: array<f32, EPT>;
//#for e 0 EPT
    rc_m[{e}] = wm[{e+1}];
    if it.w0 + b0 + {e} < it.w1 && !(wm[{e+1}] > 0.0) {
        rc_m[{e}] = -slots[it.base + it.w0 + b0 + {e}].a.z;
    }
//#endfor
//#for e 0 EPT
    if it.w0 + b0 + {e} < it.w1 {
        let k = sd.xp + it.w0 + b0 + {e};
        atomicStore(&rcw_j[3u * k], 0);
        atomicStore(&rcw_j[3u * k + 1u], 0);
        atomicStore(&rcw_j[3u * k + 2u], 0);
    }
//#endfor
    if tid == 0u {
        for (var k = 0u; k < 8u; k++) {
            atomicStore(&rcw_stat[k], 0u);
        }
        atomicStore(&rcw_stat[RCW_MIND], 0x7f800000u);
        atomicStore(&rcw_stat[RCW_MINR], 0x7f800000u);
    }
//#endif
//#if MESH
    // Wall contact: per point, the contact of this step (normal, gap, accumulated normal and
    // friction impulses), the point's inverse mass, and its anchor (where it last walked the
    // tree), clearance from there, and near list's head (wall_contact.wgsl), kept in registers
    // for the dispatch and in `pt_meta` / `pt_list` between dispatches.
    let tc = touch[it.rod];
    let wall_on = tc.on.x != 0u;
    let mu_s = tc.wall.x;
    let mu_k = tc.wall.y;
    let margin = tc.wall.z;
    let radius = tc.wall.w;
    let reach = radius + margin;
    var ct_on: array<bool, EPT>;
    var ct_n: array<vec3<f32>, EPT>;
    var ct_gap: array<f32, EPT>;
    var ct_ln: array<f32, EPT>;
    var ct_lt: array<vec3<f32>, EPT>;
    var pw: array<f32, EPT>;
    var anchor: array<vec3<f32>, EPT>;
    var clear: array<f32, EPT>;
    var head: array<u32, EPT>;
    let skin = reach * WALL_SKIN;
    let ridge_skin = reach * RIDGE_SKIN;
//#for e 0 EPT
    {
        let gp = it.w0 + b0 + {e};
        ct_on[{e}] = false;
        pw[{e}] = 0.0;
        head[{e}] = 0u;
        if gp < it.w1 {
            pw[{e}] = slots[it.base + gp].a.y;
            let m = pt_meta[it.base + gp];
            anchor[{e}] = m.xyz;
            clear[{e}] = m.w;
            head[{e}] = pt_list[(it.base + gp) * (NEAR_POINT + 1u)];
        }
    }
//#endfor
    var listed = 0u;
    var element_walks = 0u;
    var queries = 0u;
    var swept = 0u;
    var ridges = 0u;
    var overflows = 0u;
    var max_pen = 0.0;
    if lid == 0u {
        for (var k = 0u; k < 4u; k++) {
            atomicStore(&wg_count[wc + k], 0u);
        }
    }
//#endif
//#if GUIDE
    let tg = touch[it.rod];
    let guide_on = tg.on.y != 0u;
    if lid == 0u {
        atomicStore(&wg_guide[wgd + 0], NONE);
        atomicStore(&wg_guide[wgd + 1], NONE);
    }
//#endif
//#if !SUBGROUP
    if tid == 0u {
        atomicStore(&wg_key, NONE);
        wg_stop = 0u;
    }
//#if GROUP
    workgroupBarrier();
//#endif
    // A rod that has diverged stays where it stopped (with the rods of its group).
    if lid == 0u && atomicLoad(&status[item_index * 4u]) != 0u {
        wg_stop = 1u;
    }
//#else
    // A rod that has diverged stays where it stopped.
    stop = atomicLoad(&status[item_index * 4u]) != 0u;
//#endif
    var my_key = NONE;
    var my_val = 0.0;
    var xpar = 0u;
    var steps_done = 0u;

    for (var s = 0u; s < chunk.count; s++) {
        let step_rel = chunk.offset + s;
        let step = params.base_step + step_rel;
//#if GRID
        // Halo exchange every XS steps (a dispatch starts from the whole window, read from the
        // state buffers): publish the owned boundary slabs, wait, read the halos.
        if s > 0u && s % XS == 0u {
            let epoch = params.epoch0 + chunk.sync_base + s / XS;
            let par = epoch & 1u;
//#for e 0 EPT
            {
                // A point may belong to both slabs when the window owns fewer than 2 HALO.
                let gp = it.w0 + b0 + {e};
                if it.left != NONE && gp >= it.o0 && gp < it.o0 + HALO {
                    xch_store(xch_index(par, item_index, 0u, gp - it.o0), r[{e}], v[{e}], q[{e}], w[{e}]);
                }
                if it.right != NONE && gp + HALO >= it.o1 && gp < it.o1 {
                    xch_store(xch_index(par, item_index, 1u, gp + HALO - it.o1), r[{e}], v[{e}], q[{e}], w[{e}]);
                }
            }
//#endfor
            storageBarrier();
            if lid == 0u {
//#if NBR_SYNC
                // Publish this item's exchange, then wait for both neighbours to have published
                // the same one (or to have stopped).
                atomicStore(&sync[1u + item_index], epoch | select(0u, 0x80000000u, wg_stop != 0u));
                var fl = select(0u, epoch, it.left == NONE);
                var fr = select(0u, epoch, it.right == NONE);
                for (var i = 0u; i < SPIN_CAP; i++) {
                    if it.left != NONE && (fl & 0x3fffffffu) < epoch && (fl & 0xc0000000u) == 0u {
                        fl = atomicLoad(&sync[1u + it.left]);
                    }
                    if it.right != NONE && (fr & 0x3fffffffu) < epoch && (fr & 0xc0000000u) == 0u {
                        fr = atomicLoad(&sync[1u + it.right]);
                    }
                    if ((fl & 0x3fffffffu) >= epoch || (fl & 0xc0000000u) != 0u)
                        && ((fr & 0x3fffffffu) >= epoch || (fr & 0xc0000000u) != 0u) {
                        break;
                    }
                }
                let done_l = (fl & 0x3fffffffu) >= epoch || (fl & 0xc0000000u) != 0u;
                let done_r = (fr & 0x3fffffffu) >= epoch || (fr & 0xc0000000u) != 0u;
                // Checked after the loop, not by a loop flag (see GPU.md on lavapipe).
                if !(done_l && done_r) {
                    atomicOr(&status[item_index * 4u], 0x100u);
                    atomicOr(&sync[1u + item_index], 0x40000000u);
                    wg_stop = 1u;
                }
                if ((fl | fr) & 0xc0000000u) != 0u {
                    wg_stop = 1u;
                }
//#else
                if wg_stop != 0u {
                    atomicOr(&sync[0], 0x80000000u);
                }
                // Every exchange of every dispatch arrives once, and the host counts the
                // exchanges since it last cleared the counter (epoch0), so the target is a
                // multiple of the items. An abort bit is set before its setter arrives (or, for
                // a workgroup that stops between exchanges, when it leaves), so whoever waits
                // sees it.
                let goal = params.num_items * epoch;
                var seen = atomicAdd(&sync[0], 1u) + 1u;
                for (var i = 0u; i < SPIN_CAP; i++) {
                    if (seen & 0x3fffffffu) >= goal || (seen & 0xc0000000u) != 0u {
                        break;
                    }
                    seen = atomicLoad(&sync[0]);
                }
                // Checked after the loop, not by a loop flag: a driver that cuts loops short (see
                // GPU.md on lavapipe) must still report a timeout, never run on with stale halos.
                if (seen & 0x3fffffffu) < goal && (seen & 0xc0000000u) == 0u {
                    seen = atomicOr(&sync[0], 0x40000000u) | 0x40000000u;
                    atomicOr(&status[item_index * 4u], 0x100u);
                }
                wg_stop = select(0u, 1u, (seen & 0xc0000000u) != 0u);
//#endif
            }
            storageBarrier();
//#for e 0 EPT
            {
                let gp = it.w0 + b0 + {e};
                var i = NONE;
                if gp < it.o0 && it.left != NONE {
                    i = xch_index(par, it.left, 1u, gp + HALO - it.o0);
                }
                if gp >= it.o1 && gp < it.w1 && it.right != NONE {
                    i = xch_index(par, it.right, 0u, gp - it.o1);
                }
                if i != NONE {
//#if COHERENT
                    r[{e}] = xch[i].xyz;
                    v[{e}] = xch[i + HALO].xyz;
                    q[{e}] = xch[i + 2u * HALO];
                    w[{e}] = xch[i + 3u * HALO].xyz;
//#else
                    r[{e}] = vec3<f32>(xch_get(i), xch_get(i + HALO), xch_get(i + 2u * HALO));
                    v[{e}] = vec3<f32>(xch_get(i + 3u * HALO), xch_get(i + 4u * HALO), xch_get(i + 5u * HALO));
                    q[{e}] = vec4<f32>(xch_get(i + 6u * HALO), xch_get(i + 7u * HALO), xch_get(i + 8u * HALO), xch_get(i + 9u * HALO));
                    w[{e}] = vec3<f32>(xch_get(i + 10u * HALO), xch_get(i + 11u * HALO), xch_get(i + 12u * HALO));
//#endif
                }
            }
//#endfor
        }
//#endif
        // Extended arrays: index x is local point b0 - 1 + x (0: left neighbour's last,
        // EPT + 1: right neighbour's first).
        var rx: array<vec3<f32>, XP>;
        var qx: array<vec4<f32>, XP>;
        var vx: array<vec3<f32>, XP>;
//#if BEND_DAMP
        var wx: array<vec3<f32>, XP>;
//#endif
//#if SUBGROUP
        if subgroupAny(stop) {
            break;
        }
//#else
//#if SHFL
        if workgroupUniformLoad(&wg_stop) != 0u {
            break;
        }
//#endif
//#endif
//#if SHFL
        // Neighbours' boundary points by subgroup shuffles (lane 0 / SG - 1 get nothing useful
        // and keep zeros: no constraint or force of theirs reads those entries).
        {
            let rl = subgroupShuffleUp(r[EPT - 1u], 1u);
            let rr = subgroupShuffleDown(r[0], 1u);
            let ql = subgroupShuffleUp(q[EPT - 1u], 1u);
            let qr = subgroupShuffleDown(q[0], 1u);
//#if BEND_DAMP
            let wl = subgroupShuffleUp(w[EPT - 1u], 1u);
            let wr = subgroupShuffleDown(w[0], 1u);
//#endif
//#if STRETCH_DAMP
            let vl = subgroupShuffleUp(v[EPT - 1u], 1u);
            let vr = subgroupShuffleDown(v[0], 1u);
//#endif
            if has_left {
                rx[0] = rl;
                qx[0] = ql;
//#if BEND_DAMP
                wx[0] = wl;
//#endif
//#if STRETCH_DAMP
                vx[0] = vl;
//#endif
            }
            if has_right {
                rx[EPT + 1u] = rr;
                qx[EPT + 1u] = qr;
//#if BEND_DAMP
                wx[EPT + 1u] = wr;
//#endif
//#if STRETCH_DAMP
                vx[EPT + 1u] = vr;
//#endif
            }
        }
//#else
        // Publish this thread's first and last point for its neighbours.
        sh_r[2u * tid] = vec4<f32>(r[0], 0.0);
        sh_r[2u * tid + 1u] = vec4<f32>(r[EPT - 1u], 0.0);
        sh_q[2u * tid] = q[0];
        sh_q[2u * tid + 1u] = q[EPT - 1u];
//#if BEND_DAMP
        sh_w[2u * tid] = vec4<f32>(w[0], 0.0);
        sh_w[2u * tid + 1u] = vec4<f32>(w[EPT - 1u], 0.0);
//#endif
//#if STRETCH_DAMP
        sh_v[xpar * 2u * WG + 2u * tid] = vec4<f32>(v[0], 0.0);
        sh_v[xpar * 2u * WG + 2u * tid + 1u] = vec4<f32>(v[EPT - 1u], 0.0);
//#endif
        if workgroupUniformLoad(&wg_stop) != 0u {
            break;
        }
        if has_left {
            rx[0] = sh_r[2u * tid - 1u].xyz;
            qx[0] = sh_q[2u * tid - 1u];
//#if BEND_DAMP
            wx[0] = sh_w[2u * tid - 1u].xyz;
//#endif
//#if STRETCH_DAMP
            vx[0] = sh_v[xpar * 2u * WG + 2u * tid - 1u].xyz;
//#endif
        }
        if has_right {
            rx[EPT + 1u] = sh_r[2u * tid + 2u].xyz;
            qx[EPT + 1u] = sh_q[2u * tid + 2u];
//#if BEND_DAMP
            wx[EPT + 1u] = sh_w[2u * tid + 2u].xyz;
//#endif
//#if STRETCH_DAMP
            vx[EPT + 1u] = sh_v[xpar * 2u * WG + 2u * tid + 2u].xyz;
//#endif
        }
//#if STRETCH_DAMP
        xpar ^= 1u;
//#endif
//#if EXTENSIBLE
        // Without constraint sweeps no other barrier separates these reads from the next
        // step's writes of sh_r / sh_q / sh_w.
        workgroupBarrier();
//#endif
//#endif
//#for e 0 EPT
        rx[{e+1}] = r[{e}];
        qx[{e+1}] = q[{e}];
        vx[{e+1}] = v[{e}];
//#if BEND_DAMP
        wx[{e+1}] = w[{e}];
//#endif
//#endfor

        // Deferred length check of the previous step's result, for owned elements whose two
        // points this thread now sees.
        if s > 0u {
//#for e 0 EPT
            {
                let ge = it.w0 + b0 + {e};
                if ge < end_elem && ge >= it.o0 && ge < it.o1 {
//#if REGC
                    let l0 = ks[{e+1}].a.x;
//#else
                    let l0 = slots[it.base + ge].a.x;
//#endif
                    let d = rx[{e+2}] - rx[{e+1}];
                    let ratio = dot(d, d) / (l0 * l0);
                    if !(ratio >= params.lo2 && ratio <= params.hi2) {
                        let code = select(3u, 2u, not_finite(ratio));
                        let key = key_of(step_rel - 1u, ge - it.w0, code);
                        if key < my_key {
                            my_key = key;
                            my_val = ratio;
                        }
//#if SUBGROUP
                        stop = true;
//#else
                        atomicMin(&wg_key, key);
                        wg_stop = 1u;
//#endif
                    }
                }
            }
//#endfor
        }

        // Forces on the thread's points and torques on its frames. Element / node x covers local
        // index b0 - 1 + x, x = 0..=EPT; contributions are summed in the CPU's order.
        var fb: array<vec3<f32>, XP>;
        var te: array<vec3<f32>, XP>;
        var ta: array<vec3<f32>, XP>;
        var tb: array<vec3<f32>, XP>;
//#for x 0 EPT+1
        {
            let le = b0 + {x};  // local element index + 1
            if le >= 1u && it.w0 + le - 1u < end_elem {
                let ge = it.w0 + le - 1u;
//#if REGC
                let sl = ks[{x}];
//#else
                let sl = slots[it.base + ge];
//#endif
                let pe = parallel_element(rx[{x}], rx[{x+1}], qx[{x}], sl.a.w, sl.a.x);
                var f = pe.fb;
//#if EXTENSIBLE
                f += stretch_element(rx[{x}], rx[{x+1}], sl.b.w, sl.a.x);
//#if STRETCH_DAMP
                if sl.c.w > 0.0 {
                    f += stretch_damping_element(rx[{x}], rx[{x+1}], vx[{x}], vx[{x+1}], sl.c.w, sl.a.x);
                }
//#endif
//#endif
                fb[{x}] = f;
                te[{x}] = pe.torque;
                // Node ge between frames ge and ge + 1.
                if ge + 1u < end_elem {
                    let nt = bend_twist_node(qx[{x}], qx[{x+1}], sl.d.xyz, sl.e.xyz, sl.d.w);
                    ta[{x}] = nt.ta;
                    tb[{x}] = nt.tb;
//#if BEND_DAMP
                    let nd = bend_damping_node(qx[{x}], qx[{x+1}], wx[{x}], wx[{x+1}], sl.e.w, sl.d.w);
                    ta[{x}] += nd.ta;
                    tb[{x}] += nd.tb;
//#endif
                }
            }
        }
//#endfor

//#if CLAMP
        // The clamps' prescribed angular velocities (world) in this step, and the torques their
        // nodes give the end frames (computed once here, not in every copy of the unrolled loop
        // below). Frame 0 is the thread's first; frame n - 1 is picked out by its index.
        var om0 = vec3<f32>(0.0);
        var om1 = vec3<f32>(0.0);
        var tc0 = vec3<f32>(0.0);
        var tc1 = vec3<f32>(0.0);
        if c0 {
            let dr = drives[it.rod * 2u];
            om0 = select(vec3<f32>(0.0), dr.w.xyz, step >= dr.window.x && step < dr.window.y);
            let k = clamps[2u * it.rod];
            tc0 = clamp_torque(qc0, q[0], w[0], om0, k.d.xyz, k.e.xyz, k.d.w, k.e.w, false);
            // The clamp's torque on the rod, in world coordinates: the end's reaction torque.
            let world0 = quat_rotate(q[0], tc0);
            rt0 = low_pass(rt0, xt0, world0);
            xt0 = world0;
        }
        if c1 {
            let dr = drives[it.rod * 2u + 1u];
            om1 = select(vec3<f32>(0.0), dr.w.xyz, step >= dr.window.x && step < dr.window.y);
            var qf = q[0];
            var wf = w[0];
//#for e 1 EPT
            if it.w0 + b0 + {e} == f1 {
                qf = q[{e}];
                wf = w[{e}];
            }
//#endfor
            let k = clamps[2u * it.rod + 1u];
            tc1 = clamp_torque(qc1, qf, wf, om1, k.d.xyz, k.e.xyz, k.d.w, k.e.w, true);
            let world1 = quat_rotate(qf, tc1);
            rt1 = low_pass(rt1, xt1, world1);
            xt1 = world1;
        }
//#endif
//#if REACT
        // The held points' momentum balance before the constraints, m (v_p - v) / h - f, and
        // the impulses their distance constraints give their neighbours.
        var fpre0 = vec3<f32>(0.0);
        var fpre1 = vec3<f32>(0.0);
        var jr0 = vec3<f32>(0.0);
        var jr1 = vec3<f32>(0.0);
//#endif
        // Integrate velocities: v += h f / m and Euler's equations with the gyroscopic term.
//#for e 0 EPT
        {
            let gp = it.w0 + b0 + {e};
            if gp < it.w1 {
//#if REGC
                let sl = ks[{e+1}];
//#else
                let sl = slots[it.base + gp];
//#endif
//#if DRAG
                var f = (g - vx[{e+1}] * it.drag) * sl.a.z;
//#else
                var f = g * sl.a.z;
//#endif
                f += fb[{e}];
                f -= fb[{e+1}];
//#if LOADS
                f += loads[it.base + gp].xyz;
//#endif
                var vn = vx[{e+1}] + f * (h * sl.a.y);
                var wn = w[{e}];
                if gp < end_elem {
                    // Torque order as on the CPU: parallel, node j-1 (as its b), node j (as its a),
                    // then a clamp's node.
                    var tq = ((te[{e+1}] + tb[{e}]) + ta[{e+1}]);
//#if CLAMP
                    if c0 && gp == 0u {
                        tq += tc0;
                    }
                    if c1 && gp == f1 {
                        tq += tc1;
                    }
//#endif
                    // Half kick, the gyroscopic precession of (ω1, ω2) by h (J - I)/I ω3 as a
                    // Cayley rotation, half kick: as the CPU's soa::integrate_velocities (an
                    // explicit ω × Iω term loses the step's stability once frames spin).
                    let kick = tq * sl.c.xyz * (0.5 * h);
                    wn += kick;
                    let t = 0.5 * h * (sl.b.z * sl.c.x - 1.0) * wn.z;
                    let inv = 1.0 / (1.0 + t * t);
                    let cs = (1.0 - t * t) * inv;
                    let sn = 2.0 * t * inv;
                    wn = vec3<f32>(cs * wn.x - sn * wn.y, sn * wn.x + cs * wn.y, wn.z) + kick;
                }
                // Held end points follow their prescribed motion exactly.
                if gp == 0u && (it.flags & 1u) != 0u {
                    let dr = drives[it.rod * 2u];
                    let on = step >= dr.window.x && step < dr.window.y;
                    vn = select(vec3<f32>(0.0), dr.v.xyz, on);
//#if REACT
                    fpre0 = (vn - vx[{e+1}]) * (sl.a.z * inv_h) - f;
//#endif
                }
                if gp == it.n && (it.flags & 4u) != 0u {
                    let dr = drives[it.rod * 2u + 1u];
                    let on = step >= dr.window.x && step < dr.window.y;
                    vn = select(vec3<f32>(0.0), dr.v.xyz, on);
//#if REACT
                    fpre1 = (vn - vx[{e+1}]) * (sl.a.z * inv_h) - f;
//#endif
                }
                vx[{e+1}] = vn;
                w[{e}] = wn;
            }
        }
//#endfor

//#if GUIDE
        // The introducer holds the points from 1 up to the first one outside it on its axis,
        // moving along it (backend-cpu guide.rs). Every thread applies it to its halo copies
        // too, from the same values, as its neighbour does to its own points.
        var guide_end = 0u;
        {
            let gpar = s & 1u;
            if lid == 0u {
                atomicStore(&wg_guide[wgd + (gpar ^ 1u)], NONE);
            }
            if guide_on {
//#for e 0 EPT
                {
                    let gp = it.w0 + b0 + {e};
                    if gp >= 1u && gp < it.w1 && guide_offset(tg, rx[{e+1}]).w < 0.0 {
                        atomicMin(&wg_guide[wgd + gpar], gp);
                    }
                }
//#endfor
            }
            workgroupBarrier();
            if guide_on {
                guide_end = atomicLoad(&wg_guide[wgd + gpar]);
            }
//#for x 0 XP
            {
                if b0 + {x} >= 2u {
                    let gp = it.w0 + b0 + {x} - 1u;
                    if gp < guide_end && gp < it.w1 {
                        rx[{x}] -= guide_offset(tg, rx[{x}]).xyz;
                        vx[{x}] = tg.guide_a.xyz * dot(vx[{x}], tg.guide_a.xyz);
                    }
                }
            }
//#endfor
//#for e 0 EPT
            r[{e}] = rx[{e+1}];
//#endfor
        }
//#endif
//#if MESH
        // Wall contacts of this step, from where the points start it and how they would move
        // (backend-cpu mesh_contact.rs): a point whose motion crosses into the wall beyond half
        // its reach is put back on the wall it crossed; any other is queried as a sphere unless
        // it is still within its clearance.
        let cpar = s & 1u;
        if wall_on {
            if lid == 0u {
                if s > 0u {
                    let c = atomicExchange(&wg_count[wc + (cpar ^ 1u) * 2u], 0u);
                    let esc = atomicExchange(&wg_count[wc + (cpar ^ 1u) * 2u + 1u], 0u);
                    atomicStore(&wall_stats[it.rod * WALL_STATS + 2u], c);
                    atomicMax(&wall_stats[it.rod * WALL_STATS + 3u], c);
                    atomicMax(&wall_stats[it.rod * WALL_STATS + 1u], esc);
                }
                atomicAdd(&wall_stats[it.rod * WALL_STATS + 4u], 1u);
            }
            // Which points need more than one comparison: those that move far enough to be
            // swept, and those whose clearance does not excuse them. Their queries run in one
            // loop that is not unrolled, on copies indexed by the loop (one copy of the query
            // code, whatever EPT; the unrolled state stays in registers).
            var need = 0u;
            var dq_p: array<vec3<f32>, EPT>;
            var dq_v: array<vec3<f32>, EPT>;
            var dq_anchor: array<vec3<f32>, EPT>;
            var dq_clear: array<f32, EPT>;
            var dq_head: array<u32, EPT>;
            var dq_on: array<bool, EPT>;
            var dq_n: array<vec3<f32>, EPT>;
            var dq_gap: array<f32, EPT>;
//#for e 0 EPT
            {
                ct_on[{e}] = false;
                ct_ln[{e}] = 0.0;
                ct_lt[{e}] = vec3<f32>(0.0);
                let dp = vx[{e+1}] * h;
                let moved = length(rx[{e+1}] - anchor[{e}]);
                let excused = (head[{e}] & LIST_VALID) != 0u && moved < clear[{e}];
                if it.w0 + b0 + {e} < it.w1 && (!excused || dot(dp, dp) > 0.25 * reach * reach) {
                    need |= 1u << u32({e});
                    dq_p[{e}] = rx[{e+1}];
                    dq_v[{e}] = dp;
                    dq_anchor[{e}] = anchor[{e}];
                    dq_clear[{e}] = clear[{e}];
                    dq_head[{e}] = head[{e}];
                }
            }
//#endfor
            var n_escaped = 0u;
            for (var k = 0u; k < EPT; k++) {
                if (need & (1u << k)) == 0u {
                    continue;
                }
                let p = dq_p[k];
                let dp = dq_v[k];
                dq_on[k] = false;
                var crossed = false;
                if dot(dp, dp) > 0.25 * reach * reach {
                    // Swept: a wall crossed beyond the sphere's reach puts the point back on it.
                    let cr = wall_first_crossing(p, dp);
                    if cr.f >= 0.0 {
                        let wn = wall_tris[cr.slot].n.xyz;
                        let ahead = -cr.f * dot(dp, wn);
                        let gap = ahead - radius;
                        n_escaped += select(0u, 1u, ahead < 0.0);
                        max_pen = max(max_pen, -gap);
                        swept += 1u;
                        dq_on[k] = true;
                        dq_n[k] = wn;
                        dq_gap[k] = gap;
                        crossed = true;
                    }
                }
                let moved = length(p - dq_anchor[k]);
                let valid = (dq_head[k] & LIST_VALID) != 0u;
                // Within its clearance a point cannot touch the wall; within the skin its near
                // list holds every triangle it can touch; else it walks the tree.
                if !crossed && !(valid && moved < dq_clear[k]) {
                    var hq: WallHit;
                    let lb = (it.base + it.w0 + b0 + k) * (NEAR_POINT + 1u);
                    if valid && (dq_head[k] & LIST_OVER) == 0u && moved <= skin {
                        listed += 1u;
                        hq = wall_query_listed(p, reach, lb, dq_head[k]);
                    } else {
                        queries += 1u;
                        hq = wall_walk(p, reach, reach + skin, lb);
                        overflows += select(0u, 1u, hq.overflow);
                        dq_anchor[k] = p;
                        // Rounding of the distances must not open a gap.
                        dq_clear[k] = max(sqrt(hq.near2) - reach * 1.001, 0.0);
                        dq_head[k] = pt_list[lb];
                    }
                    if hq.count > 0u {
                        n_escaped += select(0u, 1u, hq.escaped);
                        if dot(hq.dir, hq.dir) > 0.0 {
                            // Depths are measured against the inflated sphere.
                            let pen = hq.depth - margin;
                            max_pen = max(max_pen, pen);
                            dq_on[k] = true;
                            dq_n[k] = hq.dir;
                            dq_gap[k] = -pen;
                        }
                    }
                }
            }
//#for e 0 EPT
            if (need & (1u << u32({e}))) != 0u {
                ct_on[{e}] = dq_on[{e}];
                ct_n[{e}] = dq_n[{e}];
                ct_gap[{e}] = dq_gap[{e}];
                anchor[{e}] = dq_anchor[{e}];
                clear[{e}] = dq_clear[{e}];
                head[{e}] = dq_head[{e}];
            }
//#endfor
            if n_escaped > 0u {
                atomicAdd(&wg_count[wc + cpar * 2u + 1u], n_escaped);
            }
        }
        // Elements nearer a ridge of the wall between their points than at them: each point's
        // own gap (its contact's, else the margin) and clearance beyond its reach, shared with
        // the neighbours (mesh_contact.rs `segment_contacts`).
        var ogx: array<f32, XP>;
        var cex: array<f32, XP>;
//#for e 0 EPT
        {
            ogx[{e+1}] = select(margin, ct_gap[{e}], ct_on[{e}]);
            cex[{e+1}] = 0.0;
            if (head[{e}] & LIST_VALID) != 0u {
                cex[{e+1}] = max(clear[{e}] - length(rx[{e+1}] - anchor[{e}]), 0.0);
            }
        }
//#endfor
        sh_g[2u * tid] = vec2<f32>(ogx[1], cex[1]);
        sh_g[2u * tid + 1u] = vec2<f32>(ogx[EPT], cex[EPT]);
        workgroupBarrier();
        ogx[0] = margin;
        cex[0] = 0.0;
        ogx[EPT + 1u] = margin;
        cex[EPT + 1u] = 0.0;
        if has_left {
            let g = sh_g[2u * tid - 1u];
            ogx[0] = g.x;
            cex[0] = g.y;
        }
        if has_right {
            let g = sh_g[2u * tid + 2u];
            ogx[EPT + 1u] = g.x;
            cex[EPT + 1u] = g.y;
        }
        // Element x joins extended points x and x + 1 (local element b0 - 1 + x). A thread tests
        // the elements that end at its points (x = 1 ..= EPT) and takes the one before its first
        // point (x = 0) from its left neighbour, which tested it as its last. The elements near
        // the wall are tested in one loop that is not unrolled, as the points above.
        var seg_on: array<bool, XP>;
        var seg_n: array<vec3<f32>, XP>;
        var seg_w: array<vec3<f32>, XP>;
        var eneed = 0u;
        var de_a: array<vec3<f32>, XP>;
        var de_d: array<vec3<f32>, XP>;
        var de_limit: array<f32, XP>;
        var de_on: array<bool, XP>;
        var de_n: array<vec3<f32>, XP>;
        var de_w: array<vec3<f32>, XP>;
//#for x 1 EPT+1
        {
            seg_on[{x}] = false;
            let d = rx[{x+1}] - rx[{x}];
            let clear_sum = cex[{x}] + cex[{x+1}];
            // Only a wall nearer than both points' own, by 2 % of the radius, makes a ridge
            // contact.
            let limit = min(ogx[{x}], ogx[{x+1}]) + radius * 0.98;
            if wall_on && it.w0 + b0 + {x} - 1u < end_elem && clear_sum * clear_sum < dot(d, d) && limit > 0.0 {
                eneed |= 1u << u32({x});
                de_a[{x}] = rx[{x}];
                de_d[{x}] = d;
                de_limit[{x}] = limit;
            }
        }
//#endfor
        for (var x = 1u; x <= EPT; x++) {
            if (eneed & (1u << x)) == 0u {
                continue;
            }
            let ge = it.w0 + b0 + x - 1u;
            let a = de_a[x];
            let d = de_d[x];
            let eb = (it.base + ge) * (NEAR_ELEMENT + 1u);
            let eh = el_list[eb];
            let e0 = el_meta[2u * (it.base + ge)].xyz;
            let e1 = el_meta[2u * (it.base + ge) + 1u].xyz;
            var sh: SegmentHit;
            if (eh & LIST_VALID) != 0u && (eh & LIST_OVER) == 0u
                && length(a - e0) <= ridge_skin && length(a + d - e1) <= ridge_skin {
                sh = wall_segment_listed(a, d, de_limit[x], eb, eh);
            } else {
                element_walks += 1u;
                sh = wall_segment_walk(a, d, de_limit[x], reach + ridge_skin, eb);
                el_meta[2u * (it.base + ge)] = vec4<f32>(a, 0.0);
                el_meta[2u * (it.base + ge) + 1u] = vec4<f32>(a + d, 0.0);
            }
            de_on[x] = sh.found && sh.fraction >= 1e-6 && sh.fraction <= 1.0 - 1e-6;
            if de_on[x] {
                de_n[x] = sh.normal;
                de_w[x] = sh.on_wall;
                ridges += 1u;
                max_pen = max(max_pen, radius - sh.signed_distance);
            }
        }
//#for x 1 EPT+1
        if (eneed & (1u << u32({x}))) != 0u {
            seg_on[{x}] = de_on[{x}];
            seg_n[{x}] = de_n[{x}];
            seg_w[{x}] = de_w[{x}];
        }
//#endfor
        // The last element to the right neighbour (through the exchange arrays, free here).
        sh_r[2u * tid] = vec4<f32>(seg_n[EPT], select(0.0, 1.0, seg_on[EPT]));
        sh_q[2u * tid] = vec4<f32>(seg_w[EPT], 0.0);
        workgroupBarrier();
        seg_on[0] = false;
        if has_left {
            let l = sh_r[2u * tid - 2u];
            seg_on[0] = l.w > 0.5;
            seg_n[0] = l.xyz;
            seg_w[0] = sh_q[2u * tid - 2u].xyz;
        }
        if wall_on {
            // A point between ridge elements takes their planes' contacts as one: the mean of
            // their normals and the lesser gap, where nearer than its own.
            var n_contacts = 0u;
//#for e 0 EPT
            {
                var sum = vec3<f32>(0.0);
                var gap = 3.0e38;
                var any = false;
                if seg_on[{e}] {
                    let eg = dot(seg_n[{e}], rx[{e+1}] - seg_w[{e}]) - radius;
                    if eg < ogx[{e+1}] {
                        sum += seg_n[{e}];
                        gap = min(gap, eg);
                        any = true;
                    }
                }
                if seg_on[{e+1}] {
                    let eg = dot(seg_n[{e+1}], rx[{e+1}] - seg_w[{e+1}]) - radius;
                    if eg < ogx[{e+1}] {
                        sum += seg_n[{e+1}];
                        gap = min(gap, eg);
                        any = true;
                    }
                }
                if any && it.w0 + b0 + {e} < it.w1 {
                    ct_on[{e}] = true;
                    ct_n[{e}] = normalize(sum);
                    ct_gap[{e}] = gap;
                }
                n_contacts += select(0u, 1u, ct_on[{e}]);
            }
//#endfor
            if n_contacts > 0u {
                atomicAdd(&wg_count[wc + cpar * 2u], n_contacts);
            }
        }
//#endif
//#if BIND
        // Bindings: the outer rods publish their points at the step's start, and each inner
        // point is bound to the nearest point of the outer centreline (BindingSet::update).
        if b_outer {
//#for e 0 EPT
            if it.w0 + b0 + {e} < it.w1 {
                wb_x[xo + it.w0 + b0 + {e}] = vec4<f32>(rx[{e+1}], wm[{e+1}]);
                atomicStore(&wb_lo[xo + it.w0 + b0 + {e}], NONE);
                atomicStore(&wb_hi[xo + it.w0 + b0 + {e}], 0u);
            }
//#endfor
        }
        workgroupBarrier();
        var b_on: array<bool, EPT>;
        var b_s: array<f32, EPT>;
        var b_t: array<vec3<f32>, EPT>;
        var b_off: array<vec3<f32>, EPT>;
//#for e 0 EPT
        b_on[{e}] = false;
        if b_inner && it.w0 + b0 + {e} < it.w1 {
            let bd = bind_nearest(rx[{e+1}], bseg[{e}], oxo, om, cp.capture);
            bseg[{e}] = bd.seg;
            b_on[{e}] = bd.on;
            b_s[{e}] = bd.s;
            b_t[{e}] = bd.t;
            b_off[{e}] = bd.off;
            // Two-way: listed where the outer rod will look for its share.
            let entry = xi + it.w0 + b0 + {e};
            var code = BIND_FREE;
            if bd.on && b_two {
                code = bind_code(bd.seg, bd.s);
                atomicMin(&wb_lo[oxo + bd.seg], entry);
                atomicMax(&wb_hi[oxo + bd.seg], entry);
            }
            wb_i[entry] = vec4<u32>(0u, 0u, 0u, code);
        }
//#endfor
//#endif
//#if RODC
        // Rod contact: the contacts of the step, found at its start (coupling.rs `detect`,
        // collide rods.rs), each phase dealt out over all the workgroup's threads.
//#for e 0 EPT
        if it.w0 + b0 + {e} < it.w1 {
            let k = sd.xp + it.w0 + b0 + {e};
            rcw_x[k] = vec4<f32>(rx[{e+1}], rc_m[{e}]);
            atomicStore(&rcw_cnt[k], 0u);
        }
//#endfor
        if tid == 0u {
            atomicStore(&rcw_np, 0u);
            atomicStore(&rcw_nc, 0u);
        }
        workgroupBarrier();
        // Bounding spheres (rods.rs `build_spheres`): the centre of the points' box, the
        // farthest point from it, the rod's radius and half the margin.
        for (var q = tid; q < rc_spheres; q += WG) {
            let sp = rc_sphere_of_strands(q, rc_grp.x, rc_grp.y);
            rcw_m[q] = vec2<u32>(sp.item, sp.first | (sp.count << 16u));
            let kd = strands[sp.item];
            let k0 = kd.xp + sp.first;
            var lo = rcw_x[k0].xyz;
            var hi = lo;
            for (var k = 1u; k <= sp.count; k++) {
                let p = rcw_x[k0 + k].xyz;
                lo = min(lo, p);
                hi = max(hi, p);
            }
            let c = 0.5 * (lo + hi);
            var r2 = 0.0;
            for (var k = 0u; k <= sp.count; k++) {
                let d = rcw_x[k0 + k].xyz - c;
                r2 = max(r2, dot(d, d));
            }
            rcw_s[q] = vec4<f32>(c, sqrt(r2) + kd.radius + kd.half_margin);
        }
        workgroupBarrier();
        // Overlapping sphere pairs (rods.rs `find_pairs`): a sphere with itself when its own
        // segments may touch, two spheres of one rod when some of their segments are farther
        // apart than the skip, any two when they overlap.
        for (var q = tid; q < rc_spheres * rc_spheres; q += WG) {
            let i = q / rc_spheres;
            let j = q % rc_spheres;
            if j < i {
                continue;
            }
            let d = rcw_s[i].xyz - rcw_s[j].xyz;
            let rr = rcw_s[i].w + rcw_s[j].w;
            var want = i == j || dot(d, d) < rr * rr;
            if want {
                let si = rc_sphere(i);
                let sj = rc_sphere(j);
                if si.item == sj.item {
                    let skip = strands[si.item].skip;
                    if i == j {
                        want = skip != NONE && si.count > skip + 1u;
                    } else {
                        want = skip != NONE && sj.first + sj.count - 1u - si.first > skip;
                    }
                } else {
                    want = i != j;
                }
            }
            if want {
                let k = atomicAdd(&rcw_np, 1u);
                if k < RC_PAIRS {
                    rcw_pairs[k] = (i << 16u) | j;
                }
            }
        }
        workgroupBarrier();
        // The segment pairs of the sphere pairs (rods.rs `narrow`), one thread a pair; a pair or
        // contact that does not fit is counted (and makes the host's next read fail).
        let rc_np = atomicLoad(&rcw_np);
        for (var q = tid; q < min(rc_np, RC_PAIRS); q += WG) {
            rc_pair(q, rc_list0, inv_h);
        }
        storageBarrier();
        workgroupBarrier();
        let rc_nc = atomicLoad(&rcw_nc);
        if tid == 0u {
            rc_max = max(rc_max, rc_nc);
            let over = select(0u, rc_np - RC_PAIRS, rc_np > RC_PAIRS) + select(0u, rc_nc - RC_LIST, rc_nc > RC_LIST);
            if over > 0u {
                atomicAdd(&rcw_stat[RCW_DROP], over);
            }
        }
        // Each thread's share of the list, with each contact's effective inverse mass, its
        // points' masses split among their contacts; and the radii of the nearest pair so far.
        let rc_min = atomicLoad(&rcw_stat[RCW_MIND]);
        rc_count = 0u;
        for (var k = tid; k < min(rc_nc, RC_LIST); k += WG) {
            let o = rc_list0 + 3u * k;
            let e0 = rc_list[o];
            let ia = e0.x;
            let ib = e0.y;
            let st = bitcast<vec2<f32>>(e0.zw);
            let e2 = bitcast<vec2<f32>>(rc_list[o + 2u].xy);
            let c = vec4<f32>(1.0 - st.x, st.x, 1.0 - st.y, st.y);
            let w = max(vec4<f32>(rcw_x[ia].w, rcw_x[ia + 1u].w, rcw_x[ib].w, rcw_x[ib + 1u].w), vec4<f32>(0.0));
            let m = vec4<f32>(
                f32(atomicLoad(&rcw_cnt[ia])),
                f32(atomicLoad(&rcw_cnt[ia + 1u])),
                f32(atomicLoad(&rcw_cnt[ib])),
                f32(atomicLoad(&rcw_cnt[ib + 1u])),
            );
            let ww = dot(c * c, w * m);
            rc_ia[rc_count] = ia;
            rc_ib[rc_count] = ib;
            rc_st[rc_count] = st;
            rc_nb[rc_count] = bitcast<vec4<f32>>(rc_list[o + 1u]);
            rc_w[rc_count] = vec2<f32>(ww, select(0.0, 1.0 / ww, ww > 0.0));
            rc_l[rc_count] = vec4<f32>(0.0);
            if bitcast<u32>(e2.x) == rc_min {
                atomicStore(&rcw_stat[RCW_RAD], bitcast<u32>(e2.y));
            }
            rc_count += 1u;
        }
        workgroupBarrier();
//#endif

//#if !EXTENSIBLE
        // Distance constraints, red–black, as the CPU's solver: d = e + h (v_b - v_a) with e the
        // element vector at the start of the step, s = (l0 - |d|) / (w_a + w_b) / h / |d|.
        var ed: array<vec3<f32>, XP>;
//#for x 0 EPT+1
        ed[{x}] = rx[{x+1}] - rx[{x}];
//#endfor
        for (var iter = 0u; iter < ITER; iter++) {
            // Red: x odd, the thread's own points only.
//#for x 1 EPT+1 2
            {
//#if SWEEP_LOADS
                let le = b0 + {x};
                var l0 = 1.0;
                var wa = 0.0;
                var wb = 0.0;
                if cok[{x}] {
                    l0 = slots[it.base + it.w0 + le - 1u].a.x;
                    wa = slots[it.base + it.w0 + le - 1u].a.y;
                    wb = slots[it.base + it.w0 + le].a.y;
                }
                let ci = select(0.0, 1.0 / (wa + wb), wa + wb > 0.0);
//#else
                let l0 = cl0[{x}];
                let wa = wm[{x}];
                let wb = wm[{x+1}];
                let ci = cinv[{x}];
//#endif
                let d = ed[{x}] + (vx[{x+1}] - vx[{x}]) * h;
//#if FAST
                let t = select(0.0, l0 * inverseSqrt(dot(d, d)) - 1.0, cok[{x}]);
                vx[{x}] -= d * (t * cka[{x}]);
                vx[{x+1}] += d * (t * ckb[{x}]);
//#if REACT
                // The impulse point b took (or point a gave) as if the end were free.
                let imp = t * cinv[{x}] * inv_h;
//#endif
//#else
//#if RSQRT
                let sc = select(0.0, (l0 * inverseSqrt(dot(d, d)) - 1.0) * ci * inv_h, cok[{x}]);
//#else
                let len = sqrt(dot(d, d));
                let sc = select(0.0, (l0 - len) * ci * inv_h / len, cok[{x}]);
//#endif
                vx[{x}] -= d * (sc * wa);
                vx[{x+1}] += d * (sc * wb);
//#if REACT
                let imp = sc;
//#endif
//#endif
//#if REACT
                if u32({x}) == 1u && react0 {
                    jr0 += d * imp;
                }
                if u32({x}) == rj1 {
                    jr1 -= d * imp;
                }
//#endif
            }
//#endfor
            // Exchange the boundary velocities the red half-sweep changed.
//#if SHFL
            {
                let vl = subgroupShuffleUp(vx[EPT], 1u);
                let vr = subgroupShuffleDown(vx[1], 1u);
                vx[0] = select(vx[0], vl, has_left);
                vx[EPT + 1u] = select(vx[EPT + 1u], vr, has_right);
            }
//#else
            sh_v[xpar * 2u * WG + 2u * tid] = vec4<f32>(vx[1], 0.0);
            sh_v[xpar * 2u * WG + 2u * tid + 1u] = vec4<f32>(vx[EPT], 0.0);
            workgroupBarrier();
            if has_left {
                vx[0] = sh_v[xpar * 2u * WG + 2u * tid - 1u].xyz;
            }
            if has_right {
                vx[EPT + 1u] = sh_v[xpar * 2u * WG + 2u * tid + 2u].xyz;
            }
            xpar ^= 1u;
//#endif
            // Black: x even, including both boundary constraints.
//#for x 0 EPT+1 2
            {
//#if SWEEP_LOADS
                let le = b0 + {x};
                var l0 = 1.0;
                var wa = 0.0;
                var wb = 0.0;
                if cok[{x}] {
                    l0 = slots[it.base + it.w0 + le - 1u].a.x;
                    wa = slots[it.base + it.w0 + le - 1u].a.y;
                    wb = slots[it.base + it.w0 + le].a.y;
                }
                let ci = select(0.0, 1.0 / (wa + wb), wa + wb > 0.0);
//#else
                let l0 = cl0[{x}];
                let wa = wm[{x}];
                let wb = wm[{x+1}];
                let ci = cinv[{x}];
//#endif
                let d = ed[{x}] + (vx[{x+1}] - vx[{x}]) * h;
//#if FAST
                let t = select(0.0, l0 * inverseSqrt(dot(d, d)) - 1.0, cok[{x}]);
                vx[{x}] -= d * (t * cka[{x}]);
                vx[{x+1}] += d * (t * ckb[{x}]);
//#if REACT
                // The impulse point b took (or point a gave) as if the end were free.
                let imp = t * cinv[{x}] * inv_h;
//#endif
//#else
//#if RSQRT
                let sc = select(0.0, (l0 * inverseSqrt(dot(d, d)) - 1.0) * ci * inv_h, cok[{x}]);
//#else
                let len = sqrt(dot(d, d));
                let sc = select(0.0, (l0 - len) * ci * inv_h / len, cok[{x}]);
//#endif
                vx[{x}] -= d * (sc * wa);
                vx[{x+1}] += d * (sc * wb);
//#if REACT
                let imp = sc;
//#endif
//#endif
//#if REACT
                if u32({x}) == 1u && react0 {
                    jr0 += d * imp;
                }
                if u32({x}) == rj1 {
                    jr1 -= d * imp;
                }
//#endif
            }
//#endfor
//#if MESH
            // Each contact once; kinematic points are left alone.
//#for e 0 EPT
            if ct_on[{e}] && pw[{e}] > 0.0 {
                let rc = resolve_contact(vx[{e+1}], ct_n[{e}], ct_gap[{e}] * inv_h, ct_ln[{e}], ct_lt[{e}], mu_s, mu_k);
                vx[{e+1}] = rc.v;
                ct_ln[{e}] = rc.ln;
                ct_lt[{e}] = rc.lt;
            }
//#endfor
//#endif
//#if BIND
            // The binding sweep after the rods' own (BindingSet::sweep, as one Jacobi pass): the
            // outer rods publish their velocities, each bound inner point takes the impulse that
            // removes its offset across the outer segment by the step's end and publishes it
            // (two-way), and each outer point adds the shares of the inner points bound to its
            // two segments (found once per step, summed in their order: the same sum on every
            // run).
            if b_outer {
//#for e 0 EPT
                if it.w0 + b0 + {e} < it.w1 {
                    wb_x[xo + it.w0 + b0 + {e}] = vec4<f32>(vx[{e+1}], wm[{e+1}]);
                }
//#endfor
            }
            workgroupBarrier();
            if b_inner {
//#for e 0 EPT
                if b_on[{e}] {
                    let j = bseg[{e}];
                    let s = b_s[{e}];
                    let wi = wm[{e+1}];
                    let xa = wb_x[oxo + j];
                    let xb = wb_x[oxo + j + 1u];
                    // The outer points' inverse masses come with their velocities (w).
                    let wa = select(0.0, xa.w, b_two);
                    let wb = select(0.0, xb.w, b_two);
                    let wsum = wi + (1.0 - s) * (1.0 - s) * wa + s * s * wb;
                    if wsum > 0.0 {
                        let vc = xa.xyz * (1.0 - s) + xb.xyz * s;
                        let d = b_off[{e}] * cp.correction + (vx[{e+1}] - vc) * h;
                        let dp = d - b_t[{e}] * dot(b_t[{e}], d);
                        let imp = dp * (-1.0 / (h * wsum));
                        vx[{e+1}] += imp * wi;
//#if REACT
                        // A held point does not move; the binding's push on it is part of its
                        // reaction, as on the CPU (`KinematicImpulses`). The first end's point is
                        // its thread's first, the last end's is `rj1`.
                        if u32({e}) == 0u && react0 {
                            jr0 -= imp;
                        }
                        if u32({e}) == rj1 {
                            jr1 -= imp;
                        }
//#endif
                        if b_two {
                            let entry = xi + it.w0 + b0 + {e};
                            wb_i[entry] = vec4<u32>(bitcast<vec3<u32>>(imp), wb_i[entry].w);
                        }
                    }
                }
//#endfor
            }
            workgroupBarrier();
            if b_outer {
//#for e 0 EPT
                {
                    // The shares of the inner points bound to the segment before this point and
                    // to the one after it.
                    let gp = it.w0 + b0 + {e};
                    if gp < it.w1 {
                        var jv = vec3<f32>(0.0);
                        if gp >= 1u {
                            jv += bind_gather(xo + gp - 1u, gp - 1u, 1u);
                        }
                        if gp < it.n {
                            jv += bind_gather(xo + gp, gp, 0u);
                        }
                        vx[{e+1}] += jv * wm[{e+1}];
//#if REACT
                        // A held point's share goes into its reaction.
                        if u32({e}) == 0u && react0 {
                            jr0 -= jv;
                        }
                        if u32({e}) == rj1 {
                            jr1 -= jv;
                        }
//#endif
                    }
                }
//#endfor
            }
//#endif
//#if RODC
            // Rod contact after the rods' own constraints (coupling.rs `sweep`): the velocities
            // published, every contact resolved on them, each point's summed impulses taken.
//#for e 0 EPT
            if it.w0 + b0 + {e} < it.w1 {
                rcw_x[sd.xp + it.w0 + b0 + {e}] = vec4<f32>(vx[{e+1}], rc_m[{e}]);
            }
//#endfor
            workgroupBarrier();
            for (var k = 0u; k < rc_count; k++) {
                let w = rc_w[k];
                if !(w.x > 0.0) {
                    continue;
                }
                let ia = rc_ia[k];
                let ib = rc_ib[k];
                let st = rc_st[k];
                let c = vec4<f32>(1.0 - st.x, st.x, 1.0 - st.y, st.y);
                let v = (rcw_x[ia].xyz * c.x + rcw_x[ia + 1u].xyz * c.y)
                    - (rcw_x[ib].xyz * c.z + rcw_x[ib + 1u].xyz * c.w);
                let nb = rc_nb[k];
                let l = rc_l[k];
                let rs = rc_resolve(v, nb.xyz, nb.w, w.x, w.y, l.w, l.xyz, sd.mu_s, sd.mu_k);
                rc_l[k] = vec4<f32>(rs.lt, rs.ln);
                if any(rs.p != vec3<f32>(0.0)) {
                    let wf = vec4<f32>(rcw_x[ia].w, rcw_x[ia + 1u].w, rcw_x[ib].w, rcw_x[ib + 1u].w);
                    let f = select(-1.0 / wf, wf, wf > vec4<f32>(0.0));
                    rc_add4(ia, ib, c * vec4<f32>(1.0, 1.0, -1.0, -1.0), f, rs.p);
                }
            }
            workgroupBarrier();
//#for e 0 EPT
            if it.w0 + b0 + {e} < it.w1 {
                let dv = rc_take(sd.xp + it.w0 + b0 + {e});
                if rc_m[{e}] > 0.0 {
                    vx[{e+1}] += dv;
                }
//#if REACT
                // A held point does not move; what the contacts push on it (its velocity
                // change times its mass) is part of its reaction, as on the CPU.
                if u32({e}) == 0u && react0 {
                    jr0 += dv * rc_m[{e}];
                }
                if u32({e}) == rj1 {
                    jr1 += dv * rc_m[{e}];
                }
//#endif
            }
//#endfor
//#endif
        }
//#else
//#if MESH
        // Without distance sweeps the contacts are still solved, as on the CPU.
        for (var iter = 0u; iter < tc.on.z; iter++) {
            // Each contact once; kinematic points are left alone.
//#for e 0 EPT
            if ct_on[{e}] && pw[{e}] > 0.0 {
                let rc = resolve_contact(vx[{e+1}], ct_n[{e}], ct_gap[{e}] * inv_h, ct_ln[{e}], ct_lt[{e}], mu_s, mu_k);
                vx[{e+1}] = rc.v;
                ct_ln[{e}] = rc.ln;
                ct_lt[{e}] = rc.lt;
            }
//#endfor
        }
//#endif
//#endif
//#if GUIDE
        // Guided points keep only their velocity along the axis.
//#for e 0 EPT
        {
            let gp = it.w0 + b0 + {e};
            if gp >= 1u && gp < guide_end && gp < it.w1 {
                vx[{e+1}] = tg.guide_a.xyz * dot(vx[{e+1}], tg.guide_a.xyz);
            }
        }
//#endfor
//#endif

//#if REACT
        // The reaction forces of the step (reaction.rs `finish`), filtered.
        if react0 {
            let raw = fpre0 + jr0 * inv_h;
            rf0 = low_pass(rf0, xf0, raw);
            xf0 = raw;
        }
        if react1 {
            let raw = fpre1 + jr1 * inv_h;
            rf1 = low_pass(rf1, xf1, raw);
            xf1 = raw;
        }
//#endif
        // Integrate positions and frames: r += h v, q <- normalise(q + q ⊗ (0, h ω / 2)).
//#for e 0 EPT
        {
            let gp = it.w0 + b0 + {e};
            if gp < it.w1 {
                v[{e}] = vx[{e+1}];
                r[{e}] = r[{e}] + v[{e}] * h;
                // A held point is placed on its path, not integrated: adding h v to a
                // coordinate ~10⁵ times larger in f32 would drift by up to half an ulp per step.
                if (gp == 0u && (it.flags & 1u) != 0u) || (gp == it.n && (it.flags & 4u) != 0u) {
                    let dr = drives[it.rod * 2u + select(0u, 1u, gp != 0u)];
                    let lo = max(dr.window.z, dr.window.x);
                    let hi = min(step + 1u, dr.window.y);
                    let count = select(0u, hi - lo, hi > lo);
                    r[{e}] = dr.origin.xyz + f32(count) * (h * dr.v.xyz);
                }
                if gp < end_elem {
                    let qn = q[{e}] + quat_mul(q[{e}], vec4<f32>(w[{e}] * (h * 0.5), 0.0));
                    let n2 = dot(qn, qn);
                    q[{e}] = qn / sqrt(n2);
                    if !(n2 > 0.0) || not_finite(n2) {
                        if gp >= it.o0 && gp < it.o1 {
                            let key = key_of(step_rel, gp - it.w0, 1u);
                            if key < my_key {
                                my_key = key;
                                my_val = n2;
                            }
//#if SUBGROUP
                            stop = true;
//#else
                            atomicMin(&wg_key, key);
                            wg_stop = 1u;
//#endif
                        }
                    }
                }
            }
        }
//#endfor
//#if CLAMP
        // The clamps turn with their prescribed rotation: q_c <- normalise(exp(h ω) ⊗ q_c).
        if c0 {
            let qn = quat_mul(exp_rotation(om0 * h), qc0);
            qc0 = qn / sqrt(dot(qn, qn));
        }
        if c1 {
            let qn = quat_mul(exp_rotation(om1 * h), qc1);
            qc1 = qn / sqrt(dot(qn, qn));
        }
//#endif
        steps_done = s + 1u;
    }

    // Length check of the last step, then write the owned points back.
//#if SUBGROUP
    let rn = subgroupShuffleDown(r[0], 1u);
    let stopped = subgroupAny(stop);
//#else
//#if SHFL
    let rn = subgroupShuffleDown(r[0], 1u);
    let stopped = workgroupUniformLoad(&wg_stop) != 0u;
//#else
    sh_r[2u * tid] = vec4<f32>(r[0], 0.0);
    let stopped = workgroupUniformLoad(&wg_stop) != 0u;
    let rn = sh_r[2u * tid + 2u].xyz;
//#endif
//#endif
//#if GRID
    // A workgroup that stopped tells the others, which may be waiting for its next exchange.
    if lid == 0u && stopped {
//#if NBR_SYNC
        atomicOr(&sync[1u + item_index], 0x80000000u);
//#else
        atomicOr(&sync[0], 0x80000000u);
//#endif
    }
//#endif
    if steps_done > 0u && !stopped && has_right {
        let ge = it.w0 + b0 + EPT - 1u;
        if ge < end_elem && ge >= it.o0 && ge < it.o1 {
            let l0 = slots[it.base + ge].a.x;
            let d = rn - r[EPT - 1u];
            let ratio = dot(d, d) / (l0 * l0);
            if !(ratio >= params.lo2 && ratio <= params.hi2) {
                let key = key_of(chunk.offset + steps_done - 1u, ge - it.w0, select(3u, 2u, not_finite(ratio)));
                if key < my_key {
                    my_key = key;
                    my_val = ratio;
                }
//#if !SUBGROUP
                atomicMin(&wg_key, key);
//#endif
            }
        }
    }
    if steps_done > 0u && !stopped {
//#for e 0 EPT-1
        {
            let ge = it.w0 + b0 + {e};
            if ge < end_elem && ge >= it.o0 && ge < it.o1 {
                let l0 = slots[it.base + ge].a.x;
                let d = r[{e+1}] - r[{e}];
                let ratio = dot(d, d) / (l0 * l0);
                if !(ratio >= params.lo2 && ratio <= params.hi2) {
                    let key = key_of(chunk.offset + steps_done - 1u, ge - it.w0, select(3u, 2u, not_finite(ratio)));
                    if key < my_key {
                        my_key = key;
                        my_val = ratio;
                    }
//#if !SUBGROUP
                    atomicMin(&wg_key, key);
//#endif
                }
            }
        }
//#endfor
    }
//#if SUBGROUP
    let first = subgroupMin(my_key);
//#else
    workgroupBarrier();
    let first = atomicLoad(&wg_key);
//#endif
//#if RODC
    // The group's statistics: the last step's contacts, the most in a step, the nearest pair,
    // the steps and what did not fit (one thread per group writes them).
    if tid == 0u && steps_done > 0u {
        let o = wid.x * RC_STATS;
        atomicStore(&rc_stats[o + 2u], atomicLoad(&rcw_nc));
        atomicMax(&rc_stats[o + 3u], rc_max);
        let md = atomicLoad(&rcw_stat[RCW_MIND]);
        if md < atomicLoad(&rc_stats[o]) {
            atomicStore(&rc_stats[o], md);
            atomicStore(&rc_stats[o + 1u], atomicLoad(&rcw_stat[RCW_RAD]));
        }
        atomicMin(&rc_stats[o + 4u], atomicLoad(&rcw_stat[RCW_MINR]));
        atomicAdd(&rc_stats[o + 5u], steps_done);
        atomicAdd(&rc_stats[o + 6u], atomicLoad(&rcw_stat[RCW_DROP]));
    }
//#endif
//#if MESH
    // The counts of the last step, this thread's totals, and each point's last contact.
    if wall_on {
        if lid == 0u && steps_done > 0u {
            let lp = ((steps_done - 1u) & 1u) * 2u;
            let c = atomicLoad(&wg_count[wc + lp]);
            atomicStore(&wall_stats[it.rod * WALL_STATS + 2u], c);
            atomicMax(&wall_stats[it.rod * WALL_STATS + 3u], c);
            atomicMax(&wall_stats[it.rod * WALL_STATS + 1u], atomicLoad(&wg_count[wc + lp + 1u]));
        }
        if max_pen > 0.0 {
            atomicMax(&wall_stats[it.rod * WALL_STATS], bitcast<u32>(max_pen));
        }
        // Words 5 ..= 10, in their order.
        let totals = array<u32, 6>(swept, queries, overflows, ridges, listed, element_walks);
        for (var k = 0u; k < 6u; k++) {
            if totals[k] > 0u {
                atomicAdd(&wall_stats[it.rod * WALL_STATS + 5u + k], totals[k]);
            }
        }
        if steps_done > 0u {
//#for e 0 EPT
            {
                let gp = it.w0 + b0 + {e};
                if gp < it.w1 {
                    let sl = it.base + gp;
                    contact_out[2u * sl] = vec4<f32>(ct_n[{e}], select(0.0, 1.0, ct_on[{e}]));
                    contact_out[2u * sl + 1u] = vec4<f32>(select(vec3<f32>(0.0), ct_n[{e}] * ct_ln[{e}] + ct_lt[{e}], ct_on[{e}]), 0.0);
                    pt_meta[sl] = vec4<f32>(anchor[{e}], clear[{e}]);
                }
            }
//#endfor
        }
    }
//#endif
    if my_key != NONE && my_key == first {
        atomicStore(&status[item_index * 4u + 1u], it.w0 + ((first >> 2u) & 0x3fffu));
        atomicStore(&status[item_index * 4u + 2u], params.base_step + (first >> 16u));
        atomicStore(&status[item_index * 4u + 3u], bitcast<u32>(my_val));
        atomicOr(&status[item_index * 4u], first & 3u);
    }
//#for e 0 EPT
    {
        let gp = it.w0 + b0 + {e};
        if gp >= it.o0 && gp < it.o1 {
            let s = it.base + gp;
            pos[s] = vec4<f32>(r[{e}], 0.0);
            vel[s] = vec4<f32>(v[{e}], 0.0);
            frm[s] = q[{e}];
            omg[s] = vec4<f32>(w[{e}], 0.0);
        }
    }
//#endfor
//#if CLAMP
    if c0 {
        clamps[2u * it.rod].q = qc0;
        clamps[2u * it.rod].rt = rt0;
        clamps[2u * it.rod].xt = vec4<f32>(xt0, 0.0);
    }
    if c1 {
        clamps[2u * it.rod + 1u].q = qc1;
        clamps[2u * it.rod + 1u].rt = rt1;
        clamps[2u * it.rod + 1u].xt = vec4<f32>(xt1, 0.0);
    }
//#endif
//#if BIND
    if b_inner {
//#for e 0 EPT
        if it.w0 + b0 + {e} < it.w1 {
            bind_seg[it.base + it.w0 + b0 + {e}] = bseg[{e}];
        }
//#endfor
    }
//#endif
//#if REACT
    if react0 {
        clamps[2u * it.rod].rf = rf0;
        clamps[2u * it.rod].xf = vec4<f32>(xf0, 0.0);
    }
    if react1 {
        clamps[2u * it.rod + 1u].rf = rf1;
        clamps[2u * it.rod + 1u].xf = vec4<f32>(xf1, 0.0);
    }
//#endif
}
