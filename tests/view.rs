//! `cosserat view` in a real window under Xvfb, driven by a script as a hand would drive it
//! (push, twist, a screenshot, quit) and by the keyboard: it exits cleanly, the pictures show
//! the rope, and the held end moved as far as it was pushed.
//!
//! It needs `xvfb-run` (Debian's `xvfb`; `xdotool` for the keys) and a wgpu adapter
//! (lavapipe). Without them the window tests pass after saying why they did not run, unless
//! `COSSERAT_REQUIRE_DISPLAY=1` (CI installs both and sets it) or, for the adapter,
//! `COSSERAT_REQUIRE_GPU=1`, which make them fail.
#![cfg(feature = "view")]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Whether `xvfb-run` can be started; `false` means the test is skipped (or fails when a
/// display is required).
fn xvfb_available() -> bool {
    let found = Command::new("xvfb-run")
        .arg("--help")
        .output()
        .is_ok_and(|o| o.status.success() || !o.stdout.is_empty() || !o.stderr.is_empty());
    if !found {
        assert!(
            std::env::var("COSSERAT_REQUIRE_DISPLAY").as_deref() != Ok("1"),
            "COSSERAT_REQUIRE_DISPLAY=1 but xvfb-run is not installed (apt-get install xvfb)"
        );
        eprintln!(
            "skipped: xvfb-run is not installed (apt-get install xvfb), so no window can be opened"
        );
    }
    found
}

/// `xvfb-run -a` picks a free display number, but two started at once can pick the same one:
/// the window tests take turns.
static ONE_DISPLAY_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Runs `cosserat ARGS` in a window under Xvfb; `None` when it found no adapter (allowed
/// unless `COSSERAT_REQUIRE_GPU=1`).
fn view_under_xvfb(args: &[&std::ffi::OsStr]) -> Option<(String, String)> {
    let _turn = ONE_DISPLAY_AT_A_TIME
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    // `cosserat ARGS`, or any other program when the first argument is `bash`.
    let program: &std::ffi::OsStr = if args.first().is_some_and(|a| *a == "bash") {
        "bash".as_ref()
    } else {
        env!("CARGO_BIN_EXE_cosserat").as_ref()
    };
    let args = if program == "bash" { &args[1..] } else { args };
    let run = || {
        Command::new("xvfb-run")
            .args(["-a", "-s", "-screen 0 800x600x24"])
            .arg(program)
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .output()
            .unwrap()
    };
    // The X server `xvfb-run` starts is not always there when the program connects (the last
    // test's server, still going away, can hold the display number `-a` picked): once seen in
    // CI, as the viewer's error that it cannot connect. Such a start is tried again, twice at
    // most; anything else the program says fails the test at once.
    let mut out = run();
    for _ in 0..2 {
        if !String::from_utf8_lossy(&out.stderr).contains("Failed to open connection to X server") {
            break;
        }
        std::thread::sleep(std::time::Duration::from_secs(1));
        out = run();
    }
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    if stderr.contains("no GPU adapter") {
        assert!(
            std::env::var("COSSERAT_REQUIRE_GPU").as_deref() != Ok("1"),
            "COSSERAT_REQUIRE_GPU=1 but there is no adapter: {stderr}"
        );
        eprintln!("skipped: {stderr}");
        return None;
    }
    assert!(
        out.status.success(),
        "exit {:?}\nstdout: {stdout}\nstderr: {stderr}",
        out.status
    );
    Some((stdout, stderr))
}

/// The JSON summary line the viewer prints on exit.
fn summary(stdout: &str) -> serde_json::Value {
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no summary line in: {stdout}"));
    serde_json::from_str(line).unwrap()
}

fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cosserat-view-{}-{test}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The PNG's pixels as RGBA rows, decoded with the render crate's reader.
fn pixels(path: &Path) -> (u32, u32, Vec<u8>) {
    let image = cosserat_render::read_png(path).unwrap_or_else(|e| panic!("{e}"));
    (image.width, image.height, image.rgba)
}

/// How many pixels differ from the top-left one (the background) by more than a little, and
/// how many of those are the first rod's blue (the readout over the picture is white on
/// black, the background light grey).
fn drawn_pixels(rgba: &[u8]) -> (usize, usize) {
    let background = &rgba[..3];
    let drawn: Vec<&[u8]> = rgba
        .chunks_exact(4)
        .filter(|p| (0..3).any(|k| p[k].abs_diff(background[k]) > 16))
        .collect();
    let blue = drawn
        .iter()
        .filter(|p| p[2] > 120 && u32::from(p[2]) > u32::from(p[0]) + 60)
        .count();
    (drawn.len(), blue)
}

/// The hand's script in `dir` (push 0.1 m/s for 0.2 s, twist, a screenshot at 0.3 s, quit at
/// 0.35 s), with the paths of the script, its screenshot and a last picture.
fn push_script(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let (script, middle, last) = (
        dir.join("hand.txt"),
        dir.join("middle.png"),
        dir.join("last.png"),
    );
    std::fs::write(
        &script,
        format!(
            "# the hand\n0.0 push 0.1\n0.2 push 0\n0.2 twist 4\n0.3 screenshot {}\n0.35 quit\n",
            middle.display()
        ),
    )
    .unwrap();
    (script, middle, last)
}

/// That the picture is `size` and shows the rope: pixels that differ from the background,
/// some of them the rope's blue.
fn assert_shows_the_rope(picture: &Path, size: (u32, u32)) {
    let (w, h, rgba) = pixels(picture);
    assert_eq!((w, h), size, "{}", picture.display());
    let (drawn, rope) = drawn_pixels(&rgba);
    assert!(
        drawn > 50 && rope > 20,
        "{}: {drawn} pixels differ from the background, {rope} are the rope's blue",
        picture.display()
    );
}

/// The pendulum's rope (16 elements, pinned at its first end) pushed along its axis at
/// 0.1 m/s for 0.2 s of simulated time, then twisted, photographed, and closed: the command
/// exits 0, both pictures are the size asked and show the rope, and the summary says the
/// held end moved 20 mm along the axis. The viewer said once which gamepad it reads, or that
/// it found none (this machine may have no `/dev/input` at all).
#[test]
fn a_scripted_hand_pushes_the_wire_in_a_window() {
    if !xvfb_available() {
        return;
    }
    let dir = scratch("push");
    let (script, middle, last) = push_script(&dir);
    let started = std::time::Instant::now();
    let Some((stdout, stderr)) = view_under_xvfb(&[
        "view".as_ref(),
        "scenes/pendulum.toml".as_ref(),
        "--elements".as_ref(),
        "16".as_ref(),
        "--width".as_ref(),
        "320".as_ref(),
        "--height".as_ref(),
        "200".as_ref(),
        "--script".as_ref(),
        script.as_os_str(),
        "--screenshot".as_ref(),
        last.as_os_str(),
    ]) else {
        return;
    };
    eprintln!("viewer ran {:.1} s", started.elapsed().as_secs_f64());
    let summary = summary(&stdout);
    let line = summary.to_string();
    let moved = summary["hand_displacement_m"].as_f64().unwrap();
    assert!(
        (moved - 0.02).abs() < 1e-4,
        "the held end moved {moved} m along its axis, 0.1 m/s for 0.2 s is 0.02 m: {line}"
    );
    assert!(summary["frames"].as_u64().unwrap() >= 1, "{line}");
    assert!(summary["time_s"].as_f64().unwrap() > 0.349, "{line}");
    assert_eq!(stderr.matches("gamepad: ").count(), 1, "{stderr}");
    assert!(
        summary["gamepad"].is_string() || stderr.contains("gamepad: none found"),
        "{line}\n{stderr}"
    );
    assert!(
        summary["hand_force_norm_n"].as_f64().unwrap() > 0.0,
        "{line}"
    );
    for picture in [&middle, &last] {
        assert_shows_the_rope(picture, (320, 200));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `--frames K` closes the window after K frames, saving the last with `--screenshot`; the
/// scene runs as written meanwhile (nobody steers). With `--no-gamepad` no pad is looked for.
#[test]
fn frames_close_the_window() {
    if !xvfb_available() {
        return;
    }
    let dir = scratch("frames");
    let last = dir.join("last.png");
    let Some((stdout, stderr)) = view_under_xvfb(&[
        "view".as_ref(),
        "scenes/pendulum.toml".as_ref(),
        "--no-gamepad".as_ref(),
        "--elements".as_ref(),
        "8".as_ref(),
        "--width".as_ref(),
        "160".as_ref(),
        "--height".as_ref(),
        "120".as_ref(),
        "--frames".as_ref(),
        "5".as_ref(),
        "--screenshot".as_ref(),
        last.as_os_str(),
    ]) else {
        return;
    };
    let summary = summary(&stdout);
    assert_eq!(summary["frames"], 5, "{summary}");
    assert_eq!(summary["hand_displacement_m"], 0.0, "{summary}");
    assert!(summary["gamepad"].is_null(), "{summary}");
    assert!(!stderr.contains("gamepad"), "{stderr}");
    let (w, h, rgba) = pixels(&last);
    assert_eq!((w, h), (160, 120));
    assert!(drawn_pixels(&rgba).0 > 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// The keyboard steers: under Xvfb, `xdotool` holds the up arrow on the window for half a
/// second and then presses Q; the viewer exits 0 and the held end moved forward along its
/// axis. Skipped where `xdotool` is missing, unless `COSSERAT_REQUIRE_DISPLAY=1`.
#[test]
fn the_up_arrow_pushes_the_wire() {
    if !xvfb_available() {
        return;
    }
    if Command::new("xdotool").arg("version").output().is_err() {
        assert!(
            std::env::var("COSSERAT_REQUIRE_DISPLAY").as_deref() != Ok("1"),
            "COSSERAT_REQUIRE_DISPLAY=1 but xdotool is not installed (apt-get install xdotool)"
        );
        eprintln!(
            "skipped: xdotool is not installed (apt-get install xdotool), so no key can be pressed"
        );
        return;
    }
    let dir = scratch("keys");
    let summary_file = dir.join("summary.json");
    // Started inside the X server: the viewer in the background, then the keys once its
    // window is there.
    let hand = r#"
        timeout 60 "$1" view scenes/pendulum.toml --elements 8 --width 320 --height 200 > "$2" &
        viewer=$!
        for i in $(seq 150); do
            window=$(xdotool search --name pendulum 2>/dev/null | head -1)
            [ -n "$window" ] && break
            sleep 0.2
        done
        [ -n "$window" ] || { echo "no window"; kill $viewer; exit 3; }
        sleep 0.5
        # No window manager gives the window the focus: take it, so that keys reach it.
        xdotool windowfocus --sync "$window"
        xdotool keydown --window "$window" Up
        sleep 0.5
        xdotool keyup --window "$window" Up
        sleep 0.2
        xdotool key --window "$window" q
        wait $viewer
    "#;
    let Some(_) = view_under_xvfb(&[
        "bash".as_ref(),
        "-c".as_ref(),
        hand.as_ref(),
        "hand".as_ref(),
        env!("CARGO_BIN_EXE_cosserat").as_ref(),
        summary_file.as_os_str(),
    ]) else {
        return;
    };
    let stdout = std::fs::read_to_string(&summary_file).unwrap();
    let summary = summary(&stdout);
    let moved = summary["hand_displacement_m"].as_f64().unwrap();
    // 0.05 m/s for half a second of wall time is 25 mm in real time; a debug build may run
    // slower than real time.
    assert!(
        moved > 1e-3 && moved < 0.05,
        "the held end moved {moved} m: {summary}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Without a display the command fails with an error that says what is missing, not a
/// panic.
#[test]
fn without_a_display_it_says_so() {
    let out = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["view", "scenes/pendulum.toml", "--elements", "4"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("needs a display"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// A bad script line is refused before any window opens, naming the file, line and value.
#[test]
fn a_bad_script_names_its_line() {
    let dir = scratch("bad");
    let script = dir.join("hand.txt");
    std::fs::write(&script, "0 push 0.1\n0.1 push quickly\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["view", "scenes/pendulum.toml", "--script"])
        .arg(&script)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("hand.txt:2") && stderr.contains("quickly"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `--offscreen` needs no display: with `DISPLAY` unset, the same scripted push runs, the
/// frames are drawn offscreen (as many as the pacing allows for 0.35 s of simulated time), the
/// script's and the last screenshots show the rope at the size asked, the held end moved
/// 20 mm, and no gamepad is looked for.
#[test]
fn offscreen_it_draws_without_a_display() {
    let dir = scratch("offscreen");
    let (script, middle, last) = push_script(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["view", "scenes/pendulum.toml", "--elements", "16"])
        .args(["--width", "320", "--height", "200", "--offscreen"])
        .arg("--script")
        .arg(&script)
        .arg("--screenshot")
        .arg(&last)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    if stderr.contains("no GPU adapter") {
        assert!(
            std::env::var("COSSERAT_REQUIRE_GPU").as_deref() != Ok("1"),
            "COSSERAT_REQUIRE_GPU=1 but there is no adapter: {stderr}"
        );
        eprintln!("skipped: {stderr}");
        return;
    }
    assert!(
        out.status.success(),
        "exit {:?}\n{stdout}\n{stderr}",
        out.status
    );
    let summary = summary(&stdout);
    let line = summary.to_string();
    let moved = summary["hand_displacement_m"].as_f64().unwrap();
    assert!((moved - 0.02).abs() < 1e-4, "{line}");
    assert!(summary["frames"].as_u64().unwrap() >= 2, "{line}");
    assert!(summary["gamepad"].is_null(), "{line}");
    assert!(!stderr.contains("gamepad"), "{stderr}");
    for picture in [&middle, &last] {
        assert_shows_the_rope(picture, (320, 200));
    }
    std::fs::remove_dir_all(&dir).ok();
}
