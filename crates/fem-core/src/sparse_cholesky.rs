//! Sparse Cholesky factorisation A = LLᵀ of the free-DOF system matrices (the projected Hessian
//! plus M/h² and spring stiffness), all sharing one [`HessianPattern`]: the fill-reducing ordering
//! and symbolic analysis are done once per mesh, each numeric factorisation refills one buffer.

use std::cell::RefCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::SparseColMatRef;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::{Conj, Par, Side};

use crate::FemError;
use crate::sparse::HessianPattern;

/// Sparse LLᵀ of matrices with one [`HessianPattern`]: the symbolic analysis (AMD ordering) once,
/// numeric factorisations into a factor buffer that is reused.
///
/// faer's high-level `Llt` factorises with its global parallelism, every rayon thread by default.
/// On 2 cores its parallel supernodal factorisation measured 1.4–2× slower than the sequential
/// one (catapult, 9.7k DOFs: 45–68 ms against 25–33 ms; a 27k-DOF beam: 360–440 ms against
/// 280–330 ms), so pools of up to [`SEQUENTIAL_FACTOR_THREADS`] threads factorise sequentially;
/// larger pools keep faer's parallel default.
///
/// Solves with a supernodal factor run this module's own kernels (one vector, no workspace
/// allocation after a thread's first solve); a simplicial factor (small or very sparse
/// matrices) is solved by faer.
#[derive(Debug, Clone)]
pub struct SparseCholesky {
    symbolic: Arc<SymbolicCholesky<usize>>,
    /// The f64 factor's values.
    l: Vec<f64>,
    /// The f32 factor's values ([`SparseCholesky::factor_for_preconditioning`]).
    l_single: Vec<f32>,
    /// The matrix rounded to f32, the f32 factorisation's input.
    a_single: Vec<f32>,
    /// Set once an f32 factor failed its check: factors sharing this analysis then go straight
    /// to f64 (the matrices one simulation factorises share their mesh and mass term, and so
    /// largely their conditioning), instead of paying for a rejected f32 factor each time.
    single_rejected: Arc<AtomicBool>,
    /// The longest row pattern of a supernode (the solves' gather buffer), 0 when simplicial.
    max_pattern: usize,
    factored: Factored,
}

/// Which factor the last factorisation left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Factored {
    /// None: never factorised, or the last factorisation failed.
    No,
    Double,
    Single,
}

/// Largest error max|x − x₀| (for |x₀| ≤ 1) of an f32 factor's check solve that
/// [`SparseCholesky::factor_for_preconditioning`] accepts.
pub const SINGLE_FACTOR_TOLERANCE: f64 = 1e-3;

/// Largest rayon pool in which sparse factorisations run sequentially.
pub const SEQUENTIAL_FACTOR_THREADS: usize = 2;

fn factor_parallelism() -> Par {
    if rayon::current_num_threads() <= SEQUENTIAL_FACTOR_THREADS {
        Par::Seq
    } else {
        Par::rayon(0)
    }
}

thread_local! {
    /// The permuted right-hand side and one supernode's gathered rows, per thread.
    static SOLVE_SCRATCH: RefCell<Vec<f64>> = const { RefCell::new(Vec::new()) };
}

impl SparseCholesky {
    /// Symbolic analysis of `pattern`'s lower triangle; faer picks a simplicial or supernodal
    /// factor from the predicted work.
    pub fn analyse(pattern: &HessianPattern) -> Result<Self, FemError> {
        Self::analyse_with(pattern, Default::default())
    }

    fn analyse_with(
        pattern: &HessianPattern,
        params: faer::sparse::linalg::cholesky::CholeskySymbolicParams<'_>,
    ) -> Result<Self, FemError> {
        let symbolic = factorize_symbolic_cholesky(
            pattern.symbolic.as_ref(),
            Side::Lower,
            SymmetricOrdering::Amd,
            params,
        )
        .map_err(|e| FemError::Factorization(format!("symbolic analysis: {e:?}")))?;
        let max_pattern = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => (0..s.n_supernodes())
                .map(|k| s.supernode(k).pattern().len())
                .max()
                .unwrap_or(0),
            SymbolicCholeskyRaw::Simplicial(_) => 0,
        };
        Ok(Self {
            l: vec![0.0; symbolic.len_val()],
            symbolic: Arc::new(symbolic),
            l_single: Vec::new(),
            a_single: Vec::new(),
            single_rejected: Arc::new(AtomicBool::new(false)),
            max_pattern,
            factored: Factored::No,
        })
    }

    /// An empty factor sharing this one's symbolic analysis.
    pub fn same_pattern(&self) -> Self {
        Self {
            symbolic: Arc::clone(&self.symbolic),
            l: vec![0.0; self.l.len()],
            l_single: Vec::new(),
            a_single: Vec::new(),
            single_rejected: Arc::clone(&self.single_rejected),
            max_pattern: self.max_pattern,
            factored: Factored::No,
        }
    }

    /// Number of stored values of L.
    pub fn factor_nnz(&self) -> usize {
        self.l.len()
    }

    /// Whether the analysis chose a supernodal factor (solved by this module's kernels).
    pub fn is_supernodal(&self) -> bool {
        matches!(self.symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_))
    }

    /// Factorises `a` (same pattern as the analysis; the lower triangle is read). On failure
    /// (not positive definite) the factor is unusable until the next successful call.
    pub fn factor(&mut self, a: SparseColMatRef<'_, usize, f64>) -> Result<(), FemError> {
        self.factored = Factored::No;
        factorize(&self.symbolic, &mut self.l, a)?;
        self.factored = Factored::Double;
        Ok(())
    }

    /// Factorises `a` for [`SparseCholesky::solve_preconditioner_in_place`]: in f32 when the
    /// factor is supernodal and the f32 factor passes a check, in f64 otherwise. Returns whether
    /// f32 served.
    ///
    /// An f32 factor is faster to compute (twice the SIMD lanes: 18 → 16 ms on the catapult,
    /// 230 → 156 ms on a 30k-DOF beam, check included) and halves the solves' memory traffic,
    /// and L̃L̃ᵀ is an exact factorisation of an SPD matrix near A: right for a preconditioner,
    /// which approximates a Hessian anyway. The check solves A x = A x₀ for a fixed x₀ with
    /// entries in [-1, 1] and accepts the f32 factor when max|x − x₀| ≤
    /// [`SINGLE_FACTOR_TOLERANCE`], so a matrix whose conditioning f32 cannot carry gets its f64
    /// factor, as do all later ones sharing this analysis; a failed f32 factorisation counts as
    /// a rejection. The check costs one product with A and one solve, a few percent of the
    /// factorisation. After an f32 factorisation [`SparseCholesky::solve_in_place`] is
    /// unavailable until the next [`SparseCholesky::factor`].
    pub fn factor_for_preconditioning(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
    ) -> Result<bool, FemError> {
        if self.is_supernodal() && !self.single_rejected.load(Ordering::Relaxed) {
            self.factored = Factored::No;
            self.a_single.clear();
            self.a_single.extend(a.val().iter().map(|&v| v as f32));
            self.l_single.resize(self.l.len(), 0.0);
            let single = SparseColMatRef::new(a.symbolic(), &self.a_single);
            if factorize(&self.symbolic, &mut self.l_single, single).is_ok() {
                self.factored = Factored::Single;
                let n = a.ncols();
                let x0: Vec<f64> = (0..n)
                    .map(|i| 2.0 * (i as f64 * 0.618_033_988_749_895).fract() - 1.0)
                    .collect();
                let mut x = vec![0.0; n];
                symmetric_lower_product(a, &x0, &mut x);
                self.solve_preconditioner_in_place(&mut x);
                let err = x
                    .iter()
                    .zip(&x0)
                    .fold(0.0f64, |m, (x, x0)| m.max((x - x0).abs()));
                if err <= SINGLE_FACTOR_TOLERANCE {
                    return Ok(true);
                }
            }
            self.single_rejected.store(true, Ordering::Relaxed);
        }
        self.factor(a).map(|()| false)
    }

    /// x ← A⁻¹ x with the last A factorised by [`SparseCholesky::factor`].
    ///
    /// # Panics
    /// If the last factorisation was not a successful [`SparseCholesky::factor`].
    pub fn solve_in_place(&self, x: &mut [f64]) {
        assert!(
            self.factored == Factored::Double,
            "exact solve without an f64 factorisation"
        );
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => self.permuted_solve(s, &self.l, x, Kernels::Best),
            SymbolicCholeskyRaw::Simplicial(_) => self.faer_solve_in_place(x, factor_parallelism()),
        }
    }

    /// faer's own solve with the f64 factor (simplicial factors; tests compare it with the
    /// supernodal kernels).
    fn faer_solve_in_place(&self, x: &mut [f64], par: Par) {
        let n = x.len();
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(1, par));
        LltRef::new(&self.symbolic, &self.l).solve_in_place_with_conj(
            Conj::No,
            faer::MatMut::from_column_major_slice_mut(x, n, 1),
            par,
            MemStack::new(&mut mem),
        );
    }

    /// x ← (L̃L̃ᵀ)⁻¹ x with whichever factor the last factorisation left, f32 (arithmetic in f64)
    /// or f64.
    ///
    /// # Panics
    /// If no factorisation has succeeded.
    pub fn solve_preconditioner_in_place(&self, x: &mut [f64]) {
        match (self.factored, self.symbolic.raw()) {
            (Factored::Single, SymbolicCholeskyRaw::Supernodal(s)) => {
                self.permuted_solve(s, &self.l_single, x, Kernels::Best)
            }
            _ => self.solve_in_place(x),
        }
    }

    /// Forward and back substitution with a supernodal factor stored as `values`, in the
    /// analysis's fill-reducing order.
    fn permuted_solve<V: Stored>(
        &self,
        symbolic: &SymbolicSupernodalCholesky<usize>,
        values: &[V],
        x: &mut [f64],
        kernels: Kernels,
    ) {
        let n = x.len();
        assert_eq!(n, symbolic.nrows(), "right-hand side length");
        SOLVE_SCRATCH.with_borrow_mut(|scratch| {
            scratch.resize(n + self.max_pattern, 0.0);
            let (y, rows) = scratch.split_at_mut(n);
            match self.symbolic.perm() {
                Some(perm) => {
                    let fwd = perm.arrays().0;
                    for (yi, &f) in y.iter_mut().zip(fwd) {
                        *yi = x[f];
                    }
                    supernodal_solve(symbolic, values, y, rows, kernels);
                    for (yi, &f) in y.iter().zip(fwd) {
                        x[f] = *yi;
                    }
                }
                None => supernodal_solve(symbolic, values, x, rows, kernels),
            }
        });
    }
}

/// Numeric LLᵀ of `a` into `l` (f64 or f32) with `symbolic`'s analysis.
fn factorize<T: faer::traits::RealField>(
    symbolic: &SymbolicCholesky<usize>,
    l: &mut [T],
    a: SparseColMatRef<'_, usize, T>,
) -> Result<(), FemError> {
    let par = factor_parallelism();
    let mut mem =
        MemBuffer::try_new(symbolic.factorize_numeric_llt_scratch::<T>(par, Default::default()))
            .map_err(|e| FemError::Factorization(format!("workspace: {e:?}")))?;
    symbolic
        .factorize_numeric_llt::<T>(
            l,
            a,
            Side::Lower,
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .map(|_| ())
        .map_err(|e| FemError::Factorization(format!("{e:?}")))
}

/// y = A x for symmetric A given by (at least) its lower triangle: entries above the diagonal
/// are skipped.
fn symmetric_lower_product(a: SparseColMatRef<'_, usize, f64>, x: &[f64], y: &mut [f64]) {
    y.fill(0.0);
    let (cp, ri, v) = (a.col_ptr(), a.row_idx(), a.val());
    for j in 0..a.ncols() {
        for k in cp[j]..cp[j + 1] {
            let i = ri[k];
            if i > j {
                y[i] += v[k] * x[j];
                y[j] += v[k] * x[i];
            } else if i == j {
                y[j] += v[k] * x[j];
            }
        }
    }
}

/// Which inner loops a supernodal solve runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kernels {
    /// AVX2 + FMA where the CPU has them, the portable loops otherwise.
    Best,
    /// The portable loops (what CPUs without AVX2 run; tests compare the two).
    #[cfg_attr(not(test), allow(dead_code))]
    Portable,
}

/// L Lᵀ x = b for a supernodal L, in place, with AVX2 + FMA where the CPU has them.
fn supernodal_solve<V: Stored>(
    symbolic: &SymbolicSupernodalCholesky<usize>,
    values: &[V],
    x: &mut [f64],
    rows: &mut [f64],
    kernels: Kernels,
) {
    #[cfg(target_arch = "x86_64")]
    if kernels == Kernels::Best
        && let Some(v3) = pulp::x86::V3::try_new()
    {
        return v3.vectorize(|| substitute(Avx2(v3), symbolic, values, x, rows));
    }
    substitute(Portable, symbolic, values, x, rows)
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
    x: &mut [f64],
    rows: &mut [f64],
) {
    let begin = symbolic.supernode_begin();
    let end = symbolic.supernode_end();
    let val_ptr = symbolic.col_ptr_for_val();
    let count = symbolic.n_supernodes();
    let block = |s: usize| {
        let (c0, m) = (begin[s], end[s] - begin[s]);
        let pattern = symbolic.supernode(s).pattern();
        let ld = m + pattern.len();
        (c0, m, pattern, ld, &values[val_ptr[s]..val_ptr[s] + ld * m])
    };
    for s in 0..count {
        let (c0, m, pattern, ld, l) = block(s);
        let top = &mut x[c0..c0 + m];
        for j in 0..m {
            let col = &l[j * ld..j * ld + m];
            let xj = top[j] / col[j].into();
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
        for j in (0..m).rev() {
            let col = &l[j * ld..j * ld + m];
            let (head, tail) = top.split_at_mut(j + 1);
            head[j] = (head[j] - k.dot(&col[j + 1..], tail)) / col[j].into();
        }
    }
}

/// How L's values are stored: f64, or rounded to f32 (widened to f64 as they are read).
trait Stored: Copy + Into<f64> {
    /// Four consecutive values as f64 lanes.
    #[cfg(target_arch = "x86_64")]
    fn load4(v3: pulp::x86::V3, v: &[Self]) -> pulp::f64x4;
}

impl Stored for f64 {
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(_: pulp::x86::V3, v: &[f64]) -> pulp::f64x4 {
        let v: &[f64; 4] = v[..4].try_into().expect("four values");
        pulp::cast(*v)
    }
}

impl Stored for f32 {
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(v3: pulp::x86::V3, v: &[f32]) -> pulp::f64x4 {
        let v: &[f32; 4] = v[..4].try_into().expect("four values");
        v3.convert_f32x4_to_f64x4(pulp::cast(*v))
    }
}

/// The substitution's inner loops: `y += a·x` for one and for four columns, and a dot product.
trait Lanes: Copy {
    fn axpy<V: Stored>(self, y: &mut [f64], x: &[V], a: f64);
    fn axpy4<V: Stored>(self, y: &mut [f64], x: [&[V]; 4], a: [f64; 4]);
    fn dot<V: Stored>(self, a: &[V], b: &[f64]) -> f64;
}

/// Scalar loops, for CPUs without AVX2.
#[derive(Clone, Copy)]
struct Portable;

impl Lanes for Portable {
    #[inline(always)]
    fn axpy<V: Stored>(self, y: &mut [f64], x: &[V], a: f64) {
        for (y, &x) in y.iter_mut().zip(x) {
            *y += x.into() * a;
        }
    }

    #[inline(always)]
    fn axpy4<V: Stored>(self, y: &mut [f64], x: [&[V]; 4], a: [f64; 4]) {
        for (i, y) in y.iter_mut().enumerate() {
            *y += x[0][i].into() * a[0]
                + x[1][i].into() * a[1]
                + x[2][i].into() * a[2]
                + x[3][i].into() * a[3];
        }
    }

    #[inline(always)]
    fn dot<V: Stored>(self, a: &[V], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(&a, &b)| a.into() * b).sum()
    }
}

/// Four-lane fused multiply–adds; only built inside [`pulp::x86::V3::vectorize`].
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Avx2(pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    #[inline(always)]
    fn axpy<V: Stored>(self, y: &mut [f64], x: &[V], a: f64) {
        let v3 = self.0;
        let n = y.len() / 4 * 4;
        let av = v3.splat_f64x4(a);
        let (yv, yt) = y.split_at_mut(n);
        for (yc, xc) in yv.chunks_exact_mut(4).zip(x.chunks_exact(4)) {
            let yc: &mut [f64; 4] = yc.try_into().expect("four values");
            *yc = pulp::cast(v3.mul_add_f64x4(V::load4(v3, xc), av, pulp::cast(*yc)));
        }
        for (y, &x) in yt.iter_mut().zip(&x[n..]) {
            *y = x.into().mul_add(a, *y);
        }
    }

    #[inline(always)]
    fn axpy4<V: Stored>(self, y: &mut [f64], x: [&[V]; 4], a: [f64; 4]) {
        let v3 = self.0;
        let n = y.len() / 4 * 4;
        let av = a.map(|a| v3.splat_f64x4(a));
        let (yv, yt) = y.split_at_mut(n);
        for (c, yc) in yv.chunks_exact_mut(4).enumerate() {
            let yc: &mut [f64; 4] = yc.try_into().expect("four values");
            let i = 4 * c;
            let mut acc = pulp::cast(*yc);
            for k in 0..4 {
                acc = v3.mul_add_f64x4(V::load4(v3, &x[k][i..]), av[k], acc);
            }
            *yc = pulp::cast(acc);
        }
        for (i, y) in yt.iter_mut().enumerate() {
            for k in 0..4 {
                *y = x[k][n + i].into().mul_add(a[k], *y);
            }
        }
    }

    #[inline(always)]
    fn dot<V: Stored>(self, a: &[V], b: &[f64]) -> f64 {
        let v3 = self.0;
        let n = a.len() / 8 * 8;
        let mut acc = [v3.splat_f64x4(0.0); 2];
        for (ac, bc) in a[..n].chunks_exact(8).zip(b[..n].chunks_exact(8)) {
            for h in 0..2 {
                let bv: &[f64; 4] = bc[4 * h..4 * h + 4].try_into().expect("four values");
                acc[h] = v3.mul_add_f64x4(V::load4(v3, &ac[4 * h..]), pulp::cast(*bv), acc[h]);
            }
        }
        let mut s = pulp::Simd::reduce_sum_f64s(v3, v3.add_f64x4(acc[0], acc[1]));
        for (&a, &b) in a[n..].iter().zip(&b[n..]) {
            s = a.into().mul_add(b, s);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constraints::DofMap;
    use crate::mesh::generate::{BoxSpec, box_mesh};

    fn pattern() -> HessianPattern {
        box_pattern([6, 2, 2])
    }

    /// The free-DOF pattern of a 1 × 0.3 × 0.2 box of `cells` pinned at x = 0.
    fn box_pattern(cells: [usize; 3]) -> HessianPattern {
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.3, 0.2],
            cells,
            ..Default::default()
        })
        .unwrap();
        let pinned: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].x == 0.0)
            .collect();
        HessianPattern::new(&mesh.tets, &DofMap::new(&mesh, &pinned))
    }

    /// Symmetric values on the pattern: off-diagonal entries from a hash of (row, column),
    /// diagonal `diag` plus the row's absolute sum (strictly diagonally dominant, hence SPD, when
    /// `diag` > 0).
    fn values(p: &HessianPattern, diag: f64) -> Vec<f64> {
        let (cp, ri) = (p.symbolic.col_ptr(), p.symbolic.row_idx());
        let mut v = vec![0.0; p.nnz()];
        let mut row_sum = vec![0.0; p.dim()];
        for j in 0..p.dim() {
            for k in cp[j]..cp[j + 1] {
                let (lo, hi) = (ri[k].min(j), ri[k].max(j));
                if lo != hi {
                    let h = (lo * 7919 + hi * 104_729) % 1000;
                    v[k] = h as f64 / 1000.0 - 0.5;
                    row_sum[j] += v[k].abs();
                }
            }
        }
        for j in 0..p.dim() {
            v[p.diag[j]] = diag + row_sum[j];
        }
        v
    }

    fn residual(p: &HessianPattern, values: &[f64], x: &[f64], b: &[f64]) -> f64 {
        let mut ax = vec![0.0; b.len()];
        p.mul_vec(values, x, &mut ax);
        let r: f64 = ax.iter().zip(b).map(|(a, b)| (a - b).powi(2)).sum();
        r.sqrt() / b.iter().map(|b| b * b).sum::<f64>().sqrt()
    }

    #[test]
    fn solves_spd_systems_sequentially_and_in_parallel() {
        let p = pattern();
        let a = values(&p, 0.1);
        let b: Vec<f64> = (0..p.dim()).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
        let mut chol = SparseCholesky::analyse(&p).unwrap();
        assert!(chol.factor_nnz() >= p.dim());
        let mut solutions = Vec::new();
        // A pool of 1 factorises sequentially, one of 4 with faer's parallel code.
        for threads in [1, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let x = pool.install(|| {
                chol.factor(p.matrix(&a)).unwrap();
                let mut x = b.clone();
                chol.solve_in_place(&mut x);
                x
            });
            assert!(residual(&p, &a, &x, &b) < 1e-13, "{threads} threads");
            solutions.push(x);
        }
        let d: f64 = solutions[0]
            .iter()
            .zip(&solutions[1])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(d < 1e-12, "sequential and parallel solutions differ by {d}");
    }

    /// A box pinned at one end, large enough for a supernodal factor to have wide supernodes
    /// with long row patterns; `force` makes faer choose supernodal whatever its estimate.
    fn supernodal(cells: [usize; 3]) -> (HessianPattern, SparseCholesky) {
        let p = box_pattern(cells);
        let params = faer::sparse::linalg::cholesky::CholeskySymbolicParams {
            supernodal_flop_ratio_threshold:
                faer::sparse::linalg::SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        let chol = SparseCholesky::analyse_with(&p, params).unwrap();
        assert!(chol.is_supernodal());
        (p, chol)
    }

    fn max_relative_difference(a: &[f64], b: &[f64]) -> f64 {
        let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
            / scale
    }

    #[test]
    fn the_supernodal_kernels_agree_with_faers_solve() {
        // Two sizes: many narrow supernodes, and wide ones whose column counts are not
        // multiples of the kernels' four-column blocks.
        for cells in [[6, 2, 2], [16, 5, 4]] {
            let (p, mut chol) = supernodal(cells);
            let a = values(&p, 0.1);
            chol.factor(p.matrix(&a)).unwrap();
            let b: Vec<f64> = (0..p.dim()).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
            let mut x = b.clone();
            chol.solve_in_place(&mut x);
            let mut reference = b.clone();
            chol.faer_solve_in_place(&mut reference, Par::Seq);
            let d = max_relative_difference(&x, &reference);
            assert!(d < 1e-13, "{cells:?}: differs from faer by {d:e}");
            assert!(residual(&p, &a, &x, &b) < 1e-13, "{cells:?}");
        }
    }

    #[test]
    fn the_portable_kernels_agree_with_the_simd_ones() {
        let (p, mut chol) = supernodal([16, 5, 4]);
        let a = values(&p, 0.1);
        chol.factor(p.matrix(&a)).unwrap();
        let SymbolicCholeskyRaw::Supernodal(s) = chol.symbolic.raw() else {
            unreachable!("forced supernodal")
        };
        let b: Vec<f64> = (0..p.dim()).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
        let (mut best, mut portable) = (b.clone(), b.clone());
        chol.permuted_solve(s, &chol.l, &mut best, Kernels::Best);
        chol.permuted_solve(s, &chol.l, &mut portable, Kernels::Portable);
        let d = max_relative_difference(&portable, &best);
        assert!(d < 1e-13, "portable and SIMD solves differ by {d:e}");
        assert!(residual(&p, &a, &portable, &b) < 1e-13);
    }

    #[test]
    fn a_well_conditioned_preconditioner_is_factorised_in_f32_and_follows_refactorisations() {
        let (p, mut chol) = supernodal([16, 5, 4]);
        let b: Vec<f64> = (0..p.dim()).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
        for diag in [0.1, 3.0] {
            let a = values(&p, diag);
            chol.factor(p.matrix(&a)).unwrap();
            let mut exact = b.clone();
            chol.solve_in_place(&mut exact);
            assert!(chol.factor_for_preconditioning(p.matrix(&a)).unwrap());
            let mut single = b.clone();
            chol.solve_preconditioner_in_place(&mut single);
            // f32's unit roundoff is 6e-8; this matrix's condition number is modest.
            let d = max_relative_difference(&single, &exact);
            assert!(d < 1e-5, "diag {diag}: f32 factor's solve off by {d:e}");
            assert!(d > 0.0, "diag {diag}: the f32 factor was not used");
            assert!(residual(&p, &a, &single, &b) < 1e-5, "diag {diag}");
        }
    }

    #[test]
    fn an_ill_conditioned_preconditioner_is_factorised_in_f64() {
        // A graph Laplacian of the pattern plus 1e-9 I: condition number about 1e10. Its f32
        // factorisation succeeds but its check solve is 0.1 off (3e-5 with 1e-4 I), so the
        // check, not a failed pivot, sends it to f64.
        let (p, mut chol) = supernodal([16, 5, 4]);
        let mut a = values(&p, 0.0);
        let (cp, ri) = (p.symbolic.col_ptr(), p.symbolic.row_idx());
        for j in 0..p.dim() {
            let mut sum = 0.0;
            for k in cp[j]..cp[j + 1] {
                if ri[k] != j {
                    a[k] = -a[k].abs();
                    sum += a[k].abs();
                }
            }
            a[p.diag[j]] = sum + 1e-9;
        }
        let sibling = chol.same_pattern();
        assert!(!chol.factor_for_preconditioning(p.matrix(&a)).unwrap());
        let b: Vec<f64> = (0..p.dim()).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
        let mut x = b.clone();
        chol.solve_preconditioner_in_place(&mut x);
        let mut exact = b.clone();
        chol.solve_in_place(&mut exact);
        assert_eq!(x, exact);
        // The rejection is remembered by every factor sharing the analysis, even for a matrix
        // f32 would carry; a fresh analysis tries f32 again.
        let good = values(&p, 1.0);
        for mut other in [chol, sibling] {
            assert!(!other.factor_for_preconditioning(p.matrix(&good)).unwrap());
        }
        let (_, mut fresh) = supernodal([16, 5, 4]);
        assert!(fresh.factor_for_preconditioning(p.matrix(&good)).unwrap());
    }

    #[test]
    #[should_panic(expected = "exact solve without an f64 factorisation")]
    fn an_f32_factor_refuses_exact_solves() {
        let (p, mut chol) = supernodal([6, 2, 2]);
        assert!(
            chol.factor_for_preconditioning(p.matrix(&values(&p, 1.0)))
                .unwrap()
        );
        chol.solve_in_place(&mut vec![1.0; p.dim()]);
    }

    #[test]
    fn an_indefinite_matrix_is_an_error_and_the_factor_recovers() {
        let p = pattern();
        let mut chol = SparseCholesky::analyse(&p).unwrap();
        let mut bad = values(&p, 0.1);
        bad[p.diag[p.dim() / 2]] = -1.0;
        assert!(matches!(
            chol.factor(p.matrix(&bad)),
            Err(FemError::Factorization(_))
        ));
        // A sibling sharing the analysis factorises independently.
        let mut sibling = chol.same_pattern();
        let good = values(&p, 1.0);
        sibling.factor(p.matrix(&good)).unwrap();
        chol.factor(p.matrix(&good)).unwrap();
        let b = vec![1.0; p.dim()];
        let (mut x, mut y) = (b.clone(), b.clone());
        chol.solve_in_place(&mut x);
        sibling.solve_in_place(&mut y);
        assert_eq!(x, y);
        assert!(residual(&p, &good, &x, &b) < 1e-13);
    }
}
