//! `cargo xtask run`: the pipeline, then every method on the held-out test trajectory, measured
//! against the full-space reference in one table (`report.json`, `report.md`).

use std::path::{Path, PathBuf};

use anyhow::Result;
use fem_core::four_digits;
use fem_core::integrator::FullSpaceModel;
use fem_core::mass::MassMatrix;
use fem_core::optim::SolverMethod;
use latent_sim::model::{MeasuredError, Rows};

use crate::output::FrameWriter;
use crate::pipeline::{Pipeline, Progress};
use crate::plot::{Plot, Scale, Series};
use crate::scene::Scene;
use crate::simulate::{Method, Runner, SimulateOptions, StepParts, Trajectory, median, write_json};
use crate::stage::Stage;

/// The start of the name under which `run` records a method's trajectory error in its model
/// file ([`MeasuredError::name`]), the test trajectory's number after it.
pub const TRAJECTORY_ERROR: &str =
    "mean relative displacement error ‖u − u_full‖_M / ‖u_full‖_M on held-out test trajectory";

/// How long the machine's multiply–add rate is probed before a method is timed.
const PROBE_TIME: std::time::Duration = std::time::Duration::from_millis(100);

/// `run` times a method's trajectory up to this many times, while its runs so far took less
/// than [`RUN_TIMING_BUDGET`], and reports the median of the runs' mean steps. A reduced
/// trajectory takes tens of milliseconds, which one burst of another process on a shared
/// machine can double; a full-space one, seconds, and runs once.
pub const RUN_REPEATS: usize = 5;
pub const RUN_TIMING_BUDGET: std::time::Duration = std::time::Duration::from_secs(1);

/// What `run` does.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Write every K-th frame of each method; 0 writes none.
    pub every: usize,
    pub methods: Vec<Method>,
    /// Which held-out test trajectory to simulate.
    pub trajectory: usize,
}

/// A scene's source as a report names it: a file's path made absolute, so that it holds from
/// wherever the report is read (a tester's report.md said `../scenes/dome.toml`, relative to
/// where the command ran); the built-in scene's name as it is.
fn scene_file(source: &str) -> String {
    let path = Path::new(source);
    // Resolved, so that `myapp/../scene/x.toml` reads `scene/x.toml`.
    match path.is_file().then(|| std::fs::canonicalize(path)) {
        Some(Ok(absolute)) => absolute.display().to_string(),
        _ => source.to_string(),
    }
}

/// The rows as `report.json` holds them: [`NOT_OF_FULL_SPACE`] `null` on full-space rows.
pub(crate) fn report_rows(rows: &[MethodReport]) -> Result<Vec<serde_json::Value>> {
    rows.iter()
        .map(|r| {
            let mut row = serde_json::to_value(r)?;
            null_if_full_space(&mut row, r.method);
            Ok(row)
        })
        .collect()
}

/// Sets [`NOT_OF_FULL_SPACE`] to `null` in `row`, a method's row as JSON (or a row that holds
/// its fields, as `bench.json`'s do), when `method` is full space: as `report.json`, so do
/// `suite.json` and `bench.json` (which held 0 there until stop 76).
pub(crate) fn null_if_full_space(row: &mut serde_json::Value, method: Method) {
    if method.is_full() {
        for key in NOT_OF_FULL_SPACE {
            row[key] = serde_json::Value::Null;
        }
    }
}

/// `report.json`'s `format`: what the file is, for a program that finds it among others.
pub const REPORT_FORMAT: &str = "latent-dynamics run report";

/// `report.json`'s `version`: raised when a field changes meaning or goes (the file was a bare
/// list of rows before version 1; in version 1 a full-space row held 0 where version 2 holds
/// `null`, [`NOT_OF_FULL_SPACE`]).
pub const REPORT_VERSION: u32 = 2;

/// The figures of a row that measure a subspace and its training poses, which a full-space
/// row has none of: `null` there in `report.json`, where the table prints a dash (a tester's
/// script read the 0 they held as a perfect score).
pub const NOT_OF_FULL_SPACE: [&str; 5] = [
    "subspace_error",
    "step_error",
    "training_distance",
    "training_distance_time",
    "training_seconds",
];

/// `report.json`: what a run measured and of what, so that a script comparing runs needs no
/// other file: the scene and its test, when it was run, what each stage chose, the warnings,
/// and a row per method.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunReport<'a> {
    pub format: &'static str,
    pub version: u32,
    /// The project version that wrote it.
    pub project_version: &'static str,
    /// When it was written, UTC (ISO 8601, to the second).
    pub written: String,
    pub scene: &'a str,
    /// The scene file by its absolute path (`<built-in cantilever>` for the default scene).
    pub scene_file: String,
    /// The held-out test trajectory measured, its frames, and the time step (s).
    pub trajectory: usize,
    pub frames: usize,
    pub time_step: f64,
    /// Each stage the pipeline loaded or computed for this run, once (its last outcome: a
    /// pipeline that ran several test trajectories has one `reference` per trajectory), in the
    /// order the stages first came, with what each chose.
    pub stages: Vec<StageLine>,
    /// [`crate::trust::assess`]'s figures not to be trusted, and what the figures do not say
    /// by themselves.
    pub untrusted: Vec<String>,
    pub caveats: Vec<String>,
    /// The test's loads: where each grabs and how far it pulls.
    pub test_forces: &'a [TestForce],
    /// The settings a model steps with that no stage key holds ([`run_settings`]), so that
    /// `export` tells a run of the same model from one before `[reduced]`, `[solver]` or
    /// `[test]` changed.
    pub settings: serde_json::Value,
    /// The rows, with `null` for what a full-space row does not have ([`NOT_OF_FULL_SPACE`]).
    pub methods: Vec<serde_json::Value>,
}

/// One load of a held-out test trajectory, as `run` describes it under its title and in
/// `report.json` (`test_forces`): where it grabs and how far it pulls, so that a test that
/// leaves the training poses can be told apart from its family's others.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TestForce {
    /// `spring` or `point`.
    pub kind: String,
    /// How many vertices it acts on, and their mean rest position (m).
    pub vertices: usize,
    pub centre: [f64; 3],
    /// Total stiffness (N/m; 0 for a point load).
    pub stiffness: f64,
    /// The largest target offset over its keyframes (m), or a point load's largest force (N).
    pub largest: f64,
    /// A spring's largest offset against the body's bounding-box diagonal.
    pub diagonal_share: Option<f64>,
    /// When it acts (s): from `start` until `end`.
    pub start: f64,
    pub end: f64,
}

impl TestForce {
    /// The loads of `model` (a test trajectory's: [`Pipeline::test_model`]).
    pub fn of(model: &FullSpaceModel) -> Vec<Self> {
        let (lo, hi) = model.mesh.bounding_box();
        let diagonal = (hi - lo).norm();
        model
            .forces
            .iter()
            .map(|f| {
                let n = f.vertices.len().max(1) as f64;
                let centre = f
                    .vertices
                    .iter()
                    .fold(fem_core::Vec3::zeros(), |c, &v| c + model.mesh.vertices[v])
                    / n;
                let largest = f
                    .keyframes
                    .iter()
                    .map(|k| (k[1] * k[1] + k[2] * k[2] + k[3] * k[3]).sqrt())
                    .fold(0.0, f64::max);
                let spring = f.kind == fem_core::forces::ForceKind::Spring;
                Self {
                    kind: if spring { "spring" } else { "point" }.into(),
                    vertices: f.vertices.len(),
                    centre: [centre.x, centre.y, centre.z],
                    stiffness: f.stiffness,
                    largest,
                    diagonal_share: (spring && diagonal > 0.0).then(|| largest / diagonal),
                    start: f.start,
                    end: f.end,
                }
            })
            .collect()
    }

    /// One line: "a spring of 1.30e3 N/m on 31 vertices around (0.1, 0.02, 0) m pulls its
    /// target up to 0.061 m away (5.8 % of the bounding-box diagonal) from t = 0.00 to 0.60 s".
    pub fn describe(&self) -> String {
        let [x, y, z] = self.centre.map(four_digits);
        let span = if self.end.is_finite() {
            format!("from t = {:.2} to {:.2} s", self.start.max(0.0), self.end)
        } else {
            format!("from t = {:.2} s on", self.start.max(0.0))
        };
        match self.diagonal_share {
            Some(share) => format!(
                "a spring of {:.2e} N/m on {} vertices around ({x}, {y}, {z}) m pulls its target \
                 up to {} m away ({:.1} % of the bounding-box diagonal) {span}",
                self.stiffness,
                self.vertices,
                four_digits(self.largest),
                100.0 * share
            ),
            None => format!(
                "a {} load of up to {} on {} vertices around ({x}, {y}, {z}) m {span}",
                self.kind,
                if self.kind == "spring" {
                    format!("{} m", four_digits(self.largest))
                } else {
                    format!("{} N", four_digits(self.largest))
                },
                self.vertices
            ),
        }
    }
}

/// The scene's `[solver]`, `[reduced]` and `[test]` as `report.json` holds them (`settings`):
/// what a reduced method's steps and its test depend on beyond the stages' cache keys.
pub fn run_settings(scene: &Scene) -> serde_json::Value {
    serde_json::json!({
        "solver": scene.solver,
        "reduced": scene.reduced,
        "test": scene.test(),
    })
}

/// What `run` says of its test under the title: its loads.
fn test_lines(forces: &[TestForce]) -> String {
    forces
        .iter()
        .map(|f| format!("the test: {}\n", f.describe()))
        .collect()
}

/// That a run's test is one draw of its family, under its loads in `report.md` and after a
/// plain run's summary (not after `--trajectories N`'s, which ran several), with the command
/// for `scene` (its file named: without `--scene` the command ran the built-in scene instead).
pub fn one_draw(scene: &Scene) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "._/+-=:,@".contains(c);
    let file = if scene.source.starts_with('<') {
        String::new()
    } else if scene.source.chars().all(plain) {
        format!(" --scene {}", scene.source)
    } else {
        // Quoted for a shell, a quote inside closing and reopening it.
        format!(" --scene '{}'", scene.source.replace('\'', "'\\''"))
    };
    format!(
        "one draw of the test family: `cargo xtask run{file} --trajectories 4` runs four, with \
         each method's spread\n"
    )
}

/// One stage of [`RunReport::stages`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct StageLine {
    pub stage: String,
    /// Its cache key, 16 hexadecimal digits (a model file's provenance holds the same keys:
    /// `export` finds the run that measured a model by them).
    pub key: String,
    /// Loaded from the cache instead of computed.
    pub cached: bool,
    pub seconds: f64,
    pub summary: String,
}

/// One row of the report.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct MethodReport {
    /// Serialised as its [`Method::name`].
    pub method: Method,
    /// Simulated dimension (free DOFs for full).
    pub dim: usize,
    /// Elements the elastic energy is evaluated on.
    pub cubature_elements: usize,
    /// A neural method's latent dimension and the PCA dimension it decodes to (None for the
    /// others): `[autoencoder] latent_dim` can grow to the latter.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latent: Option<Latent>,
    /// Mean wall time per step (the median over repeated runs of each run's mean): what a
    /// trajectory costs per step, its occasional expensive steps included (a preconditioner
    /// rebuild every few steps can double a reduced method's mean over its median step). Hz,
    /// speed-ups and the error–cost fronts are taken from it.
    pub ms_per_step: f64,
    /// Smallest and largest per-run mean over repeated runs (equal to `ms_per_step` after one).
    pub ms_min: f64,
    pub ms_max: f64,
    /// How many timed runs of the trajectory the times come from (see [`RUN_REPEATS`]).
    pub timed_runs: usize,
    /// Median wall time per step (median over repeated runs): the typical step, without the
    /// occasional expensive one.
    pub ms_median: f64,
    /// Steps per second, 1000 / `ms_per_step`.
    pub hz: f64,
    /// The faster full-space solver's ms/step (mean) divided by this method's; `None` when no
    /// full-space solver was timed beside it (`--methods` naming no full-space method).
    #[serde(default)]
    pub speedup: Option<f64>,
    /// Mean and max over frames of ‖u − u_full‖_M / ‖u_full‖_M.
    pub mean_rel_error: f64,
    pub max_rel_error: f64,
    /// The space–time relative error √(Σ_t ‖u_t − u_full,t‖²_M / Σ_t ‖u_full,t‖²_M): the
    /// trajectory's error against the trajectory's size. Unlike `mean_rel_error` it is not
    /// dominated by the frames where the reference passes near its rest shape, where a small
    /// lag divided by a small displacement is a large ratio.
    #[serde(default)]
    pub trajectory_error: f64,
    /// Largest distance of a vertex from its full-space position over all frames.
    pub max_vertex_error: f64,
    /// Mean solver iterations per step.
    pub iterations: f64,
    /// Mean over frames of the relative error of the reference's best representation in this
    /// method's subspace (u_full projected and, for neural methods, the nearest point of the
    /// subspace, linear directions included, that the runtime's `encode` finds): the part of
    /// the error the subspace itself causes, whatever the dynamics do.
    pub subspace_error: f64,
    /// Mean over frames of the relative error of one step started from the reference: the
    /// method put in its subspace's representation of the reference at the two steps before
    /// the frame ([`Runner::set_state`]), then stepped once. The error a step adds; where it is
    /// small and `mean_rel_error` large, the trajectory drifts away one small step at a time.
    pub step_error: f64,
    /// Where a reduced step's time goes, mean ms per step (zero for full space).
    pub decode_ms: f64,
    pub elastic_ms: f64,
    pub vjp_ms: f64,
    pub precond_ms: f64,
    /// ‖u − u_full‖_M / ‖u_full‖_M frame by frame (frames where the reference is at rest are
    /// skipped), to see where the error grows.
    pub frame_errors: Vec<f64>,
    /// The subspace error frame by frame, on the same frames (empty for full space): where it is
    /// small and `frame_errors` large, the dynamics, not the subspace, lose the trajectory.
    pub subspace_frame_errors: Vec<f64>,
    /// The one-step error frame by frame (empty for full space; shorter when a step from the
    /// reference failed).
    pub step_frame_errors: Vec<f64>,
    /// The largest distance over frames of this method's pose from the nearest training pose,
    /// relative to the pose ([`crate::coverage`]; zero for full space): above
    /// [`crate::coverage::OUTSIDE_TRAINING`] the trajectory left the training data.
    #[serde(default)]
    pub training_distance: f64,
    /// The time (s) of the frame at `training_distance`.
    #[serde(default)]
    pub training_distance_time: f64,
    /// The latest time a training schedule reaches (s; zero for full space): a test frame
    /// later than this is a time no schedule reached, e.g. a body still sagging or toppling
    /// under gravity (the test's end when some schedules start from the body's fall).
    #[serde(default)]
    pub training_seconds: f64,
    /// The largest ratio over frames of the elastic energy of the reference's representation in
    /// this method's subspace to the reference's own, with its time (s), over the frames whose
    /// reference energy is at least [`STRAIN_FRAMES`] of the largest (None for full space, or
    /// when no frame's energies are both finite and positive). Far above 1, the subspace holds
    /// the poses in the mass norm only by straining them, which a step will not do.
    #[serde(default)]
    pub projected_strain: Option<(f64, f64)>,
    /// Steps that started again from the last state because they could not be solved from
    /// their extrapolated start (an element inverted there, where the classic Neo-Hookean
    /// energy is not defined, or the preconditioner could not be factorised; zero for full
    /// space).
    #[serde(default)]
    pub step_restarts: usize,
    /// Why the method stopped before the last frame (its figures cover the frames before).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
    /// The f64 multiply–add rate of one thread (G/s, [`nn::peak::fma_rate`]) probed just
    /// before this method's timed runs: times taken at different rates (a shared machine, a
    /// clock that scales) compare only after dividing by it. None on `run`'s full-space row,
    /// whose times are the reference's own or a plain re-run of it, without the probe.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub machine_gfma: Option<f64>,
    /// On a reduced method's row, when it drifts from the full trajectory
    /// ([`crate::trust::drifting`]): the full simulation started from the method's own state
    /// part way through the test ([`restart`]), which says how much of the drift the full
    /// dynamics make of a small early error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub restart: Option<Restart>,
    /// Why that full simulation could not run, where it failed (an element its state inverts
    /// under the classic Neo-Hookean, a solve that did not converge): said among the figures
    /// not to be trusted, where only a log line said it before stop 77.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub restart_failed: Option<String>,
    /// On the full-space row: how far the test trajectory compresses its elements, which says
    /// whether the full simulation itself gives way ([`crate::trust::COLLAPSED_SHARE`]). When
    /// `full` did not run, [`run`] puts the reference's on the first row instead, so the
    /// warning does not depend on the methods asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compression: Option<Compression>,
    /// On the row that carries the compression: the linearised buckling load of the scene's
    /// gravity ([`Buckling`]), which says whether the body can stand as it is pinned.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub buckling: Option<Buckling>,
    /// On the row that carries the compression: what building the scene's model warned of
    /// ([`crate::pipeline::Pipeline::warnings`]), which the warnings list first.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub scene_warnings: Vec<String>,
    /// On the row that carries the compression, where the run has reduced methods: a PCA basis
    /// that `[pca] max_dimension` stopped short of its rule's target, which every reduced
    /// method inherits ([`pca::PcaFit::shortfall`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub basis_cap: Option<BasisCap>,
}

/// A neural method's latent dimension d and the PCA dimension k it decodes to
/// ([`MethodReport::latent`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Latent {
    pub latent_dim: usize,
    pub pca_dim: usize,
}

/// A PCA basis stopped by `[pca] max_dimension` before its rule's target
/// ([`MethodReport::basis_cap`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BasisCap {
    /// `[pca] max_dimension`, the coefficients the rule kept.
    pub max_dimension: usize,
    /// The rule as the scene wrote it, e.g. "`[pca] explained_energy` = 0.9999999".
    pub rule: String,
    /// The coefficients the rule asks for, where the spectrum says it (the explained-energy
    /// rule; the max-vertex-error scan stops at the cap).
    pub wanted: Option<usize>,
}

impl BasisCap {
    /// Of a fit whose rule `max_dimension` stopped; None where the rule was met or the
    /// snapshots' rank stopped it (no cap reaches further there).
    pub fn of(fit: &pca::PcaFit) -> Option<Self> {
        let pca::Shortfall::Cap { wanted } = fit.shortfall()? else {
            return None;
        };
        let rule = match fit.rule {
            pca::DimensionRule::ExplainedEnergy(f) => format!("`[pca] explained_energy` = {f}"),
            pca::DimensionRule::MaxVertexError(t) => format!("`[pca] max_vertex_error` = {t}"),
            pca::DimensionRule::Count(_) => return None,
        };
        Some(Self {
            max_dimension: fit.chosen_k(),
            rule,
            wanted,
        })
    }
}

/// Whether the body can stand under its own weight as it is pinned: the linearised buckling
/// load of gravity at rest ([`fem_core::stability`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Buckling {
    /// Gravity times this buckles the body; None when no load along gravity does (it hangs),
    /// and for the linear material, which does not buckle (its `standing_modulus` is a
    /// nonlinear material's).
    pub load_factor: Option<f64>,
    /// The largest displacement of the linear response to gravity at rest (m).
    pub sag: f64,
    /// The body's bounding-box diagonal (m).
    pub size: f64,
    /// The Young's modulus at which the load factor would be 1 (it scales with E).
    pub standing_modulus: Option<f64>,
    /// The Young's modulus at which the sag would be [`Buckling::VALID_SAG`] of the size (it
    /// scales with 1/E), or [`Buckling::MARGIN`] times the standing modulus where that is
    /// larger ([`Buckling::firm`]).
    pub firm_modulus: f64,
    /// Whether the eigenvalue iteration converged.
    pub converged: bool,
}

impl Buckling {
    /// The linear sag under the scene's gravity, against the body's size, below which a load
    /// factor under 1 is told: the body then holds its shape at rest in the linear sense, so a
    /// load factor below 1 marks a loss of stability (a 27 cm plate standing on its edge: 0.51,
    /// with a sag of 1.2 % of its size). A softer body bends far under its weight before any
    /// such mode, where the estimate at rest does not hold: the built-in cantilever held
    /// horizontal (0.33, its sag three times its size), AutoDef's armadillo (0.14, 61 %) and
    /// dinosaur (0.52, 51 %) on their feet, whose reduced methods follow them to 1–3 % where
    /// the dinosaur's test amplifies its errors for other reasons.
    pub const VALID_SAG: f64 = 0.05;

    /// The analysis of `model` (None without gravity or pins, and when K₀ cannot be
    /// factorised, which is logged). Under the linear material no load factor, since it does
    /// not buckle, but the moduli of the same body under a nonlinear material, which the
    /// warnings that name one tell a linear body's user to switch to.
    pub fn of(model: &FullSpaceModel) -> Option<Self> {
        let b = match fem_core::stability::gravity_buckling(model) {
            Ok(b) => b?,
            Err(e) => {
                tracing::warn!("the buckling load of gravity was not estimated: {e}");
                return None;
            }
        };
        let (lo, hi) = model.mesh.bounding_box();
        let size = (hi - lo).norm();
        let standing_modulus = b.load_factor.map(|l| model.youngs_modulus / l);
        let linear = model.material.is_linear();
        Some(Self {
            load_factor: b.load_factor.filter(|_| !linear),
            sag: b.sag,
            size,
            standing_modulus,
            firm_modulus: Self::firm(model.youngs_modulus, b.sag, size, standing_modulus),
            converged: b.converged,
        })
    }

    /// The Young's modulus that brings a linear sag `sag` at modulus `e` to
    /// [`Buckling::VALID_SAG`] of `size` (the sag scales with 1/E), and at least
    /// [`Buckling::MARGIN`] times the one at which the body would buckle (`standing`), so that a
    /// slender column is not sent to a modulus at which it would still buckle or nearly.
    pub fn firm(e: f64, sag: f64, size: f64, standing: Option<f64>) -> f64 {
        let firm = e * sag / (Self::VALID_SAG * size);
        standing.map_or(firm, |s| firm.max(Self::MARGIN * s))
    }

    /// The margin over the buckling modulus of [`Buckling::firm`]: close to its buckling load
    /// a body's sway grows as 1/(1 − 1/λ). A blob of fused spheres on its feet at E = 2.5·10⁵ Pa,
    /// 1.07 times its standing modulus, swayed 30 % of its size under gravity alone and left
    /// the training poses in the test; at 10⁶ Pa it stood (`neural-cubature` 1.6 %).
    pub const MARGIN: f64 = 2.0;

    /// The period of the body's slowest swing, estimated from its sag δ under gravity g as a
    /// mass on a spring that gravity stretches by δ: 2π √(δ/g) (s). None without a sag.
    pub fn swing_period(&self, g: f64) -> Option<f64> {
        (self.sag > 0.0 && g > 0.0 && self.sag.is_finite())
            .then(|| 2.0 * std::f64::consts::PI * (self.sag / g).sqrt())
    }

    /// What to say of a time step `h` longer than [`Self::swing_period`]: implicit Euler then
    /// damps every motion of the body out within one step (at ωh = 2π a free swing keeps
    /// 1/(1 + 4π²), 2.5 %, of its amplitude a step), so the body creeps to its rest pose and no
    /// drag's dynamics are left to compare. Most often a step written in milliseconds
    /// (`step = 16.67` for 60 Hz), which nothing else said: a game developer's scene ran to
    /// t = 1,667 s on a test of 100 frames without a word.
    pub fn step_warning(&self, h: f64, g: f64) -> Option<String> {
        let period = self.swing_period(g)?;
        (h > period).then(|| {
            // Steps are written in milliseconds as 1, 10 or 16.67; a step under a second is
            // one meant in seconds, for a body stiffer or smaller than the step suits.
            let milliseconds = if h >= 1.0 {
                format!(
                    "a step meant in milliseconds is written in seconds (`[time] step = {}`), \
                     and ",
                    h / 1000.0
                )
            } else {
                String::new()
            };
            format!(
                "the time step h = {h} s is {:.1} times the period of the body's slowest swing \
                 (about {} s, from its {:.3e} m sag under gravity), so implicit Euler damps \
                 every motion out within a step and the body only creeps to rest: \
                 {milliseconds}a step below {} s (a tenth of the period) follows the body's \
                 swing",
                h / period,
                four_digits(period),
                self.sag,
                four_digits(period / 10.0)
            )
        })
    }

    /// The load factor below 1 when the estimate holds: the body buckles under its own weight.
    /// An unconverged search counts too, as its load factor is an upper bound
    /// ([`fem_core::stability::GravityBuckling::load_factor`]): a thin stool whose search
    /// stopped at 0.255 fell under its weight and was not warned of.
    pub fn buckles(&self) -> Option<f64> {
        let l = self.load_factor?;
        (l < 1.0 && self.sag < Self::VALID_SAG * self.size).then_some(l)
    }
}

/// How far a trajectory compresses its elements.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Compression {
    /// The smallest det F (deformed over rest volume) over the elements and frames.
    pub volume_ratio: f64,
    /// The time (s) of its frame.
    pub time: f64,
    /// Frames with at least one element inverted or flat (det F ≤ 0), of `frames`.
    pub inverted_frames: usize,
    pub frames: usize,
    /// The largest share, over the frames, of the body's rest volume in elements squeezed
    /// below [`Compression::SQUEEZED`] of their volume (inverted ones included): one sliver
    /// crushed under a spring is a tiny share, a body giving way a large one.
    pub squeezed_share: f64,
    /// The time (s) of its frame.
    pub squeezed_time: f64,
    /// Whether the material is stable Neo-Hookean, which already resists inversion: then only
    /// a stiffer body helps.
    pub inversion_safe: bool,
    /// The largest vertex displacement over the frames (m), and the time (s) of its frame.
    pub travel: f64,
    pub travel_time: f64,
    /// The largest principal stretch of any element over the frames where elements past
    /// [`Compression::STRETCHED`] hold at least the volume of an element of mean size, and the
    /// time (s) of its frame: a body hung from one vertex, or pulled past what a solid takes,
    /// stretches the elements at the grip without limit. A sliver (a tet nearly flat, as
    /// Delaunay meshes of scattered points have) stretches far in F when its corners move a
    /// little, and alone holds almost no volume: on a tester's bar with 0.25° slivers one
    /// stood at 6.4× while its corners had moved 7 mm.
    pub stretched: Option<(f64, f64)>,
    /// Under the linear material only: the largest, over the frames, of the volume-weighted
    /// mean over the elements of ½‖HᵀH‖_F (H = F − I, the part of the Green strain that linear
    /// elasticity leaves out), and the time (s) of its frame. A rotation by θ everywhere gives
    /// about θ²/√2 (0.06 at 17°): past [`Compression::LINEAR_STRAIN`] the linear model stretches
    /// a body that only turns, and its motion is not the body's.
    pub linear_strain: Option<(f64, f64)>,
}

impl Compression {
    /// An element below this det F counts as squeezed.
    pub const SQUEEZED: f64 = 0.5;

    /// Whether the trajectory gives way: [`crate::trust::COLLAPSED_SHARE`] of the body squeezed
    /// under half its volume at some frame.
    pub fn gives_way(&self) -> bool {
        self.squeezed_share >= crate::trust::COLLAPSED_SHARE
    }

    /// A principal stretch past this (four times an element's length along one direction) is
    /// past what the test's loads do to a body that carries them. Measured on the test drag:
    /// hung from one vertex, a bunny stretched 8.5× in its 1 s and a chain link 4.1×; pinned as
    /// the suite pins them, the armadillo's drag stretched one element 3.0×, and a drag on a
    /// 10 cm slab glued by its whole bottom face 3.7× (a thin margin; the one-vertex pin is
    /// also said when the model is built).
    pub const STRETCHED: f64 = 4.0;

    /// The mean nonlinear strain ([`Compression::linear_strain`]) past which a linear material's
    /// test is not the body's physics: about a 15° rotation of the whole body. A 20 cm plate
    /// clamped at one edge fell 0.286 m under gravity as linear, 0.095 m as stable Neo-Hookean.
    pub const LINEAR_STRAIN: f64 = 0.05;

    /// ½‖HᵀH‖ of an element's deformation gradient `f` (H = F − I): the part of the Green
    /// strain linear elasticity leaves out, about θ²/√2 for a rotation θ.
    pub fn left_out_strain(f: &fem_core::Mat3) -> f64 {
        let h = f - fem_core::Mat3::identity();
        0.5 * (h.transpose() * h).norm()
    }

    /// [`Self::left_out_strain`] averaged over `model`'s body by rest volume, in the full
    /// displacement `u`: what [`Self::linear_strain`] takes the largest of over frames.
    pub fn mean_left_out_strain(model: &FullSpaceModel, u: &[f64]) -> f64 {
        let rest = &model.elements.volume;
        let total: f64 = rest.iter().sum();
        let sum: f64 = rest
            .iter()
            .enumerate()
            .map(|(e, w)| Self::left_out_strain(&model.elements.deformation_gradient(e, u)) * w)
            .sum();
        if total > 0.0 { sum / total } else { 0.0 }
    }

    /// Over `frames` of free displacements of `model`, each taken `step` seconds after the last
    /// (the first at `step`). None without frames.
    pub fn of(model: &FullSpaceModel, frames: &[Vec<f64>], step: f64) -> Option<Self> {
        let mesh = &model.mesh;
        let rest: Vec<f64> = (0..mesh.num_tets())
            .map(|t| mesh.signed_volume(t))
            .collect();
        let total: f64 = rest.iter().sum();
        let mean_element = total / rest.len().max(1) as f64;
        // Only the linear material leaves out the strain that `linear_strain` measures.
        let linear = model.material.is_linear();
        let (mut u, mut ratios) = (vec![0.0; model.num_full()], Vec::new());
        let mut out: Option<Self> = None;
        for (k, f) in frames.iter().enumerate() {
            let time = (k + 1) as f64 * step;
            model.dofs.scatter(f, &mut u);
            mesh.volume_ratios(&u, &mut ratios);
            let o = out.get_or_insert(Self {
                volume_ratio: f64::INFINITY,
                time,
                inverted_frames: 0,
                frames: frames.len(),
                squeezed_share: 0.0,
                squeezed_time: time,
                inversion_safe: matches!(
                    model.material,
                    fem_core::material::AnyMaterial::StableNeoHookean(_)
                ),
                travel: 0.0,
                travel_time: time,
                stretched: None,
                linear_strain: None,
            });
            let travel = fem_core::integrator::max_displacement(&u);
            if travel > o.travel {
                (o.travel, o.travel_time) = (travel, time);
            }
            let mut nonlinear_strain = 0.0;
            // The largest stretch of an element of a tenth of the mean size or more, else of
            // any: the figure said is not a sliver's beside the element that counts.
            let (mut stretch, mut sized_stretch, mut stretched_volume) = (0.0_f64, 0.0_f64, 0.0);
            // The largest singular value of F is at most its Frobenius norm, so only the elements
            // whose norm passes the limit need it.
            for e in 0..model.elements.len() {
                let f = model.elements.deformation_gradient(e, &u);
                if linear {
                    nonlinear_strain += Self::left_out_strain(&f) * rest[e] / total;
                }
                if f.norm() <= Self::STRETCHED {
                    continue;
                }
                let largest = (f.transpose() * f)
                    .symmetric_eigenvalues()
                    .iter()
                    .copied()
                    .fold(0.0, f64::max)
                    .sqrt();
                if largest > Self::STRETCHED {
                    stretch = stretch.max(largest);
                    if rest[e] >= 0.1 * mean_element {
                        sized_stretch = sized_stretch.max(largest);
                    }
                    stretched_volume += rest[e];
                }
            }
            if sized_stretch > 0.0 {
                stretch = sized_stretch;
            }
            if stretched_volume >= mean_element && o.stretched.is_none_or(|(s, _)| stretch > s) {
                o.stretched = Some((stretch, time));
            }
            if linear && o.linear_strain.is_none_or(|(s, _)| nonlinear_strain > s) {
                o.linear_strain = Some((nonlinear_strain, time));
            }
            let smallest = ratios.iter().copied().fold(f64::INFINITY, f64::min);
            if smallest < o.volume_ratio {
                (o.volume_ratio, o.time) = (smallest, time);
            }
            // A ratio that is not a number counts as inverted and squeezed, not as sound.
            o.inverted_frames += usize::from(ratios.iter().any(|r| r.is_nan() || *r <= 0.0));
            let squeezed: f64 = ratios
                .iter()
                .zip(&rest)
                .filter(|(r, _)| r.is_nan() || **r < Self::SQUEEZED)
                .map(|(_, v)| v)
                .sum();
            if squeezed / total > o.squeezed_share {
                (o.squeezed_share, o.squeezed_time) = (squeezed / total, time);
            }
        }
        out
    }
}

/// How much the full-space test trajectory amplifies a small error: the state (displacement
/// and velocity) scaled by 1 − `change` at `time`, then simulated on with the same solver and
/// compared with the reference as every method is.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Sensitivity {
    /// When the state was changed (s).
    pub time: f64,
    /// The relative change of the state.
    pub change: f64,
    /// Mean over the frames from the change on of ‖u − u_full‖_M / ‖u_full‖_M.
    pub mean_error: f64,
    /// The same at the last frame.
    pub last_error: f64,
}

/// Where in the test trajectory [`sensitivity`] and [`restart`] change the state (fraction of
/// its frames): late enough that the test's forces have acted, early enough to leave time to
/// grow.
pub const SENSITIVITY_AT: f64 = 0.3;

/// Simulates test trajectory `trajectory` in full space from the reference's state after frame
/// `frame`, scaled by 1 − `change`, and measures it against the cached reference. With `change`
/// = 0 the reference is reproduced to the solver's tolerance.
pub fn sensitivity(
    pipeline: &mut Pipeline<'_>,
    trajectory: usize,
    frame: usize,
    change: f64,
    stage_progress: Progress<'_>,
) -> Result<Sensitivity> {
    let errors = rerun(pipeline, trajectory, frame, stage_progress, |state| {
        state.u.iter_mut().for_each(|x| *x *= 1.0 - change);
        state.v.iter_mut().for_each(|x| *x *= 1.0 - change);
        Ok(())
    })?;
    Ok(Sensitivity {
        time: frame as f64 * pipeline.scene.time.step,
        change,
        mean_error: mean(&errors.rel),
        last_error: errors.rel.last().copied().unwrap_or(0.0),
    })
}

/// The full simulation started from a reduced method's own state part way through the test,
/// against the reference. A method's drift is partly the full dynamics' own: started from a
/// state a little off, the full simulation goes on to end somewhere else too. Where the
/// restarted full trajectory ends about as far off as the method, most of the drift is the
/// test amplifying the method's early error, and the trajectory errors rank the methods by how
/// they are perturbed more than by how good they are.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Restart {
    /// When the full simulation took over the method's state (s).
    pub time: f64,
    /// The method's own relative error then.
    pub start_error: f64,
    /// Mean over the frames after the restart of the restarted full trajectory's relative error.
    pub mean_error: f64,
    /// The same at the last frame.
    pub last_error: f64,
    /// The method's own mean error over the same frames.
    pub method_mean_error: f64,
    /// The method's own error at the last frame.
    pub method_last_error: f64,
}

impl Restart {
    /// The share of the method's drift after the restart that the full dynamics make on their
    /// own from its state (near 1: nearly all; near 0: the reduced steps drift by themselves).
    pub fn share(&self) -> f64 {
        if self.method_mean_error > 0.0 {
            self.mean_error / self.method_mean_error
        } else {
            0.0
        }
    }
}

/// Runs reduced `row.method` again to frame `frame` of test trajectory `trajectory` (runs
/// reproduce bit for bit), then simulates the full space on from its state there: the
/// displacement it reports and the velocity implicit Euler gives it, (u_frame − u_frame−1)/h.
pub fn restart(
    pipeline: &mut Pipeline<'_>,
    row: &MethodReport,
    trajectory: usize,
    frame: usize,
    stage_progress: Progress<'_>,
) -> Result<Restart> {
    let method = row.method;
    anyhow::ensure!(
        !method.is_full(),
        "{method} is full space: there is no reduced state to restart from"
    );
    let reference = pipeline.reference(trajectory, stage_progress)?;
    let frames = reference.frames.len();
    anyhow::ensure!(
        row.frame_errors.len() == frames,
        "{method} has errors for {} of the reference's {frames} frames",
        row.frame_errors.len()
    );
    anyhow::ensure!(
        frame >= 1 && frame < frames,
        "frame {frame} is not within the reference's {frames} frames"
    );
    let sim_opts = SimulateOptions {
        method,
        trajectory: Trajectory::Test(trajectory),
        out: PathBuf::new(),
        frames: Some(frame),
        every: 0,
        solver: None,
    };
    let mut runner = Runner::from_options(pipeline, &sim_opts, stage_progress)?;
    let mut before = runner.displacement();
    for _ in 1..frame {
        runner.step()?;
        before = runner.displacement();
    }
    runner.step()?;
    let now = runner.displacement();
    let mut start = ErrorAccumulator::default();
    start.add(runner.model(), &now, &reference.frames[frame - 1]);
    let (mean_error, last_error) =
        full_from(pipeline, trajectory, frame, &before, &now, stage_progress)?;
    let after = &row.frame_errors[frame..];
    Ok(Restart {
        time: frame as f64 * pipeline.scene.time.step,
        start_error: mean(&start.rel),
        mean_error,
        last_error,
        method_mean_error: mean(after),
        method_last_error: after.last().copied().unwrap_or(0.0),
    })
}

/// Simulates test trajectory `trajectory` in full space from frame `frame` on, started from
/// displacement `now` (every vertex) and the velocity implicit Euler gives it after `before`,
/// (now − before)/h; returns the mean relative error of the frames after `frame` against the
/// cached reference, and the last frame's. Started from the reference's own frames it
/// reproduces the reference.
pub fn full_from(
    pipeline: &mut Pipeline<'_>,
    trajectory: usize,
    frame: usize,
    before: &[f64],
    now: &[f64],
    stage_progress: Progress<'_>,
) -> Result<(f64, f64)> {
    let h = pipeline.scene.time.step;
    let errors = rerun(pipeline, trajectory, frame, stage_progress, |state| {
        anyhow::ensure!(
            state.u.len() == now.len() && now.len() == before.len(),
            "the full model has {} displacements, the states given {} and {}",
            state.u.len(),
            before.len(),
            now.len()
        );
        implicit_euler_state(state, before, now, h);
        Ok(())
    })?;
    Ok((mean(&errors.rel), errors.rel.last().copied().unwrap_or(0.0)))
}

/// Simulates test trajectory `trajectory` in full space from the reference's state after frame
/// `frame` (step and time too) changed by `change`, and measures the frames from there on
/// against the cached reference.
fn rerun(
    pipeline: &mut Pipeline<'_>,
    trajectory: usize,
    frame: usize,
    stage_progress: Progress<'_>,
    change: impl FnOnce(&mut fem_core::integrator::State) -> Result<()>,
) -> Result<ErrorAccumulator> {
    let reference = pipeline.reference(trajectory, stage_progress)?;
    let frames = reference.frames.len();
    anyhow::ensure!(
        frame < frames,
        "frame {frame} is past the reference's {frames} frames"
    );
    let scene = pipeline.scene;
    let h = scene.time.step;
    let time = fem_core::integrator::TimeConfig {
        frames,
        ..scene.time.clone()
    };
    let mut sim = fem_core::integrator::Simulator::new(
        pipeline.test_model(trajectory)?,
        time,
        scene.solver.clone(),
    )?;
    // The reference's state after `frame` steps, without simulating them again.
    if frame > 0 {
        let mut before = vec![0.0; sim.model.num_full()];
        let mut now = before.clone();
        if frame > 1 {
            sim.model
                .dofs
                .scatter(&reference.frames[frame - 2], &mut before);
        }
        sim.model
            .dofs
            .scatter(&reference.frames[frame - 1], &mut now);
        implicit_euler_state(&mut sim.state, &before, &now, h);
        sim.state.step = frame;
        sim.state.time = frame as f64 * h;
    }
    change(&mut sim.state)?;
    let mut errors = ErrorAccumulator::default();
    for r in &reference.frames[frame..] {
        sim.step()?;
        errors.add(&sim.model, &sim.state.u, r);
    }
    Ok(errors)
}

/// Puts `state` at displacement `now` with the velocity implicit Euler gives it after
/// displacement `before`, (now − before)/h (full vectors of the same length).
fn implicit_euler_state(
    state: &mut fem_core::integrator::State,
    before: &[f64],
    now: &[f64],
    h: f64,
) {
    state.u.copy_from_slice(now);
    for ((v, a), b) in state.v.iter_mut().zip(now).zip(before) {
        *v = (a - b) / h;
    }
}

/// Errors of a trajectory against the reference, frame by frame.
#[derive(Debug, Default)]
struct ErrorAccumulator {
    rel: Vec<f64>,
    max_vertex: f64,
    /// Σ over frames of ½‖u − u_full‖²_M and of ½‖u_full‖²_M.
    squared_error: f64,
    squared_size: f64,
}

impl ErrorAccumulator {
    /// The space–time relative error (zero when the reference never moved).
    fn trajectory_error(&self) -> f64 {
        if self.squared_size > 0.0 {
            (self.squared_error / self.squared_size).sqrt()
        } else {
            0.0
        }
    }

    fn add(&mut self, model: &FullSpaceModel, u: &[f64], reference_free: &[f64]) {
        let mut r = vec![0.0; u.len()];
        model.dofs.scatter(reference_free, &mut r);
        self.add_full(&model.mass, u, &r);
    }

    /// Adds the frame of displacement `u` against the reference's `r` (both every vertex).
    fn add_full(&mut self, mass: &MassMatrix, u: &[f64], r: &[f64]) {
        let (error, size) = mass.error_and_size(u, r);
        // MassMatrix::relative_error, from the two terms the sums need too.
        if size > 0.0 {
            self.rel.push((error / size).sqrt());
        }
        self.squared_error += error;
        self.squared_size += size;
        for (a, b) in u.chunks_exact(3).zip(r.chunks_exact(3)) {
            let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            self.max_vertex = self
                .max_vertex
                .max((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
        }
    }
}

/// Runs the requested methods on test trajectory `opts.trajectory`; returns the report rows.
pub fn run(
    pipeline: &mut Pipeline<'_>,
    opts: &RunOptions,
    stage_progress: Progress<'_>,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<Vec<MethodReport>> {
    if opts.methods.is_empty() {
        anyhow::bail!("the methods name none; name at least one (neural-cubature, …)");
    }
    if let Some(m) = Method::repeated(&opts.methods) {
        anyhow::bail!("the methods name {m} twice; name each method once");
    }
    // A latent dimension the PCA basis cannot hold is refused before any method runs.
    if opts.methods.iter().any(|m| m.is_neural()) {
        let k = pipeline.pca(stage_progress)?.basis.k();
        if let Some(problem) = crate::pipeline::latent_dim_refusal(&pipeline.scene.autoencoder, k) {
            anyhow::bail!("{}: {problem}", pipeline.scene.source);
        }
    }
    let mut rows = Vec::new();
    for &method in &opts.methods {
        // `full` already is the scene's solver: a row forcing the same solver would repeat it.
        if method.repeats_full(&opts.methods, pipeline.scene.solver.method) {
            tracing::info!(
                "{} is the scene's solver, measured as `full`",
                method.name()
            );
            continue;
        }
        let m = Measure {
            method,
            trajectory: opts.trajectory,
            out: opts.out.join(method.name()),
            every: opts.every,
            // A full-space trajectory is timed once, as `full`'s is, so that the faster
            // full-space solver, the speed-ups' base, is picked from like figures.
            repeats: if method.is_full() { 1 } else { RUN_REPEATS },
            time_budget: Some(RUN_TIMING_BUDGET),
            time_full: false,
            solver: None,
        };
        rows.push(measure(pipeline, &m, stage_progress, progress)?);
    }
    set_speedups(&mut rows);
    // `full` carries it; `full-newton` and `full-lbfgs` rows do not.
    if !rows.iter().any(|r| r.compression.is_some())
        && let Some(first) = rows.first_mut()
    {
        let reference = pipeline.reference(opts.trajectory, stage_progress)?;
        first.compression =
            Compression::of(&pipeline.model, &reference.frames, pipeline.scene.time.step);
    }
    if let Some(row) = rows.iter_mut().find(|r| r.compression.is_some()) {
        row.buckling = *pipeline
            .buckling
            .get_or_init(|| Buckling::of(&pipeline.model));
        row.scene_warnings = pipeline.warnings.clone();
        if opts.methods.iter().any(|m| !m.is_full()) {
            let fit = pipeline.pca(stage_progress)?;
            row.basis_cap = BasisCap::of(&fit);
        }
        let time = &pipeline.scene.time;
        if let Some(b) = &row.buckling
            && !time.quasi_static
            && let Some(w) = b.step_warning(time.step, pipeline.scene.gravity.magnitude())
        {
            row.scene_warnings.push(w);
        }
    }
    // A reference that gives way is said to (`trust::COLLAPSED_SHARE`), and the methods are
    // not judged against it: restarting it from each method's state (the whole rest of the
    // test in full space, about 30 s a method on a 1,500-vertex tire) would only say how a
    // body that is no longer a solid amplifies a small difference.
    let gives_way = crate::trust::reference_gives_way(&rows);
    for i in 0..rows.len() {
        if gives_way || !crate::trust::drifting(&rows[i]) {
            continue;
        }
        let frame = (SENSITIVITY_AT * rows[i].frame_errors.len() as f64) as usize;
        let label = format!("full from {}", rows[i].method);
        progress(&label, 0, 1);
        match restart(pipeline, &rows[i], opts.trajectory, frame, stage_progress) {
            Ok(r) => rows[i].restart = Some(r),
            Err(e) => {
                tracing::warn!(
                    "the full simulation from {}'s state was not measured: {e:#}",
                    rows[i].method
                );
                rows[i].restart_failed = Some(format!("{e:#}"));
            }
        }
        progress(&label, 1, 1);
    }
    // The model first: building it may compute stages, and a run stopped there (Ctrl-C in
    // Python) leaves the folder's files of the run before whole, none of them rewritten.
    let model = match crate::export::run_method(&opts.methods) {
        Some(method) => Some((
            method,
            crate::export::scene_model(pipeline, method, Rows::Used, stage_progress)?,
        )),
        None => None,
    };
    let assessment = crate::trust::assess(&rows);
    let test_forces = TestForce::of(&pipeline.test_model(opts.trajectory)?);
    let report = RunReport {
        format: REPORT_FORMAT,
        version: REPORT_VERSION,
        project_version: env!("CARGO_PKG_VERSION"),
        written: crate::output::utc_now(),
        scene: &pipeline.scene.name,
        scene_file: scene_file(&pipeline.scene.source),
        trajectory: opts.trajectory,
        frames: pipeline.scene.test().frames_per_schedule,
        time_step: pipeline.scene.time.step,
        stages: stage_lines(&pipeline.outcomes, pipeline.reference_key(opts.trajectory)),
        untrusted: assessment.untrusted,
        caveats: assessment.caveats,
        test_forces: &test_forces,
        settings: run_settings(pipeline.scene),
        methods: report_rows(&rows)?,
    };
    write_json(&opts.out.join("report.json"), &report)?;
    if let Some((method, mut model)) = model {
        if let Some(row) = rows
            .iter()
            .find(|r| r.method == method && r.failure.is_none())
        {
            model.provenance.errors.push(MeasuredError {
                name: format!("{TRAJECTORY_ERROR} {}", opts.trajectory),
                held_out: true,
                value: row.mean_rel_error,
            });
        }
        model.save(crate::export::model_path(&opts.out, method))?;
    }
    // What was run, above the table: report.md alone says which scene and test it measured.
    let title = heading(pipeline.scene, opts.trajectory);
    crate::output::write_file(
        &opts.out.join("report.md"),
        format!(
            "# {title}\n\nscene: {}\n\n{}{}\n{}",
            scene_file(&pipeline.scene.source),
            test_lines(&test_forces),
            one_draw(pipeline.scene),
            report_markdown(&rows)
        )
        .as_bytes(),
    )?;
    let plotted = format!(
        "{}, test trajectory {}",
        pipeline.scene.name, opts.trajectory
    );
    crate::output::write_file(
        &opts.out.join("report.svg"),
        error_plot(&plotted, &rows).as_bytes(),
    )?;
    let h = pipeline.scene.time.step;
    crate::output::write_file(
        &opts.out.join("errors.csv"),
        errors_csv(&rows, h).as_bytes(),
    )?;
    crate::output::write_file(
        &opts.out.join("errors.svg"),
        frame_error_plot(&plotted, &rows, h).as_bytes(),
    )?;
    Ok(rows)
}

/// Each stage's last outcome, in the order the stages first came, and of the `reference`s
/// (one per test trajectory the pipeline ran) the one keyed `reference`, this run's: the cubature
/// stage computes trajectory 0's, after this run's when the cache is empty.
fn stage_lines(outcomes: &[crate::pipeline::StageOutcome], reference: u64) -> Vec<StageLine> {
    let ours = outcomes
        .iter()
        .any(|o| o.stage == Stage::Reference && o.key == reference);
    let mut lines: Vec<StageLine> = Vec::new();
    for o in outcomes
        .iter()
        .filter(|o| o.stage != Stage::Reference || o.key == reference || !ours)
    {
        let line = StageLine {
            stage: o.stage.to_string(),
            key: format!("{:016x}", o.key),
            cached: o.cached,
            seconds: o.seconds,
            summary: o.summary.clone(),
        };
        match lines.iter_mut().find(|l| l.stage == line.stage) {
            Some(l) => *l = line,
            None => lines.push(line),
        }
    }
    lines
}

/// `report.md`, and the middle of what `run` prints: the table, where a reduced step's time
/// goes, where `neural-cubature` stands against `pca-cubature`, steps started again, and the
/// warnings of [`crate::trust`].
pub fn report_markdown(rows: &[MethodReport]) -> String {
    let mut s = markdown(rows);
    s.push_str(&time_split_markdown(rows));
    s.push_str(&standing_line(rows));
    for r in rows.iter().filter(|r| r.step_restarts > 0) {
        s.push_str(&format!(
            "\n{}: {} of its steps started again from the last state (not solvable from their \
             extrapolated start, e.g. an element inverted there)\n",
            r.method, r.step_restarts
        ));
    }
    s.push_str(&crate::trust::assess(rows).text(""));
    s
}

/// The scene and the test a run measured: the line above `run`'s table and `report.md`'s title.
fn heading(scene: &Scene, trajectory: usize) -> String {
    format!(
        "{} — held-out test trajectory {trajectory}, {} frames",
        scene.name,
        scene.test().frames_per_schedule
    )
}

/// What `cargo xtask run` shows after the stages: the test's loads ([`TestForce`]), the table,
/// where a reduced step's time goes, the warnings of [`crate::trust`], and where the report, the
/// frames and the model are (a plain run adds [`one_draw`]).
pub fn summary(
    scene: &Scene,
    opts: &RunOptions,
    test_forces: &[TestForce],
    rows: &[MethodReport],
) -> String {
    let mut s = format!("\n{}\n\n", heading(scene, opts.trajectory));
    s.push_str(&test_lines(test_forces));
    s.push('\n');
    s.push_str(&report_markdown(rows));
    s.push_str(&format!(
        "\nreport: {} (also report.md, report.svg; errors by frame: errors.csv, errors.svg)",
        opts.out.join("report.json").display()
    ));
    if opts.every > 0 {
        s.push_str(&format!(
            "; frames: {}/<method>/series.pvd",
            opts.out.display()
        ));
    }
    s.push('\n');
    if let Some(m) = crate::export::run_method(&opts.methods) {
        s.push_str(&format!(
            "model: {}\n",
            crate::export::model_path(&opts.out, m).display()
        ));
    }
    s
}

/// Where `neural-cubature` stands against `pca-cubature` on the error–cost plane
/// ([`crate::suite::standing`]), with both figures and, on an axis where it loses, why, as lines
/// of `run`'s summary (empty unless both ran).
pub fn standing_line(rows: &[MethodReport]) -> String {
    let find = |m: Method| rows.iter().find(|r| r.method == m);
    let (Some(n), Some(p)) = (find(Method::NeuralCubature), find(Method::PcaCubature)) else {
        return String::new();
    };
    let standing = crate::suite::standing(n, p);
    if standing == "—" {
        return String::new();
    }
    let (n_ms, p_ms) = distinct(n.ms_per_step, p.ms_per_step, 3);
    let (n_error, p_error) = distinct(100.0 * n.mean_rel_error, 100.0 * p.mean_rel_error, 2);
    format!(
        "\nneural-cubature against pca-cubature: {standing} ({n_ms} against {p_ms} ms a step, \
         {n_error} against {p_error} % off; step times move by up to 50 % between runs on a \
         shared machine, `cargo xtask bench` repeats them and sweeps both methods' sizes)\n"
    ) + &standing_reasons(n, p)
}

/// `a` and `b` with `digits` decimals, or up to three more where those print the same: a
/// standing "more accurate" must not read "0.91 against 0.91 % off". Equal to all of them, as
/// `digits` give them.
fn distinct(a: f64, b: f64, digits: usize) -> (String, String) {
    let show = |d: usize| (format!("{a:.d$}"), format!("{b:.d$}"));
    (digits..=digits + 3)
        .map(show)
        .find(|(x, y)| x != y)
        .unwrap_or_else(|| show(digits))
}

/// Where `neural-cubature` (`n`) loses to `pca-cubature` (`p`), from the figures that
/// separate them (empty when it loses on neither axis). Both evaluate their elements in the
/// PCA coordinates (the decoder's output is one), so a step costs about the same at the same
/// rule size and iterations, whatever the latent dimension: a slower step is told by the rule
/// sizes, the iterations and the time split. A larger error is told by the subspace and
/// one-step errors: the subspace's, the steps', or the test's dynamics making more of an early
/// difference.
fn standing_reasons(n: &MethodReport, p: &MethodReport) -> String {
    let mut s = String::new();
    let ratio = |a: f64, b: f64| a / b.max(f64::MIN_POSITIVE);
    if n.ms_per_step > p.ms_per_step {
        let times = ratio(n.ms_per_step, p.ms_per_step);
        let slower = 100.0 * (times - 1.0);
        // Past twice as long, as a multiple: "slower by 289 %" read as noise on 0.007 ms steps.
        let by = if slower < 1.0 {
            format!("slower by {slower:.1} %")
        } else if times < 2.0 {
            format!("slower by {slower:.0} %")
        } else {
            format!("{times:.1} times as long a step")
        };
        let noise = if slower < 100.0 * STEP_TIME_SPREAD {
            ", less than step times move between runs"
        } else {
            ""
        };
        // On steps of a few microseconds the decoder's fixed cost can be the whole difference.
        let decoder = n.decode_ms + n.vjp_ms;
        let decoder_alone = if decoder >= p.ms_per_step {
            format!(
                " (the decoder alone takes longer than {}'s whole step, {:.3} ms: on a step \
                 this cheap it is what a latent space costs)",
                p.method, p.ms_per_step
            )
        } else {
            String::new()
        };
        s += &format!(
            "- {by}{noise}: {} against {} elements, both evaluated in the {} PCA \
             coordinates (the decoder's output), {:.1} against {:.1} iterations a step; per \
             step the decoder {:.3} ms{decoder_alone}, the elastic terms {:.3} against {:.3} \
             ms, the preconditioner {:.3} against {:.3} ms\n",
            n.cubature_elements,
            p.cubature_elements,
            p.dim,
            n.iterations,
            p.iterations,
            decoder,
            n.elastic_ms,
            p.elastic_ms,
            n.precond_ms,
            p.precond_ms,
        );
    }
    // Level errors (`suite::level`) are no loss to explain.
    if n.mean_rel_error > p.mean_rel_error
        && !crate::suite::level(n.mean_rel_error, p.mean_rel_error)
    {
        // A subspace a little further from the test explains a larger error only when the
        // difference is a fair part of the error's (on the catapult, 0.06 against 0.05 % does
        // not explain 1.59 against 1.16 %).
        let subspace = ratio(n.subspace_error, p.subspace_error) > REASON_RATIO
            && n.subspace_error - p.subspace_error
                >= REASON_SHARE * (n.mean_rel_error - p.mean_rel_error);
        let cause = if subspace {
            format!(
                "its subspace holds the test less well (more `[reduced] complement_directions` \
                 or {} close it)",
                crate::trust::larger_latent(n)
            )
        } else if n.step_error > 0.0
            && p.step_error > 0.0
            && ratio(n.step_error, p.step_error) > REASON_RATIO
        {
            "its steps add more error from the same start (the cubature rule: stage \
             `cubature-neural`'s force error against stage `cubature`'s, or the solve)"
                .to_string()
        } else {
            "neither its subspace nor its steps are far enough from pca-cubature's to explain \
             it, so the test's dynamics made more of a small difference"
                .to_string()
        };
        let (n_subspace, p_subspace) =
            distinct(100.0 * n.subspace_error, 100.0 * p.subspace_error, 2);
        let (n_step, p_step) = distinct(100.0 * n.step_error, 100.0 * p.step_error, 2);
        s += &format!(
            "- less accurate: its subspace holds the test to {n_subspace} against {p_subspace} \
             %, one step from the reference lands {n_step} against {p_step} % off: {cause}\n"
        );
    }
    s
}

/// A figure of neural-cubature's more than this many times pca-cubature's is where
/// [`standing_reasons`] places a larger error (step errors only when both are measured: a
/// method whose every one-step solve failed reports none).
const REASON_RATIO: f64 = 1.2;

/// … and the subspace's only when its excess is at least this share of the error's.
const REASON_SHARE: f64 = 0.25;

/// A step slower by less than this fraction is within what the same run's step times move
/// between runs on this machine (10–25 % at equal iterations, docs/results-suite.md, stop 52;
/// up to 50 % on a shared machine, as the standing line says), and [`standing_reasons`] says
/// so; above it the difference may still be the machine's, which the standing line's advice
/// (`cargo xtask bench`) settles.
pub(crate) const STEP_TIME_SPREAD: f64 = 0.1;

/// Where a reduced step's time goes, mean ms per step, as a markdown table under a heading
/// (empty when no reduced method ran).
pub fn time_split_markdown(rows: &[MethodReport]) -> String {
    let mut reduced = reduced_rows(rows).peekable();
    if reduced.peek().is_none() {
        return String::new();
    }
    let mut s = String::from(
        "\nwhere a reduced step's time goes (mean ms per step):\n\n\
         | method | decode | elastic | VJP | preconditioner or Newton matrix |\n|---|---:|---:|---:|---:|\n",
    );
    for r in reduced {
        s.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} |\n",
            r.method, r.decode_ms, r.elastic_ms, r.vjp_ms, r.precond_ms
        ));
    }
    s
}

/// Speed-ups over the faster full-space solver among `rows`; none when no full-space solver ran.
pub fn set_speedups(rows: &mut [MethodReport]) {
    let fastest_full = rows
        .iter()
        .filter(|r| r.method.is_full())
        .map(|r| r.ms_per_step)
        .fold(f64::INFINITY, f64::min);
    for r in rows {
        r.speedup = fastest_full
            .is_finite()
            .then(|| fastest_full / r.ms_per_step);
    }
}

/// A speed-up as a table cell with `digits` decimals, at least one below 10× (a suite's 0.4×
/// read `0×` with none), and a dash where no full-space solver ran.
pub(crate) fn speedup_cell(speedup: Option<f64>, digits: usize) -> String {
    speedup.map_or_else(
        || "—".into(),
        |x| {
            let digits = if x < 10.0 { digits.max(1) } else { digits };
            format!("{x:.digits$}×")
        },
    )
}

/// One method measured on a test trajectory.
#[derive(Debug, Clone)]
pub struct Measure {
    pub method: Method,
    pub trajectory: usize,
    /// Frames go to this folder (when `every > 0`).
    pub out: PathBuf,
    pub every: usize,
    /// Timed runs of the whole trajectory; errors come from the first, the reported time is
    /// the median over runs of each run's mean step, the spread their minimum and maximum.
    pub repeats: usize,
    /// With a budget, runs after the first are made (up to `repeats`) only while the runs so
    /// far took less than it, and show no progress: `run`'s cheap repeats of a short trajectory.
    /// Without, every one of `repeats` runs (`bench`).
    pub time_budget: Option<std::time::Duration>,
    /// Time the scene's full-space solver in this process as any method (`bench`, after its
    /// warm-up). Without it, `full` takes the reference's recorded step times when this process
    /// computed the reference, and runs the trajectory again for its time when it was loaded.
    pub time_full: bool,
    /// Overrides the method's solver (reduced methods default to L-BFGS).
    pub solver: Option<SolverMethod>,
}

/// The step times of `opts`'s method over `frames` steps of its trajectory, run again.
fn time_again(
    pipeline: &mut Pipeline<'_>,
    opts: &SimulateOptions,
    frames: usize,
    stage_progress: Progress<'_>,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<Vec<f64>> {
    let mut runner = Runner::from_options(pipeline, opts, stage_progress)?;
    let mut seconds = Vec::with_capacity(frames);
    for k in 0..frames {
        seconds.push(runner.step()?.seconds);
        progress(opts.method.name(), k + 1, frames);
    }
    Ok(seconds)
}

/// Simulates `m.method` on the test trajectory and compares it with the full-space reference.
pub fn measure(
    pipeline: &mut Pipeline<'_>,
    m: &Measure,
    stage_progress: Progress<'_>,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<MethodReport> {
    let reference = pipeline.reference(m.trajectory, stage_progress)?;
    let frames = reference.frames.len();
    let method = m.method;
    let sim_opts = SimulateOptions {
        method,
        trajectory: Trajectory::Test(m.trajectory),
        out: m.out.clone(),
        frames: Some(frames),
        every: m.every,
        solver: m.solver,
    };
    // Made whatever `every` is: it removes the frames an earlier run left, and makes `frames/`
    // only for a first frame written.
    let mut writer = Some(FrameWriter::new(&sim_opts.out)?).filter(|_| m.every > 0);
    if method == Method::Full && !m.time_full {
        // A reference loaded from the cache was timed by another process, on a machine then
        // busier or idler than now: the scene's solver runs the trajectory again here, for its
        // time only (its frames are the reference's).
        let step_seconds = if pipeline.reference_computed_here(m.trajectory) {
            reference.step_seconds.clone()
        } else {
            time_again(pipeline, &sim_opts, frames, stage_progress, progress)?
        };
        let full_ms = mean(&step_seconds) * 1e3;
        let model = pipeline.test_model(m.trajectory)?;
        if let Some(mut w) = writer {
            w.write(&model.mesh, 0, 0.0, &vec![0.0; model.num_full()])?;
            let mut u = vec![0.0; model.num_full()];
            for (k, f) in reference.frames.iter().enumerate() {
                if (k + 1) % m.every == 0 || k + 1 == frames {
                    model.dofs.scatter(f, &mut u);
                    w.write(
                        &model.mesh,
                        k + 1,
                        (k + 1) as f64 * pipeline.scene.time.step,
                        &u,
                    )?;
                }
            }
            w.finish()?;
        }
        return Ok(MethodReport {
            method,
            dim: model.dofs.num_free(),
            latent: None,
            cubature_elements: model.elements.len(),
            ms_per_step: full_ms,
            ms_min: full_ms,
            ms_median: median(&step_seconds) * 1e3,
            ms_max: full_ms,
            timed_runs: 1,
            hz: 1e3 / full_ms,
            speedup: None,
            mean_rel_error: 0.0,
            max_rel_error: 0.0,
            trajectory_error: 0.0,
            max_vertex_error: 0.0,
            iterations: mean_usize(&reference.iterations),
            subspace_error: 0.0,
            projected_strain: None,
            step_error: 0.0,
            frame_errors: vec![0.0; reference.frames.len()],
            subspace_frame_errors: Vec::new(),
            step_frame_errors: Vec::new(),
            decode_ms: 0.0,
            elastic_ms: 0.0,
            vjp_ms: 0.0,
            precond_ms: 0.0,
            training_distance: 0.0,
            training_distance_time: 0.0,
            training_seconds: 0.0,
            step_restarts: 0,
            failure: None,
            machine_gfma: None,
            restart: None,
            restart_failed: None,
            compression: Compression::of(&model, &reference.frames, pipeline.scene.time.step),
            buckling: None,
            scene_warnings: Vec::new(),
            basis_cap: None,
        });
    }
    let machine_gfma = Some(nn::peak::fma_rate(PROBE_TIME).multiply_adds_per_second / 1e9);
    let mut errors = ErrorAccumulator::default();
    let mut medians = Vec::with_capacity(m.repeats.max(1));
    let mut means = Vec::with_capacity(m.repeats.max(1));
    let mut iterations = Vec::with_capacity(frames);
    let mut step_restarts = 0;
    // Each run's split of its steps' time: the report gives the run whose mean is the median
    // one, the run `ms/step` stands for (the first run's, cold, added up to half as much again
    // as the mean on a tester's bowl, 0.211 against 0.141 ms).
    let mut run_parts = Vec::with_capacity(m.repeats.max(1));
    let mut cubature_elements = 0;
    let mut dim = 0;
    let mut failure = None;
    // The last run's runner measures the one-step errors afterwards (set_state resets it).
    let mut last_runner = None;
    // The reduced pose of each frame of the first run, for its distance to the training data.
    let mut poses: Vec<Vec<f64>> = Vec::new();
    let mut timed = 0.0;
    for repeat in 0..m.repeats.max(1) {
        if repeat > 0 && m.time_budget.is_some_and(|b| timed >= b.as_secs_f64()) {
            break;
        }
        let mut runner = Runner::from_options(pipeline, &sim_opts, stage_progress)?;
        let first = repeat == 0;
        let show = first || m.time_budget.is_none();
        if first && let Some(w) = writer.as_mut() {
            w.write(&runner.model().mesh, 0, 0.0, &runner.displacement())?;
        }
        let mut times = Vec::with_capacity(frames);
        let mut parts = StepParts::default();
        for k in 0..frames {
            let info = match runner.step() {
                Ok(info) => info,
                Err(_) if !first => {
                    // A repeat for the time only (runs reproduce bit for bit, so it fails where
                    // the first did, which reported it): its partial times are not a run's.
                    times.clear();
                    break;
                }
                Err(e) => {
                    // Keep the last good state on disk (never the failed one) and report the
                    // failure in the row instead of aborting the other methods.
                    if first
                        && let Some(w) = writer.as_mut()
                        && k % m.every.max(1) != 0
                    {
                        w.write(
                            &runner.model().mesh,
                            k,
                            runner.time(),
                            &runner.displacement(),
                        )?;
                    }
                    failure = Some(format!("frame {}: {e:#}", k + 1));
                    break;
                }
            };
            times.push(info.seconds);
            parts.decode += info.parts.decode;
            parts.elastic += info.parts.elastic;
            parts.vjp += info.parts.vjp;
            parts.precond += info.parts.precond;
            if show {
                progress(method.name(), k + 1, frames);
            }
            if !first {
                continue;
            }
            iterations.push(info.iterations);
            step_restarts += usize::from(info.restarted);
            if let Some(q) = runner.coefficients() {
                poses.push(q.to_vec());
            }
            // Reconstruction for the error is outside the timed step.
            let u = runner.displacement();
            errors.add(runner.model(), &u, &reference.frames[k]);
            if let Some(w) = writer.as_mut()
                && ((k + 1) % m.every == 0 || k + 1 == frames)
            {
                w.write(&runner.model().mesh, k + 1, runner.time(), &u)?;
            }
        }
        if times.is_empty() && !first {
            break;
        }
        timed += times.iter().sum::<f64>();
        medians.push(median(&times) * 1e3);
        means.push(mean(&times) * 1e3);
        run_parts.push(parts);
        cubature_elements = runner.elements();
        dim = runner.dim();
        last_runner = Some(runner);
        if failure.is_some() {
            break;
        }
    }
    if let Some(w) = writer {
        w.finish()?;
    }
    let model = pipeline.test_model(m.trajectory)?;
    let ms = median(&means);
    let parts = means
        .iter()
        .zip(&run_parts)
        .min_by(|a, b| (a.0 - ms).abs().total_cmp(&(b.0 - ms).abs()))
        .map_or_else(StepParts::default, |(_, p)| *p);
    let done = iterations.len().max(1);
    let per_step_ms = |seconds: f64| seconds * 1e3 / done as f64;
    let ((subspace_frame_errors, projected_strain), step_frame_errors) = if method.is_full() {
        ((Vec::new(), None), Vec::new())
    } else {
        let fit = pipeline.pca(stage_progress)?;
        let states = reference_states(&fit.basis, &reference.frames);
        let h = pipeline.scene.time.step;
        let energies = reference_energies(pipeline, m.trajectory, &model, &reference.frames);
        match last_runner.as_mut() {
            Some(runner) => (
                subspace_errors(
                    runner,
                    &model,
                    &fit.basis,
                    &states,
                    (&reference.frames, &energies),
                    h,
                    &mut |k, n| progress(&format!("{} subspace", method.name()), k, n),
                )?,
                step_errors(method, runner, &states, &reference.frames, &mut |k, n| {
                    progress(&format!("{} one-step", method.name()), k, n)
                })?,
            ),
            None => ((Vec::new(), None), Vec::new()),
        }
    };
    let (mut training_distance, mut training_distance_time, mut training_seconds) = (0.0, 0.0, 0.0);
    if !poses.is_empty() {
        let training = pipeline.coverage(stage_progress)?;
        // Schedules started from the body's fall run to the test's last frame.
        let frames = if training.later_start {
            pipeline.scene.test().frames_per_schedule
        } else {
            training.frames_per_schedule
        };
        training_seconds = frames as f64 * pipeline.scene.time.step;
        for (k, q) in poses.iter().enumerate() {
            let d = training.poses.distance(q);
            if d > training_distance {
                training_distance = d;
                training_distance_time = (k + 1) as f64 * pipeline.scene.time.step;
            }
        }
    }
    // A neural method's latent dimension and the basis it decodes to, for advice that names
    // them.
    let latent = if method.is_neural() {
        Some(Latent {
            latent_dim: pipeline.train(stage_progress)?.latent_dim,
            pca_dim: pipeline.pca(stage_progress)?.basis.k(),
        })
    } else {
        None
    };
    Ok(MethodReport {
        method,
        dim,
        latent,
        cubature_elements,
        ms_per_step: ms,
        ms_min: means.iter().copied().fold(f64::INFINITY, f64::min),
        ms_median: median(&medians),
        ms_max: means.iter().copied().fold(0.0, f64::max),
        timed_runs: means.len(),
        hz: 1e3 / ms,
        speedup: None,
        mean_rel_error: mean(&errors.rel),
        max_rel_error: errors.rel.iter().fold(0.0, |a, &b| a.max(b)),
        trajectory_error: errors.trajectory_error(),
        max_vertex_error: errors.max_vertex,
        iterations: mean_usize(&iterations),
        subspace_error: mean(&subspace_frame_errors),
        projected_strain,
        step_error: mean(&step_frame_errors),
        decode_ms: per_step_ms(parts.decode),
        elastic_ms: per_step_ms(parts.elastic),
        vjp_ms: per_step_ms(parts.vjp),
        precond_ms: per_step_ms(parts.precond),
        frame_errors: errors.rel,
        subspace_frame_errors,
        step_frame_errors,
        training_distance,
        training_distance_time,
        training_seconds,
        step_restarts,
        failure,
        machine_gfma,
        restart: None,
        restart_failed: None,
        compression: None,
        buckling: None,
        scene_warnings: Vec::new(),
        basis_cap: None,
    })
}

/// The reference's PCA coefficients at steps 0 (rest), 1, …, n: frame j is the state after
/// step j + 1.
fn reference_states(basis: &pca::PcaBasis, frames: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let k = basis.k();
    let mut states = Vec::with_capacity(frames.len() + 1);
    states.push(vec![0.0; k]);
    for f in frames {
        let mut q = vec![0.0; k];
        basis.project(f, &mut q);
        states.push(q);
    }
    states
}

/// Relative error, frame by frame, of the reference frames' best representation in reduced
/// `runner`'s subspace: its state set to each frame's coefficients (`states`,
/// [`reference_states`]), which the runtime encodes (for PCA, q itself; for the autoencoder with
/// its linear directions, the nearest point of the subspace), and the error of U q. A spring's
/// dent, which the runtime's displacement adds outside the subspace, is left out. With it, the
/// largest ratio of U q's elastic energy to the frame's (`reference`, [`reference_energies`];
/// [`largest_strain_ratio`]) and its time, frames `time_step` apart.
fn subspace_errors(
    runner: &mut Runner,
    model: &FullSpaceModel,
    basis: &pca::PcaBasis,
    states: &[Vec<f64>],
    (frames, reference): (&[Vec<f64>], &[f64]),
    time_step: f64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SubspaceFit> {
    let mut free = vec![0.0; basis.n()];
    let (mut u, mut r) = (vec![0.0; model.num_full()], vec![0.0; model.num_full()]);
    let mut errors = ErrorAccumulator::default();
    let mut buf = fem_core::assembly::AssemblyBuffers::default();
    let mut projected = Vec::with_capacity(frames.len());
    progress(0, frames.len());
    for (j, f) in frames.iter().enumerate() {
        runner.set_state(j + 1, &states[j + 1], &states[j])?;
        let q = runner
            .coefficients()
            .ok_or_else(|| anyhow::anyhow!("a full-space runner has no subspace"))?;
        basis.reconstruct(q, &mut free);
        model.dofs.scatter(&free, &mut u);
        model.dofs.scatter(f, &mut r);
        errors.add_full(&model.mass, &u, &r);
        projected.push(model.elastic_energy(&u, &mut buf));
        progress(j + 1, frames.len());
    }
    let strain = largest_strain_ratio(reference, &projected)
        .map(|(ratio, j)| (ratio, (j + 1) as f64 * time_step));
    Ok((errors.rel, strain))
}

/// The elastic energy of each of test trajectory `trajectory`'s reference `frames` on `model`,
/// computed once per pipeline and shared by every reduced method's strain ratio.
fn reference_energies(
    pipeline: &mut Pipeline<'_>,
    trajectory: usize,
    model: &FullSpaceModel,
    frames: &[Vec<f64>],
) -> std::sync::Arc<Vec<f64>> {
    pipeline
        .reference_energies
        .entry(trajectory)
        .or_insert_with(|| {
            let mut buf = fem_core::assembly::AssemblyBuffers::default();
            let mut u = vec![0.0; model.num_full()];
            let energies = frames
                .iter()
                .map(|f| {
                    model.dofs.scatter(f, &mut u);
                    model.elastic_energy(&u, &mut buf)
                })
                .collect();
            std::sync::Arc::new(energies)
        })
        .clone()
}

/// The subspace error frame by frame, and the largest strain ratio with its time
/// ([`MethodReport::projected_strain`]).
type SubspaceFit = (Vec<f64>, Option<(f64, f64)>);

/// Frames whose reference elastic energy is below this share of the test's largest are left
/// out of [`MethodReport::projected_strain`]: near rest the ratio of two small energies says
/// little (the chain of stop 65 at its first frame: 3.4 at 1/300 of the largest).
pub const STRAIN_FRAMES: f64 = 0.1;

/// The largest ratio of `projected` to `reference` elastic energy (per frame) over the frames
/// [`STRAIN_FRAMES`] admits, and the index of its frame.
fn largest_strain_ratio(reference: &[f64], projected: &[f64]) -> Option<(f64, usize)> {
    let top = reference
        .iter()
        .copied()
        .filter(|e| e.is_finite())
        .fold(0.0, f64::max);
    reference
        .iter()
        .zip(projected)
        .enumerate()
        .filter(|(_, (r, p))| {
            r.is_finite() && p.is_finite() && **r > 0.0 && **r >= STRAIN_FRAMES * top
        })
        .map(|(j, (r, p))| (p / r, j))
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// The relative error of one step of reduced `runner` from each frame's two predecessors in
/// the reference (`states`, [`reference_states`]; rest before the first step), frame by frame;
/// its own trajectory's state is replaced frame by frame. A failed step ends the list there
/// (logged): the trajectory's own failure is reported with its row.
fn step_errors(
    method: Method,
    runner: &mut Runner,
    states: &[Vec<f64>],
    frames: &[Vec<f64>],
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<f64>> {
    let mut errors = ErrorAccumulator::default();
    for (j, f) in frames.iter().enumerate() {
        progress(j, frames.len());
        // Before the first step the body was at rest too.
        runner.set_state(j, &states[j], &states[j.saturating_sub(1)])?;
        if let Err(e) = runner.step() {
            tracing::warn!(
                "{}: the step to frame {} from the reference failed: {e:#}",
                method.name(),
                j + 1
            );
            break;
        }
        errors.add(runner.model(), &runner.displacement(), f);
    }
    // Said ended even where a step failed.
    progress(frames.len(), frames.len());
    Ok(errors.rel)
}

/// The mean of `v` (0 when empty: an empty float sum is −0, which the tables would print).
fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.iter().sum::<f64>() / v.len() as f64
}

fn mean_usize(v: &[usize]) -> f64 {
    v.iter().sum::<usize>() as f64 / v.len().max(1) as f64
}

/// Mean relative error against ms/step (mean), one marker per method, both axes logarithmic.
/// Full space has no error against itself: it is named in the title instead of plotted; the
/// other full-space solvers are drawn apart, so that their round-off does not set the y axis.
pub fn error_plot(scene: &str, rows: &[MethodReport]) -> String {
    let full = rows
        .iter()
        .find(|r| r.method == Method::Full)
        .map(|r| format!(" (full: {:.1} ms/step)", r.ms_per_step))
        .unwrap_or_default();
    let series: Vec<Series> = rows
        .iter()
        .filter(|r| r.method != Method::Full)
        .map(|r| Series {
            name: format!("{} (dim {}, {} el.)", r.method, r.dim, r.cubature_elements),
            points: vec![(r.ms_per_step, r.mean_rel_error)],
            line: false,
            reference: r.method.is_full(),
            color: Some(r.method.color()),
            ..Default::default()
        })
        .collect();
    let plot = Plot {
        title: format!("{scene}: error against cost{full}"),
        x_label: "ms per step (mean)".into(),
        y_label: "mean relative error".into(),
        x_scale: Scale::Log,
        y_scale: Scale::Log,
    };
    crate::plot::svg(&plot, &series)
}

/// The reduced rows (full space has no error against itself).
fn reduced_rows(rows: &[MethodReport]) -> impl Iterator<Item = &MethodReport> {
    rows.iter().filter(|r| !r.method.is_full())
}

/// The errors frame by frame as CSV: frame, time, then for every reduced method its trajectory
/// error and its one-step error (empty cells past a failure). Frames where the reference is at
/// rest have no relative error and are left out of both lists, so on a scene that starts at
/// rest without gravity the rows count the frames that moved.
pub fn errors_csv(rows: &[MethodReport], h: f64) -> String {
    let reduced: Vec<&MethodReport> = reduced_rows(rows).collect();
    let mut s = String::from("frame,time");
    for r in &reduced {
        s.push_str(&format!(",{0},{0} one-step", r.method));
    }
    s.push('\n');
    let frames = reduced
        .iter()
        .map(|r| r.frame_errors.len().max(r.step_frame_errors.len()))
        .max()
        .unwrap_or(0);
    let cell = |v: &[f64], j: usize| v.get(j).map(|e| e.to_string()).unwrap_or_default();
    for j in 0..frames {
        s.push_str(&format!("{},{}", j + 1, (j + 1) as f64 * h));
        for r in &reduced {
            s.push_str(&format!(
                ",{},{}",
                cell(&r.frame_errors, j),
                cell(&r.step_frame_errors, j)
            ));
        }
        s.push('\n');
    }
    s
}

/// Relative error against time, one colour per reduced method: the trajectory's error (solid)
/// and the error of one step from the reference (dashed). A solid line far above its dashed
/// one is a trajectory that drifts away in small steps.
pub fn frame_error_plot(scene: &str, rows: &[MethodReport], h: f64) -> String {
    let over_time = |v: &[f64]| -> Vec<(f64, f64)> {
        v.iter()
            .enumerate()
            .map(|(j, &e)| ((j + 1) as f64 * h, e))
            .collect()
    };
    let mut series = Vec::new();
    for r in reduced_rows(rows) {
        let i = r.method.color();
        series.push(Series {
            name: r.method.to_string(),
            points: over_time(&r.frame_errors),
            line: true,
            dashed: false,
            color: Some(i),
            ..Default::default()
        });
        series.push(Series {
            // Listed under its method, in its colour, dashed: the name can stay short.
            name: "one step".into(),
            points: over_time(&r.step_frame_errors),
            line: true,
            dashed: true,
            color: Some(i),
            ..Default::default()
        });
    }
    let plot = Plot {
        title: format!("{scene}: error along the test trajectory"),
        x_label: "time (s)".into(),
        y_label: "relative error ‖u − u_full‖_M / ‖u_full‖_M".into(),
        x_scale: Scale::Linear,
        y_scale: Scale::Log,
    };
    crate::plot::svg(&plot, &series)
}

/// A probed multiply–add rate as a table cell (a dash where none was probed).
pub(crate) fn gfma_cell(rate: Option<f64>) -> String {
    rate.map_or_else(|| "—".into(), |g| format!("{g:.1}"))
}

/// A table's cell of what only a reduced method has (its subspace error, one-step error,
/// distance from the training data): `cell`, or "—" for a full-space method, which has no
/// subspace and no training data to be measured against.
pub(crate) fn reduced_cell(method: Method, cell: String) -> String {
    if method.is_full() { "—".into() } else { cell }
}

/// The report as a markdown table.
pub fn markdown(rows: &[MethodReport]) -> String {
    let mut s = String::from(
        "| method | dim | elements | ms/step (mean) | median ms/step | Hz | speed-up | mean rel. error | space-time error | max rel. error | max vertex error | subspace error | one-step error | from training | iterations | machine G FMA/s |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let reduced = |cell| reduced_cell(r.method, cell);
        s.push_str(&format!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.1} | {} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {} | {} | {} | {:.1} | {} |\n",
            match &r.failure {
                Some(_) => format!("{} (failed)", r.method),
                None => r.method.to_string(),
            },
            r.dim,
            r.cubature_elements,
            r.ms_per_step,
            r.ms_median,
            r.hz,
            speedup_cell(r.speedup, 1),
            r.mean_rel_error,
            r.trajectory_error,
            r.max_rel_error,
            r.max_vertex_error,
            reduced(format!("{:.2e}", r.subspace_error)),
            reduced(format!("{:.2e}", r.step_error)),
            reduced(format!("{:.2}", r.training_distance)),
            r.iterations,
            gfma_cell(r.machine_gfma),
        ));
    }
    for r in rows {
        if let Some(f) = &r.failure {
            s.push_str(&format!("\n{} failed at {f}\n", r.method));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    /// A report names a scene file by its absolute path (a relative one is taken from where the
    /// command runs: a test runs in its crate's folder, which holds Cargo.toml), and the
    /// built-in scene by its name.
    #[test]
    fn a_report_names_its_scene_file_absolutely() {
        let here = std::env::current_dir().unwrap();
        assert_eq!(
            super::scene_file("Cargo.toml"),
            here.join("Cargo.toml").display().to_string()
        );
        assert_eq!(
            super::scene_file("<built-in cantilever>"),
            "<built-in cantilever>"
        );
    }

    /// A step longer than the body's slowest swing is said, naming the step in seconds that a
    /// step in milliseconds meant; a step within it, no sag, or no gravity say nothing.
    #[test]
    fn a_step_past_the_slowest_swing_is_said() {
        let b = super::Buckling {
            load_factor: None,
            sag: 0.05,
            size: 0.3,
            standing_modulus: None,
            firm_modulus: 1e5,
            converged: true,
        };
        let period = b.swing_period(9.81).unwrap();
        assert!((period - 2.0 * std::f64::consts::PI * (0.05f64 / 9.81).sqrt()).abs() < 1e-12);
        assert!((period - 0.4486).abs() < 1e-3, "{period}");
        let w = b.step_warning(16.67, 9.81).expect("a step in milliseconds");
        assert!(w.contains("`[time] step = 0.01667`"), "{w}");
        assert!(w.contains("37.2 times"), "{w}");
        assert_eq!(b.step_warning(0.01667, 9.81), None);
        assert_eq!(b.step_warning(0.4, 9.81), None);
        let seconds = b.step_warning(0.5, 9.81).expect("a step past the swing");
        assert!(
            !seconds.contains("milliseconds") && seconds.contains("below 0.04486 s"),
            "{seconds}"
        );
        // A stiff small body's swing lasts a couple of milliseconds: the step it asks for is
        // said in significant digits, not rounded to "0.000 s" (a z-up fork pinned along y).
        let stiff = super::Buckling { sag: 6.386e-7, ..b };
        let w = stiff
            .step_warning(0.01, 9.81)
            .expect("a step past a 1.6 ms swing");
        assert!(
            w.contains("about 0.001603 s") && w.contains("below 0.0001603 s"),
            "{w}"
        );
        assert_eq!(b.step_warning(16.67, 0.0), None);
        let flat = super::Buckling { sag: 0.0, ..b };
        assert_eq!(flat.step_warning(16.67, 9.81), None);
    }

    /// The largest projected-to-reference energy ratio, over the frames whose reference energy
    /// is at least a tenth of the largest; frames near rest, non-finite or zero energies left out.
    #[test]
    fn the_strain_ratio_skips_frames_near_rest() {
        let reference = [1e-4, 1.0, 2.0, 0.05, f64::NAN, 3.0];
        let projected = [1.0, 3.0, 2.2, 5.0, 1.0, f64::INFINITY];
        // Frame 0 (3/10⁴ of the largest, ratio 10⁴) and frame 3 (ratio 100, at 1/60) are near
        // rest; frame 4's reference and frame 5's projection are not finite.
        assert_eq!(
            super::largest_strain_ratio(&reference, &projected),
            Some((3.0, 1))
        );
        assert_eq!(super::largest_strain_ratio(&[0.0; 3], &[1.0; 3]), None);
    }

    use super::{ErrorAccumulator, Method, MethodReport, mean, standing_line};
    use fem_core::element::Elements;
    use fem_core::mass::{MassKind, MassMatrix};
    use fem_core::mesh::generate::{BoxSpec, box_mesh};

    /// A trajectory that lags its reference by a fixed shift while the reference swings
    /// through rest: each frame's ratio is the lag over the displacement, unbounded near rest,
    /// while the space–time error is the lag over the trajectory's size.
    #[test]
    fn the_space_time_error_weighs_frames_by_their_size() {
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.2, 0.2],
            cells: [4, 1, 1],
            ..Default::default()
        })
        .unwrap();
        let mass = MassMatrix::new(
            &Elements::new(&mesh),
            mesh.num_vertices(),
            1000.0,
            MassKind::Lumped,
        );
        let n = 3 * mesh.num_vertices();
        let shape: Vec<f64> = (0..n).map(|i| ((i * 7) % 5) as f64 * 0.01 + 0.01).collect();
        // Amplitudes 1, 0.01 and −1 of one shape; the method is off by 0.02 of it each frame.
        let mut errors = ErrorAccumulator::default();
        for a in [1.0, 0.01, -1.0] {
            let r: Vec<f64> = shape.iter().map(|s| a * s).collect();
            let u: Vec<f64> = shape.iter().map(|s| (a + 0.02) * s).collect();
            errors.add_full(&mass, &u, &r);
        }
        let expected_rel = [0.02, 2.0, 0.02];
        for (e, x) in errors.rel.iter().zip(expected_rel) {
            assert!((e - x).abs() < 1e-12 * x, "{:?}", errors.rel);
        }
        let expected = 0.02 * (3.0 / (1.0 + 1e-4 + 1.0_f64)).sqrt();
        assert!(
            (errors.trajectory_error() - expected).abs() < 1e-12,
            "{} against {expected}",
            errors.trajectory_error()
        );
        assert_eq!(ErrorAccumulator::default().trajectory_error(), 0.0);
    }

    /// Two figures print with more decimals only where the usual ones read the same.
    #[test]
    fn distinct_figures_read_distinct() {
        let pair = |a: &str, b: &str| (a.to_string(), b.to_string());
        assert_eq!(super::distinct(0.9112, 0.9149, 2), pair("0.911", "0.915"));
        assert_eq!(super::distinct(1.2, 3.4, 2), pair("1.20", "3.40"));
        assert_eq!(super::distinct(0.5, 0.5, 2), pair("0.50", "0.50"));
        assert_eq!(
            super::distinct(0.50001, 0.50002, 2),
            pair("0.50001", "0.50002")
        );
    }

    /// The compression of a trajectory: its smallest det F and when, the frames with an
    /// inverted element, and the largest share of the volume squeezed under half and when, over
    /// a pinned box's free displacements.
    #[test]
    fn compression_finds_the_most_squeezed_frame() {
        let build = |material: &str| {
            crate::scene::Scene::from_str(
                &format!(
                    "name = \"box\"\n[mesh]\ngenerate = {{ size = [1.0, 1.0, 1.0], cells = [2, 2, 2] }}\n\
                     [material]\nmodel = \"{material}\"\nyoungs_modulus = 1e5\npoisson_ratio = 0.3\n\
                     [[pin]]\nplane = {{ axis = \"y\", side = \"min\", tolerance = 1e-6 }}\n"
                ),
                std::path::Path::new("."),
                "box.toml",
            )
            .unwrap()
            .build_model()
            .unwrap()
            .model
        };
        let model = build("linear");
        // Each free vertex moved down by `s` times its height: det F = 1 − s everywhere.
        let frame = |s: f64| {
            let mut u = vec![0.0; model.num_full()];
            for (i, v) in model.mesh.vertices.iter().enumerate() {
                u[3 * i + 1] = -s * v.y;
            }
            let mut free = vec![0.0; model.dofs.num_free()];
            model.dofs.gather(&u, &mut free);
            free
        };
        let frames = [frame(0.1), frame(0.7), frame(1.5), frame(0.2)];
        let c = super::Compression::of(&model, &frames, 0.01).unwrap();
        assert!((c.volume_ratio - (-0.5)).abs() < 1e-12, "{c:?}");
        assert!((c.time - 0.03).abs() < 1e-12, "{c:?}");
        assert_eq!(c.inverted_frames, 1);
        // Every element is squeezed from the second frame on: the whole body, first at 0.02 s.
        assert!((c.squeezed_share - 1.0).abs() < 1e-12, "{c:?}");
        assert!((c.squeezed_time - 0.02).abs() < 1e-12, "{c:?}");
        let mild = super::Compression::of(&model, &[frame(0.1)], 0.01).unwrap();
        assert_eq!((mild.squeezed_share, mild.inverted_frames), (0.0, 0));
        // The linear material's left-out strain ½‖HᵀH‖ with H = diag(0, −s, 0): s²/2 in every
        // element, largest at s = 1.5.
        let (strain, time) = c.linear_strain.expect("a linear material");
        assert!(
            (strain - 1.125).abs() < 1e-12 && (time - 0.03).abs() < 1e-12,
            "{c:?}"
        );
        assert!(
            (mild.linear_strain.unwrap().0 - 0.005).abs() < 1e-12,
            "{mild:?}"
        );
        // Another material has no such measure.
        let c = super::Compression::of(&build("stable-neo-hookean"), &frames, 0.01).unwrap();
        assert_eq!(c.linear_strain, None, "{c:?}");
        assert!((mild.volume_ratio - 0.9).abs() < 1e-12, "{mild:?}");
        assert!(super::Compression::of(&model, &[], 0.01).is_none());
        // No frame above stretched anything past the limit; one pulled up to 5 times its height
        // (F = diag(1, 5, 1)) does, and when (and one to 3.5 times does not).
        assert_eq!(c.stretched, None);
        let pulled = super::Compression::of(&model, &[frame(0.1), frame(-4.0), frame(-2.5)], 0.01)
            .unwrap()
            .stretched
            .expect("stretched 5 times");
        assert!(
            (pulled.0 - 5.0).abs() < 1e-9 && (pulled.1 - 0.02).abs() < 1e-12,
            "{pulled:?}"
        );
        assert_eq!(
            super::Compression::of(&model, &[frame(-2.5)], 0.01)
                .unwrap()
                .stretched,
            None
        );
        // A shear whose F has a Frobenius norm past the limit (4.06) and a largest stretch
        // below it (3.83): the stretch, not the norm, decides.
        let sheared = {
            let mut u = vec![0.0; model.num_full()];
            for (i, v) in model.mesh.vertices.iter().enumerate() {
                (u[3 * i], u[3 * i + 1]) = (1.5 * v.y, 2.5 * v.y);
            }
            let mut free = vec![0.0; model.dofs.num_free()];
            model.dofs.gather(&u, &mut free);
            free
        };
        let c = super::Compression::of(&model, &[sheared], 0.01).unwrap();
        assert_eq!(c.stretched, None, "{c:?}");
    }

    /// A sliver stretched far in F by a small move of its corner holds almost no volume and
    /// is not a body pulled apart; a whole element stretched as far is.
    #[test]
    fn a_stretched_sliver_alone_is_not_a_body_pulled_apart() {
        let dir = std::env::temp_dir().join(format!("sliver-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // A unit tet and, under its base, a sliver 1 mm high sharing the base.
        std::fs::write(
            dir.join("sliver.mesh"),
            "MeshVersionFormatted 2\nDimension 3\nVertices\n5\n0 0 0 0\n1 0 0 0\n0 1 0 0\n\
             0 0 1 0\n0.3 0.3 -0.001 0\nTetrahedra\n2\n1 2 3 4 0\n1 3 2 5 0\nEnd\n",
        )
        .unwrap();
        let model = crate::scene::Scene::from_str(
            "name = \"sliver\"\n[mesh]\npath = \"sliver.mesh\"\n[material]\nmodel = \"linear\"\n\
             youngs_modulus = 1e5\npoisson_ratio = 0.3\n[[pin]]\n\
             plane = { axis = \"y\", side = \"min\", tolerance = 1e-6 }\n",
            &dir,
            "sliver.toml",
        )
        .unwrap()
        .build_model()
        .unwrap()
        .model;
        let moved = |v: usize, by: [f64; 3]| {
            let mut u = vec![0.0; model.num_full()];
            u[3 * v..3 * v + 3].copy_from_slice(&by);
            let mut free = vec![0.0; model.dofs.num_free()];
            model.dofs.gather(&u, &mut free);
            free
        };
        // The sliver's corner down 1 cm: its height 11 times what it was.
        let sliver = moved(4, [0.0, 0.0, -0.01]);
        let c = super::Compression::of(&model, std::slice::from_ref(&sliver), 0.01).unwrap();
        assert_eq!(c.stretched, None, "{c:?}");
        // The unit tet's corner 5 m up: the tet six times its height.
        let pulled = moved(2, [0.0, 5.0, 0.0]);
        let c = super::Compression::of(&model, &[sliver, pulled], 0.01).unwrap();
        let (stretch, time) = c.stretched.expect("a whole element stretched");
        assert!(stretch >= 6.0 && (time - 0.02).abs() < 1e-12, "{c:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A report row's method is written as its name, in JSON as in the tables.
    #[test]
    fn rows_name_their_method_by_its_name() {
        for method in [
            Method::Full,
            Method::FullLbfgs,
            Method::FullNewton,
            Method::Pca,
            Method::PcaCubature,
            Method::Neural,
            Method::NeuralCubature,
        ] {
            let row = MethodReport {
                method,
                ..Default::default()
            };
            let json = serde_json::to_value(&row).unwrap();
            assert_eq!(json["method"], method.name());
            assert_eq!(method.to_string(), method.name());
        }
    }

    /// `run` says where neural-cubature stands against pca-cubature when both ran.
    #[test]
    fn the_summary_says_where_neural_cubature_stands() {
        let row = |method, ms_per_step, mean_rel_error| MethodReport {
            method,
            ms_per_step,
            mean_rel_error,
            ..Default::default()
        };
        let line = standing_line(&[
            row(Method::Full, 50.0, 0.0),
            row(Method::PcaCubature, 0.296, 0.00298),
            row(Method::NeuralCubature, 0.205, 0.00532),
        ]);
        assert!(
            line.contains(
                "neural-cubature against pca-cubature: frontier: faster, less accurate \
                 (0.205 against 0.296 ms a step, 0.53 against 0.30 % off"
            ),
            "{line}"
        );
        assert!(
            line.contains("- less accurate: ") && !line.contains("- slower"),
            "{line}"
        );
        let behind = standing_line(&[
            row(Method::PcaCubature, 0.2, 0.01),
            row(Method::NeuralCubature, 0.3, 0.02),
        ]);
        assert!(behind.contains(": behind ("), "{behind}");
        assert!(behind.contains("- slower by 50 %: ") && behind.contains("- less accurate: "));
        // A step a few percent slower is said to be within the spread of step times.
        let close = standing_line(&[
            row(Method::PcaCubature, 0.2, 0.01),
            row(Method::NeuralCubature, 0.206, 0.02),
        ]);
        assert!(
            close.contains("- slower by 3 %, less than step times move between runs: "),
            "{close}"
        );
        assert!(!behind.contains("less than step times move"), "{behind}");
        // Errors level (a tester's flag, 1.184 against 1.185 %): behind on time alone, and no
        // loss of accuracy explained.
        let level = standing_line(&[
            row(Method::PcaCubature, 0.2, 0.01184),
            row(Method::NeuralCubature, 0.3, 0.01185),
        ]);
        assert!(level.contains(": behind ("), "{level}");
        assert!(!level.contains("- less accurate"), "{level}");
        // The slower step's figures, neural-cubature's first.
        let timed = |method, ms_per_step, elements, elastic_ms, precond_ms| MethodReport {
            dim: 40,
            cubature_elements: elements,
            elastic_ms,
            precond_ms,
            iterations: if method == Method::PcaCubature {
                2.0
            } else {
                3.0
            },
            decode_ms: if method == Method::PcaCubature {
                0.0
            } else {
                0.01
            },
            vjp_ms: if method == Method::PcaCubature {
                0.0
            } else {
                0.02
            },
            ..row(method, ms_per_step, 0.01)
        };
        let line = standing_line(&[
            timed(Method::PcaCubature, 0.2, 300, 0.1, 0.05),
            timed(Method::NeuralCubature, 0.3, 400, 0.15, 0.07),
        ]);
        assert!(
            line.contains(
                "- slower by 50 %: 400 against 300 elements, both evaluated in the 40 PCA \
                 coordinates (the decoder's output), 3.0 against 2.0 iterations a step; per \
                 step the decoder 0.030 ms, the elastic terms 0.150 against 0.100 ms, the \
                 preconditioner 0.070 against 0.050 ms"
            ),
            "{line}"
        );
        // Past twice as long, a multiple; a decoder dearer than the other's whole step is said
        // (a tester read "slower by 289 %" on 0.007 ms steps as noise).
        let tiny = standing_line(&[
            timed(Method::PcaCubature, 0.02, 32, 0.01, 0.005),
            timed(Method::NeuralCubature, 0.07, 22, 0.01, 0.005),
        ]);
        assert!(
            tiny.contains("- 3.5 times as long a step: 22 against 32 elements")
                && tiny.contains(
                    "the decoder 0.030 ms (the decoder alone takes longer than pca-cubature's \
                     whole step, 0.020 ms: on a step this cheap it is what a latent space costs)"
                ),
            "{tiny}"
        );
        assert!(!line.contains("the decoder alone"), "{line}");
        // The cause of a larger error: the subspace's, the steps', or the dynamics'.
        let with = |subspace_error, step_error| MethodReport {
            subspace_error,
            step_error,
            ..row(Method::NeuralCubature, 0.1, 0.02)
        };
        // pca-cubature with its subspace and one-step errors, against neural-cubature `n`.
        let against = |subspace_error, step_error, n: MethodReport| {
            let p = MethodReport {
                subspace_error,
                step_error,
                ..row(Method::PcaCubature, 0.2, 0.01)
            };
            standing_line(&[p, n])
        };
        let cause = |n: MethodReport| against(0.01, 0.01, n);
        assert!(cause(with(0.02, 0.02)).contains("its subspace holds the test less well"));
        // A subspace error twice pca-cubature's but far below the error's excess is not it.
        let line = against(0.001, 0.01, with(0.002, 0.02));
        assert!(line.contains("its steps add more error"), "{line}");
        assert!(cause(with(0.01, 0.02)).contains("its steps add more error"));
        assert!(cause(with(0.01, 0.01)).contains("the test's dynamics made more"));
        // No one-step error measured for pca-cubature: the steps are not blamed.
        assert!(cause(with(0.01, 0.0)).contains("the test's dynamics made more"));
        let line = against(0.01, 0.0, with(0.01, 0.02));
        assert!(line.contains("the test's dynamics made more"), "{line}");
        assert!(!cause(with(0.01, 0.01)).contains("- slower"));
        assert_eq!(standing_line(&[row(Method::NeuralCubature, 0.2, 0.01)]), "");
    }

    /// Full space has no subspace error: its mean must print as 0, not −0.
    #[test]
    fn mean_of_nothing_is_positive_zero() {
        assert!(mean(&[]) == 0.0 && mean(&[]).is_sign_positive());
        assert_eq!(mean(&[1.0, 2.0, 6.0]), 3.0);
    }
}
