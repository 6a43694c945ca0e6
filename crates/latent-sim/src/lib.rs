//! Reduced implicit Euler in linear (PCA) and nonlinear (autoencoder) subspaces (DESIGN §8).
//!
//! A [`Subspace`] maps latent coordinates z to PCA coefficients q (linear: q = z; neural:
//! q = decode(z)), and u = Uq. One step minimises, over z,
//!
//! E(z) = Σ_{e∈S} w_e V_e(U_e q(z)) + Φ(Uq(z), t) − f_gᵀUq(z) + 1/(2h²) (q − q̃)ᵀ (UᵀMU) (q − q̃),
//!
//! with q̃ = q_n + h q̇_n and ∇E(z) = J(z)ᵀ ∂E/∂q, one vector–Jacobian product. Only the rows of U
//! of the element set's vertices are ever multiplied ("partial decode"); a cubature rule's
//! scattered elements go further and keep ∂F/∂q per element, so that F = I + (∂F/∂q) q needs no
//! displacement at all. Springs and point loads are quadratic and linear in u, hence exact
//! functions of q through Σ_v U_vᵀU_v and Σ_v U_vᵀ: their vertices are never decoded. The full
//! displacement u = Uq is formed only when a frame is written out.
//!
//! # A trained model in any program
//!
//! The pipeline's product is one file (`cargo xtask export`, or `cargo xtask run`'s
//! `<method>.ldm`): a [`ReducedModel`] ([`model`]). Its [`ReducedRuntime`] steps it with the
//! solver settings `cargo xtask run` measures, behind the [`Interactive`] API that
//! [`FullRuntime`] offers for the same mesh in full space ([`runtime`]). Dragging a vertex for a
//! second and letting go (`cargo run --release -p latent-sim --example drag -- MODEL` does the
//! same on a model file):
//!
//! ```
//! use latent_sim::{Interactive, ReducedModel};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # let path = std::env::temp_dir().join(format!("latent-sim-doc-{}.ldm", std::process::id()));
//! # doc_model::bar().save(&path)?;
//!
//! let model = ReducedModel::load(&path)?; // a typed error on any damaged file
//! let mut sim = model.simulator()?;
//! // The surface vertex farthest along x (the bar's free end), grabbed with a 5 kN/m spring.
//! let surface = sim.surface().vertices().to_vec();
//! let rest = sim.rest_positions().to_vec();
//! let tip = *surface.iter().max_by(|&&a, &&b| rest[a].x.total_cmp(&rest[b].x)).unwrap();
//! let start = rest[tip];
//! let handle = sim.grab_near(start.into(), 0.01, 5000.0)?;
//! let mut frame = vec![0.0f32; 3 * surface.len()]; // what a renderer uploads
//! for step in 1..=100 {
//!     // Up 10 cm over the second.
//!     sim.move_handle(handle, [start.x, start.y + 0.1 * step as f64 / 100.0, start.z])?;
//!     sim.step()?;
//!     sim.surface_positions_into(&mut frame)?; // decodes the surface rows only
//! }
//! let at = surface.iter().position(|&v| v == tip).unwrap();
//! let lifted = frame[3 * at + 1] as f64 - start.y;
//! assert!(lifted > 0.005, "the tip rose {lifted} m against gravity");
//! sim.release(handle)?;
//! assert!(sim.release(handle).is_err()); // released already
//! sim.step()?;
//! # std::fs::remove_file(&path)?;
//! # Ok(())
//! # }
//! # mod doc_model {
//! #     use fem_core::{Vec3, constraints::{Axis, Side, VertexSelection}};
//! #     use fem_core::{integrator::{FullSpaceModel, TimeConfig}, material::MaterialConfig};
//! #     use latent_sim::model::{ModelSource, ReducedModel, Rows, SubspaceSource};
//! #     /// A 1 m bar clamped at x = 0, PCA on smooth bending shapes (no pipeline needed).
//! #     pub fn bar() -> ReducedModel {
//! #         let spec = fem_core::mesh::generate::BoxSpec {
//! #             size: [1.0, 0.2, 0.2], cells: [8, 2, 2], ..Default::default()
//! #         };
//! #         let mesh = fem_core::mesh::generate::box_mesh(&spec).unwrap();
//! #         let pinned = VertexSelection::plane(Axis::X, Side::Min, None).select(&mesh, "pin").unwrap();
//! #         let material = MaterialConfig { youngs_modulus: 1e7, ..Default::default() };
//! #         let g = Vec3::new(0.0, -9.81, 0.0);
//! #         let model = FullSpaceModel::new(mesh, &material, pinned, g, vec![]).unwrap();
//! #         // Beam shapes: bending (x², x³) in y and z with their rotations, stretch, torsion.
//! #         let shape = |j: usize, p: Vec3| -> [f64; 3] {
//! #             let (x, y, z) = (p.x, p.y - 0.1, p.z - 0.1);
//! #             match j {
//! #                 0 => [-2.0 * x * y, x * x, 0.0],
//! #                 1 => [-2.0 * x * z, 0.0, x * x],
//! #                 2 => [-3.0 * x * x * y, x * x * x, 0.0],
//! #                 3 => [-3.0 * x * x * z, 0.0, x * x * x],
//! #                 4 => [x, 0.0, 0.0],
//! #                 _ => [0.0, -x * z, x * y],
//! #             }
//! #         };
//! #         let (n, k) = (model.dofs.num_free(), 6);
//! #         let mut u = vec![0.0; n * k];
//! #         for j in 0..k {
//! #             for (r, &d) in model.dofs.free.iter().enumerate() {
//! #                 u[j * n + r] = shape(j, model.mesh.vertices[d / 3])[d % 3];
//! #             }
//! #         }
//! #         let basis = pca::PcaBasis::new(n, k, u, None, vec![1.0; k]).unwrap();
//! #         let time = TimeConfig { step: 0.01, frames: 1, quasi_static: false };
//! #         ReducedModel::build(ModelSource {
//! #             model: &model, material: &material, time: &time, basis: &basis, cubature: None,
//! #             subspace: SubspaceSource::Linear, solver: Default::default(),
//! #             preconditioning: Default::default(), spring_compliance: true, full_solver: Default::default(),
//! #             rows: Rows::Used, provenance: Default::default(), training: None,
//! #         }).unwrap()
//! #     }
//! # }
//! ```

mod config;
pub mod coverage;
mod dense_factor;
pub mod model;
mod neural;
mod onset;
mod reduced;
pub mod runtime;
mod simulator;
mod subspace;

pub use config::{
    DEFAULT_ONSET_DIRECTIONS, MAX_COMPLEMENT_DIRECTIONS, MAX_ONSET_DIRECTIONS,
    REDUCED_MIN_ITERATIONS, ReducedSolverConfig,
};

/// A point, as the runtime's positions are read ([`Interactive::rest_positions`]), so that one
/// crate is all a program needs.
pub use fem_core::Vec3;
/// The forces a program adds to a runtime ([`Interactive::add_force`]).
pub use fem_core::forces::{ExternalForce, ForceKind};
pub use model::{ModelFileError, ModelFormatError, ReducedModel};
pub use neural::NeuralSubspace;
pub use onset::{Augmented, DirectionParts};
pub use reduced::{ElasticPath, ReducedSpace, SERIAL_MAX_ELEMENTS, SpaceBuffers, SpaceParts};
pub use runtime::{
    AnyReducedSimulator, FullRuntime, Handle, Interactive, MAX_POINT_LOAD, MAX_SPRING_STIFFNESS,
    Real, ReducedRuntime, RuntimeError, StepStats, Surface, body_force, body_stiffness,
    check_point_load,
};
pub use simulator::{
    ActiveDent, PRECOND_MAX_AGE, Preconditioning, ReducedEnergy, ReducedSimulator, ReducedState,
    ReducedStepReport,
};
pub use subspace::{LinearSubspace, Subspace};

/// The largest step count [`ReducedSimulator::set_state`] takes: 2⁵³, where the time `step · h`
/// is still an exact multiple of h.
pub const MAX_STATE_STEP: usize = 1 << 53;

/// Errors of the reduced integrators.
#[derive(Debug, thiserror::Error)]
pub enum ReducedError {
    #[error(transparent)]
    Fem(#[from] fem_core::FemError),
    /// The basis does not fit the model.
    #[error("basis has {rows} rows but the model has {free} free DOFs; rebuild the PCA stage")]
    BasisShape { rows: usize, free: usize },
    /// A state vector given from outside does not have the subspace's length.
    #[error("a state of {got} coefficients was given to a subspace of {expected}")]
    StateShape { expected: usize, got: usize },
    /// A state given from outside with a coefficient that is not a finite number.
    #[error("a state was given coefficient {index} = {value}: every coefficient must be finite")]
    StateNotFinite { index: usize, value: f64 },
    /// A state given from outside at a step count past [`MAX_STATE_STEP`].
    #[error(
        "a state was given step {step}: at most {MAX_STATE_STEP} (2⁵³, past which the time \
         step · h is no longer an exact multiple of h)"
    )]
    StateStep { step: usize },
    /// A cubature rule that does not fit the model.
    #[error("cubature rule: {reason}; refit the cubature stage")]
    Cubature { reason: String },
    /// A reduced matrix that must be positive definite is not.
    #[error("the reduced {what} matrix is not positive definite")]
    NotPositiveDefinite { what: &'static str },
    /// A reduced matrix with entries that are not finite: e.g. an element it evaluates is
    /// inverted at this state, where the material (classic Neo-Hookean) has no energy.
    #[error(
        "the reduced {what} matrix has entries that are not finite at this state: a spring so \
         stiff that its terms overflow, or, with classic Neo-Hookean only, an element it \
         evaluates inverted, where that material has no energy (a state given from outside, \
         such as a full-space state projected on the basis, can invert one)"
    )]
    NotFinite { what: &'static str },
    /// The parts of a reduced space do not fit together or the mesh.
    #[error("reduced space: {reason}")]
    Parts { reason: String },
    /// A force or handle on a vertex whose basis rows the space does not hold (or that does not
    /// exist).
    #[error(
        "vertex {vertex} has no basis rows in this model (it holds those of the surface and of the \
         elements it evaluates, as an export keeps by default): read the surface's positions, or \
         export with every vertex's rows (`cargo xtask export --all-rows`, Python's \
         `export_model(..., all_rows=True)`) to reach the others"
    )]
    NoBasisRows { vertex: usize },
    /// A force index past the forces there are.
    #[error("there is no force {index} (there are {count})")]
    NoSuchForce { index: usize, count: usize },
    /// A force that cannot act on this model ([`fem_core::forces::ExternalForce::problem`]).
    #[error("invalid force: {reason}")]
    InvalidForce { reason: String },
    /// Keyframes that are empty, not finite or not in time order.
    #[error("keyframes must be finite [t, x, y, z] rows in time order, at least one")]
    Keyframes,
    /// A model that does not hold together ([`ReducedModel::check`]).
    #[error("invalid model: {reason}")]
    InvalidModel { reason: String },
}
