//! `run::sensitivity` and `run::restart` against the cached reference: an unchanged state
//! reproduces it exactly, a changed one does not, and the change shows from the frame it was made
//! at; a restart from a reduced method measures the full dynamics from its state.

use std::path::Path;

mod common;
use common::{measure, scratch};

use pipeline::pipeline::Pipeline;
use pipeline::run::sensitivity;
use pipeline::scene::Scene;
use pipeline::simulate::Method;

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
    // Started from the reference's state at frame 12, not simulated again to it: the same
    // frames to the solver's tolerance (its starting guesses differ).
    let same = sensitivity(&mut p, 0, 12, 0.0, &none).unwrap();
    assert!(same.mean_error < 1e-6 && same.last_error < 1e-6, "{same:?}");
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

/// The full simulation started from the reference's own frames (the velocity implicit Euler
/// gives them) goes on as the reference did; a reduced method's restart starts from its own
/// error at that frame and compares the method over the same frames.
#[test]
fn a_restart_from_the_references_frames_reproduces_it_and_one_from_a_method_measures_it() {
    let scene = Scene::from_str(SCENE, Path::new("."), "sensitivity test").unwrap();
    let cache = scratch("restart");
    let mut p = Pipeline::new(&scene, &cache).unwrap();
    let none = |_: usize, _: usize| {};
    let reference = p.reference(0, &none).unwrap();
    let model = p.test_model(0).unwrap();
    let full = |free: &[f64]| {
        let mut u = vec![0.0; model.num_full()];
        model.dofs.scatter(free, &mut u);
        u
    };
    // Frame j of the reference is the state after step j + 1.
    let (before, now) = (full(&reference.frames[10]), full(&reference.frames[11]));
    let (mean, last) = pipeline::run::full_from(&mut p, 0, 12, &before, &now, &none).unwrap();
    assert!(mean < 1e-6 && last < 1e-6, "{mean:e} {last:e}");
    // The velocity matters: started at rest from the same displacement, it does not.
    let (mean, _) = pipeline::run::full_from(&mut p, 0, 12, &now, &now, &none).unwrap();
    assert!(mean > 1e-3, "{mean:e}");
    assert!(
        pipeline::run::full_from(&mut p, 0, 12, &now[1..], &now, &none).is_err(),
        "a state of the wrong size"
    );

    let row = measure(&mut p, Method::Pca, &cache.join("out"));
    let r = pipeline::run::restart(&mut p, &row, 0, 12, &none).unwrap();
    // The method run again to frame 12 is where the measured run was: its error there, taken
    // from the state the full simulation starts from, is the measured one to the bit.
    assert_eq!(r.start_error, row.frame_errors[11]);
    assert!(r.start_error > 0.0);
    assert!(r.mean_error > 0.0 && r.mean_error.is_finite(), "{r:?}");
    assert!((r.time - 0.12).abs() < 1e-12);
    let full_row = measure(&mut p, Method::Full, &cache.join("out"));
    assert!(pipeline::run::restart(&mut p, &full_row, 0, 12, &none).is_err());
    assert!(
        pipeline::run::restart(&mut p, &row, 0, 40, &none).is_err(),
        "past the reference's frames"
    );
    let _ = std::fs::remove_dir_all(&cache);
}
