//! `cargo xtask …`: the pipeline's command line. Parses flags, shows progress, dispatches.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use pipeline::bench::BenchOptions;
use pipeline::pipeline::{Pipeline, StageOutcome};
use pipeline::run::RunOptions;
use pipeline::scene::Scene;
use pipeline::shard::Shard;
use pipeline::simulate::{Method, SimulateOptions, Trajectory};
use pipeline::stress::Condition;
use pipeline::suite::SuiteMesh;
use pipeline::trajectories::MAX_TRAJECTORIES;

mod view;

#[derive(Parser)]
#[command(
    name = "cargo xtask",
    bin_name = "cargo xtask",
    about = "Latent-space dynamics pipeline"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Flags shared by every command.
#[derive(clap::Args, Clone)]
struct Common {
    /// Scene file (TOML); the built-in cantilever when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Artifact cache folder, shared by every command on the scene (default: out/SCENE/cache
    /// in the project's folder, SCENE the scene's name, whatever --out says; outside the
    /// project, in the folder the command runs from).
    #[arg(long)]
    cache: Option<PathBuf>,
}

/// A stage command's arguments: the scene and cache, and where its curves go.
#[derive(clap::Args)]
struct StageArgs {
    #[command(flatten)]
    common: Common,
    /// Folder of the stage's curves (default: out/SCENE/STAGE in the project's folder).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Subcommand)]
enum Command {
    /// The main job: every stage (cached), then each method on the held-out test trajectory,
    /// compared with the full-space reference.
    Run(RunArgs),
    /// Simulate a scene with one method and write frames ParaView opens.
    Simulate(SimulateArgs),
    /// The mesh suite: a minimal scene (mesh, material, bottom pinned, gravity, time step) on
    /// every mesh file of a folder (.mesh, .msh, .vtk, .vtu, TetGen .node/.ele), each run from an
    /// empty cache; one table of every method's error and speed-up and the pipeline's time.
    Suite(SuiteArgs),
    /// Stage `snapshots`: simulate the training schedules.
    Snapshots(SnapshotsArgs),
    /// Stage `pca`: the mass-orthonormal basis (runs `snapshots` first if needed); writes its
    /// spectrum (and, under `[pca] max_vertex_error`, its error curve) to out/SCENE/pca/.
    Pca(StageArgs),
    /// Stage `cubature`: optimized cubature for the PCA subspace (runs earlier stages if needed);
    /// writes its error curve to out/SCENE/cubature/.
    Cubature(StageArgs),
    /// Stage `train`: the autoencoder on the PCA coefficients (runs earlier stages if needed);
    /// writes the loss curve to out/SCENE/train/.
    Train(StageArgs),
    /// Time every method at several sizes on the held-out trajectory (warm-up, repeated runs)
    /// and write bench.json, bench.md and bench.svg (error against ms/step, Pareto front).
    Bench(BenchArgs),
    /// Every method under extreme conditions (time steps, stiffness, Poisson ratio, forces beyond
    /// training, a long free run): a table of stable / error / diverged with the error measured.
    Stress(StressArgs),
    /// Write one reduced method's trained model as a self-contained file (running the stages it
    /// needs, cached as always), for latent-sim's runtime: `ReducedModel::load(path)?.simulator()`.
    Export(ExportArgs),
    /// Drag the mesh in a browser: a loopback server stepping the scene's reduced methods and
    /// full space in real time (running the stages it needs, cached), or a model file's method.
    View(view::ViewArgs),
    /// Run the stages in order, skipping cached ones.
    Pipeline(PipelineArgs),
}

#[derive(clap::Args)]
struct RunArgs {
    #[command(flatten)]
    common: Common,
    /// Output folder (default: out/SCENE in the project's folder; the stage cache stays in
    /// out/SCENE/cache unless --cache moves it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write every K-th frame of each method (0: none).
    #[arg(long, allow_negative_numbers = true, default_value_t = 5)]
    every: usize,
    /// Methods to compare.
    #[arg(long, value_enum, value_delimiter = ',', num_args = 1.., default_values_t = [MethodArg::Full, MethodArg::FullNewton, MethodArg::FullLbfgs, MethodArg::Pca, MethodArg::PcaCubature, MethodArg::Neural, MethodArg::NeuralCubature])]
    methods: Vec<MethodArg>,
    /// Held-out test trajectory to simulate (any index: trajectory i depends only on the
    /// test's seed and i). Default: 0, or 0..`[test] schedules` when the scene asks for more
    /// than one (as `--trajectories`).
    #[arg(long, allow_negative_numbers = true)]
    trajectory: Option<usize>,
    /// Run on held-out test trajectories 0..N instead (every cached stage is kept): trajectory
    /// 0's report where a plain run writes it, trajectory i's in OUT/trajectory-i, and a table
    /// of every method's error on each, with their mean and the worst, in OUT/trajectories.md.
    #[arg(long, allow_negative_numbers = true, conflicts_with = "trajectory", value_parser = clap::value_parser!(u64).range(1..=MAX_TRAJECTORIES as u64))]
    trajectories: Option<u64>,
}

#[derive(clap::Args)]
struct SimulateArgs {
    #[command(flatten)]
    common: Common,
    #[arg(long, value_enum, default_value_t = MethodArg::Full)]
    method: MethodArg,
    /// Drive the simulation with held-out test trajectory N instead of the scene's forces.
    #[arg(long, allow_negative_numbers = true)]
    test: Option<usize>,
    /// Number of frames (overrides the scene).
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u64).range(1..))]
    frames: Option<u64>,
    /// Write every K-th frame (and the last); 0 writes only the summary.
    #[arg(long, allow_negative_numbers = true, default_value_t = 1)]
    every: usize,
    /// Overrides the method's solver: the scene's `[solver] method` for `full`, its `[reduced]
    /// method` for the reduced methods (`full-lbfgs` and `full-newton` name theirs).
    #[arg(long, value_enum)]
    solver: Option<SolverArg>,
    /// Output folder (default: out/SCENE/simulate/METHOD, apart from the frames `run` writes
    /// in out/SCENE/METHOD).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(clap::Args)]
struct SuiteArgs {
    /// Folder of meshes in any format `[mesh] path` takes (default: the shared/ folder's
    /// meshes beside the repository).
    #[arg(long)]
    meshes: Option<PathBuf>,
    /// Leave out meshes with more vertices than this (the generated ones too).
    #[arg(long, allow_negative_numbers = true)]
    max_vertices: Option<usize>,
    /// Young's modulus of every scene, Pa.
    #[arg(long, allow_negative_numbers = true, default_value_t = 1.0e5, value_parser = positive_pascals)]
    youngs_modulus: f64,
    /// The axis the folder's meshes stand on: each is pinned at its lowest 2 % along it, with
    /// gravity along minus it (the generated meshes stand on y).
    #[arg(long, value_enum, default_value_t = AxisArg::Y)]
    up: AxisArg,
    /// The folder's mesh files in other units than metres: their coordinates times this are
    /// metres (0.001 for millimetres, 0.01 for centimetres), as each scene's `[mesh] scale`.
    /// The generated meshes are in metres.
    #[arg(long, allow_negative_numbers = true, default_value_t = 1.0, value_parser = positive_scale)]
    scale: f64,
    /// Output folder (default: out/suite).
    #[arg(long)]
    out: Option<PathBuf>,
    /// The long run: also the generated bars of 15,360 and 58,800 tets (the latter takes tens
    /// of minutes on 2 cores) and a generated figure of 30,078 tets.
    #[arg(long)]
    generated: bool,
    /// Also run every method on test trajectories 1..N of each mesh, after its pipeline's time
    /// is taken: a second table gives each method's mean error over trajectories 0..N and the
    /// worst.
    #[arg(long, allow_negative_numbers = true, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=MAX_TRAJECTORIES as u64))]
    trajectories: u64,
}

#[derive(clap::Args)]
struct SnapshotsArgs {
    #[command(flatten)]
    common: Common,
    /// Simulate only shard I of N (every N-th schedule from I), for array jobs. Without it,
    /// an array job's variables give the shard: SLURM_ARRAY_TASK_ID and
    /// SLURM_ARRAY_TASK_COUNT, or a Kubernetes Indexed Job's JOB_COMPLETION_INDEX with
    /// LATENT_SHARD_COUNT (docs/cluster.md).
    #[arg(long, value_name = "I/N", allow_hyphen_values = true)]
    shard: Option<String>,
    /// Combine shards 0..N into the snapshots artifact.
    #[arg(long, allow_negative_numbers = true, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    merge: Option<u64>,
}

#[derive(clap::Args)]
struct BenchArgs {
    #[command(flatten)]
    common: Common,
    /// Output folder (default: out/SCENE/bench).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Timed runs of the trajectory per variant (after one warm-up run).
    #[arg(long, allow_negative_numbers = true, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=1000))]
    repeats: u64,
    /// PCA dimensions (default: the latent dimensions, half and all of the scene's basis).
    #[arg(long, allow_hyphen_values = true, value_delimiter = ',')]
    pca_dims: Vec<usize>,
    /// Latent dimensions (default: half, once and twice the scene's).
    #[arg(long, allow_hyphen_values = true, value_delimiter = ',')]
    latent_dims: Vec<usize>,
    /// Cubature tolerances (default: 0.1, 0.05, 0.02); the scene's own runs in any case.
    #[arg(long, allow_hyphen_values = true, value_delimiter = ',')]
    tolerances: Vec<f64>,
    /// Complement-direction counts for the neural methods at the scene's latent dimension
    /// (default: none beyond the scene's own; see `[reduced] complement_directions`).
    #[arg(long, allow_hyphen_values = true, value_delimiter = ',')]
    complement_dims: Vec<usize>,
    /// Held-out test trajectory to simulate.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0)]
    trajectory: usize,
}

#[derive(clap::Args)]
struct StressArgs {
    #[command(flatten)]
    common: Common,
    /// Output folder for stress.json and stress.md (default: out/SCENE/stress).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Methods to stress.
    #[arg(long, value_enum, value_delimiter = ',', num_args = 1.., default_values_t = [MethodArg::Full, MethodArg::FullNewton, MethodArg::FullLbfgs, MethodArg::Pca, MethodArg::PcaCubature, MethodArg::Neural, MethodArg::NeuralCubature])]
    methods: Vec<MethodArg>,
    /// Steps in all of the free-run condition: the test trajectory, then no external force up to
    /// this many (the test's frames or fewer: no free step).
    #[arg(long, allow_negative_numbers = true, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(0..=fem_core::integrator::MAX_FRAMES as u64))]
    free_steps: u64,
    /// Held-out test trajectory to simulate.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0)]
    trajectory: usize,
}

#[derive(clap::Args)]
struct ExportArgs {
    #[command(flatten)]
    common: Common,
    /// The reduced method whose model to write.
    #[arg(long, value_enum, default_value_t = ReducedMethodArg::NeuralCubature)]
    method: ReducedMethodArg,
    /// Model file (default: out/SCENE/METHOD.ldm).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Keep the basis rows of every vertex (the whole displacement can be read back, interior
    /// vertices grabbed), not only those of the surface and the evaluated elements.
    #[arg(long)]
    all_rows: bool,
}

#[derive(clap::Args)]
struct PipelineArgs {
    #[command(flatten)]
    common: Common,
    /// Last stage to run.
    #[arg(long, value_enum, default_value_t = StageArg::Pca)]
    until: StageArg,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum MethodArg {
    /// Full space with the scene's solver (the reference).
    Full,
    /// Full space with preconditioned L-BFGS.
    FullLbfgs,
    /// Full space with Newton.
    FullNewton,
    Pca,
    PcaCubature,
    Neural,
    NeuralCubature,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::Full => Method::Full,
            MethodArg::FullLbfgs => Method::FullLbfgs,
            MethodArg::FullNewton => Method::FullNewton,
            MethodArg::Pca => Method::Pca,
            MethodArg::PcaCubature => Method::PcaCubature,
            MethodArg::Neural => Method::Neural,
            MethodArg::NeuralCubature => Method::NeuralCubature,
        }
    }
}

/// The methods a model file can hold: the reduced ones (full space has no trained model).
#[derive(Clone, Copy, ValueEnum)]
enum ReducedMethodArg {
    Pca,
    PcaCubature,
    Neural,
    NeuralCubature,
}

impl From<ReducedMethodArg> for Method {
    fn from(m: ReducedMethodArg) -> Self {
        match m {
            ReducedMethodArg::Pca => Method::Pca,
            ReducedMethodArg::PcaCubature => Method::PcaCubature,
            ReducedMethodArg::Neural => Method::Neural,
            ReducedMethodArg::NeuralCubature => Method::NeuralCubature,
        }
    }
}

/// The axis a folder of meshes stands on (`suite --up`).
#[derive(Clone, Copy, ValueEnum)]
enum AxisArg {
    X,
    Y,
    Z,
}

impl From<AxisArg> for fem_core::constraints::Axis {
    fn from(a: AxisArg) -> Self {
        match a {
            AxisArg::X => Self::X,
            AxisArg::Y => Self::Y,
            AxisArg::Z => Self::Z,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    Newton,
    Lbfgs,
}

#[derive(Clone, Copy, ValueEnum)]
enum StageArg {
    Snapshots,
    Pca,
    Cubature,
    Train,
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        // A warning a user reads before the run's first line: its level and text, without the
        // clock and the module path ("2026-12-02T04:18:08.731909Z  WARN pipeline::pipeline:").
        .without_time()
        .with_target(false)
        // Colour codes only on a terminal (and not under NO_COLOR): a log redirected to a file
        // reads as plain text.
        .with_ansi(
            std::io::IsTerminal::is_terminal(&std::io::stderr())
                && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty()),
        )
        .init();
    if let Err(e) = dispatch(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// What every task shares: the project root that anchors default paths, and one progress bar
/// for long stages (schedules or frames), hidden until a stage reports progress.
struct Context {
    root: PathBuf,
    stage_bar: ProgressBar,
}

impl Context {
    fn new() -> Self {
        let stage_bar = bar(0, "stage");
        stage_bar.set_draw_target(ProgressDrawTarget::hidden());
        Self {
            root: pipeline::output_root(),
            stage_bar,
        }
    }

    /// A long stage's progress, `(done, total)`, on the stage bar; in a log, where no bar is
    /// drawn, a line every [`LOG_EVERY`].
    fn stage_progress(&self, done: usize, total: usize) {
        log_progress(done, total);
        let b = &self.stage_bar;
        if b.is_hidden() {
            b.set_draw_target(ProgressDrawTarget::stderr());
        }
        b.set_length(total as u64);
        b.set_position(done as u64);
        if done == total {
            b.finish_and_clear();
            b.set_draw_target(ProgressDrawTarget::hidden());
            b.reset();
        }
    }

    /// `out/SCENE/PARTS…` under the project root (or the folder the command runs from, outside
    /// it: [`pipeline::output_root`]).
    fn out(&self, scene: &Scene, parts: &[&str]) -> PathBuf {
        parts
            .iter()
            .fold(self.root.join("out").join(&scene.name), |p, s| p.join(s))
    }

    /// The scene file given, or the built-in cantilever.
    fn scene(&self, common: &Common) -> Result<Scene> {
        match &common.scene {
            Some(p) => Scene::from_file(p),
            None => Ok(Scene::builtin()),
        }
    }

    /// The cache folder given, or `out/SCENE/cache`.
    fn cache(&self, scene: &Scene, common: &Common) -> PathBuf {
        common
            .cache
            .clone()
            .unwrap_or_else(|| self.out(scene, &["cache"]))
    }

    /// The folder of the scene's last `run` report: beside the cache `--cache` names when that
    /// folder holds a `report.json` of this scene (`run --cache C --out O` writes O/report.json,
    /// and C's default is O/cache), else `out/SCENE`.
    fn run_report_dir(&self, scene: &Scene, common: &Common) -> PathBuf {
        common
            .cache
            .as_deref()
            .and_then(Path::parent)
            .filter(|dir| report_scene(&dir.join("report.json")).as_deref() == Some(&scene.name))
            .map_or_else(|| self.out(scene, &[]), PathBuf::from)
    }

    /// A pipeline for the scene and its output folder `out`: a file in the folder's place is
    /// said first, and the folder is made once the model is built, so that a scene the model
    /// refuses (a pin that selects nothing) leaves no empty folder.
    fn pipeline_into<'a>(
        &self,
        scene: &'a Scene,
        common: &Common,
        out: PathBuf,
    ) -> Result<(Pipeline<'a>, PathBuf)> {
        pipeline::output::check_folder(&out, OUT_NAME, OUT_PURPOSE)?;
        let p = self.pipeline(scene, common)?;
        Ok((p, output_folder(out)?))
    }

    /// A pipeline for the scene, printing each stage's outcome.
    fn pipeline<'a>(&self, scene: &'a Scene, common: &Common) -> Result<Pipeline<'a>> {
        let mut p = Pipeline::new(scene, self.cache(scene, common))?;
        println!("{}", p.body_summary());
        p.on_stage = Box::new(print_stage);
        p.on_stage_start = Box::new(stage_started);
        Ok(p)
    }
}

/// A Young's modulus from the command line: a positive, finite number of pascals.
fn positive_scale(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(_) => Err(format!(
            "a scale is a positive number, the metres in one of the files' units (0.001 for \
             millimetres), got {text}"
        )),
        Err(e) => Err(e.to_string()),
    }
}

fn positive_pascals(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(_) => Err(format!(
            "a Young's modulus is a positive number of pascals, got {text}"
        )),
        Err(e) => Err(e.to_string()),
    }
}

fn bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>12} [{bar:40.cyan/blue}] {pos}/{len} {per_sec} eta {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

/// A bar for methods stepping through frames, `(method, done, total)`, and with `say_ends` a
/// line when each run ends (in a log, where no bar is drawn, the time between two stage lines
/// is then accounted for; `bench`, whose variants repeat their runs, says its variants instead).
fn method_progress(bar: &ProgressBar, say_ends: bool) -> impl FnMut(&str, usize, usize) + '_ {
    let mut started = std::time::Instant::now();
    move |m, done, total| {
        if done <= 1 && bar.message() != m {
            started = std::time::Instant::now();
        }
        bar.set_message(m.to_string());
        bar.set_length(total as u64);
        bar.set_position(done as u64);
        if say_ends && done == total {
            let seconds = started.elapsed().as_secs_f64();
            let took = if seconds < 0.1 {
                format!("{:.1} ms", seconds * 1e3)
            } else {
                format!("{seconds:.1} s")
            };
            // A subspace's errors put the reference's frames in it, one by one; the one-step
            // errors step from them.
            let unit = if total == 1 {
                "run"
            } else if m.ends_with(" subspace") {
                "frames"
            } else {
                "steps"
            };
            let line = format!("{m:>10}: {total} {unit} in {took}");
            if bar.is_hidden() {
                println!("{line}");
            } else {
                bar.println(line);
            }
            bar.set_message("");
        }
    }
}

fn print_stage(o: &StageOutcome) {
    stage_ended(o);
    println!("{o}");
}

/// A stage ended: it and any stage that failed inside it (its error caught) are no longer
/// being computed.
fn stage_ended(o: &StageOutcome) {
    if !o.cached {
        // Down to this stage: one that failed inside it (its error caught) ends with it.
        let mut computing = LOG_STAGES.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(i) = computing.iter().rposition(|s| s.stage == o.stage) {
            computing.truncate(i);
        }
    }
}

/// How often a log, where no progress bar is drawn, gets a line on the stage being computed.
const LOG_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

/// A stage being computed, for the lines a log gets instead of the bar.
struct Computing {
    stage: pipeline::stage::Stage,
    started: std::time::Instant,
    said: std::time::Instant,
}

/// The stages being computed, innermost last (a stage computes the earlier ones it needs).
static LOG_STAGES: std::sync::Mutex<Vec<Computing>> = std::sync::Mutex::new(Vec::new());

/// Whether the stage lines go to a log rather than a terminal: the bar, drawn on stderr, is not
/// in the log.
fn logging() -> bool {
    !std::io::IsTerminal::is_terminal(&std::io::stdout())
}

/// A stage starts to compute: in a log, a line saying so, since its own line comes only when
/// it ends (a 30k-tet mesh's snapshots take minutes).
fn stage_started(stage: pipeline::stage::Stage) {
    let now = std::time::Instant::now();
    let mut computing = LOG_STAGES.lock().unwrap_or_else(|e| e.into_inner());
    // A stage that another being computed needs says so: "pca: computing" came before
    // "snapshots: computing" with nothing to say why (a tester read it as out of order).
    let needed_by = computing.last().map_or(String::new(), |outer| {
        format!(", which {} needs", outer.stage)
    });
    computing.push(Computing {
        stage,
        started: now,
        said: now,
    });
    if logging() {
        println!("{stage:>10}: computing{needed_by}");
    }
}

/// In a log, the innermost stage's progress every [`LOG_EVERY`].
fn log_progress(done: usize, total: usize) {
    if done >= total || !logging() {
        return;
    }
    let mut computing = LOG_STAGES.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(c) = computing.last_mut()
        && c.said.elapsed() >= LOG_EVERY
    {
        c.said = std::time::Instant::now();
        println!(
            "{:>10}: {done} of {total} after {:.0} s",
            c.stage,
            c.started.elapsed().as_secs_f64()
        );
    }
}

/// Ends the command quietly, as other command-line tools end, when its output goes into a pipe
/// closed early (`cargo xtask run | head`): `println!` panics on a broken pipe ("failed printing
/// to stdout: Broken pipe"), since the Rust runtime ignores SIGPIPE (and restoring its default
/// action takes `unsafe`, which the workspace forbids). Exit status 141, a shell's for a command
/// SIGPIPE ended; every other panic as before.
fn quiet_on_a_closed_pipe() {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(141);
        }
        report(info);
    }));
}

fn dispatch(cli: Cli) -> Result<()> {
    quiet_on_a_closed_pipe();
    let cx = Context::new();
    match cli.command {
        Command::Run(args) => run(&cx, args),
        Command::Export(args) => export(&cx, args),
        Command::View(args) => view::view(&cx, args),
        Command::Suite(args) => suite(&cx, args),
        Command::Bench(args) => bench(&cx, args),
        Command::Stress(args) => stress(&cx, args),
        Command::Simulate(args) => simulate(&cx, args),
        Command::Snapshots(args) => snapshots(&cx, args),
        Command::Pca(args) => pca(&cx, &args),
        Command::Cubature(args) => cubature(&cx, &args),
        Command::Train(args) => train(&cx, &args),
        Command::Pipeline(args) => pipeline_until(&cx, args),
    }
}

/// `run`: every stage, then each method on the held-out trajectory, with the report.
fn run(cx: &Context, args: RunArgs) -> Result<()> {
    let RunArgs {
        common,
        out,
        every,
        methods,
        trajectory,
        trajectories,
    } = args;
    let methods = methods_once(&methods)?;
    let scene = cx.scene(&common)?;
    // A scene whose `[test]` asks for several trajectories gets them all, unless one is named.
    let asked = scene.test().schedules;
    let count = match (trajectories, trajectory) {
        (Some(n), _) => Some(n as usize),
        (None, None) if asked > MAX_TRAJECTORIES => bail!(
            "{}: [test] schedules = {asked}: a plain `run` measures at most {MAX_TRAJECTORIES} \
             test trajectories; lower it, or name one with --trajectory",
            scene.source
        ),
        (None, None) if asked > 1 => Some(asked),
        _ => None,
    };
    let (mut p, out) =
        cx.pipeline_into(&scene, &common, out.unwrap_or_else(|| cx.out(&scene, &[])))?;
    let progress = |d, t| cx.stage_progress(d, t);
    // The basis first (and the training data, when it must be computed), so that the stage
    // lines come in order before the methods run; a cached basis loads without its snapshots,
    // which the run does not read (`coverage` keeps what it measures against). Full space
    // alone needs neither.
    if methods.iter().any(|m| !m.is_full()) {
        p.pca(&progress)?;
    }
    let opts = RunOptions {
        out,
        every,
        methods,
        trajectory: trajectory.unwrap_or(0),
    };
    let method_bar = bar(0, "");
    let rows = match count {
        Some(n) => {
            let mut runs = pipeline::trajectories::run_trajectories(
                &mut p,
                &opts,
                n,
                &progress,
                &mut |i| method_bar.println(format!("test trajectory {i} ({} of {n})", i + 1)),
                &mut method_progress(&method_bar, true),
            )?;
            let table = pipeline::trajectories::spreads(&runs);
            method_bar.finish_and_clear();
            println!(
                "\n{} — every method on held-out test trajectories 0..{n} (trajectory 0 is \
                 the default test; its report follows)\n\n{}{}\ntable: {}; trajectory i's \
                 report: {}",
                scene.name,
                pipeline::trajectories::markdown(&table),
                pipeline::trajectories::warnings(&runs, 1),
                opts.out.join("trajectories.md").display(),
                opts.out.join("trajectory-i").display()
            );
            runs.swap_remove(0)
        }
        None => pipeline::run::run(
            &mut p,
            &opts,
            &progress,
            &mut method_progress(&method_bar, true),
        )?,
    };
    method_bar.finish_and_clear();
    if opts
        .methods
        .iter()
        .any(|m| matches!(m, Method::Neural | Method::NeuralCubature))
    {
        println!("{}", p.linear_directions_summary(&progress)?);
    }
    let test_forces = pipeline::run::TestForce::of(&p.test_model(opts.trajectory)?);
    print!(
        "{}",
        pipeline::run::summary(&scene, &opts, &test_forces, &rows)
    );
    // `--trajectories N` ran several draws already.
    if count.is_none() {
        print!("{}", pipeline::run::one_draw(&scene));
    }
    Ok(())
}

/// `export`: one reduced method's trained model as a file for latent-sim's runtime.
fn export(cx: &Context, args: ExportArgs) -> Result<()> {
    let ExportArgs {
        common,
        method,
        out,
        all_rows,
    } = args;
    let method = Method::from(method);
    let scene = cx.scene(&common)?;
    let path = out.unwrap_or_else(|| pipeline::export::model_path(&cx.out(&scene, &[]), method));
    // Said before any stage runs, not after them: a folder, or a path written as one (`dir/`)
    // that does not exist yet, which the write would refuse only after every stage.
    let as_folder = path
        .as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator);
    if path.is_dir() || as_folder {
        bail!(
            "`--out` {} names a folder: give the model file's path, e.g. {}",
            path.display(),
            pipeline::export::model_path(&path, method).display()
        );
    }
    let mut p = cx.pipeline(&scene, &common)?;
    let rows = if all_rows {
        latent_sim::model::Rows::All
    } else {
        latent_sim::model::Rows::Used
    };
    let progress = |d, t| cx.stage_progress(d, t);
    let mut model = pipeline::export::scene_model(&mut p, method, rows, &progress)?;
    // What `run` found of this model, from its report beside the model file, else where `view`
    // looks for the scene's last run: recorded in the file, as `run` records it, and said.
    let out = pipeline::export::report_dir(&path, cx.run_report_dir(&scene, &common));
    pipeline::export::record_run_error(&out, &mut model, &scene);
    model.save(&path)?;
    println!(
        "{}",
        pipeline::export::describe(&scene.name, method, &model, &path)
    );
    println!("{}", pipeline::export::run_verdict(&out, &model, &scene));
    Ok(())
}

/// The scene a `report.json` is of (its `scene` field), if it reads.
fn report_scene(report: &Path) -> Option<String> {
    let text = std::fs::read_to_string(report).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v.get("scene")?.as_str().map(str::to_string)
}

/// `suite`: the minimal scene on every mesh of a folder, with one table.
fn suite(cx: &Context, args: SuiteArgs) -> Result<()> {
    let SuiteArgs {
        meshes,
        max_vertices,
        youngs_modulus,
        up,
        scale,
        out,
        generated,
        trajectories,
    } = args;
    let given = meshes.is_some();
    let dir = meshes.unwrap_or_else(|| pipeline::project_root().join("../shared/meshes"));
    let mut files: Vec<SuiteMesh> = match pipeline::suite::meshes(&dir, max_vertices) {
        Ok(files) => files.into_iter().map(SuiteMesh::File).collect(),
        // The generated bars run without the folder.
        Err(e) if generated => {
            eprintln!("warning: {e:#}; running the generated meshes only");
            Vec::new()
        }
        // The default folder is the development checkout's shared/ beside the repository,
        // which a user's clone does not have.
        Err(e) if !given && !dir.is_dir() => {
            return Err(e.context(
                "with no `--meshes DIR`, the suite reads the meshes of ../shared/meshes beside \
                 the repository: give your folder of meshes with `--meshes DIR`, or \
                 `--generated` for the meshes generated in code (tens of minutes; with \
                 `--max-vertices 7000` the 15k-tet bar and the 30k-tet figure only)",
            ));
        }
        Err(e) => return Err(e),
    };
    if generated {
        for g in pipeline::suite::generated() {
            if let Some(max) = max_vertices {
                // Generated once for its size (the suite generates it again to run it).
                let vertices = g.read()?.num_vertices();
                if vertices > max {
                    eprintln!(
                        "warning: suite: leaving out the generated {}: {vertices} vertices, \
                         above --max-vertices {max}",
                        g.name()
                    );
                    continue;
                }
            }
            files.push(g);
        }
    }
    let out = output_folder(out.unwrap_or_else(|| cx.root.join("out").join("suite")))?;
    let progress = |d, t| cx.stage_progress(d, t);
    let rows = pipeline::suite::run_suite(
        &files,
        youngs_modulus,
        up.into(),
        scale,
        trajectories as usize,
        &out,
        &progress,
        &mut |name| println!("{name}"),
        pipeline::suite::StageHooks {
            start: &stage_started,
            end: &stage_ended,
        },
    )?;
    pipeline::suite::write(&out, &rows)?;
    print!("\n{}", pipeline::suite::markdown(&rows));
    println!("table: {}", out.join("suite.md").display());
    Ok(())
}

/// `--methods` as the pipeline's methods, each named once: checked before any stage runs.
pub(crate) fn methods_once(args: &[MethodArg]) -> Result<Vec<Method>> {
    let methods: Vec<Method> = args.iter().map(|&m| Method::from(m)).collect();
    if let Some(m) = Method::repeated(&methods) {
        bail!("--methods names {m} twice; name each method once");
    }
    Ok(methods)
}

/// `path`, created if needed, as the folder a command writes into: checked before any stage
/// runs, so that a file in its place is said at once, not after the pipeline's minutes.
fn output_folder(path: PathBuf) -> Result<PathBuf> {
    pipeline::output::create_folder(&path, OUT_NAME, OUT_PURPOSE)?;
    Ok(path)
}

/// How the output folder is named in errors, and what it is for.
const OUT_NAME: &str = "`--out`";
const OUT_PURPOSE: &str = "to write the results into";

/// `bench`: every method at several sizes, timed in one process.
fn bench(cx: &Context, args: BenchArgs) -> Result<()> {
    let scene = &cx.scene(&args.common)?;
    let opts = &BenchOptions {
        out: output_folder(args.out.unwrap_or_else(|| cx.out(scene, &["bench"])))?,
        cache: cx.cache(scene, &args.common),
        trajectory: args.trajectory,
        repeats: args.repeats as usize,
        pca_dims: args.pca_dims,
        latent_dims: args.latent_dims,
        tolerances: args.tolerances,
        complement_dims: args.complement_dims,
    };
    let method_bar = bar(0, "");
    let progress = |d, t| cx.stage_progress(d, t);
    let rows = pipeline::bench::bench(
        scene,
        opts,
        &stage_started,
        &mut print_stage,
        &mut |label| method_bar.println(format!("     bench: {label}")),
        &progress,
        &mut method_progress(&method_bar, false),
    )?;
    method_bar.finish_and_clear();
    print!("{}", pipeline::bench::summary(scene, opts, &rows));
    Ok(())
}

/// `stress`: every method under extreme conditions, one line per pair as it ends.
fn stress(cx: &Context, args: StressArgs) -> Result<()> {
    let StressArgs {
        common,
        out,
        methods,
        free_steps,
        trajectory,
    } = args;
    let methods = methods_once(&methods)?;
    let scene = cx.scene(&common)?;
    let out = out.unwrap_or_else(|| cx.out(&scene, &["stress"]));
    let (mut p, out) = cx.pipeline_into(&scene, &common, out)?;
    let progress = |d, t| cx.stage_progress(d, t);
    // Every stage first, so the table's progress is not interleaved with training.
    for &m in &methods {
        match m {
            Method::PcaCubature => drop(p.cubature(&progress)?),
            Method::Neural => drop(p.train(&progress)?),
            Method::NeuralCubature => drop(p.cubature_neural(&progress)?),
            _ => drop(p.pca(&progress)?),
        }
    }
    let results = pipeline::stress::stress(
        &mut p,
        &methods,
        &Condition::defaults(free_steps as usize),
        trajectory,
        &progress,
        &mut |r| println!("{r}"),
    )?;
    pipeline::stress::write(&out, &results)?;
    println!("\n{}", pipeline::stress::markdown(&results));
    if !methods.iter().any(|m| m.is_full()) {
        println!(
            "(no full-space method among --methods: the table says whether each run stayed \
             stable, not its error, which `--methods full,…` measures)"
        );
    }
    println!(
        "stress: {} (also stress.md)",
        out.join("stress.json").display()
    );
    Ok(())
}

/// `simulate`: one method, writing ParaView frames and a summary.
fn simulate(cx: &Context, args: SimulateArgs) -> Result<()> {
    let SimulateArgs {
        common,
        method,
        test,
        frames,
        every,
        solver,
        out,
    } = args;
    let method = Method::from(method);
    let scene = cx.scene(&common)?;
    let mut p = cx.pipeline(&scene, &common)?;
    let opts = SimulateOptions {
        method,
        trajectory: test.map(Trajectory::Test).unwrap_or(Trajectory::Scene),
        out: output_folder(out.unwrap_or_else(|| cx.out(&scene, &["simulate", method.name()])))?,
        frames: frames.map(|f| f as usize),
        every,
        solver: solver.map(|s| match s {
            SolverArg::Newton => fem_core::optim::SolverMethod::Newton,
            SolverArg::Lbfgs => fem_core::optim::SolverMethod::Lbfgs,
        }),
    };
    let frames_bar = bar(0, method.name());
    let progress = |d, t| cx.stage_progress(d, t);
    let result = pipeline::simulate::simulate(&mut p, &opts, &progress, &mut |done, total| {
        frames_bar.set_length(total as u64);
        frames_bar.set_position(done as u64);
    });
    frames_bar.finish_and_clear();
    print!("{}", result?.summary.describe(&opts.out));
    Ok(())
}

/// `snapshots`: the training data, whole, as one shard, or merged from shards.
fn snapshots(cx: &Context, args: SnapshotsArgs) -> Result<()> {
    let SnapshotsArgs {
        common,
        shard,
        merge,
    } = args;
    let scene = cx.scene(&common)?;
    let mut p = cx.pipeline(&scene, &common)?;
    let progress = |d, t| cx.stage_progress(d, t);
    // Without a flag, an array job's variables give the shard.
    let shard = match (shard, merge) {
        (Some(s), _) => Some(parse_shard(&s)?),
        (None, None) => Shard::from_env()?.map(|(s, scheduler)| {
            println!(
                "shard {}/{} from the {scheduler}'s variables",
                s.index, s.count
            );
            s
        }),
        (None, Some(_)) => None,
    };
    match (shard, merge) {
        (Some(_), Some(_)) => bail!("give either --shard or --merge, not both"),
        (Some(s), None) => {
            p.snapshot_shard(s.index, s.count, &progress)?;
        }
        (None, Some(n)) => {
            let set = p.merge_shards(n as usize)?;
            let cached = p
                .outcomes
                .last()
                .is_some_and(|o| o.stage == pipeline::stage::Stage::Snapshots && o.cached);
            if cached {
                println!(
                    "the merged snapshots are already in the cache ({} frames): no shard was read",
                    set.num_frames()
                );
            } else {
                println!("merged {n} shards: {} frames", set.num_frames());
            }
        }
        (None, None) => {
            let set = p.snapshots(&progress)?;
            println!(
                "{} frames of {} free DOFs from {} schedules",
                set.num_frames(),
                set.dim,
                set.schedules.len()
            );
        }
    }
    Ok(())
}

/// A stage command's folder for its curves: `--out`, or out/SCENE/STAGE.
fn stage_out(cx: &Context, scene: &Scene, args: &StageArgs, stage: &str) -> Result<PathBuf> {
    output_folder(args.out.clone().unwrap_or_else(|| cx.out(scene, &[stage])))
}

/// `pca`: the basis, its spectrum and (under the vertex-error rule) its error curve.
fn pca(cx: &Context, args: &StageArgs) -> Result<()> {
    let scene = cx.scene(&args.common)?;
    let mut p = cx.pipeline(&scene, &args.common)?;
    // Made (or refused) before the stage runs, not after.
    let dir = stage_out(cx, &scene, args, "pca")?;
    let fit = p.pca(&|d, t| cx.stage_progress(d, t))?;
    print!("{}", pipeline::stage_report::describe_pca(&fit));
    pipeline::stage_report::write_pca_curves(&dir, &fit)?;
    if fit.max_vertex_error_per_k.is_empty() {
        println!("spectrum: {}", dir.join("spectrum.csv").display());
    } else {
        println!("spectrum and error curve: {}", dir.display());
    }
    Ok(())
}

/// `cubature`: the PCA subspace's rule and its error curve.
fn cubature(cx: &Context, args: &StageArgs) -> Result<()> {
    let scene = cx.scene(&args.common)?;
    let mut p = cx.pipeline(&scene, &args.common)?;
    let dir = stage_out(cx, &scene, args, "cubature")?;
    let c = p.cubature(&|d, t| cx.stage_progress(d, t))?;
    print!("{}", c.describe(p.model.elements.len()));
    c.write_error_curve(&dir)?;
    println!("error curve: {}", dir.join("error.svg").display());
    Ok(())
}

/// `train`: the autoencoder and its loss curve.
fn train(cx: &Context, args: &StageArgs) -> Result<()> {
    let scene = cx.scene(&args.common)?;
    let mut p = cx.pipeline(&scene, &args.common)?;
    let dir = stage_out(cx, &scene, args, "train")?;
    let trained = p.train(&|d, t| cx.stage_progress(d, t))?;
    trained.write_loss_curve(&dir)?;
    print!("{}", trained.describe());
    println!("loss curve: {}", dir.join("loss.svg").display());
    Ok(())
}

/// `pipeline --until STAGE`: the stages in order up to STAGE.
fn pipeline_until(cx: &Context, args: PipelineArgs) -> Result<()> {
    let scene = cx.scene(&args.common)?;
    let mut p = cx.pipeline(&scene, &args.common)?;
    let progress = |d, t| cx.stage_progress(d, t);
    match args.until {
        StageArg::Snapshots => drop(p.snapshots(&progress)?),
        StageArg::Pca => drop(p.pca(&progress)?),
        StageArg::Cubature => drop(p.cubature(&progress)?),
        StageArg::Train => drop(p.train(&progress)?),
    }
    Ok(())
}

fn parse_shard(s: &str) -> Result<Shard> {
    let wrong =
        || anyhow::anyhow!("--shard takes I/N, two whole numbers 0 ≤ I < N, e.g. 0/4; got {s}");
    let (i, n) = s.split_once('/').ok_or_else(wrong)?;
    let (i, n) = (
        i.trim().parse().map_err(|_| wrong())?,
        n.trim().parse().map_err(|_| wrong())?,
    );
    Ok(Shard::new(i, n)?)
}
