//! Stable Neo-Hookean (Smith, de Goes, Kim 2018), and the cofactor helpers shared by the
//! materials of this module.

use super::{Lame, Mat9, Material, cofactor_tangent};
use crate::Mat3;

/// Stable Neo-Hookean (Smith, de Goes & Kim, "Stable Neo-Hookean Flesh Simulation", 2018),
/// without the log(I₂ + 1) barrier term.
///
/// With I₁ = tr(FᵀF) = ‖F‖², J = det F, cof(F) = ∂J/∂F = J F⁻ᵀ and α = 1 + μ'/λ':
///
/// * ψ(F) = μ'/2 (I₁ − 3) + λ'/2 (J − α)² − λ'/2 (1 − α)²
///   = μ'/2 (I₁ − 3) − μ'(J − 1) + λ'/2 (J − 1)²   (the form evaluated; it needs no α)
/// * P(F) = μ' F + λ'(J − α) cof(F) = μ' F + (λ'(J − 1) − μ') cof(F)
/// * ∂P/∂F = μ' I₉ + λ' vec(cof) vec(cof)ᵀ + (λ'(J − 1) − μ') ∂cof/∂F
///
/// where ∂cof_ij/∂F_kl = ∂²J/∂F_ij∂F_kl = Σ_{m,n} ε_ikn ε_jlm F_nm: in the column-major
/// flattening the 3×3 block (j, l) of ∂cof/∂F is −ε_jlm \[f_m\]×, with f_m column m of F and
/// \[v\]× the cross-product matrix (diagonal blocks are zero).
///
/// # Lamé parameters
///
/// The constant makes ψ(I) = 0 and the choice of α makes P(I) = 0. Linearising at F = I
/// (∂cof/∂F(I) = vec(I)vec(I)ᵀ − 𝒯 with 𝒯 the transposition) gives the tangent
/// μ'(I₉ + 𝒯) + (λ' − μ') vec(I)vec(I)ᵀ, which is linear elasticity's 2μ𝒮 + λ vec(I)vec(I)ᵀ
/// exactly when μ' = μ and λ' = λ + μ. [`StableNeoHookean::new`] applies this mapping, so a
/// given (E, ν) means the same thing for every material of this module in the small-strain
/// limit.
///
/// ψ is a polynomial in F: finite for every F, and inverted elements are pushed back through
/// the (J − α)² term (`INVERSION_SAFE`). It is rotation invariant.
///
/// # Projection
///
/// [`Material::dpdf_projected`] uses the analytic eigensystem of tangents of the form
/// μ I₉ + a vec(cof)vec(cof)ᵀ + c ∂cof/∂F (here a = λ', c = λ'(J − 1) − μ'; see
/// `super::cofactor_tangent`): a positive definite tangent is returned as it is, otherwise its
/// negative eigenvalues are clamped to zero, which equals the clamped eigen-decomposition of
/// [`super::project_psd`] at the cost of one 3×3 SVD (and a 3×3 eigenproblem only when the
/// scaling block is indefinite).
///
/// # Derivation
///
/// ∂I₁/∂F = 2F and ∂J/∂F = cof(F), so P = μ'F − μ' cof + λ'(J − 1) cof. Differentiating,
/// ∂(λ'(J − 1) − μ')/∂F = λ' cof and ∂cof/∂F is the Hessian of the cubic J (above). In the
/// SVD frame the Hessian of J is block diagonal: it couples only the diagonal entries
/// (entry (i, j) = σ_k) and each off-diagonal pair (F̂_ij, F̂_ji) through the minor
/// −σ_k F̂_ij F̂_ji, which gives ±σ_k on the flip/twist modes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StableNeoHookean {
    /// Stable Neo-Hookean shear parameter μ' (= Lamé μ).
    pub mu_snh: f64,
    /// Stable Neo-Hookean volume parameter λ' (= Lamé λ + μ; not the Lamé λ).
    pub lambda_snh: f64,
}

impl StableNeoHookean {
    /// Maps the Lamé parameters to μ' = μ, λ' = λ + μ (same small-strain behaviour as
    /// [`super::LinearElastic`] with the same Lamé parameters).
    pub fn new(lame: Lame) -> Self {
        Self {
            mu_snh: lame.mu,
            lambda_snh: lame.lambda + lame.mu,
        }
    }

    /// The Lamé parameters this material was built from: μ = μ', λ = λ' − μ'.
    pub fn lame(&self) -> Lame {
        Lame {
            mu: self.mu_snh,
            lambda: self.lambda_snh - self.mu_snh,
        }
    }

    /// The rest-stability offset α = 1 + μ'/λ'.
    pub fn alpha(&self) -> f64 {
        1.0 + self.mu_snh / self.lambda_snh
    }
}

#[allow(non_snake_case)]
impl Material for StableNeoHookean {
    const NAME: &'static str = "stable-neo-hookean";
    const INVERSION_SAFE: bool = true;

    #[inline]
    fn psi(&self, F: &Mat3) -> f64 {
        let (mu, la) = (self.mu_snh, self.lambda_snh);
        let Jm1 = det(F) - 1.0;
        0.5 * mu * (F.norm_squared() - 3.0) - mu * Jm1 + 0.5 * la * Jm1 * Jm1
    }

    #[inline]
    fn pk1(&self, F: &Mat3) -> Mat3 {
        let cof = cofactor(F);
        let J = det_from_cofactor(F, &cof);
        F * self.mu_snh + cof * (self.lambda_snh * (J - 1.0) - self.mu_snh)
    }

    #[inline]
    fn psi_pk1(&self, F: &Mat3) -> (f64, Mat3) {
        let (mu, la) = (self.mu_snh, self.lambda_snh);
        let cof = cofactor(F);
        let Jm1 = det_from_cofactor(F, &cof) - 1.0;
        let psi = 0.5 * mu * (F.norm_squared() - 3.0) - mu * Jm1 + 0.5 * la * Jm1 * Jm1;
        (psi, F * mu + cof * (la * Jm1 - mu))
    }

    #[inline]
    fn dpdf(&self, F: &Mat3) -> Mat9 {
        let (mu, la) = (self.mu_snh, self.lambda_snh);
        let cof = cofactor(F);
        let J = det_from_cofactor(F, &cof);
        // (g_i g_j) λ' is exactly symmetric, and a plain 9×9 loop vectorises.
        let g = cof.as_slice();
        let mut m = Mat9::from_fn(|i, j| g[i] * g[j] * la);
        for a in 0..9 {
            m[(a, a)] += mu;
        }
        add_cofactor_hessian(&mut m, F, la * (J - 1.0) - mu);
        m
    }

    /// Analytic projection (see the type's documentation). Non-finite F yields the
    /// (non-finite) tangent unchanged.
    #[inline]
    fn dpdf_projected(&self, F: &Mat3) -> Mat9 {
        let (mu, la) = (self.mu_snh, self.lambda_snh);
        cofactor_tangent::project(self.dpdf(F), F, mu, |J| (la, la * (J - 1.0) - mu))
    }
}

// ---------------------------------------------------------------------------------------------
// Helpers shared by the materials of this module.

/// cof(F) = ∂ det F / ∂F = det(F) F⁻ᵀ, computed directly: its columns are f₁×f₂, f₂×f₀, f₀×f₁
/// for the columns f_i of F. Defined (and smooth) for every F.
#[allow(non_snake_case)]
#[inline]
pub(super) fn cofactor(F: &Mat3) -> Mat3 {
    let (f0, f1, f2) = (F.column(0), F.column(1), F.column(2));
    Mat3::from_columns(&[f1.cross(&f2), f2.cross(&f0), f0.cross(&f1)])
}

/// det F = f₀ · (f₁ × f₂): the same expansion as [`det_from_cofactor`], so ψ and P agree on
/// the sign of J to the last bit.
#[allow(non_snake_case)]
#[inline]
pub(super) fn det(F: &Mat3) -> f64 {
    F.column(0).dot(&F.column(1).cross(&F.column(2)))
}

/// det F = f₀ · cof(F)₀, reusing an already computed cofactor.
#[allow(non_snake_case)]
#[inline]
pub(super) fn det_from_cofactor(F: &Mat3, cof: &Mat3) -> f64 {
    F.column(0).dot(&cof.column(0))
}

/// m += s ∂cof(F)/∂F (the Hessian of det F) in the column-major flattening: block (j, l) is
/// −s ε_jlm \[f_m\]× for j ≠ l, where \[v\]× x = v × x. Exactly symmetric.
#[allow(non_snake_case)]
#[inline]
pub(super) fn add_cofactor_hessian(m: &mut Mat9, F: &Mat3, s: f64) {
    // Even permutations (j, l, m): ε_jlm = +1, block (j, l) = −s[f_m]×, block (l, j) = +s[f_m]×.
    for (j, l, c) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
        let v = [F[(0, c)] * s, F[(1, c)] * s, F[(2, c)] * s];
        // Entry (r, k) of −[v]× = [[0, v₂, −v₁], [−v₂, 0, v₀], [v₁, −v₀, 0]] goes to block (j, l);
        // block (l, j) is its transpose.
        let mut add = |r: usize, k: usize, x: f64| {
            m[(r + 3 * j, k + 3 * l)] += x;
            m[(k + 3 * l, r + 3 * j)] += x;
        };
        add(0, 1, v[2]);
        add(0, 2, -v[1]);
        add(1, 0, -v[2]);
        add(1, 2, v[0]);
        add(2, 0, v[1]);
        add(2, 1, -v[0]);
    }
}

/// Upper triangle (row ≤ column) of m += s vec(a) vec(b)ᵀ; finish with [`mirror_upper`].
#[inline]
pub(super) fn add_outer_upper(m: &mut Mat9, a: &Mat3, b: &Mat3, s: f64) {
    let (a, b) = (a.as_slice(), b.as_slice());
    for j in 0..9 {
        let sb = s * b[j];
        for i in 0..=j {
            m[(i, j)] += a[i] * sb;
        }
    }
}

/// Copies the strict upper triangle of `m` onto its lower triangle.
#[inline]
pub(super) fn mirror_upper(m: &mut Mat9) {
    for j in 0..9 {
        for i in 0..j {
            m[(j, i)] = m[(i, j)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::corotated::signed_svd;
    use super::cofactor_tangent::{scaling_block, twist_flip};
    use super::*;

    fn material() -> StableNeoHookean {
        StableNeoHookean::new(Lame {
            mu: 1.3,
            lambda: 7.9,
        })
    }

    fn sample_fs() -> Vec<Mat3> {
        vec![
            Mat3::identity(),
            Mat3::new(1.2, 0.3, -0.1, 0.05, 0.9, 0.2, -0.3, 0.1, 1.1),
            Mat3::new(0.3, 0.1, 0.0, -0.2, 0.4, 0.1, 0.0, 0.05, -0.6),
            Mat3::new(2.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, -0.5),
            Mat3::new(0.1, 1.5, 0.0, 0.0, 0.2, 0.0, 0.7, 0.0, 0.1),
            Mat3::from_diagonal_element(0.2),
            Mat3::zeros(),
        ]
    }

    #[test]
    fn analytic_eigensystem_reconstructs_the_tangent() {
        let m = material();
        for f in sample_fs() {
            let svd = signed_svd(&f);
            let s = &svd.sigma;
            let c = m.lambda_snh * (s[0] * s[1] * s[2] - 1.0) - m.mu_snh;
            let mut rec = Mat9::zeros();
            let mut vecs: Vec<Mat3> = Vec::new();
            for (val, w) in twist_flip(&svd, m.mu_snh, c) {
                let q = w / 2f64.sqrt();
                add_outer_upper(&mut rec, &q, &q, val);
                vecs.push(q);
            }
            let eig = scaling_block(s, m.mu_snh, m.lambda_snh, c).symmetric_eigen();
            for i in 0..3 {
                let e = eig.eigenvectors.column(i);
                let mut q = Mat3::zeros();
                for j in 0..3 {
                    q += svd.u.column(j) * svd.v.column(j).transpose() * e[j];
                }
                add_outer_upper(&mut rec, &q, &q, eig.eigenvalues[i]);
                vecs.push(q);
            }
            mirror_upper(&mut rec);
            let a = m.dpdf(&f);
            assert!((rec - a).norm() <= 1e-12 * a.norm(), "F = {f}");
            // The nine eigenvectors are orthonormal.
            for (i, p) in vecs.iter().enumerate() {
                for (j, q) in vecs.iter().enumerate() {
                    let d = p.dot(q) - if i == j { 1.0 } else { 0.0 };
                    assert!(d.abs() < 1e-12, "F = {f}: <q{i}, q{j}> off by {d}");
                }
            }
        }
    }

    #[test]
    fn analytic_projection_equals_numeric_projection() {
        let m = material();
        for f in sample_fs() {
            let a = m.dpdf_projected(&f);
            let b = super::super::project_psd(&m.dpdf(&f));
            assert_eq!(a, a.transpose());
            assert!((a - b).norm() <= 1e-10 * b.norm().max(1.0), "F = {f}");
        }
    }

    #[test]
    fn cofactor_hessian_matches_finite_differences() {
        let f = Mat3::new(1.2, 0.3, -0.1, 0.05, 0.9, 0.2, -0.3, 0.1, 1.1);
        let mut h = Mat9::zeros();
        add_cofactor_hessian(&mut h, &f, 1.0);
        let eps = 1e-6;
        for b in 0..9 {
            let (mut fp, mut fm) = (f, f);
            fp.as_mut_slice()[b] += eps;
            fm.as_mut_slice()[b] -= eps;
            let d = (cofactor(&fp) - cofactor(&fm)) / (2.0 * eps);
            for a in 0..9 {
                assert!((h[(a, b)] - d.as_slice()[a]).abs() < 1e-8);
            }
        }
        let inv_t = f.try_inverse().unwrap().transpose() * f.determinant();
        assert!((cofactor(&f) - inv_t).norm() < 1e-14);
    }
}
