//! The reduced implicit Euler time stepper, generic over the subspace.

use std::time::Instant;

use fem_core::FemError;
use fem_core::forces::ExternalForce;
use fem_core::integrator::{FullSpaceModel, TimeConfig};
use fem_core::optim::{
    Lbfgs, NewtonSystem, Objective, PreconditionerUse, SolveParams, SolveStats, SolverConfig,
    SolverMethod, newton,
};

use crate::dense_factor::DenseFactor;
use crate::reduced::{ReducedSpace, SpaceBuffers, axpy, dot};
use crate::{ReducedError, Subspace};

mod gauss_newton;
mod kernels;
mod preconditioner;
mod springs;
pub use springs::ActiveDent;

pub(crate) use kernels::sandwich;
use preconditioner::{FRESH_REBUILDS_IN_SOLVE, PRECOND_EXTRA_ITERATIONS, REBUILD_AFTER_ITERATIONS};
pub use preconditioner::{PRECOND_MAX_AGE, Preconditioning};
use springs::{SpringCompliance, SpringTerm};

/// Latent state: z, and the PCA coefficients q and their velocity q̇ carried between steps.
#[derive(Debug, Clone, PartialEq)]
pub struct ReducedState {
    pub step: usize,
    pub time: f64,
    pub z: Vec<f64>,
    pub q: Vec<f64>,
    pub qdot: Vec<f64>,
    /// (z_n − z_{n−1})/h: the next solve starts from z_n + h ż_n (+ h² z̈_n after a step).
    pub zdot: Vec<f64>,
}

/// Per-step statistics.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ReducedStepReport {
    pub step: usize,
    pub time: f64,
    pub iterations: usize,
    pub relative_gradient: f64,
    pub wall_seconds: f64,
    /// Time building and factorising the L-BFGS preconditioner, or Newton's matrix
    /// (Gauss–Newton Jᵀ H J, its Jacobian included) with the Newton solver.
    pub precond_seconds: f64,
    /// Time decoding: the network's forward pass (q = decode(z)) and the partial decode Uq over
    /// the vertices the elastic energy touches.
    pub decode_seconds: f64,
    /// Time in the elastic energy and its reduced gradient over the (cubature) elements.
    pub elastic_seconds: f64,
    /// Time in the decoder's vector–Jacobian product Jᵀ ∂E/∂q.
    pub vjp_seconds: f64,
    /// Evaluations of the step energy and its gradient (iterations plus line-search trials).
    pub evaluations: usize,
    /// Whether the L-BFGS preconditioner was rebuilt in this step: at its start, or within its
    /// solve, where it had served 32 iterations without converging beyond the count of the
    /// first solve it served (none for one made in this step).
    pub preconditioner_rebuilt: bool,
    /// Whether L-BFGS crawled or its line search failed and the step was solved again with
    /// reduced Newton from z_n (`iterations` then counts L-BFGS's iterations too).
    pub newton_fallback: bool,
    /// Whether the step started again from z_n, the last step's answer, because it could not
    /// be solved from its extrapolated start: the energy was not finite there (an element
    /// inverted under the classic Neo-Hookean model) or the preconditioner's matrix could not
    /// be factorised there.
    pub restarted: bool,
}

/// Energies of a reduced state (see [`ReducedSimulator::energy`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct ReducedEnergy {
    pub elastic: f64,
    pub kinetic: f64,
    /// Potential of gravity and of the active external forces.
    pub external: f64,
    pub total: f64,
}

/// The preconditioner a step's L-BFGS solve starts with, which decides whether the solve may
/// rebuild it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Starting {
    /// A matrix a solve never rebuilds: the rest state's (`preconditioner = "rest"`).
    Fixed,
    /// The current-state matrix, made at this step's start.
    Fresh,
    /// The current-state matrix, kept from an earlier step.
    Aged,
}

/// Time spent in each part of the objective, accumulated over one step.
#[derive(Debug, Clone, Copy, Default)]
struct Timers {
    decode: f64,
    elastic: f64,
    vjp: f64,
    /// Building and factorising Newton's matrix.
    newton: f64,
    /// Rebuilding the preconditioner within a solve, where it stopped serving.
    precond: f64,
    /// Evaluations of the energy and its gradient.
    evaluations: usize,
}

/// Implicit Euler in a subspace.
#[derive(Debug, Clone)]
pub struct ReducedSimulator<S: Subspace> {
    pub model: FullSpaceModel,
    pub space: ReducedSpace,
    pub subspace: S,
    pub time: TimeConfig,
    pub solver: SolverConfig,
    pub state: ReducedState,
    work: Work,
    lbfgs: Lbfgs,
    /// The factorised preconditioner. It is rebuilt when a force switches on or off
    /// (`precond_active` records the active set it was built for); for a nonlinear subspace also
    /// when it is [`PRECOND_MAX_AGE`] steps old or the solves it serves got harder (see
    /// [`PRECOND_EXTRA_ITERATIONS`]).
    precond: DenseFactor,
    precond_active: Option<Vec<bool>>,
    /// Which matrix preconditions L-BFGS.
    pub preconditioning: Preconditioning,
    /// How the current preconditioner has served.
    precond_use: PreconditionerUse,
    /// The next z and q while a step solves (swapped with the state after it).
    next_z: Vec<f64>,
    next_q: Vec<f64>,
    /// z̈_n = (ż_n − ż_{n−1})/h, a start hint valid when `zddot_step` is the state's step.
    zddot: Vec<f64>,
    zddot_step: Option<usize>,
    /// Whether springs pull with the patch compliance the subspace lacks added in series
    /// ([`Self::set_spring_compliance`]), and the factor that measures it.
    compliance: SpringCompliance,
    /// Whether a solve of the step under way was redone with reduced Newton.
    fell_back: bool,
    /// Whether a solve of the step under way rebuilt the preconditioner at its iterate.
    rebuilt_in_solve: bool,
}

/// Reusable buffers of one step.
#[derive(Debug, Clone)]
struct Work {
    u: Vec<f64>,
    grad_full: Vec<f64>,
    q: Vec<f64>,
    grad_q: Vec<f64>,
    tmp_q: Vec<f64>,
    /// (UᵀMU)(q − q̃).
    mass_q: Vec<f64>,
    predicted: Vec<f64>,
    jac: Vec<f64>,
    /// The root-mean-square column norm of `jac` when it was last formed: how much ∂E/∂z
    /// shrinks or grows the gradient in q, so that the solver's relative gradient compares
    /// quantities in the same units ([`StepObjective::value_gradient`]).
    jacobian_scale: f64,
    /// The smallest gradient scale in q ([`gradient_floor`]).
    gradient_floor: f64,
    space: SpaceBuffers,
    springs: SpringTerm,
    /// A k×k matrix in q (preconditioner or the constant part of the Newton matrix).
    hk: Vec<f64>,
    /// k×d scratch of the sandwich JᵀAJ.
    ab: Vec<f64>,
    /// d×d: the preconditioner or Newton matrix, and the Newton matrix's constant part.
    hz: Vec<f64>,
    hz_const: Vec<f64>,
    /// k×k: the element terms of the Gauss–Newton matrix summed in q, and d×d: their image in z
    /// (when that is cheaper, [`gauss_newton::sum_in_q_is_cheaper`]).
    hq: Vec<f64>,
    hz_elastic: Vec<f64>,
    /// U J on the rows of the element vertices (3·n × d, row-major: a vertex's three rows are
    /// 3·d contiguous values).
    uj: Vec<f64>,
    /// With the element bases, over the whole element set (m elements, row-major): the element
    /// bases times J (9m × d, the sum in z only) and the stress derivatives times those rows
    /// (9m × n, n = k or d).
    stacked_bj: Vec<f64>,
    stacked_abj: Vec<f64>,
    newton: DenseFactor,
    timers: Timers,
}

impl<S: Subspace> ReducedSimulator<S> {
    /// Starts at rest (q = 0, z = encode(0)).
    pub fn new(
        model: FullSpaceModel,
        space: ReducedSpace,
        mut subspace: S,
        time: TimeConfig,
        solver: SolverConfig,
    ) -> Result<Self, ReducedError> {
        let mut errors = Vec::new();
        time.check(&mut errors);
        solver.check(&mut errors);
        FemError::collect(errors)?;
        let (k, d) = (subspace.coeff_dim(), subspace.latent_dim());
        if k != space.k {
            return Err(ReducedError::BasisShape {
                rows: space.k,
                free: k,
            });
        }
        let q = vec![0.0; k];
        let mut z = vec![0.0; d];
        subspace.encode(&q, &mut z);
        let mut qz = vec![0.0; k];
        subspace.decode(&z, &mut qz);
        let n = model.num_full();
        let sim = Self {
            state: ReducedState {
                step: 0,
                time: 0.0,
                z,
                q: qz,
                qdot: vec![0.0; k],
                zdot: vec![0.0; d],
            },
            work: Work {
                u: vec![0.0; n],
                grad_full: vec![0.0; n],
                q: vec![0.0; k],
                grad_q: vec![0.0; k],
                tmp_q: vec![0.0; k],
                mass_q: vec![0.0; k],
                predicted: vec![0.0; k],
                jac: vec![0.0; k * d],
                jacobian_scale: 1.0,
                gradient_floor: gradient_floor(&model),
                space: space.buffers(),
                springs: SpringTerm::default(),
                hk: vec![0.0; k * k],
                ab: vec![0.0; k * d],
                hz: vec![0.0; d * d],
                hz_const: vec![0.0; d * d],
                hq: Vec::new(),
                hz_elastic: vec![0.0; d * d],
                uj: Vec::new(),
                stacked_bj: Vec::new(),
                stacked_abj: Vec::new(),
                newton: DenseFactor::default(),
                timers: Timers::default(),
            },
            lbfgs: Lbfgs::new(d, solver.lbfgs_memory),
            precond: DenseFactor::default(),
            precond_active: None,
            preconditioning: Preconditioning::default(),
            precond_use: PreconditionerUse::default(),
            next_z: vec![0.0; d],
            next_q: vec![0.0; k],
            zddot: vec![0.0; d],
            zddot_step: None,
            compliance: SpringCompliance::default(),
            fell_back: false,
            rebuilt_in_solve: false,
            model,
            space,
            subspace,
            time,
            solver,
        };
        let mut sim = sim;
        let z = sim.state.z.clone();
        sim.subspace.jacobian(&z, &mut sim.work.jac);
        sim.work.jacobian_scale = rms_column_norm(&sim.work.jac, k);
        sim.soften_springs();
        Ok(sim)
    }

    /// Puts the simulator at step `step` (time `step · h`) in the states its subspace gives to
    /// the PCA coefficients `q_now` (at that step) and `q_before` (one step earlier): z =
    /// encode(q) (with linear directions beside a network, the nearest point of the subspace:
    /// [`Augmented`](crate::Augmented)), q = decode(z), the velocities their differences over h (zero when
    /// quasi-static). Nothing of the previous solves is kept (warm-start history, L-BFGS pairs,
    /// preconditioner), so the next [`step`](Self::step) depends on these two states only: what
    /// a one-step error measures, started from a reference trajectory.
    ///
    /// # Errors
    /// [`ReducedError::StateShape`] when a vector's length is not the subspace's k,
    /// [`ReducedError::StateNotFinite`] when a coefficient is not finite,
    /// [`ReducedError::StateStep`] for a step past [`MAX_STATE_STEP`](crate::MAX_STATE_STEP);
    /// on any of these the state is left as it was.
    pub fn set_state(
        &mut self,
        step: usize,
        q_now: &[f64],
        q_before: &[f64],
    ) -> Result<(), ReducedError> {
        if step > crate::MAX_STATE_STEP {
            return Err(ReducedError::StateStep { step });
        }
        let (k, d) = (self.space.k, self.subspace.latent_dim());
        for q in [q_now, q_before] {
            if q.len() != k {
                return Err(ReducedError::StateShape {
                    expected: k,
                    got: q.len(),
                });
            }
            if let Some((index, &value)) = q.iter().enumerate().find(|(_, x)| !x.is_finite()) {
                return Err(ReducedError::StateNotFinite { index, value });
            }
        }
        let (mut z_before, mut q_b) = (vec![0.0; d], vec![0.0; k]);
        self.subspace.encode(q_before, &mut z_before);
        self.subspace.decode(&z_before, &mut q_b);
        self.subspace.encode(q_now, &mut self.state.z);
        self.subspace.decode(&self.state.z, &mut self.state.q);
        let h = self.time.step;
        let rate = if self.time.quasi_static { 0.0 } else { 1.0 / h };
        for ((v, now), before) in self.state.qdot.iter_mut().zip(&self.state.q).zip(&q_b) {
            *v = (now - before) * rate;
        }
        for ((v, now), before) in self.state.zdot.iter_mut().zip(&self.state.z).zip(&z_before) {
            *v = (now - before) * rate;
        }
        self.state.step = step;
        self.state.time = step as f64 * h;
        self.zddot_step = None;
        self.zddot.fill(0.0);
        self.lbfgs.reset();
        self.precond_active = None;
        self.precond_use.restart();
        self.settle_dents();
        Ok(())
    }

    /// Back at rest at time 0, as [`ReducedSimulator::new`] left it: the next steps are those of
    /// a new simulator with the same forces, bit for bit.
    pub fn reset(&mut self) {
        let zero = vec![0.0; self.space.k];
        self.subspace.encode(&zero, &mut self.state.z);
        self.subspace.decode(&self.state.z, &mut self.state.q);
        self.state.qdot.fill(0.0);
        self.state.zdot.fill(0.0);
        self.state.step = 0;
        self.state.time = 0.0;
        self.zddot.fill(0.0);
        self.zddot_step = None;
        self.lbfgs.reset();
        self.precond_use.restart();
        self.clear_dents();
        self.forces_changed();
    }

    /// Adds an external force (its vertices must have basis rows in the space), acting from
    /// the next step; its index is the number of forces before it.
    ///
    /// # Errors
    /// [`ReducedError::InvalidForce`] for a force [`ExternalForce::problem`] refuses, and
    /// [`ReducedError::NoBasisRows`] as [`ReducedSpace::push_force`].
    pub fn add_force(&mut self, force: ExternalForce) -> Result<usize, ReducedError> {
        if let Some(reason) = force.problem(self.model.mesh.num_vertices()) {
            return Err(ReducedError::InvalidForce { reason });
        }
        self.space.push_force(&force)?;
        self.model.forces.push(force);
        let index = self.model.forces.len() - 1;
        self.soften_spring(index);
        self.forces_changed();
        Ok(index)
    }

    /// Removes force `index` (the later ones move down by one) and returns it.
    ///
    /// # Errors
    /// [`ReducedError::NoSuchForce`] when there is no such force.
    pub fn remove_force(&mut self, index: usize) -> Result<ExternalForce, ReducedError> {
        if index >= self.model.forces.len() {
            return Err(ReducedError::NoSuchForce {
                index,
                count: self.model.forces.len(),
            });
        }
        self.space.remove_force(index);
        self.remove_dent(index);
        self.forces_changed();
        Ok(self.model.forces.remove(index))
    }

    /// Replaces force `index`'s keyframes (a spring's offset, a load's value): what moving a
    /// spring's target changes. The springs' constant Hessian does not depend on them, so the
    /// preconditioner is kept.
    ///
    /// # Errors
    /// [`ReducedError::NoSuchForce`] when there is no such force; [`ReducedError::Keyframes`]
    /// when the keyframes are empty, not finite or not in time order.
    pub fn set_force_keyframes(
        &mut self,
        index: usize,
        keyframes: &[[f64; 4]],
    ) -> Result<(), ReducedError> {
        let count = self.model.forces.len();
        let force = self
            .model
            .forces
            .get_mut(index)
            .ok_or(ReducedError::NoSuchForce { index, count })?;
        if !fem_core::forces::keyframes_usable(keyframes) {
            return Err(ReducedError::Keyframes);
        }
        force.keyframes.clear();
        force.keyframes.extend_from_slice(keyframes);
        Ok(())
    }

    /// After forces were added or removed: the springs' Hessian and the preconditioner that
    /// includes it are rebuilt by the next step.
    fn forces_changed(&mut self) {
        self.work.springs.valid = false;
        self.precond_active = None;
    }

    /// Jᵀ (UᵀK₀U + UᵀMU/h² + Σ k_s/n U_vᵀU_v) J at z (d×d, column-major, into
    /// `work.hz`): every constant quadratic term of the step energy, including the springs
    /// active at time `t` (a stiff spring left out of the preconditioner stalls L-BFGS along its
    /// direction).
    fn preconditioner_matrix(&mut self, z: &[f64], t: f64) {
        let (k, d) = (self.space.k, self.subspace.latent_dim());
        let inv_h2 = self.inv_h2();
        let w = &mut self.work;
        let springs = w.springs.update(&self.model, &self.space, t);
        for (i, a) in w.hk.iter_mut().enumerate() {
            *a = (self.space.rest_stiffness[i] + inv_h2 * self.space.mass[i]) + springs[i];
        }
        self.subspace.jacobian(z, &mut w.jac);
        w.jacobian_scale = rms_column_norm(&w.jac, k);
        sandwich(&w.hk, &w.jac, k, d, &mut w.ab, &mut w.hz);
    }

    fn inv_h2(&self) -> f64 {
        if self.time.quasi_static {
            0.0
        } else {
            1.0 / (self.time.step * self.time.step)
        }
    }

    /// Advances one step.
    pub fn step(&mut self) -> Result<ReducedStepReport, ReducedError> {
        let start = Instant::now();
        let h = self.time.step;
        let t = (self.state.step + 1) as f64 * h;
        let k = self.space.k;
        self.predict();
        self.work.timers = Timers::default();
        self.fell_back = false;
        self.rebuilt_in_solve = false;
        let params = SolveParams {
            tolerance: self.solver.tolerance,
            max_iterations: self.solver.max_iterations,
            step: self.state.step + 1,
        };
        // Warm start on the latent trajectory's extrapolation z_n + h ż_n + h² z̈_n: the minimiser
        // moves little from it in smooth motion (AutoDef started at z_n; the second-order term
        // took 21 % of the iterations off on the catapult, 29 % for PCA). The first step, and a
        // state set from outside, start from z_n + h ż_n.
        let mut z = std::mem::take(&mut self.next_z);
        z.clear();
        z.extend_from_slice(&self.state.z);
        if !self.time.quasi_static {
            let h2 = if self.zddot_step == Some(self.state.step) {
                h * h
            } else {
                0.0
            };
            for ((z, v), a) in z.iter_mut().zip(&self.state.zdot).zip(&self.zddot) {
                *z += h * v + h2 * a;
            }
        }
        let pstart = Instant::now();
        let mut rebuilt = false;
        let mut restarted = false;
        let mut starting = Starting::Fixed;
        if self.solver.method == SolverMethod::Lbfgs {
            let d = self.subspace.latent_dim();
            let current = self.precond_active.as_ref().is_some_and(|a| {
                self.model
                    .forces
                    .iter()
                    .map(|f| f.is_active(t))
                    .eq(a.iter().copied())
            });
            // The state changes little from step to step: a preconditioner that depends on it
            // (J(z), or the tangents) is kept until it is PRECOND_MAX_AGE steps old or the solves
            // it served cost PRECOND_EXTRA_ITERATIONS more iterations than a fresh one would
            // (AutoDef rebuilt it every step). The rest-state one of a linear subspace never
            // goes stale.
            let preconditioning = match self.preconditioning {
                Preconditioning::Auto => Preconditioning::CurrentState,
                p => p,
            };
            let depends_on_state =
                !self.subspace.is_linear() || preconditioning == Preconditioning::CurrentState;
            let stale = depends_on_state
                && self
                    .precond_use
                    .is_stale(PRECOND_MAX_AGE, PRECOND_EXTRA_ITERATIONS);
            if !current || stale {
                self.precond_active = None;
                match preconditioning {
                    Preconditioning::Auto | Preconditioning::CurrentState => {
                        // The Gauss–Newton matrix at the solve's starting point, as reduced Newton
                        // forms it (exact tangents cost a fraction of their projections: at 300
                        // elements the rebuild takes 0.4 instead of 1 ms). Formed at z_n instead
                        // of the extrapolated start, J(z) and the tangents lag a step behind the
                        // motion: 7.2 instead of 4.5 iterations per step on the catapult (with
                        // the first-order start z_n + h ż_n).
                        let mut precond = std::mem::take(&mut self.precond);
                        let mut factored = self.step_objective().factor_gauss_newton(
                            &z,
                            &mut precond,
                            "preconditioner",
                        );
                        // An extrapolated start past an inverted element (classic Neo-Hookean)
                        // has no matrix: form it at z_n and start there (see the solve below).
                        if factored.is_err() && z != self.state.z {
                            restarted = true;
                            z.copy_from_slice(&self.state.z);
                            factored = self.step_objective().factor_gauss_newton(
                                &z,
                                &mut precond,
                                "preconditioner",
                            );
                        }
                        self.precond = precond;
                        factored?;
                    }
                    Preconditioning::Rest => {
                        self.preconditioner_matrix(&z, t);
                        self.precond.factor(&self.work.hz, d, "preconditioner")?;
                    }
                }
                self.precond_active =
                    Some(self.model.forces.iter().map(|f| f.is_active(t)).collect());
                self.precond_use.restart();
                rebuilt = true;
                // A new preconditioner also marks a change of the curvature (a force switched,
                // or the state moved on): the next solve starts without the old pairs.
                self.lbfgs.reset();
            }
            if preconditioning == Preconditioning::CurrentState {
                starting = if rebuilt {
                    Starting::Fresh
                } else {
                    Starting::Aged
                };
            }
        }
        let precond_seconds = pstart.elapsed().as_secs_f64();
        let stats = match self.solve(&mut z, t, params, starting) {
            // The extrapolated start can leave the region where the energy is defined (an
            // element inverted under the classic Neo-Hookean model, whose energy is then not
            // finite) where z_n, the last step's answer, was inside it: start again from z_n.
            Err(FemError::NonFinite { what, .. }) if z != self.state.z => {
                tracing::info!("{what} not finite from the extrapolated start; retrying from z_n");
                restarted = true;
                self.lbfgs.reset();
                z.copy_from_slice(&self.state.z);
                let now = if self.rebuilt_in_solve {
                    Starting::Fresh
                } else {
                    starting
                };
                self.solve(&mut z, t, params, now)?
            }
            r => r?,
        };
        let mut q_new = std::mem::take(&mut self.next_q);
        q_new.resize(k, 0.0);
        self.subspace.decode(&z, &mut q_new);
        if q_new.iter().chain(&z).any(|v| !v.is_finite()) {
            return Err(FemError::NonFinite {
                what: "reduced coordinates",
                step: self.state.step + 1,
            }
            .into());
        }
        for i in 0..k {
            self.state.qdot[i] = if self.time.quasi_static {
                0.0
            } else {
                (q_new[i] - self.state.q[i]) / h
            };
        }
        for ((v, a), (new, old)) in self
            .state
            .zdot
            .iter_mut()
            .zip(&mut self.zddot)
            .zip(z.iter().zip(&self.state.z))
        {
            let v_new = if self.time.quasi_static {
                0.0
            } else {
                (new - old) / h
            };
            *a = (v_new - *v) / h;
            *v = v_new;
        }
        self.zddot_step = (!self.time.quasi_static).then_some(self.state.step + 1);
        // The old state's vectors become the next step's buffers.
        self.next_q = std::mem::replace(&mut self.state.q, q_new);
        self.next_z = std::mem::replace(&mut self.state.z, z);
        self.state.step += 1;
        self.state.time = t;
        self.settle_dents();
        Ok(ReducedStepReport {
            step: self.state.step,
            time: t,
            iterations: stats.iterations,
            relative_gradient: stats.relative_gradient,
            wall_seconds: start.elapsed().as_secs_f64(),
            precond_seconds: precond_seconds + self.work.timers.precond + self.work.timers.newton,
            decode_seconds: self.work.timers.decode,
            elastic_seconds: self.work.timers.elastic,
            vjp_seconds: self.work.timers.vjp,
            evaluations: self.work.timers.evaluations,
            preconditioner_rebuilt: rebuilt || self.rebuilt_in_solve,
            newton_fallback: self.fell_back,
            restarted,
        })
    }

    /// Minimises the step objective at time `t` from `z` (overwritten) with the configured
    /// solver. With L-BFGS and a current-state preconditioner, once the preconditioner has
    /// served [`REBUILD_AFTER_ITERATIONS`] iterations without converging, beyond what its first
    /// solve took when it was `starting` as [`Starting::Aged`], it is rebuilt at the solve's
    /// iterate and L-BFGS goes on from there: once for an aged one, then up to
    /// [`FRESH_REBUILDS_IN_SOLVE`] times for fresh ones, after which L-BFGS has the full
    /// iteration cap. A solve that still crawls or whose line search fails is redone with
    /// reduced Newton from z_n, and the next step rebuilds the preconditioner.
    fn solve(
        &mut self,
        z: &mut [f64],
        t: f64,
        params: SolveParams,
        starting: Starting,
    ) -> Result<SolveStats, FemError> {
        let inv_h2 = self.inv_h2();
        let mut obj = StepObjective {
            model: &self.model,
            space: &self.space,
            subspace: &mut self.subspace,
            work: &mut self.work,
            t,
            inv_h2,
            scale: 0.0,
            noise: 0.0,
        };
        if self.solver.method == SolverMethod::Newton {
            return newton(&mut obj, z, params);
        }
        // Iterations of attempts cut short, counted into the step's total.
        let mut spent = 0;
        let mut precond = starting;
        let mut fresh_rebuilds = FRESH_REBUILDS_IN_SOLVE;
        let e = loop {
            let cap = match precond {
                Starting::Aged => self.precond_use.fresh_iterations() + REBUILD_AFTER_ITERATIONS,
                Starting::Fresh if fresh_rebuilds > 0 => REBUILD_AFTER_ITERATIONS,
                _ => params.max_iterations,
            };
            let attempt = SolveParams {
                max_iterations: cap.min(params.max_iterations),
                ..params
            };
            // The curvature pairs of the last steps' solves are kept until the preconditioner
            // is rebuilt: 10 % fewer iterations on the catapult.
            match self
                .lbfgs
                .minimize_warm(&mut obj, &mut self.precond, z, attempt)
            {
                Ok(mut s) => {
                    self.precond_use.record(s.iterations);
                    s.iterations += spent;
                    return Ok(s);
                }
                Err(e @ (FemError::NotConverged { .. } | FemError::LineSearchFailed { .. })) => {
                    spent += match e {
                        FemError::NotConverged { iterations, .. } => iterations,
                        FemError::LineSearchFailed { iteration, .. } => iteration + 1,
                        _ => 0,
                    };
                    match precond {
                        Starting::Aged => {}
                        Starting::Fresh if fresh_rebuilds > 0 => fresh_rebuilds -= 1,
                        _ => break e,
                    }
                    // L-BFGS accepts only steps that lower the energy: the iterate is at
                    // least as good as the start, and the matrix there sees the motion so far.
                    let start = Instant::now();
                    let factored = obj.factor_gauss_newton(z, &mut self.precond, "preconditioner");
                    obj.work.timers.precond += start.elapsed().as_secs_f64();
                    if factored.is_err() {
                        break e;
                    }
                    precond = Starting::Fresh;
                    self.precond_use.restart();
                    self.lbfgs.reset();
                    self.rebuilt_in_solve = true;
                }
                Err(e) => return Err(e),
            }
        };
        // Where the energy curves far more than even a fresh preconditioner says (a nearly
        // degenerate element along the subspace), L-BFGS crawls: redo the step with Newton on
        // the reduced Hessian. A current-state preconditioner is rebuilt at the next step's
        // start: the count of this solve would make a poor yardstick for the next ones.
        tracing::info!("{e}; retrying the step with reduced Newton");
        self.fell_back = true;
        if starting != Starting::Fixed {
            self.precond_active = None;
        }
        self.lbfgs.reset();
        z.copy_from_slice(&self.state.z);
        // A retry that fails too is said as both solvers' failure, with every iteration spent
        // (a paper reproducer's scene of `[reduced] method = "lbfgs"` read "Newton did not
        // converge", as the full-space simulator's message once did).
        const BOTH: &str = "L-BFGS, then reduced Newton from the step's start";
        let mut s = newton(&mut obj, z, params).map_err(|e| match e {
            FemError::NotConverged {
                step,
                iterations,
                residual,
                tolerance,
                ..
            } => FemError::NotConverged {
                solver: BOTH,
                step,
                iterations: iterations + spent,
                residual,
                tolerance,
            },
            FemError::LineSearchFailed {
                step, iteration, ..
            } => FemError::LineSearchFailed {
                solver: BOTH,
                step,
                iteration: iteration + spent,
            },
            e => e,
        })?;
        s.iterations += spent;
        Ok(s)
    }

    /// The inertial prediction q̃ = q_n + h q̇_n of the next step (q_n when quasi-static).
    fn predict(&mut self) {
        let h = self.time.step;
        for i in 0..self.space.k {
            self.work.predicted[i] = if self.time.quasi_static {
                self.state.q[i]
            } else {
                self.state.q[i] + h * self.state.qdot[i]
            };
        }
    }

    /// The objective of the next step, for the current state.
    fn step_objective(&mut self) -> StepObjective<'_, S> {
        let h = self.time.step;
        self.predict();
        let inv_h2 = self.inv_h2();
        StepObjective {
            model: &self.model,
            space: &self.space,
            subspace: &mut self.subspace,
            work: &mut self.work,
            t: (self.state.step + 1) as f64 * h,
            inv_h2,
            scale: 0.0,
            noise: 0.0,
        }
    }

    /// The next step's objective E(z) and its gradient (into `g`), for the current state: what
    /// [`step`](Self::step) minimises. For diagnostics and derivative checks.
    pub fn objective(&mut self, z: &[f64], g: &mut [f64]) -> f64 {
        self.step_objective().value_gradient(z, g)
    }

    /// The next step's Newton matrix Jᵀ H_q J at z (d×d, column-major, into `out`), H_q the
    /// reduced Hessian in q with the element tangents projected when `projected`: the exact
    /// Hessian of [`objective`](Self::objective) for a linear subspace, its Gauss–Newton part
    /// otherwise. For diagnostics and derivative checks.
    pub fn newton_matrix(&mut self, z: &[f64], projected: bool, out: &mut [f64]) {
        let mut obj = self.step_objective();
        obj.newton_matrix_constant(z);
        obj.newton_matrix(projected);
        out.copy_from_slice(&obj.work.hz);
    }

    /// The energies of the current state: elastic over the subspace's element set (the cubature
    /// rule when there is one, the energy the solver minimises), kinetic ½ q̇ᵀ(UᵀMU)q̇, and the
    /// potential of gravity and of the forces active now.
    pub fn energy(&mut self) -> ReducedEnergy {
        let (model, space, w) = (&self.model, &self.space, &mut self.work);
        let elastic = space.elastic_energy_gradient(
            model,
            &self.state.q,
            &mut w.u,
            &mut w.grad_full,
            &mut w.grad_q,
            &mut w.space,
        );
        let k = space.k;
        let mut kinetic = 0.0;
        for i in 0..k {
            let mut m = 0.0;
            for j in 0..k {
                m += space.mass[j * k + i] * self.state.qdot[j];
            }
            kinetic += 0.5 * self.state.qdot[i] * m;
        }
        let mut external = -dot(&space.gravity, &self.state.q);
        for i in 0..model.forces.len() {
            let t = self.state.time;
            external += space
                .force_energy_gradient(model, i, t, &self.state.q, &mut w.tmp_q, &mut w.space)
                .0;
        }
        ReducedEnergy {
            elastic,
            kinetic,
            external,
            total: elastic + kinetic + external,
        }
    }

    /// The full displacement of the current state (3 per vertex): u = Uq, plus the dent each
    /// softened spring makes in its patch (see [`Self::set_spring_compliance`]).
    pub fn full_displacement(&self) -> Vec<f64> {
        let mut u = vec![0.0; self.model.num_full()];
        self.displacement_into(&mut u);
        u
    }

    /// [`Self::full_displacement`] into `u` (of the model's full length).
    pub fn displacement_into(&self, u: &mut [f64]) {
        self.displacement_with_dents(u);
    }
}

/// The objective of one reduced step, over latent coordinates z.
struct StepObjective<'a, S: Subspace> {
    model: &'a FullSpaceModel,
    space: &'a ReducedSpace,
    subspace: &'a mut S,
    work: &'a mut Work,
    t: f64,
    inv_h2: f64,
    scale: f64,
    noise: f64,
}

impl<S: Subspace> StepObjective<'_, S> {
    /// E and ∂E/∂q at q = decode(z) (into work.grad_q).
    fn energy_q(&mut self, z: &[f64]) -> f64 {
        let (model, space, w) = (self.model, self.space, &mut *self.work);
        let t0 = Instant::now();
        w.timers.evaluations += 1;
        self.subspace.decode(z, &mut w.q);
        let t1 = Instant::now();
        let elastic = space.elastic_energy_gradient(
            model,
            &w.q,
            &mut w.u,
            &mut w.grad_full,
            &mut w.grad_q,
            &mut w.space,
        );
        w.timers.decode += (t1 - t0).as_secs_f64();
        w.timers.elastic += t1.elapsed().as_secs_f64();
        let mut scale = norm(&w.grad_q);
        // Gravity (linear in q) and the active springs / point loads, as functions of q.
        let mut external = -dot(&space.gravity, &w.q);
        let mut external_size = external.abs();
        // tmp_q collects ∂(external)/∂q.
        for (t, g) in w.tmp_q.iter_mut().zip(&space.gravity) {
            *t = -g;
        }
        for i in 0..model.forces.len() {
            let (e, size) =
                space.force_energy_gradient(model, i, self.t, &w.q, &mut w.tmp_q, &mut w.space);
            external += e;
            external_size += size;
        }
        scale = scale.max(norm(&w.tmp_q));
        for i in 0..space.k {
            w.grad_q[i] += w.tmp_q[i];
        }
        let mut inertia = 0.0;
        if self.inv_h2 > 0.0 {
            let k = space.k;
            for i in 0..k {
                w.tmp_q[i] = w.q[i] - w.predicted[i];
            }
            // (UᵀMU)(q − q̃) by columns: the same sums as row by row, vectorised.
            w.mass_q.fill(0.0);
            for (j, &x) in w.tmp_q.iter().enumerate() {
                axpy(x, &space.mass[j * k..(j + 1) * k], &mut w.mass_q);
            }
            let mut in_norm2 = 0.0;
            for i in 0..k {
                let m = w.mass_q[i];
                inertia += 0.5 * self.inv_h2 * w.tmp_q[i] * m;
                w.grad_q[i] += self.inv_h2 * m;
                in_norm2 += (self.inv_h2 * m).powi(2);
            }
            scale = scale.max(in_norm2.sqrt());
        }
        self.scale = scale.max(w.gradient_floor);
        self.noise = 16.0
            * f64::EPSILON
            * (model.energy_scale + elastic.abs() + external_size + inertia.abs());
        elastic + external + inertia
    }
}

impl<S: Subspace> Objective for StepObjective<'_, S> {
    fn dim(&self) -> usize {
        self.subspace.latent_dim()
    }

    fn value_gradient(&mut self, z: &[f64], g: &mut [f64]) -> f64 {
        let e = self.energy_q(z);
        let t0 = Instant::now();
        self.subspace.vjp(z, &self.work.grad_q, g);
        self.work.timers.vjp += t0.elapsed().as_secs_f64();
        // The gradient's scale was taken in q; g = Jᵀ ∂E/∂q is in z. A decoder whose outputs
        // are small next to its inputs (a stiff body's millimetre coefficients from O(1)
        // latent coordinates) shrinks every gradient by the size of J, and a relative gradient
        // against the q scale then met the tolerance at the start of every step: the body
        // never moved (an AutoDef bar, classic Neo-Hookean, neural methods 100 % off). 1 for a
        // linear subspace, so the PCA methods are as before.
        self.scale *= self.work.jacobian_scale;
        e
    }

    fn gradient_scale(&self) -> f64 {
        self.scale
    }

    fn value_noise(&self) -> f64 {
        self.noise
    }
}

impl<S: Subspace> NewtonSystem for StepObjective<'_, S> {
    /// Gauss–Newton in z: (Jᵀ H_q J) d = −g, exact Newton for a linear subspace. As in full
    /// space, H_q is first the exact reduced Hessian (elastic + UᵀMU/h² + springs); only when
    /// that is not positive definite are the element tangents projected.
    fn newton_direction(&mut self, z: &[f64], g: &[f64], d: &mut [f64]) -> Result<(), FemError> {
        let start = Instant::now();
        let mut factor = std::mem::take(&mut self.work.newton);
        let factored = self.factor_gauss_newton(z, &mut factor, "Newton");
        self.work.newton = factor;
        factored.map_err(|_| {
            FemError::Factorization("reduced Hessian is not positive definite".into())
        })?;
        d.iter_mut().zip(g).for_each(|(d, g)| *d = -g);
        self.work.newton.solve_in_place(d);
        self.work.timers.newton += start.elapsed().as_secs_f64();
        Ok(())
    }
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// The root-mean-square Euclidean norm of the columns of the k-row column-major `m` (1 for
/// the columns of an identity); 1 for an empty matrix.
pub(super) fn rms_column_norm(m: &[f64], k: usize) -> f64 {
    let cols = m.len() / k.max(1);
    if cols == 0 {
        return 1.0;
    }
    (m.iter().map(|x| x * x).sum::<f64>() / cols as f64).sqrt()
}

/// Gradients (in q, whose coordinates are displacements times √mass) below 10⁻¹² of the body's
/// characteristic elastic force E·V/L, over √M, are round-off: at rest with nothing acting every
/// term of the step's gradient is, and a gradient relative to them alone never converged (a
/// neural model with gravity off failed its first step). Far below any load: gravity's gradient
/// is √M·g, about 10⁹ times this on a 2 MPa bar and 10¹¹ on the soft default cantilever.
fn gradient_floor(model: &FullSpaceModel) -> f64 {
    let (lo, hi) = model.mesh.bounding_box();
    let size = (hi - lo).norm();
    let mass: f64 = model.mass.lumped.iter().sum();
    if size > 0.0 && mass > 0.0 {
        1e-12 * model.energy_scale / (size * mass.sqrt())
    } else {
        0.0
    }
}
