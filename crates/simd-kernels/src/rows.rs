//! Row kernels under `pulp`'s SIMD dispatch, shared by `nn`'s single-vector kernels and
//! `latent-sim`'s per-element products: call them from inside a [`pulp::WithSimd`] body so that
//! they are compiled with its target features (both are `#[inline(always)]`).
//!
//! Each output element is one fixed sequence of operations: a vector accumulator over the
//! full-width SIMD chunks (fused multiply–adds in column order), then the columns past the last
//! full chunk in order. So results do not depend on how callers group rows.

use pulp::Simd;

/// The dot products of R rows (each at least as long as x) with x: one vector accumulator per
/// row over the full SIMD chunks of x, summed across lanes, then the remaining entries in order.
#[inline(always)]
pub fn dot_rows<S: Simd, const R: usize>(simd: S, rows: [&[f64]; R], x: &[f64]) -> [f64; R] {
    let (xv, xt) = S::as_simd_f64s(x);
    let n = xv.len();
    let split: [(&[S::f64s], &[f64]); R] = std::array::from_fn(|r| {
        let (head, tail) = S::as_simd_f64s(&rows[r][..x.len()]);
        (&head[..n], tail)
    });
    let mut acc = [simd.splat_f64s(0.0); R];
    for (c, &x) in xv.iter().enumerate() {
        for r in 0..R {
            acc[r] = simd.mul_add_e_f64s(split[r].0[c], x, acc[r]);
        }
    }
    std::array::from_fn(|r| {
        let mut s = simd.reduce_sum_f64s(acc[r]);
        for (w, x) in split[r].1.iter().zip(xt) {
            s += w * x;
        }
        s
    })
}

/// out += Σ_r c_r rows_r (every row at least as long as `out`), in one pass over `out`: each
/// element gets the rows' contributions in row order.
#[inline(always)]
pub fn add_combination<S: Simd, const R: usize>(
    simd: S,
    out: &mut [f64],
    c: [f64; R],
    rows: [&[f64]; R],
) {
    let len = out.len();
    let (ov, ot) = S::as_mut_simd_f64s(out);
    let n = ov.len();
    let split: [(&[S::f64s], &[f64]); R] = std::array::from_fn(|r| {
        let (head, tail) = S::as_simd_f64s(&rows[r][..len]);
        (&head[..n], tail)
    });
    let cs = c.map(|x| simd.splat_f64s(x));
    for (k, o) in ov.iter_mut().enumerate() {
        let mut acc = *o;
        for r in 0..R {
            acc = simd.mul_add_e_f64s(cs[r], split[r].0[k], acc);
        }
        *o = acc;
    }
    for (k, o) in ot.iter_mut().enumerate() {
        for r in 0..R {
            *o += c[r] * split[r].1[k];
        }
    }
}
