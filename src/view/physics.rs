//! The physics thread: steps the simulation against the wall clock, takes the hand's input
//! every tick, and publishes the latest state for the window to draw.
//!
//! Drawing must never hold the physics back: a haptic loop ticks at 1 kHz, a window draws at
//! 60 Hz or less (much less on a software rasteriser), so the two run on their own threads and
//! meet only in a [`Mailbox`]: after a tick the physics swaps its freshly filled [`Pose`] into
//! the mailbox (a lock held for a swap of a few pointers) and the window takes the latest one
//! when it draws; a pose nobody took is overwritten, so the window always shows a recent state
//! and the physics never waits for a frame. A pose is published after every tick once the last
//! one was taken, else every [`PUBLISH_EVERY`] ticks, so the window draws a state at most a few
//! milliseconds old without the physics reading the rods out a thousand times a second.
//!
//! A tick is 1 ms of simulated time (or one step where the step is longer): the hand's push and
//! twist are set through the same control call a haptic device makes
//! (`Simulation::set_end_velocity`), then the tick's steps are run. The thread sleeps while the
//! simulation is ahead of the wall clock. If it falls behind by more than [`MAX_LAG`], it stops
//! trying to catch up (which would only make the lag grow) and counts the time lost: the
//! real-time factor drops below 1 and the window says so, rather than the window or the hand
//! freezing.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use cosserat::{ContactSample, RodHandle, Simulation};

use super::script::{Action, Timed};

/// Simulated time of one tick of the hand [s] (a haptic device's 1 kHz).
const TICK: f64 = 1e-3;
/// How far the simulation may fall behind the wall clock before the lag is written off [s].
const MAX_LAG: f64 = 0.1;
/// Ticks after which a pose is published even though the last one was not drawn yet: the
/// window draws a pose at most this many ticks old, and the physics does not spend time on
/// poses nobody draws (at 60 frames a second most ticks are not drawn).
const PUBLISH_EVERY: u32 = 4;
/// Wall time over which the real-time factor shown is measured [s].
const RATE_WINDOW: f64 = 0.5;

/// An `f64` shared between threads (its bits in an `AtomicU64`).
#[derive(Default)]
pub(crate) struct SharedF64(AtomicU64);

impl SharedF64 {
    pub(crate) fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Relaxed))
    }
    pub(crate) fn set(&self, x: f64) {
        self.0.store(x.to_bits(), Relaxed);
    }
}

/// What the keyboard, the mouse and the script ask for; the physics thread reads it every
/// tick, as a haptic device's state is read.
#[derive(Default)]
pub(crate) struct Controls {
    /// Push speed of the held end along its axis [m/s] (negative pulls).
    pub(crate) push: SharedF64,
    /// Twist rate of the held end about its axis [rad/s].
    pub(crate) twist: SharedF64,
    /// Paused by the user (space).
    pub(crate) paused: AtomicBool,
    /// Single steps asked for while paused.
    pub(crate) single_steps: AtomicU32,
    /// Back to the initial state.
    pub(crate) reset: AtomicBool,
    /// The viewer is closing: publish the last state and stop.
    pub(crate) quit: AtomicBool,
    /// The physics thread has ended, normally or not (set by [`Ended`]).
    pub(crate) ended: AtomicBool,
}

/// Sets [`Controls::ended`] when dropped, so that the window stops waiting for poses even if
/// the physics thread panics.
pub(crate) struct Ended(pub(crate) Arc<Controls>);

impl Drop for Ended {
    fn drop(&mut self) {
        self.0.ended.store(true, Relaxed);
    }
}

/// The held end that the hand steers: the first end of the first rod that holds one.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Hand {
    /// The rod.
    pub(crate) rod: RodHandle,
    /// Unit axis of the push and twist: the rod's first element at the start.
    pub(crate) axis: [f64; 3],
    /// Whether the end is clamped (only a clamped end's frame turns with the twist).
    pub(crate) clamped: bool,
}

impl Hand {
    /// Finds the held first end and takes it over: the scene's own motion of that end (a
    /// constant push, a keyframed path) is replaced by the hand, which starts at rest.
    /// `None` when no rod holds its first end.
    pub(crate) fn take_over(sim: &mut Simulation) -> Result<Option<Self>, String> {
        let handles: Vec<RodHandle> = sim.rods().collect();
        for rod in handles {
            let mut condition = sim.end_condition(rod, 0).map_err(|e| e.to_string())?;
            if !condition.holds_point() {
                continue;
            }
            let points = sim.positions(rod);
            let d: [f64; 3] = std::array::from_fn(|k| points[1][k] - points[0][k]);
            let length = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(length > 0.0) {
                return Err(format!(
                    "rod {} (`{}`): its first element has no length, so its held end has no axis to push along",
                    rod.0,
                    sim.rod_name(rod)
                ));
            }
            condition.motion = None;
            condition.path = None;
            let clamped = condition.holds_frame();
            sim.set_end_condition(rod, 0, condition)
                .map_err(|e| e.to_string())?;
            return Ok(Some(Self {
                rod,
                axis: d.map(|x| x / length),
                clamped,
            }));
        }
        Ok(None)
    }
}

/// One rod as drawn.
#[derive(Clone, Debug, Default)]
pub(crate) struct RodFrame {
    pub(crate) points: Vec<[f64; 3]>,
    pub(crate) d1: Vec<[f64; 3]>,
    pub(crate) radius: f64,
    /// Normal force of the wall on each point [N]; empty when the stepper reports no contacts.
    pub(crate) contact_force: Vec<f64>,
}

/// The state the physics publishes after a tick: what the window draws and shows.
#[derive(Clone, Debug, Default)]
pub(crate) struct Pose {
    pub(crate) rods: Vec<RodFrame>,
    /// Simulated time [s] and steps since the start (restarted by a reset).
    pub(crate) time: f64,
    pub(crate) steps: u64,
    /// The force the hand applies to the rod at the held end [N]; `None` without a hand or
    /// where the stepper computes no reactions (GPU).
    pub(crate) hand_force: Option<[f64; 3]>,
    /// The held end's displacement along the axis since the start [m].
    pub(crate) hand_displacement: f64,
    /// Push speed [m/s] and twist rate [rad/s] the hand was set to.
    pub(crate) push: f64,
    pub(crate) twist: f64,
    /// Simulated seconds per wall second over the last half second of running.
    pub(crate) real_time_factor: f64,
    pub(crate) paused: bool,
    /// Why the simulation stopped (a divergence), until it is reset.
    pub(crate) stopped: Option<String>,
    /// Screenshots the script asked for at this tick (carried over when a pose is
    /// overwritten before being drawn).
    pub(crate) screenshots: Vec<PathBuf>,
    /// The physics thread has ended: this is the last pose.
    pub(crate) finished: bool,
}

impl Pose {
    /// The rods as the renderer draws them.
    pub(crate) fn rod_poses(&self) -> Vec<cosserat_render::RodPose<'_>> {
        self.rods
            .iter()
            .map(|r| cosserat_render::RodPose {
                points: &r.points,
                d1: &r.d1,
                radius: r.radius,
                contact_force: (!r.contact_force.is_empty()).then_some(&r.contact_force[..]),
            })
            .collect()
    }
}

/// Where the physics leaves the latest pose and the window takes it.
#[derive(Default)]
pub(crate) struct Mailbox {
    latest: Mutex<Option<Pose>>,
    /// A pose the window has drawn and gives back, so that publishing allocates nothing.
    spare: Mutex<Option<Pose>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Mailbox {
    /// Puts `back` in the mailbox and hands back an old pose to fill next time.
    fn publish(&self, back: &mut Pose) {
        let mut slot = lock(&self.latest);
        let mut fresh = std::mem::take(back);
        match slot.take() {
            Some(mut unread) => {
                // Screenshots asked for in a pose nobody drew are still wanted.
                unread.screenshots.append(&mut fresh.screenshots);
                fresh.screenshots = std::mem::take(&mut unread.screenshots);
                *back = unread;
            }
            None => {
                if let Some(spare) = lock(&self.spare).take() {
                    *back = spare;
                }
            }
        }
        *slot = Some(fresh);
    }

    /// Whether a published pose has not been taken yet.
    fn holds_unread(&self) -> bool {
        lock(&self.latest).is_some()
    }

    /// The latest pose, if one came since the last call.
    pub(crate) fn take(&self) -> Option<Pose> {
        lock(&self.latest).take()
    }

    /// Returns a drawn pose for reuse.
    pub(crate) fn give_back(&self, mut pose: Pose) {
        pose.screenshots.clear();
        *lock(&self.spare) = Some(pose);
    }
}

/// What the physics thread did, for the summary and `--stats`.
#[derive(Clone, Debug, Default)]
pub(crate) struct PhysicsReport {
    /// Steps taken (resets included).
    pub(crate) steps: u64,
    /// Steps per tick and the step [s].
    pub(crate) tick_steps: u64,
    pub(crate) dt: f64,
    /// Wall time of each tick's steps [s].
    pub(crate) tick_times: Vec<f64>,
    /// Wall time of reading and publishing each pose published while running [s].
    pub(crate) publish_times: Vec<f64>,
    /// Simulated and wall seconds while running (not paused).
    pub(crate) simulated_s: f64,
    pub(crate) running_wall_s: f64,
    /// Lag written off because the simulation could not keep up [s].
    pub(crate) behind_s: f64,
    /// Why it stopped, if it diverged.
    pub(crate) stopped: Option<String>,
}

/// Runs the physics until [`Controls::quit`]; publishes a last pose with `finished` set.
pub(crate) fn run(
    mut sim: Simulation,
    hand: Option<Hand>,
    script: Vec<Timed>,
    controls: Arc<Controls>,
    mailbox: Arc<Mailbox>,
) -> PhysicsReport {
    let dt = sim.dt();
    let tick_steps = ((TICK / dt).round() as u64).max(1);
    let tick_s = tick_steps as f64 * dt;
    let mut report = PhysicsReport {
        tick_steps,
        dt,
        ..Default::default()
    };
    let mut gather = Gatherer::new(&sim, hand);
    let mut back = Pose::default();
    let initial = match sim.snapshot() {
        Ok(s) => s,
        Err(e) => {
            report.stopped = Some(format!("the initial state cannot be kept for resets: {e}"));
            gather.fill(&sim, &controls, &mut back);
            back.stopped = report.stopped.clone();
            back.finished = true;
            mailbox.publish(&mut back);
            return report;
        }
    };
    // The wall clock and the simulated time it is measured from: restarted after a pause,
    // a reset, or lag written off.
    let mut origin = (Instant::now(), sim.time());
    // Simulated time since the start, counted on through resets: the script's clock.
    let mut script_time = 0.0;
    let mut next_action = 0;
    let mut pause_until: Option<Instant> = None;
    let mut rate = RateMeter::new(sim.time());
    let mut last = Instant::now();
    let mut was_running = false;
    let mut published_paused = None;
    let mut stopped: Option<String> = None;
    let mut unpublished = 0;
    // The script quits after a divergence (nobody is there to reset), as at its `quit`.
    let scripted = !script.is_empty();
    while !controls.quit.load(Relaxed) {
        let now = Instant::now();
        if was_running {
            report.running_wall_s += (now - last).as_secs_f64();
        }
        last = now;
        if controls.reset.swap(false, Relaxed) {
            if let Err(e) = sim.restore(&initial) {
                stopped = Some(format!("reset failed: {e}"));
            } else {
                stopped = None;
            }
            origin = (now, sim.time());
            rate = RateMeter::new(sim.time());
            published_paused = None;
        }
        let paused = controls.paused.load(Relaxed)
            || pause_until.is_some_and(|t| now < t)
            || stopped.is_some();
        if paused {
            was_running = false;
            let single = controls.single_steps.swap(0, Relaxed);
            let stepped = single > 0 && stopped.is_none();
            if stepped {
                steer(&mut sim, hand, &controls);
                let t0 = Instant::now();
                if let Err(e) = sim.run(u64::from(single)) {
                    stopped = Some(e.to_string());
                }
                report.tick_times.push(t0.elapsed().as_secs_f64());
                report.steps += u64::from(single);
                script_time += f64::from(single) * dt;
            }
            if stepped || published_paused != Some(stopped.clone()) {
                gather.fill(&sim, &controls, &mut back);
                back.paused = true;
                back.real_time_factor = 0.0;
                back.stopped = stopped.clone();
                mailbox.publish(&mut back);
                published_paused = Some(stopped.clone());
            }
            if scripted && stopped.is_some() {
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
            origin = (Instant::now(), sim.time());
            rate = RateMeter::new(sim.time());
            continue;
        }
        pause_until = None;
        published_paused = None;
        // Real time: the simulation should be where the wall clock says.
        let due = origin.1 + (now - origin.0).as_secs_f64();
        let ahead = sim.time() + 0.5 * tick_s - due;
        if ahead > 0.0 {
            was_running = true;
            std::thread::sleep(Duration::from_secs_f64(ahead.min(2e-3)));
            continue;
        }
        // The script's actions due by now; those after a pause wait for its end.
        while let Some(timed) = script.get(next_action)
            && timed.at <= script_time + 0.5 * dt
            && pause_until.is_none()
        {
            next_action += 1;
            match &timed.action {
                Action::Push(v) => controls.push.set(*v),
                Action::Twist(w) => controls.twist.set(*w),
                Action::Pause(s) => pause_until = Some(now + Duration::from_secs_f64(*s)),
                Action::Screenshot(path) => back.screenshots.push(path.clone()),
                Action::Reset => controls.reset.store(true, Relaxed),
                Action::Quit => controls.quit.store(true, Relaxed),
            }
        }
        if pause_until.is_some() || controls.reset.load(Relaxed) || controls.quit.load(Relaxed) {
            was_running = false;
            continue;
        }
        was_running = true;
        steer(&mut sim, hand, &controls);
        let t0 = Instant::now();
        let result = sim.run(tick_steps);
        report.tick_times.push(t0.elapsed().as_secs_f64());
        report.steps += tick_steps;
        report.simulated_s += tick_s;
        script_time += tick_s;
        if let Err(e) = result {
            stopped = Some(e.to_string());
            report.stopped = stopped.clone();
        }
        let lag = due - sim.time();
        if lag > MAX_LAG {
            report.behind_s += lag;
            origin = (Instant::now(), sim.time());
        }
        let rate_now = rate.update(sim.time());
        unpublished += 1;
        if unpublished >= PUBLISH_EVERY || !mailbox.holds_unread() || stopped.is_some() {
            let t0 = Instant::now();
            gather.fill(&sim, &controls, &mut back);
            back.real_time_factor = rate_now;
            back.stopped = stopped.clone();
            mailbox.publish(&mut back);
            report.publish_times.push(t0.elapsed().as_secs_f64());
            unpublished = 0;
        }
    }
    gather.fill(&sim, &controls, &mut back);
    back.paused = controls.paused.load(Relaxed);
    back.stopped = stopped;
    back.real_time_factor = rate.last;
    back.finished = true;
    mailbox.publish(&mut back);
    report
}

/// Sets the held end's motion from the controls: what a haptic device does every tick.
fn steer(sim: &mut Simulation, hand: Option<Hand>, controls: &Controls) {
    if let Some(hand) = hand {
        let (push, twist) = (controls.push.get(), controls.twist.get());
        let twist = if hand.clamped { twist } else { 0.0 };
        // The end is held (found so at the start), so this cannot fail; a failure would only
        // leave the last motion in place.
        let _ = sim.set_end_velocity(
            hand.rod,
            0,
            hand.axis.map(|a| a * push),
            hand.axis.map(|a| a * twist),
        );
    }
}

/// The real-time factor over the last [`RATE_WINDOW`] of wall time.
struct RateMeter {
    since: Instant,
    sim_since: f64,
    last: f64,
}

impl RateMeter {
    fn new(sim_time: f64) -> Self {
        Self {
            since: Instant::now(),
            sim_since: sim_time,
            last: 1.0,
        }
    }

    fn update(&mut self, sim_time: f64) -> f64 {
        let wall = self.since.elapsed().as_secs_f64();
        if wall >= RATE_WINDOW {
            self.last = (sim_time - self.sim_since) / wall;
            self.since = Instant::now();
            self.sim_since = sim_time;
        }
        self.last
    }
}

/// Fills poses from the simulation, reusing its buffers.
struct Gatherer {
    hand: Option<Hand>,
    start: Option<[f64; 3]>,
    contacts: bool,
    samples: Vec<ContactSample>,
}

impl Gatherer {
    fn new(sim: &Simulation, hand: Option<Hand>) -> Self {
        let mut samples = Vec::new();
        let contacts = !sim.obstacles().is_empty()
            && sim.rods().all(|h| sim.contacts(h, &mut samples).is_ok());
        Self {
            hand,
            start: hand.map(|h| sim.positions(h.rod)[0]),
            contacts,
            samples,
        }
    }

    fn fill(&mut self, sim: &Simulation, controls: &Controls, pose: &mut Pose) {
        let handles: Vec<RodHandle> = sim.rods().collect();
        pose.rods.resize_with(handles.len(), RodFrame::default);
        for (frame, &h) in pose.rods.iter_mut().zip(&handles) {
            frame.points = sim.positions(h);
            frame.d1 = sim.first_directors(h);
            frame.radius = sim.rod_radius(h);
            frame.contact_force.clear();
            if self.contacts && sim.contacts(h, &mut self.samples).is_ok() {
                frame.contact_force.resize(frame.points.len(), 0.0);
                for c in &self.samples {
                    // The wall's push along its normal; friction is left out (as recorded runs).
                    let normal: f64 = (0..3).map(|k| c.force[k] * c.normal[k]).sum();
                    if let Some(slot) = frame.contact_force.get_mut(c.point) {
                        *slot = normal.max(0.0);
                    }
                }
            }
        }
        pose.time = sim.time();
        pose.steps = sim.steps();
        pose.paused = false;
        pose.finished = false;
        match (self.hand, self.start) {
            (Some(hand), Some(start)) => {
                let p = pose.rods[hand.rod.0].points[0];
                pose.hand_displacement = (0..3).map(|k| (p[k] - start[k]) * hand.axis[k]).sum();
                pose.hand_force = sim.end_reaction(hand.rod, 0).map(|r| r.force);
            }
            _ => {
                pose.hand_displacement = 0.0;
                pose.hand_force = None;
            }
        }
        pose.push = controls.push.get();
        pose.twist = controls.twist.get();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pose nobody drew is overwritten by the next, keeping its screenshots; the window
    /// gets the newest.
    #[test]
    fn the_mailbox_keeps_the_newest_pose_and_every_screenshot() {
        let mailbox = Mailbox::default();
        let mut back = Pose {
            time: 1.0,
            screenshots: vec!["a.png".into()],
            ..Default::default()
        };
        mailbox.publish(&mut back);
        back.time = 2.0;
        back.screenshots = vec!["b.png".into()];
        mailbox.publish(&mut back);
        let got = mailbox.take().unwrap();
        assert_eq!(got.time, 2.0);
        assert_eq!(
            got.screenshots,
            vec![PathBuf::from("a.png"), PathBuf::from("b.png")]
        );
        assert!(mailbox.take().is_none());
        mailbox.give_back(got);
        let mut next = Pose::default();
        mailbox.publish(&mut next);
        assert_eq!(
            next.time, 2.0,
            "the spare is reused as the next back buffer"
        );
        assert!(next.screenshots.is_empty());
    }
}
