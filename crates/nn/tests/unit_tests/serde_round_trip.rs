//! The model artifact: a serde round trip is bit-identical; corrupted artifacts are errors.

use faer::Mat;
use nn::{Activation, Autoencoder, InputScaling, Mlp, NnError};
use serde_json::{Value, json};

use super::{Rng, random_mlp};

fn model() -> Autoencoder {
    let mut rng = Rng::new(1);
    let data = Mat::from_fn(5, 30, |i, _| 10f64.powi(-(i as i32)) * rng.range(-1.0, 1.0));
    Autoencoder::new(
        random_mlp(&[5, 8, 2], Activation::Elu, 2),
        random_mlp(&[2, 8, 5], Activation::Elu, 3),
        Some(InputScaling::standardize(data.as_ref())),
    )
    .unwrap()
}

#[test]
fn json_round_trip_is_bit_identical() {
    let ae = model();
    let json = serde_json::to_string(&ae).unwrap();
    let back: Autoencoder = serde_json::from_str(&json).unwrap();
    assert_eq!(back, ae);
    let (mut w1, mut w2) = (ae.workspace(), back.workspace());
    let z = [0.37, -1.21];
    let v = [0.1, -0.2, 0.3, 1e-3, 7.0];
    let (mut q1, mut q2) = ([0.0; 5], [0.0; 5]);
    ae.decode(&z, &mut q1, &mut w1);
    back.decode(&z, &mut q2, &mut w2);
    assert_eq!(q1.map(f64::to_bits), q2.map(f64::to_bits));
    let (mut g1, mut g2) = ([0.0; 2], [0.0; 2]);
    ae.decode_vjp(&z, &v, &mut g1, &mut w1);
    back.decode_vjp(&z, &v, &mut g2, &mut w2);
    assert_eq!(g1.map(f64::to_bits), g2.map(f64::to_bits));
    let (mut j1, mut j2) = ([0.0; 10], [0.0; 10]);
    ae.decode_jacobian(&z, &mut j1, &mut w1);
    back.decode_jacobian(&z, &mut j2, &mut w2);
    assert_eq!(j1.map(f64::to_bits), j2.map(f64::to_bits));
    let value: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(value["format_version"], json!(Autoencoder::FORMAT_VERSION));
}

/// Deserialises `ae` after `corrupt` edits its JSON, expecting an error containing `needle`.
fn expect_error(corrupt: impl FnOnce(&mut Value), needle: &str) {
    let mut value = serde_json::to_value(model()).unwrap();
    corrupt(&mut value);
    let err = serde_json::from_value::<Autoencoder>(value).unwrap_err();
    assert!(err.to_string().contains(needle), "{err}");
}

#[test]
fn skip_round_trips_and_version_1_loads_without_it() {
    let mut ae = model().with_skip().unwrap();
    let (enc, dec) = ae.networks_mut();
    *enc = random_mlp(&[5, 8, 2], Activation::Elu, 4);
    *dec = random_mlp(&[2, 8, 5], Activation::Elu, 5);
    let json = serde_json::to_string(&ae).unwrap();
    let back: Autoencoder = serde_json::from_str(&json).unwrap();
    assert!(back.has_skip());
    assert_eq!(back, ae);

    // A version 1 artifact has no `skip` field: it loads as a plain autoencoder.
    let mut v1 = serde_json::to_value(model()).unwrap();
    v1["format_version"] = json!(1);
    v1.as_object_mut().unwrap().remove("skip");
    let old: Autoencoder = serde_json::from_value(v1.clone()).unwrap();
    assert!(!old.has_skip());
    v1["skip"] = json!(true);
    let err = serde_json::from_value::<Autoencoder>(v1).unwrap_err();
    assert!(
        err.to_string().contains("version 1 has no linear skip"),
        "{err}"
    );
}

#[test]
fn corrupted_artifacts_are_errors() {
    expect_error(|v| v["format_version"] = json!(99), "format version 99");
    expect_error(
        |v| {
            v["decoder"]["weights"][1].as_array_mut().unwrap().pop();
        },
        "layer 1 has 39 weights, expected 5 × 8",
    );
    expect_error(
        |v| v["encoder"]["sizes"] = json!([5, 8, 3]),
        "weights, expected 3 × 8",
    );
    expect_error(
        |v| v["encoder"]["biases"][0] = json!([0.0, 0.0]),
        "layer 0 has 2 biases, expected 8",
    );
    expect_error(
        |v| v["encoder"]["activations"] = json!([]),
        "0 activations for 1 hidden",
    );
    expect_error(|v| v["encoder"]["sizes"] = json!([5, 0, 2]), "width 0");
    expect_error(
        |v| v["scaling"]["scale"][2] = json!(-1.0),
        "scale 2 must be positive",
    );
    expect_error(
        |v| v["scaling"]["shift"] = json!([0.0]),
        "1 shifts and 5 scales",
    );
    expect_error(|v| v["extra"] = json!(1), "unknown field");
    expect_error(
        |v| v["decoder"]["weights"][0][3] = Value::Null,
        "invalid type: null",
    );
    // A decoder that does not invert the encoder's shapes.
    let enc = random_mlp(&[5, 8, 2], Activation::Elu, 2);
    let dec = random_mlp(&[3, 8, 5], Activation::Elu, 3);
    let mut value = serde_json::to_value(model()).unwrap();
    value["encoder"] = serde_json::to_value(&enc).unwrap();
    value["decoder"] = serde_json::to_value(&dec).unwrap();
    let err = serde_json::from_value::<Autoencoder>(value).unwrap_err();
    assert!(
        err.to_string()
            .contains("encoder maps 5 → 2 but decoder maps 3 → 5"),
        "{err}"
    );
}

#[test]
fn non_finite_parameters_are_rejected() {
    // JSON cannot carry NaN, so check the validation every loader goes through directly.
    let mlp = random_mlp(&[3, 4, 2], Activation::Tanh, 1);
    let mut weights: Vec<Vec<f64>> = (0..2).map(|l| mlp.weights(l).to_vec()).collect();
    let biases: Vec<Vec<f64>> = (0..2).map(|l| mlp.bias(l).to_vec()).collect();
    weights[1][5] = f64::NAN;
    let err = Mlp::from_parameters(
        vec![3, 4, 2],
        vec![Activation::Tanh],
        weights,
        biases.clone(),
    )
    .unwrap_err();
    assert!(matches!(err, NnError::InvalidNetwork(_)));
    assert!(
        err.to_string()
            .contains("layer 1 weight (row 1, column 1) is not finite"),
        "{err}"
    );
    let mut bad_bias = biases;
    bad_bias[0][0] = f64::INFINITY;
    let weights: Vec<Vec<f64>> = (0..2).map(|l| mlp.weights(l).to_vec()).collect();
    let err =
        Mlp::from_parameters(vec![3, 4, 2], vec![Activation::Tanh], weights, bad_bias).unwrap_err();
    assert!(
        err.to_string().contains("layer 0 bias 0 is not finite"),
        "{err}"
    );
    // A model whose weights were made non-finite after construction cannot be rebuilt.
    let mut ae = model();
    ae.networks_mut().1.weights_mut(0)[0] = f64::NAN;
    let (enc, dec) = (ae.encoder().clone(), ae.decoder().clone());
    assert!(Autoencoder::new(enc, dec, None).is_err());
}
