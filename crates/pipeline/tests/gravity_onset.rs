//! The `pca` stage's gravity-onset directions: appended where the basis misses how the body
//! starts to fall, not otherwise, and `[pca] gravity_directions` honoured; with them a reduced
//! method follows the first frames of the fall that its basis alone cannot.

use std::path::Path;
use std::sync::Arc;

mod common;
use common::{measure, scratch};

use pca::PcaFit;
use pipeline::pipeline::{Pipeline, StageSummary};
use pipeline::scene::Scene;
use pipeline::simulate::Method;

/// A beam with a basis too small to hold its own fall (`dimension = 3`), no patch responses
/// beside the fall's positions (`tests/pipeline.rs` tests those).
const SCENE: &str = r#"name = "onset"
[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [6, 1, 1] }
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
[[pin]]
plane = { axis = "x", side = "min", tolerance = 1.0e-6 }
[gravity]
acceleration = [0.0, -9.81, 0.0]
[time]
step = 0.01
[training]
schedules = 4
frames_per_schedule = 20
[test]
frames_per_schedule = 12
[pca]
dimension = 3
patch_responses = 0
"#;

/// The `pca` stage's fit of scene `text` in a scratch cache `name`, and the count of gravity
/// directions the pipeline resolves for it.
fn fit_of(text: &str, name: &str) -> (Arc<PcaFit>, usize) {
    let scene = Scene::from_str(text, Path::new("."), name).unwrap();
    let cache = scratch(name);
    let mut p = Pipeline::new(&scene, &cache).unwrap();
    let fit = p.pca(&|_, _| {}).unwrap();
    let _ = std::fs::remove_dir_all(&cache);
    (fit, p.gravity_directions())
}

/// The `pca` method's mean error over the first `n` frames of the test, and the basis size.
fn first_frames(text: &str, name: &str, n: usize) -> (f64, usize, usize, String) {
    let scene = Scene::from_str(text, Path::new("."), name).unwrap();
    let cache = scratch(name);
    let mut p = Pipeline::new(&scene, &cache).unwrap();
    let fit = p.pca(&|_, _| {}).unwrap();
    let row = measure(&mut p, Method::Pca, &cache.join("out"));
    let _ = std::fs::remove_dir_all(&cache);
    let early = row.frame_errors[..n].iter().sum::<f64>() / n as f64;
    (early, fit.basis.k(), fit.appended, fit.summary())
}

#[test]
fn a_basis_that_misses_the_fall_gets_its_directions_and_follows_it() {
    let (with, k, appended, summary) = first_frames(SCENE, "onset-default", 3);
    assert!(appended >= 1, "{summary}");
    assert_eq!(k, 3 + appended);
    assert!(summary.contains("gravity_directions"), "{summary}");
    assert!(
        summary.contains("those columns miss") && summary.contains("% of its first step"),
        "{summary}"
    );
    let off = SCENE.replace("dimension = 3", "dimension = 3\ngravity_directions = 0");
    let (without, k, appended, summary) = first_frames(&off, "onset-off", 3);
    assert_eq!((k, appended), (3, 0), "{summary}");
    assert!(!summary.contains("gravity_directions"), "{summary}");
    // The fall is a shape the three columns miss: with its directions the first frames are
    // followed more than twice as closely (13 against 32 % off when written).
    assert!(
        with < 0.5 * without,
        "first frames {with:.3e} with the directions, {without:.3e} without"
    );
}

#[test]
fn a_basis_that_holds_the_fall_is_left_as_it_is_unless_asked() {
    // Without gravity there is nothing to add, whatever the scene asks for.
    let weightless = SCENE.replace(
        "acceleration = [0.0, -9.81, 0.0]",
        "acceleration = [0.0, 0.0, 0.0]",
    );
    let (fit, count) = fit_of(&weightless, "onset-weightless");
    assert_eq!(count, 0);
    assert_eq!((fit.appended, fit.basis.k()), (0, 3));
    // A basis of 60 columns (of 72 free coordinates) holds this small beam's fall: by default nothing is appended, and
    // a scene that names a count gets its directions all the same.
    let large = SCENE.replace("dimension = 3", "dimension = 60");
    let (fit, _) = fit_of(&large, "onset-large");
    assert_eq!((fit.appended, fit.basis.k()), (0, 60), "{}", fit.summary());
    // The stage's line says how closely the basis holds the fall, below the 1 % that adds it.
    let missed = fit.fall_missed.unwrap();
    assert!(missed < 0.01, "{missed}");
    let line = fit.summary();
    assert!(
        line.contains(&format!(
            "to {:.2} %, no gravity directions added",
            100.0 * missed
        )),
        "{line}"
    );
    let asked = large.replace("dimension = 60", "dimension = 60\ngravity_directions = 2");
    let (fit, _) = fit_of(&asked, "onset-asked");
    assert!(fit.appended >= 1, "{}", fit.summary());
    // Positions the basis holds already are left out, and the line says how many of those asked.
    let scene = Scene::from_str(&asked, Path::new("."), "onset-asked").unwrap();
    let line = fit.summary_in(&scene);
    assert_eq!(
        line.contains("`[pca] gravity_directions` = 2, one left out: under 0.1 % of it"),
        fit.appended == 1,
        "{line}"
    );
    assert!(!line.contains("left out") || fit.appended == 1, "{line}");
}

/// A quasi-static scene has one position of its "fall", the static sag K₀⁻¹f_g: however many
/// are asked for, at most one is appended.
#[test]
fn a_quasi_static_scene_gets_its_static_sag_at_most() {
    let text = SCENE
        .replace("step = 0.01", "step = 0.01\nquasi_static = true")
        .replace("dimension = 3", "dimension = 3\ngravity_directions = 3");
    let (fit, _) = fit_of(&text, "onset-static");
    assert_eq!((fit.appended, fit.basis.k()), (1, 4), "{}", fit.summary());
    // The two positions that were never offered are not said to be left out.
    let scene = Scene::from_str(&text, Path::new("."), "onset-static").unwrap();
    let line = fit.summary_in(&scene);
    assert!(!line.contains("left out"), "{line}");
}

/// The `pca` line says what the rule's next value would keep: a count, the energy it leaves
/// out; the explained-energy rule, the columns one 9 more keeps (the advice of a larger basis
/// names the rule, and a tester asked for its next value).
#[test]
fn the_pca_line_says_what_the_next_value_keeps() {
    let (fit, _) = fit_of(SCENE, "next-count");
    let line = fit.summary();
    assert!(
        line.contains("`[pca] dimension` = 3, holding all but ")
            && line.contains(" of the snapshots' energy"),
        "{line}"
    );
    // Printed with one decimal more than written, counted at the value printed.
    for (f, next) in [("0.999", "0.9999"), ("0.995", "0.9995"), ("0.6", "0.96")] {
        let energy = SCENE.replace("dimension = 3", &format!("explained_energy = {f}"));
        let (fit, _) = fit_of(&energy, &format!("next-energy-{f}"));
        let line = fit.summary();
        let n = fit.energy_dimension(next.parse().unwrap());
        assert!(n >= fit.chosen_k(), "{line}");
        assert!(
            line.contains(&format!(
                "(`[pca] explained_energy` = {f}; one 9 more, {next}, keeps {n})"
            )),
            "{line}"
        );
    }
}
