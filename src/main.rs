//! The `cosserat` command: runs scene files and reports time, accuracy and state.
//!
//! `cosserat run SCENE` steps a scene and prints a summary (or one JSON object with `--json`,
//! for scripts and benchmarks); `--out DIR` also writes the trajectory for NumPy and ParaView.
//! `cosserat converge SCENE` estimates how accurate such a run is (`docs/convergence.md`).
//! `cosserat render RUN_DIR` draws a run's frames into pictures and a video
//! (`docs/rendering.md`); `cosserat view SCENE` opens a window that simulates a scene in real
//! time while it draws it, with a wire to steer. With no arguments it runs the built-in demo, the paper's free-space
//! pendulum.

use clap::{Parser, Subcommand};
use cosserat::convergence::{self, Refinement};
use cosserat::report::{RunReport, StepTimes};
use cosserat::scene::{load_scene, parse_scene};
use cosserat::{Backend, Simulation};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[cfg(feature = "render")]
mod render;
#[cfg(feature = "view")]
mod view;

/// The demo run by `cosserat` with no arguments.
const DEMO_SCENE: &str = include_str!("../scenes/pendulum.toml");

#[derive(Parser)]
#[command(
    name = "cosserat",
    version,
    about = "Fast, accurate Cosserat rod simulation (CoRdE, inextensible CoRdE)"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene file.
    Run(RunArgs),
    /// Estimate a scene's discretisation error: run it again with half the step (or twice the
    /// elements), and again, and compare the runs along the way (Richardson, Roache's GCI).
    Converge(ConvergeArgs),
    /// Work with mesh files.
    #[command(subcommand)]
    Mesh(MeshCommand),
    /// Draw a run written with `run --out` into PNG frames and an animation (MP4 through
    /// ffmpeg when installed, else GIF), offscreen on any GPU or on Mesa's lavapipe.
    #[cfg(feature = "render")]
    Render(render::RenderArgs),
    /// Open a window that simulates a scene in real time while it draws it; steer the held
    /// end of its wire with the keyboard and mouse (arrows push, pull and twist; space pauses;
    /// R resets), or with a script.
    #[cfg(feature = "view")]
    View(view::ViewArgs),
}

#[derive(Subcommand)]
enum MeshCommand {
    /// Load an OBJ or STL mesh as a scene would, repair its orientation, and report what was
    /// found and changed: dropped and welded triangles, flipped patches, loose pieces,
    /// openings, seams, the lumen's volume and extent.
    Inspect(InspectArgs),
}

#[derive(clap::Args)]
struct InspectArgs {
    /// The mesh (OBJ or STL).
    file: PathBuf,
    /// Multiply coordinates by this (0.001 for millimetres), as a scene's `scale`.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Print one JSON object instead of a summary.
    #[arg(long)]
    json: bool,
}

/// Which scene, how long, on which backend: what `run` and `converge` share.
#[derive(clap::Args)]
struct SceneArgs {
    /// The scene (TOML).
    scene: PathBuf,
    /// Backend: cpu, cpu-rayon or gpu.
    #[arg(long, default_value = "cpu")]
    backend: String,
    /// Number of steps (default: the scene's).
    #[arg(long, conflicts_with = "duration")]
    steps: Option<u64>,
    /// Simulated time in seconds (default: the scene's).
    #[arg(long)]
    duration: Option<f64>,
    /// Set the number of elements of every rod.
    #[arg(long)]
    elements: Option<usize>,
    /// Override a scene value: KEY=VALUE with a dotted key, e.g. solver.dt=1e-5 or rod.0.elements=1000.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Print one JSON object instead of a summary.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct RunArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Write the trajectory (trajectory.npz, frame_*.vtp, environment.vtp, trajectory.pvd,
    /// run.json) into this folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Frames to record with --out besides the initial state, evenly spaced over the run, the
    /// last at its end.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    frames: u64,
    /// With --out, write only trajectory.npz and run.json (no VTK files).
    #[arg(long, requires = "out")]
    npz_only: bool,
    /// After the run, draw it into DIR/render (needs --out; the options of `cosserat render`
    /// apply).
    #[cfg(feature = "render")]
    #[arg(long, requires = "out")]
    render: bool,
    #[cfg(feature = "render")]
    #[command(flatten)]
    render_options: render::RenderOptions,
    /// Time every step on its own, as a haptic or real-time loop calls it, and report the
    /// median, 99th percentile and largest step time.
    #[arg(long)]
    step_times: bool,
    /// Stop once the rods have settled: when, over two successive batches of steps (1000, or
    /// one frame's with --out), no point moved faster than TOL [m/s] on average. The report
    /// gives the time (`settled_at_s`); a run that does not settle runs to its end and says so.
    #[arg(long, value_name = "TOL")]
    until_static: Option<f64>,
}

#[derive(clap::Args)]
struct ConvergeArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// What to refine: `time` (halve the step) or `space` (double every rod's elements).
    #[arg(long, default_value = "time")]
    refine: String,
    /// Number of runs, each twice as fine as the one before (at least 2; 3 give an observed
    /// order and error estimates).
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Times at which the runs are compared, evenly spaced, the last at the end.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    checkpoints: u64,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Run(args)) => run(&args),
        Some(Command::Converge(args)) => converge(&args),
        Some(Command::Mesh(MeshCommand::Inspect(args))) => inspect(&args),
        #[cfg(feature = "render")]
        Some(Command::Render(args)) => render::render(&args),
        #[cfg(feature = "view")]
        Some(Command::View(args)) => view::view(&args),
        None => demo(),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

/// `cosserat mesh inspect`: the mesh as a scene would load it.
fn inspect(args: &InspectArgs) -> Result<ExitCode, String> {
    use cosserat::cosserat_collide::{MeshCollider, load_mesh};
    let name = args.file.display().to_string();
    let (mut mesh, report) = load_mesh(&args.file, args.scale).map_err(|e| e.to_string())?;
    let repair = mesh.repair_orientation();
    let notes = cosserat::environment::intake_notes(&name, &report, &repair);
    let (lo, hi) = mesh.bounds();
    let vertices = mesh.vertices().len();
    let triangles = mesh.triangles().len();
    let encloses = MeshCollider::new(mesh).encloses_volume();
    if args.json {
        let v = serde_json::json!({
            "file": name,
            "scale": args.scale,
            "vertices": vertices,
            "triangles": triangles,
            "input_triangles": report.input_triangles,
            "degenerate_dropped": report.degenerate_dropped,
            "short_faces_dropped": report.short_faces_dropped,
            "duplicates_dropped": report.duplicates_dropped,
            "welded_vertices": report.welded_vertices,
            "boundary_edges": report.boundary_edges,
            "misoriented_edges_before": repair.misoriented_before,
            "misoriented_edges_after": repair.misoriented_after,
            "flipped_triangles": repair.flipped,
            "pieces": repair.pieces,
            "non_manifold_edges": repair.non_manifold_edges,
            "openings": repair.openings,
            "lumen_volume": repair.lumen_volume,
            "encloses_volume": encloses,
            "bounds": [[lo.x, lo.y, lo.z], [hi.x, hi.y, hi.z]],
            "notes": notes,
        });
        println!("{v}");
        return Ok(ExitCode::SUCCESS);
    }
    println!("mesh       {name} (scale {})", args.scale);
    println!(
        "size       {vertices} vertices, {triangles} triangles ({} in the file; {} zero-area, {} short and {} duplicate dropped, {} vertices welded)",
        report.input_triangles,
        report.degenerate_dropped,
        report.short_faces_dropped,
        report.duplicates_dropped,
        report.welded_vertices
    );
    println!(
        "extent     [{:.4}, {:.4}, {:.4}] to [{:.4}, {:.4}, {:.4}]",
        lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
    );
    println!(
        "winding    {} edges against each other before the repair, {} after; {} triangles turned",
        repair.misoriented_before, repair.misoriented_after, repair.flipped
    );
    println!(
        "pieces     {} ({} loose besides the largest); sizes {:?}",
        repair.pieces.len(),
        repair.fragments(),
        &repair.pieces[..repair.pieces.len().min(8)]
    );
    println!(
        "openings   {} ({} boundary edges); {} edges shared by more than two triangles",
        repair.openings, report.boundary_edges, repair.non_manifold_edges
    );
    println!(
        "lumen      {:.4e} (units³, openings closed); {}",
        repair.lumen_volume,
        if encloses {
            "encloses a volume: points are inside or outside by the winding number"
        } else {
            "encloses no volume (a sheet): the side of the nearest wall decides"
        }
    );
    for n in &notes {
        eprintln!("warning: {n}");
    }
    Ok(ExitCode::SUCCESS)
}

fn parse_backend(name: &str) -> Result<Backend, String> {
    match name {
        "cpu" => Ok(Backend::Cpu),
        "cpu-rayon" => Ok(Backend::CpuRayon),
        "gpu" => Ok(Backend::Gpu),
        other => Err(format!(
            "unknown backend `{other}`: expected cpu, cpu-rayon or gpu"
        )),
    }
}

/// Outcome of stepping a simulation for a while.
struct RunOutcome {
    steps: u64,
    /// Stopped by Ctrl-C or SIGTERM before the last step.
    interrupted: bool,
    wall_s: f64,
    divergence: Option<String>,
    /// With `--step-times`: the steps' wall times.
    step_times: Option<StepTimes>,
    /// With `--until-static`: when the rods were found settled.
    settled_at: Option<f64>,
    /// With `--until-static`: the largest mean point speed over the last batch [m/s].
    last_speed: Option<f64>,
}

/// Steps `sim` by `steps` steps, in batches (or one at a time with `time_each`), recording
/// frames with `record`.
fn step_for(
    sim: &mut Simulation,
    steps: u64,
    record: &mut Option<Recorder>,
    show_progress: bool,
    time_each: bool,
    until_static: Option<f64>,
) -> RunOutcome {
    let bar = (show_progress && steps >= 20_000).then(|| {
        let b = indicatif::ProgressBar::new(steps);
        b.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} steps, {eta} left")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    });
    let mut wall = 0.0;
    let mut done = 0;
    let mut divergence = None;
    // Batches end at the recorder's next frame, or every 1000 steps without one.
    let boundary = |done: u64, record: &Option<Recorder>| {
        record
            .as_ref()
            .and_then(Recorder::next_step)
            .unwrap_or((done / 1000 + 1) * 1000)
            .min(steps)
    };
    // The inside test against the lumen every few thousand steps (about 200 times a run) and
    // after the last: a wire that left the vessel stops the run, and the report's penetration
    // and escaped points are measured at any depth.
    let check_every = (steps / 200).max(1000);
    let mut checked_at = 0;
    let capture = |sim: &Simulation, record: &mut Option<Recorder>| {
        if let Some(Err(e)) = record.as_mut().map(|r| r.capture(sim)) {
            // A non-finite state cannot be recorded; the divergence check reports it.
            eprintln!("warning: frame at t = {} not recorded: {e}", sim.time());
        }
    };
    capture(sim, record);
    let mut times = Vec::new();
    let mut interrupted = false;
    // `--until-static`: the points at the last check, the time then, and how many batches in a
    // row were calm.
    let positions =
        |sim: &Simulation| -> Vec<[f64; 3]> { sim.rods().flat_map(|h| sim.positions(h)).collect() };
    let mut calm = (until_static.map(|_| (positions(sim), sim.time())), 0);
    let (mut settled_at, mut last_speed) = (None, None);
    while done < steps {
        if STOP.load(std::sync::atomic::Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let end = boundary(done, record);
        let n = if time_each { 1 } else { end - done };
        let t0 = Instant::now();
        let res = sim.run(n);
        let elapsed = t0.elapsed().as_secs_f64();
        wall += elapsed;
        let res = res.and_then(|()| {
            let due = sim.steps() - checked_at >= check_every || sim.steps() >= steps;
            if due {
                checked_at = sim.steps();
                sim.check_lumen().map(|_| ())
            } else {
                Ok(())
            }
        });
        match res {
            Ok(()) => done += n,
            Err(e) => {
                done = sim.steps();
                divergence = Some(e.to_string());
                break;
            }
        }
        if time_each {
            times.push(elapsed);
            if done != end {
                continue;
            }
        }
        if record.as_ref().and_then(Recorder::next_step) == Some(done) {
            capture(sim, record);
        }
        if let Some(b) = &bar {
            b.set_position(done);
        }
        if let (Some(tol), (Some((before, t0)), calm_batches)) = (until_static, &mut calm)
            && sim.time() > *t0
        {
            let now = positions(sim);
            let moved = before
                .iter()
                .zip(&now)
                .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt())
                .fold(0.0, f64::max);
            let speed = moved / (sim.time() - *t0);
            last_speed = Some(speed);
            *calm_batches = if speed <= tol { *calm_batches + 1 } else { 0 };
            (*before, *t0) = (now, sim.time());
            if *calm_batches >= 2 {
                settled_at = Some(sim.time());
                break;
            }
        }
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if interrupted
        && record
            .as_ref()
            .is_some_and(|r| r.last_captured != sim.steps())
    {
        capture(sim, record);
    }
    RunOutcome {
        steps: done,
        interrupted,
        wall_s: wall,
        divergence,
        step_times: StepTimes::of(&times),
        settled_at,
        last_speed,
    }
}

/// Records frames of a run for `--out`.
struct Recorder {
    /// The steps (counted from the start of the run) after which frames are recorded
    /// (`cosserat::output::frame_steps`), and how many of them were recorded.
    schedule: Vec<u64>,
    recorded: usize,
    trajectory: cosserat::output::Trajectory,
    /// The `.vtp` files, written as frames are captured (`None` with `--npz-only`).
    series: Option<cosserat::output::VtpSeries>,
    /// Whether every rod reports its contacts (a run with an environment on a CPU backend).
    contacts: bool,
    /// The step of the last frame captured.
    last_captured: u64,
}

impl Recorder {
    fn new(
        sim: &Simulation,
        steps: u64,
        frames: u64,
        series: Option<cosserat::output::VtpSeries>,
    ) -> Result<Self, String> {
        let mut trajectory = cosserat::output::Trajectory::new();
        for h in sim.rods() {
            let n = sim.positions(h).len() - 1;
            trajectory
                .add_rod(sim.rod_name(h), sim.rod_radius(h), n)
                .map_err(|e| e.to_string())?;
        }
        // Every mesh the rods collide with, as one (analytic shapes are infinite: not drawn).
        let mut meshes = sim.obstacles().iter().filter_map(|o| match o.geometry() {
            cosserat::obstacles::Geometry::Mesh(env) => Some(env.collider.mesh()),
            cosserat::obstacles::Geometry::Shape(_) => None,
        });
        trajectory.environment = meshes.next().map(|first| {
            let mut out = cosserat::output::EnvironmentMesh {
                vertices: Vec::new(),
                triangles: Vec::new(),
            };
            for mesh in std::iter::once(first).chain(meshes) {
                let offset = out.vertices.len() as u32;
                out.vertices
                    .extend(mesh.vertices().iter().map(|v| [v.x, v.y, v.z]));
                out.triangles
                    .extend(mesh.triangles().iter().map(|t| t.map(|c| c + offset)));
            }
            out
        });
        let mut probe = Vec::new();
        let contacts =
            !sim.obstacles().is_empty() && sim.rods().all(|h| sim.contacts(h, &mut probe).is_ok());
        Ok(Self {
            schedule: cosserat::output::frame_steps(steps, frames),
            recorded: 0,
            trajectory,
            series,
            contacts,
            last_captured: u64::MAX,
        })
    }

    /// The step after which the next scheduled frame is due, if any is left.
    fn next_step(&self) -> Option<u64> {
        self.schedule.get(self.recorded).copied()
    }

    fn capture(&mut self, sim: &Simulation) -> Result<(), String> {
        let mut samples = Vec::new();
        let data: Vec<_> = sim
            .rods()
            .map(|h| {
                let points = sim.positions(h);
                let forces = if self.contacts {
                    let mut f = vec![0.0; points.len()];
                    if sim.contacts(h, &mut samples).is_ok() {
                        for c in &samples {
                            // The wall's push along its normal; friction is left out.
                            let normal: f64 = (0..3).map(|k| c.force[k] * c.normal[k]).sum();
                            if let Some(slot) = f.get_mut(c.point) {
                                *slot = normal.max(0.0);
                            }
                        }
                    }
                    f
                } else {
                    Vec::new()
                };
                (
                    points,
                    sim.first_directors(h),
                    sim.velocities(h),
                    forces,
                    sim.strains(h),
                )
            })
            .collect();
        let frames: Vec<_> = data
            .iter()
            .map(|(p, d, v, f, e)| cosserat::output::RodFrame {
                points: p,
                directors: d,
                velocities: v,
                contact_forces: f,
                strains: e,
            })
            .collect();
        self.trajectory
            .push_frame(sim.time(), &frames)
            .map_err(|e| e.to_string())?;
        self.last_captured = sim.steps();
        // The schedule moves past every step already reached (an interrupted run captures
        // off schedule).
        while self.next_step().is_some_and(|s| s <= self.last_captured) {
            self.recorded += 1;
        }
        match self.series.as_mut() {
            Some(series) => series.append(&self.trajectory).map_err(|e| e.to_string()),
            None => Ok(()),
        }
    }
}

/// A scene loaded with the command line's overrides (and `extra` after them), its name and
/// the steps to run.
struct LoadedScene {
    builder: cosserat::SimulationBuilder,
    name: String,
    steps: u64,
}

/// The command line's `--set` and `--elements` as overrides.
fn overrides(args: &SceneArgs) -> Result<Vec<(String, String)>, String> {
    scene_overrides(&args.scene, &args.overrides, args.elements)
}

/// `--set KEY=VALUE` pairs and `--elements N` (for every rod of the scene at `scene`) as
/// overrides.
fn scene_overrides(
    scene: &Path,
    sets: &[String],
    elements: Option<usize>,
) -> Result<Vec<(String, String)>, String> {
    let mut overrides = Vec::new();
    for kv in sets {
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| format!("--set `{kv}`: expected KEY=VALUE"))?;
        overrides.push((k.trim().to_string(), v.trim().to_string()));
    }
    if let Some(n) = elements {
        let count = count_rods(scene)?;
        for i in 0..count {
            overrides.push((format!("rod.{i}.elements"), n.to_string()));
        }
    }
    Ok(overrides)
}

fn load(args: &SceneArgs, extra: &[(String, String)]) -> Result<LoadedScene, String> {
    let mut overrides = overrides(args)?;
    overrides.extend_from_slice(extra);
    let (builder, length, name) = load_scene(&args.scene, &overrides).map_err(|e| e.to_string())?;
    let dt = builder.time_step();
    let steps = match (args.steps, args.duration) {
        (Some(n), _) => n,
        (None, Some(d)) if d.is_finite() && d > 0.0 => (d / dt).round() as u64,
        (None, Some(d)) => {
            return Err(format!(
                "--duration {d} is invalid: expected a positive number of seconds"
            ));
        }
        (None, None) => length.steps,
    };
    if steps == 0 {
        return Err(format!(
            "{}: the run has no steps (dt = {dt:e} s): give --steps N with N ≥ 1 or a --duration of at least one step",
            args.scene.display()
        ));
    }
    let builder = builder.backend(parse_backend(&args.backend)?);
    Ok(LoadedScene {
        builder,
        name,
        steps,
    })
}

fn run(run_args: &RunArgs) -> Result<ExitCode, String> {
    let args = &run_args.scene;
    let LoadedScene {
        builder,
        name,
        steps,
    } = load(args, &[])?;
    if let Some(tol) = run_args.until_static
        && !(tol.is_finite() && tol > 0.0)
    {
        return Err(format!(
            "--until-static {tol} is invalid: expected a positive speed in m/s"
        ));
    }
    // An unwritable output directory is found before the run, not after it: the manifest is
    // written first.
    let series = match &run_args.out {
        Some(dir) => {
            write_manifest(dir, args, &name)?;
            if run_args.npz_only {
                None
            } else {
                Some(cosserat::output::VtpSeries::create(dir).map_err(|e| format!("--out: {e}"))?)
            }
        }
        None => None,
    };
    let mut sim = builder
        .build()
        .map_err(|e| format!("{}: {e}", args.scene.display()))?;
    let mut recorder = run_args
        .out
        .as_ref()
        .map(|_| Recorder::new(&sim, steps, run_args.frames, series))
        .transpose()?;
    // Ctrl-C or SIGTERM stops the run between two batches; what was run is written and
    // reported. A second signal while the handler is installed does nothing more.
    if let Err(e) = ctrlc::set_handler(|| STOP.store(true, std::sync::atomic::Ordering::Relaxed)) {
        eprintln!("warning: Ctrl-C will not save the run: {e}");
    }
    let outcome = step_for(
        &mut sim,
        steps,
        &mut recorder,
        !args.json,
        run_args.step_times,
        run_args.until_static,
    );
    if let (Some(dir), Some(rec)) = (&run_args.out, &recorder) {
        write_output(dir, rec)?;
    }
    report(&sim, &name, &outcome, args.json);
    #[cfg(feature = "render")]
    if let (true, Some(dir)) = (run_args.render, &run_args.out) {
        // The report went to stdout as one JSON object; the render's summary goes to stderr
        // then, so that stdout stays one object.
        let render_args = render::RenderArgs::for_run(dir, run_args.render_options.clone(), false);
        if args.json {
            render::render_quietly(&render_args)?;
        } else {
            render::render(&render_args)?;
        }
    }
    Ok(if outcome.divergence.is_some() {
        ExitCode::from(1)
    } else if outcome.interrupted {
        // The shell's convention for a process ended by SIGINT.
        ExitCode::from(130)
    } else {
        ExitCode::SUCCESS
    })
}

/// Set by Ctrl-C or SIGTERM: the run stops before its next batch of steps.
static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn converge(c: &ConvergeArgs) -> Result<ExitCode, String> {
    let args = &c.scene;
    let refinement = match c.refine.as_str() {
        "time" => Refinement::Time,
        "space" => Refinement::Space,
        other => {
            return Err(format!(
                "--refine `{other}` is invalid: expected time or space"
            ));
        }
    };
    let base = load(args, &[])?;
    let dt = base.builder.time_step();
    // Every rod's elements as the first run (built first) has them, for the space
    // refinement's overrides of the later runs.
    let mut elements: Vec<usize> = Vec::new();
    let build = |factor: u32| {
        let extra: Vec<(String, String)> = match refinement {
            Refinement::Time => vec![("solver.dt".into(), format!("{:e}", dt / f64::from(factor)))],
            Refinement::Space => elements
                .iter()
                .enumerate()
                .map(|(i, n)| {
                    (
                        format!("rod.{i}.elements"),
                        (n * factor as usize).to_string(),
                    )
                })
                .collect(),
        };
        let scene = load(args, &extra)?;
        let sim = scene
            .builder
            .build()
            .map_err(|e| format!("{}: {e}", args.scene.display()))?;
        if factor == 1 {
            elements = sim
                .rods()
                .map(|h| sim.positions(h).len().saturating_sub(1))
                .collect();
        }
        Ok(sim)
    };
    if !args.json {
        eprintln!(
            "running {} {} runs of {} ({} steps in the first)…",
            c.runs,
            refinement.name(),
            base.name,
            base.steps
        );
    }
    match convergence::study(
        refinement,
        c.runs,
        base.steps,
        c.checkpoints as usize,
        build,
    ) {
        Ok(study) => {
            report_study(&base.name, &study, args.json);
            Ok(ExitCode::SUCCESS)
        }
        Err(e @ convergence::StudyError::Diverged { .. }) => {
            if args.json {
                let v = serde_json::json!({"scene": base.name, "diverged": true, "error": e.to_string()});
                println!("{v}");
            } else {
                println!("DIVERGED   {e}");
            }
            Ok(ExitCode::from(1))
        }
        Err(e) => Err(e.to_string()),
    }
}

fn report_study(name: &str, study: &convergence::Study, json: bool) {
    let formal = study.refinement.formal_order();
    if json {
        let quantity = |q: &convergence::Convergence| {
            serde_json::json!({
                "differences": q.differences,
                "worst": q.worst.iter().map(|w| w.0).collect::<Vec<_>>(),
                "worst_times": q.worst.iter().map(|w| w.1).collect::<Vec<_>>(),
                "scale": q.scale,
                "observed_order": q.grid.observed_order,
                "formal_order": formal,
                "asymptotic": q.asymptotic(),
                "negligible": q.negligible(),
                "estimated_errors": q.estimated_errors,
                "gci": q.grid.gci,
            })
        };
        let levels: Vec<_> = study
            .levels
            .iter()
            .map(|l| {
                serde_json::json!({
                    "factor": l.factor, "dt": l.dt, "elements": l.elements, "steps": l.steps,
                    "simulated_s": l.time, "wall_s": l.wall_s, "max_strain": l.max_strain,
                })
            })
            .collect();
        let rods: Vec<_> = study
            .rods
            .iter()
            .map(|r| {
                let forces: Vec<_> = r
                    .end_forces
                    .iter()
                    .map(|(end, q)| {
                        let mut v = quantity(q);
                        v["end"] = serde_json::json!(end);
                        v
                    })
                    .collect();
                serde_json::json!({
                    "name": r.name,
                    "points_compared": r.points,
                    "positions": quantity(&r.positions),
                    "end_forces": forces,
                })
            })
            .collect();
        let v = serde_json::json!({
            "scene": name,
            "refinement": study.refinement.name(),
            "runs": levels,
            "checkpoint_times": study.checkpoint_times,
            "rods": rods,
        });
        println!("{v}");
        return;
    }
    println!(
        "converge   {name}: {} refinement, {} runs to t = {} s, compared at {} times",
        study.refinement.name(),
        study.levels.len(),
        study.levels[0].time,
        study.checkpoint_times.len()
    );
    println!("run  dt [s]      elements      steps       wall [s]   max strain");
    for (k, l) in study.levels.iter().enumerate() {
        let elements: Vec<String> = l.elements.iter().map(|n| n.to_string()).collect();
        println!(
            "{k:<4} {:<11.3e} {:<13} {:<11} {:<10.3} {:.2e}",
            l.dt,
            elements.join(","),
            l.steps,
            l.wall_s,
            l.max_strain
        );
    }
    for r in &study.rods {
        println!("rod \"{}\"", r.name);
        let what = format!("centreline ({} points compared)", r.points);
        report_quantity(&what, "m", "point", &r.positions, study);
        for (end, q) in &r.end_forces {
            let what = format!(
                "force at its {} end (filtered, as a haptic device renders it)",
                if *end == 0 { "first" } else { "last" }
            );
            report_quantity(&what, "N", "end", q, study);
        }
    }
}

/// The text lines of one quantity of a study: what it is, its differences, order, estimates
/// and GCI. `unit` is its unit, `place` what `worst.0` counts (a point, an end).
fn report_quantity(
    what: &str,
    unit: &str,
    place: &str,
    q: &convergence::Convergence,
    study: &convergence::Study,
) {
    let formal = study.refinement.formal_order();
    let last = study.levels.len() - 1;
    println!("  {what}");
    let diffs: Vec<String> = q
        .differences
        .iter()
        .zip(&q.worst)
        .enumerate()
        .map(|(k, (d, (j, t)))| {
            format!(
                "runs {k}–{}: {d:.3e} {unit} ({place} {j}, t {t:.4} s)",
                k + 1
            )
        })
        .collect();
    println!("    largest difference between  {}", diffs.join(", "));
    match (q.grid.observed_order, &q.estimated_errors) {
        (Some(p), Some(errors)) => {
            let e: Vec<String> = errors
                .iter()
                .enumerate()
                .map(|(k, e)| format!("run {k} {e:.2e} {unit}"))
                .collect();
            println!("    observed order {p:.2} (formal {formal}): in the asymptotic range");
            println!("    estimated error             {}", e.join(", "));
        }
        _ if q.negligible() => println!(
            "    the runs agree to within {:e} of its size ({:.3e} {unit}): no discretisation error is measurable",
            convergence::NEGLIGIBLE,
            q.scale
        ),
        (p, _) => {
            let p = p.map_or("none".to_string(), |p| format!("{p:.2}"));
            println!(
                "    observed order {p} (formal {formal}): NOT in the asymptotic range ({}–{}); no error estimate",
                convergence::ASYMPTOTIC_ORDERS.0,
                convergence::ASYMPTOTIC_ORDERS.1
            );
        }
    }
    println!(
        "    GCI of run {last} (error bound, Fs {}): {:.2e} {unit}",
        q.grid.safety_factor, q.grid.gci
    );
}

fn count_rods(path: &Path) -> Result<usize, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read the scene: {e}", path.display()))?;
    let doc: toml::Table = toml::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(doc
        .get("rod")
        .and_then(|r| r.as_array())
        .map_or(0, |a| a.len()))
}

/// Writes `run.json` into `dir` (created if needed): the scene and its `[render]` table, so
/// that `cosserat render DIR` knows how the scene wants to be drawn.
fn write_manifest(dir: &Path, args: &SceneArgs, name: &str) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("--out {}: {e}", dir.display()))?;
    let render = cosserat::scene::load_render_section(&args.scene, &overrides(args)?)
        .map_err(|e| e.to_string())?
        .unwrap_or_default();
    let manifest = serde_json::json!({
        "scene": args.scene,
        "name": name,
        "render": render,
    });
    let path = dir.join("run.json");
    std::fs::write(&path, format!("{manifest:#}\n"))
        .map_err(|e| format!("--out: {}: {e}", path.display()))
}

/// Writes the NumPy file of the recorded frames (the `.vtp` files were written as the frames
/// were made).
fn write_output(dir: &Path, rec: &Recorder) -> Result<(), String> {
    cosserat::output::write_npz(&dir.join("trajectory.npz"), &rec.trajectory)
        .map_err(|e| e.to_string())
}

fn report(sim: &Simulation, name: &str, o: &RunOutcome, json: bool) {
    let mut r = RunReport::new(
        sim,
        name,
        o.steps,
        o.wall_s,
        o.divergence.clone(),
        o.step_times,
    );
    r.interrupted = o.interrupted;
    r.settled_at_s = o.settled_at;
    if let (None, Some(speed), None) = (o.settled_at, o.last_speed, &o.divergence) {
        r.run_warnings.push(format!(
            "the run did not settle (--until-static): points still moved at {speed:.3e} m/s on average over the last batch of steps"
        ));
    }
    if json {
        match serde_json::to_string(&r) {
            Ok(text) => println!("{text}"),
            Err(e) => eprintln!("error: the report could not be written as JSON: {e}"),
        }
        return;
    }
    for w in &r.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "scene      {name} ({} elements, {} backend, {} stepper, {})",
        r.elements, r.backend, r.stepper, r.precision
    );
    let per_step = r
        .us_per_step
        .map_or_else(|| "no steps".to_string(), |us| format!("{us:.2} µs/step"));
    println!(
        "ran        {} steps of {:.3e} s = {:.4} s simulated in {:.3} s wall ({per_step}, {:.1}× real time)",
        r.steps,
        r.dt,
        r.simulated_s,
        r.wall_s,
        r.simulated_s / r.wall_s.max(1e-12)
    );
    if let Some(t) = r.step_us {
        let us = |x: Option<f64>| x.map_or_else(|| "n/a".to_string(), |x| format!("{x:.2} µs"));
        println!(
            "step time  median {}, 99th percentile {}, largest {} after the first ({:.2} µs; each step timed on its own)",
            us(t.median),
            us(t.p99),
            us(t.max),
            t.first
        );
    }
    println!("accuracy   max strain |l/l0 - 1| = {:.3e}", r.max_strain);
    println!(
        "energy     kinetic {:.6e} J, potential {:.6e} J",
        r.kinetic_energy, r.potential_energy
    );
    println!(
        "tip        [{:.6}, {:.6}, {:.6}] m",
        r.tip[0], r.tip[1], r.tip[2]
    );
    if let Some(t) = r.settled_at_s {
        println!("settled    at t = {t:.6} s (--until-static)");
    }
    for e in &r.reactions {
        println!(
            "reaction   {} end {}: force [{:.6e}, {:.6e}, {:.6e}] N, torque [{:.6e}, {:.6e}, {:.6e}] N m",
            e.rod, e.end, e.force[0], e.force[1], e.force[2], e.torque[0], e.torque[1], e.torque[2]
        );
    }
    if let Some(c) = r.contact {
        println!(
            "contact    {} points in contact, max penetration {:.3e} m, {} escaped, detection {:.2} µs/step",
            c.contacts, c.max_penetration, c.escaped_points, c.collision_us_per_step
        );
    }
    if let Some(st) = r.stiff {
        println!(
            "stiff      {:.2} iterations and {:.2} factorisations per step; {} of {} rod-steps ended above their tolerance (up to {:.1e}; largest residual {:.2e}); {} retaken in halves, {} with axial compliance",
            st.iterations_per_step,
            st.factorisations_per_step,
            st.unconverged_steps,
            st.steps_kept,
            st.max_tolerance,
            st.max_residual,
            st.halved_steps,
            st.axial_steps
        );
    }
    if let Some(d) = &r.divergence {
        println!("DIVERGED   {d}");
    }
    if r.interrupted {
        println!(
            "STOPPED    by a signal after {} steps; the output holds the frames so far",
            r.steps
        );
    }
    for w in &r.run_warnings {
        eprintln!("warning: {w}");
    }
}

fn demo() -> Result<ExitCode, String> {
    let (builder, length, name) = parse_scene(Path::new("scenes/pendulum.toml"), DEMO_SCENE, &[])
        .map_err(|e| e.to_string())?;
    println!(
        "Running the built-in demo: the free-space pendulum of Korzeniowski et al. (section 3.1)."
    );
    println!(
        "Try `cosserat run scenes/pendulum.toml --elements 1000 --json` or `cosserat --help`.\n"
    );
    let mut sim = builder.build().map_err(|e| e.to_string())?;
    let outcome = step_for(&mut sim, length.steps, &mut None, true, false, None);
    report(&sim, &name, &outcome, false);
    Ok(if outcome.divergence.is_some() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
