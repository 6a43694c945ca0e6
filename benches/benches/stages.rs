//! The offline stages between snapshots and training: the PCA fit (`pca_fit`) and the cubature
//! fit (`cubature`), on synthetic inputs of the shipped scenes' sizes, so no pipeline run is needed.
//!
//! * `pca_fit/<n>x<N>`: mass-weighted thin SVD and the max-vertex-error dimension rule (the scenes'
//!   rule, at 1 % of the largest vertex displacement) on a rank-400 snapshot matrix with a spectrum
//!   decaying like 1/m²: n = 1,500 free DOFs (an earlier default cantilever) and 9,759 (the
//!   catapult), N = 1,920 snapshots (32 schedules of 60 frames, the scenes' training default).
//! * `cubature/build` and `cubature/fit`: the training matrix of 150 poses and the greedy + NNLS
//!   fit to the default 2 % on a 20 × 4 × 4-cell beam (an earlier default scene's mesh, 1,920 tets)
//!   with a 10-mode smooth basis: the cubature tests' fixture.
//! * `cubature/build-nonlinear`: the neural rule's training matrix on the same beam and poses,
//!   at the sizes of a 27k-tet minimal scene's neural methods: k = 60 reduced coordinates (the 10
//!   modes and 50 more columns the poses leave at zero) and Jacobians of 60 × 50, so each
//!   element and pose costs the product Jᵀ(U_eᵀf) of the stage.
//!
//! ```sh
//! cargo bench -p benches --bench stages
//! ```

#[path = "../../crates/cubature/tests/unit_tests/fixture.rs"]
mod fixture;

use std::time::Duration;

use criterion::{Criterion, SamplingMode};
use cubature::{CubatureConfig, Poses, TrainingMatrix, fit};
use faer::Mat;
use fem_core::rng::SplitMix64;
use pca::{PcaBasis, PcaConfig};

/// Snapshots of the scenes' training default: 32 schedules × 60 frames.
const SNAPSHOTS: usize = 1_920;

/// A rank-400 n × N snapshot matrix with singular values decaying like 1/m², and a lumped-mass
/// diagonal varying by vertex.
fn snapshots(n: usize) -> (Mat<f64>, Vec<f64>) {
    let r = 400.min(n).min(SNAPSHOTS);
    let mut rng = SplitMix64::new(7);
    let a = Mat::from_fn(n, r, |_, m| rng.range(-1.0, 1.0) / ((m + 1) as f64).powi(2));
    let b = Mat::from_fn(r, SNAPSHOTS, |_, _| rng.range(-1.0, 1.0));
    let mass = (0..n).map(|i| 1.0 + ((i / 3) % 7) as f64 * 0.1).collect();
    (a * b, mass)
}

fn largest_vertex_displacement(s: &Mat<f64>) -> f64 {
    let mut largest = 0.0f64;
    for j in 0..s.ncols() {
        for v in 0..s.nrows() / 3 {
            let d = (0..3).map(|c| s[(3 * v + c, j)].powi(2)).sum::<f64>();
            largest = largest.max(d.sqrt());
        }
    }
    largest
}

fn bench_pca(c: &mut Criterion) {
    let mut group = c.benchmark_group("pca_fit");
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(20));
    for n in [1_500, 9_759] {
        let (s, mass) = snapshots(n);
        let config = PcaConfig::by_max_vertex_error(0.01 * largest_vertex_displacement(&s));
        let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &config, 3).expect("a valid fit");
        println!(
            "pca_fit/{n}x{SNAPSHOTS}: k = {} (tolerance met: {})",
            fit.chosen_k(),
            fit.tolerance_met
        );
        group.bench_function(format!("{n}x{SNAPSHOTS}"), |b| {
            b.iter(|| PcaBasis::fit(s.as_ref(), Some(&mass), &config, 3).expect("a valid fit"))
        });
    }
    group.finish();
}

fn bench_cubature(c: &mut Criterion) {
    let model = fixture::beam([20, 4, 4]);
    let (basis, k, lambda) = fixture::modal_basis(&model);
    let poses = fixture::random_poses(&model, &basis, &lambda, 150, 11);
    let config = CubatureConfig::default();
    let build = || {
        TrainingMatrix::build(&model, &basis, k, Poses::linear(poses.as_ref()), &config)
            .expect("a valid training matrix")
    };
    let data = build();
    let rule = fit(&data, &config).expect("a fit");
    println!(
        "cubature: {} tets, k = {k}, {} poses: {} elements at training error {:.4}",
        model.elements.len(),
        data.num_poses(),
        rule.len(),
        rule.training_error
    );
    let mut group = c.benchmark_group("cubature");
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1));
    group.bench_function("build", |b| b.iter(build));
    group.bench_function("fit", |b| b.iter(|| fit(&data, &config).expect("a fit")));

    let (wide, d) = (60, 50);
    let nf = model.dofs.num_free();
    let mut rng = SplitMix64::new(5);
    let mut basis_wide = basis.clone();
    basis_wide.extend((0..(wide - k) * nf).map(|_| rng.range(-1.0, 1.0)));
    let q = Mat::from_fn(
        wide,
        poses.ncols(),
        |i, j| if i < k { poses[(i, j)] } else { 0.0 },
    );
    let jacobians: Vec<Mat<f64>> = (0..poses.ncols())
        .map(|_| Mat::from_fn(wide, d, |_, _| rng.range(-1.0, 1.0)))
        .collect();
    let refs: Vec<_> = jacobians.iter().map(|j| j.as_ref()).collect();
    group.bench_function("build-nonlinear", |b| {
        b.iter(|| {
            TrainingMatrix::build(
                &model,
                &basis_wide,
                wide,
                Poses::nonlinear(q.as_ref(), &refs),
                &config,
            )
            .expect("a valid training matrix")
        })
    });
    group.finish();
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    bench_pca(&mut c);
    bench_cubature(&mut c);
    c.final_summary();
}
