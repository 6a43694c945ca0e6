//! Small meshes written in every format the readers take, so the malformed-input tests need no
//! files from `shared/`. Each writer produces what the real exporter writes (extra sections
//! included), but only as much as the readers need.

use fem_core::TetMesh;
use fem_core::mesh::generate::{BoxSpec, box_mesh};

/// A file format and the reader that takes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Medit,
    Gmsh22,
    Gmsh41Ascii,
    Gmsh41Binary,
    Vtk42,
    Vtk51,
}

impl Format {
    pub const ALL: [Format; 6] = [
        Format::Medit,
        Format::Gmsh22,
        Format::Gmsh41Ascii,
        Format::Gmsh41Binary,
        Format::Vtk42,
        Format::Vtk51,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Format::Medit => "medit",
            Format::Gmsh22 => "gmsh22",
            Format::Gmsh41Ascii => "gmsh41",
            Format::Gmsh41Binary => "gmsh41-binary",
            Format::Vtk42 => "vtk42",
            Format::Vtk51 => "vtk51",
        }
    }

    pub fn extension(self) -> &'static str {
        match self {
            Format::Medit => "mesh",
            Format::Gmsh22 | Format::Gmsh41Ascii | Format::Gmsh41Binary => "msh",
            Format::Vtk42 | Format::Vtk51 => "vtk",
        }
    }

    pub fn write(self, mesh: &TetMesh) -> Vec<u8> {
        match self {
            Format::Medit => medit(mesh).into_bytes(),
            Format::Gmsh22 => gmsh22(mesh).into_bytes(),
            Format::Gmsh41Ascii => gmsh41_ascii(mesh).into_bytes(),
            Format::Gmsh41Binary => gmsh41_binary(mesh),
            Format::Vtk42 => vtk42(mesh).into_bytes(),
            Format::Vtk51 => vtk51(mesh).into_bytes(),
        }
    }
}

/// A box of `cells` hexahedra, 6 tets each.
pub fn box_of(cells: [usize; 3]) -> TetMesh {
    box_mesh(&BoxSpec {
        size: [0.3, 0.1, 0.1],
        cells,
        ..Default::default()
    })
    .expect("a valid box")
}

fn xyz(v: &fem_core::Vec3) -> String {
    format!("{:?} {:?} {:?}", v.x, v.y, v.z)
}

pub fn medit(mesh: &TetMesh) -> String {
    let mut s = String::from("MeshVersionFormatted 2\nDimension 3\n");
    s += &format!("Vertices\n{}\n", mesh.num_vertices());
    for v in &mesh.vertices {
        s += &format!("{} 0\n", xyz(v));
    }
    let tris = mesh.surface_triangles();
    s += &format!("Triangles\n{}\n", tris.len());
    for t in &tris {
        s += &format!("{} {} {} 2\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s += &format!("Tetrahedra\n{}\n", mesh.num_tets());
    for t in &mesh.tets {
        s += &format!("{} {} {} {} 1\n", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1);
    }
    s + "End\n"
}

/// Node tags are sparse (`10 + 3i`), as Gmsh writes after removing nodes.
fn tag(i: usize) -> usize {
    10 + 3 * i
}

pub fn gmsh22(mesh: &TetMesh) -> String {
    let mut s = String::from(
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n2\n2 2 \"skin\"\n3 1 \"body\"\n$EndPhysicalNames\n",
    );
    s += &format!("$Nodes\n{}\n", mesh.num_vertices());
    for (i, v) in mesh.vertices.iter().enumerate() {
        s += &format!("{} {}\n", tag(i), xyz(v));
    }
    let tris = mesh.surface_triangles();
    s += &format!("$EndNodes\n$Elements\n{}\n", tris.len() + mesh.num_tets());
    let mut number = 1;
    for t in &tris {
        s += &format!(
            "{number} 2 2 2 1 {} {} {}\n",
            tag(t[0]),
            tag(t[1]),
            tag(t[2])
        );
        number += 1;
    }
    for t in &mesh.tets {
        s += &format!(
            "{number} 4 2 1 1 {} {} {} {}\n",
            tag(t[0]),
            tag(t[1]),
            tag(t[2]),
            tag(t[3])
        );
        number += 1;
    }
    s + "$EndElements\n"
}

/// Bounding box as `min max` text, for the `$Entities` section.
fn bbox(mesh: &TetMesh) -> String {
    let (lo, hi) = mesh.bounding_box();
    format!("{} {}", xyz(&lo), xyz(&hi))
}

pub fn gmsh41_ascii(mesh: &TetMesh) -> String {
    let n = mesh.num_vertices();
    let m = mesh.num_tets();
    let mut s = String::from("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n");
    s += &format!("$Entities\n0 0 0 1\n1 {} 1 1 0\n$EndEntities\n", bbox(mesh));
    // Two node blocks, so block bookkeeping is exercised.
    let half = n / 2;
    s += &format!("$Nodes\n2 {n} {} {}\n", tag(0), tag(n - 1));
    for (block, range) in [(1, 0..half), (2, half..n)] {
        s += &format!("3 {block} 0 {}\n", range.len());
        for i in range.clone() {
            s += &format!("{}\n", tag(i));
        }
        for i in range {
            s += &format!("{}\n", xyz(&mesh.vertices[i]));
        }
    }
    s += &format!("$EndNodes\n$Elements\n1 {m} 1 {m}\n3 1 4 {m}\n");
    for (e, t) in mesh.tets.iter().enumerate() {
        s += &format!(
            "{} {} {} {} {}\n",
            e + 1,
            tag(t[0]),
            tag(t[1]),
            tag(t[2]),
            tag(t[3])
        );
    }
    s + "$EndElements\n"
}

/// MSH 4.1 binary, little-endian, 8-byte `size_t`.
pub fn gmsh41_binary(mesh: &TetMesh) -> Vec<u8> {
    let n = mesh.num_vertices();
    let m = mesh.num_tets();
    let mut b = b"$MeshFormat\n4.1 1 8\n".to_vec();
    b.extend(1i32.to_le_bytes());
    b.extend(b"\n$EndMeshFormat\n$Nodes\n");
    let st = |b: &mut Vec<u8>, v: usize| b.extend((v as u64).to_le_bytes());
    let int = |b: &mut Vec<u8>, v: i32| b.extend(v.to_le_bytes());
    for v in [1, n, tag(0), tag(n - 1)] {
        st(&mut b, v);
    }
    for v in [3, 1, 0] {
        int(&mut b, v);
    }
    st(&mut b, n);
    for i in 0..n {
        st(&mut b, tag(i));
    }
    for v in &mesh.vertices {
        for c in v.iter() {
            b.extend(c.to_le_bytes());
        }
    }
    b.extend(b"\n$EndNodes\n$Elements\n");
    for v in [1, m, 1, m] {
        st(&mut b, v);
    }
    for v in [3, 1, 4] {
        int(&mut b, v);
    }
    st(&mut b, m);
    for (e, t) in mesh.tets.iter().enumerate() {
        st(&mut b, e + 1);
        for &i in t {
            st(&mut b, tag(i));
        }
    }
    b.extend(b"\n$EndElements\n");
    b
}

pub fn vtk42(mesh: &TetMesh) -> String {
    let n = mesh.num_vertices();
    let m = mesh.num_tets();
    let mut s = format!(
        "# vtk DataFile Version 4.2\nwritten by the fuzz tests\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS {n} double\n"
    );
    for v in &mesh.vertices {
        s += &format!("{}\n", xyz(v));
    }
    s += &format!("CELLS {m} {}\n", 5 * m);
    for t in &mesh.tets {
        s += &format!("4 {} {} {} {}\n", t[0], t[1], t[2], t[3]);
    }
    s += &format!("CELL_TYPES {m}\n");
    s += &"10\n".repeat(m);
    s += &format!("CELL_DATA {m}\nSCALARS id int 1\nLOOKUP_TABLE default\n");
    for e in 0..m {
        s += &format!("{e}\n");
    }
    s
}

pub fn vtk51(mesh: &TetMesh) -> String {
    let n = mesh.num_vertices();
    let m = mesh.num_tets();
    let mut s = format!(
        "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET UNSTRUCTURED_GRID\nFIELD FieldData 1\nTIME 1 1 double\n0\nPOINTS {n} double\n"
    );
    for v in &mesh.vertices {
        s += &format!("{}\n", xyz(v));
    }
    s += &format!("CELLS {} {}\nOFFSETS vtktypeint64\n", m + 1, 4 * m);
    let offsets: Vec<String> = (0..=m).map(|e| (4 * e).to_string()).collect();
    s += &offsets.join(" ");
    s += "\nCONNECTIVITY vtktypeint64\n";
    for t in &mesh.tets {
        s += &format!("{} {} {} {}\n", t[0], t[1], t[2], t[3]);
    }
    s += &format!("CELL_TYPES {m}\n");
    s += &"10\n".repeat(m);
    s
}
