//! How much the full-space test trajectory itself amplifies a small error: reruns it with the
//! state (displacement and velocity) scaled by 1 − ε at one frame, and prints the perturbed
//! trajectory's relative distance (lumped-mass norm) from the cached reference, frame by frame.
//! A reduced method makes an error of this size at every step (its one-step error in
//! `report.json`); when one such error grows several-fold by the end, the test measures the
//! scene's sensitivity as much as the subspace.
//!
//! ```sh
//! cargo xtask run --scene S.toml                  # caches the reference
//! cargo run --release -p pipeline --example perturb -- S.toml [FRAME] [EPS] [CACHE]
//! ```
//! FRAME defaults to 30, EPS to 0.01, CACHE to `out/<scene>/cache`.

use anyhow::{Context, Result, bail};
use fem_core::integrator::{Simulator, TimeConfig};
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        bail!("usage: perturb SCENE.toml [FRAME] [EPS] [CACHE]");
    };
    let scene = Scene::from_file(path.as_ref())?;
    let frame: usize = args
        .get(1)
        .map(|a| a.parse())
        .transpose()
        .context("FRAME")?
        .unwrap_or(30);
    let eps: f64 = args
        .get(2)
        .map(|a| a.parse())
        .transpose()
        .context("EPS")?
        .unwrap_or(0.01);
    let cache = match args.get(3) {
        Some(c) => c.into(),
        None => pipeline::project_root()
            .join("out")
            .join(&scene.name)
            .join("cache"),
    };
    let mut p = Pipeline::new(&scene, &cache)?;
    let reference = p.reference(0, &|_, _| {})?;
    let frames = reference.frames.len();
    if frame >= frames {
        bail!("FRAME = {frame} is past the reference's {frames} frames");
    }
    let time = TimeConfig {
        frames,
        ..scene.time.clone()
    };
    let mut sim = Simulator::new(p.test_model(0)?, time, scene.solver.clone())?;
    let weights: Vec<f64> = (sim.model.dofs.free.iter())
        .map(|&d| sim.model.mass.lumped[d / 3])
        .collect();
    let norm = |a: &[f64]| {
        (a.iter().zip(&weights))
            .map(|(x, m)| m * x * x)
            .sum::<f64>()
            .sqrt()
    };
    let mut free = vec![0.0; sim.model.dofs.num_free()];
    let mut errors = Vec::with_capacity(frames);
    for (f, r) in reference.frames.iter().enumerate() {
        if f == frame {
            sim.state.u.iter_mut().for_each(|x| *x *= 1.0 - eps);
            sim.state.v.iter_mut().for_each(|x| *x *= 1.0 - eps);
        }
        sim.step()?;
        sim.model.dofs.gather(&sim.state.u, &mut free);
        let d: Vec<f64> = free.iter().zip(r).map(|(a, b)| a - b).collect();
        errors.push(norm(&d) / norm(r).max(f64::MIN_POSITIVE));
    }
    let mean = errors.iter().sum::<f64>() / frames as f64;
    let max = errors.iter().copied().fold(0.0, f64::max);
    println!(
        "{}: state scaled by 1 − {eps} at frame {frame}: mean relative error {:.3} %, max {:.3} %, last {:.3} %",
        scene.name,
        100.0 * mean,
        100.0 * max,
        100.0 * errors[frames - 1]
    );
    for (f, e) in errors.iter().enumerate().skip(frame).step_by(10) {
        println!(
            "  t = {:.2} s: {:.3} %",
            (f + 1) as f64 * scene.time.step,
            100.0 * e
        );
    }
    Ok(())
}
