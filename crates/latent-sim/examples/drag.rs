//! Loads a trained model, drags one vertex for a second of simulated time, lets go for another
//! second, and prints how fast it stepped and how far the vertex moved: what a program using a
//! model does, start to end.
//!
//! ```sh
//! cargo xtask export                       # out/cantilever/neural-cubature.ldm
//! cargo run --release -p latent-sim --example drag -- out/cantilever/neural-cubature.ldm
//! cargo run --release -p latent-sim --example drag -- out/cantilever/neural-cubature.ldm --full
//! ```
//!
//! The vertex is the surface vertex farthest from the pins, pulled against gravity by 20 % of
//! the mesh's size L with a spring of 10⁻³ E·L, or, when that is weaker, one that carries the
//! body's weight at that stretch, M|g|/(0.2 L) (on the soft default cantilever the weight sets
//! it: 1.9 kN/m, where 10⁻³ E·L is 104 N/m). Each frame reads the
//! surface back into an `f32` buffer, as a renderer would. `--full` does the same in full space
//! on the model's mesh ([`FullRuntime`]), for comparison.

use std::time::Instant;

use latent_sim::{FullRuntime, Interactive, ReducedModel, Vec3};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Prints an error as its message, not Rust's debug form of it.
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.iter().find(|a| !a.starts_with("--")) else {
        eprintln!("usage: drag MODEL [--full]   (a model file from `cargo xtask export`)");
        std::process::exit(2);
    };
    let full = args.iter().any(|a| a == "--full");
    let start = Instant::now();
    let model = ReducedModel::load(path)?;
    let load_ms = start.elapsed().as_secs_f64() * 1e3;
    let bytes = std::fs::metadata(path).map_or(0, |m| m.len());
    let p = &model.provenance;
    println!(
        "{path}: {} model of scene {} ({:.2} MB, loaded in {load_ms:.1} ms): {} vertices ({} with \
         basis rows), k = {}, latent dimension {}, {} elements evaluated",
        p.method,
        p.scene,
        bytes as f64 / 1e6,
        model.mesh.num_vertices(),
        model.space.vertices.len(),
        model.space.k,
        model.latent_dim(),
        model
            .cubature
            .as_ref()
            .map_or(model.mesh.num_tets(), |c| c.len()),
    );
    let start = Instant::now();
    if full {
        let mut sim = FullRuntime::from_model(&model)?;
        println!(
            "full space: simulator built in {:.1} ms",
            start.elapsed().as_secs_f64() * 1e3
        );
        drag(&mut sim, &model)
    } else {
        let mut sim = model.simulator()?;
        println!(
            "reduced: simulator built in {:.1} ms",
            start.elapsed().as_secs_f64() * 1e3
        );
        drag(&mut sim, &model)
    }
}

/// The drag and release on `sim`, printed.
fn drag<S: Interactive>(sim: &mut S, model: &ReducedModel) -> Result<()> {
    let rest = sim.rest_positions().to_vec();
    let surface = sim.surface().vertices().to_vec();
    // The surface vertex farthest from the pins (from the centroid when nothing is pinned).
    let anchor = if model.pinned.is_empty() {
        &surface[..]
    } else {
        &model.pinned[..]
    };
    let centre = anchor.iter().fold(Vec3::zeros(), |s, &v| s + rest[v]) / anchor.len() as f64;
    let (at, &vertex) = surface
        .iter()
        .enumerate()
        .max_by(|a, b| {
            (rest[*a.1] - centre)
                .norm()
                .total_cmp(&(rest[*b.1] - centre).norm())
        })
        .ok_or("the model has no surface")?;
    let (lo, hi) = model.mesh.bounding_box();
    let size = (hi - lo).norm();
    let g = Vec3::from(model.gravity);
    let up = if g.norm() > 0.0 {
        -g.normalize()
    } else {
        Vec3::y()
    };
    // A spring that holds the body's weight when stretched by the drag's 0.2 L (a soft, heavy
    // body hangs from it instead of falling away), and at least 10⁻³ E·L.
    let weight = model.mass() * g.norm();
    let stiffness = (1e-3 * model.material.youngs_modulus * size).max(weight / (0.2 * size));
    let steps = (1.0 / model.time_step).round().max(1.0) as usize;
    let grabbed_at = rest[vertex];
    let handle = sim.grab(&[vertex], stiffness)?;
    let mut frame = vec![0.0f32; 3 * surface.len()];
    let (mut step_s, mut read_s) = (Vec::new(), Vec::new());
    // The furthest the pose went beyond the training poses (None in full space).
    let mut beyond: Option<f64> = None;
    let position = |frame: &[f32]| {
        Vec3::new(
            frame[3 * at] as f64,
            frame[3 * at + 1] as f64,
            frame[3 * at + 2] as f64,
        )
    };
    let mut run = |sim: &mut S, frame: &mut [f32]| -> Result<()> {
        let t = Instant::now();
        let stats = sim.step()?;
        step_s.push(t.elapsed().as_secs_f64());
        if let Some(b) = stats.beyond_training {
            beyond = Some(beyond.map_or(b, |m| m.max(b)));
        }
        let t = Instant::now();
        sim.surface_positions_into(frame)?;
        read_s.push(t.elapsed().as_secs_f64());
        Ok(())
    };
    for k in 1..=steps {
        let target = grabbed_at + up * (0.2 * size * k as f64 / steps as f64);
        sim.move_handle(handle, target.into())?;
        run(sim, &mut frame)?;
    }
    let dragged = position(&frame);
    sim.release(handle)?;
    for _ in 0..steps {
        run(sim, &mut frame)?;
    }
    let after = position(&frame);
    let total: f64 = step_s.iter().sum();
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "dragged vertex {vertex} {:.3} m against gravity over {:.2} s ({steps} steps, spring {:.0} N/m), then let go for {:.2} s",
        0.2 * size,
        steps as f64 * model.time_step,
        stiffness,
        steps as f64 * model.time_step
    );
    println!(
        "{:.0} steps/s ({:.3} ms/step mean, {:.3} median); surface read-back {:.1} µs/frame median ({} vertices, f32)",
        step_s.len() as f64 / total,
        total * 1e3 / step_s.len() as f64,
        median(&mut step_s) * 1e3,
        median(&mut read_s) * 1e6,
        surface.len()
    );
    println!(
        "the vertex moved {:.4} m by the release ({:.4} m toward the target); 1 s after it, it is {:.4} m from rest",
        (dragged - grabbed_at).norm(),
        (dragged - grabbed_at).dot(&up),
        (after - grabbed_at).norm()
    );
    if let Some(b) = beyond {
        println!(
            "the pose went up to {:.0} % of its size beyond the training poses{}",
            100.0 * b,
            if b > latent_sim::coverage::OUTSIDE_TRAINING {
                ", where the model extrapolates"
            } else {
                ""
            }
        );
    }
    Ok(())
}
