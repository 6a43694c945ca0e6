//! Saint Venant–Kirchhoff.

use super::cofactor_tangent::{PAIRS, mode_shapes, project_with};
use super::stable_neo_hookean::mirror_upper;
use super::{Lame, Mat9, Material};
use crate::Mat3;

/// Saint Venant–Kirchhoff: linear elasticity applied to the Green–Lagrange strain.
///
/// With E = ½(FᵀF − I) and the second Piola–Kirchhoff stress S = 2μE + λ tr(E) I:
///
/// * ψ(F) = μ E:E + λ/2 (tr E)²
/// * P(F) = F S = F (2μE + λ tr(E) I)
/// * ∂P_ij/∂F_kl = δ_ik S_lj + μ (F_il F_kj + (FFᵀ)_ik δ_jl) + λ F_ij F_kl
///
/// ψ is a polynomial in F, so everything is finite for every F (`INVERSION_SAFE`), but the
/// model is notoriously weak under compression: ψ → 0 as F → 0 and inverted elements
/// (F = −I, ψ = 0) are not pushed back. It is rotation invariant.
///
/// # Projection
///
/// [`Material::dpdf_projected`] uses the tangent's eigensystem in the frame of the SVD
/// F = UΣVᵀ. In principal stretches ψ = μ/4 Σ_i (σ_i² − 1)² + λ/8 (I − 3)², I = Σ_i σ_i², so
/// with ψ_i = ∂ψ/∂σ_i and c = λ/2 (I − 3), for each pair (i, j):
///
/// * twist (u_i v_jᵀ − u_j v_iᵀ)/√2: (ψ_i + ψ_j)/(σ_i + σ_j) = μ(σ_i² − σ_iσ_j + σ_j² − 1) + c,
/// * flip (u_i v_jᵀ + u_j v_iᵀ)/√2: (ψ_i − ψ_j)/(σ_i − σ_j) = μ(σ_i² + σ_iσ_j + σ_j² − 1) + c,
///
/// and the scaling modes Σ_i e_i u_i v_iᵀ come from the 3×3 Hessian ∂²ψ/∂σ_i∂σ_j =
/// δ_ij (μ(3σ_i² − 1) + c) + λσ_iσ_j. A positive definite tangent is returned as it is (no SVD);
/// otherwise its negative eigenvalues are clamped to zero, which equals the clamped
/// eigen-decomposition of [`super::project_psd`] at the cost of one 3×3 SVD (and a 3×3
/// eigenproblem when the scaling block is indefinite).
///
/// # Derivation
///
/// δE = ½(δFᵀF + FᵀδF), so δψ = (2μE + λ tr(E) I) : δE = S : FᵀδF = FS : δF, giving P = FS.
/// Then δP = δF S + F δS with δS = 2μ δE + λ tr(δE) I and tr(δE) = F : δF. For δF = e_k e_lᵀ:
/// (δF S)_ij = δ_ik S_lj, (F δE)_ij = ½(F_il F_kj + (FFᵀ)_ik δ_jl) and F tr(δE) = F_kl F.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StVenantKirchhoff {
    /// Shear modulus μ.
    pub mu: f64,
    /// First Lamé parameter λ.
    pub lambda: f64,
}

impl StVenantKirchhoff {
    pub fn new(lame: Lame) -> Self {
        Self {
            mu: lame.mu,
            lambda: lame.lambda,
        }
    }

    /// Green–Lagrange strain E = ½(FᵀF − I).
    #[allow(non_snake_case)]
    #[inline]
    fn green_strain(F: &Mat3) -> Mat3 {
        let mut E = F.tr_mul(F);
        E[(0, 0)] -= 1.0;
        E[(1, 1)] -= 1.0;
        E[(2, 2)] -= 1.0;
        E * 0.5
    }

    /// Second Piola–Kirchhoff stress S = 2μE + λ tr(E) I.
    #[allow(non_snake_case)]
    #[inline]
    fn pk2(&self, E: &Mat3) -> Mat3 {
        let mut S = E * (2.0 * self.mu);
        let lt = self.lambda * E.trace();
        S[(0, 0)] += lt;
        S[(1, 1)] += lt;
        S[(2, 2)] += lt;
        S
    }

    #[allow(non_snake_case)]
    #[inline]
    fn energy(&self, E: &Mat3) -> f64 {
        let tr = E.trace();
        self.mu * E.norm_squared() + 0.5 * self.lambda * tr * tr
    }
}

#[allow(non_snake_case)]
impl Material for StVenantKirchhoff {
    const NAME: &'static str = "stvk";
    const INVERSION_SAFE: bool = true;

    #[inline]
    fn psi(&self, F: &Mat3) -> f64 {
        self.energy(&Self::green_strain(F))
    }

    #[inline]
    fn pk1(&self, F: &Mat3) -> Mat3 {
        F * self.pk2(&Self::green_strain(F))
    }

    #[inline]
    fn psi_pk1(&self, F: &Mat3) -> (f64, Mat3) {
        let E = Self::green_strain(F);
        (self.energy(&E), F * self.pk2(&E))
    }

    fn dpdf(&self, F: &Mat3) -> Mat9 {
        let (mu, lambda) = (self.mu, self.lambda);
        let S = self.pk2(&Self::green_strain(F));
        let B = F * F.transpose();
        let mut m = Mat9::zeros();
        // Upper triangle (a ≤ b), then mirrored so the result is exactly symmetric.
        for l in 0..3 {
            for k in 0..3 {
                let b = k + 3 * l;
                let lf = lambda * F[(k, l)];
                let mut col = [0.0; 9];
                for c in 0..=l {
                    let mk = mu * F[(k, c)];
                    for r in 0..3 {
                        col[r + 3 * c] = mk * F[(r, l)] + lf * F[(r, c)];
                    }
                    // δ_rk S_lc
                    col[k + 3 * c] += S[(l, c)];
                }
                // δ_lc μ (FFᵀ)_rk
                for r in 0..3 {
                    col[r + 3 * l] += mu * B[(r, k)];
                }
                m.column_mut(b).as_mut_slice()[..=b].copy_from_slice(&col[..=b]);
            }
        }
        mirror_upper(&mut m);
        m
    }

    /// Analytic projection (see the type's documentation). Non-finite F yields the
    /// (non-finite) tangent unchanged.
    fn dpdf_projected(&self, F: &Mat3) -> Mat9 {
        let (mu, lambda) = (self.mu, self.lambda);
        project_with(self.dpdf(F), F, None, |svd| {
            let s = &svd.sigma;
            let c = 0.5 * lambda * (s.norm_squared() - 3.0);
            let shapes = mode_shapes(svd);
            let pairs = std::array::from_fn(|m| {
                let (i, j) = PAIRS[m % 3];
                let (a, b) = (s[i], s[j]);
                // Twists (a² − ab + b²), then flips (a² + ab + b²).
                let ab = if m < 3 { -a * b } else { a * b };
                (mu * (a * a + ab + b * b - 1.0) + c, shapes[m])
            });
            let block = Mat3::from_fn(|i, j| {
                let diagonal = if i == j {
                    mu * (3.0 * s[i] * s[i] - 1.0) + c
                } else {
                    0.0
                };
                diagonal + lambda * s[i] * s[j]
            });
            (pairs, block)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverted_identity_is_an_unstressed_state() {
        let m = StVenantKirchhoff::new(Lame {
            mu: 1.0,
            lambda: 3.0,
        });
        let f = -Mat3::identity();
        assert_eq!(m.psi(&f), 0.0);
        assert_eq!(m.pk1(&f), Mat3::zeros());
        let a = m.dpdf(&f);
        assert_eq!(a, a.transpose());
    }
}
