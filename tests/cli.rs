//! The `cosserat` command as a user runs it.

use std::process::Command;

fn cosserat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cosserat"))
}

/// Runs `cosserat` with `args` (from the repository root), expects success and returns its
/// JSON output.
fn run_json(args: &[&str]) -> serde_json::Value {
    let out = cosserat()
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn run_json_reports_every_field() {
    let v = run_json(&[
        "run",
        "scenes/pendulum.toml",
        "--elements",
        "32",
        "--steps",
        "200",
        "--json",
    ]);
    for key in [
        "scene",
        "backend",
        "elements",
        "steps",
        "dt",
        "wall_s",
        "us_per_step",
        "max_strain",
        "kinetic_energy",
        "potential_energy",
        "tip",
        "diverged",
    ] {
        assert!(v.get(key).is_some(), "missing `{key}` in {v}");
    }
    assert_eq!(v["elements"], 32);
    assert_eq!(v["steps"], 200);
    assert_eq!(v["diverged"], false);
    assert!(v["max_strain"].as_f64().unwrap() < 1e-2);
    assert!(
        v["kinetic_energy"].as_f64().unwrap() > 0.0,
        "the pendulum has started to swing"
    );
}

/// The JSON report reads back as the library's typed `RunReport`, with its optional parts
/// present exactly when the scene has them.
#[test]
fn the_json_report_is_the_typed_run_report() {
    use cosserat::report::RunReport;
    let typed = |args: &[&str]| -> RunReport {
        serde_json::from_value(run_json(args)).expect("a RunReport")
    };
    let free = typed(&[
        "run",
        "scenes/pendulum.toml",
        "--elements",
        "16",
        "--steps",
        "20",
        "--json",
    ]);
    assert_eq!(free.steps, 20);
    assert_eq!(free.stepper, "cpu explicit");
    assert!(free.us_per_step.is_some_and(|us| us > 0.0));
    assert!(free.contact.is_none() && free.stiff.is_none() && free.coupling.is_none());
    assert_eq!(free.tips.len(), 1);
    let vessel = typed(&[
        "run",
        "scenes/stiff-guidewire-insertion.toml",
        "--elements",
        "32",
        "--steps",
        "5",
        "--json",
    ]);
    assert_eq!(vessel.stepper, "cpu stiff");
    let contact = vessel.contact.expect("mesh contact figures");
    assert!(contact.triangles > 1000, "{contact:?}");
    assert!(vessel.stiff.is_some_and(|s| s.steps_kept == 5));
    assert!(vessel.max_reaction_force.is_some());
}

/// A run with the stiff solver says how well its steps converged.
#[test]
fn stiff_runs_report_their_convergence() {
    let v = run_json(&[
        "run",
        "scenes/nitinol-pendulum.toml",
        "--elements",
        "50",
        "--steps",
        "100",
        "--json",
    ]);
    let st = &v["stiff"];
    let it = st["iterations_per_step"].as_f64().unwrap();
    assert!((1.0..=2.0).contains(&it), "{st}");
    // The default refactorises once per step, and again only when an iteration stalls.
    let factorisations = st["factorisations_per_step"].as_f64().unwrap();
    assert!((1.0..=it).contains(&factorisations), "{st}");
    let unconverged = st["unconverged_steps"].as_u64().unwrap();
    let (residual, tolerance) = (
        st["max_residual"].as_f64().unwrap(),
        st["max_tolerance"].as_f64().unwrap(),
    );
    assert!(tolerance >= 1e-5, "{st}");
    // Without unconverged steps, no step's residual ended above its tolerance.
    assert!(unconverged > 0 || residual <= tolerance, "{st}");
    assert_eq!(st["axial_steps"], 0, "{st}");
    assert_eq!(st["halved_steps"], 0, "{st}");
    assert_eq!(st["steps_kept"], 100, "{st}");
}

/// `--step-times` times every step on its own, as a haptic loop calls it, and reports the
/// first step apart from the median, 99th percentile and largest of the others.
#[test]
fn step_times_report_percentiles() {
    let args = [
        "run",
        "scenes/nitinol-pendulum.toml",
        "--elements",
        "50",
        "--steps",
        "300",
        "--json",
    ];
    assert!(run_json(&args).get("step_us").is_none());
    let v = run_json(&[&args[..], &["--step-times"]].concat());
    let t = &v["step_us"];
    let get = |k: &str| t[k].as_f64().unwrap_or_else(|| panic!("`{k}` in {t}"));
    let (first, median, p99, max) = (get("first"), get("median"), get("p99"), get("max"));
    assert!(first > 0.0 && median > 0.0, "{t}");
    assert!(median <= p99 && p99 <= max, "{t}");
    assert_eq!(v["steps"], 300);
}

#[test]
fn a_diverging_run_says_where_and_exits_nonzero() {
    let out = cosserat()
        .args([
            "run",
            "scenes/pendulum.toml",
            "--elements",
            "200",
            "--steps",
            "2000",
            "--set",
            "solver.dt=5e-3",
            "--set",
            "solver.check_stability=false",
            "--json",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["diverged"], true);
    let why = v["divergence"].as_str().unwrap();
    assert!(
        why.contains("rod 0") && why.contains("element") && why.contains("step"),
        "{why}"
    );
}

/// `--out` writes the frames asked for, also when `--step-times` steps one step at a time.
/// A rod across the vessel's wall, most of it deep outside where no contact query reaches:
/// the run stops as diverged naming the rod and point, and with `environment.stop_outside =
/// false` it runs on and reports the true count and depth.
#[test]
fn a_rod_outside_the_lumen_stops_the_run_and_is_measured_at_any_depth() {
    let scene =
        std::env::temp_dir().join(format!("cosserat-cli-outside-{}.toml", std::process::id()));
    std::fs::write(
        &scene,
        r#"
name = "across-the-wall"
[solver]
dt = 1e-5
duration = 0.02
gravity = [0.0, 0.0, 0.0]
[environment]
mesh = { kind = "vessel", triangles = 26000 }
[[rod]]
elements = 20
shape = { kind = "straight", start = [0.05, 0.0, 0.0], direction = [0.0, 1.0, 0.0], length = 0.05 }
material = { young_modulus = 1.0e6, poisson_ratio = 0.5, density = 1100.0, radius = 0.0005 }
start = { kind = "clamped" }
"#,
    )
    .unwrap();
    let path = scene.to_str().unwrap();
    let out = cosserat().args(["run", path, "--json"]).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stopped: cosserat::report::RunReport = serde_json::from_slice(&out.stdout).unwrap();
    let why = stopped.divergence.clone().unwrap_or_default();
    assert!(
        why.contains("outside the lumen") && why.contains("rod 0"),
        "{why}"
    );
    assert!(stopped.steps < 2000, "stopped at step {}", stopped.steps);
    let v = run_json(&[
        "run",
        path,
        "--json",
        "--set",
        "environment.stop_outside=false",
    ]);
    let went_on: cosserat::report::RunReport = serde_json::from_value(v).unwrap();
    std::fs::remove_file(&scene).ok();
    assert!(!went_on.diverged);
    let c = went_on.contact.expect("contact figures");
    // The rod reaches 5 cm off the trunk's axis, whose lumen is about 1 cm wide: the deepest
    // point is more than 3 cm behind the wall, far beyond any contact query's reach.
    assert!(c.escaped_points >= 10, "{c:?}");
    assert!(c.max_penetration > 0.03, "{c:?}");
}

/// An entry far from the vessel, or one that does not lead into the lumen, is reported when the
/// scene is built: here the phantom insertion's entry is moved half a metre away from the
/// phantom, then turned away from it.
#[test]
fn an_entry_far_from_the_vessel_is_reported() {
    let run = |point: &str, direction: &str| {
        run_json(&[
            "run",
            "scenes/phantom-insertion.toml",
            "--elements",
            "16",
            "--steps",
            "1",
            "--json",
            "--set",
            &format!("environment.mesh.entry.point={point}"),
            "--set",
            &format!("environment.mesh.entry.direction={direction}"),
        ])["warnings"]
            .to_string()
    };
    let far = run("[500.0, 0.42, -0.32]", "[-1.0, 0.0, 0.0]");
    assert!(far.contains("4.99"), "{far}");
    assert!(
        far.contains("from where its axis reaches the lumen"),
        "{far}"
    );
    let away = run("[500.0, 0.42, -0.32]", "[1.0, 0.0, 0.0]");
    assert!(away.contains("does not lead into the lumen"), "{away}");
    let fine = run("[1.0, 0.42, -0.32]", "[-1.0, 0.0, 0.0]");
    assert!(!fine.contains("lumen"), "{fine}");
}

/// A simulation far larger than the machine's memory is refused with the numbers before it is
/// built (the kernel would otherwise kill it without a word).
#[test]
fn a_simulation_too_large_for_the_memory_is_refused() {
    let Some(available) = cosserat::sim::available_memory() else {
        return;
    };
    // The scenes' largest rod (10⁷ elements) with the stiff scheme in f64, about 44 GB: more
    // than this machine (24 GiB) has; a larger machine cannot be made to refuse it.
    let elements: u64 = 10_000_000;
    if elements * 3500 < available {
        eprintln!("note: {available} bytes available, more than the largest scene needs");
        return;
    }
    let started = std::time::Instant::now();
    let out = cosserat()
        .args(["run", "scenes/pendulum.toml", "--steps", "1", "--elements"])
        .arg(elements.to_string())
        .args([
            "--set",
            "solver.scheme=\"stiff\"",
            "--set",
            "solver.dt=1e-3",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("GiB available") && err.contains("stiff"),
        "{err}"
    );
    assert!(started.elapsed().as_secs_f64() < 120.0);
}

/// `cosserat mesh inspect` reports the shipped phantom as loaded and repaired.
#[test]
fn mesh_inspect_reports_the_phantom() {
    let v = run_json(&[
        "mesh",
        "inspect",
        "data/meshes/phantom.obj",
        "--scale",
        "0.001",
        "--json",
    ]);
    assert_eq!(v["triangles"], 6392, "{v}");
    assert_eq!(v["misoriented_edges_after"], 0, "{v}");
    assert_eq!(v["encloses_volume"], true, "{v}");
    assert!(v["lumen_volume"].as_f64().unwrap() > 0.0, "{v}");
    assert!(v["openings"].as_u64().unwrap() >= 1, "{v}");
    let out = cosserat()
        .args(["mesh", "inspect", "no/such/mesh.obj"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no/such/mesh.obj"));
}

/// A run of no steps is refused, whether asked for by steps or by a duration shorter than
/// half a step.
#[test]
fn a_run_of_no_steps_is_refused() {
    for extra in [["--steps", "0"], ["--duration", "1e-9"]] {
        let out = cosserat()
            .args(["run", "scenes/pendulum.toml"])
            .args(extra)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{extra:?} ran");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("no steps") && err.contains("pendulum.toml"),
            "{err}"
        );
    }
}

/// An output folder that cannot be made is an error before the first step: the run, which
/// would take minutes, does not start.
#[test]
fn an_unwritable_out_is_refused_before_the_run() {
    let file = std::env::temp_dir().join(format!("cosserat-cli-file-{}", std::process::id()));
    std::fs::write(&file, "a file, not a folder").unwrap();
    let target = file.join("out");
    let started = std::time::Instant::now();
    let out = cosserat()
        .args(["run", "scenes/guidewire-insertion.toml", "--out"])
        .arg(&target)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    std::fs::remove_file(&file).ok();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--out") && err.contains("cosserat-cli-file"),
        "{err}"
    );
    assert!(
        started.elapsed().as_secs_f64() < 60.0,
        "the refusal came after the run"
    );
}

/// SIGTERM (and Ctrl-C) stop a run between two batches: the frames so far are on disk as a
/// valid series, the NumPy file is written, the summary covers the steps taken, and the exit
/// status is 130.
#[test]
fn a_terminated_run_leaves_its_frames_and_its_summary() {
    let dir = std::env::temp_dir().join(format!("cosserat-cli-term-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let child = cosserat()
        .args([
            "run",
            "scenes/pendulum.toml",
            "--elements",
            "16",
            "--steps",
            "100000000",
            "--frames",
            "100000",
            "--json",
            "--out",
        ])
        .arg(&dir)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until a few frames are on disk.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !dir.join("frame_00003.vtp").is_file() {
        assert!(
            std::time::Instant::now() < deadline,
            "no frames were written"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: cosserat::report::RunReport = serde_json::from_slice(&out.stdout).unwrap();
    assert!(report.interrupted && !report.diverged);
    assert!(report.steps > 0 && report.steps < 100_000_000);
    let index = std::fs::read_to_string(dir.join("trajectory.pvd")).unwrap();
    let listed: Vec<&str> = index
        .lines()
        .filter_map(|l| l.split("file=\"").nth(1))
        .map(|l| l.trim_end_matches("\"/>"))
        .collect();
    assert!(listed.len() >= 4, "{index}");
    for f in &listed {
        let bytes = std::fs::read(dir.join(f)).unwrap();
        assert!(bytes.ends_with(b"</VTKFile>\n"), "{f} is cut short");
    }
    assert!(dir.join("trajectory.npz").is_file());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn out_writes_the_trajectory() {
    for (tag, extra) in [("batched", &[][..]), ("timed", &["--step-times"][..])] {
        let dir = std::env::temp_dir().join(format!("cosserat-cli-{}-{tag}", std::process::id()));
        let path = dir.to_str().expect("a UTF-8 temporary folder");
        let args = [
            "run",
            "scenes/pendulum.toml",
            "--elements",
            "16",
            "--steps",
            "100",
            "--frames",
            "5",
            "--json",
            "--out",
            path,
        ];
        run_json(&[&args[..], extra].concat());
        for f in [
            "trajectory.npz",
            "trajectory.pvd",
            "run.json",
            "frame_00000.vtp",
            "frame_00005.vtp",
        ] {
            assert!(dir.join(f).is_file(), "{tag}: missing {f}");
        }
        // The frames are spread evenly, the last at the run's end.
        let traj = cosserat::output::read_npz(&dir.join("trajectory.npz")).unwrap();
        let dt = traj.times[1] - traj.times[0];
        assert_eq!(traj.times.len(), 6, "{tag}");
        for w in traj.times.windows(2) {
            assert!(
                ((w[1] - w[0]) / dt - 1.0).abs() < 1e-9,
                "{tag}: {:?}",
                traj.times
            );
        }
        assert_eq!(traj.rods[0].velocities.len(), 6 * 17, "{tag}");
        assert_eq!(traj.rods[0].strains.len(), 6 * 16, "{tag}");
        assert!(
            !dir.join("frame_00006.vtp").exists(),
            "{tag}: a frame too many"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}

#[test]
fn bad_input_is_an_error_message() {
    let out = cosserat()
        .args(["run", "no-such-scene.toml"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no-such-scene.toml"), "{err}");
    let out = cosserat()
        .args(["run", "scenes/pendulum.toml", "--backend", "quantum"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("quantum"));
    // A rest curvature no pair of frames can have (|κ| l / 2 = 30 · 0.1 / 2 = 1.5 ≥ 1).
    let err = refused_nitinol_pendulum(&[
        "rod.0.elements=10",
        "rod.0.rest_shape={ curvature = [30.0, 0.0, 0.0] }",
    ]);
    assert!(err.contains("node 0") && err.contains("1.500"), "{err}");
    // A rest curvature tighter than the wire's radius (nitinol: r = 0.178 mm, 1/r = 5618 1/m).
    let err = refused_nitinol_pendulum(&["rod.0.rest_shape={ curvature = [0.0, 6000.0, 0.0] }"]);
    assert!(
        err.contains("tighter than its radius") && err.contains("6.0000e3"),
        "{err}"
    );
}

/// Runs `scenes/nitinol-pendulum.toml` with the overrides `sets`, which must make it refuse
/// the scene (exit status 2) with a message naming the file and the rod; returns the message.
fn refused_nitinol_pendulum(sets: &[&str]) -> String {
    let mut args = vec!["run", "scenes/nitinol-pendulum.toml"];
    for kv in sets {
        args.extend(["--set", kv]);
    }
    let out = cosserat()
        .args(&args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        err.contains("nitinol-pendulum.toml") && err.contains("rod 0"),
        "{err}"
    );
    err
}

/// `--backend gpu` runs the same scene as the CPU and lands in the same place. Skips (with a
/// note) where no GPU adapter exists at all; CI installs lavapipe so it runs there.
#[test]
fn the_gpu_backend_agrees_with_the_cpu() {
    let run = |backend: &str| {
        cosserat()
            .args([
                "run",
                "scenes/pendulum.toml",
                "--elements",
                "64",
                "--steps",
                "400",
                "--json",
                "--backend",
                backend,
            ])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .output()
            .unwrap()
    };
    let gpu = run("gpu");
    if !gpu.status.success() {
        let err = String::from_utf8_lossy(&gpu.stderr);
        assert!(
            err.contains("adapter"),
            "the GPU run failed for another reason than a missing adapter: {err}"
        );
        assert!(
            std::env::var("COSSERAT_REQUIRE_GPU").as_deref() != Ok("1"),
            "COSSERAT_REQUIRE_GPU=1 but: {err}"
        );
        eprintln!("note: no GPU adapter here, skipping: {err}");
        return;
    }
    let cpu = run("cpu");
    let (g, c): (serde_json::Value, serde_json::Value) = (
        serde_json::from_slice(&gpu.stdout).unwrap(),
        serde_json::from_slice(&cpu.stdout).unwrap(),
    );
    assert_eq!(g["backend"], "gpu");
    // The pinned end's force, computed by both (the GPU in its kernels). Its vertical part
    // agrees to 0.2 %; the rope's tension 8 ms after release is a small difference of large
    // impulses that f32 rounding moves by up to 15 % (measured at step 400: f64 -0.0112 N, the
    // CPU in f32 -0.0113, the GPU -0.0097, the GPU with the CPU's impulse formula -0.0121).
    let force = |v: &serde_json::Value, k: usize| v["reactions"][0]["force"][k].as_f64().unwrap();
    let (zc, zg) = (force(&c, 2), force(&g, 2));
    assert!(
        zc > 0.0 && (zg - zc).abs() < 0.01 * zc,
        "gpu {zg} N, cpu {zc} N"
    );
    let (xc, xg) = (force(&c, 0), force(&g, 0));
    assert!((xg - xc).abs() < 0.2 * xc.abs(), "gpu {xg} N, cpu {xc} N");
    let tip = |v: &serde_json::Value| -> Vec<f64> {
        v["tip"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (tg, tc) = (tip(&g), tip(&c));
    // The tip has dropped ~2 mm in 8 ms; both backends are f32 with red–black sweeps.
    let drop = tc[2].abs();
    assert!(drop > 1e-4, "the pendulum moved ({drop} m)");
    for k in 0..3 {
        assert!(
            (tg[k] - tc[k]).abs() < 1e-3 * drop + 1e-6,
            "tip[{k}]: gpu {} vs cpu {}",
            tg[k],
            tc[k]
        );
    }
}

/// A time step past the stability limit (1.75 times the estimated 2.86e-5 s) spins the frames
/// up while the segment lengths still hold (strain 0.22, below the limit of 0.5); the speed
/// check stops that run instead of reporting garbage. (Further past the limit, 8e-5 s and up,
/// the lengths give way first and the strain check stops it.)
#[test]
fn runaway_energy_is_caught_even_when_lengths_hold() {
    let out = cosserat()
        .args([
            "run",
            "scenes/pendulum.toml",
            "--elements",
            "1000",
            "--steps",
            "4000",
            "--set",
            "solver.dt=5e-5",
            "--set",
            "solver.check_stability=false",
            "--json",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["diverged"], true, "{v}");
    assert!(v["divergence"].as_str().unwrap().contains("speed"), "{v}");
}

/// `solver.constraint_solver = "direct"` holds segment lengths exactly where ten iterative
/// sweeps leave a visible strain on a 1000-element rod.
#[test]
fn the_direct_constraint_solver_is_exact() {
    let strain = |solver: &str| {
        let out = cosserat()
            .args([
                "run",
                "scenes/pendulum.toml",
                "--elements",
                "400",
                "--steps",
                "300",
                "--json",
                "--set",
                "solver.precision=\"f64\"",
                "--set",
            ])
            .arg(format!("solver.constraint_solver=\"{solver}\""))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        v["max_strain"].as_f64().unwrap()
    };
    let (iterative, direct) = (strain("iterative"), strain("direct"));
    assert!(direct < 1e-10, "direct solver strain {direct}");
    assert!(
        iterative > 1e3 * direct,
        "iterative {iterative} vs direct {direct}"
    );
}

/// A run whose stiff steps end far above their tolerance says so (`run_warnings`, and a
/// `warning:` line in the summary); the same scene converged says nothing.
#[test]
fn an_unconverged_run_is_flagged() {
    let run = |extra: &[&str]| {
        let args = [
            &[
                "run",
                "scenes/nitinol-pendulum.toml",
                "--elements",
                "20",
                "--steps",
                "50",
                "--set",
                "solver.precision=\"f64\"",
                "--json",
            ][..],
            extra,
        ]
        .concat();
        run_json(&args)
    };
    let converged = run(&[]);
    assert_eq!(converged["stiff"]["unconverged_steps"], 0, "{converged}");
    assert_eq!(
        converged["run_warnings"],
        serde_json::json!([]),
        "{converged}"
    );
    // One iteration against a tolerance no step reaches.
    let v = run(&[
        "--set",
        "solver.stiff.iterations=1",
        "--set",
        "solver.stiff.tolerance=1e-12",
    ]);
    let warnings = v["run_warnings"].as_array().unwrap();
    assert!(
        warnings.len() == 1 && warnings[0].as_str().unwrap().contains("not converged"),
        "{v}"
    );
}

/// `converge` runs the scene at three steps and reports, per rod, the distances between the
/// runs, the observed order and the estimated error of every run; the runs all end at the
/// same time, and the explicit pendulum converges at first order.
#[test]
fn converge_reports_each_run_and_its_estimated_error() {
    let v = run_json(&[
        "converge",
        "scenes/pendulum.toml",
        "--elements",
        "16",
        "--set",
        "solver.dt=1e-4",
        "--set",
        "solver.precision=\"f64\"",
        "--steps",
        "300",
        "--json",
    ]);
    assert_eq!(v["refinement"], "time", "{v}");
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 3, "{v}");
    for (k, run) in runs.iter().enumerate() {
        assert_eq!(run["steps"], 300u64 << k, "{run}");
        assert_eq!(run["elements"][0], 16, "{run}");
        let t = run["simulated_s"].as_f64().unwrap();
        assert!((t - 0.03).abs() < 1e-12, "{run}");
    }
    let rod = &v["rods"][0];
    assert_eq!(rod["name"], "rope", "{rod}");
    assert_eq!(rod["points_compared"], 17, "{rod}");
    let positions = &rod["positions"];
    assert_eq!(positions["asymptotic"], true, "{rod}");
    // The explicit scheme is first order in time.
    let order = positions["observed_order"].as_f64().unwrap();
    assert!((0.8..1.2).contains(&order), "{rod}");
    assert_eq!(positions["estimated_errors"].as_array().unwrap().len(), 3);

    let out = cosserat()
        .args(["converge", "scenes/pendulum.toml", "--refine", "sideways"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--refine `sideways`"), "{err}");
}

/// `--until-static` stops a damped cantilever once it has settled and says when; the report
/// then holds the statics: the clamp's force balances the weight, its torque the weight's
/// moment, and the tip's tangent is a unit vector bent downward. A bad tolerance is refused.
#[test]
fn until_static_stops_a_settled_cantilever_and_reports_its_clamp() {
    use cosserat::report::RunReport;
    let args = [
        "run",
        "scenes/nitinol-pendulum.toml",
        "--set",
        "rod.0.start.kind=\"clamped\"",
        "--set",
        "rod.0.damping.drag=20",
        "--elements",
        "50",
        "--duration",
        "60",
        "--until-static",
        "1e-6",
        "--json",
    ];
    let r: RunReport = serde_json::from_value(run_json(&args)).expect("a RunReport");
    let settled = r.settled_at_s.expect("it settles");
    assert!(
        settled < 59.0 && (settled - r.simulated_s).abs() < 1e-9,
        "{settled}"
    );
    let m = cosserat::cosserat_model::presets::preset("nitinol")
        .unwrap()
        .material();
    let weight = m.linear_density() * 1.0 * 9.81;
    let clamp = r
        .reactions
        .iter()
        .find(|e| e.end == 0)
        .expect("the clamp's reaction");
    assert!(
        (clamp.force[2] / weight - 1.0).abs() < 1e-3,
        "{clamp:?} vs {weight}"
    );
    // The weight's moment about the clamp: W times the centre of mass's x.
    assert!(
        clamp.torque[1] < 0.0 && clamp.torque[1].abs() < 0.5 * weight,
        "{clamp:?}"
    );
    let t = r.tip_tangents["guidewire"];
    assert!(((t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt() - 1.0).abs() < 1e-9);
    assert!(t[2] < 0.0, "{t:?}");
    let out = cosserat()
        .args(["run", "scenes/pendulum.toml", "--until-static", "0"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--until-static 0 is invalid"));
}
