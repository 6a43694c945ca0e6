//! The fenris peer (feature `peers`): the same mesh, displacement and Lamé parameters handed to
//! fenris 0.0.33 with fenris-solid's Neo-Hookean material, through fenris's own assemblers.
//!
//! fenris-solid's `NeoHookeanMaterial` is ψ = μ/2 (I_C − 3) − μ ln J + λ/2 (ln J)², the same
//! energy as fem-core's classic [`fem_core::material::NeoHookean`] (not the stable Neo-Hookean
//! default), so those two do equal work; the test below checks that their energy, gradient and
//! unprojected Hessian agree. fenris has no free-DOF elimination, so the comparison uses an
//! unpinned mesh on both sides, which makes the two sparsity patterns identical.

use std::sync::Mutex;

use fem_core::TetMesh;
use fem_core::material::Lame;
use fenris::assembly::global::{
    CsrAssembler, CsrParAssembler, VectorAssembler, VectorParAssembler, assemble_scalar,
    color_nodes, par_assemble_scalar,
};
use fenris::assembly::local::UniformQuadratureTable;
use fenris::assembly::local::{ElementEllipticAssembler, ElementEllipticAssemblerBuilder};
use fenris::connectivity::Tet4Connectivity;
use fenris::mesh::Tet4Mesh;
use fenris::nalgebra::{DVector, DVectorView, Point3, U3};
use fenris::nalgebra_sparse::CsrMatrix;
use fenris::quadrature::CanonicalStiffnessQuadrature;
use fenris_paradis::DisjointSubsets;
use fenris_solid::MaterialEllipticOperator;
use fenris_solid::materials::{LameParameters, NeoHookeanMaterial};

/// fenris's quadrature table for linear tets (one point) with uniform Lamé parameters.
type QTable = UniformQuadratureTable<f64, U3, LameParameters<f64>>;
/// fenris's element assembler for the Neo-Hookean operator at a displacement.
type Assembler<'a> = ElementEllipticAssembler<
    'a,
    f64,
    Tet4Mesh<f64>,
    MaterialEllipticOperator<'a, NeoHookeanMaterial>,
    QTable,
>;

/// A mesh set up for fenris: its Tet4 mesh, the Neo-Hookean operator with one-point quadrature,
/// the element colouring of its parallel assemblers, and their reusable workspaces.
#[allow(missing_debug_implementations)]
pub struct FenrisNeoHookean {
    mesh: Tet4Mesh<f64>,
    qtable: QTable,
    colors: Vec<DisjointSubsets>,
    // fenris's serial assemblers keep their workspace in a `RefCell`; the mutex (locked once per
    // assembly) makes this type `Sync` so that it can be used inside a rayon pool.
    csr: Mutex<CsrAssembler<f64>>,
    par_csr: CsrParAssembler<f64>,
    vector: Mutex<VectorAssembler<f64>>,
    par_vector: VectorParAssembler<f64>,
    operator: MaterialEllipticOperator<'static, NeoHookeanMaterial>,
}

impl FenrisNeoHookean {
    /// Copies `mesh` into fenris and uses the Lamé parameters `lame` unchanged (no second
    /// E, ν conversion, so both codes see bit-identical μ and λ).
    pub fn new(mesh: &TetMesh, lame: Lame) -> Self {
        let vertices = mesh
            .vertices
            .iter()
            .map(|v| Point3::new(v.x, v.y, v.z))
            .collect();
        let cells = mesh.tets.iter().map(|&t| Tet4Connectivity(t)).collect();
        let mesh = Tet4Mesh::from_vertices_and_connectivity(vertices, cells);
        let qtable = mesh
            .canonical_stiffness_quadrature()
            .with_uniform_data(LameParameters {
                mu: lame.mu,
                lambda: lame.lambda,
            });
        let colors = color_nodes(&mesh);
        Self {
            mesh,
            qtable,
            colors,
            csr: Mutex::default(),
            par_csr: CsrParAssembler::default(),
            vector: Mutex::default(),
            par_vector: VectorParAssembler::default(),
            operator: MaterialEllipticOperator::new(&NeoHookeanMaterial),
        }
    }

    fn assembler<'a>(&'a self, u: &'a [f64]) -> Assembler<'a> {
        ElementEllipticAssemblerBuilder::new()
            .with_u(DVectorView::from_slice(u, u.len()))
            .with_finite_element_space(&self.mesh)
            .with_operator(&self.operator)
            .with_quadrature_table(&self.qtable)
            .build()
    }

    /// Number of colours of fenris's greedy element colouring (parallel assemblers only).
    pub fn num_colors(&self) -> usize {
        self.colors.len()
    }

    /// Energy and gradient (overwrites `grad`), with fenris's serial assemblers: one pass for
    /// the energy and one for the gradient, as fenris has no fused energy-and-gradient pass.
    pub fn energy_gradient(&self, u: &[f64], grad: &mut DVector<f64>) -> f64 {
        let a = self.assembler(u);
        let e = assemble_scalar(&a).expect("fenris energy");
        grad.fill(0.0);
        self.vector
            .lock()
            .expect("not poisoned")
            .assemble_vector_into(&mut *grad, &a)
            .expect("fenris gradient");
        e
    }

    /// [`Self::energy_gradient`] with fenris's parallel assemblers (rayon; the gradient is
    /// scattered colour by colour).
    pub fn par_energy_gradient(&self, u: &[f64], grad: &mut DVector<f64>) -> f64 {
        let a = self.assembler(u);
        let e = par_assemble_scalar(&a).expect("fenris energy");
        grad.fill(0.0);
        self.par_vector
            .assemble_vector_into(&mut *grad, &self.colors, &a)
            .expect("fenris gradient");
        e
    }

    /// fenris's CSR matrix with the pattern of the full (unpinned) Hessian, all values zero.
    pub fn hessian_matrix(&self, u: &[f64]) -> CsrMatrix<f64> {
        let pattern = self
            .csr
            .lock()
            .expect("not poisoned")
            .assemble_pattern(&self.assembler(u));
        let nnz = pattern.nnz();
        CsrMatrix::try_from_pattern_and_values(pattern, vec![0.0; nnz])
            .expect("fenris's pattern is valid")
    }

    /// The (unprojected) Hessian into the existing pattern of `h`, serial.
    pub fn hessian(&self, u: &[f64], h: &mut CsrMatrix<f64>) {
        h.values_mut().fill(0.0);
        self.csr
            .lock()
            .expect("not poisoned")
            .assemble_into_csr(h, &self.assembler(u))
            .expect("fenris Hessian");
    }

    /// [`Self::hessian`] with fenris's coloured parallel assembler.
    pub fn par_hessian(&self, u: &[f64], h: &mut CsrMatrix<f64>) {
        h.values_mut().fill(0.0);
        self.par_csr
            .assemble_into_csr(h, &self.colors, &self.assembler(u))
            .expect("fenris Hessian");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::smooth_displacement;
    use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
    use fem_core::constraints::DofMap;
    use fem_core::element::Elements;
    use fem_core::material::NeoHookean;
    use fem_core::mesh::generate::{BoxSpec, box_mesh};
    use fem_core::sparse::HessianPattern;

    fn max_abs(v: impl Iterator<Item = f64>) -> f64 {
        v.fold(0.0, |m, x| m.max(x.abs()))
    }

    /// fem-core's classic Neo-Hookean and fenris's compute the same energy, gradient and
    /// Hessian on the benchmark state, serial and parallel: the peer benchmark compares equal
    /// work.
    #[test]
    fn fenris_neo_hookean_matches_ours() {
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.2, 0.3],
            cells: [12, 3, 4],
            ..Default::default()
        })
        .unwrap();
        let lame = Lame::from_young_poisson(1.0e5, 0.45);
        let u = smooth_displacement(&mesh);
        let elements = Elements::new(&mesh);
        let ours = NeoHookean::new(lame);
        let peer = FenrisNeoHookean::new(&mesh, lame);
        assert!(peer.num_colors() > 1);

        let mut buf = AssemblyBuffers::default();
        let mut g = vec![0.0; u.len()];
        let e = assembly::energy_gradient(&ours, &elements, ElementSet::All, &u, &mut g, &mut buf);
        let mut gf = DVector::zeros(u.len());
        for parallel in [false, true] {
            let ef = if parallel {
                peer.par_energy_gradient(&u, &mut gf)
            } else {
                peer.energy_gradient(&u, &mut gf)
            };
            assert!(e > 0.0);
            assert!((e - ef).abs() <= 1e-12 * e, "energy {e} vs fenris {ef}");
            let scale = max_abs(g.iter().copied());
            let diff = max_abs(g.iter().zip(gf.iter()).map(|(a, b)| a - b));
            assert!(
                diff <= 1e-12 * scale,
                "gradient differs by {diff:e} of {scale:e}"
            );
        }

        let dofs = DofMap::new(&mesh, &[]);
        let pattern = HessianPattern::new(&elements.tets, &dofs);
        let mut values = vec![0.0; pattern.nnz()];
        assembly::hessian(
            &ours,
            &elements,
            ElementSet::All,
            &u,
            false,
            &pattern,
            &mut values,
            &mut buf,
        );
        let mut h = peer.hessian_matrix(&u);
        // Symmetric pattern: our CSC arrays and fenris's CSR arrays describe the same entries.
        assert_eq!(pattern.symbolic.col_ptr(), h.row_offsets());
        assert_eq!(pattern.symbolic.row_idx(), h.col_indices());
        for parallel in [false, true] {
            if parallel {
                peer.par_hessian(&u, &mut h);
            } else {
                peer.hessian(&u, &mut h);
            }
            let scale = max_abs(values.iter().copied());
            let diff = max_abs(values.iter().zip(h.values()).map(|(a, b)| a - b));
            assert!(
                diff <= 1e-12 * scale,
                "Hessian differs by {diff:e} of {scale:e}"
            );
        }
    }
}
