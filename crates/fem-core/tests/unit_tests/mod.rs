//! Integration tests of fem-core. Tests that need `../shared/` skip with a printed reason when it
//! is absent (a user's clone has no `shared/`).

mod assembly;
mod integrator;
mod large_strain;
mod materials;
mod readers;
mod stability;

use std::io::Write;
use std::path::PathBuf;

/// This package's folder, read when the test runs: `cargo test` sets `CARGO_MANIFEST_DIR` for
/// the test process too, so a copy of the checkout tested against the same build (`.ci/run`
/// does this) looks beside the copy, not beside the checkout that compiled the binary.
pub fn manifest_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")))
}

/// The `shared/` folder beside the repository (or `$LATENT_SHARED_DIR`), if present; otherwise
/// prints one line saying that `what` is skipped and why (to the stderr handle itself: the
/// harness captures `eprintln!` and shows it only for failed tests).
pub fn shared_dir(what: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("LATENT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest_dir().join("../../../shared"));
    if dir.is_dir() {
        return Some(dir);
    }
    let _ = writeln!(
        std::io::stderr(),
        "skipping {what}: {} not found (set LATENT_SHARED_DIR to the shared/ folder to run it)",
        dir.display()
    );
    None
}
