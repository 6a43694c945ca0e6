//! Typed errors of the crate. Every message says what went wrong and where.

/// Errors of configuration checks, fitting and basis handling.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PcaError {
    /// A `[pca]` configuration value is invalid; `field` is the dotted scene path (`pca.dimension`).
    #[error("invalid value for `{field}`: {reason}")]
    InvalidConfig { field: String, reason: String },
    /// Several configuration errors, reported together.
    #[error("{}", .0.iter().map(|e| format!("  - {e}")).collect::<Vec<_>>().join("\n"))]
    Many(Vec<PcaError>),
    /// The snapshot matrix has no rows or no columns.
    #[error("the snapshot matrix is empty ({nrows} rows × {ncols} snapshots)")]
    EmptySnapshots { nrows: usize, ncols: usize },
    /// A snapshot entry is NaN or infinite.
    #[error("snapshot matrix entry (row {row}, snapshot {col}) is not finite: {value}")]
    NonFiniteSnapshot { row: usize, col: usize, value: f64 },
    /// Every snapshot is identically zero, so there is no subspace to find.
    #[error("every snapshot is identically zero; PCA has nothing to fit")]
    ZeroSnapshots,
    /// The mass vector does not have one entry per row.
    #[error("mass has {found} entries but the snapshots have {expected} rows")]
    MassLength { expected: usize, found: usize },
    /// A mass entry is zero, negative or not finite (pass free DOFs only).
    #[error("mass entry {index} must be positive and finite, got {value}")]
    InvalidMass { index: usize, value: f64 },
    /// The rows cannot be split into vertices of `group` consecutive rows.
    #[error("{nrows} rows cannot be grouped into vertices of {group} rows each")]
    InvalidGroup { group: usize, nrows: usize },
    /// A requested basis dimension is 0 or larger than what is available.
    #[error("basis dimension {requested} is out of range 1..={available}")]
    DimensionOutOfRange { requested: usize, available: usize },
    /// A matrix or vector argument has the wrong shape.
    #[error("{what} has shape {found:?}, expected {expected:?}")]
    ShapeMismatch {
        what: &'static str,
        expected: (usize, usize),
        found: (usize, usize),
    },
    /// A stored basis (e.g. a deserialized artifact) is inconsistent.
    #[error("invalid PCA basis: {0}")]
    InvalidBasis(String),
    /// The SVD iteration did not converge.
    #[error("the singular value decomposition did not converge")]
    SvdNoConvergence,
}

impl PcaError {
    /// `Ok(())` for no errors, the single error for one, [`PcaError::Many`] for several.
    pub fn collect(mut errors: Vec<PcaError>) -> Result<(), PcaError> {
        match errors.len() {
            0 => Ok(()),
            1 => Err(errors.remove(0)),
            _ => Err(PcaError::Many(errors)),
        }
    }
}
