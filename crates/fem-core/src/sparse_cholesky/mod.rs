//! Sparse Cholesky factorisation A = LLᵀ of the free-DOF system matrices (the projected Hessian
//! plus M/h² and spring stiffness), all sharing one [`HessianPattern`]: the fill-reducing ordering
//! and symbolic analysis are done once per mesh, each numeric factorisation refills one buffer.
//!
//! faer analyses and factorises; the solves are this module's own (`supernodal_solve.rs`, with
//! the inner loops in `kernels.rs`), because they read a factor stored in f32 or 16 bits
//! (`storage.rs`) with f64 arithmetic, which faer's solve cannot, and were faster than faer's in
//! f64 too: 1.0–1.1 ms against 1.3–1.5 ms on the catapult's 1.6 M-value factor, 0.73–0.79 ms
//! with f32 values.

mod kernels;
mod storage;
mod supernodal_solve;

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
use kernels::half_kernels;
use storage::{Half, Stored};
use supernodal_solve::{Kernels, SupernodeBlock, reciprocal_diagonal, supernodal_solve};

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

    /// Gives this factor rejection flags of its own, set as they are now, and returns them for
    /// its siblings ([`Self::share_rejections`]): a copy of a simulation must not change how
    /// the original's factors are stored.
    pub fn own_rejections(&mut self) -> (Arc<AtomicBool>, Arc<AtomicBool>) {
        let copy = |flag: &AtomicBool| Arc::new(AtomicBool::new(flag.load(Ordering::Relaxed)));
        self.single_rejected = copy(&self.single_rejected);
        self.half_rejected = copy(&self.half_rejected);
        (
            Arc::clone(&self.single_rejected),
            Arc::clone(&self.half_rejected),
        )
    }

    /// Shares `flags` ([`Self::own_rejections`]'s) with this factor.
    pub fn share_rejections(&mut self, flags: &(Arc<AtomicBool>, Arc<AtomicBool>)) {
        self.single_rejected = Arc::clone(&flags.0);
        self.half_rejected = Arc::clone(&flags.1);
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

    /// A copy's factors given flags of their own ([`SparseCholesky::own_rejections`]) keep
    /// their rejections to themselves and their siblings: the original still tries f32.
    #[test]
    fn a_copy_with_its_own_rejections_leaves_the_original_alone() {
        let (p, original) = supernodal([16, 5, 4]);
        let (mut copy, mut copy_sibling) = (original.clone(), original.same_pattern());
        let flags = copy.own_rejections();
        copy_sibling.share_rejections(&flags);
        assert_eq!(
            copy.factor_for_preconditioning(p.matrix(&laplacian(&p, 1e-9)))
                .unwrap(),
            FactorPrecision::Double
        );
        let good = values(&p, 1.0);
        assert_all_factor_as([copy_sibling], &p, &good, FactorPrecision::Double);
        let mut original = original;
        assert_ne!(
            original
                .factor_for_preconditioning(p.matrix(&good))
                .unwrap(),
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
