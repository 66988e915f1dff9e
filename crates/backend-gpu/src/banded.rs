//! The stiff scheme's banded solve on the GPU, for many rods at once (`shaders/banded_solve.wgsl`,
//! `shaders/banded_partitioned.wgsl`).
//!
//! The CPU's stiff scheme (backend-cpu `stiff`) takes each Newton step of its implicit solve by
//! factorising `J K⁻¹ Jᵀ + α̃` of every rod, a symmetric matrix banded along the rod with 3×3
//! blocks (two on either side of the diagonal), and solving it exactly in `O(n)`. This module
//! is that factorisation and solve on the GPU for a batch of rods of equal length, the first
//! piece of the stiff scheme on the GPU: it takes the assembled block rows from the host and
//! returns the solutions, so that it can be checked on its own against the matrix it was given
//! (`tests/banded.rs`) and measured on its own (`examples/banded_bench.rs`).
//!
//! **One rod per invocation** ([`Strategy::Chain`]). The elimination is a chain: block row
//! `k + 1` needs the Schur complement of row `k`. Here each invocation runs one rod's chain,
//! exactly as the CPU does (same pivots, same fallback for singular pivots), with the batch
//! spread over invocations and every array laid out rod-minor so that a subgroup's loads are
//! coalesced. That is the right shape when there are at least as many rods as the GPU has lanes
//! to hide latency with; one rod alone runs a single invocation's chain of `2n − 1` dependent
//! block eliminations.
//!
//! **One rod per workgroup** ([`Strategy::CyclicReduction`]): block cyclic reduction on the
//! 6×6 element blocks, `log₂ n` levels of independent eliminations, its blocks in a global
//! scratch buffer. Both were measured on an H100 (`docs/benchmarks/stiff-gpu.md`) and both are
//! bound by latency: the chain by its dependent loads, the reduction by the scratch buffer its
//! 6×6 products read and write inside loops.
//!
//! **Partitioned** ([`Strategy::Partitioned`], `shaders/banded_partitioned.wgsl`): what that
//! measurement pointed to. One rod per workgroup of [`PARTITIONED_THREADS`] invocations, each
//! owning a contiguous slice of the rod's elements: it loads its slice (laid out on the host so
//! that the workgroup's loads coalesce), eliminates the slice's interior into its first element
//! in private memory (a partitioned, SPIKE-like elimination), the workgroup solves the reduced
//! system of one 6×6 row per invocation by cyclic reduction through 27 numbers of workgroup
//! memory per invocation, and each invocation back-substitutes its slice. Factorisation and
//! solve are one pass, and nothing of the matrix goes back to memory between the phases: only
//! the solution is written. Rods are padded with identity rows to a multiple of the invocation
//! count, so any length works. [`BandedBatch::new`] takes fewer invocations for short rods and
//! where the adapter's workgroup memory is small; [`BandedBatch::new_partitioned`] takes a given
//! count and refuses, with the sizes, what the adapter cannot give.
//!
//! **Precision.** [`Precision::F64`] is what the stiff scheme needs (its matrices span more than
//! `f32` resolves, see backend-cpu `stiff/direct.rs`) and needs the adapter's `SHADER_F64`
//! feature; [`Precision::F32`] (scaled by the diagonal on the host) exists to measure what `f64`
//! costs and how much accuracy it buys.

use crate::device::Gpu;
use crate::{GpuError, GpuOptions};

/// Numbers in one block row: the diagonal block's upper triangle (6), then the blocks in the
/// next two block columns, row-major (9 each).
pub const BLOCK_ROW: usize = 24;

/// The arithmetic of the factorisation and solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// Double precision (needs `SHADER_F64`).
    F64,
    /// Single precision (measurement only), the system scaled symmetrically by its diagonal
    /// on the host before it is rounded (`(S A S) y = S b`, `x = S y`, `S = diag(A)^(-1/2)`):
    /// unscaled, the bend–twist unknowns of a real wire's system come out wrong in `f32`
    /// (backend-cpu `stiff/precision_tests.rs` measures both).
    F32,
}

impl Precision {
    fn bytes(self) -> usize {
        match self {
            Self::F64 => 8,
            Self::F32 => 4,
        }
    }
}

/// How the batch is spread over the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// One rod per invocation: the CPU's chain of block eliminations.
    Chain,
    /// One rod per workgroup: block cyclic reduction on 6×6 element blocks.
    CyclicReduction,
    /// One rod per workgroup, partitioned: each invocation eliminates its own slice of the rod
    /// in private memory, the slices' boundary rows are solved by cyclic reduction through
    /// workgroup memory, then each invocation back-substitutes its slice
    /// (`shaders/banded_partitioned.wgsl`). Factorisation and solve are one kernel.
    Partitioned,
}

/// Invocations per workgroup: rods of [`Strategy::Chain`], rows of
/// [`Strategy::CyclicReduction`].
const WG: u32 = 64;

/// Numbers of an interior element's factors the partitioned solve keeps in an invocation's
/// private arrays for the way back (`P C`, `P G`, `P g`).
const PARTITIONED_INTERIOR: usize = 78;

/// The most bytes of those private arrays per invocation: 16 elements in `f64`, 32 in `f32`.
/// Measured on an NVIDIA H200 (driver 580.159.04): 32 elements per invocation in `f64`
/// (19 968 bytes) failed to compile there, 16 in `f64` and 32 in `f32` (9 984 bytes each) ran.
const PARTITIONED_PRIVATE_BYTES: usize = 16 * PARTITIONED_INTERIOR * 8;

/// The most elements of a rod one invocation of the partitioned solve may own in `precision`
/// (its private arrays within [`PARTITIONED_PRIVATE_BYTES`]).
pub(crate) fn partitioned_max_slice(precision: Precision) -> usize {
    PARTITIONED_PRIVATE_BYTES / (PARTITIONED_INTERIOR * precision.bytes())
}

/// Numbers the cyclic reduction keeps per element (`CR_STRIDE` of the kernel).
const CR_STRIDE: usize = 228;

/// Invocations per rod of [`Strategy::Partitioned`] unless asked otherwise: 256 elements give
/// each four (a separator and three interior elements), two warps of an NVIDIA GPU per rod keep
/// the workgroup barriers of the reduced system cheap, and its exchange (27 numbers per
/// invocation) fits the default 16 KiB of workgroup memory in `f64` (13.8 KB).
pub const PARTITIONED_THREADS: u32 = 64;

/// Numbers per invocation in the partitioned kernel's workgroup array (`XQ` of the kernel).
const PARTITIONED_XQ: usize = 27;

/// The workgroup memory in bytes [`Strategy::Partitioned`] needs with `threads` invocations
/// per rod.
pub fn partitioned_workgroup_bytes(precision: Precision, threads: u32) -> usize {
    partitioned_xch(threads) * precision.bytes()
}

pub(crate) fn partitioned_xch(threads: u32) -> usize {
    // The first separator coupling (36 numbers) goes through it even for one invocation.
    (PARTITIONED_XQ * threads as usize).max(36)
}

/// Where the numbers of a rod's rows and right-hand sides sit in the buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Layout {
    /// `(k · BLOCK_ROW + e) · rods + rod` and `(k · 3 + c) · rods + rod` (Chain, CR).
    RodMinor,
    /// Elements padded to `threads · per_thread`, each invocation's slice interleaved with the
    /// others': number q of element j of invocation t's slice at `((rod · per_thread + j) · Q +
    /// q) · threads + t`, Q = 48 for the rows (block rows 2j and 2j + 1) and 6 for the vectors.
    Partitioned { threads: usize, per_thread: usize },
}

impl Layout {
    /// Where entry `e` of block row `k` of `rod` (of `rods`) sits in the rows buffer.
    fn row_index(self, rods: usize, rod: usize, k: usize, e: usize) -> usize {
        match self {
            Self::RodMinor => (k * BLOCK_ROW + e) * rods + rod,
            Self::Partitioned {
                threads,
                per_thread,
            } => {
                let (t, j) = (k / 2 / per_thread, k / 2 % per_thread);
                let q = (k % 2) * BLOCK_ROW + e;
                ((rod * per_thread + j) * 2 * BLOCK_ROW + q) * threads + t
            }
        }
    }

    /// Where component `c` of block row `k` of `rod` (of `rods`) sits in the right-hand-side
    /// buffer.
    fn x_index(self, rods: usize, rod: usize, k: usize, c: usize) -> usize {
        match self {
            Self::RodMinor => (k * 3 + c) * rods + rod,
            Self::Partitioned {
                threads,
                per_thread,
            } => {
                let (t, j) = (k / 2 / per_thread, k / 2 % per_thread);
                ((rod * per_thread + j) * 6 + (k % 2) * 3 + c) * threads + t
            }
        }
    }
}

/// A batch of `rods` block-banded systems with `count` block rows each, on one device: upload
/// the rows, factorise, solve for right-hand sides, read the solutions back.
pub struct BandedBatch {
    gpu: Gpu,
    precision: Precision,
    strategy: Strategy,
    layout: Layout,
    rods: usize,
    count: usize,
    /// Per rod and block row, the scale of each unknown ([`Precision::F32`]; ones otherwise).
    scale: Vec<[f64; 3]>,
    rows: wgpu::Buffer,
    x: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// The passes of one factorisation and solve, in order.
    passes: Vec<(wgpu::ComputePipeline, wgpu::BindGroup)>,
}

impl BandedBatch {
    /// A batch of `rods` systems of `elements` elements each (`2 elements − 1` block rows) on a
    /// device of its own.
    ///
    /// [`Strategy::Partitioned`] takes [`PARTITIONED_THREADS`] invocations per rod (fewer for
    /// rods of fewer elements, or where the adapter's workgroup memory is smaller than the
    /// exchange needs); [`new_partitioned`](Self::new_partitioned) chooses them.
    pub fn new(
        options: &GpuOptions,
        precision: Precision,
        strategy: Strategy,
        rods: usize,
        elements: usize,
    ) -> Result<Self, GpuError> {
        Self::build(options, precision, strategy, rods, elements, None)
    }

    /// A [`Strategy::Partitioned`] batch with `threads` invocations per rod (a power of two),
    /// refused where the adapter's workgroup limits are smaller than they need.
    pub fn new_partitioned(
        options: &GpuOptions,
        precision: Precision,
        rods: usize,
        elements: usize,
        threads: u32,
    ) -> Result<Self, GpuError> {
        if !threads.is_power_of_two() {
            return Err(GpuError::InvalidInput(format!(
                "the partitioned solve needs a power of two of invocations per rod (got {threads})"
            )));
        }
        Self::build(
            options,
            precision,
            Strategy::Partitioned,
            rods,
            elements,
            Some(threads),
        )
    }

    fn build(
        options: &GpuOptions,
        precision: Precision,
        strategy: Strategy,
        rods: usize,
        elements: usize,
        threads: Option<u32>,
    ) -> Result<Self, GpuError> {
        if rods == 0 || elements == 0 {
            return Err(GpuError::InvalidInput(format!(
                "a banded batch needs rods and elements (got {rods} rods of {elements} elements)"
            )));
        }
        let gpu = Gpu::acquire(options)?;
        let has_f64 = gpu.device.features().contains(wgpu::Features::SHADER_F64);
        if precision == Precision::F64 && !has_f64 {
            return Err(GpuError::NoAdapter(format!(
                "adapter `{}` has no double-precision shaders (SHADER_F64), which the stiff \
                 scheme's solve needs",
                gpu.adapter.name
            )));
        }
        let count = 2 * elements - 1;
        let layout = match strategy {
            Strategy::Chain | Strategy::CyclicReduction => Layout::RodMinor,
            Strategy::Partitioned => {
                let limits = &gpu.limits;
                let storage = limits.max_compute_workgroup_storage_size as usize;
                let invocations = limits
                    .max_compute_invocations_per_workgroup
                    .min(limits.max_compute_workgroup_size_x);
                let threads = match threads {
                    Some(t) => t,
                    None => {
                        // No more invocations than elements, none the adapter cannot give.
                        let mut t = PARTITIONED_THREADS.min((elements as u32).next_power_of_two());
                        while t > 1
                            && (t > invocations
                                || partitioned_workgroup_bytes(precision, t) > storage)
                        {
                            t /= 2;
                        }
                        t
                    }
                };
                let need = partitioned_workgroup_bytes(precision, threads);
                if threads > invocations || need > storage {
                    return Err(GpuError::InvalidInput(format!(
                        "the partitioned solve with {threads} invocations per rod needs \
                         {threads} invocations and {need} bytes of workgroup memory in \
                         {precision:?}; adapter `{}` offers {invocations} invocations and \
                         {storage} bytes",
                        gpu.adapter.name
                    )));
                }
                let threads = threads as usize;
                let per_thread = elements.div_ceil(threads);
                let private = per_thread * PARTITIONED_INTERIOR * precision.bytes();
                if private > PARTITIONED_PRIVATE_BYTES {
                    return Err(GpuError::InvalidInput(format!(
                        "the partitioned solve of {elements} elements with {threads} invocations \
                         per rod keeps {per_thread} elements per invocation, {private} bytes of \
                         private arrays in {precision:?}; at most {PARTITIONED_PRIVATE_BYTES} \
                         compile everywhere it was tried (an NVIDIA driver refused 32 elements in \
                         F64): take more invocations per rod"
                    )));
                }
                Layout::Partitioned {
                    threads,
                    per_thread,
                }
            }
        };
        // Numbers per rod in the rows and right-hand-side buffers.
        let (row_len, x_len) = match layout {
            Layout::RodMinor => (count * BLOCK_ROW, count * 3),
            Layout::Partitioned {
                threads,
                per_thread,
            } => (
                threads * per_thread * 2 * BLOCK_ROW,
                threads * per_thread * 6,
            ),
        };
        let device = &gpu.device;
        let real = precision.bytes() as u64;
        let buffer = |label: &str, len: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (len as u64 * real).max(16),
                usage,
                mapped_at_creation: false,
            })
        };
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let rows = buffer("banded rows", rods * row_len, storage);
        let x = buffer(
            "banded rhs",
            rods * x_len,
            storage | wgpu::BufferUsages::COPY_SRC,
        );
        let staging = buffer(
            "banded staging",
            rods * x_len,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let shape = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("banded shape"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        gpu.queue.write_buffer(
            &shape,
            0,
            bytemuck::cast_slice(&[rods as u32, count as u32, elements as u32, 0]),
        );
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(match layout {
            Layout::RodMinor => wgpu::ShaderModuleDescriptor {
                label: Some("banded_solve.wgsl"),
                source: wgpu::ShaderSource::Wgsl(source(precision).into()),
            },
            Layout::Partitioned {
                threads,
                per_thread,
            } => wgpu::ShaderModuleDescriptor {
                label: Some("banded_partitioned.wgsl"),
                source: wgpu::ShaderSource::Wgsl(
                    partitioned_source(precision, threads as u32, per_thread as u32).into(),
                ),
            },
        });
        let pipeline = |entry: &str, bindings: &[(u32, &wgpu::Buffer)]| {
            let p = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
            let entries: Vec<_> = bindings
                .iter()
                .map(|&(binding, b)| wgpu::BindGroupEntry {
                    binding,
                    resource: b.as_entire_binding(),
                })
                .collect();
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(entry),
                layout: &p.get_bind_group_layout(0),
                entries: &entries,
            });
            (p, group)
        };
        let passes = match strategy {
            Strategy::Chain => {
                // The chain's factor: P⁻¹, Y and Z of every block row (the cyclic reduction
                // keeps its own in its scratch).
                let piv = buffer("banded factor", rods * count * BLOCK_ROW, storage);
                vec![
                    pipeline("factor", &[(0, &shape), (1, &rows), (2, &piv)]),
                    pipeline("solve", &[(0, &shape), (2, &piv), (3, &x)]),
                ]
            }
            Strategy::CyclicReduction => {
                let cr = buffer(
                    "banded cyclic reduction",
                    rods * elements * CR_STRIDE,
                    wgpu::BufferUsages::STORAGE,
                );
                vec![
                    pipeline("factor_cr", &[(0, &shape), (1, &rows), (4, &cr)]),
                    pipeline("solve_cr", &[(0, &shape), (3, &x), (4, &cr)]),
                ]
            }
            // Factorisation and solve in one pass, nothing of the matrix kept between them.
            Strategy::Partitioned => {
                if let Layout::Partitioned {
                    threads,
                    per_thread,
                } = layout
                {
                    let part = [per_thread as u32, threads as u32, 0, 0];
                    gpu.queue
                        .write_buffer(&shape, 0, bytemuck::cast_slice(&part));
                }
                vec![pipeline("partitioned", &[(0, &shape), (1, &rows), (3, &x)])]
            }
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Wgpu(format!("compiling the banded solve: {e}")));
        }
        Ok(Self {
            gpu,
            precision,
            strategy,
            layout,
            rods,
            count,
            scale: vec![[1.0; 3]; rods * count],
            rows,
            x,
            staging,
            passes,
        })
    }

    /// Block rows per rod.
    pub fn block_rows(&self) -> usize {
        self.count
    }

    /// Rods in the batch.
    pub fn rods(&self) -> usize {
        self.rods
    }

    /// [`Strategy::Partitioned`]: invocations per rod and elements per invocation.
    pub fn partition(&self) -> Option<(usize, usize)> {
        match self.layout {
            Layout::RodMinor => None,
            Layout::Partitioned {
                threads,
                per_thread,
            } => Some((threads, per_thread)),
        }
    }

    /// Where entry `e` of block row `k` of `rod` sits in the rows buffer.
    fn row_index(&self, rod: usize, k: usize, e: usize) -> usize {
        self.layout.row_index(self.rods, rod, k, e)
    }

    /// Where component `c` of block row `k` of `rod` sits in the right-hand-side buffer.
    fn x_index(&self, rod: usize, k: usize, c: usize) -> usize {
        self.layout.x_index(self.rods, rod, k, c)
    }

    /// Block rows per rod in the buffers (the partitioned layout's padding included).
    fn stored_rows(&self) -> usize {
        match self.layout {
            Layout::RodMinor => self.count,
            Layout::Partitioned {
                threads,
                per_thread,
            } => 2 * threads * per_thread,
        }
    }

    /// Uploads every rod's block rows: `rows[rod][k]` is block row `k` of rod `rod`
    /// ([`BLOCK_ROW`] numbers; the blocks past the last row must be zero).
    pub fn set_rows(&mut self, rows: &[Vec<[f64; BLOCK_ROW]>]) -> Result<(), GpuError> {
        self.check_rods(rows.len(), "rows")?;
        let (layout, rods) = (self.layout, self.rods);
        let stored = self.stored_rows();
        let mut flat = vec![0.0f64; self.rods * stored * BLOCK_ROW];
        // The padding past the last block row: identity diagonal blocks, no coupling.
        for rod in 0..self.rods {
            for k in self.count..stored {
                for e in [0, 3, 5] {
                    let i = self.row_index(rod, k, e);
                    flat[i] = 1.0;
                }
            }
        }
        for (rod, r) in rows.iter().enumerate() {
            if r.len() != self.count {
                return Err(GpuError::InvalidInput(format!(
                    "rod {rod}: {} block rows given, the batch has {}",
                    r.len(),
                    self.count
                )));
            }
            let scale = &mut self.scale[rod * self.count..(rod + 1) * self.count];
            for (s, row) in scale.iter_mut().zip(r) {
                *s = match self.precision {
                    Precision::F64 => [1.0; 3],
                    Precision::F32 => {
                        [row[0], row[3], row[5]].map(|d| if d > 0.0 { 1.0 / d.sqrt() } else { 1.0 })
                    }
                };
            }
            let s = |k: usize| scale.get(k).copied().unwrap_or([1.0; 3]);
            for (k, row) in r.iter().enumerate() {
                // Entry e of block (k, k + off) at (i, j) scales by s_k,i s_{k+off},j.
                let (sk, s1, s2) = (s(k), s(k + 1), s(k + 2));
                let diag = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
                for (e, v) in row.iter().enumerate() {
                    let f = match e {
                        0..6 => sk[diag[e].0] * sk[diag[e].1],
                        6..15 => sk[(e - 6) / 3] * s1[(e - 6) % 3],
                        _ => sk[(e - 15) / 3] * s2[(e - 15) % 3],
                    };
                    flat[layout.row_index(rods, rod, k, e)] = *v * f;
                }
            }
        }
        self.upload(&self.rows, &flat);
        Ok(())
    }

    /// Uploads every rod's right-hand side: `rhs[rod][k]` belongs to block row `k` (after the
    /// rows, whose scale it takes in [`Precision::F32`]).
    pub fn set_rhs(&mut self, rhs: &[Vec<[f64; 3]>]) -> Result<(), GpuError> {
        self.check_rods(rhs.len(), "right-hand sides")?;
        let mut flat = vec![0.0f64; self.rods * self.stored_rows() * 3];
        for (rod, b) in rhs.iter().enumerate() {
            if b.len() != self.count {
                return Err(GpuError::InvalidInput(format!(
                    "rod {rod}: {} right-hand-side blocks given, the batch has {}",
                    b.len(),
                    self.count
                )));
            }
            for (k, v) in b.iter().enumerate() {
                let s = self.scale[rod * self.count + k];
                for (c, x) in v.iter().enumerate() {
                    flat[self.x_index(rod, k, c)] = *x * s[c];
                }
            }
        }
        self.upload(&self.x, &flat);
        Ok(())
    }

    /// Submits `repeats` factorisations and solves of the uploaded rows and right-hand side
    /// (each repeat solves in place, so only `repeats = 1` leaves the solution of the uploaded
    /// system; more are for timing) and waits for them.
    pub fn run(&mut self, repeats: usize) -> Result<(), GpuError> {
        let groups = match self.strategy {
            Strategy::Chain => (self.rods as u32).div_ceil(WG),
            Strategy::CyclicReduction | Strategy::Partitioned => self.rods as u32,
        };
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        for _ in 0..repeats {
            for (pipeline, group) in &self.passes {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups(groups, 1, 1);
            }
        }
        self.gpu.queue.submit([encoder.finish()]);
        self.gpu.wait_idle()
    }

    /// The solutions of the last [`run`](Self::run): `[rod][k]`.
    pub fn solution(&mut self) -> Result<Vec<Vec<[f64; 3]>>, GpuError> {
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        encoder.copy_buffer_to_buffer(&self.x, 0, &self.staging, 0, self.staging.size());
        self.gpu.queue.submit([encoder.finish()]);
        self.staging.map_async(wgpu::MapMode::Read, .., |_| {});
        self.gpu.wait_idle()?;
        let flat: Vec<f64> = {
            let view = self
                .staging
                .get_mapped_range(..)
                .map_err(|e| GpuError::Wgpu(format!("mapping the solution: {e}")))?;
            match self.precision {
                Precision::F64 => bytemuck::cast_slice::<u8, f64>(&view).to_vec(),
                Precision::F32 => bytemuck::cast_slice::<u8, f32>(&view)
                    .iter()
                    .map(|&v| f64::from(v))
                    .collect(),
            }
        };
        self.staging.unmap();
        Ok((0..self.rods)
            .map(|rod| {
                (0..self.count)
                    .map(|k| {
                        let s = self.scale[rod * self.count + k];
                        [0, 1, 2].map(|c| flat[self.x_index(rod, k, c)] * s[c])
                    })
                    .collect()
            })
            .collect())
    }

    fn check_rods(&self, given: usize, what: &str) -> Result<(), GpuError> {
        if given != self.rods {
            return Err(GpuError::InvalidInput(format!(
                "{given} rods' {what} given, the batch has {}",
                self.rods
            )));
        }
        Ok(())
    }

    fn upload(&self, buffer: &wgpu::Buffer, values: &[f64]) {
        match self.precision {
            Precision::F64 => self
                .gpu
                .queue
                .write_buffer(buffer, 0, bytemuck::cast_slice(values)),
            Precision::F32 => {
                let v: Vec<f32> = values.iter().map(|&x| x as f32).collect();
                self.gpu
                    .queue
                    .write_buffer(buffer, 0, bytemuck::cast_slice(&v));
            }
        }
    }
}

/// The componentwise backward error of `x` as a solution of `A x = b`, `A` given by its block
/// rows as [`BandedBatch::set_rows`] takes them: `max_i |A x − b|_i / (|A| |x| + |b|)_i`
/// (Oettli–Prager), the smallest relative change of the entries of `A` and `b` that makes `x`
/// exact. A stable factorisation keeps it near the arithmetic's resolution however badly `A`
/// is scaled, where `‖A x − b‖ / ‖b‖` grows with the condition number.
pub fn backward_error(rows: &[[f64; BLOCK_ROW]], x: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let n = rows.len().min(x.len()).min(b.len());
    // The residual and the scale |A| |x| + |b|, row by row.
    let mut r: Vec<[f64; 3]> = b[..n].iter().map(|v| v.map(|c| -c)).collect();
    let mut scale: Vec<[f64; 3]> = b[..n].iter().map(|v| v.map(f64::abs)).collect();
    let mut add = |k: usize, i: usize, v: f64| {
        r[k][i] += v;
        scale[k][i] += v.abs();
    };
    for k in 0..n {
        let e = &rows[k];
        let d = [[e[0], e[1], e[2]], [e[1], e[3], e[4]], [e[2], e[4], e[5]]];
        for i in 0..3 {
            for j in 0..3 {
                add(k, i, d[i][j] * x[k][j]);
            }
        }
        // The blocks above the diagonal and, by symmetry, their transposes below it.
        for (off, at) in [(1, 6), (2, 15)] {
            if k + off >= n {
                continue;
            }
            for i in 0..3 {
                for j in 0..3 {
                    let v = e[at + 3 * i + j];
                    add(k, i, v * x[k + off][j]);
                    add(k + off, j, v * x[k][i]);
                }
            }
        }
    }
    r.iter()
        .flatten()
        .zip(scale.iter().flatten())
        .map(|(r, s)| if *s > 0.0 { r.abs() / s } else { r.abs() })
        .fold(0.0, f64::max)
}

/// The kernel's source for `precision`.
pub(crate) fn source(precision: Precision) -> String {
    let (real, max) = match precision {
        Precision::F64 => ("f64", "1.7976931348623157e308lf"),
        Precision::F32 => ("f32", "3.4028234e38"),
    };
    format!(
        "{}\n{}",
        crate::shader::CHOLESKY_WGSL,
        crate::shader::BANDED_SOLVE_WGSL
    )
    .replace("REAL(MAX_REAL)", &format!("{real}({max})"))
    .replace("REAL", real)
    .replace("CR_WG", &format!("{WG}u"))
    .replace("(WG)", &format!("({WG})"))
}

/// The partitioned kernel's source for `precision`, `threads` invocations per rod and
/// `per_thread` elements each.
pub(crate) fn partitioned_source(precision: Precision, threads: u32, per_thread: u32) -> String {
    let real = match precision {
        Precision::F64 => "f64",
        Precision::F32 => "f32",
    };
    format!(
        "const PT: u32 = {threads}u;\nconst EPT: u32 = {per_thread}u;\nconst XCH: u32 = {}u;\n\n{}",
        partitioned_xch(threads),
        format!(
            "{}\n{}\n{}",
            crate::shader::BANDED_PARTITIONED_MAIN_WGSL,
            crate::shader::CHOLESKY_WGSL,
            crate::shader::BANDED_PARTITIONED_WGSL
        )
        .replace("REAL", real)
    )
}
