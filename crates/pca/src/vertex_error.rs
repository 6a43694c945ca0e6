//! The per-vertex reconstruction error and the incremental scan over k that selects the basis
//! dimension by it.
//!
//! From the thin SVD M^{1/2}S = Ũ Σ Vᵀ and U = M^{-1/2}Ũ, the projection coefficients of snapshot j
//! are (UᵀM s_j)_i = σ_i V_{ji}, so the residual after k modes is
//!
//! R_k = S − Σ_{i<k} σ_i u_i v_iᵀ,   R_k = R_{k−1} − σ_{k−1} u_{k−1} v_{k−1}ᵀ.
//!
//! Each step is one rank-one update, O(n·N), after which the largest vertex norm of R_k is read
//! off (the maximum is taken tile by tile, so the update and the norms share one pass). The scan
//! applies `K_BLOCK` modes per pass over R and processes snapshot columns in parallel.

use rayon::prelude::*;

/// Modes applied per pass over the residual: enough to amortise streaming R through memory, few
/// enough not to overshoot the answer by much.
const K_BLOCK: usize = 16;
/// Snapshot columns per parallel task.
const COLS_PER_TASK: usize = 8;
/// Rows per tile (rounded down to whole vertices): a tile of R per column plus K_BLOCK tiles of U
/// fit in L1/L2.
const ROWS_PER_TILE: usize = 384;

/// max_v ‖r_v‖₂² over the vertices of one column (`group` consecutive rows per vertex).
pub(crate) fn max_group_norm_sq(column: &[f64], group: usize) -> f64 {
    column
        .chunks_exact(group)
        .map(|g| g.iter().map(|x| x * x).sum::<f64>())
        .fold(0.0, f64::max)
}

/// r ← r − c·u, returning the largest squared vertex norm of the updated r.
fn subtract_and_max(r: &mut [f64], u: &[f64], c: f64, group: usize) -> f64 {
    // Compile-time group sizes let the per-vertex loop unroll and vectorise; 3 is the common case.
    match group {
        1 => subtract_and_max_fixed::<1, 4>(r, u, c),
        2 => subtract_and_max_fixed::<2, 8>(r, u, c),
        3 => subtract_and_max_fixed::<3, 12>(r, u, c),
        _ => subtract_and_max_any(r, u, c, group),
    }
}

/// [`subtract_and_max`] for groups of `G` rows, four vertices (`B = 4·G` rows) per step with
/// independent running maxima: one running maximum is a dependency chain that stalls the loop.
fn subtract_and_max_fixed<const G: usize, const B: usize>(r: &mut [f64], u: &[f64], c: f64) -> f64 {
    debug_assert_eq!(B, 4 * G);
    let mut worst = [0.0f64; 4];
    let mut r_blocks = r.chunks_exact_mut(B);
    let mut u_blocks = u.chunks_exact(B);
    for (rb, ub) in (&mut r_blocks).zip(&mut u_blocks) {
        let mut sq = [0.0f64; B];
        for d in 0..B {
            rb[d] -= c * ub[d];
            sq[d] = rb[d] * rb[d];
        }
        for (v, w) in worst.iter_mut().enumerate() {
            let norm_sq: f64 = sq[v * G..(v + 1) * G].iter().sum();
            *w = w.max(norm_sq);
        }
    }
    let tail = subtract_and_max_any(r_blocks.into_remainder(), u_blocks.remainder(), c, G);
    worst.into_iter().fold(tail, f64::max)
}

/// [`subtract_and_max`] for any group size.
fn subtract_and_max_any(r: &mut [f64], u: &[f64], c: f64, group: usize) -> f64 {
    let mut worst = 0.0f64;
    for (rv, uv) in r.chunks_exact_mut(group).zip(u.chunks_exact(group)) {
        let mut norm_sq = 0.0;
        for (x, y) in rv.iter_mut().zip(uv) {
            *x -= c * y;
            norm_sq += *x * *x;
        }
        worst = worst.max(norm_sq);
    }
    worst
}

/// What the scan found.
#[derive(Debug)]
pub(crate) struct Scan {
    /// max over vertices and snapshots of the reconstruction distance for k = 1, 2, … (as far as
    /// the scan went).
    pub per_k: Vec<f64>,
    /// The smallest k at which `stop` held, if any k ≤ the number of modes given did.
    pub chosen: Option<usize>,
    /// The basis columns formed so far (at least `per_k.len()` of them), column-major.
    pub basis: Vec<f64>,
}

/// Scans k = 1..=`modes` and stops at the first k for which `stop(k, error)` holds (e.g. the
/// maximum vertex error is within a tolerance).
///
/// * `snapshots`: S, n × N.
/// * `columns(start, count)`: columns `start..start + count` of U, column-major. They are asked
///   for block by block, so memory grows with the k reached, not with `modes`.
/// * `coefficient(j, i)`: the coefficient of column i in snapshot j: σ_i V_{ji} for the SVD's
///   modes, (UᵀM s_j)_i for any M-orthonormal columns.
pub(crate) fn scan_max_vertex_error(
    snapshots: faer::MatRef<'_, f64>,
    modes: usize,
    columns: impl Fn(usize, usize) -> Vec<f64>,
    coefficient: impl Fn(usize, usize) -> f64 + Sync,
    group: usize,
    stop: impl Fn(usize, f64) -> bool,
) -> Scan {
    let n = snapshots.nrows();
    let mut residual: Vec<f64> = Vec::with_capacity(n * snapshots.ncols());
    for col in snapshots.col_iter() {
        residual.extend(col.iter());
    }
    let rows_per_tile = (ROWS_PER_TILE / group).max(1) * group;
    let mut per_k = Vec::with_capacity(modes);
    let mut basis: Vec<f64> = Vec::new();
    let mut k0 = 0;
    while k0 < modes {
        let kc = K_BLOCK.min(modes - k0);
        basis.extend(columns(k0, kc));
        let formed = &basis;
        // Each task owns a few snapshot columns and walks them in row tiles, so the tiles of R and
        // of the K_BLOCK basis columns stay in L1/L2 while every update of the block is applied:
        // R is streamed once per block, not once per mode.
        let block_max = residual
            .par_chunks_mut(n * COLS_PER_TASK)
            .enumerate()
            .fold(
                || [0.0f64; K_BLOCK],
                |mut acc, (task, cols)| {
                    let ncols = cols.len() / n;
                    let mut coeff = [[0.0f64; K_BLOCK]; COLS_PER_TASK];
                    for (c, row) in coeff.iter_mut().enumerate().take(ncols) {
                        for (t, x) in row.iter_mut().enumerate().take(kc) {
                            *x = coefficient(task * COLS_PER_TASK + c, k0 + t);
                        }
                    }
                    let mut start = 0;
                    while start < n {
                        let end = (start + rows_per_tile).min(n);
                        for (c, col) in cols.chunks_exact_mut(n).enumerate() {
                            let r = &mut col[start..end];
                            for t in 0..kc {
                                let i = k0 + t;
                                let u = &formed[i * n + start..i * n + end];
                                let worst = subtract_and_max(r, u, coeff[c][t], group);
                                acc[t] = acc[t].max(worst);
                            }
                        }
                        start = end;
                    }
                    acc
                },
            )
            .reduce(
                || [0.0f64; K_BLOCK],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(b) {
                        *x = x.max(y);
                    }
                    a
                },
            );
        for (t, &worst_sq) in block_max.iter().take(kc).enumerate() {
            let worst = worst_sq.sqrt();
            per_k.push(worst);
            if stop(k0 + t + 1, worst) {
                return Scan {
                    per_k,
                    chosen: Some(k0 + t + 1),
                    basis,
                };
            }
        }
        k0 += kc;
    }
    Scan {
        per_k,
        chosen: None,
        basis,
    }
}
