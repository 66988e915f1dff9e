//! `cosserat view SCENE`: a window that simulates a scene in real time while it draws it, with
//! the held end of its wire steered by the keyboard, the mouse, a gamepad or a script.
//!
//! Two threads: the physics ([`physics`]) steps the simulation against the wall clock in 1 ms
//! ticks and publishes the latest state through a mailbox; the window ([`window`], on the main
//! thread, as window systems require) draws the newest state with `cosserat-render`'s
//! pipelines at up to `--max-fps` and turns input into the hand's push and twist, which the
//! physics reads every tick through the same control call a haptic device makes; a gamepad
//! ([`gamepad`], Linux only) is read on a thread of its own and its actions are sent to the
//! window's event loop, which applies them as it applies keys. Neither waits
//! for the other: a slow frame never holds a tick back, and physics that cannot keep up shows a
//! real-time factor below 1 instead of freezing the window.
//!
//! On exit the command prints one JSON line (frames drawn, simulated time, the hand's
//! displacement and force, the tip, the real-time factor), and with `--stats FILE` writes the
//! timings; a script (`--script`, [`script`]) makes all of it testable under Xvfb.

mod gamepad;
mod offscreen;
mod physics;
mod script;
mod window;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use cosserat::scene::{load_render_section, load_scene};
use cosserat_render::{Bounds, Projection, RenderSettings, SurfaceMesh, View, include_rod};

use physics::{Controls, Ended, Hand, Mailbox, PhysicsReport};
use window::{Setup, Viewer, WindowReport};

/// `cosserat view`'s arguments.
#[derive(clap::Args)]
pub(crate) struct ViewArgs {
    /// The scene (TOML).
    scene: PathBuf,
    /// Backend: cpu, cpu-rayon or gpu.
    #[arg(long, default_value = "cpu")]
    backend: String,
    /// Set the number of elements of every rod.
    #[arg(long)]
    elements: Option<usize>,
    /// Override a scene value: KEY=VALUE with a dotted key, e.g. solver.dt=1e-4.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Timed actions to play (one a line: `TIME push|twist|pause|screenshot|reset|quit
    /// [VALUE]`, TIME in simulated seconds).
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,
    /// Close after drawing this many frames.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    frames: Option<u64>,
    /// Save the last frame drawn as this PNG file.
    #[arg(long, value_name = "PNG")]
    screenshot: Option<PathBuf>,
    /// Window width in pixels (default: the scene's `[render]` width, else 1280).
    #[arg(long)]
    width: Option<u32>,
    /// Window height in pixels (default: the scene's `[render]` height, else 720).
    #[arg(long)]
    height: Option<u32>,
    /// Where the camera looks from, as for `cosserat render` (auto, front, iso, AZIMUTH,ELEVATION, …).
    #[arg(long)]
    view: Option<String>,
    /// Most frames drawn per second.
    #[arg(long, default_value_t = 60.0)]
    max_fps: f64,
    /// Push speed of the arrow keys, of a full right-button drag and of a gamepad's full stick
    /// [m/s].
    #[arg(long, default_value_t = 0.05)]
    push_speed: f64,
    /// Twist rate of the arrow keys, of a full right-button drag and of a gamepad's full stick
    /// [rad/s].
    #[arg(long, default_value_t = 6.0)]
    twist_rate: f64,
    /// Write the run's timings (frames, fps, real-time factor, tick times) as JSON here.
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,
    /// Do not look for a gamepad (Linux: /dev/input/event*) nor read one.
    #[arg(long)]
    no_gamepad: bool,
    /// Draw without a window: the frames go to an offscreen picture at up to --max-fps and
    /// the script steers (no display needed; for measuring a GPU's frame rate).
    #[arg(long)]
    offscreen: bool,
}

/// `cosserat view`: opens the window and runs until it is closed, the script quits or
/// `--frames` are drawn.
pub(crate) fn view(args: &ViewArgs) -> Result<ExitCode, String> {
    leave_a_core_to_the_physics();
    let overrides = crate::scene_overrides(&args.scene, &args.overrides, args.elements)?;
    let (builder, _, name) = load_scene(&args.scene, &overrides).map_err(|e| e.to_string())?;
    let section = load_render_section(&args.scene, &overrides)
        .map_err(|e| e.to_string())?
        .unwrap_or_default();
    let script = args
        .script
        .as_deref()
        .map(script::load)
        .transpose()?
        .unwrap_or_default();
    for (option, value) in [
        ("max-fps", args.max_fps),
        ("push-speed", args.push_speed),
        ("twist-rate", args.twist_rate),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(format!(
                "--{option} {value} is invalid: expected a positive number"
            ));
        }
    }
    let view_text = args.view.as_deref().or(section.view.as_deref());
    let view = view_text
        .map(View::parse)
        .transpose()
        .map_err(|e| e.to_string())?;
    let projection = match section.camera.as_deref() {
        Some(text) => Projection::parse(text)
            .map_err(|e| format!("{}: render.camera: {e}", args.scene.display()))?,
        None => Projection::Orthographic,
    };
    let projection = match (projection, section.fov) {
        (Projection::Perspective { .. }, Some(fov)) => {
            Projection::Perspective { fov_y_degrees: fov }
        }
        (p, _) => p,
    };
    let settings = RenderSettings {
        width: args.width.or(section.width).unwrap_or(1280),
        height: args.height.or(section.height).unwrap_or(720),
        force_scale: section
            .force_scale
            .unwrap_or(RenderSettings::default().force_scale),
        ..RenderSettings::default()
    };
    if settings.width == 0 || settings.height == 0 {
        return Err(format!(
            "--width {} --height {} is invalid: expected at least one pixel each",
            settings.width, settings.height
        ));
    }
    let builder = builder.backend(crate::parse_backend(&args.backend)?);
    let mut sim = builder
        .build()
        .map_err(|e| format!("{}: {e}", args.scene.display()))?;
    let hand = Hand::take_over(&mut sim).map_err(|e| format!("{}: {e}", args.scene.display()))?;
    if hand.is_none() {
        eprintln!(
            "note: {}: no rod holds its first end, so there is nothing to steer; the scene runs as written",
            args.scene.display()
        );
    }
    let mesh = sim.environment().map(|env| {
        let m = env.collider.mesh();
        SurfaceMesh {
            vertices: m.vertices().iter().map(|v| [v.x, v.y, v.z]).collect(),
            triangles: m.triangles().to_vec(),
        }
    });
    let bounds = scene_bounds(&sim, mesh.as_ref());
    // A vessel is seen along its thinnest axis; rods in free space from the front (from -y,
    // gravity down), since the box of their reach is about as deep as it is wide.
    let view = view.unwrap_or(if mesh.is_some() {
        View::Auto
    } else {
        View::Angles {
            azimuth: 0.0,
            elevation: 0.0,
        }
    });
    // The display is opened before the physics starts: without one, the command stops here
    // with an error rather than a panic. Offscreen, there is no window and no input but the
    // script.
    let event_loop = if args.offscreen {
        None
    } else {
        Some(
            winit::event_loop::EventLoop::<gamepad::PadAction>::with_user_event()
                .build()
                .map_err(|e| {
                    format!(
                        "cosserat view needs a display and found none ({e}); set DISPLAY, run it under `xvfb-run`, or draw with --offscreen"
                    )
                })?,
        )
    };
    // The pad's reader hands its actions to the event loop, which wakes to apply them; it ends
    // when the loop has closed (or the pad is unplugged).
    let pad = match &event_loop {
        Some(_) if !args.no_gamepad => gamepad::find(),
        _ => None,
    };
    let pad_name = pad.as_ref().map(|p| p.name().to_string());
    if let (Some(pad), Some(event_loop)) = (pad, &event_loop) {
        let proxy = event_loop.create_proxy();
        pad.spawn(args.push_speed, args.twist_rate, move |action| {
            proxy.send_event(action).is_ok()
        })
        .map_err(|e| format!("cannot start the gamepad's thread: {e}"))?;
    }
    let controls = Arc::new(Controls::default());
    let mailbox = Arc::new(Mailbox::default());
    let physics = {
        let (controls, mailbox) = (controls.clone(), mailbox.clone());
        std::thread::Builder::new()
            .name("physics".into())
            .spawn(move || {
                let _ended = Ended(controls.clone());
                physics::run(sim, hand, script, controls, mailbox)
            })
            .map_err(|e| format!("cannot start the physics thread: {e}"))?
    };
    let setup = Setup {
        name: name.clone(),
        settings,
        mesh,
        bounds,
        view,
        projection,
        max_fps: args.max_fps,
        frames: args.frames,
        screenshot: args.screenshot.clone(),
        push_speed: args.push_speed,
        twist_rate: args.twist_rate,
        steerable: hand.is_some(),
    };
    let started = std::time::Instant::now();
    let (mut window, looped) = match event_loop {
        Some(event_loop) => {
            let mut viewer = Viewer::new(setup, controls.clone(), mailbox.clone());
            let looped = event_loop.run_app(&mut viewer);
            (viewer.finish(), looped)
        }
        None => (offscreen::run(setup, &controls, &mailbox), Ok(())),
    };
    let wall_s = started.elapsed().as_secs_f64();
    controls
        .quit
        .store(true, std::sync::atomic::Ordering::Relaxed);
    let physics = physics
        .join()
        .map_err(|_| "the physics thread panicked".to_string())?;
    // The physics' very last state, if it came after the last frame drawn.
    if let Some(pose) = mailbox.take() {
        window.last = pose;
    }
    looped.map_err(|e| format!("the window's event loop failed: {e}"))?;
    if let Some(e) = &window.error {
        return Err(e.clone());
    }
    let summary = summary(
        &name,
        &args.scene,
        hand,
        pad_name.as_deref(),
        &physics,
        &window,
        wall_s,
    );
    println!("{summary}");
    if let Some(path) = &args.stats {
        let stats = stats(&physics, &window, wall_s);
        std::fs::write(path, format!("{stats:#}\n"))
            .map_err(|e| format!("--stats {}: {e}", path.display()))?;
    }
    Ok(if physics.stopped.is_some() {
        eprintln!(
            "error: the simulation stopped: {}",
            physics.stopped.as_deref().unwrap_or_default()
        );
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

/// On a machine of two cores, Mesa's software rasteriser (lavapipe) draws with one thread
/// instead of one per core, unless `LP_NUM_THREADS` says otherwise: with two, its threads
/// and the physics thread take turns on the same cores and the soft insertion's 1 ms ticks
/// ran at 0.77 of real time at 60 frames a second, against 0.93 with one
/// (`docs/rendering.md`, "Viewer"). GPU drivers ignore the variable.
fn leave_a_core_to_the_physics() {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    if cores <= 2 && std::env::var_os("LP_NUM_THREADS").is_none() {
        // SAFETY: called first thing in `view`, before this process starts any other thread
        // (the physics, rayon's pool, the Vulkan driver's), so nothing reads the environment
        // while it changes.
        unsafe { std::env::set_var("LP_NUM_THREADS", "1") };
    }
}

/// What the camera frames, so that it can stay still while the rods move: the mesh and the
/// rods as they start (a wire pushed into a vessel stays inside the mesh's box); without a
/// mesh, every point a rod of its length can reach from its first point (a pendulum's swing).
fn scene_bounds(sim: &cosserat::Simulation, mesh: Option<&SurfaceMesh>) -> Bounds {
    let mut bounds = Bounds::EMPTY;
    if let Some(m) = mesh {
        m.include_in(&mut bounds);
    }
    for h in sim.rods() {
        let points = sim.positions(h);
        let radius = sim.rod_radius(h);
        include_rod(
            &mut bounds,
            &cosserat_render::RodPose {
                points: &points,
                d1: &[],
                radius,
                contact_force: None,
            },
        );
        if mesh.is_none() {
            let length: f64 = points
                .windows(2)
                .map(|w| {
                    (0..3)
                        .map(|k| (w[1][k] - w[0][k]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .sum();
            bounds.include_ball(points[0], length + radius);
        }
    }
    bounds
}

/// The middle value of `values` (sorted in place), or `None` when empty; `q` in 0–1 picks
/// another quantile.
fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let i = ((values.len() - 1) as f64 * q).round() as usize;
    Some(values[i])
}

/// Frames per second from the median interval between frames shown.
fn median_fps(window: &WindowReport) -> Option<f64> {
    quantile(&mut window.intervals.clone(), 0.5)
        .filter(|s| *s > 0.0)
        .map(|s| 1.0 / s)
}

/// The line printed on exit.
fn summary(
    name: &str,
    scene: &Path,
    hand: Option<Hand>,
    gamepad: Option<&str>,
    physics: &PhysicsReport,
    window: &WindowReport,
    wall_s: f64,
) -> serde_json::Value {
    let last = &window.last;
    let force = last.hand_force;
    serde_json::json!({
        "scene": scene,
        "name": name,
        "frames": window.frames,
        "time_s": last.time,
        "steps": physics.steps,
        "hand_rod": hand.map(|h| h.rod.0),
        "hand_displacement_m": last.hand_displacement,
        "hand_force_n": force,
        "hand_force_norm_n": force.map(|f| f.iter().map(|x| x * x).sum::<f64>().sqrt()),
        "tip": last.rods.first().and_then(|r| r.points.last()),
        "real_time_factor": real_time_factor(physics),
        "fps_median": median_fps(window),
        "screenshots": window.screenshots,
        "adapter": window.adapter,
        "gamepad": gamepad,
        "stopped": physics.stopped,
        "wall_s": wall_s,
    })
}

/// Simulated seconds per wall second while the physics ran (pauses left out).
fn real_time_factor(physics: &PhysicsReport) -> Option<f64> {
    (physics.running_wall_s > 0.0).then(|| physics.simulated_s / physics.running_wall_s)
}

/// `--stats`: what a measurement of the viewer needs.
fn stats(physics: &PhysicsReport, window: &WindowReport, wall_s: f64) -> serde_json::Value {
    let mut ticks = physics.tick_times.clone();
    let mut ms = |q: f64| quantile(&mut ticks, q).map(|s| s * 1e3);
    let (p50, p99, max) = (ms(0.5), ms(0.99), ms(1.0));
    serde_json::json!({
        "frames": window.frames,
        "wall_s": wall_s,
        "fps_median": median_fps(window),
        "fps_mean": (wall_s > 0.0).then(|| window.frames as f64 / wall_s),
        "frame_interval_p99_ms": quantile(&mut window.intervals.clone(), 0.99).map(|s| s * 1e3),
        "physics_real_time_factor": real_time_factor(physics),
        "physics_simulated_s": physics.simulated_s,
        "physics_running_wall_s": physics.running_wall_s,
        "physics_behind_s": physics.behind_s,
        "physics_steps": physics.steps,
        "dt_s": physics.dt,
        "steps_per_tick": physics.tick_steps,
        "ticks": physics.tick_times.len(),
        "tick_p50_ms": p50,
        "tick_p99_ms": p99,
        "tick_max_ms": max,
        "publishes": physics.publish_times.len(),
        "publish_p50_ms": quantile(&mut physics.publish_times.clone(), 0.5).map(|s| s * 1e3),
        "adapter": window.adapter,
        "samples": window.samples,
        "width": window.size.0,
        "height": window.size.1,
    })
}
