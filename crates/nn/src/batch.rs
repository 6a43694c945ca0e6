//! Batched evaluation and backpropagation of an [`Mlp`] for training.
//!
//! A batch of c inputs is an `n₀ × c` column-major block X (one sample per contiguous column).
//! Forward: A_l = W_l H_{l−1} + b_l 1ᵀ, H_l = σ(A_l). Backward from G_L = ∂ℒ/∂A_L:
//! ∂ℒ/∂W_l = G_l H_{l−1}ᵀ, ∂ℒ/∂b_l = G_l 1, G_{l−1} = σ'(A_{l−1}) ⊙ (W_lᵀ G_l), and the input
//! gradient Wᵀ₁G₁ when asked. Every product is one matrix–matrix multiplication.

use crate::{Mlp, linalg};

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
#[derive(Debug, Clone)]
pub struct MlpBatchWorkspace {
    sizes: Vec<usize>,
    capacity: usize,
    /// A_l, n_l × capacity, for every dense layer.
    pre: Vec<Vec<f64>>,
    /// H_l, n_l × capacity, for every hidden layer.
    post: Vec<Vec<f64>>,
    /// Backward buffers, widest × capacity.
    ga: Vec<f64>,
    gh: Vec<f64>,
}

impl MlpBatchWorkspace {
    /// The largest batch this workspace holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }
}

impl Mlp {
    /// Scratch memory for [`Mlp::forward_batch`] / [`Mlp::backward_batch`] on up to `capacity`
    /// samples.
    pub fn batch_workspace(&self, capacity: usize) -> MlpBatchWorkspace {
        let sizes = self.sizes();
        let widest = sizes.iter().copied().max().unwrap_or(0);
        let layers = sizes.len() - 1;
        MlpBatchWorkspace {
            sizes: sizes.to_vec(),
            capacity,
            pre: sizes[1..]
                .iter()
                .map(|&n| vec![0.0; n * capacity])
                .collect(),
            post: sizes[1..layers]
                .iter()
                .map(|&n| vec![0.0; n * capacity])
                .collect(),
            ga: vec![0.0; widest * capacity],
            gh: vec![0.0; widest * capacity],
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
            let input: &[f64] = if l == 0 { x } else { &ws.post[l - 1] };
            let a = &mut ws.pre[l][..n_out * c];
            linalg::mul_w(a, self.weights(l), input, n_out, n_in, c);
            let b = self.bias(l);
            for col in a.chunks_exact_mut(n_out) {
                col.iter_mut().zip(b).for_each(|(a, b)| *a += b);
            }
            if l < last {
                self.activations()[l].apply(&ws.pre[l][..n_out * c], &mut ws.post[l]);
            }
        }
        &ws.pre[last][..sizes[last + 1] * c]
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
        let sizes = self.sizes();
        let last = self.num_layers() - 1;
        assert_eq!(x.len(), sizes[0] * c, "input block length");
        assert_eq!(g_out.len(), sizes[last + 1] * c, "output gradient length");
        ws.ga[..g_out.len()].copy_from_slice(g_out);
        for l in (0..=last).rev() {
            let (n_in, n_out) = (sizes[l], sizes[l + 1]);
            let input: &[f64] = if l == 0 { x } else { &ws.post[l - 1] };
            let g = &ws.ga[..n_out * c];
            linalg::mul_outer(&mut grad.weights[l], g, input, n_out, n_in, c);
            let db = &mut grad.biases[l];
            db.fill(0.0);
            for col in g.chunks_exact(n_out) {
                db.iter_mut().zip(col).for_each(|(d, g)| *d += g);
            }
            if l > 0 {
                let gh = &mut ws.gh[..n_in * c];
                linalg::mul_wt(gh, self.weights(l), g, n_out, n_in, c);
                self.activations()[l - 1].scale_by_derivative(
                    &ws.pre[l - 1][..n_in * c],
                    &ws.post[l - 1],
                    gh,
                );
                std::mem::swap(&mut ws.ga, &mut ws.gh);
            }
        }
        if let Some(g_in) = g_in {
            let (n_in, n_out) = (sizes[0], sizes[1]);
            linalg::mul_wt(g_in, self.weights(0), &ws.ga, n_out, n_in, c);
        }
    }
}
