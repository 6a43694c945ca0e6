//! Times a fit on a large synthetic snapshot matrix (not a benchmark harness; run once with
//! `cargo run -p pca --release --example pca_fit_timing [n] [N]`).

use std::time::Instant;

use faer::Mat;
use pca::{PcaBasis, PcaConfig};

fn main() -> Result<(), pca::PcaError> {
    let mut args = std::env::args()
        .skip(1)
        .map(|a| a.parse::<usize>().expect("usize"));
    let n = args.next().unwrap_or(10_002);
    let ns = args.next().unwrap_or(2_000);
    // Rank-400 snapshots with a spectrum decaying like 1/m²: S = A diag(1/m²) B.
    let r = 400.min(n).min(ns);
    let mut rng = rng::SplitMix64::new(7);
    let a = Mat::from_fn(n, r, |_, m| rng.range(-1.0, 1.0) / ((m + 1) as f64).powi(2));
    let b = Mat::from_fn(r, ns, |_, _| rng.range(-1.0, 1.0));
    let s = a * b;
    let mass: Vec<f64> = (0..n).map(|i| 1.0 + ((i / 3) % 7) as f64 * 0.1).collect();
    println!(
        "n = {n}, N = {ns}, threads = {}",
        rayon::current_num_threads()
    );
    // A tolerance of 1 % of the largest vertex displacement, for a rule that is met.
    let largest = (0..ns)
        .flat_map(|j| (0..n / 3).map(move |v| (j, v)))
        .map(|(j, v)| {
            (0..3)
                .map(|c| s[(3 * v + c, j)].powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0f64, f64::max);

    for (name, config) in [
        ("dimension = 50", PcaConfig::by_dimension(50)),
        ("dimension = 300", PcaConfig::by_dimension(300)),
        (
            "explained_energy = 0.9999",
            PcaConfig::by_explained_energy(0.9999),
        ),
        (
            "max_vertex_error = 1 % of the largest displacement",
            PcaConfig::by_max_vertex_error(0.01 * largest),
        ),
        (
            "max_vertex_error = 1e-300 (scans to the cap, 300)",
            PcaConfig::by_max_vertex_error(1e-300),
        ),
    ] {
        let t = Instant::now();
        let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &config, 3)?;
        println!(
            "{name}: k = {}, met = {}, scanned {} k, {:.2} s",
            fit.chosen_k(),
            fit.tolerance_met,
            fit.max_vertex_error_per_k.len(),
            t.elapsed().as_secs_f64()
        );
    }
    let t = Instant::now();
    let sv = s.singular_values().unwrap();
    println!(
        "faer singular values only: {:.2} s (σ_0 = {:.3e})",
        t.elapsed().as_secs_f64(),
        sv[0]
    );
    let t = Instant::now();
    let svd = s.thin_svd().unwrap();
    println!(
        "faer thin SVD with vectors: {:.2} s ({} columns of U)",
        t.elapsed().as_secs_f64(),
        svd.U().ncols()
    );
    Ok(())
}
