//! VTK XML writers for ParaView: one `.vtu` UnstructuredGrid per frame and a `.pvd` collection
//! that strings the frames into a time series.
//!
//! A frame stores the **rest** positions as `Points`, the tets as cells of type 10
//! (`VTK_TETRA`, `connectivity`/`offsets`/`types`), and per-vertex arrays as `PointData`:
//! 3-component `Float64` vectors (e.g. `displacement`, made the active vectors so ParaView's
//! *Warp By Vector* applies it directly) and 1-component `Float64` scalars. Data are written in
//! the `ascii` format with the shortest decimal form that reads back to the same `f64`, so
//! values round-trip exactly. Non-finite values are refused ([`MeshError::Invalid`] naming the
//! array), never written. Every file is written atomically ([`super::write_atomic`]).

use std::fmt::Write as _;
use std::path::Path;

use crate::{MeshError, TetMesh, Vec3};

/// VTK cell type of the linear tetrahedron.
const VTK_TETRA: u8 = 10;

/// Writes `mesh` with vector and scalar point data as a VTK XML UnstructuredGrid (`.vtu`).
///
/// Each array needs one value per vertex; the `displacement` vector array (or else the first
/// one) is marked as the active vectors.
pub fn write_vtu(
    path: &Path,
    mesh: &TetMesh,
    point_data: &[(&str, &[Vec3])],
    scalar_point_data: &[(&str, &[f64])],
) -> Result<(), MeshError> {
    let xml = vtu_xml(mesh, point_data, scalar_point_data, path)?;
    super::write_atomic(path, xml.as_bytes()).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes a ParaView `.pvd` collection listing `(time, file)` frames.
///
/// File names should be relative to the `.pvd`'s folder (so the series can be moved); an
/// absolute path inside that folder is made relative, any other is written as given.
pub fn write_pvd(path: &Path, entries: &[(f64, String)]) -> Result<(), MeshError> {
    let invalid = |reason: String| MeshError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut xml = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n",
    );
    for (k, (time, file)) in entries.iter().enumerate() {
        if !time.is_finite() {
            return Err(invalid(format!(
                "pvd entry {k} ({file}) has a non-finite timestep {time}"
            )));
        }
        if file.is_empty() {
            return Err(invalid(format!("pvd entry {k} has an empty file name")));
        }
        let relative = Path::new(file)
            .strip_prefix(dir)
            .ok()
            .filter(|_| Path::new(file).is_absolute())
            .map_or_else(|| file.clone(), |p| p.to_string_lossy().into_owned());
        xml.push_str("    <DataSet timestep=\"");
        // To 12 significant digits: a time k·h is 0.35, not 0.35000000000000003.
        push_f64(&mut xml, format!("{time:.11e}").parse().unwrap_or(*time));
        // Writing to a String cannot fail.
        let _ = writeln!(
            xml,
            "\" group=\"\" part=\"0\" file=\"{}\"/>",
            escape(&relative)
        );
    }
    xml.push_str("  </Collection>\n</VTKFile>\n");
    super::write_atomic(path, xml.as_bytes()).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Appends `x` in the shortest form that parses back to the same `f64` (exponent form only for
/// very small or large magnitudes, to keep files short).
fn push_f64(out: &mut String, x: f64) {
    let a = x.abs();
    // Writing to a String cannot fail.
    let _ = if a == 0.0 || (1e-4..1e16).contains(&a) {
        write!(out, "{x}")
    } else {
        write!(out, "{x:e}")
    };
}

/// Escapes the XML special characters of an attribute value.
fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            _ => out.push(c),
        }
    }
    out
}

fn vtu_xml(
    mesh: &TetMesh,
    point_data: &[(&str, &[Vec3])],
    scalar_point_data: &[(&str, &[f64])],
    path: &Path,
) -> Result<String, MeshError> {
    let invalid = |reason: String| MeshError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    let n = mesh.vertices.len();
    if let Some((i, v)) = mesh
        .vertices
        .iter()
        .enumerate()
        .find(|(_, v)| !v.iter().all(|c| c.is_finite()))
    {
        return Err(invalid(format!(
            "Points: vertex {i} has a non-finite rest position ({}, {}, {})",
            v.x, v.y, v.z
        )));
    }
    if let Some((t, tet)) = mesh
        .tets
        .iter()
        .enumerate()
        .find(|(_, tet)| tet.iter().any(|&i| i >= n))
    {
        return Err(invalid(format!(
            "tet {t} {tet:?} references a vertex beyond the {n} vertices"
        )));
    }
    let names: Vec<&str> = point_data
        .iter()
        .map(|(name, _)| *name)
        .chain(scalar_point_data.iter().map(|(name, _)| *name))
        .collect();
    for (k, name) in names.iter().enumerate() {
        if name.trim().is_empty() {
            return Err(invalid("a point-data array has an empty name".into()));
        }
        if names[..k].contains(name) {
            return Err(invalid(format!("two point-data arrays are named '{name}'")));
        }
    }
    for &(name, values) in point_data {
        if values.len() != n {
            return Err(invalid(format!(
                "point data '{name}' has {} vectors, expected one per vertex ({n})",
                values.len()
            )));
        }
        if let Some(i) = values.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(invalid(format!(
                "point data '{name}' has a non-finite value at vertex {i}: ({}, {}, {})",
                values[i].x, values[i].y, values[i].z
            )));
        }
    }
    for &(name, values) in scalar_point_data {
        if values.len() != n {
            return Err(invalid(format!(
                "point data '{name}' has {} values, expected one per vertex ({n})",
                values.len()
            )));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(invalid(format!(
                "point data '{name}' has a non-finite value at vertex {i}: {}",
                values[i]
            )));
        }
    }

    // Roughly 25 bytes per number.
    let numbers =
        n * 3 * (1 + point_data.len()) + n * scalar_point_data.len() + mesh.tets.len() * 6;
    let mut xml = String::with_capacity(512 + 25 * numbers);
    // Writing to a String cannot fail: the results of write! below are ignored.
    xml.push_str("<?xml version=\"1.0\"?>\n");
    xml.push_str("<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n");
    xml.push_str("  <UnstructuredGrid>\n");
    let _ = writeln!(
        xml,
        "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{}\">",
        mesh.tets.len()
    );

    xml.push_str("      <PointData");
    let active_vectors = point_data
        .iter()
        .find(|(name, _)| *name == "displacement")
        .or(point_data.first());
    if let Some((name, _)) = active_vectors {
        let _ = write!(xml, " Vectors=\"{}\"", escape(name));
    }
    if let Some((name, _)) = scalar_point_data.first() {
        let _ = write!(xml, " Scalars=\"{}\"", escape(name));
    }
    xml.push_str(">\n");
    for &(name, values) in point_data {
        push_vectors(&mut xml, Some(name), values);
    }
    for &(name, values) in scalar_point_data {
        let _ = writeln!(
            xml,
            "        <DataArray type=\"Float64\" Name=\"{}\" format=\"ascii\">",
            escape(name)
        );
        for &v in values {
            xml.push_str("          ");
            push_f64(&mut xml, v);
            xml.push('\n');
        }
        xml.push_str("        </DataArray>\n");
    }
    xml.push_str("      </PointData>\n");

    xml.push_str("      <Points>\n");
    push_vectors(&mut xml, None, &mesh.vertices);
    xml.push_str("      </Points>\n");

    xml.push_str("      <Cells>\n");
    xml.push_str("        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    for [a, b, c, d] in &mesh.tets {
        let _ = writeln!(xml, "          {a} {b} {c} {d}");
    }
    xml.push_str("        </DataArray>\n");
    xml.push_str("        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for t in 1..=mesh.tets.len() {
        let _ = writeln!(xml, "          {}", 4 * t);
    }
    xml.push_str("        </DataArray>\n");
    xml.push_str("        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for _ in &mesh.tets {
        let _ = writeln!(xml, "          {VTK_TETRA}");
    }
    xml.push_str("        </DataArray>\n");
    xml.push_str("      </Cells>\n");
    xml.push_str("    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
    Ok(xml)
}

/// Appends a 3-component Float64 DataArray, one vector per line.
fn push_vectors(xml: &mut String, name: Option<&str>, values: &[Vec3]) {
    xml.push_str("        <DataArray type=\"Float64\"");
    if let Some(name) = name {
        let _ = write!(xml, " Name=\"{}\"", escape(name));
    }
    xml.push_str(" NumberOfComponents=\"3\" format=\"ascii\">\n");
    for v in values {
        xml.push_str("          ");
        push_f64(xml, v.x);
        xml.push(' ');
        push_f64(xml, v.y);
        xml.push(' ');
        push_f64(xml, v.z);
        xml.push('\n');
    }
    xml.push_str("        </DataArray>\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tet() -> TetMesh {
        TetMesh {
            vertices: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            tets: vec![[0, 1, 2, 3]],
        }
    }

    #[test]
    fn numbers_round_trip_exactly() {
        let values = [
            0.0,
            -0.0,
            1.0,
            0.1,
            1.0 / 3.0,
            -2.5e-300,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            1e16,
            123456.789,
            -9.999999999999999e-5,
        ];
        for x in values {
            let mut s = String::new();
            push_f64(&mut s, x);
            let back: f64 = s.parse().unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{x} was written as {s}");
            assert!(s.len() <= 24, "{s}");
        }
    }

    #[test]
    fn writes_points_cells_and_point_data() {
        let mesh = tet();
        let u = vec![Vec3::new(0.1, -0.2, 1e-12); 4];
        let s = [1.0, 2.0, 3.0, 4.0];
        let xml = vtu_xml(
            &mesh,
            &[("displacement", &u)],
            &[("von <Mises>", &s)],
            Path::new("a.vtu"),
        )
        .unwrap();
        assert!(xml.contains("<Piece NumberOfPoints=\"4\" NumberOfCells=\"1\">"));
        assert!(xml.contains("<PointData Vectors=\"displacement\" Scalars=\"von &lt;Mises&gt;\">"));
        assert!(xml.contains("Name=\"displacement\" NumberOfComponents=\"3\""));
        assert!(xml.contains("0.1 -0.2 1e-12\n"));
        assert!(xml.contains("          0 1 2 3\n"));
        assert!(xml.contains("Name=\"types\" format=\"ascii\">\n          10\n"));
        assert_eq!(
            xml.matches("<DataArray").count(),
            xml.matches("</DataArray>").count()
        );
    }

    #[test]
    fn non_finite_or_mismatched_data_is_refused_naming_the_array() {
        let mesh = tet();
        let mut u = vec![Vec3::zeros(); 4];
        u[2].y = f64::NAN;
        let err = vtu_xml(&mesh, &[("displacement", &u)], &[], Path::new("a.vtu")).unwrap_err();
        assert!(
            matches!(&err, MeshError::Invalid { reason, .. } if reason.contains("'displacement'") && reason.contains("vertex 2")),
            "{err}"
        );
        let err = vtu_xml(
            &mesh,
            &[],
            &[("energy", &[1.0, f64::INFINITY, 0.0, 0.0])],
            Path::new("a.vtu"),
        )
        .unwrap_err();
        assert!(err.to_string().contains("'energy'"), "{err}");
        let err = vtu_xml(
            &mesh,
            &[("v", &[Vec3::zeros(); 3])],
            &[],
            Path::new("a.vtu"),
        )
        .unwrap_err();
        assert!(err.to_string().contains("has 3 vectors"), "{err}");
        let zeros = [Vec3::zeros(); 4];
        let err = vtu_xml(
            &mesh,
            &[("v", &zeros)],
            &[("v", &[0.0; 4])],
            Path::new("a.vtu"),
        )
        .unwrap_err();
        assert!(
            err.to_string()
                .contains("two point-data arrays are named 'v'"),
            "{err}"
        );
        let mut bad = tet();
        bad.tets[0][3] = 4;
        assert!(vtu_xml(&bad, &[], &[], Path::new("a.vtu")).is_err());
        bad = tet();
        bad.vertices[0].x = f64::NEG_INFINITY;
        assert!(
            vtu_xml(&bad, &[], &[], Path::new("a.vtu"))
                .unwrap_err()
                .to_string()
                .contains("Points")
        );
    }

    #[test]
    fn files_are_written_and_pvd_paths_are_relative() {
        let dir = crate::io::test_dir("vtu-files");
        let frame = dir.join("frames").join("frame_0.vtu");
        let mesh = tet();
        write_vtu(&frame, &mesh, &[("displacement", &mesh.vertices)], &[]).unwrap();
        assert!(
            std::fs::read_to_string(&frame)
                .unwrap()
                .ends_with("</VTKFile>\n")
        );
        let pvd = dir.join("series.pvd");
        let absolute = dir
            .join("frames/frame_1.vtu")
            .to_string_lossy()
            .into_owned();
        write_pvd(
            &pvd,
            &[
                (0.0, "frames/frame_0.vtu".into()),
                (0.01, absolute),
                (35.0 * 0.01, "frames/frame_35.vtu".into()),
            ],
        )
        .unwrap();
        let text = std::fs::read_to_string(&pvd).unwrap();
        assert!(text.contains(
            "<DataSet timestep=\"0\" group=\"\" part=\"0\" file=\"frames/frame_0.vtu\"/>"
        ));
        assert!(
            text.contains("timestep=\"0.01\" group=\"\" part=\"0\" file=\"frames/frame_1.vtu\"")
        );
        // 35 × 0.01 is 0.35000000000000003 in f64; the time is written to 12 digits.
        assert!(text.contains("timestep=\"0.35\" group"), "{text}");
        let err = write_pvd(&pvd, &[(f64::NAN, "a.vtu".into())]).unwrap_err();
        assert!(matches!(err, MeshError::Invalid { .. }));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
