//! `cargo xtask view`: the interactive viewer (crates/viewer) on a scene's trained models, or on
//! a model file, beside full space for the contrast.

use std::net::{IpAddr, SocketAddr, TcpListener};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use latent_sim::model::{MeasuredError, Rows};
use latent_sim::{FullRuntime, ReducedModel};
use pipeline::run::TRAJECTORY_ERROR;
use pipeline::simulate::Method;
use viewer::{Server, Session, Settings};

use super::{Common, MethodArg};

/// The flags of `cargo xtask view`.
#[derive(clap::Args)]
pub struct ViewArgs {
    /// Scene file (TOML); the built-in cantilever when neither this nor --model is given.
    #[arg(long, conflicts_with = "model")]
    scene: Option<PathBuf>,
    /// A model file from `cargo xtask export` (its method, and full space on its mesh).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Artifact cache folder (default: out/SCENE/cache).
    #[arg(long, conflicts_with = "model")]
    cache: Option<PathBuf>,
    /// The method shown first (`full` for full space with the scene's solver, `full-newton` or
    /// `full-lbfgs` to choose it; default: neural-cubature, or the model file's method).
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// The reduced methods offered with --scene (full space is always offered).
    #[arg(long, value_enum, value_delimiter = ',', num_args = 1.., conflicts_with = "model", default_values_t = [MethodArg::NeuralCubature, MethodArg::Neural, MethodArg::PcaCubature, MethodArg::Pca])]
    methods: Vec<MethodArg>,
    /// Port; 0 picks a free one. When the default port is taken, a free one is used instead.
    #[arg(long, allow_negative_numbers = true, default_value_t = DEFAULT_PORT)]
    port: u16,
    /// Address to listen on. Anything but loopback lets other machines drive the session.
    #[arg(long, default_value = "127.0.0.1", value_parser = parse_host)]
    host: IpAddr,
}

const DEFAULT_PORT: u16 = 8080;

/// Full space on `model`'s mesh with the scene's solver, or the one `--method full-newton` or
/// `full-lbfgs` names (the page calls it `full` either way), said on a line of its own.
fn full_runtime(model: &ReducedModel, chosen: Option<Method>) -> Result<FullRuntime> {
    use fem_core::optim::{SolverConfig, SolverMethod};
    let mut solver = SolverConfig::from(&model.full_solver);
    let why = match chosen.and_then(|m| Some((m, m.forced_full_solver()?))) {
        Some((m, forced)) => {
            solver.method = forced;
            format!("as --method {m} asks")
        }
        None => "the scene's solver".to_string(),
    };
    let name = match solver.method {
        SolverMethod::Newton => "Newton",
        SolverMethod::Lbfgs => "L-BFGS",
    };
    println!("full space solves its steps with {name} ({why})");
    Ok(FullRuntime::new(
        model.full_space_model()?,
        model.time(),
        solver,
    )?)
}

/// `--host`: an IP address, or `localhost` (the loopback address the docs name).
fn parse_host(text: &str) -> Result<IpAddr, String> {
    if text.eq_ignore_ascii_case("localhost") {
        return Ok(IpAddr::from([127, 0, 0, 1]));
    }
    text.parse().map_err(|_| {
        "give an IP address, e.g. 127.0.0.1 (or localhost), or 0.0.0.0 for every one".to_string()
    })
}

/// The name full space goes by on the page.
const FULL: &str = "full";

/// Builds the session, serves it and prints where; returns when the server stops.
pub(crate) fn view(cx: &super::Context, args: ViewArgs) -> Result<()> {
    let progress = &|d, t| cx.stage_progress(d, t);
    let chosen = args.method.map(Method::from);
    let (settings, mut methods, default_start) = match &args.model {
        Some(path) => {
            if !path.exists() {
                bail!(
                    "{}: no such model file: `cargo xtask run` writes neural-cubature's beside \
                     its report (out/SCENE/neural-cubature.ldm), `cargo xtask export --method M` \
                     any method's; or view the scene itself with --scene",
                    path.display()
                );
            }
            let model = ReducedModel::load(path).context("cannot load the model")?;
            let name = model.provenance.method.clone();
            println!(
                "{}: {name} model of scene {}, {} vertices",
                path.display(),
                model.provenance.scene,
                model.mesh.num_vertices()
            );
            println!("{}", model_accuracy(&model.provenance.errors));
            // `run` writes its models beside its report.
            let report = path.with_file_name("report.md");
            if report.is_file() {
                let dir = report.parent().unwrap_or(Path::new("."));
                match pipeline::export::report_is_of(dir, &model) {
                    Ok(()) => println!("the report beside it: {}", report.display()),
                    Err(why) => println!(
                        "the report beside it is not known to be this model's: {why} (`cargo \
                         xtask run` the model's scene again to measure it)"
                    ),
                }
            }
            let methods = vec![
                viewer::Method::new(name.clone(), model.simulator()?),
                viewer::Method::new(FULL, full_runtime(&model, chosen)?),
            ];
            (Settings::for_model(&model), methods, name)
        }
        None => {
            let common = Common {
                scene: args.scene.clone(),
                cache: args.cache.clone(),
            };
            let mut wanted = crate::methods_once(&args.methods)?;
            let scene = cx.scene(&common)?;
            let mut p = cx.pipeline(&scene, &common)?;
            if let Some(m) = chosen
                && !m.is_full()
                && !wanted.contains(&m)
            {
                println!("--method {m} is not among --methods: offered first beside them");
                wanted.insert(0, m);
            }
            wanted.retain(|m| !m.is_full());
            let default_start = wanted.first().map(|m| m.name().to_string());
            let report_dir = cx.run_report_dir(&scene, &common);
            let report = report_dir.join("report.json");
            let mut methods = Vec::new();
            let mut settings = None;
            let mut measured = Vec::new();
            for m in wanted {
                let model = pipeline::export::scene_model(&mut p, m, Rows::Used, progress)?;
                if settings.is_none() {
                    settings = Some(Settings::for_model(&model));
                    methods.push(viewer::Method::new(FULL, full_runtime(&model, chosen)?));
                }
                // What that run measured of this very model (its stages' keys in the report).
                let error = pipeline::export::run_error(&report_dir, &model, &scene);
                measured.push((m.name().to_string(), error));
                methods.push(viewer::Method::new(m.name(), model.simulator()?));
            }
            let (Some(settings), Some(default_start)) = (settings, default_start) else {
                bail!("--methods names no reduced method; the viewer needs one to build on");
            };
            let cache = common.cache.as_deref();
            println!("{}", run_accuracy(&report, &scene, cache, &measured));
            (settings, methods, default_start)
        }
    };
    // The first method is the one shown first; full space last unless asked for.
    let start = match chosen {
        Some(m) if m.is_full() => FULL.to_string(),
        Some(m) => m.name().to_string(),
        None => default_start,
    };
    let Some(index) = methods.iter().position(|m| m.name == start) else {
        bail!(
            "--method {start} is not among this session's methods ({})",
            methods
                .iter()
                .map(|m| m.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    };
    let shown = methods.remove(index);
    methods.insert(0, shown);
    if let Some(full) = methods.iter().position(|m| m.name == FULL)
        && full != 0
    {
        let f = methods.remove(full);
        methods.push(f);
    }
    let names: Vec<String> = methods.iter().map(|m| m.name.clone()).collect();
    let session = Session::new(settings, methods)?;
    if !args.host.is_loopback() {
        eprintln!(
            "warning: listening on {}: anyone who can reach this machine on that port can watch \
             and drive the simulation (the viewer has no authentication)",
            args.host
        );
    }
    let listener = match TcpListener::bind(SocketAddr::new(args.host, args.port)) {
        Err(e) if args.port == DEFAULT_PORT && e.kind() == std::io::ErrorKind::AddrInUse => {
            eprintln!("port {DEFAULT_PORT} is taken; listening on a free port instead");
            TcpListener::bind(SocketAddr::new(args.host, 0))
        }
        other => other,
    }
    .map_err(|e| {
        let hint = if e.kind() == std::io::ErrorKind::AddrInUse {
            "; `--port 0` picks a free one"
        } else {
            ""
        };
        anyhow::anyhow!("cannot listen on {}:{}: {e}{hint}", args.host, args.port)
    })?;
    let server = Server::serve(listener, session)?;
    let port = server.local_addr().port();
    let url = if args.host.is_unspecified() {
        format!("http://127.0.0.1:{port}/ (from elsewhere: this machine's address, port {port})")
    } else {
        server.url()
    };
    println!(
        "viewer: open {url} in a browser ({}); Ctrl-C stops it",
        names.join(", ")
    );
    server.wait();
    Ok(())
}

/// What a model file says of its accuracy: the held-out error `run` measured, or that none was.
fn model_accuracy(errors: &[MeasuredError]) -> String {
    let held_out = || errors.iter().filter(|e| e.held_out);
    // `run` records the trajectory's displacement error, and `export` the one a report of the
    // same model gives; without one, an exported model has only the cubature rule's force
    // error on the test poses, which is no measure of how far the motion goes off (5.3 % for
    // a rule whose trajectory `run` measures 0.20 % off).
    let trajectory = held_out().find(|e| e.name.starts_with(TRAJECTORY_ERROR));
    match (trajectory, held_out().next()) {
        (Some(e), _) => format!(
            "measured when it was trained: {:.2} % ({}); `run`'s report.md says whether to trust it",
            100.0 * e.value,
            e.name
        ),
        (None, Some(e)) => format!(
            "no trajectory error is recorded in the model (`cargo xtask run` records it where the \
             method's run reached its last frame, and `export` the one such a run measured of the \
             same model): {} {:.2} %, a force error, not how far the motion goes off",
            e.name,
            100.0 * e.value
        ),
        (None, None) => "no held-out error is recorded in the model: `cargo xtask run` measures \
                         each method against full space and says what not to trust"
            .to_string(),
    }
}

/// What the last `run` of the scene measured of the models offered (`measured`: each method
/// with its error in `report`, None where the report is not of that model: another scene's,
/// stages changed since, or the method not run), or how to measure it: a person drags a model
/// without the table otherwise.
fn run_accuracy(
    report: &std::path::Path,
    scene: &pipeline::scene::Scene,
    cache: Option<&std::path::Path>,
    measured: &[(String, Option<f64>)],
) -> String {
    // The viewer's own cache, so that the run reuses the stages it trained.
    let command = format!(
        "`cargo xtask run{}{}`",
        match &scene.source {
            s if s.ends_with(".toml") => format!(" --scene {s}"),
            _ => String::new(),
        },
        cache.map_or(String::new(), |c| {
            // Quoted where a shell would split it.
            let c = c.display().to_string();
            if c.contains(char::is_whitespace) {
                format!(" --cache \"{c}\"")
            } else {
                format!(" --cache {c}")
            }
        })
    );
    let (known, unknown): (Vec<_>, Vec<_>) = measured.iter().partition(|(_, e)| e.is_some());
    if known.is_empty() {
        let stale = if report.is_file() {
            format!(
                " ({} measures none of these models: the scene changed since, or that run ran \
                 other methods)",
                report.display()
            )
        } else {
            String::new()
        };
        return format!(
            "how far each method is from full space: {command}{stale}; its report.md lists what \
             not to trust"
        );
    }
    let figures: Vec<String> = known
        .iter()
        .filter_map(|(m, e)| Some(format!("{m} {:.2} %", 100.0 * (*e)?)))
        .collect();
    let rest = if unknown.is_empty() {
        String::new()
    } else {
        let names: Vec<&str> = unknown.iter().map(|(m, _)| m.as_str()).collect();
        format!(
            "; not measured there: {} ({command} measures them)",
            names.join(", ")
        )
    };
    format!(
        "the last `run` of this scene measured these models, off its held-out test: {} ({}; its \
         report.md says whether to trust them){rest}",
        figures.join(", "),
        report.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Before the viewer starts it says what `run` measured of the models it offers, or how to
    /// measure them.
    #[test]
    fn the_viewer_says_what_run_measured_or_how_to_measure_it() {
        let scene = pipeline::scene::Scene::builtin();
        let dir = std::env::temp_dir().join(format!("view-accuracy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = dir.join("report.json");
        let offered = |errors: &[(&str, Option<f64>)]| -> Vec<(String, Option<f64>)> {
            errors.iter().map(|(m, e)| (m.to_string(), *e)).collect()
        };
        let none = run_accuracy(&report, &scene, None, &offered(&[("pca", None)]));
        assert!(
            none.starts_with("how far each method is from full space: `cargo xtask run`;"),
            "{none}"
        );
        // A cache of the viewer's own is the run's too.
        let cached = run_accuracy(
            &report,
            &scene,
            Some(std::path::Path::new("c/cache")),
            &offered(&[("pca", None)]),
        );
        assert!(
            cached.contains("`cargo xtask run --cache c/cache`;"),
            "{cached}"
        );
        // A report of other stages (a scene changed since) measures none of them.
        std::fs::write(&report, "{}").unwrap();
        let stale = run_accuracy(&report, &scene, None, &offered(&[("pca", None)]));
        assert!(stale.contains("measures none of these models"), "{stale}");
        let some = run_accuracy(
            &report,
            &scene,
            None,
            &offered(&[("pca", Some(0.0479)), ("neural-cubature", None)]),
        );
        assert!(
            some.starts_with(
                "the last `run` of this scene measured these models, off its held-out test: \
                 pca 4.79 % ("
            ) && some.ends_with(
                "; not measured there: neural-cubature (`cargo xtask run` measures them)"
            ),
            "{some}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A model file's trajectory error is its accuracy; an exported model's cubature force
    /// error is said to be no such thing.
    #[test]
    fn a_model_says_its_trajectory_error_not_its_force_error() {
        let force = MeasuredError {
            name: "cubature: relative reduced-force error on held-out test trajectory 0".into(),
            held_out: true,
            value: 0.0532,
        };
        let trajectory = MeasuredError {
            name: format!("{TRAJECTORY_ERROR} 0"),
            held_out: true,
            value: 0.0024,
        };
        let run = model_accuracy(&[force.clone(), trajectory]);
        assert!(
            run.starts_with("measured when it was trained: 0.24 % (mean relative"),
            "{run}"
        );
        let exported = model_accuracy(std::slice::from_ref(&force));
        assert!(
            exported.starts_with("no trajectory error is recorded"),
            "{exported}"
        );
        assert!(exported.contains("5.32 %, a force error"), "{exported}");
        assert!(model_accuracy(&[]).starts_with("no held-out error"));
    }

    /// `--host localhost` is the loopback address; anything else not an IP address says what
    /// to give.
    #[test]
    fn hosts_are_ip_addresses_or_localhost() {
        assert_eq!(parse_host("localhost"), Ok(IpAddr::from([127, 0, 0, 1])));
        assert_eq!(parse_host("0.0.0.0"), Ok(IpAddr::from([0, 0, 0, 0])));
        assert_eq!(parse_host("::1"), Ok("::1".parse().unwrap()));
        assert!(
            parse_host("example.org")
                .unwrap_err()
                .contains("give an IP address")
        );
    }
}
