//! The springs' constant Hessian in q, kept between steps while the same forces are active,
//! and the patch compliance a subspace lacks, put in series with each spring.
//!
//! A spring on a small patch of a full mesh stretches less than its stiffness says: the patch
//! gives way locally (a dent the size of the patch) and what reaches the rest of the body is
//! the spring in series with that local compliance. A subspace cannot make the dent, so the
//! same spring pulls the reduced body harder. On AutoDef's X mesh (PCA, k = 53) the reduced
//! spring force was 10–15 % above the full one through the whole drag, and the trajectory
//! error followed it. Linearised at rest, the full step's compliance at the patch is
//! C = G A⁻¹ Gᵀ (A = K₀ + M/h², G the mean over the patch's vertices) and the PCA basis's is
//! Ĉ = G U (UᵀAU)⁻¹ UᵀGᵀ; the reduced spring pulls the patch's mean with (I/k + C − Ĉ)⁻¹, the
//! stiffness that makes a step's response to the spring at the patch the full one's. A basis
//! holding every direction has Ĉ = C and leaves the spring as it is.
//!
//! The dent itself is put back into the displacement the simulator reports: with f the pull the
//! softened spring exerts on the patch, u = U(q − Â⁻¹UᵀGᵀf) + A⁻¹Gᵀf, the part of the full
//! step's response to f that the basis lacks (A-orthogonal to it) added to Uq: the static
//! correction of truncated modal analysis (the mode-acceleration method). Its mean over the
//! patch is (C − Ĉ)f, the stretch the series compliance gave way by, so the reported patch
//! sits where the spring's force says it is. On AutoDef's bar 77 % of PCA's error against the
//! test drag lies within two patch radii of the grab.
//!
//! The neural methods take the PCA basis's Ĉ too, not that of the decoder's tangent at rest:
//! their trajectories stay close to PCA's, and the tangent's smaller compliance softened their
//! springs too much (suite `neural-cubature`, X very low: 2.9 % against 2.5 %; bar 14.9 against
//! 14.7 %; X high 6.1 against 5.9 %).

use std::sync::Arc;

use fem_core::forces::ForceKind;
use fem_core::integrator::FullSpaceModel;
use fem_core::snapshots::StiffnessProbe;
use fem_core::{Mat3, Vec3};

use super::ReducedSimulator;
use crate::Subspace;
use crate::reduced::{ReducedSpace, axpy};

/// Whether springs are softened, and the factor of the full step's operator at rest that
/// measures the patch compliance (built when the first spring needs it).
#[derive(Debug, Clone)]
pub(super) struct SpringCompliance {
    pub(super) on: bool,
    probe: Option<Arc<StiffnessProbe>>,
    /// Per force, the dent of a softened spring's patch (None for other forces).
    dents: Vec<Option<Dent>>,
    /// The dents of springs removed since the last step: part of the state that step computed,
    /// shown until the next one, so that letting go moves nothing before the body does (the
    /// default bar's grabbed patch jumped 5 cm back at `release` before 2026-12-02).
    released: Vec<Dent>,
    /// The operator could not be factorised (a quasi-static body held by nothing): springs
    /// are left as they are.
    failed: bool,
}

impl Default for SpringCompliance {
    fn default() -> Self {
        Self {
            on: true,
            probe: None,
            dents: Vec::new(),
            released: Vec::new(),
            failed: false,
        }
    }
}

/// An active softened spring's dent: its pull f on the patch and A⁻¹Gᵀ (free DOFs × 3,
/// column-major), whose product is the displacement the full step's response adds.
#[derive(Debug, Clone, Copy)]
pub struct ActiveDent<'a> {
    pull: Vec3,
    response: &'a [f64],
}

impl ActiveDent<'_> {
    /// The dent's displacement at free DOF `r`.
    #[inline]
    pub fn at(&self, r: usize) -> f64 {
        let n = self.response.len() / 3;
        (0..3)
            .map(|c| self.pull[c] * self.response[c * n + r])
            .sum()
    }
}

/// The displacement of a spring's patch per unit of pull that the basis lacks: A⁻¹Gᵀ on the
/// free DOFs (free DOFs × 3, column-major) and the basis's own response Â⁻¹UᵀGᵀ (k × 3); and
/// the pull the spring exerted in the last step's state (None before its first step or when
/// it was inactive).
#[derive(Debug, Clone)]
struct Dent {
    full: Vec<f64>,
    basis: Vec<f64>,
    pull: Option<Vec3>,
}

impl<S: Subspace> ReducedSimulator<S> {
    /// Whether springs pull with the patch compliance the subspace lacks in series (on by
    /// default; see the module's notes). Turning it on factorises the full step's operator at
    /// rest once (a full-space sparse Cholesky, the cost of one full Newton step) when a
    /// spring needs it. The dents shown are then those of the current state under the new
    /// setting (a released spring's among them no longer).
    pub fn set_spring_compliance(&mut self, on: bool) {
        self.compliance.on = on;
        self.soften_springs();
        self.forces_changed();
        self.settle_dents();
    }

    /// [`Self::soften_spring`] for every force.
    pub(super) fn soften_springs(&mut self) {
        for index in 0..self.model.forces.len() {
            self.soften_spring(index);
        }
    }

    /// See [`Self::set_spring_compliance`].
    pub fn spring_compliance(&self) -> bool {
        self.compliance.on
    }

    /// Sets force `index`'s reduced terms: softened when it is a spring and compliance is on.
    pub(super) fn soften_spring(&mut self, index: usize) {
        let f = &self.model.forces[index];
        let missing = if self.compliance.on && f.kind == ForceKind::Spring && f.stiffness > 0.0 {
            self.missing_compliance(index)
        } else {
            None
        };
        let f = &self.model.forces[index];
        self.space
            .set_spring_compliance(index, f, missing.as_ref().map(|m| &m.0));
        let dents = &mut self.compliance.dents;
        dents.resize_with(dents.len().max(index + 1), || None);
        dents[index] = missing.map(|m| m.1);
    }

    /// Forgets force `index`'s dent (the later ones move down by one); one the state shows is
    /// shown until the next step.
    pub(super) fn remove_dent(&mut self, index: usize) {
        if index < self.compliance.dents.len()
            && let Some(dent) = self.compliance.dents.remove(index)
            && dent.pull.is_some()
        {
            self.compliance.released.push(dent);
        }
    }

    /// The displacement of every vertex (3 per vertex) into `u`: Uq plus the dents of the
    /// active softened springs (see the module's notes).
    pub(super) fn displacement_with_dents(&self, u: &mut [f64]) {
        let (shifted, dents) = self.dents();
        self.space.reconstruct(&shifted, u);
        if dents.is_empty() {
            return;
        }
        for (r, &d) in self.model.dofs.free.iter().enumerate() {
            u[d] += dents.iter().map(|dent| dent.at(r)).sum::<f64>();
        }
    }

    /// What the reported displacement is made of: the coefficients to decode, q less the basis's
    /// share of each softened spring's pull at the last step, and the dents to add, the pulls'
    /// full-space responses (see the module's notes).
    pub fn dents(&self) -> (Vec<f64>, Vec<ActiveDent<'_>>) {
        let k = self.space.k;
        let mut shifted = self.state.q.clone();
        let mut active = Vec::new();
        let compliance = &self.compliance;
        for dent in compliance
            .dents
            .iter()
            .flatten()
            .chain(&compliance.released)
        {
            let Some(pull) = dent.pull else { continue };
            for c in 0..3 {
                axpy(-pull[c], &dent.basis[c * k..(c + 1) * k], &mut shifted);
            }
            active.push(ActiveDent {
                pull,
                response: &dent.full,
            });
        }
        (shifted, active)
    }

    /// Records each softened spring's pull on its patch in the current state, at the state's
    /// time: what the dents show until the next step. A dent belongs to a state the step
    /// computed (or [`Self::set_state`] gave), so moving a handle, adding a spring or a failed
    /// step changes no reported position.
    pub(super) fn settle_dents(&mut self) {
        self.compliance.released.clear();
        let (q, t) = (&self.state.q, self.state.time);
        for (index, dent) in self.compliance.dents.iter_mut().enumerate() {
            let (Some(dent), Some(f)) = (dent, self.model.forces.get(index)) else {
                continue;
            };
            dent.pull = (f.is_active(t) && !f.vertices.is_empty()).then(|| {
                let mean = self.space.patch_mean(index, f.vertices.len(), q);
                self.space.spring_pull(index).unwrap_or_else(Mat3::identity)
                    * (f.value(t) - mean)
                    * f.stiffness
            });
        }
    }

    /// Forgets every dent's pull (a state at rest, as after [`Self::reset`]).
    pub(super) fn clear_dents(&mut self) {
        self.compliance.released.clear();
        for dent in self.compliance.dents.iter_mut().flatten() {
            dent.pull = None;
        }
    }

    /// Factorises the full step's operator at rest now, where springs are softened and it is
    /// not factorised yet: the work the first spring (a grab) would otherwise do in its step
    /// (75–110 ms on a 3,321-vertex bar), done before an interactive loop starts.
    pub fn prepare_spring_compliance(&mut self) {
        if self.compliance.on {
            self.compliance_probe();
        }
    }

    /// The full step's operator at rest, factorised once (None where it cannot be).
    fn compliance_probe(&mut self) -> Option<Arc<StiffnessProbe>> {
        if self.compliance.probe.is_none() && !self.compliance.failed {
            let scale = if self.time.quasi_static {
                f64::INFINITY
            } else {
                self.time.step
            };
            match StiffnessProbe::new(&self.model, scale) {
                Ok(p) => self.compliance.probe = Some(Arc::new(p)),
                Err(_) => self.compliance.failed = true,
            }
        }
        self.compliance.probe.clone()
    }

    /// C − Ĉ at force `index`'s patch, with its negative eigenvalues (round-off where the
    /// subspace holds the whole response) set to zero, and the patch's dent. None when the full
    /// operator or the subspace's cannot be factorised.
    fn missing_compliance(&mut self, index: usize) -> Option<(Mat3, Dent)> {
        let probe = self.compliance_probe()?;
        let f = &self.model.forces[index];
        let (full, columns) = probe.patch_response(&self.model, &f.vertices);
        let h = (!self.time.quasi_static).then_some(self.time.step);
        let (reduced, basis) = self.space.patch_response(index, f, h)?;
        let missing = full - reduced;
        let mut eigen = ((missing + missing.transpose()) * 0.5).symmetric_eigen();
        eigen.eigenvalues.apply(|l| *l = l.max(0.0));
        let c = eigen.recompose();
        let dent = Dent {
            full: columns,
            basis,
            pull: None,
        };
        c.iter().all(|x| x.is_finite()).then_some((c, dent))
    }
}

/// Σ_f k_f/n_f Σ_v U_vᵀU_v over the springs active at the time it was updated for (k×k): the
/// springs' constant Hessian in q, rebuilt only when a force switches on or off.
#[derive(Debug, Clone, Default)]
pub(super) struct SpringTerm {
    pub(super) active: Vec<bool>,
    pub(super) valid: bool,
    pub(super) matrix: Vec<f64>,
}

impl SpringTerm {
    pub(super) fn update(
        &mut self,
        model: &FullSpaceModel,
        space: &ReducedSpace,
        t: f64,
    ) -> &[f64] {
        let same = self.valid
            && model
                .forces
                .iter()
                .map(|f| f.is_active(t))
                .eq(self.active.iter().copied());
        if !same {
            let k = space.k;
            self.active.clear();
            self.active
                .extend(model.forces.iter().map(|f| f.is_active(t)));
            self.matrix.clear();
            self.matrix.resize(k * k, 0.0);
            for (f, gram) in model.forces.iter().zip(&space.force_gram) {
                if f.is_active(t) && f.stiffness > 0.0 {
                    let s = f.stiffness / f.vertices.len() as f64;
                    axpy(s, gram, &mut self.matrix);
                }
            }
            self.valid = true;
        }
        &self.matrix
    }
}
