//! The pipeline behind `cargo xtask`: scene files, the stages, their outputs.
//!
//! `main.rs` only parses flags, shows progress bars and dispatches here, so tests drive exactly
//! the code a user runs.

pub mod artifact;
pub mod bench;
pub mod output;
pub mod pipeline;
pub mod plot;
pub mod run;
pub mod scene;
pub mod simulate;
pub mod stress;

use std::path::PathBuf;

/// The workspace root (parent of this crate's manifest directory).
pub fn project_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("."))
}
