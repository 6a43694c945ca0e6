//! Linear directions beside a subspace, q = f(z) + V w: gravity-onset directions and a
//! complement.
//!
//! A body released at rest under gravity first moves along the reduced linear implicit-Euler
//! response (A q₁ = g, A q_{n+1} = g + (M/h²)(2q_n − q_{n−1}), A = UᵀMU/h² + UᵀK₀U, g = Uᵀf_g),
//! whose first steps excite more shapes than a small latent space holds: on the AutoDef
//! catapult every 24-dimensional subspace, linear or learned, is 23–25 % off after the first
//! step. [`Augmented`] adds the first m of those iterates as linear coordinates w, made
//! A-orthogonal to the subspace's tangent at rest (what f already spans there is not repeated,
//! so the reduced matrices stay well conditioned) and to each other; iterates that are nearly
//! spanned already are dropped.
//!
//! The same coordinates can hold a linear complement of the subspace: the leading directions of
//! what f misses on the training data (the pipeline's `[reduced] complement_directions`, the left
//! singular vectors of the reconstruction residuals q − f(encode(q))). They trade the latent
//! step's speed for the accuracy of the PCA basis f lives in, a little at a time, without
//! retraining f.

use fem_core::integrator::TimeConfig;

use crate::dense_factor::DenseFactor;
use crate::reduced::{axpy, dot};
use crate::simulator::sandwich;
use crate::{ReducedError, ReducedSpace, Subspace};

/// An iterate is kept when at least this fraction of its A-norm is new.
const NEW_FRACTION: f64 = 1e-3;

/// Gauss–Newton steps [`Augmented::refine`] takes at most.
const REFINE_STEPS: usize = 8;

/// Diagonal shifts a refinement step tries in turn, from round-off's size up by 100× each (the
/// last is 10⁻² of the normal matrix's mean diagonal), each with up to four halvings.
const REFINE_DAMPINGS: i32 = 6;

/// The subspace `S` with linear directions V (k × m) beside it: latent coordinates (z, w),
/// q = f(z) + V w, J = [J_f | V].
#[derive(Debug, Clone)]
pub struct Augmented<S> {
    inner: S,
    /// V, k × m column-major, each column as long as the tangent's at rest on average.
    directions: Vec<f64>,
    /// A V (k × m) and the diagonal of VᵀAV: encode's A-orthogonal projection.
    a_directions: Vec<f64>,
    a_norms: Vec<f64>,
    residual: Vec<f64>,
}

impl<S: Subspace> Augmented<S> {
    /// `inner` alone (m = 0).
    pub fn plain(inner: S) -> Self {
        Self {
            inner,
            directions: Vec::new(),
            a_directions: Vec::new(),
            a_norms: Vec::new(),
            residual: Vec::new(),
        }
    }

    /// `inner` with up to `m` gravity-onset directions for the steps of `time` on `space` (fewer
    /// when the subspace already spans some at rest, none without gravity; quasi-static steps
    /// have one, the static response K₀⁻¹g).
    ///
    /// # Errors
    /// [`ReducedError::NotPositiveDefinite`] when UᵀMU/h² + UᵀK₀U or the tangent's reduced
    /// matrix cannot be factorised.
    pub fn with_gravity_onset(
        inner: S,
        space: &ReducedSpace,
        time: &TimeConfig,
        m: usize,
    ) -> Result<Self, ReducedError> {
        Self::with_directions(inner, space, time, m, &[])
    }

    /// `inner` with up to `onset` gravity-onset directions (as [`Self::with_gravity_onset`]),
    /// then the columns of `complement` (k × c, column-major; e.g. the leading directions of
    /// what `inner` misses in the training data), each made A-orthogonal to the tangent at rest
    /// and to the directions before it, and dropped when less than a thousandth of its A-norm is
    /// new.
    ///
    /// # Errors
    /// [`ReducedError::StateShape`] when `complement`'s length is not a multiple of k;
    /// [`ReducedError::NotPositiveDefinite`] as [`Self::with_gravity_onset`].
    pub fn with_directions(
        inner: S,
        space: &ReducedSpace,
        time: &TimeConfig,
        onset: usize,
        complement: &[f64],
    ) -> Result<Self, ReducedError> {
        let (k, d) = (space.k, inner.latent_dim());
        if !complement.len().is_multiple_of(k) {
            return Err(ReducedError::StateShape {
                expected: k * complement.len().div_ceil(k),
                got: complement.len(),
            });
        }
        let onset = if space.gravity.iter().all(|&g| g == 0.0) {
            0
        } else {
            onset
        };
        if onset == 0 && complement.is_empty() {
            return Ok(Self::plain(inner));
        }
        let inv_h2 = if time.quasi_static {
            0.0
        } else {
            1.0 / (time.step * time.step)
        };
        let a: Vec<f64> = space
            .mass
            .iter()
            .zip(&space.rest_stiffness)
            .map(|(m, k0)| m * inv_h2 + k0)
            .collect();
        let mut factor = DenseFactor::default();
        factor.factor(&a, k, "onset step")?;
        // The tangent at rest, J₀ = J(encode(0)), and its reduced matrix J₀ᵀAJ₀.
        let mut inner = inner;
        let mut z0 = vec![0.0; d];
        inner.encode(&vec![0.0; k], &mut z0);
        let mut j0 = vec![0.0; k * d];
        inner.jacobian(&z0, &mut j0);
        let (mut aj0, mut g0) = (vec![0.0; k * d], vec![0.0; d * d]);
        sandwich(&a, &j0, k, d, &mut aj0, &mut g0);
        let mut tangent = DenseFactor::default();
        tangent.factor(&g0, d, "onset tangent")?;
        // The directions get the tangent's mean column length, so that a unit of w moves q about
        // as far as a unit of z: the solver's relative-gradient test weighs both alike.
        let column_size = (dot(&j0, &j0) / d.max(1) as f64).sqrt();
        if !(column_size > 0.0 && column_size.is_finite()) {
            return Ok(Self::plain(inner));
        }

        let mut out = Self::plain(inner);
        let (mut before, mut now) = (vec![0.0; k], vec![0.0; k]);
        let (mut mq, mut c, mut ac) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
        let mut coef = vec![0.0; d];
        for candidate in 0..onset + complement.len() / k {
            if candidate < onset {
                // The next iterate of the linear response.
                let two_now_minus_before: Vec<f64> =
                    now.iter().zip(&before).map(|(n, b)| 2.0 * n - b).collect();
                mat_vec(&space.mass, &two_now_minus_before, &mut mq);
                let mut next: Vec<f64> = space
                    .gravity
                    .iter()
                    .zip(&mq)
                    .map(|(g, v)| g + inv_h2 * v)
                    .collect();
                factor.solve_in_place(&mut next);
                before = std::mem::replace(&mut now, next);
                c.copy_from_slice(&now);
            } else {
                let j = candidate - onset;
                c.copy_from_slice(&complement[j * k..(j + 1) * k]);
            }
            // Without its A-projection on the tangent and on the directions kept so far.
            mat_vec(&a, &c, &mut ac);
            let full_norm = dot(&c, &ac).sqrt();
            for (cf, aj) in coef.iter_mut().zip(aj0.chunks_exact(k)) {
                *cf = dot(aj, &c);
            }
            tangent.solve_in_place(&mut coef);
            for (cf, col) in coef.iter().zip(j0.chunks_exact(k)) {
                axpy(-cf, col, &mut c);
            }
            for (v, (av, n)) in out
                .directions
                .chunks_exact(k)
                .zip(out.a_directions.chunks_exact(k).zip(&out.a_norms))
            {
                let p = dot(av, &c) / n;
                axpy(-p, v, &mut c);
            }
            mat_vec(&a, &c, &mut ac);
            let new_norm = dot(&c, &ac).sqrt();
            if new_norm.is_nan() || new_norm <= NEW_FRACTION * full_norm {
                continue;
            }
            let scale = column_size / dot(&c, &c).sqrt();
            c.iter_mut().for_each(|x| *x *= scale);
            ac.iter_mut().for_each(|x| *x *= scale);
            out.a_norms.push(dot(&c, &ac));
            out.directions.extend_from_slice(&c);
            out.a_directions.extend_from_slice(&ac);
        }
        out.residual = vec![0.0; k];
        Ok(out)
    }

    /// The directions as a model file keeps them ([`Augmented::from_parts`] rebuilds them bit
    /// for bit without the reduced matrices they were made with).
    pub fn parts(&self) -> DirectionParts {
        DirectionParts {
            directions: self.directions.clone(),
            a_directions: self.a_directions.clone(),
            a_norms: self.a_norms.clone(),
        }
    }

    /// `inner` with the directions of `parts` (k = `inner`'s coefficient count).
    ///
    /// # Errors
    /// [`ReducedError::Parts`] when the lengths do not fit k and each other, or a value is not
    /// finite (a norm not positive).
    pub fn from_parts(inner: S, parts: &DirectionParts) -> Result<Self, ReducedError> {
        let k = inner.coeff_dim();
        let m = parts.a_norms.len();
        let bad = |reason: String| Err(ReducedError::Parts { reason });
        if Some(parts.directions.len()) != m.checked_mul(k)
            || parts.a_directions.len() != parts.directions.len()
        {
            return bad(format!(
                "{m} linear directions of {k} coefficients, but {} and {} values",
                parts.directions.len(),
                parts.a_directions.len()
            ));
        }
        if parts
            .directions
            .iter()
            .chain(&parts.a_directions)
            .any(|x| !x.is_finite())
            || parts.a_norms.iter().any(|n| !(n.is_finite() && *n > 0.0))
        {
            return bad("a linear direction is not finite (or its norm not positive)".into());
        }
        Ok(Self {
            inner,
            directions: parts.directions.clone(),
            a_directions: parts.a_directions.clone(),
            a_norms: parts.a_norms.clone(),
            residual: vec![0.0; if m > 0 { k } else { 0 }],
        })
    }

    /// m, the number of directions beside the subspace.
    pub fn directions(&self) -> usize {
        self.a_norms.len()
    }

    /// The subspace the directions are beside.
    pub fn inner(&self) -> &S {
        &self.inner
    }
}

/// The linear directions of an [`Augmented`] subspace: V (k × m), A V and the diagonal of VᵀAV
/// (A = UᵀMU/h² + UᵀK₀U), all column-major.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DirectionParts {
    pub directions: Vec<f64>,
    pub a_directions: Vec<f64>,
    pub a_norms: Vec<f64>,
}

/// out = M x for a square M, column-major (by columns, as the simulator forms (UᵀMU) x).
fn mat_vec(m: &[f64], x: &[f64], out: &mut [f64]) {
    let k = out.len();
    out.fill(0.0);
    for (col, &xj) in m.chunks_exact(k).zip(x) {
        axpy(xj, col, out);
    }
}

impl<S: Subspace> Subspace for Augmented<S> {
    fn latent_dim(&self) -> usize {
        self.inner.latent_dim() + self.directions()
    }

    fn coeff_dim(&self) -> usize {
        self.inner.coeff_dim()
    }

    fn decode(&mut self, z: &[f64], q: &mut [f64]) {
        let d = self.inner.latent_dim();
        self.inner.decode(&z[..d], q);
        for (w, v) in z[d..].iter().zip(self.directions.chunks_exact(q.len())) {
            axpy(*w, v, q);
        }
    }

    fn vjp(&mut self, z: &[f64], v: &[f64], out: &mut [f64]) {
        let d = self.inner.latent_dim();
        self.inner.vjp(&z[..d], v, &mut out[..d]);
        for (o, dir) in out[d..]
            .iter_mut()
            .zip(self.directions.chunks_exact(v.len()))
        {
            *o = dot(dir, v);
        }
    }

    fn jacobian(&mut self, z: &[f64], out: &mut [f64]) {
        let (d, k) = (self.inner.latent_dim(), self.inner.coeff_dim());
        self.inner.jacobian(&z[..d], &mut out[..k * d]);
        out[k * d..].copy_from_slice(&self.directions);
    }

    /// z = encode_f(q), then w the A-orthogonal projection of q − f(z) on V; from there,
    /// Gauss–Newton on ½‖q − f(z) − V w‖² finds the nearest point of the subspace (the
    /// encoder's guess is close on the training data, not exact).
    fn encode(&mut self, q: &[f64], z: &mut [f64]) {
        self.first_guess(q, z);
        self.refine(q, z);
    }

    fn is_linear(&self) -> bool {
        self.inner.is_linear()
    }
}

impl<S: Subspace> Augmented<S> {
    /// z = encode_f(q), then w the A-orthogonal projection of q − f(z) on V.
    fn first_guess(&mut self, q: &[f64], z: &mut [f64]) {
        let (d, k) = (self.inner.latent_dim(), self.inner.coeff_dim());
        self.inner.encode(q, &mut z[..d]);
        if self.directions() == 0 {
            return;
        }
        let mut r = std::mem::take(&mut self.residual);
        r.resize(k, 0.0);
        self.inner.decode(&z[..d], &mut r);
        r.iter_mut().zip(q).for_each(|(r, q)| *r = q - *r);
        for (w, (av, n)) in z[d..]
            .iter_mut()
            .zip(self.a_directions.chunks_exact(k).zip(&self.a_norms))
        {
            *w = dot(av, &r) / n;
        }
        self.residual = r;
    }

    /// The best fit of q in the subspace, min ½‖q − f(z) − V w‖² over (z, w) (the Euclidean norm
    /// of the PCA coefficients: the displacement's mass norm), by Gauss–Newton from `z`, the
    /// encoder's answer. An encoder is trained to be close on the training data, not exact: at
    /// the first millimetres of a fall the autoencoder's encoder missed 3.6 % of the
    /// displacement along the decoder's own tangent, which no linear direction beside it (each
    /// A-orthogonal to that tangent) can take up. Each step is kept only when it lowers the
    /// misfit; at most [`REFINE_STEPS`] steps.
    fn refine(&mut self, q: &[f64], z: &mut [f64]) {
        let (k, n) = (self.inner.coeff_dim(), self.latent_dim());
        let mut fit = vec![0.0; k];
        let misfit = |s: &mut Self, z: &[f64], fit: &mut [f64]| -> f64 {
            s.decode(z, fit);
            fit.iter_mut().zip(q).for_each(|(f, q)| *f = q - *f);
            dot(fit, fit)
        };
        let mut cost = misfit(self, z, &mut fit);
        let scale = dot(q, q);
        let (mut jac, mut normal, mut step) = (vec![0.0; k * n], vec![0.0; n * n], vec![0.0; n]);
        let mut trial = vec![0.0; n];
        let mut factor = DenseFactor::default();
        for _ in 0..REFINE_STEPS {
            // Also stops on a NaN cost.
            if cost.is_nan() || cost <= 1e-24 * scale {
                break;
            }
            self.jacobian(z, &mut jac);
            for (i, ci) in jac.chunks_exact(k).enumerate() {
                step[i] = dot(ci, &fit);
                for (j, cj) in jac.chunks_exact(k).enumerate().take(i + 1) {
                    let g = dot(ci, cj);
                    normal[j * n + i] = g;
                    normal[i * n + j] = g;
                }
            }
            let trace: f64 = (0..n).map(|i| normal[i * n + i]).sum();
            // The Gauss–Newton step and its halvings first; when none lowers the misfit, shorter
            // steps nearer the gradient's direction (Levenberg–Marquardt). Where the decoder's
            // tangent nearly lies in the span of V (a small latent dimension whose directions
            // fill the PCA basis), the Gauss–Newton step is huge along the near-null direction,
            // and until 2026-12-02 the fit stopped there: at d = 3 beside 112 directions the
            // test's frames came back 11.9 % off on average, 2.5 % with the shifts.
            let (rhs, before) = (step.clone(), cost);
            let mut better = false;
            for attempt in 0..REFINE_DAMPINGS {
                let shift = 1e-12 * trace / n as f64 * 100f64.powi(attempt);
                if !factor.try_factor(&normal, n, shift) {
                    continue;
                }
                step.copy_from_slice(&rhs);
                factor.solve_in_place(&mut step);
                let mut t = 1.0;
                for _ in 0..4 {
                    trial
                        .iter_mut()
                        .zip(z.iter())
                        .zip(&step)
                        .for_each(|((x, z), s)| *x = z + t * s);
                    let c = misfit(self, &trial, &mut fit);
                    if c < cost {
                        cost = c;
                        z.copy_from_slice(&trial);
                        better = true;
                        break;
                    }
                    t *= 0.5;
                }
                if better {
                    break;
                }
            }
            // Converged: a step that gains nothing measurable ends it.
            if !better || before - cost <= 1e-10 * before {
                break;
            }
        }
    }
}
