//! Integration tests of pca. Random data comes from a hand-written, seeded generator so every run
//! sees the same numbers. Tests that need `../shared/` skip with a printed reason when it is absent.

mod config;
mod inputs;
mod norm;
mod properties;
mod reference;
mod selection;
mod serde_round_trip;

use std::io::Write;
use std::path::PathBuf;

use faer::Mat;

/// This package's folder, read when the test runs: `cargo test` sets `CARGO_MANIFEST_DIR` for
/// the test process too, so a copy of the checkout tested against the same build (`.ci/run`
/// does this) looks beside the copy, not beside the checkout that compiled the binary.
pub fn manifest_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")))
}

/// The `shared/` folder beside the repository (or `$LATENT_SHARED_DIR`), if present; otherwise
/// prints one line saying that `what` is skipped and why (to the stderr handle itself: the
/// harness captures `eprintln!` and shows it only for failed tests).
pub fn shared_dir(what: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("LATENT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest_dir().join("../../../shared"));
    if dir.is_dir() {
        return Some(dir);
    }
    let _ = writeln!(
        std::io::stderr(),
        "skipping {what}: {} not found (set LATENT_SHARED_DIR to the shared/ folder to run it)",
        dir.display()
    );
    None
}

/// Test data from the workspace's seeded generator (SplitMix64).
pub struct Rng(rng::SplitMix64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(rng::SplitMix64::new(seed))
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0.uniform()
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.0.range(lo, hi)
    }

    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    pub fn normal_mat(&mut self, nrows: usize, ncols: usize) -> Mat<f64> {
        Mat::from_fn(nrows, ncols, |_, _| self.normal())
    }

    /// Positive mass diagonal with entries in [0.1, 10), constant over each group of `group` rows
    /// (a lumped vertex mass repeated per component).
    pub fn mass(&mut self, n: usize, group: usize) -> Vec<f64> {
        let per_vertex: Vec<f64> = (0..n / group).map(|_| self.range(0.1, 10.0)).collect();
        (0..n).map(|i| per_vertex[i / group]).collect()
    }

    pub fn normal_vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.normal()).collect()
    }
}

/// Snapshots with a decaying spectrum: S = A · diag(decay^i) · B, n × N.
pub fn decaying_snapshots(rng: &mut Rng, n: usize, ns: usize, decay: f64) -> Mat<f64> {
    let r = n.min(ns);
    let a = rng.normal_mat(n, r);
    let b = rng.normal_mat(r, ns);
    let d = Mat::from_fn(r, r, |i, j| if i == j { decay.powi(i as i32) } else { 0.0 });
    a * d * b
}

/// Diagonal matrix from its diagonal.
pub fn diag(d: &[f64]) -> Mat<f64> {
    Mat::from_fn(d.len(), d.len(), |i, j| if i == j { d[i] } else { 0.0 })
}

/// Max over vertices and snapshots of ‖s − U UᵀM s‖ per vertex, computed column by column through
/// `project` / `reconstruct` (independent of the fit's incremental scan and of `max_group_error`).
pub fn brute_force_max_vertex_error(
    basis: &pca::PcaBasis,
    s: faer::MatRef<'_, f64>,
    group: usize,
) -> f64 {
    let mut q = vec![0.0; basis.k()];
    let mut back = vec![0.0; basis.n()];
    let mut worst: f64 = 0.0;
    for j in 0..s.ncols() {
        let u: Vec<f64> = s.col(j).iter().copied().collect();
        basis.project(&u, &mut q);
        basis.reconstruct(&q, &mut back);
        for v in 0..basis.n() / group {
            let d: f64 = (0..group)
                .map(|c| (u[v * group + c] - back[v * group + c]).powi(2))
                .sum::<f64>()
                .sqrt();
            worst = worst.max(d);
        }
    }
    worst
}
