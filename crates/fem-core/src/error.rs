//! Typed errors of the crate. Every message says what went wrong and where.

use std::path::PathBuf;

/// Errors raised while reading, validating or writing a mesh.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file content does not follow its format.
    #[error("{path}:{line}: {reason}")]
    Parse {
        path: PathBuf,
        /// 1-based line number (0 when the format is binary or the line is unknown).
        line: usize,
        reason: String,
    },
    /// The mesh was read but is not a usable tetrahedral mesh.
    #[error("{path}: invalid mesh: {reason}")]
    Invalid { path: PathBuf, reason: String },
    /// The file extension does not name a supported format; `hint` says what to do instead.
    #[error("{path}: unsupported mesh format: {hint}")]
    UnsupportedFormat { path: PathBuf, hint: String },
}

/// Errors of the physics and solvers.
#[derive(Debug, thiserror::Error)]
pub enum FemError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// A configuration value is out of its valid range.
    #[error("invalid value for `{field}`: {reason}")]
    InvalidConfig { field: String, reason: String },
    /// An element is inverted (det F ≤ 0) where the material cannot handle it.
    #[error(
        "element {element} is inverted (det F = {det:.3e}); the {material} material is undefined there"
    )]
    InvertedElement {
        element: usize,
        det: f64,
        material: &'static str,
    },
    /// A non-finite value appeared during a solve.
    #[error("non-finite value in {what} at step {step}")]
    NonFinite { what: &'static str, step: usize },
    /// The solver did not reach its tolerance.
    #[error(
        "{solver} did not converge at step {step}: relative gradient {residual:.3e} after {iterations} iterations (tolerance {tolerance:.1e})"
    )]
    NotConverged {
        solver: &'static str,
        step: usize,
        iterations: usize,
        residual: f64,
        tolerance: f64,
    },
    /// The line search found no decrease along a descent direction.
    #[error("{solver}: line search failed at step {step}, iteration {iteration}")]
    LineSearchFailed {
        solver: &'static str,
        step: usize,
        iteration: usize,
    },
    /// The sparse factorisation failed (the system is not positive definite).
    #[error("sparse Cholesky factorisation failed: {0}")]
    Factorization(String),
    /// A generated training or test schedule failed to simulate.
    #[error("schedule {index}: {source}")]
    Schedule {
        index: usize,
        #[source]
        source: Box<FemError>,
    },
    /// Several configuration errors, reported together.
    #[error("{}", .0.iter().map(|e| format!("  - {e}")).collect::<Vec<_>>().join("\n"))]
    Many(Vec<FemError>),
    /// Writing output failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl FemError {
    /// `Ok(())` for no errors, the single error for one, [`FemError::Many`] for several.
    pub fn collect(mut errors: Vec<FemError>) -> Result<(), FemError> {
        match errors.len() {
            0 => Ok(()),
            1 => Err(errors.remove(0)),
            _ => Err(FemError::Many(errors)),
        }
    }

    /// Whether this is a failure of a step's solve itself (not converged, no descent, a
    /// non-finite value, an inverted element), after which the frames a trajectory reached
    /// before are still good.
    pub fn is_solve_failure(&self) -> bool {
        matches!(
            self,
            FemError::NotConverged { .. }
                | FemError::LineSearchFailed { .. }
                | FemError::NonFinite { .. }
                | FemError::InvertedElement { .. }
        )
    }
}

/// `x` to four significant digits, for messages (0.01704 and 1.704e-5, not 0.017043437257239995).
pub fn four_digits(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor();
    if (-4.0..6.0).contains(&magnitude) {
        let decimals = (3.0 - magnitude).max(0.0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.3e}")
    }
}
