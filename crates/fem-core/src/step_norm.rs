//! The implicit step's operator at rest, A₀ = K₀ + M/h² on the free DOFs, as a matrix–vector
//! product: the norm in which a Galerkin step is best.
//!
//! Linearised at rest, one implicit Euler step minimises ½ uᵀA₀u − bᵀu, and its Galerkin
//! solution in a subspace span(U) is the A₀-orthogonal projection of the full step's answer
//! (Céa's lemma for this quadratic). A subspace chosen to represent the snapshots well in the
//! M-norm (PCA) can still lose the step: the part of a frame it misses may carry little mass but
//! much strain. Fitted in the A₀-norm, the subspace is chosen for what the step needs.

use crate::integrator::{FullSpaceModel, NewtonParts};
use crate::{FemError, with_material};

/// A₀ = K₀ + M/h², assembled once.
pub struct StepOperator {
    parts: NewtonParts,
}

impl std::fmt::Debug for StepOperator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StepOperator")
            .field("dim", &self.dim())
            .finish()
    }
}

impl StepOperator {
    /// Assembles K₀ (the stiffness at rest) plus M/h² for `model` with time step `h`.
    pub fn new(model: &FullSpaceModel, h: f64) -> Result<Self, FemError> {
        let mut parts = NewtonParts::new(model)?;
        let rest = vec![0.0; model.num_full()];
        let mut buf = crate::assembly::AssemblyBuffers::default();
        with_material!(&model.material, |m| crate::assembly::hessian(
            m,
            &model.elements,
            crate::assembly::ElementSet::All,
            &rest,
            true,
            &parts.pattern,
            &mut parts.values,
            &mut buf
        ));
        parts.add_mass(model, 1.0 / (h * h));
        Ok(Self { parts })
    }

    /// Number of free DOFs.
    pub fn dim(&self) -> usize {
        self.parts.pattern.dim()
    }

    /// y = A₀ x on the free DOFs.
    pub fn apply(&self, x: &[f64], y: &mut [f64]) {
        self.parts.pattern.mul_vec(&self.parts.values, x, y);
    }
}
