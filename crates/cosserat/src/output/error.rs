//! Errors of the trajectory writers.

use std::path::PathBuf;

/// What is inconsistent about a trajectory or a frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ShapeError {
    /// A frame listed a different number of rods than the trajectory has.
    #[error("the trajectory has {expected} rods but the frame gives {found}")]
    RodCount {
        /// Rods in the trajectory.
        expected: usize,
        /// Rods in the frame.
        found: usize,
    },
    /// An array of one rod has the wrong length.
    #[error("rod {rod} (`{name}`): {what} has {found} entries, expected {expected}")]
    Length {
        /// Index of the rod in [`Trajectory::rods`](super::Trajectory::rods).
        rod: usize,
        /// Name of the rod.
        name: String,
        /// Which array: `"points"` or `"directors"`.
        what: &'static str,
        /// Entries the element count and frame count call for.
        expected: usize,
        /// Entries present.
        found: usize,
    },
    /// A rod was declared with zero elements; a rod has at least one.
    #[error("rod {rod} (`{name}`) has no elements")]
    NoElements {
        /// Index of the rod.
        rod: usize,
        /// Name of the rod.
        name: String,
    },
    /// A rod was added after frames had been recorded, so its earlier frames
    /// would be missing.
    #[error("cannot add rod `{name}`: {frames} frames are already recorded")]
    FramesAlreadyRecorded {
        /// Name of the rod that was to be added.
        name: String,
        /// Frames recorded so far.
        frames: usize,
    },
    /// A triangle of the environment mesh names a vertex that does not exist.
    #[error(
        "environment triangle {triangle} has indices {indices:?} but the mesh has {vertices} vertices"
    )]
    MeshIndex {
        /// Index of the triangle.
        triangle: usize,
        /// Its vertex indices.
        indices: [u32; 3],
        /// Vertices in the mesh.
        vertices: usize,
    },
    /// A value that VTK files must not hold (NaN or infinite: ParaView's
    /// filters misbehave on them) was found. The `.npz` writer stores such
    /// values as they are.
    #[error("frame {frame}: {what} is not finite ({value})")]
    NonFinite {
        /// Index of the frame.
        frame: usize,
        /// Which value, e.g. `"time"` or `"rod 0 point 3"`.
        what: String,
        /// The offending value.
        value: f64,
    },
}

/// Why a trajectory could not be recorded or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutputError {
    /// Creating, writing or flushing a file or directory failed.
    #[error("I/O error on `{}`: {source}", path.display())]
    Io {
        /// The file or directory concerned.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The zip container of an `.npz` archive could not be written.
    #[error("cannot write zip archive `{}`: {source}", path.display())]
    Zip {
        /// The archive.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: zip::result::ZipError,
    },
    /// A frame or rod passed to the recording API has inconsistent shapes;
    /// the trajectory is left unchanged.
    #[error("cannot record: {0}")]
    Record(#[source] ShapeError),
    /// A file read back ([`read_npz`](super::read_npz)) is not what the
    /// writers write.
    #[error("cannot read `{}`: {message}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the array or field.
        message: String,
    },
    /// The trajectory handed to a writer is inconsistent, so nothing (or, for
    /// a series, nothing further) was written to `path`.
    #[error("cannot write `{}`: {source}", path.display())]
    Inconsistent {
        /// The file or directory that was to be written.
        path: PathBuf,
        /// What is inconsistent.
        #[source]
        source: ShapeError,
    },
}

impl OutputError {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| Self::Io { path, source }
    }
}
