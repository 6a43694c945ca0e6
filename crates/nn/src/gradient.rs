//! The batch loss and its gradient for training, parallel and bit-identical on any number of
//! threads, optionally fused with the Adam step.
//!
//! For a batch of n scaled samples the loss is Σ‖dec(enc(s)) − s‖² / (n k). The work is split
//! in two phases, each over a partition that depends only on the shapes, never on the thread
//! count:
//!
//! 1. Samples, in fixed chunks of [`CHUNK`]: forward through both networks, residual, and the
//!    backward sweep of the gradients G_l = ∂ℒ/∂A_l (one matrix product per layer and chunk).
//!    Chunk sums of the loss are added in chunk order.
//! 2. Weights, in fixed row blocks of every layer: dW = Σ_chunks G_l Hᵀ_{l−1} (chunks in order)
//!    and db = Σ G_l 1, then, when training, the Adam update of exactly those rows while they are
//!    still in cache. Each gradient entry is computed by one task in a fixed order, so no
//!    per-thread partial gradients are summed.

use rayon::prelude::*;

use crate::adam::{Adam, AdamUpdate};
use crate::{Autoencoder, AutoencoderGradient, CHUNK, MlpBatchWorkspace, batch, kernels};

/// About this many weights per row block of phase 2: a 200 × 200 layer is split in four (enough
/// blocks to balance two threads), small layers are one block.
const BLOCK_WEIGHTS: usize = 12_000;

/// The batch workspaces of both networks for one chunk of samples.
#[derive(Debug, Clone)]
pub(crate) struct ChunkWorkspace {
    pub(crate) encoder: MlpBatchWorkspace,
    pub(crate) decoder: MlpBatchWorkspace,
}

impl ChunkWorkspace {
    pub(crate) fn new(ae: &Autoencoder) -> Self {
        Self {
            encoder: ae.encoder().batch_workspace(CHUNK),
            decoder: ae.decoder().batch_workspace(CHUNK),
        }
    }
}

/// Which network of the autoencoder a row block belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Net {
    Encoder,
    Decoder,
}

/// Rows `row0..row0 + db.len()` of one layer's gradient, and the parameters and Adam moments of
/// those rows when the step is fused.
#[derive(Debug)]
struct RowBlock<'a> {
    net: Net,
    layer: usize,
    row0: usize,
    n_in: usize,
    dw: &'a mut [f64],
    db: &'a mut [f64],
    step: Option<StepBlock<'a>>,
}

#[derive(Debug)]
struct StepBlock<'a> {
    w: &'a mut [f64],
    b: &'a mut [f64],
    mw: &'a mut [f64],
    vw: &'a mut [f64],
    mb: &'a mut [f64],
    vb: &'a mut [f64],
}

/// The parameter arrays and Adam moments, in [`Autoencoder::parameters_mut`] order.
struct StepArrays<'a> {
    params: Vec<&'a mut [f64]>,
    m: Vec<&'a mut [f64]>,
    v: Vec<&'a mut [f64]>,
}

/// Rows per block of an `n_out × n_in` layer (a function of the shape only).
fn rows_per_block(n_out: usize, n_in: usize) -> usize {
    let blocks = (n_out * n_in).div_ceil(BLOCK_WEIGHTS).clamp(1, n_out);
    n_out.div_ceil(blocks)
}

fn split(a: &mut [f64], len: usize) -> Vec<&mut [f64]> {
    a.chunks_mut(len).collect()
}

/// The row blocks of every layer of both networks. `grads` holds the gradient arrays in
/// parameter order (W₁, b₁, W₂, …, encoder then decoder); `step` the matching parameters and
/// moments.
fn row_blocks<'a>(
    sizes: &[Vec<usize>; 2],
    mut grads: Vec<&'a mut [f64]>,
    mut step: Option<StepArrays<'a>>,
) -> Vec<RowBlock<'a>> {
    let take = std::mem::take::<&'a mut [f64]>;
    let mut blocks = Vec::new();
    let mut array = 0;
    for (net, sizes) in [Net::Encoder, Net::Decoder].into_iter().zip(sizes) {
        for (layer, w) in sizes.windows(2).enumerate() {
            let (n_in, n_out) = (w[0], w[1]);
            let rb = rows_per_block(n_out, n_in);
            let (iw, ib) = (array, array + 1);
            array += 2;
            let dws = split(take(&mut grads[iw]), rb * n_in);
            let dbs = split(take(&mut grads[ib]), rb);
            let mut steps = step.as_mut().map(|s| {
                [
                    split(take(&mut s.params[iw]), rb * n_in),
                    split(take(&mut s.params[ib]), rb),
                    split(take(&mut s.m[iw]), rb * n_in),
                    split(take(&mut s.v[iw]), rb * n_in),
                    split(take(&mut s.m[ib]), rb),
                    split(take(&mut s.v[ib]), rb),
                ]
            });
            for (i, (dw, db)) in dws.into_iter().zip(dbs).enumerate() {
                let step = steps.as_mut().map(|s| StepBlock {
                    w: take(&mut s[0][i]),
                    b: take(&mut s[1][i]),
                    mw: take(&mut s[2][i]),
                    vw: take(&mut s[3][i]),
                    mb: take(&mut s[4][i]),
                    vb: take(&mut s[5][i]),
                });
                blocks.push(RowBlock {
                    net,
                    layer,
                    row0: i * rb,
                    n_in,
                    dw,
                    db,
                    step,
                });
            }
        }
    }
    blocks
}

/// Reusable state for the loss and gradient over batches of up to `capacity` samples.
#[derive(Debug, Clone)]
pub(crate) struct GradientEngine {
    chunks: Vec<ChunkWorkspace>,
    /// Per-chunk sums of squared residuals.
    sums: Vec<f64>,
    /// ∇ of Σ‖r‖²/(n k) after [`GradientEngine::run`] or [`GradientEngine::run_adam_step`].
    pub(crate) grad: AutoencoderGradient,
}

impl GradientEngine {
    pub(crate) fn new(ae: &Autoencoder, capacity: usize) -> Self {
        let chunks = capacity.div_ceil(CHUNK).max(1);
        Self {
            chunks: (0..chunks).map(|_| ChunkWorkspace::new(ae)).collect(),
            sums: vec![0.0; chunks],
            grad: AutoencoderGradient::zeros(ae),
        }
    }

    /// Σ‖r‖² over the `n` samples of the scaled block `x`; `grad` = ∇ of Σ‖r‖²/(n k).
    pub(crate) fn run(&mut self, ae: &Autoencoder, x: &[f64], n: usize) -> f64 {
        let x = &x[..n * ae.input_dim()];
        let sum = self.forward_backward(ae, x, n);
        let sizes = [ae.encoder().sizes().to_vec(), ae.decoder().sizes().to_vec()];
        let blocks = row_blocks(&sizes, self.grad.slices_mut().collect(), None);
        let chunks = &self.chunks[..n.div_ceil(CHUNK)];
        blocks
            .into_par_iter()
            .for_each(|block| weight_block(chunks, x, &sizes, block, None));
        sum
    }

    /// Like [`GradientEngine::run`], then one Adam step of `ae` with that gradient.
    pub(crate) fn run_adam_step(
        &mut self,
        ae: &mut Autoencoder,
        adam: &mut Adam,
        x: &[f64],
        n: usize,
    ) -> f64 {
        let x = &x[..n * ae.input_dim()];
        let sum = self.forward_backward(ae, x, n);
        let sizes = [ae.encoder().sizes().to_vec(), ae.decoder().sizes().to_vec()];
        let update = adam.begin_step();
        let (m, v) = adam.moments_mut();
        let step = StepArrays {
            params: ae.parameters_mut().collect(),
            m: m.collect(),
            v: v.collect(),
        };
        let blocks = row_blocks(&sizes, self.grad.slices_mut().collect(), Some(step));
        let chunks = &self.chunks[..n.div_ceil(CHUNK)];
        blocks
            .into_par_iter()
            .for_each(|block| weight_block(chunks, x, &sizes, block, Some(update)));
        sum
    }

    /// Phase 1: every chunk's forward pass, residual and backward sweep; returns Σ‖r‖².
    fn forward_backward(&mut self, ae: &Autoencoder, x: &[f64], n: usize) -> f64 {
        let k = ae.input_dim();
        let weight = 1.0 / (n * k) as f64;
        let chunks = n.div_ceil(CHUNK);
        assert!(chunks <= self.chunks.len(), "batch exceeds the engine");
        x[..n * k]
            .par_chunks(k * CHUNK)
            .zip(self.chunks.par_iter_mut())
            .zip(self.sums.par_iter_mut())
            .for_each(|((block, ws), sum)| *sum = chunk_forward_backward(ae, block, weight, ws));
        self.sums[..chunks].iter().sum()
    }

    /// The loss training monitors: the mean squared error over `validation` when it holds
    /// samples, else over `train` (both scaled blocks).
    pub(crate) fn mean_squared_error(
        &mut self,
        ae: &Autoencoder,
        validation: &[f64],
        train: &[f64],
    ) -> f64 {
        let x = if validation.is_empty() {
            train
        } else {
            validation
        };
        self.sum_squared_error(ae, x) / x.len() as f64
    }

    /// Σ‖dec(enc(s)) − s‖² over the scaled block `x` (any length), chunk sums added in order.
    pub(crate) fn sum_squared_error(&mut self, ae: &Autoencoder, x: &[f64]) -> f64 {
        let k = ae.input_dim();
        let mut total = 0.0;
        for round in x.chunks(k * CHUNK * self.chunks.len()) {
            let chunks = (round.len() / k).div_ceil(CHUNK);
            round
                .par_chunks(k * CHUNK)
                .zip(self.chunks.par_iter_mut())
                .zip(self.sums.par_iter_mut())
                .for_each(|((block, ws), sum)| {
                    let c = block.len() / k;
                    let y = ae.forward_chunk(block, c, ws);
                    *sum = y.iter().zip(block).map(|(y, s)| (y - s) * (y - s)).sum();
                });
            total = self.sums[..chunks].iter().fold(total, |t, s| t + s);
        }
        total
    }
}

/// One chunk of phase 1: Σ‖r‖² of the chunk, and in `ws` every G_l of ℒ = weight · Σ‖r‖².
fn chunk_forward_backward(
    ae: &Autoencoder,
    x: &[f64],
    weight: f64,
    ws: &mut ChunkWorkspace,
) -> f64 {
    let (k, d) = (ae.input_dim(), ae.latent_dim());
    let c = x.len() / k;
    ae.forward_chunk(x, c, ws);
    let (y, r) = ws.decoder.output_and_gradient_mut(c);
    let mut sum = 0.0;
    for ((r, y), s) in r.iter_mut().zip(y).zip(x) {
        let e = y - s;
        sum += e * e;
        *r = 2.0 * weight * e;
    }
    let gz = ws.encoder.output_gradient_mut(c);
    ae.decoder()
        .backward_data(c, Some(&mut *gz), &mut ws.decoder);
    if ae.has_skip() {
        // ŝ = dec(z) + (z, 0): the residual's leading d entries reach z directly.
        let r = ws.decoder.output_gradient_mut(c);
        for (gc, rc) in gz.chunks_exact_mut(d).zip(r.chunks_exact(k)) {
            gc.iter_mut().zip(rc).for_each(|(g, r)| *g += r);
        }
    }
    // The encoder's input is data: its gradient is not needed.
    ae.encoder().backward_data(c, None, &mut ws.encoder);
    sum
}

/// One row block of phase 2: its weight and bias gradient summed over the chunks in order, then
/// the Adam update of its rows when fused.
fn weight_block(
    chunks: &[ChunkWorkspace],
    x: &[f64],
    sizes: &[Vec<usize>; 2],
    block: RowBlock<'_>,
    update: Option<AdamUpdate>,
) {
    let RowBlock {
        net,
        layer,
        row0,
        n_in,
        dw,
        db,
        step,
    } = block;
    let k = sizes[0][0];
    let n_out = sizes[usize::from(net == Net::Decoder)][layer + 1];
    let mut start = 0;
    for (j, ws) in chunks.iter().enumerate() {
        let c = CHUNK.min(x.len() / k - start);
        let mlp_ws = match net {
            Net::Encoder => &ws.encoder,
            Net::Decoder => &ws.decoder,
        };
        let input = match (net, layer) {
            (Net::Encoder, 0) => &x[start * k..(start + c) * k],
            (Net::Decoder, 0) => ws.encoder.output(c),
            _ => mlp_ws.hidden(layer, c),
        };
        let g = mlp_ws.gradient(layer, c);
        batch::weight_gradient_rows(n_out, n_in, row0, g, input, c, j > 0, dw, db);
        start += c;
    }
    if let (Some(s), Some(u)) = (step, update) {
        kernels::vectorized(AdamRows {
            update: u,
            step: s,
            dw,
            db,
        });
    }
}

/// The Adam update of one row block's weights and biases, vectorised.
struct AdamRows<'a, 'b> {
    update: AdamUpdate,
    step: StepBlock<'a>,
    dw: &'b [f64],
    db: &'b [f64],
}

impl kernels::Elementwise for AdamRows<'_, '_> {
    #[inline(always)]
    fn run(self) {
        let Self {
            update,
            step: s,
            dw,
            db,
        } = self;
        update.apply(s.w, dw, s.mw, s.vw);
        update.apply(s.b, db, s.mb, s.vb);
    }
}
