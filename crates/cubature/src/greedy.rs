//! Greedy element selection with non-negative least squares (An, Kim & James 2008, §4).
//!
//! Starting from the empty set, each step scores a seeded random subset of `candidates`
//! unselected elements by their alignment with the residual r = b − A_S w,
//!
//! score(e) = a_eᵀ r / ‖a_e‖   (positive alignment only),
//!
//! adds the best one to S, re-solves min ‖A_S w − b‖ subject to w ≥ 0 (Lawson–Hanson, warm
//! started from the previous passive set), and returns elements whose weight dropped to zero to
//! the pool. It stops when ‖A_S w − b‖ / ‖b‖ ≤ `tolerance`, when |S| reaches `max_elements`, or
//! when no element is positively aligned with the residual any more. If none of the random
//! candidates is aligned, the whole pool is scored before giving up.
//!
//! The NNLS works on the Gram matrix G_SS = A_SᵀA_S, grown by one column per step, so each step
//! costs O(rows · (candidates + |S|)) for the scores, the new Gram column and the residual, plus
//! O(|S|²) for the factor update: AutoDef's trick of fitting each step on a random 50-pose subset
//! is not needed. Every reduction runs in a fixed order, so a seed always gives the same rule.

use faer::MatRef;
use fem_core::rng::SplitMix64;
use rayon::prelude::*;

use crate::nnls::{ActiveSet, default_dual_tolerance, dot, norm};
use crate::{CubatureConfig, CubatureError, CubatureRule, TrainingMatrix};

/// Salt of the candidate stream, so it differs from the pose-subsample stream of the same seed.
const CANDIDATE_SALT: u64 = 0x4341_4E44_4944_0002;

/// Stop after this many consecutive steps that did not lower the error (an element that keeps
/// being admitted and dropped again, in floating point).
const MAX_STALLS: usize = 20;

/// Rows per parallel task when forming the residual.
const ROW_BLOCK: usize = 256;

/// Progress of [`fit_with_progress`], reported after each greedy step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitProgress<'a> {
    /// Greedy steps so far.
    pub step: usize,
    /// Elements currently selected (|S|).
    pub elements: usize,
    /// Current relative training error ‖A_S w − b‖ / ‖b‖.
    pub relative_error: f64,
    /// The element budget (`max_elements`, capped by the mesh).
    pub budget: usize,
    /// The current rule: selected elements of the mesh (in selection order) and their weights.
    pub selected: &'a [usize],
    pub weights: &'a [f64],
}

/// Fits a cubature rule to `data` (see the module docs).
pub fn fit(data: &TrainingMatrix, config: &CubatureConfig) -> Result<CubatureRule, CubatureError> {
    fit_with_progress(data, config, &mut |_| {})
}

/// [`fit`], calling `progress` after every greedy step.
pub fn fit_with_progress(
    data: &TrainingMatrix,
    config: &CubatureConfig,
    progress: &mut dyn FnMut(&FitProgress<'_>),
) -> Result<CubatureRule, CubatureError> {
    config.validate()?;
    // Column indices throughout; the rule and the progress name the mesh's elements.
    let m = data.num_columns();
    let rows = data.rows();
    let b = data.b();
    let b_norm = norm(b);
    if b_norm == 0.0 {
        return Err(CubatureError::ZeroTarget {
            poses: data.num_poses(),
        });
    }
    let budget = config.max_elements.min(m);
    let col_norms: Vec<f64> = (0..m)
        .into_par_iter()
        .map(|e| norm(data.column(e)))
        .collect();
    let max_col = col_norms.iter().copied().fold(0.0, f64::max);
    let dual_tol = default_dual_tolerance(rows.max(budget), max_col, b_norm);
    // A zero column (an element no basis vector moves) can never help.
    let mut pool: Vec<usize> = (0..m).filter(|&e| col_norms[e] > 0.0).collect();
    let mut rng = SplitMix64::new(config.seed ^ CANDIDATE_SALT);

    let mut selected: Vec<usize> = Vec::new();
    let mut w: Vec<f64> = Vec::new();
    let mut c: Vec<f64> = Vec::new();
    let mut gram = Gram::default();
    let mut solver = ActiveSet::default();
    let mut r = b.to_vec();
    let mut error = 1.0;
    let mut curve = Vec::new();
    let (mut step, mut stalls) = (0, 0);

    while error > config.tolerance && selected.len() < budget && !pool.is_empty() {
        step += 1;
        let score = |e: usize| dot(data.column(e), &r) / col_norms[e];
        // Partial Fisher–Yates: the first `nc` pool entries become a uniform random subset.
        let nc = config.candidates.min(pool.len());
        for i in 0..nc {
            let j = i + rng.below(pool.len() - i);
            pool.swap(i, j);
        }
        let best = match best_aligned(&pool[..nc], &score) {
            Some(found) => Some(found),
            None => best_aligned(&pool, &score),
        };
        let Some(pos) = best else {
            tracing::debug!(step, "no element is aligned with the residual any more");
            break;
        };
        let e = pool.swap_remove(pos);

        // Grow G_SS and c_S = A_Sᵀb by the new element, then re-solve from the previous set.
        let ae = data.column(e);
        let s = selected.len();
        let new_col: Vec<f64> = (0..=s)
            .into_par_iter()
            .map(|i| {
                if i < s {
                    dot(data.column(selected[i]), ae)
                } else {
                    col_norms[e] * col_norms[e]
                }
            })
            .collect();
        gram.push(&new_col);
        c.push(dot(ae, b));
        selected.push(e);
        w.push(0.0);
        solver.solve(gram.view(), &c, &mut w, dual_tol, 3 * selected.len())?;

        // Keep the passive set (positive weights), in factor order; the rest go back to the pool.
        let keep = solver.passive().to_vec();
        if keep.len() != selected.len() || keep.iter().enumerate().any(|(i, &p)| i != p) {
            let mut in_keep = vec![false; selected.len()];
            for &p in &keep {
                in_keep[p] = true;
            }
            pool.extend(
                (0..selected.len())
                    .filter(|&i| !in_keep[i])
                    .map(|i| selected[i]),
            );
            selected = keep.iter().map(|&i| selected[i]).collect();
            w = keep.iter().map(|&i| w[i]).collect();
            c = keep.iter().map(|&i| c[i]).collect();
            gram.restrict(&keep);
            solver.renumber_passive();
        }

        residual(data, &selected, &w, &mut r);
        let new_error = norm(&r) / b_norm;
        if new_error < error * (1.0 - 1e-12) {
            stalls = 0;
        } else {
            stalls += 1;
        }
        error = new_error;
        curve.push((selected.len(), error));
        let elements: Vec<usize> = selected.iter().map(|&c| data.element_of(c)).collect();
        progress(&FitProgress {
            step,
            elements: selected.len(),
            relative_error: error,
            budget,
            selected: &elements,
            weights: &w,
        });
        if stalls >= MAX_STALLS {
            tracing::debug!(step, "cubature error stopped decreasing");
            break;
        }
    }

    let selected: Vec<usize> = selected.iter().map(|&c| data.element_of(c)).collect();
    let mut order: Vec<usize> = (0..selected.len()).collect();
    order.sort_unstable_by_key(|&i| selected[i]);
    let rule = CubatureRule {
        elements: order.iter().map(|&i| selected[i]).collect(),
        weights: order.iter().map(|&i| w[i]).collect(),
        training_error: error,
        tolerance_met: error <= config.tolerance,
        error_curve: curve,
    };
    tracing::info!(
        elements = rule.len(),
        of = data.num_elements(),
        candidates = m,
        training_error = rule.training_error,
        tolerance = config.tolerance,
        steps = step,
        "cubature fitted"
    );
    Ok(rule)
}

/// Position in `candidates` of the element with the largest positive score (first on ties).
fn best_aligned(candidates: &[usize], score: &(impl Fn(usize) -> f64 + Sync)) -> Option<usize> {
    let scores: Vec<f64> = candidates.par_iter().map(|&e| score(e)).collect();
    let mut best: Option<(usize, f64)> = None;
    for (i, &s) in scores.iter().enumerate() {
        if s > 0.0 && best.is_none_or(|(_, bs)| s > bs) {
            best = Some((i, s));
        }
    }
    best.map(|(i, _)| i)
}

/// r = b − Σ_j w_j a_{S_j}, in parallel over blocks of rows (fixed summation order).
fn residual(data: &TrainingMatrix, selected: &[usize], w: &[f64], r: &mut [f64]) {
    let b = data.b();
    r.par_chunks_mut(ROW_BLOCK)
        .enumerate()
        .for_each(|(blk, out)| {
            let r0 = blk * ROW_BLOCK;
            out.copy_from_slice(&b[r0..r0 + out.len()]);
            for (&e, &we) in selected.iter().zip(w) {
                let a = &data.column(e)[r0..r0 + out.len()];
                for (o, x) in out.iter_mut().zip(a) {
                    *o -= we * x;
                }
            }
        });
}

/// The symmetric Gram matrix G_SS, column-major with spare capacity so it grows in place.
#[derive(Debug, Default)]
struct Gram {
    n: usize,
    stride: usize,
    data: Vec<f64>,
}

impl Gram {
    fn view(&self) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice_with_stride(&self.data, self.n, self.n, self.stride.max(1))
    }

    /// Appends row and column n from `col` = G[0..=n, n].
    fn push(&mut self, col: &[f64]) {
        let n = self.n;
        debug_assert_eq!(col.len(), n + 1);
        if n + 1 > self.stride {
            let stride = (2 * self.stride).max(16);
            let mut data = vec![0.0; stride * stride];
            for j in 0..n {
                data[j * stride..j * stride + n]
                    .copy_from_slice(&self.data[j * self.stride..j * self.stride + n]);
            }
            (self.stride, self.data) = (stride, data);
        }
        let st = self.stride;
        for (i, &v) in col.iter().enumerate() {
            self.data[n * st + i] = v;
            self.data[i * st + n] = v;
        }
        self.n = n + 1;
    }

    /// Keeps rows and columns `keep`, in that order.
    fn restrict(&mut self, keep: &[usize]) {
        let st = self.stride;
        let old: Vec<f64> = self.data[..self.n * st].to_vec();
        for (jn, &jo) in keep.iter().enumerate() {
            for (i_new, &io) in keep.iter().enumerate() {
                self.data[jn * st + i_new] = old[jo * st + io];
            }
        }
        self.n = keep.len();
    }
}
