//! The training poses of a pipeline's scene, for [`latent_sim::coverage`]'s measure of
//! whether a reduced trajectory stays among them: the ranges of the snapshots' PCA
//! coefficients, the stage `coverage` ([`Pipeline::coverage`]), cached apart from the
//! snapshots so that `export` and `view` read a few kilobytes instead of every snapshot.

use anyhow::Result;

pub use latent_sim::coverage::{OUTSIDE_TRAINING, TrainingPoses};

use crate::pipeline::{Pipeline, Progress};

/// What the stage `coverage` keeps of the snapshots: the ranges of their PCA coefficients, and
/// how long the training schedules run, which `run` compares a test with. Without the second a
/// warm `run` read every snapshot for two numbers (and computed them all again when only their
/// artifact had been deleted).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Coverage {
    pub poses: TrainingPoses,
    /// Frames of each training schedule.
    pub frames_per_schedule: usize,
    /// Whether some schedules start from the body's fall under its weight
    /// (`SnapshotSet::later_start`): they then run to the test's last frame.
    pub later_start: bool,
}

/// The snapshots of `pipeline`'s scene projected on its PCA basis (the stages `snapshots` and
/// `pca`, cached), as the ranges of their coefficients, and their schedules' length: what the
/// stage `coverage` computes.
///
/// # Errors
/// When a stage fails.
pub fn training_poses(pipeline: &mut Pipeline<'_>, progress: Progress<'_>) -> Result<Coverage> {
    let snaps = pipeline.snapshots(progress)?;
    let fit = pipeline.pca(progress)?;
    let s = faer::MatRef::from_column_major_slice(&snaps.data, snaps.dim, snaps.num_frames());
    let q = fit.basis.project_matrix(s);
    let k = fit.basis.k();
    let mut flat = Vec::with_capacity(k * q.ncols());
    for j in 0..q.ncols() {
        flat.extend((0..k).map(|i| q[(i, j)]));
    }
    let poses = TrainingPoses::new(k, flat);
    poses.check(k).map_err(|e| {
        anyhow::anyhow!(
            "{}: the training snapshots' coefficients: {e}",
            pipeline.scene.source
        )
    })?;
    Ok(Coverage {
        poses,
        frames_per_schedule: snaps.frames_per_schedule,
        later_start: snaps.later_start.is_some(),
    })
}

impl crate::pipeline::StageSummary for Coverage {
    fn summary(&self) -> String {
        format!(
            "the ranges of the {} training poses' {} PCA coefficients, which `run` measures each \
             reduced frame against and a model file carries for its steps",
            self.poses.len(),
            self.poses.dim()
        )
    }
}
