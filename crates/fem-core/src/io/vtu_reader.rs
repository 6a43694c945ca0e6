//! VTK XML UnstructuredGrid (`.vtu`) reader: ParaView's "Save Data" and meshio's default
//! `.vtu` output.
//!
//! Supported: one `<Piece>`, its `<Points>` and `<Cells>` (`connectivity`, `offsets`,
//! `types`) as `DataArray`s in any of the three formats, `ascii`, `binary` (base64, inline)
//! and `appended` (`raw` or `base64`), either byte order, `header_type` `UInt32` or `UInt64`,
//! uncompressed or compressed by `vtkZLibDataCompressor`. Only cells of type 10 (`VTK_TETRA`)
//! are kept, as in the legacy reader. Point and cell data are not read. Errors are
//! [`MeshError::Parse`] with line 0 (binary data has no lines) and say what is wrong; the
//! mesh is not validated here.

use std::collections::HashMap;
use std::path::Path;

use super::MAX_ENTITIES;
use super::vtk::cells_problem;
use crate::{MeshError, TetMesh, Vec3};

/// Reads the `.vtu` file at `path` (not validated).
pub fn read(path: &Path) -> Result<TetMesh, MeshError> {
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, path)
}

/// Parses the bytes of a `.vtu` file; `path` only names the source in errors.
pub fn parse(bytes: &[u8], path: &Path) -> Result<TetMesh, MeshError> {
    Reader { bytes, path }.run()
}

/// A tag of the document: its attributes and the bytes between it and its end tag.
struct Tag {
    attributes: HashMap<String, String>,
    /// Byte range of the content (empty for a self-closing tag).
    content: std::ops::Range<usize>,
    /// The byte after the tag's end.
    end: usize,
}

/// The layout of a file's binary arrays, from its `<VTKFile>` attributes.
#[derive(Clone, Copy)]
struct Layout {
    little_endian: bool,
    /// Bytes of a header value (`header_type` UInt32: 4, UInt64: 8).
    header: usize,
    compressed: bool,
}

/// The appended data: its first byte (after the `_`) and whether it is base64 text.
#[derive(Clone, Copy)]
struct Appended {
    start: usize,
    base64: bool,
}

struct Reader<'a> {
    bytes: &'a [u8],
    path: &'a Path,
}

impl Reader<'_> {
    fn error(&self, reason: impl Into<String>) -> MeshError {
        MeshError::Parse {
            path: self.path.to_path_buf(),
            line: 0,
            reason: reason.into(),
        }
    }

    fn run(&self) -> Result<TetMesh, MeshError> {
        // The appended data may hold any byte, `<` included: tags are looked for before it.
        let appended = find(self.bytes, b"<AppendedData", 0);
        let markup = &self.bytes[..appended.unwrap_or(self.bytes.len())];
        let file = self
            .tag(markup, "VTKFile", 0)?
            .ok_or_else(|| self.error("no <VTKFile> element: this is not a VTK XML file (.vtu)"))?;
        let kind = file.attributes.get("type").map_or("", String::as_str);
        if kind != "UnstructuredGrid" {
            return Err(self.error(format!(
                "a VTK XML file of type \"{kind}\": only UnstructuredGrid (.vtu) holds a \
                 tetrahedral mesh"
            )));
        }
        let layout = self.layout(&file.attributes)?;
        let appended = match appended {
            Some(at) => Some(self.appended(at)?),
            None => None,
        };
        let piece = self
            .tag(markup, "Piece", file.content.start)?
            .ok_or_else(|| self.error("no <Piece> in the <UnstructuredGrid>"))?;
        if self.tag(markup, "Piece", piece.end)?.is_some() {
            return Err(self.error(
                "several <Piece>s: merge them into one (ParaView: Filters > Merge Blocks, then \
                 Save Data)",
            ));
        }
        let count = |name: &str| -> Result<usize, MeshError> {
            piece
                .attributes
                .get(name)
                .and_then(|v| v.trim().parse::<usize>().ok())
                .filter(|&n| n <= MAX_ENTITIES)
                .ok_or_else(|| {
                    self.error(format!(
                        "<Piece> needs {name}, a count of at most {MAX_ENTITIES}"
                    ))
                })
        };
        let (num_points, num_cells) = (count("NumberOfPoints")?, count("NumberOfCells")?);
        let inside = |name: &str| -> Result<Tag, MeshError> {
            self.tag(markup, name, piece.content.start)?
                .filter(|t| t.end <= piece.end)
                .ok_or_else(|| self.error(format!("no <{name}> in the <Piece>")))
        };
        let (points, cells) = (inside("Points")?, inside("Cells")?);
        let array = |within: &Tag, name: Option<&str>, n: usize| {
            let mut from = within.content.start;
            loop {
                let Some(a) = self
                    .tag(markup, "DataArray", from)?
                    .filter(|a| a.end <= within.end)
                else {
                    return Err(self.error(format!(
                        "no DataArray{} in <{}>",
                        name.map_or(String::new(), |n| format!(" named \"{n}\"")),
                        if name.is_some() { "Cells" } else { "Points" }
                    )));
                };
                if name.is_none_or(|n| a.attributes.get("Name").is_some_and(|v| v == n)) {
                    return self.values(&a, n, layout, appended, markup);
                }
                from = a.end;
            }
        };
        let coordinates = array(&points, None, 3 * num_points)?;
        let connectivity = array(&cells, Some("connectivity"), usize::MAX)?;
        let offsets = array(&cells, Some("offsets"), num_cells)?;
        let types = array(&cells, Some("types"), num_cells)?;
        let vertices = coordinates
            .chunks_exact(3)
            .enumerate()
            .map(|(i, p)| {
                if p.iter().all(|x| x.is_finite()) {
                    Ok(Vec3::new(p[0], p[1], p[2]))
                } else {
                    Err(self.error(format!("point {i} is not finite: {p:?}")))
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let index = |x: f64, what: &dyn Fn() -> String, below: usize| {
            (x >= 0.0 && x.fract() == 0.0 && x < below as f64)
                .then_some(x as usize)
                .ok_or_else(|| {
                    self.error(format!("{} is {x}, expected 0 up to below {below}", what()))
                })
        };
        let mut tets = Vec::new();
        let mut ignored: std::collections::BTreeMap<u64, usize> = Default::default();
        let mut start = 0usize;
        for c in 0..num_cells {
            let end = index(
                offsets[c],
                &|| format!("the end offset of cell {c}"),
                connectivity.len() + 1,
            )?;
            if end < start {
                return Err(self.error(format!(
                    "the offsets decrease at cell {c} ({end} after {start})"
                )));
            }
            let t = index(types[c], &|| format!("the type of cell {c}"), 256)? as u64;
            if t != 10 {
                *ignored.entry(t).or_default() += 1;
            } else if end - start != 4 {
                return Err(self.error(format!(
                    "cell {c} has type 10 (tetrahedron) but {} points",
                    end - start
                )));
            } else {
                let mut tet = [0usize; 4];
                for (j, slot) in tet.iter_mut().enumerate() {
                    *slot = index(
                        connectivity[start + j],
                        &|| format!("point {j} of cell {c}"),
                        num_points,
                    )?;
                }
                tets.push(tet);
            }
            start = end;
        }
        if let Some(problem) = cells_problem(&ignored, tets.len(), num_cells) {
            return Err(self.error(problem));
        }
        Ok(TetMesh { vertices, tets })
    }

    /// The byte order, header size and compression a `<VTKFile>` declares.
    fn layout(&self, attributes: &HashMap<String, String>) -> Result<Layout, MeshError> {
        let get = |k: &str| attributes.get(k).map(String::as_str);
        let little_endian = match get("byte_order") {
            None | Some("LittleEndian") => true,
            Some("BigEndian") => false,
            Some(other) => {
                return Err(self.error(format!(
                    "byte_order=\"{other}\": expected LittleEndian or BigEndian"
                )));
            }
        };
        let header = match get("header_type") {
            None | Some("UInt32") => 4,
            Some("UInt64") => 8,
            Some(other) => {
                return Err(self.error(format!(
                    "header_type=\"{other}\": expected UInt32 or UInt64"
                )));
            }
        };
        let compressed = match get("compressor") {
            None | Some("") => false,
            Some("vtkZLibDataCompressor") => true,
            Some(other) => {
                return Err(self.error(format!(
                    "compressor=\"{other}\" is not read (only vtkZLibDataCompressor is): save it \
                     again with ZLib or no compression (ParaView: Save Data, Compressor Type)"
                )));
            }
        };
        Ok(Layout {
            little_endian,
            header,
            compressed,
        })
    }

    /// The `<AppendedData>` element at byte `at`: where its data starts and how it is encoded.
    fn appended(&self, at: usize) -> Result<Appended, MeshError> {
        let Some(close) = find(self.bytes, b">", at) else {
            return Err(self.error("the <AppendedData> tag is not closed"));
        };
        let attributes = attributes(&self.bytes[at + b"<AppendedData".len()..close]);
        let base64 = match attributes.get("encoding").map(String::as_str) {
            Some("raw") => false,
            Some("base64") | None => true,
            Some(other) => {
                return Err(self.error(format!(
                    "<AppendedData encoding=\"{other}\">: expected raw or base64"
                )));
            }
        };
        let Some(underscore) = find(self.bytes, b"_", close) else {
            return Err(self.error("the appended data does not start with '_'"));
        };
        Ok(Appended {
            start: underscore + 1,
            base64,
        })
    }

    /// The first element `name` at or after byte `from` of `markup`, or None.
    fn tag(&self, markup: &[u8], name: &str, from: usize) -> Result<Option<Tag>, MeshError> {
        let open = format!("<{name}");
        let mut at = from;
        let start = loop {
            let Some(i) = find(markup, open.as_bytes(), at) else {
                return Ok(None);
            };
            // `<Points` is not `<PointsData`.
            match markup.get(i + open.len()) {
                Some(b) if b.is_ascii_whitespace() || *b == b'>' || *b == b'/' => break i,
                _ => at = i + open.len(),
            }
        };
        let Some(close) = find(markup, b">", start) else {
            return Err(self.error(format!("the <{name}> tag is not closed")));
        };
        let head = &markup[start + open.len()..close];
        let attributes = attributes(head);
        if head.ends_with(b"/") {
            return Ok(Some(Tag {
                attributes,
                content: close + 1..close + 1,
                end: close + 1,
            }));
        }
        let end_tag = format!("</{name}>");
        let Some(end) = find(markup, end_tag.as_bytes(), close + 1) else {
            // The root's end tag lies past the appended data, where no tag is looked for.
            if name == "VTKFile" {
                return Ok(Some(Tag {
                    attributes,
                    content: close + 1..markup.len(),
                    end: markup.len(),
                }));
            }
            return Err(self.error(format!("<{name}> has no {end_tag}")));
        };
        Ok(Some(Tag {
            attributes,
            content: close + 1..end,
            end: end + end_tag.len(),
        }))
    }

    /// The `n` values of a `DataArray` (any count for `usize::MAX`), as numbers.
    fn values(
        &self,
        array: &Tag,
        n: usize,
        layout: Layout,
        appended: Option<Appended>,
        markup: &[u8],
    ) -> Result<Vec<f64>, MeshError> {
        let name = array
            .attributes
            .get("Name")
            .map_or("Points".to_string(), |n| format!("\"{n}\""));
        let ty = array.attributes.get("type").map_or("", String::as_str);
        let Some(size) = type_size(ty) else {
            return Err(self.error(format!(
                "DataArray {name}: type=\"{ty}\" is not a number type (Float32, Float64, Int8 to \
                 Int64, UInt8 to UInt64)"
            )));
        };
        // The bytes the array may hold: `n` values, or for the connectivity, whose count
        // only its offsets give, as many as any array may.
        let cap = if n == usize::MAX {
            16 * MAX_ENTITIES
        } else {
            n
        }
        .saturating_mul(size);
        let format = array.attributes.get("format").map_or("", String::as_str);
        let values = match format {
            "ascii" => {
                let text = without_elements(&markup[array.content.clone()]);
                let text = String::from_utf8_lossy(&text);
                text.split_whitespace()
                    .map(|t| {
                        t.parse::<f64>().map_err(|_| {
                            self.error(format!("DataArray {name}: '{t}' is not a number"))
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()?
            }
            "binary" => {
                let text = without_elements(&markup[array.content.clone()]);
                let data = self.block(&text, true, layout, &name, cap)?;
                self.numbers(&data, ty, size, layout, &name)?
            }
            "appended" => {
                let Some(appended) = appended else {
                    return Err(self.error(format!(
                        "DataArray {name} is appended, but the file has no <AppendedData>"
                    )));
                };
                let offset = array
                    .attributes
                    .get("offset")
                    .and_then(|o| o.trim().parse::<usize>().ok())
                    .ok_or_else(|| self.error(format!("DataArray {name} needs an offset")))?;
                let at = appended
                    .start
                    .checked_add(offset)
                    .filter(|&a| a <= self.bytes.len())
                    .ok_or_else(|| {
                        self.error(format!(
                            "DataArray {name}: offset {offset} is past the end of the file \
                             (truncated file?)"
                        ))
                    })?;
                let data = self.block(&self.bytes[at..], appended.base64, layout, &name, cap)?;
                self.numbers(&data, ty, size, layout, &name)?
            }
            other => {
                return Err(self.error(format!(
                    "DataArray {name}: format=\"{other}\", expected ascii, binary or appended"
                )));
            }
        };
        if n != usize::MAX && values.len() != n {
            return Err(self.error(format!(
                "DataArray {name} holds {} values where the <Piece> needs {n}",
                values.len()
            )));
        }
        if values.len() > 16 * MAX_ENTITIES {
            return Err(self.error(format!(
                "DataArray {name} holds {} values, more than the limit",
                values.len()
            )));
        }
        Ok(values)
    }

    /// The bytes of one binary array starting at `data`'s first byte: its header (a byte count,
    /// or for compressed data the block count, block size, last block's size, 0 when full, and
    /// each block's compressed size), then its bytes; at most `cap` of them. base64 data encodes
    /// a compressed array's header apart from its blocks; an uncompressed one's header with its
    /// bytes (VTK, meshio) or apart from them (other writers), both read.
    fn block(
        &self,
        data: &[u8],
        base64: bool,
        layout: Layout,
        name: &str,
        cap: usize,
    ) -> Result<Vec<u8>, MeshError> {
        let broken = |what: &str| self.error(format!("DataArray {name}: {what}"));
        let cut = || broken("its data is cut short (truncated file?) or not base64");
        // base64 text counts its characters without the line breaks a writer may put in.
        let stripped: Vec<u8>;
        let data = if base64 {
            stripped = data
                .iter()
                .copied()
                .filter(|c| !c.is_ascii_whitespace())
                .collect();
            &stripped[..]
        } else {
            data
        };
        let h = layout.header;
        let read_header = |bytes: &[u8], i: usize| -> Option<usize> {
            let b = bytes.get(i * h..(i + 1) * h)?;
            usize::try_from(super::widened(b, layout.little_endian)).ok()
        };
        // base64 characters of `bytes` bytes, None past any file.
        let chars = |bytes: usize| {
            bytes
                .checked_add(2)
                .map(|b| b / 3)
                .and_then(|q| q.checked_mul(4))
        };
        if !layout.compressed {
            let header_chars = h.div_ceil(3) * 4;
            let (len, body): (usize, std::borrow::Cow<'_, [u8]>) = if base64 {
                let head = decode_base64(data, header_chars).ok_or_else(cut)?;
                let len = read_header(&head, 0)
                    .filter(|&l| l <= cap)
                    .ok_or_else(|| broken("its byte count is missing or larger than it can be"))?;
                // A header encoded apart ends in padding (`…==`) with the bytes' text after it;
                // else it runs on into the bytes.
                if data.get(header_chars - 1) == Some(&b'=') && data.len() > header_chars {
                    let all = decode_base64(&data[header_chars..], chars(len).ok_or_else(cut)?)
                        .ok_or_else(cut)?;
                    (len, std::borrow::Cow::Owned(all))
                } else {
                    let all =
                        decode_base64(data, chars(h + len).ok_or_else(cut)?).ok_or_else(cut)?;
                    (len, std::borrow::Cow::Owned(all[h..].to_vec()))
                }
            } else {
                let len = read_header(data, 0)
                    .filter(|&l| l <= cap)
                    .ok_or_else(|| broken("its byte count is missing or larger than it can be"))?;
                (len, std::borrow::Cow::Borrowed(&data[h..]))
            };
            return body.get(..len).map(<[u8]>::to_vec).ok_or_else(cut);
        }
        // Compressed: [blocks, block size, last block's size, compressed sizes…].
        let first = if base64 {
            decode_base64(data, 4 * h)
        } else {
            data.get(..3 * h).map(<[u8]>::to_vec)
        }
        .ok_or_else(|| broken("its compression header is cut short (truncated file?)"))?;
        let (blocks, block_size, last) = (
            read_header(&first, 0),
            read_header(&first, 1).unwrap_or(0),
            read_header(&first, 2).unwrap_or(0),
        );
        // Every block but the last is full: the blocks hold at most `cap` bytes.
        let blocks = blocks
            .filter(|&b| b <= data.len() && (b <= 1 || (b - 1).saturating_mul(block_size) <= cap))
            .ok_or_else(|| broken("its block count is missing or larger than it can be"))?;
        let header_len = (3 + blocks) * h;
        let (header, rest): (Vec<u8>, std::borrow::Cow<'_, [u8]>) = if base64 {
            let encoded = chars(header_len).ok_or_else(cut)?;
            let header = decode_base64(data, encoded)
                .ok_or_else(|| broken("its compression header is cut short"))?;
            (
                header,
                std::borrow::Cow::Borrowed(data.get(encoded..).unwrap_or_default()),
            )
        } else {
            let header = data
                .get(..header_len)
                .ok_or_else(|| broken("its compression header is cut short"))?
                .to_vec();
            (header, std::borrow::Cow::Borrowed(&data[header_len..]))
        };
        let sizes: Vec<usize> = (0..blocks)
            .map(|i| read_header(&header, 3 + i))
            .collect::<Option<_>>()
            .ok_or_else(|| broken("its compressed block sizes are cut short"))?;
        let total = sizes
            .iter()
            .try_fold(0usize, |a, &s| a.checked_add(s))
            .filter(|&t| t <= rest.len())
            .ok_or_else(cut)?;
        let rest = if base64 {
            std::borrow::Cow::Owned(
                decode_base64(&rest, chars(total).ok_or_else(cut)?).ok_or_else(cut)?,
            )
        } else {
            rest
        };
        let mut out = Vec::new();
        let mut at = 0usize;
        for (i, &size) in sizes.iter().enumerate() {
            let chunk = rest.get(at..at + size).ok_or_else(cut)?;
            let expect = if i + 1 == blocks && last > 0 {
                last
            } else {
                block_size
            };
            if out.len().saturating_add(expect) > cap {
                return Err(broken("it holds more bytes than the <Piece> needs"));
            }
            let block = miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(chunk, expect)
                .ok()
                .filter(|b| b.len() == expect)
                .ok_or_else(|| {
                    broken(&format!("block {i} does not decompress to its size (zlib)"))
                })?;
            out.extend_from_slice(&block);
            at += size;
        }
        Ok(out)
    }

    /// The values of `data` read as `ty`, `size` bytes each, in the file's byte order.
    fn numbers(
        &self,
        data: &[u8],
        ty: &str,
        size: usize,
        layout: Layout,
        name: &str,
    ) -> Result<Vec<f64>, MeshError> {
        if !data.len().is_multiple_of(size) {
            return Err(self.error(format!(
                "DataArray {name}: {} bytes are no whole number of {ty} values",
                data.len()
            )));
        }
        Ok(data
            .chunks_exact(size)
            .map(|b| {
                let bits = super::widened(b, layout.little_endian);
                match ty {
                    "Float32" => f64::from(f32::from_bits(bits as u32)),
                    "Float64" => f64::from_bits(bits),
                    "Int8" | "Int16" | "Int32" | "Int64" => super::sign_extended(bits, size) as f64,
                    _ => bits as f64,
                }
            })
            .collect())
    }
}

/// A DataArray's content without the elements VTK puts beside its values (`<InformationKey
/// name="L2_NORM_RANGE" …><Value index="0">0</Value>…</InformationKey>`, whose numbers are not
/// the array's): the text outside every element.
fn without_elements(content: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(content.len());
    let mut at = 0;
    while let Some(open) = find(content, b"<", at) {
        out.extend_from_slice(&content[at..open]);
        // A comment runs to `-->`, whatever it holds.
        if content[open..].starts_with(b"<!--") {
            match find(content, b"-->", open + 4) {
                Some(end) => {
                    at = end + 3;
                    continue;
                }
                None => return out,
            }
        }
        let name_end = content[open + 1..]
            .iter()
            .position(|c| c.is_ascii_whitespace() || *c == b'>' || *c == b'/')
            .map_or(content.len(), |i| open + 1 + i);
        let name = &content[open + 1..name_end];
        let Some(close) = find(content, b">", open) else {
            return out;
        };
        at = if content[close - 1] == b'/' || name.is_empty() {
            close + 1
        } else {
            let end_tag = [b"</", name, b">"].concat();
            match find(content, &end_tag, close + 1) {
                Some(end) => end + end_tag.len(),
                None => return out,
            }
        };
    }
    out.extend_from_slice(&content[at..]);
    out
}

/// Bytes of a value of a DataArray's `type`.
fn type_size(ty: &str) -> Option<usize> {
    Some(match ty {
        "Int8" | "UInt8" => 1,
        "Int16" | "UInt16" => 2,
        "Int32" | "UInt32" | "Float32" => 4,
        "Int64" | "UInt64" | "Float64" => 8,
        _ => return None,
    })
}

/// The first `needle` in `bytes` at or after `from`.
fn find(bytes: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    bytes
        .get(from..)?
        .windows(needle.len())
        .position(|w| w == needle)
        .map(|i| from + i)
}

/// The `key="value"` (or `'value'`) attributes of a tag's head.
fn attributes(head: &[u8]) -> HashMap<String, String> {
    let text = String::from_utf8_lossy(head);
    let mut out = HashMap::new();
    let mut rest = text.as_ref();
    while let Some(eq) = rest.find('=') {
        let key = rest[..eq]
            .split_whitespace()
            .last()
            .unwrap_or_default()
            .to_string();
        let after = rest[eq + 1..].trim_start();
        let Some(quote) = after.chars().next().filter(|c| *c == '"' || *c == '\'') else {
            break;
        };
        let Some(close) = after[1..].find(quote) else {
            break;
        };
        out.insert(key, after[1..1 + close].to_string());
        rest = &after[close + 2..];
    }
    out
}

/// The bytes of the first `chars` base64 characters of `text` (whitespace skipped, padding
/// honoured), or None when `text` holds fewer or a character outside the alphabet.
fn decode_base64(text: &[u8], chars: usize) -> Option<Vec<u8>> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    // Sized by the text there is, never by a count the file declares.
    let mut out = Vec::with_capacity((chars / 4 * 3).min(text.len()));
    let mut quantum = [0u8; 4];
    let (mut filled, mut taken) = (0, 0);
    for &c in text {
        if taken == chars {
            break;
        }
        if c.is_ascii_whitespace() {
            continue;
        }
        quantum[filled] = c;
        filled += 1;
        taken += 1;
        if filled == 4 {
            let pad = quantum.iter().rev().take_while(|&&c| c == b'=').count();
            if pad > 2 {
                return None;
            }
            let mut bits = 0u32;
            for &q in &quantum[..4 - pad] {
                bits = bits << 6 | value(q)?;
            }
            bits <<= 6 * pad as u32;
            out.extend_from_slice(&bits.to_be_bytes()[1..4 - pad]);
            filled = 0;
        }
    }
    (taken == chars && filled == 0).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One tetrahedron and a triangle, the points as written in every test file.
    const POINTS: [f64; 15] = [0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1., 9., 9., 9.];
    const CONNECTIVITY: [i64; 7] = [0, 1, 2, 3, 0, 1, 4];
    const OFFSETS: [i64; 2] = [4, 7];
    const TYPES: [u8; 2] = [10, 5];

    fn encode_base64(bytes: &[u8]) -> String {
        const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut out = String::new();
        for chunk in bytes.chunks(3) {
            let mut b = [0u8; 3];
            b[..chunk.len()].copy_from_slice(chunk);
            let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
            for i in 0..4 {
                if i <= chunk.len() {
                    out.push(ABC[(n >> (18 - 6 * i) & 63) as usize] as char);
                } else {
                    out.push('=');
                }
            }
        }
        out
    }

    /// The raw bytes of the four arrays, little-endian.
    fn arrays() -> [(String, &'static str, Vec<u8>); 4] {
        let le = |v: &[i64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        [
            (
                "Name=\"Points\" NumberOfComponents=\"3\"".into(),
                "Float64",
                POINTS.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            ("Name=\"connectivity\"".into(), "Int64", le(&CONNECTIVITY)),
            ("Name=\"offsets\"".into(), "Int64", le(&OFFSETS)),
            ("Name=\"types\"".into(), "UInt8", TYPES.to_vec()),
        ]
    }

    /// A file whose arrays are `bodies` (each given its `format=…` attributes and content),
    /// with `file` attributes on `<VTKFile>` and `tail` after `</UnstructuredGrid>`.
    fn file(file: &str, bodies: &[(String, String)], tail: &[u8]) -> Vec<u8> {
        let a = arrays();
        let array = |i: usize| {
            format!(
                "<DataArray type=\"{}\" {} {}>{}</DataArray>\n",
                a[i].1, a[i].0, bodies[i].0, bodies[i].1
            )
        };
        let mut out = format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" {file}>\n\
             <UnstructuredGrid>\n<Piece NumberOfPoints=\"5\" NumberOfCells=\"2\">\n\
             <PointData><DataArray type=\"Float64\" Name=\"PointsOfMine\" format=\"ascii\">1 2 3 4 5</DataArray></PointData>\n\
             <Points>\n{}</Points>\n<Cells>\n{}{}{}</Cells>\n</Piece>\n</UnstructuredGrid>\n",
            array(0),
            array(1),
            array(2),
            array(3)
        )
        .into_bytes();
        out.extend_from_slice(tail);
        out.extend_from_slice(b"</VTKFile>\n");
        out
    }

    fn expect_mesh(bytes: &[u8]) {
        let mesh = parse(bytes, Path::new("t.vtu")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(mesh.vertices.len(), 5);
        assert_eq!(mesh.vertices[3], Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3]]);
    }

    fn error(bytes: &[u8]) -> String {
        match parse(bytes, Path::new("t.vtu")) {
            Err(MeshError::Parse { reason, .. }) => reason,
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    fn zlib_blocks(data: &[u8], block: usize, header: usize) -> (Vec<u8>, Vec<u8>) {
        let blocks: Vec<Vec<u8>> = data
            .chunks(block)
            .map(|c| miniz_oxide::deflate::compress_to_vec_zlib(c, 6))
            .collect();
        let last = data.len() - (data.len().div_ceil(block) - 1) * block;
        let mut head = Vec::new();
        for v in [blocks.len(), block, last]
            .into_iter()
            .chain(blocks.iter().map(Vec::len))
        {
            head.extend_from_slice(&(v as u64).to_le_bytes()[..header]);
        }
        (head, blocks.concat())
    }

    #[test]
    fn ascii_binary_and_appended_arrays_read_alike() {
        let a = arrays();
        let numbers = |i: usize| -> String {
            match i {
                0 => POINTS.map(|x| x.to_string()).join(" "),
                1 => CONNECTIVITY.map(|x| x.to_string()).join(" "),
                2 => OFFSETS.map(|x| x.to_string()).join(" "),
                _ => TYPES.map(|x| x.to_string()).join(" "),
            }
        };
        let ascii: Vec<(String, String)> = (0..4)
            .map(|i| ("format=\"ascii\"".into(), numbers(i)))
            .collect();
        expect_mesh(&file("byte_order=\"LittleEndian\"", &ascii, b""));
        // VTK's own ascii files put an element of numbers beside the values, before or after.
        let key = "<InformationKey name=\"L2_NORM_RANGE\" location=\"vtkDataArray\" \
                   length=\"2\">\n<Value index=\"0\">\n0\n</Value>\n<Value index=\"1\">\n1.7\n\
                   </Value>\n</InformationKey>";
        let mut keyed = ascii.clone();
        keyed[0].1 = format!("{}\n{key}\n", keyed[0].1);
        keyed[1].1 = format!("{key}\n{}", keyed[1].1);
        keyed[2].1 = format!("<!-- offsets, <ends> of cells -->{}", keyed[2].1);
        expect_mesh(&file("", &keyed, b""));
        // A header base64-encoded apart from the bytes, as some writers do.
        let apart: Vec<(String, String)> = a
            .iter()
            .map(|(_, _, bytes)| {
                let head = (bytes.len() as u32).to_le_bytes();
                (
                    "format=\"binary\"".into(),
                    format!("{}{}", encode_base64(&head), encode_base64(bytes)),
                )
            })
            .collect();
        expect_mesh(&file("", &apart, b""));
        // Inline base64, header and bytes in one stream, UInt32 and UInt64 headers.
        for (header, attr) in [(4usize, "UInt32"), (8, "UInt64")] {
            let binary: Vec<(String, String)> = a
                .iter()
                .map(|(_, _, bytes)| {
                    let mut all = (bytes.len() as u64).to_le_bytes()[..header].to_vec();
                    all.extend_from_slice(bytes);
                    ("format=\"binary\"".into(), encode_base64(&all))
                })
                .collect();
            expect_mesh(&file(
                &format!("byte_order=\"LittleEndian\" header_type=\"{attr}\""),
                &binary,
                b"",
            ));
            // Compressed in blocks of 16 bytes: the header and the blocks encoded apart.
            let zipped: Vec<(String, String)> = a
                .iter()
                .map(|(_, _, bytes)| {
                    let (head, blocks) = zlib_blocks(bytes, 16, header);
                    (
                        "format=\"binary\"".into(),
                        format!("\n  {}{}\n", encode_base64(&head), encode_base64(&blocks)),
                    )
                })
                .collect();
            expect_mesh(&file(
                &format!(
                    "byte_order=\"LittleEndian\" header_type=\"{attr}\" \
                     compressor=\"vtkZLibDataCompressor\""
                ),
                &zipped,
                b"",
            ));
        }
        // Appended raw, as ParaView saves (bytes holding '<' and '>' included), and compressed.
        for compressed in [false, true] {
            let mut data = b"<AppendedData encoding=\"raw\">\n_".to_vec();
            let start = data.len();
            let mut bodies = Vec::new();
            for (_, _, bytes) in &a {
                bodies.push((
                    format!("format=\"appended\" offset=\"{}\"", data.len() - start),
                    String::new(),
                ));
                if compressed {
                    let (head, blocks) = zlib_blocks(bytes, 16, 8);
                    data.extend_from_slice(&head);
                    data.extend_from_slice(&blocks);
                } else {
                    data.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
                    data.extend_from_slice(bytes);
                }
            }
            data.extend_from_slice(b"\n</AppendedData>\n");
            let attrs = if compressed {
                "header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\""
            } else {
                "header_type=\"UInt64\""
            };
            expect_mesh(&file(attrs, &bodies, &data));
        }
    }

    /// The frames the pipeline writes for ParaView read back as the mesh they show.
    #[test]
    fn the_writers_frames_read_back() {
        let mesh = crate::mesh::generate::box_mesh(&crate::mesh::generate::BoxSpec {
            size: [1.0, 0.5, 0.25],
            cells: [3, 2, 1],
            ..Default::default()
        })
        .unwrap();
        let path = std::env::temp_dir().join(format!("vtu-reader-{}.vtu", std::process::id()));
        let u = vec![Vec3::new(0.1, 0.0, 0.0); mesh.num_vertices()];
        super::super::vtu::write_vtu(&path, &mesh, &[("displacement", &u)], &[]).unwrap();
        let read = super::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(read.tets, mesh.tets);
        for (a, b) in read.vertices.iter().zip(&mesh.vertices) {
            assert!((a - b).norm() < 1e-12, "{a} against {b}");
        }
    }

    /// Block counts and sizes a file cannot back are refused, not multiplied past any size.
    #[test]
    fn huge_header_values_are_refused() {
        for head in [
            [1u64, u64::MAX, 0, u64::MAX],
            [u64::MAX, 1, 1, 1],
            [2, 16, 8, u64::MAX / 2],
        ] {
            let header: Vec<u8> = head.iter().flat_map(|v| v.to_le_bytes()).collect();
            let bodies: Vec<(String, String)> = (0..4)
                .map(|_| ("format=\"binary\"".into(), encode_base64(&header) + "AAAA"))
                .collect();
            let reason = error(&file(
                "header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\"",
                &bodies,
                b"",
            ));
            assert!(reason.starts_with("DataArray \"Points\":"), "{reason}");
        }
    }

    /// Hexahedra beside the tetrahedra are refused, not dropped.
    #[test]
    fn other_volume_cells_beside_tetrahedra_are_refused() {
        let body = |v: &str| ("format=\"ascii\"".to_string(), v.to_string());
        let points = POINTS.map(|x| x.to_string()).join(" ");
        let bodies = [
            body(&points),
            body("0 1 2 3 0 1 2 3 4 0 1 2"),
            body("4 12"),
            body("10 12"),
        ];
        let reason = error(&file("", &bodies, b""));
        assert!(
            reason.contains("1 of type 12, hexahedron beside its 1 tetrahedra"),
            "{reason}"
        );
    }

    #[test]
    fn big_endian_and_signed_values_read() {
        let be: Vec<(String, String)> = arrays()
            .iter()
            .map(|(_, ty, bytes)| {
                let size = type_size(ty).unwrap();
                let mut all = (bytes.len() as u32).to_be_bytes().to_vec();
                all.extend(bytes.chunks(size).flat_map(|c| c.iter().rev().copied()));
                ("format=\"binary\"".into(), encode_base64(&all))
            })
            .collect();
        expect_mesh(&file("byte_order=\"BigEndian\"", &be, b""));
    }

    #[test]
    fn broken_files_say_what_is_wrong() {
        let ascii = |connectivity: &str, types: &str| -> Vec<(String, String)> {
            vec![
                (
                    "format=\"ascii\"".into(),
                    POINTS.map(|x| x.to_string()).join(" "),
                ),
                ("format=\"ascii\"".into(), connectivity.into()),
                ("format=\"ascii\"".into(), "4 7".into()),
                ("format=\"ascii\"".into(), types.into()),
            ]
        };
        assert!(
            error(&file("", &ascii("0 1 2 9 0 1 4", "10 5"), b"")).contains("point 3 of cell 0")
        );
        assert!(error(&file("", &ascii("0 1 2 3 0 1 4", "5 5"), b"")).contains("no tetrahedra"));
        assert!(error(&file("", &ascii("0 1 2 3 0 1 4", "10"), b"")).contains("needs 2"));
        assert!(
            error(&file(
                "compressor=\"vtkLZ4DataCompressor\"",
                &ascii("0 1 2 3 0 1 4", "10 5"),
                b""
            ))
            .contains("ZLib")
        );
        assert!(error(b"<VTKFile type=\"PolyData\"></VTKFile>").contains("PolyData"));
        assert!(error(b"hello").contains("not a VTK XML file"));
        let binary: Vec<(String, String)> = arrays()
            .iter()
            .map(|(_, _, bytes)| {
                let mut all = (bytes.len() as u32).to_le_bytes().to_vec();
                all.extend_from_slice(bytes);
                let text = encode_base64(&all);
                (
                    "format=\"binary\"".into(),
                    text[..text.len() / 2].to_string(),
                )
            })
            .collect();
        assert!(error(&file("", &binary, b"")).contains("cut short"));
    }

    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            /// Files cut anywhere or with bytes changed are read or refused, never a panic,
            /// and what is read indexes its own points.
            #[test]
            fn mutated_files_never_panic(
                cut in any::<usize>(),
                edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..6),
            ) {
                let a = arrays();
                let bodies: Vec<(String, String)> = a
                    .iter()
                    .map(|(_, _, bytes)| {
                        let (head, blocks) = zlib_blocks(bytes, 16, 4);
                        ("format=\"binary\"".into(), format!("{}{}", encode_base64(&head), encode_base64(&blocks)))
                    })
                    .collect();
                let mut bytes = file("compressor=\"vtkZLibDataCompressor\"", &bodies, b"");
                let _ = parse(&bytes[..cut % (bytes.len() + 1)], Path::new("t.vtu"));
                let n = bytes.len();
                for &(at, b) in &edits {
                    bytes[at % n] = b;
                }
                if let Ok(mesh) = parse(&bytes, Path::new("t.vtu")) {
                    prop_assert!(mesh.tets.iter().flatten().all(|&i| i < mesh.vertices.len()));
                }
            }
        }
    }
}
