//! Small-strain linear elasticity.

use super::{Lame, Mat9, Material, project_psd};
use crate::Mat3;

/// Small-strain (linear) elasticity.
///
/// With the infinitesimal strain ε = ½(F + Fᵀ) − I:
///
/// * ψ(F) = μ ε:ε + λ/2 (tr ε)²
/// * P(F) = 2μ ε + λ tr(ε) I
/// * ∂P_ij/∂F_kl = μ (δ_ik δ_jl + δ_il δ_jk) + λ δ_ij δ_kl  (constant)
///
/// In the column-major flattening of [`super`] the tangent is 2μ 𝒮 + λ vec(I) vec(I)ᵀ, where 𝒮
/// projects onto symmetric matrices. Its eigenvalues are 2μ (symmetric, trace-free part),
/// 3λ + 2μ (the trace) and 0 (the three skew-symmetric directions), so it is positive
/// semidefinite whenever μ ≥ 0 and 3λ + 2μ ≥ 0 and [`Material::dpdf_projected`] returns it
/// unchanged.
///
/// The model is not rotation invariant (ψ(RF) ≠ ψ(F)): rotated elements carry spurious
/// stress. It is finite for every F, including inverted ones.
///
/// # Derivation
///
/// ε is linear in F with ∂ε/∂F = 𝒮, so ∂ψ/∂F = 𝒮ᵀ(2μ ε + λ tr(ε) I) = 2μ ε + λ tr(ε) I because
/// that tensor is already symmetric. Differentiating once more, ∂(2με)/∂F_kl = μ(e_k e_lᵀ +
/// e_l e_kᵀ) and ∂ tr ε/∂F_kl = δ_kl.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearElastic {
    /// Shear modulus μ.
    pub mu: f64,
    /// First Lamé parameter λ.
    pub lambda: f64,
}

impl LinearElastic {
    pub fn new(lame: Lame) -> Self {
        Self {
            mu: lame.mu,
            lambda: lame.lambda,
        }
    }

    /// Infinitesimal strain ε = ½(F + Fᵀ) − I.
    #[allow(non_snake_case)]
    #[inline]
    fn strain(F: &Mat3) -> Mat3 {
        let mut e = (F + F.transpose()) * 0.5;
        e[(0, 0)] -= 1.0;
        e[(1, 1)] -= 1.0;
        e[(2, 2)] -= 1.0;
        e
    }

    #[inline]
    fn energy_of_strain(&self, e: &Mat3) -> f64 {
        let tr = e.trace();
        self.mu * e.norm_squared() + 0.5 * self.lambda * tr * tr
    }

    #[inline]
    fn stress_of_strain(&self, e: &Mat3) -> Mat3 {
        let mut p = e * (2.0 * self.mu);
        let lt = self.lambda * e.trace();
        p[(0, 0)] += lt;
        p[(1, 1)] += lt;
        p[(2, 2)] += lt;
        p
    }
}

#[allow(non_snake_case)]
impl Material for LinearElastic {
    const NAME: &'static str = "linear";
    const INVERSION_SAFE: bool = true;

    #[inline]
    fn psi(&self, F: &Mat3) -> f64 {
        self.energy_of_strain(&Self::strain(F))
    }

    #[inline]
    fn pk1(&self, F: &Mat3) -> Mat3 {
        self.stress_of_strain(&Self::strain(F))
    }

    #[inline]
    fn psi_pk1(&self, F: &Mat3) -> (f64, Mat3) {
        let e = Self::strain(F);
        (self.energy_of_strain(&e), self.stress_of_strain(&e))
    }

    fn dpdf(&self, _F: &Mat3) -> Mat9 {
        let (mu, lambda) = (self.mu, self.lambda);
        let mut m = Mat9::zeros();
        for c in 0..3 {
            for r in 0..3 {
                let a = r + 3 * c;
                // δ_rk δ_cl: the identity.
                m[(a, a)] += mu;
                // δ_rl δ_ck: the transposition, column index k + 3l = c + 3r.
                m[(a, c + 3 * r)] += mu;
            }
        }
        // δ_rc δ_kl: vec(I) vec(I)ᵀ; vec(I) is 1 at flat indices 0, 4, 8.
        for a in [0, 4, 8] {
            for b in [0, 4, 8] {
                m[(a, b)] += lambda;
            }
        }
        m
    }

    /// The tangent is constant and positive semidefinite for μ ≥ 0, 3λ + 2μ ≥ 0, in which case it
    /// is returned as is (no eigen-decomposition); otherwise it is projected.
    fn dpdf_projected(&self, F: &Mat3) -> Mat9 {
        let m = self.dpdf(F);
        if self.mu >= 0.0 && 3.0 * self.lambda + 2.0 * self.mu >= 0.0 {
            m
        } else {
            project_psd(&m)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangent_is_symmetric_with_known_spectrum() {
        let m = LinearElastic::new(Lame {
            mu: 2.0,
            lambda: 5.0,
        });
        let a = m.dpdf(&Mat3::identity());
        assert_eq!(a, a.transpose());
        let mut ev: Vec<f64> = a.symmetric_eigenvalues().iter().copied().collect();
        ev.sort_by(f64::total_cmp);
        // 3 skew (0), 5 deviatoric symmetric (2μ), 1 volumetric (3λ + 2μ).
        let expect = [0.0, 0.0, 0.0, 4.0, 4.0, 4.0, 4.0, 4.0, 19.0];
        for (x, y) in ev.iter().zip(expect) {
            assert!((x - y).abs() < 1e-12, "{ev:?}");
        }
    }
}
