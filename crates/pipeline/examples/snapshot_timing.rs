//! Times the snapshot stage's work on one schedule: training schedule `I` of a scene simulated in
//! full space for `F` frames with a chosen solver, printing per-frame wall time and iterations.
//! Set `RAYON_NUM_THREADS=1` to see one schedule's cost as the stage sees it (it runs one schedule
//! per core).
//!
//! ```sh
//! RAYON_NUM_THREADS=1 cargo run --release -p pipeline --example snapshot_timing -- \
//!     data/catapult.toml 0 40 lbfgs current-state
//! ```

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use fem_core::integrator::{Simulator, TimeConfig};
use fem_core::optim::{LbfgsPreconditioner, SolverMethod};
use fem_core::snapshots::StiffnessProbe;
use pipeline::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        bail!(
            "usage: snapshot_timing SCENE SCHEDULE FRAMES newton|lbfgs [current-state|rest] [tolerance]"
        );
    }
    let scene = Scene::from_file(PathBuf::from(&args[0]))?;
    let index: usize = args[1].parse().context("SCHEDULE")?;
    let frames: usize = args[2].parse().context("FRAMES")?;
    // The snapshot stage's solver: the scene's, at the training data's tolerance.
    let mut solver = scene.training().solver(&scene.solver);
    solver.method = match args[3].as_str() {
        "newton" => SolverMethod::Newton,
        "lbfgs" => SolverMethod::Lbfgs,
        other => bail!("unknown solver {other}"),
    };
    if let Some(p) = args.get(4) {
        solver.preconditioner = match p.as_str() {
            "current-state" => LbfgsPreconditioner::CurrentState,
            "rest" => LbfgsPreconditioner::Rest,
            other => bail!("unknown preconditioner {other}"),
        };
    }
    if let Some(t) = args.get(5) {
        solver.tolerance = t.parse().context("tolerance")?;
    }
    let model = scene.build_model()?.model;
    let pattern = fem_core::sparse::HessianPattern::new(&model.elements.tets, &model.dofs);
    let chol = fem_core::sparse_cholesky::SparseCholesky::analyse(&pattern)?;
    println!(
        "Hessian: {} nonzeros; Cholesky factor: {} nonzeros",
        pattern.nnz(),
        chol.factor_nnz()
    );
    let training = scene.training();
    let probe = StiffnessProbe::new(
        &model,
        training.frames_per_schedule as f64 * scene.time.step,
    )?;
    let mut m = model.clone();
    m.forces = training.schedule(&model, &probe, index, scene.time.step);
    // The gravity the schedule falls with (its own under `[training] gravity = "any"`).
    if let Some(g) = training.turned_gravity(&model, index) {
        m.set_gravity(g);
    }
    m.scale_gravity(training.gravity_scale);
    let time = TimeConfig {
        frames,
        ..scene.time.clone()
    };
    let mut sim = Simulator::new(m, time, solver)?;
    let start = Instant::now();
    let mut times = Vec::with_capacity(frames);
    let mut iterations = 0;
    for _ in 0..frames {
        let r = sim.step()?;
        times.push(r.wall_seconds * 1e3);
        iterations += r.iterations;
    }
    let total = start.elapsed().as_secs_f64();
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "{} dofs, {frames} frames: total {:.2} s, mean {:.1} ms, median {:.1} ms, max {:.1} ms, {:.1} iterations/frame, {} factorisations, max |u| {:.4e}",
        sim.model.dofs.num_free(),
        total,
        total * 1e3 / frames as f64,
        sorted[frames / 2],
        sorted[frames - 1],
        iterations as f64 / frames as f64,
        sim.lbfgs_factorizations(),
        sim.report().max_displacement,
    );
    Ok(())
}
