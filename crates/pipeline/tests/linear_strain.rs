//! `simulate` under the linear material says when the body goes past small strains, as `run`
//! says it of its reference: the frames are then not the body's motion.

use std::path::Path;

mod common;
use common::{scratch, simulate_full};

use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

/// A 1 m bar of the linear material, clamped at x = 0, under a quasi-static tip load of
/// `load` N across it.
fn bar(load: f64) -> String {
    format!(
        r#"name = "linear-bar"
[mesh]
generate = {{ kind = "box", size = [1.0, 0.1, 0.1], cells = [10, 2, 2] }}
[material]
model = "linear"
youngs_modulus = 1.0e5
poisson_ratio = 0.3
[[pin]]
plane = {{ axis = "x", side = "min" }}
[gravity]
acceleration = [0.0, 0.0, 0.0]
[time]
step = 0.01
frames = 2
quasi_static = true
[[force]]
kind = "point"
select = {{ plane = {{ axis = "x", side = "max" }} }}
keyframes = [[0.0, 0.0, {load}, 0.0]]
"#
    )
}

#[test]
fn a_linear_simulation_past_small_strains_is_said() {
    let run = |load: f64| {
        let scene = Scene::from_str(&bar(load), Path::new("."), "bar.toml").unwrap();
        let dir = scratch(&format!("linear-{load}"));
        let mut p = Pipeline::new(&scene, &dir).unwrap();
        simulate_full(&mut p, &dir).0
    };
    // PL²/2EI ≈ 1.2 rad at the tip: far past small strains.
    let far = run(2.0);
    let (strain, time) = far.linear_strain.expect("the linear material");
    assert!(strain > 0.05, "{strain}");
    assert!(
        (time - 0.01).abs() < 1e-12 || (time - 0.02).abs() < 1e-12,
        "{time}"
    );
    let line = far.linear_warning().expect("past small strains");
    assert!(
        line.contains("past small strains under the linear material"),
        "{line}"
    );
    // A thousandth of the load: a tip rotation of about a milliradian, nothing said.
    let small = run(0.002);
    assert!(small.linear_strain.expect("the linear material").0 < 1e-4);
    assert_eq!(small.linear_warning(), None);
}
