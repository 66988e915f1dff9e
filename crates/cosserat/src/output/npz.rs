//! NumPy `.npz` writer: a zip archive of `.npy` (format version 1.0) arrays.

use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use zip::ZipWriter;
use zip::write::SimpleFileOptions;

use super::error::OutputError;
use super::trajectory::Trajectory;

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
/// | `rod_radii` | `(R,)` | radius of each rod |
/// | `rod_names` | `(R,)` | name of each rod (unicode, dtype `<U…`) |
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
    }
    npz.write_f64(
        "rod_radii",
        &[traj.rods.len()],
        traj.rods.iter().map(|r| r.radius),
    )?;
    npz.write_strings("rod_names", traj.rods.iter().map(|r| r.name.as_str()))?;
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
