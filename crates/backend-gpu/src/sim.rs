//! [`GpuSimulation`]: upload and batched stepping.
//!
//! Everything the kernels read is uploaded once, when the simulation is built on a device
//! ([`GpuSimulation::new`] acquires one, [`GpuSimulation::on_device`] takes the caller's). A
//! batch ([`GpuSimulation::step`]) then writes only the parameter block (its first step index),
//! the chunk table when the batch's shape changes, and, when the caller changed them, the
//! prescribed end motions. What the kernel reads is laid out in `layout.rs`, which kernel runs
//! is decided in `plan.rs`, the device comes from `device.rs`, and everything read back goes
//! through `readback.rs`.

use crate::device::{AdapterSummary, Gpu};
use crate::layout::{ChunkG, ClampG, DriveG, NONE, ParamsU, SlotG, TABLE_CAPACITY, TouchG};
use crate::plan::{Plan, Tuning};
use crate::readback::Readback;
use crate::{
    GpuError, GpuOptions, GpuRodInput, KernelPath, PointLoad, PrescribedMotion, SolverSettings,
};
use std::time::Duration;

/// Bytes of one chunk-table entry, the size of the table's binding.
const CHUNK_BYTES: u64 = std::mem::size_of::<ChunkG>() as u64;

/// The path of a held end point, tracked in `f64` on the host: its position before step
/// `reference`. The kernel places the point at `origin + (steps moved) h v` rather than
/// integrating it in `f32`, and a new motion starts from the tracked position, so rounding does
/// not accumulate over a long push (the CPU backend's `HeldPath` does the same).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct EndTrack {
    origin: [f64; 3],
    reference: u64,
}

/// One copy of the rods' state on the device (the dispatch-per-step path has two).
pub(crate) struct StateBuffers {
    pub(crate) pos: wgpu::Buffer,
    pub(crate) vel: wgpu::Buffer,
    pub(crate) frm: wgpu::Buffer,
    pub(crate) omg: wgpu::Buffer,
}

/// Rods stepped on the GPU. See the crate docs for the kernel paths.
pub struct GpuSimulation {
    /// The point loads, one `vec4` per slot, when the kernel was built with loads.
    loads_buf: Option<wgpu::Buffer>,
    pub(crate) gpu: Gpu,
    pub(crate) plan: Plan,
    pipeline: wgpu::ComputePipeline,
    bind_groups: Vec<wgpu::BindGroup>,
    params_buf: wgpu::Buffer,
    table_buf: wgpu::Buffer,
    table_stride: u64,
    table_key: Option<(u32, u32)>,
    /// Halo exchanges of one submission with the cached table.
    table_exchanges: u32,
    /// Halo exchanges since the grid's synchronisation words were cleared.
    epochs: u32,
    pub(crate) states: Vec<StateBuffers>,
    /// The state buffers holding the current state.
    pub(crate) current: usize,
    pub(crate) status_buf: wgpu::Buffer,
    /// The clamps, two per rod ([`ClampG`]): one copy on every path, since only the thread
    /// that steps a clamped end frame reads and writes its clamp.
    pub(crate) clamps_buf: wgpu::Buffer,
    /// The clamps as uploaded: their nodes' constants (the frames on the device move on).
    pub(crate) clamps: Vec<ClampG>,
    /// Which ends of each rod are clamped (`[first, last]`).
    pub(crate) clamped: Vec<[bool; 2]>,
    /// Which ends of each rod hold their point (`[first, last]`): those with a reaction.
    pub(crate) ends_held: Vec<[bool; 2]>,
    sync_buf: Option<wgpu::Buffer>,
    drives_buf: wgpu::Buffer,
    pub(crate) drives: Vec<DriveG>,
    /// One per entry of `drives`.
    pub(crate) tracks: Vec<EndTrack>,
    pub(crate) drives_dirty: bool,
    /// First slot and elements of each rod.
    pub(crate) rods: Vec<(u32, u32)>,
    /// Slots of all rods together.
    pub(crate) slots: u64,
    pub(crate) readback: Readback,
    settings: SolverSettings<f32>,
    pub(crate) steps: u64,
    pub(crate) query: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    pub(crate) gpu_time_pending: Vec<wgpu::Buffer>,
    pub(crate) timestamp_period_ns: f64,
    /// Wall contact (kernels with `MESH`): per-rod statistics and per-slot contacts.
    pub(crate) wall: Option<WallBuffers>,
    /// The wall's statistics and contacts as last read with the state.
    pub(crate) wall_read: Option<WallRead>,
    /// Bindings' buffers (kernels with `BIND`).
    pub(crate) bind: Option<BindBuffers>,
    /// Rod contact's buffers (kernels with `RODC`).
    pub(crate) rodc: Option<RodcBuffers>,
    /// Rod contact's statistics words as last read with the state ([`RODC_STATS`] per group).
    pub(crate) rodc_read: Option<Vec<u32>>,
    /// The reaction filter's weights for one step (`ParamsU::rf_keep` and the next two).
    reaction_filter: [f32; 3],
    /// The held ends as last read with the state (their reactions), two per rod.
    pub(crate) ends_read: Vec<ClampG>,
}

/// The wall buffers as read back with the state ([`GpuSimulation::read_state`]).
pub(crate) struct WallRead {
    /// [`WALL_STATS`] words per rod.
    pub(crate) stats: Vec<u32>,
    /// Two `[f32; 4]` per slot.
    pub(crate) contacts: Vec<[f32; 4]>,
}

/// The buffers a kernel with wall contact writes (see `shaders/rod_step.wgsl`).
pub(crate) struct WallBuffers {
    /// Per rod, [`WALL_STATS`] words.
    pub(crate) stats: wgpu::Buffer,
    /// Per slot, two `vec4`: the last step's contact normal (and whether there is one) and the
    /// wall's impulse as a velocity change.
    pub(crate) contacts: wgpu::Buffer,
    /// The points' and elements' anchors, clearances and near lists (`wall_contact.wgsl`),
    /// kept from one dispatch to the next; zeros: none yet.
    pub(crate) near: [wgpu::Buffer; 4],
    /// Which rods touch the wall.
    pub(crate) touching: Vec<bool>,
}

/// The buffers of a kernel with bindings (see `shaders/rod_step.wgsl`, `BIND`).
pub(crate) struct BindBuffers {
    /// Per workgroup, its first item and number of items.
    groups: wgpu::Buffer,
    /// Per item, its part in a binding ([`crate::layout::CouplingG`]).
    couplings: wgpu::Buffer,
    /// Per slot of an inner rod, the outer segment its point was last bound to: state (a
    /// snapshot carries it, so that a restored run finds the same segments).
    pub(crate) segments: wgpu::Buffer,
}

/// The buffers of a kernel with rod contact (see `shaders/rod_contact.wgsl`, `RODC`).
pub(crate) struct RodcBuffers {
    /// Per workgroup, its first item and number of items.
    groups: wgpu::Buffer,
    /// Per item, its part in rod contact ([`crate::layout::StrandG`]).
    strands: wgpu::Buffer,
    /// Per group, [`RODC_STATS`] words: the smallest centreline distance seen (f32 bits), the
    /// radii of that pair (f32 bits), contacts at the last step, most contacts in a step, the
    /// smallest distance over the radii (f32 bits), steps, contacts and sphere pairs that did
    /// not fit the kernel's arrays, and 0.
    pub(crate) stats: wgpu::Buffer,
    /// Per workgroup, the step's contacts (three `vec4` each, `RC_LIST` of them): scratch of
    /// one step.
    list: wgpu::Buffer,
}

/// Statistics words per group of a kernel with rod contact.
pub(crate) const RODC_STATS: usize = 8;

/// The statistics words of a group before its first step (no distance seen: +∞).
pub(crate) fn rodc_stats_init(groups: usize) -> Vec<u32> {
    let inf = f32::INFINITY.to_bits();
    (0..groups)
        .flat_map(|_| [inf, 0, 0, 0, inf, 0, 0, 0])
        .collect()
}

/// Statistics words per rod of a kernel with wall contact.
pub(crate) const WALL_STATS: usize = 11;
/// Triangles in a point's near list, and ridge triangles in an element's
/// (`shaders/wall_contact.wgsl`, checked by a test).
pub(crate) const NEAR_POINT: usize = 16;
pub(crate) const NEAR_ELEMENT: usize = 16;

/// First step index `s` with `s * dt >= t`, matching the CPU's `time = steps as f64 * dt`.
fn first_step_at(t: f64, dt: f64) -> u32 {
    if !t.is_finite() {
        return u32::MAX;
    }
    if t <= 0.0 {
        return 0;
    }
    let mut s = (t / dt).floor().max(0.0).min(u32::MAX as f64 - 2.0) as u32;
    while s > 0 && (s - 1) as f64 * dt >= t {
        s -= 1;
    }
    while (s as f64) * dt < t && s < u32::MAX - 1 {
        s += 1;
    }
    s
}

fn drive_of(m: Option<&PrescribedMotion<f32>>, dt: f64) -> DriveG {
    match m {
        None => DriveG::default(),
        Some(m) => DriveG {
            v: [m.velocity.x, m.velocity.y, m.velocity.z, 0.0],
            w: [
                m.angular_velocity.x,
                m.angular_velocity.y,
                m.angular_velocity.z,
                0.0,
            ],
            window: [
                first_step_at(m.start_time, dt),
                first_step_at(m.end_time, dt),
                0,
                0,
            ],
            origin: [0.0; 4],
        },
    }
}

impl GpuSimulation {
    /// Acquires a device and uploads `rods` to it ([`Self::on_device`] on a device of its own).
    ///
    /// The path is `options.path`, or with [`KernelPath::Auto`]: one workgroup per rod when the
    /// longest rod fits with at most four points per thread (or, from 256 rods on, one subgroup
    /// per rod when the adapter has a fixed subgroup size and the rod fits it with at most eight
    /// points per invocation); otherwise the multi-workgroup path
    /// where co-residency is known for the adapter; otherwise one workgroup per rod up to 16
    /// points per thread; otherwise one dispatch per step.
    ///
    /// The GPU always sweeps the distance constraints in red–black order (whatever
    /// `settings.ordering` says), since that is what lets the invocations of one sweep run in
    /// parallel; compare against the CPU with `Ordering::RedBlack`.
    pub fn new(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
    ) -> Result<Self, GpuError> {
        validate(&rods, settings)?;
        let gpu = Gpu::acquire(&options)?;
        Self::planned(gpu, rods, settings, options)
    }

    /// Uploads `rods` to a device the caller already has, e.g. a renderer's, which can then
    /// draw from the same device; otherwise as [`Self::new`].
    ///
    /// The adapter is the one the device was created from ([`wgpu::Device::adapter_info`]); the
    /// kernel uses the features and limits the device was created with. [`Self::new`] asks for
    /// the adapter's full limits ([`wgpu::Adapter::limits`]) and, where the adapter has them,
    /// [`wgpu::Features::SUBGROUP`] and [`wgpu::Features::MEMORY_DECORATION_COHERENT`] (and
    /// [`wgpu::Features::TIMESTAMP_QUERY`] with [`GpuOptions::timestamps`]); a device created
    /// the same way runs the same kernel, bit for bit. Without the optional features the
    /// layouts that need them are not chosen; with lower limits building can fail with
    /// [`GpuError::Wgpu`] (wgpu's default limits allow 8 storage buffers per shader stage, and
    /// the kernel binds 8 to 14).
    ///
    /// The device's uncaptured-error handler stays its owner's: errors while building are
    /// returned, but a validation error in a later batch reaches that handler instead of the
    /// next read.
    pub fn on_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
    ) -> Result<Self, GpuError> {
        validate(&rods, settings)?;
        Self::planned(
            Gpu::shared(device, queue, &options),
            rods,
            settings,
            options,
        )
    }

    /// Uploads `rods` to a device [`crate::GpuStepper::on_gpus`] opened.
    pub(crate) fn on_gpu(
        gpu: Gpu,
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
    ) -> Result<Self, GpuError> {
        validate(&rods, settings)?;
        Self::planned(gpu, rods, settings, options)
    }

    /// Plans with the production tuning and builds.
    fn planned(
        gpu: Gpu,
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
    ) -> Result<Self, GpuError> {
        let plan = Plan::new(
            &rods,
            settings,
            &options,
            &Tuning::PRODUCTION,
            &gpu.adapter,
            &gpu.limits,
        )?;
        Self::build(gpu, plan, rods, settings, &options)
    }

    /// Uploads `rods` to `gpu` and prepares `plan`'s kernel: the construction [`Self::new`],
    /// [`Self::on_device`] and the benchmark's variants share.
    pub(crate) fn build(
        gpu: Gpu,
        plan: Plan,
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: &GpuOptions,
    ) -> Result<Self, GpuError> {
        // A shared device keeps its owner's uncaptured-error handler, so errors of the
        // construction are caught here, for every device alike.
        let creation = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let memory = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let built = Self::upload(gpu, plan, rods, settings, options);
        let memory = pollster::block_on(memory.pop());
        let creation = pollster::block_on(creation.pop());
        if let Some(e) = memory.or(creation) {
            return Err(GpuError::Wgpu(format!("building the simulation: {e}")));
        }
        let sim = built?;
        sim.gpu.errors.take()?;
        Ok(sim)
    }

    #[allow(clippy::too_many_lines)]
    fn upload(
        gpu: Gpu,
        plan: Plan,
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: &GpuOptions,
    ) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let limits = &gpu.limits;
        let want_ts = gpu.adapter.timestamps;
        use wgpu::util::DeviceExt;
        let dt = settings.dt as f64;
        // Slots: rod r occupies slots base..base+n+1 (point i, element i, node i in slot i).
        let mut rod_layout = Vec::with_capacity(rods.len());
        let mut total = 0u32;
        for rod in &rods {
            let n = rod.state.elements() as u32;
            rod_layout.push((total, n));
            total += n + 1;
        }
        let slots_n = total as usize;
        let mut slots = vec![SlotG::default(); slots_n];
        let mut pos = vec![[0f32; 4]; slots_n];
        let mut vel = vec![[0f32; 4]; slots_n];
        let mut frm = vec![[0f32, 0.0, 0.0, 1.0]; slots_n];
        let mut omg = vec![[0f32; 4]; slots_n];
        let mut loads = vec![[0f32; 4]; slots_n];
        let mut drives = Vec::with_capacity(2 * rods.len());
        let mut tracks = Vec::with_capacity(2 * rods.len());
        let mut clamps = Vec::with_capacity(2 * rods.len());
        for (rod, &(base, n)) in rods.iter().zip(&rod_layout) {
            let (b, n) = (base as usize, n as usize);
            let p = &rod.params;
            let s = &rod.state;
            let mut inv = p.inv_masses.clone();
            if rod.ends[0].holds_point() {
                inv[0] = 0.0;
            }
            if rod.ends[1].holds_point() {
                inv[n] = 0.0;
            }
            for i in 0..=n {
                let sl = &mut slots[b + i];
                sl.a[1] = inv[i];
                sl.a[2] = p.masses[i];
                pos[b + i] = [s.positions[i].x, s.positions[i].y, s.positions[i].z, 0.0];
                vel[b + i] = [s.velocities[i].x, s.velocities[i].y, s.velocities[i].z, 0.0];
                if i < n {
                    let inertia = p.inertias[i];
                    sl.a[0] = p.rest_lengths[i];
                    sl.a[3] = p.parallel_stiffness[i];
                    sl.b = [inertia.x, inertia.y, inertia.z, p.stretch_stiffness[i]];
                    sl.c = [
                        1.0 / inertia.x,
                        1.0 / inertia.y,
                        1.0 / inertia.z,
                        p.stretch_damping[i],
                    ];
                    let q = s.frames[i];
                    frm[b + i] = [q.i, q.j, q.k, q.w];
                    let w = s.angular_velocities[i];
                    omg[b + i] = [w.x, w.y, w.z, 0.0];
                }
                if i + 1 < n {
                    let u = p.rest_darboux[i];
                    let k = p.bend_twist_stiffness[i];
                    sl.d = [u.x, u.y, u.z, p.node_length(i)];
                    sl.e = [k.x, k.y, k.z, p.bend_damping[i]];
                }
            }
            for load in &rod.loads {
                let l = &mut loads[b + load.point];
                l[0] += load.force.x;
                l[1] += load.force.y;
                l[2] += load.force.z;
            }
            for end in 0..2 {
                let (q, node) = (s.clamp_frames[end], &p.end_nodes[end]);
                let (u, k) = (node.rest_darboux, node.stiffness);
                clamps.push(ClampG {
                    q: [q.i, q.j, q.k, q.w],
                    d: [u.x, u.y, u.z, p.end_node_length(end)],
                    e: [k.x, k.y, k.z, node.damping],
                    ..ClampG::default()
                });
            }
            for (end, point) in [(0, 0), (1, n)] {
                let p = s.positions[point];
                let origin = [f64::from(p.x), f64::from(p.y), f64::from(p.z)];
                let mut d = drive_of(rod.ends[end].motion.as_ref(), dt);
                d.origin = [p.x, p.y, p.z, 0.0];
                drives.push(d);
                tracks.push(EndTrack {
                    origin,
                    reference: 0,
                });
            }
        }
        let clamped = rods
            .iter()
            .map(|r| r.ends.each_ref().map(|e| e.holds_frame()))
            .collect();
        let ends_held = rods
            .iter()
            .map(|r| r.ends.each_ref().map(|e| e.holds_point()))
            .collect();
        let has_loads = plan.cfg.flags.contains(&"LOADS");
        // Held ends' clamps and reactions (every kernel with CLAMP has REACT).
        let has_ends = plan.cfg.flags.contains(&"REACT");
        let has_mesh = plan.cfg.flags.contains(&"MESH");
        let has_touch = has_mesh || plan.cfg.flags.contains(&"GUIDE");
        let touch: Vec<TouchG> = rods
            .iter()
            .map(|r| {
                let mut t = TouchG::default();
                if let Some(w) = &r.wall {
                    t.wall = [
                        w.static_friction,
                        w.kinetic_friction,
                        w.margin,
                        r.params.radius,
                    ];
                    t.on[0] = 1;
                }
                if let Some(g) = &r.guide {
                    let f = |v: f64| v as f32;
                    t.guide_o = [f(g.origin[0]), f(g.origin[1]), f(g.origin[2]), f(g.length)];
                    t.guide_a = [f(g.axis[0]), f(g.axis[1]), f(g.axis[2]), f(g.clearance)];
                    t.on[1] = 1;
                }
                t.on[2] = settings.iterations.max(1) as u32;
                t
            })
            .collect();
        // One mesh for every rod that touches one (checked by `validate`).
        let collider = rods
            .iter()
            .find_map(|r| r.wall.as_ref())
            .map(|w| &w.collider);
        let perstep = plan.path == KernelPath::DispatchPerStep;
        let grid = plan.path == KernelPath::MultiWorkgroup;

        let storage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let init = |label: &str, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage,
            })
        };
        let params_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: std::mem::size_of::<ParamsU>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let table_stride = (limits.min_uniform_buffer_offset_alignment as u64).max(CHUNK_BYTES);
        let table_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("chunk table"),
            size: table_stride * TABLE_CAPACITY as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let slots_buf = init(
            "slots",
            bytemuck::cast_slice(&slots),
            wgpu::BufferUsages::STORAGE,
        );
        let items_buf = init(
            "items",
            bytemuck::cast_slice(&plan.items),
            wgpu::BufferUsages::STORAGE,
        );
        let drives_buf = init(
            "drives",
            bytemuck::cast_slice(&drives),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        );
        let loads_buf = has_loads.then(|| {
            init(
                "loads",
                bytemuck::cast_slice(&loads),
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            )
        });
        let make_state = |tag: &str| StateBuffers {
            pos: init(&format!("pos {tag}"), bytemuck::cast_slice(&pos), storage),
            vel: init(&format!("vel {tag}"), bytemuck::cast_slice(&vel), storage),
            frm: init(&format!("frm {tag}"), bytemuck::cast_slice(&frm), storage),
            omg: init(&format!("omg {tag}"), bytemuck::cast_slice(&omg), storage),
        };
        let mut states = vec![make_state("a")];
        if perstep {
            states.push(make_state("b"));
        }
        let clamps_buf = init("clamps", bytemuck::cast_slice(&clamps), storage);
        // Bindings: the groups, each item's part, and the exchange between the rods of a group.
        let bind_bufs = plan.cfg.flags.contains(&"BIND").then(|| {
            let plain = wgpu::BufferUsages::STORAGE;
            BindBuffers {
                groups: init("groups", bytemuck::cast_slice(&plan.groups), plain),
                couplings: init("couplings", bytemuck::cast_slice(&plan.couplings), plain),
                segments: init(
                    "bound segments",
                    bytemuck::cast_slice(&vec![NONE; slots_n]),
                    storage,
                ),
            }
        });
        // Rod contact: the groups, each item's part, and the statistics per group.
        let rodc_bufs = plan.cfg.flags.contains(&"RODC").then(|| {
            let plain = wgpu::BufferUsages::STORAGE;
            RodcBuffers {
                groups: init("groups", bytemuck::cast_slice(&plan.groups), plain),
                strands: init("strands", bytemuck::cast_slice(&plan.strands), plain),
                stats: init(
                    "rod contact stats",
                    bytemuck::cast_slice(&rodc_stats_init(plan.groups.len())),
                    storage,
                ),
                list: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("rod contact list"),
                    size: 48
                        * u64::from(plan.cfg.threads * plan.cfg.rodc.per_thread)
                        * plan.groups.len() as u64,
                    usage: plain,
                    mapped_at_creation: false,
                }),
            }
        });
        let touch_buf = has_touch.then(|| {
            init(
                "touch",
                bytemuck::cast_slice(&touch),
                wgpu::BufferUsages::STORAGE,
            )
        });
        let wall_bufs = match (has_mesh, collider) {
            (true, Some(c)) => {
                let nodes = c.bvh().node_words();
                let tris: Vec<u32> = c.wall_triangles().iter().flat_map(wall_words).collect();
                Some((
                    init(
                        "wall nodes",
                        bytemuck::cast_slice(&nodes),
                        wgpu::BufferUsages::STORAGE,
                    ),
                    init(
                        "wall triangles",
                        bytemuck::cast_slice(&tris),
                        wgpu::BufferUsages::STORAGE,
                    ),
                    WallBuffers {
                        stats: init(
                            "wall stats",
                            &vec![0u8; 4 * WALL_STATS * rods.len()],
                            storage,
                        ),
                        contacts: init("contacts", &vec![0u8; 32 * slots_n], storage),
                        near: [
                            init("point anchors", &vec![0u8; 16 * slots_n], storage),
                            init(
                                "point near lists",
                                &vec![0u8; 4 * (NEAR_POINT + 1) * slots_n],
                                storage,
                            ),
                            init("element anchors", &vec![0u8; 32 * slots_n], storage),
                            init(
                                "element near lists",
                                &vec![0u8; 4 * (NEAR_ELEMENT + 1) * slots_n],
                                storage,
                            ),
                        ],
                        touching: rods.iter().map(|r| r.wall.is_some()).collect(),
                    },
                ))
            }
            _ => None,
        };
        let n_items = plan.items.len();
        let status_buf = init("status", &vec![0u8; 16 * n_items], storage);
        // Word 0: the grid-wide arrival counter; words 1..: per-item flags (NBR_SYNC).
        let sync_bytes = (4 * (1 + n_items)).div_ceil(16) * 16;
        let sync_buf = grid.then(|| init("grid sync", &vec![0u8; sync_bytes], storage));
        let xch_words = 2 * n_items * 2 * plan.cfg.halo as usize * 16;
        let xch_buf = grid.then(|| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("halo exchange"),
                size: (4 * xch_words.max(4)) as u64,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        });

        // Explicit layout: the chunk table needs a dynamic offset, which derived layouts lack.
        let ro = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let rw = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: false },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let uniform = |binding, dynamic| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: dynamic,
                min_binding_size: None,
            },
            count: None,
        };
        let mut entries = vec![
            uniform(0, false),
            uniform(1, true),
            ro(2),
            ro(3),
            ro(4),
            rw(5),
            rw(6),
            rw(7),
            rw(8),
            rw(9),
        ];
        if has_loads {
            entries.push(ro(10));
        }
        if perstep {
            entries.extend([ro(11), ro(12), ro(13), ro(14)]);
        }
        if grid {
            entries.extend([rw(15), rw(16)]);
        }
        if has_ends {
            entries.push(rw(17));
        }
        if has_mesh {
            entries.extend([
                ro(18),
                ro(19),
                rw(21),
                rw(22),
                rw(23),
                rw(24),
                rw(25),
                rw(26),
            ]);
        }
        if has_touch {
            entries.push(ro(20));
        }
        if bind_bufs.is_some() {
            entries.extend([ro(27), ro(28), rw(31)]);
        }
        if rodc_bufs.is_some() {
            entries.extend([ro(27), ro(29), rw(30), rw(32)]);
        }
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("rod step"),
            entries: &entries,
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("rod step"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });

        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("rod_step.wgsl"),
            source: wgpu::ShaderSource::Wgsl(plan.cfg.source().into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("rod step"),
            layout: Some(&layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Wgpu(format!("compiling the step kernel: {e}")));
        }

        fn whole(b: &wgpu::Buffer) -> wgpu::BindingResource<'_> {
            b.as_entire_binding()
        }
        let make_bg = |dst: &StateBuffers, src: Option<&StateBuffers>| {
            let mut e = vec![
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: whole(&params_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &table_buf,
                        offset: 0,
                        size: wgpu::BufferSize::new(CHUNK_BYTES),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: whole(&slots_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: whole(&items_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: whole(&drives_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: whole(&dst.pos),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: whole(&dst.vel),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: whole(&dst.frm),
                },
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: whole(&dst.omg),
                },
                wgpu::BindGroupEntry {
                    binding: 9,
                    resource: whole(&status_buf),
                },
            ];
            if let Some(l) = &loads_buf {
                e.push(wgpu::BindGroupEntry {
                    binding: 10,
                    resource: whole(l),
                });
            }
            if let Some(s) = src {
                e.push(wgpu::BindGroupEntry {
                    binding: 11,
                    resource: whole(&s.pos),
                });
                e.push(wgpu::BindGroupEntry {
                    binding: 12,
                    resource: whole(&s.vel),
                });
                e.push(wgpu::BindGroupEntry {
                    binding: 13,
                    resource: whole(&s.frm),
                });
                e.push(wgpu::BindGroupEntry {
                    binding: 14,
                    resource: whole(&s.omg),
                });
            }
            if let (Some(s), Some(x)) = (&sync_buf, &xch_buf) {
                e.push(wgpu::BindGroupEntry {
                    binding: 15,
                    resource: whole(s),
                });
                e.push(wgpu::BindGroupEntry {
                    binding: 16,
                    resource: whole(x),
                });
            }
            if has_ends {
                e.push(wgpu::BindGroupEntry {
                    binding: 17,
                    resource: whole(&clamps_buf),
                });
            }
            if let Some((nodes, tris, w)) = &wall_bufs {
                for (binding, b) in [
                    (18, nodes),
                    (19, tris),
                    (21, &w.stats),
                    (22, &w.contacts),
                    (23, &w.near[0]),
                    (24, &w.near[1]),
                    (25, &w.near[2]),
                    (26, &w.near[3]),
                ] {
                    e.push(wgpu::BindGroupEntry {
                        binding,
                        resource: whole(b),
                    });
                }
            }
            if let Some(t) = &touch_buf {
                e.push(wgpu::BindGroupEntry {
                    binding: 20,
                    resource: whole(t),
                });
            }
            if let Some(b) = &bind_bufs {
                for (binding, buf) in [(27, &b.groups), (28, &b.couplings), (31, &b.segments)] {
                    e.push(wgpu::BindGroupEntry {
                        binding,
                        resource: whole(buf),
                    });
                }
            }
            if let Some(b) = &rodc_bufs {
                for (binding, buf) in [
                    (27, &b.groups),
                    (29, &b.strands),
                    (30, &b.stats),
                    (32, &b.list),
                ] {
                    e.push(wgpu::BindGroupEntry {
                        binding,
                        resource: whole(buf),
                    });
                }
            }
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("rod step"),
                layout: &bgl,
                entries: &e,
            })
        };
        // Per-step path: bind group i reads state i and writes state 1 - i.
        let bind_groups = if perstep {
            vec![
                make_bg(&states[1], Some(&states[0])),
                make_bg(&states[0], Some(&states[1])),
            ]
        } else {
            vec![make_bg(&states[0], None)]
        };

        let readback = Readback::new(
            device,
            slots_n as u64,
            n_items as u64,
            Duration::from_micros(options.spin_wait_us as u64),
        );
        let query = want_ts.then(|| {
            let set = device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass time"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            });
            let resolve = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            (set, resolve)
        });
        let timestamp_period_ns = gpu.queue.get_timestamp_period() as f64;
        Ok(Self {
            loads_buf,
            gpu,
            plan,
            pipeline,
            bind_groups,
            params_buf,
            table_buf,
            table_stride,
            table_key: None,
            table_exchanges: 0,
            epochs: 0,
            states,
            current: 0,
            status_buf,
            clamps_buf,
            ends_read: clamps.clone(),
            ends_held,
            clamps,
            clamped,
            sync_buf,
            drives_buf,
            drives,
            tracks,
            drives_dirty: false,
            rods: rod_layout,
            readback,
            slots: slots_n as u64,
            settings: *settings,
            steps: 0,
            query,
            gpu_time_pending: Vec::new(),
            timestamp_period_ns,
            wall: wall_bufs.map(|(_, _, w)| w),
            wall_read: None,
            bind: bind_bufs,
            rodc: rodc_bufs,
            rodc_read: None,
            reaction_filter: {
                let (keep, old, new) = cosserat_problem::report::reaction_filter_weights(
                    options.reaction_cutoff_hz,
                    f64::from(settings.dt),
                );
                [keep as f32, old as f32, new as f32]
            },
        })
    }

    /// The adapter in use.
    pub fn adapter(&self) -> &AdapterSummary {
        &self.gpu.adapter
    }

    /// The kernel path in use (never [`KernelPath::Auto`]).
    pub fn path(&self) -> KernelPath {
        self.plan.path
    }

    /// A one-line description of the kernel: path, threads, points per thread, workgroups, halo,
    /// steps per dispatch and the compiled-in terms.
    pub fn kernel_description(&self) -> String {
        self.plan.describe()
    }

    /// Steps submitted so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Simulated time of the submitted steps in seconds, as the CPU backend counts it.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.settings.dt as f64
    }

    /// Number of rods.
    pub fn rods(&self) -> usize {
        self.rods.len()
    }

    /// Rod `rod`'s contact statistics as of the last [`Self::read_state`] (`None` for a rod
    /// that touches no mesh, or before the first read): the CPU's `CollisionStats`, with
    /// `detection_seconds` 0 (detection is not timed on its own on the GPU).
    pub fn collision_stats(&self, rod: usize) -> Option<cosserat_problem::CollisionStats> {
        let touching = self.wall.as_ref()?.touching.get(rod).copied()?;
        let read = self.wall_read.as_ref().filter(|_| touching)?;
        let w = &read.stats[WALL_STATS * rod..WALL_STATS * (rod + 1)];
        Some(cosserat_problem::CollisionStats {
            max_penetration: f64::from(f32::from_bits(w[0])),
            escaped_points: w[1] as usize,
            contacts: w[2] as usize,
            max_contacts: w[3] as usize,
            steps: u64::from(w[4]),
            swept_catches: u64::from(w[5]),
            segment_contacts: u64::from(w[8]),
            queries: u64::from(w[6]),
            ..Default::default()
        })
    }

    /// Rod–rod and self-contact statistics of all groups together as of the last
    /// [`Self::read_state`] (`None` without rod contact, or before the first read): the CPU's
    /// `CouplingStats` (contacts at the last step and at most, the smallest centreline distance
    /// of two non-neighbouring segments seen at a step's start with the radii of that pair and
    /// the smallest ratio), with `detection_seconds` 0 (detection is not timed on its own).
    pub fn rod_contact_stats(&self) -> Option<cosserat_problem::CouplingStats> {
        let words = self.rodc_read.as_ref()?;
        let f = |w: u32| f64::from(f32::from_bits(w));
        let mut out = cosserat_problem::CouplingStats::default();
        for g in words.chunks_exact(RODC_STATS) {
            out.contacts += g[2] as usize;
            out.max_contacts += g[3] as usize;
            if f(g[0]) < out.min_separation {
                out.min_separation = f(g[0]);
                out.min_separation_radii = f(g[1]);
            }
            out.min_separation_ratio = out.min_separation_ratio.min(f(g[4]));
            out.steps = out.steps.max(u64::from(g[5]));
        }
        Some(out)
    }

    /// Contacts and sphere pairs that did not fit the rod-contact kernel's arrays since the
    /// start, as of the last [`Self::read_state`] (0 without rod contact). The kernel drops
    /// them, so a nonzero count makes [`Self::read_state`] fail.
    pub fn rod_contact_dropped(&self) -> u64 {
        self.rodc_read.as_ref().map_or(0, |w| {
            w.chunks_exact(RODC_STATS).map(|g| u64::from(g[6])).sum()
        })
    }

    /// What rod `rod`'s wall contact cost since the start, as of the last
    /// [`Self::read_state`]: the points' tree walks, their queries answered from near lists,
    /// the elements' tree walks, and walks whose stack overflowed (0 for any mesh with
    /// `u32` indices).
    pub fn wall_work(&self, rod: usize) -> Option<[u64; 4]> {
        let read = self.wall_read.as_ref()?;
        let w = read.stats.get(WALL_STATS * rod..WALL_STATS * (rod + 1))?;
        Some([w[6], w[9], w[10], w[7]].map(u64::from))
    }

    /// Rod `rod`'s points in contact with the wall at the last step before the last
    /// [`Self::read_state`]: point, unit normal (into the lumen), and the wall's impulse on the
    /// point over that step as a velocity change [m/s] (normal and friction).
    pub fn wall_contacts(&self, rod: usize) -> Vec<(usize, [f32; 3], [f32; 3])> {
        let (Some(read), Some(&(base, n))) = (self.wall_read.as_ref(), self.rods.get(rod)) else {
            return Vec::new();
        };
        (0..=n as usize)
            .filter_map(|i| {
                let s = base as usize + i;
                let [nx, ny, nz, on] = *read.contacts.get(2 * s)?;
                let [ix, iy, iz, _] = *read.contacts.get(2 * s + 1)?;
                (on > 0.5).then_some((i, [nx, ny, nz], [ix, iy, iz]))
            })
            .collect()
    }

    /// Replaces the point loads of rod `rod` from the next batch on. The kernel reads loads
    /// only when it was built with some (a rod had a load when the simulation was made, even
    /// a zero one); otherwise this is refused.
    pub fn set_loads(&mut self, rod: usize, loads: &[PointLoad<f32>]) -> Result<(), GpuError> {
        let Some(&(base, n)) = self.rods.get(rod) else {
            return Err(GpuError::InvalidInput(format!("no rod {rod}")));
        };
        let Some(buf) = self.loads_buf.as_ref() else {
            return Err(GpuError::InvalidInput(
                "the kernels were built without loads: give a rod a load (a zero one will do) when the simulation is made".into(),
            ));
        };
        let n = n as usize;
        let mut words = vec![[0f32; 4]; n + 1];
        for load in loads {
            let Some(w) = words.get_mut(load.point) else {
                return Err(GpuError::InvalidInput(format!(
                    "rod {rod}: load on point {}, but the rod has points 0..={n}",
                    load.point
                )));
            };
            w[0] += load.force.x;
            w[1] += load.force.y;
            w[2] += load.force.z;
        }
        self.gpu
            .queue
            .write_buffer(buf, 16 * u64::from(base), bytemuck::cast_slice(&words));
        Ok(())
    }

    /// Replaces the prescribed motion of end `end` (0 or 1) of rod `rod` from the next batch on.
    /// Its start and end times are in simulated seconds, as on the CPU. The end must be held.
    pub fn set_end_motion(
        &mut self,
        rod: usize,
        end: usize,
        motion: Option<PrescribedMotion<f32>>,
    ) -> Result<(), GpuError> {
        if rod >= self.rods.len() || end > 1 {
            return Err(GpuError::InvalidInput(format!("no end {end} of rod {rod}")));
        }
        self.replace_drive(
            2 * rod + end,
            drive_of(motion.as_ref(), self.settings.dt as f64),
        );
        Ok(())
    }

    /// Where held end `i` (an index into `drives`) is before step `step`, in `f64`.
    fn end_position(&self, i: usize, step: u64) -> [f64; 3] {
        let (d, t) = (&self.drives[i], &self.tracks[i]);
        let lo = t.reference.max(u64::from(d.window[0]));
        let hi = step.min(u64::from(d.window[1]));
        let moved = hi.saturating_sub(lo) as f64 * self.settings.dt as f64;
        std::array::from_fn(|c| t.origin[c] + moved * f64::from(d.v[c]))
    }

    /// Installs `drive` for held end `i` from the next step on, starting from where the end is.
    fn replace_drive(&mut self, i: usize, mut drive: DriveG) {
        let here = self.end_position(i, self.steps);
        self.tracks[i] = EndTrack {
            origin: here,
            reference: self.steps,
        };
        drive.window[2] = self.steps as u32;
        drive.origin = [here[0] as f32, here[1] as f32, here[2] as f32, 0.0];
        self.drives[i] = drive;
        self.drives_dirty = true;
    }

    /// Starts the path of held end `i` (an index into `drives`) again from `p`, where the end was
    /// just put, keeping its motion.
    pub(crate) fn restart_end_path(&mut self, i: usize, p: [f32; 3]) {
        self.tracks[i] = EndTrack {
            origin: p.map(f64::from),
            reference: self.steps,
        };
        let d = &mut self.drives[i];
        d.window[2] = self.steps as u32;
        d.origin = [p[0], p[1], p[2], 0.0];
        self.drives_dirty = true;
    }

    /// Drives end `end` of rod `rod` with a constant velocity and angular velocity (world frame)
    /// from the next batch on, until changed: the per-batch input of a haptic loop.
    pub fn set_end_velocity(
        &mut self,
        rod: usize,
        end: usize,
        velocity: [f32; 3],
        angular_velocity: [f32; 3],
    ) -> Result<(), GpuError> {
        if rod >= self.rods.len() || end > 1 {
            return Err(GpuError::InvalidInput(format!("no end {end} of rod {rod}")));
        }
        self.replace_drive(
            2 * rod + end,
            DriveG {
                v: [velocity[0], velocity[1], velocity[2], 0.0],
                w: [
                    angular_velocity[0],
                    angular_velocity[1],
                    angular_velocity[2],
                    0.0,
                ],
                window: [0, u32::MAX, 0, 0],
                origin: [0.0; 4],
            },
        );
        Ok(())
    }

    /// Submits `k` time-steps and returns without waiting for them.
    ///
    /// Divergence and grid timeouts are detected by the kernel, which stops the affected rod;
    /// they are reported by the next read ([`Self::read_positions`], [`Self::read_state`],
    /// [`Self::check`]).
    pub fn step(&mut self, k: u32) -> Result<(), GpuError> {
        self.submit_steps(k, false)
    }

    /// [`Self::step`] followed by [`Self::request_positions`], recorded into one submission:
    /// a haptic loop's batch with its readback costs one submit instead of two. Read the
    /// result with [`Self::read_positions`].
    pub fn step_and_request(&mut self, k: u32) -> Result<(), GpuError> {
        if k == 0 {
            return self.request_positions();
        }
        self.submit_steps(k, true)
    }

    fn submit_steps(&mut self, k: u32, readback: bool) -> Result<(), GpuError> {
        self.gpu.errors.take()?;
        if readback {
            self.readback_slot()?;
        }
        if k == 0 {
            return Ok(());
        }
        if self.steps + k as u64 > u32::MAX as u64 - 1 {
            return Err(GpuError::InvalidInput(
                "more than 2^32 - 2 steps in one simulation".into(),
            ));
        }
        if self.drives_dirty {
            self.gpu
                .queue
                .write_buffer(&self.drives_buf, 0, bytemuck::cast_slice(&self.drives));
            self.drives_dirty = false;
        }
        let xs = self.plan.cfg.exchange_steps.max(1);
        let spd = if self.plan.path == KernelPath::DispatchPerStep {
            xs
        } else {
            self.plan.steps_per_dispatch
        };
        let per_submit_steps = spd as u64 * TABLE_CAPACITY as u64;
        let mut remaining = k as u64;
        while remaining > 0 {
            let this = remaining.min(per_submit_steps) as u32;
            let dispatches = this.div_ceil(spd);
            if self.table_key != Some((this, spd)) {
                let mut table = vec![0u8; (self.table_stride * dispatches as u64) as usize];
                // Halo exchanges before each dispatch (a dispatch of c steps exchanges at
                // steps xs, 2 xs, … < c; grid barrier targets count from the submission).
                let mut exchanges = 0u32;
                for d in 0..dispatches {
                    let off = d * spd;
                    let count = spd.min(this - off);
                    let at = (self.table_stride * d as u64) as usize;
                    let entry = ChunkG {
                        offset: off,
                        count,
                        sync_base: exchanges,
                        pad1: 0,
                    };
                    table[at..at + CHUNK_BYTES as usize]
                        .copy_from_slice(bytemuck::bytes_of(&entry));
                    exchanges += (count - 1) / xs;
                }
                self.gpu.queue.write_buffer(&self.table_buf, 0, &table);
                self.table_key = Some((this, spd));
                self.table_exchanges = exchanges;
            }
            // The synchronisation words count exchanges across submissions (30 bits); they are
            // cleared only before the grid-wide counter could overflow.
            let n_items = self.plan.items.len() as u64;
            let clear = self.sync_buf.is_some()
                && (self.epochs as u64 + self.table_exchanges as u64 + 1) * n_items >= 1 << 29;
            if clear {
                self.epochs = 0;
            }
            let s = &self.settings;
            let (lo, hi) = (1.0 - s.divergence_strain, 1.0 + s.divergence_strain);
            let params = ParamsU {
                gravity: [s.gravity.x, s.gravity.y, s.gravity.z, s.dt],
                lo2: lo * lo,
                hi2: hi * hi,
                base_step: self.steps as u32,
                num_items: self.plan.items.len() as u32,
                epoch0: self.epochs,
                rf_keep: self.reaction_filter[0],
                rf_old: self.reaction_filter[1],
                rf_new: self.reaction_filter[2],
            };
            self.epochs += self.table_exchanges;
            self.gpu
                .queue
                .write_buffer(&self.params_buf, 0, bytemuck::bytes_of(&params));
            let mut enc = self
                .gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("steps"),
                });
            if let Some(sync) = self.sync_buf.as_ref().filter(|_| clear) {
                enc.clear_buffer(sync, 0, None);
            }
            {
                let ts = self
                    .query
                    .as_ref()
                    .map(|(set, _)| wgpu::ComputePassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    });
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("steps"),
                    timestamp_writes: ts,
                });
                pass.set_pipeline(&self.pipeline);
                for d in 0..dispatches {
                    let offset = (self.table_stride * d as u64) as u32;
                    pass.set_bind_group(
                        0,
                        &self.bind_groups[self.current.min(self.bind_groups.len() - 1)],
                        &[offset],
                    );
                    pass.dispatch_workgroups(self.plan.workgroups, 1, 1);
                    if self.plan.path == KernelPath::DispatchPerStep {
                        self.current ^= 1;
                    }
                }
            }
            if let Some((set, resolve)) = &self.query {
                enc.resolve_query_set(set, 0..2, resolve, 0);
                let read = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamps readback"),
                    size: 16,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                enc.copy_buffer_to_buffer(resolve, 0, &read, 0, 16);
                self.gpu_time_pending.push(read);
            }
            let last = remaining == this as u64;
            if readback && last {
                let slot = self.readback_slot()?;
                self.encode_readback(&mut enc, slot);
                let submission = self.gpu.queue.submit([enc.finish()]);
                self.map_readback(slot, submission);
            } else {
                self.gpu.queue.submit([enc.finish()]);
            }
            self.steps += this as u64;
            remaining -= this as u64;
        }
        Ok(())
    }
}

/// Rejects scenes the kernel cannot run, before anything is uploaded.
pub(crate) fn validate(
    rods: &[GpuRodInput],
    settings: &SolverSettings<f32>,
) -> Result<(), GpuError> {
    if rods.is_empty() {
        return Err(GpuError::InvalidInput("no rods".into()));
    }
    if !(settings.dt > 0.0 && settings.dt.is_finite()) {
        return Err(GpuError::InvalidInput(format!(
            "dt = {} must be finite and > 0",
            settings.dt
        )));
    }
    if settings.iterations > 10_000 {
        return Err(GpuError::InvalidInput(format!(
            "{} constraint iterations is more than the GPU kernel supports (10 000)",
            settings.iterations
        )));
    }
    for (r, rod) in rods.iter().enumerate() {
        let n = rod.state.elements();
        if n < 1 {
            return Err(GpuError::InvalidInput(format!("rod {r} has no elements")));
        }
        if n >= 1 << 24 {
            return Err(GpuError::InvalidInput(format!(
                "rod {r} has {n} elements; at most 2^24 - 1"
            )));
        }
        let p = &rod.params;
        let ok = rod.state.positions.len() == n + 1
            && rod.state.velocities.len() == n + 1
            && rod.state.angular_velocities.len() == n
            && p.rest_lengths.len() == n
            && p.masses.len() == n + 1
            && p.inv_masses.len() == n + 1
            && p.inertias.len() == n
            && p.rest_darboux.len() == n.saturating_sub(1)
            && p.bend_twist_stiffness.len() == n.saturating_sub(1)
            && p.bend_damping.len() == n.saturating_sub(1)
            && p.stretch_stiffness.len() == n
            && p.parallel_stiffness.len() == n
            && p.stretch_damping.len() == n;
        if !ok {
            return Err(GpuError::InvalidInput(format!(
                "rod {r}: state and parameter arrays do not match its {n} elements"
            )));
        }
        if rod.rod_contact.is_none() && rods.iter().any(|r| r.rod_contact.is_some()) {
            // The kernel with rod contact gives every rod its part in the group's arrays.
            return Err(GpuError::InvalidInput(format!(
                "rod {r} has no rod contact while others have: on the GPU every rod touches the others or none does"
            )));
        }
        if let (Some(c), Some(first)) = (
            &rod.rod_contact,
            rods.iter().find_map(|r| r.rod_contact.as_ref()),
        ) {
            if c != first {
                return Err(GpuError::InvalidInput(format!(
                    "rod {r}: rod contact settings differ from the rods' before it; every rod that touches rods has the same ones"
                )));
            }
            let ok = |x: f32| x.is_finite() && x >= 0.0;
            if !(ok(c.static_friction)
                && ok(c.kinetic_friction)
                && ok(c.margin)
                && rod.params.radius.is_finite()
                && rod.params.radius > 0.0)
            {
                return Err(GpuError::InvalidInput(format!(
                    "rod {r}: rod contact needs finite friction and margin >= 0 and a radius > 0"
                )));
            }
        }
        if let (Some(w), Some(first)) = (&rod.wall, rods.iter().find_map(|r| r.wall.as_ref())) {
            if !std::sync::Arc::ptr_eq(&w.collider, &first.collider) {
                return Err(GpuError::InvalidInput(format!(
                    "rod {r} touches another mesh than the rods before it; the GPU backend uploads one mesh per simulation"
                )));
            }
            let ok = |x: f32| x.is_finite() && x >= 0.0;
            let valid = ok(w.static_friction)
                && ok(w.kinetic_friction)
                && ok(w.margin)
                && rod.params.radius.is_finite()
                && rod.params.radius > 0.0;
            if !valid {
                return Err(GpuError::InvalidInput(format!(
                    "rod {r}: wall contact needs a radius > 0 and finite friction and margin >= 0 (radius {}, friction {} / {}, margin {})",
                    rod.params.radius, w.static_friction, w.kinetic_friction, w.margin
                )));
            }
        }
        if let Some(l) = rod.loads.iter().find(|l| l.point > n) {
            return Err(GpuError::InvalidInput(format!(
                "rod {r}: load on point {} of {}",
                l.point,
                n + 1
            )));
        }
    }
    Ok(())
}

/// A wall triangle as the `u32` words of its WGSL twin `WallTri` (`shaders/wall_contact.wgsl`).
fn wall_words(t: &cosserat_collide::GpuWallTriangle) -> [u32; 40] {
    let mut w = [0u32; 40];
    let f = |x: f32| x.to_bits();
    for k in 0..3 {
        w[k] = f(t.a[k]);
        w[4 + k] = f(t.b[k]);
        w[8 + k] = f(t.c[k]);
    }
    w[3] = t.boundary;
    w[7] = t.index;
    w[11] = t.pad;
    let rows = std::iter::once(&t.normal)
        .chain(&t.edge_normals)
        .chain(&t.vertex_normals);
    for (i, row) in rows.enumerate() {
        for k in 0..4 {
            w[12 + 4 * i + k] = f(row[k]);
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::first_step_at;

    #[test]
    fn step_windows_match_the_cpu_clock() {
        let dt = 2e-5f32 as f64;
        for t in [0.0, 1e-5, 2e-5, 0.1, 0.123456, 1.0] {
            let s = first_step_at(t, dt);
            assert!(s as f64 * dt >= t, "{t}: step {s}");
            assert!(
                s == 0 || ((s - 1) as f64 * dt) < t,
                "{t}: step {s} is not the first"
            );
        }
        assert_eq!(first_step_at(f64::INFINITY, dt), u32::MAX);
    }
}
