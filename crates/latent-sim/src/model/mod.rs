//! The trained model as one self-contained value, the pipeline's last product (DESIGN §11):
//! everything stepping and display need — rest mesh, surface, pins, material, time step,
//! gravity, the basis rows in use with the reduced matrices of the whole basis, the decoder,
//! the cubature rule, the linear directions, the solver settings, the ranges of the training
//! poses each step is measured against ([`crate::coverage`]) — and where it came from.
//!
//! [`ReducedModel::save`] and [`ReducedModel::load`] write and read it ([`mod@file`] has the layout
//! and the typed errors of a damaged file); [`ReducedModel::simulator`] steps it with exactly the
//! settings `cargo xtask run` measures, and [`crate::FullRuntime::from_model`] steps the same
//! mesh in full space.

pub mod file;

use cubature::CubatureRule;
use fem_core::TetMesh;
use fem_core::integrator::{FullSpaceModel, TimeConfig};
use fem_core::material::MaterialConfig;
use fem_core::optim::{LbfgsPreconditioner, SolverConfig, SolverMethod};
use nn::Autoencoder;
use pca::PcaBasis;

use crate::coverage::TrainingPoses;
use crate::{
    Augmented, DirectionParts, NeuralSubspace, Preconditioning, ReducedError, ReducedSpace,
    SpaceParts,
};

pub use file::{FORMAT_VERSION, ModelFileError, ModelFormatError};

/// A trained reduced model: see the [module documentation](self).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReducedModel {
    pub provenance: Provenance,
    /// Rest positions and tets (positively oriented).
    pub mesh: TetMesh,
    /// Boundary triangles, outward, indices into the mesh's vertices.
    pub surface: Vec<[usize; 3]>,
    /// Pinned vertices, increasing.
    pub pinned: Vec<usize>,
    /// The material, the one the reduced matrices were computed with and the basis, decoder
    /// and rule made for ([`SpaceParts::material`]): [`ReducedModel::simulator`] refuses a model
    /// whose material was changed since (export the model again from a scene with the new
    /// one); [`crate::FullRuntime::from_model`] steps the full space with it as it is.
    pub material: MaterialConfig,
    /// Gravitational acceleration (m/s²): the reduced gravity load follows it (a program may
    /// also turn it at run time, [`crate::Interactive::set_gravity_acceleration`]). A direction
    /// the training schedules did not fall along moves the body where the subspace may not
    /// reach.
    pub gravity: [f64; 3],
    /// Time step h (s) and whether each step is a static solve.
    pub time_step: f64,
    pub quasi_static: bool,
    /// Each reduced step's solve, as `cargo xtask run` measures it (`[reduced]` over `[solver]`).
    pub solver: SolverSettings,
    pub preconditioning: Preconditioning,
    /// Whether springs pull through the patch compliance the basis lacks
    /// ([`crate::ReducedSimulator::set_spring_compliance`]; `[reduced] spring_compliance`).
    pub spring_compliance: bool,
    /// The scene's full-space `[solver]`, for [`crate::FullRuntime::from_model`].
    pub full_solver: SolverSettings,
    /// Basis rows of the vertices in use and the reduced matrices of the whole basis.
    pub space: SpaceParts,
    /// The elements the elastic energy is evaluated on (None: every element).
    pub cubature: Option<CubatureRule>,
    /// How latent coordinates map to the PCA coefficients.
    pub subspace: SubspaceParts,
    /// The ranges of the training snapshots' PCA coefficients, which the runtime measures each
    /// step's pose against ([`crate::StepStats::beyond_training`]); None for a model made
    /// without them.
    pub training: Option<TrainingPoses>,
}

/// The map from latent coordinates z to PCA coefficients q.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[allow(clippy::large_enum_variant)] // one per model
pub enum SubspaceParts {
    /// q = z (the PCA methods).
    Linear,
    /// q = decode(z) + V w (the neural methods): the autoencoder (its encoder gives the rest
    /// state and [`crate::ReducedRuntime::set_state`]'s latent point) and the linear directions
    /// V beside it.
    Neural {
        autoencoder: Autoencoder,
        directions: DirectionParts,
    },
}

/// Where a model came from.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Provenance {
    /// The version of the project that wrote it.
    pub project_version: String,
    pub scene: String,
    /// The pipeline's name of the method (`neural-cubature`, `pca`, …).
    pub method: String,
    /// The cache keys of the stages it was made from.
    pub stage_keys: Vec<StageKey>,
    /// The errors measured while making it.
    pub errors: Vec<MeasuredError>,
}

/// A stage's cache key.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct StageKey {
    pub stage: String,
    pub key: u64,
}

/// An error measured by the pipeline.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeasuredError {
    /// What was measured, and in which unit.
    pub name: String,
    /// On held-out data (a test trajectory) rather than the training snapshots.
    pub held_out: bool,
    pub value: f64,
}

/// [`SolverConfig`] as the model file stores it: every field always written (the config's
/// serialised form leaves a default preconditioner out, which a format without field names
/// cannot tell).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverSettings {
    pub method: SolverMethod,
    pub tolerance: f64,
    pub max_iterations: usize,
    pub lbfgs_memory: usize,
    pub preconditioner: LbfgsPreconditioner,
}

impl From<&SolverConfig> for SolverSettings {
    fn from(c: &SolverConfig) -> Self {
        let SolverConfig {
            method,
            tolerance,
            max_iterations,
            lbfgs_memory,
            preconditioner,
        } = c.clone();
        Self {
            method,
            tolerance,
            max_iterations,
            lbfgs_memory,
            preconditioner,
        }
    }
}

impl From<&SolverSettings> for SolverConfig {
    fn from(s: &SolverSettings) -> Self {
        SolverConfig {
            method: s.method,
            tolerance: s.tolerance,
            max_iterations: s.max_iterations,
            lbfgs_memory: s.lbfgs_memory,
            preconditioner: s.preconditioner,
        }
    }
}

/// Which basis rows a model keeps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Rows {
    /// The surface's (display, grabbing) and the evaluated elements' (stepping): the default.
    #[default]
    Used,
    /// Every vertex's, so that the whole displacement can be read back (positions, frames,
    /// errors over the mesh) and interior vertices grabbed.
    All,
}

/// The subspace a model is built with.
#[derive(Debug, Clone, Copy)]
pub enum SubspaceSource<'a> {
    Linear,
    /// The autoencoder with up to `onset_directions` gravity-onset directions and the columns of
    /// `complement` (k × c, column-major) beside it ([`Augmented::with_directions`]).
    Neural {
        autoencoder: &'a Autoencoder,
        onset_directions: usize,
        complement: &'a [f64],
    },
}

/// What a model is built from: the pipeline's stage products and settings.
#[derive(Debug, Clone)]
pub struct ModelSource<'a> {
    /// The full-space model (its forces are left out of the file: they are data a program
    /// adds, [`crate::Interactive::add_force`]).
    pub model: &'a FullSpaceModel,
    pub material: &'a MaterialConfig,
    pub time: &'a TimeConfig,
    pub basis: &'a PcaBasis,
    pub cubature: Option<&'a CubatureRule>,
    pub subspace: SubspaceSource<'a>,
    pub solver: SolverConfig,
    pub preconditioning: Preconditioning,
    pub spring_compliance: bool,
    pub full_solver: SolverConfig,
    pub rows: Rows,
    pub provenance: Provenance,
    /// The ranges of the training snapshots' coefficients on `basis`, when known.
    pub training: Option<TrainingPoses>,
}

impl ReducedModel {
    /// The body's mass (kg): the density times the rest volume of the mesh's tets.
    pub fn mass(&self) -> f64 {
        self.material.density * self.mesh.volume()
    }

    /// Builds the model: the reduced space of the basis and rule, and the linear directions of
    /// a neural subspace, as the runtime will step them.
    ///
    /// # Errors
    /// When the basis or rule does not fit the model, or a reduced matrix cannot be factorised
    /// (see [`ReducedSpace::new`], [`Augmented::with_directions`]).
    pub fn build(source: ModelSource<'_>) -> Result<Self, ReducedError> {
        let ModelSource {
            model,
            material,
            time,
            basis,
            cubature,
            subspace,
            solver,
            preconditioning,
            spring_compliance,
            full_solver,
            rows,
            provenance,
            training,
        } = source;
        let space = ReducedSpace::new(model, basis, cubature)?;
        if let Some(t) = &training {
            t.check(space.k)
                .map_err(|reason| ReducedError::InvalidModel { reason })?;
        }
        let subspace = match subspace {
            SubspaceSource::Linear => SubspaceParts::Linear,
            SubspaceSource::Neural {
                autoencoder,
                onset_directions,
                complement,
            } => {
                let augmented = Augmented::with_directions(
                    NeuralSubspace::new(autoencoder.clone()),
                    &space,
                    time,
                    onset_directions,
                    complement,
                )?;
                SubspaceParts::Neural {
                    autoencoder: autoencoder.clone(),
                    directions: augmented.parts(),
                }
            }
        };
        let keep: Vec<usize> = match rows {
            Rows::Used => model.mesh.surface_vertices(),
            Rows::All => (0..model.mesh.num_vertices()).collect(),
        };
        Ok(Self {
            provenance,
            mesh: model.mesh.clone(),
            surface: model.mesh.surface_triangles(),
            pinned: model.pinned.clone(),
            material: material.clone(),
            gravity: model.gravity.into(),
            time_step: time.step,
            quasi_static: time.quasi_static,
            solver: SolverSettings::from(&solver),
            preconditioning,
            spring_compliance,
            full_solver: SolverSettings::from(&full_solver),
            space: space.parts(&keep, material),
            cubature: cubature.cloned(),
            subspace,
            training,
        })
    }

    /// The full-space model of the mesh, without forces.
    ///
    /// # Errors
    /// [`ReducedError::InvalidModel`] when the model is inconsistent ([`Self::check`]).
    pub fn full_space_model(&self) -> Result<FullSpaceModel, ReducedError> {
        self.check()
            .map_err(|reason| ReducedError::InvalidModel { reason })?;
        Ok(FullSpaceModel::new(
            self.mesh.clone(),
            &self.material,
            self.pinned.clone(),
            self.gravity.into(),
            Vec::new(),
        )?)
    }

    /// The time settings of a simulation of the model (open-ended: as many frames as asked).
    pub fn time(&self) -> TimeConfig {
        TimeConfig {
            step: self.time_step,
            frames: usize::MAX,
            quasi_static: self.quasi_static,
        }
    }

    /// The number of reduced coordinates a step solves for: for a neural model the
    /// autoencoder's latent coordinates *and* the linear directions beside them (so at least
    /// the `d` the `train` stage chose), for a PCA model the basis's k.
    pub fn latent_dim(&self) -> usize {
        match &self.subspace {
            SubspaceParts::Linear => self.space.k,
            SubspaceParts::Neural {
                autoencoder,
                directions,
            } => autoencoder.latent_dim() + directions.a_norms.len(),
        }
    }

    /// What the simulator relies on, beyond what decoding checked: indices in range, shapes
    /// that fit, finite values, valid settings. (The reduced space and directions check their
    /// own parts when built.)
    ///
    /// # Errors
    /// What is wrong, in words.
    pub fn check(&self) -> Result<(), String> {
        let nv = self.mesh.num_vertices();
        let nt = self.mesh.num_tets();
        if nt == 0 {
            return Err("the mesh has no tetrahedra".into());
        }
        if let Some(v) = self
            .mesh
            .vertices
            .iter()
            .position(|x| !x.iter().all(|c| c.is_finite()))
        {
            return Err(format!("vertex {v} is not finite"));
        }
        if let Some(t) = self
            .mesh
            .tets
            .iter()
            .position(|t| t.iter().any(|&v| v >= nv))
        {
            return Err(format!("tet {t} uses a vertex past the mesh's {nv}"));
        }
        // The pipeline validated the mesh: every tet positively oriented, none degenerate.
        let oriented = |t: usize| self.mesh.signed_volume(t) > 0.0;
        if let Some(t) = (0..nt).find(|&t| !oriented(t)) {
            return Err(format!("tet {t} is inverted or degenerate"));
        }
        if self.surface.iter().flatten().any(|&v| v >= nv) {
            return Err(format!(
                "a surface triangle uses a vertex past the mesh's {nv}"
            ));
        }
        if let Some(w) = self.pinned.windows(2).find(|w| w[0] >= w[1]) {
            return Err(format!(
                "pinned vertices must increase, found {} before {}",
                w[0], w[1]
            ));
        }
        if self.pinned.last().is_some_and(|&v| v >= nv) {
            return Err(format!("a pinned vertex is past the mesh's {nv}"));
        }
        if !self.gravity.iter().all(|g| g.is_finite()) {
            return Err("gravity is not finite".into());
        }
        let mut errors = Vec::new();
        self.material.check(&mut errors);
        self.time().check(&mut errors);
        SolverConfig::from(&self.solver).check(&mut errors);
        SolverConfig::from(&self.full_solver).check(&mut errors);
        if let Err(e) = fem_core::FemError::collect(errors) {
            return Err(e.to_string());
        }
        if let Some(rule) = &self.cubature {
            rule.check_elements(nt).map_err(|e| e.to_string())?;
        }
        if let Some(t) = &self.training {
            t.check(self.space.k)?;
        }
        if let SubspaceParts::Neural { autoencoder, .. } = &self.subspace
            && autoencoder.input_dim() != self.space.k
        {
            return Err(format!(
                "the autoencoder takes {} coefficients, the basis has {}",
                autoencoder.input_dim(),
                self.space.k
            ));
        }
        Ok(())
    }
}
