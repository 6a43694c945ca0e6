//! Progress reaches 100 %: every long stage (snapshots and their shards, the reference, the
//! autoencoder's training) and `run`, `simulate` and `stress` report progress that ends with a
//! call `done == total`, the call on which `cargo xtask` finishes and clears its bar. The
//! callbacks record every call, in order, from whichever thread makes it. A count may be
//! reported again without growing (the snapshots report the count so far before each schedule,
//! where a caller may stop them: Ctrl-C in Python), never backwards within a stage.

use std::sync::Mutex;

use pipeline::pipeline::Pipeline;
use pipeline::run::{RunOptions, run};
use pipeline::scene::Scene;
use pipeline::simulate::{Method, SimulateOptions, Trajectory, simulate};
use pipeline::stress::{Condition, stress};
use tests::{no_progress, scratch_dir};

/// The end-to-end scene with five training schedules (two shards of unequal size).
fn tiny() -> String {
    tests::TINY.replace("schedules = 4\n", "schedules = 5\n")
}

fn scene(text: &str) -> Scene {
    tests::scene(text)
}

/// Every `(done, total)` call, in the order made.
#[derive(Debug, Default)]
struct Recorder(Mutex<Vec<(usize, usize)>>);

impl Recorder {
    fn record(&self, done: usize, total: usize) {
        self.0.lock().unwrap().push((done, total));
    }

    fn calls(&self) -> Vec<(usize, usize)> {
        self.0.lock().unwrap().clone()
    }
}

/// The calls count 1, 2, …, `total`, in order, with that total (a count repeated, or 0 before
/// the first, is the same count said again).
fn assert_counts_to(what: &str, calls: &[(usize, usize)], total: usize) {
    let expected: Vec<(usize, usize)> = (1..=total).map(|d| (d, total)).collect();
    let mut counted: Vec<(usize, usize)> = calls.iter().copied().filter(|&(d, _)| d > 0).collect();
    counted.dedup();
    assert_eq!(counted, expected, "{what}: {calls:?}");
    assert!(
        calls.windows(2).all(|w| w[0].0 <= w[1].0),
        "{what}: {calls:?}"
    );
}

/// Calls from several stages one after another: each stage's calls (a stage starts where the
/// total changes or the count falls) end with `done == total`, none passes its total.
/// Returns the stages' totals.
fn assert_each_stage_completes(what: &str, calls: &[(usize, usize)]) -> Vec<usize> {
    assert!(!calls.is_empty(), "{what}: no progress at all");
    let mut totals = Vec::new();
    for (i, &(done, total)) in calls.iter().enumerate() {
        assert!(
            total > 0 && done <= total,
            "{what}: call {i} is {done}/{total}"
        );
        let ends = calls
            .get(i + 1)
            .is_none_or(|&(d, t)| t != total || d < done);
        if ends {
            assert_eq!(
                done, total,
                "{what}: a stage stopped at {done}/{total}: {calls:?}"
            );
            totals.push(total);
        }
    }
    totals
}

#[test]
fn snapshot_stages_count_every_schedule() {
    let s = scene(&tiny());
    let mut p = Pipeline::new(&s, scratch_dir("progress-snapshots")).unwrap();
    // Schedules run in parallel; the count still arrives in order, ending at the total.
    let rec = Recorder::default();
    p.snapshots(&|d, t| rec.record(d, t)).unwrap();
    assert_counts_to("snapshots", &rec.calls(), 5);
    let rec = Recorder::default();
    p.snapshot_shard(1, 2, &|d, t| rec.record(d, t)).unwrap();
    assert_counts_to("shard 1/2 (schedules 1, 3)", &rec.calls(), 2);
}

#[test]
fn the_reference_counts_every_frame() {
    let s = scene(&tiny());
    let mut p = Pipeline::new(&s, scratch_dir("progress-reference")).unwrap();
    let rec = Recorder::default();
    p.reference(0, &|d, t| rec.record(d, t)).unwrap();
    assert_counts_to("reference", &rec.calls(), 12);
}

/// Training counts epochs over all restarts and ends at the total when it runs them all, when
/// it stops early for want of improvement (patience), and when a restart stops early.
#[test]
fn training_ends_at_its_total_even_when_it_stops_early() {
    for (case, settings, early) in [
        ("all epochs", "epochs = 150\npatience = 0\n", false),
        ("stops early", "epochs = 400\npatience = 3\n", true),
        (
            "two restarts",
            "epochs = 150\npatience = 3\nrestarts = 2\n",
            true,
        ),
    ] {
        let text = tiny().replace("epochs = 150\n", settings);
        let s = scene(&text);
        let mut p = Pipeline::new(&s, scratch_dir(&format!("progress-train-{case}"))).unwrap();
        p.pca(&no_progress).unwrap();
        let rec = Recorder::default();
        let trained = p.train(&|d, t| rec.record(d, t)).unwrap();
        assert_eq!(
            trained.stopped_early,
            early,
            "{case}: {} epochs",
            trained.history.len()
        );
        let calls = rec.calls();
        let total = s.autoencoder.epochs * s.autoencoder.restarts;
        assert!(calls.iter().all(|&(_, t)| t == total), "{case}: {calls:?}");
        assert!(
            calls.windows(2).all(|w| w[0].0 < w[1].0),
            "{case}: {calls:?}"
        );
        assert_eq!(calls.last(), Some(&(total, total)), "{case}");
    }
}

/// A latent-dimension search counts the epochs of every network it may train as one count that
/// only grows, and ends at its total (a tester's bar restarted at each network).
#[test]
fn a_latent_search_counts_on_from_network_to_network() {
    let text = tiny()
        .replace(
            "latent_dim = 2\n",
            "latent_dims = [1, 3]\nmax_vertex_error = 1e-12\n",
        )
        .replace("epochs = 150\n", "epochs = 20\npatience = 0\n");
    let s = scene(&text);
    let mut p = Pipeline::new(&s, scratch_dir("progress-search")).unwrap();
    p.pca(&no_progress).unwrap();
    let rec = Recorder::default();
    let trained = p.train(&|d, t| rec.record(d, t)).unwrap();
    assert_eq!(
        trained.trials.len(),
        3,
        "no d meets 1e-12: all three trained"
    );
    let calls = rec.calls();
    assert!(calls.iter().all(|&(_, t)| t == 60), "{calls:?}");
    assert!(calls.windows(2).all(|w| w[0].0 < w[1].0), "{calls:?}");
    assert_eq!(calls.last(), Some(&(60, 60)));
}

/// `run` counts each reduced method's steps to the trajectory's frames (full space is the
/// reference stage's trajectory); the stages it computes on the way (into an empty cache) each
/// complete.
#[test]
fn run_counts_every_step_of_every_method() {
    let s = scene(&tiny());
    let out = scratch_dir("progress-run");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    let methods = [
        Method::Full,
        Method::Pca,
        Method::PcaCubature,
        Method::Neural,
        Method::NeuralCubature,
    ];
    let opts = RunOptions {
        out: out.clone(),
        every: 0,
        methods: methods.to_vec(),
        trajectory: 0,
    };
    let stages = Recorder::default();
    let mut steps: Vec<(String, usize, usize)> = Vec::new();
    run(
        &mut p,
        &opts,
        &|d, t| stages.record(d, t),
        &mut |m, d, t| steps.push((m.to_string(), d, t)),
    )
    .unwrap();
    for m in methods {
        let calls: Vec<(usize, usize)> = steps
            .iter()
            .filter(|(name, _, _)| name == m.name())
            .map(|&(_, d, t)| (d, t))
            .collect();
        // Full space is the cached reference, whose frames count as a stage below.
        let frames = if m == Method::Full { 0 } else { 12 };
        assert_counts_to(m.name(), &calls, frames);
    }
    let totals = assert_each_stage_completes("run's stages", &stages.calls());
    // The reference (12 frames), the snapshots (5 schedules) and the training (150 epochs).
    for total in [12, 5, 150] {
        assert!(totals.contains(&total), "run's stages: {totals:?}");
    }
}

#[test]
fn simulate_counts_every_step() {
    let s = scene(&tiny());
    let out = scratch_dir("progress-simulate");
    let mut p = Pipeline::new(&s, out.join("cache")).unwrap();
    for (method, trajectory, frames) in [
        (Method::Full, Trajectory::Scene, 10),
        (Method::Neural, Trajectory::Test(0), 12),
    ] {
        let opts = SimulateOptions {
            method,
            trajectory,
            out: out.join(method.name()),
            frames: None,
            every: 0,
            solver: None,
        };
        let stages = Recorder::default();
        let mut steps = Vec::new();
        simulate(&mut p, &opts, &|d, t| stages.record(d, t), &mut |d, t| {
            steps.push((d, t))
        })
        .unwrap();
        assert_counts_to(method.name(), &steps, frames);
        if method == Method::Neural {
            assert_each_stage_completes("simulate's stages", &stages.calls());
        }
    }
}

/// `stress` reports every (condition, method) pair once, condition by condition, and the
/// stages it computes complete.
#[test]
fn stress_reports_every_method_under_every_condition() {
    let s = scene(&tiny());
    let mut p = Pipeline::new(&s, scratch_dir("progress-stress")).unwrap();
    let methods = [Method::Full, Method::Pca, Method::NeuralCubature];
    let conditions = [
        Condition::Base,
        Condition::Stiffness(100.0),
        Condition::FreeRun(30),
    ];
    let stages = Recorder::default();
    let mut reported = Vec::new();
    stress(
        &mut p,
        &methods,
        &conditions,
        0,
        &|d, t| stages.record(d, t),
        &mut |r| reported.push((r.condition.clone(), r.method)),
    )
    .unwrap();
    let expected: Vec<(String, Method)> = conditions
        .iter()
        .flat_map(|c| methods.iter().map(|&m| (c.label(), m)))
        .collect();
    assert_eq!(reported, expected);
    assert_each_stage_completes("stress's stages", &stages.calls());
}
