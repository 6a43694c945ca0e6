//! Tetrahedral meshes: storage, validation on load and boundary-surface extraction.

mod config;
pub mod generate;
mod validate;

pub use config::{MeshConfig, PLAUSIBLE_SIZE, size_warning};

pub use validate::{ValidationReport, validate, validate_located};

use crate::Vec3;

/// Component label of a vertex that no tet uses, in [`TetMesh::vertex_components`].
pub const NO_COMPONENT: usize = usize::MAX;

/// A linear tetrahedral mesh: rest positions and 0-based vertex indices of each tet.
///
/// Tets are positively oriented after [`validate`]: det[X1−X0, X2−X0, X3−X0] > 0.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TetMesh {
    /// Rest positions, one per vertex.
    pub vertices: Vec<Vec3>,
    /// Vertex indices of each tetrahedron.
    pub tets: Vec<[usize; 4]>,
}

impl TetMesh {
    pub fn num_vertices(&self) -> usize {
        self.vertices.len()
    }

    pub fn num_tets(&self) -> usize {
        self.tets.len()
    }

    /// The rest volume: the sum of the tets' signed volumes (positive once the mesh is validated,
    /// which orients every tet).
    pub fn volume(&self) -> f64 {
        (0..self.num_tets()).map(|t| self.signed_volume(t)).sum()
    }

    /// Each tet's det F when vertex `i` is displaced by `u[3i..3i + 3]`: its deformed signed
    /// volume over its rest one (≤ 0 where it is inverted or flat), into `out` (one per tet).
    /// The rest volumes are positive on a validated mesh; a flat rest tet gives ±∞ or NaN.
    ///
    /// # Panics
    /// If `u` has not 3 entries per vertex.
    pub fn volume_ratios(&self, u: &[f64], out: &mut Vec<f64>) {
        assert_eq!(u.len(), 3 * self.vertices.len(), "u: 3 entries per vertex");
        let x = |v: usize| self.vertices[v] + Vec3::new(u[3 * v], u[3 * v + 1], u[3 * v + 2]);
        out.clear();
        out.extend(
            (self.tets.iter().enumerate())
                .map(|(t, tet)| tet_volume(tet.map(x)) / self.signed_volume(t)),
        );
    }

    /// Signed volume det[X1−X0, X2−X0, X3−X0] / 6 of tet `t`.
    pub fn signed_volume(&self, t: usize) -> f64 {
        tet_volume(self.tets[t].map(|v| self.vertices[v]))
    }

    /// The smallest of the six dihedral angles of tet `t`, in degrees: near 0 for a sliver
    /// (four corners nearly in a plane) or a needle, 70.5 for a regular tet.
    pub fn min_dihedral_degrees(&self, t: usize) -> f64 {
        let x = self.tets[t].map(|v| self.vertices[v]);
        // The normals of the faces opposite each corner; two faces meet at the edge they share.
        let normal = |a: usize, b: usize, c: usize| (x[b] - x[a]).cross(&(x[c] - x[a]));
        let n = [
            normal(1, 2, 3),
            normal(0, 3, 2),
            normal(0, 1, 3),
            normal(0, 2, 1),
        ];
        let mut smallest = f64::INFINITY;
        for i in 0..4 {
            for j in i + 1..4 {
                let cos = -n[i].dot(&n[j]) / (n[i].norm() * n[j].norm());
                smallest = smallest.min(cos.clamp(-1.0, 1.0).acos());
            }
        }
        smallest.to_degrees()
    }

    /// Axis-aligned bounding box (min, max) of the body: of the vertices some tet uses (of every
    /// vertex when there is no tet). Every size the scene derives from it (pin planes, training
    /// and test offsets, patch radii) is the body's, whatever stray vertices a file also holds:
    /// five unused vertices 10 m from a 25 cm bar made its drags pull by a metre. Returns zeros
    /// for an empty mesh.
    pub fn bounding_box(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        let mut add = |v: &Vec3| {
            lo = lo.inf(v);
            hi = hi.sup(v);
        };
        if self.tets.is_empty() {
            self.vertices.iter().for_each(&mut add);
        } else {
            for tet in &self.tets {
                tet.iter()
                    .filter_map(|&v| self.vertices.get(v))
                    .for_each(&mut add);
            }
        }
        if lo.x > hi.x {
            (Vec3::zeros(), Vec3::zeros())
        } else {
            (lo, hi)
        }
    }

    /// Boundary triangles: faces that belong to exactly one tet, oriented outward.
    pub fn surface_triangles(&self) -> Vec<[usize; 3]> {
        let mut faces: Vec<([usize; 3], [usize; 3])> = Vec::with_capacity(self.tets.len() * 4);
        for t in &self.tets {
            for f in TET_FACES {
                let tri = [t[f[0]], t[f[1]], t[f[2]]];
                let mut key = tri;
                key.sort_unstable();
                faces.push((key, tri));
            }
        }
        faces.sort_unstable_by_key(|f| f.0);
        let mut out = Vec::new();
        let mut i = 0;
        while i < faces.len() {
            let mut j = i + 1;
            while j < faces.len() && faces[j].0 == faces[i].0 {
                j += 1;
            }
            if j - i == 1 {
                out.push(faces[i].1);
            }
            i = j;
        }
        out
    }

    /// The connected piece of each vertex (tets sharing a vertex are connected), numbered from 0
    /// in order of first vertex, and the number of pieces. Vertices no tet uses get
    /// [`NO_COMPONENT`] and count as no piece.
    pub fn vertex_components(&self) -> (Vec<usize>, usize) {
        let n = self.vertices.len();
        let mut parent: Vec<usize> = (0..n).collect();
        let mut used = vec![false; n];
        for tet in &self.tets {
            let a = root(&mut parent, tet[0]);
            used[tet[0]] = true;
            for &v in &tet[1..] {
                used[v] = true;
                let b = root(&mut parent, v);
                if a != b {
                    parent[b] = a;
                }
            }
        }
        let mut label = vec![NO_COMPONENT; n];
        let mut count = 0;
        for v in 0..n {
            if !used[v] {
                continue;
            }
            let r = root(&mut parent, v);
            if label[r] == NO_COMPONENT {
                label[r] = count;
                count += 1;
            }
            label[v] = label[r];
        }
        (label, count)
    }

    /// The volume the closed triangles enclose, Σ a·(b×c)/6 over their rest positions: the
    /// body's volume for [`Self::surface_triangles`], its negative for triangles wound inward.
    ///
    /// Measured from a vertex of the surface, not the origin, so that a body far from the
    /// origin keeps its digits (from the origin, a 10 cm cube 10⁵ m away came out negative).
    pub fn enclosed_volume(&self, triangles: &[[usize; 3]]) -> f64 {
        let Some(o) = triangles.first().map(|t| self.vertices[t[0]]) else {
            return 0.0;
        };
        triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.vertices[v] - o);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Vertices on the boundary surface, sorted and unique.
    pub fn surface_vertices(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self.surface_triangles().into_iter().flatten().collect();
        v.sort_unstable();
        v.dedup();
        v
    }
}

/// A mesh whose tets have all four corners on its surface in this share or more is about one
/// element thick: a tester's 1 cm plate meshed at 1.2 cm (97 % of its tets) and a tube with a
/// 5 mm wall (100 %); the solid meshes measured, AutoDef's and gmsh-made, are at 0–21 %, a bar
/// two cells across at 31 %. The plate's linear sag under its weight, the same plate generated
/// 30 × 1 × 20, 30 × 3 × 20 and 60 × 4 × 40 cells (corotated, E = 10⁷ Pa, ν = 0.3, clamped
/// along its 20 cm edge): 2.4, 5.0 and 7.9 cm, against 10.8 cm from plate theory.
pub const THIN_SHARE: f64 = 0.5;

/// A tet with a dihedral angle below this (degrees) is a sliver or a needle.
pub const SLIVER_DEGREES: f64 = 5.0;

/// The share of the tets past which [`sliver_note`] speaks.
pub const SLIVER_SHARE: f64 = 0.01;

/// What to say of a mesh of which [`SLIVER_SHARE`] of the tets or more are slivers
/// ([`SLIVER_DEGREES`]), as Delaunay tetrahedralizations without a quality bound make them: a
/// note, not a warning (a tester's Delaunay bars, 5.4–5.7 % slivers down to 0.008°, ran every
/// method within 2.4 %), which says where a stiffness or a failed step from such a mesh may
/// come from. A sliver turns far in F for a small move of its corners (one stood at 6.4× for
/// 7 mm), inverts easily under classic Neo-Hookean, and slows the full solves.
pub fn sliver_note(mesh: &TetMesh) -> Option<String> {
    let angles: Vec<f64> = (0..mesh.num_tets())
        .map(|t| mesh.min_dihedral_degrees(t))
        .collect();
    let slivers = angles.iter().filter(|&&a| a < SLIVER_DEGREES).count();
    let share = slivers as f64 / angles.len().max(1) as f64;
    (share >= SLIVER_SHARE).then(|| {
        let smallest = angles.iter().copied().fold(f64::INFINITY, f64::min);
        format!(
            "{:.1} % of its tets are slivers (a dihedral angle under {SLIVER_DEGREES}°, the \
             smallest {smallest:.2}°): a quality bound when meshing (`tetgen -pq1.4`, gmsh's \
             `-optimize_netgen`, fTetWild) removes them",
            100.0 * share
        )
    })
}

/// How to mesh finer, in [`thin_warning`], for a mesh read from a file.
pub const REFINE_MESHER: &str = "a smaller gmsh `Mesh.MeshSizeMax`, TetGen's `-a`";

/// How to mesh finer, in [`thin_warning`], for a mesh the scene generates (an advice follower's
/// generated plate was told gmsh's and TetGen's options).
pub const REFINE_GENERATED: &str = "more `[mesh] generate` cells";

/// What to say of a mesh about one element thick ([`THIN_SHARE`]): linear tetrahedra that thin
/// lock in bending, so the body is far stiffer than its material, and every method is measured
/// against that stiffness. `refine` says how to mesh finer ([`REFINE_MESHER`],
/// [`REFINE_GENERATED`]).
pub fn thin_warning(mesh: &TetMesh, refine: &str) -> Option<String> {
    let triangles = mesh.surface_triangles();
    let on_surface = on_triangles(mesh.num_vertices(), &triangles);
    let tets = mesh.num_tets();
    let thin = mesh
        .tets
        .iter()
        .filter(|t| t.iter().all(|&v| on_surface[v]))
        .count();
    if tets > 0 && (thin as f64) < THIN_SHARE * tets as f64 {
        let (share, centre, count) = thickest_thin_part(mesh, &triangles, &on_surface)?;
        return (share >= THIN_PART_SHARE).then(|| {
            format!(
                "a part about one element thick around ({:.3}, {:.3}, {:.3}) holds {:.0} % of \
                 the body's volume ({count} tets, each reaching from its surface to the \
                 opposite one): linear tetrahedra that thin bend far too stiffly (a fin meshed \
                 one to two elements thick, about twice too stiffly), so the full simulation, \
                 and every method measured against it, is stiffer there than the material; \
                 three or more elements across its thickness ({refine}) bend closer to it",
                centre.x,
                centre.y,
                centre.z,
                100.0 * share
            )
        });
    }
    (tets > 0).then(|| {
        let share = if tets == 1 {
            "the mesh's one tet has".to_string()
        } else {
            format!(
                "{thin} of the mesh's {tets} tets ({:.0} %) have",
                100.0 * thin as f64 / tets as f64
            )
        };
        format!(
            "{share} all four corners on its surface: the \
             body is about one element thick, where linear tetrahedra bend far too stiffly (a \
             30 × 20 × 1 cm plate clamped along an edge sags 2.4 cm under its weight one cell \
             thick, 5.0 cm three cells thick, 7.9 cm four cells thick and twice as fine along \
             it; plate theory: 10.8 cm), so the full simulation, and every method measured \
             against it, is stiffer than the material; more elements across the thickness, and \
             finer along it ({refine}), bend closer to it"
        )
    })
}

/// A face-connected part whose tets each reach across the body, from its surface to the
/// opposite surface, in this share of the body's volume or more is said by [`thin_warning`]
/// even where the body as a whole is thick: a tester's block with a fin one to two elements
/// thick (its fin 10.5 % of the volume, twice as stiff as the fin meshed finer); AutoDef's six
/// meshes' largest such parts hold 0–3 % (the coarse X's arms), a bar two cells across none.
pub const THIN_PART_SHARE: f64 = 0.05;

/// The largest part one element thick: the tets that reach across the body, each with two
/// surface corners whose outward normals point apart (cosine below −½) and away from each
/// other, joined through their shared faces. Its share of the body's volume, its
/// volume-weighted centre and its tets; `None` for a mesh without such tets. `triangles` are
/// the mesh's [`TetMesh::surface_triangles`], `on_surface` whether each vertex is on one.
fn thickest_thin_part(
    mesh: &TetMesh,
    triangles: &[[usize; 3]],
    on_surface: &[bool],
) -> Option<(f64, Vec3, usize)> {
    let mut normal = vec![Vec3::zeros(); mesh.num_vertices()];
    for &[a, b, c] in triangles {
        let n = (mesh.vertices[b] - mesh.vertices[a]).cross(&(mesh.vertices[c] - mesh.vertices[a]));
        for v in [a, b, c] {
            normal[v] += n;
        }
    }
    for n in &mut normal {
        *n = n.try_normalize(0.0).unwrap_or_else(Vec3::zeros);
    }
    let across = |a: usize, b: usize| {
        let (na, nb) = (normal[a], normal[b]);
        let ab = mesh.vertices[b] - mesh.vertices[a];
        on_surface[a]
            && on_surface[b]
            && na.dot(&nb) < -0.5
            && ab.dot(&nb) > 0.0
            && ab.dot(&na) < 0.0
    };
    let spanning: Vec<usize> = (0..mesh.num_tets())
        .filter(|&t| {
            let v = mesh.tets[t];
            (0..4).any(|i| (i + 1..4).any(|j| across(v[i], v[j])))
        })
        .collect();
    if spanning.is_empty() {
        return None;
    }
    // Parts: spanning tets joined through a face both hold (union–find over `spanning`).
    let mut faces: Vec<([usize; 3], usize)> = Vec::with_capacity(4 * spanning.len());
    for (i, &t) in spanning.iter().enumerate() {
        let v = mesh.tets[t];
        for f in TET_FACES {
            let mut face = f.map(|j| v[j]);
            face.sort_unstable();
            faces.push((face, i));
        }
    }
    faces.sort_unstable();
    let mut parent: Vec<usize> = (0..spanning.len()).collect();
    for pair in faces.windows(2) {
        if pair[0].0 == pair[1].0 {
            let (a, b) = (root(&mut parent, pair[0].1), root(&mut parent, pair[1].1));
            parent[a] = b;
        }
    }
    let mut parts: std::collections::BTreeMap<usize, (f64, Vec3, usize)> = Default::default();
    for (i, &t) in spanning.iter().enumerate() {
        let r = root(&mut parent, i);
        let volume = mesh.signed_volume(t).abs();
        let centre = mesh.tets[t].iter().map(|&v| mesh.vertices[v]).sum::<Vec3>() / 4.0;
        let part = parts.entry(r).or_insert((0.0, Vec3::zeros(), 0));
        part.0 += volume;
        part.1 += volume * centre;
        part.2 += 1;
    }
    let total = mesh.volume();
    let (volume, moment, tets) = parts.into_values().max_by(|a, b| a.0.total_cmp(&b.0))?;
    (total > 0.0 && volume > 0.0).then(|| (volume / total, moment / volume, tets))
}

/// The faces opposite each corner of a positively oriented tet ((x1−x0)×(x2−x0)·(x3−x0) > 0),
/// counter-clockwise seen from outside: (b−a)×(c−a) points away from the fourth vertex.
/// (Before 2026-12-02 [`TetMesh::surface_triangles`] wound them the reverse, inward.)
const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Whether each of `n` vertices is a corner of one of `triangles`.
fn on_triangles(n: usize, triangles: &[[usize; 3]]) -> Vec<bool> {
    let mut on = vec![false; n];
    for &v in triangles.iter().flatten() {
        on[v] = true;
    }
    on
}

/// The root of `i`'s set in the union–find forest `parent`, halving the path on the way.
fn root(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// det[x1−x0, x2−x0, x3−x0] / 6: the signed volume of the tet with corners `x`.
fn tet_volume([x0, x1, x2, x3]: [Vec3; 4]) -> f64 {
    (x1 - x0).cross(&(x2 - x0)).dot(&(x3 - x0)) / 6.0
}

#[cfg(test)]
mod tests {
    use super::generate::{BoxSpec, GeneratedShape, box_mesh};

    /// Dihedral angles of known tets: a right corner's smallest is acos(1/√3), a regular tet's
    /// acos(1/3), a flat one's near 0; a mesh of such slivers is noted, a box's tets are not.
    #[test]
    fn dihedral_angles_and_slivers() {
        use crate::Vec3;
        let tet = |x: [Vec3; 4]| super::TetMesh {
            vertices: x.to_vec(),
            tets: vec![[0, 1, 2, 3]],
        };
        let corner = tet([Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()]);
        let expect = (1.0 / 3.0_f64.sqrt()).acos().to_degrees();
        assert!((corner.min_dihedral_degrees(0) - expect).abs() < 1e-9);
        let s = 8.0_f64.sqrt();
        let regular = tet([
            Vec3::new(s / 3.0, 0.0, -1.0 / 3.0),
            Vec3::new(-s / 6.0, 6.0_f64.sqrt() / 3.0, -1.0 / 3.0),
            Vec3::new(-s / 6.0, -(6.0_f64.sqrt()) / 3.0, -1.0 / 3.0),
            Vec3::new(0.0, 0.0, 1.0),
        ]);
        let expect = (1.0_f64 / 3.0).acos().to_degrees();
        assert!((regular.min_dihedral_degrees(0) - expect).abs() < 1e-9);
        let sliver = tet([
            Vec3::zeros(),
            Vec3::x(),
            Vec3::new(1.0, 1.0, 0.001),
            Vec3::y(),
        ]);
        assert!(sliver.min_dihedral_degrees(0) < 1.0);
        let note = super::sliver_note(&sliver).expect("all slivers");
        assert!(
            note.starts_with("100.0 % of its tets are slivers"),
            "{note}"
        );
        let bar = box_mesh(&BoxSpec {
            size: [1.0, 0.1, 0.1],
            cells: [10, 1, 1],
            ..Default::default()
        })
        .unwrap();
        assert_eq!(super::sliver_note(&bar), None);
    }

    /// A plate one cell thick is said; the same plate four or six cells through its thickness
    /// is not.
    #[test]
    fn a_mesh_one_element_thick_is_said() {
        let plate = |cells: [usize; 3]| {
            box_mesh(&BoxSpec {
                kind: Default::default(),
                size: [0.3, 0.2, 0.01],
                cells,
                origin: [0.0; 3],
            })
            .unwrap()
        };
        let w = super::thin_warning(&plate([12, 8, 1]), super::REFINE_GENERATED)
            .expect("one cell thick");
        assert!(w.contains("have all four corners on its surface"), "{w}");
        assert!(w.contains("(100 %)"), "{w}");
        // A generated mesh is told its own setting, a mesher's file the meshers'.
        assert!(w.contains("(more `[mesh] generate` cells)"), "{w}");
        assert!(!w.contains("gmsh"), "{w}");
        assert_eq!(
            super::thin_warning(&plate([12, 8, 4]), super::REFINE_MESHER),
            None
        );
        assert_eq!(
            super::thin_warning(&plate([6, 6, 6]), super::REFINE_MESHER),
            None
        );
    }

    /// A block with a fin one cell thick (14 % of its volume; 19 % with the row of the block's
    /// tets beneath it that reach from the block's side to the fin's) is said, with its centre;
    /// the block without it, a bar two cells across, the default scene's bar and the figure
    /// are not, and a fin of 1.4 % is not either.
    #[test]
    fn a_part_one_element_thick_is_said() {
        let block = |fin_cells: usize| {
            let mut m = box_mesh(&BoxSpec {
                size: [1.2, 0.6, 0.6],
                cells: [12, 6, 6],
                ..Default::default()
            })
            .unwrap();
            // Keep the lower half (y < 0.3) and, above it, one layer of cells in z for
            // `fin_cells` cells along x.
            let x = m.vertices.clone();
            m.tets.retain(|t| {
                let c = t.iter().map(|&v| x[v]).sum::<crate::Vec3>() / 4.0;
                c.y < 0.3 || (c.z < 0.1 && c.x < 0.1 * fin_cells as f64)
            });
            m
        };
        let w =
            super::thin_warning(&block(12), super::REFINE_MESHER).expect("a fin one cell thick");
        assert!(
            w.starts_with("a part about one element thick around (0.596, 0.403, 0.050) holds 19 %"),
            "{w}"
        );
        assert!(
            w.contains("(a smaller gmsh `Mesh.MeshSizeMax`, TetGen's `-a`) bend closer"),
            "{w}"
        );
        assert_eq!(super::thin_warning(&block(0), super::REFINE_MESHER), None);
        // A fin one cell long: 1.4 % of the volume, under 2 % with the tets beneath it.
        let fin = block(1);
        let triangles = fin.surface_triangles();
        let on_surface = super::on_triangles(fin.num_vertices(), &triangles);
        let (share, _, _) =
            super::thickest_thin_part(&fin, &triangles, &on_surface).expect("a fin");
        assert!(share < 0.02, "{share}");
        assert_eq!(super::thin_warning(&block(1), super::REFINE_MESHER), None);
        for (kind, size, cells) in [
            (GeneratedShape::Box, [1.0, 0.1, 0.1], [40, 2, 2]),
            (GeneratedShape::Box, [1.0, 0.2, 0.2], [40, 8, 8]),
            (GeneratedShape::Figure, [0.3, 0.3, 0.1], [39, 39, 13]),
        ] {
            let m = box_mesh(&BoxSpec {
                kind,
                size,
                cells,
                ..Default::default()
            })
            .unwrap();
            assert_eq!(
                super::thin_warning(&m, super::REFINE_MESHER),
                None,
                "{kind:?} {cells:?}"
            );
        }
    }

    #[test]
    fn volume_ratios_are_det_f() {
        let m = box_mesh(&BoxSpec {
            size: [1.0, 1.0, 1.0],
            cells: [2, 2, 2],
            ..Default::default()
        })
        .unwrap();
        let n = m.num_vertices();
        let mut ratios = Vec::new();
        // At rest every ratio is 1; a uniform squeeze to half the height halves every volume.
        m.volume_ratios(&vec![0.0; 3 * n], &mut ratios);
        assert_eq!(ratios.len(), m.num_tets());
        assert!(ratios.iter().all(|r| (r - 1.0).abs() < 1e-12), "{ratios:?}");
        let mut u = vec![0.0; 3 * n];
        for (i, v) in m.vertices.iter().enumerate() {
            u[3 * i + 1] = -0.5 * v.y;
        }
        m.volume_ratios(&u, &mut ratios);
        assert!(ratios.iter().all(|r| (r - 0.5).abs() < 1e-12), "{ratios:?}");
        // The top vertices pushed through the bottom ones: exactly the tets of the top layer
        // invert.
        for (i, v) in m.vertices.iter().enumerate() {
            u[3 * i + 1] = if v.y > 0.75 { -1.5 } else { 0.0 };
        }
        m.volume_ratios(&u, &mut ratios);
        for (t, r) in m.tets.iter().zip(&ratios) {
            let top = t.iter().any(|&v| m.vertices[v].y > 0.75);
            assert_eq!(*r <= 0.0, top, "{t:?}: {r}");
        }
    }

    /// The surface is wound counter-clockwise seen from outside, as OBJ and OpenGL expect: each
    /// triangle's normal points away from its tet's fourth vertex, and the triangles enclose
    /// the body's volume with a positive sign (they were wound inward until 2026-12-02).
    #[test]
    fn surface_triangles_face_outward() {
        for kind in [
            super::generate::GeneratedShape::Box,
            super::generate::GeneratedShape::Figure,
        ] {
            let m = box_mesh(&BoxSpec {
                kind,
                size: [0.3, 0.3, 0.1],
                cells: [13, 13, 3],
                ..Default::default()
            })
            .unwrap();
            let tris = m.surface_triangles();
            let volume: f64 = (0..m.num_tets()).map(|t| m.signed_volume(t)).sum();
            let enclosed = m.enclosed_volume(&tris);
            // Far from the origin too.
            let mut far = m.clone();
            far.vertices
                .iter_mut()
                .for_each(|v| *v += nalgebra::Vector3::new(1e5, -2e5, 3e5));
            let far = far.enclosed_volume(&tris);
            assert!(
                (far - volume).abs() < 1e-6 * volume,
                "{kind:?}: {far} against {volume}"
            );
            assert!(
                (enclosed - volume).abs() < 1e-12 * volume.max(1.0),
                "{kind:?}: {enclosed} against {volume}"
            );
            for tri in &tris {
                let tet = m
                    .tets
                    .iter()
                    .find(|t| tri.iter().all(|v| t.contains(v)))
                    .unwrap();
                let fourth = tet.iter().find(|v| !tri.contains(v)).unwrap();
                let [a, b, c] = tri.map(|v| m.vertices[v]);
                let normal = (b - a).cross(&(c - a));
                assert!(
                    normal.dot(&(m.vertices[*fourth] - a)) < 0.0,
                    "{kind:?}: {tri:?}"
                );
            }
        }
    }

    /// Vertices no tet uses do not size the body.
    #[test]
    fn bounding_box_is_the_bodys() {
        let mut m = box_mesh(&BoxSpec {
            size: [0.25, 0.06, 0.06],
            cells: [4, 1, 1],
            ..Default::default()
        })
        .unwrap();
        let body = m.bounding_box();
        m.vertices.push(nalgebra::Vector3::new(9.0, 5.0, -5.0));
        assert_eq!(m.bounding_box(), body);
        assert!((body.1 - body.0 - nalgebra::Vector3::new(0.25, 0.06, 0.06)).norm() < 1e-12);
        m.tets.clear();
        assert_eq!(m.bounding_box().1.x, 9.0);
        m.vertices.clear();
        assert_eq!(m.bounding_box().0.norm(), 0.0);
    }
}
