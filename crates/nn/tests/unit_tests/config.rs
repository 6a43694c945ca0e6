//! The `[autoencoder]` section: defaults, rule resolution and the field named by each error.

use nn::{Activation, AutoencoderConfig, DEFAULT_LATENT_DIM, LatentRule, NnError};

fn error_fields(config: &AutoencoderConfig) -> Vec<String> {
    let mut errors = Vec::new();
    config.check(&mut errors);
    errors
        .into_iter()
        .map(|e| match e {
            NnError::InvalidConfig { field, .. } => field,
            other => panic!("unexpected error {other:?}"),
        })
        .collect()
}

#[test]
fn defaults_are_valid_and_match_the_documentation() {
    let c = AutoencoderConfig::default();
    // Two layers as wide as the input, within [64, 200], unless the section says.
    assert_eq!(c.hidden, None);
    assert_eq!(c.hidden_widths(50), vec![64, 64]);
    assert_eq!(c.hidden_widths(93), vec![93, 93]);
    assert_eq!(c.hidden_widths(274), vec![200, 200]);
    let given = AutoencoderConfig {
        hidden: Some(vec![7]),
        ..AutoencoderConfig::default()
    };
    assert_eq!(given.hidden_widths(50), vec![7]);
    assert_eq!(c.activation, Activation::Elu);
    assert_eq!((c.epochs, c.batch_size, c.patience), (1000, 256, 100));
    assert_eq!(c.learning_rate, 1e-3);
    assert_eq!(c.validation_fraction, 0.1);
    assert!(c.input_scaling);
    assert_eq!(
        c.latent_rule().unwrap(),
        LatentRule::Fixed(DEFAULT_LATENT_DIM)
    );
    let parsed: AutoencoderConfig = serde_json::from_str("{}").unwrap();
    assert_eq!(parsed, c);
}

#[test]
fn rules_resolve() {
    let parsed: AutoencoderConfig = serde_json::from_str(
        r#"{"latent_dims": [3, 8], "max_vertex_error": 0.01, "activation": "tanh",
            "hidden": [100, 100]}"#,
    )
    .unwrap();
    assert_eq!(
        parsed.latent_rule().unwrap(),
        LatentRule::Search {
            lo: 3,
            hi: 8,
            tolerance: 0.01
        }
    );
    assert_eq!(parsed.activation, Activation::Tanh);
    let fixed: AutoencoderConfig = serde_json::from_str(r#"{"latent_dim": 4}"#).unwrap();
    assert_eq!(fixed.latent_rule().unwrap(), LatentRule::Fixed(4));
}

#[test]
fn invalid_values_name_their_field() {
    let d = AutoencoderConfig::default;
    let cases: Vec<(AutoencoderConfig, &str)> = vec![
        (
            AutoencoderConfig {
                latent_dim: Some(0),
                ..d()
            },
            "autoencoder.latent_dim",
        ),
        (
            AutoencoderConfig {
                latent_dims: Some([5, 3]),
                max_vertex_error: Some(1e-3),
                ..d()
            },
            "autoencoder.latent_dims",
        ),
        (
            AutoencoderConfig {
                latent_dims: Some([0, 3]),
                max_vertex_error: Some(1e-3),
                ..d()
            },
            "autoencoder.latent_dims",
        ),
        (
            AutoencoderConfig {
                latent_dims: Some([1, 3]),
                ..d()
            },
            "autoencoder.max_vertex_error",
        ),
        (
            AutoencoderConfig {
                latent_dims: Some([1, 3]),
                max_vertex_error: Some(-1.0),
                ..d()
            },
            "autoencoder.max_vertex_error",
        ),
        (
            AutoencoderConfig {
                latent_dim: Some(2),
                max_vertex_error: Some(1e-3),
                ..d()
            },
            "autoencoder.max_vertex_error",
        ),
        (
            AutoencoderConfig {
                latent_dim: Some(2),
                latent_dims: Some([1, 3]),
                max_vertex_error: Some(1e-3),
                ..d()
            },
            "autoencoder.latent_dims",
        ),
        (
            AutoencoderConfig {
                hidden: Some(vec![10, 0]),
                ..d()
            },
            "autoencoder.hidden",
        ),
        (AutoencoderConfig { epochs: 0, ..d() }, "autoencoder.epochs"),
        // A billion epochs once reserved a report for each before the first (48 GB).
        (
            AutoencoderConfig {
                epochs: 1_000_000_000,
                ..d()
            },
            "autoencoder.epochs",
        ),
        (
            AutoencoderConfig {
                restarts: usize::MAX,
                ..d()
            },
            "autoencoder.restarts",
        ),
        (
            AutoencoderConfig {
                batch_size: 0,
                ..d()
            },
            "autoencoder.batch_size",
        ),
        (
            AutoencoderConfig {
                learning_rate: 0.0,
                ..d()
            },
            "autoencoder.learning_rate",
        ),
        (
            AutoencoderConfig {
                final_learning_rate: Some(-1e-5),
                ..d()
            },
            "autoencoder.final_learning_rate",
        ),
        (
            AutoencoderConfig {
                final_learning_rate: Some(2e-3),
                ..d()
            },
            "autoencoder.final_learning_rate",
        ),
        (
            AutoencoderConfig {
                learning_rate: f64::NAN,
                ..d()
            },
            "autoencoder.learning_rate",
        ),
        (AutoencoderConfig { beta1: 1.0, ..d() }, "autoencoder.beta1"),
        (
            AutoencoderConfig { beta2: -0.1, ..d() },
            "autoencoder.beta2",
        ),
        (
            AutoencoderConfig {
                epsilon: 0.0,
                ..d()
            },
            "autoencoder.epsilon",
        ),
        (
            AutoencoderConfig {
                validation_fraction: 1.0,
                ..d()
            },
            "autoencoder.validation_fraction",
        ),
        (
            AutoencoderConfig {
                validation_fraction: f64::NAN,
                ..d()
            },
            "autoencoder.validation_fraction",
        ),
    ];
    for (config, field) in cases {
        assert_eq!(error_fields(&config), vec![field.to_string()], "{config:?}");
        let err = config.validate().unwrap_err();
        assert!(err.to_string().contains(field), "{err}");
    }
}

#[test]
fn several_errors_are_reported_together_and_unknown_fields_rejected() {
    let config = AutoencoderConfig {
        epochs: 0,
        batch_size: 0,
        ..AutoencoderConfig::default()
    };
    match config.validate() {
        Err(NnError::Many(errors)) => assert_eq!(errors.len(), 2),
        other => panic!("expected two errors, got {other:?}"),
    }
    let err = serde_json::from_str::<AutoencoderConfig>(r#"{"epoch": 3}"#).unwrap_err();
    assert!(err.to_string().contains("epoch"), "{err}");
    let err = serde_json::from_str::<AutoencoderConfig>(r#"{"activation": "gelu"}"#).unwrap_err();
    assert!(err.to_string().contains("gelu"), "{err}");
}

/// The learning rate stays constant by default; with `final_learning_rate` it falls along a half
/// cosine from the first epoch's `learning_rate` to the last epoch's final rate.
#[test]
fn the_learning_rate_decays_along_a_half_cosine() {
    let constant = AutoencoderConfig {
        epochs: 101,
        ..AutoencoderConfig::default()
    };
    assert!((1..=101).all(|e| constant.learning_rate_at(e) == 1e-3));
    let c = AutoencoderConfig {
        final_learning_rate: Some(1e-5),
        ..constant
    };
    c.validate().unwrap();
    assert_eq!(c.learning_rate_at(1), 1e-3);
    assert!((c.learning_rate_at(101) - 1e-5).abs() <= 1e-18);
    assert!((c.learning_rate_at(51) - 0.5 * (1e-3 + 1e-5)).abs() <= 1e-15);
    // A quarter of the way: f + (lr − f)(1 + cos(π/4))/2.
    let quarter = 1e-5 + (1e-3 - 1e-5) * (1.0 + std::f64::consts::FRAC_1_SQRT_2) / 2.0;
    assert!((c.learning_rate_at(26) - quarter).abs() <= 1e-15);
    assert!((1..101).all(|e| c.learning_rate_at(e + 1) < c.learning_rate_at(e)));
    let one = AutoencoderConfig { epochs: 1, ..c };
    assert_eq!(
        one.learning_rate_at(1),
        1e-3,
        "a single epoch runs at the first rate"
    );
}
