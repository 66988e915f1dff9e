//! VTK XML PolyData (`.vtp`) frames and a ParaView `.pvd` index.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use super::error::{OutputError, ShapeError};
use super::trajectory::Trajectory;

/// File name of the ParaView collection written by [`write_vtp_series`].
pub const PVD_FILE_NAME: &str = "trajectory.pvd";

/// File name of frame `frame` in a series written by [`write_vtp_series`]:
/// `frame_00000.vtp`, `frame_00001.vtp`, … (more digits past 99999).
pub fn vtp_frame_file_name(frame: usize) -> String {
    format!("frame_{frame:05}.vtp")
}

/// Writes `traj` into directory `dir` (created if missing) as one VTK XML
/// PolyData file per frame ([`vtp_frame_file_name`]) and a ParaView index
/// [`PVD_FILE_NAME`] listing them with their times.
///
/// Each frame file holds every rod, ASCII-encoded with round-trip exact
/// numbers:
///
/// * **Points**: the centreline points of rod 0, then rod 1, …
/// * **Lines**: one two-point line cell per element (segment), in the same
///   order, so element `j` of rod `i` is a cell of its own. This is what lets
///   the directors be exact per-element cell data; ParaView's *Tube* filter
///   works on it directly (a rod bent sharply may show small seams between
///   segment tubes).
/// * **Point data**: `radius` (`Float64`, the rod's radius at every point)
///   and `rod_id` (`Int32`).
/// * **Cell data**: `d1` (`Float64`, 3 components, the element's first
///   director; the active vectors), `rod_id` and `element` (`Int32`, the
///   element index within its rod). To draw the frame as arrows, apply
///   *Cell Centers* and then *Glyph* oriented by `d1`.
/// * **Field data**: `TimeValue`, the frame's time, so a single file opened
///   on its own still knows its time.
///
/// The index is written last, so it never lists a frame file that failed
/// to be written. Frame files left in `dir` by an earlier, longer run are not
/// removed, but the index does not list them.
///
/// # Errors
///
/// [`OutputError::Inconsistent`] (and nothing written) if a rod's arrays do
/// not match its element count and the number of times, or if any time,
/// point, director or radius is NaN or infinite (VTK's ASCII reader cannot
/// read those); [`OutputError::Io`] if a directory or file cannot be written.
pub fn write_vtp_series(dir: &Path, traj: &Trajectory) -> Result<(), OutputError> {
    check(traj).map_err(|source| OutputError::Inconsistent {
        path: dir.to_path_buf(),
        source,
    })?;
    fs::create_dir_all(dir).map_err(OutputError::io(dir))?;
    let mut entries = String::new();
    let mut buf = String::new();
    for (frame, &time) in traj.times.iter().enumerate() {
        let name = vtp_frame_file_name(frame);
        buf.clear();
        frame_vtp(&mut buf, traj, frame);
        let path = dir.join(&name);
        fs::write(&path, &buf).map_err(OutputError::io(&path))?;
        let _ = writeln!(
            entries,
            "    <DataSet timestep=\"{time:?}\" group=\"\" part=\"0\" file=\"{name}\"/>"
        );
    }
    let path = dir.join(PVD_FILE_NAME);
    fs::write(&path, index_text(&entries)).map_err(OutputError::io(&path))
}

/// A `.vtp` series written while a run makes it: each frame's file as soon as the frame is
/// recorded, and the ParaView index rewritten after it (to a temporary file, then renamed), so
/// that a run stopped at any moment — Ctrl-C, a kill, a crash — leaves a valid series of the
/// frames made so far. [`write_vtp_series`] writes the same files for a finished trajectory.
#[derive(Debug)]
pub struct VtpSeries {
    dir: std::path::PathBuf,
    entries: String,
    written: usize,
}

impl VtpSeries {
    /// Creates `dir` if needed and writes an empty index into it, so that a directory that
    /// cannot be written is found before a run starts, not after it.
    ///
    /// # Errors
    /// [`OutputError::Io`] naming the directory or the index.
    pub fn create(dir: &Path) -> Result<Self, OutputError> {
        fs::create_dir_all(dir).map_err(OutputError::io(dir))?;
        let series = Self {
            dir: dir.to_path_buf(),
            entries: String::new(),
            written: 0,
        };
        series.write_index()?;
        Ok(series)
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.written
    }

    /// Writes the frames of `traj` not yet written, then the index.
    ///
    /// # Errors
    /// [`OutputError::Inconsistent`] (nothing written) if the trajectory is malformed or holds
    /// values VTK cannot read; [`OutputError::Io`] naming a file that cannot be written.
    pub fn append(&mut self, traj: &Trajectory) -> Result<(), OutputError> {
        check(traj).map_err(|source| OutputError::Inconsistent {
            path: self.dir.clone(),
            source,
        })?;
        let mut buf = String::new();
        for frame in self.written..traj.times.len() {
            let name = vtp_frame_file_name(frame);
            buf.clear();
            frame_vtp(&mut buf, traj, frame);
            let path = self.dir.join(&name);
            fs::write(&path, &buf).map_err(OutputError::io(&path))?;
            let _ = writeln!(
                self.entries,
                "    <DataSet timestep=\"{:?}\" group=\"\" part=\"0\" file=\"{name}\"/>",
                traj.times[frame]
            );
            self.written = frame + 1;
        }
        self.write_index()
    }

    fn write_index(&self) -> Result<(), OutputError> {
        let text = index_text(&self.entries);
        let path = self.dir.join(PVD_FILE_NAME);
        let partial = self.dir.join(format!("{PVD_FILE_NAME}.partial"));
        fs::write(&partial, text).map_err(OutputError::io(&partial))?;
        fs::rename(&partial, &path).map_err(OutputError::io(&path))
    }
}

/// The ParaView collection listing `entries` (one `<DataSet …/>` line each).
fn index_text(entries: &str) -> String {
    format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n{entries}  </Collection>\n</VTKFile>\n"
    )
}

/// Shapes, and finiteness of every value (VTK cannot read `nan`/`inf`).
fn check(traj: &Trajectory) -> Result<(), ShapeError> {
    traj.validate()?;
    let non_finite = |frame, what: String, value: f64| {
        if value.is_finite() {
            Ok(())
        } else {
            Err(ShapeError::NonFinite { frame, what, value })
        }
    };
    for (frame, &time) in traj.times.iter().enumerate() {
        non_finite(frame, "time".into(), time)?;
    }
    for (i, rod) in traj.rods.iter().enumerate() {
        non_finite(0, format!("rod {i} radius"), rod.radius)?;
        let groups = [
            ("point", &rod.points, rod.n_points()),
            ("director", &rod.directors, rod.n_elements),
        ];
        for (what, values, per_frame) in groups {
            for (k, v) in values.iter().enumerate() {
                for &x in v {
                    non_finite(
                        k / per_frame,
                        format!("rod {i} {what} {}", k % per_frame),
                        x,
                    )?;
                }
            }
        }
    }
    Ok(())
}

/// Appends the `.vtp` document of frame `frame` to `out`. Writing to a
/// `String` cannot fail, hence the ignored `fmt::Result`s.
fn frame_vtp(out: &mut String, traj: &Trajectory, frame: usize) {
    let n_points: usize = traj.rods.iter().map(|r| r.n_points()).sum();
    let n_cells: usize = traj.rods.iter().map(|r| r.n_elements).sum();
    let _ = write!(
        out,
        "<?xml version=\"1.0\"?>\n\
         <VTKFile type=\"PolyData\" version=\"0.1\" byte_order=\"LittleEndian\">\n\
         <PolyData>\n\
         <FieldData>\n\
         <DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" format=\"ascii\">{:?}</DataArray>\n\
         </FieldData>\n\
         <Piece NumberOfPoints=\"{n_points}\" NumberOfVerts=\"0\" NumberOfLines=\"{n_cells}\" \
         NumberOfStrips=\"0\" NumberOfPolys=\"0\">\n",
        traj.times[frame]
    );

    out.push_str("<PointData Scalars=\"radius\">\n");
    open_array(out, "Float64", "radius", 1);
    for rod in &traj.rods {
        for _ in 0..rod.n_points() {
            let _ = writeln!(out, "{:?}", rod.radius);
        }
    }
    close_array(out);
    open_array(out, "Int32", "rod_id", 1);
    for (i, rod) in traj.rods.iter().enumerate() {
        for _ in 0..rod.n_points() {
            let _ = writeln!(out, "{i}");
        }
    }
    close_array(out);
    out.push_str("</PointData>\n");

    out.push_str("<CellData Vectors=\"d1\">\n");
    open_array(out, "Float64", "d1", 3);
    for rod in &traj.rods {
        for [x, y, z] in rod.frame_directors(frame).unwrap_or_default() {
            let _ = writeln!(out, "{x:?} {y:?} {z:?}");
        }
    }
    close_array(out);
    open_array(out, "Int32", "rod_id", 1);
    for (i, rod) in traj.rods.iter().enumerate() {
        for _ in 0..rod.n_elements {
            let _ = writeln!(out, "{i}");
        }
    }
    close_array(out);
    open_array(out, "Int32", "element", 1);
    for rod in &traj.rods {
        for j in 0..rod.n_elements {
            let _ = writeln!(out, "{j}");
        }
    }
    close_array(out);
    out.push_str("</CellData>\n");

    out.push_str("<Points>\n");
    open_array(out, "Float64", "Points", 3);
    for rod in &traj.rods {
        for [x, y, z] in rod.frame_points(frame).unwrap_or_default() {
            let _ = writeln!(out, "{x:?} {y:?} {z:?}");
        }
    }
    close_array(out);
    out.push_str("</Points>\n");

    out.push_str("<Lines>\n");
    open_array(out, "Int64", "connectivity", 1);
    let mut first = 0;
    for rod in &traj.rods {
        for j in 0..rod.n_elements {
            let _ = writeln!(out, "{} {}", first + j, first + j + 1);
        }
        first += rod.n_points();
    }
    close_array(out);
    open_array(out, "Int64", "offsets", 1);
    for cell in 1..=n_cells {
        let _ = writeln!(out, "{}", 2 * cell);
    }
    close_array(out);
    out.push_str("</Lines>\n</Piece>\n</PolyData>\n</VTKFile>\n");
}

fn open_array(out: &mut String, ty: &str, name: &str, components: usize) {
    let _ = writeln!(
        out,
        "<DataArray type=\"{ty}\" Name=\"{name}\" NumberOfComponents=\"{components}\" format=\"ascii\">"
    );
}

fn close_array(out: &mut String) {
    out.push_str("</DataArray>\n");
}
