//! A scripted hand steers a guidewire: every 1 ms tick it sets a new push speed and rotation
//! rate of the wire's held end through the control API, steps the simulation, and reads the
//! force at the hand, as a haptic device's loop or a learning agent would.
//!
//! ```sh
//! cargo run --release --example steer                   # CPU: the nitinol wire into the vessel
//! cargo run --release --example steer -- --backend gpu  # GPU: a soft wire in free space
//! ```
//!
//! On the CPU the wire is `scenes/nitinol-guidewire-insertion.toml` (a 0.014 inch nitinol
//! guidewire, the stiff scheme at 0.1 ms, ten steps per tick) pushed into the generated vessel
//! through its introducer; the scene's own constant push is replaced by the hand's. The GPU
//! backend has no stiff scheme yet, so there the hand steers a soft wire in free space with the
//! paper's explicit scheme (500 steps of 2 µs a tick); the hand force is the held end's
//! reaction, as on the CPU.

use std::path::Path;

use cosserat::scene::load_scene;
use cosserat::{Backend, Material, RodBuilder, RodHandle, SimulationBuilder, StateField};

/// Ticks of the hand, 1 ms each.
const TICKS: usize = 600;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let backend = match args.iter().position(|a| a == "--backend") {
        None => Backend::Cpu,
        Some(i) => match args.get(i + 1).map(String::as_str) {
            Some("cpu") => Backend::Cpu,
            Some("gpu") => Backend::Gpu,
            other => return Err(format!("--backend cpu|gpu, not {other:?}").into()),
        },
    };
    let builder = match backend {
        Backend::Gpu => free_wire(),
        _ => {
            let path = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("scenes/nitinol-guidewire-insertion.toml");
            load_scene(&path, &[])?.0
        }
    };
    let tick = 1e-3;
    let steps_per_tick = (tick / builder.time_step()).round().max(1.0) as u64;
    let mut sim = builder.backend(backend).build()?;
    let wire = RodHandle(0);
    let n = sim.stepper().elements(wire.0)?;
    let mut points = vec![[0.0; 3]; n + 1];
    sim.read(wire, StateField::Positions, &mut points)?;
    // The hand pushes along the wire's first element and twists about it.
    let axis = {
        let d = [
            points[1][0] - points[0][0],
            points[1][1] - points[0][1],
            points[1][2] - points[0][2],
        ];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|x| x / l)
    };
    println!(
        "{} stepper, {} steps of {:.1e} s per 1 ms tick",
        sim.stepper_info().name,
        steps_per_tick,
        sim.dt()
    );
    println!(
        "  t [s]  push [m/s]  twist [rad/s]  tip [m]                        |F| hand [N]  tick [µs]"
    );
    let mut worst_tick = 0.0f64;
    for k in 0..TICKS {
        let t = k as f64 * tick;
        // The script: push in with a slow surge, pull back briefly, and twist back and forth.
        let push = 0.12 + 0.08 * (2.0 * std::f64::consts::PI * 2.0 * t).sin()
            - if (0.3..0.35).contains(&t) { 0.3 } else { 0.0 };
        let twist = 6.0 * (2.0 * std::f64::consts::PI * 1.5 * t).cos();
        let started = std::time::Instant::now();
        sim.set_end_velocity(wire, 0, axis.map(|a| a * push), axis.map(|a| a * twist))?;
        sim.run(steps_per_tick)?;
        sim.read(wire, StateField::Positions, &mut points)?;
        let force = sim.end_reaction(wire, 0).map(|r| r.force_norm());
        let us = started.elapsed().as_secs_f64() * 1e6;
        worst_tick = worst_tick.max(us);
        if k % 50 == 49 {
            let tip = points[n];
            let force = force.map_or("      none".to_string(), |f| format!("{f:10.3e}"));
            println!(
                "  {:.3}  {push:+.3}      {twist:+6.2}         [{:+.4}, {:+.4}, {:+.4}]    {force}  {us:8.0}",
                sim.time(),
                tip[0],
                tip[1],
                tip[2],
            );
        }
    }
    if let Some(report) = sim.contact_report() {
        println!(
            "{} points in contact at the end, largest penetration {:.2e} m",
            report.contacts, report.max_penetration
        );
    }
    println!("slowest tick {worst_tick:.0} µs (a debug build is far slower than --release)");
    Ok(())
}

/// A soft 0.5 m wire in free space, held at its start, for the GPU (explicit scheme, `f32`).
fn free_wire() -> SimulationBuilder {
    let wire = RodBuilder::straight(
        [0.0; 3],
        [1.0, 0.0, 0.0],
        0.5,
        128,
        Material::new(5e6, 5e6 / 3.0, 1100.0, 4e-4),
    )
    .clamp_start()
    .damping(0.0, 0.0, 5.0);
    SimulationBuilder::new()
        .dt(2e-6)
        .gravity([0.0, 0.0, 0.0])
        .with_rod(wire)
}
