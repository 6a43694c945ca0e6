//! `cargo xtask simulate`: time-step a scene and write frames, a series file and a summary.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use fem_core::integrator::{Simulator, State, StepReport};
use fem_core::io::write_atomic;
use fem_core::optim::SolverMethod;

use crate::output::FrameWriter;
use crate::scene::Scene;

/// Simulation methods. Later stages add reduced ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Full-space finite elements.
    #[default]
    Full,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Full => "full",
        }
    }
}

/// What to simulate and what to write.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    pub method: Method,
    /// Output folder.
    pub out: PathBuf,
    /// Overrides `[time] frames`.
    pub frames: Option<usize>,
    /// Write every K-th frame (and the last); 0 writes no frames.
    pub every: usize,
    /// Overrides `[solver] method`.
    pub solver: Option<SolverMethod>,
}

/// What `summary.json` holds.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Summary {
    pub scene: String,
    pub method: Method,
    pub solver: SolverMethod,
    pub vertices: usize,
    pub tets: usize,
    pub free_dofs: usize,
    pub flipped_tets: usize,
    pub frames_written: usize,
    pub total_seconds: f64,
    pub median_step_ms: f64,
    pub steps: Vec<StepReport>,
}

/// The summary and the final state of a finished simulation.
#[derive(Debug)]
pub struct SimulationResult {
    pub summary: Summary,
    pub final_state: State,
}

/// Runs `scene` with `opts`; `progress(done, total)` is called after every step.
///
/// A failing step (divergence, no convergence, an inverted element the material cannot handle)
/// ends the run with an error naming the step; frames before it stay on disk with their series
/// file and summary, and the failed state is never written as a frame.
pub fn simulate(
    scene: &Scene,
    opts: &SimulateOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SimulationResult> {
    let (model, report) = scene.build_model()?;
    let mut time = scene.time.clone();
    if let Some(f) = opts.frames {
        time.frames = f;
    }
    let mut solver = scene.solver.clone();
    if let Some(m) = opts.solver {
        solver.method = m;
    }
    let mut sim = Simulator::new(model, time.clone(), solver.clone())
        .map_err(|e| anyhow::anyhow!("{}: {e}", scene.source))?;
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("cannot create output folder {}", opts.out.display()))?;
    let mut writer = FrameWriter::new(&opts.out)?;
    if opts.every > 0 {
        writer.write(&sim.model.mesh, 0, 0.0, &sim.state.u)?;
    }
    let start = Instant::now();
    let mut steps = vec![sim.report()];
    let mut failure = None;
    for k in 1..=time.frames {
        match sim.step() {
            Ok(r) => steps.push(r),
            Err(e) => {
                failure = Some(e);
                break;
            }
        }
        if opts.every > 0 && (k % opts.every == 0 || k == time.frames) {
            writer.write(&sim.model.mesh, k, sim.state.time, &sim.state.u)?;
        }
        progress(k, time.frames);
    }
    let total_seconds = start.elapsed().as_secs_f64();
    if opts.every > 0 {
        writer.finish()?;
    }
    let mut times: Vec<f64> = steps[1..].iter().map(|s| s.wall_seconds * 1e3).collect();
    times.sort_by(f64::total_cmp);
    let summary = Summary {
        scene: scene.name.clone(),
        method: opts.method,
        solver: solver.method,
        vertices: sim.model.mesh.num_vertices(),
        tets: sim.model.mesh.num_tets(),
        free_dofs: sim.model.dofs.num_free(),
        flipped_tets: report.flipped_tets,
        frames_written: writer.frames_written(),
        total_seconds,
        median_step_ms: times.get(times.len() / 2).copied().unwrap_or(0.0),
        steps,
    };
    write_json(&opts.out.join("summary.json"), &summary)?;
    if let Some(e) = failure {
        anyhow::bail!(
            "{}: simulation with method {} stopped: {e}; frames up to step {} are in {}",
            scene.source,
            opts.method.name(),
            sim.state.step,
            opts.out.display()
        );
    }
    Ok(SimulationResult {
        summary,
        final_state: sim.state,
    })
}

/// Writes pretty JSON atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    write_atomic(path, text.as_bytes()).with_context(|| format!("cannot write {}", path.display()))
}
