//! Whether a body can stand under its own weight: the linearised buckling load of gravity.
//!
//! At rest the pins hold the body against its weight with the linear response u_g = K₀⁻¹f_g and
//! the stresses σ_e of u_g in each element. Those stresses stiffen or soften the body against
//! any further displacement through the geometric stiffness K_σ (for nodes a, b of a tet of
//! volume W: W (∇N_a · σ ∇N_b) I₃). Gravity scaled by λ buckles the body where K₀ + λK_σ turns
//! singular: λ_cr is 1/μ for μ the largest eigenvalue of −K₀⁻¹K_σ (positive where compression
//! softens). Below 1 the body cannot stand as it is pinned: a plate standing on its edge
//! buckles, a figure on soft legs falls over, and a simulation of it bifurcates, so that small
//! differences (a reduced model's) grow into different motions. A body that hangs from its pins
//! is in tension and has no positive μ.
//!
//! The linear material has no geometric stiffness (its strain is linear in the displacement), so
//! nothing of this applies to it.

use crate::integrator::FullSpaceModel;
use crate::material::{AnyMaterial, Material};
use crate::step_norm::rest_stiffness;
use crate::{FemError, Mat3, with_material};

/// Power iterations at the most for each of the (at most two) eigenvalue searches.
const MAX_ITERATIONS: usize = 300;

/// The iteration stops when the estimate of μ changes by less than this, relatively.
const TOLERANCE: f64 = 1e-4;

/// What the buckling analysis found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GravityBuckling {
    /// λ_cr: gravity times this buckles the body (linearised at rest); `None` when no load
    /// along gravity does (every positive μ is absent: the body hangs in tension).
    pub load_factor: Option<f64>,
    /// Whether the power iteration met [`TOLERANCE`] within [`MAX_ITERATIONS`].
    pub converged: bool,
    /// The largest vertex displacement of the linear response to gravity, u_g = K₀⁻¹f_g (m).
    pub sag: f64,
}

/// The linearised buckling load of `model`'s gravity (see the module docs). `None` without
/// gravity or pins (nothing holds the body against its weight) and for the linear material.
///
/// # Errors
/// [`FemError`] when K₀ cannot be factorised.
pub fn gravity_buckling(model: &FullSpaceModel) -> Result<Option<GravityBuckling>, FemError> {
    if model.gravity.norm() == 0.0
        || model.pinned.is_empty()
        || matches!(model.material, AnyMaterial::Linear(_))
    {
        return Ok(None);
    }
    let mut parts = rest_stiffness(model)?;
    let stiffness = parts.values.clone();
    parts.factor()?;
    let n = model.dofs.num_free();
    let mut u = vec![0.0; n];
    model.dofs.gather(&model.gravity_load, &mut u);
    parts.chol.solve_in_place(&mut u);
    let mut full = vec![0.0; model.num_full()];
    model.dofs.scatter(&u, &mut full);
    let stress = with_material!(&model.material, |m| linear_stresses(m, model, &full));
    let geometric = Geometric {
        model,
        stress: &stress,
    };
    let solve = |x: &mut [f64]| parts.chol.solve_in_place(x);
    let k0 = |x: &[f64], y: &mut [f64]| parts.pattern.mul_vec(&stiffness, x, y);
    // A start with a share of every mode: the gravity response itself misses the sideways
    // modes of a symmetric body, so a fixed pseudo-random part is added.
    let start: Vec<f64> = u
        .iter()
        .enumerate()
        .map(|(i, &v)| v + (u_max(&u) * 0.5) * hash_unit(i))
        .collect();
    let first = power_iteration(&geometric, &solve, &k0, &start, 0.0);
    let (mu, converged) = if first.0 > 0.0 {
        first
    } else {
        // The dominant eigenvalue is negative (tension): shifted by it, the largest positive
        // one becomes dominant.
        let shift = -first.0;
        let (m, c) = power_iteration(&geometric, &solve, &k0, &start, shift);
        (m - shift, c && first.1)
    };
    let sag = full
        .chunks_exact(3)
        .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
        .fold(0.0, f64::max);
    Ok(Some(GravityBuckling {
        load_factor: (mu > 0.0).then(|| 1.0 / mu),
        converged,
        sag,
    }))
}

/// The largest |value| of `u` (1 where all are zero).
fn u_max(u: &[f64]) -> f64 {
    let m = u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if m > 0.0 { m } else { 1.0 }
}

/// A fixed number in [−1, 1] for index `i` (a hash, so that the start is the same every run).
fn hash_unit(i: usize) -> f64 {
    let mut x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
    x ^= x >> 33;
    x = x.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    x ^= x >> 33;
    (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

/// The stress of each element under the full displacement `u`, linearised at rest: the central
/// difference of the material's P at I ± εH (H = ∇u), exact for a quadratic P and within ε² of
/// the tangent otherwise.
fn linear_stresses<M: Material>(material: &M, model: &FullSpaceModel, u: &[f64]) -> Vec<Mat3> {
    (0..model.elements.len())
        .map(|e| {
            let h = model.elements.deformation_gradient(e, u) - Mat3::identity();
            let size = h.abs().max();
            if size == 0.0 {
                return Mat3::zeros();
            }
            let eps = 1e-4 / size;
            let p = (material.pk1(&(Mat3::identity() + h * eps))
                - material.pk1(&(Mat3::identity() - h * eps)))
                / (2.0 * eps);
            (p + p.transpose()) * 0.5
        })
        .collect()
}

/// The geometric stiffness K_σ on the free DOFs, as a product.
struct Geometric<'a> {
    model: &'a FullSpaceModel,
    stress: &'a [Mat3],
}

impl Geometric<'_> {
    /// y = K_σ x on the free DOFs (`full` is scratch of the full size).
    fn apply(&self, x: &[f64], y: &mut [f64], full: &mut [f64], out: &mut [f64]) {
        let (model, elements) = (self.model, &self.model.elements);
        model.dofs.scatter(x, full);
        out.fill(0.0);
        for (e, t) in elements.tets.iter().enumerate() {
            let g = elements.shape_gradients(e);
            let w = elements.volume[e];
            let s = &self.stress[e];
            let sg: Vec<[f64; 3]> = g
                .iter()
                .map(|gb| {
                    let v = s * crate::Vec3::from(*gb);
                    [v.x, v.y, v.z]
                })
                .collect();
            for a in 0..4 {
                for b in 0..4 {
                    let c = w * (g[a][0] * sg[b][0] + g[a][1] * sg[b][1] + g[a][2] * sg[b][2]);
                    for i in 0..3 {
                        out[3 * t[a] + i] += c * full[3 * t[b] + i];
                    }
                }
            }
        }
        model.dofs.gather(out, y);
    }
}

/// The eigenvalue of −K₀⁻¹K_σ (+ shift) of largest magnitude by power iteration from `start`,
/// returned without the shift as the Rayleigh quotient (−xᵀK_σx)/(xᵀK₀x) + shift, and whether
/// it converged. The operator is self-adjoint in the K₀ inner product, so the quotient converges
/// at twice the rate of the vector.
fn power_iteration(
    geometric: &Geometric<'_>,
    solve: &dyn Fn(&mut [f64]),
    k0: &dyn Fn(&[f64], &mut [f64]),
    start: &[f64],
    shift: f64,
) -> (f64, bool) {
    let n = start.len();
    let full_len = geometric.model.num_full();
    let (mut full, mut out) = (vec![0.0; full_len], vec![0.0; full_len]);
    let (mut x, mut y, mut kx) = (start.to_vec(), vec![0.0; n], vec![0.0; n]);
    let mut estimate = f64::NAN;
    for _ in 0..MAX_ITERATIONS {
        geometric.apply(&x, &mut y, &mut full, &mut out);
        y.iter_mut().for_each(|v| *v = -*v);
        k0(&x, &mut kx);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
        let (num, den) = (dot(&x, &y), dot(&x, &kx));
        if den.is_nan() || den <= 0.0 || !num.is_finite() {
            return (0.0, false);
        }
        let quotient = num / den + shift;
        let done = (quotient - estimate).abs() <= TOLERANCE * quotient.abs();
        estimate = quotient;
        if done {
            return (estimate, true);
        }
        // x ← K₀⁻¹(−K_σ x) + shift x, scaled to unit K₀-norm.
        solve(&mut y);
        for (yi, xi) in y.iter_mut().zip(&x) {
            *yi += shift * xi;
        }
        k0(&y, &mut kx);
        let norm = dot(&y, &kx).sqrt();
        if norm.is_nan() || norm <= 0.0 {
            return (0.0, false);
        }
        for (xi, yi) in x.iter_mut().zip(&y) {
            *xi = yi / norm;
        }
    }
    (estimate, false)
}
