//! The stiff scheme's banded solve on the GPU, for many rods at once (`shaders/banded_solve.wgsl`).
//!
//! The CPU's stiff scheme (backend-cpu `stiff`) takes each Newton step of its implicit solve by
//! factorising `J K⁻¹ Jᵀ + α̃` of every rod, a symmetric matrix banded along the rod with 3×3
//! blocks (two on either side of the diagonal), and solving it exactly in `O(n)`. This module
//! is that factorisation and solve on the GPU for a batch of rods of equal length, the first
//! piece of the stiff scheme on the GPU: it takes the assembled block rows from the host and
//! returns the solutions, so that it can be checked on its own against the matrix it was given
//! (`tests/banded.rs`) and measured on its own (`examples/banded_bench.rs`).
//!
//! **One rod per invocation.** The elimination is a chain: block row `k + 1` needs the Schur
//! complement of row `k`. Here each invocation runs one rod's chain, exactly as the CPU does
//! (same pivots, same fallback for singular pivots), with the batch spread over invocations and
//! every array laid out rod-minor so that a subgroup's loads are coalesced. That is the right
//! shape when there are at least as many rods as the GPU has lanes to hide latency with; one
//! rod alone runs a single invocation's chain of `2n − 1` dependent block eliminations, for which
//! a parallel elimination within a workgroup (cyclic reduction) is the answer
//! (`docs/benchmarks/stiff-gpu.md` gives the measured figures for both regimes).
//!
//! **Precision.** [`Precision::F64`] is what the stiff scheme needs (its matrices span more than
//! `f32` resolves, see backend-cpu `stiff/direct.rs`) and needs the adapter's `SHADER_F64`
//! feature; [`Precision::F32`] exists to measure what `f64` costs and how much accuracy it buys.

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
}

/// Invocations per workgroup: rods of [`Strategy::Chain`], rows of
/// [`Strategy::CyclicReduction`].
const WG: u32 = 64;

/// Numbers the cyclic reduction keeps per element (`CR_STRIDE` of the kernel).
const CR_STRIDE: usize = 228;

/// A batch of `rods` block-banded systems with `count` block rows each, on one device: upload
/// the rows, factorise, solve for right-hand sides, read the solutions back.
pub struct BandedBatch {
    gpu: Gpu,
    precision: Precision,
    strategy: Strategy,
    rods: usize,
    count: usize,
    /// Per rod and block row, the scale of each unknown ([`Precision::F32`]; ones otherwise).
    scale: Vec<[f64; 3]>,
    rows: wgpu::Buffer,
    x: wgpu::Buffer,
    staging: wgpu::Buffer,
    factor: (wgpu::ComputePipeline, wgpu::BindGroup),
    solve: (wgpu::ComputePipeline, wgpu::BindGroup),
}

impl BandedBatch {
    /// A batch of `rods` systems of `elements` elements each (`2 elements − 1` block rows) on a
    /// device of its own.
    pub fn new(
        options: &GpuOptions,
        precision: Precision,
        strategy: Strategy,
        rods: usize,
        elements: usize,
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
        let rows = buffer("banded rows", rods * count * BLOCK_ROW, storage);
        let x = buffer(
            "banded rhs",
            rods * count * 3,
            storage | wgpu::BufferUsages::COPY_SRC,
        );
        let staging = buffer(
            "banded staging",
            rods * count * 3,
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
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("banded_solve.wgsl"),
            source: wgpu::ShaderSource::Wgsl(source(precision).into()),
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
        let (factor, solve) = match strategy {
            Strategy::Chain => {
                // The chain's factor: P⁻¹, Y and Z of every block row (the cyclic reduction
                // keeps its own in its scratch).
                let piv = buffer("banded factor", rods * count * BLOCK_ROW, storage);
                (
                    pipeline("factor", &[(0, &shape), (1, &rows), (2, &piv)]),
                    pipeline("solve", &[(0, &shape), (2, &piv), (3, &x)]),
                )
            }
            Strategy::CyclicReduction => {
                let cr = buffer(
                    "banded cyclic reduction",
                    rods * elements * CR_STRIDE,
                    wgpu::BufferUsages::STORAGE,
                );
                (
                    pipeline("factor_cr", &[(0, &shape), (1, &rows), (4, &cr)]),
                    pipeline("solve_cr", &[(0, &shape), (3, &x), (4, &cr)]),
                )
            }
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Wgpu(format!("compiling the banded solve: {e}")));
        }
        Ok(Self {
            gpu,
            precision,
            strategy,
            rods,
            count,
            scale: vec![[1.0; 3]; rods * count],
            rows,
            x,
            staging,
            factor,
            solve,
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

    /// Uploads every rod's block rows: `rows[rod][k]` is block row `k` of rod `rod`
    /// ([`BLOCK_ROW`] numbers; the blocks past the last row must be zero).
    pub fn set_rows(&mut self, rows: &[Vec<[f64; BLOCK_ROW]>]) -> Result<(), GpuError> {
        self.check_rods(rows.len(), "rows")?;
        let mut flat = vec![0.0f64; self.rods * self.count * BLOCK_ROW];
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
                    flat[(k * BLOCK_ROW + e) * self.rods + rod] = *v * f;
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
        let mut flat = vec![0.0f64; self.rods * self.count * 3];
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
                    flat[(k * 3 + c) * self.rods + rod] = *x * s[c];
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
            Strategy::CyclicReduction => self.rods as u32,
        };
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        for _ in 0..repeats {
            for (pipeline, group) in [&self.factor, &self.solve] {
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
                        [0, 1, 2].map(|c| flat[(k * 3 + c) * self.rods + rod] * s[c])
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
    crate::shader::BANDED_SOLVE_WGSL
        .replace("REAL(MAX_REAL)", &format!("{real}({max})"))
        .replace("REAL", real)
        .replace("CR_WG", &format!("{WG}u"))
        .replace("(WG)", &format!("({WG})"))
}
