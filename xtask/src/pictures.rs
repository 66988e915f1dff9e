//! `cargo xtask pictures`: the pictures of the README and of `docs/`, made from the shipped
//! scenes by the `cosserat` command itself, so that they show what the code does today.
//!
//! Each picture runs a scene with `cosserat run --npz-only --out`, draws its last frame with
//! `cosserat render --last-only --format png`, and copies it into `docs/pictures/`; the knot
//! is also drawn as a small animated GIF of the whole run. The scenes
//! with the explicit scheme's tiny steps are run with the stiff scheme at 1 ms (the runs take
//! seconds instead of minutes; `docs/stiff-solver.md` compares the two schemes on them).
//!
//! `cargo xtask bench --render` (also here) measures the rendering itself: a 512-element
//! insertion into the default vessel recorded at 1000 frames, rendered at 1280×720, into
//! `docs/benchmarks/render.md` and `render.json`.

use std::path::{Path, PathBuf};

use crate::bench::{cargo, conditions, machine, root};

/// One picture: its file, the scene, the overrides and the camera, and whether a small
/// animated GIF of the whole run is made too (the file's name with `.gif`).
struct Picture {
    file: &'static str,
    scene: &'static str,
    run: &'static [&'static str],
    render: &'static [&'static str],
    animate: bool,
}

/// Frames recorded for an animated picture (besides the initial state).
const ANIMATION_FRAMES: &str = "48";

/// The stiff scheme at 1 ms in `f64`, for scenes written for the explicit scheme.
const STIFF: [&str; 6] = [
    "--set",
    "solver.scheme=\"stiff\"",
    "--set",
    "solver.dt=1e-3",
    "--set",
    "solver.precision=\"f64\"",
];

const PICTURES: &[Picture] = &[
    Picture {
        file: "phantom-insertion.png",
        scene: "scenes/phantom-insertion.toml",
        run: &STIFF,
        render: &[],
        animate: false,
    },
    Picture {
        file: "vessel-insertion.png",
        scene: "scenes/stiff-guidewire-insertion.toml",
        run: &[],
        render: &["--camera", "perspective"],
        animate: false,
    },
    Picture {
        file: "catheter-guidewire.png",
        scene: "scenes/catheter-guidewire.toml",
        run: &STIFF,
        render: &[],
        animate: false,
    },
    Picture {
        file: "fishermans-knot.png",
        scene: "scenes/fishermans-knot.toml",
        run: &[],
        render: &[],
        animate: true,
    },
];

/// The `cosserat` command through `cargo run --release`, so that it is built first.
fn cosserat(args: &[&str]) -> Result<String, String> {
    let mut all = vec!["run", "--release", "-q", "-p", "cosserat-cli", "--"];
    all.extend_from_slice(args);
    cargo(&all)
}

fn scratch(name: &str) -> PathBuf {
    root().join("target").join("xtask-pictures").join(name)
}

fn path_arg(p: &Path) -> Result<&str, String> {
    p.to_str()
        .ok_or_else(|| format!("{} is not UTF-8", p.display()))
}

/// `cargo xtask pictures`.
pub(crate) fn run() -> Result<bool, String> {
    let docs = root().join("docs").join("pictures");
    std::fs::create_dir_all(&docs).map_err(|e| format!("{}: {e}", docs.display()))?;
    for p in PICTURES {
        let dir = scratch(p.file.trim_end_matches(".png"));
        std::fs::remove_dir_all(&dir).ok();
        eprintln!("{}: running {}", p.file, p.scene);
        let frames = if p.animate { ANIMATION_FRAMES } else { "10" };
        let mut args = vec!["run", p.scene, "--npz-only", "--frames", frames, "--out"];
        args.push(path_arg(&dir)?);
        args.extend_from_slice(p.run);
        cosserat(&args)?;
        let mut args = vec![
            "render",
            path_arg(&dir)?,
            "--last-only",
            "--format",
            "png",
            "--width",
            "960",
            "--height",
            "540",
            "--samples",
            "4",
        ];
        args.extend_from_slice(p.render);
        print!("{}", cosserat(&args)?);
        let from = dir.join("render").join("last.png");
        let to = docs.join(p.file);
        std::fs::copy(&from, &to)
            .map_err(|e| format!("{} → {}: {e}", from.display(), to.display()))?;
        let size = std::fs::metadata(&to).map(|m| m.len()).unwrap_or(0);
        println!("wrote {} ({} kB)", to.display(), size / 1000);
        if p.animate {
            let out = dir.join("animation");
            let mut args = vec!["render", path_arg(&dir)?, "--out", path_arg(&out)?];
            args.extend_from_slice(&[
                "--format",
                "gif",
                "--width",
                "480",
                "--height",
                "270",
                "--samples",
                "4",
                "--fps",
                "12",
            ]);
            args.extend_from_slice(p.render);
            print!("{}", cosserat(&args)?);
            let gif = std::fs::read_dir(&out)
                .map_err(|e| format!("{}: {e}", out.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .find(|p| p.extension().is_some_and(|x| x == "gif"))
                .ok_or_else(|| format!("{}: no GIF written", out.display()))?;
            let to = docs.join(p.file.replace(".png", ".gif"));
            std::fs::copy(&gif, &to)
                .map_err(|e| format!("{} → {}: {e}", gif.display(), to.display()))?;
            let size = std::fs::metadata(&to).map(|m| m.len()).unwrap_or(0);
            println!("wrote {} ({} kB)", to.display(), size / 1000);
        }
    }
    Ok(true)
}

/// One timed configuration of the render benchmark.
struct Case {
    what: &'static str,
    args: &'static [&'static str],
}

const CASES: &[Case] = &[
    Case {
        what: "PNG frames + GIF (the default without ffmpeg: 1 sample on lavapipe)",
        args: &["--format", "gif"],
    },
    Case {
        what: "PNG frames only, 1 sample",
        args: &["--format", "png", "--samples", "1"],
    },
    Case {
        what: "PNG frames + GIF, perspective, 1 sample",
        args: &[
            "--format",
            "gif",
            "--camera",
            "perspective",
            "--view",
            "iso",
        ],
    },
    Case {
        what: "PNG frames + GIF, 4× MSAA",
        args: &["--format", "gif", "--samples", "4"],
    },
    Case {
        what: "PNG frames only, 4× MSAA",
        args: &["--format", "png", "--samples", "4"],
    },
];

/// `cargo xtask bench --render`.
pub(crate) fn bench() -> Result<bool, String> {
    let dir = scratch("render-bench");
    std::fs::remove_dir_all(&dir).ok();
    let frames = 1000;
    eprintln!("recording the insertion at {frames} frames…");
    let started = std::time::Instant::now();
    cosserat(&[
        "run",
        "scenes/stiff-guidewire-insertion.toml",
        "--npz-only",
        "--frames",
        &frames.to_string(),
        "--json",
        "--out",
        path_arg(&dir)?,
    ])?;
    let run_s = started.elapsed().as_secs_f64();
    let machine = machine();
    let conditions = conditions();
    let mut rows = Vec::new();
    let mut md = format!(
        "# Rendering a run: 1000 frames of a 512-element insertion at 1280×720\n\n\
         Machine: {machine}; {conditions}. Command: `cargo xtask bench --render`.\n\n\
         The run is `scenes/stiff-guidewire-insertion.toml` (one 512-element guidewire pushed \
         into the default ~26 000-triangle vessel, stiff scheme at 1 ms, 2450 steps) recorded \
         with `cosserat run --npz-only --frames {frames}` ({} frames with the initial state; \
         run and recording took {run_s:.1} s including `cargo run`'s check). Each row is one \
         `cosserat render RUN --json` of all frames at 1280×720 on Mesa's lavapipe (no GPU). \
         *draw* is building the tubes, drawing and reading each picture back (the drawing \
         thread); *PNG* and *animation* are the encoder thread's time writing the frames and \
         the animated file, which overlaps the drawing; *wall* is the command from start to \
         the last file, reading the run included. Goal: ≤ 30 s wall. lavapipe draws on the same \
         cores as the encoder thread and whatever else the machine runs (the load average \
         above), so compare rows of one table.\n\n\
         | configuration | samples | wall [s] | draw [s] | PNG [s] | animation [s] | read [s] | ms/frame (wall) | output [MB] |\n\
         |---|---|---|---|---|---|---|---|---|\n",
        frames + 1
    );
    for case in CASES {
        let out = dir.join("render");
        std::fs::remove_dir_all(&out).ok();
        let mut args = vec![
            "render",
            path_arg(&dir)?,
            "--json",
            "--out",
            path_arg(&out)?,
        ];
        args.extend_from_slice(case.args);
        eprintln!("{}…", case.what);
        let text = cosserat(&args)?;
        let v: serde_json::Value = serde_json::from_str(text.trim())
            .map_err(|e| format!("cosserat render --json: {e}: {text}"))?;
        let num = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        let bytes: u64 = std::fs::read_dir(&out)
            .map_err(|e| format!("{}: {e}", out.display()))?
            .filter_map(|e| e.ok()?.metadata().ok())
            .map(|m| m.len())
            .sum();
        let n = num("frames");
        md.push_str(&format!(
            "| {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} |\n",
            case.what,
            v["samples"],
            num("wall_s"),
            num("render_s"),
            num("png_s"),
            num("animation_s"),
            num("read_s"),
            1000.0 * num("wall_s") / n,
            bytes as f64 / 1e6,
        ));
        let mut row = v.clone();
        row["configuration"] = serde_json::json!(case.what);
        row["output_bytes"] = serde_json::json!(bytes);
        rows.push(row);
    }
    let adapter = rows
        .first()
        .and_then(|r| r["adapter"].as_str())
        .unwrap_or("unknown")
        .to_string();
    md.push_str(&format!("\nAdapter: {adapter}.\n"));
    let docs = root().join("docs").join("benchmarks");
    std::fs::write(docs.join("render.md"), &md).map_err(|e| format!("render.md: {e}"))?;
    let json = serde_json::json!({ "machine": machine, "conditions": conditions, "frames": frames + 1, "rows": rows });
    std::fs::write(
        docs.join("render.json"),
        serde_json::to_string_pretty(&json).unwrap_or_default(),
    )
    .map_err(|e| format!("render.json: {e}"))?;
    print!("{md}");
    Ok(true)
}
