//! Seeded, reproducible autoencoder training: Adam on the mean squared reconstruction error with
//! shuffled mini-batches, a held-out validation split, early stopping with best-weight restore,
//! and the latent-dimension search.
//!
//! Reproducibility: the seed fixes the initial weights (streams 0 and 1), the validation split
//! (stream 2) and the mini-batch order (stream 3); restart r of `restarts` takes its weights and
//! order from seed + r and its split from the seed. Each mini-batch is cut into fixed chunks of
//! [`crate::CHUNK`] samples evaluated in parallel and summed in chunk order, so the result does
//! not depend on the number of threads either.

use faer::{Mat, MatRef};

use crate::gradient::GradientEngine;
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
    /// The loss the epoch is judged by: the validation loss, or without a split the training
    /// MSE measured again on the weights the epoch ends with.
    #[serde(default)]
    pub monitored_loss: f64,
    /// Whether this epoch set a new best monitored loss: validation if any, else training
    /// measured on the weights the epoch ends with (the weights training starts from are the
    /// candidate to beat).
    pub improved: bool,
}

/// A trained autoencoder with its loss history and data split.
#[derive(Debug, Clone)]
pub struct TrainOutcome {
    /// The weights of the best epoch (by the monitored loss), not necessarily the last.
    pub model: Autoencoder,
    /// One report per epoch run.
    pub history: Vec<EpochReport>,
    /// The 1-based epoch whose weights are in `model`; 0 where no epoch beat the weights
    /// training started from (with the linear skip, PCA's truncation to d), which are kept.
    pub best_epoch: usize,
    /// The monitored loss of `model` (validation loss if there is a split, else training loss),
    /// before the origin is anchored.
    pub best_loss: f64,
    /// True when early stopping ended training before `epochs`.
    pub stopped_early: bool,
    /// Columns of the data used for training, ascending.
    pub train_indices: Vec<usize>,
    /// Columns held out for validation, ascending.
    pub validation_indices: Vec<usize>,
    /// Which of the `restarts` networks this is (0-based: trained from seed `seed + restart`).
    pub restart: usize,
    /// The monitored loss of the weights training started from, epoch 0's candidate (infinite
    /// where it was not finite).
    pub start_loss: f64,
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
    let mut kept: Option<TrainOutcome> = None;
    let total = config.epochs * config.restarts;
    for restart in 0..config.restarts {
        // Progress counts the epochs of all restarts; each outcome keeps its own history.
        let done = restart * config.epochs;
        let outcome = train_one(data, latent_dim, config, restart, |r| {
            progress(EpochReport {
                epoch: done + r.epoch,
                epochs: total,
                ..r
            })
        })?;
        tracing::info!(restart, best_loss = outcome.best_loss, "restart finished");
        if kept
            .as_ref()
            .is_none_or(|k| outcome.best_loss < k.best_loss)
        {
            kept = Some(outcome);
        }
    }
    Ok(kept.expect("validated: restarts ≥ 1"))
}

/// One network of [`train`]: restart `restart` of `config`.
fn train_one(
    data: MatRef<'_, f64>,
    latent_dim: usize,
    config: &AutoencoderConfig,
    restart: usize,
    mut progress: impl FnMut(EpochReport),
) -> Result<TrainOutcome, NnError> {
    let mut trainer = Trainer::for_restart(data, latent_dim, config, restart)?;
    let mut history = Vec::with_capacity(config.epochs.min(4096));
    let mut stopped_early = false;
    for epoch in 1..=config.epochs {
        let report = trainer.run_epoch()?;
        progress(report);
        history.push(report);
        // The clock runs from the best trained epoch, not from the start: a network that
        // leaves the truncation and takes longer than `patience` to come back below it still
        // trains (the start stays the candidate to beat when it stops).
        if config.patience > 0 && epoch - trainer.best_trained_epoch() >= config.patience {
            stopped_early = epoch < config.epochs;
            break;
        }
    }
    let Trainer {
        best,
        train_indices,
        validation_indices,
        start_loss,
        ..
    } = trainer;
    let Best {
        loss: best_loss,
        epoch: best_epoch,
        mut model,
    } = best;
    if config.anchor_origin {
        model.anchor(&vec![0.0; model.input_dim()]);
    }
    tracing::info!(best_epoch, best_loss, stopped_early, "training finished");
    Ok(TrainOutcome {
        model,
        history,
        best_epoch,
        best_loss,
        stopped_early,
        train_indices,
        validation_indices,
        restart,
        start_loss,
    })
}

/// The best weights seen so far by the monitored loss.
#[derive(Debug, Clone)]
struct Best {
    loss: f64,
    epoch: usize,
    model: Autoencoder,
}

/// Adam training of one autoencoder, one epoch at a time: what [`train`] runs, exposed so that a
/// caller (e.g. a benchmark) can step epochs itself.
///
/// [`Trainer::new`] validates the data and configuration, splits off the validation samples,
/// fits the input scaling and initialises the weights; [`Trainer::run_epoch`] makes one shuffled
/// pass of mini-batch Adam steps and evaluates the validation loss. Early stopping is the
/// caller's (see [`train`]); the trainer keeps the best weights by the monitored loss.
#[derive(Debug, Clone)]
pub struct Trainer {
    model: Autoencoder,
    epochs: usize,
    epoch: usize,
    /// The configuration's learning-rate schedule ([`AutoencoderConfig::learning_rate_at`]).
    schedule: AutoencoderConfig,
    engine: GradientEngine,
    adam: Adam,
    rng: SplitMix64,
    order: Vec<usize>,
    buffer: Vec<f64>,
    x_train: Vec<f64>,
    x_val: Vec<f64>,
    batch: usize,
    best: Best,
    /// The lowest monitored loss of the epochs run and its epoch (early stopping's clock).
    best_trained: (f64, usize),
    /// The monitored loss of the weights training started from.
    start_loss: f64,
    train_indices: Vec<usize>,
    validation_indices: Vec<usize>,
}

impl Trainer {
    /// Checks `config` and `data` (k × N, finite), splits, scales and initialises as [`train`]
    /// does (for its first network).
    pub fn new(
        data: MatRef<'_, f64>,
        latent_dim: usize,
        config: &AutoencoderConfig,
    ) -> Result<Self, NnError> {
        Self::for_restart(data, latent_dim, config, 0)
    }

    /// [`Trainer::new`] for network `restart` of [`train`]: the validation split of
    /// `config.seed`, the initial weights and mini-batch order of `config.seed + restart`.
    pub fn for_restart(
        data: MatRef<'_, f64>,
        latent_dim: usize,
        config: &AutoencoderConfig,
        restart: usize,
    ) -> Result<Self, NnError> {
        config.validate()?;
        let init_seed = config.seed.wrapping_add(restart as u64);
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

        let (train_indices, validation_indices) = match config.held_out_groups(n) {
            Some(groups) => split_groups(config.validation_fraction, &groups, config.seed),
            None => split(n, config.validation_fraction, config.seed)?,
        };
        let columns = |idx: &[usize]| Mat::from_fn(k, idx.len(), |i, j| data[(i, idx[j])]);
        let train_data = columns(&train_indices);
        let val_data = columns(&validation_indices);
        let scaling = config
            .input_scaling
            .then(|| InputScaling::centre_uniform(train_data.as_ref()));
        let model = Autoencoder::with_architecture(
            k,
            latent_dim,
            &config.hidden_widths(k),
            config.activation,
            scaling,
            init_seed,
        )?;
        let model = if config.skip {
            model.with_skip()?
        } else {
            model
        };
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
        let adam = Adam::new(config.adam(), lengths);
        tracing::info!(
            k,
            latent_dim,
            n_train,
            n_val,
            parameters = model.encoder().num_parameters() + model.decoder().num_parameters(),
            "training autoencoder"
        );
        // The weights training starts from are epoch 0's candidate: with the linear skip they
        // are PCA's truncation to d, which no epoch may come out worse than unnoticed.
        let start_loss = engine.mean_squared_error(&model, &x_val, &x_train);
        let start_loss = if start_loss.is_finite() {
            start_loss
        } else {
            f64::INFINITY
        };
        Ok(Self {
            best: Best {
                loss: start_loss,
                epoch: 0,
                model: model.clone(),
            },
            best_trained: (f64::INFINITY, 0),
            start_loss,
            model,
            epochs: config.epochs,
            epoch: 0,
            schedule: config.clone(),
            engine,
            adam,
            rng: SplitMix64::for_item(init_seed, 3),
            order: (0..n_train).collect(),
            buffer: vec![0.0; k * batch],
            x_train,
            x_val,
            batch,
            train_indices,
            validation_indices,
        })
    }

    /// One epoch: a shuffled pass of Adam steps over the training samples, then the validation
    /// loss. Updates the best weights when the monitored loss improved.
    ///
    /// # Errors
    /// [`NnError::Diverged`] when a loss is not finite.
    pub fn run_epoch(&mut self) -> Result<EpochReport, NnError> {
        self.epoch += 1;
        let epoch = self.epoch;
        let k = self.model.input_dim();
        let n_train = self.order.len();
        self.rng.shuffle(&mut self.order);
        self.adam
            .set_learning_rate(self.schedule.learning_rate_at(epoch));
        let mut sum = 0.0;
        for ids in self.order.chunks(self.batch) {
            let b = ids.len();
            for (dst, &j) in self.buffer.chunks_exact_mut(k).zip(ids) {
                dst.copy_from_slice(&self.x_train[j * k..(j + 1) * k]);
            }
            sum += self
                .engine
                .run_adam_step(&mut self.model, &mut self.adam, &self.buffer, b);
        }
        let train_loss = sum / (n_train * k) as f64;
        // Without a validation split the training loss is monitored, measured again on the
        // weights the epoch ends with: its running mean is taken before each step, so with one
        // batch an epoch it is the loss of the previous epoch's weights, and the best of those
        // kept the weights one step after it (a tester's 80 poses: 1, 10 and 38 epochs kept
        // the same network, one Adam step off PCA's truncation, 7 times its error).
        let monitored = self
            .engine
            .mean_squared_error(&self.model, &self.x_val, &self.x_train);
        let validation_loss = (!self.x_val.is_empty()).then_some(monitored);
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
        if monitored < self.best_trained.0 {
            self.best_trained = (monitored, epoch);
        }
        let improved = monitored < self.best.loss;
        if improved {
            self.best.loss = monitored;
            self.best.epoch = epoch;
            self.best.model.clone_from(&self.model);
        }
        tracing::debug!(epoch, train_loss, ?validation_loss, "epoch");
        Ok(EpochReport {
            epoch,
            epochs: self.epochs,
            train_loss,
            validation_loss,
            monitored_loss: monitored,
            improved,
        })
    }

    /// The current weights (after the last epoch, not necessarily the best).
    pub fn model(&self) -> &Autoencoder {
        &self.model
    }

    /// The weights of the best epoch so far and its monitored loss.
    pub fn best(&self) -> (&Autoencoder, f64) {
        (&self.best.model, self.best.loss)
    }

    /// The 1-based epoch of [`Trainer::best`] (0 before the first epoch, and where no epoch
    /// beat the start).
    pub fn best_epoch(&self) -> usize {
        self.best.epoch
    }

    /// The 1-based epoch with the lowest monitored loss of those run (0 before the first),
    /// whether or not it beat the start: early stopping's clock.
    pub fn best_trained_epoch(&self) -> usize {
        self.best_trained.1
    }

    /// Epochs run so far.
    pub fn epochs_run(&self) -> usize {
        self.epoch
    }

    /// Columns of the data used for training, ascending.
    pub fn train_indices(&self) -> &[usize] {
        &self.train_indices
    }

    /// Columns held out for validation, ascending.
    pub fn validation_indices(&self) -> &[usize] {
        &self.validation_indices
    }
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

/// The validation split by whole groups of consecutive samples (`groups`: their sizes): about
/// `fraction` of the groups, at least one and never all, drawn by `seed`.
fn split_groups(fraction: f64, groups: &[usize], seed: u64) -> (Vec<usize>, Vec<usize>) {
    let count = groups.len();
    let held = ((fraction * count as f64).round() as usize).clamp(1, count - 1);
    let mut order: Vec<usize> = (0..count).collect();
    SplitMix64::for_item(seed, 2).shuffle(&mut order);
    let mut is_held = vec![false; count];
    for &g in &order[..held] {
        is_held[g] = true;
    }
    let (mut train, mut val) = (Vec::new(), Vec::new());
    let mut start = 0;
    for (&size, &h) in groups.iter().zip(&is_held) {
        let side = if h { &mut val } else { &mut train };
        side.extend(start..start + size);
        start += size;
    }
    (train, val)
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
    if let Some(t) = tolerance {
        tracing::warn!(
            "no latent dimension met `max_vertex_error` = {t:e}; the closest, d = {}, is {:.3e} \
             off",
            trials[chosen].latent_dim,
            trials[chosen].error
        );
    }
    Ok(LatentSearch {
        trials,
        chosen,
        tolerance_met: false,
    })
}
