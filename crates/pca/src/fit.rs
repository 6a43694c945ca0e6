//! Fitting a basis: the thin SVD of M^{1/2}S and the choice of k.
//!
//! # Maths
//! S is n × N, one snapshot per column, uncentred (as AutoDef did: displacements from rest, so the
//! rest pose q = 0 stays exactly representable). With the diagonal mass M (I if none),
//!
//! M^{1/2} S = Ũ Σ Vᵀ (thin SVD, σ_0 ≥ σ_1 ≥ … ≥ 0),   U = M^{-1/2} Ũ_{:, :k},
//!
//! so UᵀMU = ŨᵀŨ = I. By Eckart–Young, U Uᵀ M S is the best rank-k approximation of S in the
//! M-weighted Frobenius norm, with squared error Σ_{i≥k} σ_i².
//!
//! # Choosing k
//! * count: k as given (at most min(n, N));
//! * explained energy: the smallest k with Σ_{i<k} σ_i² ≥ f · Σ_i σ_i²;
//! * max vertex error: the smallest k with max_{v, j} ‖s_{v,j} − (U UᵀM s_j)_v‖₂ ≤ τ, scanned
//!   incrementally over k: R_k = R_{k−1} − σ_{k−1} u_{k−1} v_{k−1}ᵀ, one
//!   rank-one update and one pass for the vertex norms per k, O(n·N), parallel over snapshots.
//!
//! Singular values at or below σ_0 · max(n, N) · ε are roundoff of zero; r counts the others (the
//! numerical rank) and the energy and vertex-error rules never go past it. Every rule is capped by
//! `max_dimension`; a rule that the cap stops from being met yields k = cap with
//! [`PcaFit::tolerance_met`] = false and a `tracing` warning, not an error.

use faer::{Mat, MatRef};

use crate::basis::check_mass;
use crate::svd::ThinSvd;
use crate::vertex_error::scan_max_vertex_error;
use crate::{DimensionRule, PcaBasis, PcaConfig, PcaError};

/// A fitted basis and how its dimension was chosen (everything a report needs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PcaFit {
    /// The basis with the chosen k columns (and the whole spectrum).
    pub basis: PcaBasis,
    /// The rule that chose k.
    pub rule: DimensionRule,
    /// Number of singular values above σ_0 · max(n, N) · ε.
    pub numerical_rank: usize,
    /// Whether the rule's target was reached within the cap (always true for a count).
    pub tolerance_met: bool,
    /// For the max-vertex-error rule: the maximum vertex error for k = 1, 2, …, chosen k (or up
    /// to the cap when the tolerance was not met). Empty for the other rules.
    pub max_vertex_error_per_k: Vec<f64>,
    /// Positions of the fall appended after the rule chose k ([`PcaBasis::extended`]).
    #[serde(default)]
    pub appended: usize,
    /// Static responses to patch loads appended after those (`[pca] patch_responses`): the
    /// basis has k + `appended` + `responses` columns, these the last.
    #[serde(default)]
    pub responses: usize,
    /// The fraction of the body's first step of its fall under gravity (M-norm) that the k
    /// columns miss, when the pipeline measured it.
    #[serde(default)]
    pub fall_missed: Option<f64>,
}

impl PcaFit {
    /// The dimension the rule chose (the basis has [`Self::appended`] and [`Self::responses`]
    /// more columns).
    pub fn chosen_k(&self) -> usize {
        self.basis
            .k()
            .saturating_sub(self.appended + self.responses)
    }

    /// The smallest k holding `fraction` of the snapshots' energy, from the whole spectrum (at
    /// most the numerical rank): what the explained-energy rule would choose at `fraction`,
    /// before any cap.
    pub fn energy_dimension(&self, fraction: f64) -> usize {
        energy_dimension(self.basis.singular_values(), self.numerical_rank, fraction)
    }

    /// What stopped the rule short of its target, where it was not met ([`Self::tolerance_met`]
    /// false): `max_dimension` or the snapshots' numerical rank.
    pub fn shortfall(&self) -> Option<Shortfall> {
        if self.tolerance_met {
            return None;
        }
        let k = self.chosen_k();
        Some(match self.rule {
            // The spectrum is whole, so the count the rule asks for is known.
            DimensionRule::ExplainedEnergy(f) => Shortfall::Cap {
                wanted: Some(self.energy_dimension(f)),
            },
            // Only roundoff lies past the rank: a larger cap adds nothing there.
            DimensionRule::MaxVertexError(_) if k >= self.numerical_rank => Shortfall::Rank,
            // The scan stopped at the cap: how far past it the tolerance lies is not known.
            _ => Shortfall::Cap { wanted: None },
        })
    }
}

/// Why a PCA rule's target was not reached ([`PcaFit::shortfall`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shortfall {
    /// `max_dimension` stopped the basis; `wanted`, the dimension the rule asks for where the
    /// spectrum says it (the explained-energy rule).
    Cap { wanted: Option<usize> },
    /// The snapshots span no more directions than the basis has: only more (or more varied)
    /// training poses reach the target.
    Rank,
}

impl PcaBasis {
    /// Fits a mass-orthonormal basis to `snapshots` (n × N, one snapshot per column) and chooses
    /// its dimension by `config`.
    ///
    /// * `mass`: the diagonal of M (length n, every entry positive and finite: pass free DOFs
    ///   only), or `None` for M = I.
    /// * `group`: rows per vertex (3 for displacements); vertex v owns rows `group·v..group·(v+1)`.
    ///   Used by the max-vertex-error rule; n must be a multiple of it.
    pub fn fit(
        snapshots: MatRef<'_, f64>,
        mass: Option<&[f64]>,
        config: &PcaConfig,
        group: usize,
    ) -> Result<PcaFit, PcaError> {
        let rule = config.rule()?;
        let (n, num_snapshots) = snapshots.shape();
        check_snapshots(snapshots)?;
        if group == 0 || n % group != 0 {
            return Err(PcaError::InvalidGroup { group, nrows: n });
        }
        if let Some(m) = mass {
            check_mass(m, n)?;
        }

        let sqrt_mass: Option<Vec<f64>> = mass.map(|m| m.iter().map(|x| x.sqrt()).collect());
        let weighted = match &sqrt_mass {
            Some(w) => Mat::from_fn(n, num_snapshots, |i, j| w[i] * snapshots[(i, j)]),
            None => snapshots.to_owned(),
        };
        let svd = ThinSvd::new(weighted)?;
        let sigma = svd.sigma.clone();
        let rank = numerical_rank(&sigma, n.max(num_snapshots));
        let cap = config.max_dimension.min(sigma.len());

        // Columns start..start + count of U = M^{-1/2} Ũ, column-major.
        let basis_columns = |start: usize, count: usize| -> Vec<f64> {
            let u_tilde = svd.left_vectors(start, count);
            let mut u = Vec::with_capacity(n * count);
            for col in u_tilde.col_iter() {
                match &sqrt_mass {
                    Some(w) => u.extend(col.iter().zip(w).map(|(x, w)| x / w)),
                    None => u.extend(col.iter()),
                }
            }
            u
        };

        let (k, tolerance_met, per_k, columns) = match rule {
            DimensionRule::Count(k) => {
                if k > sigma.len() {
                    return Err(PcaError::DimensionOutOfRange {
                        requested: k,
                        available: sigma.len(),
                    });
                }
                if k > rank {
                    tracing::warn!(
                        k,
                        rank,
                        "PCA dimension exceeds the numerical rank of the snapshots; the extra \
                         columns span roundoff"
                    );
                }
                (k, true, Vec::new(), basis_columns(0, k))
            }
            DimensionRule::ExplainedEnergy(fraction) => {
                let wanted = energy_dimension(&sigma, rank, fraction);
                let met = wanted <= cap;
                let k = wanted.min(cap);
                // Said by the fit's `met` (the pipeline's `pca` line), not as a warning of its own.
                if !met {
                    tracing::info!(
                        fraction,
                        needed = wanted,
                        cap,
                        "explained-energy target not reached within pca.max_dimension"
                    );
                }
                (k, met, Vec::new(), basis_columns(0, k))
            }
            DimensionRule::MaxVertexError(tolerance) => {
                let limit = cap.min(rank);
                let v = svd.v();
                let scan = scan_max_vertex_error(
                    snapshots,
                    limit,
                    basis_columns,
                    |j, i| sigma[i] * v[(j, i)],
                    group,
                    |_, error| error <= tolerance,
                );
                let (k, met) = match scan.chosen {
                    Some(k) => (k, true),
                    None => {
                        let reached = scan.per_k.last().copied().unwrap_or(f64::INFINITY);
                        tracing::warn!(
                            tolerance,
                            reached,
                            k = limit,
                            "max vertex error tolerance not met within pca.max_dimension / the \
                             numerical rank; using k = {limit}"
                        );
                        (limit, false)
                    }
                };
                let mut columns = scan.basis;
                columns.truncate(n * k);
                columns.shrink_to_fit();
                (k, met, scan.per_k, columns)
            }
        };
        tracing::debug!(k, rank, tolerance_met, "PCA basis fitted");
        Ok(PcaFit {
            basis: PcaBasis::from_parts(n, k, columns, mass.map(<[f64]>::to_vec), sigma),
            rule,
            numerical_rank: rank,
            tolerance_met,
            max_vertex_error_per_k: per_k,
            appended: 0,
            responses: 0,
            fall_missed: None,
        })
    }
}

/// Non-empty, finite, and not identically zero.
fn check_snapshots(s: MatRef<'_, f64>) -> Result<(), PcaError> {
    let (nrows, ncols) = s.shape();
    if nrows == 0 || ncols == 0 {
        return Err(PcaError::EmptySnapshots { nrows, ncols });
    }
    let mut any_nonzero = false;
    for (col, c) in s.col_iter().enumerate() {
        for (row, &value) in c.iter().enumerate() {
            if !value.is_finite() {
                return Err(PcaError::NonFiniteSnapshot { row, col, value });
            }
            any_nonzero |= value != 0.0;
        }
    }
    if any_nonzero {
        Ok(())
    } else {
        Err(PcaError::ZeroSnapshots)
    }
}

/// Number of singular values above σ_0 · `size` · ε (the usual numerical-rank threshold).
fn numerical_rank(sigma: &[f64], size: usize) -> usize {
    let threshold = sigma.first().copied().unwrap_or(0.0) * size as f64 * f64::EPSILON;
    sigma.iter().take_while(|&&s| s > threshold).count()
}

/// Smallest k ≥ 1 with Σ_{i<k} σ_i² ≥ fraction · Σ_i σ_i², searched over k ≤ `rank`.
///
/// Only roundoff lies beyond the numerical rank, so when the target is not reached by then (a
/// fraction within roundoff of 1) the answer is `rank`.
fn energy_dimension(sigma: &[f64], rank: usize, fraction: f64) -> usize {
    let total: f64 = sigma.iter().map(|s| s * s).sum();
    let target = fraction * total;
    let mut kept = 0.0;
    for (i, s) in sigma.iter().take(rank).enumerate() {
        kept += s * s;
        if kept >= target {
            return i + 1;
        }
    }
    rank.max(1)
}
