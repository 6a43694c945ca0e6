//! Known mesh defects, written in every format and read back from files through `read_mesh`:
//! each is either repaired and reported (inverted tets, unreferenced vertices, disconnected
//! pieces) or refused with an error naming the file and, for values, the line that holds them.

use std::path::{Path, PathBuf};

use fem_core::io::{MAX_ENTITIES, read_mesh};
use fem_core::mesh::ValidationReport;
use fem_core::{MeshError, TetMesh, Vec3};

use super::setup;
use super::writers::{Format, box_of};

/// A folder for this test binary's files.
fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("fem-core-defects-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes `bytes` as `<case>-<format>.<ext>` and reads it back through `read_mesh`.
fn read_as(
    case: &str,
    format: Format,
    bytes: &[u8],
) -> (PathBuf, Result<(TetMesh, ValidationReport), MeshError>) {
    let path = dir().join(format!("{case}-{}.{}", format.name(), format.extension()));
    std::fs::write(&path, bytes).unwrap();
    let result = read_mesh(&path);
    (path, result)
}

/// Reads `mesh` written in every format; `expect` checks each result.
fn in_every_format(
    case: &str,
    mesh: &TetMesh,
    expect: impl Fn(Format, &Path, &[u8], Result<(TetMesh, ValidationReport), MeshError>),
) {
    setup();
    for format in Format::ALL {
        let bytes = format.write(mesh);
        let (path, result) = read_as(case, format, &bytes);
        expect(format, &path, &bytes, result);
    }
}

/// The reason of an [`MeshError::Invalid`] for `path`, failing the test on anything else.
fn invalid_reason(
    format: Format,
    path: &Path,
    result: Result<(TetMesh, ValidationReport), MeshError>,
) -> String {
    match result {
        Err(MeshError::Invalid { path: p, reason }) => {
            assert_eq!(p, path, "{}", format.name());
            reason
        }
        other => panic!(
            "{}: expected a validation error, got {other:?}",
            format.name()
        ),
    }
}

/// The line and reason of a [`MeshError::Parse`] for `path`, failing the test on anything else.
fn parse_error(
    format: Format,
    path: &Path,
    result: Result<(TetMesh, ValidationReport), MeshError>,
) -> (usize, String) {
    match result {
        Err(e @ MeshError::Parse { .. }) => {
            assert!(
                e.to_string().contains(&path.display().to_string()),
                "{}: {e}",
                format.name()
            );
            let MeshError::Parse {
                path: p,
                line,
                reason,
            } = e
            else {
                unreachable!()
            };
            assert_eq!(p, path, "{}", format.name());
            (line, reason)
        }
        other => panic!("{}: expected a parse error, got {other:?}", format.name()),
    }
}

/// Checks that the 1-based `line` of the text file `bytes` holds `token`; in the binary format
/// the line is 0 and the reason gives a byte offset instead.
fn assert_line_holds(format: Format, bytes: &[u8], line: usize, token: &str, reason: &str) {
    if format == Format::Gmsh41Binary {
        assert_eq!(line, 0, "{reason}");
        assert!(reason.contains("byte"), "{reason}");
        return;
    }
    let text = String::from_utf8_lossy(bytes);
    let held = text.lines().nth(line.wrapping_sub(1)).unwrap_or_default();
    assert!(
        held.split_whitespace().any(|t| t == token),
        "{}: line {line} is '{held}', which does not hold '{token}' ({reason})",
        format.name()
    );
}

/// Every "tetrahedron T of N (line L)" in `reason` (T counted from 1) points at the line of
/// `mesh`'s tet T − 1 in the text file `bytes` (the line holds its four vertices as the format
/// writes them); binary files give no lines, text files at least one.
fn assert_tet_lines(format: Format, bytes: &[u8], mesh: &TetMesh, reason: &str) {
    let text = String::from_utf8_lossy(bytes);
    let mut found = 0;
    // "tetrahedron 8 of 12 (line 42)", counted from 1.
    for (at, _) in reason.match_indices("tetrahedron ") {
        let rest = &reason[at + "tetrahedron ".len()..];
        let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
        let of = format!(" of {}", mesh.num_tets());
        let Some(line) = rest[digits.len()..]
            .strip_prefix(of.as_str())
            .and_then(|r| r.strip_prefix(" (line "))
            .and_then(|r| r.split(')').next())
            .and_then(|l| l.parse::<usize>().ok())
        else {
            continue;
        };
        let t: usize = digits.parse::<usize>().unwrap() - 1;
        let held: Vec<&str> = text
            .lines()
            .nth(line - 1)
            .unwrap_or_default()
            .split_whitespace()
            .collect();
        for &i in &mesh.tets[t] {
            let token = match format {
                Format::Medit => (i + 1).to_string(),
                Format::Gmsh22 | Format::Gmsh41Ascii | Format::Gmsh41Binary => {
                    (10 + 3 * i).to_string()
                }
                Format::Vtk42 | Format::Vtk51 => i.to_string(),
            };
            assert!(
                held.contains(&token.as_str()),
                "{}: line {line} {held:?} is not tet {t} {:?} ({reason})",
                format.name(),
                mesh.tets[t]
            );
        }
        found += 1;
    }
    if format == Format::Gmsh41Binary {
        assert!(!reason.contains("(line"), "{reason}");
    } else {
        assert!(found > 0, "{}: no tet line in: {reason}", format.name());
    }
}

#[test]
fn the_generated_meshes_read_back_identically_in_every_format() {
    let mesh = box_of([3, 2, 1]);
    in_every_format("box", &mesh, |format, _, _, result| {
        let (read, report) = result.unwrap_or_else(|e| panic!("{}: {e}", format.name()));
        assert_eq!(read, mesh, "{}", format.name());
        assert_eq!(report.flipped_tets, 0);
        assert_eq!(report.unreferenced_vertices, 0);
        assert_eq!(report.components, 1);
    });
}

#[test]
fn inverted_tets_are_flipped_and_counted() {
    let good = box_of([2, 1, 1]);
    let mut mesh = good.clone();
    for t in [0, 3, 5, 11] {
        mesh.tets[t].swap(2, 3);
    }
    in_every_format("inverted", &mesh, |format, _, _, result| {
        let (read, report) = result.unwrap_or_else(|e| panic!("{}: {e}", format.name()));
        assert_eq!(report.flipped_tets, 4, "{}", format.name());
        assert_eq!(read.tets, good.tets, "{}", format.name());
    });
}

#[test]
fn unreferenced_vertices_are_kept_and_counted() {
    let mut mesh = box_of([2, 1, 1]);
    let n = mesh.num_vertices();
    mesh.vertices
        .extend([Vec3::new(5.0, 5.0, 5.0), Vec3::new(-1.0, 0.0, 2.0)]);
    in_every_format("unreferenced", &mesh, |format, _, _, result| {
        let (read, report) = result.unwrap_or_else(|e| panic!("{}: {e}", format.name()));
        assert_eq!(read.num_vertices(), n + 2, "{}", format.name());
        assert_eq!(report.unreferenced_vertices, 2, "{}", format.name());
        assert_eq!(report.components, 1, "{}", format.name());
    });
}

#[test]
fn disconnected_pieces_are_counted() {
    let mut mesh = box_of([2, 1, 1]);
    let other = box_of([1, 1, 2]);
    let offset = mesh.num_vertices();
    mesh.vertices
        .extend(other.vertices.iter().map(|v| v + Vec3::new(1.0, 0.0, 0.0)));
    mesh.tets
        .extend(other.tets.iter().map(|t| t.map(|i| i + offset)));
    let (labels, pieces) = mesh.vertex_components();
    assert_eq!(pieces, 2);
    assert!(labels[..offset].iter().all(|&c| c == 0));
    assert!(labels[offset..].iter().all(|&c| c == 1));
    in_every_format("disconnected", &mesh, |format, _, _, result| {
        let (_, report) = result.unwrap_or_else(|e| panic!("{}: {e}", format.name()));
        assert_eq!(report.components, 2, "{}", format.name());
    });
}

#[test]
fn degenerate_tets_are_refused() {
    let mut mesh = box_of([2, 1, 1]);
    let n = mesh.num_vertices();
    // Four coplanar points: a flat tet touching the box at one corner.
    mesh.vertices.extend([
        Vec3::new(0.3, 0.1, 0.3),
        Vec3::new(0.4, 0.1, 0.3),
        Vec3::new(0.3, 0.1, 0.4),
    ]);
    // Vertex n − 1 is the box corner (0.3, 0.1, 0.1), on the same plane y = 0.1.
    mesh.tets.push([n - 1, n, n + 1, n + 2]);
    let flat = mesh.num_tets() - 1;
    in_every_format("degenerate", &mesh, |format, path, bytes, result| {
        let reason = invalid_reason(format, path, result);
        assert!(
            reason.contains(&format!("tetrahedron {} of", flat + 1))
                && reason.contains("degenerate")
                && reason.contains("mesh it again with a quality bound"),
            "{}: {reason}",
            format.name()
        );
        assert_tet_lines(format, bytes, &mesh, &reason);
    });
}

#[test]
fn duplicate_tets_are_refused() {
    let mut mesh = box_of([2, 1, 1]);
    let [a, b, c, d] = mesh.tets[4];
    mesh.tets.push([b, a, c, d]);
    let copy = mesh.num_tets() - 1;
    in_every_format("duplicate", &mesh, |format, path, bytes, result| {
        let reason = invalid_reason(format, path, result);
        assert!(
            reason.contains("tetrahedron 5 of")
                && reason.contains(&format!("and tetrahedron {} of", copy + 1))
                && reason.contains("duplicate"),
            "{}: {reason}",
            format.name()
        );
        assert_tet_lines(format, bytes, &mesh, &reason);
    });
}

#[test]
fn a_tet_using_a_vertex_twice_is_refused() {
    let mut mesh = box_of([2, 1, 1]);
    mesh.tets[7][2] = mesh.tets[7][0];
    in_every_format("repeated-vertex", &mesh, |format, path, bytes, result| {
        let reason = invalid_reason(format, path, result);
        assert!(
            reason.contains("tetrahedron 8 of") && reason.contains("twice"),
            "{}: {reason}",
            format.name()
        );
        assert_tet_lines(format, bytes, &mesh, &reason);
    });
}

#[test]
fn non_finite_coordinates_are_refused_at_their_line() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut mesh = box_of([2, 1, 1]);
        mesh.vertices[5].y = bad;
        let token = format!("{bad:?}");
        in_every_format("non-finite", &mesh, |format, path, bytes, result| {
            let (line, reason) = parse_error(format, path, result);
            assert!(reason.contains("finite"), "{}: {reason}", format.name());
            assert_line_holds(format, bytes, line, &token, &reason);
        });
    }
}

#[test]
fn coordinates_whose_volumes_overflow_are_refused() {
    let mut mesh = box_of([2, 1, 1]);
    for v in &mut mesh.vertices {
        *v *= 1e110;
    }
    in_every_format("overflow", &mesh, |format, path, bytes, result| {
        let reason = invalid_reason(format, path, result);
        assert!(reason.contains("too large"), "{}: {reason}", format.name());
        assert_tet_lines(format, bytes, &mesh, &reason);
    });
}

#[test]
fn out_of_range_vertex_indices_are_refused_at_their_line() {
    let mut mesh = box_of([2, 1, 1]);
    mesh.tets[2][3] = 99;
    in_every_format("out-of-range", &mesh, |format, path, bytes, result| {
        let (line, reason) = parse_error(format, path, result);
        // The token as each format writes vertex 99: 1-based, a sparse Gmsh tag, or 0-based.
        let token = match format {
            Format::Medit => "100",
            Format::Gmsh22 | Format::Gmsh41Ascii | Format::Gmsh41Binary => "307",
            Format::Vtk42 | Format::Vtk51 => "99",
        };
        assert!(reason.contains(token), "{}: {reason}", format.name());
        if format == Format::Gmsh41Binary {
            assert_eq!(line, 0, "{reason}");
        } else {
            assert_line_holds(format, bytes, line, token, &reason);
        }
    });
}

#[test]
fn a_file_without_tets_is_refused() {
    let mut mesh = box_of([1, 1, 1]);
    mesh.tets.clear();
    for format in [Format::Medit, Format::Gmsh22, Format::Vtk42, Format::Vtk51] {
        setup();
        let (path, result) = read_as("no-tets", format, &format.write(&mesh));
        match result {
            Err(MeshError::Parse { path: p, .. }) | Err(MeshError::Invalid { path: p, .. }) => {
                assert_eq!(p, path)
            }
            other => panic!("{}: {other:?}", format.name()),
        }
    }
}

/// Counts the files declare, replaced by ones that would need gigabytes: each is refused at
/// its line before anything is allocated for it (the capped allocator would abort otherwise).
#[test]
fn huge_counts_are_refused_before_allocating() {
    setup();
    let mesh = box_of([2, 1, 1]);
    let (n, m) = (mesh.num_vertices(), mesh.num_tets());
    let tris = mesh.surface_triangles().len();
    let huge = [
        "1000000000000".to_string(),
        (MAX_ENTITIES + 1).to_string(),
        u64::MAX.to_string(),
        "18446744073709551616".to_string(),
    ];
    // (format, text before the count, the count as written)
    let counts: Vec<(Format, String, String)> = vec![
        (Format::Medit, "Vertices\n".into(), n.to_string()),
        (Format::Medit, "Tetrahedra\n".into(), m.to_string()),
        (Format::Medit, "Triangles\n".into(), tris.to_string()),
        (Format::Gmsh22, "$Nodes\n".into(), n.to_string()),
        (Format::Gmsh22, "$Elements\n".into(), (m + tris).to_string()),
        (Format::Gmsh41Ascii, "$Nodes\n2 ".into(), n.to_string()),
        (Format::Gmsh41Ascii, "3 1 0 ".into(), (n / 2).to_string()),
        (Format::Gmsh41Ascii, "$Elements\n1 ".into(), m.to_string()),
        (Format::Gmsh41Ascii, "3 1 4 ".into(), m.to_string()),
        (Format::Vtk42, "POINTS ".into(), n.to_string()),
        (Format::Vtk42, "CELLS ".into(), m.to_string()),
        (Format::Vtk42, "CELL_TYPES ".into(), m.to_string()),
        (Format::Vtk51, "CELLS ".into(), (m + 1).to_string()),
    ];
    let mut tried = 0;
    for (format, before, count) in &counts {
        let text = String::from_utf8(format.write(&mesh)).unwrap();
        let original = format!("{before}{count}");
        assert!(text.contains(&original), "{}: {original}", format.name());
        for value in &huge {
            let bad = text.replacen(&original, &format!("{before}{value}"), 1);
            let start = std::time::Instant::now();
            let (path, result) = read_as("huge", *format, bad.as_bytes());
            let (line, reason) = parse_error(*format, &path, result);
            assert!(
                reason.contains("limit")
                    || reason.contains("more than")
                    || reason.contains("expected"),
                "{} {before:?}{value}: {reason}",
                format.name()
            );
            assert_line_holds(*format, bad.as_bytes(), line, value, &reason);
            assert!(start.elapsed().as_secs_f64() < 1.0, "{reason}");
            tried += 1;
        }
    }
    // The binary format: every count word of the node and element headers.
    let bytes = Format::Gmsh41Binary.write(&mesh);
    for at in word_offsets_after(&bytes, b"$Nodes\n", 2)
        .into_iter()
        .chain(word_offsets_after(&bytes, b"$Elements\n", 2))
    {
        for value in [u64::MAX, MAX_ENTITIES as u64 + 1, 1 << 40] {
            let mut bad = bytes.clone();
            bad[at..at + 8].copy_from_slice(&value.to_le_bytes());
            let (path, result) = read_as("huge", Format::Gmsh41Binary, &bad);
            let (line, reason) = parse_error(Format::Gmsh41Binary, &path, result);
            assert_eq!(line, 0, "{reason}");
            assert!(reason.contains("limit"), "{reason}");
            tried += 1;
        }
    }
    println!("huge counts: {tried} inputs, each refused with its line before allocating");
}

/// Byte offsets of the first `count` 8-byte words after `tag`.
fn word_offsets_after(bytes: &[u8], tag: &[u8], count: usize) -> Vec<usize> {
    let at = bytes
        .windows(tag.len())
        .position(|w| w == tag)
        .expect("tag present")
        + tag.len();
    (0..count).map(|k| at + 8 * k).collect()
}

#[test]
fn missing_files_and_unknown_extensions_are_typed_errors() {
    let missing = dir().join("does-not-exist.mesh");
    match read_mesh(&missing) {
        Err(MeshError::Io { path, .. }) => assert_eq!(path, missing),
        other => panic!("{other:?}"),
    }
    let odd = dir().join("mesh.obj");
    std::fs::write(&odd, "v 0 0 0\n").unwrap();
    match read_mesh(&odd) {
        Err(MeshError::UnsupportedFormat { path, .. }) => assert_eq!(path, odd),
        other => panic!("{other:?}"),
    }
}
