//! One neural-cubature latent step (`latent_step`): the reduced implicit Euler step of
//! `latent-sim` with the AutoDef "X"-shaped decoder (6 → 200 → 200 → k, ELU), on one thread, at
//! 48, 100 and 300 cubature elements.
//!
//! The scene is an earlier default cantilever's geometry and material (1 × 0.2 × 0.2 m, 20 × 4 × 4
//! cells, stable Neo-Hookean E = 2 MPa, ν = 0.45, clamped at x = 0, gravity) with a spring dragging
//! the tip for the first half second. The subspace is synthetic, so that the benchmark needs no
//! pipeline run: k = 32 smooth mass-orthonormal columns, and a decoder whose linear skip carries
//! the leading 6 coefficients and whose random nonlinear part is scaled to bend them gently, its
//! rest state anchored. Cubature elements are spread evenly over the mesh with equal weights. The
//! cost per step (decode, elastic energy, VJP, preconditioner) is what a trained subspace of the
//! same shapes costs; iterations per step depend on the subspace and are printed.
//!
//! Steps are timed from step 20 to 100 of the trajectory (then it restarts from rest, untimed),
//! so the measured steps include the drag, its release and free motion.
//!
//! ```sh
//! cargo bench -p benches --bench latent
//! ```

use std::time::{Duration, Instant};

use criterion::{Criterion, SamplingMode};
use fem_core::Vec3;
use fem_core::constraints::{Axis, Side, VertexSelection};
use fem_core::forces::{ExternalForce, ForceKind};
use fem_core::integrator::{FullSpaceModel, TimeConfig};
use fem_core::material::{MaterialConfig, MaterialModel};
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::optim::{SolverConfig, SolverMethod};
use latent_sim::{NeuralSubspace, ReducedSimulator, ReducedSpace};
use nn::{Activation, Autoencoder, SplitMix64};
use rayon::ThreadPoolBuilder;

/// PCA coefficients k and latent dimension d of the X shape.
const K: usize = 32;
const D: usize = 6;
/// Steps from rest before timing starts, and the last step timed before a restart.
const WARM_STEPS: usize = 20;
const LAST_STEP: usize = 100;
/// Cubature sizes.
const ELEMENTS: [usize; 3] = [48, 100, 300];

fn model() -> FullSpaceModel {
    let mesh = box_mesh(&BoxSpec {
        size: [1.0, 0.2, 0.2],
        cells: [20, 4, 4],
        ..Default::default()
    })
    .expect("a valid box");
    let pinned = VertexSelection::plane(Axis::X, Side::Min, None)
        .select(&mesh, "pin")
        .expect("the x-min plane selects vertices");
    let tip: Vec<usize> = (0..mesh.num_vertices())
        .filter(|&v| (mesh.vertices[v] - Vec3::new(1.0, 0.1, 0.1)).norm() < 0.08)
        .collect();
    let spring = ExternalForce {
        kind: ForceKind::Spring,
        vertices: tip,
        stiffness: 2000.0,
        keyframes: vec![[0.0, 0.0, 0.0, 0.0], [0.3, 0.0, 0.25, 0.05]],
        start: 0.0,
        end: 0.5,
    };
    let material = MaterialConfig {
        model: MaterialModel::StableNeoHookean,
        youngs_modulus: 2.0e6,
        poisson_ratio: 0.45,
        density: 1000.0,
        ..Default::default()
    };
    FullSpaceModel::new(
        mesh,
        &material,
        pinned,
        Vec3::new(0.0, -9.81, 0.0),
        vec![spring],
    )
    .expect("a valid model")
}

/// k smooth columns (low-order bending and stretching shapes), mass-orthonormalised.
fn basis(model: &FullSpaceModel) -> pca::PcaBasis {
    let n = model.dofs.num_free();
    let mut u = vec![0.0; n * K];
    for j in 0..K {
        let (freq, axis) = ((j / 3 + 1) as f64, j % 3);
        for (r, &dof) in model.dofs.free.iter().enumerate() {
            let x = model.mesh.vertices[dof / 3];
            let along = if dof % 3 == axis { 1.0 } else { 0.2 };
            u[j * n + r] = along * (0.5 * freq * std::f64::consts::PI * x.x).sin() * x.x
                + 0.05 * (freq * (x.y + 2.0 * x.z)).cos() * x.x;
        }
    }
    let m: Vec<f64> = model
        .dofs
        .free
        .iter()
        .map(|&d| model.mass.lumped[d / 3])
        .collect();
    for j in 0..K {
        for i in 0..j {
            let p: f64 = (0..n).map(|r| u[i * n + r] * m[r] * u[j * n + r]).sum();
            for r in 0..n {
                u[j * n + r] -= p * u[i * n + r];
            }
        }
        let norm = (0..n)
            .map(|r| u[j * n + r].powi(2) * m[r])
            .sum::<f64>()
            .sqrt();
        for r in 0..n {
            u[j * n + r] /= norm;
        }
    }
    pca::PcaBasis::new(n, K, u, Some(m), vec![1.0; K]).expect("a valid basis")
}

/// The X-shaped decoder: linear skip on the leading d coefficients plus a random ELU network
/// scaled down to a gentle bend, rest state anchored.
fn autoencoder() -> Autoencoder {
    let mut ae = Autoencoder::with_architecture(K, D, &[200, 200], Activation::Elu, None, 11)
        .and_then(Autoencoder::with_skip)
        .expect("a valid architecture");
    let (encoder, decoder) = ae.networks_mut();
    let mut rng = SplitMix64::new(12);
    for net in [encoder, decoder] {
        let last = net.num_layers() - 1;
        for w in net.weights_mut(last) {
            *w = 1e-3 * rng.range(-1.0, 1.0);
        }
    }
    ae.anchor(&[0.0; K]);
    ae
}

/// A simulator at rest with `elements` cubature elements spread evenly (equal weights).
fn simulator(elements: usize) -> ReducedSimulator<NeuralSubspace> {
    let m = model();
    let total = m.elements.len();
    let chosen: Vec<usize> = (0..elements).map(|i| i * total / elements).collect();
    let rule = cubature::CubatureRule {
        elements: chosen,
        weights: vec![total as f64 / elements as f64; elements],
        training_error: 0.0,
        tolerance_met: true,
        error_curve: Vec::new(),
    };
    let space = ReducedSpace::new(&m, &basis(&m), Some(&rule)).expect("a valid space");
    let solver = SolverConfig {
        method: SolverMethod::Lbfgs,
        tolerance: 1e-4,
        max_iterations: 100,
        ..Default::default()
    };
    let time = TimeConfig {
        step: 0.01,
        frames: LAST_STEP,
        quasi_static: false,
    };
    ReducedSimulator::new(m, space, NeuralSubspace::new(autoencoder()), time, solver)
        .expect("a valid simulator")
}

fn warm(sim: &mut ReducedSimulator<NeuralSubspace>) {
    for _ in 0..WARM_STEPS {
        sim.step().expect("the warm-up steps converge");
    }
}

fn bench_latent_step(c: &mut Criterion) {
    let pool = ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("can start a rayon thread pool");
    let mut group = c.benchmark_group("latent_step");
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4));
    for elements in ELEMENTS {
        pool.install(|| {
            // One untimed pass for the figures criterion does not show.
            let mut sim = simulator(elements);
            warm(&mut sim);
            let (mut iterations, mut steps) = (0usize, 0usize);
            let mut parts = [0.0f64; 4];
            while sim.state.step < LAST_STEP {
                let r = sim.step().expect("the step converges");
                iterations += r.iterations;
                steps += 1;
                for (p, s) in parts.iter_mut().zip([
                    r.decode_seconds,
                    r.elastic_seconds,
                    r.vjp_seconds,
                    r.precond_seconds,
                ]) {
                    *p += s;
                }
            }
            let ms = |s: f64| s * 1e3 / steps as f64;
            println!(
                "latent_step/x-{elements}el: {:.1} iterations/step; mean ms/step: decode {:.4}, \
                 elastic {:.4}, VJP {:.4}, preconditioner {:.4}",
                iterations as f64 / steps as f64,
                ms(parts[0]),
                ms(parts[1]),
                ms(parts[2]),
                ms(parts[3])
            );
        });
        group.bench_function(format!("x-{elements}el/1t"), |b| {
            b.iter_custom(|iters| {
                pool.install(|| {
                    let mut sim = simulator(elements);
                    warm(&mut sim);
                    let mut total = Duration::ZERO;
                    for _ in 0..iters {
                        if sim.state.step >= LAST_STEP {
                            sim = simulator(elements);
                            warm(&mut sim);
                        }
                        let start = Instant::now();
                        sim.step().expect("the step converges");
                        total += start.elapsed();
                    }
                    total
                })
            });
        });
    }
    group.finish();
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    bench_latent_step(&mut c);
    c.final_summary();
}
