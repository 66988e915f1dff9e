//! The gamepad: the held end steered by a pad's sticks and buttons, as by the keys.
//!
//! On Linux the pad is read through the kernel's evdev interface (`/dev/input/event*`, the
//! pure-Rust `evdev` crate: no libudev, nothing to install to build). At start the viewer takes
//! the first device that reports a left stick (`ABS_X`, `ABS_Y`) and the gamepad's south button
//! (`BTN_SOUTH`, also called `BTN_GAMEPAD`); devices it cannot open (permission denied is
//! normal for a user outside the `input` group) are passed over. A reader thread blocks on the
//! device and turns its events into [`PadAction`]s through a [`Mapper`], a pure function of the
//! device's axis ranges and the events, which is what the tests check; the window applies them
//! as it applies keys. There is no hot-plug: a pad plugged in later is not seen, and one
//! unplugged ends the reader (its push and twist go back to zero) while the viewer goes on.
//! Elsewhere than Linux there is no gamepad input.
//!
//! | pad | what |
//! |---|---|
//! | left stick, up / down | push in / pull back, up to `--push-speed` at full deflection |
//! | right stick, right / left | twist, up to `--twist-rate` (positive to the right) |
//! | right / left trigger | twist positive / negative (pads whose right stick is `ABS_RX`) |
//! | d-pad | as the arrow keys: full push (up / down) or twist (right / left) |
//! | South (A, ✕) | pause / go on |
//! | East (B, ○) | pause and take one step |
//! | Start, Select | reset |
//! | Mode (the logo button) | quit |
//!
//! Stick and trigger deflections are measured from the device's own range (`absinfo` minimum
//! and maximum) and have a dead zone of [`DEAD_ZONE`] of full deflection, or the device's `flat`
//! where that is larger; beyond the dead zone the speed grows linearly from zero to the full
//! speed.

// Elsewhere than Linux nothing reads a pad, so the mapping is used by its tests alone.
#![cfg_attr(not(target_os = "linux"), allow(dead_code))]

/// Dead zone of a stick or trigger, as a fraction of its full deflection (the device's own
/// `flat` where larger, up to [`MAX_DEAD_ZONE`]).
pub(crate) const DEAD_ZONE: f64 = 0.1;
/// The largest dead zone taken from a device's `flat`.
const MAX_DEAD_ZONE: f64 = 0.5;

/// Event types and codes of `linux/input-event-codes.h` (the same numbers on every platform,
/// so that the mapping is tested everywhere; checked against `evdev`'s on Linux).
pub(crate) mod code {
    pub(crate) const EV_KEY: u16 = 0x01;
    pub(crate) const EV_ABS: u16 = 0x03;
    /// The left stick's horizontal axis (unused: it does nothing).
    #[cfg(test)]
    pub(crate) const ABS_X: u16 = 0x00;
    pub(crate) const ABS_Y: u16 = 0x01;
    pub(crate) const ABS_Z: u16 = 0x02;
    pub(crate) const ABS_RX: u16 = 0x03;
    /// The right stick's vertical axis (unused: it does nothing).
    #[cfg(test)]
    pub(crate) const ABS_RY: u16 = 0x04;
    pub(crate) const ABS_RZ: u16 = 0x05;
    pub(crate) const ABS_HAT0X: u16 = 0x10;
    pub(crate) const ABS_HAT0Y: u16 = 0x11;
    pub(crate) const BTN_SOUTH: u16 = 0x130;
    pub(crate) const BTN_EAST: u16 = 0x131;
    pub(crate) const BTN_SELECT: u16 = 0x13a;
    pub(crate) const BTN_START: u16 = 0x13b;
    pub(crate) const BTN_MODE: u16 = 0x13c;
    pub(crate) const BTN_DPAD_UP: u16 = 0x220;
    pub(crate) const BTN_DPAD_DOWN: u16 = 0x221;
    pub(crate) const BTN_DPAD_LEFT: u16 = 0x222;
    pub(crate) const BTN_DPAD_RIGHT: u16 = 0x223;
}

/// What the pad asks the viewer for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum PadAction {
    /// The pad's push speed [m/s] and twist rate [rad/s] (sticks, triggers and d-pad
    /// together), added to the keys' and the mouse's.
    Steer { push: f64, twist: f64 },
    /// Pause, or go on (as space).
    TogglePause,
    /// Pause and take one step (as N).
    Step,
    /// Back to the initial state (as R).
    Reset,
    /// Close the viewer (as Q).
    Quit,
}

/// One absolute axis as the device describes it (`input_absinfo`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct AxisInfo {
    pub(crate) code: u16,
    pub(crate) min: i32,
    pub(crate) max: i32,
    /// Values this close to the centre are reported as the centre by the device's driver.
    pub(crate) flat: i32,
    /// The axis' value when the pad was opened.
    pub(crate) value: i32,
}

impl AxisInfo {
    /// A stick's deflection in −1..=1 (the sign of the raw value's offset from the centre of
    /// its range): zero inside the dead zone, then linear to ±1 at either end of the range.
    fn stick(&self, value: i32) -> f64 {
        let (min, max) = (f64::from(self.min), f64::from(self.max));
        let half = 0.5 * (max - min);
        if !(half > 0.0) {
            return 0.0;
        }
        let x = ((f64::from(value) - 0.5 * (min + max)) / half).clamp(-1.0, 1.0);
        let dead = DEAD_ZONE
            .max(f64::from(self.flat) / half)
            .min(MAX_DEAD_ZONE);
        x.signum() * ((x.abs() - dead) / (1.0 - dead)).max(0.0)
    }

    /// A trigger's pull in 0..=1: zero at the range's minimum (released) and through the dead
    /// zone above it, one at the maximum.
    fn trigger(&self, value: i32) -> f64 {
        let (min, max) = (f64::from(self.min), f64::from(self.max));
        let travel = max - min;
        if !(travel > 0.0) {
            return 0.0;
        }
        let x = ((f64::from(value) - min) / travel).clamp(0.0, 1.0);
        let dead = DEAD_ZONE
            .max(f64::from(self.flat) / travel)
            .min(MAX_DEAD_ZONE);
        ((x - dead) / (1.0 - dead)).max(0.0)
    }
}

/// What an axis drives.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Target {
    Push,
    Twist,
}

/// An axis the mapper reads: its range, what it drives, with which sign, and its deflection now.
#[derive(Clone, Copy, Debug)]
struct Axis {
    info: AxisInfo,
    trigger: bool,
    target: Target,
    sign: f64,
    now: f64,
}

impl Axis {
    fn deflection(&self, value: i32) -> f64 {
        self.sign
            * if self.trigger {
                self.info.trigger(value)
            } else {
                self.info.stick(value)
            }
    }
}

/// Turns a pad's raw events into [`PadAction`]s: pure, so that the mapping is tested without
/// a device.
#[derive(Clone, Debug)]
pub(crate) struct Mapper {
    axes: Vec<Axis>,
    /// D-pad buttons held (pads that report the d-pad as buttons, not as a hat).
    dpad: [bool; 4],
    push_speed: f64,
    twist_rate: f64,
    /// The last push and twist reported, so that only changes are.
    last: (f64, f64),
}

impl Mapper {
    /// A mapper for a pad with these absolute axes; full deflection asks for `push_speed`
    /// [m/s] or `twist_rate` [rad/s].
    ///
    /// The left stick's vertical axis (`ABS_Y`) and the hat's (`ABS_HAT0Y`) push, up (negative
    /// values, evdev's convention) pushing in. The right stick's horizontal axis twists: it is
    /// `ABS_RX` where the pad has one (Xbox and PlayStation pads), and then `ABS_Z` and
    /// `ABS_RZ` are the left and right triggers; without `ABS_RX` (generic HID pads, whose
    /// right stick is `ABS_Z`, `ABS_RZ`) `ABS_Z` twists. The hat's horizontal axis twists too.
    pub(crate) fn new(axes: &[AxisInfo], push_speed: f64, twist_rate: f64) -> Self {
        let has_rx = axes.iter().any(|a| a.code == code::ABS_RX);
        let role = |c: u16| -> Option<(bool, Target, f64)> {
            Some(match c {
                code::ABS_Y | code::ABS_HAT0Y => (false, Target::Push, -1.0),
                code::ABS_HAT0X => (false, Target::Twist, 1.0),
                code::ABS_RX => (false, Target::Twist, 1.0),
                code::ABS_Z if has_rx => (true, Target::Twist, -1.0),
                code::ABS_RZ if has_rx => (true, Target::Twist, 1.0),
                code::ABS_Z => (false, Target::Twist, 1.0),
                _ => return None,
            })
        };
        let axes = axes
            .iter()
            .filter_map(|&info| {
                let (trigger, target, sign) = role(info.code)?;
                let mut axis = Axis {
                    info,
                    trigger,
                    target,
                    sign,
                    now: 0.0,
                };
                axis.now = axis.deflection(info.value);
                Some(axis)
            })
            .collect();
        Self {
            axes,
            dpad: [false; 4],
            push_speed,
            twist_rate,
            last: (0.0, 0.0),
        }
    }

    /// The action one raw event (type, code, value) asks for, if any: a button's press (not
    /// its release or auto-repeat), or new push and twist speeds when a stick, trigger or
    /// d-pad moved enough to change them.
    pub(crate) fn event(&mut self, kind: u16, code: u16, value: i32) -> Option<PadAction> {
        match kind {
            code::EV_ABS => {
                let axis = self.axes.iter_mut().find(|a| a.info.code == code)?;
                axis.now = axis.deflection(value);
                self.steer()
            }
            code::EV_KEY => {
                let dpad = match code {
                    code::BTN_DPAD_UP => Some(0),
                    code::BTN_DPAD_DOWN => Some(1),
                    code::BTN_DPAD_LEFT => Some(2),
                    code::BTN_DPAD_RIGHT => Some(3),
                    _ => None,
                };
                if let Some(i) = dpad {
                    // Auto-repeat (2) keeps it held.
                    self.dpad[i] = value != 0;
                    return self.steer();
                }
                if value != 1 {
                    return None;
                }
                match code {
                    code::BTN_SOUTH => Some(PadAction::TogglePause),
                    code::BTN_EAST => Some(PadAction::Step),
                    code::BTN_START | code::BTN_SELECT => Some(PadAction::Reset),
                    code::BTN_MODE => Some(PadAction::Quit),
                    _ => None,
                }
            }
            _ => None,
        }
    }

    /// Push and twist from every axis and the d-pad, if they changed since last reported.
    fn steer(&mut self) -> Option<PadAction> {
        let held = |i: usize| f64::from(u8::from(self.dpad[i]));
        let mut push = held(0) - held(1);
        let mut twist = held(3) - held(2);
        for a in &self.axes {
            match a.target {
                Target::Push => push += a.now,
                Target::Twist => twist += a.now,
            }
        }
        let now = (
            push.clamp(-1.0, 1.0) * self.push_speed,
            twist.clamp(-1.0, 1.0) * self.twist_rate,
        );
        if now == self.last {
            return None;
        }
        self.last = now;
        Some(PadAction::Steer {
            push: now.0,
            twist: now.1,
        })
    }
}

/// The reader's loop: fetches the pad's raw events (type, code, value; `fetch` blocks until
/// some come) and sends the actions they map to, until `send` returns false (the viewer has
/// closed: `None`) or `fetch` fails (the pad was unplugged: the error, after a last `Steer` of
/// zero so that the hand does not go on at the last speed the pad asked for). An interrupted
/// read is tried again.
#[cfg(any(target_os = "linux", test))]
fn pump(
    mut fetch: impl FnMut() -> std::io::Result<Vec<(u16, u16, i32)>>,
    mapper: &mut Mapper,
    send: &impl Fn(PadAction) -> bool,
) -> Option<std::io::Error> {
    loop {
        match fetch() {
            Ok(events) => {
                for (kind, code, value) in events {
                    if let Some(action) = mapper.event(kind, code, value)
                        && !send(action)
                    {
                        return None;
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                send(PadAction::Steer {
                    push: 0.0,
                    twist: 0.0,
                });
                return Some(e);
            }
        }
    }
}

#[cfg(target_os = "linux")]
pub(crate) use linux::find;

#[cfg(not(target_os = "linux"))]
pub(crate) use elsewhere::find;

/// Finding the pad and reading it: evdev.
#[cfg(target_os = "linux")]
mod linux {
    use std::os::unix::fs::FileTypeExt;
    use std::path::{Path, PathBuf};

    use evdev::{AbsoluteAxisCode, Device, KeyCode};

    use super::{AxisInfo, Mapper, PadAction, pump};

    /// Where the kernel's input devices are.
    const INPUT_DIR: &str = "/dev/input";

    /// A gamepad found and opened.
    pub(crate) struct Pad {
        path: PathBuf,
        name: String,
        axes: Vec<AxisInfo>,
        device: Device,
    }

    /// What a look through an input directory found.
    pub(crate) struct Discovery {
        /// The first gamepad, by device number.
        pub(crate) pad: Option<Pad>,
        /// Why the directory could not be read (it does not exist in most containers).
        pub(crate) unreadable: Option<String>,
        /// Character devices named `event*`.
        pub(crate) devices: usize,
        /// Those that could not be opened as evdev devices, with why (the first one's).
        pub(crate) refused: usize,
        pub(crate) first_refusal: Option<String>,
    }

    /// Looks for a gamepad under `/dev/input` and says on stderr, once, which one the viewer
    /// reads or that there is none.
    pub(crate) fn find() -> Option<Pad> {
        let found = discover(Path::new(INPUT_DIR));
        match &found.pad {
            Some(pad) => eprintln!(
                "gamepad: {} ({}): left stick pushes, right stick or triggers twist, South pauses, East steps, Start/Select resets, Mode quits",
                pad.name,
                pad.path.display()
            ),
            None => {
                let why = match (&found.unreadable, found.devices, &found.first_refusal) {
                    (Some(e), _, _) => format!("{INPUT_DIR}: {e}"),
                    (None, 0, _) => format!("no input devices under {INPUT_DIR}"),
                    (None, n, Some(e)) => format!(
                        "{n} input devices, {} of them could not be opened: {e}",
                        found.refused
                    ),
                    (None, n, None) => format!("none of {n} input devices is one"),
                };
                eprintln!("gamepad: none found ({why}); keys and mouse steer");
            }
        }
        found.pad
    }

    /// The first gamepad among the `event*` devices of `dir`; a directory that does not exist
    /// or cannot be read holds none, and devices that cannot be opened are passed over.
    pub(crate) fn discover(dir: &Path) -> Discovery {
        let mut found = Discovery {
            pad: None,
            unreadable: None,
            devices: 0,
            refused: 0,
            first_refusal: None,
        };
        let entries = match std::fs::read_dir(dir) {
            Ok(entries) => entries,
            Err(e) => {
                found.unreadable = Some(e.to_string());
                return found;
            }
        };
        let mut nodes: Vec<(u32, PathBuf)> = entries
            .filter_map(Result::ok)
            .filter_map(|e| {
                let number = e
                    .file_name()
                    .to_str()?
                    .strip_prefix("event")?
                    .parse()
                    .ok()?;
                Some((number, e.path()))
            })
            // Character devices only: opening anything else (a FIFO) could block.
            .filter(|(_, p)| std::fs::metadata(p).is_ok_and(|m| m.file_type().is_char_device()))
            .collect();
        nodes.sort();
        found.devices = nodes.len();
        for (_, path) in nodes {
            match open(&path) {
                Ok(Some(pad)) => {
                    found.pad = Some(pad);
                    break;
                }
                Ok(None) => {}
                Err(e) => {
                    found.refused += 1;
                    found.first_refusal.get_or_insert_with(|| e.to_string());
                }
            }
        }
        found
    }

    /// Opens `path`; `None` when the device is not a gamepad.
    pub(crate) fn open(path: &Path) -> std::io::Result<Option<Pad>> {
        let device = Device::open(path)?;
        let has_key = |k: KeyCode| device.supported_keys().is_some_and(|s| s.contains(k));
        let has_axis = |a: AbsoluteAxisCode| {
            device
                .supported_absolute_axes()
                .is_some_and(|s| s.contains(a))
        };
        if !(has_key(KeyCode::BTN_SOUTH)
            && has_axis(AbsoluteAxisCode::ABS_X)
            && has_axis(AbsoluteAxisCode::ABS_Y))
        {
            return Ok(None);
        }
        let axes = device
            .get_absinfo()?
            .map(|(axis, info)| AxisInfo {
                code: axis.0,
                min: info.minimum(),
                max: info.maximum(),
                flat: info.flat(),
                value: info.value(),
            })
            .collect();
        let name = device.name().unwrap_or("unnamed gamepad").to_string();
        Ok(Some(Pad {
            path: path.to_path_buf(),
            name,
            axes,
            device,
        }))
    }

    impl Pad {
        /// The pad's name as its driver gives it.
        pub(crate) fn name(&self) -> &str {
            &self.name
        }

        /// Reads the pad on a thread of its own until it is unplugged (or fails) or `send`
        /// returns false (the viewer has closed); each action (full deflection asking for
        /// `push_speed` and `twist_rate`, see [`Mapper`]) is handed to `send`. When the
        /// pad stops being read, a last `Steer` of zero is sent, so that the hand does not go on
        /// at the last speed asked. The thread blocks in the kernel between events, so it is
        /// not joined: it ends with the process.
        pub(crate) fn spawn(
            self,
            push_speed: f64,
            twist_rate: f64,
            send: impl Fn(PadAction) -> bool + Send + 'static,
        ) -> std::io::Result<()> {
            let mut mapper = Mapper::new(&self.axes, push_speed, twist_rate);
            let Pad {
                name, mut device, ..
            } = self;
            std::thread::Builder::new()
                .name("gamepad".into())
                .spawn(move || {
                    let fetch = || {
                        let events = device.fetch_events()?;
                        Ok(events
                            .map(|e| (e.event_type().0, e.code(), e.value()))
                            .collect())
                    };
                    if let Some(e) = pump(fetch, &mut mapper, &send) {
                        eprintln!("gamepad: {name}: {e}; it is no longer read");
                    }
                })
                .map(drop)
        }
    }

    #[cfg(test)]
    mod tests {
        use super::super::code;
        use super::*;
        use evdev::EventType;

        /// The codes the mapper matches are the kernel's.
        #[test]
        fn the_codes_are_evdevs() {
            assert_eq!(code::EV_KEY, EventType::KEY.0);
            assert_eq!(code::EV_ABS, EventType::ABSOLUTE.0);
            for (mine, theirs) in [
                (code::ABS_X, AbsoluteAxisCode::ABS_X),
                (code::ABS_Y, AbsoluteAxisCode::ABS_Y),
                (code::ABS_Z, AbsoluteAxisCode::ABS_Z),
                (code::ABS_RX, AbsoluteAxisCode::ABS_RX),
                (code::ABS_RY, AbsoluteAxisCode::ABS_RY),
                (code::ABS_RZ, AbsoluteAxisCode::ABS_RZ),
                (code::ABS_HAT0X, AbsoluteAxisCode::ABS_HAT0X),
                (code::ABS_HAT0Y, AbsoluteAxisCode::ABS_HAT0Y),
            ] {
                assert_eq!(mine, theirs.0, "{theirs:?}");
            }
            for (mine, theirs) in [
                (code::BTN_SOUTH, KeyCode::BTN_SOUTH),
                (code::BTN_EAST, KeyCode::BTN_EAST),
                (code::BTN_SELECT, KeyCode::BTN_SELECT),
                (code::BTN_START, KeyCode::BTN_START),
                (code::BTN_MODE, KeyCode::BTN_MODE),
                (code::BTN_DPAD_UP, KeyCode::BTN_DPAD_UP),
                (code::BTN_DPAD_DOWN, KeyCode::BTN_DPAD_DOWN),
                (code::BTN_DPAD_LEFT, KeyCode::BTN_DPAD_LEFT),
                (code::BTN_DPAD_RIGHT, KeyCode::BTN_DPAD_RIGHT),
            ] {
                assert_eq!(mine, theirs.0, "{theirs:?}");
            }
        }

        /// No `/dev/input` (containers, CI): no pad, and no error.
        #[test]
        fn discovery_without_an_input_directory_finds_nothing() {
            let found = discover(Path::new("/nonexistent/cosserat/dev/input"));
            assert!(found.pad.is_none());
            assert!(found.unreadable.is_some());
            assert_eq!((found.devices, found.refused), (0, 0));
        }

        /// Entries that are not evdev devices are passed over: a character device that is not
        /// one (`/dev/null`, opened but refusing evdev's requests), a plain file, other names.
        #[test]
        fn discovery_passes_over_what_is_not_a_pad() {
            let dir = std::env::temp_dir().join(format!("cosserat-pad-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            std::os::unix::fs::symlink("/dev/null", dir.join("event3")).unwrap();
            std::fs::write(dir.join("event0"), b"not a device").unwrap();
            std::os::unix::fs::symlink("/dev/null", dir.join("mouse0")).unwrap();
            std::os::unix::fs::symlink("/dev/null", dir.join("eventx")).unwrap();
            let found = discover(&dir);
            std::fs::remove_dir_all(&dir).unwrap();
            assert!(found.pad.is_none());
            assert!(found.unreadable.is_none());
            assert_eq!(
                found.devices, 1,
                "only event3 is a character device named event<N>"
            );
            assert_eq!(found.refused, 1);
            assert!(found.first_refusal.is_some());
        }

        /// Whatever this machine has under `/dev/input`, looking does not fail or hang.
        #[test]
        fn discovery_on_this_machine_returns() {
            let found = discover(Path::new(INPUT_DIR));
            assert!(found.refused <= found.devices);
        }

        /// A virtual pad made through `/dev/uinput`, read back through `open` and the reader
        /// thread: needs write access to `/dev/uinput` (root, or the `uinput` group), which CI
        /// and most containers lack, so it is ignored by default; run it with
        /// `cargo test --bin cosserat uinput -- --ignored`.
        #[test]
        #[ignore = "needs write access to /dev/uinput"]
        fn a_virtual_pad_through_uinput() {
            use evdev::uinput::VirtualDevice;
            use evdev::{AbsInfo, AttributeSet, InputEvent, UinputAbsSetup};
            let mut keys = AttributeSet::<KeyCode>::new();
            keys.insert(KeyCode::BTN_SOUTH);
            keys.insert(KeyCode::BTN_START);
            let stick = AbsInfo::new(0, -32768, 32767, 16, 128, 0);
            let mut builder = VirtualDevice::builder()
                .unwrap()
                .name("cosserat test pad")
                .with_keys(&keys)
                .unwrap();
            for axis in [AbsoluteAxisCode::ABS_X, AbsoluteAxisCode::ABS_Y] {
                builder = builder
                    .with_absolute_axis(&UinputAbsSetup::new(axis, stick))
                    .unwrap();
            }
            let mut virtual_pad = builder.build().unwrap();
            let path = virtual_pad
                .enumerate_dev_nodes_blocking()
                .unwrap()
                .find_map(Result::ok)
                .expect("the virtual pad's device node");
            // udev may take a moment to give the node its permissions.
            std::thread::sleep(std::time::Duration::from_millis(200));
            let pad = open(&path).unwrap().expect("the virtual pad is a pad");
            assert_eq!(pad.name(), "cosserat test pad");
            let (tx, rx) = std::sync::mpsc::channel();
            pad.spawn(0.05, 6.0, move |a| tx.send(a).is_ok()).unwrap();
            let abs = EventType::ABSOLUTE.0;
            virtual_pad
                .emit(&[InputEvent::new(abs, code::ABS_Y, -32768)])
                .unwrap();
            virtual_pad
                .emit(&[InputEvent::new(EventType::KEY.0, code::BTN_SOUTH, 1)])
                .unwrap();
            let wait = std::time::Duration::from_secs(2);
            assert_eq!(
                rx.recv_timeout(wait).unwrap(),
                PadAction::Steer {
                    push: 0.05,
                    twist: 0.0
                }
            );
            assert_eq!(rx.recv_timeout(wait).unwrap(), PadAction::TogglePause);
            // Unplugged: the reader stops the hand and ends.
            drop(virtual_pad);
            assert_eq!(
                rx.recv_timeout(wait).unwrap(),
                PadAction::Steer {
                    push: 0.0,
                    twist: 0.0
                }
            );
        }
    }
}

/// Elsewhere than Linux: no gamepad input.
#[cfg(not(target_os = "linux"))]
mod elsewhere {
    use super::PadAction;

    /// No pad can be found here.
    pub(crate) enum Pad {}

    /// Says so on stderr.
    pub(crate) fn find() -> Option<Pad> {
        eprintln!("gamepad: not read on this platform (Linux evdev only); keys and mouse steer");
        None
    }

    impl Pad {
        pub(crate) fn name(&self) -> &str {
            match *self {}
        }
        pub(crate) fn spawn(
            self,
            _: f64,
            _: f64,
            _: impl Fn(PadAction) -> bool + Send + 'static,
        ) -> std::io::Result<()> {
            match self {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::code::*;
    use super::*;

    const PUSH: f64 = 0.05;
    const TWIST: f64 = 6.0;

    fn axis(code: u16, min: i32, max: i32, flat: i32) -> AxisInfo {
        let value = if matches!(code, ABS_Z | ABS_RZ) && min == 0 {
            min
        } else {
            (min + max) / 2
        };
        AxisInfo {
            code,
            min,
            max,
            flat,
            value,
        }
    }

    /// An Xbox-like pad (xpad): sticks ±32767, triggers 0–1023, a hat.
    fn xbox() -> Mapper {
        let stick = |c| axis(c, -32768, 32767, 128);
        Mapper::new(
            &[
                stick(ABS_X),
                stick(ABS_Y),
                stick(ABS_RX),
                stick(ABS_RY),
                axis(ABS_Z, 0, 1023, 0),
                axis(ABS_RZ, 0, 1023, 0),
                axis(ABS_HAT0X, -1, 1, 0),
                axis(ABS_HAT0Y, -1, 1, 0),
            ],
            PUSH,
            TWIST,
        )
    }

    fn steer(push: f64, twist: f64) -> Option<PadAction> {
        Some(PadAction::Steer { push, twist })
    }

    /// `a` steers at `push` and `twist`, within 10⁻⁴ of the full speeds (a ±32767 range's
    /// centre is −0.5).
    fn close(a: Option<PadAction>, push: f64, twist: f64) {
        match a {
            Some(PadAction::Steer { push: p, twist: t }) => assert!(
                (p - push).abs() < 1e-4 * PUSH && (t - twist).abs() < 1e-4 * TWIST,
                "({p}, {t}) != ({push}, {twist})"
            ),
            other => panic!("{other:?} != Steer ({push}, {twist})"),
        }
    }

    /// The left stick up pushes in at the full speed (evdev's Y grows downwards), down pulls
    /// back, the centre stops; in between the speed is proportional beyond the dead zone.
    #[test]
    fn the_left_stick_pushes_up_to_the_push_speed() {
        let mut m = xbox();
        assert_eq!(m.event(EV_ABS, ABS_Y, -32768), steer(PUSH, 0.0));
        assert_eq!(m.event(EV_ABS, ABS_Y, 32767), steer(-PUSH, 0.0));
        assert_eq!(m.event(EV_ABS, ABS_Y, 0), steer(0.0, 0.0));
        // Half way up: (0.5 − 0.1) / 0.9 of the speed.
        close(m.event(EV_ABS, ABS_Y, -16384), PUSH * 0.4 / 0.9, 0.0);
        // The same value again changes nothing.
        assert_eq!(m.event(EV_ABS, ABS_Y, -16384), None);
        // The horizontal axis of the left stick does nothing.
        assert_eq!(m.event(EV_ABS, ABS_X, 32767), None);
    }

    /// Inside the dead zone (10 % of full deflection) the stick reads as centred, on either
    /// side; just beyond it the speed starts from zero.
    #[test]
    fn the_dead_zone_is_zero() {
        let mut m = xbox();
        assert_eq!(m.event(EV_ABS, ABS_Y, 3000), None, "never moved");
        assert_eq!(m.event(EV_ABS, ABS_Y, -3000), None);
        m.event(EV_ABS, ABS_Y, 32767);
        assert_eq!(m.event(EV_ABS, ABS_Y, -3200), steer(0.0, 0.0));
        let a = m.event(EV_ABS, ABS_Y, -3600);
        let Some(PadAction::Steer { push, .. }) = a else {
            panic!("{a:?}");
        };
        // (3600 / 32767.5 − 0.1) / 0.9 = 0.011 of the speed.
        assert!(push > 0.0 && push < 0.02 * PUSH, "{push}");
    }

    /// A device whose `flat` is larger than 10 % has that dead zone; a 0–255 stick is centred
    /// at 127.5.
    #[test]
    fn the_devices_flat_widens_the_dead_zone() {
        let mut m = Mapper::new(
            &[axis(ABS_X, 0, 255, 15), axis(ABS_Y, 0, 255, 38)],
            PUSH,
            TWIST,
        );
        // 38 / 127.5 = 0.298 of full deflection.
        assert_eq!(m.event(EV_ABS, ABS_Y, 127 - 35), None);
        assert_eq!(m.event(EV_ABS, ABS_Y, 128), None);
        assert_eq!(m.event(EV_ABS, ABS_Y, 0), steer(PUSH, 0.0));
        assert_eq!(m.event(EV_ABS, ABS_Y, 255), steer(-PUSH, 0.0));
        // A device claiming a flat of its whole range keeps a dead zone of half of it.
        let mut m = Mapper::new(&[axis(ABS_Y, -100, 100, 100)], PUSH, TWIST);
        assert_eq!(m.event(EV_ABS, ABS_Y, -49), None);
        close(m.event(EV_ABS, ABS_Y, -75), PUSH * 0.5, 0.0);
    }

    /// The right stick twists, positive to the right; the triggers twist too (right positive)
    /// and add to the stick, up to the full rate.
    #[test]
    fn the_right_stick_and_the_triggers_twist() {
        let mut m = xbox();
        assert_eq!(m.event(EV_ABS, ABS_RX, 32767), steer(0.0, TWIST));
        assert_eq!(m.event(EV_ABS, ABS_RX, -32768), steer(0.0, -TWIST));
        assert_eq!(m.event(EV_ABS, ABS_RX, 0), steer(0.0, 0.0));
        assert_eq!(
            m.event(EV_ABS, ABS_RY, 32767),
            None,
            "vertical does nothing"
        );
        assert_eq!(m.event(EV_ABS, ABS_RZ, 1023), steer(0.0, TWIST));
        assert_eq!(m.event(EV_ABS, ABS_Z, 1023), steer(0.0, 0.0), "both cancel");
        assert_eq!(m.event(EV_ABS, ABS_RZ, 0), steer(0.0, -TWIST));
        assert_eq!(m.event(EV_ABS, ABS_Z, 50), steer(0.0, 0.0), "released");
        // Stick and trigger together stay at the full rate.
        m.event(EV_ABS, ABS_RX, 32767);
        assert_eq!(m.event(EV_ABS, ABS_RZ, 1023), None);
        // Push and twist at once.
        close(m.event(EV_ABS, ABS_Y, -32768), PUSH, TWIST);
    }

    /// A generic HID pad (right stick on `ABS_Z`, `ABS_RZ`, no `ABS_RX`): `ABS_Z` is the right
    /// stick's horizontal axis, centred, not a trigger.
    #[test]
    fn a_generic_pads_right_stick_is_abs_z() {
        let mut m = Mapper::new(
            &[
                axis(ABS_X, 0, 255, 0),
                axis(ABS_Y, 0, 255, 0),
                AxisInfo {
                    value: 128,
                    ..axis(ABS_Z, 0, 255, 0)
                },
                AxisInfo {
                    value: 128,
                    ..axis(ABS_RZ, 0, 255, 0)
                },
            ],
            PUSH,
            TWIST,
        );
        assert_eq!(m.event(EV_ABS, ABS_Z, 130), None, "centred");
        assert_eq!(m.event(EV_ABS, ABS_Z, 255), steer(0.0, TWIST));
        assert_eq!(m.event(EV_ABS, ABS_Z, 0), steer(0.0, -TWIST));
        assert_eq!(m.event(EV_ABS, ABS_RZ, 0), None, "vertical does nothing");
    }

    /// The d-pad, as a hat or as buttons, acts as the arrow keys.
    #[test]
    fn the_dpad_is_the_arrow_keys() {
        let mut m = xbox();
        assert_eq!(m.event(EV_ABS, ABS_HAT0Y, -1), steer(PUSH, 0.0));
        assert_eq!(m.event(EV_ABS, ABS_HAT0X, -1), steer(PUSH, -TWIST));
        assert_eq!(m.event(EV_ABS, ABS_HAT0Y, 0), steer(0.0, -TWIST));
        assert_eq!(m.event(EV_ABS, ABS_HAT0X, 0), steer(0.0, 0.0));
        assert_eq!(m.event(EV_KEY, BTN_DPAD_DOWN, 1), steer(-PUSH, 0.0));
        assert_eq!(m.event(EV_KEY, BTN_DPAD_DOWN, 2), None, "auto-repeat holds");
        assert_eq!(m.event(EV_KEY, BTN_DPAD_RIGHT, 1), steer(-PUSH, TWIST));
        assert_eq!(m.event(EV_KEY, BTN_DPAD_DOWN, 0), steer(0.0, TWIST));
        assert_eq!(m.event(EV_KEY, BTN_DPAD_RIGHT, 0), steer(0.0, 0.0));
    }

    /// Buttons act when pressed, not when released or repeated.
    #[test]
    fn buttons_act_on_press() {
        let mut m = xbox();
        for (button, action) in [
            (BTN_SOUTH, PadAction::TogglePause),
            (BTN_EAST, PadAction::Step),
            (BTN_START, PadAction::Reset),
            (BTN_SELECT, PadAction::Reset),
            (BTN_MODE, PadAction::Quit),
        ] {
            assert_eq!(m.event(EV_KEY, button, 1), Some(action), "{button:#x}");
            assert_eq!(m.event(EV_KEY, button, 2), None, "{button:#x} repeated");
            assert_eq!(m.event(EV_KEY, button, 0), None, "{button:#x} released");
        }
        // Other buttons (North), other event types (EV_SYN, EV_MSC) and axes the pad did not
        // report do nothing.
        assert_eq!(m.event(EV_KEY, 0x133, 1), None);
        assert_eq!(m.event(0x00, 0, 0), None);
        assert_eq!(m.event(0x04, 4, 90001), None);
        assert_eq!(Mapper::new(&[], PUSH, TWIST).event(EV_ABS, ABS_Y, 0), None);
    }

    /// A pad unplugged mid-run: the reader sends what came before, then stops the hand and
    /// ends with the error (the viewer goes on); an interrupted read is retried.
    #[test]
    fn an_unplugged_pad_stops_the_hand_and_ends_the_reader() {
        use std::io::{Error, ErrorKind};
        let mut reads: Vec<std::io::Result<Vec<(u16, u16, i32)>>> = vec![
            Ok(vec![(EV_ABS, ABS_Y, -32768), (0, 0, 0)]),
            Err(Error::from(ErrorKind::Interrupted)),
            Ok(vec![(EV_KEY, BTN_SOUTH, 1), (EV_KEY, BTN_SOUTH, 0)]),
            // What a read of an unplugged evdev device gives.
            Err(Error::from_raw_os_error(19)),
            Ok(vec![(EV_KEY, BTN_MODE, 1)]),
        ];
        reads.reverse();
        let sent = std::cell::RefCell::new(Vec::new());
        let ended = pump(
            || reads.pop().expect("no read after the error"),
            &mut xbox(),
            &|a| {
                sent.borrow_mut().push(a);
                true
            },
        );
        assert_eq!(ended.and_then(|e| e.raw_os_error()), Some(19));
        assert_eq!(
            sent.into_inner(),
            [
                PadAction::Steer {
                    push: PUSH,
                    twist: 0.0
                },
                PadAction::TogglePause,
                PadAction::Steer {
                    push: 0.0,
                    twist: 0.0
                },
            ]
        );
        assert_eq!(reads.len(), 1, "the read after the error is not made");
    }

    /// Once the viewer has closed (the event loop refuses actions) the reader ends.
    #[test]
    fn the_reader_ends_when_the_viewer_has_closed() {
        let mut reads = 0;
        let ended = pump(
            || {
                reads += 1;
                Ok(vec![(EV_KEY, BTN_EAST, 1), (EV_KEY, BTN_EAST, 0)])
            },
            &mut xbox(),
            &|_| false,
        );
        assert!(ended.is_none());
        assert_eq!(reads, 1);
    }

    /// A stick held when the pad was opened counts from its first event on, together with the
    /// axis that moved; a degenerate range (min = max) reads zero.
    #[test]
    fn the_state_at_opening_counts() {
        let mut m = Mapper::new(
            &[
                AxisInfo {
                    value: -32768,
                    ..axis(ABS_Y, -32768, 32767, 0)
                },
                axis(ABS_RX, 5, 5, 0),
            ],
            PUSH,
            TWIST,
        );
        assert_eq!(m.event(EV_ABS, ABS_RX, 5), steer(PUSH, 0.0));
        assert_eq!(m.event(EV_ABS, ABS_RX, 1000), None);
    }
}
