//! Whether a reduced trajectory stays among the poses its subspace was trained on.
//!
//! The autoencoder and the cubature rules were fitted on the training snapshots' PCA
//! coefficients; a reduced trajectory that goes where no snapshot went makes them extrapolate,
//! and nothing in its own figures says so (the subspace error measures the reference, not the
//! reduced path). A pose q is inside the training data, for this test, when each of its
//! coefficients lies within the range the snapshots' coefficients span: the decoder and the
//! rules interpolate between training poses (a test pose is often a blend of them, far from
//! each one), they extrapolate beyond them. Its distance to the data is the part outside those
//! ranges, relative to the pose's size, ‖q − clamp(q, lo, hi)‖ / ‖q‖; coefficients of a
//! mass-orthonormal basis measure displacements in the mass norm, so this is an M-norm
//! relative distance as in DESIGN §9.

use anyhow::Result;

use crate::pipeline::{Pipeline, Progress};

/// A reduced pose more than this (relative to its size) outside the training coefficients'
/// ranges lies outside the data the decoder and the cubature rule were fitted on: a tenth of
/// its displacement goes further than any snapshot went.
pub const OUTSIDE_TRAINING: f64 = 0.1;

/// Poses smaller than this fraction of the largest training pose are measured against it
/// instead of their own size: the relative distance of a nearly zero pose says nothing.
pub const SMALL_POSE: f64 = 0.1;

/// The ranges of the training snapshots' PCA coefficients.
#[derive(Debug, Clone)]
pub struct TrainingPoses {
    lo: Vec<f64>,
    hi: Vec<f64>,
    count: usize,
    largest: f64,
}

impl TrainingPoses {
    /// The poses of `q` (k × n, column-major).
    ///
    /// # Panics
    /// When `k` is zero or does not divide `q.len()`.
    pub fn new(k: usize, q: Vec<f64>) -> Self {
        assert!(
            k > 0 && q.len().is_multiple_of(k),
            "{} values are no k = {k} poses",
            q.len()
        );
        let (mut lo, mut hi) = (vec![f64::INFINITY; k], vec![f64::NEG_INFINITY; k]);
        for p in q.chunks_exact(k) {
            for ((l, h), &v) in lo.iter_mut().zip(&mut hi).zip(p) {
                *l = l.min(v);
                *h = h.max(v);
            }
        }
        let largest = q.chunks_exact(k).map(norm).fold(0.0, f64::max);
        Self {
            lo,
            hi,
            count: q.len() / k,
            largest,
        }
    }

    /// The snapshots of `pipeline`'s scene projected on its PCA basis (the stages `snapshots`
    /// and `pca`, cached).
    ///
    /// # Errors
    /// When a stage fails.
    pub fn of(pipeline: &mut Pipeline<'_>, progress: Progress<'_>) -> Result<Self> {
        let snaps = pipeline.snapshots(progress)?;
        let fit = pipeline.pca(progress)?;
        let s = faer::MatRef::from_column_major_slice(&snaps.data, snaps.dim, snaps.num_frames());
        let q = fit.basis.project_matrix(s);
        let k = fit.basis.k();
        let mut flat = Vec::with_capacity(k * q.ncols());
        for j in 0..q.ncols() {
            flat.extend((0..k).map(|i| q[(i, j)]));
        }
        Ok(Self::new(k, flat))
    }

    /// [`TrainingPoses::of`] `pipeline`, computed once per pipeline.
    ///
    /// # Errors
    /// When a stage fails.
    pub fn shared(
        pipeline: &mut Pipeline<'_>,
        progress: Progress<'_>,
    ) -> Result<std::sync::Arc<Self>> {
        if let Some(p) = &pipeline.training_poses {
            return Ok(p.clone());
        }
        let p = std::sync::Arc::new(Self::of(pipeline, progress)?);
        pipeline.training_poses = Some(p.clone());
        Ok(p)
    }

    /// The number of poses.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The part of pose `q` outside the training coefficients' ranges, relative to ‖q‖ (to
    /// [`SMALL_POSE`] times the largest training pose when q is smaller): 0 inside them;
    /// infinite when there are no training poses.
    ///
    /// # Panics
    /// When `q` does not have k values.
    pub fn distance(&self, q: &[f64]) -> f64 {
        assert_eq!(
            q.len(),
            self.lo.len(),
            "a pose of {} values, expected k",
            q.len()
        );
        if self.is_empty() {
            return f64::INFINITY;
        }
        let outside = q
            .iter()
            .zip(self.lo.iter().zip(&self.hi))
            .map(|(&v, (&l, &h))| (v - v.clamp(l, h)).powi(2))
            .sum::<f64>()
            .sqrt();
        let size = norm(q).max(SMALL_POSE * self.largest);
        if outside == 0.0 { 0.0 } else { outside / size }
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_is_the_part_outside_the_training_ranges_relative_to_the_pose() {
        // Poses (1, 0), (0, 2), (−1, 0): ranges [−1, 1] × [0, 2]; the largest has norm 2.
        let t = TrainingPoses::new(2, vec![1.0, 0.0, 0.0, 2.0, -1.0, 0.0]);
        assert_eq!(t.len(), 3);
        // A blend of training poses, far from each, is inside.
        assert_eq!(t.distance(&[0.9, 1.9]), 0.0);
        // (3, 0): 2 beyond the range of a pose of size 3.
        assert!((t.distance(&[3.0, 0.0]) - 2.0 / 3.0).abs() < 1e-15);
        // (0, −1.5): 1.5 below [0, 2], of 1.5.
        assert!((t.distance(&[0.0, -1.5]) - 1.0).abs() < 1e-15);
        // A tiny pose is measured against 0.1 × 2: (0, −0.01) is 0.01 outside.
        assert!((t.distance(&[0.0, -0.01]) - 0.05).abs() < 1e-15);
        assert!(
            TrainingPoses::new(2, Vec::new())
                .distance(&[1.0, 0.0])
                .is_infinite()
        );
    }
}
