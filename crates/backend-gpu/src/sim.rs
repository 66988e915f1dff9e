//! [`GpuSimulation`]: device setup, upload, kernel-path selection, batched stepping and
//! double-buffered readback.
//!
//! Everything the kernels read is uploaded once in [`GpuSimulation::new`]. A batch
//! ([`GpuSimulation::step`]) then writes only a 32-byte parameter block (its first step index)
//! and, when the caller changed them, the prescribed end motions; positions travel back only
//! when asked ([`GpuSimulation::request_positions`] / [`GpuSimulation::read_positions`]),
//! through one of two staging buffers so that a haptic loop can submit the next batch before it
//! reads the previous result.

use crate::shader::KernelConfig;
use crate::{
    DivergedQuantity, Divergence, GpuError, GpuOptions, GpuRodInput, KernelPath, KernelVariant,
    PrescribedMotion, SolverSettings,
};
use bytemuck::{Pod, Zeroable};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ParamsU {
    gravity: [f32; 4],
    lo2: f32,
    hi2: f32,
    base_step: u32,
    num_items: u32,
    epoch0: u32,
    pad: [u32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct SlotG {
    a: [f32; 4],
    b: [f32; 4],
    c: [f32; 4],
    d: [f32; 4],
    e: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct ItemG {
    rod: u32,
    base: u32,
    n: u32,
    flags: u32,
    w0: u32,
    w1: u32,
    o0: u32,
    o1: u32,
    left: u32,
    right: u32,
    drag: f32,
    pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct DriveG {
    v: [f32; 4],
    w: [f32; 4],
    /// Steps `[window[0], window[1])` of the motion; `window[2]`: the step `origin` is before.
    window: [u32; 4],
    /// Position of the held point before step `window[2]` (see [`EndTrack`]).
    origin: [f32; 4],
}

/// The path of a held end point, tracked in `f64` on the host: its position before step
/// `reference`. The kernel places the point at `origin + (steps moved) h v` rather than
/// integrating it in `f32`, and a new motion starts from the tracked position, so rounding does
/// not accumulate over a long push (the CPU backend's `HeldPath` does the same).
#[derive(Clone, Copy, Debug, Default)]
struct EndTrack {
    origin: [f64; 3],
    reference: u64,
}

const NONE: u32 = u32::MAX;
/// Dispatches one submission can address in the chunk table.
const TABLE_CAPACITY: u32 = 1024;
/// Loop iterations lavapipe runs per invocation before it silently stops all loops (GPU.md),
/// with a margin.
const SOFTWARE_LOOP_BUDGET: u32 = 40_000;

/// What the backend learned about its adapter.
#[derive(Clone, Debug, PartialEq)]
pub struct AdapterSummary {
    /// Adapter name as the driver reports it (e.g. "NVIDIA H100 80GB HBM3", "llvmpipe (…)").
    pub name: String,
    /// Driver name and version info.
    pub driver: String,
    /// PCI vendor id.
    pub vendor: u32,
    /// Whether this is a software (CPU) adapter such as lavapipe.
    pub software: bool,
    /// Whether GPU timestamps can be recorded.
    pub timestamps: bool,
    /// Workgroups known to be co-resident, when known.
    pub co_resident_workgroups: Option<u32>,
    /// Largest workgroup memory in bytes.
    pub max_workgroup_storage: u32,
    /// The subgroup size, when the adapter has subgroup operations and one fixed size (the
    /// subgroup layout for short rods needs both).
    pub subgroup_size: Option<u32>,
    /// Whether storage buffers can be declared `@coherent` (the multi-workgroup halo exchange
    /// then moves vec4s through one instead of single words through atomics).
    pub coherent: bool,
}

/// The plan a simulation runs: path, kernel shape and the work items (one per workgroup).
#[derive(Clone, Debug)]
struct Plan {
    path: KernelPath,
    cfg: KernelConfig,
    items: Vec<ItemG>,
    /// Workgroups per dispatch (the items, or fewer with several rods per workgroup).
    workgroups: u32,
    steps_per_dispatch: u32,
}

struct StateBuffers {
    pos: wgpu::Buffer,
    vel: wgpu::Buffer,
    frm: wgpu::Buffer,
    omg: wgpu::Buffer,
}

/// A device buffer a blocking read copies from.
#[derive(Clone, Copy, Debug)]
enum Part {
    Positions,
    Velocities,
    Frames,
    AngularVelocities,
    Status,
}

struct Pending {
    staging: usize,
    submission: wgpu::SubmissionIndex,
    /// Set by the map callback.
    mapped: Arc<AtomicBool>,
}

/// A field of a rod's state on the device, for [`GpuSimulation::write_rod_field`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GpuField {
    /// Centreline points.
    Positions,
    /// Point velocities.
    Velocities,
    /// Frames as `[x, y, z, w]`.
    Frames,
    /// Frame angular velocities (body coordinates).
    AngularVelocities,
}

/// The state of a [`GpuSimulation`] at one step ([`GpuSimulation::snapshot`]).
#[derive(Clone, Debug)]
pub struct GpuSnapshot {
    state: Vec<u8>,
    steps: u64,
    drives: Vec<DriveG>,
    tracks: Vec<EndTrack>,
}

/// Rods stepped on the GPU. See the crate docs for the kernel paths.
pub struct GpuSimulation {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: AdapterSummary,
    plan: Plan,
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
    states: Vec<StateBuffers>,
    current: usize,
    status_buf: wgpu::Buffer,
    sync_buf: Option<wgpu::Buffer>,
    drives_buf: wgpu::Buffer,
    drives: Vec<DriveG>,
    /// One per entry of `drives`.
    tracks: Vec<EndTrack>,
    drives_dirty: bool,
    rods: Vec<(u32, u32)>,
    slots: u64,
    staging: [wgpu::Buffer; 2],
    /// Staging buffer of blocking reads ([`Self::check`], [`Self::read_state`]), made on first
    /// use and kept.
    read_staging: Option<wgpu::Buffer>,
    pending: VecDeque<Pending>,
    settings: SolverSettings<f32>,
    steps: u64,
    query: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    gpu_time_pending: Vec<wgpu::Buffer>,
    timestamp_period_ns: f64,
    error: Arc<Mutex<Option<String>>>,
    spin_wait: Duration,
}

fn round_up(x: u32, m: u32) -> u32 {
    x.div_ceil(m) * m
}

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

fn known_co_residency(info: &wgpu::AdapterInfo) -> Option<u32> {
    // One workgroup per SM is far below what was measured co-resident (8 per SM of 256 threads
    // on the H100, GPU.md) and leaves room for the kernel's registers and workgroup memory.
    let name = info.name.to_ascii_uppercase();
    if info.vendor != 0x10de {
        return None;
    }
    if name.contains("H100") && name.contains("PCIE") {
        Some(114)
    } else if name.contains("H100") || name.contains("H200") || name.contains("GH200") {
        Some(132)
    } else {
        None
    }
}

impl GpuSimulation {
    /// Uploads `rods` and prepares the kernel.
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
        Self::with_variant(rods, settings, options, KernelVariant::default())
    }

    /// [`Self::new`] with a kernel variant; for the benchmark's side-by-side measurements.
    #[doc(hidden)]
    pub fn with_variant(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
        variant: KernelVariant,
    ) -> Result<Self, GpuError> {
        validate(&rods, settings)?;
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let features = adapter.features();
        let limits = adapter.limits();
        let want_ts = options.timestamps && features.contains(wgpu::Features::TIMESTAMP_QUERY);
        let has_subgroups = features.contains(wgpu::Features::SUBGROUP);
        let has_coherent = features.contains(wgpu::Features::MEMORY_DECORATION_COHERENT);
        let mut required_features = wgpu::Features::empty();
        if want_ts {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        if has_subgroups {
            required_features |= wgpu::Features::SUBGROUP;
        }
        if has_coherent {
            required_features |= wgpu::Features::MEMORY_DECORATION_COHERENT;
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("cosserat-backend-gpu"),
            required_features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(format!("adapter `{}` gave no device: {e}", info.name)))?;
        let error = Arc::new(Mutex::new(None::<String>));
        {
            let error = error.clone();
            device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                let mut slot = error.lock().unwrap_or_else(|p| p.into_inner());
                slot.get_or_insert_with(|| e.to_string());
            }));
        }
        let software = info.device_type == wgpu::DeviceType::Cpu
            || info.name.to_ascii_lowercase().contains("llvmpipe");
        let adapter_summary = AdapterSummary {
            name: info.name.clone(),
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_string(),
            vendor: info.vendor,
            software,
            timestamps: want_ts,
            co_resident_workgroups: options.co_resident_workgroups.or(if software {
                None
            } else {
                known_co_residency(&info)
            }),
            max_workgroup_storage: limits.max_compute_workgroup_storage_size,
            // The layout puts one rod on SG consecutive invocations and relies on them forming
            // one subgroup, so the size must be fixed (NVIDIA: 32, lavapipe: 8).
            subgroup_size: (has_subgroups
                && info.subgroup_min_size == info.subgroup_max_size
                && info.subgroup_min_size >= 4)
                .then_some(info.subgroup_min_size),
            coherent: has_coherent,
        };

        let plan = make_plan(
            &rods,
            settings,
            &options,
            &variant,
            &adapter_summary,
            &limits,
        )?;
        let spin_wait = Duration::from_micros(options.spin_wait_us as u64);
        Self::build(
            device,
            queue,
            adapter_summary,
            plan,
            rods,
            settings,
            want_ts,
            error,
            &limits,
            spin_wait,
        )
    }

    #[allow(clippy::too_many_lines)]
    fn build(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter: AdapterSummary,
        plan: Plan,
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        want_ts: bool,
        error: Arc<Mutex<Option<String>>>,
        limits: &wgpu::Limits,
        spin_wait: Duration,
    ) -> Result<Self, GpuError> {
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
        let has_loads = plan.cfg.flags.contains(&"LOADS");
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
        let table_stride = (limits.min_uniform_buffer_offset_alignment as u64).max(16);
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
                wgpu::BufferUsages::STORAGE,
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
                        size: wgpu::BufferSize::new(16),
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

        let staging_size = 16 * slots_n as u64 + 16 * n_items as u64;
        let mk_staging = |label| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: staging_size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let staging = [mk_staging("readback 0"), mk_staging("readback 1")];
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
        let timestamp_period_ns = queue.get_timestamp_period() as f64;
        if let Some(e) = error.lock().unwrap_or_else(|p| p.into_inner()).take() {
            return Err(GpuError::Wgpu(e));
        }
        Ok(Self {
            device,
            queue,
            adapter,
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
            sync_buf,
            drives_buf,
            drives,
            tracks,
            drives_dirty: false,
            rods: rod_layout,
            slots: slots_n as u64,
            staging,
            read_staging: None,
            pending: VecDeque::new(),
            settings: *settings,
            steps: 0,
            query,
            gpu_time_pending: Vec::new(),
            timestamp_period_ns,
            error,
            spin_wait,
        })
    }

    /// The adapter in use.
    pub fn adapter(&self) -> &AdapterSummary {
        &self.adapter
    }

    /// The kernel path in use (never [`KernelPath::Auto`]).
    pub fn path(&self) -> KernelPath {
        self.plan.path
    }

    /// A one-line description of the kernel: path, threads, points per thread, workgroups, halo,
    /// steps per dispatch and the compiled-in terms.
    pub fn kernel_description(&self) -> String {
        let c = &self.plan.cfg;
        let layout = if c.flags.contains(&"SUBGROUP") {
            format!(
                " ({} rods/workgroup, one per subgroup of {})",
                c.threads / c.group,
                c.group
            )
        } else {
            String::new()
        };
        format!(
            "{} kernel: {} workgroups x {} threads{layout} x {} points/thread{}, halo {}{}, <= {} steps/dispatch, terms [{}]",
            self.plan.path,
            self.plan.workgroups,
            c.threads,
            c.per_thread,
            if c.unroll { "" } else { " (loops)" },
            c.halo,
            if c.exchange_steps > 1 {
                format!(" (exchange every {} steps)", c.exchange_steps)
            } else {
                String::new()
            },
            self.plan.steps_per_dispatch,
            c.flags.join(", ")
        )
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

    fn take_wgpu_error(&self) -> Result<(), GpuError> {
        match self.error.lock().unwrap_or_else(|p| p.into_inner()).take() {
            Some(e) => Err(GpuError::Wgpu(e)),
            None => Ok(()),
        }
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
        self.take_wgpu_error()?;
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
            self.queue
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
                    table[at..at + 4].copy_from_slice(&off.to_le_bytes());
                    table[at + 4..at + 8].copy_from_slice(&count.to_le_bytes());
                    table[at + 8..at + 12].copy_from_slice(&exchanges.to_le_bytes());
                    exchanges += (count - 1) / xs;
                }
                self.queue.write_buffer(&self.table_buf, 0, &table);
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
                pad: [0; 3],
            };
            self.epochs += self.table_exchanges;
            self.queue
                .write_buffer(&self.params_buf, 0, bytemuck::bytes_of(&params));
            let mut enc = self
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
                let read = self.device.create_buffer(&wgpu::BufferDescriptor {
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
                let submission = self.queue.submit([enc.finish()]);
                self.map_readback(slot, submission);
            } else {
                self.queue.submit([enc.finish()]);
            }
            self.steps += this as u64;
            remaining -= this as u64;
        }
        Ok(())
    }

    /// Starts copying the current positions (and the divergence status) into a staging buffer
    /// without waiting. At most two requests may be outstanding; [`Self::read_positions`]
    /// returns the oldest.
    pub fn request_positions(&mut self) -> Result<(), GpuError> {
        let slot = self.readback_slot()?;
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        self.encode_readback(&mut enc, slot);
        let submission = self.queue.submit([enc.finish()]);
        self.map_readback(slot, submission);
        Ok(())
    }

    /// The staging buffer the next position request uses.
    fn readback_slot(&self) -> Result<usize, GpuError> {
        if self.pending.len() >= 2 {
            return Err(GpuError::InvalidInput(
                "two position reads are already pending; read one first".into(),
            ));
        }
        Ok(match self.pending.front() {
            Some(p) => 1 - p.staging,
            None => 0,
        })
    }

    fn encode_readback(&self, enc: &mut wgpu::CommandEncoder, slot: usize) {
        let staging = &self.staging[slot];
        let pos_bytes = 16 * self.slots;
        enc.copy_buffer_to_buffer(&self.states[self.current].pos, 0, staging, 0, pos_bytes);
        enc.copy_buffer_to_buffer(
            &self.status_buf,
            0,
            staging,
            pos_bytes,
            16 * self.plan.items.len() as u64,
        );
    }

    fn map_readback(&mut self, slot: usize, submission: wgpu::SubmissionIndex) {
        let mapped = Arc::new(AtomicBool::new(false));
        let flag = mapped.clone();
        self.staging[slot].map_async(wgpu::MapMode::Read, .., move |_| {
            flag.store(true, AtomicOrdering::Release);
        });
        self.pending.push_back(Pending {
            staging: slot,
            submission,
            mapped,
        });
    }

    /// Waits until `mapped` is set by its map callback: first by polling the device in a busy
    /// loop for up to [`GpuOptions::spin_wait_us`], then blocking on `submission`.
    fn wait_mapped(
        &self,
        submission: wgpu::SubmissionIndex,
        mapped: &AtomicBool,
    ) -> Result<(), GpuError> {
        if !self.spin_wait.is_zero() {
            let start = Instant::now();
            loop {
                self.device
                    .poll(wgpu::PollType::Poll)
                    .map_err(|e| GpuError::Wgpu(format!("polling the GPU: {e}")))?;
                if mapped.load(AtomicOrdering::Acquire) {
                    return self.take_wgpu_error();
                }
                if start.elapsed() >= self.spin_wait {
                    break;
                }
                std::hint::spin_loop();
            }
        }
        self.wait(submission)
    }

    fn wait(&self, submission: wgpu::SubmissionIndex) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: Some(Duration::from_secs(120)),
            })
            .map_err(|e| GpuError::Wgpu(format!("waiting for the GPU: {e}")))?;
        self.take_wgpu_error()
    }

    /// Positions of every rod (`n + 1` points each) as of the oldest pending
    /// [`Self::request_positions`], or as of now when none is pending (blocking).
    ///
    /// Fails with [`GpuError::Diverged`] naming rod, element and step if a rod diverged, and with
    /// [`GpuError::GridTimeout`] if a grid barrier timed out.
    pub fn read_positions(&mut self) -> Result<Vec<Vec<[f32; 3]>>, GpuError> {
        if self.pending.is_empty() {
            self.request_positions()?;
        }
        let Some(p) = self.pending.pop_front() else {
            unreachable!("a request was just made")
        };
        self.wait_mapped(p.submission, &p.mapped)?;
        let staging = &self.staging[p.staging];
        let (positions, status) = {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| GpuError::Wgpu(format!("mapping the readback: {e}")))?;
            let floats: &[f32] = bytemuck::cast_slice(&view[..(16 * self.slots) as usize]);
            let status: Vec<u32> =
                bytemuck::cast_slice(&view[(16 * self.slots) as usize..]).to_vec();
            let positions = self
                .rods
                .iter()
                .map(|&(base, n)| {
                    (0..=n as usize)
                        .map(|i| {
                            let o = 4 * (base as usize + i);
                            [floats[o], floats[o + 1], floats[o + 2]]
                        })
                        .collect()
                })
                .collect();
            (positions, status)
        };
        staging.unmap();
        self.status_error(&status)?;
        Ok(positions)
    }

    fn status_error(&self, status: &[u32]) -> Result<(), GpuError> {
        let mut first: Option<Divergence> = None;
        for (i, w) in status.chunks_exact(4).enumerate() {
            if w[0] & 0x100 != 0 {
                return Err(GpuError::GridTimeout);
            }
            let code = w[0] & 0xff;
            if code == 0 {
                continue;
            }
            let value = f32::from_bits(w[3]) as f64;
            let quantity = match code {
                1 => DivergedQuantity::NonFiniteFrame,
                2 => DivergedQuantity::NonFinitePosition,
                _ => DivergedQuantity::Strain((value.sqrt() - 1.0).abs()),
            };
            let d = Divergence {
                rod: self.plan.items[i].rod as usize,
                element: w[1] as usize,
                step: w[2] as u64,
                quantity,
            };
            if first.is_none_or(|f| (d.step, d.rod, d.element) < (f.step, f.rod, f.element)) {
                first = Some(d);
            }
        }
        match first {
            Some(d) => Err(GpuError::Diverged(d)),
            None => Ok(()),
        }
    }

    /// Waits for all submitted work and reports divergence or a grid timeout, if any.
    pub fn check(&mut self) -> Result<(), GpuError> {
        let size = 16 * self.plan.items.len() as u64;
        let status = self.read_buffers(&[(Part::Status, size)])?;
        self.status_error(bytemuck::cast_slice(&status))
    }

    /// Copies `parts` (each from offset 0) one after another into the read staging buffer in one
    /// submission, waits for it, and returns the bytes: one round trip whatever the number of
    /// parts.
    fn read_buffers(&mut self, parts: &[(Part, u64)]) -> Result<Vec<u8>, GpuError> {
        let total: u64 = parts.iter().map(|p| p.1).sum();
        if self.read_staging.as_ref().is_none_or(|b| b.size() < total) {
            self.read_staging = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("read"),
                size: total,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let Some(staging) = self.read_staging.as_ref() else {
            unreachable!("made above")
        };
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("read"),
            });
        let st = &self.states[self.current];
        let mut offset = 0;
        for &(part, size) in parts {
            let source = match part {
                Part::Positions => &st.pos,
                Part::Velocities => &st.vel,
                Part::Frames => &st.frm,
                Part::AngularVelocities => &st.omg,
                Part::Status => &self.status_buf,
            };
            enc.copy_buffer_to_buffer(source, 0, staging, offset, size);
            offset += size;
        }
        let submission = self.queue.submit([enc.finish()]);
        let mapped = Arc::new(AtomicBool::new(false));
        let flag = mapped.clone();
        staging.map_async(wgpu::MapMode::Read, ..total, move |_| {
            flag.store(true, AtomicOrdering::Release);
        });
        self.wait_mapped(submission, &mapped)?;
        let bytes = staging
            .get_mapped_range(..total)
            .map_err(|e| GpuError::Wgpu(format!("mapping a readback: {e}")))?
            .to_vec();
        staging.unmap();
        Ok(bytes)
    }

    /// The full state of every rod (blocking, one round trip). Fails like
    /// [`Self::read_positions`].
    pub fn read_state(&mut self) -> Result<Vec<cosserat_model::RodState<f32>>, GpuError> {
        use cosserat_model::{Quat, RodState, Vec3};
        let bytes = 16 * self.slots;
        let status_bytes = 16 * self.plan.items.len() as u64;
        let all = self.read_buffers(&[
            (Part::Positions, bytes),
            (Part::Velocities, bytes),
            (Part::Frames, bytes),
            (Part::AngularVelocities, bytes),
            (Part::Status, status_bytes),
        ])?;
        let b = bytes as usize;
        self.status_error(bytemuck::cast_slice(&all[4 * b..]))?;
        let floats: &[f32] = bytemuck::cast_slice(&all[..4 * b]);
        let quarter = b / 4;
        let (p, v, q, w) = (
            &floats[..quarter],
            &floats[quarter..2 * quarter],
            &floats[2 * quarter..3 * quarter],
            &floats[3 * quarter..],
        );
        let v3 = |a: &[f32], i: usize| Vec3::new(a[4 * i], a[4 * i + 1], a[4 * i + 2]);
        Ok(self
            .rods
            .iter()
            .map(|&(base, n)| {
                let (b, n) = (base as usize, n as usize);
                RodState {
                    positions: (0..=n).map(|i| v3(p, b + i)).collect(),
                    velocities: (0..=n).map(|i| v3(v, b + i)).collect(),
                    frames: (0..n)
                        .map(|i| {
                            let o = 4 * (b + i);
                            Quat::new(q[o + 3], q[o], q[o + 1], q[o + 2])
                        })
                        .collect(),
                    angular_velocities: (0..n).map(|i| v3(w, b + i)).collect(),
                }
            })
            .collect())
    }

    /// The whole device state (points, frames, their velocities, the status words) and the
    /// host's bookkeeping of held ends, for [`Self::restore`] (blocking, one round trip).
    pub fn snapshot(&mut self) -> Result<GpuSnapshot, GpuError> {
        self.ensure_idle()?;
        let bytes = 16 * self.slots;
        let status_bytes = 16 * self.plan.items.len() as u64;
        let state = self.read_buffers(&[
            (Part::Positions, bytes),
            (Part::Velocities, bytes),
            (Part::Frames, bytes),
            (Part::AngularVelocities, bytes),
            (Part::Status, status_bytes),
        ])?;
        Ok(GpuSnapshot {
            state,
            steps: self.steps,
            drives: self.drives.clone(),
            tracks: self.tracks.clone(),
        })
    }

    /// Returns to a snapshot of this simulation: the next steps are, bit for bit, those that
    /// followed it.
    pub fn restore(&mut self, snapshot: &GpuSnapshot) -> Result<(), GpuError> {
        self.ensure_idle()?;
        let bytes = (16 * self.slots) as usize;
        let status_bytes = 16 * self.plan.items.len();
        if snapshot.state.len() != 4 * bytes + status_bytes
            || snapshot.drives.len() != self.drives.len()
        {
            return Err(GpuError::InvalidInput(
                "the snapshot was taken of other rods".into(),
            ));
        }
        let st = &self.states[self.current];
        for (k, buf) in [&st.pos, &st.vel, &st.frm, &st.omg].into_iter().enumerate() {
            self.queue
                .write_buffer(buf, 0, &snapshot.state[k * bytes..(k + 1) * bytes]);
        }
        self.queue
            .write_buffer(&self.status_buf, 0, &snapshot.state[4 * bytes..]);
        self.steps = snapshot.steps;
        self.drives.clone_from(&snapshot.drives);
        self.tracks.clone_from(&snapshot.tracks);
        self.drives_dirty = true;
        self.queue.submit([]);
        self.take_wgpu_error()
    }

    /// Overwrites one field of rod `rod` (`xyz` of each of its points or frames; frames as
    /// `[x, y, z, w]`), keeping whatever else the device stores beside them.
    pub fn write_rod_field(
        &mut self,
        rod: usize,
        field: GpuField,
        values: &[[f32; 4]],
    ) -> Result<(), GpuError> {
        self.ensure_idle()?;
        let Some(&(base, n)) = self.rods.get(rod) else {
            return Err(GpuError::InvalidInput(format!("no rod {rod}")));
        };
        let (base, n) = (base as usize, n as usize);
        let (part, count, width) = match field {
            GpuField::Positions => (Part::Positions, n + 1, 3),
            GpuField::Velocities => (Part::Velocities, n + 1, 3),
            GpuField::Frames => (Part::Frames, n, 4),
            GpuField::AngularVelocities => (Part::AngularVelocities, n, 3),
        };
        if values.len() != count {
            return Err(GpuError::InvalidInput(format!(
                "rod {rod}: expected {count} entries, got {}",
                values.len()
            )));
        }
        let bytes = self.read_buffers(&[(part, 16 * self.slots)])?;
        let mut words: Vec<[f32; 4]> = bytemuck::cast_slice(&bytes).to_vec();
        for (w, v) in words[base..base + count].iter_mut().zip(values) {
            w[..width].copy_from_slice(&v[..width]);
        }
        let st = &self.states[self.current];
        let buf = match part {
            Part::Positions => &st.pos,
            Part::Velocities => &st.vel,
            Part::Frames => &st.frm,
            _ => &st.omg,
        };
        self.queue.write_buffer(
            buf,
            16 * base as u64,
            bytemuck::cast_slice(&words[base..base + count]),
        );
        if field == GpuField::Positions {
            // A held end starts its path again from where it was put.
            for end in 0..2 {
                let i = 2 * rod + end;
                let p = words[base + if end == 0 { 0 } else { n }];
                self.tracks[i] = EndTrack {
                    origin: [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])],
                    reference: self.steps,
                };
                let mut d = self.drives[i];
                d.window[2] = self.steps as u32;
                d.origin = [p[0], p[1], p[2], 0.0];
                self.drives[i] = d;
            }
            self.drives_dirty = true;
        }
        self.queue.submit([]);
        self.take_wgpu_error()
    }

    /// Refuses to change the state while a position readback is in flight.
    fn ensure_idle(&self) -> Result<(), GpuError> {
        if self.pending.is_empty() {
            Ok(())
        } else {
            Err(GpuError::InvalidInput(
                "read the requested positions before changing or saving the state".into(),
            ))
        }
    }

    /// GPU time in seconds of all batches submitted since the last call, from timestamp queries
    /// (blocking); `None` when timestamps were not requested or the adapter lacks them.
    pub fn take_gpu_time(&mut self) -> Result<Option<f64>, GpuError> {
        if self.query.is_none() {
            return Ok(None);
        }
        let pending = std::mem::take(&mut self.gpu_time_pending);
        for b in &pending {
            b.map_async(wgpu::MapMode::Read, .., |_| {});
        }
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(Duration::from_secs(120)),
            })
            .map_err(|e| GpuError::Wgpu(format!("waiting for the GPU: {e}")))?;
        let mut total = 0.0;
        for b in &pending {
            {
                let view = b
                    .get_mapped_range(..)
                    .map_err(|e| GpuError::Wgpu(format!("mapping timestamps: {e}")))?;
                let t: &[u64] = bytemuck::cast_slice(&view);
                total += t[1].saturating_sub(t[0]) as f64 * self.timestamp_period_ns * 1e-9;
            }
            b.unmap();
        }
        self.take_wgpu_error()?;
        Ok(Some(total))
    }
}

fn validate(rods: &[GpuRodInput], settings: &SolverSettings<f32>) -> Result<(), GpuError> {
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

fn make_plan(
    rods: &[GpuRodInput],
    settings: &SolverSettings<f32>,
    options: &GpuOptions,
    variant: &KernelVariant,
    adapter: &AdapterSummary,
    limits: &wgpu::Limits,
) -> Result<Plan, GpuError> {
    let extensible = settings.extensible;
    let mut flags: Vec<&'static str> = Vec::new();
    if extensible {
        flags.push("EXTENSIBLE");
        if rods
            .iter()
            .any(|r| r.params.stretch_damping.iter().any(|&c| c > 0.0))
        {
            flags.push("STRETCH_DAMP");
        }
    }
    let bend_damp = rods
        .iter()
        .any(|r| r.params.bend_damping.iter().any(|&c| c > 0.0));
    if bend_damp {
        flags.push("BEND_DAMP");
    }
    if rods.iter().any(|r| r.params.drag != 0.0) {
        flags.push("DRAG");
    }
    if rods.iter().any(|r| !r.loads.is_empty()) {
        flags.push("LOADS");
    }
    let iterations = if extensible {
        0
    } else {
        settings.iterations as u32
    };
    // Workgroup memory per thread: r, q (2 vec4 each), ω with bend damping, 4 for velocities.
    let needs_v = !extensible || flags.contains(&"STRETCH_DAMP");
    let per_thread_bytes = 16 * (4 + if bend_damp { 2 } else { 0 } + if needs_v { 4 } else { 0 });
    let storage_cap = limits.max_compute_workgroup_storage_size.saturating_sub(64);
    let mut max_threads = options
        .max_threads
        .min(limits.max_compute_invocations_per_workgroup)
        .min(limits.max_compute_workgroup_size_x)
        .min(1024);
    while max_threads > 32 && max_threads * per_thread_bytes > storage_cap {
        max_threads -= 32;
    }
    let max_threads = (max_threads / 32 * 32).max(32);
    let points = rods
        .iter()
        .map(|r| r.state.elements() as u32 + 1)
        .max()
        .unwrap_or(2);
    let single_threads = max_threads.min(round_up(points.div_ceil(2), 32));
    let single_ept = round_up(points.div_ceil(single_threads), 2).max(2);
    // The subgroup layout: every rod on one subgroup, a few rods per workgroup, no barriers.
    let subgroup = adapter
        .subgroup_size
        .filter(|_| variant.subgroups && rods.len() as u32 >= variant.subgroup_min_rods)
        .map(|sg| (sg, round_up(points.div_ceil(sg), 2).max(2)))
        .filter(|&(_, ept)| ept <= variant.subgroup_points_per_thread.max(2));
    // Windows of the two multi-workgroup paths. Information travels `2 · iterations + 1` points
    // per step (forces 1, each half-sweep 1), so a window whose halo is wider than that times
    // the steps between exchanges computes its owned points exactly as the whole rod would.
    let reach = 2 * iterations + 1;
    let halo_for = |xs: u32| round_up(xs * reach + 3, 2);
    // Shuffle windows are one subgroup wide (NVIDIA 32, lavapipe 8).
    let shuffle_sg = adapter
        .subgroup_size
        .filter(|&sg| variant.shuffle_windows && sg <= max_threads);
    let multi_threads = match shuffle_sg {
        Some(sg) => sg,
        None => (max_threads.min(variant.multi_threads) / 32 * 32).max(32),
    };
    // (points per thread, halo, owned points per window) for `xs` steps between exchanges.
    let multi_shape = |xs: u32| -> (u32, u32, u32) {
        let halo = halo_for(xs);
        let ept = if variant.multi_points_per_thread > 0 {
            round_up(variant.multi_points_per_thread, 2)
        } else {
            (1..=8)
                .map(|k| 2 * k)
                .find(|&e| multi_threads * e >= 2 * halo + halo.max(64))
                .unwrap_or(16)
        };
        let chunk = (multi_threads * ept).saturating_sub(2 * halo) / 2 * 2;
        (ept, halo, chunk)
    };
    let windows_for = |chunk: u32| -> u32 {
        rods.iter()
            .map(|r| (r.state.elements() as u32 + 1).div_ceil(chunk.max(1)))
            .sum()
    };
    let co = adapter.co_resident_workgroups;
    // Steps between exchanges: as asked, fewer where the windows would own nothing or (grid)
    // would not all be co-resident.
    let want_xs = variant.exchange_steps.max(1);
    let xs_fitting = |need_co: bool| -> Option<u32> {
        (1..=want_xs).rev().find(|&xs| {
            // Each halo comes from the direct neighbour, so a window owns at least one halo.
            let (_, halo, chunk) = multi_shape(xs);
            chunk >= halo.max(2) && (!need_co || co.is_some_and(|c| windows_for(chunk) <= c))
        })
    };
    let xs_grid = xs_fitting(true);
    let xs_perstep = xs_fitting(false).unwrap_or(1);

    let multi_items = |chunk: u32, halo: u32| -> Vec<ItemG> {
        let mut items = Vec::new();
        let mut base = 0u32;
        for (r, rod) in rods.iter().enumerate() {
            let n = rod.state.elements() as u32;
            let flags = item_flags(rod);
            let first = items.len() as u32;
            let count = (n + 1).div_ceil(chunk);
            for c in 0..count {
                let o0 = c * chunk;
                let o1 = ((c + 1) * chunk).min(n + 1);
                items.push(ItemG {
                    rod: r as u32,
                    base,
                    n,
                    flags,
                    w0: o0.saturating_sub(halo),
                    w1: (o1 + halo).min(n + 1),
                    o0,
                    o1,
                    left: if c > 0 { first + c - 1 } else { NONE },
                    right: if c + 1 < count { first + c + 1 } else { NONE },
                    drag: rod.params.drag,
                    pad: 0,
                });
            }
            base += n + 1;
        }
        items
    };
    let grid_ok = match (co, xs_grid) {
        (None, _) => Err(format!(
            "co-residency of workgroups cannot be established on `{}`",
            adapter.name
        )),
        (Some(c), None) => {
            let (_, _, chunk) = multi_shape(1);
            Err(format!(
                "{} workgroups needed, at most {c} known to be co-resident",
                windows_for(chunk)
            ))
        }
        (Some(_), Some(_)) => Ok(()),
    };
    let path = match options.path {
        KernelPath::Auto => {
            // One workgroup while each thread holds at most two points (up to 512 elements
            // with 256 threads); beyond that, windows over several co-resident workgroups
            // where the adapter allows them (H200, 1000 elements: 5.5 µs/step against 6.6 for
            // one workgroup with four points per thread).
            if single_ept <= 2 || subgroup.is_some() {
                KernelPath::SingleWorkgroup
            } else if grid_ok.is_ok() {
                KernelPath::MultiWorkgroup
            } else if single_ept <= 16 {
                KernelPath::SingleWorkgroup
            } else {
                KernelPath::DispatchPerStep
            }
        }
        p => p,
    };
    if path == KernelPath::SingleWorkgroup && single_ept > 64 {
        return Err(GpuError::PathUnavailable {
            path,
            reason: format!(
                "a rod of {points} points needs {single_ept} points per thread in one workgroup (at most 64)"
            ),
        });
    }
    if path == KernelPath::MultiWorkgroup
        && let Err(reason) = grid_ok
    {
        return Err(GpuError::PathUnavailable { path, reason });
    }
    let mut group = 1;
    let mut workgroups = None;
    let mut xs_used = 1;
    let (threads, ept, items, halo_used) = match path {
        KernelPath::SingleWorkgroup => {
            let mut base = 0u32;
            let items = rods
                .iter()
                .enumerate()
                .map(|(r, rod)| {
                    let n = rod.state.elements() as u32;
                    let it = ItemG {
                        rod: r as u32,
                        base,
                        n,
                        flags: item_flags(rod),
                        w0: 0,
                        w1: n + 1,
                        o0: 0,
                        o1: n + 1,
                        left: NONE,
                        right: NONE,
                        drag: rod.params.drag,
                        pad: 0,
                    };
                    base += n + 1;
                    it
                })
                .collect::<Vec<_>>();
            match subgroup {
                Some((sg, ept)) => {
                    let cap = limits.max_compute_invocations_per_workgroup.min(1024) / sg;
                    let per_wg = variant.rods_per_workgroup.clamp(1, cap.max(1));
                    flags.push("SUBGROUP");
                    group = sg;
                    workgroups = Some((items.len() as u32).div_ceil(per_wg));
                    (sg * per_wg, ept, items, 0)
                }
                None => (single_threads, single_ept, items, 0),
            }
        }
        _ => {
            let xs = if path == KernelPath::MultiWorkgroup {
                xs_grid.unwrap_or(1)
            } else {
                xs_perstep
            };
            let (ept, halo, chunk) = multi_shape(xs);
            if chunk < halo.max(2) {
                return Err(GpuError::PathUnavailable {
                    path,
                    reason: format!(
                        "windows of {multi_threads} threads x {ept} points leave nothing inside a halo of {halo}"
                    ),
                });
            }
            xs_used = xs;
            (multi_threads, ept, multi_items(chunk, halo), halo)
        }
    };
    if path == KernelPath::MultiWorkgroup {
        flags.push("GRID");
        if variant.neighbour_sync {
            flags.push("NBR_SYNC");
        }
        if variant.coherent_exchange && adapter.coherent {
            flags.push("COHERENT");
        }
    }
    if path == KernelPath::DispatchPerStep {
        flags.push("PERSTEP");
    }
    if flags.contains(&"SUBGROUP")
        || (path != KernelPath::SingleWorkgroup && shuffle_sg == Some(threads))
    {
        flags.push("SHFL");
    }
    if variant.sweep_loads && !extensible {
        flags.push("SWEEP_LOADS");
    }
    if variant.rsqrt && !extensible {
        flags.push("RSQRT");
    }
    if variant.fast_impulse && !extensible && !variant.sweep_loads {
        flags.push("FAST");
    }
    if variant.register_constants {
        flags.push("REGC");
    }
    let cfg = KernelConfig {
        threads,
        per_thread: ept,
        iterations,
        halo: halo_used,
        exchange_steps: xs_used,
        spin_cap: options.spin_cap.max(1),
        group,
        unroll: variant.unroll,
        flags,
    };
    // Loop iterations per step and invocation, generously counted, for software adapters.
    let loops_per_step = 8 * ept
        + 16
        + iterations * (ept + 6)
        + if path == KernelPath::MultiWorkgroup {
            4 * ept + 64
        } else {
            0
        };
    let mut spd = options.max_steps_per_dispatch.max(1);
    if adapter.software {
        spd = spd.min((SOFTWARE_LOOP_BUDGET / loops_per_step).max(1));
    }
    Ok(Plan {
        path,
        cfg,
        workgroups: workgroups.unwrap_or(items.len() as u32),
        items,
        steps_per_dispatch: spd,
    })
}

fn item_flags(rod: &GpuRodInput) -> u32 {
    let mut f = 0;
    if rod.ends[0].holds_point() {
        f |= 1;
    }
    if rod.ends[0].holds_frame() {
        f |= 2;
    }
    if rod.ends[1].holds_point() {
        f |= 4;
    }
    if rod.ends[1].holds_frame() {
        f |= 8;
    }
    f
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
