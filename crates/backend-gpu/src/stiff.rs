//! The stiff scheme on the GPU: whole steps of the CPU's stiff solve (backend-cpu `stiff`,
//! `docs/stiff-solver.md`), many rods and many steps per dispatch (`shaders/stiff_step.wgsl`).
//!
//! **Why this shape.** The stiff scheme spends its step in a banded direct solve along each rod.
//! Measured on an H100/H200 (`docs/benchmarks/stiff-gpu.md`), a solve whose blocks go to and from
//! global memory between dependent phases is bound by latency: a single rod took longer on the
//! GPU than on one CPU core. What was fast was the partitioned solve, one rod per workgroup, each
//! invocation eliminating its own slice of elements (`banded_partitioned.wgsl`). This kernel puts
//! the rest of the step around that solve in the same workgroup: each invocation owns the same
//! slice of elements, points and frames for the prediction, the constraint evaluation, the
//! preconditioner, the right-hand side, the assembly of its block rows, the update and the
//! velocities, so a whole step (and many steps) runs without the host: one dispatch per batch of
//! steps, the workgroup's barriers between the passes. The passes are the CPU's, formula for
//! formula, in `f64`; the CPU's stiff stepper is the oracle (`tests/stiff_gpu.rs` at the
//! repository root).
//!
//! **What it runs**: the direct solve with its refactorisation policies, implicit Euler, the
//! geometric bound of the frames, internal damping, drag, gravity and constant point loads,
//! free, pinned and clamped ends driven by their prescribed motions (constant velocities,
//! timed moves, keyframed paths: the host evaluates each held end's velocities over each step, as
//! the CPU does, and uploads them with the batch), the divergence test, and contact with one
//! static triangle mesh shared by all rods ([`GpuStiffSimulation::with_wall`]; the CPU's stiff
//! contacts, `shaders/stiff_contact.wgsl`: points pinned on the wall inside the solve, creases,
//! element contacts at ridges, swept tests, Coulomb friction, rounds of the solve; queries
//! answered from near lists of triangles kept per point and element, `shaders/stiff_wall.wgsl`),
//! compiled only into the kernels of simulations that have a mesh, and the introducer guide
//! ([`GpuStiffRod::guide`]). **What it leaves out** (refused by
//! [`GpuStiffSimulation::new`] or by the stepper's capabilities): several obstacles,
//! analytic shapes and moving ones, friction per triangle, contact rows, bindings, rod contact,
//! sliding and hinged ends, varying loads and moments, BDF2, the
//! Gauss–Seidel variant; and, of the CPU's safety nets, the retake of an unconverged inextensible
//! step with the axial compliance and the retake of a diverged step in halves: an unconverged step
//! is counted (`StiffReport::unconverged_steps`) and a diverged one stops the rod with its
//! element and step.

use crate::device::Gpu;
use crate::{GpuError, GpuOptions};
use cosserat_collide::MeshCollider;
use cosserat_model::{Quat, RodParams, RodState, Vec3};
use cosserat_problem::{
    CollisionStats, DivergedQuantity, Divergence, EndCondition, Integrator, Refactor,
    SolverSettings, StiffReport, StiffScheme, StiffSettings, stiff_compliance, stiff_damped_row,
};
use std::sync::Arc;

/// One rod for the GPU's stiff scheme: the pieces `cosserat_backend_cpu::CpuRod::new` takes, in
/// `f64` (the stiff scheme's state is kept in `f64`).
#[derive(Clone, Debug)]
pub struct GpuStiffRod {
    /// Initial state.
    pub state: RodState<f64>,
    /// Parameters (inverse masses of held end points are zeroed here, as on the CPU).
    pub params: RodParams<f64>,
    /// Conditions at the first and last end.
    pub ends: [EndCondition<f64>; 2],
    /// Constant point forces: `(point, force)`.
    pub loads: Vec<(usize, [f64; 3])>,
    /// The straight introducer the rod is fed through, if any: the points it holds move along
    /// its axis only (the CPU's `contact::pin_guided`).
    pub guide: Option<crate::GpuGuide>,
}

/// A static triangle mesh the rods of a [`GpuStiffSimulation`] touch (one for all rods: a vessel
/// the copies of a batch share), with its Coulomb friction and speculative margin
/// (`MeshContactSettings` of the CPU).
#[derive(Clone, Debug)]
pub struct GpuStiffWall {
    /// The mesh and its tree.
    pub collider: Arc<MeshCollider>,
    /// Coulomb coefficient while a point holds.
    pub static_friction: f64,
    /// Coulomb coefficient while a point slides.
    pub kinetic_friction: f64,
    /// Speculative margin [m].
    pub margin: f64,
}

/// Invocations per rod: the partitioned solve's default (64), fewer for short rods and, in large
/// batches, where fewer pad a rod less (`slice_threads`).
const THREADS: u32 = crate::banded::PARTITIONED_THREADS;

/// Steps per dispatch on a hardware adapter (the held ends' motions of a batch are uploaded per
/// step), and on a software one, which stops a shader's loops after 65 535 iterations in all.
const STEPS_PER_DISPATCH: u64 = 64;
const STEPS_PER_DISPATCH_SOFTWARE: u64 = 1;

/// Numbers per held-end motion entry (v, 0, ω, 0).
const MOTION: usize = 8;

/// The offsets of the columns of one rod's block in a buffer, and the block's length.
#[derive(Clone, Debug, Default)]
struct Columns {
    named: Vec<(&'static str, usize)>,
    len: usize,
}

impl Columns {
    fn add(&mut self, name: &'static str, len: usize) -> usize {
        let at = self.len;
        self.named.push((name, at));
        self.len += len;
        at
    }

    fn at(&self, name: &str) -> usize {
        self.named
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, a)| *a)
            .unwrap_or_else(|| panic!("no column {name}"))
    }

    fn wgsl(&self, stride: &str) -> String {
        let mut s: String = self
            .named
            .iter()
            .map(|(n, a)| format!("const {n}: u32 = {a}u;\n"))
            .collect();
        s.push_str(&format!("const {stride}: u32 = {}u;\n", self.len));
        s
    }
}

/// Where everything of a rod sits: `np` element slots (the invocations' slices), `np + 1` points.
#[derive(Clone, Debug)]
struct StiffLayout {
    threads: usize,
    per_thread: usize,
    kc: Columns,
    st: Columns,
    wk: Columns,
}

/// Numbers of the per-rod scalars in `kc` (`K_ROD`): elements, drag rate, damped, whether each
/// end holds its point, clamps, the masses of the two end points, then 12 per clamp; then the
/// rod's radius (number 32, for its contacts), then its guide (33: whether it has one, 34 the
/// origin, 37 the unit axis, 40 the length, 41 the clearance).
const ROD_SCALARS: usize = 44;
/// Numbers per point of the contact state (`CSS` of `stiff_contact.wgsl`).
const CONTACT_STATE: usize = 56;
/// Words of the near lists of a point and of the element starting at it (`near` of
/// `stiff_wall.wgsl`: two lists of `NEAR_WORDS`).
const NEAR_LISTS: usize = 64;
/// Numbers of the per-rod report (`rep`): the counters (`ST_*` of the kernel), then per end the
/// raw and the filtered reaction (`RE`, `RE_END`), then the largest filtered force (`RE_MAX`).
const REPORT: usize = 48;
/// Where the reactions start in a rod's report, and numbers per end.
const RE: usize = 16;
const RE_END: usize = 12;
const RE_MAX: usize = 40;

impl StiffLayout {
    fn new(threads: usize, per_thread: usize) -> Self {
        let np = threads * per_thread;
        let npt = np + 1;
        let mut kc = Columns::default();
        kc.add("K_IM", npt);
        kc.add("K_IL", np);
        kc.add("K_ILB", np);
        kc.add("K_LB", np);
        kc.add("K_RU", 3 * np);
        kc.add("K_IN", 3 * np);
        kc.add("K_IIO", 3 * np);
        kc.add("K_FREE", np);
        kc.add("K_AG", 3 * np);
        kc.add("K_AO", 3 * np);
        kc.add("K_DG", 3 * np);
        kc.add("K_DO", 3 * np);
        kc.add("K_F", 3 * npt);
        kc.add("K_ROD", ROD_SCALARS);
        let mut st = Columns::default();
        st.add("S_X", 3 * npt);
        st.add("S_V", 3 * npt);
        st.add("S_Q", 4 * np);
        st.add("S_OMEGA", 3 * np);
        st.add("S_CLAMP", 8);
        st.add("S_X_PRED", 3 * npt);
        let mut wk = Columns::default();
        wk.add("W_X_OLD", 3 * npt);
        wk.add("W_V_START", 3 * npt);
        wk.add("W_UX", 3 * npt);
        wk.add("W_Q_OLD", 4 * np);
        wk.add("W_Q_PRED", 4 * np);
        for name in [
            "W_UTH",
            "W_DTHETA",
            "W_INV_K",
            "W_GAMMA",
            "W_D0",
            "W_D1",
            "W_D2",
            "W_OMEGA_C",
            "W_LAM_G",
            "W_LAM_O",
            "W_LAMP_G",
            "W_LAMP_O",
            "W_COLD_G",
            "W_COLD_O",
        ] {
            wk.add(name, 3 * np);
        }
        wk.add("W_REL", 4 * np);
        wk.add("W_CLAMP_W", 18);
        wk.add("W_CLAMP_K", 6);
        wk.add("W_CLAMP_FRAME", 8);
        wk.add("W_CLAMP_START", 6);
        Self {
            threads,
            per_thread,
            kc,
            st,
            wk,
        }
    }

    fn slots(&self) -> usize {
        self.threads * self.per_thread
    }

    /// Where number `c` of entry `j` of a column of `width` numbers per entry sits in it
    /// (`at_entry` of the kernel): coalesced over the invocations' slices.
    fn at_entry(&self, j: usize, c: usize, width: usize) -> usize {
        let np = self.slots();
        if j >= np {
            return width * np + c;
        }
        (c * self.per_thread + j % self.per_thread) * self.threads + j / self.per_thread
    }

    /// Puts `v` at entry `j` of the column at `col` of `block`.
    fn put(&self, block: &mut [f64], col: usize, j: usize, v: &[f64]) {
        for (c, x) in v.iter().enumerate() {
            block[col + self.at_entry(j, c, v.len())] = *x;
        }
    }

    /// Entry `j` of the column at `col` of `block`, `N` numbers.
    fn get<const N: usize>(&self, block: &[f64], col: usize, j: usize) -> [f64; N] {
        std::array::from_fn(|c| block[col + self.at_entry(j, c, N)])
    }

    /// The kernel's text, with the contacts' passes (`mesh`) and the guide's (`guide`).
    fn source(&self, mesh: bool, guide: bool) -> String {
        let head = format!(
            "const PT: u32 = {}u;\nconst EPT: u32 = {}u;\nconst XCH: u32 = {}u;\nconst NP: u32 = {}u;\nconst NPT: u32 = {}u;\n{}{}{}",
            self.threads,
            self.per_thread,
            crate::banded::partitioned_xch(self.threads as u32),
            self.slots(),
            self.slots() + 1,
            self.kc.wgsl("KS"),
            self.st.wgsl("SS"),
            self.wk.wgsl("WS"),
        ) + &format!("const RS: u32 = {REPORT}u;\n");
        let mut flags = Vec::new();
        if mesh {
            flags.push("MESH");
        }
        if guide {
            flags.push("GUIDE");
        }
        if mesh || guide {
            flags.push("PINS");
        }
        let contact = if mesh || guide {
            format!(
                "{}\n{}",
                crate::shader::STIFF_WALL_WGSL,
                crate::shader::STIFF_CONTACT_WGSL
            )
        } else {
            String::new()
        };
        format!(
            "{head}\n{}\n{contact}\n{}\n{}",
            crate::shader::preprocess(crate::shader::STIFF_STEP_WGSL, &flags),
            crate::shader::CHOLESKY_WGSL,
            crate::shader::BANDED_PARTITIONED_WGSL
        )
        .replace("REAL", "f64")
    }
}

/// Rods stepped by the stiff scheme on the GPU.
pub struct GpuStiffSimulation {
    gpu: Gpu,
    layout: StiffLayout,
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    shape: wgpu::Buffer,
    glob: wgpu::Buffer,
    kc: wgpu::Buffer,
    st: wgpu::Buffer,
    wk: wgpu::Buffer,
    motion: wgpu::Buffer,
    rows: wgpu::Buffer,
    rep: wgpu::Buffer,
    staging: wgpu::Buffer,
    rep_staging: wgpu::Buffer,
    /// The contact state of every point (`cs`), with a mesh or a guide.
    contact: Option<wgpu::Buffer>,
    /// The near lists of every point and element (`near`), with a mesh.
    near: Option<wgpu::Buffer>,
    wall: Option<GpuStiffWall>,
    /// Whether the kernel pins guided points (built with a rod that has a guide).
    guided: bool,
    rods: Vec<GpuStiffRod>,
    /// The held ends' motions of a batch, kept between batches (no allocation per batch).
    motion_scratch: Vec<f64>,
    /// Every rod's report as last read back (`REPORT` numbers each).
    reports: Vec<[f64; REPORT]>,
    settings: SolverSettings<f64>,
    stiff: StiffSettings,
    /// The cut-off of the reactions' low-pass filter [Hz].
    reaction_cutoff_hz: f64,
    steps_per_dispatch: u64,
    /// Steps taken.
    step: u64,
}

/// A [`GpuStiffSimulation`]'s whole state, to return to ([`GpuStiffSimulation::restore`]): copies
/// of its buffers on the device (the state, the working values with the multipliers the next step
/// starts from, the factorisation's rows, the report, the contact state and near lists) and what
/// the host keeps.
pub struct GpuStiffSnapshot {
    buffers: [wgpu::Buffer; 4],
    contact: Option<wgpu::Buffer>,
    near: Option<wgpu::Buffer>,
    rods: Vec<GpuStiffRod>,
    reports: Vec<[f64; REPORT]>,
    step: u64,
}

/// A slice of `f64` as bytes.
fn bytes(v: &[f64]) -> &[u8] {
    bytemuck::cast_slice(v)
}

impl GpuStiffSimulation {
    /// Uploads `rods` (any lengths; every rod gets as many element slots as the longest) with
    /// the solver settings `settings` (its `dt`, gravity, mode and divergence strain) and the
    /// stiff scheme's `stiff`, on a device of its own.
    pub fn new(
        rods: Vec<GpuStiffRod>,
        settings: &SolverSettings<f64>,
        stiff: &StiffSettings,
        options: &GpuOptions,
    ) -> Result<Self, GpuError> {
        Self::with_wall(rods, settings, stiff, options, None)
    }

    /// [`new`](Self::new) with the rods in contact with `wall`, as the CPU's stiff contacts
    /// (`shaders/stiff_contact.wgsl` says what differs). Without one, no contact code is
    /// compiled.
    pub fn with_wall(
        rods: Vec<GpuStiffRod>,
        settings: &SolverSettings<f64>,
        stiff: &StiffSettings,
        options: &GpuOptions,
        wall: Option<GpuStiffWall>,
    ) -> Result<Self, GpuError> {
        let mut rods = rods;
        if let Some(w) = &wall {
            check_wall(w, stiff)?;
        }
        check_input(&mut rods, stiff)?;
        let gpu = Gpu::acquire(options)?;
        if !gpu.device.features().contains(wgpu::Features::SHADER_F64) {
            return Err(GpuError::NoAdapter(format!(
                "adapter `{}` has no double-precision shaders (SHADER_F64), which the stiff \
                 scheme needs",
                gpu.adapter.name
            )));
        }
        let longest = rods.iter().map(|r| r.state.elements()).max().unwrap_or(1);
        let storage = gpu.limits.max_compute_workgroup_storage_size as usize;
        let invocations = gpu
            .limits
            .max_compute_invocations_per_workgroup
            .min(gpu.limits.max_compute_workgroup_size_x);
        let mut threads = slice_threads(longest, rods.len(), options.max_threads);
        // The exchange of the banded solve and this kernel's reduction (8 bytes per invocation).
        let need = |t: u32| {
            crate::banded::partitioned_workgroup_bytes(crate::banded::Precision::F64, t)
                + 8 * t as usize
                + 16
        };
        while threads > 1 && (threads > invocations || need(threads) > storage) {
            threads /= 2;
        }
        let per_thread = longest.div_ceil(threads as usize);
        let most = crate::banded::partitioned_max_slice(crate::banded::Precision::F64);
        if per_thread > most {
            return Err(GpuError::InvalidInput(format!(
                "a rod of {longest} elements needs {per_thread} elements in each of the {threads} \
                 invocations of the GPU's stiff scheme, and at most {most} fit an invocation's \
                 private arrays in f64: rods of up to {} elements run there (use fewer elements \
                 or --backend cpu)",
                most * threads as usize
            )));
        }
        let layout = StiffLayout::new(threads as usize, per_thread);
        let device = &gpu.device;
        let n_rods = rods.len();
        let buffer = |label: &str, len: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (len as u64 * 8).max(16),
                usage,
                mapped_at_creation: false,
            })
        };
        let storage_usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let copy_out = storage_usage | wgpu::BufferUsages::COPY_SRC;
        let slots = layout.slots();
        let rows = buffer("stiff rows", n_rods * slots * 48, copy_out);
        let x = buffer("stiff rhs", n_rods * slots * 6, wgpu::BufferUsages::STORAGE);
        let glob = buffer("stiff globals", 16, storage_usage);
        let kc = buffer("stiff constants", n_rods * layout.kc.len, storage_usage);
        let st = buffer("stiff state", n_rods * layout.st.len, copy_out);
        let wk = buffer("stiff work", n_rods * layout.wk.len, copy_out);
        let steps_per_dispatch = if gpu.adapter.software {
            STEPS_PER_DISPATCH_SOFTWARE
        } else {
            STEPS_PER_DISPATCH
        };
        let motion = buffer(
            "stiff end motions",
            steps_per_dispatch as usize * n_rods * 2 * MOTION,
            storage_usage,
        );
        let staging = buffer(
            "stiff state staging",
            n_rods * layout.st.len,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let rep = buffer("stiff report", n_rods * REPORT, copy_out);
        let rep_staging = buffer(
            "stiff report staging",
            n_rods * REPORT,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let init = |label: &str, contents: &[u8]| {
            wgpu::util::DeviceExt::create_buffer_init(
                device,
                &wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents,
                    usage: wgpu::BufferUsages::STORAGE,
                },
            )
        };
        // The mesh (tree and f64 triangles), and the points' pins and contact state.
        let mesh = wall.as_ref().map(|w| {
            let nodes = w.collider.bvh().node_words();
            let tris = w.collider.wall_triangles_f64();
            (
                init("stiff wall nodes", bytemuck::cast_slice(&nodes)),
                init("stiff wall triangles", bytes(&tris)),
            )
        });
        let guided = rods.iter().any(|r| r.guide.is_some());
        let contact = (wall.is_some() || guided).then(|| {
            buffer(
                "stiff contact state",
                n_rods * (slots + 1) * CONTACT_STATE,
                copy_out,
            )
        });
        // Four bytes a word: half the `f64` count the helper sizes by.
        let near = wall.is_some().then(|| {
            buffer(
                "stiff near lists",
                (n_rods * (slots + 1) * NEAR_LISTS).div_ceil(2),
                copy_out,
            )
        });
        let shape = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("stiff shape"),
            size: 32,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("stiff_step.wgsl"),
            source: wgpu::ShaderSource::Wgsl(layout.source(wall.is_some(), guided).into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("stiff_step"),
            layout: None,
            module: &module,
            entry_point: Some("stiff_step"),
            compilation_options: Default::default(),
            cache: None,
        });
        let mut bound = vec![
            (0, &shape),
            (1, &rows),
            (3, &x),
            (4, &glob),
            (5, &kc),
            (6, &st),
            (7, &wk),
            (8, &motion),
            (9, &rep),
        ];
        if let Some((nodes, tris)) = &mesh {
            bound.extend([(10, nodes), (11, tris)]);
        }
        if let Some(state) = &contact {
            bound.push((12, state));
        }
        if let Some(lists) = &near {
            bound.push((13, lists));
        }
        let entries: Vec<_> = bound
            .into_iter()
            .map(|(binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect();
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("stiff_step"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Wgpu(format!("compiling the stiff step: {e}")));
        }
        let mut sim = Self {
            gpu,
            layout,
            pipeline,
            group,
            shape,
            glob,
            kc,
            st,
            wk,
            motion,
            rows,
            rep,
            staging,
            rep_staging,
            contact,
            near,
            wall,
            guided,
            rods,
            motion_scratch: Vec::new(),
            reports: vec![[0.0; REPORT]; n_rods],
            settings: *settings,
            stiff: *stiff,
            reaction_cutoff_hz: cosserat_problem::report::DEFAULT_CUTOFF_HZ,
            steps_per_dispatch,
            step: 0,
        };
        for rod in 0..n_rods {
            // No step above the tolerance yet.
            sim.reports[rod][5] = -1.0;
            sim.upload_rod(rod)?;
        }
        Ok(sim)
    }

    /// Invocations per rod and elements per invocation.
    pub fn partition(&self) -> (usize, usize) {
        (self.layout.threads, self.layout.per_thread)
    }

    /// The adapter.
    pub fn adapter(&self) -> &crate::AdapterSummary {
        &self.gpu.adapter
    }

    /// Rods.
    pub fn rods(&self) -> usize {
        self.rods.len()
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// The rod as given (its state as last uploaded or read back).
    pub fn rod(&self, rod: usize) -> &GpuStiffRod {
        &self.rods[rod]
    }

    /// Uploads rod `rod`'s constants and state (from `self.rods[rod]`) and clears its work,
    /// counters and factorisation.
    fn upload_rod(&mut self, rod: usize) -> Result<(), GpuError> {
        let h = self.settings.dt;
        let kc = constants(
            &self.rods[rod],
            &self.layout,
            h,
            self.settings.extensible,
            self.stiff.inertia_floor,
        );
        let st = state_block(&self.rods[rod].state, &self.layout);
        let q = &self.gpu.queue;
        q.write_buffer(&self.kc, (rod * self.layout.kc.len * 8) as u64, bytes(&kc));
        q.write_buffer(&self.st, (rod * self.layout.st.len * 8) as u64, bytes(&st));
        // The previous step's multipliers of the first step are zero.
        let wk = vec![0.0; self.layout.wk.len];
        q.write_buffer(&self.wk, (rod * self.layout.wk.len * 8) as u64, bytes(&wk));
        // The counters and reactions go on; the factorisation and any divergence are
        // forgotten.
        if let Some(c) = &self.contact {
            // A written state starts free of contacts (the CPU's `StiffContacts::reset`).
            let len = (self.layout.slots() + 1) * CONTACT_STATE;
            q.write_buffer(c, (rod * len * 8) as u64, bytes(&vec![0.0; len]));
        }
        let report = &mut self.reports[rod];
        report[6..11].fill(0.0);
        q.write_buffer(&self.rep, (rod * REPORT * 8) as u64, bytes(&report[..]));
        Ok(())
    }

    /// Sets the cut-off of the reactions' low-pass filter [Hz] (`reaction_filter_weights`;
    /// not finite or not positive: no filter).
    pub fn set_reaction_cutoff(&mut self, hz: f64) {
        self.reaction_cutoff_hz = hz;
    }

    /// The filtered reaction at end `end` of rod `rod` after the last step (the holder's force
    /// and torque on the rod, world frame), `None` for an end that holds nothing.
    pub fn end_reaction(&self, rod: usize, end: usize) -> Option<cosserat_problem::EndReaction> {
        let r = self.rods.get(rod)?;
        if end > 1 || !r.ends[end].holds_point() {
            return None;
        }
        let b = RE + RE_END * end + 6;
        let rep = &self.reports[rod];
        Some(cosserat_problem::EndReaction {
            force: [rep[b], rep[b + 1], rep[b + 2]],
            torque: [rep[b + 3], rep[b + 4], rep[b + 5]],
        })
    }

    /// The largest filtered reaction force of any held end so far [N], `None` without one.
    pub fn max_reaction_force(&self) -> Option<f64> {
        self.rods
            .iter()
            .zip(&self.reports)
            .filter(|(r, _)| r.ends.iter().any(EndCondition::holds_point))
            .map(|(_, rep)| rep[RE_MAX])
            .reduce(f64::max)
    }

    /// Replaces rod `rod`'s state (its constants stay; a clamp keeps the clamp frame the state
    /// carries) and forgets its factorisation and any divergence.
    pub fn write_state(&mut self, rod: usize, state: RodState<f64>) -> Result<(), GpuError> {
        self.check_rod(rod)?;
        self.rods[rod].state = state;
        self.upload_rod(rod)
    }

    /// Replaces rod `rod` whole (its ends, parameters, loads and state: what a change of how an
    /// end is held or of the loads changes), keeping its counters and forgetting its
    /// factorisation and any divergence.
    pub fn replace_rod(&mut self, rod: usize, new: GpuStiffRod) -> Result<(), GpuError> {
        self.check_rod(rod)?;
        if new.state.elements() != self.rods[rod].state.elements() {
            return Err(GpuError::InvalidInput(format!(
                "rod {rod} has {} elements; a replacement must have as many",
                self.rods[rod].state.elements()
            )));
        }
        if new.guide.is_some() && !self.guided {
            return Err(GpuError::InvalidInput(format!(
                "rod {rod}: a guide given to a simulation built without guides"
            )));
        }
        let mut one = vec![new];
        check_input(&mut one, &self.stiff)?;
        self.rods[rod] = one.pop().expect("one rod");
        self.upload_rod(rod)
    }

    /// Replaces the condition at end `end` of rod `rod` by one held the same way (a new motion:
    /// the host evaluates each step's velocities from it).
    pub fn set_end_motion(
        &mut self,
        rod: usize,
        end: usize,
        condition: EndCondition<f64>,
    ) -> Result<(), GpuError> {
        self.check_rod(rod)?;
        let old = &self.rods[rod].ends[end.min(1)];
        if old.kind != condition.kind {
            return Err(GpuError::InvalidInput(format!(
                "rod {rod}, end {end}: a new motion must hold the end as before ({:?}, not {:?}); \
                 replace the rod to change how it is held",
                old.kind, condition.kind
            )));
        }
        self.rods[rod].ends[end.min(1)] = condition;
        Ok(())
    }

    fn check_rod(&self, rod: usize) -> Result<(), GpuError> {
        if rod >= self.rods.len() {
            return Err(GpuError::InvalidInput(format!(
                "rod {rod}: the simulation has {} rods",
                self.rods.len()
            )));
        }
        Ok(())
    }

    /// Takes `steps` steps (in dispatches of many steps each) and waits for them. A rod that
    /// diverges stops at that step and is reported with its element and step; the others go on
    /// to the end of the batch.
    pub fn step(&mut self, steps: u64) -> Result<(), GpuError> {
        let mut left = steps;
        while left > 0 {
            let k = left.min(self.steps_per_dispatch);
            self.dispatch(k);
            left -= k;
        }
        self.gpu.wait_idle()?;
        self.check_divergence()
    }

    /// Submits `k` steps (without waiting).
    fn dispatch(&mut self, k: u64) {
        let h = self.settings.dt;
        let n_rods = self.rods.len();
        let mut motion = std::mem::take(&mut self.motion_scratch);
        motion.clear();
        motion.resize(k as usize * n_rods * 2 * MOTION, 0.0);
        for s in 0..k as usize {
            let t = (self.step + s as u64) as f64 * h;
            for (r, rod) in self.rods.iter().enumerate() {
                for (e, end) in rod.ends.iter().enumerate() {
                    if !(end.holds_point() || end.holds_frame()) {
                        continue;
                    }
                    let (v, w) = end.velocities_over(t, h);
                    let b = ((s * n_rods + r) * 2 + e) * MOTION;
                    motion[b..b + 3].copy_from_slice(&[v.x, v.y, v.z]);
                    motion[b + 4..b + 7].copy_from_slice(&[w.x, w.y, w.z]);
                }
            }
        }
        let q = &self.gpu.queue;
        q.write_buffer(&self.motion, 0, bytes(&motion));
        self.motion_scratch = motion;
        let refactor = match self.stiff.refactor {
            Refactor::EveryStep => 0u32,
            Refactor::EveryIteration => 1,
            Refactor::Lagged => 2,
        };
        let shape = [
            self.layout.per_thread as u32,
            self.layout.threads as u32,
            k as u32,
            self.stiff.iterations as u32,
            refactor,
            n_rods as u32,
            0,
            0,
        ];
        q.write_buffer(&self.shape, 0, bytemuck::cast_slice(&shape));
        let limit = self.settings.divergence_strain;
        let g = self.settings.gravity;
        let (keep, from_old, from_new) =
            cosserat_problem::report::reaction_filter_weights(self.reaction_cutoff_hz, h);
        let glob = [
            h,
            self.stiff.tolerance,
            self.stiff.geometric,
            g.x,
            g.y,
            g.z,
            (1.0 + limit).powi(2),
            (1.0 - limit).max(0.0).powi(2),
            self.step as f64,
            keep,
            from_old,
            from_new,
            self.wall.as_ref().map_or(0.0, |w| w.margin),
            self.wall.as_ref().map_or(0.0, |w| w.static_friction),
            self.wall.as_ref().map_or(0.0, |w| w.kinetic_friction),
        ];
        q.write_buffer(&self.glob, 0, bytes(&glob));
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.group, &[]);
            pass.dispatch_workgroups(n_rods as u32, 1, 1);
        }
        q.submit([encoder.finish()]);
        self.step += k;
    }

    /// Copies `src` (rod blocks of `len` numbers) through `staging` to the host.
    fn read_back(
        &self,
        src: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        len: usize,
    ) -> Result<Vec<f64>, GpuError> {
        let size = (self.rods.len() * len * 8) as u64;
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        encoder.copy_buffer_to_buffer(src, 0, staging, 0, size);
        self.gpu.queue.submit([encoder.finish()]);
        staging.map_async(wgpu::MapMode::Read, ..size, |_| {});
        self.gpu.wait_idle()?;
        let out = {
            let view = staging
                .get_mapped_range(..size)
                .map_err(|e| GpuError::Wgpu(format!("mapping the stiff state: {e}")))?;
            bytemuck::cast_slice::<u8, f64>(&view).to_vec()
        };
        staging.unmap();
        Ok(out)
    }

    /// Reads every rod's report (counters, reactions) back into `reports`.
    fn read_reports(&mut self) -> Result<(), GpuError> {
        let all = self.read_back(&self.rep, &self.rep_staging, REPORT)?;
        for (r, chunk) in self.reports.iter_mut().zip(all.chunks_exact(REPORT)) {
            r.copy_from_slice(chunk);
        }
        Ok(())
    }

    /// The first divergence of any rod (the earliest step, then the lowest rod).
    fn check_divergence(&mut self) -> Result<(), GpuError> {
        self.read_reports()?;
        let mut first: Option<Divergence> = None;
        for (rod, s) in self.reports.iter().enumerate() {
            let kind = s[9] as u32;
            if kind == 0 {
                continue;
            }
            let value = s[10];
            let quantity = match kind {
                1 => DivergedQuantity::NonFiniteFrame,
                4 => DivergedQuantity::NonFinitePosition,
                3 => DivergedQuantity::Unconverged(value),
                _ => DivergedQuantity::Strain((value - 1.0).abs()),
            };
            let d = Divergence {
                rod,
                element: s[8] as usize,
                step: s[7] as u64,
                quantity,
            };
            if first.as_ref().is_none_or(|f| d.step < f.step) {
                first = Some(d);
            }
        }
        first.map_or(Ok(()), |d| Err(GpuError::Diverged(d)))
    }

    /// The whole state, kept on the device ([`restore`](Self::restore) returns to it): stepping
    /// on from a restored snapshot repeats the steps that followed it bit for bit.
    pub fn snapshot(&self) -> GpuStiffSnapshot {
        let device = &self.gpu.device;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("stiff snapshot"),
        });
        let mut keep = |b: &wgpu::Buffer| {
            let copy = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("stiff snapshot"),
                size: b.size(),
                usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            encoder.copy_buffer_to_buffer(b, 0, &copy, 0, b.size());
            copy
        };
        let buffers = [&self.st, &self.wk, &self.rows, &self.rep].map(&mut keep);
        let contact = self.contact.as_ref().map(&mut keep);
        let near = self.near.as_ref().map(&mut keep);
        self.gpu.queue.submit([encoder.finish()]);
        GpuStiffSnapshot {
            buffers,
            contact,
            near,
            rods: self.rods.clone(),
            reports: self.reports.clone(),
            step: self.step,
        }
    }

    /// Returns to `snapshot` (taken from this simulation): state, multipliers, factorisation,
    /// counters and reactions, the rods' ends and loads, and the step count. The constants are
    /// uploaded again from the rods as they were then.
    pub fn restore(&mut self, snapshot: &GpuStiffSnapshot) -> Result<(), GpuError> {
        if snapshot.rods.len() != self.rods.len() {
            return Err(GpuError::InvalidInput(format!(
                "a snapshot of {} rods given to a simulation of {}",
                snapshot.rods.len(),
                self.rods.len()
            )));
        }
        self.rods.clone_from(&snapshot.rods);
        self.reports.clone_from(&snapshot.reports);
        self.step = snapshot.step;
        let h = self.settings.dt;
        for rod in 0..self.rods.len() {
            let kc = constants(
                &self.rods[rod],
                &self.layout,
                h,
                self.settings.extensible,
                self.stiff.inertia_floor,
            );
            self.gpu.queue.write_buffer(
                &self.kc,
                (rod * self.layout.kc.len * 8) as u64,
                bytes(&kc),
            );
        }
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("stiff restore"),
            });
        for (copy, b) in snapshot
            .buffers
            .iter()
            .zip([&self.st, &self.wk, &self.rows, &self.rep])
        {
            encoder.copy_buffer_to_buffer(copy, 0, b, 0, b.size());
        }
        if let (Some(copy), Some(b)) = (&snapshot.contact, &self.contact) {
            encoder.copy_buffer_to_buffer(copy, 0, b, 0, b.size());
        }
        if let (Some(copy), Some(b)) = (&snapshot.near, &self.near) {
            encoder.copy_buffer_to_buffer(copy, 0, b, 0, b.size());
        }
        self.gpu.queue.submit([encoder.finish()]);
        self.gpu.wait_idle()
    }

    /// The contacts' statistics of rod `rod` as last read back (`None` without a wall): the
    /// penetration and the points behind the wall from a detection at each step's end, the
    /// points pinned at the last step and the most so far, the swept tests' catches, the
    /// element contacts per detection, and in `queries` the walks of the tree (points' and
    /// elements' queries and sweeps their near lists could not answer).
    pub fn collision_stats(&self, rod: usize) -> Option<CollisionStats> {
        self.wall.as_ref()?;
        let s = self.reports.get(rod)?;
        Some(CollisionStats {
            max_penetration: s[13],
            escaped_points: s[14] as usize,
            contacts: s[11] as usize,
            max_contacts: s[12] as usize,
            steps: s[42] as u64,
            swept_catches: s[15] as u64,
            segment_contacts: s[41] as u64,
            queries: s[43] as u64,
            ..CollisionStats::default()
        })
    }

    /// The wall's contacts with rod `rod` at the end of the last step (reads the device): each
    /// point the wall held, its unit normal into the lumen and the wall's force on it over the
    /// step [N] (normal and friction), by point. Empty without a wall.
    #[allow(clippy::type_complexity)]
    pub fn wall_contacts(&self, rod: usize) -> Result<Vec<(usize, [f64; 3], [f64; 3])>, GpuError> {
        self.check_rod(rod)?;
        let (Some(state), Some(_)) = (&self.contact, &self.wall) else {
            return Ok(Vec::new());
        };
        let points = self.layout.slots() + 1;
        let len = (points * CONTACT_STATE * 8) as u64;
        let device = &self.gpu.device;
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("stiff contacts staging"),
            size: len,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        encoder.copy_buffer_to_buffer(state, rod as u64 * len, &staging, 0, len);
        self.gpu.queue.submit([encoder.finish()]);
        staging.map_async(wgpu::MapMode::Read, .., |_| {});
        self.gpu.wait_idle()?;
        let block: Vec<f64> = {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| GpuError::Wgpu(format!("mapping the contacts: {e}")))?;
            bytemuck::cast_slice::<u8, f64>(&view).to_vec()
        };
        let n = self.rods[rod].state.elements();
        // `C_LAST` (22) says how the point touched at the end of the last step; its normal (1)
        // and the wall's force (42).
        Ok((0..=n)
            .filter_map(|i| {
                let c = &block[i * CONTACT_STATE..(i + 1) * CONTACT_STATE];
                (c[22] != 0.0).then(|| (i, [c[1], c[2], c[3]], [c[42], c[43], c[44]]))
            })
            .collect())
    }

    /// Every rod's state as it is now (reads the device).
    pub fn read_state(&mut self) -> Result<Vec<RodState<f64>>, GpuError> {
        let all = self.read_back(&self.st, &self.staging, self.layout.st.len)?;
        let l = &self.layout.st;
        let (sx, sv, sq, so, sc) = (
            l.at("S_X"),
            l.at("S_V"),
            l.at("S_Q"),
            l.at("S_OMEGA"),
            l.at("S_CLAMP"),
        );
        let states: Vec<RodState<f64>> = self
            .rods
            .iter()
            .enumerate()
            .map(|(r, rod)| {
                let block = &all[r * l.len..(r + 1) * l.len];
                let n = rod.state.elements();
                let layout = &self.layout;
                let v3 = |col: usize, i: usize| {
                    let [x, y, z] = layout.get(block, col, i);
                    Vec3::new(x, y, z)
                };
                let q4 = |col: usize, i: usize| {
                    let [x, y, z, w] = layout.get(block, col, i);
                    Quat::new(w, x, y, z)
                };
                let clamp = |e: usize| {
                    let a = sc + 4 * e;
                    Quat::new(block[a + 3], block[a], block[a + 1], block[a + 2])
                };
                let mut s = rod.state.clone();
                s.positions = (0..=n).map(|i| v3(sx, i)).collect();
                s.velocities = (0..=n).map(|i| v3(sv, i)).collect();
                s.frames = (0..n).map(|j| q4(sq, j)).collect();
                s.angular_velocities = (0..n).map(|j| v3(so, j)).collect();
                s.clamp_frames = [clamp(0), clamp(1)];
                s
            })
            .collect();
        for (rod, s) in self.rods.iter_mut().zip(&states) {
            rod.state = s.clone();
        }
        Ok(states)
    }

    /// What the stiff solve did so far, per rod (`steps`: all of them kept; the GPU retakes
    /// no step, `halved_steps` and `axial_steps` stay zero).
    pub fn report(&self) -> Vec<StiffReport> {
        self.reports
            .iter()
            .map(|s| StiffReport {
                total_iterations: s[0] as u64,
                factorisations: s[1] as u64,
                unconverged_steps: s[2] as u64,
                max_residual: s[3],
                worst_step: s[4] as u64,
                last_unconverged_step: (s[5] >= 0.0).then_some(s[5] as u64),
                steps: self.step,
                max_tolerance: self.stiff.tolerance,
                ..StiffReport::default()
            })
            .collect()
    }
}

/// Batches of at least this many rods are sliced for the least work rather than the shortest
/// step (`slice_threads`). Measured on an H100 (`docs/benchmarks/stiff-gpu.md`, "Slices for
/// batches"): 32 slices of 96-element rods were 1.09× and 1.25× faster than 64 for 1 024 and
/// 4 096 rods, and 1.3× slower for 64 and 256.
const BATCH_RODS: usize = 512;

/// Invocations per rod for `rods` rods of up to `longest` elements: the partitioned solve's 64
/// (the shortest step of a rod), or, for batches of [`BATCH_RODS`] rods or more, 32 where that
/// pads the rod less (96 elements: 32 slices of 3 instead of 64 slices of 2, a third of them
/// padding), and only while a slice stays within what the solve's private arrays hold in `f64`
/// (16 elements); never more than the rod has elements or `max_threads` allows (a power of two;
/// the adapter's limits may lower it further).
fn slice_threads(longest: usize, rods: usize, max_threads: u32) -> u32 {
    let cap = THREADS
        .min((longest as u32).next_power_of_two())
        .min(max_threads.max(1));
    let cap = 1 << (31 - cap.leading_zeros());
    let padded = |t: u32| longest.div_ceil(t as usize) * t as usize;
    let fits = |t: u32| {
        longest.div_ceil(t as usize)
            <= crate::banded::partitioned_max_slice(crate::banded::Precision::F64)
    };
    if rods >= BATCH_RODS && cap > 32 && padded(cap / 2) < padded(cap) && fits(cap / 2) {
        cap / 2
    } else {
        cap
    }
}

/// The kernel's source for `threads` invocations per rod and `per_thread` elements each (shader
/// validation).
#[cfg(test)]
pub(crate) fn source_for(threads: usize, per_thread: usize, mesh: bool, guide: bool) -> String {
    StiffLayout::new(threads, per_thread).source(mesh, guide)
}

/// Refuses a wall the kernel's contacts do not run, naming what.
fn check_wall(w: &GpuStiffWall, stiff: &StiffSettings) -> Result<(), GpuError> {
    if stiff.contact_rows {
        return Err(GpuError::InvalidInput(
            "contact rows (solver.stiff.contact_rows = true) run on the CPU only".into(),
        ));
    }
    for (name, v) in [
        ("static friction", w.static_friction),
        ("kinetic friction", w.kinetic_friction),
        ("margin", w.margin),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(GpuError::InvalidInput(format!(
                "the wall's {name} is {v}; it must be finite and not negative"
            )));
        }
    }
    Ok(())
}

/// Refuses what the kernel does not run, naming it, and zeroes the inverse masses of held end
/// points (as `CpuRod::new`).
fn check_input(rods: &mut [GpuStiffRod], stiff: &StiffSettings) -> Result<(), GpuError> {
    if rods.is_empty() {
        return Err(GpuError::InvalidInput("no rods".into()));
    }
    if stiff.scheme != StiffScheme::Direct {
        return Err(GpuError::InvalidInput(
            "the stiff scheme on the GPU runs the direct solver only (scheme = \"direct\")".into(),
        ));
    }
    if stiff.integrator != Integrator::ImplicitEuler {
        return Err(GpuError::InvalidInput(
            "the stiff scheme on the GPU runs implicit Euler only (integrator = \"implicit-euler\"); BDF2 runs on the CPU".into(),
        ));
    }
    for (i, rod) in rods.iter_mut().enumerate() {
        let n = rod.state.elements();
        if n < 2 {
            return Err(GpuError::InvalidInput(format!(
                "rod {i} has {n} element(s); the stiff scheme on the GPU needs at least 2"
            )));
        }
        for (e, end) in rod.ends.iter().enumerate() {
            if end.slide_axis().is_some() || end.hinge_axis().is_some() {
                return Err(GpuError::InvalidInput(format!(
                    "rod {i}, end {e}: sliding and hinged ends run on the CPU only"
                )));
            }
            if end.holds_point() {
                rod.params.inv_masses[if e == 0 { 0 } else { n }] = 0.0;
            }
        }
        if let Some(g) = &rod.guide {
            let unit = (g.axis.iter().map(|a| a * a).sum::<f64>() - 1.0).abs() < 1e-9;
            let finite = g.origin.iter().chain(&g.axis).all(|x| x.is_finite());
            if !(unit && finite && g.length > 0.0 && g.clearance > 0.0) {
                return Err(GpuError::InvalidInput(format!(
                    "rod {i}: a guide at {:?} along {:?}, {} m long, clearance {} m (the axis must be a unit vector, the lengths positive)",
                    g.origin, g.axis, g.length, g.clearance
                )));
            }
        }
        for &(p, f) in &rod.loads {
            if p > n || f.iter().any(|x| !x.is_finite()) {
                return Err(GpuError::InvalidInput(format!(
                    "rod {i}: a load at point {p} of {} with force {f:?}",
                    n + 1
                )));
            }
        }
    }
    Ok(())
}

/// The constants of one rod (`kc`'s block), as the CPU's `Consts::rebuild`.
fn constants(rod: &GpuStiffRod, l: &StiffLayout, h: f64, extensible: bool, floor: f64) -> Vec<f64> {
    let p = &rod.params;
    let n = rod.state.elements();
    let np = l.slots();
    let c = &l.kc;
    let mut k = vec![0.0; c.len];
    let compliance = |stiffness: f64, len: f64| stiff_compliance(stiffness, len, h);
    let damp = |alpha: f64, beta: f64| stiff_damped_row(alpha, beta, h);
    let put3 = |k: &mut Vec<f64>, col: &str, j: usize, v: [f64; 3]| l.put(k, c.at(col), j, &v);
    let put1 = |k: &mut Vec<f64>, col: usize, j: usize, v: f64| l.put(k, col, j, &[v]);
    let (im, il, ilb, lb, free) = (
        c.at("K_IM"),
        c.at("K_IL"),
        c.at("K_ILB"),
        c.at("K_LB"),
        c.at("K_FREE"),
    );
    for (i, w) in p.inv_masses.iter().enumerate() {
        put1(&mut k, im, i, *w);
    }
    let clamped = |j: usize| {
        (j == 0 && rod.ends[0].holds_frame()) || (j == n - 1 && rod.ends[1].holds_frame())
    };
    let mut damped = false;
    for j in 0..np {
        if j >= n {
            put1(&mut k, il, j, 1.0);
            put1(&mut k, ilb, j, 1.0);
            put3(&mut k, "K_IN", j, [1.0; 3]);
            put3(&mut k, "K_IIO", j, [1.0; 3]);
            continue;
        }
        let l0 = p.rest_lengths[j];
        put1(&mut k, il, j, 1.0 / l0);
        let own = p.inertias[j];
        let r = p.radius;
        let bar = floor * own.x * 4.0 / (r * r) * l0 * l0 / 12.0;
        let inertia = [own.x.max(bar), own.y.max(bar), own.z.max(bar)];
        put3(&mut k, "K_IN", j, inertia);
        put3(&mut k, "K_IIO", j, inertia.map(|x| 1.0 / x));
        put1(&mut k, free, j, if clamped(j) { 0.0 } else { 1.0 });
        let kp = p.parallel_stiffness[j];
        let stretch = if extensible {
            compliance(p.stretch_stiffness[j], l0)
        } else {
            0.0
        };
        let beta = if extensible {
            p.stretch_damping[j] * l0
        } else {
            0.0
        };
        let (f, m) = damp(stretch, beta);
        damped |= f > 0.0;
        put3(
            &mut k,
            "K_AG",
            j,
            [compliance(kp, l0), compliance(kp, l0), m],
        );
        put3(&mut k, "K_DG", j, [0.0, 0.0, f]);
        if j + 1 < n {
            let lbar = p.node_length(j);
            put1(&mut k, lb, j, lbar);
            put1(&mut k, ilb, j, 1.0 / lbar);
            let u = p.rest_darboux[j];
            put3(&mut k, "K_RU", j, [u.x, u.y, u.z]);
            let s = p.bend_twist_stiffness[j];
            let beta = p.bend_damping[j] * lbar;
            let rows = [s.x, s.y, s.z].map(|s| damp(compliance(s, lbar), beta));
            damped |= rows.iter().any(|r| r.0 > 0.0);
            put3(&mut k, "K_AO", j, rows.map(|r| r.1));
            put3(&mut k, "K_DO", j, rows.map(|r| r.0));
        } else {
            put1(&mut k, ilb, j, 1.0);
        }
    }
    for &(point, f) in &rod.loads {
        let had: [f64; 3] = l.get(&k, c.at("K_F"), point);
        put3(&mut k, "K_F", point, [0, 1, 2].map(|i| had[i] + f[i]));
    }
    let s = c.at("K_ROD");
    k[s] = n as f64;
    k[s + 1] = p.drag;
    k[s + 2] = if damped { 1.0 } else { 0.0 };
    k[s + 3] = if rod.ends[0].holds_point() { 1.0 } else { 0.0 };
    k[s + 4] = if rod.ends[1].holds_point() { 1.0 } else { 0.0 };
    let mut clamps = 0;
    for (end, frame) in [(0, 0), (1, n - 1)] {
        if rod.ends[end].holds_frame() {
            let node = &p.end_nodes[end];
            let b = s + 8 + 12 * clamps;
            k[b] = frame as f64;
            k[b + 1] = end as f64;
            k[b + 2..b + 5].copy_from_slice(&[
                node.stiffness.x,
                node.stiffness.y,
                node.stiffness.z,
            ]);
            k[b + 5..b + 8].copy_from_slice(&[
                node.rest_darboux.x,
                node.rest_darboux.y,
                node.rest_darboux.z,
            ]);
            k[b + 8] = node.damping;
            k[b + 9] = p.end_node_length(end);
            clamps += 1;
        }
    }
    k[s + 5] = clamps as f64;
    k[s + 6] = p.masses[0];
    k[s + 7] = p.masses[n];
    k[s + 32] = p.radius;
    if let Some(g) = &rod.guide {
        k[s + 33] = 1.0;
        k[s + 34..s + 37].copy_from_slice(&g.origin);
        k[s + 37..s + 40].copy_from_slice(&g.axis);
        k[s + 40] = g.length;
        k[s + 41] = g.clearance;
    }
    k
}

/// One rod's state block (`st`), padded with identity frames.
fn state_block(s: &RodState<f64>, l: &StiffLayout) -> Vec<f64> {
    let c = &l.st;
    let mut out = vec![0.0; c.len];
    for (i, (x, v)) in s.positions.iter().zip(&s.velocities).enumerate() {
        l.put(&mut out, c.at("S_X"), i, &[x.x, x.y, x.z]);
        l.put(&mut out, c.at("S_V"), i, &[v.x, v.y, v.z]);
    }
    for j in 0..l.slots() {
        let q = s.frames.get(j).copied().unwrap_or_else(Quat::identity);
        l.put(&mut out, c.at("S_Q"), j, &[q.i, q.j, q.k, q.w]);
    }
    for (j, w) in s.angular_velocities.iter().enumerate() {
        l.put(&mut out, c.at("S_OMEGA"), j, &[w.x, w.y, w.z]);
    }
    // The clamp frames: two quaternions, contiguous.
    for (e, q) in s.clamp_frames.iter().enumerate() {
        let a = c.at("S_CLAMP") + 4 * e;
        out[a..a + 4].copy_from_slice(&[q.i, q.j, q.k, q.w]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{BATCH_RODS, slice_threads};

    #[test]
    fn batches_are_sliced_with_the_least_padding_and_single_rods_for_the_shortest_step() {
        let batch = BATCH_RODS;
        // 64 slices where they pad nothing or no less than 32 would.
        assert_eq!(slice_threads(256, batch, 256), 64);
        assert_eq!(slice_threads(100, batch, 256), 64);
        assert_eq!(slice_threads(64, batch, 256), 64);
        // In a batch, 32 where 64 would pad more: 96 = 32 × 3 (64 × 2 = 128), 160 = 32 × 5.
        assert_eq!(slice_threads(96, batch, 256), 32);
        assert_eq!(slice_threads(160, batch, 256), 32);
        // Unless a slice of 32 would hold more than the solve's private arrays do in f64 (16):
        // 520 elements would be 32 × 17 (64 × 9 = 576); 480 are 32 × 15 (64 × 8 = 512).
        assert_eq!(slice_threads(520, batch, 256), 64);
        assert_eq!(slice_threads(480, batch, 256), 32);
        // Fewer rods keep the most slices.
        assert_eq!(slice_threads(96, batch - 1, 256), 64);
        assert_eq!(slice_threads(96, 1, 256), 64);
        // Never more slices than elements, nor than the options allow.
        assert_eq!(slice_threads(20, batch, 256), 32);
        assert_eq!(slice_threads(5, 1, 256), 8);
        assert_eq!(slice_threads(256, 1, 16), 16);
        assert_eq!(slice_threads(256, 1, 48), 32);
    }
}
