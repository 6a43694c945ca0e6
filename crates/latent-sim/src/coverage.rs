//! Whether a reduced pose lies among the poses its subspace was trained on.
//!
//! The autoencoder and the cubature rules were fitted on the training snapshots' PCA
//! coefficients; a reduced trajectory that goes where no snapshot went makes them extrapolate,
//! and nothing in its own figures says so. A pose q is inside the training data when each of its
//! coefficients lies within the range the snapshots' coefficients span, widened to hold the
//! rest pose's 0 (where every schedule starts): the decoder and the
//! rules interpolate between training poses (a test pose is often a blend of them, far from
//! each one), they extrapolate beyond them. Its distance to the data is the part outside those
//! ranges, relative to the pose's size, ‖q − clamp(q, lo, hi)‖ / ‖q‖; coefficients of a
//! mass-orthonormal basis measure displacements in the mass norm, so this is an M-norm
//! relative distance as in DESIGN §9. `cargo xtask run` measures it on every frame of a
//! reduced trajectory, and a model file carries the ranges so that a program stepping the
//! model reads the same figure after each step ([`crate::StepStats::beyond_training`]).

/// A reduced pose more than this (relative to its size) outside the training coefficients'
/// ranges lies outside the data the decoder and the cubature rule were fitted on: a tenth of
/// its displacement goes further than any snapshot went.
pub const OUTSIDE_TRAINING: f64 = 0.1;

/// Poses smaller than this fraction of the largest training pose are measured against it
/// instead of their own size: the relative distance of a nearly zero pose says nothing.
pub const SMALL_POSE: f64 = 0.1;

/// The ranges of the training snapshots' PCA coefficients.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
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

    /// The number of poses.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The number of coefficients of a pose (the basis's k).
    pub fn dim(&self) -> usize {
        self.lo.len()
    }

    /// The part of pose `q` outside the training coefficients' ranges, each widened to hold the
    /// rest pose's 0, relative to ‖q‖ (to
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
            // The rest pose, where every schedule starts, is among the training poses whether
            // or not a snapshot was taken there (a body at rest read 14 % beyond them).
            .map(|(&v, (&l, &h))| (v - v.clamp(l.min(0.0), h.max(0.0))).powi(2))
            .sum::<f64>()
            .sqrt();
        let size = norm(q).max(SMALL_POSE * self.largest);
        if outside == 0.0 { 0.0 } else { outside / size }
    }

    /// What a reader relies on, for ranges read from a file: `k` of each bound, at least one
    /// pose, finite bounds in order and a finite, non-negative largest pose.
    ///
    /// # Errors
    /// What is wrong, in words.
    pub fn check(&self, k: usize) -> Result<(), String> {
        if self.lo.len() != k || self.hi.len() != k {
            return Err(format!(
                "the training ranges have {} and {} bounds for k = {k} coefficients",
                self.lo.len(),
                self.hi.len()
            ));
        }
        if self.count == 0 {
            return Err("the training ranges hold no pose".into());
        }
        if let Some(i) = (0..k).find(|&i| {
            !(self.lo[i].is_finite() && self.hi[i].is_finite() && self.lo[i] <= self.hi[i])
        }) {
            return Err(format!(
                "the training range of coefficient {i} is not finite and in order ({} to {})",
                self.lo[i], self.hi[i]
            ));
        }
        if !(self.largest.is_finite() && self.largest >= 0.0) {
            return Err(format!(
                "the largest training pose's size is {}, not a finite size",
                self.largest
            ));
        }
        Ok(())
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
        assert_eq!(t.check(2), Ok(()));
        // A blend of training poses, far from each, is inside.
        assert_eq!(t.distance(&[0.9, 1.9]), 0.0);
        // (3, 0): 2 beyond the range of a pose of size 3.
        assert!((t.distance(&[3.0, 0.0]) - 2.0 / 3.0).abs() < 1e-15);
        // (0, −1.5): 1.5 below [0, 2], of 1.5.
        assert!((t.distance(&[0.0, -1.5]) - 1.0).abs() < 1e-15);
        // A tiny pose is measured against 0.1 × 2: (0, −0.01) is 0.01 outside.
        assert!((t.distance(&[0.0, -0.01]) - 0.05).abs() < 1e-15);
        // The rest pose counts among the training poses: each range widened to hold 0, so
        // poses (1, 1) and (2, 3) give the box [0, 2] × [0, 3], which holds (0, 0) and (0.5, 2),
        // not (0, 4).
        let sagged = TrainingPoses::new(2, vec![1.0, 1.0, 2.0, 3.0]);
        assert_eq!(sagged.distance(&[0.0, 0.0]), 0.0);
        assert_eq!(sagged.distance(&[0.5, 2.0]), 0.0);
        assert!((sagged.distance(&[0.0, 4.0]) - 0.25).abs() < 1e-15);
        let none = TrainingPoses::new(2, Vec::new());
        assert!(none.distance(&[1.0, 0.0]).is_infinite());
        assert!(none.check(2).unwrap_err().contains("no pose"), "{none:?}");
    }

    #[test]
    fn check_names_what_a_file_got_wrong() {
        let t = TrainingPoses::new(2, vec![1.0, 0.0, 0.0, 2.0]);
        assert!(t.check(3).unwrap_err().contains("k = 3"));
        let mut swapped = t.clone();
        swapped.lo[1] = 5.0;
        assert!(swapped.check(2).unwrap_err().contains("coefficient 1"));
        let mut nan = t.clone();
        nan.largest = f64::NAN;
        assert!(nan.check(2).unwrap_err().contains("largest"));
        // Poses all at rest are read; any other pose lies wholly outside them.
        let rest = TrainingPoses::new(2, vec![0.0; 4]);
        assert_eq!(rest.check(2), Ok(()));
        assert_eq!(rest.distance(&[0.0, 1.0]), 1.0);
        assert_eq!(rest.distance(&[0.0, 0.0]), 0.0);
    }
}
