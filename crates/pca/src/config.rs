//! The `[pca]` section of a scene: how the basis dimension k is chosen.
//!
//! At most one rule may be given; when none is, [`DEFAULT_EXPLAINED_ENERGY`] applies:
//!
//! ```toml
//! [pca]
//! max_vertex_error = 1e-3   # or: dimension = 40, or: explained_energy = 0.9999999
//! max_dimension = 300       # optional cap on k (default 300)
//! ```

use crate::PcaError;

/// The explained-energy fraction used when the `[pca]` section names no rule.
///
/// `1 − 10⁻⁷` of Σσ², i.e. a relative (mass-weighted) Frobenius reconstruction error of the
/// snapshots of at most `√(10⁻⁷) ≈ 0.03 %`. Energy is the one rule that needs no knowledge of
/// the data's units or size, which is why it is the default rather than a vertex-error tolerance.
/// The fraction is this high because the training error is far below what a held-out drag
/// meets, and the reduced trajectory drifts with what the basis lacks: on AutoDef's X (1,047
/// vertices, corotated, its minimal scene) 99.99 % kept 19 coefficients and PCA ended 38 % from
/// the full trajectory, 99.9999 % kept 50 and ended 7 %; on the armadillo 8 coefficients, 31 %,
/// against 21, 11 % (docs/results-suite.md). Once reduced springs pulled through the patch
/// compliance the basis lacks, more coefficients paid more: 99.99999 % took `neural-cubature`
/// on the suite's minimal scenes from 15.2 to 9.2 % (armadillo, k = 23 → 37), 11.7 to 5.3 %
/// (AutoDef's bar, 67 → 93), 2.5 to 0.6 % (X very low, 61 → 86), 6.7 to 4.1 % (the 27k-tet
/// beam, 26 → 42) and 19.3 to 15.3 % (the dinosaur, 68 → 109), and left X high at 3.6–3.8 %
/// (53 → 76), at 1.5–3× the cost of a step.
pub const DEFAULT_EXPLAINED_ENERGY: f64 = 0.999_999_9;

/// The default cap on the basis dimension (AutoDef's limit as well).
pub const DEFAULT_MAX_DIMENSION: usize = 300;

/// The `[pca]` section of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PcaConfig {
    /// Keep exactly this many columns.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dimension: Option<usize>,
    /// Keep the smallest k with Σ_{i<k} σ_i² ≥ `explained_energy` · Σ σ_i², a fraction in (0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub explained_energy: Option<f64>,
    /// Keep the smallest k whose largest per-vertex reconstruction distance over all snapshots is
    /// at most this (absolute, in the data's units, e.g. metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_vertex_error: Option<f64>,
    /// Upper bound on k for every rule.
    pub max_dimension: usize,
    /// The norm the k columns are chosen in, once the rule has chosen k: `mass` (the default,
    /// plain PCA: the best k-dimensional representation of the snapshots' displacements) or
    /// `step` (the k leading modes in the norm of the implicit step's operator at rest,
    /// K₀ + M/h², in which a Galerkin step is the orthogonal projection; see
    /// [`crate::PcaBasis::refit_in_norm`]). Measured: `step` takes the methods without cubature
    /// closer to the full trajectory (cantilever neural 1.00 → 0.81 %, catapult pca 3.53 →
    /// 3.44 %, AutoDef dinosaur pca 92 → 64 %), but the cubature rules fitted on its stiffer
    /// columns lose more than that on two of three scenes (catapult neural-cubature 4.22 →
    /// 5.98 %, pca-cubature 3.74 → 4.72 %; AutoDef X pca-cubature 7.0 → 12.1 %), so it is not
    /// the default. Left out of the serialised section at its default.
    #[serde(skip_serializing_if = "is_default")]
    pub norm: BasisNorm,
    /// Columns appended after the fit: the first positions of the body's linear implicit-Euler
    /// fall from rest under gravity, each M-orthogonalised against the basis before it and
    /// left out when less than 0.1 % of it is new (the pipeline computes them; they need the
    /// FEM model). `None` lets the pipeline choose: three, where the basis misses at least 1 %
    /// of the first position, else none; `Some(0)` appends none. At most
    /// [`MAX_GRAVITY_DIRECTIONS`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gravity_directions: Option<usize>,
    /// Surface patches whose static responses are offered to the basis after the fall's
    /// positions: the displacement under a unit load along each axis spread over a patch
    /// (the training family's patches, spread over the surface), appended in the patches'
    /// order where at least 3 % of one lies outside the basis, up to a tenth of the basis's
    /// columns, rounded up (the pipeline computes them; they need the FEM model). `None` lets
    /// the pipeline choose ([`DEFAULT_PATCH_RESPONSES`]); `Some(0)` appends none. At most
    /// [`MAX_PATCH_RESPONSES`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub patch_responses: Option<usize>,
}

/// The most `[pca] gravity_directions` a scene may ask for.
pub const MAX_GRAVITY_DIRECTIONS: usize = 8;

/// The patches whose responses are offered when `[pca] patch_responses` is not given.
pub const DEFAULT_PATCH_RESPONSES: usize = 48;

/// The most `[pca] patch_responses` a scene may ask for.
pub const MAX_PATCH_RESPONSES: usize = 256;

/// The norm a basis is chosen in (`[pca] norm`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BasisNorm {
    /// The mass-weighted displacement norm (PCA).
    #[default]
    Mass,
    /// The norm of the implicit step's operator at rest, K₀ + M/h².
    Step,
}

fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

impl Default for PcaConfig {
    fn default() -> Self {
        Self {
            dimension: None,
            explained_energy: None,
            max_vertex_error: None,
            max_dimension: DEFAULT_MAX_DIMENSION,
            norm: BasisNorm::default(),
            gravity_directions: None,
            patch_responses: None,
        }
    }
}

/// A resolved, validated dimension-selection rule.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DimensionRule {
    /// Exactly k columns.
    Count(usize),
    /// Smallest k with Σ_{i<k} σ_i² ≥ fraction · Σ σ_i².
    ExplainedEnergy(f64),
    /// Smallest k with max over vertices and snapshots of ‖u_v − (U Uᵀ M u)_v‖₂ ≤ tolerance.
    MaxVertexError(f64),
}

impl PcaConfig {
    /// Keep exactly `k` columns.
    pub fn by_dimension(k: usize) -> Self {
        Self {
            dimension: Some(k),
            ..Self::default()
        }
    }

    /// Keep the smallest k explaining `fraction` of Σσ².
    pub fn by_explained_energy(fraction: f64) -> Self {
        Self {
            explained_energy: Some(fraction),
            ..Self::default()
        }
    }

    /// Keep the smallest k whose maximum per-vertex reconstruction distance is ≤ `tolerance`.
    pub fn by_max_vertex_error(tolerance: f64) -> Self {
        Self {
            max_vertex_error: Some(tolerance),
            ..Self::default()
        }
    }

    /// Appends one error per invalid field to `errors` (fields named `pca.<field>`).
    pub fn check(&self, errors: &mut Vec<PcaError>) {
        let mut bad = |field: &str, reason: String| {
            errors.push(PcaError::InvalidConfig {
                field: format!("pca.{field}"),
                reason,
            })
        };
        let given: Vec<&str> = [
            ("dimension", self.dimension.is_some()),
            ("explained_energy", self.explained_energy.is_some()),
            ("max_vertex_error", self.max_vertex_error.is_some()),
        ]
        .into_iter()
        .filter_map(|(name, set)| set.then_some(name))
        .collect();
        if given.len() > 1 {
            bad(
                given[1],
                format!(
                    "give at most one of `dimension`, `explained_energy`, `max_vertex_error` (got {})",
                    given
                        .iter()
                        .map(|g| format!("`{g}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            );
        }
        if self.max_dimension == 0 {
            bad("max_dimension", "must be at least 1, got 0".into());
        }
        if let Some(k) = self.dimension {
            if k == 0 {
                bad("dimension", "must be at least 1, got 0".into());
            } else if k > self.max_dimension {
                bad(
                    "dimension",
                    format!("{k} exceeds `pca.max_dimension` = {}", self.max_dimension),
                );
            }
        }
        match self.explained_energy {
            Some(f) if !(f.is_finite() && f > 0.0 && f <= 1.0) => bad(
                "explained_energy",
                format!("must be a fraction in (0, 1], got {f}"),
            ),
            _ => {}
        }
        match self.max_vertex_error {
            Some(t) if !(t.is_finite() && t > 0.0) => bad(
                "max_vertex_error",
                format!("must be positive and finite, got {t}"),
            ),
            _ => {}
        }
        if let Some(m) = self.gravity_directions
            && m > MAX_GRAVITY_DIRECTIONS
        {
            bad(
                "gravity_directions",
                format!("must be at most {MAX_GRAVITY_DIRECTIONS}, got {m}"),
            );
        }
        if let Some(m) = self.patch_responses
            && m > MAX_PATCH_RESPONSES
        {
            bad(
                "patch_responses",
                format!("must be at most {MAX_PATCH_RESPONSES}, got {m}"),
            );
        }
    }

    /// `Ok` when every field is valid, otherwise the collected errors.
    pub fn validate(&self) -> Result<(), PcaError> {
        let mut errors = Vec::new();
        self.check(&mut errors);
        PcaError::collect(errors)
    }

    /// The validated rule this section describes ([`DEFAULT_EXPLAINED_ENERGY`] when none is given).
    pub fn rule(&self) -> Result<DimensionRule, PcaError> {
        self.validate()?;
        Ok(if let Some(k) = self.dimension {
            DimensionRule::Count(k)
        } else if let Some(f) = self.explained_energy {
            DimensionRule::ExplainedEnergy(f)
        } else if let Some(t) = self.max_vertex_error {
            DimensionRule::MaxVertexError(t)
        } else {
            DimensionRule::ExplainedEnergy(DEFAULT_EXPLAINED_ENERGY)
        })
    }
}
