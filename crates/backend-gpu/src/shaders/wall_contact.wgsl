// Contact of rod points with a static triangle mesh (a vessel wall): the GPU twin of
// cosserat_collide's sphere query (`MeshCollider::query_sphere`) and swept test
// (`MeshCollider::first_crossing`), on the same tree (`Bvh::nodes`) and the same triangles in leaf
// order (`MeshCollider::wall_triangles`).
//
// Composed after common.wgsl into kernels with the MESH flag. A point is a sphere of the rod's
// radius plus the speculative margin; every triangle whose closest point lies within that reach is
// a contact, with the normal of the feature (face, edge or corner pseudo-normal) that holds the
// closest point, signed by that normal. The point's response is the depth-weighted mean of the
// normals; the nearest triangle's sign says whether the centre has crossed the wall (escaped),
// and only then do triangles seen from behind count. See crates/collide/src/contact.rs for why.
//
// Everything is in f32 (the CPU tests in f64 on the same f32 tree): the contacts agree except
// where a triangle lies within rounding of the reach.

struct WallNode {
    lo: vec3<f32>,
    // Interior: left child (the right one follows it). Leaf: first triangle slot.
    first: u32,
    hi: vec3<f32>,
    // Triangles of a leaf; 0 for an interior node.
    count: u32,
}

struct WallTri {
    a: vec3<f32>,
    // Bits 0-2: edge k (corner k to k + 1) on the mesh boundary; bits 3-5: corner k; bit 6: the
    // triangle borders a ridge (collide `MeshCollider::ridges`).
    boundary: u32,
    b: vec3<f32>,
    index: u32,
    c: vec3<f32>,
    pad: u32,
    n: vec4<f32>,
    e0: vec4<f32>,
    e1: vec4<f32>,
    e2: vec4<f32>,
    v0: vec4<f32>,
    v1: vec4<f32>,
    v2: vec4<f32>,
}

@group(0) @binding(18) var<storage, read> wall_nodes: array<WallNode>;
@group(0) @binding(19) var<storage, read> wall_tris: array<WallTri>;

// Depth of the traversal stack: the median split keeps the tree's depth at log2(triangles / leaf
// size) + 1 (15 for the 26 000-triangle vessel), and a depth-first walk holds at most one entry
// per level.
const WALL_STACK: u32 = 40u;

// A query's answer for one point.
struct WallHit {
    // Unit response direction (zero when no contact acts).
    dir: vec3<f32>,
    // Largest depth of a contact that acts (reach minus signed distance).
    depth: f32,
    // Triangles within reach.
    count: u32,
    // The centre is behind the nearest triangle's feature, not at an opening.
    escaped: bool,
    // A lower bound of the squared distance to every triangle: the nearest tested (its plane's
    // distance where that was beyond `look`), or the nearest box the walk did not enter.
    near2: f32,
    // The stack overflowed (a tree deeper than WALL_STACK): the answer is incomplete.
    overflow: bool,
}

fn box_distance2(p: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> f32 {
    let d = max(max(lo - p, p - hi), vec3<f32>(0.0));
    return dot(d, d);
}

// Closest point on triangle abc to p (Ericson 5.1.5) and its feature: 0 face, 1 + k edge k,
// 4 + k corner k.
struct Closest {
    c: vec3<f32>,
    feature: u32,
}

fn closest_on_triangle(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> Closest {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return Closest(a, 4u);
    }
    let bp = p - b;
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return Closest(b, 5u);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return Closest(a + ab * (d1 / (d1 - d3)), 1u);
    }
    let cp = p - c;
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return Closest(c, 6u);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return Closest(a + ac * (d2 / (d2 - d6)), 3u);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return Closest(b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))), 2u);
    }
    let denom = 1.0 / (va + vb + vc);
    return Closest(a + ab * (vb * denom) + ac * (vc * denom), 0u);
}

// The pseudo-normal of a feature of the triangle in `slot`, loaded alone: the kernels load only
// the members they use, so that a walk holds few registers.
fn feature_normal(slot: u32, feature: u32) -> vec3<f32> {
    switch feature {
        case 1u: { return wall_tris[slot].e0.xyz; }
        case 2u: { return wall_tris[slot].e1.xyz; }
        case 3u: { return wall_tris[slot].e2.xyz; }
        case 4u: { return wall_tris[slot].v0.xyz; }
        case 5u: { return wall_tris[slot].v1.xyz; }
        case 6u: { return wall_tris[slot].v2.xyz; }
        default: { return wall_tris[slot].n.xyz; }
    }
}

// Edge k is boundary bit k and corner k bit 3 + k: bit `feature - 1` either way.
fn feature_on_boundary(slot: u32, feature: u32) -> bool {
    return feature != 0u && (wall_tris[slot].boundary & (1u << (feature - 1u))) != 0u;
}

// What a point's sphere touches, summed triangle by triangle: over the contacts in front of
// their feature, and over all of them (used when the nearest says the centre has crossed the
// wall).
struct Touching {
    sum_front: vec3<f32>,
    w_front: f32,
    max_front: f32,
    sum_all: vec3<f32>,
    w_all: f32,
    max_all: f32,
    best2: f32,
    best_behind: bool,
    best_boundary: bool,
    count: u32,
}

fn touching_none() -> Touching {
    var acc: Touching;
    acc.best2 = 3.0e38;
    return acc;
}

// Adds the triangle in `slot` to what the sphere of radius `reach` at `p` touches; returns the
// squared distance to it, or its plane's where that already exceeds `beyond2` (a lower bound).
fn touch_triangle(acc: ptr<function, Touching>, p: vec3<f32>, reach: f32, slot: u32, beyond2: f32) -> f32 {
    let a = wall_tris[slot].a;
    let plane = dot(wall_tris[slot].n.xyz, p - a);
    if plane * plane > beyond2 {
        return plane * plane;
    }
    return touch_near_plane(acc, p, reach, slot, a);
}

// `touch_triangle` for a triangle (corner `a`) whose plane is within reach.
fn touch_near_plane(acc: ptr<function, Touching>, p: vec3<f32>, reach: f32, slot: u32, a: vec3<f32>) -> f32 {
    let cl = closest_on_triangle(p, a, wall_tris[slot].b, wall_tris[slot].c);
    let diff = p - cl.c;
    let d2 = dot(diff, diff);
    if d2 < reach * reach {
        let d = sqrt(d2);
        let n = feature_normal(slot, cl.feature);
        let behind = dot(diff, n) < 0.0;
        let depth = reach - select(d, -d, behind);
        (*acc).count += 1u;
        if d2 < (*acc).best2 {
            (*acc).best2 = d2;
            (*acc).best_behind = behind;
            (*acc).best_boundary = feature_on_boundary(slot, cl.feature);
        }
        (*acc).sum_all += n * depth;
        (*acc).w_all += depth;
        (*acc).max_all = max((*acc).max_all, depth);
        if !behind {
            (*acc).sum_front += n * depth;
            (*acc).w_front += depth;
            (*acc).max_front = max((*acc).max_front, depth);
        }
    }
    return d2;
}

// The point's response: the depth-weighted mean normal of the contacts that act.
fn touching_hit(acc: Touching) -> WallHit {
    var hit: WallHit;
    hit.count = acc.count;
    if acc.count == 0u {
        return hit;
    }
    hit.escaped = acc.best_behind && !acc.best_boundary;
    let s = select(acc.sum_front, acc.sum_all, hit.escaped);
    let w = select(acc.w_front, acc.w_all, hit.escaped);
    let len2 = dot(s, s);
    if w > 0.0 && len2 > 0.0 {
        hit.dir = s * inverseSqrt(len2);
        hit.depth = select(acc.max_front, acc.max_all, hit.escaped);
    }
    return hit;
}

// Near lists (the CPU's `near_slots`): a point keeps the triangles within `radius` of where it
// last walked the tree (its anchor, in `pt_meta`), in `pt_list` from word `list`: word 0 is
// LIST_VALID | count (or | LIST_OVER when more than NEAR_POINT were near: the point walks the tree
// at every step then), the slots follow. While the point is within `radius - reach` of its
// anchor, every triangle within its reach is in the list.
// Elements list up to NEAR_ELEMENT ridge triangles the same way (16: with 8, the lists of
// elements at the vessel's bifurcations overflowed and their elements walked the tree at every
// step, 66 against 57 µs per step to full depth on the H100).
const NEAR_POINT: u32 = 16u;
const NEAR_ELEMENT: u32 = 16u;
const LIST_VALID: u32 = 0x80000000u;
const LIST_OVER: u32 = 0x40000000u;
const LIST_COUNT: u32 = 0x0000ffffu;
// A walk's stack entry for the root alone (its other entries are the first child of a pair).
const WALK_ROOT: u32 = 0xffffffffu;

// The nodes a walk's stack entry stands for: the root alone, or the two children that start at
// `first` (adjacent in the tree, loaded together), the right one first.
struct NodePair {
    nodes: array<WallNode, 2>,
    count: u32,
}

fn node_pair(first: u32) -> NodePair {
    var pair: NodePair;
    if first == WALK_ROOT {
        pair.nodes[0] = wall_nodes[0];
        pair.count = 1u;
    } else {
        pair.nodes[0] = wall_nodes[first + 1u];
        pair.nodes[1] = wall_nodes[first];
        pair.count = 2u;
    }
    return pair;
}

// Per slot: the point's anchor and its clearance (the distance it may move from the anchor
// before any triangle can come within its reach).
@group(0) @binding(23) var<storage, read_write> pt_meta: array<vec4<f32>>;
// Per slot, 1 + NEAR_POINT words: the point's near list.
@group(0) @binding(24) var<storage, read_write> pt_list: array<u32>;
// Per slot, two vec4: the element's anchors (its two ends when its list was made).
@group(0) @binding(25) var<storage, read_write> el_meta: array<vec4<f32>>;
// Per slot, 1 + NEAR_ELEMENT words: the ridge triangles near the element, as `pt_list`.
@group(0) @binding(26) var<storage, read_write> el_list: array<u32>;

// The sphere of radius `reach` at `p` against the triangles of its near list, four at a time:
// their slots, corners and normals are loaded together before any is tested, so that a list
// costs a few memory latencies, not two per triangle.
fn wall_query_listed(p: vec3<f32>, reach: f32, list: u32, head: u32) -> WallHit {
    var acc = touching_none();
    let n = head & LIST_COUNT;
    let r2 = reach * reach;
    for (var k = 0u; k < n; k += 4u) {
        let last = n - 1u;
        let s0 = pt_list[list + 1u + k];
        let s1 = pt_list[list + 1u + min(k + 1u, last)];
        let s2 = pt_list[list + 1u + min(k + 2u, last)];
        let s3 = pt_list[list + 1u + min(k + 3u, last)];
        let a0 = wall_tris[s0].a;
        let a1 = wall_tris[s1].a;
        let a2 = wall_tris[s2].a;
        let a3 = wall_tris[s3].a;
        let h0 = dot(wall_tris[s0].n.xyz, p - a0);
        let h1 = dot(wall_tris[s1].n.xyz, p - a1);
        let h2 = dot(wall_tris[s2].n.xyz, p - a2);
        let h3 = dot(wall_tris[s3].n.xyz, p - a3);
        if h0 * h0 <= r2 {
            touch_near_plane(&acc, p, reach, s0, a0);
        }
        if k + 1u < n && h1 * h1 <= r2 {
            touch_near_plane(&acc, p, reach, s1, a1);
        }
        if k + 2u < n && h2 * h2 <= r2 {
            touch_near_plane(&acc, p, reach, s2, a2);
        }
        if k + 3u < n && h3 * h3 <= r2 {
            touch_near_plane(&acc, p, reach, s3, a3);
        }
    }
    return touching_hit(acc);
}

// The sphere of radius `reach` at `p` against the wall through the tree, walked out to `radius`
// (at least `reach`): writes the triangles within `radius` as the point's near list at `list`,
// and returns in `near2` a lower bound of the squared distance to every triangle (the nearest
// tested, its plane's distance where that was beyond `radius`, or the nearest box the walk did
// not enter), so that a point far from the wall (outside the mesh's box, say) gets that as its
// clearance.
fn wall_walk(p: vec3<f32>, reach: f32, radius: f32, list: u32) -> WallHit {
    var acc = touching_none();
    let r2 = radius * radius;
    var near2 = 3.0e38;
    var listed = 0u;
    var over = false;
    var deep = false;
    // Nodes are visited by pairs of children (adjacent in the tree, loaded together), so that a
    // walk is a chain of as many dependent loads as interior nodes it expands. The stack holds
    // the first child of each pair; WALK_ROOT stands for the root alone.
    var stack: array<u32, WALL_STACK>;
    stack[0] = WALK_ROOT;
    var sp = 1u;
    while sp > 0u {
        sp -= 1u;
        let pair = node_pair(stack[sp]);
        for (var c = 0u; c < pair.count; c++) {
            let nd = pair.nodes[c];
            let bd2 = box_distance2(p, nd.lo, nd.hi);
            if bd2 > r2 {
                near2 = min(near2, bd2);
            } else if nd.count > 0u {
                for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
                    let d2 = touch_triangle(&acc, p, reach, slot, r2);
                    near2 = min(near2, d2);
                    if d2 < r2 {
                        if listed < NEAR_POINT {
                            pt_list[list + 1u + listed] = slot;
                            listed += 1u;
                        } else {
                            over = true;
                        }
                    }
                }
            } else if sp < WALL_STACK {
                stack[sp] = nd.first;
                sp += 1u;
            } else {
                // Nodes are left out: no bound, and the list is incomplete.
                deep = true;
                over = true;
                near2 = 0.0;
            }
        }
    }
    if deep {
        near2 = 0.0;
    }
    pt_list[list] = LIST_VALID | select(listed, LIST_OVER, over);
    var hit = touching_hit(acc);
    hit.near2 = near2;
    hit.overflow = deep;
    return hit;
}

// Whether the segment o + s d, 0 <= s <= 1, passes through the box [lo, hi].
fn segment_box(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> bool {
    var enter = 0.0;
    var leave = 1.0;
    for (var k = 0u; k < 3u; k++) {
        if d[k] == 0.0 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return false;
            }
            continue;
        }
        let inv = 1.0 / d[k];
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

// The fraction along o + s d (0 <= s <= 1) at which the segment meets triangle abc, or -1.
fn segment_triangle(o: vec3<f32>, d: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> f32 {
    let slack = 1e-6;
    let e1 = b - a;
    let e2 = c - a;
    let p = cross(d, e2);
    let det = dot(e1, p);
    if abs(det) <= 1e-30 {
        return -1.0;
    }
    let inv = 1.0 / det;
    let s = o - a;
    let u = dot(s, p) * inv;
    if u < -slack || u > 1.0 + slack {
        return -1.0;
    }
    let q = cross(s, e1);
    let v = dot(d, q) * inv;
    if v < -slack || u + v > 1.0 + slack {
        return -1.0;
    }
    let f = dot(e2, q) * inv;
    return select(-1.0, f, f >= 0.0 && f <= 1.0);
}

struct Crossing {
    // Fraction of the motion at the crossing; -1 for none.
    f: f32,
    slot: u32,
}

// The first triangle the motion from `o` by `d` enters from the lumen side (against its face
// normal).
fn wall_first_crossing(o: vec3<f32>, d: vec3<f32>) -> Crossing {
    var best = 2.0;
    var best_slot = 0u;
    var stack: array<u32, WALL_STACK>;
    var sp = 1u;
    stack[0] = 0u;
    while sp > 0u {
        sp -= 1u;
        let nd = wall_nodes[stack[sp]];
        if !segment_box(o, d, nd.lo, nd.hi) {
            continue;
        }
        if nd.count > 0u {
            for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
                if dot(wall_tris[slot].n.xyz, d) >= 0.0 {
                    continue;
                }
                let f = segment_triangle(o, d, wall_tris[slot].a, wall_tris[slot].b, wall_tris[slot].c);
                if f >= 0.0 && f < best {
                    best = f;
                    best_slot = slot;
                }
            }
        } else if sp + 2u <= WALL_STACK {
            stack[sp] = nd.first;
            stack[sp + 1u] = nd.first + 1u;
            sp += 2u;
        }
    }
    return Crossing(select(-1.0, best, best <= 1.0), best_slot);
}

// Closest points of segments p1 + s d1 and p2 + t d2 (Ericson 5.1.9, as collide's
// `closest_points_segments`): (s, t).
fn segment_segment(p1: vec3<f32>, d1: vec3<f32>, p2: vec3<f32>, d2: vec3<f32>) -> vec2<f32> {
    let r = p1 - p2;
    let a = dot(d1, d1);
    let e = dot(d2, d2);
    let f = dot(d2, r);
    if a <= 1e-30 && e <= 1e-30 {
        return vec2<f32>(0.0);
    }
    if a <= 1e-30 {
        return vec2<f32>(0.0, clamp(f / e, 0.0, 1.0));
    }
    let c = dot(d1, r);
    if e <= 1e-30 {
        return vec2<f32>(clamp(-c / a, 0.0, 1.0), 0.0);
    }
    let b = dot(d1, d2);
    let denom = a * e - b * b;
    var s = select(0.0, clamp((b * f - c * e) / denom, 0.0, 1.0), denom > 0.0);
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

// Squared distance between the segment p + s d and triangle t, and the fraction s where it is
// reached (collide `segment_triangle_distance2`).
fn segment_triangle_distance2(p: vec3<f32>, d: vec3<f32>, ta: vec3<f32>, tb: vec3<f32>, tc: vec3<f32>) -> vec2<f32> {
    let through = segment_triangle(p, d, ta, tb, tc);
    if through >= 0.0 {
        return vec2<f32>(0.0, through);
    }
    let q = p + d;
    var best = vec2<f32>(3.0e38, 0.0);
    let c0 = closest_on_triangle(p, ta, tb, tc).c;
    let d0 = dot(p - c0, p - c0);
    if d0 < best.x {
        best = vec2<f32>(d0, 0.0);
    }
    let c1 = closest_on_triangle(q, ta, tb, tc).c;
    let d1 = dot(q - c1, q - c1);
    if d1 < best.x {
        best = vec2<f32>(d1, 1.0);
    }
    let corners = array<vec3<f32>, 3>(ta, tb, tc);
    for (var k = 0u; k < 3u; k++) {
        let u = corners[k];
        let v = corners[(k + 1u) % 3u];
        let st = segment_segment(p, d, u, v - u);
        let x = p + d * st.x - (u + (v - u) * st.y);
        let dx = dot(x, x);
        if dx < best.x {
            best = vec2<f32>(dx, st.x);
        }
    }
    return best;
}

// The nearest ridge triangle (bit 6) to the element from p to p + d within `limit`: as
// collide's `segment_nearest_among` over the element's near list of ridge triangles.
struct SegmentHit {
    found: bool,
    // Fraction along the element of its nearest point.
    fraction: f32,
    // The wall's nearest point.
    on_wall: vec3<f32>,
    signed_distance: f32,
    // Direction from the wall to the element (signed by the feature's pseudo-normal).
    normal: vec3<f32>,
}

// The nearest ridge triangle to an element so far: squared distance, fraction along the element,
// and slot + 1 (0: none).
struct SegBest {
    d2: f32,
    s: f32,
    slot1: u32,
}

// Considers ridge triangle `slot` for the element's nearest (collide `consider`).
fn segment_consider(p: vec3<f32>, d: vec3<f32>, limit: f32, slot: u32, best: ptr<function, SegBest>) {
    let a = wall_tris[slot].a;
    let n = wall_tris[slot].n.xyz;
    let h0 = dot(n, p - a);
    let h1 = dot(n, p + d - a);
    if (h0 > limit && h1 > limit) || (h0 < -limit && h1 < -limit) {
        return;
    }
    let ds = segment_triangle_distance2(p, d, a, wall_tris[slot].b, wall_tris[slot].c);
    if ds.x < (*best).d2 {
        *best = SegBest(ds.x, ds.y, slot + 1u);
    }
}

// The element's nearest wall point and direction from `best` (collide `answer`).
fn segment_answer(p: vec3<f32>, d: vec3<f32>, best: SegBest) -> SegmentHit {
    var hit: SegmentHit;
    if best.slot1 == 0u {
        return hit;
    }
    hit.found = true;
    let slot = best.slot1 - 1u;
    let at = p + d * best.s;
    let cl = closest_on_triangle(at, wall_tris[slot].a, wall_tris[slot].b, wall_tris[slot].c);
    let diff = at - cl.c;
    let distance = sqrt(best.d2);
    hit.fraction = best.s;
    hit.on_wall = cl.c;
    if distance > 0.0 {
        let side = select(-1.0, 1.0, dot(diff, feature_normal(slot, cl.feature)) >= 0.0);
        hit.signed_distance = side * distance;
        hit.normal = diff * (side / distance);
    } else {
        hit.normal = wall_tris[slot].n.xyz;
    }
    return hit;
}

// The nearest ridge triangle within `limit` of the element from p to p + d, among its near list
// at `list`.
fn wall_segment_listed(p: vec3<f32>, d: vec3<f32>, limit: f32, list: u32, head: u32) -> SegmentHit {
    var best = SegBest(limit * limit, 0.0, 0u);
    let n = head & LIST_COUNT;
    for (var k = 0u; k < n; k++) {
        segment_consider(p, d, limit, el_list[list + 1u + k], &best);
    }
    return segment_answer(p, d, best);
}

// The same through the tree: writes the ridge triangles within `radius` of the element as its
// near list at `list` (collide `segment_near_slots` with ridges only), and answers among them.
fn wall_segment_walk(p: vec3<f32>, d: vec3<f32>, limit: f32, radius: f32, list: u32) -> SegmentHit {
    var best = SegBest(limit * limit, 0.0, 0u);
    let centre = p + d * 0.5;
    let r = 0.5 * length(d) + radius;
    var listed = 0u;
    var over = false;
    // By pairs of children, as `wall_walk`.
    var stack: array<u32, WALL_STACK>;
    stack[0] = WALK_ROOT;
    var sp = 1u;
    while sp > 0u {
        sp -= 1u;
        let pair = node_pair(stack[sp]);
        for (var c = 0u; c < pair.count; c++) {
            let nd = pair.nodes[c];
            if box_distance2(centre, nd.lo, nd.hi) > r * r {
                continue;
            }
            if nd.count > 0u {
                for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
                    if (wall_tris[slot].boundary & 64u) == 0u {
                        continue;
                    }
                    let a = wall_tris[slot].a;
                    let n = wall_tris[slot].n.xyz;
                    let h0 = dot(n, p - a);
                    let h1 = dot(n, p + d - a);
                    if (h0 > radius && h1 > radius) || (h0 < -radius && h1 < -radius) {
                        continue;
                    }
                    let tb = wall_tris[slot].b;
                    let tc = wall_tris[slot].c;
                    if segment_triangle_distance2(p, d, a, tb, tc).x < radius * radius {
                        if listed < NEAR_ELEMENT {
                            el_list[list + 1u + listed] = slot;
                            listed += 1u;
                        } else {
                            over = true;
                        }
                        segment_consider(p, d, limit, slot, &best);
                    }
                }
            } else if sp < WALL_STACK {
                stack[sp] = nd.first;
                sp += 1u;
            } else {
                over = true;
            }
        }
    }
    el_list[list] = LIST_VALID | select(listed, LIST_OVER, over);
    return segment_answer(p, d, best);
}
