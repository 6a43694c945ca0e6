//! What the pipeline's test binaries share.

use std::path::PathBuf;

/// An empty folder `name` under this test process's own folder in the system's temporary
/// directory (each test binary is its own process, so binaries never share one).
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir()
        .join(format!("pipeline-tests-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
