//! Optimized cubature (An, Kim & James 2008): a small weighted element set whose reduced forces
//! match the full mesh's over training poses.
//!
//! This crate will own the per-element reduced force training matrix, greedy element selection and
//! the Lawson–Hanson non-negative least-squares solver.
