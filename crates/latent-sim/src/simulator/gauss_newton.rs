//! The Gauss–Newton matrix of the reduced step in z: Jᵀ(UᵀMU/h² + springs)J plus the
//! elements' Σ_e (B_e J)ᵀ A_e (B_e J), formed in q or in z (whichever is cheaper) and factorised.

use fem_core::material::Material;
use fem_core::{Mat3, with_material};
use pulp::Arch;

use super::StepObjective;
use super::kernels::{BasisTimesQ, PanelsTimesJacobian, StressTimesRows, VertexRowsToF, sandwich};
use crate::dense_factor::DenseFactor;
use crate::{ReducedError, Subspace};

impl<S: Subspace> StepObjective<'_, S> {
    /// Decodes z into work.q and forms the parts of the Newton matrix that do not depend on the
    /// element tangents: J (work.jac), Jᵀ(UᵀMU/h² + springs)J (work.hz_const) and, without
    /// element bases (the parallel path), the decoded vertices (work.u) and U J on the element
    /// rows (work.uj, 3·n × d row-major); with them, B_e J comes from work.jac instead.
    pub(super) fn newton_matrix_constant(&mut self, z: &[f64]) {
        let (model, space) = (self.model, self.space);
        let (k, d) = (space.k, self.subspace.latent_dim());
        let w = &mut *self.work;
        let basis = space.has_element_bases();
        self.subspace.decode(z, &mut w.q);
        if !basis {
            space.decode_touched(&w.q, &mut w.u, &mut w.space);
        }
        self.subspace.jacobian(z, &mut w.jac);
        w.jacobian_scale = super::rms_column_norm(&w.jac, k);
        let springs = w.springs.update(model, space, self.t);
        for (i, a) in w.hk.iter_mut().enumerate() {
            *a = self.inv_h2 * space.mass[i] + springs[i];
        }
        sandwich(&w.hk, &w.jac, k, d, &mut w.ab, &mut w.hz_const);
        if basis {
            return;
        }
        let m = space.element_rows();
        w.uj.resize(m * d, 0.0);
        Arch::new().dispatch(PanelsTimesJacobian {
            panels: space.packed.panels(),
            rows: m,
            jac: &w.jac,
            k,
            d,
            uj: &mut w.uj,
        });
    }

    /// Factorises the Gauss–Newton matrix at z (in work.hz) into `factor`: with the exact element
    /// tangents when that matrix is positive definite (the inertia term M/h² usually makes it
    /// so), else with the tangents projected, shifted if still only semidefinite. The L-BFGS
    /// preconditioner and reduced Newton's steps both come from here.
    pub(super) fn factor_gauss_newton(
        &mut self,
        z: &[f64],
        factor: &mut DenseFactor,
        what: &'static str,
    ) -> Result<(), ReducedError> {
        let d = self.subspace.latent_dim();
        self.newton_matrix_constant(z);
        self.newton_matrix(false);
        if factor.try_factor(&self.work.hz, d, 0.0) {
            return Ok(());
        }
        self.newton_matrix(true);
        factor.factor(&self.work.hz, d, what)
    }

    /// work.hz = work.hz_const + Σ_e w_e (U_e J)ᵀ H_e (U_e J): with the element bases (both
    /// serial paths) as two matrix products over the whole element set
    /// ([`Self::stacked_element_terms`]), in z or, when that is cheaper
    /// ([`sum_in_q_is_cheaper`]), as Jᵀ(Σ_e w_e U_eᵀ H_e U_e)J; without them (the parallel path)
    /// by the same lower-triangle product, 128 elements at a time.
    ///
    /// H_e = W Gᵀ A G with A = ∂P/∂F (9×9) and G = ∂vec(F)/∂x_e (9×12), so with B = U_e J
    /// (12×d) the element's term is W (G B)ᵀ A (G B): G B costs 36·d (row 3j + i of it is
    /// Σ_a g_a[j] B[3a + i], g_a the shape gradients), A (G B) 81·d and the product 9·d², instead
    /// of forming the 12×12 H_e (about 2,300) and B ᵀ H_e B (144·d + 12·d²).
    pub(super) fn newton_matrix(&mut self, projected: bool) {
        let (k, d) = (self.space.k, self.subspace.latent_dim());
        let basis = self.space.has_element_bases();
        let identity = self.subspace.is_linear();
        let in_q = basis && !identity && sum_in_q_is_cheaper(self.space.elements.len(), k, d);
        // The element terms go into a matrix of this size: d×d, or k×k in q.
        let n = if in_q { k } else { d };
        let w = &mut *self.work;
        w.hz.copy_from_slice(&w.hz_const);
        if in_q {
            w.hq.resize(k * k, 0.0);
        }
        if basis {
            self.stacked_element_terms(projected, in_q, identity);
        } else {
            self.vertex_element_terms(projected);
        }
        let w = &mut *self.work;
        let sum = if in_q { &mut w.hq } else { &mut w.hz };
        // The elements added to the lower triangle only (and a few entries above it).
        for m in 0..n {
            for i in m + 1..n {
                sum[i * n + m] = sum[m * n + i];
            }
        }
        if in_q {
            // hz += Jᵀ (Σ_e B_eᵀ A_e B_e) J, exactly symmetric.
            sandwich(&w.hq, &w.jac, k, d, &mut w.ab, &mut w.hz_elastic);
            for (h, e) in w.hz.iter_mut().zip(&w.hz_elastic) {
                *h += e;
            }
        }
    }

    /// The element terms from the element bases (both serial paths), lower triangle: with B_e
    /// (9×k, ∂vec(F)/∂q) stacked into B (9m × k, m elements), C = B J (9m × d, one product) in z,
    /// or C = B in q and for a linear subspace (`identity`, J = I), and Y the stacked rows
    /// A_e C_e (81·n per element), the sum Σ_e C_eᵀ A_e C_e is the one product Cᵀ Y: into
    /// work.hz (on top of its constant part) in z and for J = I, into work.hq in q.
    /// Products over all elements at once run several times faster than element by element
    /// (the lower-triangle product at 34 G multiply–adds/s against 7.5 for the rank-9 updates it
    /// replaces): on the catapult, 144 elements and k = 47, 150 instead of 235 µs per matrix.
    pub(super) fn stacked_element_terms(&mut self, projected: bool, in_q: bool, identity: bool) {
        use faer::linalg::matmul::triangular::{BlockStructure, matmul as triangular_matmul};
        use faer::{Accum, MatMut, MatRef, Par};
        let (model, space) = (self.model, self.space);
        let (k, d) = (space.k, self.subspace.latent_dim());
        let bases_only = in_q || identity;
        let n = if bases_only { k } else { d };
        let (m, stride) = (space.elements.len(), space.basis_stride());
        let w = &mut *self.work;
        let bases =
            MatRef::from_row_major_slice_with_stride(space.element_bases(), 9 * m, k, stride);
        if !bases_only {
            w.stacked_bj.resize(9 * m * d, 0.0);
            faer::linalg::matmul::matmul(
                MatMut::from_row_major_slice_mut(&mut w.stacked_bj, 9 * m, d),
                Accum::Replace,
                bases,
                MatRef::from_column_major_slice(&w.jac, k, d),
                1.0,
                Par::Seq,
            );
        }
        w.stacked_abj.resize(9 * m * n, 0.0);
        let (c, c_stride) = if bases_only {
            (space.element_bases(), stride)
        } else {
            (&w.stacked_bj[..], d)
        };
        let q = &w.q;
        with_material!(&model.material, |material| {
            for (i, (&e, &weight)) in space.elements.iter().zip(&space.weights).enumerate() {
                let df = Arch::new().dispatch(BasisTimesQ {
                    basis: space.element_basis(i),
                    stride,
                    q,
                });
                let f = Mat3::identity() + Mat3::from_column_slice(&df);
                let a = scaled_tangent(material, &f, projected, model.elements.volume[e] * weight);
                let rows = &c[9 * i * c_stride..];
                Arch::new().dispatch(StressTimesRows {
                    a: &a,
                    rows: std::array::from_fn(|r| &rows[r * c_stride..r * c_stride + n]),
                    out: &mut w.stacked_abj[9 * i * n..9 * (i + 1) * n],
                });
            }
        });
        let c = MatRef::from_row_major_slice_with_stride(c, 9 * m, n, c_stride);
        let (sum, accum) = if in_q {
            (&mut w.hq, Accum::Replace)
        } else {
            (&mut w.hz, Accum::Add)
        };
        triangular_matmul(
            MatMut::from_column_major_slice_mut(sum, n, n),
            BlockStructure::TriangularLower,
            accum,
            c.transpose(),
            BlockStructure::Rectangular,
            MatRef::from_row_major_slice(&w.stacked_abj, 9 * m, n),
            BlockStructure::Rectangular,
            1.0,
            Par::Seq,
        );
    }

    /// The element terms in z without element bases (sets too large to keep them), on and below
    /// the diagonal of work.hz: G B from the decoded rows U J of each element's vertices, and
    /// A G B, stacked for [`VERTEX_CHUNK`] elements at a time and summed by one lower-triangle
    /// product per chunk, as [`Self::stacked_element_terms`] sums them over the whole set. The
    /// set is cut into two fixed halves of whole chunks, summed on two threads when the pool
    /// has them and added in the same order on any number of threads.
    pub(super) fn vertex_element_terms(&mut self, projected: bool) {
        let (model, space) = (self.model, self.space);
        let d = self.subspace.latent_dim();
        let w = &mut *self.work;
        let elements: Vec<(usize, f64, [u32; 4])> = space
            .elements
            .iter()
            .zip(&space.weights)
            .zip(space.element_touched())
            .map(|((&e, &weight), &at)| (e, weight, at))
            .collect();
        let half = elements.len().div_ceil(2 * VERTEX_CHUNK) * VERTEX_CHUNK;
        let (first, second) = elements.split_at(half.min(elements.len()));
        let mut other = vec![0.0; if second.is_empty() { 0 } else { d * d }];
        let (u, uj, hz) = (&w.u[..], &w.uj[..], &mut w.hz[..]);
        with_material!(&model.material, |material| {
            let terms = |set: &[(usize, f64, [u32; 4])], sum: &mut [f64]| {
                chunked_terms(material, model, set, (u, uj), d, projected, sum);
            };
            rayon::join(|| terms(first, hz), || terms(second, &mut other));
        });
        for (h, o) in w.hz.iter_mut().zip(&other) {
            *h += o;
        }
    }
}

/// Elements whose rows [`chunked_terms`] stacks for one product: 1,152 rows, whose two d-wide
/// blocks stay in the second-level cache up to d ≈ 50.
const VERTEX_CHUNK: usize = 128;

/// Adds Σ_e (G B_e)ᵀ A_e (G B_e) over `set` (element, weight, positions of its vertices in the
/// decoded rows) to the lower triangle of `sum` (d×d, column-major), [`VERTEX_CHUNK`] elements
/// per product; `decoded` holds the displacements and the rows U J of the touched vertices.
fn chunked_terms<M: Material>(
    material: &M,
    model: &fem_core::integrator::FullSpaceModel,
    set: &[(usize, f64, [u32; 4])],
    (u, uj): (&[f64], &[f64]),
    d: usize,
    projected: bool,
    sum: &mut [f64],
) {
    use faer::linalg::matmul::triangular::{BlockStructure, matmul as triangular_matmul};
    use faer::{Accum, MatMut, MatRef, Par};
    let rows = 9 * VERTEX_CHUNK.min(set.len());
    let (mut b, mut c, mut y) = (vec![0.0; 12 * d], vec![0.0; rows * d], vec![0.0; rows * d]);
    for chunk in set.chunks(VERTEX_CHUNK) {
        for (i, &(e, weight, at)) in chunk.iter().enumerate() {
            for (v, &p) in at.iter().enumerate() {
                let p = p as usize;
                b[3 * v * d..3 * (v + 1) * d].copy_from_slice(&uj[3 * p * d..3 * (p + 1) * d]);
            }
            Arch::new().dispatch(VertexRowsToF {
                b: &b,
                g: model.elements.shape_gradients(e),
                d,
                fb: &mut c[9 * i * d..9 * (i + 1) * d],
            });
            let f = model.elements.deformation_gradient(e, u);
            let a = scaled_tangent(material, &f, projected, model.elements.volume[e] * weight);
            let fb = &c[9 * i * d..9 * (i + 1) * d];
            Arch::new().dispatch(StressTimesRows {
                a: &a,
                rows: std::array::from_fn(|r| &fb[r * d..(r + 1) * d]),
                out: &mut y[9 * i * d..9 * (i + 1) * d],
            });
        }
        let m = 9 * chunk.len();
        triangular_matmul(
            MatMut::from_column_major_slice_mut(sum, d, d),
            BlockStructure::TriangularLower,
            Accum::Add,
            MatRef::from_row_major_slice(&c[..m * d], m, d).transpose(),
            BlockStructure::Rectangular,
            MatRef::from_row_major_slice(&y[..m * d], m, d),
            BlockStructure::Rectangular,
            1.0,
            Par::Seq,
        );
    }
}

/// An element's stress derivative ∂P/∂F at F (9×9, column-major), projected to be positive
/// semidefinite when `projected`, times `scale` (its volume and cubature weight).
fn scaled_tangent<M: Material>(material: &M, f: &Mat3, projected: bool, scale: f64) -> [f64; 81] {
    let a = if projected {
        material.dpdf_projected(f)
    } else {
        material.dpdf(f)
    };
    std::array::from_fn(|i| scale * a[i])
}

/// Whether the element terms from the element bases are formed cheaper in q, as
/// Jᵀ(Σ_e B_eᵀ A_e B_e)J (per element 81k for A B_e, then the product's k²/2 per row of B, and
/// one k×k by k×d sandwich), than in z (the product B J, then per element 81d and d²/2 per
/// row): when d is not much smaller than k, as with linear directions beside the latent
/// coordinates. The multiply–adds are weighted by their measured rates: the element kernels
/// and the sandwich run at about 10 G/s, the lower-triangle product at 34 and the full one at
/// 50 (one thread, 35 G/s peak). On the catapult (k = 47, 144 elements) z wins at d = 26 (140
/// against 148 µs) and q at d = 42 (158 against 185 µs); with k = 89, 315 elements and d = 66,
/// q (654 against 745 µs).
pub(super) fn sum_in_q_is_cheaper(elements: usize, k: usize, d: usize) -> bool {
    let (rows, k, d) = (9.0 * elements as f64, k as f64, d as f64);
    let (kernel, lower, full) = (1.0 / 10.0, 1.0 / 34.0, 1.0 / 50.0);
    let in_q = kernel * (rows * 9.0 * k + k * k * d + 0.5 * k * d * d) + lower * rows * 0.5 * k * k;
    let in_z = full * rows * k * d + kernel * rows * 9.0 * d + lower * rows * 0.5 * d * d;
    in_q < in_z
}
