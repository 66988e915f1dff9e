// Contact of the rods with a static mesh inside the stiff step: the CPU's stiff contacts
// (backend-cpu `stiff/contact.rs` and `stiff/pin.rs`, whose module docs say why each rule is
// there), pass for pass. A point touching the wall is pinned to the wall's tangent plane (or to
// the crease of two walls) for the step's solve, with Coulomb friction as a force of the step's
// own equations; the active set changes between rounds of the solve, and points an iterate
// pushes into the wall are caught after every iteration.
//
// Every point's contact is its own invocation's (the one whose slice holds it): its detection,
// its pin, its friction, its rows of the update. What crosses slices is read after a barrier:
// the element queries read both points' gaps, the assembly of an element both points' pins,
// and a pin's impulse both elements' multipliers.
//
// Composed after stiff_wall.wgsl; `stiff_step.wgsl` calls these functions with `MESH`, and the
// pins' (`PINS`) also for the points an introducer guide holds on its axis (`GUIDE`).
// Differences from the CPU: every detection queries every point (the CPU's
// `reuse_contact_queries = false`), and the penetration and escaped points of a step are those
// of a detection at its end positions (the CPU measures the deepest point exactly and tells
// escaped points by the winding number of a closed mesh; here by the nearest feature's side).

@group(0) @binding(12) var<storage, read_write> cs: array<f64>;

// Per point, CSS numbers: whether it is pinned (C_PIN: 0 no, 1 on the mesh, 2 on a guide's
// axis); its pin (normal, crease, normal impulse
// times the step, friction); how it touched at the end of the last step (C_LAST: 0 free,
// 1 held by friction, 2 sliding; C_LASTPN); its last detection (C_FOUND, normal, gap, whether
// the swept test found it, whether its centre is behind the wall); and, at the point's index, the
// element query of the element that starts there (C_RG found, normal, wall point, gap); the
// wall's force on it over the last step (C_FORCE); its clearance from the mesh (C_CLEAR2 about
// C_CLEAR_AT); the ball of its near list (C_LAT, radius C_LR, not positive: no list) and, at
// the point's index, the ball of the element's near list (C_EAT, C_ER).
const CSS: u32 = 56u;
const C_PIN: u32 = 0u;
const C_N: u32 = 1u;
const C_CR: u32 = 4u;
const C_M: u32 = 5u;
const C_PN: u32 = 8u;
const C_FR: u32 = 9u;
const C_START: u32 = 10u;
const C_MUS: u32 = 13u;
const C_MUK: u32 = 14u;
const C_DEL: u32 = 15u;
const C_DIR: u32 = 16u;
const C_KAL: u32 = 19u;
const C_KAC: u32 = 20u;
const C_SLD: u32 = 21u;
const C_LAST: u32 = 22u;
const C_LASTPN: u32 = 23u;
const C_FOUND: u32 = 24u;
const C_DN: u32 = 25u;
const C_DG: u32 = 28u;
const C_SWEPT: u32 = 29u;
// The point's clearance: the squared distance it may move from C_CLEAR_AT before any triangle
// can come within its reach (not positive: none).
const C_CLEAR2: u32 = 30u;
const C_CLEAR_AT: u32 = 45u;
const C_RG: u32 = 33u;
const C_RN: u32 = 34u;
const C_RW: u32 = 37u;
const C_RGAP: u32 = 40u;
const C_ESC: u32 = 41u;
// The wall's force on the point over the last accepted step [N] (normal and friction), while
// C_LAST says it touched.
const C_FORCE: u32 = 42u;
const C_LAT: u32 = 48u;
const C_LR: u32 = 51u;
const C_EAT: u32 = 52u;
const C_ER: u32 = 55u;

// The CPU's constants (`contact.rs`, `pin.rs`, `mesh_contact.rs`).
const DEPTH_TOLERANCE: f64 = 2e-2lf;
const ITERATION_MOVE: f64 = 1.0lf;
// cos(NORMAL_TURN), NORMAL_TURN = 0.1 rad.
const COS_NORMAL_TURN: f64 = 0.9950041652780258lf;
const CREASE_COS: f64 = 0.95lf;
const MAX_ROUNDS: u32 = 4u;
const LOOSE_ROUND: f64 = 30.0lf;
const NORMAL_CHANGE: f64 = 0.1lf;
const STICK_SPEED: f64 = 1e-4lf;
const SWEEP_FRACTION: f64 = 0.5lf;
const SEGMENT_END: f64 = 1e-6lf;
const SEGMENT_TOLERANCE: f64 = 0.02lf;
// How far a near list reaches beyond the query it was made for, in the point's reach (radius and
// margin): the list serves every query until its point has moved that far.
const LIST_SKIN: f64 = 1.0lf;

fn cbase(rod: u32, i: u32) -> u32 {
    return (rod * NPT + i) * CSS;
}
fn cg1(rod: u32, i: u32, k: u32) -> f64 {
    return cs[cbase(rod, i) + k];
}
fn cp1(rod: u32, i: u32, k: u32, v: f64) {
    cs[cbase(rod, i) + k] = v;
}
fn cg3(rod: u32, i: u32, k: u32) -> vec3<f64> {
    let b = cbase(rod, i) + k;
    return vec3<f64>(cs[b], cs[b + 1u], cs[b + 2u]);
}
fn cp3(rod: u32, i: u32, k: u32, v: vec3<f64>) {
    let b = cbase(rod, i) + k;
    cs[b] = v.x;
    cs[b + 1u] = v.y;
    cs[b + 2u] = v.z;
}

// Where the near lists of point i and of the element starting at it begin in `near`.
fn near_base(rod: u32, i: u32) -> u32 {
    return (rod * NPT + i) * 2u * NEAR_WORDS;
}

// After a walk made the list at `list` for the ball of radius `w` about `centre`: keeps the ball
// at `at` (its centre, then its radius) of point or element i, or marks it unusable when the
// list overflowed.
fn keep_ball(rod: u32, i: u32, at: u32, list: u32, centre: vec3<f64>, w: f64) {
    if near[list] == NEAR_FULL {
        cp1(rod, i, at + 3u, -1.0lf);
        return;
    }
    // Rounding of the distances must not widen the ball.
    cp1(rod, i, at + 3u, w * (1.0lf - 1e-9lf));
    cp3(rod, i, at, centre);
}

// The sphere query of point i at `x` (`sphere_walk`): from its near list while the sphere lies in
// the list's ball, else by a walk of the tree that makes the list again.
fn point_query(rod: u32, i: u32, x: vec3<f64>, reach: f64, away: vec3<f64>, cos_max: f64) -> SphereHit {
    let list = near_base(rod, i);
    let lr = cg1(rod, i, C_LR);
    if lr > 0.0lf {
        let dist = norm3(x - cg3(rod, i, C_LAT));
        if dist + reach <= lr {
            let bound = lr - dist;
            return sphere_list(x, reach, away, cos_max, list, bound * bound);
        }
    }
    atomicAdd(&wg_counts[4], 1u);
    let w = reach * (1.0lf + LIST_SKIN);
    let acc = sphere_walk(x, reach, away, cos_max, list, w);
    keep_ball(rod, i, C_LAT, list, x, w);
    return acc;
}

// The swept test of point i moving from `o` by `d` (`first_crossing64`): from its near list when
// the motion lies in the list's ball.
fn crossing_query(rod: u32, i: u32, o: vec3<f64>, d: vec3<f64>, reach: f64) -> Crossing64 {
    let lr = cg1(rod, i, C_LR);
    if lr > 0.0lf {
        let c = cg3(rod, i, C_LAT);
        if norm3(o - c) + reach <= lr && norm3(o + d - c) + reach <= lr {
            return first_crossing_list(o, d, near_base(rod, i));
        }
    }
    atomicAdd(&wg_counts[4], 1u);
    return first_crossing64(o, d);
}

// The element query of element j from `a` by `d` (`ridge_nearest`): from its near list while
// the query's ball lies in the list's, else by a walk that makes the list again.
fn element_query(rod: u32, j: u32, a: vec3<f64>, d: vec3<f64>, limit: f64) -> RidgeHit {
    let list = near_base(rod, j) + NEAR_WORDS;
    let centre = a + d * 0.5lf;
    let own = 0.5lf * norm3(d) + limit;
    let lr = cg1(rod, j, C_ER);
    if lr > 0.0lf && norm3(centre - cg3(rod, j, C_EAT)) + own <= lr {
        return ridge_list(a, d, limit, list);
    }
    atomicAdd(&wg_counts[4], 1u);
    let w = max(0.5lf * norm3(d) + (rod_radius(rod) + mesh_margin()) * (1.0lf + LIST_SKIN), own);
    let hit = ridge_nearest(a, d, limit, list, w);
    keep_ball(rod, j, C_EAT, list, centre, w);
    return hit;
}

fn rod_radius(rod: u32) -> f64 {
    return kx(rod, K_ROD + 32u);
}
fn mesh_margin() -> f64 {
    return glob[12];
}

// ---------------------------------------------------------------------------------------------
// A pinned point (`Pinned`) and its friction (`PinFriction`).

struct Pin {
    // Held on a line along `normal` (a guide's axis) instead of a plane across it.
    line: bool,
    normal: vec3<f64>,
    has_crease: bool,
    crease: vec3<f64>,
    pn: f64,
    fric: bool,
    start: vec3<f64>,
    mu_s: f64,
    mu_k: f64,
    delta: f64,
    dir: vec3<f64>,
    k_along: f64,
    k_across: f64,
    // -1 before the step's first freeze, 0 held, 1 sliding.
    sliding: f64,
}

fn is_pinned(rod: u32, i: u32) -> bool {
    return cg1(rod, i, C_PIN) != 0.0lf;
}
// Pinned on the mesh (`Pinned::on_mesh`), not on a guide's axis.
fn on_mesh(rod: u32, i: u32) -> bool {
    return cg1(rod, i, C_PIN) == 1.0lf;
}

fn load_pin(rod: u32, i: u32) -> Pin {
    var p: Pin;
    p.line = cg1(rod, i, C_PIN) == 2.0lf;
    p.normal = cg3(rod, i, C_N);
    p.has_crease = cg1(rod, i, C_CR) != 0.0lf;
    p.crease = cg3(rod, i, C_M);
    p.pn = cg1(rod, i, C_PN);
    p.fric = cg1(rod, i, C_FR) != 0.0lf;
    p.start = cg3(rod, i, C_START);
    p.mu_s = cg1(rod, i, C_MUS);
    p.mu_k = cg1(rod, i, C_MUK);
    p.delta = cg1(rod, i, C_DEL);
    p.dir = cg3(rod, i, C_DIR);
    p.k_along = cg1(rod, i, C_KAL);
    p.k_across = cg1(rod, i, C_KAC);
    p.sliding = cg1(rod, i, C_SLD);
    return p;
}

fn store_pin(rod: u32, i: u32, p: Pin) {
    cp1(rod, i, C_PIN, select(1.0lf, 2.0lf, p.line));
    cp3(rod, i, C_N, p.normal);
    cp1(rod, i, C_CR, select(0.0lf, 1.0lf, p.has_crease));
    cp3(rod, i, C_M, p.crease);
    cp1(rod, i, C_PN, p.pn);
    cp1(rod, i, C_FR, select(0.0lf, 1.0lf, p.fric));
    cp3(rod, i, C_START, p.start);
    cp1(rod, i, C_MUS, p.mu_s);
    cp1(rod, i, C_MUK, p.mu_k);
    cp1(rod, i, C_DEL, p.delta);
    cp3(rod, i, C_DIR, p.dir);
    cp1(rod, i, C_KAL, p.k_along);
    cp1(rod, i, C_KAC, p.k_across);
    cp1(rod, i, C_SLD, p.sliding);
}

// The friction's magnitude over p_n at a slip of length s, and its derivative (`law`).
fn fr_law(p: Pin, s: f64) -> vec2<f64> {
    let d = p.delta;
    if s <= d {
        return vec2<f64>(p.mu_s * s / d, p.mu_s / d);
    }
    if s < 2.0lf * d {
        let slope = (p.mu_k - p.mu_s) / d;
        return vec2<f64>(p.mu_s + slope * (s - d), slope);
    }
    return vec2<f64>(p.mu_k, 0.0lf);
}

fn fr_impulse(p: Pin, slip: vec3<f64>, pn: f64) -> vec3<f64> {
    let s = norm3(slip);
    if !(s > 0.0lf) || !(pn > 0.0lf) {
        return vec3<f64>();
    }
    return -slip * (fr_law(p, s).x * pn / s);
}

fn fr_freeze(p: ptr<function, Pin>, slip: vec3<f64>, pn0: f64) {
    let pn = max(pn0, 0.0lf);
    let s = norm3(slip);
    let law = fr_law(*p, s);
    if s <= (*p).delta {
        (*p).dir = select(vec3<f64>(), slip / s, s > 0.0lf);
        (*p).k_along = law.y * pn;
        (*p).k_across = law.y * pn;
        (*p).sliding = 0.0lf;
        return;
    }
    var continues = false;
    if (*p).sliding == 0.0lf {
        continues = true;
    } else if (*p).sliding > 0.0lf {
        continues = dot3((*p).dir, slip) > 0.0lf;
    }
    (*p).dir = slip / s;
    (*p).k_across = law.x * pn / s;
    (*p).k_along = select((*p).k_across, max(law.y, 0.0lf) * pn, continues);
    (*p).sliding = 1.0lf;
}

fn fr_tangent(p: Pin, slip: vec3<f64>, pn: f64) -> f64 {
    if norm3(slip) <= p.delta {
        return p.mu_s * max(pn, 0.0lf) / p.delta;
    }
    return 0.0lf;
}

fn fr_stiffness_along(p: Pin, e: vec3<f64>) -> f64 {
    let c = dot3(p.dir, e);
    return p.k_across + (p.k_along - p.k_across) * c * c;
}

fn fr_stale(p: Pin, slip: vec3<f64>, pn: f64, mass: f64) -> bool {
    var now = p;
    fr_freeze(&now, slip, pn);
    var t = p.dir;
    if dot3(now.dir, now.dir) > 0.5lf {
        t = now.dir;
    }
    if dot3(t, t) < 0.5lf {
        return false;
    }
    var across = vec3<f64>(0.0lf, 1.0lf, 0.0lf);
    if abs(t.x) < 0.9lf {
        across = vec3<f64>(1.0lf, 0.0lf, 0.0lf);
    }
    across = across - t * dot3(t, across);
    across = across / norm3(across);
    let r0 = (mass + fr_stiffness_along(p, t)) / (mass + fr_stiffness_along(now, t));
    let r1 = (mass + fr_stiffness_along(p, across)) / (mass + fr_stiffness_along(now, across));
    return !(r0 >= 0.5lf && r0 <= 2.0lf) || !(r1 >= 0.5lf && r1 <= 2.0lf);
}

// Two unit vectors perpendicular to the unit vector a and to each other (`perpendiculars`).
struct Dirs {
    a: vec3<f64>,
    b: vec3<f64>,
}

fn perpendiculars(a: vec3<f64>) -> Dirs {
    var pick = vec3<f64>(0.0lf, 0.0lf, 1.0lf);
    if abs(a.x) <= abs(a.y) && abs(a.x) <= abs(a.z) {
        pick = vec3<f64>(1.0lf, 0.0lf, 0.0lf);
    } else if abs(a.y) <= abs(a.z) {
        pick = vec3<f64>(0.0lf, 1.0lf, 0.0lf);
    }
    let c = cross3(a, pick);
    let b = c / norm3(c);
    return Dirs(b, cross3(a, b));
}

// The crease a point slides along (w = 1), if it is in one.
fn crease_direction(p: Pin) -> vec4<f64> {
    if !p.has_crease {
        return vec4<f64>();
    }
    let along = cross3(p.normal, p.crease);
    let nn = norm3(along);
    if nn > 0.0lf {
        return vec4<f64>(along / nn, 1.0lf);
    }
    return vec4<f64>();
}

fn sliding_part(p: Pin, v: vec3<f64>) -> vec3<f64> {
    if p.line {
        return p.normal * dot3(p.normal, v);
    }
    let t = crease_direction(p);
    if t.w > 0.0lf {
        return t.xyz * dot3(t.xyz, v);
    }
    return v - p.normal * dot3(p.normal, v);
}

fn pin_slip(p: Pin, x: vec3<f64>) -> vec3<f64> {
    return sliding_part(p, x - p.start);
}

fn free_directions(p: Pin) -> Dirs {
    if p.line {
        return Dirs(p.normal, vec3<f64>());
    }
    let t = crease_direction(p);
    if t.w > 0.0lf {
        return Dirs(t.xyz, vec3<f64>());
    }
    let n = p.normal;
    var first = perpendiculars(n).a;
    if p.fric && dot3(p.dir, p.dir) > 0.5lf {
        let f = p.dir - n * dot3(n, p.dir);
        first = f / norm3(f);
    }
    return Dirs(first, cross3(n, first));
}

fn mobility_along(p: Pin, w: f64, e: vec3<f64>) -> f64 {
    if all(e == vec3<f64>()) {
        return 0.0lf;
    }
    if p.fric && w > 0.0lf {
        return 1.0lf / (1.0lf / w + fr_stiffness_along(p, e));
    }
    return w;
}

fn mobility_times(p: Pin, w: f64, v: vec3<f64>) -> vec3<f64> {
    let d = free_directions(p);
    return d.a * (mobility_along(p, w, d.a) * dot3(d.a, v)) + d.b * (mobility_along(p, w, d.b) * dot3(d.b, v));
}

// The walls' normal impulse within a pin's impulse g (`walls_impulse`): (p_n, whether it leaves
// its crease), and the normal of the wall it stays on.
struct WallsImpulse {
    pn: f64,
    off: bool,
    normal: vec3<f64>,
}

fn walls_impulse(p: Pin, g: vec3<f64>) -> WallsImpulse {
    let pn = dot3(p.normal, g);
    if !p.has_crease {
        return WallsImpulse(pn, false, p.normal);
    }
    let m = p.crease;
    let gm = dot3(m, g);
    let c = dot3(p.normal, m);
    let det = 1.0lf - c * c;
    let a = (pn - c * gm) / det;
    let b = (gm - c * pn) / det;
    if a > 0.0lf && b > 0.0lf {
        return WallsImpulse(a + b, false, p.normal);
    }
    if a > 0.0lf {
        return WallsImpulse(a, true, p.normal);
    }
    if b > 0.0lf {
        return WallsImpulse(b, true, m);
    }
    return WallsImpulse(0.0lf, false, p.normal);
}

// `M (x − x̃) − (J_rᵀ λ)_i` (`pin_impulse`), at the Jacobians of the last `constraints`.
fn pin_impulse(rod: u32, i: u32, n: u32) -> vec3<f64> {
    let f = point_term(rod, W_LAM_G, i32(i) - 1, n, false) - point_term(rod, W_LAM_G, i32(i), n, false);
    return (s3(rod, S_X, i) - s3(rod, S_X_PRED, i)) / k1(rod, K_IM, i) - f;
}

// ---------------------------------------------------------------------------------------------
// Putting points on the wall.

// Puts point i, behind the wall of `normal` by `gap`, back on it (`back_on_walls`); returns
// whether the matrix changed.
fn back_on_walls(rod: u32, i: u32, p: ptr<function, Pin>, normal: vec3<f64>, gap: f64, radius: f64) -> bool {
    let x = s3(rod, S_X, i);
    var stay = vec3<f64>();
    var has_stay = false;
    var turned = false;
    let near_n = dot3((*p).normal, normal) >= COS_NORMAL_TURN;
    let near_m = (*p).has_crease && dot3((*p).crease, normal) >= COS_NORMAL_TURN;
    if -gap > radius {
        turned = (*p).has_crease || !near_n;
        (*p).normal = normal;
        (*p).has_crease = false;
    } else if (*p).has_crease && near_m {
        (*p).crease = normal;
        stay = (*p).normal;
        has_stay = true;
    } else if (*p).has_crease && near_n {
        stay = (*p).crease;
        has_stay = true;
        (*p).normal = normal;
    } else if !(*p).has_crease && near_n {
        (*p).normal = normal;
    } else if abs(dot3((*p).normal, normal)) <= CREASE_COS {
        stay = (*p).normal;
        has_stay = true;
        (*p).crease = normal;
        (*p).has_crease = true;
        turned = true;
    } else {
        (*p).normal = normal;
        (*p).has_crease = false;
        turned = true;
    }
    var moved = -normal * gap;
    if has_stay {
        let c = dot3(stay, normal);
        if 1.0lf - c * c > 1e-6lf {
            let beta = -gap / (1.0lf - c * c);
            moved = normal * beta - stay * (c * beta);
        }
    }
    put_s3(rod, S_X, i, x + moved);
    return turned;
}

// Pins point i on the plane through its wall point (`StiffContacts::pin`).
fn pin_on(rod: u32, i: u32, normal: vec3<f64>, gap: f64, stick: bool, pn: f64, h: f64) {
    let x = s3(rod, S_X, i);
    let on_wall = x - normal * gap;
    let start = w3(rod, W_X_OLD, i);
    let base = select(x, start, stick);
    put_s3(rod, S_X, i, base - normal * dot3(normal, base - on_wall));
    var p: Pin;
    p.normal = normal;
    p.pn = pn;
    p.sliding = -1.0lf;
    let mu_s = glob[13];
    let mu_k = glob[14];
    if mu_s > 0.0lf || mu_k > 0.0lf {
        p.fric = true;
        p.start = start;
        p.mu_s = max(mu_s, mu_k);
        p.mu_k = mu_k;
        p.delta = STICK_SPEED * h;
        if cg1(rod, i, C_LAST) == 2.0lf {
            // Sliding at the end of the last step: on along its predicted slip (`continuing`).
            let predicted = s3(rod, S_X_PRED, i) - start;
            let along = predicted - normal * dot3(normal, predicted);
            let a = norm3(along);
            if a > 0.0lf {
                p.dir = along / a;
                p.sliding = 1.0lf;
            }
        }
    }
    store_pin(rod, i, p);
}

// The two walls point i touches within `tol`, when they meet at an angle (`two_walls`): a
// crease found (w of the first) and, as (normal, gap) pairs, the nearest and the nearest at an
// angle to it.
struct TwoWalls {
    found: bool,
    n1: vec3<f64>,
    g1: f64,
    n2: vec3<f64>,
    g2: f64,
}

fn two_walls(rod: u32, i: u32, tol: f64) -> TwoWalls {
    var out: TwoWalls;
    // A point the swept test caught has no sphere contacts.
    if cg1(rod, i, C_SWEPT) != 0.0lf {
        return out;
    }
    let radius = rod_radius(rod);
    let reach = radius + mesh_margin();
    let x = s3(rod, S_X, i);
    let first = point_query(rod, i, x, reach, vec3<f64>(), 2.0lf);
    if first.wall_sd < 0.0lf || first.wall_sd - radius > tol {
        return out;
    }
    let second = point_query(rod, i, x, reach, first.wall_n, CREASE_COS);
    if second.wall_sd < 0.0lf || second.wall_sd - radius > tol {
        return out;
    }
    out.found = true;
    out.n1 = first.wall_n;
    out.g1 = first.wall_sd - radius;
    out.n2 = second.wall_n;
    out.g2 = second.wall_sd - radius;
    return out;
}

// Pins point i touching the wall of (normal, gap), and the second wall of a crease
// (`pin_touching`).
fn pin_touching(rod: u32, i: u32, normal0: vec3<f64>, gap0: f64, walls: TwoWalls, h: f64) {
    var normal = normal0;
    var gap = gap0;
    if walls.found {
        normal = walls.n1;
        gap = walls.g1;
    }
    let before = s3(rod, S_X, i);
    let last = cg1(rod, i, C_LAST);
    var stick = last == 1.0lf;
    let has_pn = last != 0.0lf;
    if !has_pn {
        let along = w3(rod, W_V_START, i) * h;
        let tangential = along - normal * dot3(normal, along);
        stick = norm3(tangential) <= STICK_SPEED * h;
    }
    pin_on(rod, i, normal, gap, stick, select(0.0lf, cg1(rod, i, C_LASTPN), has_pn), h);
    var p = load_pin(rod, i);
    if walls.found {
        let moved = s3(rod, S_X, i) - before;
        back_on_walls(rod, i, &p, walls.n2, walls.g2 + dot3(walls.n2, moved), rod_radius(rod));
    }
    if !has_pn {
        let stops = (s3(rod, S_X, i) - s3(rod, S_X_PRED, i)) / k1(rod, K_IM, i);
        p.pn = max(walls_impulse(p, stops).pn, 0.0lf);
    }
    store_pin(rod, i, p);
}

// ---------------------------------------------------------------------------------------------
// Detection (`StiffContacts::detect` without reuse: `RodMeshContact::detect_except` and
// `segment_contacts`), three passes with barriers between them. Counts of swept catches and
// element contacts go to `wg_counts`. As on the CPU, a point that has not left the ball its last
// query found free of triangles (its clearance) is not queried, a motion within that ball is not
// swept, and an element whose points' clearances cover it is not queried: each skips only what
// cannot touch, so the contacts are those of full queries.

// The step's swept catches, element contacts, pinned points, points behind the wall, and tree
// walks (queries the near lists could not answer).
var<workgroup> wg_counts: array<atomic<u32>, 5>;

fn detect_points(rod: u32, t: u32, n: u32) {
    let radius = rod_radius(rod);
    let margin = mesh_margin();
    let reach = radius + margin;
    let far2 = (SWEEP_FRACTION * reach) * (SWEEP_FRACTION * reach);
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        let x = s3(rod, S_X, i);
        let x_old = w3(rod, W_X_OLD, i);
        let d = x - x_old;
        var found = false;
        var swept = false;
        var escaped = false;
        var normal = vec3<f64>();
        var gap = 0.0lf;
        let c2 = cg1(rod, i, C_CLEAR2);
        let centre = cg3(rod, i, C_CLEAR_AT);
        let due = !(dot3(x - centre, x - centre) < c2);
        var within = false;
        if c2 > 0.0lf {
            let free = (sqrt(c2) + reach) * (sqrt(c2) + reach);
            within = dot3(x - centre, x - centre) < free && dot3(x_old - centre, x_old - centre) < free;
        }
        if dot3(d, d) > far2 && !within {
            let c = crossing_query(rod, i, x_old, d, reach);
            if c.f >= 0.0lf {
                let point = x_old + d * c.f;
                normal = tri3(c.slot, 3u);
                let ahead = dot3(x - point, normal);
                gap = ahead - radius;
                escaped = ahead < 0.0lf;
                found = true;
                swept = true;
                cp1(rod, i, C_CLEAR2, -1.0lf);
                atomicAdd(&wg_counts[0], 1u);
            }
        }
        if !swept && due {
            let acc = point_query(rod, i, x, reach, vec3<f64>(), 2.0lf);
            let r = sphere_response(acc);
            escaped = r.escaped;
            var clear = -1.0lf;
            if acc.count == 0u {
                // Rounding of the distances must not open a gap.
                let clearance = sqrt(acc.near2) - reach - 1e-9lf;
                if clearance > 0.0lf {
                    clear = clearance * clearance;
                }
            } else if norm3(r.dir) > 0.0lf {
                found = true;
                normal = r.dir;
                gap = -(r.depth - margin);
            }
            cp1(rod, i, C_CLEAR2, clear);
            cp3(rod, i, C_CLEAR_AT, x);
        }
        cp1(rod, i, C_FOUND, select(0.0lf, 1.0lf, found));
        cp3(rod, i, C_DN, normal);
        cp1(rod, i, C_DG, gap);
        cp1(rod, i, C_SWEPT, select(0.0lf, 1.0lf, swept));
        cp1(rod, i, C_ESC, select(0.0lf, 1.0lf, escaped));
    }
}

// How far beyond its reach point i at `x` is from the mesh at least (0 when unknown).
fn clearance_left(rod: u32, i: u32, x: vec3<f64>) -> f64 {
    let c2 = cg1(rod, i, C_CLEAR2);
    if !(c2 > 0.0lf) {
        return 0.0lf;
    }
    let c = cg3(rod, i, C_CLEAR_AT);
    return max(sqrt(c2) - sqrt(dot3(x - c, x - c)), 0.0lf);
}

// A point's own gap for the element queries: its contact's, or the margin.
fn own_gap(rod: u32, i: u32) -> f64 {
    if cg1(rod, i, C_FOUND) != 0.0lf {
        return cg1(rod, i, C_DG);
    }
    return mesh_margin();
}

fn detect_elements(rod: u32, t: u32, n: u32) {
    let radius = rod_radius(rod);
    for (var e = 0u; e < EPT; e++) {
        let j = first_of(t) + e;
        if j >= n {
            break;
        }
        cp1(rod, j, C_RG, 0.0lf);
        let a = s3(rod, S_X, j);
        let b = s3(rod, S_X, j + 1u);
        // Points whose clearances cover the element: it cannot reach the mesh.
        let clear = clearance_left(rod, j, a) + clearance_left(rod, j + 1u, b);
        if clear * clear >= dot3(b - a, b - a) {
            continue;
        }
        let limit = min(own_gap(rod, j), own_gap(rod, j + 1u)) + radius - SEGMENT_TOLERANCE * radius;
        if !(limit > 0.0lf) {
            continue;
        }
        let hit = element_query(rod, j, a, s3(rod, S_X, j + 1u) - a, limit);
        if !hit.found || !(hit.fraction >= SEGMENT_END && hit.fraction <= 1.0lf - SEGMENT_END) {
            continue;
        }
        atomicAdd(&wg_counts[1], 1u);
        cp1(rod, j, C_RG, 1.0lf);
        cp3(rod, j, C_RN, hit.normal);
        cp3(rod, j, C_RW, hit.on_wall);
        cp1(rod, j, C_RGAP, hit.signed_distance - radius);
    }
}

// The element contacts of its two elements on a point nearer than its own (merged as the CPU's
// `pending`: the mean normal, the lesser gap).
fn merge_elements(rod: u32, t: u32, n: u32) {
    let radius = rod_radius(rod);
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        let x = s3(rod, S_X, i);
        let own = own_gap(rod, i);
        var sum = vec3<f64>();
        var gap = 0.0lf;
        var any = false;
        for (var k = 0u; k < 2u; k++) {
            if (k == 0u && i == 0u) || (k == 1u && i >= n) {
                continue;
            }
            let j = i + k - 1u;
            if cg1(rod, j, C_RG) == 0.0lf {
                continue;
            }
            let nrm = cg3(rod, j, C_RN);
            let end_gap = dot3(nrm, x - cg3(rod, j, C_RW)) - radius;
            if end_gap >= own {
                continue;
            }
            sum += nrm;
            gap = select(end_gap, min(gap, end_gap), any);
            any = true;
        }
        if any {
            cp1(rod, i, C_FOUND, 1.0lf);
            cp3(rod, i, C_DN, sum / norm3(sum));
            cp1(rod, i, C_DG, gap);
        }
    }
}

// The whole detection at the current positions, swept from the step's start.
fn contact_detect(rod: u32, t: u32, n: u32) {
    detect_points(rod, t, n);
    sync();
    detect_elements(rod, t, n);
    sync();
    merge_elements(rod, t, n);
}

// ---------------------------------------------------------------------------------------------
// The passes of the step that contacts take part in.

// Step 1 of `contact.rs` (`begin_step`), after the prediction: pins the points touching the mesh
// at the solve's starting guess.
fn contact_begin(rod: u32, t: u32, n: u32, h: f64) {
    contact_detect(rod, t, n);
    let tol = DEPTH_TOLERANCE * rod_radius(rod);
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        let gap = cg1(rod, i, C_DG);
        if cg1(rod, i, C_FOUND) == 0.0lf || k1(rod, K_IM, i) == 0.0lf || gap > tol || is_pinned(rod, i) {
            continue;
        }
        let normal = cg3(rod, i, C_DN);
        let x_old = w3(rod, W_X_OLD, i);
        let towards = dot3(normal, s3(rod, S_X_PRED, i) - x_old);
        let along = w3(rod, W_V_START, i) * h;
        let slides = norm3(along - normal * dot3(normal, along)) > STICK_SPEED * h;
        if cg1(rod, i, C_LAST) == 0.0lf && gap >= -tol && (towards > 0.0lf || slides) {
            continue;
        }
        pin_touching(rod, i, normal, gap, two_walls(rod, i, tol), h);
    }
}

// Freezes the pinned points' friction for the Newton matrix (`freeze_friction`).
fn freeze_own(rod: u32, t: u32, n: u32) {
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        if !is_pinned(rod, i) {
            continue;
        }
        var p = load_pin(rod, i);
        if p.fric {
            fr_freeze(&p, pin_slip(p, s3(rod, S_X, i)), p.pn);
            store_pin(rod, i, p);
        }
    }
}

// A pinned point's rows of `u` (`pinned_balance`): returns `u`, and adds to `acc` its residual
// (x) and its friction's imbalance over the holding slip (y).
fn pinned_balance(rod: u32, i: u32, n: u32, u0: vec3<f64>, acc: ptr<function, vec2<f64>>) -> vec3<f64> {
    let w = k1(rod, K_IM, i);
    let p = load_pin(rod, i);
    if !(p.fric && w > 0.0lf) {
        return sliding_part(p, u0);
    }
    let slip = pin_slip(p, s3(rod, S_X, i));
    let ii = sliding_part(p, u0 / w + fr_impulse(p, slip, p.pn));
    let correction = norm3(ii) / (1.0lf / w + fr_tangent(p, slip, p.pn));
    let u = mobility_times(p, w, ii);
    var il = 0.0lf;
    if i >= 1u {
        il = k1(rod, K_IL, i - 1u);
    }
    if i < n {
        il = max(il, k1(rod, K_IL, i));
    }
    (*acc).x = max((*acc).x, norm3(u) * il);
    (*acc).y = max((*acc).y, correction / p.delta);
    return u;
}

// A pinned point's update `u + K⁻¹ Jᵀ Δλ` from `u` and `added = M⁻¹ Jᵀ Δλ` (`pinned_update`).
fn pinned_update(rod: u32, i: u32, u: vec3<f64>, added: vec3<f64>) -> vec3<f64> {
    let w = k1(rod, K_IM, i);
    let p = load_pin(rod, i);
    if p.fric && w > 0.0lf {
        return u + mobility_times(p, w, added / w);
    }
    return u + sliding_part(p, added);
}

fn outer3(a: vec3<f64>, b: vec3<f64>) -> mat3x3<f64> {
    return mat3x3<f64>(a * b.x, a * b.y, a * b.z);
}

// `R_jᵀ e / l0_j`: a direction of point motion as element j's stretch–shear rows see it.
fn project_on(rod: u32, j: u32, e: vec3<f64>) -> vec3<f64> {
    let d = dirs(rod, j);
    return vec3<f64>(dot3(d[0], e), dot3(d[1], e), dot3(d[2], e)) * k1(rod, K_IL, j);
}

// The directions a pin removes from point i's inverse mass, and by how much (`pin_blocks`).
struct Removed {
    e: array<vec3<f64>, 4>,
    c: vec4<f64>,
}

fn removed_of(rod: u32, i: u32) -> Removed {
    let w = k1(rod, K_IM, i);
    let p = load_pin(rod, i);
    var out: Removed;
    let t = crease_direction(p);
    if p.line {
        let h = perpendiculars(p.normal);
        out.e[0] = h.a;
        out.e[1] = h.b;
        out.c.y = w;
    } else if t.w > 0.0lf {
        let h = perpendiculars(t.xyz);
        out.e[0] = h.a;
        out.e[1] = h.b;
        out.c.y = w;
    } else {
        out.e[0] = p.normal;
    }
    out.c.x = w;
    let f = free_directions(p);
    out.e[2] = f.a;
    out.e[3] = f.b;
    out.c.z = w - mobility_along(p, w, f.a);
    out.c.w = w - mobility_along(p, w, f.b);
    return out;
}

// Element j's Γ blocks less its points' pinned directions: its diagonal block `dg`, and its
// coupling to element j + 1 `gsecond` (through point j + 1).
fn pin_rows(rod: u32, j: u32, n: u32, dg: ptr<function, mat3x3<f64>>, gsecond: ptr<function, mat3x3<f64>>) {
    for (var k = 0u; k < 2u; k++) {
        let i = j + k;
        if !is_pinned(rod, i) || k1(rod, K_IM, i) == 0.0lf {
            continue;
        }
        let r = removed_of(rod, i);
        for (var q = 0u; q < 4u; q++) {
            let c = r.c[q];
            let e = r.e[q];
            if c == 0.0lf || all(e == vec3<f64>()) {
                continue;
            }
            let a = project_on(rod, j, e);
            *dg -= outer3(a, a) * c;
            if k == 1u && i < n {
                *gsecond += outer3(a, project_on(rod, i, e)) * c;
            }
        }
    }
}

// After an iteration (`catch_penetrations`): pins the points the iterate pushed into the mesh,
// puts pinned points that left their plane back on the wall, lets go of pinned points the
// detection no longer sees. Returns the invocation's bits: 1 changed, 2 the matrix changed.
fn catch_penetrations(rod: u32, t: u32, n: u32, h: f64) -> u32 {
    contact_detect(rod, t, n);
    let radius = rod_radius(rod);
    let tol = DEPTH_TOLERANCE * radius;
    var bits = 0u;
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        let found = cg1(rod, i, C_FOUND) != 0.0lf;
        if !found {
            if on_mesh(rod, i) {
                cp1(rod, i, C_PIN, 0.0lf);
                bits |= 3u;
            }
            continue;
        }
        // Held points and guided ones are where their holders put them.
        if k1(rod, K_IM, i) == 0.0lf || (is_pinned(rod, i) && !on_mesh(rod, i)) {
            continue;
        }
        let gap = cg1(rod, i, C_DG);
        if !(gap < -tol) {
            continue;
        }
        let normal = cg3(rod, i, C_DN);
        if is_pinned(rod, i) {
            var p = load_pin(rod, i);
            if back_on_walls(rod, i, &p, normal, gap, radius) {
                bits |= 2u;
            }
            store_pin(rod, i, p);
            bits |= 1u;
        } else {
            pin_touching(rod, i, normal, gap, two_walls(rod, i, tol), h);
            bits |= 3u;
        }
    }
    return bits;
}

// After a round of the solve (`StiffContacts::update`): lets go of the points the wall would
// have to pull, gives the others this round's normal impulse, then catches penetrations.
// Returns the invocation's bits: 1 solve again, 2 the matrix changed.
fn contact_update(rod: u32, t: u32, n: u32, h: f64) -> u32 {
    var changed = false;
    var matrix = false;
    var released = false;
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        if !on_mesh(rod, i) {
            continue;
        }
        var p = load_pin(rod, i);
        let wi = walls_impulse(p, pin_impulse(rod, i, n));
        if wi.off {
            p.normal = wi.normal;
            p.has_crease = false;
            matrix = true;
            changed = true;
        }
        if !(wi.pn > 0.0lf) {
            released = true;
            cp1(rod, i, C_PIN, 0.0lf);
            continue;
        }
        let w = k1(rod, K_IM, i);
        let moved = p.fric && abs(wi.pn - p.pn) > NORMAL_CHANGE * wi.pn;
        p.pn = wi.pn;
        var stale = false;
        if p.fric && w > 0.0lf {
            stale = fr_stale(p, pin_slip(p, s3(rod, S_X, i)), p.pn, 1.0lf / w);
        }
        changed = changed || moved || stale;
        matrix = matrix || stale;
        store_pin(rod, i, p);
    }
    let caught = catch_penetrations(rod, t, n, h);
    var bits = 0u;
    if (caught & 1u) != 0u || changed || released {
        bits |= 1u;
    }
    if released || matrix || (caught & 2u) != 0u {
        bits |= 2u;
    }
    return bits;
}

// At the end of an accepted step (`end_step`): how each point touches, for the next step, and
// the wall's force on it (`record_forces`: its pin's impulse over the step squared). Returns the
// invocation's pinned points.
fn contact_end(rod: u32, t: u32, n: u32) -> u32 {
    let h = glob[0];
    var pinned = 0u;
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        var last = 0.0lf;
        if on_mesh(rod, i) {
            pinned += 1u;
            let p = load_pin(rod, i);
            last = 2.0lf;
            if p.fric && norm3(pin_slip(p, s3(rod, S_X, i))) <= p.delta {
                last = 1.0lf;
            }
            cp1(rod, i, C_LASTPN, p.pn);
            cp3(rod, i, C_FORCE, pin_impulse(rod, i, n) / (h * h));
        }
        cp1(rod, i, C_LAST, last);
    }
    return pinned;
}

// The step's penetration and escaped points, from a detection at its end positions (held points
// left out): the deepest depth and the count, for the invocation's points.
fn contact_depth(rod: u32, t: u32, n: u32) -> vec2<f64> {
    var out = vec2<f64>();
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        if k1(rod, K_IM, i) == 0.0lf || cg1(rod, i, C_FOUND) == 0.0lf || (is_pinned(rod, i) && !on_mesh(rod, i)) {
            continue;
        }
        out.x = max(out.x, -cg1(rod, i, C_DG));
        out.y += cg1(rod, i, C_ESC);
    }
    return out;
}

// The end of a step's solve (`end_step`): how each point touches for the next step, and the
// statistics (`rep`), the penetration from a detection at the end positions.
fn contact_record(rod: u32, t: u32, n: u32) {
    let pinned = contact_end(rod, t, n);
    atomicAdd(&wg_counts[2], pinned);
    workgroupBarrier();
    if t == 0u {
        // The step's catches and element contacts, before the statistics' own detection.
        put_r1(rod, ST_SWEPT, r1(rod, ST_SWEPT) + f64(atomicLoad(&wg_counts[0])));
        put_r1(rod, ST_SEG, r1(rod, ST_SEG) + f64(atomicLoad(&wg_counts[1])));
        let c = f64(atomicLoad(&wg_counts[2]));
        put_r1(rod, ST_CONT, c);
        put_r1(rod, ST_MAXC, max(r1(rod, ST_MAXC), c));
        put_r1(rod, ST_CSTEPS, r1(rod, ST_CSTEPS) + 1.0lf);
    }
    sync();
    contact_detect(rod, t, n);
    let depth = contact_depth(rod, t, n);
    atomicAdd(&wg_counts[3], u32(depth.y));
    let deepest = workgroup_max(t, depth.x);
    if t == 0u {
        put_r1(rod, ST_PEN, max(r1(rod, ST_PEN), deepest));
        put_r1(rod, ST_ESC, max(r1(rod, ST_ESC), f64(atomicLoad(&wg_counts[3]))));
        put_r1(rod, ST_WALKS, r1(rod, ST_WALKS) + f64(atomicLoad(&wg_counts[4])));
        for (var k = 0u; k < 5u; k++) {
            atomicStore(&wg_counts[k], 0u);
        }
    }
    sync();
}

// ---------------------------------------------------------------------------------------------
// Pins that are not the mesh's.

// Every pin of the invocation's points goes at the start of a step (`w.pinned.clear()`).
fn clear_pins(rod: u32, t: u32, n: u32) {
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        cp1(rod, first_of(t) + e, C_PIN, 0.0lf);
    }
}

var<workgroup> guide_end: atomic<u32>;

// The introducer guide (`contact::pin_guided`): the run of points it holds from index 1 on (the
// first point being held by the hand), up to the first it does not, put on its axis and pinned
// to move along it only. The rod's guide: K_ROD + 33 whether it has one, + 34 its origin, + 37
// its unit axis, + 40 its length, + 41 its clearance.
fn guide_pins(rod: u32, t: u32, n: u32) {
    let has = kx(rod, K_ROD + 33u) > 0.0lf;
    let origin = vec3<f64>(kx(rod, K_ROD + 34u), kx(rod, K_ROD + 35u), kx(rod, K_ROD + 36u));
    let axis = vec3<f64>(kx(rod, K_ROD + 37u), kx(rod, K_ROD + 38u), kx(rod, K_ROD + 39u));
    let length = kx(rod, K_ROD + 40u);
    let clearance = kx(rod, K_ROD + 41u);
    if t == 0u {
        atomicStore(&guide_end, select(1u, n + 1u, has));
    }
    workgroupBarrier();
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        let rel = s3(rod, S_X, i) - origin;
        let along = dot3(rel, axis);
        let lateral = rel - axis * along;
        if i >= 1u && !(along < length && norm3(lateral) <= clearance) {
            atomicMin(&guide_end, i);
        }
    }
    workgroupBarrier();
    let end = atomicLoad(&guide_end);
    for (var e = 0u; e <= EPT; e++) {
        if !own_point(t, e, n) {
            break;
        }
        let i = first_of(t) + e;
        if i < 1u || i >= end || k1(rod, K_IM, i) == 0.0lf {
            continue;
        }
        let x = s3(rod, S_X, i);
        let rel = x - origin;
        put_s3(rod, S_X, i, x - (rel - axis * dot3(rel, axis)));
        var p: Pin;
        p.line = true;
        p.normal = axis;
        p.sliding = -1.0lf;
        store_pin(rod, i, p);
    }
}
