//! A reduced method's trained model as one self-contained file (DESIGN §11): a
//! [`latent_sim::ReducedModel`] built from the cached stages, for `cargo xtask export` and
//! `run`, and for the runners of `simulate` and `run`, which step the same model through
//! latent-sim's runtime.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use fem_core::integrator::{FullSpaceModel, TimeConfig};
use fem_core::material::MaterialConfig;
use fem_core::optim::SolverConfig;
use latent_sim::ReducedModel;
use latent_sim::model::{MeasuredError, ModelSource, Provenance, Rows, StageKey, SubspaceSource};

use std::sync::Arc;

use crate::coverage::TrainingPoses;
use crate::pipeline::{FittedCubature, Pipeline, Progress};
use crate::simulate::{Method, solver_for};
use crate::stage::Stage;

/// The method `cargo xtask export` exports and `run` writes the model of: the paper's.
pub const DEFAULT_METHOD: Method = Method::NeuralCubature;

/// The method whose model `run` writes among `methods`: [`DEFAULT_METHOD`] when it ran, else the
/// first reduced method (none when only full-space methods ran).
pub fn run_method(methods: &[Method]) -> Option<Method> {
    if methods.contains(&DEFAULT_METHOD) {
        Some(DEFAULT_METHOD)
    } else {
        methods.iter().copied().find(|m| !m.is_full())
    }
}

/// Where `cargo xtask export` and `run` put `method`'s model: `<folder>/<method>.ldm`.
pub fn model_path(folder: &Path, method: Method) -> PathBuf {
    folder.join(format!("{}.ldm", method.name()))
}

/// The model of reduced `method` on `model` (built with `material`; its forces are not part of
/// the model) with the time step of `time` and the solver settings `solver`, from the cached
/// stages (computed when missing), keeping the basis rows `rows`.
///
/// # Errors
/// For a full-space method, or when a stage fails or its products do not fit the model.
#[allow(clippy::too_many_arguments)]
pub fn reduced_model(
    pipeline: &mut Pipeline<'_>,
    method: Method,
    model: &FullSpaceModel,
    material: &MaterialConfig,
    time: &TimeConfig,
    solver: SolverConfig,
    rows: Rows,
    progress: Progress<'_>,
) -> Result<ReducedModel> {
    reduced_model_with(
        pipeline, method, model, material, time, solver, rows, progress, None,
    )
}

/// [`reduced_model`] with the cubature rule `rule` in place of the method's stage's, when given
/// (the `cubature-neural` stage trying its candidate rules on training schedules).
///
/// # Errors
/// As [`reduced_model`].
#[allow(clippy::too_many_arguments)]
pub(crate) fn reduced_model_with(
    pipeline: &mut Pipeline<'_>,
    method: Method,
    model: &FullSpaceModel,
    material: &MaterialConfig,
    time: &TimeConfig,
    solver: SolverConfig,
    rows: Rows,
    progress: Progress<'_>,
    rule: Option<Arc<FittedCubature>>,
) -> Result<ReducedModel> {
    if method.is_full() {
        bail!(
            "{} is a full-space method; only the reduced methods (pca, pca-cubature, neural, \
             neural-cubature) have a trained model",
            method.name()
        );
    }
    let scene = pipeline.scene;
    let key = |stage: Stage, key: u64| StageKey {
        stage: stage.name().into(),
        key,
    };
    let mut stage_keys = vec![
        key(Stage::Snapshots, pipeline.snapshots_key()),
        key(Stage::Pca, pipeline.pca_key()),
    ];
    let training = |name: String, value: f64| MeasuredError {
        name,
        held_out: false,
        value,
    };
    let fit = pipeline.pca(progress)?;
    let mut errors = Vec::new();
    if let Some(&e) = fit.max_vertex_error_per_k.get(fit.chosen_k() - 1) {
        errors.push(training(
            format!(
                "PCA (k = {}): largest vertex distance over the snapshots (m)",
                fit.chosen_k()
            ),
            e,
        ));
    }
    let neural = matches!(method, Method::Neural | Method::NeuralCubature);
    // The stages in the order the runners always asked for them.
    let trained = if neural {
        stage_keys.push(key(Stage::Train, pipeline.train_key()));
        let t = pipeline.train(progress)?;
        errors.push(training(
            format!(
                "autoencoder (d = {}): largest vertex distance over the snapshots (m)",
                t.latent_dim
            ),
            t.max_vertex_error,
        ));
        Some(t)
    } else {
        None
    };
    let cubature = match method {
        Method::PcaCubature | Method::NeuralCubature if rule.is_some() => rule,
        Method::PcaCubature => {
            stage_keys.push(key(Stage::Cubature, pipeline.cubature_key()));
            Some(pipeline.cubature(progress)?)
        }
        Method::NeuralCubature => {
            stage_keys.push(key(Stage::CubatureNeural, pipeline.cubature_neural_key()));
            Some(pipeline.cubature_neural(progress)?)
        }
        _ => None,
    };
    if let Some(c) = &cubature {
        errors.push(training(
            format!(
                "cubature ({} elements): relative reduced-force error on the training poses",
                c.rule.len()
            ),
            c.rule.training_error,
        ));
        errors.push(MeasuredError {
            name: "cubature: relative reduced-force error on held-out test trajectory 0".into(),
            held_out: true,
            value: c.held_out_error,
        });
    }
    let complement = if neural {
        let columns = pipeline.complement_columns(progress)?;
        // A source unless the scene asked for none (the columns may then still hold the PCA
        // basis's patch responses, which are the `pca` stage's).
        if scene.reduced.complement_directions != Some(0) {
            stage_keys.push(key(Stage::Complement, pipeline.complement_key()));
        }
        columns
    } else {
        Vec::new()
    };
    let subspace = match &trained {
        Some(t) => SubspaceSource::Neural {
            autoencoder: &t.model,
            onset_directions: pipeline.onset_directions(),
            complement: &complement,
        },
        None => SubspaceSource::Linear,
    };
    // The runtime measures each step's pose against them, as `run` measures each frame's.
    let poses = pipeline.coverage(progress)?;
    stage_keys.push(key(Stage::Coverage, pipeline.coverage_key()));
    let source = ModelSource {
        model,
        material,
        time,
        basis: &fit.basis,
        cubature: cubature.as_ref().map(|c| &c.rule),
        subspace,
        solver,
        preconditioning: scene.reduced.preconditioner,
        spring_compliance: scene.reduced.spring_compliance,
        full_solver: scene.solver.clone(),
        rows,
        provenance: Provenance {
            project_version: env!("CARGO_PKG_VERSION").into(),
            scene: scene.name.clone(),
            method: method.name().into(),
            stage_keys,
            errors,
        },
        training: Some(TrainingPoses::clone(&poses.poses)),
    };
    ReducedModel::build(source)
        .map_err(|e| anyhow::anyhow!("{}: model of {}: {e}", scene.source, method.name()))
}

/// One line saying what the model of `method` on scene `scene`, written to `path`, holds: its
/// sizes, the vertices whose basis rows it keeps, its elements and the file's size.
pub fn describe(scene: &str, method: Method, model: &ReducedModel, path: &Path) -> String {
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    format!(
        "{}: {} model, {} vertices ({} with basis rows), {} tets, k = {}, {} reduced coordinates{}, {} elements evaluated → {} ({:.2} MB)",
        scene,
        method.name(),
        model.mesh.num_vertices(),
        model.space.vertices.len(),
        model.mesh.num_tets(),
        model.space.k,
        model.latent_dim(),
        if matches!(method, Method::Neural | Method::NeuralCubature) {
            " (the latent ones and the linear directions beside them)"
        } else {
            ""
        },
        model
            .cubature
            .as_ref()
            .map_or(model.mesh.num_tets(), |c| c.len()),
        path.display(),
        bytes as f64 / 1e6
    )
}

/// The model of reduced `method` on the scene, with the solver settings `cargo xtask run` steps
/// it with, keeping the basis rows `rows` (the rows in use, by default).
///
/// # Errors
/// As [`reduced_model`].
pub fn scene_model(
    pipeline: &mut Pipeline<'_>,
    method: Method,
    rows: Rows,
    progress: Progress<'_>,
) -> Result<ReducedModel> {
    let scene = pipeline.scene;
    let model = pipeline.model.clone();
    reduced_model(
        pipeline,
        method,
        &model,
        &scene.material,
        &scene.time,
        solver_for(scene, method),
        rows,
        progress,
    )
}

/// What `cargo xtask run` measured of `model`, read from the `report.json` it wrote in `out`:
/// the method's error on the held-out test and the figures not to be trusted that name the
/// method, the test's full simulation or the scene, when the report is of the same model
/// (every stage key of the model's provenance among the report's, and the scene's `[solver]`,
/// `[reduced]` and `[test]` as the run had them). Otherwise, why there is no measure and the
/// command that makes one: an exported model is the stages' output, and only `run` tests it.
pub fn run_verdict(out: &Path, model: &ReducedModel, scene: &crate::scene::Scene) -> String {
    let (report, error) = match measured(out, model, scene) {
        Ok(m) => m,
        Err(why) => return why,
    };
    let method = model.provenance.method.as_str();
    let mut lines: Vec<&str> = report["untrusted"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|l| l.as_str())
                .filter(|l| names(l, method) || *l == crate::trust::SCENE_FIRST)
                .collect()
        })
        .unwrap_or_default();
    // The line between the scene's warnings and the rest, where some of the rest is kept.
    if lines.last() == Some(&crate::trust::SCENE_FIRST) {
        lines.pop();
    }
    let mut s = format!(
        "measured by `cargo xtask run` on held-out test trajectory {} ({}, written {}): {method} \
         {:.2} % from the full trajectory",
        report["trajectory"],
        out.join("report.md").display(),
        report["written"].as_str().unwrap_or("?"),
        100.0 * error
    );
    if lines.is_empty() {
        s.push_str("; nothing in that report says not to trust it");
    } else {
        s.push_str("; not to be trusted:");
        for l in lines {
            s.push_str(&format!("\n- {l}"));
        }
    }
    s
}

/// The folder of the run report that speaks for the model file at `path`: the file's own folder
/// when a `report.json` is there, else `otherwise` (the scene's output folder).
pub fn report_dir(path: &Path, otherwise: PathBuf) -> PathBuf {
    let beside = path.parent().map(PathBuf::from).unwrap_or_default();
    if beside.join("report.json").is_file() {
        beside
    } else {
        otherwise
    }
}

/// Records in `model` the error `cargo xtask run` measured of it on its held-out test, as `run`
/// records it in the model it writes, when the report in `out` is of the same model
/// ([`run_verdict`]'s conditions) and the method's run reached its last frame, so that `view
/// --model` and a program reading the file have it (a tester's `export` printed 3.44 % and
/// `view` then said none was recorded). Whether it was recorded.
pub fn record_run_error(out: &Path, model: &mut ReducedModel, scene: &crate::scene::Scene) -> bool {
    let Ok((report, error)) = measured(out, model, scene) else {
        return false;
    };
    let method = model.provenance.method.as_str();
    let finished = report["methods"]
        .as_array()
        .and_then(|rows| rows.iter().find(|r| r["method"] == method))
        .is_some_and(|r| r["failure"].is_null());
    let Some(trajectory) = report["trajectory"].as_u64().filter(|_| finished) else {
        return false;
    };
    // One trajectory error, the one of this report.
    let name = crate::run::TRAJECTORY_ERROR;
    model
        .provenance
        .errors
        .retain(|e| !e.name.starts_with(name));
    model.provenance.errors.push(MeasuredError {
        name: format!("{name} {trajectory}"),
        held_out: true,
        value: error,
    });
    true
}

/// The error `cargo xtask run` measured of `model` on its held-out test, from the `report.json`
/// in `out`, when that report is of the same model ([`run_verdict`]'s conditions); None
/// otherwise.
pub fn run_error(out: &Path, model: &ReducedModel, scene: &crate::scene::Scene) -> Option<f64> {
    measured(out, model, scene).ok().map(|(_, error)| error)
}

/// The report in `out` and the error it gives `model`'s method when the report is of the same
/// model; otherwise why not, and the command that measures it.
fn measured(
    out: &Path,
    model: &ReducedModel,
    scene: &crate::scene::Scene,
) -> Result<(serde_json::Value, f64), String> {
    let path = out.join("report.json");
    let method = model.provenance.method.as_str();
    let run = "`cargo xtask run` measures it on a held-out test and says whether to trust it";
    let Some(report) = read_report(&path) else {
        return Err(format!(
            "not measured: no run report in {} ({run})",
            out.display()
        ));
    };
    let row = report["methods"]
        .as_array()
        .and_then(|rows| rows.iter().find(|r| r["method"] == method));
    let Some(error) = row.and_then(|r| r["mean_rel_error"].as_f64()) else {
        return Err(format!(
            "not measured: the run in {} did not run {method} (`cargo xtask run --methods full \
             {method}` does)",
            out.display()
        ));
    };
    let stages = report["stages"].as_array().cloned().unwrap_or_default();
    if report.get("settings").is_none() || stages.iter().any(|s| s.get("key").is_none()) {
        return Err(format!(
            "not measured: {} was written before reports named their stages' keys ({run} again)",
            path.display()
        ));
    }
    if !of_stages(&stages, model) {
        return Err(format!(
            "not measured: {} is of other stages (the scene changed since, or another scene \
             wrote there; {run})",
            path.display()
        ));
    }
    if report["settings"] != crate::run::run_settings(scene) {
        return Err(format!(
            "not measured: {} was run with other `[solver]`, `[reduced]` or `[test]` settings \
             ({run} with these)",
            path.display()
        ));
    }
    Ok((report, error))
}

/// The run report (`report.json`) at `path`, when it is there and reads as JSON.
fn read_report(path: &Path) -> Option<serde_json::Value> {
    std::fs::read(path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
}

/// Whether the stages a run report lists (its `stages`) include every stage `model` was made
/// of, each with the same key; but the snapshots, which a warm run does not read (their key is
/// in the basis's, which is compared).
fn of_stages(stages: &[serde_json::Value], model: &ReducedModel) -> bool {
    let snapshots = Stage::Snapshots.name();
    model
        .provenance
        .stage_keys
        .iter()
        .filter(|k| k.stage != snapshots)
        .all(|k| {
            let key = format!("{:016x}", k.key);
            stages
                .iter()
                .any(|s| s["stage"] == k.stage.as_str() && s["key"] == key.as_str())
        })
}

/// Whether the `report.json` in `out` is of `model`'s stages (the run that wrote it used the
/// stages the model was made of), when no scene is at hand to compare settings with: `view
/// --model` names the report beside a model only then, not one a later run of another scene
/// wrote into the same folder. Otherwise why not: no report that reads, one written before
/// reports named their stages' keys, or one of other stages.
pub fn report_is_of(out: &Path, model: &ReducedModel) -> Result<(), String> {
    let path = out.join("report.json");
    let report = read_report(&path)
        .ok_or_else(|| format!("{} is missing or does not read", path.display()))?;
    let stages = report["stages"].as_array().cloned().unwrap_or_default();
    if stages.is_empty() || stages.iter().any(|s| s.get("key").is_none()) {
        return Err(format!(
            "{} was written before reports named their stages' keys",
            path.display()
        ));
    }
    if !of_stages(&stages, model) {
        return Err(format!(
            "{} is of other stages: a later run of another scene, or of this one changed, \
             wrote there",
            path.display()
        ));
    }
    Ok(())
}

/// Whether a line of a run's warnings concerns `method`'s model: it names the method (alone or
/// in a list, "pca, neural-cubature: …"), the test's full simulation (on whichever full-space
/// row carried it, "full-newton: …", or "the full-space reference: …"), the scene, or (for a
/// reduced method) the PCA basis every reduced method shares.
pub fn names(line: &str, method: &str) -> bool {
    let who = line.split(':').next().unwrap_or("");
    who.split(", ")
        .any(|n| n == method || Method::ALL.iter().any(|m| m.is_full() && m.name() == n))
        || who == "the scene"
        || who.starts_with("the full-space")
        // Every reduced method's basis.
        || (who == "the PCA basis" && reduced(method))
}

/// Whether `method` names a reduced method (every one of which works in the PCA basis).
fn reduced(method: &str) -> bool {
    Method::ALL
        .iter()
        .any(|m| !m.is_full() && m.name() == method)
}
