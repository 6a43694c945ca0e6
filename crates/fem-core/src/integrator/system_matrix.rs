//! The free-DOF system matrix of a step (projected or exact Hessian, plus M/h² and the springs'
//! stiffness): its pattern, values and factor, built once per mesh and refactorised with a
//! growing diagonal shift when only semidefinite; and that factor as L-BFGS's preconditioner.

use super::FullSpaceModel;
use crate::material::signed_svd;
use crate::optim::Preconditioner;
use crate::sparse::{HessianPattern, NO_SLOT};
use crate::sparse_cholesky::SparseCholesky;
use crate::{FemError, Mat3, Vec3};

/// Pattern, symbolic factorisation and value buffers of the free-DOF Hessian, built once.
#[derive(Clone)]
pub(crate) struct NewtonParts {
    pub(crate) pattern: HessianPattern,
    /// The factor Newton directions solve with (and that preconditioners are swapped out of).
    pub(crate) chol: SparseCholesky,
    pub(crate) values: Vec<f64>,
    mass_slots: Vec<u32>,
}

impl std::fmt::Debug for NewtonParts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NewtonParts")
            .field("nnz", &self.pattern.nnz())
            .finish()
    }
}

impl NewtonParts {
    pub(crate) fn new(model: &FullSpaceModel) -> Result<Self, FemError> {
        let pattern = HessianPattern::new(&model.elements.tets, &model.dofs);
        let chol = SparseCholesky::analyse(&pattern)?;
        let mass_slots = model
            .mass
            .consistent
            .as_ref()
            .map(|c| pattern.vertex_csr_slots(c, &model.dofs))
            .unwrap_or_default();
        Ok(Self {
            values: vec![0.0; pattern.nnz()],
            pattern,
            chol,
            mass_slots,
        })
    }

    /// values += s·M on the free DOFs.
    pub(crate) fn add_mass(&mut self, model: &FullSpaceModel, s: f64) {
        match &model.mass.consistent {
            None => {
                for (j, &d) in model.dofs.free.iter().enumerate() {
                    self.values[self.pattern.diag[j]] += s * model.mass.lumped[d / 3];
                }
            }
            Some(csr) => {
                for (k, &m) in csr.val.iter().enumerate() {
                    for c in 0..3 {
                        let slot = self.mass_slots[3 * k + c];
                        if slot != NO_SLOT {
                            self.values[slot as usize] += s * m;
                        }
                    }
                }
            }
        }
    }

    /// Adds `diag` (one entry per DOF of the whole mesh, e.g. the springs' stiffness) to the
    /// diagonal at the free DOFs.
    pub(crate) fn add_diagonal(&mut self, model: &FullSpaceModel, diag: &[f64]) {
        for (j, &dof) in model.dofs.free.iter().enumerate() {
            self.values[self.pattern.diag[j]] += diag[dof];
        }
    }

    /// Factorises the current values into `chol`; when the matrix is only semidefinite, adds a
    /// growing multiple of its mean diagonal until the factorisation succeeds.
    pub(crate) fn factor(&mut self) -> Result<(), FemError> {
        self.factor_with(false)
    }

    /// [`NewtonParts::factor`] for a preconditioner: the factor may be f32 or 16-bit
    /// ([`SparseCholesky::factor_for_preconditioning`]), solved only through
    /// [`SparseCholesky::solve_preconditioner_in_place`].
    pub(crate) fn factor_preconditioner(&mut self) -> Result<(), FemError> {
        self.factor_with(true)
    }

    fn factor_with(&mut self, preconditioner: bool) -> Result<(), FemError> {
        let mean_diag = self
            .pattern
            .diag
            .iter()
            .map(|&s| self.values[s])
            .sum::<f64>()
            / self.pattern.dim().max(1) as f64;
        let mut shift = 0.0;
        for attempt in 0..12 {
            let a = self.pattern.matrix(&self.values);
            let r = if preconditioner {
                self.chol.factor_for_preconditioning(a).map(|_| ())
            } else {
                self.chol.factor(a)
            };
            match r {
                Ok(()) => return Ok(()),
                Err(e) => {
                    if attempt == 11 || !mean_diag.is_finite() {
                        return Err(e);
                    }
                    let next = if shift == 0.0 {
                        1e-10 * mean_diag.abs().max(f64::MIN_POSITIVE)
                    } else {
                        shift * 10.0
                    };
                    for &s in &self.pattern.diag {
                        self.values[s] += next - shift;
                    }
                    shift = next;
                }
            }
        }
        unreachable!("the last attempt returns")
    }
}

/// A factorised SPD matrix used as z = P⁻¹ r, factorised in f32 (and stored in 16 bits) where
/// that passes its check ([`SparseCholesky::factor_for_preconditioning`]): P is itself an
/// approximate Hessian.
///
/// With a `rotation` R (the body's best-fit turn since the factor's state) it solves with
/// R̂HR̂ᵀ instead of H, R̂ the block diagonal of R over the free vertices. A rotation-invariant
/// elastic energy turns its Hessian exactly so when the state turns by R; M/h² (lumped, or
/// consistent as M_v ⊗ I₃) and the springs' k·I per vertex are unchanged by one turn applied at
/// every vertex.
#[derive(Debug, Clone)]
pub struct FactoredPreconditioner {
    pub(super) chol: SparseCholesky,
    pub(super) rotation: Option<Mat3>,
}

impl Preconditioner for FactoredPreconditioner {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        z.copy_from_slice(r);
        let Some(rot) = self.rotation else {
            self.chol.solve_preconditioner_in_place(z);
            return;
        };
        let turn = |z: &mut [f64], m: &Mat3| {
            for v in z.chunks_exact_mut(3) {
                let t = m * Vec3::new(v[0], v[1], v[2]);
                v.copy_from_slice(t.as_slice());
            }
        };
        turn(z, &rot.transpose());
        self.chol.solve_preconditioner_in_place(z);
        turn(z, &rot);
    }
}

/// Turns below this angle (radians) are not followed: the Hessian hardly changes by them, and
/// a factor applied as it was made keeps the steps of bodies that do not turn what they were.
const MIN_FOLLOWED_TURN: f64 = 1e-2;

/// The free vertices' rest positions and lumped masses, for the rotation that best carries the
/// body from one state to another (mass-weighted least squares about the centres of mass: the
/// rotation U Vᵀ of the signed SVD of Σ m (p − p̄)(q − q̄)ᵀ, Kabsch's solution). A body that
/// topples about a few pinned vertices, or swings on a drag, turns far between two
/// factorisations of its preconditioner; that turn, applied to the factor, keeps it near the
/// current Hessian. The fit is a closed form of the two states alone, so a trajectory replays
/// bit for bit after a reset.
#[derive(Debug, Clone)]
pub(crate) struct BodyRotation {
    rest: Vec<Vec3>,
    mass: Vec<f64>,
}

impl BodyRotation {
    /// `None` for a material whose energy is not rotation invariant (linear elasticity: its
    /// Hessian is K₀ in every state, and the factor as made is already exact), or unless the
    /// free DOFs are whole vertices (three in a row, as [`crate::constraints::DofMap`] frees
    /// them) and there are at least three of them.
    pub(crate) fn new(model: &FullSpaceModel) -> Option<Self> {
        if model.material.is_linear() {
            return None;
        }
        let free = &model.dofs.free;
        if free.len() < 9 || !free.len().is_multiple_of(3) {
            return None;
        }
        let mut rest = Vec::with_capacity(free.len() / 3);
        let mut mass = Vec::with_capacity(free.len() / 3);
        for dofs in free.chunks_exact(3) {
            let v = dofs[0] / 3;
            if !dofs[0].is_multiple_of(3) || dofs[1] != dofs[0] + 1 || dofs[2] != dofs[0] + 2 {
                return None;
            }
            rest.push(model.mesh.vertices[v]);
            mass.push(model.mass.lumped[v]);
        }
        Some(Self { rest, mass })
    }

    /// The rotation from the state with free displacements `from` to the one with `to`, or
    /// `None` when it turns less than [`MIN_FOLLOWED_TURN`] (or a state is not finite).
    pub(crate) fn between(&self, from: &[f64], to: &[f64]) -> Option<Mat3> {
        let at =
            |x: &[f64], i: usize| self.rest[i] + Vec3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
        let total: f64 = self.mass.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        let (mut p_bar, mut q_bar) = (Vec3::zeros(), Vec3::zeros());
        for (i, &m) in self.mass.iter().enumerate() {
            p_bar += at(to, i) * m;
            q_bar += at(from, i) * m;
        }
        p_bar /= total;
        q_bar /= total;
        let mut cross = Mat3::zeros();
        for (i, &m) in self.mass.iter().enumerate() {
            cross += (at(to, i) - p_bar) * (at(from, i) - q_bar).transpose() * m;
        }
        let svd = signed_svd(&cross);
        let rot = svd.u * svd.v.transpose();
        if !rot.iter().all(|v| v.is_finite()) {
            return None;
        }
        // The angle from the trace, clamped against round-off past ±1.
        let angle = ((rot.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
        (angle >= MIN_FOLLOWED_TURN).then_some(rot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assembly::{self, AssemblyBuffers, ElementSet};
    use crate::material::{MaterialConfig, MaterialModel};
    use crate::mesh::generate::{BoxSpec, box_mesh};
    use crate::with_material;

    /// A 40 cm bar held by the three vertices of its edge along z at x = y = 0, as a hinge.
    fn hinged_bar(material: MaterialModel) -> FullSpaceModel {
        let mesh = box_mesh(&BoxSpec {
            size: [0.4, 0.1, 0.1],
            cells: [8, 2, 2],
            ..Default::default()
        })
        .unwrap();
        let pinned: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].x < 1e-9 && mesh.vertices[v].y < 1e-9)
            .collect();
        assert_eq!(pinned.len(), 3);
        let material = MaterialConfig {
            model: material,
            youngs_modulus: 1e5,
            poisson_ratio: 0.45,
            ..Default::default()
        };
        FullSpaceModel::new(mesh, &material, pinned, Vec3::zeros(), Vec::new()).unwrap()
    }

    /// Free displacements that carry the rest shape, bent by `bend`, through the turn `rot`
    /// about the origin.
    fn turned(model: &FullSpaceModel, rot: &Mat3, bend: f64) -> Vec<f64> {
        let mut x = vec![0.0; model.dofs.num_free()];
        for (j, dofs) in model.dofs.free.chunks_exact(3).enumerate() {
            let p = model.mesh.vertices[dofs[0] / 3];
            let bent = p + Vec3::new(0.0, bend * p.x * p.x, 0.0);
            let d = rot * bent - p;
            x[3 * j..3 * j + 3].copy_from_slice(d.as_slice());
        }
        x
    }

    /// The system matrix at free displacements `x`, in `parts.values`.
    fn assemble(parts: &mut NewtonParts, model: &FullSpaceModel, x: &[f64]) {
        let mut u = vec![0.0; model.num_full()];
        model.dofs.scatter(x, &mut u);
        let mut buffers = AssemblyBuffers::default();
        with_material!(&model.material, |mat| assembly::hessian(
            mat,
            &model.elements,
            ElementSet::All,
            &u,
            true,
            &parts.pattern,
            &mut parts.values,
            &mut buffers
        ));
        parts.add_mass(model, 1e4);
        // Springs on every fifth vertex, as the schedules' grabs add them: k·I per vertex.
        let springs: Vec<f64> = (0..model.num_full())
            .map(|d| if (d / 3) % 5 == 0 { 500.0 } else { 0.0 })
            .collect();
        parts.add_diagonal(model, &springs);
    }

    fn norm(v: &[f64]) -> f64 {
        v.iter().map(|x| x * x).sum::<f64>().sqrt()
    }

    #[test]
    fn the_fit_finds_a_rigid_turn_and_ignores_a_small_one() {
        let model = hinged_bar(MaterialModel::StableNeoHookean);
        let fit = BodyRotation::new(&model).unwrap();
        let rot = *nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), -1.2).matrix();
        let from = turned(&model, &Mat3::identity(), 0.3);
        let found = fit.between(&from, &turned(&model, &rot, 0.3)).unwrap();
        assert!((found - rot).norm() < 1e-9, "{found} against {rot}");
        // Displaced along the turn's own axis as well: a translation changes nothing.
        let mut shifted = turned(&model, &rot, 0.3);
        shifted
            .iter_mut()
            .skip(2)
            .step_by(3)
            .for_each(|z| *z += 0.05);
        assert!((fit.between(&from, &shifted).unwrap() - rot).norm() < 1e-9);
        let slight =
            *nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), 0.5 * MIN_FOLLOWED_TURN)
                .matrix();
        assert!(fit.between(&from, &turned(&model, &slight, 0.3)).is_none());
        // About the bar's long axis, where little of its mass lies off the axis: found as well.
        let twist = *nalgebra::Rotation3::from_axis_angle(&Vec3::x_axis(), 1.0).matrix();
        let found = fit.between(&from, &turned(&model, &twist, 0.3)).unwrap();
        assert!((found - twist).norm() < 1e-9, "{found} against {twist}");
        // A linear material's Hessian is K₀ whatever the state: nothing to follow.
        assert!(BodyRotation::new(&hinged_bar(MaterialModel::Linear)).is_none());
    }

    #[test]
    fn a_factor_turned_with_the_body_preconditions_its_turned_state() {
        // P = R̂HR̂ᵀ is the system matrix of the turned state to the factor's own precision
        // (rotation invariance of the energy; mass and springs isotropic per vertex): P⁻¹A(Rq)v
        // is v again (4·10⁻¹¹ off when written), where the unturned factor is off by several
        // times v. This mesh is small enough for a simplicial factor, which stays in f64; a
        // larger one's f32 or 16-bit factor would be off by its own rounding, 10⁻³ or more.
        for material in [MaterialModel::NeoHookean, MaterialModel::Corotated] {
            let model = hinged_bar(material);
            let mut parts = NewtonParts::new(&model).unwrap();
            let q = turned(&model, &Mat3::identity(), 0.5);
            assemble(&mut parts, &model, &q);
            parts.factor_preconditioner().unwrap();
            let empty = parts.chol.same_pattern();
            let mut pre = FactoredPreconditioner {
                chol: std::mem::replace(&mut parts.chol, empty),
                rotation: None,
            };
            let rot = *nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), -1.0).matrix();
            let turned_q = turned(&model, &rot, 0.5);
            assemble(&mut parts, &model, &turned_q);
            let n = q.len();
            let v: Vec<f64> = (0..n).map(|i| ((i * 7919) % 13) as f64 - 6.0).collect();
            let mut av = vec![0.0; n];
            parts.pattern.mul_vec(&parts.values, &v, &mut av);
            let mut z = vec![0.0; n];
            let miss = |pre: &mut FactoredPreconditioner, z: &mut Vec<f64>| {
                pre.apply(&av, z);
                let d: Vec<f64> = z.iter().zip(&v).map(|(a, b)| a - b).collect();
                norm(&d) / norm(&v)
            };
            let plain = miss(&mut pre, &mut z);
            let fit = BodyRotation::new(&model).unwrap();
            pre.rotation = fit.between(&q, &turned_q);
            assert!((pre.rotation.unwrap() - rot).norm() < 1e-9);
            let with_turn = miss(&mut pre, &mut z);
            assert!(
                with_turn < 1e-4 && plain > 1.0,
                "{material:?}: {with_turn:.2e} turned against {plain:.2e} as made"
            );
        }
    }
}
