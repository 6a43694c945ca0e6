//! The `[cubature]` section and the serialised rule.

use cubature::{CubatureConfig, CubatureError, CubatureRule};

fn error_fields(config: &CubatureConfig) -> Vec<String> {
    let mut errors = Vec::new();
    config.check(&mut errors);
    errors
        .into_iter()
        .map(|e| match e {
            CubatureError::InvalidConfig { field, .. } => field,
            other => panic!("unexpected error {other:?}"),
        })
        .collect()
}

#[test]
fn defaults() {
    let c = CubatureConfig::default();
    assert_eq!(c.tolerance, 0.02);
    assert_eq!(
        (
            c.max_elements,
            c.candidates,
            c.max_poses,
            c.seed,
            c.memory_limit_mb
        ),
        (500, 200, 150, 0, 2048)
    );
    assert!(c.validate().is_ok());
    let parsed: CubatureConfig = serde_json::from_str("{}").unwrap();
    assert_eq!(parsed, c);
}

/// `neural_tolerance` replaces `tolerance` in the neural rule's settings only, and is absent
/// from the linear rule's (whose cache key must not move with it).
#[test]
fn the_neural_tolerance_sets_the_neural_rule_only() {
    let c = CubatureConfig {
        neural_tolerance: Some(0.005),
        max_elements: 800,
        ..CubatureConfig::default()
    };
    assert!(c.validate().is_ok());
    let neural = c.for_neural();
    assert_eq!((neural.tolerance, neural.neural_tolerance), (0.005, None));
    assert_eq!(neural.max_elements, 800);
    let linear = c.for_linear();
    assert_eq!(
        linear,
        CubatureConfig {
            max_elements: 800,
            ..CubatureConfig::default()
        }
    );
    // Without it both rules take `tolerance`, and the serialised section is unchanged.
    let plain = CubatureConfig::default();
    assert_eq!(plain.for_neural(), plain);
    assert!(!serde_json::to_string(&plain).unwrap().contains("neural"));
    let parsed: CubatureConfig = serde_json::from_str(r#"{"neural_tolerance": 0.005}"#).unwrap();
    assert_eq!(parsed.neural_tolerance, Some(0.005));
}

#[test]
fn invalid_values_name_their_field() {
    let d = CubatureConfig::default;
    let cases: Vec<(CubatureConfig, &str)> = vec![
        (
            CubatureConfig {
                tolerance: 0.0,
                ..d()
            },
            "cubature.tolerance",
        ),
        (
            CubatureConfig {
                tolerance: 1.0,
                ..d()
            },
            "cubature.tolerance",
        ),
        (
            CubatureConfig {
                tolerance: -0.1,
                ..d()
            },
            "cubature.tolerance",
        ),
        (
            CubatureConfig {
                tolerance: f64::NAN,
                ..d()
            },
            "cubature.tolerance",
        ),
        (
            CubatureConfig {
                neural_tolerance: Some(0.0),
                ..d()
            },
            "cubature.neural_tolerance",
        ),
        (
            CubatureConfig {
                neural_tolerance: Some(f64::INFINITY),
                ..d()
            },
            "cubature.neural_tolerance",
        ),
        (
            CubatureConfig {
                max_elements: 0,
                ..d()
            },
            "cubature.max_elements",
        ),
        (
            CubatureConfig {
                candidates: 0,
                ..d()
            },
            "cubature.candidates",
        ),
        (
            CubatureConfig {
                max_poses: 0,
                ..d()
            },
            "cubature.max_poses",
        ),
        (
            CubatureConfig {
                memory_limit_mb: 0,
                ..d()
            },
            "cubature.memory_limit_mb",
        ),
    ];
    for (config, field) in cases {
        assert_eq!(error_fields(&config), vec![field.to_string()], "{config:?}");
        let err = config.validate().unwrap_err();
        assert!(err.to_string().contains(field), "{err}");
    }
}

#[test]
fn several_errors_are_reported_together() {
    let config = CubatureConfig {
        tolerance: 2.0,
        candidates: 0,
        ..Default::default()
    };
    match config.validate() {
        Err(CubatureError::Many(errors)) => assert_eq!(errors.len(), 2),
        other => panic!("expected two errors, got {other:?}"),
    }
}

#[test]
fn config_round_trip_and_unknown_fields() {
    let c = CubatureConfig {
        tolerance: 0.013,
        neural_tolerance: Some(0.004),
        max_elements: 321,
        candidates: 64,
        max_poses: 80,
        seed: 99,
        memory_limit_mb: 512,
    };
    let json = serde_json::to_string(&c).unwrap();
    assert_eq!(serde_json::from_str::<CubatureConfig>(&json).unwrap(), c);
    let err = serde_json::from_str::<CubatureConfig>(r#"{"tolerence": 0.1}"#).unwrap_err();
    assert!(err.to_string().contains("tolerence"), "{err}");
}

fn rule() -> CubatureRule {
    CubatureRule {
        elements: vec![2, 7, 40],
        weights: vec![12.5, 0.1 + 0.2, 3.0e-7],
        training_error: 0.0187,
        tolerance_met: true,
        error_curve: vec![(1, 0.9), (2, 0.2), (3, 0.0187)],
    }
}

#[test]
fn rule_round_trip() {
    let r = rule();
    let json = serde_json::to_string(&r).unwrap();
    assert_eq!(serde_json::from_str::<CubatureRule>(&json).unwrap(), r);
    assert!(r.check_elements(41).is_ok());
    assert!(matches!(
        r.check_elements(40),
        Err(CubatureError::InvalidRule(_))
    ));
}

#[test]
fn corrupt_rules_are_rejected() {
    let mut cases = Vec::new();
    let mut r = rule();
    r.weights[1] = -1.0;
    cases.push((r, "weight of element 7"));
    let mut r = rule();
    r.elements = vec![7, 2, 40];
    cases.push((r, "strictly increasing"));
    let mut r = rule();
    r.weights.pop();
    cases.push((r, "3 elements but 2 weights"));
    for (bad, msg) in cases {
        let json = serde_json::to_string(&bad).unwrap();
        let err = serde_json::from_str::<CubatureRule>(&json).unwrap_err();
        assert!(err.to_string().contains(msg), "{err}");
    }
    let err = serde_json::from_str::<CubatureRule>(
        r#"{"elements":[],"weights":[],"training_error":1.0,"tolerance_met":false,"error_curve":[],"x":1}"#,
    )
    .unwrap_err();
    assert!(err.to_string().contains('x'), "{err}");
}
