//! Dimension selection: each rule picks the smallest k meeting its target, checked by brute force.

use faer::Mat;
use pca::{DimensionRule, PcaBasis, PcaConfig, Shortfall};

use super::{Rng, brute_force_max_vertex_error, decaying_snapshots};

#[test]
fn explained_energy_rule_picks_the_smallest_k() {
    let mut rng = Rng::new(100);
    let s = decaying_snapshots(&mut rng, 45, 30, 0.6);
    let mass = rng.mass(45, 3);
    for fraction in [0.3, 0.9, 0.99, 0.999, 0.99999, 1.0 - 1e-9] {
        let fit = PcaBasis::fit(
            s.as_ref(),
            Some(&mass),
            &PcaConfig::by_explained_energy(fraction),
            3,
        )
        .unwrap();
        let k = fit.chosen_k();
        assert!(fit.tolerance_met);
        assert_eq!(fit.rule, DimensionRule::ExplainedEnergy(fraction));
        assert!(fit.max_vertex_error_per_k.is_empty());
        // Independently from the spectrum.
        let sigma = fit.basis.singular_values();
        let total: f64 = sigma.iter().map(|s| s * s).sum();
        let kept = |k: usize| sigma[..k].iter().map(|s| s * s).sum::<f64>() / total;
        assert!(
            kept(k) >= fraction,
            "fraction {fraction}: k = {k} keeps {}",
            kept(k)
        );
        assert!(
            k == 1 || kept(k - 1) < fraction,
            "fraction {fraction}: k − 1 = {} suffices",
            k - 1
        );
        assert_eq!(fit.basis.explained_energy(k), kept(k));
        // The count any fraction would give, from this fit's spectrum.
        assert_eq!(fit.energy_dimension(fraction), k);
    }
}

#[test]
fn explained_energy_rule_is_capped() {
    let mut rng = Rng::new(101);
    let s = decaying_snapshots(&mut rng, 45, 30, 0.6);
    let config = PcaConfig {
        explained_energy: Some(0.999999),
        max_dimension: 3,
        ..PcaConfig::default()
    };
    let fit = PcaBasis::fit(s.as_ref(), None, &config, 3).unwrap();
    assert_eq!(fit.chosen_k(), 3);
    assert!(!fit.tolerance_met);
    // The count the rule asks for, which the cap written back lets it reach.
    let Some(Shortfall::Cap {
        wanted: Some(wanted),
    }) = fit.shortfall()
    else {
        panic!("{:?}", fit.shortfall());
    };
    assert!(wanted > 3, "{wanted}");
    let raised = PcaConfig {
        max_dimension: wanted,
        ..config
    };
    let fit = PcaBasis::fit(s.as_ref(), None, &raised, 3).unwrap();
    assert!(fit.tolerance_met);
    assert_eq!(fit.chosen_k(), wanted);
    assert_eq!(fit.shortfall(), None);
}

#[test]
fn max_vertex_error_rule_picks_the_smallest_k() {
    let mut rng = Rng::new(110);
    let (n, ns) = (60, 40);
    let s = decaying_snapshots(&mut rng, n, ns, 0.7);
    let mass = rng.mass(n, 3);
    // Brute force: the error curve for every k from independent reconstructions.
    let full = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_dimension(40), 3)
        .unwrap()
        .basis;
    let brute: Vec<f64> = (1..=40)
        .map(|k| brute_force_max_vertex_error(&full.truncate(k).unwrap(), s.as_ref(), 3))
        .collect();
    let mut checked = 0;
    for k_target in [1usize, 2, 3, 5, 8, 13, 21] {
        // A tolerance just above the brute-force error at k_target (so k_target or earlier meets it).
        let tolerance = brute[k_target - 1] * (1.0 + 1e-6);
        let expected = brute.iter().position(|&e| e <= tolerance).unwrap() + 1;
        let fit = PcaBasis::fit(
            s.as_ref(),
            Some(&mass),
            &PcaConfig::by_max_vertex_error(tolerance),
            3,
        )
        .unwrap();
        let k = fit.chosen_k();
        assert!(fit.tolerance_met);
        assert_eq!(k, expected, "tolerance {tolerance:e}");
        // Reconstruct with k and k − 1 directly.
        assert!(brute_force_max_vertex_error(&fit.basis, s.as_ref(), 3) <= tolerance);
        if k > 1 {
            let fewer = fit.basis.truncate(k - 1).unwrap();
            assert!(brute_force_max_vertex_error(&fewer, s.as_ref(), 3) > tolerance);
        }
        // The reported curve is the brute-force one.
        assert_eq!(fit.max_vertex_error_per_k.len(), k);
        for (i, (a, b)) in fit.max_vertex_error_per_k.iter().zip(&brute).enumerate() {
            assert!(
                (a - b).abs() <= 1e-9 * b,
                "k = {}: scan {a:e} vs brute force {b:e}",
                i + 1
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 7);
}

#[test]
fn max_group_error_matches_brute_force() {
    let mut rng = Rng::new(120);
    let s = decaying_snapshots(&mut rng, 30, 15, 0.5);
    let mass = rng.mass(30, 3);
    let basis = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_dimension(4), 3)
        .unwrap()
        .basis;
    for group in [1, 3, 5] {
        let a = basis.max_group_error(s.as_ref(), group).unwrap();
        let b = brute_force_max_vertex_error(&basis, s.as_ref(), group);
        assert!((a - b).abs() <= 1e-12 * b, "group {group}: {a} vs {b}");
    }
}

/// The per-k curve of any M-orthonormal basis, appended columns included, is the brute-force
/// one, and the scan stops where `stop` first holds: within one block of columns and one tile of
/// rows, and across several.
#[test]
fn max_group_errors_match_brute_force_per_k() {
    for (seed, n, fitted) in [(121, 45, 6), (122, 600, 18)] {
        let mut rng = Rng::new(seed);
        let s = decaying_snapshots(&mut rng, n, 40, 0.8);
        let mass = rng.mass(n, 3);
        let config = PcaConfig::by_dimension(fitted);
        let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &config, 3).unwrap();
        let extra: Vec<Vec<f64>> = (0..2).map(|_| rng.normal_vec(n)).collect();
        let (basis, _) = fit.basis.extended(&extra, 1e-3).unwrap();
        let k = fitted + 2;
        assert_eq!(basis.k(), k);
        let brute: Vec<f64> = (1..=k)
            .map(|k| brute_force_max_vertex_error(&basis.truncate(k).unwrap(), s.as_ref(), 3))
            .collect();
        let all = basis.max_group_errors(s.as_ref(), 3, |_, _| false).unwrap();
        assert_eq!(all.len(), k);
        for (i, (a, b)) in all.iter().zip(&brute).enumerate() {
            assert!(
                (a - b).abs() <= 1e-9 * b,
                "n = {n}, k = {}: {a:e} vs {b:e}",
                i + 1
            );
        }
        let some = basis
            .max_group_errors(s.as_ref(), 3, |k, _| k == 3)
            .unwrap();
        assert_eq!(some, all[..3]);
        assert!(basis.max_group_errors(s.as_ref(), 7, |_, _| false).is_err());
    }
}

#[test]
fn unmet_tolerance_returns_the_cap() {
    let mut rng = Rng::new(130);
    let s = decaying_snapshots(&mut rng, 30, 20, 0.5);
    let config = PcaConfig {
        max_vertex_error: Some(1e-300),
        max_dimension: 5,
        ..PcaConfig::default()
    };
    let fit = PcaBasis::fit(s.as_ref(), None, &config, 3).unwrap();
    assert_eq!(fit.chosen_k(), 5);
    assert!(!fit.tolerance_met);
    assert_eq!(fit.max_vertex_error_per_k.len(), 5);
    assert!(fit.max_vertex_error_per_k.iter().all(|&e| e > 1e-300));
    // The scan stopped at the cap: how many the tolerance needs is not known.
    assert_eq!(fit.shortfall(), Some(Shortfall::Cap { wanted: None }));
}

#[test]
fn low_rank_data_has_a_zero_tail_and_small_k() {
    let mut rng = Rng::new(140);
    let (n, ns, r) = (90, 50, 4);
    let a = rng.normal_mat(n, r);
    let b = rng.normal_mat(r, ns);
    let s = &a * &b;
    let mass = rng.mass(n, 3);
    let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_dimension(r), 3).unwrap();
    let sigma = fit.basis.singular_values();
    assert_eq!(fit.numerical_rank, r);
    assert!(sigma[r - 1] > 1e-3 * sigma[0]);
    assert!(
        sigma[r..].iter().all(|&x| x < 1e-13 * sigma[0]),
        "{:?}",
        &sigma[r..]
    );

    let scale = s.norm_max();
    let by_error = PcaBasis::fit(
        s.as_ref(),
        Some(&mass),
        &PcaConfig::by_max_vertex_error(1e-10 * scale),
        3,
    )
    .unwrap();
    assert!(by_error.tolerance_met);
    assert!(by_error.chosen_k() <= r, "k = {}", by_error.chosen_k());
    assert!(brute_force_max_vertex_error(&by_error.basis, s.as_ref(), 3) <= 1e-10 * scale);
    // A tolerance below roundoff stops at the rank, under the cap: no cap reaches it.
    let past_rank = PcaBasis::fit(
        s.as_ref(),
        Some(&mass),
        &PcaConfig::by_max_vertex_error(1e-300),
        3,
    )
    .unwrap();
    assert_eq!(past_rank.chosen_k(), r);
    assert_eq!(past_rank.shortfall(), Some(Shortfall::Rank));

    for fraction in [1.0, 1.0 - 1e-12] {
        let by_energy = PcaBasis::fit(
            s.as_ref(),
            Some(&mass),
            &PcaConfig::by_explained_energy(fraction),
            3,
        )
        .unwrap();
        assert_eq!(by_energy.chosen_k(), r, "fraction {fraction}");
        assert!(by_energy.tolerance_met);
    }
}

#[test]
fn a_single_snapshot_gives_one_mode() {
    let s = Mat::from_fn(9, 1, |i, _| (i as f64 - 4.0) * 0.1);
    let fit = PcaBasis::fit(s.as_ref(), None, &PcaConfig::by_max_vertex_error(1e-12), 3).unwrap();
    assert_eq!(fit.chosen_k(), 1);
    assert_eq!(fit.basis.singular_values().len(), 1);
    let expected = s.norm_l2();
    assert!((fit.basis.singular_values()[0] - expected).abs() < 1e-15 * expected);
}
