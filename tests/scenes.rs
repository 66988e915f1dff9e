//! Scene files: every shipped scene loads and runs a few steps; bad scenes are refused with the
//! file, the field and the value named, never a panic.

use cosserat::RodHandle;
use cosserat::scene::{SceneError, load_scene, parse_scene};
use std::path::Path;

const GOOD: &str = r#"
[solver]
dt = 2e-5
steps = 10
[[rod]]
elements = 8
shape = { kind = "straight", start = [0, 0, 0], direction = [1, 0, 0], length = 0.1 }
material = { young_modulus = 1e6, density = 1000, radius = 0.002 }
start = { kind = "clamped" }
"#;

fn error_for(text: &str) -> String {
    match parse_scene(Path::new("bad.toml"), text, &[]) {
        Ok(_) => panic!("the scene should have been refused:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn shipped_scenes_load_and_run() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            // As shipped: a scene's resolution, step and materials belong together.
            let (builder, _, _) = load_scene(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
            let mut sim = builder
                .build()
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            sim.run(5)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            count += 1;
        }
    }
    assert!(count >= 1, "no scene files found in {}", dir.display());
}

#[test]
fn a_good_scene_builds() {
    let (b, run, name) = parse_scene(Path::new("good.toml"), GOOD, &[]).unwrap();
    assert_eq!(run.steps, 10);
    assert_eq!(name, "good");
    let sim = b.build().unwrap();
    assert_eq!(sim.element_count(), 8);
}

#[test]
fn bad_values_name_file_field_and_value() {
    let cases = [
        (
            GOOD.replace("radius = 0.002", "radius = -0.002"),
            "rod[0].material.radius",
            "-0.002",
        ),
        (GOOD.replace("dt = 2e-5", "dt = 0.0"), "solver.dt", "0.0"),
        (
            GOOD.replace("elements = 8", "elements = 0"),
            "rod[0].elements",
            "0",
        ),
        (
            GOOD.replace("kind = \"clamped\"", "kind = \"glued\""),
            "rod[0].start.kind",
            "glued",
        ),
        (
            GOOD.replace("[solver]", "[solver]\nmode = \"stretchy\""),
            "solver.mode",
            "stretchy",
        ),
        (
            GOOD.replace("direction = [1, 0, 0]", "direction = [0, 0, 0]"),
            "rod[0].shape.direction",
            "0.0",
        ),
        (
            GOOD.replace("density = 1000", "density = nan"),
            "rod[0].material.density",
            "NaN",
        ),
        (
            GOOD.replace(
                "start = { kind = \"clamped\" }",
                "start = { kind = \"free\", velocity = [1, 0, 0] }",
            ),
            "rod[0].start.kind",
            "free",
        ),
        (
            GOOD.replace(
                "start = { kind = \"clamped\" }",
                "start = { kind = \"free\", slide = [1, 0, 0] }",
            ),
            "rod[0].start.kind",
            "free",
        ),
        (
            GOOD.replace(
                "start = { kind = \"clamped\" }",
                "start = { kind = \"pinned\", slide = [0, 0, 0] }",
            ),
            "rod[0].start.slide",
            "0.0",
        ),
        (
            GOOD.replace(
                "start = { kind = \"clamped\" }",
                "start = { kind = \"clamped\", path = { times = [0.5, 1.0] } }",
            ),
            "rod[0].start.path",
            "keyframes",
        ),
        (
            GOOD.replace(
                "start = { kind = \"clamped\" }",
                "start = { kind = \"pinned\", path = { times = [0, 1], rotation = [[0, 0, 0], [1, 0, 0]] } }",
            ),
            "rod[0].start.kind",
            "pinned",
        ),
        (
            GOOD.replace(
                "start = { kind = \"clamped\" }",
                "start = { kind = \"pinned\", slide = [1, 0, 0], path = { times = [0, 1], displacement = [[0, 0, 0], [0.1, 0.01, 0]] } }",
            ),
            "rod[0].start.path.displacement",
            "0.1",
        ),
        (
            GOOD.replace(
                "steps = 10",
                "steps = 10\nscheme = \"stiff\"\n[solver.stiff]\nrefactor = \"sometimes\"",
            ),
            "solver.stiff.refactor",
            "sometimes",
        ),
        (
            GOOD.replace(
                "steps = 10",
                "steps = 10\nscheme = \"stiff\"\n[solver.stiff]\nintegrator = \"rk4\"",
            ),
            "solver.stiff.integrator",
            "rk4",
        ),
        (
            GOOD.replace(
                "steps = 10",
                "steps = 10\nscheme = \"stiff\"\n[solver.stiff]\nhalve_above = -0.5",
            ),
            "solver.stiff.halve_above",
            "-0.5",
        ),
        (
            GOOD.replace(
                "steps = 10",
                "steps = 10\nscheme = \"stiff\"\n[solver.stiff]\ncontact_rows = \"pins\"",
            ),
            "solver.stiff.contact_rows",
            "pins",
        ),
        (
            GOOD.to_string() + "[[rod.load]]\npoint = 99\nforce = [0, 0, 1]\n",
            "rod[0].load[0].point",
            "99",
        ),
        (
            GOOD.to_string()
                + "[[rod.load]]\npoint = -1\nmoment = [0, 1e-4, 0]\nprofile = { kind = \"ramp\", duration = -1 }\n",
            "rod[0].load[0].profile.duration",
            "-1",
        ),
        (
            GOOD.to_string()
                + "[[rod.load]]\nat = 0.5\nforce = [0, 0, 1]\nprofile = { kind = \"table\", points = [[0, 1], [0, 2]] }\n",
            "rod[0].load[0].profile.points",
            "must increase",
        ),
        (
            GOOD.to_string() + "[[rod.distributed_load]]\npoint = 3\nforce = [0, 0, -1]\n",
            "rod[0].distributed_load[0]",
            "point = Some(3)",
        ),
        (
            GOOD.to_string() + "[batch]\ncopies = 2\ngpus = 0\n",
            "batch.gpus",
            "0",
        ),
        (
            GOOD.to_string() + "[batch]\ncopies = 2\ngpus = \"every\"\n",
            "batch.gpus",
            "\"every\"",
        ),
    ];
    for (text, field, value) in cases {
        let msg = error_for(&text);
        assert!(msg.starts_with("bad.toml:"), "{msg}");
        assert!(msg.contains(field), "expected field `{field}` in: {msg}");
        assert!(msg.contains(value), "expected value `{value}` in: {msg}");
    }
}

/// `[batch] copies = N` steps N copies of the rods, each exactly as the scene alone, steered
/// one by one; `gpus` only says where they run (the CPU backends ignore it).
#[test]
fn copies_of_a_scene_step_as_the_scene_alone() {
    let text = GOOD.replace(
        "start = { kind = \"clamped\" }",
        "start = { kind = \"clamped\" }\nend = { kind = \"pinned\" }",
    );
    let (alone, _, _) = parse_scene(Path::new("good.toml"), &text, &[]).unwrap();
    let batch = text + "[batch]\ncopies = 3\ngpus = \"all\"\n";
    let (b, _, _) = parse_scene(Path::new("batch.toml"), &batch, &[]).unwrap();
    let mut alone = alone.build().unwrap();
    let mut copies = b.build().unwrap();
    assert_eq!(copies.rods().count(), 3);
    let push = [0.0, 0.05, 0.0];
    alone
        .set_end_velocity(RodHandle(0), 1, push, [0.0; 3])
        .unwrap();
    copies
        .set_end_velocity(RodHandle(1), 1, push, [0.0; 3])
        .unwrap();
    alone.run(200).unwrap();
    copies.run(200).unwrap();
    let pushed = alone.positions(RodHandle(0));
    assert_eq!(copies.positions(RodHandle(1)), pushed);
    for still in [0, 2] {
        let p = copies.positions(RodHandle(still));
        assert_eq!(p, copies.positions(RodHandle(2 - still)));
        assert_ne!(p, pushed, "copy {still} was not pushed");
    }
    // Several GPUs alone ask for no copies.
    let (b, _, _) = parse_scene(
        Path::new("gpus.toml"),
        &(GOOD.to_string() + "[batch]\ngpus = 2\n"),
        &[],
    )
    .unwrap();
    assert_eq!(b.build().unwrap().rods().count(), 1);
}

#[test]
fn unknown_fields_and_wrong_types_are_refused() {
    let msg = error_for(&GOOD.replace("radius = 0.002", "radius = 0.002, radious = 1"));
    assert!(msg.contains("radious"), "{msg}");
    let msg = error_for(&GOOD.replace("elements = 8", "elements = \"eight\""));
    assert!(
        msg.starts_with("bad.toml:") && msg.contains("elements"),
        "{msg}"
    );
    let msg = error_for("this is not toml = = =");
    assert!(msg.starts_with("bad.toml:"), "{msg}");
}

#[test]
fn overrides_apply_and_bad_ones_are_named() {
    let (b, _, _) = parse_scene(
        Path::new("good.toml"),
        GOOD,
        &[("rod.0.elements".into(), "20".into())],
    )
    .unwrap();
    assert_eq!(b.build().unwrap().element_count(), 20);
    let err = parse_scene(
        Path::new("good.toml"),
        GOOD,
        &[("rod.5.elements".into(), "20".into())],
    )
    .err()
    .unwrap();
    assert!(matches!(err, SceneError::Override { .. }), "{err}");
    assert!(err.to_string().contains("rod.5.elements"));
}

#[test]
fn a_missing_file_is_an_error_not_a_panic() {
    let err = load_scene(Path::new("does/not/exist.toml"), &[])
        .err()
        .unwrap();
    assert!(err.to_string().contains("does/not/exist.toml"), "{err}");
}

/// The stiff scheme steps bindings (`scenes/catheter-guidewire.toml`) and rod–rod and
/// self-contact (`scenes/fishermans-knot.toml`, whose loose knot has parts within the margin of
/// each other).
#[test]
fn the_stiff_scheme_takes_bindings_and_rod_contact() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let stiff = [("solver.scheme".to_string(), "\"stiff\"".to_string())];
    let (builder, _, _) = load_scene(&dir.join("catheter-guidewire.toml"), &stiff).unwrap();
    let mut sim = builder.build().unwrap();
    sim.run(3).unwrap();
    assert!(sim.coupling_stats().unwrap().bound_points > 0);
    let (builder, _, _) = load_scene(&dir.join("fishermans-knot.toml"), &stiff).unwrap();
    let mut sim = builder.build().unwrap();
    sim.run(2).unwrap();
    let stats = sim.coupling_stats().unwrap();
    assert_eq!(stats.steps, 2, "{stats:?}");
    assert!(stats.min_separation_ratio >= 0.99, "{stats:?}");
}

/// `solver.stability_safety` sets the fraction of the estimated critical step below which the
/// explicit scheme runs without a warning: at 0.95 of the estimate the default (0.9) warns and
/// 1.0 does not, at 0.8 a fraction of 0.5 warns; a step above the estimate is refused whatever
/// the fraction; a fraction outside (0, 1] is refused naming the field.
#[test]
fn the_stability_safety_fraction_is_the_users() {
    use cosserat::cosserat_model::Material;
    use cosserat::cosserat_model::stability::{StabilityInput, stable_step};
    // The estimate of GOOD's rod: E = 1 MPa, ν = 0.5 (the default), 8 elements of 12.5 mm.
    let material = Material::new(1e6, 1e6 / 3.0, 1000.0, 0.002);
    let hc = stable_step(&StabilityInput::new(&material, 0.1 / 8.0, false)).critical_dt;
    let build = |dt: f64, safety: Option<f64>| -> Result<cosserat::Simulation, String> {
        let mut set = vec![("solver.dt".to_string(), format!("{dt:e}"))];
        if let Some(f) = safety {
            set.push(("solver.stability_safety".to_string(), format!("{f:?}")));
        }
        let (b, _, _) =
            parse_scene(Path::new("good.toml"), GOOD, &set).map_err(|e| e.to_string())?;
        b.build().map_err(|e| e.to_string())
    };
    let warned = |sim: &cosserat::Simulation| {
        sim.warnings()
            .iter()
            .any(|w| w.contains("below the estimated critical step"))
    };
    assert!(warned(&build(0.95 * hc, None).unwrap()));
    assert!(!warned(&build(0.95 * hc, Some(1.0)).unwrap()));
    assert!(warned(&build(0.8 * hc, Some(0.5)).unwrap()));
    assert!(!warned(&build(0.8 * hc, None).unwrap()));
    assert!(build(1.1 * hc, Some(1.0)).is_err());
    for bad in [0.0, 1.5, -0.2] {
        let e = match build(0.4 * hc, Some(bad)) {
            Ok(_) => panic!("{bad} accepted"),
            Err(e) => e,
        };
        assert!(
            e.contains("solver.stability_safety") && e.contains(&format!("{bad}")),
            "{e}"
        );
    }
}

/// `environment.mesh.seed` draws a random vessel: the same seed the same anatomy, another seed
/// another one, each with its branches' centrelines for placing and scoring rods.
#[test]
fn a_seeded_vessel_is_a_reproducible_random_anatomy() {
    let scene = |seed: u64| {
        format!(
            "{GOOD}\n[environment]\nmesh = {{ kind = \"vessel\", triangles = 4000, seed = {seed} }}\n"
        )
    };
    let geometry = |seed: u64| {
        let (b, _, _) = parse_scene(Path::new("seeded.toml"), &scene(seed), &[]).unwrap();
        let env = b.environment_ref().expect("an environment").clone();
        let v = env.vessel.expect("a generated vessel");
        (v.trunk.expect("a trunk").points, v.branches)
    };
    let (trunk, branches) = geometry(3);
    assert!(
        (2..=4).contains(&branches.len()),
        "{} branches",
        branches.len()
    );
    let (again, _) = geometry(3);
    assert_eq!(trunk, again);
    let (other, _) = geometry(4);
    assert_ne!(trunk, other);
    let err = error_for(&format!(
        "{GOOD}\n[environment]\nmesh = {{ kind = \"vessel\", seed = -1 }}\n"
    ));
    assert!(
        err.contains("environment.mesh") && err.contains("-1"),
        "{err}"
    );
}

/// A load placed `at` a fraction of the rod acts on the nearest point, whatever the number of
/// elements; `point` and `at` together, or a fraction outside 0..=1, are refused by name.
#[test]
fn a_load_at_a_fraction_follows_the_elements() {
    let with_load = |load: &str, elements: usize| {
        let text = format!("{GOOD}\n[[rod.load]]\n{load}\nforce = [0.0, 0.0, -0.01]\n");
        let over = [("rod.0.elements".to_string(), elements.to_string())];
        let (b, _, _) = parse_scene(Path::new("load.toml"), &text, &over).unwrap();
        let mut sim = b.build().unwrap();
        sim.run(50).unwrap();
        sim.positions(RodHandle(0))
    };
    assert_eq!(with_load("at = 1.0", 8), with_load("point = -1", 8));
    assert_eq!(with_load("at = 0.5", 8), with_load("point = 4", 8));
    assert_eq!(with_load("at = 0.5", 16), with_load("point = 8", 16));
    let both = error_for(&format!(
        "{GOOD}\n[[rod.load]]\npoint = 2\nat = 0.5\nforce = [0.0, 0.0, -0.01]\n"
    ));
    assert!(
        both.contains("rod[0].load[0]") && both.contains("exactly one"),
        "{both}"
    );
    let outside = error_for(&format!(
        "{GOOD}\n[[rod.load]]\nat = 1.5\nforce = [0.0, 0.0, -0.01]\n"
    ));
    assert!(
        outside.contains("load[0].at") && outside.contains("1.5"),
        "{outside}"
    );
}

/// A rod built stretched (`rest_length` shorter than its shape, or `pre_strain`) and pinned at
/// both ends holds the tension `E A ε` of its strain: the pins' reactions pull outwards with it,
/// and the two ways of saying the strain build the same rod. Both together are refused.
#[test]
fn a_pre_stretched_rod_holds_its_tension() {
    let (e, r, eps) = (1e6_f64, 0.002_f64, 0.01_f64);
    let scene = |strain: &str| {
        format!(
            r#"
[solver]
dt = 2e-5
steps = 10
mode = "extensible"
gravity = [0.0, 0.0, 0.0]
[[rod]]
elements = 8
shape = {{ kind = "straight", start = [0, 0, 0], direction = [1, 0, 0], length = 0.1 }}
material = {{ young_modulus = {e}, density = 1000, radius = {r} }}
{strain}
start = {{ kind = "pinned" }}
end = {{ kind = "pinned" }}
"#
        )
    };
    let run = |strain: &str| {
        let (b, _, _) = parse_scene(Path::new("taut.toml"), &scene(strain), &[]).unwrap();
        let mut sim = b.reaction_cutoff_hz(f64::INFINITY).build().unwrap();
        sim.run(200).unwrap();
        let h = RodHandle(0);
        (
            sim.end_reaction(h, 0).unwrap().force,
            sim.end_reaction(h, 1).unwrap().force,
            sim.positions(h),
        )
    };
    let tension = e * std::f64::consts::PI * r * r * eps;
    let (start, end, p) = run(&format!("rest_length = {}", 0.1 / (1.0 + eps)));
    assert!(
        (start[0] / -tension - 1.0).abs() < 1e-3,
        "{start:?} vs {tension}"
    );
    assert!(
        (end[0] / tension - 1.0).abs() < 1e-3,
        "{end:?} vs {tension}"
    );
    let (_, _, q) = run(&format!("pre_strain = {eps}"));
    for (a, b) in p.iter().zip(&q) {
        assert!(
            (0..3).all(|k| (a[k] - b[k]).abs() < 1e-12),
            "{a:?} vs {b:?}"
        );
    }
    let err = error_for(&scene("pre_strain = 0.01\nrest_length = 0.09"));
    assert!(
        err.contains("pre_strain") && err.contains("one of them"),
        "{err}"
    );
    let err = error_for(&scene("pre_strain = -1.5"));
    assert!(err.contains("pre_strain") && err.contains("-1.5"), "{err}");
}

/// `rest_lengths` gives every element its own rest length: a rod whose first half is built
/// stretched by 2 % and second half unstretched, pinned at both ends, relaxes until both halves
/// carry one tension; a wrong count or length is refused by name.
#[test]
fn rest_lengths_per_element_set_an_uneven_strain() {
    let scene = |rest: &str| {
        format!(
            r#"
[solver]
dt = 2e-5
steps = 10
mode = "extensible"
precision = "f64"
gravity = [0.0, 0.0, 0.0]
[[rod]]
elements = 4
shape = {{ kind = "straight", start = [0, 0, 0], direction = [1, 0, 0], length = 0.1 }}
material = {{ young_modulus = 1e6, density = 1000, radius = 0.002 }}
damping = {{ drag = 2000.0 }}
rest_lengths = {rest}
start = {{ kind = "pinned" }}
end = {{ kind = "pinned" }}
"#
        )
    };
    let (a, b) = (0.025 / 1.02, 0.025);
    let (builder, _, _) = parse_scene(
        Path::new("uneven.toml"),
        &scene(&format!("[{a}, {a}, {b}, {b}]")),
        &[],
    )
    .unwrap();
    let mut sim = builder.build().unwrap();
    sim.run(20_000).unwrap();
    let p = sim.positions(RodHandle(0));
    // Equal tension: equal strain in every element; total length 0.1 over the rest 0.1 − 0.05·(0.02/1.02).
    let rest_total = 2.0 * a + 2.0 * b;
    let strain = 0.1 / rest_total - 1.0;
    for (j, rest) in [a, a, b, b].iter().enumerate() {
        let l = p[j + 1][0] - p[j][0];
        assert!(
            (l / rest - 1.0 - strain).abs() < 1e-6,
            "element {j}: {l} over {rest}: strain {} against {strain}",
            l / rest - 1.0
        );
    }
    let err = error_for(&scene("[0.025, 0.025]"));
    assert!(
        err.contains("rest_lengths") && err.contains("one per element: 4"),
        "{err}"
    );
    let err = error_for(&scene("[0.025, 0.025, -1.0, 0.025]"));
    assert!(
        err.contains("rest_lengths[2]") && err.contains("-1"),
        "{err}"
    );
}
