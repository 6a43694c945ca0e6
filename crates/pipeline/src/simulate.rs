//! `cargo xtask simulate`: time-step a scene with one method and write frames, a series file
//! and a summary. The same runners serve `cargo xtask run`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use fem_core::integrator::{FullSpaceModel, Simulator, StepReport, TimeConfig};
use fem_core::material::MaterialConfig;
use fem_core::optim::{SolverConfig, SolverMethod};
use latent_sim::model::Rows;
use latent_sim::{Interactive, ReducedRuntime, ReducedStepReport};

use crate::output::FrameWriter;
use crate::pipeline::{Pipeline, Progress};
use crate::scene::Scene;

/// Simulation methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Full-space finite elements.
    #[default]
    Full,
    /// Full space with preconditioned L-BFGS whatever the scene's solver (the reference uses the
    /// scene's), so speed-ups are measured against the faster full-space solver.
    FullLbfgs,
    /// Full space with Newton whatever the scene's solver.
    FullNewton,
    /// Linear model reduction with the PCA basis, every element evaluated.
    Pca,
    /// The PCA basis with the elastic energy on the cubature elements only.
    PcaCubature,
    /// The autoencoder's latent space (decoder into the PCA basis), every element evaluated.
    Neural,
    /// The autoencoder's latent space with a cubature rule: the paper's method. The rule is its
    /// own (fitted in the decoder's tangent) unless the PCA subspace's follows training
    /// schedules clearly closer (stage `cubature-neural`).
    NeuralCubature,
}

impl Method {
    /// Every method, in `cargo xtask run`'s order (its default list).
    pub const ALL: [Method; 7] = [
        Method::Full,
        Method::FullNewton,
        Method::FullLbfgs,
        Method::Pca,
        Method::PcaCubature,
        Method::Neural,
        Method::NeuralCubature,
    ];

    /// The method's name on the command line, in reports and in file names (its serde name).
    pub fn name(self) -> &'static str {
        match self {
            Method::Full => "full",
            Method::FullLbfgs => "full-lbfgs",
            Method::FullNewton => "full-newton",
            Method::Pca => "pca",
            Method::PcaCubature => "pca-cubature",
            Method::Neural => "neural",
            Method::NeuralCubature => "neural-cubature",
        }
    }

    /// The method's colour in every plot (an index into [`crate::plot`]'s palette), the same in
    /// `report.svg`, `errors.svg` and `bench.svg` whichever methods a run measured.
    pub fn color(self) -> usize {
        match self {
            Method::FullNewton => 0,
            Method::Pca => 1,
            Method::PcaCubature => 2,
            Method::Neural => 3,
            Method::NeuralCubature => 4,
            Method::Full => 5,
            Method::FullLbfgs => 6,
        }
    }

    /// Whether the method steps through the trained autoencoder.
    pub fn is_neural(self) -> bool {
        matches!(self, Method::Neural | Method::NeuralCubature)
    }

    /// Whether the method simulates in full space.
    pub fn is_full(self) -> bool {
        matches!(self, Method::Full | Method::FullLbfgs | Method::FullNewton)
    }

    /// The first method `methods` names a second time, if any: a list of methods to compare
    /// names each once (twice would measure and write the same method twice).
    pub fn repeated(methods: &[Method]) -> Option<Method> {
        (1..methods.len())
            .find(|&i| methods[..i].contains(&methods[i]))
            .map(|i| methods[i])
    }

    /// Whether this method, among `methods`, repeats `full`: it forces the solver that already
    /// is the scene's (`scene_solver`), and `full` runs too. `run` and `stress` skip it.
    pub fn repeats_full(self, methods: &[Method], scene_solver: SolverMethod) -> bool {
        methods.contains(&Method::Full) && self.forced_full_solver() == Some(scene_solver)
    }

    /// The full-space solver this method forces, whatever the scene's (`None` for `full`, which
    /// uses the scene's, and for the reduced methods).
    pub fn forced_full_solver(self) -> Option<SolverMethod> {
        match self {
            Method::FullLbfgs => Some(SolverMethod::Lbfgs),
            Method::FullNewton => Some(SolverMethod::Newton),
            _ => None,
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

pub use latent_sim::REDUCED_MIN_ITERATIONS;

/// Which forces drive the simulation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Trajectory {
    /// The scene's own `[[force]]` list for `[time] frames` steps.
    #[default]
    Scene,
    /// Held-out test trajectory i of the `[test]` section.
    Test(usize),
}

/// What to simulate and what to write.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    pub method: Method,
    pub trajectory: Trajectory,
    /// Output folder.
    pub out: PathBuf,
    /// Overrides the number of frames.
    pub frames: Option<usize>,
    /// Write every K-th frame (and the last); 0 writes no frames.
    pub every: usize,
    /// Overrides the method's solver: `[solver] method` for `full`, `[reduced] method` for the
    /// reduced methods. `full-lbfgs` and `full-newton` name theirs, so the other one is refused.
    pub solver: Option<SolverMethod>,
}

/// What `summary.json` holds.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Summary {
    pub scene: String,
    pub method: Method,
    pub solver: SolverMethod,
    /// `[solver] max_iterations` of a full-space run (the reduced methods take at least
    /// `REDUCED_MIN_ITERATIONS`).
    pub max_iterations: usize,
    pub vertices: usize,
    pub tets: usize,
    pub free_dofs: usize,
    /// Dimension of the simulated space (free DOFs for full, k for PCA).
    pub dim: usize,
    pub frames_written: usize,
    pub total_seconds: f64,
    /// The mean step (what `run` reports as ms/step) and the median one.
    pub mean_step_ms: f64,
    pub median_step_ms: f64,
    /// Per-step numbers of a full-space run (with energies).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub steps: Vec<StepReport>,
    /// Per-step numbers of a reduced run.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub reduced_steps: Vec<ReducedStepReport>,
    /// Per step of a reduced run, the largest vertex displacement (m) of its decoded state: what
    /// `steps[].max_displacement` is for full space, so that the two compare without the frames.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub reduced_max_displacement: Vec<f64>,
    /// Under the linear material: the largest over the steps of the strain it leaves out
    /// averaged over the body ([`crate::run::Compression::mean_left_out_strain`]), and its time
    /// (s); `run` measures the same of its reference (`linear_strain`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub linear_strain: Option<(f64, f64)>,
}

impl Summary {
    /// What `cargo xtask simulate` shows: the steps, sizes and times, and where the frames
    /// written to `out` are.
    pub fn describe(&self, out: &Path) -> String {
        let mut s = format!(
            "{}: {} steps of {} (dim {}; {} vertices, {} tets) in {:.2} s, {:.3} ms/step (median {:.3}), {} frames written to {}\n",
            self.scene,
            self.steps
                .len()
                .saturating_sub(1)
                .max(self.reduced_steps.len()),
            self.method.name(),
            self.dim,
            self.vertices,
            self.tets,
            self.total_seconds,
            self.mean_step_ms,
            self.median_step_ms,
            self.frames_written,
            out.display()
        );
        let switched: Vec<usize> = self
            .steps
            .iter()
            .filter(|r| r.solver_switched)
            .map(|r| r.step)
            .collect();
        if let Some(line) = crate::trust::solver_switches(
            self.solver,
            self.max_iterations,
            &switched,
            self.steps.len().saturating_sub(1),
        ) {
            s.push_str(&format!("{line}\n"));
        }
        if self.frames_written > 0 {
            s.push_str(&format!(
                "open {} in ParaView\n",
                out.join("series.pvd").display()
            ));
        }
        s
    }

    /// What to say of a run of the linear material past small strains
    /// ([`crate::run::Compression::LINEAR_STRAIN`]), as `run` says it of its reference: a
    /// tester's bar at α = 5 grew 209 % in volume under `simulate` without a word.
    pub fn linear_warning(&self) -> Option<String> {
        crate::trust::past_small_strains(
            "the simulation",
            self.linear_strain?,
            "these frames are not the body's motion",
        )
    }
}

/// The summary and the final full displacement of a finished simulation.
#[derive(Debug)]
pub struct SimulationResult {
    pub summary: Summary,
    /// Full displacement (3 per vertex) after the last step.
    pub final_displacement: Vec<f64>,
}

/// One method, stepping: full space, or a reduced method's trained model through latent-sim's
/// runtime (the API any other program steps an exported model with).
#[allow(clippy::large_enum_variant)]
pub enum Runner {
    Full(Simulator),
    Reduced(ReducedRuntime),
}

impl std::fmt::Debug for Runner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Runner::Full(_) => "Runner::Full",
            Runner::Reduced(_) => "Runner::Reduced",
        })
    }
}

/// Timing and iterations of one step.
#[derive(Debug, Clone, Copy)]
pub struct StepInfo {
    pub seconds: f64,
    pub iterations: usize,
    /// Where a reduced step's time went (zero for full space).
    pub parts: StepParts,
    /// Whether a reduced step started again from the last state, not solvable from its
    /// extrapolated start (`ReducedStepReport::restarted`).
    pub restarted: bool,
}

/// Seconds of one reduced step spent in each part of the solve.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StepParts {
    /// Network forward pass and partial decode Uq.
    pub decode: f64,
    /// Elastic energy and reduced gradient over the (cubature) elements.
    pub elastic: f64,
    /// Decoder vector–Jacobian products.
    pub vjp: f64,
    /// Building and factorising the preconditioner.
    pub precond: f64,
}

impl StepParts {
    fn of(r: &ReducedStepReport) -> Self {
        Self {
            decode: r.decode_seconds,
            elastic: r.elastic_seconds,
            vjp: r.vjp_seconds,
            precond: r.precond_seconds,
        }
    }
}

impl Runner {
    /// Builds the runner of `method` on `model` (forces already in place; `material` is the
    /// one it was built with). A reduced method's model is built from the cached stages with
    /// every basis row ([`crate::export::reduced_model`]) and its forces are added to the
    /// runtime in order, so that it steps as the same model loaded from a file would.
    pub fn new(
        pipeline: &mut Pipeline<'_>,
        method: Method,
        model: FullSpaceModel,
        material: &MaterialConfig,
        time: TimeConfig,
        solver: SolverConfig,
        progress: Progress<'_>,
    ) -> Result<Self> {
        if method.is_full() {
            return Ok(Runner::Full(Simulator::new(model, time, solver)?));
        }
        let reduced = crate::export::reduced_model(
            pipeline,
            method,
            &model,
            material,
            &time,
            solver,
            Rows::All,
            progress,
        )?;
        let mut runtime = reduced.simulator()?;
        for f in model.forces {
            runtime.add_force(f)?;
        }
        Ok(Runner::Reduced(runtime))
    }

    /// [`Runner::new`] on the model, time and solver [`setup`] gives for `opts`.
    pub fn from_options(
        pipeline: &mut Pipeline<'_>,
        opts: &SimulateOptions,
        progress: Progress<'_>,
    ) -> Result<Self> {
        let scene = pipeline.scene;
        let (model, time, solver) = setup(pipeline, opts)?;
        Self::new(
            pipeline,
            opts.method,
            model,
            &scene.material,
            time,
            solver,
            progress,
        )
    }

    pub fn step(&mut self) -> Result<StepInfo> {
        Ok(match self {
            Runner::Full(s) => {
                let r = s.step()?;
                StepInfo {
                    seconds: r.wall_seconds,
                    iterations: r.iterations,
                    parts: StepParts::default(),
                    restarted: false,
                }
            }
            Runner::Reduced(s) => {
                let r = s.step_report()?;
                StepInfo {
                    seconds: r.wall_seconds,
                    iterations: r.iterations,
                    parts: StepParts::of(&r),
                    restarted: r.restarted,
                }
            }
        })
    }

    /// Puts a reduced runner at step `step` in the states its subspace gives to the PCA
    /// coefficients `q_now` and `q_before` (of steps `step` and `step − 1`), nothing of its
    /// earlier solves kept (see [`latent_sim::ReducedSimulator::set_state`]).
    ///
    /// # Errors
    /// For a full-space runner, which has no coefficients.
    pub fn set_state(&mut self, step: usize, q_now: &[f64], q_before: &[f64]) -> Result<()> {
        match self {
            Runner::Full(_) => anyhow::bail!("a full-space runner has no subspace state"),
            Runner::Reduced(s) => s.set_state(step, q_now, q_before)?,
        }
        Ok(())
    }

    /// The PCA coefficients of a reduced runner's state (None in full space).
    pub fn coefficients(&self) -> Option<&[f64]> {
        match self {
            Runner::Full(_) => None,
            Runner::Reduced(s) => Some(s.coefficients()),
        }
    }

    /// The full displacement of the current state (reconstructed for reduced methods).
    pub fn displacement(&self) -> Vec<f64> {
        match self {
            Runner::Full(s) => s.state.u.clone(),
            Runner::Reduced(s) => {
                let mut u = vec![0.0; s.simulator().model().num_full()];
                // The runner's model holds every row, so this cannot fail.
                if let Err(e) = s.displacement_into(&mut u) {
                    tracing::error!("{e}");
                }
                u
            }
        }
    }

    pub fn time(&self) -> f64 {
        match self {
            Runner::Full(s) => s.state.time,
            Runner::Reduced(s) => s.time(),
        }
    }

    pub fn model(&self) -> &FullSpaceModel {
        match self {
            Runner::Full(s) => &s.model,
            Runner::Reduced(s) => s.simulator().model(),
        }
    }

    /// Total energy (elastic + kinetic + external potential) of the current state; for reduced
    /// methods the elastic part is over their element set (the energy their solver sees).
    pub fn total_energy(&mut self) -> f64 {
        match self {
            Runner::Full(s) => s.report().total_energy,
            Runner::Reduced(s) => s.energy().total,
        }
    }

    /// Simulated dimension.
    pub fn dim(&self) -> usize {
        match self {
            Runner::Full(s) => s.model.dofs.num_free(),
            Runner::Reduced(s) => s.simulator().latent_dim(),
        }
    }

    /// Elements the elastic energy is evaluated on.
    pub fn elements(&self) -> usize {
        match self {
            Runner::Full(s) => s.model.elements.len(),
            Runner::Reduced(s) => s.simulator().space().elements.len(),
        }
    }
}

/// The model, time and solver settings for `opts.trajectory`.
pub fn setup(
    pipeline: &Pipeline<'_>,
    opts: &SimulateOptions,
) -> Result<(FullSpaceModel, TimeConfig, SolverConfig)> {
    let scene = pipeline.scene;
    let (model, frames) = match opts.trajectory {
        Trajectory::Scene => (pipeline.model.clone(), scene.time.frames),
        Trajectory::Test(i) => (pipeline.test_model(i)?, scene.test().frames_per_schedule),
    };
    let time = TimeConfig {
        frames: opts.frames.unwrap_or(frames),
        ..scene.time.clone()
    };
    let mut solver = solver_for(scene, opts.method);
    if let Some(m) = opts.solver {
        if let Some(forced) = opts.method.forced_full_solver()
            && forced != m
        {
            anyhow::bail!(
                "`--solver {}` contradicts `--method {}`, which names its solver: use `--method \
                 full --solver {0}` or `--method full-{0}`",
                m.name(),
                opts.method.name(),
            );
        }
        solver.method = m;
    }
    Ok((model, time, solver))
}

/// The solver settings of `method` on `scene`: `[solver]` for the full-space methods,
/// `[reduced]` for the reduced ones.
pub fn solver_for(scene: &Scene, method: Method) -> SolverConfig {
    let mut solver = scene.solver.clone();
    // Reduced methods (and full-lbfgs) get at least REDUCED_MIN_ITERATIONS iterations: quasi-Newton
    // needs more, cheaper iterations than Newton.
    match method {
        Method::Full => {}
        Method::FullNewton => solver.method = SolverMethod::Newton,
        Method::FullLbfgs => {
            solver.method = SolverMethod::Lbfgs;
            solver.max_iterations = solver.max_iterations.max(REDUCED_MIN_ITERATIONS);
        }
        Method::Pca | Method::PcaCubature | Method::Neural | Method::NeuralCubature => {
            solver = scene.reduced.solver(&scene.solver);
        }
    }
    solver
}

/// Runs one method with `opts`; `progress(done, total)` is called after every step.
///
/// A failing step (divergence, no convergence, an inverted element the material cannot handle)
/// ends the run with an error naming the step; frames before it stay on disk with their series
/// file and summary, and the failed state is never written as a frame.
pub fn simulate(
    pipeline: &mut Pipeline<'_>,
    opts: &SimulateOptions,
    stage_progress: Progress<'_>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SimulationResult> {
    let scene = pipeline.scene;
    let (model, time, solver) = setup(pipeline, opts)?;
    let (frames, step) = (time.frames, time.step);
    let mut runner = Runner::new(
        pipeline,
        opts.method,
        model,
        &scene.material,
        time,
        solver.clone(),
        stage_progress,
    )?;
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("cannot create output folder {}", opts.out.display()))?;
    let mut writer = FrameWriter::new(&opts.out)?;
    if opts.every > 0 {
        writer.write(&runner.model().mesh, 0, 0.0, &runner.displacement())?;
    }
    let start = Instant::now();
    let mut steps = Vec::new();
    let mut reduced_steps = Vec::new();
    let mut reduced_max_displacement = Vec::new();
    let mut times = Vec::new();
    let mut failure = None;
    let mut done = 0;
    let linear = runner.model().material.is_linear();
    let mut linear_strain: Option<(f64, f64)> = None;
    if let Runner::Full(s) = &mut runner {
        steps.push(s.report());
    }
    for k in 1..=frames {
        let step = match &mut runner {
            Runner::Full(s) => s.step().map_err(anyhow::Error::from).map(|r| {
                times.push(r.wall_seconds);
                steps.push(r);
            }),
            Runner::Reduced(s) => s.step_report().map_err(anyhow::Error::from).map(|r| {
                times.push(r.wall_seconds);
                reduced_steps.push(r);
            }),
        };
        if step.is_ok() && matches!(runner, Runner::Reduced(_)) {
            reduced_max_displacement.push(fem_core::integrator::max_displacement(
                &runner.displacement(),
            ));
        }
        if let Err(e) = step {
            // The last good state goes to disk (unless it already did); the failed one never.
            if opts.every > 0 && done % opts.every != 0 && done > 0 {
                writer.write(
                    &runner.model().mesh,
                    done,
                    runner.time(),
                    &runner.displacement(),
                )?;
            }
            failure = Some(e);
            break;
        }
        done = k;
        if linear {
            let strain = crate::run::Compression::mean_left_out_strain(
                runner.model(),
                &runner.displacement(),
            );
            if linear_strain.is_none_or(|(s, _)| strain > s) {
                linear_strain = Some((strain, runner.time()));
            }
        }
        if opts.every > 0 && (k % opts.every == 0 || k == frames) {
            writer.write(
                &runner.model().mesh,
                k,
                runner.time(),
                &runner.displacement(),
            )?;
        }
        progress(k, frames);
    }
    let total_seconds = start.elapsed().as_secs_f64();
    if opts.every > 0 {
        writer.finish()?;
    }
    let model = runner.model();
    let summary = Summary {
        scene: scene.name.clone(),
        method: opts.method,
        solver: solver.method,
        max_iterations: solver.max_iterations,
        vertices: model.mesh.num_vertices(),
        tets: model.mesh.num_tets(),
        free_dofs: model.dofs.num_free(),
        dim: runner.dim(),
        frames_written: writer.frames_written(),
        total_seconds,
        mean_step_ms: times.iter().sum::<f64>() / times.len().max(1) as f64 * 1e3,
        median_step_ms: median(&times) * 1e3,
        steps,
        reduced_steps,
        reduced_max_displacement,
        linear_strain,
    };
    if let Some(line) = summary.linear_warning() {
        crate::pipeline::warn_once(&format!("{}: {line}", scene.source));
    }
    write_json(&opts.out.join("summary.json"), &summary)?;
    if let Some(e) = failure {
        anyhow::bail!(
            "{}: simulation with method {} stopped: {e}; frames up to step {done} (the last good \
             state) are in {}; {}",
            scene.source,
            opts.method.name(),
            opts.out.display(),
            stopped_remedy(
                model,
                scene.material.youngs_modulus,
                step,
                matches!(opts.trajectory, Trajectory::Scene)
            )
        );
    }
    Ok(SimulationResult {
        summary,
        final_displacement: runner.displacement(),
    })
}

/// What to change where a step of the scene could not be solved: the scene's loads that
/// strain the body past its own size first (a point load at least the force E·L² that does, L
/// the bounding-box diagonal; a spring whose target lies at least L away), then the step. An
/// advice follower's point load at the scene's limit, 1e6 times E·L², failed its first step
/// with no word of what to change (stop 77). The loads are named as the scene's `[[force]]`s
/// only where they are (`scene_forces`; a test trajectory's are its drag's).
fn stopped_remedy(
    model: &FullSpaceModel,
    youngs_modulus: f64,
    step: f64,
    scene_forces: bool,
) -> String {
    use fem_core::forces::ForceKind;
    let rest = &model.mesh.vertices;
    let body = latent_sim::body_force(rest, youngs_modulus);
    let size = (body / youngs_modulus).sqrt();
    let norm = |k: &[f64; 4]| (k[1] * k[1] + k[2] * k[2] + k[3] * k[3]).sqrt();
    let mut loads: Vec<String> = Vec::new();
    let forces = if scene_forces { &model.forces[..] } else { &[] };
    for (i, f) in forces.iter().enumerate() {
        let largest = f.keyframes.iter().map(norm).fold(0.0, f64::max);
        match f.kind {
            ForceKind::Point if largest >= body => loads.push(format!(
                "`force[{i}]`'s point load reaches {largest:.3e} N, {:.1e} times the {body:.3e} N \
                 (E times the squared bounding-box diagonal) that strains the body by its own \
                 size",
                largest / body
            )),
            ForceKind::Spring if largest >= size => loads.push(format!(
                "`force[{i}]`'s spring pulls its target {largest:.3e} m away, {:.1} times the \
                 body's {size:.3e} m bounding-box diagonal",
                largest / size
            )),
            _ => {}
        }
    }
    if loads.is_empty() {
        format!(
            "a smaller `[time] step` (now {step} s) makes each step's solve easier, and lighter \
             loads or a stiffer material (`[material] youngs_modulus`) a gentler motion"
        )
    } else {
        format!(
            "{}: lighter `keyframes` keep the motion within what the material models, and a \
             smaller `[time] step` (now {step} s) makes each step's solve easier",
            loads.join("; ")
        )
    }
}

/// Median of a list: its middle value, or the mean of the middle two when it has an even
/// count (0 when empty).
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Writes pretty JSON atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    crate::output::write_file(path, text.as_bytes())
}
