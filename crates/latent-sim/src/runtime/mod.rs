//! Interactive simulation of a mesh, reduced or in full space, behind one API (DESIGN §11): grab
//! vertices with a spring ([`Interactive::grab`], [`Interactive::grab_near`]), move the
//! spring's target, release it; several handles at once; gravity on or off; reset to rest;
//! step; read positions, or only the surface's into an `f32` or `f64` buffer.
//!
//! A handle is a spring force of fem-core ([`fem_core::forces`]): a stiffness k split evenly
//! over its n vertices, each pulled toward its rest position moved by one offset d, energy
//! k/(2n) Σ_v ‖u_v − d‖². Grabbing at a point p records the vertices' mean displacement ū, and
//! moving the target to t sets d = ū + (t − p): the patch is dragged by how far the target
//! moved from where it was grabbed. Forces given as data ([`Interactive::add_force`], e.g. a
//! scene's schedule) act the same way in both simulators, so a program can run one schedule
//! in full space and reduced and compare.

mod full;
mod handles;
mod reduced;
mod surface;

pub use full::FullRuntime;
pub use handles::{
    Handle, MAX_POINT_LOAD, MAX_SPRING_STIFFNESS, body_force, body_stiffness, check_point_load,
};
pub use reduced::{AnyReducedSimulator, ReducedRuntime};
pub use surface::Surface;

use fem_core::forces::ExternalForce;
use fem_core::{FemError, Vec3, four_digits};

use crate::ReducedError;

/// A floating-point type positions can be read into.
pub trait Real: Copy + sealed::Sealed {
    /// The nearest value of this type.
    fn from_f64(x: f64) -> Self;
}

impl Real for f32 {
    #[inline]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
}

impl Real for f64 {
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// What one step did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[non_exhaustive]
pub struct StepStats {
    /// The step just taken (1 for the first) and the time it reached.
    pub step: usize,
    pub time: f64,
    /// Solver iterations.
    pub iterations: usize,
    /// The solve's gradient against the step's forces when it stopped (the tolerance or below
    /// when it converged).
    pub relative_gradient: f64,
    /// Wall time of the step.
    pub seconds: f64,
    /// L-BFGS's preconditioner was rebuilt during this step: a step that costs several times a
    /// plain one (a reduced model's 2.4 ms against 0.18 ms on the default bar; one step in two
    /// to five while the body moves, rarely at rest).
    pub preconditioner_rebuilt: bool,
    /// L-BFGS crawled (or its line search failed) and the step was solved on with Newton (in
    /// full space, with the other solver than the scene's): a slow step, in a reduced model
    /// usually a pull far beyond what it was trained for.
    pub newton_fallback: bool,
    /// How far the pose the step reached lies beyond the training poses' ranges, relative to
    /// its size ([`crate::coverage::TrainingPoses::distance`]; `cargo xtask run` reports the
    /// largest over a test as `from training`): 0 among them; above
    /// [`crate::coverage::OUTSIDE_TRAINING`] (0.1) the decoder and the cubature rule
    /// extrapolate and the motion is not to be trusted as the body's. None in full space and
    /// for a model made without the ranges.
    pub beyond_training: Option<f64>,
}

/// Errors of the interactive simulators.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    #[error(transparent)]
    Reduced(#[from] ReducedError),
    #[error(transparent)]
    Fem(#[from] FemError),
    /// A handle this simulator does not have any more (released already), or made on a copy
    /// of it after the copy.
    #[error("no handle {0} in this simulator (released already, or made on a copy of it?)")]
    UnknownHandle(Handle),
    /// Another simulator's handle.
    #[error("handle {0} belongs to another simulator, not to this one")]
    ForeignHandle(Handle),
    /// No surface vertex within the radius of the point, where the surface is now (deformed);
    /// `nearest` is the distance to the nearest one.
    #[error(
        "no surface vertex within {} of ({}, {}, {}) where the surface is now (deformed, not at \
         rest); the nearest is {} away: a larger radius, or a point nearer the body",
        four_digits(*radius),
        four_digits(point[0]),
        four_digits(point[1]),
        four_digits(point[2]),
        four_digits(*nearest)
    )]
    NothingInReach {
        point: [f64; 3],
        radius: f64,
        nearest: f64,
    },
    /// A vertex index past the mesh's vertices.
    #[error("vertex {vertex} does not exist (the mesh has {count})")]
    NoSuchVertex { vertex: usize, count: usize },
    /// A grab or a force on pinned vertices only.
    #[error(
        "the vertices given or found near the point ({count}) are all pinned: a spring or a \
         load on them moves nothing; grab or load free vertices"
    )]
    AllPinned { count: usize },
    /// A handle on no vertex.
    #[error("a handle needs at least one vertex")]
    NoVertices,
    /// A vertex the mesh file lists that no tetrahedron uses: no part of the body moves with it.
    #[error(
        "vertex {vertex} belongs to no tetrahedron (the mesh file lists it, no tet uses it), so \
         nothing of the body moves with it: choose vertices of the body"
    )]
    NotInBody { vertex: usize },
    /// A force whose active span is not a span: start or end not a number, or end not after
    /// start (an empty span never acts).
    #[error(
        "a force's active span runs from `start` to `end` (s; start may be −∞ and end +∞, for \
         always), so start < end, got start = {start}, end = {end}"
    )]
    ActiveSpan { start: f64, end: f64 },
    /// A force whose active span ended before the simulation's clock: it would never act.
    #[error(
        "the force's active span ends at t = {end} s, not after the simulation's clock (t = \
         {now} s), so it would never act: spans and keyframe times are on the simulation's \
         clock (`time`), not times from now"
    )]
    SpanOver { end: f64, now: f64 },
    /// A number that must be positive and finite (a stiffness, a radius) is not.
    #[error("the {what} must be positive and finite, got {value}")]
    NotPositive { what: &'static str, value: f64 },
    /// A point or target with a coordinate that is not finite.
    #[error("the {what} must be finite, got ({}, {}, {})", value[0], value[1], value[2])]
    NotFinite { what: &'static str, value: [f64; 3] },
    /// A spring far stiffer than the body ([`handles::MAX_SPRING_STIFFNESS`]).
    #[error(
        "a spring of stiffness {stiffness:.3e} N/m is more than {max:e} times the body's own \
         stiffness at its size (E × its bounding-box diagonal = {body:.3e} N/m): it would hold its \
         vertices no more firmly than a softer one while swamping every solve; give at most \
         {shown:.3e} N/m \
         (the body's own stiffness is already a firm grip)",
        max = handles::MAX_SPRING_STIFFNESS,
        shown = handles::printed_limit(*.limit)
    )]
    TooStiff {
        stiffness: f64,
        body: f64,
        limit: f64,
    },
    /// A point load far larger than the body's own force scale ([`handles::MAX_POINT_LOAD`]).
    #[error(
        "a point load of {load:.3e} N is more than {max:e} times the force that strains the body \
         by its own size (E × the square of its bounding-box diagonal = {body:.3e} N): it would \
         only overflow the solves; give at most {shown:.3e} N",
        max = handles::MAX_POINT_LOAD,
        shown = handles::printed_limit(*.limit)
    )]
    TooLarge { load: f64, body: f64, limit: f64 },
    /// A point load given a stiffness, which only a spring has.
    #[error(
        "a point load has no stiffness, got {0}: give it 0 (its keyframes are its force), or make \
         it a spring"
    )]
    PointStiffness(f64),
    /// A point load has no target to move.
    #[error("handle {0} is a point load; only a spring has a target to move")]
    NotASpring(Handle),
    /// A spring has no load to set.
    #[error(
        "handle {0} is a spring; only a point load has a force to set (move a spring's target \
         with move_handle)"
    )]
    NotAPointLoad(Handle),
    /// A caller's buffer of the wrong length.
    #[error("the {what} buffer has {got} values, expected {expected} (3 per vertex)")]
    BufferLength {
        what: &'static str,
        expected: usize,
        got: usize,
    },
}

/// One simulator of a mesh that a program drives interactively: [`ReducedRuntime`] (a trained
/// model) or [`FullRuntime`] (full space). Positions are rest positions plus displacement; the
/// surface is [`Interactive::surface`]'s vertices, in its order.
pub trait Interactive {
    /// Rest positions, one per vertex.
    fn rest_positions(&self) -> &[Vec3];
    /// The boundary surface: its vertices and triangles.
    fn surface(&self) -> &Surface;
    /// Simulated time (s) and steps taken.
    fn time(&self) -> f64;
    fn steps(&self) -> usize;
    /// Advances one time step.
    ///
    /// # Errors
    /// When the step's solve fails (diverges, does not converge, meets an inverted element);
    /// the state is then the one before the step.
    fn step(&mut self) -> Result<StepStats, RuntimeError>;
    /// Grabs `vertices` with a spring of total stiffness `stiffness` (N/m), its target at their
    /// current centroid.
    ///
    /// # Errors
    /// [`RuntimeError::NoVertices`], [`RuntimeError::NoSuchVertex`],
    /// [`RuntimeError::NotInBody`], [`RuntimeError::NotPositive`], [`RuntimeError::TooStiff`],
    /// [`RuntimeError::AllPinned`]; a reduced model without the rows of a vertex:
    /// [`ReducedError::NoBasisRows`].
    fn grab(&mut self, vertices: &[usize], stiffness: f64) -> Result<Handle, RuntimeError>;
    /// Grabs the surface vertices within `radius` of `point` (where they are now) with a spring
    /// of total stiffness `stiffness`, its target at `point`.
    ///
    /// # Errors
    /// [`RuntimeError::NothingInReach`], [`RuntimeError::NotPositive`],
    /// [`RuntimeError::TooStiff`], [`RuntimeError::AllPinned`], [`RuntimeError::NotFinite`].
    fn grab_near(
        &mut self,
        point: [f64; 3],
        radius: f64,
        stiffness: f64,
    ) -> Result<Handle, RuntimeError>;
    /// Moves a handle's target to `target`: its vertices are pulled toward where they were
    /// grabbed, moved by `target` minus the grab point.
    ///
    /// # Errors
    /// [`RuntimeError::UnknownHandle`], [`RuntimeError::ForeignHandle`], [`RuntimeError::NotASpring`],
    /// [`RuntimeError::NotFinite`].
    fn move_handle(&mut self, handle: Handle, target: [f64; 3]) -> Result<(), RuntimeError>;
    /// A spring handle's target now: where [`Interactive::move_handle`] put it, or where the
    /// keyframes of a spring added with [`Interactive::add_force`] put it at this time, whether
    /// or not its active span holds this time.
    ///
    /// # Errors
    /// [`RuntimeError::UnknownHandle`], [`RuntimeError::ForeignHandle`], [`RuntimeError::NotASpring`].
    fn handle_target(&mut self, handle: Handle) -> Result<[f64; 3], RuntimeError>;
    /// Sets a point load's total force (N), spread over its vertices, from now on (its
    /// keyframes become that one value; it acts while its active span holds, as added): a
    /// force a program changes every frame, at the cost of moving a handle (the preconditioner
    /// is kept).
    ///
    /// # Errors
    /// [`RuntimeError::UnknownHandle`], [`RuntimeError::ForeignHandle`],
    /// [`RuntimeError::NotAPointLoad`], [`RuntimeError::NotFinite`],
    /// [`RuntimeError::TooLarge`].
    fn set_load(&mut self, handle: Handle, force: [f64; 3]) -> Result<(), RuntimeError>;
    /// The handles (and forces added as data) held now, in the order they were made.
    fn handles(&mut self) -> Vec<Handle>;
    /// Lets go of a handle (or removes a force added with [`Interactive::add_force`]).
    ///
    /// # Errors
    /// [`RuntimeError::UnknownHandle`], [`RuntimeError::ForeignHandle`].
    fn release(&mut self, handle: Handle) -> Result<(), RuntimeError>;
    /// Adds a force given as data (a spring or point load with its schedule, as a scene's
    /// `[[force]]` resolves to); it can be released like a handle, and a spring's target moved
    /// (from its vertices' rest centroid). Its keyframe times and active span are on the
    /// simulation's clock ([`Interactive::time`]), not counted from the call: a ramp over
    /// 0–0.5 s added at t = 1 s acts at full strength at once.
    ///
    /// # Errors
    /// [`RuntimeError::NoSuchVertex`], [`RuntimeError::NoVertices`],
    /// [`RuntimeError::NotInBody`], [`ReducedError::Keyframes`], [`RuntimeError::ActiveSpan`],
    /// [`RuntimeError::SpanOver`], a point load's [`RuntimeError::TooLarge`] value,
    /// a spring's [`RuntimeError::NotPositive`] or [`RuntimeError::TooStiff`] stiffness,
    /// [`RuntimeError::AllPinned`]; a reduced model without the rows of
    /// a vertex: [`ReducedError::NoBasisRows`].
    fn add_force(&mut self, force: ExternalForce) -> Result<Handle, RuntimeError>;
    /// Turns gravity on (its acceleration, the model's unless
    /// [`Interactive::set_gravity_acceleration`] changed it) or off.
    fn set_gravity(&mut self, enabled: bool);
    fn gravity(&self) -> bool;
    /// Sets gravity's acceleration (m/s²), e.g. to tilt the world; it acts while gravity is on.
    /// A reduced model's load follows exactly (it is linear in the acceleration), but a
    /// direction its training schedules did not fall along moves the body where its subspace
    /// may not reach.
    ///
    /// # Errors
    /// [`RuntimeError::NotFinite`].
    fn set_gravity_acceleration(&mut self, g: [f64; 3]) -> Result<(), RuntimeError>;
    /// Gravity's acceleration (m/s²), whether or not gravity is on.
    fn gravity_acceleration(&self) -> [f64; 3];
    /// Back to rest at time 0; handles, forces and the gravity setting stay.
    fn reset(&mut self);
    /// Does now the work the first grab (or spring) would do in its step, so that an
    /// interactive loop's first grab does not stall a frame: a reduced model factorises the
    /// full step's operator at rest once, for the patch compliance its springs pull through
    /// (75–110 ms on the 3,321-vertex default bar; later grabs cost 7–10 ms). Nothing in full
    /// space, and nothing when it was done already.
    fn prepare_grab(&mut self) {}
    /// Positions of every vertex (3 per vertex) into `out`.
    ///
    /// # Errors
    /// [`RuntimeError::BufferLength`]; a reduced model that keeps only the rows in use (the
    /// default export): [`ReducedError::NoBasisRows`] — read the surface instead.
    fn positions_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError>;
    /// Positions of the surface vertices (3 per vertex, in [`Surface::vertices`]'s order) into
    /// `out`, without allocating: a reduced model decodes only those vertices' rows.
    ///
    /// # Errors
    /// [`RuntimeError::BufferLength`].
    fn surface_positions_into<T: Real>(&mut self, out: &mut [T]) -> Result<(), RuntimeError>
    where
        Self: Sized;
    /// Velocities (m/s) of the surface vertices (3 per vertex, in [`Surface::vertices`]'s
    /// order) into `out`: (u_n − u_{n−1})/h, implicit Euler's; a reduced model's are the
    /// subspace's, without the dents its springs make outside it.
    ///
    /// # Errors
    /// [`RuntimeError::BufferLength`].
    fn surface_velocities_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError>;
    /// [`Interactive::surface_positions_into`] an `f32` buffer, for a trait object
    /// (`Box<dyn Interactive>`, which cannot call a generic method): simulators of different
    /// types side by side, as the viewer holds them.
    ///
    /// # Errors
    /// [`RuntimeError::BufferLength`].
    fn surface_positions_f32(&mut self, out: &mut [f32]) -> Result<(), RuntimeError>;
}

/// Checks a handle's stiffness, a radius, a point.
fn positive(what: &'static str, value: f64) -> Result<(), RuntimeError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(RuntimeError::NotPositive { what, value })
    }
}

fn finite(what: &'static str, value: [f64; 3]) -> Result<(), RuntimeError> {
    if value.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(RuntimeError::NotFinite { what, value })
    }
}

fn buffer_length(what: &'static str, expected: usize, got: usize) -> Result<(), RuntimeError> {
    if expected == got {
        Ok(())
    } else {
        Err(RuntimeError::BufferLength {
            what,
            expected,
            got,
        })
    }
}
