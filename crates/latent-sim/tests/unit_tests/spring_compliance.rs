//! A spring on a patch pulls the reduced body as hard as it pulls the full one: the patch
//! compliance the basis lacks is put in series with it (see `simulator/springs.rs`).

use fem_core::Vec3;
use fem_core::constraints::{Axis, Side, VertexSelection};
use fem_core::forces::{ExternalForce, ForceKind};
use fem_core::integrator::{FullSpaceModel, Simulator};
use fem_core::material::{MaterialConfig, MaterialModel};
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::optim::{SolverConfig, SolverMethod};
use latent_sim::{LinearSubspace, ReducedSimulator};

use super::{full_rank_basis, reduced_space, small_basis};
use crate::unit_tests::models::time;

fn newton() -> SolverConfig {
    SolverConfig {
        method: SolverMethod::Newton,
        tolerance: 1e-12,
        max_iterations: 50,
        ..Default::default()
    }
}

/// A linear-elastic bar pinned at x = 0, no gravity, with a spring of stiffness `ks` on its
/// far top corner vertex pulling it towards `w` from the start.
fn cornered(ks: f64, w: [f64; 3]) -> (FullSpaceModel, usize) {
    let mesh = box_mesh(&BoxSpec {
        size: [1.0, 0.2, 0.2],
        cells: [6, 2, 2],
        ..Default::default()
    })
    .unwrap();
    let corner = (0..mesh.num_vertices())
        .max_by(|&a, &b| {
            let s = |v: usize| mesh.vertices[v].x + mesh.vertices[v].y + mesh.vertices[v].z;
            s(a).total_cmp(&s(b))
        })
        .unwrap();
    let pinned = VertexSelection::plane(Axis::X, Side::Min, None)
        .select(&mesh, "pin")
        .unwrap();
    let spring = ExternalForce {
        kind: ForceKind::Spring,
        vertices: vec![corner],
        stiffness: ks,
        keyframes: vec![[0.0, w[0], w[1], w[2]]],
        start: 0.0,
        end: f64::INFINITY,
    };
    let material = MaterialConfig {
        model: MaterialModel::Linear,
        youngs_modulus: 1e5,
        poisson_ratio: 0.4,
        ..Default::default()
    };
    let model = FullSpaceModel::new(mesh, &material, pinned, Vec3::zeros(), vec![spring]).unwrap();
    (model, corner)
}

/// For a spring on one vertex of a linear body, one step from rest: the full step's spring
/// force is F = (I/k + C)⁻¹ w, C the vertex's compliance under the step's operator A. The
/// reduced step with the missing compliance C − Ĉ in series applies the same F, so its
/// coefficients are Â⁻¹ Uᵀ e_v F exactly; the spring as it is pulls harder and misses them.
#[test]
fn a_softened_spring_pulls_the_reduced_body_with_the_full_steps_force() {
    let (ks, w) = (4e3, [0.0, 0.02, 0.01]);
    let (m, corner) = cornered(ks, w);
    let mut full = Simulator::new(m.clone(), time(1), newton()).unwrap();
    full.step().unwrap();
    let force = Vec3::from_fn(|c, _| ks * (w[c] - full.state.u[3 * corner + c]));

    let k = 5;
    let n = m.dofs.num_free();
    let basis = small_basis(&m, k);
    let space = reduced_space(&m, &basis, k, None).unwrap();
    let h = time(1).step;
    // Â = UᵀK₀U + UᵀMU/h² (column-major) and b = Uᵀ e_v F.
    let a = faer::Mat::<f64>::from_fn(k, k, |i, j| {
        space.rest_stiffness[j * k + i] + space.mass[j * k + i] / (h * h)
    });
    let b = faer::Mat::<f64>::from_fn(k, 1, |j, _| {
        (0..3)
            .map(|c| basis[j * n + m.dofs.index[3 * corner + c]] * force[c])
            .sum()
    });
    let want = faer::linalg::solvers::Solve::solve(&a.partial_piv_lu(), &b);
    let miss = |on: bool| {
        let mut red = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            LinearSubspace::new(k),
            time(1),
            newton(),
        )
        .unwrap();
        red.set_spring_compliance(on);
        assert_eq!(red.spring_compliance(), on);
        red.step().unwrap();
        let q = &red.state.q;
        let diff: f64 = (0..k).map(|j| (q[j] - want[(j, 0)]).powi(2)).sum::<f64>();
        let size: f64 = (0..k).map(|j| want[(j, 0)].powi(2)).sum::<f64>();
        (diff / size).sqrt()
    };
    let (softened, plain) = (miss(true), miss(false));
    assert!(
        softened < 1e-8,
        "softened spring: {softened:.2e} from Â⁻¹UᵀF"
    );
    assert!(
        plain > 1e-2,
        "the spring as it is: only {plain:.2e} from Â⁻¹UᵀF"
    );
}

/// Softening is on by default, applies to springs given to the simulator and added later,
/// leaves point loads alone, and a basis holding every direction lacks no compliance (its
/// spring's terms are those of the spring as it is, to round-off).
#[test]
fn softening_is_the_default_and_vanishes_for_a_complete_basis() {
    let (m, corner) = cornered(4e3, [0.0, 0.02, 0.01]);
    let n = m.dofs.num_free();
    let complete = full_rank_basis(&m);
    let k = 5;
    let basis = small_basis(&m, k);
    for (basis, k, lacks) in [(complete, n, false), (basis, k, true)] {
        let space = reduced_space(&m, &basis, k, None).unwrap();
        let mut red =
            ReducedSimulator::new(m.clone(), space, LinearSubspace::new(k), time(3), newton())
                .unwrap();
        assert!(red.spring_compliance());
        let load = ExternalForce {
            kind: ForceKind::Point,
            vertices: vec![corner],
            stiffness: 0.0,
            keyframes: vec![[0.0, 0.0, -1.0, 0.0]],
            start: 0.0,
            end: f64::INFINITY,
        };
        let again = m.forces[0].clone();
        // A force without keyframes is refused, not taken to panic at the next step.
        let empty = ExternalForce {
            keyframes: Vec::new(),
            ..load.clone()
        };
        let e = red.add_force(empty).unwrap_err().to_string();
        assert!(e.starts_with("invalid force: keyframes must be"), "{e}");
        red.add_force(load).unwrap();
        red.add_force(again).unwrap();
        // The energies of the three forces at some q, softened and not.
        let q: Vec<f64> = (0..k).map(|j| 1e-3 * ((j + 1) as f64).sin()).collect();
        let energies = |red: &ReducedSimulator<LinearSubspace>| -> Vec<f64> {
            let mut buf = red.space.buffers();
            let mut g = vec![0.0; k];
            (0..3)
                .map(|i| {
                    red.space
                        .force_energy_gradient(&red.model, i, 0.01, &q, &mut g, &mut buf)
                        .0
                })
                .collect()
        };
        let soft = energies(&red);
        red.set_spring_compliance(false);
        let plain = energies(&red);
        assert_eq!(soft[1], plain[1], "a point load is never softened");
        assert_eq!(
            soft[0], soft[2],
            "a spring added later is softened as one given"
        );
        let change = (soft[0] - plain[0]).abs() / plain[0].abs();
        if lacks {
            assert!(
                change > 1e-3,
                "a 5-column basis: the spring's energy moved {change:.1e}"
            );
        } else {
            assert!(
                change < 1e-9,
                "a complete basis: the spring's energy moved {change:.1e}"
            );
        }
    }
}

/// The same step, displaced: the reduced step's force F on the patch is the full one's, and the
/// displacement the simulator reports adds back the dent the basis lacks, U(q − Â⁻¹UᵀGᵀF) +
/// A⁻¹GᵀF, which for a linear body is the full step's displacement A⁻¹GᵀF itself. Uq alone
/// misses it; without softening nothing is added; a moved target or a new spring shows only
/// after a step; a removed spring takes its dent with it.
#[test]
fn the_reported_displacement_holds_the_dent_the_basis_lacks() {
    let (ks, w) = (4e3, [0.0, 0.02, 0.01]);
    let (m, _) = cornered(ks, w);
    let mut full = Simulator::new(m.clone(), time(1), newton()).unwrap();
    full.step().unwrap();
    let k = 5;
    let basis = small_basis(&m, k);
    let space = reduced_space(&m, &basis, k, None).unwrap();
    let distance = |u: &[f64]| {
        let d: f64 = u
            .iter()
            .zip(&full.state.u)
            .map(|(a, b)| (a - b).powi(2))
            .sum();
        let s: f64 = full.state.u.iter().map(|b| b * b).sum();
        (d / s).sqrt()
    };
    let stepped = |on: bool| {
        let mut red = ReducedSimulator::new(
            m.clone(),
            space.clone(),
            LinearSubspace::new(k),
            time(1),
            newton(),
        )
        .unwrap();
        red.set_spring_compliance(on);
        red.step().unwrap();
        red
    };
    let mut red = stepped(true);
    let mut uq = vec![0.0; m.num_full()];
    red.space.reconstruct(&red.state.q, &mut uq);
    let (dented, bare) = (distance(&red.full_displacement()), distance(&uq));
    assert!(
        dented < 1e-7,
        "with the dent: {dented:.2e} from the full step"
    );
    assert!(bare > 1e-2, "Uq alone: only {bare:.2e} from the full step");

    let plain = stepped(false);
    let mut uq_plain = vec![0.0; m.num_full()];
    plain.space.reconstruct(&plain.state.q, &mut uq_plain);
    assert_eq!(plain.full_displacement(), uq_plain, "no softening, no dent");

    // The dent belongs to the state the step computed: moving the target, adding a spring or
    // removing one changes no reported position until the next step.
    let stepped_u = red.full_displacement();
    red.set_force_keyframes(0, &[[0.0, 0.0, -0.05, 0.0]])
        .unwrap();
    let again = red.model.forces[0].clone();
    red.add_force(again).unwrap();
    assert_eq!(red.full_displacement(), stepped_u, "no step, no new dent");
    red.remove_force(1).unwrap();
    red.remove_force(0).unwrap();
    assert_eq!(
        red.full_displacement(),
        stepped_u,
        "no step, the dent stays"
    );

    red.step().unwrap();
    red.space.reconstruct(&red.state.q, &mut uq);
    assert_eq!(
        red.full_displacement(),
        uq,
        "after a step the removed spring's dent is gone"
    );
}
