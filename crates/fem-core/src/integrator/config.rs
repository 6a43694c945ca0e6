//! The `[time]` and `[gravity]` sections of a scene.

use crate::FemError;

/// The `[time]` section of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeConfig {
    /// Time step h in seconds.
    pub step: f64,
    /// Number of steps `simulate` takes with the scene's own forces (200 when not given).
    #[serde(default = "default_frames")]
    pub frames: usize,
    /// Solve for static equilibrium at each frame's loads instead of dynamics.
    #[serde(default)]
    pub quasi_static: bool,
}

fn default_frames() -> usize {
    200
}

impl Default for TimeConfig {
    fn default() -> Self {
        Self {
            step: 0.01,
            frames: default_frames(),
            quasi_static: false,
        }
    }
}

impl TimeConfig {
    pub fn check(&self, errors: &mut Vec<FemError>) {
        if !(self.step.is_finite() && self.step > 0.0) {
            errors.push(FemError::InvalidConfig {
                field: "time.step".into(),
                reason: format!("must be a positive number of seconds, got {}", self.step),
            });
        }
        if self.frames == 0 {
            errors.push(FemError::InvalidConfig {
                field: "time.frames".into(),
                reason: "must be at least 1".into(),
            });
        }
    }
}

/// The most frames a scene may ask of one simulation (`[time] frames`, and a schedule's
/// `frames_per_schedule`): a million steps, hours of simulated time at usual steps; a value
/// past it is a typo, and its buffers would not fit in memory. (A model's runtime, which
/// steps without end, has no such count.)
pub const MAX_FRAMES: usize = 1_000_000;

/// The `[gravity]` section of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GravityConfig {
    /// Gravitational acceleration in m/s².
    #[serde(deserialize_with = "crate::exact::array")]
    pub acceleration: [f64; 3],
}

impl GravityConfig {
    /// Whether there is any gravity (an acceleration other than zero).
    pub fn is_on(&self) -> bool {
        self.acceleration.iter().any(|&g| g != 0.0)
    }

    /// |g|, the acceleration's magnitude (m/s²).
    pub fn magnitude(&self) -> f64 {
        self.acceleration.iter().map(|x| x * x).sum::<f64>().sqrt()
    }
}

impl Default for GravityConfig {
    fn default() -> Self {
        Self {
            acceleration: [0.0, -9.81, 0.0],
        }
    }
}
