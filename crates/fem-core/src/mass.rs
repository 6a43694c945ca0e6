//! Mass matrices of linear tets: lumped (ρW/4 per vertex, the default) and consistent
//! (ρW(1+δ_ab)/20 for each vertex pair of a tet, identical on the three components).

use crate::element::Elements;

/// How the mass matrix is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MassKind {
    #[default]
    Lumped,
    Consistent,
}

/// A mass matrix over vertices (the same scalar block on each of the 3 components).
#[derive(Debug, Clone)]
pub struct MassMatrix {
    /// Row sums per vertex (the lumped mass; also the consistent matrix's row sums).
    pub lumped: Vec<f64>,
    /// Consistent mass as vertex-level CSR (`row_ptr`, `col`, `val`), when requested.
    pub consistent: Option<VertexCsr>,
}

/// Symmetric vertex-level sparse matrix in CSR form, columns sorted within each row.
#[derive(Debug, Clone)]
pub struct VertexCsr {
    pub row_ptr: Vec<usize>,
    pub col: Vec<usize>,
    pub val: Vec<f64>,
}

impl MassMatrix {
    pub fn new(elements: &Elements, num_vertices: usize, density: f64, kind: MassKind) -> Self {
        let mut lumped = vec![0.0; num_vertices];
        for (t, &w) in elements.tets.iter().zip(&elements.volume) {
            for &v in t {
                lumped[v] += density * w / 4.0;
            }
        }
        let consistent = (kind == MassKind::Consistent).then(|| {
            let mut entries: Vec<(usize, usize, f64)> = Vec::with_capacity(16 * elements.len());
            for (t, &w) in elements.tets.iter().zip(&elements.volume) {
                for a in 0..4 {
                    for b in 0..4 {
                        let m = density * w * if a == b { 2.0 } else { 1.0 } / 20.0;
                        entries.push((t[a], t[b], m));
                    }
                }
            }
            entries.sort_unstable_by_key(|e| (e.0, e.1));
            let mut row_ptr = vec![0usize; num_vertices + 1];
            let mut col = Vec::new();
            let mut val: Vec<f64> = Vec::new();
            let mut last = None;
            for (r, c, m) in entries {
                if last == Some((r, c)) {
                    *val.last_mut().expect("an entry was pushed for this key") += m;
                } else {
                    col.push(c);
                    val.push(m);
                    row_ptr[r + 1] += 1;
                    last = Some((r, c));
                }
            }
            for r in 0..num_vertices {
                row_ptr[r + 1] += row_ptr[r];
            }
            VertexCsr { row_ptr, col, val }
        });
        Self { lumped, consistent }
    }

    pub fn kind(&self) -> MassKind {
        if self.consistent.is_some() {
            MassKind::Consistent
        } else {
            MassKind::Lumped
        }
    }

    pub fn total(&self) -> f64 {
        self.lumped.iter().sum()
    }

    /// out = M x for full vectors (3 per vertex).
    pub fn apply(&self, x: &[f64], out: &mut [f64]) {
        match &self.consistent {
            None => {
                for (v, &m) in self.lumped.iter().enumerate() {
                    for c in 0..3 {
                        out[3 * v + c] = m * x[3 * v + c];
                    }
                }
            }
            Some(csr) => {
                for v in 0..self.lumped.len() {
                    let mut s = [0.0; 3];
                    for k in csr.row_ptr[v]..csr.row_ptr[v + 1] {
                        let w = csr.col[k];
                        for c in 0..3 {
                            s[c] += csr.val[k] * x[3 * w + c];
                        }
                    }
                    out[3 * v..3 * v + 3].copy_from_slice(&s);
                }
            }
        }
    }

    /// ½ xᵀ M x.
    pub fn half_norm_squared(&self, x: &[f64], scratch: &mut [f64]) -> f64 {
        self.apply(x, scratch);
        0.5 * x
            .iter()
            .zip(scratch.iter())
            .map(|(a, b)| a * b)
            .sum::<f64>()
    }

    /// The error metric of every report (DESIGN §9): ‖u − r‖_M / ‖r‖_M for full displacement
    /// vectors u and reference r, or `None` where the reference is at rest (‖r‖_M = 0).
    pub fn relative_error(&self, u: &[f64], r: &[f64]) -> Option<f64> {
        let (num, den) = self.error_and_size(u, r);
        (den > 0.0).then(|| (num / den).sqrt())
    }

    /// ½‖u − r‖²_M and ½‖r‖²_M, the two terms of [`MassMatrix::relative_error`] (summed over
    /// frames they give a trajectory's space–time error).
    pub fn error_and_size(&self, u: &[f64], r: &[f64]) -> (f64, f64) {
        let diff: Vec<f64> = u.iter().zip(r).map(|(a, b)| a - b).collect();
        let mut scratch = vec![0.0; u.len()];
        (
            self.half_norm_squared(&diff, &mut scratch),
            self.half_norm_squared(r, &mut scratch),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::generate::{BoxSpec, box_mesh};

    #[test]
    fn the_relative_error_is_the_mass_weighted_ratio_and_none_at_rest() {
        let m = box_mesh(&BoxSpec {
            size: [1.0, 0.5, 0.2],
            cells: [2, 1, 1],
            ..Default::default()
        })
        .unwrap();
        let elements = crate::element::Elements::new(&m);
        let mass = MassMatrix::new(&elements, m.num_vertices(), 1000.0, MassKind::Lumped);
        let n = 3 * m.num_vertices();
        let r: Vec<f64> = (0..n).map(|i| (i % 7) as f64 * 0.01).collect();
        // Vertex 0 moved by 0.1 along x only: ‖u − r‖²_M = m₀ · 0.01.
        let mut u = r.clone();
        u[0] += 0.1;
        let den: f64 = (0..n).map(|i| mass.lumped[i / 3] * r[i] * r[i]).sum();
        let expected = (mass.lumped[0] * 0.01 / den).sqrt();
        let got = mass.relative_error(&u, &r).unwrap();
        assert!(
            (got - expected).abs() <= 1e-14 * expected,
            "{got} vs {expected}"
        );
        assert_eq!(mass.relative_error(&u, &vec![0.0; n]), None);
    }

    #[test]
    fn consistent_and_lumped_agree_on_rigid_motion() {
        let m = box_mesh(&BoxSpec {
            size: [1.0, 0.5, 0.2],
            cells: [3, 2, 2],
            ..Default::default()
        })
        .unwrap();
        let e = Elements::new(&m);
        let lumped = MassMatrix::new(&e, m.num_vertices(), 1000.0, MassKind::Lumped);
        let cons = MassMatrix::new(&e, m.num_vertices(), 1000.0, MassKind::Consistent);
        assert!((lumped.total() - 100.0).abs() < 1e-9);
        let n = 3 * m.num_vertices();
        let x: Vec<f64> = (0..n).map(|i| [1.0, -2.0, 0.5][i % 3]).collect();
        let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
        lumped.apply(&x, &mut a);
        cons.apply(&x, &mut b);
        for i in 0..n {
            assert!((a[i] - b[i]).abs() < 1e-10);
        }
        // Kinetic energy of a uniform velocity is ½ m |v|² for both.
        let ke = cons.half_norm_squared(&x, &mut b);
        assert!((ke - 0.5 * 100.0 * 5.25).abs() < 1e-8, "{ke}");
    }
}
