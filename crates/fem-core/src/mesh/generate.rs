//! Procedural meshes, so scenes need no mesh file: a box (a beam when one side is long), or a
//! figure voxelised in a box (a trunk on a flat base, a head on a neck and two arms).
//!
//! Each hexahedral cell is split into six tetrahedra along its main diagonal (the Freudenthal /
//! Kuhn split), which is conforming across cells without alternating patterns, so any subset of
//! a grid's cells is a conforming mesh too.

use super::TetMesh;
use crate::{FemError, Vec3};

/// A box `[origin, origin + size]` divided into `cells` hexahedra.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// The shape built in the box: the box itself (the default) or a figure.
    #[serde(default)]
    pub kind: GeneratedShape,
    /// Edge lengths of the box.
    #[serde(deserialize_with = "crate::exact::array")]
    pub size: [f64; 3],
    /// Number of cells along each axis (each ≥ 1).
    #[serde(deserialize_with = "crate::exact::array")]
    pub cells: [usize; 3],
    /// Minimum corner.
    #[serde(default, deserialize_with = "crate::exact::array")]
    pub origin: [f64; 3],
}

/// Shapes the generator can build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GeneratedShape {
    /// An axis-aligned box (a beam when one side is long).
    #[default]
    Box,
    /// A figure standing on its flat base at the box's lowest y, the cells of the grid whose
    /// centres lie inside it: a vertical trunk up to 60 % of the height, a head at the top on a
    /// neck of half the trunk's radius, and two arms along x at half the height, spanning the
    /// box's width. Sizes follow the box: the trunk's radius is the smaller of half the depth
    /// (z) and a sixth of the width (x); the arms' is 40 % of it; the head's the smallest of half
    /// the depth, half the width and a fifth of the height. Arms and head swing about the trunk,
    /// which is what linear subspaces miss.
    Figure,
}

impl GeneratedShape {
    /// The name a scene gives it (`kind = "figure"`).
    pub fn name(self) -> &'static str {
        match self {
            GeneratedShape::Box => "box",
            GeneratedShape::Figure => "figure",
        }
    }

    /// The figure's head radius in a box of edge lengths `size`.
    fn head_radius(size: [f64; 3]) -> f64 {
        let [w, h, d] = size;
        (0.5 * d).min(0.5 * w).min(0.2 * h)
    }

    /// The parts of the shape of a box of edge lengths `size` that point `p`, relative to the
    /// box's minimum corner, lies in: [trunk or neck, head, arms] for a figure; a box is all
    /// trunk.
    fn parts(self, p: [f64; 3], size: [f64; 3]) -> [bool; 3] {
        match self {
            GeneratedShape::Box => [true, false, false],
            GeneratedShape::Figure => {
                let [w, h, d] = size;
                let (cx, cz) = (0.5 * w, 0.5 * d);
                let trunk = (0.5 * d).min(w / 6.0);
                let arm = 0.4 * trunk;
                let head = Self::head_radius(size);
                let head_y = h - head;
                let r2 = |a: f64, b: f64| a * a + b * b;
                let axial = r2(p[0] - cx, p[2] - cz);
                let in_trunk = p[1] <= 0.6 * h && axial <= trunk * trunk;
                let in_neck = p[1] <= head_y && axial <= 0.25 * trunk * trunk;
                let in_head = axial + (p[1] - head_y).powi(2) <= head * head;
                let in_arms = r2(p[1] - 0.5 * h, p[2] - cz) <= arm * arm;
                [in_trunk || in_neck, in_head, in_arms]
            }
        }
    }
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

/// Builds the spec's shape with 6 tets per kept cell of its grid (every cell of a box, the
/// cells whose centres lie inside a figure), positively oriented, without unused vertices.
///
/// # Errors
/// An invalid spec (one error per field), or a figure whose grid is too coarse to hold it in
/// one piece with its base, arms and head (`mesh.generate.cells`).
pub fn box_mesh(spec: &BoxSpec) -> Result<TetMesh, FemError> {
    let mut errors = Vec::new();
    spec.check(&mut errors);
    FemError::collect(errors)?;
    let count = spec.num_vertices().expect("checked above");
    let [nx, ny, nz] = spec.cells;
    let idx = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);
    let grid = |a: usize, i: f64| spec.size[a] * i / spec.cells[a] as f64;
    let mut vertices = Vec::with_capacity(count);
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                vertices.push(Vec3::new(
                    spec.origin[0] + grid(0, i as f64),
                    spec.origin[1] + grid(1, j as f64),
                    spec.origin[2] + grid(2, k as f64),
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
    // Whether a kept cell holds each part where the figure needs it.
    #[derive(Default)]
    struct Found {
        base: bool,
        head: bool,
        left_arm: bool,
        right_arm: bool,
    }
    let mut found = Found::default();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let centre = [
                    grid(0, i as f64 + 0.5),
                    grid(1, j as f64 + 0.5),
                    grid(2, k as f64 + 0.5),
                ];
                let [trunk, head, arms] = spec.kind.parts(centre, spec.size);
                if !(trunk || head || arms) {
                    continue;
                }
                found.base |= trunk && j == 0;
                found.head |= head;
                found.left_arm |= arms && i == 0;
                found.right_arm |= arms && i + 1 == nx;
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
    if spec.kind == GeneratedShape::Box {
        // Every cell kept: every vertex used, one piece.
        return Ok(mesh);
    }
    let mesh = compacted(mesh);
    let too_coarse = |what: String| FemError::InvalidConfig {
        field: "mesh.generate.cells".into(),
        reason: format!(
            "the {} at cells = {:?} {what}: give more cells along each axis",
            spec.kind.name(),
            spec.cells
        ),
    };
    let (_, pieces) = mesh.vertex_components();
    if pieces != 1 {
        return Err(too_coarse(format!(
            "is {pieces} pieces (0: no cell's centre is inside it), not one body"
        )));
    }
    // The figure's parts at this resolution: the trunk on the box's floor, a head, arms to both
    // ends of its width.
    let missing: Vec<&str> = [
        (found.base, "base"),
        (found.head, "head"),
        (found.left_arm && found.right_arm, "arms"),
    ]
    .into_iter()
    .filter_map(|(there, part)| (!there).then_some(part))
    .collect();
    if !missing.is_empty() {
        return Err(too_coarse(format!("has no {}", missing.join(" or "))));
    }
    Ok(mesh)
}

/// `mesh` without the vertices no tet uses, the rest in their order.
fn compacted(mut mesh: TetMesh) -> TetMesh {
    let mut used = vec![false; mesh.vertices.len()];
    for &v in mesh.tets.iter().flatten() {
        used[v] = true;
    }
    let mut new_index = vec![usize::MAX; used.len()];
    let kept = new_index.iter_mut().zip(&used).filter(|(_, u)| **u);
    for (new, (slot, _)) in kept.enumerate() {
        *slot = new;
    }
    let mut v = 0;
    mesh.vertices.retain(|_| {
        v += 1;
        used[v - 1]
    });
    for i in mesh.tets.iter_mut().flatten() {
        *i = new_index[*i];
    }
    mesh
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
    fn figure_is_one_body_standing_on_its_base() {
        let spec = BoxSpec {
            kind: GeneratedShape::Figure,
            size: [0.6, 0.6, 0.2],
            cells: [30, 30, 10],
            origin: [0.0, 1.0, 0.0],
        };
        let m = box_mesh(&spec).unwrap();
        assert!((0..m.num_tets()).all(|t| m.signed_volume(t) > 0.0));
        // No unused vertex is left.
        let mut used = vec![false; m.num_vertices()];
        m.tets.iter().flatten().for_each(|&v| used[v] = true);
        assert!(used.iter().all(|&u| u));
        // The arms span the box's width and the head reaches its top; the base is flat.
        let (lo, hi) = m.bounding_box();
        assert!(
            (lo.x - 0.0).abs() < 1e-12 && (hi.x - 0.6).abs() < 1e-12,
            "{lo} {hi}"
        );
        assert!(
            (lo.y - 1.0).abs() < 1e-12 && (hi.y - 1.6).abs() < 1e-12,
            "{lo} {hi}"
        );
        // Trunk + neck + head + arms: well inside the box, far from empty.
        let fill = m.volume() / (0.6 * 0.6 * 0.2);
        assert!((0.15..0.45).contains(&fill), "{fill}");
        // The arms are thin: at the arms' height the cross-section is much wider than at the
        // height of the trunk below them.
        let width_at = |y: f64| {
            let xs = m
                .vertices
                .iter()
                .filter(|v| (v.y - y).abs() < 1e-9)
                .map(|v| v.x);
            let (a, b) = xs.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
            b - a
        };
        assert!(
            width_at(1.3) > 0.55 && width_at(1.1) < 0.25,
            "{} {}",
            width_at(1.3),
            width_at(1.1)
        );
    }

    #[test]
    fn kinds_are_named_as_scenes_name_them() {
        for kind in [GeneratedShape::Box, GeneratedShape::Figure] {
            let json = serde_json::to_value(kind).unwrap();
            assert_eq!(json.as_str(), Some(kind.name()));
        }
    }

    #[test]
    fn a_figure_too_coarse_to_hold_together_is_refused() {
        let err = box_mesh(&BoxSpec {
            kind: GeneratedShape::Figure,
            size: [0.6, 0.6, 0.2],
            cells: [2, 2, 2],
            origin: [0.0; 3],
        })
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("mesh.generate.cells")
                && err.contains("the figure at cells = [2, 2, 2] is 0 pieces"),
            "{err}"
        );
        let refused = |size: [f64; 3], cells: [usize; 3]| {
            let spec = BoxSpec {
                kind: GeneratedShape::Figure,
                size,
                cells,
                origin: [0.0; 3],
            };
            box_mesh(&spec).unwrap_err().to_string()
        };
        // Arms apart from the trunk.
        let err = refused([0.6, 0.6, 0.2], [4, 4, 1]);
        assert!(err.contains("is 2 pieces"), "{err}");
        // One cell (trunk and arms, but no head), and trunk and head without arms.
        let err = refused([0.3, 0.3, 0.1], [1, 1, 1]);
        assert!(err.contains("has no head"), "{err}");
        let err = refused([0.3, 0.3, 0.1], [6, 6, 3]);
        assert!(err.contains("has no arms"), "{err}");
        // A head floating above the floor.
        let err = refused([0.2, 0.5, 0.3], [12, 14, 4]);
        assert!(err.contains("has no base"), "{err}");
    }

    /// A box keeps the vertex and tet order it always had (cached stages key on the mesh).
    #[test]
    fn box_order_is_unchanged() {
        let m = box_mesh(&BoxSpec {
            size: [2.0, 1.0, 1.0],
            cells: [2, 1, 1],
            ..Default::default()
        })
        .unwrap();
        assert_eq!(m.num_vertices(), 12);
        assert_eq!(m.vertices[1], Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(m.vertices[4], Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(m.vertices[6], Vec3::new(0.0, 0.0, 1.0));
        // Cell 0, axis orders xyz and xzy (the second turned positive by swapping its last two).
        assert_eq!(&m.tets[..2], &[[0, 1, 4, 10], [0, 1, 10, 7]]);
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
