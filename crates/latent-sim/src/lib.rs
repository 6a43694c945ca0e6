//! Reduced implicit Euler in linear (PCA) and nonlinear (autoencoder) subspaces (DESIGN §8).
//!
//! A [`Subspace`] maps latent coordinates z to PCA coefficients q (linear: q = z; neural:
//! q = decode(z)), and u = Uq. One step minimises, over z,
//!
//! E(z) = Σ_{e∈S} w_e V_e(U_e q(z)) + Φ(Uq(z), t) − f_gᵀUq(z) + 1/(2h²) (q − q̃)ᵀ (UᵀMU) (q − q̃),
//!
//! with q̃ = q_n + h q̇_n and ∇E(z) = J(z)ᵀ ∂E/∂q, one vector–Jacobian product. Only the rows of U
//! of the element set's vertices are ever multiplied ("partial decode"); a cubature rule's
//! scattered elements go further and keep ∂F/∂q per element, so that F = I + (∂F/∂q) q needs no
//! displacement at all. Springs and point loads are quadratic and linear in u, hence exact
//! functions of q through Σ_v U_vᵀU_v and Σ_v U_vᵀ: their vertices are never decoded. The full
//! displacement u = Uq is formed only when a frame is written out.

mod config;
pub mod model;
mod neural;
mod onset;
mod reduced;
pub mod runtime;
mod simulator;
mod subspace;

pub use config::{
    MAX_COMPLEMENT_DIRECTIONS, MAX_ONSET_DIRECTIONS, REDUCED_MIN_ITERATIONS, ReducedSolverConfig,
};

pub use model::{ModelFileError, ModelFormatError, ReducedModel};
pub use neural::NeuralSubspace;
pub use onset::{Augmented, DirectionParts};
pub use reduced::{ElasticPath, ReducedSpace, SERIAL_MAX_ELEMENTS, SpaceBuffers, SpaceParts};
pub use runtime::{
    AnyReducedSimulator, FullRuntime, Handle, Interactive, Real, ReducedRuntime, RuntimeError,
    StepStats, Surface,
};
pub use simulator::{
    PRECOND_MAX_AGE, Preconditioning, ReducedEnergy, ReducedSimulator, ReducedState,
    ReducedStepReport,
};
pub use subspace::{LinearSubspace, Subspace};

/// Errors of the reduced integrators.
#[derive(Debug, thiserror::Error)]
pub enum ReducedError {
    #[error(transparent)]
    Fem(#[from] fem_core::FemError),
    /// The basis does not fit the model.
    #[error("basis has {rows} rows but the model has {free} free DOFs; rebuild the PCA stage")]
    BasisShape { rows: usize, free: usize },
    /// A state vector given from outside does not have the subspace's length.
    #[error("a state of {got} coefficients was given to a subspace of {expected}")]
    StateShape { expected: usize, got: usize },
    /// A cubature rule that does not fit the model.
    #[error("cubature rule: {reason}; refit the cubature stage")]
    Cubature { reason: String },
    /// A reduced matrix that must be positive definite is not.
    #[error("the reduced {what} matrix is not positive definite")]
    NotPositiveDefinite { what: &'static str },
    /// The parts of a reduced space do not fit together or the mesh.
    #[error("reduced space: {reason}")]
    Parts { reason: String },
    /// A force or handle on a vertex whose basis rows the space does not hold (or that does not
    /// exist).
    #[error(
        "vertex {vertex} has no basis rows in this model (it holds those of the surface and of the \
         elements it evaluates; export with all rows to reach the others)"
    )]
    NoBasisRows { vertex: usize },
    /// A force index past the forces there are.
    #[error("there is no force {index} (there are {count})")]
    NoSuchForce { index: usize, count: usize },
    /// Keyframes that are empty, not finite or not in time order.
    #[error("keyframes must be finite [t, x, y, z] rows in time order, at least one")]
    Keyframes,
    /// A model that does not hold together ([`ReducedModel::check`]).
    #[error("invalid model: {reason}")]
    InvalidModel { reason: String },
}
