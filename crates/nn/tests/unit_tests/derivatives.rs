//! VJP, JVP and Jacobian of the MLP and of the autoencoder's decoder against central finite
//! differences, and their mutual consistency, for every activation.

use nn::{Activation, Autoencoder, InputScaling, Mlp};

use super::{Rng, dot, random_mlp, rel_err};

const SIZES: [usize; 4] = [4, 7, 5, 6];

/// Central-difference Jacobian (n_out × n_in, column-major) of `f` at `z`.
fn fd_jacobian(f: &mut dyn FnMut(&[f64], &mut [f64]), z: &[f64], n_out: usize) -> Vec<f64> {
    let h = 1e-5;
    let mut jac = vec![0.0; n_out * z.len()];
    let (mut yp, mut ym) = (vec![0.0; n_out], vec![0.0; n_out]);
    for j in 0..z.len() {
        let mut zp = z.to_vec();
        let mut zm = z.to_vec();
        zp[j] += h;
        zm[j] -= h;
        f(&zp, &mut yp);
        f(&zm, &mut ym);
        for i in 0..n_out {
            jac[j * n_out + i] = (yp[i] - ym[i]) / (2.0 * h);
        }
    }
    jac
}

/// Jᵀv and Jw from a column-major Jacobian.
fn jt_v(jac: &[f64], v: &[f64], n_in: usize) -> Vec<f64> {
    let n_out = v.len();
    (0..n_in)
        .map(|j| dot(&jac[j * n_out..(j + 1) * n_out], v))
        .collect()
}

fn j_w(jac: &[f64], w: &[f64], n_out: usize) -> Vec<f64> {
    (0..n_out)
        .map(|i| (0..w.len()).map(|j| jac[j * n_out + i] * w[j]).sum())
        .collect()
}

#[test]
fn mlp_derivatives_match_finite_differences_for_every_activation() {
    for (a, act) in Activation::ALL.into_iter().enumerate() {
        let mlp = random_mlp(&SIZES, act, 10 + a as u64);
        let mut ws = mlp.workspace();
        let mut rng = Rng::new(100 + a as u64);
        for trial in 0..5 {
            let z = rng.vec(4);
            let v = rng.vec(6);
            let w = rng.vec(4);
            let mut fd_ws = mlp.workspace();
            let fd = fd_jacobian(&mut |x, y| mlp.forward(x, y, &mut fd_ws), &z, 6);

            let mut jac = vec![0.0; 24];
            mlp.jacobian(&z, &mut jac, &mut ws);
            let e = rel_err(&jac, &fd);
            assert!(e <= 1e-7, "{act} trial {trial}: Jacobian rel. error {e:e}");

            let mut vjp = vec![0.0; 4];
            mlp.vjp(&z, &v, &mut vjp, &mut ws);
            let e = rel_err(&vjp, &jt_v(&fd, &v, 4));
            assert!(e <= 1e-7, "{act} trial {trial}: VJP rel. error {e:e}");

            let mut jvp = vec![0.0; 6];
            mlp.jvp(&z, &w, &mut jvp, &mut ws);
            let e = rel_err(&jvp, &j_w(&fd, &w, 6));
            assert!(e <= 1e-7, "{act} trial {trial}: JVP rel. error {e:e}");
        }
    }
}

#[test]
fn jvp_and_vjp_are_adjoint_and_build_the_jacobian() {
    for (a, act) in Activation::ALL.into_iter().enumerate() {
        let mlp = random_mlp(&SIZES, act, 20 + a as u64);
        let mut ws = mlp.workspace();
        let mut rng = Rng::new(200 + a as u64);
        let z = rng.vec(4);
        let (v, w) = (rng.vec(6), rng.vec(4));
        let (mut jw, mut jtv) = (vec![0.0; 6], vec![0.0; 4]);
        mlp.jvp(&z, &w, &mut jw, &mut ws);
        mlp.vjp(&z, &v, &mut jtv, &mut ws);
        let (lhs, rhs) = (dot(&jw, &v), dot(&w, &jtv));
        assert!(
            (lhs - rhs).abs() <= 1e-13 * (1.0 + lhs.abs()),
            "{act}: <Jw, v> = {lhs} but <w, Jᵀv> = {rhs}"
        );

        let mut jac = vec![0.0; 24];
        mlp.jacobian(&z, &mut jac, &mut ws);
        for j in 0..4 {
            let mut e = vec![0.0; 4];
            e[j] = 1.0;
            mlp.jvp(&z, &e, &mut jw, &mut ws);
            assert!(
                rel_err(&jac[j * 6..(j + 1) * 6], &jw) <= 1e-14,
                "{act} column {j}"
            );
        }
        for i in 0..6 {
            let mut e = vec![0.0; 6];
            e[i] = 1.0;
            mlp.vjp(&z, &e, &mut jtv, &mut ws);
            let row: Vec<f64> = (0..4).map(|j| jac[j * 6 + i]).collect();
            assert!(rel_err(&row, &jtv) <= 1e-14, "{act} row {i}");
        }
    }
}

#[test]
fn workspace_reuse_leaves_no_stale_state() {
    let mlp = random_mlp(&SIZES, Activation::Elu, 3);
    let mut rng = Rng::new(4);
    let (z1, z2, v) = (rng.vec(4), rng.vec(4), rng.vec(6));
    let mut shared = mlp.workspace();
    let mut scratch = vec![0.0; 24];
    // Run every operation at z1, then each one at z2 must equal a fresh workspace's answer.
    mlp.jacobian(&z1, &mut scratch, &mut shared);
    let (mut a, mut b) = (vec![0.0; 4], vec![0.0; 4]);
    mlp.vjp(&z2, &v, &mut a, &mut shared);
    mlp.vjp(&z2, &v, &mut b, &mut mlp.workspace());
    assert_eq!(a, b);
    // The cached VJP after a forward equals the plain VJP, bit for bit.
    let mut y = vec![0.0; 6];
    mlp.forward(&z1, &mut y, &mut shared);
    mlp.vjp_cached(&v, &mut a, &mut shared);
    mlp.vjp(&z1, &v, &mut b, &mut shared);
    assert_eq!(a, b);
    // A network without hidden layers is affine: J = W.
    let lin = random_mlp(&[3, 2], Activation::Elu, 5);
    let mut jac = vec![0.0; 6];
    lin.jacobian(&[0.1, 0.2, 0.3], &mut jac, &mut lin.workspace());
    let w = lin.weights(0);
    for i in 0..2 {
        for j in 0..3 {
            assert_eq!(jac[j * 2 + i], w[i * 3 + j]);
        }
    }
}

#[test]
fn jacobian_follows_weight_changes_on_a_reused_workspace() {
    // The Jacobian keeps packed copies of the weights, W₂W₁ and W₂b₁ in the workspace; every
    // way of changing the parameters must make it repack, and a workspace moved between two
    // networks of the same shape must not mix them up. ELU takes the product over its nonlinear
    // units, which reads W₂W₁ and W₂b₁; tanh the plain one.
    for act in [Activation::Tanh, Activation::Elu] {
        let mut mlp = random_mlp(&[3, 9, 11, 5], act, 21);
        let other = random_mlp(&[3, 9, 11, 5], act, 22);
        let z = [0.2, -0.4, 0.7];
        let mut ws = mlp.workspace();
        let mut jac = vec![0.0; 15];
        let fresh = |mlp: &nn::Mlp| {
            let mut j = vec![0.0; 15];
            mlp.jacobian(&z, &mut j, &mut mlp.workspace());
            j
        };
        mlp.jacobian(&z, &mut jac, &mut ws);
        other.jacobian(&z, &mut jac, &mut ws);
        assert_eq!(jac, fresh(&other), "{act}");
        mlp.jacobian(&z, &mut jac, &mut ws);
        let before = jac.clone();
        mlp.weights_mut(2)[7] += 0.5;
        mlp.jacobian(&z, &mut jac, &mut ws);
        assert_eq!(jac, fresh(&mlp), "{act}");
        assert_ne!(jac, before, "{act}");
        // b₁ moves the value a₂ and so σ'(a₂): through W₂b₁ on the ELU path.
        let before = jac.clone();
        mlp.bias_mut(0).iter_mut().for_each(|b| *b += 0.3);
        mlp.jacobian(&z, &mut jac, &mut ws);
        assert_eq!(jac, fresh(&mlp), "{act}");
        assert_ne!(jac, before, "{act}");
        for p in mlp.parameters_mut() {
            p.iter_mut().for_each(|x| *x *= 0.9);
        }
        mlp.jacobian(&z, &mut jac, &mut ws);
        assert_eq!(jac, fresh(&mlp), "{act}");
        mlp.clone_from(&other);
        mlp.jacobian(&z, &mut jac, &mut ws);
        assert_eq!(jac, fresh(&other), "{act}");
    }
}

#[test]
fn jacobian_matches_the_jvp_whichever_units_have_a_unit_derivative() {
    // The Jacobian takes the product after the first hidden layer as W₂W₁ plus a correction
    // over the units whose σ' is not 1 when few are (ELU's a₁ ≤ 0 units), and as the plain
    // product otherwise. First-layer biases of +5 make (almost) every ELU unit linear, −5 none,
    // 0 about half; each case, with one hidden layer and with two, must give the columns of the
    // JVP (an independent forward pass per column).
    for sizes in [[4, 9, 6].as_slice(), &[4, 9, 11, 6], &[4, 30, 8, 5, 6]] {
        for (case, bias) in [5.0, 0.0, -5.0].into_iter().enumerate() {
            let mut mlp = random_mlp(sizes, Activation::Elu, 60 + case as u64);
            mlp.bias_mut(0).iter_mut().for_each(|b| *b += bias);
            let (n_in, n_out) = (sizes[0], sizes[sizes.len() - 1]);
            let mut rng = Rng::new(70 + case as u64);
            let z: Vec<f64> = rng.vec(n_in).iter().map(|x| 0.3 * x).collect();
            let mut ws = mlp.workspace();
            let mut jac = vec![f64::NAN; n_in * n_out];
            // Twice on one workspace: the second call reuses W₂W₁ and the support buffer.
            for _ in 0..2 {
                mlp.jacobian(&z, &mut jac, &mut ws);
                let mut jw = vec![0.0; n_out];
                for j in 0..n_in {
                    let mut e = vec![0.0; n_in];
                    e[j] = 1.0;
                    mlp.jvp(&z, &e, &mut jw, &mut mlp.workspace());
                    let col = &jac[j * n_out..(j + 1) * n_out];
                    let err = rel_err(col, &jw);
                    assert!(err <= 1e-13, "{sizes:?}, bias {bias}, column {j}: {err:e}");
                }
            }
        }
    }
}

/// f(z) by plain loops over the layers (the definition, no kernels).
fn plain_forward(mlp: &Mlp, z: &[f64]) -> Vec<f64> {
    let sizes = mlp.sizes();
    let mut x = z.to_vec();
    for l in 0..sizes.len() - 1 {
        let (w, b) = (mlp.weights(l), mlp.bias(l));
        let mut y: Vec<f64> = (0..sizes[l + 1])
            .map(|i| {
                b[i] + (0..sizes[l])
                    .map(|j| w[i * sizes[l] + j] * x[j])
                    .sum::<f64>()
            })
            .collect();
        if l + 2 < sizes.len() {
            y.iter_mut()
                .for_each(|y| *y = mlp.activations()[l].value(*y));
        }
        x = y;
    }
    x
}

#[test]
fn forward_and_vjp_match_plain_evaluations_whichever_units_are_linear() {
    // With a wide first layer, the second one runs over the first's nonlinear units only
    // (W₂h₁ = W₂W₁z + W₂b₁ + W₂[:, S](h₁ − a₁)[S], and the VJP likewise) when few enough are
    // nonlinear: first-layer biases of +5 make (almost) all ELU units linear, 0 about half, −5
    // none (the plain products). Each must give the plain forward pass, the VJP must be the
    // transpose of the JVP (a dense forward-mode pass), and `vjp` must equal `forward` then
    // `vjp_cached` bit for bit, with two and three hidden layers.
    for sizes in [[3, 40, 11, 5].as_slice(), &[3, 40, 9, 8, 5]] {
        for (case, bias) in [5.0, 0.0, -5.0].into_iter().enumerate() {
            let mut mlp = random_mlp(sizes, Activation::Elu, 80 + case as u64);
            mlp.bias_mut(0).iter_mut().for_each(|b| *b += bias);
            let (n_in, n_out) = (sizes[0], sizes[sizes.len() - 1]);
            let mut rng = Rng::new(90 + case as u64);
            let v = rng.vec(n_out);
            let mut ws = mlp.workspace();
            for trial in 0..3 {
                let z: Vec<f64> = rng.vec(n_in).iter().map(|x| 0.5 * x).collect();
                let what = format!("{sizes:?}, bias {bias}, trial {trial}");
                let mut y = vec![f64::NAN; n_out];
                mlp.forward(&z, &mut y, &mut ws);
                let err = rel_err(&y, &plain_forward(&mlp, &z));
                assert!(err <= 1e-13, "{what}: forward {err:e}");
                let mut cached = vec![f64::NAN; n_in];
                mlp.vjp_cached(&v, &mut cached, &mut ws);
                let mut direct = vec![f64::NAN; n_in];
                mlp.vjp(&z, &v, &mut direct, &mut ws);
                assert_eq!(cached, direct, "{what}: vjp against forward + vjp_cached");
                let jtv: Vec<f64> = (0..n_in)
                    .map(|j| {
                        let mut e = vec![0.0; n_in];
                        e[j] = 1.0;
                        let mut jw = vec![0.0; n_out];
                        mlp.jvp(&z, &e, &mut jw, &mut mlp.workspace());
                        dot(&jw, &v)
                    })
                    .collect();
                let err = rel_err(&direct, &jtv);
                assert!(err <= 1e-13, "{what}: VJP against the JVP {err:e}");
            }
            // New weights on the same workspace: W₂W₁, W₂b₁ and W₂ᵀ must follow.
            mlp.weights_mut(1).iter_mut().for_each(|w| *w *= -0.8);
            mlp.bias_mut(0)[0] += 0.1;
            let z = vec![0.1; n_in];
            let mut y = vec![f64::NAN; n_out];
            mlp.forward(&z, &mut y, &mut ws);
            let err = rel_err(&y, &plain_forward(&mlp, &z));
            assert!(
                err <= 1e-13,
                "{sizes:?}, bias {bias}: forward after new weights {err:e}"
            );
        }
    }
}

#[test]
#[should_panic(expected = "vjp_cached needs a forward pass")]
fn cached_vjp_without_forward_panics() {
    let mlp = random_mlp(&SIZES, Activation::Tanh, 3);
    let mut ws = mlp.workspace();
    let mut jac = vec![0.0; 24];
    mlp.jacobian(&[0.0; 4], &mut jac, &mut ws);
    mlp.vjp_cached(&[1.0; 6], &mut [0.0; 4], &mut ws);
}

/// The decoder with the linear skip (ŝ = dec(z) + (z, 0), in scaled units) against finite
/// differences, with and without scaling; the skip changes every derivative by an identity block.
#[test]
fn decoder_derivatives_with_the_linear_skip_match_finite_differences() {
    let (k, d) = (6, 3);
    let scaling = InputScaling::new(
        vec![0.5, -1.0, 0.0, 2.0, 1e-3, -1e-4],
        vec![10.0, 1.0, 0.1, 1e-2, 1e-3, 1e-4],
    )
    .unwrap();
    for (case, scaling) in [Some(scaling), None].into_iter().enumerate() {
        let mut ae = Autoencoder::new(
            random_mlp(&[k, 5, d], Activation::Elu, 40),
            random_mlp(&[d, 5, 4, k], Activation::Elu, 41),
            scaling,
        )
        .unwrap()
        .with_skip()
        .unwrap();
        // with_skip zeroes the output layers: put random ones back.
        let (enc, dec) = ae.networks_mut();
        *enc = random_mlp(&[k, 5, d], Activation::Elu, 42);
        *dec = random_mlp(&[d, 5, 4, k], Activation::Elu, 43);
        let mut ws = ae.workspace();
        let mut rng = Rng::new(44);
        let z = rng.vec(d);
        let (v, w) = (rng.vec(k), rng.vec(d));
        let mut fd_ws = ae.workspace();
        let fd = fd_jacobian(&mut |x, y| ae.decode(x, y, &mut fd_ws), &z, k);
        let mut jac = vec![0.0; k * d];
        ae.decode_jacobian(&z, &mut jac, &mut ws);
        assert!(rel_err(&jac, &fd) <= 1e-7, "case {case}: Jacobian");
        let mut jtv = vec![0.0; d];
        ae.decode_vjp(&z, &v, &mut jtv, &mut ws);
        assert!(rel_err(&jtv, &jt_v(&fd, &v, d)) <= 1e-7, "case {case}: VJP");
        let mut jw = vec![0.0; k];
        ae.decode_jvp(&z, &w, &mut jw, &mut ws);
        assert!(rel_err(&jw, &j_w(&fd, &w, k)) <= 1e-7, "case {case}: JVP");
        let mut q = vec![0.0; k];
        let mut cached = vec![0.0; d];
        ae.decode(&z, &mut q, &mut ws);
        ae.decode_vjp_cached(&v, &mut cached, &mut ws);
        assert_eq!(cached, jtv, "case {case}: cached VJP");
        // Without the skip the same networks give a different Jacobian (the skip is not a no-op).
        let plain = Autoencoder::new(
            ae.encoder().clone(),
            ae.decoder().clone(),
            ae.scaling().cloned(),
        )
        .unwrap();
        let mut jp = vec![0.0; k * d];
        plain.decode_jacobian(&z, &mut jp, &mut plain.workspace());
        assert!(rel_err(&jp, &jac) > 1e-3, "case {case}");
    }
}

/// A fresh skip autoencoder is the truncation to the leading d (scaled) features, and `anchor`
/// makes a chosen point round-trip exactly.
#[test]
fn skip_starts_as_truncation_and_anchor_is_exact() {
    let (k, d) = (5, 2);
    let ae = Autoencoder::with_architecture(k, d, &[8, 8], Activation::Elu, None, 7)
        .unwrap()
        .with_skip()
        .unwrap();
    let mut ws = ae.workspace();
    let q = [0.3, -1.2, 0.7, 2.0, -0.1];
    let mut out = [0.0; 5];
    ae.reconstruct(&q, &mut out, &mut ws);
    assert_eq!(out, [0.3, -1.2, 0.0, 0.0, 0.0]);

    let scaling = InputScaling::new(
        vec![0.1, 0.2, -0.3, 0.0, 0.5],
        vec![2.0, 1.0, 0.5, 0.1, 3.0],
    );
    let mut ae = Autoencoder::new(
        random_mlp(&[k, 6, d], Activation::Elu, 8),
        random_mlp(&[d, 6, k], Activation::Elu, 9),
        Some(scaling.unwrap()),
    )
    .unwrap();
    let rest = [0.0; 5];
    ae.reconstruct(&rest, &mut out, &mut ae.workspace());
    assert!(out.iter().any(|v| v.abs() > 1e-3), "{out:?}");
    let mut other = [0.0; 5];
    let p = [0.4, 0.1, -0.2, 0.3, 0.0];
    ae.reconstruct(&p, &mut other, &mut ae.workspace());
    ae.anchor(&rest);
    let mut anchored = [0.0; 5];
    ae.reconstruct(&rest, &mut anchored, &mut ae.workspace());
    assert!(anchored.iter().all(|v| v.abs() <= 1e-14), "{anchored:?}");
    // Every other point moves by the same constant −out.
    let mut moved = [0.0; 5];
    ae.reconstruct(&p, &mut moved, &mut ae.workspace());
    for i in 0..k {
        assert!((moved[i] - (other[i] - out[i])).abs() <= 1e-13);
    }
}

#[test]
fn decoder_derivatives_are_in_original_units() {
    let (k, d) = (6, 3);
    for act in [Activation::Elu, Activation::Softplus] {
        let encoder = random_mlp(&[k, 5, d], act, 30);
        let decoder = random_mlp(&[d, 5, 4, k], act, 31);
        // Scales spanning six orders of magnitude, as PCA coefficients do.
        let scaling = InputScaling::new(
            vec![0.5, -1.0, 0.0, 2.0, 1e-3, -1e-4],
            vec![10.0, 1.0, 0.1, 1e-2, 1e-3, 1e-4],
        )
        .unwrap();
        let ae = Autoencoder::new(encoder, decoder.clone(), Some(scaling.clone())).unwrap();
        let mut ws = ae.workspace();
        let mut rng = Rng::new(32);
        let z = rng.vec(d);
        let (v, w) = (rng.vec(k), rng.vec(d));

        // decode = shift + scale ⊙ decoder.
        let (mut q, mut raw) = (vec![0.0; k], vec![0.0; k]);
        ae.decode(&z, &mut q, &mut ws);
        decoder.forward(&z, &mut raw, &mut decoder.workspace());
        for i in 0..k {
            assert_eq!(q[i], scaling.shift()[i] + scaling.scale()[i] * raw[i]);
        }

        let mut fd_ws = ae.workspace();
        let fd = fd_jacobian(&mut |x, y| ae.decode(x, y, &mut fd_ws), &z, k);
        let mut jac = vec![0.0; k * d];
        ae.decode_jacobian(&z, &mut jac, &mut ws);
        assert!(rel_err(&jac, &fd) <= 1e-7, "{act} Jacobian");
        let mut jtv = vec![0.0; d];
        ae.decode_vjp(&z, &v, &mut jtv, &mut ws);
        assert!(rel_err(&jtv, &jt_v(&fd, &v, d)) <= 1e-7, "{act} VJP");
        let mut jw = vec![0.0; k];
        ae.decode_jvp(&z, &w, &mut jw, &mut ws);
        assert!(rel_err(&jw, &j_w(&fd, &w, k)) <= 1e-7, "{act} JVP");
        let (lhs, rhs) = (dot(&jw, &v), dot(&w, &jtv));
        assert!((lhs - rhs).abs() <= 1e-12 * (1.0 + lhs.abs()));

        // The cached VJP after decode equals the plain one.
        let mut cached = vec![0.0; d];
        ae.decode(&z, &mut q, &mut ws);
        ae.decode_vjp_cached(&v, &mut cached, &mut ws);
        assert_eq!(cached, jtv);

        // encode applies the scaling: encode(q) = encoder((q − shift)/scale).
        let q0 = rng.vec(k);
        let s: Vec<f64> = (0..k)
            .map(|i| (q0[i] - scaling.shift()[i]) / scaling.scale()[i])
            .collect();
        let (mut z1, mut z2) = (vec![0.0; d], vec![0.0; d]);
        ae.encode(&q0, &mut z1, &mut ws);
        ae.encoder()
            .forward(&s, &mut z2, &mut ae.encoder().workspace());
        assert_eq!(z1, z2);
    }
}

#[test]
fn derivatives_scale_to_the_autodef_shape() {
    // 6 → 200 → 200 → 49: the Jacobian columns still equal JVPs of unit vectors.
    let mlp = Mlp::new(&[6, 200, 200, 49], Activation::Elu, 9).unwrap();
    let mut ws = mlp.workspace();
    let z = [0.3, -0.2, 0.5, -0.7, 0.1, 0.9];
    let mut jac = vec![0.0; 49 * 6];
    mlp.jacobian(&z, &mut jac, &mut ws);
    let mut fd_ws = mlp.workspace();
    let fd = fd_jacobian(&mut |x, y| mlp.forward(x, y, &mut fd_ws), &z, 49);
    assert!(rel_err(&jac, &fd) <= 1e-7);
    let mut col = vec![0.0; 49];
    for j in 0..6 {
        let mut e = [0.0; 6];
        e[j] = 1.0;
        mlp.jvp(&z, &e, &mut col, &mut ws);
        assert!(rel_err(&jac[j * 49..(j + 1) * 49], &col) <= 1e-13);
    }
}

/// The number of first-layer units of `mlp` at `z` whose activation is not the identity there
/// (ELU: a₁ < 0), from a₁ = W₁z + b₁ computed here.
fn nonlinear_first_units(mlp: &Mlp, z: &[f64]) -> usize {
    let (n0, n1) = (mlp.sizes()[0], mlp.sizes()[1]);
    let (w, b) = (mlp.weights(0), mlp.bias(0));
    (0..n1)
        .filter(|&i| b[i] + (0..n0).map(|j| w[i * n0 + j] * z[j]).sum::<f64>() < 0.0)
        .count()
}

/// Whether the VJP at `z` runs its second layer over the first layer's nonlinear units S (the
/// condition `Mlp` documents for its sparse layer: two hidden layers or more and
/// 4 (|S| + n₀) < 3 n₁) with at least a tenth of the units in S, so that the correction over S
/// has work to do: a test can require the path it means to check.
fn takes_sparse_layer(mlp: &Mlp, z: &[f64]) -> bool {
    let (sizes, s) = (mlp.sizes(), nonlinear_first_units(mlp, z));
    sizes.len() > 3 && 4 * (s + sizes[0]) < 3 * sizes[1] && 10 * s >= sizes[1]
}

/// Jᵀv by central differences of v · f(z) with f = `f`, step `h`.
fn fd_vjp(f: &mut dyn FnMut(&[f64]) -> Vec<f64>, z: &[f64], v: &[f64], h: f64) -> Vec<f64> {
    (0..z.len())
        .map(|j| {
            let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
            zp[j] += h;
            zm[j] -= h;
            (dot(&f(&zp), v) - dot(&f(&zm), v)) / (2.0 * h)
        })
        .collect()
}

/// The decoder's VJP where it runs the second layer over the first layer's nonlinear units only
/// (the path a trained ELU decoder takes at run time) against central differences of the plain
/// forward pass: decoders shaped like the cantilever's (20 → 100 → 100 → k) and the catapult's
/// (24 → 200 → 200 → 89), a small one, and one with three hidden layers (the sparse layer below
/// a dense top layer), at first-layer bias shifts that leave 10–40 % of the units nonlinear, on
/// a fresh and on a reused workspace. Each case asserts that it takes the sparse path.
#[test]
fn sparse_layer_vjp_matches_finite_differences() {
    let cases: [(&[usize], f64); 5] = [
        (&[20, 100, 100, 60], 0.5),
        (&[24, 200, 200, 89], 0.3),
        (&[3, 40, 11, 5], 0.3),
        (&[4, 64, 32, 16, 12], 0.5),
        (&[6, 48, 48, 48, 30], 0.5),
    ];
    for (case, (sizes, shift)) in cases.into_iter().enumerate() {
        let mut mlp = random_mlp(sizes, Activation::Elu, 300 + case as u64);
        mlp.bias_mut(0).iter_mut().for_each(|b| *b += shift);
        let (n_in, n_out) = (sizes[0], sizes[sizes.len() - 1]);
        let mut rng = Rng::new(400 + case as u64);
        let mut reused = mlp.workspace();
        let mut sparse_trials = 0;
        for trial in 0..4 {
            let z: Vec<f64> = rng.vec(n_in).iter().map(|x| 0.5 * x).collect();
            let v = rng.vec(n_out);
            let what = format!("{sizes:?}, bias shift {shift}, trial {trial}");
            if !takes_sparse_layer(&mlp, &z) {
                continue;
            }
            sparse_trials += 1;
            let fd = fd_vjp(&mut |x| plain_forward(&mlp, x), &z, &v, 1e-6);
            for ws in [&mut reused, &mut mlp.workspace()] {
                let mut jtv = vec![f64::NAN; n_in];
                mlp.vjp(&z, &v, &mut jtv, ws);
                let err = rel_err(&jtv, &fd);
                assert!(err <= 1e-7, "{what}: VJP against differences {err:e}");
                let mut y = vec![0.0; n_out];
                mlp.forward(&z, &mut y, ws);
                mlp.vjp_cached(&v, &mut jtv, ws);
                let err = rel_err(&jtv, &fd);
                assert!(
                    err <= 1e-7,
                    "{what}: cached VJP against differences {err:e}"
                );
            }
        }
        assert!(
            sparse_trials >= 3,
            "{sizes:?}: only {sparse_trials} of 4 points take the sparse layer"
        );
    }
}

/// The same through the autoencoder's decode VJP as the latent simulation calls it: with the
/// input scaling and the linear skip, ∂/∂z of v · decode(z) by central differences of `decode`.
#[test]
fn sparse_layer_decode_vjp_matches_finite_differences() {
    let (k, d) = (30, 6);
    let mut rng = Rng::new(500);
    let shift: Vec<f64> = rng.vec(k).iter().map(|x| 0.1 * x).collect();
    let scale: Vec<f64> = (0..k).map(|i| 10f64.powi(-(i as i32 % 4))).collect();
    for (case, skip) in [false, true].into_iter().enumerate() {
        let scaling = InputScaling::new(shift.clone(), scale.clone()).unwrap();
        let encoder = random_mlp(&[k, 32, d], Activation::Elu, 501);
        let mut decoder = random_mlp(&[d, 120, 80, k], Activation::Elu, 502);
        decoder.bias_mut(0).iter_mut().for_each(|b| *b += 0.3);
        let mut ae = Autoencoder::new(encoder.clone(), decoder.clone(), Some(scaling)).unwrap();
        if skip {
            // with_skip zeroes the output layers: put the random ones back.
            ae = ae.with_skip().unwrap();
            let (enc, dec) = ae.networks_mut();
            *enc = encoder;
            *dec = decoder.clone();
        }
        let mut ws = ae.workspace();
        let mut fd_ws = ae.workspace();
        for trial in 0..3 {
            let z: Vec<f64> = rng.vec(d).iter().map(|x| 0.5 * x).collect();
            let v = rng.vec(k);
            let what = format!("skip {skip} (case {case}), trial {trial}");
            assert!(takes_sparse_layer(&decoder, &z), "{what}: dense path");
            let fd = fd_vjp(
                &mut |x| {
                    let mut q = vec![0.0; k];
                    ae.decode(x, &mut q, &mut fd_ws);
                    q
                },
                &z,
                &v,
                1e-6,
            );
            let mut jtv = vec![f64::NAN; d];
            ae.decode_vjp(&z, &v, &mut jtv, &mut ws);
            let err = rel_err(&jtv, &fd);
            assert!(
                err <= 1e-7,
                "{what}: decode VJP against differences {err:e}"
            );
            let mut q = vec![0.0; k];
            ae.decode(&z, &mut q, &mut ws);
            let mut cached = vec![f64::NAN; d];
            ae.decode_vjp_cached(&v, &mut cached, &mut ws);
            assert_eq!(cached, jtv, "{what}: cached decode VJP");
        }
    }
}
