//! Reduced implicit Euler in linear (PCA) and nonlinear (autoencoder) subspaces.
//!
//! This crate will own the `Subspace` abstraction (latent `z` → PCA coefficients `q`, with Jacobian
//! and vector–Jacobian product), reduced energies evaluated over cubature elements with partial
//! decode, and the preconditioned L-BFGS / Newton integrators in latent space.
