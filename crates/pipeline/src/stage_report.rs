//! What the single-stage commands (`cargo xtask pca`, `train`, `cubature`) show and write beside
//! a stage's artifact: what it holds, in a few lines, and its curves as CSV and SVG (PCA's
//! spectrum, the autoencoder's loss, cubature's error against its element count).

use std::path::Path;

use anyhow::{Context, Result};
use pca::PcaFit;

use crate::pipeline::{FittedCubature, TrainedModel};
use crate::plot;

/// The leading singular values, the chosen k and the energy it explains (the stage's own line
/// says by which rule).
pub fn describe_pca(fit: &PcaFit) -> String {
    let s = fit.basis.singular_values();
    let shown: Vec<String> = s.iter().take(12).map(|v| format!("{v:.3e}")).collect();
    format!(
        "singular values: {} …\nk = {}{}{}, explained energy {:.6}\n",
        shown.join(" "),
        fit.chosen_k(),
        match fit.appended {
            0 => String::new(),
            m => format!(" + {m} positions of the fall under gravity"),
        },
        match fit.responses {
            0 => String::new(),
            r => format!(" + {r} static responses to patch loads"),
        },
        fit.basis.explained_energy(fit.chosen_k())
    )
}

/// Writes `spectrum.csv` (index, singular value) and, for the vertex-error rule,
/// `vertex_error.csv` (k, maximum vertex error over the snapshots) into `dir`.
pub fn write_pca_curves(dir: &Path, fit: &PcaFit) -> Result<()> {
    crate::output::create_folder(dir, "the output folder", "for the curves")?;
    let mut csv = String::from("index,singular_value\n");
    for (i, v) in fit.basis.singular_values().iter().enumerate() {
        csv.push_str(&format!("{},{v}\n", i + 1));
    }
    crate::output::write_file(&dir.join("spectrum.csv"), csv.as_bytes())?;
    if !fit.max_vertex_error_per_k.is_empty() {
        let mut csv = String::from("k,max_vertex_error\n");
        for (i, e) in fit.max_vertex_error_per_k.iter().enumerate() {
            csv.push_str(&format!("{},{e}\n", i + 1));
        }
        crate::output::write_file(&dir.join("vertex_error.csv"), csv.as_bytes())?;
    }
    Ok(())
}

impl TrainedModel {
    /// The network's sizes, its best epoch and training time, and its worst vertex error over
    /// the snapshots beside PCA's at the same dimension and the PCA dimension that matches it.
    pub fn describe(&self) -> String {
        format!(
            "autoencoder {k} → {d} → {k}, hidden layers {:?}: {}{}, {:.1} s\n\
             max vertex error over the snapshots: autoencoder (d = {d}) {:.3e}, PCA with {d} columns {:.3e}; PCA needs {} columns to match\n",
            self.model.hidden_widths(),
            match (self.best_epoch, self.history.len()) {
                (0, n) => format!("kept its start, none of {n} epochs closer"),
                (e, n) => format!("best epoch {e} of {n}"),
            },
            if self.stopped_early {
                " (stopped early)"
            } else {
                ""
            },
            self.train_seconds,
            self.max_vertex_error,
            self.pca_error_at_latent_dim,
            self.pca_k_matching
                .map(|k| k.to_string())
                .unwrap_or_else(|| format!("more than {}", self.pca_k)),
            k = self.pca_k,
            d = self.latent_dim
        )
    }

    /// Writes `loss.csv` and `loss.svg` into `dir`. The CSV has a row per epoch, and epoch 0
    /// for the weights training started from: the training loss (the epoch's running mean,
    /// taken before each step), the validation loss, the monitored loss that judged the epoch
    /// (the validation loss, or without a split the training loss measured again after the
    /// epoch) and `best`, 1 on the judged run's best: the weights kept, or where the network
    /// was trained again on every schedule ([`TrainedModel::retrained_epochs`]), the epoch
    /// count it was trained for.
    pub fn write_loss_curve(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let split = self.history.iter().any(|r| r.validation_loss.is_some());
        let kept = |epoch: usize| u8::from(epoch == self.best_epoch);
        let mut csv = String::from("epoch,train_loss,validation_loss,monitored_loss,best\n");
        let start = if split {
            self.start_loss.to_string()
        } else {
            String::new()
        };
        csv.push_str(&format!("0,,{start},{},{}\n", self.start_loss, kept(0)));
        for r in &self.history {
            let v = r.validation_loss.map(|v| v.to_string()).unwrap_or_default();
            csv.push_str(&format!(
                "{},{},{},{},{}\n",
                r.epoch,
                r.train_loss,
                v,
                r.monitored_loss,
                kept(r.epoch)
            ));
        }
        crate::output::write_file(&dir.join("loss.csv"), csv.as_bytes())?;
        let mut series = vec![plot::Series {
            name: "training".into(),
            points: self
                .history
                .iter()
                .map(|r| (r.epoch as f64, r.train_loss))
                .collect(),
            line: true,
            ..Default::default()
        }];
        // The monitored loss from the start (epoch 0): the validation loss, or the training
        // loss after each epoch.
        series.push(plot::Series {
            name: if split {
                "validation".into()
            } else {
                "training, after the epoch".into()
            },
            points: std::iter::once((0.0, self.start_loss))
                .chain(
                    self.history
                        .iter()
                        .map(|r| (r.epoch as f64, r.monitored_loss)),
                )
                .filter(|(_, l)| l.is_finite() && *l > 0.0)
                .collect(),
            line: true,
            ..Default::default()
        });
        // The judged run's best: the start's, or the best epoch's.
        let kept = if self.best_epoch == 0 {
            Some(self.start_loss)
        } else {
            self.history
                .iter()
                .find(|r| r.epoch == self.best_epoch)
                .map(|r| r.monitored_loss)
        };
        if let Some(loss) = kept.filter(|l| l.is_finite() && *l > 0.0) {
            series.push(plot::Series {
                name: match self.retrained_epochs {
                    Some(n) => format!("best (epoch {n}; the network kept trained again for {n})"),
                    None => format!("kept (epoch {})", self.best_epoch),
                },
                points: vec![(self.best_epoch as f64, loss)],
                line: false,
                ..Default::default()
            });
        }
        let plot = plot::Plot {
            title: format!(
                "autoencoder {} → {} → {} (MSE, scaled units)",
                self.pca_k, self.latent_dim, self.pca_k
            ),
            x_label: "epoch".into(),
            y_label: "loss".into(),
            x_scale: plot::Scale::Linear,
            y_scale: plot::Scale::Log,
        };
        crate::output::write_file(&dir.join("loss.svg"), plot::svg(&plot, &series).as_bytes())?;
        Ok(())
    }
}

impl FittedCubature {
    /// The rule's size out of `elements`, its force error on the training poses (and whether
    /// it met its tolerance) and on the held-out trajectory, and its fit time.
    pub fn describe(&self, elements: usize) -> String {
        format!(
            "{} of {} elements, relative force error {:.3e} on the training poses ({}met), {:.3e} on the held-out trajectory, fitted in {:.2} s\n",
            self.rule.len(),
            elements,
            self.rule.training_error,
            if self.rule.tolerance_met {
                ""
            } else {
                "tolerance not "
            },
            self.held_out_error,
            self.fit_seconds
        )
    }

    /// Writes `error.csv` (elements, relative force error on the training poses) and `error.svg`.
    pub fn write_error_curve(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        // One row per step of the greedy path: NNLS may drop elements, so a count can come
        // back (a tester's 584 rows held 500 counts), and `step` keys the rows. The held-out
        // error was measured when the path first reached its count, and goes on that row.
        let mut csv = String::from("step,elements,relative_error,held_out_error\n");
        let mut said = std::collections::BTreeSet::new();
        for (step, (n, e)) in self.rule.error_curve.iter().enumerate() {
            let held = self
                .held_out_curve
                .iter()
                .find(|&&(m, _)| m == *n)
                .filter(|_| said.insert(*n))
                .map(|&(_, h)| h.to_string())
                .unwrap_or_default();
            csv.push_str(&format!("{},{n},{e},{held}\n", step + 1));
        }
        crate::output::write_file(&dir.join("error.csv"), csv.as_bytes())?;
        let series = vec![
            plot::Series {
                name: "training poses".into(),
                points: self
                    .rule
                    .error_curve
                    .iter()
                    .map(|&(n, e)| (n as f64, e))
                    .collect(),
                line: true,
                ..Default::default()
            },
            plot::Series {
                name: "held-out trajectory".into(),
                points: self
                    .held_out_curve
                    .iter()
                    .map(|&(n, e)| (n as f64, e))
                    .collect(),
                line: true,
                ..Default::default()
            },
        ];
        let plot = plot::Plot {
            title: "optimized cubature: relative reduced-force error".into(),
            x_label: "elements".into(),
            y_label: "relative error".into(),
            x_scale: plot::Scale::Linear,
            y_scale: plot::Scale::Log,
        };
        crate::output::write_file(&dir.join("error.svg"), plot::svg(&plot, &series).as_bytes())?;
        Ok(())
    }
}
