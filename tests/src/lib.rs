//! Support for the workspace's end-to-end tests (in `tests/tests/`).
//!
//! Tests that compare against independent references read them from the `shared/` folder beside
//! the repository. A user's clone has no such folder, so those tests say what they skip and why.

use std::io::Write;
use std::path::PathBuf;

/// This package's folder, read when the test runs: `cargo test` sets `CARGO_MANIFEST_DIR` for
/// the test process too, so a copy of the checkout tested against the same build (`.ci/run`
/// does this) looks beside the copy, not beside the checkout that compiled the binary. The
/// compile-time value serves a test binary started by hand.
pub fn manifest_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")))
}

/// The `shared/` folder beside the repository (or `$LATENT_SHARED_DIR`), if present; otherwise
/// prints one line saying that `what` is skipped and why.
pub fn shared_dir(what: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("LATENT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest_dir().join("../../shared"));
    if dir.is_dir() {
        return Some(dir);
    }
    skip(&format!(
        "{what}: {} not found (set LATENT_SHARED_DIR to the shared/ folder to run it)",
        dir.display()
    ));
    None
}

/// Prints `skipping <reason>` as one line on the terminal. Written to the stderr handle itself,
/// not through `eprintln!`, which the test harness captures and shows only for failed tests: a
/// skip must be seen in a passing run.
pub fn skip(reason: &str) {
    let _ = writeln!(std::io::stderr(), "skipping {reason}");
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

/// A 6×1×1-cell beam whose every stage (snapshots, PCA, autoencoder, cubature, reference) runs
/// in well under a second: the scene of the end-to-end tests, which vary it by text replacement.
/// Its full space is Newton's, the reference the tests check full-space L-BFGS against. Its
/// basis is the six PCA columns (and the fall's positions) without patch responses, whose own
/// test is `crates/pipeline/tests/patch_responses.rs`.
pub const TINY: &str = r#"
name = "tiny"
[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [6, 1, 1] }
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
density = 1000.0
[[pin]]
plane = { axis = "x", side = "min" }
[time]
step = 0.02
frames = 10
[solver]
method = "newton"
tolerance = 1.0e-8
[training]
schedules = 4
frames_per_schedule = 8
[test]
frames_per_schedule = 12
[pca]
dimension = 6
patch_responses = 0
[autoencoder]
latent_dim = 2
hidden = [16, 16]
epochs = 150
batch_size = 16
"#;

/// Scene text parsed with relative paths from the working folder, named `tiny.toml` in messages.
pub fn scene(text: &str) -> pipeline::scene::Scene {
    pipeline::scene::Scene::from_str(text, std::path::Path::new("."), "tiny.toml")
        .expect("the test scene is valid")
}

/// A progress callback that ignores its calls.
pub fn no_progress(_: usize, _: usize) {}
