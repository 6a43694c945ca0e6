//! The `pca` stage's static patch responses: appended where the snapshots' basis misses them,
//! `[pca] patch_responses` honoured, and given to the neural methods beside the decoder; with
//! them a basis of two training pulls holds a drag on other patches better than without.

use std::path::Path;

mod common;
use common::{measure, scratch};

use pipeline::pipeline::{Pipeline, StageSummary};
use pipeline::scene::Scene;
use pipeline::simulate::Method;

/// A beam trained on two pulls only, tested with a drag on a patch of its own.
const SCENE: &str = r#"name = "responses"
[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [8, 2, 2] }
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
[[pin]]
plane = { axis = "x", side = "min", tolerance = 1.0e-6 }
[time]
step = 0.01
[training]
schedules = 2
kinds = ["pull"]
frames_per_schedule = 20
[test]
frames_per_schedule = 20
[autoencoder]
latent_dim = 3
epochs = 20
"#;

fn pipeline_of<'a>(scene: &'a Scene, name: &str) -> Pipeline<'a> {
    Pipeline::new(scene, scratch(name)).unwrap()
}

#[test]
fn responses_are_appended_where_the_basis_misses_them() {
    let with = Scene::from_str(SCENE, Path::new("."), "responses").unwrap();
    let off_text = format!("{SCENE}[pca]\npatch_responses = 0\n");
    let without = Scene::from_str(&off_text, Path::new("."), "responses-off").unwrap();
    let mut p = pipeline_of(&with, "responses-on");
    let mut q = pipeline_of(&without, "responses-off");
    let (fit, plain) = (p.pca(&|_, _| {}).unwrap(), q.pca(&|_, _| {}).unwrap());
    assert_eq!(plain.responses, 0);
    assert!(
        !plain.summary().contains("patch_responses"),
        "{}",
        plain.summary()
    );
    // Two pulls leave most patches' responses outside the basis: as many as the cap allows.
    assert_eq!(
        fit.responses,
        plain.basis.k().div_ceil(10),
        "{}",
        fit.summary()
    );
    assert_eq!(fit.basis.k(), plain.basis.k() + fit.responses);
    assert_eq!(fit.chosen_k(), plain.chosen_k());
    // They are the patches' responses in order, each kept where 3 % of it is new.
    let offered = p
        .patch_response_columns(pca::DEFAULT_PATCH_RESPONSES)
        .unwrap();
    assert_eq!(offered.len(), 3 * pca::DEFAULT_PATCH_RESPONSES);
    let (expected, fractions) = plain
        .basis
        .extended_at_most(&offered, 0.03, fit.responses)
        .unwrap();
    assert_eq!(expected, fit.basis);
    assert!(fractions.iter().filter(|&&f| f >= 0.03).count() == fit.responses);
    let line = fit.summary();
    assert!(
        line.contains(&format!("plus {} static response", fit.responses))
            && line.contains(&format!("{} columns in all", fit.basis.k())),
        "{line}"
    );
    // At most a tenth of the columns before them, which the line says when reached.
    let most = (fit.basis.k() - fit.responses).div_ceil(10);
    assert!(fit.responses <= most, "{line}");
    assert_eq!(
        line.contains("the most it takes (a tenth of the columns before them)"),
        fit.responses == most,
        "{line}"
    );
    // The basis stays M-orthonormal with them.
    let (k, mass) = (fit.basis.k(), fit.basis.mass().unwrap());
    for i in 0..k {
        for j in 0..=i {
            let dot: f64 = (fit.basis.column(i).iter())
                .zip(fit.basis.column(j))
                .zip(mass)
                .map(|((a, b), m)| a * b * m)
                .sum();
            let want = if i == j { 1.0 } else { 0.0 };
            assert!((dot - want).abs() < 1e-8, "columns {i}, {j}: {dot}");
        }
    }
    // The neural methods get the response columns first beside the decoder, then the
    // complement directions, orthonormal in q.
    let beside = p.complement_columns(&|_, _| {}).unwrap();
    let c = beside.len() / k;
    assert!(c >= fit.responses);
    for (a, col) in beside.chunks_exact(k).enumerate() {
        if a < fit.responses {
            let j = k - fit.responses + a;
            assert!(
                col.iter()
                    .enumerate()
                    .all(|(i, &x)| x == f64::from(u8::from(i == j)))
            );
        }
        for (b, other) in beside.chunks_exact(k).enumerate().take(a + 1) {
            let dot: f64 = col.iter().zip(other).map(|(x, y)| x * y).sum();
            let want = if a == b { 1.0 } else { 0.0 };
            assert!((dot - want).abs() < 1e-10, "directions {a}, {b}: {dot}");
        }
    }
    assert!(
        p.linear_directions_summary(&|_, _| {})
            .unwrap()
            .contains(&format!(
                "the PCA basis's {} patch responses: at most",
                fit.responses
            ))
    );
    // The test drag grabs a patch the two pulls did not: the basis holds it better with the
    // responses, and so do `pca` and `neural` follow it.
    let out = scratch("responses-out");
    for method in [Method::Pca, Method::Neural] {
        let (on, off) = (measure(&mut p, method, &out), measure(&mut q, method, &out));
        assert!(
            on.subspace_error < 0.8 * off.subspace_error,
            "{method:?}: subspace error {:.3e} with the responses, {:.3e} without",
            on.subspace_error,
            off.subspace_error
        );
        assert!(
            on.mean_rel_error < off.mean_rel_error,
            "{method:?}: {:.3e} with the responses, {:.3e} without",
            on.mean_rel_error,
            off.mean_rel_error
        );
    }
}
