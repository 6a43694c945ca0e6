//! Elementwise activations σ applied after every hidden dense layer, with σ' for backpropagation.
//!
//! | name | σ(a) | σ'(a) |
//! |---|---|---|
//! | `elu` (default) | a if a > 0, else eᵃ − 1 | 1 if a > 0, else eᵃ |
//! | `tanh` | tanh a | 1 − tanh² a |
//! | `softplus` | ln(1 + eᵃ) | 1 / (1 + e⁻ᵃ) |
//! | `identity` | a | 1 |
//! | `relu` | max(a, 0) | 1 if a > 0, else 0 |
//!
//! The latent dynamics minimise an energy through the decoder, so the decoder should be smooth:
//! ELU is C¹ with a continuous, bounded derivative, tanh and softplus are C^∞. ReLU is accepted but
//! **unsuitable for simulation**: its Jacobian jumps whenever a pre-activation changes sign, which
//! makes the energy landscape piecewise and its gradient discontinuous (L-BFGS and Newton stall).

/// An elementwise activation function.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// Exponential linear unit with α = 1 (C¹; the default, as in AutoDef).
    #[default]
    Elu,
    /// Hyperbolic tangent.
    Tanh,
    /// ln(1 + eᵃ), a smooth ReLU.
    Softplus,
    /// No activation (a linear layer).
    Identity,
    /// max(a, 0). Non-smooth: unsuitable for simulation, see the module docs.
    Relu,
}

impl Activation {
    /// Every activation, for tests and error messages.
    pub const ALL: [Activation; 5] = [
        Activation::Elu,
        Activation::Tanh,
        Activation::Softplus,
        Activation::Identity,
        Activation::Relu,
    ];

    /// σ(a).
    #[inline]
    pub fn value(self, a: f64) -> f64 {
        match self {
            Activation::Elu => elu(a),
            Activation::Tanh => a.tanh(),
            Activation::Softplus => softplus(a),
            Activation::Identity => a,
            Activation::Relu => a.max(0.0),
        }
    }

    /// σ'(a), given also h = σ(a). Every activation's derivative is a function of its output
    /// alone (ELU: min(h, 0) + 1, tanh: 1 − h², softplus: 1 − e⁻ʰ, ReLU: 1 if h > 0 else 0),
    /// which is what this evaluates, so backpropagation need not keep the pre-activations; `a`
    /// is not read.
    #[inline]
    pub fn derivative(self, _a: f64, h: f64) -> f64 {
        self.derivative_from_output(h)
    }

    /// σ'(a) from h = σ(a) alone (see [`Activation::derivative`]).
    #[inline]
    pub fn derivative_from_output(self, h: f64) -> f64 {
        match self {
            Activation::Elu => elu_derivative(h),
            Activation::Tanh => 1.0 - h * h,
            Activation::Softplus => softplus_derivative(h),
            Activation::Identity => 1.0,
            Activation::Relu => relu_derivative(h),
        }
    }

    /// True for activations whose derivative is continuous (all but ReLU).
    pub fn is_smooth(self) -> bool {
        self != Activation::Relu
    }

    /// x ← σ(x) elementwise (pre-activations in, activations out). The match is outside the
    /// loop so each arm is a tight loop.
    #[inline(always)] // also into the SIMD kernels, compiled with their target features
    pub(crate) fn apply_in_place(self, x: &mut [f64]) {
        match self {
            Activation::Elu => x.iter_mut().for_each(|x| *x = elu(*x)),
            Activation::Tanh => x.iter_mut().for_each(|x| *x = x.tanh()),
            Activation::Softplus => x.iter_mut().for_each(|x| *x = softplus(*x)),
            Activation::Identity => {}
            Activation::Relu => x.iter_mut().for_each(|x| *x = x.max(0.0)),
        }
    }

    /// x ← σ(x + b) for every column x of a block (`x.len()` a multiple of `b.len()`): the bias
    /// and the activation in one pass over the block.
    #[inline(always)] // also into the SIMD kernels, compiled with their target features
    pub(crate) fn apply_biased(self, x: &mut [f64], b: &[f64]) {
        for col in x.chunks_exact_mut(b.len()) {
            let pairs = col.iter_mut().zip(b);
            match self {
                Activation::Elu => pairs.for_each(|(x, b)| *x = elu(*x + b)),
                Activation::Tanh => pairs.for_each(|(x, b)| *x = (*x + b).tanh()),
                Activation::Softplus => pairs.for_each(|(x, b)| *x = softplus(*x + b)),
                Activation::Identity => pairs.for_each(|(x, b)| *x += b),
                Activation::Relu => pairs.for_each(|(x, b)| *x = (*x + b).max(0.0)),
            }
        }
    }

    /// g ← σ'(a) ⊙ g elementwise, given h = σ(a) (the backward step through the activation).
    #[inline(always)] // also into the SIMD kernels, compiled with their target features
    pub(crate) fn scale_by_derivative(self, h: &[f64], g: &mut [f64]) {
        let g = &mut g[..h.len()];
        match self {
            Activation::Elu => g
                .iter_mut()
                .zip(h)
                .for_each(|(g, &h)| *g *= elu_derivative(h)),
            Activation::Tanh => g.iter_mut().zip(h).for_each(|(g, &h)| *g *= 1.0 - h * h),
            Activation::Softplus => g
                .iter_mut()
                .zip(h)
                .for_each(|(g, &h)| *g *= softplus_derivative(h)),
            Activation::Identity => {}
            Activation::Relu => g
                .iter_mut()
                .zip(h)
                .for_each(|(g, &h)| *g *= relu_derivative(h)),
        }
    }
}

impl std::fmt::Display for Activation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Activation::Elu => "elu",
            Activation::Tanh => "tanh",
            Activation::Softplus => "softplus",
            Activation::Identity => "identity",
            Activation::Relu => "relu",
        })
    }
}

#[inline]
fn elu(a: f64) -> f64 {
    // Both branches are computed so the loop stays branch-free and vectorises.
    let e = expm1_nonpositive(a.min(0.0));
    if a > 0.0 { a } else { e }
}

/// eˣ − 1 for x ≤ 0, accurate to a few ulps, branch-free and vectorisable (libm's `exp_m1` is an
/// opaque call that dominated training time).
///
/// x = k ln 2 + r with |r| ≤ ln2/2 (Cody–Waite split of ln 2), eʳ − 1 by its degree-13 Taylor
/// polynomial (truncation below 10⁻¹⁷ relative), then eˣ − 1 = 2ᵏ(eʳ − 1) + (2ᵏ − 1), where both
/// terms are exact for the k that occur, so there is no cancellation near 0.
#[inline]
fn expm1_nonpositive(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    // Adding 1.5·2⁵² rounds to an integer held in the low mantissa bits.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    // Below −700 the result is −1 to double precision; clamping keeps 2ᵏ a normal number.
    let x = x.max(-700.0);
    let t = x * LOG2E + MAGIC;
    let kf = t - MAGIC;
    let k = (t.to_bits() as i64).wrapping_sub(MAGIC.to_bits() as i64);
    let r = (x - kf * LN2_HI) - kf * LN2_LO;
    // Estrin's scheme: four independent chains instead of one long Horner chain.
    const C: [f64; 13] = [
        1.0,
        0.5,
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 120.0,
        1.0 / 720.0,
        1.0 / 5_040.0,
        1.0 / 40_320.0,
        1.0 / 362_880.0,
        1.0 / 3_628_800.0,
        1.0 / 39_916_800.0,
        1.0 / 479_001_600.0,
        1.0 / 6_227_020_800.0,
    ];
    // eʳ − 1 = r · Σ_{i<13} C_i rⁱ.
    let r2 = r * r;
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    let p01 = C[0] + C[1] * r;
    let p23 = C[2] + C[3] * r;
    let p45 = C[4] + C[5] * r;
    let p67 = C[6] + C[7] * r;
    let p89 = C[8] + C[9] * r;
    let p1011 = C[10] + C[11] * r;
    let p03 = p01 + p23 * r2;
    let p47 = p45 + p67 * r2;
    let p811 = p89 + p1011 * r2;
    let p07 = p03 + p47 * r4;
    let p812 = p811 + C[12] * r4;
    let p = p07 + p812 * r8;
    let em1_r = p * r;
    let two_k = f64::from_bits((k.wrapping_add(1023) as u64) << 52);
    two_k * em1_r + (two_k - 1.0)
}

#[inline]
fn elu_derivative(h: f64) -> f64 {
    // σ'(a) = eᵃ = σ(a) + 1 for a ≤ 0 (where σ ≤ 0) and 1 for a > 0 (where σ > 0): min(h, 0) + 1
    // selects without a branch, so the loops vectorise.
    h.min(0.0) + 1.0
}

#[inline]
fn softplus(a: f64) -> f64 {
    // max(a, 0) + ln(1 + e^{-|a|}) never overflows.
    a.max(0.0) + (-a.abs()).exp().ln_1p()
}

/// The logistic function 1/(1 + e⁻ᵃ) from h = ln(1 + eᵃ): eʰ = 1 + eᵃ, so σ' = 1 − e⁻ʰ, computed
/// as −expm1(−h) to stay accurate when h is tiny (a ≪ 0).
#[inline]
fn softplus_derivative(h: f64) -> f64 {
    -(-h).exp_m1()
}

#[inline]
fn relu_derivative(h: f64) -> f64 {
    // h = max(a, 0) > 0 exactly when a > 0.
    if h > 0.0 { 1.0 } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_expm1_matches_libm() {
        let mut worst: f64 = 0.0;
        for i in 0..200_000 {
            // Dense near 0 (cancellation), then out to the clamp.
            let x = -(i as f64 * 1e-5).powi(3) - 1e-300 * i as f64;
            let (a, b) = (expm1_nonpositive(x), x.exp_m1());
            worst = worst.max((a - b).abs() / b.abs().max(f64::MIN_POSITIVE));
        }
        assert!(worst < 4.0 * f64::EPSILON, "worst relative error {worst:e}");
        assert_eq!(expm1_nonpositive(0.0), 0.0);
        assert_eq!(expm1_nonpositive(-800.0), -1.0);
        assert_eq!(expm1_nonpositive(f64::NEG_INFINITY), -1.0);
        assert_eq!(elu(2.5), 2.5);
    }

    #[test]
    fn derivatives_from_the_output_match_the_textbook_formulas() {
        for i in 0..=800 {
            let a = -40.0 + 0.1 * i as f64;
            let textbook = [
                (Activation::Elu, if a > 0.0 { 1.0 } else { a.exp() }),
                (Activation::Tanh, 1.0 / a.cosh().powi(2)),
                (Activation::Softplus, 1.0 / (1.0 + (-a).exp())),
                (Activation::Identity, 1.0),
                (Activation::Relu, if a > 0.0 { 1.0 } else { 0.0 }),
            ];
            for (act, want) in textbook {
                let got = act.derivative_from_output(act.value(a));
                // Absolute error at the rounding level of σ near ±1 (ELU, tanh saturate there).
                assert!(
                    (got - want).abs() <= 1e-13 * want.abs() + 4.0 * f64::EPSILON,
                    "{act} at {a}: {got} vs {want}"
                );
            }
        }
    }
}
