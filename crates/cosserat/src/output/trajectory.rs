//! In-memory trajectory: the recorded frames of every rod.

use super::error::{OutputError, ShapeError};

/// One rod's recorded frames, stored frame-major as plain arrays.
///
/// For `T` recorded frames and `n_elements = n`, `points` holds `T * (n + 1)`
/// centreline points (frame 0's `n + 1` points, then frame 1's, …) and
/// `directors` holds `T * n` vectors: the first director `d1` of each element
/// (the material frame's first axis, perpendicular to the tangent in an
/// unsheared rod). The optional per-point and per-element quantities
/// (`velocities`, `contact_forces`, `strains`) are either recorded for every
/// frame or empty: the first frame decides.
#[derive(Debug, Clone, PartialEq)]
pub struct RodTrajectory {
    /// Human-readable name (e.g. `"guidewire"`); written to the `.npz` as
    /// `rod_names`.
    pub name: String,
    /// Cross-section radius, used for rendering tubes.
    pub radius: f64,
    /// Centreline points of every frame, `T * (n_elements + 1)` of them.
    pub points: Vec<[f64; 3]>,
    /// First director `d1` of every element of every frame, `T * n_elements`.
    pub directors: Vec<[f64; 3]>,
    /// Number of elements (segments) `n`; the rod has `n + 1` points.
    pub n_elements: usize,
    /// Point velocities [m/s], `T * (n + 1)`, or empty when not recorded.
    pub velocities: Vec<[f64; 3]>,
    /// Normal force of the wall on each point [N] (zero where it touches
    /// nothing), `T * (n + 1)`, or empty when not recorded (a run without an
    /// environment, or a backend that does not report contacts).
    pub contact_forces: Vec<f64>,
    /// Axial strain `l / l0 - 1` of each element, `T * n`, or empty when not
    /// recorded.
    pub strains: Vec<f64>,
}

impl RodTrajectory {
    /// An empty record (no frames) of a rod with `n_elements` elements.
    pub fn new(name: impl Into<String>, radius: f64, n_elements: usize) -> Self {
        Self {
            name: name.into(),
            radius,
            points: Vec::new(),
            directors: Vec::new(),
            n_elements,
            velocities: Vec::new(),
            contact_forces: Vec::new(),
            strains: Vec::new(),
        }
    }

    /// Number of points per frame, `n_elements + 1`.
    pub fn n_points(&self) -> usize {
        self.n_elements + 1
    }

    /// Number of complete frames held in `points`.
    pub fn n_frames(&self) -> usize {
        self.points.len() / self.n_points()
    }

    /// Centreline points of frame `frame`, or `None` if it is not recorded.
    pub fn frame_points(&self, frame: usize) -> Option<&[[f64; 3]]> {
        let n = self.n_points();
        self.points.get(frame * n..(frame + 1) * n)
    }

    /// Element directors `d1` of frame `frame`, or `None` if not recorded.
    pub fn frame_directors(&self, frame: usize) -> Option<&[[f64; 3]]> {
        let n = self.n_elements;
        self.directors.get(frame * n..(frame + 1) * n)
    }

    /// Point velocities of frame `frame`, or `None` if not recorded.
    pub fn frame_velocities(&self, frame: usize) -> Option<&[[f64; 3]]> {
        let n = self.n_points();
        self.velocities.get(frame * n..(frame + 1) * n)
    }

    /// Contact forces on the points of frame `frame`, or `None` if not
    /// recorded.
    pub fn frame_contact_forces(&self, frame: usize) -> Option<&[f64]> {
        let n = self.n_points();
        self.contact_forces.get(frame * n..(frame + 1) * n)
    }

    /// Element strains of frame `frame`, or `None` if not recorded.
    pub fn frame_strains(&self, frame: usize) -> Option<&[f64]> {
        let n = self.n_elements;
        self.strains.get(frame * n..(frame + 1) * n)
    }

    /// Checks this rod (index `rod` in its trajectory) holds exactly
    /// `frames` frames.
    pub(crate) fn check(&self, rod: usize, frames: usize) -> Result<(), ShapeError> {
        if self.n_elements == 0 {
            return Err(ShapeError::NoElements {
                rod,
                name: self.name.clone(),
            });
        }
        check_len(
            self,
            rod,
            "points",
            frames * self.n_points(),
            self.points.len(),
        )?;
        check_len(
            self,
            rod,
            "directors",
            frames * self.n_elements,
            self.directors.len(),
        )?;
        let optional = [
            ("velocities", self.velocities.len(), self.n_points()),
            ("contact_forces", self.contact_forces.len(), self.n_points()),
            ("strains", self.strains.len(), self.n_elements),
        ];
        for (what, found, per_frame) in optional {
            if found != 0 {
                check_len(self, rod, what, frames * per_frame, found)?;
            }
        }
        Ok(())
    }
}

fn check_len(
    r: &RodTrajectory,
    rod: usize,
    what: &'static str,
    expected: usize,
    found: usize,
) -> Result<(), ShapeError> {
    if expected == found {
        Ok(())
    } else {
        Err(ShapeError::Length {
            rod,
            name: r.name.clone(),
            what,
            expected,
            found,
        })
    }
}

/// The state of one rod at one output time, borrowed from the simulation;
/// the argument of [`Trajectory::push_frame`]. The optional quantities are
/// empty slices when not recorded (`..Default::default()`).
#[derive(Debug, Clone, Copy, Default)]
pub struct RodFrame<'a> {
    /// The `n + 1` centreline points.
    pub points: &'a [[f64; 3]],
    /// The first director `d1` of each of the `n` elements.
    pub directors: &'a [[f64; 3]],
    /// The `n + 1` point velocities [m/s], or empty.
    pub velocities: &'a [[f64; 3]],
    /// The normal force of the wall on each of the `n + 1` points [N], or
    /// empty.
    pub contact_forces: &'a [f64],
    /// The strain `l / l0 - 1` of each of the `n` elements, or empty.
    pub strains: &'a [f64],
}

/// A triangle mesh written beside the rods: the environment the rods
/// collide with, as the simulation sees it (normals pointing into the lumen).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EnvironmentMesh {
    /// Vertex positions [m].
    pub vertices: Vec<[f64; 3]>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
}

impl EnvironmentMesh {
    /// Checks every index names a vertex and every coordinate is finite.
    pub(crate) fn check(&self) -> Result<(), ShapeError> {
        let n = self.vertices.len();
        if let Some((t, &tri)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
        {
            return Err(ShapeError::MeshIndex {
                triangle: t,
                indices: tri,
                vertices: n,
            });
        }
        for (v, p) in self.vertices.iter().enumerate() {
            if let Some(&x) = p.iter().find(|x| !x.is_finite()) {
                return Err(ShapeError::NonFinite {
                    frame: 0,
                    what: format!("environment vertex {v}"),
                    value: x,
                });
            }
        }
        Ok(())
    }
}

/// The steps after which a run of `steps` steps records `frames` frames
/// besides its initial state (step 0, listed first), evenly: frame `k` at
/// step `round(k * steps / frames)`, so the last frame is the run's end and
/// no interval is more than one step longer than another. With more frames
/// than steps, every step is a frame.
pub fn frame_steps(steps: u64, frames: u64) -> Vec<u64> {
    let frames = frames.clamp(1, steps.max(1));
    let (s, f) = (u128::from(steps), u128::from(frames));
    (0..=f).map(|k| ((k * s + f / 2) / f) as u64).collect()
}

/// Recorded frames of a set of rods at common output times, and the
/// environment they move in.
///
/// Build it with [`Trajectory::new`] and [`Trajectory::add_rod`], record with
/// [`Trajectory::push_frame`], then hand it to [`write_npz`](super::write_npz)
/// or [`write_vtp_series`](super::write_vtp_series). The fields are public so
/// that a trajectory can also be assembled directly; the writers check it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// Time of each recorded frame (`T` entries).
    pub times: Vec<f64>,
    /// The rods, in the order given to [`Trajectory::add_rod`].
    pub rods: Vec<RodTrajectory>,
    /// The static mesh the rods collide with, if any.
    pub environment: Option<EnvironmentMesh>,
}

impl Trajectory {
    /// An empty trajectory with no rods and no frames.
    pub fn new() -> Self {
        Self::default()
    }

    /// Declares a rod of `n_elements` elements (so `n_elements + 1` points)
    /// and returns its index, which is also its position in the slice given
    /// to [`push_frame`](Self::push_frame) and its `{i}` in the `.npz` array
    /// names. All rods must be added before the first frame is recorded.
    pub fn add_rod(
        &mut self,
        name: impl Into<String>,
        radius: f64,
        n_elements: usize,
    ) -> Result<usize, OutputError> {
        let name = name.into();
        if !self.times.is_empty() {
            return Err(OutputError::Record(ShapeError::FramesAlreadyRecorded {
                name,
                frames: self.times.len(),
            }));
        }
        if n_elements == 0 {
            return Err(OutputError::Record(ShapeError::NoElements {
                rod: self.rods.len(),
                name,
            }));
        }
        self.rods.push(RodTrajectory::new(name, radius, n_elements));
        Ok(self.rods.len() - 1)
    }

    /// Records one output frame at `time`: `rods[i]` is the state of rod `i`.
    ///
    /// Every rod must be given, with exactly `n_i + 1` points and `n_i`
    /// directors; otherwise an [`OutputError::Record`] is returned and the
    /// trajectory is left unchanged.
    pub fn push_frame(&mut self, time: f64, rods: &[RodFrame<'_>]) -> Result<(), OutputError> {
        if rods.len() != self.rods.len() {
            return Err(OutputError::Record(ShapeError::RodCount {
                expected: self.rods.len(),
                found: rods.len(),
            }));
        }
        let first = self.times.is_empty();
        for (i, (rod, frame)) in self.rods.iter().zip(rods).enumerate() {
            check_len(rod, i, "points", rod.n_points(), frame.points.len())
                .and_then(|()| {
                    check_len(rod, i, "directors", rod.n_elements, frame.directors.len())
                })
                .map_err(OutputError::Record)?;
            // An optional quantity is recorded in every frame or in none; the
            // first frame decides.
            let optional = [
                (
                    "velocities",
                    rod.velocities.is_empty(),
                    frame.velocities.len(),
                    rod.n_points(),
                ),
                (
                    "contact_forces",
                    rod.contact_forces.is_empty(),
                    frame.contact_forces.len(),
                    rod.n_points(),
                ),
                (
                    "strains",
                    rod.strains.is_empty(),
                    frame.strains.len(),
                    rod.n_elements,
                ),
            ];
            for (what, absent, found, per_frame) in optional {
                let expected = if (first && found == 0) || (!first && absent) {
                    0
                } else {
                    per_frame
                };
                check_len(rod, i, what, expected, found).map_err(OutputError::Record)?;
            }
        }
        for (rod, frame) in self.rods.iter_mut().zip(rods) {
            rod.points.extend_from_slice(frame.points);
            rod.directors.extend_from_slice(frame.directors);
            rod.velocities.extend_from_slice(frame.velocities);
            rod.contact_forces.extend_from_slice(frame.contact_forces);
            rod.strains.extend_from_slice(frame.strains);
        }
        self.times.push(time);
        Ok(())
    }

    /// Number of recorded frames `T`.
    pub fn n_frames(&self) -> usize {
        self.times.len()
    }

    /// Checks that every rod holds exactly one frame per entry of `times`
    /// and has at least one element.
    pub fn validate(&self) -> Result<(), ShapeError> {
        let frames = self.times.len();
        self.rods
            .iter()
            .enumerate()
            .try_for_each(|(i, rod)| rod.check(i, frames))?;
        self.environment
            .as_ref()
            .map_or(Ok(()), EnvironmentMesh::check)
    }
}
