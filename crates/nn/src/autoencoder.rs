//! The autoencoder on PCA coefficients: q ∈ Rᵏ → encoder → z ∈ Rᵈ → decoder → q̂ ∈ Rᵏ, with an
//! optional per-feature [`InputScaling`] s = (q − shift)/scale in front of the encoder and undone
//! behind the decoder. Its serialised form is the model artifact.
//!
//! The networks see scaled coefficients: encode(q) = enc((q − shift)/scale) and
//! decode(z) = shift + scale ⊙ dec(z). Hence the decoder Jacobian in original units is
//! J = diag(scale) J_dec, and Jᵀv = J_decᵀ (scale ⊙ v), Jw = scale ⊙ (J_dec w).
//!
//! The training loss is the mean squared reconstruction error of the *scaled* coefficients,
//! ℒ = 1/(N k) Σ_j ‖dec(enc(s_j)) − s_j‖², which is what [`Autoencoder::loss`] returns.
//!
//! With the linear skip ([`Autoencoder::with_skip`]) both networks are residuals around the
//! truncation to the leading d features: z = enc(s) + s₁..d and ŝ = dec(z) + (z, 0). For PCA
//! coefficients (ordered by variance) the autoencoder then starts as PCA-d, exactly when the
//! output layers start at zero, and training only learns the nonlinear correction.

use faer::{Mat, MatRef};
use rayon::prelude::*;

use crate::gradient::{ChunkWorkspace, GradientEngine};
use crate::{Activation, InputScaling, Mlp, MlpGradient, MlpWorkspace, NnError};

/// Samples per parallel work item in batched evaluation and training. Fixed (not derived from the
/// thread count) so that sums over chunks, taken in chunk order, are bit-identical on any number
/// of threads.
pub const CHUNK: usize = 64;

/// A trained (or freshly initialised) autoencoder: encoder, decoder and optional input scaling.
///
/// Deserialisation checks [`Autoencoder::FORMAT_VERSION`], that the encoder maps k → d and the
/// decoder d → k, that the scaling has k features, and that every weight is finite.
#[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "AutoencoderData")]
pub struct Autoencoder {
    format_version: u32,
    encoder: Mlp,
    decoder: Mlp,
    scaling: Option<InputScaling>,
    /// The linear skip: identity from the leading d inputs to z and from z to the leading d
    /// outputs (see the module docs).
    skip: bool,
}

impl Clone for Autoencoder {
    fn clone(&self) -> Self {
        Self {
            format_version: self.format_version,
            encoder: self.encoder.clone(),
            decoder: self.decoder.clone(),
            scaling: self.scaling.clone(),
            skip: self.skip,
        }
    }

    /// Reuses the weight arrays of `self`.
    fn clone_from(&mut self, source: &Self) {
        self.format_version = source.format_version;
        self.encoder.clone_from(&source.encoder);
        self.decoder.clone_from(&source.decoder);
        self.scaling.clone_from(&source.scaling);
        self.skip = source.skip;
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct AutoencoderData {
    format_version: u32,
    encoder: Mlp,
    decoder: Mlp,
    scaling: Option<InputScaling>,
    /// Absent in version 1 files, which had no skip.
    #[serde(default)]
    skip: bool,
}

impl TryFrom<AutoencoderData> for Autoencoder {
    type Error = NnError;

    fn try_from(d: AutoencoderData) -> Result<Self, NnError> {
        if !(1..=Autoencoder::FORMAT_VERSION).contains(&d.format_version) {
            return Err(NnError::InvalidModel(format!(
                "format version {} is not a supported version (1 to {})",
                d.format_version,
                Autoencoder::FORMAT_VERSION
            )));
        }
        if d.format_version < 2 && d.skip {
            return Err(NnError::InvalidModel(
                "format version 1 has no linear skip, but `skip` is set".into(),
            ));
        }
        let mut ae = Autoencoder::new(d.encoder, d.decoder, d.scaling)?;
        if d.skip {
            ae.set_skip()?;
        }
        Ok(ae)
    }
}

impl Autoencoder {
    /// The version of the serialised layout; bumped whenever it changes. Version 2 added `skip`;
    /// version 1 files still load (without a skip).
    pub const FORMAT_VERSION: u32 = 2;

    /// An autoencoder from its parts, checking that they fit together.
    pub fn new(encoder: Mlp, decoder: Mlp, scaling: Option<InputScaling>) -> Result<Self, NnError> {
        let bad = |reason: String| Err(NnError::InvalidModel(reason));
        let (k, d) = (encoder.input_dim(), encoder.output_dim());
        if decoder.input_dim() != d || decoder.output_dim() != k {
            return bad(format!(
                "encoder maps {k} → {d} but decoder maps {} → {}",
                decoder.input_dim(),
                decoder.output_dim()
            ));
        }
        if let Some(s) = &scaling
            && s.dim() != k
        {
            return bad(format!(
                "input scaling has {} features, the encoder takes {k}",
                s.dim()
            ));
        }
        if !encoder.is_finite() || !decoder.is_finite() {
            return bad("a weight or bias is not finite".into());
        }
        Ok(Self {
            format_version: Self::FORMAT_VERSION,
            encoder,
            decoder,
            scaling,
            skip: false,
        })
    }

    /// Turns on the linear skip (see the module docs) and zeroes both output layers, so that the
    /// autoencoder starts as the truncation to the leading d features: z = s₁..d, ŝ = (z, 0).
    /// Needs d ≤ k.
    pub fn with_skip(mut self) -> Result<Self, NnError> {
        self.set_skip()?;
        for net in [&mut self.encoder, &mut self.decoder] {
            let last = net.num_layers() - 1;
            net.weights_mut(last).fill(0.0);
            net.bias_mut(last).fill(0.0);
        }
        Ok(self)
    }

    fn set_skip(&mut self) -> Result<(), NnError> {
        if self.latent_dim() > self.input_dim() {
            return Err(NnError::InvalidModel(format!(
                "a linear skip needs latent dimension {} ≤ input dimension {}",
                self.latent_dim(),
                self.input_dim()
            )));
        }
        self.skip = true;
        Ok(())
    }

    /// Whether the linear skip is on.
    pub fn has_skip(&self) -> bool {
        self.skip
    }

    /// Shifts the decoder's output bias so that decode(encode(q)) = q exactly for this `q` (the
    /// rest state, say), moving every reconstruction by the same constant.
    pub fn anchor(&mut self, q: &[f64]) {
        let mut ws = self.workspace();
        let mut out = vec![0.0; q.len()];
        self.reconstruct(q, &mut out, &mut ws);
        let last = self.decoder.num_layers() - 1;
        let scale = self.scaling.as_ref().map(|s| s.scale().to_vec());
        for (i, b) in self.decoder.bias_mut(last).iter_mut().enumerate() {
            let err = q[i] - out[i];
            *b += scale.as_ref().map_or(err, |s| err / s[i]);
        }
    }

    /// A freshly initialised autoencoder k → hidden… → d → reversed hidden… → k with `activation`
    /// on every hidden layer (linear latent and output layers). The encoder is seeded with stream
    /// 0 of `seed`, the decoder with stream 1.
    pub fn with_architecture(
        k: usize,
        d: usize,
        hidden: &[usize],
        activation: Activation,
        scaling: Option<InputScaling>,
        seed: u64,
    ) -> Result<Self, NnError> {
        let enc_sizes: Vec<usize> = std::iter::once(k)
            .chain(hidden.iter().copied())
            .chain(std::iter::once(d))
            .collect();
        let dec_sizes: Vec<usize> = enc_sizes.iter().rev().copied().collect();
        let mut streams = (0..2).map(|i| crate::SplitMix64::for_item(seed, i).next_u64());
        let encoder = Mlp::new(&enc_sizes, activation, streams.next().unwrap_or(0))?;
        let decoder = Mlp::new(&dec_sizes, activation, streams.next().unwrap_or(0))?;
        Self::new(encoder, decoder, scaling)
    }

    /// k, the number of PCA coefficients.
    pub fn input_dim(&self) -> usize {
        self.encoder.input_dim()
    }

    /// d, the latent dimension.
    pub fn latent_dim(&self) -> usize {
        self.encoder.output_dim()
    }

    /// The encoder's hidden layer widths (the decoder's, reversed).
    pub fn hidden_widths(&self) -> &[usize] {
        let sizes = self.encoder.sizes();
        &sizes[1..sizes.len() - 1]
    }

    pub fn encoder(&self) -> &Mlp {
        &self.encoder
    }

    pub fn decoder(&self) -> &Mlp {
        &self.decoder
    }

    /// Mutable networks, e.g. for finite-difference checks (the caller keeps them finite).
    pub fn networks_mut(&mut self) -> (&mut Mlp, &mut Mlp) {
        (&mut self.encoder, &mut self.decoder)
    }

    pub fn scaling(&self) -> Option<&InputScaling> {
        self.scaling.as_ref()
    }

    /// Every parameter array, encoder first then decoder, in [`Mlp::parameters_mut`] order.
    pub fn parameters_mut(&mut self) -> impl Iterator<Item = &mut [f64]> {
        self.encoder
            .parameters_mut()
            .chain(self.decoder.parameters_mut())
    }

    /// Scratch memory for the single-sample operations.
    pub fn workspace(&self) -> AutoencoderWorkspace {
        AutoencoderWorkspace {
            encoder: self.encoder.workspace(),
            decoder: self.decoder.workspace(),
            s: vec![0.0; self.input_dim()],
            z_scratch: vec![0.0; self.latent_dim()],
        }
    }

    /// z = encode(q).
    pub fn encode(&self, q: &[f64], z: &mut [f64], ws: &mut AutoencoderWorkspace) {
        let s: &[f64] = match &self.scaling {
            Some(sc) => {
                assert_eq!(q.len(), sc.dim(), "input length");
                sc.apply(q, &mut ws.s);
                &ws.s
            }
            None => q,
        };
        self.encoder.forward(s, z, &mut ws.encoder);
        if self.skip {
            add_leading(z, s);
        }
    }

    /// q = decode(z), in original units. Leaves the state for [`Autoencoder::decode_vjp_cached`].
    pub fn decode(&self, z: &[f64], q: &mut [f64], ws: &mut AutoencoderWorkspace) {
        self.decoder.forward(z, q, &mut ws.decoder);
        if self.skip {
            add_leading(q, z);
        }
        if let Some(sc) = &self.scaling {
            ws.s.copy_from_slice(q);
            sc.invert(&ws.s, q);
        }
    }

    /// out = decode(encode(q)).
    pub fn reconstruct(&self, q: &[f64], out: &mut [f64], ws: &mut AutoencoderWorkspace) {
        let mut z = std::mem::take(&mut ws.z_scratch);
        z.resize(self.latent_dim(), 0.0);
        self.encode(q, &mut z, ws);
        self.decode(&z, out, ws);
        ws.z_scratch = z;
    }

    /// out = J(z)ᵀ v for q = decode(z) in original units.
    pub fn decode_vjp(&self, z: &[f64], v: &[f64], out: &mut [f64], ws: &mut AutoencoderWorkspace) {
        let v: &[f64] = match &self.scaling {
            Some(sc) => {
                scale_into(sc.scale(), v, &mut ws.s);
                &ws.s
            }
            None => v,
        };
        self.decoder.vjp(z, v, out, &mut ws.decoder);
        if self.skip {
            add_leading(out, v);
        }
    }

    /// out = J(z)ᵀ v at the z of the last [`Autoencoder::decode`] on `ws` (no second forward
    /// pass: decode, form v = ∂E/∂q, then call this).
    ///
    /// # Panics
    /// If `ws` holds no decode.
    pub fn decode_vjp_cached(&self, v: &[f64], out: &mut [f64], ws: &mut AutoencoderWorkspace) {
        let v: &[f64] = match &self.scaling {
            Some(sc) => {
                scale_into(sc.scale(), v, &mut ws.s);
                &ws.s
            }
            None => v,
        };
        self.decoder.vjp_cached(v, out, &mut ws.decoder);
        if self.skip {
            add_leading(out, v);
        }
    }

    /// out = J(z) w for q = decode(z) in original units.
    pub fn decode_jvp(&self, z: &[f64], w: &[f64], out: &mut [f64], ws: &mut AutoencoderWorkspace) {
        self.decoder.jvp(z, w, out, &mut ws.decoder);
        if self.skip {
            add_leading(out, w);
        }
        if let Some(sc) = &self.scaling {
            out.iter_mut().zip(sc.scale()).for_each(|(o, s)| *o *= s);
        }
    }

    /// out = J(z), the `k × d` decoder Jacobian in original units, column-major.
    pub fn decode_jacobian(&self, z: &[f64], out: &mut [f64], ws: &mut AutoencoderWorkspace) {
        self.decoder.jacobian(z, out, &mut ws.decoder);
        if self.skip {
            let k = self.input_dim();
            for j in 0..self.latent_dim() {
                out[j * k + j] += 1.0;
            }
        }
        if let Some(sc) = &self.scaling {
            for col in out.chunks_exact_mut(sc.dim()) {
                col.iter_mut().zip(sc.scale()).for_each(|(o, s)| *o *= s);
            }
        }
    }

    /// The training objective on `data` (k × N, one sample per column): the mean squared error
    /// of the scaled reconstruction (see the module docs). Parallel over fixed chunks.
    pub fn loss(&self, data: MatRef<'_, f64>) -> Result<f64, NnError> {
        let x = self.scaled_block(data)?;
        Ok(self.sum_squared_error(&x) / x.len() as f64)
    }

    /// decode(encode(q)) for every column of `data` (k × N), in original units.
    pub fn reconstruct_batch(&self, data: MatRef<'_, f64>) -> Result<Mat<f64>, NnError> {
        let k = self.input_dim();
        let mut x = self.scaled_block(data)?;
        x.par_chunks_mut(k * CHUNK).for_each_init(
            || ChunkWorkspace::new(self),
            |ws, block| {
                let c = block.len() / k;
                let y = self.forward_chunk(block, c, ws);
                block.copy_from_slice(y);
            },
        );
        Ok(Mat::from_fn(k, data.ncols(), |i, j| {
            let s = x[j * k + i];
            match &self.scaling {
                Some(sc) => sc.shift()[i] + sc.scale()[i] * s,
                None => s,
            }
        }))
    }

    /// Both networks on a chunk of `c` scaled samples `x` (k × c), skips included; returns the
    /// reconstruction ŝ (k × c), which lives in `ws.decoder` (z in `ws.encoder`).
    pub(crate) fn forward_chunk<'w>(
        &self,
        x: &[f64],
        c: usize,
        ws: &'w mut ChunkWorkspace,
    ) -> &'w [f64] {
        let (k, d) = (self.input_dim(), self.latent_dim());
        self.encoder.forward_batch(x, c, &mut ws.encoder);
        let z = ws.encoder.output_mut(c);
        if self.skip {
            for (zc, xc) in z.chunks_exact_mut(d).zip(x.chunks_exact(k)) {
                add_leading(zc, xc);
            }
        }
        self.decoder.forward_batch(z, c, &mut ws.decoder);
        let y = ws.decoder.output_mut(c);
        if self.skip {
            for (yc, zc) in y.chunks_exact_mut(k).zip(z.chunks_exact(d)) {
                add_leading(yc, zc);
            }
        }
        ws.decoder.output(c)
    }

    /// The loss on `data` and its gradient with respect to every weight and bias.
    pub fn loss_gradient(
        &self,
        data: MatRef<'_, f64>,
    ) -> Result<(f64, AutoencoderGradient), NnError> {
        let x = self.scaled_block(data)?;
        let n = data.ncols();
        let mut engine = GradientEngine::new(self, n);
        let sum = engine.run(self, &x, n);
        Ok((sum / x.len() as f64, engine.grad))
    }

    /// The scaled data as one contiguous k × N column-major block, checking shape and finiteness.
    pub(crate) fn scaled_block(&self, data: MatRef<'_, f64>) -> Result<Vec<f64>, NnError> {
        let k = self.input_dim();
        if data.nrows() != k {
            return Err(NnError::ShapeMismatch {
                what: "data",
                expected: (k, data.ncols()),
                found: (data.nrows(), data.ncols()),
            });
        }
        let mut x = vec![0.0; k * data.ncols()];
        let mut raw = vec![0.0; k];
        for (j, col) in x.chunks_exact_mut(k).enumerate() {
            for i in 0..k {
                let v = data[(i, j)];
                if !v.is_finite() {
                    return Err(NnError::NonFiniteData {
                        feature: i,
                        sample: j,
                        value: v,
                    });
                }
                raw[i] = v;
            }
            match &self.scaling {
                Some(sc) => sc.apply(&raw, col),
                None => col.copy_from_slice(&raw),
            }
        }
        Ok(x)
    }

    /// Σ‖dec(enc(s)) − s‖² over the scaled block `x`, summed chunk by chunk in order.
    pub(crate) fn sum_squared_error(&self, x: &[f64]) -> f64 {
        let n = x.len() / self.input_dim();
        GradientEngine::new(self, n.min(8 * CHUNK)).sum_squared_error(self, x)
    }
}

/// a[i] += b[i] for the leading min(len) entries (the linear skip).
fn add_leading(a: &mut [f64], b: &[f64]) {
    a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
}

fn scale_into(scale: &[f64], v: &[f64], out: &mut [f64]) {
    assert_eq!(v.len(), scale.len(), "cotangent length");
    for i in 0..v.len() {
        out[i] = scale[i] * v[i];
    }
}

/// Scratch memory for the single-sample operations of an [`Autoencoder`].
#[derive(Debug, Clone)]
pub struct AutoencoderWorkspace {
    encoder: MlpWorkspace,
    decoder: MlpWorkspace,
    /// Scaled coefficients (length k).
    s: Vec<f64>,
    z_scratch: Vec<f64>,
}

/// ∂ℒ/∂θ for the encoder and decoder of an [`Autoencoder`].
#[derive(Debug, Clone, PartialEq)]
pub struct AutoencoderGradient {
    pub encoder: MlpGradient,
    pub decoder: MlpGradient,
}

impl AutoencoderGradient {
    pub fn zeros(ae: &Autoencoder) -> Self {
        Self {
            encoder: MlpGradient::zeros(&ae.encoder),
            decoder: MlpGradient::zeros(&ae.decoder),
        }
    }

    /// Every array in the order of [`Autoencoder::parameters_mut`].
    pub fn slices(&self) -> impl Iterator<Item = &[f64]> {
        self.encoder.slices().chain(self.decoder.slices())
    }

    /// Every array, mutable, in the order of [`Autoencoder::parameters_mut`].
    pub(crate) fn slices_mut(&mut self) -> impl Iterator<Item = &mut [f64]> {
        self.encoder.slices_mut().chain(self.decoder.slices_mut())
    }
}
