//! Mass-orthonormal principal component analysis of snapshot matrices.
//!
//! Given snapshots S (n × N, one per column, uncentred) and a diagonal mass M, the basis is
//! U = M^{-1/2} Ũ_{:, :k} from the thin SVD M^{1/2}S = Ũ Σ Vᵀ, so that UᵀMU = I; coefficients are
//! q = UᵀMu and reconstructions u = Uq. The dimension k is chosen by count, by explained energy or
//! as the smallest k whose maximum per-vertex reconstruction distance over the snapshots is below a
//! tolerance (see [`fit`] for the maths). The whole singular value spectrum is kept for reports.
//!
//! The crate knows nothing about meshes: it takes matrices, an optional mass diagonal and the
//! number of consecutive rows that make up one vertex.
//!
//! ```
//! use faer::Mat;
//! use pca::{PcaBasis, PcaConfig};
//!
//! // Six snapshots of two 3-D vertices (n = 6) spanning a 2-D subspace.
//! let s = Mat::from_fn(6, 6, |i, j| {
//!     let (a, b) = ((j as f64).sin(), (j as f64).cos());
//!     a * (i as f64 + 1.0) + b * (1.0 - 0.5 * i as f64)
//! });
//! let mass = [1.0, 1.0, 1.0, 2.0, 2.0, 2.0];
//!
//! let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_max_vertex_error(1e-9), 3)?;
//! let basis = &fit.basis;
//! assert_eq!(fit.chosen_k(), 2);
//! assert!(fit.tolerance_met);
//!
//! // UᵀMU = I.
//! let m = faer::Mat::from_fn(6, 6, |i, j| if i == j { mass[i] } else { 0.0 });
//! let gram = basis.basis_ref().transpose() * &m * basis.basis_ref();
//! assert!((gram - Mat::<f64>::identity(2, 2)).norm_max() < 1e-12);
//!
//! // A snapshot in the span is reproduced: u = U UᵀM u.
//! let u: Vec<f64> = s.col(4).iter().copied().collect();
//! let mut q = vec![0.0; basis.k()];
//! let mut back = vec![0.0; basis.n()];
//! basis.project(&u, &mut q);
//! basis.reconstruct(&q, &mut back);
//! assert!(u.iter().zip(&back).all(|(a, b)| (a - b).abs() < 1e-12));
//! # Ok::<(), pca::PcaError>(())
//! ```

pub mod basis;
pub mod config;
pub mod error;
pub mod fit;
pub mod norm;
mod svd;
mod vertex_error;

pub use basis::{PcaBasis, orthogonalise};
pub use config::{
    BasisNorm, DEFAULT_EXPLAINED_ENERGY, DEFAULT_MAX_DIMENSION, DEFAULT_PATCH_RESPONSES,
    DimensionRule, MAX_GRAVITY_DIRECTIONS, MAX_PATCH_RESPONSES, PcaConfig,
};
pub use error::PcaError;
pub use fit::{PcaFit, Shortfall};
