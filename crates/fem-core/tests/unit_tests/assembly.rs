//! Whole-mesh energy, gradient and Hessian against finite differences, the weighted element
//! set, and the patch test.

use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
use fem_core::constraints::DofMap;
use fem_core::element::Elements;
use fem_core::material::{Material, MaterialConfig, MaterialModel};
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::sparse::HessianPattern;
use fem_core::{TetMesh, with_material};

/// SplitMix64: a tiny deterministic generator for test data.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// The symmetric sparse matrix with `values` on `pattern`, as a dense matrix.
fn dense_matrix(pattern: &HessianPattern, values: &[f64]) -> faer::Mat<f64> {
    let n = pattern.dim();
    let mut out = faer::Mat::<f64>::zeros(n, n);
    let (mut e, mut c) = (vec![0.0; n], vec![0.0; n]);
    for j in 0..n {
        e.fill(0.0);
        e[j] = 1.0;
        pattern.mul_vec(values, &e, &mut c);
        for i in 0..n {
            out[(i, j)] = c[i];
        }
    }
    out
}

fn small_box() -> TetMesh {
    box_mesh(&BoxSpec {
        size: [1.0, 0.4, 0.3],
        cells: [3, 2, 2],
        ..Default::default()
    })
    .unwrap()
}

fn config(model: MaterialModel) -> MaterialConfig {
    MaterialConfig {
        model,
        youngs_modulus: 1.0e4,
        poisson_ratio: 0.35,
        ..Default::default()
    }
}

#[test]
fn gradient_and_hessian_match_finite_differences_for_every_material() {
    let mesh = small_box();
    let elements = Elements::new(&mesh);
    let n = 3 * mesh.num_vertices();
    let mut rng = Rng(7);
    let u: Vec<f64> = (0..n).map(|_| 0.05 * rng.next()).collect();
    let dofs = DofMap::new(&mesh, &[]);
    let pattern = HessianPattern::new(&elements.tets, &dofs);
    for model in MaterialModel::ALL {
        let mat = config(model).build();
        let mut buf = AssemblyBuffers::default();
        let mut grad = vec![0.0; n];
        let e0 = with_material!(&mat, |m| assembly::energy_gradient(
            m,
            &elements,
            ElementSet::All,
            &u,
            &mut grad,
            &mut buf
        ));
        let e_only = with_material!(&mat, |m| assembly::energy(
            m,
            &elements,
            ElementSet::All,
            &u,
            &mut buf
        ));
        assert!((e0 - e_only).abs() <= 1e-12 * e0.abs(), "{model:?}");
        let energy_at = |x: &[f64], buf: &mut AssemblyBuffers| {
            with_material!(&mat, |m| assembly::energy(
                m,
                &elements,
                ElementSet::All,
                x,
                buf
            ))
        };
        let h = 1e-6;
        let gnorm = grad.iter().map(|g| g * g).sum::<f64>().sqrt();
        let mut worst: f64 = 0.0;
        for i in (0..n).step_by(5) {
            let (mut up, mut um) = (u.clone(), u.clone());
            up[i] += h;
            um[i] -= h;
            let fd = (energy_at(&up, &mut buf) - energy_at(&um, &mut buf)) / (2.0 * h);
            worst = worst.max((fd - grad[i]).abs() / gnorm);
        }
        assert!(worst < 1e-7, "{model:?}: gradient FD error {worst:.2e}");

        // Hessian (unprojected) columns against finite differences of the gradient.
        let mut values = vec![0.0; pattern.nnz()];
        with_material!(&mat, |m| assembly::hessian(
            m,
            &elements,
            ElementSet::All,
            &u,
            false,
            &pattern,
            &mut values,
            &mut buf
        ));
        let mut col = vec![0.0; n];
        let mut e = vec![0.0; n];
        let (mut gp, mut gm) = (vec![0.0; n], vec![0.0; n]);
        let mut worst: f64 = 0.0;
        let mut scale: f64 = 0.0;
        for j in (0..n).step_by(7) {
            e.fill(0.0);
            e[j] = 1.0;
            pattern.mul_vec(&values, &e, &mut col);
            let (mut up, mut um) = (u.clone(), u.clone());
            up[j] += h;
            um[j] -= h;
            with_material!(&mat, |m| {
                assembly::energy_gradient(m, &elements, ElementSet::All, &up, &mut gp, &mut buf);
                assembly::energy_gradient(m, &elements, ElementSet::All, &um, &mut gm, &mut buf);
            });
            for i in 0..n {
                let fd = (gp[i] - gm[i]) / (2.0 * h);
                worst = worst.max((fd - col[i]).abs());
                scale = scale.max(col[i].abs());
            }
        }
        assert!(
            worst < 1e-6 * scale,
            "{model:?}: Hessian FD error {:.2e}",
            worst / scale
        );
    }
}

#[test]
fn projected_hessian_is_positive_semidefinite() {
    let mesh = small_box();
    let elements = Elements::new(&mesh);
    let n = 3 * mesh.num_vertices();
    let mut rng = Rng(11);
    // Large random displacements: many elements are strongly deformed or inverted.
    let u: Vec<f64> = (0..n).map(|_| 0.3 * rng.next()).collect();
    let dofs = DofMap::new(&mesh, &[]);
    let pattern = HessianPattern::new(&elements.tets, &dofs);
    for model in [
        MaterialModel::Corotated,
        MaterialModel::Stvk,
        MaterialModel::StableNeoHookean,
    ] {
        let mat = config(model).build();
        let mut buf = AssemblyBuffers::default();
        let mut values = vec![0.0; pattern.nnz()];
        with_material!(&mat, |m| assembly::hessian(
            m,
            &elements,
            ElementSet::All,
            &u,
            true,
            &pattern,
            &mut values,
            &mut buf
        ));
        let dense = dense_matrix(&pattern, &values);
        let eig = dense.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
        let max = eig.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let min = eig.iter().fold(f64::INFINITY, |m, &v| m.min(v));
        assert!(
            min >= -1e-9 * max,
            "{model:?}: min eigenvalue {min:.3e} of {max:.3e}"
        );
        if model != MaterialModel::StableNeoHookean {
            continue;
        }
        // And the projection is not idle: the unprojected Hessian here is indefinite.
        with_material!(&mat, |m| assembly::hessian(
            m,
            &elements,
            ElementSet::All,
            &u,
            false,
            &pattern,
            &mut values,
            &mut buf
        ));
        let raw = dense_matrix(&pattern, &values);
        let raw_min = raw
            .self_adjoint_eigenvalues(faer::Side::Lower)
            .unwrap()
            .iter()
            .fold(f64::INFINITY, |m, &v| m.min(v));
        assert!(
            raw_min < -1e-6 * max,
            "{model:?}: expected an indefinite raw Hessian"
        );
    }
}

#[test]
fn weighted_element_sets_sum_their_members() {
    let mesh = small_box();
    let elements = Elements::new(&mesh);
    let n = 3 * mesh.num_vertices();
    let mut rng = Rng(3);
    let u: Vec<f64> = (0..n).map(|_| 0.05 * rng.next()).collect();
    let mat = config(MaterialModel::StableNeoHookean).build();
    let mut buf = AssemblyBuffers::default();
    let all: Vec<usize> = (0..elements.len()).collect();
    let ones = vec![1.0; all.len()];
    let (mut g_full, mut g_set) = (vec![0.0; n], vec![0.0; n]);
    with_material!(&mat, |m| {
        let e_full =
            assembly::energy_gradient(m, &elements, ElementSet::All, &u, &mut g_full, &mut buf);
        let set = ElementSet::Weighted {
            indices: &all,
            weights: &ones,
        };
        let e_set = assembly::energy_gradient(m, &elements, set, &u, &mut g_set, &mut buf);
        // Same elements, same order, weight 1: bit-identical.
        assert_eq!(e_full, e_set);
        assert_eq!(g_full, g_set);
        // A subset with weights equals the explicit weighted sum of per-element energies.
        let idx = [3usize, 17, 40, 41];
        let w = [0.5, 2.0, 1.5, 0.25];
        let set = ElementSet::Weighted {
            indices: &idx,
            weights: &w,
        };
        let e_sub = assembly::energy(m, &elements, set, &u, &mut buf);
        let expect: f64 = idx
            .iter()
            .zip(&w)
            .map(|(&e, &wt)| wt * elements.volume[e] * m.psi(&elements.deformation_gradient(e, &u)))
            .sum();
        assert!((e_sub - expect).abs() <= 1e-13 * expect.abs());
    });
}

#[test]
fn patch_test_affine_displacement_gives_constant_f_and_no_interior_force() {
    let mesh = box_mesh(&BoxSpec {
        size: [1.0, 1.0, 1.0],
        cells: [3, 3, 3],
        ..Default::default()
    })
    .unwrap();
    let elements = Elements::new(&mesh);
    let a = nalgebra::Matrix3::new(0.01, 0.02, -0.01, 0.005, -0.02, 0.01, 0.0, 0.015, 0.03);
    let u: Vec<f64> = mesh
        .vertices
        .iter()
        .flat_map(|x| {
            let d = a * x;
            [d.x, d.y, d.z]
        })
        .collect();
    let expect = nalgebra::Matrix3::identity() + a;
    for e in 0..elements.len() {
        let f = elements.deformation_gradient(e, &u);
        assert!((f - expect).norm() < 1e-14, "element {e}");
    }
    // Uniform stress is in equilibrium: interior vertices feel no net force.
    let surface = mesh.surface_vertices();
    for model in MaterialModel::ALL {
        let mat = config(model).build();
        let mut grad = vec![0.0; u.len()];
        let mut buf = AssemblyBuffers::default();
        with_material!(&mat, |m| assembly::energy_gradient(
            m,
            &elements,
            ElementSet::All,
            &u,
            &mut grad,
            &mut buf
        ));
        let scale = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        assert!(scale > 0.0);
        for v in 0..mesh.num_vertices() {
            if surface.binary_search(&v).is_err() {
                for c in 0..3 {
                    assert!(
                        grad[3 * v + c].abs() < 1e-12 * scale,
                        "{model:?} vertex {v}"
                    );
                }
            }
        }
    }
}
