//! Gmsh MSH 2.x ASCII (2.0–2.2), parsed line by line: `$Nodes` (`tag x y z`, tags arbitrary) and
//! `$Elements` (`number type ntags tags… nodes…`), keeping type 4 (4-node tetrahedron) and
//! counting every other element type; other sections (`$PhysicalNames`, `$NodeData`, …) are
//! skipped to their `$End…` line. Errors carry the 1-based line.

use std::collections::HashMap;
use std::path::Path;

use super::{Skipped, TET4, finish, parse_error, snippet};
use crate::io::MAX_ENTITIES;
use crate::{MeshError, TetMesh, Vec3};

/// Non-blank, trimmed lines with their 1-based numbers.
#[derive(Debug)]
struct LineReader<'a> {
    lines: std::str::Lines<'a>,
    line: usize,
    path: &'a Path,
}

impl<'a> LineReader<'a> {
    fn next_nonblank(&mut self) -> Option<(usize, &'a str)> {
        for l in self.lines.by_ref() {
            self.line += 1;
            let t = l.trim();
            if !t.is_empty() {
                return Some((self.line, t));
            }
        }
        None
    }

    fn error(&self, line: usize, reason: impl Into<String>) -> MeshError {
        parse_error(self.path, line, reason)
    }

    /// The next non-blank line, or an end-of-file error naming `what` was expected.
    fn expect(&mut self, what: &dyn Fn() -> String) -> Result<(usize, &'a str), MeshError> {
        self.next_nonblank().ok_or_else(|| {
            self.error(
                self.line.max(1),
                format!(
                    "unexpected end of file: expected {} (truncated file?)",
                    what()
                ),
            )
        })
    }

    fn count(&mut self, what: &str) -> Result<usize, MeshError> {
        let (line, text) = self.expect(&|| format!("the number of {what}"))?;
        let n: usize = text.parse().map_err(|_| {
            self.error(
                line,
                format!("expected the number of {what}, found '{}'", snippet(text)),
            )
        })?;
        if n > MAX_ENTITIES {
            return Err(self.error(
                line,
                format!("{n} {what} declared, more than the limit of {MAX_ENTITIES}"),
            ));
        }
        Ok(n)
    }

    fn end_tag(&mut self, tag: &str, after: &str) -> Result<(), MeshError> {
        let (line, text) = self.expect(&|| tag.to_string())?;
        if text == tag {
            Ok(())
        } else {
            Err(self.error(
                line,
                format!("expected {tag} after {after}, found '{}'", snippet(text)),
            ))
        }
    }
}

pub(super) fn parse(text: &str, path: &Path) -> Result<TetMesh, MeshError> {
    let mut reader = LineReader {
        lines: text.lines(),
        line: 0,
        path,
    };
    let mut nodes: Option<(Vec<Vec3>, HashMap<u64, usize>)> = None;
    let mut tets: Option<Vec<[usize; 4]>> = None;
    let mut ignored = Skipped::new();
    // Gmsh's `Mesh.SaveParametric` writes the nodes as `$ParametricNodes`.
    let mut parametric = false;
    while let Some((line, header)) = reader.next_nonblank() {
        match header {
            "$Nodes" => {
                if nodes.is_some() {
                    return Err(reader.error(line, "a second $Nodes section"));
                }
                nodes = Some(read_nodes(&mut reader, text.len())?);
            }
            "$Elements" => {
                let Some((_, index)) = &nodes else {
                    return Err(reader.error(
                        line,
                        if parametric {
                            "the nodes are in $ParametricNodes, which is not read: save the mesh \
                             again without Mesh.SaveParametric"
                        } else {
                            "$Elements comes before $Nodes"
                        },
                    ));
                };
                if tets.is_some() {
                    return Err(reader.error(line, "a second $Elements section"));
                }
                tets = Some(read_elements(&mut reader, index, text.len(), &mut ignored)?);
            }
            _ => match header.strip_prefix('$') {
                Some(name) if !name.starts_with("End") && !name.is_empty() => {
                    parametric |= name == "ParametricNodes";
                    let end = format!("$End{name}");
                    loop {
                        match reader.next_nonblank() {
                            Some((_, l)) if l == end => break,
                            Some(_) => {}
                            None => {
                                return Err(reader.error(
                                    reader.line.max(1),
                                    format!(
                                        "unexpected end of file: section {header} (line {line}) has no {end}"
                                    ),
                                ));
                            }
                        }
                    }
                }
                _ => {
                    return Err(reader.error(
                        line,
                        format!(
                            "expected a section start such as $Nodes or $Elements, found '{}'",
                            snippet(header)
                        ),
                    ));
                }
            },
        }
    }
    let last = reader.line.max(1);
    let Some((vertices, _)) = nodes else {
        return Err(reader.error(last, "no $Nodes section"));
    };
    let Some(tets) = tets else {
        return Err(reader.error(last, "no $Elements section"));
    };
    finish(vertices, tets, &ignored, path, last)
}

fn read_nodes(
    reader: &mut LineReader<'_>,
    text_len: usize,
) -> Result<(Vec<Vec3>, HashMap<u64, usize>), MeshError> {
    let n = reader.count("nodes")?;
    // A header may lie about its count: never reserve more than the text could hold.
    let capacity = n.min(text_len / 8);
    let mut vertices = Vec::with_capacity(capacity);
    let mut index = HashMap::with_capacity(capacity);
    for k in 0..n {
        let (line, text) = reader.expect(&|| format!("node {} of {n}", k + 1))?;
        let err = |reason: String| reader.error(line, reason);
        if text.starts_with('$') {
            return Err(err(format!(
                "expected node {} of {n} ('tag x y z'), found '{}': fewer nodes than declared",
                k + 1,
                snippet(text)
            )));
        }
        let mut fields = text.split_whitespace();
        let tag_text = fields.next().unwrap_or_default();
        let tag: u64 = tag_text.parse().map_err(|_| {
            err(format!(
                "expected the tag of node {} (a positive integer), found '{}'",
                k + 1,
                snippet(tag_text)
            ))
        })?;
        let mut x = [0.0f64; 3];
        for (axis, slot) in ["x", "y", "z"].iter().zip(&mut x) {
            let field = fields.next().ok_or_else(|| {
                err(format!(
                    "node {tag}: expected 'tag x y z', the {axis} coordinate is missing"
                ))
            })?;
            *slot = field.parse().map_err(|_| {
                err(format!(
                    "node {tag}: expected the {axis} coordinate (a number), found '{}'",
                    snippet(field)
                ))
            })?;
            if !slot.is_finite() {
                return Err(err(format!(
                    "node {tag}: the {axis} coordinate is not finite ('{field}')"
                )));
            }
        }
        if let Some(extra) = fields.next() {
            return Err(err(format!(
                "node {tag}: expected 'tag x y z', found an extra value '{}'",
                snippet(extra)
            )));
        }
        if index.insert(tag, k).is_some() {
            return Err(err(format!("node tag {tag} appears twice in $Nodes")));
        }
        vertices.push(Vec3::new(x[0], x[1], x[2]));
    }
    reader.end_tag("$EndNodes", &format!("{n} nodes"))?;
    Ok((vertices, index))
}

fn read_elements(
    reader: &mut LineReader<'_>,
    index: &HashMap<u64, usize>,
    text_len: usize,
    ignored: &mut Skipped,
) -> Result<Vec<[usize; 4]>, MeshError> {
    let m = reader.count("elements")?;
    let mut tets = Vec::with_capacity(m.min(text_len / 16));
    for k in 0..m {
        let (line, text) = reader.expect(&|| format!("element {} of {m}", k + 1))?;
        let err = |reason: String| reader.error(line, reason);
        if text.starts_with('$') {
            return Err(err(format!(
                "expected element {} of {m}, found '{}': fewer elements than declared",
                k + 1,
                snippet(text)
            )));
        }
        let mut fields = text.split_whitespace();
        let mut next_int = |what: &str| -> Result<i64, MeshError> {
            let field = fields.next().ok_or_else(|| {
                err(format!(
                    "element {} of {m}: expected 'number type ntags tags… nodes…', {what} is missing",
                    k + 1
                ))
            })?;
            field.parse().map_err(|_| {
                err(format!(
                    "element {} of {m}: expected {what} (an integer), found '{}'",
                    k + 1,
                    snippet(field)
                ))
            })
        };
        let number = next_int("the element number")?;
        let element_type = next_int("the element type")?;
        let num_tags = next_int("the number of tags")?;
        if element_type != TET4 {
            *ignored.entry(element_type).or_default() += 1;
            continue;
        }
        if num_tags < 0 {
            return Err(err(format!(
                "element {number}: the number of tags is {num_tags}, which is negative"
            )));
        }
        for t in 0..num_tags {
            next_int(&format!("tag {} of {num_tags}", t + 1))?;
        }
        let mut tet = [0usize; 4];
        for (c, slot) in tet.iter_mut().enumerate() {
            let tag = next_int(&format!("node {} of the 4-node tetrahedron", c + 1))?;
            *slot = u64::try_from(tag)
                .ok()
                .and_then(|t| index.get(&t))
                .copied()
                .ok_or_else(|| {
                    err(format!(
                        "element {number} references node {tag}, which $Nodes does not define"
                    ))
                })?;
        }
        if let Some(extra) = fields.next() {
            return Err(err(format!(
                "element {number}: a 4-node tetrahedron (type 4) with {num_tags} tags has {} values, found more ('{}')",
                7 + num_tags,
                snippet(extra)
            )));
        }
        tets.push(tet);
    }
    reader.end_tag("$EndElements", &format!("{m} elements"))?;
    Ok(tets)
}

/// 1-based line of the `t`-th 4-node tetrahedron (0-based, in file order) of a file that
/// [`parse`] read.
pub(super) fn tet_line(text: &str, t: usize) -> Option<usize> {
    let mut reader = LineReader {
        lines: text.lines(),
        line: 0,
        path: Path::new(""),
    };
    while reader.next_nonblank()?.1 != "$Elements" {}
    let total: usize = reader.next_nonblank()?.1.parse().ok()?;
    let mut tets = 0;
    for _ in 0..total {
        let (line, element) = reader.next_nonblank()?;
        if element.split_whitespace().nth(1) == Some("4") {
            if tets == t {
                return Some(line);
            }
            tets += 1;
        }
    }
    None
}
