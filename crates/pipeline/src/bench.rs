//! `cargo xtask bench`: every method at several sizes on one held-out trajectory, timed in one
//! process with a warm-up and repeated runs, so users can choose a method by its cost and its
//! error (`bench.json`, `bench.md`, `bench.svg` with the Pareto front).
//!
//! Each size is a variant of the scene (the PCA dimension, the autoencoder's latent dimension,
//! the cubature tolerance), so every variant's stages are ordinary cached stages: a second bench
//! of the same scene only re-times.

use std::path::{Path, PathBuf};

use anyhow::Result;
use fem_core::optim::SolverMethod;

use crate::pipeline::{Pipeline, Progress};
use crate::plot::{Plot, Scale, Series};
use crate::run::{Measure, MethodReport, measure, set_speedups};
use crate::scene::Scene;
use crate::simulate::{Method, write_json};

/// What `bench` sweeps.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub out: PathBuf,
    /// Artifact cache shared by every variant.
    pub cache: PathBuf,
    pub trajectory: usize,
    /// Timed runs per variant, after one untimed warm-up run.
    pub repeats: usize,
    /// PCA dimensions for `pca` (empty: the latent dimensions, half and all of the scene's basis).
    pub pca_dims: Vec<usize>,
    /// Latent dimensions for `neural` (empty: the scene's, half and double it).
    pub latent_dims: Vec<usize>,
    /// Cubature tolerances for both cubature methods.
    pub tolerances: Vec<f64>,
    /// `[reduced] complement_directions` counts to run the neural methods with, at the scene's
    /// latent dimension (none by default).
    pub complement_dims: Vec<usize>,
}

/// Default cubature tolerances swept.
pub const DEFAULT_TOLERANCES: [f64; 3] = [0.1, 0.05, 0.02];

/// One benchmarked variant.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BenchRow {
    /// Method and size, e.g. `pca k=16` or `neural-cubature tol=0.05`.
    pub variant: String,
    #[serde(flatten)]
    pub report: MethodReport,
    /// Offline cost of the variant's own stages as recorded when they were computed (s):
    /// autoencoder training and/or cubature fit. Snapshots and PCA are shared by all.
    pub offline_seconds: f64,
    /// Not dominated in (ms/step, mean relative error) by another variant.
    pub pareto: bool,
}

/// A scene variant: which method, its label, and how the scene changes.
struct Variant {
    method: Method,
    label: String,
    scene: Scene,
    solver: Option<SolverMethod>,
}

/// Refuses a sweep that would time nothing or leave out what it was asked for: before the
/// stages, the repeats, tolerances and complement counts; once the PCA basis is known (`sizes`: the rule's k and
/// the basis's columns), dimensions it cannot have.
fn check_options(opts: &BenchOptions, sizes: Option<(usize, usize)>) -> Result<()> {
    if opts.repeats == 0 {
        anyhow::bail!("`repeats` (`--repeats`) must be at least 1: the timed runs of each variant");
    }
    if let Some(t) = opts.tolerances.iter().find(|t| !(**t > 0.0 && **t < 1.0)) {
        anyhow::bail!(
            "cubature tolerance {t} (`--tolerances`): each must lie between 0 and 1, a relative \
             force error such as 0.05"
        );
    }
    if let Some(&c) = opts
        .complement_dims
        .iter()
        .find(|&&c| c > latent_sim::MAX_COMPLEMENT_DIRECTIONS)
    {
        anyhow::bail!(
            "complement direction count {c} (`--complement-dims`): at most {}",
            latent_sim::MAX_COMPLEMENT_DIRECTIONS
        );
    }
    let Some((chosen_k, basis_k)) = sizes else {
        return Ok(());
    };
    let past = |dims: &[usize], max: usize| dims.iter().copied().find(|&k| k == 0 || k > max);
    if let Some(k) = past(&opts.pca_dims, chosen_k) {
        anyhow::bail!(
            "PCA dimension {k} (`--pca-dims`): the scene's PCA rule keeps k = {chosen_k} \
             directions of the snapshots, so a variant can have 1 to {chosen_k} (a larger basis \
             needs `[pca]` to keep more){}",
            if basis_k > chosen_k {
                format!(
                    "; the basis's {basis_k} columns also count the {} gravity and patch \
                     directions appended to them, which every variant keeps",
                    basis_k - chosen_k
                )
            } else {
                String::new()
            }
        );
    }
    if let Some(d) = past(&opts.latent_dims, basis_k) {
        anyhow::bail!(
            "latent dimension {d} (`--latent-dims`): the autoencoder's input has the basis's \
             {basis_k} columns, so a variant can have 1 to {basis_k}"
        );
    }
    Ok(())
}

/// `chosen_k` is the PCA rule's k, `basis_k` the basis's columns with those appended to it (the
/// autoencoder's input, whose half is the default latent dimension).
fn variants(scene: &Scene, chosen_k: usize, basis_k: usize, opts: &BenchOptions) -> Vec<Variant> {
    let mut v = Vec::new();
    let base = |method: Method, label: String| Variant {
        method,
        label,
        scene: scene.clone(),
        solver: None,
    };
    v.push(base(
        Method::Full,
        format!("full ({})", scene.solver.method.name()),
    ));
    // The other full-space solver beside the scene's.
    v.push(match scene.solver.method {
        SolverMethod::Newton => base(Method::FullLbfgs, "full-lbfgs".into()),
        SolverMethod::Lbfgs => base(Method::FullNewton, "full-newton".into()),
    });
    let tolerances = if opts.tolerances.is_empty() {
        DEFAULT_TOLERANCES.to_vec()
    } else {
        opts.tolerances.clone()
    };
    let mut latent_dims = opts.latent_dims.clone();
    if latent_dims.is_empty() {
        let d = scene
            .autoencoder
            .latent_dim
            .or(scene.autoencoder.latent_dims.map(|r| r[0]))
            .unwrap_or_else(|| crate::pipeline::default_latent_dim(basis_k));
        // Twice d at most the autoencoder's input: the largest variant there is.
        latent_dims = vec![d.div_ceil(2), d, (2 * d).min(basis_k)];
    }
    latent_dims.sort_unstable();
    latent_dims.dedup();
    let mut pca_dims = if opts.pca_dims.is_empty() {
        // The latent dimensions too: PCA and the autoencoder compared at equal dimension.
        let mut dims = latent_dims.clone();
        dims.extend([chosen_k.div_ceil(2), chosen_k]);
        dims
    } else {
        opts.pca_dims.clone()
    };
    pca_dims.retain(|&k| k <= chosen_k);
    pca_dims.sort_unstable();
    pca_dims.dedup();
    // The scene's own `pca-cubature` is the k sweep's row at its k unless the tolerances have it.
    let own_k_swept = pca_dims.contains(&chosen_k);
    for k in pca_dims {
        let mut s = scene.clone();
        s.pca = pca::PcaConfig {
            dimension: Some(k),
            explained_energy: None,
            max_vertex_error: None,
            ..scene.pca.clone()
        };
        v.push(Variant {
            method: Method::Pca,
            label: format!("pca k={k}"),
            scene: s.clone(),
            solver: None,
        });
        // With cubature at the scene's tolerance too, so that the reduced methods are compared at
        // equal error on speed. At the scene's own k this is the scene's own `pca-cubature`,
        // unless the tolerance sweep below already has its tolerance; its label then names the
        // tolerance too, beside its Newton variant's.
        if k < chosen_k || !tolerances.contains(&scene.cubature.tolerance) {
            v.push(Variant {
                method: Method::PcaCubature,
                label: if k < chosen_k {
                    format!("pca-cubature k={k}")
                } else {
                    format!("pca-cubature k={k} tol={}", scene.cubature.tolerance)
                },
                scene: s,
                solver: None,
            });
        }
    }
    for &method in &[Method::PcaCubature, Method::NeuralCubature] {
        let own = match method {
            Method::NeuralCubature => scene.cubature.for_neural().tolerance,
            _ => scene.cubature.tolerance,
        };
        // The scene's own tolerance with the scene's solver runs whatever `tolerances` says,
        // as the partner of the Newton variant below (a tester's `--tolerances 0.05` left the
        // Newton variant at 0.02 with nothing to compare it with).
        let own_run = tolerances.contains(&own) || (method == Method::PcaCubature && own_k_swept);
        for tol in tolerances.iter().copied().chain((!own_run).then_some(own)) {
            let mut s = scene.clone();
            s.cubature.tolerance = tol;
            s.cubature.neural_tolerance = None;
            v.push(Variant {
                method,
                label: format!("{} tol={tol}", method.name()),
                scene: s,
                solver: None,
            });
        }
        // Newton in the latent space (d×d Gauss–Newton) against the default L-BFGS, at the
        // scene's own tolerance for the method's rule.
        v.push(Variant {
            method,
            label: format!("{} tol={own} newton", method.name()),
            scene: scene.clone(),
            solver: Some(SolverMethod::Newton),
        });
    }
    // Any d up to the autoencoder's input, the basis with its appended columns.
    for d in latent_dims.into_iter().filter(|&d| d <= basis_k) {
        let mut s = scene.clone();
        s.autoencoder.latent_dim = Some(d);
        s.autoencoder.latent_dims = None;
        s.autoencoder.max_vertex_error = None;
        v.push(Variant {
            method: Method::Neural,
            label: format!("neural d={d}"),
            scene: s.clone(),
            solver: None,
        });
        v.push(Variant {
            method: Method::NeuralCubature,
            label: format!("neural-cubature d={d}"),
            scene: s.clone(),
            solver: None,
        });
        // The autoencoder alone at its size (only the onset directions beside it): the
        // complement directions the scene adds by default bring every d back to about PCA's
        // count, which hides what a small latent space buys at low cost.
        if scene.reduced.complement_directions != Some(0) {
            s.reduced.complement_directions = Some(0);
            v.push(Variant {
                method: Method::NeuralCubature,
                label: format!("neural-cubature d={d} c=0"),
                scene: s,
                solver: None,
            });
        }
    }
    let mut complement_dims = opts.complement_dims.clone();
    complement_dims.sort_unstable();
    complement_dims.dedup();
    for c in complement_dims {
        let mut s = scene.clone();
        s.reduced.complement_directions = Some(c);
        for method in [Method::Neural, Method::NeuralCubature] {
            v.push(Variant {
                method,
                label: format!("{} c={c}", method.name()),
                scene: s.clone(),
                solver: None,
            });
        }
    }
    v
}

/// Marks the rows no other row beats on both time and error.
fn mark_pareto(rows: &mut [BenchRow]) {
    let points: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (r.report.ms_per_step, r.report.mean_rel_error))
        .collect();
    let failed: Vec<Option<String>> = rows.iter().map(|r| r.report.failure.clone()).collect();
    for (i, r) in rows.iter_mut().enumerate() {
        let (t, e) = points[i];
        r.pareto = r.report.failure.is_none()
            && !points.iter().enumerate().any(|(j, &(t2, e2))| {
                j != i && failed[j].is_none() && t2 <= t && e2 <= e && (t2 < t || e2 < e)
            });
    }
}

/// Runs the sweep. `on_variant(label)` is called before each variant, `on_stage_start` when a
/// stage starts to compute and `on_stage` when one ends (each shared stage once).
pub fn bench(
    scene: &Scene,
    opts: &BenchOptions,
    on_stage_start: &dyn Fn(crate::stage::Stage),
    on_stage: &mut dyn FnMut(&crate::pipeline::StageOutcome),
    on_variant: &mut dyn FnMut(&str),
    stage_progress: Progress<'_>,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<Vec<BenchRow>> {
    check_options(opts, None)?;
    // Every variant builds its own pipeline over the shared cache: a stage they share is said
    // once, when first computed or loaded, not again by each variant.
    let mut said = std::collections::HashSet::new();
    let on_stage = &mut |o: &crate::pipeline::StageOutcome| {
        if said.insert(o.path.clone()) {
            on_stage(o);
        }
    };
    let (chosen_k, basis_k) = {
        let mut p = Pipeline::new(scene, &opts.cache)?;
        p.on_stage = Box::new(&mut *on_stage);
        p.on_stage_start = Box::new(on_stage_start);
        p.reference(opts.trajectory, stage_progress)?;
        // The rule's k: a variant `dimension = k` then has the scene's own basis, with the same
        // gravity directions appended.
        let fit = p.pca(stage_progress)?;
        (fit.chosen_k(), fit.basis.k())
    };
    check_options(opts, Some((chosen_k, basis_k)))?;
    let mut rows = Vec::new();
    for v in variants(scene, chosen_k, basis_k, opts) {
        on_variant(&v.label);
        let mut p = Pipeline::new(&v.scene, &opts.cache)?;
        p.on_stage = Box::new(&mut *on_stage);
        p.on_stage_start = Box::new(on_stage_start);
        let offline_seconds = match v.method {
            Method::PcaCubature => p.cubature(stage_progress)?.fit_seconds,
            Method::Neural => p.train(stage_progress)?.train_seconds,
            Method::NeuralCubature => {
                p.train(stage_progress)?.train_seconds
                    + p.cubature_neural(stage_progress)?.fit_seconds
            }
            _ => 0.0,
        };
        let m = Measure {
            method: v.method,
            trajectory: opts.trajectory,
            out: opts.out.join("frames"),
            every: 0,
            repeats: opts.repeats,
            time_budget: None,
            time_full: true,
            solver: v.solver,
        };
        // Warm-up: caches, page faults, the allocator; its time is discarded.
        let warm = Measure {
            repeats: 1,
            ..m.clone()
        };
        measure(&mut p, &warm, stage_progress, progress)?;
        let report = measure(&mut p, &m, stage_progress, progress)?;
        rows.push(BenchRow {
            variant: v.label,
            report,
            offline_seconds,
            pareto: false,
        });
    }
    let mut reports: Vec<MethodReport> = rows.iter().map(|r| r.report.clone()).collect();
    set_speedups(&mut reports);
    for (row, r) in rows.iter_mut().zip(reports) {
        row.report = r;
    }
    mark_pareto(&mut rows);
    write(&opts.out, &scene.name, &rows)?;
    Ok(rows)
}

fn write(out: &Path, scene: &str, rows: &[BenchRow]) -> Result<()> {
    let mut json = Vec::with_capacity(rows.len());
    for row in rows {
        let mut value = serde_json::to_value(row)?;
        crate::run::null_if_full_space(&mut value, row.report.method);
        json.push(value);
    }
    write_json(&out.join("bench.json"), &json)?;
    crate::output::write_file(&out.join("bench.md"), markdown(rows).as_bytes())?;
    crate::output::write_file(&out.join("bench.svg"), plot(scene, rows).as_bytes())?;
    Ok(())
}

/// What `cargo xtask bench` shows at the end: the table and where it is written.
pub fn summary(scene: &Scene, opts: &BenchOptions, rows: &[BenchRow]) -> String {
    format!(
        "\n{} — held-out test trajectory {}, {} timed runs per variant\n\n{}\nbench: {} (also bench.md, bench.svg)\n",
        scene.name,
        opts.trajectory,
        opts.repeats,
        markdown(rows),
        opts.out.join("bench.json").display()
    )
}

/// The sweep as a markdown table (Pareto-optimal variants marked with ★).
pub fn markdown(rows: &[BenchRow]) -> String {
    let mut s = String::from(
        "| variant | dim | elements | ms/step (mean) | spread | median ms/step | Hz | speed-up | mean rel. error | space-time error | max rel. error | subspace error | one-step error | iterations | offline s | machine G FMA/s | Pareto |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|\n",
    );
    for r in rows {
        let m = &r.report;
        s.push_str(&format!(
            "| {} | {} | {} | {:.3} | {:.3}–{:.3} | {:.3} | {:.1} | {} | {:.2e} | {:.2e} | {:.2e} | {} | {} | {:.1} | {:.1} | {} | {} |\n",
            match &m.failure {
                Some(f) => format!("{} (failed at {f})", r.variant),
                None => r.variant.clone(),
            },
            m.dim,
            m.cubature_elements,
            m.ms_per_step,
            m.ms_min,
            m.ms_max,
            m.ms_median,
            m.hz,
            crate::run::speedup_cell(m.speedup, 1),
            m.mean_rel_error,
            m.trajectory_error,
            m.max_rel_error,
            crate::run::reduced_cell(m.method, format!("{:.2e}", m.subspace_error)),
            crate::run::reduced_cell(m.method, format!("{:.2e}", m.step_error)),
            m.iterations,
            r.offline_seconds,
            crate::run::gfma_cell(m.machine_gfma),
            if r.pareto { "★" } else { "" }
        ));
    }
    // A front drawn through variants far off the full trajectory reads as speed-ups of
    // stand-ins (a tester's sweep starred `pca-cubature k=2` at 5642×, 67 % off).
    let off: Vec<String> = rows
        .iter()
        .filter(|r| {
            !r.report.method.is_full()
                && r.report.failure.is_none()
                && r.report.mean_rel_error > crate::trust::UNTRUSTED_ERROR
        })
        .map(|r| format!("{} ({:.0} %)", r.variant, 100.0 * r.report.mean_rel_error))
        .collect();
    if !off.is_empty() {
        s.push_str(&format!(
            "\nmore than {:.0} % off the full trajectory on average, not a stand-in for it at \
             any speed (★ marks the front of every variant): {}; `cargo xtask run` on the scene \
             says why its own sizes fall short\n",
            100.0 * crate::trust::UNTRUSTED_ERROR,
            off.join(", ")
        ));
    }
    s
}

/// Error (log) against ms/step (log), one series per method, the Pareto front as a line.
/// Variants with zero error (the full-space reference itself) cannot sit on a log axis: the
/// title names the reference's cost instead. The other full-space solvers are drawn apart, so
/// that their round-off does not set the y axis.
pub fn plot(scene: &str, rows: &[BenchRow]) -> String {
    let mut series: Vec<Series> = Vec::new();
    for r in rows {
        let point = (r.report.ms_per_step, r.report.mean_rel_error);
        match series.iter_mut().find(|s| s.name == r.report.method.name()) {
            Some(s) => s.points.push(point),
            None => series.push(Series {
                name: r.report.method.to_string(),
                points: vec![point],
                line: false,
                reference: r.report.method.is_full(),
                color: Some(r.report.method.color()),
                ..Default::default()
            }),
        }
    }
    let full = rows
        .iter()
        .find(|r| r.report.method == Method::Full)
        .map(|r| format!(" (full: {:.1} ms/step)", r.report.ms_per_step))
        .unwrap_or_default();
    let mut front: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.pareto && r.report.mean_rel_error > 0.0)
        .map(|r| (r.report.ms_per_step, r.report.mean_rel_error))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    series.push(Series {
        name: "Pareto front".into(),
        points: front,
        line: true,
        color: Some(crate::plot::GUIDE),
        ..Default::default()
    });
    let p = Plot {
        title: format!("{scene}: error against cost, every method and size{full}"),
        x_label: "ms per step (mean)".into(),
        y_label: "mean relative error".into(),
        x_scale: Scale::Log,
        y_scale: Scale::Log,
    };
    crate::plot::svg(&p, &series)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Options of one small sweep; each test changes what it is about.
    fn options() -> BenchOptions {
        BenchOptions {
            out: PathBuf::new(),
            cache: PathBuf::new(),
            trajectory: 0,
            repeats: 1,
            pca_dims: vec![4],
            latent_dims: vec![2],
            tolerances: vec![0.1],
            complement_dims: Vec::new(),
        }
    }

    /// `bench.json` holds `null`, not 0, for what a full-space row has none of, as
    /// `report.json` does.
    #[test]
    fn bench_json_holds_null_for_what_full_space_has_none_of() {
        let out = std::env::temp_dir().join(format!("bench-json-{}", std::process::id()));
        std::fs::create_dir_all(&out).unwrap();
        let mut full = row(10.0, 0.0);
        full.report.method = Method::Full;
        write(&out, "s", &[full, row(0.1, 0.02)]).unwrap();
        let text = std::fs::read_to_string(out.join("bench.json")).unwrap();
        let _ = std::fs::remove_dir_all(&out);
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        for key in crate::run::NOT_OF_FULL_SPACE {
            assert!(json[0][key].is_null(), "{key}: {text}");
            assert!(json[1][key].is_number(), "{key}: {text}");
        }
    }

    /// Variants more than 20 % off are named under the table, the front drawn as it is.
    #[test]
    fn variants_far_off_the_full_trajectory_are_named() {
        let mut far = row(0.001, 0.67);
        far.variant = "pca-cubature k=2".into();
        far.pareto = true;
        let mut near = row(0.5, 0.02);
        near.variant = "pca-cubature k=40".into();
        let table = markdown(&[far, near.clone()]);
        assert!(
            table.contains("more than 20 % off the full trajectory on average"),
            "{table}"
        );
        assert!(
            table.contains("variant): pca-cubature k=2 (67 %);"),
            "{table}"
        );
        assert!(!markdown(&[near]).contains("off the full trajectory on average"));
    }

    fn row(ms: f64, err: f64) -> BenchRow {
        BenchRow {
            variant: String::new(),
            report: MethodReport {
                method: Method::Pca,
                dim: 1,
                cubature_elements: 1,
                latent: None,
                ms_per_step: ms,
                ms_min: ms,
                ms_median: ms,
                ms_max: ms,
                timed_runs: 1,
                hz: 1e3 / ms,
                speedup: None,
                mean_rel_error: err,
                max_rel_error: err,
                trajectory_error: err,
                max_vertex_error: err,
                iterations: 1.0,
                subspace_error: 0.0,
                projected_strain: None,
                step_error: 0.0,
                decode_ms: 0.0,
                elastic_ms: 0.0,
                vjp_ms: 0.0,
                precond_ms: 0.0,
                frame_errors: vec![err],
                subspace_frame_errors: Vec::new(),
                step_frame_errors: Vec::new(),
                training_distance: 0.0,
                training_distance_time: 0.0,
                training_seconds: 0.0,
                step_restarts: 0,
                failure: None,
                machine_gfma: None,
                restart: None,
                restart_failed: None,
                compression: None,
                buckling: None,
                scene_warnings: Vec::new(),
                basis_cap: None,
            },
            offline_seconds: 0.0,
            pareto: false,
        }
    }

    /// A sweep that would time nothing, or leave out a size or tolerance it names, is refused
    /// naming the value and the range that works; the defaults pass.
    #[test]
    fn a_sweep_that_would_leave_out_what_it_names_is_refused() {
        let sizes = Some((10, 12));
        for (opts, says) in [
            (
                BenchOptions {
                    repeats: 0,
                    ..options()
                },
                "`--repeats`",
            ),
            (
                BenchOptions {
                    tolerances: vec![0.05, -1.0],
                    ..options()
                },
                "tolerance -1",
            ),
            (
                BenchOptions {
                    tolerances: vec![f64::NAN],
                    ..options()
                },
                "tolerance NaN",
            ),
            (
                BenchOptions {
                    pca_dims: vec![4, 11],
                    ..options()
                },
                "1 to 10",
            ),
            (
                BenchOptions {
                    pca_dims: vec![0],
                    ..options()
                },
                "PCA dimension 0",
            ),
            (
                BenchOptions {
                    latent_dims: vec![13],
                    ..options()
                },
                "1 to 12",
            ),
            (
                BenchOptions {
                    complement_dims: vec![8, 1000],
                    ..options()
                },
                "count 1000",
            ),
        ] {
            let err = check_options(&opts, sizes).unwrap_err().to_string();
            assert!(err.contains(says), "{err}");
        }
        check_options(&options(), sizes).unwrap();
        let at_the_limits = BenchOptions {
            pca_dims: vec![10],
            latent_dims: vec![12],
            ..options()
        };
        check_options(&at_the_limits, sizes).unwrap();
        // Before the basis is known only the repeats and tolerances are checked.
        check_options(
            &BenchOptions {
                pca_dims: vec![99],
                ..options()
            },
            None,
        )
        .unwrap();
    }

    /// `--complement-dims` adds both neural methods per count, each with its scene's
    /// `[reduced] complement_directions` set, after the latent sizes.
    #[test]
    fn complement_counts_become_neural_variants() {
        let scene = Scene::builtin();
        let opts = BenchOptions {
            complement_dims: vec![8, 0, 8],
            ..options()
        };
        let found: Vec<(String, Option<usize>)> = variants(&scene, 10, 10, &opts)
            .into_iter()
            .map(|v| (v.label, v.scene.reduced.complement_directions))
            .filter(|(label, _)| label.contains(" c=") && !label.contains(" d="))
            .collect();
        let want = [
            ("neural c=0", Some(0)),
            ("neural-cubature c=0", Some(0)),
            ("neural c=8", Some(8)),
            ("neural-cubature c=8", Some(8)),
        ];
        assert_eq!(
            found,
            want.map(|(l, c)| (l.to_string(), c)).to_vec(),
            "sorted, without repeats"
        );
        let none = BenchOptions {
            complement_dims: Vec::new(),
            ..opts
        };
        assert!(
            variants(&scene, 10, 10, &none)
                .iter()
                .all(|v| !v.label.contains(" c=") || v.label.contains(" d="))
        );
    }

    /// The scene's own `pca-cubature` (its k, its tolerance) is a row, once, and so is each
    /// cubature method's own tolerance with the scene's solver, beside its Newton variant.
    #[test]
    fn the_scenes_own_pca_cubature_is_a_row() {
        let scene = Scene::builtin();
        let own = scene.cubature.tolerance;
        let mut opts = BenchOptions {
            pca_dims: vec![4, 10],
            ..options()
        };
        let own_rows = |opts: &BenchOptions| {
            variants(&scene, 10, 10, opts)
                .into_iter()
                .filter(|v| {
                    let at_own_k = v.method == Method::PcaCubature
                        && v.solver.is_none()
                        && v.scene.cubature.tolerance == own
                        && v.scene.pca.dimension == Some(10);
                    at_own_k || v.label == format!("pca-cubature tol={own}")
                })
                .count()
        };
        assert_eq!(own_rows(&opts), 1, "as `pca-cubature k=10 tol={own}`");
        let labels: Vec<String> = variants(&scene, 10, 10, &opts)
            .into_iter()
            .map(|v| v.label)
            .collect();
        assert!(
            labels.contains(&format!("pca-cubature k=10 tol={own}"))
                && labels.contains(&"pca-cubature k=4".to_string()),
            "{labels:?}"
        );
        opts.tolerances = vec![0.1, own];
        assert_eq!(own_rows(&opts), 1, "as `pca-cubature tol={own}`");
        // Neither the k sweep nor the tolerances at the scene's own: the own tolerance still
        // runs with the scene's solver for both methods, beside its Newton variant.
        opts.tolerances = vec![0.1];
        opts.pca_dims = vec![4];
        let own_neural = scene.cubature.for_neural().tolerance;
        let labels: Vec<String> = variants(&scene, 10, 10, &opts)
            .into_iter()
            .map(|v| v.label)
            .collect();
        for (method, tol) in [("pca-cubature", own), ("neural-cubature", own_neural)] {
            for label in [
                format!("{method} tol={tol}"),
                format!("{method} tol={tol} newton"),
            ] {
                assert_eq!(
                    labels.iter().filter(|l| **l == label).count(),
                    1,
                    "{label}: {labels:?}"
                );
            }
        }
    }

    /// Without `--latent-dims` the sweep takes half, once and twice the scene's latent dimension:
    /// `[autoencoder] latent_dim` when set, else the pipeline's default for the basis's k (it
    /// took AutoDef's fixed 6 until 2026-12-02).
    #[test]
    fn latent_sizes_default_to_the_scenes_own() {
        let mut scene = Scene::builtin();
        scene.autoencoder.latent_dim = None;
        scene.autoencoder.latent_dims = None;
        let neural = |scene: &Scene| -> Vec<String> {
            let opts = BenchOptions {
                latent_dims: Vec::new(),
                ..options()
            };
            variants(scene, 30, 40, &opts)
                .into_iter()
                .filter(|v| v.method == Method::Neural)
                .map(|v| v.label)
                .collect()
        };
        let d = crate::pipeline::default_latent_dim(40);
        assert_eq!(d, 20);
        assert_eq!(
            neural(&scene),
            ["neural d=10", "neural d=20", "neural d=40"]
        );
        scene.autoencoder.latent_dim = Some(8);
        assert_eq!(neural(&scene), ["neural d=4", "neural d=8", "neural d=16"]);
    }

    /// Each swept latent dimension also runs `neural-cubature` without complement directions,
    /// unless the scene already has none.
    #[test]
    fn latent_sizes_also_run_without_complement_directions() {
        let mut scene = Scene::builtin();
        let opts = BenchOptions {
            latent_dims: vec![3, 2],
            ..options()
        };
        let bare = |scene: &Scene| -> Vec<(String, Option<usize>)> {
            variants(scene, 10, 10, &opts)
                .into_iter()
                .filter(|v| v.label.ends_with(" c=0"))
                .map(|v| (v.label, v.scene.reduced.complement_directions))
                .collect()
        };
        assert_eq!(
            bare(&scene),
            [
                ("neural-cubature d=2 c=0".to_string(), Some(0)),
                ("neural-cubature d=3 c=0".to_string(), Some(0)),
            ]
        );
        scene.reduced.complement_directions = Some(0);
        assert!(bare(&scene).is_empty(), "the plain d rows are already bare");
    }

    #[test]
    fn pareto_front_keeps_only_undominated_rows() {
        let mut rows = vec![
            row(10.0, 0.0),
            row(1.0, 0.1),
            row(2.0, 0.2), // dominated by (1.0, 0.1)
            row(0.5, 0.3),
            row(0.5, 0.4), // dominated by (0.5, 0.3)
        ];
        mark_pareto(&mut rows);
        let marks: Vec<bool> = rows.iter().map(|r| r.pareto).collect();
        assert_eq!(marks, [true, true, false, true, false]);
    }
}
