//! The `[pca]` section: defaults, rule resolution and the field named by each error.

use pca::{DEFAULT_EXPLAINED_ENERGY, DimensionRule, PcaConfig, PcaError};

/// The fields named by the errors of `config`, in order.
fn error_fields(config: &PcaConfig) -> Vec<String> {
    let mut errors = Vec::new();
    config.check(&mut errors);
    errors
        .into_iter()
        .map(|e| match e {
            PcaError::InvalidConfig { field, .. } => field,
            other => panic!("unexpected error {other:?}"),
        })
        .collect()
}

#[test]
fn default_config_uses_the_default_energy_rule() {
    let config = PcaConfig::default();
    assert_eq!(config.max_dimension, 300);
    assert_eq!(
        config.rule().unwrap(),
        DimensionRule::ExplainedEnergy(DEFAULT_EXPLAINED_ENERGY)
    );
    // An empty section deserialises to the default.
    let parsed: PcaConfig = serde_json::from_str("{}").unwrap();
    assert_eq!(parsed, config);
}

#[test]
fn each_rule_resolves() {
    assert_eq!(
        PcaConfig::by_dimension(7).rule().unwrap(),
        DimensionRule::Count(7)
    );
    assert_eq!(
        PcaConfig::by_explained_energy(0.5).rule().unwrap(),
        DimensionRule::ExplainedEnergy(0.5)
    );
    assert_eq!(
        PcaConfig::by_explained_energy(1.0).rule().unwrap(),
        DimensionRule::ExplainedEnergy(1.0)
    );
    assert_eq!(
        PcaConfig::by_max_vertex_error(1e-3).rule().unwrap(),
        DimensionRule::MaxVertexError(1e-3)
    );
    let parsed: PcaConfig =
        serde_json::from_str(r#"{"max_vertex_error": 0.002, "max_dimension": 40}"#).unwrap();
    assert_eq!(parsed.rule().unwrap(), DimensionRule::MaxVertexError(0.002));
    assert_eq!(parsed.max_dimension, 40);
}

#[test]
fn invalid_values_name_their_field() {
    let cases: Vec<(PcaConfig, &str)> = vec![
        (PcaConfig::by_dimension(0), "pca.dimension"),
        (
            PcaConfig {
                dimension: Some(301),
                ..PcaConfig::default()
            },
            "pca.dimension",
        ),
        (PcaConfig::by_explained_energy(0.0), "pca.explained_energy"),
        (PcaConfig::by_explained_energy(-0.5), "pca.explained_energy"),
        (
            PcaConfig::by_explained_energy(1.0 + 1e-12),
            "pca.explained_energy",
        ),
        (
            PcaConfig::by_explained_energy(f64::NAN),
            "pca.explained_energy",
        ),
        (PcaConfig::by_max_vertex_error(0.0), "pca.max_vertex_error"),
        (
            PcaConfig::by_max_vertex_error(-1e-3),
            "pca.max_vertex_error",
        ),
        (
            PcaConfig::by_max_vertex_error(f64::NAN),
            "pca.max_vertex_error",
        ),
        (
            PcaConfig::by_max_vertex_error(f64::INFINITY),
            "pca.max_vertex_error",
        ),
        (
            PcaConfig {
                max_dimension: 0,
                explained_energy: Some(0.9),
                ..PcaConfig::default()
            },
            "pca.max_dimension",
        ),
        (
            PcaConfig {
                gravity_directions: Some(pca::MAX_GRAVITY_DIRECTIONS + 1),
                ..PcaConfig::default()
            },
            "pca.gravity_directions",
        ),
        (
            PcaConfig {
                patch_responses: Some(pca::MAX_PATCH_RESPONSES + 1),
                ..PcaConfig::default()
            },
            "pca.patch_responses",
        ),
    ];
    for (config, field) in cases {
        assert_eq!(error_fields(&config), vec![field.to_string()], "{config:?}");
        let err = config.rule().unwrap_err();
        assert!(err.to_string().contains(field), "{err}");
    }
}

#[test]
fn two_rules_are_rejected() {
    let config = PcaConfig {
        dimension: Some(5),
        max_vertex_error: Some(1e-3),
        ..PcaConfig::default()
    };
    assert_eq!(
        error_fields(&config),
        vec!["pca.max_vertex_error".to_string()]
    );
    let config = PcaConfig {
        dimension: Some(5),
        explained_energy: Some(0.9),
        max_vertex_error: Some(1e-3),
        ..PcaConfig::default()
    };
    let msg = config.validate().unwrap_err().to_string();
    assert!(
        msg.contains("`dimension`, `explained_energy`, `max_vertex_error`"),
        "{msg}"
    );
}

#[test]
fn several_errors_are_reported_together() {
    let config = PcaConfig {
        explained_energy: Some(2.0),
        max_dimension: 0,
        ..PcaConfig::default()
    };
    match config.validate() {
        Err(PcaError::Many(errors)) => assert_eq!(errors.len(), 2),
        other => panic!("expected two errors, got {other:?}"),
    }
}

#[test]
fn unknown_fields_are_rejected() {
    let err = serde_json::from_str::<PcaConfig>(r#"{"dimesion": 3}"#).unwrap_err();
    assert!(err.to_string().contains("dimesion"), "{err}");
}
