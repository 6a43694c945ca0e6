//! `cargo xtask …`: the pipeline's command line. Parses flags, shows progress, dispatches.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use xtask::scene::Scene;
use xtask::simulate::{Method, SimulateOptions, simulate};

#[derive(Parser)]
#[command(name = "cargo xtask", about = "Latent-space dynamics pipeline")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the main job on a scene (the built-in default when none is given).
    Run {
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Output folder (default: out/<scene name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write every K-th frame.
        #[arg(long, default_value_t = 1)]
        every: usize,
    },
    /// Simulate a scene and write frames ParaView opens.
    Simulate {
        #[arg(long)]
        scene: Option<PathBuf>,
        #[arg(long, value_enum, default_value_t = MethodArg::Full)]
        method: MethodArg,
        /// Number of frames (overrides the scene's `[time] frames`).
        #[arg(long)]
        frames: Option<usize>,
        /// Write every K-th frame (and the last); 0 writes only the summary.
        #[arg(long, default_value_t = 1)]
        every: usize,
        /// Overrides the scene's `[solver] method`.
        #[arg(long, value_enum)]
        solver: Option<SolverArg>,
        /// Output folder (default: out/<scene name>/<method>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Full,
}

#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    Newton,
    Lbfgs,
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

fn progress_bar(len: u64, what: &str) -> ProgressBar {
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

fn run_simulation(scene: &Scene, opts: &SimulateOptions) -> Result<()> {
    let bar = progress_bar(
        opts.frames.unwrap_or(scene.time.frames) as u64,
        opts.method.name(),
    );
    let result = simulate(scene, opts, &mut |done, _| bar.set_position(done as u64));
    bar.finish_and_clear();
    let result = result?;
    let s = &result.summary;
    println!(
        "{}: {} frames of {} ({} vertices, {} tets, {} free DOF) in {:.2} s, median {:.2} ms/step, {} frames written to {}",
        s.scene,
        s.steps.len() - 1,
        s.method.name(),
        s.vertices,
        s.tets,
        s.free_dofs,
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

fn dispatch(cli: Cli) -> Result<()> {
    let root = xtask::project_root();
    match cli.command {
        Command::Run { scene, out, every } => {
            let scene = load_scene(scene.as_ref())?;
            let out = out.unwrap_or_else(|| root.join("out").join(&scene.name));
            let opts = SimulateOptions {
                method: Method::Full,
                out: out.join("full"),
                frames: None,
                every,
                solver: None,
            };
            run_simulation(&scene, &opts)
        }
        Command::Simulate {
            scene,
            method,
            frames,
            every,
            solver,
            out,
        } => {
            let scene = load_scene(scene.as_ref())?;
            let method = match method {
                MethodArg::Full => Method::Full,
            };
            let opts = SimulateOptions {
                method,
                out: out.unwrap_or_else(|| root.join("out").join(&scene.name).join(method.name())),
                frames,
                every,
                solver: solver.map(|s| match s {
                    SolverArg::Newton => fem_core::optim::SolverMethod::Newton,
                    SolverArg::Lbfgs => fem_core::optim::SolverMethod::Lbfgs,
                }),
            };
            run_simulation(&scene, &opts)
        }
    }
}
