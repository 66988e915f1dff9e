//! Kernel variants for measurement only: the benchmark's side-by-side comparisons
//! (`examples/gpu_bench.rs`) and the tests that hold every variant to the CPU.
//!
//! Nothing here is reached from [`GpuSimulation::new`] or [`GpuSimulation::on_device`]: they
//! plan with `Tuning::PRODUCTION` and never build a [`KernelVariant`]. A variant either picks
//! other values of the production knobs (`plan::Tuning`, whose production values were chosen by
//! these very measurements), or switches on code that exists only to be measured
//! ([`Measurement`]: the impulse by `inverseSqrt` alone, constraint constants read from storage
//! in every sweep, per-thread loops left as WGSL loops). The second kind is applied to a
//! finished plan here, so the production planner contains none of it; its WGSL stays behind
//! `//#if RSQRT` / `//#if SWEEP_LOADS` blocks that a production kernel never enables.

use crate::device::Gpu;
use crate::plan::{Plan, Tuning};
use crate::sim::validate;
use crate::{GpuError, GpuOptions, GpuRodInput, GpuSimulation, SolverSettings};

/// Kernel variants the benchmark compares (see `examples/gpu_bench.rs`); measurement only, not
/// part of the stable API. [`KernelVariant::default`] plans exactly what
/// [`GpuSimulation::new`] plans.
#[doc(hidden)]
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KernelVariant {
    /// Unroll the per-thread loops at composition time, so that a thread's points live in
    /// registers (default). `false` emits WGSL loops over dynamically indexed private arrays
    /// (measurement only).
    pub unroll: bool,
    /// Allow the subgroup layout for short rods (one rod per subgroup, no workgroup barriers)
    /// where the adapter has `SUBGROUP` and a fixed subgroup size (default).
    pub subgroups: bool,
    /// Fewest rods for which the subgroup layout is used (default 256).
    pub subgroup_min_rods: u32,
    /// Compute the constraint impulse with one `inverseSqrt` instead of the CPU's `sqrt` and
    /// division (measurement only; default off).
    pub rsqrt: bool,
    /// Read rest lengths and inverse masses from storage in every constraint sweep instead of
    /// keeping them in registers for the dispatch (measurement only; default off).
    pub sweep_loads: bool,
    /// Rods per workgroup in the subgroup layout (default 4: 128 invocations on NVIDIA).
    pub rods_per_workgroup: u32,
    /// Most points per invocation for which the subgroup layout is used (default 8).
    pub subgroup_points_per_thread: u32,
    /// Threads per workgroup of the multi-workgroup path (default 128, capped by
    /// [`GpuOptions::max_threads`]).
    pub multi_threads: u32,
    /// Points per thread of the multi-workgroup windows; 0 (default) picks the fewest (even)
    /// that leave each window owning at least one halo and 64 points.
    pub multi_points_per_thread: u32,
    /// Steps between halo exchanges of the multi-workgroup paths (default 3).
    pub exchange_steps: u32,
    /// Multi-workgroup path: each workgroup waits only for its two neighbours' flags instead of
    /// a grid-wide arrival counter (default).
    pub neighbour_sync: bool,
    /// Multi-workgroup path: exchange halos as vec4s through a `@coherent` buffer where the
    /// adapter allows it (default).
    pub coherent_exchange: bool,
    /// Multi-workgroup windows of one subgroup whose threads exchange their boundary points by
    /// subgroup shuffles (default off).
    pub shuffle_windows: bool,
    /// Keep the per-point and per-element parameters in registers for the whole dispatch
    /// (default).
    pub register_constants: bool,
    /// Constraint impulse from one `inverseSqrt` with the per-constraint factors in registers
    /// (default).
    pub fast_impulse: bool,
    /// Compute the reactions at held ends (default). `false` leaves them out of a kernel without
    /// clamps, to measure what they cost (measurement only).
    pub reactions: bool,
}

/// The knobs of a [`KernelVariant`] that switch on code no production kernel contains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Measurement {
    unroll: bool,
    rsqrt: bool,
    sweep_loads: bool,
    reactions: bool,
}

impl Measurement {
    /// None of the measurement-only code.
    const NONE: Self = Self {
        unroll: true,
        rsqrt: false,
        sweep_loads: false,
        reactions: true,
    };

    /// Switches the measurement-only code on in a production `plan`. `RSQRT` and `SWEEP_LOADS`
    /// replace parts of the distance-constraint sweep, so they apply to inextensible rods only;
    /// `SWEEP_LOADS` reads the constants `FAST` keeps in registers, so it turns `FAST` off.
    fn apply(&self, plan: &mut Plan, extensible: bool) {
        plan.cfg.unroll = self.unroll;
        if !self.reactions && !plan.cfg.flags.contains(&"CLAMP") {
            plan.cfg.flags.retain(|f| *f != "REACT");
        }
        if extensible {
            return;
        }
        let flags = &mut plan.cfg.flags;
        let mut extra = Vec::new();
        if self.sweep_loads {
            extra.push("SWEEP_LOADS");
            flags.retain(|f| *f != "FAST");
        }
        if self.rsqrt {
            extra.push("RSQRT");
        }
        // Before the register flags, where the kernel description has always listed them.
        let at = flags
            .iter()
            .position(|f| *f == "FAST" || *f == "REGC")
            .unwrap_or(flags.len());
        for (k, flag) in extra.into_iter().enumerate() {
            flags.insert(at + k, flag);
        }
    }
}

impl KernelVariant {
    /// This variant's production knobs and measurement-only knobs.
    fn split(&self) -> (Tuning, Measurement) {
        let Self {
            unroll,
            subgroups,
            subgroup_min_rods,
            rsqrt,
            sweep_loads,
            rods_per_workgroup,
            subgroup_points_per_thread,
            multi_threads,
            multi_points_per_thread,
            exchange_steps,
            neighbour_sync,
            coherent_exchange,
            shuffle_windows,
            register_constants,
            fast_impulse,
            reactions,
        } = self.clone();
        (
            Tuning {
                subgroups,
                subgroup_min_rods,
                rods_per_workgroup,
                subgroup_points_per_thread,
                multi_threads,
                multi_points_per_thread,
                exchange_steps,
                neighbour_sync,
                coherent_exchange,
                shuffle_windows,
                register_constants,
                fast_impulse,
            },
            Measurement {
                unroll,
                rsqrt,
                sweep_loads,
                reactions,
            },
        )
    }
}

impl Default for KernelVariant {
    /// The production tuning with no measurement-only code.
    fn default() -> Self {
        let Tuning {
            subgroups,
            subgroup_min_rods,
            rods_per_workgroup,
            subgroup_points_per_thread,
            multi_threads,
            multi_points_per_thread,
            exchange_steps,
            neighbour_sync,
            coherent_exchange,
            shuffle_windows,
            register_constants,
            fast_impulse,
        } = Tuning::PRODUCTION;
        let Measurement {
            unroll,
            rsqrt,
            sweep_loads,
            reactions,
        } = Measurement::NONE;
        Self {
            unroll,
            subgroups,
            subgroup_min_rods,
            rsqrt,
            sweep_loads,
            rods_per_workgroup,
            subgroup_points_per_thread,
            multi_threads,
            multi_points_per_thread,
            exchange_steps,
            neighbour_sync,
            coherent_exchange,
            shuffle_windows,
            register_constants,
            fast_impulse,
            reactions,
        }
    }
}

impl GpuSimulation {
    /// [`Self::new`] with a kernel variant; for the benchmark's side-by-side measurements.
    #[doc(hidden)]
    pub fn with_variant(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
        variant: KernelVariant,
    ) -> Result<Self, GpuError> {
        validate(&rods, settings)?;
        let gpu = Gpu::acquire(&options)?;
        let (tuning, measurement) = variant.split();
        let mut plan = Plan::new(
            &rods,
            settings,
            &options,
            &tuning,
            &gpu.adapter,
            &gpu.limits,
        )?;
        measurement.apply(&mut plan, settings.extensible);
        Self::build(gpu, plan, rods, settings, &options)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::fixtures::{h100, rods};
    use crate::{Ordering, SolverSettings};
    use cosserat_model::Vec3;

    fn plan(variant: &KernelVariant, extensible: bool) -> Plan {
        let settings = SolverSettings {
            dt: 2e-5,
            iterations: 10,
            ordering: Ordering::RedBlack,
            extensible,
            gravity: Vec3::new(0.0, 0.0, -9.81),
            divergence_strain: 0.5,
        };
        let (tuning, measurement) = variant.split();
        let mut plan = Plan::new(
            &rods(&[100, 1000]),
            &settings,
            &GpuOptions::default(),
            &tuning,
            &h100(),
            &wgpu::Limits::default(),
        )
        .expect("a plan");
        measurement.apply(&mut plan, extensible);
        plan
    }

    /// The default variant is the production plan: the benchmark's baseline is what runs.
    #[test]
    fn the_default_variant_is_production() {
        let (tuning, measurement) = KernelVariant::default().split();
        assert_eq!(tuning, Tuning::PRODUCTION);
        assert_eq!(measurement, Measurement::NONE);
    }

    /// Measurement-only flags reach the kernel only through a variant, in inextensible mode,
    /// before the register flags.
    #[test]
    fn measurement_code_comes_only_from_variants() {
        let production = plan(&KernelVariant::default(), false);
        for flag in ["RSQRT", "SWEEP_LOADS"] {
            assert!(!production.cfg.flags.contains(&flag));
        }
        assert!(production.cfg.unroll);
        let all = KernelVariant {
            unroll: false,
            rsqrt: true,
            sweep_loads: true,
            ..KernelVariant::default()
        };
        let p = plan(&all, false);
        let tail = &p.cfg.flags[p.cfg.flags.len() - 3..];
        assert_eq!(tail, ["SWEEP_LOADS", "RSQRT", "REGC"], "{}", p.describe());
        assert!(!p.cfg.unroll && p.describe().contains("(loops)"));
        let rsqrt = plan(
            &KernelVariant {
                rsqrt: true,
                ..KernelVariant::default()
            },
            false,
        );
        let tail = &rsqrt.cfg.flags[rsqrt.cfg.flags.len() - 3..];
        assert_eq!(tail, ["RSQRT", "FAST", "REGC"]);
        let extensible = plan(&all, true);
        for flag in ["RSQRT", "SWEEP_LOADS", "FAST"] {
            assert!(!extensible.cfg.flags.contains(&flag));
        }
    }
}
