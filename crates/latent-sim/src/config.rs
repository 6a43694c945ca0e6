//! The `[reduced]` section of a scene: how the reduced methods solve each step.

use fem_core::FemError;
use fem_core::optim::{SolverConfig, SolverMethod};

use crate::Preconditioning;

/// Smallest iteration cap of the reduced methods' L-BFGS (AutoDef used 500). A step that needs
/// more is redone with reduced Newton: on the catapult, where large rotations make the rest-state
/// preconditioner poor, capping at 100 instead of 500 halved pca-cubature's median step (629 →
/// 290 ms under load) without changing any step that converges normally (5–17 iterations on the
/// cantilever).
pub const REDUCED_MIN_ITERATIONS: usize = 100;

/// The most gravity-onset directions a scene may ask for.
pub const MAX_ONSET_DIRECTIONS: usize = 32;

/// The most complement directions a scene may ask for (the PCA dimension bounds it too).
pub const MAX_COMPLEMENT_DIRECTIONS: usize = 256;

/// The `[reduced]` section: how the reduced methods solve each step. `[solver]` is the full-space
/// solver's (the reference's); the reduced iteration cap is `[solver] max_iterations`, at least
/// [`REDUCED_MIN_ITERATIONS`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReducedSolverConfig {
    /// `lbfgs` (preconditioned L-BFGS, the paper's solver) or `newton` (Gauss–Newton in z).
    pub method: SolverMethod,
    /// Relative gradient tolerance of each step's solve. A reduced trajectory is already a few
    /// tenths of a percent to a few percent away from the full one, so solving each step to 1e-3
    /// changes it far less than that: on the six meshes of the suite (the corotated dinosaur,
    /// whose test amplifies errors fivefold, included) every `pca-cubature` and
    /// `neural-cubature` error stayed the same to 0.01 points against 1e-4, with 10–30 % fewer
    /// iterations (docs/results-suite.md).
    pub tolerance: f64,
    /// L-BFGS's preconditioner: `current-state` (the Gauss–Newton matrix at the step's start,
    /// kept for a few steps), `rest` (the stiffness at rest, AutoDef's) or `auto` (the first).
    pub preconditioner: Preconditioning,
    /// Linear gravity-onset directions beside the autoencoder's latent coordinates
    /// ([`crate::Augmented`]): the first m steps of the reduced linear response to gravity
    /// from rest, minus what the decoder spans at rest; the neural methods' dimension grows by
    /// the directions kept. `None` (the default) lets the pipeline choose
    /// ([`DEFAULT_ONSET_DIRECTIONS`] under gravity, none without).
    pub onset_directions: Option<usize>,
    /// Linear directions beside the autoencoder's latent coordinates after the onset ones: the
    /// leading left singular vectors of what the autoencoder misses in the snapshots, q −
    /// decode(encode(q)) (stage `complement`), minus what the decoder spans at rest. Each costs
    /// a latent coordinate in every step and brings the neural methods closer to the whole PCA
    /// basis's accuracy, without retraining. `None` (the default) lets the pipeline choose
    /// from the data: as many as bring the autoencoder's loss on the snapshots within the PCA
    /// basis's own; `Some(0)` adds none.
    pub complement_directions: Option<usize>,
    /// Whether a spring pulls the reduced body through the patch compliance the PCA basis
    /// lacks, put in series with it ([`crate::ReducedSimulator::set_spring_compliance`]). A
    /// subspace cannot dent the patch a spring holds, so without it the spring pulls the
    /// reduced body harder than the full one (10–15 % on AutoDef's X mesh). Costs one
    /// factorisation of the full step's operator at rest when the first spring is added.
    pub spring_compliance: bool,
}

/// Gravity-onset directions when a scene with gravity names none: the first two steps of a
/// release are then exact in the linear regime, where a small latent space is furthest from
/// the full response (on the catapult they took `neural-cubature` from 5.6 to 5.0 % and its
/// worst frame from 23.5 to 6.6 %; on AutoDef's X mesh from 17.6 to 13.8 %).
pub const DEFAULT_ONSET_DIRECTIONS: usize = 2;

impl Default for ReducedSolverConfig {
    fn default() -> Self {
        Self {
            method: SolverMethod::Lbfgs,
            tolerance: 1e-3,
            preconditioner: Preconditioning::default(),
            onset_directions: None,
            complement_directions: None,
            spring_compliance: true,
        }
    }
}

impl ReducedSolverConfig {
    /// Appends one error per invalid field to `errors`.
    pub fn check(&self, errors: &mut Vec<FemError>) {
        let t = self.tolerance;
        if !(t.is_finite() && t > 0.0 && t < 1.0) {
            errors.push(FemError::InvalidConfig {
                field: "reduced.tolerance".into(),
                reason: format!("must be in (0, 1), got {t}"),
            });
        }
        for (field, count, max) in [
            (
                "onset_directions",
                self.onset_directions,
                MAX_ONSET_DIRECTIONS,
            ),
            (
                "complement_directions",
                self.complement_directions,
                MAX_COMPLEMENT_DIRECTIONS,
            ),
        ] {
            if let Some(count) = count
                && count > max
            {
                errors.push(FemError::InvalidConfig {
                    field: format!("reduced.{field}"),
                    reason: format!(
                        "at most {max} (each costs a latent coordinate in every step), got {count}"
                    ),
                });
            }
        }
    }

    /// The settings of each reduced step's solve: `full` (the scene's `[solver]`) with this
    /// section's method and tolerance, and at least [`REDUCED_MIN_ITERATIONS`] iterations
    /// (quasi-Newton needs more, cheaper iterations than Newton).
    pub fn solver(&self, full: &SolverConfig) -> SolverConfig {
        let mut solver = full.clone();
        solver.method = self.method;
        solver.tolerance = self.tolerance;
        solver.max_iterations = solver.max_iterations.max(REDUCED_MIN_ITERATIONS);
        solver
    }
}
