//! The binary formats read by transcoding or decompressing (legacy VTK `BINARY`, `.vtu` inline
//! base64 with zlib blocks, `.vtu` appended raw): seeded mutations of small meshes written here
//! end in a mesh or a typed error, never a panic, under the binary's heap cap (a header that
//! declares gigabytes of blocks must not get them).

use std::path::Path;

use fem_core::MeshError;
use fem_core::io::parse_mesh;
use fem_core::rng::SplitMix64;

use super::mutate::random_mutation;
use super::{setup, writers};

/// `mesh` as a big-endian legacy VTK 5.1 `BINARY` file.
fn vtk_binary(mesh: &fem_core::TetMesh) -> Vec<u8> {
    let mut b = format!(
        "# vtk DataFile Version 5.1\nfuzz\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS {} double\n",
        mesh.num_vertices()
    )
    .into_bytes();
    for v in &mesh.vertices {
        for c in v.iter() {
            b.extend(c.to_be_bytes());
        }
    }
    let n = mesh.num_tets();
    b.extend(format!("\nCELLS {} {}\nOFFSETS vtktypeint64\n", n + 1, 4 * n).bytes());
    for i in 0..=n as i64 {
        b.extend((4 * i).to_be_bytes());
    }
    b.extend(b"\nCONNECTIVITY vtktypeint64\n");
    for t in &mesh.tets {
        for &i in t {
            b.extend((i as i64).to_be_bytes());
        }
    }
    b.extend(format!("\nCELL_TYPES {n}\n").bytes());
    for _ in 0..n {
        b.extend(10i32.to_be_bytes());
    }
    b.push(b'\n');
    b
}

/// The raw little-endian bytes of the four arrays of a `.vtu` piece.
fn arrays(mesh: &fem_core::TetMesh) -> [(&'static str, &'static str, Vec<u8>); 4] {
    let points = mesh
        .vertices
        .iter()
        .flat_map(|v| v.iter().flat_map(|c| c.to_le_bytes()))
        .collect();
    let connectivity = mesh
        .tets
        .iter()
        .flatten()
        .flat_map(|&i| (i as i64).to_le_bytes())
        .collect();
    let offsets = (1..=mesh.num_tets() as i64)
        .flat_map(|i| (4 * i).to_le_bytes())
        .collect();
    let types = vec![10u8; mesh.num_tets()];
    [
        ("Points\" NumberOfComponents=\"3", "Float64", points),
        ("connectivity", "Int64", connectivity),
        ("offsets", "Int64", offsets),
        ("types", "UInt8", types),
    ]
}

fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    bytes
        .chunks(3)
        .flat_map(|c| {
            let n = c
                .iter()
                .enumerate()
                .fold(0u32, |n, (i, &b)| n | u32::from(b) << (16 - 8 * i));
            (0..4).map(move |i| {
                if i <= c.len() {
                    ABC[(n >> (18 - 6 * i) & 63) as usize]
                } else {
                    b'='
                }
            })
        })
        .map(char::from)
        .collect()
}

/// `mesh` as a `.vtu` file, its arrays inline base64 in zlib blocks of 64 bytes (`appended`
/// false, as meshio writes) or appended raw and uncompressed (as ParaView can save).
fn vtu(mesh: &fem_core::TetMesh, appended: bool) -> Vec<u8> {
    let mut tail = Vec::new();
    let mut body = String::new();
    for (name, ty, bytes) in arrays(mesh) {
        if appended {
            body += &format!(
                "<DataArray type=\"{ty}\" Name=\"{name}\" format=\"appended\" offset=\"{}\"/>\n",
                tail.len()
            );
            tail.extend((bytes.len() as u64).to_le_bytes());
            tail.extend(&bytes);
        } else {
            let blocks: Vec<Vec<u8>> = bytes
                .chunks(64)
                .map(|c| miniz_oxide::deflate::compress_to_vec_zlib(c, 6))
                .collect();
            let last = bytes.len() - (blocks.len().max(1) - 1) * 64;
            let mut head = Vec::new();
            for v in [blocks.len(), 64, last]
                .into_iter()
                .chain(blocks.iter().map(Vec::len))
            {
                head.extend((v as u32).to_le_bytes());
            }
            body += &format!(
                "<DataArray type=\"{ty}\" Name=\"{name}\" format=\"binary\">{}{}</DataArray>\n",
                base64(&head),
                base64(&blocks.concat())
            );
        }
    }
    let (points, cells): (Vec<&str>, Vec<&str>) = {
        let lines: Vec<&str> = body.lines().collect();
        (lines[..1].to_vec(), lines[1..].to_vec())
    };
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"{}\"{}>\n<UnstructuredGrid>\n\
         <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n<Points>\n{}\n</Points>\n\
         <Cells>\n{}\n</Cells>\n</Piece>\n</UnstructuredGrid>\n",
        if appended { "UInt64" } else { "UInt32" },
        if appended {
            ""
        } else {
            " compressor=\"vtkZLibDataCompressor\""
        },
        mesh.num_vertices(),
        mesh.num_tets(),
        points.join("\n"),
        cells.join("\n")
    )
    .into_bytes();
    if appended {
        out.extend(b"<AppendedData encoding=\"raw\">\n_");
        out.extend(tail);
        out.extend(b"\n</AppendedData>\n");
    }
    out.extend(b"</VTKFile>\n");
    out
}

/// Every written file reads as the mesh it holds; mutations of it end in a validated mesh or a
/// typed error naming the file.
#[test]
fn campaign_binary_vtk_and_vtu() {
    setup();
    let mesh = writers::box_of([2, 2, 1]);
    let bases: [(&str, Vec<u8>); 3] = [
        ("fuzz-input.vtk", vtk_binary(&mesh)),
        ("fuzz-input.vtu", vtu(&mesh, false)),
        ("fuzz-input.vtu", vtu(&mesh, true)),
    ];
    let mut rng = SplitMix64::new(74);
    let (mut valid, mut refused) = (0, 0);
    for (name, bytes) in &bases {
        let path = Path::new(name);
        let (read, _) = parse_mesh(bytes, path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            (read.vertices.len(), read.num_tets()),
            (mesh.num_vertices(), mesh.num_tets())
        );
        for _ in 0..2000 {
            let edits = 1 + rng.below(3);
            let mutated = (0..edits).fold(bytes.clone(), |b, _| {
                random_mutation(&mut rng, true).apply(&b)
            });
            match parse_mesh(&mutated, path) {
                Ok((m, _)) => {
                    assert!(m.tets.iter().flatten().all(|&i| i < m.num_vertices()));
                    assert!((0..m.num_tets()).all(|t| m.signed_volume(t) > 0.0));
                    valid += 1;
                }
                Err(e @ (MeshError::Parse { .. } | MeshError::Invalid { .. })) => {
                    assert!(e.to_string().contains(name), "{e}");
                    refused += 1;
                }
                Err(e) => panic!("{name}: an unexpected error kind: {e:?}"),
            }
        }
    }
    println!("binary VTK and .vtu: {valid} mutated inputs read, {refused} refused");
    assert!(refused > 0);
}
