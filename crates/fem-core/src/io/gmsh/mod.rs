//! Gmsh `.msh` reader: one parser per format version, chosen by the `$MeshFormat` header.
//!
//! - **2.x ASCII** (2.0–2.2): `gmsh/v2.rs`, line by line. 2.x binary is rejected.
//! - **4.1 ASCII and binary**: `gmsh/v41.rs`, value by value. 4.0 and older formats are rejected.
//!
//! Both keep the 4-node tetrahedra and skip every other element type. Every node becomes a
//! vertex, in the file's node order (nodes no tet uses are kept; validation reports them), and
//! node tags are mapped to 0-based indices. Errors are [`MeshError::Parse`] with a 1-based line
//! (0 for binary files, whose byte offset the reason gives).
//!
//! Why not the `mshio` crate for 4.1: it drops dense node tags (yet dense tags need not come in
//! file order), gives no line numbers, reserves memory for whatever count a header declares
//! (nom 5's `count`) and panics on some malformed input (`unimplemented!`, a `size_t` size above
//! 255). Guarding it took a pass of our own over `$Nodes` and `$Elements` that read every value
//! mshio reads, so that pass is the parser.

use std::collections::HashMap;
use std::path::Path;

use crate::{MeshError, TetMesh, Vec3};

mod v2;
mod v41;

/// Gmsh element type of the 4-node tetrahedron.
const TET4: i64 = 4;

/// How many elements of each skipped (non-`TET4`) Gmsh element type a file holds.
type Skipped = HashMap<i64, usize>;

/// Reads the Gmsh `.msh` file at `path` (not validated).
pub fn read(path: &Path) -> Result<TetMesh, MeshError> {
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_bytes(&bytes, path)
}

/// Parses the content of a Gmsh `.msh` file (2.x ASCII, 4.1 ASCII or binary); `path` only names
/// the source in errors.
pub fn parse_bytes(bytes: &[u8], path: &Path) -> Result<TetMesh, MeshError> {
    let format = mesh_format(bytes, path)?;
    let err = |reason: String| parse_error(path, format.line, reason);
    let (text, version) = (&format.version_text, format.version);
    if (2.0..3.0).contains(&version) {
        if format.binary {
            return Err(err(format!(
                "binary Gmsh {text} files are not supported: save as ASCII (Mesh.Binary = 0) or as MSH 4.1"
            )));
        }
        v2::parse(&String::from_utf8_lossy(bytes), path)
    } else if text == "4.1" {
        v41::parse(bytes, path, &format)
    } else if (4.0..4.1).contains(&version) {
        Err(err(format!(
            "Gmsh MSH {text} is not supported: re-export as MSH 4.1 (gmsh -format msh41) or 2.2"
        )))
    } else {
        Err(err(format!(
            "unsupported Gmsh MSH version {text} (supported: 2.2 ASCII, 4.1 ASCII and binary)"
        )))
    }
}

/// 1-based line of the `t`-th 4-node tetrahedron (0-based, in file order) of a text file that
/// [`parse_bytes`] read, for messages about a tet that validation refuses; `None` in binary
/// files.
pub(crate) fn tet_line(bytes: &[u8], t: usize) -> Option<usize> {
    let format = mesh_format(bytes, Path::new("")).ok()?;
    if format.version < 3.0 {
        v2::tet_line(&String::from_utf8_lossy(bytes), t)
    } else {
        v41::tet_line(bytes, &format, t)
    }
}

fn parse_error(path: &Path, line: usize, reason: impl Into<String>) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        line,
        reason: reason.into(),
    }
}

/// At most 40 characters of `s`, for quoting input in messages.
fn snippet(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if s.chars().nth(40).is_some() {
        out.push('…');
    }
    out
}

/// The `$MeshFormat` header.
#[derive(Debug)]
struct MeshFormat {
    version_text: String,
    version: f64,
    binary: bool,
    /// sizeof(size_t) in binary files.
    data_size: usize,
    /// Byte offset just after the `version file-type data-size` line.
    body: usize,
    /// Line of the `version file-type data-size` line.
    line: usize,
}

fn mesh_format(bytes: &[u8], path: &Path) -> Result<MeshFormat, MeshError> {
    let mut offset = 0;
    let mut lines = bytes.split(|&b| b == b'\n').enumerate().map(|(i, l)| {
        offset += l.len() + 1;
        (i + 1, offset, l.trim_ascii())
    });
    let Some((line, _, first)) = lines.find(|(_, _, l)| !l.is_empty()) else {
        return Err(parse_error(path, 1, "empty file: expected $MeshFormat"));
    };
    if first == b"$NOD" {
        return Err(parse_error(
            path,
            line,
            "Gmsh MSH 1.0 ($NOD) is not supported: re-export as MSH 4.1 or 2.2",
        ));
    }
    if first != b"$MeshFormat" {
        return Err(parse_error(
            path,
            line,
            format!(
                "expected $MeshFormat on the first line, found '{}': a `.msh` file is read as \
                 Gmsh's, and some tools (IPC's examples, for one) write their own format under \
                 that name; write it from the tool that made it as Gmsh MSH 4.1 or 2.2, MEDIT \
                 `.mesh`, legacy VTK or TetGen `.node`/`.ele`",
                snippet(&String::from_utf8_lossy(first))
            ),
        ));
    }
    let Some((line, body, header)) = lines.next() else {
        return Err(parse_error(
            path,
            line,
            "unexpected end of file: expected 'version file-type data-size' after $MeshFormat",
        ));
    };
    let header = String::from_utf8_lossy(header);
    let bad = || {
        parse_error(
            path,
            line,
            format!(
                "expected 'version file-type data-size' (e.g. '4.1 0 8'), found '{}'",
                snippet(&header)
            ),
        )
    };
    let fields: Vec<&str> = header.split_whitespace().collect();
    let [version_text, file_type, data_size] = fields[..] else {
        return Err(bad());
    };
    let version: f64 = version_text.parse().map_err(|_| bad())?;
    let binary = match file_type {
        "0" => false,
        "1" => true,
        _ => return Err(bad()),
    };
    let data_size: usize = data_size.parse().map_err(|_| bad())?;
    // 4.1 declares the size in ASCII files too; only 4 and 8 exist.
    if (binary || version_text == "4.1") && data_size != 4 && data_size != 8 {
        return Err(parse_error(
            path,
            line,
            format!("unsupported size_t size {data_size} (expected 4 or 8)"),
        ));
    }
    Ok(MeshFormat {
        version_text: version_text.to_string(),
        version,
        binary,
        data_size,
        body,
        line,
    })
}

/// The name of a Gmsh element type that a file without tetrahedra most often holds instead.
fn element_name(t: i64) -> Option<&'static str> {
    Some(match t {
        1 => "2-node line",
        2 => "3-node triangle",
        3 => "4-node quadrangle",
        5 => "8-node hexahedron",
        6 => "6-node prism",
        7 => "5-node pyramid",
        8 => "3-node line",
        9 => "6-node triangle",
        10 => "9-node quadrangle",
        11 => "10-node tetrahedron",
        15 => "point",
        16 => "8-node quadrangle",
        29 => "20-node tetrahedron",
        _ => return None,
    })
}

/// What to do about a file whose elements hold no 4-node tetrahedron, by what it holds: higher
/// order tetrahedra (mesh at order 1), only surfaces, lines and points (the volume was not
/// meshed, or not saved: gmsh saves only the elements of physical groups when there are any).
fn missing_tets_remedy(types: &[i64]) -> &'static str {
    // Lines, triangles, quadrangles and points of every order Gmsh writes.
    const LOWER_DIMENSIONS: [i64; 17] = [
        1, 2, 3, 8, 9, 10, 15, 16, 20, 21, 22, 23, 24, 25, 26, 27, 28,
    ];
    if types.iter().any(|t| matches!(t, 11 | 29 | 30 | 31)) {
        "; higher-order tetrahedra are not read: mesh with first-order elements (`-order 1` \
         on gmsh's command line, `Mesh.ElementOrder = 1` in a .geo file)"
    } else if !types.is_empty() && types.iter().all(|t| LOWER_DIMENSIONS.contains(t)) {
        "; that is a surface (or line) mesh, and a volume mesh is needed: mesh the volume (`gmsh -3 \
         part.geo`, or Mesh > 3D), and where the .geo file defines physical groups give the \
         volume one (`Physical Volume`) or set `Mesh.SaveAll = 1`, since gmsh then saves only \
         the elements of physical groups"
    } else {
        "; a tetrahedral volume mesh is needed (in gmsh, no `Recombine` and \
         `Mesh.SubdivisionAlgorithm = 0`)"
    }
}

/// Builds the mesh, refusing a file without any 4-node tetrahedron with a message naming what
/// it holds instead.
fn finish(
    vertices: Vec<Vec3>,
    tets: Vec<[usize; 4]>,
    ignored: &Skipped,
    path: &Path,
    line: usize,
) -> Result<TetMesh, MeshError> {
    let mut kinds: Vec<(i64, usize)> = ignored.iter().map(|(&t, &n)| (t, n)).collect();
    kinds.sort_unstable();
    let summary = kinds
        .iter()
        .map(|&(t, n)| match element_name(t) {
            Some(name) => format!("{n} of type {t} ({name})"),
            None => format!("{n} of type {t}"),
        })
        .collect::<Vec<_>>()
        .join(", ");
    if tets.is_empty() {
        let held = if summary.is_empty() {
            "no elements".to_string()
        } else {
            summary
        };
        let types: Vec<i64> = kinds.iter().map(|&(t, _)| t).collect();
        return Err(parse_error(
            path,
            line,
            format!(
                "no 4-node tetrahedra (Gmsh element type 4) in the file; it holds {held}{}",
                missing_tets_remedy(&types)
            ),
        ));
    }
    // Hexahedra, prisms, pyramids and higher-order tetrahedra of every order Gmsh writes.
    let volumes: Vec<String> = kinds
        .iter()
        .filter(|(t, _)| {
            matches!(
                t,
                5 | 6 | 7 | 11 | 12 | 13 | 14 | 17 | 18 | 19 | 29..=35 | 71..=79 | 92 | 93
            )
        })
        .map(|&(t, n)| match element_name(t) {
            Some(name) => format!("{n} of type {t} ({name})"),
            None => format!("{n} of type {t}"),
        })
        .collect();
    if !volumes.is_empty() {
        return Err(parse_error(
            path,
            line,
            super::other_volumes_problem(&volumes.join(", "), tets.len()),
        ));
    }
    if !summary.is_empty() {
        tracing::debug!(
            "{}: ignored non-tetrahedral elements: {summary}",
            path.display()
        );
    }
    Ok(TetMesh { vertices, tets })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::MAX_ENTITIES;

    const V22: &str = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n\
        $PhysicalNames\n1\n3 1 \"solid\"\n$EndPhysicalNames\n\
        $Nodes\n5\n10 0 0 0\n20 1 0 0\n30 0 1 0\n40 0 0 1\n50 9 9 9\n$EndNodes\n\
        $Elements\n3\n1 15 2 0 1 10\n2 2 2 0 1 10 20 30\n3 4 2 1 1 10 20 30 40\n$EndElements\n";

    const V41: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n\
        $Nodes\n2 5 1 5\n0 1 0 1\n5\n9 9 9\n3 1 0 4\n4\n3\n2\n1\n0 0 1\n0 1 0\n1 0 0\n0 0 0\n$EndNodes\n\
        $Elements\n2 2 1 2\n2 1 2 1\n1 1 2 3\n3 1 4 1\n2 1 2 3 4\n$EndElements\n";

    fn parse_str(text: &str) -> Result<TetMesh, MeshError> {
        parse_bytes(text.as_bytes(), Path::new("test.msh"))
    }

    /// The line and reason of a parse error (panics on anything else, which fails the test).
    fn parse_error(bytes: &[u8]) -> (usize, String) {
        match parse_bytes(bytes, Path::new("test.msh")) {
            Err(MeshError::Parse { line, reason, .. }) => (line, reason),
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    /// A 2.2 file saved with `Mesh.SaveParametric` says so.
    #[test]
    fn parametric_nodes_are_named() {
        let parametric = V22
            .replace("$Nodes\n", "$ParametricNodes\n")
            .replace("$EndNodes", "$EndParametricNodes");
        let (_, reason) = parse_error(parametric.as_bytes());
        assert!(reason.contains("without Mesh.SaveParametric"), "{reason}");
    }

    /// One file of a mesh gmsh split over several is refused; a file with every partition, or
    /// whose `$PartitionedEntities` cannot be read, is read as it is.
    #[test]
    fn one_file_of_a_split_mesh_is_refused() {
        let partitioned = |volume_1_in: &str| {
            V41.replace(
                "$Nodes\n",
                &format!(
                    "$PartitionedEntities\n2\n0\n0 0 0 2\n\
                     1 3 1 {volume_1_in} 0 0 0 1 1 1 0 0\n\
                     2 3 1 1 2 0 0 0 1 1 1 0 0\n$EndPartitionedEntities\n$Nodes\n"
                ),
            )
        };
        let (line, reason) = parse_error(partitioned("1 1").as_bytes());
        assert_eq!(line, 5, "{reason}"); // the number of partitions
        assert!(
            reason.contains("holds partition 1 of the 2 gmsh split the mesh into"),
            "{reason}"
        );
        for whole in [partitioned("2 1 2"), partitioned("1 x")] {
            assert_eq!(parse_str(&whole).expect(&whole).tets.len(), 1);
        }
    }

    /// A hexahedron beside the tetrahedra is refused, not dropped.
    #[test]
    fn other_volume_elements_beside_tetrahedra_are_refused() {
        let hexed = V22.replace(
            "$Elements\n3\n",
            "$Elements\n4\n9 5 2 1 1 10 20 30 40 50 10 20 30\n",
        );
        let (_, reason) = parse_error(hexed.as_bytes());
        assert!(
            reason.contains("1 of type 5 (8-node hexahedron) beside its 1 tetrahedra"),
            "{reason}"
        );
    }

    /// The V41 mesh written as MSH 4.1 binary (little-endian, 8-byte size_t).
    fn v41_binary() -> Vec<u8> {
        let mut b = b"$MeshFormat\n4.1 1 8\n".to_vec();
        b.extend(1i32.to_le_bytes());
        b.extend(b"\n$EndMeshFormat\n$Nodes\n");
        let st = |b: &mut Vec<u8>, v: u64| b.extend(v.to_le_bytes());
        let int = |b: &mut Vec<u8>, v: i32| b.extend(v.to_le_bytes());
        let dbl = |b: &mut Vec<u8>, v: f64| b.extend(v.to_le_bytes());
        for v in [2, 5, 1, 5] {
            st(&mut b, v);
        }
        for v in [0, 1, 0] {
            int(&mut b, v);
        }
        st(&mut b, 1);
        st(&mut b, 5);
        for v in [9.0, 9.0, 9.0] {
            dbl(&mut b, v);
        }
        for v in [3, 1, 0] {
            int(&mut b, v);
        }
        st(&mut b, 4);
        for v in [4, 3, 2, 1] {
            st(&mut b, v);
        }
        for v in [0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0] {
            dbl(&mut b, v);
        }
        b.extend(b"\n$EndNodes\n$Elements\n");
        for v in [1, 1, 2, 2] {
            st(&mut b, v);
        }
        for v in [3, 1, 4] {
            int(&mut b, v);
        }
        st(&mut b, 1);
        for v in [2, 1, 2, 3, 4] {
            st(&mut b, v);
        }
        b.extend(b"\n$EndElements\n");
        b
    }

    #[test]
    fn v22_maps_arbitrary_tags_keeps_all_nodes_and_only_tets() {
        let mesh = parse_str(V22).unwrap();
        assert_eq!(mesh.vertices.len(), 5, "unreferenced node 50 is kept");
        assert_eq!(mesh.vertices[4], Vec3::new(9.0, 9.0, 9.0));
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3]]);
    }

    #[test]
    fn v41_ascii_and_binary_follow_the_file_node_order() {
        let ascii = parse_str(V41).unwrap();
        // Node tags 5, 4, 3, 2, 1 come in that order: dense, but not sorted.
        assert_eq!(ascii.vertices[1], Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(ascii.vertices[4], Vec3::new(0.0, 0.0, 0.0));
        assert_eq!(ascii.tets, vec![[4, 3, 2, 1]]);
        let binary = parse_bytes(&v41_binary(), Path::new("b.msh")).unwrap();
        assert_eq!(binary, ascii);
    }

    #[test]
    fn sparse_tags_and_crlf_are_fine() {
        let sparse = V41
            .replace("2 5 1 5\n", "2 5 1 5000\n")
            .replace("\n5\n9 9 9", "\n5000\n9 9 9");
        assert_eq!(parse_str(&sparse).unwrap(), parse_str(V41).unwrap());
        let crlf = V22.replace('\n', "\r\n");
        assert_eq!(parse_str(&crlf).unwrap(), parse_str(V22).unwrap());
    }

    #[test]
    fn unsupported_versions_are_rejected_clearly() {
        let bin22 = V22.replace("2.2 0 8", "2.2 1 8");
        assert!(parse_error(bin22.as_bytes()).1.contains("binary Gmsh 2.2"));
        let v40 = V41.replace("4.1 0 8", "4 0 8");
        assert!(
            parse_error(v40.as_bytes())
                .1
                .contains("MSH 4 is not supported")
        );
        assert!(
            parse_error(b"$NOD\n1\n1 0 0 0\n$ENDNOD\n")
                .1
                .contains("1.0")
        );
        assert!(parse_error(b"").1.contains("empty"));
        // Another tool's `.msh` (IPC's starts with its nodes): said not to be Gmsh's, with the
        // conversion.
        let other = parse_error(b"$Nodes\n4\n0 0 0\n");
        assert_eq!(other.0, 1);
        assert!(
            other.1.contains("found '$Nodes'") && other.1.contains("from the tool that made it"),
            "{}",
            other.1
        );
        assert!(
            parse_error(b"$MeshFormat\n5.0 0 8\n$EndMeshFormat\n")
                .1
                .contains("unsupported")
        );
        assert_eq!(parse_error(b"$MeshFormat\n4.1 x 8\n").0, 2);
        assert!(parse_error(b"$MeshFormat\n4.1 1 3\n").1.contains("size_t"));
    }

    #[test]
    fn v22_truncation_and_count_mismatch_are_errors() {
        let cut = &V22[..V22.find("40 0 0 1").unwrap()];
        let (line, reason) = parse_error(cut.as_bytes());
        assert!(reason.contains("end of file"), "{reason}");
        assert_eq!(line, 12);
        let short = V22.replace("$Nodes\n5", "$Nodes\n6");
        let (line, reason) = parse_error(short.as_bytes());
        assert_eq!(line, 15);
        assert!(reason.contains("fewer nodes"), "{reason}");
        let long = V22.replace("$Nodes\n5", "$Nodes\n4");
        assert!(parse_error(long.as_bytes()).1.contains("$EndNodes"));
        for end in 0..V22.len() {
            if let Ok(mesh) = parse_str(&V22[..end]) {
                assert_eq!(mesh.tets.len(), 1, "prefix of {end} bytes");
            }
        }
    }

    #[test]
    fn v41_truncation_is_an_error() {
        for end in 0..V41.len() {
            if let Ok(mesh) = parse_str(&V41[..end]) {
                assert_eq!(mesh.tets.len(), 1, "prefix of {end} bytes");
            }
        }
        let binary = v41_binary();
        for end in 0..binary.len() {
            if let Ok(mesh) = parse_bytes(&binary[..end], Path::new("b.msh")) {
                assert_eq!(mesh.tets.len(), 1, "prefix of {end} bytes");
            }
        }
    }

    #[test]
    fn bad_node_references_are_reported_with_their_line() {
        let bad = V22.replace("3 4 2 1 1 10 20 30 40", "3 4 2 1 1 10 20 30 41");
        let (line, reason) = parse_error(bad.as_bytes());
        assert_eq!(line, 20);
        assert!(reason.contains("node 41"), "{reason}");
        let bad = V41.replace("2 1 2 3 4", "2 1 2 3 9");
        let (line, reason) = parse_error(bad.as_bytes());
        assert_eq!(line, 24);
        assert!(reason.contains("node 9"), "{reason}");
        let dup = V41.replace("4\n3\n2\n1\n", "4\n4\n2\n1\n");
        let (line, reason) = parse_error(dup.as_bytes());
        assert_eq!(line, 11);
        assert!(reason.contains("twice"), "{reason}");
    }

    #[test]
    fn non_finite_coordinates_are_rejected_with_their_line() {
        for bad in ["nan", "inf", "1e999"] {
            let text = V22.replace("20 1 0 0", &format!("20 1 {bad} 0"));
            let (line, reason) = parse_error(text.as_bytes());
            assert_eq!(line, 11, "{reason}");
            assert!(reason.contains("not finite"), "{reason}");
            let text = V41.replace("0 1 0\n", &format!("0 {bad} 0\n"));
            let (line, reason) = parse_error(text.as_bytes());
            assert_eq!(line, 15, "{reason}");
            assert!(reason.contains("y coordinate of node 3"), "{reason}");
        }
        let mut binary = v41_binary();
        let at = binary
            .windows(8)
            .position(|w| w == 9.0f64.to_le_bytes())
            .unwrap();
        binary[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        let (line, reason) = parse_error(&binary);
        assert_eq!(line, 0);
        assert!(
            reason.contains("not finite") && reason.contains("byte"),
            "{reason}"
        );
    }

    #[test]
    fn huge_counts_fail_fast() {
        let text = V22.replace("$Nodes\n5", "$Nodes\n1000000000000");
        let (line, reason) = parse_error(text.as_bytes());
        assert_eq!(line, 9);
        assert!(reason.contains("limit"), "{reason}");
        let text = V22.replace("$Elements\n3", &format!("$Elements\n{MAX_ENTITIES}"));
        assert!(parse_error(text.as_bytes()).1.contains("fewer elements"));
        let text = V41.replace("2 5 1 5\n", "2 1000000000000 1 5\n");
        assert!(parse_error(text.as_bytes()).1.contains("limit"));
        let text = V41.replace("3 1 0 4", "3 1 0 40000000");
        assert!(parse_error(text.as_bytes()).1.contains("more than the 5"));
        let text = V41.replace("2 2 1 2", "2 99999999999 1 2");
        assert!(parse_error(text.as_bytes()).1.contains("limit"));
        let text = V41.replace("2 2 1 2", "2 0 1 2");
        assert!(parse_error(text.as_bytes()).1.contains("no elements"));
        let text = V41.replace("2 5 1 5\n", "0 0 1 5\n");
        assert!(parse_error(text.as_bytes()).1.contains("no nodes"));
    }

    #[test]
    fn malformed_headers_and_counts_found_by_fuzzing_are_typed_errors() {
        // A size_t size other than 4 or 8 is refused at the header line.
        let (line, reason) = parse_error(V41.replace("4.1 0 8", "4.1 0 999").as_bytes());
        assert_eq!(line, 2);
        assert!(reason.contains("size_t"), "{reason}");
        // A negative number of tags used to shift the node list silently.
        let text = V22.replace("3 4 2 1 1 10 20 30 40", "3 4 -2 10 20 30 40");
        let (line, reason) = parse_error(text.as_bytes());
        assert_eq!(line, 20);
        assert!(reason.contains("negative"), "{reason}");
        // An element block larger than the section: refused at its line before it is read.
        let text = V41.replace("3 1 4 1\n", "3 1 4 1000000000000\n");
        let (line, reason) = parse_error(text.as_bytes());
        assert_eq!(line, 23);
        assert!(reason.contains("limit"), "{reason}");
        let text = V41.replace("3 1 4 1\n", "3 1 4 2\n");
        let (line, reason) = parse_error(text.as_bytes());
        assert_eq!(line, 23);
        assert!(reason.contains("more than the 1 left"), "{reason}");
        let text = V41.replace("2 2 1 2\n", "2 3 1 3\n");
        let (_, reason) = parse_error(text.as_bytes());
        assert!(reason.contains("blocks hold 2"), "{reason}");
        // cargo fuzz (gmsh_v41): a binary header ending the file was reported at line 3 of 2.
        let (line, reason) = parse_error(b"$MeshFormat\n4.1 1  8");
        assert_eq!(line, 2);
        assert!(reason.contains("byte order"), "{reason}");
    }

    #[test]
    fn a_file_without_tets_says_what_it_holds() {
        let text = V22.replace(
            "3 4 2 1 1 10 20 30 40",
            "3 11 2 1 1 10 20 30 40 10 10 10 10 10 10",
        );
        let (_, reason) = parse_error(text.as_bytes());
        assert!(
            reason.contains("1 of type 11 (10-node tetrahedron)"),
            "{reason}"
        );
        assert!(
            reason.contains("higher-order tetrahedra are not read"),
            "{reason}"
        );
        assert!(reason.contains("`-order 1`"), "{reason}");
        // Only a triangle: a surface mesh, with the physical-group trap named.
        let text = V22.replace("3 4 2 1 1 10 20 30 40", "3 2 2 1 1 10 20 30");
        let (_, reason) = parse_error(text.as_bytes());
        assert!(
            reason.contains(
                "(3-node triangle), 1 of type 15 (point); that is a surface (or line) mesh"
            ),
            "{reason}"
        );
        assert!(reason.contains("`Mesh.SaveAll = 1`"), "{reason}");
        // A hexahedron: not tetrahedral.
        let text = V22.replace("3 4 2 1 1 10 20 30 40", "3 5 2 1 1 10 20 30 40 10 20 30 40");
        let (_, reason) = parse_error(text.as_bytes());
        assert!(
            reason.contains("(8-node hexahedron), 1 of type 15 (point); a tetrahedral volume mesh"),
            "{reason}"
        );
    }

    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        fn mutate(base: &[u8], edits: &[(usize, u8)]) -> Vec<u8> {
            let mut bytes = base.to_vec();
            for &(pos, b) in edits {
                if let Some(slot) = bytes.get_mut(pos % base.len().max(1)) {
                    *slot = b;
                }
            }
            bytes
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            #[test]
            fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
                let _ = parse_bytes(&bytes, Path::new("f.msh"));
                let mut with_header = b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n".to_vec();
                with_header.extend(&bytes);
                let _ = parse_bytes(&with_header, Path::new("f.msh"));
            }

            #[test]
            fn mutated_valid_files_never_panic(
                edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..6)
            ) {
                let _ = parse_bytes(&mutate(V22.as_bytes(), &edits), Path::new("f.msh"));
                let _ = parse_bytes(&mutate(V41.as_bytes(), &edits), Path::new("f.msh"));
                let _ = parse_bytes(&mutate(&v41_binary(), &edits), Path::new("f.msh"));
            }

            #[test]
            fn mutated_digits_never_panic(
                edits in prop::collection::vec((any::<usize>(), b'0'..=b'9'), 1..4)
            ) {
                for base in [V22.as_bytes(), V41.as_bytes()] {
                    if let Ok(mesh) = parse_bytes(&mutate(base, &edits), Path::new("f.msh")) {
                        prop_assert!(mesh.tets.iter().flatten().all(|&i| i < mesh.vertices.len()));
                    }
                }
            }
        }
    }
}
