//! The nonlinear materials against closed forms at large strain, written here from the textbook
//! energies (Bonet & Wood for Neo-Hookean and St. Venant–Kirchhoff, Stomakhin et al. 2012 for
//! fixed corotated, Smith et al. 2018 for stable Neo-Hookean) rather than from the code: uniaxial
//! stretch with and without lateral stretch, F = diag(a, b, b), and simple shear,
//! F = I + γ e₁⊗e₂, up to a = 2 and γ = 1.
//!
//! The materials are built the way a scene builds them (`MaterialConfig::build` from E and ν), so
//! the Lamé conversion and stable Neo-Hookean's reparametrisation (μ' = μ, λ' = λ + μ, chosen so
//! that its small-strain limit is linear elasticity's) are part of what is checked.
//!
//! For an isotropic ψ and a diagonal F = diag(s), P is diagonal with P_ii = ∂ψ/∂s_i, so each
//! material's uniaxial reference is its energy as a function of the principal stretches and the
//! derivatives of that function, taken by hand. Simple shear keeps J = 1 and couples F₀₁, so its
//! references are the tensor formulas evaluated entry by entry; for corotated ψ comes from F's
//! singular values (√(4 + γ²) ± γ)/2 and P = 2μ(F − R) from the closed-form polar rotation
//! R = [[2, γ], [−γ, 2]] / √(4 + γ²): two routes that must agree with the code and each other.

#![allow(non_snake_case)]

use fem_core::Mat3;
use fem_core::mass::MassKind;
use fem_core::material::{Material, MaterialConfig, MaterialModel};
use fem_core::with_material;
use nalgebra::{Rotation3, Vector3};

/// A stiff, nearly incompressible rubber: the catapult's and the cantilever's E and ν.
const E: f64 = 1.0e5;
const NU: f64 = 0.45;

/// Lamé μ and λ from E and ν (the textbook conversion).
fn lame() -> (f64, f64) {
    let mu = E / (2.0 * (1.0 + NU));
    let la = E * NU / ((1.0 + NU) * (1.0 - 2.0 * NU));
    (mu, la)
}

/// ψ(F) and P(F) of `model` built as a scene builds it.
fn evaluate(model: MaterialModel, F: &Mat3) -> (f64, Mat3) {
    let config = MaterialConfig {
        model,
        youngs_modulus: E,
        poisson_ratio: NU,
        density: 1000.0,
        mass: MassKind::Lumped,
    };
    with_material!(&config.build(), |m| (m.psi(F), m.pk1(F)))
}

/// The energy of one material as a function of the principal stretches s and its gradient
/// (∂ψ/∂s₀, ∂ψ/∂s₁, ∂ψ/∂s₂).
type Principal = fn([f64; 3]) -> (f64, [f64; 3]);

/// Stable Neo-Hookean (Smith et al. 2018, without the log barrier):
/// ψ = μ'/2 (I₁ − 3) + λ'/2 (J − α)² − λ'/2 (1 − α)² with α = 1 + μ'/λ', μ' = μ, λ' = λ + μ.
fn stable_neo_hookean(s: [f64; 3]) -> (f64, [f64; 3]) {
    let (mu, la) = lame();
    let (mu_, la_) = (mu, la + mu);
    let alpha = 1.0 + mu_ / la_;
    let J = s[0] * s[1] * s[2];
    let I1: f64 = s.iter().map(|x| x * x).sum();
    let psi = 0.5 * mu_ * (I1 - 3.0) + 0.5 * la_ * (J - alpha).powi(2)
        - 0.5 * la_ * (1.0 - alpha).powi(2);
    (psi, s.map(|si| mu_ * si + la_ * (J - alpha) * J / si))
}

/// Fixed corotated (Stomakhin et al. 2012): ψ = μ Σ (s_i − 1)² + λ/2 (J − 1)².
fn corotated(s: [f64; 3]) -> (f64, [f64; 3]) {
    let (mu, la) = lame();
    let J = s[0] * s[1] * s[2];
    let psi =
        mu * s.iter().map(|si| (si - 1.0).powi(2)).sum::<f64>() + 0.5 * la * (J - 1.0).powi(2);
    (
        psi,
        s.map(|si| 2.0 * mu * (si - 1.0) + la * (J - 1.0) * J / si),
    )
}

/// St. Venant–Kirchhoff: principal Green strains e_i = (s_i² − 1)/2,
/// ψ = μ Σ e_i² + λ/2 (Σ e_i)², ∂ψ/∂s_i = (2μ e_i + λ Σ e) s_i.
fn stvk(s: [f64; 3]) -> (f64, [f64; 3]) {
    let (mu, la) = lame();
    let e = s.map(|si| 0.5 * (si * si - 1.0));
    let tr: f64 = e.iter().sum();
    let psi = mu * e.iter().map(|ei| ei * ei).sum::<f64>() + 0.5 * la * tr * tr;
    let mut d = [0.0; 3];
    for i in 0..3 {
        d[i] = (2.0 * mu * e[i] + la * tr) * s[i];
    }
    (psi, d)
}

/// Compressible Neo-Hookean (Bonet & Wood §6.4.3): ψ = μ/2 (I₁ − 3) − μ ln J + λ/2 (ln J)².
fn neo_hookean(s: [f64; 3]) -> (f64, [f64; 3]) {
    let (mu, la) = lame();
    let lnJ = (s[0] * s[1] * s[2]).ln();
    let I1: f64 = s.iter().map(|x| x * x).sum();
    let psi = 0.5 * mu * (I1 - 3.0) - mu * lnJ + 0.5 * la * lnJ * lnJ;
    (psi, s.map(|si| mu * si - mu / si + la * lnJ / si))
}

const MATERIALS: [(MaterialModel, Principal); 4] = [
    (MaterialModel::StableNeoHookean, stable_neo_hookean),
    (MaterialModel::Corotated, corotated),
    (MaterialModel::Stvk, stvk),
    (MaterialModel::NeoHookean, neo_hookean),
];

/// Relative agreement asked of ψ and P: round-off of the code's own evaluation (the SVD of
/// corotated included) is far below it, a wrong term at these strains far above.
const TOLERANCE: f64 = 1e-12;

/// Asserts ψ and P against the references, relative to their size or, near zero, to μ (the
/// stress scale).
fn assert_close(what: &str, (psi, P): (f64, Mat3), (psi_ref, P_ref): (f64, Mat3)) {
    let (mu, _) = lame();
    let e = (psi - psi_ref).abs() / psi_ref.abs().max(mu);
    assert!(
        e <= TOLERANCE,
        "{what}: ψ = {psi:e}, reference {psi_ref:e} (rel. {e:e})"
    );
    let e = (P - P_ref).norm() / P_ref.norm().max(mu);
    assert!(
        e <= TOLERANCE,
        "{what}: P = {P}, reference {P_ref} (rel. {e:e})"
    );
}

/// Stretches (a, b): F = diag(a, b, b). Pure uniaxial stretch to 2 and compression to 0.6,
/// then with the lateral contraction or expansion that loads volume and shear together.
const STRETCHES: [(f64, f64); 6] = [
    (2.0, 1.0),
    (1.5, 1.0),
    (0.6, 1.0),
    (2.0, 0.75),
    (1.3, 1.2),
    (0.7, 1.1),
];

#[test]
fn uniaxial_and_lateral_stretch_match_the_principal_stretch_energies() {
    for (model, principal) in MATERIALS {
        for (a, b) in STRETCHES {
            let s = [a, b, b];
            let (psi, d) = principal(s);
            let F = Mat3::from_diagonal(&Vector3::from(s));
            let P_ref = Mat3::from_diagonal(&Vector3::from(d));
            let what = format!("{model:?}, F = diag({a}, {b}, {b})");
            assert_close(&what, evaluate(model, &F), (psi, P_ref));
        }
    }
}

/// The same stretches along axes that are not the coordinate axes: F = Q diag(s) Qᵀ gives
/// ψ unchanged and P = Q diag(∂ψ/∂s) Qᵀ, through the code's general (non-diagonal) paths.
#[test]
fn stretch_along_rotated_axes_matches_the_principal_stretch_energies() {
    let axis = nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0));
    let Q = *Rotation3::from_axis_angle(&axis, 0.7).matrix();
    for (model, principal) in MATERIALS {
        for (a, b) in STRETCHES {
            let s = [a, b, b];
            let (psi, d) = principal(s);
            let F = Q * Mat3::from_diagonal(&Vector3::from(s)) * Q.transpose();
            let P_ref = Q * Mat3::from_diagonal(&Vector3::from(d)) * Q.transpose();
            let what = format!("{model:?}, F = Q diag({a}, {b}, {b}) Qᵀ");
            assert_close(&what, evaluate(model, &F), (psi, P_ref));
        }
    }
}

/// ψ and P under simple shear F = I + γ e₁⊗e₂ (J = 1), entry by entry.
fn shear_reference(model: MaterialModel, g: f64) -> (f64, Mat3) {
    let (mu, la) = lame();
    match model {
        // P = μF + (λ(J − 1) − μ) cof F with J = 1 and cof F = F⁻ᵀ = I − γ e₂⊗e₁ for the
        // classic form; stable Neo-Hookean's λ'(J − α) = −μ' at J = 1 gives the same with
        // μ' = μ. Either way ψ = μγ²/2 and P = μγ (e₁⊗e₂ + e₂⊗e₁).
        MaterialModel::StableNeoHookean | MaterialModel::NeoHookean => (
            0.5 * mu * g * g,
            Mat3::new(0.0, mu * g, 0.0, mu * g, 0.0, 0.0, 0.0, 0.0, 0.0),
        ),
        // E = ½ [[0, γ, 0], [γ, γ², 0], [0, 0, 0]], tr E = γ²/2, S = 2μE + λ tr(E) I, P = FS.
        MaterialModel::Stvk => {
            let psi = 0.5 * mu * g * g + 0.25 * mu * g.powi(4) + 0.125 * la * g.powi(4);
            let P = Mat3::new(
                0.5 * la * g * g + mu * g * g,
                mu * g + mu * g.powi(3) + 0.5 * la * g.powi(3),
                0.0,
                mu * g,
                mu * g * g + 0.5 * la * g * g,
                0.0,
                0.0,
                0.0,
                0.5 * la * g * g,
            );
            (psi, P)
        }
        // Singular values σ± = (r ± γ)/2 with r = √(4 + γ²) and 1; the polar rotation of
        // F = RS is R = [[2, γ], [−γ, 2]] / r in the (e₁, e₂) plane.
        MaterialModel::Corotated => {
            let r = (4.0 + g * g).sqrt();
            let (sp, sm) = ((r + g) / 2.0, (r - g) / 2.0);
            let psi = mu * ((sp - 1.0).powi(2) + (sm - 1.0).powi(2));
            let F = Mat3::new(1.0, g, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
            let R = Mat3::new(2.0 / r, g / r, 0.0, -g / r, 2.0 / r, 0.0, 0.0, 0.0, 1.0);
            (psi, (F - R) * (2.0 * mu))
        }
        MaterialModel::Linear => unreachable!("not a large-strain material"),
    }
}

#[test]
fn simple_shear_matches_the_closed_forms() {
    for (model, _) in MATERIALS {
        for g in [0.25, 0.5, 1.0] {
            let F = Mat3::new(1.0, g, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
            let what = format!("{model:?}, simple shear γ = {g}");
            assert_close(&what, evaluate(model, &F), shear_reference(model, g));
        }
    }
}

/// The corotated shear reference's two routes agree with each other: ψ from the singular
/// values is μ‖F − R‖² with the closed-form R, and dψ/dγ is P₀₁ (only F₀₁ moves with γ); the
/// same derivative check for the others, by central differences of the reference energies.
#[test]
fn shear_references_are_consistent_with_themselves() {
    let (mu, _) = lame();
    for (model, _) in MATERIALS {
        for g in [0.25, 0.5, 1.0] {
            let (psi, P) = shear_reference(model, g);
            let h = 1e-6;
            let dpsi =
                (shear_reference(model, g + h).0 - shear_reference(model, g - h).0) / (2.0 * h);
            assert!(
                (dpsi - P[(0, 1)]).abs() <= 1e-7 * mu,
                "{model:?}, γ = {g}: dψ/dγ = {dpsi}, P₀₁ = {}",
                P[(0, 1)]
            );
            if model == MaterialModel::Corotated {
                let r = (4.0 + g * g).sqrt();
                let F = Mat3::new(1.0, g, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
                let R = Mat3::new(2.0 / r, g / r, 0.0, -g / r, 2.0 / r, 0.0, 0.0, 0.0, 1.0);
                assert!((R.transpose() * R - Mat3::identity()).norm() <= 1e-15);
                let S = R.transpose() * F;
                assert!((S - S.transpose()).norm() <= 1e-15, "RᵀF is symmetric");
                let e = (mu * (F - R).norm_squared() - psi).abs();
                assert!(
                    e <= 1e-12 * mu,
                    "{g}: μ‖F − R‖² against the singular values"
                );
            }
        }
    }
}

/// The hand-taken derivatives of the principal-stretch energies against central differences of
/// those energies, and each energy at rest zero with zero gradient.
#[test]
fn principal_stretch_references_are_consistent_with_themselves() {
    let (mu, _) = lame();
    for (model, principal) in MATERIALS {
        let (psi0, d0) = principal([1.0; 3]);
        assert!(psi0.abs() <= 1e-12 * mu && d0.iter().all(|d| d.abs() <= 1e-9 * mu));
        for (a, b) in STRETCHES {
            let s = [a, b, b];
            let (_, d) = principal(s);
            for i in 0..3 {
                let h = 1e-6;
                let (mut sp, mut sm) = (s, s);
                sp[i] += h;
                sm[i] -= h;
                let fd = (principal(sp).0 - principal(sm).0) / (2.0 * h);
                assert!(
                    (fd - d[i]).abs() <= 1e-6 * d[i].abs().max(mu),
                    "{model:?}, s = {s:?}, ∂ψ/∂s_{i}: {} against {fd}",
                    d[i]
                );
            }
        }
    }
}
