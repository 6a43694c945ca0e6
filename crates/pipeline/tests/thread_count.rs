//! The stages' results do not depend on how many threads compute them: the same scene on a
//! pool of one thread and on a pool of two gives the same basis, network and rules to the bit
//! (faer's dense kernels split their work by the parallelism they are given, so the pipeline
//! gives them a fixed one, [`pipeline::pipeline::FAER_TASKS`]).

use std::path::Path;

mod common;
use common::scratch;

use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

const SCENE: &str = r#"name = "threads"
[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [16, 3, 3] }
[[pin]]
plane = { axis = "x", side = "min" }
[training]
schedules = 8
frames_per_schedule = 40
[test]
frames_per_schedule = 20
[autoencoder]
epochs = 20
[cubature]
max_elements = 60
"#;

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

#[test]
fn one_thread_and_two_compute_the_same_stages() {
    let scene = Scene::from_str(SCENE, Path::new("."), "threads").unwrap();
    let stages = |threads: usize| {
        pool(threads).install(|| {
            let cache = scratch(&format!("threads-{threads}"));
            let mut p = Pipeline::new(&scene, &cache).unwrap();
            let none = |_: usize, _: usize| {};
            let snapshots = p.snapshots(&none).unwrap().data.clone();
            let pca = p.pca(&none).unwrap();
            let cubature = p.cubature(&none).unwrap().rule.clone();
            let train = p.train(&none).unwrap().model.clone();
            let complement = p.complement(&none).unwrap().directions.clone();
            let neural = p.cubature_neural(&none).unwrap().rule.clone();
            (
                snapshots,
                pca.basis.clone(),
                cubature,
                train,
                complement,
                neural,
            )
        })
    };
    // Three threads: past two, the full-space factorisation runs in parallel too.
    let one = stages(1);
    for threads in [2, 3] {
        let other = stages(threads);
        assert!(one.0 == other.0, "snapshots on {threads} threads");
        assert!(one.1 == other.1, "pca on {threads} threads");
        assert!(one.2 == other.2, "cubature on {threads} threads");
        assert!(one.3 == other.3, "train on {threads} threads");
        assert!(one.4 == other.4, "complement on {threads} threads");
        assert!(one.5 == other.5, "cubature-neural on {threads} threads");
    }
}
