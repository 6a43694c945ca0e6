//! The `[autoencoder]` section of a scene: architecture, training hyper-parameters and how the
//! latent dimension d is chosen.
//!
//! ```toml
//! [autoencoder]
//! latent_dim = 6                 # or: latent_dims = [3, 12] with max_vertex_error = 1e-3
//! # hidden = [200, 200]          # default: two layers as wide as the input, within [64, 200]
//! activation = "elu"             # elu | tanh | softplus | identity | relu (relu: not for simulation)
//! epochs = 1000
//! batch_size = 256
//! learning_rate = 1e-3
//! final_learning_rate = 1e-5     # optional: cosine decay to this over the epochs (default: constant)
//! validation_fraction = 0.1
//! patience = 100                 # epochs without improvement before stopping; 0 = never stop early
//! seed = 0
//! input_scaling = true
//! skip = true                    # linear skip: start as PCA-d, learn the nonlinear correction
//! anchor_origin = true           # decode(encode(0)) = 0 exactly (the rest state)
//! ```

use crate::{Activation, AdamParams, NnError};

/// The latent dimension used when the section names neither `latent_dim` nor `latent_dims`
/// (AutoDef's "X" example).
pub const DEFAULT_LATENT_DIM: usize = 6;

/// The narrowest and widest hidden layer of the default architecture
/// ([`AutoencoderConfig::hidden_widths`]).
pub const DEFAULT_HIDDEN_RANGE: [usize; 2] = [64, 200];

/// The widest hidden layer a scene may ask for: fifty times the default's widest, its weights
/// (width² of them between two such layers) still within memory.
pub const MAX_HIDDEN_WIDTH: usize = 10_000;

/// The most hidden layers a scene may ask for.
pub const MAX_HIDDEN_LAYERS: usize = 64;

/// The most epochs a training may run: far past any network here needs (the defaults stop
/// within a few thousand), and small enough that a report per epoch is a few megabytes.
pub const MAX_EPOCHS: usize = 1_000_000;

/// The most networks one training may train from different seeds.
pub const MAX_RESTARTS: usize = 100;

/// `latent_dims` read with its length checked: a scene's TOML hands serde an array as a tuple
/// and lets it stop at two values, so `[4, 8, 16]` was read as `[4, 8]` without a word (as
/// `fem_core::exact` reads the other sections' lists). Binary formats read as before.
fn two_or_none<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<[usize; 2]>, D::Error> {
    use serde::Deserialize;
    if !d.is_human_readable() {
        return Option::<[usize; 2]>::deserialize(d);
    }
    Option::<Vec<usize>>::deserialize(d)?
        .map(|v| {
            let n = v.len();
            <[usize; 2]>::try_from(v)
                .map_err(|_| serde::de::Error::invalid_length(n, &"a list of 2 values"))
        })
        .transpose()
}

/// One network, the default (left out of the serialised section, so that the stage keys of
/// scenes that do not set it stay what they were).
fn is_one(n: &usize) -> bool {
    *n == 1
}

/// The `[autoencoder]` section of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AutoencoderConfig {
    /// Train exactly this latent dimension.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latent_dim: Option<usize>,
    /// Search d = lo..=hi in order for the smallest whose maximum vertex error is at most
    /// `max_vertex_error` (see [`crate::train_search`]).
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "two_or_none"
    )]
    pub latent_dims: Option<[usize; 2]>,
    /// The tolerance of the `latent_dims` search (absolute, in the data's units, e.g. metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_vertex_error: Option<f64>,
    /// Hidden layer widths of the encoder; the decoder uses them reversed. Absent: two layers as
    /// wide as the input (see [`Self::hidden_widths`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hidden: Option<Vec<usize>>,
    /// The activation of every hidden layer (the latent and output layers are linear).
    pub activation: Activation,
    /// Maximum number of passes over the training data.
    pub epochs: usize,
    /// Samples per Adam step.
    pub batch_size: usize,
    pub learning_rate: f64,
    /// With a value, the learning rate falls from `learning_rate` to this along a half cosine
    /// over the epochs, lr_e = f + ½(lr − f)(1 + cos(π(e − 1)/(epochs − 1))), instead of staying
    /// constant: Adam's late steps stop rattling the weights around the minimum (on the AutoDef
    /// catapult the training loss jumps by 3× between epochs at a constant 1e-3).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_learning_rate: Option<f64>,
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
    /// Fraction of the samples held out (seeded) for validation and early stopping, in [0, 1).
    /// With 0 the training loss is monitored instead.
    pub validation_fraction: f64,
    /// The samples' groups, as the sizes of consecutive runs of columns (e.g. the frames of each
    /// training schedule, in order). When given (at least two groups, summing to the number of
    /// samples), the validation split holds out whole groups, about `validation_fraction` of
    /// them, so that early stopping and the kept weights judge the network on loads it never
    /// saw rather than on frames between ones it did. Set by the caller, not a scene key.
    #[serde(skip)]
    pub validation_groups: Vec<usize>,
    /// Stop after this many epochs without a new best monitored loss; 0 disables early stopping.
    /// The best weights are returned either way.
    pub patience: usize,
    /// Seeds initialisation, the validation split and the mini-batch order.
    pub seed: u64,
    /// Networks to train, from the initial weights and mini-batch orders of seeds `seed`,
    /// `seed + 1`, …, all on the validation split of `seed`; the one with the lowest monitored
    /// loss (validation, else training) is kept. Training outcomes spread (the catapult's
    /// network trained with seeds 0–3 ends 7.9–12.4 % from the full trajectory), and the
    /// validation loss only partly tells them apart: four restarts there (validation losses
    /// 1.04, 0.82, 0.98 and 0.89e-6) keep the second, 11.7 % off against the first's 12.4 %.
    /// Costs `restarts` times the training time; at least 1.
    #[serde(skip_serializing_if = "is_one")]
    pub restarts: usize,
    /// Centre every coefficient on the training data's mean and divide all of them by one common
    /// scale (the RMS of their standard deviations) before the encoder, undone after the decoder
    /// ([`InputScaling::centre_uniform`](crate::InputScaling::centre_uniform)). The common scale
    /// keeps the loss proportional to the mass-weighted displacement error for coefficients of a
    /// mass-orthonormal basis. Stored with the model.
    pub input_scaling: bool,
    /// A linear skip around both networks: z = enc(s) + s₁..d and ŝ = dec(z) + (z, 0), with the
    /// output layers starting at zero, so training starts from the truncation to the leading d
    /// (highest-variance) PCA coefficients and only learns the nonlinear correction
    /// ([`Autoencoder::with_skip`](crate::Autoencoder::with_skip)).
    pub skip: bool,
    /// After training, shift the decoder's output bias so that q = 0 (the rest state, for
    /// displacement coefficients) round-trips exactly
    /// ([`Autoencoder::anchor`](crate::Autoencoder::anchor)): without it a simulation at rest
    /// starts, and small displacements are measured, against a constant offset.
    pub anchor_origin: bool,
}

impl Default for AutoencoderConfig {
    fn default() -> Self {
        let adam = AdamParams::default();
        Self {
            latent_dim: None,
            latent_dims: None,
            max_vertex_error: None,
            hidden: None,
            activation: Activation::Elu,
            epochs: 1000,
            batch_size: 256,
            learning_rate: adam.learning_rate,
            final_learning_rate: None,
            beta1: adam.beta1,
            beta2: adam.beta2,
            epsilon: adam.epsilon,
            validation_fraction: 0.1,
            validation_groups: Vec::new(),
            patience: 100,
            seed: 0,
            restarts: 1,
            input_scaling: true,
            skip: true,
            anchor_origin: true,
        }
    }
}

/// A resolved, validated latent-dimension rule.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LatentRule {
    /// Exactly d.
    Fixed(usize),
    /// The smallest d in lo..=hi whose maximum vertex error is ≤ tolerance.
    Search {
        lo: usize,
        hi: usize,
        tolerance: f64,
    },
}

impl AutoencoderConfig {
    /// The sizes of the groups the validation split holds out whole, for `n` samples: the
    /// non-empty `validation_groups` (an empty one, a schedule whose first step failed, holds no
    /// sample to validate on), when the fraction is positive and at least two of them cover the
    /// samples. None: the split draws single samples.
    pub fn held_out_groups(&self, n: usize) -> Option<Vec<usize>> {
        let groups: Vec<usize> = self
            .validation_groups
            .iter()
            .copied()
            .filter(|&g| g > 0)
            .collect();
        (self.validation_fraction > 0.0 && groups.len() >= 2 && groups.iter().sum::<usize>() == n)
            .then_some(groups)
    }

    /// The hidden layer widths for `input_dim` inputs (the PCA dimension k): `hidden` when
    /// given, else two layers of k clamped to [`DEFAULT_HIDDEN_RANGE`]. The decoder's last hidden
    /// layer then spans the k coefficients it maps to, and no more: the decode and its VJP,
    /// which every reduced L-BFGS iteration runs, cost in proportion to the widths. AutoDef used
    /// [200, 200] and [100, 100]; on four meshes of the suite (k = 50–93) the 64- and 100-wide
    /// networks ended as close to the full trajectory as the 200-wide one (within the spread
    /// of training, ±0.5 points) at a half to a fifth of the decode time.
    pub fn hidden_widths(&self, input_dim: usize) -> Vec<usize> {
        self.hidden.clone().unwrap_or_else(|| {
            let [lo, hi] = DEFAULT_HIDDEN_RANGE;
            vec![input_dim.clamp(lo, hi); 2]
        })
    }

    /// The learning rate of 1-based `epoch`: `learning_rate`, or its cosine decay to
    /// `final_learning_rate` over `epochs`.
    pub fn learning_rate_at(&self, epoch: usize) -> f64 {
        let (lr, Some(f)) = (self.learning_rate, self.final_learning_rate) else {
            return self.learning_rate;
        };
        let t = epoch.saturating_sub(1) as f64 / self.epochs.saturating_sub(1).max(1) as f64;
        f + 0.5 * (lr - f) * (1.0 + (std::f64::consts::PI * t.min(1.0)).cos())
    }

    /// Adam's hyper-parameters from this section.
    pub fn adam(&self) -> AdamParams {
        AdamParams {
            learning_rate: self.learning_rate,
            beta1: self.beta1,
            beta2: self.beta2,
            epsilon: self.epsilon,
        }
    }

    /// Appends one error per invalid field to `errors` (fields named `autoencoder.<field>`).
    pub fn check(&self, errors: &mut Vec<NnError>) {
        let mut bad = |field: &str, reason: String| {
            errors.push(NnError::InvalidConfig {
                field: format!("autoencoder.{field}"),
                reason,
            })
        };
        match (self.latent_dim, self.latent_dims) {
            (Some(_), Some(_)) => bad(
                "latent_dims",
                "give either `latent_dim` or `latent_dims`, not both".into(),
            ),
            (Some(0), None) => bad("latent_dim", "must be at least 1, got 0".into()),
            (None, Some([lo, hi])) if lo == 0 || lo > hi => bad(
                "latent_dims",
                format!("must be a range [lo, hi] with 1 ≤ lo ≤ hi, got [{lo}, {hi}]"),
            ),
            _ => {}
        }
        match (self.latent_dims.is_some(), self.max_vertex_error) {
            (true, None) => bad(
                "max_vertex_error",
                "is required with `latent_dims` (the search tolerance)".into(),
            ),
            (false, Some(_)) => bad(
                "max_vertex_error",
                "is only used with `latent_dims`; remove it or give a range".into(),
            ),
            (true, Some(t)) if !(t.is_finite() && t > 0.0) => bad(
                "max_vertex_error",
                format!("must be positive and finite, got {t}"),
            ),
            _ => {}
        }
        let hidden = self.hidden.as_deref().unwrap_or_default();
        if let Some(i) = hidden.iter().position(|&n| n == 0) {
            bad("hidden", format!("layer {i} has width 0"));
        }
        if let Some((i, n)) = hidden
            .iter()
            .enumerate()
            .find(|&(_, &n)| n > MAX_HIDDEN_WIDTH)
        {
            bad(
                "hidden",
                format!(
                    "layer {i} has width {n}, above {MAX_HIDDEN_WIDTH} (a layer's weights grow \
                     with the square of its width; the default is {} to {})",
                    DEFAULT_HIDDEN_RANGE[0], DEFAULT_HIDDEN_RANGE[1]
                ),
            );
        }
        if hidden.len() > MAX_HIDDEN_LAYERS {
            bad(
                "hidden",
                format!(
                    "{} layers, above {MAX_HIDDEN_LAYERS} (the default is two)",
                    hidden.len()
                ),
            );
        }
        if !(1..=MAX_EPOCHS).contains(&self.epochs) {
            bad(
                "epochs",
                format!(
                    "must be 1 to {MAX_EPOCHS}, got {} (`patience` stops a training early)",
                    self.epochs
                ),
            );
        }
        if self.batch_size == 0 {
            bad("batch_size", "must be at least 1, got 0".into());
        }
        let lr = self.learning_rate;
        if !(lr.is_finite() && lr > 0.0) {
            bad(
                "learning_rate",
                format!("must be positive and finite, got {lr}"),
            );
        }
        if let Some(f) = self.final_learning_rate
            && !(f.is_finite() && f > 0.0 && f <= lr)
        {
            bad(
                "final_learning_rate",
                format!("must be positive and at most learning_rate ({lr}), got {f}"),
            );
        }
        for (field, beta) in [("beta1", self.beta1), ("beta2", self.beta2)] {
            if !(0.0..1.0).contains(&beta) {
                bad(field, format!("must be in [0, 1), got {beta}"));
            }
        }
        let eps = self.epsilon;
        if !(eps.is_finite() && eps > 0.0) {
            bad("epsilon", format!("must be positive and finite, got {eps}"));
        }
        let f = self.validation_fraction;
        if !(0.0..1.0).contains(&f) {
            bad("validation_fraction", format!("must be in [0, 1), got {f}"));
        }
        if !(1..=MAX_RESTARTS).contains(&self.restarts) {
            bad(
                "restarts",
                format!("must be 1 to {MAX_RESTARTS}, got {}", self.restarts),
            );
        }
    }

    /// `Ok` when every field is valid, otherwise the collected errors.
    pub fn validate(&self) -> Result<(), NnError> {
        let mut errors = Vec::new();
        self.check(&mut errors);
        NnError::collect(errors)
    }

    /// The validated latent rule ([`DEFAULT_LATENT_DIM`] when none is given).
    pub fn latent_rule(&self) -> Result<LatentRule, NnError> {
        self.validate()?;
        Ok(
            match (self.latent_dim, self.latent_dims, self.max_vertex_error) {
                (Some(d), _, _) => LatentRule::Fixed(d),
                (None, Some([lo, hi]), Some(tolerance)) => LatentRule::Search { lo, hi, tolerance },
                _ => LatentRule::Fixed(DEFAULT_LATENT_DIM),
            },
        )
    }
}
