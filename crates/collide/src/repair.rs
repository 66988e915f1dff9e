//! Orientation repair of a mesh as it comes from a scanner or a segmentation: triangles wound
//! the wrong way, loose fragments, openings.
//!
//! Contacts push a point along the wall's normal into the lumen, so a patch of triangles wound
//! the other way pushes points out through the wall. Meshes of real anatomy carry such patches
//! (a segmentation's seams, pieces merged from several files), and one sign test over the whole
//! mesh cannot fix a patch. The repair walks each connected piece triangle by triangle across
//! its shared edges and winds every triangle to agree with the one it was reached from (two
//! triangles agree when they run their shared edge in opposite directions); it then turns each
//! piece as a whole so that its normals point into the volume it encloses, with its openings
//! closed for that measure. What it did, and what it found (pieces, openings, edges shared by
//! more than two triangles), is returned for the user to see.

use std::collections::HashMap;

use crate::mesh::TriMesh;
use crate::winding::{caps_of, closed_volume};

/// What [`TriMesh::repair_orientation`] found and changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OrientationRepair {
    /// Triangles per connected piece, largest first (pieces meet across shared edges).
    pub pieces: Vec<usize>,
    /// Edges whose two triangles ran them the same way, before the repair.
    pub misoriented_before: usize,
    /// The same after the repair (0 unless a piece cannot be oriented, as a Möbius strip).
    pub misoriented_after: usize,
    /// Triangles whose winding the repair reversed.
    pub flipped: usize,
    /// Edges used by more than two triangles (left as they are; the walk does not cross them).
    pub non_manifold_edges: usize,
    /// Openings: boundary loops, closed by the inside test for itself.
    pub openings: usize,
    /// Volume enclosed by the whole mesh, openings closed, after the repair [units³] (positive:
    /// the normals point into it).
    pub lumen_volume: f64,
}

impl OrientationRepair {
    /// Pieces beyond the largest: loose fragments.
    pub fn fragments(&self) -> usize {
        self.pieces.len().saturating_sub(1)
    }
}

/// Edges keyed by their sorted vertices: the triangles using each, with the direction each runs it
/// (`true`: from the smaller vertex to the larger).
fn edge_uses(triangles: &[[u32; 3]]) -> HashMap<(u32, u32), Vec<(usize, bool)>> {
    let mut edges: HashMap<(u32, u32), Vec<(usize, bool)>> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (u, v) = (tri[k], tri[(k + 1) % 3]);
            edges
                .entry((u.min(v), u.max(v)))
                .or_default()
                .push((t, u < v));
        }
    }
    edges
}

fn misoriented(edges: &HashMap<(u32, u32), Vec<(usize, bool)>>) -> usize {
    edges
        .values()
        .filter(|uses| uses.len() == 2 && uses[0].1 == uses[1].1)
        .count()
}

impl TriMesh {
    /// Winds every connected piece consistently and turns each so that its normals point into
    /// the volume it encloses (the lumen); see the [module docs](crate::repair).
    pub fn repair_orientation(&mut self) -> OrientationRepair {
        let n = self.triangles().len();
        let edges = edge_uses(self.triangles());
        let mut report = OrientationRepair {
            misoriented_before: misoriented(&edges),
            non_manifold_edges: edges.values().filter(|u| u.len() > 2).count(),
            ..OrientationRepair::default()
        };
        // Neighbours across manifold edges.
        let mut neighbours: Vec<Vec<(usize, (u32, u32))>> = vec![Vec::new(); n];
        for (&key, uses) in &edges {
            if let [(a, _), (b, _)] = uses[..] {
                neighbours[a].push((b, key));
                neighbours[b].push((a, key));
            }
        }
        let runs = |tri: &[u32; 3], (lo, hi): (u32, u32)| -> bool {
            (0..3).any(|k| tri[k] == lo && tri[(k + 1) % 3] == hi)
        };
        let mut tris = self.triangles().to_vec();
        let mut piece_of = vec![usize::MAX; n];
        let mut pieces: Vec<Vec<usize>> = Vec::new();
        let mut flipped = vec![false; n];
        for seed in 0..n {
            if piece_of[seed] != usize::MAX {
                continue;
            }
            let id = pieces.len();
            let mut members = vec![seed];
            piece_of[seed] = id;
            let mut k = 0;
            while k < members.len() {
                let t = members[k];
                k += 1;
                for &(m, key) in &neighbours[t] {
                    if piece_of[m] != usize::MAX {
                        continue;
                    }
                    // Agreeing neighbours run the shared edge in opposite directions.
                    if runs(&tris[t], key) == runs(&tris[m], key) {
                        tris[m].swap(1, 2);
                        flipped[m] = !flipped[m];
                    }
                    piece_of[m] = id;
                    members.push(m);
                }
            }
            pieces.push(members);
        }
        // Each piece's normals into the volume it encloses; a sheet (no volume) keeps the
        // orientation of its seed.
        let vertices = self.vertices().to_vec();
        for members in &pieces {
            let own: Vec<[u32; 3]> = members.iter().map(|&t| tris[t]).collect();
            if closed_volume(&vertices, &own) > 0.0 {
                for &t in members {
                    tris[t].swap(1, 2);
                    flipped[t] = !flipped[t];
                }
            }
        }
        report.flipped = flipped.iter().filter(|&&f| f).count();
        report.misoriented_after = misoriented(&edge_uses(&tris));
        report.openings = caps_of(&vertices, &tris).len();
        report.lumen_volume = -closed_volume(&vertices, &tris);
        let mut sizes: Vec<usize> = pieces.iter().map(Vec::len).collect();
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        report.pieces = sizes;
        self.set_triangles_same_vertices(tris);
        report
    }
}
