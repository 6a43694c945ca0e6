//! When a full-space L-BFGS step skips its aged factor and starts with a fresh one.
//!
//! A current-state factor serves several steps while the body moves smoothly. Where elements turn
//! fast within a step, the factor's stiff directions are wrong by the next step and each reuse
//! fails: on a thin coil falling, 1 of 79 reused factors finished its solve, and every step spent
//! its budget on the aged factor before refactorising (43 % of its iterations). After
//! [`SKIP_AFTER`] factors in a row whose first reuse failed, each step starts with a fresh factor,
//! and the aged one is tried again every [`SKIP_PROBE_PERIOD`] + 1 steps. Counts, not timings,
//! so that the trajectory never depends on the machine's load.
//!
//! Measured on full-space test trajectories (one thread; time modelled from exact counts and
//! each mesh's unit costs): a coil 488 → 417 ms a step, a gmsh jelly −13 to −15 %, a ring −9 to
//! −12 %, AutoDef's catapult −9 % on two of three drags; ±2 % on the armadillo, the dinosaur's
//! first drag, a plate and a tentacle; +7 % on the dinosaur's second drag. Scenes whose reuses
//! succeed keep their trajectories to the bit (`docs/results-suite.md`, stop 63).

/// Factors in a row whose first reuse failed, after which steps start with a fresh factor.
pub(super) const SKIP_AFTER: usize = 2;
/// While skipping, steps that start with a fresh factor between two that try the aged one.
pub(super) const SKIP_PROBE_PERIOD: usize = 8;

/// When a step skips the aged factor and starts with a fresh one.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct AgedReuse {
    /// Factors in a row whose first reuse was cut short.
    failed_in_row: usize,
    /// Steps since an aged factor was last tried while skipping.
    skipped: usize,
}

impl AgedReuse {
    /// Called once at the start of a solve whose factor has served a solve already: whether this
    /// solve should start with a fresh factor instead.
    pub(super) fn skips_aged(&mut self) -> bool {
        if self.failed_in_row < SKIP_AFTER {
            return false;
        }
        if self.skipped >= SKIP_PROBE_PERIOD {
            self.skipped = 0;
        } else {
            self.skipped += 1;
        }
        self.skipped < SKIP_PROBE_PERIOD
    }

    /// A factor's first reuse was cut short.
    pub(super) fn first_reuse_failed(&mut self) {
        self.failed_in_row += 1;
    }

    /// An aged factor finished a solve: reuse is worth trying again.
    pub(super) fn reuse_served(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aged_factors_are_skipped_after_two_short_lives_and_tried_every_ninth_step() {
        let mut r = AgedReuse::default();
        assert!(!r.skips_aged());
        r.first_reuse_failed();
        assert!(!r.skips_aged());
        r.first_reuse_failed();
        let tries: Vec<bool> = (0..20).map(|_| !r.skips_aged()).collect();
        let tried: Vec<usize> = (0..20).filter(|&i| tries[i]).collect();
        assert_eq!(tried, vec![7, 16]);
        r.reuse_served();
        assert!(!r.skips_aged());
    }
}
