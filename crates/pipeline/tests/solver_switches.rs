//! A full-space step whose solver stops short, finished by the other one, is said: by
//! `simulate --method full` and by `run`'s reference line, whose times include both solvers'
//! work (a `[solver] max_iterations` far too low switched most steps without a word).

use std::path::Path;

mod common;
use common::{scratch, simulate_full};

use pipeline::pipeline::{Pipeline, StageSummary};
use pipeline::scene::Scene;

/// A soft 1 m bar clamped at x = 0, falling under gravity for 6 steps, its full-space L-BFGS
/// capped at `cap` iterations a step (`None`: the default).
fn bar(cap: Option<usize>) -> String {
    let solver = cap.map_or(String::new(), |c| {
        format!("[solver]\nmax_iterations = {c}\n")
    });
    format!(
        r#"name = "capped-bar"
[mesh]
generate = {{ kind = "box", size = [1.0, 0.1, 0.1], cells = [10, 2, 2] }}
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.45
[[pin]]
plane = {{ axis = "x", side = "min" }}
[time]
step = 0.01
frames = 6
{solver}[test]
frames_per_schedule = 6
"#
    )
}

#[test]
fn steps_finished_by_the_other_solver_are_said() {
    let run = |cap: Option<usize>| {
        let scene = Scene::from_str(&bar(cap), Path::new("."), "bar.toml").unwrap();
        let dir = scratch(&format!("switches-{cap:?}"));
        let mut p = Pipeline::new(&scene, &dir).unwrap();
        let (summary, out) = simulate_full(&mut p, &dir);
        let reference = p.reference(0, &|_, _| {}).unwrap();
        (
            summary.describe(&out),
            reference.summary_in(&scene),
            summary.steps.iter().filter(|r| r.solver_switched).count(),
            reference.switched.clone(),
        )
    };
    // Two iterations cannot finish a step of the fall: Newton finishes them.
    let (said, reference_line, switched, reference_switched) = run(Some(2));
    assert!(switched > 0);
    let expected = format!("L-BFGS stopped short of `[solver] tolerance` on {switched} of the 6");
    assert!(said.contains(&expected), "{said}");
    assert!(said.contains("`[solver] max_iterations` = 2"), "{said}");
    assert!(!reference_switched.is_empty());
    assert!(
        reference_line.contains(&format!("on {} of the 6 steps", reference_switched.len())),
        "{reference_line}"
    );
    assert!(
        reference_line.contains(&format!("the first at step {}", reference_switched[0])),
        "{reference_line}"
    );
    // At the default cap L-BFGS finishes every step, and nothing is said.
    let (said, reference_line, switched, reference_switched) = run(None);
    assert_eq!(switched, 0);
    assert!(reference_switched.is_empty());
    assert!(!said.contains("stopped short"), "{said}");
    assert!(
        !reference_line.contains("stopped short"),
        "{reference_line}"
    );
}
