//! The dense multilayer perceptron y = f(x) and its exact derivatives at one input.
//!
//! With layer sizes n₀ → n₁ → … → n_L, dense layer l computes a_l = W_l h_{l−1} + b_l with
//! h₀ = x; hidden layers apply an activation h_l = σ_l(a_l) and the output is linear, y = a_L.
//! With D_l = diag(σ_l'(a_l)) the Jacobian is J = W_L D_{L−1} W_{L−1} ⋯ D₁ W₁, and
//!
//! * [`Mlp::vjp`] computes Jᵀv by one forward pass and one backward pass (reverse mode),
//! * [`Mlp::jvp`] computes Jw by pushing the pair [h | t] through the layers (forward mode, one
//!   two-column product per layer),
//! * [`Mlp::jacobian`] computes J by pushing [h | I] through the layers (forward mode with n₀
//!   tangent columns at once). For a decoder n₀ = d is small (≈ 6), so this costs a few forward
//!   passes, far less than n_L reverse passes.
//!
//! None of them allocate: scratch lives in an [`MlpWorkspace`] made once by [`Mlp::workspace`].
//! Batched evaluation and backpropagation for training are in [`crate::batch`].

use crate::{Activation, NnError, SplitMix64, linalg};

/// A dense feed-forward network with an activation on every hidden layer and a linear output.
///
/// Weights are stored row-major (`n_out × n_in`, one output neuron per contiguous row) so every
/// product runs on contiguous memory. Deserialisation validates sizes and finiteness.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "MlpData")]
pub struct Mlp {
    /// Layer widths n₀, …, n_L (at least two).
    sizes: Vec<usize>,
    /// One activation per hidden layer (`sizes.len() − 2`).
    activations: Vec<Activation>,
    /// W_l, row-major `sizes[l+1] × sizes[l]`.
    weights: Vec<Vec<f64>>,
    /// b_l, length `sizes[l+1]`.
    biases: Vec<Vec<f64>>,
}

/// The serialised form, validated into an [`Mlp`] on deserialisation.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct MlpData {
    sizes: Vec<usize>,
    activations: Vec<Activation>,
    weights: Vec<Vec<f64>>,
    biases: Vec<Vec<f64>>,
}

impl TryFrom<MlpData> for Mlp {
    type Error = NnError;

    fn try_from(d: MlpData) -> Result<Self, NnError> {
        Mlp::from_parameters(d.sizes, d.activations, d.weights, d.biases)
    }
}

fn check_architecture(sizes: &[usize], activations: &[Activation]) -> Result<(), NnError> {
    let bad = |reason: String| Err(NnError::InvalidNetwork(reason));
    if sizes.len() < 2 {
        return bad(format!(
            "a network needs at least an input and an output size, got {sizes:?}"
        ));
    }
    if let Some(l) = sizes.iter().position(|&n| n == 0) {
        return bad(format!("layer {l} has width 0 (sizes {sizes:?})"));
    }
    if activations.len() != sizes.len() - 2 {
        return bad(format!(
            "{} activations for {} hidden layers (sizes {sizes:?})",
            activations.len(),
            sizes.len() - 2
        ));
    }
    Ok(())
}

impl Mlp {
    /// A network with layer widths `sizes` (input, hidden…, output), `activation` on every hidden
    /// layer, Glorot-uniform weights drawn from SplitMix64(`seed`) and zero biases.
    ///
    /// Glorot uniform (W ~ U(±√(6/(n_in + n_out)))) is Keras' default, which AutoDef trained with.
    pub fn new(sizes: &[usize], activation: Activation, seed: u64) -> Result<Self, NnError> {
        let activations = vec![activation; sizes.len().saturating_sub(2)];
        Self::with_activations(sizes, &activations, seed)
    }

    /// Like [`Mlp::new`] with one activation per hidden layer.
    pub fn with_activations(
        sizes: &[usize],
        activations: &[Activation],
        seed: u64,
    ) -> Result<Self, NnError> {
        check_architecture(sizes, activations)?;
        let mut rng = SplitMix64::new(seed);
        let weights = sizes
            .windows(2)
            .map(|w| {
                let (n_in, n_out) = (w[0], w[1]);
                let limit = (6.0 / (n_in + n_out) as f64).sqrt();
                (0..n_in * n_out)
                    .map(|_| rng.range(-limit, limit))
                    .collect()
            })
            .collect();
        let biases = sizes[1..].iter().map(|&n| vec![0.0; n]).collect();
        Ok(Self {
            sizes: sizes.to_vec(),
            activations: activations.to_vec(),
            weights,
            biases,
        })
    }

    /// A network from explicit parameters: `weights[l]` row-major `sizes[l+1] × sizes[l]`,
    /// `biases[l]` of length `sizes[l+1]`, all finite.
    pub fn from_parameters(
        sizes: Vec<usize>,
        activations: Vec<Activation>,
        weights: Vec<Vec<f64>>,
        biases: Vec<Vec<f64>>,
    ) -> Result<Self, NnError> {
        check_architecture(&sizes, &activations)?;
        let bad = |reason: String| Err(NnError::InvalidNetwork(reason));
        let layers = sizes.len() - 1;
        if weights.len() != layers || biases.len() != layers {
            return bad(format!(
                "{} weight and {} bias arrays for {layers} layers",
                weights.len(),
                biases.len()
            ));
        }
        for l in 0..layers {
            let (n_in, n_out) = (sizes[l], sizes[l + 1]);
            if weights[l].len() != n_in * n_out {
                return bad(format!(
                    "layer {l} has {} weights, expected {n_out} × {n_in} = {}",
                    weights[l].len(),
                    n_in * n_out
                ));
            }
            if biases[l].len() != n_out {
                return bad(format!(
                    "layer {l} has {} biases, expected {n_out}",
                    biases[l].len()
                ));
            }
            if let Some(i) = weights[l].iter().position(|x| !x.is_finite()) {
                return bad(format!(
                    "layer {l} weight (row {}, column {}) is not finite: {}",
                    i / n_in,
                    i % n_in,
                    weights[l][i]
                ));
            }
            if let Some(i) = biases[l].iter().position(|x| !x.is_finite()) {
                return bad(format!(
                    "layer {l} bias {i} is not finite: {}",
                    biases[l][i]
                ));
            }
        }
        Ok(Self {
            sizes,
            activations,
            weights,
            biases,
        })
    }

    /// Layer widths n₀, …, n_L.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    /// n₀.
    pub fn input_dim(&self) -> usize {
        self.sizes[0]
    }

    /// n_L.
    pub fn output_dim(&self) -> usize {
        self.sizes[self.sizes.len() - 1]
    }

    /// The number of dense layers L (hidden layers + the output layer).
    pub fn num_layers(&self) -> usize {
        self.sizes.len() - 1
    }

    /// The activation of each hidden layer.
    pub fn activations(&self) -> &[Activation] {
        &self.activations
    }

    /// W_l, row-major `sizes[l+1] × sizes[l]`.
    pub fn weights(&self, layer: usize) -> &[f64] {
        &self.weights[layer]
    }

    /// W_l, mutable (the caller keeps it finite).
    pub fn weights_mut(&mut self, layer: usize) -> &mut [f64] {
        &mut self.weights[layer]
    }

    /// b_l.
    pub fn bias(&self, layer: usize) -> &[f64] {
        &self.biases[layer]
    }

    /// b_l, mutable (the caller keeps it finite).
    pub fn bias_mut(&mut self, layer: usize) -> &mut [f64] {
        &mut self.biases[layer]
    }

    /// The total number of weights and biases.
    pub fn num_parameters(&self) -> usize {
        self.weights.iter().map(Vec::len).sum::<usize>()
            + self.biases.iter().map(Vec::len).sum::<usize>()
    }

    /// Every parameter array in a fixed order (W₁, b₁, W₂, b₂, …), as the optimiser sees them.
    pub fn parameters_mut(&mut self) -> impl Iterator<Item = &mut [f64]> {
        self.weights
            .iter_mut()
            .zip(self.biases.iter_mut())
            .flat_map(|(w, b)| [w.as_mut_slice(), b.as_mut_slice()])
    }

    /// The lengths of the arrays of [`Mlp::parameters_mut`], in the same order.
    pub fn parameter_lengths(&self) -> impl Iterator<Item = usize> + '_ {
        self.weights
            .iter()
            .zip(&self.biases)
            .flat_map(|(w, b)| [w.len(), b.len()])
    }

    /// True when every weight and bias is finite.
    pub fn is_finite(&self) -> bool {
        self.weights
            .iter()
            .chain(&self.biases)
            .all(|p| p.iter().all(|x| x.is_finite()))
    }

    /// The activation after dense layer `l` (hidden layers only).
    fn activation(&self, l: usize) -> Activation {
        self.activations[l]
    }

    /// Scratch memory for the single-input operations of this network.
    pub fn workspace(&self) -> MlpWorkspace {
        MlpWorkspace::new(&self.sizes)
    }

    fn check_workspace(&self, ws: &MlpWorkspace) {
        assert_eq!(
            ws.sizes, self.sizes,
            "the workspace was made for another network"
        );
    }

    /// out = f(z). Also leaves the forward state in `ws` for [`Mlp::vjp_cached`].
    pub fn forward(&self, z: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        assert_eq!(z.len(), self.input_dim(), "input length");
        assert_eq!(out.len(), self.output_dim(), "output length");
        let last = self.num_layers() - 1;
        for l in 0..=last {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let x: &[f64] = if l == 0 { z } else { &ws.post[l - 1] };
            let a = &mut ws.pre[l];
            linalg::mul_w(a, &self.weights[l], x, n_out, n_in, 1);
            a.iter_mut().zip(&self.biases[l]).for_each(|(a, b)| *a += b);
            if l < last {
                self.activation(l).apply(&ws.pre[l], &mut ws.post[l]);
            }
        }
        out.copy_from_slice(&ws.pre[last]);
        ws.cached = true;
    }

    /// out = J(z)ᵀ v, the vector–Jacobian product (one forward and one backward pass).
    pub fn vjp(&self, z: &[f64], v: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        assert_eq!(z.len(), self.input_dim(), "input length");
        let last = self.num_layers() - 1;
        for l in 0..last {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let x: &[f64] = if l == 0 { z } else { &ws.post[l - 1] };
            let a = &mut ws.pre[l];
            linalg::mul_w(a, &self.weights[l], x, n_out, n_in, 1);
            a.iter_mut().zip(&self.biases[l]).for_each(|(a, b)| *a += b);
            self.activation(l).apply(&ws.pre[l], &mut ws.post[l]);
        }
        // The output layer's value is not needed for Jᵀv; mark the cache partial.
        ws.cached = false;
        self.backward(v, out, ws);
    }

    /// out = J(z)ᵀ v at the z of the last [`Mlp::forward`] on `ws` (saves the forward pass when
    /// the caller needs f(z) first, e.g. to form v = ∂E/∂y).
    ///
    /// # Panics
    /// If `ws` holds no complete forward pass.
    pub fn vjp_cached(&self, v: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        assert!(
            ws.cached,
            "vjp_cached needs a forward pass on this workspace"
        );
        self.backward(v, out, ws);
    }

    /// Reverse sweep from v = ∂/∂y using the hidden pre-activations and activations in `ws`.
    fn backward(&self, v: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        assert_eq!(v.len(), self.output_dim(), "cotangent length");
        assert_eq!(out.len(), self.input_dim(), "output length");
        let last = self.num_layers() - 1;
        ws.ga[..v.len()].copy_from_slice(v);
        for l in (1..=last).rev() {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            linalg::mul_wt(&mut ws.gh, &self.weights[l], &ws.ga, n_out, n_in, 1);
            self.activation(l - 1)
                .scale_by_derivative(&ws.post[l - 1], &mut ws.gh);
            std::mem::swap(&mut ws.ga, &mut ws.gh);
        }
        let (n_in, n_out) = (self.sizes[0], self.sizes[1]);
        linalg::mul_wt(out, &self.weights[0], &ws.ga, n_out, n_in, 1);
    }

    /// out = J(z) w, the Jacobian–vector product (forward mode; the value and the tangent share
    /// one two-column product per layer, so W is read once).
    pub fn jvp(&self, z: &[f64], w: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        assert_eq!(w.len(), self.input_dim(), "tangent length");
        assert_eq!(out.len(), self.output_dim(), "output length");
        self.tangent_forward(z, w, 1, out, ws);
    }

    /// out = J(z), the full `n_L × n₀` Jacobian, column-major (column j = ∂f/∂z_j).
    pub fn jacobian(&self, z: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        let n0 = self.input_dim();
        assert_eq!(
            out.len(),
            self.output_dim() * n0,
            "Jacobian length (n_out × n_in)"
        );
        // Seed the tangents with the identity: column 1 + j of X₀ is e_j.
        let x0 = &mut ws.tan[0];
        x0[n0..n0 * (1 + n0)].fill(0.0);
        for j in 0..n0 {
            x0[n0 * (1 + j) + j] = 1.0;
        }
        self.tangent_forward_seeded(z, n0, out, ws);
    }

    /// Forward mode with `m` tangent columns `t` (n₀ × m, column-major): out = J t.
    fn tangent_forward(
        &self,
        z: &[f64],
        t: &[f64],
        m: usize,
        out: &mut [f64],
        ws: &mut MlpWorkspace,
    ) {
        let n0 = self.input_dim();
        ws.tan[0][n0..n0 * (1 + m)].copy_from_slice(&t[..n0 * m]);
        self.tangent_forward_seeded(z, m, out, ws);
    }

    /// Forward mode when `ws.tan[0]` already holds the tangents in columns 1..=m.
    ///
    /// X_l = [h_l | T_l] (n_l × (1 + m)); Y = W_{l+1} X_l; h_{l+1} = σ(Y₀ + b);
    /// T_{l+1} = σ'(Y₀ + b) ⊙ Y_{1..}. The output layer only needs W_L T_{L−1}.
    fn tangent_forward_seeded(&self, z: &[f64], m: usize, out: &mut [f64], ws: &mut MlpWorkspace) {
        assert_eq!(z.len(), self.input_dim(), "input length");
        let n0 = self.input_dim();
        ws.tan[0][..n0].copy_from_slice(z);
        let last = self.num_layers() - 1;
        for l in 0..last {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let y = &mut ws.y;
            linalg::mul_w(y, &self.weights[l], &ws.tan[l], n_out, n_in, 1 + m);
            let a = &mut ws.pre[l];
            a.iter_mut()
                .zip(&y[..n_out])
                .zip(&self.biases[l])
                .for_each(|((a, y), b)| *a = y + b);
            let (h, d) = (&mut ws.post[l], &mut ws.dsig);
            self.activation(l).apply_with_derivative(&ws.pre[l], h, d);
            let next = &mut ws.tan[l + 1];
            next[..n_out].copy_from_slice(&h[..n_out]);
            for j in 1..=m {
                let (dst, src) = (
                    &mut next[j * n_out..(j + 1) * n_out],
                    &y[j * n_out..(j + 1) * n_out],
                );
                for i in 0..n_out {
                    dst[i] = d[i] * src[i];
                }
            }
        }
        let (n_in, n_out) = (self.sizes[last], self.sizes[last + 1]);
        let tangents = &ws.tan[last][n_in..n_in * (1 + m)];
        linalg::mul_w(out, &self.weights[last], tangents, n_out, n_in, m);
        ws.cached = false;
    }
}

/// Scratch memory for [`Mlp::forward`], [`Mlp::vjp`], [`Mlp::jvp`] and [`Mlp::jacobian`], made
/// once by [`Mlp::workspace`] and reused for every call, so the hot path never allocates.
#[derive(Debug, Clone)]
pub struct MlpWorkspace {
    sizes: Vec<usize>,
    /// a_l for every dense layer.
    pre: Vec<Vec<f64>>,
    /// h_l = σ(a_l) for every hidden layer.
    post: Vec<Vec<f64>>,
    /// X_l = [h_l | T_l], n_l × (1 + n₀) column-major, for l = 0..L−1.
    tan: Vec<Vec<f64>>,
    /// The product W X of the current layer, max n_l × (1 + n₀).
    y: Vec<f64>,
    /// σ'(a_l) of the current layer.
    dsig: Vec<f64>,
    /// Backward sweep buffers (gradient w.r.t. a_l and h_l).
    ga: Vec<f64>,
    gh: Vec<f64>,
    /// Whether `pre`/`post` hold a complete forward pass (for `vjp_cached`).
    cached: bool,
}

impl MlpWorkspace {
    fn new(sizes: &[usize]) -> Self {
        let n0 = sizes[0];
        let widest = sizes.iter().copied().max().unwrap_or(0);
        let layers = sizes.len() - 1;
        Self {
            sizes: sizes.to_vec(),
            pre: sizes[1..].iter().map(|&n| vec![0.0; n]).collect(),
            post: sizes[1..layers].iter().map(|&n| vec![0.0; n]).collect(),
            tan: sizes[..layers]
                .iter()
                .map(|&n| vec![0.0; n * (1 + n0)])
                .collect(),
            y: vec![0.0; widest * (1 + n0)],
            dsig: vec![0.0; widest],
            ga: vec![0.0; widest],
            gh: vec![0.0; widest],
            cached: false,
        }
    }
}
