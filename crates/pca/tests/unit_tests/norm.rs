//! A basis refitted in another norm: M-orthonormal, nested in order, the best span in that norm.

use faer::Mat;
use faer::linalg::solvers::Solve;
use pca::{PcaBasis, PcaConfig};

use super::{Rng, decaying_snapshots, diag};

/// ‖(I − P)S‖²_W with P the W-orthogonal projector on span(U), by solving the normal equations
/// (UᵀWU) c = UᵀWs column by column: independent of how the basis was made.
fn w_error(u: &Mat<f64>, w: &Mat<f64>, s: &Mat<f64>) -> f64 {
    let g = u.transpose() * w * u;
    let rhs = u.transpose() * w * s;
    let c = g.llt(faer::Side::Lower).unwrap().solve(&rhs);
    let r = s - u * c;
    let wr = w * &r;
    (0..r.ncols())
        .map(|j| (0..r.nrows()).map(|i| r[(i, j)] * wr[(i, j)]).sum::<f64>())
        .sum()
}

fn columns(b: &PcaBasis) -> Mat<f64> {
    b.basis_ref().to_owned()
}

#[test]
fn the_refit_is_m_orthonormal_and_best_in_its_norm() {
    let mut rng = Rng::new(7);
    let (n, ns, k) = (60, 40, 6);
    let s = decaying_snapshots(&mut rng, n, ns, 0.8);
    let mass = rng.mass(n, 3);
    let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_dimension(k), 3).unwrap();
    // W: the mass plus a stiffness-like SPD part that weighs some rows far more.
    let b = rng.normal_mat(n, n);
    let w = diag(&mass) + (&b * b.transpose()) * 0.05;
    let refit = fit.basis.refit_in_norm(s.as_ref(), |x| &w * x).unwrap();
    assert_eq!((refit.n(), refit.k()), (n, k));
    let u = columns(&refit);
    let utmu = u.transpose() * diag(&mass) * &u;
    for i in 0..k {
        for j in 0..k {
            let e = if i == j { 1.0 } else { 0.0 };
            assert!(
                (utmu[(i, j)] - e).abs() < 1e-10,
                "UᵀMU[{i},{j}] = {}",
                utmu[(i, j)]
            );
        }
    }
    // Best in W: below the M-norm PCA's W-error, and no worse than any of a few random spans.
    let pca_u = columns(&fit.basis);
    let best = w_error(&u, &w, &s);
    assert!(best < w_error(&pca_u, &w, &s), "{best}");
    for seed in 0..5 {
        let mut r = Rng::new(100 + seed);
        let other = &pca_u + r.normal_mat(n, k) * 0.1;
        assert!(best <= w_error(&other, &w, &s) * (1.0 + 1e-12));
    }
    // Nested: its first j columns are the j-dimensional refit.
    let fit3 = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_dimension(3), 3).unwrap();
    let refit3 = columns(&fit3.basis.refit_in_norm(s.as_ref(), |x| &w * x).unwrap());
    let lead = u.subcols(0, 3).to_owned();
    let p = &lead * (lead.transpose() * diag(&mass) * &refit3);
    assert!((&p - &refit3).norm_l2() < 1e-8 * refit3.norm_l2());
}

#[test]
fn in_the_mass_norm_the_refit_spans_the_pca_basis() {
    let mut rng = Rng::new(8);
    let (n, ns, k) = (45, 30, 5);
    let s = decaying_snapshots(&mut rng, n, ns, 0.7);
    let mass = rng.mass(n, 3);
    let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_dimension(k), 3).unwrap();
    let m = diag(&mass);
    let refit = columns(&fit.basis.refit_in_norm(s.as_ref(), |x| &m * x).unwrap());
    let pca_u = columns(&fit.basis);
    let p = &pca_u * (pca_u.transpose() * &m * &refit);
    assert!((&p - &refit).norm_l2() < 1e-8 * refit.norm_l2());
}

/// The refit is the same to the bit on every run, so the stages after it stay cached: its sums
/// run in a fixed order (a parallel sum's split points, and so its round-off, vary by run).
#[test]
fn the_refit_reproduces_to_the_bit() {
    let mut rng = Rng::new(9);
    let (n, ns, k) = (30_000, 12, 5);
    let s = decaying_snapshots(&mut rng, n, ns, 0.8);
    let mass = rng.mass(n, 3);
    let fit = PcaBasis::fit(s.as_ref(), Some(&mass), &PcaConfig::by_dimension(k), 3).unwrap();
    let weights: Vec<f64> = mass.iter().map(|m| 2.0 * m + 1.0).collect();
    let w = |x: faer::MatRef<'_, f64>| {
        Mat::from_fn(x.nrows(), x.ncols(), |i, j| weights[i] * x[(i, j)])
    };
    let first = fit.basis.refit_in_norm(s.as_ref(), w).unwrap();
    for _ in 0..4 {
        assert_eq!(fit.basis.refit_in_norm(s.as_ref(), w).unwrap(), first);
    }
}
