//! Integration tests of fem-core. Tests that need `../shared/` skip with a printed reason when it
//! is absent (a user's clone has no `shared/`).

mod assembly;
mod integrator;
mod materials;
mod readers;

use std::path::PathBuf;

/// The `shared/` folder beside the repository (or `$LATENT_SHARED_DIR`), if present.
pub fn shared_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("LATENT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "skipping: {} not found (set LATENT_SHARED_DIR to the shared/ folder to run this test)",
            dir.display()
        );
        None
    }
}
