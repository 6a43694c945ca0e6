//! Legacy VTK (`.vtk`) reader for ASCII `DATASET UNSTRUCTURED_GRID` files.
//!
//! Supported: the `# vtk DataFile Version x.y` header (2.0 up to 5.1) and a title line, then
//! `POINTS n float|double|…`, and the cells in either layout:
//! - classic (≤ 4.2): `CELLS n size` followed by `k i₀ … iₖ₋₁` per cell;
//! - 5.1: `CELLS n_offsets n_connectivity` followed by `OFFSETS <type>` and
//!   `CONNECTIVITY <type>` arrays;
//!
//! then `CELL_TYPES n`. Only cells of type 10 (`VTK_TETRA`) are kept; other cell types are
//! ignored. `FIELD` and `METADATA` blocks are skipped, and reading stops at `POINT_DATA` or
//! `CELL_DATA` (attribute data is not needed). Values may wrap lines freely. Indices are already
//! 0-based. Other dataset types are rejected. Errors are [`MeshError::Parse`] with the 1-based
//! line; the mesh is not validated here.
//!
//! `BINARY` files (meshio's and VTK's default) hold the same blocks with each array as
//! big-endian values after its header line; [`parse_bytes`] reads them as the ASCII file they
//! stand for, their errors without a line (0) past the header.

use std::path::Path;

use super::MAX_ENTITIES;
use crate::{MeshError, TetMesh, Vec3};

/// VTK cell type of the linear tetrahedron.
const VTK_TETRA: u64 = 10;

/// Reads the legacy VTK file at `path` (not validated).
pub fn read(path: &Path) -> Result<TetMesh, MeshError> {
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_bytes(&bytes, path)
}

/// Parses a legacy VTK file, ASCII or `BINARY`; `path` only names the source in errors.
pub fn parse_bytes(bytes: &[u8], path: &Path) -> Result<TetMesh, MeshError> {
    if is_binary(bytes) {
        // The ASCII text's lines are not the file's: its errors say none.
        parse(&binary_as_ascii(bytes, path)?, path).map_err(|e| match e {
            MeshError::Parse { path, reason, .. } => MeshError::Parse {
                path,
                line: 0,
                reason,
            },
            other => other,
        })
    } else {
        parse(&String::from_utf8_lossy(bytes), path)
    }
}

/// Whether a legacy VTK file says `BINARY` on its third line.
pub(crate) fn is_binary(bytes: &[u8]) -> bool {
    bytes.split(|&b| b == b'\n').nth(2).is_some_and(|l| {
        String::from_utf8_lossy(l)
            .trim()
            .eq_ignore_ascii_case("BINARY")
    })
}

/// The ASCII file a `BINARY` legacy VTK file stands for: its header and block lines as they
/// are, each binary array (big-endian, `size` bytes a value) written out as numbers on one line.
/// Reading stops at the attribute data, which the mesh does not need.
fn binary_as_ascii(bytes: &[u8], path: &Path) -> Result<String, MeshError> {
    let mut r = BinaryReader {
        bytes,
        at: 0,
        line: 0,
        path,
    };
    let mut out = String::new();
    for _ in 0..2 {
        out += &r.raw_line()?;
        out.push('\n');
    }
    r.raw_line()?;
    out += "ASCII\n";
    while let Some(line) = r.line()? {
        let words: Vec<&str> = line.split_whitespace().collect();
        let keyword = words[0].to_ascii_uppercase();
        out += &line;
        out.push('\n');
        let at_line = r.line;
        let count = |i: usize| {
            words
                .get(i)
                .and_then(|w| w.parse::<usize>().ok())
                .filter(|&n| n <= MAX_ENTITIES.saturating_mul(16))
                .ok_or_else(|| MeshError::Parse {
                    path: path.to_path_buf(),
                    line: at_line,
                    reason: format!(
                        "expected counts after {keyword}, found '{}'",
                        snippet(&line)
                    ),
                })
        };
        match keyword.as_str() {
            "DATASET" => {}
            "POINTS" => {
                let n = count(1)?;
                let ty = words.get(2).copied().unwrap_or_default();
                r.values(n.saturating_mul(3), ty, &mut out)?;
            }
            "CELLS" => {
                let (n, size) = (count(1)?, count(2)?);
                let next = r.peek_line();
                if next
                    .trim_start()
                    .to_ascii_uppercase()
                    .starts_with("OFFSETS")
                {
                    for (block, values) in [("OFFSETS", n), ("CONNECTIVITY", size)] {
                        let header = r.line()?.unwrap_or_default();
                        let ty = header.split_whitespace().nth(1).unwrap_or_default();
                        if !header.trim_start().to_ascii_uppercase().starts_with(block) {
                            return Err(
                                r.error(format!("expected {block}, found '{}'", snippet(&header)))
                            );
                        }
                        out += &header;
                        out.push('\n');
                        r.values(values, ty, &mut out)?;
                    }
                } else {
                    r.values(size, "int", &mut out)?;
                }
            }
            "CELL_TYPES" => r.values(count(1)?, "int", &mut out)?,
            "FIELD" => {
                // Arrays of `name components tuples type`, read past.
                let mut skipped = String::new();
                for _ in 0..count(2)? {
                    let header = r.line()?.unwrap_or_default();
                    let w: Vec<&str> = header.split_whitespace().collect();
                    let n = w.get(1).zip(w.get(2)).and_then(|(a, b)| {
                        a.parse::<usize>()
                            .ok()?
                            .checked_mul(b.parse::<usize>().ok()?)
                    });
                    let Some(n) = n else {
                        return Err(r.error(format!(
                            "expected a FIELD array's `name components tuples type`, found '{}'",
                            snippet(&header)
                        )));
                    };
                    r.values(n, w.get(3).copied().unwrap_or_default(), &mut skipped)?;
                    skipped.clear();
                }
                out.truncate(out.len() - line.len() - 1);
            }
            "METADATA" => {
                // Text lines up to a blank one.
                out.truncate(out.len() - line.len() - 1);
                while r.raw_line().is_ok_and(|l| !l.trim().is_empty()) {}
            }
            // The attribute data: the mesh is complete.
            _ => break,
        }
    }
    Ok(out)
}

/// Lines and big-endian arrays of a `BINARY` legacy VTK file.
struct BinaryReader<'a> {
    bytes: &'a [u8],
    at: usize,
    /// Lines read as text so far.
    line: usize,
    path: &'a Path,
}

impl BinaryReader<'_> {
    fn error(&self, reason: impl Into<String>) -> MeshError {
        // Binary arrays hold newline bytes: lines counted past the header are not the file's.
        MeshError::Parse {
            path: self.path.to_path_buf(),
            line: if self.line <= 3 { self.line } else { 0 },
            reason: reason.into(),
        }
    }

    /// The next line, whatever it holds; an error at the end of the file.
    fn raw_line(&mut self) -> Result<String, MeshError> {
        if self.at >= self.bytes.len() {
            return Err(self.error("unexpected end of file: expected the header (truncated file?)"));
        }
        let rest = &self.bytes[self.at..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.at += (end + 1).min(rest.len());
        self.line += 1;
        Ok(String::from_utf8_lossy(&rest[..end])
            .trim_end_matches('\r')
            .to_string())
    }

    /// The next line that is not blank, None at the end of the file.
    fn line(&mut self) -> Result<Option<String>, MeshError> {
        while self.at < self.bytes.len() {
            let line = self.raw_line()?;
            if !line.trim().is_empty() {
                return Ok(Some(line));
            }
        }
        Ok(None)
    }

    /// The next line that is not blank, left to be read.
    fn peek_line(&mut self) -> String {
        let (at, line) = (self.at, self.line);
        let next = self.line().ok().flatten().unwrap_or_default();
        (self.at, self.line) = (at, line);
        next
    }

    /// `n` big-endian values of the legacy type `ty`, written to `out` as numbers on one line;
    /// the line break after the array is read past.
    fn values(&mut self, n: usize, ty: &str, out: &mut String) -> Result<(), MeshError> {
        use std::fmt::Write;
        let ty = ty.to_ascii_lowercase();
        let size = match ty.as_str() {
            "char" | "unsigned_char" | "bit" => 1,
            "short" | "unsigned_short" => 2,
            "int" | "unsigned_int" | "float" | "vtktypeint32" | "vtktypeuint32" => 4,
            "long" | "unsigned_long" | "double" | "vtktypeint64" | "vtktypeuint64" => 8,
            _ => {
                return Err(self.error(format!(
                    "expected the data type of a binary array (float, double, int, vtktypeint64, …), found '{}'",
                    snippet(&ty)
                )));
            }
        };
        let needed = n
            .checked_mul(size)
            .filter(|&b| b <= self.bytes.len() - self.at);
        let Some(needed) = needed else {
            return Err(self.error(format!(
                "the binary array after this line needs {n} values of {size} bytes, but the file \
                 has {} bytes left (truncated file?)",
                self.bytes.len() - self.at
            )));
        };
        out.reserve(n * 12);
        for chunk in self.bytes[self.at..self.at + needed].chunks_exact(size) {
            let bits = super::widened(chunk, false);
            let _ = match ty.as_str() {
                "float" => write!(out, "{} ", f64::from(f32::from_bits(bits as u32))),
                "double" => write!(out, "{} ", f64::from_bits(bits)),
                "char" | "short" | "int" | "long" | "vtktypeint32" | "vtktypeint64" => {
                    write!(out, "{} ", super::sign_extended(bits, size))
                }
                _ => write!(out, "{bits} "),
            };
        }
        out.push('\n');
        self.at += needed;
        if self.bytes.get(self.at) == Some(&b'\n') {
            self.at += 1;
        }
        Ok(())
    }
}

/// Parses the text of a legacy VTK file; `path` only names the source in errors.
pub fn parse(text: &str, path: &Path) -> Result<TetMesh, MeshError> {
    Parser {
        tokens: Tokens::new(text),
        path,
        text_len: text.len(),
    }
    .run()
}

/// 1-based line of the `t`-th tetrahedron (0-based, among the cells of type 10) of a file that
/// [`parse`] read: the line of its point count (classic layout) or of its first connectivity
/// value (5.1 layout), for messages about a tet that validation refuses.
pub(crate) fn tet_line(text: &str, t: usize) -> Option<usize> {
    let keyword = |tokens: &mut Tokens<'_>, name: &str| {
        while let Some(tok) = tokens.next() {
            if tok.text.eq_ignore_ascii_case(name) {
                return Some(());
            }
        }
        None
    };
    let number = |tokens: &mut Tokens<'_>| tokens.next()?.text.parse::<usize>().ok();
    let fresh = || {
        let mut tokens = Tokens::new(text);
        // The header and title lines are free text.
        tokens.raw_line()?;
        tokens.raw_line()?;
        Some(tokens)
    };
    // Which cell is the t-th tetrahedron.
    let mut tokens = fresh()?;
    keyword(&mut tokens, "CELL_TYPES")?;
    let n = number(&mut tokens)?;
    let mut tets = 0;
    let mut cell = None;
    for c in 0..n {
        if number(&mut tokens)? == 10 {
            if tets == t {
                cell = Some(c);
                break;
            }
            tets += 1;
        }
    }
    let cell = cell?;
    let mut tokens = fresh()?;
    keyword(&mut tokens, "CELLS")?;
    number(&mut tokens)?;
    number(&mut tokens)?;
    if tokens
        .peek()
        .is_some_and(|tok| tok.text.eq_ignore_ascii_case("OFFSETS"))
    {
        tokens.next()?;
        tokens.next()?; // data type
        let mut start = 0;
        for _ in 0..=cell {
            start = number(&mut tokens)?;
        }
        keyword(&mut tokens, "CONNECTIVITY")?;
        tokens.next()?; // data type
        for _ in 0..start {
            tokens.next()?;
        }
        return tokens.next().map(|tok| tok.line);
    }
    for _ in 0..cell {
        let k = number(&mut tokens)?;
        for _ in 0..k {
            tokens.next()?;
        }
    }
    tokens.next().map(|tok| tok.line)
}

#[derive(Debug, Clone, Copy)]
struct Token<'a> {
    text: &'a str,
    line: usize,
}

/// Whitespace-separated tokens with their 1-based line numbers.
#[derive(Debug)]
struct Tokens<'a> {
    lines: std::str::Lines<'a>,
    current: std::str::SplitWhitespace<'a>,
    line: usize,
    peeked: Option<Token<'a>>,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str) -> Self {
        Self {
            lines: text.lines(),
            current: "".split_whitespace(),
            line: 0,
            peeked: None,
        }
    }

    /// A whole raw line (only used for the two header lines, before any token is read).
    fn raw_line(&mut self) -> Option<(usize, &'a str)> {
        let line = self.lines.next()?;
        self.line += 1;
        Some((self.line, line))
    }

    fn next(&mut self) -> Option<Token<'a>> {
        if let Some(t) = self.peeked.take() {
            return Some(t);
        }
        loop {
            if let Some(text) = self.current.next() {
                return Some(Token {
                    text,
                    line: self.line,
                });
            }
            self.current = self.lines.next()?.split_whitespace();
            self.line += 1;
        }
    }

    fn peek(&mut self) -> Option<Token<'a>> {
        if self.peeked.is_none() {
            self.peeked = self.next();
        }
        self.peeked
    }
}

/// Keywords that start a top-level block of an unstructured grid.
const BLOCKS: [&str; 7] = [
    "POINTS",
    "CELLS",
    "CELL_TYPES",
    "POINT_DATA",
    "CELL_DATA",
    "FIELD",
    "METADATA",
];

fn is_block(token: &str) -> bool {
    BLOCKS.iter().any(|b| b.eq_ignore_ascii_case(token))
}

/// At most 40 characters of `s`, for quoting input in messages.
fn snippet(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if s.chars().nth(40).is_some() {
        out.push('…');
    }
    out
}

#[derive(Debug)]
struct Parser<'a> {
    tokens: Tokens<'a>,
    path: &'a Path,
    text_len: usize,
}

impl<'a> Parser<'a> {
    fn error(&self, line: usize, reason: impl Into<String>) -> MeshError {
        MeshError::Parse {
            path: self.path.to_path_buf(),
            line,
            reason: reason.into(),
        }
    }

    fn expect(&mut self, what: &dyn Fn() -> String) -> Result<Token<'a>, MeshError> {
        match self.tokens.next() {
            Some(t) => Ok(t),
            None => Err(self.error(
                self.tokens.line.max(1),
                format!(
                    "unexpected end of file: expected {} (truncated file?)",
                    what()
                ),
            )),
        }
    }

    fn read_u64(&mut self, what: &dyn Fn() -> String) -> Result<(u64, usize), MeshError> {
        let t = self.expect(what)?;
        t.text.parse::<u64>().map(|v| (v, t.line)).map_err(|_| {
            self.error(
                t.line,
                format!(
                    "expected {} (a non-negative integer), found '{}'",
                    what(),
                    snippet(t.text)
                ),
            )
        })
    }

    fn read_count(&mut self, what: &str, limit: usize) -> Result<usize, MeshError> {
        let (n, line) = self.read_u64(&|| what.to_string())?;
        usize::try_from(n)
            .ok()
            .filter(|&n| n <= limit)
            .ok_or_else(|| {
                self.error(
                    line,
                    format!("{what} is {n}, more than the limit of {limit}"),
                )
            })
    }

    /// A 0-based point index, checked against the number of points.
    fn read_index(
        &mut self,
        num_points: usize,
        what: &dyn Fn() -> String,
    ) -> Result<usize, MeshError> {
        let (i, line) = self.read_u64(what)?;
        usize::try_from(i)
            .ok()
            .filter(|&i| i < num_points)
            .ok_or_else(|| {
                self.error(
                    line,
                    format!(
                        "{} is {i}, but there are only {num_points} points (indices are 0-based)",
                        what()
                    ),
                )
            })
    }

    fn expect_keyword(&mut self, keyword: &str, context: &str) -> Result<Token<'a>, MeshError> {
        let t = self.expect(&|| format!("{keyword} {context}"))?;
        if t.text.eq_ignore_ascii_case(keyword) {
            Ok(t)
        } else {
            Err(self.error(
                t.line,
                format!("expected {keyword} {context}, found '{}'", snippet(t.text)),
            ))
        }
    }

    /// The data-type word after POINTS, OFFSETS or CONNECTIVITY (`double`, `vtktypeint64`, …).
    fn read_data_type(&mut self, block: &str) -> Result<(), MeshError> {
        let t = self.expect(&|| format!("the data type of {block}"))?;
        if t.text.starts_with(|c: char| c.is_ascii_alphabetic()) && !is_block(t.text) {
            Ok(())
        } else {
            Err(self.error(
                t.line,
                format!(
                    "expected the data type of {block} (float, double, vtktypeint64, …), found '{}'",
                    snippet(t.text)
                ),
            ))
        }
    }

    fn run(mut self) -> Result<TetMesh, MeshError> {
        self.read_header()?;
        let mut points: Option<Vec<Vec3>> = None;
        // Per cell: its points if it has exactly four (the only cells that can be tetrahedra).
        let mut cells: Option<Vec<Option<[usize; 4]>>> = None;
        let mut tets: Option<Vec<[usize; 4]>> = None;
        while let Some(tok) = self.tokens.next() {
            let keyword = tok.text.to_ascii_uppercase();
            match keyword.as_str() {
                "POINTS" => {
                    if points.is_some() {
                        return Err(self.error(tok.line, "a second POINTS block"));
                    }
                    points = Some(self.read_points()?);
                }
                "CELLS" => {
                    let Some(num_points) = points.as_ref().map(Vec::len) else {
                        return Err(self.error(tok.line, "CELLS comes before POINTS"));
                    };
                    if cells.is_some() {
                        return Err(self.error(tok.line, "a second CELLS block"));
                    }
                    cells = Some(self.read_cells(num_points)?);
                }
                "CELL_TYPES" => {
                    let Some(cells) = cells.as_ref() else {
                        return Err(self.error(tok.line, "CELL_TYPES comes before CELLS"));
                    };
                    if tets.is_some() {
                        return Err(self.error(tok.line, "a second CELL_TYPES block"));
                    }
                    tets = Some(self.read_cell_types(cells, tok.line)?);
                }
                // Attribute data follows; the mesh is complete.
                "POINT_DATA" | "CELL_DATA" => break,
                "FIELD" | "METADATA" => {
                    while self.tokens.peek().is_some_and(|t| !is_block(t.text)) {
                        self.tokens.next();
                    }
                }
                _ => {
                    return Err(self.error(
                        tok.line,
                        format!(
                            "expected POINTS, CELLS, CELL_TYPES, POINT_DATA or CELL_DATA, found '{}'",
                            snippet(tok.text)
                        ),
                    ));
                }
            }
        }
        let last = self.tokens.line.max(1);
        let vertices = points.ok_or_else(|| self.error(last, "no POINTS block"))?;
        if cells.is_none() {
            return Err(self.error(last, "no CELLS block"));
        }
        let tets = tets.ok_or_else(|| self.error(last, "no CELL_TYPES block"))?;
        Ok(TetMesh { vertices, tets })
    }

    fn read_header(&mut self) -> Result<(), MeshError> {
        let Some((line, first)) = self.tokens.raw_line() else {
            return Err(self.error(1, "empty file: expected '# vtk DataFile Version x.y'"));
        };
        let first = first.trim();
        let is_vtk = first
            .get(..first.len().min(14))
            .is_some_and(|p| p.eq_ignore_ascii_case("# vtk DataFile"));
        if !is_vtk {
            return Err(self.error(
                line,
                format!(
                    "expected '# vtk DataFile Version x.y' on the first line, found '{}'",
                    snippet(first)
                ),
            ));
        }
        if self.tokens.raw_line().is_none() {
            return Err(self.error(line, "unexpected end of file: expected the title line"));
        }
        let t = self.expect(&|| "ASCII or BINARY".into())?;
        if t.text.eq_ignore_ascii_case("BINARY") {
            return Err(self.error(
                t.line,
                "a binary legacy VTK file is read from its bytes (`parse_bytes`, `read_mesh`), \
                 not as text",
            ));
        }
        if !t.text.eq_ignore_ascii_case("ASCII") {
            return Err(self.error(
                t.line,
                format!("expected ASCII or BINARY, found '{}'", snippet(t.text)),
            ));
        }
        self.expect_keyword("DATASET", "after ASCII")?;
        let t = self.expect(&|| "the dataset type".into())?;
        if !t.text.eq_ignore_ascii_case("UNSTRUCTURED_GRID") {
            return Err(self.error(
                t.line,
                format!(
                    "only DATASET UNSTRUCTURED_GRID is supported, found '{}'",
                    snippet(t.text)
                ),
            ));
        }
        Ok(())
    }

    fn read_points(&mut self) -> Result<Vec<Vec3>, MeshError> {
        let n = self.read_count("the number of POINTS", MAX_ENTITIES)?;
        self.read_data_type("POINTS")?;
        // A header may lie about its count: never reserve more than the text could hold.
        let mut points = Vec::with_capacity(n.min(self.text_len / 6));
        for k in 0..n {
            let mut x = [0.0f64; 3];
            for (axis, slot) in ["x", "y", "z"].iter().zip(&mut x) {
                let what = || format!("the {axis} coordinate of point {k} of {n}");
                let t = self.expect(&what)?;
                *slot = t.text.parse().map_err(|_| {
                    self.error(
                        t.line,
                        format!(
                            "expected {} (a number), found '{}'",
                            what(),
                            snippet(t.text)
                        ),
                    )
                })?;
                if !slot.is_finite() {
                    return Err(self.error(
                        t.line,
                        format!("{} is not finite ('{}')", what(), snippet(t.text)),
                    ));
                }
            }
            points.push(Vec3::new(x[0], x[1], x[2]));
        }
        Ok(points)
    }

    fn read_cells(&mut self, num_points: usize) -> Result<Vec<Option<[usize; 4]>>, MeshError> {
        let n = self.read_count("the number of CELLS", MAX_ENTITIES)?;
        let size_limit = MAX_ENTITIES.saturating_mul(16);
        let size = self.read_count("the size of the CELLS list", size_limit)?;
        if self
            .tokens
            .peek()
            .is_some_and(|t| t.text.eq_ignore_ascii_case("OFFSETS"))
        {
            return self.read_offsets_connectivity(n, size, num_points);
        }
        let mut cells = Vec::with_capacity(n.min(self.text_len / 8));
        let mut used = 0usize;
        for c in 0..n {
            let what = || format!("the number of points of cell {c} of {n}");
            let (k, line) = self.read_u64(&what)?;
            let k = usize::try_from(k).unwrap_or(usize::MAX);
            used = used
                .checked_add(k)
                .and_then(|u| u.checked_add(1))
                .filter(|&u| u <= size)
                .ok_or_else(|| {
                    self.error(
                        line,
                        format!(
                            "cell {c} has {k} points, which overruns the CELLS size of {size} values"
                        ),
                    )
                })?;
            let mut tet = [0usize; 4];
            for j in 0..k {
                let i = self.read_index(num_points, &|| format!("point {j} of cell {c}"))?;
                if let Some(slot) = tet.get_mut(j) {
                    *slot = i;
                }
            }
            cells.push((k == 4).then_some(tet));
        }
        if used != size {
            return Err(self.error(
                self.tokens.line.max(1),
                format!("CELLS declares a size of {size} values, but its {n} cells hold {used}"),
            ));
        }
        Ok(cells)
    }

    /// The VTK 5.1 layout: `OFFSETS` (n_offsets values) then `CONNECTIVITY` (size values).
    fn read_offsets_connectivity(
        &mut self,
        num_offsets: usize,
        size: usize,
        num_points: usize,
    ) -> Result<Vec<Option<[usize; 4]>>, MeshError> {
        self.expect_keyword("OFFSETS", "after CELLS")?;
        self.read_data_type("OFFSETS")?;
        let mut offsets = Vec::with_capacity(num_offsets.min(self.text_len / 2));
        let mut previous = 0usize;
        for k in 0..num_offsets {
            let what = || format!("offset {k} of {num_offsets}");
            let (o, line) = self.read_u64(&what)?;
            let o = usize::try_from(o).unwrap_or(usize::MAX);
            let valid = if k == 0 {
                o == 0
            } else {
                o >= previous && o <= size
            };
            if !valid {
                return Err(self.error(
                    line,
                    format!(
                        "{} is {o}: offsets must start at 0, not decrease and not exceed the connectivity size {size}",
                        what()
                    ),
                ));
            }
            offsets.push(o);
            previous = o;
        }
        if num_offsets > 0 && previous != size {
            return Err(self.error(
                self.tokens.line.max(1),
                format!("the last offset is {previous}, but the connectivity holds {size} values"),
            ));
        }
        self.expect_keyword("CONNECTIVITY", "after the offsets")?;
        self.read_data_type("CONNECTIVITY")?;
        let mut connectivity = Vec::with_capacity(size.min(self.text_len / 2));
        for k in 0..size {
            connectivity.push(
                self.read_index(num_points, &|| format!("connectivity value {k} of {size}"))?,
            );
        }
        Ok(offsets
            .windows(2)
            .map(|w| {
                connectivity
                    .get(w[0]..w[1])
                    .and_then(|ids| <[usize; 4]>::try_from(ids).ok())
            })
            .collect())
    }

    fn read_cell_types(
        &mut self,
        cells: &[Option<[usize; 4]>],
        line: usize,
    ) -> Result<Vec<[usize; 4]>, MeshError> {
        let n = self.read_count("the number of CELL_TYPES", MAX_ENTITIES)?;
        if n != cells.len() {
            return Err(self.error(
                line,
                format!(
                    "CELL_TYPES lists {n} types, but CELLS has {} cells",
                    cells.len()
                ),
            ));
        }
        let mut tets = Vec::with_capacity(cells.iter().flatten().count());
        let mut ignored: std::collections::BTreeMap<u64, usize> = Default::default();
        for (c, cell) in cells.iter().enumerate() {
            let (t, line) = self.read_u64(&|| format!("the type of cell {c} of {n}"))?;
            if t != VTK_TETRA {
                *ignored.entry(t).or_default() += 1;
                continue;
            }
            let tet = cell.ok_or_else(|| {
                self.error(
                    line,
                    format!("cell {c} has type 10 (tetrahedron) but does not have 4 points"),
                )
            })?;
            tets.push(tet);
        }
        if let Some(problem) = cells_problem(&ignored, tets.len(), n) {
            return Err(self.error(line, problem));
        }
        let summary = said(&ignored, |_| true);
        if !summary.is_empty() {
            tracing::debug!(
                "{}: ignored non-tetrahedral cells: {summary}",
                self.path.display()
            );
        }
        Ok(tets)
    }
}

/// The cells of `ignored` (type → count) whose type `keep` takes, said as "560 of type 12,
/// hexahedron; 3 of type 5, triangle".
fn said(ignored: &std::collections::BTreeMap<u64, usize>, keep: impl Fn(u64) -> bool) -> String {
    ignored
        .iter()
        .filter(|(t, _)| keep(**t))
        .map(|(&t, k)| match cell_name(t) {
            Some(name) => format!("{k} of type {t}, {name}"),
            None => format!("{k} of type {t}"),
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// What is wrong with a file's `cells` cells, `tets` of them linear tetrahedra and `ignored`
/// the others (type → count): no tetrahedron at all (what it holds, and what to do), or other
/// volume cells beside them (voxels, hexahedra, wedges, pyramids, pentagonal and hexagonal
/// prisms, polyhedra, and the quadratic, bi- and triquadratic, Lagrange and Bézier volume
/// cells), which read alone the body would lose. None where the tetrahedra are the body.
pub(super) fn cells_problem(
    ignored: &std::collections::BTreeMap<u64, usize>,
    tets: usize,
    cells: usize,
) -> Option<String> {
    if tets == 0 {
        let summary = said(ignored, |_| true);
        let types: Vec<u64> = ignored.keys().copied().collect();
        return Some(format!(
            "no tetrahedra (VTK cell type 10) among the {cells} cells{}{}",
            if summary.is_empty() {
                String::new()
            } else {
                format!(" ({summary})")
            },
            missing_tets_remedy(&types)
        ));
    }
    let others = said(
        ignored,
        |t| matches!(t, 11..=17 | 24..=27 | 29 | 31..=33 | 42 | 71..=74 | 78..=82),
    );
    (!others.is_empty()).then(|| super::other_volumes_problem(&others, tets))
}

/// The name of a VTK cell type that a file without tetrahedra most often holds instead.
fn cell_name(t: u64) -> Option<&'static str> {
    Some(match t {
        1 => "vertex",
        3 => "line",
        5 => "triangle",
        7 => "polygon",
        9 => "quad",
        12 => "hexahedron",
        13 => "wedge",
        14 => "pyramid",
        22 => "quadratic triangle",
        24 => "quadratic tetrahedron",
        71 => "Lagrange tetrahedron",
        _ => return None,
    })
}

/// What to do about a file whose cells hold no linear tetrahedron, by what it holds.
fn missing_tets_remedy(types: &[u64]) -> &'static str {
    const LOWER_DIMENSIONS: [u64; 9] = [1, 2, 3, 4, 5, 6, 7, 8, 9];
    if types.contains(&24) || types.contains(&71) {
        "; quadratic and Lagrange tetrahedra are not read: export first-order (4-point) tetrahedra, e.g. \
         mesh with `-order 1` in gmsh"
    } else if !types.is_empty() && types.iter().all(|t| LOWER_DIMENSIONS.contains(t)) {
        "; that is a surface mesh, and a tetrahedral volume mesh is needed (TetGen `tetgen -pq \
         part.stl`, `gmsh -3`, or fTetWild)"
    } else {
        "; a tetrahedral volume mesh is needed"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two cells: a tetrahedron and a triangle, with attribute data after.
    const LEGACY: &str = "# vtk DataFile Version 4.2\nsome title\nASCII\nDATASET UNSTRUCTURED_GRID\n\
        POINTS 5 double\n0 0 0 1 0 0\n0 1 0\n0 0 1 9 9 9\n\
        CELLS 2 9\n4 0 1 2 3\n3 0 1 4\n\
        CELL_TYPES 2\n10\n5\n\
        POINT_DATA 5\nSCALARS s double 1\nLOOKUP_TABLE default\n1 2 3 4 5\n";

    const V51: &str = "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET UNSTRUCTURED_GRID\n\
        FIELD FieldData 1\nTIME 1 1 double\n0.5\n\
        POINTS 5 float\n0 0 0 1 0 0 0 1 0\n0 0 1 9 9 9\n\
        METADATA\nINFORMATION 0\n\n\
        CELLS 3 7\nOFFSETS vtktypeint64\n0 3 7\nCONNECTIVITY vtktypeint64\n0 1 4\n0 1 2 3\n\
        CELL_TYPES 2\n5\n10\n\
        CELL_DATA 2\nFIELD FieldData 1\nid 1 2 int\n7 8\n";

    fn parse_str(text: &str) -> Result<TetMesh, MeshError> {
        parse(text, Path::new("test.vtk"))
    }

    /// The line and reason of a parse error (panics on anything else, which fails the test).
    fn parse_error(text: &str) -> (usize, String) {
        match parse_str(text) {
            Err(MeshError::Parse { line, reason, .. }) => (line, reason),
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    /// `LEGACY` and `V51` as `BINARY` files: every array big-endian after its header line (a
    /// cell type 10 holds a newline byte), attribute data after the cells.
    fn binary_files() -> [Vec<u8>; 2] {
        fn be<T: Copy>(values: &[T], bytes: impl Fn(T) -> Vec<u8>) -> Vec<u8> {
            let mut out: Vec<u8> = values.iter().flat_map(|&v| bytes(v)).collect();
            out.push(b'\n');
            out
        }
        let f64s = |v: &[f64]| be(v, |x| x.to_be_bytes().to_vec());
        let f32s = |v: &[f32]| be(v, |x| x.to_be_bytes().to_vec());
        let i32s = |v: &[i32]| be(v, |x| x.to_be_bytes().to_vec());
        let i64s = |v: &[i64]| be(v, |x| x.to_be_bytes().to_vec());
        let points = [0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1., 9., 9., 9.];
        let text = |t: &str| t.as_bytes().to_vec();
        let legacy = [
            text("# vtk DataFile Version 4.2\nsome title\nBINARY\nDATASET UNSTRUCTURED_GRID\n"),
            text("POINTS 5 double\n"),
            f64s(&points),
            text("CELLS 2 9\n"),
            i32s(&[4, 0, 1, 2, 3, 3, 0, 1, 4]),
            text("CELL_TYPES 2\n"),
            i32s(&[10, 5]),
            text("POINT_DATA 5\nSCALARS s double 1\nLOOKUP_TABLE default\n"),
            f64s(&[1., 2., 3., 4., 5.]),
        ]
        .concat();
        let points: Vec<f32> = points.iter().map(|&x| x as f32).collect();
        let v51 = [
            text("# vtk DataFile Version 5.1\nvtk output\nBINARY\nDATASET UNSTRUCTURED_GRID\n"),
            text("FIELD FieldData 1\nTIME 1 1 double\n"),
            f64s(&[0.5]),
            text("POINTS 5 float\n"),
            f32s(&points),
            text("METADATA\nINFORMATION 0\n\n"),
            text("CELLS 3 7\nOFFSETS vtktypeint64\n"),
            i64s(&[0, 3, 7]),
            text("CONNECTIVITY vtktypeint64\n"),
            i64s(&[0, 1, 4, 0, 1, 2, 3]),
            text("CELL_TYPES 2\n"),
            i32s(&[5, 10]),
            text("CELL_DATA 2\nFIELD FieldData 1\nid 1 2 int\n"),
            i32s(&[7, 8]),
        ]
        .concat();
        [legacy, v51]
    }

    /// A `BINARY` file reads as the ASCII file it stands for, in both cell layouts.
    #[test]
    fn binary_files_read_as_their_ascii_twins() {
        let [legacy, v51] = binary_files();
        let path = Path::new("b.vtk");
        for (bytes, ascii) in [(legacy, LEGACY), (v51, V51)] {
            assert!(is_binary(&bytes));
            let mesh = parse_bytes(&bytes, path).unwrap();
            let twin = parse_str(ascii).unwrap();
            assert_eq!(mesh.vertices, twin.vertices);
            assert_eq!(mesh.tets, twin.tets);
        }
        // Negative indices are said as they are, not as huge unsigned ones.
        let [legacy, _] = binary_files();
        let at = legacy
            .windows(8)
            .position(|w| w == [0, 0, 0, 4, 0, 0, 0, 0])
            .unwrap();
        let mut bad = legacy.clone();
        bad[at + 4..at + 8].copy_from_slice(&(-2i32).to_be_bytes());
        match parse_bytes(&bad, path) {
            Err(MeshError::Parse { reason, .. }) => assert!(reason.contains("'-2'"), "{reason}"),
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    /// Hexahedra or wedges beside the tetrahedra are refused: read alone, the tetrahedra would
    /// be the body without them.
    #[test]
    fn other_volume_cells_beside_tetrahedra_are_refused() {
        let hexed = LEGACY
            .replace(
                "CELLS 2 9\n4 0 1 2 3\n3 0 1 4",
                "CELLS 2 14\n4 0 1 2 3\n8 0 1 2 3 4 0 1 2",
            )
            .replace("CELL_TYPES 2\n10\n5", "CELL_TYPES 2\n10\n12");
        let (_, reason) = parse_error(&hexed);
        assert!(
            reason.contains("1 of type 12, hexahedron beside its 1 tetrahedra")
                && reason.contains("tetrahedra only"),
            "{reason}"
        );
    }

    /// A binary file cut short or holding an unknown data type is an error saying so.
    #[test]
    fn broken_binary_files_say_what_is_wrong() {
        let [legacy, v51] = binary_files();
        let path = Path::new("b.vtk");
        let reason = |bytes: &[u8]| match parse_bytes(bytes, path) {
            Err(MeshError::Parse { reason, .. }) => reason,
            other => panic!("expected a parse error, got {other:?}"),
        };
        let cut = legacy.windows(6).position(|w| w == b"POINTS").unwrap() + 40;
        assert!(
            reason(&legacy[..cut]).contains("truncated"),
            "{}",
            reason(&legacy[..cut])
        );
        let bytes: Vec<u8> = v51
            .windows(14)
            .position(|w| w == b"POINTS 5 float")
            .map(|at| [&v51[..at], b"POINTS 5 quads", &v51[at + 14..]].concat())
            .unwrap();
        assert!(
            reason(&bytes).contains("found 'quads'"),
            "{}",
            reason(&bytes)
        );
    }

    #[test]
    fn reads_legacy_cells_keeping_only_tetrahedra() {
        let mesh = parse_str(LEGACY).unwrap();
        assert_eq!(mesh.vertices.len(), 5);
        assert_eq!(mesh.vertices[3], Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3]]);
    }

    /// A file without linear tetrahedra names what it holds and what to do: a quadratic
    /// tetrahedron asks for first order, triangles alone for a volume mesh.
    #[test]
    fn a_file_without_tetrahedra_says_what_it_holds_and_what_to_do() {
        let quadratic = LEGACY.replace("CELL_TYPES 2\n10\n5", "CELL_TYPES 2\n24\n5");
        let (_, reason) = parse_error(&quadratic);
        assert!(
            reason.contains("(1 of type 5, triangle; 1 of type 24, quadratic tetrahedron)"),
            "{reason}"
        );
        assert!(
            reason.contains("quadratic and Lagrange tetrahedra are not read"),
            "{reason}"
        );
        let surface = LEGACY.replace("CELL_TYPES 2\n10\n5", "CELL_TYPES 2\n9\n5");
        let (_, reason) = parse_error(&surface);
        assert!(reason.contains("that is a surface mesh"), "{reason}");
    }

    #[test]
    fn reads_the_5_1_offsets_connectivity_layout() {
        let mesh = parse_str(V51).unwrap();
        assert_eq!(mesh, parse_str(LEGACY).unwrap());
    }

    #[test]
    fn counts_on_the_next_line_and_crlf_are_fine() {
        let text = LEGACY
            .replace("POINTS 5 double", "POINTS\n5\ndouble")
            .replace('\n', "\r\n");
        assert_eq!(parse_str(&text).unwrap(), parse_str(LEGACY).unwrap());
    }

    #[test]
    fn truncated_files_are_errors() {
        let cut = &LEGACY[..LEGACY.find("CELL_TYPES").unwrap()];
        assert!(parse_error(cut).1.contains("CELL_TYPES"));
        let (line, reason) = parse_error(&LEGACY[..LEGACY.find("3 0 1 4").unwrap() + 4]);
        assert_eq!(line, 11);
        assert!(reason.contains("end of file"), "{reason}");
        for text in [LEGACY, V51] {
            for end in 0..text.len() {
                if let Ok(mesh) = parse_str(&text[..end]) {
                    assert_eq!(mesh.tets, vec![[0, 1, 2, 3]], "prefix of {end} bytes");
                }
            }
        }
    }

    #[test]
    fn bad_indices_and_sizes_are_reported_with_their_line() {
        let (line, reason) = parse_error(&LEGACY.replace("4 0 1 2 3", "4 0 1 2 5"));
        assert_eq!(line, 10);
        assert!(reason.contains("only 5 points"), "{reason}");
        let (_, reason) = parse_error(&LEGACY.replace("4 0 1 2 3", "4 0 1 -2 3"));
        assert!(reason.contains("'-2'"), "{reason}");
        let (_, reason) = parse_error(&LEGACY.replace("CELLS 2 9", "CELLS 2 8"));
        assert!(reason.contains("overruns"), "{reason}");
        let (_, reason) = parse_error(&LEGACY.replace("CELLS 2 9", "CELLS 2 10"));
        assert!(reason.contains("hold 9"), "{reason}");
        let (_, reason) =
            parse_error(&LEGACY.replace("CELL_TYPES 2\n10\n5", "CELL_TYPES 2\n5\n10"));
        assert!(reason.contains("does not have 4 points"), "{reason}");
        let (_, reason) = parse_error(&V51.replace("0 3 7", "0 3 8"));
        assert!(reason.contains("connectivity"), "{reason}");
        let (_, reason) = parse_error(&V51.replace("0 3 7", "0 3 2"));
        assert!(reason.contains("offset 2"), "{reason}");
        let (line, reason) = parse_error(&V51.replace("0 1 2 3", "0 1 2 7"));
        assert_eq!(line, 19);
        assert!(reason.contains("only 5 points"), "{reason}");
        let (_, reason) = parse_error(&LEGACY.replace("CELL_TYPES 2", "CELL_TYPES 3"));
        assert!(reason.contains("CELLS has 2"), "{reason}");
    }

    #[test]
    fn non_finite_coordinates_are_rejected() {
        for bad in ["nan", "inf", "-1e400", "x"] {
            let (line, reason) = parse_error(&LEGACY.replace("0 1 0\n", &format!("0 {bad} 0\n")));
            assert_eq!(line, 7, "{reason}");
            assert!(reason.contains("y coordinate of point 2"), "{reason}");
        }
    }

    #[test]
    fn huge_counts_fail_fast() {
        let (line, reason) = parse_error(&LEGACY.replace("POINTS 5", "POINTS 1000000000000"));
        assert_eq!(line, 5);
        assert!(reason.contains("limit"), "{reason}");
        let text = LEGACY.replace("POINTS 5", &format!("POINTS {MAX_ENTITIES}"));
        assert!(parse_error(&text).1.contains("found 'CELLS'"));
        assert!(
            parse_error(&LEGACY.replace("CELLS 2 9", "CELLS 2 99999999999999"))
                .1
                .contains("limit")
        );
        assert!(
            parse_error(&LEGACY.replace("3 0 1 4", "18446744073709551615 0 1 4"))
                .1
                .contains("overruns")
        );
    }

    #[test]
    fn unsupported_variants_are_rejected_clearly() {
        assert!(
            parse_error(&LEGACY.replace("ASCII", "BINARY"))
                .1
                .contains("binary")
        );
        assert!(
            parse_error(&LEGACY.replace("UNSTRUCTURED_GRID", "POLYDATA"))
                .1
                .contains("POLYDATA")
        );
        assert!(parse_error("hello\n").1.contains("# vtk DataFile"));
        assert!(parse_error("").1.contains("empty"));
        let (_, reason) =
            parse_error(&LEGACY.replace("CELL_TYPES 2\n10\n5", "CELL_TYPES 2\n12\n5"));
        assert!(reason.contains("1 of type 12"), "{reason}");
        assert!(
            parse_error(&LEGACY.replace("CELLS", "LINES"))
                .1
                .contains("LINES")
        );
        let points_after = LEGACY.replace("POINTS 5 double", "CELLS 0 0\nPOINTS 5 double");
        assert!(parse_error(&points_after).1.contains("before POINTS"));
    }

    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        fn mutate(base: &str, edits: &[(usize, char)]) -> String {
            let mut chars: Vec<char> = base.chars().collect();
            let len = chars.len();
            for &(pos, c) in edits {
                if let Some(slot) = chars.get_mut(pos % len) {
                    *slot = c;
                }
            }
            chars.into_iter().collect()
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            #[test]
            fn arbitrary_text_never_panics(text in "\\PC{0,200}") {
                let _ = parse_str(&text);
                let _ = parse_str(&format!("# vtk DataFile Version 4.2\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n{text}"));
            }

            #[test]
            fn mutated_valid_files_never_panic(
                edits in prop::collection::vec((any::<usize>(), any::<char>()), 1..6),
                digits in prop::collection::vec((any::<usize>(), prop::char::range('0', '9')), 1..4),
            ) {
                for base in [LEGACY, V51] {
                    let _ = parse_str(&mutate(base, &edits));
                    if let Ok(mesh) = parse_str(&mutate(base, &digits)) {
                        prop_assert!(mesh.tets.iter().flatten().all(|&i| i < mesh.vertices.len()));
                    }
                }
            }

            /// Binary files cut anywhere or with any bytes changed are read or refused, never a
            /// panic, and what is read indexes its own points.
            #[test]
            fn mutated_binary_files_never_panic(
                cut in any::<usize>(),
                edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..6),
            ) {
                for mut bytes in binary_files() {
                    let _ = parse_bytes(&bytes[..cut % (bytes.len() + 1)], Path::new("b.vtk"));
                    let n = bytes.len();
                    for &(at, b) in &edits {
                        bytes[at % n] = b;
                    }
                    if let Ok(mesh) = parse_bytes(&bytes, Path::new("b.vtk")) {
                        prop_assert!(mesh.tets.iter().flatten().all(|&i| i < mesh.vertices.len()));
                    }
                }
            }
        }
    }
}
