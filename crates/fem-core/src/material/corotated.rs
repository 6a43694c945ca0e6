//! Fixed corotated elasticity (Stomakhin et al. 2012), and the rotation-variant SVD shared by
//! the materials of this module.

use super::cofactor_tangent::{PAIRS, mode_shapes, project_with, scaling_block, twist_flip};
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
/// ψ, P and ∂P/∂F need R, not the SVD: where det F is well positive (every element of a body
/// that is not being crushed) R is the polar factor, which a few Newton steps find about four
/// times faster than the Jacobi SVD (`cargo bench -p benches --bench fem -- material`), and
/// ∂R/∂F follows from it (`Corotated::tangent_from_rotation`). Elsewhere, and to project a
/// tangent that is not positive definite, the SVD is taken.
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
        let Jm1 = det(F) - 1.0;
        self.mu * (F - rotation(F)).norm_squared() + 0.5 * self.lambda * Jm1 * Jm1
    }

    #[inline]
    fn pk1(&self, F: &Mat3) -> Mat3 {
        self.psi_pk1(F).1
    }

    #[inline]
    fn psi_pk1(&self, F: &Mat3) -> (f64, Mat3) {
        let cof = cofactor(F);
        let Jm1 = det_from_cofactor(F, &cof) - 1.0;
        let d = F - rotation(F);
        let psi = self.mu * d.norm_squared() + 0.5 * self.lambda * Jm1 * Jm1;
        let P = d * (2.0 * self.mu) + cof * (self.lambda * Jm1);
        (psi, P)
    }

    fn dpdf(&self, F: &Mat3) -> Mat9 {
        match tangent_rotation(F) {
            Some(r) => self.tangent_from_rotation(F, &r),
            None => self.tangent_from_svd(F, &signed_svd(F)),
        }
    }

    /// Analytic projection: the tangent's eigensystem in the SVD frame (see the type's
    /// documentation) with its negative eigenvalues clamped to zero, which equals the clamped
    /// eigen-decomposition of [`super::project_psd`]. A positive definite tangent is returned
    /// as it is, without the SVD where the polar rotation gave it; otherwise it costs one 3×3
    /// SVD (and a 3×3 eigenproblem when the scaling block is indefinite). Non-finite F yields
    /// the (non-finite) tangent unchanged.
    fn dpdf_projected(&self, F: &Mat3) -> Mat9 {
        let (m, svd) = match tangent_rotation(F) {
            Some(r) => (self.tangent_from_rotation(F, &r), None),
            None => {
                let svd = signed_svd(F);
                (self.tangent_from_svd(F, &svd), Some(svd))
            }
        };
        let (mu, lambda) = (self.mu, self.lambda);
        project_with(m, F, svd, |svd| {
            // 2μ I₉ and the λ terms have the eigensystem of the Neo-Hookean tangents with
            // (μ, a, c) = (2μ, λ, λ(J − 1)); −2μ ∂R/∂F adds −4μ/(σ_i + σ_j) to each twist
            // (w wᵀ with ‖w‖² = 2).
            let s = &svd.sigma;
            let c = lambda * (s[0] * s[1] * s[2] - 1.0);
            let mut pairs = twist_flip(svd, 2.0 * mu, c);
            for (twist, (i, j)) in pairs[..3].iter_mut().zip(PAIRS) {
                twist.0 -= 4.0 * mu / rotation_denominator(s, i, j);
            }
            (pairs, scaling_block(s, 2.0 * mu, lambda, c))
        })
    }
}

/// σ_i + σ_j, clamped from below (see [`Corotated`]); `max` also maps NaN to the floor.
fn rotation_denominator(s: &Vec3, i: usize, j: usize) -> f64 {
    (s[i] + s[j]).max(ROTATION_DENOMINATOR_FLOOR * s[0].max(1.0))
}

#[allow(non_snake_case)]
impl Corotated {
    /// ∂P/∂F at F with −2μ ∂R/∂F from the rotation-variant SVD `svd` of F: Σ over the pairs
    /// (i, j) of −2μ/(σ_i + σ_j) w wᵀ, w = u_i v_jᵀ − u_j v_iᵀ.
    fn tangent_from_svd(&self, F: &Mat3, svd: &SignedSvd) -> Mat9 {
        let s = &svd.sigma;
        // The twists' shapes come first.
        let w = mode_shapes(svd);
        self.tangent(F, |m| {
            for (k, (i, j)) in PAIRS.into_iter().enumerate() {
                // `max` also maps a NaN denominator to the floor; w is then NaN anyway.
                add_outer_upper(
                    m,
                    &w[k],
                    &w[k],
                    -2.0 * self.mu / rotation_denominator(s, i, j),
                );
            }
        })
    }

    /// ∂P/∂F at F with −2μ ∂R/∂F from the polar rotation R of F, no SVD: ω of δR = Rω̂ is
    /// G a(δF) with G = (tr(S) I − S)⁻¹, S = RᵀF, and a(δF) = axial(RᵀδF − δFᵀR) (see the
    /// type's derivation), and ⟨δF', Rω̂⟩ = a(δF')·ω, so ∂R/∂F = Σ_ij G_ij vec(A_i) vec(A_j)ᵀ
    /// with A_i the matrix of a(δF)_i = A_i : δF.
    fn tangent_from_rotation(&self, F: &Mat3, R: &Mat3) -> Mat9 {
        let S = R.tr_mul(F);
        let mut T = -(S + S.transpose()) * 0.5;
        let trace = S.trace();
        for i in 0..3 {
            T[(i, i)] += trace;
        }
        // T is symmetric, so its inverse is cof(T)/det T.
        let cof_t = cofactor(&T);
        let G = cof_t / det_from_cofactor(&T, &cof_t);
        let (r0, r1, r2) = (R.column(0), R.column(1), R.column(2));
        let zero = Vec3::zeros();
        // a₀ = r₂·δf₁ − r₁·δf₂, a₁ = r₀·δf₂ − r₂·δf₀, a₂ = r₁·δf₀ − r₀·δf₁ (δf_j column j).
        let a = [
            Mat3::from_columns(&[zero, r2.into(), -r1]),
            Mat3::from_columns(&[-r2, zero, r0.into()]),
            Mat3::from_columns(&[r1.into(), -r0, zero]),
        ];
        self.tangent(F, |m| {
            for (i, ai) in a.iter().enumerate() {
                for (j, aj) in a.iter().enumerate() {
                    add_outer_upper(m, ai, aj, -2.0 * self.mu * G[(i, j)]);
                }
            }
        })
    }

    /// ∂P/∂F = 2μ I₉ + λ vec(cof) vec(cof)ᵀ + λ(J − 1) ∂cof/∂F plus the rotational term, which
    /// `add_rotation` adds to the upper triangle.
    fn tangent(&self, F: &Mat3, add_rotation: impl FnOnce(&mut Mat9)) -> Mat9 {
        let (mu, lambda) = (self.mu, self.lambda);
        let cof = cofactor(F);
        let J = det_from_cofactor(F, &cof);
        let mut m = Mat9::zeros();
        add_outer_upper(&mut m, &cof, &cof, lambda);
        add_rotation(&mut m);
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
// The rotation R = UVᵀ.

/// R = UVᵀ of the rotation-variant SVD: by Newton's polar iteration ([`polar_rotation`]) when
/// F is well away from inversion, from [`signed_svd`] otherwise.
#[allow(non_snake_case)]
#[inline]
fn rotation(F: &Mat3) -> Mat3 {
    polar_rotation(F).unwrap_or_else(|| {
        let svd = signed_svd(F);
        svd.u * svd.v.transpose()
    })
}

/// Below this det F / (‖F‖²/3)^{3/2} (1 for a scaled rotation, 0 for a singular F) the polar
/// iteration is not used.
const POLAR_MIN_SHAPE: f64 = 1e-3;
/// Newton steps at most; from a well-shaped F the iteration settles in 3–7.
const POLAR_MAX_STEPS: usize = 12;
/// A step smaller than this (Frobenius) leaves an error of about its square: the last one.
const POLAR_LAST_STEP: f64 = 1e-8;
/// The steps are scaled while |det X − 1| is above this: far from a scaled rotation scaling
/// saves steps, near one it changes nothing and costs a cube root.
const POLAR_SCALED_STEPS_DET: f64 = 1e-2;
/// Below this ‖F‖² the tangent takes the SVD even where the polar rotation exists: with the
/// shape above 10⁻³, σ₂ ≥ 1.9·10⁻⁴ ‖F‖, so from here on σ_i + σ_j stays above the floor the
/// SVD's tangent clamps it to (see [`Corotated`]), and the two tangents agree.
const POLAR_TANGENT_MIN_NORM_SQUARED: f64 = 1e-9;

/// The polar rotation of F for its tangent: [`polar_rotation`] but for F so small that the
/// tangent's denominators would fall below their floor.
#[allow(non_snake_case)]
fn tangent_rotation(F: &Mat3) -> Option<Mat3> {
    polar_rotation(F).filter(|_| F.norm_squared() >= POLAR_TANGENT_MIN_NORM_SQUARED)
}

/// The rotation of the polar decomposition F = RS (S symmetric positive definite), which
/// for det F > 0 is the UVᵀ of the rotation-variant SVD, by Newton's iteration
/// X ← (γX + γ⁻¹X⁻ᵀ)/2 from X = F with X⁻ᵀ = cof(X)/det X (Higham 1986). γ = (det X)^{-1/3}
/// scales the steps while det X is far from 1; scaled or not, the iteration converges
/// quadratically to the same R, so R is the polar factor to rounding. `None` when det F is
/// not positive, F is too near singular (see [`POLAR_MIN_SHAPE`]), non-finite, or the
/// iteration has not settled in [`POLAR_MAX_STEPS`]: the caller then takes the SVD, which
/// handles every F.
#[allow(non_snake_case)]
fn polar_rotation(F: &Mat3) -> Option<Mat3> {
    let mean_square = F.norm_squared() / 3.0;
    let det_f = det(F);
    if det_f.is_nan() || det_f <= POLAR_MIN_SHAPE * mean_square * mean_square.sqrt() {
        return None;
    }
    let mut x = *F;
    for _ in 0..POLAR_MAX_STEPS {
        let cof = cofactor(&x);
        let d = det_from_cofactor(&x, &cof);
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let next = if (d - 1.0).abs() > POLAR_SCALED_STEPS_DET {
            let gamma = d.cbrt().recip();
            (x * gamma + cof * (1.0 / (gamma * d))) * 0.5
        } else {
            (x + cof * (1.0 / d)) * 0.5
        };
        let step = (next - x).norm_squared();
        x = next;
        if step <= POLAR_LAST_STEP * POLAR_LAST_STEP {
            return Some(x);
        }
    }
    None
}

// ---------------------------------------------------------------------------------------------
// Rotation-variant SVD.

/// F = U diag(σ) Vᵀ with U, V proper rotations, σ₀ ≥ σ₁ ≥ |σ₂| and σ₂ carrying the sign of
/// det F.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SignedSvd {
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
pub(crate) fn signed_svd(F: &Mat3) -> SignedSvd {
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
    fn polar_rotation_is_the_svd_rotation() {
        let mut rng = crate::rng::SplitMix64::new(7);
        for n in 0..2000 {
            let f = random_f(&mut rng, [1e-3, 0.1, 1.0, 4.0][n % 4]);
            let svd = signed_svd(&f);
            let expected = svd.u * svd.v.transpose();
            let r = polar_rotation(&f).unwrap_or_else(|| panic!("F = {f}: no polar rotation"));
            assert!((r - expected).norm() < 1e-12, "F = {f}: {r} vs {expected}");
            assert!((r.transpose() * r - Mat3::identity()).norm() < 1e-14);
        }
        assert_eq!(polar_rotation(&Mat3::identity()), Some(Mat3::identity()));
        // Shape det F / (‖F‖²/3)^{3/2} 1.8·10⁻³, just above the threshold.
        assert!(polar_rotation(&Mat3::from_diagonal(&Vec3::new(1.0, 1.0, 1e-3))).is_some());
        for f in [
            // Shape 3.7·10⁻⁴, just below it.
            Mat3::from_diagonal(&Vec3::new(1.0, 1.0, 2e-4)),
            Mat3::from_diagonal(&Vec3::new(1.0, 1.0, -1.0)),
            Mat3::zeros(),
            Mat3::from_element(f64::NAN),
            Mat3::from_diagonal(&Vec3::new(f64::INFINITY, 1.0, 1.0)),
        ] {
            assert_eq!(polar_rotation(&f), None, "F = {f}");
        }
    }

    /// F = R₁ diag(σ) R₂ with random rotations and ln σ_i uniform in ±spread/2 (spread 4: σ
    /// from 0.14 to 7.4).
    fn random_f(rng: &mut crate::rng::SplitMix64, spread: f64) -> Mat3 {
        let mut angle = || rng.range(-3.0, 3.0);
        let r1 = nalgebra::Rotation3::from_euler_angles(angle(), angle(), angle());
        let r2 = nalgebra::Rotation3::from_euler_angles(angle(), angle(), angle());
        let s = Vec3::from_fn(|_, _| (spread * rng.range(-0.5, 0.5)).exp());
        r1.matrix() * Mat3::from_diagonal(&s) * r2.matrix()
    }

    #[test]
    fn tangent_from_the_polar_rotation_is_the_svd_one() {
        let m = Corotated::new(Lame {
            mu: 1.0,
            lambda: 9.0,
        });
        let mut rng = crate::rng::SplitMix64::new(11);
        let mut fs = vec![
            Mat3::identity(),
            Mat3::from_diagonal(&Vec3::new(0.1, 3.0, 2.0)),
            Mat3::new(1.2, 0.3, -0.1, 0.05, 0.9, 0.2, -0.3, 0.1, 1.1),
            Mat3::new(0.7, 0.6, 0.0, -0.6, 0.7, 0.1, 0.0, 0.05, 1.3),
        ];
        fs.extend((0..200).map(|n| random_f(&mut rng, [0.1, 1.0, 4.0][n % 3])));
        for f in &fs {
            let r = polar_rotation(f).expect("well-shaped F");
            let (a, b) = (
                m.tangent_from_rotation(f, &r),
                m.tangent_from_svd(f, &signed_svd(f)),
            );
            assert!((a - b).norm() <= 1e-11 * b.norm(), "F = {f}: {a} vs {b}");
        }
        // A crushed element keeps the SVD tangent's floor on σ_i + σ_j: the polar rotation
        // exists, but the tangent does not take it.
        for scale in [1e-5, 1e-10, 1e-100] {
            let f = fs[3] * scale;
            assert!(polar_rotation(&f).is_some());
            assert_eq!(
                m.dpdf(&f),
                m.tangent_from_svd(&f, &signed_svd(&f)),
                "scale {scale}"
            );
        }
    }

    #[test]
    fn projection_at_the_zero_matrix_is_the_shear_part() {
        // At F = 0 the tangent is 2μ I₉ − (2μ/floor) Σ w wᵀ: twists hugely negative, flips and
        // scalings 2μ, so the projection is 2μ times the projection onto symmetric matrices.
        let m = Corotated::new(Lame {
            mu: 1.5,
            lambda: 40.0,
        });
        let symmetric = Mat9::from_fn(|a, b| {
            let (r, c) = (a % 3, a / 3);
            let (k, l) = (b % 3, b / 3);
            let same = if (r, c) == (k, l) { 0.5 } else { 0.0 };
            let transposed = if (r, c) == (l, k) { 0.5 } else { 0.0 };
            same + transposed
        });
        let p = m.dpdf_projected(&Mat3::zeros());
        assert!((p - symmetric * 3.0).norm() < 1e-12, "{p}");
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
