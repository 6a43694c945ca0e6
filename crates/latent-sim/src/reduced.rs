//! The reduced space of a model: rows of the basis U per vertex and the projected constant
//! matrices, plus partial decode and projection over the vertices an element set touches.
//!
//! The rows of the touched vertices are also kept packed, column-major (3·n_touched × k), so that
//! the partial decode u_t = U_t q is k contiguous axpys and the projection U_tᵀ g is k dot
//! products with independent accumulators: both vectorise, where a dot per row is one dependent
//! chain of adds.

use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
use fem_core::constraints::FIXED;
use fem_core::integrator::FullSpaceModel;
use fem_core::material::Material;
use fem_core::{Mat3, with_material};
use pulp::{Arch, Simd, WithSimd};

use crate::ReducedError;

/// Weighted sets up to this many elements are evaluated serially over the touched entries only;
/// larger ones go through the parallel full-length assembly.
pub const SERIAL_MAX_ELEMENTS: usize = 2048;

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
    fn new(vertex_rows: &[f64], k: usize, vertices: &[usize]) -> Self {
        let rows = 3 * vertices.len();
        let mut data = vec![0.0; rows.div_ceil(PANEL) * PANEL * k];
        for (i, &v) in vertices.iter().enumerate() {
            for c in 0..3 {
                let r = &vertex_rows[(3 * v + c) * k..(3 * v + c + 1) * k];
                let row = 3 * i + c;
                for (j, &x) in r.iter().enumerate() {
                    data[(row / PANEL) * PANEL * k + j * PANEL + row % PANEL] = x;
                }
            }
        }
        Self { rows, k, data }
    }

    /// Entry (r, j).
    #[inline]
    pub(crate) fn get(&self, r: usize, j: usize) -> f64 {
        self.data[(r / PANEL) * PANEL * self.k + j * PANEL + r % PANEL]
    }

    /// The panels in row order, each PANEL·k entries (column j at j·PANEL).
    #[inline]
    pub(crate) fn panels(&self) -> std::slice::ChunksExact<'_, f64> {
        self.data.chunks_exact(PANEL * self.k)
    }

    /// out = P q (out has `rows` entries); each entry is the sequential sum over j.
    fn apply(&self, q: &[f64], out: &mut [f64]) {
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

    /// Pᵀ P (k×k, column-major).
    fn gram(&self) -> Vec<f64> {
        let k = self.k;
        let mut out = vec![0.0; k * k];
        for b in 0..k {
            for a in 0..k {
                out[b * k + a] = (0..self.rows)
                    .map(|r| self.get(r, a) * self.get(r, b))
                    .sum();
            }
        }
        out
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

/// Scratch of the partial decode and projection, sized by [`ReducedSpace::buffers`].
#[derive(Debug, Default)]
pub struct SpaceBuffers {
    /// Packed touched values (decoded displacement, then gradients), 3 per touched vertex.
    packed: Vec<f64>,
    /// The packed gradient of one force, 3 per vertex of the largest force.
    force: Vec<f64>,
    assembly: AssemblyBuffers,
}

/// Basis rows, reduced mass / rest stiffness / gravity, and the element set with its vertices.
#[derive(Debug, Clone)]
pub struct ReducedSpace {
    /// Number of basis vectors k.
    pub k: usize,
    /// Row-major 3×k block of U for each vertex (zero for fixed vertices).
    rows: Vec<f64>,
    /// UᵀMU, k×k column-major (the identity for a mass-orthonormal basis and the same mass).
    pub mass: Vec<f64>,
    /// UᵀK₀U, k×k column-major, K₀ the stiffness at rest.
    pub rest_stiffness: Vec<f64>,
    /// Uᵀ f_g.
    pub gravity: Vec<f64>,
    /// Elements evaluated and their weights (all elements, weight 1, without cubature).
    pub elements: Vec<usize>,
    pub weights: Vec<f64>,
    /// Vertices of those elements and of the external forces: the only rows ever decoded. The
    /// vertices of the elements come first (sorted), then those only forces touch (sorted).
    pub touched: Vec<usize>,
    /// How many of `touched` are vertices of the elements.
    element_vertices: usize,
    /// For each element of the set, the positions of its four vertices in `touched`.
    element_touched: Vec<[u32; 4]>,
    /// The rows of `touched`, packed.
    pub(crate) packed: PackedRows,
    /// The rows of each force's vertices, packed, and their Gram matrix Σ_v U_vᵀU_v (k×k).
    force_rows: Vec<PackedRows>,
    pub(crate) force_gram: Vec<Vec<f64>>,
    /// Weighted sets of at most this many elements take the serial path (see
    /// [`SERIAL_MAX_ELEMENTS`]); both paths give bit-identical results.
    pub serial_max_elements: usize,
}

impl ReducedSpace {
    /// `basis` is U, n_free × k column-major, on the model's free DOFs. `cubature` restricts the
    /// elastic energy to weighted elements (None: every element, weight 1).
    pub fn new(
        model: &FullSpaceModel,
        basis: &[f64],
        k: usize,
        cubature: Option<(Vec<usize>, Vec<f64>)>,
    ) -> Result<Self, ReducedError> {
        let nf = model.dofs.num_free();
        if k == 0 || basis.len() != nf * k {
            return Err(ReducedError::BasisShape {
                rows: basis.len() / k.max(1),
                free: nf,
            });
        }
        let nv = model.mesh.num_vertices();
        let mut rows = vec![0.0; nv * 3 * k];
        for v in 0..nv {
            for c in 0..3 {
                let r = model.dofs.index[3 * v + c];
                if r != FIXED {
                    for j in 0..k {
                        rows[(v * 3 + c) * k + j] = basis[j * nf + r];
                    }
                }
            }
        }
        let (elements, weights) = cubature.unwrap_or_else(|| {
            (
                (0..model.elements.len()).collect(),
                vec![1.0; model.elements.len()],
            )
        });
        let mut touched: Vec<usize> = elements
            .iter()
            .flat_map(|&e| model.elements.tets[e])
            .collect();
        touched.sort_unstable();
        touched.dedup();
        let element_vertices = touched.len();
        let mut position = vec![u32::MAX; nv];
        for (i, &v) in touched.iter().enumerate() {
            position[v] = i as u32;
        }
        let mut force_only: Vec<usize> = model
            .forces
            .iter()
            .flat_map(|f| f.vertices.iter().copied())
            .filter(|&v| position[v] == u32::MAX)
            .collect();
        force_only.sort_unstable();
        force_only.dedup();
        touched.extend(force_only);
        let element_touched = elements
            .iter()
            .map(|&e| model.elements.tets[e].map(|v| position[v]))
            .collect();
        let packed = PackedRows::new(&rows, k, &touched);
        let force_rows: Vec<PackedRows> = model
            .forces
            .iter()
            .map(|f| PackedRows::new(&rows, k, &f.vertices))
            .collect();
        let force_gram = force_rows.iter().map(PackedRows::gram).collect();
        let mut space = Self {
            k,
            rows,
            mass: vec![0.0; k * k],
            rest_stiffness: vec![0.0; k * k],
            gravity: vec![0.0; k],
            elements,
            weights,
            touched,
            element_vertices,
            element_touched,
            packed,
            force_rows,
            force_gram,
            serial_max_elements: SERIAL_MAX_ELEMENTS,
        };
        // UᵀMU and Uᵀf_g from the full mass matrix, one basis column at a time.
        let n = model.num_full();
        let (mut col, mut mcol) = (vec![0.0; n], vec![0.0; n]);
        let mut cols = Vec::with_capacity(k);
        for j in 0..k {
            model.dofs.scatter(&basis[j * nf..(j + 1) * nf], &mut col);
            cols.push(col.clone());
        }
        for j in 0..k {
            model.mass.apply(&cols[j], &mut mcol);
            for i in 0..k {
                space.mass[j * k + i] = dot(&cols[i], &mcol);
            }
            space.gravity[j] = dot(&cols[j], &model.gravity_load);
        }
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

    /// Work buffers for [`Self::decode_touched`] and [`Self::elastic_energy_gradient`].
    pub fn buffers(&self) -> SpaceBuffers {
        let largest = self.force_rows.iter().map(|p| p.rows).max().unwrap_or(0);
        SpaceBuffers {
            packed: vec![0.0; self.packed.rows],
            force: vec![0.0; largest],
            assembly: AssemblyBuffers::default(),
        }
    }

    /// The 3×k rows of U for vertex `v`, row-major.
    #[inline]
    pub fn vertex_rows(&self, v: usize) -> &[f64] {
        &self.rows[v * 3 * self.k..(v + 1) * 3 * self.k]
    }

    /// Rows of the element vertices in the packed order (3 per vertex).
    #[inline]
    pub(crate) fn element_rows(&self) -> usize {
        3 * self.element_vertices
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

    /// The full displacement u = Uq (for output frames).
    pub fn reconstruct(&self, q: &[f64], u: &mut [f64]) {
        let k = self.k;
        for v in 0..u.len() / 3 {
            let r = self.vertex_rows(v);
            for c in 0..3 {
                u[3 * v + c] = dot(&r[c * k..(c + 1) * k], q);
            }
        }
    }

    /// out += Σ_v U_vᵀ g_v over the vertices of force `force` (g full length).
    pub fn project_force_add(
        &self,
        model: &FullSpaceModel,
        force: usize,
        g: &[f64],
        out: &mut [f64],
        buf: &mut SpaceBuffers,
    ) {
        let vertices = &model.forces[force].vertices;
        let gf = &mut buf.force[..3 * vertices.len()];
        for (&v, x) in vertices.iter().zip(gf.chunks_exact_mut(3)) {
            x.copy_from_slice(&g[3 * v..3 * v + 3]);
        }
        self.force_rows[force].apply_transpose_add(gf, out);
    }

    /// Weighted elastic energy over the element set and its gradient ∂V/∂q (into `grad_q`);
    /// `+∞` when some element's energy is undefined. `u` must hold the decoded touched rows;
    /// `grad_full` is scratch of full length (used by large sets only).
    ///
    /// Small sets (cubature rules) run serially and touch only the entries of their vertices;
    /// large ones use the parallel assembly. Each gradient entry and the energy are the same
    /// sums in the same (element) order either way.
    pub fn elastic_energy_gradient(
        &self,
        model: &FullSpaceModel,
        u: &[f64],
        grad_full: &mut [f64],
        grad_q: &mut [f64],
        buf: &mut SpaceBuffers,
    ) -> f64 {
        let m = self.element_rows();
        let gt = &mut buf.packed[..m];
        let energy = if self.elements.len() <= self.serial_max_elements {
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

    /// Energy of the set and its gradient in packed order (`gt`, 3 per element vertex).
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
                let r = self.vertex_rows(v);
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
