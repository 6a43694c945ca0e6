//! Dense multilayer perceptrons and autoencoders with exact derivatives.
//!
//! This crate will own dense layers with smooth activations, the decoder's forward pass, its
//! vector–Jacobian and Jacobian–vector products and full Jacobian without allocation in the hot
//! path, Adam, and seeded autoencoder training on PCA coefficients. It knows nothing about meshes.
