//! Hyperelastic materials: energy density ψ(F), first Piola–Kirchhoff stress P = ∂ψ/∂F, its
//! derivative ∂P/∂F and a positive-semidefinite projection of it for Newton's method.
//!
//! Flattening convention: `vec(F)` is column-major (nalgebra's storage order), so entry
//! `r + 3c` of `vec(F)` is `F[(r, c)]`, and `dpdf[(r + 3c, k + 3l)] = ∂P_rc / ∂F_kl`.
//!
//! Parameters are given as Young's modulus E and Poisson ratio ν and converted to Lamé
//! parameters μ = E / (2(1+ν)), λ = Eν / ((1+ν)(1−2ν)).

mod cofactor_tangent;
mod corotated;
mod linear;
mod neo_hookean;
mod projection;
mod stable_neo_hookean;
mod stvk;

pub use corotated::Corotated;
pub(crate) use corotated::signed_svd;
pub use linear::LinearElastic;
pub use neo_hookean::NeoHookean;
pub use projection::project_psd;
pub use stable_neo_hookean::StableNeoHookean;
pub use stvk::StVenantKirchhoff;

use crate::{FemError, Mat3};

/// 9×9 matrix: derivative of a 3×3 stress with respect to a 3×3 deformation gradient.
pub type Mat9 = nalgebra::SMatrix<f64, 9, 9>;

/// Lamé parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lame {
    pub mu: f64,
    pub lambda: f64,
}

impl Lame {
    /// μ = E / (2(1+ν)), λ = Eν / ((1+ν)(1−2ν)).
    pub fn from_young_poisson(youngs_modulus: f64, poisson_ratio: f64) -> Self {
        let (e, nu) = (youngs_modulus, poisson_ratio);
        Self {
            mu: e / (2.0 * (1.0 + nu)),
            lambda: e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        }
    }
}

/// A hyperelastic energy density. Implementations are plain data (`Copy`) so that element loops
/// are monomorphised and inlined.
pub trait Material: Send + Sync + Copy + std::fmt::Debug {
    /// Human-readable name used in error messages.
    const NAME: &'static str;
    /// Whether ψ, P and ∂P/∂F are finite for inverted elements (det F ≤ 0).
    const INVERSION_SAFE: bool;

    /// Energy density ψ(F) per unit rest volume. `+∞` where the material is undefined.
    fn psi(&self, f: &Mat3) -> f64;
    /// First Piola–Kirchhoff stress P(F) = ∂ψ/∂F.
    fn pk1(&self, f: &Mat3) -> Mat3;
    /// ψ and P together; override when they share work.
    fn psi_pk1(&self, f: &Mat3) -> (f64, Mat3) {
        (self.psi(f), self.pk1(f))
    }
    /// ∂P/∂F in the column-major flattening described in the module docs.
    fn dpdf(&self, f: &Mat3) -> Mat9;
    /// A positive-semidefinite approximation of ∂P/∂F (negative eigenvalues clamped to zero).
    fn dpdf_projected(&self, f: &Mat3) -> Mat9 {
        project_psd(&self.dpdf(f))
    }
}

/// The material models a scene can name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MaterialModel {
    /// Small-strain linear elasticity (not rotation invariant).
    Linear,
    /// Fixed corotated elasticity (Stomakhin et al. 2012).
    Corotated,
    /// Saint Venant–Kirchhoff.
    Stvk,
    /// Classic compressible Neo-Hookean; undefined for inverted elements.
    NeoHookean,
    /// Stable Neo-Hookean (Smith et al. 2018); inversion safe.
    #[default]
    StableNeoHookean,
}

impl MaterialModel {
    /// Every model, in declaration order.
    pub const ALL: [MaterialModel; 5] = [
        MaterialModel::Linear,
        MaterialModel::Corotated,
        MaterialModel::Stvk,
        MaterialModel::NeoHookean,
        MaterialModel::StableNeoHookean,
    ];
}

/// The `[material]` section of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialConfig {
    #[serde(default)]
    pub model: MaterialModel,
    /// Young's modulus E in Pa.
    pub youngs_modulus: f64,
    /// Poisson ratio ν in [0, 0.5).
    pub poisson_ratio: f64,
    /// Density ρ in kg/m³; water's (1000) when not given.
    #[serde(default = "default_density")]
    pub density: f64,
    /// Lumped (default) or consistent mass matrix.
    #[serde(default)]
    pub mass: crate::mass::MassKind,
}

fn default_density() -> f64 {
    1000.0
}

impl Default for MaterialConfig {
    fn default() -> Self {
        Self {
            model: MaterialModel::default(),
            youngs_modulus: 1.0e5,
            poisson_ratio: 0.45,
            density: default_density(),
            mass: crate::mass::MassKind::Lumped,
        }
    }
}

impl MaterialConfig {
    /// Appends one error per invalid field to `errors`.
    pub fn check(&self, errors: &mut Vec<FemError>) {
        let mut bad = |field: &str, reason: String| {
            errors.push(FemError::InvalidConfig {
                field: format!("material.{field}"),
                reason,
            })
        };
        if !(self.youngs_modulus.is_finite() && self.youngs_modulus > 0.0) {
            bad(
                "youngs_modulus",
                format!("must be positive and finite, got {}", self.youngs_modulus),
            );
        }
        if !(self.poisson_ratio.is_finite() && (0.0..0.5).contains(&self.poisson_ratio)) {
            bad(
                "poisson_ratio",
                format!("must be in [0, 0.5), got {}", self.poisson_ratio),
            );
        }
        if !(self.density.is_finite() && self.density > 0.0) {
            bad(
                "density",
                format!("must be positive and finite, got {}", self.density),
            );
        }
    }

    /// `Ok` when every field is valid, otherwise the collected errors.
    pub fn validate(&self) -> Result<(), FemError> {
        let mut errors = Vec::new();
        self.check(&mut errors);
        FemError::collect(errors)
    }

    pub fn lame(&self) -> Lame {
        Lame::from_young_poisson(self.youngs_modulus, self.poisson_ratio)
    }

    /// The material this configuration describes.
    pub fn build(&self) -> AnyMaterial {
        let lame = self.lame();
        match self.model {
            MaterialModel::Linear => AnyMaterial::Linear(LinearElastic::new(lame)),
            MaterialModel::Corotated => AnyMaterial::Corotated(Corotated::new(lame)),
            MaterialModel::Stvk => AnyMaterial::Stvk(StVenantKirchhoff::new(lame)),
            MaterialModel::NeoHookean => AnyMaterial::NeoHookean(NeoHookean::new(lame)),
            MaterialModel::StableNeoHookean => {
                AnyMaterial::StableNeoHookean(StableNeoHookean::new(lame))
            }
        }
    }
}

/// One of the concrete materials; dispatch once per assembly with `with_material!`.
#[derive(Debug, Clone, Copy)]
pub enum AnyMaterial {
    Linear(LinearElastic),
    Corotated(Corotated),
    Stvk(StVenantKirchhoff),
    NeoHookean(NeoHookean),
    StableNeoHookean(StableNeoHookean),
}

/// Runs `$body` with `$m` bound to the concrete material inside an [`AnyMaterial`], so that the
/// body is monomorphised per material (no dynamic dispatch inside element loops).
#[macro_export]
macro_rules! with_material {
    ($any:expr, |$m:ident| $body:expr) => {
        match $any {
            $crate::material::AnyMaterial::Linear($m) => $body,
            $crate::material::AnyMaterial::Corotated($m) => $body,
            $crate::material::AnyMaterial::Stvk($m) => $body,
            $crate::material::AnyMaterial::NeoHookean($m) => $body,
            $crate::material::AnyMaterial::StableNeoHookean($m) => $body,
        }
    };
}

impl AnyMaterial {
    /// Linear elasticity: its energy is quadratic in the displacement, so it neither turns with
    /// the body nor buckles.
    pub fn is_linear(&self) -> bool {
        matches!(self, AnyMaterial::Linear(_))
    }

    pub fn name(&self) -> &'static str {
        fn name_of<M: Material>(_: &M) -> &'static str {
            M::NAME
        }
        with_material!(self, |m| name_of(m))
    }
}
