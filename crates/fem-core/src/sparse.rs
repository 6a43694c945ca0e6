//! Sparsity pattern of the free-DOF Hessian and the scatter maps from element matrices into it.
//!
//! The pattern stores both triangles (column-compressed, rows sorted), so it serves matrix–vector
//! products as well as the sparse Cholesky factorisation (which reads the lower triangle). It is
//! built once per mesh and pin set; every Newton iteration only refills the values.
//!
//! For parallel assembly the columns are split into [`ColumnPart`]s: contiguous column ranges,
//! hence contiguous, disjoint ranges of the values array that threads can fill independently.

use std::ops::Range;

use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use rayon::prelude::*;

use crate::constraints::{DofMap, FIXED};
use crate::mass::VertexCsr;

/// Marks a local entry that touches a fixed DOF.
pub const NO_SLOT: u32 = u32::MAX;

/// Free-DOF Hessian pattern plus the slot of every element entry in the values array.
#[derive(Debug, Clone)]
pub struct HessianPattern {
    pub symbolic: SymbolicSparseColMat<usize>,
    /// For each element, where its local entries go in the values array.
    pub element_slots: Vec<ElementSlots>,
    /// Value index of each free DOF's diagonal entry.
    pub diag: Vec<usize>,
    /// The columns split into one part per thread of the rayon pool the pattern was built in,
    /// balanced by number of entries.
    pub parts: Vec<ColumnPart>,
}

/// Where the local Hessian of one element goes in the values array.
///
/// DOFs are freed or fixed by whole vertices, and a free vertex's three DOFs are consecutive, so
/// the three columns of a vertex have the same rows and a vertex's three rows are adjacent in
/// each of them: local entry (3a+i, 3b+k) of vertex pair (a, b) is at value index
/// `base[4a + b] + k·stride[b] + i`. Six times smaller than a slot per entry, and a scatter adds
/// runs of three.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ElementSlots {
    /// Value index of local entry (3a, 3b), or [`NO_SLOT`] when vertex a or b is fixed.
    pub base: [u32; 16],
    /// Number of entries in each column of vertex b: the distance between its columns.
    pub stride: [u32; 4],
}

impl ElementSlots {
    /// Value index of local entry (r, c), or [`NO_SLOT`] when its row or column is fixed.
    #[inline]
    pub fn slot(&self, r: usize, c: usize) -> u32 {
        let (a, i, b, k) = (r / 3, r % 3, c / 3, c % 3);
        let base = self.base[4 * a + b];
        if base == NO_SLOT {
            NO_SLOT
        } else {
            base + k as u32 * self.stride[b] + i as u32
        }
    }
}

/// A contiguous range of columns of a [`HessianPattern`], hence a contiguous range of its
/// values, and the elements with an entry in those columns.
#[derive(Debug, Clone)]
pub struct ColumnPart {
    /// The value indices of the part's columns.
    pub values: Range<usize>,
    /// The elements with at least one entry in the part, ascending.
    pub elements: Vec<u32>,
}

impl HessianPattern {
    /// Builds the pattern of all vertex pairs that share a tet, restricted to free DOFs.
    ///
    /// # Panics
    ///
    /// If `dofs` frees only some DOFs of a vertex, or numbers a vertex's free DOFs apart
    /// ([`DofMap::new`] never does).
    pub fn new(tets: &[[usize; 4]], dofs: &DofMap) -> Self {
        let nv = dofs.num_full() / 3;
        for v in 0..nv {
            let d = &dofs.index[3 * v..3 * v + 3];
            assert!(
                d.iter().all(|&x| x == FIXED)
                    || (d[0] != FIXED && d[1] == d[0] + 1 && d[2] == d[0] + 2),
                "vertex {v}: DOFs must be freed or fixed by whole vertices, consecutively"
            );
        }
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); nv];
        for t in tets {
            for &a in t {
                adj[a].extend_from_slice(t);
            }
        }
        adj.par_iter_mut().for_each(|l| {
            l.sort_unstable();
            l.dedup();
        });
        let n = dofs.num_free();
        let mut col_ptr = Vec::with_capacity(n + 1);
        col_ptr.push(0usize);
        let mut row_idx = Vec::new();
        for &d in &dofs.free {
            for &w in &adj[d / 3] {
                for c in 0..3 {
                    let r = dofs.index[3 * w + c];
                    if r != FIXED {
                        row_idx.push(r);
                    }
                }
            }
            col_ptr.push(row_idx.len());
        }
        assert!(
            row_idx.len() < NO_SLOT as usize,
            "Hessian has more than 2^32 entries"
        );
        let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let find = |row: usize, col: usize| -> u32 {
            let cp = symbolic.col_ptr();
            let rows = &symbolic.row_idx()[cp[col]..cp[col + 1]];
            match rows.binary_search(&row) {
                Ok(k) => (cp[col] + k) as u32,
                Err(_) => NO_SLOT,
            }
        };
        let cp = symbolic.col_ptr();
        let element_slots = tets
            .par_iter()
            .map(|t| {
                let first = t.map(|v| dofs.index[3 * v]);
                let mut slots = ElementSlots {
                    base: [NO_SLOT; 16],
                    stride: [0; 4],
                };
                for b in 0..4 {
                    if first[b] == FIXED {
                        continue;
                    }
                    slots.stride[b] = (cp[first[b] + 1] - cp[first[b]]) as u32;
                    for a in 0..4 {
                        if first[a] != FIXED {
                            slots.base[4 * a + b] = find(first[a], first[b]);
                        }
                    }
                }
                slots
            })
            .collect();
        let diag = (0..n).map(|j| find(j, j) as usize).collect();
        let parts = column_parts(&symbolic, tets, dofs, rayon::current_num_threads());
        Self {
            symbolic,
            element_slots,
            diag,
            parts,
        }
    }

    pub fn nnz(&self) -> usize {
        self.symbolic.row_idx().len()
    }

    pub fn dim(&self) -> usize {
        self.diag.len()
    }

    /// A view of `values` as a sparse matrix with this pattern.
    pub fn matrix<'a>(&'a self, values: &'a [f64]) -> SparseColMatRef<'a, usize, f64> {
        SparseColMatRef::new(self.symbolic.as_ref(), values)
    }

    /// Slots of a vertex-level matrix (e.g. consistent mass): for CSR entry k and component c,
    /// `out[3k + c]` is its value index, or [`NO_SLOT`] when a DOF is fixed.
    pub fn vertex_csr_slots(&self, csr: &VertexCsr, dofs: &DofMap) -> Vec<u32> {
        let cp = self.symbolic.col_ptr();
        let ri = self.symbolic.row_idx();
        let mut out = vec![NO_SLOT; 3 * csr.col.len()];
        for v in 0..csr.row_ptr.len() - 1 {
            for k in csr.row_ptr[v]..csr.row_ptr[v + 1] {
                let w = csr.col[k];
                for c in 0..3 {
                    let (r, col) = (dofs.index[3 * v + c], dofs.index[3 * w + c]);
                    if r != FIXED && col != FIXED {
                        let rows = &ri[cp[col]..cp[col + 1]];
                        if let Ok(p) = rows.binary_search(&r) {
                            out[3 * k + c] = (cp[col] + p) as u32;
                        }
                    }
                }
            }
        }
        out
    }

    /// y = A x for the symmetric matrix with these values.
    pub fn mul_vec(&self, values: &[f64], x: &[f64], y: &mut [f64]) {
        let cp = self.symbolic.col_ptr();
        let ri = self.symbolic.row_idx();
        y.fill(0.0);
        for j in 0..self.dim() {
            let xj = x[j];
            for k in cp[j]..cp[j + 1] {
                y[ri[k]] += values[k] * xj;
            }
        }
    }
}

/// Splits the columns into `count` contiguous parts of about equal numbers of entries, and lists
/// for each part the elements that have an entry in it (an element with free DOFs in several
/// parts is listed in each of them).
fn column_parts(
    symbolic: &SymbolicSparseColMat<usize>,
    tets: &[[usize; 4]],
    dofs: &DofMap,
    count: usize,
) -> Vec<ColumnPart> {
    let cp = symbolic.col_ptr();
    let (n, nnz) = (cp.len() - 1, cp[cp.len() - 1]);
    let count = count.clamp(1, n.max(1));
    // bounds[p]..bounds[p + 1] are the columns of part p.
    let mut bounds = vec![0usize; count + 1];
    for p in 1..count {
        let target = nnz * p / count;
        bounds[p] = cp.partition_point(|&x| x < target).clamp(bounds[p - 1], n);
    }
    bounds[count] = n;
    assert!(tets.len() <= u32::MAX as usize, "more than 2^32 elements");
    let mut elements = vec![Vec::new(); count];
    let mut touched = Vec::with_capacity(12);
    for (e, t) in tets.iter().enumerate() {
        touched.clear();
        for &v in t {
            for c in 0..3 {
                let col = dofs.index[3 * v + c];
                if col != FIXED {
                    touched.push(bounds.partition_point(|&b| b <= col) - 1);
                }
            }
        }
        touched.sort_unstable();
        touched.dedup();
        for &p in &touched {
            elements[p].push(e as u32);
        }
    }
    elements
        .into_iter()
        .enumerate()
        .map(|(p, elements)| ColumnPart {
            values: cp[bounds[p]]..cp[bounds[p + 1]],
            elements,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::generate::{BoxSpec, box_mesh};

    /// Every local entry's slot is where the pattern stores (row, column), and the column parts
    /// tile the values and list exactly the elements with an entry in them.
    #[test]
    fn element_slots_and_column_parts_match_the_pattern() {
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.3, 0.2],
            cells: [5, 2, 2],
            ..Default::default()
        })
        .unwrap();
        let pinned: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].x == 0.0 || v % 7 == 3)
            .collect();
        let dofs = DofMap::new(&mesh, &pinned);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let pattern = pool.install(|| HessianPattern::new(&mesh.tets, &dofs));
        let (cp, ri) = (pattern.symbolic.col_ptr(), pattern.symbolic.row_idx());
        let mut touches = vec![vec![false; mesh.num_tets()]; pattern.parts.len()];
        for (e, t) in mesh.tets.iter().enumerate() {
            for r in 0..12 {
                for c in 0..12 {
                    let row = dofs.index[3 * t[r / 3] + r % 3];
                    let col = dofs.index[3 * t[c / 3] + c % 3];
                    let slot = pattern.element_slots[e].slot(r, c);
                    if row == FIXED || col == FIXED {
                        assert_eq!(slot, NO_SLOT);
                        continue;
                    }
                    let s = slot as usize;
                    assert!(
                        (cp[col]..cp[col + 1]).contains(&s) && ri[s] == row,
                        "{e} ({r}, {c})"
                    );
                    let p = pattern
                        .parts
                        .iter()
                        .position(|p| p.values.contains(&s))
                        .unwrap();
                    touches[p][e] = true;
                }
            }
        }
        assert_eq!(pattern.parts.len(), 3);
        assert_eq!(pattern.parts[0].values.start, 0);
        assert_eq!(pattern.parts[2].values.end, pattern.nnz());
        for (p, part) in pattern.parts.iter().enumerate() {
            if p > 0 {
                assert_eq!(pattern.parts[p - 1].values.end, part.values.start);
            }
            let expect: Vec<u32> = (0..mesh.num_tets() as u32)
                .filter(|&e| touches[p][e as usize])
                .collect();
            assert_eq!(part.elements, expect);
        }
    }
}
