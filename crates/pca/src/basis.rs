//! The mass-orthonormal basis U (n × k) with UᵀMU = I: projection, reconstruction, truncation and
//! its serialised form.
//!
//! With a diagonal mass M (the identity when none is given), the coefficients of a vector u are
//! q = UᵀMu and its reconstruction is Uq. Because UᵀMU = I, `U Uᵀ M` is the M-orthogonal projector
//! onto span(U), so q minimises ‖u − Uq‖_M over all q (the normal equations UᵀM(u − Uq) = 0 hold).

use faer::{Mat, MatRef};
use rayon::prelude::*;

use crate::PcaError;
use crate::vertex_error::max_group_norm_sq;

/// A mass-orthonormal PCA basis.
///
/// Stored as plain data (faer matrices have no serde support): the basis is `n × k`, column-major.
/// Deserialisation validates every invariant, so a corrupt artifact is an error, not a panic later.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "BasisData")]
pub struct PcaBasis {
    /// Rows (degrees of freedom).
    n: usize,
    /// Columns (basis dimension).
    k: usize,
    /// U, column-major, `n * k` entries.
    basis: Vec<f64>,
    /// The diagonal of M, length n; `None` means M = I.
    mass: Option<Vec<f64>>,
    /// Every singular value of M^{1/2}S from the fit, non-increasing (min(n, N) of them).
    singular_values: Vec<f64>,
}

/// The serialised form, validated into a [`PcaBasis`] on deserialisation.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct BasisData {
    n: usize,
    k: usize,
    basis: Vec<f64>,
    mass: Option<Vec<f64>>,
    singular_values: Vec<f64>,
}

impl TryFrom<BasisData> for PcaBasis {
    type Error = PcaError;

    fn try_from(d: BasisData) -> Result<Self, PcaError> {
        let bad = |reason: String| Err(PcaError::InvalidBasis(reason));
        if d.n == 0 || d.k == 0 {
            return bad(format!("shape {} × {} is empty", d.n, d.k));
        }
        if d.basis.len() != d.n * d.k {
            return bad(format!(
                "basis has {} entries, expected n·k = {}",
                d.basis.len(),
                d.n * d.k
            ));
        }
        if let Some(i) = d.basis.iter().position(|x| !x.is_finite()) {
            return bad(format!(
                "basis entry (row {}, column {}) is not finite",
                i % d.n,
                i / d.n
            ));
        }
        if let Some(m) = &d.mass {
            check_mass(m, d.n)?;
        }
        if d.singular_values.len() < d.k {
            return bad(format!(
                "{} singular values for a basis of dimension {}",
                d.singular_values.len(),
                d.k
            ));
        }
        if d.singular_values
            .iter()
            .any(|s| !(s.is_finite() && *s >= 0.0))
        {
            return bad("singular values must be finite and non-negative".into());
        }
        if d.singular_values.windows(2).any(|w| w[0] < w[1]) {
            return bad("singular values must be sorted in non-increasing order".into());
        }
        Ok(Self {
            n: d.n,
            k: d.k,
            basis: d.basis,
            mass: d.mass,
            singular_values: d.singular_values,
        })
    }
}

/// Checks that `mass` has `n` positive, finite entries.
pub(crate) fn check_mass(mass: &[f64], n: usize) -> Result<(), PcaError> {
    if mass.len() != n {
        return Err(PcaError::MassLength {
            expected: n,
            found: mass.len(),
        });
    }
    match mass.iter().position(|m| !(m.is_finite() && *m > 0.0)) {
        Some(index) => Err(PcaError::InvalidMass {
            index,
            value: mass[index],
        }),
        None => Ok(()),
    }
}

impl PcaBasis {
    /// A basis from its columns U (`n × k`, column-major), the mass diagonal it is orthonormal
    /// in (`None`: M = I) and the spectrum to report (at least k non-increasing values), checked
    /// like a deserialised one. For bases made elsewhere; [`PcaBasis::fit`] makes its own.
    ///
    /// # Errors
    /// [`PcaError::InvalidBasis`] (shape, non-finite entries, spectrum),
    /// [`PcaError::MassLength`] or [`PcaError::InvalidMass`].
    pub fn new(
        n: usize,
        k: usize,
        basis: Vec<f64>,
        mass: Option<Vec<f64>>,
        singular_values: Vec<f64>,
    ) -> Result<Self, PcaError> {
        Self::try_from(BasisData {
            n,
            k,
            basis,
            mass,
            singular_values,
        })
    }

    /// Assembles a basis from parts the fit has already validated.
    pub(crate) fn from_parts(
        n: usize,
        k: usize,
        basis: Vec<f64>,
        mass: Option<Vec<f64>>,
        singular_values: Vec<f64>,
    ) -> Self {
        debug_assert_eq!(basis.len(), n * k);
        Self {
            n,
            k,
            basis,
            mass,
            singular_values,
        }
    }

    /// Number of rows n (degrees of freedom).
    pub fn n(&self) -> usize {
        self.n
    }

    /// Basis dimension k (number of columns).
    pub fn k(&self) -> usize {
        self.k
    }

    /// U as an `n × k` faer view.
    pub fn basis_ref(&self) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice(&self.basis, self.n, self.k)
    }

    /// Column `i` of U as a slice of length n.
    ///
    /// # Panics
    /// If `i >= k`.
    pub fn column(&self, i: usize) -> &[f64] {
        assert!(i < self.k, "column {i} out of range for k = {}", self.k);
        &self.basis[i * self.n..(i + 1) * self.n]
    }

    /// The diagonal of M, or `None` for M = I.
    pub fn mass(&self) -> Option<&[f64]> {
        self.mass.as_deref()
    }

    /// Every singular value σ_i of M^{1/2}S from the fit, non-increasing; the spectrum to report.
    pub fn singular_values(&self) -> &[f64] {
        &self.singular_values
    }

    /// Fraction of the snapshot energy captured by the first `k` modes,
    /// Σ_{i<k} σ_i² / Σ_i σ_i² (`k` is clamped to the number of singular values).
    ///
    /// `√(1 − fraction)` is the relative Frobenius reconstruction error ‖S − U Uᵀ M S‖_M / ‖S‖_M.
    pub fn explained_energy(&self, k: usize) -> f64 {
        let total: f64 = self.singular_values.iter().map(|s| s * s).sum();
        let kept: f64 = self.singular_values.iter().take(k).map(|s| s * s).sum();
        if total > 0.0 { kept / total } else { 1.0 }
    }

    /// The basis made of the first `k` columns (the singular values are kept whole).
    ///
    /// Fit once with a generous dimension and truncate to compare several k.
    pub fn truncate(&self, k: usize) -> Result<Self, PcaError> {
        if k == 0 || k > self.k {
            return Err(PcaError::DimensionOutOfRange {
                requested: k,
                available: self.k,
            });
        }
        Ok(Self {
            n: self.n,
            k,
            basis: self.basis[..self.n * k].to_vec(),
            mass: self.mass.clone(),
            singular_values: self.singular_values.clone(),
        })
    }

    /// The basis with `directions` (each of length n) appended: each made M-orthogonal to the
    /// columns before it (two passes of Gram–Schmidt) and of unit M-norm, and left out when
    /// less than `min_new` of its M-norm lies outside their span. Returns the basis and, per
    /// direction, the fraction of its M-norm that was new (0 for a zero direction). The
    /// spectrum stays the fit's (padded with zeros where the columns outnumber it).
    ///
    /// # Errors
    /// [`PcaError::InvalidBasis`] when a direction's length is not n or it is not finite.
    pub fn extended(
        &self,
        directions: &[Vec<f64>],
        min_new: f64,
    ) -> Result<(Self, Vec<f64>), PcaError> {
        self.extended_at_most(directions, min_new, usize::MAX)
    }

    /// [`Self::extended`], stopping once `max_count` directions are appended (the fractions
    /// then cover the directions looked at).
    ///
    /// # Errors
    /// As [`Self::extended`].
    pub fn extended_at_most(
        &self,
        directions: &[Vec<f64>],
        min_new: f64,
        max_count: usize,
    ) -> Result<(Self, Vec<f64>), PcaError> {
        let n = self.n;
        let mass = self.mass.as_deref();
        let mut basis = self.basis.clone();
        let mut new_fractions = Vec::with_capacity(directions.len());
        for (i, d) in directions.iter().enumerate() {
            if basis.len() / n - self.k >= max_count {
                break;
            }
            if d.len() != n || d.iter().any(|x| !x.is_finite()) {
                return Err(PcaError::InvalidBasis(format!(
                    "direction {i} to append has {} entries (n = {n}) or a non-finite one",
                    d.len()
                )));
            }
            let norm = m_dot(mass, d, d).sqrt();
            let mut r = d.clone();
            let left = orthogonalise(&mut r, &basis, mass);
            let fraction = if norm > 0.0 { left / norm } else { 0.0 };
            new_fractions.push(fraction);
            if norm > 0.0 && fraction >= min_new {
                basis.extend(r.iter().map(|x| x / left));
            }
        }
        let k = basis.len() / n;
        // The spectrum covers every column (a basis of all min(n, N) modes plus more).
        let mut singular_values = self.singular_values.clone();
        if singular_values.len() < k {
            singular_values.resize(k, 0.0);
        }
        Ok((
            Self::from_parts(n, k, basis, self.mass.clone(), singular_values),
            new_fractions,
        ))
    }

    /// q = UᵀMu, the M-orthogonal projection coefficients of `u`.
    ///
    /// # Panics
    /// If `u.len() != n` or `q.len() != k`.
    pub fn project(&self, u: &[f64], q: &mut [f64]) {
        assert_eq!(u.len(), self.n, "project: u must have n entries");
        assert_eq!(q.len(), self.k, "project: q must have k entries");
        for (qi, col) in q.iter_mut().zip(self.basis.chunks_exact(self.n)) {
            *qi = m_dot(self.mass.as_deref(), col, u);
        }
    }

    /// u = Uq.
    ///
    /// # Panics
    /// If `q.len() != k` or `u.len() != n`.
    pub fn reconstruct(&self, q: &[f64], u: &mut [f64]) {
        assert_eq!(q.len(), self.k, "reconstruct: q must have k entries");
        assert_eq!(u.len(), self.n, "reconstruct: u must have n entries");
        u.fill(0.0);
        for (qi, col) in q.iter().zip(self.basis.chunks_exact(self.n)) {
            for (ui, c) in u.iter_mut().zip(col) {
                *ui += qi * c;
            }
        }
    }

    /// Q = UᵀMS (k × N) for snapshots S (n × N), one column per snapshot.
    ///
    /// # Panics
    /// If `snapshots.nrows() != n`.
    pub fn project_matrix(&self, snapshots: MatRef<'_, f64>) -> Mat<f64> {
        assert_eq!(
            snapshots.nrows(),
            self.n,
            "project_matrix: snapshots must have n rows"
        );
        let u = self.basis_ref();
        match &self.mass {
            Some(m) => {
                let ms = Mat::from_fn(self.n, snapshots.ncols(), |i, j| m[i] * snapshots[(i, j)]);
                u.transpose() * ms
            }
            None => u.transpose() * snapshots,
        }
    }

    /// S = UQ (n × N) for coefficients Q (k × N).
    ///
    /// # Panics
    /// If `coefficients.nrows() != k`.
    pub fn reconstruct_matrix(&self, coefficients: MatRef<'_, f64>) -> Mat<f64> {
        assert_eq!(
            coefficients.nrows(),
            self.k,
            "reconstruct_matrix: coefficients must have k rows"
        );
        self.basis_ref() * coefficients
    }

    /// The largest per-vertex reconstruction distance over all snapshots,
    /// max_{v, j} ‖s_{v,j} − (U UᵀM s_j)_v‖₂, where vertex v owns rows `group·v .. group·(v+1)`.
    pub fn max_group_error(
        &self,
        snapshots: MatRef<'_, f64>,
        group: usize,
    ) -> Result<f64, PcaError> {
        self.check_groups(snapshots, group)?;
        let mut residual = self.reconstruct_matrix(self.project_matrix(snapshots).as_ref());
        residual -= snapshots;
        let max_sq = (0..residual.ncols())
            .into_par_iter()
            .map(|j| max_group_norm_sq(residual.col_as_slice(j), group))
            .reduce(|| 0.0, f64::max);
        Ok(max_sq.sqrt())
    }

    /// [`Self::max_group_error`] of the first k columns for k = 1, 2, …, up to the first k for
    /// which `stop(k, error)` holds or all of them: one incremental pass (rank-one updates of
    /// the residual, `K_BLOCK` columns per sweep over it) instead of a reconstruction per k.
    /// Valid for any M-orthonormal columns, appended ones included, since their coefficients are
    /// the projections UᵀMS.
    pub fn max_group_errors(
        &self,
        snapshots: MatRef<'_, f64>,
        group: usize,
        stop: impl Fn(usize, f64) -> bool,
    ) -> Result<Vec<f64>, PcaError> {
        self.check_groups(snapshots, group)?;
        let q = self.project_matrix(snapshots);
        let n = self.n;
        let scan = crate::vertex_error::scan_max_vertex_error(
            snapshots,
            self.k,
            |start, count| self.basis[start * n..(start + count) * n].to_vec(),
            |j, i| q[(i, j)],
            group,
            stop,
        );
        Ok(scan.per_k)
    }

    /// Snapshots of n rows, and vertices of `group` rows that tile them.
    fn check_groups(&self, snapshots: MatRef<'_, f64>, group: usize) -> Result<(), PcaError> {
        if snapshots.nrows() != self.n {
            return Err(PcaError::ShapeMismatch {
                what: "snapshot matrix",
                expected: (self.n, snapshots.ncols()),
                found: snapshots.shape(),
            });
        }
        if group == 0 || !self.n.is_multiple_of(group) {
            return Err(PcaError::InvalidGroup {
                group,
                nrows: self.n,
            });
        }
        Ok(())
    }
}

/// aᵀMb (M = I without a mass), summed in order so that it reproduces bit for bit.
pub(crate) fn m_dot(mass: Option<&[f64]>, a: &[f64], b: &[f64]) -> f64 {
    match mass {
        Some(m) => a.iter().zip(b).zip(m).map(|((a, b), m)| a * m * b).sum(),
        None => a.iter().zip(b).map(|(a, b)| a * b).sum(),
    }
}

/// Makes `v` M-orthogonal to the M-orthonormal columns `basis` (column-major, `v.len()` rows
/// each) by two passes of modified Gram–Schmidt, and returns the M-norm left (`mass` `None`:
/// M = I).
pub fn orthogonalise(v: &mut [f64], basis: &[f64], mass: Option<&[f64]>) -> f64 {
    for _ in 0..2 {
        for col in basis.chunks_exact(v.len()) {
            let c = m_dot(mass, col, v);
            v.iter_mut().zip(col).for_each(|(r, u)| *r -= c * u);
        }
    }
    m_dot(mass, v, v).sqrt()
}
