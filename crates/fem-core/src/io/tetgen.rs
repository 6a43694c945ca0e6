//! TetGen `.node` / `.ele` reader: the pair of files `tetgen` writes by default (`NAME.1.node`
//! and `NAME.1.ele`), read together from either name.
//!
//! Supported, as the TetGen manual describes them:
//! - `#` starts a comment that runs to the end of the line; blank lines are skipped;
//! - `.node`: a header `<points> <dimension = 3> <attributes> <boundary markers 0|1>`, then one
//!   line per point, `<number> <x> <y> <z>` followed by its attributes and marker (ignored);
//! - `.ele`: a header `<tets> <nodes per tet 4|10> <region attribute 0|1>`, then one line per
//!   tet, `<number> <n₁> … <nₖ>` and its region (ignored). Of a 10-node (`-o2`) tet the four
//!   corners, which come first, are kept;
//! - points numbered from 0 or from 1 (the first point's number says which), consecutively; the
//!   `.ele` file refers to them by those numbers.
//!
//! Indices are converted to 0-based. Reading stops at the first problem with a
//! [`MeshError::Parse`] naming the file and the line; the mesh is not validated here (see
//! [`crate::io::read_mesh`]).

use std::path::{Path, PathBuf};

use super::MAX_ENTITIES;
use super::medit::{Parser, Tokens};
use crate::{MeshError, TetMesh, Vec3};

/// The `.node` and `.ele` files of the TetGen mesh that `path` (either of them) names, with the
/// letter case of its extension (`M.NODE` pairs with `M.ELE`).
pub fn pair_paths(path: &Path) -> (PathBuf, PathBuf) {
    let upper = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.chars().all(|c| c.is_ascii_uppercase()));
    let (node, ele) = if upper {
        ("NODE", "ELE")
    } else {
        ("node", "ele")
    };
    (path.with_extension(node), path.with_extension(ele))
}

/// Parses a TetGen mesh from the text of its `.node` file (`node_path` names it in errors) and
/// of its `.ele` file (`ele_path`). Of a 10-node mesh the mid-edge points, which no corner
/// uses, are left out.
pub fn parse(
    node: &str,
    node_path: &Path,
    ele: &str,
    ele_path: &Path,
) -> Result<TetMesh, MeshError> {
    let (vertices, base) = read_nodes(node, node_path)?;
    let (tets, per_tet) = read_tets(ele, ele_path, base, vertices.len())?;
    let mut mesh = TetMesh { vertices, tets };
    if per_tet == 10 {
        drop_unused_vertices(&mut mesh);
    }
    Ok(mesh)
}

/// 1-based line of tet `t` (0-based) in the `.ele` text that [`parse`] read (the line of its
/// number), for messages about a tet that validation refuses.
pub(crate) fn tet_line(ele: &str, t: usize) -> Option<usize> {
    let mut tokens = Tokens::new(ele);
    let _count = tokens.next()?;
    let per_tet: usize = tokens.next()?.text.parse().ok()?;
    let region: usize = tokens.next()?.text.parse().ok()?;
    let skip = t.checked_mul(1 + per_tet + region)?;
    for _ in 0..skip {
        tokens.next()?;
    }
    tokens.next().map(|tok| tok.line)
}

/// A header's count, checked against [`MAX_ENTITIES`].
fn count(file: &mut Parser<'_>, what: &str) -> Result<usize, MeshError> {
    file.read_at_most(&|| format!("the number of {what}"), MAX_ENTITIES, &|n| {
        format!("{n} {what} is more than this reader accepts ({MAX_ENTITIES})")
    })
}

/// A header flag that is 0 or 1.
fn flag(file: &mut Parser<'_>, what: &str) -> Result<usize, MeshError> {
    file.read_at_most(&|| format!("the number of {what} (0 or 1)"), 1, &|v| {
        format!("the number of {what} must be 0 or 1, found {v}")
    })
}

/// Skips `n` tokens (attributes, markers, extra nodes), each named by `what` if missing.
fn skip(file: &mut Parser<'_>, n: usize, what: &dyn Fn() -> String) -> Result<(), MeshError> {
    for _ in 0..n {
        file.expect(what)?;
    }
    Ok(())
}

/// The points of a `.node` file, and the number of its first point (0 or 1).
fn read_nodes(text: &str, path: &Path) -> Result<(Vec<Vec3>, usize), MeshError> {
    let mut file = Parser::new(text, path);
    let n = count(&mut file, "points")?;
    let (dimension, line) = file.read_usize(&|| "the dimension".into())?;
    if dimension != 3 {
        return Err(file.error(
            line,
            format!("the dimension is {dimension}; a tetrahedral mesh needs 3"),
        ));
    }
    let attributes =
        file.read_at_most(&|| "the number of attributes".into(), MAX_ENTITIES, &|n| {
            format!("{n} attributes per point is too many")
        })?;
    let markers = flag(&mut file, "boundary markers")?;
    // A header may lie about its count: never reserve more than the text could hold.
    let mut vertices = Vec::with_capacity(n.min(text.len() / 8));
    let mut base = 0;
    for i in 0..n {
        let what = || format!("point {} of {n}", base + i);
        let (number, line) = file.read_usize(&what)?;
        if i == 0 && number > 1 {
            return Err(file.error(
                line,
                format!("the first point is numbered {number}; TetGen numbers from 0 or 1"),
            ));
        }
        if i == 0 {
            base = number;
        } else if number != base + i {
            return Err(file.error(
                line,
                format!(
                    "points must be numbered consecutively: expected {}, found {number}",
                    base + i
                ),
            ));
        }
        let mut xyz = [0.0; 3];
        for (c, value) in xyz.iter_mut().enumerate() {
            let axis = ["x", "y", "z"][c];
            *value =
                file.read_coordinate(&|| format!("the {axis} coordinate of point {number}"))?;
        }
        skip(&mut file, attributes + markers, &|| {
            format!("the attributes and marker of point {number}")
        })?;
        vertices.push(Vec3::new(xyz[0], xyz[1], xyz[2]));
    }
    Ok((vertices, base))
}

/// The tets of an `.ele` file, as 0-based indices into the `points` points numbered from
/// `base`, and the nodes per tet (4 or 10).
fn read_tets(
    text: &str,
    path: &Path,
    base: usize,
    points: usize,
) -> Result<(Vec<[usize; 4]>, usize), MeshError> {
    let mut file = Parser::new(text, path);
    let n = count(&mut file, "tets")?;
    let (per_tet, line) = file.read_usize(&|| "the number of nodes per tet".into())?;
    if per_tet != 4 && per_tet != 10 {
        return Err(file.error(
            line,
            format!("a tet has 4 nodes (10 with `-o2`), the header says {per_tet}"),
        ));
    }
    let region = flag(&mut file, "region attributes")?;
    let mut tets = Vec::with_capacity(n.min(text.len() / 10));
    for i in 0..n {
        file.read_usize(&|| format!("the number of tet {} of {n}", i + 1))?;
        let mut tet = [0; 4];
        for (c, corner) in tet.iter_mut().enumerate() {
            let (node, line) = file.read_usize(&|| format!("node {} of tet {}", c + 1, i + 1))?;
            *corner = node
                .checked_sub(base)
                .filter(|&v| v < points)
                .ok_or_else(|| {
                    let range = match points {
                        0 => "the .node file has no points".to_string(),
                        _ => format!("numbered {base} to {}", base + points - 1),
                    };
                    file.error(
                        line,
                        format!("node {node} is not a point of the .node file ({range})"),
                    )
                })?;
        }
        skip(&mut file, per_tet - 4 + region, &|| {
            format!("the other nodes and region of tet {}", i + 1)
        })?;
        tets.push(tet);
    }
    Ok((tets, per_tet))
}

/// Leaves out the vertices no tet uses, renumbering the rest in order.
fn drop_unused_vertices(mesh: &mut TetMesh) {
    const UNUSED: usize = usize::MAX;
    let mut new_index = vec![UNUSED; mesh.vertices.len()];
    for &v in mesh.tets.iter().flatten() {
        new_index[v] = 0;
    }
    for (kept, slot) in new_index.iter_mut().filter(|s| **s != UNUSED).enumerate() {
        *slot = kept;
    }
    let mut i = 0;
    mesh.vertices.retain(|_| {
        i += 1;
        new_index[i - 1] != UNUSED
    });
    for v in mesh.tets.iter_mut().flatten() {
        *v = new_index[*v];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NODE: &str = "# a unit tet and its mirror\n5 3 0 1\n1 0 0 0 1\n2 1 0 0 1\n\
                        3 0 1 0 1\n4 0 0 1 1\n5 0 0 -1 1\n";
    const ELE: &str = "2 4 1\n  1  1 2 3 4  7\n  2  1 3 2 5  7 # region 7\n";

    fn read(node: &str, ele: &str) -> Result<TetMesh, MeshError> {
        parse(node, Path::new("m.node"), ele, Path::new("m.ele"))
    }

    #[test]
    fn reads_points_from_one_and_tets_by_their_numbers() {
        let mesh = read(NODE, ELE).unwrap();
        assert_eq!(mesh.vertices.len(), 5);
        assert_eq!(mesh.vertices[4], Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3], [0, 2, 1, 4]]);
        assert_eq!(tet_line(ELE, 1), Some(3));
    }

    #[test]
    fn reads_points_from_zero_and_the_corners_of_ten_node_tets() {
        let node = "4 3 1 0\n0 0 0 0 9.5\n1 1 0 0 9.5\n2 0 1 0 9.5\n3 0 0 1 9.5\n";
        let ele = "1 10 0\n0 0 1 2 3 0 0 0 0 0 0\n";
        let mesh = read(node, ele).unwrap();
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3]]);
        // The mid-edge points of a 10-node mesh are left out, the corners renumbered.
        let node = "6 3 0 0\n0 0 0 0\n1 0.5 0 0\n2 1 0 0\n3 0 1 0\n4 9 9 9\n5 0 0 1\n";
        let ele = "1 10 0\n0 0 2 3 5 1 4 4 4 4 4\n";
        let mesh = read(node, ele).unwrap();
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(mesh.vertices[1], Vec3::new(1.0, 0.0, 0.0));
    }

    #[test]
    fn errors_name_the_file_the_line_and_what_is_wrong() {
        let cases = [
            (
                NODE.replace("3 0 1 0 1", "4 0 1 0 1"),
                ELE.to_string(),
                "m.node:5:",
                "consecutively",
            ),
            (
                NODE.replace("5 3 0 1", "5 2 0 1"),
                ELE.to_string(),
                "m.node:2:",
                "needs 3",
            ),
            (
                NODE.replace("2 1 0 0 1", "2 1 zero 0 1"),
                ELE.to_string(),
                "m.node:4:",
                "y coordinate",
            ),
            (
                NODE.replace("2 1 0 0 1", "2 1 inf 0 1"),
                ELE.to_string(),
                "m.node:4:",
                "is not finite",
            ),
            (
                NODE.to_string(),
                ELE.replace("1 3 2 5", "1 3 2 6"),
                "m.ele:3:",
                "node 6 is not a point",
            ),
            (
                NODE.to_string(),
                ELE.replace("2 4 1", "3 4 1"),
                "m.ele:3:",
                "tet 3 of 3",
            ),
            (
                NODE.to_string(),
                ELE.replace("2 4 1", "2 8 1"),
                "m.ele:1:",
                "4 nodes",
            ),
            (
                NODE.to_string(),
                "# nothing\n".to_string(),
                "m.ele:1:",
                "the number of tets",
            ),
        ];
        for (node, ele, at, what) in cases {
            let e = read(&node, &ele).unwrap_err().to_string();
            assert!(e.starts_with(at) && e.contains(what), "{e}");
        }
    }

    #[test]
    fn a_huge_declared_count_is_refused_before_allocating() {
        let e = read("99999999999 3 0 0\n", ELE).unwrap_err().to_string();
        assert!(e.contains("more than this reader accepts"), "{e}");
        let e = read("1000000 3 0 0\n0 0 0 0\n", ELE)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("end of file") && e.contains("point 1 of 1000000"),
            "{e}"
        );
    }

    #[test]
    fn the_pair_keeps_the_letter_case_of_the_name_given() {
        let pair = |p: &str| pair_paths(Path::new(p));
        assert_eq!(pair("a/m.1.ele"), ("a/m.1.node".into(), "a/m.1.ele".into()));
        assert_eq!(pair("M.NODE"), ("M.NODE".into(), "M.ELE".into()));
    }
}
