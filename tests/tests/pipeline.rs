//! The cached pipeline: skipping unchanged stages, recomputing only what changed, shards, and an
//! end-to-end run of a tiny scene.

use pipeline::pipeline::{Pipeline, StageSummary};
use pipeline::run::{RunOptions, run};
use pipeline::simulate::Method;
use pipeline::stage::Stage;
use tests::{TINY, no_progress, scene, scratch_dir};

/// `methods` on test trajectory 0, writing no frames under `out`: their report rows.
fn run_methods(
    p: &mut Pipeline<'_>,
    out: &std::path::Path,
    methods: &[Method],
) -> Vec<pipeline::run::MethodReport> {
    let opts = RunOptions {
        out: out.to_path_buf(),
        every: 0,
        methods: methods.to_vec(),
        trajectory: 0,
    };
    run(p, &opts, &no_progress, &mut |_, _, _| {}).unwrap()
}

fn stages(p: &Pipeline<'_>) -> Vec<(Stage, bool)> {
    p.outcomes.iter().map(|o| (o.stage, o.cached)).collect()
}

#[test]
fn unchanged_scenes_do_no_work_and_pca_changes_reuse_snapshots() {
    let cache = scratch_dir("pipeline-cache");
    let s = scene(TINY);
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let start = std::time::Instant::now();
    let first = p.pca(&no_progress).unwrap();
    let wall = start.elapsed().as_secs_f64();
    assert_eq!(stages(&p), [(Stage::Snapshots, false), (Stage::Pca, false)]);
    // Each stage reports its own time: the PCA's excludes the snapshots it had to compute first.
    let own: f64 = p.outcomes.iter().map(|o| o.seconds).sum();
    assert!(
        own <= wall && p.outcomes[0].seconds > 0.0,
        "stage seconds {:?} add up to more than the {wall} s they took",
        p.outcomes.iter().map(|o| o.seconds).collect::<Vec<_>>()
    );
    // Second run: nothing is computed, the basis is identical.
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let again = p.pca(&no_progress).unwrap();
    assert_eq!(stages(&p), [(Stage::Pca, true)]);
    assert_eq!(first, again);
    // Changing only [pca]: the snapshots are reused, the basis recomputed.
    let s2 = scene(&TINY.replace("dimension = 6", "dimension = 4"));
    let mut p = Pipeline::new(&s2, &cache).unwrap();
    let fit = p.pca(&no_progress).unwrap();
    assert_eq!(fit.chosen_k(), 4);
    assert_eq!(stages(&p), [(Stage::Snapshots, true), (Stage::Pca, false)]);
    // Changing the physics invalidates both.
    let s3 = scene(&TINY.replace("youngs_modulus = 1.0e5", "youngs_modulus = 2.0e5"));
    let mut p = Pipeline::new(&s3, &cache).unwrap();
    p.pca(&no_progress).unwrap();
    assert_eq!(stages(&p), [(Stage::Snapshots, false), (Stage::Pca, false)]);
}

/// `[cubature] neural_tolerance` refits the neural rule only, to that tolerance; the PCA rule
/// keeps its cached artifact.
#[test]
fn the_neural_tolerance_refits_the_neural_rule_only() {
    let cache = scratch_dir("pipeline-neural-tolerance");
    let s = scene(&format!("{TINY}[cubature]\ntolerance = 0.2\n"));
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let linear = p.cubature(&no_progress).unwrap();
    let loose = p.cubature_neural(&no_progress).unwrap();
    assert!(
        loose.rule.training_error <= 0.2,
        "{}",
        loose.rule.training_error
    );
    let s2 = scene(&format!(
        "{TINY}[cubature]\ntolerance = 0.2\nneural_tolerance = 0.01\n"
    ));
    let mut p = Pipeline::new(&s2, &cache).unwrap();
    assert_eq!(p.cubature(&no_progress).unwrap().rule, linear.rule);
    let tight = p.cubature_neural(&no_progress).unwrap();
    let computed: Vec<(Stage, bool)> = stages(&p)
        .into_iter()
        .filter(|(stage, _)| matches!(stage, Stage::Cubature | Stage::CubatureNeural))
        .collect();
    assert_eq!(
        computed,
        [(Stage::Cubature, true), (Stage::CubatureNeural, false)]
    );
    // The rule fitted in the decoder's tangent, whichever rule the stage kept.
    let fitted = |c: &pipeline::pipeline::FittedCubature| {
        c.validation
            .as_ref()
            .filter(|v| v.pca_kept)
            .map_or(c.rule.len(), |v| v.tangent_elements)
    };
    if tight.validation.as_ref().is_none_or(|v| !v.pca_kept) {
        assert!(
            tight.rule.training_error <= 0.01 || !tight.rule.tolerance_met,
            "{:?}",
            tight.rule
        );
    }
    assert!(fitted(&tight) > fitted(&loose));
}

/// The neural methods' rule is the one fitted in the decoder's tangent unless the PCA
/// subspace's follows training schedules clearly closer; the stage keeps how both did.
#[test]
fn the_neural_rule_is_kept_by_how_it_follows_training_schedules() {
    let cache = scratch_dir("pipeline-neural-rule-validation");
    let s = scene(TINY);
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let pca = p.cubature(&no_progress).unwrap();
    let kept = p.cubature_neural(&no_progress).unwrap();
    let v = kept
        .validation
        .clone()
        .expect("the two rules ran on training schedules");
    // The tiny family's four schedules, each from rest and whole.
    assert_eq!(v.schedules, [0, 1, 2, 3]);
    assert_eq!((v.tangent_errors.len(), v.pca_errors.len()), (4, 4));
    assert!(
        v.tangent_errors
            .iter()
            .chain(&v.pca_errors)
            .all(|e| e.is_finite() && *e > 0.0 && *e < 1.0),
        "{v:?}"
    );
    assert_eq!(
        v.pca_kept,
        pipeline::pipeline::pca_rule_clearly_closer(&v.tangent_errors, &v.pca_errors)
    );
    assert_eq!(v.pca_kept, kept.rule == pca.rule, "{v:?}");
    assert_eq!(v.pca_elements, pca.rule.len());
    let line = kept.summary();
    assert!(line.contains("training schedules"), "{line}");
    // A PCA rule closer on average and not kept says why.
    let (tangent_mean, pca_mean) = v.means();
    assert_eq!(
        line.contains("not clearly"),
        !v.pca_kept && pca_mean < tangent_mean,
        "{line}"
    );
}

#[test]
fn a_corrupt_artifact_is_recomputed_not_used() {
    let cache = scratch_dir("pipeline-corrupt");
    let s = scene(TINY);
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let good = p.snapshots(&no_progress).unwrap();
    let path = p.outcomes[0].path.clone();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let again = p.snapshots(&no_progress).unwrap();
    assert_eq!(stages(&p), [(Stage::Snapshots, false)]);
    assert_eq!(good, again);
}

#[test]
fn merged_shards_equal_the_unsharded_snapshots() {
    let s = scene(TINY);
    let cache = scratch_dir("pipeline-shards");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    for i in 0..3 {
        p.snapshot_shard(i, 3, &no_progress).unwrap();
    }
    let merged = p.merge_shards(3).unwrap();
    let cache2 = scratch_dir("pipeline-unsharded");
    let mut q = Pipeline::new(&s, &cache2).unwrap();
    let whole = q.snapshots(&no_progress).unwrap();
    assert_eq!(merged, whole);
    assert_eq!(whole.num_frames(), 4 * 8);
    // Missing shards are named.
    let cache3 = scratch_dir("pipeline-missing-shard");
    let mut r = Pipeline::new(&s, &cache3).unwrap();
    r.snapshot_shard(0, 2, &no_progress).unwrap();
    let err = format!("{:#}", r.merge_shards(2).unwrap_err());
    assert!(err.contains("shard 1/2"), "{err}");
    // One command to run, and the I/O error said once.
    assert_eq!(err.matches("`cargo xtask snapshots").count(), 1, "{err}");
    assert_eq!(err.matches("(os error").count(), 1, "{err}");
}

#[test]
fn a_tiny_scene_runs_end_to_end() {
    let s = scene(TINY);
    let out = scratch_dir("pipeline-run");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let opts = RunOptions {
        out: out.clone(),
        every: 4,
        methods: vec![
            Method::Full,
            Method::Pca,
            Method::PcaCubature,
            Method::Neural,
            Method::NeuralCubature,
        ],
        trajectory: 0,
    };
    let rows = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    assert_eq!(rows.len(), 5);
    let (full, pca, cub) = (&rows[0], &rows[1], &rows[2]);
    // TINY's 6 PCA columns and the positions of the fall under gravity they miss.
    let k = p.pca(&no_progress).unwrap().basis.k();
    assert!(k > 6, "{k}");
    for neural in &rows[3..] {
        // d = 2 latent coordinates (TINY's) and the linear directions chosen by default
        // (gravity's onset, the complement the data asks for), within the k PCA coefficients.
        assert!(neural.dim > 2 && neural.dim <= k, "{neural:?}");
        assert!(neural.mean_rel_error.is_finite(), "{neural:?}");
    }
    assert!(rows[4].cubature_elements < full.cubature_elements);
    assert_eq!(cub.method, Method::PcaCubature);
    assert!(cub.cubature_elements < full.cubature_elements, "{cub:?}");
    assert!(
        cub.mean_rel_error.is_finite() && cub.max_rel_error < 1.0,
        "{cub:?}"
    );
    assert_eq!(full.method, Method::Full);
    assert_eq!(full.mean_rel_error, 0.0);
    assert_eq!(pca.dim, k);
    assert!(pca.mean_rel_error.is_finite() && pca.mean_rel_error > 0.0);
    assert!(pca.max_rel_error < 1.0, "{pca:?}");
    assert!(pca.ms_per_step > 0.0 && full.ms_per_step > 0.0);
    // The subspace error frame by frame covers the trajectory's frames and averages to the
    // reported subspace error; full space has none.
    assert!(full.subspace_frame_errors.is_empty());
    for r in &rows[1..] {
        let f = &r.subspace_frame_errors;
        assert_eq!(f.len(), r.frame_errors.len(), "{}", r.method);
        let mean = f.iter().sum::<f64>() / f.len() as f64;
        assert!(
            mean > 0.0 && (mean - r.subspace_error).abs() <= 1e-12 * mean,
            "{}: {mean} vs {}",
            r.method,
            r.subspace_error
        );
    }
    // One step from the reference: the first starts from rest like the trajectory, so the two
    // agree there to rounding; later steps start from the reference, not from the method's own
    // (drifting) states.
    assert!(full.step_frame_errors.is_empty());
    for r in &rows[1..] {
        let (f, st) = (&r.frame_errors, &r.step_frame_errors);
        assert_eq!(st.len(), f.len(), "{}", r.method);
        assert!(
            (st[0] - f[0]).abs() <= 1e-9 * f[0],
            "{}: first step {} vs {}",
            r.method,
            st[0],
            f[0]
        );
        assert!(
            st[1..] != f[1..],
            "{}: one-step errors repeat the trajectory's",
            r.method
        );
        let mean = st.iter().sum::<f64>() / st.len() as f64;
        assert!((mean - r.step_error).abs() <= 1e-12 * mean, "{}", r.method);
    }
    let csv = std::fs::read_to_string(out.join("errors.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "frame,time,pca,pca one-step,pca-cubature,pca-cubature one-step,neural,neural one-step,\
         neural-cubature,neural-cubature one-step"
    );
    assert_eq!(lines.count(), rows[1].frame_errors.len());
    let svg = std::fs::read_to_string(out.join("errors.svg")).unwrap();
    assert_eq!(svg.matches("<polyline").count(), 8, "{svg}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    // What was run rides with the rows: a script comparing runs needs no other file.
    assert_eq!(report["format"], pipeline::run::REPORT_FORMAT);
    assert_eq!(report["version"], pipeline::run::REPORT_VERSION);
    assert_eq!(report["trajectory"], 0);
    assert!(report["written"].as_str().is_some_and(|w| w.ends_with('Z')));
    let stages = report["stages"].as_array().unwrap();
    assert!(
        stages
            .iter()
            .any(|s| s["stage"] == "pca" && s["summary"].as_str().is_some_and(|t| !t.is_empty())),
        "{stages:?}"
    );
    for key in [
        "method",
        "dim",
        "cubature_elements",
        "ms_per_step",
        "hz",
        "speedup",
        "mean_rel_error",
        "max_rel_error",
        "max_vertex_error",
        "subspace_frame_errors",
        "step_error",
        "step_frame_errors",
    ] {
        assert!(
            report["methods"][1].get(key).is_some(),
            "report.json lacks {key}"
        );
    }
    // What a full-space row has no figure of is null there, a number on a reduced row.
    assert_eq!(report["methods"][0]["method"], "full");
    for key in pipeline::run::NOT_OF_FULL_SPACE {
        let null = serde_json::Value::Null;
        assert_eq!(report["methods"][0].get(key), Some(&null), "full: {key}");
        assert!(report["methods"][1][key].is_f64(), "{key}");
    }
    assert!(report["methods"][0]["mean_rel_error"].is_f64());
    assert!(out.join("report.md").is_file());
    for m in ["full", "pca", "pca-cubature", "neural", "neural-cubature"] {
        let pvd = std::fs::read_to_string(out.join(m).join("series.pvd")).unwrap();
        // Frames 0, 4, 8 and the last (12).
        assert_eq!(pvd.matches("<DataSet").count(), 4, "{m}: {pvd}");
    }
}

/// `[reduced] onset_directions` reaches the neural methods: with gravity, their dimension grows
/// by the directions kept (here both: 2 latent coordinates of 6 coefficients leave room), and
/// the trajectory stays finite.
#[test]
fn onset_directions_reach_the_neural_methods() {
    let text = format!(
        "{TINY}[gravity]\nacceleration = [0.0, -9.81, 0.0]\n[reduced]\nonset_directions = 2\n\
         complement_directions = 0\n"
    );
    let s = scene(&text);
    let out = scratch_dir("pipeline-onset");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let rows = run_methods(&mut p, &out, &[Method::Neural, Method::NeuralCubature]);
    for r in &rows {
        assert_eq!(r.dim, 4, "{r:?}");
        assert!(r.failure.is_none() && r.mean_rel_error.is_finite(), "{r:?}");
        // No full-space solver ran beside them: no speed-up, and a dash in the table.
        assert_eq!(r.speedup, None, "{r:?}");
    }
    let table = pipeline::run::markdown(&rows);
    assert!(
        table.lines().skip(2).all(|l| l.contains("| — |")),
        "{table}"
    );
    // A method named twice is refused before anything is measured.
    let opts = RunOptions {
        out: out.clone(),
        every: 0,
        methods: vec![Method::Pca, Method::Neural, Method::Pca],
        trajectory: 0,
    };
    let err = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap_err();
    assert_eq!(
        err.to_string(),
        "the methods name pca twice; name each method once"
    );
    // So is a run of no method, which would report nothing.
    let none = RunOptions {
        methods: Vec::new(),
        ..opts
    };
    let err = run(&mut p, &none, &no_progress, &mut |_, _, _| {}).unwrap_err();
    assert!(err.to_string().contains("name at least one"), "{err}");
}

/// Without `[reduced] onset_directions` and `complement_directions` the neural methods run
/// exactly as with the counts the pipeline chose written in the scene: the default number of
/// onset directions under gravity and none without, and the complement directions that bring
/// the autoencoder's loss on the snapshots within the PCA basis's.
#[test]
fn linear_directions_default_to_the_counts_chosen() {
    let s = scene(TINY);
    let out = scratch_dir("pipeline-linear-defaults");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    assert_eq!(p.onset_directions(), latent_sim::DEFAULT_ONSET_DIRECTIONS);
    let c = p.complement(&no_progress).unwrap();
    let count = c.default_count();
    // The snapshots' mass-norm energy and what the basis leaves out of it, recomputed here.
    let snaps = p.snapshots(&no_progress).unwrap();
    let fit = p.pca(&no_progress).unwrap();
    let mass = fit.basis.mass().expect("a mass-orthonormal basis");
    let mut q = vec![0.0; fit.basis.k()];
    let (mut energy, mut kept) = (0.0, 0.0);
    for u in snaps.data.chunks_exact(snaps.dim) {
        energy += u.iter().zip(mass).map(|(x, m)| m * x * x).sum::<f64>();
        fit.basis.project(u, &mut q);
        kept += q.iter().map(|x| x * x).sum::<f64>();
    }
    assert!((c.snapshot_energy - energy).abs() <= 1e-12 * energy);
    assert!((c.pca_lost_energy - (energy - kept)).abs() <= 1e-9 * energy);
    let allowed = (energy - kept).max(1e-14 * energy);
    let missed = |n: usize| c.singular_values[n..].iter().map(|r| r * r).sum::<f64>();
    let new = fit.basis.k() - 2;
    assert!(
        count <= new,
        "{count} directions, {new} can be new beside d = 2"
    );
    assert!(count == new || missed(count) <= allowed, "{count}");
    assert!(
        count == 0 || missed(count - 1) > allowed,
        "{count} is not the fewest"
    );
    let line = p.linear_directions_summary(&no_progress).unwrap();
    let responses = match fit.responses {
        0 => String::new(),
        r => format!(", the PCA basis's {r} patch responses"),
    };
    let most = (2 + 2 + count + fit.responses).min(fit.basis.k());
    assert_eq!(
        line,
        format!(
            "neural methods: d = 2 latent coordinates, 2 gravity-onset directions (the default \
             under gravity), {count} complement directions (what the data asks for, see stage \
             complement){responses}: at most {most} coordinates, fewer where a direction lies in \
             the span of the decoder and the others (the table's dim)"
        )
    );
    let chosen = run_methods(&mut p, &out, &[Method::Neural, Method::NeuralCubature]);
    for r in &chosen {
        assert!(r.dim <= most, "{} coordinates, at most {most} said", r.dim);
    }
    let written = scene(&format!(
        "{TINY}[reduced]\nonset_directions = {}\ncomplement_directions = {count}\n",
        latent_sim::DEFAULT_ONSET_DIRECTIONS
    ));
    let mut p = Pipeline::new(&written, out.join("cache")).unwrap();
    let named = run_methods(&mut p, &out, &[Method::Neural, Method::NeuralCubature]);
    for (a, b) in chosen.iter().zip(&named) {
        assert_eq!((a.dim, &a.frame_errors), (b.dim, &b.frame_errors));
    }
    let weightless = scene(&format!(
        "{TINY}[gravity]\nacceleration = [0.0, 0.0, 0.0]\n"
    ));
    let p = Pipeline::new(&weightless, out.join("cache")).unwrap();
    assert_eq!(p.onset_directions(), 0);
}

/// `[reduced] complement_directions`: stage `complement` is the SVD of the autoencoder's
/// residuals over the snapshots (orthonormal directions, singular values in order whose squares
/// sum to ‖Q − decode(encode(Q))‖²_F), all its directions complete every reconstruction exactly,
/// and the neural methods get the directions kept beside their latent coordinates, which brings
/// them closer to the reference frames. Asking for more directions than there are is an error
/// naming the scene and the field.
#[test]
fn complement_directions_complete_the_autoencoder() {
    // Six PCA columns and nothing appended.
    let tiny = TINY.replace("dimension = 6", "dimension = 6\ngravity_directions = 0");
    let text = format!("{tiny}[reduced]\ncomplement_directions = 2\nonset_directions = 0\n");
    let s = scene(&text);
    let out = scratch_dir("pipeline-complement");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let c = p.complement(&no_progress).unwrap();
    let (k, r) = (c.k, c.singular_values.len());
    assert_eq!((k, r), (6, 6), "k = 6 coefficients, 32 snapshots");
    let cols: Vec<&[f64]> = c.directions.chunks_exact(k).collect();
    for i in 0..r {
        for j in 0..r {
            let dot: f64 = cols[i].iter().zip(cols[j]).map(|(a, b)| a * b).sum();
            let want = if i == j { 1.0 } else { 0.0 };
            assert!((dot - want).abs() <= 1e-12, "columns {i}, {j}: {dot}");
        }
    }
    assert!(c.singular_values.windows(2).all(|w| w[0] >= w[1]));

    let snaps = p.snapshots(&no_progress).unwrap();
    let fit = p.pca(&no_progress).unwrap();
    let trained = p.train(&no_progress).unwrap();
    let mut ws = trained.model.workspace();
    let (mut q, mut qh) = (vec![0.0; k], vec![0.0; k]);
    let mut residual = 0.0;
    for u in snaps.data.chunks_exact(snaps.dim) {
        fit.basis.project(u, &mut q);
        trained.model.reconstruct(&q, &mut qh, &mut ws);
        residual += q.iter().zip(&qh).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        pipeline::pipeline::complete(&c.directions, &q, &mut qh);
        let size = q.iter().map(|a| a * a).sum::<f64>().sqrt();
        for (a, b) in q.iter().zip(&qh) {
            assert!((a - b).abs() <= 1e-12 * size, "{a} against {b}");
        }
    }
    let sigma2: f64 = c.singular_values.iter().map(|s| s * s).sum();
    assert!(
        (residual - sigma2).abs() <= 1e-9 * residual,
        "{residual:e} against {sigma2:e}"
    );

    let with = run_methods(&mut p, &out, &[Method::Neural]);
    let plain = scene(&format!(
        "{TINY}[reduced]\ncomplement_directions = 0\nonset_directions = 0\n"
    ));
    let mut p0 = Pipeline::new(&plain, out.join("cache")).unwrap();
    let without = run_methods(&mut p0, &out, &[Method::Neural]);
    let (with, without) = (&with[0], &without[0]);
    assert!(
        with.failure.is_none() && with.mean_rel_error.is_finite(),
        "{with:?}"
    );
    assert_eq!((without.dim, with.dim), (2, 4), "both directions are new");
    assert!(
        with.subspace_error < 0.9 * without.subspace_error,
        "{} against {}",
        with.subspace_error,
        without.subspace_error
    );

    let too_many = scene(&format!("{tiny}[reduced]\ncomplement_directions = 7\n"));
    let mut p = Pipeline::new(&too_many, out.join("cache")).unwrap();
    let err = p.complement_columns(&no_progress).unwrap_err().to_string();
    assert!(
        err.contains("tiny.toml") && err.contains("reduced.complement_directions = 7"),
        "{err}"
    );
}

/// Without `[autoencoder] latent_dim` the latent dimension is half the PCA dimension within
/// [6, k], without `hidden` the two hidden layers are k wide within [64, 200], and the stage
/// says so; a latent dimension above k is an error that names the field and the values that
/// work, before any training.
#[test]
fn the_latent_dimension_defaults_from_the_pca_dimension_and_never_exceeds_it() {
    let defaulted = TINY
        .replace("dimension = 6", "dimension = 5\ngravity_directions = 0")
        .replace("latent_dim = 2\n", "epochs = 20\n")
        .replace("epochs = 150\n", "")
        .replace("hidden = [16, 16]\n", "");
    let s = scene(&defaulted);
    let mut p = Pipeline::new(&s, scratch_dir("pipeline-latent-default")).unwrap();
    let trained = p.train(&no_progress).unwrap();
    assert_eq!((trained.pca_k, trained.latent_dim), (5, 5));
    assert_eq!(pipeline::pipeline::default_latent_dim(5), 5);
    assert_eq!(pipeline::pipeline::default_latent_dim(22), 11);
    assert_eq!(pipeline::pipeline::default_latent_dim(9), 6);
    assert_eq!(trained.model.hidden_widths(), [64, 64]);
    let line = &p.outcomes.last().unwrap().summary;
    assert!(line.starts_with("d = 5 of k = 5 (the default"), "{line}");
    assert!(
        line.contains("hidden layers [64, 64] (the default, k within [64, 200]"),
        "{line}"
    );
    // With d = k the start (the linear skip's truncation) reproduces the coefficients exactly:
    // no epoch comes closer on the schedule held out, the start is kept and nothing is trained
    // again (before stop 77 the weights one Adam step off it were, and then trained again).
    assert_eq!(trained.best_epoch, 0, "{line}");
    assert_eq!(trained.retrained_epochs, None, "{line}");
    assert!(line.contains("none closer than the start"), "{line}");
    let snaps = p.snapshots(&no_progress).unwrap();
    let fit = p.pca(&no_progress).unwrap();
    let basis = &fit.basis;
    let mut ws = trained.model.workspace();
    let (mut q, mut qh) = (vec![0.0; basis.k()], vec![0.0; basis.k()]);
    let mut rec = vec![0.0; snaps.dim];
    let mut worst = 0.0f64;
    for u in snaps.data.chunks_exact(snaps.dim) {
        basis.project(u, &mut q);
        trained.model.reconstruct(&q, &mut qh, &mut ws);
        basis.reconstruct(&qh, &mut rec);
        for (a, b) in u.chunks_exact(3).zip(rec.chunks_exact(3)) {
            let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
            worst = worst.max(d.sqrt());
        }
    }
    assert!(
        (worst - trained.max_vertex_error).abs() <= 1e-12 * worst,
        "{worst} against {}",
        trained.max_vertex_error
    );

    let too_wide = TINY
        .replace("latent_dim = 2", "latent_dim = 8")
        .replace("dimension = 6", "dimension = 6\ngravity_directions = 0");
    let s = scene(&too_wide);
    let mut p = Pipeline::new(&s, scratch_dir("pipeline-latent-too-wide")).unwrap();
    let e = p.train(&no_progress).unwrap_err().to_string();
    assert!(
        e.contains("`autoencoder.latent_dim` = 8") && e.contains("at most 6"),
        "{e}"
    );
}

/// When every training schedule fails at its first step, the snapshots stage says so, with the
/// solver's error and what to change (a schedule failing later only ends that schedule: see
/// fem-core's `a_schedule_whose_solve_fails_keeps_its_earlier_frames`).
#[test]
fn snapshots_that_never_start_are_an_error_that_says_what_to_change() {
    // The training family's own tolerance too: by default it is the looser 10⁻².
    let s = scene(
        &TINY
            .replace(
                "tolerance = 1.0e-8",
                "tolerance = 1.0e-15\nmax_iterations = 1",
            )
            .replace("[training]\n", "[training]\ntolerance = 1.0e-15\n"),
    );
    let cache = scratch_dir("pipeline-no-frames");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let err = format!("{:#}", p.snapshots(&no_progress).unwrap_err());
    for part in [
        "tiny.toml",
        "every training schedule",
        "did not converge",
        "[solver] max_iterations",
    ] {
        assert!(err.contains(part), "{part:?} missing from: {err}");
    }
}

/// A held-out test whose full-space solve fails partway is compared over the frames it reached:
/// the reference keeps them and says why it stopped, and every method runs that many frames.
/// (A drag two to three lengths away with a cap of 2 iterations, 8 in the retry, which goes on
/// from where the first solver stopped.)
#[test]
fn a_reference_that_fails_partway_is_compared_over_the_frames_it_reached() {
    let s = scene(
        &TINY
            .replace(
                "tolerance = 1.0e-8",
                "tolerance = 1.0e-8\nmax_iterations = 2",
            )
            .replace(
                "[test]\nframes_per_schedule = 12",
                "[test]\nframes_per_schedule = 20\noffset = [2.0, 3.0]\nstiffness = [5.0, 10.0]",
            ),
    );
    let cache = scratch_dir("pipeline-reference-stops");
    let mut p = Pipeline::new(&s, &cache).unwrap();
    let r = p.reference(0, &no_progress).unwrap();
    let e = r
        .stopped
        .as_deref()
        .expect("the capped solver stops the test drag");
    assert!(e.contains("did not converge"), "{e}");
    assert!(
        !r.frames.is_empty() && r.frames.len() < 20,
        "{}",
        r.frames.len()
    );
    let out = scratch_dir("pipeline-reference-stops-out");
    let rows = run_methods(&mut p, &out, &[Method::Full, Method::Pca]);
    assert_eq!(rows[1].frame_errors.len(), r.frames.len());
    let summary = p
        .outcomes
        .iter()
        .find(|o| o.stage == Stage::Reference)
        .unwrap()
        .summary
        .clone();
    assert!(
        summary.contains("compared over these frames only"),
        "{summary}"
    );
}

/// When the scene leaves the schedules at their default length (60 frames) and the test lasts
/// longer (80 here), every fourth schedule starts from the body's state under gravity alone
/// at frame 20 if it is still moving after 60 (a soft beam swinging down), so that they reach
/// the test's last frame. Not when it has come to rest (a stiff beam) nor when the scene sets
/// the length; the stage's line says why.
#[test]
fn some_schedules_start_later_when_the_body_moves_on_under_gravity() {
    use fem_core::integrator::{Simulator, TimeConfig};
    use fem_core::snapshots::{MovingStart, generate_from};
    let with = |name: &str, youngs: &str, length: &str| {
        let text = TINY
            .replace("youngs_modulus = 1.0e5", youngs)
            .replace(
                "[time]",
                "[gravity]\nacceleration = [0.0, -9.81, 0.0]\n[time]",
            )
            .replace(
                "[training]\nschedules = 4\nframes_per_schedule = 8",
                &format!("[training]\nschedules = 4\n{length}"),
            )
            .replace(
                "[test]\nframes_per_schedule = 12",
                "[test]\nframes_per_schedule = 80",
            );
        let s = scene(&text);
        let cache = scratch_dir(&format!("pipeline-later-start-{name}"));
        let mut p = Pipeline::new(&s, &cache).unwrap();
        let set = p.snapshots(&no_progress).unwrap();
        let line = p.outcomes.last().unwrap().summary.clone();
        // The latest time a schedule reaches, as the trust warnings see it.
        let reaches = run_methods(&mut p, &cache.join("out"), &[Method::Pca])[0].training_seconds;
        let model = p.model.clone();
        drop(p);
        (s, model, set, line, reaches)
    };
    let (s, model, set, line, reaches) = with("soft", "youngs_modulus = 2.0e4", "");
    assert!(
        (reaches - 80.0 * 0.02).abs() < 1e-9,
        "to the test's end: {reaches}"
    );
    let why = set
        .later_start
        .clone()
        .expect("a soft beam still swings after 60 frames");
    assert_eq!(set.schedules, [0, 1, 2, 3], "{line}");
    assert_eq!(set.frames, [60; 4], "{line}");
    assert!(why.contains("at 0.40 s") && why.contains("(80)"), "{why}");
    assert!(line.contains(&why), "{line}");
    // The same frames as the family started by hand from 20 frames of a plain run with no grab,
    // and the same travel as that run's largest vertex displacement over the check's 60 frames
    // (against the beam's 1.04 m diagonal).
    let time = TimeConfig {
        frames: 60,
        ..s.time.clone()
    };
    let cfg = s.training();
    let mut sim = Simulator::new(model.clone(), time, cfg.solver(&s.solver)).unwrap();
    let mut travel = 0.0f64;
    let mut start = None;
    for frame in 1..=60 {
        sim.step().unwrap();
        travel = travel.max(fem_core::integrator::max_displacement(&sim.state.u));
        if frame == 20 {
            start = Some(MovingStart {
                u: sim.state.u.clone(),
                v: sim.state.v.clone(),
            });
        }
    }
    let (lo, hi) = model.mesh.bounding_box();
    let moved = format!(
        "in 1.20 s under gravity alone it moves up to {:.0} % of its bounding-box diagonal",
        100.0 * travel / (hi - lo).norm()
    );
    assert!(why.contains(&moved), "{why} against {moved}");
    let start = start.unwrap();
    let by_hand = generate_from(
        &model,
        &cfg,
        &s.time,
        &s.solver,
        (0, 1),
        Some(&|| Ok(Some(start.clone()))),
        &|_| {},
    )
    .unwrap();
    let scale = by_hand.data.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(scale > 1e-3, "the beam moves: {scale}");
    for (a, b) in set.data.iter().zip(&by_hand.data) {
        assert!((a - b).abs() <= 1e-9 * scale, "{a} against {b}");
    }
    let (_, _, set, line, reaches) = with("stiff", "youngs_modulus = 1.0e9", "");
    assert_eq!(set.later_start, None, "at rest: {line}");
    assert!(
        (reaches - 60.0 * 0.02).abs() < 1e-9,
        "the schedules' end: {reaches}"
    );
    let (s, model, set, _, _) = with("set", "youngs_modulus = 2.0e4", "frames_per_schedule = 60");
    assert_eq!(set.later_start, None, "the scene's length");
    // The give-way check still runs beside them, and every schedule starts from rest: the
    // same frames as the family generated with no later start at all.
    let from_rest = generate_from(
        &model,
        &s.training(),
        &s.time,
        &s.solver,
        (0, 1),
        None,
        &|_| {},
    )
    .unwrap();
    assert_eq!(set.data, from_rest.data);
}

/// A simulation that writes no frames (`every` = 0) leaves none of an earlier run's behind: no
/// `frames/` folder and no `series.pvd` naming files that are gone.
#[test]
fn a_run_without_frames_leaves_no_frames_behind() {
    let s = scene(TINY);
    let out = scratch_dir("pipeline-no-frames");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let simulate = |p: &mut Pipeline<'_>, every: usize| {
        let opts = pipeline::simulate::SimulateOptions {
            method: Method::Full,
            trajectory: pipeline::simulate::Trajectory::Scene,
            out: out.join("sim"),
            frames: Some(4),
            every,
            solver: None,
        };
        pipeline::simulate::simulate(p, &opts, &|_, _| {}, &mut |_, _| {}).unwrap()
    };
    simulate(&mut p, 2);
    assert!(out.join("sim/series.pvd").is_file() && out.join("sim/frames").is_dir());
    simulate(&mut p, 0);
    assert!(!out.join("sim/series.pvd").exists() && !out.join("sim/frames").exists());
    assert!(out.join("sim/summary.json").is_file());
    // `run` as well, method by method.
    for every in [2, 0] {
        let opts = RunOptions {
            out: out.join("run"),
            every,
            methods: vec![Method::Full],
            trajectory: 0,
        };
        run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
        let method = out.join("run").join("full");
        assert_eq!(
            method.join("series.pvd").is_file(),
            every > 0,
            "every {every}"
        );
        assert_eq!(method.join("frames").is_dir(), every > 0, "every {every}");
    }
}

/// A reduced simulation's summary gives each step's largest vertex displacement, as full space's
/// does, so the two compare without reading the frames: one per step, the last that of the
/// final state.
#[test]
fn a_reduced_simulation_reports_its_largest_displacement_per_step() {
    let s = scene(TINY);
    let out = scratch_dir("pipeline-reduced-displacement");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let opts = pipeline::simulate::SimulateOptions {
        method: Method::Pca,
        trajectory: pipeline::simulate::Trajectory::Test(0),
        out: out.join("sim"),
        frames: Some(6),
        every: 0,
        solver: None,
    };
    let r = pipeline::simulate::simulate(&mut p, &opts, &|_, _| {}, &mut |_, _| {}).unwrap();
    let largest = &r.summary.reduced_max_displacement;
    assert_eq!(largest.len(), r.summary.reduced_steps.len());
    assert_eq!(largest.len(), 6);
    let last = r
        .final_displacement
        .chunks_exact(3)
        .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
        .fold(0.0, f64::max);
    assert_eq!(*largest.last().unwrap(), last);
    assert!(largest.iter().all(|d| *d > 0.0), "{largest:?}");
    let json = std::fs::read_to_string(out.join("sim/summary.json")).unwrap();
    assert!(json.contains("\"reduced_max_displacement\""), "{json}");
}

/// Under `[training] gravity = "any"` the `snapshots` line says how many schedules fell along
/// turned gravity, computed or loaded from the cache; with the scene's gravity it says nothing
/// of it.
#[test]
fn the_snapshots_line_says_how_many_schedules_fell_along_turned_gravity() {
    let line = |name: &str, gravity: &str| {
        let text = TINY
            .replace(
                "[time]",
                "[gravity]\nacceleration = [0.0, -9.81, 0.0]\n[time]",
            )
            .replace(
                "[training]\nschedules = 4",
                &format!("[training]\nschedules = 4\n{gravity}"),
            );
        let s = scene(&text);
        let cache = scratch_dir(&format!("pipeline-turned-gravity-{name}"));
        let lines: Vec<String> = (0..2)
            .map(|_| {
                let mut p = Pipeline::new(&s, &cache).unwrap();
                p.snapshots(&no_progress).unwrap();
                p.outcomes.last().unwrap().summary.clone()
            })
            .collect();
        assert_eq!(lines[0], lines[1], "computed and loaded");
        lines[0].clone()
    };
    let turned = line("any", "gravity = \"any\"");
    assert!(
        turned.contains("; 2 of them fell along gravity turned another way"),
        "{turned}"
    );
    let scene_gravity = line("scene", "");
    assert!(!scene_gravity.contains("turned"), "{scene_gravity}");
}
