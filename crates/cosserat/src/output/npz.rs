//! NumPy `.npz` writer and reader: a zip archive of `.npy` (format version
//! 1.0) arrays. The reader reads back what the writer writes (it is how
//! `cosserat render` gets a run's frames), not every `.npz` NumPy can make.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Read, Seek, Write};
use std::path::Path;

use zip::ZipWriter;
use zip::write::SimpleFileOptions;

use super::error::OutputError;
use super::trajectory::{EnvironmentMesh, RodTrajectory, Trajectory};

/// Writes `traj` as a NumPy `.npz` archive at `path` (the file is created or
/// truncated; its directory must exist).
///
/// The archive holds, for `T` frames and rods `i = 0, 1, …` of `n_i`
/// elements, these arrays (all little-endian `float64` in C order unless
/// noted):
///
/// | name | shape | content |
/// |------|-------|---------|
/// | `times` | `(T,)` | time of each frame |
/// | `rod{i}` | `(T, n_i + 1, 3)` | centreline points of rod `i` |
/// | `rod{i}_directors` | `(T, n_i, 3)` | first director `d1` of each element |
/// | `rod{i}_velocities` | `(T, n_i + 1, 3)` | point velocities, when recorded |
/// | `rod{i}_contact_force` | `(T, n_i + 1)` | normal force of the wall on each point [N], when recorded |
/// | `rod{i}_strain` | `(T, n_i)` | strain `l / l0 - 1` of each element, when recorded |
/// | `rod_radii` | `(R,)` | radius of each rod |
/// | `rod_names` | `(R,)` | name of each rod (unicode, dtype `<U…`) |
/// | `mesh_vertices` | `(V, 3)` | the environment's vertices, when it has one |
/// | `mesh_triangles` | `(F, 3)` | its triangles' vertex indices (`uint32`) |
///
/// Load it with `numpy.load(path)`; no `allow_pickle` is needed. Entries are
/// deflate-compressed, as `numpy.savez_compressed` does. Non-finite values
/// are stored as they are.
///
/// # Errors
///
/// [`OutputError::Inconsistent`] if a rod's arrays do not match its element
/// count and the number of times (nothing is written then);
/// [`OutputError::Io`] or [`OutputError::Zip`] if writing fails.
pub fn write_npz(path: &Path, traj: &Trajectory) -> Result<(), OutputError> {
    traj.validate()
        .map_err(|source| OutputError::Inconsistent {
            path: path.to_path_buf(),
            source,
        })?;
    let file = File::create(path).map_err(OutputError::io(path))?;
    let mut npz = NpzWriter {
        zip: ZipWriter::new(BufWriter::new(file)),
        path,
    };
    let t = traj.times.len();
    npz.write_f64("times", &[t], traj.times.iter().copied())?;
    for (i, rod) in traj.rods.iter().enumerate() {
        npz.write_f64(
            &format!("rod{i}"),
            &[t, rod.n_points(), 3],
            rod.points.iter().flatten().copied(),
        )?;
        npz.write_f64(
            &format!("rod{i}_directors"),
            &[t, rod.n_elements, 3],
            rod.directors.iter().flatten().copied(),
        )?;
        if !rod.velocities.is_empty() {
            npz.write_f64(
                &format!("rod{i}_velocities"),
                &[t, rod.n_points(), 3],
                rod.velocities.iter().flatten().copied(),
            )?;
        }
        if !rod.contact_forces.is_empty() {
            npz.write_f64(
                &format!("rod{i}_contact_force"),
                &[t, rod.n_points()],
                rod.contact_forces.iter().copied(),
            )?;
        }
        if !rod.strains.is_empty() {
            npz.write_f64(
                &format!("rod{i}_strain"),
                &[t, rod.n_elements],
                rod.strains.iter().copied(),
            )?;
        }
    }
    npz.write_f64(
        "rod_radii",
        &[traj.rods.len()],
        traj.rods.iter().map(|r| r.radius),
    )?;
    npz.write_strings("rod_names", traj.rods.iter().map(|r| r.name.as_str()))?;
    if let Some(mesh) = &traj.environment {
        npz.write_f64(
            "mesh_vertices",
            &[mesh.vertices.len(), 3],
            mesh.vertices.iter().flatten().copied(),
        )?;
        let bytes: Vec<u8> = mesh
            .triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        npz.start(
            "mesh_triangles",
            &npy_header("<u4", &[mesh.triangles.len(), 3]),
            bytes.len(),
        )?;
        npz.zip.write_all(&bytes).map_err(OutputError::io(path))?;
    }
    let inner = npz.zip.finish().map_err(|source| OutputError::Zip {
        path: path.to_path_buf(),
        source,
    })?;
    // `into_inner` flushes the buffer and reports what `Drop` would ignore.
    inner.into_inner().map_err(|e| OutputError::Io {
        path: path.to_path_buf(),
        source: e.into_error(),
    })?;
    Ok(())
}

/// Adds `.npy` entries to a zip archive.
struct NpzWriter<'p, W: Write + Seek> {
    zip: ZipWriter<W>,
    path: &'p Path,
}

impl<W: Write + Seek> NpzWriter<'_, W> {
    fn zip_err(&self) -> impl FnOnce(zip::result::ZipError) -> OutputError {
        let path = self.path.to_path_buf();
        move |source| OutputError::Zip { path, source }
    }

    fn start(&mut self, name: &str, header: &[u8], data_len: usize) -> Result<(), OutputError> {
        let size = (header.len() + data_len) as u64;
        let options = SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated)
            .large_file(size >= u64::from(u32::MAX));
        self.zip
            .start_file(format!("{name}.npy"), options)
            .map_err(self.zip_err())?;
        self.zip
            .write_all(header)
            .map_err(OutputError::io(self.path))
    }

    /// Writes a `float64` array of the given shape from `values` (C order;
    /// the caller guarantees the count matches the shape).
    fn write_f64(
        &mut self,
        name: &str,
        shape: &[usize],
        values: impl Iterator<Item = f64>,
    ) -> Result<(), OutputError> {
        let count: usize = shape.iter().product();
        self.start(name, &npy_header("<f8", shape), count * 8)?;
        let mut buf = Vec::with_capacity(8 * 4096);
        for v in values {
            buf.extend_from_slice(&v.to_le_bytes());
            if buf.len() >= 8 * 4096 {
                self.zip
                    .write_all(&buf)
                    .map_err(OutputError::io(self.path))?;
                buf.clear();
            }
        }
        self.zip.write_all(&buf).map_err(OutputError::io(self.path))
    }

    /// Writes a 1-d NumPy unicode array (`<U{k}`, UTF-32LE, zero-padded).
    fn write_strings<'s>(
        &mut self,
        name: &str,
        strings: impl ExactSizeIterator<Item = &'s str> + Clone,
    ) -> Result<(), OutputError> {
        let width = strings
            .clone()
            .map(|s| s.chars().count())
            .max()
            .unwrap_or(0)
            .max(1);
        let n = strings.len();
        let mut data = Vec::with_capacity(n * width * 4);
        for s in strings {
            let mut chars = 0;
            for c in s.chars() {
                data.extend_from_slice(&u32::from(c).to_le_bytes());
                chars += 1;
            }
            data.resize(data.len() + (width - chars) * 4, 0);
        }
        self.start(name, &npy_header(&format!("<U{width}"), &[n]), data.len())?;
        self.zip
            .write_all(&data)
            .map_err(OutputError::io(self.path))
    }
}

/// The `.npy` format 1.0 preamble: magic, version, header length and the
/// header dict padded with spaces and a final `'\n'` so that the data starts
/// at a multiple of 64 bytes, exactly as `numpy.lib.format` writes it.
pub(crate) fn npy_header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let shape = match shape {
        [n] => format!("({n},)"),
        _ => {
            let dims: Vec<String> = shape.iter().map(usize::to_string).collect();
            format!("({})", dims.join(", "))
        }
    };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    // 6 magic bytes + 2 version bytes + 2 length bytes + dict + '\n'.
    let unpadded = 10 + dict.len() + 1;
    dict.extend(std::iter::repeat_n(
        ' ',
        unpadded.next_multiple_of(64) - unpadded,
    ));
    dict.push('\n');
    let mut out = Vec::with_capacity(10 + dict.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    // The dict is at most a few hundred bytes, far below u16::MAX.
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

/// Reads a trajectory written by [`write_npz`]: times, rods (names, radii,
/// points, directors and whatever optional quantities were recorded) and the
/// environment mesh.
///
/// # Errors
/// [`OutputError::Io`] if the file cannot be opened; [`OutputError::Read`]
/// naming the array when the archive lacks one or holds one of another type
/// or shape; [`OutputError::Inconsistent`] if the arrays disagree.
pub fn read_npz(path: &Path) -> Result<Trajectory, OutputError> {
    let bad = |message: String| OutputError::Read {
        path: path.to_path_buf(),
        message,
    };
    let file = File::open(path).map_err(OutputError::io(path))?;
    let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file))
        .map_err(|e| bad(format!("not a zip archive: {e}")))?;
    let mut arrays: HashMap<String, Npy> = HashMap::new();
    for k in 0..zip.len() {
        let mut entry = zip.by_index(k).map_err(|e| bad(e.to_string()))?;
        let name = entry.name().map_err(|e| bad(e.to_string()))?;
        let Some(name) = name.strip_suffix(".npy").map(str::to_owned) else {
            continue;
        };
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| bad(format!("`{name}`: {e}")))?;
        let npy = Npy::parse(&bytes).map_err(|e| bad(format!("`{name}`: {e}")))?;
        arrays.insert(name, npy);
    }
    let mut take = |name: &str| {
        arrays
            .remove(name)
            .ok_or_else(|| bad(format!("no array `{name}`")))
    };
    let times = take("times")?.f64s("times", 1).map_err(&bad)?;
    let radii = take("rod_radii")?.f64s("rod_radii", 1).map_err(&bad)?;
    let names = take("rod_names")?.strings("rod_names").map_err(&bad)?;
    if names.len() != radii.len() {
        return Err(bad(format!(
            "`rod_names` has {} entries but `rod_radii` {}",
            names.len(),
            radii.len()
        )));
    }
    let t = times.len();
    let triples =
        |v: Vec<f64>| -> Vec<[f64; 3]> { v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect() };
    let mut rods = Vec::with_capacity(radii.len());
    for (i, (name, radius)) in names.into_iter().zip(radii).enumerate() {
        let key = format!("rod{i}");
        let points = take(&key)?;
        let n_points = match points.shape.as_slice() {
            [frames, n, 3] if *frames == t && *n >= 2 => *n,
            other => {
                return Err(bad(format!(
                    "`{key}` has shape {other:?}, expected ({t}, n + 1, 3)"
                )));
            }
        };
        let mut rod = RodTrajectory::new(name, radius, n_points - 1);
        rod.points = triples(points.f64s(&key, 3).map_err(&bad)?);
        let key = format!("rod{i}_directors");
        rod.directors = triples(take(&key)?.f64s(&key, 3).map_err(&bad)?);
        let key = format!("rod{i}_velocities");
        if let Ok(v) = take(&key) {
            rod.velocities = triples(v.f64s(&key, 3).map_err(&bad)?);
        }
        let key = format!("rod{i}_contact_force");
        if let Ok(v) = take(&key) {
            rod.contact_forces = v.f64s(&key, 2).map_err(&bad)?;
        }
        let key = format!("rod{i}_strain");
        if let Ok(v) = take(&key) {
            rod.strains = v.f64s(&key, 2).map_err(&bad)?;
        }
        rods.push(rod);
    }
    let environment = match take("mesh_vertices") {
        Ok(v) => {
            let vertices = triples(v.f64s("mesh_vertices", 2).map_err(&bad)?);
            let tri = take("mesh_triangles")?;
            if tri.descr != "<u4" {
                return Err(bad(format!(
                    "`mesh_triangles` has dtype {}, expected <u4",
                    tri.descr
                )));
            }
            let triangles = tri
                .data
                .chunks_exact(12)
                .map(|c| {
                    std::array::from_fn(|k| {
                        u32::from_le_bytes([c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]])
                    })
                })
                .collect();
            Some(EnvironmentMesh {
                vertices,
                triangles,
            })
        }
        Err(_) => None,
    };
    let traj = Trajectory {
        times,
        rods,
        environment,
    };
    traj.validate()
        .map_err(|source| OutputError::Inconsistent {
            path: path.to_path_buf(),
            source,
        })?;
    Ok(traj)
}

/// One `.npy` array: its dtype, shape and raw little-endian data.
struct Npy {
    descr: String,
    shape: Vec<usize>,
    data: Vec<u8>,
}

impl Npy {
    /// Parses format 1.0 or 2.0 with a C-order header as [`npy_header`] writes it.
    fn parse(bytes: &[u8]) -> Result<Self, String> {
        let rest = bytes.strip_prefix(b"\x93NUMPY").ok_or("not a .npy array")?;
        let (len, header_start) = match rest.first() {
            Some(1) if rest.len() >= 4 => (usize::from(u16::from_le_bytes([rest[2], rest[3]])), 10),
            Some(2 | 3) if rest.len() >= 6 => (
                u32::from_le_bytes([rest[2], rest[3], rest[4], rest[5]]) as usize,
                12,
            ),
            _ => return Err("unknown .npy version".into()),
        };
        let header = bytes
            .get(header_start..header_start + len)
            .and_then(|h| std::str::from_utf8(h).ok())
            .ok_or("truncated header")?;
        let field = |key: &str| -> Result<&str, String> {
            let at = header
                .find(&format!("'{key}':"))
                .ok_or(format!("no `{key}` in the header"))?;
            Ok(header[at + key.len() + 3..].trim_start())
        };
        if !field("fortran_order")?.starts_with("False") {
            return Err("Fortran order is not supported".into());
        }
        let descr = field("descr")?;
        let descr = descr
            .strip_prefix('\'')
            .and_then(|d| d.split('\'').next())
            .ok_or("bad descr")?
            .to_string();
        let shape = field("shape")?;
        let shape = shape
            .strip_prefix('(')
            .and_then(|s| s.split(')').next())
            .ok_or("bad shape")?;
        let shape = shape
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<usize>().map_err(|e| format!("bad shape: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            descr,
            shape,
            data: bytes[header_start + len..].to_vec(),
        })
    }

    /// The values of a `<f8` array of `dims` dimensions.
    fn f64s(&self, name: &str, dims: usize) -> Result<Vec<f64>, String> {
        if self.descr != "<f8" || self.shape.len() != dims {
            return Err(format!(
                "`{name}` has dtype {} and shape {:?}, expected <f8 with {dims} dimensions",
                self.descr, self.shape
            ));
        }
        let count: usize = self.shape.iter().product();
        if self.data.len() != 8 * count {
            return Err(format!(
                "`{name}` holds {} bytes, expected {}",
                self.data.len(),
                8 * count
            ));
        }
        Ok(self
            .data
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(std::array::from_fn(|k| c[k])))
            .collect())
    }

    /// The strings of a 1-d `<U…` array (trailing NULs removed).
    fn strings(&self, name: &str) -> Result<Vec<String>, String> {
        let width: usize = self
            .descr
            .strip_prefix("<U")
            .and_then(|w| w.parse().ok())
            .ok_or(format!("`{name}` has dtype {}, expected <U…", self.descr))?;
        let n = match self.shape.as_slice() {
            [n] => *n,
            other => {
                return Err(format!(
                    "`{name}` has shape {other:?}, expected 1 dimension"
                ));
            }
        };
        if self.data.len() != 4 * width * n {
            return Err(format!("`{name}` is truncated"));
        }
        Ok(self
            .data
            .chunks_exact((4 * width).max(1))
            .map(|s| {
                s.chunks_exact(4)
                    .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .take_while(|&c| c != 0)
                    .filter_map(char::from_u32)
                    .collect()
            })
            .collect())
    }
}
