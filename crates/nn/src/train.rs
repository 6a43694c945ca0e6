//! Seeded, reproducible autoencoder training: Adam on the mean squared reconstruction error with
//! shuffled mini-batches, a held-out validation split, early stopping with best-weight restore,
//! and the latent-dimension search.
//!
//! Reproducibility: the seed fixes the initial weights (streams 0 and 1), the validation split
//! (stream 2) and the mini-batch order (stream 3). Each mini-batch is cut into fixed chunks of
//! [`crate::CHUNK`] samples evaluated in parallel and summed in chunk order, so the result does
//! not depend on the number of threads either.

use faer::{Mat, MatRef};

use crate::autoencoder::GradientEngine;
use crate::{Adam, Autoencoder, AutoencoderConfig, InputScaling, LatentRule, NnError, SplitMix64};

/// One line of the loss history, passed to the progress callback after every epoch.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpochReport {
    /// 1-based epoch number.
    pub epoch: usize,
    /// The configured maximum number of epochs.
    pub epochs: usize,
    /// Mean over the epoch's mini-batches of the (scaled) MSE, taken before each step (as Keras
    /// reports it).
    pub train_loss: f64,
    /// The (scaled) MSE on the validation split after the epoch; `None` without a split.
    pub validation_loss: Option<f64>,
    /// Whether this epoch set a new best monitored loss (validation if any, else training).
    pub improved: bool,
}

/// A trained autoencoder with its loss history and data split.
#[derive(Debug, Clone)]
pub struct TrainOutcome {
    /// The weights of the best epoch (by the monitored loss), not necessarily the last.
    pub model: Autoencoder,
    /// One report per epoch run.
    pub history: Vec<EpochReport>,
    /// The 1-based epoch whose weights are in `model`.
    pub best_epoch: usize,
    /// The monitored loss of `model` (validation loss if there is a split, else training loss).
    pub best_loss: f64,
    /// True when early stopping ended training before `epochs`.
    pub stopped_early: bool,
    /// Columns of the data used for training, ascending.
    pub train_indices: Vec<usize>,
    /// Columns held out for validation, ascending.
    pub validation_indices: Vec<usize>,
}

/// Trains an autoencoder with latent dimension `latent_dim` on `data` (k × N PCA coefficients, one
/// sample per column) with the hyper-parameters of `config` (its latent rule is ignored here).
/// `progress` is called after every epoch; nothing is printed (logs go to `tracing`).
pub fn train(
    data: MatRef<'_, f64>,
    latent_dim: usize,
    config: &AutoencoderConfig,
    mut progress: impl FnMut(EpochReport),
) -> Result<TrainOutcome, NnError> {
    config.validate()?;
    if latent_dim == 0 {
        return Err(NnError::InvalidConfig {
            field: "autoencoder.latent_dim".into(),
            reason: "must be at least 1, got 0".into(),
        });
    }
    let (k, n) = (data.nrows(), data.ncols());
    if k == 0 || n == 0 {
        return Err(NnError::EmptyData {
            features: k,
            samples: n,
        });
    }
    for j in 0..n {
        for i in 0..k {
            let value = data[(i, j)];
            if !value.is_finite() {
                return Err(NnError::NonFiniteData {
                    feature: i,
                    sample: j,
                    value,
                });
            }
        }
    }
    if !config.activation.is_smooth() {
        tracing::warn!(
            "activation `{}` is not smooth: latent simulation through this decoder sees a \
             discontinuous energy gradient",
            config.activation
        );
    }

    let (train_indices, validation_indices) = split(n, config.validation_fraction, config.seed)?;
    let columns = |idx: &[usize]| Mat::from_fn(k, idx.len(), |i, j| data[(i, idx[j])]);
    let train_data = columns(&train_indices);
    let val_data = columns(&validation_indices);
    let scaling = config
        .input_scaling
        .then(|| InputScaling::centre_uniform(train_data.as_ref()));
    let mut model = Autoencoder::with_architecture(
        k,
        latent_dim,
        &config.hidden,
        config.activation,
        scaling,
        config.seed,
    )?;
    let x_train = model.scaled_block(train_data.as_ref())?;
    let x_val = model.scaled_block(val_data.as_ref())?;
    let (n_train, n_val) = (train_indices.len(), validation_indices.len());

    let batch = config.batch_size.min(n_train);
    let mut engine = GradientEngine::new(&model, batch);
    let lengths: Vec<usize> = model
        .encoder()
        .parameter_lengths()
        .chain(model.decoder().parameter_lengths())
        .collect();
    let mut adam = Adam::new(config.adam(), lengths);
    let mut rng = SplitMix64::for_item(config.seed, 3);
    let mut order: Vec<usize> = (0..n_train).collect();
    let mut buffer = vec![0.0; k * batch];

    tracing::info!(
        k,
        latent_dim,
        n_train,
        n_val,
        parameters = model.encoder().num_parameters() + model.decoder().num_parameters(),
        "training autoencoder"
    );
    let mut history = Vec::with_capacity(config.epochs);
    let mut best = (f64::INFINITY, 0, model.clone());
    let mut stopped_early = false;
    for epoch in 1..=config.epochs {
        rng.shuffle(&mut order);
        let mut sum = 0.0;
        for ids in order.chunks(batch) {
            let b = ids.len();
            for (dst, &j) in buffer.chunks_exact_mut(k).zip(ids) {
                dst.copy_from_slice(&x_train[j * k..(j + 1) * k]);
            }
            sum += engine.run(&model, &buffer[..k * b], b);
            adam.step(model.parameters_mut(), engine.grads[0].slices());
        }
        let train_loss = sum / (n_train * k) as f64;
        let validation_loss =
            (n_val > 0).then(|| model.sum_squared_error(&x_val) / x_val.len() as f64);
        let monitored = validation_loss.unwrap_or(train_loss);
        if !monitored.is_finite() || !train_loss.is_finite() {
            return Err(NnError::Diverged {
                epoch,
                loss: if train_loss.is_finite() {
                    monitored
                } else {
                    train_loss
                },
            });
        }
        let improved = monitored < best.0;
        if improved {
            best = (monitored, epoch, model.clone());
        }
        let report = EpochReport {
            epoch,
            epochs: config.epochs,
            train_loss,
            validation_loss,
            improved,
        };
        tracing::debug!(epoch, train_loss, ?validation_loss, "epoch");
        progress(report);
        history.push(report);
        if config.patience > 0 && epoch - best.1 >= config.patience {
            stopped_early = epoch < config.epochs;
            break;
        }
    }
    let (best_loss, best_epoch, model) = best;
    tracing::info!(best_epoch, best_loss, stopped_early, "training finished");
    Ok(TrainOutcome {
        model,
        history,
        best_epoch,
        best_loss,
        stopped_early,
        train_indices,
        validation_indices,
    })
}

/// Seeded split of 0..n into (training, validation) index lists, both ascending.
fn split(n: usize, fraction: f64, seed: u64) -> Result<(Vec<usize>, Vec<usize>), NnError> {
    let n_val = if fraction > 0.0 {
        if n < 2 {
            return Err(NnError::TooFewSamples {
                samples: n,
                reason: "a validation split needs at least 2 (set validation_fraction = 0)".into(),
            });
        }
        ((fraction * n as f64).round() as usize).clamp(1, n - 1)
    } else {
        0
    };
    let mut perm: Vec<usize> = (0..n).collect();
    SplitMix64::for_item(seed, 2).shuffle(&mut perm);
    let mut val = perm[..n_val].to_vec();
    let mut train = perm[n_val..].to_vec();
    val.sort_unstable();
    train.sort_unstable();
    Ok((train, val))
}

/// One latent dimension tried by [`train_search`].
#[derive(Debug, Clone)]
pub struct LatentTrial {
    pub latent_dim: usize,
    /// What the caller's error function returned for the trained model.
    pub error: f64,
    pub outcome: TrainOutcome,
}

/// The result of [`train_search`]: every trial in order and the chosen one.
#[derive(Debug, Clone)]
pub struct LatentSearch {
    pub trials: Vec<LatentTrial>,
    /// Index into `trials`: the first meeting the tolerance, else the one with the smallest error.
    pub chosen: usize,
    /// Whether the chosen trial meets the tolerance (always true for a fixed `latent_dim`).
    pub tolerance_met: bool,
}

impl LatentSearch {
    pub fn chosen_trial(&self) -> &LatentTrial {
        &self.trials[self.chosen]
    }

    pub fn model(&self) -> &Autoencoder {
        &self.trials[self.chosen].outcome.model
    }
}

/// Trains per the config's latent rule. For `latent_dims = [lo, hi]` it trains d = lo, lo+1, …
/// in order, evaluates `error_fn` (e.g. the maximum per-vertex reconstruction distance through the
/// PCA basis) on each, and stops at the first d whose error is ≤ `max_vertex_error`. For a fixed
/// `latent_dim` it trains once. `progress` receives the latent dimension and each epoch's report.
pub fn train_search(
    data: MatRef<'_, f64>,
    config: &AutoencoderConfig,
    error_fn: impl Fn(&Autoencoder) -> f64,
    mut progress: impl FnMut(usize, EpochReport),
) -> Result<LatentSearch, NnError> {
    let (dims, tolerance) = match config.latent_rule()? {
        LatentRule::Fixed(d) => (d..=d, None),
        LatentRule::Search { lo, hi, tolerance } => (lo..=hi, Some(tolerance)),
    };
    let mut trials: Vec<LatentTrial> = Vec::new();
    for d in dims {
        let outcome = train(data, d, config, |r| progress(d, r))?;
        let error = error_fn(&outcome.model);
        tracing::info!(latent_dim = d, error, "latent dimension tried");
        trials.push(LatentTrial {
            latent_dim: d,
            error,
            outcome,
        });
        match tolerance {
            None => {
                return Ok(LatentSearch {
                    trials,
                    chosen: 0,
                    tolerance_met: true,
                });
            }
            Some(t) if error <= t => {
                let chosen = trials.len() - 1;
                return Ok(LatentSearch {
                    trials,
                    chosen,
                    tolerance_met: true,
                });
            }
            Some(_) => {}
        }
    }
    let chosen = trials
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.error.total_cmp(&b.1.error))
        .map_or(0, |(i, _)| i);
    tracing::warn!(
        tolerance,
        best = trials[chosen].error,
        "no latent dimension met the tolerance"
    );
    Ok(LatentSearch {
        trials,
        chosen,
        tolerance_met: false,
    })
}
