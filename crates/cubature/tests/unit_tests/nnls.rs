//! Lawson–Hanson NNLS: KKT conditions, a brute-force oracle, exact recovery, degenerate columns.

use cubature::{CubatureError, NnlsParams, nnls, nnls_with};
use faer::linalg::solvers::SolveLstsq;
use faer::{Mat, MatRef};
use fem_core::rng::SplitMix64;
use proptest::prelude::*;

use super::{norm, normal_mat};

/// w = Aᵀ(b − Ax).
fn dual(a: MatRef<'_, f64>, b: &[f64], x: &[f64]) -> Vec<f64> {
    let r: Vec<f64> = (0..a.nrows())
        .map(|i| b[i] - (0..a.ncols()).map(|j| a[(i, j)] * x[j]).sum::<f64>())
        .collect();
    (0..a.ncols())
        .map(|j| (0..a.nrows()).map(|i| a[(i, j)] * r[i]).sum())
        .collect()
}

fn residual_norm(a: MatRef<'_, f64>, b: &[f64], x: &[f64]) -> f64 {
    let r: Vec<f64> = (0..a.nrows())
        .map(|i| b[i] - (0..a.ncols()).map(|j| a[(i, j)] * x[j]).sum::<f64>())
        .collect();
    norm(&r)
}

/// Asserts the KKT conditions of min ‖Ax − b‖, x ≥ 0, with a tolerance relative to ‖A‖‖b‖.
fn assert_kkt(a: MatRef<'_, f64>, b: &[f64], x: &[f64], rel: f64) {
    let max_col = (0..a.ncols())
        .map(|j| norm(&a.col(j).iter().copied().collect::<Vec<_>>()))
        .fold(0.0, f64::max);
    let tol = rel * max_col * norm(b).max(1e-300);
    let w = dual(a, b, x);
    for j in 0..x.len() {
        assert!(x[j] >= 0.0, "x[{j}] = {} < 0", x[j]);
        if x[j] > 0.0 {
            assert!(
                w[j].abs() <= tol,
                "x[{j}] > 0 but w[{j}] = {} (tol {tol})",
                w[j]
            );
        } else {
            assert!(w[j] <= tol, "x[{j}] = 0 but w[{j}] = {} > tol {tol}", w[j]);
        }
    }
}

/// The NNLS minimum by enumeration: unconstrained least squares (QR) on every subset of columns,
/// the smallest residual among the non-negative solutions. Returns (x, residual norm).
fn brute_force(a: MatRef<'_, f64>, b: &[f64]) -> (Vec<f64>, f64) {
    let n = a.ncols();
    assert!(n <= 8);
    let rhs = Mat::from_fn(b.len(), 1, |i, _| b[i]);
    let mut best = (vec![0.0; n], norm(b));
    for mask in 1u32..(1 << n) {
        let cols: Vec<usize> = (0..n).filter(|j| mask & (1 << j) != 0).collect();
        let sub = Mat::from_fn(a.nrows(), cols.len(), |i, c| a[(i, cols[c])]);
        let z = sub.qr().solve_lstsq(&rhs);
        if (0..cols.len()).any(|c| z[(c, 0)] < 0.0 || z[(c, 0)].is_nan()) {
            continue;
        }
        let mut x = vec![0.0; n];
        for (c, &j) in cols.iter().enumerate() {
            x[j] = z[(c, 0)];
        }
        let r = residual_norm(a, b, &x);
        if r < best.1 {
            best = (x, r);
        }
    }
    best
}

#[test]
fn small_example_by_hand() {
    let a = faer::mat![[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let s = nnls(a.as_ref(), &[1.0, 0.0, -1.0]).unwrap();
    assert!((s.x[0] - 0.5).abs() < 1e-14, "{:?}", s.x);
    assert_eq!(s.x[1], 0.0);
    assert!((s.residual_norm - 1.5f64.sqrt()).abs() < 1e-14);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Random tall, square and wide problems (wide ones are rank deficient).
    #[test]
    fn kkt_conditions_hold_on_random_problems(seed in any::<u64>(), rows in 1usize..30, n in 1usize..20) {
        let mut rng = SplitMix64::new(seed);
        let a = normal_mat(&mut rng, rows, n);
        let b: Vec<f64> = (0..rows).map(|_| rng.normal()).collect();
        let s = nnls(a.as_ref(), &b).unwrap();
        assert_kkt(a.as_ref(), &b, &s.x, 1e-9);
        prop_assert!((s.residual_norm - residual_norm(a.as_ref(), &b, &s.x)).abs() <= 1e-12 * (1.0 + norm(&b)));
        prop_assert!(s.iterations <= 3 * n);
    }

    /// Full-column-rank problems have a unique minimiser: it matches the enumeration oracle.
    #[test]
    fn matches_brute_force_oracle(seed in any::<u64>(), n in 1usize..=8, extra in 0usize..6) {
        let mut rng = SplitMix64::new(seed);
        let rows = n + extra + 1;
        let a = normal_mat(&mut rng, rows, n);
        let b: Vec<f64> = (0..rows).map(|_| rng.normal()).collect();
        let s = nnls(a.as_ref(), &b).unwrap();
        let (x, r) = brute_force(a.as_ref(), &b);
        prop_assert!((s.residual_norm - r).abs() <= 1e-10 * norm(&b), "{} vs {}", s.residual_norm, r);
        let dx: f64 = s.x.iter().zip(&x).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt();
        prop_assert!(dx <= 1e-8 * (1.0 + norm(&x)), "{:?} vs {:?}", s.x, x);
    }
}

#[test]
fn recovers_an_exactly_representable_solution() {
    let mut rng = SplitMix64::new(7);
    for trial in 0..20 {
        let (rows, n) = (40, 12);
        let a = normal_mat(&mut rng, rows, n);
        // Half the entries zero, the rest positive.
        let x_true: Vec<f64> = (0..n)
            .map(|j| {
                if (j + trial) % 2 == 0 {
                    0.0
                } else {
                    rng.range(0.1, 2.0)
                }
            })
            .collect();
        let b: Vec<f64> = (0..rows)
            .map(|i| (0..n).map(|j| a[(i, j)] * x_true[j]).sum())
            .collect();
        let s = nnls(a.as_ref(), &b).unwrap();
        assert!(s.residual_norm <= 1e-12 * norm(&b), "{}", s.residual_norm);
        for j in 0..n {
            assert!(
                (s.x[j] - x_true[j]).abs() <= 1e-10,
                "trial {trial}, x[{j}] = {} vs {}",
                s.x[j],
                x_true[j]
            );
        }
    }
}

#[test]
fn degenerate_columns_are_handled() {
    let mut rng = SplitMix64::new(99);
    for _ in 0..20 {
        let rows = 10;
        let a1: Vec<f64> = (0..rows).map(|_| rng.normal()).collect();
        let a2: Vec<f64> = (0..rows).map(|_| rng.normal()).collect();
        // Columns: a1, a2, a1 (duplicate), 0, a1 + a2 (dependent), 2·a2 (parallel).
        let cols: [Vec<f64>; 6] = [
            a1.clone(),
            a2.clone(),
            a1.clone(),
            vec![0.0; rows],
            a1.iter().zip(&a2).map(|(x, y)| x + y).collect(),
            a2.iter().map(|x| 2.0 * x).collect(),
        ];
        let a = Mat::from_fn(rows, cols.len(), |i, j| cols[j][i]);
        let b: Vec<f64> = (0..rows).map(|_| rng.normal()).collect();
        let s = nnls(a.as_ref(), &b).unwrap();
        assert_kkt(a.as_ref(), &b, &s.x, 1e-9);
        // Every column lies in the cone of a1 and a2, so the minimum equals that of [a1, a2].
        let reduced = Mat::from_fn(rows, 2, |i, j| cols[j][i]);
        let (_, r) = brute_force(reduced.as_ref(), &b);
        assert!(
            (s.residual_norm - r).abs() <= 1e-10 * norm(&b),
            "{} vs {r}",
            s.residual_norm
        );
        assert_eq!(s.x[3], 0.0, "a zero column gets no weight");
    }
    // An all-zero matrix and a zero right-hand side give x = 0.
    let z = Mat::<f64>::zeros(4, 3);
    let s = nnls(z.as_ref(), &[1.0, 2.0, 3.0, 4.0]).unwrap();
    assert_eq!(s.x, vec![0.0; 3]);
    let a = normal_mat(&mut rng, 5, 3);
    assert_eq!(nnls(a.as_ref(), &[0.0; 5]).unwrap().x, vec![0.0; 3]);
    // No columns at all.
    let e = Mat::<f64>::zeros(3, 0);
    let s = nnls(e.as_ref(), &[3.0, 0.0, 4.0]).unwrap();
    assert!(s.x.is_empty() && (s.residual_norm - 5.0).abs() < 1e-15);
}

#[test]
fn nnls_is_deterministic() {
    let mut rng = SplitMix64::new(5);
    let a = normal_mat(&mut rng, 30, 25);
    let b: Vec<f64> = (0..30).map(|_| rng.normal()).collect();
    let s1 = nnls(a.as_ref(), &b).unwrap();
    let s2 = nnls(a.as_ref(), &b).unwrap();
    assert_eq!(s1, s2);
}

#[test]
fn bad_input_is_reported() {
    let a = faer::mat![[1.0, 2.0], [3.0, 4.0]];
    assert!(matches!(
        nnls(a.as_ref(), &[1.0]),
        Err(CubatureError::ShapeMismatch { .. })
    ));
    assert!(matches!(
        nnls(a.as_ref(), &[1.0, f64::NAN]),
        Err(CubatureError::NonFiniteInput { index: 1, .. })
    ));
    let bad = faer::mat![[1.0, 2.0], [3.0, f64::INFINITY]];
    assert!(matches!(
        nnls(bad.as_ref(), &[1.0, 1.0]),
        Err(CubatureError::NonFiniteInput { index: 3, .. })
    ));
    // Both columns are needed (b = a1 + a2 with orthogonal columns): one iteration is not enough.
    let eye = faer::mat![[1.0, 0.0], [0.0, 1.0]];
    let params = NnlsParams {
        max_iterations: Some(1),
        ..Default::default()
    };
    assert_eq!(
        nnls_with(eye.as_ref(), &[1.0, 1.0], &params),
        Err(CubatureError::NnlsNoConvergence { iterations: 1 })
    );
}
