//! Profiles a reduced method on a scene's held-out test trajectory from the cached stages: the
//! sizes a step works on (latent and PCA dimensions, cubature elements, touched vertices, force
//! vertices) and the mean step time and its parts over R repeats of the trajectory, on the
//! current rayon pool (set `RAYON_NUM_THREADS=1` for one thread). Run `cargo xtask run` on the
//! scene first so that the stages are cached; this example computes any that are missing.
//!
//! ```sh
//! RAYON_NUM_THREADS=1 cargo run --release -p xtask --example latent_profile -- \
//!     data/catapult.toml neural-cubature 5
//! ```

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};

use fem_core::integrator::FullSpaceModel;
use latent_sim::{AnyReducedSimulator, ElasticPath, ReducedSimulator, ReducedSpace, Subspace};
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;
use pipeline::simulate::{Method, Runner, SimulateOptions, Trajectory, setup};

/// Mean time of one elastic energy-and-gradient evaluation by each serial path, at a fixed q,
/// over about 2.5 million element evaluations (20,000 of a 128-element rule, 185 of the whole
/// catapult).
fn time_elastic_paths(space: &ReducedSpace, model: &FullSpaceModel) {
    let k = space.k;
    let q: Vec<f64> = (0..k).map(|i| 1e-3 * (i as f64 + 0.5).sin()).collect();
    for path in [ElasticPath::ElementBasis, ElasticPath::Vertices] {
        let mut space = space.clone();
        space.set_elastic_path(model, path);
        let mut buf = space.buffers();
        let n = model.num_full();
        let (mut u, mut gf, mut gq) = (vec![0.0; n], vec![0.0; n], vec![0.0; k]);
        let reps = (2_560_000 / space.elements.len().max(1)).clamp(1, 20_000);
        let start = Instant::now();
        let mut sink = 0.0;
        for _ in 0..reps {
            sink += space.elastic_energy_gradient(model, &q, &mut u, &mut gf, &mut gq, &mut buf);
        }
        println!(
            "elastic energy and gradient, {path:?}: {:.2} µs ({sink:.3e})",
            start.elapsed().as_secs_f64() * 1e6 / reps as f64
        );
    }
}

/// Time of the Gauss–Newton matrix Jᵀ H_q J with exact tangents (what a preconditioner rebuild
/// forms before its d×d factorisation) and of the Jacobian J alone, at the initial state: the
/// best of 20 batches, which a busy machine disturbs least. A batch is 100 calls for a set of up
/// to 128 elements and fewer for larger ones (one for the whole catapult), so that a method
/// without cubature is timed in seconds, not minutes.
fn time_newton_matrix<S: Subspace>(sim: &mut ReducedSimulator<S>) {
    let (k, d) = (sim.subspace.coeff_dim(), sim.subspace.latent_dim());
    let z = sim.state.z.clone();
    let (mut h, mut jac) = (vec![0.0; d * d], vec![0.0; k * d]);
    let batch = (12_800 / sim.space.elements.len().max(1)).clamp(1, 100);
    let best = |f: &mut dyn FnMut()| {
        (0..20)
            .map(|_| {
                let start = Instant::now();
                for _ in 0..batch {
                    f();
                }
                start.elapsed().as_secs_f64() * 1e6 / batch as f64
            })
            .fold(f64::INFINITY, f64::min)
    };
    let matrix = best(&mut || sim.newton_matrix(&z, false, &mut h));
    let jacobian = best(&mut || sim.subspace.jacobian(&z, &mut jac));
    println!(
        "Gauss–Newton matrix: {matrix:.1} µs, of which the Jacobian {jacobian:.1} µs (best of 20 × {batch})"
    );
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!("usage: latent_profile SCENE METHOD [REPEATS] [CACHE]");
    }
    let path = PathBuf::from(&args[0]);
    let scene = Scene::from_file(&path)?;
    let method: Method = serde_json::from_value(serde_json::Value::String(args[1].clone()))
        .with_context(|| format!("unknown method {}", args[1]))?;
    if method.is_full() {
        bail!("latent_profile times reduced methods only");
    }
    let repeats: usize = args
        .get(2)
        .map_or(Ok(3), |r| r.parse())
        .context("REPEATS")?;
    let cache = args.get(3).map_or_else(
        || PathBuf::from("out").join(&scene.name).join("cache"),
        PathBuf::from,
    );
    let mut pipeline = Pipeline::new(&scene, &cache)?;
    let quiet = |_: usize, _: usize| {};
    let opts = SimulateOptions {
        method,
        trajectory: Trajectory::Test(0),
        out: PathBuf::from("out/latent_profile"),
        frames: None,
        every: 0,
        solver: None,
    };
    let mut sums = [0.0f64; 8];
    let mut steps = 0usize;
    let mut step_means = Vec::with_capacity(repeats);
    // Every runner is built before any steps, so that a profiler started after the setup
    // (`perf record --delay`) sees the steps only.
    let setup_start = std::time::Instant::now();
    let mut runners = Vec::with_capacity(repeats.max(1));
    for _ in 0..repeats.max(1) {
        let (model, time, solver) = setup(&pipeline, &opts)?;
        let frames = time.frames;
        runners.push((
            Runner::new(
                &mut pipeline,
                method,
                model,
                &scene.material,
                time,
                solver,
                &quiet,
            )?,
            frames,
        ));
    }
    println!(
        "setup of {} runners: {:.2} s",
        runners.len(),
        setup_start.elapsed().as_secs_f64()
    );
    for (repeat, (mut runner, frames)) in runners.into_iter().enumerate() {
        if repeat == 0 {
            let Runner::Reduced(r) = &runner else {
                unreachable!("full methods were refused above")
            };
            let sim = r.simulator();
            let (space, forces, d) = (sim.space(), &sim.model().forces, sim.latent_dim());
            let force_vertices: Vec<usize> = forces.iter().map(|f| f.vertices.len()).collect();
            println!(
                "k = {}, d = {d}, elements = {}, touched vertices = {}, force vertices = {force_vertices:?}",
                space.k,
                space.elements.len(),
                space.touched.len(),
            );
            time_elastic_paths(space, runner.model());
            if let Runner::Reduced(r) = &mut runner {
                match r.simulator_mut() {
                    AnyReducedSimulator::Linear(s) => time_newton_matrix(s),
                    AnyReducedSimulator::Neural(s) => time_newton_matrix(s),
                }
            }
        }
        let mut total = 0.0;
        for _ in 0..frames {
            let r = match &mut runner {
                Runner::Reduced(r) => r.step_report()?,
                Runner::Full(_) => unreachable!("full methods were refused above"),
            };
            total += r.wall_seconds;
            for (s, x) in sums.iter_mut().zip([
                r.wall_seconds,
                r.decode_seconds,
                r.elastic_seconds,
                r.vjp_seconds,
                r.precond_seconds,
                r.iterations as f64,
                r.evaluations as f64,
                f64::from(u8::from(r.preconditioner_rebuilt)),
            ]) {
                *s += x;
            }
            steps += 1;
        }
        step_means.push(total * 1e3 / frames as f64);
    }
    let per = |x: f64| x * 1e3 / steps as f64;
    println!(
        "mean ms/step per repeat: {:?}",
        step_means
            .iter()
            .map(|x| format!("{x:.3}"))
            .collect::<Vec<_>>()
    );
    println!(
        "mean over all: step {:.3} ms, decode {:.3}, elastic {:.3}, VJP {:.3}, preconditioner {:.3}, other {:.3}; {:.2} iterations, {:.2} evaluations per step, preconditioner rebuilt in {:.0} % of steps",
        per(sums[0]),
        per(sums[1]),
        per(sums[2]),
        per(sums[3]),
        per(sums[4]),
        per(sums[0] - sums[1] - sums[2] - sums[3] - sums[4]),
        sums[5] / steps as f64,
        sums[6] / steps as f64,
        100.0 * sums[7] / steps as f64
    );
    Ok(())
}
