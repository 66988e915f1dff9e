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

fn feature_normal(t: WallTri, feature: u32) -> vec3<f32> {
    switch feature {
        case 1u: { return t.e0.xyz; }
        case 2u: { return t.e1.xyz; }
        case 3u: { return t.e2.xyz; }
        case 4u: { return t.v0.xyz; }
        case 5u: { return t.v1.xyz; }
        case 6u: { return t.v2.xyz; }
        default: { return t.n.xyz; }
    }
}

// Edge k is boundary bit k and corner k bit 3 + k: bit `feature - 1` either way.
fn feature_on_boundary(t: WallTri, feature: u32) -> bool {
    return feature != 0u && (t.boundary & (1u << (feature - 1u))) != 0u;
}

// The sphere of radius `reach` at `p` against the wall, the tree walked out to `look` (at least
// `reach`) so that `near2` bounds the distance to every triangle from below: a point with no
// contact is clear of the wall by at least sqrt(near2) - reach. Boxes the walk leaves out bound
// the triangles in them, so a point far from the wall (outside the mesh's box, say) gets a
// clearance of that distance, not just of `look`.
fn wall_query(p: vec3<f32>, reach: f32, look: f32) -> WallHit {
    var hit: WallHit;
    hit.near2 = 3.0e38;
    let r2 = reach * reach;
    let look2 = look * look;
    // Sums over the contacts in front of their feature, and over all of them (used when the
    // nearest says the centre has crossed the wall).
    var sum_front = vec3<f32>(0.0);
    var w_front = 0.0;
    var max_front = 0.0;
    var sum_all = vec3<f32>(0.0);
    var w_all = 0.0;
    var max_all = 0.0;
    var best2 = 3.0e38;
    var best_behind = false;
    var best_boundary = false;
    var stack: array<u32, WALL_STACK>;
    var sp = 0u;
    var node = 0u;
    loop {
        let nd = wall_nodes[node];
        let bd2 = box_distance2(p, nd.lo, nd.hi);
        if bd2 > look2 {
            hit.near2 = min(hit.near2, bd2);
        } else {
            if nd.count > 0u {
                for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
                    let t = wall_tris[slot];
                    let plane = dot(t.n.xyz, p - t.a);
                    if plane * plane > look2 {
                        hit.near2 = min(hit.near2, plane * plane);
                        continue;
                    }
                    let cl = closest_on_triangle(p, t.a, t.b, t.c);
                    let diff = p - cl.c;
                    let d2 = dot(diff, diff);
                    hit.near2 = min(hit.near2, d2);
                    if d2 < r2 {
                        let d = sqrt(d2);
                        let n = feature_normal(t, cl.feature);
                        let behind = dot(diff, n) < 0.0;
                        let depth = reach - select(d, -d, behind);
                        hit.count += 1u;
                        if d2 < best2 {
                            best2 = d2;
                            best_behind = behind;
                            best_boundary = feature_on_boundary(t, cl.feature);
                        }
                        sum_all += n * depth;
                        w_all += depth;
                        max_all = max(max_all, depth);
                        if !behind {
                            sum_front += n * depth;
                            w_front += depth;
                            max_front = max(max_front, depth);
                        }
                    }
                }
            } else {
                // Descend into the left child now, keep the right one for later.
                if sp < WALL_STACK {
                    stack[sp] = nd.first + 1u;
                    sp += 1u;
                } else {
                    hit.overflow = true;
                }
                node = nd.first;
                continue;
            }
        }
        if sp == 0u {
            break;
        }
        sp -= 1u;
        node = stack[sp];
    }
    if hit.overflow {
        // Nodes were left out: no bound.
        hit.near2 = 0.0;
    }
    if hit.count == 0u {
        return hit;
    }
    hit.escaped = best_behind && !best_boundary;
    let s = select(sum_front, sum_all, hit.escaped);
    let w = select(w_front, w_all, hit.escaped);
    let len2 = dot(s, s);
    if w > 0.0 && len2 > 0.0 {
        hit.dir = s * inverseSqrt(len2);
        hit.depth = select(max_front, max_all, hit.escaped);
    }
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
                let t = wall_tris[slot];
                if dot(t.n.xyz, d) >= 0.0 {
                    continue;
                }
                let f = segment_triangle(o, d, t.a, t.b, t.c);
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
fn segment_triangle_distance2(p: vec3<f32>, d: vec3<f32>, t: WallTri) -> vec2<f32> {
    let through = segment_triangle(p, d, t.a, t.b, t.c);
    if through >= 0.0 {
        return vec2<f32>(0.0, through);
    }
    let q = p + d;
    var best = vec2<f32>(3.0e38, 0.0);
    let c0 = closest_on_triangle(p, t.a, t.b, t.c).c;
    let d0 = dot(p - c0, p - c0);
    if d0 < best.x {
        best = vec2<f32>(d0, 0.0);
    }
    let c1 = closest_on_triangle(q, t.a, t.b, t.c).c;
    let d1 = dot(q - c1, q - c1);
    if d1 < best.x {
        best = vec2<f32>(d1, 1.0);
    }
    let corners = array<vec3<f32>, 3>(t.a, t.b, t.c);
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

fn wall_segment_nearest(p: vec3<f32>, d: vec3<f32>, limit: f32) -> SegmentHit {
    var hit: SegmentHit;
    let centre = p + d * 0.5;
    let r = 0.5 * length(d) + limit;
    let r2 = r * r;
    var best2 = limit * limit;
    var best_s = 0.0;
    var best_slot = 0u;
    var stack: array<u32, WALL_STACK>;
    var sp = 0u;
    var node = 0u;
    loop {
        let nd = wall_nodes[node];
        if box_distance2(centre, nd.lo, nd.hi) <= r2 {
            if nd.count > 0u {
                for (var slot = nd.first; slot < nd.first + nd.count; slot++) {
                    let t = wall_tris[slot];
                    if (t.boundary & 64u) == 0u {
                        continue;
                    }
                    let h0 = dot(t.n.xyz, p - t.a);
                    let h1 = dot(t.n.xyz, p + d - t.a);
                    if (h0 > limit && h1 > limit) || (h0 < -limit && h1 < -limit) {
                        continue;
                    }
                    let ds = segment_triangle_distance2(p, d, t);
                    if ds.x < best2 {
                        best2 = ds.x;
                        best_s = ds.y;
                        best_slot = slot;
                        hit.found = true;
                    }
                }
            } else {
                if sp < WALL_STACK {
                    stack[sp] = nd.first + 1u;
                    sp += 1u;
                }
                node = nd.first;
                continue;
            }
        }
        if sp == 0u {
            break;
        }
        sp -= 1u;
        node = stack[sp];
    }
    if !hit.found {
        return hit;
    }
    let t = wall_tris[best_slot];
    let at = p + d * best_s;
    let cl = closest_on_triangle(at, t.a, t.b, t.c);
    let diff = at - cl.c;
    let distance = sqrt(best2);
    hit.fraction = best_s;
    hit.on_wall = cl.c;
    if distance > 0.0 {
        let side = select(-1.0, 1.0, dot(diff, feature_normal(t, cl.feature)) >= 0.0);
        hit.signed_distance = side * distance;
        hit.normal = diff * (side / distance);
    } else {
        hit.normal = t.n.xyz;
    }
    return hit;
}
