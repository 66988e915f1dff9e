//! The [`Stepper`] trait: one interface to every way of stepping rods, with the runtime control
//! a haptic loop, a learning agent, a script or a viewer needs.
//!
//! A stepper owns its rods and its [`Clock`]. Between calls to [`Stepper::advance`] a caller
//! may change any end's condition or motion, replace loads, read the state into its own
//! buffers (nothing is allocated per call), write state, and take or restore a [`Snapshot`].
//! Values cross the trait in `f64` whatever precision the stepper runs in; the conversion is
//! the only cost the trait adds, and it is paid per point read or written, not per step.
//!
//! Why a trait object: the facade picks the stepper at run time (a scene file says which
//! scheme, precision and backend), and every method here is called at most once per tick, so
//! dynamic dispatch costs nothing measurable while it keeps the facade free of per-backend
//! code.

use std::any::Any;
use std::fmt;

use cosserat_model::energy::Energies;

use crate::capabilities::{Capabilities, Capability};
use crate::clock::Clock;
use crate::divergence::Divergence;
use crate::ends::{EndCondition, EndPath};
use crate::report::{CollisionStats, CouplingStats, EndReaction, StiffSummary};
use crate::settings::PointLoad;

/// What a stepper is, for reports and errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepperInfo {
    /// Its name in reports ("cpu explicit", "cpu stiff", "gpu explicit", …).
    pub name: &'static str,
    /// Whether it computes in `f64`.
    pub double_precision: bool,
}

/// A per-point or per-element vector quantity of a rod's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StateField {
    /// Centreline points [m], `n + 1` per rod.
    Positions,
    /// Point velocities [m/s], `n + 1` per rod.
    Velocities,
    /// Angular velocities of the frames in body coordinates [rad/s], `n` per rod.
    AngularVelocities,
    /// Director `d1`, `d2` or `d3` (`Director(0..3)`) of each frame, world coordinates, `n` per
    /// rod (read only; write frames with [`Stepper::write_frames`]).
    Director(usize),
}

impl StateField {
    /// Entries per rod of `elements` elements.
    pub fn len(self, elements: usize) -> usize {
        match self {
            StateField::Positions | StateField::Velocities => elements + 1,
            StateField::AngularVelocities | StateField::Director(_) => elements,
        }
    }

    /// How the field is named in errors.
    pub fn name(self) -> &'static str {
        match self {
            StateField::Positions => "positions",
            StateField::Velocities => "velocities",
            StateField::AngularVelocities => "angular velocities",
            StateField::Director(0) => "directors d1",
            StateField::Director(1) => "directors d2",
            StateField::Director(2) => "directors d3",
            StateField::Director(_) => "directors",
        }
    }
}

/// One contact of a rod point with the environment at the last step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactSample {
    /// Index of the point.
    pub point: usize,
    /// Unit normal of the wall at the contact, pointing into the lumen.
    pub normal: [f64; 3],
    /// Force the wall applied to the point over the last step [N] (normal and friction).
    pub force: [f64; 3],
}

/// A stepper's complete state at one tick, to come back to with [`Stepper::restore`]:
/// restoring and taking `N` steps gives the same state, bit for bit, as the `N` steps that
/// followed the snapshot.
pub struct Snapshot {
    stepper: &'static str,
    clock: Clock,
    data: Box<dyn Any + Send + Sync>,
}

impl Snapshot {
    /// Wraps a stepper's own state (its type is checked on restore).
    pub fn new(stepper: &'static str, clock: Clock, data: Box<dyn Any + Send + Sync>) -> Self {
        Self {
            stepper,
            clock,
            data,
        }
    }

    /// The clock when it was taken.
    pub fn clock(&self) -> Clock {
        self.clock
    }

    /// The stepper that took it.
    pub fn stepper(&self) -> &'static str {
        self.stepper
    }

    /// The stepper's own state, if it is of type `S`.
    pub fn data<S: 'static>(&self) -> Option<&S> {
        self.data.downcast_ref()
    }
}

impl fmt::Debug for Snapshot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Snapshot")
            .field("stepper", &self.stepper)
            .field("clock", &self.clock)
            .finish_non_exhaustive()
    }
}

/// Why a batch of steps failed.
#[derive(Debug)]
pub enum StepError {
    /// A rod diverged.
    Diverged(Divergence),
    /// The backend failed for a reason of its own (a GPU device error, a timeout).
    Backend(String),
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepError::Diverged(d) => d.fmt(f),
            StepError::Backend(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for StepError {}

impl From<Divergence> for StepError {
    fn from(d: Divergence) -> Self {
        StepError::Diverged(d)
    }
}

impl StepError {
    /// The divergence, if that is what happened.
    pub fn divergence(&self) -> Option<&Divergence> {
        match self {
            StepError::Diverged(d) => Some(d),
            StepError::Backend(_) => None,
        }
    }
}

/// A control call that was refused; nothing was changed.
#[derive(Clone, Debug, PartialEq)]
pub enum ControlError {
    /// No rod with this index.
    NoRod {
        /// The index asked for.
        rod: usize,
        /// How many rods there are.
        rods: usize,
    },
    /// An end other than 0 (first point) or 1 (last point).
    NoEnd {
        /// The end asked for.
        end: usize,
    },
    /// A point the rod does not have.
    NoPoint {
        /// Index of the rod.
        rod: usize,
        /// The point asked for.
        point: usize,
        /// Its last point.
        last: usize,
    },
    /// A buffer of the wrong length.
    Length {
        /// What was read or written.
        field: &'static str,
        /// Entries the rod has.
        expected: usize,
        /// Entries given.
        got: usize,
    },
    /// A value that is not finite, or out of its range.
    Value {
        /// What was given.
        field: &'static str,
        /// Why it is refused.
        why: String,
    },
    /// The stepper cannot do this.
    Unsupported {
        /// The stepper.
        stepper: &'static str,
        /// What it lacks.
        what: String,
    },
    /// A snapshot taken by another stepper, or of other rods.
    Snapshot(String),
}

impl fmt::Display for ControlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ControlError::NoRod { rod, rods } => {
                write!(f, "no rod {rod}: the simulation has rods 0..{rods}")
            }
            ControlError::NoEnd { end } => {
                write!(
                    f,
                    "no end {end}: ends are 0 (first point) and 1 (last point)"
                )
            }
            ControlError::NoPoint { rod, point, last } => {
                write!(f, "rod {rod} has points 0..={last}, not {point}")
            }
            ControlError::Length {
                field,
                expected,
                got,
            } => write!(f, "{field}: expected {expected} entries, got {got}"),
            ControlError::Value { field, why } => write!(f, "{field}: {why}"),
            ControlError::Unsupported { stepper, what } => {
                write!(f, "the {stepper} stepper cannot {what}")
            }
            ControlError::Snapshot(why) => write!(f, "cannot restore the snapshot: {why}"),
        }
    }
}

impl std::error::Error for ControlError {}

/// Every way of stepping rods: the explicit scheme, coupled rods, the stiff scheme, bound stiff
/// rods, the GPU.
///
/// Rods are numbered in the order they were given; ends are 0 (first point) and 1 (last
/// point). Between calls to [`advance`](Self::advance) every other method may be called in any
/// order; none of them allocates unless stated.
pub trait Stepper: Send {
    /// Name and precision.
    fn info(&self) -> StepperInfo;

    /// What it can do.
    fn capabilities(&self) -> Capabilities;

    /// Where it is in time.
    fn clock(&self) -> Clock;

    /// Takes `steps` steps of the clock's `dt`. Returns the largest `|l/l0 − 1|` of any segment
    /// over the batch (or at its end, for steppers that check strain on the device). On a
    /// divergence the state is the diverged one and the clock stands at the step that diverged.
    fn advance(&mut self, steps: u64) -> Result<f64, StepError>;

    /// Number of rods.
    fn rod_count(&self) -> usize;

    /// Elements of rod `rod` (it has one more point).
    fn elements(&self, rod: usize) -> Result<usize, ControlError>;

    /// Copies a field of rod `rod` into `out`, whose length must be
    /// [`StateField::len`]`(elements)`.
    fn read(&self, rod: usize, field: StateField, out: &mut [[f64; 3]])
    -> Result<(), ControlError>;

    /// Copies the frames of rod `rod` into `out` as unit quaternions `[w, x, y, z]` (body to
    /// world), one per element.
    fn read_frames(&self, rod: usize, out: &mut [[f64; 4]]) -> Result<(), ControlError>;

    /// Overwrites positions, velocities or angular velocities of rod `rod` (directors are
    /// written as frames). Positions of held end points move the holder with them.
    fn write(
        &mut self,
        rod: usize,
        field: StateField,
        values: &[[f64; 3]],
    ) -> Result<(), ControlError>;

    /// Overwrites the frames of rod `rod` (`[w, x, y, z]`, normalised here). The clamp of a
    /// clamped end closes on the written end frame (its node at rest).
    fn write_frames(&mut self, rod: usize, values: &[[f64; 4]]) -> Result<(), ControlError>;

    /// The condition at end `end` of rod `rod`.
    fn end_condition(&self, rod: usize, end: usize) -> Result<EndCondition<f64>, ControlError>;

    /// Replaces the condition at end `end` of rod `rod` from the next step on: a new motion
    /// (push or pull speed, rotation rate, a timed move), or a change between free, pinned and
    /// clamped. A held end starts its motion from where it is.
    fn set_end_condition(
        &mut self,
        rod: usize,
        end: usize,
        condition: EndCondition<f64>,
    ) -> Result<(), ControlError>;

    /// Replaces the external point loads of rod `rod` (an empty slice removes them).
    fn set_loads(&mut self, rod: usize, loads: &[PointLoad<f64>]) -> Result<(), ControlError>;

    /// The filtered reaction at a held end after the last step: the force and torque the holder
    /// applies to the rod. `None` for a free end, and from steppers without
    /// [`Capability::Reactions`](crate::Capability::Reactions).
    fn end_reaction(&self, rod: usize, end: usize) -> Option<EndReaction>;

    /// The largest filtered reaction force at any held end so far [N]; `None` when no end is
    /// held or reactions are not computed.
    fn max_reaction_force(&self) -> Option<f64>;

    /// Replaces `out` with the contacts of rod `rod` at the last step (empty without mesh
    /// contact; allocates only while `out` grows).
    fn contacts(&self, rod: usize, out: &mut Vec<ContactSample>) -> Result<(), ControlError>;

    /// Contact measurements of rod `rod` since the start; `None` without mesh contact.
    fn collision_stats(&self, rod: usize) -> Option<CollisionStats>;

    /// Measurements of bindings and rod contacts; `None` when the rods do not interact.
    fn coupling_stats(&self) -> Option<CouplingStats>;

    /// What the stiff solver did so far; `None` for other schemes.
    fn stiff_summary(&self) -> Option<StiffSummary>;

    /// Energies of the current state, all rods together.
    fn energies(&self) -> Energies;

    /// The first point moving faster than `limit` [m/s], or frame whose surface (at the rod's
    /// radius) spins faster: an explicit step past its stable limit pumps energy into a rod
    /// while its segment lengths still hold.
    fn check_speed(&self, limit: f64) -> Result<(), Divergence>;

    /// The complete state, for [`restore`](Self::restore).
    fn snapshot(&mut self) -> Result<Snapshot, StepError>;

    /// Returns to a snapshot this stepper took.
    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), ControlError>;

    /// Makes analytic obstacle `shape` (the `shape`-th of the rods' shapes, in the order they
    /// were given) follow `path` from where it is now, the path's displacement and rotation
    /// taken from that pose; `None` holds it where it is now. A stepper without moving
    /// obstacles refuses.
    fn set_obstacle_path(
        &mut self,
        shape: usize,
        path: Option<EndPath>,
    ) -> Result<(), ControlError> {
        let _ = (shape, path);
        Err(ControlError::Unsupported {
            stepper: self.info().name,
            what: "move obstacles".into(),
        })
    }
}

/// Checks a rod index against a count.
pub fn check_rod(rod: usize, rods: usize) -> Result<(), ControlError> {
    if rod < rods {
        Ok(())
    } else {
        Err(ControlError::NoRod { rod, rods })
    }
}

/// Checks an end index.
pub fn check_end(end: usize) -> Result<(), ControlError> {
    if end <= 1 {
        Ok(())
    } else {
        Err(ControlError::NoEnd { end })
    }
}

/// Checks a buffer's length against a field of a rod of `elements` elements.
pub fn check_len(field: StateField, elements: usize, got: usize) -> Result<(), ControlError> {
    let expected = field.len(elements);
    if got == expected {
        Ok(())
    } else {
        Err(ControlError::Length {
            field: field.name(),
            expected,
            got,
        })
    }
}

/// Checks that every value is finite.
pub fn check_finite<const N: usize>(
    field: &'static str,
    values: &[[f64; N]],
) -> Result<(), ControlError> {
    match values.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
        None => Ok(()),
        Some(i) => Err(ControlError::Value {
            field,
            why: format!("entry {i} is not finite"),
        }),
    }
}

/// `Ok` when `has` covers `needs`; else [`ControlError::Unsupported`] for `stepper`, saying
/// `"{doing} {what is missing}"` ("drive an end with sliding ends (…)").
pub fn check_capabilities(
    stepper: &'static str,
    has: Capabilities,
    needs: Capabilities,
    doing: &str,
) -> Result<(), ControlError> {
    let missing = has.missing(needs);
    if missing.is_empty() {
        return Ok(());
    }
    let list: Vec<&str> = missing.iter().map(|c| c.describe()).collect();
    Err(ControlError::Unsupported {
        stepper,
        what: format!("{doing} {}", list.join(", ")),
    })
}

/// Checks loads given to [`Stepper::set_loads`] for rod `rod` of `last + 1` points: points that
/// exist, finite forces and moments, and what their profiles and moments need among `has`.
pub fn check_loads(
    stepper: &'static str,
    has: Capabilities,
    rod: usize,
    last: usize,
    loads: &[PointLoad<f64>],
) -> Result<(), ControlError> {
    if let Some(l) = loads.iter().find(|l| l.point > last) {
        return Err(ControlError::NoPoint {
            rod,
            point: l.point,
            last,
        });
    }
    if loads
        .iter()
        .any(|l| !l.force.iter().chain(l.moment.iter()).all(|x| x.is_finite()))
    {
        return Err(ControlError::Value {
            field: "load",
            why: "forces and moments must be finite".into(),
        });
    }
    check_capabilities(stepper, has, PointLoad::needs(loads), "set")
}

/// The capabilities an end condition needs beyond holding and constant motions.
pub fn condition_needs(condition: &EndCondition<f64>) -> Capabilities {
    Capabilities::NONE
        .with_if(Capability::EndPaths, condition.path.is_some())
        .with_if(Capability::SlidingEnds, condition.slide_axis().is_some())
        .with_if(Capability::HingedEnds, condition.hinge_axis().is_some())
}

/// Checks an end condition's motion: finite velocities and a start no later than its end; a
/// finite slide axis on a held end. (A path checks itself when it is made.)
pub fn check_condition(condition: &EndCondition<f64>) -> Result<(), ControlError> {
    if let Some(a) = condition.slide {
        if !a.iter().all(|x| x.is_finite()) {
            return Err(ControlError::Value {
                field: "end slide axis",
                why: format!("{:?} is not finite", [a.x, a.y, a.z]),
            });
        }
        if !condition.holds_point() {
            return Err(ControlError::Value {
                field: "end slide axis",
                why: "a free end has no point to slide: hold it (pinned or clamped)".into(),
            });
        }
    }
    if let Some(a) = condition.hinge {
        if !a.iter().all(|x| x.is_finite()) {
            return Err(ControlError::Value {
                field: "end hinge axis",
                why: format!("{:?} is not finite", [a.x, a.y, a.z]),
            });
        }
        if !condition.holds_frame() {
            return Err(ControlError::Value {
                field: "end hinge axis",
                why: "only a clamped end has a frame to turn about a hinge".into(),
            });
        }
    }
    if let Some(m) = condition.motion {
        let finite = m
            .velocity
            .iter()
            .chain(m.angular_velocity.iter())
            .all(|x| x.is_finite());
        if !finite {
            return Err(ControlError::Value {
                field: "end motion",
                why: "velocity and angular velocity must be finite".into(),
            });
        }
        if m.start_time.is_nan() || m.end_time.is_nan() || m.start_time > m.end_time {
            return Err(ControlError::Value {
                field: "end motion",
                why: format!(
                    "start time {} s must not be after end time {} s",
                    m.start_time, m.end_time
                ),
            });
        }
    }
    Ok(())
}

/// Copies a field of `state` into `out` (checked against its length): the read every stepper
/// that keeps a [`RodState`](cosserat_model::RodState) on the host answers with.
pub fn read_state_field<T: cosserat_model::Real>(
    state: &cosserat_model::RodState<T>,
    field: StateField,
    out: &mut [[f64; 3]],
) -> Result<(), ControlError> {
    use cosserat_model::quat::directors;
    check_len(field, state.elements(), out.len())?;
    let f = |v: &cosserat_model::Vec3<T>| [v.x.to_f64(), v.y.to_f64(), v.z.to_f64()];
    match field {
        StateField::Positions => state.positions.iter().zip(out).for_each(|(v, o)| *o = f(v)),
        StateField::Velocities => state
            .velocities
            .iter()
            .zip(out)
            .for_each(|(v, o)| *o = f(v)),
        StateField::AngularVelocities => state
            .angular_velocities
            .iter()
            .zip(out)
            .for_each(|(v, o)| *o = f(v)),
        StateField::Director(k) if k < 3 => state
            .frames
            .iter()
            .zip(out)
            .for_each(|(q, o)| *o = f(&directors(q)[k])),
        StateField::Director(k) => {
            return Err(ControlError::Value {
                field: "director",
                why: format!("director {k} does not exist: they are 0 (d1), 1 (d2), 2 (d3)"),
            });
        }
    }
    Ok(())
}

/// Copies the frames of `state` into `out` as `[w, x, y, z]` (checked against its length).
pub fn read_state_frames<T: cosserat_model::Real>(
    state: &cosserat_model::RodState<T>,
    out: &mut [[f64; 4]],
) -> Result<(), ControlError> {
    if out.len() != state.elements() {
        return Err(ControlError::Length {
            field: "frames",
            expected: state.elements(),
            got: out.len(),
        });
    }
    for (q, o) in state.frames.iter().zip(out) {
        *o = [q.w.to_f64(), q.i.to_f64(), q.j.to_f64(), q.k.to_f64()];
    }
    Ok(())
}

/// Checks values to write into a field of a rod of `elements` elements: the length, finite
/// values, and a field that can be written (directors are written as frames).
pub fn check_write(
    field: StateField,
    elements: usize,
    values: &[[f64; 3]],
) -> Result<(), ControlError> {
    if let StateField::Director(_) = field {
        return Err(ControlError::Value {
            field: "directors",
            why: "directors are written as frames (write_frames)".into(),
        });
    }
    check_len(field, elements, values.len())?;
    check_finite(field.name(), values)
}

/// Checks frames to write into a rod of `elements` elements and returns them as unit
/// quaternions `[w, x, y, z]`: one per element, finite, none zero.
pub fn unit_frames(
    elements: usize,
    values: &[[f64; 4]],
) -> Result<impl Iterator<Item = [f64; 4]> + '_, ControlError> {
    if values.len() != elements {
        return Err(ControlError::Length {
            field: "frames",
            expected: elements,
            got: values.len(),
        });
    }
    check_finite("frames", values)?;
    if let Some(i) = values
        .iter()
        .position(|q| q.iter().map(|x| x * x).sum::<f64>() < 1e-12)
    {
        return Err(ControlError::Value {
            field: "frames",
            why: format!("frame {i} is zero, not a rotation"),
        });
    }
    Ok(values.iter().map(|q| {
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        q.map(|x| x / n)
    }))
}
