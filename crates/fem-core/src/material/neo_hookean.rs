//! Classic compressible Neo-Hookean.

use super::stable_neo_hookean::{cofactor, det, det_from_cofactor, mirror_upper};
use super::{Lame, Mat9, Material, cofactor_tangent};
use crate::Mat3;

/// Compressible Neo-Hookean (e.g. Bonet & Wood, "Nonlinear Continuum Mechanics for Finite
/// Element Analysis", §6.4.3).
///
/// With I₁ = tr(FᵀF), J = det F and G = F⁻ᵀ = cof(F)/J:
///
/// * ψ(F) = μ/2 (I₁ − 3) − μ ln J + λ/2 (ln J)²
/// * P(F) = μ (F − F⁻ᵀ) + λ ln(J) F⁻ᵀ
/// * ∂P_ij/∂F_kl = μ δ_ik δ_jl + λ F⁻¹_ji F⁻¹_lk − (λ ln J − μ) F⁻¹_jk F⁻¹_li
///   = μ δ_ik δ_jl + λ G_ij G_kl + (μ − λ ln J) G_il G_kj
///
/// The energy is undefined for J ≤ 0 (ln J) and is **not** inversion safe: there
/// [`Material::psi`] returns `+∞` (so line searches reject the state) while
/// [`Material::pk1`], [`Material::dpdf`] and [`Material::dpdf_projected`] return NaN-filled
/// matrices. At F = I the tangent is 2μ𝒮 + λ vec(I)vec(I)ᵀ, linear elasticity's.
///
/// # Derivation
///
/// ∂I₁/∂F = 2F and ∂ln J/∂F = F⁻ᵀ, which gives P. For the tangent, ∂(F⁻ᵀ)_ij/∂F_kl =
/// −F⁻¹_jk F⁻¹_li (from δ(F⁻¹) = −F⁻¹ δF F⁻¹) and ∂ ln J/∂F_kl = F⁻¹_lk, so
/// ∂P_ij/∂F_kl = μ δ_ik δ_jl + μ F⁻¹_jk F⁻¹_li + λ F⁻¹_lk F⁻¹_ji − λ ln J F⁻¹_jk F⁻¹_li.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeoHookean {
    /// Shear modulus μ.
    pub mu: f64,
    /// First Lamé parameter λ.
    pub lambda: f64,
}

impl NeoHookean {
    pub fn new(lame: Lame) -> Self {
        Self {
            mu: lame.mu,
            lambda: lame.lambda,
        }
    }

    /// (F⁻ᵀ, ln J), or `None` when J ≤ 0 or J is NaN.
    #[allow(non_snake_case)]
    #[inline]
    fn inverse_transpose_and_log_det(F: &Mat3) -> Option<(Mat3, f64)> {
        let cof = cofactor(F);
        let J = det_from_cofactor(F, &cof);
        if J > 0.0 {
            Some((cof / J, J.ln()))
        } else {
            None
        }
    }
}

#[allow(non_snake_case)]
impl Material for NeoHookean {
    const NAME: &'static str = "neo-hookean";
    const INVERSION_SAFE: bool = false;

    #[inline]
    fn psi(&self, F: &Mat3) -> f64 {
        let J = det(F);
        if J <= 0.0 {
            return f64::INFINITY;
        }
        let lnJ = J.ln();
        0.5 * self.mu * (F.norm_squared() - 3.0) - self.mu * lnJ + 0.5 * self.lambda * lnJ * lnJ
    }

    #[inline]
    fn pk1(&self, F: &Mat3) -> Mat3 {
        match Self::inverse_transpose_and_log_det(F) {
            Some((G, lnJ)) => F * self.mu + G * (self.lambda * lnJ - self.mu),
            None => Mat3::repeat(f64::NAN),
        }
    }

    #[inline]
    fn psi_pk1(&self, F: &Mat3) -> (f64, Mat3) {
        let cof = cofactor(F);
        let J = det_from_cofactor(F, &cof);
        if J <= 0.0 {
            return (f64::INFINITY, Mat3::repeat(f64::NAN));
        }
        let lnJ = J.ln();
        let psi = 0.5 * self.mu * (F.norm_squared() - 3.0) - self.mu * lnJ
            + 0.5 * self.lambda * lnJ * lnJ;
        let P = F * self.mu + cof * ((self.lambda * lnJ - self.mu) / J);
        (psi, P)
    }

    fn dpdf(&self, F: &Mat3) -> Mat9 {
        let Some((G, lnJ)) = Self::inverse_transpose_and_log_det(F) else {
            return Mat9::repeat(f64::NAN);
        };
        let (mu, lambda) = (self.mu, self.lambda);
        let cross = mu - lambda * lnJ;
        let g = G.as_slice();
        let mut m = Mat9::zeros();
        // Upper triangle (a = r + 3c ≤ b = k + 3l), then mirrored: exactly symmetric.
        for l in 0..3 {
            for k in 0..3 {
                let b = k + 3 * l;
                let lg = lambda * g[b];
                let mut col = [0.0; 9];
                for c in 0..=l {
                    let ck = cross * G[(k, c)];
                    for r in 0..3 {
                        col[r + 3 * c] = lg * g[r + 3 * c] + ck * G[(r, l)];
                    }
                }
                col[b] += mu;
                m.column_mut(b).as_mut_slice()[..=b].copy_from_slice(&col[..=b]);
            }
        }
        mirror_upper(&mut m);
        m
    }

    /// The analytic projection of `super::cofactor_tangent` (ψ = μ/2 I₁ + h(J) with
    /// h = −μ ln J + λ/2 (ln J)², so a = h'' = (μ + λ − λ ln J)/J², c = h' = (λ ln J − μ)/J);
    /// NaN-filled for J ≤ 0.
    fn dpdf_projected(&self, F: &Mat3) -> Mat9 {
        let m = self.dpdf(F);
        if !m[(0, 0)].is_finite() {
            return m;
        }
        let (mu, lambda) = (self.mu, self.lambda);
        cofactor_tangent::project(m, F, mu, |J| {
            let lnJ = J.ln();
            (
                (mu + lambda - lambda * lnJ) / (J * J),
                (lambda * lnJ - mu) / J,
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverted_is_infinite_energy_and_nan_derivatives() {
        let m = NeoHookean::new(Lame {
            mu: 1.0,
            lambda: 2.0,
        });
        for f in [
            Mat3::from_diagonal(&crate::Vec3::new(1.0, 1.0, -0.5)),
            Mat3::zeros(),
        ] {
            assert_eq!(m.psi(&f), f64::INFINITY);
            let (psi, p) = m.psi_pk1(&f);
            assert_eq!(psi, f64::INFINITY);
            assert!(p.iter().all(|x| x.is_nan()));
            assert!(m.pk1(&f).iter().all(|x| x.is_nan()));
            assert!(m.dpdf(&f).iter().all(|x| x.is_nan()));
            assert!(m.dpdf_projected(&f).iter().all(|x| x.is_nan()));
        }
    }
}
