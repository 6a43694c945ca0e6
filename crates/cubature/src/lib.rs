//! Optimized cubature (An, Kim & James 2008): a small weighted element set whose reduced forces
//! match the full mesh's over training poses.
//!
//! A subspace maps reduced coordinates to PCA coefficients q (linear: q = z; neural: q = decode(z),
//! Jacobian J = ∂q/∂z) and q to displacements u = Uq on the free DOFs. The reduced elastic force
//! of element e at training pose i is
//!
//! g_{e,i} = J_iᵀ U_eᵀ f_e(U q_i),   f_e = ∂V_e/∂u_e,
//!
//! and the mesh's is b_i = Σ_e g_{e,i}. Cubature looks for a small set S and weights w ≥ 0 with
//!
//! Σ_{e∈S} w_e g_{e,i} ≈ b_i   for every training pose i,
//!
//! so that at run time V(u) ≈ Σ_{e∈S} w_e V_e(u) costs |S| element evaluations instead of m.
//! Each pose's rows are divided by ‖b_i‖ so that large and small deformations count equally.
//! Stacking poses gives a tall system A w ≈ b with A = [g_{e,i}] of size (P·d) × m.
//!
//! - [`TrainingMatrix::build`] evaluates A in parallel over elements (module [`training`]).
//! - [`fit`] runs the greedy selection with Lawson–Hanson NNLS (modules [`greedy`] and
//!   [`nnls`](mod@nnls)), recording the relative error against |S|.
//! - [`CubatureRule::evaluate`] measures a rule on held-out poses built the same way, and
//!   [`HeldOutForces`] gives the same figure from the rule's columns alone (the pipeline's
//!   error on the held-out test, without a matrix of every element for it).
//!
//! ```
//! use cubature::{CubatureConfig, Poses, TrainingMatrix, fit};
//! use faer::Mat;
//! use fem_core::constraints::{Axis, Side, VertexSelection};
//! use fem_core::integrator::FullSpaceModel;
//! use fem_core::material::MaterialConfig;
//! use fem_core::mesh::generate::{BoxSpec, box_mesh};
//!
//! // A cantilever beam of 192 tets pinned at x = 0.
//! let mesh = box_mesh(&BoxSpec { size: [1.0, 0.25, 0.25], cells: [8, 2, 2], ..Default::default() })?;
//! let pinned = VertexSelection::plane(Axis::X, Side::Min, None).select(&mesh, "pin[0]")?;
//! let model = FullSpaceModel::new(mesh, &MaterialConfig::default(), pinned, [0.0; 3].into(), vec![])?;
//!
//! // A two-column basis on the free DOFs: bending in y and in z (u ∝ x²).
//! let nf = model.dofs.num_free();
//! let mut basis = vec![0.0; 2 * nf];
//! for (r, &dof) in model.dofs.free.iter().enumerate() {
//!     let x = model.mesh.vertices[dof / 3][0];
//!     match dof % 3 { 1 => basis[r] = x * x, 2 => basis[nf + r] = x * x, _ => {} }
//! }
//! // Twenty poses, bending up to 0.2 at the tip in both directions.
//! let q = Mat::from_fn(2, 20, |j, i| 0.2 * ((i + 1) as f64 * (1.3 + j as f64)).sin());
//!
//! let config = CubatureConfig { tolerance: 0.05, ..Default::default() };
//! let data = TrainingMatrix::build(&model, &basis, 2, Poses::linear(q.as_ref()), &config)?;
//! let rule = fit(&data, &config)?;
//! assert!(rule.tolerance_met && rule.training_error <= 0.05);
//! assert!(rule.len() < 20, "{} of 192 elements", rule.len());
//! assert!((rule.evaluate(&data)? - rule.training_error).abs() < 1e-12);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod config;
pub mod error;
pub mod greedy;
pub mod nnls;
pub mod rule;
pub mod training;

pub use config::CubatureConfig;
pub use error::CubatureError;
pub use greedy::{FitProgress, fit, fit_with_progress};
pub use nnls::{NnlsParams, NnlsSolution, nnls, nnls_with};
pub use rule::CubatureRule;
pub use training::{HeldOutForces, Poses, TrainingMatrix, kept_poses};
