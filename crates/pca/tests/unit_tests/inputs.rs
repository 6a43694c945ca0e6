//! Invalid inputs give the right typed errors.

use faer::Mat;
use pca::{PcaBasis, PcaConfig, PcaError};

use super::{Rng, decaying_snapshots};

fn fit_err(s: &Mat<f64>, mass: Option<&[f64]>, config: &PcaConfig, group: usize) -> PcaError {
    PcaBasis::fit(s.as_ref(), mass, config, group).unwrap_err()
}

#[test]
fn empty_snapshot_matrices_are_rejected() {
    let config = PcaConfig::default();
    assert_eq!(
        fit_err(&Mat::zeros(0, 4), None, &config, 1),
        PcaError::EmptySnapshots { nrows: 0, ncols: 4 }
    );
    assert_eq!(
        fit_err(&Mat::zeros(6, 0), None, &config, 3),
        PcaError::EmptySnapshots { nrows: 6, ncols: 0 }
    );
}

#[test]
fn non_finite_snapshot_values_name_their_entry() {
    let mut rng = Rng::new(1);
    let mut s = rng.normal_mat(9, 4);
    s[(7, 2)] = f64::NAN;
    s[(1, 3)] = f64::INFINITY;
    match fit_err(&s, None, &PcaConfig::default(), 3) {
        PcaError::NonFiniteSnapshot { row, col, value } => {
            assert_eq!((row, col), (7, 2));
            assert!(value.is_nan());
        }
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn all_zero_snapshots_are_rejected() {
    assert_eq!(
        fit_err(&Mat::zeros(6, 3), None, &PcaConfig::default(), 3),
        PcaError::ZeroSnapshots
    );
}

#[test]
fn bad_mass_is_rejected() {
    let mut rng = Rng::new(2);
    let s = rng.normal_mat(6, 4);
    let config = PcaConfig::default();
    assert_eq!(
        fit_err(&s, Some(&[1.0; 5]), &config, 3),
        PcaError::MassLength {
            expected: 6,
            found: 5
        }
    );
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let mut m = vec![1.0; 6];
        m[4] = bad;
        match fit_err(&s, Some(&m), &config, 3) {
            PcaError::InvalidMass { index, .. } => assert_eq!(index, 4),
            other => panic!("mass {bad}: unexpected {other:?}"),
        }
    }
}

#[test]
fn bad_groups_are_rejected() {
    let mut rng = Rng::new(3);
    let s = rng.normal_mat(7, 4);
    let config = PcaConfig::by_max_vertex_error(1e-3);
    assert_eq!(
        fit_err(&s, None, &config, 3),
        PcaError::InvalidGroup { group: 3, nrows: 7 }
    );
    assert_eq!(
        fit_err(&s, None, &config, 0),
        PcaError::InvalidGroup { group: 0, nrows: 7 }
    );
}

#[test]
fn invalid_config_is_reported_by_fit() {
    let mut rng = Rng::new(4);
    let s = rng.normal_mat(6, 4);
    match fit_err(&s, None, &PcaConfig::by_explained_energy(1.5), 3) {
        PcaError::InvalidConfig { field, .. } => assert_eq!(field, "pca.explained_energy"),
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn dimension_beyond_min_n_n_is_rejected() {
    let mut rng = Rng::new(5);
    let s = rng.normal_mat(12, 4);
    assert_eq!(
        fit_err(&s, None, &PcaConfig::by_dimension(5), 3),
        PcaError::DimensionOutOfRange {
            requested: 5,
            available: 4
        }
    );
    // k = min(n, N) itself is fine.
    assert_eq!(
        PcaBasis::fit(s.as_ref(), None, &PcaConfig::by_dimension(4), 3)
            .unwrap()
            .chosen_k(),
        4
    );
}

#[test]
fn truncate_out_of_range_is_rejected() {
    let mut rng = Rng::new(6);
    let s = decaying_snapshots(&mut rng, 12, 8, 0.5);
    let basis = PcaBasis::fit(s.as_ref(), None, &PcaConfig::by_dimension(5), 3)
        .unwrap()
        .basis;
    for k in [0, 6] {
        assert_eq!(
            basis.truncate(k).unwrap_err(),
            PcaError::DimensionOutOfRange {
                requested: k,
                available: 5
            }
        );
    }
}

#[test]
fn max_group_error_checks_its_inputs() {
    let mut rng = Rng::new(7);
    let s = decaying_snapshots(&mut rng, 12, 8, 0.5);
    let basis = PcaBasis::fit(s.as_ref(), None, &PcaConfig::by_dimension(3), 3)
        .unwrap()
        .basis;
    assert!(matches!(
        basis.max_group_error(rng.normal_mat(9, 2).as_ref(), 3),
        Err(PcaError::ShapeMismatch { .. })
    ));
    assert_eq!(
        basis.max_group_error(s.as_ref(), 5).unwrap_err(),
        PcaError::InvalidGroup {
            group: 5,
            nrows: 12
        }
    );
}
