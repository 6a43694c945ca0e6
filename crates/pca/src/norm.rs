//! A basis chosen in another norm than M's, returned M-orthonormal like every basis.
//!
//! # Maths
//! For a symmetric positive definite W (n × n, given as a product S ↦ WS), the rank-k subspace
//! that best represents the snapshots S in the W-weighted Frobenius norm is spanned by the
//! leading POD modes of the method of snapshots: with the Gram matrix G = SᵀWS = V Λ Vᵀ
//! (λ_0 ≥ λ_1 ≥ …), the modes are φ_i = S v_i / √λ_i, W-orthonormal. Only the span matters to
//! a Galerkin simulation; the columns are then made M-orthonormal in their order by modified
//! Gram–Schmidt (twice), so that the first j columns still span the j leading modes and
//! UᵀMU = I holds as the rest of the pipeline needs.

use faer::{Mat, MatRef};

use crate::basis::orthogonalise;
use crate::{PcaBasis, PcaError};

impl PcaBasis {
    /// A basis of the same dimension k as `self` spanned by the k leading POD modes of
    /// `snapshots` in the norm of W, where `apply_w(S)` returns W·S. The columns are
    /// M-orthonormal in `self`'s mass; `self`'s singular values (the M-norm spectrum) are kept
    /// for reports.
    pub fn refit_in_norm(
        &self,
        snapshots: MatRef<'_, f64>,
        apply_w: impl Fn(MatRef<'_, f64>) -> Mat<f64>,
    ) -> Result<PcaBasis, PcaError> {
        let (n, num) = snapshots.shape();
        let k = self.k();
        if n != self.n() || num < k {
            return Err(PcaError::InvalidBasis(format!(
                "snapshots are {n} × {num}, the basis needs {} rows and at least {k} columns",
                self.n()
            )));
        }
        let ws = apply_w(snapshots);
        if ws.shape() != (n, num) {
            return Err(PcaError::InvalidBasis(format!(
                "W·S is {} × {}, expected {n} × {num}",
                ws.nrows(),
                ws.ncols()
            )));
        }
        let gram = snapshots.transpose() * &ws;
        let sym = Mat::from_fn(num, num, |i, j| 0.5 * (gram[(i, j)] + gram[(j, i)]));
        let eig = sym
            .self_adjoint_eigen(faer::Side::Lower)
            .map_err(|_| PcaError::SvdNoConvergence)?;
        let values: Vec<f64> = eig.S().column_vector().iter().copied().collect();
        let mut order: Vec<usize> = (0..num).collect();
        order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
        let largest = values[order[0]];
        if !(largest.is_finite() && largest > 0.0) {
            return Err(PcaError::ZeroSnapshots);
        }
        let threshold = largest * num as f64 * f64::EPSILON;
        let mut coefficients = Mat::<f64>::zeros(num, k);
        for (c, &i) in order.iter().take(k).enumerate() {
            if values[i] <= threshold {
                return Err(PcaError::DimensionOutOfRange {
                    requested: k,
                    available: c,
                });
            }
            let s = 1.0 / values[i].sqrt();
            for r in 0..num {
                coefficients[(r, c)] = eig.U()[(r, i)] * s;
            }
        }
        let modes = snapshots * &coefficients;
        // In order, not a parallel sum: rayon's split points vary from run to run, and with
        // them the round-off, so the basis (and every stage after it) would not reproduce.
        let mut columns: Vec<f64> = Vec::with_capacity(n * k);
        for c in 0..k {
            let mut v: Vec<f64> = modes.col(c).iter().copied().collect();
            let norm = orthogonalise(&mut v, &columns, self.mass());
            if !(norm.is_finite() && norm > 0.0) {
                return Err(PcaError::DimensionOutOfRange {
                    requested: k,
                    available: c,
                });
            }
            columns.extend(v.iter().map(|x| x / norm));
        }
        Ok(PcaBasis::from_parts(
            n,
            k,
            columns,
            self.mass().map(<[f64]>::to_vec),
            self.singular_values().to_vec(),
        ))
    }
}
