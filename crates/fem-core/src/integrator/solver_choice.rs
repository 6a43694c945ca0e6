//! Which solver the steps of a full-space L-BFGS scene use, and when L-BFGS skips its aged factor.
//!
//! Preconditioned L-BFGS is the faster full-space solver on nearly every scene measured, but it
//! crawls where the body's elements turn fast within a step (a thin coil spring falling: 93
//! iterations a step against Newton's 7.8, and only 1 of 79 reused factors finishing its solve).
//! Two rules, both counting iterations rather than timing them, so that the trajectory never
//! depends on the machine's load:
//!
//! - [`AgedReuse`]: after [`SKIP_AFTER`] factors in a row whose first reuse failed, each step
//!   starts with a fresh factor, and an aged one is tried again every [`SKIP_PROBE_PERIOD`] + 1
//!   steps;
//! - [`SolverChoice`]: when an L-BFGS step costs more than Newton would have, twice in a row,
//!   the next steps go to Newton, and L-BFGS is tried again after [`SWITCH_FIRST_PERIOD`] of them
//!   (twice as many after each try that crawls again, up to [`SWITCH_MAX_PERIOD`]).
//!
//! Measured on 2 cores (test trajectories, ms a step from the counts, L-BFGS alone → with both
//! rules, Newton alone): a coil 488 → 282 (280), a slender rod 153 → 111 (105), a toppling torus
//! 111 → 99 (189), a cantilever 70 → 71 and a 6k-vertex beam 92 → 92 (neither switches; the
//! beam's trajectory is the same to the bit); the coil's snapshots 675 → 470 s. More meshes are
//! in `docs/results-suite.md` (stop 63).

/// Factors in a row whose first reuse failed, after which steps start with a fresh factor.
pub(super) const SKIP_AFTER: usize = 2;
/// While skipping, steps that start with a fresh factor between two that try the aged one.
pub(super) const SKIP_PROBE_PERIOD: usize = 8;
/// Newton's iterations a step, assumed until a Newton solve has run.
const NEWTON_DEFAULT_ITERATIONS: usize = 5;
/// Crawling L-BFGS steps in a row that send the steps to Newton.
const SWITCH_STRIKES: usize = 2;
/// Newton steps before L-BFGS is tried again, doubled after each try that crawls.
pub(super) const SWITCH_FIRST_PERIOD: usize = 8;
pub(super) const SWITCH_MAX_PERIOD: usize = 64;

/// What a Newton iteration costs in L-BFGS iterations, from the factor's fill nnz(L)/nnz(A): a
/// Newton iteration assembles the Hessian and factorises it in f64, where an L-BFGS iteration
/// evaluates the gradient and solves with a factor it already has. Measured on 2 cores from 8.6
/// (a coil, fill 2.8) to 23 (a 6k-vertex beam, fill 10.4); the line 4 + 2·fill goes through the
/// five meshes measured within 15 %.
pub(super) fn newton_iteration_cost(factor_nnz: usize, matrix_nnz: usize) -> usize {
    let fill = factor_nnz as f64 / matrix_nnz.max(1) as f64;
    (4.0 + 2.0 * fill).round() as usize
}

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

/// How a solve went, as the choice of solver sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SolveOutcome {
    /// Newton finished the solve, in this many iterations.
    Newton(usize),
    /// Newton could not finish the solve and L-BFGS went on from where it stopped: a Newton
    /// step all the same, whose count says nothing of Newton's usual one.
    NewtonFailed,
    /// L-BFGS finished the solve: the iterations of the attempt that finished it, plus what a
    /// factorisation costs when that attempt's factor was fresh.
    Lbfgs(usize),
    /// L-BFGS could not finish the solve and Newton went on from where it stopped.
    LbfgsFailed,
}

/// Which solver the next steps of an L-BFGS scene use.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct SolverChoice {
    on_newton: bool,
    /// Newton's iterations in its last solve.
    newton_iterations: Option<usize>,
    /// Crawling L-BFGS steps in a row.
    strikes: usize,
    /// Newton steps since the steps went to Newton or L-BFGS was last tried.
    newton_steps: usize,
    /// Newton steps before L-BFGS is tried again.
    period: usize,
    /// L-BFGS steps since the steps last came back from Newton.
    lbfgs_steps: usize,
}

impl Default for SolverChoice {
    fn default() -> Self {
        Self {
            on_newton: false,
            newton_iterations: None,
            strikes: 0,
            newton_steps: 0,
            period: SWITCH_FIRST_PERIOD,
            lbfgs_steps: usize::MAX / 2,
        }
    }
}

impl SolverChoice {
    /// Whether the next solve goes to Newton.
    pub(super) fn newton(&self) -> bool {
        self.on_newton && !self.probing()
    }

    /// Whether the next solve tries L-BFGS again after a run of Newton steps (with a fresh
    /// factor: the one from before the run is stale).
    pub(super) fn probing(&self) -> bool {
        self.on_newton && self.newton_steps >= self.period
    }

    /// What Newton would cost for a solve, in L-BFGS iterations, with a Newton iteration worth
    /// `newton_cost` of them.
    pub(super) fn newton_work(&self, newton_cost: usize) -> usize {
        newton_cost
            * self
                .newton_iterations
                .unwrap_or(NEWTON_DEFAULT_ITERATIONS)
                .max(1)
    }

    /// Records how the solve went.
    pub(super) fn record(&mut self, outcome: SolveOutcome, newton_cost: usize) {
        let probing = self.probing();
        let crawled = match outcome {
            SolveOutcome::Newton(iterations) => {
                self.newton_iterations = Some(iterations);
                self.newton_steps += 1;
                return;
            }
            SolveOutcome::NewtonFailed => {
                self.newton_steps += 1;
                return;
            }
            SolveOutcome::Lbfgs(work) => work > self.newton_work(newton_cost),
            SolveOutcome::LbfgsFailed => true,
        };
        if probing {
            if crawled {
                self.newton_steps = 0;
                self.period = (2 * self.period).min(SWITCH_MAX_PERIOD);
            } else {
                self.on_newton = false;
                self.strikes = 0;
                self.lbfgs_steps = 0;
            }
            return;
        }
        self.lbfgs_steps += 1;
        if !crawled {
            self.strikes = 0;
            return;
        }
        self.strikes += 1;
        if self.strikes >= SWITCH_STRIKES {
            self.on_newton = true;
            self.newton_steps = 0;
            // Back within a period of the last return: that try was lucky.
            self.period = if self.lbfgs_steps <= self.period {
                (2 * self.period).min(SWITCH_MAX_PERIOD)
            } else {
                SWITCH_FIRST_PERIOD
            };
        }
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

    #[test]
    fn two_crawls_send_the_steps_to_newton_and_a_good_try_brings_them_back() {
        let cost = 10;
        let mut c = SolverChoice::default();
        // Newton assumed at 5 iterations: 50 L-BFGS iterations' worth.
        c.record(SolveOutcome::Lbfgs(60), cost);
        assert!(!c.newton(), "one crawl is not enough");
        c.record(SolveOutcome::Lbfgs(40), cost);
        c.record(SolveOutcome::Lbfgs(60), cost);
        assert!(!c.newton(), "the strikes must be in a row");
        c.record(SolveOutcome::LbfgsFailed, cost);
        assert!(c.newton());
        for _ in 0..SWITCH_FIRST_PERIOD {
            assert!(c.newton() && !c.probing());
            c.record(SolveOutcome::Newton(3), cost);
        }
        assert!(c.probing() && !c.newton());
        // Newton now costs 30: an L-BFGS try at 31 crawled, and the wait doubles.
        c.record(SolveOutcome::Lbfgs(31), cost);
        assert!(c.newton());
        for _ in 0..2 * SWITCH_FIRST_PERIOD {
            c.record(SolveOutcome::Newton(3), cost);
        }
        assert!(c.probing());
        c.record(SolveOutcome::Lbfgs(30), cost);
        assert!(
            !c.newton() && !c.probing(),
            "a try at Newton's cost comes back"
        );
        // Crawling again right after coming back: the next wait is doubled again.
        c.record(SolveOutcome::Lbfgs(31), cost);
        c.record(SolveOutcome::Lbfgs(31), cost);
        assert!(c.newton());
        assert_eq!(c.period, 4 * SWITCH_FIRST_PERIOD);
    }

    #[test]
    fn the_wait_for_another_try_is_bounded() {
        let mut c = SolverChoice::default();
        c.record(SolveOutcome::LbfgsFailed, 10);
        c.record(SolveOutcome::LbfgsFailed, 10);
        for _ in 0..10 {
            while !c.probing() {
                c.record(SolveOutcome::Newton(4), 10);
            }
            c.record(SolveOutcome::LbfgsFailed, 10);
        }
        assert_eq!(c.period, SWITCH_MAX_PERIOD);
        assert!(c.newton());
    }

    #[test]
    fn newton_costs_more_where_its_factor_fills_in_more() {
        assert_eq!(newton_iteration_cost(280, 100), 10);
        assert_eq!(newton_iteration_cost(1040, 100), 25);
        assert_eq!(newton_iteration_cost(5, 0), 14);
    }
}
