//! Unconstrained minimisation for implicit time stepping: Newton with a line search and
//! preconditioned L-BFGS, behind one [`Objective`] interface so the full-space and latent-space
//! integrators share them. Convergence is judged for both on the same relative gradient norm
//! ‖∇E‖ ≤ tol · s, where the objective supplies the force scale s.

mod lbfgs;
mod line_search;
mod newton;

pub use lbfgs::{Lbfgs, Preconditioner};
pub use line_search::{LineSearchResult, armijo_backtracking};
pub use newton::{NewtonSystem, newton};

use crate::FemError;

/// How a factorised preconditioner has served since it was made: the solves it served, the
/// iterations of the first of them, and the iterations the later ones took beyond that first
/// count, summed. Once that excess reaches about what a refactorisation costs in iterations,
/// slowing solves predict more slow ones and a fresh factor pays for itself within a step or
/// two. Counts rather than timings, so that when a factor is refreshed (and so the trajectory,
/// at the solver's tolerance) never depends on the machine's load. The full-space and the
/// reduced integrators keep their preconditioners by it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PreconditionerUse {
    solves: usize,
    fresh_iterations: usize,
    excess: usize,
}

impl PreconditionerUse {
    /// A new factor: nothing served yet.
    pub fn restart(&mut self) {
        *self = Self::default();
    }

    /// Records a converged solve of `iterations`.
    pub fn record(&mut self, iterations: usize) {
        if self.solves == 0 {
            self.fresh_iterations = iterations;
        } else {
            self.excess += iterations.saturating_sub(self.fresh_iterations);
        }
        self.solves += 1;
    }

    /// Solves served since the factorisation.
    pub fn solves(&self) -> usize {
        self.solves
    }

    /// Iterations of the first solve after the factorisation.
    pub fn fresh_iterations(&self) -> usize {
        self.fresh_iterations
    }

    /// Whether the factor has served `max_solves` solves, or its later solves took
    /// `excess_iterations` more iterations than its first one, together.
    pub fn is_stale(&self, max_solves: usize, excess_iterations: usize) -> bool {
        self.solves >= max_solves || self.excess >= excess_iterations
    }
}

/// A smooth function to minimise.
pub trait Objective {
    /// Number of unknowns.
    fn dim(&self) -> usize;
    /// E(x) and ∇E(x) (written to `g`). E may be `+∞` where the model is undefined (an inverted
    /// element of a material that cannot invert): the line search then steps back.
    fn value_gradient(&mut self, x: &[f64], g: &mut [f64]) -> f64;
    /// The force scale s used for the relative gradient test, for the state of the last
    /// `value_gradient` call.
    fn gradient_scale(&self) -> f64;
    /// An estimate of the round-off in E at the last evaluated point. Elastic energies of stiff
    /// materials at small strain are differences of large terms (μ/2·I₁ against μ ln J, say), so
    /// their absolute error is about ε·E·volume, far above ε·|E|. Changes of E below this level
    /// carry no information and the line search judges such steps by the gradient instead.
    fn value_noise(&self) -> f64 {
        0.0
    }
}

/// The `[solver]` section of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverConfig {
    #[serde(default)]
    pub method: SolverMethod,
    /// Relative gradient tolerance.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Iteration cap per solve (per time step).
    #[serde(default = "default_max_iterations")]
    pub max_iterations: usize,
    /// Number of correction pairs kept by L-BFGS.
    #[serde(default = "default_memory")]
    pub lbfgs_memory: usize,
    /// L-BFGS's initial inverse Hessian. Left out of the serialised form at its default, so that
    /// the cache keys of scenes that never set it (every Newton scene) stay what they were.
    #[serde(default, skip_serializing_if = "is_default")]
    pub preconditioner: LbfgsPreconditioner,
}

fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

fn default_tolerance() -> f64 {
    1e-6
}
fn default_max_iterations() -> usize {
    100
}
fn default_memory() -> usize {
    8
}

/// The most correction pairs L-BFGS may keep: far past where more history stops paying (its
/// two-loop recursion costs each pair every iteration).
pub const MAX_LBFGS_MEMORY: usize = 1_000;

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            method: SolverMethod::default(),
            tolerance: default_tolerance(),
            max_iterations: default_max_iterations(),
            lbfgs_memory: default_memory(),
            preconditioner: LbfgsPreconditioner::default(),
        }
    }
}

impl SolverConfig {
    pub fn check(&self, errors: &mut Vec<FemError>) {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            errors.push(FemError::InvalidConfig {
                field: "solver.tolerance".into(),
                reason: format!("must be in (0, 1), got {}", self.tolerance),
            });
        }
        if self.max_iterations == 0 {
            errors.push(FemError::InvalidConfig {
                field: "solver.max_iterations".into(),
                reason: "must be at least 1".into(),
            });
        }
        if !(1..=MAX_LBFGS_MEMORY).contains(&self.lbfgs_memory) {
            errors.push(FemError::InvalidConfig {
                field: "solver.lbfgs_memory".into(),
                reason: format!(
                    "must be 1 to {MAX_LBFGS_MEMORY} correction pairs (each holds two vectors \
                     of every degree of freedom; the default is {}), got {}",
                    default_memory(),
                    self.lbfgs_memory
                ),
            });
        }
    }
}

/// Which minimiser a time step uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SolverMethod {
    /// Newton with projected Hessians and sparse Cholesky: robust, and redoes the steps L-BFGS
    /// cannot finish.
    Newton,
    /// L-BFGS preconditioned by a factorised system matrix ([`LbfgsPreconditioner`]): the
    /// default. It stops at the same relative gradient as Newton for a fraction of the cost
    /// (on a 16.6k-DOF beam's training schedules 4.4–5.3 s against 10.9–11.7 s for 60 steps on
    /// one core), and a step it cannot finish is redone with Newton, so a scene without
    /// `[solver]` loses no robustness by it.
    #[default]
    Lbfgs,
}

impl SolverMethod {
    /// The name a scene's `method` and the command line's `--solver` write.
    pub fn name(self) -> &'static str {
        match self {
            SolverMethod::Newton => "newton",
            SolverMethod::Lbfgs => "lbfgs",
        }
    }
}

/// The matrix whose factor preconditions full-space L-BFGS.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LbfgsPreconditioner {
    /// The projected Hessian + M/h² at the start of a step, refactorised only when the solves
    /// it serves slow down (or it is [`crate::integrator::PRECOND_MAX_AGE`] steps old), and
    /// turned with the body's best-fit rotation in between
    /// ([`crate::integrator::FactoredPreconditioner`]). Large rotations leave the rest matrix
    /// far from the true curvature; this one follows them.
    #[default]
    CurrentState,
    /// K₀ + M/h² at rest, factorised once (AutoDef's choice): cheapest while deformations stay
    /// small, slow to converge once parts of the body rotate.
    Rest,
}

/// Outcome of one minimisation.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SolveStats {
    pub iterations: usize,
    /// Final ‖∇E‖ / s.
    pub relative_gradient: f64,
    /// Final objective value.
    pub energy: f64,
}

/// Tolerances and the step number (for error messages) of one solve.
#[derive(Debug, Clone, Copy)]
pub struct SolveParams {
    pub tolerance: f64,
    pub max_iterations: usize,
    /// Time step index, reported in errors.
    pub step: usize,
}

/// A full (Newton or preconditioned quasi-Newton) step this small relative to the unknowns
/// cannot change them any more in floating point: the solve has reached its round-off floor.
///
/// For stiff problems (condition number κ ≫ 1) the gradient, a sum of element forces of size
/// ‖K‖‖x‖, carries round-off of about ε‖K‖‖x‖, so a relative gradient tolerance below ε·κ is
/// unreachable; the step size still says when x is as accurate as it can be.
/// A solve that stops at its round-off floor must still have a relative gradient below this.
pub(crate) const ROUNDOFF_SANITY: f64 = 1e-3;

pub(crate) fn at_roundoff_floor(x: &[f64], d: &[f64], relative_gradient: f64) -> bool {
    const STEP: f64 = 1e-12;
    const SANITY: f64 = ROUNDOFF_SANITY;
    let xmax = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let dmax = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    xmax > 0.0 && dmax <= STEP * xmax && relative_gradient <= SANITY
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

pub(crate) fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// Relative gradient ‖g‖ / s, guarding a zero scale.
pub(crate) fn relative(gnorm: f64, scale: f64) -> f64 {
    if scale > 0.0 {
        gnorm / scale
    } else if gnorm == 0.0 {
        0.0
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::PreconditionerUse;

    #[test]
    fn a_preconditioner_goes_stale_by_extra_iterations_or_by_age() {
        let mut u = PreconditionerUse::default();
        u.record(5);
        assert_eq!((u.solves(), u.fresh_iterations()), (1, 5));
        u.record(9); // 4 beyond the first
        u.record(3); // none
        u.record(7); // 2 more: 6 in all
        assert!(!u.is_stale(16, 10));
        assert!(u.is_stale(16, 6));
        assert!(u.is_stale(4, 10), "four solves served");
        u.record(9); // 10 in all
        assert!(u.is_stale(16, 10));
        u.restart();
        assert_eq!(u, PreconditionerUse::default());
        assert!(!u.is_stale(16, 10));
    }
}
