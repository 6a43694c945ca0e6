//! The dense matrix products of batches (training), on plain slices, through faer's matmul (which
//! dispatches to AVX2/AVX-512 kernels at run time). Weights are row-major `m × n` (one output
//! neuron per contiguous row); activations, tangents and gradients are column-major `n × c`
//! blocks (one sample or tangent direction per contiguous column). Always sequential: callers
//! parallelise over independent sample chunks instead. The products of single inputs (forward,
//! derivatives, Jacobian) are in [`crate::kernels`].

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

/// dst (m × c) = W (m × n) · X (n × c).
pub(crate) fn mul_w(dst: &mut [f64], w: &[f64], x: &[f64], m: usize, n: usize, c: usize) {
    let w = MatRef::from_row_major_slice(&w[..m * n], m, n);
    let x = MatRef::from_column_major_slice(&x[..n * c], n, c);
    let dst = MatMut::from_column_major_slice_mut(&mut dst[..m * c], m, c);
    matmul(dst, Accum::Replace, w, x, 1.0, Par::Seq);
}

/// dst (n × c) = Wᵀ (n × m) · G (m × c), with W stored as (m × n).
pub(crate) fn mul_wt(dst: &mut [f64], w: &[f64], g: &[f64], m: usize, n: usize, c: usize) {
    let wt = MatRef::from_row_major_slice(&w[..m * n], m, n).transpose();
    let g = MatRef::from_column_major_slice(&g[..m * c], m, c);
    let dst = MatMut::from_column_major_slice_mut(&mut dst[..n * c], n, c);
    matmul(dst, Accum::Replace, wt, g, 1.0, Par::Seq);
}

/// dW (rows × n, row-major) = G[row0..row0 + rows] (rows × c) · Xᵀ (c × n), or `+=` with
/// `accumulate`: rows of the weight gradient of a batch, G being m × c.
pub(crate) fn mul_outer_rows(
    dw: &mut [f64],
    g: &[f64],
    x: &[f64],
    m: usize,
    row0: usize,
    rows: usize,
    n: usize,
    c: usize,
    accumulate: bool,
) {
    let g = MatRef::from_column_major_slice(&g[..m * c], m, c).subrows(row0, rows);
    let xt = MatRef::from_column_major_slice(&x[..n * c], n, c).transpose();
    let dw = MatMut::from_row_major_slice_mut(&mut dw[..rows * n], rows, n);
    let accum = if accumulate {
        Accum::Add
    } else {
        Accum::Replace
    };
    matmul(dw, accum, g, xt, 1.0, Par::Seq);
}
