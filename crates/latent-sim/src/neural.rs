//! The autoencoder's decoder as a subspace: q = decode(z), J = ∂decode/∂z.

use nn::{Autoencoder, AutoencoderWorkspace};

use crate::Subspace;

/// A nonlinear subspace given by a trained autoencoder (on PCA coefficients).
///
/// Keeps the decoder's workspace, and remembers the last decoded z so that the VJP that follows
/// a decode at the same point (every gradient evaluation) reuses the forward pass.
#[derive(Debug, Clone)]
pub struct NeuralSubspace {
    model: Autoencoder,
    ws: AutoencoderWorkspace,
    last_z: Vec<f64>,
    has_forward: bool,
}

impl NeuralSubspace {
    pub fn new(model: Autoencoder) -> Self {
        let ws = model.workspace();
        let d = model.latent_dim();
        Self {
            model,
            ws,
            last_z: vec![f64::NAN; d],
            has_forward: false,
        }
    }

    pub fn model(&self) -> &Autoencoder {
        &self.model
    }
}

impl Subspace for NeuralSubspace {
    fn latent_dim(&self) -> usize {
        self.model.latent_dim()
    }

    fn coeff_dim(&self) -> usize {
        self.model.input_dim()
    }

    fn decode(&mut self, z: &[f64], q: &mut [f64]) {
        self.model.decode(z, q, &mut self.ws);
        self.last_z.copy_from_slice(z);
        self.has_forward = true;
    }

    fn vjp(&mut self, z: &[f64], v: &[f64], out: &mut [f64]) {
        if self.has_forward && self.last_z == z {
            self.model.decode_vjp_cached(v, out, &mut self.ws);
        } else {
            self.model.decode_vjp(z, v, out, &mut self.ws);
            self.has_forward = false;
        }
    }

    fn jacobian(&mut self, z: &[f64], out: &mut [f64]) {
        self.model.decode_jacobian(z, out, &mut self.ws);
        self.has_forward = false;
    }

    fn encode(&mut self, q: &[f64], z: &mut [f64]) {
        self.model.encode(q, z, &mut self.ws);
    }
}
