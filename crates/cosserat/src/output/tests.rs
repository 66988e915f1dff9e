//! Tests: a minimal `.npy`/`.npz` reader and XML checker read back what the
//! writers produce, so no Python or extra crate is needed.

use std::collections::HashMap;
use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};

use super::*;

/// A fresh, empty scratch directory for one test.
fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cosserat-output-{}-{test}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    dir
}

/// Two rods (3 and 1 elements) over `frames` frames with distinct values,
/// including awkward ones (negative zero, tiny, huge, non-terminating).
fn sample(frames: usize) -> Trajectory {
    let mut traj = Trajectory::new();
    assert_eq!(traj.add_rod("guidewire", 0.00035, 3).unwrap(), 0);
    assert_eq!(traj.add_rod("catheter ø", 1.0 / 3.0, 1).unwrap(), 1);
    for f in 0..frames {
        let s = f as f64;
        let p0: Vec<[f64; 3]> = (0..4)
            .map(|k| [k as f64 * 0.1 + s, -0.0, 1e-300 * (k as f64 + s)])
            .collect();
        let d0: Vec<[f64; 3]> = (0..3).map(|k| [0.0, 1.0 / (k as f64 + 3.0), s]).collect();
        let p1 = [[1e20, 2.0, s], [3.0, -4.5, s / 7.0]];
        let d1 = [[std::f64::consts::PI, 0.0, -s]];
        let v0: Vec<[f64; 3]> = (0..4).map(|k| [s, -(k as f64), 0.5]).collect();
        let v1 = [[1.0, 2.0, 3.0], [0.0, -0.0, s]];
        let f0 = [0.0, 0.25 * s, 1e-9, 0.0];
        let f1 = [s, 0.0];
        let e0 = [1e-6, -2e-6 * s, 0.0];
        let e1 = [s * 1e-3];
        traj.push_frame(
            0.125 * s + 1e-7,
            &[
                RodFrame {
                    points: &p0,
                    directors: &d0,
                    velocities: &v0,
                    contact_forces: &f0,
                    strains: &e0,
                },
                RodFrame {
                    points: &p1,
                    directors: &d1,
                    velocities: &v1,
                    contact_forces: &f1,
                    strains: &e1,
                },
            ],
        )
        .unwrap();
    }
    traj
}

// ---------------------------------------------------------------- npy reader

#[derive(Debug)]
struct Npy {
    descr: String,
    shape: Vec<usize>,
    data: Vec<u8>,
}

impl Npy {
    fn f64s(&self) -> Vec<f64> {
        assert_eq!(self.descr, "<f8");
        self.data
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }
}

/// Parses one `.npy` v1.0 file, checking the preamble strictly.
fn parse_npy(bytes: &[u8]) -> Npy {
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00", "magic and version 1.0");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!((10 + len) % 64, 0, "data must start 64-byte aligned");
    let header = std::str::from_utf8(&bytes[10..10 + len]).unwrap();
    assert!(header.is_ascii());
    assert!(header.ends_with('\n'));
    let dict = header.trim_end_matches('\n').trim_end_matches(' ');
    assert!(
        dict.starts_with("{'descr': '") && dict.ends_with(", }"),
        "{dict}"
    );
    let rest = &dict["{'descr': '".len()..];
    let (descr, rest) = rest.split_once('\'').unwrap();
    let rest = rest
        .strip_prefix(", 'fortran_order': False, 'shape': (")
        .unwrap();
    let (shape, rest) = rest.split_once(')').unwrap();
    assert_eq!(rest, ", }");
    let shape: Vec<usize> = shape
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    Npy {
        descr: descr.to_owned(),
        shape,
        data: bytes[10 + len..].to_vec(),
    }
}

/// Reads every entry `name.npy` of an `.npz` archive.
fn read_npz_arrays(path: &Path) -> HashMap<String, Npy> {
    let mut zip = zip::ZipArchive::new(fs::File::open(path).unwrap()).unwrap();
    let mut out = HashMap::new();
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).unwrap();
        let name = entry
            .name()
            .unwrap()
            .strip_suffix(".npy")
            .unwrap()
            .to_owned();
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).unwrap();
        out.insert(name, parse_npy(&bytes));
    }
    out
}

#[test]
fn npy_header_matches_numpy_layout() {
    let h = npy_header_for_test("<f8", &[2, 3, 3]);
    assert_eq!(h.len() % 64, 0);
    let dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3, 3), }";
    let mut expected = b"\x93NUMPY\x01\x00".to_vec();
    expected.extend_from_slice(&[118, 0]); // 128 - 10
    expected.extend_from_slice(dict.as_bytes());
    expected.resize(127, b' ');
    expected.push(b'\n');
    assert_eq!(h, expected);
    // One-dimensional shapes are written as Python 1-tuples.
    let h = npy_header_for_test("<f8", &[5]);
    assert!(
        std::str::from_utf8(&h[10..])
            .unwrap()
            .contains("'shape': (5,), }")
    );
}

fn npy_header_for_test(descr: &str, shape: &[usize]) -> Vec<u8> {
    super::npz::npy_header(descr, shape)
}

#[test]
fn npz_round_trips_shapes_and_values() {
    let dir = scratch("npz");
    let traj = sample(4);
    let path = dir.join("trajectory.npz");
    write_npz(&path, &traj).unwrap();
    let arrays = read_npz_arrays(&path);

    let mut names: Vec<&str> = arrays.keys().map(String::as_str).collect();
    names.sort_unstable();
    assert_eq!(
        names,
        [
            "rod0",
            "rod0_contact_force",
            "rod0_directors",
            "rod0_strain",
            "rod0_velocities",
            "rod1",
            "rod1_contact_force",
            "rod1_directors",
            "rod1_strain",
            "rod1_velocities",
            "rod_names",
            "rod_radii",
            "times"
        ]
    );
    assert_eq!(arrays["times"].shape, [4]);
    assert_eq!(arrays["times"].f64s(), traj.times);
    for (i, rod) in traj.rods.iter().enumerate() {
        let p = &arrays[&format!("rod{i}")];
        assert_eq!(p.shape, [4, rod.n_elements + 1, 3]);
        let flat: Vec<f64> = rod.points.iter().flatten().copied().collect();
        // Bit-exact, including the sign of -0.0.
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&p.f64s()), bits(&flat));
        let d = &arrays[&format!("rod{i}_directors")];
        assert_eq!(d.shape, [4, rod.n_elements, 3]);
        let flat: Vec<f64> = rod.directors.iter().flatten().copied().collect();
        assert_eq!(d.f64s(), flat);
        let v = &arrays[&format!("rod{i}_velocities")];
        assert_eq!(v.shape, [4, rod.n_elements + 1, 3]);
        let f = &arrays[&format!("rod{i}_contact_force")];
        assert_eq!(f.shape, [4, rod.n_elements + 1]);
        assert_eq!(f.f64s(), rod.contact_forces);
        let e = &arrays[&format!("rod{i}_strain")];
        assert_eq!(e.shape, [4, rod.n_elements]);
        assert_eq!(e.f64s(), rod.strains);
    }
    // Frame-major C order: element [t, k, c] sits at (t * (n + 1) + k) * 3 + c.
    let rod0 = arrays["rod0"].f64s();
    assert_eq!(
        rod0[(2 * 4 + 3) * 3],
        traj.rods[0].frame_points(2).unwrap()[3][0]
    );

    assert_eq!(arrays["rod_radii"].f64s(), [0.00035, 1.0 / 3.0]);
    let names = &arrays["rod_names"];
    assert_eq!(names.descr, "<U10");
    assert_eq!(names.shape, [2]);
    let decoded: Vec<String> = names
        .data
        .chunks_exact(40)
        .map(|s| {
            s.chunks_exact(4)
                .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
                .filter(|&c| c != 0)
                .map(|c| char::from_u32(c).unwrap())
                .collect()
        })
        .collect();
    assert_eq!(decoded, ["guidewire", "catheter ø"]);
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn npz_keeps_non_finite_values_and_handles_no_frames() {
    let dir = scratch("npz-edge");
    let mut traj = sample(1);
    traj.rods[1].points[0][0] = f64::NAN;
    traj.rods[1].directors[0][2] = f64::NEG_INFINITY;
    let path = dir.join("t.npz");
    write_npz(&path, &traj).unwrap();
    let arrays = read_npz_arrays(&path);
    assert!(arrays["rod1"].f64s()[0].is_nan());
    assert_eq!(arrays["rod1_directors"].f64s()[2], f64::NEG_INFINITY);

    let mut empty = Trajectory::new();
    empty.add_rod("r", 1.0, 2).unwrap();
    write_npz(&path, &empty).unwrap();
    let arrays = read_npz_arrays(&path);
    assert_eq!(arrays["times"].shape, [0]);
    assert_eq!(arrays["rod0"].shape, [0, 3, 3]);
    assert!(arrays["rod0"].data.is_empty());
    assert_eq!(arrays["rod0_directors"].shape, [0, 2, 3]);

    write_npz(&path, &Trajectory::new()).unwrap();
    let arrays = read_npz_arrays(&path);
    assert_eq!(arrays["rod_names"].descr, "<U1");
    assert_eq!(arrays["rod_names"].shape, [0]);
    fs::remove_dir_all(&dir).unwrap();
}

// -------------------------------------------------------------- XML checking

#[derive(Debug)]
struct Element {
    name: String,
    attrs: HashMap<String, String>,
    text: String,
    children: Vec<Element>,
}

impl Element {
    fn child(&self, name: &str) -> &Element {
        let mut it = self.children.iter().filter(|c| c.name == name);
        let c = it.next().unwrap_or_else(|| panic!("no <{name}>"));
        assert!(it.next().is_none(), "several <{name}>");
        c
    }

    fn array(&self, name: &str) -> &Element {
        let mut it = self.children.iter().filter(|c| {
            c.name == "DataArray" && c.attrs.get("Name").map(String::as_str) == Some(name)
        });
        let c = it.next().unwrap_or_else(|| panic!("no array {name}"));
        assert!(it.next().is_none(), "several arrays {name}");
        c
    }

    fn attr<T: std::str::FromStr>(&self, name: &str) -> T
    where
        T::Err: std::fmt::Debug,
    {
        self.attrs[name].parse().unwrap()
    }
}

/// A strict parser for the XML subset the writers emit: a `<?xml …?>`
/// declaration, then one element tree with double-quoted attributes and
/// text without entities. Panics on anything malformed (unbalanced tags,
/// stray `<`/`&`, text after the root).
fn parse_xml(doc: &str) -> Element {
    let rest = doc
        .strip_prefix("<?xml version=\"1.0\"?>")
        .expect("declaration");
    let mut stack: Vec<Element> = Vec::new();
    let mut root = None;
    let mut rest = rest;
    loop {
        let lt = rest.find('<');
        let text = &rest[..lt.unwrap_or(rest.len())];
        assert!(
            !text.contains('>') && !text.contains('&'),
            "bad text {text:?}"
        );
        match stack.last_mut() {
            Some(top) => top.text.push_str(text),
            None => assert!(text.trim().is_empty(), "text outside root: {text:?}"),
        }
        let Some(lt) = lt else { break };
        let gt = rest[lt..].find('>').expect("unclosed tag") + lt;
        let tag = &rest[lt + 1..gt];
        rest = &rest[gt + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let el = stack.pop().expect("close without open");
            assert_eq!(el.name, name, "mismatched close tag");
            match stack.last_mut() {
                Some(top) => top.children.push(el),
                None => {
                    assert!(root.is_none(), "two roots");
                    root = Some(el);
                }
            }
            continue;
        }
        let (tag, empty) = match tag.strip_suffix('/') {
            Some(t) => (t, true),
            None => (tag, false),
        };
        assert!(!tag.contains('<'));
        let (name, mut attrs_src) = tag.split_once(' ').unwrap_or((tag, ""));
        assert!(!name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric()));
        let mut attrs = HashMap::new();
        loop {
            attrs_src = attrs_src.trim_start();
            if attrs_src.is_empty() {
                break;
            }
            let (key, after) = attrs_src.split_once("=\"").expect("attribute");
            let (value, after) = after.split_once('"').expect("closing quote");
            assert!(!value.contains('<') && !value.contains('&'));
            assert!(
                attrs.insert(key.to_owned(), value.to_owned()).is_none(),
                "duplicate attribute {key}"
            );
            attrs_src = after;
        }
        let el = Element {
            name: name.to_owned(),
            attrs,
            text: String::new(),
            children: Vec::new(),
        };
        if empty {
            stack.last_mut().expect("empty root").children.push(el);
        } else {
            assert!(!stack.is_empty() || root.is_none(), "two roots");
            stack.push(el);
        }
    }
    assert!(stack.is_empty(), "unclosed elements");
    root.expect("no root element")
}

/// A `.vtp` file as written: its XML (with the appended data cut out) and the
/// appended bytes after the `_` marker.
fn read_vtp(path: &Path) -> (Element, Vec<u8>) {
    let bytes = fs::read(path).unwrap();
    let marker = b"<AppendedData encoding=\"raw\">\n_";
    let at = bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .expect("appended data");
    let head = std::str::from_utf8(&bytes[..at]).unwrap();
    let tail = b"\n</AppendedData>\n</VTKFile>\n";
    assert!(
        bytes.ends_with(tail),
        "file does not end with the appended data"
    );
    let data = bytes[at + marker.len()..bytes.len() - tail.len()].to_vec();
    let root = parse_xml(&format!("{head}</VTKFile>"));
    assert_eq!(root.attrs["header_type"], "UInt64");
    assert_eq!(root.attrs["compressor"], "vtkZLibDataCompressor");
    (root, data)
}

/// The raw bytes of an appended, zlib-compressed array: the block header
/// (count, block size, last partial size, compressed sizes) is checked
/// against the data it describes.
fn appended_bytes(array: &Element, data: &[u8]) -> Vec<u8> {
    assert_eq!(array.attrs["format"], "appended");
    let offset: usize = array.attr("offset");
    let word = |k: usize| {
        let o = offset + 8 * k;
        u64::from_le_bytes(data[o..o + 8].try_into().unwrap()) as usize
    };
    let (blocks, block, last) = (word(0), word(1), word(2));
    let mut at = offset + 8 * (3 + blocks);
    let mut out = Vec::new();
    for b in 0..blocks {
        let size = word(3 + b);
        let mut z = flate2::read::ZlibDecoder::new(&data[at..at + size]);
        let mut chunk = Vec::new();
        z.read_to_end(&mut chunk).unwrap();
        let expected = if b + 1 == blocks && last != 0 {
            last
        } else {
            block
        };
        assert_eq!(
            chunk.len(),
            expected,
            "block {b} of {}",
            array.attrs["Name"]
        );
        out.extend_from_slice(&chunk);
        at += size;
    }
    out
}

fn f64_array(array: &Element, data: &[u8]) -> Vec<f64> {
    assert_eq!(array.attrs["type"], "Float64");
    appended_bytes(array, data)
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn i64_array(array: &Element, data: &[u8]) -> Vec<i64> {
    assert_eq!(array.attrs["type"], "Int64");
    appended_bytes(array, data)
        .chunks_exact(8)
        .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn i32_array(array: &Element, data: &[u8]) -> Vec<i32> {
    assert_eq!(array.attrs["type"], "Int32");
    appended_bytes(array, data)
        .chunks_exact(4)
        .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

#[test]
fn vtp_series_round_trips() {
    let dir = scratch("vtp").join("series");
    let traj = sample(3);
    write_vtp_series(&dir, &traj).unwrap();

    let pvd = parse_xml(&fs::read_to_string(dir.join(PVD_FILE_NAME)).unwrap());
    assert_eq!(pvd.name, "VTKFile");
    assert_eq!(pvd.attrs["type"], "Collection");
    let sets = &pvd.child("Collection").children;
    assert_eq!(sets.len(), 3);

    for (frame, set) in sets.iter().enumerate() {
        assert_eq!(set.name, "DataSet");
        assert_eq!(set.attr::<f64>("timestep"), traj.times[frame]);
        assert_eq!(set.attrs["file"], vtp_frame_file_name(frame));
        assert_eq!(set.attrs["file"], format!("frame_0000{frame}.vtp"));
        let (vtp, data) = read_vtp(&dir.join(&set.attrs["file"]));
        assert_eq!(vtp.attrs["type"], "PolyData");
        let poly = vtp.child("PolyData");
        let time = f64_array(poly.child("FieldData").array("TimeValue"), &data);
        assert_eq!(time, [traj.times[frame]]);
        let piece = poly.child("Piece");
        assert_eq!(piece.attr::<usize>("NumberOfPoints"), 4 + 2);
        assert_eq!(piece.attr::<usize>("NumberOfLines"), 3 + 1);

        let points = piece.child("Points").array("Points");
        assert_eq!(points.attrs["NumberOfComponents"], "3");
        let expected: Vec<f64> = traj
            .rods
            .iter()
            .flat_map(|r| r.frame_points(frame).unwrap().iter().flatten().copied())
            .collect();
        let got = f64_array(points, &data);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got), bits(&expected));

        let lines = piece.child("Lines");
        assert_eq!(
            i64_array(lines.array("connectivity"), &data),
            [0, 1, 1, 2, 2, 3, 4, 5]
        );
        assert_eq!(i64_array(lines.array("offsets"), &data), [2, 4, 6, 8]);

        let pd = piece.child("PointData");
        assert_eq!(
            f64_array(pd.array("radius"), &data),
            [0.00035, 0.00035, 0.00035, 0.00035, 1.0 / 3.0, 1.0 / 3.0]
        );
        assert_eq!(i32_array(pd.array("rod_id"), &data), [0, 0, 0, 0, 1, 1]);
        // d1 at a point is the mean of its elements' (an end point has one).
        let d = traj.rods[0].frame_directors(frame).unwrap();
        let at_points = f64_array(pd.array("d1"), &data);
        assert_eq!(&at_points[..3], &d[0]);
        assert_eq!(at_points[4], 0.5 * (d[0][1] + d[1][1]));
        assert_eq!(at_points.len(), 3 * 6);
        assert_eq!(
            f64_array(pd.array("velocity"), &data),
            traj.rods
                .iter()
                .flat_map(|r| r.frame_velocities(frame).unwrap().iter().flatten().copied())
                .collect::<Vec<_>>()
        );
        assert_eq!(
            f64_array(pd.array("contact_force"), &data),
            traj.rods
                .iter()
                .flat_map(|r| r.frame_contact_forces(frame).unwrap().iter().copied())
                .collect::<Vec<_>>()
        );

        let cd = piece.child("CellData");
        assert_eq!(cd.attrs["Vectors"], "d1");
        let expected: Vec<f64> = traj
            .rods
            .iter()
            .flat_map(|r| r.frame_directors(frame).unwrap().iter().flatten().copied())
            .collect();
        assert_eq!(f64_array(cd.array("d1"), &data), expected);
        assert_eq!(i32_array(cd.array("rod_id"), &data), [0, 0, 0, 1]);
        assert_eq!(i32_array(cd.array("element"), &data), [0, 1, 2, 0]);
        assert_eq!(
            f64_array(cd.array("strain"), &data),
            traj.rods
                .iter()
                .flat_map(|r| r.frame_strains(frame).unwrap().iter().copied())
                .collect::<Vec<_>>()
        );
    }
    fs::remove_dir_all(dir.parent().unwrap()).unwrap();
}

/// The environment is written once as triangles and listed as part 1 of
/// every time step; an array longer than one zlib block comes back whole.
#[test]
fn the_environment_mesh_is_written_beside_the_frames() {
    let dir = scratch("vtp-env").join("series");
    let mut traj = sample(2);
    // A strip of triangles long enough to span several 32 KiB blocks.
    let n = 3000;
    let vertices: Vec<[f64; 3]> = (0..n).map(|k| [k as f64, (k % 2) as f64, 0.5]).collect();
    let triangles: Vec<[u32; 3]> = (0..n as u32 - 2).map(|k| [k, k + 1, k + 2]).collect();
    traj.environment = Some(EnvironmentMesh {
        vertices: vertices.clone(),
        triangles: triangles.clone(),
    });
    write_vtp_series(&dir, &traj).unwrap();
    let pvd = parse_xml(&fs::read_to_string(dir.join(PVD_FILE_NAME)).unwrap());
    let sets = &pvd.child("Collection").children;
    assert_eq!(sets.len(), 4);
    assert_eq!(sets[1].attrs["file"], ENVIRONMENT_FILE_NAME);
    assert_eq!(sets[1].attrs["part"], "1");
    assert_eq!(sets[1].attr::<f64>("timestep"), traj.times[0]);
    let (vtp, data) = read_vtp(&dir.join(ENVIRONMENT_FILE_NAME));
    let piece = vtp.child("PolyData").child("Piece");
    assert_eq!(piece.attr::<usize>("NumberOfPolys"), n - 2);
    let points = f64_array(piece.child("Points").array("Points"), &data);
    assert_eq!(
        points,
        vertices.iter().flatten().copied().collect::<Vec<_>>()
    );
    let polys = piece.child("Polys");
    let connectivity = i64_array(polys.array("connectivity"), &data);
    assert_eq!(
        connectivity,
        triangles
            .iter()
            .flatten()
            .map(|&i| i64::from(i))
            .collect::<Vec<_>>()
    );
    assert_eq!(
        i64_array(polys.array("offsets"), &data).last(),
        Some(&(3 * (n as i64 - 2)))
    );

    // A triangle naming a missing vertex is refused before anything is written.
    let bad_dir = scratch("vtp-env-bad");
    if let Some(m) = traj.environment.as_mut() {
        m.triangles[5] = [0, 1, n as u32];
    }
    let err = write_vtp_series(&bad_dir.join("s"), &traj).unwrap_err();
    assert!(err.to_string().contains("triangle 5"), "{err}");
    assert!(!bad_dir.join("s").exists());
    fs::remove_dir_all(dir.parent().unwrap()).unwrap();
    fs::remove_dir_all(&bad_dir).unwrap();
}

/// `read_npz` gives back what `write_npz` wrote, optional quantities and the
/// environment included, bit for bit.
#[test]
fn npz_reads_back_into_the_same_trajectory() {
    let dir = scratch("npz-read");
    let mut traj = sample(3);
    traj.environment = Some(EnvironmentMesh {
        vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, -0.0], [0.0, 1e-300, 2.0]],
        triangles: vec![[0, 1, 2], [2, 1, 0]],
    });
    let path = dir.join("t.npz");
    write_npz(&path, &traj).unwrap();
    assert_eq!(read_npz(&path).unwrap(), traj);
    // Without optional quantities or environment.
    let mut plain = sample(2);
    for rod in &mut plain.rods {
        rod.velocities.clear();
        rod.contact_forces.clear();
        rod.strains.clear();
    }
    write_npz(&path, &plain).unwrap();
    assert_eq!(read_npz(&path).unwrap(), plain);
    // A file that is not an archive names itself.
    fs::write(&path, "not a zip").unwrap();
    let err = read_npz(&path).unwrap_err().to_string();
    assert!(err.contains("t.npz") && err.contains("zip"), "{err}");
    fs::remove_dir_all(&dir).unwrap();
}

/// Frames are spread evenly over the run: intervals differ by at most one
/// step, the first is the initial state and the last is the run's end.
#[test]
fn frame_steps_sample_evenly_to_the_end() {
    assert_eq!(frame_steps(10, 4), [0, 3, 5, 8, 10]);
    assert_eq!(frame_steps(2450, 1000).len(), 1001);
    assert_eq!(frame_steps(3, 100), [0, 1, 2, 3]);
    assert_eq!(frame_steps(700_000, 100).last(), Some(&700_000));
    for (steps, frames) in [
        (10, 4),
        (2450, 1000),
        (700_000, 100),
        (1001, 1000),
        (7, 7),
        (1, 1),
    ] {
        let s = frame_steps(steps, frames);
        assert_eq!(s[0], 0);
        assert_eq!(*s.last().unwrap(), steps);
        let gaps: Vec<u64> = s.windows(2).map(|w| w[1] - w[0]).collect();
        let (lo, hi) = (gaps.iter().min().unwrap(), gaps.iter().max().unwrap());
        assert!(
            *lo >= 1 && hi - lo <= 1,
            "{steps} steps, {frames} frames: gaps {lo}..{hi}"
        );
    }
}

#[test]
fn vtp_rejects_non_finite_before_writing() {
    let dir = scratch("vtp-nan");
    let mut traj = sample(2);
    traj.rods[0].points[5][1] = f64::INFINITY; // frame 1, point 1
    let err = write_vtp_series(&dir, &traj).unwrap_err();
    match &err {
        OutputError::Inconsistent {
            path,
            source: ShapeError::NonFinite { frame: 1, what, .. },
        } => {
            assert_eq!(path, &dir);
            assert_eq!(what, "rod 0 point 1");
        }
        other => panic!("unexpected {other:?}"),
    }
    assert!(err.to_string().contains(&*dir.to_string_lossy()));
    assert_eq!(fs::read_dir(&dir).unwrap().count(), 0, "nothing written");
    fs::remove_dir_all(&dir).unwrap();
}

// ------------------------------------------------------------ shape errors

#[test]
fn push_frame_rejects_bad_shapes_without_changing_anything() {
    // A frame that leaves out a quantity the first frame recorded is refused.
    let mut traj = sample(2);
    let err = traj
        .push_frame(
            9.0,
            &[
                RodFrame {
                    points: &[[0.0; 3]; 4],
                    directors: &[[0.0; 3]; 3],
                    ..Default::default()
                },
                RodFrame {
                    points: &[[0.0; 3]; 2],
                    directors: &[[0.0; 3]; 1],
                    ..Default::default()
                },
            ],
        )
        .unwrap_err();
    assert!(matches!(
        err,
        OutputError::Record(ShapeError::Length {
            rod: 0,
            what: "velocities",
            expected: 4,
            found: 0,
            ..
        })
    ));
    assert_eq!(traj, sample(2));

    let mut traj = sample(2);
    for rod in &mut traj.rods {
        rod.velocities.clear();
        rod.contact_forces.clear();
        rod.strains.clear();
    }
    let before = traj.clone();
    let p0 = [[0.0; 3]; 4];
    let d0 = [[0.0; 3]; 3];
    let p1 = [[0.0; 3]; 2];
    let d1 = [[0.0; 3]; 1];
    let frame = |p0: &'static [[f64; 3]], d1: &'static [[f64; 3]]| {
        [
            RodFrame {
                points: p0,
                directors: &[[0.0; 3]; 3],
                ..Default::default()
            },
            RodFrame {
                points: &[[0.0; 3]; 2],
                directors: d1,
                ..Default::default()
            },
        ]
    };

    // Wrong point count in the first rod.
    let err = traj
        .push_frame(9.0, &frame(&[[0.0; 3]; 5], &[[0.0; 3]; 1]))
        .unwrap_err();
    assert!(matches!(
        err,
        OutputError::Record(ShapeError::Length {
            rod: 0,
            what: "points",
            expected: 4,
            found: 5,
            ..
        })
    ));
    assert!(err.to_string().contains("guidewire"), "{err}");
    // Wrong director count in the second rod: the first must not be appended.
    let err = traj
        .push_frame(9.0, &frame(&[[0.0; 3]; 4], &[]))
        .unwrap_err();
    assert!(matches!(
        err,
        OutputError::Record(ShapeError::Length {
            rod: 1,
            what: "directors",
            expected: 1,
            found: 0,
            ..
        })
    ));
    // Wrong number of rods.
    let one = [RodFrame {
        points: &p0,
        directors: &d0,
        ..Default::default()
    }];
    let err = traj.push_frame(9.0, &one).unwrap_err();
    assert!(matches!(
        err,
        OutputError::Record(ShapeError::RodCount {
            expected: 2,
            found: 1
        })
    ));
    assert_eq!(traj, before);

    // Rods cannot be added once frames exist, and need an element.
    assert!(matches!(
        traj.add_rod("late", 1.0, 2),
        Err(OutputError::Record(ShapeError::FramesAlreadyRecorded {
            frames: 2,
            ..
        }))
    ));
    assert!(matches!(
        Trajectory::new().add_rod("empty", 1.0, 0),
        Err(OutputError::Record(ShapeError::NoElements { rod: 0, .. }))
    ));
    assert_eq!(traj, before);

    // A correct frame is accepted.
    let good = [
        RodFrame {
            points: &p0,
            directors: &d0,
            ..Default::default()
        },
        RodFrame {
            points: &p1,
            directors: &d1,
            ..Default::default()
        },
    ];
    traj.push_frame(9.0, &good).unwrap();
    assert_eq!(traj.n_frames(), 3);
    assert_eq!(traj.rods[1].n_frames(), 3);
    assert_eq!(traj.rods[1].frame_points(2).unwrap(), &p1);
    assert_eq!(traj.rods[0].frame_directors(3), None);
}

#[test]
fn writers_reject_inconsistent_trajectories_without_writing() {
    let dir = scratch("inconsistent");
    let mut traj = sample(2);
    traj.rods[1].points.pop();
    let npz = dir.join("t.npz");
    let err = write_npz(&npz, &traj).unwrap_err();
    match &err {
        OutputError::Inconsistent {
            path,
            source:
                ShapeError::Length {
                    rod: 1,
                    what: "points",
                    expected: 4,
                    found: 3,
                    ..
                },
        } => assert_eq!(path, &npz),
        other => panic!("unexpected {other:?}"),
    }
    assert!(err.to_string().contains("t.npz"), "{err}");
    assert!(!npz.exists());

    let mut traj = sample(2);
    traj.times.push(1.0);
    let series = dir.join("series");
    assert!(matches!(
        write_vtp_series(&series, &traj),
        Err(OutputError::Inconsistent { .. })
    ));
    assert!(!series.exists());

    let mut traj = sample(1);
    traj.rods[0].n_elements = 0;
    assert!(matches!(
        write_npz(&npz, &traj),
        Err(OutputError::Inconsistent {
            source: ShapeError::NoElements { rod: 0, .. },
            ..
        })
    ));
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn io_errors_name_the_path() {
    let dir = scratch("io");
    let path = dir.join("missing-dir").join("t.npz");
    let err = write_npz(&path, &sample(1)).unwrap_err();
    assert!(matches!(&err, OutputError::Io { path: p, .. } if p == &path));
    assert!(err.to_string().contains("missing-dir"), "{err}");

    // A regular file where the series directory should be.
    let blocker = dir.join("blocker");
    fs::write(&blocker, "x").unwrap();
    let err = write_vtp_series(&blocker.join("series"), &sample(1)).unwrap_err();
    assert!(matches!(err, OutputError::Io { .. }), "{err:?}");
    fs::remove_dir_all(&dir).unwrap();
}
