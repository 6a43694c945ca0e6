//! Typed errors of the crate. Every message says what went wrong and where.

/// Errors of configuration checks, model construction, deserialisation and training.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NnError {
    /// An `[autoencoder]` value is invalid; `field` is the dotted scene path (`autoencoder.epochs`).
    #[error("invalid value for `{field}`: {reason}")]
    InvalidConfig { field: String, reason: String },
    /// Several configuration errors, reported together.
    #[error("{}", .0.iter().map(|e| format!("  - {e}")).collect::<Vec<_>>().join("\n"))]
    Many(Vec<NnError>),
    /// Layer sizes, activations or parameter arrays do not describe a valid network.
    #[error("invalid network: {0}")]
    InvalidNetwork(String),
    /// A stored model (e.g. a deserialised artifact) is inconsistent.
    #[error("invalid autoencoder model: {0}")]
    InvalidModel(String),
    /// The training data has no samples or no features.
    #[error("the training data is empty ({features} features × {samples} samples)")]
    EmptyData { features: usize, samples: usize },
    /// There are too few samples for the requested validation split.
    #[error("{samples} samples are too few: {reason}")]
    TooFewSamples { samples: usize, reason: String },
    /// A data entry is NaN or infinite.
    #[error("data entry (feature {feature}, sample {sample}) is not finite: {value}")]
    NonFiniteData {
        feature: usize,
        sample: usize,
        value: f64,
    },
    /// A matrix or vector argument has the wrong shape.
    #[error("{what} has shape {found:?}, expected {expected:?}")]
    ShapeMismatch {
        what: &'static str,
        expected: (usize, usize),
        found: (usize, usize),
    },
    /// The loss became NaN or infinite (learning rate too large, or bad data).
    #[error("training diverged at epoch {epoch}: the loss is {loss}")]
    Diverged { epoch: usize, loss: f64 },
}

impl NnError {
    /// `Ok(())` for no errors, the single error for one, [`NnError::Many`] for several.
    pub fn collect(mut errors: Vec<NnError>) -> Result<(), NnError> {
        match errors.len() {
            0 => Ok(()),
            1 => Err(errors.remove(0)),
            _ => Err(NnError::Many(errors)),
        }
    }
}
