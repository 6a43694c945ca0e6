//! The cached stages by name: what each is called on disk and in cache keys, the version of what
//! it computes, and the command that rebuilds its artifact.
//!
//! A stage's [`name`](Stage::name) is part of its artifact's file name and header and of its
//! cache key, so it must never change: a renamed stage would orphan every cached artifact.

use std::fmt;
use std::str::FromStr;

/// A cached stage of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    /// The training schedules simulated in full space.
    Snapshots,
    /// One shard of the snapshots, for array jobs (merged into [`Stage::Snapshots`]).
    SnapshotsShard,
    /// The mass-orthonormal PCA basis of the snapshots.
    Pca,
    /// The cubature rule of the PCA subspace.
    Cubature,
    /// The cubature rule of the autoencoder's subspace.
    CubatureNeural,
    /// The autoencoder on the snapshots' PCA coefficients.
    Train,
    /// The directions the autoencoder misses.
    Complement,
    /// The full-space simulation of a held-out test trajectory.
    Reference,
    /// The ranges of the snapshots' PCA coefficients ([`crate::coverage`]), kept apart so that
    /// `export` and `view` need not load the snapshots.
    Coverage,
}

impl Stage {
    /// Every stage.
    pub const ALL: [Stage; 9] = [
        Stage::Snapshots,
        Stage::SnapshotsShard,
        Stage::Pca,
        Stage::Cubature,
        Stage::CubatureNeural,
        Stage::Train,
        Stage::Complement,
        Stage::Reference,
        Stage::Coverage,
    ];

    /// The stage's name in artifact file names, artifact headers and cache keys.
    pub const fn name(self) -> &'static str {
        match self {
            Stage::Snapshots => "snapshots",
            Stage::SnapshotsShard => "snapshots-shard",
            Stage::Pca => "pca",
            Stage::Cubature => "cubature",
            Stage::CubatureNeural => "cubature-neural",
            Stage::Train => "train",
            Stage::Complement => "complement",
            Stage::Reference => "reference",
            Stage::Coverage => "coverage",
        }
    }

    /// Version of what the stage computes, mixed into its cache key. Bump a stage's number when
    /// its numerical method changes so that its cached artifacts (and everything downstream,
    /// whose keys include its key) are recomputed, while other stages' caches stay valid.
    pub const fn version(self) -> u32 {
        match self {
            // 2: inputs centred with one common scale instead of per-feature standardisation.
            // 3: the training gradient sums in a different (still fixed) order.
            // 5: without `[autoencoder] latent_dim`, d is half the PCA dimension (was 6).
            // 6: the artifact says whether the hidden widths are the default's (a new field, which
            //    the stored format cannot default: scenes that name `hidden` keep their key).
            // 7: the judged network kept where the one trained again on every schedule misses
            //    the snapshots by more (`retrain_missed`, a new field).
            // 8: without a validation split the weights are kept by their own training loss
            //    measured after the epoch (was the epoch's running mean, the weights before its
            //    steps), and the start (PCA's truncation, with the skip) is a candidate;
            //    early stopping's clock runs from the best trained epoch.
            // 9: each epoch's monitored loss and the start's are kept, for `loss.csv` (new
            //    fields).
            Stage::Train => 9,
            // 2: Newton factorises the exact Hessian first (different iterates within tolerance).
            // 3: sequential sparse factorisation on small pools (round-off), current-state
            //    L-BFGS preconditioner (iterates within tolerance).
            // 4: L-BFGS's preconditioner solves with its factor rounded to f32 (iterates within
            //    tolerance).
            // 5: L-BFGS's preconditioner factorised in f32 where it passes its check (iterates
            //    within tolerance).
            // 6: each step's solve starts from the extrapolation u_n + h u̇_n + h² ü_n (iterates
            //    within tolerance).
            // 7: the preconditioner's f32 factor stored in 16 bits where that passes its check
            //    (iterates within tolerance).
            // 8: the substitutions multiply by the diagonal's reciprocals instead of dividing
            //    (round-off).
            // 9 (not the reference): a schedule whose solve fails partway keeps its earlier
            //    frames, and the set says which stopped.
            // 10: with default-length schedules, every fourth starts later when the body is
            //     still moving under gravity after them (`later_start`).
            // 11 (and the reference's 10): a step one full-space solver cannot finish goes on
            //     with the other from where the first stopped, not from the step's start.
            // 12 (and the reference's 11): L-BFGS's current-state factor turned with the body
            //     between refactorisations, and an aged one cut short after its fresh count plus
            //     a refactorisation's cost (iterates within tolerance).
            // 13: the training patches placed closer together near the pins
            //     (`fem_core::snapshots::NEAR_PINS`).
            Stage::Snapshots | Stage::SnapshotsShard => 13,
            // 9: a solve that fails partway keeps the frames before it (`stopped`).
            // 12: the steps whose solver stopped short and the other finished (`switched`, a
            //     new field).
            Stage::Reference => 12,
            // 2: the held-out error along the greedy path is stored with the rule.
            // 3: forces fitted in the step's compliance norm (other rules).
            // 4: the held-out error over all the test's frames, from the rule's own columns
            //    (`cubature::HeldOutForces`), not the memory limit's subsample.
            // 5: on a mesh past the memory limit, every pose and a subsample of the elements as
            //    candidates (other rules); the poses and candidates stored (new fields).
            // 6: the neural stage's choice stored beside the rule (`FittedCubature::validation`,
            //    a field the old artifacts lack).
            Stage::Cubature => 6,
            // 3: the decoder's Jacobian from SIMD kernels (round-off).
            // 4: forces fitted in the step's compliance norm, with the complement directions
            //    beside the decoder's Jacobian (other rules).
            // 5: poses completed by the complement directions (other rules).
            // 6: the held-out error as for `cubature` 4.
            // 7: candidates and stored fields as for `cubature` 5.
            // 8: the rule fitted in the decoder's tangent or the PCA subspace's, whichever
            //    follows training schedules clearly closer (`FittedCubature::validation`).
            Stage::CubatureNeural => 8,
            // 2: the default explained energy 1 − 10⁻⁷ instead of 1 − 10⁻⁶ (scenes naming no rule).
            // 3: the positions of the fall under gravity appended (`PcaFit::appended`, a new
            //    field the old artifacts lack).
            // 4: static responses to patch loads appended (`PcaFit::responses`).
            // 5: faer's kernels at a fixed parallelism, `FAER_TASKS` (the same as before on
            //    two threads, round-off on others; every stage after it too, whose keys hold
            //    this one's).
            Stage::Pca => 5,
            // 2: with what the PCA basis leaves out of the snapshots, for the default count.
            // 3: with the snapshots' energy and the latent dimension.
            Stage::Complement => 3,
            // 2: with the training schedules' length (`Coverage`), which `run` read the
            //    snapshots for.
            Stage::Coverage => 2,
        }
    }

    /// The command that (re)builds the stage's artifact. Every command recomputes an unusable
    /// artifact of a stage it needs, so re-running it repairs the cache.
    pub const fn rebuild_command(self) -> &'static str {
        match self {
            Stage::Snapshots => "cargo xtask snapshots",
            Stage::SnapshotsShard => {
                "cargo xtask snapshots --shard I/N` (for that shard) or `cargo xtask snapshots"
            }
            Stage::Pca => "cargo xtask pca",
            Stage::Cubature => "cargo xtask cubature",
            Stage::CubatureNeural => "cargo xtask run --methods neural-cubature",
            Stage::Train => "cargo xtask train",
            // The complement and the full-space simulation of a held-out trajectory are
            // computed by `run`.
            Stage::Complement | Stage::Reference => "cargo xtask run",
            // The ranges are computed by whatever needs them first.
            Stage::Coverage => "cargo xtask export",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

impl serde::Serialize for Stage {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// A name that is no stage's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a stage")]
pub struct UnknownStage(pub String);

impl FromStr for Stage {
    type Err = UnknownStage;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Stage::ALL
            .into_iter()
            .find(|stage| stage.name() == s)
            .ok_or_else(|| UnknownStage(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::Stage;

    /// Names and versions are part of every cache key and artifact file name: these are the
    /// ones the caches on disk were written with.
    #[test]
    fn names_and_versions_are_the_ones_on_disk() {
        let found: Vec<(&str, u32)> = Stage::ALL.map(|s| (s.name(), s.version())).to_vec();
        assert_eq!(
            found,
            [
                ("snapshots", 13),
                ("snapshots-shard", 13),
                ("pca", 5),
                ("cubature", 6),
                ("cubature-neural", 8),
                ("train", 9),
                ("complement", 3),
                ("reference", 12),
                ("coverage", 2),
            ]
        );
        for s in Stage::ALL {
            assert_eq!(s.name().parse::<Stage>(), Ok(s));
            assert_eq!(format!("{s:>16}"), format!("{:>16}", s.name()));
        }
        assert!("cubature_neural".parse::<Stage>().is_err());
    }
}
