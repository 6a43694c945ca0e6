//! Maps from latent coordinates z to PCA coefficients q, with the derivatives the integrator needs.

/// A (possibly nonlinear) map q = f(z) with its Jacobian J = ∂q/∂z.
///
/// Implementations keep their own work buffers: these are called in the innermost loop.
pub trait Subspace {
    /// d, the number of latent coordinates.
    fn latent_dim(&self) -> usize;
    /// k, the number of PCA coefficients.
    fn coeff_dim(&self) -> usize;
    /// q = f(z).
    fn decode(&mut self, z: &[f64], q: &mut [f64]);
    /// out = J(z)ᵀ v.
    fn vjp(&mut self, z: &[f64], v: &[f64], out: &mut [f64]);
    /// The k×d Jacobian J(z), column-major.
    fn jacobian(&mut self, z: &[f64], out: &mut [f64]);
    /// A latent point whose decoding approximates q (the encoder, or a projection).
    fn encode(&mut self, q: &[f64], z: &mut [f64]);
    /// Whether J is constant (the subspace is linear).
    fn is_linear(&self) -> bool {
        false
    }
}

/// The identity map: z = q, J = I. Simulating in it is linear model reduction with the PCA basis.
#[derive(Debug, Clone, Copy)]
pub struct LinearSubspace {
    k: usize,
}

impl LinearSubspace {
    pub fn new(k: usize) -> Self {
        Self { k }
    }
}

impl Subspace for LinearSubspace {
    fn latent_dim(&self) -> usize {
        self.k
    }
    fn coeff_dim(&self) -> usize {
        self.k
    }
    fn decode(&mut self, z: &[f64], q: &mut [f64]) {
        q.copy_from_slice(z);
    }
    fn vjp(&mut self, _z: &[f64], v: &[f64], out: &mut [f64]) {
        out.copy_from_slice(v);
    }
    fn jacobian(&mut self, _z: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for i in 0..self.k {
            out[i * self.k + i] = 1.0;
        }
    }
    fn encode(&mut self, q: &[f64], z: &mut [f64]) {
        z.copy_from_slice(q);
    }
    fn is_linear(&self) -> bool {
        true
    }
}
