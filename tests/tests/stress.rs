//! The stability stress suite: every method under extreme conditions on a tiny scene, long free
//! runs with the energy checked step by step, and elements forced through inversion.

use std::path::Path;

use fem_core::assembly::{ElementSet, find_inverted};
use fem_core::integrator::Simulator;
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;
use pipeline::simulate::Method;
use pipeline::stress::{Condition, Outcome, stress};
use tests::scratch_dir;

/// The end-to-end scene under its own name.
fn tiny() -> String {
    tests::TINY.replace("name = \"tiny\"", "name = \"stress-tiny\"")
}

const ALL: [Method; 6] = [
    Method::Full,
    Method::FullLbfgs,
    Method::Pca,
    Method::PcaCubature,
    Method::Neural,
    Method::NeuralCubature,
];

fn scene(text: &str) -> Scene {
    Scene::from_str(text, Path::new("."), "stress-tiny.toml").unwrap()
}

fn no_progress(_: usize, _: usize) {}

/// Time steps 1e-4 … 0.1 s, Young's modulus over 4 orders of magnitude, ν = 0.495, forces 3× the
/// training range: no method produces a non-finite or unbounded state; where full space runs,
/// full-space L-BFGS agrees with the reference and the reduced methods' error is reported.
#[test]
fn every_method_survives_every_condition_or_reports_an_error() {
    let s = scene(&tiny());
    let cache = scratch_dir("stress-conditions");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    // `cargo xtask stress`'s conditions; the free run has its own test below.
    let conditions: Vec<Condition> = Condition::defaults(0)
        .into_iter()
        .filter(|c| !matches!(c, Condition::FreeRun(_)))
        .collect();
    let results = stress(&mut p, &ALL, &conditions, 0, &no_progress, &mut |_| {}).unwrap();
    println!("{}", pipeline::stress::markdown(&results));
    assert_eq!(results.len(), ALL.len() * conditions.len());
    for r in &results {
        match &r.outcome {
            Outcome::Diverged { step, reason } => panic!(
                "{} under {} diverged at step {step}: {reason}",
                r.method, r.condition
            ),
            Outcome::Error { message, .. } => assert!(
                !message.is_empty(),
                "{} under {}: an error without a message",
                r.method,
                r.condition
            ),
            Outcome::Ok {
                mean_rel_error,
                max_displacement,
            } => {
                assert!(max_displacement.is_finite());
                if let Some(e) = mean_rel_error {
                    assert!(e.is_finite(), "{} under {}", r.method, r.condition);
                }
            }
        }
        if r.method == Method::FullLbfgs
            && let Outcome::Ok {
                mean_rel_error: Some(e),
                ..
            } = r.outcome
        {
            assert!(
                e < 1e-5,
                "full-space L-BFGS differs from Newton by {e:.2e} under {}",
                r.condition
            );
        }
    }
    // The scene itself must run cleanly with every method.
    for r in results.iter().filter(|r| r.condition == "base") {
        assert!(r.outcome.is_ok(), "{}: {:?}", r.method, r.outcome);
    }
}

/// With L-BFGS as the scene's solver, `full-lbfgs` beside `full` would repeat it: skipped, as
/// `run` skips it, where `full-newton` runs.
#[test]
fn a_method_forcing_the_scenes_own_solver_is_not_repeated() {
    let s = scene(&tiny().replace("method = \"newton\"", "method = \"lbfgs\""));
    assert_eq!(s.solver.method, fem_core::optim::SolverMethod::Lbfgs);
    let cache = scratch_dir("stress-repeat");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let methods = [Method::Full, Method::FullLbfgs, Method::FullNewton];
    let results = stress(
        &mut p,
        &methods,
        &[Condition::Base],
        0,
        &no_progress,
        &mut |_| {},
    )
    .unwrap();
    let ran: Vec<Method> = results.iter().map(|r| r.method).collect();
    assert_eq!(ran, [Method::Full, Method::FullNewton]);
}

/// 10,000 steps: the test drag, then no external force. Implicit Euler is dissipative, so the
/// total energy (elastic + kinetic + gravity) of every method must never rise after the release
/// (beyond the solver tolerance's slack), and the displacement stays bounded.
#[test]
fn long_free_runs_never_gain_energy() {
    let s = scene(&tiny());
    let cache = scratch_dir("stress-free-run");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let results = stress(
        &mut p,
        &ALL,
        &[Condition::FreeRun(10_000)],
        0,
        &no_progress,
        &mut |_| {},
    )
    .unwrap();
    for r in &results {
        assert!(r.outcome.is_ok(), "{}: {:?}", r.method, r.outcome);
    }
}

/// The free run's energy check does not depend on the scene's solver tolerance: with the
/// reduced solves stopped at a loose 5e-2, their energies alone would rise and fall from step to
/// step by more than the check's slack; the free run solves to at most 1e-6 instead.
#[test]
fn a_loose_reduced_tolerance_does_not_fake_an_energy_gain() {
    let s = scene(&format!("{}[reduced]\ntolerance = 5.0e-2\n", tiny()));
    let cache = scratch_dir("stress-free-run-loose");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let results = stress(
        &mut p,
        &[Method::PcaCubature, Method::NeuralCubature],
        &[Condition::FreeRun(2_000)],
        0,
        &no_progress,
        &mut |_| {},
    )
    .unwrap();
    for r in &results {
        assert!(r.outcome.is_ok(), "{}: {:?}", r.method, r.outcome);
    }
}

/// A 20 cm cube on the floor: a spring pulls its top face down through the pinned bottom face
/// (every element inverts), then lets go.
fn inversion_scene(model: &str) -> Scene {
    scene(&format!(
        r#"
name = "inversion"
[mesh]
generate = {{ kind = "box", size = [0.2, 0.2, 0.2], cells = [2, 2, 2] }}
[material]
model = "{model}"
youngs_modulus = 1.0e5
poisson_ratio = 0.4
density = 1000.0
[[pin]]
plane = {{ axis = "y", side = "min" }}
[gravity]
acceleration = [0.0, 0.0, 0.0]
[time]
step = 0.01
frames = 300
[solver]
tolerance = 1.0e-6
[[force]]
kind = "spring"
select = {{ plane = {{ axis = "y", side = "max" }} }}
stiffness = 1.0e6
keyframes = [[0.0, 0.0, 0.0, 0.0], [0.3, 0.0, -0.3, 0.0]]
start = 0.0
end = 0.5
"#
    ))
}

/// Stable Neo-Hookean goes through inversion under the drag and, once released, comes back to
/// its rest shape with no element left inverted.
#[test]
fn stable_neo_hookean_recovers_from_inversion() {
    let s = inversion_scene("stable-neo-hookean");
    let model = s.build_model().unwrap().model;
    let mut sim = Simulator::new(model, s.time.clone(), s.solver.clone()).unwrap();
    let mut inverted_during_drag = false;
    for step in 1..=s.time.frames {
        sim.step()
            .unwrap_or_else(|e| panic!("stable Neo-Hookean failed at step {step}: {e}"));
        assert!(sim.state.u.iter().all(|x| x.is_finite()));
        if sim.state.time <= 0.5 {
            inverted_during_drag |=
                find_inverted(&sim.model.elements, ElementSet::All, &sim.state.u).is_some();
        }
    }
    assert!(
        inverted_during_drag,
        "the drag was meant to invert elements; make it stronger"
    );
    let largest = sim
        .state
        .u
        .chunks_exact(3)
        .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
        .fold(0.0, f64::max);
    assert!(
        largest < 1e-3,
        "2.5 s after the release the largest displacement is still {largest:.3e} m"
    );
    assert!(find_inverted(&sim.model.elements, ElementSet::All, &sim.state.u).is_none());
}

/// Classic Neo-Hookean is undefined for J ≤ 0: the same drag either stays inside its domain
/// (every element un-inverted, every value finite) or stops with a typed error; it never
/// produces an inverted or non-finite state.
#[test]
fn classic_neo_hookean_never_produces_garbage_under_inverting_forces() {
    let s = inversion_scene("neo-hookean");
    let model = s.build_model().unwrap().model;
    let mut sim = Simulator::new(model, s.time.clone(), s.solver.clone()).unwrap();
    // Handed a state with an inverted element, it refuses with an error naming the element.
    let mut inverted = sim.state.u.clone();
    let top = sim
        .model
        .mesh
        .vertices
        .iter()
        .position(|v| v[1] > 0.19)
        .unwrap();
    inverted[3 * top + 1] = -0.4;
    let saved = std::mem::replace(&mut sim.state.u, inverted);
    let e = sim.step().expect_err("an inverted start must be refused");
    assert!(e.to_string().contains("invert"), "{e}");
    sim.state.u = saved;
    for step in 1..=50 {
        match sim.step() {
            Ok(_) => {
                assert!(sim.state.u.iter().all(|x| x.is_finite()), "step {step}");
                assert_eq!(
                    find_inverted(&sim.model.elements, ElementSet::All, &sim.state.u),
                    None,
                    "classic Neo-Hookean accepted an inverted state at step {step}"
                );
            }
            Err(e) => {
                println!("classic Neo-Hookean stopped at step {step}: {e}");
                assert!(!e.to_string().is_empty());
                return;
            }
        }
    }
}

/// A run that fails part-way (an iteration cap too small for the inverting drag) stops with an
/// error naming the method and step, keeps its last good state on disk as the last frame, and
/// never writes the failed one.
#[test]
fn a_failed_run_keeps_its_last_good_frame_and_nothing_after() {
    // No gravity, and a spring that only starts pulling at t = 0.1 s (step 6): the steps before
    // are at rest and converge at once.
    let text = tiny().replace(
        "tolerance = 1.0e-8",
        "tolerance = 1.0e-8\nmax_iterations = 1",
    ) + r#"
[gravity]
acceleration = [0.0, 0.0, 0.0]
[[force]]
kind = "spring"
select = { plane = { axis = "x", side = "max" } }
stiffness = 1.0e5
keyframes = [[0.1, 0.0, 0.0, 0.0], [0.2, 0.0, 1.0, 0.0]]
start = 0.1
end = 1.0
"#;
    let s = scene(&text);
    let cache = scratch_dir("stress-failed-run-cache");
    let out = scratch_dir("stress-failed-run-out");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let opts = pipeline::simulate::SimulateOptions {
        method: Method::Full,
        trajectory: pipeline::simulate::Trajectory::Scene,
        out: out.clone(),
        frames: Some(10),
        every: 4,
        solver: None,
    };
    let e = pipeline::simulate::simulate(&mut p, &opts, &no_progress, &mut |_, _| {})
        .expect_err("one Newton iteration, then four of L-BFGS, cannot reach 1e-8");
    let message = format!("{e:#}");
    println!("{message}");
    assert!(message.contains("full"), "{message}");
    let done: usize = message
        .split("frames up to step ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no step in {message}"));
    let mut written: Vec<usize> = std::fs::read_dir(out.join("frames"))
        .unwrap()
        .filter_map(|e| {
            let name = e.ok()?.file_name().into_string().ok()?;
            name.strip_prefix("frame_")?
                .strip_suffix(".vtu")?
                .parse()
                .ok()
        })
        .collect();
    written.sort_unstable();
    assert!(
        done >= 5,
        "the run should fail once the spring starts, not at step {done}"
    );
    assert_eq!(written.last(), Some(&done), "frames on disk: {written:?}");
    assert!(out.join("series.pvd").exists() && out.join("summary.json").exists());
}
