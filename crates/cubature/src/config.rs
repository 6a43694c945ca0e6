//! The `[cubature]` section of a scene: when the greedy selection stops, how many candidates it
//! scores and how much training data it may hold.
//!
//! ```toml
//! [cubature]
//! tolerance = 0.02        # relative force error ‖A_S w − b‖ / ‖b‖ to reach
//! neural_tolerance = 0.005 # optional: the neural subspace's rule to this instead
//! max_elements = 500      # element budget |S|
//! candidates = 200        # random unselected elements scored per greedy step
//! max_poses = 150         # training poses kept (seeded subsample when more are given)
//! seed = 0
//! memory_limit_mb = 2048  # refuse training matrices larger than this
//! ```

use crate::CubatureError;

/// Default relative force error (see [`CubatureConfig::tolerance`]).
pub const DEFAULT_TOLERANCE: f64 = 0.02;
/// Default element budget.
pub const DEFAULT_MAX_ELEMENTS: usize = 500;
/// Default number of candidates scored per greedy step (An et al. and AutoDef use 200).
pub const DEFAULT_CANDIDATES: usize = 200;
/// Default number of training poses kept.
pub const DEFAULT_MAX_POSES: usize = 150;
/// Default memory budget of the training matrix, in MiB.
pub const DEFAULT_MEMORY_LIMIT_MB: u64 = 2048;

/// The `[cubature]` section of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CubatureConfig {
    /// Stop once the relative error ‖A_S w − b‖ / ‖b‖ over the (per-pose normalised) training
    /// forces is at most this, a fraction in (0, 1).
    ///
    /// AutoDef used 0.01–0.05; 0.02 is the middle of that range: at 0.05 the reduced forces are
    /// visibly off in large deformations, below 0.01 the element count (and so the run-time cost)
    /// grows quickly for little gain in trajectory accuracy.
    pub tolerance: f64,
    /// With a value, the rule of the neural subspace is fitted to this tolerance instead of
    /// `tolerance`, which then sets the linear subspace's only. The neural rule is smaller for
    /// the same tolerance (its forces have the latent dimension, not the PCA one), so a scene
    /// can buy accuracy there without the PCA rule growing to its element budget.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub neural_tolerance: Option<f64>,
    /// Stop once this many elements are selected (AutoDef: 400–1000). Capped by the mesh size.
    pub max_elements: usize,
    /// Number of random unselected elements scored against the residual per greedy step.
    pub candidates: usize,
    /// Keep at most this many training poses, chosen by a seeded subsample when more are given
    /// (held-out poses too, [`crate::HeldOutForces`]).
    /// Each kept pose costs `d · elements` doubles of training matrix (`d · candidates` on a
    /// mesh whose matrix keeps a subsample of the elements to fit `memory_limit_mb`).
    pub max_poses: usize,
    /// Seed of the pose subsample and of the candidate draws.
    pub seed: u64,
    /// Refuse to build a training matrix (plus its pose displacements) larger than this, in MiB.
    pub memory_limit_mb: u64,
}

impl Default for CubatureConfig {
    fn default() -> Self {
        Self {
            tolerance: DEFAULT_TOLERANCE,
            neural_tolerance: None,
            max_elements: DEFAULT_MAX_ELEMENTS,
            candidates: DEFAULT_CANDIDATES,
            max_poses: DEFAULT_MAX_POSES,
            seed: 0,
            memory_limit_mb: DEFAULT_MEMORY_LIMIT_MB,
        }
    }
}

impl CubatureConfig {
    /// Appends one error per invalid field to `errors` (fields named `cubature.<field>`).
    pub fn check(&self, errors: &mut Vec<CubatureError>) {
        let mut bad = |field: &str, reason: String| {
            errors.push(CubatureError::InvalidConfig {
                field: format!("cubature.{field}"),
                reason,
            })
        };
        let tolerances = [
            ("tolerance", Some(self.tolerance)),
            ("neural_tolerance", self.neural_tolerance),
        ];
        for (field, value) in tolerances {
            if let Some(t) = value.filter(|t| !(t.is_finite() && *t > 0.0 && *t < 1.0)) {
                bad(
                    field,
                    format!("must be a relative error in (0, 1), got {t}"),
                );
            }
        }
        for (field, value) in [
            ("max_elements", self.max_elements),
            ("candidates", self.candidates),
            ("max_poses", self.max_poses),
        ] {
            if value == 0 {
                bad(field, "must be at least 1, got 0".into());
            }
        }
        if self.memory_limit_mb == 0 {
            bad("memory_limit_mb", "must be at least 1, got 0".into());
        }
    }

    /// The settings of the neural subspace's rule: `neural_tolerance`, when given, in place of
    /// `tolerance`.
    pub fn for_neural(&self) -> Self {
        Self {
            tolerance: self.neural_tolerance.unwrap_or(self.tolerance),
            neural_tolerance: None,
            ..self.clone()
        }
    }

    /// The settings the linear subspace's rule depends on (`neural_tolerance` left out).
    pub fn for_linear(&self) -> Self {
        Self {
            neural_tolerance: None,
            ..self.clone()
        }
    }

    /// `Ok` when every field is valid, otherwise the collected errors.
    pub fn validate(&self) -> Result<(), CubatureError> {
        let mut errors = Vec::new();
        self.check(&mut errors);
        CubatureError::collect(errors)
    }
}
