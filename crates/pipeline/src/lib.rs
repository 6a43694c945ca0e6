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

use std::path::{Path, PathBuf};

/// The workspace root (two levels above this crate's manifest directory, `crates/pipeline`,
/// where it was built), or the current folder when that holds no workspace any more (a binary
/// copied to another machine, or its build tree gone): `out/` is then made where it runs, not
/// at a path of the build.
pub fn project_root() -> PathBuf {
    root_or_here(Path::new(env!("CARGO_MANIFEST_DIR")))
}

/// Two levels above `manifest` when a `Cargo.toml` is there, else `.`.
fn root_or_here(manifest: &Path) -> PathBuf {
    manifest
        .ancestors()
        .nth(2)
        .filter(|root| root.join("Cargo.toml").is_file())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// The workspace this crate is built in is the root; a manifest path whose workspace is
    /// gone gives the current folder.
    #[test]
    fn the_root_is_the_workspace_while_it_exists() {
        let root = super::root_or_here(Path::new(env!("CARGO_MANIFEST_DIR")));
        assert!(
            root.join("crates/pipeline/Cargo.toml").is_file(),
            "{root:?}"
        );
        assert_eq!(
            super::root_or_here(Path::new("/nonexistent/ws/crates/pipeline")),
            Path::new(".")
        );
    }
}
