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
        let bm = &self.bm[e];
        let w = self.volume[e] * scale;
        // ag[(r, 3(b−1)+k)] = Σ_l A[r, k+3l] g_b[l], for vertices b = 1..3.
        let mut ag = [[0.0f64; 9]; 9];
        for b in 0..3 {
            for k in 0..3 {
                let col = 3 * b + k;
                for r in 0..9 {
                    let mut s = 0.0;
                    for l in 0..3 {
                        s += a[(r, k + 3 * l)] * bm[(b, l)];
                    }
                    ag[r][col] = s;
                }
            }
        }
        // h9[(3(a−1)+i, col)] = Σ_j g_a[j] ag[(i+3j, col)].
        let mut h9 = [[0.0f64; 9]; 9];
        for av in 0..3 {
            for i in 0..3 {
                let row = 3 * av + i;
                for col in 0..9 {
                    let mut s = 0.0;
                    for j in 0..3 {
                        s += bm[(av, j)] * ag[i + 3 * j][col];
                    }
                    h9[row][col] = s * w;
                }
            }
        }
        // Expand to 12×12: vertex 0 rows/columns are minus the sums over vertices 1..3.
        let mut out = [0.0; 144];
        for r in 0..9 {
            for c in 0..9 {
                out[(r + 3) * 12 + c + 3] = h9[r][c];
            }
        }
        for r in 3..12 {
            for k in 0..3 {
                let s = out[r * 12 + 3 + k] + out[r * 12 + 6 + k] + out[r * 12 + 9 + k];
                out[r * 12 + k] = -s;
            }
        }
        for c in 0..12 {
            for i in 0..3 {
                let s = out[(3 + i) * 12 + c] + out[(6 + i) * 12 + c] + out[(9 + i) * 12 + c];
                out[i * 12 + c] = -s;
            }
        }
        out
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
