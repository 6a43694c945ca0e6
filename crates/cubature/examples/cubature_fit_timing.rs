//! Times the training-matrix build and greedy fits on a cantilever beam with a 10-mode smooth
//! basis (the test fixture), and reports elements chosen and training / held-out errors.
//!
//! `cargo run -p cubature --release --example cubature_fit_timing -- [cells_x cells_yz train_poses]`
//! (default 40 8 150: 15,360 tets, 150 training and 50 held-out poses).

#[path = "../tests/unit_tests/fixture.rs"]
mod fixture;

use std::time::Instant;

use cubature::{CubatureConfig, Poses, TrainingMatrix, fit};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse())
        .collect::<Result<_, _>>()?;
    let (cx, cyz, poses) = match args[..] {
        [a, b, c] => (a, b, c),
        [] => (40, 8, 150),
        _ => return Err("expected: cells_x cells_yz train_poses".into()),
    };
    let model = fixture::beam([cx, cyz, cyz]);
    let (basis, k, lambda) = fixture::modal_basis(&model);
    let q_train = fixture::random_poses(&model, &basis, &lambda, poses, 11);
    let q_test = fixture::random_poses(&model, &basis, &lambda, 50, 12345);
    let config = CubatureConfig {
        max_poses: poses,
        ..Default::default()
    };
    let t = Instant::now();
    let train = TrainingMatrix::build(&model, &basis, k, Poses::linear(q_train.as_ref()), &config)?;
    let build = t.elapsed().as_secs_f64();
    let held_out =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q_test.as_ref()), &config)?;
    println!(
        "{} tets, {} free DOFs, k = {k}, {} training poses ({} rows, {:.0} MiB): build {build:.2} s",
        model.elements.len(),
        model.dofs.num_free(),
        train.num_poses(),
        train.rows(),
        (train.rows() * train.num_columns() * 8) as f64 / (1 << 20) as f64
    );
    for tolerance in [0.05, 0.02, 0.01, 0.005, 0.001, 0.0001] {
        let config = CubatureConfig {
            tolerance,
            ..config.clone()
        };
        let t = Instant::now();
        let rule = fit(&train, &config)?;
        let secs = t.elapsed().as_secs_f64();
        println!(
            "tolerance {tolerance}: {} elements, training error {:.4}, held-out error {:.4}, fit {secs:.3} s",
            rule.len(),
            rule.training_error,
            rule.evaluate(&held_out)?
        );
    }
    Ok(())
}
