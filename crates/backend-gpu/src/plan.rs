//! The plan a simulation runs: which kernel path, the kernel's shape (threads, points per
//! thread, halo, steps between exchanges, flags) and the work items, one per workgroup or
//! subgroup.
//!
//! Planning needs the scene, the solver settings and what is known about the adapter, and
//! nothing of a device: it is pure arithmetic, decided once before anything is uploaded, and
//! its unit tests run without a GPU. The numbers it starts from are the measured production
//! choices in [`Tuning::PRODUCTION`]; the benchmark's `KernelVariant` (see `variants.rs`) is
//! the only other source of a [`Tuning`].

use crate::device::AdapterSummary;
use crate::layout::{CouplingG, ItemG, NONE, StrandG};
use crate::shader::{KernelConfig, RodcShape};
use crate::{EndCondition, GpuError, GpuOptions, GpuRodInput, KernelPath, SolverSettings};

/// Loop iterations lavapipe runs per invocation before it silently stops all loops (GPU.md),
/// with a margin.
const SOFTWARE_LOOP_BUDGET: u32 = 40_000;

/// The choices of kernel layout a [`Plan`] is made with. Every value of
/// [`Tuning::PRODUCTION`] was measured against its alternatives (`docs/benchmarks/gpu.md`);
/// the alternatives stay reachable for that measurement through `KernelVariant`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Tuning {
    /// Allow the subgroup layout for short rods (one rod per subgroup, no workgroup barriers)
    /// where the adapter has `SUBGROUP` and a fixed subgroup size.
    pub(crate) subgroups: bool,
    /// Fewest rods for which the subgroup layout is used: it has more points per invocation
    /// and so more latency per step than the workgroup layout, which wins while the rods leave
    /// the GPU idle; with many rods its fuller subgroups give more throughput.
    pub(crate) subgroup_min_rods: u32,
    /// Rods per workgroup in the subgroup layout (4: 128 invocations on NVIDIA).
    pub(crate) rods_per_workgroup: u32,
    /// Most points per invocation for which the subgroup layout is used.
    pub(crate) subgroup_points_per_thread: u32,
    /// Threads per workgroup of the multi-workgroup path (capped by
    /// [`GpuOptions::max_threads`]): smaller windows finish a step sooner, and the halo they
    /// repeat costs less than the extra latency of wider ones (H200, 1000 elements: 5.5 µs/step
    /// with 128 threads against 6.4 with 256).
    pub(crate) multi_threads: u32,
    /// Points per thread of the multi-workgroup windows; 0 picks the fewest (even) that leave
    /// each window owning at least one halo and 64 points.
    pub(crate) multi_points_per_thread: u32,
    /// Steps between halo exchanges of the multi-workgroup paths (the dispatch-per-step path
    /// then runs this many steps per dispatch). The halo grows to cover them,
    /// `exchange_steps · (2 · iterations + 1) + 3` points, and the grid barrier is paid once
    /// per exchange. Lowered where the windows would not all be co-resident.
    pub(crate) exchange_steps: u32,
    /// Multi-workgroup path: each workgroup waits only for its two neighbours' flags instead of
    /// a grid-wide arrival counter.
    pub(crate) neighbour_sync: bool,
    /// Multi-workgroup path: exchange halos as vec4s through a `@coherent` buffer where the
    /// adapter has `MEMORY_DECORATION_COHERENT`, instead of single words through atomics.
    pub(crate) coherent_exchange: bool,
    /// Multi-workgroup windows of one subgroup (threads = the adapter's subgroup size) whose
    /// threads exchange their boundary points by subgroup shuffles instead of workgroup memory.
    pub(crate) shuffle_windows: bool,
    /// Keep the per-point and per-element parameters in registers for the whole dispatch
    /// instead of reading them from storage in every step.
    pub(crate) register_constants: bool,
    /// Constraint impulse from one `inverseSqrt` with the per-constraint factors
    /// `w / (w_a + w_b) / h` kept in registers (fewer dependent operations per sweep).
    pub(crate) fast_impulse: bool,
}

impl Tuning {
    /// What [`crate::GpuSimulation::new`] and [`crate::GpuSimulation::on_device`] plan with.
    pub(crate) const PRODUCTION: Self = Self {
        subgroups: true,
        subgroup_min_rods: 256,
        rods_per_workgroup: 4,
        subgroup_points_per_thread: 8,
        multi_threads: 128,
        multi_points_per_thread: 0,
        exchange_steps: 3,
        neighbour_sync: true,
        coherent_exchange: true,
        shuffle_windows: false,
        register_constants: true,
        fast_impulse: true,
    };
}

/// The plan a simulation runs: path, kernel shape and the work items (one per workgroup, or
/// per subgroup in the subgroup layout).
#[derive(Clone, Debug)]
pub(crate) struct Plan {
    /// Never [`KernelPath::Auto`].
    pub(crate) path: KernelPath,
    pub(crate) cfg: KernelConfig,
    pub(crate) items: Vec<ItemG>,
    /// Workgroups per dispatch (the items, or fewer with several rods per workgroup).
    pub(crate) workgroups: u32,
    /// Bindings: per workgroup its first item and number of items, and per item its part in a
    /// binding (both empty without bindings).
    pub(crate) groups: Vec<[u32; 2]>,
    pub(crate) couplings: Vec<CouplingG>,
    /// Rod contact: per item its part ([`StrandG`]; empty without rod contact).
    pub(crate) strands: Vec<StrandG>,
    /// Most steps one dispatch of a persistent path runs.
    pub(crate) steps_per_dispatch: u32,
}

fn round_up(x: u32, m: u32) -> u32 {
    x.div_ceil(m) * m
}

impl Plan {
    /// The plan for `rods` on `adapter`: the path (`options.path`, or chosen as
    /// [`GpuSimulation::new`] says), the kernel's shape and flags, and the work items.
    ///
    /// [`GpuSimulation::new`]: crate::GpuSimulation::new
    pub(crate) fn new(
        rods: &[GpuRodInput],
        settings: &SolverSettings<f32>,
        options: &GpuOptions,
        tuning: &Tuning,
        adapter: &AdapterSummary,
        limits: &wgpu::Limits,
    ) -> Result<Self, GpuError> {
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
        // Clamps: a clamp frame per clamped end, acting through its node (`layout::ClampG`).
        if rods
            .iter()
            .any(|r| r.ends.iter().any(EndCondition::holds_frame))
        {
            flags.push("CLAMP");
        }
        // Reactions at held ends (every clamped end holds its point too).
        if rods
            .iter()
            .any(|r| r.ends.iter().any(EndCondition::holds_point))
        {
            flags.push("REACT");
        }
        // Contact with a mesh and the introducer: only in the workgroup layout of the
        // single-workgroup path (their per-step counts and the guide's extent are agreed
        // through workgroup memory).
        let mesh = rods.iter().any(|r| r.wall.is_some());
        let guide = rods.iter().any(|r| r.guide.is_some());
        if mesh {
            flags.push("MESH");
        }
        if guide {
            flags.push("GUIDE");
        }
        // Bindings: the rods they couple share a workgroup.
        let bind = rods.iter().any(|r| r.binding.is_some());
        if bind {
            if extensible {
                return Err(GpuError::InvalidInput(
                    "bindings run on the GPU with inextensible rods only".into(),
                ));
            }
            flags.push("BIND");
        }
        // Rod contact: every rod that has it shares one workgroup with the others.
        let rodc = rods.iter().any(|r| r.rod_contact.is_some());
        if rodc {
            if extensible {
                return Err(GpuError::InvalidInput(
                    "rod contact runs on the GPU with inextensible rods only".into(),
                ));
            }
            if bind {
                return Err(GpuError::InvalidInput(
                    "bindings and rod contact in one simulation run on the CPU backends only"
                        .into(),
                ));
            }
            flags.push("RODC");
        }
        let coupled = coupled_groups(rods)?;
        let contact = mesh || guide || bind || rodc;
        let iterations = if extensible {
            0
        } else {
            settings.iterations as u32
        };
        // Workgroup memory per thread: r, q (2 vec4 each), ω with bend damping, 4 for velocities.
        let needs_v = !extensible || flags.contains(&"STRETCH_DAMP");
        let per_thread_bytes =
            16 * (4 + if bend_damp { 2 } else { 0 } + if needs_v { 4 } else { 0 });
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
        // Bindings exchange in workgroup memory the outer rods' points (a vec4 and two words
        // each) and the inner rods' impulses (a vec4 each): as many as the largest group has.
        let group_points = |of: &dyn Fn(usize) -> bool| -> u32 {
            coupled
                .iter()
                .map(|g| {
                    g.iter()
                        .filter(|&&r| of(r))
                        .map(|&r| rods[r].state.elements() as u32 + 1)
                        .sum::<u32>()
                })
                .max()
                .unwrap_or(0)
        };
        let is_outer = |r: usize| rods.iter().any(|o| o.binding.is_some_and(|b| b.outer == r));
        let (bind_points, bind_inner) = if bind {
            (
                group_points(&is_outer),
                group_points(&|r| rods[r].binding.is_some()),
            )
        } else {
            (0, 0)
        };
        // Rod contact keeps in workgroup memory, per point of the largest group, its position or
        // velocity (a vec4), its number of contacts and its impulse (4 words), and per bounding
        // sphere a vec4, what it covers (2 words) and room for its overlapping pairs; the step's
        // contacts are listed in storage.
        let rodc_shape = if rodc {
            let per_sphere = RODC_SEGMENTS_PER_SPHERE;
            let points = group_points(&|r| rods[r].rod_contact.is_some());
            let spheres = coupled
                .iter()
                .map(|g| {
                    g.iter()
                        .filter(|&&r| rods[r].rod_contact.is_some())
                        .map(|&r| (rods[r].state.elements() as u32).div_ceil(per_sphere))
                        .sum::<u32>()
                })
                .max()
                .unwrap_or(1);
            if spheres >= 1 << 16 {
                return Err(GpuError::InvalidInput(format!(
                    "rod contact with {spheres} bounding spheres; at most 65 535"
                )));
            }
            RodcShape {
                points,
                spheres,
                per_sphere,
                // Every pair of spheres, or 32 a sphere (the knot's tightened core has ~10).
                pairs: (spheres * (spheres + 1) / 2).min(32 * spheres),
                per_thread: RODC_PER_THREAD,
            }
        } else {
            RodcShape::default()
        };
        // (Workgroup memory bounds the points far below the 65 536 segments a sphere's
        // first segment is packed into.)
        let rodc_bytes = 32 * rodc_shape.points + 24 * rodc_shape.spheres + 4 * rodc_shape.pairs;
        let (single_threads, single_ept) = if bind || rodc {
            // The fewest points per thread with which every group's rods fit one workgroup, in
            // its threads and its memory.
            let lanes = |ept: u32| -> u32 {
                coupled
                    .iter()
                    .map(|g| {
                        g.iter()
                            .map(|&r| (rods[r].state.elements() as u32 + 1).div_ceil(ept))
                            .sum::<u32>()
                    })
                    .max()
                    .unwrap_or(1)
            };
            let bytes = |ept: u32| {
                round_up(lanes(ept), 32) * (per_thread_bytes + if mesh { 16 } else { 0 })
                    + 24 * bind_points
                    + 16 * bind_inner
                    + rodc_bytes
                    + 256
            };
            let ept = (1..=32)
                .map(|k| 2 * k)
                .find(|&e| lanes(e) <= max_threads && bytes(e) <= storage_cap)
                .ok_or_else(|| {
                    GpuError::InvalidInput(format!(
                        "coupled rods (bindings: {bind_points} points in outer rods and {bind_inner} in inner rods; rod contact: {} points) do not fit one workgroup's {} bytes of memory",
                        rodc_shape.points,
                        limits.max_compute_workgroup_storage_size
                    ))
                })?;
            (round_up(lanes(ept), 32).min(max_threads), ept)
        } else {
            let threads = max_threads.min(round_up(points.div_ceil(2), 32));
            (threads, round_up(points.div_ceil(threads), 2).max(2))
        };
        // The subgroup layout: every rod on one subgroup, a few rods per workgroup, no barriers.
        let subgroup = adapter
            .subgroup_size
            .filter(|_| {
                tuning.subgroups && !contact && rods.len() as u32 >= tuning.subgroup_min_rods
            })
            .map(|sg| (sg, round_up(points.div_ceil(sg), 2).max(2)))
            .filter(|&(_, ept)| ept <= tuning.subgroup_points_per_thread.max(2));
        // Windows of the two multi-workgroup paths. Information travels `2 · iterations + 1` points
        // per step (forces 1, each half-sweep 1), so a window whose halo is wider than that times
        // the steps between exchanges computes its owned points exactly as the whole rod would.
        let reach = 2 * iterations + 1;
        let halo_for = |xs: u32| round_up(xs * reach + 3, 2);
        // Shuffle windows are one subgroup wide (NVIDIA 32, lavapipe 8).
        let shuffle_sg = adapter
            .subgroup_size
            .filter(|&sg| tuning.shuffle_windows && sg <= max_threads);
        let multi_threads = match shuffle_sg {
            Some(sg) => sg,
            None => (max_threads.min(tuning.multi_threads) / 32 * 32).max(32),
        };
        // (points per thread, halo, owned points per window) for `xs` steps between exchanges.
        let multi_shape = |xs: u32| -> (u32, u32, u32) {
            let halo = halo_for(xs);
            let ept = if tuning.multi_points_per_thread > 0 {
                round_up(tuning.multi_points_per_thread, 2)
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
        let want_xs = tuning.exchange_steps.max(1);
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
                        lane0: 0,
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
                if single_ept <= 2 || subgroup.is_some() || (contact && single_ept <= 64) {
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
        if contact && path != KernelPath::SingleWorkgroup {
            return Err(GpuError::PathUnavailable {
                path,
                reason: "mesh contact, guides and bindings run on the single-workgroup path only"
                    .into(),
            });
        }
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
        let mut groups = Vec::new();
        let mut couplings = Vec::new();
        let mut strands = Vec::new();
        let mut xs_used = 1;
        let (threads, ept, items, halo_used) = match path {
            KernelPath::SingleWorkgroup => {
                let bases: Vec<u32> = rods
                    .iter()
                    .scan(0u32, |b, rod| {
                        let base = *b;
                        *b += rod.state.elements() as u32 + 1;
                        Some(base)
                    })
                    .collect();
                let item = |r: usize, lane0: u32| {
                    let rod = &rods[r];
                    let n = rod.state.elements() as u32;
                    ItemG {
                        rod: r as u32,
                        base: bases[r],
                        n,
                        flags: item_flags(rod),
                        w0: 0,
                        w1: n + 1,
                        o0: 0,
                        o1: n + 1,
                        left: NONE,
                        right: NONE,
                        drag: rod.params.drag,
                        lane0,
                    }
                };
                let items = if bind || rodc {
                    // The items group by group, each rod on its own run of threads.
                    let mut items = Vec::with_capacity(rods.len());
                    for g in &coupled {
                        groups.push([items.len() as u32, g.len() as u32]);
                        let mut lane = 0;
                        for &r in g {
                            items.push(item(r, lane));
                            lane += (rods[r].state.elements() as u32 + 1).div_ceil(single_ept);
                        }
                    }
                    if bind {
                        couplings = coupling_of_items(rods, &items, &groups);
                    }
                    if rodc {
                        strands = strands_of_items(rods, &items, &groups, rodc_shape.per_sphere);
                    }
                    workgroups = Some(groups.len() as u32);
                    items
                } else {
                    (0..rods.len()).map(|r| item(r, 0)).collect::<Vec<_>>()
                };
                match subgroup {
                    Some((sg, ept)) => {
                        let cap = limits.max_compute_invocations_per_workgroup.min(1024) / sg;
                        let per_wg = tuning.rods_per_workgroup.clamp(1, cap.max(1));
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
            if tuning.neighbour_sync {
                flags.push("NBR_SYNC");
            }
            if tuning.coherent_exchange && adapter.coherent {
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
        if tuning.fast_impulse && !extensible {
            flags.push("FAST");
        }
        if tuning.register_constants {
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
            unroll: true,
            bind_points,
            bind_inner,
            rodc: rodc_shape,
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
            }
            // A tree walk per point (nodes and triangles visited), counted generously for the
            // small meshes of software runs.
            + if mesh { ept * 256 } else { 0 }
            // A binding's walk along the outer rod and its compare-exchange loops.
            + if bind { ept * 64 + iterations * ept * 8 } else { 0 }
            // Rod contact: the strided loops over spheres (and their points), sphere pairs and
            // their segments (a sphere pair's k + k² tests on one thread), and per sweep each
            // of the thread's contacts and its four points.
            + if rodc {
                let (k, t) = (rodc_shape.per_sphere, threads.max(1));
                let sph = rodc_shape.spheres;
                (2 * sph * (k + 1) + sph * sph + rodc_shape.pairs * (k + k * k)) / t
                    + 8
                    + rodc_shape.per_thread * (2 + iterations * 6)
            } else {
                0
            };
        let mut spd = options.max_steps_per_dispatch.max(1);
        if adapter.software {
            spd = spd.min((SOFTWARE_LOOP_BUDGET / loops_per_step).max(1));
        }
        Ok(Self {
            path,
            cfg,
            workgroups: workgroups.unwrap_or(items.len() as u32),
            items,
            groups,
            couplings,
            strands,
            steps_per_dispatch: spd,
        })
    }

    /// A one-line description of the kernel: path, threads, points per thread, workgroups,
    /// halo, steps per dispatch and the compiled-in terms.
    pub(crate) fn describe(&self) -> String {
        let c = &self.cfg;
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
            self.path,
            self.workgroups,
            c.threads,
            c.per_thread,
            if c.unroll { "" } else { " (loops)" },
            c.halo,
            if c.exchange_steps > 1 {
                format!(" (exchange every {} steps)", c.exchange_steps)
            } else {
                String::new()
            },
            self.steps_per_dispatch,
            c.flags.join(", ")
        )
    }
}

/// The rods bindings couple, as groups (connected components, each in rod order, ordered by
/// their first rod); every rod is in one, alone when unbound. Fails for a binding to a rod
/// that does not exist, to the rod itself, or groups of more than four rods (one workgroup's
/// `GROUP_MAX`).
pub(crate) fn coupled_groups(rods: &[GpuRodInput]) -> Result<Vec<Vec<usize>>, GpuError> {
    let mut root: Vec<usize> = (0..rods.len()).collect();
    fn find(root: &mut [usize], mut r: usize) -> usize {
        while root[r] != r {
            root[r] = root[root[r]];
            r = root[r];
        }
        r
    }
    for (inner, rod) in rods.iter().enumerate() {
        if let Some(b) = &rod.binding {
            if b.outer >= rods.len() || b.outer == inner {
                return Err(GpuError::InvalidInput(format!(
                    "rod {inner}: bound to rod {} (the simulation has rods 0..{}, and a rod cannot be bound to itself)",
                    b.outer,
                    rods.len()
                )));
            }
            let (a, o) = (find(&mut root, inner), find(&mut root, b.outer));
            root[a.max(o)] = a.min(o);
        }
    }
    // Rod contact couples every rod that has it with every other.
    let touching: Vec<usize> = (0..rods.len())
        .filter(|&r| rods[r].rod_contact.is_some())
        .collect();
    for w in touching.windows(2) {
        let (a, b) = (find(&mut root, w[0]), find(&mut root, w[1]));
        root[a.max(b)] = a.min(b);
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut group_of = vec![usize::MAX; rods.len()];
    for r in 0..rods.len() {
        let top = find(&mut root, r);
        if group_of[top] == usize::MAX {
            group_of[top] = groups.len();
            groups.push(Vec::new());
        }
        groups[group_of[top]].push(r);
    }
    if let Some(g) = groups.iter().find(|g| g.len() > 4) {
        return Err(GpuError::InvalidInput(format!(
            "rods {g:?} are bound together or touch each other: the GPU couples at most 4 rods in one group"
        )));
    }
    Ok(groups)
}

/// Each item's part in a binding ([`CouplingG`]), with the outer rod named by its item, and each
/// outer (inner) rod's first entry in its workgroup's outer (inner) exchange arrays, after the
/// group's earlier outer (inner) rods.
fn coupling_of_items(rods: &[GpuRodInput], items: &[ItemG], groups: &[[u32; 2]]) -> Vec<CouplingG> {
    let item_of = |rod: usize| items.iter().position(|it| it.rod as usize == rod);
    let mut out = vec![
        CouplingG {
            outer: NONE,
            ..CouplingG::default()
        };
        items.len()
    ];
    for (k, it) in items.iter().enumerate() {
        if let Some(b) = &rods[it.rod as usize].binding
            && let Some(o) = item_of(b.outer)
        {
            out[k].outer = o as u32;
            out[k].role |= 1 | if b.two_way { 4 } else { 0 };
            out[k].capture = b.capture;
            out[k].correction = b.offset_correction;
            out[o].role |= 2;
        }
    }
    for &[first, count] in groups {
        let (mut outer, mut inner) = (0, 0);
        for k in first as usize..(first + count) as usize {
            if out[k].role & 2 != 0 {
                out[k].xo = outer;
                outer += items[k].n + 1;
            }
            if out[k].role & 1 != 0 {
                out[k].xi = inner;
                inner += items[k].n + 1;
            }
        }
    }
    out
}

/// Contacts one thread keeps for its step's sweeps (`RC_CAP`): the step's contacts are listed
/// and dealt out over the workgroup's threads in turn, so the workgroup holds this many times
/// its threads; a step that finds more is reported (`GpuError::InvalidInput` at the next read).
pub(crate) const RODC_PER_THREAD: u32 = 16;

/// Segments per bounding sphere of the GPU's broad phase (`RC_K`). The CPU's
/// `segments_per_sphere` is not taken: spheres only cull, so any size finds the contacts of
/// testing every segment pair (collide rods.rs), and one thread tests a sphere pair's
/// segments, which wants fewer, longer spheres than the CPU's loop over pairs: with 8, the
/// knot's tightened core has ~4 times fewer pairs than with 4 and its arrays fit the H100's
/// workgroup memory.
pub(crate) const RODC_SEGMENTS_PER_SPHERE: u32 = 8;

/// Each item's part in rod contact ([`StrandG`]): its first entries in its workgroup's point and
/// sphere arrays (after the group's earlier rods), its bounding spheres, and its self-contact
/// skip as the CPU computes it (`cosserat_collide::RodCollider::self_skip_for` on the chain of
/// radius `r + margin / 2`), from the rod's initial mean segment length.
fn strands_of_items(
    rods: &[GpuRodInput],
    items: &[ItemG],
    groups: &[[u32; 2]],
    per_sphere: u32,
) -> Vec<StrandG> {
    let mut out = vec![StrandG::default(); items.len()];
    for &[first, count] in groups {
        let (mut xp, mut xs) = (0, 0);
        for k in first as usize..(first + count) as usize {
            let rod = &rods[items[k].rod as usize];
            let Some(c) = rod.rod_contact else { continue };
            let n = items[k].n;
            let half = 0.5 * c.margin;
            let pts = &rod.state.positions;
            let len: f64 = pts
                .windows(2)
                .map(|w| f64::from((w[1] - w[0]).norm()))
                .sum();
            let h = len / f64::from(n);
            let radius = f64::from(rod.params.radius + half);
            let skip = if !c.self_collisions {
                NONE
            } else if h.is_nan() || h <= 0.0 {
                n
            } else {
                ((2.0 * radius / h).floor() as u32 + 1).clamp(1, n)
            };
            let spheres = n.div_ceil(per_sphere);
            out[k] = StrandG {
                xp,
                xs,
                spheres,
                skip,
                radius: rod.params.radius,
                half_margin: half,
                mu_s: c.static_friction,
                mu_k: c.kinetic_friction,
            };
            xp += n + 1;
            xs += spheres;
        }
    }
    out
}

/// An item's end bits ([`ItemG::flags`]): which ends hold their point and which are clamped.
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

/// Scenes and adapters to plan for without a GPU.
#[cfg(test)]
pub(crate) mod fixtures {
    use crate::device::AdapterSummary;
    use crate::{EndCondition, GpuRodInput};
    use cosserat_model::Material;
    use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};

    /// Pinned rods of the given numbers of elements.
    pub(crate) fn rods(sizes: &[usize]) -> Vec<GpuRodInput> {
        let spec = RodSpec::new(Material::new(1.0e6, 1.0e6 / 3.0, 1100.0, 0.005));
        sizes
            .iter()
            .map(|&n| {
                let pts = straight_polyline([0.0; 3], [1.0, 0.0, 0.0], 0.01 * n as f64, n);
                let (state, params) = build_rod::<f32>(&pts, &spec).expect("valid rod");
                GpuRodInput {
                    state,
                    params,
                    ends: [EndCondition::pinned(), EndCondition::free()],
                    loads: vec![],
                    wall: None,
                    guide: None,
                    binding: None,
                    rod_contact: None,
                }
            })
            .collect()
    }

    /// An H100 as the backend sees it: 132 co-resident workgroups, subgroups of 32.
    pub(crate) fn h100() -> AdapterSummary {
        AdapterSummary {
            name: "NVIDIA H100 80GB HBM3".into(),
            driver: String::new(),
            vendor: 0x10de,
            software: false,
            timestamps: false,
            co_resident_workgroups: Some(132),
            max_workgroup_storage: 49152,
            subgroup_size: Some(32),
            coherent: true,
        }
    }

    /// lavapipe as the backend sees it: no co-residency, no fixed subgroup size.
    pub(crate) fn lavapipe() -> AdapterSummary {
        AdapterSummary {
            name: "llvmpipe (LLVM 17.0.6, 256 bits)".into(),
            vendor: 0x10005,
            software: true,
            co_resident_workgroups: None,
            subgroup_size: None,
            coherent: false,
            ..h100()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::{h100, lavapipe, rods};
    use super::*;
    use crate::{Ordering, SolverSettings};
    use cosserat_model::Vec3;

    fn settings() -> SolverSettings<f32> {
        SolverSettings {
            dt: 2e-5,
            iterations: 10,
            ordering: Ordering::RedBlack,
            extensible: false,
            gravity: Vec3::new(0.0, 0.0, -9.81),
            divergence_strain: 0.5,
        }
    }

    fn plan(sizes: &[usize], adapter: &AdapterSummary) -> Plan {
        let limits = wgpu::Limits {
            max_compute_workgroup_storage_size: adapter.max_workgroup_storage,
            ..wgpu::Limits::default()
        };
        Plan::new(
            &rods(sizes),
            &settings(),
            &GpuOptions::default(),
            &Tuning::PRODUCTION,
            adapter,
            &limits,
        )
        .expect("a plan")
    }

    /// The automatic choice follows [`crate::GpuSimulation::new`]'s rules.
    #[test]
    fn the_path_follows_rod_length_and_adapter() {
        let short = plan(&[100], &h100());
        assert_eq!(short.path, KernelPath::SingleWorkgroup);
        assert_eq!((short.cfg.threads, short.cfg.per_thread), (64, 2));

        let long = plan(&[1000], &h100());
        assert_eq!(long.path, KernelPath::MultiWorkgroup);
        for flag in ["GRID", "NBR_SYNC", "COHERENT", "FAST", "REGC"] {
            assert!(long.cfg.flags.contains(&flag), "{}", long.describe());
        }
        // Windows cover the rod, each overlapping its neighbours by the halo.
        let items = &long.items;
        assert!(items.len() > 1 && items.len() <= 132);
        assert_eq!((items[0].o0, items.last().map(|i| i.o1)), (0, Some(1001)));
        for (k, pair) in items.windows(2).enumerate() {
            assert_eq!(pair[0].o1, pair[1].o0);
            assert_eq!((pair[0].right, pair[1].left), (k as u32 + 1, k as u32));
            assert_eq!(pair[1].w0, pair[1].o0 - long.cfg.halo);
        }

        // Without co-residency: one workgroup up to 16 points per thread, then one dispatch
        // per exchange period; a software adapter also caps the steps per dispatch.
        let soft = plan(&[1000], &lavapipe());
        assert_eq!(soft.path, KernelPath::SingleWorkgroup);
        assert!(soft.steps_per_dispatch < GpuOptions::default().max_steps_per_dispatch);
        let longest = plan(&[5000], &lavapipe());
        assert_eq!(longest.path, KernelPath::DispatchPerStep);
        assert!(longest.cfg.flags.contains(&"PERSTEP"));
    }

    /// Rods in contact (the knot's two strands of 256 elements) share one workgroup on the
    /// single-workgroup path, their arrays within the adapter's workgroup memory, each rod on
    /// its own run of threads; the items name their first entries in the group's arrays.
    #[test]
    fn rods_in_contact_share_one_workgroup() {
        for adapter in [h100(), lavapipe()] {
            let limits = wgpu::Limits {
                max_compute_workgroup_storage_size: adapter.max_workgroup_storage,
                ..wgpu::Limits::default()
            };
            let mut rods = rods(&[256, 256]);
            for r in &mut rods {
                r.rod_contact = Some(crate::GpuRodContact {
                    self_collisions: true,
                    static_friction: 0.4,
                    kinetic_friction: 0.3,
                    margin: 2e-4,
                });
            }
            let p = Plan::new(
                &rods,
                &settings(),
                &GpuOptions::default(),
                &Tuning::PRODUCTION,
                &adapter,
                &limits,
            )
            .expect("a plan");
            eprintln!("{}: {}", adapter.name, p.describe());
            assert_eq!(p.path, KernelPath::SingleWorkgroup);
            assert!(p.cfg.flags.contains(&"RODC") && !p.cfg.flags.contains(&"BIND"));
            assert_eq!((p.workgroups, p.groups.clone()), (1, vec![[0, 2]]));
            let r = p.cfg.rodc;
            assert_eq!((r.points, r.spheres, r.per_sphere), (514, 64, 8));
            let lanes = 257u32.div_ceil(p.cfg.per_thread);
            assert_eq!((p.items[0].lane0, p.items[1].lane0), (0, lanes));
            assert!(2 * lanes <= p.cfg.threads);
            let s = &p.strands;
            assert_eq!((s[0].xp, s[1].xp, s[0].xs, s[1].xs), (0, 257, 0, 32));
            // 1 cm elements of a 5 mm rod with a 0.2 mm margin: ⌊2 · 5.1 / 10⌋ + 1.
            assert_eq!(s[0].skip, 2);
        }
    }

    /// Many short rods go one per subgroup, four per workgroup, where the subgroup size is fixed.
    #[test]
    fn many_short_rods_take_the_subgroup_layout() {
        let many = vec![8; 300];
        let p = plan(&many, &h100());
        assert_eq!(p.path, KernelPath::SingleWorkgroup);
        assert!(p.cfg.flags.contains(&"SUBGROUP") && p.cfg.flags.contains(&"SHFL"));
        assert_eq!((p.cfg.group, p.cfg.threads, p.workgroups), (32, 128, 75));
        assert_eq!(p.items.len(), 300);
        let p = plan(&many, &lavapipe());
        assert!(!p.cfg.flags.contains(&"SUBGROUP"));
        assert_eq!(p.workgroups, 300);
    }
}
