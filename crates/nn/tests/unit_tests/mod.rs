//! Integration tests of nn. Random data comes from a hand-written, seeded generator so every run
//! sees the same numbers.

mod backprop;
mod config;
mod derivatives;
mod serde_round_trip;
mod training;

use faer::Mat;
use nn::{Activation, Mlp};

/// Test data from the workspace's seeded generator (SplitMix64).
pub struct Rng(nn::SplitMix64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(nn::SplitMix64::new(seed))
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.0.range(lo, hi)
    }

    pub fn vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.range(-1.0, 1.0)).collect()
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.0.next_u64() % n as u64) as usize
    }
}

/// A random network with O(1) weights and nonzero biases (so every activation is exercised on
/// both sides of 0).
pub fn random_mlp(sizes: &[usize], activation: Activation, seed: u64) -> Mlp {
    let mut rng = Rng::new(seed);
    let weights = sizes
        .windows(2)
        .map(|w| {
            let s = 1.5 / (w[0] as f64).sqrt();
            (0..w[0] * w[1]).map(|_| s * rng.range(-1.0, 1.0)).collect()
        })
        .collect();
    let biases = sizes[1..].iter().map(|&n| rng.vec(n)).collect();
    Mlp::from_parameters(
        sizes.to_vec(),
        vec![activation; sizes.len() - 2],
        weights,
        biases,
    )
    .unwrap()
}

/// ‖a − b‖ / ‖b‖.
pub fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den.max(1e-300)).sqrt()
}

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Points on a smooth nonlinear 2-D manifold in R¹⁰, one per column: x = A φ(u, v) with
/// φ = [sin πu, v cos πu, uv, v², tanh(2(u + v))] and (u, v) uniform in [−1, 1]².
pub fn manifold_data(n: usize, seed: u64) -> Mat<f64> {
    let mut rng = Rng::new(seed);
    let a = Mat::from_fn(10, 5, |_, _| rng.range(-1.0, 1.0));
    let uv: Vec<(f64, f64)> = (0..n)
        .map(|_| (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)))
        .collect();
    Mat::from_fn(10, n, |i, j| {
        let (u, v) = uv[j];
        let pi = std::f64::consts::PI;
        let phi = [
            (pi * u).sin(),
            v * (pi * u).cos(),
            u * v,
            v * v,
            (2.0 * (u + v)).tanh(),
        ];
        (0..5).map(|m| a[(i, m)] * phi[m]).sum()
    })
}
