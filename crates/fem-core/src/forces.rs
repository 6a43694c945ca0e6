//! External forces as data with time schedules, so one schedule can be replayed on every method.
//!
//! * A **point load** applies a total force f(t) split evenly over its vertices:
//!   energy −Σ_v f(t)ᵀu_v / n.
//! * A **spring** pulls its vertex patch toward its rest position moved by an offset d(t) (the
//!   paper's mouse drag, made replayable): energy k/(2n) Σ_v ‖u_v − d(t)‖², with total
//!   stiffness k split over the n vertices.
//!
//! Both act while start ≤ t < end; f(t) and d(t) interpolate keyframes (t, x, y, z) linearly and
//! hold the first/last value outside them.

use crate::constraints::VertexSelection;
use crate::{FemError, TetMesh, Vec3};

/// What a force does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ForceKind {
    Spring,
    Point,
}

/// One `[[force]]` entry of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceConfig {
    pub kind: ForceKind,
    /// The vertices the force acts on, chosen like pins.
    pub select: VertexSelection,
    /// Total spring stiffness k in N/m (springs only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness: Option<f64>,
    /// Keyframes `[t, x, y, z]`: the spring's target offset in m, or the point load's total force
    /// in N.
    #[serde(deserialize_with = "crate::exact::rows")]
    pub keyframes: Vec<[f64; 4]>,
    /// Time the force switches on (s).
    #[serde(default)]
    pub start: f64,
    /// Time the force switches off (s); forever when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end: Option<f64>,
}

/// A force resolved against a mesh: a scene's `[[force]]` ([`ForceConfig::resolve`]), or one
/// built by a program and given to a runtime (`latent_sim::Interactive::add_force`, which
/// checks it).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExternalForce {
    pub kind: ForceKind,
    /// The vertices it acts on: indices into the mesh's vertices, counted from 0 in the order
    /// the mesh file lists them.
    pub vertices: Vec<usize>,
    /// Total spring stiffness k in N/m, split over the vertices (0 for a point load).
    pub stiffness: f64,
    /// Keyframes `[t, x, y, z]` in time order: the spring's target offset from the vertices'
    /// rest positions in m, or the point load's total force in N.
    pub keyframes: Vec<[f64; 4]>,
    /// The force acts while `start ≤ t < end` (s): `f64::NEG_INFINITY` and `f64::INFINITY` for
    /// always.
    pub start: f64,
    pub end: f64,
}

impl ForceConfig {
    /// Checks the values and selects the vertices. `field` names the entry, e.g. `force[2]`.
    pub fn resolve(&self, mesh: &TetMesh, field: &str) -> Result<ExternalForce, FemError> {
        let bad = |sub: &str, reason: String| FemError::InvalidConfig {
            field: format!("{field}.{sub}"),
            reason,
        };
        let vertices = self.select.select(mesh, &format!("{field}.select"))?;
        let stiffness = match (self.kind, self.stiffness) {
            (ForceKind::Spring, Some(k)) if k.is_finite() && k > 0.0 => k,
            (ForceKind::Spring, Some(k)) => {
                return Err(bad("stiffness", format!("must be positive, got {k}")));
            }
            (ForceKind::Spring, None) => {
                return Err(bad("stiffness", "a spring needs a stiffness".into()));
            }
            (ForceKind::Point, None) => 0.0,
            (ForceKind::Point, Some(_)) => {
                return Err(bad("stiffness", "only springs have a stiffness".into()));
            }
        };
        if self.keyframes.is_empty() {
            return Err(bad("keyframes", "needs at least one [t, x, y, z]".into()));
        }
        if self.keyframes.iter().flatten().any(|v| !v.is_finite()) {
            return Err(bad("keyframes", "values must be finite".into()));
        }
        if self.keyframes.windows(2).any(|w| w[1][0] < w[0][0]) {
            return Err(bad("keyframes", "times must not decrease".into()));
        }
        let end = self.end.unwrap_or(f64::INFINITY);
        if !self.start.is_finite() || end.is_nan() || end <= self.start {
            return Err(bad(
                "end",
                format!("needs start < end, got {} and {end}", self.start),
            ));
        }
        Ok(ExternalForce {
            kind: self.kind,
            vertices,
            stiffness,
            keyframes: self.keyframes.clone(),
            start: self.start,
            end,
        })
    }
}

/// Whether `keyframes` can drive a force: at least one row, every value finite, times in order.
/// The one test of a force's keyframes built in code, its own or replaced
/// ([`ExternalForce::problem`], the runtime's `add_force` and `set_keyframes`).
pub fn keyframes_usable(keyframes: &[[f64; 4]]) -> bool {
    !keyframes.is_empty()
        && keyframes.iter().flatten().all(|x| x.is_finite())
        && keyframes.windows(2).all(|w| w[1][0] >= w[0][0])
}

impl ExternalForce {
    /// What makes this force unusable on a mesh of `num_vertices` vertices, if anything: no
    /// vertex or one past the mesh, keyframes that are empty, not finite or out of time order,
    /// a stiffness that is negative or not finite, a span that is not a number. A force built
    /// in code is checked so before a model takes it ([`crate::integrator::FullSpaceModel::new`]);
    /// a scene's is made right by [`ForceConfig::resolve`].
    pub fn problem(&self, num_vertices: usize) -> Option<String> {
        if self.vertices.is_empty() {
            Some("acts on no vertex".into())
        } else if let Some(v) = self.vertices.iter().find(|&&v| v >= num_vertices) {
            Some(format!(
                "vertex {v} is past the mesh's {num_vertices} vertices"
            ))
        } else if !keyframes_usable(&self.keyframes) {
            Some("keyframes must be finite [t, x, y, z] rows in time order, at least one".into())
        } else if !(self.stiffness.is_finite() && self.stiffness >= 0.0) {
            Some(format!(
                "the stiffness must be finite and not negative, got {}",
                self.stiffness
            ))
        } else if self.start.is_nan() || self.end.is_nan() {
            Some("start and end must be numbers (infinite for always)".into())
        } else {
            None
        }
    }

    pub fn is_active(&self, t: f64) -> bool {
        t >= self.start && t < self.end
    }

    /// The keyframed vector (offset or force) at time `t`.
    pub fn value(&self, t: f64) -> Vec3 {
        let k = &self.keyframes;
        let at = |i: usize| Vec3::new(k[i][1], k[i][2], k[i][3]);
        if t <= k[0][0] {
            return at(0);
        }
        for i in 1..k.len() {
            if t <= k[i][0] {
                let span = k[i][0] - k[i - 1][0];
                let s = if span > 0.0 {
                    (t - k[i - 1][0]) / span
                } else {
                    1.0
                };
                return at(i - 1) * (1.0 - s) + at(i) * s;
            }
        }
        at(k.len() - 1)
    }

    /// Adds this force's energy to the return value, its gradient to `grad` and its Hessian
    /// diagonal to `hess_diag` (full vectors, 3 per vertex) at time `t` and displacement `u`.
    pub fn accumulate(
        &self,
        t: f64,
        u: &[f64],
        grad: Option<&mut [f64]>,
        hess_diag: Option<&mut [f64]>,
    ) -> f64 {
        if !self.is_active(t) {
            return 0.0;
        }
        let value = self.value(t);
        let n = self.vertices.len() as f64;
        let mut energy = 0.0;
        match self.kind {
            ForceKind::Point => {
                let f = value / n;
                for &v in &self.vertices {
                    for c in 0..3 {
                        energy -= f[c] * u[3 * v + c];
                    }
                }
                if let Some(g) = grad {
                    for &v in &self.vertices {
                        for c in 0..3 {
                            g[3 * v + c] -= f[c];
                        }
                    }
                }
            }
            ForceKind::Spring => {
                let k = self.stiffness / n;
                let mut g = grad;
                for &v in &self.vertices {
                    for c in 0..3 {
                        let r = u[3 * v + c] - value[c];
                        energy += 0.5 * k * r * r;
                        if let Some(g) = g.as_deref_mut() {
                            g[3 * v + c] += k * r;
                        }
                    }
                }
                if let Some(h) = hess_diag {
                    for &v in &self.vertices {
                        for c in 0..3 {
                            h[3 * v + c] += k;
                        }
                    }
                }
            }
        }
        energy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spring() -> ExternalForce {
        ExternalForce {
            kind: ForceKind::Spring,
            vertices: vec![0, 2],
            stiffness: 10.0,
            keyframes: vec![[0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.0, -2.0]],
            start: 0.0,
            end: 2.0,
        }
    }

    #[test]
    fn keyframes_interpolate_and_hold() {
        let f = spring();
        assert_eq!(f.value(-1.0), Vec3::zeros());
        assert!((f.value(0.5) - Vec3::new(0.5, 0.0, -1.0)).norm() < 1e-15);
        assert_eq!(f.value(7.0), Vec3::new(1.0, 0.0, -2.0));
        assert!(f.is_active(1.5) && !f.is_active(2.0));
    }

    #[test]
    fn spring_gradient_matches_finite_differences() {
        let f = spring();
        let u: Vec<f64> = (0..9).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut g = vec![0.0; 9];
        let mut h = vec![0.0; 9];
        f.accumulate(0.3, &u, Some(&mut g), Some(&mut h));
        for i in 0..9 {
            let (mut up, mut um) = (u.clone(), u.clone());
            up[i] += 1e-6;
            um[i] -= 1e-6;
            let fd =
                (f.accumulate(0.3, &up, None, None) - f.accumulate(0.3, &um, None, None)) / 2e-6;
            assert!((fd - g[i]).abs() < 1e-7, "{i}: {fd} vs {}", g[i]);
        }
        assert_eq!(h[0], 5.0);
        assert_eq!(h[3], 0.0);
    }
}
