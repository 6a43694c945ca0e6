//! The latent-dynamics pipeline as a library: scene files, the cached stages (snapshots → PCA →
//! autoencoder → cubature), every method's simulation, and the run, bench and stress reports.
//!
//! `cargo xtask` only parses flags, shows progress bars and dispatches here, so tests and other
//! programs drive exactly the code a user runs. Long work reports progress through callbacks.

pub mod artifact;
pub mod bench;
pub mod coverage;
pub mod export;
pub mod output;
pub mod pipeline;
pub mod plot;
pub mod run;
pub mod scene;
pub mod shard;
pub mod simulate;
pub mod stage;
pub mod stage_report;
pub mod stress;
pub mod suite;
pub mod trajectories;
pub mod trust;

use std::path::PathBuf;

/// The workspace root (two levels above this crate's manifest directory, `crates/pipeline`).
pub fn project_root() -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    manifest
        .ancestors()
        .nth(2)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("."))
}
