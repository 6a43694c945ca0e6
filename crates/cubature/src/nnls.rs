//! Lawson–Hanson non-negative least squares: min ‖Ax − b‖ subject to x ≥ 0.
//!
//! The active-set method of Lawson & Hanson (1974, ch. 23). The passive set P holds the columns
//! allowed to be positive; x is kept feasible with x_P > 0 and x_Z = 0. Each outer step moves the
//! column with the largest dual component w = Aᵀ(b − Ax) (above a tolerance) into P and solves the
//! unconstrained least-squares problem on P; whenever that solution leaves the feasible set the
//! inner loop steps from x toward it until the first component reaches zero and moves that
//! component back out. At the end the KKT conditions hold: x ≥ 0, w_j ≤ tol where x_j = 0 and
//! w_j ≈ 0 where x_j > 0.
//!
//! The passive least-squares problems are solved through the normal equations G_PP z = c_P with
//! G = AᵀA, c = Aᵀb, using a Cholesky factor G_PP = RᵀR that is updated in O(|P|²) when a column
//! enters (one triangular solve) or leaves (Givens rotations restore the triangle). The passive
//! set is small in cubature (≤ a few hundred columns), so the squared condition number of the
//! normal equations is an acceptable price for never touching the tall matrix A inside the loop.
//! A column whose Cholesky pivot would fall below [`DEPENDENCE_TOLERANCE`] relative to its own
//! norm is numerically dependent on the passive ones; it is skipped rather than admitted, which is
//! how duplicate, zero and rank-deficient columns are handled. The algorithm is deterministic
//! (ties go to the lowest index).
//!
//! The factor and the passive set survive between solves, so the greedy fit, which grows the
//! problem by one column a step, goes on from the last step's solution instead of starting over. On
//! the cubature stage of the stiff cantilever that was the default scene until 2026-11-27 (training
//! matrix and greedy fit, 169 of 15,360 elements) that took 2.6–2.8 s, against 3.3–3.5 s with every
//! step solved from an empty passive set (two runs each, alternating).
//!
//! ```
//! use faer::mat;
//! // min ‖Ax − b‖, x ≥ 0: the unconstrained solution is (1, −1), the constrained one (0.5, 0).
//! let a = mat![[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
//! let b = [1.0, 0.0, -1.0];
//! let s = cubature::nnls(a.as_ref(), &b)?;
//! assert!((s.x[0] - 0.5).abs() < 1e-12 && s.x[1] == 0.0);
//! assert!((s.residual_norm - 1.5f64.sqrt()).abs() < 1e-12);
//! # Ok::<(), cubature::CubatureError>(())
//! ```

use faer::{Mat, MatRef};

use crate::CubatureError;

/// A column enters the passive set only if the square of its Cholesky pivot is at least this
/// fraction of its squared norm G_tt, i.e. its component orthogonal to the passive columns is at
/// least 10⁻⁵ of its length. Below that the normal equations would lose more than half the digits.
pub const DEPENDENCE_TOLERANCE: f64 = 1e-10;

/// Tunables of [`nnls_with`]. `None` picks the default described on each field.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NnlsParams {
    /// Cap on the number of iterations (columns moved into or out of the passive set).
    /// Default 3n, as in Lawson & Hanson's code.
    pub max_iterations: Option<usize>,
    /// A column enters the passive set only if its dual component a_jᵀ(b − Ax) exceeds this.
    /// Default 10 ε · max(rows, n) · maxⱼ‖a_j‖ · ‖b‖, the size of rounding error in that product.
    pub dual_tolerance: Option<f64>,
}

/// The result of [`nnls`].
#[derive(Debug, Clone, PartialEq)]
pub struct NnlsSolution {
    /// The minimiser, x ≥ 0, with exact zeros outside the passive set.
    pub x: Vec<f64>,
    /// ‖Ax − b‖, computed directly from A (not from the normal equations).
    pub residual_norm: f64,
    /// Iterations used (columns moved into or out of the passive set).
    pub iterations: usize,
}

/// Solves min ‖Ax − b‖ subject to x ≥ 0 with the default [`NnlsParams`].
pub fn nnls(a: MatRef<'_, f64>, b: &[f64]) -> Result<NnlsSolution, CubatureError> {
    nnls_with(a, b, &NnlsParams::default())
}

/// Solves min ‖Ax − b‖ subject to x ≥ 0.
///
/// Errors: `b` does not have one entry per row of `a`, non-finite input, or the iteration limit.
pub fn nnls_with(
    a: MatRef<'_, f64>,
    b: &[f64],
    params: &NnlsParams,
) -> Result<NnlsSolution, CubatureError> {
    let (rows, n) = (a.nrows(), a.ncols());
    if b.len() != rows {
        return Err(CubatureError::ShapeMismatch {
            what: "right-hand side b",
            expected: (rows, 1),
            found: (b.len(), 1),
        });
    }
    check_finite("right-hand side b", b.iter().copied())?;
    for j in 0..n {
        check_finite("matrix A", a.col(j).iter().copied()).map_err(|e| match e {
            CubatureError::NonFiniteInput { what, index, value } => CubatureError::NonFiniteInput {
                what,
                index: j * rows + index,
                value,
            },
            other => other,
        })?;
    }
    let mut x = vec![0.0; n];
    let mut iterations = 0;
    if n > 0 {
        let g: Mat<f64> = a.transpose() * a;
        let c: Vec<f64> = (0..n).map(|j| dot_col(a, j, b)).collect();
        let b_norm = norm(b);
        let max_col = (0..n).map(|j| g[(j, j)].sqrt()).fold(0.0, f64::max);
        let tol = params
            .dual_tolerance
            .unwrap_or_else(|| default_dual_tolerance(rows.max(n), max_col, b_norm));
        let max_iter = params.max_iterations.unwrap_or(3 * n);
        iterations = ActiveSet::default().solve(g.as_ref(), &c, &mut x, tol, max_iter)?;
    }
    let mut r = b.to_vec();
    for (j, &xj) in x.iter().enumerate() {
        if xj != 0.0 {
            for (ri, aij) in r.iter_mut().zip(a.col(j).iter()) {
                *ri -= aij * xj;
            }
        }
    }
    Ok(NnlsSolution {
        x,
        residual_norm: norm(&r),
        iterations,
    })
}

/// 10 ε · size · ‖a‖_max · ‖b‖: the rounding error of a dual component a_jᵀ(b − Ax).
pub(crate) fn default_dual_tolerance(size: usize, max_col_norm: f64, b_norm: f64) -> f64 {
    10.0 * f64::EPSILON * size.max(1) as f64 * max_col_norm * b_norm
}

/// The Lawson–Hanson iteration on the normal equations, with a Cholesky factor of G_PP that
/// survives between calls so a caller that grows the problem by one column (the greedy cubature
/// loop) can warm-start from the previous passive set.
#[derive(Debug, Default)]
pub(crate) struct ActiveSet {
    /// Passive column indices, in the order of the factor's columns.
    passive: Vec<usize>,
    /// Upper-triangular R with RᵀR = G_PP: `r[j]` is column j, entries R[0..=j, j].
    r: Vec<Vec<f64>>,
    /// Scratch: solution on the passive set.
    z: Vec<f64>,
    /// Columns refused since the passive set last shrank (dependent, or no descent).
    blocked: Vec<bool>,
    /// Membership of the passive set.
    in_passive: Vec<bool>,
}

impl ActiveSet {
    /// The passive set, in factor order.
    pub(crate) fn passive(&self) -> &[usize] {
        &self.passive
    }

    /// Renames the passive columns to 0..|P| in factor order (the caller has permuted its columns
    /// to match). The factor is unchanged.
    pub(crate) fn renumber_passive(&mut self) {
        for (i, p) in self.passive.iter_mut().enumerate() {
            *p = i;
        }
    }

    /// Runs Lawson–Hanson on G = `g`, c = `c` from the feasible `x`, whose positive entries must be
    /// exactly the current passive set (empty for a cold start) with the factor matching `g`.
    /// Returns the iterations used; on return x_P > 0 solves the passive problem and x_Z = 0.
    pub(crate) fn solve(
        &mut self,
        g: MatRef<'_, f64>,
        c: &[f64],
        x: &mut [f64],
        tol: f64,
        max_iterations: usize,
    ) -> Result<usize, CubatureError> {
        let n = c.len();
        debug_assert!(g.nrows() == n && g.ncols() == n && x.len() == n);
        self.blocked.clear();
        self.blocked.resize(n, false);
        self.in_passive.clear();
        self.in_passive.resize(n, false);
        for &p in &self.passive {
            self.in_passive[p] = true;
        }
        let mut iterations = 0;
        if !self.passive.is_empty() {
            self.inner(c, x, None, &mut iterations, max_iterations)?;
        }
        loop {
            let mut best: Option<(usize, f64)> = None;
            for j in 0..n {
                if self.in_passive[j] || self.blocked[j] {
                    continue;
                }
                let mut w = c[j];
                for &p in &self.passive {
                    w -= g[(j, p)] * x[p];
                }
                if w > tol && best.is_none_or(|(_, bw)| w > bw) {
                    best = Some((j, w));
                }
            }
            let Some((t, _)) = best else { break };
            iterations += 1;
            if iterations > max_iterations {
                return Err(CubatureError::NnlsNoConvergence {
                    iterations: max_iterations,
                });
            }
            if !self.try_append(g, t) {
                self.blocked[t] = true;
                continue;
            }
            self.inner(c, x, Some(t), &mut iterations, max_iterations)?;
        }
        Ok(iterations)
    }

    /// Solves the passive problem and restores feasibility (Lawson–Hanson's inner loop).
    /// `added` is the column that just entered, refused again if it brings no descent.
    fn inner(
        &mut self,
        c: &[f64],
        x: &mut [f64],
        added: Option<usize>,
        iterations: &mut usize,
        max_iterations: usize,
    ) -> Result<(), CubatureError> {
        let mut first = true;
        loop {
            self.solve_passive(c);
            let s = self.passive.len();
            if first && let Some(t) = added {
                // In exact arithmetic w_t > 0 implies z_t > 0; rounding can break that, and
                // admitting t would then cycle (enter, leave at step length 0, enter again).
                if self.z[s - 1] <= 0.0 {
                    self.delete(s - 1);
                    x[t] = 0.0;
                    self.blocked[t] = true;
                    return Ok(());
                }
            }
            first = false;
            if self.z.iter().all(|&z| z > 0.0) {
                for (i, &p) in self.passive.iter().enumerate() {
                    x[p] = self.z[i];
                }
                return Ok(());
            }
            *iterations += 1;
            if *iterations > max_iterations {
                return Err(CubatureError::NnlsNoConvergence {
                    iterations: max_iterations,
                });
            }
            // Largest step toward z that keeps x feasible.
            let (mut alpha, mut hit) = (f64::INFINITY, 0);
            for (i, &p) in self.passive.iter().enumerate() {
                if self.z[i] <= 0.0 {
                    let a = x[p] / (x[p] - self.z[i]);
                    if a < alpha {
                        (alpha, hit) = (a, i);
                    }
                }
            }
            for (i, &p) in self.passive.iter().enumerate() {
                x[p] += alpha * (self.z[i] - x[p]);
            }
            for i in (0..s).rev() {
                let p = self.passive[i];
                if i == hit || x[p] <= 0.0 {
                    x[p] = 0.0;
                    self.delete(i);
                }
            }
            self.blocked.fill(false);
            if self.passive.is_empty() {
                return Ok(());
            }
        }
    }

    /// Appends column t to the factor unless it is numerically dependent on the passive columns.
    fn try_append(&mut self, g: MatRef<'_, f64>, t: usize) -> bool {
        let gtt = g[(t, t)];
        if gtt.is_nan() || gtt <= 0.0 {
            return false;
        }
        let s = self.passive.len();
        // Rᵀ l = G[P, t]; row i of Rᵀ is column i of R.
        let mut col = vec![0.0; s + 1];
        for i in 0..s {
            let ri = &self.r[i];
            let mut v = g[(self.passive[i], t)];
            for k in 0..i {
                v -= ri[k] * col[k];
            }
            col[i] = v / ri[i];
        }
        let d2 = gtt - col[..s].iter().map(|l| l * l).sum::<f64>();
        if d2.is_nan() || d2 <= DEPENDENCE_TOLERANCE * gtt {
            return false;
        }
        col[s] = d2.sqrt();
        self.r.push(col);
        self.passive.push(t);
        self.in_passive[t] = true;
        true
    }

    /// Removes the passive column at factor position `i`; Givens rotations restore the triangle.
    fn delete(&mut self, i: usize) {
        let p = self.passive.remove(i);
        self.in_passive[p] = false;
        self.r.remove(i);
        // Columns i.. now hold one sub-diagonal entry each (upper Hessenberg).
        for q in i..self.r.len() {
            let (a, b) = (self.r[q][q], self.r[q][q + 1]);
            let h = a.hypot(b);
            let (cs, sn) = if h == 0.0 { (1.0, 0.0) } else { (a / h, b / h) };
            self.r[q][q] = h;
            self.r[q].pop();
            for col in &mut self.r[q + 1..] {
                let (u, v) = (col[q], col[q + 1]);
                col[q] = cs * u + sn * v;
                col[q + 1] = -sn * u + cs * v;
            }
        }
    }

    /// z = G_PP⁻¹ c_P through RᵀR.
    fn solve_passive(&mut self, c: &[f64]) {
        let s = self.passive.len();
        self.z.clear();
        self.z.resize(s, 0.0);
        for i in 0..s {
            let ri = &self.r[i];
            let mut v = c[self.passive[i]];
            for k in 0..i {
                v -= ri[k] * self.z[k];
            }
            self.z[i] = v / ri[i];
        }
        for i in (0..s).rev() {
            let mut v = self.z[i];
            for j in i + 1..s {
                v -= self.r[j][i] * self.z[j];
            }
            self.z[i] = v / self.r[i][i];
        }
    }
}

pub(crate) fn check_finite(
    what: &'static str,
    values: impl Iterator<Item = f64>,
) -> Result<(), CubatureError> {
    for (index, value) in values.enumerate() {
        if !value.is_finite() {
            return Err(CubatureError::NonFiniteInput { what, index, value });
        }
    }
    Ok(())
}

fn dot_col(a: MatRef<'_, f64>, j: usize, v: &[f64]) -> f64 {
    a.col(j).iter().zip(v).map(|(x, y)| x * y).sum()
}

pub(crate) fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
