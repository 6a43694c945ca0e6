//! Fixed corotated elasticity (Stomakhin et al. 2012), and the rotation-variant SVD shared by
//! the materials of this module.

use super::stable_neo_hookean::{
    add_cofactor_hessian, add_outer_upper, cofactor, det, det_from_cofactor, mirror_upper,
};
use super::{Lame, Mat9, Material};
use crate::{Mat3, Vec3};

/// Fixed corotated elasticity (Stomakhin, Howes, Schroeder & Teran, "Energetically consistent
/// invertible elasticity", 2012).
///
/// With the rotation-variant SVD F = UΣVᵀ (U, V rotations, σ₀ ≥ σ₁ ≥ |σ₂|, σ₂ < 0 iff
/// det F < 0), R = UVᵀ (a rotation, det R = +1 even for inverted F), S = RᵀF = VΣVᵀ
/// (symmetric), J = det F and cof(F) = ∂J/∂F:
///
/// * ψ(F) = μ ‖F − R‖²_F + λ/2 (J − 1)² = μ Σ_i (σ_i − 1)² + λ/2 (J − 1)²
/// * P(F) = 2μ (F − R) + λ (J − 1) cof(F)
/// * ∂P/∂F = 2μ (I₉ − ∂R/∂F) + λ vec(cof) vec(cof)ᵀ + λ (J − 1) ∂cof/∂F, with
///   ∂R/∂F = Σ_k w_k w_kᵀ / (σ_i + σ_j), w_k = vec(u_i v_jᵀ − u_j v_iᵀ), over the pairs
///   (i, j) with third index k.
///
/// At F = I the tangent is 2μ𝒮 + λ vec(I)vec(I)ᵀ, the linear-elasticity tangent.
///
/// # Inversion and the singular set
///
/// ψ, P and ∂P/∂F are finite for every finite F (`INVERSION_SAFE`). R (hence P) is continuous
/// but not differentiable where σ_i + σ_j = 0 for some pair, which with the ordering above
/// happens only when σ₁ + σ₂ = 0 (e.g. F = diag(1, 1, −1)) or for rank-deficient F. There the
/// denominator σ_i + σ_j is clamped from below to 10⁻⁸ · max(σ₀, 1), so ∂P/∂F stays finite
/// (with entries up to ~2μ · 10⁸); its rotational part is then not the derivative of P, and
/// is negative, so the projected tangent simply drops it. Non-finite F gives non-finite output
/// (never a panic or a hang).
///
/// # Derivation
///
/// ∂‖F − R‖²/∂F = 2(F − R) because (F − R) : δR = R S : R Ω − R : R Ω = S : Ω − I : Ω = 0 for
/// the skew Ω = RᵀδR and symmetric S. For δR, differentiate F = RS: RᵀδF = Ω S + δS, so the
/// skew part gives RᵀδF − δFᵀR = ΩS + SΩ. Writing Ω = ω̂ (ω̂x = ω × x),
/// axial(ω̂S + Sω̂) = (tr(S) I − S) ω, hence ω = (tr(S) I − S)⁻¹ axial(RᵀδF − δFᵀR) with
/// axial(A) = (A₂₁, A₀₂, A₁₀). In the SVD frame (δF̂ = UᵀδFV) tr(S)I − S = diag(σ₁ + σ₂,
/// σ₀ + σ₂, σ₀ + σ₁), so ω̂_k = (δF̂_ji − δF̂_ij)/(σ_i + σ_j) (signs per the pair's orientation)
/// and δR = U ω̂ Vᵀ, which is the symmetric rank-3 operator above. The λ terms are those of
/// any (J − 1)² energy: ∂J/∂F = cof and ∂cof/∂F is the Hessian of det (see
/// [`super::StableNeoHookean`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corotated {
    /// Shear modulus μ.
    pub mu: f64,
    /// First Lamé parameter λ.
    pub lambda: f64,
}

impl Corotated {
    pub fn new(lame: Lame) -> Self {
        Self {
            mu: lame.mu,
            lambda: lame.lambda,
        }
    }
}

#[allow(non_snake_case)]
impl Material for Corotated {
    const NAME: &'static str = "corotated";
    const INVERSION_SAFE: bool = true;

    #[inline]
    fn psi(&self, F: &Mat3) -> f64 {
        let s = signed_svd(F).sigma;
        let Jm1 = det(F) - 1.0;
        let d = s.add_scalar(-1.0);
        self.mu * d.norm_squared() + 0.5 * self.lambda * Jm1 * Jm1
    }

    #[inline]
    fn pk1(&self, F: &Mat3) -> Mat3 {
        self.psi_pk1(F).1
    }

    #[inline]
    fn psi_pk1(&self, F: &Mat3) -> (f64, Mat3) {
        let svd = signed_svd(F);
        let R = svd.u * svd.v.transpose();
        let cof = cofactor(F);
        let Jm1 = det_from_cofactor(F, &cof) - 1.0;
        let d = svd.sigma.add_scalar(-1.0);
        let psi = self.mu * d.norm_squared() + 0.5 * self.lambda * Jm1 * Jm1;
        let P = (F - R) * (2.0 * self.mu) + cof * (self.lambda * Jm1);
        (psi, P)
    }

    fn dpdf(&self, F: &Mat3) -> Mat9 {
        let (mu, lambda) = (self.mu, self.lambda);
        let svd = signed_svd(F);
        let (u, s, v) = (&svd.u, &svd.sigma, &svd.v);
        let cof = cofactor(F);
        let J = det_from_cofactor(F, &cof);
        let floor = ROTATION_DENOMINATOR_FLOOR * s[0].max(1.0);
        let mut m = Mat9::zeros();
        add_outer_upper(&mut m, &cof, &cof, lambda);
        for (i, j) in [(1, 2), (0, 2), (0, 1)] {
            let w = u.column(i) * v.column(j).transpose() - u.column(j) * v.column(i).transpose();
            // `max` also maps a NaN denominator to the floor; w is then NaN anyway.
            let denom = (s[i] + s[j]).max(floor);
            add_outer_upper(&mut m, &w, &w, -2.0 * mu / denom);
        }
        mirror_upper(&mut m);
        for a in 0..9 {
            m[(a, a)] += 2.0 * mu;
        }
        add_cofactor_hessian(&mut m, F, lambda * (J - 1.0));
        m
    }
}

/// Relative lower bound of σ_i + σ_j in ∂R/∂F (see [`Corotated`]).
const ROTATION_DENOMINATOR_FLOOR: f64 = 1e-8;

// ---------------------------------------------------------------------------------------------
// Rotation-variant SVD.

/// F = U diag(σ) Vᵀ with U, V proper rotations, σ₀ ≥ σ₁ ≥ |σ₂| and σ₂ carrying the sign of
/// det F.
#[derive(Debug, Clone, Copy)]
pub(super) struct SignedSvd {
    pub u: Mat3,
    pub sigma: Vec3,
    pub v: Mat3,
}

/// Relative orthogonality at which a one-sided Jacobi rotation is skipped.
const JACOBI_TOL: f64 = 1e-15;
/// Sweep cap; 3×3 one-sided Jacobi converges quadratically, typically in 3–5 sweeps.
const JACOBI_MAX_SWEEPS: usize = 16;

/// Rotation-variant SVD by one-sided (Hestenes) Jacobi: plane rotations V accumulate until the
/// columns of B = FV are mutually orthogonal to [`JACOBI_TOL`], which gives singular values
/// with high relative accuracy. Columns are sorted by decreasing norm, V is made a rotation
/// (negating its last column if needed), U = [b₀/σ₀, u₁, u₀ × u₁] with u₁ the normalised part
/// of b₁ orthogonal to u₀ (any unit vector orthogonal to u₀ if b₁ vanishes), and
/// σ₂ = u₂ · b₂ is signed. Rank-deficient and zero F are handled (U completes to a rotation);
/// non-finite F gives non-finite output after at most [`JACOBI_MAX_SWEEPS`] sweeps.
#[allow(non_snake_case)]
pub(super) fn signed_svd(F: &Mat3) -> SignedSvd {
    let mut b = *F;
    let mut v = Mat3::identity();
    for _ in 0..JACOBI_MAX_SWEEPS {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let alpha = b.column(p).norm_squared();
            let beta = b.column(q).norm_squared();
            let gamma = b.column(p).dot(&b.column(q));
            // |γ| ≤ tol √(αβ), squared. NaN input is skipped too (and propagates).
            if gamma * gamma <= (JACOBI_TOL * JACOBI_TOL) * (alpha * beta) || gamma.is_nan() {
                continue;
            }
            let zeta = (beta - alpha) / (2.0 * gamma);
            // t = sign(ζ)/(|ζ| + √(1 + ζ²)), the smaller root of t² + 2ζt − 1 = 0; for huge |ζ|
            // (ζ² would overflow) t = 1/(2ζ) to full precision.
            let za = zeta.abs();
            let t = if za < 1e100 {
                (1.0 / (za + (1.0 + zeta * zeta).sqrt())).copysign(zeta)
            } else {
                0.5 / zeta
            };
            let c = 1.0 / (1.0 + t * t).sqrt();
            let s = c * t;
            for i in 0..3 {
                let (bp, bq) = (b[(i, p)], b[(i, q)]);
                b[(i, p)] = c * bp - s * bq;
                b[(i, q)] = s * bp + c * bq;
                let (vp, vq) = (v[(i, p)], v[(i, q)]);
                v[(i, p)] = c * vp - s * vq;
                v[(i, q)] = s * vp + c * vq;
            }
            rotated = true;
        }
        if !rotated {
            break;
        }
    }

    // Sort columns by decreasing norm; each swap flips det V.
    let mut n = [
        b.column(0).norm_squared(),
        b.column(1).norm_squared(),
        b.column(2).norm_squared(),
    ];
    let mut odd = false;
    for (p, q) in [(0, 1), (1, 2), (0, 1)] {
        if n[p] < n[q] {
            n.swap(p, q);
            b.swap_columns(p, q);
            v.swap_columns(p, q);
            odd = !odd;
        }
    }
    if odd {
        b.column_mut(2).neg_mut();
        v.column_mut(2).neg_mut();
    }

    let b0: Vec3 = b.column(0).into_owned();
    let b1: Vec3 = b.column(1).into_owned();
    let b2: Vec3 = b.column(2).into_owned();
    let s0 = b0.norm();
    let u0 = if s0 > 0.0 { b0 / s0 } else { Vec3::x() };
    let w = b1 - u0 * u0.dot(&b1);
    let wn = w.norm();
    let u1 = if wn > 1e-150 * s0 {
        w / wn
    } else {
        orthogonal_unit(&u0)
    };
    let u2 = u0.cross(&u1);
    SignedSvd {
        u: Mat3::from_columns(&[u0, u1, u2]),
        sigma: Vec3::new(s0, u1.dot(&b1), u2.dot(&b2)),
        v,
    }
}

/// A unit vector orthogonal to the unit vector `a`.
fn orthogonal_unit(a: &Vec3) -> Vec3 {
    let i = a.iamin();
    let mut e = Vec3::zeros();
    e[i] = 1.0;
    let w = e - a * a[i];
    w / w.norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_svd(f: &Mat3) {
        let svd = signed_svd(f);
        let (u, s, v) = (svd.u, svd.sigma, svd.v);
        let scale = f.norm().max(1e-300);
        let rec = u * Mat3::from_diagonal(&s) * v.transpose();
        assert!((rec - f).norm() <= 1e-14 * scale, "F = {f}, rec = {rec}");
        for q in [u, v] {
            assert!((q.transpose() * q - Mat3::identity()).norm() < 1e-14, "{q}");
            assert!((q.determinant() - 1.0).abs() < 1e-14);
        }
        assert!(s[0] >= s[1] - 1e-15 * scale && s[1] >= s[2].abs() - 1e-15 * scale);
        if f.determinant() != 0.0 {
            assert_eq!(s[2] < 0.0, f.determinant() < 0.0, "F = {f}, σ = {s}");
        }
    }

    #[test]
    fn signed_svd_of_assorted_matrices() {
        let cases = [
            Mat3::identity(),
            -Mat3::identity(),
            Mat3::zeros(),
            Mat3::from_diagonal(&Vec3::new(1.0, 1.0, -1.0)),
            Mat3::from_diagonal(&Vec3::new(0.1, 3.0, 2.0)),
            Mat3::new(1.2, 0.3, -0.1, 0.05, 0.9, 0.2, -0.3, 0.1, 1.1),
            Mat3::new(0.3, 0.1, 0.0, -0.2, 0.4, 0.1, 0.0, 0.05, -0.6),
            // Rank one and rank two.
            Vec3::new(1.0, 2.0, 3.0) * Vec3::new(-1.0, 0.5, 2.0).transpose(),
            Mat3::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0),
            // Nearly repeated singular values.
            Mat3::from_diagonal(&Vec3::new(1.0, 1.0 + 1e-12, 1.0 - 1e-12)),
            Mat3::new(1e-9, 1.0, 0.0, 0.0, 1e-9, 1.0, 1.0, 0.0, 1e-9),
        ];
        for f in &cases {
            check_svd(f);
        }
        let nan = Mat3::from_element(f64::NAN);
        assert!(signed_svd(&nan).sigma[0].is_nan());
    }

    #[test]
    fn rotation_gradient_matches_finite_differences_when_inverted() {
        // F = RS with S indefinite: ∂R/∂F is smooth away from σ_i + σ_j = 0.
        let f = Mat3::new(0.3, 0.1, 0.0, -0.2, 0.4, 0.1, 0.0, 0.05, -0.6);
        let m = Corotated::new(Lame {
            mu: 1.0,
            lambda: 0.0,
        });
        let a = m.dpdf(&f);
        let h = 1e-6;
        for b in 0..9 {
            let (mut fp, mut fm) = (f, f);
            fp.as_mut_slice()[b] += h;
            fm.as_mut_slice()[b] -= h;
            let d = (m.pk1(&fp) - m.pk1(&fm)) / (2.0 * h);
            for r in 0..9 {
                assert!((a[(r, b)] - d.as_slice()[r]).abs() < 1e-7, "{r} {b}");
            }
        }
    }

    #[test]
    fn singular_set_stays_finite() {
        let m = Corotated::new(Lame {
            mu: 1.0,
            lambda: 4.0,
        });
        for f in [
            Mat3::from_diagonal(&Vec3::new(1.0, 1.0, -1.0)),
            Mat3::zeros(),
            Mat3::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0),
        ] {
            assert!(m.psi(&f).is_finite());
            assert!(m.pk1(&f).iter().all(|x| x.is_finite()));
            assert!(m.dpdf(&f).iter().all(|x| x.is_finite()));
            assert!(m.dpdf_projected(&f).iter().all(|x| x.is_finite()));
        }
    }
}
