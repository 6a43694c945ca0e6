//! The model file: a fixed header, then the model serialised with postcard.
//!
//! Layout (little-endian): magic `LATDYNm\0` · format version (u32) · payload length (u64) ·
//! payload checksum (u64, FNV-1a) · header checksum (u64, FNV-1a of the 28 bytes before it) ·
//! payload. Reading checks, in order, that the magic is this format's, the version one this
//! build reads, the header intact, the payload as long as announced and intact, that it decodes
//! with nothing left over and that the decoded model is consistent ([`ReducedModel::check`]);
//! each failure is its own [`ModelFormatError`], never a panic. Writing goes through a temporary
//! file renamed into place ([`fem_core::io::write_atomic`]), so a reader never sees a half-written
//! model and an interrupted export leaves the previous one intact.

use std::path::{Path, PathBuf};

use super::ReducedModel;

/// The first eight bytes of every model file.
pub const MAGIC: &[u8; 8] = b"LATDYNm\0";

/// Version of the file's layout and of the model's serialised form. Bump it when either
/// changes, so that an older build refuses a newer file instead of misreading it.
pub const FORMAT_VERSION: u32 = 4;

/// Bytes before the payload.
pub const HEADER_LEN: usize = 8 + 4 + 8 + 8 + 8;

/// What is wrong with the bytes of a model file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelFormatError {
    /// Shorter than its header, or than the payload its header announces.
    #[error(
        "the file is truncated: {len} bytes where its {what} needs {needed} (was the writer \
         interrupted?)"
    )]
    Truncated {
        len: u64,
        needed: u64,
        what: &'static str,
    },
    /// Not a model file of this project (the magic does not match).
    #[error("not a latent-dynamics model file (its first bytes are not the model magic)")]
    Foreign,
    /// Written by a newer build.
    #[error(
        "written in model format version {version}; this build reads version {supported}: update \
         latent-sim to read it"
    )]
    NewerFormat { version: u32, supported: u32 },
    /// Written by an older build, in a format this one no longer reads.
    #[error(
        "written in model format version {version}; this build reads version {supported}: export \
         the model again with `cargo xtask export`"
    )]
    OlderFormat { version: u32, supported: u32 },
    /// The header's checksum does not match the header.
    #[error("the header checksum does not match (the file is corrupted)")]
    HeaderCorrupted,
    /// The payload's checksum does not match the payload.
    #[error("the payload checksum does not match (the file is corrupted)")]
    PayloadCorrupted,
    /// Bytes after the payload the header announces.
    #[error("{extra} bytes follow the payload its header announces (appended to?)")]
    TrailingBytes { extra: u64 },
    /// The payload is intact but does not decode as a model.
    #[error("the payload does not decode as a model: {reason}")]
    Decode { reason: String },
    /// The model decodes but is inconsistent.
    #[error("the model is inconsistent: {reason}")]
    Invalid { reason: String },
}

/// Why a model file could not be read or written; names the file. The message holds the
/// cause (not chained as a source too, which printed it twice).
#[derive(Debug, thiserror::Error)]
pub enum ModelFileError {
    #[error("{}: cannot read: {cause}", path.display())]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{}: cannot write: {cause}", path.display())]
    Write {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{}: {cause}", path.display())]
    Format {
        path: PathBuf,
        cause: ModelFormatError,
    },
}

impl ModelFileError {
    /// What is wrong with the content, when the file could be read.
    pub fn format(&self) -> Option<&ModelFormatError> {
        match self {
            ModelFileError::Format { cause, .. } => Some(cause),
            _ => None,
        }
    }
}

/// FNV-1a, 64 bit (the stage artifacts' checksum): it changes on any single-bit flip.
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// `bytes[at..at + N]`, which the caller has checked exist.
fn field<const N: usize>(bytes: &[u8], at: usize) -> [u8; N] {
    let mut out = [0; N];
    out.copy_from_slice(&bytes[at..at + N]);
    out
}

/// Checks the header of a model file of `len` bytes, `head` its first bytes (all of them, up
/// to [`HEADER_LEN`]), and returns the payload's checksum: everything [`ReducedModel::from_bytes`]
/// checks before it reads the payload, so that a file is judged by its first bytes and its
/// length before the rest is read.
fn check_header(head: &[u8], len: u64) -> Result<u64, ModelFormatError> {
    let truncated = |needed: usize, what| ModelFormatError::Truncated {
        len,
        needed: needed as u64,
        what,
    };
    // A short file is truncated if what it has is the start of a model file, foreign if not.
    let magic_len = head.len().min(MAGIC.len());
    if head[..magic_len] != MAGIC[..magic_len] {
        return Err(ModelFormatError::Foreign);
    }
    if head.len() < 12 {
        return Err(truncated(HEADER_LEN, "header"));
    }
    let version = u32::from_le_bytes(field(head, 8));
    if version > FORMAT_VERSION {
        return Err(ModelFormatError::NewerFormat {
            version,
            supported: FORMAT_VERSION,
        });
    }
    if version < FORMAT_VERSION {
        return Err(ModelFormatError::OlderFormat {
            version,
            supported: FORMAT_VERSION,
        });
    }
    if head.len() < HEADER_LEN {
        return Err(truncated(HEADER_LEN, "header"));
    }
    let payload_len = u64::from_le_bytes(field(head, 12));
    let payload_sum = u64::from_le_bytes(field(head, 20));
    let header_sum = u64::from_le_bytes(field(head, 28));
    if fnv1a(&head[..28]) != header_sum {
        return Err(ModelFormatError::HeaderCorrupted);
    }
    let have = len.saturating_sub(HEADER_LEN as u64);
    if have < payload_len {
        return Err(ModelFormatError::Truncated {
            len,
            needed: (HEADER_LEN as u64).saturating_add(payload_len),
            what: "payload",
        });
    }
    if have > payload_len {
        return Err(ModelFormatError::TrailingBytes {
            extra: have - payload_len,
        });
    }
    Ok(payload_sum)
}

impl ReducedModel {
    /// The model as the bytes of a model file.
    pub fn to_bytes(&self) -> Vec<u8> {
        let payload =
            postcard::to_allocvec(self).expect("a model serialises (no maps, no unsized values)");
        let mut bytes = Vec::with_capacity(HEADER_LEN + payload.len());
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&fnv1a(&payload).to_le_bytes());
        let header_sum = fnv1a(&bytes);
        bytes.extend_from_slice(&header_sum.to_le_bytes());
        bytes.extend_from_slice(&payload);
        bytes
    }

    /// Reads the bytes of a model file (see the [module documentation](self)).
    ///
    /// # Errors
    /// One [`ModelFormatError`] per way the bytes can be wrong.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, ModelFormatError> {
        let head = &bytes[..bytes.len().min(HEADER_LEN)];
        let payload_sum = check_header(head, bytes.len() as u64)?;
        Self::from_summed_payload(&bytes[HEADER_LEN..], payload_sum)
    }

    /// The payload whose header passed ([`check_header`]), checked against its checksum, then
    /// decoded.
    fn from_summed_payload(payload: &[u8], sum: u64) -> Result<Self, ModelFormatError> {
        if fnv1a(payload) != sum {
            return Err(ModelFormatError::PayloadCorrupted);
        }
        Self::from_payload(payload)
    }

    /// Decodes and checks a payload without its header: what [`Self::from_bytes`] does once the
    /// header and checksums have passed. For tools and fuzzing, which want to reach the decoder
    /// without forging checksums.
    ///
    /// # Errors
    /// [`ModelFormatError::Decode`] or [`ModelFormatError::Invalid`].
    pub fn from_payload(payload: &[u8]) -> Result<Self, ModelFormatError> {
        let mut model = match postcard::take_from_bytes::<Self>(payload) {
            Ok((model, [])) => model,
            Ok((_, rest)) => {
                return Err(ModelFormatError::Decode {
                    reason: format!("{} bytes left over after the model", rest.len()),
                });
            }
            Err(e) => {
                return Err(ModelFormatError::Decode {
                    reason: e.to_string(),
                });
            }
        };
        model
            .check()
            .map_err(|reason| ModelFormatError::Invalid { reason })?;
        // Files written before 2026-12-02 wound the surface inward: turn it outward.
        if model.mesh.enclosed_volume(&model.surface) < 0.0 {
            model.surface.iter_mut().for_each(|t| t.swap(1, 2));
        }
        Ok(model)
    }

    /// Writes the model file at `path` atomically.
    ///
    /// # Errors
    /// [`ModelFileError::Write`].
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), ModelFileError> {
        let path = path.as_ref();
        fem_core::io::write_atomic(path, &self.to_bytes()).map_err(|cause| ModelFileError::Write {
            path: path.to_path_buf(),
            cause,
        })
    }

    /// Reads the model file at `path`.
    ///
    /// # Errors
    /// [`ModelFileError::Read`], or [`ModelFileError::Format`] with what is wrong with the
    /// content (truncated, corrupted, foreign, newer, …).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ModelFileError> {
        let path = path.as_ref();
        let read = |cause| ModelFileError::Read {
            path: path.to_path_buf(),
            cause,
        };
        // Only a regular file: a device or a pipe may never end (/dev/zero filled memory, a
        // FIFO blocked past Ctrl-C), and a folder is not a model.
        let meta = std::fs::metadata(path).map_err(read)?;
        if !meta.is_file() {
            return Err(read(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a regular file",
            )));
        }
        let format = |cause| ModelFileError::Format {
            path: path.to_path_buf(),
            cause,
        };
        // The header first: a file that is not a model, or whose length is not the one its
        // header announces, is refused before the rest of it is read (a 3 GiB file was read
        // whole to be told so). The length is the open file's: a model renamed into place
        // after the check above is read whole as itself.
        use std::io::Read;
        let mut file = std::fs::File::open(path).map_err(read)?;
        let len = file.metadata().map_err(read)?.len();
        let mut head = Vec::with_capacity(HEADER_LEN);
        (&mut file)
            .take(HEADER_LEN as u64)
            .read_to_end(&mut head)
            .map_err(read)?;
        let payload_sum = check_header(&head, len).map_err(format)?;
        // As long as the header says, and one byte more to see a file that grew meanwhile;
        // a length this machine cannot hold is an error, not an abort.
        let expected = len.saturating_sub(HEADER_LEN as u64);
        let mut payload = Vec::new();
        usize::try_from(expected)
            .ok()
            .and_then(|n| payload.try_reserve_exact(n).ok())
            .ok_or_else(|| read(std::io::Error::from(std::io::ErrorKind::OutOfMemory)))?;
        file.take(expected + 1)
            .read_to_end(&mut payload)
            .map_err(read)?;
        if payload.len() as u64 != expected {
            // Written to while read: judged as the bytes read, as from_bytes does.
            head.extend_from_slice(&payload);
            return Self::from_bytes(&head).map_err(format);
        }
        Self::from_summed_payload(&payload, payload_sum).map_err(format)
    }
}
