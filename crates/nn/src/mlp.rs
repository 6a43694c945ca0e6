//! The dense multilayer perceptron y = f(x) and its exact derivatives at one input.
//!
//! With layer sizes n₀ → n₁ → … → n_L, dense layer l computes a_l = W_l h_{l−1} + b_l with
//! h₀ = x; hidden layers apply an activation h_l = σ_l(a_l) and the output is linear, y = a_L.
//! With D_l = diag(σ_l'(a_l)) the Jacobian is J = W_L D_{L−1} W_{L−1} ⋯ D₁ W₁, and
//!
//! * [`Mlp::vjp`] computes Jᵀv by one forward pass and one backward pass (reverse mode), the
//!   top hidden layer's two steps fused into one pass over its weights,
//! * [`Mlp::jvp`] computes Jw by pushing the pair [h | t] through the layers (forward mode, both
//!   products of a layer in one pass over its weights),
//! * [`Mlp::jacobian`] computes J by pushing [h | I] through the layers (forward mode with n₀
//!   tangent columns at once). For a decoder n₀ = d is small (≈ 6), so this costs a few forward
//!   passes, far less than n_L reverse passes.
//!
//! The products are the explicit-SIMD kernels of the crate's `kernels` module; the weights start
//! on a cache line so that no SIMD load of a row splits.
//! None of them allocate: scratch lives in an [`MlpWorkspace`] made once by [`Mlp::workspace`].
//! Batched evaluation and backpropagation for training are in [`crate::batch`].

use std::sync::atomic::{AtomicU64, Ordering};

use crate::aligned::AlignedVec;
use crate::{Activation, NnError, SplitMix64, kernels};

/// A dense feed-forward network with an activation on every hidden layer and a linear output.
///
/// Weights are stored row-major (`n_out × n_in`, one output neuron per contiguous row) so every
/// product runs on contiguous memory. Deserialisation validates sizes and finiteness.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "MlpData")]
pub struct Mlp {
    /// Layer widths n₀, …, n_L (at least two).
    sizes: Vec<usize>,
    /// One activation per hidden layer (`sizes.len() − 2`).
    activations: Vec<Activation>,
    /// W_l, row-major `sizes[l+1] × sizes[l]`, on a cache-line boundary.
    weights: Vec<AlignedVec>,
    /// b_l, length `sizes[l+1]`.
    biases: Vec<AlignedVec>,
    /// Identifies the parameter values: a fresh number from [`fresh_version`] whenever they may
    /// change (every `&mut` accessor), kept by clones (same values). A workspace holding weights
    /// packed for [`Mlp::jacobian`] repacks when it differs. Not serialised.
    #[serde(skip_serializing)]
    version: u64,
}

/// A number no other [`Mlp`] parameter state has had in this process (never 0).
fn fresh_version() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// Equal architecture and parameters (the version is bookkeeping).
impl PartialEq for Mlp {
    fn eq(&self, other: &Self) -> bool {
        self.sizes == other.sizes
            && self.activations == other.activations
            && self.weights == other.weights
            && self.biases == other.biases
    }
}

impl Clone for Mlp {
    fn clone(&self) -> Self {
        Self {
            sizes: self.sizes.clone(),
            activations: self.activations.clone(),
            weights: self.weights.clone(),
            biases: self.biases.clone(),
            version: self.version,
        }
    }

    /// Reuses the arrays of `self` (training keeps a copy of the best weights every epoch).
    fn clone_from(&mut self, source: &Self) {
        self.sizes.clone_from(&source.sizes);
        self.activations.clone_from(&source.activations);
        self.weights.clone_from(&source.weights);
        self.biases.clone_from(&source.biases);
        self.version = source.version;
    }
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
                let mut a = AlignedVec::zeros(n_in * n_out);
                a.iter_mut().for_each(|x| *x = rng.range(-limit, limit));
                a
            })
            .collect();
        let biases = sizes[1..].iter().map(|&n| AlignedVec::zeros(n)).collect();
        Ok(Self {
            sizes: sizes.to_vec(),
            activations: activations.to_vec(),
            weights,
            biases,
            version: fresh_version(),
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
            if Some(weights[l].len()) != n_in.checked_mul(n_out) {
                return bad(format!(
                    "layer {l} has {} weights, expected {n_out} × {n_in}",
                    weights[l].len()
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
        let aligned = |a: Vec<Vec<f64>>| a.iter().map(|a| AlignedVec::from_slice(a)).collect();
        Ok(Self {
            sizes,
            activations,
            weights: aligned(weights),
            biases: aligned(biases),
            version: fresh_version(),
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
        self.version = fresh_version();
        &mut self.weights[layer]
    }

    /// b_l.
    pub fn bias(&self, layer: usize) -> &[f64] {
        &self.biases[layer]
    }

    /// b_l, mutable (the caller keeps it finite).
    pub fn bias_mut(&mut self, layer: usize) -> &mut [f64] {
        self.version = fresh_version();
        &mut self.biases[layer]
    }

    /// The total number of weights and biases.
    pub fn num_parameters(&self) -> usize {
        self.weights.iter().map(|w| w.len()).sum::<usize>()
            + self.biases.iter().map(|b| b.len()).sum::<usize>()
    }

    /// Every parameter array in a fixed order (W₁, b₁, W₂, b₂, …), as the optimiser sees them.
    pub fn parameters_mut(&mut self) -> impl Iterator<Item = &mut [f64]> {
        self.version = fresh_version();
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

    /// h_l = σ(W_l h_{l−1} + b_l) for the hidden layers l = 0..end into `ws.hidden`, from
    /// h₋₁ = x = `z`. With two hidden layers or more, also decides from the first layer
    /// whether the second, forward and backward, runs over the first layer's nonlinear units
    /// only (`ws.sparse`, see [`Mlp::sparse_layer`]), even when `end` = 1 stops before it.
    fn forward_hidden(&self, z: &[f64], end: usize, ws: &mut MlpWorkspace) {
        let deep = self.num_layers() > 2;
        ws.sparse = false;
        for l in 0..end {
            if l == 1 && ws.sparse {
                self.sparse_layer(z, ws);
                continue;
            }
            let n_out = self.sizes[l + 1];
            let (done, rest) = ws.hidden.split_at_mut(l);
            let x: &[f64] = if l == 0 { z } else { &done[l - 1] };
            let h = &mut rest[0][..n_out];
            let pre = (l == 0 && deep).then_some(&mut ws.pre[..]);
            let (w, b) = (&self.weights[l], &self.biases[l]);
            kernels::dense_layer(self.activation(l), h, pre, w, b, x);
            if l == 0 && deep {
                let (n0, n1) = (self.sizes[0], self.sizes[1]);
                let h = &ws.hidden[0][..n1];
                let s = nonlinear_units(self.activation(0), &ws.pre[..n1], h, &mut ws.support);
                ws.sparse = 4 * (s + n0) < 3 * n1;
                if ws.sparse && ws.packed_version != self.version {
                    self.pack(ws);
                }
            }
        }
    }

    /// The second layer h₂ = σ(W₂h₁ + b₂) from the first layer's nonlinear units S
    /// (`ws.support`): a unit with σ(a) = a is linear, so
    ///   W₂h₁ = W₂W₁z + W₂b₁ + W₂[:, S] (h₁ − a₁)[S]
    /// exactly, with W₂W₁ and W₂b₁ kept by [`Mlp::pack`] and W₂'s columns read from its
    /// transpose. For ELU, S is the units with a₁ < 0: about half, so the layer costs
    /// n₂ (n₀ + |S|) multiply–adds instead of n₂ n₁. Taken when n₀ + |S| < 3/4 n₁ (the listed
    /// rows run a little slower than the plain product).
    fn sparse_layer(&self, z: &[f64], ws: &mut MlpWorkspace) {
        let (n1, n2) = (self.sizes[1], self.sizes[2]);
        let (first, rest) = ws.hidden.split_at_mut(1);
        let (a, h) = (&ws.pre[..n1], &first[0][..n1]);
        let s = ws.support.len();
        let g = &mut ws.gathered[..s];
        for (g, &j) in g.iter_mut().zip(&ws.support) {
            *g = h[j as usize] - a[j as usize];
        }
        let h2 = &mut rest[0][..n2];
        through_linear_units(&ws.w21t, &ws.first_bias, z, h2);
        kernels::add_listed_rows(h2, &ws.w2t, &ws.support, g);
        kernels::vectorized(kernels::ApplyBiased(
            self.activation(1),
            h2,
            &self.biases[1],
        ));
    }

    /// The backward step through the second layer and the first from g₂ = ∂/∂a₂
    /// (`ws.grad[1]`) when the forward pass took [`Mlp::sparse_layer`]:
    ///   ∂/∂z = W₁ᵀ (σ'(a₁) ⊙ W₂ᵀ g₂) = (W₂W₁)ᵀ g₂ + W₁[S, :]ᵀ ((σ'(a₁) − 1) ⊙ W₂[:, S]ᵀ g₂)
    /// since σ' = 1 off S.
    fn sparse_backward(&self, out: &mut [f64], ws: &mut MlpWorkspace) {
        let (n0, n1, n2) = (self.sizes[0], self.sizes[1], self.sizes[2]);
        let (h, g2) = (&ws.hidden[0][..n1], &ws.grad[1][..n2]);
        let s = ws.support.len();
        let t = &mut ws.gathered[..s];
        kernels::listed_rows_vec(t, &ws.w2t, &ws.support, g2);
        let act = self.activation(0);
        for (t, &j) in t.iter_mut().zip(&ws.support) {
            *t *= act.derivative_from_output(h[j as usize]) - 1.0;
        }
        kernels::mat_vec(out, &ws.w21t, g2, n0, n2);
        kernels::add_listed_rows(out, &self.weights[0], &ws.support, t);
    }

    /// out = f(z). Also leaves the forward state in `ws` for [`Mlp::vjp_cached`].
    pub fn forward(&self, z: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        assert_eq!(z.len(), self.input_dim(), "input length");
        assert_eq!(out.len(), self.output_dim(), "output length");
        let last = self.num_layers() - 1;
        self.forward_hidden(z, last, ws);
        let x: &[f64] = if last == 0 { z } else { &ws.hidden[last - 1] };
        kernels::mat_vec(
            out,
            &self.weights[last],
            x,
            self.sizes[last + 1],
            self.sizes[last],
        );
        out.iter_mut()
            .zip(&self.biases[last])
            .for_each(|(y, b)| *y += b);
        ws.cached = true;
    }

    /// out = J(z)ᵀ v, the vector–Jacobian product (one forward and one backward pass; the
    /// output layer's value is not needed).
    ///
    /// The top hidden layer k = L − 2 runs forward and backward in one pass over its weights:
    /// u = W_Lᵀ v is known before h_k is, so each row i of W_k gives
    /// h_{k,i} = σ(W_k[i, :] h_{k−1} + b_{k,i}), then adds σ'(h_{k,i}) u_i W_k[i, :] to W_kᵀ g_k
    /// while the row is in L1 (`kernels::fused_layer`), unless that layer is the second and
    /// runs over the first layer's nonlinear units only (see `Mlp::sparse_layer`). The result
    /// is bit-identical to [`Mlp::forward`] followed by [`Mlp::vjp_cached`].
    pub fn vjp(&self, z: &[f64], v: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        assert_eq!(z.len(), self.input_dim(), "input length");
        assert_eq!(v.len(), self.output_dim(), "cotangent length");
        assert_eq!(out.len(), self.input_dim(), "output length");
        ws.cached = false;
        let last = self.num_layers() - 1;
        if last == 0 {
            self.backward(v, out, ws);
            return;
        }
        let k = last - 1;
        self.forward_hidden(z, k, ws);
        if ws.sparse && k == 1 {
            // The second layer runs over the first's nonlinear units, forward and backward.
            self.sparse_layer(z, ws);
            self.backward(v, out, ws);
            return;
        }
        let (n_in, n_out) = (self.sizes[last], self.sizes[last + 1]);
        kernels::mat_t_vec(&mut ws.grad[k], &self.weights[last], v, n_out, n_in);
        let (below, above) = ws.hidden.split_at_mut(k);
        let x: &[f64] = if k == 0 { z } else { &below[k - 1] };
        let (grad_below, grad_above) = ws.grad.split_at_mut(k);
        let gx: &mut [f64] = if k == 0 {
            &mut *out
        } else {
            &mut grad_below[k - 1]
        };
        kernels::fused_layer(
            self.activation(k),
            &self.weights[k],
            &self.biases[k],
            x,
            &grad_above[0],
            &mut above[0],
            gx,
        );
        if k > 0 {
            self.backward_below(k, out, ws);
        }
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

    /// Reverse sweep from v = ∂/∂y using the hidden activations in `ws`: g ← W_lᵀ g, then
    /// g ← σ'(a_{l−1}) ⊙ g with σ' taken from h_{l−1}, down to the input.
    fn backward(&self, v: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        assert_eq!(v.len(), self.output_dim(), "cotangent length");
        assert_eq!(out.len(), self.input_dim(), "output length");
        let last = self.num_layers() - 1;
        let (n_in, n_out) = (self.sizes[last], self.sizes[last + 1]);
        if last == 0 {
            kernels::mat_t_vec(out, &self.weights[0], v, n_out, n_in);
            return;
        }
        kernels::mat_t_vec(&mut ws.grad[last - 1], &self.weights[last], v, n_out, n_in);
        self.backward_below(last, out, ws);
    }

    /// The reverse sweep below layer `top ≥ 1`, from `ws.grad[top − 1]` = W_topᵀ g_top (before
    /// the activation's derivative): out = ∂/∂z.
    fn backward_below(&self, top: usize, out: &mut [f64], ws: &mut MlpWorkspace) {
        for l in (1..=top).rev() {
            if l == 1 && top > 1 && ws.sparse {
                self.sparse_backward(out, ws);
                return;
            }
            let n_in = self.sizes[l];
            let (below, above) = ws.grad.split_at_mut(l);
            let dst = &mut below[l - 1][..n_in];
            if l < top {
                let n_out = self.sizes[l + 1];
                kernels::mat_t_vec(dst, &self.weights[l], &above[0], n_out, n_in);
            }
            self.activation(l - 1)
                .scale_by_derivative(&ws.hidden[l - 1][..n_in], dst);
        }
        kernels::mat_t_vec(
            out,
            &self.weights[0],
            &ws.grad[0],
            self.sizes[1],
            self.sizes[0],
        );
    }

    /// out = J(z) w, the Jacobian–vector product (forward mode: the value and the tangent are
    /// pushed through each layer side by side, t ← σ'(a) ⊙ (W t)).
    pub fn jvp(&self, z: &[f64], w: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        assert_eq!(z.len(), self.input_dim(), "input length");
        assert_eq!(w.len(), self.input_dim(), "tangent length");
        assert_eq!(out.len(), self.output_dim(), "output length");
        let last = self.num_layers() - 1;
        for l in 0..last {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let (done, rest) = ws.hidden.split_at_mut(l);
            let (done_t, rest_t) = ws.grad.split_at_mut(l);
            let (x, t): (&[f64], &[f64]) = if l == 0 {
                (z, w)
            } else {
                (&done[l - 1], &done_t[l - 1])
            };
            let (h, s) = (&mut rest[0][..n_out], &mut rest_t[0][..n_out]);
            // One pass over W for both products (the value is bit-identical to `forward`'s).
            kernels::mat_vec2(h, s, &self.weights[l], x, t, n_out, n_in);
            let act = self.activation(l);
            act.apply_biased(h, &self.biases[l]);
            s.iter_mut()
                .zip(h.iter())
                .for_each(|(s, &h)| *s *= act.derivative_from_output(h));
        }
        let t: &[f64] = if last == 0 { w } else { &ws.grad[last - 1] };
        kernels::mat_vec(
            out,
            &self.weights[last],
            t,
            self.sizes[last + 1],
            self.sizes[last],
        );
        ws.cached = false;
    }

    /// out = J(z), the full `n_L × n₀` Jacobian, column-major (column j = ∂f/∂z_j).
    ///
    /// Forward mode with all n₀ tangents at once: X_l = [h_l | T_l] (n_l × (1 + n₀),
    /// row-major), X₁ = [σ(W₁z + b₁) | σ'(a₁) ⊙ W₁] (the seed is the identity, so only the
    /// value is a product), X_{l+1} = [σ(a_{l+1}) | σ'(a_{l+1}) ⊙ (W_{l+1} T_l)] with
    /// [a_{l+1} − b_{l+1} | W_{l+1} T_l] = W_{l+1} X_l one matrix product, and J = W_L T_{L−1}.
    /// For the X decoder 6 → 200 → 200 → 49 that is 200·200·7 + 49·200·6 ≈ 340 k multiply–adds,
    /// far fewer than the 49 reverse passes of reverse mode (≈ 2 M).
    ///
    /// The first of these products, W₂ T₁ = W₂ (σ'(a₁) ⊙ W₁), is taken as
    /// W₂W₁ + W₂ ((σ'(a₁) − 1) ⊙ W₁) when that is cheaper: W₂W₁ is kept with the packed weights,
    /// and the second term only reads the units that are not linear, the ELU units with a₁ < 0
    /// (about half of them); the value W₂h₁ likewise. See `Mlp::first_product`.
    ///
    /// The products run on copies of W_2, …, W_L packed with their rows in SIMD lanes (see
    /// `kernels::pack_rows`), kept in `ws` and refreshed when the weights have changed since.
    pub fn jacobian(&self, z: &[f64], out: &mut [f64], ws: &mut MlpWorkspace) {
        self.check_workspace(ws);
        let n0 = self.input_dim();
        assert_eq!(z.len(), n0, "input length");
        assert_eq!(
            out.len(),
            self.output_dim() * n0,
            "Jacobian length (n_out × n_in)"
        );
        ws.cached = false;
        let (c, last) = (1 + n0, self.num_layers() - 1);
        if last == 0 {
            // Affine: J = W.
            let w = &self.weights[0];
            for (j, col) in out.chunks_exact_mut(self.output_dim()).enumerate() {
                for (i, o) in col.iter_mut().enumerate() {
                    *o = w[i * n0 + j];
                }
            }
            return;
        }
        if ws.packed_version != self.version {
            self.pack(ws);
        }
        // X₁ = [σ(W₁z + b₁) | σ' ⊙ W₁] (or, for the units of `support`, (σ' − 1) ⊙ W₁).
        let (n1, w) = (self.sizes[1], &self.weights[0]);
        let (h, d) = (&mut ws.grad[0][..n1], &mut ws.hidden[0][..n1]);
        kernels::mat_vec(h, w, z, n1, n0);
        ws.pre[..n1]
            .iter_mut()
            .zip(h.iter().zip(&self.biases[0]))
            .for_each(|(a, (h, b))| *a = h + b);
        kernels::activate(self.activation(0), h, &self.biases[0], d);
        self.first_product(z, ws);
        for l in 2..last {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let (done, rest) = ws.tan.split_at_mut(l);
            kernels::mat_mat_packed(kernels::Product {
                y: &mut rest[0],
                ldy: c,
                y0: 0,
                packed: &ws.packed[l - 1],
                m: n_out,
                n: n_in,
                x: &done[l - 1],
                ldx: c,
                x0: 0,
                c,
                support: None,
                plus: None,
            });
            self.activate_tangents(l, &mut ws.tan[l], &mut ws.grad[l], &mut ws.hidden[l], c);
        }
        if last > 1 {
            // J = W_L T_{L−1}: the tangent columns only, as J row-major into `ws.jac`.
            let (n_in, n_out) = (self.sizes[last], self.sizes[last + 1]);
            kernels::mat_mat_packed(kernels::Product {
                y: &mut ws.jac,
                ldy: n0,
                y0: 0,
                packed: &ws.packed[last - 1],
                m: n_out,
                n: n_in,
                x: &ws.tan[last - 1],
                ldx: c,
                x0: 1,
                c: n0,
                support: None,
                plus: None,
            });
        }
        let n_out = self.output_dim();
        for (i, row) in ws.jac.chunks_exact(n0).take(n_out).enumerate() {
            for (k, &j) in row.iter().enumerate() {
                out[k * n_out + i] = j;
            }
        }
    }

    /// Packs W₂, …, W_L for the Jacobian's products, and forms what the second layer's
    /// products over the first layer's nonlinear units need: W₂W₁ (row-major, and in the
    /// layout of X₂'s tangent columns), W₂b₁ and W₂ᵀ.
    fn pack(&self, ws: &mut MlpWorkspace) {
        let (n0, last, lanes) = (self.input_dim(), self.num_layers() - 1, ws.lanes);
        for l in 1..=last {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            kernels::pack_rows(&mut ws.packed[l - 1], &self.weights[l], n_out, n_in, lanes);
        }
        let (n1, n2) = (self.sizes[1], self.sizes[2]);
        kernels::mat_mat_packed(kernels::Product {
            y: &mut ws.w21,
            ldy: n0,
            y0: 0,
            packed: &ws.packed[0],
            m: n2,
            n: n1,
            x: &self.weights[0],
            ldx: n0,
            x0: 0,
            c: n0,
            support: None,
            plus: None,
        });
        if last > 1 {
            let p = &ws.w21[..n2 * n0];
            for (row, p) in ws.first.chunks_exact_mut(1 + n0).zip(p.chunks_exact(n0)) {
                row[1..].copy_from_slice(p);
            }
            transpose(&mut ws.w21t, p, n2, n0);
        }
        let w2 = &self.weights[1];
        kernels::mat_vec(&mut ws.first_bias, w2, &self.biases[0], n2, n1);
        transpose(&mut ws.w2t, w2, n2, n1);
        ws.packed_version = self.version;
    }

    /// The product after X₁ = [h₁ | T₁]: X₂ before its activation (or J's rows when W₂ is the
    /// last layer), W₂ X₁, into `ws.tan[1]` (or `ws.jac`), from the first layer's
    /// pre-activation a₁ (`ws.pre`), h₁ = σ(a₁) (`ws.grad[0]`) and σ'(a₁) (`ws.hidden[0]`).
    ///
    /// A unit with σ(a) = a and σ'(a) = 1 (ELU's units with a > 0, about half of them) is
    /// linear, so with the units S that are not,
    ///   W₂h₁ = W₂W₁z + W₂b₁ + W₂[:, S] (h₁ − a₁)[S],
    ///   W₂T₁ = W₂W₁ + W₂[:, S] ((σ'(a₁) − 1) ⊙ W₁)[S],
    /// exactly, one product of 1 + n₀ columns over S, with W₂W₁ and W₂b₁ kept by [`Mlp::pack`].
    /// Taken when S has fewer than 3/4 of the units: its loop over a list of columns runs at
    /// about 80 % of the dense one's multiply–add rate. tanh and softplus have no linear units.
    fn first_product(&self, z: &[f64], ws: &mut MlpWorkspace) {
        let (n0, last) = (self.input_dim(), self.num_layers() - 1);
        let (c, n1, n2, w) = (1 + n0, self.sizes[1], self.sizes[2], &self.weights[0]);
        let (a, h, d) = (&ws.pre[..n1], &ws.grad[0][..n1], &ws.hidden[0][..n1]);
        let s = nonlinear_units(self.activation(0), a, h, &mut ws.support);
        let sparse = 4 * s < 3 * n1;
        // With one hidden layer W₂ is the last layer: J = W₂T₁, no value.
        let (v, cols) = if last == 1 { (0, n0) } else { (1, c) };
        let (tan0, rest) = ws.tan.split_at_mut(1);
        let (x, ldx, x0) = if sparse {
            // X's rows [h − a | (σ' − 1) ⊙ W₁] (without the value with one hidden layer) for
            // the units of S, gathered.
            let x = &mut ws.gathered[..s * cols];
            for (row, &j) in x.chunks_exact_mut(cols).zip(&ws.support) {
                let (j, dj) = (j as usize, d[j as usize] - 1.0);
                if v == 1 {
                    row[0] = h[j] - a[j];
                }
                row[v..]
                    .iter_mut()
                    .zip(&w[j * n0..(j + 1) * n0])
                    .for_each(|(t, w)| *t = dj * w);
            }
            if v == 1 {
                // The value's part W₂W₁z + W₂b₁ into P's first column (`grad[1]` is scratch
                // until `activate_tangents` below).
                let part = &mut ws.grad[1][..n2];
                through_linear_units(&ws.w21t, &ws.first_bias, z, part);
                for (row, &p) in ws.first.chunks_exact_mut(c).zip(part.iter()) {
                    row[0] = p;
                }
            }
            (&ws.gathered[..s * cols], cols, 0)
        } else {
            tangent_rows(&mut tan0[0], h, d, Some(w), c);
            (&tan0[0][..], c, 1 - v)
        };
        let (y, ldy) = if last == 1 {
            (&mut ws.jac, n0)
        } else {
            (&mut rest[0], c)
        };
        kernels::mat_mat_packed(kernels::Product {
            y,
            ldy,
            y0: 0,
            packed: &ws.packed[0],
            m: n2,
            n: n1,
            x,
            ldx,
            x0,
            c: cols,
            support: sparse.then_some(&ws.support[..]),
            plus: sparse.then_some(if last == 1 {
                &ws.w21[..]
            } else {
                &ws.first[..]
            }),
        });
        if last > 1 {
            self.activate_tangents(1, &mut ws.tan[1], &mut ws.grad[1], &mut ws.hidden[1], c);
        }
    }

    /// X_l ← [σ(a + b_l) | σ'(a) ⊙ T] for X_l = [a | T] (row-major, `c` columns), with σ and
    /// σ' evaluated on gathered copies in `h` and `d` so that they vectorise.
    fn activate_tangents(&self, l: usize, x: &mut [f64], h: &mut [f64], d: &mut [f64], c: usize) {
        let (act, n) = (self.activation(l), self.sizes[l + 1]);
        let (h, d) = (&mut h[..n], &mut d[..n]);
        for (h, row) in h.iter_mut().zip(x.chunks_exact(c)) {
            *h = row[0];
        }
        kernels::activate(act, h, &self.biases[l], d);
        tangent_rows(x, h, d, None, c);
    }
}

/// out = W₂W₁z + W₂b₁ (length n₂) from (W₂W₁)ᵀ (n₀ × n₂, row-major) and W₂b₁: the second
/// layer's pre-activation without b₂ when every first-layer unit is linear. As a combination of
/// the n₀ rows of (W₂W₁)ᵀ: n₀ passes over `out` rather than n₂ short dot products with their
/// horizontal sums.
fn through_linear_units(w21t: &[f64], w2b1: &[f64], z: &[f64], out: &mut [f64]) {
    let (n0, n2) = (z.len(), out.len());
    kernels::mat_t_vec(out, w21t, z, n0, n2);
    out.iter_mut().zip(&w2b1[..n2]).for_each(|(o, q)| *o += q);
}

/// dst (n × m, row-major) = srcᵀ for src (m × n, row-major).
fn transpose(dst: &mut [f64], src: &[f64], m: usize, n: usize) {
    for (j, row) in dst.chunks_exact_mut(m).take(n).enumerate() {
        for (i, t) in row.iter_mut().enumerate() {
            *t = src[i * n + j];
        }
    }
}

/// The units j whose activation is not linear at a_j (σ(a_j) ≠ a_j or σ'(a_j) ≠ 1, given
/// h = σ(a)) into `support`, in order; returns how many.
fn nonlinear_units(act: Activation, a: &[f64], h: &[f64], support: &mut Vec<u32>) -> usize {
    // Branch-free: about half the units are linear, in no order a predictor could learn.
    support.resize(a.len(), 0);
    let mut s = 0;
    for (j, (&a, &h)) in a.iter().zip(h).enumerate() {
        support[s] = j as u32;
        s += usize::from(h != a || act.derivative_from_output(h) != 1.0);
    }
    support.truncate(s);
    s
}

/// The rows [h_i | d_i t_i] of X (row-major, `c` columns), where t_i is the row's own tangents
/// (`seed` = None) or row i of `seed` (c − 1 columns). The loop over a row is unrolled for
/// c ≤ 8: with c a run-time number it cost more than the 200 × 7 multiplications.
fn tangent_rows(x: &mut [f64], h: &[f64], d: &[f64], seed: Option<&[f64]>, c: usize) {
    #[inline(always)]
    fn rows<const C: usize>(x: &mut [f64], h: &[f64], d: &[f64], seed: Option<&[f64]>, c: usize) {
        let c = if C == 0 { c } else { C };
        let rows = x.chunks_exact_mut(c).zip(h).zip(d);
        match seed {
            Some(w) => {
                for (((row, &h), &d), w) in rows.zip(w.chunks_exact(c - 1)) {
                    row[0] = h;
                    row[1..].iter_mut().zip(w).for_each(|(t, w)| *t = d * w);
                }
            }
            None => {
                for ((row, &h), &d) in rows {
                    row[0] = h;
                    row[1..].iter_mut().for_each(|t| *t *= d);
                }
            }
        }
    }
    match c {
        2 => rows::<2>(x, h, d, seed, c),
        3 => rows::<3>(x, h, d, seed, c),
        4 => rows::<4>(x, h, d, seed, c),
        5 => rows::<5>(x, h, d, seed, c),
        6 => rows::<6>(x, h, d, seed, c),
        7 => rows::<7>(x, h, d, seed, c),
        8 => rows::<8>(x, h, d, seed, c),
        _ => rows::<0>(x, h, d, seed, c),
    }
}

/// Scratch memory for [`Mlp::forward`], [`Mlp::vjp`], [`Mlp::jvp`] and [`Mlp::jacobian`], made
/// once by [`Mlp::workspace`] and reused for every call, so the hot path never allocates.
#[derive(Debug, Clone)]
pub struct MlpWorkspace {
    sizes: Vec<usize>,
    /// h_l = σ(a_l) for every hidden layer (the forward state of `vjp_cached`).
    hidden: Vec<AlignedVec>,
    /// Backward gradients (VJP) or tangents (JVP) per hidden layer.
    grad: Vec<AlignedVec>,
    /// SIMD lanes of this machine: the padding of the packed weights and of `tan` and `jac`.
    lanes: usize,
    /// X_l = [h_l | T_l] for every hidden layer (Jacobian), row-major, with n_l rounded up to
    /// a multiple of `lanes` rows.
    tan: Vec<Vec<f64>>,
    /// W_L T_{L−1}, row-major with the padded rows (Jacobian).
    jac: Vec<f64>,
    /// W_l packed for the Jacobian's products, for l = 2, …, L.
    packed: Vec<AlignedVec>,
    /// W₂W₁ in the layout of the first product's result, after a column for the value's
    /// W₂W₁z + W₂b₁ when there is one (see `Mlp::first_product`).
    first: Vec<f64>,
    /// The first hidden layer's units that are not linear at z.
    support: Vec<u32>,
    /// Per unit of `support`: the Jacobian's rows [h₁ − a₁ | (σ' − 1) ⊙ W₁], the forward
    /// pass's h₁ − a₁ or the VJP's (σ' − 1) ⊙ W₂ᵀg₂.
    gathered: Vec<f64>,
    /// The first hidden layer's pre-activation a₁.
    pre: Vec<f64>,
    /// W₂b₁ (see `Mlp::first_product` and `Mlp::sparse_layer`).
    first_bias: Vec<f64>,
    /// W₂W₁, row-major with W₂'s rows padded to a multiple of `lanes`.
    w21: Vec<f64>,
    /// (W₂W₁)ᵀ, row-major (with two hidden layers or more).
    w21t: Vec<f64>,
    /// W₂ᵀ, row-major.
    w2t: Vec<f64>,
    /// Whether the last forward pass took `Mlp::sparse_layer`.
    sparse: bool,
    /// The [`Mlp`] version whose weights are in `packed` and `first` (0: none).
    packed_version: u64,
    /// Whether `hidden` holds the state of the last [`Mlp::forward`] (for `vjp_cached`).
    cached: bool,
}

impl MlpWorkspace {
    fn new(sizes: &[usize]) -> Self {
        let (n0, lanes) = (sizes[0], kernels::lanes());
        let hidden = &sizes[1..sizes.len() - 1];
        let ld = |n: usize| kernels::padded_rows(n, lanes);
        let n_last = sizes[sizes.len() - 1];
        Self {
            sizes: sizes.to_vec(),
            hidden: hidden.iter().map(|&n| AlignedVec::zeros(n)).collect(),
            grad: hidden.iter().map(|&n| AlignedVec::zeros(n)).collect(),
            lanes,
            tan: hidden
                .iter()
                .map(|&n| vec![0.0; ld(n) * (1 + n0)])
                .collect(),
            jac: if hidden.is_empty() {
                Vec::new()
            } else {
                vec![0.0; ld(n_last) * n0]
            },
            packed: sizes[1..]
                .windows(2)
                .map(|w| AlignedVec::zeros(kernels::packed_len(w[1], w[0], lanes)))
                .collect(),
            first: match sizes.len() {
                0..=3 => Vec::new(),
                _ => vec![0.0; ld(sizes[2]) * (1 + n0)],
            },
            w21: match sizes.len() {
                0..=2 => Vec::new(),
                _ => vec![0.0; ld(sizes[2]) * n0],
            },
            w21t: match sizes.len() {
                0..=3 => Vec::new(),
                _ => vec![0.0; n0 * sizes[2]],
            },
            w2t: match sizes.len() {
                0..=2 => Vec::new(),
                _ => vec![0.0; sizes[1] * sizes[2]],
            },
            sparse: false,
            support: Vec::with_capacity(sizes[1]),
            gathered: vec![0.0; sizes[1] * (1 + n0)],
            pre: vec![0.0; sizes[1]],
            first_bias: vec![0.0; if sizes.len() > 2 { sizes[2] } else { 0 }],
            packed_version: 0,
            cached: false,
        }
    }
}
