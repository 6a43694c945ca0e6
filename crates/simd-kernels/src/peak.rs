//! The f64 multiply–add rate one thread of this machine sustains with the SIMD instructions the
//! kernels are dispatched to: the yardstick that turns a kernel's time into a fraction
//! of what the core can do. On a shared or frequency-scaled machine absolute times move by tens
//! of percent from one hour to the next; a kernel's time measured beside this rate does not.
//!
//! The probe runs [`CHAINS`] independent chains a ← a·b + c of SIMD vectors (enough independent
//! fused multiply–adds to cover their latency on current x86 and ARM cores), so it is bound by
//! the multiply–add throughput alone: no memory traffic, no horizontal sums.
//!
//! ```
//! let probe = simd_kernels::peak::fma_rate(std::time::Duration::from_millis(5));
//! assert!(probe.multiply_adds_per_second > 0.0);
//! ```

use std::hint::black_box;
use std::time::{Duration, Instant};

use pulp::{Arch, Simd, WithSimd};

/// Independent accumulator chains of the probe.
pub const CHAINS: usize = 12;

/// The result of [`fma_rate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FmaRate {
    /// f64 multiply–adds per second (each SIMD lane counts), the best of the timed rounds.
    pub multiply_adds_per_second: f64,
    /// f64 lanes of the SIMD vectors the probe (and the crate's kernels) ran on.
    pub lanes: usize,
}

/// Measures the f64 multiply–add rate of the calling thread for about `duration` (the best of
/// several rounds, which a busy machine disturbs least).
pub fn fma_rate(duration: Duration) -> FmaRate {
    let lanes = crate::lanes();
    // Rounds of about 2 ms: long next to the timer's resolution, short next to a scheduler slice.
    let iterations = calibrate();
    let per_round = (iterations * CHAINS * lanes) as f64;
    let start = Instant::now();
    let mut best = f64::INFINITY;
    let mut rounds = 0;
    while rounds < 3 || start.elapsed() < duration {
        let t = Instant::now();
        black_box(run(iterations, 1.0));
        best = best.min(t.elapsed().as_secs_f64());
        rounds += 1;
    }
    FmaRate {
        multiply_adds_per_second: per_round / best,
        lanes,
    }
}

/// Iterations of one probe round of about 2 ms.
fn calibrate() -> usize {
    let mut iterations = 1_000;
    loop {
        let t = Instant::now();
        black_box(run(iterations, 1.0));
        let seconds = t.elapsed().as_secs_f64();
        if seconds > 2e-3 || iterations > 1 << 30 {
            return iterations;
        }
        iterations *= if seconds < 2e-4 { 10 } else { 2 };
    }
}

/// Each lane of each chain after `iterations` steps of a ← a·b + c from `a0`, summed over all
/// [`CHAINS`] chains and lanes.
fn run(iterations: usize, a0: f64) -> f64 {
    Arch::new().dispatch(Chains {
        iterations: black_box(iterations),
        a0,
        b: black_box(PROBE_B),
        c: black_box(PROBE_C),
    })
}

/// The probe's multiplier and addend: a fixed point at c/(1 − b) = 1, so the values stay near 1.
const PROBE_B: f64 = 0.999_999;
const PROBE_C: f64 = 1.0 - PROBE_B;

struct Chains {
    iterations: usize,
    a0: f64,
    b: f64,
    c: f64,
}

impl WithSimd for Chains {
    type Output = f64;

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) -> f64 {
        let Self {
            iterations,
            a0,
            b,
            c,
        } = self;
        let (b, c) = (simd.splat_f64s(b), simd.splat_f64s(c));
        let mut acc = [simd.splat_f64s(a0); CHAINS];
        for _ in 0..iterations {
            for a in &mut acc {
                *a = simd.mul_add_e_f64s(*a, b, c);
            }
        }
        acc.iter().map(|&a| simd.reduce_sum_f64s(a)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The probe really performs its iterations: every lane follows aₙ = 1 + bⁿ (a₀ − 1), the
    /// closed form of a ← a·b + c with c = 1 − b.
    #[test]
    fn the_probe_runs_every_multiply_add() {
        let lanes = crate::lanes();
        for iterations in [0, 1, 7, 1_000, 123_457] {
            let a0 = 3.0;
            let expected = (CHAINS * lanes) as f64 * (1.0 + PROBE_B.powi(iterations) * (a0 - 1.0));
            let got = run(iterations as usize, a0);
            assert!(
                (got - expected).abs() <= 1e-9 * expected,
                "{iterations} iterations: {got} instead of {expected}"
            );
        }
    }

    #[test]
    fn the_rate_is_finite_and_positive() {
        let probe = fma_rate(Duration::from_millis(1));
        assert!(probe.multiply_adds_per_second.is_finite());
        assert!(probe.multiply_adds_per_second > 0.0);
        assert!(probe.lanes >= 1);
    }
}
