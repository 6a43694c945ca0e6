//! Support for the workspace's end-to-end tests (in `tests/tests/`).
//!
//! Tests that compare against independent references read them from the `shared/` folder beside
//! the repository. A user's clone has no such folder, so those tests print why they skip.

use std::path::PathBuf;

/// The `shared/` folder beside the repository (or `$LATENT_SHARED_DIR`), if present; prints a
/// skip reason otherwise.
pub fn shared_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("LATENT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
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

/// A fresh empty folder under the system's temporary directory for a test's output.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir()
        .join(format!("latent-dynamics-tests-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("can create a folder under the temporary directory");
    dir
}

/// Relative difference ‖a − b‖ / ‖b‖ of two vectors.
pub fn relative_difference(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den).sqrt()
}
