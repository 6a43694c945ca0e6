//! What the pipeline's test binaries share.

use std::path::{Path, PathBuf};

use pipeline::pipeline::Pipeline;
use pipeline::run::{Measure, MethodReport};
use pipeline::simulate::Method;

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

/// The scene's own trajectory simulated in full space, writing no frames, and where they
/// would go (`dir/sim`).
#[allow(dead_code)] // Not every test binary simulates.
pub fn simulate_full(p: &mut Pipeline<'_>, dir: &Path) -> (pipeline::simulate::Summary, PathBuf) {
    try_simulate_full(p, dir).unwrap()
}

/// [`simulate_full`], its error returned.
#[allow(dead_code)] // Not every test binary simulates.
pub fn try_simulate_full(
    p: &mut Pipeline<'_>,
    dir: &Path,
) -> anyhow::Result<(pipeline::simulate::Summary, PathBuf)> {
    use pipeline::simulate::{SimulateOptions, Trajectory, simulate};
    let opts = SimulateOptions {
        method: Method::Full,
        trajectory: Trajectory::Scene,
        out: dir.join("sim"),
        frames: None,
        every: 0,
        solver: None,
    };
    let summary = simulate(p, &opts, &|_, _| {}, &mut |_, _| {})?.summary;
    Ok((summary, opts.out))
}

/// `method` run once on test trajectory 0 and compared with the reference, writing no frames
/// (`out` is where they would go).
#[allow(dead_code)] // Not every test binary measures a method.
pub fn measure(p: &mut Pipeline<'_>, method: Method, out: &Path) -> MethodReport {
    let m = Measure {
        method,
        trajectory: 0,
        out: out.to_path_buf(),
        every: 0,
        repeats: 1,
        time_budget: None,
        time_full: false,
        solver: None,
    };
    pipeline::run::measure(p, &m, &|_, _| {}, &mut |_, _, _| {}).unwrap()
}
