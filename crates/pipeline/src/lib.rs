//! The latent-dynamics pipeline as a library: scene files, the cached stages (snapshots → PCA →
//! autoencoder → cubature), every method's simulation, and the run, bench and stress reports.
//!
//! `cargo xtask` only parses flags, shows progress bars and dispatches here, so tests and other
//! programs drive exactly the code a user runs. Long work reports progress through callbacks.
//!
//! [`pipeline::Pipeline::new`] sets faer's global parallelism to
//! [`pipeline::FAER_TASKS`] tasks, so that the stages compute the same to the bit on any
//! number of threads; a program that uses faer itself and wants another setting sets it again
//! after building a pipeline.

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
/// copied to another machine, or its build tree gone). The default outputs go by
/// [`output_root`].
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

/// Where the command line's default output folders (`out/…`) go: the project's folder
/// ([`project_root`]) when the command runs inside it (`cargo xtask` from any of its folders),
/// else the folder it runs from (a built binary copied or called from elsewhere).
pub fn output_root() -> PathBuf {
    let here = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
    root_for(&project_root(), &here)
}

/// `root` when `here` lies inside it (both as the file system resolves them), else `here`.
fn root_for(root: &Path, here: &Path) -> PathBuf {
    let resolved = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    if resolved(here).starts_with(resolved(root)) {
        root.to_path_buf()
    } else {
        here.to_path_buf()
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// Inside the project (its root or a folder below) the outputs go to the project; outside
    /// it, where the command runs.
    #[test]
    fn outputs_go_to_the_project_only_from_inside_it() {
        let root = super::project_root();
        let inside = root.join("crates");
        assert_eq!(super::root_for(&root, &inside), root);
        assert_eq!(super::root_for(&root, &root), root);
        let outside = Path::new("/").to_path_buf();
        assert_eq!(super::root_for(&root, &outside), outside);
    }

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
