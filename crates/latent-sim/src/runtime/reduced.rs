//! The runtime of a trained model: [`ReducedRuntime`], built by [`ReducedModel::simulator`].

use fem_core::Vec3;
use fem_core::constraints::FIXED;
use fem_core::forces::ExternalForce;
use fem_core::integrator::FullSpaceModel;
use fem_core::optim::SolverConfig;

use super::handles::{self, Backend, Handles};
use super::{Handle, Interactive, Real, RuntimeError, StepStats, Surface, buffer_length};
use crate::coverage::TrainingPoses;
use crate::model::{ReducedModel, SubspaceParts};
use crate::reduced::PackedRows;
use crate::{
    ActiveDent, Augmented, LinearSubspace, NeuralSubspace, ReducedEnergy, ReducedError,
    ReducedSimulator, ReducedSpace, ReducedState, ReducedStepReport, Subspace,
};

/// The reduced simulator of a model, with its subspace's type.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
pub enum AnyReducedSimulator {
    /// PCA: q = z.
    Linear(ReducedSimulator<LinearSubspace>),
    /// The autoencoder with linear directions beside it.
    Neural(ReducedSimulator<Augmented<NeuralSubspace>>),
}

/// `$body` with `$s` bound to the simulator inside an [`AnyReducedSimulator`].
macro_rules! each {
    ($sim:expr, $s:ident => $body:expr) => {
        match $sim {
            AnyReducedSimulator::Linear($s) => $body,
            AnyReducedSimulator::Neural($s) => $body,
        }
    };
}

impl AnyReducedSimulator {
    pub fn model(&self) -> &FullSpaceModel {
        each!(self, s => &s.model)
    }

    pub fn space(&self) -> &ReducedSpace {
        each!(self, s => &s.space)
    }

    pub fn state(&self) -> &ReducedState {
        each!(self, s => &s.state)
    }

    /// The number of reduced coordinates a step solves for (the autoencoder's latent ones and
    /// the linear directions beside them: [`ReducedModel::latent_dim`](crate::ReducedModel::latent_dim)).
    pub fn latent_dim(&self) -> usize {
        each!(self, s => s.subspace.latent_dim())
    }
}

/// A trained model stepping: the [`Interactive`] API over the reduced simulator, with exactly
/// the solver settings the model holds (those `cargo xtask run` measures).
///
/// A clone steps exactly as the original would from where it was made (its solver's history,
/// factors and handles included): keep one to roll back to (`sim = saved.clone()`), or to try
/// a move ahead. The handles made before the clone act on both; one made on either after it is
/// unknown to the other. A clone costs about the model's size in memory (its mesh, elements
/// and basis rows in use); the factorisation at rest that springs pull through is shared once
/// made ([`Interactive::prepare_grab`] before cloning, for many instances of one model).
#[derive(Debug, Clone)]
pub struct ReducedRuntime {
    sim: AnyReducedSimulator,
    surface: Surface,
    /// The surface vertices' rows of U, packed: reading the surface decodes only these.
    surface_rows: PackedRows,
    surface_u: Vec<f64>,
    /// Gravity's acceleration (the space's load is zero while gravity is off).
    gravity: [f64; 3],
    gravity_enabled: bool,
    handles: Handles,
    /// The training poses' ranges, when the model holds them.
    training: Option<TrainingPoses>,
}

impl ReducedModel {
    /// The runtime of this model, at rest, gravity on, no force.
    ///
    /// # Errors
    /// When the model is inconsistent ([`ReducedModel::check`], its space's or directions'
    /// parts), or a setting is invalid.
    pub fn simulator(&self) -> Result<ReducedRuntime, RuntimeError> {
        ReducedRuntime::new(self)
    }
}

impl ReducedRuntime {
    /// See [`ReducedModel::simulator`].
    pub fn new(model: &ReducedModel) -> Result<Self, RuntimeError> {
        if model.material != model.space.material {
            return Err(ReducedError::InvalidModel {
                reason: format!(
                    "its material ({:?}) is not the one its reduced matrices were computed with \
                     and its subspace trained for ({:?}): export the model again from a scene \
                     with the new material (`cargo xtask export`), or step the full space with \
                     it (`FullRuntime::from_model`)",
                    model.material, model.space.material
                ),
            }
            .into());
        }
        let full = model.full_space_model()?;
        let space = ReducedSpace::from_parts(&full, &model.space, model.cubature.as_ref())?;
        let surface = Surface::new(&model.surface, full.mesh.num_vertices());
        if let Some(&vertex) = surface.vertices().iter().find(|&&v| !space.has_rows(v)) {
            return Err(ReducedError::NoBasisRows { vertex }.into());
        }
        let surface_rows = PackedRows::new(&space, surface.vertices());
        let (time, solver) = (model.time(), SolverConfig::from(&model.solver));
        let k = space.k;
        let mut sim = match &model.subspace {
            SubspaceParts::Linear => AnyReducedSimulator::Linear(ReducedSimulator::new(
                full,
                space,
                LinearSubspace::new(k),
                time,
                solver,
            )?),
            SubspaceParts::Neural {
                autoencoder,
                directions,
            } => {
                let subspace =
                    Augmented::from_parts(NeuralSubspace::new(autoencoder.clone()), directions)?;
                AnyReducedSimulator::Neural(ReducedSimulator::new(
                    full, space, subspace, time, solver,
                )?)
            }
        };
        each!(&mut sim, s => s.preconditioning = model.preconditioning);
        each!(&mut sim, s => s.set_spring_compliance(model.spring_compliance));
        Ok(Self {
            sim,
            surface_u: vec![0.0; 3 * surface.vertices().len()],
            surface,
            surface_rows,
            gravity: model.gravity,
            gravity_enabled: true,
            handles: Handles::default(),
            training: model.training.clone(),
        })
    }

    /// One step, with where its time went.
    ///
    /// # Errors
    /// As [`ReducedSimulator::step`].
    pub fn step_report(&mut self) -> Result<ReducedStepReport, ReducedError> {
        each!(&mut self.sim, s => s.step())
    }

    /// Puts the simulator in the states its subspace gives to the PCA coefficients `q_now` (at
    /// step `step`) and `q_before` ([`ReducedSimulator::set_state`]).
    ///
    /// # Errors
    /// [`ReducedError::StateShape`], [`ReducedError::StateNotFinite`],
    /// [`ReducedError::StateStep`].
    pub fn set_state(
        &mut self,
        step: usize,
        q_now: &[f64],
        q_before: &[f64],
    ) -> Result<(), ReducedError> {
        each!(&mut self.sim, s => s.set_state(step, q_now, q_before))
    }

    /// The energies of the current state ([`ReducedSimulator::energy`]).
    pub fn energy(&mut self) -> ReducedEnergy {
        each!(&mut self.sim, s => s.energy())
    }

    /// The displacement u = Uq of every vertex (3 per vertex) into `out`.
    ///
    /// # Errors
    /// [`RuntimeError::BufferLength`]; [`ReducedError::NoBasisRows`] when the model keeps only
    /// the rows in use.
    pub fn displacement_into(&self, out: &mut [f64]) -> Result<(), RuntimeError> {
        let space = self.sim.space();
        buffer_length("displacement", self.sim.model().num_full(), out.len())?;
        if let Some(vertex) = (0..out.len() / 3).find(|&v| !space.has_rows(v)) {
            return Err(ReducedError::NoBasisRows { vertex }.into());
        }
        each!(&self.sim, s => s.displacement_into(out));
        Ok(())
    }

    /// The PCA coefficients q of the current state.
    pub fn coefficients(&self) -> &[f64] {
        &self.sim.state().q
    }

    /// How far the current pose lies beyond the training poses' ranges, relative to its size
    /// ([`StepStats::beyond_training`]); None when the model holds no ranges.
    pub fn beyond_training(&self) -> Option<f64> {
        self.training
            .as_ref()
            .map(|t| t.distance(&self.sim.state().q))
    }

    /// The reduced simulator. Its forces are the handles' (change them through this runtime).
    pub fn simulator(&self) -> &AnyReducedSimulator {
        &self.sim
    }

    /// The reduced simulator, mutable: for diagnostics that evaluate its objective.
    pub fn simulator_mut(&mut self) -> &mut AnyReducedSimulator {
        &mut self.sim
    }
}

/// Component `c` of vertex `v`'s displacement from the dents (`index`: the model's DOF
/// numbering; a pinned component has none).
fn dent_at(dents: &[ActiveDent<'_>], index: &[usize], v: usize, c: usize) -> f64 {
    match index[3 * v + c] {
        FIXED => 0.0,
        r => dents.iter().map(|d| d.at(r)).sum(),
    }
}

impl Backend for ReducedRuntime {
    fn rest(&self) -> &[Vec3] {
        &self.sim.model().mesh.vertices
    }

    fn tets(&self) -> &[[usize; 4]] {
        &self.sim.model().mesh.tets
    }

    fn pinned(&self) -> &[usize] {
        &self.sim.model().pinned
    }

    fn youngs_modulus(&self) -> f64 {
        self.sim.model().youngs_modulus
    }

    fn surface(&self) -> &Surface {
        &self.surface
    }

    fn displacement(&self, v: usize) -> Result<Vec3, RuntimeError> {
        let space = self.sim.space();
        let rows = space
            .vertex_rows(v)
            .ok_or(ReducedError::NoBasisRows { vertex: v })?;
        let (q, dents) = each!(&self.sim, s => s.dents());
        let k = space.k;
        let index = &self.sim.model().dofs.index;
        let row = |c: usize| -> f64 {
            dent_at(&dents, index, v, c)
                + rows[c * k..(c + 1) * k]
                    .iter()
                    .zip(&q)
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
        };
        Ok(Vec3::new(row(0), row(1), row(2)))
    }

    fn surface_displacements(&mut self) -> &[f64] {
        let (q, dents) = each!(&self.sim, s => s.dents());
        self.surface_rows.apply(&q, &mut self.surface_u);
        if !dents.is_empty() {
            let index = &self.sim.model().dofs.index;
            for (&v, u) in self
                .surface
                .vertices()
                .iter()
                .zip(self.surface_u.chunks_exact_mut(3))
            {
                for (c, uc) in u.iter_mut().enumerate() {
                    *uc += dent_at(&dents, index, v, c);
                }
            }
        }
        &self.surface_u
    }

    fn push_force(&mut self, force: ExternalForce) -> Result<usize, RuntimeError> {
        Ok(each!(&mut self.sim, s => s.add_force(force))?)
    }

    fn remove_force(&mut self, index: usize) -> Result<(), RuntimeError> {
        each!(&mut self.sim, s => s.remove_force(index))?;
        Ok(())
    }

    fn set_keyframes(&mut self, index: usize, keyframes: &[[f64; 4]]) -> Result<(), RuntimeError> {
        Ok(each!(&mut self.sim, s => s.set_force_keyframes(index, keyframes))?)
    }

    fn handles(&mut self) -> &mut Handles {
        &mut self.handles
    }

    fn force(&self, index: usize) -> &ExternalForce {
        &self.sim.model().forces[index]
    }

    fn now(&self) -> f64 {
        self.sim.state().time
    }
}

impl Interactive for ReducedRuntime {
    fn rest_positions(&self) -> &[Vec3] {
        self.rest()
    }

    fn surface(&self) -> &Surface {
        &self.surface
    }

    fn time(&self) -> f64 {
        self.sim.state().time
    }

    fn steps(&self) -> usize {
        self.sim.state().step
    }

    fn step(&mut self) -> Result<StepStats, RuntimeError> {
        let r = self.step_report()?;
        Ok(StepStats {
            step: r.step,
            time: r.time,
            iterations: r.iterations,
            relative_gradient: r.relative_gradient,
            seconds: r.wall_seconds,
            preconditioner_rebuilt: r.preconditioner_rebuilt,
            newton_fallback: r.newton_fallback,
            beyond_training: self.beyond_training(),
        })
    }

    fn grab(&mut self, vertices: &[usize], stiffness: f64) -> Result<Handle, RuntimeError> {
        handles::grab(self, vertices, stiffness)
    }

    fn grab_near(
        &mut self,
        point: [f64; 3],
        radius: f64,
        stiffness: f64,
    ) -> Result<Handle, RuntimeError> {
        handles::grab_near(self, point, radius, stiffness)
    }

    fn move_handle(&mut self, handle: Handle, target: [f64; 3]) -> Result<(), RuntimeError> {
        handles::move_handle(self, handle, target)
    }

    fn release(&mut self, handle: Handle) -> Result<(), RuntimeError> {
        handles::release(self, handle)
    }

    fn handle_target(&mut self, handle: Handle) -> Result<[f64; 3], RuntimeError> {
        handles::target(self, handle)
    }

    fn set_load(&mut self, handle: Handle, force: [f64; 3]) -> Result<(), RuntimeError> {
        handles::set_load(self, handle, force)
    }

    fn handles(&mut self) -> Vec<Handle> {
        handles::list(self)
    }

    fn add_force(&mut self, force: ExternalForce) -> Result<Handle, RuntimeError> {
        handles::add_force(self, force)
    }

    fn set_gravity(&mut self, enabled: bool) {
        self.gravity_enabled = enabled;
        let g = if enabled { self.gravity } else { [0.0; 3] };
        each!(&mut self.sim, s => s.space.set_gravity(g.into()));
    }

    fn gravity(&self) -> bool {
        self.gravity_enabled
    }

    fn set_gravity_acceleration(&mut self, g: [f64; 3]) -> Result<(), RuntimeError> {
        super::finite("gravity acceleration", g)?;
        self.gravity = g;
        self.set_gravity(self.gravity_enabled);
        Ok(())
    }

    fn gravity_acceleration(&self) -> [f64; 3] {
        self.gravity
    }

    fn reset(&mut self) {
        each!(&mut self.sim, s => s.reset());
    }

    fn prepare_grab(&mut self) {
        each!(&mut self.sim, s => s.prepare_spring_compliance());
    }

    fn positions_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError> {
        self.displacement_into(out)?;
        for (x, rest) in out.chunks_exact_mut(3).zip(self.rest()) {
            for c in 0..3 {
                x[c] += rest[c];
            }
        }
        Ok(())
    }

    fn surface_positions_f32(&mut self, out: &mut [f32]) -> Result<(), RuntimeError> {
        self.surface_positions_into(out)
    }

    fn surface_velocities_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError> {
        buffer_length("surface", self.surface_u.len(), out.len())?;
        self.surface_rows.apply(&self.sim.state().qdot, out);
        Ok(())
    }

    fn surface_positions_into<T: Real>(&mut self, out: &mut [T]) -> Result<(), RuntimeError> {
        buffer_length("surface", self.surface_u.len(), out.len())?;
        self.surface_displacements();
        let rest = &self.sim.model().mesh.vertices;
        for ((o, u), &v) in out
            .chunks_exact_mut(3)
            .zip(self.surface_u.chunks_exact(3))
            .zip(self.surface.vertices())
        {
            for c in 0..3 {
                o[c] = T::from_f64(rest[v][c] + u[c]);
            }
        }
        Ok(())
    }
}
