//! The implicit step's operator at rest, A₀ = K₀ + M/h² on the free DOFs, as a matrix–vector
//! product: the norm in which a Galerkin step is best.
//!
//! Linearised at rest, one implicit Euler step minimises ½ uᵀA₀u − bᵀu, and its Galerkin
//! solution in a subspace span(U) is the A₀-orthogonal projection of the full step's answer
//! (Céa's lemma for this quadratic). A subspace chosen to represent the snapshots well in the
//! M-norm (PCA) can still lose the step: the part of a frame it misses may carry little mass but
//! much strain. Fitted in the A₀-norm, the subspace is chosen for what the step needs.

use crate::integrator::{FullSpaceModel, NewtonParts, TimeConfig};
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
        let mut parts = rest_stiffness(model)?;
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

/// K₀, the stiffness at rest, on the free DOFs (add the mass term with
/// [`NewtonParts::add_mass`]).
pub(crate) fn rest_stiffness(model: &FullSpaceModel) -> Result<NewtonParts, FemError> {
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
    Ok(parts)
}

/// How a body at rest starts to fall under gravity: the first `count` positions of linear
/// implicit Euler from rest, A₀x₁ = f_g and A₀x_{n+1} = f_g + (M/h²)(2x_n − x_{n−1}) with
/// A₀ = K₀ + M/h², on the free DOFs (one factorisation of A₀).
///
/// While h is short against the body's slowest period these are a uniform fall held back in a
/// layer at the pins, a shape that carries too little of the snapshots' energy for PCA to keep
/// but that every scene starting at rest under gravity passes through. Quasi-static steps
/// have one position, the static response K₀⁻¹f_g. Without gravity, or without pins in a
/// quasi-static scene (K₀ is then singular), there are none.
///
/// # Errors
/// [`FemError`] when A₀ cannot be factorised.
pub fn gravity_onset(
    model: &FullSpaceModel,
    time: &TimeConfig,
    count: usize,
) -> Result<Vec<Vec<f64>>, FemError> {
    let pinned = model.dofs.free.len() < model.num_full();
    if count == 0 || model.gravity.norm() == 0.0 || (time.quasi_static && !pinned) {
        return Ok(Vec::new());
    }
    let (count, inv_h2) = if time.quasi_static {
        (1, 0.0)
    } else {
        (count, 1.0 / (time.step * time.step))
    };
    let mut parts = rest_stiffness(model)?;
    let stiffness = parts.values.clone();
    parts.add_mass(model, inv_h2);
    // M/h² alone, in the same value layout.
    let mass: Vec<f64> = parts
        .values
        .iter()
        .zip(&stiffness)
        .map(|(a, k)| a - k)
        .collect();
    parts.factor()?;
    let n = model.dofs.free.len();
    let load: Vec<f64> = model
        .dofs
        .free
        .iter()
        .map(|&d| model.gravity_load[d])
        .collect();
    let mut iterates: Vec<Vec<f64>> = Vec::with_capacity(count);
    let (mut inertia, rest) = (vec![0.0; n], vec![0.0; n]);
    for i in 0..count {
        // (M/h²)(2x_n − x_{n−1}), with x₀ = x₋₁ = 0.
        if let Some(now) = iterates.last() {
            let prev = if i >= 2 { &iterates[i - 2] } else { &rest };
            let y: Vec<f64> = now.iter().zip(prev).map(|(a, b)| 2.0 * a - b).collect();
            parts.pattern.mul_vec(&mass, &y, &mut inertia);
        }
        let mut x: Vec<f64> = load.iter().zip(&inertia).map(|(f, m)| f + m).collect();
        parts.chol.solve_in_place(&mut x);
        iterates.push(x);
    }
    Ok(iterates)
}
