//! Builds a guidewire inside a catheter in code and steps it as a 1 kHz haptic loop would: a
//! nitinol wire (the `nitinol` preset, 0.014 inch) bound two-way inside a polymer catheter (the
//! `catheter-polymer` preset), both held at their hubs and pushed forward under gravity, with
//! the stiff scheme at one 1 ms step per tick. Prints, every 0.2 s, both tips, how far the wire
//! tip is ahead of the catheter's along x (it starts 5 cm inside and comes out after 1.7 s),
//! the force each hand feels, and the mean wall time of a tick.
//!
//! Run with `cargo run --release --example guidewire_in_catheter`.

use cosserat::cosserat_backend_cpu::StiffSettings;
use cosserat::cosserat_constraints::BindingVariant;
use cosserat::cosserat_model::presets::preset;
use cosserat::{EndCondition, PrescribedMotion, RodBuilder, SimulationBuilder};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let push = |speed: f64| PrescribedMotion {
        velocity: [speed, 0.0, 0.0].into(),
        angular_velocity: [0.0; 3].into(),
        start_time: 0.0,
        end_time: f64::INFINITY,
    };
    let catheter_material = preset("catheter-polymer")
        .ok_or("no catheter preset")?
        .material();
    let wire_material = preset("nitinol").ok_or("no nitinol preset")?.material();
    // The catheter: 0.3 m from its hub at the origin, 2 mm elements, pushed at 5 cm/s.
    let catheter = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], 0.3, 150, catheter_material)
        .name("catheter")
        .damping(0.0, 0.0, 5.0)
        .start(EndCondition::clamped().driven(push(0.05)));
    // The wire: held 10 cm behind the hub, its tip 5 cm inside the catheter, pushed 3 cm/s
    // faster than the catheter, so its hand stays behind the hub.
    let wire = RodBuilder::straight([-0.1, 0.0, 0.0], [1.0, 0.0, 0.0], 0.35, 175, wire_material)
        .name("guidewire")
        .damping(0.0, 0.0, 5.0)
        .start(EndCondition::clamped().driven(push(0.08)));
    let mut builder = SimulationBuilder::new()
        .dt(1e-3)
        .gravity([0.0, 0.0, -9.81])
        .double_precision(true)
        .stiff_solver(Some(StiffSettings::default()))
        .reaction_cutoff_hz(50.0);
    let catheter = builder.add_rod(catheter);
    let wire = builder.add_rod(wire);
    let mut sim = builder
        .bind(wire, catheter, BindingVariant::TwoWay)
        .build()?;
    println!(
        "  t [s]   catheter tip [m]              wire tip [m]                  ahead [mm]  |F| hub [N]  |F| wire hand [N]  tick [µs]"
    );
    for _ in 0..10 {
        // A haptic loop calls `step` once per tick; here 200 ticks between prints.
        let start = std::time::Instant::now();
        for _ in 0..200 {
            sim.step()?;
        }
        let tick_us = start.elapsed().as_secs_f64() * 1e6 / 200.0;
        let tip = |h| *sim.positions(h).last().expect("a rod has points");
        let (c, w) = (tip(catheter), tip(wire));
        let force = |h| sim.end_reaction(h, 0).map_or(f64::NAN, |r| r.force_norm());
        println!(
            "  {:.2}   [{:+.4}, {:+.4}, {:+.4}]   [{:+.4}, {:+.4}, {:+.4}]   {:8.1}    {:.2e}     {:.2e}          {:6.0}",
            sim.time(),
            c[0],
            c[1],
            c[2],
            w[0],
            w[1],
            w[2],
            (w[0] - c[0]) * 1e3,
            force(catheter),
            force(wire),
            tick_us,
        );
    }
    let stiff = sim.stiff_summary().ok_or("the stiff solver ran")?;
    println!(
        "{:.2} iterations per rod-step, {} of {} rod-steps above the tolerance; {} wire points bound",
        stiff.iterations_per_step(),
        stiff.unconverged_steps,
        stiff.steps_kept,
        sim.coupling_stats().map_or(0, |c| c.bound_points),
    );
    Ok(())
}
