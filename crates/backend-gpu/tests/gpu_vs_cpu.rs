//! The GPU backend against the CPU backend (the oracle) on the paper's free-space pendulum and
//! on scenes that exercise every compiled-in term, end condition and kernel path.
//!
//! Both sides run in `f32` with red–black constraint ordering, so they evaluate the same
//! expressions in the same order up to the rounding of fused multiply-adds and of sums the GPU
//! regroups. Tolerance: the largest point discrepancy after the run, divided by the largest
//! displacement of any point on the CPU, must stay below [`REL_TOL`]; an absolute floor of [`FLOOR_ULPS`]
//! `f32` ulps of the rod's extent covers the rounding of the positions themselves, which each
//! side rounds independently once per step.
//!
//! Measured on lavapipe: extensible runs agree to ≤ 7e-6 of the displacement, inextensible
//! pendulums to ≤ 5e-5, and 300 rods of 8 elements (which move only 89 µm) to ≤ 3.3e-4. The
//! kernel computes the constraint impulse exactly as the CPU's red–black solver does; what is
//! left is rounding (fused multiply-adds, `sqrt`, division), amplified by the division by `h`.
//! [`REL_TOL`] leaves an order of magnitude over the worst case seen.
//!
//! Tests that need an adapter print a note and pass when there is none (machines without
//! Vulkan), unless `COSSERAT_REQUIRE_GPU=1`, which makes a missing adapter a failure; CI
//! installs Mesa's lavapipe and sets it.

use cosserat_backend_cpu::{
    CpuRod, EndCondition, Ordering, PointLoad, PrescribedMotion, SolverSettings, step_rod,
};
use cosserat_backend_gpu::{
    GpuError, GpuOptions, GpuRodInput, GpuSimulation, GpuStepper, KernelPath, KernelVariant,
};
use cosserat_model::energy::{ForceModel, energies};
use cosserat_model::quat::exp_rotation;
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, Quat, RodParams, RodState, Vec3};
use cosserat_problem::{EndReaction, StateField, Stepper};

/// Relative agreement required (see the module docs).
const REL_TOL: f64 = 5e-3;
/// Relative agreement required of a clamped end frame, against its turn. Over 1000 steps the
/// end frames' rounding grows as the positions' does not: at the last end frame of a
/// 300-element rod clamped at both ends (`clamped_cantilevers_match_cpu`) the CPU in `f32`
/// differs from itself in `f64` by 3.1e-3 of the turn and from the GPU by 3.3e-3, while the
/// GPU differs from `f64` by 7e-4 (measured on lavapipe).
const FRAME_TOL: f64 = 2e-2;
/// Absolute floor in `f32` ulps of the rod's extent (see the module docs).
const FLOOR_ULPS: f64 = 16.0;

fn material() -> Material {
    // The pendulum scene's rubber cord: E = 1 MPa, ν = 0.5, ρ = 1100 kg/m³, r = 5 mm.
    Material::new(1.0e6, 1.0e6 / 3.0, 1100.0, 0.005)
}

fn settings(extensible: bool) -> SolverSettings<f32> {
    SolverSettings {
        dt: 2e-5,
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible,
        gravity: Vec3::new(0.0, 0.0, -9.81),
        divergence_strain: 0.5,
    }
}

/// A straight horizontal rod of `n` elements of 1 cm along `dir`, pinned at its first point and
/// released swinging: a rigid rotation of 1 rad/s about the horizontal axis across the rod.
///
/// Released from rest, a rod moves only ~20 µm in 100 steps, which is ~170 `f32` ulps at 1 m:
/// the comparison would then measure how each side rounds `r += h v`, not the dynamics. With
/// the swing every point moves ~h·ω·|r| per step, many ulps, and the test compares motion.
fn pendulum(n: usize, dir: [f64; 3], spec: RodSpec) -> (RodState<f32>, RodParams<f32>) {
    let pts = straight_polyline([0.0, 0.0, 0.0], dir, 0.01 * n as f64, n);
    let (mut s, p) = build_rod::<f32>(&pts, &spec).expect("valid rod");
    let d = Vec3::new(dir[0] as f32, dir[1] as f32, dir[2] as f32).normalize();
    let omega = d.cross(&Vec3::z()).normalize();
    for (v, r) in s.velocities.iter_mut().zip(&s.positions) {
        *v = omega.cross(r);
    }
    for (w, q) in s.angular_velocities.iter_mut().zip(&s.frames) {
        *w = cosserat_model::quat::rotate_inv(q, &omega);
    }
    (s, p)
}

/// State, parameters, end conditions and loads of one test rod.
type TestRod = (
    RodState<f32>,
    RodParams<f32>,
    [EndCondition<f32>; 2],
    Vec<PointLoad<f32>>,
);
/// Initial and final positions of one rod on the CPU.
type StartEnd = (Vec<Vec3<f32>>, Vec<Vec3<f32>>);

struct Case {
    rods: Vec<TestRod>,
}

impl Case {
    fn pendulums(sizes: &[usize]) -> Self {
        let rods = sizes
            .iter()
            .enumerate()
            .map(|(i, &n)| {
                let a = 0.7 * i as f64;
                let (s, p) = pendulum(n, [a.cos(), a.sin(), 0.0], RodSpec::new(material()));
                (s, p, [EndCondition::pinned(), EndCondition::free()], vec![])
            })
            .collect();
        Self { rods }
    }

    fn gpu_input(&self) -> Vec<GpuRodInput> {
        self.rods
            .iter()
            .map(|(s, p, e, l)| GpuRodInput {
                state: s.clone(),
                params: p.clone(),
                ends: e.clone(),
                loads: l.clone(),
                wall: None,
                guide: None,
                binding: None,
                rod_contact: None,
            })
            .collect()
    }

    fn cpu_run(&self, settings: &SolverSettings<f32>, steps: u64) -> Vec<StartEnd> {
        self.rods
            .iter()
            .zip(self.cpu_states(settings, steps))
            .map(|((s, ..), end)| (s.positions.clone(), end.positions))
            .collect()
    }

    /// The rods' whole states after `steps` steps on the CPU.
    fn cpu_states(&self, settings: &SolverSettings<f32>, steps: u64) -> Vec<RodState<f32>> {
        self.rods
            .iter()
            .enumerate()
            .map(|(r, (s, p, e, l))| {
                let mut rod = CpuRod::new(s.clone(), p.clone(), e.clone(), l.clone());
                for k in 0..steps {
                    step_rod(&mut rod, settings, k as f64 * settings.dt as f64, r, k)
                        .expect("the CPU oracle must not diverge");
                }
                rod.state
            })
            .collect()
    }
}

/// Builds the simulation, or prints why not and returns `None` when there is no adapter.
fn gpu(case: &Case, settings: &SolverSettings<f32>, options: GpuOptions) -> Option<GpuSimulation> {
    gpu_variant(case, settings, options, KernelVariant::default())
}

/// [`gpu`] with a kernel variant.
fn gpu_variant(
    case: &Case,
    settings: &SolverSettings<f32>,
    options: GpuOptions,
    variant: KernelVariant,
) -> Option<GpuSimulation> {
    match GpuSimulation::with_variant(case.gpu_input(), settings, options, variant) {
        Ok(sim) => Some(sim),
        Err(GpuError::NoAdapter(why)) => {
            assert!(
                std::env::var("COSSERAT_REQUIRE_GPU").as_deref() != Ok("1"),
                "COSSERAT_REQUIRE_GPU=1 but there is no adapter: {why}"
            );
            eprintln!("note: skipping GPU test, no adapter: {why}");
            None
        }
        Err(e) => panic!("GPU simulation could not be created: {e}"),
    }
}

/// Largest point discrepancy relative to the largest CPU displacement, per rod.
fn compare(cpu: &[StartEnd], gpu: &[Vec<[f32; 3]>], what: &str) {
    assert_eq!(cpu.len(), gpu.len());
    for (r, ((start, end), g)) in cpu.iter().zip(gpu).enumerate() {
        assert_eq!(end.len(), g.len());
        let disp = start
            .iter()
            .zip(end)
            .map(|(a, b)| (b - a).cast::<f64>().norm())
            .fold(0.0, f64::max);
        let extent = start
            .iter()
            .map(|a| a.cast::<f64>().norm())
            .fold(0.0, f64::max);
        let err = end
            .iter()
            .zip(g)
            .map(|(c, g)| {
                (Vec3::new(g[0] as f64, g[1] as f64, g[2] as f64) - c.cast::<f64>()).norm()
            })
            .fold(0.0, f64::max);
        let allowed = REL_TOL * disp + FLOOR_ULPS * f32::EPSILON as f64 * extent;
        assert!(disp > 0.0, "{what}, rod {r}: the CPU rod did not move");
        assert!(
            err <= allowed,
            "{what}, rod {r}: GPU-CPU discrepancy {err:.3e} m > {allowed:.3e} m (CPU displacement {disp:.3e} m)"
        );
        eprintln!(
            "{what}, rod {r}: discrepancy {:.2e} of displacement {disp:.2e} m",
            err / disp
        );
    }
}

fn run_and_compare(
    case: &Case,
    settings: &SolverSettings<f32>,
    options: GpuOptions,
    steps: u32,
    per_dispatch: u32,
    what: &str,
) {
    run_variant_and_compare(
        case,
        settings,
        options,
        KernelVariant::default(),
        steps,
        per_dispatch,
        what,
    );
}

/// [`run_and_compare`] with a kernel variant; returns the kernel description (`None` without an
/// adapter).
fn run_variant_and_compare(
    case: &Case,
    settings: &SolverSettings<f32>,
    options: GpuOptions,
    variant: KernelVariant,
    steps: u32,
    per_dispatch: u32,
    what: &str,
) -> Option<(String, Option<u32>)> {
    let cpu = case.cpu_run(settings, steps as u64);
    let mut sim = gpu_variant(case, settings, options, variant)?;
    eprintln!(
        "{what}: {} on {}",
        sim.kernel_description(),
        sim.adapter().name
    );
    let mut done = 0;
    while done < steps {
        let k = per_dispatch.min(steps - done);
        sim.step(k).expect("submit");
        done += k;
    }
    let g = sim
        .read_positions()
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(sim.steps(), steps as u64);
    compare(&cpu, &g, what);
    Some((sim.kernel_description(), sim.adapter().subgroup_size))
}

#[test]
fn pendulum_inextensible_matches_cpu() {
    for n in [16, 100, 1000, 2048] {
        let case = Case::pendulums(&[n]);
        run_and_compare(
            &case,
            &settings(false),
            GpuOptions::default(),
            100,
            10,
            &format!("inextensible n={n}"),
        );
    }
}

#[test]
fn pendulum_extensible_matches_cpu() {
    for n in [16, 100, 1000, 2048] {
        let case = Case::pendulums(&[n]);
        run_and_compare(
            &case,
            &settings(true),
            GpuOptions::default(),
            100,
            10,
            &format!("extensible n={n}"),
        );
    }
}

#[test]
fn several_rods_at_once_match_cpu() {
    let case = Case::pendulums(&[16, 100, 33, 257]);
    for ext in [false, true] {
        run_and_compare(
            &case,
            &settings(ext),
            GpuOptions::default(),
            100,
            25,
            &format!("4 rods, extensible={ext}"),
        );
    }
}

#[test]
fn dispatch_per_step_path_matches_cpu() {
    // Rods longer than one chunk, so halos between workgroups are exercised.
    let case = Case::pendulums(&[2000, 700]);
    for ext in [false, true] {
        let options = GpuOptions {
            path: KernelPath::DispatchPerStep,
            ..GpuOptions::default()
        };
        run_and_compare(
            &case,
            &settings(ext),
            options,
            60,
            20,
            &format!("dispatch-per-step, extensible={ext}"),
        );
    }
}

/// Damping (both kinds), drag, a point load, a clamped end driven with linear and angular
/// velocity, twist and a curved rest shape: every optional term and end condition at once.
fn busy_case() -> Case {
    busy_case_sized(&[40, 300])
}

/// [`busy_case`] with rods of the given numbers of elements.
fn busy_case_sized(sizes: &[usize]) -> Case {
    let mut spec = RodSpec::new(material());
    spec.bend_damping = 1e-9; // h·c/(l·I) ≈ 0.4: explicit damping stays stable
    spec.stretch_damping = 1e-3; // h·c/(l0·m) ≈ 0.2
    spec.drag = 2.0;
    spec.rest_shape = cosserat_model::rod::RestShape::Uniform([3.0, -1.0, 2.0]);
    let mut rods = Vec::new();
    for (i, &n) in sizes.iter().enumerate() {
        let (s, p) = pendulum(n, [1.0, 0.2 * i as f64, 0.1], spec);
        let motion = PrescribedMotion {
            velocity: Vec3::new(0.0, 0.3, 0.1),
            angular_velocity: Vec3::new(20.0, 0.0, 5.0),
            start_time: 2e-4,
            end_time: 1.2e-3,
        };
        let ends = [EndCondition::clamped().driven(motion), EndCondition::free()];
        let loads = vec![
            PointLoad::new(n, Vec3::new(0.0, 0.0, 0.05)),
            PointLoad::new(n / 2, Vec3::new(0.01, 0.0, 0.0)),
        ];
        rods.push((s, p, ends, loads));
    }
    Case { rods }
}

#[test]
fn every_term_and_end_condition_matches_cpu() {
    let case = busy_case();
    for ext in [false, true] {
        for path in [KernelPath::SingleWorkgroup, KernelPath::DispatchPerStep] {
            let options = GpuOptions {
                path,
                max_threads: 64,
                ..GpuOptions::default()
            };
            run_and_compare(
                &case,
                &settings(ext),
                options,
                100,
                7,
                &format!("busy scene, {path}, extensible={ext}"),
            );
        }
    }
}

/// The windows of the multi-workgroup paths with halos for several steps between exchanges,
/// one-subgroup windows exchanging by shuffles, parameters in registers and the folded impulse,
/// each with every term and end condition, on the dispatch-per-step path (which runs the same
/// windows, `exchange_steps` steps per dispatch, and needs no co-residency).
#[test]
fn wide_halo_and_shuffle_windows_match_cpu() {
    let case = busy_case();
    let base = KernelVariant::default();
    let variants = [
        (
            "2 steps per exchange",
            KernelVariant {
                exchange_steps: 2,
                ..base.clone()
            },
        ),
        (
            "3 steps per exchange, 4 points/thread, registers, folded impulse",
            KernelVariant {
                exchange_steps: 3,
                multi_points_per_thread: 4,
                register_constants: true,
                fast_impulse: true,
                ..base.clone()
            },
        ),
        (
            "shuffle windows, 16 points/thread",
            KernelVariant {
                shuffle_windows: true,
                multi_points_per_thread: 16,
                exchange_steps: 1,
                ..base.clone()
            },
        ),
        (
            "shuffle windows, 24 points/thread, 2 steps per exchange, registers, folded impulse",
            KernelVariant {
                shuffle_windows: true,
                multi_points_per_thread: 24,
                exchange_steps: 2,
                register_constants: true,
                fast_impulse: true,
                ..base.clone()
            },
        ),
    ];
    for (name, variant) in variants {
        for ext in [false, true] {
            let options = GpuOptions {
                path: KernelPath::DispatchPerStep,
                max_threads: 64,
                ..GpuOptions::default()
            };
            let what = format!("busy scene, dispatch per step, {name}, extensible={ext}");
            let Some((kernel, sg)) = run_variant_and_compare(
                &case,
                &settings(ext),
                options,
                variant.clone(),
                100,
                7,
                &what,
            ) else {
                return;
            };
            if variant.exchange_steps > 1 {
                assert!(
                    kernel.contains(&format!("exchange every {} steps", variant.exchange_steps)),
                    "{what}: {kernel}"
                );
            }
            if variant.shuffle_windows && sg.is_some_and(|sg| sg <= 64) {
                assert!(kernel.contains("SHFL"), "{what}: {kernel}");
            }
            if variant.fast_impulse && !ext {
                assert!(kernel.contains("FAST"), "{what}: {kernel}");
            }
        }
    }
}

/// Halos wide enough for several steps between exchanges compute the owned points exactly as
/// exchanging every step does: the same windows, the same arithmetic, so the positions agree
/// to the bit (a halo one step too narrow shows up here, although it stays far inside the CPU
/// tolerance).
#[test]
fn steps_between_exchanges_change_no_bit() {
    let case = busy_case_sized(&[300, 170]);
    for ext in [false, true] {
        let s = settings(ext);
        let run = |xs: u32, shuffle: bool| -> Option<(Vec<Vec<[f32; 3]>>, String)> {
            let variant = KernelVariant {
                exchange_steps: xs,
                shuffle_windows: shuffle,
                multi_points_per_thread: 16,
                multi_threads: 32,
                ..KernelVariant::default()
            };
            let options = GpuOptions {
                path: KernelPath::DispatchPerStep,
                ..GpuOptions::default()
            };
            let mut sim = gpu_variant(&case, &s, options, variant)?;
            sim.step(41).expect("submit");
            let p = sim.read_positions().expect("read");
            Some((p, sim.kernel_description()))
        };
        for shuffle in [false, true] {
            let Some((reference, k1)) = run(1, shuffle) else {
                return;
            };
            for xs in [2, 3] {
                let (p, k) = run(xs, shuffle).expect("adapter");
                let worst = reference
                    .iter()
                    .flatten()
                    .zip(p.iter().flatten())
                    .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f32::max))
                    .fold(0.0, f32::max);
                eprintln!("extensible={ext}, {xs} steps/exchange: worst {worst:e}\n  {k1}\n  {k}");
                assert!(
                    worst == 0.0,
                    "extensible={ext}, shuffle={shuffle}, {xs} steps per exchange differ by {worst:e} from one: {k}"
                );
            }
        }
    }
}

/// `step_and_request` (steps and readback in one submission) gives what `step` and
/// `read_positions` give.
#[test]
fn step_and_request_matches_step_then_read() {
    let case = Case::pendulums(&[300, 40]);
    let s = settings(false);
    let Some(mut a) = gpu(&case, &s, GpuOptions::default()) else {
        return;
    };
    let Some(mut b) = gpu(
        &case,
        &s,
        GpuOptions {
            spin_wait_us: 0,
            ..GpuOptions::default()
        },
    ) else {
        return;
    };
    for k in [1, 5, 20] {
        a.step(k).expect("submit");
        let pa = a.read_positions().expect("read");
        b.step_and_request(k).expect("submit");
        let pb = b.read_positions().expect("read");
        assert_eq!(pa, pb, "after a batch of {k}");
    }
    // Pipelined: the next batch submitted before the previous result is read.
    a.step_and_request(3).expect("submit");
    a.step_and_request(3).expect("submit");
    let first = a.read_positions().expect("read");
    let second = a.read_positions().expect("read");
    b.step(3).expect("submit");
    assert_eq!(first, b.read_positions().expect("read"));
    b.step(3).expect("submit");
    assert_eq!(second, b.read_positions().expect("read"));
    assert!(a.step_and_request(1).is_ok() && a.step_and_request(1).is_ok());
    assert!(matches!(
        a.step_and_request(1),
        Err(GpuError::InvalidInput(_))
    ));
}

/// The subgroup layout (one rod per subgroup, several rods per workgroup, no workgroup barrier)
/// with every term and end condition, against the CPU; on an adapter without a fixed subgroup
/// size the workgroup layout runs instead, and the test says so.
#[test]
fn subgroup_layout_matches_cpu() {
    // 3 rods at 2 per workgroup: the second workgroup has a group without a rod.
    let case = busy_case_sized(&[40, 13, 7]);
    let variant = KernelVariant {
        subgroup_min_rods: 1,
        rods_per_workgroup: 2,
        ..KernelVariant::default()
    };
    for ext in [false, true] {
        let what = format!("busy scene, subgroup layout, extensible={ext}");
        let Some((kernel, sg)) = run_variant_and_compare(
            &case,
            &settings(ext),
            GpuOptions::default(),
            variant.clone(),
            100,
            7,
            &what,
        ) else {
            return;
        };
        // 41 points fit one subgroup at <= 8 points per invocation when it has >= 6 lanes.
        let expect = sg.is_some_and(|sg| 41u32.div_ceil(sg).next_multiple_of(2) <= 8);
        assert_eq!(
            kernel.contains("one per subgroup"),
            expect,
            "{what}: subgroup size {sg:?}, kernel {kernel}"
        );
        if !expect {
            eprintln!("note: {what} ran the workgroup layout (subgroup size {sg:?})");
        }
    }
}

/// Many short rods take the subgroup layout by default (where the adapter allows it).
#[test]
fn many_short_rods_match_cpu() {
    let sizes = vec![8usize; 300];
    let case = Case::pendulums(&sizes);
    let Some((kernel, sg)) = run_variant_and_compare(
        &case,
        &settings(false),
        GpuOptions::default(),
        KernelVariant::default(),
        60,
        20,
        "300 rods of 8 elements",
    ) else {
        return;
    };
    assert_eq!(
        kernel.contains("one per subgroup"),
        sg.is_some(),
        "{kernel}"
    );
}

#[test]
fn driven_end_follows_per_batch_velocity() {
    let case = Case::pendulums(&[50]);
    let Some(mut sim) = gpu(&case, &settings(false), GpuOptions::default()) else {
        return;
    };
    sim.set_end_velocity(0, 0, [0.0, 0.0, 1.0], [0.0; 3])
        .expect("rod 0 end 0");
    sim.step(10).expect("submit");
    sim.request_positions().expect("request");
    // Submitted before the previous result is read, as a haptic loop does.
    sim.set_end_velocity(0, 0, [0.0, 0.0, 0.0], [0.0; 3])
        .expect("rod 0 end 0");
    sim.step(10).expect("submit");
    let first = sim.read_positions().expect("first batch");
    let second = sim.read_positions().expect("second batch");
    let dz = 10.0 * 2e-5;
    assert!(
        (first[0][0][2] - dz).abs() < 1e-9,
        "driven point at {:?}",
        first[0][0]
    );
    assert!(
        (second[0][0][2] - dz).abs() < 1e-9,
        "held point moved to {:?}",
        second[0][0]
    );
    assert!(sim.set_end_velocity(3, 0, [0.0; 3], [0.0; 3]).is_err());
}

/// A long push far from the origin, as a guidewire is fed: the driven end must stay on its
/// prescribed path. Integrated as `r += h v` in `f32`, each step's increment (0.7 µm, ~12 ulps
/// at 0.5 m) is rounded the same way and the error grows linearly (about 1e-4 m here); placed on
/// the path tracked in `f64`, the point is off by a few ulps at most, however long the push.
#[test]
fn a_long_push_keeps_the_driven_end_on_its_path() {
    let mut case = Case::pendulums(&[8]);
    let offset = Vec3::new(0.5f32, -0.3, 0.2);
    for r in &mut case.rods[0].0.positions {
        *r += offset;
    }
    for v in &mut case.rods[0].0.velocities {
        *v = Vec3::zeros();
    }
    for w in &mut case.rods[0].0.angular_velocities {
        *w = Vec3::zeros();
    }
    let mut s = settings(false);
    s.dt = 3.5e-6;
    s.gravity = Vec3::zeros();
    let Some(mut sim) = gpu(&case, &s, GpuOptions::default()) else {
        return;
    };
    let h = f64::from(s.dt);
    let mut exact = [0.5f64, -0.3, 0.2];
    // Per-batch velocities, as a haptic loop sets them: 0.2 m/s along x, then along y, ...
    let velocities = [[0.2f32, 0.0, 0.0], [0.0, 0.15, 0.0], [-0.1, 0.0, 0.05]];
    let batch = 4000u32;
    for k in 0..6 {
        let v = velocities[k % velocities.len()];
        sim.set_end_velocity(0, 0, v, [0.0; 3])
            .expect("rod 0 end 0");
        sim.step(batch).expect("submit");
        for c in 0..3 {
            exact[c] += f64::from(batch) * h * f64::from(v[c]);
        }
    }
    let p = sim.read_positions().expect("positions")[0][0];
    let error = (0..3)
        .map(|c| (f64::from(p[c]) - exact[c]).abs())
        .fold(0.0, f64::max);
    // 8 f32 ulps at 0.5 m.
    assert!(
        error < 8.0 * 6e-8,
        "driven end {p:?}, exact {exact:?}, error {error:e}"
    );
}

#[test]
fn divergence_names_rod_element_and_step() {
    let layouts = [
        KernelVariant::default(),
        KernelVariant {
            subgroup_min_rods: 1,
            ..KernelVariant::default()
        },
    ];
    for variant in layouts {
        divergence_with(variant);
    }
}

fn divergence_with(variant: KernelVariant) {
    let case = Case::pendulums(&[20, 30]);
    let mut s = settings(true);
    s.dt = 5e-3; // far beyond the stable step of the stretching springs
    s.divergence_strain = 0.1;
    let Some(mut sim) = gpu_variant(&case, &s, GpuOptions::default(), variant) else {
        return;
    };
    eprintln!("divergence: {}", sim.kernel_description());
    sim.step(50).expect("submit");
    match sim.read_positions() {
        Err(GpuError::Diverged(d)) => {
            assert!(d.rod < 2 && d.step < 50, "{d}");
            assert!(d.element < 30, "{d}");
            let msg = GpuError::Diverged(d).to_string();
            assert!(
                msg.contains(&format!("rod {}", d.rod))
                    && msg.contains("element")
                    && msg.contains("step"),
                "{msg}"
            );
            // The CPU, stepping the same rod, diverges too, no later than the GPU says.
            let cpu_rod = &case.rods[d.rod];
            let mut rod = CpuRod::new(
                cpu_rod.0.clone(),
                cpu_rod.1.clone(),
                cpu_rod.2.clone(),
                vec![],
            );
            let cpu_step = (0..50u64)
                .find(|&k| step_rod(&mut rod, &s, k as f64 * s.dt as f64, d.rod, k).is_err());
            assert!(
                cpu_step.is_some_and(|k| k <= d.step + 1),
                "CPU diverged at {cpu_step:?}, GPU reported {d}"
            );
        }
        other => panic!("expected a divergence, got {other:?}"),
    }
    // Once diverged, the rod stays stopped and the error stays reported.
    sim.step(5).expect("submit");
    assert!(matches!(sim.check(), Err(GpuError::Diverged(_))));
}

#[test]
fn multi_workgroup_path_never_hangs() {
    let case = Case::pendulums(&[1500]);
    let s = settings(false);
    let forced = GpuOptions {
        path: KernelPath::MultiWorkgroup,
        ..GpuOptions::default()
    };
    let Some(sim) = gpu(&Case::pendulums(&[16]), &s, GpuOptions::default()) else {
        return;
    };
    let software = sim.adapter().software;
    let known = sim.adapter().co_resident_workgroups;
    drop(sim);
    match GpuSimulation::new(case.gpu_input(), &s, forced.clone()) {
        Err(GpuError::PathUnavailable { path, reason }) => {
            assert_eq!(path, KernelPath::MultiWorkgroup);
            assert!(
                known.is_none() || software,
                "refused on an adapter with known co-residency: {reason}"
            );
        }
        Ok(mut sim) => {
            assert!(
                !software,
                "the grid path must be refused on software adapters"
            );
            sim.step(50).expect("submit");
            let g = sim.read_positions().expect("grid path");
            compare(&case.cpu_run(&s, 50), &g, "multi-workgroup");
        }
        Err(e) => panic!("unexpected error: {e}"),
    }
    // Asserting a co-residency the adapter does not have must end in an error or a correct
    // result, never a hang: the spin loops are capped.
    let asserted = GpuOptions {
        co_resident_workgroups: Some(64),
        spin_cap: 2000,
        ..forced
    };
    // Both synchronisation schemes: the grid-wide counter and the neighbours' flags (with
    // halos for two steps per exchange).
    for variant in [
        KernelVariant::default(),
        KernelVariant {
            exchange_steps: 2,
            neighbour_sync: true,
            register_constants: true,
            fast_impulse: true,
            ..KernelVariant::default()
        },
    ] {
        let mut sim =
            GpuSimulation::with_variant(case.gpu_input(), &s, asserted.clone(), variant.clone())
                .expect("grid path with asserted co-residency");
        assert_eq!(sim.path(), KernelPath::MultiWorkgroup);
        sim.step(5).expect("submit");
        match sim.read_positions() {
            Err(GpuError::GridTimeout) => eprintln!(
                "grid barrier timed out as expected on {} ({})",
                sim.adapter().name,
                sim.kernel_description()
            ),
            Ok(g) => compare(&case.cpu_run(&s, 5), &g, "multi-workgroup (asserted)"),
            Err(e) => panic!("unexpected error: {e}"),
        }
    }
}

#[test]
fn read_state_round_trips_and_frames_stay_unit() {
    let case = Case::pendulums(&[64]);
    let Some(mut sim) = gpu(&case, &settings(false), GpuOptions::default()) else {
        return;
    };
    let before = sim.read_state().expect("state");
    assert_eq!(
        before[0], case.rods[0].0,
        "upload and readback must be exact"
    );
    sim.step(30).expect("submit");
    let after = sim.read_state().expect("state");
    for q in &after[0].frames {
        assert!((q.norm() - 1.0).abs() < 1e-5);
    }
    assert!(
        after[0].positions[0] == before[0].positions[0],
        "the pinned point moved"
    );
}

#[test]
fn missing_input_is_an_error_not_a_panic() {
    let settings = settings(false);
    assert!(matches!(
        GpuSimulation::new(vec![], &settings, GpuOptions::default()),
        Err(GpuError::InvalidInput(_))
    ));
    let msg = GpuError::NoAdapter("none".into()).to_string();
    assert!(msg.contains("--backend cpu"), "{msg}");
}

/// The paths the clamp tests run: the multi-workgroup path only where the adapter can run it
/// (a real GPU; lavapipe cannot).
const CLAMP_PATHS: [KernelPath; 3] = [
    KernelPath::SingleWorkgroup,
    KernelPath::DispatchPerStep,
    KernelPath::MultiWorkgroup,
];

/// [`gpu`] on `path`, with workgroups of at most 64 threads (several windows for a rod of 300
/// elements) except on the multi-workgroup path, which keeps its own windows; `None` also where
/// the adapter cannot run the multi-workgroup path, which it notes.
fn gpu_on(case: &Case, settings: &SolverSettings<f32>, path: KernelPath) -> Option<GpuSimulation> {
    let options = GpuOptions {
        path,
        max_threads: if path == KernelPath::MultiWorkgroup {
            256
        } else {
            64
        },
        ..GpuOptions::default()
    };
    if path == KernelPath::MultiWorkgroup
        && let Err(GpuError::PathUnavailable { reason, .. }) =
            GpuSimulation::new(case.gpu_input(), settings, options.clone())
    {
        eprintln!("note: no {path} path on this adapter: {reason}");
        return None;
    }
    gpu(case, settings, options)
}

/// The angle-like distance between two unit quaternions, whichever sign they carry.
fn quat_gap(a: &Quat<f32>, b: &Quat<f32>) -> f64 {
    let (a, b) = (a.cast::<f64>(), b.cast::<f64>());
    (a - b).norm().min((a + b).norm())
}

/// A straight rod of `n` elements of 1 cm along the horizontal direction at `angle`.
fn straight_rod(n: usize, angle: f64, spec: &RodSpec) -> (RodState<f32>, RodParams<f32>) {
    let pts = straight_polyline(
        [0.0; 3],
        [angle.cos(), angle.sin(), 0.0],
        0.01 * n as f64,
        n,
    );
    build_rod::<f32>(&pts, spec).expect("valid rod")
}

/// Cantilevers sagging under gravity, clamped at the first end, at the last, and at both (with
/// bending damping, so the clamps' damping acts too): they bend hardest at their clamps, so the
/// end frames turn against the clamps' nodes. Positions, every frame and the clamp frames
/// against the CPU, on the single-workgroup path and on the windows of the dispatch-per-step
/// and (on a real GPU) multi-workgroup paths (the 300-element rod's two clamps in different
/// windows).
#[test]
fn clamped_cantilevers_match_cpu() {
    let (free, clamped) = (EndCondition::free, EndCondition::clamped);
    let rods = [
        (40, [clamped(), free()], 0.0),
        (40, [free(), clamped()], 0.0),
        (300, [clamped(), clamped()], 1e-9),
    ]
    .into_iter()
    .enumerate()
    .map(|(i, (n, ends, damping))| {
        let mut spec = RodSpec::new(material());
        spec.bend_damping = damping;
        let (s, p) = straight_rod(n, 0.9 * i as f64, &spec);
        (s, p, ends, vec![])
    })
    .collect();
    let case = Case { rods };
    let s = settings(false);
    let steps = 1000;
    let cpu = case.cpu_states(&s, steps);
    for path in CLAMP_PATHS {
        let Some(mut sim) = gpu_on(&case, &s, path) else {
            continue;
        };
        let what = format!("clamped cantilevers, {}", sim.kernel_description());
        assert!(what.contains("CLAMP"), "{what}");
        for _ in 0..10 {
            sim.step(steps as u32 / 10).expect("submit");
        }
        let g = sim.read_state().unwrap_or_else(|e| panic!("{what}: {e}"));
        let start_end: Vec<StartEnd> = case
            .rods
            .iter()
            .zip(&cpu)
            .map(|(r, c)| (r.0.positions.clone(), c.positions.clone()))
            .collect();
        let positions: Vec<Vec<[f32; 3]>> = g
            .iter()
            .map(|s| s.positions.iter().map(|p| [p.x, p.y, p.z]).collect())
            .collect();
        compare(&start_end, &positions, &what);
        for (r, ((rod, c), g)) in case.rods.iter().zip(&cpu).zip(&g).enumerate() {
            let n = c.frames.len();
            for (end, frame) in [(0, 0), (1, n - 1)] {
                if !rod.2[end].holds_frame() {
                    continue;
                }
                // The clamped end frame turned against its clamp (as on the CPU, within the
                // tolerance of its turn), and the clamp held still.
                let turn = quat_gap(&rod.0.frames[frame], &c.frames[frame]);
                let err = quat_gap(&c.frames[frame], &g.frames[frame]);
                let allowed = FRAME_TOL * turn + FLOOR_ULPS * f64::from(f32::EPSILON);
                assert!(
                    turn > 1e-4,
                    "{what}, rod {r}: end frame {frame} turned {turn:e}"
                );
                assert!(
                    err <= allowed,
                    "{what}, rod {r}: end frame {frame} differs by {err:.3e} > {allowed:.3e} (turn {turn:.3e})"
                );
                let gap = quat_gap(&c.clamp_frames[end], &g.clamp_frames[end]);
                let moved = quat_gap(&rod.0.clamp_frames[end], &g.clamp_frames[end]);
                assert!(
                    gap < 1e-6 && moved < 1e-6,
                    "{what}, rod {r}: clamp {end} {gap:e} from the CPU's, moved {moved:e}"
                );
                eprintln!(
                    "{what}, rod {r}: end frame {frame} {:.2e} of its turn {turn:.2e}",
                    err / turn
                );
            }
        }
    }
}

/// Rods of 20 and 300 elements clamped at both ends, the clamps driven with angular velocities
/// for the first 1 ms of 80 steps: on the device each clamp frame turns by `exp(ω t)` and
/// `read_state` returns it, as the CPU has it; the end frames follow.
fn driven_clamps_case() -> Case {
    let motion = |w: Vec3<f32>| PrescribedMotion {
        velocity: Vec3::zeros(),
        angular_velocity: w,
        start_time: 0.0,
        end_time: 1e-3,
    };
    let ends = [
        EndCondition::clamped().driven(motion(Vec3::new(15.0, 0.0, 0.0))),
        EndCondition::clamped().driven(motion(Vec3::new(0.0, 4.0, -8.0))),
    ];
    let rods = [20, 300]
        .into_iter()
        .map(|n| {
            let (s, p) = straight_rod(n, 0.3, &RodSpec::new(material()));
            (s, p, ends.clone(), vec![])
        })
        .collect();
    Case { rods }
}

#[test]
fn driven_clamps_turn_on_the_device_and_read_back() {
    let case = driven_clamps_case();
    let s = settings(false);
    let steps = 80;
    let cpu = case.cpu_states(&s, steps);
    for path in CLAMP_PATHS {
        let Some(mut sim) = gpu_on(&case, &s, path) else {
            continue;
        };
        let what = sim.kernel_description();
        // Batches that cut the drive's window.
        for k in [7, 30, 43] {
            sim.step(k).expect("submit");
        }
        let g = sim.read_state().unwrap_or_else(|e| panic!("{what}: {e}"));
        for (r, ((rod, c), g)) in case.rods.iter().zip(&cpu).zip(&g).enumerate() {
            let n = c.frames.len();
            for (end, frame) in [(0, 0), (1, n - 1)] {
                let Some(m) = rod.2[end].motion else {
                    unreachable!("both ends are driven")
                };
                // The steps whose time k h (h in f32, as both sides count it) is in the window.
                let on = (0..steps)
                    .filter(|&k| (m.start_time..m.end_time).contains(&(k as f64 * f64::from(s.dt))))
                    .count();
                let turn = m.angular_velocity.cast::<f64>() * (on as f64 * f64::from(s.dt));
                let exact = exp_rotation(&turn) * rod.0.clamp_frames[end].cast::<f64>();
                let exact = Quat::new(
                    exact.w as f32,
                    exact.i as f32,
                    exact.j as f32,
                    exact.k as f32,
                );
                let (to_exact, to_cpu) = (
                    quat_gap(&g.clamp_frames[end], &exact),
                    quat_gap(&g.clamp_frames[end], &c.clamp_frames[end]),
                );
                assert!(
                    to_exact < 2e-6 && to_cpu < 2e-6,
                    "{what}, rod {r}, clamp {end}: {to_exact:e} from exp(ω t), {to_cpu:e} from the CPU's"
                );
                // The end frame followed its clamp (the drive turned it by 0.018 rad).
                let lag = quat_gap(&g.frames[frame], &g.clamp_frames[end]);
                let cpu_lag = quat_gap(&c.frames[frame], &c.clamp_frames[end]);
                assert!(
                    lag < 0.5 * turn.norm() && (lag - cpu_lag).abs() < 1e-2 * cpu_lag + 1e-6,
                    "{what}, rod {r}, end {end}: end frame {lag:e} from its clamp, {cpu_lag:e} on the CPU"
                );
                eprintln!(
                    "{what}, rod {r}, clamp {end}: {to_exact:.1e} from exp(ω t), {to_cpu:.1e} from the CPU; end frame {lag:.3e} behind ({cpu_lag:.3e} on the CPU)"
                );
            }
        }
    }
}

/// The stepper's clamps: its energies count the clamps' nodes (with the clamp frames read
/// back), a snapshot restores the clamp frames with the rest of the state, and writing frames
/// closes the clamps on them (at rest: nothing moves afterwards).
#[test]
fn the_stepper_keeps_its_clamps_through_snapshots_and_writes() {
    let case = driven_clamps_case();
    let mut s = settings(false);
    s.gravity = Vec3::zeros();
    let mut st = match GpuStepper::new(case.gpu_input(), &s, GpuOptions::default()) {
        Ok(st) => st,
        Err(GpuError::NoAdapter(why)) => {
            assert!(
                std::env::var("COSSERAT_REQUIRE_GPU").as_deref() != Ok("1"),
                "COSSERAT_REQUIRE_GPU=1 but there is no adapter: {why}"
            );
            eprintln!("note: skipping GPU test, no adapter: {why}");
            return;
        }
        Err(e) => panic!("GPU stepper could not be created: {e}"),
    };
    /// Positions and frames of one rod.
    type Read = (Vec<[f64; 3]>, Vec<[f64; 4]>);
    let read_all = |st: &GpuStepper| -> Vec<Read> {
        (0..st.rod_count())
            .map(|r| {
                let n = st.elements(r).expect("rod");
                let (mut p, mut q) = (vec![[0.0; 3]; n + 1], vec![[0.0; 4]; n]);
                st.read(r, StateField::Positions, &mut p).expect("read");
                st.read_frames(r, &mut q).expect("read");
                (p, q)
            })
            .collect()
    };
    // Snapshot mid-drive: the clamps must come back too, or the drive's second half differs.
    st.advance(30).expect("advance");
    let snap = st.snapshot().expect("snapshot");
    st.advance(40).expect("advance");
    let (a, ea) = (read_all(&st), st.energies());
    st.restore(&snap).expect("restore");
    st.advance(40).expect("advance");
    assert_eq!(read_all(&st), a, "restored and stepped again");
    assert_eq!(st.energies().bend_twist, ea.bend_twist);

    // Bending energy with the clamps' nodes, against the CPU's.
    let cpu = case.cpu_states(&s, 70);
    let model = |clamped| ForceModel {
        extensible: false,
        gravity: s.gravity,
        clamped,
    };
    let bend = |clamped| -> f64 {
        case.rods
            .iter()
            .zip(&cpu)
            .map(|(rod, c)| energies(c, &rod.1, &model(clamped)).bend_twist)
            .sum()
    };
    let (with, without) = (bend([true; 2]), bend([false; 2]));
    assert!(
        with > 1.5 * without,
        "the clamps' nodes hold {with:e} - {without:e}"
    );
    assert!(
        (ea.bend_twist - with).abs() < 1e-2 * with,
        "GPU bending energy {:e}, CPU {with:e}",
        ea.bend_twist
    );

    // Put every rod back straight and still: the written end frames re-seat the clamps, so
    // the rods stay at rest. Measured on lavapipe 10 steps later: frames turning at ≤ 0.06
    // rad/s and 1.3e-10 J of bending energy (rounding), against 19 rad/s and 1.6e-5 J with the
    // clamps left where the drive turned them.
    for (r, rod) in case.rods.iter().enumerate() {
        let n = rod.0.frames.len();
        let p: Vec<[f64; 3]> = rod
            .0
            .positions
            .iter()
            .map(|x| x.cast::<f64>().into())
            .collect();
        let q: Vec<[f64; 4]> = rod
            .0
            .frames
            .iter()
            .map(|q| [q.w, q.i, q.j, q.k].map(f64::from))
            .collect();
        st.write(r, StateField::Positions, &p).expect("write");
        st.write(r, StateField::Velocities, &vec![[0.0; 3]; n + 1])
            .expect("write");
        st.write(r, StateField::AngularVelocities, &vec![[0.0; 3]; n])
            .expect("write");
        st.write_frames(r, &q).expect("write");
    }
    let at_rest = st.energies().bend_twist;
    assert!(
        at_rest < 1e-12,
        "bending energy {at_rest:e} after the write"
    );
    st.advance(10).expect("advance");
    for r in 0..st.rod_count() {
        let n = st.elements(r).expect("rod");
        let mut w = vec![[0.0; 3]; n];
        st.read(r, StateField::AngularVelocities, &mut w)
            .expect("read");
        let fastest = w.iter().map(|w| Vec3::from(*w).norm()).fold(0.0, f64::max);
        assert!(fastest < 1.0, "rod {r}: a frame turns at {fastest:e} rad/s");
    }
    let after = st.energies().bend_twist;
    assert!(
        after < 1e-8,
        "bending energy {after:e} 10 steps after the write"
    );
}

/// Reactions at held ends (a driven clamp at the first end, a pin at the last) follow the CPU
/// oracle's on every path: on the windowed path the last end's force is summed by the window
/// that owns the end point, the first end's torque by the thread that steps the end frame.
#[test]
fn reactions_at_held_ends_match_cpu_on_every_path() {
    let mut case = busy_case();
    for rod in &mut case.rods {
        rod.2[1] = EndCondition::pinned();
    }
    let s = settings(false);
    let steps = 100;
    let cpu: Vec<[Option<EndReaction>; 2]> = case
        .rods
        .iter()
        .enumerate()
        .map(|(r, (st, p, e, l))| {
            let mut rod = CpuRod::new(st.clone(), p.clone(), e.clone(), l.clone());
            for k in 0..steps {
                step_rod(&mut rod, &s, k as f64 * s.dt as f64, r, k).expect("the CPU oracle");
            }
            [rod.end_reaction(0), rod.end_reaction(1)]
        })
        .collect();
    for path in [KernelPath::SingleWorkgroup, KernelPath::DispatchPerStep] {
        let options = GpuOptions {
            path,
            max_threads: 64,
            ..GpuOptions::default()
        };
        let Some(mut sim) = gpu(&case, &s, options) else {
            return;
        };
        sim.step(steps as u32).expect("submit");
        sim.read_state().expect("read");
        for (r, ends) in cpu.iter().enumerate() {
            for (end, want) in ends.iter().enumerate() {
                let want = want.expect("a held end");
                let got = sim.end_reaction(r, end).expect("a held end on the GPU");
                let scale = |v: [f64; 3]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                let (fs, ts) = (scale(want.force), scale(want.torque));
                for k in 0..3 {
                    assert!(
                        (got.force[k] - want.force[k]).abs() <= 0.02 * fs,
                        "{path}, rod {r}, end {end}: force {:?}, CPU {:?}",
                        got.force,
                        want.force
                    );
                    assert!(
                        (got.torque[k] - want.torque[k]).abs() <= 1e-3 * ts + 1e-12,
                        "{path}, rod {r}, end {end}: torque {:?}, CPU {:?}",
                        got.torque,
                        want.torque
                    );
                }
                assert!(fs > 0.0 && (end == 1 || ts > 0.0), "{path}: {want:?}");
            }
        }
    }
}
