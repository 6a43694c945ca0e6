//! The springs' constant Hessian in q, kept between steps while the same forces are active.

use fem_core::integrator::FullSpaceModel;

use crate::reduced::{ReducedSpace, axpy};

/// Σ_f k_f/n_f Σ_v U_vᵀU_v over the springs active at the time it was updated for (k×k): the
/// springs' constant Hessian in q, rebuilt only when a force switches on or off.
#[derive(Debug, Default)]
pub(super) struct SpringTerm {
    pub(super) active: Vec<bool>,
    pub(super) valid: bool,
    pub(super) matrix: Vec<f64>,
}

impl SpringTerm {
    pub(super) fn update(
        &mut self,
        model: &FullSpaceModel,
        space: &ReducedSpace,
        t: f64,
    ) -> &[f64] {
        let same = self.valid
            && model
                .forces
                .iter()
                .map(|f| f.is_active(t))
                .eq(self.active.iter().copied());
        if !same {
            let k = space.k;
            self.active.clear();
            self.active
                .extend(model.forces.iter().map(|f| f.is_active(t)));
            self.matrix.clear();
            self.matrix.resize(k * k, 0.0);
            for (f, gram) in model.forces.iter().zip(&space.force_gram) {
                if f.is_active(t) && f.stiffness > 0.0 {
                    let s = f.stiffness / f.vertices.len() as f64;
                    axpy(s, gram, &mut self.matrix);
                }
            }
            self.valid = true;
        }
        &self.matrix
    }
}
