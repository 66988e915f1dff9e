//! GPU time stepping of Cosserat rods with wgpu compute shaders.
//!
//! The step is the CPU backend's (`cosserat_backend_cpu::step_rod`, the paper's Fig. 5 without
//! collisions): forces and torques (a clamped end's clamp acting on the end frame through its
//! bend–twist node) → integrate velocities and Euler's equations → held end points take their
//! prescribed velocities, clamps turn with their prescribed angular velocities → red–black
//! distance-constraint sweeps (inextensible mode) → integrate positions and frames → NaN /
//! strain check. What differs is where the rod lives
//! while it is stepped, because on a GPU that decides the speed (see `/docs/gpu.md` and the
//! measurements it cites): a dependent phase costs ~0.1 µs inside a workgroup and ~2 µs
//! across workgroups, and a launch costs ~50–80 µs as seen from the host. Hence three kernel
//! paths, all built from one WGSL kernel ([`KernelPath`]):
//!
//! - **single workgroup**: one rod per workgroup, its points in registers (several per thread),
//!   neighbours exchanged through workgroup memory, `k` steps per dispatch. Many rods fill the
//!   GPU with no inter-workgroup synchronisation at all; from 256 short rods on, where the
//!   adapter has a fixed subgroup size, each rod runs on one subgroup instead (several per
//!   workgroup, neighbours exchanged by shuffles, no barrier at all).
//!
//! Every kernel is composed as text with the per-thread loops unrolled (`shader.rs`), so a
//! thread's points stay in registers: dynamically indexed private arrays go to local memory,
//! and that, not synchronisation, was what made the earlier kernel slow.
//! - **multi-workgroup (grid)**: a rod too long for one workgroup is cut into chunks, each
//!   stepped by a co-resident workgroup on a window that overlaps its neighbours by a halo wider
//!   than the information travels in a few steps (3 by default). Every few steps the windows
//!   exchange halos (through atomics, or vec4s in a `@coherent` buffer) and wait for their
//!   neighbours (a spin on storage flags, capped, with a timeout reported as an error).
//! - **dispatch per step**: the same chunks and halos, one dispatch per exchange period, for
//!   adapters on which co-residency cannot be established (lavapipe, unknown GPUs).
//!
//! The host uploads everything once; afterwards a batch sends only its step range and any
//! changed end motion, and positions are read back only when asked, into one of two staging
//! buffers, so the next batch can be submitted before the previous result is read.
//!
//! A simulation acquires a device of its own ([`GpuSimulation::new`]) or runs on one the caller
//! already has ([`GpuSimulation::on_device`]), so that a renderer can share it. The code is laid
//! out by job: `layout.rs` (the structs uploaded, checked against the WGSL), `plan.rs` (path and
//! kernel shape), `device.rs`, `sim.rs` (upload and stepping), `readback.rs`, and `variants.rs`
//! (measurement-only kernel variants, outside the production path).

pub mod banded;
mod device;
mod layout;
mod plan;
mod readback;
mod shader;
mod sim;
mod stepper;
mod stiff;
mod stiff_stepper;
mod variants;

pub use cosserat_problem::{
    DivergedQuantity, Divergence, EndCondition, EndKind, Gpus, Ordering, PointLoad,
    PrescribedMotion, SolverSettings,
};
pub use device::AdapterSummary;
pub use readback::{GpuField, GpuSnapshot};
pub use sim::GpuSimulation;
pub use stepper::GpuStepper;
pub use stiff::{GpuStiffRod, GpuStiffSimulation, GpuStiffSnapshot, GpuStiffWall};
pub use stiff_stepper::{GpuStiffStepper, StiffRodParts};
#[doc(hidden)]
pub use variants::KernelVariant;

use cosserat_model::{RodParams, RodState};

/// One rod to simulate on the GPU: the same pieces as `cosserat_backend_cpu::CpuRod::new` takes.
#[derive(Clone, Debug)]
pub struct GpuRodInput {
    /// Initial state.
    pub state: RodState<f32>,
    /// Parameters (inverse masses of held end points are zeroed by the backend, as on the CPU).
    pub params: RodParams<f32>,
    /// Conditions at the first (`[0]`) and last (`[1]`) end.
    pub ends: [EndCondition<f32>; 2],
    /// Constant point forces.
    pub loads: Vec<PointLoad<f32>>,
    /// Contact with the environment's mesh (`None`: none, and no contact code runs for it).
    pub wall: Option<GpuWall>,
    /// A straight introducer the rod is fed through from its first point.
    pub guide: Option<GpuGuide>,
    /// This rod is bound inside another one (a guidewire in a catheter).
    pub binding: Option<GpuBinding>,
    /// This rod touches the other rods and itself (`None`: it touches no rod). Every rod has it,
    /// with the same settings, or none does.
    pub rod_contact: Option<GpuRodContact>,
}

/// Rod–rod and self-contact with Coulomb friction: the CPU's `RodContactSpec`
/// (`cosserat_backend_cpu::coupling`), found by the collide crate's bounding spheres and
/// segment–segment test (`cosserat_collide::RodCollider`) and resolved inside the constraint
/// iterations (`cosserat_constraints::RodContactSet`). The rods that have it share one
/// workgroup (at most four rods; `shaders/rod_contact.wgsl`). The bounding spheres' size is the
/// kernel's own (`plan::RODC_SEGMENTS_PER_SPHERE`): the broad phase only culls, so the contacts
/// are those of testing every segment pair whatever it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuRodContact {
    /// Whether a rod collides with itself.
    pub self_collisions: bool,
    /// Static friction coefficient.
    pub static_friction: f32,
    /// Kinetic friction coefficient.
    pub kinetic_friction: f32,
    /// Speculative margin [m]: segments this close get a contact that stops them meeting within
    /// the step.
    pub margin: f32,
}

/// A binding of the rod it belongs to (the inner rod, a guidewire) to the centreline of an outer
/// rod (a catheter): the CPU's `BindingSet` (`cosserat_constraints::binding`). Each inner point
/// inside the outer rod is held on its centreline across it, free to slide along it. The two
/// rods share one workgroup (at most four rods coupled together).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuBinding {
    /// Index of the outer rod.
    pub outer: usize,
    /// Whether the outer rod takes its share of the impulses (v2); `false`: it drives the inner
    /// rod and is not affected by it (v1).
    pub two_way: bool,
    /// Inner points farther than this from the outer centreline are free [m].
    pub capture: f32,
    /// Fraction of a bound point's offset from the centreline removed per step.
    pub offset_correction: f32,
}

/// A rod's contact with a static triangle mesh (a vessel's lumen, or a solid's outside): the
/// CPU's `MeshContactSettings`. Every rod of a simulation that touches a mesh touches the same
/// one (one tree is uploaded).
#[derive(Clone, Debug)]
pub struct GpuWall {
    /// The mesh and its tree.
    pub collider: std::sync::Arc<cosserat_collide::MeshCollider>,
    /// Coulomb friction: sticking holds while the friction impulse stays within
    /// `static_friction` times the normal one; sliding takes `kinetic_friction` times it.
    pub static_friction: f32,
    /// See `static_friction`.
    pub kinetic_friction: f32,
    /// Speculative margin [m]: points this close to the wall get a contact that stops them
    /// reaching it within the step.
    pub margin: f32,
}

/// A straight introducer (the CPU's `cosserat_backend_cpu::Guide`): the points from the second
/// one up to the first one outside it are held on its axis and move only along it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuGuide {
    /// Where the axis starts [m].
    pub origin: [f64; 3],
    /// Unit direction of the axis.
    pub axis: [f64; 3],
    /// Length along the axis [m].
    pub length: f64,
    /// Largest distance from the axis of a point it holds [m].
    pub clearance: f64,
}

/// Which kernel path steps the rods.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum KernelPath {
    /// Chosen from the scene and the adapter (see [`GpuSimulation::new`]).
    #[default]
    Auto,
    /// One workgroup per rod, the rod in registers, many steps per dispatch.
    SingleWorkgroup,
    /// Several co-resident workgroups per rod with a grid barrier, many steps per dispatch.
    MultiWorkgroup,
    /// Several workgroups per rod, one dispatch per step.
    DispatchPerStep,
}

impl std::fmt::Display for KernelPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Auto => "auto",
            Self::SingleWorkgroup => "single-workgroup",
            Self::MultiWorkgroup => "multi-workgroup",
            Self::DispatchPerStep => "dispatch-per-step",
        })
    }
}

/// Options of a [`GpuSimulation`] besides the physics.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuOptions {
    /// Kernel path; [`KernelPath::Auto`] picks one.
    pub path: KernelPath,
    /// Record GPU time with timestamp queries where the adapter supports them
    /// (see [`GpuSimulation::take_gpu_time`]).
    pub timestamps: bool,
    /// The number of workgroups the caller guarantees to be co-resident on this adapter. `None`
    /// uses the built-in table (NVIDIA H100/H200: one per SM); adapters not in it cannot use the
    /// multi-workgroup path. Asserting a wrong number can only make the grid barrier time out
    /// (reported as [`GpuError::GridTimeout`]), never hang.
    pub co_resident_workgroups: Option<u32>,
    /// Iteration cap of each grid-barrier spin loop.
    pub spin_cap: u32,
    /// Upper bound on threads per workgroup (further limited by the adapter's workgroup memory).
    pub max_threads: u32,
    /// Upper bound on steps per dispatch of the persistent paths. On software adapters
    /// (lavapipe), which silently stop a shader's loops after 65 535 iterations in total, the
    /// backend lowers it further so that no dispatch reaches that cap.
    pub max_steps_per_dispatch: u32,
    /// How long a read ([`GpuSimulation::read_positions`] and the other blocking reads) polls
    /// the device in a busy loop before it falls back to a blocking wait, in microseconds. A
    /// blocking wait sleeps in the driver and wakes up tens of microseconds after the GPU has
    /// finished; polling returns as soon as the copy is done, at the price of one busy CPU
    /// core while it waits. 0 always blocks.
    pub spin_wait_us: u32,
    /// Cut-off of the low-pass filter on the reactions at held ends [Hz] (as the CPU's;
    /// `f64::INFINITY` reports the raw value).
    pub reaction_cutoff_hz: f64,
}

impl Default for GpuOptions {
    fn default() -> Self {
        Self {
            path: KernelPath::Auto,
            timestamps: false,
            co_resident_workgroups: None,
            spin_cap: 1 << 20,
            max_threads: 256,
            max_steps_per_dispatch: 10_000,
            spin_wait_us: 2_000,
            reaction_cutoff_hz: cosserat_problem::report::DEFAULT_CUTOFF_HZ,
        }
    }
}

/// What went wrong on the GPU side.
#[derive(Clone, Debug, PartialEq)]
pub enum GpuError {
    /// No adapter (or no device) could be obtained.
    NoAdapter(String),
    /// The scene is not valid for this backend.
    InvalidInput(String),
    /// The requested kernel path cannot run this scene on this adapter.
    PathUnavailable {
        /// The path asked for.
        path: KernelPath,
        /// Why not.
        reason: String,
    },
    /// A rod diverged (NaN or strain beyond the limit), as the CPU backend reports it.
    Diverged(Divergence),
    /// The grid barrier of the multi-workgroup path did not complete within its spin cap: the
    /// workgroups were not co-resident. The state after this is not meaningful.
    GridTimeout,
    /// wgpu reported an error (shader compilation, validation, mapping, device loss).
    Wgpu(String),
}

impl std::fmt::Display for GpuError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoAdapter(why) => write!(f, "no GPU adapter available ({why}); run with `--backend cpu` to use the CPU backend"),
            Self::InvalidInput(why) => write!(f, "invalid scene for the GPU backend: {why}"),
            Self::PathUnavailable { path, reason } => write!(f, "the {path} kernel path is unavailable: {reason}"),
            Self::Diverged(d) => write!(f, "{d}"),
            Self::GridTimeout => f.write_str(
                "the multi-workgroup grid barrier timed out (its workgroups were not co-resident); use the single-workgroup or dispatch-per-step path",
            ),
            Self::Wgpu(e) => write!(f, "wgpu error: {e}"),
        }
    }
}

impl std::error::Error for GpuError {}

impl From<Divergence> for GpuError {
    fn from(d: Divergence) -> Self {
        Self::Diverged(d)
    }
}
