//! Integration tests of cubature. Random data comes from `fem_core::rng::SplitMix64`, so every run
//! sees the same numbers.

mod config;
mod greedy;
mod nnls;
mod training;

pub mod fixture;

pub use fixture::{beam, modal_basis, random_poses};

use cubature::{CubatureConfig, Poses, TrainingMatrix};
use faer::Mat;
use fem_core::rng::SplitMix64;

pub fn normal_mat(rng: &mut SplitMix64, nrows: usize, ncols: usize) -> Mat<f64> {
    Mat::from_fn(nrows, ncols, |_, _| rng.normal())
}

pub fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// The beam (1,920 tets), its modal basis, and training / held-out matrices (100 and 40 poses).
pub struct BeamProblem {
    pub train: TrainingMatrix,
    pub held_out: TrainingMatrix,
}

pub fn beam_problem() -> BeamProblem {
    let model = beam([20, 4, 4]);
    let (basis, k, lambda) = modal_basis(&model);
    let config = CubatureConfig::default();
    let q_train = random_poses(&model, &basis, &lambda, 100, 11);
    let q_test = random_poses(&model, &basis, &lambda, 40, 12345);
    let train =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q_train.as_ref()), &config).unwrap();
    let held_out =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q_test.as_ref()), &config).unwrap();
    BeamProblem { train, held_out }
}
