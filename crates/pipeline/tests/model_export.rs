//! The trained model leaving the pipeline: `run` writes the default method's model file beside
//! its report, and a model loaded from its file, driven by the held-out trajectory's forces
//! through latent-sim's runtime, steps bit for bit as `run` and `simulate` step the method.

use std::path::Path;

mod common;
use common::scratch;

use latent_sim::model::Rows;
use latent_sim::{Interactive, ReducedModel};
use pipeline::export::{self, model_path};
use pipeline::pipeline::Pipeline;
use pipeline::run::{RunOptions, run};
use pipeline::scene::Scene;
use pipeline::simulate::{Method, Runner, SimulateOptions, Trajectory, setup};

/// A bar with interior vertices (so that a model keeps only some rows), trained in seconds.
const TINY: &str = r#"
name = "export"
[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [6, 2, 2] }
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
density = 1000.0
[[pin]]
plane = { axis = "x", side = "min" }
[time]
step = 0.02
frames = 8
[training]
schedules = 3
frames_per_schedule = 8
[test]
frames_per_schedule = 8
[pca]
dimension = 6
[cubature]
tolerance = 0.05
[autoencoder]
latent_dim = 3
hidden = [8]
epochs = 30
batch_size = 8
"#;

fn no_progress(_: usize, _: usize) {}

#[test]
fn a_model_loaded_from_its_file_replays_the_runners_trajectory_bit_for_bit() {
    let scene = Scene::from_str(TINY, Path::new("."), "tiny.toml").unwrap();
    let dir = scratch("replay");
    let mut p = Pipeline::new(&scene, dir.join("cache")).unwrap();
    for method in [
        Method::Pca,
        Method::PcaCubature,
        Method::Neural,
        Method::NeuralCubature,
    ] {
        let opts = SimulateOptions {
            method,
            trajectory: Trajectory::Test(0),
            out: dir.join(method.name()),
            frames: None,
            every: 0,
            solver: None,
        };
        let (model, time, solver) = setup(&p, &opts).unwrap();
        let forces = model.forces.clone();
        assert!(!forces.is_empty());
        let mut runner = Runner::new(
            &mut p,
            method,
            model,
            &scene.material,
            time.clone(),
            solver,
            &no_progress,
        )
        .unwrap();
        let path = model_path(&dir, method);
        export::scene_model(&mut p, method, Rows::Used, &no_progress)
            .unwrap()
            .save(&path)
            .unwrap();
        let loaded = ReducedModel::load(&path).unwrap();
        assert_eq!(loaded.provenance.method, method.name());
        let mut sim = loaded.simulator().unwrap();
        for f in forces {
            sim.add_force(f).unwrap();
        }
        let Runner::Reduced(reference) = &mut runner else {
            panic!("a reduced runner")
        };
        for step in 1..=time.frames {
            reference.step_report().unwrap();
            sim.step().unwrap();
            let (a, b) = (reference.coefficients(), sim.coefficients());
            assert!(
                a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{}: step {step}: {a:?} vs {b:?}",
                method.name()
            );
        }
        // At rest with nothing acting every term of the step's gradient is round-off; the
        // model steps and stays at rest (neural models failed every step here).
        let mut still = loaded.simulator().unwrap();
        still.set_gravity(false);
        for step in 1..=3 {
            still
                .step()
                .unwrap_or_else(|e| panic!("{}: at rest, step {step}: {e}", method.name()));
            let size = still
                .coefficients()
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(
                size < 1e-9,
                "{}: at rest, step {step}: moved {size:.2e}",
                method.name()
            );
        }
    }
}

#[test]
fn run_writes_the_default_methods_model_beside_its_report() {
    let scene = Scene::from_str(TINY, Path::new("."), "tiny.toml").unwrap();
    let dir = scratch("run");
    let mut p = Pipeline::new(&scene, dir.join("cache")).unwrap();
    let opts = RunOptions {
        out: dir.join("out"),
        every: 0,
        methods: vec![Method::Full, Method::Pca, Method::NeuralCubature],
        trajectory: 0,
    };
    let rows = run(&mut p, &opts, &no_progress, &mut |_, _, _| {}).unwrap();
    assert_eq!(
        export::run_method(&opts.methods),
        Some(export::DEFAULT_METHOD)
    );
    let model = ReducedModel::load(model_path(&opts.out, Method::NeuralCubature)).unwrap();
    assert!(opts.out.join("report.json").exists());
    assert_eq!(model.provenance.scene, "export");
    let row = rows
        .iter()
        .find(|r| r.method == Method::NeuralCubature)
        .unwrap();
    let held_out = model
        .provenance
        .errors
        .iter()
        .find(|e| {
            e.held_out && e.name.contains("test trajectory 0") && e.name.contains("displacement")
        })
        .unwrap();
    assert_eq!(held_out.value, row.mean_rel_error);
    // Stepped through the runtime under the test's forces, the model says after each step how
    // far its pose lies beyond the training poses: at its furthest, what the report says.
    let (test, _, _) = setup(
        &p,
        &SimulateOptions {
            method: Method::NeuralCubature,
            trajectory: Trajectory::Test(0),
            out: dir.join("replay"),
            frames: None,
            every: 0,
            solver: None,
        },
    )
    .unwrap();
    let mut sim = model.simulator().unwrap();
    for f in test.forces {
        sim.add_force(f).unwrap();
    }
    let mut furthest = 0.0f64;
    for _ in 0..row.frame_errors.len() {
        let beyond = sim.step().unwrap().beyond_training.unwrap();
        assert_eq!(Some(beyond), sim.beyond_training());
        furthest = furthest.max(beyond);
    }
    assert_eq!(furthest, row.training_distance);
    // A reduced trajectory is timed again while its runs stay within the budget; a full-space
    // one once.
    let frames = row.frame_errors.len() as f64;
    let budget = pipeline::run::RUN_TIMING_BUDGET.as_secs_f64();
    for r in &rows {
        let runs = r.timed_runs;
        assert!((1..=pipeline::run::RUN_REPEATS).contains(&runs), "{runs}");
        assert!(r.ms_min <= r.ms_per_step && r.ms_per_step <= r.ms_max);
        if r.method == Method::Full {
            assert_eq!(runs, 1);
        } else {
            // Each further run started while the runs before it took less than the budget.
            assert!(
                (runs - 1) as f64 * r.ms_min * frames * 1e-3 < budget,
                "{runs}"
            );
            if pipeline::run::RUN_REPEATS as f64 * r.ms_max * frames * 1e-3 < budget {
                assert_eq!(runs, pipeline::run::RUN_REPEATS, "{}", r.method.name());
            }
        }
    }
    let stages: Vec<&str> = model
        .provenance
        .stage_keys
        .iter()
        .map(|k| k.stage.as_str())
        .collect();
    // The complement stage chose the model's complement directions (the scene names no count).
    assert_eq!(
        stages,
        [
            "snapshots",
            "pca",
            "train",
            "cubature-neural",
            "complement",
            "coverage"
        ]
    );
    // Only reduced methods have a model; without the default, the first reduced one is written.
    assert_eq!(
        export::run_method(&[Method::Full, Method::FullNewton]),
        None
    );
    assert_eq!(
        export::run_method(&[Method::Full, Method::PcaCubature, Method::Pca]),
        Some(Method::PcaCubature)
    );
    let err = export::scene_model(&mut p, Method::Full, Rows::Used, &no_progress).unwrap_err();
    assert!(err.to_string().contains("full-space method"), "{err}");
}
