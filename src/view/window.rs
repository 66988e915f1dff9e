//! The window: draws the latest pose the physics published, turns keys, mouse and gamepad into
//! the hand's controls and the camera, and shows what the hand feels in the window's title.
//!
//! This runs on the main thread (window systems want their event loop there). It paces itself
//! to `max_fps` with `ControlFlow::WaitUntil` rather than relying on the swap chain's vsync,
//! because under Xvfb there is no display to wait for and a software rasteriser drawing flat out
//! would take the cores the physics needs.
//!
//! The readout (scene, simulated time, push and twist, hand force and displacement, real-time
//! factor, frames per second) is drawn over the picture in the renderer's built-in bitmap
//! font every frame, and set as the window's title four times a second.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use cosserat_render::{
    Bounds, Camera, Image, Presented, Projection, RenderSettings, SurfaceMesh, SurfaceRenderer,
    View, write_png,
};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use super::gamepad::PadAction;
use super::physics::{Controls, Mailbox, Pose};

/// Degrees the camera turns per pixel dragged.
const ORBIT_DEG_PER_PX: f64 = 0.3;
/// Zoom per wheel notch.
const ZOOM_PER_NOTCH: f64 = 1.15;
/// Pixels of right-button drag that make the full push speed or twist rate.
const DRAG_FULL_PX: f64 = 100.0;
/// Frames drawn to a window that gives no texture before a closing viewer gives up drawing.
const CLOSING_SKIPS: u32 = 30;
/// How long a closing viewer waits for the physics' last state.
pub(crate) const CLOSING_WAIT: Duration = Duration::from_secs(2);

/// How the window starts and what it is asked to do.
pub(crate) struct Setup {
    pub(crate) name: String,
    pub(crate) settings: RenderSettings,
    pub(crate) mesh: Option<SurfaceMesh>,
    pub(crate) bounds: Bounds,
    pub(crate) view: View,
    pub(crate) projection: Projection,
    pub(crate) max_fps: f64,
    pub(crate) frames: Option<u64>,
    pub(crate) screenshot: Option<PathBuf>,
    pub(crate) push_speed: f64,
    pub(crate) twist_rate: f64,
    /// Whether a held end can be steered (else keys for it do nothing).
    pub(crate) steerable: bool,
}

/// What the window did, for the summary and `--stats`.
#[derive(Default)]
pub(crate) struct WindowReport {
    pub(crate) frames: u64,
    /// Wall time between successive frames shown [s].
    pub(crate) intervals: Vec<f64>,
    pub(crate) adapter: String,
    pub(crate) samples: u32,
    pub(crate) size: (u32, u32),
    /// The last pose drawn.
    pub(crate) last: Pose,
    pub(crate) screenshots: Vec<PathBuf>,
    pub(crate) error: Option<String>,
}

/// Which steering keys are down.
#[derive(Default)]
struct Held {
    push: bool,
    pull: bool,
    twist_left: bool,
    twist_right: bool,
}

/// The winit application.
pub(crate) struct Viewer {
    setup: Setup,
    controls: Arc<Controls>,
    mailbox: Arc<Mailbox>,
    window: Option<Arc<Window>>,
    renderer: Option<SurfaceRenderer>,
    pose: Pose,
    view: View,
    zoom: f64,
    cursor: (f64, f64),
    orbiting: bool,
    /// Where the right button went down: the drag from there steers.
    steering_from: Option<(f64, f64)>,
    held: Held,
    /// The gamepad's push [m/s] and twist [rad/s], added to the keys' and the drag's.
    pad: (f64, f64),
    pending: Vec<PathBuf>,
    /// When the viewer was asked to close: it draws the physics' last state, or gives up
    /// waiting for it after [`CLOSING_WAIT`].
    closing: Option<Instant>,
    closing_skips: u32,
    next_frame: Instant,
    last_shown: Option<Instant>,
    title_at: Instant,
    fps_window: (Instant, u64),
    fps: f64,
    capture: Image,
    report: WindowReport,
}

impl Viewer {
    pub(crate) fn new(setup: Setup, controls: Arc<Controls>, mailbox: Arc<Mailbox>) -> Self {
        let now = Instant::now();
        Self {
            view: setup.view,
            setup,
            controls,
            mailbox,
            window: None,
            renderer: None,
            pose: Pose::default(),
            zoom: 1.0,
            cursor: (0.0, 0.0),
            orbiting: false,
            steering_from: None,
            held: Held::default(),
            pad: (0.0, 0.0),
            pending: Vec::new(),
            closing: None,
            closing_skips: 0,
            next_frame: now,
            last_shown: None,
            title_at: now,
            fps_window: (now, 0),
            fps: 0.0,
            capture: Image::default(),
            report: WindowReport::default(),
        }
    }

    /// What the window did, with the last pose it drew.
    pub(crate) fn finish(mut self) -> WindowReport {
        self.report.last = std::mem::take(&mut self.pose);
        if let Some(r) = &self.renderer {
            self.report.size = r.size();
        }
        self.report
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, why: String) {
        self.report.error.get_or_insert(why);
        self.controls.quit.store(true, Relaxed);
        event_loop.exit();
    }

    /// The camera for the window's size, the view turned by dragging and the wheel's zoom.
    fn camera(&self, width: u32, height: u32) -> Result<Camera, String> {
        Camera::framing(
            &self.setup.bounds,
            self.view,
            self.setup.projection,
            width,
            height,
        )
        .map(|c| c.zoomed(self.zoom))
        .map_err(|e| e.to_string())
    }

    /// Sets the hand's push and twist from the keys held, the right-button drag and the pad.
    fn steer(&self) {
        if !self.setup.steerable {
            return;
        }
        let axis = |plus: bool, minus: bool| f64::from(u8::from(plus)) - f64::from(u8::from(minus));
        let mut push = axis(self.held.push, self.held.pull);
        let mut twist = axis(self.held.twist_right, self.held.twist_left);
        if let Some((x0, y0)) = self.steering_from {
            // Up pushes in, right twists: a joystick whose deflection sets the speed.
            push += ((y0 - self.cursor.1) / DRAG_FULL_PX).clamp(-2.0, 2.0);
            twist += ((self.cursor.0 - x0) / DRAG_FULL_PX).clamp(-2.0, 2.0);
        }
        self.controls
            .push
            .set(push * self.setup.push_speed + self.pad.0);
        self.controls
            .twist
            .set(twist * self.setup.twist_rate + self.pad.1);
    }

    fn toggle_pause(&self) {
        self.controls.paused.fetch_xor(true, Relaxed);
    }

    fn step_once(&self) {
        self.controls.paused.store(true, Relaxed);
        self.controls.single_steps.fetch_add(1, Relaxed);
    }

    fn reset(&self) {
        self.controls.reset.store(true, Relaxed);
    }

    fn key(&mut self, key: &Key, pressed: bool, repeat: bool) {
        match key {
            Key::Named(NamedKey::ArrowUp) => self.held.push = pressed,
            Key::Named(NamedKey::ArrowDown) => self.held.pull = pressed,
            Key::Named(NamedKey::ArrowLeft) => self.held.twist_left = pressed,
            Key::Named(NamedKey::ArrowRight) => self.held.twist_right = pressed,
            Key::Named(NamedKey::Space) if pressed && !repeat => self.toggle_pause(),
            Key::Named(NamedKey::Escape) if pressed => self.begin_closing(),
            Key::Character(c) if pressed => match c.as_str() {
                "w" | "W" => self.held.push = true,
                "s" | "S" => self.held.pull = true,
                "a" | "A" => self.held.twist_left = true,
                "d" | "D" => self.held.twist_right = true,
                "n" | "N" | "." => self.step_once(),
                "r" | "R" if !repeat => self.reset(),
                "q" | "Q" => self.begin_closing(),
                "0" | "c" | "C" => {
                    // Back to the camera the viewer opened with.
                    self.view = self.setup.view;
                    self.zoom = 1.0;
                }
                _ => {}
            },
            Key::Character(c) => match c.as_str() {
                "w" | "W" => self.held.push = false,
                "s" | "S" => self.held.pull = false,
                "a" | "A" => self.held.twist_left = false,
                "d" | "D" => self.held.twist_right = false,
                _ => {}
            },
            _ => {}
        }
        self.steer();
    }

    /// A gamepad's action: the same as the keys'; its push and twist add to theirs.
    fn pad_action(&mut self, action: PadAction) {
        match action {
            PadAction::Steer { push, twist } => {
                self.pad = (push, twist);
                self.steer();
            }
            PadAction::TogglePause => self.toggle_pause(),
            PadAction::Step => self.step_once(),
            PadAction::Reset => self.reset(),
            PadAction::Quit => self.begin_closing(),
        }
    }

    fn begin_closing(&mut self) {
        self.closing.get_or_insert_with(Instant::now);
        // The physics publishes its last state and stops; the next frame draws it.
        self.controls.quit.store(true, Relaxed);
    }

    fn redraw(&mut self, event_loop: &ActiveEventLoop) {
        // Read before taking the pose: once the physics has ended, its last pose is in the
        // mailbox.
        let physics_ended = self.controls.ended.load(Relaxed);
        if let Some(pose) = self.mailbox.take() {
            let drawn = std::mem::replace(&mut self.pose, pose);
            self.mailbox.give_back(drawn);
            self.pending.append(&mut self.pose.screenshots);
        }
        let Some((w, h)) = self.renderer.as_ref().map(SurfaceRenderer::size) else {
            return;
        };
        // The last frame: the physics has stopped (closing, or a scripted run that quit or
        // diverged), or `--frames` are drawn.
        let last = self.pose.finished
            || physics_ended
            || self.closing.is_some_and(|t| t.elapsed() > CLOSING_WAIT)
            || self
                .setup
                .frames
                .is_some_and(|k| self.report.frames + 1 >= k);
        let capture = !self.pending.is_empty() || (last && self.setup.screenshot.is_some());
        let camera = match self.camera(w, h) {
            Ok(c) => c,
            Err(e) => return self.fail(event_loop, e),
        };
        let Some(renderer) = self.renderer.as_mut() else {
            return;
        };
        let lines = readout(&self.setup.name, &self.pose, self.fps, self.setup.steerable);
        renderer.set_overlay(&lines.iter().map(String::as_str).collect::<Vec<_>>());
        let rods = self.pose.rod_poses();
        let shown = renderer.draw(&camera, &rods, capture.then_some(&mut self.capture));
        drop(rods);
        match shown {
            Ok(Presented::Shown) => {}
            Ok(Presented::Skipped) => {
                if self.closing.is_some() || last {
                    self.closing_skips += 1;
                    if self.closing_skips > CLOSING_SKIPS {
                        let why = "the window gave no picture to draw the last frame into";
                        if capture {
                            return self.fail(event_loop, why.into());
                        }
                        event_loop.exit();
                    }
                }
                return;
            }
            Err(e) => return self.fail(event_loop, e.to_string()),
        }
        let now = Instant::now();
        if let Some(before) = self.last_shown {
            self.report.intervals.push((now - before).as_secs_f64());
        }
        self.last_shown = Some(now);
        self.report.frames += 1;
        if capture {
            let mut paths = std::mem::take(&mut self.pending);
            if last && let Some(p) = &self.setup.screenshot {
                paths.push(p.clone());
            }
            for path in paths {
                if let Err(e) = write_png(&path, &self.capture) {
                    return self.fail(event_loop, format!("screenshot: {e}"));
                }
                self.report.screenshots.push(path);
            }
        }
        self.update_title(now);
        if last {
            // With `--frames`, the physics is told to stop here; its last pose is not drawn.
            self.controls.quit.store(true, Relaxed);
            event_loop.exit();
        }
    }

    fn update_title(&mut self, now: Instant) {
        let elapsed = (now - self.fps_window.0).as_secs_f64();
        if elapsed >= 1.0 {
            self.fps = (self.report.frames - self.fps_window.1) as f64 / elapsed;
            self.fps_window = (now, self.report.frames);
        }
        if now < self.title_at {
            return;
        }
        self.title_at = now + Duration::from_millis(250);
        let Some(window) = &self.window else {
            return;
        };
        let lines = readout(&self.setup.name, &self.pose, self.fps, self.setup.steerable);
        window.set_title(&lines.join(" | "));
    }
}

/// The readout: what the hand does and feels, and how fast things run; drawn over the
/// picture, one line each, and joined into the window's title.
fn readout(name: &str, p: &Pose, fps: f64, steerable: bool) -> Vec<String> {
    let mut lines = vec![format!("{name}  t {:.3} s", p.time)];
    if steerable {
        lines.push(format!(
            "push {:+.3} m/s  twist {:+.1} rad/s",
            p.push, p.twist
        ));
        lines.push(match p.hand_force {
            Some(f) => {
                let norm = f.iter().map(|x| x * x).sum::<f64>().sqrt();
                // Newtons to three decimals where a hand feels it, else the small value itself.
                let force = if norm >= 0.01 {
                    format!("{norm:.3}")
                } else {
                    format!("{norm:.2e}")
                };
                format!("hand {force} N  moved {:+.1} mm", 1e3 * p.hand_displacement)
            }
            None => format!(
                "hand: no reaction  moved {:+.1} mm",
                1e3 * p.hand_displacement
            ),
        });
    }
    let mut speed = format!("real time x{:.2}  {fps:.0} fps", p.real_time_factor);
    if p.real_time_factor < 0.95 && !p.paused {
        speed += "  (physics behind)";
    }
    lines.push(speed);
    if let Some(why) = &p.stopped {
        lines.push(format!("STOPPED: {why} (R resets)"));
    } else if p.paused {
        lines.push("paused (space goes on, N steps)".into());
    }
    lines
}

impl ApplicationHandler<PadAction> for Viewer {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let attributes = Window::default_attributes()
            .with_title(format!("{} | cosserat view", self.setup.name))
            .with_inner_size(PhysicalSize::new(
                self.setup.settings.width,
                self.setup.settings.height,
            ));
        let window = match event_loop.create_window(attributes) {
            Ok(w) => Arc::new(w),
            Err(e) => return self.fail(event_loop, format!("cannot open a window: {e}")),
        };
        let size = window.inner_size();
        let settings = RenderSettings {
            width: size.width.max(1),
            height: size.height.max(1),
            ..self.setup.settings
        };
        match SurfaceRenderer::new(window.clone(), settings) {
            Ok(mut r) => {
                r.set_mesh(self.setup.mesh.as_ref());
                self.report.adapter = r.adapter().to_string();
                self.report.samples = r.samples();
                self.renderer = Some(r);
            }
            Err(e) => return self.fail(event_loop, e.to_string()),
        }
        self.window = Some(window);
        self.next_frame = Instant::now();
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => self.begin_closing(),
            WindowEvent::Resized(size) => {
                if let Some(r) = self.renderer.as_mut() {
                    r.resize(size.width, size.height);
                }
            }
            WindowEvent::KeyboardInput { event, .. } => self.key(
                &event.logical_key,
                event.state == ElementState::Pressed,
                event.repeat,
            ),
            WindowEvent::MouseInput { state, button, .. } => {
                let down = state == ElementState::Pressed;
                match button {
                    MouseButton::Left => {
                        if down && self.view == View::Auto {
                            // Orbiting starts from where the automatic view looks from.
                            if let Some(r) = &self.renderer {
                                let (w, h) = r.size();
                                if let Ok(c) = self.camera(w, h) {
                                    self.view = View::looking_from(c.towards_camera);
                                }
                            }
                        }
                        self.orbiting = down;
                    }
                    MouseButton::Right => {
                        self.steering_from = down.then_some(self.cursor);
                        self.steer();
                    }
                    _ => {}
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                let (dx, dy) = (position.x - self.cursor.0, position.y - self.cursor.1);
                self.cursor = (position.x, position.y);
                if self.orbiting
                    && let View::Angles { azimuth, elevation } = self.view
                {
                    self.view = View::Angles {
                        azimuth: azimuth - dx * ORBIT_DEG_PER_PX,
                        elevation: (elevation + dy * ORBIT_DEG_PER_PX).clamp(-89.0, 89.0),
                    };
                }
                if self.steering_from.is_some() {
                    self.steer();
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => f64::from(y),
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                self.zoom = (self.zoom * ZOOM_PER_NOTCH.powf(notches)).clamp(0.05, 500.0);
            }
            WindowEvent::RedrawRequested => self.redraw(event_loop),
            _ => {}
        }
    }

    /// The gamepad's actions, sent by its reader thread.
    fn user_event(&mut self, _: &ActiveEventLoop, action: PadAction) {
        self.pad_action(action);
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        let now = Instant::now();
        if now >= self.next_frame {
            if let Some(w) = &self.window {
                w.request_redraw();
            }
            let interval = Duration::from_secs_f64(1.0 / self.setup.max_fps);
            self.next_frame = (self.next_frame + interval).max(now);
        }
        event_loop.set_control_flow(ControlFlow::WaitUntil(self.next_frame));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn viewer(steerable: bool) -> Viewer {
        let setup = Setup {
            name: "test".into(),
            settings: RenderSettings::default(),
            mesh: None,
            bounds: Bounds::EMPTY,
            view: View::Auto,
            projection: Projection::Orthographic,
            max_fps: 60.0,
            frames: None,
            screenshot: None,
            push_speed: 0.05,
            twist_rate: 6.0,
            steerable,
        };
        Viewer::new(setup, Arc::default(), Arc::default())
    }

    /// The gamepad's actions reach the controls as the keys' do: its push and twist add to the
    /// keys', its buttons pause, step, reset and quit.
    #[test]
    fn pad_actions_drive_the_controls_as_keys_do() {
        let mut v = viewer(true);
        let c = v.controls.clone();
        v.pad_action(PadAction::Steer {
            push: 0.02,
            twist: -3.0,
        });
        assert_eq!((c.push.get(), c.twist.get()), (0.02, -3.0));
        v.key(&Key::Named(NamedKey::ArrowUp), true, false);
        assert!((c.push.get() - 0.07).abs() < 1e-15, "{}", c.push.get());
        v.key(&Key::Named(NamedKey::ArrowUp), false, false);
        v.pad_action(PadAction::Steer {
            push: 0.0,
            twist: 0.0,
        });
        assert_eq!((c.push.get(), c.twist.get()), (0.0, 0.0));
        v.pad_action(PadAction::TogglePause);
        assert!(c.paused.load(Relaxed));
        v.pad_action(PadAction::TogglePause);
        assert!(!c.paused.load(Relaxed));
        v.pad_action(PadAction::Step);
        assert!(c.paused.load(Relaxed));
        assert_eq!(c.single_steps.load(Relaxed), 1);
        v.pad_action(PadAction::Reset);
        assert!(c.reset.load(Relaxed));
        assert!(!c.quit.load(Relaxed));
        v.pad_action(PadAction::Quit);
        assert!(c.quit.load(Relaxed) && v.closing.is_some());
        // Without a held end the sticks do nothing.
        let mut v = viewer(false);
        v.pad_action(PadAction::Steer {
            push: 0.05,
            twist: 6.0,
        });
        assert_eq!(v.controls.push.get(), 0.0);
    }

    /// The readout says what the hand feels and when the physics is behind or paused.
    #[test]
    fn the_readout_says_force_speed_and_state() {
        let mut pose = Pose {
            time: 1.5,
            push: 0.05,
            hand_force: Some([0.3, 0.0, 0.4]),
            hand_displacement: 0.012,
            real_time_factor: 0.8,
            ..Default::default()
        };
        let lines = readout("wire", &pose, 59.6, true);
        assert_eq!(lines[0], "wire  t 1.500 s");
        assert_eq!(lines[1], "push +0.050 m/s  twist +0.0 rad/s");
        assert_eq!(lines[2], "hand 0.500 N  moved +12.0 mm");
        assert_eq!(lines[3], "real time x0.80  60 fps  (physics behind)");
        pose.hand_force = Some([0.0, 2e-4, 0.0]);
        pose.paused = true;
        let lines = readout("wire", &pose, 60.0, true);
        assert!(lines[2].starts_with("hand 2.00e-4 N"), "{}", lines[2]);
        assert!(!lines[3].contains("behind"), "{}", lines[3]);
        assert!(lines[4].starts_with("paused"), "{lines:?}");
        pose.stopped = Some("diverged".into());
        let lines = readout("free", &pose, 60.0, false);
        assert_eq!(lines.len(), 3, "no hand lines without a hand: {lines:?}");
        assert!(lines[2].contains("STOPPED: diverged"), "{lines:?}");
    }
}
