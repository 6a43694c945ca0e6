//! Vertex selections (axis plane, box, sphere, index list), pinned vertices and the map between
//! full degrees of freedom (3 per vertex) and the free ones the solvers work on.

use crate::{FemError, TetMesh, Vec3, four_digits};

/// Which side of the bounding box an axis plane sits on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    Min,
    Max,
}

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// Vertices within `tolerance` (mesh units) of the bounding box's min or max along `axis`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaneSelector {
    pub axis: Axis,
    pub side: Side,
    /// Absolute distance from the plane; default 1e-6 of the bounding-box diagonal.
    #[serde(default)]
    pub tolerance: Option<f64>,
}

/// Vertices inside an axis-aligned box.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSelector {
    #[serde(deserialize_with = "crate::exact::array")]
    pub min: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    pub max: [f64; 3],
}

/// Vertices inside a sphere.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSelector {
    #[serde(deserialize_with = "crate::exact::array")]
    pub center: [f64; 3],
    pub radius: f64,
}

/// A set of vertices, given by exactly one of its fields. Used by `[[pin]]` and `[[force]]`.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VertexSelection {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane: Option<PlaneSelector>,
    #[serde(default, rename = "box", skip_serializing_if = "Option::is_none")]
    pub aabb: Option<BoxSelector>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sphere: Option<SphereSelector>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub indices: Option<Vec<usize>>,
}

impl VertexSelection {
    pub fn plane(axis: Axis, side: Side, tolerance: Option<f64>) -> Self {
        Self {
            plane: Some(PlaneSelector {
                axis,
                side,
                tolerance,
            }),
            ..Default::default()
        }
    }

    pub fn sphere(center: [f64; 3], radius: f64) -> Self {
        Self {
            sphere: Some(SphereSelector { center, radius }),
            ..Default::default()
        }
    }

    /// The selected vertices, sorted. `field` names the selection in errors (e.g. `pin[0]`).
    /// Selecting nothing is an error: a pin or force that touches no vertex is a mistake.
    pub fn select(&self, mesh: &TetMesh, field: &str) -> Result<Vec<usize>, FemError> {
        let bad = |sub: &str, reason: String| FemError::InvalidConfig {
            field: format!("{field}{sub}"),
            reason,
        };
        let given = [
            self.plane.is_some(),
            self.aabb.is_some(),
            self.sphere.is_some(),
            self.indices.is_some(),
        ]
        .iter()
        .filter(|b| **b)
        .count();
        if given != 1 {
            return Err(bad(
                "",
                format!("give exactly one of `plane`, `box`, `sphere`, `indices` ({given} given)"),
            ));
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let mut out: Vec<usize> = if let Some(p) = &self.plane {
            let (lo, hi) = mesh.bounding_box();
            let tol = p.tolerance.unwrap_or(1e-6 * (hi - lo).norm());
            if !(tol.is_finite() && tol >= 0.0) {
                return Err(bad(
                    ".plane.tolerance",
                    format!("must be a non-negative number, got {tol}"),
                ));
            }
            let a = p.axis.index();
            let at = match p.side {
                Side::Min => lo[a],
                Side::Max => hi[a],
            };
            (0..mesh.num_vertices())
                .filter(|&i| (mesh.vertices[i][a] - at).abs() <= tol)
                .collect()
        } else if let Some(b) = &self.aabb {
            if !finite(&b.min) || !finite(&b.max) || (0..3).any(|i| b.min[i] > b.max[i]) {
                return Err(bad(".box", "needs finite min ≤ max on every axis".into()));
            }
            (0..mesh.num_vertices())
                .filter(|&i| {
                    let v = mesh.vertices[i];
                    (0..3).all(|a| v[a] >= b.min[a] && v[a] <= b.max[a])
                })
                .collect()
        } else if let Some(s) = &self.sphere {
            if !(finite(&s.center) && s.radius.is_finite() && s.radius > 0.0) {
                return Err(bad(
                    ".sphere",
                    "needs a finite center and a positive radius".into(),
                ));
            }
            let c = Vec3::from(s.center);
            (0..mesh.num_vertices())
                .filter(|&i| (mesh.vertices[i] - c).norm() <= s.radius)
                .collect()
        } else {
            let idx = self.indices.as_deref().unwrap_or(&[]);
            if let Some(&i) = idx.iter().find(|&&i| i >= mesh.num_vertices()) {
                return Err(bad(
                    ".indices",
                    format!(
                        "vertex {i} is out of range (indices count from 0: 0 to {})",
                        mesh.num_vertices().saturating_sub(1)
                    ),
                ));
            }
            idx.to_vec()
        };
        out.sort_unstable();
        out.dedup();
        if out.is_empty() {
            // A box or sphere placed where the body is not: say where the body is, in the
            // scene's units (a mesh in millimetres read without `scale` is 1000 times larger).
            let (lo, hi) = mesh.bounding_box();
            // A coordinate at round-off from zero (−7.3e-17 on a mesh made at the origin) is 0.
            let tiny = 1e-9 * (hi - lo).norm();
            let at = |x: f64| four_digits(if x.abs() < tiny { 0.0 } else { x });
            let span = |a: usize| format!("{} to {}", at(lo[a]), at(hi[a]));
            return Err(bad(
                "",
                format!(
                    "selects no vertex of the mesh, which spans x {}, y {}, z {} (m, after \
                     `[mesh] scale`)",
                    span(0),
                    span(1),
                    span(2)
                ),
            ));
        }
        Ok(out)
    }
}

/// Marker for a pinned (or otherwise eliminated) degree of freedom in [`DofMap::index`].
pub const FIXED: usize = usize::MAX;

/// Map between the 3n full degrees of freedom and the free ones.
///
/// A pinned vertex keeps zero displacement. Vertices that no tet references carry neither mass
/// nor stiffness, so they are eliminated too (and stay at rest).
#[derive(Debug, Clone, PartialEq)]
pub struct DofMap {
    /// Full DOF index (3·vertex + component) of each free DOF, increasing.
    pub free: Vec<usize>,
    /// Free index of each full DOF, or [`FIXED`].
    pub index: Vec<usize>,
}

impl DofMap {
    /// Frees every DOF of every referenced vertex that is not in `pinned`.
    pub fn new(mesh: &TetMesh, pinned: &[usize]) -> Self {
        let n = mesh.num_vertices();
        let mut eliminated = vec![true; n];
        for t in &mesh.tets {
            for &v in t {
                eliminated[v] = false;
            }
        }
        for &v in pinned {
            eliminated[v] = true;
        }
        let mut free = Vec::with_capacity(3 * n);
        let mut index = vec![FIXED; 3 * n];
        for v in 0..n {
            if !eliminated[v] {
                for c in 0..3 {
                    index[3 * v + c] = free.len();
                    free.push(3 * v + c);
                }
            }
        }
        Self { free, index }
    }

    pub fn num_free(&self) -> usize {
        self.free.len()
    }

    pub fn num_full(&self) -> usize {
        self.index.len()
    }

    /// Writes free values into a full vector; fixed entries become zero.
    pub fn scatter(&self, free: &[f64], full: &mut [f64]) {
        full.fill(0.0);
        for (k, &d) in self.free.iter().enumerate() {
            full[d] = free[k];
        }
    }

    /// Reads the free entries of a full vector.
    pub fn gather(&self, full: &[f64], free: &mut [f64]) {
        for (k, &d) in self.free.iter().enumerate() {
            free[k] = full[d];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::generate::{BoxSpec, box_mesh};

    #[test]
    fn selections() {
        let m = box_mesh(&BoxSpec {
            size: [1.0, 1.0, 1.0],
            cells: [2, 2, 2],
            ..Default::default()
        })
        .unwrap();
        let left = VertexSelection::plane(Axis::X, Side::Min, None)
            .select(&m, "pin[0]")
            .unwrap();
        assert_eq!(left.len(), 9);
        assert!(left.iter().all(|&v| m.vertices[v].x == 0.0));
        let ball = VertexSelection::sphere([0.5, 0.5, 0.5], 0.01)
            .select(&m, "pin[0]")
            .unwrap();
        assert_eq!(ball.len(), 1);
        let none = VertexSelection::sphere([5.0, 5.0, 5.0], 0.1).select(&m, "pin[1]");
        let msg = none.unwrap_err().to_string();
        assert!(msg.contains("pin[1]") && msg.contains("no vertex"), "{msg}");
        let two = VertexSelection {
            indices: Some(vec![1]),
            sphere: Some(SphereSelector {
                center: [0.0; 3],
                radius: 1.0,
            }),
            ..Default::default()
        };
        assert!(two.select(&m, "pin[2]").is_err());
        let dofs = DofMap::new(&m, &left);
        assert_eq!(dofs.num_free(), 3 * (27 - 9));
        let free: Vec<f64> = (0..dofs.num_free()).map(|i| i as f64 + 1.0).collect();
        let mut full = vec![0.0; 81];
        dofs.scatter(&free, &mut full);
        let mut back = vec![0.0; free.len()];
        dofs.gather(&full, &mut back);
        assert_eq!(back, free);
        assert!(left.iter().all(|&v| full[3 * v] == 0.0));
    }
}
