//! Checks run on every mesh that enters the program (DESIGN §3).

use std::path::Path;

use super::TetMesh;
use crate::MeshError;

/// What validation found and fixed.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ValidationReport {
    /// Tets whose rest orientation was negative and were flipped (two indices swapped).
    pub flipped_tets: usize,
    /// Vertices that no tet references. They are kept (indices stay stable) but carry no mass.
    pub unreferenced_vertices: usize,
    /// Smallest |volume| divided by the mean |volume|.
    pub min_relative_volume: f64,
    /// Connected pieces (tets sharing a vertex are connected). More than one is allowed, but
    /// every piece needs its own support in a scene.
    pub components: usize,
}

/// Relative volume below which a tet counts as degenerate: |V_e| < EPS · mean |V|.
pub const DEGENERATE_RELATIVE_VOLUME: f64 = 1e-10;

/// Validates `mesh` in place: indices in range, finite coordinates, no degenerate or duplicate
/// tets, positive orientation (inverted rest tets are flipped and counted); counts unreferenced
/// vertices and connected pieces. `path` names the source in errors.
pub fn validate(mesh: &mut TetMesh, path: &Path) -> Result<ValidationReport, MeshError> {
    validate_located(mesh, path, &|_| None)
}

/// [`validate`], naming the line of a refused tet: `line_of_tet(t)` is the 1-based line of tet
/// `t` in the file it was read from, when known.
pub fn validate_located(
    mesh: &mut TetMesh,
    path: &Path,
    line_of_tet: &dyn Fn(usize) -> Option<usize>,
) -> Result<ValidationReport, MeshError> {
    let invalid = |reason: String| MeshError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    // "tetrahedron 8 of 2475 (line 42)": counted from 1 in the file's order, as the readers
    // count, so a user finds it in the file.
    let count = mesh.tets.len();
    let tet = |t: usize| match line_of_tet(t) {
        Some(line) => format!("tetrahedron {} of {count} (line {line})", t + 1),
        None => format!("tetrahedron {} of {count}", t + 1),
    };
    // Four vertices, counted from 1 in the file's order.
    let vertices_of = |v: &[usize; 4]| {
        format!(
            "{}, {}, {}, {} (counted from 1 in the order the file lists them)",
            v[0] + 1,
            v[1] + 1,
            v[2] + 1,
            v[3] + 1
        )
    };
    if mesh.tets.is_empty() {
        return Err(invalid("the mesh has no tetrahedra".into()));
    }
    let n = mesh.vertices.len();
    if let Some((i, v)) = mesh
        .vertices
        .iter()
        .enumerate()
        .find(|(_, v)| !v.iter().all(|c| c.is_finite()))
    {
        return Err(invalid(format!(
            "vertex {} of {n} has a non-finite coordinate ({}, {}, {})",
            i + 1,
            v.x,
            v.y,
            v.z
        )));
    }
    let mut referenced = vec![false; n];
    for (t, vertices) in mesh.tets.iter().enumerate() {
        for &i in vertices {
            if i >= n {
                return Err(invalid(format!(
                    "{} references vertex {} (counted from 1) but the mesh has {n} vertices",
                    tet(t),
                    i + 1
                )));
            }
            referenced[i] = true;
        }
        for a in 0..4 {
            for b in a + 1..4 {
                if vertices[a] == vertices[b] {
                    return Err(invalid(format!(
                        "{} uses vertex {} twice: its vertices are {}",
                        tet(t),
                        vertices[a] + 1,
                        vertices_of(vertices)
                    )));
                }
            }
        }
    }
    let volumes: Vec<f64> = (0..mesh.tets.len())
        .map(|t| mesh.signed_volume(t))
        .collect();
    // Finite coordinates can still overflow a volume (|x| near 1e100 and beyond).
    if let Some(t) = volumes.iter().position(|v| !v.is_finite()) {
        return Err(invalid(format!(
            "{}, on vertices {}, has a non-finite volume: its coordinates are too large",
            tet(t),
            vertices_of(&mesh.tets[t])
        )));
    }
    let mean = volumes.iter().map(|v| v.abs()).sum::<f64>() / volumes.len() as f64;
    if !mean.is_finite() {
        return Err(invalid(
            "the total volume overflows: the coordinates are too large".into(),
        ));
    }
    if mean <= 0.0 {
        return Err(invalid("all tetrahedra have zero volume".into()));
    }
    let mut report = ValidationReport {
        min_relative_volume: f64::INFINITY,
        ..Default::default()
    };
    for (t, &v) in volumes.iter().enumerate() {
        let rel = v.abs() / mean;
        if rel < DEGENERATE_RELATIVE_VOLUME {
            return Err(invalid(format!(
                "{}, on vertices {}, is degenerate (volume {v:.3e}, {rel:.1e} of the mean): \
                 mesh it again with a quality bound, e.g. `tetgen -pq1.4` (not `-p` alone), \
                 gmsh's `-optimize_netgen` or fTetWild",
                tet(t),
                vertices_of(&mesh.tets[t])
            )));
        }
        report.min_relative_volume = report.min_relative_volume.min(rel);
        if v < 0.0 {
            mesh.tets[t].swap(2, 3);
            report.flipped_tets += 1;
            // Its volume computed again in the new order: one lost in the round-off of far
            // coordinates (5·10⁷ beside 1) can come out of the swap without a sign.
            let w = mesh.signed_volume(t);
            if w <= 0.0 {
                return Err(invalid(format!(
                    "{}, on vertices {}, is degenerate: its volume ({v:.3e}, then {w:.3e} turned \
                     the other way) is lost in the round-off of its coordinates",
                    tet(t),
                    vertices_of(&mesh.tets[t])
                )));
            }
        }
    }
    // Two tets on the same four vertices overlap: their mass and stiffness would count twice.
    let mut sorted: Vec<([usize; 4], usize)> = mesh
        .tets
        .iter()
        .enumerate()
        .map(|(t, tet)| {
            let mut key = *tet;
            key.sort_unstable();
            (key, t)
        })
        .collect();
    sorted.sort_unstable();
    if let Some(w) = sorted.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(invalid(format!(
            "{} and {} use the same four vertices, {} (a duplicate element)",
            tet(w[0].1),
            tet(w[1].1),
            vertices_of(&w[0].0)
        )));
    }
    report.unreferenced_vertices = referenced.iter().filter(|r| !**r).count();
    report.components = mesh.vertex_components().1;
    if report.flipped_tets > 0 {
        let n = report.flipped_tets;
        tracing::warn!(
            "{}: {n} {} wound inside out (inverted at rest) and {} reoriented",
            path.display(),
            if n == 1 { "tet was" } else { "tets were" },
            if n == 1 { "is" } else { "are" }
        );
    }
    if report.components > 1 {
        tracing::warn!(
            "{}: the mesh has {} disconnected pieces",
            path.display(),
            report.components
        );
    }
    if report.unreferenced_vertices > 0 {
        let n = report.unreferenced_vertices;
        tracing::warn!(
            "{}: {n} {} by no tet (not part of the body: {} not move, and the body's size and \
             pin planes are taken without {})",
            path.display(),
            if n == 1 {
                "vertex is used"
            } else {
                "vertices are used"
            },
            if n == 1 { "it does" } else { "they do" },
            if n == 1 { "it" } else { "them" }
        );
    }
    Ok(report)
}
