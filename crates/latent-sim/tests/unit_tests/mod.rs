//! Reduced implicit Euler: derivative checks and the full-rank limit; the model file and the
//! interactive runtime (in `unit/`).

mod load_check;
mod model_file;
mod models;
mod runtime;
mod spring_compliance;

use cubature::CubatureRule;
use fem_core::Vec3;
use fem_core::constraints::{Axis, Side, VertexSelection};
use fem_core::forces::{ExternalForce, ForceKind};
use fem_core::integrator::{FullSpaceModel, Simulator, TimeConfig};
use fem_core::material::MaterialConfig;
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::optim::{SolverConfig, SolverMethod};
use latent_sim::{
    Augmented, ElasticPath, LinearSubspace, NeuralSubspace, Preconditioning, ReducedError,
    ReducedSimulator, ReducedSpace, Subspace,
};

/// The space of U (`basis`, n_free × k column-major) and the rule of `cubature`'s elements and
/// weights, built as the pca and cubature crates hand them over (the rule unchecked, so that
/// bad rules reach the space's own checks).
fn reduced_space(
    m: &FullSpaceModel,
    basis: &[f64],
    k: usize,
    cubature: Option<(Vec<usize>, Vec<f64>)>,
) -> Result<ReducedSpace, ReducedError> {
    let n = m.dofs.num_free();
    let basis = pca::PcaBasis::new(n, k, basis.to_vec(), None, vec![1.0; k]).unwrap();
    let rule = cubature.map(|(elements, weights)| CubatureRule {
        elements,
        weights,
        training_error: 0.0,
        tolerance_met: true,
        error_curve: Vec::new(),
    });
    ReducedSpace::new(m, &basis, rule.as_ref())
}

/// A 1 m bar of 4 × 1 × 1 cells.
fn bar() -> fem_core::TetMesh {
    box_mesh(&BoxSpec {
        size: [1.0, 0.2, 0.2],
        cells: [4, 1, 1],
        ..Default::default()
    })
    .unwrap()
}

fn material() -> MaterialConfig {
    MaterialConfig {
        youngs_modulus: 1e5,
        poisson_ratio: 0.4,
        ..Default::default()
    }
}

/// `mesh` clamped at its lowest x, under gravity g along y, with `forces`.
fn clamped(mesh: fem_core::TetMesh, g: f64, forces: Vec<ExternalForce>) -> FullSpaceModel {
    let pinned = VertexSelection::plane(Axis::X, Side::Min, None)
        .select(&mesh, "pin")
        .unwrap();
    FullSpaceModel::new(mesh, &material(), pinned, Vec3::new(0.0, g, 0.0), forces).unwrap()
}

fn model() -> FullSpaceModel {
    let mesh = bar();
    let tip = (0..mesh.num_vertices())
        .filter(|&v| mesh.vertices[v].x > 0.99)
        .collect::<Vec<_>>();
    let spring = ExternalForce {
        kind: ForceKind::Spring,
        vertices: tip,
        stiffness: 2e3,
        keyframes: vec![[0.0, 0.0, 0.0, 0.0], [0.05, 0.0, 0.1, 0.05]],
        start: 0.0,
        end: 0.08,
    };
    clamped(mesh, -9.81, vec![spring])
}

/// U = M^{-1/2} (the identity, scaled): full rank and mass-orthonormal.
fn full_rank_basis(model: &FullSpaceModel) -> Vec<f64> {
    let n = model.dofs.num_free();
    let mut u = vec![0.0; n * n];
    for (j, &d) in model.dofs.free.iter().enumerate() {
        u[j * n + j] = 1.0 / model.mass.lumped[d / 3].sqrt();
    }
    u
}

/// A few smooth, mass-orthonormalised columns.
fn small_basis(model: &FullSpaceModel, k: usize) -> Vec<f64> {
    let n = model.dofs.num_free();
    let mut u = vec![0.0; n * k];
    for j in 0..k {
        for (r, &d) in model.dofs.free.iter().enumerate() {
            let x = model.mesh.vertices[d / 3];
            u[j * n + r] = ((j + 1) as f64 * x.x + 0.3 * (d % 3) as f64 + j as f64).sin() * x.x;
        }
    }
    // Gram–Schmidt in the lumped mass inner product.
    let m: Vec<f64> = model
        .dofs
        .free
        .iter()
        .map(|&d| model.mass.lumped[d / 3])
        .collect();
    for j in 0..k {
        for i in 0..j {
            let p: f64 = (0..n).map(|r| u[i * n + r] * m[r] * u[j * n + r]).sum();
            for r in 0..n {
                u[j * n + r] -= p * u[i * n + r];
            }
        }
        let nn: f64 = (0..n)
            .map(|r| u[j * n + r].powi(2) * m[r])
            .sum::<f64>()
            .sqrt();
        for r in 0..n {
            u[j * n + r] /= nn;
        }
    }
    u
}

fn time(frames: usize) -> TimeConfig {
    TimeConfig {
        step: 0.01,
        frames,
        quasi_static: false,
    }
}

fn solver(method: SolverMethod) -> SolverConfig {
    SolverConfig {
        method,
        tolerance: 1e-10,
        max_iterations: 500,
        ..Default::default()
    }
}

/// A latent point near a simulated state z but off it (by up to 0.05 per coordinate), where
/// no derivative vanishes by symmetry.
fn moved_off(z: &[f64]) -> Vec<f64> {
    z.iter()
        .enumerate()
        .map(|(i, v)| v + 0.05 * (i as f64 + 1.0).sin())
        .collect()
}

/// Checks `sim.objective`'s gradient at `z` against central differences, component by component.
fn assert_gradient_matches_fd<S: Subspace>(sim: &mut ReducedSimulator<S>, z: &[f64], what: &str) {
    let d = z.len();
    let mut g = vec![0.0; d];
    sim.objective(z, &mut g);
    let gnorm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!(gnorm > 0.0, "{what}: zero gradient");
    let mut scratch = vec![0.0; d];
    for i in 0..d {
        let h = 1e-6;
        let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
        zp[i] += h;
        zm[i] -= h;
        let fd = (sim.objective(&zp, &mut scratch) - sim.objective(&zm, &mut scratch)) / (2.0 * h);
        assert!(
            (fd - g[i]).abs() < 1e-6 * gnorm,
            "{what}: component {i}: {fd} vs {}",
            g[i]
        );
    }
}

#[test]
fn reduced_gradient_matches_finite_differences_with_and_without_cubature() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    let subsets = [
        None,
        Some((vec![0usize, 3, 7, 11, 20], vec![2.0, 0.5, 1.5, 3.0, 0.7])),
    ];
    for cubature in subsets {
        let space = reduced_space(&m, &basis, k, cubature.clone()).unwrap();
        let mut sim = ReducedSimulator::new(
            m.clone(),
            space,
            LinearSubspace::new(k),
            time(10),
            solver(SolverMethod::Lbfgs),
        )
        .unwrap();
        // Move away from rest so that inertia, springs and elasticity all contribute.
        for _ in 0..3 {
            sim.step().unwrap();
        }
        let z: Vec<f64> = sim
            .state
            .z
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.01 * (i as f64).cos())
            .collect();
        let what = format!("linear, cubature {}", cubature.is_some());
        assert_gradient_matches_fd(&mut sim, &z, &what);
    }
}

/// An unpinned body in uniform gravity translates rigidly: implicit Euler gives
/// u_n = h² g n(n+1)/2. From the second step on, the start z_n + h ż_n + h² z̈_n is that solution
/// (the subspace spans the translation), so the solver has nothing left to do.
#[test]
fn free_fall_in_the_subspace_starts_at_the_solution_after_the_first_step() {
    let g = -9.81;
    let m =
        FullSpaceModel::new(bar(), &material(), vec![], Vec3::new(0.0, g, 0.0), vec![]).unwrap();
    let n = m.dofs.num_free();
    let space = reduced_space(&m, &full_rank_basis(&m), n, None).unwrap();
    for method in [SolverMethod::Newton, SolverMethod::Lbfgs] {
        let mut red = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            LinearSubspace::new(n),
            time(6),
            solver(method),
        )
        .unwrap();
        let h = red.time.step;
        for step in 1..=6 {
            let r = red.step().unwrap();
            if step > 1 {
                assert_eq!(r.iterations, 0, "{method:?}, step {step}");
            }
            let expect = h * h * g * (step * (step + 1)) as f64 / 2.0;
            for (i, &u) in red.full_displacement().iter().enumerate() {
                let want = if i % 3 == 1 { expect } else { 0.0 };
                assert!(
                    (u - want).abs() <= 1e-9 * expect.abs(),
                    "{method:?}, step {step}, dof {i}: {u} against {want}"
                );
            }
        }
    }
}

#[test]
fn full_rank_linear_subspace_reproduces_the_full_trajectory() {
    let m = model();
    let n = m.dofs.num_free();
    let frames = 15;
    let space = reduced_space(&m, &full_rank_basis(&m), n, None).unwrap();
    for (method, preconditioning) in [
        (SolverMethod::Newton, Preconditioning::Auto),
        (SolverMethod::Lbfgs, Preconditioning::Rest),
        (SolverMethod::Lbfgs, Preconditioning::CurrentState),
    ] {
        let mut red = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            LinearSubspace::new(n),
            time(frames),
            solver(method),
        )
        .unwrap();
        red.preconditioning = preconditioning;
        let mut full =
            Simulator::new(m.clone(), time(frames), solver(SolverMethod::Newton)).unwrap();
        for f in 0..frames {
            full.step().unwrap();
            red.step().unwrap();
            let u = red.full_displacement();
            let diff: f64 = u
                .iter()
                .zip(&full.state.u)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            let size: f64 = full.state.u.iter().map(|a| a * a).sum::<f64>().sqrt();
            assert!(
                diff <= 1e-7 * size,
                "{method:?} {preconditioning:?} frame {f}: {:.2e}",
                diff / size
            );
        }
    }
}

/// Also through three gravity-onset directions beside the latent coordinates, and through two
/// onset and one complement direction.
#[test]
fn neural_reduced_gradient_matches_finite_differences_with_and_without_cubature() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    let ae =
        nn::Autoencoder::with_architecture(k, 3, &[12, 10], nn::Activation::Elu, None, 5).unwrap();
    let extra: Vec<f64> = (0..k).map(|i| (1.7 * i as f64 + 0.4).cos()).collect();
    for (onset, complement) in [(0, &[][..]), (3, &[][..]), (2, &extra[..])] {
        for cubature in [
            None,
            Some((vec![1usize, 4, 9, 15], vec![1.5, 0.5, 2.0, 1.0])),
        ] {
            let space = reduced_space(&m, &basis, k, cubature.clone()).unwrap();
            let sub = Augmented::with_directions(
                NeuralSubspace::new(ae.clone()),
                &space,
                &time(10),
                onset,
                complement,
            )
            .unwrap();
            let kept = sub.directions();
            let asked = onset + complement.len() / k;
            assert!(
                kept <= asked && (asked == 0 || kept >= 2),
                "{kept} of {asked}"
            );
            let mut sim =
                ReducedSimulator::new(m.clone(), space, sub, time(10), solver(SolverMethod::Lbfgs))
                    .unwrap();
            for _ in 0..2 {
                sim.step().unwrap();
            }
            assert_eq!(sim.subspace.latent_dim(), 3 + kept);
            let z = moved_off(&sim.state.z);
            let what = format!(
                "neural, {onset} onset and {} complement directions, cubature {}",
                complement.len() / k,
                cubature.is_some()
            );
            assert_gradient_matches_fd(&mut sim, &z, &what);
        }
    }
}

/// The three ways of evaluating the elastic energy give the same energy and gradient: the serial
/// and the parallel vertex paths the same sums in the same order (bit for bit), the element basis
/// the same sums grouped differently (to rounding).
#[test]
fn elastic_paths_agree() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    let q: Vec<f64> = (0..k).map(|i| 0.05 * (i as f64 + 0.3).sin()).collect();
    for cubature in [
        None,
        Some((vec![0usize, 3, 7, 11, 20], vec![2.0, 0.5, 1.5, 3.0, 0.7])),
    ] {
        let mut results = Vec::new();
        for path in [
            ElasticPath::Vertices,
            ElasticPath::Parallel,
            ElasticPath::ElementBasis,
        ] {
            let mut space = reduced_space(&m, &basis, k, cubature.clone()).unwrap();
            space.set_elastic_path(&m, path);
            assert_eq!(space.elastic_path(), path);
            let mut buf = space.buffers();
            let n = m.num_full();
            let (mut u, mut grad_full, mut grad_q) = (vec![0.0; n], vec![0.0; n], vec![0.0; k]);
            let e = space.elastic_energy_gradient(
                &m,
                &q,
                &mut u,
                &mut grad_full,
                &mut grad_q,
                &mut buf,
            );
            assert!(e > 0.0 && grad_q.iter().any(|&g| g != 0.0));
            results.push((e, grad_q));
        }
        let what = format!("cubature {}", cubature.is_some());
        assert_eq!(results[0], results[1], "{what}");
        let (e, g) = &results[2];
        assert!(
            (e - results[0].0).abs() <= 1e-12 * results[0].0,
            "{what}: energy"
        );
        assert_close(g, &results[0].1, 1e-11, &format!("{what}: gradient"));
    }
}

/// A cubature rule (scattered elements) takes the element basis, the whole mesh the vertex path.
#[test]
fn elastic_path_follows_the_element_set() {
    let m = model();
    let k = 4;
    let basis = small_basis(&m, k);
    let all = reduced_space(&m, &basis, k, None).unwrap();
    assert_eq!(all.elastic_path(), ElasticPath::Vertices);
    let rule = reduced_space(&m, &basis, k, Some((vec![0, 9, 20], vec![1.0; 3]))).unwrap();
    assert_eq!(rule.elastic_path(), ElasticPath::ElementBasis);
}

/// A rule that does not fit the mesh is a typed error naming what is wrong, not a panic.
#[test]
fn a_cubature_rule_that_does_not_fit_is_an_error() {
    let m = model();
    let k = 4;
    let basis = small_basis(&m, k);
    let n = m.elements.len();
    for (rule, want) in [
        (
            (vec![0, n], vec![1.0; 2]),
            format!("element {n} does not exist"),
        ),
        (
            (vec![0, 3], vec![1.0]),
            "2 elements but 1 weights".to_string(),
        ),
        ((vec![0, 3], vec![1.0, -0.5]), "weight -0.5".to_string()),
        ((vec![0, 3], vec![f64::NAN, 1.0]), "weight NaN".to_string()),
    ] {
        let err = reduced_space(&m, &basis, k, Some(rule)).unwrap_err();
        assert!(
            matches!(err, latent_sim::ReducedError::Cubature { .. })
                && err.to_string().contains(&want),
            "{err}"
        );
    }
}

/// Springs and point loads evaluated in q (through Σ U_vᵀU_v and Σ U_vᵀ) equal the full-space
/// force energy at the decoded displacement, and their gradient is its projection Uᵀ∇Φ.
#[test]
fn forces_in_q_match_the_full_space_forces() {
    let mut m = model();
    let n = m.num_full();
    let k = 5;
    let basis = small_basis(&m, k);
    let vertices: Vec<usize> = (0..m.mesh.num_vertices()).step_by(3).collect();
    for kind in [ForceKind::Spring, ForceKind::Point] {
        m.forces = vec![ExternalForce {
            kind,
            vertices: vertices.clone(),
            stiffness: 75.0,
            keyframes: vec![[0.0, 0.0, 0.0, 0.0], [1.0, 0.03, -0.02, 0.05]],
            start: 0.0,
            end: 1.0,
        }];
        let space = reduced_space(&m, &basis, k, None).unwrap();
        let mut buf = space.buffers();
        let q: Vec<f64> = (0..k).map(|i| 0.02 * (i as f64 + 0.7).cos()).collect();
        let mut u = vec![0.0; n];
        space.reconstruct(&q, &mut u);
        let mut grad_u = vec![0.0; n];
        let expected = m.forces[0].accumulate(0.6, &u, Some(&mut grad_u), None);
        let mut grad_q = vec![0.0; k];
        let (e, size) = space.force_energy_gradient(&m, 0, 0.6, &q, &mut grad_q, &mut buf);
        assert!(size >= e.abs());
        assert!(
            (e - expected).abs() <= 1e-12 * size,
            "{kind:?}: {e} against {expected}"
        );
        let free: Vec<f64> = m.dofs.free.iter().map(|&d| grad_u[d]).collect();
        let projected: Vec<f64> = (0..k)
            .map(|j| {
                (0..free.len())
                    .map(|r| basis[j * free.len() + r] * free[r])
                    .sum()
            })
            .collect();
        assert_close(&grad_q, &projected, 1e-12, &format!("{kind:?} gradient"));
        // Inactive forces contribute nothing.
        let mut zero = vec![0.0; k];
        assert_eq!(
            space.force_energy_gradient(&m, 0, 2.0, &q, &mut zero, &mut buf),
            (0.0, 0.0)
        );
        assert!(zero.iter().all(|&x| x == 0.0));
    }
}

/// Central differences of the objective's gradient, d×d column-major.
fn fd_hessian<S: Subspace>(sim: &mut ReducedSimulator<S>, z: &[f64]) -> Vec<f64> {
    let d = z.len();
    let mut h = vec![0.0; d * d];
    let (mut gp, mut gm) = (vec![0.0; d], vec![0.0; d]);
    let step = 1e-6;
    for j in 0..d {
        let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
        zp[j] += step;
        zm[j] -= step;
        sim.objective(&zp, &mut gp);
        sim.objective(&zm, &mut gm);
        for i in 0..d {
            h[j * d + i] = (gp[i] - gm[i]) / (2.0 * step);
        }
    }
    h
}

fn assert_close(a: &[f64], b: &[f64], rel: f64, what: &str) {
    let size = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    let diff = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(diff <= rel * size, "{what}: {:.2e} relative", diff / size);
}

/// A neural subspace (an untrained autoencoder k → d, seed 5) stepped by reduced Newton.
fn neural_newton(
    m: &FullSpaceModel,
    space: &ReducedSpace,
    k: usize,
    d: usize,
) -> ReducedSimulator<NeuralSubspace> {
    let ae =
        nn::Autoencoder::with_architecture(k, d, &[12, 10], nn::Activation::Elu, None, 5).unwrap();
    ReducedSimulator::new(
        m.clone(),
        space.clone(),
        NeuralSubspace::new(ae),
        time(10),
        solver(SolverMethod::Newton),
    )
    .unwrap()
}

/// The Newton matrix is formed in z (Σ_e (U_eJ)ᵀH_e(U_eJ) + Jᵀ(M/h² + springs)J), or in q then
/// sandwiched when d is close to k. For a
/// linear subspace it is the exact Hessian of the objective; for the decoder it is Jᵀ H_q J with
/// H_q the exact Hessian in q, which a linear subspace at the same state measures.
#[test]
fn newton_matrix_in_z_matches_finite_differences_and_the_q_space_hessian() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    // Eight scattered elements: the element-basis path, in z at d = 3 and in q at d = 6.
    let cubature = Some((
        vec![1usize, 4, 7, 10, 13, 16, 19, 22],
        vec![1.5, 0.5, 2.0, 1.0, 0.8, 1.2, 0.6, 1.1],
    ));
    let space = reduced_space(&m, &basis, k, cubature).unwrap();
    let mut lin = ReducedSimulator::new(
        m.clone(),
        space.clone(),
        LinearSubspace::new(k),
        time(10),
        solver(SolverMethod::Newton),
    )
    .unwrap();
    for _ in 0..3 {
        lin.step().unwrap();
    }
    // Linear: exact Hessian (the spring is active, so its term is checked too).
    let z: Vec<f64> = lin.state.z.iter().map(|v| v * 1.1 + 0.01).collect();
    let mut h = vec![0.0; k * k];
    lin.newton_matrix(&z, false, &mut h);
    assert_close(&h, &fd_hessian(&mut lin, &z), 1e-6, "linear");

    // Neural: Jᵀ H_q J, H_q by differences of the linear objective at the same state. With 3
    // latent coordinates of 6 the element terms are summed in z; with 6 in q, then sandwiched.
    for d in [3, 6] {
        let mut neural = neural_newton(&m, &space, k, d);
        for _ in 0..2 {
            neural.step().unwrap();
        }
        let z = moved_off(&neural.state.z);
        let mut hz = vec![0.0; d * d];
        neural.newton_matrix(&z, false, &mut hz);
        lin.state = latent_sim::ReducedState {
            z: neural.state.q.clone(),
            ..neural.state.clone()
        };
        let mut q = vec![0.0; k];
        neural.subspace.decode(&z, &mut q);
        let hq = fd_hessian(&mut lin, &q);
        let mut jac = vec![0.0; k * d];
        neural.subspace.jacobian(&z, &mut jac);
        let mut reference = vec![0.0; d * d];
        for a in 0..d {
            for b in 0..d {
                for i in 0..k {
                    for j in 0..k {
                        reference[b * d + a] += jac[a * k + i] * hq[j * k + i] * jac[b * k + j];
                    }
                }
            }
        }
        let what = format!("neural, d = {d}");
        assert_close(&hz, &reference, 1e-6, &what);
        assert!(
            (0..d).all(|a| (0..d).all(|b| hz[a * d + b] == hz[b * d + a])),
            "{what}: not exactly symmetric"
        );
        // Projected tangents: positive semidefinite elastic part, so the matrix is SPD here.
        neural.newton_matrix(&z, true, &mut hz);
        assert!((0..d).all(|i| hz[i * d + i] > 0.0));
        // The cubature rule takes the element basis (F = I + B_e q, G B = B_e J), on the serial
        // vertex path too; the parallel path's stacked terms from decoded vertices and U J form
        // the same matrix to rounding.
        assert_eq!(neural.space.elastic_path(), ElasticPath::ElementBasis);
        for path in [ElasticPath::Vertices, ElasticPath::Parallel] {
            neural.space.set_elastic_path(&neural.model, path);
            let mut by_path = vec![0.0; d * d];
            neural.newton_matrix(&z, true, &mut by_path);
            assert_close(
                &hz,
                &by_path,
                1e-12,
                &format!("{what}: element basis against {path:?}"),
            );
        }
    }
}

/// Without element bases (the parallel path) the Gauss–Newton matrix stacks 128 elements at a
/// time: over a set of two whole chunks and a partial one it forms the element-basis matrix, and
/// the same matrix to the bit on one thread as on the pool.
#[test]
fn chunked_newton_matrix_matches_the_element_basis_one() {
    let mesh = box_mesh(&BoxSpec {
        size: [1.0, 0.2, 0.2],
        cells: [12, 2, 2],
        ..Default::default()
    })
    .unwrap();
    let m = clamped(mesh, -9.81, vec![]);
    let elements = m.elements.len();
    assert!(
        elements > 2 * 128 && !elements.is_multiple_of(128),
        "{elements}"
    );
    let k = 6;
    let basis = small_basis(&m, k);
    let space = reduced_space(&m, &basis, k, None).unwrap();
    for d in [3, 6] {
        let mut sim = neural_newton(&m, &space, k, d);
        sim.step().unwrap();
        let z = moved_off(&sim.state.z);
        let mut matrices = Vec::new();
        for path in [ElasticPath::ElementBasis, ElasticPath::Parallel] {
            sim.space.set_elastic_path(&sim.model, path);
            let mut h = vec![0.0; d * d];
            sim.newton_matrix(&z, true, &mut h);
            assert!(h.iter().any(|&x| x != 0.0), "{path:?}");
            matrices.push(h);
        }
        assert_close(&matrices[1], &matrices[0], 1e-12, &format!("d = {d}"));
        // Its two halves are added in the same order on one thread as on two.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut alone = vec![0.0; d * d];
        one.install(|| sim.newton_matrix(&z, true, &mut alone));
        assert_eq!(alone, matrices[1], "d = {d}: one thread against the pool");
    }
}

/// The preconditioner changes how L-BFGS gets there, not where: with cubature, a neural subspace
/// follows the same trajectory with the rest-state and the current-state preconditioner (rebuilt
/// every few steps) and with Newton, to the solver tolerance.
#[test]
fn every_preconditioner_and_newton_follow_the_same_neural_trajectory() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    let ae =
        nn::Autoencoder::with_architecture(k, 3, &[12, 10], nn::Activation::Elu, None, 7).unwrap();
    let cubature = Some((vec![1usize, 4, 9, 15, 22], vec![1.5, 0.5, 2.0, 1.0, 3.0]));
    let space = reduced_space(&m, &basis, k, cubature).unwrap();
    let frames = 30;
    let run = |method: SolverMethod, preconditioning: Preconditioning| {
        let mut sim = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            NeuralSubspace::new(ae.clone()),
            time(frames),
            solver(method),
        )
        .unwrap();
        sim.preconditioning = preconditioning;
        let mut iterations = 0;
        let mut states = Vec::new();
        for _ in 0..frames {
            iterations += sim.step().unwrap().iterations;
            states.push(sim.state.q.clone());
        }
        (states, iterations)
    };
    let (reference, _) = run(SolverMethod::Newton, Preconditioning::Auto);
    let size = reference
        .iter()
        .flatten()
        .fold(0.0f64, |a, &b| a.max(b.abs()));
    assert!(size > 0.0);
    for p in [
        Preconditioning::Rest,
        Preconditioning::CurrentState,
        Preconditioning::Auto,
    ] {
        let (states, iterations) = run(SolverMethod::Lbfgs, p);
        assert!(iterations > 0);
        for (f, (a, b)) in states.iter().zip(&reference).enumerate() {
            for (x, y) in a.iter().zip(b) {
                assert!(
                    (x - y).abs() <= 1e-6 * size,
                    "{p:?} frame {f}: {x} vs {y} (scale {size:e})"
                );
            }
        }
    }
}

/// A simulator put at step j in the states of another one's steps j and j − 1 takes the same
/// next step (the same minimisation from another warm start, so to the solver's tolerance), for
/// a linear and a neural subspace, and refuses states of the wrong length. The neural subspace
/// needs encode(decode(z)) = z for that: a skip autoencoder whose encoder is the truncation
/// q ↦ q₁..d and whose decoder z ↦ (z, g(z)) adds a nonlinear g in the trailing coefficients.
#[test]
fn a_simulator_restarted_from_two_states_takes_the_same_next_step() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    let mut ae = nn::Autoencoder::with_architecture(k, 3, &[12, 10], nn::Activation::Elu, None, 5)
        .unwrap()
        .with_skip()
        .unwrap();
    {
        let (_, decoder) = ae.networks_mut();
        let last = decoder.num_layers() - 1;
        let w = decoder.weights_mut(last);
        let n_in = w.len() / k;
        for (i, row) in w.chunks_exact_mut(n_in).enumerate().skip(3) {
            for (j, x) in row.iter_mut().enumerate() {
                *x = 0.3 * ((i * n_in + j) as f64).sin();
            }
        }
    }
    let space = reduced_space(&m, &basis, k, None).unwrap();
    fn check<S: Subspace + Clone>(
        m: &FullSpaceModel,
        space: &ReducedSpace,
        subspace: S,
        what: &str,
    ) {
        let frames = 8;
        let mut run = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            subspace.clone(),
            time(frames),
            solver(SolverMethod::Lbfgs),
        )
        .unwrap();
        let mut states = vec![run.state.q.clone()];
        for _ in 0..frames {
            run.step().unwrap();
            states.push(run.state.q.clone());
        }
        let mut restarted = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            subspace,
            time(frames),
            solver(SolverMethod::Lbfgs),
        )
        .unwrap();
        // Steps out of order: nothing of the previous restart may carry over.
        for j in [5, 1, 7, 3] {
            restarted.set_state(j, &states[j], &states[j - 1]).unwrap();
            assert_eq!(restarted.state.step, j);
            restarted.step().unwrap();
            let size = states[j + 1].iter().map(|a| a * a).sum::<f64>().sqrt();
            let diff = states[j + 1]
                .iter()
                .zip(&restarted.state.q)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(
                diff <= 1e-6 * size,
                "{what}, step {}: {:.2e} of {size:.2e}",
                j + 1,
                diff
            );
        }
        let err = restarted
            .set_state(2, &states[2][..5], &states[1])
            .unwrap_err();
        assert!(
            matches!(
                err,
                latent_sim::ReducedError::StateShape {
                    expected: 6,
                    got: 5
                }
            ),
            "{err}"
        );
        // A coefficient that is not finite is refused, not carried into the next step (a
        // tester's NaN state was taken and failed the step after with a preconditioner error).
        let mut bad = states[1].clone();
        bad[3] = f64::NAN;
        let err = restarted.set_state(2, &states[2], &bad).unwrap_err();
        assert!(
            matches!(
                err,
                latent_sim::ReducedError::StateNotFinite { index: 3, .. }
            ),
            "{err}"
        );
        // A step count whose next step would overflow is refused (a debug build panicked).
        let err = restarted
            .set_state(usize::MAX, &states[2], &states[1])
            .unwrap_err();
        assert!(
            matches!(err, latent_sim::ReducedError::StateStep { .. }),
            "{err}"
        );
        restarted
            .set_state(latent_sim::MAX_STATE_STEP, &states[2], &states[1])
            .unwrap();
        restarted.step().unwrap();
    }
    check(&m, &space, LinearSubspace::new(k), "linear");
    check(&m, &space, NeuralSubspace::new(ae), "neural");
}

/// A skip autoencoder k → d whose output layers are zero: exactly the truncation to the leading
/// d coefficients, z = q₁..d, q = (z, 0).
fn truncation(k: usize, d: usize) -> NeuralSubspace {
    NeuralSubspace::new(
        nn::Autoencoder::with_architecture(k, d, &[8], nn::Activation::Elu, None, 3)
            .unwrap()
            .with_skip()
            .unwrap(),
    )
}

fn gravity_only(g: f64) -> FullSpaceModel {
    clamped(bar(), g, vec![])
}

/// In the linear regime (a tiny gravity) the first m steps from rest lie in the span of the m
/// onset directions, so a one-coordinate subspace with them follows the k-coefficient trajectory
/// for m steps, where the subspace alone is far off.
#[test]
fn onset_directions_reproduce_the_first_steps_of_a_release_under_gravity() {
    let m = gravity_only(-1e-3);
    let k = 6;
    let space = reduced_space(&m, &small_basis(&m, k), k, None).unwrap();
    let steps = 3;
    let mut reference = ReducedSimulator::new(
        m.clone(),
        space.clone(),
        LinearSubspace::new(k),
        time(steps),
        solver(SolverMethod::Lbfgs),
    )
    .unwrap();
    let run = |onset: usize| {
        let sub =
            Augmented::with_gravity_onset(truncation(k, 1), &space, &time(steps), onset).unwrap();
        assert_eq!(
            sub.latent_dim(),
            1 + onset,
            "all {onset} directions are new"
        );
        ReducedSimulator::new(
            m.clone(),
            space.clone(),
            sub,
            time(steps),
            solver(SolverMethod::Lbfgs),
        )
        .unwrap()
    };
    let (mut with, mut without) = (run(steps), run(0));
    for step in 1..=steps {
        reference.step().unwrap();
        with.step().unwrap();
        without.step().unwrap();
        let q = &reference.state.q;
        let size = q.iter().map(|a| a * a).sum::<f64>().sqrt();
        let off = |p: &[f64]| {
            q.iter()
                .zip(p)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
                / size
        };
        let (e_with, e_without) = (off(&with.state.q), off(&without.state.q));
        assert!(
            e_with <= 1e-6,
            "step {step}: {e_with:.2e} with the directions"
        );
        assert!(e_without >= 1e-2, "step {step}: {e_without:.2e} without");
    }
}

/// Columns `from..` of the Jacobian `jac` (k × d) are A-orthogonal to every column before them,
/// A = UᵀMU/h² + UᵀK₀U.
fn assert_linear_columns_a_orthogonal(space: &ReducedSpace, h: f64, jac: &[f64], from: usize) {
    let k = space.k;
    let a: Vec<f64> = space
        .mass
        .iter()
        .zip(&space.rest_stiffness)
        .map(|(m, k0)| m / (h * h) + k0)
        .collect();
    let a_dot = |x: &[f64], y: &[f64]| -> f64 {
        (0..k)
            .map(|i| (0..k).map(|j| x[i] * a[j * k + i] * y[j]).sum::<f64>())
            .sum()
    };
    let cols: Vec<&[f64]> = jac.chunks_exact(k).collect();
    for i in from..cols.len() {
        for (j, c) in cols.iter().enumerate().take(i) {
            let (aij, aii, ajj) = (a_dot(cols[i], c), a_dot(cols[i], cols[i]), a_dot(c, c));
            assert!(
                aij.abs() <= 1e-9 * (aii * ajj).sqrt(),
                "columns {i}, {j}: {aij:.3e}"
            );
        }
    }
}

/// The directions are A-orthogonal (A = UᵀMU/h² + UᵀK₀U) to the tangent at rest and to each
/// other, J = [J_f | V] and q is linear in w; none are added without gravity, for m = 0, or
/// where the subspace already spans every coefficient. (The reduced gradient through them is
/// checked with the neural subspace's.)
#[test]
fn onset_directions_are_new_and_linear() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    let h = time(1).step;
    let space = reduced_space(&m, &basis, k, None).unwrap();
    let ae =
        nn::Autoencoder::with_architecture(k, 2, &[12, 10], nn::Activation::Elu, None, 5).unwrap();
    let mut sub =
        Augmented::with_gravity_onset(NeuralSubspace::new(ae.clone()), &space, &time(1), 3)
            .unwrap();
    assert_eq!(sub.directions(), 3);
    let d = sub.latent_dim();
    let mut z0 = vec![0.0; d];
    sub.encode(&vec![0.0; k], &mut z0);
    assert!(
        z0[2..].iter().all(|w| w.abs() <= 1e-12),
        "rest is at w = 0: {z0:?}"
    );
    let mut jac = vec![0.0; k * d];
    sub.jacobian(&z0, &mut jac);
    assert_linear_columns_a_orthogonal(&space, h, &jac, 2);
    let cols: Vec<&[f64]> = jac.chunks_exact(k).collect();
    // q is linear in w, along V.
    let (mut q1, mut q2) = (vec![0.0; k], vec![0.0; k]);
    let mut z = z0.clone();
    z[0] += 0.1;
    sub.decode(&z, &mut q1);
    z[3] += 0.5;
    sub.decode(&z, &mut q2);
    for i in 0..k {
        assert!((q2[i] - q1[i] - 0.5 * cols[3][i]).abs() <= 1e-12 * (1.0 + q1[i].abs()));
    }
    // Nothing to add: no gravity, m = 0, or a subspace that spans all k coefficients at rest.
    let still = gravity_only(0.0);
    let space0 = reduced_space(&still, &small_basis(&still, k), k, None).unwrap();
    let none = Augmented::with_gravity_onset(truncation(k, 2), &space0, &time(1), 3).unwrap();
    assert_eq!(none.directions(), 0);
    let none = Augmented::with_gravity_onset(truncation(k, 2), &space, &time(1), 0).unwrap();
    assert_eq!(none.directions(), 0);
    let none = Augmented::with_gravity_onset(LinearSubspace::new(k), &space, &time(1), 3).unwrap();
    assert_eq!(none.directions(), 0);
}

/// encode finds the point of the subspace nearest q, not the encoder's guess: an untrained
/// autoencoder's encoder is far off, yet a pose the subspace holds (any decoded (z, w)) comes
/// back to within round-off, and a pose it does not hold comes back no farther than the
/// encoder's guess put it.
#[test]
fn encode_finds_the_nearest_point_of_the_subspace() {
    let m = model();
    let k = 6;
    let space = reduced_space(&m, &small_basis(&m, k), k, None).unwrap();
    let ae =
        nn::Autoencoder::with_architecture(k, 2, &[12, 10], nn::Activation::Elu, None, 5).unwrap();
    let mut sub =
        Augmented::with_gravity_onset(NeuralSubspace::new(ae.clone()), &space, &time(1), 2)
            .unwrap();
    let d = sub.latent_dim();
    assert_eq!(d, 4);
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let mut ws = ae.workspace();
    for (a, b) in [(0.3, 0.02), (-0.5, 0.05), (0.8, -0.01)] {
        // A pose in the subspace.
        let target: Vec<f64> = (0..d).map(|i| a * (i as f64 + 1.0).sin() + b).collect();
        let mut q = vec![0.0; k];
        sub.decode(&target, &mut q);
        // The encoder alone is far from it ...
        let (mut ze, mut qe) = (vec![0.0; 2], vec![0.0; k]);
        ae.encode(&q, &mut ze, &mut ws);
        ae.decode(&ze, &mut qe, &mut ws);
        let off = |p: &[f64]| norm(&p.iter().zip(&q).map(|(x, y)| x - y).collect::<Vec<_>>());
        assert!(off(&qe) > 1e-2 * norm(&q), "the encoder is already exact");
        // ... encode is not.
        let (mut z, mut back) = (vec![0.0; d], vec![0.0; k]);
        sub.encode(&q, &mut z);
        sub.decode(&z, &mut back);
        assert!(
            off(&back) <= 1e-8 * norm(&q),
            "{} of {}",
            off(&back),
            norm(&q)
        );
        // A pose off the subspace: q plus a little of every coefficient.
        let q2: Vec<f64> = q
            .iter()
            .enumerate()
            .map(|(i, x)| x + 0.01 * (i as f64).cos())
            .collect();
        sub.encode(&q2, &mut z);
        sub.decode(&z, &mut back);
        let miss = norm(&back.iter().zip(&q2).map(|(x, y)| x - y).collect::<Vec<_>>());
        assert!(miss <= norm(&q2.iter().zip(&q).map(|(x, y)| x - y).collect::<Vec<_>>()) + 1e-12);
    }
}

/// Where the decoder's tangent lies in the span of the linear directions (here by
/// construction: they include the tangent at z*, away from rest, and fill the coefficients
/// beside d = 2), encode still finds the poses the subspace holds around z*.
#[test]
fn encode_finds_poses_where_the_tangent_lies_in_the_directions() {
    let m = model();
    let k = 6;
    let space = reduced_space(&m, &small_basis(&m, k), k, None).unwrap();
    let ae =
        nn::Autoencoder::with_architecture(k, 2, &[12, 10], nn::Activation::Elu, None, 5).unwrap();
    let mut inner = NeuralSubspace::new(ae);
    let star = [1.5, -2.0];
    let mut tangent = vec![0.0; 2 * k];
    inner.jacobian(&star, &mut tangent);
    let generic: Vec<f64> = (0..2 * k).map(|i| (1.3 * i as f64 + 0.5).sin()).collect();
    let complement = [&tangent[..], &generic].concat();
    let mut sub = Augmented::with_directions(inner, &space, &time(1), 0, &complement).unwrap();
    assert_eq!(sub.directions(), 4);
    let d = sub.latent_dim();
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    for t in 0..50 {
        let mut target = vec![0.0; d];
        target[0] = star[0] + 0.3 * (0.7 * t as f64).sin();
        target[1] = star[1] + 0.3 * (1.1 * t as f64).cos();
        for (i, w) in target[2..].iter_mut().enumerate() {
            *w = 0.3 * (0.37 * (t + i) as f64).cos();
        }
        let mut q = vec![0.0; k];
        sub.decode(&target, &mut q);
        let (mut z, mut back) = (vec![0.0; d], vec![0.0; k]);
        sub.encode(&q, &mut z);
        sub.decode(&z, &mut back);
        let off = norm(&back.iter().zip(&q).map(|(x, y)| x - y).collect::<Vec<_>>());
        assert!(off <= 1e-8 * norm(&q), "pose {t}: {off} of {}", norm(&q));
    }
}

/// Complement directions join the subspace where they are new: one already in the tangent at
/// rest, or a repeat, is dropped; the kept ones are A-orthogonal to the tangent and to the onset
/// directions before them; they are added without gravity too; a column of the wrong length is a
/// typed error.
#[test]
fn complement_directions_are_kept_where_new() {
    let m = model();
    let k = 6;
    let h = time(1).step;
    let space = reduced_space(&m, &small_basis(&m, k), k, None).unwrap();
    let ae =
        nn::Autoencoder::with_architecture(k, 2, &[12, 10], nn::Activation::Elu, None, 5).unwrap();
    let mut inner = NeuralSubspace::new(ae.clone());
    let (mut z0, mut j0) = (vec![0.0; 2], vec![0.0; 2 * k]);
    inner.encode(&vec![0.0; k], &mut z0);
    inner.jacobian(&z0, &mut j0);
    // In the tangent, new, the same again, new.
    let new1: Vec<f64> = (0..k).map(|i| (0.9 * i as f64 + 0.2).sin()).collect();
    let new2: Vec<f64> = (0..k).map(|i| (i as f64 - 2.5).powi(2)).collect();
    let in_tangent: Vec<f64> = (0..k).map(|i| 2.0 * j0[i] - 0.5 * j0[k + i]).collect();
    let candidates = [&in_tangent[..], &new1, &new1, &new2].concat();
    let mut sub = Augmented::with_directions(
        NeuralSubspace::new(ae.clone()),
        &space,
        &time(1),
        1,
        &candidates,
    )
    .unwrap();
    assert_eq!(sub.directions(), 3, "the onset direction, new1 and new2");
    let d = sub.latent_dim();
    let mut jac = vec![0.0; k * d];
    sub.jacobian(
        &z0.iter().copied().chain([0.0; 3]).collect::<Vec<_>>(),
        &mut jac,
    );
    assert_linear_columns_a_orthogonal(&space, h, &jac, 2);
    // Without gravity only the onset directions go.
    let still = gravity_only(0.0);
    let space0 = reduced_space(&still, &small_basis(&still, k), k, None).unwrap();
    let sub0 =
        Augmented::with_directions(NeuralSubspace::new(ae.clone()), &space0, &time(1), 2, &new1)
            .unwrap();
    assert_eq!(sub0.directions(), 1);
    let err = Augmented::with_directions(NeuralSubspace::new(ae), &space, &time(1), 0, &new1[1..])
        .unwrap_err();
    assert!(
        matches!(err, latent_sim::ReducedError::StateShape { .. }),
        "{err}"
    );
}

/// Under the classic Neo-Hookean model the energy is not finite past an inverted element. A
/// state moving so fast that the extrapolated start of the next solve inverts the bar still
/// steps: the solve starts again from the last answer, where the energy is finite, ends with
/// every element upright, and its report counts the restart.
#[test]
fn a_start_that_inverts_an_element_is_retried_from_the_last_state() {
    let mut m = model();
    m.forces.clear();
    let classic = MaterialConfig {
        model: fem_core::material::MaterialModel::NeoHookean,
        ..material()
    };
    let m = FullSpaceModel::new(
        m.mesh.clone(),
        &classic,
        m.pinned.clone(),
        m.gravity,
        vec![],
    )
    .unwrap();
    let k = 4;
    let basis = small_basis(&m, k);
    let space = reduced_space(&m, &basis, k, None).unwrap();
    for method in [SolverMethod::Lbfgs, SolverMethod::Newton] {
        let mut sim = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            LinearSubspace::new(k),
            time(4),
            solver(method),
        )
        .unwrap();
        // q_n = 0 after q_{n-1} = X: the start q_n + h q̇_n = −X, which compresses the bar past
        // inversion.
        let x: Vec<f64> = (0..k).map(|i| if i == 0 { 200.0 } else { 0.0 }).collect();
        let rest = vec![0.0; k];
        sim.set_state(1, &rest, &x).unwrap();
        let mut g = vec![0.0; k];
        let start: Vec<f64> = x.iter().map(|v| -v).collect();
        assert!(
            !sim.objective(&start, &mut g).is_finite(),
            "{method:?}: the extrapolated start must be outside the energy's domain for this test"
        );
        let report = sim
            .step()
            .unwrap_or_else(|e| panic!("{method:?}: the step failed: {e}"));
        assert!(report.restarted, "{method:?}: the report says so");
        assert!(sim.state.q.iter().all(|v| v.is_finite()));
        assert!(sim.energy().elastic.is_finite(), "{method:?}");
        // A step from rest starts inside the domain and says so.
        sim.set_state(1, &rest, &rest).unwrap();
        assert!(!sim.step().unwrap().restarted, "{method:?}");
    }
}

/// q = s z: the identity subspace with latent coordinates 1/s times larger, as a decoder whose
/// outputs are small next to its inputs (nonlinear, for the simulator: its Jacobian is formed).
#[derive(Debug, Clone)]
struct Stretched {
    k: usize,
    s: f64,
}

impl Subspace for Stretched {
    fn latent_dim(&self) -> usize {
        self.k
    }
    fn coeff_dim(&self) -> usize {
        self.k
    }
    fn decode(&mut self, z: &[f64], q: &mut [f64]) {
        q.iter_mut().zip(z).for_each(|(q, z)| *q = self.s * z);
    }
    fn vjp(&mut self, _z: &[f64], v: &[f64], out: &mut [f64]) {
        out.iter_mut().zip(v).for_each(|(o, v)| *o = self.s * v);
    }
    fn jacobian(&mut self, _z: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for i in 0..self.k {
            out[i * self.k + i] = self.s;
        }
    }
    fn encode(&mut self, q: &[f64], z: &mut [f64]) {
        z.iter_mut().zip(q).for_each(|(z, q)| *z = q / self.s);
    }
}

/// The solver's convergence test does not depend on the latent coordinates' units: the same
/// subspace with z scaled by 10⁵ (q = 10⁻⁵ z), at the default tolerance, follows the linear
/// subspace's trajectory. Before the relative gradient was measured in z's units it stopped at
/// the start of every step there, and the bar never moved.
#[test]
fn the_trajectory_does_not_depend_on_the_units_of_z() {
    let m = model();
    let k = 6;
    let basis = small_basis(&m, k);
    let space = reduced_space(&m, &basis, k, None).unwrap();
    let solver = SolverConfig {
        tolerance: 1e-4,
        ..solver(SolverMethod::Lbfgs)
    };
    let mut linear = ReducedSimulator::new(
        m.clone(),
        space.clone(),
        LinearSubspace::new(k),
        time(8),
        solver.clone(),
    )
    .unwrap();
    let mut stretched =
        ReducedSimulator::new(m, space, Stretched { k, s: 1e-5 }, time(8), solver).unwrap();
    for step in 1..=8 {
        linear.step().unwrap();
        stretched.step().unwrap();
        let size = linear.state.q.iter().map(|a| a * a).sum::<f64>().sqrt();
        let diff = linear
            .state
            .q
            .iter()
            .zip(&stretched.state.q)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(size > 0.0, "step {step}: the linear run must move");
        assert!(diff <= 1e-2 * size, "step {step}: {diff:.2e} of {size:.2e}");
    }
}

/// A current-state preconditioner that has served a solve 32 iterations past its first solve's
/// count (none for one made in the step), or past the iteration cap, is rebuilt at the solve's
/// iterate, and L-BFGS goes on from there instead of handing the step to Newton. The rest
/// state's matrix is never rebuilt within a solve: a solve that cannot finish with it falls back
/// to Newton.
#[test]
fn a_preconditioner_that_stops_serving_is_rebuilt_within_the_solve() {
    let m = model();
    let n = m.dofs.num_free();
    let space = reduced_space(&m, &full_rank_basis(&m), n, None).unwrap();
    let simulator = |preconditioning| {
        let mut red = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            LinearSubspace::new(n),
            time(10),
            solver(SolverMethod::Lbfgs),
        )
        .unwrap();
        red.preconditioning = preconditioning;
        red
    };
    let step = |red: &mut ReducedSimulator<LinearSubspace>, cap: usize| {
        red.solver.max_iterations = cap;
        let r = red.step().unwrap();
        (r.preconditioner_rebuilt, r.newton_fallback, r.iterations)
    };
    let mut red = simulator(Preconditioning::CurrentState);
    // The first step takes 4 iterations to 1e-10 with the preconditioner made at its start:
    // held to 3 at a time, L-BFGS rebuilds it at its iterate and finishes.
    let (rebuilt, fell_back, iterations) = step(&mut red, 3);
    assert!(rebuilt && !fell_back && iterations > 3, "{iterations}");
    // The next two steps keep it (5 iterations each); the third rebuilds it at its start, as
    // the two took 8 more than its first solve.
    let kept: Vec<_> = (0..4).map(|_| step(&mut red, 500)).collect();
    assert_eq!(
        kept,
        [
            (false, false, 5),
            (false, false, 5),
            (true, false, 3),
            (false, false, 6)
        ]
    );
    // The next step takes 7 iterations with the kept preconditioner: held to 2, L-BFGS rebuilds
    // it at its iterate and finishes, as above.
    let (rebuilt, fell_back, iterations) = step(&mut red, 2);
    assert!(rebuilt && !fell_back && iterations > 2, "{iterations}");
    assert!(!step(&mut red, 500).0);
    // The rest state's matrix, held to 3: Newton finishes the step, and the matrix is kept.
    let mut red = simulator(Preconditioning::Rest);
    assert!(step(&mut red, 500).0);
    let (rebuilt, fell_back, _) = step(&mut red, 3);
    assert!(!rebuilt && fell_back);
    assert!(!step(&mut red, 500).0);
    // Held to one iteration, neither finishes: the failure is said as both solvers', with
    // every iteration spent (it read "Newton did not converge" under an L-BFGS scene).
    red.solver.max_iterations = 1;
    let e = red.step().unwrap_err().to_string();
    assert!(
        e.starts_with("L-BFGS, then reduced Newton from the step's start did not converge")
            && e.contains("after 2 iterations"),
        "{e}"
    );
}
