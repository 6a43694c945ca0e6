//! Per-feature input scaling s = (q − shift) / scale, stored with the model.
//!
//! PCA coefficients span orders of magnitude (the first is large, the last tiny), and a network
//! with O(1) initial weights learns the tiny ones slowly. Standardising every feature to zero mean
//! and unit standard deviation over the training data puts them on an equal footing. The decoder
//! undoes the scaling, q = shift + scale ⊙ s, so every decoder derivative is in original units.

use faer::MatRef;

use crate::NnError;

/// An affine per-feature map s = (q − shift) / scale with positive, finite scales.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "ScalingData")]
pub struct InputScaling {
    shift: Vec<f64>,
    scale: Vec<f64>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ScalingData {
    shift: Vec<f64>,
    scale: Vec<f64>,
}

impl TryFrom<ScalingData> for InputScaling {
    type Error = NnError;

    fn try_from(d: ScalingData) -> Result<Self, NnError> {
        InputScaling::new(d.shift, d.scale)
    }
}

impl InputScaling {
    /// A scaling from explicit shifts and scales (same length, finite, scales positive).
    pub fn new(shift: Vec<f64>, scale: Vec<f64>) -> Result<Self, NnError> {
        let bad = |reason: String| Err(NnError::InvalidModel(format!("input scaling: {reason}")));
        if shift.len() != scale.len() || shift.is_empty() {
            return bad(format!(
                "{} shifts and {} scales (need the same, nonzero number)",
                shift.len(),
                scale.len()
            ));
        }
        if let Some(i) = shift.iter().position(|s| !s.is_finite()) {
            return bad(format!("shift {i} is not finite: {}", shift[i]));
        }
        if let Some(i) = scale.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
            return bad(format!(
                "scale {i} must be positive and finite, got {}",
                scale[i]
            ));
        }
        Ok(Self { shift, scale })
    }

    /// Standardisation over the samples (columns) of `data` (features × samples): shift = mean,
    /// scale = population standard deviation of each feature. A feature whose deviation is below
    /// 10⁻¹² of the largest one (e.g. constant) gets the largest deviation as its scale, so it is
    /// left small instead of being blown up; all-constant data gets scale 1.
    pub fn standardize(data: MatRef<'_, f64>) -> Self {
        let (k, n) = (data.nrows(), data.ncols());
        let inv_n = 1.0 / n.max(1) as f64;
        let shift: Vec<f64> = (0..k)
            .map(|i| (0..n).map(|j| data[(i, j)]).sum::<f64>() * inv_n)
            .collect();
        let std: Vec<f64> = (0..k)
            .map(|i| {
                let var = (0..n)
                    .map(|j| (data[(i, j)] - shift[i]).powi(2))
                    .sum::<f64>()
                    * inv_n;
                var.sqrt()
            })
            .collect();
        let widest = std.iter().copied().fold(0.0, f64::max);
        let fallback = if widest > 0.0 { widest } else { 1.0 };
        let scale = std
            .iter()
            .map(|&s| {
                if s > 1e-12 * widest && s > 0.0 {
                    s
                } else {
                    fallback
                }
            })
            .collect();
        Self { shift, scale }
    }

    /// Centring with one common scale: shift = mean of each feature, scale = the root mean square
    /// of the features' standard deviations, the same for every feature.
    ///
    /// This is the scaling training uses. A common scale keeps the relative weight of the
    /// features in the squared error, which matters for PCA coefficients of a mass-orthonormal
    /// basis: there ‖q − q̂‖² is the mass-weighted displacement error, and per-feature
    /// standardisation would make the tiny trailing coefficients count as much as the dominant
    /// ones.
    pub fn centre_uniform(data: MatRef<'_, f64>) -> Self {
        let per_feature = Self::standardize(data);
        let (k, n) = (data.nrows(), data.ncols());
        let inv_n = 1.0 / n.max(1) as f64;
        let mean_var = (0..k)
            .map(|i| {
                (0..n)
                    .map(|j| (data[(i, j)] - per_feature.shift[i]).powi(2))
                    .sum::<f64>()
                    * inv_n
            })
            .sum::<f64>()
            / k.max(1) as f64;
        let common = if mean_var > 0.0 && mean_var.is_finite() {
            mean_var.sqrt()
        } else {
            1.0
        };
        Self {
            shift: per_feature.shift,
            scale: vec![common; k],
        }
    }

    /// The number of features.
    pub fn dim(&self) -> usize {
        self.shift.len()
    }

    pub fn shift(&self) -> &[f64] {
        &self.shift
    }

    pub fn scale(&self) -> &[f64] {
        &self.scale
    }

    /// s = (q − shift) / scale.
    pub fn apply(&self, q: &[f64], s: &mut [f64]) {
        for i in 0..self.shift.len() {
            s[i] = (q[i] - self.shift[i]) / self.scale[i];
        }
    }

    /// q = shift + scale ⊙ s.
    pub fn invert(&self, s: &[f64], q: &mut [f64]) {
        for i in 0..self.shift.len() {
            q[i] = self.shift[i] + self.scale[i] * s[i];
        }
    }
}
