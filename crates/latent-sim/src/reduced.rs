//! The reduced space of a model: rows of the basis U per vertex and the projected constant
//! matrices, plus partial decode and projection over the vertices an element set touches.
//!
//! The rows of the touched vertices are also kept packed, column-major (3·n_touched × k), so that
//! the partial decode u_t = U_t q is k contiguous axpys and the projection U_tᵀ g is k dot
//! products with independent accumulators: both vectorise, where a dot per row is one dependent
//! chain of adds.

use cubature::CubatureRule;
use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
use fem_core::constraints::FIXED;
use fem_core::forces::{ExternalForce, ForceKind};
use fem_core::integrator::FullSpaceModel;
use fem_core::material::{Material, MaterialConfig};
use fem_core::{Mat3, Vec3, with_material};
use pca::PcaBasis;
use pulp::{Arch, Simd, WithSimd};
use simd_kernels::rows::{add_combination, dot_rows};

use crate::ReducedError;

/// Weighted sets up to this many elements are evaluated serially (see [`ElasticPath`]); larger
/// ones go through the parallel full-length assembly.
pub const SERIAL_MAX_ELEMENTS: usize = 2048;

/// How [`ReducedSpace::elastic_energy_gradient`] evaluates the weighted element set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ElasticPath {
    /// Each element keeps B_e = ∂vec(F)/∂q (9×k, precomputed): F = I + reshape(B_e q) and
    /// ∂V/∂q += w_e V_e B_eᵀ vec(P) in one pass over the elements, no displacement formed. For
    /// scattered sets (cubature rules), whose elements share few vertices: it streams 9 k-vectors
    /// per element once, where the vertex paths stream 3 per vertex twice (decode and projection).
    ElementBasis,
    /// Partial decode u_t = U_t q of the element vertices, the elements serially over them, and
    /// the projection U_tᵀ g back: for small sets whose elements share most vertices. The
    /// element bases are kept beside it for the Gauss–Newton matrix.
    Vertices,
    /// Partial decode, the parallel full-length assembly and the projection: for large sets. The
    /// same sums in the same order as [`ElasticPath::Vertices`], so the same energy to the bit
    /// (its Gauss–Newton matrix, without element bases, differs from theirs by rounding).
    Parallel,
}

/// Rows of the packed layout per panel: one panel's slice of a column fills a cache line.
pub(crate) const PANEL: usize = 8;

/// Rows of U of a list of vertices (3 per vertex, row 3i + c), in panels of [`PANEL`] rows:
/// entry (r, j) at (r / PANEL)·PANEL·k + j·PANEL + r % PANEL, the last panel padded with zeros.
/// Decode then streams through memory once with a panel of accumulators in registers, and each
/// panel of a gradient is loaded once for all k dot products.
#[derive(Debug, Clone)]
pub(crate) struct PackedRows {
    /// 3 × the number of vertices.
    pub(crate) rows: usize,
    k: usize,
    data: Vec<f64>,
}

impl PackedRows {
    /// The rows of `vertices` from `space`.
    pub(crate) fn new(space: &ReducedSpace, vertices: &[usize]) -> Self {
        let (rows, k) = (3 * vertices.len(), space.k);
        let mut data = vec![0.0; rows.div_ceil(PANEL) * PANEL * k];
        for (i, &v) in vertices.iter().enumerate() {
            let block = space.rows_of(v);
            for c in 0..3 {
                let r = &block[c * k..(c + 1) * k];
                let row = 3 * i + c;
                for (j, &x) in r.iter().enumerate() {
                    data[(row / PANEL) * PANEL * k + j * PANEL + row % PANEL] = x;
                }
            }
        }
        Self { rows, k, data }
    }

    /// The panels in row order, each PANEL·k entries (column j at j·PANEL).
    #[inline]
    pub(crate) fn panels(&self) -> std::slice::ChunksExact<'_, f64> {
        self.data.chunks_exact(PANEL * self.k)
    }

    /// out = P q (out has `rows` entries); each entry is the sequential sum over j.
    pub(crate) fn apply(&self, q: &[f64], out: &mut [f64]) {
        Arch::new().dispatch(Apply {
            data: &self.data,
            k: self.k,
            q,
            out,
        });
    }

    /// out_j += (column j)ᵀ g over the first g.len() rows.
    fn apply_transpose_add(&self, g: &[f64], out: &mut [f64]) {
        Arch::new().dispatch(ApplyTransposeAdd {
            data: &self.data,
            k: self.k,
            g,
            out,
        });
    }
}

// The panel loops of [`PackedRows::apply`] and [`PackedRows::apply_transpose_add`], run through
// `pulp`'s dispatch so that they are compiled with the CPU's SIMD features (AVX2: a panel of 8
// rows is two 4-wide registers instead of four 2-wide ones). The operations and their order are
// those of plain loops, so the results are the same bit for bit on any CPU. (A closure would be
// compiled as a function of its own, without the features: hence the structs.)

struct Apply<'a> {
    data: &'a [f64],
    k: usize,
    q: &'a [f64],
    out: &'a mut [f64],
}

impl WithSimd for Apply<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let Self { data, k, q, out } = self;
        for (panel, o) in data.chunks_exact(PANEL * k).zip(out.chunks_mut(PANEL)) {
            let mut acc = [0.0f64; PANEL];
            for (c, &qj) in panel.chunks_exact(PANEL).zip(q) {
                for i in 0..PANEL {
                    acc[i] += c[i] * qj;
                }
            }
            o.copy_from_slice(&acc[..o.len()]);
        }
    }
}

struct ApplyTransposeAdd<'a> {
    data: &'a [f64],
    k: usize,
    g: &'a [f64],
    out: &'a mut [f64],
}

impl WithSimd for ApplyTransposeAdd<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let Self { data, k, g, out } = self;
        for (panel, gp) in data.chunks_exact(PANEL * k).zip(g.chunks(PANEL)) {
            let mut g8 = [0.0f64; PANEL];
            g8[..gp.len()].copy_from_slice(gp);
            for (c, o) in panel.chunks_exact(PANEL).zip(out.iter_mut()) {
                let p: [f64; PANEL] = std::array::from_fn(|i| c[i] * g8[i]);
                *o += ((p[0] + p[4]) + (p[1] + p[5])) + ((p[2] + p[6]) + (p[3] + p[7]));
            }
        }
    }
}

/// The rows of an element basis are padded with zeros to a multiple of this, the SIMD width, so
/// that its kernels have no scalar remainder.
pub(crate) const LANES: usize = 4;

/// The elastic energy and ∂V/∂q over the element set for [`ElasticPath::ElementBasis`]: per
/// element F = I + B_e q, ψ and P at F, then ∂V/∂q += w V B_eᵀ vec(P). `q` and `grad` are padded
/// with zeros to the basis rows' length. The material is evaluated inside the dispatched
/// function, so that it is compiled for the same instruction set and inlined.
struct BasisPass<'a, M: Material> {
    material: &'a M,
    basis: &'a [f64],
    /// w_e V_e per element of the set.
    scales: &'a [f64],
    q: &'a [f64],
    grad: &'a mut [f64],
}

impl<M: Material> WithSimd for BasisPass<'_, M> {
    /// The energy, and whether some element's energy was undefined.
    type Output = (f64, bool);

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) -> (f64, bool) {
        let Self {
            material,
            basis,
            scales,
            q,
            grad,
        } = self;
        let mut energy = 0.0;
        let mut undefined = false;
        let kp = q.len();
        for (i, b) in basis.chunks_exact(9 * kp).enumerate() {
            let rows: [&[f64]; 9] = std::array::from_fn(|r| &b[r * kp..(r + 1) * kp]);
            let df = dot_rows(simd, rows, q);
            let f = Mat3::identity() + Mat3::from_column_slice(&df);
            let (psi, stress) = material.psi_pk1(&f);
            let scale = scales[i];
            undefined |= psi.is_nan();
            energy += psi * scale;
            let p: [f64; 9] = std::array::from_fn(|r| scale * stress[(r % 3, r / 3)]);
            // grad += Bᵀ p: one pass over grad, the nine rows summed chunk by chunk.
            add_combination(simd, grad, p, rows);
        }
        (energy, undefined)
    }
}

/// Scratch of the partial decode and projection, sized by [`ReducedSpace::buffers`].
#[derive(Debug, Clone, Default)]
pub struct SpaceBuffers {
    /// Packed touched values (decoded displacement, then gradients), 3 per touched vertex.
    packed: Vec<f64>,
    /// A k-vector: G_f q of a spring.
    gq: Vec<f64>,
    /// q and ∂V/∂q padded to the element basis rows' stride.
    qpad: Vec<f64>,
    gpad: Vec<f64>,
    assembly: AssemblyBuffers,
}

/// Basis rows, reduced mass / rest stiffness / gravity, and the element set with its vertices.
#[derive(Debug, Clone)]
pub struct ReducedSpace {
    /// Number of basis vectors k.
    pub k: usize,
    /// For each vertex, the place of its block in `rows`, or [`NO_ROWS`] when the space does not
    /// hold its rows (a space built from a model file keeps those of the vertices it uses).
    slot: Vec<u32>,
    /// Row-major 3×k block of U for each vertex held (zero for fixed vertices).
    rows: Vec<f64>,
    /// A block of zeros, the rows of a vertex not held.
    zero_block: Vec<f64>,
    /// UᵀMU, k×k column-major (the identity for a mass-orthonormal basis and the same mass).
    pub mass: Vec<f64>,
    /// UᵀK₀U, k×k column-major, K₀ the stiffness at rest.
    pub rest_stiffness: Vec<f64>,
    /// Uᵀ f_g: the per-axis loads (`gravity_axes`) at the model's gravity ([`Self::set_gravity`]).
    pub gravity: Vec<f64>,
    /// Uᵀ f_g per unit acceleration along x, y and z (3 columns of k): f_g is linear in the
    /// acceleration, so a program may turn gravity any way without the basis's every row.
    gravity_axes: Vec<f64>,
    /// Elements evaluated and their weights (all elements, weight 1, without cubature).
    pub elements: Vec<usize>,
    pub weights: Vec<f64>,
    /// Vertices of those elements (sorted): the only rows ever decoded.
    pub touched: Vec<usize>,
    /// For each element of the set, the positions of its four vertices in `touched`.
    element_touched: Vec<[u32; 4]>,
    /// The rows of `touched`, packed.
    pub(crate) packed: PackedRows,
    /// For each element of the set, B_e = ∂vec(F)/∂q (9×k, row-major: row 3j + i is ∂F_ij/∂q,
    /// each row padded with zeros to a multiple of [`LANES`]), unless the path is
    /// [`ElasticPath::Parallel`] (then empty): the Gauss–Newton matrix takes them on the
    /// [`ElasticPath::Vertices`] path too.
    element_basis: Vec<f64>,
    /// w_e V_e per element of the set, with the element basis.
    element_scales: Vec<f64>,
    /// Per force, Σ_v U_vᵀ U_v (k×k) and Σ_v U_vᵀ (k×3, column-major; column c sums the rows of
    /// the c-th components) over its vertices: springs and point loads are then exact quadratic
    /// and linear functions of q, and no force vertex is ever decoded.
    pub(crate) force_gram: Vec<Vec<f64>>,
    force_sums: Vec<Vec<f64>>,
    /// Per force, R = K/k_f: a spring pulls its patch's mean ū towards its target w with the
    /// 3×3 stiffness K instead of k_f I (the identity unless
    /// [`Self::set_spring_compliance`] softened it). Its `force_gram` then holds
    /// G + S(R − I)Sᵀ/n.
    force_pull: Vec<Mat3>,
    /// How the elastic energy is evaluated (chosen by [`ReducedSpace::new`]).
    elastic_path: ElasticPath,
}

impl ReducedSpace {
    /// The space of `basis` (U on the model's free DOFs), with the elastic energy restricted to
    /// the elements of `cubature` and their weights (None: every element, weight 1).
    ///
    /// # Errors
    /// [`ReducedError::BasisShape`] when U's rows are not the model's free DOFs,
    /// [`ReducedError::Cubature`] when the rule does not fit the mesh.
    pub fn new(
        model: &FullSpaceModel,
        basis: &PcaBasis,
        cubature: Option<&CubatureRule>,
    ) -> Result<Self, ReducedError> {
        let nf = model.dofs.num_free();
        let k = basis.k();
        if basis.n() != nf {
            return Err(ReducedError::BasisShape {
                rows: basis.n(),
                free: nf,
            });
        }
        let columns: Vec<&[f64]> = (0..k).map(|j| basis.column(j)).collect();
        let nv = model.mesh.num_vertices();
        let mut rows = vec![0.0; nv * 3 * k];
        for v in 0..nv {
            for c in 0..3 {
                let r = model.dofs.index[3 * v + c];
                if r != FIXED {
                    for j in 0..k {
                        rows[(v * 3 + c) * k + j] = columns[j][r];
                    }
                }
            }
        }
        let slot = (0..nv as u32).collect();
        let mut space = Self::assemble(
            model,
            k,
            slot,
            rows,
            cubature.map(|r| (&r.elements[..], &r.weights[..])),
        )?;
        // UᵀMU and Uᵀf_g from the full mass matrix, one basis column at a time.
        let n = model.num_full();
        let (mut col, mut mcol) = (vec![0.0; n], vec![0.0; n]);
        let mut cols = Vec::with_capacity(k);
        for column in &columns {
            model.dofs.scatter(column, &mut col);
            cols.push(col.clone());
        }
        for j in 0..k {
            model.mass.apply(&cols[j], &mut mcol);
            for i in 0..k {
                space.mass[j * k + i] = dot(&cols[i], &mcol);
            }
        }
        // Column c of the axes: Σ_v m_v U_{v,c}, the load of a unit acceleration along c.
        let lumped = &model.mass.lumped;
        for (j, col) in cols.iter().enumerate() {
            for c in 0..3 {
                space.gravity_axes[c * k + j] =
                    (0..lumped.len()).map(|v| lumped[v] * col[3 * v + c]).sum();
            }
        }
        space.set_gravity(model.gravity);
        // UᵀK₀U over every element (the preconditioner uses the true rest stiffness).
        let all: Vec<usize> = (0..model.elements.len()).collect();
        let ones = vec![1.0; all.len()];
        let rest = vec![0.0; n];
        let mut k0 = vec![0.0; k * k];
        with_material!(&model.material, |m| {
            space.project_hessian(model, m, &all, &ones, &rest, false, &mut k0);
        });
        space.rest_stiffness = k0;
        Ok(space)
    }

    /// A space from the parts a model file keeps ([`ReducedSpace::parts`]): the basis rows of
    /// some vertices and the reduced matrices computed from the whole basis. The same numbers
    /// as the space the parts came from, bit for bit, wherever the rows are held.
    ///
    /// # Errors
    /// [`ReducedError::Parts`] when the parts do not fit together or the model (shapes, vertex
    /// indices, an element of the set whose rows are missing), [`ReducedError::Cubature`] as
    /// [`ReducedSpace::new`].
    pub fn from_parts(
        model: &FullSpaceModel,
        parts: &SpaceParts,
        cubature: Option<&CubatureRule>,
    ) -> Result<Self, ReducedError> {
        let bad = |reason: String| Err(ReducedError::Parts { reason });
        let SpaceParts {
            k,
            vertices,
            rows,
            mass,
            rest_stiffness,
            gravity_axes,
            material: _,
        } = parts;
        let (k, nv) = (*k, model.mesh.num_vertices());
        if k == 0 {
            return bad("the basis has no column".into());
        }
        // A count read from a file: its products checked, not wrapped into a wrong figure.
        let (Some(square), Some(three)) = (k.checked_mul(k), k.checked_mul(3)) else {
            return bad(format!(
                "the basis has {k} columns, more than memory can hold"
            ));
        };
        for (what, v, len) in [
            ("reduced mass", mass, square),
            ("reduced rest stiffness", rest_stiffness, square),
            ("reduced gravity", gravity_axes, three),
        ] {
            if v.len() != len {
                return bad(format!(
                    "the {what} has {} entries, expected {len}",
                    v.len()
                ));
            }
            if v.iter().any(|x| !x.is_finite()) {
                return bad(format!("the {what} is not finite"));
            }
        }
        if Some(rows.len()) != vertices.len().checked_mul(three) {
            return bad(format!(
                "{} basis values for {} vertices of 3 × {k} rows",
                rows.len(),
                vertices.len()
            ));
        }
        if rows.iter().any(|x| !x.is_finite()) {
            return bad("a basis row is not finite".into());
        }
        if let Some(w) = vertices.windows(2).find(|w| w[0] >= w[1]) {
            return bad(format!(
                "the vertices with rows must increase, found {} before {}",
                w[0], w[1]
            ));
        }
        if let Some(&v) = vertices.last().filter(|&&v| v >= nv) {
            return bad(format!(
                "vertex {v} has rows but the mesh has {nv} vertices"
            ));
        }
        let mut slot = vec![NO_ROWS; nv];
        for (i, &v) in vertices.iter().enumerate() {
            slot[v] = i as u32;
        }
        let mut space = Self::assemble(
            model,
            k,
            slot,
            rows.clone(),
            cubature.map(|r| (&r.elements[..], &r.weights[..])),
        )?;
        space.mass.copy_from_slice(mass);
        space.rest_stiffness.copy_from_slice(rest_stiffness);
        space.gravity_axes.copy_from_slice(gravity_axes);
        space.set_gravity(model.gravity);
        Ok(space)
    }

    /// Sets the reduced gravity load to that of acceleration `g` (m/s²).
    pub fn set_gravity(&mut self, g: Vec3) {
        let k = self.k;
        for j in 0..k {
            self.gravity[j] = (0..3).map(|c| g[c] * self.gravity_axes[c * k + j]).sum();
        }
    }

    /// What [`ReducedSpace::from_parts`] needs, with the rows of `vertices` (sorted, unique; the
    /// vertices of the element set are always added, since stepping reads them) and the
    /// `material` the space was built with.
    pub fn parts(&self, vertices: &[usize], material: &MaterialConfig) -> SpaceParts {
        let mut keep: Vec<usize> = vertices
            .iter()
            .chain(&self.touched)
            .copied()
            .filter(|&v| self.has_rows(v))
            .collect();
        keep.sort_unstable();
        keep.dedup();
        let mut rows = Vec::with_capacity(keep.len() * 3 * self.k);
        for &v in &keep {
            rows.extend_from_slice(self.rows_of(v));
        }
        SpaceParts {
            k: self.k,
            vertices: keep,
            rows,
            mass: self.mass.clone(),
            rest_stiffness: self.rest_stiffness.clone(),
            gravity_axes: self.gravity_axes.clone(),
            material: material.clone(),
        }
    }

    /// Everything but the reduced matrices, which are left zero: the element set, its vertices
    /// (whose rows must be held), the packed rows and the terms of the model's forces.
    fn assemble(
        model: &FullSpaceModel,
        k: usize,
        slot: Vec<u32>,
        rows: Vec<f64>,
        cubature: Option<(&[usize], &[f64])>,
    ) -> Result<Self, ReducedError> {
        let nv = model.mesh.num_vertices();
        if let Some((elements, weights)) = cubature {
            check_rule(elements, weights, model.elements.len())?;
        }
        let (elements, weights) = match cubature {
            Some((e, w)) => (e.to_vec(), w.to_vec()),
            None => (
                (0..model.elements.len()).collect(),
                vec![1.0; model.elements.len()],
            ),
        };
        let mut touched: Vec<usize> = elements
            .iter()
            .flat_map(|&e| model.elements.tets[e])
            .collect();
        touched.sort_unstable();
        touched.dedup();
        if let Some(&v) = touched.iter().find(|&&v| slot[v] == NO_ROWS) {
            return Err(ReducedError::Parts {
                reason: format!(
                    "vertex {v} of the elastic element set has no basis rows; export the model \
                     with the rows of every vertex the elements use"
                ),
            });
        }
        let mut position = vec![u32::MAX; nv];
        for (i, &v) in touched.iter().enumerate() {
            position[v] = i as u32;
        }
        let element_touched = elements
            .iter()
            .map(|&e| model.elements.tets[e].map(|v| position[v]))
            .collect();
        let path = if elements.len() > SERIAL_MAX_ELEMENTS {
            ElasticPath::Parallel
        } else if 9 * elements.len() <= 6 * touched.len() {
            ElasticPath::ElementBasis
        } else {
            ElasticPath::Vertices
        };
        let mut space = Self {
            k,
            slot,
            rows,
            zero_block: vec![0.0; 3 * k],
            mass: vec![0.0; k * k],
            rest_stiffness: vec![0.0; k * k],
            gravity: vec![0.0; k],
            gravity_axes: vec![0.0; 3 * k],
            elements,
            weights,
            touched,
            element_touched,
            packed: PackedRows {
                rows: 0,
                k,
                data: Vec::new(),
            },
            element_basis: Vec::new(),
            element_scales: Vec::new(),
            force_gram: Vec::with_capacity(model.forces.len()),
            force_sums: Vec::with_capacity(model.forces.len()),
            force_pull: Vec::with_capacity(model.forces.len()),
            elastic_path: ElasticPath::Vertices,
        };
        space.packed = PackedRows::new(&space, &space.touched);
        for f in &model.forces {
            space.push_force(f)?;
        }
        space.set_elastic_path(model, path);
        Ok(space)
    }

    /// Adds the terms of force `f`, which goes after the model's forces
    /// ([`crate::ReducedSimulator::add_force`] keeps both lists in step).
    ///
    /// # Errors
    /// [`ReducedError::NoBasisRows`] when a vertex of `f` has no rows in this space (or does
    /// not exist).
    pub fn push_force(&mut self, f: &ExternalForce) -> Result<(), ReducedError> {
        if let Some(&vertex) = f.vertices.iter().find(|&&v| !self.has_rows(v)) {
            return Err(ReducedError::NoBasisRows { vertex });
        }
        let (gram, sums) = self.force_terms(f);
        self.force_gram.push(gram);
        self.force_sums.push(sums);
        self.force_pull.push(Mat3::identity());
        Ok(())
    }

    /// Σ_v U_vᵀU_v (k×k) and Σ_v U_vᵀ (k×3) over the vertices of `f` (which have rows).
    fn force_terms(&self, f: &ExternalForce) -> (Vec<f64>, Vec<f64>) {
        let k = self.k;
        let (mut gram, mut sums) = (vec![0.0; k * k], vec![0.0; 3 * k]);
        for &v in &f.vertices {
            let block = self.rows_of(v);
            for c in 0..3 {
                let r = &block[c * k..(c + 1) * k];
                axpy(1.0, r, &mut sums[c * k..(c + 1) * k]);
                for (b, &rb) in r.iter().enumerate() {
                    axpy(rb, r, &mut gram[b * k..(b + 1) * k]);
                }
            }
        }
        (gram, sums)
    }

    /// Removes the terms of force `index` (the later ones move down by one). Does nothing when
    /// there is no such force.
    pub fn remove_force(&mut self, index: usize) {
        if index < self.force_gram.len() {
            self.force_gram.remove(index);
            self.force_sums.remove(index);
            self.force_pull.remove(index);
        }
    }

    /// The compliance Ĉ = G U Â⁻¹ UᵀGᵀ of force `index`'s patch (`f`, the model's force at that
    /// index) in the basis, with Â = UᵀK₀U + UᵀMU/h² the implicit step's reduced operator at
    /// rest (UᵀK₀U alone when `h` is None, a quasi-static step) and G the mean over the patch's
    /// vertices: the mean displacement of the patch the basis allows under a unit load spread
    /// over it. None when Â cannot be factorised or there is no such force.
    pub fn patch_compliance(
        &self,
        index: usize,
        f: &ExternalForce,
        h: Option<f64>,
    ) -> Option<Mat3> {
        self.patch_response(index, f, h).map(|(c, _)| c)
    }

    /// [`Self::patch_compliance`] and the coefficients behind it, Â⁻¹UᵀGᵀ (k×3,
    /// column-major): column c is the basis's response to a unit total load along axis c spread
    /// evenly over the patch.
    pub fn patch_response(
        &self,
        index: usize,
        f: &ExternalForce,
        h: Option<f64>,
    ) -> Option<(Mat3, Vec<f64>)> {
        let (k, sums) = (self.k, self.force_sums.get(index)?);
        let mass_scale = h.map_or(0.0, |h| 1.0 / (h * h));
        let a: Vec<f64> = self
            .rest_stiffness
            .iter()
            .zip(&self.mass)
            .map(|(kk, m)| kk + mass_scale * m)
            .collect();
        let mut factor = crate::dense_factor::DenseFactor::default();
        if !factor.try_factor(&a, k, 0.0) {
            return None;
        }
        // UᵀGᵀ = S/n, S the k×3 sums.
        let share = 1.0 / f.vertices.len().max(1) as f64;
        let mut x: Vec<f64> = sums.iter().map(|s| s * share).collect();
        for c in 0..3 {
            factor.solve_in_place(&mut x[c * k..(c + 1) * k]);
        }
        let compliance =
            Mat3::from_fn(|r, c| share * dot(&sums[r * k..(r + 1) * k], &x[c * k..(c + 1) * k]));
        Some((compliance, x))
    }

    /// The mean displacement U q over force `index`'s patch of `n` vertices (zero when there is
    /// no such force).
    pub fn patch_mean(&self, index: usize, n: usize, q: &[f64]) -> Vec3 {
        let (k, share) = (self.k, 1.0 / n.max(1) as f64);
        self.force_sums.get(index).map_or(Vec3::zeros(), |sums| {
            Vec3::from_fn(|c, _| share * dot(&sums[c * k..(c + 1) * k], q))
        })
    }

    /// Sets how spring `index` (`f`, the model's force at that index) pulls its patch: with
    /// `missing` = C, the patch compliance the subspace lacks, its mean is pulled with K =
    /// (I/k_f + C)⁻¹ instead of k_f I, the stiffness of the spring in series with what the
    /// subspace cannot deform; with None as the model's spring. Each call starts from the
    /// spring's own terms, so calls do not compound.
    pub fn set_spring_compliance(
        &mut self,
        index: usize,
        f: &ExternalForce,
        missing: Option<&Mat3>,
    ) {
        if index >= self.force_gram.len() {
            return;
        }
        let (mut gram, sums) = self.force_terms(f);
        let mut pull = Mat3::identity();
        let ks = f.stiffness;
        if let Some(c) = missing.filter(|_| f.kind == ForceKind::Spring && ks > 0.0)
            && let Some(stiff) = (Mat3::identity() / ks + c).try_inverse()
        {
            // G' = Σ_v (U_v − Ū)ᵀ(U_v − Ū) + S R Sᵀ/n (Ū = Sᵀ/n the patch's mean rows): the
            // spread about the mean and the softened pull on it, each a sum of squares, so
            // that G' stays semidefinite however stiff the spring (G + S(R − I)Sᵀ/n, the same
            // matrix, cancels to round-off of either sign).
            let k = self.k;
            let n = f.vertices.len() as f64;
            pull = stiff / ks;
            gram.fill(0.0);
            let mut centred = vec![0.0; k];
            for &v in &f.vertices {
                let block = self.rows_of(v);
                for c in 0..3 {
                    for ((x, r), s) in centred
                        .iter_mut()
                        .zip(&block[c * k..(c + 1) * k])
                        .zip(&sums[c * k..(c + 1) * k])
                    {
                        *x = r - s / n;
                    }
                    for (b, &xb) in centred.iter().enumerate() {
                        axpy(xb, &centred, &mut gram[b * k..(b + 1) * k]);
                    }
                }
            }
            for b in 0..k {
                for r in 0..3 {
                    let w: f64 = (0..3).map(|c| pull[(r, c)] * sums[c * k + b]).sum::<f64>() / n;
                    axpy(w, &sums[r * k..(r + 1) * k], &mut gram[b * k..(b + 1) * k]);
                }
            }
        }
        self.force_gram[index] = gram;
        self.force_sums[index] = sums;
        self.force_pull[index] = pull;
    }

    /// R = K/k_f, how force `index` pulls its patch's mean (see [`Self::set_spring_compliance`];
    /// the identity for a spring as the model has it, None when there is no such force).
    pub fn spring_pull(&self, index: usize) -> Option<Mat3> {
        self.force_pull.get(index).copied()
    }

    /// Whether the space holds the rows of vertex `v`.
    #[inline]
    pub fn has_rows(&self, v: usize) -> bool {
        self.slot.get(v).is_some_and(|&s| s != NO_ROWS)
    }

    /// Whether the space holds the rows of every vertex (so that [`Self::reconstruct`] gives
    /// the whole displacement).
    pub fn has_all_rows(&self) -> bool {
        self.slot.iter().all(|&s| s != NO_ROWS)
    }

    /// Work buffers for [`Self::decode_touched`], [`Self::elastic_energy_gradient`] and
    /// [`Self::force_energy_gradient`].
    pub fn buffers(&self) -> SpaceBuffers {
        SpaceBuffers {
            packed: vec![0.0; self.packed.rows],
            gq: vec![0.0; self.k],
            qpad: vec![0.0; self.basis_stride()],
            gpad: vec![0.0; self.basis_stride()],
            assembly: AssemblyBuffers::default(),
        }
    }

    /// How the elastic energy is evaluated.
    pub fn elastic_path(&self) -> ElasticPath {
        self.elastic_path
    }

    /// Evaluates the elastic energy by `path` from now on (the default is chosen by
    /// [`Self::new`]); builds the element bases unless `path` is [`ElasticPath::Parallel`]. The
    /// serial paths both form the Gauss–Newton matrix from them, by products over all the
    /// elements at once, which beat the vertex path's former element-by-element updates (a
    /// 500-element rule of a 2,475-tet bar, d = k = 132: 5.4 against 10.3 ms).
    pub fn set_elastic_path(&mut self, model: &FullSpaceModel, path: ElasticPath) {
        self.elastic_path = path;
        if path == ElasticPath::Parallel {
            self.element_basis = Vec::new();
            self.element_scales = Vec::new();
            return;
        }
        self.element_scales = self
            .elements
            .iter()
            .zip(&self.weights)
            .map(|(&e, &w)| model.elements.volume[e] * w)
            .collect();
        let (k, kp) = (self.k, self.basis_stride());
        let mut basis = vec![0.0; self.elements.len() * 9 * kp];
        for (&e, b) in self.elements.iter().zip(basis.chunks_exact_mut(9 * kp)) {
            // F_ij = δ_ij + Σ_a u_a[i] g_a[j] with u_a[i] = (row 3v_a + i of U) q.
            let g = model.elements.shape_gradients(e);
            for (a, &v) in model.elements.tets[e].iter().enumerate() {
                let block = self.rows_of(v);
                for j in 0..3 {
                    for i in 0..3 {
                        let r = &block[i * k..(i + 1) * k];
                        let row = 3 * j + i;
                        axpy(g[a][j], r, &mut b[row * kp..row * kp + k]);
                    }
                }
            }
        }
        self.element_basis = basis;
    }

    /// The 3×k rows of U for vertex `v`, row-major, when the space holds them.
    #[inline]
    pub fn vertex_rows(&self, v: usize) -> Option<&[f64]> {
        self.has_rows(v).then(|| self.rows_of(v))
    }

    /// The 3×k rows of vertex `v`, zeros when the space does not hold them (every caller has
    /// checked that it does where it matters: the element set's vertices and forces').
    #[inline]
    fn rows_of(&self, v: usize) -> &[f64] {
        let n = 3 * self.k;
        match self.slot.get(v) {
            Some(&s) if s != NO_ROWS => &self.rows[s as usize * n..(s as usize + 1) * n],
            _ => &self.zero_block,
        }
    }

    /// Rows of the element vertices in the packed order (3 per vertex).
    #[inline]
    pub(crate) fn element_rows(&self) -> usize {
        self.packed.rows
    }

    /// Element i's basis B_e = ∂vec(F)/∂q on the serial paths: 9 rows of
    /// [`Self::basis_stride`] entries (k, then zeros), row-major.
    #[inline]
    pub(crate) fn element_basis(&self, i: usize) -> &[f64] {
        let n = 9 * self.basis_stride();
        &self.element_basis[i * n..(i + 1) * n]
    }

    /// All the element bases, element after element: 9 rows of [`Self::basis_stride`] entries
    /// per element, row-major (empty on the [`ElasticPath::Parallel`] path).
    #[inline]
    pub(crate) fn element_bases(&self) -> &[f64] {
        &self.element_basis
    }

    /// Whether the element bases are held (every serial path over a nonempty element set).
    #[inline]
    pub(crate) fn has_element_bases(&self) -> bool {
        !self.element_basis.is_empty()
    }

    /// Length of an element basis row (k padded to the SIMD width).
    #[inline]
    pub(crate) fn basis_stride(&self) -> usize {
        self.k.next_multiple_of(LANES)
    }

    /// The positions in `touched` of each element's vertices.
    #[inline]
    pub(crate) fn element_touched(&self) -> &[[u32; 4]] {
        &self.element_touched
    }

    /// u_v = U_v q for the touched vertices only (other entries of `u` are left alone).
    pub fn decode_touched(&self, q: &[f64], u: &mut [f64], buf: &mut SpaceBuffers) {
        let ut = &mut buf.packed;
        self.packed.apply(q, ut);
        for (&v, x) in self.touched.iter().zip(ut.chunks_exact(3)) {
            u[3 * v..3 * v + 3].copy_from_slice(x);
        }
    }

    /// The full displacement u = Uq (for output frames); zero at the vertices whose rows the
    /// space does not hold (see [`Self::has_all_rows`]).
    pub fn reconstruct(&self, q: &[f64], u: &mut [f64]) {
        let k = self.k;
        for v in 0..u.len() / 3 {
            let r = self.rows_of(v);
            for c in 0..3 {
                u[3 * v + c] = dot(&r[c * k..(c + 1) * k], q);
            }
        }
    }

    /// Energy of force `force` at time `t` as a function of q, with its gradient added to
    /// `grad_q`, and the size of the terms the energy sums (for rounding estimates: a spring's
    /// energy is a difference of larger terms). Zero when the force is not active at `t`.
    ///
    /// A spring pulls each of its n vertices towards the offset v(t) with stiffness κ = k_f/n:
    /// ½κ Σ_v |U_v q − v|² = ½κ (qᵀGq − 2 qᵀSv + n|v|²), gradient κ(Gq − Sv), with G = Σ_v U_vᵀU_v
    /// and S = Σ_v U_vᵀ precomputed. A softened spring ([`Self::set_spring_compliance`]) has v
    /// replaced by Rv in the linear and constant terms and its own G. A point load f(t) spread
    /// over n vertices: −qᵀSf/n.
    pub fn force_energy_gradient(
        &self,
        model: &FullSpaceModel,
        force: usize,
        t: f64,
        q: &[f64],
        grad_q: &mut [f64],
        buf: &mut SpaceBuffers,
    ) -> (f64, f64) {
        let f = &model.forces[force];
        if !f.is_active(t) || f.vertices.is_empty() {
            return (0.0, 0.0);
        }
        let k = self.k;
        let n = f.vertices.len() as f64;
        let value = f.value(t);
        let sums = &self.force_sums[force];
        let column = |c: usize| &sums[c * k..(c + 1) * k];
        match f.kind {
            ForceKind::Point => {
                let mut energy = 0.0;
                for c in 0..3 {
                    let fc = value[c] / n;
                    energy -= fc * dot(column(c), q);
                    axpy(-fc, column(c), grad_q);
                }
                (energy, energy.abs())
            }
            ForceKind::Spring => {
                let kappa = f.stiffness / n;
                let gq = &mut buf.gq;
                gq.fill(0.0);
                for (j, &qj) in q.iter().enumerate() {
                    axpy(qj, &self.force_gram[force][j * k..(j + 1) * k], gq);
                }
                let quadratic = dot(q, gq);
                let pulled = self.force_pull[force] * value;
                let mut linear = 0.0;
                for c in 0..3 {
                    linear += pulled[c] * dot(column(c), q);
                    axpy(-pulled[c], column(c), gq);
                }
                axpy(kappa, gq, grad_q);
                let constant = n * value.dot(&pulled);
                let energy = 0.5 * kappa * (quadratic - 2.0 * linear + constant);
                let size = 0.5 * kappa * (quadratic.abs() + 2.0 * linear.abs() + constant);
                (energy, size)
            }
        }
    }

    /// Weighted elastic energy over the element set at coefficients `q` and its gradient ∂V/∂q
    /// (into `grad_q`); `+∞` when some element's energy is undefined. `u` (full length) receives
    /// the decoded rows of the element vertices on the vertex paths; `grad_full` is scratch of full
    /// length (used by the parallel path only). See [`ElasticPath`] for how each path works.
    pub fn elastic_energy_gradient(
        &self,
        model: &FullSpaceModel,
        q: &[f64],
        u: &mut [f64],
        grad_full: &mut [f64],
        grad_q: &mut [f64],
        buf: &mut SpaceBuffers,
    ) -> f64 {
        if self.elastic_path == ElasticPath::ElementBasis {
            return with_material!(&model.material, |mat| self
                .elastic_element_basis(mat, q, grad_q, buf));
        }
        self.decode_touched(q, u, buf);
        let m = self.element_rows();
        let gt = &mut buf.packed[..m];
        let energy = if self.elastic_path == ElasticPath::Vertices {
            with_material!(&model.material, |mat| self
                .elastic_serial(model, mat, u, gt))
        } else {
            let set = ElementSet::Weighted {
                indices: &self.elements,
                weights: &self.weights,
            };
            let e = with_material!(&model.material, |mat| assembly::energy_gradient(
                mat,
                &model.elements,
                set,
                u,
                grad_full,
                &mut buf.assembly
            ));
            for (&v, x) in self.touched.iter().zip(gt.chunks_exact_mut(3)) {
                x.copy_from_slice(&grad_full[3 * v..3 * v + 3]);
            }
            e
        };
        grad_q.fill(0.0);
        self.packed.apply_transpose_add(gt, grad_q);
        energy
    }

    /// [`ElasticPath::ElementBasis`]: F = I + B_e q, then ∂V/∂q += w V B_eᵀ vec(P), element by
    /// element.
    fn elastic_element_basis<M: Material>(
        &self,
        material: &M,
        q: &[f64],
        grad_q: &mut [f64],
        buf: &mut SpaceBuffers,
    ) -> f64 {
        let k = self.k;
        buf.qpad[..k].copy_from_slice(q);
        buf.gpad.fill(0.0);
        let (energy, undefined) = Arch::new().dispatch(BasisPass {
            material,
            basis: &self.element_basis,
            scales: &self.element_scales,
            q: &buf.qpad,
            grad: &mut buf.gpad,
        });
        grad_q.copy_from_slice(&buf.gpad[..k]);
        if undefined { f64::INFINITY } else { energy }
    }

    /// Energy of the set and its gradient in packed order (`gt`, 3 per element vertex). (Compiled
    /// for AVX2 under `pulp`'s dispatch this loop measured 25 % slower than the baseline build.)
    fn elastic_serial<M: Material>(
        &self,
        model: &FullSpaceModel,
        material: &M,
        u: &[f64],
        gt: &mut [f64],
    ) -> f64 {
        gt.fill(0.0);
        let mut energy = 0.0;
        let mut undefined = false;
        for ((&e, &w), at) in self
            .elements
            .iter()
            .zip(&self.weights)
            .zip(&self.element_touched)
        {
            let (psi_w, g, _) = model.elements.energy_gradient(material, e, u, w);
            undefined |= psi_w.is_nan();
            energy += psi_w;
            for a in 0..4 {
                let p = 3 * at[a] as usize;
                for i in 0..3 {
                    gt[p + i] += g[3 * a + i];
                }
            }
        }
        if undefined { f64::INFINITY } else { energy }
    }

    /// Σ_e w_e U_eᵀ H_e U_e over `elements` at displacement `u` (H_e projected when asked),
    /// written to `out` (k×k column-major) and returned.
    pub fn project_hessian<'a, M: Material>(
        &self,
        model: &FullSpaceModel,
        material: &M,
        elements: &[usize],
        weights: &[f64],
        u: &[f64],
        projected: bool,
        out: &'a mut [f64],
    ) -> &'a [f64] {
        let k = self.k;
        out.fill(0.0);
        let mut ue = vec![0.0; 12 * k];
        let mut hu = vec![0.0; 12 * k];
        for (&e, &w) in elements.iter().zip(weights) {
            let f: Mat3 = model.elements.deformation_gradient(e, u);
            let a = if projected {
                material.dpdf_projected(&f)
            } else {
                material.dpdf(&f)
            };
            let h = model.elements.local_hessian(e, &a, w);
            let tet = model.elements.tets[e];
            for (a_local, &v) in tet.iter().enumerate() {
                let r = self.rows_of(v);
                ue[a_local * 3 * k..(a_local + 1) * 3 * k].copy_from_slice(r);
            }
            // hu = H U_e (12×k, row-major), then out += U_eᵀ hu.
            for i in 0..12 {
                let hrow = &h[i * 12..(i + 1) * 12];
                let dst = &mut hu[i * k..(i + 1) * k];
                dst.fill(0.0);
                for (l, &hv) in hrow.iter().enumerate() {
                    if hv != 0.0 {
                        axpy(hv, &ue[l * k..(l + 1) * k], dst);
                    }
                }
            }
            for i in 0..12 {
                let urow = &ue[i * k..(i + 1) * k];
                let hrow = &hu[i * k..(i + 1) * k];
                for b in 0..k {
                    let hb = hrow[b];
                    if hb != 0.0 {
                        axpy(hb, urow, &mut out[b * k..(b + 1) * k]);
                    }
                }
            }
        }
        out
    }
}

/// [`ReducedSpace`]'s slot of a vertex whose rows it does not hold.
const NO_ROWS: u32 = u32::MAX;

/// The data a [`ReducedSpace`] is rebuilt from ([`ReducedSpace::parts`],
/// [`ReducedSpace::from_parts`]): the basis rows of some vertices and the reduced matrices
/// computed from the whole basis.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SpaceParts {
    /// Number of basis vectors.
    pub k: usize,
    /// Vertices whose rows are kept, increasing.
    pub vertices: Vec<usize>,
    /// Their rows: a row-major 3×k block per vertex.
    pub rows: Vec<f64>,
    /// UᵀMU and UᵀK₀U (k×k, column-major), K₀ the stiffness at rest over every element.
    pub mass: Vec<f64>,
    pub rest_stiffness: Vec<f64>,
    /// Uᵀf_g per unit acceleration along x, y and z (3 columns of k, column-major; the
    /// lumped masses' load): the reduced gravity load of any acceleration.
    pub gravity_axes: Vec<f64>,
    /// The material the reduced matrices were computed with (the mass, the rest stiffness and
    /// the gravity load depend on it), and the basis, decoder and rule made for.
    pub material: MaterialConfig,
}

/// A rule's elements exist (`count` of them) and its weights are as many, finite and not
/// negative.
fn check_rule(elements: &[usize], weights: &[f64], count: usize) -> Result<(), ReducedError> {
    let bad = |reason: String| Err(ReducedError::Cubature { reason });
    if elements.len() != weights.len() {
        return bad(format!(
            "{} elements but {} weights",
            elements.len(),
            weights.len()
        ));
    }
    if let Some(&e) = elements.iter().find(|&&e| e >= count) {
        return bad(format!("element {e} does not exist (the mesh has {count})"));
    }
    if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return bad(format!("weight {w} is not a finite, non-negative number"));
    }
    Ok(())
}

/// aᵀb with eight independent accumulators (vectorisable; the order of the sum differs from
/// the sequential one only by rounding).
#[inline]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    let mut acc = [0.0f64; 8];
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// y += a x.
#[inline]
pub(crate) fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}
