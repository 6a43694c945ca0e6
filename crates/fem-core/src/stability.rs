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
//! a linear simulation does not buckle; the estimate, made at rest where every material has the
//! same K₀ and stresses, says what the body would do under a nonlinear material of the same
//! modulus, which is what a user who is told to switch needs.

use crate::integrator::{FullSpaceModel, NewtonParts};
use crate::material::Material;
use crate::step_norm::rest_stiffness;
use crate::{FemError, Mat3, with_material};

/// Power iterations at the most for each of the (at most two) eigenvalue searches.
const MAX_ITERATIONS: usize = 300;

/// The iteration stops when the residual of its eigenpair is this small against the
/// eigenvalue (K₀ norm); the eigenvalue is then known to about its square, relatively.
const TOLERANCE: f64 = 1e-3;

/// What the buckling analysis found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GravityBuckling {
    /// λ_cr: gravity times this buckles the body (linearised at rest); `None` when no load
    /// along gravity does (no positive μ: the body hangs in tension), or when the search found
    /// none before it stopped. Unconverged it is an upper bound: the iteration's Rayleigh
    /// quotient never exceeds the largest eigenvalue μ, so 1/quotient ≥ 1/μ.
    pub load_factor: Option<f64>,
    /// Whether the power iteration reached its residual tolerance (10⁻³ of the eigenvalue)
    /// within its 300 iterations.
    pub converged: bool,
    /// The largest vertex displacement of the linear response to gravity, u_g = K₀⁻¹f_g (m).
    pub sag: f64,
}

/// The linearised buckling load of `model`'s gravity (see the module docs). `None` without
/// gravity or pins (nothing holds the body against its weight). For the linear material it is
/// the load of the same body under a nonlinear material of its modulus (a tester's linear
/// snowman moved 1.4 times its size with nothing said of the modulus that keeps it up).
///
/// # Errors
/// [`FemError`] when K₀ cannot be factorised.
pub fn gravity_buckling(model: &FullSpaceModel) -> Result<Option<GravityBuckling>, FemError> {
    if model.gravity.norm() == 0.0 || model.pinned.is_empty() {
        return Ok(None);
    }
    let Prestress {
        parts,
        stiffness,
        u,
        full,
        stress,
    } = Prestress::of(model)?;
    let geometric = Geometric {
        model,
        stress: &stress,
    };
    let solve = |x: &mut [f64]| parts.chol.solve_in_place(x);
    let k0 = |x: &[f64], y: &mut [f64]| parts.pattern.mul_vec(&stiffness, x, y);
    // A start with a share of every mode: the gravity response itself misses the sideways
    // modes of a symmetric body, so a fixed pseudo-random part is added.
    let scale = 0.5 * u_max(&u);
    let start: Vec<f64> = u
        .iter()
        .enumerate()
        .map(|(i, &v)| v + scale * hash_unit(i))
        .collect();
    let (mu, converged) = largest_positive(&geometric, &solve, &k0, &start);
    let sag = crate::integrator::max_displacement(&full);
    Ok(Some(GravityBuckling {
        load_factor: (mu > 0.0).then(|| 1.0 / mu),
        converged,
        sag,
    }))
}

/// The body held by its pins against its weight, linearised at rest.
struct Prestress {
    /// K₀ on the free DOFs, factorised.
    parts: NewtonParts,
    /// K₀'s values, for its products (the factor keeps its own copy).
    stiffness: Vec<f64>,
    /// u_g = K₀⁻¹f_g on the free DOFs, and on every DOF.
    u: Vec<f64>,
    full: Vec<f64>,
    /// The stress of u_g in each element.
    stress: Vec<Mat3>,
}

impl Prestress {
    fn of(model: &FullSpaceModel) -> Result<Self, FemError> {
        let mut parts = rest_stiffness(model)?;
        let stiffness = parts.values.clone();
        parts.factor()?;
        let mut u = vec![0.0; model.dofs.num_free()];
        model.dofs.gather(&model.gravity_load, &mut u);
        parts.chol.solve_in_place(&mut u);
        let mut full = vec![0.0; model.num_full()];
        model.dofs.scatter(&u, &mut full);
        let stress = with_material!(&model.material, |m| linear_stresses(m, model, &full));
        Ok(Self {
            parts,
            stiffness,
            u,
            full,
            stress,
        })
    }
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
    /// y = K_σ x on the free DOFs (`full` and `out` are scratch of the full size).
    fn apply(&self, x: &[f64], y: &mut [f64], full: &mut [f64], out: &mut [f64]) {
        let (model, elements) = (self.model, &self.model.elements);
        model.dofs.scatter(x, full);
        out.fill(0.0);
        for (e, t) in elements.tets.iter().enumerate() {
            let g = elements.shape_gradients(e);
            let (w, s) = (elements.volume[e], &self.stress[e]);
            let sg = g.map(|gb| s * crate::Vec3::from(gb));
            for a in 0..4 {
                for b in 0..4 {
                    let c = w * crate::Vec3::from(g[a]).dot(&sg[b]);
                    for i in 0..3 {
                        out[3 * t[a] + i] += c * full[3 * t[b] + i];
                    }
                }
            }
        }
        model.dofs.gather(out, y);
    }
}

/// The largest positive eigenvalue μ of −K₀⁻¹K_σ (≤ 0 when there is none) and whether it was
/// found to the tolerance. Power iteration finds the eigenvalue of largest magnitude; where
/// that is negative (tension dominates), a second run shifted by it makes the largest
/// positive one dominant. A first run that does not converge leaves the answer unknown.
fn largest_positive(
    geometric: &Geometric<'_>,
    solve: &dyn Fn(&mut [f64]),
    k0: &dyn Fn(&[f64], &mut [f64]),
    start: &[f64],
) -> (f64, bool) {
    let (first, converged) = power_iteration(geometric, solve, k0, start, 0.0, MAX_ITERATIONS);
    if first > 0.0 || !converged {
        return (first, converged);
    }
    let shift = -first;
    let (shifted, converged) = power_iteration(geometric, solve, k0, start, shift, MAX_ITERATIONS);
    (shifted - shift, converged)
}

/// The eigenvalue of largest magnitude of the operator A = −K₀⁻¹K_σ + shift·I by power
/// iteration from `start`: its Rayleigh quotient in the K₀ inner product (where A is
/// self-adjoint), shift included, and whether it converged: the residual ‖Ax − qx‖ in the K₀
/// norm within [`TOLERANCE`] of |q − shift| for a unit x. A stalled iteration (two eigenvalues
/// of equal magnitude and opposite sign, which a body bent about a neutral axis comes close
/// to) keeps a large residual and is reported as not converged, whatever its quotient does.
/// Stopped after `max_iterations`, the quotient is that of its last iterate, which is never
/// above the largest eigenvalue.
fn power_iteration(
    geometric: &Geometric<'_>,
    solve: &dyn Fn(&mut [f64]),
    k0: &dyn Fn(&[f64], &mut [f64]),
    start: &[f64],
    shift: f64,
    max_iterations: usize,
) -> (f64, bool) {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
    let n = start.len();
    let full_len = geometric.model.num_full();
    let (mut full, mut out) = (vec![0.0; full_len], vec![0.0; full_len]);
    let (mut x, mut y, mut kx, mut ky) = (start.to_vec(), vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    k0(&x, &mut kx);
    let mut quotient = f64::NAN;
    for _ in 0..max_iterations {
        // x has unit K₀-norm from the second pass on; den keeps the first one exact.
        let den = dot(&x, &kx);
        geometric.apply(&x, &mut y, &mut full, &mut out);
        y.iter_mut().for_each(|v| *v = -*v);
        let num = dot(&x, &y);
        if den.is_nan() || den <= 0.0 || !num.is_finite() {
            return (0.0, false);
        }
        quotient = num / den + shift;
        // y ← A x = K₀⁻¹(−K_σ x) + shift x.
        solve(&mut y);
        for (yi, xi) in y.iter_mut().zip(&x) {
            *yi += shift * xi;
        }
        k0(&y, &mut ky);
        // ‖Ax − qx‖²_K₀ = yᵀK₀y − 2q yᵀK₀x + q² xᵀK₀x, with yᵀK₀x = −xᵀK_σx + shift xᵀK₀x.
        let yy = dot(&y, &ky);
        let yx = num + shift * den;
        let residual = (yy - 2.0 * quotient * yx + quotient * quotient * den).max(0.0) / den;
        if residual.sqrt() <= TOLERANCE * (quotient - shift).abs() {
            return (quotient, true);
        }
        let norm = yy.sqrt();
        if norm.is_nan() || norm <= 0.0 {
            return (0.0, false);
        }
        for ((xi, yi), (kxi, kyi)) in x.iter_mut().zip(&y).zip(kx.iter_mut().zip(&ky)) {
            *xi = yi / norm;
            *kxi = kyi / norm;
        }
    }
    (quotient, false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constraints::{Axis, Side, VertexSelection};
    use crate::material::{MaterialConfig, MaterialModel};
    use crate::mesh::generate::{BoxSpec, box_mesh};

    /// A small bar along `size` of `cells`, pinned at `axis`'s `side`, under gravity along −y.
    fn bar(size: [f64; 3], cells: [usize; 3], axis: Axis, side: Side) -> FullSpaceModel {
        let mesh = box_mesh(&BoxSpec {
            size,
            cells,
            ..Default::default()
        })
        .unwrap();
        let pinned = VertexSelection::plane(axis, side, Some(1e-6))
            .select(&mesh, "pin")
            .unwrap();
        let material = MaterialConfig {
            model: MaterialModel::StableNeoHookean,
            youngs_modulus: 1e5,
            poisson_ratio: 0.3,
            ..Default::default()
        };
        FullSpaceModel::new(
            mesh,
            &material,
            pinned,
            crate::Vec3::new(0.0, -9.81, 0.0),
            vec![],
        )
        .unwrap()
    }

    /// The largest positive eigenvalue of −K₀⁻¹K_σ from dense matrices: K₀ = LLᵀ, and the
    /// eigenvalues of the symmetric L⁻¹(−K_σ)L⁻ᵀ.
    fn dense_largest(model: &FullSpaceModel) -> f64 {
        let p = Prestress::of(model).unwrap();
        let (parts, stiffness) = (&p.parts, &p.stiffness);
        let n = model.dofs.num_free();
        let geometric = Geometric {
            model,
            stress: &p.stress,
        };
        let (mut k, mut ks) = (
            nalgebra::DMatrix::zeros(n, n),
            nalgebra::DMatrix::zeros(n, n),
        );
        let (mut e, mut col) = (vec![0.0; n], vec![0.0; n]);
        let (mut f1, mut f2) = (vec![0.0; model.num_full()], vec![0.0; model.num_full()]);
        for j in 0..n {
            e.fill(0.0);
            e[j] = 1.0;
            parts.pattern.mul_vec(stiffness, &e, &mut col);
            k.set_column(j, &nalgebra::DVector::from_column_slice(&col));
            geometric.apply(&e, &mut col, &mut f1, &mut f2);
            ks.set_column(j, &nalgebra::DVector::from_column_slice(&col));
        }
        let l = k.cholesky().unwrap().l();
        let li = l.clone().try_inverse().unwrap();
        let a = &li * (-ks) * li.transpose();
        let a = (&a + a.transpose()) * 0.5;
        a.symmetric_eigenvalues()
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The power iteration finds the dense answer: on a standing column (compression), on a
    /// cantilever held horizontal (tension above, compression below), and on a hanging column
    /// (tension only: its largest eigenvalue is next to zero, below the others' spread, so the
    /// shifted run does not settle and the answer is no load factor, unconverged).
    #[test]
    fn the_iteration_finds_the_largest_positive_eigenvalue() {
        for (what, model) in [
            (
                "standing",
                bar([0.02, 0.3, 0.02], [1, 12, 1], Axis::Y, Side::Min),
            ),
            (
                "horizontal",
                bar([0.3, 0.02, 0.02], [12, 1, 1], Axis::X, Side::Min),
            ),
            (
                "hanging",
                bar([0.02, 0.3, 0.02], [1, 12, 1], Axis::Y, Side::Max),
            ),
        ] {
            let dense = dense_largest(&model);
            let b = gravity_buckling(&model).unwrap().unwrap();
            let found = b.load_factor.map_or(0.0, |l| 1.0 / l);
            if dense > 1e-9 * dense.abs().max(1.0) && what != "hanging" {
                assert!(b.converged, "{what}: {b:?}");
                assert!(
                    (found / dense - 1.0).abs() < 1e-4,
                    "{what}: {found} against {dense}"
                );
            } else {
                assert!(
                    found <= 1e-6 || !b.converged,
                    "{what}: {found} against {dense} ({b:?})"
                );
            }
        }
    }
    /// Stopped short, the iteration's quotient is below the largest eigenvalue, so the load
    /// factor it gives is at least the true one: a body an unconverged search says buckles
    /// does (a thin stool's search stopped at 0.255 after 300 iterations).
    #[test]
    fn an_unconverged_quotient_bounds_the_eigenvalue_from_below() {
        let model = bar([0.02, 0.3, 0.02], [1, 12, 1], Axis::Y, Side::Min);
        let dense = dense_largest(&model);
        let p = Prestress::of(&model).unwrap();
        let geometric = Geometric {
            model: &model,
            stress: &p.stress,
        };
        let solve = |x: &mut [f64]| p.parts.chol.solve_in_place(x);
        let k0 = |x: &[f64], y: &mut [f64]| p.parts.pattern.mul_vec(&p.stiffness, x, y);
        let start: Vec<f64> = (0..p.u.len()).map(hash_unit).collect();
        let mut below = 0;
        for iterations in 1..=8 {
            let (q, converged) = power_iteration(&geometric, &solve, &k0, &start, 0.0, iterations);
            assert!(q <= dense * (1.0 + 1e-9), "{iterations}: {q} above {dense}");
            if !converged && q < dense * (1.0 - 1e-6) {
                below += 1;
            }
        }
        assert!(below > 0, "the search converged at once and bounds nothing");
    }
}
