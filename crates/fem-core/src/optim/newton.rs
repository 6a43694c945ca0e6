//! Newton's method with a backtracking line search.

use super::{
    Objective, SolveParams, SolveStats, armijo_backtracking, at_roundoff_floor, dot, norm, relative,
};
use crate::FemError;

/// An objective that can also solve with its (positive definite, e.g. projected) Hessian.
pub trait NewtonSystem: Objective {
    /// Solves H(x) d = −g. Implementations regularise H when it is only semidefinite.
    fn newton_direction(&mut self, x: &[f64], g: &[f64], d: &mut [f64]) -> Result<(), FemError>;
}

/// Minimises `system` from `x` (overwritten with the minimiser).
///
/// Each iteration solves for the Newton direction, falls back to steepest descent if that is not
/// a descent direction, and backtracks until the Armijo condition holds.
pub fn newton<S: NewtonSystem + ?Sized>(
    system: &mut S,
    x: &mut [f64],
    params: SolveParams,
) -> Result<SolveStats, FemError> {
    let n = system.dim();
    let mut g = vec![0.0; n];
    let mut d = vec![0.0; n];
    let mut x_new = vec![0.0; n];
    let mut g_new = vec![0.0; n];
    let mut value = system.value_gradient(x, &mut g);
    if !value.is_finite() || g.iter().any(|v| !v.is_finite()) {
        return Err(FemError::NonFinite {
            what: "energy at the start of the Newton solve",
            step: params.step,
        });
    }
    for it in 0..=params.max_iterations {
        let rel = relative(norm(&g), system.gradient_scale());
        if rel <= params.tolerance {
            return Ok(SolveStats {
                iterations: it,
                relative_gradient: rel,
                energy: value,
            });
        }
        if it == params.max_iterations {
            return Err(FemError::NotConverged {
                solver: "Newton",
                step: params.step,
                iterations: it,
                residual: rel,
                tolerance: params.tolerance,
            });
        }
        system.newton_direction(x, &g, &mut d)?;
        let slope = dot(&g, &d);
        if slope.is_nan() || slope >= 0.0 || d.iter().any(|v| !v.is_finite()) {
            for i in 0..n {
                d[i] = -g[i];
            }
        } else if at_roundoff_floor(x, &d, rel) {
            return Ok(SolveStats {
                iterations: it,
                relative_gradient: rel,
                energy: value,
            });
        }
        match armijo_backtracking(system, x, value, &g, &d, 1.0, &mut x_new, &mut g_new) {
            Some(ls) => {
                tracing::debug!(
                    step = params.step,
                    iteration = it,
                    relative_gradient = rel,
                    alpha = ls.alpha,
                    energy = ls.value,
                    "Newton iteration"
                );
                x.copy_from_slice(&x_new);
                std::mem::swap(&mut g, &mut g_new);
                value = ls.value;
            }
            None => {
                // No decrease is measurable any more: accept when within round-off of converged.
                system.value_gradient(x, &mut g);
                if rel <= params.tolerance.sqrt().min(1e3 * params.tolerance) {
                    return Ok(SolveStats {
                        iterations: it,
                        relative_gradient: rel,
                        energy: value,
                    });
                }
                return Err(FemError::LineSearchFailed {
                    solver: "Newton",
                    step: params.step,
                    iteration: it,
                });
            }
        }
    }
    unreachable!("the loop returns at it == max_iterations")
}
