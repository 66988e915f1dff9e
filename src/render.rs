//! `cosserat render RUN_DIR` and `cosserat run --render`: a run's frames as pictures.
//!
//! A run directory written with `--out` holds `trajectory.npz` (every rod's centreline,
//! directors, contact forces and the environment mesh) and `run.json` (the scene and its
//! `[render]` table). This module reads them, settles the options (command line, then the
//! scene's `[render]` table, then defaults), frames one camera on everything drawn over the
//! whole run so that the picture stays still while the rods move, and hands each frame to
//! `cosserat_render`. Drawing and file encoding overlap: a second thread writes the PNG frames
//! and the animation while the next frame is drawn.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Instant;

use cosserat::output::{Trajectory, read_npz};
use cosserat::scene::RenderSection;
use cosserat_render::{
    AnimationFormat, AnimationWriter, Bounds, Camera, Image, Projection, RenderSettings, Renderer,
    RodPose, SurfaceMesh, View, include_rod, write_png,
};

/// Name of the manifest a run writes beside its trajectory.
pub(crate) const MANIFEST_FILE_NAME: &str = "run.json";

/// What a run directory says about itself (`run.json`).
#[derive(serde::Serialize, serde::Deserialize, Default)]
pub(crate) struct Manifest {
    /// The scene file the run came from.
    pub(crate) scene: PathBuf,
    /// The scene's name.
    pub(crate) name: String,
    /// The scene's `[render]` table.
    #[serde(default)]
    pub(crate) render: RenderSection,
}

/// The picture options of the command line; each overrides the scene's `[render]` table.
#[derive(clap::Args, Clone, Default)]
pub(crate) struct RenderOptions {
    /// Picture width in pixels (default 1280).
    #[arg(long)]
    width: Option<u32>,
    /// Picture height in pixels (default 720).
    #[arg(long)]
    height: Option<u32>,
    /// Projection: ortho (default) or perspective.
    #[arg(long)]
    camera: Option<String>,
    /// Where the camera looks from: auto (along the scene's thinnest axis; default), front,
    /// back, left, right, top, bottom, iso, or AZIMUTH,ELEVATION in degrees.
    #[arg(long)]
    view: Option<String>,
    /// Vertical field of view of the perspective camera in degrees (default 35).
    #[arg(long)]
    fov: Option<f64>,
    /// Animated file: mp4 (needs ffmpeg on the PATH), gif, or png (frames only). Default: mp4
    /// when ffmpeg is found, else gif.
    #[arg(long)]
    format: Option<String>,
    /// Frames per second of the animation (default 30).
    #[arg(long)]
    fps: Option<u32>,
    /// Normal contact force drawn fully red [N] (default: the 95th percentile of the run's
    /// contact forces).
    #[arg(long)]
    force_scale: Option<f64>,
    /// Samples per pixel: 4 (smooth edges) or 1. Default: 4 on a GPU, 1 on a software adapter
    /// such as lavapipe, where 4 cost three times as much.
    #[arg(long)]
    samples: Option<u32>,
    /// Render only the last frame (a still of the run's end, framed on it), as `last.png`.
    #[arg(long)]
    last_only: bool,
}

/// `cosserat render`'s arguments.
#[derive(clap::Args)]
pub(crate) struct RenderArgs {
    /// A run directory written by `cosserat run --out` (it holds trajectory.npz).
    run_dir: PathBuf,
    /// Where the pictures go (default: RUN_DIR/render).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    options: RenderOptions,
    /// Print one JSON object (frames, sizes, times) instead of a summary.
    #[arg(long)]
    json: bool,
}

impl RenderArgs {
    /// The arguments `cosserat run --render` uses for its own output directory.
    pub(crate) fn for_run(run_dir: &Path, options: RenderOptions, json: bool) -> Self {
        Self {
            run_dir: run_dir.to_path_buf(),
            out: None,
            options,
            json,
        }
    }
}

/// What rendering did and how long each part took.
#[derive(serde::Serialize)]
struct RenderReport {
    run_dir: PathBuf,
    out: PathBuf,
    frames: usize,
    width: u32,
    height: u32,
    samples: u32,
    adapter: String,
    camera: String,
    view: String,
    animation: Option<PathBuf>,
    /// Reading the run's trajectory and mesh [s].
    read_s: f64,
    /// Building the tubes, drawing and reading the pictures back [s].
    render_s: f64,
    /// Writing the PNG frames [s].
    png_s: f64,
    /// Encoding the animation [s].
    animation_s: f64,
    /// From the start of the command to the last file written [s].
    wall_s: f64,
}

/// `cosserat render`: the summary (or JSON object) on stdout.
pub(crate) fn render(args: &RenderArgs) -> Result<std::process::ExitCode, String> {
    render_with(args, |line| println!("{line}"))
}

/// The same with the summary on stderr, for `cosserat run --json --render`, whose stdout holds
/// the run's JSON object alone.
pub(crate) fn render_quietly(args: &RenderArgs) -> Result<std::process::ExitCode, String> {
    render_with(args, |line| eprintln!("{line}"))
}

fn render_with(args: &RenderArgs, say: impl Fn(&str)) -> Result<std::process::ExitCode, String> {
    let start = Instant::now();
    let npz = args.run_dir.join("trajectory.npz");
    if !npz.is_file() {
        return Err(format!(
            "{}: no trajectory here; a run writes one with `cosserat run SCENE --out {}`",
            npz.display(),
            args.run_dir.display()
        ));
    }
    let manifest_path = args.run_dir.join(MANIFEST_FILE_NAME);
    let manifest: Manifest = if manifest_path.is_file() {
        let text = std::fs::read_to_string(&manifest_path)
            .map_err(|e| format!("{}: {e}", manifest_path.display()))?;
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", manifest_path.display()))?
    } else {
        Manifest::default()
    };
    let traj = read_npz(&npz).map_err(|e| e.to_string())?;
    if traj.n_frames() == 0 {
        return Err(format!("{}: the run recorded no frames", npz.display()));
    }
    let read_s = start.elapsed().as_secs_f64();
    let opts = Settled::new(&args.options, &manifest.render, &manifest_path, &traj)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.run_dir.join("render"));
    std::fs::create_dir_all(&out).map_err(|e| format!("--out {}: {e}", out.display()))?;

    let mesh = traj.environment.as_ref().map(|m| SurfaceMesh {
        vertices: m.vertices.clone(),
        triangles: m.triangles.clone(),
    });
    let mut bounds = Bounds::EMPTY;
    if let Some(m) = &mesh {
        m.include_in(&mut bounds);
    }
    let frames: Vec<usize> = if args.options.last_only {
        vec![traj.n_frames() - 1]
    } else {
        (0..traj.n_frames()).collect()
    };
    // The camera frames every drawn frame, so it stays still while the rods move.
    for &frame in &frames {
        for rod in poses(&traj, frame) {
            include_rod(&mut bounds, &rod);
        }
    }
    let camera = Camera::framing(
        &bounds,
        opts.view,
        opts.projection,
        opts.settings.width,
        opts.settings.height,
    )
    .map_err(|e| e.to_string())?;
    let mut renderer = Renderer::new(opts.settings).map_err(|e| e.to_string())?;
    renderer.set_mesh(mesh.as_ref());

    let animation = match (opts.format, args.options.last_only) {
        (Some(format), false) => Some(out.join(format!(
            "{}.{}",
            file_stem(&manifest.name),
            format.extension()
        ))),
        _ => None,
    };
    let mut writer = animation
        .as_ref()
        .zip(opts.format)
        .map(|(path, format)| {
            AnimationWriter::create(
                path,
                format,
                opts.settings.width,
                opts.settings.height,
                opts.fps,
            )
        })
        .transpose()
        .map_err(|e| e.to_string())?;

    // The encoder thread writes what the drawing thread sends; two frames in flight at most.
    let (send, receive) = mpsc::sync_channel::<(usize, Image)>(2);
    let (recycle_send, recycle) = mpsc::channel::<Image>();
    let last_only = args.options.last_only;
    let out_dir = out.clone();
    let encoder = std::thread::spawn(move || -> Result<(f64, f64), String> {
        let (mut png_s, mut animation_s) = (0.0, 0.0);
        for (frame, image) in receive {
            let t0 = Instant::now();
            let name = if last_only {
                "last.png".to_string()
            } else {
                format!("frame_{frame:05}.png")
            };
            write_png(&out_dir.join(name), &image).map_err(|e| e.to_string())?;
            let t1 = Instant::now();
            if let Some(w) = writer.as_mut() {
                w.push(&image).map_err(|e| e.to_string())?;
            }
            png_s += (t1 - t0).as_secs_f64();
            animation_s += t1.elapsed().as_secs_f64();
            // The drawing thread may be gone after an error; the picture is then dropped.
            let _ = recycle_send.send(image);
        }
        let t = Instant::now();
        if let Some(w) = writer {
            w.finish().map_err(|e| e.to_string())?;
        }
        animation_s += t.elapsed().as_secs_f64();
        Ok((png_s, animation_s))
    });
    let mut render_s = 0.0;
    let mut drawn = Ok(());
    for &frame in &frames {
        let t0 = Instant::now();
        let mut image = recycle.try_recv().unwrap_or_default();
        if let Err(e) = renderer.render_into(&camera, &poses(&traj, frame), &mut image) {
            drawn = Err(e.to_string());
            break;
        }
        render_s += t0.elapsed().as_secs_f64();
        if send.send((frame, image)).is_err() {
            break; // the encoder stopped; its error is reported below
        }
    }
    drop(send);
    let encoded = encoder
        .join()
        .map_err(|_| "the encoder thread panicked".to_string())?;
    drawn?;
    let (png_s, animation_s) = encoded?;
    let report = RenderReport {
        run_dir: args.run_dir.clone(),
        out: out.clone(),
        frames: frames.len(),
        width: opts.settings.width,
        height: opts.settings.height,
        samples: renderer.samples(),
        adapter: renderer.adapter().to_string(),
        camera: opts.camera_name,
        view: opts.view_name,
        animation,
        read_s,
        render_s,
        png_s,
        animation_s,
        wall_s: start.elapsed().as_secs_f64(),
    };
    if args.json {
        say(&serde_json::to_string(&report).map_err(|e| e.to_string())?);
    } else {
        say(&format!(
            "rendered   {} frames of {}x{} ({} samples, {} camera, view {}) on {}",
            report.frames,
            report.width,
            report.height,
            report.samples,
            report.camera,
            report.view,
            report.adapter
        ));
        say(&format!(
            "time       {:.2} s: read {:.2} s, draw {:.2} s, PNG {:.2} s, animation {:.2} s (PNG and animation overlap the drawing)",
            report.wall_s, report.read_s, report.render_s, report.png_s, report.animation_s
        ));
        say(&match &report.animation {
            Some(a) => format!(
                "wrote      {} and the frames in {}",
                a.display(),
                out.display()
            ),
            None => format!("wrote      the frames in {}", out.display()),
        });
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// Every rod of `traj` at frame `frame`, as the renderer takes it.
fn poses(traj: &Trajectory, frame: usize) -> Vec<RodPose<'_>> {
    traj.rods
        .iter()
        .map(|r| RodPose {
            points: r.frame_points(frame).unwrap_or_default(),
            d1: r.frame_directors(frame).unwrap_or_default(),
            radius: r.radius,
            contact_force: r.frame_contact_forces(frame),
        })
        .collect()
}

/// A file name from a scene name: letters, digits, `-` and `_` kept, the rest `_`.
fn file_stem(name: &str) -> String {
    let stem: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if stem.is_empty() { "run".into() } else { stem }
}

/// The options in force: the command line's, else the scene's, else the defaults.
struct Settled {
    settings: RenderSettings,
    projection: Projection,
    view: View,
    camera_name: String,
    view_name: String,
    format: Option<AnimationFormat>,
    fps: u32,
}

impl Settled {
    fn new(
        cli: &RenderOptions,
        scene: &RenderSection,
        manifest: &Path,
        traj: &Trajectory,
    ) -> Result<Self, String> {
        // A scene value that is wrong names the manifest (and the scene it came from) and the
        // field; a command-line value names the option.
        let from_scene = |field: &str, e: String| {
            format!(
                "{} (the scene's [render] table), render.{field}: {e}",
                manifest.display()
            )
        };
        let pick = |cli: Option<String>, scene: Option<String>, default: &str, field: &str| match (
            cli, scene,
        ) {
            (Some(v), _) => (v, None),
            (None, Some(v)) => (v, Some(field.to_string())),
            (None, None) => (default.to_string(), None),
        };
        let (camera_name, camera_field) =
            pick(cli.camera.clone(), scene.camera.clone(), "ortho", "camera");
        let (view_name, view_field) = pick(cli.view.clone(), scene.view.clone(), "auto", "view");
        let blame = |field: &Option<String>, e: cosserat_render::RenderError| match field {
            Some(f) => from_scene(f, e.to_string()),
            None => e.to_string(),
        };
        let mut projection =
            Projection::parse(&camera_name).map_err(|e| blame(&camera_field, e))?;
        if let (Projection::Perspective { fov_y_degrees }, Some(fov)) =
            (&mut projection, cli.fov.or(scene.fov))
        {
            *fov_y_degrees = fov;
        }
        let view = View::parse(&view_name).map_err(|e| blame(&view_field, e))?;
        let format = match cli.format.as_deref() {
            None => Some(AnimationFormat::best_available()),
            Some("mp4") => Some(AnimationFormat::Mp4),
            Some("gif") => Some(AnimationFormat::Gif),
            Some("png") => None,
            Some(other) => {
                return Err(format!(
                    "--format `{other}` is invalid: expected mp4, gif or png"
                ));
            }
        };
        if format == Some(AnimationFormat::Mp4) && !cosserat_render::ffmpeg_available() {
            return Err(
                "--format mp4 needs ffmpeg on the PATH; use --format gif or install ffmpeg".into(),
            );
        }
        let force_scale = match cli.force_scale.or(scene.force_scale) {
            Some(f) => f,
            None => contact_force_percentile(traj, 0.95).unwrap_or(1.0),
        };
        let settings = RenderSettings {
            width: cli.width.or(scene.width).unwrap_or(1280),
            height: cli.height.or(scene.height).unwrap_or(720),
            samples: cli.samples,
            force_scale,
            ..Default::default()
        };
        Ok(Self {
            settings,
            projection,
            view,
            camera_name,
            view_name,
            format,
            fps: cli.fps.or(scene.fps).unwrap_or(30),
        })
    }
}

/// The `q` quantile of the positive contact forces of the whole run, if any touched.
fn contact_force_percentile(traj: &Trajectory, q: f64) -> Option<f64> {
    let mut forces: Vec<f64> = traj
        .rods
        .iter()
        .flat_map(|r| r.contact_forces.iter().copied())
        .filter(|f| *f > 0.0 && f.is_finite())
        .collect();
    if forces.is_empty() {
        return None;
    }
    forces.sort_by(f64::total_cmp);
    let k = ((forces.len() - 1) as f64 * q).round() as usize;
    Some(forces[k])
}
