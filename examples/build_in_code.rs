//! Builds a scene in code: a guidewire-like rod with a curved tip, clamped at its base, pushed
//! forward and twisted, and prints where its tip goes.
//!
//! Run with `cargo run --release --example build_in_code`.

use cosserat::cosserat_model::rod::RestShape;
use cosserat::{
    EndCondition, Material, PrescribedMotion, RodBuilder, RodHandle, SimulationBuilder,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // A soft polymer wire, 0.3 m long, 1 mm thick, with an intrinsic bend of 1/(10 cm).
    let polymer = Material::new(5.0e7, 5.0e7 / 3.0, 1200.0, 0.5e-3);
    let push_and_twist = PrescribedMotion {
        velocity: [0.05, 0.0, 0.0].into(),
        angular_velocity: [std::f64::consts::PI, 0.0, 0.0].into(),
        start_time: 0.0,
        end_time: 0.5,
    };
    let wire = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], 0.3, 150, polymer)
        .name("wire")
        .rest_shape(RestShape::Uniform([10.0, 0.0, 0.0]))
        .damping(0.0, 0.0, 5.0)
        .start(EndCondition::clamped().driven(push_and_twist));
    let mut sim = SimulationBuilder::new()
        .dt(1.5e-6)
        .iterations(10)
        .gravity([0.0, 0.0, -9.81])
        .with_rod(wire)
        .build()?;
    let wire = RodHandle(0);
    for _ in 0..10 {
        sim.run(40_000)?;
        let tip = *sim.positions(wire).last().expect("a rod has points");
        println!(
            "t = {:.2} s  tip = [{:+.4}, {:+.4}, {:+.4}] m  max strain {:.1e}",
            sim.time(),
            tip[0],
            tip[1],
            tip[2],
            sim.max_strain()
        );
    }
    Ok(())
}
