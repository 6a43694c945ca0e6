//! What the viewer steps: any of latent-sim's interactive simulators, behind an object-safe
//! trait so that one session can hold reduced and full-space methods side by side.

use fem_core::Vec3;
use latent_sim::{Handle, Interactive, ReducedModel, RuntimeError, StepStats, Surface};

/// [`Interactive`] without its generic read-back, so that simulators of different types fit in
/// one list (`Box<dyn Simulator>`). Every `Interactive + Send` type is one.
pub trait Simulator: Send {
    /// Rest positions, one per vertex.
    fn rest_positions(&self) -> &[Vec3];
    /// The boundary surface.
    fn surface(&self) -> &Surface;
    /// Steps taken and simulated time.
    fn steps(&self) -> usize;
    fn time(&self) -> f64;
    /// One time step ([`Interactive::step`]).
    ///
    /// # Errors
    /// When the solve fails; the state is then the one before the step.
    fn step(&mut self) -> Result<StepStats, RuntimeError>;
    /// [`Interactive::grab`].
    ///
    /// # Errors
    /// As [`Interactive::grab`].
    fn grab(&mut self, vertices: &[usize], stiffness: f64) -> Result<Handle, RuntimeError>;
    /// [`Interactive::grab_near`].
    ///
    /// # Errors
    /// As [`Interactive::grab_near`].
    fn grab_near(
        &mut self,
        point: [f64; 3],
        radius: f64,
        stiffness: f64,
    ) -> Result<Handle, RuntimeError>;
    /// [`Interactive::move_handle`].
    ///
    /// # Errors
    /// As [`Interactive::move_handle`].
    fn move_handle(&mut self, handle: Handle, target: [f64; 3]) -> Result<(), RuntimeError>;
    /// [`Interactive::release`].
    ///
    /// # Errors
    /// As [`Interactive::release`].
    fn release(&mut self, handle: Handle) -> Result<(), RuntimeError>;
    /// [`Interactive::set_gravity`].
    fn set_gravity(&mut self, enabled: bool);
    /// [`Interactive::reset`].
    fn reset(&mut self);
    /// The surface positions as `f32` ([`Interactive::surface_positions_into`]).
    ///
    /// # Errors
    /// [`RuntimeError::BufferLength`].
    fn surface_positions_f32(&mut self, out: &mut [f32]) -> Result<(), RuntimeError>;
}

impl<T: Interactive + Send> Simulator for T {
    fn rest_positions(&self) -> &[Vec3] {
        Interactive::rest_positions(self)
    }
    fn surface(&self) -> &Surface {
        Interactive::surface(self)
    }
    fn steps(&self) -> usize {
        Interactive::steps(self)
    }
    fn time(&self) -> f64 {
        Interactive::time(self)
    }
    fn step(&mut self) -> Result<StepStats, RuntimeError> {
        Interactive::step(self)
    }
    fn grab(&mut self, vertices: &[usize], stiffness: f64) -> Result<Handle, RuntimeError> {
        Interactive::grab(self, vertices, stiffness)
    }
    fn grab_near(
        &mut self,
        point: [f64; 3],
        radius: f64,
        stiffness: f64,
    ) -> Result<Handle, RuntimeError> {
        Interactive::grab_near(self, point, radius, stiffness)
    }
    fn move_handle(&mut self, handle: Handle, target: [f64; 3]) -> Result<(), RuntimeError> {
        Interactive::move_handle(self, handle, target)
    }
    fn release(&mut self, handle: Handle) -> Result<(), RuntimeError> {
        Interactive::release(self, handle)
    }
    fn set_gravity(&mut self, enabled: bool) {
        Interactive::set_gravity(self, enabled);
    }
    fn reset(&mut self) {
        Interactive::reset(self);
    }
    fn surface_positions_f32(&mut self, out: &mut [f32]) -> Result<(), RuntimeError> {
        Interactive::surface_positions_into(self, out)
    }
}

/// A simulator and the name a client selects it by (`neural-cubature`, `full`, …).
pub struct Method {
    pub name: String,
    pub simulator: Box<dyn Simulator>,
}

impl std::fmt::Debug for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Method").field("name", &self.name).finish()
    }
}

impl Method {
    /// `simulator` under `name`.
    pub fn new(name: impl Into<String>, simulator: impl Simulator + 'static) -> Self {
        Self {
            name: name.into(),
            simulator: Box::new(simulator),
        }
    }
}

/// A session's settings: what it shows and the grab defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The scene's name, shown on the page.
    pub scene: String,
    /// Simulated seconds per step: the session steps at this rate in real time.
    pub time_step: f64,
    /// Pinned vertices (mesh indices), marked on the page.
    pub pinned: Vec<usize>,
    /// Grab defaults: radius (m) around the picked point and total spring stiffness (N/m).
    pub radius: f64,
    pub stiffness: f64,
    /// The largest radius and stiffness a client may ask for.
    pub max_radius: f64,
    pub max_stiffness: f64,
    /// Targets farther than this from the mesh's rest centre are refused (m).
    pub max_reach: f64,
    /// The most position frames sent per second.
    pub max_fps: f64,
}

impl Settings {
    /// The settings for `model`'s scene. With L the diagonal of the mesh's bounding box and E
    /// Young's modulus: radius L/20; stiffness 10⁻² E L (several times a 5:1 cantilever's own
    /// tip stiffness, so that the grabbed patch follows the cursor most of the way), both
    /// adjustable up to L and 100×; targets within 10 L of the centre; 120 frames per second
    /// at most.
    pub fn for_model(model: &ReducedModel) -> Self {
        let (lo, hi) = model.mesh.bounding_box();
        let size = (hi - lo).norm().max(f64::MIN_POSITIVE);
        let stiffness = 1e-2 * model.material.youngs_modulus * size;
        Self {
            scene: model.provenance.scene.clone(),
            time_step: model.time_step,
            pinned: model.pinned.clone(),
            radius: size / 20.0,
            stiffness,
            max_radius: size,
            max_stiffness: 100.0 * stiffness,
            max_reach: 10.0 * size,
            max_fps: 120.0,
        }
    }
}
