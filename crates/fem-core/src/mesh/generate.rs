//! Procedural box/beam meshes, so scenes need no mesh file.
//!
//! Each hexahedral cell is split into six tetrahedra along its main diagonal (the Freudenthal /
//! Kuhn split), which is conforming across cells without alternating patterns.

use super::TetMesh;
use crate::{FemError, Vec3};

/// A box `[origin, origin + size]` divided into `cells` hexahedra.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// The only generated shape so far; kept so scene files can say what they generate.
    #[serde(default)]
    pub kind: GeneratedShape,
    /// Edge lengths of the box.
    pub size: [f64; 3],
    /// Number of cells along each axis (each ≥ 1).
    pub cells: [usize; 3],
    /// Minimum corner.
    #[serde(default)]
    pub origin: [f64; 3],
}

/// Shapes the generator can build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GeneratedShape {
    /// An axis-aligned box (a beam when one side is long).
    #[default]
    Box,
}

impl Default for BoxSpec {
    fn default() -> Self {
        Self {
            kind: GeneratedShape::Box,
            size: [1.0, 0.1, 0.1],
            cells: [20, 2, 2],
            origin: [0.0; 3],
        }
    }
}

/// Largest mesh the generator builds, to refuse typos like `cells = [1000000, 1000, 1000]`.
pub const MAX_GENERATED_VERTICES: usize = 20_000_000;

impl BoxSpec {
    /// Appends one error per invalid field (named as in a scene: `mesh.generate.…`).
    pub fn check(&self, errors: &mut Vec<FemError>) {
        let mut bad =
            |field: String, reason: String| errors.push(FemError::InvalidConfig { field, reason });
        for a in 0..3 {
            if !(self.size[a].is_finite() && self.size[a] > 0.0) {
                bad(
                    format!("mesh.generate.size[{a}]"),
                    format!("must be a positive finite length, got {}", self.size[a]),
                );
            }
            if !self.origin[a].is_finite() {
                bad(
                    format!("mesh.generate.origin[{a}]"),
                    format!("must be finite, got {}", self.origin[a]),
                );
            }
            if self.cells[a] == 0 {
                bad(
                    format!("mesh.generate.cells[{a}]"),
                    "must be at least 1".into(),
                );
            }
        }
        if self.num_vertices().is_none() {
            bad(
                "mesh.generate.cells".into(),
                format!("more than {MAX_GENERATED_VERTICES} vertices"),
            );
        }
    }

    /// (nx+1)(ny+1)(nz+1), when at most [`MAX_GENERATED_VERTICES`].
    fn num_vertices(&self) -> Option<usize> {
        let [nx, ny, nz] = self.cells;
        nx.checked_add(1)
            .and_then(|c| c.checked_mul(ny.checked_add(1)?))
            .and_then(|c| c.checked_mul(nz.checked_add(1)?))
            .filter(|&c| c <= MAX_GENERATED_VERTICES)
    }
}

/// Builds a box mesh with 6 tets per cell, positively oriented.
pub fn box_mesh(spec: &BoxSpec) -> Result<TetMesh, FemError> {
    let mut errors = Vec::new();
    spec.check(&mut errors);
    FemError::collect(errors)?;
    let count = spec.num_vertices().expect("checked above");
    let [nx, ny, nz] = spec.cells;
    let idx = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);
    let mut vertices = Vec::with_capacity(count);
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                vertices.push(Vec3::new(
                    spec.origin[0] + spec.size[0] * i as f64 / nx as f64,
                    spec.origin[1] + spec.size[1] * j as f64 / ny as f64,
                    spec.origin[2] + spec.size[2] * k as f64 / nz as f64,
                ));
            }
        }
    }
    // Paths from corner 000 to 111 through one axis at a time: one tet per axis permutation.
    const PERMS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for p in PERMS {
                    let mut c = [0usize; 3];
                    let mut tet = [idx(i, j, k); 4];
                    for (s, &axis) in p.iter().enumerate() {
                        c[axis] = 1;
                        tet[s + 1] = idx(i + c[0], j + c[1], k + c[2]);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    let mut mesh = TetMesh { vertices, tets };
    for t in 0..mesh.tets.len() {
        if mesh.signed_volume(t) < 0.0 {
            mesh.tets[t].swap(2, 3);
        }
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_volume_and_counts() {
        let m = box_mesh(&BoxSpec {
            size: [2.0, 0.5, 0.25],
            cells: [4, 3, 2],
            origin: [1.0, -1.0, 0.0],
            ..Default::default()
        })
        .unwrap();
        assert_eq!(m.num_vertices(), 5 * 4 * 3);
        assert_eq!(m.num_tets(), 6 * 24);
        let vol = m.volume();
        assert!((vol - 0.25).abs() < 1e-12, "{vol}");
        assert!((0..m.num_tets()).all(|t| m.signed_volume(t) > 0.0));
        // A closed box surface: 2 triangles per boundary quad.
        let quads = 2 * (4 * 3 + 3 * 2 + 4 * 2);
        assert_eq!(m.surface_triangles().len(), 2 * quads);
    }

    #[test]
    fn rejects_bad_specs() {
        assert!(
            box_mesh(&BoxSpec {
                cells: [0, 1, 1],
                ..Default::default()
            })
            .is_err()
        );
        assert!(
            box_mesh(&BoxSpec {
                size: [f64::NAN, 1.0, 1.0],
                ..Default::default()
            })
            .is_err()
        );
        assert!(
            box_mesh(&BoxSpec {
                cells: [100_000, 100_000, 100_000],
                ..Default::default()
            })
            .is_err()
        );
    }
}
