//! The reduced space of a model: rows of the basis U per vertex and the projected constant
//! matrices, plus partial decode and projection over the vertices an element set touches.

use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
use fem_core::constraints::FIXED;
use fem_core::integrator::FullSpaceModel;
use fem_core::material::Material;
use fem_core::{Mat3, with_material};

use crate::ReducedError;

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
    /// Vertices of those elements and of the external forces: the only rows ever decoded.
    pub touched: Vec<usize>,
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
            .chain(model.forces.iter().flat_map(|f| f.vertices.iter().copied()))
            .collect();
        touched.sort_unstable();
        touched.dedup();
        let mut space = Self {
            k,
            rows,
            mass: vec![0.0; k * k],
            rest_stiffness: vec![0.0; k * k],
            gravity: vec![0.0; k],
            elements,
            weights,
            touched,
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

    /// The 3×k rows of U for vertex `v`, row-major.
    #[inline]
    pub fn vertex_rows(&self, v: usize) -> &[f64] {
        &self.rows[v * 3 * self.k..(v + 1) * 3 * self.k]
    }

    /// u_v = U_v q for the touched vertices only (other entries of `u` are left alone).
    pub fn decode_touched(&self, q: &[f64], u: &mut [f64]) {
        for &v in &self.touched {
            self.decode_vertex(v, q, u);
        }
    }

    #[inline]
    fn decode_vertex(&self, v: usize, q: &[f64], u: &mut [f64]) {
        let r = self.vertex_rows(v);
        let k = self.k;
        for c in 0..3 {
            u[3 * v + c] = dot(&r[c * k..(c + 1) * k], q);
        }
    }

    /// The full displacement u = Uq (for output frames).
    pub fn reconstruct(&self, q: &[f64], u: &mut [f64]) {
        for v in 0..u.len() / 3 {
            self.decode_vertex(v, q, u);
        }
    }

    /// out = Σ_v U_vᵀ g_v over the touched vertices.
    pub fn project_touched(&self, g: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        let k = self.k;
        for &v in &self.touched {
            let r = self.vertex_rows(v);
            for c in 0..3 {
                let gv = g[3 * v + c];
                if gv != 0.0 {
                    for (o, u) in out.iter_mut().zip(&r[c * k..(c + 1) * k]) {
                        *o += u * gv;
                    }
                }
            }
        }
    }

    /// out += Σ_v U_vᵀ g_v over `vertices`.
    pub fn project_vertices_add(&self, g: &[f64], vertices: &[usize], out: &mut [f64]) {
        let k = self.k;
        for &v in vertices {
            let r = self.vertex_rows(v);
            for c in 0..3 {
                let gv = g[3 * v + c];
                for (o, u) in out.iter_mut().zip(&r[c * k..(c + 1) * k]) {
                    *o += u * gv;
                }
            }
        }
    }

    /// Weighted elastic energy over the element set and its gradient ∂V/∂q (into `grad_q`).
    /// `u` must hold the decoded touched rows; `grad_full` is scratch of full length.
    pub fn elastic_energy_gradient(
        &self,
        model: &FullSpaceModel,
        u: &[f64],
        grad_full: &mut [f64],
        grad_q: &mut [f64],
        buf: &mut AssemblyBuffers,
    ) -> f64 {
        let set = ElementSet::Weighted {
            indices: &self.elements,
            weights: &self.weights,
        };
        let e = with_material!(&model.material, |m| assembly::energy_gradient(
            m,
            &model.elements,
            set,
            u,
            grad_full,
            buf
        ));
        self.project_touched(grad_full, grad_q);
        e
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
                        for (d, s) in dst.iter_mut().zip(&ue[l * k..(l + 1) * k]) {
                            *d += hv * s;
                        }
                    }
                }
            }
            for i in 0..12 {
                let urow = &ue[i * k..(i + 1) * k];
                let hrow = &hu[i * k..(i + 1) * k];
                for b in 0..k {
                    let hb = hrow[b];
                    if hb != 0.0 {
                        for a2 in 0..k {
                            out[b * k + a2] += urow[a2] * hb;
                        }
                    }
                }
            }
        }
        out
    }
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
