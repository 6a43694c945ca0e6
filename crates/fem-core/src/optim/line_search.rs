//! Backtracking line search with the Armijo sufficient-decrease condition.

use super::{Objective, dot};

/// Where a line search ended.
#[derive(Debug, Clone, Copy)]
pub struct LineSearchResult {
    /// Accepted step length.
    pub alpha: f64,
    /// Objective at the accepted point.
    pub value: f64,
    /// Number of objective evaluations.
    pub evaluations: usize,
}

/// Halves α from `alpha0` until E(x + αd) ≤ E(x) + c₁α∇Eᵀd. On success `x_new` and `g_new` hold
/// the accepted point and its gradient.
///
/// Near a minimum the decrease can fall below the round-off of E itself; a step whose value is
/// equal to E(x) within round-off ([`Objective::value_noise`]) and whose gradient is smaller is
/// then accepted too.
pub fn armijo_backtracking<O: Objective + ?Sized>(
    objective: &mut O,
    x: &[f64],
    value: f64,
    gradient: &[f64],
    direction: &[f64],
    alpha0: f64,
    x_new: &mut [f64],
    g_new: &mut [f64],
) -> Option<LineSearchResult> {
    const C1: f64 = 1e-4;
    const MAX_HALVINGS: usize = 60;
    let slope = dot(gradient, direction);
    if slope.is_nan() || slope >= 0.0 {
        return None;
    }
    let gnorm2 = dot(gradient, gradient);
    let mut alpha = alpha0;
    for k in 0..MAX_HALVINGS {
        for i in 0..x.len() {
            x_new[i] = x[i] + alpha * direction[i];
        }
        let trial = objective.value_gradient(x_new, g_new);
        if trial.is_finite() {
            if trial <= value + C1 * alpha * slope {
                return Some(LineSearchResult {
                    alpha,
                    value: trial,
                    evaluations: k + 1,
                });
            }
            let noise =
                (64.0 * f64::EPSILON * value.abs().max(trial.abs())).max(objective.value_noise());
            if (trial - value).abs() <= noise && dot(g_new, g_new) < gnorm2 {
                return Some(LineSearchResult {
                    alpha,
                    value: trial,
                    evaluations: k + 1,
                });
            }
        }
        alpha *= 0.5;
    }
    None
}
