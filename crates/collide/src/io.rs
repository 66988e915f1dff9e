//! Reading meshes from Wavefront OBJ and STL (binary and ASCII).
//!
//! Anatomy meshes come from segmentation tools as OBJ or STL, usually in millimetres, while the
//! simulator works in metres; every loader therefore takes a unit `scale` (e.g. `0.001` for
//! mm → m) applied to the coordinates as they are read.
//!
//! The parsers are small and hand-written on purpose: only positions and faces matter here, and a
//! hand-written parser can report the exact line and value of every problem. All results go
//! through the same validation as [`TriMesh::new`], so a bad file is an error or a counted repair,
//! never a panic.
//!
//! * OBJ: `v x y z [w]` and `f` lines (indices `i`, `i/t`, `i//n`, `i/t/n`, 1-based or negative
//!   relative); polygons are fan-triangulated; all other statements are ignored.
//! * STL: binary when the size matches `84 + 50·n` for the count `n` in the header, ASCII when the
//!   text starts with `solid` and has `facet`/`vertex` statements; corners with bit-identical
//!   coordinates are welded into shared vertices (STL stores each corner separately), which is what
//!   makes the manifold check meaningful.

use std::collections::HashMap;
use std::path::Path;

use crate::mesh::{MeshError, MeshReport, TriMesh, build};

fn check_scale(name: &str, scale: f64) -> Result<(), MeshError> {
    if scale.is_finite() && scale > 0.0 {
        Ok(())
    } else {
        Err(MeshError::InvalidScale {
            path: name.to_string(),
            scale,
        })
    }
}

fn read(path: &Path) -> Result<Vec<u8>, MeshError> {
    std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Loads an OBJ or STL file, chosen by extension (`.obj`, `.stl`, case-insensitive; anything else
/// is sniffed: OBJ if it looks like text with `v ` lines, STL otherwise), scaling coordinates by
/// `scale`.
pub fn load_mesh(path: impl AsRef<Path>, scale: f64) -> Result<(TriMesh, MeshReport), MeshError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    check_scale(&name, scale)?;
    let bytes = read(path)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("obj") => parse_obj_bytes(&bytes, &name, scale),
        Some("stl") => parse_stl(&bytes, &name, scale),
        _ => {
            let head = &bytes[..bytes.len().min(4096)];
            let looks_obj = std::str::from_utf8(head).is_ok_and(|s| {
                s.lines()
                    .any(|l| l.starts_with("v ") || l.starts_with("v\t"))
            });
            if looks_obj {
                parse_obj_bytes(&bytes, &name, scale)
            } else {
                parse_stl(&bytes, &name, scale)
            }
        }
    }
}

/// Loads a Wavefront OBJ file, scaling coordinates by `scale`.
pub fn load_obj(path: impl AsRef<Path>, scale: f64) -> Result<(TriMesh, MeshReport), MeshError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    check_scale(&name, scale)?;
    let bytes = read(path)?;
    parse_obj_bytes(&bytes, &name, scale)
}

/// Loads a binary or ASCII STL file, scaling coordinates by `scale`.
pub fn load_stl(path: impl AsRef<Path>, scale: f64) -> Result<(TriMesh, MeshReport), MeshError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    check_scale(&name, scale)?;
    let bytes = read(path)?;
    parse_stl(&bytes, &name, scale)
}

fn parse_obj_bytes(
    bytes: &[u8],
    name: &str,
    scale: f64,
) -> Result<(TriMesh, MeshReport), MeshError> {
    let text = std::str::from_utf8(bytes).map_err(|e| MeshError::Parse {
        path: name.to_string(),
        line: Some(
            1 + bytes[..e.valid_up_to()]
                .iter()
                .filter(|&&b| b == b'\n')
                .count(),
        ),
        message: "not valid UTF-8 text (is this a binary file?)".to_string(),
    })?;
    parse_obj(text, name, scale)
}

/// Parses OBJ text. `name` labels errors (usually the file path).
pub fn parse_obj(text: &str, name: &str, scale: f64) -> Result<(TriMesh, MeshReport), MeshError> {
    check_scale(name, scale)?;
    let err = |line: usize, message: String| MeshError::Parse {
        path: name.to_string(),
        line: Some(line),
        message,
    };
    let mut verts: Vec<[f64; 3]> = Vec::new();
    let mut vert_lines: Vec<usize> = Vec::new();
    let mut tris: Vec<[i64; 3]> = Vec::new();
    let mut tri_lines: Vec<usize> = Vec::new();
    let mut poly: Vec<i64> = Vec::with_capacity(8);
    let mut short_faces = 0;
    for (ln0, raw) in text.lines().enumerate() {
        let ln = ln0 + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let mut p = [0.0; 3];
                for (k, slot) in p.iter_mut().enumerate() {
                    let tok = it.next().ok_or_else(|| {
                        err(ln, format!("vertex has {k} coordinates, expected 3"))
                    })?;
                    let x: f64 = tok
                        .parse()
                        .map_err(|_| err(ln, format!("invalid vertex coordinate {tok:?}")))?;
                    *slot = x * scale;
                }
                verts.push(p);
                vert_lines.push(ln);
            }
            Some("f") => {
                poly.clear();
                for tok in it {
                    let first = tok.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| err(ln, format!("invalid face index {tok:?}")))?;
                    // 1-based; negative is relative to the current end; 0 is invalid (maps to -1).
                    let idx = if i > 0 {
                        i - 1
                    } else if i < 0 {
                        verts.len() as i64 + i
                    } else {
                        -1
                    };
                    if idx < 0 || idx as usize >= verts.len() {
                        return Err(MeshError::IndexOutOfRange {
                            path: name.to_string(),
                            line: Some(ln),
                            triangle: tris.len(),
                            index: i,
                            vertex_count: verts.len(),
                        });
                    }
                    poly.push(idx);
                }
                // A face of one or two vertices has no area: dropped and reported, as a
                // zero-area triangle is.
                if poly.len() < 3 {
                    short_faces += 1;
                    continue;
                }
                for k in 1..poly.len() - 1 {
                    tris.push([poly[0], poly[k], poly[k + 1]]);
                    tri_lines.push(ln);
                }
            }
            _ => {}
        }
    }
    let (mesh, mut report) = build(verts, &tris, Some((&tri_lines, &vert_lines)), name, 0)?;
    report.short_faces_dropped = short_faces;
    Ok((mesh, report))
}

/// Parses STL data, binary or ASCII. `name` labels errors (usually the file path).
pub fn parse_stl(bytes: &[u8], name: &str, scale: f64) -> Result<(TriMesh, MeshReport), MeshError> {
    check_scale(name, scale)?;
    let binary_count = if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        (84 + 50 * n == bytes.len()).then_some(n)
    } else {
        None
    };
    let is_ascii = bytes.trim_ascii_start().starts_with(b"solid")
        && std::str::from_utf8(&bytes[..bytes.len().min(1024)])
            .is_ok_and(|s| s.contains("facet") || s.contains("endsolid"));
    if let Some(n) = binary_count
        && !is_ascii
    {
        return parse_stl_binary(bytes, n, name, scale);
    }
    if is_ascii {
        let text = std::str::from_utf8(bytes).map_err(|e| MeshError::Parse {
            path: name.to_string(),
            line: Some(
                1 + bytes[..e.valid_up_to()]
                    .iter()
                    .filter(|&&b| b == b'\n')
                    .count(),
            ),
            message: "ASCII STL is not valid UTF-8".to_string(),
        })?;
        return parse_stl_ascii(text, name, scale);
    }
    if bytes.len() < 84 {
        return Err(MeshError::Parse {
            path: name.to_string(),
            line: None,
            message: format!(
                "file is {} bytes: too short for a binary STL header (84 bytes) and not ASCII STL",
                bytes.len()
            ),
        });
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    Err(MeshError::Parse {
        path: name.to_string(),
        line: None,
        message: format!(
            "binary STL header announces {n} triangles ({} bytes) but the file has {} bytes",
            84 + 50 * n,
            bytes.len()
        ),
    })
}

/// Welds bit-identical corners into shared vertices.
struct Welder {
    map: HashMap<[u64; 3], u32>,
    verts: Vec<[f64; 3]>,
    lines: Vec<usize>,
    corners: usize,
}

impl Welder {
    fn new(cap: usize) -> Self {
        Self {
            map: HashMap::with_capacity(cap),
            verts: Vec::with_capacity(cap),
            lines: Vec::with_capacity(cap),
            corners: 0,
        }
    }
    fn add(&mut self, p: [f64; 3], line: usize) -> i64 {
        self.corners += 1;
        // +0.0 normalises -0.0 so the two zeros weld.
        let key = [
            (p[0] + 0.0).to_bits(),
            (p[1] + 0.0).to_bits(),
            (p[2] + 0.0).to_bits(),
        ];
        let next = self.verts.len() as u32;
        let id = *self.map.entry(key).or_insert(next);
        if id == next {
            self.verts.push(p);
            self.lines.push(line);
        }
        id as i64
    }
}

fn parse_stl_binary(
    bytes: &[u8],
    n: usize,
    name: &str,
    scale: f64,
) -> Result<(TriMesh, MeshReport), MeshError> {
    let mut w = Welder::new(n);
    let mut tris = Vec::with_capacity(n);
    for t in 0..n {
        let rec = &bytes[84 + 50 * t..84 + 50 * (t + 1)];
        let mut tri = [0i64; 3];
        for (k, slot) in tri.iter_mut().enumerate() {
            let mut p = [0.0; 3];
            for (c, pc) in p.iter_mut().enumerate() {
                let o = 12 + 12 * k + 4 * c;
                let x = f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]);
                if !x.is_finite() {
                    return Err(MeshError::Parse {
                        path: name.to_string(),
                        line: None,
                        message: format!(
                            "triangle {t}, corner {k} has a non-finite coordinate {x}"
                        ),
                    });
                }
                *pc = f64::from(x) * scale;
            }
            *slot = w.add(p, 0);
        }
        tris.push(tri);
    }
    let welded = w.corners - w.verts.len();
    build(w.verts, &tris, None, name, welded)
}

fn parse_stl_ascii(text: &str, name: &str, scale: f64) -> Result<(TriMesh, MeshReport), MeshError> {
    let err = |line: usize, message: String| MeshError::Parse {
        path: name.to_string(),
        line: Some(line),
        message,
    };
    let mut w = Welder::new(1024);
    let mut tris: Vec<[i64; 3]> = Vec::new();
    let mut tri_lines: Vec<usize> = Vec::new();
    let mut corner: Vec<i64> = Vec::with_capacity(3);
    let mut facet_line = 0;
    let mut in_facet = false;
    for (ln0, raw) in text.lines().enumerate() {
        let ln = ln0 + 1;
        let mut it = raw.split_whitespace();
        match it.next() {
            Some("facet") => {
                if in_facet {
                    return Err(err(ln, "facet starts before the previous endfacet".into()));
                }
                in_facet = true;
                facet_line = ln;
                corner.clear();
            }
            Some("vertex") => {
                if !in_facet {
                    return Err(err(ln, "vertex outside a facet".into()));
                }
                let mut p = [0.0; 3];
                for (k, slot) in p.iter_mut().enumerate() {
                    let tok = it.next().ok_or_else(|| {
                        err(ln, format!("vertex has {k} coordinates, expected 3"))
                    })?;
                    let x: f64 = tok
                        .parse()
                        .map_err(|_| err(ln, format!("invalid vertex coordinate {tok:?}")))?;
                    if !x.is_finite() {
                        return Err(MeshError::NonFiniteVertex {
                            path: name.to_string(),
                            line: Some(ln),
                            vertex: w.corners,
                            value: x,
                        });
                    }
                    *slot = x * scale;
                }
                corner.push(w.add(p, ln));
            }
            Some("endfacet") => {
                if corner.len() != 3 {
                    return Err(err(
                        facet_line,
                        format!("facet has {} vertices, expected 3", corner.len()),
                    ));
                }
                tris.push([corner[0], corner[1], corner[2]]);
                tri_lines.push(facet_line);
                in_facet = false;
            }
            _ => {}
        }
    }
    if in_facet {
        return Err(err(facet_line, "facet not closed by endfacet".into()));
    }
    let welded = w.corners - w.verts.len();
    let vl = w.lines.clone();
    build(w.verts, &tris, Some((&tri_lines, &vl)), name, welded)
}
