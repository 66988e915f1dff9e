//! `cosserat render` and the run directory it reads, as a user runs them: a small run of the
//! vessel drawn into frames and a GIF, `--npz-only`, and errors that name what is wrong.
//!
//! Drawing needs a wgpu adapter (lavapipe in CI). Without one the drawing tests pass without
//! checking, unless `COSSERAT_REQUIRE_GPU=1`, which makes a missing adapter a failure.
#![cfg(feature = "render")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn cosserat(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap()
}

fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cosserat-render-{}-{test}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    dir
}

fn text(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 temporary folder")
}

/// The width and height of a PNG file, from its header (the first chunk, IHDR).
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n") && &bytes[12..16] == b"IHDR");
    let word = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
    (word(16), word(20))
}

/// Whether `out` failed for want of an adapter, which passes unless one is required.
fn no_adapter(out: &Output) -> bool {
    let err = String::from_utf8_lossy(&out.stderr);
    if err.contains("no GPU adapter") {
        assert!(
            std::env::var("COSSERAT_REQUIRE_GPU").as_deref() != Ok("1"),
            "COSSERAT_REQUIRE_GPU=1 but there is no adapter: {err}"
        );
        eprintln!("skipped: {err}");
        return true;
    }
    false
}

/// Whether the command drew: `false` when it found no adapter (allowed unless
/// `COSSERAT_REQUIRE_GPU=1`, see [`no_adapter`]); otherwise it must have succeeded.
fn rendered(out: &Output) -> bool {
    if no_adapter(out) {
        return false;
    }
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    true
}

/// A wire pushed a few millimetres into the vessel (stiff scheme, 40 steps of 1 ms), recorded
/// at 4 frames with `--npz-only`: the run directory holds the NumPy file with the mesh and the
/// contact forces, and `run.json` with the scene's `[render]` table; `cosserat render` draws
/// five PNG frames and a GIF of the size asked for.
#[test]
fn a_run_is_drawn_into_frames_and_a_gif() {
    let dir = scratch("gif");
    let out = cosserat(&[
        "run",
        "scenes/stiff-guidewire-insertion.toml",
        "--steps",
        "40",
        "--elements",
        "64",
        "--frames",
        "4",
        "--npz-only",
        "--json",
        "--set",
        "render.view=\"top\"",
        "--out",
        text(&dir),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| n.ends_with(".vtp") || n.ends_with(".pvd")),
        "{names:?}"
    );
    let traj = cosserat::output::read_npz(&dir.join("trajectory.npz")).unwrap();
    assert_eq!(traj.n_frames(), 5);
    let mesh = traj.environment.as_ref().expect("the vessel is written");
    assert!(
        mesh.triangles.len() > 20_000,
        "{} triangles",
        mesh.triangles.len()
    );
    assert_eq!(traj.rods[0].contact_forces.len(), 5 * 65);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    assert_eq!(manifest["render"]["view"], "top");

    let out = cosserat(&[
        "render",
        text(&dir),
        "--width",
        "64",
        "--height",
        "40",
        "--format",
        "gif",
        "--json",
    ]);
    if !rendered(&out) {
        return;
    }
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["frames"], 5);
    assert_eq!(report["view"], "top", "the scene's [render] table is used");
    let render = dir.join("render");
    for k in 0..5 {
        let png = render.join(format!("frame_{k:05}.png"));
        assert_eq!(png_size(&png), (64, 40));
    }
    assert!(!render.join("frame_00005.png").exists());
    let gif = std::fs::read(render.join("stiff-guidewire-insertion.gif")).unwrap();
    assert!(gif.starts_with(b"GIF89a"));
    std::fs::remove_dir_all(&dir).ok();
}

/// `--format mp4` pipes the frames through ffmpeg into an H.264 MP4 with one picture per frame
/// (checked with ffprobe). Without ffmpeg the command refuses mp4 with a message that says so;
/// `COSSERAT_REQUIRE_FFMPEG=1` (set by CI, which installs it) makes a missing ffmpeg a failure.
#[test]
fn render_writes_an_mp4_through_ffmpeg() {
    let has_ffmpeg = Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_ffmpeg {
        assert!(
            std::env::var("COSSERAT_REQUIRE_FFMPEG").as_deref() != Ok("1"),
            "COSSERAT_REQUIRE_FFMPEG=1 but ffmpeg does not run"
        );
    }
    let dir = scratch("mp4");
    let out = cosserat(&[
        "run",
        "scenes/pendulum.toml",
        "--elements",
        "8",
        "--steps",
        "40",
        "--frames",
        "4",
        "--out",
        text(&dir),
        "--render",
        "--format",
        "mp4",
        "--width",
        "64",
        "--height",
        "48",
    ]);
    if no_adapter(&out) {
        return;
    }
    if !has_ffmpeg {
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("needs ffmpeg"), "{err}");
        return;
    }
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mp4 = dir.join("render").join("pendulum.mp4");
    let bytes = std::fs::read(&mp4).unwrap_or_else(|e| panic!("{}: {e}", mp4.display()));
    assert_eq!(&bytes[4..8], b"ftyp", "not an MP4 file");
    let probe = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-count_frames",
            "-show_entries",
            "stream=codec_name,nb_read_frames,width,height",
            "-of",
            "default=nw=1",
        ])
        .arg(&mp4)
        .output();
    if let Some(probe) = probe.ok().filter(|p| p.status.success()) {
        let info = String::from_utf8_lossy(&probe.stdout);
        for line in [
            "codec_name=h264",
            "width=64",
            "height=48",
            "nb_read_frames=5",
        ] {
            assert!(info.contains(line), "ffprobe says:\n{info}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `run --render` draws what the run wrote; `--last-only` writes one still.
#[test]
fn run_render_draws_the_run_it_made() {
    let dir = scratch("run-render");
    let out = cosserat(&[
        "run",
        "scenes/pendulum.toml",
        "--elements",
        "8",
        "--steps",
        "50",
        "--frames",
        "2",
        "--out",
        text(&dir),
        "--render",
        "--last-only",
        "--format",
        "png",
        "--width",
        "48",
        "--height",
        "32",
        "--camera",
        "perspective",
    ]);
    if !rendered(&out) {
        return;
    }
    assert_eq!(png_size(&dir.join("render").join("last.png")), (48, 32));
    assert!(!dir.join("render").join("frame_00000.png").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// A folder without a run, a bad view on the command line or in the scene, and `--render`
/// without `--out` are refused with messages that name the file, option or field.
#[test]
fn bad_render_input_names_what_is_wrong() {
    let dir = scratch("errors");
    std::fs::create_dir_all(&dir).unwrap();
    let out = cosserat(&["render", text(&dir)]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("trajectory.npz") && err.contains("--out"),
        "{err}"
    );

    let out = cosserat(&[
        "run",
        "scenes/pendulum.toml",
        "--elements",
        "4",
        "--steps",
        "10",
        "--frames",
        "1",
        "--npz-only",
        "--set",
        "render.view=\"sideways\"",
        "--out",
        text(&dir),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = cosserat(&["render", text(&dir), "--format", "png"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("run.json") && err.contains("render.view") && err.contains("sideways"),
        "{err}"
    );
    let out = cosserat(&["render", text(&dir), "--view", "10,200"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--view") && err.contains("10,200"), "{err}");
    let out = cosserat(&["render", text(&dir), "--view", "auto", "--format", "avi"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--format") && err.contains("avi"), "{err}");

    // An unknown field of the scene's [render] table is refused when the scene loads.
    let out = cosserat(&[
        "run",
        "scenes/pendulum.toml",
        "--steps",
        "1",
        "--set",
        "render.colour=\"red\"",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("colour"), "{err}");

    let out = cosserat(&["run", "scenes/pendulum.toml", "--steps", "1", "--render"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--out"));
    std::fs::remove_dir_all(&dir).ok();
}
