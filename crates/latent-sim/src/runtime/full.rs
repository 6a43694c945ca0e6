//! Full-space simulation behind the same interaction API: [`FullRuntime`].

use fem_core::Vec3;
use fem_core::forces::ExternalForce;
use fem_core::integrator::{FullSpaceModel, Simulator, StepReport, TimeConfig};
use fem_core::optim::SolverConfig;

use super::handles::{self, Backend, Handles};
use super::{Handle, Interactive, Real, RuntimeError, StepStats, Surface, buffer_length};
use crate::ReducedError;
use crate::model::ReducedModel;

/// fem-core's full-space simulator with the [`Interactive`] API: the reference a program can
/// switch to on the same mesh.
///
/// A clone steps exactly as the original would from where it was made (as
/// [`crate::ReducedRuntime`]'s), its sparse factors copied.
#[derive(Debug, Clone)]
pub struct FullRuntime {
    sim: Simulator,
    surface: Surface,
    surface_u: Vec<f64>,
    /// Gravity's acceleration (the simulator's load is zero while gravity is off).
    gravity: [f64; 3],
    gravity_enabled: bool,
    handles: Handles,
}

impl FullRuntime {
    /// A simulator of `model` (its forces act as given, not as handles), at rest.
    ///
    /// # Errors
    /// Invalid time or solver settings ([`Simulator::new`]).
    pub fn new(
        model: FullSpaceModel,
        time: TimeConfig,
        solver: SolverConfig,
    ) -> Result<Self, RuntimeError> {
        let surface = Surface::new(&model.mesh.surface_triangles(), model.mesh.num_vertices());
        let gravity = model.gravity.into();
        Ok(Self {
            sim: Simulator::new(model, time, solver)?,
            surface_u: vec![0.0; 3 * surface.vertices().len()],
            surface,
            gravity,
            gravity_enabled: true,
            handles: Handles::default(),
        })
    }

    /// The full-space simulator of a trained model's mesh, material, pins, gravity and time
    /// step, with the scene's full-space solver (`[solver]`).
    ///
    /// # Errors
    /// As [`ReducedModel::full_space_model`] and [`FullRuntime::new`].
    pub fn from_model(model: &ReducedModel) -> Result<Self, RuntimeError> {
        let full = model.full_space_model()?;
        Self::new(full, model.time(), SolverConfig::from(&model.full_solver))
    }

    /// One step, with its energies and solver figures.
    ///
    /// # Errors
    /// As [`Simulator::step`].
    pub fn step_report(&mut self) -> Result<StepReport, RuntimeError> {
        Ok(self.sim.step()?)
    }

    /// The displacement of every vertex (3 per vertex).
    pub fn displacement(&self) -> &[f64] {
        &self.sim.state.u
    }

    /// The full-space simulator. Its forces are the handles' (change them through this runtime).
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }
}

impl Backend for FullRuntime {
    fn rest(&self) -> &[Vec3] {
        &self.sim.model.mesh.vertices
    }

    fn tets(&self) -> &[[usize; 4]] {
        &self.sim.model.mesh.tets
    }

    fn pinned(&self) -> &[usize] {
        &self.sim.model.pinned
    }

    fn youngs_modulus(&self) -> f64 {
        self.sim.model.youngs_modulus
    }

    fn surface(&self) -> &Surface {
        &self.surface
    }

    fn displacement(&self, v: usize) -> Result<Vec3, RuntimeError> {
        let u = &self.sim.state.u;
        Ok(Vec3::new(u[3 * v], u[3 * v + 1], u[3 * v + 2]))
    }

    fn surface_displacements(&mut self) -> &[f64] {
        let u = &self.sim.state.u;
        for (out, &v) in self
            .surface_u
            .chunks_exact_mut(3)
            .zip(self.surface.vertices())
        {
            out.copy_from_slice(&u[3 * v..3 * v + 3]);
        }
        &self.surface_u
    }

    fn push_force(&mut self, force: ExternalForce) -> Result<usize, RuntimeError> {
        self.sim.model.forces.push(force);
        self.sim.forces_changed();
        Ok(self.sim.model.forces.len() - 1)
    }

    fn remove_force(&mut self, index: usize) -> Result<(), RuntimeError> {
        let count = self.sim.model.forces.len();
        if index >= count {
            return Err(ReducedError::NoSuchForce { index, count }.into());
        }
        self.sim.model.forces.remove(index);
        self.sim.forces_changed();
        Ok(())
    }

    fn set_keyframes(&mut self, index: usize, keyframes: &[[f64; 4]]) -> Result<(), RuntimeError> {
        let count = self.sim.model.forces.len();
        let force = self
            .sim
            .model
            .forces
            .get_mut(index)
            .ok_or(ReducedError::NoSuchForce { index, count })?;
        force.keyframes.clear();
        force.keyframes.extend_from_slice(keyframes);
        Ok(())
    }

    fn handles(&mut self) -> &mut Handles {
        &mut self.handles
    }

    fn force(&self, index: usize) -> &ExternalForce {
        &self.sim.model.forces[index]
    }

    fn now(&self) -> f64 {
        self.sim.state.time
    }
}

impl Interactive for FullRuntime {
    fn rest_positions(&self) -> &[Vec3] {
        self.rest()
    }

    fn surface(&self) -> &Surface {
        &self.surface
    }

    fn time(&self) -> f64 {
        self.sim.state.time
    }

    fn steps(&self) -> usize {
        self.sim.state.step
    }

    fn step(&mut self) -> Result<StepStats, RuntimeError> {
        let r = self.sim.step()?;
        Ok(StepStats {
            step: r.step,
            time: r.time,
            iterations: r.iterations,
            relative_gradient: r.relative_gradient,
            seconds: r.wall_seconds,
            preconditioner_rebuilt: r.preconditioner_factorised,
            newton_fallback: r.solver_switched,
            beyond_training: None,
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
        self.sim.model.set_gravity(g.into());
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
        self.sim.reset();
    }

    fn positions_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError> {
        buffer_length("positions", self.sim.state.u.len(), out.len())?;
        for ((x, u), rest) in out
            .chunks_exact_mut(3)
            .zip(self.sim.state.u.chunks_exact(3))
            .zip(&self.sim.model.mesh.vertices)
        {
            for c in 0..3 {
                x[c] = rest[c] + u[c];
            }
        }
        Ok(())
    }

    fn surface_positions_f32(&mut self, out: &mut [f32]) -> Result<(), RuntimeError> {
        self.surface_positions_into(out)
    }

    fn surface_velocities_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError> {
        buffer_length("surface", self.surface_u.len(), out.len())?;
        let v = &self.sim.state.v;
        for (o, &vertex) in out.chunks_exact_mut(3).zip(self.surface.vertices()) {
            o.copy_from_slice(&v[3 * vertex..3 * vertex + 3]);
        }
        Ok(())
    }

    fn surface_positions_into<T: Real>(&mut self, out: &mut [T]) -> Result<(), RuntimeError> {
        buffer_length("surface", self.surface_u.len(), out.len())?;
        let (u, rest) = (&self.sim.state.u, &self.sim.model.mesh.vertices);
        for (o, &v) in out.chunks_exact_mut(3).zip(self.surface.vertices()) {
            for c in 0..3 {
                o[c] = T::from_f64(rest[v][c] + u[3 * v + c]);
            }
        }
        Ok(())
    }
}
