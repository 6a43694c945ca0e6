//! A seeded synthetic data set on a smooth d-dimensional manifold, for benchmarks and tests:
//! x = A tanh(B z + c) + σ ε with z ~ U(−1, 1)ᵈ and ε ~ N(0, I).
//!
//! Every number comes from one [`SplitMix64`] stream in a fixed order (documented on
//! [`TanhManifold::sample`]), so a seed gives the same data on every machine, and the recipe can
//! be mirrored in another language (`benches/peers/torch_autoencoder.py` does, for the PyTorch
//! peer benchmark).
//!
//! ```
//! let data = nn::synthetic::TanhManifold::autodef_x().sample(2_000, 7);
//! assert_eq!((data.nrows(), data.ncols()), (49, 2_000));
//! ```

use faer::Mat;

use crate::SplitMix64;

/// The generator's shape: A is `ambient × width`, B is `width × latent`, c has `width` entries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TanhManifold {
    /// Dimension of x (the autoencoder's input, e.g. 49 PCA coefficients).
    pub ambient: usize,
    /// Intrinsic dimension d of the manifold.
    pub latent: usize,
    /// Number of tanh features.
    pub width: usize,
    /// Standard deviation σ of the additive Gaussian noise.
    pub noise: f64,
}

impl TanhManifold {
    /// The AutoDef "X" shape: 49 coefficients on a 6-D manifold of 16 tanh features, σ = 0.01.
    pub fn autodef_x() -> Self {
        Self {
            ambient: 49,
            latent: 6,
            width: 16,
            noise: 0.01,
        }
    }

    /// `samples` points, one per column (`ambient × samples`).
    ///
    /// Draw order from `SplitMix64::new(seed)`, with u = uniform in [0, 1):
    /// B row-major, B_ml = 2u − 1; c_m = u − 1/2; A row-major, A_im = (2u − 1)/√width; then per
    /// sample, z_l = 2u − 1 for every l, and per entry i one Box–Muller normal
    /// ε = √(−2 ln(1 − u₁)) cos(2π u₂).
    pub fn sample(&self, samples: usize, seed: u64) -> Mat<f64> {
        let Self {
            ambient,
            latent,
            width,
            noise,
        } = *self;
        let mut rng = SplitMix64::new(seed);
        let mut sym = |n: usize, scale: f64| -> Vec<f64> {
            (0..n)
                .map(|_| scale * (2.0 * rng.uniform() - 1.0))
                .collect()
        };
        let b = sym(width * latent, 1.0);
        let c = sym(width, 0.5);
        let a = sym(ambient * width, 1.0 / (width as f64).sqrt());
        let mut x = Mat::zeros(ambient, samples);
        let mut features = vec![0.0; width];
        for j in 0..samples {
            let z: Vec<f64> = (0..latent).map(|_| 2.0 * rng.uniform() - 1.0).collect();
            for m in 0..width {
                let row = &b[m * latent..(m + 1) * latent];
                let s: f64 = row.iter().zip(&z).map(|(b, z)| b * z).sum();
                features[m] = (s + c[m]).tanh();
            }
            for i in 0..ambient {
                let row = &a[i * width..(i + 1) * width];
                let clean: f64 = row.iter().zip(&features).map(|(a, f)| a * f).sum();
                let (u1, u2) = (rng.uniform(), rng.uniform());
                let normal = (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                x[(i, j)] = clean + noise * normal;
            }
        }
        x
    }
}
