//! Reproduces the independent PCA of a beam trajectory in
//! `shared/validation/beams/dynamics_reference.json` (`pca_of_snapshots`, computed with numpy).

use std::path::Path;

use faer::Mat;
use pca::{PcaBasis, PcaConfig};

use super::shared_dir;

const SNAPSHOTS: &str =
    "validation/beams/beam_struct_20x2x2_P1_implicit_euler_g392.40_lumped_snapshots.csv";
const REFERENCE: &str = "validation/beams/dynamics_reference.json";

/// The CSV holds one step per line (50 lines of 567 = 3 · 189 displacement DOFs, `3·node + c`)
/// after a `#` comment; returns S with one snapshot per column (567 × 50).
fn read_snapshots(path: &Path) -> Mat<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            l.split(',')
                .map(|x| x.trim().parse::<f64>().unwrap())
                .collect()
        })
        .collect();
    let steps = rows.len();
    let dofs = rows[0].len();
    assert!(rows.iter().all(|r| r.len() == dofs));
    Mat::from_fn(dofs, steps, |i, j| rows[j][i])
}

fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[test]
fn reproduces_the_shared_beam_snapshot_pca() {
    let Some(shared) = shared_dir("the PCA of the shared beam snapshots") else {
        return;
    };
    let s = read_snapshots(&shared.join(SNAPSHOTS));
    assert_eq!(s.shape(), (567, 50));
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shared.join(REFERENCE)).unwrap()).unwrap();
    let uncentred = &reference["pca_of_snapshots"]["uncentered"];
    let sigma_ref = numbers(&uncentred["singular_values"]);
    let error_ref = numbers(&uncentred["relative_frobenius_reconstruction_error_r1_to_r10"]);
    assert_eq!((sigma_ref.len(), error_ref.len()), (20, 10));

    let fit = PcaBasis::fit(s.as_ref(), None, &PcaConfig::by_dimension(10), 3).unwrap();
    let sigma = fit.basis.singular_values();
    assert_eq!(sigma.len(), 50);
    let mut worst_sigma: f64 = 0.0;
    for (i, (a, b)) in sigma.iter().zip(&sigma_ref).enumerate() {
        let rel = (a - b).abs() / b;
        worst_sigma = worst_sigma.max(rel);
        assert!(
            rel <= 1e-8,
            "σ_{i} = {a:e}, reference {b:e} (relative {rel:e})"
        );
    }

    let norm = s.norm_l2();
    let total: f64 = sigma.iter().map(|x| x * x).sum();
    let mut worst_error: f64 = 0.0;
    let mut reproduced = Vec::new();
    for (r, &expected) in (1..=10).zip(&error_ref) {
        // Directly, by projecting and reconstructing every snapshot …
        let b = fit.basis.truncate(r).unwrap();
        let back = b.reconstruct_matrix(b.project_matrix(s.as_ref()).as_ref());
        let direct = (&s - back).norm_l2() / norm;
        // … and from the spectrum's tail.
        let tail = (sigma[r..].iter().map(|x| x * x).sum::<f64>() / total).sqrt();
        reproduced.push(direct);
        for (how, got) in [("direct", direct), ("tail", tail)] {
            let rel = (got - expected).abs() / expected;
            worst_error = worst_error.max(rel);
            assert!(
                rel <= 1e-8,
                "r = {r} ({how}): {got:e} vs reference {expected:e} ({rel:e})"
            );
        }
    }
    let show = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.15e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    eprintln!("σ_1..20 = [{}]", show(&sigma[..20]));
    eprintln!(
        "relative Frobenius error r = 1..10 = [{}]",
        show(&reproduced)
    );
    eprintln!(
        "beam snapshot PCA: worst relative deviation σ_1..20 {worst_sigma:.2e}, \
         Frobenius errors r = 1..10 {worst_error:.2e}"
    );
}
