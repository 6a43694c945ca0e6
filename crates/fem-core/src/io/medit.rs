//! MEDIT `.mesh` reader (ASCII), the format written by MEDIT/mmg, TetGen, Gmsh, meshio and GAUSS.
//!
//! The file is read as a stream of whitespace-separated tokens, so a count may sit on its
//! keyword's line or on the next one and entries may wrap lines. Supported:
//! - keywords in any letter case; `#` starts a comment that runs to the end of the line;
//! - `MeshVersionFormatted` 1–4 (ASCII only: the version only matters for binary `.meshb`);
//! - `Dimension` (must be 3; assumed 3 when absent);
//! - `Vertices` (`x y z ref`) and `Tetrahedra` (`i j k l ref`, 1-based), the only sections kept;
//! - every other section is skipped: known ones (`Edges`, `Triangles`, `Quadrilaterals`,
//!   `Hexahedra`, `Prisms`, `Corners`, `Ridges`, `Required*`, `Normals`, …) by their count and
//!   entry width, unknown ones up to the next keyword;
//! - `End` is optional, as is the final newline.
//!
//! Binary `.meshb` files are not supported. Indices are converted to 0-based. Reading stops at
//! the first problem with a [`MeshError::Parse`] naming the line; the mesh is not validated here
//! (see [`crate::io::read_mesh`]).

use std::path::Path;

use super::MAX_ENTITIES;
use crate::{MeshError, TetMesh, Vec3};

/// Reads the MEDIT `.mesh` file at `path` (not validated).
pub fn read(path: &Path) -> Result<TetMesh, MeshError> {
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&String::from_utf8_lossy(&bytes), path)
}

/// Parses the text of a MEDIT `.mesh` file; `path` only names the source in errors.
pub fn parse(text: &str, path: &Path) -> Result<TetMesh, MeshError> {
    Parser::new(text, path).run()
}

/// 1-based line of tetrahedron `t` (0-based, counted over every `Tetrahedra` section) in a file
/// that [`parse`] read, for messages about a tet that validation refuses.
pub(crate) fn tet_line(text: &str, t: usize) -> Option<usize> {
    let mut tokens = Tokens::new(text);
    let mut seen = 0usize;
    while let Some(tok) = tokens.next() {
        if !tok.text.eq_ignore_ascii_case("tetrahedra") {
            continue;
        }
        let n: usize = tokens.next()?.text.parse().ok()?;
        let skip = if t < seen + n { t - seen } else { n };
        for _ in 0..skip.checked_mul(5)? {
            tokens.next()?;
        }
        if t < seen + n {
            return tokens.next().map(|tok| tok.line);
        }
        seen += n;
    }
    None
}

/// A token and the 1-based line it came from.
#[derive(Debug, Clone, Copy)]
pub(super) struct Token<'a> {
    pub(super) text: &'a str,
    pub(super) line: usize,
}

/// Whitespace-separated tokens with `#` comments removed, tracking line numbers.
#[derive(Debug)]
pub(super) struct Tokens<'a> {
    lines: std::str::Lines<'a>,
    current: std::str::SplitWhitespace<'a>,
    line: usize,
    peeked: Option<Token<'a>>,
}

impl<'a> Tokens<'a> {
    pub(super) fn new(text: &'a str) -> Self {
        Self {
            lines: text.lines(),
            current: "".split_whitespace(),
            line: 0,
            peeked: None,
        }
    }

    pub(super) fn next(&mut self) -> Option<Token<'a>> {
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
            let line = self.lines.next()?;
            self.line += 1;
            let content = line.find('#').map_or(line, |i| &line[..i]);
            self.current = content.split_whitespace();
        }
    }

    fn peek(&mut self) -> Option<Token<'a>> {
        if self.peeked.is_none() {
            self.peeked = self.next();
        }
        self.peeked
    }

    /// Line of the last token read (for errors at end of file).
    fn last_line(&self) -> usize {
        self.line.max(1)
    }
}

/// Whether `token` starts a keyword (every number starts with a digit, a sign or a dot).
fn is_keyword(token: &str) -> bool {
    token.starts_with(|c: char| c.is_ascii_alphabetic())
}

/// Number of tokens per entry of the sections this reader skips by count (3D files).
fn entry_width(keyword: &str) -> Option<usize> {
    Some(match keyword {
        "corners"
        | "ridges"
        | "requiredvertices"
        | "requirededges"
        | "requiredtriangles"
        | "requiredquadrilaterals"
        | "requiredtetrahedra"
        | "requiredhexahedra" => 1,
        "normalatvertices" | "tangentatvertices" => 2,
        "edges" | "normals" | "tangents" | "normalattrianglevertices" | "tangentatedgevertices" => {
            3
        }
        "triangles" | "edgesp2" => 4,
        "quadrilaterals" => 5,
        "pyramids" => 6,
        "prisms" | "trianglesp2" => 7,
        "hexahedra" => 9,
        "tetrahedrap2" => 11,
        _ => return None,
    })
}

/// A token stream with the errors of a text mesh format: the file, the line and what was
/// expected (shared with the TetGen reader).
#[derive(Debug)]
pub(super) struct Parser<'a> {
    tokens: Tokens<'a>,
    path: &'a Path,
    text_len: usize,
}

impl<'a> Parser<'a> {
    pub(super) fn new(text: &'a str, path: &'a Path) -> Self {
        Self {
            tokens: Tokens::new(text),
            path,
            text_len: text.len(),
        }
    }

    pub(super) fn error(&self, line: usize, reason: impl Into<String>) -> MeshError {
        MeshError::Parse {
            path: self.path.to_path_buf(),
            line,
            reason: reason.into(),
        }
    }

    /// The next token, or an error saying what was expected at the end of the file.
    pub(super) fn expect(&mut self, what: &dyn Fn() -> String) -> Result<Token<'a>, MeshError> {
        match self.tokens.next() {
            Some(t) => Ok(t),
            None => Err(self.error(
                self.tokens.last_line(),
                format!(
                    "unexpected end of file: expected {} (truncated file?)",
                    what()
                ),
            )),
        }
    }

    pub(super) fn read_usize(
        &mut self,
        what: &dyn Fn() -> String,
    ) -> Result<(usize, usize), MeshError> {
        let t = self.expect(what)?;
        match t.text.parse::<usize>() {
            Ok(v) => Ok((v, t.line)),
            Err(_) => Err(self.error(
                t.line,
                format!(
                    "expected {} (a non-negative integer), found '{}'",
                    what(),
                    t.text
                ),
            )),
        }
    }

    fn read_count(&mut self, section: &str) -> Result<usize, MeshError> {
        self.read_at_most(
            &|| format!("the number of entries of {section}"),
            MAX_ENTITIES,
            &|n| format!("{section} declares {n} entries, more than the limit of {MAX_ENTITIES}"),
        )
    }

    /// A non-negative integer no larger than `limit`; `too_large(n)` says why a larger one is
    /// refused, at its line.
    pub(super) fn read_at_most(
        &mut self,
        what: &dyn Fn() -> String,
        limit: usize,
        too_large: &dyn Fn(usize) -> String,
    ) -> Result<usize, MeshError> {
        let (n, line) = self.read_usize(what)?;
        if n > limit {
            return Err(self.error(line, too_large(n)));
        }
        Ok(n)
    }

    pub(super) fn read_coordinate(&mut self, what: &dyn Fn() -> String) -> Result<f64, MeshError> {
        let t = self.expect(what)?;
        let value = parse_f64(t.text).ok_or_else(|| {
            self.error(
                t.line,
                format!("expected {} (a number), found '{}'", what(), t.text),
            )
        })?;
        if !value.is_finite() {
            return Err(self.error(t.line, format!("{} is not finite ('{}')", what(), t.text)));
        }
        Ok(value)
    }

    /// Reads an entry's reference (an integer label; some writers print it as a real).
    fn read_reference(&mut self, what: &dyn Fn() -> String) -> Result<(), MeshError> {
        let t = self.expect(what)?;
        if t.text.parse::<i64>().is_ok() || parse_f64(t.text).is_some_and(f64::is_finite) {
            Ok(())
        } else {
            Err(self.error(
                t.line,
                format!("expected {} (an integer), found '{}'", what(), t.text),
            ))
        }
    }

    fn run(mut self) -> Result<TetMesh, MeshError> {
        let mut vertices: Option<Vec<Vec3>> = None;
        let mut tets: Vec<[usize; 4]> = Vec::new();
        let mut saw_tetrahedra = false;
        // Volume elements beside the tetrahedra (`12 Hexahedra`), which would be left out.
        let mut other_volumes: Vec<String> = Vec::new();
        // Lines of tets read before the Vertices section, checked once the vertex count is known.
        let mut unchecked: Vec<(usize, usize)> = Vec::new();

        while let Some(tok) = self.tokens.next() {
            if !is_keyword(tok.text) {
                return Err(self.error(
                    tok.line,
                    format!(
                        "expected a keyword (Vertices, Tetrahedra, End, ...), found '{}'",
                        tok.text
                    ),
                ));
            }
            let keyword = tok.text.to_ascii_lowercase();
            match keyword.as_str() {
                "meshversionformatted" => {
                    let (v, line) = self.read_usize(&|| "the MeshVersionFormatted value".into())?;
                    if !(1..=4).contains(&v) {
                        return Err(self.error(
                            line,
                            format!("unsupported MeshVersionFormatted {v} (expected 1 to 4)"),
                        ));
                    }
                }
                "dimension" => {
                    let (d, line) = self.read_usize(&|| "the Dimension value".into())?;
                    if d != 3 {
                        return Err(self.error(
                            line,
                            format!("Dimension is {d}, but only 3D tetrahedral meshes are supported (expected 3)"),
                        ));
                    }
                }
                "vertices" => {
                    if vertices.is_some() {
                        return Err(self.error(tok.line, "a second Vertices section"));
                    }
                    vertices = Some(self.read_vertices()?);
                }
                "tetrahedra" => {
                    saw_tetrahedra = true;
                    let n = self.read_count("Tetrahedra")?;
                    if tets.len().saturating_add(n) > MAX_ENTITIES {
                        return Err(self.error(
                            tok.line,
                            format!("more than {MAX_ENTITIES} tetrahedra in total"),
                        ));
                    }
                    tets.reserve(n.min(self.text_len / 10));
                    let num_vertices = vertices.as_ref().map(Vec::len);
                    for k in 0..n {
                        let mut tet = [0usize; 4];
                        let mut first_line = 0;
                        for (c, slot) in tet.iter_mut().enumerate() {
                            let what =
                                || format!("vertex {} of tetrahedron {} of {n}", c + 1, k + 1);
                            let (i, line) = self.read_usize(&what)?;
                            if c == 0 {
                                first_line = line;
                            }
                            if i == 0 {
                                return Err(self.error(
                                    line,
                                    format!("{} is 0, but MEDIT indices start at 1", what()),
                                ));
                            }
                            if let Some(nv) = num_vertices
                                && i > nv
                            {
                                return Err(self.error(
                                    line,
                                    format!("{} is {i}, but there are only {nv} vertices", what()),
                                ));
                            }
                            *slot = i - 1;
                        }
                        self.read_reference(&|| format!("the reference of tetrahedron {}", k + 1))?;
                        if num_vertices.is_none() {
                            unchecked.push((tets.len(), first_line));
                        }
                        tets.push(tet);
                    }
                }
                "end" => break,
                other => {
                    let n = self.skip_section(other, tok)?;
                    if matches!(other, "hexahedra" | "prisms" | "pyramids") && n > 0 {
                        other_volumes.push(format!("{n} {}", tok.text));
                    }
                }
            }
        }

        let Some(vertices) = vertices else {
            return Err(self.error(
                self.tokens.last_line(),
                "no Vertices section found (is this a MEDIT .mesh file?)",
            ));
        };
        if !saw_tetrahedra {
            return Err(self.error(
                self.tokens.last_line(),
                "no Tetrahedra section found: a tetrahedral volume mesh is needed",
            ));
        }
        if !tets.is_empty() && !other_volumes.is_empty() {
            return Err(self.error(
                self.tokens.last_line(),
                super::other_volumes_problem(&other_volumes.join(", "), tets.len()),
            ));
        }
        for (t, line) in unchecked {
            if let Some(&i) = tets
                .get(t)
                .and_then(|tet| tet.iter().find(|&&i| i >= vertices.len()))
            {
                return Err(self.error(
                    line,
                    format!(
                        "tetrahedron {} uses vertex {}, but there are only {} vertices",
                        t + 1,
                        i + 1,
                        vertices.len()
                    ),
                ));
            }
        }
        Ok(TetMesh { vertices, tets })
    }

    fn read_vertices(&mut self) -> Result<Vec<Vec3>, MeshError> {
        let n = self.read_count("Vertices")?;
        // A header may lie about its count: never reserve more than the text could hold.
        let mut vertices = Vec::with_capacity(n.min(self.text_len / 8));
        for k in 0..n {
            let mut x = [0.0; 3];
            for (c, slot) in x.iter_mut().enumerate() {
                *slot = self.read_coordinate(&|| {
                    format!(
                        "coordinate {} of vertex {} of {n}",
                        ["x", "y", "z"][c],
                        k + 1
                    )
                })?;
            }
            self.read_reference(&|| format!("the reference of vertex {}", k + 1))?;
            vertices.push(Vec3::new(x[0], x[1], x[2]));
        }
        Ok(vertices)
    }

    /// Skips a section this reader does not keep: by its count when the entry width is known,
    /// otherwise up to the next keyword.
    /// Returns the section's entry count (0 for an unknown section).
    fn skip_section(&mut self, keyword: &str, tok: Token<'a>) -> Result<usize, MeshError> {
        let name = tok.text;
        let Some(width) = entry_width(keyword) else {
            tracing::debug!(
                "{}:{}: skipping unknown MEDIT section {name}",
                self.path.display(),
                tok.line
            );
            while self.tokens.peek().is_some_and(|t| !is_keyword(t.text)) {
                self.tokens.next();
            }
            return Ok(0);
        };
        let n = self.read_count(name)?;
        for k in 0..n {
            for _ in 0..width {
                let t = self.expect(&|| format!("entry {} of {n} of {name}", k + 1))?;
                if is_keyword(t.text) {
                    return Err(self.error(
                        t.line,
                        format!(
                            "{name} declares {n} entries of {width} values, but keyword '{}' appears in entry {}",
                            t.text,
                            k + 1
                        ),
                    ));
                }
            }
        }
        Ok(n)
    }
}

/// Parses a real, also accepting the Fortran exponent letter `D`.
fn parse_f64(s: &str) -> Option<f64> {
    s.parse::<f64>()
        .ok()
        .or_else(|| s.replace(['d', 'D'], "e").parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUBE_CORNER: &str = "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n\
        0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\nTetrahedra\n1\n1 2 3 4 0\nEnd\n";

    fn parse_str(text: &str) -> Result<TetMesh, MeshError> {
        parse(text, Path::new("test.mesh"))
    }

    /// The line and reason of a parse error (panics on anything else, which fails the test).
    fn parse_error(text: &str) -> (usize, String) {
        match parse_str(text) {
            Err(MeshError::Parse { line, reason, .. }) => (line, reason),
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    /// Hexahedra beside the tetrahedra are refused, not dropped; an empty section is no matter.
    #[test]
    fn other_volume_elements_beside_tetrahedra_are_refused() {
        let hexed = CUBE_CORNER.replace("End", "Hexahedra\n1\n1 2 3 4 1 2 3 4 0\nEnd");
        let (_, reason) = parse_error(&hexed);
        assert!(
            reason.contains("1 Hexahedra beside its 1 tetrahedra"),
            "{reason}"
        );
        assert!(parse_str(&CUBE_CORNER.replace("End", "Prisms\n0\nEnd")).is_ok());
    }

    #[test]
    fn reads_a_single_tet_with_zero_based_indices() {
        let mesh = parse_str(CUBE_CORNER).unwrap();
        assert_eq!(mesh.vertices.len(), 4);
        assert_eq!(mesh.vertices[1], Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3]]);
    }

    #[test]
    fn counts_on_keyword_or_next_line_comments_case_and_no_final_newline() {
        let text = "# header comment\nmeshversionformatted\n1\nDIMENSION\n3\n\n# vertices follow\n\
            VERTICES 4 # count on the keyword line\n0 0 0 0\n1 0 0 0 # trailing\n0 1 0 0\n0 0 1.0e0 0\n\
            Triangles\n1\n1 2 3 7\nCorners 2\n1\n2\nSomeUnknownSection 3 1.5 2.5\n\
            tetrahedra\n1\n4 3 2 1 5\nend";
        let mesh = parse_str(text).unwrap();
        assert_eq!(mesh.vertices.len(), 4);
        assert_eq!(mesh.tets, vec![[3, 2, 1, 0]]);
    }

    #[test]
    fn sections_after_tetrahedra_and_missing_end_are_fine() {
        let text = CUBE_CORNER.replace("End\n", "Edges 1\n1 2 0\nRidges\n1\n1\n");
        assert_eq!(parse_str(&text).unwrap().tets.len(), 1);
    }

    #[test]
    fn tetrahedra_before_vertices_are_range_checked_afterwards() {
        let ok = "Dimension 3\nTetrahedra 1\n1 2 3 4 0\nVertices 4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n";
        assert_eq!(parse_str(ok).unwrap().tets, vec![[0, 1, 2, 3]]);
        let bad = ok.replace("1 2 3 4 0", "1 2 3 5 0");
        assert_eq!(parse_error(&bad).0, 3);
    }

    #[test]
    fn truncated_file_is_an_error_not_a_short_mesh() {
        let text = "Dimension 3\nVertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n";
        let (line, reason) = parse_error(text);
        assert_eq!(line, 6);
        assert!(reason.contains("end of file"), "{reason}");
        let cut = CUBE_CORNER.replace("1 2 3 4 0\nEnd\n", "1 2 3");
        assert!(parse_error(&cut).1.contains("tetrahedron 1"));
        // Every prefix of a valid file either fails or (when cut after a whole section) parses.
        for end in 0..CUBE_CORNER.len() {
            if let Ok(mesh) = parse_str(&CUBE_CORNER[..end]) {
                assert_eq!(mesh.tets.len(), 1, "prefix of {end} bytes");
            }
        }
    }

    #[test]
    fn bad_indices_are_reported_with_their_line() {
        let (line, reason) = parse_error(&CUBE_CORNER.replace("1 2 3 4 0", "1 2 3 5 0"));
        assert_eq!(line, 11);
        assert!(reason.contains("only 4 vertices"), "{reason}");
        let (line, reason) = parse_error(&CUBE_CORNER.replace("1 2 3 4 0", "0 2 3 4 0"));
        assert_eq!(line, 11);
        assert!(reason.contains("start at 1"), "{reason}");
        let (_, reason) = parse_error(&CUBE_CORNER.replace("1 2 3 4 0", "1 2 -3 4 0"));
        assert!(reason.contains("'-3'"), "{reason}");
    }

    #[test]
    fn non_finite_and_malformed_coordinates_are_rejected() {
        for bad in ["nan", "NaN", "inf", "-infinity", "1e999", "abc", "1.0.0"] {
            let text = CUBE_CORNER.replace("1 0 0 1", &format!("1 {bad} 0 1"));
            let (line, reason) = parse_error(&text);
            assert_eq!(line, 6, "{bad}: {reason}");
            assert!(reason.contains("coordinate y of vertex 2"), "{reason}");
        }
        let text = CUBE_CORNER.replace("1 0 0 1", "1.0D+00 0 0 1");
        assert_eq!(parse_str(&text).unwrap().vertices[1].x, 1.0);
    }

    #[test]
    fn huge_counts_fail_fast_without_allocating() {
        let text = "Dimension 3\nVertices\n1000000000000\n0 0 0 0\n";
        let (line, reason) = parse_error(text);
        assert_eq!(line, 3);
        assert!(reason.contains("limit"), "{reason}");
        let text = format!("Dimension 3\nVertices\n{MAX_ENTITIES}\n0 0 0 0\n");
        assert!(parse_error(&text).1.contains("end of file"));
        let text = "Triangles 99999999999999999999999\n";
        assert!(parse_str(text).is_err());
    }

    #[test]
    fn wrong_dimension_and_missing_sections_are_rejected() {
        let (line, reason) = parse_error(&CUBE_CORNER.replace("Dimension 3", "Dimension\n2"));
        assert_eq!(line, 3);
        assert!(reason.contains("Dimension is 2"), "{reason}");
        assert!(
            parse_error("MeshVersionFormatted 1\nDimension 3\nEnd\n")
                .1
                .contains("Vertices")
        );
        let no_tets = "Dimension 3\nVertices 1\n0 0 0 0\nEnd";
        assert!(parse_error(no_tets).1.contains("Tetrahedra"));
        assert!(parse_error("").1.contains("Vertices"));
        assert!(parse_error("4 5 6").1.contains("keyword"));
        let dup = CUBE_CORNER.replace("Tetrahedra", "Vertices 0\nTetrahedra");
        assert!(parse_error(&dup).1.contains("second Vertices"));
    }

    #[test]
    fn wrong_count_in_a_skipped_section_is_caught() {
        let text = CUBE_CORNER.replace("Tetrahedra", "Triangles 2\n1 2 3 0\nTetrahedra");
        let (line, reason) = parse_error(&text);
        assert_eq!(line, 11);
        assert!(reason.contains("Triangles declares 2"), "{reason}");
    }

    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            #[test]
            fn arbitrary_text_never_panics(text in "\\PC{0,200}") {
                let _ = parse_str(&text);
            }

            #[test]
            fn token_soup_never_panics(
                tokens in prop::collection::vec(
                    prop_oneof![
                        Just("Vertices".to_string()), Just("Tetrahedra".to_string()),
                        Just("Dimension".to_string()), Just("End".to_string()),
                        Just("Triangles".to_string()), Just("#".to_string()),
                        Just("\n".to_string()), "-?[0-9]{1,3}(\\.[0-9])?",
                    ],
                    0..60,
                )
            ) {
                let _ = parse_str(&tokens.join(" "));
            }

            #[test]
            fn mutated_valid_file_never_panics(
                edits in prop::collection::vec((0usize..CUBE_CORNER.len(), any::<char>()), 1..6)
            ) {
                let mut chars: Vec<char> = CUBE_CORNER.chars().collect();
                for (pos, c) in edits {
                    if let Some(slot) = chars.get_mut(pos) {
                        *slot = c;
                    }
                }
                let text: String = chars.into_iter().collect();
                if let Ok(mesh) = parse_str(&text) {
                    prop_assert!(mesh.tets.iter().flatten().all(|&i| i < mesh.vertices.len()));
                }
            }
        }
    }
}
