//! Properties of a fitted basis: M-orthonormality, exact reconstruction, the least-squares
//! optimality of the projection, and the spectrum checked against an independent computation.

use faer::{Mat, MatRef};
use pca::{PcaBasis, PcaConfig};

use super::{Rng, decaying_snapshots, diag};

fn fit(s: MatRef<'_, f64>, mass: Option<&[f64]>, k: usize) -> PcaBasis {
    PcaBasis::fit(s, mass, &PcaConfig::by_dimension(k), 3)
        .unwrap()
        .basis
}

/// ‖x‖²_M.
fn m_norm_sq(x: &[f64], mass: &[f64]) -> f64 {
    x.iter().zip(mass).map(|(x, m)| m * x * x).sum()
}

#[test]
fn basis_is_mass_orthonormal() {
    for (seed, n, ns, k) in [(10, 60, 25, 25), (11, 90, 40, 12), (12, 30, 80, 30)] {
        let mut rng = Rng::new(seed);
        let s = decaying_snapshots(&mut rng, n, ns, 0.8);
        let mass = rng.mass(n, 3);
        let basis = fit(s.as_ref(), Some(&mass), k);
        let u = basis.basis_ref();
        let gram = u.transpose() * diag(&mass) * u;
        let err = (&gram - Mat::<f64>::identity(k, k)).norm_max();
        assert!(err < 1e-10, "seed {seed}: ‖UᵀMU − I‖_max = {err:e}");
        // Without the mass weighting the columns are not orthonormal: the test can tell.
        let plain = (u.transpose() * u - Mat::<f64>::identity(k, k)).norm_max();
        assert!(plain > 1e-3, "seed {seed}: UᵀU unexpectedly ≈ I");
    }
}

#[test]
fn full_rank_reconstruction_is_exact() {
    let mut rng = Rng::new(20);
    // Generic 45 × 15 snapshots: rank 15.
    let s = rng.normal_mat(45, 15);
    let mass = rng.mass(45, 3);
    let basis = fit(s.as_ref(), Some(&mass), 15);
    let back = basis.reconstruct_matrix(basis.project_matrix(s.as_ref()).as_ref());
    let err = (&back - &s).norm_max() / s.norm_max();
    assert!(err < 1e-12, "relative reconstruction error {err:e}");
    // One mode fewer cannot reproduce generic data.
    let fewer = basis.truncate(14).unwrap();
    let back = fewer.reconstruct_matrix(fewer.project_matrix(s.as_ref()).as_ref());
    assert!((&back - &s).norm_max() / s.norm_max() > 1e-3);

    // Rank-4 data: k = 4 reproduces it exactly.
    let a = rng.normal_mat(45, 4);
    let b = rng.normal_mat(4, 20);
    let low = &a * &b;
    let basis = fit(low.as_ref(), Some(&mass), 4);
    let back = basis.reconstruct_matrix(basis.project_matrix(low.as_ref()).as_ref());
    let err = (&back - &low).norm_max() / low.norm_max();
    assert!(err < 1e-12, "rank-4 relative reconstruction error {err:e}");
}

#[test]
fn projection_is_the_m_norm_least_squares_optimum() {
    let mut rng = Rng::new(30);
    let n = 48;
    let s = decaying_snapshots(&mut rng, n, 30, 0.7);
    let mass = rng.mass(n, 3);
    let basis = fit(s.as_ref(), Some(&mass), 6);
    let k = basis.k();
    let mut q = vec![0.0; k];
    let mut back = vec![0.0; n];
    for trial in 0..5 {
        let u = rng.normal_vec(n);
        basis.project(&u, &mut q);
        basis.reconstruct(&q, &mut back);
        let r: Vec<f64> = u.iter().zip(&back).map(|(u, b)| u - b).collect();
        let best = m_norm_sq(&r, &mass);
        // Normal equations: UᵀM(u − Uq) = 0.
        let mut g = vec![0.0; k];
        basis.project(&r, &mut g);
        let g_max = g.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        assert!(g_max < 1e-12 * u.iter().fold(0.0f64, |a, x| a.max(x.abs())));
        // Every perturbation increases the error, by exactly ε²‖δ‖² since UᵀMU = I.
        for _ in 0..10 {
            let delta = rng.normal_vec(k);
            for eps in [1e-3, 1e-1, 1.0] {
                let qp: Vec<f64> = q.iter().zip(&delta).map(|(q, d)| q + eps * d).collect();
                basis.reconstruct(&qp, &mut back);
                let rp: Vec<f64> = u.iter().zip(&back).map(|(u, b)| u - b).collect();
                let worse = m_norm_sq(&rp, &mass);
                let expected = eps * eps * delta.iter().map(|d| d * d).sum::<f64>();
                assert!(
                    worse > best,
                    "trial {trial}: perturbation decreased the error"
                );
                assert!(
                    ((worse - best) - expected).abs() <= 1e-9 * expected.max(best),
                    "trial {trial}: increase {} vs ε²‖δ‖² = {expected}",
                    worse - best
                );
            }
        }
    }
}

#[test]
fn spectrum_matches_eigenvalues_of_the_mass_gram_matrix() {
    let mut rng = Rng::new(40);
    let (n, ns) = (60, 18);
    let s = rng.normal_mat(n, ns);
    let mass = rng.mass(n, 3);
    let basis = fit(s.as_ref(), Some(&mass), 3);
    let sigma = basis.singular_values();
    assert_eq!(sigma.len(), ns);
    assert!(
        sigma.windows(2).all(|w| w[0] >= w[1]),
        "not sorted: {sigma:?}"
    );
    // σ_i² are the eigenvalues of SᵀMS.
    let gram = s.transpose() * diag(&mass) * &s;
    let mut lambda = gram.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
    lambda.reverse();
    for (i, (s, l)) in sigma.iter().zip(&lambda).enumerate() {
        assert!(
            (s * s - l).abs() <= 1e-10 * l,
            "σ_{i}² = {} but λ_{i} = {l}",
            s * s
        );
    }
    // The explained energy and the M-weighted Frobenius error agree (Eckart–Young).
    for k in 1..ns {
        let b = basis.clone();
        let b = if k <= b.k() {
            b.truncate(k).unwrap()
        } else {
            fit(s.as_ref(), Some(&mass), k)
        };
        let r = &s - b.reconstruct_matrix(b.project_matrix(s.as_ref()).as_ref());
        let err_sq: f64 = (0..n)
            .map(|i| mass[i] * (0..ns).map(|j| r[(i, j)].powi(2)).sum::<f64>())
            .sum();
        let total: f64 = sigma.iter().map(|s| s * s).sum();
        let predicted = total * (1.0 - b.explained_energy(k));
        assert!(
            (err_sq - predicted).abs() <= 1e-9 * total,
            "k = {k}: ‖S − UUᵀMS‖²_M = {err_sq}, Σ_(i≥k) σ² = {predicted}"
        );
    }
}

#[test]
fn batched_and_single_projection_agree() {
    let mut rng = Rng::new(50);
    let s = decaying_snapshots(&mut rng, 30, 12, 0.6);
    let mass = rng.mass(30, 3);
    let basis = fit(s.as_ref(), Some(&mass), 5);
    let q_all = basis.project_matrix(s.as_ref());
    let u_all = basis.reconstruct_matrix(q_all.as_ref());
    let mut q = vec![0.0; 5];
    let mut u = vec![0.0; 30];
    for j in 0..12 {
        let col: Vec<f64> = s.col(j).iter().copied().collect();
        basis.project(&col, &mut q);
        basis.reconstruct(&q, &mut u);
        for i in 0..5 {
            assert!((q[i] - q_all[(i, j)]).abs() < 1e-12);
        }
        for i in 0..30 {
            assert!((u[i] - u_all[(i, j)]).abs() < 1e-12);
        }
    }
    // The view exposes the same columns.
    for i in 0..5 {
        let col: Vec<f64> = basis.basis_ref().col(i).iter().copied().collect();
        assert_eq!(col.as_slice(), basis.column(i));
    }
}

#[test]
fn truncation_equals_a_smaller_fit() {
    let mut rng = Rng::new(60);
    let s = decaying_snapshots(&mut rng, 36, 20, 0.7);
    let mass = rng.mass(36, 3);
    let big = fit(s.as_ref(), Some(&mass), 10);
    let small = fit(s.as_ref(), Some(&mass), 4);
    let cut = big.truncate(4).unwrap();
    assert_eq!(cut.k(), 4);
    assert_eq!(cut.singular_values(), big.singular_values());
    assert!((cut.basis_ref() - small.basis_ref()).norm_max() < 1e-13);
}

#[test]
fn identity_mass_is_the_default() {
    let mut rng = Rng::new(70);
    let s = decaying_snapshots(&mut rng, 24, 10, 0.5);
    let none = fit(s.as_ref(), None, 4);
    let ones = fit(s.as_ref(), Some(&[1.0; 24]), 4);
    assert!(none.mass().is_none());
    assert!((none.basis_ref() - ones.basis_ref()).norm_max() < 1e-14);
    let u = none.basis_ref();
    assert!((u.transpose() * u - Mat::<f64>::identity(4, 4)).norm_max() < 1e-12);
}

#[test]
fn extended_basis_stays_mass_orthonormal_and_spans_what_it_kept() {
    let (n, k) = (60, 6);
    let mut rng = Rng::new(40);
    let s = decaying_snapshots(&mut rng, n, 20, 0.7);
    let mass = rng.mass(n, 3);
    let basis = fit(s.as_ref(), Some(&mass), k);
    let new = rng.normal_vec(n);
    // A combination of the basis's own columns adds nothing; a zero direction neither.
    let inside: Vec<f64> = (0..n)
        .map(|i| 2.0 * basis.column(0)[i] - basis.column(3)[i])
        .collect();
    let (extended, fractions) = basis
        .extended(&[new.clone(), inside, vec![0.0; n]], 0.01)
        .unwrap();
    assert_eq!(extended.k(), k + 1);
    assert!(
        fractions[0] > 0.1,
        "a random direction is mostly new: {fractions:?}"
    );
    assert!(fractions[1] < 1e-12 && fractions[2] == 0.0, "{fractions:?}");
    let u = extended.basis_ref();
    let gram = u.transpose() * diag(&mass) * u;
    let err = (&gram - Mat::<f64>::identity(k + 1, k + 1)).norm_max();
    assert!(err < 1e-12, "‖UᵀMU − I‖_max = {err:e}");
    // The first k columns are the fit's, and the new direction is reproduced by the basis.
    assert_eq!(
        &extended
            .basis_ref()
            .as_ref()
            .col(0)
            .iter()
            .copied()
            .collect::<Vec<_>>()[..],
        basis.column(0)
    );
    let mut q = vec![0.0; k + 1];
    let mut back = vec![0.0; n];
    extended.project(&new, &mut q);
    extended.reconstruct(&q, &mut back);
    let miss = m_norm_sq(
        &back
            .iter()
            .zip(&new)
            .map(|(a, b)| a - b)
            .collect::<Vec<_>>(),
        &mass,
    );
    assert!(
        miss.sqrt() < 1e-12 * m_norm_sq(&new, &mass).sqrt(),
        "{miss:e}"
    );
    // The same direction asked for twice is kept once.
    let (twice, f) = basis.extended(&[new.clone(), new], 0.01).unwrap();
    assert_eq!((twice.k(), f[1] < 1e-12), (k + 1, true), "{f:?}");
    // A basis of every mode the snapshots have, extended past its spectrum, is still a valid
    // basis (the spectrum is padded, so it reads back).
    let all = fit(s.as_ref(), Some(&mass), 20);
    let (more, _) = all.extended(&[rng.normal_vec(n)], 0.01).unwrap();
    assert_eq!(more.k(), 21);
    let parts = (0..21).flat_map(|j| more.column(j).to_vec()).collect();
    let again = PcaBasis::new(
        n,
        21,
        parts,
        Some(mass.clone()),
        more.singular_values().to_vec(),
    );
    assert_eq!(again.unwrap(), more);
    // A direction of the wrong length is an error naming it.
    let e = basis.extended(&[vec![1.0; n - 1]], 0.01).unwrap_err();
    assert!(e.to_string().contains("direction 0"), "{e}");
    // At most two of four new directions, the first two that are new (the second, a repeat of
    // the first, is not), the same columns as `extended` appends first.
    let others: Vec<Vec<f64>> = (0..3).map(|_| rng.normal_vec(n)).collect();
    let four = [
        others[0].clone(),
        others[0].clone(),
        others[1].clone(),
        others[2].clone(),
    ];
    let (capped, f) = basis.extended_at_most(&four, 0.01, 2).unwrap();
    assert_eq!((capped.k(), f.len()), (k + 2, 3), "{f:?}");
    assert!(f[1] < 1e-12, "{f:?}");
    let (all_four, _) = basis.extended(&four, 0.01).unwrap();
    assert_eq!(all_four.k(), k + 3);
    assert_eq!(capped.column(k + 1), all_four.column(k + 1));
}
