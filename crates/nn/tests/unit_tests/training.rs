//! Training: it learns a nonlinear manifold far better than linear PCA, is bit-reproducible,
//! stops early with the best weights restored, and searches the latent dimension. A training
//! step is exactly Adam on the loss gradient.

use faer::Mat;
use nn::{Adam, Autoencoder, AutoencoderConfig, NnError, Trainer, train, train_search};

use super::{Rng, manifold_data};

/// Mean squared error per entry of the best rank-r affine (centred PCA) reconstruction of `data`.
fn pca_mse(data: &Mat<f64>, r: usize) -> f64 {
    let (k, n) = (data.nrows(), data.ncols());
    let mean: Vec<f64> = (0..k)
        .map(|i| (0..n).map(|j| data[(i, j)]).sum::<f64>() / n as f64)
        .collect();
    let centred = Mat::from_fn(k, n, |i, j| data[(i, j)] - mean[i]);
    let s = centred.singular_values().unwrap();
    s[r..].iter().map(|s| s * s).sum::<f64>() / (k * n) as f64
}

fn mse(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    (a - b).squared_norm_l2() / (a.nrows() * a.ncols()) as f64
}

#[test]
fn learns_a_nonlinear_manifold_far_better_than_pca() {
    let data = manifold_data(1000, 42);
    let linear = pca_mse(&data, 2);
    let config = AutoencoderConfig {
        hidden: Some(vec![32, 32]),
        epochs: 1000,
        batch_size: 32,
        learning_rate: 3e-3,
        patience: 0,
        seed: 1,
        ..AutoencoderConfig::default()
    };
    let outcome = train(data.as_ref(), 2, &config, |_| {}).unwrap();
    let rec = outcome.model.reconstruct_batch(data.as_ref()).unwrap();
    let nonlinear = mse(&rec, &data);
    assert!(
        nonlinear <= 0.1 * linear,
        "autoencoder MSE {nonlinear:e} is not ≤ 1/10 of rank-2 PCA's {linear:e}"
    );
    // The loss went down by orders of magnitude and the history is complete.
    let h = &outcome.history;
    assert_eq!(h.len(), 1000);
    assert!(h[999].train_loss < 0.05 * h[0].train_loss);
    assert_eq!(outcome.validation_indices.len(), 100);
}

#[test]
fn training_is_bit_reproducible() {
    let data = manifold_data(300, 7);
    let config = AutoencoderConfig {
        hidden: Some(vec![16, 16]),
        epochs: 15,
        batch_size: 100,
        patience: 0,
        seed: 11,
        ..AutoencoderConfig::default()
    };
    let a = train(data.as_ref(), 2, &config, |_| {}).unwrap();
    let b = train(data.as_ref(), 2, &config, |_| {}).unwrap();
    assert_eq!(a.model, b.model);
    assert_eq!(a.history, b.history);
    // The chunked sums do not depend on the number of threads either.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let c = pool.install(|| train(data.as_ref(), 2, &config, |_| {}).unwrap());
    assert_eq!(a.model, c.model);
    // Another seed gives other weights, another split and another history.
    let other = AutoencoderConfig { seed: 12, ..config };
    let d = train(data.as_ref(), 2, &other, |_| {}).unwrap();
    assert_ne!(a.model, d.model);
    assert_ne!(a.validation_indices, d.validation_indices);
    assert_ne!(a.history[14].train_loss, d.history[14].train_loss);
}

/// Restarts train from seeds seed, seed + 1, … on one validation split and keep the network with
/// the lowest monitored loss: the same network, bit for bit, as the best of the restarts trained
/// one at a time; progress counts the epochs of all of them.
#[test]
fn restarts_keep_the_network_with_the_lowest_validation_loss() {
    let data = manifold_data(300, 7);
    let config = AutoencoderConfig {
        hidden: Some(vec![16, 16]),
        epochs: 20,
        batch_size: 50,
        patience: 0,
        seed: 11,
        restarts: 3,
        ..AutoencoderConfig::default()
    };
    let mut epochs_seen = Vec::new();
    let kept = train(data.as_ref(), 2, &config, |r| {
        epochs_seen.push((r.epoch, r.epochs))
    })
    .unwrap();
    assert_eq!(epochs_seen.len(), 60);
    assert_eq!(epochs_seen.last(), Some(&(60, 60)));
    let single = |restart: usize| {
        let mut t = Trainer::for_restart(data.as_ref(), 2, &config, restart).unwrap();
        for _ in 0..config.epochs {
            t.run_epoch().unwrap();
        }
        let (_, loss) = t.best();
        (loss, t.validation_indices().to_vec())
    };
    let runs: Vec<(f64, Vec<usize>)> = (0..3).map(single).collect();
    // One split for all; different networks (different losses).
    assert!(runs.iter().all(|(_, v)| *v == kept.validation_indices));
    assert!(runs[0].0 != runs[1].0 && runs[1].0 != runs[2].0);
    let best = (0..3)
        .min_by(|&a, &b| runs[a].0.total_cmp(&runs[b].0))
        .unwrap();
    assert_eq!(kept.restart, best);
    assert_eq!(kept.best_loss, runs[best].0);
    // Restart 0 is the network one restart trains.
    let one = train(
        data.as_ref(),
        2,
        &AutoencoderConfig {
            restarts: 1,
            ..config.clone()
        },
        |_| {},
    )
    .unwrap();
    assert_eq!(one.best_loss, runs[0].0);
    assert_eq!(one.restart, 0);
    // No restarts is a configuration error naming the field.
    let err = train(
        data.as_ref(),
        2,
        &AutoencoderConfig {
            restarts: 0,
            ..config
        },
        |_| {},
    )
    .unwrap_err();
    assert!(err.to_string().contains("restarts"), "{err}");
}

#[test]
fn early_stopping_restores_the_best_weights() {
    // Noise has no structure to learn: the validation loss stalls while the net memorises.
    let mut rng = Rng::new(3);
    let data = Mat::from_fn(6, 60, |_, _| rng.range(-1.0, 1.0));
    let config = AutoencoderConfig {
        hidden: Some(vec![64]),
        epochs: 3000,
        batch_size: 16,
        learning_rate: 1e-2,
        patience: 20,
        seed: 5,
        // The returned model must be exactly the best epoch's (anchoring would move it).
        anchor_origin: false,
        // A random start, which the first epochs beat (with the skip, PCA's truncation may be
        // the best fit of noise: `training_keeps_its_start_when_no_epoch_beats_it`).
        skip: false,
        ..AutoencoderConfig::default()
    };
    let mut seen = 0;
    let outcome = train(data.as_ref(), 2, &config, |r| {
        seen += 1;
        assert_eq!(r.epoch, seen);
    })
    .unwrap();
    let h = &outcome.history;
    assert!(outcome.stopped_early);
    assert!(h.len() < 3000);
    assert_eq!(seen, h.len());
    assert_eq!(outcome.best_epoch + config.patience, h.len());
    let best = h
        .iter()
        .map(|r| r.validation_loss.unwrap())
        .fold(f64::INFINITY, f64::min);
    assert_eq!(outcome.best_loss, best);
    assert_eq!(h[outcome.best_epoch - 1].validation_loss, Some(best));
    assert!(h[outcome.best_epoch - 1].improved);
    // The returned model is the best epoch's, not the last: its validation loss is the best one.
    let val = Mat::from_fn(6, outcome.validation_indices.len(), |i, j| {
        data[(i, outcome.validation_indices[j])]
    });
    assert_eq!(outcome.model.loss(val.as_ref()).unwrap(), best);
    assert!(h.last().unwrap().validation_loss.unwrap() > best);
    // The split is disjoint and complete.
    let mut all: Vec<usize> = outcome
        .train_indices
        .iter()
        .chain(&outcome.validation_indices)
        .copied()
        .collect();
    all.sort_unstable();
    assert_eq!(all, (0..60).collect::<Vec<_>>());
}

#[test]
fn without_validation_the_training_loss_is_monitored() {
    let data = manifold_data(50, 9);
    let config = AutoencoderConfig {
        hidden: Some(vec![8]),
        epochs: 30,
        batch_size: 10,
        validation_fraction: 0.0,
        patience: 0,
        // The kept weights as trained (anchoring would move them).
        anchor_origin: false,
        ..AutoencoderConfig::default()
    };
    let outcome = train(data.as_ref(), 2, &config, |_| {}).unwrap();
    assert!(outcome.validation_indices.is_empty());
    assert!(outcome.history.iter().all(|r| r.validation_loss.is_none()));
    // The loss kept is the kept weights' own on the whole training set (the epoch's running
    // mean, taken before each step, belongs to the weights the epoch started from).
    assert_eq!(
        outcome.model.loss(data.as_ref()).unwrap(),
        outcome.best_loss
    );
    assert!(outcome.best_epoch > 0);
    let last = outcome.history.last().unwrap().train_loss;
    assert!(outcome.best_loss < last, "{} {last}", outcome.best_loss);
}

#[test]
fn training_keeps_its_start_when_no_epoch_beats_it() {
    // One batch an epoch at a rate far too high: every Adam step leaves PCA's truncation (the
    // skip's start) for something worse, and the start is kept, not the first step's weights.
    let data = manifold_data(40, 4);
    let config = AutoencoderConfig {
        hidden: Some(vec![16]),
        epochs: 12,
        batch_size: 64,
        learning_rate: 0.5,
        validation_fraction: 0.0,
        patience: 0,
        anchor_origin: false,
        ..AutoencoderConfig::default()
    };
    let outcome = train(data.as_ref(), 3, &config, |_| {}).unwrap();
    assert_eq!(outcome.best_epoch, 0);
    assert!(outcome.history.iter().all(|r| !r.improved));
    // The start is the truncation to the first 3 scaled coefficients.
    let start = nn::Autoencoder::with_architecture(
        10,
        3,
        &[16],
        config.activation,
        Some(nn::InputScaling::centre_uniform(data.as_ref())),
        config.seed,
    )
    .unwrap()
    .with_skip()
    .unwrap();
    assert_eq!(
        outcome.model.loss(data.as_ref()).unwrap(),
        start.loss(data.as_ref()).unwrap()
    );
}

#[test]
fn latent_search_stops_at_the_first_dimension_meeting_the_tolerance() {
    let data = manifold_data(80, 1);
    let config = AutoencoderConfig {
        latent_dims: Some([1, 4]),
        max_vertex_error: Some(0.5),
        hidden: Some(vec![8]),
        epochs: 3,
        batch_size: 40,
        ..AutoencoderConfig::default()
    };
    let mut dims_seen = Vec::new();
    let search = train_search(
        data.as_ref(),
        &config,
        |ae| if ae.latent_dim() >= 3 { 0.1 } else { 1.0 },
        |d, r| {
            if r.epoch == 1 {
                dims_seen.push(d)
            }
        },
    )
    .unwrap();
    assert_eq!(dims_seen, vec![1, 2, 3]);
    assert_eq!(search.trials.len(), 3);
    assert!(search.tolerance_met);
    assert_eq!(search.chosen_trial().latent_dim, 3);
    assert_eq!(search.model().latent_dim(), 3);

    // Never met: every dimension is tried and the one with the smallest error is chosen.
    let search = train_search(
        data.as_ref(),
        &config,
        |ae| 10.0 - ae.latent_dim() as f64 * (ae.latent_dim() % 2) as f64,
        |_, _| {},
    )
    .unwrap();
    assert_eq!(search.trials.len(), 4);
    assert!(!search.tolerance_met);
    assert_eq!(search.chosen_trial().latent_dim, 3);
}

#[test]
fn bad_data_is_an_error() {
    let config = AutoencoderConfig {
        epochs: 1,
        ..AutoencoderConfig::default()
    };
    let mut data = manifold_data(20, 2);
    data[(3, 7)] = f64::NAN;
    match train(data.as_ref(), 2, &config, |_| {}) {
        Err(NnError::NonFiniteData {
            feature: 3,
            sample: 7,
            ..
        }) => {}
        other => panic!("{other:?}"),
    }
    let empty = Mat::<f64>::zeros(4, 0);
    assert!(matches!(
        train(empty.as_ref(), 2, &config, |_| {}),
        Err(NnError::EmptyData { .. })
    ));
    let one = Mat::<f64>::zeros(4, 1);
    assert!(matches!(
        train(one.as_ref(), 2, &config, |_| {}),
        Err(NnError::TooFewSamples { .. })
    ));
    let err = train(manifold_data(20, 2).as_ref(), 0, &config, |_| {}).unwrap_err();
    assert!(err.to_string().contains("autoencoder.latent_dim"), "{err}");
    let diverge = AutoencoderConfig {
        learning_rate: 1e300,
        epochs: 50,
        hidden: Some(vec![4]),
        ..AutoencoderConfig::default()
    };
    assert!(matches!(
        train(manifold_data(40, 3).as_ref(), 2, &diverge, |_| {}),
        Err(NnError::Diverged { .. })
    ));
}

/// Adam at a rate of 1e-2 on 150 samples in one batch, no validation split, seed 3.
fn one_batch_config(hidden: Vec<usize>, epochs: usize) -> AutoencoderConfig {
    AutoencoderConfig {
        hidden: Some(hidden),
        epochs,
        batch_size: 150,
        learning_rate: 1e-2,
        validation_fraction: 0.0,
        patience: 0,
        seed: 3,
        // Zero-initialised output layers (the skip) give gradients at rounding level, which
        // Adam's normalisation amplifies: these tests are about updates from real gradients.
        skip: false,
        ..AutoencoderConfig::default()
    }
}

/// |b − a| for every parameter of two networks of the same architecture, in order.
fn parameter_changes(a: &Autoencoder, b: &Autoencoder) -> Vec<f64> {
    let (mut a, mut b) = (a.clone(), b.clone());
    a.parameters_mut()
        .zip(b.parameters_mut())
        .flat_map(|(a, b)| {
            a.iter()
                .zip(b.iter())
                .map(|(a, b)| (b - a).abs())
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn a_training_step_is_adam_on_the_loss_gradient() {
    // 130 × 100 layers (13,000 weights) are split into row blocks for the parallel weight
    // gradient and the fused Adam update; every row must get its own gradient and update.
    let data = manifold_data(150, 4);
    let config = one_batch_config(vec![130, 100], 1);
    let step = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut trainer = Trainer::new(data.as_ref(), 2, &config).unwrap();
            let before = trainer.model().clone();
            trainer.run_epoch().unwrap();
            (before, trainer.model().clone())
        })
    };
    let (before, after) = step(2);
    assert_eq!(after, step(1).1, "one and two threads differ");

    // The same step by hand: the gradient of the loss over all samples (one batch), then Adam.
    let (_, grad) = before.loss_gradient(data.as_ref()).unwrap();
    let mut expected = before.clone();
    let lengths: Vec<usize> = grad.slices().map(<[f64]>::len).collect();
    Adam::new(config.adam(), lengths).step(expected.parameters_mut(), grad.slices());
    let mut after = after;
    let arrays = after.parameters_mut().zip(expected.parameters_mut());
    for (i, (got, want)) in arrays.enumerate() {
        for (j, (g, w)) in got.iter().zip(want.iter()).enumerate() {
            // The batch is shuffled, so its sums are taken in another order: equal to rounding.
            assert!((g - w).abs() <= 1e-12, "array {i} entry {j}: {g} vs {w}");
        }
    }
    // Adam's first step moves every parameter with a nonzero gradient by about the rate.
    let moved = parameter_changes(&before, &after)
        .into_iter()
        .filter(|d| *d > 0.5e-2)
        .count();
    assert!(moved > 20_000, "only {moved} parameters moved");
}

/// The trainer follows the schedule: with a final rate 100 times smaller, the first epoch is the
/// constant-rate one bit for bit, and the last moves the weights about 100 times less.
#[test]
fn the_trainer_follows_the_learning_rate_schedule() {
    let data = manifold_data(150, 4);
    let config = one_batch_config(vec![20, 20], 2);
    let largest_move = |config: &AutoencoderConfig| {
        let mut trainer = Trainer::new(data.as_ref(), 2, config).unwrap();
        trainer.run_epoch().unwrap();
        let first = trainer.model().clone();
        trainer.run_epoch().unwrap();
        let largest = parameter_changes(&first, trainer.model())
            .into_iter()
            .fold(0.0, f64::max);
        (first, largest)
    };
    let (first_constant, constant) = largest_move(&config);
    let decayed = AutoencoderConfig {
        final_learning_rate: Some(1e-4),
        ..config
    };
    let (first_decayed, decayed) = largest_move(&decayed);
    assert_eq!(
        first_constant, first_decayed,
        "the first epoch runs at learning_rate"
    );
    assert!(
        constant > 5e-3 && decayed < 1e-3,
        "largest move in the last epoch: {constant:e} at a constant rate, {decayed:e} decayed"
    );
}

/// With the linear skip on PCA coefficients, training starts exactly at the truncation to the
/// leading d coefficients and ends far below it; with `anchor_origin` the origin round-trips.
#[test]
fn the_skip_starts_at_pca_and_the_origin_is_anchored() {
    let x = manifold_data(600, 8);
    // PCA coefficients: q = Vᵀx for the left singular vectors V (uncentred, as for snapshots).
    let v = x.svd().unwrap().U().to_owned();
    let q = v.transpose() * &x;
    let config = AutoencoderConfig {
        hidden: Some(vec![32, 32]),
        epochs: 1000,
        batch_size: 32,
        learning_rate: 3e-3,
        patience: 0,
        seed: 2,
        input_scaling: false,
        ..AutoencoderConfig::default()
    };
    let start = Trainer::new(q.as_ref(), 2, &config)
        .unwrap()
        .model()
        .clone();
    let rec = start.reconstruct_batch(q.as_ref()).unwrap();
    let truncated = Mat::from_fn(10, 600, |i, j| if i < 2 { q[(i, j)] } else { 0.0 });
    assert_eq!(
        rec, truncated,
        "the skip autoencoder starts as the truncation"
    );
    let pca2 = mse(&truncated, &q);

    let outcome = train(q.as_ref(), 2, &config, |_| {}).unwrap();
    assert!(outcome.model.has_skip());
    let trained = mse(&outcome.model.reconstruct_batch(q.as_ref()).unwrap(), &q);
    assert!(
        trained <= 0.2 * pca2,
        "trained MSE {trained:e} is not ≤ 1/5 of the truncation's {pca2:e}"
    );
    let mut origin = [1.0; 10];
    let mut ws = outcome.model.workspace();
    outcome.model.reconstruct(&[0.0; 10], &mut origin, &mut ws);
    assert!(origin.iter().all(|o| o.abs() <= 1e-13), "{origin:?}");
}

/// With the samples' groups given, the validation split holds out whole groups (about the
/// validation fraction of them, at least one, never all; empty groups skipped); groups that do
/// not add up to the samples fall back to the split of single samples.
#[test]
fn the_validation_split_holds_out_whole_groups() {
    use nn::Trainer;
    let data = manifold_data(40, 3);
    let with = |groups: Vec<usize>, fraction: f64| {
        let config = AutoencoderConfig {
            hidden: Some(vec![8]),
            validation_fraction: fraction,
            validation_groups: groups,
            seed: 5,
            ..AutoencoderConfig::default()
        };
        let t = Trainer::new(data.as_ref(), 2, &config).unwrap();
        (t.train_indices().to_vec(), t.validation_indices().to_vec())
    };
    let (train, val) = with(vec![10, 0, 10, 10, 10], 0.25);
    assert_eq!(val.len(), 10, "{val:?}");
    assert_eq!(val[9] - val[0], 9, "one whole group: {val:?}");
    assert!([0, 10, 20, 30].contains(&val[0]), "{val:?}");
    assert_eq!(train.len() + val.len(), 40);
    assert!(train.iter().all(|i| !val.contains(i)));
    // A fraction that rounds to no group still holds one out; one that rounds to all keeps one.
    assert_eq!(with(vec![20, 20], 0.01).1.len(), 20);
    assert_eq!(with(vec![20, 20], 0.9).1.len(), 20);
    // Groups that do not cover the samples: single samples, as without groups.
    assert_eq!(with(vec![10, 10], 0.25), with(Vec::new(), 0.25));
    assert_eq!(with(Vec::new(), 0.25).1.len(), 10);
}
