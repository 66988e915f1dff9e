//! Offscreen pictures and videos of Cosserat rod runs.
//!
//! A user who wants to see a run should not have to load hundreds of VTK files into ParaView.
//! This crate draws what a run recorded — rods as shaded tubes of their radius, turned with
//! their material frames; the vessel translucent; points pressed against the wall coloured by
//! their normal force — into PNG frames and one animated file (MP4 through ffmpeg, else GIF).
//! It runs on any wgpu adapter, Mesa's lavapipe included, so it works on a machine without a
//! GPU and in CI. The same drawing goes into a window's surface ([`SurfaceRenderer`], for
//! `cosserat view`).
//!
//! It takes plain data only ([`RodPose`]: centreline, directors, radius, contact forces;
//! [`SurfaceMesh`]: vertices and triangles) and knows nothing of simulations or file layouts;
//! the `cosserat render` command reads a run directory and hands its frames over.
//!
//! ```no_run
//! use cosserat_render::{Bounds, Camera, Projection, RenderSettings, Renderer, RodPose, View};
//! # fn main() -> Result<(), cosserat_render::RenderError> {
//! let points = [[0.0, 0.0, 0.0], [0.1, 0.0, 0.02], [0.2, 0.0, 0.0]];
//! let rod = RodPose { points: &points, d1: &[], radius: 0.004, contact_force: None };
//! let mut bounds = Bounds::EMPTY;
//! cosserat_render::include_rod(&mut bounds, &rod);
//! let settings = RenderSettings { width: 320, height: 180, ..Default::default() };
//! let camera = Camera::framing(&bounds, View::Auto, Projection::Orthographic, 320, 180)?;
//! let mut renderer = Renderer::new(settings)?;
//! let image = renderer.render(&camera, &[rod])?;
//! cosserat_render::write_png(std::path::Path::new("rod.png"), &image)?;
//! # Ok(())
//! # }
//! ```
//!
//! Same input on the same adapter gives the same bytes ([`renderer`] says why); the golden
//! test (`tests/golden.rs`) compares a small scene with a stored picture within a tolerance,
//! since rasterisers of different adapters differ in the last bit of an edge.

pub mod camera;
mod draw;
mod encode;
mod font;
mod geometry;
mod overlay;
pub mod renderer;
pub mod surface;

pub use camera::{Bounds, Camera, Projection, View};
pub use encode::{AnimationFormat, AnimationWriter, ffmpeg_available, read_png, write_png};
pub use geometry::{MESH_COLOUR, ROD_COLOURS, RodPose, SIDES, SurfaceMesh, include_rod};
pub use renderer::{Image, RenderSettings, Renderer};
pub use surface::{Presented, SurfaceRenderer};

use std::path::{Path, PathBuf};

/// Why a picture could not be made or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// wgpu found no adapter, or the adapter gave no device.
    #[error(
        "no GPU adapter for rendering: {0} (Mesa's lavapipe works without a GPU: apt-get install mesa-vulkan-drivers)"
    )]
    NoAdapter(String),
    /// The device reported an error.
    #[error("rendering failed on the device: {0}")]
    Device(String),
    /// An option has a value it cannot take.
    #[error("--{option} `{value}` is invalid: expected {expected}")]
    Option {
        /// The option's name, as on the command line.
        option: &'static str,
        /// The value given.
        value: String,
        /// What it may be.
        expected: &'static str,
    },
    /// A file or folder could not be written or read.
    #[error("I/O error on `{}`: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A picture file could not be encoded or decoded.
    #[error("`{}`: {message}", path.display())]
    Encode {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// ffmpeg could not be run or failed.
    #[error("{0}")]
    Ffmpeg(String),
}

impl RenderError {
    pub(crate) fn io(path: &Path) -> impl FnOnce(std::io::Error) -> Self + '_ {
        move |source| Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
