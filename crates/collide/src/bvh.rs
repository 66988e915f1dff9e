//! A flat AABB hierarchy over the triangles of a mesh, built by object (volume) partitioning.
//!
//! Why object partitioning: vessel meshes are hollow, thin-walled tubes. Spatial subdivisions
//! (octrees, BSP) spend most of their cells on empty lumen and are unbalanced; splitting the
//! *triangle set* instead (as the reference paper does) gives a balanced tree whose depth is
//! `⌈log2(n / leaf_size)⌉ + 1` whatever the shape, so the traversal cost per query is predictable
//! and the traversal stack can be a small fixed array (GPU shared memory in the paper).
//!
//! Split rule: the triangles of a node are split at the **median of their centroids along the
//! longest axis of the centroid bounds**. We chose the median over SAH binning because the median
//! guarantees the balanced depth above (a fixed traversal stack is then provably enough), is
//! deterministic and simple, and for the near-uniform triangulations of vessel walls SAH has little
//! to gain (the triangles are all about the same size).
//!
//! Layout: nodes live in one array of [`BvhNode`], a `#[repr(C)]` 32-byte struct of `f32` bounds
//! and `u32` links, with the two children of an interior node stored next to each other; a second
//! `u32` array lists triangle indices in leaf order. Both are exactly what a GPU kernel wants, and
//! the CPU traversal runs on these same arrays, so CPU and GPU see one tree. The `f32` bounds are
//! rounded *outward* from the exact `f64` bounds, so the tree is conservative: it may visit a node
//! it did not need to, never skip one it needed.

use nalgebra::Vector3;

use crate::mesh::TriMesh;

/// Traversal stack size. The median split keeps the depth at `⌈log2(n)⌉ + 1 ≤ 33` for any mesh
/// with `u32` indices, so a depth-first traversal never needs more entries than this.
pub const STACK_SIZE: usize = 64;

/// Default maximum number of triangles per leaf.
pub const DEFAULT_LEAF_SIZE: usize = 4;

/// One node of the flat tree, laid out for direct upload to a GPU buffer (32 bytes, `f32`/`u32`).
///
/// * Interior node: `count == 0`; the children are `first` and `first + 1`.
/// * Leaf: `count > 0`; its triangles are `tri_indices[first .. first + count]`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhNode {
    /// Lower corner of the box (rounded down from the exact bounds).
    pub min: [f32; 3],
    /// Left child (interior) or first slot in the triangle-index array (leaf).
    pub first: u32,
    /// Upper corner of the box (rounded up from the exact bounds).
    pub max: [f32; 3],
    /// Number of triangles for a leaf, 0 for an interior node.
    pub count: u32,
}

impl BvhNode {
    /// `true` for a leaf.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }

    /// Squared distance from `p` to the box (0 inside), computed in `f64`.
    #[inline(always)]
    pub fn distance_squared(&self, p: &[f64; 3]) -> f64 {
        let mut d2 = 0.0;
        for k in 0..3 {
            let lo = f64::from(self.min[k]);
            let hi = f64::from(self.max[k]);
            let d = (lo - p[k]).max(p[k] - hi).max(0.0);
            d2 += d * d;
        }
        d2
    }
}

/// The AABB tree: flat node array plus the leaf-ordered triangle-index array.
#[derive(Clone, Debug)]
pub struct Bvh {
    nodes: Vec<BvhNode>,
    tri_indices: Vec<u32>,
    leaf_size: usize,
    depth: usize,
}

/// A violated tree invariant found by [`Bvh::check_invariants`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("BVH invariant violated: {0}")]
pub struct InvariantViolation(pub String);

/// Whether the segment `from + s d`, `0 ≤ s ≤ 1`, passes through `node`'s box grown by `r` on
/// every side (Kay and Kajiya's slabs).
#[inline(always)]
fn segment_meets_box(from: &[f64; 3], d: &[f64; 3], node: &BvhNode, r: f64) -> bool {
    let (mut enter, mut leave) = (0.0_f64, 1.0_f64);
    for k in 0..3 {
        let (lo, hi) = (f64::from(node.min[k]) - r, f64::from(node.max[k]) + r);
        if d[k] == 0.0 {
            if from[k] < lo || from[k] > hi {
                return false;
            }
            continue;
        }
        let inv = 1.0 / d[k];
        let (t0, t1) = ((lo - from[k]) * inv, (hi - from[k]) * inv);
        enter = enter.max(t0.min(t1));
        leave = leave.min(t0.max(t1));
        if enter > leave {
            return false;
        }
    }
    true
}

fn round_down(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) > x { f.next_down() } else { f }
}

fn round_up(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x { f.next_up() } else { f }
}

impl Bvh {
    /// Builds the tree with [`DEFAULT_LEAF_SIZE`] triangles per leaf at most.
    pub fn build(mesh: &TriMesh) -> Self {
        Self::build_with_leaf_size(mesh, DEFAULT_LEAF_SIZE)
    }

    /// Builds the tree with at most `leaf_size` triangles per leaf (clamped to `1..=255`).
    pub fn build_with_leaf_size(mesh: &TriMesh, leaf_size: usize) -> Self {
        let leaf_size = leaf_size.clamp(1, 255);
        let n = mesh.triangles().len();
        let mut lo = Vec::with_capacity(n);
        let mut hi = Vec::with_capacity(n);
        let mut centroid = Vec::with_capacity(n);
        for t in 0..n {
            let [a, b, c] = mesh.triangle(t);
            lo.push(a.inf(&b).inf(&c));
            hi.push(a.sup(&b).sup(&c));
            centroid.push((a + b + c) / 3.0);
        }
        let mut tri_indices: Vec<u32> = (0..n as u32).collect();
        let mut nodes = Vec::with_capacity(2 * n.div_ceil(leaf_size).max(1));
        nodes.push(BvhNode::default());
        let mut depth = 0;
        // Explicit work list: (node, first, count, level).
        let mut work = vec![(0usize, 0usize, n, 1usize)];
        while let Some((node, first, count, level)) = work.pop() {
            depth = depth.max(level);
            let slice = &mut tri_indices[first..first + count];
            let mut bmin = Vector3::repeat(f64::INFINITY);
            let mut bmax = Vector3::repeat(f64::NEG_INFINITY);
            let mut cmin = Vector3::repeat(f64::INFINITY);
            let mut cmax = Vector3::repeat(f64::NEG_INFINITY);
            for &t in slice.iter() {
                let t = t as usize;
                bmin = bmin.inf(&lo[t]);
                bmax = bmax.sup(&hi[t]);
                cmin = cmin.inf(&centroid[t]);
                cmax = cmax.sup(&centroid[t]);
            }
            let nd = &mut nodes[node];
            nd.min = [round_down(bmin.x), round_down(bmin.y), round_down(bmin.z)];
            nd.max = [round_up(bmax.x), round_up(bmax.y), round_up(bmax.z)];
            if count <= leaf_size {
                nd.first = first as u32;
                nd.count = count as u32;
                continue;
            }
            let ext = cmax - cmin;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = count / 2;
            slice.select_nth_unstable_by(mid, |&a, &b| {
                centroid[a as usize][axis].total_cmp(&centroid[b as usize][axis])
            });
            let left = nodes.len();
            nodes[node].first = left as u32;
            nodes[node].count = 0;
            nodes.push(BvhNode::default());
            nodes.push(BvhNode::default());
            work.push((left + 1, first + mid, count - mid, level + 1));
            work.push((left, first, mid, level + 1));
        }
        Self {
            nodes,
            tri_indices,
            leaf_size,
            depth,
        }
    }

    /// The flat node array (root at index 0), ready for GPU upload as is.
    pub fn nodes(&self) -> &[BvhNode] {
        &self.nodes
    }

    /// Triangle indices (into the mesh) in leaf order; leaves refer to ranges of this array.
    pub fn tri_indices(&self) -> &[u32] {
        &self.tri_indices
    }

    /// Maximum triangles per leaf used at build time.
    pub fn leaf_size(&self) -> usize {
        self.leaf_size
    }

    /// Number of levels (a single leaf root has depth 1).
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// Number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.nodes.iter().filter(|n| n.is_leaf()).count()
    }

    /// The node array as raw 32-bit words (`f32` bounds bit-cast to `u32`), 8 words per node, for
    /// APIs that take a `&[u32]` buffer.
    pub fn node_words(&self) -> Vec<u32> {
        let mut w = Vec::with_capacity(self.nodes.len() * 8);
        for n in &self.nodes {
            w.extend(n.min.iter().map(|x| x.to_bits()));
            w.push(n.first);
            w.extend(n.max.iter().map(|x| x.to_bits()));
            w.push(n.count);
        }
        w
    }

    /// Calls `visit(slot)` for every leaf-order slot (an index into [`tri_indices`](Self::tri_indices))
    /// whose leaf box is within distance `r` of `p`. Iterative, fixed stack, no allocation.
    #[inline]
    pub fn for_each_near(&self, p: &[f64; 3], r: f64, visit: impl FnMut(usize)) {
        let r2 = r * r;
        self.for_each_in(|n| n.distance_squared(p) <= r2, visit);
    }

    /// Calls `visit(slot)`, in leaf order as [`Self::for_each_near`] does, for every slot
    /// whose leaf box may be within distance `r` of the segment `from → to`: the segment passes
    /// through the box grown by `r` on every side. A long segment's leaves lie along it, where
    /// the sphere around its middle that holds it takes in every leaf as far to its sides.
    #[inline]
    pub fn for_each_near_segment(
        &self,
        from: &[f64; 3],
        to: &[f64; 3],
        r: f64,
        visit: impl FnMut(usize),
    ) {
        // Rounding of the slab fractions must not drop a leaf at the edge.
        let r = r * (1.0 + 1e-9);
        let d = [to[0] - from[0], to[1] - from[1], to[2] - from[2]];
        self.for_each_in(|n| segment_meets_box(from, &d, n, r), visit);
    }

    /// Calls `visit(slot)` for every slot of the leaves whose box, and every ancestor's, is
    /// `near`, in leaf order. Iterative, fixed stack, no allocation.
    #[inline(always)]
    fn for_each_in(&self, near: impl Fn(&BvhNode) -> bool, mut visit: impl FnMut(usize)) {
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0usize;
        let mut node = 0u32;
        loop {
            let n = &self.nodes[node as usize];
            if near(n) {
                if n.is_leaf() {
                    let first = n.first as usize;
                    for slot in first..first + n.count as usize {
                        visit(slot);
                    }
                } else {
                    // Descend into the left child now, keep the right one for later.
                    stack[sp] = n.first + 1;
                    sp += 1;
                    node = n.first;
                    continue;
                }
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            node = stack[sp];
        }
    }

    /// Checks the structural invariants: every node's box contains its children's boxes and its
    /// triangles; every triangle appears in exactly one leaf; leaves respect the leaf size; child
    /// links are in range; the depth fits the traversal stack.
    pub fn check_invariants(&self, mesh: &TriMesh) -> Result<(), InvariantViolation> {
        let fail = |s: String| Err(InvariantViolation(s));
        let n = mesh.triangles().len();
        if self.tri_indices.len() != n {
            return fail(format!(
                "{} triangle slots for {} triangles",
                self.tri_indices.len(),
                n
            ));
        }
        let mut seen = vec![0u32; n];
        let contains = |outer: &BvhNode, lo: [f64; 3], hi: [f64; 3]| {
            (0..3).all(|k| f64::from(outer.min[k]) <= lo[k] && hi[k] <= f64::from(outer.max[k]))
        };
        let mut stack = vec![(0usize, 1usize)];
        let mut max_depth = 0;
        let mut visited = 0usize;
        while let Some((i, level)) = stack.pop() {
            visited += 1;
            if visited > self.nodes.len() {
                return fail("node graph has a cycle or shared children".into());
            }
            max_depth = max_depth.max(level);
            let nd = &self.nodes[i];
            if (0..3).any(|k| nd.min[k].partial_cmp(&nd.max[k]).is_none_or(|o| o.is_gt())) {
                return fail(format!("node {i} has an empty or NaN box"));
            }
            if nd.is_leaf() {
                let (f, c) = (nd.first as usize, nd.count as usize);
                if c > self.leaf_size || f + c > n {
                    return fail(format!("leaf {i} range {f}+{c} invalid"));
                }
                for &t in &self.tri_indices[f..f + c] {
                    let t = t as usize;
                    if t >= n {
                        return fail(format!("leaf {i} refers to triangle {t} >= {n}"));
                    }
                    seen[t] += 1;
                    let [a, b, cc] = mesh.triangle(t);
                    let lo = a.inf(&b).inf(&cc);
                    let hi = a.sup(&b).sup(&cc);
                    if !contains(nd, lo.into(), hi.into()) {
                        return fail(format!("leaf {i} box does not contain triangle {t}"));
                    }
                }
            } else {
                let l = nd.first as usize;
                if l + 1 >= self.nodes.len() || l <= i {
                    return fail(format!("node {i} has invalid children {l}"));
                }
                for ch in [l, l + 1] {
                    let c = &self.nodes[ch];
                    let lo = c.min.map(f64::from);
                    let hi = c.max.map(f64::from);
                    if !contains(nd, lo, hi) {
                        return fail(format!("node {i} box does not contain child {ch}"));
                    }
                    stack.push((ch, level + 1));
                }
            }
        }
        if visited != self.nodes.len() {
            return fail(format!(
                "{} nodes reachable of {}",
                visited,
                self.nodes.len()
            ));
        }
        if let Some(t) = seen.iter().position(|&c| c != 1) {
            return fail(format!("triangle {t} appears {} times", seen[t]));
        }
        if max_depth != self.depth {
            return fail(format!(
                "recorded depth {} but actual {}",
                self.depth, max_depth
            ));
        }
        if max_depth > STACK_SIZE {
            return fail(format!(
                "depth {max_depth} exceeds the traversal stack of {STACK_SIZE}"
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> TriMesh {
        let mut v = Vec::new();
        let mut t = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                v.push([
                    i as f64 * 0.1,
                    j as f64 * 0.1,
                    ((i * j) as f64 * 0.01).sin(),
                ]);
            }
        }
        let id = |i: usize, j: usize| (i * (n + 1) + j) as u32;
        for i in 0..n {
            for j in 0..n {
                t.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                t.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        TriMesh::new(v, t, "grid").expect("valid grid").0
    }

    #[test]
    fn node_layout_is_gpu_ready() {
        assert_eq!(std::mem::size_of::<BvhNode>(), 32);
        assert_eq!(std::mem::align_of::<BvhNode>(), 4);
        let m = grid(3);
        let b = Bvh::build(&m);
        let w = b.node_words();
        assert_eq!(w.len(), 8 * b.nodes().len());
        assert_eq!(f32::from_bits(w[0]), b.nodes()[0].min[0]);
        assert_eq!(w[7], b.nodes()[0].count);
    }

    #[test]
    fn balanced_depth_and_invariants_for_all_leaf_sizes() {
        let m = grid(40); // 3200 triangles
        for leaf in [1, 2, 4, 8] {
            let b = Bvh::build_with_leaf_size(&m, leaf);
            b.check_invariants(&m).unwrap();
            let bound = (3200f64 / leaf as f64).log2().ceil() as usize + 2;
            assert!(
                b.depth() <= bound,
                "leaf {leaf}: depth {} > {bound}",
                b.depth()
            );
            assert!(b.leaf_count() >= 3200 / leaf);
        }
        // A single triangle: the root is a leaf.
        let one = TriMesh::new(
            vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
            "one",
        )
        .unwrap()
        .0;
        let b = Bvh::build(&one);
        b.check_invariants(&one).unwrap();
        assert_eq!((b.depth(), b.nodes().len()), (1, 1));
    }

    #[test]
    fn invariant_checker_catches_corruption() {
        let m = grid(6);
        let good = Bvh::build(&m);
        let mut b = good.clone();
        b.nodes[1].max[0] = b.nodes[0].max[0] + 1.0;
        assert!(b.check_invariants(&m).is_err());
        let mut b = good.clone();
        let last = b.tri_indices.len() - 1;
        b.tri_indices[last] = b.tri_indices[0];
        assert!(b.check_invariants(&m).is_err());
        let mut b = good.clone();
        let leaf = b.nodes.iter().position(|n| n.is_leaf()).unwrap();
        b.nodes[leaf].min[2] = b.nodes[leaf].max[2] + 1.0;
        assert!(b.check_invariants(&m).is_err());
        let mut b = good.clone();
        b.depth = 99;
        assert!(b.check_invariants(&m).is_err());
    }

    #[test]
    fn outward_rounding_is_conservative() {
        for x in [0.1f64, -0.1, 1.0 / 3.0, -2.0 / 3.0, 1e-30, 0.0] {
            assert!(f64::from(round_down(x)) <= x);
            assert!(f64::from(round_up(x)) >= x);
        }
    }

    #[test]
    fn segment_query_visits_every_triangle_near_the_segment_in_leaf_order() {
        let m = grid(20);
        let b = Bvh::build_with_leaf_size(&m, 2);
        for (k, (from, to)) in [
            ([0.1, 0.2, 0.3], [1.7, 0.4, 0.1]),
            ([0.5, 0.5, 0.1], [0.5, 0.5, 0.1]),
            ([-1.0, 0.0, 0.05], [0.3, 1.1, -0.05]),
            ([1.9, 0.1, -0.2], [0.2, 1.9, 0.2]),
        ]
        .into_iter()
        .enumerate()
        {
            let r = 0.05 + 0.1 * k as f64;
            let mut got = Vec::new();
            b.for_each_near_segment(&from, &to, r, |s| got.push(s));
            assert!(got.windows(2).all(|w| w[0] < w[1]), "not in leaf order");
            let (p, q) = (Vector3::from(from), Vector3::from(to));
            let mut near = 0;
            for (slot, &t) in b.tri_indices().iter().enumerate() {
                let [a, bb, c] = m.triangle(t as usize);
                let (d2, _) = crate::segment::segment_triangle_distance2(&p, &(q - p), &a, &bb, &c);
                if d2 < r * r {
                    near += 1;
                    assert!(got.contains(&slot), "{k}: slot {slot} missed");
                }
            }
            assert!(near > 0 && got.len() < b.tri_indices().len(), "{k}");
        }
    }

    #[test]
    fn sphere_query_visits_exactly_the_brute_force_leaves() {
        let m = grid(20);
        let b = Bvh::build_with_leaf_size(&m, 2);
        for (k, p) in [
            [0.5, 0.5, 0.3],
            [1.0, 2.0, 0.0],
            [-1.0, 0.0, 0.0],
            [1.9, 0.1, -0.2],
        ]
        .iter()
        .enumerate()
        {
            let r = 0.05 + 0.1 * k as f64;
            let mut got = Vec::new();
            b.for_each_near(p, r, |s| got.push(s));
            got.sort_unstable();
            let mut want: Vec<usize> = Vec::new();
            for n in b.nodes().iter().filter(|n| n.is_leaf()) {
                // A leaf is visited iff it and all its ancestors are within r; ancestors contain
                // it, so iff the leaf itself is.
                if n.distance_squared(p) <= r * r {
                    want.extend(n.first as usize..(n.first + n.count) as usize);
                }
            }
            want.sort_unstable();
            assert_eq!(got, want);
        }
    }
}
