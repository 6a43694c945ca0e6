//! The free-DOF system matrix of a step (projected or exact Hessian, plus M/h² and the springs'
//! stiffness): its pattern, values and factor, built once per mesh and refactorised with a
//! growing diagonal shift when only semidefinite; and that factor as L-BFGS's preconditioner.

use super::FullSpaceModel;
use crate::FemError;
use crate::optim::Preconditioner;
use crate::sparse::{HessianPattern, NO_SLOT};
use crate::sparse_cholesky::SparseCholesky;

/// Pattern, symbolic factorisation and value buffers of the free-DOF Hessian, built once.
pub(crate) struct NewtonParts {
    pub(crate) pattern: HessianPattern,
    /// The factor Newton directions solve with (and that preconditioners are swapped out of).
    pub(crate) chol: SparseCholesky,
    pub(crate) values: Vec<f64>,
    mass_slots: Vec<u32>,
}

impl std::fmt::Debug for NewtonParts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NewtonParts")
            .field("nnz", &self.pattern.nnz())
            .finish()
    }
}

impl NewtonParts {
    pub(crate) fn new(model: &FullSpaceModel) -> Result<Self, FemError> {
        let pattern = HessianPattern::new(&model.elements.tets, &model.dofs);
        let chol = SparseCholesky::analyse(&pattern)?;
        let mass_slots = model
            .mass
            .consistent
            .as_ref()
            .map(|c| pattern.vertex_csr_slots(c, &model.dofs))
            .unwrap_or_default();
        Ok(Self {
            values: vec![0.0; pattern.nnz()],
            pattern,
            chol,
            mass_slots,
        })
    }

    /// values += s·M on the free DOFs.
    pub(crate) fn add_mass(&mut self, model: &FullSpaceModel, s: f64) {
        match &model.mass.consistent {
            None => {
                for (j, &d) in model.dofs.free.iter().enumerate() {
                    self.values[self.pattern.diag[j]] += s * model.mass.lumped[d / 3];
                }
            }
            Some(csr) => {
                for (k, &m) in csr.val.iter().enumerate() {
                    for c in 0..3 {
                        let slot = self.mass_slots[3 * k + c];
                        if slot != NO_SLOT {
                            self.values[slot as usize] += s * m;
                        }
                    }
                }
            }
        }
    }

    /// Adds `diag` (one entry per DOF of the whole mesh, e.g. the springs' stiffness) to the
    /// diagonal at the free DOFs.
    pub(crate) fn add_diagonal(&mut self, model: &FullSpaceModel, diag: &[f64]) {
        for (j, &dof) in model.dofs.free.iter().enumerate() {
            self.values[self.pattern.diag[j]] += diag[dof];
        }
    }

    /// Factorises the current values into `chol`; when the matrix is only semidefinite, adds a
    /// growing multiple of its mean diagonal until the factorisation succeeds.
    pub(crate) fn factor(&mut self) -> Result<(), FemError> {
        self.factor_with(false)
    }

    /// [`NewtonParts::factor`] for a preconditioner: the factor may be f32 or 16-bit
    /// ([`SparseCholesky::factor_for_preconditioning`]), solved only through
    /// [`SparseCholesky::solve_preconditioner_in_place`].
    pub(crate) fn factor_preconditioner(&mut self) -> Result<(), FemError> {
        self.factor_with(true)
    }

    fn factor_with(&mut self, preconditioner: bool) -> Result<(), FemError> {
        let mean_diag = self
            .pattern
            .diag
            .iter()
            .map(|&s| self.values[s])
            .sum::<f64>()
            / self.pattern.dim().max(1) as f64;
        let mut shift = 0.0;
        for attempt in 0..12 {
            let a = self.pattern.matrix(&self.values);
            let r = if preconditioner {
                self.chol.factor_for_preconditioning(a).map(|_| ())
            } else {
                self.chol.factor(a)
            };
            match r {
                Ok(()) => return Ok(()),
                Err(e) => {
                    if attempt == 11 || !mean_diag.is_finite() {
                        return Err(e);
                    }
                    let next = if shift == 0.0 {
                        1e-10 * mean_diag.abs().max(f64::MIN_POSITIVE)
                    } else {
                        shift * 10.0
                    };
                    for &s in &self.pattern.diag {
                        self.values[s] += next - shift;
                    }
                    shift = next;
                }
            }
        }
        unreachable!("the last attempt returns")
    }
}

/// A factorised SPD matrix used as z = P⁻¹ r, factorised in f32 (and stored in 16 bits) where
/// that passes its check ([`SparseCholesky::factor_for_preconditioning`]): P is itself an
/// approximate Hessian.
#[derive(Debug)]
pub struct FactoredPreconditioner {
    pub(super) chol: SparseCholesky,
}

impl Preconditioner for FactoredPreconditioner {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        z.copy_from_slice(r);
        self.chol.solve_preconditioner_in_place(z);
    }
}
