//! A simulation whose step cannot be solved says what to change: the scene's load that strains
//! the body past its own size, by name, then the step (an advice follower's point load at the
//! scene's limit failed its first step with no word of what to change).

use std::path::Path;

mod common;
use common::{scratch, try_simulate_full};

use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

/// A soft 1 m bar clamped at x = 0 whose free end a point load of `load` N pushes up from the
/// first step, for 3 steps.
fn bar(load: f64) -> String {
    format!(
        r#"name = "pushed-bar"
[mesh]
generate = {{ kind = "box", size = [1.0, 0.1, 0.1], cells = [10, 2, 2] }}
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.45
[[pin]]
plane = {{ axis = "x", side = "min" }}
[time]
step = 0.01
frames = 3
[[force]]
kind = "point"
select = {{ plane = {{ axis = "x", side = "max" }} }}
keyframes = [[0.0, 0.0, {load}, 0.0]]
"#
    )
}

fn simulate_full(load: f64) -> anyhow::Result<()> {
    let scene = Scene::from_str(&bar(load), Path::new("."), "bar.toml").unwrap();
    let dir = scratch(&format!("stopped-{load:e}"));
    let mut p = Pipeline::new(&scene, &dir).unwrap();
    try_simulate_full(&mut p, &dir).map(|_| ())
}

#[test]
fn a_step_that_cannot_be_solved_names_the_load_and_the_step() {
    // 1e11 N against the 1.02e5 N (E times the squared 1.01 m diagonal) that strains the bar by
    // its size: under the scene's limit, and no solver gets through the first step.
    let e = simulate_full(1.0e11).unwrap_err().to_string();
    assert!(
        e.contains("bar.toml: simulation with method full stopped"),
        "{e}"
    );
    assert!(
        e.contains("`force[0]`'s point load reaches 1.000e11 N, 9.8e5 times the 1.020e5 N"),
        "{e}"
    );
    assert!(e.contains("a smaller `[time] step` (now 0.01 s)"), "{e}");
    // A load the bar takes runs through.
    simulate_full(10.0).unwrap();
}
