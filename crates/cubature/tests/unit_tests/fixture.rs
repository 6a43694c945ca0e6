//! Test fixture shared by the tests and the `cubature_fit_timing` example: a cantilever beam, a smooth
//! mass-orthonormal modal basis on it and random poses shaped like static load responses.

use faer::{Mat, MatRef};
use fem_core::constraints::{Axis, Side, VertexSelection};
use fem_core::integrator::FullSpaceModel;
use fem_core::material::MaterialConfig;
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::rng::SplitMix64;

/// A cantilever beam [0, 1] × [0, 0.2]² of `cells` hexahedra (6 tets each), pinned at x = 0,
/// stable Neo-Hookean with the default E = 10⁵ Pa, ν = 0.45.
pub fn beam(cells: [usize; 3]) -> FullSpaceModel {
    let mesh = box_mesh(&BoxSpec {
        size: [1.0, 0.2, 0.2],
        cells,
        ..Default::default()
    })
    .unwrap();
    let pinned = VertexSelection::plane(Axis::X, Side::Min, None)
        .select(&mesh, "pin[0]")
        .unwrap();
    FullSpaceModel::new(
        mesh,
        &MaterialConfig::default(),
        pinned,
        [0.0, 0.0, 0.0].into(),
        vec![],
    )
    .unwrap()
}

/// Ten smooth, soft displacement fields of a beam along x (bending of several orders and
/// wavelengths in y and z, torsion), mass-orthonormalised (UᵀMU = I with the lumped mass) on the
/// free DOFs: n_free × 10, column-major. Stiff fields (stretch, squash) are left out, as PCA of
/// simulated snapshots leaves them out: with them, the per-pose normalised forces are dominated
/// by their second-order response and a handful of elements fits everything.
pub fn smooth_basis(model: &FullSpaceModel) -> (Vec<f64>, usize) {
    use std::f64::consts::PI;
    type Field = fn(f64, f64, f64) -> [f64; 3];
    let fields: [Field; 10] = [
        |s, _, _| [0.0, s * s, 0.0],
        |s, _, _| [0.0, 0.0, s * s],
        |s, _, _| [0.0, s * s * s, 0.0],
        |s, _, _| [0.0, 0.0, s * s * s],
        |s, _, _| [0.0, (2.0 * PI * s).sin() * s, 0.0],
        |s, _, _| [0.0, 0.0, (2.0 * PI * s).sin() * s],
        |s, _, _| [0.0, (3.0 * PI * s).sin() * s, 0.0],
        |s, _, _| [0.0, 0.0, (3.0 * PI * s).sin() * s],
        |s, y, z| [0.0, -s * z, s * y],
        |s, y, z| [0.0, -s * s * z, s * s * y],
    ];
    let k = fields.len();
    let nf = model.dofs.num_free();
    let mass: Vec<f64> = model
        .dofs
        .free
        .iter()
        .map(|&d| model.mass.lumped[d / 3])
        .collect();
    let mut basis = vec![0.0; nf * k];
    for (j, field) in fields.iter().enumerate() {
        for (r, &d) in model.dofs.free.iter().enumerate() {
            let x = model.mesh.vertices[d / 3];
            let v = field(x[0], x[1] - 0.1, x[2] - 0.1);
            basis[j * nf + r] = v[d % 3];
        }
    }
    // Modified Gram–Schmidt in the mass inner product, twice for accuracy.
    for _ in 0..2 {
        for j in 0..k {
            for i in 0..j {
                let (lo, hi) = basis.split_at_mut(j * nf);
                let ui = &lo[i * nf..(i + 1) * nf];
                let uj = &mut hi[..nf];
                let p: f64 = (0..nf).map(|r| ui[r] * mass[r] * uj[r]).sum();
                for r in 0..nf {
                    uj[r] -= p * ui[r];
                }
            }
            let uj = &mut basis[j * nf..(j + 1) * nf];
            let n = (0..nf).map(|r| uj[r] * uj[r] * mass[r]).sum::<f64>().sqrt();
            uj.iter_mut().for_each(|x| *x /= n);
        }
    }
    (basis, k)
}

/// Reduced rest stiffness UᵀK₀U by central differences of Uᵀ∇V (exact up to rounding: the
/// gradient is smooth and ε is tiny), symmetrised.
fn reduced_rest_stiffness(model: &FullSpaceModel, basis: &[f64], k: usize) -> Mat<f64> {
    use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
    let nf = model.dofs.num_free();
    let eps = 1e-6;
    let mut buf = AssemblyBuffers::default();
    let (mut u, mut grad, mut g_free) = (
        vec![0.0; model.num_full()],
        vec![0.0; model.num_full()],
        vec![0.0; nf],
    );
    let mut projected = |col: &[f64]| -> Vec<f64> {
        model.dofs.scatter(col, &mut u);
        fem_core::with_material!(&model.material, |m| assembly::energy_gradient(
            m,
            &model.elements,
            ElementSet::All,
            &u,
            &mut grad,
            &mut buf
        ));
        model.dofs.gather(&grad, &mut g_free);
        (0..k)
            .map(|i| (0..nf).map(|r| basis[i * nf + r] * g_free[r]).sum())
            .collect()
    };
    let mut kr = Mat::zeros(k, k);
    for j in 0..k {
        let plus: Vec<f64> = basis[j * nf..(j + 1) * nf]
            .iter()
            .map(|x| eps * x)
            .collect();
        let minus: Vec<f64> = plus.iter().map(|x| -x).collect();
        let (gp, gm) = (projected(&plus), projected(&minus));
        for i in 0..k {
            kr[(i, j)] = (gp[i] - gm[i]) / (2.0 * eps);
        }
    }
    Mat::from_fn(k, k, |i, j| 0.5 * (kr[(i, j)] + kr[(j, i)]))
}

/// The smooth basis rotated to its modes: U ← U V with VᵀUᵀK₀UV = Λ, so UᵀMU = I still and the
/// rest stiffness is diagonal. Returns (basis, k, λ).
pub fn modal_basis(model: &FullSpaceModel) -> (Vec<f64>, usize, Vec<f64>) {
    let (basis, k) = smooth_basis(model);
    let nf = model.dofs.num_free();
    let kr = reduced_rest_stiffness(model, &basis, k);
    let evd = kr.self_adjoint_eigen(faer::Side::Lower).unwrap();
    let v = evd.U();
    let lambda: Vec<f64> = (0..k).map(|j| evd.S()[j]).collect();
    let u = MatRef::from_column_major_slice(&basis, nf, k) * v;
    let rotated = (0..k)
        .flat_map(|j| u.col(j).iter().copied().collect::<Vec<_>>())
        .collect();
    (rotated, k, lambda)
}

/// `count` random poses (k × count) of a modal basis with stiffnesses `lambda`, shaped like static
/// responses to random loads, q_j = n_j / λ_j with n standard normal (so soft modes dominate the
/// displacement and every mode contributes comparably to the force, as in simulated snapshots),
/// each scaled so that its largest vertex displacement is between 5 % and 25 % of the
/// beam's length.
pub fn random_poses(
    model: &FullSpaceModel,
    basis: &[f64],
    lambda: &[f64],
    count: usize,
    seed: u64,
) -> Mat<f64> {
    let nf = model.dofs.num_free();
    let k = lambda.len();
    let mut rng = SplitMix64::new(seed);
    let mut q = Mat::zeros(k, count);
    for i in 0..count {
        let dir: Vec<f64> = (0..k).map(|j| rng.normal() / lambda[j]).collect();
        let mut u = vec![0.0; nf];
        for (j, &dj) in dir.iter().enumerate() {
            for r in 0..nf {
                u[r] += basis[j * nf + r] * dj;
            }
        }
        let max_disp = u
            .chunks(3)
            .map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
            .fold(0.0, f64::max);
        let amplitude = rng.range(0.05, 0.25);
        for j in 0..k {
            q[(j, i)] = dir[j] * amplitude / max_disp;
        }
    }
    q
}
