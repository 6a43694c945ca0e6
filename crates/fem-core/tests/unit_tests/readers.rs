//! Mesh readers against the shared reference files (`shared/meshes`, `shared/validation/readers`,
//! `shared/validation/beams`), and the VTU/PVD writers against a minimal XML parse.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use fem_core::io::{read_mesh, vtu};
use fem_core::mesh::ValidationReport;
use fem_core::{TetMesh, Vec3};
use serde_json::Value;

/// Reads `path` through `read_mesh` (so validation applies), failing the test with the error.
fn read(path: &Path) -> (TetMesh, ValidationReport) {
    read_mesh(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn load_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("missing number `{key}` in {v}"))
}

fn vec3(v: &Value, key: &str) -> Vec3 {
    let a = v[key]
        .as_array()
        .unwrap_or_else(|| panic!("missing array `{key}`"));
    Vec3::new(
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    )
}

/// The counts a MEDIT file declares after `Vertices` and `Tetrahedra`, read independently of the
/// reader (tokens, `#` comments removed, keywords in any case).
fn declared_medit_counts(path: &Path) -> (usize, usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let tokens: Vec<&str> = text
        .lines()
        .flat_map(|l| l.split('#').next().unwrap_or("").split_whitespace())
        .collect();
    let count_after = |keyword: &str| -> usize {
        let i = tokens
            .iter()
            .position(|t| t.eq_ignore_ascii_case(keyword))
            .unwrap_or_else(|| panic!("{}: no {keyword}", path.display()));
        tokens[i + 1].parse().unwrap()
    };
    (count_after("Vertices"), count_after("Tetrahedra"))
}

/// Totals compared with the reference JSONs.
#[derive(Debug)]
struct Stats {
    num_vertices: usize,
    num_tets: usize,
    volume_sum_abs: f64,
    bbox: (Vec3, Vec3),
    coordinate_sum: f64,
    index_sum: u64,
}

fn stats(mesh: &TetMesh) -> Stats {
    Stats {
        num_vertices: mesh.num_vertices(),
        num_tets: mesh.num_tets(),
        volume_sum_abs: (0..mesh.num_tets())
            .map(|t| mesh.signed_volume(t).abs())
            .sum(),
        bbox: mesh.bounding_box(),
        coordinate_sum: mesh.vertices.iter().map(|v| v.x + v.y + v.z).sum(),
        index_sum: mesh.tets.iter().flatten().map(|&i| i as u64).sum(),
    }
}

/// Checks `mesh` against a JSON `stats` block. `coordinate_tolerance` is how far each coordinate
/// may be from the reference (0 for the files written from the reference coordinates).
fn check_stats(
    name: &str,
    mesh: &TetMesh,
    report: &ValidationReport,
    expected: &Value,
    coordinate_tolerance: f64,
) {
    let s = stats(mesh);
    assert_eq!(
        s.num_vertices as f64,
        num(expected, "num_vertices"),
        "{name}: vertices"
    );
    assert_eq!(s.num_tets as f64, num(expected, "num_tets"), "{name}: tets");
    assert_eq!(
        report.unreferenced_vertices as f64,
        num(expected, "num_unreferenced_vertices"),
        "{name}: unreferenced vertices"
    );
    assert_eq!(
        report.flipped_tets as f64,
        num(expected, "num_tets_negative_orientation"),
        "{name}: flipped tets"
    );
    assert_eq!(
        s.index_sum as f64,
        num(expected, "checksum_sum_of_0based_tet_indices"),
        "{name}: index checksum"
    );

    let volume = num(expected, "volume_sum_abs");
    let volume_tol = 1e-12 * volume + 1e3 * coordinate_tolerance * volume;
    assert!(
        (s.volume_sum_abs - volume).abs() <= volume_tol,
        "{name}: sum |volume| {} vs {volume}",
        s.volume_sum_abs
    );
    let coords = num(expected, "checksum_sum_of_coordinates");
    let coords_tol =
        1e-12 * coords.abs().max(1.0) + 3.0 * s.num_vertices as f64 * coordinate_tolerance;
    assert!(
        (s.coordinate_sum - coords).abs() <= coords_tol,
        "{name}: coordinate checksum {} vs {coords}",
        s.coordinate_sum
    );
    let (lo, hi) = (vec3(expected, "bbox_min"), vec3(expected, "bbox_max"));
    assert!(
        (s.bbox.0 - lo).amax() <= coordinate_tolerance
            && (s.bbox.1 - hi).amax() <= coordinate_tolerance,
        "{name}: bbox {:?} vs {lo:?} {hi:?}",
        s.bbox
    );
}

/// `a` and `b` have the same tets and their vertices differ by at most `tolerance`.
fn assert_same_mesh(name: &str, a: &TetMesh, b: &TetMesh, tolerance: f64) {
    assert_eq!(a.num_vertices(), b.num_vertices(), "{name}: vertex count");
    assert_eq!(a.tets, b.tets, "{name}: tets differ");
    let worst = a
        .vertices
        .iter()
        .zip(&b.vertices)
        .map(|(p, q)| (p - q).amax())
        .fold(0.0, f64::max);
    assert!(
        worst <= tolerance,
        "{name}: vertices differ by {worst:e} (tolerance {tolerance:e})"
    );
}

#[test]
fn every_shared_mesh_reads_with_its_declared_counts() {
    let Some(shared) = super::shared_dir("the shared meshes' declared counts") else {
        return;
    };
    let dir = shared.join("meshes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mesh"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no .mesh files in {}", dir.display());
    for path in &files {
        let (mesh, report) = read(path);
        let (vertices, tets) = declared_medit_counts(path);
        assert_eq!(mesh.num_vertices(), vertices, "{}", path.display());
        assert_eq!(mesh.num_tets(), tets, "{}", path.display());
        assert!(report.min_relative_volume > 0.0, "{}", path.display());
    }
}

#[test]
fn readers_agree_on_the_spot_reference_in_every_format() {
    let Some(shared) = super::shared_dir("the spot reference in every format") else {
        return;
    };
    let dir = shared.join("validation/readers");
    let json = load_json(&dir.join("spot_gmsh_1091.json"));
    let expected = &json["stats"];
    let native_tolerance = num(&json, "max_abs_change_from_source_coordinates") * (1.0 + 1e-6);
    let files: Vec<String> = json["files"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    assert_eq!(files.len(), 4);

    // The four files written from the same rounded coordinates: identical meshes.
    let reference = read(&dir.join("spot_gmsh_1091.mesh")).0;
    for file in &files {
        let (mesh, report) = read(&dir.join(file));
        check_stats(file, &mesh, &report, expected, 0.0);
        assert_same_mesh(file, &mesh, &reference, 0.0);
    }

    // Gmsh's own output keeps its unrounded coordinates (within the JSON's stated change).
    let native: Vec<&str> = vec![
        "spot_gmsh_native_v22.msh",
        "spot_gmsh_native_v41.msh",
        "spot_gmsh_native_v41_binary.msh",
    ];
    let mut native_meshes = Vec::new();
    for file in &native {
        let (mesh, report) = read(&dir.join(file));
        check_stats(file, &mesh, &report, expected, native_tolerance);
        assert_same_mesh(file, &mesh, &reference, native_tolerance);
        native_meshes.push(mesh);
    }
    assert_eq!(
        native_meshes[1], native_meshes[2],
        "native 4.1 ASCII and binary differ"
    );
    assert_eq!(
        native_meshes[0], native_meshes[1],
        "native 2.2 and 4.1 differ"
    );

    // GAUSS's MEDIT file: count on the keyword line, no final newline.
    let gauss = dir.join("gauss_arma_4.mesh");
    let (mesh, _) = read(&gauss);
    assert_eq!(
        (mesh.num_vertices(), mesh.num_tets()),
        declared_medit_counts(&gauss)
    );

    // Every mesh file in the folder was checked above.
    let checked: Vec<&str> = files
        .iter()
        .map(String::as_str)
        .chain(native.iter().copied())
        .chain(["gauss_arma_4.mesh"])
        .collect();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        let is_mesh = [".mesh", ".msh", ".vtk"].iter().any(|e| name.ends_with(e));
        assert!(
            !is_mesh || checked.contains(&name.as_str()),
            "{name} is not covered by this test"
        );
    }
}

#[test]
fn beam_meshes_are_identical_in_every_format() {
    let Some(shared) = super::shared_dir("the beam meshes in every format") else {
        return;
    };
    let dir = shared.join("validation/beams");
    for name in ["beam_gmsh_h0.05", "beam_struct_20x2x2"] {
        let json = load_json(&dir.join(format!("{name}.json")));
        let expected = &json["stats"];
        let tip = num(&json, "tip_centre_node_0based") as usize;
        let reference = read(&dir.join(format!("{name}.mesh"))).0;
        let mut files: Vec<(String, f64)> = ["mesh", "vtk"]
            .iter()
            .map(|e| (format!("{name}.{e}"), 0.0))
            .chain(
                ["v41", "v22"]
                    .iter()
                    .map(|v| (format!("{name}_{v}.msh"), 0.0)),
            )
            .collect();
        if let Some(native) = json["info"]["native_file"].as_str() {
            let tolerance = num(&json, "max_abs_change_from_source_coordinates") * (1.0 + 1e-6);
            files.push((native.to_string(), tolerance));
        }
        for (file, tolerance) in &files {
            let (mesh, report) = read(&dir.join(file));
            check_stats(file, &mesh, &report, expected, *tolerance);
            assert_same_mesh(file, &mesh, &reference, *tolerance);
            let at_tip = mesh.vertices[tip] - Vec3::new(1.0, 0.05, 0.05);
            assert!(
                at_tip.amax() <= 1e-9,
                "{file}: vertex {tip} is not the tip centre"
            );
        }
    }
}

// ------------------------------------------------------------------------------------------------
// Writers
// ------------------------------------------------------------------------------------------------

/// One XML element of the minimal parser: name, attributes and the text directly inside it.
#[derive(Debug, Clone)]
struct Element {
    name: String,
    attributes: BTreeMap<String, String>,
    text: String,
    /// Names of the enclosing elements, outermost first.
    parents: Vec<String>,
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

/// Parses the subset of XML the writers produce, panicking on unbalanced or malformed tags.
fn parse_xml(xml: &str) -> Vec<Element> {
    let body = xml
        .strip_prefix("<?xml version=\"1.0\"?>")
        .expect("missing XML declaration");
    let mut elements: Vec<Element> = Vec::new();
    let mut stack: Vec<usize> = Vec::new();
    let mut rest = body;
    while let Some(open) = rest.find('<') {
        let text = &rest[..open];
        if let Some(&top) = stack.last() {
            elements[top].text.push_str(text);
        } else {
            assert!(text.trim().is_empty(), "text outside the root: {text:?}");
        }
        let close = rest[open..].find('>').expect("unterminated tag") + open;
        let tag = &rest[open + 1..close];
        rest = &rest[close + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let top = stack.pop().expect("closing tag without an open one");
            assert_eq!(elements[top].name, name.trim(), "mismatched closing tag");
            continue;
        }
        let self_closing = tag.ends_with('/');
        let tag = tag.trim_end_matches('/');
        let mut parts = tag.splitn(2, char::is_whitespace);
        let name = parts.next().unwrap().to_string();
        assert!(
            !name.is_empty() && !name.contains(['<', '"', '=']),
            "bad tag <{tag}>"
        );
        let mut attributes = BTreeMap::new();
        let mut attrs = parts.next().unwrap_or("").trim();
        while !attrs.is_empty() {
            let eq = attrs.find("=\"").expect("attribute without =\"");
            let key = attrs[..eq].trim().to_string();
            let value_end = attrs[eq + 2..].find('"').expect("unterminated attribute") + eq + 2;
            let value = &attrs[eq + 2..value_end];
            assert!(
                !value.contains(['<', '>']),
                "unescaped attribute value {value:?}"
            );
            assert!(
                attributes.insert(key.clone(), unescape(value)).is_none(),
                "duplicate attribute {key}"
            );
            attrs = attrs[value_end + 1..].trim_start();
        }
        let parents = stack.iter().map(|&i| elements[i].name.clone()).collect();
        elements.push(Element {
            name,
            attributes,
            text: String::new(),
            parents,
        });
        if !self_closing {
            stack.push(elements.len() - 1);
        }
    }
    assert!(rest.trim().is_empty(), "trailing text {rest:?}");
    assert!(stack.is_empty(), "unclosed elements");
    assert_eq!(
        elements.iter().filter(|e| e.parents.is_empty()).count(),
        1,
        "one root"
    );
    elements
}

fn numbers(e: &Element) -> Vec<f64> {
    e.text
        .split_whitespace()
        .map(|t| t.parse().unwrap_or_else(|_| panic!("not a number: {t}")))
        .collect()
}

fn data_array<'a>(elements: &'a [Element], parent: &str, name: Option<&str>) -> &'a Element {
    elements
        .iter()
        .find(|e| {
            e.name == "DataArray"
                && e.parents.last().map(String::as_str) == Some(parent)
                && e.attributes.get("Name").map(String::as_str) == name
        })
        .unwrap_or_else(|| panic!("no DataArray {name:?} in {parent}"))
}

/// Deterministic finite f64 values with every kind of bit pattern (SplitMix64).
fn awkward_values(count: usize) -> Vec<f64> {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut out = vec![
        0.0,
        -0.0,
        1.0 / 3.0,
        5e-324,
        f64::MAX,
        -f64::MIN_POSITIVE,
        0.1,
        1e16,
    ];
    while out.len() < count {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        let x = f64::from_bits(z ^ (z >> 31));
        if x.is_finite() {
            out.push(x);
        }
    }
    out.truncate(count);
    out
}

#[test]
fn vtu_and_pvd_are_well_formed_and_values_round_trip_exactly() {
    let dir = std::env::temp_dir().join(format!("fem-core-readers-vtu-{}", std::process::id()));
    let mesh = TetMesh {
        vertices: vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0),
        ],
        tets: vec![[0, 1, 2, 3], [1, 2, 3, 4]],
    };
    let values = awkward_values(3 * 5 + 5);
    let displacement: Vec<Vec3> = values[..15]
        .chunks(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect();
    let energy = &values[15..];

    let mut entries = Vec::new();
    for frame in 0..3 {
        let file = format!("frames/frame_{frame:04}.vtu");
        vtu::write_vtu(
            &dir.join(&file),
            &mesh,
            &[("displacement", &displacement)],
            &[("energy & \"density\"", energy)],
        )
        .unwrap();
        entries.push((frame as f64 * 0.1, file));
    }
    let pvd = dir.join("run.pvd");
    vtu::write_pvd(&pvd, &entries).unwrap();

    let xml = std::fs::read_to_string(dir.join(&entries[0].1)).unwrap();
    let elements = parse_xml(&xml);
    let root = &elements[0];
    assert_eq!(root.name, "VTKFile");
    assert_eq!(root.attributes["type"], "UnstructuredGrid");
    let piece = elements.iter().find(|e| e.name == "Piece").unwrap();
    assert_eq!(piece.parents, ["VTKFile", "UnstructuredGrid"]);
    assert_eq!(piece.attributes["NumberOfPoints"], "5");
    assert_eq!(piece.attributes["NumberOfCells"], "2");
    let point_data = elements.iter().find(|e| e.name == "PointData").unwrap();
    assert_eq!(point_data.attributes["Vectors"], "displacement");

    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let u = data_array(&elements, "PointData", Some("displacement"));
    assert_eq!(u.attributes["NumberOfComponents"], "3");
    assert_eq!(u.attributes["type"], "Float64");
    assert_eq!(bits(&numbers(u)), bits(&values[..15]));
    let e = data_array(&elements, "PointData", Some("energy & \"density\""));
    assert_eq!(bits(&numbers(e)), bits(energy));

    let points = data_array(&elements, "Points", None);
    let rest: Vec<f64> = mesh.vertices.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
    assert_eq!(bits(&numbers(points)), bits(&rest));
    let connectivity = numbers(data_array(&elements, "Cells", Some("connectivity")));
    assert_eq!(connectivity, [0.0, 1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 4.0]);
    assert_eq!(
        numbers(data_array(&elements, "Cells", Some("offsets"))),
        [4.0, 8.0]
    );
    assert_eq!(
        numbers(data_array(&elements, "Cells", Some("types"))),
        [10.0, 10.0]
    );

    let collection = parse_xml(&std::fs::read_to_string(&pvd).unwrap());
    assert_eq!(collection[0].attributes["type"], "Collection");
    let datasets: Vec<&Element> = collection.iter().filter(|e| e.name == "DataSet").collect();
    assert_eq!(datasets.len(), 3);
    for (d, (time, file)) in datasets.iter().zip(&entries) {
        assert_eq!(d.parents, ["VTKFile", "Collection"]);
        assert_eq!(d.attributes["timestep"].parse::<f64>().unwrap(), *time);
        assert_eq!(&d.attributes["file"], file);
        assert!(dir.join(file).is_file(), "{file} is listed but missing");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `mesh` as a TetGen pair `NAME.node` / `NAME.ele` in `dir`, numbered from `base`, with a
/// comment, one point attribute, boundary markers and region attributes, as `tetgen` writes
/// them; returns the `.ele` path.
fn write_tetgen(dir: &Path, name: &str, mesh: &TetMesh, base: usize) -> PathBuf {
    use std::fmt::Write;
    let mut node = format!("# {name}\n{} 3 1 1\n", mesh.num_vertices());
    for (i, p) in mesh.vertices.iter().enumerate() {
        writeln!(
            node,
            "{} {:e} {:e} {:e} 0.5 {}",
            i + base,
            p.x,
            p.y,
            p.z,
            i % 2
        )
        .unwrap();
    }
    let mut ele = format!("{} 4 1\n", mesh.num_tets());
    for (i, t) in mesh.tets.iter().enumerate() {
        let [a, b, c, d] = t.map(|v| v + base);
        writeln!(ele, "  {} {a} {b} {c} {d} -1", i + base).unwrap();
    }
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join(format!("{name}.node")), node).unwrap();
    let ele_path = dir.join(format!("{name}.ele"));
    std::fs::write(&ele_path, ele).unwrap();
    ele_path
}

#[test]
fn tetgen_pairs_read_from_either_file_as_the_mesh_they_hold() {
    use fem_core::mesh::generate::{BoxSpec, box_mesh};
    let dir = std::env::temp_dir().join(format!("fem-core-tetgen-{}", std::process::id()));
    let spec = BoxSpec {
        size: [0.3, 0.1, 0.2],
        cells: [3, 2, 2],
        ..BoxSpec::default()
    };
    let mut meshes = vec![("box".to_string(), box_mesh(&spec).unwrap())];
    // The real meshes too, when shared/ is there.
    if let Some(shared) = super::shared_dir("TetGen copies of the shared meshes") {
        for name in ["X_25cm_very_low", "25cm_bar_2k_tets"] {
            let (mesh, _) = read(&shared.join(format!("meshes/{name}.mesh")));
            meshes.push((name.to_string(), mesh));
        }
    }
    for (name, mesh) in &meshes {
        for base in [0, 1] {
            let ele = write_tetgen(&dir, &format!("{name}.{base}"), mesh, base);
            for path in [ele.clone(), ele.with_extension("node")] {
                let (read_back, report) = read(&path);
                assert_eq!(report.flipped_tets, 0, "{name}");
                assert_same_mesh(name, mesh, &read_back, 0.0);
            }
        }
    }
    // A pair with a file missing names the missing file.
    let lone = write_tetgen(&dir, "lone", &meshes[0].1, 1);
    std::fs::remove_file(lone.with_extension("node")).unwrap();
    match fem_core::io::read_mesh(&lone) {
        Err(fem_core::MeshError::Io { path, .. }) => assert_eq!(path, lone.with_extension("node")),
        other => panic!("{other:?}"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_surface_mesh_is_refused_with_what_to_do() {
    let e = fem_core::io::read_mesh(Path::new("bunny.obj"))
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("bunny.obj: unsupported mesh format: a surface mesh")
            && e.contains("tetgen -pqg")
            && e.contains("[mesh] path"),
        "{e}"
    );
    let e = fem_core::io::read_mesh(Path::new("frame.meshb"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("binary MEDIT") && e.contains("out.mesh"), "{e}");
}
