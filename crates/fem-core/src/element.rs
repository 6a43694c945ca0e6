//! Linear tetrahedral elements: precomputed rest-shape data and the per-element kinematics.
//!
//! For tet e with rest vertices X₀..X₃, Dm = [X₁−X₀, X₂−X₀, X₃−X₀], Bm = Dm⁻¹ and the rest volume
//! W = |det Dm| / 6. With displacements u, the deformation gradient is
//! F = I + [u₁−u₀, u₂−u₀, u₃−u₀] Bm (computed from displacements, not positions, so small
//! deformations keep their relative precision). The shape gradient of vertex b ≥ 1 is gᵦ = row
//! b−1 of Bm and g₀ = −(g₁+g₂+g₃), so ∂V/∂u_b = W P g_b and
//! ∂²V/∂u_{a,i}∂u_{b,k} = W Σ_{j,l} (∂P/∂F)_{ij,kl} g_{a,j} g_{b,l}.

use crate::material::{Mat9, Material};
use crate::{Mat3, TetMesh};

/// Rest-shape data of every element, structure-of-arrays.
#[derive(Debug, Clone)]
pub struct Elements {
    /// Vertex indices of each tet (positively oriented).
    pub tets: Vec<[usize; 4]>,
    /// Bm = Dm⁻¹ of each tet.
    pub bm: Vec<Mat3>,
    /// Rest volume W of each tet.
    pub volume: Vec<f64>,
}

/// Local gradient of one element: 4 vertices × 3 components, index 3a + i.
pub type LocalVector = [f64; 12];
/// Local Hessian of one element, row-major 12×12 with index 3a + i.
pub type LocalMatrix = [f64; 144];

impl Elements {
    /// Precomputes Bm and W for every tet of a validated mesh.
    pub fn new(mesh: &TetMesh) -> Self {
        let mut bm = Vec::with_capacity(mesh.num_tets());
        let mut volume = Vec::with_capacity(mesh.num_tets());
        for t in &mesh.tets {
            let x0 = mesh.vertices[t[0]];
            let dm = Mat3::from_columns(&[
                mesh.vertices[t[1]] - x0,
                mesh.vertices[t[2]] - x0,
                mesh.vertices[t[3]] - x0,
            ]);
            volume.push(dm.determinant().abs() / 6.0);
            // Validation rejected degenerate tets, so Dm is invertible.
            bm.push(dm.try_inverse().unwrap_or_else(Mat3::zeros));
        }
        Self {
            tets: mesh.tets.clone(),
            bm,
            volume,
        }
    }

    pub fn len(&self) -> usize {
        self.tets.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tets.is_empty()
    }

    /// F of element `e` for the full displacement vector `u` (length 3n).
    #[inline]
    pub fn deformation_gradient(&self, e: usize, u: &[f64]) -> Mat3 {
        let t = &self.tets[e];
        let u0 = [u[3 * t[0]], u[3 * t[0] + 1], u[3 * t[0] + 2]];
        let mut d = Mat3::zeros();
        for b in 0..3 {
            let v = t[b + 1];
            for i in 0..3 {
                d[(i, b)] = u[3 * v + i] - u0[i];
            }
        }
        Mat3::identity() + d * self.bm[e]
    }

    /// The gradients g_a = ∂N_a/∂X of element `e`'s four linear shape functions: g_1..g_3 are the
    /// rows of Bm, g_0 = −(g_1 + g_2 + g_3). F = I + Σ_a u_a ⊗ g_a.
    #[inline]
    pub fn shape_gradients(&self, e: usize) -> [[f64; 3]; 4] {
        let bm = &self.bm[e];
        let mut g = [[0.0f64; 3]; 4];
        for b in 1..4 {
            for l in 0..3 {
                g[b][l] = bm[(b - 1, l)];
            }
        }
        for l in 0..3 {
            g[0][l] = -(g[1][l] + g[2][l] + g[3][l]);
        }
        g
    }

    /// Local gradient W P gₐ of element `e` for stress `p`, weighted by `scale`.
    #[inline]
    pub fn local_gradient(&self, e: usize, p: &Mat3, scale: f64) -> LocalVector {
        let h = p * self.bm[e].transpose() * (self.volume[e] * scale);
        let mut out = [0.0; 12];
        for b in 0..3 {
            for i in 0..3 {
                out[3 * (b + 1) + i] = h[(i, b)];
                out[i] -= h[(i, b)];
            }
        }
        out
    }

    /// Local Hessian W Gᵀ A G of element `e` for the stress derivative `a`, weighted by `scale`.
    ///
    /// Exploits that each column of G = ∂vec(F)/∂u has three non-zeros: the product costs about a
    /// third of a dense 9×12 sandwich.
    #[inline]
    pub fn local_hessian(&self, e: usize, a: &Mat9, scale: f64) -> LocalMatrix {
        let mut columns = [0.0; 144];
        self.local_hessian_columns(e, a, scale, [true; 4], &mut columns);
        let mut out = [0.0; 144];
        for r in 0..12 {
            for c in 0..12 {
                out[12 * r + c] = columns[12 * c + r];
            }
        }
        out
    }

    /// The column blocks `blocks[b]` (columns 3b..3b+3, vertex b) of [`Self::local_hessian`],
    /// written **column-major** into `out` (entry (r, c) at `out[12c + r]`); other entries of
    /// `out` are left as they are. Each block is computed on its own, with the same operations
    /// whichever other blocks are requested, so a subset is bit-identical to the full matrix and
    /// costs about a quarter of it per block.
    ///
    /// Column block b is H_ab = W Σ_j g_a[j] Σ_l g_b[l] A_jl for the rows of vertices a = 1..3,
    /// with A_jl the 3×3 block of A at rows 3j.., columns 3l.., and minus their sum for a = 0.
    #[inline]
    pub(crate) fn local_hessian_columns(
        &self,
        e: usize,
        a: &Mat9,
        scale: f64,
        blocks: [bool; 4],
        out: &mut LocalMatrix,
    ) {
        let g = self.shape_gradients(e);
        // W g_a for the rows of vertices a = 1..3.
        let w = self.volume[e] * scale;
        let wg: [[f64; 3]; 3] = std::array::from_fn(|av| g[av + 1].map(|x| x * w));
        let a: &[f64; 81] = a.as_slice().try_into().expect("9×9");
        let col = |c: usize| -> &[f64; 9] { a[9 * c..9 * c + 9].try_into().expect("9 rows") };
        for b in 0..4 {
            if !blocks[b] {
                continue;
            }
            let gb = g[b];
            for k in 0..3 {
                // y[i + 3j] = Σ_l A[(i + 3j, k + 3l)] g_b[l]: three contiguous columns of A.
                let (c0, c1, c2) = (col(k), col(k + 3), col(k + 6));
                let mut y = [0.0f64; 9];
                for r in 0..9 {
                    y[r] = c0[r] * gb[0] + c1[r] * gb[1] + c2[r] * gb[2];
                }
                // Rows 3a + i of vertices a = 1..3: W Σ_j g_a[j] y[i + 3j].
                let out = &mut out[12 * (3 * b + k)..12 * (3 * b + k) + 12];
                for av in 0..3 {
                    for i in 0..3 {
                        let wga = &wg[av];
                        out[3 * av + 3 + i] = y[i] * wga[0] + y[i + 3] * wga[1] + y[i + 6] * wga[2];
                    }
                }
                // Rows of vertex 0 are minus the sums over vertices 1..3.
                for i in 0..3 {
                    out[i] = -(out[3 + i] + out[6 + i] + out[9 + i]);
                }
            }
        }
    }

    /// Energy, local gradient and F of element `e` (weight `scale`), in one pass.
    #[inline]
    pub fn energy_gradient<M: Material>(
        &self,
        material: &M,
        e: usize,
        u: &[f64],
        scale: f64,
    ) -> (f64, LocalVector, Mat3) {
        let f = self.deformation_gradient(e, u);
        let (psi, p) = material.psi_pk1(&f);
        (
            psi * self.volume[e] * scale,
            self.local_gradient(e, &p, scale),
            f,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::generate::{BoxSpec, box_mesh};

    /// Any subset of column blocks is computed with exactly the operations of the full matrix.
    #[test]
    fn column_blocks_are_bit_identical_to_the_full_local_hessian() {
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.5, 0.3],
            cells: [1, 1, 1],
            ..Default::default()
        })
        .unwrap();
        let elements = Elements::new(&mesh);
        let a =
            Mat9::from_fn(|i, j| ((3 * i + 5 * j) as f64).sin() + if i == j { 4.0 } else { 0.0 });
        for e in 0..elements.len() {
            let full = elements.local_hessian(e, &a, 0.7);
            for mask in 1..16u32 {
                let blocks: [bool; 4] = std::array::from_fn(|b| mask & (1 << b) != 0);
                let mut out = [f64::NAN; 144];
                elements.local_hessian_columns(e, &a, 0.7, blocks, &mut out);
                for r in 0..12 {
                    for c in 0..12 {
                        if blocks[c / 3] {
                            let (x, y) = (out[12 * c + r], full[12 * r + c]);
                            assert_eq!(x.to_bits(), y.to_bits(), "{mask:b} ({r}, {c})");
                        }
                    }
                }
            }
        }
    }
}
