//! `cosserat view --offscreen`: the viewer without a window. The physics thread runs exactly as
//! with a window (same ticks, mailbox and script); this loop, on the main thread, draws the
//! newest pose at up to `--max-fps` into an offscreen picture with the same pipelines as the
//! window (`cosserat_render::Renderer`), waiting for the GPU to finish each frame, and
//! screenshots read that picture back.
//!
//! It exists to measure what the window cannot show on a machine without a display: how many
//! frames a GPU draws while the physics keeps real time (a server's GPU, CI without Xvfb). What
//! it leaves out is the window itself: presenting the frame to the display, the readout drawn
//! over the picture, and input (a script steers instead).

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use cosserat_render::{Camera, Image, write_png};

use super::physics::{Controls, Mailbox, Pose};
use super::window::{CLOSING_WAIT, Setup, WindowReport};

/// Draws until the physics ends (a script's `quit`, a divergence, Ctrl-C's default aside) or
/// `--frames` are drawn. Errors (no adapter, a device error, a screenshot that cannot be
/// written) end the run with the physics told to stop, in the report's `error`.
pub(crate) fn run(setup: Setup, controls: &Arc<Controls>, mailbox: &Arc<Mailbox>) -> WindowReport {
    let mut report = WindowReport::default();
    if let Err(e) = draw_until_done(&setup, controls, mailbox, &mut report) {
        report.error.get_or_insert(e);
    }
    controls.quit.store(true, Relaxed);
    report
}

fn draw_until_done(
    setup: &Setup,
    controls: &Arc<Controls>,
    mailbox: &Arc<Mailbox>,
    report: &mut WindowReport,
) -> Result<(), String> {
    let mut renderer = cosserat_render::Renderer::new(setup.settings).map_err(|e| e.to_string())?;
    renderer.set_mesh(setup.mesh.as_ref());
    report.adapter = renderer.adapter().to_string();
    report.samples = renderer.samples();
    let (width, height) = (setup.settings.width, setup.settings.height);
    report.size = (width, height);
    let camera = Camera::framing(&setup.bounds, setup.view, setup.projection, width, height)
        .map_err(|e| e.to_string())?;
    let interval = Duration::from_secs_f64(1.0 / setup.max_fps);
    let mut pose = Pose::default();
    let mut pending = Vec::new();
    let mut capture = Image::default();
    let mut next_frame = Instant::now();
    let mut last_shown: Option<Instant> = None;
    let mut ended_at: Option<Instant> = None;
    loop {
        let now = Instant::now();
        if now < next_frame {
            std::thread::sleep(next_frame - now);
        }
        next_frame = (next_frame + interval).max(Instant::now());
        // Read before taking the pose: once the physics has ended, its last pose is in the
        // mailbox.
        let physics_ended = controls.ended.load(Relaxed);
        if let Some(newer) = mailbox.take() {
            let drawn = std::mem::replace(&mut pose, newer);
            mailbox.give_back(drawn);
            pending.append(&mut pose.screenshots);
        }
        if physics_ended && !pose.finished {
            // The physics ended without its last pose reaching us yet; wait for it a while.
            let since = *ended_at.get_or_insert_with(Instant::now);
            if since.elapsed() < CLOSING_WAIT {
                continue;
            }
        }
        let last =
            pose.finished || physics_ended || setup.frames.is_some_and(|k| report.frames + 1 >= k);
        let rods = pose.rod_poses();
        renderer
            .draw(&camera, &rods)
            .map_err(|e| format!("drawing a frame: {e}"))?;
        let shown = Instant::now();
        if let Some(before) = last_shown {
            report.intervals.push((shown - before).as_secs_f64());
        }
        last_shown = Some(shown);
        report.frames += 1;
        if last && let Some(p) = &setup.screenshot {
            pending.push(p.clone());
        }
        if !pending.is_empty() {
            renderer
                .render_into(&camera, &rods, &mut capture)
                .map_err(|e| format!("screenshot: {e}"))?;
            for path in pending.drain(..) {
                write_png(&path, &capture).map_err(|e| format!("screenshot: {e}"))?;
                report.screenshots.push(path);
            }
        }
        drop(rods);
        if last {
            report.last = pose;
            return Ok(());
        }
    }
}
