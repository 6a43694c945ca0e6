//! Structured mutations of a valid mesh file: the damage real files suffer (truncation, flipped
//! bits, a number replaced by a huge, negative, non-finite or non-numeric one, lines lost or
//! repeated) rather than uniform noise, so most inputs get deep into a reader before failing.
//!
//! Positions are raw `u64`s reduced modulo the input length when applied, so a mutation can be
//! generated (by proptest or [`random_mutation`]) without knowing the file.

use fem_core::io::MAX_ENTITIES;
use fem_core::rng::SplitMix64;

/// One edit of a file.
#[derive(Debug, Clone, PartialEq)]
pub enum Mutation {
    /// Keep the first `keep`‰ of the bytes.
    Truncate {
        per_mille: u64,
    },
    FlipBit {
        at: u64,
        bit: u8,
    },
    SetByte {
        at: u64,
        byte: u8,
    },
    /// Replace the `token`-th whitespace-separated token with `with`.
    ReplaceToken {
        token: u64,
        with: String,
    },
    DeleteLine {
        line: u64,
    },
    DuplicateLine {
        line: u64,
    },
    SwapLines {
        a: u64,
        b: u64,
    },
    /// Remove `len` bytes starting at `at`.
    DeleteRange {
        at: u64,
        len: u64,
    },
    /// Insert `text` at byte `at`.
    Insert {
        at: u64,
        text: String,
    },
    /// Overwrite 8 bytes at an 8-aligned offset with `word` (a huge count, NaN, -1 … in binary
    /// files).
    OverwriteWord {
        at: u64,
        word: [u8; 8],
    },
}

/// Values a number in a mesh file gets replaced with: huge, negative, non-finite, malformed, or
/// another format's keyword.
pub fn replacement_tokens() -> Vec<String> {
    let mut v: Vec<String> = [
        "nan",
        "NaN",
        "-nan",
        "inf",
        "-inf",
        "Infinity",
        "1e309",
        "-1e309",
        "1e300",
        "-1e300",
        "1e-320",
        "-1",
        "-0",
        "0",
        "1",
        "2",
        "3",
        "4",
        "5",
        "10",
        "11",
        "0.5",
        "-2147483648",
        "2147483647",
        "2147483648",
        "4294967295",
        "4294967296",
        "9223372036854775807",
        "9223372036854775808",
        "18446744073709551615",
        "18446744073709551616",
        "99999999999999999999999999",
        "1000000000000",
        "1.0e+",
        "0x10",
        "1,5",
        "abc",
        "#",
        "$",
        "$Nodes",
        "$EndNodes",
        "$Elements",
        "$EndElements",
        "$MeshFormat",
        "Vertices",
        "Tetrahedra",
        "Triangles",
        "End",
        "POINTS",
        "CELLS",
        "CELL_TYPES",
        "OFFSETS",
        "CONNECTIVITY",
        "POINT_DATA",
        "\u{0}",
        "\u{e9}",
        "\u{fffd}",
        "",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for n in [MAX_ENTITIES - 1, MAX_ENTITIES, MAX_ENTITIES + 1] {
        v.push(n.to_string());
    }
    v
}

/// 8-byte words for binary files.
pub fn replacement_words() -> Vec<[u8; 8]> {
    vec![
        u64::MAX.to_le_bytes(),
        (MAX_ENTITIES as u64).to_le_bytes(),
        (MAX_ENTITIES as u64 + 1).to_le_bytes(),
        (1u64 << 40).to_le_bytes(),
        (1u64 << 32).to_le_bytes(),
        0u64.to_le_bytes(),
        1u64.to_le_bytes(),
        (-1i64).to_le_bytes(),
        f64::NAN.to_le_bytes(),
        f64::INFINITY.to_le_bytes(),
        f64::MAX.to_le_bytes(),
        [0xff, 0xff, 0xff, 0x7f, 0xff, 0xff, 0xff, 0x7f],
        [0x00, 0x00, 0x00, 0x80, 0x00, 0x00, 0x00, 0x80],
    ]
}

/// Byte ranges of the whitespace-separated tokens of `bytes`.
fn tokens(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, b) in bytes.iter().enumerate() {
        match (b.is_ascii_whitespace(), start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, bytes.len()));
    }
    out
}

/// Byte ranges of the lines of `bytes`, each with its newline.
fn lines(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, b) in bytes.iter().enumerate() {
        if *b == b'\n' {
            out.push((start, i + 1));
            start = i + 1;
        }
    }
    if start < bytes.len() {
        out.push((start, bytes.len()));
    }
    out
}

fn pick(x: u64, len: usize) -> usize {
    if len == 0 {
        0
    } else {
        (x % len as u64) as usize
    }
}

impl Mutation {
    pub fn apply(&self, input: &[u8]) -> Vec<u8> {
        let mut b = input.to_vec();
        let len = b.len();
        match self {
            Mutation::Truncate { per_mille } => {
                b.truncate((len as u64 * (per_mille % 1000) / 1000) as usize);
            }
            Mutation::FlipBit { at, bit } => {
                if len > 0 {
                    b[pick(*at, len)] ^= 1 << (bit % 8);
                }
            }
            Mutation::SetByte { at, byte } => {
                if len > 0 {
                    b[pick(*at, len)] = *byte;
                }
            }
            Mutation::ReplaceToken { token, with } => {
                let t = tokens(&b);
                if !t.is_empty() {
                    let (s, e) = t[pick(*token, t.len())];
                    b.splice(s..e, with.bytes());
                }
            }
            Mutation::DeleteLine { line } => {
                let l = lines(&b);
                if !l.is_empty() {
                    let (s, e) = l[pick(*line, l.len())];
                    b.drain(s..e);
                }
            }
            Mutation::DuplicateLine { line } => {
                let l = lines(&b);
                if !l.is_empty() {
                    let (s, e) = l[pick(*line, l.len())];
                    let copy = b[s..e].to_vec();
                    b.splice(e..e, copy);
                }
            }
            Mutation::SwapLines { a, b: other } => {
                let l = lines(&b);
                if l.len() >= 2 {
                    let (i, j) = (pick(*a, l.len()), pick(*other, l.len()));
                    let (i, j) = (i.min(j), i.max(j));
                    if i != j {
                        let (first, second) = (l[i], l[j]);
                        let mut out = b[..first.0].to_vec();
                        out.extend(&b[second.0..second.1]);
                        out.extend(&b[first.1..second.0]);
                        out.extend(&b[first.0..first.1]);
                        out.extend(&b[second.1..]);
                        b = out;
                    }
                }
            }
            Mutation::DeleteRange { at, len: n } => {
                if len > 0 {
                    let s = pick(*at, len);
                    let e = (s + (*n % 64) as usize + 1).min(len);
                    b.drain(s..e);
                }
            }
            Mutation::Insert { at, text } => {
                let s = pick(*at, len + 1);
                b.splice(s..s, text.bytes());
            }
            Mutation::OverwriteWord { at, word } => {
                if len >= 8 {
                    let s = pick(*at, len / 8) * 8;
                    b[s..s + 8].copy_from_slice(word);
                }
            }
        }
        b
    }
}

/// A random mutation, text-oriented or binary-oriented.
pub fn random_mutation(rng: &mut SplitMix64, binary: bool) -> Mutation {
    let r = rng.next_u64();
    let kinds = if binary { 11 } else { 10 };
    match rng.below(kinds) {
        0 => Mutation::Truncate { per_mille: r },
        1 => Mutation::FlipBit {
            at: r,
            bit: rng.below(8) as u8,
        },
        2 => Mutation::SetByte {
            at: r,
            byte: rng.next_u64() as u8,
        },
        3 | 4 => {
            let tokens = replacement_tokens();
            Mutation::ReplaceToken {
                token: r,
                with: tokens[rng.below(tokens.len())].clone(),
            }
        }
        5 => Mutation::DeleteLine { line: r },
        6 => Mutation::DuplicateLine { line: r },
        7 => Mutation::SwapLines {
            a: r,
            b: rng.next_u64(),
        },
        8 => Mutation::DeleteRange {
            at: r,
            len: rng.next_u64(),
        },
        9 => {
            let tokens = replacement_tokens();
            Mutation::Insert {
                at: r,
                text: format!(" {} ", tokens[rng.below(tokens.len())]),
            }
        }
        _ => {
            let words = replacement_words();
            Mutation::OverwriteWord {
                at: r,
                word: words[rng.below(words.len())],
            }
        }
    }
}
