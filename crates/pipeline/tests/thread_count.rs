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
            (snapshots, pca.basis.clone(), cubature, train)
        })
    };
    let (one, two) = (stages(1), stages(2));
    assert!(one.0 == two.0, "snapshots");
    assert!(one.1 == two.1, "pca");
    assert!(one.2 == two.2, "cubature");
    assert!(one.3 == two.3, "train");
}
