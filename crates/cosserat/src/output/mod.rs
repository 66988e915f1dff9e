//! Trajectory writers: record rod shapes while a simulation runs, then save
//! them in formats that standard tools open directly.
//!
//! A simulation produces far more states than anyone wants to look at; what a
//! user keeps is a *trajectory*: the centreline points and the material frame
//! of every rod at a handful of output times. This module holds that data
//! ([`Trajectory`], one [`RodTrajectory`] per rod) as plain `f64` arrays, with
//! no dependency on the simulation types, and writes it in two forms:
//!
//! * [`write_npz`] — one NumPy `.npz` archive for analysis in Python:
//!   `d = numpy.load("trajectory.npz")`, then `d["times"]`, `d["rod0"]`
//!   (shape `(T, n+1, 3)`), `d["rod0_directors"]` (shape `(T, n, 3)`), ready
//!   for matplotlib plots of tip paths, curvature, energy post-processing or
//!   comparison against a reference solution. Values are stored bit-exact
//!   (little-endian float64), so tests and regression checks can compare them.
//! * [`write_vtp_series`] — a binary (zlib-compressed) VTK XML PolyData file
//!   per frame, the environment mesh as `environment.vtp`, and a
//!   `trajectory.pvd` index, for ParaView (or VisIt, PyVista): open the `.pvd`,
//!   press play, apply a *Tube* filter with radius from the `radius` array to
//!   see the guidewire or catheter as a solid, colour by `contact_force`,
//!   `velocity` or `strain`, and *Cell Centers* + *Glyph* (oriented by `d1`)
//!   to see how the material frame twists.
//!
//! [`read_npz`] reads an archive back (the `cosserat render` command draws
//! a run from it), and [`frame_steps`] says at which steps a run of `N`
//! steps records its frames.
//!
//! Recording is a matter of [`Trajectory::add_rod`] once per rod and
//! [`Trajectory::push_frame`] once per output frame:
//!
//! ```
//! use cosserat::output::{RodFrame, Trajectory, write_npz, write_vtp_series};
//! # fn main() -> Result<(), cosserat::output::OutputError> {
//! let mut traj = Trajectory::new();
//! let wire = traj.add_rod("guidewire", 0.0004, 2)?;
//! for step in 0..3 {
//!     let t = step as f64 * 0.01;
//!     let points = [[0.0, 0.0, 0.0], [0.1, 0.0, t], [0.2, 0.0, 2.0 * t]];
//!     let d1 = [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
//!     traj.push_frame(t, &[RodFrame { points: &points, directors: &d1, ..Default::default() }])?;
//! }
//! assert_eq!(traj.rods[wire].n_frames(), 3);
//! let dir = std::env::temp_dir().join("cosserat-output-doctest");
//! write_vtp_series(&dir, &traj)?; // creates `dir`
//! write_npz(&dir.join("trajectory.npz"), &traj)?;
//! assert_eq!(cosserat::output::read_npz(&dir.join("trajectory.npz"))?, traj);
//! # std::fs::remove_dir_all(&dir).ok();
//! # Ok(())
//! # }
//! ```
//!
//! Bad shapes (a frame with the wrong number of points, a rod whose arrays
//! disagree with its element count) are reported as [`OutputError`], never
//! as a panic; [`Trajectory::push_frame`] checks everything before it changes
//! anything, so a rejected frame leaves the trajectory as it was.

mod error;
mod npz;
mod trajectory;
mod vtk;

#[cfg(test)]
mod tests;

pub use error::{OutputError, ShapeError};
pub use npz::{read_npz, write_npz};
pub use trajectory::{EnvironmentMesh, RodFrame, RodTrajectory, Trajectory, frame_steps};
pub use vtk::{
    ENVIRONMENT_FILE_NAME, PVD_FILE_NAME, VtpSeries, vtp_frame_file_name, write_environment_vtp,
    write_vtp_series,
};
