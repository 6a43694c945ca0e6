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
    /// The f32 factor rounded to 16 bits ([`Half`]), each column scaled by its own power of two.
    l_half: Vec<Half>,
    /// 1 / (diagonal of L as each of the three stores holds it), by column in the factor's
    /// order: the substitutions multiply by it instead of dividing, which took a division's
    /// latency out of each column's dependency chain.
    inv_l: Vec<f64>,
    inv_single: Vec<f64>,
    inv_half: Vec<f64>,
    /// Per column of L (in the factor's order), the square of the factor by which its 16-bit
    /// values, widened, exceed L̃'s; the solve multiplies by it between its two passes.
    half_scaling: Vec<f64>,
    /// The matrix rounded to f32, the f32 factorisation's input.
    a_single: Vec<f32>,
    /// Set once an f32 factor failed its check: factors sharing this analysis then go straight
    /// to f64 (the matrices one simulation factorises share their mesh and mass term, and so
    /// largely their conditioning), instead of paying for a rejected f32 factor each time.
    single_rejected: Arc<AtomicBool>,
    /// The same for the 16-bit factor: set once one failed its check, after which the f32
    /// factor serves.
    half_rejected: Arc<AtomicBool>,
    /// The longest row pattern of a supernode (the solves' gather buffer), 0 when simplicial.
    max_pattern: usize,
    /// How the last successful factorisation stored its factor; None before one.
    factored: Option<FactorPrecision>,
}

/// How the factor of [`SparseCholesky::factor_for_preconditioning`] is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FactorPrecision {
    /// f64: the matrix's conditioning is beyond what f32 carries, or the factor is simplicial.
    Double,
    /// f32.
    Single,
    /// 16 bits per value (IEEE half precision, subnormals flushed, each column of L scaled by
    /// the power of two that puts its largest value near 2¹⁵).
    Half,
}

/// Largest error max|x − x₀| (for |x₀| ≤ 1) of an f32 factor's check solve that
/// [`SparseCholesky::factor_for_preconditioning`] accepts.
pub const SINGLE_FACTOR_TOLERANCE: f64 = 1e-3;

/// Largest error max|x − x₀| (for |x₀| ≤ 1) of a 16-bit factor's check solve that
/// [`SparseCholesky::factor_for_preconditioning`] accepts.
///
/// The check solve returns x = P⁻¹A x₀, so the error measures how far the preconditioned operator
/// moves a generic vector from itself. Half precision rounds each value by up to 2⁻¹¹, and the
/// error grows with the matrix's conditioning: over the training schedules of this project's
/// scenes it was 0.022–0.034 (cantilever), 0.034–0.046 (beam6k), 0.035–0.081 (catapult) and
/// 0.055–0.12 (dino), and the L-BFGS iterations per frame with the 16-bit factor were within
/// 3 % of the f32 one's (7.0 → 7.1, 18.3 → 18.2, 7.9 → 8.1, 36.2 → 36.7). L-BFGS's curvature
/// pairs correct a preconditioner that far off, as they correct its age; a factor further off
/// falls back to f32.
pub const HALF_FACTOR_TOLERANCE: f64 = 0.25;

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
            l_half: Vec::new(),
            inv_l: Vec::new(),
            inv_single: Vec::new(),
            inv_half: Vec::new(),
            half_scaling: Vec::new(),
            a_single: Vec::new(),
            single_rejected: Arc::new(AtomicBool::new(false)),
            half_rejected: Arc::new(AtomicBool::new(false)),
            max_pattern,
            factored: None,
        })
    }

    /// An empty factor sharing this one's symbolic analysis.
    pub fn same_pattern(&self) -> Self {
        Self {
            symbolic: Arc::clone(&self.symbolic),
            l: vec![0.0; self.l.len()],
            l_single: Vec::new(),
            l_half: Vec::new(),
            inv_l: Vec::new(),
            inv_single: Vec::new(),
            inv_half: Vec::new(),
            half_scaling: Vec::new(),
            a_single: Vec::new(),
            single_rejected: Arc::clone(&self.single_rejected),
            half_rejected: Arc::clone(&self.half_rejected),
            max_pattern: self.max_pattern,
            factored: None,
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
        self.factored = None;
        factorize(&self.symbolic, &mut self.l, a)?;
        reciprocal_diagonal(&self.symbolic, &self.l, &mut self.inv_l);
        self.factored = Some(FactorPrecision::Double);
        Ok(())
    }

    /// Factorises `a` for [`SparseCholesky::solve_preconditioner_in_place`]: in f32 when the
    /// factor is supernodal and the f32 factor passes a check, stored in 16 bits when that
    /// passes its own check too, in f64 otherwise. Returns how the factor is stored.
    ///
    /// An f32 factor is faster to compute (twice the SIMD lanes: 18 → 16 ms on the catapult,
    /// 230 → 156 ms on a 30k-DOF beam, check included) and halves the solves' memory traffic,
    /// and L̃L̃ᵀ is an exact factorisation of an SPD matrix near A: right for a preconditioner,
    /// which approximates a Hessian anyway. The solves stream the whole factor twice; 16-bit
    /// values (the f32 factor rounded, where this CPU has the AVX2 kernels that widen them)
    /// halve that traffic again: 15 % faster solves on a 6.9 M-value factor, not 50 %, as the
    /// kernels are also bound by their own arithmetic.
    ///
    /// The check solves A x = A x₀ for a fixed x₀ with entries in [-1, 1] and accepts the 16-bit
    /// factor when max|x − x₀| ≤ [`HALF_FACTOR_TOLERANCE`], else the f32 one when it is within
    /// [`SINGLE_FACTOR_TOLERANCE`]. A matrix whose conditioning a precision cannot carry gets
    /// the next, as do all later ones sharing this analysis; a failed f32 factorisation counts
    /// as a rejection. A check costs one product with A and one solve, a few percent of the
    /// factorisation. After a reduced-precision factorisation [`SparseCholesky::solve_in_place`]
    /// is unavailable until the next [`SparseCholesky::factor`].
    pub fn factor_for_preconditioning(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
    ) -> Result<FactorPrecision, FemError> {
        if self.is_supernodal() && !self.single_rejected.load(Ordering::Relaxed) {
            self.factored = None;
            self.a_single.clear();
            self.a_single.extend(a.val().iter().map(|&v| v as f32));
            self.l_single.resize(self.l.len(), 0.0);
            let single = SparseColMatRef::new(a.symbolic(), &self.a_single);
            if factorize(&self.symbolic, &mut self.l_single, single).is_ok() {
                reciprocal_diagonal(&self.symbolic, &self.l_single, &mut self.inv_single);
                if half_kernels() && !self.half_rejected.load(Ordering::Relaxed) {
                    if self.encode_half() {
                        self.factored = Some(FactorPrecision::Half);
                        if self.check_error(a) <= HALF_FACTOR_TOLERANCE {
                            return Ok(FactorPrecision::Half);
                        }
                    }
                    self.half_rejected.store(true, Ordering::Relaxed);
                }
                self.factored = Some(FactorPrecision::Single);
                if self.check_error(a) <= SINGLE_FACTOR_TOLERANCE {
                    return Ok(FactorPrecision::Single);
                }
            }
            self.single_rejected.store(true, Ordering::Relaxed);
        }
        self.factor(a).map(|()| FactorPrecision::Double)
    }

    /// Rounds the f32 factor into `l_half`, column by column ([`Half::encode_column`]), and
    /// records each column's scaling; false when a column is not finite.
    fn encode_half(&mut self) -> bool {
        let SymbolicCholeskyRaw::Supernodal(symbolic) = self.symbolic.raw() else {
            return false;
        };
        // Values above a diagonal block's diagonal are never read, so they are left as they are.
        self.l_half.resize(self.l_single.len(), Half(0));
        self.half_scaling.clear();
        for s in 0..symbolic.n_supernodes() {
            let b = SupernodeBlock::new(symbolic, s);
            let (single, half) = (&self.l_single[b.values.clone()], &mut self.l_half[b.values]);
            // Column j's values are its rows j.. (the diagonal block's upper part is unused).
            for (j, (col, out)) in single
                .chunks_exact(b.ld)
                .zip(half.chunks_exact_mut(b.ld))
                .enumerate()
            {
                match Half::encode_column(&col[j..], &mut out[j..]) {
                    Some(scaling) => self.half_scaling.push(scaling),
                    None => return false,
                }
            }
        }
        reciprocal_diagonal(&self.symbolic, &self.l_half, &mut self.inv_half);
        true
    }

    /// max|x − x₀| for x the preconditioner solve of A x = A x₀, x₀ a fixed vector with entries
    /// in [-1, 1]; infinite when x is not finite (a zero pivot, an overflow).
    fn check_error(&self, a: SparseColMatRef<'_, usize, f64>) -> f64 {
        let n = a.ncols();
        let x0: Vec<f64> = (0..n)
            .map(|i| 2.0 * (i as f64 * 0.618_033_988_749_895).fract() - 1.0)
            .collect();
        let mut x = vec![0.0; n];
        symmetric_lower_product(a, &x0, &mut x);
        self.solve_preconditioner_in_place(&mut x);
        x.iter().zip(&x0).fold(0.0f64, |m, (x, x0)| {
            let e = (x - x0).abs();
            // f64::max would drop a NaN.
            if e.is_nan() { f64::INFINITY } else { m.max(e) }
        })
    }

    /// x ← A⁻¹ x with the last A factorised by [`SparseCholesky::factor`].
    ///
    /// # Panics
    /// If the last factorisation was not a successful [`SparseCholesky::factor`].
    pub fn solve_in_place(&self, x: &mut [f64]) {
        assert!(
            self.factored == Some(FactorPrecision::Double),
            "exact solve without an f64 factorisation"
        );
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => {
                self.permuted_solve(s, &self.l, &self.inv_l, None, x, Kernels::Best)
            }
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

    /// x ← (L̃L̃ᵀ)⁻¹ x with whichever factor the last factorisation left, 16-bit or f32
    /// (arithmetic in f64) or f64.
    ///
    /// # Panics
    /// If no factorisation has succeeded.
    pub fn solve_preconditioner_in_place(&self, x: &mut [f64]) {
        match (self.factored, self.symbolic.raw()) {
            (Some(FactorPrecision::Single), SymbolicCholeskyRaw::Supernodal(s)) => {
                self.permuted_solve(s, &self.l_single, &self.inv_single, None, x, Kernels::Best)
            }
            (Some(FactorPrecision::Half), SymbolicCholeskyRaw::Supernodal(s)) => {
                let scaling = Some(&self.half_scaling[..]);
                self.permuted_solve(s, &self.l_half, &self.inv_half, scaling, x, Kernels::Best)
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
        inv_diag: &[f64],
        scaling: Option<&[f64]>,
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
                    supernodal_solve(symbolic, values, inv_diag, scaling, y, rows, kernels);
                    for (yi, &f) in y.iter().zip(fwd) {
                        x[f] = *yi;
                    }
                }
                None => supernodal_solve(symbolic, values, inv_diag, scaling, x, rows, kernels),
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

/// L Lᵀ x = b for a supernodal L, in place, with AVX2 + FMA where the CPU has them. With
/// `scaling` the stored factor is L̂ = L Σ for a diagonal Σ, and L Lᵀ = L̂ Σ⁻² L̂ᵀ is solved by
/// multiplying by Σ² (`scaling`, per column) between the two passes.
fn supernodal_solve<V: Stored>(
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
fn reciprocal_diagonal<V: Stored>(
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
struct SupernodeBlock<'a> {
    c0: usize,
    m: usize,
    pattern: &'a [usize],
    ld: usize,
    values: std::ops::Range<usize>,
}

impl<'a> SupernodeBlock<'a> {
    fn new(symbolic: &'a SymbolicSupernodalCholesky<usize>, s: usize) -> Self {
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

/// How L's values are stored: f64, rounded to f32, or to 16 bits (widened to f64 as they are
/// read).
trait Stored: Copy {
    /// The value as f64.
    fn widen(self) -> f64;

    /// Four consecutive values as f64 lanes.
    #[cfg(target_arch = "x86_64")]
    fn load4(v3: pulp::x86::V3, v: &[Self]) -> pulp::f64x4;
}

impl Stored for f64 {
    #[inline(always)]
    fn widen(self) -> f64 {
        self
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(_: pulp::x86::V3, v: &[f64]) -> pulp::f64x4 {
        let v: &[f64; 4] = v[..4].try_into().expect("four values");
        pulp::cast(*v)
    }
}

impl Stored for f32 {
    #[inline(always)]
    fn widen(self) -> f64 {
        self.into()
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(v3: pulp::x86::V3, v: &[f32]) -> pulp::f64x4 {
        let v: &[f32; 4] = v[..4].try_into().expect("four values");
        v3.convert_f32x4_to_f64x4(pulp::cast(*v))
    }
}

/// An IEEE half-precision bit pattern read as 2⁻¹¹² times its value, the factor of a 16-bit
/// preconditioner.
///
/// Widening shifts the half's exponent and mantissa into an f32's fields, which rebiases the
/// exponent by −112 for free (three integer operations and one conversion per four values); the
/// solve undoes that and each column's own scaling between its two passes. Encoding flushes
/// halves below the normal range (2⁻¹⁴) to zero, so every widened value is a normal f32.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Half(u16);

impl Half {
    /// Largest value encoded: max|v|·c lands in (2¹⁴, 2¹⁵] for the power-of-two scale c, below
    /// the half range's 65504.
    const TOP_EXPONENT: i32 = 15;

    /// Rounds one column of L into `out`, scaled by the power of two c that puts its largest
    /// value in (2¹⁴, 2¹⁵], to nearest even; values below 2⁻¹⁴ after scaling (2⁻²⁹ of the
    /// column's largest) become zero. Widened, the halves are σ = c·2⁻¹¹² times the values;
    /// returns σ², or None when a value is not finite. An all-zero column gets c = 1.
    fn encode_column(values: &[f32], out: &mut [Half]) -> Option<f64> {
        let mut max = 0.0f32;
        for v in values {
            if !v.is_finite() {
                return None;
            }
            max = max.max(v.abs());
        }
        let k = if max > 0.0 {
            (Self::TOP_EXPONENT - f64::from(max).log2().ceil() as i32).min(127)
        } else {
            0
        };
        let c = 2f32.powi(k);
        for (o, &v) in out.iter_mut().zip(values) {
            *o = Half::round(v * c);
        }
        let sigma = f64::from(c) * 2f64.powi(-112);
        Some(sigma * sigma)
    }

    /// The half nearest `v` (ties to even), zero below 2⁻¹⁴; `v` below 65504 in magnitude.
    fn round(v: f32) -> Half {
        let bits = v.to_bits();
        let sign = ((bits >> 16) & 0x8000) as u16;
        let magnitude = bits & 0x7fff_ffff;
        if magnitude < 0x3880_0000 {
            return Half(0);
        }
        // Round the 23-bit mantissa to 10 bits (a carry into the exponent is right), then
        // rebias the exponent from 127 to 15.
        let rounded = (magnitude + 0x0fff + ((magnitude >> 13) & 1)) >> 13;
        Half(sign | (rounded - (112 << 10)) as u16)
    }

    /// The f32 bit pattern of 2⁻¹¹² times the half's value: sign-extend, shift the exponent and
    /// mantissa into place, clear the three exponent bits the sign extension set.
    #[inline(always)]
    fn f32_bits(bits: i32) -> u32 {
        ((bits << 13) as u32) & 0x8fff_ffff
    }
}

impl Stored for Half {
    #[inline(always)]
    fn widen(self) -> f64 {
        f32::from_bits(Half::f32_bits(i32::from(self.0 as i16))).into()
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(v3: pulp::x86::V3, v: &[Half]) -> pulp::f64x4 {
        let v: &[Half; 4] = v[..4].try_into().expect("four values");
        let lanes: [u16; 8] = [v[0].0, v[1].0, v[2].0, v[3].0, 0, 0, 0, 0];
        let wide = v3.sse4_1._mm_cvtepi16_epi32(pulp::cast(lanes));
        let shifted = v3.sse2._mm_slli_epi32::<13>(wide);
        let mask = v3.sse2._mm_set1_epi32(0x8fff_ffff_u32 as i32);
        let f = v3
            .sse2
            ._mm_castsi128_ps(v3.sse2._mm_and_si128(shifted, mask));
        pulp::cast(v3.avx._mm256_cvtps_pd(f))
    }
}

/// Whether 16-bit factors are worth storing: only the AVX2 kernels widen them at the speed of
/// the memory they save.
fn half_kernels() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        pulp::x86::V3::try_new().is_some()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
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
            *y += x.widen() * a;
        }
    }

    #[inline(always)]
    fn axpy4<V: Stored>(self, y: &mut [f64], x: [&[V]; 4], a: [f64; 4]) {
        for (i, y) in y.iter_mut().enumerate() {
            *y += x[0][i].widen() * a[0]
                + x[1][i].widen() * a[1]
                + x[2][i].widen() * a[2]
                + x[3][i].widen() * a[3];
        }
    }

    #[inline(always)]
    fn dot<V: Stored>(self, a: &[V], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(&a, &b)| a.widen() * b).sum()
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
            *y = x.widen().mul_add(a, *y);
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
                *y = x[k][n + i].widen().mul_add(a[k], *y);
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
            s = a.widen().mul_add(b, s);
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

    /// A fixed right-hand side of entries in [-5, 5].
    fn rhs(p: &HessianPattern) -> Vec<f64> {
        (0..p.dim()).map(|i| ((i * 37) % 11) as f64 - 5.0).collect()
    }

    /// Every factor in `factors` factorises `a` into `expected` (a rejection is remembered by
    /// all factors sharing an analysis).
    fn assert_all_factor_as(
        factors: impl IntoIterator<Item = SparseCholesky>,
        p: &HessianPattern,
        a: &[f64],
        expected: FactorPrecision,
    ) {
        for mut f in factors {
            assert_eq!(f.factor_for_preconditioning(p.matrix(a)).unwrap(), expected);
        }
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
        let b = rhs(&p);
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

    /// max|a − b| / max|b|; infinite when a value is not finite (f64::max would drop a NaN).
    fn max_relative_difference(a: &[f64], b: &[f64]) -> f64 {
        if !a.iter().chain(b).all(|v| v.is_finite()) {
            return f64::INFINITY;
        }
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
            let b = rhs(&p);
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
        let b = rhs(&p);
        let (mut best, mut portable) = (b.clone(), b.clone());
        chol.permuted_solve(s, &chol.l, &chol.inv_l, None, &mut best, Kernels::Best);
        chol.permuted_solve(
            s,
            &chol.l,
            &chol.inv_l,
            None,
            &mut portable,
            Kernels::Portable,
        );
        let d = max_relative_difference(&portable, &best);
        assert!(d < 1e-13, "portable and SIMD solves differ by {d:e}");
        assert!(residual(&p, &a, &portable, &b) < 1e-13);
    }

    #[test]
    fn a_well_conditioned_preconditioner_is_stored_in_16_bits_and_follows_refactorisations() {
        let (p, mut chol) = supernodal([16, 5, 4]);
        let b = rhs(&p);
        let expected = if half_kernels() {
            FactorPrecision::Half
        } else {
            FactorPrecision::Single
        };
        for diag in [0.1, 3.0] {
            let a = values(&p, diag);
            chol.factor(p.matrix(&a)).unwrap();
            let mut exact = b.clone();
            chol.solve_in_place(&mut exact);
            assert_eq!(
                chol.factor_for_preconditioning(p.matrix(&a)).unwrap(),
                expected
            );
            let mut reduced = b.clone();
            chol.solve_preconditioner_in_place(&mut reduced);
            // Half's unit roundoff is 2⁻¹¹ ≈ 5e-4, f32's 6e-8; the condition number is modest.
            let (tolerance, floor) = match expected {
                FactorPrecision::Half => (1e-2, 1e-6),
                _ => (1e-5, 0.0),
            };
            let d = max_relative_difference(&reduced, &exact);
            assert!(
                d < tolerance,
                "diag {diag}: {expected:?} solve off by {d:e}"
            );
            assert!(
                d > floor,
                "diag {diag}: the {expected:?} factor was not used ({d:e})"
            );
            assert!(residual(&p, &a, &reduced, &b) < tolerance, "diag {diag}");
        }
    }

    /// A graph Laplacian of the pattern plus `shift` I: condition number about 1/shift.
    fn laplacian(p: &HessianPattern, shift: f64) -> Vec<f64> {
        let mut a = values(p, 0.0);
        let (cp, ri) = (p.symbolic.col_ptr(), p.symbolic.row_idx());
        for j in 0..p.dim() {
            let mut sum = 0.0;
            for k in cp[j]..cp[j + 1] {
                if ri[k] != j {
                    a[k] = -a[k].abs();
                    sum += a[k].abs();
                }
            }
            a[p.diag[j]] = sum + shift;
        }
        a
    }

    #[test]
    fn an_ill_conditioned_preconditioner_is_factorised_in_f64() {
        // Condition number about 1e10: the f32 factorisation succeeds but its check solve is 0.1
        // off (3e-5 with 1e-4 I), so the check, not a failed pivot, sends it to f64.
        let (p, mut chol) = supernodal([16, 5, 4]);
        let a = laplacian(&p, 1e-9);
        let sibling = chol.same_pattern();
        assert_eq!(
            chol.factor_for_preconditioning(p.matrix(&a)).unwrap(),
            FactorPrecision::Double
        );
        let b = rhs(&p);
        let mut x = b.clone();
        chol.solve_preconditioner_in_place(&mut x);
        let mut exact = b.clone();
        chol.solve_in_place(&mut exact);
        assert_eq!(x, exact);
        // The rejection is remembered by every factor sharing the analysis, even for a matrix
        // f32 would carry; a fresh analysis tries the reduced precisions again.
        let good = values(&p, 1.0);
        assert_all_factor_as([chol, sibling], &p, &good, FactorPrecision::Double);
        let (_, mut fresh) = supernodal([16, 5, 4]);
        assert_ne!(
            fresh.factor_for_preconditioning(p.matrix(&good)).unwrap(),
            FactorPrecision::Double
        );
    }

    #[test]
    fn a_matrix_16_bits_cannot_carry_gets_the_f32_factor() {
        if !half_kernels() {
            eprintln!("skipping: no AVX2 kernels for 16-bit factors on this CPU");
            return;
        }
        // Condition number about 3e4: f32's check error is 3e-4, half's beyond its tolerance
        // (0.24 already at 1e-4 I, 1e-3 at 3e-4 I).
        let (p, mut chol) = supernodal([16, 5, 4]);
        let a = laplacian(&p, 3e-5);
        let sibling = chol.same_pattern();
        assert_eq!(
            chol.factor_for_preconditioning(p.matrix(&a)).unwrap(),
            FactorPrecision::Single
        );
        let b = rhs(&p);
        let mut x = b.clone();
        chol.solve_preconditioner_in_place(&mut x);
        assert!(residual(&p, &a, &x, &b) < 1e-3);
        // Remembered: a well-conditioned matrix then also gets f32, on either factor.
        let good = values(&p, 1.0);
        assert_all_factor_as([chol, sibling], &p, &good, FactorPrecision::Single);
    }

    #[test]
    fn columns_of_very_different_scales_keep_their_16_bit_accuracy() {
        if !half_kernels() {
            eprintln!("skipping: no AVX2 kernels for 16-bit factors on this CPU");
            return;
        }
        // L' = L D with every third column of an f32 factor scaled by 1e-10 is the factor of
        // L D² Lᵀ. Scaled per column, its 16-bit copy solves as accurately as L's; with one
        // scale for the whole factor those columns would fall below the half range and vanish.
        let (p, mut chol) = supernodal([16, 5, 4]);
        assert_eq!(
            chol.factor_for_preconditioning(p.matrix(&values(&p, 0.1)))
                .unwrap(),
            FactorPrecision::Half
        );
        let symbolic = Arc::clone(&chol.symbolic);
        let SymbolicCholeskyRaw::Supernodal(s) = symbolic.raw() else {
            unreachable!("forced supernodal")
        };
        for k in 0..s.n_supernodes() {
            let b = SupernodeBlock::new(s, k);
            for (j, col) in chol.l_single[b.values].chunks_exact_mut(b.ld).enumerate() {
                if (b.c0 + j).is_multiple_of(3) {
                    col.iter_mut().for_each(|v| *v *= 1e-10);
                }
            }
        }
        reciprocal_diagonal(&chol.symbolic, &chol.l_single, &mut chol.inv_single);
        assert!(chol.encode_half());
        let b = rhs(&p);
        let (mut single, mut half) = (b.clone(), b.clone());
        chol.permuted_solve(
            s,
            &chol.l_single,
            &chol.inv_single,
            None,
            &mut single,
            Kernels::Best,
        );
        let scaling = Some(&chol.half_scaling[..]);
        chol.permuted_solve(
            s,
            &chol.l_half,
            &chol.inv_half,
            scaling,
            &mut half,
            Kernels::Best,
        );
        let d = max_relative_difference(&half, &single);
        assert!(d < 1e-2, "16-bit solve off by {d:e}");
    }

    #[test]
    fn halves_round_to_nearest_and_widen_exactly() {
        let scale = 2f64.powi(112);
        // Every finite normal half and zero: widening gives its value (times 2⁻¹¹²), and
        // rounding that value gives the half back.
        for bits in 0..=u16::MAX {
            let exponent = i32::from((bits >> 10) & 0x1f);
            if exponent == 0x1f || (exponent == 0 && bits & 0x3ff != 0) || bits == 0x8000 {
                continue;
            }
            let magnitude = if exponent == 0 {
                0.0
            } else {
                (1.0 + f64::from(bits & 0x3ff) / 1024.0) * 2f64.powi(exponent - 15)
            };
            let value = if bits & 0x8000 != 0 {
                -magnitude
            } else {
                magnitude
            };
            assert_eq!(Half(bits).widen() * scale, value, "{bits:#06x}");
            assert_eq!(Half::round(value as f32), Half(bits), "{bits:#06x}");
        }
        // Between two halves: the nearer one, and on a tie the one with an even mantissa.
        let one_ulp = 2f32.powi(-10);
        for (v, expected) in [
            (1.0 + 0.49 * one_ulp, 1.0),
            (1.0 + 0.51 * one_ulp, 1.0 + one_ulp),
            (1.0 + 0.5 * one_ulp, 1.0),
            (1.0 + 1.5 * one_ulp, 1.0 + 2.0 * one_ulp),
            (-(1.0 + 0.51 * one_ulp), -(1.0 + one_ulp)),
            (2047.5, 2048.0),
        ] {
            assert_eq!(Half::round(v).widen() * scale, f64::from(expected), "{v}");
        }
        // Below the normal range: zero.
        for v in [6.0e-5f32, -6.0e-5, 1e-30, 0.0] {
            assert_eq!(Half::round(v), Half(0), "{v}");
        }
    }

    #[test]
    fn encoding_scales_each_column_s_largest_value_to_the_top_of_the_half_range() {
        for max in [1e-20f32, 3.7e-3, 1.0, 631.0, 4.2e12] {
            let values = [max, -0.5 * max, 1e-3 * max, 1e-10 * max, 0.0];
            let mut out = [Half(0); 5];
            let scaling = Half::encode_column(&values, &mut out).unwrap();
            // Widened, the halves are σ times the values, and scaling is σ².
            let sigma = scaling.sqrt();
            for (v, h) in values.iter().zip(&out) {
                let back = h.widen() / sigma;
                let v = f64::from(*v);
                assert!(
                    (back - v).abs() <= 2f64.powi(-11) * v.abs() + 1e-9 * f64::from(max),
                    "max {max}: {v} → {back}"
                );
            }
            let top = out[0].widen() * 2f64.powi(112);
            assert!(
                top > 16384.0 && top <= 32768.0,
                "max {max}: scaled to {top}"
            );
        }
        let mut out = [Half(1); 2];
        assert!(Half::encode_column(&[0.0, 0.0], &mut out).is_some());
        assert_eq!(out, [Half(0); 2]);
        assert!(Half::encode_column(&[1.0, f32::INFINITY], &mut out).is_none());
        assert!(Half::encode_column(&[f32::NAN, 1.0], &mut out).is_none());
    }

    #[test]
    fn the_simd_widening_of_halves_matches_the_scalar_one() {
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = pulp::x86::V3::try_new() {
            let all: Vec<Half> = (0..=u16::MAX)
                .map(Half)
                .filter(|h| (h.0 >> 10) & 0x1f != 0x1f)
                .collect();
            for chunk in all.chunks_exact(4) {
                let wide: [f64; 4] = pulp::cast(Half::load4(v3, chunk));
                for (w, h) in wide.iter().zip(chunk) {
                    assert_eq!(w.to_bits(), h.widen().to_bits(), "{:#06x}", h.0);
                }
            }
            return;
        }
        eprintln!("skipping: no AVX2 on this CPU");
    }

    #[test]
    fn the_portable_kernels_agree_with_the_simd_ones_on_16_bit_factors() {
        let (p, mut chol) = supernodal([16, 5, 4]);
        let a = values(&p, 0.1);
        if chol.factor_for_preconditioning(p.matrix(&a)).unwrap() != FactorPrecision::Half {
            eprintln!("skipping: no 16-bit factors on this CPU");
            return;
        }
        let SymbolicCholeskyRaw::Supernodal(s) = chol.symbolic.raw() else {
            unreachable!("forced supernodal")
        };
        let b = rhs(&p);
        let (mut best, mut portable) = (b.clone(), b.clone());
        let scaling = Some(&chol.half_scaling[..]);
        let inv = &chol.inv_half;
        chol.permuted_solve(s, &chol.l_half, inv, scaling, &mut best, Kernels::Best);
        chol.permuted_solve(
            s,
            &chol.l_half,
            inv,
            scaling,
            &mut portable,
            Kernels::Portable,
        );
        let d = max_relative_difference(&portable, &best);
        assert!(d < 1e-13, "portable and SIMD solves differ by {d:e}");
    }

    #[test]
    #[should_panic(expected = "exact solve without an f64 factorisation")]
    fn a_reduced_precision_factor_refuses_exact_solves() {
        let (p, mut chol) = supernodal([6, 2, 2]);
        assert_ne!(
            chol.factor_for_preconditioning(p.matrix(&values(&p, 1.0)))
                .unwrap(),
            FactorPrecision::Double
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
