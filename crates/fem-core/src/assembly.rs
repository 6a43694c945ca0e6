//! Assembly of energy, gradient and (projected) Hessian over a weighted element set Σ w_e V_e.
//!
//! The full mesh is the set of all elements with weight 1; a cubature rule is a small set with
//! its own weights. Both go through the same code. Element work runs in parallel (rayon) into
//! per-element buffers owned by [`AssemblyBuffers`]. Every global entry is summed in element
//! order, so results are bit-identical for any thread count: the gradient scatter is serial; the
//! Hessian is scattered in parallel by column ranges ([`crate::sparse::ColumnPart`]), each part
//! visiting its elements in ascending order.

use rayon::prelude::*;

use crate::element::{Elements, LocalMatrix, LocalVector};
use crate::material::{Mat9, Material};
use crate::sparse::{ColumnPart, ElementSlots, HessianPattern, NO_SLOT};

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
#[derive(Debug, Clone, Default)]
pub struct AssemblyBuffers {
    energy: Vec<f64>,
    grad: Vec<LocalVector>,
    /// ∂P/∂F (or its projection) of each element, for the parallel Hessian scatter.
    tangent: Vec<Mat9>,
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
///
/// On one thread (or for a weighted set) each element's matrix is scattered as soon as it is
/// computed. On more threads the element tangents are computed in parallel first, then each
/// [`ColumnPart`] of the pattern is filled by one task: it evaluates only the column blocks of
/// its elements that it owns and adds them into its own slice of `values`. Either way each entry
/// is the same sum in the same (element) order.
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
    values.fill(0.0);
    let tangent = |e: usize| {
        let f = elements.deformation_gradient(e, u);
        if projected {
            material.dpdf_projected(&f)
        } else {
            material.dpdf(&f)
        }
    };
    let serial = rayon::current_num_threads() == 1
        || pattern.parts.len() == 1
        || matches!(set, ElementSet::Weighted { .. });
    if serial {
        let mut h = [0.0; 144];
        for k in 0..set.len(elements) {
            let (e, w) = set.get(k);
            elements.local_hessian_columns(e, &tangent(e), w, [true; 4], &mut h);
            let slots = &pattern.element_slots[e];
            for b in 0..4 {
                for k in 0..3 {
                    add_column(values, 0, &h, slots, b, k);
                }
            }
        }
        return;
    }

    buf.tangent.resize(elements.len(), Mat9::zeros());
    buf.tangent
        .par_iter_mut()
        .with_min_len(MIN_CHUNK / 4)
        .enumerate()
        .for_each(|(e, a)| *a = tangent(e));
    // Disjoint slices of `values`, one per part (the parts tile the values in order).
    let mut tasks: Vec<(&ColumnPart, &mut [f64])> = Vec::with_capacity(pattern.parts.len());
    let mut rest = &mut values[..];
    for part in &pattern.parts {
        let (mine, tail) = rest.split_at_mut(part.values.len());
        tasks.push((part, mine));
        rest = tail;
    }
    let tangents = &buf.tangent;
    tasks.into_par_iter().for_each(|(part, vals)| {
        let (lo, len) = (part.values.start, vals.len());
        // The value index relative to this part, or ≥ len when not in it (NO_SLOT included,
        // since every value index is below NO_SLOT).
        let local = |s: u32| (s as usize).wrapping_sub(lo);
        let mut h = [0.0; 144];
        for &e in &part.elements {
            let e = e as usize;
            let slots = &pattern.element_slots[e];
            // Column (b, k) is in this part iff its (free) diagonal entry is.
            let owned = |b: usize, k: usize| {
                let base = slots.base[5 * b];
                base != NO_SLOT && local(base + k as u32 * (slots.stride[b] + 1)) < len
            };
            let own: [[bool; 3]; 4] = std::array::from_fn(|b| std::array::from_fn(|k| owned(b, k)));
            let blocks = own.map(|o| o.contains(&true));
            elements.local_hessian_columns(e, &tangents[e], 1.0, blocks, &mut h);
            for b in 0..4 {
                for k in 0..3 {
                    if own[b][k] {
                        add_column(vals, lo, &h, slots, b, k);
                    }
                }
            }
        }
    });
}

/// Adds column 3b+k of the local Hessian `h` (column-major) to `values`, which starts at value
/// index `offset`: one run of three per free vertex a (see [`ElementSlots`]).
#[inline]
fn add_column(
    values: &mut [f64],
    offset: usize,
    h: &LocalMatrix,
    slots: &ElementSlots,
    b: usize,
    k: usize,
) {
    let c = 3 * b + k;
    let shift = k * slots.stride[b] as usize;
    for a in 0..4 {
        let base = slots.base[4 * a + b];
        if base != NO_SLOT {
            let p = base as usize + shift - offset;
            let run = &mut values[p..p + 3];
            for i in 0..3 {
                run[i] += h[12 * c + 3 * a + i];
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constraints::DofMap;
    use crate::material::{Corotated, Lame, NeoHookean, StableNeoHookean};
    use crate::mesh::generate::{BoxSpec, box_mesh};

    fn pool(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
    }

    /// The definition, independently of the scheduling: each member's [`Elements::local_hessian`]
    /// scattered in set order.
    fn reference<M: Material>(
        m: &M,
        elements: &Elements,
        set: ElementSet<'_>,
        u: &[f64],
        projected: bool,
        pattern: &HessianPattern,
    ) -> Vec<f64> {
        let mut values = vec![0.0; pattern.nnz()];
        for k in 0..set.len(elements) {
            let (e, w) = set.get(k);
            let f = elements.deformation_gradient(e, u);
            let a = if projected {
                m.dpdf_projected(&f)
            } else {
                m.dpdf(&f)
            };
            let h = elements.local_hessian(e, &a, w);
            for r in 0..12 {
                for c in 0..12 {
                    let s = pattern.element_slots[e].slot(r, c);
                    if s != NO_SLOT {
                        values[s as usize] += h[12 * r + c];
                    }
                }
            }
        }
        values
    }

    fn check<M: Material>(m: &M, elements: &Elements, u: &[f64], patterns: &[HessianPattern]) {
        let indices = [7, 3, 30, 3, 12];
        let weights = [0.5, 2.0, 1.5, 0.25, 3.0];
        let sets = [
            ElementSet::All,
            ElementSet::Weighted {
                indices: &indices,
                weights: &weights,
            },
        ];
        for pattern in patterns {
            for set in sets {
                let exact = reference(m, elements, set, u, false, pattern);
                let projected_ref = reference(m, elements, set, u, true, pattern);
                assert!(exact.iter().all(|x| x.is_finite()));
                // The state is strained enough that some elements are projected.
                assert_ne!(exact, projected_ref, "{}", M::NAME);
                for projected in [false, true] {
                    let expect = if projected { &projected_ref } else { &exact };
                    for threads in [1, 2, 3] {
                        let mut values = vec![f64::NAN; pattern.nnz()];
                        let mut buf = AssemblyBuffers::default();
                        pool(threads).install(|| {
                            hessian(
                                m,
                                elements,
                                set,
                                u,
                                projected,
                                pattern,
                                &mut values,
                                &mut buf,
                            )
                        });
                        let same = values
                            .iter()
                            .zip(expect)
                            .all(|(a, b)| a.to_bits() == b.to_bits());
                        assert!(
                            same,
                            "{}: {} parts, {threads} threads, projected {projected}, {set:?}",
                            M::NAME,
                            pattern.parts.len()
                        );
                    }
                }
            }
        }
    }

    /// Serial and column-parallel assembly give the same bits as the definition, for any thread
    /// count and any number of column parts, with pinned vertices and strained (partly
    /// compressed, so partly projected) elements.
    #[test]
    fn hessian_is_bit_identical_for_any_schedule() {
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.3, 0.2],
            cells: [8, 3, 2],
            ..Default::default()
        })
        .unwrap();
        let elements = Elements::new(&mesh);
        let u: Vec<f64> = (0..3 * mesh.num_vertices())
            .map(|i| 0.02 * (1.7 * i as f64).sin())
            .collect();
        let pinned: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].x == 0.0)
            .collect();
        let dofs = DofMap::new(&mesh, &pinned);
        let patterns: Vec<HessianPattern> = [1, 2, 3, 5]
            .into_iter()
            .map(|p| pool(p).install(|| HessianPattern::new(&elements.tets, &dofs)))
            .collect();
        for (p, pattern) in [1, 2, 3, 5].into_iter().zip(&patterns) {
            assert_eq!(pattern.parts.len(), p);
        }
        let lame = Lame::from_young_poisson(1.0e5, 0.45);
        check(&StableNeoHookean::new(lame), &elements, &u, &patterns);
        check(&NeoHookean::new(lame), &elements, &u, &patterns);
        check(&Corotated::new(lame), &elements, &u, &patterns);
    }
}
