//! Forward and back substitution, L Lᵀ x = b in place, with a supernodal factor of faer's
//! symbolic analysis whose values are stored in f64, f32 or 16 bits ([`Stored`]); the arithmetic
//! is f64 throughout.
//!
//! Hand-written rather than faer's solve, which reads a factor only in its own precision and
//! takes a workspace per call: on the catapult (9.7k DOFs, 1.6 M values in L, one thread) faer's
//! solve took 1.3–1.5 ms, this one 1.0–1.1 ms with the f64 factor (agreeing to 3e-19) and
//! 0.73–0.79 ms with the f32 one; on a 30k-DOF beam (11.8 M values) 13.7 ms in f64 and 10.1 ms
//! with f32 values (`cargo bench -p benches --bench fem -- sparse`). Multiplying by each column's
//! reciprocal diagonal instead of dividing took the catapult's 16-bit solve from 736 to 660 µs.

use faer::sparse::linalg::cholesky::SymbolicCholesky;
use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

#[cfg(target_arch = "x86_64")]
use super::kernels::Avx2;
use super::kernels::{Lanes, Portable};
use super::storage::Stored;

/// Which inner loops a supernodal solve runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kernels {
    /// AVX2 + FMA where the CPU has them, the portable loops otherwise.
    Best,
    /// The portable loops (what CPUs without AVX2 run; tests compare the two).
    #[cfg_attr(not(test), allow(dead_code))]
    Portable,
}

/// L Lᵀ x = b for a supernodal L, in place, with AVX2 + FMA where the CPU has them. With
/// `scaling` the stored factor is L̂ = L Σ for a diagonal Σ, and L Lᵀ = L̂ Σ⁻² L̂ᵀ is solved by
/// multiplying by Σ² (`scaling`, per column) between the two passes.
pub(super) fn supernodal_solve<V: Stored>(
    symbolic: &SymbolicSupernodalCholesky<usize>,
    values: &[V],
    inv_diag: &[f64],
    scaling: Option<&[f64]>,
    x: &mut [f64],
    rows: &mut [f64],
    kernels: Kernels,
) {
    #[cfg(target_arch = "x86_64")]
    if kernels == Kernels::Best
        && let Some(v3) = pulp::x86::V3::try_new()
    {
        return v3.vectorize(|| substitute(Avx2(v3), symbolic, values, inv_diag, scaling, x, rows));
    }
    substitute(Portable, symbolic, values, inv_diag, scaling, x, rows)
}

/// 1 / L_jj for every column j of a supernodal factor stored as `values` (in the factor's
/// order; empty for a simplicial factor).
pub(super) fn reciprocal_diagonal<V: Stored>(
    symbolic: &SymbolicCholesky<usize>,
    values: &[V],
    out: &mut Vec<f64>,
) {
    out.clear();
    let SymbolicCholeskyRaw::Supernodal(symbolic) = symbolic.raw() else {
        return;
    };
    for s in 0..symbolic.n_supernodes() {
        let b = SupernodeBlock::new(symbolic, s);
        let l = &values[b.values];
        out.extend((0..b.m).map(|j| 1.0 / l[j * b.ld + j].widen()));
    }
}

/// Where supernode s of a supernodal factor lies: its first column `c0`, its `m` columns, its
/// row `pattern` below the diagonal block, the block's leading dimension `ld = m + p`, and the
/// range of its `ld × m` values in the factor's value array.
pub(super) struct SupernodeBlock<'a> {
    pub(super) c0: usize,
    pub(super) m: usize,
    pub(super) pattern: &'a [usize],
    pub(super) ld: usize,
    pub(super) values: std::ops::Range<usize>,
}

impl<'a> SupernodeBlock<'a> {
    pub(super) fn new(symbolic: &'a SymbolicSupernodalCholesky<usize>, s: usize) -> Self {
        let c0 = symbolic.supernode_begin()[s];
        let m = symbolic.supernode_end()[s] - c0;
        let pattern = symbolic.supernode(s).pattern();
        let ld = m + pattern.len();
        let start = symbolic.col_ptr_for_val()[s];
        Self {
            c0,
            m,
            pattern,
            ld,
            values: start..start + ld * m,
        }
    }
}

/// Supernode s owns columns `c0..c0 + m` of L as one column-major block: its m × m
/// lower-triangular diagonal block on top of the rows `pattern` (p of them, all past the block).
///
/// Forward: the diagonal block's triangular solve, then the p rows' update gathered in `rows`
/// (four columns per pass over them) and scattered once. Backward, in reverse: the p rows
/// gathered, each column's dot product with them, then the transposed triangular solve. Each
/// pass reads every stored value of L once.
#[inline(always)]
fn substitute<K: Lanes, V: Stored>(
    k: K,
    symbolic: &SymbolicSupernodalCholesky<usize>,
    values: &[V],
    inv_diag: &[f64],
    scaling: Option<&[f64]>,
    x: &mut [f64],
    rows: &mut [f64],
) {
    let count = symbolic.n_supernodes();
    let block = |s: usize| {
        let b = SupernodeBlock::new(symbolic, s);
        (b.c0, b.m, b.pattern, b.ld, &values[b.values])
    };
    for s in 0..count {
        let (c0, m, pattern, ld, l) = block(s);
        let top = &mut x[c0..c0 + m];
        let inv = &inv_diag[c0..c0 + m];
        for j in 0..m {
            let col = &l[j * ld..j * ld + m];
            let xj = top[j] * inv[j];
            top[j] = xj;
            k.axpy(&mut top[j + 1..], &col[j + 1..], -xj);
        }
        let p = pattern.len();
        if p == 0 {
            continue;
        }
        let acc = &mut rows[..p];
        acc.fill(0.0);
        let mut j = 0;
        while j + 4 <= m {
            let c = std::array::from_fn(|i| &l[(j + i) * ld + m..(j + i + 1) * ld]);
            k.axpy4(acc, c, [top[j], top[j + 1], top[j + 2], top[j + 3]]);
            j += 4;
        }
        for j in j..m {
            k.axpy(acc, &l[j * ld + m..(j + 1) * ld], top[j]);
        }
        for (&r, &a) in pattern.iter().zip(acc.iter()) {
            x[r] -= a;
        }
    }
    if let Some(scaling) = scaling {
        for (x, s) in x.iter_mut().zip(scaling) {
            *x *= s;
        }
    }
    for s in (0..count).rev() {
        let (c0, m, pattern, ld, l) = block(s);
        let p = pattern.len();
        let gathered = &mut rows[..p];
        for (g, &r) in gathered.iter_mut().zip(pattern) {
            *g = x[r];
        }
        let top = &mut x[c0..c0 + m];
        if p > 0 {
            for (j, t) in top.iter_mut().enumerate() {
                *t -= k.dot(&l[j * ld + m..(j + 1) * ld], gathered);
            }
        }
        let inv = &inv_diag[c0..c0 + m];
        for j in (0..m).rev() {
            let col = &l[j * ld..j * ld + m];
            let (head, tail) = top.split_at_mut(j + 1);
            head[j] = (head[j] - k.dot(&col[j + 1..], tail)) * inv[j];
        }
    }
}
