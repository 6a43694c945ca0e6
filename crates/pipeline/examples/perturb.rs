//! How much the full-space test trajectory itself amplifies a small error
//! ([`pipeline::run::sensitivity`]): reruns it with the state (displacement and velocity)
//! scaled by 1 − ε after one frame and prints how far it ends from the cached reference.
//! (`cargo xtask run` measures, for a reduced method that drifts, the full simulation started
//! from the method's own state instead: [`pipeline::run::restart`].)
//!
//! ```sh
//! cargo xtask run --scene S.toml                  # caches the reference
//! cargo run --release -p pipeline --example perturb -- S.toml [FRAME] [EPS] [CACHE]
//! ```
//! FRAME defaults to 30, EPS to 0.01, CACHE to `out/<scene>/cache`.

use anyhow::{Context, Result, bail};
use pipeline::pipeline::Pipeline;
use pipeline::run::sensitivity;
use pipeline::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        bail!("usage: perturb SCENE.toml [FRAME] [EPS] [CACHE]");
    };
    let scene = Scene::from_file(path)?;
    let frame: usize = (args.get(1).map(|a| a.parse()).transpose())
        .context("FRAME")?
        .unwrap_or(30);
    let eps: f64 = (args.get(2).map(|a| a.parse()).transpose())
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
    let s = sensitivity(&mut p, 0, frame, eps, &|_, _| {})?;
    println!(
        "{}: state scaled by 1 − {eps} at t = {:.2} s: {:.3} % off at the last frame, {:.3} % on average from then on",
        scene.name,
        s.time,
        100.0 * s.last_error,
        100.0 * s.mean_error
    );
    Ok(())
}
