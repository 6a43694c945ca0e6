//! Implicit Euler posed as an energy minimisation (DESIGN §3):
//!
//! u_{n+1} = argmin_u  V(u) + Φ(u, t_{n+1}) − f_gᵀu + 1/(2h²) ‖u − u_n − h u̇_n‖²_M,
//! u̇_{n+1} = (u_{n+1} − u_n)/h,
//!
//! with V the elastic energy, Φ the external force potentials (springs, point loads) and f_g = Mg
//! the gravity load. The quasi-static mode drops the inertia term and finds static equilibrium,
//! falling back to automatic load stepping from rest when a direct solve fails.
//!
//! Unknowns are the free DOFs only ([`DofMap`](crate::constraints::DofMap)); pinned vertices stay
//! at zero displacement.
//!
//! Each dynamic step's solve starts from the second-order extrapolation
//! u_n + h u̇_n + h² ü_n, with ü_n = (u̇_n − u̇_{n−1})/h the last step's acceleration, rather than
//! from u_n: the minimiser is the same, only closer (fewer L-BFGS iterations on smooth motion).
//! The first step, a state set from outside, and an extrapolation whose energy is not finite
//! start from u_n.
//!
//! The pieces, one a file: the scene's `[time]` and `[gravity]` sections (`config.rs`), the
//! problem (`model.rs`), one step's objective (`step_objective.rs`), the system matrix and its
//! factor (`system_matrix.rs`), the time stepper (`simulator.rs`) and when its L-BFGS skips an aged
//! factor (`aged_reuse.rs`).

mod aged_reuse;
mod config;
mod model;
mod simulator;
mod step_objective;
mod system_matrix;

pub use config::{GravityConfig, MAX_FRAMES, TimeConfig};
pub use model::FullSpaceModel;
pub use simulator::{PRECOND_MAX_AGE, RETRY_BUDGET, Simulator, State, StepReport};
pub use system_matrix::FactoredPreconditioner;
pub(crate) use system_matrix::NewtonParts;

/// The largest vertex displacement (m) of `u`, 3 values per vertex: a step's
/// [`StepReport::max_displacement`].
pub fn max_displacement(u: &[f64]) -> f64 {
    u.chunks_exact(3)
        .map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
        .fold(0.0, f64::max)
}
