//! Artifacts survive a serde round trip unchanged, and corrupt ones are rejected.

use pca::{PcaBasis, PcaConfig, PcaFit};

use super::{Rng, decaying_snapshots};

#[test]
fn basis_round_trip_is_identical() {
    let mut rng = Rng::new(200);
    let s = decaying_snapshots(&mut rng, 27, 14, 0.6);
    let mass = rng.mass(27, 3);
    let fit = PcaBasis::fit(
        s.as_ref(),
        Some(&mass),
        &PcaConfig::by_max_vertex_error(1e-4),
        3,
    )
    .unwrap();
    let json = serde_json::to_string(&fit.basis).unwrap();
    let back: PcaBasis = serde_json::from_str(&json).unwrap();
    assert_eq!(back, fit.basis);
    // Bit-identical, not merely equal up to ±0.
    let bits = |b: &PcaBasis| -> Vec<u64> {
        (0..b.k())
            .flat_map(|i| b.column(i).iter().map(|x| x.to_bits()).collect::<Vec<_>>())
            .collect()
    };
    assert_eq!(bits(&back), bits(&fit.basis));

    let json = serde_json::to_string(&fit).unwrap();
    let back: PcaFit = serde_json::from_str(&json).unwrap();
    assert_eq!(back, fit);

    let none = PcaBasis::fit(s.as_ref(), None, &PcaConfig::by_dimension(3), 3)
        .unwrap()
        .basis;
    let back: PcaBasis = serde_json::from_str(&serde_json::to_string(&none).unwrap()).unwrap();
    assert_eq!(back, none);
}

#[test]
fn config_round_trip() {
    let config = PcaConfig {
        max_vertex_error: Some(2.5e-3),
        max_dimension: 77,
        ..PcaConfig::default()
    };
    let back: PcaConfig = serde_json::from_str(&serde_json::to_string(&config).unwrap()).unwrap();
    assert_eq!(back, config);
}

#[test]
fn corrupt_artifacts_are_rejected() {
    let good = r#"{"n":3,"k":1,"basis":[1.0,0.0,0.0],"mass":null,"singular_values":[2.0,1.0]}"#;
    let basis: PcaBasis = serde_json::from_str(good).unwrap();
    assert_eq!((basis.n(), basis.k()), (3, 1));
    let bad = [
        r#"{"n":3,"k":2,"basis":[1.0,0.0,0.0],"mass":null,"singular_values":[2.0,1.0]}"#,
        r#"{"n":3,"k":1,"basis":[1.0,0.0,0.0],"mass":[1.0,0.0,1.0],"singular_values":[2.0]}"#,
        r#"{"n":3,"k":1,"basis":[1.0,0.0,0.0],"mass":[1.0,1.0],"singular_values":[2.0]}"#,
        r#"{"n":3,"k":1,"basis":[1.0,0.0,0.0],"mass":null,"singular_values":[1.0,2.0]}"#,
        r#"{"n":3,"k":1,"basis":[1.0,0.0,0.0],"mass":null,"singular_values":[]}"#,
        r#"{"n":0,"k":0,"basis":[],"mass":null,"singular_values":[]}"#,
        r#"{"n":3,"k":1,"basis":[1.0,0.0,0.0],"mass":null,"singular_values":[2.0],"extra":1}"#,
    ];
    for text in bad {
        assert!(
            serde_json::from_str::<PcaBasis>(text).is_err(),
            "accepted {text}"
        );
    }
    // The message comes from the typed error.
    let err = serde_json::from_str::<PcaBasis>(bad[0])
        .unwrap_err()
        .to_string();
    assert!(err.contains("invalid PCA basis"), "{err}");
}
