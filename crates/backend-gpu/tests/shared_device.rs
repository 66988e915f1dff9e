//! Simulations built on a device the caller made ([`GpuSimulation::on_device`],
//! [`GpuStepper::on_device`]), as a renderer sharing its device would, against simulations that
//! acquire their own ([`GpuSimulation::new`]): on a device created the way the backend creates
//! one, the results must be the same bit for bit, and several simulations must be able to share
//! one device without disturbing each other.
//!
//! Like `gpu_vs_cpu.rs`, these tests print a note and pass without an adapter, unless
//! `COSSERAT_REQUIRE_GPU=1`.

use cosserat_backend_gpu::{
    EndCondition, GpuError, GpuOptions, GpuRodInput, GpuSimulation, GpuStepper, Gpus, KernelPath,
    Ordering, PointLoad, PrescribedMotion, SolverSettings,
};
use cosserat_model::rod::{RodSpec, build_rod, straight_polyline};
use cosserat_model::{Material, RodState, Vec3};
use cosserat_problem::{DivergedQuantity, StateField, StepError, Stepper};

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

/// Two damped rods with drag, point loads and a driven clamped end: every uploaded struct
/// (slots, items, drives, loads) carries data that changes the result.
fn rods() -> Vec<GpuRodInput> {
    let mut spec = RodSpec::new(Material::new(1.0e6, 1.0e6 / 3.0, 1100.0, 0.005));
    spec.bend_damping = 1e-9;
    spec.stretch_damping = 1e-3;
    spec.drag = 2.0;
    spec.rest_shape = cosserat_model::rod::RestShape::Uniform([3.0, -1.0, 2.0]);
    [30usize, 90]
        .iter()
        .enumerate()
        .map(|(i, &n)| {
            let pts = straight_polyline(
                [0.0, 0.0, 0.0],
                [1.0, 0.3 * i as f64, 0.1],
                0.01 * n as f64,
                n,
            );
            let (state, params) = build_rod::<f32>(&pts, &spec).expect("valid rod");
            let motion = PrescribedMotion {
                velocity: Vec3::new(0.0, 0.3, 0.1),
                angular_velocity: Vec3::new(20.0, 0.0, 5.0),
                start_time: 2e-4,
                end_time: 1.2e-3,
            };
            GpuRodInput {
                state,
                params,
                ends: [EndCondition::clamped().driven(motion), EndCondition::free()],
                loads: vec![PointLoad::new(n, Vec3::new(0.0, 0.0, 0.05))],
                wall: None,
                guide: None,
                binding: None,
                rod_contact: None,
            }
        })
        .collect()
}

/// `Some(value)`, or `None` after a note when there is no adapter (a failure with
/// `COSSERAT_REQUIRE_GPU=1`).
fn or_skip<T>(made: Result<T, GpuError>) -> Option<T> {
    match made {
        Ok(x) => Some(x),
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

/// A device made as the caller of `on_device` would make it, here the way the backend makes
/// its own: a high-performance adapter, its full limits, and the optional features the
/// kernels use where the adapter has them.
fn own_device() -> Result<(wgpu::Device, wgpu::Queue), GpuError> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        ..Default::default()
    }))
    .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
    let wanted = wgpu::Features::SUBGROUP | wgpu::Features::MEMORY_DECORATION_COHERENT;
    pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("a renderer's device"),
        required_features: adapter.features() & wanted,
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .map_err(|e| GpuError::NoAdapter(e.to_string()))
}

/// Every float of `states` as bits, so that equality means bit for bit (and NaN equals itself).
fn bits(states: &[RodState<f32>]) -> Vec<u32> {
    let mut out = Vec::new();
    for s in states {
        for v in s
            .positions
            .iter()
            .chain(&s.velocities)
            .chain(&s.angular_velocities)
        {
            out.extend([v.x, v.y, v.z].map(f32::to_bits));
        }
        for q in s.frames.iter().chain(&s.clamp_frames) {
            out.extend([q.i, q.j, q.k, q.w].map(f32::to_bits));
        }
    }
    out
}

/// Steps `sim` in uneven batches (with a changed end velocity in between) and returns its state.
fn run(sim: &mut GpuSimulation) -> Vec<RodState<f32>> {
    sim.step(37).expect("submit");
    sim.set_end_velocity(1, 0, [0.0, 0.0, 0.2], [0.0, 3.0, 0.0])
        .expect("a held end");
    sim.step(64).expect("submit");
    sim.step(1).expect("submit");
    sim.read_state().expect("read")
}

#[test]
fn a_simulation_on_the_callers_device_matches_its_own_device_bit_for_bit() {
    for (extensible, path) in [
        (false, KernelPath::Auto),
        (true, KernelPath::Auto),
        (false, KernelPath::DispatchPerStep),
    ] {
        let s = settings(extensible);
        let options = GpuOptions {
            path,
            ..GpuOptions::default()
        };
        let Some(mut own) = or_skip(GpuSimulation::new(rods(), &s, options.clone())) else {
            return;
        };
        let Some((device, queue)) = or_skip(own_device()) else {
            return;
        };
        let mut shared = GpuSimulation::on_device(device, queue, rods(), &s, options)
            .expect("a simulation on the caller's device");
        let what = format!("extensible {extensible}, {}", own.kernel_description());
        assert_eq!(own.adapter(), shared.adapter(), "{what}");
        assert_eq!(
            own.kernel_description(),
            shared.kernel_description(),
            "{what}"
        );
        let (a, b) = (run(&mut own), run(&mut shared));
        assert_eq!(bits(&a), bits(&b), "{what}");
        assert_ne!(
            bits(&a),
            bits(&rods().into_iter().map(|r| r.state).collect::<Vec<_>>()),
            "{what}: the rods did not move"
        );
        assert_eq!(own.steps(), shared.steps());
    }
}

/// Two simulations on one device, stepped in turn, each give what they give alone.
#[test]
fn simulations_sharing_a_device_do_not_disturb_each_other() {
    let (s, options) = (settings(false), GpuOptions::default());
    let Some(mut alone) = or_skip(GpuSimulation::new(rods(), &s, options.clone())) else {
        return;
    };
    let Some((device, queue)) = or_skip(own_device()) else {
        return;
    };
    let mut other_rods = rods();
    other_rods.truncate(1);
    let mut first =
        GpuSimulation::on_device(device.clone(), queue.clone(), rods(), &s, options.clone())
            .expect("first simulation");
    let mut second = GpuSimulation::on_device(device, queue, other_rods.clone(), &s, options)
        .expect("second simulation");
    second.step(50).expect("submit");
    let a = run(&mut first);
    second.step(50).expect("submit");
    let b = second.read_state().expect("read");
    assert_eq!(bits(&run(&mut alone)), bits(&a));
    let mut second_alone = GpuSimulation::new(other_rods, &s, GpuOptions::default())
        .expect("the adapter was there a moment ago");
    second_alone.step(100).expect("submit");
    assert_eq!(bits(&second_alone.read_state().expect("read")), bits(&b));
}

/// The [`Stepper`] on the caller's device reads what the one on its own device reads.
#[test]
fn a_stepper_on_the_callers_device_matches_its_own_device() {
    let (s, options) = (settings(false), GpuOptions::default());
    let Some(mut own) = or_skip(GpuStepper::new(rods(), &s, options.clone())) else {
        return;
    };
    let Some((device, queue)) = or_skip(own_device()) else {
        return;
    };
    let mut shared = GpuStepper::on_device(device, queue, rods(), &s, options).expect("a stepper");
    own.advance(80).expect("advance");
    shared.advance(80).expect("advance");
    assert_eq!(own.clock(), shared.clock());
    for rod in 0..own.rod_count() {
        let n = own.elements(rod).expect("rod");
        let (mut a, mut b) = (vec![[0.0; 3]; n + 1], vec![[0.0; 3]; n + 1]);
        own.read(rod, StateField::Positions, &mut a).expect("read");
        shared
            .read(rod, StateField::Positions, &mut b)
            .expect("read");
        assert_eq!(a, b, "rod {rod}");
    }
}

/// Positions of every rod of `stepper`, rod after rod.
fn positions(stepper: &GpuStepper) -> Vec<[f64; 3]> {
    let mut all = Vec::new();
    for rod in 0..stepper.rod_count() {
        let mut p = vec![[0.0; 3]; stepper.elements(rod).expect("rod") + 1];
        stepper
            .read(rod, StateField::Positions, &mut p)
            .expect("read");
        all.extend(p);
    }
    all
}

/// A stepper whose rods are split across two devices (here two devices on one adapter, as
/// [`GpuStepper::on_gpus`] puts them on two cards) steps, steers, restores and reports
/// divergence as one device does: each share plans the same kernel as the whole, so bit for bit.
#[test]
fn a_stepper_split_across_devices_matches_one_device() {
    let s = settings(false);
    let both = || [rods(), rods()].concat();
    let Some(mut one) = or_skip(GpuStepper::new(both(), &s, GpuOptions::default())) else {
        return;
    };
    let mut split = GpuStepper::split(both(), &s, 2, |share| {
        GpuSimulation::new(share, &s, GpuOptions::default())
    })
    .expect("two devices");
    assert_eq!(split.simulations().len(), 2);
    assert_eq!(split.simulations()[1].rods(), 2);
    // Steering a rod of the second share reaches its device.
    for st in [&mut one, &mut split] {
        st.advance(40).expect("advance");
        let mut c = st.end_condition(3, 0).expect("end");
        c.motion.as_mut().expect("driven").velocity = Vec3::new(0.0, -0.2, 0.0);
        st.set_end_condition(3, 0, c).expect("steer");
        st.advance(40).expect("advance");
    }
    assert_eq!(one.clock(), split.clock());
    let after = positions(&one);
    assert_eq!(positions(&split), after);
    // Snapshots hold every device's state.
    let snap = split.snapshot().expect("snapshot");
    split.advance(30).expect("advance");
    assert_ne!(positions(&split), after);
    split.restore(&snap).expect("restore");
    assert_eq!(positions(&split), after);
    // A rod of the second device that blows up is reported by its index in the whole.
    let n = split.elements(2).expect("rod");
    let mut p = vec![[0.0; 3]; n + 1];
    split.read(2, StateField::Positions, &mut p).expect("read");
    let wild: Vec<[f64; 3]> = p
        .iter()
        .map(|x| std::array::from_fn(|k| p[0][k] + 4.0 * (x[k] - p[0][k])))
        .collect();
    split.write(2, StateField::Positions, &wild).expect("write");
    match split.advance(20) {
        Err(StepError::Diverged(d)) => {
            assert_eq!(d.rod, 2, "{d}");
            assert!(matches!(d.quantity, DivergedQuantity::Strain(_)), "{d}");
        }
        other => panic!("expected rod 2 to diverge, got {other:?}"),
    }
}

/// Asking for more GPUs than the machine has, or than there are rods, fails with a message that
/// says what there is.
#[test]
fn asking_for_more_gpus_than_there_are_says_how_many_there_are() {
    let s = settings(false);
    if or_skip(GpuStepper::new(rods(), &s, GpuOptions::default())).is_none() {
        return;
    }
    let Err(e) = GpuStepper::on_gpus(rods(), &s, GpuOptions::default(), Gpus::Count(3)) else {
        panic!("three GPUs for two rods");
    };
    assert!(
        e.to_string().contains("gpus = 3: the scene has 2 rods"),
        "{e}"
    );
    // Every adapter there is, at most one per rod: lavapipe alone is one device.
    let all = GpuStepper::on_gpus(
        [rods(), rods()].concat(),
        &s,
        GpuOptions::default(),
        Gpus::All,
    )
    .expect("every adapter");
    assert!(!all.simulations().is_empty());
    assert_eq!(
        all.simulations()
            .iter()
            .map(GpuSimulation::rods)
            .sum::<usize>(),
        4
    );
}
