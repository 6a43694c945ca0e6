//! Full-space hyperelastic finite elements on linear tetrahedra.
//!
//! `fem-core` owns everything the reduced methods stand on: tetrahedral meshes and their
//! readers/writers, hyperelastic materials with exact derivatives, per-element kinematics,
//! mass matrices, pinned-vertex constraints, external forces with time schedules, assembly of
//! energy / gradient / projected Hessian over a *weighted element set* (the full mesh and a
//! cubature rule share one code path), and implicit Euler posed as an energy minimisation,
//! solved by Newton (sparse Cholesky with symbolic reuse) or preconditioned L-BFGS.
//!
//! ```
//! use fem_core::mesh::generate::{box_mesh, BoxSpec};
//! use fem_core::material::{MaterialConfig, MaterialModel};
//!
//! let mesh = box_mesh(&BoxSpec { size: [1.0, 0.1, 0.1], cells: [10, 1, 1], ..Default::default() }).unwrap();
//! assert_eq!(mesh.num_vertices(), 11 * 2 * 2);
//! let material = MaterialConfig { model: MaterialModel::StableNeoHookean, ..Default::default() };
//! assert!(material.validate().is_ok());
//! ```

pub mod assembly;
pub mod constraints;
pub mod element;
pub mod error;
pub mod exact;
pub mod forces;
pub mod integrator;
pub mod io;
pub mod mass;
pub mod material;
pub mod mesh;
pub mod optim;
pub mod snapshots;
pub mod sparse;
pub mod sparse_cholesky;
pub mod stability;
pub mod step_norm;

/// The seeded generator of the training schedules, re-exported so `fem_core::rng::SplitMix64`
/// names the one the schedules are drawn with.
pub use rng;

pub use error::{FemError, MeshError, four_digits};
pub use mesh::TetMesh;

/// 3-vector of `f64`, the coordinate type used throughout.
pub type Vec3 = nalgebra::Vector3<f64>;
/// 3×3 matrix of `f64` (deformation gradients, stresses).
pub type Mat3 = nalgebra::Matrix3<f64>;
