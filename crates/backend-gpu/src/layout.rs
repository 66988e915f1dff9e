//! The structs the host uploads and the kernel reads, byte for byte.
//!
//! Each is `#[repr(C)]` and [`Pod`], so that a slice of them is the buffer's contents, and each
//! has a WGSL twin in `shaders/rod_step.wgsl`. Rust and WGSL must agree on every member's name,
//! offset and scalar type and on the struct's size; nothing but a test can see when they do not,
//! because the GPU reads whatever bytes it is given. So the structs are declared through
//! [`gpu_struct!`], which also records each field's name, offset, size and scalar type as the
//! compiler laid it out ([`GpuLayout`]), and a test (below) parses the composed kernel with naga
//! and compares every recorded layout with the WGSL struct of the same name: a field renamed,
//! retyped, added or moved on either side fails it. Nothing here is mirrored by hand.

use bytemuck::{Pod, Zeroable};

/// `left` / `right` of an [`ItemG`] without a neighbour (the kernel's `0xffffffff`).
pub(crate) const NONE: u32 = u32::MAX;
/// Dispatches one submission can address in the chunk table (one [`ChunkG`] per dispatch).
pub(crate) const TABLE_CAPACITY: u32 = 1024;

/// The layout of one shared struct as the Rust compiler made it.
#[cfg(test)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct GpuLayout {
    /// The name of its WGSL twin.
    pub(crate) wgsl: &'static str,
    /// `size_of` of the Rust struct.
    pub(crate) size: usize,
    /// Its fields in declaration order.
    pub(crate) fields: &'static [FieldLayout],
}

/// One field of a [`GpuLayout`].
#[cfg(test)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct FieldLayout {
    pub(crate) name: &'static str,
    pub(crate) offset: usize,
    pub(crate) size: usize,
    /// `"f32"` or `"u32"`: the scalar of the field or of its array elements.
    pub(crate) scalar: &'static str,
}

/// The scalar a field is made of, to compare with the WGSL member's.
#[cfg(test)]
pub(crate) trait Scalar {
    /// `"f32"` or `"u32"`.
    const NAME: &'static str;
}

#[cfg(test)]
impl Scalar for f32 {
    const NAME: &'static str = "f32";
}

#[cfg(test)]
impl Scalar for u32 {
    const NAME: &'static str = "u32";
}

#[cfg(test)]
impl<T: Scalar, const N: usize> Scalar for [T; N] {
    const NAME: &'static str = T::NAME;
}

/// Declares a `#[repr(C)]` [`Pod`] struct shared with the kernel and records its layout in an
/// associated `LAYOUT` constant (test builds only), from the struct itself (`offset_of!`, `size_of`), so the list
/// the layout test checks cannot drift from the struct.
macro_rules! gpu_struct {
    (
        $(#[$meta:meta])*
        struct $name:ident as $wgsl:literal {
            $($(#[$fmeta:meta])* $field:ident: $ty:ty,)*
        }
    ) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
        pub(crate) struct $name {
            $($(#[$fmeta])* pub(crate) $field: $ty,)*
        }

        #[cfg(test)]
        impl $name {
            /// This struct's layout, for the layout test.
            pub(crate) const LAYOUT: GpuLayout = GpuLayout {
                wgsl: $wgsl,
                size: std::mem::size_of::<$name>(),
                fields: &[$(FieldLayout {
                    name: stringify!($field),
                    offset: std::mem::offset_of!($name, $field),
                    size: std::mem::size_of::<$ty>(),
                    scalar: <$ty as Scalar>::NAME,
                },)*],
            };
        }
    };
}

gpu_struct! {
    /// The per-submission parameter block (`params`, binding 0): the only data a batch writes
    /// besides changed end motions.
    struct ParamsU as "Params" {
        /// xyz gravity, w the time step h.
        gravity: [f32; 4],
        /// Allowed band of squared length ratios `(l/l0)²`.
        lo2: f32,
        hi2: f32,
        /// Index of the submission's first step.
        base_step: u32,
        /// Work items per dispatch.
        num_items: u32,
        /// Multi-workgroup path: halo exchanges since the synchronisation words were cleared.
        epoch0: u32,
        /// Weights of the reaction filter's last output, last raw value and new raw value
        /// (`backend-cpu` `reaction.rs`).
        rf_keep: f32,
        rf_old: f32,
        rf_new: f32,
    }
}

gpu_struct! {
    /// One dispatch's entry of the chunk table (`chunk`, binding 1, at a dynamic offset).
    struct ChunkG as "Chunk" {
        /// First step of the dispatch relative to `ParamsU::base_step`.
        offset: u32,
        /// Steps of the dispatch.
        count: u32,
        /// Multi-workgroup path: halo exchanges of the submission's earlier dispatches.
        sync_base: u32,
        pad1: u32,
    }
}

gpu_struct! {
    /// Per-point, per-element and per-node parameters (`slots`, binding 2); slot `i` of a rod
    /// holds its point `i`, element `i` and node `i`.
    struct SlotG as "Slot" {
        /// l0 (element), inverse mass (point), mass (point), Kp (element).
        a: [f32; 4],
        /// Inertia (element), Ks (element).
        b: [f32; 4],
        /// Inverse inertia (element), stretch damping (element).
        c: [f32; 4],
        /// Rest Darboux vector (node), node length (node).
        d: [f32; 4],
        /// Bend/twist stiffness (node), bend damping (node).
        e: [f32; 4],
    }
}

gpu_struct! {
    /// One work item (`items`, binding 3): the window of a rod one workgroup (or subgroup)
    /// steps and the part of it the item owns.
    struct ItemG as "Item" {
        rod: u32,
        /// Slot of the rod's point 0.
        base: u32,
        /// Elements of the rod.
        n: u32,
        /// Bit 0: end 0 holds its point, bit 1 it is clamped (its clamp acts through a
        /// [`ClampG`]); bits 2 and 3 the same for end 1.
        flags: u32,
        /// Window `[w0, w1)` and owned range `[o0, o1)` of point indices.
        w0: u32,
        w1: u32,
        o0: u32,
        o1: u32,
        /// Neighbouring items of the same rod (multi-workgroup paths), or [`NONE`].
        left: u32,
        right: u32,
        drag: f32,
        /// Bindings: the item's first thread in its workgroup (0 otherwise).
        lane0: u32,
    }
}

gpu_struct! {
    /// An item's part in a binding (`couplings`, binding 28, kernels with `BIND`): the outer
    /// rod's item (inner rods; [`NONE`] otherwise), its role (bit 0 inner, bit 1 outer, bit 2
    /// two-way), the capture distance and the offset removed per step, and its first entries in
    /// the workgroup's outer and inner exchange arrays.
    struct CouplingG as "Coupling" {
        outer: u32,
        role: u32,
        capture: f32,
        correction: f32,
        xo: u32,
        xi: u32,
        pad0: u32,
        pad1: u32,
    }
}

gpu_struct! {
    /// A rod's part in rod contact (`strands`, binding 29; kernels with `RODC`): its first entry
    /// in its workgroup's point arrays (`xp`) and sphere array (`xs`), its number of
    /// bounding spheres, the self-contact skip (segment pairs `|i − j| <= skip` of the rod are
    /// not tested; `NONE` when it does not touch itself), its radius, half the margin and the
    /// friction coefficients.
    struct StrandG as "Strand" {
        xp: u32,
        xs: u32,
        spheres: u32,
        skip: u32,
        radius: f32,
        half_margin: f32,
        mu_s: f32,
        mu_k: f32,
    }
}

gpu_struct! {
    /// A held end's prescribed motion (`drives`, binding 4): velocity `v` and angular velocity
    /// `w` (world frame) during steps `[window[0], window[1])`.
    struct DriveG as "Drive" {
        v: [f32; 4],
        w: [f32; 4],
        /// Steps `[window[0], window[1])` of the motion; `window[2]`: the step `origin` is before.
        window: [u32; 4],
        /// Position of the held point before step `window[2]` (see `sim::EndTrack`).
        origin: [f32; 4],
    }
}

gpu_struct! {
    /// The clamp of one end (`clamps`, binding 17, bound only to kernels built with `CLAMP`),
    /// two per rod: index `2 · rod + end`. Every rod has both, clamped or not, so that the
    /// clamp frames are read back and saved the same way for every rod; the kernel reads the
    /// node and turns `q` only at clamped ends (item flag bits 1 and 3), keeping `q` in a
    /// register for the dispatch and writing it back at its end. `d` and `e` have the layout of
    /// a [`SlotG`]'s node.
    struct ClampG as "Clamp" {
        /// The clamp frame as `[x, y, z, w]` (`RodState::clamp_frames`): state.
        q: [f32; 4],
        /// Rest Darboux vector and length of the clamp's node (`EndNode::rest_darboux`,
        /// `RodParams::end_node_length`).
        d: [f32; 4],
        /// Bend/twist stiffness and damping of the clamp's node (`EndNode::stiffness`,
        /// `EndNode::damping`).
        e: [f32; 4],
        /// The end's filtered reaction force (w: the largest so far) [N]: state.
        rf: [f32; 4],
        /// The end's filtered reaction torque (world) [N m]: state.
        rt: [f32; 4],
        /// Last step's raw reaction force: state (the filter's input).
        xf: [f32; 4],
        /// Last step's raw reaction torque: state.
        xt: [f32; 4],
    }
}

gpu_struct! {
    /// What a rod touches (`touch`, binding 20, bound only to kernels built with `MESH` or
    /// `GUIDE`), one per rod.
    struct TouchG as "Touch" {
        /// Static and kinetic friction with the wall, the contact margin and the rod's radius.
        wall: [f32; 4],
        /// The guide's origin and length.
        guide_o: [f32; 4],
        /// The guide's unit axis and clearance.
        guide_a: [f32; 4],
        /// Whether the rod has a wall and a guide (0 / 1), the contact sweeps of a step without
        /// distance sweeps, and 0.
        on: [u32; 4],
    }
}

/// Every struct the host uploads, for the layout test.
#[cfg(test)]
pub(crate) const SHARED: [GpuLayout; 8] = [
    ParamsU::LAYOUT,
    ChunkG::LAYOUT,
    SlotG::LAYOUT,
    ItemG::LAYOUT,
    DriveG::LAYOUT,
    ClampG::LAYOUT,
    TouchG::LAYOUT,
    CouplingG::LAYOUT,
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shader::KernelConfig;

    /// A member of a WGSL struct as naga laid it out.
    #[derive(Debug, PartialEq)]
    struct Member {
        name: String,
        offset: usize,
        size: usize,
        scalar: String,
    }

    fn scalar_name(module: &naga::Module, ty: naga::Handle<naga::Type>) -> String {
        use naga::TypeInner as T;
        let scalar = match &module.types[ty].inner {
            T::Scalar(s) | T::Vector { scalar: s, .. } | T::Atomic(s) => *s,
            T::Array { base, .. } => return scalar_name(module, *base),
            other => return format!("{other:?}"),
        };
        match (scalar.kind, scalar.width) {
            (naga::ScalarKind::Float, 4) => "f32".into(),
            (naga::ScalarKind::Uint, 4) => "u32".into(),
            (kind, width) => format!("{kind:?}{}", 8 * width),
        }
    }

    /// The members and size of struct `name` in `module`, as naga lays them out.
    fn wgsl_struct(module: &naga::Module, name: &str) -> Option<(Vec<Member>, usize)> {
        let gctx = module.to_ctx();
        module.types.iter().find_map(|(_, ty)| {
            let naga::TypeInner::Struct { members, span } = &ty.inner else {
                return None;
            };
            (ty.name.as_deref() == Some(name)).then(|| {
                let members = members
                    .iter()
                    .map(|m| Member {
                        name: m.name.clone().unwrap_or_default(),
                        offset: m.offset as usize,
                        size: module.types[m.ty].inner.size(gctx) as usize,
                        scalar: scalar_name(module, m.ty),
                    })
                    .collect();
                (members, *span as usize)
            })
        })
    }

    fn rust_struct(layout: &GpuLayout) -> (Vec<Member>, usize) {
        let members = layout
            .fields
            .iter()
            .map(|f| Member {
                name: f.name.into(),
                offset: f.offset,
                size: f.size,
                scalar: f.scalar.into(),
            })
            .collect();
        (members, layout.size)
    }

    /// Every struct the host uploads has a WGSL twin of the same member names, offsets, sizes
    /// and scalar types, and the same size, in the kernel as composed for every path (the
    /// declarations sit outside the `//#if` blocks, but a flag must not be able to change them
    /// unnoticed).
    #[test]
    fn uploaded_structs_match_their_wgsl_twins() {
        // One kernel of each path and layout, with every scene term somewhere.
        for (group, flags) in [
            (1, vec![]),
            (
                1,
                vec![
                    "EXTENSIBLE",
                    "STRETCH_DAMP",
                    "BEND_DAMP",
                    "DRAG",
                    "LOADS",
                    "REGC",
                ],
            ),
            (
                1,
                vec![
                    "GRID",
                    "NBR_SYNC",
                    "COHERENT",
                    "BEND_DAMP",
                    "FAST",
                    "REGC",
                    "CLAMP",
                ],
            ),
            (1, vec!["PERSTEP", "LOADS", "FAST", "REGC", "CLAMP"]),
            (
                32,
                vec!["SUBGROUP", "SHFL", "DRAG", "FAST", "REGC", "REACT"],
            ),
            (1, vec!["MESH", "GUIDE", "DRAG", "FAST", "REGC", "CLAMP"]),
            (1, vec!["MESH", "BIND", "DRAG", "FAST", "REGC", "CLAMP"]),
            (1, vec!["RODC", "DRAG", "FAST", "REGC", "CLAMP"]),
        ] {
            let cfg = KernelConfig {
                threads: 64,
                per_thread: 2,
                iterations: 10,
                halo: 24,
                exchange_steps: 3,
                spin_cap: 1024,
                group,
                unroll: true,
                bind_points: 0,
                bind_inner: 0,
                rodc: Default::default(),
                flags: flags.clone(),
            };
            let src = cfg.source();
            let module = naga::front::wgsl::parse_str(&src)
                .unwrap_or_else(|e| panic!("{flags:?}: {}", e.emit_to_string(&src)));
            // Rod contact's struct exists only in its kernels.
            let rodc = [StrandG::LAYOUT];
            let extra: &[GpuLayout] = if flags.contains(&"RODC") { &rodc } else { &[] };
            for layout in SHARED.iter().chain(extra) {
                let Some(wgsl) = wgsl_struct(&module, layout.wgsl) else {
                    panic!("{flags:?}: no struct `{}` in the kernel", layout.wgsl);
                };
                assert_eq!(
                    rust_struct(layout),
                    wgsl,
                    "{flags:?}: the Rust layout of `{}` (left) differs from the WGSL one (right)",
                    layout.wgsl
                );
            }
            // The wall's tree and triangles are uploaded as the collide crate lays them out.
            if flags.contains(&"MESH") {
                let offsets = |name: &str| {
                    let (members, size) = wgsl_struct(&module, name).expect("wall struct");
                    (members.iter().map(|m| m.offset).collect::<Vec<_>>(), size)
                };
                let node = offsets("WallNode");
                assert_eq!(node, (vec![0, 12, 16, 28], 32), "WallNode against BvhNode");
                assert_eq!(
                    std::mem::size_of::<cosserat_collide::BvhNode>(),
                    node.1,
                    "BvhNode's size"
                );
                let tri = offsets("WallTri");
                assert_eq!(
                    tri,
                    (
                        vec![0, 12, 16, 28, 32, 44, 48, 64, 80, 96, 112, 128, 144],
                        160
                    ),
                    "WallTri against GpuWallTriangle"
                );
                assert_eq!(
                    std::mem::size_of::<cosserat_collide::GpuWallTriangle>(),
                    tri.1,
                    "GpuWallTriangle's size"
                );
                // The near lists' lengths, which size the host's buffers.
                for (name, n) in [
                    ("NEAR_POINT", crate::sim::NEAR_POINT),
                    ("NEAR_ELEMENT", crate::sim::NEAR_ELEMENT),
                ] {
                    let decl = format!("const {name}: u32 = {n}u;");
                    assert!(src.contains(&decl), "the kernel lacks `{decl}`");
                }
            }
        }
    }

    /// The comparison sees a difference: a struct checked against the wrong WGSL twin, or one
    /// field moved, fails it.
    #[test]
    fn the_layout_check_tells_structs_apart() {
        let src = KernelConfig {
            threads: 64,
            per_thread: 2,
            iterations: 10,
            halo: 0,
            exchange_steps: 1,
            spin_cap: 1,
            group: 1,
            unroll: true,
            bind_points: 0,
            bind_inner: 0,
            rodc: Default::default(),
            flags: vec![],
        }
        .source();
        let module = naga::front::wgsl::parse_str(&src).expect("the kernel parses");
        let chunk = wgsl_struct(&module, "Chunk").expect("Chunk");
        assert_ne!(rust_struct(&ParamsU::LAYOUT), chunk);
        assert_eq!(rust_struct(&ChunkG::LAYOUT), chunk);
        // ChunkG with its first two fields' names swapped, as a reordered declaration would.
        let (mut moved, size) = rust_struct(&ChunkG::LAYOUT);
        let first = moved[0].name.clone();
        moved[0].name = std::mem::replace(&mut moved[1].name, first);
        assert_ne!((moved, size), chunk);
    }
}
