//! The cached stages: snapshots → PCA (→ train → cubature, later), and the full-space reference
//! on the held-out test trajectory.
//!
//! A stage's artifact is stored under a key that hashes what the stage reads: the scene sections,
//! the mesh content and pinned vertices, the upstream stages' keys and the artifact format
//! version. A stage whose artifact exists and loads under its key is skipped, so re-running the
//! pipeline with an unchanged scene does no numerical work, and changing `[pca]` reuses the
//! snapshots.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use fem_core::integrator::{FullSpaceModel, Simulator, TimeConfig};
use fem_core::snapshots::{self, ScheduleConfig, SnapshotSet, StiffnessProbe};
use pca::{PcaBasis, PcaFit};
use rayon::prelude::*;
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::artifact::{self, Expect, KeyBuilder, fnv1a};
use crate::scene::Scene;
use crate::stage::Stage;

/// Age past which a temporary file in the cache belongs to a killed run (a live write takes
/// seconds).
pub const STALE_TEMPORARY_AGE: std::time::Duration = std::time::Duration::from_secs(3600);

/// Whether a file can be made in folder `dir`: one is created there under a name of
/// [`fem_core::io::write_atomic`]'s temporaries (which a later sweep removes if this one is
/// killed in between) and removed.
fn writable(dir: &Path) -> std::io::Result<()> {
    // Unique per call, so that pipelines of one process probing at once do not collide.
    let probe = fem_core::io::temporary_path(dir, "write-probe");
    std::fs::create_dir_all(dir)?;
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)?;
    std::fs::remove_file(&probe)
}

/// What happened to one stage in a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageOutcome {
    pub stage: Stage,
    /// Loaded from the cache instead of computed.
    pub cached: bool,
    /// Time spent in this stage itself: loading, or computing less the upstream stages that the
    /// computation had to load or compute first (each of those has its own outcome).
    pub seconds: f64,
    pub path: PathBuf,
    /// Its cache key: what it was computed from (a model file's provenance names the same).
    pub key: u64,
    /// What the stage chose and why, in one line (sizes, dimensions, rule sizes and errors).
    pub summary: String,
}

/// Two lines: whether the stage was loaded (and from where) or computed (in how long, to
/// where), and under it what it chose.
impl std::fmt::Display for StageOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.cached {
            writeln!(
                f,
                "{:>10}: unchanged, skipped ({})",
                self.stage,
                self.path.display()
            )?;
        } else {
            writeln!(
                f,
                "{:>10}: computed in {:.1} s → {}",
                self.stage,
                self.seconds,
                self.path.display()
            )?;
        }
        write!(f, "{:>10}  {}", "", self.summary)
    }
}

/// One line saying what a stage's artifact holds and why, for [`StageOutcome::summary`].
pub trait StageSummary {
    fn summary(&self) -> String;

    /// The line for `scene`, where what the scene asks of the artifact changes it (the
    /// complement directions it takes); [`StageSummary::summary`] otherwise.
    fn summary_in(&self, scene: &Scene) -> String {
        let _ = scene;
        self.summary()
    }

    /// What makes a loaded artifact unusable by a model of `free` free DOFs, when its
    /// checksums passed (tampered with, or written by a build whose layout changed without a
    /// new version): then the stage is computed again instead of a later stage panicking.
    fn problem(&self, free: usize) -> Option<String> {
        let _ = free;
        None
    }
}

impl StageSummary for SnapshotSet {
    fn problem(&self, free: usize) -> Option<String> {
        let frames = self
            .frames
            .iter()
            .try_fold(0usize, |a, &b| a.checked_add(b));
        if self.dim != free {
            Some(format!(
                "snapshots of {} DOFs for a model of {free}",
                self.dim
            ))
        } else if self.frames.len() != self.schedules.len() {
            Some("a frame count per schedule expected".into())
        } else if frames.and_then(|f| f.checked_mul(free)) != Some(self.data.len()) {
            Some(format!(
                "{} values for the frames it counts",
                self.data.len()
            ))
        } else {
            None
        }
    }

    fn summary(&self) -> String {
        let n = self.schedules.len();
        let mut s = format!(
            "{n} schedule{} × {} frames = {} training poses",
            if n == 1 { "" } else { "s" },
            self.frames_per_schedule,
            self.num_frames()
        );
        if let Some(why) = &self.later_start {
            s += &format!(" ({why})");
        }
        if let Some(first) = self.stopped.first() {
            s += &format!(
                "; {} of them stopped early where the full-space solve failed, their earlier \
                 frames kept (schedule {} after {} frames: {})",
                self.stopped.len(),
                first.index,
                first.frames,
                first.error
            );
        }
        s
    }
}

impl StageSummary for PcaFit {
    fn summary(&self) -> String {
        pca_line(self, None)
    }

    fn summary_in(&self, scene: &Scene) -> String {
        pca_line(self, Some(scene))
    }
}

/// The `pca` stage's line; with the `scene` it was fitted for, also how many positions of the
/// fall it was to append (said as the default's where the scene did not name them: a tester
/// read "`[pca] gravity_directions` = 3" as a setting its scene did not have) and whether the
/// next value of its rule passes `max_dimension`.
fn pca_line(fit: &PcaFit, scene: Option<&Scene>) -> String {
    let gravity_asked = scene.and_then(|scene| {
        let asked = scene.pca.gravity_directions.or(
            // Absent, the default count is asked where the test appends any.
            (fit.appended > 0).then_some(DEFAULT_GRAVITY_DIRECTIONS),
        );
        // A quasi-static scene's fall has one position, its static sag
        // (`fem_core::step_norm::gravity_onset`): the others were never offered.
        asked.map(|a| if scene.time.quasi_static { a.min(1) } else { a })
    });
    let defaulted = scene.is_some_and(|s| s.pca.gravity_directions.is_none());
    let max_dimension = scene.map(|s| s.pca.max_dimension);
    let why = match fit.rule {
        pca::DimensionRule::Count(k) => match 1.0 - fit.basis.explained_energy(k) {
            left if left > 0.0 => format!(
                "`[pca] dimension` = {k}, holding all but {left:.1e} of the snapshots' energy"
            ),
            _ => format!("`[pca] dimension` = {k}, holding all of the snapshots' energy"),
        },
        pca::DimensionRule::ExplainedEnergy(f) if f >= 1.0 => {
            "the smallest basis holding all of the snapshots' energy (`[pca] \
             explained_energy` = 1)"
                .to_string()
        }
        pca::DimensionRule::ExplainedEnergy(f) => {
            // The next value the advice of a larger basis names ("one 9 more": a tenth of the
            // energy left out), printed with one decimal more than `f` as written (0.995 →
            // 0.9995, 0.9999999 → 0.99999999, not 0.9999999900000001), and the count at the
            // value printed.
            let decimals = format!("{f}").split('.').nth(1).map_or(0, str::len) + 1;
            let printed = format!("{:.decimals$}", 1.0 - (1.0 - f) / 10.0);
            let next: f64 = printed.parse().unwrap_or(1.0);
            let more = if fit.tolerance_met && next < 1.0 && next > f {
                let n = fit.energy_dimension(next);
                let past = match max_dimension {
                    Some(cap) if n > cap => format!(", past `max_dimension` = {cap}"),
                    _ => String::new(),
                };
                format!("; one 9 more, {printed}, keeps {n}{past}")
            } else {
                String::new()
            };
            format!(
                "the smallest basis holding all but {:.1e} of the snapshots' energy (`[pca] \
                 explained_energy` = {f}{more})",
                1.0 - f
            )
        }
        pca::DimensionRule::MaxVertexError(t) => format!(
            "the smallest basis whose worst vertex error over the snapshots is at most {t} \
             (`[pca] max_vertex_error`)"
        ),
    };
    let k = fit.chosen_k();
    // Where the rule was stopped short, the basis has as many coefficients as the cap.
    let met = match fit.shortfall() {
        None => String::new(),
        Some(pca::Shortfall::Cap { wanted: Some(w) }) => format!(
            " (stopped at `[pca] max_dimension` = {k}; the rule asks for {w}, which a \
             `max_dimension` of {w} lets it keep)"
        ),
        Some(pca::Shortfall::Cap { wanted: None }) => {
            format!(" (not reached within `[pca] max_dimension` = {k})")
        }
        Some(pca::Shortfall::Rank) => format!(
            " (not reached: the snapshots span {k} independent directions and the basis holds \
             them all; a larger tolerance, or training schedules that move the body in other \
             ways)"
        ),
    };
    let mut line = match (fit.appended, fit.fall_missed) {
        (0, Some(f)) => format!(
            "k = {k}: {why}{met}; they hold the body's first step of its fall from rest under \
             gravity to {:.2} %, no gravity directions added (`[pca] gravity_directions`)",
            100.0 * f
        ),
        (0, None) => format!("k = {k}: {why}{met}"),
        (m, _) => format!(
            "k = {k} + {m}: {why}{met}, plus {m} position{} of the body's fall from rest \
             under gravity (those columns miss{} its first step; \
             `[pca] gravity_directions`{})",
            if m == 1 { "" } else { "s" },
            fit.fall_missed
                .map(|f| format!(" {:.2} % of", 100.0 * f))
                .unwrap_or_default(),
            match gravity_asked {
                Some(asked) if asked > m => format!(
                    " = {asked}{}, {} left out: under {} % of {} lay outside the basis, so \
                     {} only add its round-off",
                    if defaulted { ", the default" } else { "" },
                    if asked - m == 1 {
                        "one".to_string()
                    } else {
                        (asked - m).to_string()
                    },
                    100.0 * GRAVITY_DIRECTION_NEW,
                    if asked - m == 1 { "it" } else { "each" },
                    if asked - m == 1 {
                        "it would"
                    } else {
                        "they would"
                    },
                ),
                _ => String::new(),
            }
        ),
    };
    if fit.responses > 0 {
        // At most a tenth of the columns before them (`PATCH_RESPONSE_SHARE`).
        let most = (fit.basis.k() - fit.responses).div_ceil(PATCH_RESPONSE_SHARE);
        line += &format!(
            "; plus {} static response{} to a load on a surface patch that the basis \
             missed{}, {} columns in all (`[pca] patch_responses`)",
            fit.responses,
            if fit.responses == 1 { "" } else { "s" },
            if fit.responses >= most {
                ", the most it takes (a tenth of the columns before them)".to_string()
            } else {
                String::new()
            },
            fit.basis.k()
        );
    }
    line
}

impl RuleValidation {
    /// The mean over the schedules of each rule's error: the tangent's and the PCA subspace's.
    pub fn means(&self) -> (f64, f64) {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        (mean(&self.tangent_errors), mean(&self.pca_errors))
    }
}

/// Whether the PCA subspace's rule follows the training schedules clearly closer than the
/// tangent's: where it fails fewer of them, or where its error is lower on average by more than
/// twice the standard error of the schedules' differences (a paired comparison: the schedules'
/// own spread says how much of a difference is the few schedules drawn) and by more than
/// [`RULE_MARGIN`] of the tangent's error. Never on fewer than two schedules.
pub fn pca_rule_clearly_closer(tangent: &[f64], pca: &[f64]) -> bool {
    let failures = |v: &[f64]| v.iter().filter(|e| !e.is_finite()).count();
    if tangent.len() != pca.len() || tangent.len() < 2 {
        return false;
    }
    let (t_failed, p_failed) = (failures(tangent), failures(pca));
    if t_failed > 0 || p_failed > 0 {
        return p_failed < t_failed;
    }
    let n = tangent.len() as f64;
    let d: Vec<f64> = tangent.iter().zip(pca).map(|(t, p)| t - p).collect();
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    let tangent_mean = tangent.iter().sum::<f64>() / n;
    mean > 2.0 * (var / n).sqrt() && mean > RULE_MARGIN * tangent_mean
}

/// Up to [`VALIDATION_SCHEDULES`] training schedules of `snaps` spread over the family, each
/// recorded whole and started from rest (as the test is; the moving starts every
/// [`snapshots::LATER_EVERY`]th schedule takes when `later_start` says so are left out).
pub fn validation_schedules(snaps: &SnapshotSet) -> Vec<usize> {
    let moving = snaps.later_start.is_some();
    let whole: Vec<usize> = snaps
        .schedules
        .iter()
        .zip(&snaps.frames)
        .filter(|&(&s, &f)| {
            f == snaps.frames_per_schedule
                && !(moving && s % snapshots::LATER_EVERY == snapshots::LATER_EVERY - 1)
        })
        .map(|(&s, _)| s)
        .collect();
    let n = whole.len().min(VALIDATION_SCHEDULES);
    (0..n).map(|i| whole[i * whole.len() / n]).collect()
}

impl StageSummary for FittedCubature {
    fn summary(&self) -> String {
        format!(
            "{} element{}, relative force error {:.2} % on the training poses{} and {:.2} % on \
             the test trajectory's",
            self.rule.len(),
            if self.rule.len() == 1 { "" } else { "s" },
            100.0 * self.rule.training_error,
            if self.rule.tolerance_met {
                ""
            } else {
                " (the element budget stopped it before the tolerance)"
            },
            100.0 * self.held_out_error
        ) + &self.candidates.map_or(String::new(), |c| {
            format!(
                "; chosen from {c} elements drawn at random, so that the training poses' forces \
                 fit `[cubature] memory_limit_mb` ({} poses fitted; the target forces sum every \
                 element)",
                self.poses
            )
        }) + &self.validation.as_ref().map_or(String::new(), |v| {
            let pct = |e: f64| {
                if e.is_finite() {
                    format!("{:.2} %", 100.0 * e)
                } else {
                    "a failed step".into()
                }
            };
            let (tangent_mean, pca_mean) = v.means();
            // Each rule's name and mean error, the kept one first (the PCA rule named by its
            // stage where it is kept).
            let tangent = (
                format!(
                    "the rule fitted in the decoder's tangent ({} elements)",
                    v.tangent_elements
                ),
                tangent_mean,
            );
            let stage = if v.pca_kept { "stage `cubature`, " } else { "" };
            let pca = (
                format!(
                    "the PCA subspace's rule ({stage}{} elements)",
                    v.pca_elements
                ),
                pca_mean,
            );
            let ((kept, mine), (other, theirs)) = if v.pca_kept {
                (pca, tangent)
            } else {
                (tangent, pca)
            };
            // Where the PCA rule was closer on average and still not kept, why.
            let why = if !v.pca_kept && pca_mean < tangent_mean {
                if pca_mean < (1.0 - RULE_MARGIN) * tangent_mean {
                    " (closer on average, but within the spread of the schedules' differences: \
                     not clearly)"
                } else {
                    " (closer on average by less than a tenth: not clearly)"
                }
            } else {
                ""
            };
            format!(
                "; kept {kept}: on {} training schedules neural-cubature stays {} on average \
                 from the full trajectories (their PCA coefficients) with it, {} with {other}{why}",
                v.schedules.len(),
                pct(mine),
                pct(theirs)
            )
        })
    }
}

impl TrainedModel {
    /// What to say where the autoencoder misses the snapshots by more than PCA's truncation to
    /// its own dimension, which the paper's method is to beat: a tester's networks without the
    /// skip and the input scaling (AutoDef's) lost to it on three meshes of three (the X
    /// 2.25e-2 against 2.16e-2, the bar 7.3e-2 against 4.3e-2) without a word.
    fn behind_pca(&self) -> String {
        // False for NaN on either side: no PCA error at d (d > k without the skip) says nothing.
        let behind = self.max_vertex_error > 1.01 * self.pca_error_at_latent_dim;
        if !behind {
            return String::new();
        }
        let start = if self.model.has_skip() || self.latent_dim > self.pca_k {
            ""
        } else {
            ": `[autoencoder] skip = true` (the default) starts the network from it and learns \
             the correction"
        };
        format!(
            ", closer than the autoencoder, whose neural methods then start behind a PCA basis \
             of that size{start}"
        )
    }
}

impl StageSummary for TrainedModel {
    fn summary(&self) -> String {
        format!(
            "d = {} of k = {}{}; hidden layers {:?}{}; worst vertex error over the snapshots \
             {:.3e} (PCA with {} coefficients: {:.3e}{}); {} epochs{}{}",
            self.latent_dim,
            self.pca_k,
            match &self.latent_choice {
                Some(why) => format!(" ({why})"),
                None => String::new(),
            },
            self.model.hidden_widths(),
            if self.hidden_chosen {
                format!(
                    " (the default, k within {:?}; `[autoencoder] hidden` sets them)",
                    nn::DEFAULT_HIDDEN_RANGE
                )
            } else {
                String::new()
            },
            self.max_vertex_error,
            self.latent_dim,
            self.pca_error_at_latent_dim,
            self.behind_pca(),
            self.history.len(),
            match (self.best_epoch, self.model.has_skip()) {
                (0, true) => ", none closer than the start, PCA's truncation to d through the \
                              linear skip, which is kept"
                    .to_string(),
                (0, false) => ", none closer than the weights training started from, which are \
                               kept"
                    .to_string(),
                _ => String::new(),
            },
            match self.retrained_epochs {
                Some(e) => format!(
                    " judged on whole training schedules held out, then the best count ({e}) \
                     again on every schedule"
                ),
                None => match self.retrain_missed {
                    Some(e) => format!(
                        " judged on whole training schedules held out (trained again on every \
                         schedule for the best count ({}), it missed the snapshots by {e:.3e}, \
                         past `[autoencoder] max_vertex_error`, and the judged network, which \
                         met it, is kept)",
                        self.best_epoch.max(1)
                    ),
                    None => String::new(),
                },
            }
        )
    }
}

impl StageSummary for Complement {
    fn summary(&self) -> String {
        let c = self.default_count();
        self.line(
            c,
            &format!("the leading {c} (unless `[reduced] complement_directions` says)"),
        )
    }

    fn summary_in(&self, scene: &Scene) -> String {
        match scene.reduced.complement_directions {
            // Beyond the residuals' count `complement_count` stops with its own error.
            Some(c) if c <= self.singular_values.len() => self.line(
                c,
                &format!(
                    "the leading {c} (`[reduced] complement_directions`; the default would be {})",
                    self.default_count()
                ),
            ),
            _ => self.summary(),
        }
    }
}

impl StageSummary for Reference {
    fn problem(&self, free: usize) -> Option<String> {
        let n = self.frames.len();
        if let Some(k) = self.frames.iter().position(|f| f.len() != free) {
            Some(format!("frame {k} is not {free} values"))
        } else if self.step_seconds.len() != n || self.iterations.len() != n {
            Some("a time and an iteration count per frame expected".into())
        } else {
            None
        }
    }

    fn summary(&self) -> String {
        let n = self.step_seconds.len().max(1) as f64;
        let mut s = format!(
            "{} frames of the full-space test trajectory, {:.1} ms of wall time a step",
            self.frames.len(),
            1e3 * self.step_seconds.iter().sum::<f64>() / n
        );
        if let Some(e) = &self.stopped {
            s += &format!(
                "; the full-space solve failed at the next step ({e}), so every method is \
                 compared over these frames only: a milder test (`[test] offset`, `stiffness`) \
                 or a smaller `[time] step` would let it finish"
            );
        }
        s
    }

    fn summary_in(&self, scene: &Scene) -> String {
        let mut s = self.summary();
        if let Some(line) = crate::trust::solver_switches(
            scene.solver.method,
            scene.solver.max_iterations,
            &self.switched,
            self.frames.len(),
        ) {
            s += &format!("; {line}");
        }
        s
    }
}

/// A body whose kinetic energy under gravity alone has fallen to this fraction of its peak by
/// the default schedule length is taken as at rest there (its training schedules all start
/// from rest).
pub const SETTLED_KINETIC: f64 = 1e-4;

/// A body whose centre of mass lies this fraction of its height or more above its pins'
/// centre, against gravity, stands on them (the `snapshots` line says when it falls over); one
/// hung from them or held at a side does not.
pub const STANDS_ABOVE: f64 = 0.25;

/// A body standing on its pins that its weight alone moves this fraction of its bounding-box
/// diagonal or more falls over or folds: a firm one sags a few per cent of its size (the soft
/// bear that fell backwards moved 110 %).
pub const FALLS_OVER: f64 = 0.5;

/// The most frames of the run under gravity alone that checks whether the body gives way under
/// its weight where no later start applies (the scene sets its schedules' length, or the test
/// is no longer): the default schedule length, so that longer schedules do not pay a longer
/// check.
pub const GIVES_WAY_CHECK_FRAMES: usize = 60;

/// Training schedules the `cubature-neural` stage runs `neural-cubature` on with each candidate
/// rule ([`RuleValidation`]): enough, spread over the family, for the spread of their
/// differences to say what a difference is worth; the 2 × 12 runs took about 2 s on the
/// default scene and 5.5 s on a 30k-tet figure.
pub const VALIDATION_SCHEDULES: usize = 12;

/// Why the autoencoder of `cfg` cannot be trained on a PCA basis of `k` columns: a latent
/// dimension (or a searched range) past k, which the linear skip cannot take. Stage `train`
/// refuses it, and `run` before it measures any method (a tester's `latent_dim = 12` on k = 10
/// was refused after the PCA methods had run, their results thrown away).
pub fn latent_dim_refusal(cfg: &nn::AutoencoderConfig, k: usize) -> Option<String> {
    if !cfg.skip {
        return None;
    }
    match (cfg.latent_dim, cfg.latent_dims) {
        (Some(d), _) if d > k => Some(format!(
            "`autoencoder.latent_dim` = {d} is larger than the PCA basis (k = {k}), and the \
             linear skip needs d ≤ k: set `latent_dim` to at most {k}, or keep more PCA \
             coefficients (`[pca] dimension` of {d} or more, within `max_dimension`, one 9 more \
             in `[pca] explained_energy`, or a smaller `[pca] max_vertex_error`)"
        )),
        (None, Some([lo, hi])) if hi > k => Some(format!(
            "`autoencoder.latent_dims` = [{lo}, {hi}] reaches past the PCA basis (k = {k}), and \
             the linear skip needs d ≤ k: set the range to at most [{}, {k}], or keep more PCA \
             coefficients",
            lo.min(k)
        )),
        _ => None,
    }
}

/// The share of the tangent's error by which the PCA subspace's rule must be closer on the
/// training schedules to be kept. Within a tenth of each other the two rules' test errors went
/// either way (AutoDef's X in StVK: 1.83 against 1.82 % on its schedules, 1.1 against 2.9 % on
/// the test; the tuned catapult: 2.28 against 2.21 %, 3.63 against 3.59 % on the test with 20 %
/// more elements); where the PCA rule won on the test by far they were apart by 2–10 times (a
/// nearly incompressible finger, a rubber bushing).
pub const RULE_MARGIN: f64 = 0.1;

/// Progress of a long stage: `(done, total)`.
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// The full-space simulation of a held-out test trajectory: the ground truth for errors.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct Reference {
    /// Free-DOF displacement after each step.
    pub frames: Vec<Vec<f64>>,
    /// Wall time of each step (s), measured when the reference was computed.
    pub step_seconds: Vec<f64>,
    /// Solver iterations of each step.
    pub iterations: Vec<usize>,
    /// The steps (numbered from 1) on which the scene's solver stopped short and the other one
    /// finished (`StepReport::solver_switched`).
    pub switched: Vec<usize>,
    /// The solver's error when the full-space solve failed partway: `frames` holds the steps
    /// before it, and every method is compared over those.
    pub stopped: Option<String>,
}

/// A cubature rule for the PCA subspace and how well it generalises (stage `cubature`).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct FittedCubature {
    pub rule: cubature::CubatureRule,
    /// Relative force error on poses of the held-out test trajectory.
    pub held_out_error: f64,
    /// (elements, held-out relative error) along the greedy path (training excluded from the
    /// fit time, which covers building the training matrix and the greedy fit).
    pub held_out_curve: Vec<(usize, f64)>,
    pub fit_seconds: f64,
    /// The training poses fitted and, when the training data keeps a subsample of the elements
    /// to fit `[cubature] memory_limit_mb`, how many the rule was chosen from (`None`: every
    /// element).
    pub poses: usize,
    pub candidates: Option<usize>,
    /// For the neural methods' rule: how the rule fitted in the decoder's tangent and the PCA
    /// subspace's rule followed training schedules, and which one the stage kept.
    #[serde(default)]
    pub validation: Option<RuleValidation>,
}

/// The neural methods' two candidate rules run on training schedules (stage `cubature-neural`):
/// the one fitted to the reduced forces in the decoder's tangent, as AutoDef fits it, and the PCA
/// subspace's (stage `cubature`), which fits every PCA coordinate's force and holds for any
/// tangent within the basis. The tangent's, the paper's and often the smaller, is kept unless
/// the PCA subspace's follows the schedules clearly closer ([`pca_rule_clearly_closer`]).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RuleValidation {
    /// The training schedules run (from rest, recorded whole).
    pub schedules: Vec<usize>,
    /// Per schedule, the mean relative distance of the PCA coefficients from the full
    /// trajectory's over its frames: with the tangent's rule and with the PCA subspace's
    /// (infinite where a step failed).
    pub tangent_errors: Vec<f64>,
    pub pca_errors: Vec<f64>,
    /// The elements of each rule.
    pub tangent_elements: usize,
    pub pca_elements: usize,
    /// Whether the PCA subspace's rule was kept.
    pub pca_kept: bool,
}

/// W F with FFᵀ = (WᵀÂW)⁺ (`w` k×m, `a` = Â k×k): the tangent whose reduced forces Fᵀ Wᵀ f
/// measure a force error by the step displacement it makes, δfᵀ(WᵀÂW)⁻¹δf. F = V Λ^{-1/2} from
/// the eigenpairs of WᵀÂW; directions with eigenvalues below 10⁻¹² of the largest (W not of full
/// rank) are dropped, their columns left zero.
fn whitened(w: faer::MatRef<'_, f64>, a: faer::MatRef<'_, f64>) -> faer::Mat<f64> {
    let wa = w.transpose() * a * w;
    let m = wa.nrows();
    let sym = faer::Mat::<f64>::from_fn(m, m, |r, c| 0.5 * (wa[(r, c)] + wa[(c, r)]));
    let Ok(eigen) = sym.self_adjoint_eigen(faer::Side::Lower) else {
        return w.to_owned();
    };
    let (vectors, values) = (eigen.U(), eigen.S());
    let top = (0..m).map(|c| values[c]).fold(0.0, f64::max);
    let f = faer::Mat::<f64>::from_fn(m, m, |r, c| {
        let l = values[c];
        if l > 1e-12 * top {
            vectors[(r, c)] / l.sqrt()
        } else {
            0.0
        }
    });
    w * f
}

/// Poses for a cubature fit: linear ones when there are no tangents (PCA, whose basis is
/// whitened instead), nonlinear ones with a tangent per pose otherwise.
fn cubature_poses<'a>(
    q: &'a faer::Mat<f64>,
    tangents: &'a [faer::MatRef<'a, f64>],
) -> cubature::Poses<'a> {
    if tangents.is_empty() {
        cubature::Poses::linear(q.as_ref())
    } else {
        cubature::Poses::nonlinear(q.as_ref(), tangents)
    }
}

/// What the autoencoder misses in the training data (stage `complement`): the left singular
/// vectors of the reconstruction residuals R = Q − decode(encode(Q)) over the snapshots' PCA
/// coefficients Q, in order, for `[reduced] complement_directions`.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct Complement {
    /// The PCA dimension k (each direction's length).
    pub k: usize,
    /// The autoencoder's latent dimension d: its tangent at rest spans d of the k coefficients,
    /// so at most k − d directions are new beside it.
    pub latent_dim: usize,
    /// k × r column-major, orthonormal (r = min(k, snapshots)).
    pub directions: Vec<f64>,
    /// The residuals' singular values, largest first (‖R‖_F² = their sum of squares).
    pub singular_values: Vec<f64>,
    /// The snapshots' energy ‖S‖²_M, and what the mass-orthonormal PCA basis U leaves out of
    /// it, ‖S‖²_M − ‖UᵀMS‖²_F (the units of ‖R‖_F²).
    pub snapshot_energy: f64,
    pub pca_lost_energy: f64,
}

/// The autoencoder's validation split holds out whole training schedules and the network is
/// trained again on all of them for the epochs that split judged best (keyed, so that networks
/// trained on a split of frames are not reused).
const VALIDATION_BY_SCHEDULE: &str = "validation by schedule, then every schedule";

/// Residual energy below this fraction of the snapshots' is round-off, not worth a direction.
const COMPLEMENT_ROUND_OFF: f64 = 1e-14;

impl Complement {
    /// Σ_{i≥c} ρ_i² for c = 0, …, r (the last is zero), summed from the smallest up.
    fn tails(&self) -> Vec<f64> {
        let mut tails = vec![0.0; self.singular_values.len() + 1];
        for (i, r) in self.singular_values.iter().enumerate().rev() {
            tails[i] = tails[i + 1] + r * r;
        }
        tails
    }

    /// What the autoencoder may still miss of the snapshots with its default complement
    /// directions: what the PCA basis leaves out of them, and at least round-off in their
    /// energy.
    pub fn allowed_residual(&self) -> f64 {
        self.pca_lost_energy
            .max(COMPLEMENT_ROUND_OFF * self.snapshot_energy)
    }

    /// The directions a neural method takes when `[reduced] complement_directions` is absent:
    /// the fewest leading ones after which what the autoencoder still misses of the snapshots,
    /// Σ_{i≥c} ρ_i², is at most [`Complement::allowed_residual`], and no more than the k − d
    /// that can be new. With them the neural subspace holds the training data within twice
    /// the loss the PCA rule accepted, whatever the latent dimension; an autoencoder that
    /// already does needs none.
    pub fn default_count(&self) -> usize {
        let allowed = self.allowed_residual();
        let count = self
            .tails()
            .iter()
            .position(|&t| t <= allowed)
            .unwrap_or(self.singular_values.len());
        count
            .min(self.k.saturating_sub(self.latent_dim))
            .min(latent_sim::MAX_COMPLEMENT_DIRECTIONS)
    }

    /// The fraction of the snapshots' energy the autoencoder misses with its leading `count`
    /// complement directions added.
    pub fn missed_with(&self, count: usize) -> f64 {
        let tails = self.tails();
        tails[count.min(tails.len() - 1)] / self.snapshot_energy.max(f64::MIN_POSITIVE)
    }

    /// The stage's line when the neural methods take `count` directions, `taken` saying which.
    fn line(&self, count: usize, taken: &str) -> String {
        format!(
            "{} directions of what the autoencoder misses; the neural methods take {taken}: of \
             the snapshots' energy the autoencoder misses {:.2e} without them and {:.2e} with \
             them, the PCA basis {:.2e}",
            self.singular_values.len(),
            self.missed_with(0),
            self.missed_with(count),
            self.pca_lost_energy / self.snapshot_energy.max(f64::MIN_POSITIVE)
        )
    }
}

/// q̂ ← q̂ + V Vᵀ(q − q̂) for orthonormal columns V (k × c, column-major): the autoencoder's
/// reconstruction q̂ of q completed by the mass-orthogonal projection of what it missed on the
/// complement directions ([`Complement`]).
pub fn complete(v: &[f64], q: &[f64], qh: &mut [f64]) {
    let r: Vec<f64> = q.iter().zip(qh.iter()).map(|(a, b)| a - b).collect();
    for col in v.chunks_exact(q.len()) {
        let c: f64 = col.iter().zip(&r).map(|(a, b)| a * b).sum();
        qh.iter_mut().zip(col).for_each(|(x, vi)| *x += c * vi);
    }
}

/// The trained autoencoder and how it compares with PCA on the snapshots (stage `train`).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct TrainedModel {
    pub model: nn::Autoencoder,
    pub latent_dim: usize,
    /// Columns of the PCA basis it was trained on (its input size).
    pub pca_k: usize,
    pub history: Vec<nn::EpochReport>,
    /// The monitored loss of the weights the judged run started from, epoch 0's candidate.
    pub start_loss: f64,
    pub best_epoch: usize,
    pub stopped_early: bool,
    /// Every latent dimension tried with its maximum vertex error.
    pub trials: Vec<(usize, f64)>,
    /// Largest vertex distance over the snapshots of U·decode(encode(q)) from the snapshot.
    pub max_vertex_error: f64,
    /// The same for PCA with as many columns as the latent dimension.
    pub pca_error_at_latent_dim: f64,
    /// The smallest PCA dimension whose error is at most the autoencoder's, if any up to k.
    pub pca_k_matching: Option<usize>,
    pub train_seconds: f64,
    /// Why the latent dimension is what it is, when the scene did not name it.
    #[serde(default)]
    pub latent_choice: Option<String>,
    /// Whether the hidden widths are the default's (the scene did not name them).
    #[serde(default)]
    pub hidden_chosen: bool,
    /// When whole schedules were held out to judge the epochs: the best count, for which the
    /// network was then trained again on every schedule (`model` is that network; `history`
    /// and `best_epoch` are the judged run's).
    #[serde(default)]
    pub retrained_epochs: Option<usize>,
    /// When the network trained again on every schedule missed the snapshots by more than
    /// `[autoencoder] max_vertex_error`, which the judged one met: its worst vertex error (the
    /// judged network is kept, and `retrained_epochs` is `None`).
    #[serde(default)]
    pub retrain_missed: Option<f64>,
}

/// The latent dimension when `[autoencoder]` names no rule: half the PCA dimension, at least
/// [`nn::DEFAULT_LATENT_DIM`] and at most k (the linear skip needs d ≤ k). On the shipped
/// scenes the autoencoder with about k/2 latent coordinates came within a few tenths of a
/// percent of the whole PCA basis on the test trajectory (cantilever k = 22, d = 10–20;
/// catapult k = 47, d = 24), where a fixed small d (AutoDef's 6) was 20–80 % off on meshes it
/// was not chosen for.
pub fn default_latent_dim(k: usize) -> usize {
    k.div_ceil(2).max(nn::DEFAULT_LATENT_DIM).min(k)
}

/// How many positions of the body's fall under gravity (its gravity directions) the `pca` stage
/// appends when `[pca] gravity_directions` is not given, where the basis holds less than
/// 1 − [`GRAVITY_ONSET_MISSED`] of the first.
pub const DEFAULT_GRAVITY_DIRECTIONS: usize = 3;

/// By default the gravity directions are appended when the PCA basis misses at least this
/// fraction of the body's first step from rest under gravity (in the lumped mass norm the basis
/// is orthonormal in). A scene that names `gravity_directions` gets them without this test.
pub const GRAVITY_ONSET_MISSED: f64 = 0.01;

/// A position of the fall is appended when at least this fraction of its M-norm lies outside
/// the basis so far: less would add a direction of the basis's own round-off.
const GRAVITY_DIRECTION_NEW: f64 = 1e-3;

/// A patch's static response joins the basis when at least this fraction of its M-norm lies
/// outside it. On a 30k-tet toy of a trunk with arms, whose test drag the snapshots' basis held
/// to 1.8 %, the 8 of 144 responses over 3 % took that to 0.95 % and `pca` from 26 to 8 %
/// (8 more PCA columns: 1.80 %); 27 over 1 % gave 0.82 %.
const PATCH_RESPONSE_NEW: f64 = 0.03;

/// The patch responses appended are at most 1/this of the basis's columns before them.
const PATCH_RESPONSE_SHARE: usize = 10;

/// The body's vertices (those some tet uses), how many the pins hold, and each pin's count.
#[derive(Debug, Clone)]
struct BodyCounts {
    vertices: usize,
    held: usize,
    each_pin: Vec<usize>,
}

/// A scene's pipeline with its cache folder and the model every stage shares.
pub struct Pipeline<'a> {
    pub scene: &'a Scene,
    pub model: FullSpaceModel,
    pub mesh_hash: u64,
    pub cache: PathBuf,
    pub outcomes: Vec<StageOutcome>,
    /// Called after each stage (to print a line).
    pub on_stage: Box<dyn FnMut(&StageOutcome) + 'a>,
    /// What building the scene's model warned of (a mesh of an unusual size, a body its own
    /// weight would crush, pins that hold a piece at a vertex or along a line), also logged:
    /// `run` lists them first among the figures not to be trusted.
    pub warnings: Vec<String>,
    /// Called when a stage starts to compute (not when it is loaded from the cache): a log,
    /// where no progress bar is drawn, can say what the minutes until its line are spent on.
    pub on_stage_start: Box<dyn FnMut(Stage) + 'a>,
    /// Artifacts already loaded or computed in this run, by path: a stage that several later
    /// stages need is read (and announced) once, and every user shares the one copy.
    memo: std::collections::HashMap<PathBuf, Arc<dyn std::any::Any + Send + Sync>>,
    /// Sum of the recorded stages' own seconds, to take nested stages out of a stage's time.
    recorded_seconds: f64,
    /// The elastic energy of each frame of a test trajectory's reference, by trajectory, once a
    /// run has needed it: every reduced method's strain ratio divides by the same.
    pub(crate) reference_energies: std::collections::HashMap<usize, Arc<Vec<f64>>>,
    /// The body's vertex counts (fewer than the mesh's when some vertex no tet uses), for
    /// [`Pipeline::body_summary`] and the cache keys.
    body: BodyCounts,
    /// The buckling analysis of the scene's gravity, once a run has needed it (it depends on
    /// the model alone, not on the test trajectory).
    pub(crate) buckling: std::cell::OnceCell<Option<crate::run::Buckling>>,
    /// The forces of each test trajectory once [`Pipeline::test_model`] has built them: each
    /// costs a factorisation of the full step's operator (the stiffness probe), and a run asks
    /// for them once per method.
    test_forces:
        std::cell::RefCell<std::collections::HashMap<usize, Vec<fem_core::forces::ExternalForce>>>,
}

impl std::fmt::Debug for Pipeline<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pipeline")
            .field("scene", &self.scene.name)
            .field("cache", &self.cache)
            .field("outcomes", &self.outcomes)
            .finish()
    }
}

/// Logs a warning the first time this process meets it (a bench builds one pipeline per
/// variant of the same scene).
pub(crate) fn warn_once(message: &str) {
    let new = {
        let mut seen = WARNED.lock().unwrap_or_else(|e| e.into_inner());
        let new = !seen.iter().any(|m| m == message);
        if new {
            seen.push(message.to_string());
        }
        new
    };
    // Outside the lock: a subscriber may run code of its own (Python's `warnings.warn`).
    if new {
        tracing::warn!("{message}");
    }
}

/// The warnings [`warn_once`] said in this process.
static WARNED: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

/// Lets every warning be said once more: a program that runs the pipeline again (a Python
/// call after another, a notebook cell run twice) hears its warnings again.
pub fn forget_warnings() {
    WARNED.lock().unwrap_or_else(|e| e.into_inner()).clear();
}

/// The parallelism the pipeline gives faer's dense kernels (the PCA's QR and SVD, the
/// products of the cubature fit and the complement): a fixed count of tasks, not the threads
/// the pool has, since those kernels split their sums by it. With the pool's count a tester's
/// PCA basis came out different on 1, 2, 3 and 4 threads in its last digits, and the greedy
/// cubature then chose a rule of 323, 326 or 324 elements on AutoDef's small X (0.89 against
/// 0.73 % off its test); with a fixed count every stage and every error is the same to the bit
/// on any number of threads. Two, the cores of the machine every figure in the docs was
/// measured on, so that those figures stand (8 tasks gave the same speed there but moved the
/// catapult's `neural-cubature` rule from 306 to 305 elements and its error from 3.56 to
/// 3.69 %); on more cores these stages, seconds beside the snapshots' minutes, go no wider.
pub const FAER_TASKS: usize = 2;

impl<'a> Pipeline<'a> {
    /// Builds the scene's model; `cache` is the folder for artifacts.
    ///
    /// Sets faer's global parallelism to [`FAER_TASKS`] tasks, so that what the stages compute
    /// does not depend on the number of threads (`RAYON_NUM_THREADS`) that compute it.
    pub fn new(scene: &'a Scene, cache: impl AsRef<Path>) -> Result<Self> {
        faer::set_global_parallelism(faer::Par::rayon(FAER_TASKS));
        let cache = cache.as_ref();
        // A scene read from a file was checked; one built or changed in code is checked here,
        // before a stage meets what it did not expect (an empty list of training kinds).
        scene.check()?;
        let built = scene.build_model()?;
        let model = built.model;
        let body = BodyCounts {
            vertices: model.mesh.num_vertices() - built.validation.unreferenced_vertices,
            held: built.held_vertices,
            each_pin: built.pin_vertices,
        };
        let (lo, hi) = model.mesh.bounding_box();
        // The pins' warnings were printed while the scene was checked; they join the rest so
        // that `run` lists them among what not to trust.
        let warnings: Vec<String> = built
            .warnings
            .iter()
            .cloned()
            .chain(fem_core::mesh::size_warning((hi - lo).norm()))
            .chain(fem_core::mesh::thin_warning(
                &model.mesh,
                if scene.mesh.generate.is_some() {
                    fem_core::mesh::REFINE_GENERATED
                } else {
                    fem_core::mesh::REFINE_MESHER
                },
            ))
            .chain(crate::scene::weight_warning(scene, (hi - lo).into()))
            .chain(crate::scene::density_warning(scene.material.density))
            .collect();
        for w in &warnings {
            warn_once(&format!("{}: {w}", scene.source));
        }
        let mut bytes =
            Vec::with_capacity(model.mesh.num_vertices() * 24 + model.mesh.num_tets() * 32);
        for v in &model.mesh.vertices {
            for c in v.iter() {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        for t in &model.mesh.tets {
            for &i in t {
                bytes.extend_from_slice(&(i as u64).to_le_bytes());
            }
        }
        crate::output::create_folder(cache, "the cache folder", "for the stages' artifacts")?;
        match fem_core::io::remove_stale_temporaries(cache, STALE_TEMPORARY_AGE) {
            Ok(0) => {}
            Ok(n) => tracing::info!(
                "removed {n} temporary file(s) left in {} by killed runs",
                cache.display()
            ),
            Err(e) => tracing::warn!("cannot clean temporaries in {}: {e}", cache.display()),
        }
        Ok(Self {
            scene,
            mesh_hash: fnv1a(&bytes),
            model,
            cache: cache.to_path_buf(),
            outcomes: Vec::new(),
            on_stage: Box::new(|_| {}),
            on_stage_start: Box::new(|_| {}),
            warnings,
            memo: std::collections::HashMap::new(),
            recorded_seconds: 0.0,
            reference_energies: std::collections::HashMap::new(),
            body,
            buckling: std::cell::OnceCell::new(),
            test_forces: Default::default(),
        })
    }

    /// One line on the body as the scene built it: its vertices and tets, its size, and how
    /// many vertices the pins hold, each pin's count beside (`cargo xtask` prints it first, so
    /// that a pin's tolerance that caught too much or too little shows before any stage).
    pub fn body_summary(&self) -> String {
        let mesh = &self.model.mesh;
        let (lo, hi) = mesh.bounding_box();
        let size = hi - lo;
        let BodyCounts {
            vertices,
            held,
            each_pin,
        } = &self.body;
        // The share says at once whether a tolerance caught a face or half the body.
        let share = 100.0 * *held as f64 / (*vertices).max(1) as f64;
        let share = if share < 1.0 {
            format!("{share:.1} %")
        } else {
            format!("{share:.0} %")
        };
        let pins = match each_pin.as_slice() {
            [] => "no pins".to_string(),
            [_] => format!("the pin holds {held} of them ({share})"),
            each => format!(
                "the pins hold {held} of them, {share} ({})",
                each.iter()
                    .enumerate()
                    .map(|(i, n)| format!("pin[{i}] {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let slivers = fem_core::mesh::sliver_note(mesh)
            .map(|n| format!("; {n}"))
            .unwrap_or_default();
        format!(
            "{}: {vertices} vertices and {} tets, {:.3} × {:.3} × {:.3} m; {pins}{slivers}",
            self.scene.source,
            mesh.num_tets(),
            size.x,
            size.y,
            size.z
        )
    }

    /// What every full-space simulation reads: mesh, material, pins, gravity, time step, and
    /// the solver as that simulation runs it.
    fn physics_key(&self, stage: Stage, solver: &fem_core::optim::SolverConfig) -> KeyBuilder {
        let s = self.scene;
        let key = KeyBuilder::new(stage)
            .mix_key(self.mesh_hash)
            .mix(&s.material)
            .mix(&self.model.pinned)
            .mix(&s.gravity)
            .mix(&(s.time.step, s.time.quasi_static))
            .mix(solver);
        // Since 2026-12-01 (stop 54) the body's size, which scales the loads, leaves out the
        // vertices no tet uses: the stages of a mesh that has some are computed again. Every
        // other mesh's size, and key, stayed as they were.
        if self.body.vertices < self.model.mesh.num_vertices() {
            key.mix(&"the body's size without its unused vertices")
        } else {
            key
        }
    }

    pub fn snapshots_key(&self) -> u64 {
        // The solver at the training data's tolerance: a `[solver] tolerance` that only the test
        // uses does not recompute the snapshots.
        let training = self.scene.training();
        let key = self
            .physics_key(Stage::Snapshots, &training.solver(&self.scene.solver))
            .mix(&training);
        // Schedules left at the default length may start later to reach the test's last frame,
        // when the test lasts longer than they do (`later_start`); a shorter test changes
        // nothing (since stop 76: a tester's test of 30 or 40 frames beside 60-frame schedules
        // computed the snapshots again).
        let until = self.scene.test().frames_per_schedule;
        match self.scene.training.frames_per_schedule {
            None if until > training.frames_per_schedule => key.mix(&until).finish(),
            _ => key.finish(),
        }
    }

    pub fn pca_key(&self) -> u64 {
        // The default rule written out is the default rule.
        let mut pca = self.scene.pca.clone();
        if pca.dimension.is_none()
            && pca.max_vertex_error.is_none()
            && pca.explained_energy == Some(pca::DEFAULT_EXPLAINED_ENERGY)
        {
            pca.explained_energy = None;
        }
        if pca.patch_responses == Some(pca::DEFAULT_PATCH_RESPONSES) {
            pca.patch_responses = None;
        }
        KeyBuilder::new(Stage::Pca)
            .mix_key(self.snapshots_key())
            .mix(&pca)
            .mix(&(
                self.gravity_directions(),
                GRAVITY_ONSET_MISSED,
                GRAVITY_DIRECTION_NEW,
            ))
            .mix(&(
                self.patch_responses(),
                PATCH_RESPONSE_NEW,
                PATCH_RESPONSE_SHARE,
            ))
            .finish()
    }

    pub fn cubature_key(&self) -> u64 {
        KeyBuilder::new(Stage::Cubature)
            .mix_key(self.pca_key())
            .mix_key(self.reference_key(0))
            .mix(&self.scene.cubature.for_linear())
            .finish()
    }

    pub fn train_key(&self) -> u64 {
        KeyBuilder::new(Stage::Train)
            .mix_key(self.pca_key())
            .mix(&self.scene.autoencoder)
            .mix(&VALIDATION_BY_SCHEDULE)
            .finish()
    }

    pub(crate) fn reference_key(&self, trajectory: usize) -> u64 {
        // Trajectory i depends on the test family's seed and i, not on how many trajectories
        // it has: keyed as a family of one, a scene whose `[test] schedules` grows (`run
        // --trajectories`) keeps its references and the stages keyed on trajectory 0's, and
        // the scenes that leave the count at its default keep their caches (one that sets
        // another count computed its references, and the cubature rules keyed on the first,
        // once more after this key changed).
        let family = fem_core::snapshots::ScheduleConfig {
            schedules: 1,
            ..self.scene.test()
        };
        let key = self
            .physics_key(Stage::Reference, &self.scene.solver)
            .mix(&family)
            .mix(&trajectory);
        // A test whose patches are spread (`[test] patches = "spread"`) grabs where the
        // placement puts them, which changed in stop 69 (`fem_core::snapshots::NEAR_PINS`);
        // the default random test's key stays as it was.
        if family.patches == fem_core::snapshots::PatchPlacement::Spread {
            key.mix(&"spread patches closer together near the pins")
                .finish()
        } else {
            key.finish()
        }
    }

    fn path(&self, stage: Stage, key: u64) -> PathBuf {
        self.cache.join(format!("{stage}-{key:016x}.art"))
    }

    /// Loads the artifact of `stage` under `key`, or computes and stores it; shared with every
    /// later use in this pipeline.
    fn stage<T: Serialize + DeserializeOwned + StageSummary + Send + Sync + 'static>(
        &mut self,
        stage: Stage,
        key: u64,
        compute: impl FnOnce(&mut Self) -> Result<T>,
    ) -> Result<Arc<T>> {
        let path = self.path(stage, key);
        if let Some(v) = self
            .memo
            .get(&path)
            .and_then(|v| v.clone().downcast::<T>().ok())
        {
            return Ok(v);
        }
        let value = Arc::new(self.load_or_compute(stage, key, path.clone(), compute)?);
        self.memo.insert(path, value.clone());
        Ok(value)
    }

    fn load_or_compute<T: Serialize + DeserializeOwned + StageSummary>(
        &mut self,
        stage: Stage,
        key: u64,
        path: PathBuf,
        compute: impl FnOnce(&mut Self) -> Result<T>,
    ) -> Result<T> {
        let start = (Instant::now(), self.recorded_seconds);
        if path.exists() {
            let expect = Expect {
                stage,
                key: Some(key),
                mesh: Some(self.mesh_hash),
            };
            match artifact::load::<T>(&path, expect) {
                Ok(v) => match v.problem(self.model.dofs.num_free()) {
                    None => {
                        let summary = v.summary_in(self.scene);
                        self.record(stage, key, true, start, path, summary);
                        return Ok(v);
                    }
                    Some(p) => tracing::warn!("{}: {p}; computing the stage again", path.display()),
                },
                Err(e) => tracing::warn!("{}; computing the stage again", e.problem()),
            }
        }
        // A cache folder that cannot be written would fail the stage only once computed.
        writable(&self.cache).with_context(|| {
            format!(
                "the cache folder {} cannot be written, and stage {stage} is not in it: give a \
                 folder you may write (--cache)",
                self.cache.display()
            )
        })?;
        (self.on_stage_start)(stage);
        let value = compute(self)?;
        artifact::save(&path, stage, key, self.mesh_hash, &value)
            .with_context(|| format!("cannot write {}", path.display()))?;
        let summary = value.summary_in(self.scene);
        self.record(stage, key, false, start, path, summary);
        Ok(value)
    }

    /// Records a finished stage; `start` is its start time and the recorded seconds then.
    fn record(
        &mut self,
        stage: Stage,
        key: u64,
        cached: bool,
        start: (Instant, f64),
        path: PathBuf,
        summary: String,
    ) {
        let nested = self.recorded_seconds - start.1;
        let seconds = (start.0.elapsed().as_secs_f64() - nested).max(0.0);
        self.recorded_seconds += seconds;
        let summary = match stage {
            Stage::Snapshots => summary + &self.turned_gravity_note(),
            _ => summary,
        };
        let o = StageOutcome {
            stage,
            key,
            cached,
            seconds,
            path,
            summary,
        };
        (self.on_stage)(&o);
        self.outcomes.push(o);
    }

    /// What the `snapshots` line adds under `[training] gravity = "any"` (the artifact, keyed
    /// on that setting, does not hold it): how many schedules fell along turned gravity.
    fn turned_gravity_note(&self) -> String {
        let training = self.scene.training();
        if training.gravity != snapshots::GravityDirections::Any {
            return String::new();
        }
        let turned = (0..training.schedules)
            .filter(|&i| training.turned_gravity(&self.model, i).is_some())
            .count();
        format!(
            "; {turned} of them fell along gravity turned another way, a direction drawn from \
             the seed for each (`[training] gravity = \"any\"`)"
        )
    }

    /// Stage `snapshots`: every training schedule simulated in full space.
    pub fn snapshots(&mut self, progress: Progress<'_>) -> Result<Arc<SnapshotSet>> {
        let key = self.snapshots_key();
        self.stage(Stage::Snapshots, key, |p| {
            p.unmerged_shards();
            let set = p.simulate_shard(&p.scene.training(), (0, 1), progress)?;
            p.some_frames(set)
        })
    }

    /// Says when the cache holds snapshot shards (`cargo xtask snapshots --shard I/N`) while the
    /// merged snapshots are about to be simulated whole: a tester's `--shard 0/1`, and a stage
    /// run before `--merge`, simulated every schedule again without a word of the shards.
    fn unmerged_shards(&self) {
        let prefix = format!("{}-", Stage::SnapshotsShard.name());
        let shards = std::fs::read_dir(&self.cache).map_or(0, |entries| {
            entries
                .filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
                .count()
        });
        if shards > 0 {
            warn_once(&format!(
                "{}: the cache {} holds {shards} snapshot shard file{} but not the merged \
                 snapshots: `cargo xtask snapshots --merge N` (N the shards' count) combines \
                 them; every training schedule is simulated here instead",
                self.scene.source,
                self.cache.display(),
                if shards == 1 { "" } else { "s" }
            ));
        }
    }

    /// Where every fourth training schedule starts, when not at rest: the scene leaves
    /// `[training] frames_per_schedule` at its default, the held-out test outlasts it, and
    /// under gravity alone the body is still moving when the schedules end (sagging, swinging
    /// or toppling on). The test's later frames then ride on poses that schedules from rest
    /// never reach, so a quarter of them start from the body's state under gravity alone at frame
    /// `test − training` and end at the test's last frame. Costs one full-space run, cut short
    /// once the body is at rest when the schedules end. The state, with the reason the
    /// `snapshots` line prints; beside it, what to warn of at once when that run gives way
    /// under the body's weight ([`Pipeline::gives_way`]) or carries it past twice its size
    /// ([`Pipeline::beyond_swing`]). Where no later start applies (the
    /// scene sets the schedules' length, or the test is no longer), the run still checks that,
    /// over the schedules' length up to [`GIVES_WAY_CHECK_FRAMES`], and every schedule starts
    /// from rest.
    fn later_start(
        scene: &Scene,
        model: &FullSpaceModel,
    ) -> Result<LaterStart, fem_core::FemError> {
        let cfg = scene.training();
        if (model.gravity * cfg.gravity_scale).norm() == 0.0 || scene.time.quasi_static {
            return Ok((None, None));
        }
        let until = scene.test().frames_per_schedule;
        let from = cfg.frames_per_schedule;
        let later = scene.training.frames_per_schedule.is_none() && until > from;
        let mut model = model.clone();
        model.forces.clear();
        model.scale_gravity(cfg.gravity_scale);
        // Frame `at` gives the later start (0: none).
        let (at, last) = if later {
            (until - from, from.max(until - from))
        } else {
            (0, from.min(GIVES_WAY_CHECK_FRAMES))
        };
        let time = TimeConfig {
            frames: last,
            ..scene.time.clone()
        };
        let mut sim = Simulator::new(model, time, cfg.solver(&scene.solver))?;
        let (mut start, mut peak_kinetic, mut frames) = (None, 0.0f64, Vec::new());
        let mut settled = false;
        for frame in 1..=last {
            let Ok(report) = sim.step() else {
                // A body the solver cannot follow under its own weight alone: its schedules
                // start from rest.
                break;
            };
            // The state is the full vector; `Compression` reads free DOFs, as the snapshots hold.
            let mut free = vec![0.0; sim.model.dofs.num_free()];
            sim.model.dofs.gather(&sim.state.u, &mut free);
            frames.push(free);
            peak_kinetic = peak_kinetic.max(report.kinetic_energy);
            if frame == from && report.kinetic_energy <= SETTLED_KINETIC * peak_kinetic {
                // At rest when the schedules end (a stable equilibrium): it stays there.
                settled = true;
                break;
            }
            if frame == at {
                start = Some(snapshots::MovingStart {
                    u: sim.state.u.clone(),
                    v: sim.state.v.clone(),
                });
            }
        }
        let Some(c) = crate::run::Compression::of(&sim.model, &frames, scene.time.step) else {
            return Ok((None, None));
        };
        let (lo, hi) = sim.model.mesh.bounding_box();
        // Without pins the run (the scene's springs left out) falls freely: no swing to pass.
        let pinned = !sim.model.pinned.is_empty();
        let gives_way = Self::gives_way(&c).or_else(|| {
            pinned
                .then(|| Self::beyond_swing(&c, (hi - lo).norm()))
                .flatten()
        });
        if !later || settled || frames.len() < last {
            return Ok((None, gives_way));
        }
        // How far its weight carries it: a body meant to stand that falls over is told here, a
        // stage before `run`'s list says what would hold it up.
        let falls = if Self::falls_over(&sim.model, &c, (hi - lo).norm()) {
            "; standing on its pins, it falls over or folds about them: if it should stand, pins \
             that hold more of its base or a stiffer material (`[material] youngs_modulus`) keep \
             it up"
        } else {
            ""
        };
        let why = format!(
            "every {}th starts from the body falling under gravity alone at {:.2} s, since it \
             still moves when they end (in {:.2} s under gravity alone it moves up to {:.0} % of \
             its bounding-box diagonal{falls}), and runs to the test's last frame ({until}); \
             `[training] frames_per_schedule` set starts them all at rest",
            snapshots::LATER_EVERY,
            at as f64 * scene.time.step,
            last as f64 * scene.time.step,
            100.0 * c.travel / (hi - lo).norm().max(f64::MIN_POSITIVE)
        );
        Ok((start.map(|s| (s, why)), gives_way))
    }

    /// What to say at once of a run under gravity alone ([`Self::later_start`]) that gives
    /// way as `run` judges the test ([`crate::trust::COLLAPSED_SHARE`]), instead of after every
    /// stage and method has run on it: a tire on its edge, in soft StVK, was told after
    /// 20 minutes.
    fn gives_way(c: &crate::run::Compression) -> Option<String> {
        c.gives_way().then(|| {
            format!(
                "under gravity alone, with no other load, the full simulation squeezes {:.1} % of \
                 the body's volume under half its rest volume by t = {:.2} s (elements inverted \
                 in {} of its first {} frames): the body gives way under its own weight as \
                 pinned, so the training data and the test hold a crushed body, and every method \
                 is measured against it; {}",
                100.0 * c.squeezed_share,
                c.squeezed_time,
                c.inverted_frames,
                c.frames,
                crate::trust::keeps_it_solid(c.inversion_safe)
            )
        })
    }

    /// Whether a body stands on its pins (they hold it from below: its centre of mass lies
    /// [`STANDS_ABOVE`] of its height or more above theirs, against gravity) and a run under
    /// gravity alone moves it [`FALLS_OVER`] of its bounding-box diagonal (`size`) or further:
    /// it falls over or folds about them instead of standing, which the `snapshots` line says.
    /// A tester's soft bear on two pinned soles fell backwards, every method 33 % off its test
    /// drag with nothing said but the line's figure (4.6 % ten times as stiff). Not a warning:
    /// AutoDef's catapult folds so too (157 %), its methods 1.6 % off.
    fn falls_over(model: &FullSpaceModel, c: &crate::run::Compression, size: f64) -> bool {
        let g = model.gravity.norm();
        if !(g > 0.0 && size > 0.0 && c.travel >= FALLS_OVER * size) || model.pinned.is_empty() {
            return false;
        }
        let up = -model.gravity / g;
        let height = |v: usize| model.mesh.vertices[v].dot(&up);
        // The centre of mass's height, each vertex weighed by its lumped mass.
        let masses = &model.mass.lumped;
        let mass: f64 = masses.iter().sum();
        let centre = masses
            .iter()
            .enumerate()
            .map(|(v, m)| m * height(v))
            .sum::<f64>()
            / mass;
        let pins = model.pinned.iter().map(|&v| height(v)).sum::<f64>() / model.pinned.len() as f64;
        let (lo, hi) = (0..model.mesh.num_vertices())
            .map(height)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| {
                (l.min(y), h.max(y))
            });
        mass > 0.0 && centre - pins >= STANDS_ABOVE * (hi - lo)
    }

    /// What to say at once of a run under gravity alone that carries the body
    /// [`crate::trust::BEYOND_SWING`] times its bounding-box diagonal (`size`) or further, as
    /// `run` says of a test only after every stage: a tester's soft coil spring hung from its
    /// top stretched to 4.5 times its size, said a minute later by the `snapshots` line's
    /// figure alone and warned of at the end of `run`.
    fn beyond_swing(c: &crate::run::Compression, size: f64) -> Option<String> {
        (size > 0.0 && c.travel >= crate::trust::BEYOND_SWING * size).then(|| {
            let units =
                crate::scene::unit_hint(size).map_or(String::new(), |u| format!("{u}; else "));
            format!(
                "under gravity alone, with no other load, the full simulation moves the body up \
                 to {:.3} m at t = {:.2} s, {:.0} % of its {:.3} m bounding-box diagonal: more \
                 than {} times its size, beyond any swing about its pins, so it stretches that \
                 far or passes through itself or its pins (the simulation has no contact), and \
                 the training data and the test hold that motion; {units}pins that hold more \
                 of it or a stiffer material (`[material] youngs_modulus`) keep it up",
                c.travel,
                c.travel_time,
                100.0 * c.travel / size,
                size,
                crate::trust::BEYOND_SWING,
            )
        })
    }

    /// `set`, or an error saying why it holds no frame at all (every schedule failed at its
    /// first step) and what to change.
    fn some_frames(&self, set: SnapshotSet) -> Result<SnapshotSet> {
        match set.stopped.first() {
            Some(s) if set.num_frames() == 0 => bail!(
                "{}: stage snapshots: every training schedule's full-space solve failed at its \
                 first step (schedule {}: {}); milder loads (`[training] offset`, `stiffness`), a \
                 smaller `[time] step` or a larger `[solver] max_iterations` would let it start",
                self.scene.source,
                s.index,
                s.error
            ),
            _ => Ok(set),
        }
    }

    fn simulate_shard(
        &self,
        cfg: &ScheduleConfig,
        shard: (usize, usize),
        progress: Progress<'_>,
    ) -> Result<SnapshotSet> {
        if let Some(why) = self.scene.unsupported_in_stages() {
            bail!("{}: {why}", self.scene.source);
        }
        let total = shard_len(cfg.schedules, shard);
        // Said before the schedules' minutes, not when the last of them runs out of memory.
        let frames = total.saturating_mul(cfg.frames_per_schedule);
        if let Some(problem) = snapshot_memory_problem(
            frames,
            self.model.dofs.num_free(),
            cfg.frames_per_schedule,
            machine_memory(),
        ) {
            bail!("{}: {problem}", self.scene.source);
        }
        // Computed beside the schedules from rest; its reason is kept for the stage's line.
        let why = std::sync::Mutex::new(None);
        let (scene, model) = (self.scene, &self.model);
        let later = || {
            Self::later_start(scene, model).map(|(later, gives_way)| {
                if let Some(w) = gives_way {
                    warn_once(&format!("{}: {w}", scene.source));
                }
                later.map(|(start, reason)| {
                    *why.lock().unwrap_or_else(|e| e.into_inner()) = Some(reason);
                    start
                })
            })
        };
        let mut set = snapshots::generate_from(
            model,
            cfg,
            &scene.time,
            &scene.solver,
            shard,
            Some(&later),
            &|done| progress(done, total),
        )
        .map_err(|e| anyhow::anyhow!("{}: stage snapshots: {e}", scene.source))?;
        set.later_start = why.into_inner().unwrap_or_else(|e| e.into_inner());
        Ok(set)
    }

    /// Simulates shard `index` of `count` and stores it as a partial artifact (for cluster
    /// array jobs); [`merge_shards`](Self::merge_shards) combines them.
    pub fn snapshot_shard(
        &mut self,
        index: usize,
        count: usize,
        progress: Progress<'_>,
    ) -> Result<PathBuf> {
        if count == 0 || index >= count {
            bail!("--shard {index}/{count}: need 0 ≤ index < count");
        }
        let schedules = self.scene.training().schedules;
        if shard_len(schedules, (index, count)) == 0 {
            // Written all the same: a merge reads every shard 0..count.
            warn_once(&format!(
                "{}: shard {index}/{count} holds no schedule: the scene trains on {schedules} \
                 schedule{}, one to each of the first {schedules} shards, so more than \
                 {schedules} shards leave some idle (`[training] schedules` sets the count)",
                self.scene.source,
                if schedules == 1 { "" } else { "s" },
            ));
        }
        let key = KeyBuilder::new(Stage::SnapshotsShard)
            .mix_key(self.snapshots_key())
            .mix(&(index, count))
            .finish();
        self.stage(Stage::SnapshotsShard, key, |p| {
            p.simulate_shard(&p.scene.training(), (index, count), progress)
        })?;
        Ok(self.path(Stage::SnapshotsShard, key))
    }

    /// Merges shards `0..count` into the `snapshots` artifact (identical to an unsharded run).
    pub fn merge_shards(&mut self, count: usize) -> Result<Arc<SnapshotSet>> {
        let key = self.snapshots_key();
        self.stage(Stage::Snapshots, key, |p| {
            let mut parts = Vec::with_capacity(count);
            for index in 0..count {
                let k = KeyBuilder::new(Stage::SnapshotsShard)
                    .mix_key(key)
                    .mix(&(index, count))
                    .finish();
                let path = p.path(Stage::SnapshotsShard, k);
                let part: SnapshotSet = artifact::load(
                    &path,
                    Expect {
                        stage: Stage::SnapshotsShard,
                        key: Some(k),
                        mesh: Some(p.mesh_hash),
                    },
                )
                .map_err(|e| {
                    anyhow::anyhow!(
                        "shard {index}/{count} is missing or unusable ({}); run `cargo xtask snapshots --shard {index}/{count}`",
                        e.problem()
                    )
                })?;
                parts.push(part);
            }
            let set =
                SnapshotSet::merge(parts).map_err(|e| anyhow::anyhow!("merging shards: {e}"))?;
            p.some_frames(set)
        })
    }

    /// Stage `pca`: the mass-orthonormal basis of the snapshots (which are loaded or computed
    /// only when the basis itself is not cached).
    pub fn pca(&mut self, progress: Progress<'_>) -> Result<Arc<PcaFit>> {
        let key = self.pca_key();
        self.stage(Stage::Pca, key, |p| {
            let snaps = p.snapshots(progress)?;
            let mass: Vec<f64> = p
                .model
                .dofs
                .free
                .iter()
                .map(|&d| p.model.mass.lumped[d / 3])
                .collect();
            let mat =
                faer::MatRef::from_column_major_slice(&snaps.data, snaps.dim, snaps.num_frames());
            let err = |e: pca::PcaError| match e {
                // A fixed count past the poses the snapshots kept (schedules that stopped
                // early keep fewer than the scene's check counted).
                pca::PcaError::DimensionOutOfRange {
                    requested,
                    available,
                } if p.scene.pca.dimension == Some(requested) => {
                    if available < snaps.num_frames() {
                        anyhow::anyhow!(
                            "{}: `pca.dimension` = {requested} is more than the mesh's \
                             {available} free coordinates: give at most {available}, or a finer \
                             mesh",
                            p.scene.source
                        )
                    } else {
                        anyhow::anyhow!(
                            "{}: `pca.dimension` = {requested} is more than the {available} \
                             training poses the snapshots hold can span: give at most \
                             {available}, or more `[training] schedules` or \
                             `frames_per_schedule`",
                            p.scene.source
                        )
                    }
                }
                e => anyhow::anyhow!("{}: stage pca: {e}", p.scene.source),
            };
            let mut fit = PcaBasis::fit(mat, Some(&mass), &p.scene.pca, 3).map_err(err)?;
            if p.scene.pca.norm == pca::BasisNorm::Step {
                let op = fem_core::step_norm::StepOperator::new(&p.model, p.scene.time.step)?;
                fit.basis = fit
                    .basis
                    .refit_in_norm(mat, |s| {
                        let cols: Vec<Vec<f64>> = (0..s.ncols())
                            .into_par_iter()
                            .map(|j| {
                                let x: Vec<f64> = s.col(j).iter().copied().collect();
                                let mut y = vec![0.0; x.len()];
                                op.apply(&x, &mut y);
                                y
                            })
                            .collect();
                        faer::Mat::from_fn(s.nrows(), s.ncols(), |i, j| cols[j][i])
                    })
                    .map_err(err)?;
            }
            let count = p.gravity_directions();
            if count > 0 {
                let onset = fem_core::step_norm::gravity_onset(&p.model, &p.scene.time, count)
                    .map_err(|e| {
                        anyhow::anyhow!("{}: stage pca, gravity directions: {e}", p.scene.source)
                    })?;
                let (basis, new) = fit
                    .basis
                    .extended(&onset, GRAVITY_DIRECTION_NEW)
                    .map_err(err)?;
                // By default only where the basis misses how the body starts to fall.
                fit.fall_missed = new.first().copied();
                let missed = fit.fall_missed.is_some_and(|f| f >= GRAVITY_ONSET_MISSED);
                if missed || p.scene.pca.gravity_directions.is_some() {
                    fit.appended = basis.k() - fit.basis.k();
                    fit.basis = basis;
                }
            }
            let patches = p.patch_responses();
            if patches > 0 {
                let responses = p.patch_response_columns(patches).map_err(|e| {
                    anyhow::anyhow!("{}: stage pca, patch responses: {e}", p.scene.source)
                })?;
                // In the patches' order (spread over the surface, each the farthest from those
                // before it), at most a tenth of the basis: on a small mesh most patches' local
                // responses are partly new (117 of 144 over 3 % on a 748-vertex bar, which
                // doubled its basis for 0.2 point of `pca`'s error). Taking the most new first
                // instead covered the toy's test drag worse (subspace error 1.18 against 0.95 %,
                // `pca` 23 against 8 %).
                let most = fit.basis.k().div_ceil(PATCH_RESPONSE_SHARE);
                let (basis, _) = fit
                    .basis
                    .extended_at_most(&responses, PATCH_RESPONSE_NEW, most)
                    .map_err(err)?;
                fit.responses = basis.k() - fit.basis.k();
                fit.basis = basis;
            }
            Ok(fit)
        })
    }

    /// The scene's `[pca] patch_responses`, or [`pca::DEFAULT_PATCH_RESPONSES`].
    pub fn patch_responses(&self) -> usize {
        self.scene
            .pca
            .patch_responses
            .unwrap_or(pca::DEFAULT_PATCH_RESPONSES)
    }

    /// The static responses A⁻¹Gᵀ to a unit load along each axis spread over each of the first
    /// `patches` surface patches the training family grabs (spread over the surface), A =
    /// K₀ + M/T² as the schedules' stiffness probe: three columns of free DOFs per patch.
    ///
    /// # Errors
    /// When the stiffness probe cannot be factorised.
    pub fn patch_response_columns(&self, patches: usize) -> Result<Vec<Vec<f64>>> {
        use fem_core::snapshots::{PatchPlacement, ScheduleConfig, ScheduleKind, StiffnessProbe};
        let family = ScheduleConfig {
            kinds: vec![ScheduleKind::Pull],
            patches: PatchPlacement::Spread,
            ..self.scene.training()
        };
        let step = self.scene.time.step;
        let probe = StiffnessProbe::new(&self.model, family.frames_per_schedule as f64 * step)?;
        let n = self.model.dofs.num_free();
        let mut columns = Vec::with_capacity(3 * patches);
        for i in 0..patches {
            // A body whose surface is pinned everywhere has no patch to load.
            let Some(vertices) = family.patch(&self.model, i) else {
                break;
            };
            let (_, response) = probe.patch_response(&self.model, &vertices);
            columns.extend(response.chunks_exact(n).map(<[f64]>::to_vec));
        }
        Ok(columns)
    }

    /// The scene's `[pca] gravity_directions`, or [`DEFAULT_GRAVITY_DIRECTIONS`] under gravity.
    pub fn gravity_directions(&self) -> usize {
        if self.model.gravity.norm() == 0.0 {
            return 0;
        }
        self.scene
            .pca
            .gravity_directions
            .unwrap_or(DEFAULT_GRAVITY_DIRECTIONS)
    }

    /// Stage `cubature`: a weighted element set reproducing the PCA subspace's reduced elastic
    /// forces over the snapshots, with its error on the held-out test trajectory. Forces are
    /// compared in the step's compliance norm, δfᵀ(WᵀÂW)⁻¹δf (docs/numerics.md).
    pub fn cubature(&mut self, progress: Progress<'_>) -> Result<Arc<FittedCubature>> {
        let key = self.cubature_key();
        self.stage(Stage::Cubature, key, |p| p.fit_cubature(false, progress))
    }

    /// Stage `cubature-neural`: the same for the autoencoder's subspace, with reduced forces
    /// WᵀUᵀf at the decoded poses z = encode(q), W = [J(z) | V] the decoder's Jacobian and the
    /// complement directions beside it.
    pub fn cubature_neural(&mut self, progress: Progress<'_>) -> Result<Arc<FittedCubature>> {
        let key = self.cubature_neural_key();
        self.stage(Stage::CubatureNeural, key, |p| {
            let tangent = p.fit_cubature(true, progress)?;
            p.validated_neural_rule(tangent, progress)
        })
    }

    /// The neural methods' rule: `tangent` (fitted in the decoder's tangent), or the PCA
    /// subspace's where that keeps `neural-cubature` clearly closer to the full trajectories of
    /// a few training schedules ([`RuleValidation`], [`pca_rule_clearly_closer`]). The two disagree on which is better from mesh to
    /// mesh: the PCA rule fits every coordinate's force at every pose, so it holds wherever the
    /// decoder's tangent turns; the tangent's fits fewer forces, and is the closer where the
    /// tangent stays near the training poses'. (A nearly incompressible finger: 0.7 % with the
    /// PCA rule against 6.2 %; AutoDef's X in StVK: 2.9 against 1.1 %.)
    fn validated_neural_rule(
        &mut self,
        tangent: FittedCubature,
        progress: Progress<'_>,
    ) -> Result<FittedCubature> {
        let pca = self.cubature(progress)?;
        let snaps = self.snapshots(progress)?;
        let schedules = validation_schedules(&snaps);
        if schedules.len() < 2 || pca.rule == tangent.rule {
            return Ok(tangent);
        }
        let tangent = Arc::new(tangent);
        // Each schedule's first frame in the snapshots, its frames and its forces.
        let cfg = self.scene.training();
        let h = self.scene.time.step;
        let probe = StiffnessProbe::new(&self.model, cfg.frames_per_schedule as f64 * h)?;
        let runs: Vec<_> = schedules
            .iter()
            .filter_map(|&s| {
                let at = snaps.schedules.iter().position(|&x| x == s)?;
                let first = snaps.frames[..at].iter().sum();
                // A schedule that fell along its own direction (`[training] gravity = "any"`)
                // is run under that gravity.
                let turned = cfg
                    .turned_gravity(&self.model, s)
                    .map(|g| (g * cfg.gravity_scale).into());
                Some((
                    first,
                    snaps.frames[at],
                    cfg.schedule(&self.model, &probe, s, h),
                    turned,
                ))
            })
            .collect();
        // A rule the model cannot be built or stepped with is not tried: the tangent's is kept,
        // and the stage says why.
        let (tangent_errors, pca_errors) = match self
            .rule_errors_on_training(&tangent, &runs, 0, progress)
            .and_then(|t| {
                Ok((
                    t,
                    self.rule_errors_on_training(&pca, &runs, runs.len(), progress)?,
                ))
            }) {
            Ok(errors) => errors,
            Err(e) => {
                tracing::warn!(
                    "{}: stage cubature-neural: the rules could not be run on training \
                     schedules ({e:#}); keeping the rule fitted in the decoder's tangent",
                    self.scene.source
                );
                return Ok(Arc::unwrap_or_clone(tangent));
            }
        };
        progress(2 * runs.len(), 2 * runs.len());
        let validation = RuleValidation {
            schedules,
            pca_kept: pca_rule_clearly_closer(&tangent_errors, &pca_errors),
            tangent_errors,
            pca_errors,
            tangent_elements: tangent.rule.len(),
            pca_elements: pca.rule.len(),
        };
        let mut kept = if validation.pca_kept {
            (*pca).clone()
        } else {
            Arc::unwrap_or_clone(tangent)
        };
        kept.validation = Some(validation);
        Ok(kept)
    }

    /// `neural-cubature` with the rule `rule` on each of the training `schedules` from rest
    /// (`(first frame, frames, forces, turned gravity)` of each in the snapshots, the last for a
    /// schedule that fell along its own direction): the mean over its frames of
    /// ‖q − q_full‖ / ‖q_full‖, q the PCA coefficients (those of the recorded full-space frames
    /// projected on the basis); infinite when a step fails. One runtime runs them all, reset
    /// between them, so that its springs' patch compliance is factorised once.
    fn rule_errors_on_training(
        &mut self,
        rule: &Arc<FittedCubature>,
        schedules: &[ScheduleRun],
        done: usize,
        progress: Progress<'_>,
    ) -> Result<Vec<f64>> {
        use latent_sim::Interactive as _;
        let snaps = self.snapshots(progress)?;
        let fit = self.pca(progress)?;
        let scene = self.scene;
        let method = crate::simulate::Method::NeuralCubature;
        let mut model = self.model.clone();
        model.forces.clear();
        // Training without gravity switches it off in the runtime rather than in the model, whose
        // gravity-onset directions (part of the subspace the test runs) need it.
        let scale = scene.training().gravity_scale;
        if scale > 0.0 {
            model.scale_gravity(scale);
        }
        let reduced = crate::export::reduced_model_with(
            self,
            method,
            &model,
            &scene.material,
            &scene.time,
            crate::simulate::solver_for(scene, method),
            latent_sim::model::Rows::Used,
            progress,
            Some(rule.clone()),
        )?;
        let mut runtime = reduced.simulator()?;
        runtime.set_gravity(scale > 0.0);
        let mut errors = Vec::with_capacity(schedules.len());
        let mut q_full = vec![0.0; fit.basis.k()];
        let along_scene = runtime.gravity_acceleration();
        for (i, (first, frames, forces, turned)) in schedules.iter().enumerate() {
            // The stage's bar counts both rules' runs (and Ctrl-C in Python stops there).
            progress(done + i, 2 * schedules.len());
            runtime.reset();
            runtime.set_gravity_acceleration(turned.unwrap_or(along_scene))?;
            let handles = forces
                .iter()
                .map(|f| runtime.add_force(f.clone()))
                .collect::<Result<Vec<_>, _>>()?;
            let (mut sum, mut count) = (0.0, 0usize);
            for t in 0..*frames {
                if runtime.step_report().is_err() {
                    (sum, count) = (f64::INFINITY, 1);
                    break;
                }
                fit.basis.project(snaps.frame(first + t), &mut q_full);
                let norm = q_full.iter().map(|x| x * x).sum::<f64>().sqrt();
                if norm > 0.0 {
                    let q = runtime.coefficients();
                    let diff = q
                        .iter()
                        .zip(&q_full)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum::<f64>()
                        .sqrt();
                    sum += diff / norm;
                    count += 1;
                }
            }
            for handle in handles {
                runtime.release(handle)?;
            }
            errors.push(if count > 0 { sum / count as f64 } else { 0.0 });
        }
        Ok(errors)
    }

    pub fn cubature_neural_key(&self) -> u64 {
        // The complement directions are fitted beside the decoder's tangent (in the step's
        // compliance norm their stiffness no longer lets them dominate).
        let mut key = KeyBuilder::new(Stage::CubatureNeural)
            .mix_key(self.cubature_key())
            .mix_key(self.train_key());
        if self.scene.reduced.complement_directions != Some(0) {
            key = key
                .mix_key(self.complement_key())
                .mix(&self.scene.reduced.complement_directions);
        }
        // The rule kept after both ran on training schedules with the reduced solver (since
        // 2026-12-02, stop 60): its settings, and the choice's.
        // Defaults written out are the defaults (`current-state` is what `auto` means).
        let mut reduced = self.scene.reduced.clone();
        if reduced.onset_directions == Some(self.default_onset_directions()) {
            reduced.onset_directions = None;
        }
        if reduced.preconditioner == latent_sim::Preconditioning::CurrentState {
            reduced.preconditioner = latent_sim::Preconditioning::Auto;
        }
        key = key
            .mix(&reduced)
            .mix(&self.scene.reduced.solver(&self.scene.solver))
            .mix(&(VALIDATION_SCHEDULES, RULE_MARGIN));
        // Mixed in only when given, so that the keys of scenes without it stay as they were.
        if let Some(t) = self.scene.cubature.neural_tolerance {
            key = key.mix(&t);
        }
        key.finish()
    }

    fn fit_cubature(&mut self, neural: bool, progress: Progress<'_>) -> Result<FittedCubature> {
        let snaps = self.snapshots(progress)?;
        let fit = self.pca(progress)?;
        let reference = self.reference(0, progress)?;
        let trained = if neural {
            Some(self.train(progress)?)
        } else {
            None
        };
        let basis = &fit.basis;
        let k = basis.k();
        let columns = basis_columns(basis);
        let cfg = &if neural {
            self.scene.cubature.for_neural()
        } else {
            self.scene.cubature.for_linear()
        };
        let err = |e: cubature::CubatureError| {
            anyhow::anyhow!("{}: stage cubature: {e}", self.scene.source)
        };
        // The complement directions C beside the decoder (neural methods), orthonormal in q.
        let beside = if neural {
            self.complement_columns(progress)?
        } else {
            Vec::new()
        };
        // Poses in the subspace: q itself, or f + CCᵀ(q − f) with f = decode(encode(q)) and the
        // decoder Jacobian at encode(q): the point of the neural subspace with its linear
        // directions nearest q, as the reduced simulation visits them. (At f alone the rule
        // never saw the complement's part of a pose: X high 3.8 against 2.3 %, AutoDef's bar 5.3
        // against 4.9 %.)
        let poses = |frames: faer::MatRef<'_, f64>| -> (faer::Mat<f64>, Vec<faer::Mat<f64>>) {
            let q = basis.project_matrix(frames);
            let Some(t) = &trained else {
                return (q, Vec::new());
            };
            let ae = &t.model;
            let d = ae.latent_dim();
            let mut ws = ae.workspace();
            let (mut z, mut qh, mut jac) = (vec![0.0; d], vec![0.0; k], vec![0.0; k * d]);
            let mut decoded = faer::Mat::<f64>::zeros(k, q.ncols());
            let mut jacobians = Vec::with_capacity(q.ncols());
            for j in 0..q.ncols() {
                let col: Vec<f64> = (0..k).map(|i| q[(i, j)]).collect();
                ae.encode(&col, &mut z, &mut ws);
                ae.decode(&z, &mut qh, &mut ws);
                ae.decode_jacobian(&z, &mut jac, &mut ws);
                complete(&beside, &col, &mut qh);
                for i in 0..k {
                    decoded[(i, j)] = qh[i];
                }
                jacobians.push(faer::Mat::from_fn(k, d, |r, c| jac[c * k + r]));
            }
            (decoded, jacobians)
        };
        // The forces are fitted in the norm of the displacement they make in one step: each
        // pose's tangent W (I, or [J | C] with the complement directions C beside the decoder's
        // Jacobian) is replaced by W F with FFᵀ = (WᵀÂW)⁻¹, so the rule's relative error is
        // ‖δf‖ in (WᵀÂW)⁻¹ over ‖f‖ in it. The two gravity-onset directions are left out of the
        // fit: with them the suite's neural rules took 5–18 % more elements and ended 0.1–0.4
        // points further off on three meshes of four (docs/numerics.md).
        let step = self.reduced_step_operator(&columns, k)?;
        // For PCA the whitening is one change of basis: U F with coefficients FᵀÂq (Â is
        // positive definite, so F is invertible and UF·FᵀÂq = Uq), and no pose needs a tangent.
        let whitened_basis = (!neural).then(|| {
            let f = whitened(faer::Mat::<f64>::identity(k, k).as_ref(), step.as_ref());
            let nf = columns.len() / k;
            let uf = faer::MatRef::from_column_major_slice(&columns, nf, k) * &f;
            (column_major(uf.as_ref()), f.transpose() * &step)
        });
        let tangents = |jacobians: &[faer::Mat<f64>]| -> Vec<faer::Mat<f64>> {
            let c = beside.len() / k;
            jacobians
                .iter()
                .map(|j| {
                    let d = j.ncols();
                    let w = faer::Mat::<f64>::from_fn(k, d + c, |r, col| {
                        if col < d {
                            j[(r, col)]
                        } else {
                            beside[(col - d) * k + r]
                        }
                    });
                    whitened(w.as_ref(), step.as_ref())
                })
                .collect()
        };
        // Only the training frames the fit keeps are formed into poses: a neural pose carries a
        // k × d Jacobian and its tangent, which over every frame of a small mesh's training set
        // took 1.6 GB (a 496-tet sheet, k = 252).
        let kept = cubature::kept_poses(snaps.num_frames(), cfg);
        let s = faer::Mat::<f64>::from_fn(snaps.dim, kept.len(), |i, j| {
            snaps.data[kept[j] * snaps.dim + i]
        });
        let s = s.as_ref();
        let held: Vec<f64> = reference.frames.iter().flatten().copied().collect();
        let h = faer::MatRef::from_column_major_slice(&held, snaps.dim, reference.frames.len());
        // The training poses and the held-out test's frames, each as coefficients in the
        // whitened basis (PCA) or as coefficients with their whitened tangents (neural).
        let pose_set = |frames| -> (faer::Mat<f64>, Vec<faer::Mat<f64>>) {
            let (q, jacobians) = poses(frames);
            match &whitened_basis {
                Some((_, to)) => (to * &q, Vec::new()),
                None => (q, tangents(&jacobians)),
            }
        };
        let (q_train, tan_train) = pose_set(s);
        let (q_held, tan_held) = pose_set(h);
        let basis_used = whitened_basis
            .as_ref()
            .map_or(&columns[..], |(b, _)| &b[..]);
        let refs_train: Vec<_> = tan_train.iter().map(|m| m.as_ref()).collect();
        let refs_held: Vec<_> = tan_held.iter().map(|m| m.as_ref()).collect();
        let p_held = cubature_poses(&q_held, &refs_held);
        let mut held =
            cubature::HeldOutForces::new(&self.model, basis_used, k, p_held, cfg).map_err(err)?;
        let start = Instant::now();
        let p_train = cubature_poses(&q_train, &refs_train).kept_of(snaps.num_frames());
        let train = cubature::TrainingMatrix::build(&self.model, basis_used, k, p_train, cfg)
            .map_err(err)?;
        // The held-out error along the greedy path, at element counts about 20 % apart (its
        // time left out of the fit's).
        let mut held_out_curve = Vec::new();
        let mut next = 1;
        let mut held_seconds = 0.0;
        let mut held_failed = None;
        // The bar counts elements against the budget; a rule that meets its tolerance first
        // ends it short, and the bar is then filled.
        let budget = cfg.max_elements.max(1);
        let rule = cubature::fit_with_progress(&train, cfg, &mut |p| {
            progress(p.elements.min(budget - 1), budget);
            if p.elements >= next {
                let t = Instant::now();
                match held.relative_error(p.selected, p.weights) {
                    Ok(e) => held_out_curve.push((p.elements, e)),
                    Err(e) => held_failed = held_failed.take().or(Some(e)),
                }
                held_seconds += t.elapsed().as_secs_f64();
                next = p.elements + 1 + p.elements / 5;
            }
        })
        .map_err(err)?;
        progress(budget, budget);
        if let Some(e) = held_failed {
            return Err(err(e));
        }
        let fit_seconds = start.elapsed().as_secs_f64() - held_seconds;
        let held_out_error = held
            .relative_error(&rule.elements, &rule.weights)
            .map_err(err)?;
        if held_out_curve.last().is_none_or(|&(n, _)| n != rule.len()) {
            held_out_curve.push((rule.len(), held_out_error));
        }
        Ok(FittedCubature {
            rule,
            held_out_error,
            held_out_curve,
            fit_seconds,
            poses: train.num_poses(),
            candidates: (train.num_columns() < train.num_elements()).then(|| train.num_columns()),
            validation: None,
        })
    }

    /// Â = UᵀAU (k×k) for the basis columns U (free DOFs × k, column-major), A = K₀ + M/h² the
    /// implicit step's operator at rest (K₀ alone for a quasi-static scene).
    fn reduced_step_operator(&self, columns: &[f64], k: usize) -> Result<faer::Mat<f64>> {
        let h = if self.scene.time.quasi_static {
            f64::INFINITY
        } else {
            self.scene.time.step
        };
        let op = fem_core::step_norm::StepOperator::new(&self.model, h)
            .with_context(|| format!("{}: stage cubature", self.scene.source))?;
        let n = self.model.dofs.num_free();
        let mut au = vec![0.0; n * k];
        au.par_chunks_mut(n)
            .zip(columns.par_chunks(n))
            .for_each(|(y, x)| op.apply(x, y));
        let u = faer::MatRef::from_column_major_slice(columns, n, k);
        Ok(u.transpose() * faer::MatRef::from_column_major_slice(&au, n, k))
    }

    /// Stage `train`: the autoencoder on the snapshots' PCA coefficients, the basis frozen.
    pub fn train(&mut self, progress: Progress<'_>) -> Result<Arc<TrainedModel>> {
        let key = self.train_key();
        self.stage(Stage::Train, key, |p| {
            let snaps = p.snapshots(progress)?;
            let fit = p.pca(progress)?;
            let basis = &fit.basis;
            let s =
                faer::MatRef::from_column_major_slice(&snaps.data, snaps.dim, snaps.num_frames());
            let q = basis.project_matrix(s);
            let error_of = |ae: &nn::Autoencoder| -> f64 {
                match ae.reconstruct_batch(q.as_ref()) {
                    Ok(qh) => max_vertex_distance(basis.basis_ref(), qh.as_ref(), s),
                    Err(_) => f64::INFINITY,
                }
            };
            let start = Instant::now();
            let k = basis.k();
            let source = &p.scene.source;
            let mut cfg = p.scene.autoencoder.clone();
            // Validation on whole schedules the network never trained on: early stopping and
            // the kept weights then judge it on loads it has not seen, as the test's drag is.
            // With the retraining below, a 29k-tet torus's neural subspace missed 0.28 % of the
            // test instead of 0.42 % (`neural` 7.9 → 5.7 %; docs/results-suite.md, stop 45).
            cfg.validation_groups = snaps.frames.clone();
            let mut latent_choice = None;
            match (cfg.latent_dim, cfg.latent_dims) {
                (None, None) => {
                    let d = default_latent_dim(k);
                    latent_choice = Some(format!(
                        "the default, half the PCA dimension within [{}, k]; \
                         `[autoencoder] latent_dim` sets it",
                        nn::DEFAULT_LATENT_DIM.min(k)
                    ));
                    cfg.latent_dim = Some(d);
                }
                _ => {
                    if let Some(problem) = latent_dim_refusal(&cfg, k) {
                        bail!("{source}: {problem}");
                    }
                }
            }
            // One count over every network a search may train (d = lo, lo + 1, …), so that it
            // grows from network to network instead of starting again at each (a tester's bar
            // read "529 … 494 … 342 … 165 of 1000", a stall to the eye); a search that meets
            // its tolerance early ends the count there.
            let (first, networks) = match (cfg.latent_dim, cfg.latent_dims) {
                (None, Some([lo, hi])) => (lo, hi.saturating_sub(lo) + 1),
                (d, _) => (d.unwrap_or(0), 1),
            };
            let reported = std::cell::Cell::new((0, 0));
            let search = nn::train_search(q.as_ref(), &cfg, error_of, |d, r| {
                let done = d.saturating_sub(first) * r.epochs + r.epoch;
                let total = networks * r.epochs;
                reported.set((done, total));
                progress(done, total)
            })
            .map_err(|e| anyhow::anyhow!("{}: stage train: {e}", p.scene.source))?;
            // Training that stops early for want of improvement ends before its last epoch:
            // the stage still reports its end, where a progress bar finishes.
            if let (done, total) = reported.get()
                && done < total
            {
                progress(total, total);
            }
            let chosen = search.chosen_trial();
            let d = chosen.latent_dim;
            if let (Some([lo, hi]), Some(tolerance)) = (cfg.latent_dims, cfg.max_vertex_error) {
                latent_choice = Some(if search.tolerance_met {
                    format!(
                        "the smallest in [{lo}, {hi}] whose worst vertex error over the \
                         snapshots met `[autoencoder] max_vertex_error` = {tolerance:e}"
                    )
                } else {
                    // A range that already reaches k cannot widen (a tester widened it to k
                    // and was told the same again).
                    let more = if hi >= k {
                        format!(
                            "the range reaches k = {k} already: more PCA coefficients \
                             (`[pca] max_vertex_error` = {tolerance:e} sizes the basis for it) \
                             may meet it"
                        )
                    } else {
                        "a wider range, or more PCA coefficients, may meet it".to_string()
                    };
                    format!(
                        "none in [{lo}, {hi}] met `[autoencoder] max_vertex_error` = \
                         {tolerance:e}: d = {d} came closest in the search, {:.3e} off; {more}",
                        chosen.error
                    )
                });
            }
            // Then every schedule, the held-out ones too, for as many epochs as the held-out
            // ones judged best: a schedule held out may be the only one that grabs a limb.
            // Where no epoch beat the start (PCA's truncation to d, through the linear skip)
            // on the held-out schedules, the start is kept as judged.
            let by_schedule =
                cfg.held_out_groups(q.ncols()).is_some() && chosen.outcome.best_epoch > 0;
            let mut retrain_missed = None;
            let (model, error, retrained_epochs) = if by_schedule {
                let epochs = chosen.outcome.best_epoch.max(1);
                let all = nn::AutoencoderConfig {
                    latent_dim: Some(d),
                    latent_dims: None,
                    max_vertex_error: None,
                    epochs,
                    validation_fraction: 0.0,
                    validation_groups: Vec::new(),
                    patience: 0,
                    ..cfg.clone()
                };
                let outcome = nn::train(q.as_ref(), d, &all, |_| {})
                    .map_err(|e| anyhow::anyhow!("{}: stage train: {e}", p.scene.source))?;
                let error = error_of(&outcome.model);
                tracing::info!(
                    judged = chosen.error,
                    retrained = error,
                    "worst vertex errors over every snapshot"
                );
                // Both are judged on every snapshot, the held-out schedules' too. The network
                // trained again is kept (it has seen every schedule) unless it breaks the
                // tolerance the judged one met: on a few poses, trained again for a handful of
                // epochs, it can miss them by twice as much (a tester's 80 poses: 1.95e-2
                // against 9.3e-3, where `max_vertex_error` asked for 1e-2). Elsewhere the two
                // differ by a few per cent either way (the catapult 6.45e-3 against 6.29e-3,
                // the default scene 4.866e-2 against 4.868e-2).
                let breaks = cfg
                    .max_vertex_error
                    .is_some_and(|t| search.tolerance_met && error > t);
                if !breaks {
                    (outcome.model, error, Some(epochs))
                } else {
                    retrain_missed = Some(error);
                    (chosen.outcome.model.clone(), chosen.error, None)
                }
            } else {
                (chosen.outcome.model.clone(), chosen.error, None)
            };
            let train_seconds = start.elapsed().as_secs_f64();
            // PCA's error with k columns as far as both comparisons need: to d, and to the
            // first k that matches the autoencoder (one incremental pass; a reconstruction per k
            // took 26 s of a 29k-tet torus's 34 s stage).
            // (The error need not fall with k: a match below d is remembered, not waited for.)
            let matched = std::cell::Cell::new(false);
            let met = |k: usize, e: f64| {
                matched.set(matched.get() || e <= error);
                k >= d && matched.get()
            };
            let per_k = basis.max_group_errors(s, 3, met)?;
            let pca_error_at_latent_dim = d
                .checked_sub(1)
                .and_then(|i| per_k.get(i).copied())
                .unwrap_or(f64::NAN);
            let pca_k_matching = per_k.iter().position(|&e| e <= error).map(|i| i + 1);
            Ok(TrainedModel {
                model,
                latent_dim: d,
                pca_k: basis.k(),
                history: chosen.outcome.history.clone(),
                start_loss: chosen.outcome.start_loss,
                best_epoch: chosen.outcome.best_epoch,
                stopped_early: chosen.outcome.stopped_early,
                trials: search
                    .trials
                    .iter()
                    .map(|t| (t.latent_dim, t.error))
                    .collect(),
                max_vertex_error: error,
                pca_error_at_latent_dim,
                pca_k_matching,
                train_seconds,
                latent_choice,
                retrain_missed,
                hidden_chosen: p.scene.autoencoder.hidden.is_none(),
                retrained_epochs,
            })
        })
    }

    /// Stage `complement`: the directions the trained autoencoder misses in the snapshots
    /// ([`Complement`]), for the neural methods' `[reduced] complement_directions`.
    pub fn complement(&mut self, progress: Progress<'_>) -> Result<Arc<Complement>> {
        let key = self.complement_key();
        self.stage(Stage::Complement, key, |p| {
            let snaps = p.snapshots(progress)?;
            let fit = p.pca(progress)?;
            let trained = p.train(progress)?;
            let s =
                faer::MatRef::from_column_major_slice(&snaps.data, snaps.dim, snaps.num_frames());
            let q = fit.basis.project_matrix(s);
            let qh = trained
                .model
                .reconstruct_batch(q.as_ref())
                .map_err(|e| anyhow::anyhow!("{}: stage complement: {e}", p.scene.source))?;
            let residual = &q - &qh;
            let svd = residual.thin_svd().map_err(|_| {
                anyhow::anyhow!(
                    "{}: stage complement: the SVD of the autoencoder's residuals did not converge",
                    p.scene.source
                )
            })?;
            let u = svd.U();
            let k = q.nrows();
            // ‖S‖²_M = Σσ² over every singular value of M^{1/2}S the fit keeps.
            let snapshot_energy: f64 = fit.basis.singular_values().iter().map(|s| s * s).sum();
            let kept = q.squared_norm_l2();
            Ok(Complement {
                k,
                latent_dim: trained.latent_dim,
                directions: column_major(u),
                singular_values: svd.S().column_vector().iter().copied().collect(),
                snapshot_energy,
                pca_lost_energy: (snapshot_energy - kept).max(0.0),
            })
        })
    }

    /// Stage `coverage`: the ranges of the snapshots' PCA coefficients, which `run` measures
    /// each reduced frame against and a model file carries for its runtime's steps.
    ///
    /// # Errors
    /// When a stage it needs fails.
    pub fn coverage(&mut self, progress: Progress<'_>) -> Result<Arc<crate::coverage::Coverage>> {
        let key = self.coverage_key();
        self.stage(Stage::Coverage, key, |p| {
            crate::coverage::training_poses(p, progress)
        })
    }

    pub fn coverage_key(&self) -> u64 {
        KeyBuilder::new(Stage::Coverage)
            .mix_key(self.pca_key())
            .finish()
    }

    pub fn complement_key(&self) -> u64 {
        KeyBuilder::new(Stage::Complement)
            .mix_key(self.train_key())
            .finish()
    }

    /// One line saying what the neural methods get beside their latent coordinates and why:
    /// the onset and complement directions asked for, by the scene or by default (those the
    /// decoder already spans at rest are dropped when the model is built, so the methods'
    /// dimension in the report can be smaller than their sum).
    ///
    /// # Errors
    /// When a stage the counts need fails.
    pub fn linear_directions_summary(&mut self, progress: Progress<'_>) -> Result<String> {
        let d = self.train(progress)?.latent_dim;
        let onset = self.onset_directions();
        let onset_why = match self.scene.reduced.onset_directions {
            Some(_) => "as `[reduced] onset_directions` says",
            None if onset > 0 => "the default under gravity",
            None => "none without gravity",
        };
        let complement = self.complement_count(progress)?;
        let complement_why = match self.scene.reduced.complement_directions {
            Some(_) => "as `[reduced] complement_directions` says",
            None => "what the data asks for, see stage complement",
        };
        let responses = self.pca(progress)?.responses;
        let responses_text = if responses > 0 {
            format!(", the PCA basis's {responses} patch responses")
        } else {
            String::new()
        };
        // The table's dim is what remains once the model is built.
        let most = (d + onset + complement + responses).min(self.pca(progress)?.basis.k());
        Ok(format!(
            "neural methods: d = {d} latent coordinates, {onset} gravity-onset directions \
             ({onset_why}), {complement} complement directions ({complement_why}){responses_text}: \
             at most {most} coordinates, fewer where a direction lies in the span of the decoder \
             and the others (the table's dim)"
        ))
    }

    /// The scene's `[reduced] onset_directions`, or when absent
    /// [`latent_sim::DEFAULT_ONSET_DIRECTIONS`] under gravity and none without.
    pub fn onset_directions(&self) -> usize {
        self.scene
            .reduced
            .onset_directions
            .unwrap_or_else(|| self.default_onset_directions())
    }

    /// [`Self::onset_directions`] when the scene gives none.
    fn default_onset_directions(&self) -> usize {
        if self.scene.gravity.is_on() {
            latent_sim::DEFAULT_ONSET_DIRECTIONS
        } else {
            0
        }
    }

    /// How many [`Complement`] directions the neural methods take: the scene's `[reduced]
    /// complement_directions`, or when absent [`Complement::default_count`] (no stage run for
    /// an explicit 0).
    ///
    /// # Errors
    /// When the residuals have fewer directions than asked for, or a stage fails.
    pub fn complement_count(&mut self, progress: Progress<'_>) -> Result<usize> {
        if self.scene.reduced.complement_directions == Some(0) {
            return Ok(0);
        }
        let c = self.complement(progress)?;
        let available = c.singular_values.len();
        Ok(match self.scene.reduced.complement_directions {
            Some(count) if count > available => bail!(
                "{}: reduced.complement_directions = {count}, but the autoencoder's residuals \
                 have only {available} directions (the PCA dimension or the number of \
                 snapshots); use at most {available}",
                self.scene.source
            ),
            Some(count) => count,
            None => c.default_count(),
        })
    }

    /// The linear directions beside the decoder, orthonormal in q (k × c, column-major): the
    /// PCA basis's patch-response columns ([`pca::PcaFit::responses`]), then the leading
    /// [`Pipeline::complement_count`] [`Complement`] directions made orthogonal to them (empty,
    /// and no complement stage run, for an explicit 0 and no responses). The autoencoder
    /// learns the snapshots, which hold next to nothing along the responses: without them
    /// beside it the neural subspace would miss what they were appended for.
    ///
    /// # Errors
    /// As [`Pipeline::complement_count`].
    pub fn complement_columns(&mut self, progress: Progress<'_>) -> Result<Vec<f64>> {
        let count = self.complement_count(progress)?;
        let fit = self.pca(progress)?;
        let (k, responses) = (fit.basis.k(), fit.responses);
        let mut columns = Vec::with_capacity(k * (responses + count));
        for j in k - responses..k {
            columns.extend((0..k).map(|i| if i == j { 1.0 } else { 0.0 }));
        }
        if count == 0 {
            return Ok(columns);
        }
        let c = self.complement(progress)?;
        debug_assert_eq!(c.k, k);
        if responses == 0 {
            return Ok(c.directions[..c.k * count].to_vec());
        }
        for direction in c.directions.chunks_exact(c.k).take(count) {
            // Orthogonal to the responses (which zeroes their entries) and the directions kept.
            let mut v = direction.to_vec();
            let norm = pca::orthogonalise(&mut v, &columns, None);
            // A direction (of unit norm) almost inside the span before it adds nothing.
            if norm > 1e-3 {
                columns.extend(v.iter().map(|x| x / norm));
            }
        }
        Ok(columns)
    }

    /// The full-space simulation of test trajectory `trajectory` (cached stage `reference`).
    pub fn reference(
        &mut self,
        trajectory: usize,
        progress: Progress<'_>,
    ) -> Result<Arc<Reference>> {
        let key = self.reference_key(trajectory);
        self.stage(Stage::Reference, key, |p| {
            let cfg = p.scene.test();
            // Said before the test's minutes, not when the last of its frames runs out of memory.
            if let Some(problem) = trajectory_memory_problem(
                cfg.frames_per_schedule,
                p.model.dofs.num_free(),
                machine_memory(),
            ) {
                bail!("{}: {problem}", p.scene.source);
            }
            let model = p.test_model(trajectory)?;
            let time = TimeConfig {
                frames: cfg.frames_per_schedule,
                ..p.scene.time.clone()
            };
            let mut sim = Simulator::new(model, time, p.scene.solver.clone())?;
            let mut r = Reference {
                frames: Vec::new(),
                step_seconds: Vec::new(),
                iterations: Vec::new(),
                switched: Vec::new(),
                stopped: None,
            };
            let mut free = vec![0.0; sim.model.dofs.num_free()];
            for f in 0..cfg.frames_per_schedule {
                let s = match sim.step() {
                    Ok(s) => s,
                    // A solve that fails partway leaves the frames before it as the ground
                    // truth; failing at the first step leaves nothing to compare with.
                    Err(e) if e.is_solve_failure() && f > 0 => {
                        r.stopped = Some(e.to_string());
                        progress(cfg.frames_per_schedule, cfg.frames_per_schedule);
                        break;
                    }
                    Err(e) => bail!(
                        "{}: full-space reference, test trajectory {trajectory}: {e}",
                        p.scene.source
                    ),
                };
                sim.model.dofs.gather(&sim.state.u, &mut free);
                r.frames.push(free.clone());
                r.step_seconds.push(s.wall_seconds);
                r.iterations.push(s.iterations);
                if s.solver_switched {
                    r.switched.push(f + 1);
                }
                progress(f + 1, cfg.frames_per_schedule);
            }
            Ok(r)
        })
    }

    /// Whether this pipeline computed test trajectory `trajectory`'s reference, rather than
    /// loading it from the cache: then the step times it recorded are this process's.
    pub fn reference_computed_here(&self, trajectory: usize) -> bool {
        let path = self.path(Stage::Reference, self.reference_key(trajectory));
        self.outcomes
            .iter()
            .any(|o| o.stage == Stage::Reference && !o.cached && o.path == path)
    }

    /// The model with test trajectory `trajectory`'s forces and gravity in place of the scene's.
    /// Every index has one: trajectory i depends only on the test family's seed and i, not on
    /// `[test] schedules`.
    pub fn test_model(&self, trajectory: usize) -> Result<FullSpaceModel> {
        if let Some(why) = self.scene.unsupported_in_stages() {
            bail!("{}: {why}", self.scene.source);
        }
        let cfg = self.scene.test();
        let mut model = self.model.clone();
        let built = self.test_forces.borrow().get(&trajectory).cloned();
        model.forces = match built {
            Some(forces) => forces,
            None => {
                let probe = StiffnessProbe::new(
                    &self.model,
                    cfg.frames_per_schedule as f64 * self.scene.time.step,
                )?;
                let forces = cfg.schedule(&self.model, &probe, trajectory, self.scene.time.step);
                self.test_forces
                    .borrow_mut()
                    .insert(trajectory, forces.clone());
                forces
            }
        };
        model.scale_gravity(cfg.gravity_scale);
        Ok(model)
    }
}

fn shard_len(total: usize, (index, count): (usize, usize)) -> usize {
    (index..total).step_by(count.max(1)).count()
}

/// This machine's memory in bytes (Linux's `MemTotal`), or `None` where it cannot be read.
fn machine_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Why `frames` training frames of `dim` free coordinates cannot be held on a machine of
/// `memory` bytes: more than half of it (the PCA stage works on a copy), with the schedules that
/// fit at `frames_per_schedule` a schedule. A 60k-tet mesh's 36k free coordinates take 0.5 GiB
/// over the default 32 schedules of 60 frames; 1,000 schedules (16 GiB) ran out of memory only
/// as the last of hours of schedules ended.
fn snapshot_memory_problem(
    frames: usize,
    dim: usize,
    frames_per_schedule: usize,
    memory: Option<u64>,
) -> Option<String> {
    let (bytes, limit, memory) = past_memory(frames, dim, memory?, 2)?;
    let per_schedule = (frames_per_schedule.max(1) as u128) * (dim as u128) * 8;
    Some(format!(
        "the training snapshots would take {:.1} GiB ({frames} frames of {dim} free \
         coordinates), more than half of this machine's {:.1} GiB of memory (the PCA stage works \
         on a copy): at most {} `[training] schedules` of {frames_per_schedule} frames fit, or \
         fewer `frames_per_schedule`",
        gib(bytes),
        gib(memory),
        limit / per_schedule.max(1)
    ))
}

/// The bytes of `frames` frames of `dim` free coordinates, the `1/share` of `memory` they may
/// take, and `memory`, when they take more.
fn past_memory(frames: usize, dim: usize, memory: u64, share: u128) -> Option<(u128, u128, u128)> {
    let bytes = (frames as u128) * (dim as u128) * 8;
    let limit = u128::from(memory) / share;
    (bytes > limit).then_some((bytes, limit, u128::from(memory)))
}

/// `bytes` in GiB.
fn gib(bytes: u128) -> f64 {
    bytes as f64 / f64::from(1u32 << 30)
}

/// Why a test trajectory of `frames` frames of `dim` free coordinates cannot be held in
/// `memory` bytes, if it cannot: `run` holds the reference and each method's trajectory beside
/// it, so a reference may take an eighth of the machine.
fn trajectory_memory_problem(frames: usize, dim: usize, memory: Option<u64>) -> Option<String> {
    let (bytes, limit, memory) = past_memory(frames, dim, memory?, 8)?;
    Some(format!(
        "a test trajectory of {frames} frames of {dim} free coordinates takes {:.1} GiB, and \
             `run` holds one per method beside it: more than this machine's {:.1} GiB of memory \
             allow; at most {} `[test] frames_per_schedule` fit",
        gib(bytes),
        gib(memory),
        limit / (dim.max(1) as u128 * 8)
    ))
}

/// Largest ‖u_v − (U q̂)_v‖ over vertices v and snapshot columns, with u the snapshots.
fn max_vertex_distance(
    basis: faer::MatRef<'_, f64>,
    coefficients: faer::MatRef<'_, f64>,
    snapshots: faer::MatRef<'_, f64>,
) -> f64 {
    let rec = basis * coefficients;
    let mut worst: f64 = 0.0;
    for j in 0..snapshots.ncols() {
        for v in 0..snapshots.nrows() / 3 {
            let mut d2 = 0.0;
            for c in 0..3 {
                let d = rec[(3 * v + c, j)] - snapshots[(3 * v + c, j)];
                d2 += d * d;
            }
            worst = worst.max(d2);
        }
    }
    worst.sqrt()
}

/// A matrix's entries column after column.
fn column_major(m: faer::MatRef<'_, f64>) -> Vec<f64> {
    (0..m.ncols())
        .flat_map(|j| (0..m.nrows()).map(move |i| m[(i, j)]))
        .collect()
}

/// U as one column-major slice (n_free × k).
pub fn basis_columns(basis: &PcaBasis) -> Vec<f64> {
    (0..basis.k())
        .flat_map(|j| basis.column(j).iter().copied())
        .collect()
}

/// What the run under gravity alone finds ([`Pipeline::later_start`]): the later start with the
/// reason the `snapshots` line gives, and what to warn of at once when the body gives way or
/// is carried past twice its size.
type LaterStart = (Option<(snapshots::MovingStart, String)>, Option<String>);

/// A training schedule as the rule validation runs it again: its first frame in the snapshots,
/// its frames, its forces, and the gravity it fell with when turned (`[training] gravity =
/// "any"`).
type ScheduleRun = (
    usize,
    usize,
    Vec<fem_core::forces::ExternalForce>,
    Option<[f64; 3]>,
);

#[cfg(test)]
mod tests {
    use super::{Pipeline, pca_rule_clearly_closer, validation_schedules, whitened};

    /// Training data past half the machine's memory is refused before it is simulated, with the
    /// schedules that fit; where the memory cannot be read nothing is said.
    #[test]
    fn snapshots_past_half_the_memory_are_refused_with_what_fits() {
        let gib = 1u64 << 30;
        // 32 schedules of 60 frames of a 60k-tet mesh's 36k free coordinates: 0.5 GiB.
        assert_eq!(
            super::snapshot_memory_problem(1920, 36_000, 60, Some(24 * gib)),
            None
        );
        let said = super::snapshot_memory_problem(40 * 60, 36_000, 60, Some(gib)).unwrap();
        assert!(
            said.contains("would take 0.6 GiB (2400 frames of 36000 free coordinates)")
                && said.contains("this machine's 1.0 GiB")
                && said.contains("at most 31 `[training] schedules` of 60 frames fit"),
            "{said}"
        );
        assert_eq!(
            super::snapshot_memory_problem(usize::MAX, 36_000, 60, None),
            None
        );
        assert!(super::machine_memory().is_none_or(|m| m > gib / 4));
    }

    /// A test trajectory past an eighth of the machine's memory is refused before it is
    /// simulated, with the frames that fit.
    #[test]
    fn test_trajectories_past_an_eighth_of_the_memory_are_refused() {
        let gib = 1u64 << 30;
        assert_eq!(
            super::trajectory_memory_problem(100, 36_000, Some(24 * gib)),
            None
        );
        let said = super::trajectory_memory_problem(1_000_000, 36_000, Some(24 * gib)).unwrap();
        assert!(
            said.contains("1000000 frames of 36000 free coordinates takes 268.2 GiB")
                && said.contains("at most 11184 `[test] frames_per_schedule` fit"),
            "{said}"
        );
        assert_eq!(
            super::trajectory_memory_problem(usize::MAX, 36_000, None),
            None
        );
    }

    /// The complement stage's line names the count the neural methods take: the scene's when it
    /// sets one, with the default beside it, else the default.
    #[test]
    fn the_complement_line_names_the_count_taken() {
        use super::{Complement, StageSummary};
        let c = Complement {
            k: 4,
            latent_dim: 1,
            directions: vec![0.0; 16],
            singular_values: vec![3.0, 1.0, 1e-3, 1e-9],
            snapshot_energy: 100.0,
            pca_lost_energy: 1e-5,
        };
        assert_eq!(c.default_count(), 2);
        let scene_with = |line: &str| {
            let text = format!(
                "name = \"bar\"\n[mesh]\ngenerate = {{ kind = \"box\", size = [0.4, 0.1, \
                 0.1], cells = [4, 1, 1] }}\n[material]\nmodel = \"corotated\"\n\
                 youngs_modulus = 1e5\npoisson_ratio = 0.4\n[[pin]]\nplane = {{ axis = \"x\", \
                 side = \"min\" }}\n[reduced]\n{line}"
            );
            crate::scene::Scene::from_str(&text, std::path::Path::new("."), "bar").unwrap()
        };
        let default = c.summary_in(&scene_with(""));
        assert!(
            default.contains("take the leading 2 (unless `[reduced] complement_directions` says)"),
            "{default}"
        );
        let set = c.summary_in(&scene_with("complement_directions = 1\n"));
        assert!(
            set.contains(
                "take the leading 1 (`[reduced] complement_directions`; the default would be 2)"
            ) && set.contains("misses 1.00e-1 without them and 1.00e-2 with them"),
            "{set}"
        );
    }

    /// A cube standing on its base under its own weight: one so soft its weight crushes it is
    /// said at once, by the run under gravity alone that decides the later starts; a firm one
    /// is not.
    #[test]
    fn a_body_its_weight_crushes_is_said_by_the_run_under_gravity_alone() {
        let crushed = |youngs: f64, training: &str| {
            let text = format!(
                "name = \"cube\"\n[mesh]\ngenerate = {{ kind = \"box\", size = [0.2, 0.2, 0.2], \
                 cells = [2, 2, 2] }}\n[material]\nmodel = \"corotated\"\nyoungs_modulus = \
                 {youngs}\npoisson_ratio = 0.4\n[[pin]]\nplane = {{ axis = \"y\", side = \
                 \"min\" }}\n[gravity]\nacceleration = [0.0, -9.81, 0.0]\n[time]\nstep = \
                 0.01\n[solver]\nmethod = \"newton\"\n[test]\nframes_per_schedule = 80\n\
                 {training}"
            );
            let scene = crate::scene::Scene::from_str(&text, std::path::Path::new("."), "cube")
                .expect("a valid scene");
            let cache = std::env::temp_dir().join(format!(
                "latent-dynamics-gives-way-{}-{youngs}-{}",
                std::process::id(),
                training.len()
            ));
            let p = Pipeline::new(&scene, &cache).unwrap();
            let (later, said) = Pipeline::later_start(&scene, &p.model).unwrap();
            std::fs::remove_dir_all(&cache).ok();
            (later.is_some(), said)
        };
        // ρgH/E = 1000 · 9.81 · 0.2 / 20 ≈ 98: flattened.
        let (_, soft) = crushed(20.0, "");
        let soft = soft.expect("a cube at 20 Pa is crushed by its weight");
        assert!(
            soft.contains("squeezes") && soft.contains("gives way under its own weight"),
            "{soft}"
        );
        // A firm cube is at rest when the schedules end: no later start, nothing to say.
        assert_eq!(crushed(1.0e6, ""), (false, None));
        // Schedules of the scene's own length take no later start, and are still checked
        // (over their 30 frames).
        let (later, set) = crushed(20.0, "[training]\nframes_per_schedule = 30\n");
        assert!(!later);
        let set = set.expect("said with the schedules' length set");
        assert!(set.contains("of its first 30 frames"), "{set}");
    }

    /// A column standing on a hinge, one edge of its base pinned, falls over under its weight:
    /// the `snapshots` line says so, from the run under gravity alone; hung from the same edge
    /// at its top it swings, and on its whole base it stands: neither is told it falls over.
    #[test]
    fn a_body_that_falls_over_its_pins_is_said_at_once() {
        let said = |pin: &str| {
            let text = format!(
                "name = \"column\"\n[mesh]\ngenerate = {{ kind = \"box\", size = [0.1, 0.3, \
                 0.1], cells = [2, 6, 2] }}\n[material]\nmodel = \"stable-neo-hookean\"\n\
                 youngs_modulus = 1e6\npoisson_ratio = 0.4\n[[pin]]\n{pin}\n[gravity]\n\
                 acceleration = [0.0, -9.81, 0.0]\n[time]\nstep = 0.01\n[solver]\nmethod = \
                 \"newton\"\n"
            );
            let scene = crate::scene::Scene::from_str(&text, std::path::Path::new("."), "column")
                .expect("a valid scene");
            let cache = std::env::temp_dir().join(format!(
                "latent-dynamics-falls-over-{}-{}",
                std::process::id(),
                pin.len()
            ));
            let p = Pipeline::new(&scene, &cache).unwrap();
            let (later, _) = Pipeline::later_start(&scene, &p.model).unwrap();
            std::fs::remove_dir_all(&cache).ok();
            later.map(|(_, why)| why)
        };
        let edge = |y: f64| {
            format!(
                "box = {{ min = [-0.001, {}, -1.0], max = [0.001, {}, 1.0] }}",
                y - 0.001,
                y + 0.001
            )
        };
        let standing = said(&edge(0.0)).expect("a column falling over its hinge still moves");
        assert!(
            standing.contains("standing on its pins, it falls over or folds about them"),
            "{standing}"
        );
        for other in [
            edge(0.3),
            "plane = { axis = \"y\", side = \"min\" }".to_string(),
        ] {
            let said = said(&other);
            assert!(
                said.as_ref().is_none_or(|h| !h.contains("falls over")),
                "{said:?}"
            );
        }
    }

    /// A soft rod hung from its top that its weight stretches past twice its size under
    /// gravity alone is said by that run, before any stage; a firm one is not.
    #[test]
    fn a_body_its_weight_stretches_beyond_any_swing_is_said_at_once() {
        let hung_by = |youngs: f64, holder: &str| {
            let text = format!(
                "name = \"rod\"\n[mesh]\ngenerate = {{ kind = \"box\", size = [0.02, 0.2, 0.02], \
                 cells = [1, 6, 1] }}\n[material]\nmodel = \"stable-neo-hookean\"\n\
                 youngs_modulus = {youngs}\npoisson_ratio = 0.45\n{holder}[gravity]\n\
                 acceleration = [0.0, -9.81, 0.0]\n[time]\nstep = 0.01\n[solver]\nmethod = \
                 \"newton\"\n"
            );
            let scene = crate::scene::Scene::from_str(&text, std::path::Path::new("."), "rod")
                .expect("a valid scene");
            let cache = std::env::temp_dir().join(format!(
                "latent-dynamics-beyond-swing-{}-{youngs}",
                std::process::id()
            ));
            let p = Pipeline::new(&scene, &cache).unwrap();
            let (_, said) = Pipeline::later_start(&scene, &p.model).unwrap();
            std::fs::remove_dir_all(&cache).ok();
            said
        };
        let hung = |youngs: f64| {
            hung_by(
                youngs,
                "[[pin]]\nplane = { axis = \"y\", side = \"max\" }\n",
            )
        };
        let soft = hung(30.0).expect("a rod at 30 Pa stretches far under its weight");
        assert!(
            soft.contains("beyond any swing about its pins") && soft.contains("youngs_modulus"),
            "{soft}"
        );
        assert_eq!(hung(1.0e6), None);
        // Held by a spring for the whole run instead of pins: the run under gravity alone,
        // without the scene's forces, falls freely, which no stiffer material would stop.
        let spring = "[[force]]\nkind = \"spring\"\nselect = { plane = { axis = \"y\", side = \
                      \"max\" } }\nstiffness = 1.0e4\nkeyframes = [[0.0, 0.0, 0.0, 0.0]]\n";
        assert_eq!(hung_by(1.0e6, spring), None);
    }

    /// The schedules run are those recorded whole and from rest, spread over the family: a
    /// schedule stopped partway and, when the set has moving starts, every fourth are left out.
    #[test]
    fn validation_schedules_are_whole_and_from_rest() {
        let set = |count: usize, later: bool| fem_core::snapshots::SnapshotSet {
            dim: 1,
            schedules: (0..count).collect(),
            frames_per_schedule: 5,
            frames: (0..count).map(|s| if s == 1 { 2 } else { 5 }).collect(),
            stopped: Vec::new(),
            later_start: later.then(|| "moving".to_string()),
            data: Vec::new(),
        };
        assert_eq!(validation_schedules(&set(6, false)), [0, 2, 3, 4, 5]);
        assert_eq!(validation_schedules(&set(8, true)), [0, 2, 4, 5, 6]);
        // At most VALIDATION_SCHEDULES, spread over the whole family.
        let many = validation_schedules(&set(100, true));
        assert_eq!(many.len(), super::VALIDATION_SCHEDULES);
        assert_eq!(many[0], 0);
        assert!(*many.last().unwrap() > 85, "{many:?}");
        assert!(many.windows(2).all(|w| w[0] < w[1]));
    }

    /// The PCA subspace's rule is kept where it is closer on every schedule by more than their
    /// spread, or where only the tangent's fails; not for a difference within the spread, a
    /// single schedule, or a failure of its own.
    #[test]
    fn the_pca_rule_must_be_clearly_closer() {
        let tangent = [0.10, 0.12, 0.08, 0.11];
        assert!(pca_rule_clearly_closer(&tangent, &[0.02, 0.03, 0.02, 0.02]));
        assert!(!pca_rule_clearly_closer(
            &tangent,
            &[0.02, 0.20, 0.02, 0.15]
        ));
        assert!(!pca_rule_clearly_closer(&tangent, &tangent));
        assert!(!pca_rule_clearly_closer(&[0.10], &[0.01]));
        let failed = [0.10, f64::INFINITY, 0.08, 0.11];
        assert!(pca_rule_clearly_closer(&failed, &[0.2, 0.2, 0.2, 0.2]));
        assert!(!pca_rule_clearly_closer(&tangent, &failed));
        assert!(!pca_rule_clearly_closer(&[], &[]));
    }

    /// The whitened tangent is Â-orthonormal on W's range, and a column W repeats is dropped
    /// (its direction left zero), not blown up.
    #[test]
    fn a_whitened_tangent_is_orthonormal_in_the_step_operator() {
        let a = faer::Mat::<f64>::from_fn(4, 4, |i, j| {
            if i == j {
                4.0 + i as f64
            } else {
                1.0 / (1.0 + (i + j) as f64)
            }
        });
        let w = faer::Mat::<f64>::from_fn(4, 3, |i, j| match j {
            0 => 1.0 + i as f64,
            1 => (i as f64 - 1.5).powi(2),
            _ => 1.0 + i as f64 + (i as f64 - 1.5).powi(2),
        });
        let t = whitened(w.as_ref(), a.as_ref());
        let g = t.transpose() * &a * &t;
        let mut ones = 0;
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j && g[(i, i)] > 0.5 { 1.0 } else { 0.0 };
                assert!(
                    (g[(i, j)] - want).abs() < 1e-9,
                    "TᵀÂT[{i},{j}] = {}",
                    g[(i, j)]
                );
            }
            ones += usize::from(g[(i, i)] > 0.5);
        }
        assert_eq!(ones, 2, "W has rank 2");
    }
}
