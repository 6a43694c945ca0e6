//! The full-space problem that does not change during a simulation: mesh, elements, material,
//! mass, constrained DOFs, gravity and external forces, with its elastic and external energies.

use crate::assembly::{self, AssemblyBuffers, ElementSet};
use crate::constraints::DofMap;
use crate::element::Elements;
use crate::forces::ExternalForce;
use crate::mass::MassMatrix;
use crate::material::{AnyMaterial, MaterialConfig};
use crate::{FemError, TetMesh, Vec3, with_material};

/// Everything about the physical problem that does not change during a simulation.
#[derive(Debug, Clone)]
pub struct FullSpaceModel {
    pub mesh: TetMesh,
    pub elements: Elements,
    pub material: AnyMaterial,
    pub youngs_modulus: f64,
    pub mass: MassMatrix,
    pub dofs: DofMap,
    /// Pinned vertices, sorted.
    pub pinned: Vec<usize>,
    pub gravity: Vec3,
    /// Gravity load M g as a full vector.
    pub gravity_load: Vec<f64>,
    pub forces: Vec<ExternalForce>,
    /// E · total rest volume: the size of the terms that cancel in the elastic energy.
    pub energy_scale: f64,
}

impl FullSpaceModel {
    pub fn new(
        mesh: TetMesh,
        material: &MaterialConfig,
        pinned: Vec<usize>,
        gravity: Vec3,
        forces: Vec<ExternalForce>,
    ) -> Result<Self, FemError> {
        material.validate()?;
        // Sorted and each once, as the field says (a lookup by binary search relies on it).
        let mut pinned = pinned;
        pinned.sort_unstable();
        pinned.dedup();
        if !gravity.iter().all(|g| g.is_finite()) {
            return Err(FemError::InvalidConfig {
                field: "gravity.acceleration".into(),
                reason: "must be finite".into(),
            });
        }
        // What a mesh file and a scene are checked for on reading; a model built in code may
        // not have been.
        let n = mesh.num_vertices();
        let invalid =
            |field: String, reason: String| Err(FemError::InvalidConfig { field, reason });
        if let Some(t) = mesh.tets.iter().position(|t| t.iter().any(|&v| v >= n)) {
            return invalid(
                "mesh.tets".into(),
                format!("tet {t} names a vertex past the mesh's {n} vertices"),
            );
        }
        if let Some(&v) = pinned.last().filter(|&&v| v >= n) {
            return invalid(
                "pin".into(),
                format!("vertex {v} is past the mesh's {n} vertices (counted from 0)"),
            );
        }
        for (i, f) in forces.iter().enumerate() {
            if let Some(reason) = f.problem(n) {
                return invalid(format!("force[{i}]"), reason);
            }
        }
        let elements = Elements::new(&mesh);
        let mass = MassMatrix::new(
            &elements,
            mesh.num_vertices(),
            material.density,
            material.mass,
        );
        let dofs = DofMap::new(&mesh, &pinned);
        let energy_scale = material.youngs_modulus * elements.volume.iter().sum::<f64>();
        Ok(Self {
            energy_scale,
            elements,
            material: material.build(),
            youngs_modulus: material.youngs_modulus,
            mass,
            dofs,
            pinned,
            gravity: Vec3::zeros(),
            gravity_load: vec![0.0; 3 * mesh.num_vertices()],
            forces,
            mesh,
        })
        .map(|mut model| {
            model.set_gravity(gravity);
            model
        })
    }

    pub fn num_full(&self) -> usize {
        3 * self.mesh.num_vertices()
    }

    /// Sets gravity's acceleration and the nodal load it makes (the lumped masses times it).
    pub fn set_gravity(&mut self, gravity: Vec3) {
        for (v, &m) in self.mass.lumped.iter().enumerate() {
            for c in 0..3 {
                self.gravity_load[3 * v + c] = m * gravity[c];
            }
        }
        self.gravity = gravity;
    }

    /// Scales gravity, its acceleration and the nodal load it makes, by `factor` (a schedule
    /// family's `gravity_scale`).
    pub fn scale_gravity(&mut self, factor: f64) {
        for g in self.gravity_load.iter_mut() {
            *g *= factor;
        }
        self.gravity *= factor;
    }

    /// Elastic energy V(u) over all elements.
    pub fn elastic_energy(&self, u: &[f64], buf: &mut AssemblyBuffers) -> f64 {
        with_material!(&self.material, |m| assembly::energy(
            m,
            &self.elements,
            ElementSet::All,
            u,
            buf
        ))
    }

    /// Potential energy of the external forces at time `t`: Φ(u, t) − f_gᵀu.
    pub fn external_energy(&self, u: &[f64], t: f64) -> f64 {
        let mut e = -dot(&self.gravity_load, u);
        for f in &self.forces {
            e += f.accumulate(t, u, None, None);
        }
        e
    }

    /// A force scale below which gradients count as zero: 1e-8 · E · L² (L the bounding-box
    /// diagonal), the force that would move the body by about 1e-8 L. A body at rest with no load
    /// converges at once, and one settling towards rest stops once its forces are within the
    /// round-off of the stress evaluation (about ε·E·L² summed over elements, which a relative
    /// tolerance of 1e-6 on a smaller floor could not reach: seen on a released cube at 1e-8 m
    /// from rest, Newton stalling at a relative gradient of 3.6e-6).
    pub(crate) fn force_floor(&self) -> f64 {
        let (lo, hi) = self.mesh.bounding_box();
        1e-8 * self.youngs_modulus * (hi - lo).norm_squared()
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
