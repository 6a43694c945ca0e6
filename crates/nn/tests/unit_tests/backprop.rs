//! Gradients of the batch MSE loss with respect to every weight and bias against central finite
//! differences, Adam's update rule, and batched evaluation against single-sample evaluation.

use faer::Mat;
use nn::{Activation, Adam, AdamParams, Autoencoder, InputScaling, MlpGradient};

use super::{Rng, random_mlp};

/// Checks several random entries of every parameter array of `ae` (plus the largest-gradient one)
/// against a central difference of `loss`.
fn check_gradient(ae: &Autoencoder, data: &Mat<f64>, label: &str) {
    let (_, grad) = ae.loss_gradient(data.as_ref()).unwrap();
    let mut rng = Rng::new(77);
    let h = 1e-5;
    for net in 0..2 {
        let (g, layers): (&MlpGradient, usize) = if net == 0 {
            (&grad.encoder, ae.encoder().num_layers())
        } else {
            (&grad.decoder, ae.decoder().num_layers())
        };
        for l in 0..layers {
            for bias in [false, true] {
                let gl = if bias { g.bias(l) } else { g.weights(l) };
                let gmax = gl.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
                assert!(
                    gmax > 0.0,
                    "{label}: net {net} layer {l} has a zero gradient"
                );
                let argmax = gl.iter().position(|x| x.abs() == gmax).unwrap();
                let mut entries: Vec<usize> = (0..4).map(|_| rng.below(gl.len())).collect();
                // The last entry lies in the last row block of a layer split for parallelism.
                entries.extend([argmax, gl.len() - 1]);
                for i in entries {
                    let eval = |delta: f64| {
                        let mut p = ae.clone();
                        let (enc, dec) = p.networks_mut();
                        let mlp = if net == 0 { enc } else { dec };
                        let arr = if bias {
                            mlp.bias_mut(l)
                        } else {
                            mlp.weights_mut(l)
                        };
                        arr[i] += delta;
                        p.loss(data.as_ref()).unwrap()
                    };
                    let fd = (eval(h) - eval(-h)) / (2.0 * h);
                    let err = (gl[i] - fd).abs() / fd.abs().max(1e-3 * gmax);
                    assert!(
                        err <= 1e-6,
                        "{label}: net {net} layer {l} {} entry {i}: backprop {} vs FD {fd} \
                         (rel. {err:e})",
                        if bias { "bias" } else { "weight" },
                        gl[i]
                    );
                }
            }
        }
    }
}

#[test]
fn loss_gradient_matches_finite_differences() {
    let (k, d) = (5, 2);
    for (a, act) in [Activation::Elu, Activation::Tanh, Activation::Softplus]
        .into_iter()
        .enumerate()
    {
        let mut rng = Rng::new(40 + a as u64);
        // 70 samples: two parallel chunks of the fixed chunk size 64 are summed.
        let data = Mat::from_fn(k, 70, |i, _| (i as f64 + 1.0) * rng.range(-1.0, 1.0));
        let scaling = InputScaling::standardize(data.as_ref());
        let ae = Autoencoder::new(
            random_mlp(&[k, 6, 4, d], act, 50 + a as u64),
            random_mlp(&[d, 4, 6, k], act, 60 + a as u64),
            Some(scaling),
        )
        .unwrap();
        check_gradient(&ae, &data, &format!("{act}"));
    }
    // Layers of 130 × 100 weights are split into row blocks for the parallel weight gradient.
    let mut rng = Rng::new(45);
    let data = Mat::from_fn(k, 70, |i, _| (i as f64 + 1.0) * rng.range(-1.0, 1.0));
    let ae = Autoencoder::new(
        random_mlp(&[k, 130, 100, d], Activation::Elu, 46),
        random_mlp(&[d, 100, 130, k], Activation::Elu, 47),
        Some(InputScaling::standardize(data.as_ref())),
    )
    .unwrap();
    check_gradient(&ae, &data, "row blocks");
    // Without scaling and with a network without hidden layers in the encoder.
    let mut rng = Rng::new(3);
    let data = Mat::from_fn(3, 9, |_, _| rng.range(-2.0, 2.0));
    let ae = Autoencoder::new(
        random_mlp(&[3, 2], Activation::Elu, 1),
        random_mlp(&[2, 5, 3], Activation::Elu, 2),
        None,
    )
    .unwrap();
    check_gradient(&ae, &data, "unscaled");
    // With the linear skip (random output layers, so every path carries gradient).
    for (case, scaled) in [true, false].into_iter().enumerate() {
        let mut rng = Rng::new(70 + case as u64);
        let data = Mat::from_fn(k, 70, |i, _| (i as f64 + 1.0) * rng.range(-1.0, 1.0));
        let scaling = scaled.then(|| InputScaling::centre_uniform(data.as_ref()));
        let mut ae = Autoencoder::new(
            random_mlp(&[k, 6, d], Activation::Elu, 71),
            random_mlp(&[d, 6, k], Activation::Elu, 72),
            scaling,
        )
        .unwrap()
        .with_skip()
        .unwrap();
        let (enc, dec) = ae.networks_mut();
        *enc = random_mlp(&[k, 6, d], Activation::Elu, 73);
        *dec = random_mlp(&[d, 6, k], Activation::Elu, 74);
        check_gradient(&ae, &data, &format!("skip, scaled {scaled}"));
    }
}

#[test]
fn loss_is_the_mean_squared_scaled_reconstruction_error() {
    let mut rng = Rng::new(8);
    let data = Mat::from_fn(4, 100, |i, _| (i as f64 + 1.0) * rng.range(-1.0, 1.0));
    let scaling = InputScaling::standardize(data.as_ref());
    let ae = Autoencoder::new(
        random_mlp(&[4, 5, 2], Activation::Elu, 1),
        random_mlp(&[2, 5, 4], Activation::Elu, 2),
        Some(scaling.clone()),
    )
    .unwrap();
    // Independent single-sample evaluation.
    let mut ws = ae.workspace();
    let mut sum = 0.0;
    let mut out = vec![0.0; 4];
    let rec = ae.reconstruct_batch(data.as_ref()).unwrap();
    for j in 0..100 {
        let q: Vec<f64> = (0..4).map(|i| data[(i, j)]).collect();
        ae.reconstruct(&q, &mut out, &mut ws);
        for i in 0..4 {
            assert!((rec[(i, j)] - out[i]).abs() <= 1e-12 * (1.0 + out[i].abs()));
            sum += ((out[i] - q[i]) / scaling.scale()[i]).powi(2);
        }
    }
    let loss = ae.loss(data.as_ref()).unwrap();
    assert!(
        (loss - sum / 400.0).abs() <= 1e-12 * loss,
        "{loss} vs {}",
        sum / 400.0
    );
}

#[test]
fn adam_follows_the_update_rule() {
    let params = AdamParams {
        learning_rate: 0.1,
        beta1: 0.9,
        beta2: 0.99,
        epsilon: 1e-8,
    };
    let mut adam = Adam::new(params, [2]);
    let mut x = vec![1.0, -2.0];
    // First step: m̂ = g, v̂ = g², so every coordinate moves by lr·|g|/(|g| + ε) against g.
    adam.step(
        std::iter::once(x.as_mut_slice()),
        std::iter::once(&[4.0, -0.5][..]),
    );
    let first = [
        1.0 - 0.1 * 4.0 / (4.0 + 1e-8),
        -2.0 + 0.1 * 0.5 / (0.5 + 1e-8),
    ];
    assert!(
        (x[0] - first[0]).abs() < 1e-15 && (x[1] - first[1]).abs() < 1e-15,
        "{x:?}"
    );
    // Second step by hand.
    let g: [f64; 2] = [1.0, 3.0];
    let mut expect = x.clone();
    for i in 0..2 {
        let g1: f64 = [4.0, -0.5][i];
        let m = 0.9 * (0.1 * g1) + 0.1 * g[i];
        let v = 0.99 * (0.01 * g1 * g1) + 0.01 * g[i] * g[i];
        let (mh, vh) = (m / (1.0 - 0.81), v / (1.0 - 0.9801));
        expect[i] -= 0.1 * mh / (vh.sqrt() + 1e-8);
    }
    adam.step(std::iter::once(x.as_mut_slice()), std::iter::once(&g[..]));
    assert!((x[0] - expect[0]).abs() < 1e-14 && (x[1] - expect[1]).abs() < 1e-14);
    assert_eq!(adam.steps(), 2);
}

#[test]
fn batched_forward_equals_single_forward() {
    let mlp = random_mlp(&[5, 9, 7, 3], Activation::Tanh, 4);
    let mut rng = Rng::new(5);
    let c = 13;
    let x = rng.vec(5 * c);
    let mut bws = mlp.batch_workspace(c);
    let y = mlp.forward_batch(&x, c, &mut bws).to_vec();
    let mut ws = mlp.workspace();
    let mut one = vec![0.0; 3];
    for j in 0..c {
        mlp.forward(&x[j * 5..(j + 1) * 5], &mut one, &mut ws);
        for i in 0..3 {
            assert!((y[j * 3 + i] - one[i]).abs() <= 1e-14 * (1.0 + one[i].abs()));
        }
    }
}
