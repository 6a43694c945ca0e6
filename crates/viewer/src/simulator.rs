//! What the viewer steps: any of latent-sim's interactive simulators, as trait objects
//! (`Box<dyn Interactive + Send>`) so that one session holds reduced and full-space methods
//! side by side.

use latent_sim::{Interactive, ReducedModel};

/// A simulator and the name a client selects it by (`neural-cubature`, `full`, …).
pub struct Method {
    pub name: String,
    pub simulator: Box<dyn Interactive + Send>,
}

impl std::fmt::Debug for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Method").field("name", &self.name).finish()
    }
}

impl Method {
    /// `simulator` under `name`.
    pub fn new(name: impl Into<String>, simulator: impl Interactive + Send + 'static) -> Self {
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
    /// The direction the page draws up (a unit vector): against the scene's gravity, or +y
    /// without gravity, so that a mesh made with z up stands on the page as it stands in the
    /// scene.
    pub up: [f64; 3],
}

/// The unit vector against `gravity`, or +y when there is none (or it is not finite).
fn up_from_gravity(gravity: [f64; 3]) -> [f64; 3] {
    let g = fem_core::Vec3::from(gravity);
    let n = g.norm();
    if n.is_finite() && n > 0.0 {
        // + 0 turns −0 into 0, which a page reads as written (`[-0.0, 1.0, -0.0]` puzzled one).
        (-g / n).map(|c| c + 0.0).into()
    } else {
        crate::protocol::Y_UP
    }
}

impl Settings {
    /// The settings for `model`'s scene. With L the diagonal of the mesh's bounding box, E
    /// Young's modulus and M|g| the body's weight: radius L/20; stiffness 10⁻² E L (several
    /// times a 5:1 cantilever's own tip stiffness, so that the grabbed patch follows the cursor
    /// most of the way), and at least M|g|/(0.2 L), which holds a soft, heavy body's weight
    /// when the spring is stretched by a fifth of its size; both adjustable up to L and 100×;
    /// targets within 10 L of the centre; 120 frames per second at most.
    pub fn for_model(model: &ReducedModel) -> Self {
        let (lo, hi) = model.mesh.bounding_box();
        let size = (hi - lo).norm().max(f64::MIN_POSITIVE);
        let weight = model.mass() * fem_core::Vec3::from(model.gravity).norm();
        let stiffness = (1e-2 * model.material.youngs_modulus * size).max(weight / (0.2 * size));
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
            up: up_from_gravity(model.gravity),
        }
    }
}

#[cfg(test)]
mod tests {
    /// Up is against gravity, written without negative zeros; without gravity, y.
    #[test]
    fn up_is_against_gravity() {
        let up = super::up_from_gravity([0.0, -9.81, 0.0]);
        assert_eq!(up, [0.0, 1.0, 0.0]);
        assert!(up.iter().all(|c| c.is_sign_positive()), "{up:?}");
        assert_eq!(super::up_from_gravity([0.0, 0.0, 2.0]), [0.0, 0.0, -1.0]);
        assert_eq!(super::up_from_gravity([0.0; 3]), crate::protocol::Y_UP);
    }
}
