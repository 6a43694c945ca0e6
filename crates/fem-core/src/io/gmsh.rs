//! Gmsh `.msh` reader.
//!
//! The version is taken from `$MeshFormat`:
//! - **2.x ASCII** (2.0–2.2) is parsed here, line by line: `$Nodes` (`tag x y z`, tags arbitrary)
//!   and `$Elements` (`tag type ntags tags… nodes…`), keeping type 4 (4-node tetrahedron) and
//!   ignoring every other element type; other sections (`$PhysicalNames`, `$NodeData`, …) are
//!   skipped. 2.x binary is rejected.
//! - **4.1 ASCII and binary** are parsed by the [`mshio`] crate, keeping `Tet4` element blocks.
//!   A light pass of our own over `$Nodes` recovers the node tags in file order (mshio drops
//!   them when they are dense, yet dense tags need not be in file order), checks that
//!   coordinates are finite and counts are within [`MAX_ENTITIES`], and gives line numbers.
//!   Parametric nodes (`SaveParametric`) are not supported. 4.0 and older are rejected.
//!
//! Every node becomes a vertex, in the file's node order (nodes no tet uses are kept; validation
//! reports them), and node tags are mapped to 0-based indices. Errors are [`MeshError::Parse`]
//! with a 1-based line (0 for binary files, whose byte offset the reason gives).

use std::collections::HashMap;
use std::path::Path;

use super::MAX_ENTITIES;
use crate::{MeshError, TetMesh, Vec3};

/// Gmsh element type of the 4-node tetrahedron.
const TET4: i64 = 4;

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
        parse_v2(&String::from_utf8_lossy(bytes), path)
    } else if text == "4.1" {
        parse_v41(bytes, path, &format)
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
    if format.binary {
        return None;
    }
    let elements = find_section(bytes, format.body, b"$Elements")?;
    let mut c = Cursor {
        bytes,
        pos: elements,
        encoding: Encoding::Ascii,
        path: Path::new(""),
    };
    let what = &String::new;
    if format.version < 3.0 {
        let total = c.size_t(what).ok()?;
        let mut tets = 0;
        for _ in 0..total {
            c.skip_whitespace();
            let rest = bytes.get(c.pos..)?;
            let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            let text = std::str::from_utf8(&rest[..end]).ok()?;
            if text.split_whitespace().nth(1) == Some("4") {
                if tets == t {
                    return Some(c.line(c.pos));
                }
                tets += 1;
            }
            c.pos += end;
        }
        return None;
    }
    let num_blocks = c.size_t(what).ok()?;
    for _ in 0..3 {
        c.size_t(what).ok()?;
    }
    let mut tets = 0usize;
    for _ in 0..num_blocks {
        c.int(what).ok()?;
        c.int(what).ok()?;
        let element_type = c.int(what).ok()?;
        let n = usize::try_from(c.size_t(what).ok()?).ok()?;
        let per = 1 + nodes_per_element(element_type)?;
        let skip = if element_type == TET4 && t < tets + n {
            t - tets
        } else {
            n
        };
        for _ in 0..skip.checked_mul(per)? {
            c.size_t(what).ok()?;
        }
        if element_type == TET4 {
            if t < tets + n {
                c.skip_whitespace();
                return Some(c.line(c.pos));
            }
            tets += n;
        }
    }
    None
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
                "expected $MeshFormat on the first line, found '{}'",
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
    // mshio also reads the size in ASCII 4.1 files (and panics on one above 255).
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

// ---------------------------------------------------------------------------------------------
// MSH 2.x ASCII
// ---------------------------------------------------------------------------------------------

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

fn parse_v2(text: &str, path: &Path) -> Result<TetMesh, MeshError> {
    let mut reader = LineReader {
        lines: text.lines(),
        line: 0,
        path,
    };
    let mut nodes: Option<(Vec<Vec3>, HashMap<u64, usize>)> = None;
    let mut tets: Option<Vec<[usize; 4]>> = None;
    let mut ignored: HashMap<i64, usize> = HashMap::new();
    while let Some((line, header)) = reader.next_nonblank() {
        match header {
            "$Nodes" => {
                if nodes.is_some() {
                    return Err(reader.error(line, "a second $Nodes section"));
                }
                nodes = Some(read_nodes_v2(&mut reader, text.len())?);
            }
            "$Elements" => {
                let Some((_, index)) = &nodes else {
                    return Err(reader.error(line, "$Elements comes before $Nodes"));
                };
                if tets.is_some() {
                    return Err(reader.error(line, "a second $Elements section"));
                }
                tets = Some(read_elements_v2(
                    &mut reader,
                    index,
                    text.len(),
                    &mut ignored,
                )?);
            }
            _ => match header.strip_prefix('$') {
                Some(name) if !name.starts_with("End") && !name.is_empty() => {
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

fn read_nodes_v2(
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

fn read_elements_v2(
    reader: &mut LineReader<'_>,
    index: &HashMap<u64, usize>,
    text_len: usize,
    ignored: &mut HashMap<i64, usize>,
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

/// Builds the mesh, refusing a file without any 4-node tetrahedron with a message naming what
/// it holds instead.
fn finish(
    vertices: Vec<Vec3>,
    tets: Vec<[usize; 4]>,
    ignored: &HashMap<i64, usize>,
    path: &Path,
    line: usize,
) -> Result<TetMesh, MeshError> {
    let mut kinds: Vec<(i64, usize)> = ignored.iter().map(|(&t, &n)| (t, n)).collect();
    kinds.sort_unstable();
    let summary = kinds
        .iter()
        .map(|(t, n)| format!("{n} of type {t}"))
        .collect::<Vec<_>>()
        .join(", ");
    if tets.is_empty() {
        let held = if summary.is_empty() {
            "no elements".to_string()
        } else {
            summary
        };
        return Err(parse_error(
            path,
            line,
            format!(
                "no 4-node tetrahedra (Gmsh element type 4) in the file; it holds {held} (type 11 is the 10-node tetrahedron, which is not supported)"
            ),
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

// ---------------------------------------------------------------------------------------------
// MSH 4.1 (mshio) and our pass over $Nodes
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy)]
enum Encoding {
    Ascii,
    Binary { size_t: usize, big_endian: bool },
}

/// Reads MSH 4.1 values (whitespace-separated text or raw binary) from a byte offset.
#[derive(Debug)]
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    encoding: Encoding,
    path: &'a Path,
}

impl<'a> Cursor<'a> {
    /// 1-based line of byte `pos` in a text file, 0 in a binary one.
    fn line(&self, pos: usize) -> usize {
        match self.encoding {
            Encoding::Ascii => {
                let before = self.bytes.get(..pos).unwrap_or(self.bytes);
                1 + before.iter().filter(|&&b| b == b'\n').count()
            }
            Encoding::Binary { .. } => 0,
        }
    }

    fn error(&self, pos: usize, reason: impl Into<String>) -> MeshError {
        let reason = reason.into();
        let reason = match self.encoding {
            Encoding::Ascii => reason,
            Encoding::Binary { .. } => format!("{reason} (at byte {pos})"),
        };
        parse_error(self.path, self.line(pos), reason)
    }

    fn skip_whitespace(&mut self) {
        while self
            .bytes
            .get(self.pos)
            .is_some_and(u8::is_ascii_whitespace)
        {
            self.pos += 1;
        }
    }

    fn eof(&self, what: &dyn Fn() -> String) -> MeshError {
        self.error(
            self.pos,
            format!(
                "unexpected end of file: expected {} (truncated file?)",
                what()
            ),
        )
    }

    /// The next whitespace-separated token of a text file and its byte offset.
    fn token(&mut self, what: &dyn Fn() -> String) -> Result<(&'a str, usize), MeshError> {
        self.skip_whitespace();
        let start = self.pos;
        while self
            .bytes
            .get(self.pos)
            .is_some_and(|b| !b.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        let raw = self.bytes.get(start..self.pos).unwrap_or_default();
        if raw.is_empty() {
            return Err(self.eof(what));
        }
        std::str::from_utf8(raw)
            .map(|t| (t, start))
            .map_err(|_| self.error(start, format!("expected {}, found non-text bytes", what())))
    }

    /// The next `N` raw bytes of a binary file.
    fn raw<const N: usize>(&mut self, what: &dyn Fn() -> String) -> Result<[u8; N], MeshError> {
        let bytes = self
            .pos
            .checked_add(N)
            .and_then(|end| self.bytes.get(self.pos..end))
            .and_then(|b| <[u8; N]>::try_from(b).ok())
            .ok_or_else(|| self.eof(what))?;
        self.pos += N;
        Ok(bytes)
    }

    fn parse_token<T: std::str::FromStr>(
        &mut self,
        what: &dyn Fn() -> String,
        kind: &str,
    ) -> Result<T, MeshError> {
        let (text, pos) = self.token(what)?;
        text.parse().map_err(|_| {
            self.error(
                pos,
                format!("expected {} ({kind}), found '{}'", what(), snippet(text)),
            )
        })
    }

    fn size_t(&mut self, what: &dyn Fn() -> String) -> Result<u64, MeshError> {
        match self.encoding {
            Encoding::Ascii => self.parse_token(what, "a non-negative integer"),
            Encoding::Binary {
                size_t: 4,
                big_endian,
            } => {
                let b = self.raw::<4>(what)?;
                Ok(u64::from(if big_endian {
                    u32::from_be_bytes(b)
                } else {
                    u32::from_le_bytes(b)
                }))
            }
            Encoding::Binary { big_endian, .. } => {
                let b = self.raw::<8>(what)?;
                Ok(if big_endian {
                    u64::from_be_bytes(b)
                } else {
                    u64::from_le_bytes(b)
                })
            }
        }
    }

    fn int(&mut self, what: &dyn Fn() -> String) -> Result<i64, MeshError> {
        match self.encoding {
            Encoding::Ascii => self.parse_token(what, "an integer"),
            Encoding::Binary { big_endian, .. } => {
                let b = self.raw::<4>(what)?;
                Ok(i64::from(if big_endian {
                    i32::from_be_bytes(b)
                } else {
                    i32::from_le_bytes(b)
                }))
            }
        }
    }

    /// A finite double.
    fn double(&mut self, what: &dyn Fn() -> String) -> Result<f64, MeshError> {
        let pos = self.pos;
        let value: f64 = match self.encoding {
            Encoding::Ascii => self.parse_token(what, "a number")?,
            Encoding::Binary { big_endian, .. } => {
                let b = self.raw::<8>(what)?;
                if big_endian {
                    f64::from_be_bytes(b)
                } else {
                    f64::from_le_bytes(b)
                }
            }
        };
        if value.is_finite() {
            Ok(value)
        } else {
            // Point at the value itself, not at the whitespace before it.
            let mut at = Cursor { pos, ..*self };
            at.skip_whitespace();
            Err(self.error(at.pos, format!("{} is not finite ({value})", what())))
        }
    }

    fn usize_count(&mut self, what: &dyn Fn() -> String) -> Result<usize, MeshError> {
        let pos = self.pos;
        let n = self.size_t(what)?;
        usize::try_from(n)
            .ok()
            .filter(|&n| n <= MAX_ENTITIES)
            .ok_or_else(|| {
                self.error(
                    pos,
                    format!("{} is {n}, more than the limit of {MAX_ENTITIES}", what()),
                )
            })
    }

    fn end_tag(&mut self, tag: &str) -> Result<(), MeshError> {
        self.skip_whitespace();
        if self
            .bytes
            .get(self.pos..)
            .is_some_and(|rest| rest.starts_with(tag.as_bytes()))
        {
            Ok(())
        } else {
            Err(self.error(
                self.pos,
                format!("expected {tag}: the section holds more data than its header declares"),
            ))
        }
    }
}

/// Byte offset just after the line `name` (a section start such as `$Nodes`) at or after `from`.
fn find_section(bytes: &[u8], from: usize, name: &[u8]) -> Option<usize> {
    let mut start = from;
    loop {
        let rest = bytes.get(start..)?;
        let at = start + rest.windows(name.len()).position(|w| w == name)?;
        let at_line_start = at == 0 || bytes.get(at - 1).is_some_and(u8::is_ascii_whitespace);
        let mut end = at + name.len();
        while matches!(bytes.get(end), Some(b' ' | b'\t' | b'\r')) {
            end += 1;
        }
        if at_line_start && bytes.get(end) == Some(&b'\n') {
            return Some(end + 1);
        }
        start = at + 1;
    }
}

/// What our pass over `$Nodes` finds: node tags in file order, their 0-based indices and the
/// size of each node block.
#[derive(Debug)]
struct NodeTags {
    index: HashMap<u64, usize>,
    block_sizes: Vec<usize>,
}

fn scan_nodes(mut c: Cursor<'_>) -> Result<NodeTags, MeshError> {
    let header = c.pos;
    let num_blocks = c.usize_count(&|| "the number of node blocks in $Nodes".into())?;
    let num_nodes = c.usize_count(&|| "the number of nodes in $Nodes".into())?;
    c.size_t(&|| "the smallest node tag".into())?;
    c.size_t(&|| "the largest node tag".into())?;
    if num_nodes == 0 {
        return Err(c.error(header, "$Nodes declares no nodes"));
    }
    // A header may lie about its count: never reserve more than the file could hold.
    let mut index = HashMap::with_capacity(num_nodes.min(c.bytes.len() / 8));
    let mut block_sizes = Vec::new();
    let mut tags = Vec::new();
    for b in 1..=num_blocks {
        let block = c.pos;
        c.int(&|| format!("the entity dimension of node block {b}"))?;
        c.int(&|| format!("the entity tag of node block {b}"))?;
        let parametric = c.int(&|| format!("the parametric flag of node block {b}"))?;
        let n = c.usize_count(&|| format!("the number of nodes in node block {b}"))?;
        if parametric != 0 {
            return Err(c.error(
                block,
                format!("node block {b} has parametric coordinates, which are not supported (save without Mesh.SaveParametric)"),
            ));
        }
        if index.len() + n > num_nodes {
            return Err(c.error(
                block,
                format!("node block {b} holds {n} nodes, more than the {num_nodes} that $Nodes declares in total"),
            ));
        }
        tags.clear();
        for k in 1..=n {
            let pos = c.pos;
            let tag = c.size_t(&|| format!("node tag {k} of {n} in node block {b}"))?;
            if index.insert(tag, index.len()).is_some() {
                let mut at = Cursor { pos, ..c };
                at.skip_whitespace();
                return Err(at.error(at.pos, format!("node tag {tag} appears twice in $Nodes")));
            }
            tags.push(tag);
        }
        for &tag in &tags {
            for axis in ["x", "y", "z"] {
                c.double(&|| format!("the {axis} coordinate of node {tag}"))?;
            }
        }
        block_sizes.push(n);
    }
    if index.len() != num_nodes {
        return Err(c.error(
            header,
            format!(
                "$Nodes declares {num_nodes} nodes, but its blocks hold {}",
                index.len()
            ),
        ));
    }
    c.end_tag("$EndNodes")?;
    Ok(NodeTags { index, block_sizes })
}

/// Nodes per element of the Gmsh element types (`None` for types this table does not know;
/// mshio then reports them).
fn nodes_per_element(element_type: i64) -> Option<usize> {
    Some(match element_type {
        15 => 1,
        1 => 2,
        2 | 8 => 3,
        3 | 4 | 26 => 4,
        7 | 27 => 5,
        6 | 9 | 28 => 6,
        5 | 16 => 8,
        10 | 20 => 9,
        11 | 21 => 10,
        22 => 12,
        19 => 13,
        14 => 14,
        18 | 23 | 24 => 15,
        17 | 29 => 20,
        25 => 21,
        12 => 27,
        30 => 35,
        31 => 56,
        92 => 64,
        93 => 125,
        _ => return None,
    })
}

/// Our pass over `$Elements`: checks each block's count against the section header before mshio
/// walks the blocks, so a huge or inconsistent count is refused at its line.
fn scan_elements(mut c: Cursor<'_>) -> Result<(), MeshError> {
    let num_blocks = c.usize_count(&|| "the number of element blocks in $Elements".into())?;
    let header = c.pos;
    let total = c.usize_count(&|| "the number of elements in $Elements".into())?;
    if total == 0 {
        return Err(c.error(header, "$Elements declares no elements"));
    }
    c.size_t(&|| "the smallest element tag".into())?;
    c.size_t(&|| "the largest element tag".into())?;
    let mut seen = 0usize;
    for b in 1..=num_blocks {
        c.int(&|| format!("the entity dimension of element block {b}"))?;
        c.int(&|| format!("the entity tag of element block {b}"))?;
        let element_type = c.int(&|| format!("the element type of element block {b}"))?;
        let count_at = c.pos;
        let n = c.usize_count(&|| format!("the number of elements in element block {b}"))?;
        if n > total - seen {
            let mut at = Cursor { pos: count_at, ..c };
            at.skip_whitespace();
            return Err(at.error(
                at.pos,
                format!(
                    "element block {b} holds {n} elements, more than the {} left of the {total} that $Elements declares",
                    total - seen
                ),
            ));
        }
        seen += n;
        let Some(nodes) = nodes_per_element(element_type) else {
            return Ok(());
        };
        for k in 1..=n {
            for _ in 0..=nodes {
                c.size_t(&|| format!("element {k} of {n} in element block {b}"))?;
            }
        }
    }
    if seen != total {
        return Err(c.error(
            header,
            format!("$Elements declares {total} elements, but its blocks hold {seen}"),
        ));
    }
    c.end_tag("$EndElements")
}

/// Line (0 if binary or not found) of element `element` of element block `block`, for errors
/// found after mshio has parsed the file.
fn locate_element(
    mut c: Cursor<'_>,
    blocks: &[mshio::ElementBlock<u64, i32>],
    block: usize,
    element: usize,
) -> usize {
    let mut walk = || -> Result<usize, MeshError> {
        for _ in 0..4 {
            c.size_t(&String::new)?;
        }
        for (b, blk) in blocks.iter().enumerate() {
            for _ in 0..3 {
                c.int(&String::new)?;
            }
            c.size_t(&String::new)?;
            let per = 1 + blk.elements.first().map_or(0, |e| e.nodes.len());
            let skip = if b == block {
                element
            } else {
                blk.elements.len()
            };
            for _ in 0..skip.saturating_mul(per) {
                c.size_t(&String::new)?;
            }
            if b == block {
                c.skip_whitespace();
                return Ok(c.line(c.pos));
            }
        }
        Ok(0)
    };
    walk().unwrap_or(0)
}

/// Converts an mshio error into a parse error at the position it names.
fn mshio_error(bytes: &[u8], cursor: &Cursor<'_>, err: &mshio::MshParserError<&[u8]>) -> MeshError {
    let mut parts: Vec<String> = Vec::new();
    for (_, kind) in err.backtrace.iter().rev() {
        if kind.is_nom_error() {
            continue;
        }
        let part = kind
            .context()
            .map_or_else(|| kind.to_string(), str::to_string);
        if parts.last() != Some(&part) {
            parts.push(part);
        }
    }
    if parts.is_empty() {
        // Only nom's own error kinds: name the common one plainly.
        let nom = err
            .backtrace
            .first()
            .map(|(_, kind)| format!("{kind:?}"))
            .unwrap_or_default();
        parts.push(if nom.contains("Eof") {
            "unexpected end of file (truncated file or unterminated section)".into()
        } else {
            format!("malformed data ({nom})")
        });
    }
    let reason = format!("Gmsh 4.1 parser (mshio): {}", parts.join(": "));
    // The deepest error comes first; nom hands out sub-slices of the input.
    let base = bytes.as_ptr() as usize;
    let offset = err
        .backtrace
        .first()
        .and_then(|(rest, _)| (rest.as_ptr() as usize).checked_sub(base))
        .filter(|&o| o <= bytes.len());
    match offset {
        Some(pos) => cursor.error(pos, reason),
        None => parse_error(cursor.path, 0, reason),
    }
}

fn parse_v41(bytes: &[u8], path: &Path, format: &MeshFormat) -> Result<TetMesh, MeshError> {
    let encoding = if format.binary {
        let marker = bytes.get(format.body..format.body.saturating_add(4));
        let big_endian = match marker {
            Some([1, 0, 0, 0]) => false,
            Some([0, 0, 0, 1]) => true,
            _ => {
                // The marker follows the header line, which may end the file: name that line.
                return Err(parse_error(
                    path,
                    format.line,
                    format!(
                        "binary MSH file without the integer 1 after this header line (at byte {}): cannot tell the byte order",
                        format.body
                    ),
                ));
            }
        };
        Encoding::Binary {
            size_t: format.data_size,
            big_endian,
        }
    } else {
        Encoding::Ascii
    };
    let cursor = |pos: usize| Cursor {
        bytes,
        pos,
        encoding,
        path,
    };
    let end_line = cursor(bytes.len()).line(bytes.len());

    // Our own pass first: it checks counts before mshio walks them and keeps the tag order.
    let nodes_at = find_section(bytes, format.body, b"$Nodes")
        .ok_or_else(|| parse_error(path, end_line, "no $Nodes section"))?;
    let tags = scan_nodes(cursor(nodes_at))?;
    let elements_at = find_section(bytes, format.body, b"$Elements")
        .ok_or_else(|| parse_error(path, end_line, "no $Elements section"))?;
    scan_elements(cursor(elements_at))?;

    // mshio has panicking paths on malformed input (e.g. `unimplemented!`): contain them.
    let parsed = std::panic::catch_unwind(|| mshio::parse_msh_bytes(bytes));
    let msh = match parsed {
        Ok(Ok(msh)) => msh,
        Ok(Err(err)) => return Err(mshio_error(bytes, &cursor(0), &err)),
        Err(_) => {
            return Err(parse_error(
                path,
                0,
                "the Gmsh 4.1 parser (mshio) failed on this malformed file",
            ));
        }
    };
    let inconsistent = || {
        parse_error(
            path,
            0,
            "mshio and the $Nodes scan disagree on the node blocks (malformed file?)",
        )
    };
    let nodes = msh.data.nodes.ok_or_else(inconsistent)?;
    if nodes.node_blocks.len() != tags.block_sizes.len() {
        return Err(inconsistent());
    }
    let mut vertices = Vec::with_capacity(tags.index.len());
    for (block, &size) in nodes.node_blocks.iter().zip(&tags.block_sizes) {
        if block.nodes.len() != size {
            return Err(inconsistent());
        }
        vertices.extend(block.nodes.iter().map(|n| Vec3::new(n.x, n.y, n.z)));
    }

    let elements = msh
        .data
        .elements
        .ok_or_else(|| parse_error(path, end_line, "no $Elements section"))?;
    let mut tets = Vec::new();
    let mut ignored: HashMap<i64, usize> = HashMap::new();
    for (b, block) in elements.element_blocks.iter().enumerate() {
        if block.element_type != mshio::ElementType::Tet4 {
            *ignored.entry(block.element_type as i64).or_default() += block.elements.len();
            continue;
        }
        tets.reserve(block.elements.len());
        for (k, element) in block.elements.iter().enumerate() {
            let mut tet = [usize::MAX; 4];
            let mut filled = 0;
            for (slot, tag) in tet.iter_mut().zip(&element.nodes) {
                *slot = *tags.index.get(tag).ok_or_else(|| {
                    let line = locate_element(cursor(elements_at), &elements.element_blocks, b, k);
                    parse_error(
                        path,
                        line,
                        format!(
                            "element {} references node {tag}, which $Nodes does not define",
                            element.element_tag
                        ),
                    )
                })?;
                filled += 1;
            }
            if filled != 4 || element.nodes.len() != 4 {
                return Err(parse_error(
                    path,
                    0,
                    format!("element {} does not have 4 nodes", element.element_tag),
                ));
            }
            tets.push(tet);
        }
    }
    finish(vertices, tets, &ignored, path, end_line)
}

#[cfg(test)]
mod tests {
    use super::*;

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
        // mshio panics on a size above 255 (contained, but with no line): refused up front.
        let (line, reason) = parse_error(V41.replace("4.1 0 8", "4.1 0 999").as_bytes());
        assert_eq!(line, 2);
        assert!(reason.contains("size_t"), "{reason}");
        // A negative number of tags used to shift the node list silently.
        let text = V22.replace("3 4 2 1 1 10 20 30 40", "3 4 -2 10 20 30 40");
        let (line, reason) = parse_error(text.as_bytes());
        assert_eq!(line, 20);
        assert!(reason.contains("negative"), "{reason}");
        // An element block larger than the section: refused at its line before mshio walks it.
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
        assert!(reason.contains("1 of type 11"), "{reason}");
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
