//! What the autoencoder buys over PCA at the same number of coordinates, on training schedules
//! it never saw. Every fifth schedule of a scene's snapshots is held out, from the third on, so
//! that the held-out ones mix schedules from rest with those that start from the body's fall
//! (every fourth, when the snapshots have them). On the others an autoencoder with latent
//! dimension d is trained (the scene's `[autoencoder]` settings, its validation split by
//! schedule included; the train stage then trains again on every schedule, which this leaves
//! out). Its reconstruction of the held-out schedules is put beside PCA's with d components.
//! Both are fitted without the held-out schedules: the scene's basis, which saw them, is
//! turned to the principal directions of the schedules trained on, whose d leading ones are
//! PCA's and the network's linear skip. Errors are relative, in the mass norm the basis is
//! orthonormal in: ‖Q − Q̂‖_F / ‖Q‖_F over the frames.
//!
//! With the epochs its validation judged best printed beside them, this says whether the
//! network learns a correction that carries over to loads it has not seen, or only the
//! truncation its linear skip starts from.
//!
//! ```sh
//! cargo run --release -p pipeline --example autoencoder_gain -- SCENE CACHE [D ...] \
//!     [--epochs N] [--patience N] [--learning-rate X] [--final-learning-rate X] \
//!     [--validation-fraction X] [--train-schedules N]
//! ```
//! The options replace the scene's `[autoencoder]` keys of the same names (`--train-schedules`
//! trains on only the first N schedules not held out). D defaults to k/8, k/4 and k/2. The
//! cache needs the snapshots and PCA stages, which the example computes when they are missing.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use faer::Mat;
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

/// One schedule in this many is held out: not a multiple of
/// [`fem_core::snapshots::LATER_EVERY`], whose schedules differ from the others.
const HOLD_OUT_EVERY: usize = 5;

fn main() -> Result<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    // The options first (each with its value), then the positional arguments that are left.
    let mut option = |name: &str| -> Result<Option<String>> {
        let Some(i) = args.iter().position(|a| a == name) else {
            return Ok(None);
        };
        let value = args
            .get(i + 1)
            .with_context(|| format!("{name} needs a value"))?
            .clone();
        args.drain(i..i + 2);
        Ok(Some(value))
    };
    let count = |name: &str, v: Option<String>| -> Result<Option<usize>> {
        v.map(|v| {
            v.parse()
                .with_context(|| format!("{name} {v}: not a whole number ≥ 0"))
        })
        .transpose()
    };
    let number = |name: &str, v: Option<String>| -> Result<Option<f64>> {
        v.map(|v| {
            v.parse()
                .with_context(|| format!("{name} {v}: not a number"))
        })
        .transpose()
    };
    let epochs = count("--epochs", option("--epochs")?)?;
    let patience = count("--patience", option("--patience")?)?;
    let rate = number("--learning-rate", option("--learning-rate")?)?;
    let final_rate = number("--final-learning-rate", option("--final-learning-rate")?)?;
    let fraction = number("--validation-fraction", option("--validation-fraction")?)?;
    let most = count("--train-schedules", option("--train-schedules")?)?;
    if args.len() < 2 || args.iter().any(|a| a.starts_with("--")) {
        bail!(
            "usage: autoencoder_gain SCENE CACHE [D ...] [--epochs N] [--patience N] \
             [--learning-rate X] [--final-learning-rate X] [--validation-fraction X] \
             [--train-schedules N]"
        );
    }
    let mut scene = Scene::from_file(PathBuf::from(&args[0]))?;
    let ae = &mut scene.autoencoder;
    ae.epochs = epochs.unwrap_or(ae.epochs);
    ae.patience = patience.unwrap_or(ae.patience);
    ae.learning_rate = rate.unwrap_or(ae.learning_rate);
    ae.final_learning_rate = final_rate.or(ae.final_learning_rate);
    ae.validation_fraction = fraction.unwrap_or(ae.validation_fraction);
    // The scene's keys as overridden, checked as the train stage checks them.
    ae.validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", args[0]))?;
    let mut p = Pipeline::new(&scene, PathBuf::from(&args[1]))?;
    let quiet = |_: usize, _: usize| {};
    let snaps = p.snapshots(&quiet)?;
    let fit = p.pca(&quiet)?;
    let basis = &fit.basis;
    let k = basis.k();
    let s = faer::MatRef::from_column_major_slice(&snaps.data, snaps.dim, snaps.num_frames());
    let q = basis.project_matrix(s);
    // Columns of each schedule, held out or not.
    let (mut train, mut held, mut train_groups) = (Vec::new(), Vec::new(), Vec::new());
    let (mut start, mut held_schedules) = (0, 0);
    for (i, &n) in snaps.frames.iter().enumerate() {
        let columns = start..start + n;
        if i % HOLD_OUT_EVERY == 2 {
            held.extend(columns);
            held_schedules += 1;
        } else if most.is_none_or(|m| train_groups.len() < m) {
            train.extend(columns);
            train_groups.push(n);
        }
        start += n;
    }
    if held.is_empty() || train_groups.len() < 2 {
        bail!(
            "{} schedules, {} of them to train on: the example needs one held out and two to \
             train on (`[training] schedules`, `--train-schedules`)",
            snaps.frames.len(),
            train_groups.len()
        );
    }
    // The scene's basis saw the held-out schedules: its coordinates are turned to the principal
    // directions of the schedules trained on, so that PCA's d leading ones and the network's
    // linear skip (which starts from them) are fitted without the held-out schedules, as the
    // pipeline's are without the test. (The turn keeps the mass norm: both are orthonormal.)
    let pick = |cols: &[usize]| Mat::from_fn(k, cols.len(), |i, j| q[(i, cols[j])]);
    let turn = pick(&train)
        .as_ref()
        .thin_svd()
        .map_err(|e| anyhow::anyhow!("SVD of the training coefficients: {e:?}"))?
        .U()
        .to_owned();
    if turn.ncols() < k {
        bail!(
            "{} training frames for k = {k}: too few to fit PCA on them alone",
            train.len()
        );
    }
    let q = turn.transpose() * &q;
    let pick = |cols: &[usize]| Mat::from_fn(k, cols.len(), |i, j| q[(i, cols[j])]);
    let (q_train, q_held) = (pick(&train), pick(&held));
    let dims: Vec<usize> = if args.len() > 2 {
        args[2..]
            .iter()
            .map(|a| a.parse().with_context(|| format!("latent dimension {a}")))
            .collect::<Result<_>>()?
    } else {
        vec![(k / 8).max(2), (k / 4).max(3), k.div_ceil(2)]
    };
    println!(
        "{}: k = {k}, {} schedules, {held_schedules} held out ({} frames), {} trained on; \
         errors relative, mass norm; PCA-d from the schedules trained on",
        scene.name,
        snaps.frames.len(),
        held.len(),
        train_groups.len()
    );
    println!(
        "| d | PCA-d held out | autoencoder held out | PCA-d trained on | autoencoder trained on \
         | best epoch | epochs run |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    for d in dims {
        if d == 0 || d > k {
            bail!("latent dimension {d} is not in 1..={k}");
        }
        let mut cfg = scene.autoencoder.clone();
        cfg.latent_dim = Some(d);
        cfg.latent_dims = None;
        if cfg.validation_fraction > 0.0 {
            cfg.validation_groups = train_groups.clone();
        }
        let outcome = nn::train(q_train.as_ref(), d, &cfg, |_| {})
            .map_err(|e| anyhow::anyhow!("training d = {d}: {e}"))?;
        let ae = |m: &Mat<f64>| -> Result<f64> {
            let r = outcome.model.reconstruct_batch(m.as_ref())?;
            Ok(relative(m, |i, j| r[(i, j)]))
        };
        let pca = |m: &Mat<f64>| relative(m, |i, j| if i < d { m[(i, j)] } else { 0.0 });
        println!(
            "| {d} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {} | {} |",
            pca(&q_held),
            ae(&q_held)?,
            pca(&q_train),
            ae(&q_train)?,
            outcome.best_epoch,
            outcome.history.len()
        );
    }
    Ok(())
}

/// ‖M − R‖_F / ‖M‖_F with R given entry by entry.
fn relative(m: &Mat<f64>, r: impl Fn(usize, usize) -> f64) -> f64 {
    let (mut err, mut norm) = (0.0, 0.0);
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            let x = m[(i, j)];
            err += (x - r(i, j)).powi(2);
            norm += x * x;
        }
    }
    (err / norm.max(f64::MIN_POSITIVE)).sqrt()
}
