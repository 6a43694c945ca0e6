//! Linear tetrahedral elements: precomputed rest-shape data and the per-element kinematics.
//!
//! For tet e with rest vertices X₀..X₃, Dm = [X₁−X₀, X₂−X₀, X₃−X₀], Bm = Dm⁻¹ and the rest volume
//! W = |det Dm| / 6. With displacements u, the deformation gradient is
//! F = I + [u₁−u₀, u₂−u₀, u₃−u₀] Bm (computed from displacements, not positions, so small
//! deformations keep their relative precision). The shape gradient of vertex b ≥ 1 is gᵦ = row
//! b−1 of Bm and g₀ = −(g₁+g₂+g₃), so ∂V/∂u_b = W P g_b and
//! ∂²V/∂u_{a,i}∂u_{b,k} = W Σ_{j,l} (∂P/∂F)_{ij,kl} g_a[j] g_b[l].

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
        let mut out = [0.0; 144];
        self.local_hessian_columns(e, a, scale, [true; 4], &mut out);
        out
    }

    /// The column blocks `blocks[b]` (columns 3b..3b+3, vertex b) of [`Self::local_hessian`],
    /// written into `out`; other entries of `out` are left as they are. Each block is computed
    /// on its own, with the same operations whichever other blocks are requested, so a subset is
    /// bit-identical to the full matrix and costs about a quarter of it per block.
    ///
    /// Column block b is H_ab = W Σ_j g_a[j] Σ_l g_b[l] A_jl for rows of vertices a = 1..3, with
    /// A_jl the 3×3 block of A at rows 3j.., columns 3l.., and minus their sum for a = 0.
    #[inline]
    pub fn local_hessian_columns(
        &self,
        e: usize,
        a: &Mat9,
        scale: f64,
        blocks: [bool; 4],
        out: &mut LocalMatrix,
    ) {
        let bm = &self.bm[e];
        let w = self.volume[e] * scale;
        let mut g = [[0.0f64; 3]; 4];
        for b in 1..4 {
            for l in 0..3 {
                g[b][l] = bm[(b - 1, l)];
            }
        }
        for l in 0..3 {
            g[0][l] = -(g[1][l] + g[2][l] + g[3][l]);
        }
        let a = a.as_slice();
        for b in 0..4 {
            if !blocks[b] {
                continue;
            }
            let gb = g[b];
            // y[j] = Σ_l g_b[l] A_jl, each 3×3 block column by column: y[j][3k + i] =
            // Σ_l A[(i + 3j, k + 3l)] g_b[l]. Nine contiguous numbers, so the next stage is a
            // 9-wide axpy.
            let mut y = [[0.0f64; 9]; 3];
            for j in 0..3 {
                for k in 0..3 {
                    for i in 0..3 {
                        let mut s = 0.0;
                        for l in 0..3 {
                            s += a[9 * (k + 3 * l) + i + 3 * j] * gb[l];
                        }
                        y[j][3 * k + i] = s;
                    }
                }
            }
            // Rows of vertices 1..3: H_ab = W Σ_j g_a[j] y[j].
            for av in 1..4 {
                let mut h = [0.0f64; 9];
                for j in 0..3 {
                    for (h, y) in h.iter_mut().zip(&y[j]) {
                        *h += g[av][j] * y;
                    }
                }
                for k in 0..3 {
                    for i in 0..3 {
                        out[(3 * av + i) * 12 + 3 * b + k] = h[3 * k + i] * w;
                    }
                }
            }
            // Rows of vertex 0 are minus the sums over vertices 1..3.
            for c in 3 * b..3 * b + 3 {
                for i in 0..3 {
                    let s = out[(3 + i) * 12 + c] + out[(6 + i) * 12 + c] + out[(9 + i) * 12 + c];
                    out[i * 12 + c] = -s;
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
                            let (x, y) = (out[12 * r + c], full[12 * r + c]);
                            assert_eq!(x.to_bits(), y.to_bits(), "{mask:b} ({r}, {c})");
                        }
                    }
                }
            }
        }
    }
}
