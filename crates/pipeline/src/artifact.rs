//! Stage artifacts on disk: serde + postcard behind a header, written atomically.
//!
//! Layout: magic `LATDYN\0a` · format version (u32) · stage name (u16 length + UTF-8) · cache
//! key (u64) · mesh hash (u64) · payload length (u64) · payload checksum (u64, FNV-1a) · header
//! checksum (u64, FNV-1a of every byte before it) · payload. Loading checks the magic and
//! version, then the header checksum (so a damaged header reads as corruption, not as another
//! stage or mesh), then that stage, mesh and key are the expected ones, then the payload length,
//! checksum and decoding, and says which command rebuilds the artifact when any is off: a
//! truncated, corrupted, outdated or foreign file is never used. Writes go to a temporary file
//! that is renamed into place, so an interrupted stage leaves the previous artifact intact.

use std::path::Path;

use fem_core::io::write_atomic;
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::stage::Stage;

const MAGIC: &[u8; 8] = b"LATDYN\0a";

/// Version of every artifact's layout and meaning; bump it when either changes so old caches
/// are recomputed instead of misread. 2: header checksum.
pub const FORMAT_VERSION: u32 = 2;

/// Why an artifact could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ArtifactError {
    /// The I/O error is part of the message, not a source error: a chain printed whole
    /// (`{:#}`) would say it twice.
    #[error("{path}: cannot read: {cause}; re-run `{}` to rebuild it", .stage.rebuild_command())]
    Io {
        path: String,
        stage: Stage,
        cause: std::io::Error,
    },
    #[error("{path}: {reason}; re-run `{}` to rebuild it", .stage.rebuild_command())]
    Invalid {
        path: String,
        stage: Stage,
        reason: String,
    },
}

impl ArtifactError {
    /// What is wrong with the artifact, without the advice to rebuild it: for a caller that
    /// rebuilds it itself.
    pub fn problem(&self) -> String {
        match self {
            Self::Io { path, cause, .. } => format!("{path}: cannot read: {cause}"),
            Self::Invalid { path, reason, .. } => format!("{path}: {reason}"),
        }
    }
}

/// FNV-1a, 64 bit: a stable hash for cache keys and checksums (it changes on any single-bit
/// flip). Not for security.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    fnv1a_continue(0xcbf2_9ce4_8422_2325, bytes)
}

fn fnv1a_continue(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Builds a cache key from the things a stage's output depends on.
#[derive(Debug, Clone)]
pub struct KeyBuilder(u64);

impl KeyBuilder {
    /// A key for `stage` at the current [`FORMAT_VERSION`] and the stage's own
    /// [`version`](Stage::version).
    pub fn new(stage: Stage) -> Self {
        let h = fnv1a(stage.name().as_bytes());
        let h = fnv1a_continue(h, &FORMAT_VERSION.to_le_bytes());
        Self(fnv1a_continue(h, &stage.version().to_le_bytes()))
    }

    /// Mixes in a serialisable value (a scene section, a list of pinned vertices, …). A
    /// negative zero is mixed as zero: `[-0.0, -9.81, 0.0]` is the same gravity.
    pub fn mix<T: Serialize + ?Sized>(mut self, value: &T) -> Self {
        let mut bytes = serde_json::to_vec(value).expect("scene values serialise to JSON");
        let mut at = 0;
        while let Some(i) = bytes[at..].windows(4).position(|w| w == b"-0.0") {
            let i = at + i;
            let number_ends = bytes.get(i + 4).is_none_or(|b| !b.is_ascii_digit());
            let number_starts = i == 0 || !bytes[i - 1].is_ascii_alphanumeric();
            if number_ends && number_starts {
                bytes.remove(i);
            }
            at = i + 1;
        }
        self.0 = fnv1a_continue(self.0, &(bytes.len() as u64).to_le_bytes());
        self.0 = fnv1a_continue(self.0, &bytes);
        self
    }

    /// Mixes in another key (an upstream stage's).
    pub fn mix_key(mut self, key: u64) -> Self {
        self.0 = fnv1a_continue(self.0, &key.to_le_bytes());
        self
    }

    pub fn finish(self) -> u64 {
        self.0
    }
}

/// Writes `value` as the artifact of `stage`.
pub fn save<T: Serialize>(
    path: &Path,
    stage: Stage,
    key: u64,
    mesh: u64,
    value: &T,
) -> std::io::Result<()> {
    let stage = stage.name();
    let payload = postcard::to_allocvec(value).map_err(std::io::Error::other)?;
    let stage_len = u16::try_from(stage.len()).map_err(std::io::Error::other)?;
    let mut bytes = Vec::with_capacity(payload.len() + 72 + stage.len());
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&stage_len.to_le_bytes());
    bytes.extend_from_slice(stage.as_bytes());
    bytes.extend_from_slice(&key.to_le_bytes());
    bytes.extend_from_slice(&mesh.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&fnv1a(&payload).to_le_bytes());
    let header_sum = fnv1a(&bytes);
    bytes.extend_from_slice(&header_sum.to_le_bytes());
    bytes.extend_from_slice(&payload);
    write_atomic(path, &bytes)
}

/// What the caller expects of an artifact.
#[derive(Debug, Clone, Copy)]
pub struct Expect {
    pub stage: Stage,
    /// The cache key, when it must match.
    pub key: Option<u64>,
    /// The mesh hash, when it must match.
    pub mesh: Option<u64>,
}

/// Reads and checks the artifact at `path`.
pub fn load<T: DeserializeOwned>(path: &Path, expect: Expect) -> Result<T, ArtifactError> {
    let shown = path.display().to_string();
    let stage = expect.stage;
    let bytes = std::fs::read(path).map_err(|cause| ArtifactError::Io {
        path: shown.clone(),
        stage,
        cause,
    })?;
    let invalid = |reason: String| ArtifactError::Invalid {
        path: shown.clone(),
        stage,
        reason,
    };
    let mut r = Reader {
        bytes: &bytes,
        at: 0,
    };
    let truncated = || {
        invalid(format!(
            "the file is truncated ({} bytes, shorter than its header)",
            bytes.len()
        ))
    };
    if r.take(8).ok_or_else(truncated)? != MAGIC {
        return Err(invalid("not an artifact of this tool (bad magic)".into()));
    }
    let version = u32::from_le_bytes(r.array().ok_or_else(truncated)?);
    if version != FORMAT_VERSION {
        return Err(invalid(format!(
            "written by artifact format version {version}, this build reads version {FORMAT_VERSION}"
        )));
    }
    let len = u16::from_le_bytes(r.array().ok_or_else(truncated)?) as usize;
    let name = r.take(len).ok_or_else(truncated)?;
    let key = u64::from_le_bytes(r.array().ok_or_else(truncated)?);
    let mesh = u64::from_le_bytes(r.array().ok_or_else(truncated)?);
    let len = u64::from_le_bytes(r.array().ok_or_else(truncated)?);
    let sum = u64::from_le_bytes(r.array().ok_or_else(truncated)?);
    let header_end = r.at;
    let header_sum = u64::from_le_bytes(r.array().ok_or_else(truncated)?);
    if fnv1a(&bytes[..header_end]) != header_sum {
        return Err(invalid(
            "header checksum mismatch (the file is corrupted)".into(),
        ));
    }
    if name != expect.stage.name().as_bytes() {
        return Err(invalid(format!(
            "holds stage `{}`, expected `{}`",
            String::from_utf8_lossy(name),
            expect.stage
        )));
    }
    if let Some(m) = expect.mesh
        && m != mesh
    {
        return Err(invalid(format!(
            "built for another mesh (mesh hash {mesh:016x}, the scene's is {m:016x}: the mesh file, its vertex count or the generated box changed)"
        )));
    }
    if let Some(k) = expect.key
        && k != key
    {
        return Err(invalid(format!(
            "built from other inputs (key {key:016x}, expected {k:016x})"
        )));
    }
    let payload = &bytes[r.at..];
    if payload.len() as u64 != len {
        return Err(invalid(format!(
            "payload is {} bytes, the header says {len} ({})",
            payload.len(),
            if (payload.len() as u64) < len {
                "truncated: was the writer interrupted?"
            } else {
                "padded or appended to"
            }
        )));
    }
    if fnv1a(payload) != sum {
        return Err(invalid(
            "payload checksum mismatch (the file is corrupted)".into(),
        ));
    }
    match postcard::take_from_bytes::<T>(payload) {
        Ok((value, [])) => Ok(value),
        Ok((_, rest)) => Err(invalid(format!(
            "the payload decodes with {} bytes left over (written by another build?)",
            rest.len()
        ))),
        Err(e) => Err(invalid(format!(
            "cannot decode the payload: {e} (written by another build?)"
        ))),
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.at.checked_add(n)?;
        let s = self.bytes.get(self.at..end)?;
        self.at = end;
        Some(s)
    }

    fn array<const N: usize>(&mut self) -> Option<[u8; N]> {
        self.take(N)?.try_into().ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("artifact-test-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join(name)
    }

    /// A negative zero keys as zero; other numbers with a minus keep it.
    #[test]
    fn negative_zero_keys_as_zero() {
        let key = |v: &[f64]| KeyBuilder::new(Stage::Pca).mix(v).finish();
        assert_eq!(key(&[-0.0, -9.81, 0.0]), key(&[0.0, -9.81, 0.0]));
        assert_eq!(key(&[-0.0]), key(&[0.0]));
        assert_ne!(key(&[-0.01]), key(&[0.01]));
        assert_ne!(key(&[-0.05, 1.0]), key(&[0.05, 1.0]));
        assert_ne!(key(&[-10.0]), key(&[10.0]));
    }

    #[test]
    fn round_trip_and_every_corruption_is_detected() {
        let p = tmp("a.art");
        let value: Vec<f64> = (0..100).map(|i| i as f64 * 0.5).collect();
        save(&p, Stage::Pca, 42, 7, &value).unwrap();
        let ok = Expect {
            stage: Stage::Pca,
            key: Some(42),
            mesh: Some(7),
        };
        assert_eq!(load::<Vec<f64>>(&p, ok).unwrap(), value);
        let msg = |e: ArtifactError| e.to_string();
        assert!(
            msg(load::<Vec<f64>>(&p, Expect { key: Some(1), ..ok }).unwrap_err())
                .contains("other inputs")
        );
        assert!(
            msg(load::<Vec<f64>>(
                &p,
                Expect {
                    mesh: Some(1),
                    ..ok
                }
            )
            .unwrap_err())
            .contains("another mesh")
        );
        assert!(
            msg(load::<Vec<f64>>(
                &p,
                Expect {
                    stage: Stage::Train,
                    ..ok
                }
            )
            .unwrap_err())
            .contains("re-run `cargo xtask train`")
        );
        let bytes = std::fs::read(&p).unwrap();
        // Every truncation and every single-bit flip is rejected.
        for cut in 0..bytes.len() {
            std::fs::write(&p, &bytes[..cut]).unwrap();
            assert!(load::<Vec<f64>>(&p, ok).is_err(), "truncated at {cut}");
        }
        for i in 0..bytes.len() {
            for bit in [0u8, 3, 7] {
                let mut b = bytes.clone();
                b[i] ^= 1 << bit;
                std::fs::write(&p, &b).unwrap();
                assert!(
                    load::<Vec<f64>>(&p, ok).is_err(),
                    "flip at byte {i} bit {bit}"
                );
            }
        }
    }
}
