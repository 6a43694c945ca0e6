//! Analytic eigensystem and PSD projection of the tangents of energies ψ(F) = μ/2 I₁ + h(J);
//! [`clamped_from_modes`] serves any isotropic energy whose eigensystem is given in the same
//! frame (the corotated and StVK tangents too).
//!
//! Both Neo-Hookean models of this module have this form, so their tangents are
//! ∂P/∂F = μ I₉ + a vec(cof) vec(cof)ᵀ + c ∂cof/∂F with a = h''(J), c = h'(J) and
//! cof(F) = ∂J/∂F (Smith, de Goes & Kim 2018 §4 for stable Neo-Hookean; Kim & Eberle, "Dynamic
//! Deformables", 2022, ch. 7). With the rotation-variant SVD F = UΣVᵀ (U, V rotations,
//! σ₀ ≥ σ₁ ≥ |σ₂|, J = σ₀σ₁σ₂), for each pair (i, j) with third index k:
//!
//! * twist  (u_i v_jᵀ − u_j v_iᵀ)/√2 has eigenvalue μ + c σ_k,
//! * flip   (u_i v_jᵀ + u_j v_iᵀ)/√2 has eigenvalue μ − c σ_k,
//!
//! and the three scaling modes Σ_i e_i u_i v_iᵀ come from the eigenpairs (λ, e) of the 3×3 matrix
//! μ I + a g gᵀ + c [[0, σ₂, σ₁], [σ₂, 0, σ₀], [σ₁, σ₀, 0]] with g = (σ₁σ₂, σ₀σ₂, σ₀σ₁).
//!
//! In the SVD frame the Hessian of J is block diagonal: it couples only the diagonal entries
//! (entry (i, j) = σ_k) and each off-diagonal pair (F̂_ij, F̂_ji) through the minor
//! −σ_k F̂_ij F̂_ji, which gives ±σ_k on the flip/twist modes; vec(cof) is U diag(g) Vᵀ.

use super::corotated::{SignedSvd, signed_svd};
use super::stable_neo_hookean::{add_outer_upper, mirror_upper};
use super::{Mat9, project_psd};
use crate::Mat3;

/// The index pairs (i, j) of the twist and flip modes, in [`twist_flip`]'s order: pair k has
/// third index k.
pub(super) const PAIRS: [(usize, usize); 3] = [(1, 2), (0, 2), (0, 1)];

/// The shapes w of the twist and flip modes, twists first: u_i v_jᵀ − u_j v_iᵀ and
/// u_i v_jᵀ + u_j v_iᵀ over [`PAIRS`] (unit eigenvectors vec(w)/√2).
pub(super) fn mode_shapes(svd: &SignedSvd) -> [Mat3; 6] {
    let (u, v) = (&svd.u, &svd.v);
    let [(a0, b0), (a1, b1), (a2, b2)] = PAIRS.map(|(i, j)| {
        (
            u.column(i) * v.column(j).transpose(),
            u.column(j) * v.column(i).transpose(),
        )
    });
    [a0 - b0, a1 - b1, a2 - b2, a0 + b0, a1 + b1, a2 + b2]
}

/// The twist and flip eigenpairs of μ I₉ + c ∂cof/∂F: `(eigenvalue, w)` with unit eigenvector
/// vec(w)/√2, the twist of pair k with μ + c σ_k, its flip with μ − c σ_k.
pub(super) fn twist_flip(svd: &SignedSvd, mu: f64, c: f64) -> [(f64, Mat3); 6] {
    let s = &svd.sigma;
    let [t0, t1, t2, f0, f1, f2] = mode_shapes(svd);
    [
        (mu + c * s[0], t0),
        (mu + c * s[1], t1),
        (mu + c * s[2], t2),
        (mu - c * s[0], f0),
        (mu - c * s[1], f1),
        (mu - c * s[2], f2),
    ]
}

/// The 3×3 matrix whose eigenpairs (λ, e) give the scaling eigenpairs (λ, Σ_i e_i u_i v_iᵀ).
pub(super) fn scaling_block(s: &crate::Vec3, mu: f64, a: f64, c: f64) -> Mat3 {
    let g = crate::Vec3::new(s[1] * s[2], s[0] * s[2], s[0] * s[1]);
    let mut m = g * g.transpose() * a;
    for i in 0..3 {
        m[(i, i)] += mu;
    }
    let off = [(1, 2, 0), (0, 2, 1), (0, 1, 2)];
    for (i, j, k) in off {
        m[(i, j)] += c * s[k];
        m[(j, i)] += c * s[k];
    }
    m
}

/// The projection onto the PSD cone of the exact tangent `m` = μ I₉ + a ggᵀ + c ∂cof/∂F of F
/// ([`project_with`]); `coefficients(J)` gives (a, c) at J = σ₀σ₁σ₂.
#[allow(non_snake_case)]
pub(super) fn project(
    m: Mat9,
    F: &Mat3,
    mu: f64,
    coefficients: impl Fn(f64) -> (f64, f64),
) -> Mat9 {
    project_with(m, F, None, |svd| {
        let s = &svd.sigma;
        let (a, c) = coefficients(s[0] * s[1] * s[2]);
        (twist_flip(svd, mu, c), scaling_block(s, mu, a, c))
    })
}

/// The projection onto the PSD cone of the exact tangent `m` of F, whose eigensystem in the
/// SVD frame `eigensystem` gives: the twist and flip pairs in [`twist_flip`]'s shape and the
/// scaling block ([`clamped_from_modes`]).
///
/// A positive definite `m` is recognised by a Cholesky-type factorisation and returned
/// unchanged, without the SVD (most elements of a Neo-Hookean body; about half of a moving
/// corotated or StVK body's, whose twists are zero at rest). `svd`, when the caller has it
/// already, saves computing it again. Non-finite F yields `m` unchanged.
#[allow(non_snake_case)]
pub(super) fn project_with(
    m: Mat9,
    F: &Mat3,
    svd: Option<SignedSvd>,
    eigensystem: impl FnOnce(&SignedSvd) -> ([(f64, Mat3); 6], Mat3),
) -> Mat9 {
    if is_positive_definite(&m) || !F.iter().all(|x| x.is_finite()) {
        return m;
    }
    let svd = svd.unwrap_or_else(|| signed_svd(F));
    let (pairs, block) = eigensystem(&svd);
    clamped_from_modes(m, &svd, pairs, &block)
}

/// The projection of the tangent `m` onto the PSD cone from its eigensystem in the SVD frame
/// of F: the six twist and flip pairs `(eigenvalue, w)` of [`twist_flip`]'s shape and the 3×3
/// scaling block of [`scaling_block`]'s, with the negative eigenvalues clamped to zero.
///
/// Either `m` minus its negative modes or the sum of its positive ones, whichever has the
/// smaller eigenvalues in total: each way errs by rounding in the scale of what it removes or
/// adds. Subtraction is the usual case (a few negative modes); a crushed StVK element has nine,
/// and near the corotated singular set one twist is ~μ·10⁸, which subtracted would leave the
/// result to cancellation. If the 3×3 eigenproblem fails, the generic [`project_psd`] is used.
pub(super) fn clamped_from_modes(
    m: Mat9,
    svd: &SignedSvd,
    pairs: [(f64, Mat3); 6],
    block: &Mat3,
) -> Mat9 {
    // The scaling modes live in the span of d_i = u_i v_iᵀ, where the tangent is
    // Σ_ij B_ij vec(d_i) vec(d_j)ᵀ.
    let d = || [0, 1, 2].map(|i| svd.u.column(i) * svd.v.column(i).transpose());
    // Sylvester's criterion; on failure (indefinite or borderline) decompose.
    let block_pd = block[(0, 0)] > 0.0
        && block[(0, 0)] * block[(1, 1)] - block[(0, 1)] * block[(0, 1)] > 0.0
        && block.determinant() > 0.0;
    // Modes as (eigenvalue, q) with unit vec(q) for the scaling ones; twist and flip keep
    // w = √2 q, so their rank-one term is (λ/2) w wᵀ.
    let mut scaling: [(f64, Mat3); 3] = [(0.0, Mat3::zeros()); 3];
    if !block_pd {
        let Some(eig) = block.try_symmetric_eigen(f64::EPSILON, 1000) else {
            return project_psd(&m);
        };
        let d = d();
        for (mode, (val, e)) in scaling
            .iter_mut()
            .zip(eig.eigenvalues.iter().zip(eig.eigenvectors.column_iter()))
        {
            *mode = (*val, d[0] * e[0] + d[1] * e[1] + d[2] * e[2]);
        }
    }
    let negative: f64 = pairs
        .iter()
        .chain(&scaling)
        .map(|(v, _)| (-v).max(0.0))
        .sum();
    let positive: f64 = pairs
        .iter()
        .chain(&scaling)
        .map(|(v, _)| v.max(0.0))
        .sum::<f64>()
        + if block_pd { block.trace() } else { 0.0 };
    let half = |(val, w): &(f64, Mat3)| (0.5 * val, *w);
    let modes = pairs.iter().map(half).chain(scaling);
    let mut out;
    if negative <= positive {
        if negative == 0.0 {
            return m;
        }
        out = m;
        for (val, q) in modes.filter(|(v, _)| *v < 0.0) {
            add_outer_upper(&mut out, &q, &q, -val);
        }
    } else {
        out = Mat9::zeros();
        for (val, q) in modes.filter(|(v, _)| *v > 0.0) {
            add_outer_upper(&mut out, &q, &q, val);
        }
        if block_pd {
            let d = d();
            for (i, di) in d.iter().enumerate() {
                for (j, dj) in d.iter().enumerate() {
                    add_outer_upper(&mut out, di, dj, block[(i, j)]);
                }
            }
        }
    }
    mirror_upper(&mut out);
    out
}

/// Whether the symmetric matrix `m` is positive definite (in floating point): a right-looking
/// LDLᵀ elimination on the lower triangle that stops at the first pivot that is not positive.
pub(super) fn is_positive_definite(m: &Mat9) -> bool {
    let mut c: [f64; 81] = m.as_slice().try_into().expect("9×9");
    // One const-generic step per column, so that every loop has a constant trip count and is
    // unrolled (runtime-length triangular loops cost several times more here).
    ldl_step::<0>(&mut c)
        && ldl_step::<1>(&mut c)
        && ldl_step::<2>(&mut c)
        && ldl_step::<3>(&mut c)
        && ldl_step::<4>(&mut c)
        && ldl_step::<5>(&mut c)
        && ldl_step::<6>(&mut c)
        && ldl_step::<7>(&mut c)
        && c[80] > 0.0
}

/// Eliminates column J of the column-major 9×9 `c` (lower triangle); false if its pivot is not
/// positive (or NaN).
#[inline(always)]
fn ldl_step<const J: usize>(c: &mut [f64; 81]) -> bool {
    let d = c[J * 10];
    if d.is_nan() || d <= 0.0 {
        return false;
    }
    let inv = 1.0 / d;
    // Trailing columns k > J, rows i ≥ k: c_ik −= c_iJ c_kJ / d.
    for k in J + 1..9 {
        let f = c[9 * J + k] * inv;
        for i in k..9 {
            c[9 * k + i] -= f * c[9 * J + i];
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positive_definite_test_agrees_with_eigenvalues() {
        let q = Mat9::from_fn(|i, j| ((i * 7 + j * 3) as f64).sin())
            .qr()
            .q();
        for shift in [-3.0, -0.5, 0.5, 1.0, 4.0] {
            let d = nalgebra::SVector::<f64, 9>::from_fn(|i, _| i as f64 + shift);
            let a = q * Mat9::from_diagonal(&d) * q.transpose();
            let a = (a + a.transpose()) * 0.5;
            assert_eq!(is_positive_definite(&a), d.min() > 0.0, "shift {shift}");
        }
        assert!(!is_positive_definite(&Mat9::repeat(f64::NAN)));
        assert!(!is_positive_definite(&Mat9::zeros()));
    }
}
