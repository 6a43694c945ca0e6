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
use crate::{MeshError, TetMesh, Vec3};

/// The `.node` and `.ele` files of the TetGen mesh that `path` (either of them) names.
pub fn pair_paths(path: &Path) -> (PathBuf, PathBuf) {
    (path.with_extension("node"), path.with_extension("ele"))
}

/// Parses a TetGen mesh from the text of its `.node` file (`node_path` names it in errors) and
/// of its `.ele` file (`ele_path`).
pub fn parse(
    node: &str,
    node_path: &Path,
    ele: &str,
    ele_path: &Path,
) -> Result<TetMesh, MeshError> {
    let (vertices, base) = read_nodes(node, node_path)?;
    let tets = read_tets(ele, ele_path, base, vertices.len())?;
    Ok(TetMesh { vertices, tets })
}

/// 1-based line of tet `t` (0-based) in the `.ele` text that [`parse`] read, for messages about
/// a tet that validation refuses.
pub(crate) fn tet_line(ele: &str, t: usize) -> Option<usize> {
    // The header is the first data line, then one line per tet.
    data_lines(ele).nth(t.checked_add(1)?).map(|l| l.number)
}

/// A line with content: its 1-based number and its tokens, comments removed.
struct Line<'a> {
    number: usize,
    tokens: Vec<&'a str>,
}

fn data_lines(text: &str) -> impl Iterator<Item = Line<'_>> {
    text.lines().enumerate().filter_map(|(i, line)| {
        let content = line.find('#').map_or(line, |at| &line[..at]);
        let tokens: Vec<&str> = content.split_whitespace().collect();
        (!tokens.is_empty()).then_some(Line {
            number: i + 1,
            tokens,
        })
    })
}

/// Errors of one file, with the line the last problem was found at.
struct File<'a> {
    path: &'a Path,
    lines: usize,
}

impl File<'_> {
    fn error(&self, line: usize, reason: impl Into<String>) -> MeshError {
        MeshError::Parse {
            path: self.path.to_path_buf(),
            line: line.max(1),
            reason: reason.into(),
        }
    }

    /// Token `i` of `line` as an integer, `what` naming it in the error.
    fn integer(&self, line: &Line<'_>, i: usize, what: &str) -> Result<usize, MeshError> {
        let Some(token) = line.tokens.get(i) else {
            return Err(self.error(line.number, format!("missing {what}")));
        };
        token.parse::<usize>().map_err(|_| {
            self.error(
                line.number,
                format!("expected {what} (a non-negative integer), found '{token}'"),
            )
        })
    }

    /// The header's count, checked against [`MAX_ENTITIES`].
    fn count(&self, line: &Line<'_>, what: &str) -> Result<usize, MeshError> {
        let n = self.integer(line, 0, what)?;
        if n > MAX_ENTITIES {
            return Err(self.error(
                line.number,
                format!("{what} {n} is more than this reader accepts ({MAX_ENTITIES})"),
            ));
        }
        Ok(n)
    }

    fn truncated(&self, what: &str, read: usize, declared: usize) -> MeshError {
        self.error(
            self.lines,
            format!(
                "unexpected end of file: the header declares {declared} {what}, the file has \
                 {read} (truncated file?)"
            ),
        )
    }
}

/// The points of a `.node` file, and the number of its first point (0 or 1).
fn read_nodes(text: &str, path: &Path) -> Result<(Vec<Vec3>, usize), MeshError> {
    let file = File {
        path,
        lines: text.lines().count(),
    };
    let mut lines = data_lines(text);
    let Some(header) = lines.next() else {
        return Err(file.error(
            1,
            "empty file: expected the header `<points> 3 <attributes> <markers>`",
        ));
    };
    let n = file.count(&header, "the number of points")?;
    let dimension = file.integer(&header, 1, "the dimension")?;
    if dimension != 3 {
        return Err(file.error(
            header.number,
            format!("the dimension is {dimension}; a tetrahedral mesh needs 3"),
        ));
    }
    let attributes = file.integer(&header, 2, "the number of attributes")?;
    let markers = file.integer(&header, 3, "the number of boundary markers (0 or 1)")?;
    if markers > 1 {
        return Err(file.error(
            header.number,
            format!("the number of boundary markers must be 0 or 1, found {markers}"),
        ));
    }
    let width = 4usize
        .checked_add(attributes)
        .and_then(|w| w.checked_add(markers))
        .ok_or_else(|| {
            file.error(
                header.number,
                format!("{attributes} attributes per point is more than a file can hold"),
            )
        })?;
    // A header may lie about its count: never reserve more than the text could hold.
    let mut vertices = Vec::with_capacity(n.min(text.len() / 8));
    let mut base = 0;
    for i in 0..n {
        let Some(line) = lines.next() else {
            return Err(file.truncated("points", i, n));
        };
        if line.tokens.len() < width {
            return Err(file.error(
                line.number,
                format!(
                    "a point needs {width} values (number, x, y, z, {attributes} attributes, \
                     {markers} markers), found {}",
                    line.tokens.len()
                ),
            ));
        }
        let number = file.integer(&line, 0, "the point number")?;
        if i == 0 {
            if number > 1 {
                return Err(file.error(
                    line.number,
                    format!("the first point is numbered {number}; TetGen numbers from 0 or 1"),
                ));
            }
            base = number;
        } else if number != base + i {
            return Err(file.error(
                line.number,
                format!(
                    "points must be numbered consecutively: expected {}, found {number}",
                    base + i
                ),
            ));
        }
        let mut xyz = [0.0; 3];
        for (c, value) in xyz.iter_mut().enumerate() {
            let token = line.tokens[1 + c];
            *value = token.parse::<f64>().map_err(|_| {
                file.error(
                    line.number,
                    format!(
                        "expected the {} coordinate of point {number} (a number), found '{token}'",
                        ["x", "y", "z"][c]
                    ),
                )
            })?;
        }
        vertices.push(Vec3::new(xyz[0], xyz[1], xyz[2]));
    }
    Ok((vertices, base))
}

/// The tets of an `.ele` file, as 0-based indices into the `points` points numbered from `base`.
fn read_tets(
    text: &str,
    path: &Path,
    base: usize,
    points: usize,
) -> Result<Vec<[usize; 4]>, MeshError> {
    let file = File {
        path,
        lines: text.lines().count(),
    };
    let mut lines = data_lines(text);
    let Some(header) = lines.next() else {
        return Err(file.error(
            1,
            "empty file: expected the header `<tets> <nodes per tet> <region attribute>`",
        ));
    };
    let n = file.count(&header, "the number of tets")?;
    let per_tet = file.integer(&header, 1, "the number of nodes per tet")?;
    if per_tet != 4 && per_tet != 10 {
        return Err(file.error(
            header.number,
            format!("a tet has 4 nodes (10 with `-o2`), the header says {per_tet}"),
        ));
    }
    let mut tets = Vec::with_capacity(n.min(text.len() / 10));
    for i in 0..n {
        let Some(line) = lines.next() else {
            return Err(file.truncated("tets", i, n));
        };
        if line.tokens.len() < 1 + per_tet {
            return Err(file.error(
                line.number,
                format!(
                    "a tet needs its number and {per_tet} nodes, found {} values",
                    line.tokens.len()
                ),
            ));
        }
        file.integer(&line, 0, "the tet number")?;
        let mut tet = [0; 4];
        for (c, corner) in tet.iter_mut().enumerate() {
            let node = file.integer(&line, 1 + c, "a node number")?;
            *corner = node
                .checked_sub(base)
                .filter(|&v| v < points)
                .ok_or_else(|| {
                    file.error(
                        line.number,
                        format!(
                            "node {node} is not a point of the .node file (numbered {base} to {})",
                            (base + points).saturating_sub(1)
                        ),
                    )
                })?;
        }
        tets.push(tet);
    }
    Ok(tets)
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
                NODE.to_string(),
                ELE.replace("1 3 2 5", "1 3 2 6"),
                "m.ele:3:",
                "node 6 is not a point",
            ),
            (
                NODE.to_string(),
                ELE.replace("2 4 1", "3 4 1"),
                "m.ele:3:",
                "declares 3 tets",
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
                "empty file",
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
        assert!(e.contains("declares 1000000 points"), "{e}");
    }
}
