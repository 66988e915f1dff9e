//! Clamps that turn freely about an axis (hinges), checked against the end conditions they
//! must reproduce: a hinge about the axis a rod bends about leaves that bending free, as a pin
//! does; a hinge about an axis the rod does not bend about holds the bending, as a clamp does;
//! and the hinge carries no moment about its axis. Schemes that cannot run hinges refuse them
//! by name, and bad axes are refused with the field and the value.

use cosserat::cosserat_model::Material;
use cosserat::{
    EndCondition, RodBuilder, SimulationBuilder, StateField, StiffSettings, scene::parse_scene,
};
use std::path::Path;

const LENGTH: f64 = 0.1;
const N: usize = 10;

fn material() -> Material {
    Material::new(1e6, 1e6 / 3.0, 1000.0, 2e-3)
}

/// Points of a horizontal rod along x, held at its start by `start`, after `steps` steps of
/// 2e-5 s under gravity along −z (with drag `drag`), and the start's reaction torque.
fn run(start: EndCondition<f64>, steps: u64, drag: f64) -> (Vec<[f64; 3]>, [f64; 3]) {
    let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], LENGTH, N, material())
        .damping(0.0, 0.0, drag)
        .start(start);
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(2e-5)
        .gravity([0.0, 0.0, -9.81])
        .reaction_cutoff_hz(f64::INFINITY)
        .with_rod(rod)
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    sim.run(steps).unwrap();
    let mut x = vec![[0.0; 3]; N + 1];
    sim.read(h, StateField::Positions, &mut x).unwrap();
    let torque = sim.end_reaction(h, 0).unwrap().torque;
    (x, torque)
}

fn largest_difference(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f64::max)
}

/// A rod hinged about y (the axis its weight bends it about) swings down as a pinned one does:
/// the same points to rounding after it has fallen by a large angle.
#[test]
fn a_hinge_about_the_bending_axis_swings_like_a_pin() {
    let steps = 5_000; // 0.1 s: the tip falls by about 0.05 m
    let (hinged, torque) = run(
        EndCondition::clamped().hinged_about([0.0, 1.0, 0.0].into()),
        steps,
        0.0,
    );
    let (pinned, _) = run(EndCondition::pinned(), steps, 0.0);
    let (clamped, _) = run(EndCondition::clamped(), steps, 0.0);
    let fall = -hinged[N][2];
    assert!(fall > 0.02, "the hinged rod fell by only {fall} m");
    let d = largest_difference(&hinged, &pinned);
    assert!(d < 1e-6 * fall, "hinged and pinned differ by {d} m");
    // Not a pin by accident: the clamped rod is elsewhere.
    assert!(largest_difference(&hinged, &clamped) > 0.1 * fall);
    // No moment about the hinge's axis.
    assert!(
        torque[1].abs() < 1e-9,
        "moment about the hinge {} N m",
        torque[1]
    );
}

/// A rod hinged about z (vertical: its weight does not bend it about that axis) sags as a
/// clamped one does, and at rest the hinge carries the whole moment of the weight about y,
/// `g Σ m_i x_i` over the points where they hang, but none about z.
#[test]
fn a_hinge_about_another_axis_holds_like_a_clamp() {
    let m = material();
    // Damped to rest: the first mode critically damped, for 8 of its periods over 2π.
    let omega1 =
        3.516 * (m.bend_twist_stiffness()[0] / (m.linear_density() * LENGTH.powi(4))).sqrt();
    let drag = 2.0 * omega1;
    let steps = (8.0 / omega1 / 2e-5) as u64;
    let (hinged, torque) = run(
        EndCondition::clamped().hinged_about([0.0, 0.0, 1.0].into()),
        steps,
        drag,
    );
    let (clamped, _) = run(EndCondition::clamped(), steps, drag);
    let sag = -hinged[N][2];
    assert!(sag > 1e-3, "the hinged rod sagged by only {sag} m");
    let d = largest_difference(&hinged, &clamped);
    assert!(d < 1e-6 * sag, "hinged and clamped differ by {d} m");
    // Point masses: an element's mass shared between its two points.
    let element = m.linear_density() * LENGTH / N as f64;
    let moment: f64 = hinged
        .iter()
        .enumerate()
        .map(|(i, x)| {
            let mass = if i == 0 || i == N {
                0.5 * element
            } else {
                element
            };
            mass * 9.81 * x[0]
        })
        .sum();
    assert!(
        (torque[1] + moment).abs() < 0.01 * moment,
        "moment about y {} N m, the weight's {moment}",
        torque[1]
    );
    assert!(
        torque[2].abs() < 1e-9,
        "moment about the hinge {} N m",
        torque[2]
    );
}

#[test]
fn schemes_that_cannot_hinge_say_so_and_bad_axes_are_refused() {
    let rod = || RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], LENGTH, 8, material());
    let hinged = rod().start(EndCondition::clamped().hinged_about([0.0, 1.0, 0.0].into()));
    let e = SimulationBuilder::new()
        .dt(1e-3)
        .stiff_solver(Some(StiffSettings::default()))
        .with_rod(hinged)
        .build()
        .err()
        .expect("the stiff scheme ran a hinge")
        .to_string();
    assert!(e.contains("hinged clamps"), "{e}");
    // Through the control API: a pinned end has no frame to hinge.
    let mut sim = SimulationBuilder::new()
        .double_precision(true)
        .dt(1e-5)
        .with_rod(rod().start(EndCondition::pinned()))
        .build()
        .unwrap();
    let h = sim.rods().next().unwrap();
    let e = sim
        .set_end_condition(
            h,
            0,
            EndCondition::pinned().hinged_about([0.0, 1.0, 0.0].into()),
        )
        .unwrap_err()
        .to_string();
    assert!(e.contains("only a clamped end"), "{e}");
    // A scene: a hinge on a pinned end, and a zero axis.
    for (end, why) in [
        (
            "{ kind = \"pinned\", hinge = [0.0, 1.0, 0.0] }",
            "rod[0].start.kind",
        ),
        (
            "{ kind = \"clamped\", hinge = [0.0, 0.0, 0.0] }",
            "rod[0].start.hinge",
        ),
    ] {
        let toml = format!(
            "[solver]\ndt = 1e-5\nduration = 1e-4\n[[rod]]\nelements = 4\nshape = {{ kind = \"straight\", start = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.1 }}\n\
             material = {{ young_modulus = 1e6, poisson_ratio = 0.5, density = 1000.0, radius = 1e-3 }}\n\
             start = {end}\n"
        );
        let Err(e) = parse_scene(Path::new("hinge.toml"), &toml, &[]) else {
            panic!("{end} was accepted");
        };
        let e = e.to_string();
        assert!(e.contains(why), "{end}: {e}");
    }
}
