//! `cargo xtask …`: the pipeline's command line. Parses flags, shows progress, dispatches.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use pipeline::bench::{BenchOptions, bench};
use pipeline::pipeline::{Pipeline, StageOutcome};
use pipeline::run::{RunOptions, markdown, run};
use pipeline::scene::Scene;
use pipeline::shard::Shard;
use pipeline::simulate::{Method, SimulateOptions, Trajectory, simulate};
use pipeline::stress::{Condition, Outcome, stress};

mod view;

#[derive(Parser)]
#[command(name = "cargo xtask", about = "Latent-space dynamics pipeline")]
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
    /// Artifact cache folder (default: out/SCENE/cache, SCENE the scene's name).
    #[arg(long)]
    cache: Option<PathBuf>,
}

#[derive(Subcommand)]
enum Command {
    /// The main job: every stage (cached), then each method on the held-out test trajectory,
    /// compared with the full-space reference.
    Run {
        #[command(flatten)]
        common: Common,
        /// Output folder (default: out/SCENE).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write every K-th frame of each method (0: none).
        #[arg(long, default_value_t = 5)]
        every: usize,
        /// Methods to compare.
        #[arg(long, value_enum, value_delimiter = ',', num_args = 1.., default_values_t = [MethodArg::Full, MethodArg::FullNewton, MethodArg::FullLbfgs, MethodArg::Pca, MethodArg::PcaCubature, MethodArg::Neural, MethodArg::NeuralCubature])]
        methods: Vec<MethodArg>,
        /// Held-out test trajectory to simulate.
        #[arg(long, default_value_t = 0)]
        trajectory: usize,
    },
    /// Simulate a scene with one method and write frames ParaView opens.
    Simulate {
        #[command(flatten)]
        common: Common,
        #[arg(long, value_enum, default_value_t = MethodArg::Full)]
        method: MethodArg,
        /// Drive the simulation with held-out test trajectory N instead of the scene's forces.
        #[arg(long)]
        test: Option<usize>,
        /// Number of frames (overrides the scene).
        #[arg(long)]
        frames: Option<usize>,
        /// Write every K-th frame (and the last); 0 writes only the summary.
        #[arg(long, default_value_t = 1)]
        every: usize,
        /// Overrides the scene's `[solver] method`.
        #[arg(long, value_enum)]
        solver: Option<SolverArg>,
        /// Output folder (default: out/SCENE/METHOD).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The mesh suite: a minimal scene (mesh, material, bottom pinned, gravity, time step) on
    /// every .mesh file of a folder, each run from an empty cache; one table of every method's
    /// error and speed-up and the pipeline's time.
    Suite {
        /// Folder of MEDIT meshes (default: the shared/ folder's meshes beside the repository).
        #[arg(long)]
        meshes: Option<PathBuf>,
        /// Leave out meshes with more vertices than this.
        #[arg(long)]
        max_vertices: Option<usize>,
        /// Young's modulus of every scene, Pa.
        #[arg(long, default_value_t = 1.0e5)]
        youngs_modulus: f64,
        /// Output folder (default: out/suite).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Stage `snapshots`: simulate the training schedules.
    Snapshots {
        #[command(flatten)]
        common: Common,
        /// Simulate only shard I of N (every N-th schedule from I), for array jobs. Without it,
        /// an array job's variables give the shard: SLURM_ARRAY_TASK_ID and
        /// SLURM_ARRAY_TASK_COUNT, or a Kubernetes Indexed Job's JOB_COMPLETION_INDEX with
        /// LATENT_SHARD_COUNT (docs/cluster.md).
        #[arg(long, value_name = "I/N")]
        shard: Option<String>,
        /// Combine shards 0..N into the snapshots artifact.
        #[arg(long, value_name = "N")]
        merge: Option<usize>,
    },
    /// Stage `pca`: the mass-orthonormal basis (runs `snapshots` first if needed).
    Pca {
        #[command(flatten)]
        common: Common,
    },
    /// Stage `cubature`: optimized cubature for the PCA subspace (runs earlier stages if needed).
    Cubature {
        #[command(flatten)]
        common: Common,
    },
    /// Stage `train`: the autoencoder on the PCA coefficients (runs earlier stages if needed);
    /// writes the loss curve to out/SCENE/train/.
    Train {
        #[command(flatten)]
        common: Common,
    },
    /// Time every method at several sizes on the held-out trajectory (warm-up, repeated runs)
    /// and write bench.json, bench.md and bench.svg (error against ms/step, Pareto front).
    Bench {
        #[command(flatten)]
        common: Common,
        /// Output folder (default: out/SCENE/bench).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Timed runs of the trajectory per variant (after one warm-up run).
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        /// PCA dimensions (default: the latent dimensions, half and all of the scene's basis).
        #[arg(long, value_delimiter = ',')]
        pca_dims: Vec<usize>,
        /// Latent dimensions (default: half, once and twice the scene's).
        #[arg(long, value_delimiter = ',')]
        latent_dims: Vec<usize>,
        /// Cubature tolerances (default: 0.1, 0.05, 0.02).
        #[arg(long, value_delimiter = ',')]
        tolerances: Vec<f64>,
        /// Complement-direction counts for the neural methods at the scene's latent dimension
        /// (default: none; see `[reduced] complement_directions`).
        #[arg(long, value_delimiter = ',')]
        complement_dims: Vec<usize>,
        /// Held-out test trajectory to simulate.
        #[arg(long, default_value_t = 0)]
        trajectory: usize,
    },
    /// Every method under extreme conditions (time steps, stiffness, Poisson ratio, forces beyond
    /// training, a long free run): a table of ok / error / diverged with the error measured.
    Stress {
        #[command(flatten)]
        common: Common,
        /// Output folder for stress.json and stress.md (default: out/SCENE/stress).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Methods to stress.
        #[arg(long, value_enum, value_delimiter = ',', num_args = 1.., default_values_t = [MethodArg::Full, MethodArg::FullNewton, MethodArg::FullLbfgs, MethodArg::Pca, MethodArg::PcaCubature, MethodArg::Neural, MethodArg::NeuralCubature])]
        methods: Vec<MethodArg>,
        /// Steps of the free-run condition (test trajectory, then no external force).
        #[arg(long, default_value_t = 2000)]
        free_steps: usize,
        /// Held-out test trajectory to simulate.
        #[arg(long, default_value_t = 0)]
        trajectory: usize,
    },
    /// Write one reduced method's trained model as a self-contained file (running the stages it
    /// needs, cached as always), for latent-sim's runtime: `ReducedModel::load(path)?.simulator()`.
    Export {
        #[command(flatten)]
        common: Common,
        /// The reduced method whose model to write.
        #[arg(long, value_enum, default_value_t = MethodArg::NeuralCubature)]
        method: MethodArg,
        /// Model file (default: out/<scene name>/<method>.ldm).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Keep the basis rows of every vertex (the whole displacement can be read back, interior
        /// vertices grabbed), not only those of the surface and the evaluated elements.
        #[arg(long)]
        all_rows: bool,
    },
    /// Drag the mesh in a browser: a loopback server stepping the scene's reduced methods and
    /// full space in real time (running the stages it needs, cached), or a model file's method.
    View(view::ViewArgs),
    /// Run the stages in order, skipping cached ones.
    Pipeline {
        #[command(flatten)]
        common: Common,
        /// Last stage to run.
        #[arg(long, value_enum, default_value_t = StageArg::Pca)]
        until: StageArg,
    },
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
        .init();
    if let Err(e) = dispatch(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn load_scene(path: Option<&PathBuf>) -> Result<Scene> {
    match path {
        Some(p) => Scene::from_file(p),
        None => Ok(Scene::builtin()),
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

fn print_stage(o: &StageOutcome) {
    if o.cached {
        println!("{:>10}: unchanged, skipped ({})", o.stage, o.path.display());
    } else {
        println!(
            "{:>10}: computed in {:.1} s → {}",
            o.stage,
            o.seconds,
            o.path.display()
        );
    }
    println!("{:>10}  {}", "", o.summary);
}

/// A pipeline for the scene, printing a line per stage.
fn pipeline<'a>(scene: &'a Scene, cache: Option<&PathBuf>, root: &Path) -> Result<Pipeline<'a>> {
    let cache = cache
        .cloned()
        .unwrap_or_else(|| root.join("out").join(&scene.name).join("cache"));
    let mut p = Pipeline::new(scene, &cache)?;
    p.on_stage = Box::new(print_stage);
    Ok(p)
}

fn dispatch(cli: Cli) -> Result<()> {
    let root = pipeline::project_root();
    // One bar for long stages (schedules or frames); hidden until a stage reports progress.
    let stage_bar = bar(0, "stage");
    stage_bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    let stage_progress = |done: usize, total: usize| {
        if stage_bar.is_hidden() {
            stage_bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
        }
        stage_bar.set_length(total as u64);
        stage_bar.set_position(done as u64);
        if done == total {
            stage_bar.finish_and_clear();
            stage_bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
            stage_bar.reset();
        }
    };
    match cli.command {
        Command::Run {
            common,
            out,
            every,
            methods,
            trajectory,
        } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            p.pca(&stage_progress)?;
            let out = out.unwrap_or_else(|| root.join("out").join(&scene.name));
            let opts = RunOptions {
                out: out.clone(),
                every,
                methods: methods.into_iter().map(Method::from).collect(),
                trajectory,
            };
            let method_bar = bar(0, "");
            let rows = run(&mut p, &opts, &stage_progress, &mut |m, done, total| {
                method_bar.set_message(m.to_string());
                method_bar.set_length(total as u64);
                method_bar.set_position(done as u64);
            })?;
            method_bar.finish_and_clear();
            println!(
                "\n{} — held-out test trajectory {trajectory}, {} frames\n",
                scene.name,
                scene.test().frames_per_schedule
            );
            print!("{}", markdown(&rows));
            let reduced: Vec<_> = rows
                .iter()
                .filter(|r| !r.method.starts_with("full"))
                .collect();
            if !reduced.is_empty() {
                println!("\nwhere a reduced step's time goes (mean ms per step):\n");
                println!(
                    "| method | decode | elastic | VJP | preconditioner or Newton matrix |\n|---|---:|---:|---:|---:|"
                );
                for r in reduced {
                    println!(
                        "| {} | {:.3} | {:.3} | {:.3} | {:.3} |",
                        r.method, r.decode_ms, r.elastic_ms, r.vjp_ms, r.precond_ms
                    );
                }
            }
            let warnings = pipeline::trust::warnings(&rows);
            if !warnings.is_empty() {
                println!("\nnot to be trusted:");
                for w in &warnings {
                    println!("- {w}");
                }
            }
            println!(
                "\nreport: {} (also report.md, report.svg; errors by frame: errors.csv, errors.svg); frames: {}/<method>/series.pvd",
                out.join("report.json").display(),
                out.display()
            );
            if let Some(m) = pipeline::export::run_method(&opts.methods) {
                println!("model: {}", pipeline::export::model_path(&out, m).display());
            }
            Ok(())
        }
        Command::Export {
            common,
            method,
            out,
            all_rows,
        } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            let method = Method::from(method);
            let path = out.unwrap_or_else(|| {
                pipeline::export::model_path(&root.join("out").join(&scene.name), method)
            });
            let rows = if all_rows {
                latent_sim::model::Rows::All
            } else {
                latent_sim::model::Rows::Used
            };
            let model = pipeline::export::scene_model(&mut p, method, rows, &stage_progress)?;
            model.save(&path)?;
            let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
            println!(
                "{}: {} model, {} vertices ({} with basis rows), {} tets, k = {}, latent dimension {}, {} elements evaluated → {} ({:.2} MB)",
                scene.name,
                method.name(),
                model.mesh.num_vertices(),
                model.space.vertices.len(),
                model.mesh.num_tets(),
                model.space.k,
                model.latent_dim(),
                model
                    .cubature
                    .as_ref()
                    .map_or(model.mesh.num_tets(), |c| c.len()),
                path.display(),
                bytes as f64 / 1e6
            );
            Ok(())
        }
        Command::Suite {
            meshes,
            max_vertices,
            youngs_modulus,
            out,
        } => {
            let dir = meshes.unwrap_or_else(|| root.join("../shared/meshes"));
            let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
                .map_err(|e| anyhow::anyhow!("cannot read mesh folder {}: {e}", dir.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "mesh"))
                .collect();
            files.sort();
            if let Some(max) = max_vertices {
                let mut kept = Vec::new();
                for f in files {
                    let (m, _) = fem_core::io::read_mesh(&f)?;
                    if m.num_vertices() <= max {
                        kept.push(f);
                    }
                }
                files = kept;
            }
            if files.is_empty() {
                bail!("no .mesh files to run in {}", dir.display());
            }
            let out = out.unwrap_or_else(|| root.join("out").join("suite"));
            let rows = pipeline::suite::run_suite(
                &files,
                youngs_modulus,
                &out,
                &stage_progress,
                &mut |name| println!("{name}"),
            )?;
            let table = pipeline::suite::markdown(&rows);
            print!("\n{table}");
            std::fs::create_dir_all(&out)?;
            fem_core::io::write_atomic(&out.join("suite.md"), table.as_bytes())?;
            fem_core::io::write_atomic(
                &out.join("suite.json"),
                serde_json::to_string_pretty(&rows)?.as_bytes(),
            )?;
            println!("table: {}", out.join("suite.md").display());
            Ok(())
        }
        Command::Bench {
            common,
            out,
            repeats,
            pca_dims,
            latent_dims,
            tolerances,
            complement_dims,
            trajectory,
        } => {
            let scene = load_scene(common.scene.as_ref())?;
            let cache = common
                .cache
                .unwrap_or_else(|| root.join("out").join(&scene.name).join("cache"));
            let out = out.unwrap_or_else(|| root.join("out").join(&scene.name).join("bench"));
            let opts = BenchOptions {
                out: out.clone(),
                cache,
                trajectory,
                repeats,
                pca_dims,
                latent_dims,
                tolerances,
                complement_dims,
            };
            let method_bar = bar(0, "");
            let rows = bench(
                &scene,
                &opts,
                &mut print_stage,
                &mut |label| method_bar.println(format!("     bench: {label}")),
                &stage_progress,
                &mut |m, done, total| {
                    method_bar.set_message(m.to_string());
                    method_bar.set_length(total as u64);
                    method_bar.set_position(done as u64);
                },
            )?;
            method_bar.finish_and_clear();
            println!(
                "\n{} — held-out test trajectory {trajectory}, {repeats} timed runs per variant\n",
                scene.name
            );
            print!("{}", pipeline::bench::markdown(&rows));
            println!(
                "\nbench: {} (also bench.md, bench.svg)",
                out.join("bench.json").display()
            );
            Ok(())
        }
        Command::Stress {
            common,
            out,
            methods,
            free_steps,
            trajectory,
        } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            let methods: Vec<Method> = methods.into_iter().map(Method::from).collect();
            // Every stage first, so the table's progress is not interleaved with training.
            for &m in &methods {
                match m {
                    Method::PcaCubature => drop(p.cubature(&stage_progress)?),
                    Method::Neural => drop(p.train(&stage_progress)?),
                    Method::NeuralCubature => drop(p.cubature_neural(&stage_progress)?),
                    _ => drop(p.pca(&stage_progress)?),
                }
            }
            let out = out.unwrap_or_else(|| root.join("out").join(&scene.name).join("stress"));
            let conditions = Condition::defaults(free_steps);
            let results = stress(
                &mut p,
                &methods,
                &conditions,
                trajectory,
                &stage_progress,
                &mut |r| {
                    let detail = match &r.outcome {
                        Outcome::Error { message, .. } => format!(": {message}"),
                        Outcome::Diverged { reason, .. } => format!(": {reason}"),
                        Outcome::Ok { .. } => String::new(),
                    };
                    println!(
                        "{:>16} | {:<20} | {}{detail}",
                        r.method,
                        r.condition,
                        r.outcome.cell()
                    );
                },
            )?;
            pipeline::stress::write(&out, &results)?;
            println!("\n{}", pipeline::stress::markdown(&results));
            println!(
                "stress: {} (also stress.md)",
                out.join("stress.json").display()
            );
            Ok(())
        }
        Command::Simulate {
            common,
            method,
            test,
            frames,
            every,
            solver,
            out,
        } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            let method = Method::from(method);
            let opts = SimulateOptions {
                method,
                trajectory: test.map(Trajectory::Test).unwrap_or(Trajectory::Scene),
                out: out.unwrap_or_else(|| root.join("out").join(&scene.name).join(method.name())),
                frames,
                every,
                solver: solver.map(|s| match s {
                    SolverArg::Newton => fem_core::optim::SolverMethod::Newton,
                    SolverArg::Lbfgs => fem_core::optim::SolverMethod::Lbfgs,
                }),
            };
            let frames_bar = bar(0, method.name());
            let result = simulate(&mut p, &opts, &stage_progress, &mut |done, total| {
                frames_bar.set_length(total as u64);
                frames_bar.set_position(done as u64);
            });
            frames_bar.finish_and_clear();
            let s = result?.summary;
            println!(
                "{}: {} steps of {} (dim {}; {} vertices, {} tets) in {:.2} s, median {:.3} ms/step, {} frames written to {}",
                s.scene,
                s.steps.len().saturating_sub(1).max(s.reduced_steps.len()),
                s.method.name(),
                s.dim,
                s.vertices,
                s.tets,
                s.total_seconds,
                s.median_step_ms,
                s.frames_written,
                opts.out.display()
            );
            if s.frames_written > 0 {
                println!("open {} in ParaView", opts.out.join("series.pvd").display());
            }
            Ok(())
        }
        Command::Snapshots {
            common,
            shard,
            merge,
        } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
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
                    p.snapshot_shard(s.index, s.count, &stage_progress)?;
                }
                (None, Some(n)) => {
                    let set = p.merge_shards(n)?;
                    println!("merged {n} shards: {} frames", set.num_frames());
                }
                (None, None) => {
                    let set = p.snapshots(&stage_progress)?;
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
        Command::Pca { common } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            let fit = p.pca(&stage_progress)?;
            print_pca(&fit);
            let dir = root.join("out").join(&scene.name).join("pca");
            write_pca_curves(&dir, &fit)?;
            println!("spectrum and error curve: {}", dir.display());
            Ok(())
        }
        Command::Cubature { common } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            let c = p.cubature(&stage_progress)?;
            println!(
                "{} of {} elements, relative force error {:.3e} on the training poses ({}met), {:.3e} on the held-out trajectory, fitted in {:.2} s",
                c.rule.len(),
                p.model.elements.len(),
                c.rule.training_error,
                if c.rule.tolerance_met {
                    ""
                } else {
                    "tolerance not "
                },
                c.held_out_error,
                c.fit_seconds
            );
            let dir = root.join("out").join(&scene.name).join("cubature");
            c.write_error_curve(&dir)?;
            println!("error curve: {}", dir.join("error.svg").display());
            Ok(())
        }
        Command::Train { common } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            let trained = p.train(&stage_progress)?;
            let dir = root.join("out").join(&scene.name).join("train");
            trained.write_loss_curve(&dir)?;
            print_training(&trained);
            println!("loss curve: {}", dir.join("loss.svg").display());
            Ok(())
        }
        Command::View(args) => view::view(args, &stage_progress),
        Command::Pipeline { common, until } => {
            let scene = load_scene(common.scene.as_ref())?;
            let mut p = pipeline(&scene, common.cache.as_ref(), &root)?;
            match until {
                StageArg::Snapshots => {
                    p.snapshots(&stage_progress)?;
                }
                StageArg::Pca => {
                    p.pca(&stage_progress)?;
                }
                StageArg::Cubature => {
                    p.cubature(&stage_progress)?;
                }
                StageArg::Train => {
                    p.train(&stage_progress)?;
                }
            }
            Ok(())
        }
    }
}

fn print_pca(fit: &pca::PcaFit) {
    let s = fit.basis.singular_values();
    let shown: Vec<String> = s.iter().take(12).map(|v| format!("{v:.3e}")).collect();
    println!("singular values: {} …", shown.join(" "));
    println!(
        "k = {} ({:?}; tolerance met: {}), explained energy {:.6}",
        fit.chosen_k(),
        fit.rule,
        fit.tolerance_met,
        fit.basis.explained_energy(fit.chosen_k())
    );
}

/// `spectrum.csv` (index, singular value) and, for the vertex-error rule, `vertex_error.csv`
/// (k, maximum vertex error over the snapshots).
fn write_pca_curves(dir: &Path, fit: &pca::PcaFit) -> Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut csv = String::from("index,singular_value\n");
    for (i, v) in fit.basis.singular_values().iter().enumerate() {
        csv.push_str(&format!("{},{v}\n", i + 1));
    }
    fem_core::io::write_atomic(&dir.join("spectrum.csv"), csv.as_bytes())?;
    if !fit.max_vertex_error_per_k.is_empty() {
        let mut csv = String::from("k,max_vertex_error\n");
        for (i, e) in fit.max_vertex_error_per_k.iter().enumerate() {
            csv.push_str(&format!("{},{e}\n", i + 1));
        }
        fem_core::io::write_atomic(&dir.join("vertex_error.csv"), csv.as_bytes())?;
    }
    Ok(())
}

fn print_training(t: &pipeline::pipeline::TrainedModel) {
    println!(
        "autoencoder {k} → {d} → {k}: best epoch {} of {}{}, {:.1} s",
        t.best_epoch,
        t.history.len(),
        if t.stopped_early {
            " (stopped early)"
        } else {
            ""
        },
        t.train_seconds,
        k = t.pca_k,
        d = t.latent_dim
    );
    println!(
        "max vertex error over the snapshots: autoencoder (d = {}) {:.3e}, PCA with {} columns {:.3e}; PCA needs {} columns to match",
        t.latent_dim,
        t.max_vertex_error,
        t.latent_dim,
        t.pca_error_at_latent_dim,
        t.pca_k_matching
            .map(|k| k.to_string())
            .unwrap_or_else(|| format!("more than {}", t.pca_k))
    );
}

fn parse_shard(s: &str) -> Result<Shard> {
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| anyhow::anyhow!("--shard takes I/N, e.g. 0/4; got {s}"))?;
    Ok(Shard::new(i.trim().parse()?, n.trim().parse()?)?)
}
