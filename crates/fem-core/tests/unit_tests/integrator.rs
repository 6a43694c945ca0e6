//! Implicit Euler and the quasi-static mode: rest states, dissipation, solver agreement, large
//! loads and clear errors.

use fem_core::FemError;
use fem_core::constraints::{Axis, Side, VertexSelection};
use fem_core::forces::{ExternalForce, ForceKind};
use fem_core::integrator::{FullSpaceModel, PRECOND_MAX_AGE, Simulator, TimeConfig};
use fem_core::material::{MaterialConfig, MaterialModel};
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::optim::{LbfgsPreconditioner, SolverConfig, SolverMethod};
use fem_core::{TetMesh, Vec3};

fn beam(cells: [usize; 3]) -> TetMesh {
    box_mesh(&BoxSpec {
        size: [1.0, 0.1, 0.1],
        cells,
        ..Default::default()
    })
    .unwrap()
}

fn model(
    mesh: TetMesh,
    material: MaterialModel,
    youngs_modulus: f64,
    gravity: [f64; 3],
    forces: Vec<ExternalForce>,
) -> FullSpaceModel {
    let pinned = VertexSelection::plane(Axis::X, Side::Min, None)
        .select(&mesh, "pin")
        .unwrap();
    let material = MaterialConfig {
        model: material,
        youngs_modulus,
        poisson_ratio: 0.4,
        ..Default::default()
    };
    FullSpaceModel::new(mesh, &material, pinned, Vec3::from(gravity), forces).unwrap()
}

fn solver(method: SolverMethod, tolerance: f64) -> SolverConfig {
    SolverConfig {
        method,
        tolerance,
        max_iterations: 200,
        ..Default::default()
    }
}

fn dynamic(frames: usize) -> TimeConfig {
    TimeConfig {
        step: 0.01,
        frames,
        quasi_static: false,
    }
}

/// One quasi-static solve: static equilibrium under the loads at t = 1.
fn static_frame() -> TimeConfig {
    TimeConfig {
        step: 1.0,
        frames: 1,
        quasi_static: true,
    }
}

/// The unpinned 6×2×2 beam (stable Neo-Hookean, E = 10⁵ Pa) under gravity `g`.
fn free_body(g: [f64; 3]) -> FullSpaceModel {
    let material = MaterialConfig {
        model: MaterialModel::StableNeoHookean,
        youngs_modulus: 1e5,
        poisson_ratio: 0.4,
        ..Default::default()
    };
    FullSpaceModel::new(beam([6, 2, 2]), &material, vec![], Vec3::from(g), vec![]).unwrap()
}

fn tip(mesh: &TetMesh) -> usize {
    (0..mesh.num_vertices())
        .min_by(|&a, &b| {
            let d = |v: usize| (mesh.vertices[v] - Vec3::new(1.0, 0.05, 0.05)).norm();
            d(a).total_cmp(&d(b))
        })
        .unwrap()
}

#[test]
fn a_body_at_rest_without_loads_stays_exactly_at_rest() {
    for method in [SolverMethod::Newton, SolverMethod::Lbfgs] {
        let m = model(
            beam([6, 2, 2]),
            MaterialModel::StableNeoHookean,
            1e5,
            [0.0; 3],
            vec![],
        );
        let mut sim = Simulator::new(m, dynamic(5), solver(method, 1e-8)).unwrap();
        for _ in 0..5 {
            let r = sim.step().unwrap();
            assert_eq!(r.iterations, 0, "{method:?}");
        }
        assert!(sim.state.u.iter().all(|&u| u == 0.0));
        assert!(sim.state.v.iter().all(|&v| v == 0.0));
    }
}

/// An unpinned body in uniform gravity translates rigidly: implicit Euler gives
/// u_n = h² g n(n+1)/2 exactly. From the second step on, the start u_n + h u̇_n + h² ü_n is that
/// solution, so the solver has nothing left to do.
#[test]
fn free_fall_follows_implicit_euler_and_the_extrapolated_start_is_already_the_solution() {
    let g = [0.0, -9.81, 0.0];
    for method in [SolverMethod::Newton, SolverMethod::Lbfgs] {
        let mut sim = Simulator::new(free_body(g), dynamic(6), solver(method, 1e-8)).unwrap();
        let h = sim.time.step;
        for n in 1..=6 {
            let r = sim.step().unwrap();
            if n == 1 {
                assert!(
                    r.iterations > 0,
                    "{method:?}: the first step starts from rest"
                );
            } else {
                assert_eq!(r.iterations, 0, "{method:?}, step {n}");
            }
            let expect = h * h * g[1] * (n * (n + 1)) as f64 / 2.0;
            for (i, &u) in sim.state.u.iter().enumerate() {
                let want = if i % 3 == 1 { expect } else { 0.0 };
                assert!(
                    (u - want).abs() <= 1e-9 * expect.abs(),
                    "{method:?}, step {n}, dof {i}: {u} against {want}"
                );
            }
        }
    }
}

#[test]
fn pinned_beam_under_gravity_settles_and_never_gains_energy() {
    // First bending mode ≈ 1.6 Hz; with h = 0.05 implicit Euler damps it within a few seconds.
    let time = TimeConfig {
        step: 0.05,
        frames: 200,
        quasi_static: false,
    };
    let mesh = beam([10, 2, 2]);
    let t = tip(&mesh);
    let m = model(
        mesh,
        MaterialModel::StableNeoHookean,
        1e7,
        [0.0, -9.81, 0.0],
        vec![],
    );
    let mut sim = Simulator::new(m, time, solver(SolverMethod::Newton, 1e-10)).unwrap();
    let mut last = sim.report().total_energy;
    let mut max_ke: f64 = 0.0;
    for k in 0..200 {
        let r = sim.step().unwrap();
        // Implicit Euler is dissipative: with constant forces the total energy cannot grow.
        let slack = 1e-9 * r.elastic_energy.abs().max(1e-12);
        assert!(
            r.total_energy <= last + slack,
            "step {k}: total energy rose from {last} to {}",
            r.total_energy
        );
        last = r.total_energy;
        max_ke = max_ke.max(r.kinetic_energy);
    }
    let r = sim.report();
    assert!(
        r.kinetic_energy < 1e-8 * max_ke,
        "still moving: {} of {max_ke}",
        r.kinetic_energy
    );
    let dynamic_tip = sim.state.u[3 * t + 1];
    // It settles where the static solve says it should.
    let m = model(
        beam([10, 2, 2]),
        MaterialModel::StableNeoHookean,
        1e7,
        [0.0, -9.81, 0.0],
        vec![],
    );
    let time = static_frame();
    let mut stat = Simulator::new(m, time, solver(SolverMethod::Newton, 1e-10)).unwrap();
    stat.step().unwrap();
    let static_tip = stat.state.u[3 * t + 1];
    assert!(static_tip < -0.01, "{static_tip}");
    assert!(
        (dynamic_tip - static_tip).abs() < 1e-6 * static_tip.abs(),
        "dynamic {dynamic_tip} vs static {static_tip}"
    );
}

#[test]
fn newton_and_lbfgs_give_the_same_trajectory() {
    let mesh = beam([8, 2, 2]);
    let spring = ExternalForce {
        kind: ForceKind::Spring,
        vertices: vec![tip(&mesh)],
        stiffness: 500.0,
        keyframes: vec![[0.0, 0.0, 0.0, 0.0], [0.1, 0.0, 0.1, 0.05]],
        start: 0.0,
        end: 0.15,
    };
    const STEPS: usize = 40;
    let mut runs = Vec::new();
    for (method, preconditioner) in [
        (SolverMethod::Newton, LbfgsPreconditioner::default()),
        (SolverMethod::Lbfgs, LbfgsPreconditioner::Rest),
        (SolverMethod::Lbfgs, LbfgsPreconditioner::CurrentState),
    ] {
        let m = model(
            mesh.clone(),
            MaterialModel::StableNeoHookean,
            1e5,
            [0.0, -9.81, 0.0],
            vec![spring.clone()],
        );
        let cfg = SolverConfig {
            preconditioner,
            ..solver(method, 1e-10)
        };
        let mut sim = Simulator::new(m, dynamic(STEPS), cfg).unwrap();
        let mut iters = 0;
        for _ in 0..STEPS {
            iters += sim.step().unwrap().iterations;
        }
        runs.push((sim.state.u.clone(), iters, sim.lbfgs_factorizations()));
    }
    let a = &runs[0].0;
    let size = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!(size > 1e-3);
    for (b, iters, _) in &runs[1..] {
        let diff = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            diff < 1e-6 * size,
            "Newton and L-BFGS differ by {:.2e}",
            diff / size
        );
        assert!(
            *iters > runs[0].1,
            "L-BFGS should take more (cheaper) iterations"
        );
    }
    // The rest-state factor is made once; the current-state one is refreshed as the beam swings
    // (at least every PRECOND_MAX_AGE steps) but serves several steps each time.
    assert_eq!(runs[1].2, 1);
    let current = runs[2].2;
    assert!(
        (STEPS / PRECOND_MAX_AGE..=STEPS / 2).contains(&current),
        "{current} current-state factorisations in {STEPS} steps"
    );
    // Following the curvature, it needs fewer iterations than the rest-state factor.
    assert!(
        runs[2].1 < runs[1].1,
        "iterations: current-state {} vs rest {}",
        runs[2].1,
        runs[1].1
    );
}

#[test]
fn quasi_static_bends_a_beam_by_half_its_length() {
    let mesh = beam([20, 2, 2]);
    let t = tip(&mesh);
    // Soft enough that gravity bends the tip down by more than half the length.
    let m = model(
        mesh,
        MaterialModel::StableNeoHookean,
        2e5,
        [0.0, -9.81, 0.0],
        vec![],
    );
    let time = static_frame();
    let mut sim = Simulator::new(m, time, solver(SolverMethod::Newton, 1e-8)).unwrap();
    let r = sim.step().unwrap();
    let drop = -sim.state.u[3 * t + 1];
    assert!(drop > 0.5, "tip dropped only {drop}");
    assert!(r.relative_gradient <= 1e-8, "{r:?}");
    assert!(r.elastic_energy > 0.0 && r.elastic_energy.is_finite());
}

#[test]
fn quasi_static_newton_and_lbfgs_find_the_same_equilibrium() {
    let mesh = beam([12, 2, 2]);
    let t = tip(&mesh);
    let time = static_frame();
    let mut tips = Vec::new();
    for method in [SolverMethod::Newton, SolverMethod::Lbfgs] {
        let m = model(
            mesh.clone(),
            MaterialModel::StableNeoHookean,
            5e6,
            [0.0, -9.81, 0.0],
            vec![],
        );
        let cfg = SolverConfig {
            max_iterations: 2000,
            ..solver(method, 1e-9)
        };
        let mut sim = Simulator::new(m, time.clone(), cfg).unwrap();
        sim.step().unwrap();
        tips.push(sim.state.u[3 * t + 1]);
    }
    assert!(tips[0] < -0.01, "{tips:?}");
    assert!((tips[0] - tips[1]).abs() < 1e-6 * tips[0].abs(), "{tips:?}");
}

#[test]
fn classic_neo_hookean_reports_an_inverted_start_instead_of_garbage() {
    let mesh = beam([4, 1, 1]);
    let m = model(mesh, MaterialModel::NeoHookean, 1e5, [0.0; 3], vec![]);
    let mut sim = Simulator::new(m, dynamic(1), solver(SolverMethod::Newton, 1e-8)).unwrap();
    // Push one free vertex through the opposite face of its tets.
    let v = sim.model.mesh.num_vertices() - 1;
    sim.state.u[3 * v] = -0.6;
    match sim.step() {
        Err(FemError::InvertedElement { material, .. }) => assert_eq!(material, "neo-hookean"),
        other => panic!("expected an inverted-element error, got {other:?}"),
    }
}

#[test]
fn springs_pull_their_patch_toward_the_target() {
    let mesh = beam([8, 2, 2]);
    let t = tip(&mesh);
    let spring = ExternalForce {
        kind: ForceKind::Spring,
        vertices: vec![t],
        stiffness: 1e4,
        keyframes: vec![[0.0, 0.0, 0.2, 0.0]],
        start: 0.0,
        end: f64::INFINITY,
    };
    let m = model(
        mesh,
        MaterialModel::StableNeoHookean,
        1e5,
        [0.0; 3],
        vec![spring],
    );
    let time = static_frame();
    let mut sim = Simulator::new(m, time, solver(SolverMethod::Newton, 1e-10)).unwrap();
    sim.step().unwrap();
    let up = sim.state.u[3 * t + 1];
    assert!(up > 0.0 && up < 0.2, "{up}");
}

#[test]
fn quasi_static_without_support_is_a_clear_error() {
    let mesh = beam([4, 1, 1]);
    let material = MaterialConfig::default();
    let m =
        FullSpaceModel::new(mesh, &material, vec![], Vec3::new(0.0, -9.81, 0.0), vec![]).unwrap();
    let time = static_frame();
    let err = Simulator::new(m, time, SolverConfig::default()).unwrap_err();
    assert!(err.to_string().contains("pin"), "{err}");
}

/// The AutoDef dinosaur, feet pinned, soft enough (E = 5e4) that training schedule 17 of the
/// pull-and-poke family (seed 1, the default before drags joined it) topples the body about its feet, 0.48 m at the head. Newton with
/// projected Hessians crawls through that rotation (relative gradient stuck at 0.2 after 100
/// iterations at step 58), L-BFGS does not: a failed step is redone with the other solver, so
/// a scene that names either one completes the schedule.
#[test]
fn a_step_where_newton_crawls_is_redone_with_lbfgs() {
    let Some(shared) =
        super::shared_dir("the dinosaur step Newton cannot finish (needs the AutoDef mesh)")
    else {
        return;
    };
    let (mesh, _) = fem_core::io::read_mesh(&shared.join("meshes/25cm_dino_low.mesh")).unwrap();
    let pinned = VertexSelection::plane(Axis::Y, Side::Min, Some(0.005))
        .select(&mesh, "pin")
        .unwrap();
    let material = MaterialConfig {
        model: MaterialModel::StableNeoHookean,
        youngs_modulus: 5.0e4,
        poisson_ratio: 0.45,
        density: 1000.0,
        ..Default::default()
    };
    let m =
        FullSpaceModel::new(mesh, &material, pinned, Vec3::new(0.0, -9.81, 0.0), vec![]).unwrap();
    use fem_core::snapshots::ScheduleKind;
    let family = fem_core::snapshots::ScheduleConfig {
        kinds: vec![ScheduleKind::Pull, ScheduleKind::Poke],
        patches: fem_core::snapshots::PatchPlacement::Random,
        ..fem_core::snapshots::ScheduleConfig::training()
    };
    let time = dynamic(family.frames_per_schedule);
    let probe =
        fem_core::snapshots::StiffnessProbe::new(&m, family.frames_per_schedule as f64 * time.step)
            .unwrap();
    let forces = family.schedule(&m, &probe, 17, time.step);
    let frames = fem_core::snapshots::simulate_schedule(
        &m,
        forces,
        1.0,
        &time,
        &SolverConfig {
            method: SolverMethod::Newton,
            ..Default::default()
        },
        family.frames_per_schedule,
    )
    .expect("the Newton scene completes the schedule through the L-BFGS retry");
    let largest = frames
        .iter()
        .flat_map(|f| f.chunks(3))
        .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
        .fold(0.0f64, f64::max);
    assert!(
        largest > 0.3,
        "the schedule is the large rotation it was ({largest} m)"
    );
}

/// A 1 m bar of `cells`, 10 cm square, clamped at x = 0, without gravity.
fn clamped_bar(cells: [usize; 3]) -> FullSpaceModel {
    let mesh = box_mesh(&BoxSpec {
        size: [1.0, 0.1, 0.1],
        cells,
        ..Default::default()
    })
    .unwrap();
    let pinned = VertexSelection::plane(Axis::X, Side::Min, None)
        .select(&mesh, "pin")
        .unwrap();
    FullSpaceModel::new(
        mesh,
        &MaterialConfig::default(),
        pinned,
        Vec3::zeros(),
        vec![],
    )
    .unwrap()
}

/// Spread training patches lie closer together near the pins, where a grab's response is
/// local: of 32 on a bar clamped at one end, more grab its fifth next to the clamp than a fifth
/// as long out along it.
#[test]
fn spread_patches_are_denser_near_the_pins() {
    use fem_core::snapshots::{PatchPlacement, ScheduleConfig};
    let m = clamped_bar([40, 3, 3]);
    let family = ScheduleConfig {
        patches: PatchPlacement::Spread,
        ..ScheduleConfig::training()
    };
    let mut xs: Vec<f64> = (0..32)
        .map(|i| {
            let p = family.patch(&m, i).unwrap();
            p.iter().map(|&v| m.mesh.vertices[v].x).sum::<f64>() / p.len() as f64
        })
        .collect();
    xs.sort_by(f64::total_cmp);
    let within = |a: f64, b: f64| xs.iter().filter(|&&x| a <= x && x < b).count();
    let (near, out) = (within(0.0, 0.2), within(0.6, 0.8));
    assert!(
        near > out,
        "{near} patches next to the clamp, {out} out along the bar: {xs:?}"
    );
}

/// Spread training patches cover the surface: on a long bar clamped at one end, the centres of
/// 8 schedules' patches are further apart than 8 random draws', pairwise and from the far end,
/// and the draws of everything else (kind, stiffness, direction) are the same.
#[test]
fn spread_patches_cover_the_surface_and_change_nothing_else() {
    use fem_core::snapshots::{PatchPlacement, ScheduleConfig, StiffnessProbe};
    let m = clamped_bar([20, 2, 2]);
    let h = 0.01;
    let probe = StiffnessProbe::new(&m, 0.6).unwrap();
    let centres = |patches| -> Vec<(Vec3, f64, usize)> {
        let family = ScheduleConfig {
            patches,
            ..ScheduleConfig::training()
        };
        (0..8)
            .map(|i| {
                let f = &family.schedule(&m, &probe, i, h)[0];
                // The patch alone is the schedule's, drawn without the stiffness probe.
                assert_eq!(
                    family.patch(&m, i).as_ref(),
                    Some(&f.vertices),
                    "schedule {i}"
                );
                let c = f.vertices.iter().map(|&v| m.mesh.vertices[v]).sum::<Vec3>()
                    / f.vertices.len() as f64;
                (c, f.keyframes.len() as f64 + f.end, f.vertices.len())
            })
            .collect()
    };
    let (spread, random) = (
        centres(PatchPlacement::Spread),
        centres(PatchPlacement::Random),
    );
    let closest = |c: &[(Vec3, f64, usize)]| {
        let mut d = f64::INFINITY;
        for i in 0..c.len() {
            for j in 0..i {
                d = d.min((c[i].0 - c[j].0).norm());
            }
        }
        d
    };
    assert!(
        closest(&spread) > 2.0 * closest(&random),
        "closest pair: spread {:.3}, random {:.3}",
        closest(&spread),
        closest(&random)
    );
    // Eight patches over a 1 m bar: none of its length is more than a bar-length/8 + the
    // patch's reach from a spread centre.
    let far_end = spread
        .iter()
        .map(|c| 1.0 - c.0.x)
        .fold(f64::INFINITY, f64::min);
    assert!(
        far_end < 0.1,
        "the nearest spread patch is {far_end:.3} m from the free end"
    );
    for (s, r) in spread.iter().zip(&random) {
        assert_eq!(
            s.1, r.1,
            "the schedule's kind and timing must not depend on the placement"
        );
    }
}

/// A training schedule whose full-space solve fails partway ends there, not the family: its
/// earlier frames are kept (the same as a solver that does not fail computes), the set says which
/// schedule stopped and why, and shards merge to the same set.
#[test]
fn a_schedule_whose_solve_fails_keeps_its_earlier_frames() {
    use fem_core::snapshots::{ScheduleConfig, ScheduleKind, generate, simulate_schedule};
    let m = model(
        beam([10, 2, 2]),
        MaterialModel::StableNeoHookean,
        1e5,
        [0.0, -9.81, 0.0],
        vec![],
    );
    // Pulls two to three bar lengths away with a stiff spring, and a cap of 4 iterations (16 in
    // the retry with the other solver): most steps need more.
    let family = ScheduleConfig {
        schedules: 4,
        frames_per_schedule: 30,
        kinds: vec![ScheduleKind::Pull],
        offset: [2.0, 3.0],
        stiffness: [5.0, 10.0],
        tolerance: None,
        ..ScheduleConfig::training()
    };
    let time = dynamic(family.frames_per_schedule);
    let capped = SolverConfig {
        method: SolverMethod::Newton,
        tolerance: 1e-6,
        max_iterations: 4,
        ..Default::default()
    };
    let set = generate(&m, &family, &time, &capped, (0, 1), &|_| {}).unwrap();
    assert_eq!(set.schedules, vec![0, 1, 2, 3]);
    assert!(!set.stopped.is_empty(), "the cap stops some schedule");
    for s in &set.stopped {
        assert!(s.frames < family.frames_per_schedule);
        assert_eq!(set.frames[s.index], s.frames);
        assert!(s.error.contains("did not converge") || s.error.contains("line search"));
    }
    assert_eq!(set.num_frames(), set.frames.iter().sum::<usize>());
    assert_eq!(set.data.len(), set.dim * set.num_frames());

    // The kept frames are the ones a solver without the cap reaches.
    let s = set.stopped.iter().max_by_key(|s| s.frames).unwrap();
    assert!(s.frames > 0, "the test wants a schedule stopped partway");
    let probe =
        fem_core::snapshots::StiffnessProbe::new(&m, family.frames_per_schedule as f64 * time.step)
            .unwrap();
    let whole = simulate_schedule(
        &m,
        family.schedule(&m, &probe, s.index, time.step),
        1.0,
        &time,
        &solver(SolverMethod::Newton, 1e-9),
        family.frames_per_schedule,
    )
    .unwrap();
    let start: usize = set.frames[..s.index].iter().sum();
    for (j, reference) in whole.iter().take(s.frames).enumerate() {
        let kept = set.frame(start + j);
        let scale = reference.iter().map(|v| v * v).sum::<f64>().sqrt();
        let diff = kept
            .iter()
            .zip(reference)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        assert!(
            diff <= 1e-6 * scale.max(1e-12),
            "frame {j} of schedule {}: {diff:e} from the uncapped solve ({scale:e})",
            s.index
        );
    }

    let shards: Vec<_> = (0..2)
        .map(|i| generate(&m, &family, &time, &capped, (i, 2), &|_| {}).unwrap())
        .collect();
    assert_eq!(
        fem_core::snapshots::SnapshotSet::merge(shards).unwrap(),
        set
    );
}

/// `generate_from` starts every fourth schedule from the given state (its grab timed from
/// there) and the others from rest, each the same as a simulator started there by hand.
#[test]
fn every_fourth_schedule_starts_from_the_moving_state_given() {
    use fem_core::snapshots::{MovingStart, ScheduleConfig, generate, generate_from};
    let m = falling_beam();
    // The solver's own tolerance (the family's default would loosen it to 10⁻²).
    let family = ScheduleConfig {
        schedules: 4,
        frames_per_schedule: 10,
        tolerance: None,
        ..ScheduleConfig::training()
    };
    let time = dynamic(family.frames_per_schedule);
    let newton = solver(SolverMethod::Newton, 1e-10);
    let mut fall = Simulator::new(m.clone(), dynamic(7), newton.clone()).unwrap();
    for _ in 0..7 {
        fall.step().unwrap();
    }
    let start = MovingStart {
        u: fall.state.u.clone(),
        v: fall.state.v.clone(),
    };
    let set = generate_from(
        &m,
        &family,
        &time,
        &newton,
        (0, 1),
        Some(&|| Ok(Some(start.clone()))),
        &|_| {},
    )
    .unwrap();
    let rest = generate(&m, &family, &time, &newton, (0, 1), &|_| {}).unwrap();
    let frames = family.frames_per_schedule;
    for s in 0..4 {
        let later = s % fem_core::snapshots::LATER_EVERY == fem_core::snapshots::LATER_EVERY - 1;
        let again = rerun_schedule(
            &m,
            &family,
            s,
            &time,
            &newton,
            m.gravity,
            later.then_some(&start),
        );
        for (f, free) in again.iter().enumerate() {
            let kept = set.frame(s * frames + f);
            let diff = farthest(kept, free);
            assert!(diff <= 1e-9, "schedule {s} frame {f}: {diff:e}");
            let moved = farthest(kept, rest.frame(s * frames + f));
            assert_eq!(moved > 1e-4, later, "schedule {s} frame {f}: {moved:e}");
        }
    }
}

/// The soft 8×2×2 beam of the schedule tests (stable Neo-Hookean, E = 2·10⁴ Pa) under gravity.
fn falling_beam() -> FullSpaceModel {
    model(
        beam([8, 2, 2]),
        MaterialModel::StableNeoHookean,
        2e4,
        [0.0, -9.81, 0.0],
        vec![],
    )
}

/// The largest difference of two vectors' entries.
fn farthest(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Schedule `s` of `family` simulated again on its own, under gravity `g` and from `start`
/// when given: its free-DOF displacement frame by frame.
fn rerun_schedule(
    m: &FullSpaceModel,
    family: &fem_core::snapshots::ScheduleConfig,
    s: usize,
    time: &TimeConfig,
    solver: &SolverConfig,
    g: Vec3,
    start: Option<&fem_core::snapshots::MovingStart>,
) -> Vec<Vec<f64>> {
    let probe =
        fem_core::snapshots::StiffnessProbe::new(m, family.frames_per_schedule as f64 * time.step)
            .unwrap();
    let mut with = m.clone();
    with.forces = family.schedule(m, &probe, s, time.step);
    if g != m.gravity {
        with.set_gravity(g);
    }
    let mut sim = Simulator::new(with, time.clone(), solver.clone()).unwrap();
    if let Some(start) = start {
        sim.state.u.copy_from_slice(&start.u);
        sim.state.v.copy_from_slice(&start.v);
    }
    let mut free = vec![0.0; sim.model.dofs.num_free()];
    (0..family.frames_per_schedule)
        .map(|_| {
            sim.step().unwrap();
            sim.model.dofs.gather(&sim.state.u, &mut free);
            free.clone()
        })
        .collect()
}

/// Under `gravity = "any"` schedules 1 and 2 of every four fall along their own drawn direction
/// at the scene's strength, 0 and 3 (which may start from the body's fall) along the scene's:
/// each is the simulation of its forces under that gravity.
#[test]
fn half_the_schedules_fall_along_their_own_directions_under_any_gravity() {
    use fem_core::snapshots::{GravityDirections, ScheduleConfig, generate};
    let m = falling_beam();
    let family = ScheduleConfig {
        schedules: 4,
        frames_per_schedule: 6,
        tolerance: None,
        gravity: GravityDirections::Any,
        gravity_scale: 0.5,
        ..ScheduleConfig::training()
    };
    let time = dynamic(family.frames_per_schedule);
    let newton = solver(SolverMethod::Newton, 1e-10);
    let set = generate(&m, &family, &time, &newton, (0, 1), &|_| {}).unwrap();
    let mut turned = Vec::new();
    for s in 0..4 {
        let g = family.gravity_of(&m, s);
        assert!((g.norm() - 9.81).abs() < 1e-12, "schedule {s}: {g:?}");
        let along_scene = s % fem_core::snapshots::LATER_EVERY == 0
            || s % fem_core::snapshots::LATER_EVERY == fem_core::snapshots::LATER_EVERY - 1;
        assert_eq!(g == m.gravity, along_scene, "schedule {s}: {g:?}");
        // Drawn from the seed: the same every time.
        assert_eq!(g, family.gravity_of(&m, s));
        if !along_scene {
            turned.push(g);
        }
        let again = rerun_schedule(&m, &family, s, &time, &newton, 0.5 * g, None);
        for (f, free) in again.iter().enumerate() {
            let diff = farthest(set.frame(s * family.frames_per_schedule + f), free);
            assert!(diff <= 1e-9, "schedule {s} frame {f}: {diff:e}");
        }
    }
    assert_ne!(turned[0], turned[1]);
    // Along the scene's, the family is the one it was before the setting.
    let scene = ScheduleConfig {
        gravity: GravityDirections::Scene,
        ..family.clone()
    };
    assert!((0..4).all(|s| scene.gravity_of(&m, s) == m.gravity));
}

/// A step L-BFGS cannot finish within its cap is finished by Newton from where L-BFGS stopped:
/// the trajectory is the one Newton alone computes, and each step's iterations count both.
#[test]
fn a_step_lbfgs_cannot_finish_is_finished_by_newton_from_where_it_stopped() {
    let m = model(
        beam([10, 2, 2]),
        MaterialModel::StableNeoHookean,
        1e5,
        [0.0, -9.81, 0.0],
        vec![],
    );
    let capped = SolverConfig {
        method: SolverMethod::Lbfgs,
        tolerance: 1e-9,
        max_iterations: 2,
        ..Default::default()
    };
    let mut retried = Simulator::new(m.clone(), dynamic(8), capped).unwrap();
    let mut newton = Simulator::new(m, dynamic(8), solver(SolverMethod::Newton, 1e-9)).unwrap();
    let mut more = 0;
    for _ in 0..8 {
        let r = retried.step().unwrap();
        let n = newton.step().unwrap();
        if r.iterations > 2 {
            more += 1;
            // Two L-BFGS iterations, then fewer Newton iterations than from the step's start
            // (3 in all against Newton's 2–3 alone; 4–5 when the retry started over).
            assert!(
                r.iterations < 2 + n.iterations,
                "{} against Newton's {}",
                r.iterations,
                n.iterations
            );
        }
    }
    assert!(more > 0, "the cap makes some step need the retry");
    let scale = newton.state.u.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    assert!(scale > 1e-3, "the beam sags: {scale}");
    for (a, b) in retried.state.u.iter().zip(&newton.state.u) {
        assert!((a - b).abs() <= 1e-6 * scale, "{a} against {b}");
    }
}

/// A step that neither solver finishes, the retry included, is said as both solvers' failure,
/// with every iteration the step spent: "L-BFGS did not converge" alone read as the scene's
/// Newton failing by itself.
#[test]
fn a_step_neither_solver_finishes_names_both() {
    let m = model(
        beam([10, 2, 2]),
        MaterialModel::StableNeoHookean,
        1e5,
        [0.0, -5000.0, 0.0],
        vec![],
    );
    for (method, said) in [
        (
            SolverMethod::Newton,
            "Newton, then L-BFGS from where it stopped did not converge at step 1",
        ),
        (
            SolverMethod::Lbfgs,
            "L-BFGS, then Newton from where it stopped did not converge at step 1",
        ),
    ] {
        let capped = SolverConfig {
            method,
            tolerance: 1e-12,
            max_iterations: 1,
            ..Default::default()
        };
        let mut sim = Simulator::new(m.clone(), dynamic(2), capped).unwrap();
        let e = sim.step().unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with(said), "{text}");
        // One of the first solver's and the retry's four.
        assert!(
            matches!(e, FemError::NotConverged { iterations: 5, .. }),
            "{text}"
        );
    }
}

/// ‖u − x‖ and ‖x‖ over the free DOFs (`free` their full indices, `x` on them).
fn off_free(u: &[f64], free: &[usize], x: &[f64]) -> (f64, f64) {
    let diff = free
        .iter()
        .zip(x)
        .map(|(&d, v)| (u[d] - v).powi(2))
        .sum::<f64>();
    (diff.sqrt(), x.iter().map(|v| v * v).sum::<f64>().sqrt())
}

/// `gravity_onset` is linear implicit Euler from rest: for the linear material the full
/// simulation's first steps are exactly those positions, and an unpinned body falls as
/// u_n = h² g n(n+1)/2 whatever the material.
#[test]
fn gravity_onset_is_the_first_steps_of_a_fall_from_rest() {
    use fem_core::step_norm::gravity_onset;
    let g = [0.0, -9.81, 0.0];
    let m = model(beam([8, 2, 2]), MaterialModel::Linear, 1e5, g, vec![]);
    let onset = gravity_onset(&m, &dynamic(3), 3).unwrap();
    assert_eq!(onset.len(), 3);
    let free = m.dofs.free.clone();
    let mut sim = Simulator::new(m, dynamic(3), solver(SolverMethod::Newton, 1e-12)).unwrap();
    for (n, x) in onset.iter().enumerate() {
        sim.step().unwrap();
        let (diff, size) = off_free(&sim.state.u, &free, x);
        assert!(diff <= 1e-9 * size, "step {}: {diff:e} of {size:e}", n + 1);
    }
    // Held at the pins, the fall is not uniform: near them the body drops less than the free
    // fall h²g·n(n+1)/2 (a third less here), at the far end about that far.
    let free_fall = -(0.01f64.powi(2)) * g[1] * 6.0;
    let drops: Vec<f64> = onset[2].iter().skip(1).step_by(3).map(|v| -v).collect();
    let least = drops.iter().fold(f64::INFINITY, |a, &v| a.min(v));
    let most = drops.iter().fold(0.0f64, |a, &v| a.max(v));
    assert!(
        most - least > 0.2 * free_fall && (most / free_fall - 1.0).abs() < 0.1,
        "{least:e} {most:e} against {free_fall:e}"
    );

    let free_body = free_body(g);
    let time = dynamic(4);
    let onset = gravity_onset(&free_body, &time, 4).unwrap();
    for (n, x) in onset.iter().enumerate() {
        let n = n + 1;
        let expect = time.step * time.step * g[1] * (n * (n + 1)) as f64 / 2.0;
        for (i, &u) in x.iter().enumerate() {
            let want = if i % 3 == 1 { expect } else { 0.0 };
            assert!(
                (u - want).abs() <= 1e-9 * expect.abs(),
                "step {n}, dof {i}: {u}"
            );
        }
    }
    // Quasi-static: one position, the static response (the linear material's static solve);
    // without gravity: none.
    let m = model(beam([8, 2, 2]), MaterialModel::Linear, 1e5, g, vec![]);
    let statics = gravity_onset(&m, &static_frame(), 3).unwrap();
    assert_eq!(statics.len(), 1);
    let free = m.dofs.free.clone();
    let mut sim = Simulator::new(m, static_frame(), solver(SolverMethod::Newton, 1e-12)).unwrap();
    sim.step().unwrap();
    let (diff, size) = off_free(&sim.state.u, &free, &statics[0]);
    assert!(size > 0.0 && diff <= 1e-9 * size, "{diff:e} of {size:e}");
    assert!(
        gravity_onset(&free_body, &static_frame(), 3)
            .unwrap()
            .is_empty()
    );
    let m = model(
        beam([8, 2, 2]),
        MaterialModel::Linear,
        1e5,
        [0.0; 3],
        vec![],
    );
    assert!(gravity_onset(&m, &dynamic(3), 3).unwrap().is_empty());
}

/// A model built in code is refused naming its field for what a file or a scene is checked for
/// on reading: a tet or a pin past the mesh, a force that cannot act (each once a panic in a
/// step or in building the model).
#[test]
fn a_model_built_in_code_is_checked() {
    let material = MaterialConfig::default();
    let mesh = beam([2, 1, 1]);
    let n = mesh.num_vertices();
    let build =
        |mesh: TetMesh, pinned: Vec<usize>, forces: Vec<ExternalForce>| match FullSpaceModel::new(
            mesh,
            &material,
            pinned,
            Vec3::zeros(),
            forces,
        ) {
            Err(FemError::InvalidConfig { field, reason }) => format!("{field}: {reason}"),
            other => panic!("expected an invalid configuration, got {:?}", other.is_ok()),
        };
    let mut torn = mesh.clone();
    torn.tets[1][2] = n;
    assert!(build(torn, vec![0], vec![]).starts_with("mesh.tets: tet 1 names a vertex past"));
    assert!(
        build(mesh.clone(), vec![0, n], vec![]).starts_with(&format!("pin: vertex {n} is past"))
    );
    let force = ExternalForce {
        kind: ForceKind::Point,
        vertices: vec![1],
        stiffness: 0.0,
        keyframes: vec![[0.0, 0.0, 1.0, 0.0]],
        start: f64::NEG_INFINITY,
        end: f64::INFINITY,
    };
    assert!(
        FullSpaceModel::new(
            mesh.clone(),
            &material,
            vec![0],
            Vec3::zeros(),
            vec![force.clone()]
        )
        .is_ok()
    );
    let cases = [
        (
            ExternalForce {
                keyframes: vec![],
                ..force.clone()
            },
            "keyframes must be",
        ),
        (
            ExternalForce {
                vertices: vec![n],
                ..force.clone()
            },
            "past the mesh's",
        ),
        (
            ExternalForce {
                vertices: vec![],
                ..force.clone()
            },
            "acts on no vertex",
        ),
        (
            ExternalForce {
                stiffness: f64::NAN,
                ..force.clone()
            },
            "the stiffness must be finite",
        ),
        (
            ExternalForce {
                start: f64::NAN,
                ..force.clone()
            },
            "start and end must be numbers",
        ),
    ];
    for (bad, said) in cases {
        let e = build(mesh.clone(), vec![0], vec![force.clone(), bad]);
        assert!(e.contains(said) && e.starts_with("force[1]"), "{e}");
    }
}
