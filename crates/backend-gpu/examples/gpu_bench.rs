//! GPU benchmark: the paper's free-space test (section 3.1) and a many-rods throughput test, with
//! the agreement with the CPU backend measured next to every figure.
//!
//! Usage: `gpu_bench OUT.json [--quick | --focus | --host]` (`--host`: only the single step with
//! readback, three rounds). The free-space test is a straight horizontal rod of
//! 1 cm elements pinned at one end, released swinging at 1 rad/s about the pin under gravity,
//! 10 red–black constraint iterations per step, dt = 20 µs. (A release from rest moves the rod
//! by only a few f32 ulps in the 100 steps compared with the CPU; the swing makes that
//! comparison measure the dynamics. The work per step is the same.)
//!
//! For every size, kernel path and steps-per-dispatch `k` it reports
//! - GPU time per step from timestamp queries around each batch of `k` steps;
//! - host-visible time per step: `step(k)` plus `read_positions()`, wall clock, divided by `k`
//!   (for `k = 1` that is one step including the readback of all positions);
//! - the largest GPU–CPU point discrepancy after 100 steps relative to the largest displacement.
//!
//! A first section measures kernel variants side by side (unrolled per-thread loops against
//! WGSL loops, constraint constants in registers against storage loads, subgroup against
//! workgroup layout, threads per workgroup, rods per workgroup), so that one run on the device
//! says where the time goes.

use cosserat_backend_cpu::{CpuRod, EndCondition, Ordering, SolverSettings, step_rod};
use cosserat_backend_gpu::{
    GpuError, GpuOptions, GpuRodInput, GpuSimulation, KernelPath, KernelVariant,
};
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Vec3};
use serde_json::{Value, json};
use std::time::Instant;

/// Agreement required for a run to count as passing (as in `tests/gpu_vs_cpu.rs`).
const REL_TOL: f64 = 5e-3;
const FLOOR_ULPS: f64 = 16.0;
const CHECK_STEPS: u32 = 100;

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

fn pendulum(n: usize, angle: f64) -> GpuRodInput {
    let dir = [angle.cos(), angle.sin(), 0.0];
    let pts = straight_polyline([0.0, 0.0, 0.0], dir, 0.01 * n as f64, n);
    let (mut state, params) = build_rod::<f32>(
        &pts,
        &RodSpec::new(Material::new(1.0e6, 1.0e6 / 3.0, 1100.0, 0.005)),
    )
    .expect("valid rod");
    let d = Vec3::new(dir[0] as f32, dir[1] as f32, 0.0);
    let omega = d.cross(&Vec3::z()).normalize();
    for (v, r) in state.velocities.iter_mut().zip(&state.positions) {
        *v = omega.cross(r);
    }
    for (w, q) in state.angular_velocities.iter_mut().zip(&state.frames) {
        *w = cosserat_model::quat::rotate_inv(q, &omega);
    }
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
}

/// CPU positions after `steps` steps, rods spread over the machine's cores.
fn cpu_positions(rods: &[GpuRodInput], steps: u32) -> Vec<Vec<Vec3<f32>>> {
    let s = settings();
    let threads = std::thread::available_parallelism().map_or(4, |n| n.get());
    let chunk = rods.len().div_ceil(threads).max(1);
    let mut out = vec![Vec::new(); rods.len()];
    std::thread::scope(|scope| {
        for (part, slots) in rods.chunks(chunk).zip(out.chunks_mut(chunk)) {
            scope.spawn(move || {
                for (rod, slot) in part.iter().zip(slots) {
                    let mut cpu = CpuRod::new(
                        rod.state.clone(),
                        rod.params.clone(),
                        rod.ends.clone(),
                        rod.loads.clone(),
                    );
                    for k in 0..steps as u64 {
                        step_rod(&mut cpu, &s, k as f64 * s.dt as f64, 0, k)
                            .expect("CPU oracle diverged");
                    }
                    *slot = cpu.state.positions;
                }
            });
        }
    });
    out
}

/// Worst relative discrepancy over the rods, and whether every rod passes.
fn agreement(rods: &[GpuRodInput], cpu: &[Vec<Vec3<f32>>], gpu: &[Vec<[f32; 3]>]) -> (f64, bool) {
    let mut worst: f64 = 0.0;
    let mut ok = true;
    for ((rod, c), g) in rods.iter().zip(cpu).zip(gpu) {
        let start = &rod.state.positions;
        let disp = start
            .iter()
            .zip(c)
            .map(|(a, b)| (b - a).cast::<f64>().norm())
            .fold(0.0, f64::max);
        let extent = start
            .iter()
            .map(|a| a.cast::<f64>().norm())
            .fold(0.0, f64::max);
        let err = c
            .iter()
            .zip(g)
            .map(|(c, g)| {
                (Vec3::new(g[0] as f64, g[1] as f64, g[2] as f64) - c.cast::<f64>()).norm()
            })
            .fold(0.0, f64::max);
        worst = worst.max(err / disp);
        ok &= err <= REL_TOL * disp + FLOOR_ULPS * f32::EPSILON as f64 * extent;
    }
    (worst, ok)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

struct Measured {
    kernel: String,
    gpu_us_per_step: Option<f64>,
    host_us_per_step: f64,
    agreement: f64,
    pass: bool,
}

/// One configuration: agreement after 100 steps, then GPU and host-visible timing.
#[allow(clippy::too_many_arguments)]
fn measure(
    rods: &[GpuRodInput],
    cpu: &[Vec<Vec3<f32>>],
    path: KernelPath,
    k: u32,
    budget_steps: u32,
    max_threads: u32,
    variant: &KernelVariant,
    host: bool,
) -> Result<Measured, GpuError> {
    let opts = GpuOptions {
        path,
        timestamps: true,
        max_threads,
        ..GpuOptions::default()
    };
    let mut sim =
        GpuSimulation::with_variant(rods.to_vec(), &settings(), opts.clone(), variant.clone())?;
    let kernel = sim.kernel_description();
    let mut done = 0;
    while done < CHECK_STEPS {
        let kk = k.min(CHECK_STEPS - done);
        sim.step(kk)?;
        done += kk;
    }
    let g = sim.read_positions()?;
    let (agreement, pass) = agreement(rods, cpu, &g);
    // GPU time: batches of k submitted back to back, timed by timestamps around each batch.
    sim.take_gpu_time()?;
    let batches = (budget_steps / k).clamp(3, 400);
    for _ in 0..batches {
        sim.step(k)?;
    }
    let gpu = sim.take_gpu_time()?.map(|t| t * 1e6 / (batches * k) as f64);
    sim.check()?;
    drop(sim);
    if !host {
        return Ok(Measured {
            kernel,
            gpu_us_per_step: gpu,
            host_us_per_step: f64::NAN,
            agreement,
            pass,
        });
    }
    // Host-visible: a simulation without timestamp queries, step(k) + read_positions().
    let mut sim = GpuSimulation::with_variant(
        rods.to_vec(),
        &settings(),
        GpuOptions {
            timestamps: false,
            ..opts
        },
        variant.clone(),
    )?;
    sim.step(k)?;
    sim.read_positions()?;
    let reps = (budget_steps / k).clamp(5, 60);
    let mut times = Vec::with_capacity(reps as usize);
    for _ in 0..reps {
        let t = Instant::now();
        sim.step(k)?;
        sim.read_positions()?;
        times.push(t.elapsed().as_secs_f64() * 1e6 / k as f64);
    }
    Ok(Measured {
        kernel,
        gpu_us_per_step: gpu,
        host_us_per_step: median(times),
        agreement,
        pass,
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(out_path) = args.get(1).filter(|a| !a.starts_with("--")).cloned() else {
        eprintln!("usage: gpu_bench OUT.json [--quick | --focus | --host]");
        std::process::exit(2);
    };
    let quick = args.iter().any(|a| a == "--quick");
    if args.iter().any(|a| a == "--host") {
        // The single step with readback only, three rounds in a row to show the spread.
        let rounds: Vec<Value> = (0..3)
            .map(|round| {
                println!("\nround {}", round + 1);
                host_section()
            })
            .collect();
        let doc =
            json!({"host_rounds": rounds, "date": std::env::var("BENCH_DATE").unwrap_or_default()});
        std::fs::write(&out_path, serde_json::to_string_pretty(&doc).expect("json"))
            .expect("write output");
        eprintln!("wrote {out_path}");
        return;
    }
    if args.iter().any(|a| a == "--focus") {
        let doc = focus_section();
        std::fs::write(&out_path, serde_json::to_string_pretty(&doc).expect("json"))
            .expect("write output");
        eprintln!("wrote {out_path}");
        return;
    }
    let (sizes, ks, rod_counts, rod_sizes): (Vec<usize>, Vec<u32>, Vec<usize>, Vec<usize>) =
        if quick {
            (vec![128, 1000], vec![1, 10], vec![1, 10], vec![64])
        } else {
            (
                vec![128, 256, 512, 1000, 2048, 4096, 8192, 16384],
                vec![1, 10, 100],
                vec![1, 10, 100, 1000, 10_000],
                vec![64, 128, 512],
            )
        };
    // Probe the adapter once.
    let probe = match GpuSimulation::new(
        vec![pendulum(16, 0.0)],
        &settings(),
        GpuOptions {
            timestamps: true,
            ..GpuOptions::default()
        },
    ) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let adapter = probe.adapter().clone();
    drop(probe);
    eprintln!(
        "adapter: {} ({}), timestamps: {}",
        adapter.name, adapter.driver, adapter.timestamps
    );

    let variants = variant_section(quick);

    let mut free_space = Vec::new();
    println!(
        "| elements | path | steps/dispatch | GPU µs/step | host µs/step (incl. readback) | GPU–CPU discrepancy / displacement |"
    );
    println!("|---|---|---|---|---|---|");
    for &n in &sizes {
        let rods = vec![pendulum(n, 0.0)];
        let cpu = cpu_positions(&rods, CHECK_STEPS);
        let points = n as u32 + 1;
        for path in [
            KernelPath::SingleWorkgroup,
            KernelPath::MultiWorkgroup,
            KernelPath::DispatchPerStep,
        ] {
            // One workgroup beyond 32 points per thread is spilling registers for no purpose.
            if path == KernelPath::SingleWorkgroup && points > 256 * 32 {
                continue;
            }
            for &k in &ks {
                let budget = if quick { 20 } else { 2000 };
                let row = match measure(
                    &rods,
                    &cpu,
                    path,
                    k,
                    budget,
                    256,
                    &KernelVariant::default(),
                    true,
                ) {
                    Ok(m) => {
                        println!(
                            "| {n} | {path} | {k} | {} | {:.1} | {:.1e}{} |",
                            m.gpu_us_per_step.map_or("-".into(), |g| format!("{g:.2}")),
                            m.host_us_per_step,
                            m.agreement,
                            if m.pass { "" } else { " FAIL" }
                        );
                        json!({"elements": n, "path": path.to_string(), "steps_per_dispatch": k, "kernel": m.kernel,
                               "gpu_us_per_step": m.gpu_us_per_step, "host_us_per_step": m.host_us_per_step,
                               "cpu_discrepancy_rel": m.agreement, "cpu_agreement_pass": m.pass})
                    }
                    Err(GpuError::PathUnavailable { reason, .. }) => {
                        eprintln!("{n} elements, {path}: unavailable: {reason}");
                        json!({"elements": n, "path": path.to_string(), "steps_per_dispatch": k, "unavailable": reason})
                    }
                    Err(e) => {
                        println!("| {n} | {path} | {k} | error: {e} | | |");
                        json!({"elements": n, "path": path.to_string(), "steps_per_dispatch": k, "error": e.to_string()})
                    }
                };
                let unavailable = row.get("unavailable").is_some();
                free_space.push(row);
                if unavailable {
                    break;
                }
            }
        }
    }

    let mut many = Vec::new();
    println!(
        "\n| rods | elements | GPU µs/step | steps/s (GPU) | host µs/step, 100 steps/dispatch | worst discrepancy | all rods pass |"
    );
    println!("|---|---|---|---|---|---|---|");
    for &e in &rod_sizes {
        for &count in &rod_counts {
            // Each rod points its own way, so a mix-up of rods would show in the comparison.
            let rods: Vec<GpuRodInput> = (0..count)
                .map(|i| pendulum(e, i as f64 * 2.399963))
                .collect();
            let cpu = cpu_positions(&rods, CHECK_STEPS);
            let k = if quick { 10 } else { 100 };
            let row = match measure(
                &rods,
                &cpu,
                KernelPath::SingleWorkgroup,
                k,
                if quick { 20 } else { 1000 },
                256,
                &KernelVariant::default(),
                true,
            ) {
                Ok(m) => {
                    let sps = m.gpu_us_per_step.map(|g| 1e6 / g);
                    println!(
                        "| {count} | {e} | {} | {} | {:.1} | {:.1e} | {} |",
                        m.gpu_us_per_step.map_or("-".into(), |g| format!("{g:.2}")),
                        sps.map_or("-".into(), |s| format!("{s:.0}")),
                        m.host_us_per_step,
                        m.agreement,
                        m.pass
                    );
                    json!({"rods": count, "elements": e, "steps_per_dispatch": k, "kernel": m.kernel, "gpu_us_per_step": m.gpu_us_per_step,
                           "steps_per_s_gpu": sps, "host_us_per_step": m.host_us_per_step, "cpu_discrepancy_rel_worst": m.agreement, "all_rods_pass": m.pass})
                }
                Err(err) => {
                    println!("| {count} | {e} | error: {err} | | | | false |");
                    json!({"rods": count, "elements": e, "error": err.to_string()})
                }
            };
            many.push(row);
        }
    }
    let doc: Value = json!({
        "adapter": adapter.name, "driver": adapter.driver, "timestamps": adapter.timestamps,
        "co_resident_workgroups": adapter.co_resident_workgroups,
        "date": std::env::var("BENCH_DATE").unwrap_or_default(),
        "command": args.join(" "),
        "scene": "free-space pendulum: 1 cm elements, pinned end, released swinging at 1 rad/s, gravity, dt 20 us, 10 red-black iterations, f32",
        "agreement": format!("max |r_gpu - r_cpu| / max CPU displacement after {CHECK_STEPS} steps; pass: <= {REL_TOL} + {FLOOR_ULPS} f32 ulp of the extent"),
        "subgroup_size": adapter.subgroup_size,
        "variants": variants, "free_space": free_space, "many_rods": many,
    });
    std::fs::write(&out_path, serde_json::to_string_pretty(&doc).expect("json"))
        .expect("write output");
    eprintln!("wrote {out_path}");
}

/// Kernel variants side by side, GPU time at 100 steps per dispatch (10 in quick mode).
fn variant_section(quick: bool) -> Vec<Value> {
    let k = if quick { 10 } else { 100 };
    let budget = if quick { 20 } else { 1000 };
    // The kernel before the current defaults (halo exchange every step through a grid-wide
    // counter, parameters read every step, the CPU's impulse formula), against which the
    // structural variants below are measured; the current default gets rows of its own.
    let base = KernelVariant {
        exchange_steps: 1,
        neighbour_sync: false,
        register_constants: false,
        fast_impulse: false,
        ..KernelVariant::default()
    };
    let workgroup = KernelVariant {
        subgroups: false,
        ..base.clone()
    };
    // The subgroup layout even for a single rod.
    let sub1 = KernelVariant {
        subgroup_min_rods: 1,
        ..base.clone()
    };
    let named = |name: &str, v: &KernelVariant| (name.to_string(), v.clone());
    let structure = [
        named(
            "loops, constants loaded per sweep",
            &KernelVariant {
                unroll: false,
                sweep_loads: true,
                ..workgroup.clone()
            },
        ),
        named(
            "loops",
            &KernelVariant {
                unroll: false,
                ..workgroup.clone()
            },
        ),
        named(
            "unrolled, constants loaded per sweep",
            &KernelVariant {
                sweep_loads: true,
                ..workgroup.clone()
            },
        ),
        named("unrolled (workgroup layout)", &workgroup),
        named(
            "unrolled, inverseSqrt impulse",
            &KernelVariant {
                rsqrt: true,
                ..workgroup.clone()
            },
        ),
        named("unrolled, subgroup layout", &sub1),
    ];
    // (label, elements, rods, path, max threads, variant)
    type Case = (String, usize, usize, KernelPath, u32, KernelVariant);
    let mut cases: Vec<Case> = Vec::new();
    for n in [128usize, 1000] {
        for (name, v) in &structure {
            cases.push((
                name.clone(),
                n,
                1,
                KernelPath::SingleWorkgroup,
                256,
                v.clone(),
            ));
        }
    }
    for threads in [128u32, 256, 512] {
        cases.push((
            format!("unrolled, {threads} threads max"),
            1000,
            1,
            KernelPath::SingleWorkgroup,
            threads,
            workgroup.clone(),
        ));
    }
    for threads in [64u32, 96, 128, 160, 192, 256] {
        let v = KernelVariant {
            multi_threads: threads,
            ..base.clone()
        };
        cases.push((
            format!("multi-workgroup, unrolled, {threads} threads"),
            1000,
            1,
            KernelPath::MultiWorkgroup,
            256,
            v.clone(),
        ));
        cases.push((
            format!("multi-workgroup, unrolled, {threads} threads, inverseSqrt impulse"),
            1000,
            1,
            KernelPath::MultiWorkgroup,
            256,
            KernelVariant { rsqrt: true, ..v },
        ));
    }
    for n in [512usize, 4096] {
        cases.push((
            "multi-workgroup, loops".into(),
            n,
            1,
            KernelPath::MultiWorkgroup,
            256,
            KernelVariant {
                unroll: false,
                ..base.clone()
            },
        ));
        for threads in [128u32, 256] {
            cases.push((
                format!("multi-workgroup, unrolled, {threads} threads"),
                n,
                1,
                KernelPath::MultiWorkgroup,
                256,
                KernelVariant {
                    multi_threads: threads,
                    ..base.clone()
                },
            ));
        }
    }
    // The current defaults and the steps between them and the previous kernel.
    let current = KernelVariant::default();
    for (name, n, path, v) in [
        (
            "default",
            1000usize,
            KernelPath::MultiWorkgroup,
            current.clone(),
        ),
        (
            "default, 96 threads",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                multi_threads: 96,
                ..current.clone()
            },
        ),
        (
            "default, exchange every step",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                exchange_steps: 1,
                ..current.clone()
            },
        ),
        (
            "default, grid-wide counter",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                neighbour_sync: false,
                ..current.clone()
            },
        ),
        (
            "default, parameters from storage",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                register_constants: false,
                ..current.clone()
            },
        ),
        (
            "default, CPU impulse formula",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                fast_impulse: false,
                ..current.clone()
            },
        ),
        (
            "default, exchange by atomic words",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                coherent_exchange: false,
                ..current.clone()
            },
        ),
        (
            "default, 2 steps per exchange",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                exchange_steps: 2,
                ..current.clone()
            },
        ),
        (
            "default (workgroup layout)",
            1000,
            KernelPath::SingleWorkgroup,
            KernelVariant {
                subgroups: false,
                ..current.clone()
            },
        ),
        (
            "default (workgroup layout)",
            128,
            KernelPath::SingleWorkgroup,
            KernelVariant {
                subgroups: false,
                ..current.clone()
            },
        ),
        (
            "default, no reactions",
            1000,
            KernelPath::MultiWorkgroup,
            KernelVariant {
                reactions: false,
                ..current.clone()
            },
        ),
        (
            "default (workgroup layout), no reactions",
            1000,
            KernelPath::SingleWorkgroup,
            KernelVariant {
                subgroups: false,
                reactions: false,
                ..current.clone()
            },
        ),
        (
            "default (workgroup layout), no reactions",
            128,
            KernelPath::SingleWorkgroup,
            KernelVariant {
                subgroups: false,
                reactions: false,
                ..current.clone()
            },
        ),
        ("default", 4096, KernelPath::MultiWorkgroup, current.clone()),
        (
            "default",
            16384,
            KernelPath::MultiWorkgroup,
            current.clone(),
        ),
    ] {
        cases.push((name.to_string(), n, 1, path, 256, v));
    }
    cases.push((
        "single workgroup, 1024 threads".into(),
        4096,
        1,
        KernelPath::SingleWorkgroup,
        1024,
        workgroup.clone(),
    ));
    for ept in [2u32, 4, 6, 8] {
        // Subgroup layout at the largest rod that fits with `ept` points per lane on 32 lanes.
        let n = 32 * ept as usize - 1;
        cases.push((
            format!("subgroup layout, {ept} points/lane"),
            n,
            1,
            KernelPath::SingleWorkgroup,
            256,
            sub1.clone(),
        ));
        cases.push((
            format!("workgroup layout, same rod ({ept} points/lane case)"),
            n,
            1,
            KernelPath::SingleWorkgroup,
            256,
            workgroup.clone(),
        ));
    }
    for count in [100usize, 1000] {
        for (name, v) in [("subgroup layout", &sub1), ("workgroup layout", &workgroup)] {
            cases.push((
                name.to_string(),
                128,
                count,
                KernelPath::SingleWorkgroup,
                256,
                v.clone(),
            ));
        }
    }
    let many = if quick { 100 } else { 10_000 };
    for per_wg in [1u32, 2, 4, 8] {
        cases.push((
            format!("subgroup layout, {per_wg} rods/workgroup"),
            128,
            many,
            KernelPath::SingleWorkgroup,
            256,
            KernelVariant {
                rods_per_workgroup: per_wg,
                ..base.clone()
            },
        ));
    }
    for ept in [6u32, 8] {
        cases.push((
            format!("subgroup layout, 4 rods/workgroup, {ept} points/lane cap (rods of 128)"),
            128,
            many,
            KernelPath::SingleWorkgroup,
            256,
            KernelVariant {
                subgroup_points_per_thread: ept,
                ..base.clone()
            },
        ));
    }
    cases.push((
        "subgroup layout, inverseSqrt impulse".into(),
        128,
        many,
        KernelPath::SingleWorkgroup,
        256,
        KernelVariant {
            rsqrt: true,
            ..base.clone()
        },
    ));
    cases.push((
        "workgroup layout, one rod per workgroup".into(),
        128,
        many,
        KernelPath::SingleWorkgroup,
        256,
        workgroup.clone(),
    ));
    cases.push((
        "workgroup layout, loops (the old kernel's structure)".into(),
        128,
        many,
        KernelPath::SingleWorkgroup,
        256,
        KernelVariant {
            unroll: false,
            ..workgroup.clone()
        },
    ));

    println!("| variant | elements | rods | GPU µs/step | kernel | discrepancy |");
    println!("|---|---|---|---|---|---|");
    let mut out = Vec::new();
    type CpuRun = ((usize, usize), Vec<Vec<Vec3<f32>>>);
    let mut cpu_cache: Vec<CpuRun> = Vec::new();
    for (name, n, count, path, threads, variant) in cases {
        let rods: Vec<GpuRodInput> = (0..count)
            .map(|i| pendulum(n, i as f64 * 2.399963))
            .collect();
        if !cpu_cache.iter().any(|(key, _)| *key == (n, count)) {
            cpu_cache.push(((n, count), cpu_positions(&rods, CHECK_STEPS)));
        }
        let cpu = &cpu_cache
            .iter()
            .find(|(key, _)| *key == (n, count))
            .expect("cached")
            .1;
        let row = match measure(&rods, cpu, path, k, budget, threads, &variant, false) {
            Ok(m) => {
                println!(
                    "| {name} | {n} | {count} | {} | {} | {:.1e}{} |",
                    m.gpu_us_per_step.map_or("-".into(), |g| format!("{g:.2}")),
                    m.kernel,
                    m.agreement,
                    if m.pass { "" } else { " FAIL" }
                );
                json!({"variant": name, "elements": n, "rods": count, "steps_per_dispatch": k,
                       "kernel": m.kernel, "gpu_us_per_step": m.gpu_us_per_step,
                       "cpu_discrepancy_rel": m.agreement, "cpu_agreement_pass": m.pass})
            }
            Err(e) => {
                println!("| {name} | {n} | {count} | error: {e} | | |");
                json!({"variant": name, "elements": n, "rods": count, "error": e.to_string()})
            }
        };
        out.push(row);
        // Keep only the CPU results of the current size (10 000-rod runs are large).
        if cpu_cache.len() > 2 {
            cpu_cache.remove(0);
        }
    }
    out
}

/// The multi-workgroup window shapes and the host readback side by side at 1000 elements (and
/// a few checks at other sizes): the exploration behind the planner's defaults (`--focus`).
fn focus_section() -> Value {
    let base = KernelVariant::default();
    // (label, elements, rods, path, variant)
    type Case = (String, usize, usize, KernelPath, KernelVariant);
    let mut cases: Vec<Case> = Vec::new();
    let multi = KernelPath::MultiWorkgroup;
    for n in [1000usize, 4096, 16384] {
        for (threads, xs) in [(128u32, 2u32), (96, 2), (128, 3), (160, 3), (128, 1)] {
            if n > 1000 && !(threads == 128 && xs == 2) {
                continue;
            }
            for coherent in [false, true] {
                let v = KernelVariant {
                    multi_threads: threads,
                    exchange_steps: xs,
                    coherent_exchange: coherent,
                    ..base.clone()
                };
                let name = format!(
                    "{threads} threads, {xs} steps/exchange{}",
                    if coherent { ", coherent" } else { "" }
                );
                cases.push((name, n, 1, multi, v));
            }
        }
    }
    for (name, v) in [
        ("default", base.clone()),
        (
            "default, previous kernel",
            KernelVariant {
                exchange_steps: 1,
                neighbour_sync: false,
                register_constants: false,
                fast_impulse: false,
                ..base.clone()
            },
        ),
    ] {
        cases.push((name.to_string(), 1000, 1, KernelPath::Auto, v));
    }
    println!("| variant | elements | rods | GPU µs/step | kernel | discrepancy |");
    println!("|---|---|---|---|---|---|");
    let mut rows = Vec::new();
    type CpuRun = ((usize, usize), Vec<Vec<Vec3<f32>>>);
    let mut cpu_cache: Vec<CpuRun> = Vec::new();
    for (name, n, count, path, variant) in cases {
        let rods: Vec<GpuRodInput> = (0..count)
            .map(|i| pendulum(n, i as f64 * 2.399963))
            .collect();
        if !cpu_cache.iter().any(|(key, _)| *key == (n, count)) {
            cpu_cache.push(((n, count), cpu_positions(&rods, CHECK_STEPS)));
            if cpu_cache.len() > 2 {
                cpu_cache.remove(0);
            }
        }
        let cpu = &cpu_cache
            .iter()
            .find(|(key, _)| *key == (n, count))
            .expect("cached")
            .1;
        // Twice, to see the spread.
        let mut times = Vec::new();
        let mut last = None;
        for _ in 0..2 {
            match measure(&rods, cpu, path, 100, 2000, 256, &variant, false) {
                Ok(m) => {
                    times.push(m.gpu_us_per_step.unwrap_or(f64::NAN));
                    last = Some(Ok(m));
                }
                Err(e) => {
                    last = Some(Err(e));
                    break;
                }
            }
        }
        let row = match last.expect("measured") {
            Ok(m) => {
                let t = times.iter().copied().fold(f64::INFINITY, f64::min);
                let spread = times.iter().copied().fold(0.0, f64::max) - t;
                println!(
                    "| {name} | {n} | {count} | {t:.2} (±{spread:.2}) | {} | {:.1e}{} |",
                    m.kernel,
                    m.agreement,
                    if m.pass { "" } else { " FAIL" }
                );
                json!({"variant": name, "elements": n, "rods": count, "kernel": m.kernel,
                       "gpu_us_per_step": times, "cpu_discrepancy_rel": m.agreement, "cpu_agreement_pass": m.pass})
            }
            Err(e) => {
                println!("| {name} | {n} | {count} | error: {e} | | |");
                json!({"variant": name, "elements": n, "rods": count, "error": e.to_string()})
            }
        };
        rows.push(row);
    }
    json!({"focus": rows, "host": host_section()})
}

/// A single step including readback, host-visible, by way of waiting and submitting.
fn host_section() -> Value {
    println!(
        "\n| path | elements | wait | submission | median µs | min µs | p90 µs | step() µs | GPU µs |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut rows = Vec::new();
    for n in [1000usize, 128] {
        let rods = vec![pendulum(n, 0.0)];
        for path in [
            KernelPath::SingleWorkgroup,
            KernelPath::MultiWorkgroup,
            KernelPath::DispatchPerStep,
        ] {
            // (spin µs, submission): "request" = step + request_positions + read_positions,
            // "combined" = step_and_request + read_positions, "state" = step + read_state (what
            // the facade's `Simulation::step` does).
            for (spin, how) in [
                (0u32, "step + request"),
                (2000, "step + request"),
                (2000, "step_and_request"),
                (0, "step_and_request"),
                (2000, "step + read_state"),
            ] {
                let opts = GpuOptions {
                    path,
                    spin_wait_us: spin,
                    ..GpuOptions::default()
                };
                let Ok(mut sim) = GpuSimulation::with_variant(
                    rods.clone(),
                    &settings(),
                    opts,
                    KernelVariant::default(),
                ) else {
                    continue;
                };
                let mut total = Vec::new();
                let mut submit = Vec::new();
                for i in 0..260 {
                    let t = Instant::now();
                    if how == "step_and_request" {
                        sim.step_and_request(1).expect("submit");
                    } else {
                        sim.step(1).expect("submit");
                    }
                    let ts = t.elapsed().as_secs_f64() * 1e6;
                    if how == "step + read_state" {
                        sim.read_state().expect("read");
                    } else {
                        sim.read_positions().expect("read");
                    }
                    if i >= 10 {
                        total.push(t.elapsed().as_secs_f64() * 1e6);
                        submit.push(ts);
                    }
                }
                total.sort_by(f64::total_cmp);
                let (med, min, p90) = (
                    total[total.len() / 2],
                    total[0],
                    total[total.len() * 9 / 10],
                );
                let sub = median(submit);
                let wait = if spin > 0 { "spin" } else { "block" };
                println!(
                    "| {path} | {n} | {wait} | {how} | {med:.1} | {min:.1} | {p90:.1} | {sub:.1} | |"
                );
                rows.push(
                    json!({"path": path.to_string(), "elements": n, "wait": wait, "submission": how,
                    "median_us": med, "min_us": min, "p90_us": p90, "step_call_us": sub}),
                );
            }
        }
    }
    Value::Array(rows)
}
