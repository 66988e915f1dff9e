// A static triangle mesh for the stiff step's contacts (`stiff_contact.wgsl`), in f64: the
// queries of the CPU's stiff contacts (`RodMeshContact` in backend-cpu `mesh_contact.rs`, on
// `cosserat_collide::MeshCollider`), formula for formula, so that the CPU is the oracle to
// rounding. The explicit kernels' `wall_contact.wgsl` answers the same questions in f32 with
// near lists; the stiff scheme keeps its state in f64 and pins points on the wall to within a
// fraction of a micrometre, so here the corners and pseudo-normals are the CPU's f64 values
// (`MeshCollider::wall_triangles_f64`); the tree's boxes are the CPU's f32 boxes, widened to f64
// as the CPU widens them. A query walks the tree only when the near list of its point or element
// (below) cannot answer it.
//
// Composed after stiff_step.wgsl only for simulations with a mesh.

struct StiffNode {
    lo: vec3<f32>,
    // Interior: left child (the right one follows it). Leaf: first triangle slot.
    first: u32,
    hi: vec3<f32>,
    // Triangles of a leaf; 0 for an interior node.
    count: u32,
}

@group(0) @binding(10) var<storage, read> mesh_nodes: array<StiffNode>;
// Per triangle slot (leaf order) TRI numbers: corners a, b, c, the face normal, the
// pseudo-normals of edges 0-2 and corners 0-2 (3 numbers each), then the boundary and ridge
// bits (as `GpuWallTriangle::boundary`) and the triangle's index in the mesh.
@group(0) @binding(11) var<storage, read> mesh_tris: array<f64>;

const TRI: u32 = 32u;
// The traversal stack (as the CPU's `STACK_SIZE`).
const MESH_STACK: u32 = 64u;

fn tri3(slot: u32, k: u32) -> vec3<f64> {
    let b = slot * TRI + 3u * k;
    return vec3<f64>(mesh_tris[b], mesh_tris[b + 1u], mesh_tris[b + 2u]);
}
fn tri_bits(slot: u32) -> u32 {
    return u32(mesh_tris[slot * TRI + 30u]);
}

fn node_distance2(p: vec3<f64>, nd: StiffNode) -> f64 {
    let lo = vec3<f64>(nd.lo);
    let hi = vec3<f64>(nd.hi);
    let d = max(max(lo - p, p - hi), vec3<f64>());
    return dot(d, d);
}

// Closest point on triangle abc to p (Ericson 5.1.5, collide `closest_point_triangle`) and its
// feature: 0 face, 1 + k edge k, 4 + k corner k.
struct Closest64 {
    c: vec3<f64>,
    feature: u32,
}

fn closest_on_triangle64(p: vec3<f64>, a: vec3<f64>, b: vec3<f64>, c: vec3<f64>) -> Closest64 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0lf && d2 <= 0.0lf {
        return Closest64(a, 4u);
    }
    let bp = p - b;
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0lf && d4 <= d3 {
        return Closest64(b, 5u);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0lf && d1 >= 0.0lf && d3 <= 0.0lf {
        return Closest64(a + ab * (d1 / (d1 - d3)), 1u);
    }
    let cp = p - c;
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0lf && d5 <= d6 {
        return Closest64(c, 6u);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0lf && d2 >= 0.0lf && d6 <= 0.0lf {
        return Closest64(a + ac * (d2 / (d2 - d6)), 3u);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0lf && (d4 - d3) >= 0.0lf && (d5 - d6) >= 0.0lf {
        return Closest64(b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))), 2u);
    }
    let denom = 1.0lf / (va + vb + vc);
    return Closest64(a + ab * (vb * denom) + ac * (vc * denom), 0u);
}

// The pseudo-normal of a feature: the face normal is number 3 of the slot, edge k number 4 + k,
// corner k number 7 + k.
fn feature_normal64(slot: u32, feature: u32) -> vec3<f64> {
    if feature == 0u {
        return tri3(slot, 3u);
    }
    return tri3(slot, 3u + feature);
}

fn feature_on_boundary64(slot: u32, feature: u32) -> bool {
    return feature != 0u && (tri_bits(slot) & (1u << (feature - 1u))) != 0u;
}

// A sphere's contacts with the mesh, summed as the CPU's `MeshCollider::respond`: over the
// contacts in front of their feature, and over all (when the nearest says the centre crossed
// the wall). With `crease_of` set, it also keeps the nearest wall in front (and, in a second
// walk, the nearest at an angle to a given one): `StiffContacts::two_walls`.
struct SphereHit {
    sum_front: vec3<f64>,
    w_front: f64,
    max_front: f64,
    sum_all: vec3<f64>,
    w_all: f64,
    max_all: f64,
    near_d2: f64,
    near_signed: f64,
    near_boundary: bool,
    count: u32,
    // The nearest wall in front (least signed distance >= 0) among those that pass `wall_filter`:
    // its pseudo-normal and signed distance (`wall_sd` < 0: none).
    wall_n: vec3<f64>,
    wall_sd: f64,
    // A lower bound of the squared distance to every triangle: the nearest tested, the plane's
    // distance of one ruled out by its plane, or the nearest box the walk did not enter (0 when
    // the stack overflowed and nodes were left out).
    near2: f64,
}

// Near lists: a point's (or an element's) triangles, kept between queries. A walk for a sphere
// of radius `r` may also list every triangle within a larger `w` of its centre (those whose box
// and plane are within `w`); while a later sphere of radius `r` about `p` lies inside that ball,
// the list holds every triangle the sphere can touch, in the walk's order, so scanning it gives
// the walk's answer to the last bit, at the cost of the list instead of the tree's levels of
// dependent loads. A list takes NEAR_WORDS words of `near`: the count, then the slots; a count of
// NEAR_FULL marks one that overflowed (the walk's answer stands, the list is not used).
@group(0) @binding(13) var<storage, read_write> near: array<u32>;

const NEAR_WORDS: u32 = 32u;
const NEAR_FULL: u32 = 0xffffffffu;

// Appends `slot` to the list at `list` holding `listed` entries; returns the new count,
// NEAR_FULL when it does not fit.
fn list_push(list: u32, listed: u32, slot: u32) -> u32 {
    if listed == NEAR_FULL || listed + 1u >= NEAR_WORDS {
        return NEAR_FULL;
    }
    near[list + 1u + listed] = slot;
    return listed + 1u;
}

// One triangle of a sphere query (`MeshCollider::query_sphere`'s test of a triangle), summed into
// `acc`; `best_wall` is the least signed distance of the walls kept so far.
fn sphere_triangle(
    acc: ptr<function, SphereHit>,
    best_wall: ptr<function, f64>,
    slot: u32,
    p: vec3<f64>,
    r: f64,
    away: vec3<f64>,
    cos_max: f64,
) {
    let r2 = r * r;
    let a = tri3(slot, 0u);
    let plane = dot(tri3(slot, 3u), p - a);
    // `TriData::beyond_plane` with `PLANE_REJECT`.
    if plane * plane > r2 * (1.0lf + 1e-9lf) {
        (*acc).near2 = min((*acc).near2, plane * plane);
        return;
    }
    let cl = closest_on_triangle64(p, a, tri3(slot, 1u), tri3(slot, 2u));
    let diff = p - cl.c;
    let d2 = dot(diff, diff);
    (*acc).near2 = min((*acc).near2, d2);
    if !(d2 < r2) {
        return;
    }
    let d = sqrt(d2);
    let n = feature_normal64(slot, cl.feature);
    let front = dot(diff, n) >= 0.0lf;
    let sd = select(-d, d, front);
    if d2 < (*acc).near_d2 {
        (*acc).near_d2 = d2;
        (*acc).near_signed = sd;
        (*acc).near_boundary = feature_on_boundary64(slot, cl.feature);
    }
    let depth = r - sd;
    (*acc).count += 1u;
    (*acc).sum_all += n * depth;
    (*acc).w_all += depth;
    (*acc).max_all = max((*acc).max_all, depth);
    if front {
        (*acc).sum_front += n * depth;
        (*acc).w_front += depth;
        (*acc).max_front = max((*acc).max_front, depth);
        if abs(dot(away, n)) <= cos_max && sd < *best_wall {
            *best_wall = sd;
            (*acc).wall_n = n;
            (*acc).wall_sd = sd;
        }
    }
}

fn sphere_start() -> SphereHit {
    var acc: SphereHit;
    acc.near_d2 = 1.0e300lf;
    acc.wall_sd = -1.0lf;
    acc.near2 = 1.0e300lf;
    return acc;
}

// Walks the tree for the sphere of radius `r` at `p` (`MeshCollider::query_sphere`). The walls
// in front are kept (`wall_n`, `wall_sd`) when `filter` is on: those whose normal makes a cosine
// of at most `cos_max` in magnitude with `away` (pass a zero `away` and 2 to keep every wall).
// It also lists at `list` the triangles within `w` >= `r` of `p` (the point's near list).
fn sphere_walk(p: vec3<f64>, r: f64, away: vec3<f64>, cos_max: f64, list: u32, w: f64) -> SphereHit {
    var acc = sphere_start();
    var best_wall = 1.0e300lf;
    let reach = max(w, r);
    let w2 = reach * reach;
    var listed = 0u;
    var stack: array<u32, MESH_STACK>;
    stack[0] = 0u;
    var sp = 1u;
    while sp > 0u {
        sp -= 1u;
        let nd = mesh_nodes[stack[sp]];
        let bd2 = node_distance2(p, nd);
        if bd2 > w2 {
            acc.near2 = min(acc.near2, bd2);
            continue;
        }
        if nd.count == 0u {
            if sp + 2u <= MESH_STACK {
                stack[sp] = nd.first;
                stack[sp + 1u] = nd.first + 1u;
                sp += 2u;
            } else {
                acc.near2 = 0.0lf;
                listed = NEAR_FULL;
            }
            continue;
        }
        for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
            if listed != NEAR_FULL {
                let plane = dot(tri3(slot, 3u), p - tri3(slot, 0u));
                if plane * plane <= w2 * (1.0lf + 1e-9lf) {
                    listed = list_push(list, listed, slot);
                }
            }
            sphere_triangle(&acc, &best_wall, slot, p, r, away, cos_max);
        }
    }
    near[list] = listed;
    return acc;
}

// The sphere query of `sphere_walk` answered from the list at `list`, made about a centre within
// its ball: `bound2` is the squared distance from `p` to the ball's surface, a lower bound of
// the distance to every triangle left out.
fn sphere_list(p: vec3<f64>, r: f64, away: vec3<f64>, cos_max: f64, list: u32, bound2: f64) -> SphereHit {
    var acc = sphere_start();
    acc.near2 = bound2;
    var best_wall = 1.0e300lf;
    let count = near[list];
    for (var k = 1u; k <= count; k++) {
        sphere_triangle(&acc, &best_wall, near[list + k], p, r, away, cos_max);
    }
    return acc;
}

// The point's response (`respond`): unit direction (zero: none), the deepest depth of the
// contacts that act, and whether the centre crossed the wall.
struct Response {
    dir: vec3<f64>,
    depth: f64,
    escaped: bool,
}

fn sphere_response(acc: SphereHit) -> Response {
    var out: Response;
    if acc.count == 0u {
        return out;
    }
    out.escaped = acc.near_signed < 0.0lf && !acc.near_boundary;
    let s = select(acc.sum_front, acc.sum_all, out.escaped);
    let w = select(acc.w_front, acc.w_all, out.escaped);
    let len = sqrt(dot(s, s));
    if w > 0.0lf && len > 0.0lf {
        out.dir = s / len;
        out.depth = select(acc.max_front, acc.max_all, out.escaped);
    }
    return out;
}

// Whether the segment o + s d, 0 <= s <= 1, passes through the box (collide `sweep::segment_box`).
fn segment_node(o: vec3<f64>, d: vec3<f64>, nd: StiffNode) -> bool {
    let lo = vec3<f64>(nd.lo);
    let hi = vec3<f64>(nd.hi);
    var enter = 0.0lf;
    var leave = 1.0lf;
    for (var k = 0u; k < 3u; k++) {
        if d[k] == 0.0lf {
            if o[k] < lo[k] || o[k] > hi[k] {
                return false;
            }
            continue;
        }
        let inv = 1.0lf / d[k];
        let t0 = (lo[k] - o[k]) * inv;
        let t1 = (hi[k] - o[k]) * inv;
        enter = max(enter, min(t0, t1));
        leave = min(leave, max(t0, t1));
        if enter > leave {
            return false;
        }
    }
    return true;
}

// The fraction along o + s d at which the segment meets triangle abc, or -1 (collide
// `sweep::segment_triangle`).
fn segment_triangle64(o: vec3<f64>, d: vec3<f64>, a: vec3<f64>, b: vec3<f64>, c: vec3<f64>) -> f64 {
    let slack = 1e-9lf;
    let e1 = b - a;
    let e2 = c - a;
    let p = cross(d, e2);
    let det = dot(e1, p);
    if abs(det) <= 1e-300lf {
        return -1.0lf;
    }
    let inv = 1.0lf / det;
    let s = o - a;
    let u = dot(s, p) * inv;
    if !(u >= -slack && u <= 1.0lf + slack) {
        return -1.0lf;
    }
    let q = cross(s, e1);
    let v = dot(d, q) * inv;
    if v < -slack || u + v > 1.0lf + slack {
        return -1.0lf;
    }
    let f = dot(e2, q) * inv;
    return select(-1.0lf, f, f >= 0.0lf && f <= 1.0lf);
}

// The first triangle the motion from `o` by `d` enters from the lumen side (`first_crossing`):
// the fraction (-1: none) and the slot.
struct Crossing64 {
    f: f64,
    slot: u32,
}

// One triangle of `first_crossing`: a crossing from the lumen side before `best` replaces it.
fn crossing_triangle(best: ptr<function, Crossing64>, slot: u32, o: vec3<f64>, d: vec3<f64>) {
    if dot(tri3(slot, 3u), d) >= 0.0lf {
        return;
    }
    let f = segment_triangle64(o, d, tri3(slot, 0u), tri3(slot, 1u), tri3(slot, 2u));
    if f >= 0.0lf && f < (*best).f {
        (*best).f = f;
        (*best).slot = slot;
    }
}

fn crossing_found(best: Crossing64) -> Crossing64 {
    return Crossing64(select(-1.0lf, best.f, best.f <= 1.0lf), best.slot);
}

fn first_crossing64(o: vec3<f64>, d: vec3<f64>) -> Crossing64 {
    var best = Crossing64(2.0lf, 0u);
    if all(d == vec3<f64>()) {
        return Crossing64(-1.0lf, 0u);
    }
    var stack: array<u32, MESH_STACK>;
    stack[0] = 0u;
    var sp = 1u;
    while sp > 0u {
        sp -= 1u;
        let nd = mesh_nodes[stack[sp]];
        if !segment_node(o, d, nd) {
            continue;
        }
        if nd.count > 0u {
            for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
                crossing_triangle(&best, slot, o, d);
            }
        } else if sp + 2u <= MESH_STACK {
            stack[sp] = nd.first;
            stack[sp + 1u] = nd.first + 1u;
            sp += 2u;
        }
    }
    return crossing_found(best);
}

// `first_crossing64` from a point's list, for a motion inside the list's ball.
fn first_crossing_list(o: vec3<f64>, d: vec3<f64>, list: u32) -> Crossing64 {
    var best = Crossing64(2.0lf, 0u);
    if all(d == vec3<f64>()) {
        return Crossing64(-1.0lf, 0u);
    }
    let count = near[list];
    for (var k = 1u; k <= count; k++) {
        crossing_triangle(&best, near[list + k], o, d);
    }
    return crossing_found(best);
}

// Closest points of segments p1 + s d1 and p2 + t d2 (collide `closest_points_segments`): (s, t).
fn segment_segment64(p1: vec3<f64>, d1: vec3<f64>, p2: vec3<f64>, d2: vec3<f64>) -> vec2<f64> {
    let r = p1 - p2;
    let a = dot(d1, d1);
    let e = dot(d2, d2);
    let f = dot(d2, r);
    let eps = 1e-300lf;
    if a <= eps && e <= eps {
        return vec2<f64>();
    }
    if a <= eps {
        return vec2<f64>(0.0lf, clamp(f / e, 0.0lf, 1.0lf));
    }
    let c = dot(d1, r);
    if e <= eps {
        return vec2<f64>(clamp(-c / a, 0.0lf, 1.0lf), 0.0lf);
    }
    let b = dot(d1, d2);
    let denom = a * e - b * b;
    var s = 0.0lf;
    if denom > 0.0lf {
        s = clamp((b * f - c * e) / denom, 0.0lf, 1.0lf);
    }
    var t = (b * s + f) / e;
    if t < 0.0lf {
        t = 0.0lf;
        s = clamp(-c / a, 0.0lf, 1.0lf);
    } else if t > 1.0lf {
        t = 1.0lf;
        s = clamp((b - c) / a, 0.0lf, 1.0lf);
    }
    return vec2<f64>(s, t);
}

// Squared distance between the segment p + s d and triangle abc, and the fraction s where it is
// reached (collide `segment_triangle_distance2`).
fn segment_triangle_distance2_64(p: vec3<f64>, d: vec3<f64>, a: vec3<f64>, b: vec3<f64>, c: vec3<f64>) -> vec2<f64> {
    let through = segment_triangle64(p, d, a, b, c);
    if through >= 0.0lf {
        return vec2<f64>(0.0lf, through);
    }
    let q = p + d;
    var best = vec2<f64>(1.0e300lf, 0.0lf);
    let c0 = closest_on_triangle64(p, a, b, c).c;
    let e0 = dot(p - c0, p - c0);
    if e0 < best.x {
        best = vec2<f64>(e0, 0.0lf);
    }
    let c1 = closest_on_triangle64(q, a, b, c).c;
    let e1 = dot(q - c1, q - c1);
    if e1 < best.x {
        best = vec2<f64>(e1, 1.0lf);
    }
    let st0 = segment_segment64(p, d, a, b - a);
    let x0 = p + d * st0.x - (a + (b - a) * st0.y);
    if dot(x0, x0) < best.x {
        best = vec2<f64>(dot(x0, x0), st0.x);
    }
    let st1 = segment_segment64(p, d, b, c - b);
    let x1 = p + d * st1.x - (b + (c - b) * st1.y);
    if dot(x1, x1) < best.x {
        best = vec2<f64>(dot(x1, x1), st1.x);
    }
    let st2 = segment_segment64(p, d, c, a - c);
    let x2 = p + d * st2.x - (c + (a - c) * st2.y);
    if dot(x2, x2) < best.x {
        best = vec2<f64>(dot(x2, x2), st2.x);
    }
    return best;
}

// Whether the triangle lies wholly before the start or past the end of the segment p + s d by
// more than r along it, or wholly farther than r to one side of the line across it in the
// triangle's plane (collide `segment::beyond_sides`).
fn beyond_sides64(p: vec3<f64>, d: vec3<f64>, slot: u32, r0: f64) -> bool {
    let len = sqrt(dot(d, d));
    if !(len > 0.0lf) {
        return false;
    }
    let r = r0 * (1.0lf + 1e-9lf);
    let a = tri3(slot, 0u) - p;
    let b = tri3(slot, 1u) - p;
    let c = tri3(slot, 2u) - p;
    let along = d / len;
    let xa = dot(along, a);
    let ya = dot(along, b);
    let za = dot(along, c);
    if min(min(xa, ya), za) > len + r || max(max(xa, ya), za) < -r {
        return true;
    }
    let across = cross(d, tri3(slot, 3u));
    let width = sqrt(dot(across, across));
    if !(width > 1e-9lf * len) {
        return false;
    }
    let axis = across / width;
    let xs = dot(axis, a);
    let ys = dot(axis, b);
    let zs = dot(axis, c);
    return min(min(xs, ys), zs) > r || max(max(xs, ys), zs) < -r;
}

// The ridge triangle nearest to the element from p to p + d within `limit` (collide
// `segment_nearest_among` over the element's list of ridge triangles): whether one is, the
// fraction along the element, the wall's nearest point, the signed distance and the direction
// from the wall to the element.
struct RidgeHit {
    found: bool,
    fraction: f64,
    on_wall: vec3<f64>,
    signed_distance: f64,
    normal: vec3<f64>,
}

// The nearest ridge triangle so far: its squared distance and fraction along the element, its
// slot, and whether there is one.
struct RidgeBest {
    d2: f64,
    s: f64,
    slot: u32,
    found: bool,
}

// One triangle of `segment_nearest_among`: a ridge triangle within `limit` of the element nearer
// than the best so far replaces it.
fn ridge_triangle(best: ptr<function, RidgeBest>, slot: u32, p: vec3<f64>, d: vec3<f64>, limit: f64) {
    if (tri_bits(slot) & 64u) == 0u {
        return;
    }
    let a = tri3(slot, 0u);
    let n = tri3(slot, 3u);
    let h0 = dot(n, p - a);
    let h1 = dot(n, p + d - a);
    if (h0 > limit && h1 > limit) || (h0 < -limit && h1 < -limit) || beyond_sides64(p, d, slot, limit) {
        return;
    }
    let ds = segment_triangle_distance2_64(p, d, a, tri3(slot, 1u), tri3(slot, 2u));
    if ds.x < limit * limit && (!(*best).found || ds.x < (*best).d2) {
        (*best).found = true;
        (*best).d2 = ds.x;
        (*best).s = ds.y;
        (*best).slot = slot;
    }
}

// The ridge triangle nearest to the element from p to p + d within `limit`, by a walk of the tree
// that also lists at `list` the ridge triangles within `w` of the element's centre (the
// element's near list).
fn ridge_nearest(p: vec3<f64>, d: vec3<f64>, limit: f64, list: u32, w: f64) -> RidgeHit {
    var best: RidgeBest;
    let centre = p + d * 0.5lf;
    let reach = max(w, 0.5lf * sqrt(dot(d, d)) + limit);
    let reach2 = reach * reach;
    var listed = 0u;
    var stack: array<u32, MESH_STACK>;
    stack[0] = 0u;
    var sp = 1u;
    while sp > 0u {
        sp -= 1u;
        let nd = mesh_nodes[stack[sp]];
        if node_distance2(centre, nd) > reach2 {
            continue;
        }
        if nd.count == 0u {
            if sp + 2u <= MESH_STACK {
                stack[sp] = nd.first;
                stack[sp + 1u] = nd.first + 1u;
                sp += 2u;
            } else {
                listed = NEAR_FULL;
            }
            continue;
        }
        for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
            if listed != NEAR_FULL && (tri_bits(slot) & 64u) != 0u {
                let plane = dot(tri3(slot, 3u), centre - tri3(slot, 0u));
                if plane * plane <= reach2 * (1.0lf + 1e-9lf) {
                    listed = list_push(list, listed, slot);
                }
            }
            ridge_triangle(&best, slot, p, d, limit);
        }
    }
    near[list] = listed;
    return ridge_hit(best, p, d);
}

// `ridge_nearest` from an element's list, for an element whose query lies inside the list's
// ball.
fn ridge_list(p: vec3<f64>, d: vec3<f64>, limit: f64, list: u32) -> RidgeHit {
    var best: RidgeBest;
    let count = near[list];
    for (var k = 1u; k <= count; k++) {
        ridge_triangle(&best, near[list + k], p, d, limit);
    }
    return ridge_hit(best, p, d);
}

fn ridge_hit(best: RidgeBest, p: vec3<f64>, d: vec3<f64>) -> RidgeHit {
    var out: RidgeHit;
    if !best.found {
        return out;
    }
    out.found = true;
    let best_slot = best.slot;
    let at = p + d * best.s;
    let cl = closest_on_triangle64(at, tri3(best_slot, 0u), tri3(best_slot, 1u), tri3(best_slot, 2u));
    let diff = at - cl.c;
    let distance = sqrt(best.d2);
    out.fraction = best.s;
    out.on_wall = cl.c;
    if distance > 0.0lf {
        let side = select(-1.0lf, 1.0lf, dot(diff, feature_normal64(best_slot, cl.feature)) >= 0.0lf);
        out.signed_distance = side * distance;
        out.normal = diff * (side / distance);
    } else {
        out.normal = tri3(best_slot, 3u);
    }
    return out;
}
