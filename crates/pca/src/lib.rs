//! Mass-orthonormal principal component analysis of snapshot matrices.
//!
//! This crate will own the thin SVD of `M^{1/2} S`, the basis `U` with `UᵀMU = I`, projection
//! `q = UᵀMu`, reconstruction `u = Uq`, the singular value spectrum and the choice of the
//! dimension `k` (by count, explained energy or maximum per-vertex error). It knows nothing about
//! meshes: it takes matrices and an optional diagonal mass.
