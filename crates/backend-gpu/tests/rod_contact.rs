//! Rod–rod and self-contact on the GPU (`RODC`) against the CPU's coupled explicit step (its
//! oracle: `cosserat_backend_cpu::step_coupled_batch` with the same `RodContactSpec`), both in
//! `f32` with red–black distance sweeps.
//!
//! The two sides find the same contacts (the same spheres, pairs and segment tests), but resolve
//! them differently: the CPU one contact after another (Gauss–Seidel), the GPU all at once with
//! the points' masses split among their contacts (Jacobi, `shaders/rod_contact.wgsl`). Where a
//! point takes part in one contact the runs agree to rounding. Where several contacts share
//! points they differ by what ten iterations leave unconverged, and, with friction, by how the
//! two solvers share the normal impulse among redundant contacts (which decides each one's
//! friction cone: both are Coulomb solutions). Measured on lavapipe, as the largest point
//! discrepancy over the travel of the driven ends: crossing rods pressed together 2.1e-3
//! ([`CROSS_TOL`] 2e-2), dragged along each other without friction 4.5e-4, sticking 7.8e-2
//! ([`STICK_TOL`]), a coil pressed onto itself 5.2e-2 ([`COIL_TOL`]). Both keep every pair of
//! non-neighbouring segments at least 99 % of their radii apart.
//!
//! Tests that need an adapter print a note and pass when there is none, unless
//! `COSSERAT_REQUIRE_GPU=1` (CI installs lavapipe and sets it).

use cosserat_backend_cpu::{
    Coupling, CpuRod, EndCondition, Ordering, PrescribedMotion, RodContactSpec, SolverSettings,
    step_coupled_batch,
};
use cosserat_backend_gpu::{
    GpuError, GpuOptions, GpuRodContact, GpuRodInput, GpuSimulation, GpuStepper,
};
use cosserat_constraints::Friction;
use cosserat_model::rod::{RodSpec, build_rod};
use cosserat_model::{Material, RodParams, RodState, Vec3};
use cosserat_problem::Stepper;

/// Largest point discrepancy GPU − CPU over the pressed rod's travel, two crossing rods.
const CROSS_TOL: f64 = 0.02;
/// The same for a rod pressed onto another and dragged along it, sticking: the rods touch in
/// four redundant contacts, whose share of the normal impulse (and so of the friction cone) the
/// two solvers split differently (see [`friction_holds_a_dragged_rod_back_as_on_the_cpu`]).
const STICK_TOL: f64 = 0.12;
/// The same for a coil compressed until its turns touch (self-contact, 48 contacts sharing
/// points): what ten iterations leave unconverged differs between the two solvers (5.2 % of
/// the travel measured; 4.0 % with 40 iterations after 10 000 steps, against 6.2 % with 10).
const COIL_TOL: f64 = 0.1;
/// The coil's ends' speed [m/s] and its friction (none: friction is the dragged rod's test).
const V_COIL: f32 = 0.02;
const MU_COIL: f64 = 0.0;

const RADIUS: f64 = 1.0e-3;

fn gpu_required() -> bool {
    std::env::var("COSSERAT_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// What was built, or `None` (a note printed) when there is no adapter and none is required.
fn built<T>(made: Result<T, GpuError>) -> Option<T> {
    match made {
        Ok(x) => Some(x),
        Err(GpuError::NoAdapter(e)) => {
            assert!(
                !gpu_required(),
                "COSSERAT_REQUIRE_GPU=1 but no adapter: {e}"
            );
            eprintln!("note: skipping the GPU rod-contact test: no adapter ({e})");
            None
        }
        Err(e) => panic!("gpu: {e}"),
    }
}

fn settings() -> SolverSettings<f32> {
    SolverSettings {
        dt: 1e-5,
        iterations: 10,
        ordering: Ordering::RedBlack,
        extensible: false,
        gravity: Vec3::zeros(),
        divergence_strain: 0.5,
    }
}

fn spec(mu: f64) -> RodContactSpec {
    RodContactSpec {
        self_collisions: true,
        friction: Friction {
            static_coefficient: mu,
            kinetic_coefficient: 0.75 * mu,
        },
        margin: 2e-4,
        segments_per_sphere: 4,
    }
}

fn gpu_spec(s: &RodContactSpec) -> GpuRodContact {
    GpuRodContact {
        self_collisions: s.self_collisions,
        static_friction: s.friction.static_coefficient as f32,
        kinetic_friction: s.friction.kinetic_coefficient as f32,
        margin: s.margin as f32,
    }
}

/// A rubber cord of radius 1 mm through `points`.
fn rod(points: &[[f64; 3]]) -> (RodState<f32>, RodParams<f32>) {
    let spec = RodSpec::new(Material::new(1.0e6, 1.0e6 / 3.0, 1100.0, RADIUS));
    let (s, mut p) = build_rod::<f32>(points, &spec).expect("valid rod");
    p.drag = 10.0;
    (s, p)
}

fn line(start: [f64; 3], dir: [f64; 3], length: f64, n: usize) -> Vec<[f64; 3]> {
    (0..=n)
        .map(|i| {
            let t = length * i as f64 / n as f64;
            [
                start[0] + dir[0] * t,
                start[1] + dir[1] * t,
                start[2] + dir[2] * t,
            ]
        })
        .collect()
}

fn pinned_moving(v: [f32; 3]) -> EndCondition<f32> {
    EndCondition::pinned().driven(PrescribedMotion::push(Vec3::new(v[0], v[1], v[2])))
}

/// State, parameters and end conditions of one test rod.
type TestRod = (RodState<f32>, RodParams<f32>, [EndCondition<f32>; 2]);

struct Case {
    rods: Vec<TestRod>,
    spec: RodContactSpec,
}

/// What a run left: every rod's positions, and the smallest distance over the radii of any two
/// segments in contact seen at a step's start.
struct Outcome {
    positions: Vec<Vec<Vec3<f32>>>,
    min_ratio: f64,
    max_contacts: usize,
}

impl Case {
    fn cpu(&self, steps: u64) -> Outcome {
        let s = settings();
        let mut rods: Vec<CpuRod<f32>> = self
            .rods
            .iter()
            .map(|(st, p, e)| CpuRod::new(st.clone(), p.clone(), e.clone(), vec![]))
            .collect();
        let mut coupling = Coupling::new(&rods, &[], Some(self.spec)).expect("coupling");
        let mut stats = Vec::new();
        step_coupled_batch(&mut rods, &mut coupling, &s, 0.0, 0, steps, &mut stats)
            .expect("the CPU run holds");
        let c = coupling.stats();
        Outcome {
            positions: rods.iter().map(|r| r.state.positions.clone()).collect(),
            min_ratio: c.min_separation_ratio,
            max_contacts: c.max_contacts,
        }
    }

    fn gpu_input(&self) -> Vec<GpuRodInput> {
        self.rods
            .iter()
            .map(|(st, p, e)| GpuRodInput {
                state: st.clone(),
                params: p.clone(),
                ends: e.clone(),
                loads: vec![],
                wall: None,
                guide: None,
                binding: None,
                rod_contact: Some(gpu_spec(&self.spec)),
            })
            .collect()
    }

    /// `None` when there is no adapter and none is required.
    fn gpu(&self, steps: u64) -> Option<Outcome> {
        let mut sim = built(GpuSimulation::new(
            self.gpu_input(),
            &settings(),
            GpuOptions::default(),
        ))?;
        assert!(
            sim.kernel_description().contains("RODC"),
            "{}",
            sim.kernel_description()
        );
        sim.step(steps as u32).expect("the GPU run holds");
        let states = sim.read_state().expect("read");
        let c = sim.rod_contact_stats().expect("rod contact statistics");
        Some(Outcome {
            positions: states.into_iter().map(|s| s.positions).collect(),
            min_ratio: c.min_separation_ratio,
            max_contacts: c.max_contacts,
        })
    }
}

fn largest_gap(a: &[Vec3<f32>], b: &[Vec3<f32>]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| f64::from((p - q).norm()))
        .fold(0.0, f64::max)
}

/// Two crossing rods, the upper one pushed down onto the lower one (both ends of each held):
/// the upper rod bends the lower one without passing through it, as on the CPU.
fn crossing(mu: f64) -> Case {
    let n = 24;
    let (sa, pa) = rod(&line([-0.024, 0.0, 2.4e-3], [1.0, 0.0, 0.0], 0.048, n));
    let (sb, pb) = rod(&line([0.0, -0.024, 0.0], [0.0, 1.0, 0.0], 0.048, n));
    let down = pinned_moving([0.0, 0.0, -0.2]);
    Case {
        rods: vec![
            (sa, pa, [down.clone(), down]),
            (sb, pb, [EndCondition::pinned(), EndCondition::pinned()]),
        ],
        spec: spec(mu),
    }
}

#[test]
fn crossing_rods_pressed_together_follow_the_cpu_and_do_not_pass_through() {
    let case = crossing(0.4);
    // 4 mm of travel at 0.2 m/s: 2 mm to close the gap, 2 mm of pressing.
    let steps = 2000;
    let Some(gpu) = case.gpu(steps) else {
        return;
    };
    let cpu = case.cpu(steps);
    let travel = 0.2 * 1e-5 * steps as f64;
    for (r, (g, c)) in gpu.positions.iter().zip(&cpu.positions).enumerate() {
        let gap = largest_gap(g, c);
        eprintln!(
            "rod {r}: largest gap GPU − CPU {gap:.3e} m ({:.2e} of the travel)",
            gap / travel
        );
        assert!(gap <= CROSS_TOL * travel, "rod {r}: {gap} m");
    }
    // The lower rod was pushed down by the upper one, as far as on the CPU.
    let sag = |o: &Outcome| -f64::from(o.positions[1][12].z);
    eprintln!("sag: GPU {:.4e} m, CPU {:.4e} m", sag(&gpu), sag(&cpu));
    assert!(sag(&cpu) > 1e-3 && sag(&gpu) > 1e-3);
    eprintln!(
        "min separation / radii: GPU {:.4}, CPU {:.4}; most contacts GPU {}, CPU {}",
        gpu.min_ratio, cpu.min_ratio, gpu.max_contacts, cpu.max_contacts
    );
    assert!(gpu.min_ratio >= 0.99 && cpu.min_ratio >= 0.99);
    assert!(gpu.max_contacts > 0);
}

/// A rod across another (both ends of each held), its ends pushed down and along the lower
/// rod at once.
fn dragged(mu: f64) -> Case {
    let n = 24;
    let (sa, pa) = rod(&line([0.0, -0.024, 2.4e-3], [0.0, 1.0, 0.0], 0.048, n));
    let (sb, pb) = rod(&line([-0.024, 0.0, 0.0], [1.0, 0.0, 0.0], 0.048, n));
    let press = pinned_moving([0.1, 0.0, -0.2]);
    Case {
        rods: vec![
            (sa, pa, [press.clone(), press]),
            (sb, pb, [EndCondition::pinned(), EndCondition::pinned()]),
        ],
        spec: spec(mu),
    }
}

/// The upper rod pressed onto the lower one and dragged along it: with friction the part of it
/// that touches is held back (sticks) and the rod bows; without, it slides along with its ends;
/// on the GPU as on the CPU.
#[test]
fn friction_holds_a_dragged_rod_back_as_on_the_cpu() {
    let steps = 1500;
    let mut lag = Vec::new();
    for mu in [0.0, 2.0] {
        let case = dragged(mu);
        let Some(gpu) = case.gpu(steps) else {
            return;
        };
        let cpu = case.cpu(steps);
        let travel = 0.2 * 1e-5 * steps as f64;
        let gap = largest_gap(&gpu.positions[0], &cpu.positions[0]);
        eprintln!(
            "mu = {mu}: largest gap GPU − CPU {gap:.3e} m ({:.2e} of the travel)",
            gap / travel
        );
        // How far the middle of the upper rod lags behind its ends along x.
        let behind = |o: &Outcome| f64::from(o.positions[0][0].x - o.positions[0][12].x);
        eprintln!(
            "mu = {mu}: lag GPU {:.4e} m, CPU {:.4e} m; min separation / radii GPU {:.4}, CPU {:.4}; most contacts GPU {}, CPU {}",
            behind(&gpu),
            behind(&cpu),
            gpu.min_ratio,
            cpu.min_ratio,
            gpu.max_contacts,
            cpu.max_contacts
        );
        let tol = if mu > 0.0 { STICK_TOL } else { CROSS_TOL };
        assert!(gap <= tol * travel, "mu = {mu}: {gap} m");
        assert!(gpu.min_ratio >= 0.99, "mu = {mu}: {}", gpu.min_ratio);
        lag.push((behind(&gpu), behind(&cpu)));
    }
    let ((slip_g, slip_c), (stick_g, stick_c)) = (lag[0], lag[1]);
    assert!(stick_c > slip_c + 2e-4, "CPU: {stick_c} vs {slip_c}");
    assert!(stick_g > slip_g + 2e-4, "GPU: {stick_g} vs {slip_g}");
}

/// A coil of three turns, 2.5 mm apart, compressed along its axis by its held ends until its
/// turns press on each other: self-contact between segments a turn apart, as on the CPU, and
/// never closer than 99 % of the radii.
#[test]
fn a_compressed_coil_touches_itself_as_on_the_cpu() {
    let (turns, radius, pitch, n) = (3.0, 5e-3, 2.5e-3, 48);
    let pts: Vec<[f64; 3]> = (0..=n)
        .map(|i| {
            let a = std::f64::consts::TAU * turns * i as f64 / n as f64;
            let z = pitch * turns * i as f64 / n as f64;
            [radius * a.cos(), radius * a.sin(), z]
        })
        .collect();
    let (s, p) = rod(&pts);
    let case = Case {
        rods: vec![(
            s,
            p,
            [
                pinned_moving([0.0, 0.0, V_COIL]),
                pinned_moving([0.0, 0.0, -V_COIL]),
            ],
        )],
        spec: spec(MU_COIL),
    };
    // Each end moves 1.6 mm: the coil shortens by 3.2 mm, twice what closes its three gaps.
    let steps = 8000;
    let Some(gpu) = case.gpu(steps) else {
        return;
    };
    let cpu = case.cpu(steps);
    let travel = V_COIL as f64 * 1e-5 * steps as f64;
    let gap = largest_gap(&gpu.positions[0], &cpu.positions[0]);
    eprintln!(
        "largest gap GPU − CPU {gap:.3e} m ({:.2e} of the travel)",
        gap / travel
    );
    eprintln!(
        "min separation / radii: GPU {:.4}, CPU {:.4}; most contacts GPU {}, CPU {}",
        gpu.min_ratio, cpu.min_ratio, gpu.max_contacts, cpu.max_contacts
    );
    assert!(gpu.max_contacts >= 4, "{}", gpu.max_contacts);
    assert!(gap <= COIL_TOL * travel, "{gap} m");
    assert!(gpu.min_ratio >= 0.99 && cpu.min_ratio >= 0.99);
}

/// The stepper reports the rod-contact statistics the facade prints (`min_separation`).
#[test]
fn the_stepper_reports_rod_contact_statistics() {
    let case = crossing(0.4);
    let Some(mut stepper) = built(GpuStepper::new(
        case.gpu_input(),
        &settings(),
        GpuOptions::default(),
    )) else {
        return;
    };
    stepper.advance(1500).expect("steps");
    let c = stepper.coupling_stats().expect("statistics");
    assert!(c.max_contacts > 0 && c.steps == 1500, "{c:?}");
    assert!(
        c.min_separation.is_finite() && (c.min_separation_radii - 2.0 * RADIUS).abs() < 1e-9,
        "{c:?}"
    );
    assert!((c.min_separation / c.min_separation_radii - c.min_separation_ratio).abs() < 1e-6);
}

/// The impulses of contacts sharing a point are summed as integers, in no particular order but
/// to the same sum: two runs of the pressed crossing are the same bit for bit, and so are the
/// steps after a snapshot and the same steps after restoring it.
#[test]
fn contacts_step_the_same_on_every_run_and_after_a_restore() {
    let case = crossing(0.4);
    let make = || GpuSimulation::new(case.gpu_input(), &settings(), GpuOptions::default());
    let Some(mut sim) = built(make()) else {
        return;
    };
    sim.step(1200).expect("steps");
    let snap = sim.snapshot().expect("snapshot");
    sim.step(300).expect("steps");
    let first = sim.read_state().expect("read");
    assert!(sim.rod_contact_stats().expect("stats").contacts > 0);
    sim.restore(&snap).expect("restore");
    sim.step(300).expect("steps");
    let again = sim.read_state().expect("read");
    let mut other = make().expect("a second simulation");
    other.step(1500).expect("steps");
    let fresh = other.read_state().expect("read");
    for r in 0..2 {
        assert_eq!(first[r].positions, again[r].positions, "rod {r}: restored");
        assert_eq!(
            first[r].velocities, again[r].velocities,
            "rod {r}: restored"
        );
        assert_eq!(
            first[r].positions, fresh[r].positions,
            "rod {r}: second run"
        );
    }
}

/// What the kernel cannot step is refused before anything runs: rod contact on some rods only,
/// with other settings on another rod, or on extensible rods.
#[test]
fn rod_contact_the_kernel_cannot_step_is_refused() {
    let refused = |mut rods: Vec<GpuRodInput>, s: SolverSettings<f32>| {
        GpuSimulation::new(std::mem::take(&mut rods), &s, GpuOptions::default())
            .err()
            .map(|e| e.to_string())
    };
    let case = crossing(0.4);
    let mut some = case.gpu_input();
    some[1].rod_contact = None;
    let e = refused(some, settings()).expect("refused");
    assert!(e.contains("every rod touches the others or none"), "{e}");
    let mut other = case.gpu_input();
    if let Some(c) = other[1].rod_contact.as_mut() {
        c.margin *= 2.0;
    }
    let e = refused(other, settings()).expect("refused");
    assert!(e.contains("settings differ"), "{e}");
    // Checked when the kernel is planned, after an adapter is found.
    let extensible = SolverSettings {
        extensible: true,
        ..settings()
    };
    let e = refused(case.gpu_input(), extensible).expect("refused");
    assert!(
        e.contains("inextensible rods only") || (!gpu_required() && e.contains("adapter")),
        "{e}"
    );
}
