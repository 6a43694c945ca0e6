//! `run::sensitivity` against the cached reference: an unchanged state reproduces it exactly, a
//! changed one does not, and the change shows from the frame it was made at.

use std::path::Path;

mod common;
use common::scratch;

use pipeline::pipeline::Pipeline;
use pipeline::run::sensitivity;
use pipeline::scene::Scene;

const SCENE: &str = r#"name = "sensitivity"
[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [5, 1, 1] }
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
[[pin]]
plane = { axis = "x", side = "min", tolerance = 1.0e-6 }
[gravity]
acceleration = [0.0, -9.81, 0.0]
[time]
step = 0.01
[test]
frames_per_schedule = 40
"#;

#[test]
fn an_unchanged_state_reproduces_the_reference_and_a_changed_one_does_not() {
    let scene = Scene::from_str(SCENE, Path::new("."), "sensitivity test").unwrap();
    let cache = scratch("sensitivity");
    let mut p = Pipeline::new(&scene, &cache).unwrap();
    let none = |_: usize, _: usize| {};
    let same = sensitivity(&mut p, 0, 12, 0.0, &none).unwrap();
    assert_eq!((same.mean_error, same.last_error), (0.0, 0.0));
    assert!((same.time - 0.12).abs() < 1e-12, "{}", same.time);
    let changed = sensitivity(&mut p, 0, 12, 0.01, &none).unwrap();
    assert!(
        changed.mean_error > 1e-4 && changed.last_error > 0.0,
        "{changed:?}"
    );
    assert!(
        sensitivity(&mut p, 0, 40, 0.01, &none).is_err(),
        "past the last frame"
    );
    let _ = std::fs::remove_dir_all(&cache);
}
