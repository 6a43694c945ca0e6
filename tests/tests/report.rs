//! The numbers `cargo xtask run` reports, recomputed here from what it writes and from the
//! definitions, not from the code that computes them: the mass-weighted relative error and the
//! largest vertex error from the frames each method writes, the speed-ups and rates from the
//! reported times, and how far a cubature rule moves a method's trajectory from the same method
//! evaluating every element.

use std::path::Path;

use pipeline::pipeline::Pipeline;
use pipeline::run::{MethodReport, RunOptions, run};
use pipeline::scene::Scene;
use pipeline::simulate::Method;
use pipeline::trajectories::{run_trajectories, spreads, trajectory_dir};
use tests::{TINY, no_progress, scene, scratch_dir};

/// Runs `methods` on test trajectory 0 of `s`, writing every frame to `out`.
fn run_all_frames(s: &Scene, out: &Path, methods: &[Method]) -> Vec<MethodReport> {
    let mut p = Pipeline::new(s, out.join("cache")).unwrap();
    let opts = RunOptions {
        out: out.to_path_buf(),
        every: 1,
        methods: methods.to_vec(),
        trajectory: 0,
    };
    run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap()
}

// ---------------------------------------------------------------------------------------------
// The written frames, read back with a minimal parse of the VTU files.

/// The numbers of the first `<DataArray>` after `marker` in `xml`.
fn array_after(xml: &str, marker: &str) -> Vec<f64> {
    let at = xml.find(marker).unwrap_or_else(|| panic!("no {marker}"));
    let start = at + xml[at..].find('>').unwrap() + 1;
    let end = start + xml[start..].find("</DataArray>").unwrap();
    xml[start..end]
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect()
}

/// One written frame: rest positions, tets and the displacement, 3 numbers per vertex.
struct Frame {
    points: Vec<f64>,
    tets: Vec<[usize; 4]>,
    displacement: Vec<f64>,
}

fn read_frame(dir: &Path, method: &str, step: usize) -> Frame {
    let path = dir.join(method).join(format!("frames/frame_{step:05}.vtu"));
    let xml = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let points_at = xml.find("<Points>").expect("a Points section");
    Frame {
        points: array_after(&xml[points_at..], "<DataArray"),
        tets: array_after(&xml, "Name=\"connectivity\"")
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]].map(|i| i as usize))
            .collect(),
        displacement: array_after(&xml, "Name=\"displacement\""),
    }
}

/// Every frame after the start, 1..=`frames`.
fn read_frames(dir: &Path, method: &str, frames: usize) -> Vec<Frame> {
    (1..=frames).map(|k| read_frame(dir, method, k)).collect()
}

// ---------------------------------------------------------------------------------------------
// The mass matrix, from the mesh in the frames.

/// Volume of tet `t` of `points` (3 per vertex).
fn volume(points: &[f64], t: &[usize; 4]) -> f64 {
    let p = |i: usize| [points[3 * t[i]], points[3 * t[i] + 1], points[3 * t[i] + 2]];
    let (a, b, c, d) = (p(0), p(1), p(2), p(3));
    let e = |x: [f64; 3]| [x[0] - a[0], x[1] - a[1], x[2] - a[2]];
    let (u, v, w) = (e(b), e(c), e(d));
    let det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0]);
    det.abs() / 6.0
}

#[derive(Clone, Copy, Debug)]
enum Mass {
    /// Each tet's mass ρV split equally over its four vertices.
    Lumped,
    /// The linear tet's ρV/20 (1 + δ_ab) between its vertices a, b.
    Consistent,
}

/// xᵀ M x for displacements x (3 per vertex), density 1: relative errors do not depend on it.
fn m_norm_squared(mass: Mass, frame: &Frame, x: &[f64]) -> f64 {
    let mut sum = 0.0;
    for t in &frame.tets {
        let vol = volume(&frame.points, t);
        for c in 0..3 {
            let xs: Vec<f64> = t.iter().map(|&v| x[3 * v + c]).collect();
            let squares: f64 = xs.iter().map(|x| x * x).sum();
            sum += match mass {
                Mass::Lumped => vol / 4.0 * squares,
                Mass::Consistent => {
                    let total: f64 = xs.iter().sum();
                    vol / 20.0 * (squares + total * total)
                }
            };
        }
    }
    sum
}

/// What the report should say about a method's frames against the full-space frames: the
/// relative M-norm error of each frame where the reference has moved, and the largest distance
/// of a vertex from its reference position over all frames.
fn expected_errors(mass: Mass, method: &[Frame], full: &[Frame]) -> (Vec<f64>, f64) {
    let mut rel = Vec::new();
    let mut max_vertex: f64 = 0.0;
    for (m, f) in method.iter().zip(full) {
        let diff: Vec<f64> = m
            .displacement
            .iter()
            .zip(&f.displacement)
            .map(|(a, b)| a - b)
            .collect();
        let den = m_norm_squared(mass, f, &f.displacement);
        if den > 0.0 {
            rel.push((m_norm_squared(mass, f, &diff) / den).sqrt());
        }
        for d in diff.chunks_exact(3) {
            max_vertex = max_vertex.max((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
        }
    }
    (rel, max_vertex)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(f64::MIN_POSITIVE)
}

// ---------------------------------------------------------------------------------------------

/// The error columns of the report (frame errors, their mean and maximum, the largest vertex
/// error) against the same quantities computed here from the written frames, with a lumped and
/// with a consistent mass matrix, for a linear and a neural method with and without cubature.
#[test]
fn error_columns_match_the_written_frames() {
    for (mass, section) in [
        (Mass::Lumped, ""),
        (Mass::Consistent, "mass = \"consistent\"\n"),
    ] {
        let text = TINY.replace(
            "density = 1000.0\n",
            &format!("density = 1000.0\n{section}"),
        );
        let s = scene(&text);
        let out = scratch_dir(&format!("report-errors-{mass:?}"));
        let methods = [
            Method::Full,
            Method::Pca,
            Method::PcaCubature,
            Method::Neural,
            Method::NeuralCubature,
        ];
        let rows = run_all_frames(&s, &out, &methods);
        let frames = 12;
        let full = read_frames(&out, "full", frames);
        assert!(
            full.iter()
                .all(|f| f.displacement.iter().any(|&x| x != 0.0))
        );
        for r in &rows[1..] {
            let what = format!("{mass:?} mass, {}", r.method);
            assert!(r.failure.is_none(), "{what}: {:?}", r.failure);
            let method = read_frames(&out, r.method.name(), frames);
            let (rel, max_vertex) = expected_errors(mass, &method, &full);
            assert_eq!(rel.len(), r.frame_errors.len(), "{what}: frames");
            for (k, (a, b)) in r.frame_errors.iter().zip(&rel).enumerate() {
                assert!(close(*a, *b), "{what}, frame {}: {a} against {b}", k + 1);
            }
            let mean = rel.iter().sum::<f64>() / rel.len() as f64;
            let max = rel.iter().copied().fold(0.0, f64::max);
            assert!(
                close(r.mean_rel_error, mean),
                "{what}: mean {} against {mean}",
                r.mean_rel_error
            );
            assert!(
                close(r.max_rel_error, max),
                "{what}: max {} against {max}",
                r.max_rel_error
            );
            assert!(
                close(r.max_vertex_error, max_vertex),
                "{what}: max vertex error {} against {max_vertex}",
                r.max_vertex_error
            );
            // Not trivially zero: the reduced methods are measurably off.
            assert!(
                mean > 1e-4 && max_vertex > 0.0,
                "{what}: {mean}, {max_vertex}"
            );
        }
    }
}

/// The report's times: the `full` row's time is the mean step of the cached reference and its
/// median the middle of its sorted steps, every row's speed-up is the faster full-space
/// solver's time over its own, its rate is 1000 / (ms per step), and `report.json` says the
/// same. Both full-space solvers run, so "the faster" is a choice between two times.
#[test]
fn speedups_and_rates_follow_from_the_reported_times() {
    let s = scene(TINY);
    let out = scratch_dir("report-speedups");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let other_full = match s.solver.method {
        fem_core::optim::SolverMethod::Newton => Method::FullLbfgs,
        fem_core::optim::SolverMethod::Lbfgs => Method::FullNewton,
    };
    let opts = RunOptions {
        out: out.clone(),
        every: 0,
        methods: vec![Method::Full, other_full, Method::Pca, Method::PcaCubature],
        trajectory: 0,
    };
    let rows = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    assert_eq!(rows.len(), 4);
    assert!(p.reference_computed_here(0));
    let mut steps = p.reference(0, &no_progress).unwrap().step_seconds.clone();
    let reference_ms = steps.iter().sum::<f64>() / steps.len() as f64 * 1e3;
    assert!(
        close(rows[0].ms_per_step, reference_ms),
        "{} against {reference_ms}",
        rows[0].ms_per_step
    );
    steps.sort_by(f64::total_cmp);
    let n = steps.len();
    let middle = if n % 2 == 1 {
        steps[n / 2]
    } else {
        0.5 * (steps[n / 2 - 1] + steps[n / 2])
    };
    assert!(
        close(rows[0].ms_median, middle * 1e3),
        "{} against {}",
        rows[0].ms_median,
        middle * 1e3
    );
    for r in &rows[2..] {
        assert!(
            r.ms_min <= r.ms_per_step && r.ms_per_step <= r.ms_max && r.ms_median > 0.0,
            "{}: {} {} {} {}",
            r.method,
            r.ms_min,
            r.ms_per_step,
            r.ms_max,
            r.ms_median
        );
    }
    // A later run loads the reference, timed then: `full` runs again for its time, with the
    // reference's frames (no error) and iterations.
    let mut later = Pipeline::new(&s, out.join("cache")).unwrap();
    let again = run(
        &mut later,
        &RunOptions {
            out: out.join("later"),
            methods: vec![Method::Full],
            ..opts.clone()
        },
        &no_progress,
        &mut |_, _, _| {},
    )
    .unwrap();
    assert!(!later.reference_computed_here(0));
    assert_ne!(again[0].ms_per_step, rows[0].ms_per_step);
    assert_eq!(again[0].mean_rel_error, 0.0);
    assert_eq!(again[0].iterations, rows[0].iterations);
    let fastest_full = rows[0].ms_per_step.min(rows[1].ms_per_step);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    for (i, r) in rows.iter().enumerate() {
        assert!(r.ms_per_step > 0.0, "{}", r.method);
        let speedup = fastest_full / r.ms_per_step;
        assert!(
            r.speedup.is_some_and(|s| close(s, speedup)),
            "{}: speed-up {:?} against {speedup}",
            r.method,
            r.speedup
        );
        let hz = 1e3 / r.ms_per_step;
        assert!(close(r.hz, hz), "{}: {} Hz against {hz}", r.method, r.hz);
        let row = &json["methods"][i];
        assert_eq!(row["method"], r.method.name());
        for (key, value) in [
            ("ms_per_step", r.ms_per_step),
            ("ms_median", r.ms_median),
            ("speedup", speedup),
            ("hz", hz),
        ] {
            let written = row[key].as_f64().unwrap();
            assert!(
                close(written, value),
                "{}: report.json {key} {written} against {value}",
                r.method
            );
        }
    }
}

/// mean over frames of ‖u_a − u_b‖_M / ‖u_b‖_M between two methods' written frames.
fn mean_distance(out: &Path, a: &str, b: &str, frames: usize) -> f64 {
    let (fa, fb) = (read_frames(out, a, frames), read_frames(out, b, frames));
    let (rel, _) = expected_errors(Mass::Lumped, &fa, &fb);
    rel.iter().sum::<f64>() / rel.len() as f64
}

/// The PCA and neural methods with their cubature rules against the same methods evaluating
/// every element, on a beam of 864 tets where the rules keep 17 and 6 of them: each rule must
/// leave its method's trajectory within 1 % of the trajectory without it
/// (measured: 0.28 % and 0.14 %; with every weight replaced by 1, 35 % and 13 %), and move the
/// reported error by at most half a percentage point (measured: 0.01 and 0.04; with unit
/// weights 26 and 8.5).
#[test]
fn cubature_rules_stay_close_to_every_element() {
    // The neural rule is fitted on the decoder's tangent and the complement directions beside
    // it; the gravity-onset directions are integrated by the same rule without being fitted
    // (docs/numerics.md), so they are left out here.
    let text = TINY.replace("cells = [6, 1, 1]", "cells = [16, 3, 3]")
        + "[cubature]\ntolerance = 0.02\n[reduced]\nonset_directions = 0\ncomplement_directions = 2\n";
    let s = scene(&text);
    let out = scratch_dir("report-cubature");
    let methods = [
        Method::Full,
        Method::Pca,
        Method::PcaCubature,
        Method::Neural,
        Method::NeuralCubature,
    ];
    let rows = run_all_frames(&s, &out, &methods);
    let all = rows[0].cubature_elements;
    for (every, rule) in [(&rows[1], &rows[2]), (&rows[3], &rows[4])] {
        let what = format!("{} against {}", rule.method, every.method);
        assert!(rule.failure.is_none() && every.failure.is_none(), "{what}");
        assert_eq!(every.cubature_elements, all, "{what}");
        assert!(
            10 * rule.cubature_elements < all,
            "{what}: {} of {all} elements",
            rule.cubature_elements
        );
        let d = mean_distance(&out, rule.method.name(), every.method.name(), 12);
        assert!(
            d <= 0.01,
            "{what}: the rule moves the trajectory by {:.2} %",
            100.0 * d
        );
        let gap = (rule.mean_rel_error - every.mean_rel_error).abs();
        assert!(
            gap <= 0.005,
            "{what}: reported errors {} and {}",
            rule.mean_rel_error,
            every.mean_rel_error
        );
    }
}

/// `run --trajectories 3`: each trajectory's report in its folder, trajectory 0's where a plain
/// run writes it and the same to the bit; the table's errors are the runs' own; raising
/// `[test] schedules` leaves every stage's cache key alone, so the first reference is shared.
#[test]
fn several_trajectories_report_each_and_their_spread() {
    let out = scratch_dir("report-trajectories");
    let cache = out.join("cache");
    let methods = vec![Method::Full, Method::Pca, Method::PcaCubature];
    let plain = scene(TINY);
    let single = {
        let mut p = Pipeline::new(&plain, &cache).unwrap();
        let opts = RunOptions {
            out: out.join("plain"),
            every: 0,
            methods: methods.clone(),
            trajectory: 0,
        };
        run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap()
    };
    let references = || {
        std::fs::read_dir(&cache)
            .unwrap()
            .filter(|e| {
                let name = e.as_ref().unwrap().file_name();
                name.to_string_lossy().starts_with("reference-")
            })
            .count()
    };
    assert_eq!(references(), 1);
    let mut raised = scene(TINY);
    raised.raise_test_trajectories(3);
    assert_eq!(raised.test().schedules, 3);
    let mut p = Pipeline::new(&raised, &cache).unwrap();
    let opts = RunOptions {
        out: out.join("three"),
        every: 0,
        methods,
        trajectory: 0,
    };
    let mut seen = Vec::new();
    let runs = run_trajectories(
        &mut p,
        &opts,
        3,
        &no_progress,
        &mut |i| seen.push(i),
        &mut |_, _, _| {},
    )
    .unwrap();
    assert_eq!(seen, [0, 1, 2]);
    assert_eq!(
        references(),
        3,
        "trajectory 0's reference is the plain run's"
    );
    for (a, b) in runs[0].iter().zip(&single) {
        assert_eq!(a.method, b.method);
        assert_eq!(a.frame_errors, b.frame_errors, "{}", a.method);
    }
    let table = spreads(&runs);
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(opts.out.join("trajectories.json")).unwrap())
            .unwrap();
    for (i, rows) in runs.iter().enumerate() {
        let dir = trajectory_dir(&opts.out, i);
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap())
                .unwrap();
        for (j, r) in rows.iter().enumerate() {
            assert_eq!(report["methods"][j]["method"], r.method.name());
            assert_eq!(table[j].errors[i], Some(r.mean_rel_error));
            let w = written[j]["errors"][i].as_f64().unwrap();
            assert!(
                close(w, r.mean_rel_error),
                "{w} against {}",
                r.mean_rel_error
            );
        }
    }
    // The trajectories differ, so their errors do.
    let pca = &table[1];
    assert_ne!(pca.errors[0], pca.errors[1]);
    let mean = pca.errors.iter().map(|e| e.unwrap()).sum::<f64>() / 3.0;
    assert!((pca.mean.unwrap() - mean).abs() <= 1e-15 * mean);
    let worst = pca.errors.iter().map(|e| e.unwrap()).fold(0.0, f64::max);
    assert_eq!(pca.worst.map(|w| w.1), Some(worst));
    let md = std::fs::read_to_string(opts.out.join("trajectories.md")).unwrap();
    assert!(
        md.contains("| pca-cubature |") && !md.contains("| full |"),
        "{md}"
    );
    // Trajectory i exists whatever `[test] schedules` says: the plain scene (one schedule) runs
    // trajectory 2 to the same errors as the family of three, from the same cached reference.
    let mut p = Pipeline::new(&plain, &cache).unwrap();
    let opts = RunOptions {
        out: out.join("plain-2"),
        every: 0,
        methods: vec![Method::Full, Method::Pca],
        trajectory: 2,
    };
    let third = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    assert_eq!(references(), 3);
    for (a, b) in third.iter().zip(&runs[2]) {
        assert_eq!(a.method, b.method);
        assert_eq!(a.frame_errors, b.frame_errors, "{}", a.method);
    }
    let e = run_trajectories(
        &mut p,
        &opts,
        0,
        &no_progress,
        &mut |_| {},
        &mut |_, _, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("at least 1"), "{e}");
}

/// A run of test trajectory 1 from an empty cache, where the cubature stage computes trajectory
/// 0's reference after the run's own, lists the run's reference among its stages, as the same
/// run on the warm cache does.
#[test]
fn a_report_names_its_own_reference_from_an_empty_cache() {
    let out = scratch_dir("report-own-reference");
    let s = scene(TINY);
    let reference_key = |dir: &str| {
        let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
        let opts = RunOptions {
            out: out.join(dir),
            every: 0,
            methods: Method::ALL.to_vec(),
            trajectory: 1,
        };
        run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
        let computed = p
            .outcomes
            .iter()
            .filter(|o| o.stage == pipeline::stage::Stage::Reference && !o.cached)
            .count();
        let json = std::fs::read(opts.out.join("report.json")).unwrap();
        let report: serde_json::Value = serde_json::from_slice(&json).unwrap();
        let stages = report["stages"].as_array().unwrap().clone();
        let references: Vec<_> = stages
            .iter()
            .filter(|l| l["stage"] == "reference")
            .collect();
        assert_eq!(references.len(), 1, "{stages:?}");
        (computed, references[0]["key"].clone())
    };
    let (cold_computed, cold) = reference_key("cold");
    let (warm_computed, warm) = reference_key("warm");
    // Both references computed the first time (the test is not vacuous), none the second.
    assert_eq!((cold_computed, warm_computed), (2, 0));
    assert_eq!(cold, warm);
}

/// A warm run reads no snapshots: with every stage after them cached, it runs without their
/// artifact (deleted, the largest, to save disk) and computes nothing.
#[test]
fn a_warm_run_needs_no_snapshots() {
    let out = scratch_dir("report-no-snapshots");
    let s = scene(TINY);
    let opts = RunOptions {
        out: out.join("run"),
        every: 0,
        methods: Method::ALL.to_vec(),
        trajectory: 0,
    };
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let cold = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    for entry in std::fs::read_dir(out.join("cache")).unwrap().flatten() {
        if entry
            .file_name()
            .to_string_lossy()
            .starts_with("snapshots-")
        {
            std::fs::remove_file(entry.path()).unwrap();
        }
    }
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let warm = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    let computed: Vec<_> = p.outcomes.iter().filter(|o| !o.cached).collect();
    assert!(computed.is_empty(), "{computed:?}");
    for (a, b) in cold.iter().zip(&warm) {
        assert_eq!(a.training_seconds, b.training_seconds, "{}", a.method);
        assert_eq!(a.training_distance, b.training_distance, "{}", a.method);
    }
    assert!(warm.iter().any(|r| r.training_seconds > 0.0));
    // The warm run's report lists no snapshots, and is still the model's.
    let model = pipeline::export::scene_model(
        &mut p,
        Method::NeuralCubature,
        latent_sim::model::Rows::Used,
        &no_progress,
    )
    .unwrap();
    assert_eq!(pipeline::export::report_is_of(&opts.out, &model), Ok(()));
    let said = pipeline::export::run_verdict(&opts.out, &model, &s);
    assert!(said.starts_with("measured by `cargo xtask run`"), "{said}");
    assert!(p.outcomes.iter().all(|o| o.cached), "{:?}", p.outcomes);
}

/// An artifact whose checksums pass and whose content does not fit the model (snapshots of
/// other DOFs, a reference frame cut short) is computed again, not read into a panic.
#[test]
fn an_artifact_that_does_not_fit_is_computed_again() {
    use pipeline::artifact::save;
    use pipeline::stage::Stage;
    let out = scratch_dir("report-unfit-artifact");
    let s = scene(TINY);
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let snaps = p.snapshots(&no_progress).unwrap();
    let reference = p.reference(0, &no_progress).unwrap();
    let (good_snaps, good_frames) = ((*snaps).clone(), reference.frames.clone());
    // The mesh hash of the header, the 8 bytes after the key.
    let header = |stage: Stage| {
        let o = p.outcomes.iter().find(|o| o.stage == stage).unwrap();
        let bytes = std::fs::read(&o.path).unwrap();
        let key = o.key.to_le_bytes();
        let at = bytes.windows(8).position(|w| w == key).unwrap() + 8;
        (
            o.path.clone(),
            o.key,
            u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()),
        )
    };
    let (path, key, mesh) = header(Stage::Snapshots);
    let mut bad = good_snaps.clone();
    bad.dim += 1;
    save(&path, Stage::Snapshots, key, mesh, &bad).unwrap();
    let (path, key, mesh) = header(Stage::Reference);
    let mut cut = (*reference).clone();
    cut.frames[5].truncate(1);
    save(&path, Stage::Reference, key, mesh, &cut).unwrap();
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    assert_eq!(*p.snapshots(&no_progress).unwrap(), good_snaps);
    assert_eq!(p.reference(0, &no_progress).unwrap().frames, good_frames);
    assert!(p.outcomes.iter().all(|o| !o.cached), "{:?}", p.outcomes);
}

/// The reference's compression reaches the report whether or not `full` ran: on its row when
/// it did, on the first row otherwise (a `full-lbfgs` row too), the same values.
#[test]
fn compression_is_reported_without_a_full_row() {
    let out = scratch_dir("report-compression");
    let s = scene(TINY);
    let with_full = run_all_frames(&s, &out.join("with"), &[Method::Full, Method::Pca]);
    let mut p = Pipeline::new(&s, out.join("with").join("cache")).unwrap();
    let mut without = |methods: Vec<Method>| {
        let opts = RunOptions {
            out: out.join("without"),
            every: 0,
            methods,
            trajectory: 0,
        };
        run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap()
    };
    let full = with_full[0]
        .compression
        .expect("the full row's compression");
    assert!(
        full.volume_ratio > 0.0 && full.volume_ratio < 1.0,
        "{full:?}"
    );
    assert_eq!(with_full[1].compression, None);
    let reduced = without(vec![Method::Pca, Method::PcaCubature]);
    assert_eq!(reduced[0].compression, Some(full));
    assert_eq!(reduced[1].compression, None);
    // The other full-space solver's row does not carry it, so the first row does.
    let lbfgs_first = without(vec![Method::FullLbfgs, Method::Pca]);
    assert_eq!(lbfgs_first[0].compression, Some(full));
    assert_eq!(lbfgs_first[1].compression, None);
}

/// A plate standing on its edge, pinned along its foot: soft, it buckles under its own weight
/// and the run says so on the full row, with the modulus that would keep it standing; at
/// twice that modulus it stands and nothing is said.
#[test]
fn a_plate_that_buckles_under_its_weight_is_said() {
    let plate = |modulus: f64| {
        scene(&format!(
            r#"
name = "plate"
[mesh]
generate = {{ kind = "box", size = [0.27, 0.27, 0.025], cells = [8, 8, 2] }}
[material]
model = "stable-neo-hookean"
youngs_modulus = {modulus:e}
poisson_ratio = 0.45
[[pin]]
plane = {{ axis = "y", side = "min", tolerance = 1.0e-3 }}
[gravity]
acceleration = [0.0, -9.81, 0.0]
[time]
step = 0.01
[test]
frames_per_schedule = 4
"#
        ))
    };
    let out = scratch_dir("report-buckling");
    let soft = plate(2.0e4);
    let mut p = Pipeline::new(&soft, out.join("cache")).unwrap();
    let opts = RunOptions {
        out: out.clone(),
        every: 0,
        methods: vec![Method::Full],
        trajectory: 0,
    };
    let rows = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    let b = rows[0].buckling.expect("the full row carries the analysis");
    let load = b.buckles().expect("a soft plate on its edge buckles");
    let standing = b.standing_modulus.unwrap();
    assert!((standing - 2.0e4 / load).abs() < 1e-6 * standing, "{b:?}");
    let warnings = pipeline::trust::assess(&rows).untrusted;
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("buckles under its own weight")),
        "{warnings:?}"
    );
    // report.md has the warnings under its table, as `run` prints them.
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("not to be trusted:\n- full: the body buckles"),
        "{report}"
    );
    // Its title says what it measured.
    let title = report.lines().next().unwrap_or_default();
    assert!(
        title.starts_with("# ") && title.contains(" — held-out test trajectory 0, "),
        "{title}"
    );
    let stiff = plate(2.0 * standing);
    let out = scratch_dir("report-standing");
    let mut p = Pipeline::new(&stiff, out.join("cache")).unwrap();
    let rows = run(
        &mut p,
        &RunOptions {
            out: out.clone(),
            ..opts
        },
        &no_progress,
        &mut |_, _, _| {},
    )
    .unwrap();
    let b = rows[0].buckling.unwrap();
    assert!((b.load_factor.unwrap() - 2.0).abs() < 1e-3, "{b:?}");
    assert_eq!(b.buckles(), None);
    assert!(pipeline::trust::assess(&rows).untrusted.is_empty());
}

/// The test's loads are said under the title and in `report.json`: the spring's vertices, their
/// mean rest position, its stiffness, its largest target offset against the bounding-box
/// diagonal and its span, the test model's own.
#[test]
fn the_report_says_where_the_test_grabs_and_how_far_it_pulls() {
    let s = scene(TINY);
    let out = scratch_dir("report-test-forces");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let opts = RunOptions {
        out: out.clone(),
        every: 0,
        methods: vec![Method::Pca],
        trajectory: 0,
    };
    run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    let model = p.test_model(0).unwrap();
    assert_eq!(model.forces.len(), 1, "the default test is one drag");
    let force = &model.forces[0];
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let written = &json["test_forces"][0];
    assert_eq!(written["kind"], "spring");
    assert_eq!(written["vertices"], force.vertices.len());
    assert!(close(
        written["stiffness"].as_f64().unwrap(),
        force.stiffness
    ));
    for axis in 0..3 {
        let mean = force
            .vertices
            .iter()
            .map(|&v| model.mesh.vertices[v][axis])
            .sum::<f64>()
            / force.vertices.len() as f64;
        assert!(
            close(written["centre"][axis].as_f64().unwrap(), mean),
            "{written}"
        );
    }
    let largest = force
        .keyframes
        .iter()
        .map(|k| (k[1] * k[1] + k[2] * k[2] + k[3] * k[3]).sqrt())
        .fold(0.0, f64::max);
    let (lo, hi) = model.mesh.bounding_box();
    let share = written["diagonal_share"].as_f64().unwrap();
    assert!(
        close(written["largest"].as_f64().unwrap(), largest),
        "{written}"
    );
    assert!(close(share, largest / (hi - lo).norm()), "{written}");
    // The default family's offsets: 2–10 % of the diagonal.
    assert!((0.02..=0.10 + 1e-12).contains(&share), "{written}");
    assert_eq!(written["end"].as_f64().unwrap(), force.end);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let line = format!(
        "the test: a spring of {:.2e} N/m on {} vertices around (",
        force.stiffness,
        force.vertices.len()
    );
    assert!(md.contains(&line), "{md}");
    assert!(md.contains(&format!(
        "({:.1} % of the bounding-box diagonal)",
        100.0 * share
    )));
    // The command names the scene file it was run on (without it, the built-in scene ran).
    assert!(
        md.contains(&format!(
            "one draw of the test family: `cargo xtask run --scene {} --trajectories 4`",
            s.source
        )),
        "{md}"
    );
}

/// `export` says what `run` measured of the model it writes, from the run's `report.json`
/// when that report is of the same stages: the method's error and the warnings that name it;
/// otherwise why it was not measured.
#[test]
fn an_exported_model_is_told_what_the_run_measured_of_it() {
    use latent_sim::model::Rows;
    use pipeline::export::{run_verdict, scene_model};
    let s = scene(TINY);
    let out = scratch_dir("report-export-verdict");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let opts = RunOptions {
        out: out.join("run"),
        every: 0,
        methods: vec![Method::Full, Method::PcaCubature],
        trajectory: 0,
    };
    let rows = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    let model = scene_model(&mut p, Method::PcaCubature, Rows::Used, &no_progress).unwrap();
    let said = run_verdict(&out.join("run"), &model, &s);
    let error = format!(
        "pca-cubature {:.2} % from the full trajectory",
        100.0 * rows[1].mean_rel_error
    );
    assert!(
        said.starts_with("measured by `cargo xtask run` on held-out test trajectory 0")
            && said.contains(&error),
        "{said}"
    );
    // The error is recorded in the model as `run` records it, once the report is of it.
    let mut recorded = model.clone();
    assert!(pipeline::export::record_run_error(
        &out.join("run"),
        &mut recorded,
        &s
    ));
    let e = recorded.provenance.errors.last().unwrap();
    assert_eq!(e.value, rows[1].mean_rel_error);
    assert_eq!(e.name, format!("{} 0", pipeline::run::TRAJECTORY_ERROR));
    assert!(e.held_out);
    let count = recorded.provenance.errors.len();
    // Recorded again, it is still one.
    assert!(pipeline::export::record_run_error(
        &out.join("run"),
        &mut recorded,
        &s
    ));
    assert_eq!(recorded.provenance.errors.len(), count);
    assert_eq!(
        recorded.provenance.errors.len(),
        model.provenance.errors.len() + 1
    );
    // A method the run left out, a scene changed since, and no run at all.
    let mut pca = scene_model(&mut p, Method::Pca, Rows::Used, &no_progress).unwrap();
    assert!(!pipeline::export::record_run_error(
        &out.join("run"),
        &mut pca,
        &s
    ));
    let said = run_verdict(&out.join("run"), &pca, &s);
    assert!(
        said.starts_with("not measured: the run in") && said.contains("did not run pca"),
        "{said}"
    );
    let stiffer = scene(&TINY.replace("youngs_modulus = 1.0e5", "youngs_modulus = 2.0e5"));
    let mut q = Pipeline::new(&stiffer, out.join("cache")).unwrap();
    let other = scene_model(&mut q, Method::PcaCubature, Rows::Used, &no_progress).unwrap();
    let said = run_verdict(&out.join("run"), &other, &stiffer);
    assert!(said.contains("is of other stages"), "{said}");
    // Without a scene at hand (`view --model`), the stages alone tell the report's model.
    assert_eq!(
        pipeline::export::report_is_of(&out.join("run"), &model),
        Ok(())
    );
    let why = pipeline::export::report_is_of(&out.join("run"), &other).unwrap_err();
    assert!(
        why.ends_with(
            "is of other stages: a later run of another scene, or of this one changed, wrote there"
        ),
        "{why}"
    );
    let why = pipeline::export::report_is_of(&out.join("nowhere"), &model).unwrap_err();
    assert!(why.ends_with("is missing or does not read"), "{why}");
    let said = run_verdict(&out.join("nowhere"), &model, &s);
    assert!(said.starts_with("not measured: no run report in"), "{said}");
    // The same stages under other solver settings, which no stage key holds.
    let looser = scene(&TINY.replace("[solver]\n", "[reduced]\ntolerance = 0.01\n[solver]\n"));
    let said = run_verdict(&out.join("run"), &model, &looser);
    assert!(
        said.contains("was run with other `[solver]`, `[reduced]` or `[test]` settings"),
        "{said}"
    );
    // The lines kept are those of the method, the test's full simulation and the scene.
    use pipeline::export::names;
    for line in [
        "pca-cubature: 30 % from the full trajectory",
        "pca, pca-cubature, neural: at t = 0.2 s their poses go",
        "full-newton: the full-space simulation of the test squeezes",
        "full: the full-space simulation of the test moves the body",
        "the full-space reference squeezes 6 % of the body's volume",
        "the scene: its own weight strains the body",
        "the PCA basis: `[pca] max_dimension` = 8 stopped it at that many coefficients",
    ] {
        assert!(names(line, "pca-cubature"), "{line}");
    }
    // The basis every reduced method shares is none of a full-space model's.
    assert!(!names(
        "the PCA basis: `[pca] max_dimension` = 8 stopped it",
        "full"
    ));
    for line in [
        "pca: its subspace alone is 28.8 % from the test trajectory",
        "neural-cubature: its cubature rule adds 17 percentage points",
        "pca, neural: at t = 0.2 s their poses go",
    ] {
        assert!(!names(line, "pca-cubature"), "{line}");
    }
}
