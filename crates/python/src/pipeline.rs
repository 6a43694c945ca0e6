//! The pipeline from Python: `run_pipeline` (what `cargo xtask run` does, same stages and
//! cache) with its report as Python objects, and `export_model` (what `cargo xtask export`
//! does). Both run without the GIL.

use std::path::{Path, PathBuf};

use latent_sim::model::Rows;
use pipeline::pipeline::{Pipeline, StageOutcome};
use pipeline::run::{MethodReport, RunOptions};
use pipeline::scene::Scene;
use pipeline::simulate::Method;
use pipeline::trajectories::MAX_TRAJECTORIES;
use pyo3::prelude::*;

use crate::errors::{self, Class};
use crate::interrupt::Interrupt;
use crate::model::Model;

/// Every method, in `cargo xtask run`'s order (its default list).
const METHODS: [Method; 7] = Method::ALL;

fn method(name: &str) -> PyResult<Method> {
    METHODS
        .iter()
        .copied()
        .find(|m| m.name() == name)
        .ok_or_else(|| {
            let names: Vec<_> = METHODS.iter().map(|m| m.name()).collect();
            Class::InvalidArgument.err(format!(
                "unknown method {name:?}; the methods are {}",
                names.join(", ")
            ))
        })
}

/// The scene of a file, or the built-in default scene for None.
fn scene(path: Option<&Path>) -> anyhow::Result<Scene> {
    match path {
        Some(p) => Scene::from_file(p),
        None => Ok(Scene::builtin()),
    }
}

/// Where a pipeline call failed: reading the scene or building its model, or later.
enum Failure {
    Scene(anyhow::Error),
    Run(anyhow::Error),
}

impl Failure {
    fn into_py(self) -> PyErr {
        match self {
            Failure::Scene(e) => errors::pipeline(e, Class::Scene),
            Failure::Run(e) => errors::pipeline(e, Class::Pipeline),
        }
    }
}

/// The scene's pipeline over `cache`: a cache folder that cannot be made is a failure of the
/// run (`PipelineError`, as any other output's), the model's build one of the scene.
fn pipeline_of<'a>(scene: &'a Scene, cache: &Path) -> Result<Pipeline<'a>, Failure> {
    pipeline::output::create_folder(cache, "the cache folder", "for the stages' artifacts")
        .map_err(Failure::Run)?;
    Pipeline::new(scene, cache).map_err(Failure::Scene)
}

/// One stage of a pipeline call: computed or loaded from the cache.
#[pyclass(module = "latent_dynamics", frozen, get_all)]
#[derive(Debug, Clone)]
pub struct Stage {
    /// The stage's name (``snapshots``, ``pca``, ``train``, ``cubature``, ...).
    name: String,
    /// Loaded from the cache rather than computed.
    cached: bool,
    /// Time spent in the stage itself (s).
    seconds: f64,
    /// The artifact's file in the cache.
    path: PathBuf,
    /// What the stage chose and why, in one line.
    summary: String,
}

impl From<&StageOutcome> for Stage {
    fn from(o: &StageOutcome) -> Self {
        Self {
            name: o.stage.name().to_string(),
            cached: o.cached,
            seconds: o.seconds,
            path: o.path.clone(),
            summary: o.summary.clone(),
        }
    }
}

#[pymethods]
impl Stage {
    fn __repr__(&self) -> String {
        format!(
            "Stage({:?}, cached={}, seconds={:.2})",
            self.name,
            if self.cached { "True" } else { "False" },
            self.seconds
        )
    }
}

/// One method's row of a run's report (``report.json``'s fields).
#[pyclass(module = "latent_dynamics", frozen, get_all)]
#[derive(Debug, Clone)]
pub struct MethodRow {
    /// The method's name (``full``, ``pca``, ``neural-cubature``, ...).
    method: String,
    /// Simulated dimension (free degrees of freedom for full space).
    dimension: usize,
    /// Elements the elastic energy is evaluated on.
    elements: usize,
    /// Mean wall time per step (ms), its spread over repeated runs, and the median step (the
    /// typical one, without the occasional expensive step the mean includes).
    ms_per_step: f64,
    ms_min: f64,
    ms_max: f64,
    ms_median: f64,
    /// How many timed runs of the trajectory the times come from.
    timed_runs: usize,
    /// Steps per second.
    hz: f64,
    /// The faster full-space solver's ms/step (mean) over this method's; None when no
    /// full-space method ran beside it.
    speedup: Option<f64>,
    /// Mean and largest over frames of the relative error ‖u − u_full‖_M / ‖u_full‖_M.
    mean_rel_error: f64,
    max_rel_error: f64,
    /// The space–time relative error √(Σ‖u − u_full‖²_M / Σ‖u_full‖²_M) over the frames: not
    /// dominated by frames where the reference passes near rest.
    trajectory_error: f64,
    /// Largest distance of a vertex from its full-space position over all frames (m).
    max_vertex_error: f64,
    /// Mean solver iterations per step.
    iterations: f64,
    /// Mean relative error of the reference's best representation in the method's subspace
    /// (None for full space, which has no subspace).
    subspace_error: Option<f64>,
    /// Mean relative error of one step started from the reference (None for full space).
    step_error: Option<f64>,
    /// How far the method's trajectory left the training data: the largest part of a pose
    /// outside the training snapshots' coefficient ranges, relative to the pose (above 0.1
    /// ``warnings`` says so), and the time (s) it happened (None for full space).
    training_distance: Option<f64>,
    training_distance_time: Option<f64>,
    /// Steps that started again from the last state, not solvable from their extrapolated
    /// start (0 for full space).
    step_restarts: usize,
    /// The relative error frame by frame.
    frame_errors: Vec<f64>,
    /// Why the method stopped before the last frame (None when it finished).
    failure: Option<String>,
}

impl From<&MethodReport> for MethodRow {
    fn from(r: &MethodReport) -> Self {
        let reduced = |x: f64| (!r.method.is_full()).then_some(x);
        Self {
            method: r.method.name().to_string(),
            dimension: r.dim,
            elements: r.cubature_elements,
            ms_per_step: r.ms_per_step,
            ms_min: r.ms_min,
            ms_max: r.ms_max,
            timed_runs: r.timed_runs,
            ms_median: r.ms_median,
            hz: r.hz,
            speedup: r.speedup,
            mean_rel_error: r.mean_rel_error,
            max_rel_error: r.max_rel_error,
            trajectory_error: r.trajectory_error,
            max_vertex_error: r.max_vertex_error,
            iterations: r.iterations,
            // As report.json holds them: what full space has none of is None, not 0.
            subspace_error: reduced(r.subspace_error),
            step_error: reduced(r.step_error),
            training_distance: reduced(r.training_distance),
            training_distance_time: reduced(r.training_distance_time),
            step_restarts: r.step_restarts,
            frame_errors: r.frame_errors.clone(),
            failure: r.failure.clone(),
        }
    }
}

#[pymethods]
impl MethodRow {
    fn __repr__(&self) -> String {
        format!(
            "MethodRow({:?}, dimension={}, elements={}, ms_per_step={:.4}, mean_rel_error={:.4})",
            self.method, self.dimension, self.elements, self.ms_per_step, self.mean_rel_error
        )
    }
}

/// The report of ``run_pipeline``: what ``cargo xtask run`` prints and writes.
#[pyclass(module = "latent_dynamics", frozen, get_all)]
#[derive(Debug, Clone)]
pub struct Report {
    /// The scene's name.
    scene: String,
    /// One row per method, in the order run.
    rows: Vec<MethodRow>,
    /// The stages the run loaded or computed, in order.
    stages: Vec<Stage>,
    /// The run's "not to be trusted" warnings (empty when the full simulation does not give way
    /// and every reduced method is within bounds).
    warnings: Vec<String>,
    /// What the figures do not say by themselves (a trajectory that left the training poses
    /// and still ended close to the full one, reduction slower than full space on this mesh).
    caveats: Vec<String>,
    /// The folder of ``report.json``, ``report.md``, ``report.svg``, ``errors.csv``, ...
    out_dir: PathBuf,
    /// The model file the run wrote (None when no reduced method ran).
    model_path: Option<PathBuf>,
}

impl Report {
    /// The report of a run of `methods` whose rows are `rows`, written to `out_dir`, after
    /// `stages`: the assessment of [`pipeline::trust`] and the model file `run` wrote there.
    fn of(
        scene: &str,
        rows: &[MethodReport],
        stages: &[StageOutcome],
        out_dir: PathBuf,
        methods: &[Method],
    ) -> Self {
        let assessment = pipeline::trust::assess(rows);
        Self {
            scene: scene.to_string(),
            rows: rows.iter().map(MethodRow::from).collect(),
            stages: stages.iter().map(Stage::from).collect(),
            warnings: assessment.untrusted,
            caveats: assessment.caveats,
            model_path: pipeline::export::run_method(methods)
                .map(|m| pipeline::export::model_path(&out_dir, m)),
            out_dir,
        }
    }
}

#[pymethods]
impl Report {
    /// The row of ``method``; raises ``InvalidArgumentError`` when it did not run.
    fn row(&self, method: &str) -> PyResult<MethodRow> {
        self.rows
            .iter()
            .find(|r| r.method == method)
            .cloned()
            .ok_or_else(|| {
                let ran: Vec<&str> = self.rows.iter().map(|r| r.method.as_str()).collect();
                Class::InvalidArgument.err(format!(
                    "no row for method {method:?} in this report; its rows are {}",
                    ran.join(", ")
                ))
            })
    }

    fn __repr__(&self) -> String {
        format!(
            "Report({:?}, {} rows, {} stages)",
            self.scene,
            self.rows.len(),
            self.stages.len()
        )
    }
}

/// The Python callbacks of a pipeline call, from the thread running the pipeline: `on_stage`
/// after each stage, and `on_progress` with the stage computing (or the method running), how
/// far it got and of how much, on its first and last report and at most every
/// [`PROGRESS_EVERY`] between. Every report also checks for Ctrl-C ([`Interrupt`]). A callback's
/// exception stops the call as Ctrl-C does and is raised by it: a typo in a callback that only
/// said so when a 14-minute run ended cost the 14 minutes (the stages done stay cached).
struct Callbacks<'c> {
    on_stage: Option<&'c Py<PyAny>>,
    on_progress: Option<&'c Py<PyAny>>,
    interrupt: &'c Interrupt,
    /// The stages computing, innermost last (a stage computes the earlier ones it needs), and
    /// what `on_progress` was last told and when.
    state: std::sync::Mutex<ProgressState>,
}

/// How often `on_progress` hears of the same stage or method at most.
const PROGRESS_EVERY: std::time::Duration = std::time::Duration::from_secs(1);

#[derive(Default)]
struct ProgressState {
    computing: Vec<pipeline::stage::Stage>,
    said: Option<(String, std::time::Instant)>,
}

impl<'c> Callbacks<'c> {
    fn new(
        py: Python<'_>,
        on_stage: Option<&'c Py<PyAny>>,
        on_progress: Option<&'c Py<PyAny>>,
        interrupt: &'c Interrupt,
    ) -> PyResult<Self> {
        for (name, c) in [("on_stage", on_stage), ("on_progress", on_progress)] {
            if let Some(c) = c
                && !c.bind(py).is_callable()
            {
                return Err(Class::InvalidArgument.err(format!("{name} must be callable")));
            }
        }
        Ok(Self {
            on_stage,
            on_progress,
            interrupt,
            state: std::sync::Mutex::new(ProgressState::default()),
        })
    }

    fn state(&self) -> std::sync::MutexGuard<'_, ProgressState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Calls `callback` with `args`; its exception stops the call.
    fn call<A: for<'py> pyo3::call::PyCallArgs<'py>>(&self, callback: &Py<PyAny>, args: A) {
        if let Some(e) = Python::attach(|py| callback.call1(py, args).err()) {
            self.interrupt.stop(e);
        }
    }

    fn install(&'c self, p: &mut Pipeline<'c>) {
        p.on_stage_start = Box::new(move |stage| self.state().computing.push(stage));
        p.on_stage = Box::new(move |o: &StageOutcome| {
            {
                let mut state = self.state();
                if let Some(i) = state.computing.iter().rposition(|s| *s == o.stage) {
                    state.computing.remove(i);
                }
            }
            if let Some(callback) = self.on_stage {
                self.call(callback, (Stage::from(o),));
            }
            self.interrupt.check();
        });
    }

    /// Stops the call here when Ctrl-C (or a callback's `KeyboardInterrupt`) asked.
    fn check(&self) {
        self.interrupt.check();
    }

    /// A progress report of the innermost stage computing.
    fn stage(&self, done: usize, total: usize) {
        let name = self.state().computing.last().map(|s| s.name().to_string());
        match name {
            Some(name) => self.progress(&name, done, total),
            None => self.interrupt.check(),
        }
    }

    /// A method's run reporting its frames: `on_progress` hears it as `run <method>`, apart
    /// from the stage of the same name (`pca`).
    fn method(&self, label: &str, done: usize, total: usize) {
        self.progress(&format!("run {label}"), done, total);
    }

    /// A progress report of `what` (a stage, or a method's run), passed on to `on_progress`
    /// on its first and last report (done 0, done = total) and a report of something else,
    /// and otherwise at most every [`PROGRESS_EVERY`].
    fn progress(&self, what: &str, done: usize, total: usize) {
        if let Some(callback) = self.on_progress {
            let due = {
                let mut state = self.state();
                let now = std::time::Instant::now();
                let due = done == 0
                    || done >= total
                    || match &state.said {
                        Some((last, at)) => last != what || now - *at >= PROGRESS_EVERY,
                        None => true,
                    };
                if due {
                    state.said = Some((what.to_string(), now));
                }
                due
            };
            if due {
                self.call(callback, (what, done, total));
            }
        }
        self.interrupt.check();
    }
}

/// The methods a `methods` argument names: a list of names, or one name as a string (a list
/// of its letters is no one's meaning, and PyO3 would refuse it in its own words).
fn methods(names: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<Method>> {
    let names: Option<Vec<String>> = match names {
        None => None,
        Some(one) if one.is_instance_of::<pyo3::types::PyString>() => Some(vec![one.extract()?]),
        // A sequence is reserved whole before it is read: a `range(10**12)` is refused first.
        Some(many) if many.len().is_ok_and(|n| n > 4 * Method::ALL.len()) => {
            return Err(Class::InvalidArgument.err(format!(
                "methods lists {} items; there are {} methods",
                many.len().unwrap_or_default(),
                Method::ALL.len()
            )));
        }
        Some(many) => Some(many.extract().map_err(|_| {
            // A list with something else than a name in it: that item, else the whole.
            let item = many.try_iter().ok().and_then(|items| {
                items.enumerate().find_map(|(i, item)| {
                    let item = item.ok()?;
                    (!item.is_instance_of::<pyo3::types::PyString>()).then(|| {
                        format!(
                            "methods[{i}] must be a method name (a str), got {}",
                            crate::simulator::describe(&item)
                        )
                    })
                })
            });
            Class::InvalidArgument.err(item.unwrap_or_else(|| {
                format!(
                    "methods must be a list of method names (e.g. [\"full\", \
                     \"neural-cubature\"]) or one name, got {}",
                    crate::simulator::describe(many)
                )
            }))
        })?),
    };
    match names {
        None => Ok(METHODS.to_vec()),
        Some(names) if names.is_empty() => {
            Err(Class::InvalidArgument.err("methods must name at least one method"))
        }
        Some(names) => {
            let methods: Vec<Method> = names.iter().map(|n| method(n)).collect::<PyResult<_>>()?;
            match Method::repeated(&methods) {
                Some(m) => Err(Class::InvalidArgument
                    .err(format!("methods names {m} twice; name each method once"))),
                None => Ok(methods),
            }
        }
    }
}

/// A count or index argument `name`, refused with a clear error when negative (a bare
/// `OverflowError` before).
fn non_negative(name: &str, value: i64) -> PyResult<usize> {
    usize::try_from(value)
        .map_err(|_| Class::InvalidArgument.err(format!("{name} must be 0 or more, got {value}")))
}

/// The output folder and cache folder of a call: `out/<scene name>` under the current
/// directory and its `cache/` unless given (from the checkout's root these are the folders
/// `cargo xtask` uses).
fn folders(scene: &Scene, out: Option<PathBuf>, cache: Option<PathBuf>) -> (PathBuf, PathBuf) {
    let out = out.unwrap_or_else(|| PathBuf::from("out").join(&scene.name));
    let cache = cache.unwrap_or_else(|| out.join("cache"));
    (out, cache)
}

/// A pipeline call's Python callbacks, as its functions take them.
struct Hooks {
    on_stage: Option<Py<PyAny>>,
    on_progress: Option<Py<PyAny>>,
}

/// Runs `body` without the GIL, stopped by Ctrl-C ([`Interrupt`]), on the pipeline of `scene`:
/// the scene read, its folders and the callbacks installed. `body` gets the scene, the
/// pipeline, the output folder and the [`Callbacks`] its progress reports go to; a callback's
/// exception, if one raised, is raised when `body` is done.
fn with_pipeline<T: Send>(
    py: Python<'_>,
    scene: Option<PathBuf>,
    out_dir: Option<PathBuf>,
    cache_dir: Option<PathBuf>,
    hooks: Hooks,
    body: impl FnOnce(&Scene, &mut Pipeline<'_>, PathBuf, &Callbacks<'_>) -> Result<T, Failure> + Send,
) -> PyResult<T> {
    let interrupt = Interrupt::new();
    let callbacks = Callbacks::new(
        py,
        hooks.on_stage.as_ref(),
        hooks.on_progress.as_ref(),
        &interrupt,
    )?;
    let value = interrupt.run(py, || -> Result<T, Failure> {
        // Each call says its warnings, even those an earlier call said.
        pipeline::pipeline::forget_warnings();
        let scene = self::scene(scene.as_deref()).map_err(Failure::Scene)?;
        let (out, cache) = folders(&scene, out_dir, cache_dir);
        let mut p = pipeline_of(&scene, &cache)?;
        callbacks.install(&mut p);
        body(&scene, &mut p, out, &callbacks)
    })?;
    value.map_err(Failure::into_py)
}

/// [`with_pipeline`] as `cargo xtask run` starts it: the basis computed or loaded first, so that
/// its stage is the first reported.
fn in_run_pipeline<T: Send>(
    py: Python<'_>,
    scene: Option<PathBuf>,
    out_dir: Option<PathBuf>,
    cache_dir: Option<PathBuf>,
    hooks: Hooks,
    body: impl FnOnce(&Scene, &mut Pipeline<'_>, PathBuf, &Callbacks<'_>) -> Result<T, Failure> + Send,
) -> PyResult<T> {
    with_pipeline(py, scene, out_dir, cache_dir, hooks, |scene, p, out, cb| {
        p.pca(&|done, total| cb.stage(done, total))
            .map_err(Failure::Run)?;
        body(scene, p, out, cb)
    })
}

/// Runs the pipeline on a scene and every requested method on one held-out test trajectory, as
/// ``cargo xtask run --trajectory`` does (``run_trajectories`` runs several): the stages load from the cache or are computed (and cached), then
/// each method is simulated and measured against full space. Writes the report files into
/// ``out_dir`` and, when a reduced method ran, the model of ``neural-cubature`` (or the first
/// reduced method) as ``out_dir/<method>.ldm``.
///
/// ``scene``: a scene file (TOML), or None for the built-in default scene. ``out_dir``:
/// default ``out/<scene name>``; ``cache_dir``: default ``out_dir/cache`` (run from the
/// checkout's root, both are ``cargo xtask``'s). ``methods``: a list of names or one name,
/// default every method.
/// ``trajectory``: the held-out test trajectory (any index: trajectory i depends only on the
/// test's seed and i). ``every``: write every K-th frame as ParaView files (0: none). ``on_stage``: called with
/// each ``Stage`` as it ends (from the thread running the pipeline; an exception it raises is
/// raised, and stops the run at once as Ctrl-C does).
/// ``on_progress``: called with the stage computing (``("snapshots", 3, 32)``) or the method
/// running (``("run neural-cubature", 40, 100)``; then its errors, ``"run neural-cubature
/// subspace"`` and ``"run neural-cubature one-step"``), how far it got and of how much, on its first
/// and last report and at most once a second between; one call at a time, from the
/// pipeline's threads (a slow callback slows the run); its exceptions as ``on_stage``'s. What
/// the library warns of while it works (a
/// body that gives way under its own weight, a mesh not in metres) arrives as a
/// ``PipelineWarning`` through ``warnings.warn``. Runs without the
/// GIL, on a thread of its own: Ctrl-C (``KeyboardInterrupt``) in a call from the main thread
/// stops it at its next progress report.
///
/// Raises ``SceneError`` for a scene that cannot be read or has a bad field or mesh,
/// ``SolverError`` when a stage's solve fails, ``InvalidArgumentError`` for an unknown method
/// and ``PipelineError`` otherwise.
#[pyfunction]
#[pyo3(signature = (scene = None, *, out_dir = None, cache_dir = None, methods = None, trajectory = 0, every = 0, on_stage = None, on_progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn run_pipeline(
    py: Python<'_>,
    scene: Option<PathBuf>,
    out_dir: Option<PathBuf>,
    cache_dir: Option<PathBuf>,
    methods: Option<&Bound<'_, PyAny>>,
    trajectory: i64,
    every: i64,
    on_stage: Option<Py<PyAny>>,
    on_progress: Option<Py<PyAny>>,
) -> PyResult<Report> {
    let methods = self::methods(methods)?;
    let (trajectory, every) = (
        non_negative("trajectory", trajectory)?,
        non_negative("every", every)?,
    );
    in_run_pipeline(
        py,
        scene,
        out_dir,
        cache_dir,
        Hooks {
            on_stage,
            on_progress,
        },
        |scene, p, out, cb| {
            let opts = RunOptions {
                out: out.clone(),
                every,
                methods: methods.clone(),
                trajectory,
            };
            let rows = pipeline::run::run(
                p,
                &opts,
                &|done, total| cb.stage(done, total),
                &mut |what, done, total| cb.method(what, done, total),
            )
            .map_err(Failure::Run)?;
            Ok(Report::of(&scene.name, &rows, &p.outcomes, out, &methods))
        },
    )
}

/// Runs the pipeline on a scene and every requested method on held-out test trajectories
/// 0..``count``, as ``cargo xtask run --trajectories count`` does, and returns one ``Report``
/// per trajectory; every cached stage is kept (trajectory i depends only on the test's seed
/// and i, not on ``[test] schedules``). Trajectory 0's files go to ``out_dir`` as
/// ``run_pipeline`` writes them, trajectory i's to ``out_dir/trajectory-i``, and the table of
/// every method's error on each, their mean and the worst to ``out_dir/trajectories.md`` and
/// ``trajectories.json``. A report's ``stages`` are those its trajectory loaded or computed
/// (after the first, its reference). Other arguments and errors as ``run_pipeline``;
/// ``count`` below 1 or above 64 raises ``InvalidArgumentError``.
#[pyfunction]
#[pyo3(signature = (scene = None, count = 4, *, out_dir = None, cache_dir = None, methods = None, every = 0, on_stage = None, on_progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn run_trajectories(
    py: Python<'_>,
    scene: Option<PathBuf>,
    count: i64,
    out_dir: Option<PathBuf>,
    cache_dir: Option<PathBuf>,
    methods: Option<&Bound<'_, PyAny>>,
    every: i64,
    on_stage: Option<Py<PyAny>>,
    on_progress: Option<Py<PyAny>>,
) -> PyResult<Vec<Report>> {
    let every = non_negative("every", every)?;
    let count = usize::try_from(count)
        .ok()
        .filter(|n| (1..=MAX_TRAJECTORIES).contains(n))
        .ok_or_else(|| {
            Class::InvalidArgument.err(format!(
                "count must be from 1 to {MAX_TRAJECTORIES} test trajectories, got {count}"
            ))
        })?;
    let methods = self::methods(methods)?;
    in_run_pipeline(
        py,
        scene,
        out_dir,
        cache_dir,
        Hooks {
            on_stage,
            on_progress,
        },
        |scene, p, out, cb| {
            let stage = |done: usize, total: usize| cb.stage(done, total);
            let opts = RunOptions {
                out: out.clone(),
                every,
                methods: methods.clone(),
                trajectory: 0,
            };
            let (mut runs, mut reports) = (Vec::new(), Vec::new());
            for i in 0..count {
                let before = if i == 0 { 0 } else { p.outcomes.len() };
                pipeline::trajectories::run_more(
                    p,
                    &opts,
                    &mut runs,
                    i + 1,
                    &stage,
                    &mut |_| cb.check(),
                    &mut |what, done, total| cb.method(what, done, total),
                )
                .map_err(Failure::Run)?;
                reports.push(Report::of(
                    &scene.name,
                    &runs[i],
                    &p.outcomes[before..],
                    pipeline::trajectories::trajectory_dir(&out, i),
                    &methods,
                ));
            }
            pipeline::trajectories::write(&out, &runs).map_err(Failure::Run)?;
            Ok(reports)
        },
    )
}

/// Exports a reduced method's trained model as one file, as ``cargo xtask export`` does (the
/// stages load from the cache or are computed), and returns it loaded.
///
/// ``scene``: a scene file, or None for the built-in default scene. ``method``: a reduced
/// method (``pca``, ``pca-cubature``, ``neural``, ``neural-cubature``). ``path``: default
/// ``out/<scene name>/<method>.ldm``; ``cache_dir``: default ``out/<scene name>/cache``.
/// ``all_rows``: keep every vertex's basis rows (so ``Simulator.positions`` can read the whole
/// mesh) rather than only those in use. ``on_stage`` and ``on_progress`` as for ``run_pipeline``. Runs without the
/// GIL; Ctrl-C stops it as it stops ``run_pipeline``.
///
/// Raises as ``run_pipeline``, ``InvalidArgumentError`` for a full-space method, and
/// ``ModelFileError`` when the file cannot be written.
#[pyfunction]
#[pyo3(signature = (scene = None, method = "neural-cubature", *, path = None, cache_dir = None, all_rows = false, on_stage = None, on_progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn export_model(
    py: Python<'_>,
    scene: Option<PathBuf>,
    method: &str,
    path: Option<PathBuf>,
    cache_dir: Option<PathBuf>,
    all_rows: bool,
    on_stage: Option<Py<PyAny>>,
    on_progress: Option<Py<PyAny>>,
) -> PyResult<Model> {
    let method = self::method(method)?;
    if method.is_full() {
        return Err(Class::InvalidArgument.err(format!(
            "{} is a full-space method; only the reduced methods (pca, pca-cubature, neural, \
             neural-cubature) have a trained model",
            method.name()
        )));
    }
    let rows = if all_rows { Rows::All } else { Rows::Used };
    let hooks = Hooks {
        on_stage,
        on_progress,
    };
    let (model, path) = with_pipeline(py, scene, None, cache_dir, hooks, |_, p, out, cb| {
        let progress = |done: usize, total: usize| cb.stage(done, total);
        let mut model =
            pipeline::export::scene_model(p, method, rows, &progress).map_err(Failure::Run)?;
        let path = path.unwrap_or_else(|| pipeline::export::model_path(&out, method));
        // What `run` measured of this model, recorded as `cargo xtask export` records it: from
        // the report beside the file, else the scene's output folder's.
        let report = pipeline::export::report_dir(&path, out.clone());
        pipeline::export::record_run_error(&report, &mut model, p.scene);
        model
            .save(&path)
            .map_err(|e| Failure::Run(anyhow::Error::new(e)))?;
        Ok((model, path))
    })?;
    Ok(Model::new(model, Some(path)))
}
