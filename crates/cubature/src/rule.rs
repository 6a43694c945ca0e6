//! A fitted cubature rule: elements, non-negative weights and the error curve of the fit.

use fem_core::assembly::ElementSet;

use crate::nnls::norm;
use crate::{CubatureError, TrainingMatrix};

/// A cubature rule: V(u) ≈ Σ_{e∈S} w_e V_e(u).
///
/// Elements are sorted by index. Deserialisation checks the invariants (matching lengths,
/// distinct elements, finite non-negative weights); [`CubatureRule::check_elements`] checks the
/// indices against a mesh.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "RuleData")]
pub struct CubatureRule {
    /// Selected element indices S, increasing.
    pub elements: Vec<usize>,
    /// Weight w_e ≥ 0 of each selected element.
    pub weights: Vec<f64>,
    /// Relative error ‖A_S w − b‖ / ‖b‖ on the training poses.
    pub training_error: f64,
    /// Whether the training error reached the configured tolerance (otherwise the element budget
    /// or the candidate pool ran out first).
    pub tolerance_met: bool,
    /// (|S|, relative training error) after each greedy step.
    pub error_curve: Vec<(usize, f64)>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RuleData {
    elements: Vec<usize>,
    weights: Vec<f64>,
    training_error: f64,
    tolerance_met: bool,
    error_curve: Vec<(usize, f64)>,
}

impl TryFrom<RuleData> for CubatureRule {
    type Error = CubatureError;

    fn try_from(d: RuleData) -> Result<Self, CubatureError> {
        let rule = Self {
            elements: d.elements,
            weights: d.weights,
            training_error: d.training_error,
            tolerance_met: d.tolerance_met,
            error_curve: d.error_curve,
        };
        rule.check()?;
        Ok(rule)
    }
}

impl CubatureRule {
    /// Number of selected elements.
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    /// The rule as an element set for `fem_core::assembly`.
    pub fn element_set(&self) -> ElementSet<'_> {
        ElementSet::Weighted {
            indices: &self.elements,
            weights: &self.weights,
        }
    }

    /// Internal consistency: equal lengths, strictly increasing elements, finite weights ≥ 0.
    pub fn check(&self) -> Result<(), CubatureError> {
        let bad = |reason: String| Err(CubatureError::InvalidRule(reason));
        if self.elements.len() != self.weights.len() {
            return bad(format!(
                "{} elements but {} weights",
                self.elements.len(),
                self.weights.len()
            ));
        }
        if let Some(w) = self.elements.windows(2).find(|w| w[0] >= w[1]) {
            return bad(format!(
                "elements must be strictly increasing, found {} before {}",
                w[0], w[1]
            ));
        }
        if let Some(i) = self
            .weights
            .iter()
            .position(|w| !(w.is_finite() && *w >= 0.0))
        {
            return bad(format!(
                "weight of element {} is {}, expected finite and non-negative",
                self.elements[i], self.weights[i]
            ));
        }
        if !(self.training_error.is_finite() && self.training_error >= 0.0) {
            return bad(format!("training error is {}", self.training_error));
        }
        Ok(())
    }

    /// [`CubatureRule::check`] plus every element index below `num_elements` (the mesh's count).
    pub fn check_elements(&self, num_elements: usize) -> Result<(), CubatureError> {
        self.check()?;
        match self.elements.last() {
            Some(&e) if e >= num_elements => Err(CubatureError::InvalidRule(format!(
                "element {e} is out of range for a mesh of {num_elements} elements"
            ))),
            _ => Ok(()),
        }
    }

    /// Relative error ‖A_S w − b‖ / ‖b‖ of the rule on `data` (e.g. held-out poses built with
    /// [`TrainingMatrix::build`]).
    pub fn evaluate(&self, data: &TrainingMatrix) -> Result<f64, CubatureError> {
        let r = self.residual(data)?;
        Ok(norm(&r) / norm(data.b()))
    }

    /// Relative error of each pose block, ‖(A_S w − b)_i‖ / ‖b_i‖, in the order of
    /// [`TrainingMatrix::pose_indices`].
    pub fn pose_errors(&self, data: &TrainingMatrix) -> Result<Vec<f64>, CubatureError> {
        let r = self.residual(data)?;
        let d = data.dim();
        Ok(r.chunks(d)
            .zip(data.b().chunks(d))
            .map(|(ri, bi)| {
                let bn = norm(bi);
                if bn > 0.0 { norm(ri) / bn } else { norm(ri) }
            })
            .collect())
    }

    fn residual(&self, data: &TrainingMatrix) -> Result<Vec<f64>, CubatureError> {
        self.check_elements(data.num_elements())?;
        let mut r: Vec<f64> = data.b().iter().map(|x| -x).collect();
        for (&e, &w) in self.elements.iter().zip(&self.weights) {
            let Some(c) = data.column_of(e) else {
                return Err(CubatureError::InvalidRule(format!(
                    "element {e} is not among the {} candidate elements the training data keeps",
                    data.num_columns()
                )));
            };
            for (ri, a) in r.iter_mut().zip(data.column(c)) {
                *ri += w * a;
            }
        }
        Ok(r)
    }
}
