//! SIMD kernels that several crates share and that belong to none of them: the row kernels
//! (dot products of rows with a vector, a linear combination of rows added to a vector) under
//! `pulp`'s run-time dispatch, and the probe of the f64 multiply–add rate one thread sustains,
//! the yardstick that turns a kernel's time into a fraction of what the core can do.
//!
//! ```
//! use pulp::{Arch, Simd, WithSimd};
//!
//! struct Dot<'a>(&'a [f64], &'a [f64]);
//! impl WithSimd for Dot<'_> {
//!     type Output = f64;
//!     #[inline(always)]
//!     fn with_simd<S: Simd>(self, simd: S) -> f64 {
//!         simd_kernels::rows::dot_rows(simd, [self.0], self.1)[0]
//!     }
//! }
//! let x = [1.0, 2.0, 3.0];
//! assert_eq!(Arch::new().dispatch(Dot(&x, &x)), 14.0);
//! ```

pub mod peak;
pub mod rows;

use pulp::{Arch, Simd, WithSimd};

/// f64 lanes of the SIMD vectors the kernels are dispatched to on this machine.
pub fn lanes() -> usize {
    struct Lanes;
    impl WithSimd for Lanes {
        type Output = usize;
        #[inline(always)]
        fn with_simd<S: Simd>(self, _: S) -> usize {
            S::F64_LANES
        }
    }
    Arch::new().dispatch(Lanes)
}
