//! Greedy selection on a real mesh: tolerance, element count, held-out error, determinism.

use std::time::Instant;

use cubature::{CubatureConfig, CubatureRule, FitProgress, TrainingMatrix, fit, fit_with_progress};
use faer::Mat;
use fem_core::rng::SplitMix64;

use super::{BeamProblem, beam_problem, normal_mat};

fn fit_beam(p: &BeamProblem, tolerance: f64, seed: u64) -> CubatureRule {
    let config = CubatureConfig {
        tolerance,
        seed,
        ..Default::default()
    };
    let t = Instant::now();
    let rule = fit(&p.train, &config).unwrap();
    let held_out = rule.evaluate(&p.held_out).unwrap();
    println!(
        "tolerance {tolerance}: {} of {} elements, training error {:.4}, held-out error {:.4}, \
         max held-out pose error {:.4}, fit {:.3} s",
        rule.len(),
        p.train.num_elements(),
        rule.training_error,
        held_out,
        rule.pose_errors(&p.held_out)
            .unwrap()
            .into_iter()
            .fold(0.0, f64::max),
        t.elapsed().as_secs_f64()
    );
    rule
}

fn assert_rule_consistent(rule: &CubatureRule, data: &TrainingMatrix) {
    rule.check_elements(data.num_elements()).unwrap();
    assert!(rule.weights.iter().all(|&w| w > 0.0));
    let &(n, e) = rule.error_curve.last().unwrap();
    assert_eq!(n, rule.len());
    assert_eq!(e, rule.training_error);
    let direct = rule.evaluate(data).unwrap();
    assert!(
        (direct - rule.training_error).abs() <= 1e-12,
        "{direct} vs {}",
        rule.training_error
    );
}

#[test]
fn beam_rule_meets_tolerance_and_generalises() {
    let p = beam_problem();
    let m = p.train.num_elements();
    for tolerance in [0.05, 0.02, 0.01] {
        let rule = fit_beam(&p, tolerance, 0);
        assert!(rule.tolerance_met, "tolerance {tolerance} not met");
        assert!(rule.training_error <= tolerance);
        assert_rule_consistent(&rule, &p.train);
        assert!(rule.len() * 10 < m, "{} of {m} elements", rule.len());
        let held_out = rule.evaluate(&p.held_out).unwrap();
        assert!(
            held_out <= 3.0 * tolerance,
            "held-out error {held_out} at tolerance {tolerance}"
        );
    }
}

#[test]
fn same_seed_same_rule_for_any_thread_count() {
    let p = beam_problem();
    let rule = fit_beam(&p, 0.05, 3);
    let again = fit_beam(&p, 0.05, 3);
    assert_eq!(rule, again);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let serial = pool.install(|| fit_beam(&p, 0.05, 3));
    assert_eq!(rule, serial);
    let other = fit_beam(&p, 0.05, 4);
    assert_ne!(rule.elements, other.elements);
}

#[test]
fn element_budget_stops_the_fit() {
    let p = beam_problem();
    let config = CubatureConfig {
        tolerance: 1e-6,
        max_elements: 5,
        ..Default::default()
    };
    let mut reports: Vec<(usize, f64, usize)> = Vec::new();
    let rule = fit_with_progress(&p.train, &config, &mut |r: &FitProgress<'_>| {
        assert_eq!(r.selected.len(), r.elements);
        assert_eq!(r.weights.len(), r.elements);
        reports.push((r.elements, r.relative_error, r.budget));
    })
    .unwrap();
    assert_eq!(rule.len(), 5);
    assert!(!rule.tolerance_met && rule.training_error > 1e-6);
    assert_rule_consistent(&rule, &p.train);
    assert_eq!(reports.len(), rule.error_curve.len());
    for (&r, &(n, e)) in reports.iter().zip(&rule.error_curve) {
        assert_eq!(r, (n, e, 5));
    }
}

/// b is a non-negative combination of 6 of 300 random columns: the greedy finds a rule at a tight
/// tolerance with about that many elements.
#[test]
fn recovers_a_sparse_representable_target() {
    let mut rng = SplitMix64::new(17);
    let (rows, m) = (120, 300);
    let a = normal_mat(&mut rng, rows, m);
    let support = [3, 50, 77, 150, 222, 299];
    let b: Vec<f64> = (0..rows)
        .map(|i| {
            support
                .iter()
                .map(|&j| a[(i, j)] * (1.0 + j as f64 / 100.0))
                .sum()
        })
        .collect();
    let data = TrainingMatrix::from_matrix(a.as_ref(), &b, 1).unwrap();
    let config = CubatureConfig {
        tolerance: 1e-10,
        candidates: m,
        ..Default::default()
    };
    let rule = fit(&data, &config).unwrap();
    assert!(rule.tolerance_met, "{}", rule.training_error);
    assert_eq!(rule.elements, support);
    for (&j, &w) in rule.elements.iter().zip(&rule.weights) {
        assert!((w - (1.0 + j as f64 / 100.0)).abs() < 1e-8, "{j}: {w}");
    }
}

#[test]
fn a_target_no_element_can_approach_stops_cleanly() {
    // Every column points away from b: no positive alignment, so nothing is selected.
    let a = Mat::from_fn(3, 4, |i, j| if i == j % 3 { -1.0 } else { 0.0 });
    let data = TrainingMatrix::from_matrix(a.as_ref(), &[1.0, 1.0, 1.0], 3).unwrap();
    let rule = fit(&data, &CubatureConfig::default()).unwrap();
    assert!(rule.is_empty() && !rule.tolerance_met);
    assert_eq!(rule.training_error, 1.0);
}

/// A dense random problem that needs hundreds of elements: the warm-started, incrementally
/// factored NNLS inside the greedy loop must agree with a cold NNLS solve on the final set.
#[test]
fn greedy_weights_are_the_nnls_optimum_on_the_selected_set() {
    let mut rng = SplitMix64::new(23);
    let (rows, m) = (300, 900);
    let a = normal_mat(&mut rng, rows, m);
    let b: Vec<f64> = (0..rows).map(|i| (0..m).map(|j| a[(i, j)]).sum()).collect();
    let data = TrainingMatrix::from_matrix(a.as_ref(), &b, 3).unwrap();
    let config = CubatureConfig {
        tolerance: 1e-3,
        max_elements: 400,
        ..Default::default()
    };
    let t = Instant::now();
    let rule = fit(&data, &config).unwrap();
    println!(
        "dense problem: {} elements, error {:.2e}, {} steps, fit {:.3} s",
        rule.len(),
        rule.training_error,
        rule.error_curve.len(),
        t.elapsed().as_secs_f64()
    );
    assert!(rule.len() > 100, "{}", rule.len());
    assert_rule_consistent(&rule, &data);
    let a_s = Mat::from_fn(rows, rule.len(), |i, j| a[(i, rule.elements[j])]);
    let cold = cubature::nnls(a_s.as_ref(), &b).unwrap();
    let b_norm = super::norm(&b);
    assert!(
        (cold.residual_norm / b_norm - rule.training_error).abs() <= 1e-9,
        "cold {} vs greedy {}",
        cold.residual_norm / b_norm,
        rule.training_error
    );
    for (j, (&w, &x)) in rule.weights.iter().zip(&cold.x).enumerate() {
        assert!(
            (w - x).abs() <= 1e-6 * (1.0 + x.abs()),
            "weight {j}: {w} vs {x}"
        );
    }
}
