//! Projection of a symmetric 9×9 tangent onto the positive-semidefinite cone.

use super::Mat9;

/// Returns the nearest (Frobenius) positive-semidefinite matrix to the symmetric part of `a`:
/// eigenvalues below zero are clamped to zero.
///
/// Most elements in a simulation are in a stable state, so a Cholesky factorisation of
/// `a + δI` is tried first, with δ = 1e-10 · max |a_ii|; when it succeeds every eigenvalue of `a`
/// is at least −δ and `a` is returned unchanged, which skips the eigen-decomposition. The shift
/// matters: isotropic tangents at rest are exactly singular in the three rotation directions.
pub fn project_psd(a: &Mat9) -> Mat9 {
    let sym = (a + a.transpose()) * 0.5;
    let delta = 1e-10 * sym.diagonal().amax();
    if delta > 0.0 && (sym + Mat9::identity() * delta).cholesky().is_some() {
        return sym;
    }
    let eig = sym.symmetric_eigen();
    let mut vals = eig.eigenvalues;
    for v in vals.iter_mut() {
        *v = v.max(0.0);
    }
    let q = &eig.eigenvectors;
    q * nalgebra::Matrix::from_diagonal(&vals) * q.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_clamps_negative_eigenvalues_only() {
        let mut d = nalgebra::SVector::<f64, 9>::from_fn(|i, _| i as f64 - 3.0);
        let q = Mat9::from_fn(|i, j| ((i * 7 + j * 3) as f64).sin())
            .qr()
            .q();
        let a = q * Mat9::from_diagonal(&d) * q.transpose();
        let p = project_psd(&a);
        for v in d.iter_mut() {
            *v = v.max(0.0);
        }
        let expect = q * Mat9::from_diagonal(&d) * q.transpose();
        assert!((p - expect).norm() < 1e-10 * expect.norm());
        // Positive definite input is returned unchanged.
        let spd = q * Mat9::from_diagonal(&d.add_scalar(1.0)) * q.transpose();
        assert!((project_psd(&spd) - spd).norm() < 1e-12 * spd.norm());
    }
}
