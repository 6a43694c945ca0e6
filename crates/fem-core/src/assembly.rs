//! Assembly of energy, gradient and (projected) Hessian over a weighted element set Σ w_e V_e.
//!
//! The full mesh is the set of all elements with weight 1; a cubature rule is a small set with
//! its own weights. Both go through the same code. Element work runs in parallel (rayon) into
//! per-element buffers owned by [`AssemblyBuffers`]; the scatter into global vectors is serial and
//! in element order, so results are bit-identical for any thread count.

use rayon::prelude::*;

use crate::element::{Elements, LocalMatrix, LocalVector};
use crate::material::Material;
use crate::sparse::{HessianPattern, NO_SLOT};

/// Elements below this count per task are not worth splitting further.
const MIN_CHUNK: usize = 256;

/// Which elements contribute, and with which weights.
#[derive(Debug, Clone, Copy)]
pub enum ElementSet<'a> {
    /// Every element, weight 1.
    All,
    /// A subset with non-negative weights (a cubature rule).
    Weighted {
        indices: &'a [usize],
        weights: &'a [f64],
    },
}

impl ElementSet<'_> {
    pub fn len(&self, elements: &Elements) -> usize {
        match self {
            ElementSet::All => elements.len(),
            ElementSet::Weighted { indices, .. } => indices.len(),
        }
    }

    pub fn is_empty(&self, elements: &Elements) -> bool {
        self.len(elements) == 0
    }

    /// Element index and weight of the k-th member.
    #[inline]
    pub fn get(&self, k: usize) -> (usize, f64) {
        match self {
            ElementSet::All => (k, 1.0),
            ElementSet::Weighted { indices, weights } => (indices[k], weights[k]),
        }
    }
}

/// Reusable per-element scratch, so repeated assemblies do not allocate.
#[derive(Debug, Default)]
pub struct AssemblyBuffers {
    energy: Vec<f64>,
    grad: Vec<LocalVector>,
    hess: Vec<LocalMatrix>,
}

/// Total weighted energy Σ w_e W_e ψ(F_e); `+∞` when some element's energy is undefined.
pub fn energy<M: Material>(
    material: &M,
    elements: &Elements,
    set: ElementSet<'_>,
    u: &[f64],
    buf: &mut AssemblyBuffers,
) -> f64 {
    let n = set.len(elements);
    buf.energy.resize(n, 0.0);
    buf.energy
        .par_iter_mut()
        .with_min_len(MIN_CHUNK)
        .enumerate()
        .for_each(|(k, out)| {
            let (e, w) = set.get(k);
            let f = elements.deformation_gradient(e, u);
            *out = w * elements.volume[e] * material.psi(&f);
        });
    sum_energy(&buf.energy)
}

/// Energy and its gradient with respect to the full displacement vector (overwrites `grad`).
pub fn energy_gradient<M: Material>(
    material: &M,
    elements: &Elements,
    set: ElementSet<'_>,
    u: &[f64],
    grad: &mut [f64],
    buf: &mut AssemblyBuffers,
) -> f64 {
    let n = set.len(elements);
    buf.energy.resize(n, 0.0);
    buf.grad.resize(n, [0.0; 12]);
    buf.energy
        .par_iter_mut()
        .zip(buf.grad.par_iter_mut())
        .with_min_len(MIN_CHUNK)
        .enumerate()
        .for_each(|(k, (en, g))| {
            let (e, w) = set.get(k);
            let (psi_w, local, _) = elements.energy_gradient(material, e, u, w);
            *en = psi_w;
            *g = local;
        });
    grad.fill(0.0);
    for k in 0..n {
        let (e, _) = set.get(k);
        let t = &elements.tets[e];
        let g = &buf.grad[k];
        for a in 0..4 {
            for i in 0..3 {
                grad[3 * t[a] + i] += g[3 * a + i];
            }
        }
    }
    sum_energy(&buf.energy)
}

/// Assembles the Hessian of the weighted elastic energy into `values` (overwritten), on the
/// free-DOF `pattern`. With `projected`, each element's ∂P/∂F is projected onto the PSD cone
/// first, so the result is positive semidefinite.
pub fn hessian<M: Material>(
    material: &M,
    elements: &Elements,
    set: ElementSet<'_>,
    u: &[f64],
    projected: bool,
    pattern: &HessianPattern,
    values: &mut [f64],
    buf: &mut AssemblyBuffers,
) {
    let n = set.len(elements);
    buf.hess.resize(n, [0.0; 144]);
    buf.hess
        .par_iter_mut()
        .with_min_len(MIN_CHUNK / 4)
        .enumerate()
        .for_each(|(k, h)| {
            let (e, w) = set.get(k);
            let f = elements.deformation_gradient(e, u);
            let a = if projected {
                material.dpdf_projected(&f)
            } else {
                material.dpdf(&f)
            };
            *h = elements.local_hessian(e, &a, w);
        });
    values.fill(0.0);
    for k in 0..n {
        let (e, _) = set.get(k);
        let slots = &pattern.element_slots[e];
        let h = &buf.hess[k];
        for r in 0..144 {
            let s = slots[r];
            if s != NO_SLOT {
                values[s as usize] += h[r];
            }
        }
    }
}

/// The first element of the set with det F ≤ 0, with its determinant.
pub fn find_inverted(elements: &Elements, set: ElementSet<'_>, u: &[f64]) -> Option<(usize, f64)> {
    (0..set.len(elements)).find_map(|k| {
        let (e, _) = set.get(k);
        let det = elements.deformation_gradient(e, u).determinant();
        (det <= 0.0 || det.is_nan()).then_some((e, det))
    })
}

fn sum_energy(values: &[f64]) -> f64 {
    let mut s = 0.0;
    for &v in values {
        if v.is_nan() {
            return f64::INFINITY;
        }
        s += v;
    }
    s
}
