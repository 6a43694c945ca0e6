//! Sparse Cholesky factorisation A = LLᵀ of the free-DOF system matrices (the projected Hessian
//! plus M/h² and spring stiffness), all sharing one [`HessianPattern`]: the fill-reducing ordering
//! and symbolic analysis are done once per mesh, each numeric factorisation refills one buffer.

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::SparseColMatRef;
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
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
/// 280–330 ms), so pools of up to [`SEQUENTIAL_FACTOR_THREADS`] threads factorise and solve
/// sequentially; larger pools keep faer's parallel default.
#[derive(Debug, Clone)]
pub struct SparseCholesky {
    symbolic: Arc<SymbolicCholesky<usize>>,
    /// The factor's values; meaningful only after a successful [`SparseCholesky::factor`].
    l: Vec<f64>,
    factored: bool,
}

/// Largest rayon pool in which sparse factorisations run sequentially.
pub const SEQUENTIAL_FACTOR_THREADS: usize = 2;

fn factor_parallelism() -> Par {
    if rayon::current_num_threads() <= SEQUENTIAL_FACTOR_THREADS {
        Par::Seq
    } else {
        Par::rayon(0)
    }
}

impl SparseCholesky {
    /// Symbolic analysis of `pattern`'s lower triangle.
    pub fn analyse(pattern: &HessianPattern) -> Result<Self, FemError> {
        let symbolic = factorize_symbolic_cholesky(
            pattern.symbolic.as_ref(),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| FemError::Factorization(format!("symbolic analysis: {e:?}")))?;
        Ok(Self {
            l: vec![0.0; symbolic.len_val()],
            symbolic: Arc::new(symbolic),
            factored: false,
        })
    }

    /// An empty factor sharing this one's symbolic analysis.
    pub fn same_pattern(&self) -> Self {
        Self {
            symbolic: Arc::clone(&self.symbolic),
            l: vec![0.0; self.l.len()],
            factored: false,
        }
    }

    /// Number of stored values of L.
    pub fn factor_nnz(&self) -> usize {
        self.l.len()
    }

    /// Factorises `a` (same pattern as the analysis; the lower triangle is read). On failure
    /// (not positive definite) the factor is unusable until the next successful call.
    pub fn factor(&mut self, a: SparseColMatRef<'_, usize, f64>) -> Result<(), FemError> {
        let par = factor_parallelism();
        let mut mem = MemBuffer::try_new(
            self.symbolic
                .factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        )
        .map_err(|e| FemError::Factorization(format!("workspace: {e:?}")))?;
        self.factored = false;
        self.symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.l,
                a,
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| FemError::Factorization(format!("{e:?}")))?;
        self.factored = true;
        Ok(())
    }

    /// x ← A⁻¹ x with the last factorised A.
    ///
    /// # Panics
    /// If no factorisation has succeeded.
    pub fn solve_in_place(&self, x: &mut [f64]) {
        assert!(
            self.factored,
            "solve with a sparse Cholesky never factorised"
        );
        let par = factor_parallelism();
        let n = x.len();
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(1, par));
        LltRef::new(&self.symbolic, &self.l).solve_in_place_with_conj(
            Conj::No,
            faer::MatMut::from_column_major_slice_mut(x, n, 1),
            par,
            MemStack::new(&mut mem),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constraints::DofMap;
    use crate::mesh::generate::{BoxSpec, box_mesh};

    fn pattern() -> HessianPattern {
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.3, 0.2],
            cells: [6, 2, 2],
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
