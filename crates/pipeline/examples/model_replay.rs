//! Measures a model file against `cargo xtask run`: loads `out/<scene>/<method>.ldm` (written by
//! `run` or `cargo xtask export`), drives it with the held-out test trajectory's forces through
//! latent-sim's runtime beside the runner `run` steps the method with, and prints
//!
//! - the file's size and what makes it up, its load time (median of 20) and the simulator's
//!   construction time;
//! - whether the loaded model's trajectory is `run`'s, bit for bit, step by step;
//! - the mean ms per step of both (as `report.json`'s), over R runs of the trajectory each (each a new runner and
//!   a new runtime of the loaded model, in turn), beside `report.json`'s figure for the method
//!   when there is one;
//! - the surface read-back per frame, into f32 and f64 buffers.
//!
//! ```sh
//! cargo xtask run --every 0      # or: cargo xtask export --scene S --method M
//! cargo run --release -p pipeline --example model_replay -- [SCENE.toml|builtin] [METHOD] [R]
//! ```

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use latent_sim::{Interactive, ReducedModel};
use pipeline::export::{DEFAULT_METHOD, model_path};
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;
use pipeline::simulate::{Method, Runner, SimulateOptions, Trajectory, median, setup};

/// "median (min–max)" of per-run figures.
fn spread(v: &mut [f64]) -> String {
    let m = median(v);
    v.sort_by(f64::total_cmp);
    format!("{m:.4} ({:.4}–{:.4})", v[0], v[v.len() - 1])
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = match args.first().map(String::as_str) {
        None | Some("builtin") => Scene::builtin(),
        Some(path) => Scene::from_file(path)?,
    };
    let method = match args.get(1) {
        Some(name) => serde_json::from_value::<Method>(serde_json::Value::String(name.clone()))
            .with_context(|| format!("unknown method {name}"))?,
        None => DEFAULT_METHOD,
    };
    let repeats: usize = args.get(2).map(|r| r.parse()).transpose()?.unwrap_or(5);
    let root = pipeline::project_root();
    let folder = root.join("out").join(&scene.name);
    let path = model_path(&folder, method);
    if !path.exists() {
        bail!(
            "{} is missing: run `cargo xtask run` or `cargo xtask export` first",
            path.display()
        );
    }

    // The file: size, parts, load time.
    let bytes = std::fs::metadata(&path)?.len();
    let loads: Vec<f64> = (0..20)
        .map(|_| {
            let t = Instant::now();
            let m = ReducedModel::load(&path);
            let s = t.elapsed().as_secs_f64();
            m.map(|_| s)
        })
        .collect::<Result<_, _>>()?;
    let model = ReducedModel::load(&path)?;
    let raw = std::fs::read(&path)?;
    let t = Instant::now();
    let _ = ReducedModel::from_payload(&raw[latent_sim::model::file::HEADER_LEN..])?;
    let decode = t.elapsed().as_secs_f64();
    let part = |v: &dyn erased::Size| v.size();
    println!(
        "{}: {:.3} MB; load {:.2} ms (median of 20; decode and check alone {:.2} ms); parts: basis rows {:.3} MB ({} of {} vertices × 3 × k = {}), reduced matrices {:.3} MB, mesh and surface {:.3} MB, subspace (autoencoder, directions) {:.3} MB, cubature rule {:.3} MB",
        path.display(),
        bytes as f64 / 1e6,
        median(&loads) * 1e3,
        decode * 1e3,
        (model.space.rows.len() * 8) as f64 / 1e6,
        model.space.vertices.len(),
        model.mesh.num_vertices(),
        model.space.k,
        ((model.space.mass.len()
            + model.space.rest_stiffness.len()
            + model.space.gravity_axes.len())
            * 8) as f64
            / 1e6,
        (part(&model.mesh) + part(&model.surface)) as f64 / 1e6,
        part(&model.subspace) as f64 / 1e6,
        part(&model.cubature) as f64 / 1e6,
    );

    // The runner `run` steps the method with, and the loaded model, on the test trajectory.
    let mut p = Pipeline::new(&scene, folder.join("cache"))?;
    let quiet = |_: usize, _: usize| {};
    let opts = SimulateOptions {
        method,
        trajectory: Trajectory::Test(0),
        out: PathBuf::from("out/model_replay"),
        frames: None,
        every: 0,
        solver: None,
    };
    let frames = setup(&p, &opts)?.1.frames;
    let forces = setup(&p, &opts)?.0.forces;
    let mut runner = || -> Result<Runner> {
        let (m, time, solver) = setup(&p, &opts)?;
        Runner::new(&mut p, method, m, &scene.material, time, solver, &quiet)
    };
    let Runner::Reduced(mut reference) = runner()? else {
        bail!("{} is not a reduced method", method.name());
    };
    let t = Instant::now();
    let mut sim = model.simulator()?;
    let build = t.elapsed().as_secs_f64();
    for f in forces.clone() {
        sim.add_force(f)?;
    }
    // Lockstep with a runner, reading the surface back after each step.
    let mut first_difference = None;
    let ns = sim.surface().vertices().len();
    let (mut s32, mut s64) = (vec![0.0f32; 3 * ns], vec![0.0f64; 3 * ns]);
    let (mut read32, mut read64) = (Vec::new(), Vec::new());
    for step in 1..=frames {
        sim.step()?;
        reference.step_report()?;
        let same = reference
            .coefficients()
            .iter()
            .zip(sim.coefficients())
            .all(|(a, b)| a.to_bits() == b.to_bits());
        if !same && first_difference.is_none() {
            first_difference = Some(step);
        }
        let t = Instant::now();
        sim.surface_positions_into(&mut s32)?;
        read32.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        sim.surface_positions_into(&mut s64)?;
        read64.push(t.elapsed().as_secs_f64());
    }
    // Timing: whole trajectories, steps only, in turn: a runner and a runtime built from the
    // loaded model. (The lockstep runtime above, reset and re-run, measured 4 % slower on the
    // cantilever, as did no other instance, reset or not: where its buffers were allocated.)
    let (mut runner_ms, mut runtime_ms) = (Vec::new(), Vec::new());
    let trajectory = |step: &mut dyn FnMut() -> Result<f64>| -> Result<f64> {
        // The mean step, as report.json's ms_per_step.
        let total = (0..frames).map(|_| step()).sum::<Result<f64>>()?;
        Ok(total / frames as f64 * 1e3)
    };
    for _ in 0..repeats {
        let mut r = runner()?;
        runner_ms.push(trajectory(&mut || Ok(r.step()?.seconds))?);
        let mut fresh = model.simulator()?;
        for f in forces.clone() {
            fresh.add_force(f)?;
        }
        runtime_ms.push(trajectory(&mut || Ok(fresh.step()?.seconds))?);
    }
    let report: Option<f64> = std::fs::read_to_string(folder.join("report.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| {
            v["methods"]
                .as_array()?
                .iter()
                .find(|r| r["method"] == method.name())
                .and_then(|r| r["ms_per_step"].as_f64())
        });
    println!(
        "simulator built in {:.2} ms; {frames} steps of the test trajectory: {}",
        build * 1e3,
        match first_difference {
            None => "the loaded model's coefficients are run's, bit for bit, at every step".into(),
            Some(s) => format!("DIFFERENT from run's from step {s}"),
        }
    );
    println!(
        "{}: mean ms/step, median (range) over {repeats} runs: run's runner {}, runtime of the \
         loaded model {}{}",
        method.name(),
        spread(&mut runner_ms),
        spread(&mut runtime_ms),
        report.map_or(String::new(), |r| format!("; report.json {r:.4}"))
    );
    println!(
        "surface read-back ({ns} vertices): f32 {:.2} µs/frame, f64 {:.2} µs/frame (medians)",
        median(&read32) * 1e6,
        median(&read64) * 1e6
    );
    Ok(())
}

/// Serialised sizes of the model's parts (postcard, as in the file).
mod erased {
    pub trait Size {
        fn size(&self) -> usize;
    }

    impl<T: serde::Serialize> Size for T {
        fn size(&self) -> usize {
            postcard::to_allocvec(self).map_or(0, |v| v.len())
        }
    }
}
