//! `--script FILE`: a hand's input written down, so that the viewer can be driven without
//! anybody at the keyboard (tests under Xvfb, demos, measurements).
//!
//! One action per line, at a simulated time, in the order they happen:
//! ```text
//! # time [s]  action       value
//! 0.0         push         0.05     # push speed along the held end's axis [m/s] (negative pulls)
//! 0.2         push         0
//! 0.2         twist        3.0      # rate of twist about the axis [rad/s]
//! 0.3         pause        0.5      # stop the physics for 0.5 s of wall time, then go on
//! 0.4         screenshot   out.png  # save the next frame drawn
//! 0.4         reset                 # back to the initial state
//! 0.5         quit
//! ```
//! Actions at the same time are taken in the order written; those after a `pause` are taken
//! when it ends. Times are simulated seconds, not wall-clock ones: a machine that cannot keep up with real
//! time replays the same motion, only slower, so a script gives the same hand motion
//! everywhere. A line that cannot be read is refused with the file, line number and value.

use std::path::{Path, PathBuf};

/// What a script line does.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Action {
    /// Push speed along the held end's axis [m/s] from now on (negative pulls).
    Push(f64),
    /// Twist rate about the held end's axis [rad/s] from now on.
    Twist(f64),
    /// Stop the physics for this many wall-clock seconds.
    Pause(f64),
    /// Save the next frame drawn into this PNG file.
    Screenshot(PathBuf),
    /// Back to the state the viewer started with.
    Reset,
    /// Close the viewer.
    Quit,
}

/// One line of a script: an action at a simulated time.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Timed {
    /// Simulated time [s] at which the action is taken.
    pub(crate) at: f64,
    /// What is done.
    pub(crate) action: Action,
}

/// Reads the script at `path`.
pub(crate) fn load(path: &Path) -> Result<Vec<Timed>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("--script {}: cannot read it: {e}", path.display()))?;
    parse(path, &text)
}

/// Parses a script's text; `path` names it in messages.
pub(crate) fn parse(path: &Path, text: &str) -> Result<Vec<Timed>, String> {
    let mut actions: Vec<Timed> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let at_line = |why: String| format!("{}:{}: {why}", path.display(), i + 1);
        let mut words = line.split_whitespace();
        let (Some(time), Some(verb)) = (words.next(), words.next()) else {
            return Err(at_line(format!(
                "`{line}`: expected TIME ACTION [VALUE], e.g. `0.2 push 0.05`"
            )));
        };
        let at: f64 = time
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite() && *t >= 0.0)
            .ok_or_else(|| {
                at_line(format!(
                    "time `{time}` is invalid: expected simulated seconds ≥ 0"
                ))
            })?;
        if let Some(before) = actions.last()
            && at < before.at
        {
            return Err(at_line(format!(
                "time {at} comes before the previous line's {}: actions must be in time order",
                before.at
            )));
        }
        let value = words.next();
        if let Some(extra) = words.next() {
            return Err(at_line(format!(
                "`{extra}` after `{verb}`: expected one value at most"
            )));
        }
        let number = |what: &str, positive: bool| -> Result<f64, String> {
            let v = value.ok_or_else(|| at_line(format!("`{verb}` needs a value: {what}")))?;
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && (!positive || *x >= 0.0))
                .ok_or_else(|| at_line(format!("{verb} `{v}` is invalid: expected {what}")))
        };
        let none = |action: Action| match value {
            Some(v) => Err(at_line(format!("`{verb}` takes no value, found `{v}`"))),
            None => Ok(action),
        };
        let action = match verb {
            "push" => Action::Push(number("a speed in m/s (negative pulls)", false)?),
            "twist" => Action::Twist(number("a rate in rad/s", false)?),
            "pause" => Action::Pause(number("wall-clock seconds ≥ 0", true)?),
            "screenshot" => Action::Screenshot(PathBuf::from(
                value.ok_or_else(|| at_line("`screenshot` needs a PNG file to write".into()))?,
            )),
            "reset" => none(Action::Reset)?,
            "quit" => none(Action::Quit)?,
            other => {
                return Err(at_line(format!(
                    "unknown action `{other}`: expected push, twist, pause, screenshot, reset or quit"
                )));
            }
        };
        actions.push(Timed { at, action });
    }
    Ok(actions)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_script_reads_in_order_with_comments() {
        let text = "# a hand\n0 push 0.05\n0.2 push 0 # stop\n\n0.2 twist -3\n0.3 pause 0.5\n0.4 screenshot a.png\n0.45 reset\n0.5 quit\n";
        let s = parse(Path::new("s.txt"), text).unwrap();
        assert_eq!(s.len(), 7);
        assert_eq!(s[0].action, Action::Push(0.05));
        assert_eq!(s[2].action, Action::Twist(-3.0));
        assert_eq!(s[4].action, Action::Screenshot("a.png".into()));
        assert_eq!(
            s[6],
            Timed {
                at: 0.5,
                action: Action::Quit
            }
        );
    }

    #[test]
    fn bad_lines_name_file_line_and_value() {
        for (text, line, value) in [
            ("0 push fast", ":1:", "fast"),
            ("0 push 1\nsoon quit", ":2:", "soon"),
            ("0 jump 3", ":1:", "jump"),
            ("0.5 quit\n0.2 push 1", ":2:", "0.2"),
            ("0 pause -1", ":1:", "-1"),
            ("0 quit now", ":1:", "now"),
            ("0", ":1:", "`0`"),
            ("0 push 1 2", ":1:", "2"),
            ("0 screenshot", ":1:", "screenshot"),
        ] {
            let e = parse(Path::new("hand.txt"), text).unwrap_err();
            assert!(
                e.starts_with("hand.txt") && e.contains(line) && e.contains(value),
                "{e}"
            );
        }
    }
}
