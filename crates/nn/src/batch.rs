//! Batched evaluation and backpropagation of an [`Mlp`] for training.
//!
//! A batch of c inputs is an `n₀ × c` column-major block X (one sample per contiguous column).
//! Forward: A_l = W_l H_{l−1} + b_l 1ᵀ, H_l = σ(A_l). Backward from G_L = ∂ℒ/∂A_L:
//! ∂ℒ/∂W_l = G_l H_{l−1}ᵀ, ∂ℒ/∂b_l = G_l 1, G_{l−1} = σ'(A_{l−1}) ⊙ (W_lᵀ G_l), and the input
//! gradient Wᵀ₁G₁ when asked. Every product is one matrix–matrix multiplication.

use crate::{Mlp, kernels, linalg};

/// ∂ℒ/∂W_l and ∂ℒ/∂b_l for every layer of an [`Mlp`], in the network's layout.
#[derive(Debug, Clone, PartialEq)]
pub struct MlpGradient {
    weights: Vec<Vec<f64>>,
    biases: Vec<Vec<f64>>,
}

impl MlpGradient {
    /// A zero gradient shaped like `mlp`.
    pub fn zeros(mlp: &Mlp) -> Self {
        let l = mlp.num_layers();
        Self {
            weights: (0..l).map(|i| vec![0.0; mlp.weights(i).len()]).collect(),
            biases: (0..l).map(|i| vec![0.0; mlp.bias(i).len()]).collect(),
        }
    }

    /// ∂ℒ/∂W_l, row-major like the weights.
    pub fn weights(&self, layer: usize) -> &[f64] {
        &self.weights[layer]
    }

    /// ∂ℒ/∂b_l.
    pub fn bias(&self, layer: usize) -> &[f64] {
        &self.biases[layer]
    }

    /// Every array in the order of [`Mlp::parameters_mut`].
    pub fn slices(&self) -> impl Iterator<Item = &[f64]> {
        self.weights
            .iter()
            .zip(&self.biases)
            .flat_map(|(w, b)| [w.as_slice(), b.as_slice()])
    }

    /// Every array, mutable, in the order of [`Mlp::parameters_mut`].
    pub(crate) fn slices_mut(&mut self) -> impl Iterator<Item = &mut [f64]> {
        self.weights
            .iter_mut()
            .zip(self.biases.iter_mut())
            .flat_map(|(w, b)| [w.as_mut_slice(), b.as_mut_slice()])
    }

    /// self += other, elementwise.
    pub fn add_assign(&mut self, other: &MlpGradient) {
        for (a, b) in self
            .weights
            .iter_mut()
            .chain(self.biases.iter_mut())
            .zip(other.weights.iter().chain(&other.biases))
        {
            a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
        }
    }
}

/// Scratch memory for batches of up to `capacity` samples, made by [`Mlp::batch_workspace`].
///
/// Keeps what backpropagation needs and nothing more: every layer's activations (the
/// pre-activations are overwritten by σ in place, since every σ' is a function of σ's output,
/// see [`crate::Activation::derivative`]) and every layer's gradient G_l = ∂ℒ/∂A_l, so that the
/// weight gradients G_l H_{l−1}ᵀ can be formed after the backward sweep, over several chunks.
#[derive(Debug, Clone)]
pub struct MlpBatchWorkspace {
    sizes: Vec<usize>,
    capacity: usize,
    /// H_l = σ(A_l) for hidden layers, Y = A_L for the output layer; n_{l+1} × capacity each.
    act: Vec<Vec<f64>>,
    /// G_l = ∂ℒ/∂A_l, n_{l+1} × capacity, for every layer.
    grad: Vec<Vec<f64>>,
}

impl MlpBatchWorkspace {
    /// The largest batch this workspace holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The output block Y (`n_L × c`) of the last forward pass.
    pub(crate) fn output(&self, c: usize) -> &[f64] {
        let last = self.act.len() - 1;
        &self.act[last][..self.sizes[last + 1] * c]
    }

    /// The output block Y (`n_L × c`), mutable (e.g. to add a skip connection; the output layer
    /// is linear, so the backward sweep never reads Y).
    pub(crate) fn output_mut(&mut self, c: usize) -> &mut [f64] {
        let last = self.act.len() - 1;
        &mut self.act[last][..self.sizes[last + 1] * c]
    }

    /// The output Y and the buffer for G_L = ∂ℒ/∂Y (both `n_L × c`), for the caller to fill.
    pub(crate) fn output_and_gradient_mut(&mut self, c: usize) -> (&[f64], &mut [f64]) {
        let last = self.act.len() - 1;
        let len = self.sizes[last + 1] * c;
        (&self.act[last][..len], &mut self.grad[last][..len])
    }

    /// The buffer for G_L = ∂ℒ/∂Y (`n_L × c`).
    pub(crate) fn output_gradient_mut(&mut self, c: usize) -> &mut [f64] {
        let last = self.grad.len() - 1;
        &mut self.grad[last][..self.sizes[last + 1] * c]
    }

    /// G_l (`n_{l+1} × c`) of the last backward sweep.
    pub(crate) fn gradient(&self, layer: usize, c: usize) -> &[f64] {
        &self.grad[layer][..self.sizes[layer + 1] * c]
    }

    /// The input of layer `l ≥ 1`, H_{l−1} (`n_l × c`).
    pub(crate) fn hidden(&self, layer: usize, c: usize) -> &[f64] {
        &self.act[layer - 1][..self.sizes[layer] * c]
    }
}

impl Mlp {
    /// Scratch memory for [`Mlp::forward_batch`] / [`Mlp::backward_batch`] on up to `capacity`
    /// samples.
    pub fn batch_workspace(&self, capacity: usize) -> MlpBatchWorkspace {
        let sizes = self.sizes();
        let blocks = || -> Vec<Vec<f64>> {
            sizes[1..]
                .iter()
                .map(|&n| vec![0.0; n * capacity])
                .collect()
        };
        MlpBatchWorkspace {
            sizes: sizes.to_vec(),
            capacity,
            act: blocks(),
            grad: blocks(),
        }
    }

    fn check_batch(&self, ws: &MlpBatchWorkspace, c: usize) {
        assert_eq!(
            ws.sizes,
            self.sizes(),
            "the workspace was made for another network"
        );
        assert!(
            c <= ws.capacity,
            "batch of {c} exceeds workspace capacity {}",
            ws.capacity
        );
    }

    /// Y = f(X) for `c` inputs X (`n₀ × c`, column-major); returns Y (`n_L × c`, column-major),
    /// which lives in `ws` until the next call. Keeps the state [`Mlp::backward_batch`] needs.
    pub fn forward_batch<'w>(
        &self,
        x: &[f64],
        c: usize,
        ws: &'w mut MlpBatchWorkspace,
    ) -> &'w [f64] {
        self.check_batch(ws, c);
        let sizes = self.sizes();
        assert_eq!(x.len(), sizes[0] * c, "input block length");
        let last = self.num_layers() - 1;
        for l in 0..=last {
            let (n_in, n_out) = (sizes[l], sizes[l + 1]);
            let (done, rest) = ws.act.split_at_mut(l);
            let input: &[f64] = if l == 0 { x } else { &done[l - 1][..n_in * c] };
            let a = &mut rest[0][..n_out * c];
            linalg::mul_w(a, self.weights(l), input, n_out, n_in, c);
            let b = self.bias(l);
            if l < last {
                kernels::vectorized(kernels::ApplyBiased(self.activations()[l], a, b));
            } else {
                for col in a.chunks_exact_mut(n_out) {
                    col.iter_mut().zip(b).for_each(|(a, b)| *a += b);
                }
            }
        }
        ws.output(c)
    }

    /// Backpropagates G = ∂ℒ/∂Y (`n_L × c`) through the batch of the last
    /// [`Mlp::forward_batch`] on `ws` (whose input was `x`): overwrites `grad` with ∂ℒ/∂W, ∂ℒ/∂b
    /// and, when given, `g_in` (`n₀ × c`) with ∂ℒ/∂X.
    pub fn backward_batch(
        &self,
        x: &[f64],
        g_out: &[f64],
        c: usize,
        grad: &mut MlpGradient,
        g_in: Option<&mut [f64]>,
        ws: &mut MlpBatchWorkspace,
    ) {
        self.check_batch(ws, c);
        assert_eq!(x.len(), self.input_dim() * c, "input block length");
        let out = ws.output_gradient_mut(c);
        assert_eq!(g_out.len(), out.len(), "output gradient length");
        out.copy_from_slice(g_out);
        self.backward_data(c, g_in, ws);
        let sizes = self.sizes();
        for l in 0..self.num_layers() {
            let input = if l == 0 { x } else { ws.hidden(l, c) };
            weight_gradient_rows(
                sizes[l + 1],
                sizes[l],
                0,
                ws.gradient(l, c),
                input,
                c,
                false,
                &mut grad.weights[l],
                &mut grad.biases[l],
            );
        }
    }

    /// The backward sweep without weight gradients: from G_L (already in `ws`, see
    /// [`MlpBatchWorkspace::output_gradient_mut`]) every G_{l−1} = σ'(A_{l−1}) ⊙ (W_lᵀ G_l), and
    /// ∂ℒ/∂X = W₁ᵀ G₁ into `g_in` when given (skipped otherwise: nothing upstream needs it).
    pub(crate) fn backward_data(
        &self,
        c: usize,
        g_in: Option<&mut [f64]>,
        ws: &mut MlpBatchWorkspace,
    ) {
        self.check_batch(ws, c);
        let sizes = self.sizes();
        for l in (1..self.num_layers()).rev() {
            let (n_in, n_out) = (sizes[l], sizes[l + 1]);
            let (below, above) = ws.grad.split_at_mut(l);
            let gh = &mut below[l - 1][..n_in * c];
            linalg::mul_wt(gh, self.weights(l), &above[0][..n_out * c], n_out, n_in, c);
            let (act, h) = (self.activations()[l - 1], &ws.act[l - 1][..n_in * c]);
            kernels::vectorized(kernels::ScaleByDerivative(act, h, gh));
        }
        if let Some(g_in) = g_in {
            let (n_in, n_out) = (sizes[0], sizes[1]);
            assert_eq!(g_in.len(), n_in * c, "input gradient length");
            linalg::mul_wt(
                g_in,
                self.weights(0),
                &ws.grad[0][..n_out * c],
                n_out,
                n_in,
                c,
            );
        }
    }
}

/// Rows `row0..row0 + db.len()` of an `n_out × n_in` layer's gradients from one chunk of `c`
/// samples: dW ← G[rows] Hᵀ and db ← G[rows] 1, or added to them with `accumulate`. `g` is G
/// (`n_out × c`), `input` is H (`n_in × c`); `dw` is the `rows × n_in` row-major block.
pub(crate) fn weight_gradient_rows(
    n_out: usize,
    n_in: usize,
    row0: usize,
    g: &[f64],
    input: &[f64],
    c: usize,
    accumulate: bool,
    dw: &mut [f64],
    db: &mut [f64],
) {
    let rows = db.len();
    linalg::mul_outer_rows(dw, g, input, n_out, row0, rows, n_in, c, accumulate);
    if !accumulate {
        db.fill(0.0);
    }
    for col in g[..n_out * c].chunks_exact(n_out) {
        db.iter_mut()
            .zip(&col[row0..row0 + rows])
            .for_each(|(d, g)| *d += g);
    }
}
