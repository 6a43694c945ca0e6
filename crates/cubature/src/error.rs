//! Typed errors of the crate. Every message says what went wrong and where.

/// Errors of configuration checks, training-matrix construction, NNLS and greedy fitting.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CubatureError {
    /// A `[cubature]` configuration value is invalid; `field` is the dotted scene path
    /// (`cubature.tolerance`).
    #[error("invalid value for `{field}`: {reason}")]
    InvalidConfig { field: String, reason: String },
    /// Several configuration errors, reported together.
    #[error("{}", .0.iter().map(|e| format!("  - {e}")).collect::<Vec<_>>().join("\n"))]
    Many(Vec<CubatureError>),
    /// No training poses were given.
    #[error("no training poses were given")]
    NoPoses,
    /// The model has no elements to choose from.
    #[error("the model has no elements")]
    NoElements,
    /// A matrix or vector argument has the wrong shape.
    #[error("{what} has shape {found:?}, expected {expected:?}")]
    ShapeMismatch {
        what: &'static str,
        expected: (usize, usize),
        found: (usize, usize),
    },
    /// An input entry is NaN or infinite.
    #[error("{what} entry {index} is not finite: {value}")]
    NonFiniteInput {
        what: &'static str,
        index: usize,
        value: f64,
    },
    /// An element's reduced force is NaN or infinite at a pose (e.g. an element inverted under a
    /// material that is undefined there).
    #[error("the reduced force of element {element} is not finite at pose {pose}")]
    NonFiniteForce { element: usize, pose: usize },
    /// Every pose has a zero target force, so there is nothing to fit (e.g. only the rest pose).
    #[error("every training pose has a zero reduced force (all {poses} poses are at rest?)")]
    ZeroTarget { poses: usize },
    /// Not even [`crate::training::MIN_POSES`] poses' training matrix fits the memory budget.
    #[error(
        "the cubature training data needs {needed_mb} MiB for the fewest poses a fit uses \
         ({poses} poses × {dim} reduced coordinates × {elements} candidate elements), above \
         `cubature.memory_limit_mb` = {limit_mb}; set `cubature.memory_limit_mb` to at least \
         {needed_mb} ({all_mb} keeps all {all_poses} poses, which a rule fitted on fewer misses \
         the forces of more often; a smaller `cubature.max_elements` also takes fewer \
         candidates, 8 for each element of the rule)"
    )]
    MemoryLimit {
        needed_mb: u64,
        /// MiB that keep every pose the fit asks for, with these candidates.
        all_mb: u64,
        /// The poses the fit asks for (`cubature.max_poses` or fewer given).
        all_poses: usize,
        limit_mb: u64,
        poses: usize,
        dim: usize,
        elements: usize,
    },
    /// The NNLS active-set iteration hit its iteration limit.
    #[error("non-negative least squares did not converge in {iterations} iterations")]
    NnlsNoConvergence { iterations: usize },
    /// A stored cubature rule (e.g. a deserialized artifact) is inconsistent.
    #[error("invalid cubature rule: {0}")]
    InvalidRule(String),
}

impl CubatureError {
    /// `Ok(())` for no errors, the single error for one, [`CubatureError::Many`] for several.
    pub fn collect(mut errors: Vec<CubatureError>) -> Result<(), CubatureError> {
        match errors.len() {
            0 => Ok(()),
            1 => Err(errors.remove(0)),
            _ => Err(CubatureError::Many(errors)),
        }
    }
}
