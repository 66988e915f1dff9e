//! VTK XML PolyData (`.vtp`) frames, the environment mesh, and a ParaView
//! `.pvd` index.
//!
//! The files are binary: every array is stored in one appended block after
//! the XML, compressed with zlib (`compressor="vtkZLibDataCompressor"`,
//! 64-bit block headers), which is what ParaView itself writes. A 512-element
//! frame takes a few kilobytes instead of the ~100 kB of ASCII with
//! round-trip digits, and a 26 000-triangle vessel a few hundred kilobytes;
//! values stay bit-exact.

use std::fmt::Write as _;
use std::fs;
use std::io::Write as _;
use std::path::Path;

use super::error::{OutputError, ShapeError};
use super::trajectory::{EnvironmentMesh, Trajectory};

/// File name of the ParaView collection written by [`write_vtp_series`].
pub const PVD_FILE_NAME: &str = "trajectory.pvd";

/// File name of the environment mesh written beside the frames.
pub const ENVIRONMENT_FILE_NAME: &str = "environment.vtp";

/// File name of frame `frame` in a series written by [`write_vtp_series`]:
/// `frame_00000.vtp`, `frame_00001.vtp`, … (more digits past 99999).
pub fn vtp_frame_file_name(frame: usize) -> String {
    format!("frame_{frame:05}.vtp")
}

/// Writes `traj` into directory `dir` (created if missing) as one VTK XML
/// PolyData file per frame ([`vtp_frame_file_name`]), the environment mesh
/// ([`ENVIRONMENT_FILE_NAME`], when the trajectory has one) and a ParaView
/// index [`PVD_FILE_NAME`] listing them with their times (the environment as
/// a second part of every time step, so opening the index shows both).
///
/// Each frame file holds every rod:
///
/// * **Points**: the centreline points of rod 0, then rod 1, … (`Float64`).
/// * **Lines**: one two-point line cell per element (segment), in the same
///   order, so element `j` of rod `i` is a cell of its own. ParaView's *Tube*
///   filter works on it directly (a rod bent sharply may show small seams
///   between segment tubes).
/// * **Point data**: `radius` (the rod's radius at every point), `rod_id`
///   (`Int32`), `d1` (the mean of the directors of the point's elements), and
///   when recorded `velocity` [m/s], `contact_force` (the wall's normal force
///   on the point [N]) and `strain` (the mean of its elements').
/// * **Cell data**: `d1` (the element's first director; the active vectors),
///   `rod_id` and `element` (`Int32`, the element index within its rod), and
///   when recorded `strain` (`l / l0 - 1`). To draw the frame as arrows, apply
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
/// not match its element count and the number of times, if any time, point,
/// director, radius or recorded quantity is NaN or infinite, or if the
/// environment's triangles name missing vertices; [`OutputError::Io`] if a
/// directory or file cannot be written.
pub fn write_vtp_series(dir: &Path, traj: &Trajectory) -> Result<(), OutputError> {
    check(traj, 0).map_err(|source| OutputError::Inconsistent {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut series = VtpSeries::create(dir)?;
    series.append(traj)
}

/// Writes `mesh` as a VTK XML PolyData file of triangles at `path`.
///
/// # Errors
/// [`OutputError::Inconsistent`] if a triangle names a missing vertex or a
/// coordinate is not finite; [`OutputError::Io`] if the file cannot be
/// written.
pub fn write_environment_vtp(path: &Path, mesh: &EnvironmentMesh) -> Result<(), OutputError> {
    mesh.check().map_err(|source| OutputError::Inconsistent {
        path: path.to_path_buf(),
        source,
    })?;
    let mut doc = Document::new();
    doc.xml.push_str("<PolyData>\n");
    let _ = writeln!(
        doc.xml,
        "<Piece NumberOfPoints=\"{}\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"{}\">",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    doc.xml.push_str("<Points>\n");
    doc.array_f64("Points", 3, mesh.vertices.iter().flatten().copied());
    doc.xml.push_str("</Points>\n<Polys>\n");
    doc.array_i64(
        "connectivity",
        1,
        mesh.triangles.iter().flatten().map(|&i| i64::from(i)),
    );
    doc.array_i64(
        "offsets",
        1,
        (1..=mesh.triangles.len() as i64).map(|t| 3 * t),
    );
    doc.xml.push_str("</Polys>\n</Piece>\n</PolyData>\n");
    fs::write(path, doc.finish()).map_err(OutputError::io(path))
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
    /// Whether [`ENVIRONMENT_FILE_NAME`] was written (then every time step of
    /// the index lists it as part 1).
    environment: bool,
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
            environment: false,
        };
        series.write_index()?;
        Ok(series)
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.written
    }

    /// Writes the frames of `traj` not yet written (and its environment, the first time it
    /// has one), then the index.
    ///
    /// # Errors
    /// [`OutputError::Inconsistent`] (nothing written) if the trajectory is malformed or holds
    /// values VTK cannot read; [`OutputError::Io`] naming a file that cannot be written.
    pub fn append(&mut self, traj: &Trajectory) -> Result<(), OutputError> {
        check(traj, self.written).map_err(|source| OutputError::Inconsistent {
            path: self.dir.clone(),
            source,
        })?;
        if let (false, Some(mesh)) = (self.environment, &traj.environment) {
            write_environment_vtp(&self.dir.join(ENVIRONMENT_FILE_NAME), mesh)?;
            self.environment = true;
        }
        for frame in self.written..traj.times.len() {
            let name = vtp_frame_file_name(frame);
            let path = self.dir.join(&name);
            fs::write(&path, frame_vtp(traj, frame)).map_err(OutputError::io(&path))?;
            let time = traj.times[frame];
            let _ = writeln!(
                self.entries,
                "    <DataSet timestep=\"{time:?}\" group=\"\" part=\"0\" file=\"{name}\"/>"
            );
            if self.environment {
                let _ = writeln!(
                    self.entries,
                    "    <DataSet timestep=\"{time:?}\" group=\"\" part=\"1\" file=\"{ENVIRONMENT_FILE_NAME}\"/>"
                );
            }
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

/// Shapes, and finiteness of every value of frames `from..` (ParaView's
/// filters misbehave on `nan`/`inf`). A series checks each frame once, as it
/// is written, so a run of `T` frames costs `T` checks, not `T²`.
fn check(traj: &Trajectory, from: usize) -> Result<(), ShapeError> {
    traj.validate()?;
    let non_finite = |frame, what: &dyn Fn() -> String, value: f64| {
        if value.is_finite() {
            Ok(())
        } else {
            Err(ShapeError::NonFinite {
                frame,
                what: what(),
                value,
            })
        }
    };
    for (frame, &time) in traj.times.iter().enumerate().skip(from) {
        non_finite(frame, &|| "time".into(), time)?;
    }
    for (i, rod) in traj.rods.iter().enumerate() {
        non_finite(0, &|| format!("rod {i} radius"), rod.radius)?;
        let groups: [(&str, &[[f64; 3]], usize); 3] = [
            ("point", &rod.points, rod.n_points()),
            ("director", &rod.directors, rod.n_elements),
            ("velocity", &rod.velocities, rod.n_points()),
        ];
        for (what, values, per_frame) in groups {
            for (k, v) in values.iter().enumerate().skip(from * per_frame) {
                for &x in v {
                    non_finite(
                        k / per_frame,
                        &|| format!("rod {i} {what} {}", k % per_frame),
                        x,
                    )?;
                }
            }
        }
        let scalars: [(&str, &[f64], usize); 2] = [
            ("contact force", &rod.contact_forces, rod.n_points()),
            ("strain", &rod.strains, rod.n_elements),
        ];
        for (what, values, per_frame) in scalars {
            for (k, &x) in values.iter().enumerate().skip(from * per_frame) {
                non_finite(
                    k / per_frame,
                    &|| format!("rod {i} {what} {}", k % per_frame),
                    x,
                )?;
            }
        }
    }
    Ok(())
}

/// A VTK XML document being built: the XML, and the appended binary data its
/// arrays point into.
struct Document {
    xml: String,
    data: Vec<u8>,
}

/// Uncompressed bytes per zlib block (VTK's own default).
const BLOCK: usize = 32 * 1024;

impl Document {
    fn new() -> Self {
        Self {
            xml: String::from(
                "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\">\n",
            ),
            data: Vec::new(),
        }
    }

    /// Declares an array stored at the end of the appended data and stores
    /// `bytes` there: a header of `u64`s (number of blocks, block size, size
    /// of the last block if partial or 0, compressed size of each block),
    /// then the zlib streams.
    fn array(
        &mut self,
        ty: &str,
        name: &str,
        components: usize,
        tuples: Option<usize>,
        bytes: &[u8],
    ) {
        let tuples = tuples.map_or(String::new(), |n| format!(" NumberOfTuples=\"{n}\""));
        let _ = writeln!(
            self.xml,
            "<DataArray type=\"{ty}\" Name=\"{name}\" NumberOfComponents=\"{components}\"{tuples} format=\"appended\" offset=\"{}\"/>",
            self.data.len()
        );
        let blocks: Vec<Vec<u8>> = bytes
            .chunks(BLOCK)
            .map(|chunk| {
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
                // Writing into a `Vec` cannot fail.
                let _ = z.write_all(chunk);
                z.finish().unwrap_or_default()
            })
            .collect();
        let last = bytes.len() % BLOCK;
        let header = [blocks.len(), BLOCK, last]
            .into_iter()
            .chain(blocks.iter().map(Vec::len));
        for h in header {
            self.data.extend_from_slice(&(h as u64).to_le_bytes());
        }
        for b in &blocks {
            self.data.extend_from_slice(b);
        }
    }

    fn array_f64(&mut self, name: &str, components: usize, values: impl Iterator<Item = f64>) {
        let bytes: Vec<u8> = values.flat_map(f64::to_le_bytes).collect();
        self.array("Float64", name, components, None, &bytes);
    }

    fn array_i32(&mut self, name: &str, values: impl Iterator<Item = i32>) {
        let bytes: Vec<u8> = values.flat_map(i32::to_le_bytes).collect();
        self.array("Int32", name, 1, None, &bytes);
    }

    fn array_i64(&mut self, name: &str, components: usize, values: impl Iterator<Item = i64>) {
        let bytes: Vec<u8> = values.flat_map(i64::to_le_bytes).collect();
        self.array("Int64", name, components, None, &bytes);
    }

    /// The whole file: the XML, then the appended data after its `_` marker.
    fn finish(mut self) -> Vec<u8> {
        self.xml.push_str("<AppendedData encoding=\"raw\">\n_");
        let mut out = self.xml.into_bytes();
        out.extend_from_slice(&self.data);
        out.extend_from_slice(b"\n</AppendedData>\n</VTKFile>\n");
        out
    }
}

/// The `.vtp` file of frame `frame`.
fn frame_vtp(traj: &Trajectory, frame: usize) -> Vec<u8> {
    let n_points: usize = traj.rods.iter().map(|r| r.n_points()).sum();
    let n_cells: usize = traj.rods.iter().map(|r| r.n_elements).sum();
    let mut doc = Document::new();
    doc.xml.push_str("<PolyData>\n<FieldData>\n");
    doc.array(
        "Float64",
        "TimeValue",
        1,
        Some(1),
        &traj.times[frame].to_le_bytes(),
    );
    let _ = writeln!(
        doc.xml,
        "</FieldData>\n<Piece NumberOfPoints=\"{n_points}\" NumberOfVerts=\"0\" NumberOfLines=\"{n_cells}\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">"
    );
    let all = |f: &dyn Fn(&super::RodTrajectory) -> bool| traj.rods.iter().all(f);
    let velocities = all(&|r| !r.velocities.is_empty());
    let forces = all(&|r| !r.contact_forces.is_empty());
    let strains = all(&|r| !r.strains.is_empty());

    let _ = writeln!(
        doc.xml,
        "<PointData Scalars=\"radius\"{}>",
        if velocities {
            " Vectors=\"velocity\""
        } else {
            ""
        }
    );
    doc.array_f64(
        "radius",
        1,
        traj.rods
            .iter()
            .flat_map(|r| std::iter::repeat_n(r.radius, r.n_points())),
    );
    doc.array_i32(
        "rod_id",
        traj.rods
            .iter()
            .enumerate()
            .flat_map(|(i, r)| std::iter::repeat_n(i as i32, r.n_points())),
    );
    // Element quantities at the points: the mean of the point's (one or two)
    // elements.
    let at_points = |values: &[[f64; 3]]| -> Vec<[f64; 3]> {
        let n = values.len();
        if n == 0 {
            return Vec::new();
        }
        (0..=n)
            .map(|i| {
                let (a, b) = (values[i.saturating_sub(1)], values[i.min(n - 1)]);
                std::array::from_fn(|k| 0.5 * (a[k] + b[k]))
            })
            .collect()
    };
    doc.array_f64(
        "d1",
        3,
        traj.rods
            .iter()
            .flat_map(|r| at_points(r.frame_directors(frame).unwrap_or_default()))
            .flatten(),
    );
    if velocities {
        doc.array_f64(
            "velocity",
            3,
            traj.rods
                .iter()
                .flat_map(|r| r.frame_velocities(frame).unwrap_or_default())
                .flatten()
                .copied(),
        );
    }
    if forces {
        doc.array_f64(
            "contact_force",
            1,
            traj.rods
                .iter()
                .flat_map(|r| r.frame_contact_forces(frame).unwrap_or_default())
                .copied(),
        );
    }
    if strains {
        doc.array_f64(
            "strain",
            1,
            traj.rods.iter().flat_map(|r| {
                let s: Vec<[f64; 3]> = r
                    .frame_strains(frame)
                    .unwrap_or_default()
                    .iter()
                    .map(|&x| [x, 0.0, 0.0])
                    .collect();
                at_points(&s).into_iter().map(|v| v[0])
            }),
        );
    }
    doc.xml
        .push_str("</PointData>\n<CellData Vectors=\"d1\">\n");
    doc.array_f64(
        "d1",
        3,
        traj.rods
            .iter()
            .flat_map(|r| r.frame_directors(frame).unwrap_or_default())
            .flatten()
            .copied(),
    );
    doc.array_i32(
        "rod_id",
        traj.rods
            .iter()
            .enumerate()
            .flat_map(|(i, r)| std::iter::repeat_n(i as i32, r.n_elements)),
    );
    doc.array_i32(
        "element",
        traj.rods.iter().flat_map(|r| 0..r.n_elements as i32),
    );
    if strains {
        doc.array_f64(
            "strain",
            1,
            traj.rods
                .iter()
                .flat_map(|r| r.frame_strains(frame).unwrap_or_default())
                .copied(),
        );
    }
    doc.xml.push_str("</CellData>\n<Points>\n");
    doc.array_f64(
        "Points",
        3,
        traj.rods
            .iter()
            .flat_map(|r| r.frame_points(frame).unwrap_or_default())
            .flatten()
            .copied(),
    );
    doc.xml.push_str("</Points>\n<Lines>\n");
    let mut first = 0i64;
    let mut connectivity = Vec::with_capacity(2 * n_cells);
    for rod in &traj.rods {
        for j in 0..rod.n_elements as i64 {
            connectivity.extend_from_slice(&[first + j, first + j + 1]);
        }
        first += rod.n_points() as i64;
    }
    doc.array_i64("connectivity", 1, connectivity.into_iter());
    doc.array_i64("offsets", 1, (1..=n_cells as i64).map(|c| 2 * c));
    doc.xml.push_str("</Lines>\n</Piece>\n</PolyData>\n");
    doc.finish()
}
