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
#[derive(Debug)]
pub struct HessianPattern {
    pub symbolic: SymbolicSparseColMat<usize>,
    /// For each element, the value index of its local entry (3a+i, 3b+k) (row-major 12×12).
    pub element_slots: Vec<[u32; 144]>,
    /// Value index of each free DOF's diagonal entry.
    pub diag: Vec<usize>,
    /// The columns split into one part per thread of the rayon pool the pattern was built in,
    /// balanced by number of entries.
    pub parts: Vec<ColumnPart>,
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
    pub fn new(tets: &[[usize; 4]], dofs: &DofMap) -> Self {
        let nv = dofs.num_full() / 3;
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
        let element_slots = tets
            .par_iter()
            .map(|t| {
                let mut s = [NO_SLOT; 144];
                for a in 0..4 {
                    for i in 0..3 {
                        let r = dofs.index[3 * t[a] + i];
                        if r == FIXED {
                            continue;
                        }
                        for b in 0..4 {
                            for k in 0..3 {
                                let c = dofs.index[3 * t[b] + k];
                                if c != FIXED {
                                    s[(3 * a + i) * 12 + 3 * b + k] = find(r, c);
                                }
                            }
                        }
                    }
                }
                s
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
