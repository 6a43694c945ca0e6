//! Dense multilayer perceptrons and autoencoders with exact derivatives, in f64.
//!
//! An [`Mlp`] maps x ∈ R^{n₀} to y = W_L σ(⋯σ(W₁x + b₁)⋯) + b_L (activation on hidden layers,
//! linear output). At one input it evaluates y, the vector–Jacobian product Jᵀv (reverse mode),
//! the Jacobian–vector product Jw and the full Jacobian J (forward mode with n₀ tangents), each at
//! the cost of a few forward passes and without allocating: scratch lives in an [`MlpWorkspace`].
//! With two hidden layers or more, all four skip the first layer's linear units (ELU's units
//! with a > 0) in the second layer's product, through W₂W₁ kept in the workspace: exact, and
//! about half the work of that product.
//!
//! An [`Autoencoder`] on PCA coefficients q ∈ Rᵏ pairs an encoder k → d with a decoder d → k and
//! an optional per-feature [`InputScaling`]; its decoder derivatives are in original units. It is
//! trained by [`train()`] (Adam on the mean squared reconstruction error, shuffled mini-batches
//! evaluated in parallel, a seeded validation split, early stopping, bit-reproducible for a seed)
//! and serialised with serde as the model artifact (validated on load, see
//! [`Autoencoder::FORMAT_VERSION`]). [`train_search`] picks the smallest latent dimension meeting
//! a caller-supplied error tolerance. The crate knows nothing about meshes.
//!
//! ```
//! use faer::Mat;
//! use nn::{AutoencoderConfig, train};
//!
//! // 200 samples of a 1-D curve in R³, one sample per column.
//! let data = Mat::from_fn(3, 200, |i, j| {
//!     let t = j as f64 / 199.0 * 2.0 - 1.0;
//!     [t, t * t, (2.0 * t).sin()][i]
//! });
//! let config = AutoencoderConfig {
//!     hidden: Some(vec![16]),
//!     epochs: 200,
//!     batch_size: 32,
//!     learning_rate: 1e-2,
//!     patience: 0,
//!     ..AutoencoderConfig::default()
//! };
//! let mut losses = Vec::new();
//! let trained = train(data.as_ref(), 1, &config, |r| losses.push(r.train_loss))?;
//! assert_eq!(losses.len(), 200);
//! assert!(trained.best_loss < 0.05, "{}", trained.best_loss);
//!
//! // Decode a latent point and take the vector–Jacobian product Jᵀv of q = decode(z).
//! let ae = &trained.model;
//! let mut ws = ae.workspace();
//! let (z, v) = ([0.3], [1.0, 0.0, 0.0]);
//! let mut q = [0.0; 3];
//! let mut jtv = [0.0; 1];
//! ae.decode(&z, &mut q, &mut ws);
//! ae.decode_vjp(&z, &v, &mut jtv, &mut ws);
//!
//! // It matches a central finite difference of the first output.
//! let h = 1e-6;
//! let (mut qp, mut qm) = ([0.0; 3], [0.0; 3]);
//! ae.decode(&[z[0] + h], &mut qp, &mut ws);
//! ae.decode(&[z[0] - h], &mut qm, &mut ws);
//! assert!((jtv[0] - (qp[0] - qm[0]) / (2.0 * h)).abs() < 1e-6 * (1.0 + jtv[0].abs()));
//!
//! // The artifact round-trips through serde.
//! let json = serde_json::to_string(ae).unwrap();
//! let back: nn::Autoencoder = serde_json::from_str(&json).unwrap();
//! assert_eq!(&back, ae);
//! # Ok::<(), nn::NnError>(())
//! ```

pub mod activation;
pub mod adam;
mod aligned;
pub mod autoencoder;
pub mod batch;
pub mod config;
pub mod error;
mod gradient;
mod kernels;
mod linalg;
pub mod mlp;
pub mod scaling;
pub mod synthetic;
pub mod train;

/// The multiply–add rate the crate's kernels are measured against (from `simd-kernels`).
pub use simd_kernels::peak;

pub use activation::Activation;
pub use adam::{Adam, AdamParams};
pub use autoencoder::{Autoencoder, AutoencoderGradient, AutoencoderWorkspace, CHUNK};
pub use batch::{MlpBatchWorkspace, MlpGradient};
pub use config::{AutoencoderConfig, DEFAULT_HIDDEN_RANGE, DEFAULT_LATENT_DIM, LatentRule};
pub use error::NnError;
pub use mlp::{Mlp, MlpWorkspace};
pub use rng::SplitMix64;
pub use scaling::InputScaling;
pub use train::{
    EpochReport, LatentSearch, LatentTrial, TrainOutcome, Trainer, train, train_search,
};

/// Compiles and runs the README's example as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
