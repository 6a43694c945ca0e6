//! Gmsh MSH 4.1, ASCII and binary (either byte order, 4- or 8-byte `size_t`): `$Nodes` and
//! `$Elements` are read block by block with one [`Cursor`] over text tokens or raw values, keeping
//! `Tet4` blocks and skipping the rest. Other sections (`$Entities`, `$PhysicalNames`, …) are not
//! read, so damage there goes unnoticed: of 30,000 randomly damaged files, those `mshio` refused
//! for it alone are now read, and every file it read gives the same mesh. The one exception,
//! `$PartitionedEntities`, is read where it can be, only to refuse one file of a mesh gmsh
//! split over several (`Mesh.PartitionSplitMeshFiles`), which would otherwise be read as the
//! whole body. Parametric nodes (`SaveParametric`) are not supported.
//!
//! Every count is checked against the section's header and [`MAX_ENTITIES`] before anything is
//! reserved for it, coordinates must be finite, and errors carry the 1-based line of the value at
//! fault (line 0 and the byte offset in binary files).

use std::collections::HashMap;
use std::path::Path;

use super::{MeshFormat, Skipped, TET4, finish, parse_error, snippet};
use crate::io::MAX_ENTITIES;
use crate::{MeshError, TetMesh, Vec3};

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

    /// [`Cursor::error`] at the value that starts at `pos`: in a text file past the whitespace
    /// before it, so the line is the value's own.
    fn error_at_value(&self, pos: usize, reason: impl Into<String>) -> MeshError {
        let at = match self.encoding {
            Encoding::Ascii => {
                let rest = self.bytes.get(pos..).unwrap_or_default();
                pos + rest.iter().take_while(|b| b.is_ascii_whitespace()).count()
            }
            Encoding::Binary { .. } => pos,
        };
        self.error(at, reason)
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
            Err(self.error_at_value(pos, format!("{} is not finite ({value})", what())))
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

/// Parses a file whose `$MeshFormat` says 4.1.
pub(super) fn parse(bytes: &[u8], path: &Path, format: &MeshFormat) -> Result<TetMesh, MeshError> {
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
    let nodes_at = find_section(bytes, format.body, b"$Nodes")
        .ok_or_else(|| parse_error(path, end_line, "no $Nodes section"))?;
    let (vertices, index) = read_nodes(cursor(nodes_at))?;
    let elements_at = find_section(bytes, format.body, b"$Elements")
        .ok_or_else(|| parse_error(path, end_line, "no $Elements section"))?;
    let elements = read_elements(cursor(elements_at), &index)?;
    if let Some(at) = find_section(bytes, format.body, b"$PartitionedEntities")
        && let Some((total, held)) = partitions_of(&mut cursor(at), &elements.volumes)
        && !held.is_empty()
        && held.len() < total
    {
        let held: Vec<String> = held.iter().map(i64::to_string).collect();
        return Err(cursor(at).error(
            at,
            format!(
                "this file holds partition{} {} of the {total} gmsh split the mesh into, a part \
                 of the body: save it unpartitioned, or with every partition in one file \
                 (Mesh.PartitionSplitMeshFiles = 0)",
                if held.len() == 1 { "" } else { "s" },
                held.join(", ")
            ),
        ));
    }
    finish(vertices, elements.tets, &elements.ignored, path, end_line)
}

/// From `$PartitionedEntities`: how many partitions the mesh was split into, and the partitions
/// the volume entities in `volumes` (those holding this file's tets) belong to. `None` when the
/// section cannot be read or does not name one of them: it is not needed to read the mesh, so
/// its damage is no error, only no check.
fn partitions_of(
    c: &mut Cursor<'_>,
    volumes: &[i64],
) -> Option<(usize, std::collections::BTreeSet<i64>)> {
    let what = &String::new;
    let total = c.usize_count(what).ok()?;
    let ghosts = c.usize_count(what).ok()?;
    for _ in 0..ghosts {
        c.int(what).ok()?;
        c.int(what).ok()?;
    }
    let mut counts = [0usize; 4];
    for n in &mut counts {
        *n = c.usize_count(what).ok()?;
    }
    let mut of_volume = HashMap::new();
    for (dim, &n) in counts.iter().enumerate() {
        for _ in 0..n {
            let tag = c.int(what).ok()?;
            c.int(what).ok()?; // parent's dimension
            c.int(what).ok()?; // parent's tag
            let in_partitions = c.usize_count(what).ok()?;
            let mut partitions = Vec::new();
            for _ in 0..in_partitions {
                partitions.push(c.int(what).ok()?);
            }
            // A point's coordinates, else a bounding box.
            for _ in 0..if dim == 0 { 3 } else { 6 } {
                c.double(what).ok()?;
            }
            let physical = c.usize_count(what).ok()?;
            for _ in 0..physical {
                c.int(what).ok()?;
            }
            if dim > 0 {
                let bounding = c.usize_count(what).ok()?;
                for _ in 0..bounding {
                    c.int(what).ok()?;
                }
            }
            if dim == 3 {
                of_volume.insert(tag, partitions);
            }
        }
    }
    c.end_tag("$EndPartitionedEntities").ok()?;
    let mut held = std::collections::BTreeSet::new();
    for tag in volumes {
        held.extend(of_volume.get(tag)?);
    }
    Some((total, held))
}

/// The smallest and largest tag of a `$Nodes` or `$Elements` header: tag 0 is reserved, and the
/// largest may not be below the smallest.
fn tag_range(c: &mut Cursor<'_>, what: &str) -> Result<(), MeshError> {
    let at = c.pos;
    let min = c.size_t(&|| format!("the smallest {what} tag"))?;
    if min == 0 {
        return Err(c.error_at_value(
            at,
            format!("{what} tag 0 is reserved (the smallest {what} tag is 0)"),
        ));
    }
    let at = c.pos;
    let max = c.size_t(&|| format!("the largest {what} tag"))?;
    if max < min {
        return Err(c.error_at_value(
            at,
            format!("the largest {what} tag, {max}, is below the smallest, {min}"),
        ));
    }
    Ok(())
}

/// `$Nodes`: the vertices in file order, and each node tag's 0-based index. Node tags may come in
/// any order, dense or sparse; the order of the file is the order of the vertices.
fn read_nodes(mut c: Cursor<'_>) -> Result<(Vec<Vec3>, HashMap<u64, usize>), MeshError> {
    let header = c.pos;
    let num_blocks = c.usize_count(&|| "the number of node blocks in $Nodes".into())?;
    let num_nodes = c.usize_count(&|| "the number of nodes in $Nodes".into())?;
    tag_range(&mut c, "node")?;
    if num_nodes == 0 {
        return Err(c.error(header, "$Nodes declares no nodes"));
    }
    // A header may lie about its count: never reserve more than the file could hold.
    let capacity = num_nodes.min(c.bytes.len() / 8);
    let mut index = HashMap::with_capacity(capacity);
    let mut vertices = Vec::with_capacity(capacity);
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
                return Err(
                    c.error_at_value(pos, format!("node tag {tag} appears twice in $Nodes"))
                );
            }
            tags.push(tag);
        }
        for &tag in &tags {
            let mut x = [0.0; 3];
            for (axis, x) in ["x", "y", "z"].into_iter().zip(&mut x) {
                *x = c.double(&|| format!("the {axis} coordinate of node {tag}"))?;
            }
            vertices.push(Vec3::new(x[0], x[1], x[2]));
        }
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
    Ok((vertices, index))
}

/// Nodes per element of each Gmsh element type (Gmsh's `GmshDefines.h`), `Err` for the types
/// whose elements have no fixed number of nodes (polygons, polyhedra, sub-elements) and `None`
/// for numbers Gmsh does not define: a block of elements is skipped by its node count.
fn nodes_per_element(element_type: i64) -> Option<Result<usize, ()>> {
    Some(Ok(match element_type {
        15 | 84..=89 | 132 => 1,
        1 => 2,
        2 | 8 => 3,
        3 | 4 | 26 => 4,
        7 | 27 => 5,
        6 | 9 | 28 => 6,
        62 => 7,
        5 | 16 | 63 => 8,
        10 | 20 | 64 => 9,
        11 | 21 | 65 => 10,
        66 => 11,
        22 | 39 => 12,
        19 => 13,
        14 => 14,
        18 | 23 | 24 => 15,
        36 | 40 | 137 => 16,
        13 | 52 => 18,
        17 | 29 | 41 => 20,
        25 | 53 | 125 => 21,
        32 => 22,
        54 | 57 | 111 => 24,
        37 => 25,
        12 | 55 => 27,
        33 | 42 | 58 => 28,
        126 => 29,
        56 | 118 => 30,
        59 | 99 => 32,
        112 => 33,
        79 => 34,
        30 => 35,
        38 | 43 | 60 => 36,
        127 => 37,
        61 | 80 | 90 => 40,
        113 => 42,
        100 => 44,
        44 | 128 => 45,
        81 => 46,
        47 => 49,
        114 => 51,
        82 => 52,
        129 => 53,
        45 | 119 => 55,
        31 | 101 => 56,
        83 => 58,
        115 => 60,
        130 => 61,
        48 | 92 => 64,
        46 => 66,
        102 => 68,
        116 | 131 => 69,
        91 => 75,
        117 => 78,
        103 => 80,
        49 => 81,
        71 => 84,
        120 => 91,
        104 => 92,
        50 => 100,
        105 => 104,
        72 => 120,
        51 => 121,
        93 => 125,
        106 => 126,
        121 => 140,
        73 => 165,
        107 => 196,
        122 => 204,
        94 => 216,
        74 => 220,
        123 => 285,
        75 => 286,
        108 => 288,
        95 => 343,
        124 => 385,
        109 => 405,
        96 => 512,
        110 => 550,
        97 => 729,
        98 => 1000,
        34 | 35 | 67..=70 | 133..=136 | 138..=140 => return Some(Err(())),
        _ => return None,
    }))
}

/// What [`read_elements`] reads of `$Elements`.
struct Elements {
    /// The 4-node tetrahedra, node indices from `read_elements`' `index`.
    tets: Vec<[usize; 4]>,
    /// How many elements of each other type were skipped.
    ignored: Skipped,
    /// The tags of the volume entities the tetrahedra belong to.
    volumes: Vec<i64>,
}

/// `$Elements`, with node tags mapped to indices by `index`.
fn read_elements(mut c: Cursor<'_>, index: &HashMap<u64, usize>) -> Result<Elements, MeshError> {
    let num_blocks = c.usize_count(&|| "the number of element blocks in $Elements".into())?;
    let header = c.pos;
    let total = c.usize_count(&|| "the number of elements in $Elements".into())?;
    if total == 0 {
        return Err(c.error(header, "$Elements declares no elements"));
    }
    tag_range(&mut c, "element")?;
    let mut tets = Vec::new();
    let mut ignored = Skipped::new();
    let mut seen = 0usize;
    let mut volumes = Vec::new();
    for b in 1..=num_blocks {
        let dimension = c.int(&|| format!("the entity dimension of element block {b}"))?;
        let entity = c.int(&|| format!("the entity tag of element block {b}"))?;
        let type_at = c.pos;
        let element_type = c.int(&|| format!("the element type of element block {b}"))?;
        let count_at = c.pos;
        let n = c.usize_count(&|| format!("the number of elements in element block {b}"))?;
        if n > total - seen {
            return Err(c.error_at_value(
                count_at,
                format!(
                    "element block {b} holds {n} elements, more than the {} left of the {total} that $Elements declares",
                    total - seen
                ),
            ));
        }
        seen += n;
        let nodes = match nodes_per_element(element_type) {
            Some(Ok(nodes)) => nodes,
            Some(Err(())) => {
                return Err(c.error_at_value(
                    type_at,
                    format!("element block {b}: element type {element_type} has no fixed number of nodes, which is not supported"),
                ));
            }
            None => {
                return Err(c.error_at_value(
                    type_at,
                    format!("element block {b}: unknown element type {element_type}"),
                ));
            }
        };
        if element_type != TET4 {
            *ignored.entry(element_type).or_default() += n;
            for k in 1..=n {
                for _ in 0..=nodes {
                    c.size_t(&|| format!("element {k} of {n} in element block {b}"))?;
                }
            }
            continue;
        }
        if dimension == 3 && n > 0 {
            volumes.push(entity);
        }
        // Never reserve more than the rest of the file could hold.
        tets.reserve(n.min((c.bytes.len() - c.pos) / 8));
        for k in 1..=n {
            let at = c.pos;
            let tag = c.size_t(&|| format!("element {k} of {n} in element block {b}"))?;
            let mut tet = [0usize; 4];
            for (v, slot) in tet.iter_mut().enumerate() {
                let node = c.size_t(&|| format!("node {} of element {tag}", v + 1))?;
                *slot = *index.get(&node).ok_or_else(|| {
                    c.error_at_value(
                        at,
                        format!(
                            "element {tag} references node {node}, which $Nodes does not define"
                        ),
                    )
                })?;
            }
            tets.push(tet);
        }
    }
    if seen != total {
        return Err(c.error(
            header,
            format!("$Elements declares {total} elements, but its blocks hold {seen}"),
        ));
    }
    c.end_tag("$EndElements")?;
    Ok(Elements {
        tets,
        ignored,
        volumes,
    })
}

/// 1-based line of the `t`-th 4-node tetrahedron (0-based, in file order) of a text file that
/// [`parse`] read; `None` in a binary file.
pub(super) fn tet_line(bytes: &[u8], format: &MeshFormat, t: usize) -> Option<usize> {
    if format.binary {
        return None;
    }
    let mut c = Cursor {
        bytes,
        pos: find_section(bytes, format.body, b"$Elements")?,
        encoding: Encoding::Ascii,
        path: Path::new(""),
    };
    let what = &String::new;
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
        let per = 1 + nodes_per_element(element_type)?.ok()?;
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
