//! `cargo xtask run`: the pipeline, then every method on the held-out test trajectory, measured
//! against the full-space reference in one table (`report.json`, `report.md`).

use std::path::PathBuf;

use anyhow::Result;
use fem_core::integrator::FullSpaceModel;

use crate::output::FrameWriter;
use crate::pipeline::{Pipeline, Progress};
use crate::simulate::{Method, Runner, SimulateOptions, Trajectory, median, setup, write_json};

/// What `run` does.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Write every K-th frame of each method; 0 writes none.
    pub every: usize,
    pub methods: Vec<Method>,
    /// Which held-out test trajectory to simulate.
    pub trajectory: usize,
}

/// One row of the report.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MethodReport {
    pub method: String,
    /// Simulated dimension (free DOFs for full).
    pub dim: usize,
    /// Elements the elastic energy is evaluated on.
    pub cubature_elements: usize,
    /// Median wall time per step.
    pub ms_per_step: f64,
    pub hz: f64,
    /// Full-space ms/step divided by this method's.
    pub speedup: f64,
    /// Mean and max over frames of ‖u − u_full‖_M / ‖u_full‖_M.
    pub mean_rel_error: f64,
    pub max_rel_error: f64,
    /// Largest distance of a vertex from its full-space position over all frames.
    pub max_vertex_error: f64,
    /// Mean solver iterations per step.
    pub iterations: f64,
}

/// Errors of a trajectory against the reference, frame by frame.
#[derive(Debug, Default)]
struct ErrorAccumulator {
    rel: Vec<f64>,
    max_vertex: f64,
}

impl ErrorAccumulator {
    fn add(&mut self, model: &FullSpaceModel, u: &[f64], reference_free: &[f64]) {
        let mut r = vec![0.0; u.len()];
        model.dofs.scatter(reference_free, &mut r);
        let diff: Vec<f64> = u.iter().zip(&r).map(|(a, b)| a - b).collect();
        let mut scratch = vec![0.0; u.len()];
        let num = model.mass.half_norm_squared(&diff, &mut scratch);
        let den = model.mass.half_norm_squared(&r, &mut scratch);
        if den > 0.0 {
            self.rel.push((num / den).sqrt());
        }
        for d in diff.chunks_exact(3) {
            self.max_vertex = self
                .max_vertex
                .max((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
        }
    }
}

/// Runs the requested methods on test trajectory `opts.trajectory`; returns the report rows.
pub fn run(
    pipeline: &mut Pipeline<'_>,
    opts: &RunOptions,
    stage_progress: Progress<'_>,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<Vec<MethodReport>> {
    let reference = pipeline.reference(opts.trajectory, stage_progress)?;
    let frames = reference.frames.len();
    let full_ms = median(&reference.step_seconds) * 1e3;
    let mut rows = Vec::new();
    for &method in &opts.methods {
        let sim_opts = SimulateOptions {
            method,
            trajectory: Trajectory::Test(opts.trajectory),
            out: opts.out.join(method.name()),
            frames: Some(frames),
            every: opts.every,
            solver: None,
        };
        let writer = if opts.every > 0 {
            Some(FrameWriter::new(&sim_opts.out)?)
        } else {
            None
        };
        let row = match method {
            Method::Full => {
                let model = pipeline.test_model(opts.trajectory)?;
                if let Some(mut w) = writer {
                    w.write(&model.mesh, 0, 0.0, &vec![0.0; model.num_full()])?;
                    let mut u = vec![0.0; model.num_full()];
                    for (k, f) in reference.frames.iter().enumerate() {
                        if (k + 1) % opts.every == 0 || k + 1 == frames {
                            model.dofs.scatter(f, &mut u);
                            w.write(
                                &model.mesh,
                                k + 1,
                                (k + 1) as f64 * pipeline.scene.time.step,
                                &u,
                            )?;
                        }
                    }
                    w.finish()?;
                }
                MethodReport {
                    method: method.name().into(),
                    dim: model.dofs.num_free(),
                    cubature_elements: model.elements.len(),
                    ms_per_step: full_ms,
                    hz: 1e3 / full_ms,
                    speedup: 1.0,
                    mean_rel_error: 0.0,
                    max_rel_error: 0.0,
                    max_vertex_error: 0.0,
                    iterations: mean_usize(&reference.iterations),
                }
            }
            _ => {
                let (model, time, solver) = setup(pipeline, &sim_opts)?;
                let mut runner =
                    Runner::new(pipeline, method, model, time, solver, stage_progress)?;
                let mut writer = writer;
                if let Some(w) = writer.as_mut() {
                    w.write(&runner.model().mesh, 0, 0.0, &runner.displacement())?;
                }
                let mut errors = ErrorAccumulator::default();
                let mut times = Vec::with_capacity(frames);
                let mut iterations = Vec::with_capacity(frames);
                for k in 0..frames {
                    let info = runner.step().map_err(|e| {
                        anyhow::anyhow!("method {} failed at frame {}: {e}", method.name(), k + 1)
                    })?;
                    times.push(info.seconds);
                    iterations.push(info.iterations);
                    // Reconstruction for the error is outside the timed step.
                    let u = runner.displacement();
                    errors.add(runner.model(), &u, &reference.frames[k]);
                    if let Some(w) = writer.as_mut()
                        && ((k + 1) % opts.every == 0 || k + 1 == frames)
                    {
                        w.write(&runner.model().mesh, k + 1, runner.time(), &u)?;
                    }
                    progress(method.name(), k + 1, frames);
                }
                if let Some(w) = writer {
                    w.finish()?;
                }
                let ms = median(&times) * 1e3;
                let cubature_elements = match &runner {
                    Runner::Full(s) => s.model.elements.len(),
                    Runner::Pca(s) => s.space.elements.len(),
                    Runner::Neural(s) => s.space.elements.len(),
                };
                MethodReport {
                    method: method.name().into(),
                    dim: runner.dim(),
                    cubature_elements,
                    ms_per_step: ms,
                    hz: 1e3 / ms,
                    speedup: full_ms / ms,
                    mean_rel_error: errors.rel.iter().sum::<f64>() / errors.rel.len().max(1) as f64,
                    max_rel_error: errors.rel.iter().fold(0.0, |a, &b| a.max(b)),
                    max_vertex_error: errors.max_vertex,
                    iterations: mean_usize(&iterations),
                }
            }
        };
        rows.push(row);
    }
    write_json(&opts.out.join("report.json"), &rows)?;
    fem_core::io::write_atomic(&opts.out.join("report.md"), markdown(&rows).as_bytes())?;
    Ok(rows)
}

fn mean_usize(v: &[usize]) -> f64 {
    v.iter().sum::<usize>() as f64 / v.len().max(1) as f64
}

/// The report as a markdown table.
pub fn markdown(rows: &[MethodReport]) -> String {
    let mut s = String::from(
        "| method | dim | elements | ms/step | Hz | speed-up | mean rel. error | max rel. error | max vertex error | iterations |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {:.3} | {:.1} | {:.1}× | {:.2e} | {:.2e} | {:.2e} | {:.1} |\n",
            r.method,
            r.dim,
            r.cubature_elements,
            r.ms_per_step,
            r.hz,
            r.speedup,
            r.mean_rel_error,
            r.max_rel_error,
            r.max_vertex_error,
            r.iterations
        ));
    }
    s
}
