//! Which matrix preconditions the reduced L-BFGS, and when one that depends on the state is
//! rebuilt.

/// The most steps an L-BFGS preconditioner that depends on the state is kept: a bound, not
/// the rule. A count of extra iterations decides when the solves it serves have got harder;
/// where they do not (steps of one or two iterations, a body nearly at rest), an older matrix
/// serves as well. At 8 steps (before 2026-12-01) the rebuilds were about half the mean step
/// (46–65 %) on AutoDef's bar and X meshes and on the generated bars. With no bound at all,
/// `neural-cubature` on the bar 2k went 0.68 → 0.32 ms a step (1.1 → 1.3 iterations), on bar
/// 15k 1.9 → 1.4 ms, on X very low 0.19 → 0.09 ms; where the solves do get harder (the
/// catapult, the dinosaur, the figure) the same rebuilds happen either way.
pub const PRECOND_MAX_AGE: usize = 64;

/// A preconditioner that depends on the state is rebuilt once the solves it served have taken,
/// together, this many iterations more than the first one did: about what a rebuild costs in
/// energy evaluations (its Jacobian and per-element Gauss–Newton products take 9–10 evaluations'
/// time on the catapult's 128-element rule). A fixed count, not a timing, so that trajectories
/// do not depend on the machine's load. On the catapult it measured 5.0 iterations and 24 %
/// rebuilds per step against 4.5 and 37 % for the rule it replaced (rebuild when one solve takes
/// half again as many iterations as the first), about 5 % less time.
pub(super) const PRECOND_EXTRA_ITERATIONS: usize = 8;

/// A current-state preconditioner that has served this many iterations of a solve without
/// converging, beyond what its first solve took when it was kept from an earlier step, is
/// rebuilt at the solve's iterate, and L-BFGS goes on from there. Before stop 64 such a solve ran
/// to the iteration cap and was redone by reduced Newton from the step's start, and a
/// preconditioner whose first solve had failed that way kept the failure as its yardstick and
/// was never found stale: a jelly (d = 112, 500 elements) dragged, punched and turned by gravity
/// in a 60 Hz loop fell back to Newton in 123 of 447 steps, 60 of 60 with gravity sideways on 2
/// rebuilds. The count is at the upper end of a rebuild's cost (10–30 evaluations at 500
/// elements), so that a solve a few iterations longer than the first, which normal motion
/// gives, keeps its preconditioner: at 8 the catapult's and the dinosaur's test drags rebuilt
/// 56 and 66 times in 100 steps instead of 35 and 40; at 32, 35 and 40.
pub(super) const REBUILD_AFTER_ITERATIONS: usize = 32;

/// How many times a solve rebuilds a preconditioner made within the step (at the step's start
/// or by an earlier rebuild) before L-BFGS gets the full iteration cap and then, failing that,
/// reduced Newton. A step far from anything trained (a punch of two body weights, gravity
/// turned) can outrun even a fresh matrix; two more rebuilds finished every such step of five
/// game loops where one rebuild of the aged matrix left 1–19 to Newton, and took their worst
/// frames from 139–337 to 75–104 ms (the jelly, a starfish, a stool); four did no better.
pub(super) const FRESH_REBUILDS_IN_SOLVE: usize = 2;

/// The matrix that preconditions the reduced L-BFGS.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preconditioning {
    /// `current-state`, with or without cubature. Without cubature its matrix costs every element
    /// of the mesh, but the rest matrix is so far from the Hessian once the body rotates that
    /// L-BFGS crawls: on the catapult, pca (no cubature) took 712 ms per step with `rest` (95
    /// iterations) against 36 ms with `current-state` (15), neural 75 against 15 ms; on the
    /// cantilever 1.7 against 1.0 ms and 1.1 against 0.8 ms.
    #[default]
    Auto,
    /// The Gauss–Newton matrix Jᵀ(Σ_e w_e U_eᵀ H_e U_e + UᵀMU/h² + springs)J at the state the
    /// step starts from, with the exact element tangents H_e when the matrix is positive
    /// definite and tangents projected to be positive semidefinite otherwise (the matrix of
    /// reduced Newton, over the same elements): it sees the rotations and stretches the body is
    /// in. Kept for several steps (see [`PRECOND_MAX_AGE`]).
    CurrentState,
    /// Jᵀ(UᵀK₀U + UᵀMU/h² + springs)J with the stiffness at rest over every element (AutoDef's):
    /// cheap to form, but far from the Hessian once the body rotates or stretches.
    Rest,
}
