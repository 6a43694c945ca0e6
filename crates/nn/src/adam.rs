//! Adam (Kingma & Ba 2015) over a list of parameter arrays.
//!
//! With gradient g at step t: m ← β₁m + (1 − β₁)g, v ← β₂v + (1 − β₂)g²,
//! θ ← θ − lr · m̂ / (√v̂ + ε) with the bias corrections m̂ = m/(1 − β₁ᵗ), v̂ = v/(1 − β₂ᵗ).

/// Adam's hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamParams {
    pub learning_rate: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
}

impl Default for AdamParams {
    /// lr 10⁻³, β₁ 0.9, β₂ 0.999, ε 10⁻⁸ (the paper's and Keras' defaults).
    fn default() -> Self {
        Self {
            learning_rate: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
        }
    }
}

/// The optimiser state: first and second moments per parameter array and the step count.
#[derive(Debug, Clone)]
pub struct Adam {
    params: AdamParams,
    step: u64,
    m: Vec<Vec<f64>>,
    v: Vec<Vec<f64>>,
}

impl Adam {
    /// State for parameter arrays of the given lengths (in the order `step` will see them).
    pub fn new(params: AdamParams, lengths: impl IntoIterator<Item = usize>) -> Self {
        let (m, v) = lengths
            .into_iter()
            .map(|n| (vec![0.0; n], vec![0.0; n]))
            .unzip();
        Self {
            params,
            step: 0,
            m,
            v,
        }
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One update of every array in `params` with the matching array of `grads`.
    ///
    /// # Panics
    /// If the arrays do not match the lengths given to [`Adam::new`].
    pub fn step<'p, 'g>(
        &mut self,
        params: impl Iterator<Item = &'p mut [f64]>,
        grads: impl Iterator<Item = &'g [f64]>,
    ) {
        self.step += 1;
        let AdamParams {
            learning_rate,
            beta1,
            beta2,
            epsilon,
        } = self.params;
        let t = self.step.min(i32::MAX as u64) as i32;
        let c1 = 1.0 / (1.0 - beta1.powi(t));
        let c2 = 1.0 / (1.0 - beta2.powi(t));
        let mut count = 0;
        for (((p, g), m), v) in params
            .zip(grads)
            .zip(self.m.iter_mut())
            .zip(self.v.iter_mut())
        {
            assert!(
                p.len() == g.len() && p.len() == m.len(),
                "parameter array {count} does not match the optimiser state"
            );
            let n = p.len();
            let (g, m, v) = (&g[..n], &mut m[..n], &mut v[..n]);
            for i in 0..n {
                let gi = g[i];
                m[i] = beta1 * m[i] + (1.0 - beta1) * gi;
                v[i] = beta2 * v[i] + (1.0 - beta2) * gi * gi;
                p[i] -= learning_rate * (m[i] * c1) / ((v[i] * c2).sqrt() + epsilon);
            }
            count += 1;
        }
        assert_eq!(count, self.m.len(), "fewer parameter arrays than the state");
    }
}
