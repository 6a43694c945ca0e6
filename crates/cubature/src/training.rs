//! The training matrix: per-element reduced forces over the training poses, normalised per pose.
//!
//! For pose i with PCA coefficients q_i (and, for a nonlinear subspace, the Jacobian
//! J_i = ∂q/∂z, k × d), the reduced force of element e is
//!
//! g_{e,i} = J_iᵀ U_eᵀ f_e(U q_i),
//!
//! where f_e = ∂V_e/∂u_e is the element's 12-vector gradient and U_e the 12 × k rows of the basis
//! for its four vertices (zero rows for pinned DOFs). The target is b_i = Σ_e g_{e,i}, the reduced
//! force of the whole mesh. Each pose's rows (all g_{e,i} and b_i) are divided by ‖b_i‖, so every
//! pose counts equally whatever its deformation; poses with ‖b_i‖ ≈ 0 (at rest) are skipped. The
//! stacked matrix A has one column per element and P·d rows; b has P·d entries.
//!
//! Memory: A takes 8·P·d·m bytes (m elements) plus 8·P·3n for the pose displacements; 150 poses of
//! a 49-dimensional basis on 30,000 elements is 1.8 GB. [`CubatureConfig::max_poses`] caps P (a
//! seeded subsample, as AutoDef fitted on a subset of poses). When those do not fit
//! [`CubatureConfig::memory_limit_mb`], A keeps the columns of a seeded subsample of the elements
//! only, the candidates the rule is chosen from, down to [`CANDIDATES_PER_RULE_ELEMENT`] times
//! [`CubatureConfig::max_elements`]; the target b still sums every element's force, evaluated
//! and added up without being kept. Only then does the pose subsample shrink (a warning says
//! so), and only below [`MIN_POSES`] poses is it [`CubatureError::MemoryLimit`], never an
//! allocation failure. Poses where an element's force is not finite (inverted under a material
//! undefined there) are left out of the fit and listed ([`TrainingMatrix::invalid_poses`]).
//!
//! [`HeldOutForces`] measures a rule on poses it was not fitted to without that matrix: the
//! targets from one assembly of the whole mesh per pose, the columns of the elements asked
//! about only. `max_poses` caps its poses too; the memory limit does not apply to it.

use std::collections::HashMap;

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use fem_core::constraints::FIXED;
use fem_core::integrator::FullSpaceModel;
use fem_core::rng::SplitMix64;
use fem_core::with_material;
use rayon::prelude::*;

use crate::nnls::{check_finite, norm};
use crate::{CubatureConfig, CubatureError};

/// Poses whose target norm is below this fraction of the largest are treated as at rest.
pub const ZERO_POSE_TOLERANCE: f64 = 1e-10;

/// The fewest training poses the memory budget may cut a fit down to.
pub const MIN_POSES: usize = 16;

/// The fewest candidate elements, per element of the rule's budget, that the memory budget may
/// cut A's columns down to before it cuts poses: a 500-element rule is chosen from at least
/// 4,000 elements.
pub const CANDIDATES_PER_RULE_ELEMENT: usize = 8;

/// Salt of the pose-subsample stream, so it differs from the candidate stream of the same seed.
const POSE_SALT: u64 = 0x7053_4D50_4C45_0001;

/// Salt of the candidate-element subsample of a mesh whose A does not fit the memory budget.
const ELEMENT_SALT: u64 = 0x454C_454D_454E_0003;

/// Elements per parallel task when summing the forces of the elements A does not keep.
const OTHERS_BLOCK: usize = 512;

/// One task's sum of those forces (poses × k), and the first of its elements whose force is
/// not finite with the pose where.
type BlockSum = (Vec<f64>, Option<(usize, usize)>);

/// Training poses: PCA coefficients and, for a nonlinear subspace, the decoder Jacobians.
#[derive(Debug, Clone, Copy)]
pub struct Poses<'a> {
    /// q_i, k × P: one pose per column.
    pub q: MatRef<'a, f64>,
    /// J_i = ∂q/∂z at each pose, P matrices of k × d; `None` for the linear subspace (J = I).
    pub jacobians: Option<&'a [MatRef<'a, f64>]>,
    /// `Some(n)` when these are the [`kept_poses`] of a set of `n` ([`Poses::kept_of`]): the fit
    /// then keeps, and numbers, the poses it would have kept of all `n`.
    pub kept_of: Option<usize>,
}

impl<'a> Poses<'a> {
    /// Poses of the linear subspace (u = Uq, reduced coordinates q).
    pub fn linear(q: MatRef<'a, f64>) -> Self {
        Self {
            q,
            jacobians: None,
            kept_of: None,
        }
    }

    /// Poses of a nonlinear subspace q = q(z), with J_i = ∂q/∂z at pose i.
    pub fn nonlinear(q: MatRef<'a, f64>, jacobians: &'a [MatRef<'a, f64>]) -> Self {
        Self {
            q,
            jacobians: Some(jacobians),
            kept_of: None,
        }
    }

    /// These poses as the [`kept_poses`] of a set of `total` (in that order): the fit keeps
    /// exactly the poses, numbered as in the whole set, that it would keep of all `total`, also
    /// where the memory limit makes it keep fewer.
    pub fn kept_of(self, total: usize) -> Self {
        Self {
            kept_of: Some(total),
            ..self
        }
    }
}

/// The stacked, per-pose normalised reduced forces: A (rows × m, column-major, one column per
/// element) and the target b = A·1.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingMatrix {
    rows: usize,
    dim: usize,
    /// The mesh's elements.
    elements: usize,
    /// The element of each column when A keeps a subsample of them (increasing), `None` when
    /// it keeps every element in order.
    candidates: Option<Vec<usize>>,
    a: Vec<f64>,
    b: Vec<f64>,
    pose_indices: Vec<usize>,
    pose_scales: Vec<f64>,
    skipped_poses: Vec<usize>,
    invalid_poses: Vec<usize>,
}

impl TrainingMatrix {
    /// Builds the training matrix of `model` for the basis U (`basis`, n_free × k column-major
    /// on the model's free DOFs) at `poses`, keeping at most `config.max_poses` of them.
    ///
    /// Element forces are evaluated in parallel over elements; each element reads only the basis
    /// rows of its own four vertices.
    pub fn build(
        model: &FullSpaceModel,
        basis: &[f64],
        k: usize,
        poses: Poses<'_>,
        config: &CubatureConfig,
    ) -> Result<Self, CubatureError> {
        config.validate()?;
        let dim = check_inputs(model, basis, k, &poses)?;
        let m = model.elements.len();
        // Poses are numbered, and subsampled, as in the whole set they were kept from.
        let given = match poses.kept_of {
            Some(total) => {
                let kept = kept_poses(total, config);
                if kept.len() != poses.q.ncols() {
                    return Err(CubatureError::ShapeMismatch {
                        what: "poses kept of the whole set (kept_poses)",
                        expected: (k, kept.len()),
                        found: (k, poses.q.ncols()),
                    });
                }
                Some(kept)
            }
            None => None,
        };
        let num_poses = poses.kept_of.unwrap_or(poses.q.ncols());

        // A matrix beyond the memory budget keeps the columns of fewer elements first, down to
        // CANDIDATES_PER_RULE_ELEMENT per element of the rule's budget: the rule is chosen from
        // those, and the target still sums every element. Then poses are left out of the
        // subsample (with a warning), down to MIN_POSES: a large mesh fits the default budget
        // instead of stopping the stage. Below that the fit would be too thin to trust, and that
        // is an error naming the settings that would work.
        let n_full = model.num_full() as u128;
        let limit = config.memory_limit_mb as u128 * (1 << 20);
        let wanted = num_poses.min(config.max_poses);
        let bytes = |poses: usize, columns: usize| {
            8 * poses as u128 * (dim as u128 * columns as u128 + n_full)
        };
        let floor = m.min(CANDIDATES_PER_RULE_ELEMENT.saturating_mul(config.max_elements));
        let columns = if bytes(wanted, m) <= limit {
            m
        } else {
            let room = limit.saturating_sub(8 * wanted as u128 * n_full)
                / (8 * wanted as u128 * dim as u128);
            (room.min(m as u128) as usize).max(floor)
        };
        let per_pose = bytes(1, columns);
        let fit = (limit / per_pose).min(wanted as u128) as usize;
        if fit < wanted.min(MIN_POSES) {
            let needed = per_pose * wanted.min(MIN_POSES) as u128;
            let mib = |bytes: u128| bytes.div_ceil(1 << 20).min(u64::MAX as u128) as u64;
            return Err(CubatureError::MemoryLimit {
                needed_mb: mib(needed),
                all_mb: mib(per_pose * wanted as u128),
                all_poses: wanted,
                limit_mb: config.memory_limit_mb,
                poses: wanted.min(MIN_POSES),
                dim,
                elements: columns,
            });
        }
        if columns < m {
            tracing::info!(
                "cubature: the training matrix keeps {columns} of the {m} elements as \
                 candidates, so that {fit} poses × {dim} reduced coordinates fit \
                 `cubature.memory_limit_mb` = {}; the target forces sum every element",
                config.memory_limit_mb
            );
        }
        if fit < wanted {
            tracing::warn!(
                "cubature: {fit} of {wanted} training poses fit `cubature.memory_limit_mb` = {} \
                 ({dim} reduced coordinates × {columns} candidate elements of {m}, {:.3} MiB \
                 a pose); fitting on those (`memory_limit_mb` = {} keeps all {wanted}; a \
                 tester's rule fitted on 16 of 150 missed the test's forces by 6.3 % against \
                 1.7 %)",
                config.memory_limit_mb,
                per_pose as f64 / (1u64 << 20) as f64,
                (per_pose * wanted as u128).div_ceil(1 << 20)
            );
        }
        let candidates =
            (columns < m).then(|| subsample_with(m, columns, config.seed ^ ELEMENT_SALT));
        let chosen = subsample(num_poses, fit, config.seed);
        // Where each chosen pose is among those given: itself, or its place among the kept ones
        // (a subsample of fit is within the subsample of more: the same draws, fewer of them).
        let local: Vec<usize> = match &given {
            Some(kept) => chosen
                .iter()
                .map(|c| {
                    kept.binary_search(c)
                        .expect("a subsample lies within a larger one")
                })
                .collect(),
            None => chosen.clone(),
        };
        let np = chosen.len();
        let rows = np * dim;
        let bytes = per_pose * np as u128;
        tracing::debug!(
            poses = np,
            dim,
            elements = m,
            columns,
            mib = (bytes >> 20) as u64,
            "building the cubature training matrix"
        );

        let (displacements, jacobians) = chosen_poses(model, basis, &poses, &local);

        let element_of = |c: usize| candidates.as_ref().map_or(c, |ids| ids[c]);
        let mut a = vec![0.0; rows * columns];
        // The forces of the elements A does not keep, summed (zero when it keeps them all).
        let mut rest = vec![0.0; rows];
        let mut rest_not_finite = None;
        with_material!(&model.material, |material| {
            let forces = ElementForces {
                model,
                basis,
                k,
                displacements: &displacements,
                jacobians: jacobians.as_deref(),
            };
            a.par_chunks_mut(rows).enumerate().for_each_init(
                || (vec![0.0; 12 * k], vec![0.0; k]),
                |(ue, g), (c, column)| forces.column(material, element_of(c), column, ue, g),
            );
            if let Some(ids) = &candidates {
                let mut kept = vec![false; m];
                ids.iter().for_each(|&e| kept[e] = true);
                let others: Vec<usize> = (0..m).filter(|&e| !kept[e]).collect();
                // Fixed blocks summed in order, so that a seed always gives the same target;
                // summed in the k PCA coordinates, each pose's tangent applied once after.
                let sums: Vec<BlockSum> = others
                    .par_chunks(OTHERS_BLOCK)
                    .map(|block| {
                        let mut sum = vec![0.0; np * k];
                        let (mut ue, mut g) = (vec![0.0; 12 * k], vec![0.0; k]);
                        let mut not_finite = None;
                        for &e in block {
                            let bad =
                                forces.add_reduced_forces(material, e, &mut sum, &mut ue, &mut g);
                            not_finite = not_finite.or(bad.map(|p| (e, p)));
                        }
                        (sum, not_finite)
                    })
                    .collect();
                let mut total = vec![0.0; np * k];
                for (sum, bad) in sums {
                    total.iter_mut().zip(&sum).for_each(|(t, x)| *t += x);
                    rest_not_finite = rest_not_finite.or(bad);
                }
                forces.apply_tangents(&total, &mut rest);
            }
        });
        drop(displacements);
        // A pose where some element's force is not finite (an element that a reconstructed or
        // decoded pose inverts, under a material undefined there) is left out of the fit like a
        // pose at rest; only when every pose is, the stage fails, naming the first such element.
        let mut invalid = vec![false; np];
        for column in a.chunks(rows).chain([&rest[..]]) {
            for (p, block) in column.chunks(dim).enumerate() {
                if !invalid[p] && block.iter().any(|x| !x.is_finite()) {
                    invalid[p] = true;
                }
            }
        }
        if invalid.iter().all(|&bad| bad) {
            return Err(match a.iter().position(|x| !x.is_finite()) {
                Some(idx) => CubatureError::NonFiniteForce {
                    element: element_of(idx / rows),
                    pose: chosen[(idx % rows) / dim],
                },
                // Only among the elements A does not keep.
                None => {
                    let (element, block) = rest_not_finite.unwrap_or((0, 0));
                    CubatureError::NonFiniteForce {
                        element,
                        pose: chosen[block],
                    }
                }
            });
        }
        let invalid_poses: Vec<usize> =
            (0..np).filter(|&p| invalid[p]).map(|p| chosen[p]).collect();
        if !invalid_poses.is_empty() {
            tracing::warn!(
                "cubature: {} of {np} training poses have an element whose force is not finite \
                 there (inverted under the material) and are left out of the fit",
                invalid_poses.len()
            );
            for column in a.chunks_mut(rows).chain([&mut rest[..]]) {
                for (p, block) in column.chunks_mut(dim).enumerate() {
                    if invalid[p] {
                        block.fill(0.0);
                    }
                }
            }
        }
        let mut b = column_sum(&a, rows, columns);
        b.iter_mut().zip(&rest).for_each(|(b, r)| *b += r);
        let scales: Vec<f64> = b.chunks(dim).map(norm).collect();
        let largest = scales.iter().copied().fold(0.0, f64::max);
        if largest == 0.0 {
            return Err(CubatureError::ZeroTarget { poses: np });
        }
        let keep: Vec<usize> = (0..np)
            .filter(|&p| scales[p] > ZERO_POSE_TOLERANCE * largest)
            .collect();
        let skipped_poses: Vec<usize> = (0..np)
            .filter(|&p| !keep.contains(&p) && !invalid[p])
            .map(|p| chosen[p])
            .collect();
        if !skipped_poses.is_empty() {
            tracing::debug!(
                skipped = skipped_poses.len(),
                "poses at rest left out of the cubature fit"
            );
        }
        let new_rows = keep.len() * dim;
        let inv: Vec<f64> = keep.iter().map(|&p| 1.0 / scales[p]).collect();
        // Compact and normalise in place: the new column c starts at or before the old one.
        let compact = |column: &mut [f64], c: usize| {
            for (kp, &p) in keep.iter().enumerate() {
                let (src, dst) = (c * rows + p * dim, c * new_rows + kp * dim);
                column.copy_within(src..src + dim, dst);
                for x in &mut column[dst..dst + dim] {
                    *x *= inv[kp];
                }
            }
        };
        for c in 0..columns {
            compact(&mut a, c);
        }
        compact(&mut rest, 0);
        a.truncate(new_rows * columns);
        a.shrink_to_fit();
        let mut b = column_sum(&a, new_rows, columns);
        b.iter_mut().zip(&rest).for_each(|(b, r)| *b += r);
        Ok(Self {
            rows: new_rows,
            dim,
            elements: m,
            candidates,
            a,
            b,
            pose_indices: keep.iter().map(|&p| chosen[p]).collect(),
            pose_scales: keep.iter().map(|&p| scales[p]).collect(),
            skipped_poses,
            invalid_poses,
        })
    }

    /// A training matrix from given data: A (rows × elements), b, and the number of reduced
    /// coordinates per pose `dim` (rows must be a multiple of it). No normalisation is applied.
    pub fn from_matrix(a: MatRef<'_, f64>, b: &[f64], dim: usize) -> Result<Self, CubatureError> {
        let (rows, m) = (a.nrows(), a.ncols());
        if m == 0 {
            return Err(CubatureError::NoElements);
        }
        if rows == 0 || dim == 0 || rows % dim != 0 {
            return Err(CubatureError::ShapeMismatch {
                what: "training matrix A (poses·d × elements)",
                expected: (rows.div_ceil(dim.max(1)).max(1) * dim.max(1), m),
                found: (rows, m),
            });
        }
        if b.len() != rows {
            return Err(CubatureError::ShapeMismatch {
                what: "target b",
                expected: (rows, 1),
                found: (b.len(), 1),
            });
        }
        let data: Vec<f64> = (0..m).flat_map(|j| a.col(j).iter().copied()).collect();
        check_finite("training matrix A", data.iter().copied())?;
        check_finite("target b", b.iter().copied())?;
        if b.iter().all(|&x| x == 0.0) {
            return Err(CubatureError::ZeroTarget { poses: rows / dim });
        }
        Ok(Self {
            rows,
            dim,
            elements: m,
            candidates: None,
            a: data,
            b: b.to_vec(),
            pose_indices: (0..rows / dim).collect(),
            pose_scales: vec![1.0; rows / dim],
            skipped_poses: Vec::new(),
            invalid_poses: Vec::new(),
        })
    }

    /// A as a faer view, rows × columns (a column per element, or per candidate element when
    /// the matrix keeps a subsample of them: [`TrainingMatrix::element_of`]).
    pub fn a(&self) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice(&self.a, self.rows, self.num_columns())
    }

    /// Column `c`: the normalised reduced forces of element [`TrainingMatrix::element_of`]`(c)`
    /// over all poses.
    pub fn column(&self, c: usize) -> &[f64] {
        &self.a[c * self.rows..(c + 1) * self.rows]
    }

    /// Number of columns: the elements a rule is chosen from.
    pub fn num_columns(&self) -> usize {
        self.candidates.as_ref().map_or(self.elements, Vec::len)
    }

    /// The element of column `c`.
    pub fn element_of(&self, c: usize) -> usize {
        self.candidates.as_ref().map_or(c, |ids| ids[c])
    }

    /// The column of element `e`, if the matrix keeps it.
    pub fn column_of(&self, e: usize) -> Option<usize> {
        match &self.candidates {
            None => (e < self.elements).then_some(e),
            Some(ids) => ids.binary_search(&e).ok(),
        }
    }

    /// The target b = Σ_e a_e (each pose block has unit norm after normalisation).
    pub fn b(&self) -> &[f64] {
        &self.b
    }

    /// Number of rows, poses × d.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Reduced coordinates per pose (k for the linear subspace, d for a nonlinear one).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of the mesh's elements (as many as the columns, unless the matrix keeps a
    /// subsample of them).
    pub fn num_elements(&self) -> usize {
        self.elements
    }

    /// Number of poses in the matrix.
    pub fn num_poses(&self) -> usize {
        self.pose_indices.len()
    }

    /// Index (into the poses given to [`TrainingMatrix::build`]) of each pose block, in order.
    pub fn pose_indices(&self) -> &[usize] {
        &self.pose_indices
    }

    /// ‖b_i‖ before normalisation for each pose block: the pose's unnormalised reduced force is
    /// `pose_scales()[p]` times block p of [`TrainingMatrix::b`].
    pub fn pose_scales(&self) -> &[f64] {
        &self.pose_scales
    }

    /// Chosen poses left out because their target force was (numerically) zero.
    pub fn skipped_poses(&self) -> &[usize] {
        &self.skipped_poses
    }

    /// Chosen poses left out because some element's force was not finite there (an element
    /// inverted under a material that is undefined for inverted elements).
    pub fn invalid_poses(&self) -> &[usize] {
        &self.invalid_poses
    }
}

/// The reduced forces of poses a rule was not fitted to, for the rule's error there (the
/// held-out test's frames), normalised per pose as in [`TrainingMatrix`] and giving the same
/// error as [`CubatureRule::evaluate`](crate::CubatureRule::evaluate) on a matrix of every
/// element built from all of them.
///
/// The target b_i comes from one assembly of the whole mesh's force per pose, b_i = J_iᵀ Uᵀ f(u_i),
/// and A's columns are computed only for the elements asked about, when first asked, and kept.
/// A [`TrainingMatrix`] of the same poses holds every element's column: 8·P·d·m bytes, about
/// 2 GB for 100 poses of 85 coordinates on 29k elements, built at the cost of the training
/// matrix itself, where a greedy path visits a few hundred elements. The memory limit does not
/// apply (this holds P full displacements and the visited columns); `max_poses` and the seed
/// choose the poses as there, and poses where an element's force is not finite are left out
/// and listed ([`HeldOutForces::invalid_poses`]), with a warning.
pub struct HeldOutForces<'a> {
    model: &'a FullSpaceModel,
    basis: &'a [f64],
    k: usize,
    dim: usize,
    displacements: Vec<Vec<f64>>,
    jacobians: Option<Vec<MatRef<'a, f64>>>,
    /// 1 / ‖b_i‖ of each pose kept.
    inv_scales: Vec<f64>,
    b: Vec<f64>,
    invalid_poses: Vec<usize>,
    columns: HashMap<usize, Vec<f64>>,
}

impl std::fmt::Debug for HeldOutForces<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HeldOutForces")
            .field("k", &self.k)
            .field("dim", &self.dim)
            .field("poses", &self.inv_scales.len())
            .field("columns", &self.columns.len())
            .finish_non_exhaustive()
    }
}

impl<'a> HeldOutForces<'a> {
    /// The poses' targets (see the type's docs); poses where the force is not finite (an element
    /// the pose inverts, under a material undefined there) or zero (at rest) are left out, as
    /// [`TrainingMatrix::build`] leaves them out.
    pub fn new(
        model: &'a FullSpaceModel,
        basis: &'a [f64],
        k: usize,
        poses: Poses<'a>,
        config: &CubatureConfig,
    ) -> Result<Self, CubatureError> {
        config.validate()?;
        let dim = check_inputs(model, basis, k, &poses)?;
        let chosen = subsample(poses.q.ncols(), config.max_poses, config.seed);
        let (displacements, jacobians) = chosen_poses(model, basis, &poses, &chosen);
        let dofs = &model.dofs;
        let nf = dofs.num_free();
        // Each pose's target, or the first element whose force is not finite there (any entry,
        // a pinned DOF's too, as a column of TrainingMatrix is then not finite either).
        let targets: Vec<Result<Vec<f64>, usize>> = with_material!(&model.material, |material| {
            displacements
                .par_iter()
                .enumerate()
                .map(|(p, u)| {
                    let elements = &model.elements;
                    let mut f = vec![0.0; u.len()];
                    for (e, tet) in elements.tets.iter().enumerate() {
                        let (_, fe, _) = elements.energy_gradient(material, e, u, 1.0);
                        if !fe.iter().all(|x| x.is_finite()) {
                            return Err(e);
                        }
                        for (a, &v) in tet.iter().enumerate() {
                            for c in 0..3 {
                                f[3 * v + c] += fe[3 * a + c];
                            }
                        }
                    }
                    let g: Vec<f64> = (0..k)
                        .map(|j| {
                            let col = &basis[j * nf..(j + 1) * nf];
                            col.iter().zip(&dofs.free).map(|(x, &r)| x * f[r]).sum()
                        })
                        .collect();
                    let mut out = vec![0.0; dim];
                    tangent_transpose_product(jacobians.as_ref().map(|js| js[p]), &g, &mut out);
                    Ok(out)
                })
                .collect()
        });
        let invalid_poses: Vec<usize> = (0..chosen.len())
            .filter(|&p| targets[p].is_err())
            .map(|p| chosen[p])
            .collect();
        if invalid_poses.len() == chosen.len() {
            return Err(CubatureError::NonFiniteForce {
                element: targets[0].as_ref().err().copied().unwrap_or(0),
                pose: chosen[0],
            });
        }
        if !invalid_poses.is_empty() {
            tracing::warn!(
                "cubature: {} of {} held-out poses have an element whose force is not finite \
                 there (inverted under the material) and are left out of the error",
                invalid_poses.len(),
                chosen.len()
            );
        }
        let scales: Vec<f64> = targets
            .iter()
            .map(|t| t.as_ref().map_or(0.0, |t| norm(t)))
            .collect();
        let largest = scales.iter().copied().fold(0.0, f64::max);
        if largest == 0.0 || !largest.is_finite() {
            return Err(CubatureError::ZeroTarget {
                poses: chosen.len(),
            });
        }
        let keep: Vec<usize> = (0..chosen.len())
            .filter(|&p| targets[p].is_ok() && scales[p] > ZERO_POSE_TOLERANCE * largest)
            .collect();
        let inv_scales: Vec<f64> = keep.iter().map(|&p| 1.0 / scales[p]).collect();
        let b = keep
            .iter()
            .zip(&inv_scales)
            .flat_map(|(&p, &s)| targets[p].iter().flatten().map(move |x| x * s))
            .collect();
        let displacements = displacements
            .into_iter()
            .enumerate()
            .filter(|(p, _)| keep.binary_search(p).is_ok())
            .map(|(_, u)| u)
            .collect();
        let jacobians = jacobians.map(|js| keep.iter().map(|&p| js[p]).collect());
        Ok(Self {
            model,
            basis,
            k,
            dim,
            displacements,
            jacobians,
            inv_scales,
            b,
            invalid_poses,
            columns: HashMap::new(),
        })
    }

    /// The number of poses kept.
    pub fn num_poses(&self) -> usize {
        self.inv_scales.len()
    }

    /// The target b: each kept pose's reduced force over the whole mesh, divided by its norm.
    pub fn b(&self) -> &[f64] {
        &self.b
    }

    /// Poses (indices into the poses given) left out because an element's force is not finite
    /// there, as [`TrainingMatrix::invalid_poses`].
    pub fn invalid_poses(&self) -> &[usize] {
        &self.invalid_poses
    }

    /// ‖A_S w − b‖ / ‖b‖ for elements S with weights w, in any order (the columns of S not yet
    /// computed are, in parallel, and kept for the next call).
    ///
    /// # Errors
    /// [`CubatureError::InvalidRule`] when the lengths differ or an element is out of range.
    pub fn relative_error(
        &mut self,
        elements: &[usize],
        weights: &[f64],
    ) -> Result<f64, CubatureError> {
        let m = self.model.elements.len();
        if elements.len() != weights.len() {
            return Err(CubatureError::InvalidRule(format!(
                "{} elements and {} weights",
                elements.len(),
                weights.len()
            )));
        }
        if let Some(&e) = elements.iter().find(|&&e| e >= m) {
            return Err(CubatureError::InvalidRule(format!(
                "element {e} is out of range for a mesh of {m} elements"
            )));
        }
        let mut missing: Vec<usize> = elements
            .iter()
            .copied()
            .filter(|e| !self.columns.contains_key(e))
            .collect();
        missing.sort_unstable();
        missing.dedup();
        let (k, p) = (self.k, self.inv_scales.len());
        let forces = ElementForces {
            model: self.model,
            basis: self.basis,
            k,
            displacements: &self.displacements,
            jacobians: self.jacobians.as_deref(),
        };
        let inv_scales = &self.inv_scales;
        let dim = self.dim;
        let computed: Vec<(usize, Vec<f64>)> = with_material!(&self.model.material, |material| {
            missing
                .par_iter()
                .map_init(
                    || (vec![0.0; 12 * k], vec![0.0; k]),
                    |(ue, g), &e| {
                        let mut column = vec![0.0; p * dim];
                        forces.column(material, e, &mut column, ue, g);
                        for (block, s) in column.chunks_mut(dim).zip(inv_scales) {
                            block.iter_mut().for_each(|x| *x *= s);
                        }
                        (e, column)
                    },
                )
                .collect()
        });
        self.columns.extend(computed);
        let mut r: Vec<f64> = self.b.iter().map(|x| -x).collect();
        for (e, &w) in elements.iter().zip(weights) {
            for (ri, a) in r.iter_mut().zip(&self.columns[e]) {
                *ri += w * a;
            }
        }
        Ok(norm(&r) / norm(&self.b).max(f64::MIN_POSITIVE))
    }
}

/// The full displacements u_i = U q_i of poses `chosen`, and their tangents J_i for a nonlinear
/// subspace.
fn chosen_poses<'a>(
    model: &FullSpaceModel,
    basis: &[f64],
    poses: &Poses<'a>,
    chosen: &[usize],
) -> (Vec<Vec<f64>>, Option<Vec<MatRef<'a, f64>>>) {
    let dofs = &model.dofs;
    let (nf, n_full) = (dofs.num_free(), model.num_full());
    let q = poses.q;
    let displacements = chosen
        .par_iter()
        .map(|&i| {
            let mut u = vec![0.0; n_full];
            for (j, &qj) in q.col(i).iter().enumerate() {
                if qj != 0.0 {
                    for (r, &full) in dofs.free.iter().enumerate() {
                        u[full] += basis[j * nf + r] * qj;
                    }
                }
            }
            u
        })
        .collect();
    let jacobians = poses
        .jacobians
        .map(|js| chosen.iter().map(|&i| js[i]).collect());
    (displacements, jacobians)
}

/// `out` = Jᵀg for a nonlinear subspace's tangent J (k × d), g itself for a linear one.
fn tangent_transpose_product(jacobian: Option<MatRef<'_, f64>>, g: &[f64], out: &mut [f64]) {
    match jacobian {
        None => out.copy_from_slice(g),
        // Through faer's SIMD kernels: this product was two thirds of the neural rule's
        // stage as a scalar dot per coordinate.
        Some(j) => matmul(
            MatMut::from_column_major_slice_mut(out, j.ncols(), 1),
            Accum::Replace,
            j.transpose(),
            MatRef::from_column_major_slice(g, j.nrows(), 1),
            1.0,
            Par::Seq,
        ),
    }
}

/// What the reduced force of one element at each pose needs: the basis, the poses' full
/// displacements and, for a nonlinear subspace, their tangents.
struct ElementForces<'a, 'b> {
    model: &'a FullSpaceModel,
    basis: &'a [f64],
    k: usize,
    displacements: &'a [Vec<f64>],
    jacobians: Option<&'a [MatRef<'b, f64>]>,
}

impl ElementForces<'_, '_> {
    /// U_e, 12 × k row-major, zero rows for fixed DOFs, into `ue`.
    fn basis_rows(&self, e: usize, ue: &mut [f64]) {
        let (k, dofs) = (self.k, &self.model.dofs);
        let nf = dofs.num_free();
        for (a_local, &v) in self.model.elements.tets[e].iter().enumerate() {
            for c in 0..3 {
                let row = &mut ue[(3 * a_local + c) * k..(3 * a_local + c + 1) * k];
                match dofs.index[3 * v + c] {
                    FIXED => row.fill(0.0),
                    r => {
                        for (j, x) in row.iter_mut().enumerate() {
                            *x = self.basis[j * nf + r];
                        }
                    }
                }
            }
        }
    }

    /// g_i = U_eᵀ f_e(u_i) of element `e` at every pose i, each handed to `use_force(i, g_i)`;
    /// `ue` (12·k) and `g` (k) are scratch.
    fn each_pose_force<M: fem_core::material::Material>(
        &self,
        material: &M,
        e: usize,
        ue: &mut [f64],
        g: &mut [f64],
        mut use_force: impl FnMut(usize, &[f64]),
    ) {
        let k = self.k;
        self.basis_rows(e, ue);
        for (p, u) in self.displacements.iter().enumerate() {
            let (_, f, _) = self.model.elements.energy_gradient(material, e, u, 1.0);
            g.fill(0.0);
            for (l, &fl) in f.iter().enumerate() {
                if fl != 0.0 {
                    for (gj, uj) in g.iter_mut().zip(&ue[l * k..(l + 1) * k]) {
                        *gj += uj * fl;
                    }
                }
            }
            use_force(p, g);
        }
    }

    /// g_{e,i} = J_iᵀ U_eᵀ f_e(u_i) of element `e` for every pose i, stacked into `column`
    /// (poses × d); `ue` (12·k) and `g` (k) are scratch.
    fn column<M: fem_core::material::Material>(
        &self,
        material: &M,
        e: usize,
        column: &mut [f64],
        ue: &mut [f64],
        g: &mut [f64],
    ) {
        let dim = column.len() / self.displacements.len().max(1);
        self.each_pose_force(material, e, ue, g, |p, g| {
            let out = &mut column[p * dim..(p + 1) * dim];
            tangent_transpose_product(self.jacobians.map(|js| js[p]), g, out);
        });
    }

    /// Adds U_eᵀ f_e(u_i) of element `e` for every pose i into `sum` (poses × k, before any
    /// tangent: J_iᵀ is applied once to the sum); returns the first pose where it is not
    /// finite.
    fn add_reduced_forces<M: fem_core::material::Material>(
        &self,
        material: &M,
        e: usize,
        sum: &mut [f64],
        ue: &mut [f64],
        g: &mut [f64],
    ) -> Option<usize> {
        let k = self.k;
        let mut not_finite = None;
        self.each_pose_force(material, e, ue, g, |p, g| {
            if not_finite.is_none() && g.iter().any(|x| !x.is_finite()) {
                not_finite = Some(p);
            }
            for (s, x) in sum[p * k..(p + 1) * k].iter_mut().zip(g) {
                *s += x;
            }
        });
        not_finite
    }

    /// `out` (poses × d) = J_iᵀ `sum_i` for each pose block of `sum` (poses × k).
    fn apply_tangents(&self, sum: &[f64], out: &mut [f64]) {
        let dim = out.len() / self.displacements.len().max(1);
        for (p, (s, o)) in sum
            .chunks_exact(self.k)
            .zip(out.chunks_exact_mut(dim))
            .enumerate()
        {
            tangent_transpose_product(self.jacobians.map(|js| js[p]), s, o);
        }
    }
}

/// Checks a basis and poses against `model` (shapes, finite values) and returns the reduced
/// dimension d of the poses' forces (k for a linear subspace, the Jacobians' columns otherwise).
fn check_inputs(
    model: &FullSpaceModel,
    basis: &[f64],
    k: usize,
    poses: &Poses<'_>,
) -> Result<usize, CubatureError> {
    let m = model.elements.len();
    if m == 0 {
        return Err(CubatureError::NoElements);
    }
    let nf = model.dofs.num_free();
    if k == 0 || basis.len() != nf * k {
        return Err(CubatureError::ShapeMismatch {
            what: "basis U (free DOFs × k)",
            expected: (nf, k),
            found: (basis.len() / k.max(1), k),
        });
    }
    let num_poses = poses.q.ncols();
    if num_poses == 0 {
        return Err(CubatureError::NoPoses);
    }
    if poses.q.nrows() != k {
        return Err(CubatureError::ShapeMismatch {
            what: "pose coefficients q (k × poses)",
            expected: (k, num_poses),
            found: (poses.q.nrows(), num_poses),
        });
    }
    let dim = match poses.jacobians {
        None => k,
        Some(js) => {
            if js.len() != num_poses {
                return Err(CubatureError::ShapeMismatch {
                    what: "Jacobian list (one per pose)",
                    expected: (num_poses, 1),
                    found: (js.len(), 1),
                });
            }
            let d = js[0].ncols();
            for j in js {
                if j.nrows() != k || j.ncols() != d || d == 0 {
                    return Err(CubatureError::ShapeMismatch {
                        what: "pose Jacobian J (k × d)",
                        expected: (k, d.max(1)),
                        found: (j.nrows(), j.ncols()),
                    });
                }
            }
            d
        }
    };
    check_finite("basis U", basis.iter().copied())?;
    check_finite(
        "pose coefficients q",
        (0..num_poses).flat_map(|i| poses.q.col(i).iter().copied()),
    )?;
    if let Some(js) = poses.jacobians {
        check_finite(
            "pose Jacobians",
            js.iter()
                .flat_map(|j| (0..j.ncols()).flat_map(move |c| j.col(c).iter().copied())),
        )?;
    }
    Ok(dim)
}

/// Row sums of a column-major rows × m matrix, in element order (deterministic), in parallel over
/// blocks of rows.
fn column_sum(a: &[f64], rows: usize, m: usize) -> Vec<f64> {
    const BLOCK: usize = 64;
    let mut b = vec![0.0; rows];
    b.par_chunks_mut(BLOCK).enumerate().for_each(|(blk, out)| {
        let r0 = blk * BLOCK;
        for e in 0..m {
            let col = &a[e * rows + r0..e * rows + r0 + out.len()];
            for (o, x) in out.iter_mut().zip(col) {
                *o += x;
            }
        }
    });
    b
}

/// The poses of `num_poses` that [`TrainingMatrix::build`] keeps when they fit
/// `config.memory_limit_mb` (at most `config.max_poses`, a seeded subsample in increasing
/// order): a caller whose poses are costly to form (a decoder's Jacobian and tangent each, 1.5
/// GB over a 2,000-frame training set on a 496-tet sheet) forms only these and passes them
/// marked with [`Poses::kept_of`]: `build` then keeps and numbers exactly the poses it would
/// have of the whole set, also where the memory limit leaves room for fewer.
pub fn kept_poses(num_poses: usize, config: &CubatureConfig) -> Vec<usize> {
    subsample(num_poses, config.max_poses, config.seed)
}

/// The poses kept: all of them, or a seeded uniform subsample of `max` in increasing order.
fn subsample(n: usize, max: usize, seed: u64) -> Vec<usize> {
    subsample_with(n, max, seed ^ POSE_SALT)
}

/// All of 0..n, or a uniform subsample of `max` in increasing order drawn from `stream`.
fn subsample_with(n: usize, max: usize, stream: u64) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..n).collect();
    if n > max {
        let mut rng = SplitMix64::new(stream);
        for i in 0..max {
            let j = i + rng.below(n - i);
            idx.swap(i, j);
        }
        idx.truncate(max);
        idx.sort_unstable();
    }
    idx
}
