//! The full-space time stepper: state, per-step report, the solve of each step by Newton or
//! preconditioned L-BFGS (with the preconditioner's refresh policy, and a step either solver
//! cannot finish finished by the other from where it stopped),
//! and quasi-static load stepping.

use std::time::Instant;

use super::aged_reuse::AgedReuse;
use super::step_objective::StepObjective;
use super::system_matrix::BodyRotation;
use super::{FactoredPreconditioner, FullSpaceModel, NewtonParts, TimeConfig};
use crate::FemError;
use crate::assembly::{self, AssemblyBuffers, ElementSet};
use crate::optim::{
    Lbfgs, LbfgsPreconditioner, PreconditionerUse, SolveParams, SolverConfig, SolverMethod, newton,
};
use crate::sparse_cholesky::SparseCholesky;
use crate::with_material;

/// The iteration cap of a step's retry with the other solver, in multiples of
/// `[solver] max_iterations`.
pub const RETRY_BUDGET: usize = 4;

/// Per-frame numbers, also written to `summary.json`.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct StepReport {
    pub step: usize,
    pub time: f64,
    pub iterations: usize,
    pub relative_gradient: f64,
    pub wall_seconds: f64,
    pub elastic_energy: f64,
    pub kinetic_energy: f64,
    /// Φ(u) − f_gᵀu: potential of gravity and of the forces active at this time.
    pub external_energy: f64,
    /// Elastic + kinetic + external.
    pub total_energy: f64,
    pub max_displacement: f64,
    /// Load-stepping sub-solves taken (quasi-static only; 0 when the direct solve converged).
    pub load_steps: usize,
    /// The scene's solver could not finish a solve of this step and the other one went on
    /// from where it stopped.
    pub solver_switched: bool,
    /// L-BFGS's preconditioner was assembled and factorised during this step.
    pub preconditioner_factorised: bool,
}

/// Simulation state: displacement and velocity (full vectors) at time `time`.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    pub step: usize,
    pub time: f64,
    pub u: Vec<f64>,
    pub v: Vec<f64>,
}

/// Full-space implicit Euler time stepper. A clone steps exactly as the original would from
/// where it was made; its factors are copies with their own record of which precisions failed.
#[derive(Debug)]
pub struct Simulator {
    pub model: FullSpaceModel,
    pub time: TimeConfig,
    pub solver: SolverConfig,
    pub state: State,
    buffers: AssemblyBuffers,
    newton: Option<NewtonParts>,
    lbfgs: Option<LbfgsParts>,
    lbfgs_factorizations: usize,
    /// Whether a solve of the step under way went on with the other solver.
    switched: bool,
    /// ü_n = (u̇_n − u̇_{n−1})/h (full) and the step n it belongs to: a start hint only.
    acceleration: Option<(usize, Vec<f64>)>,
}

/// Steps a current-state L-BFGS preconditioner serves at most before it is refactorised.
pub const PRECOND_MAX_AGE: usize = 16;

/// What assembling and factorising the preconditioner costs, in L-BFGS iterations (an energy and
/// gradient evaluation plus two triangular solves). Measured on 2 cores: 25 ms against 2.5 ms per
/// iteration on the catapult (9.8k DOFs), 1.3 ms against 0.15 ms on an earlier default cantilever
/// (1.5k DOFs). A fixed figure rather than a timing, so that when a factor is refreshed (and so the
/// trajectory, at the solver's tolerance) never depends on the machine's load.
const REFACTOR_COST_ITERATIONS: usize = 10;

/// L-BFGS with the factor that preconditions it, and how well that factor still serves.
#[derive(Debug, Clone)]
struct LbfgsParts {
    lbfgs: Lbfgs,
    pre: FactoredPreconditioner,
    /// How the factor has served; a current-state factor goes stale once its later solves'
    /// extra iterations add up to [`REFACTOR_COST_ITERATIONS`] or after [`PRECOND_MAX_AGE`].
    usage: PreconditionerUse,
    /// A solve with the factor failed: the next one refactorises.
    failed: bool,
    /// For a current-state factor: the free displacements it was made at, and how to find the
    /// body's turn since then, which each solve applies to it
    /// ([`FactoredPreconditioner`]'s rotation).
    made_at: Vec<f64>,
    turn: Option<BodyRotation>,
    /// Whether a step should skip the aged factor: kept across refactorisations.
    reuse: AgedReuse,
}

impl Clone for Simulator {
    fn clone(&self) -> Self {
        let mut newton = self.newton.clone();
        let mut lbfgs = self.lbfgs.clone();
        // The factors of one simulation share which precisions their matrices failed; a copy
        // gets that record as it is now, its own from then on.
        let mut factors: Vec<&mut SparseCholesky> = newton
            .iter_mut()
            .map(|n| &mut n.chol)
            .chain(lbfgs.iter_mut().map(|l| &mut l.pre.chol))
            .collect();
        if let Some((first, rest)) = factors.split_first_mut() {
            let flags = first.own_rejections();
            for f in rest {
                f.share_rejections(&flags);
            }
        }
        Self {
            model: self.model.clone(),
            time: self.time.clone(),
            solver: self.solver.clone(),
            state: self.state.clone(),
            buffers: self.buffers.clone(),
            newton,
            lbfgs,
            lbfgs_factorizations: self.lbfgs_factorizations,
            switched: self.switched,
            acceleration: self.acceleration.clone(),
        }
    }
}

impl Simulator {
    /// A simulator at rest at time 0.
    pub fn new(
        model: FullSpaceModel,
        time: TimeConfig,
        solver: SolverConfig,
    ) -> Result<Self, FemError> {
        let mut errors = Vec::new();
        time.check(&mut errors);
        solver.check(&mut errors);
        FemError::collect(errors)?;
        if time.quasi_static
            && model.pinned.is_empty()
            && model
                .forces
                .iter()
                .all(|f| f.kind != crate::forces::ForceKind::Spring)
        {
            return Err(FemError::InvalidConfig {
                field: "pin".into(),
                reason: "a quasi-static scene needs pinned vertices or a spring to hold the body (otherwise it has no equilibrium)".into(),
            });
        }
        let n = model.num_full();
        Ok(Self {
            state: State {
                step: 0,
                time: 0.0,
                u: vec![0.0; n],
                v: vec![0.0; n],
            },
            model,
            time,
            solver,
            buffers: AssemblyBuffers::default(),
            newton: None,
            lbfgs: None,
            lbfgs_factorizations: 0,
            switched: false,
            acceleration: None,
        })
    }

    fn ensure_newton(&mut self) -> Result<(), FemError> {
        if self.newton.is_none() {
            self.newton = Some(NewtonParts::new(&self.model)?);
        }
        Ok(())
    }

    /// Makes L-BFGS's preconditioner ready for a solve from `x` at time `t`: K₀ + M/h² (K₀ alone
    /// when quasi-static) factorised once, or the projected Hessian + M/h² + springs at `x`,
    /// refactorised when missing, stale or [`PRECOND_MAX_AGE`] steps old (or when `refresh`).
    fn ensure_lbfgs(&mut self, x: &[f64], t: f64, refresh: bool) -> Result<(), FemError> {
        let current = self.solver.preconditioner == LbfgsPreconditioner::CurrentState;
        if let Some(p) = &self.lbfgs
            && !(current
                && (refresh
                    || p.failed
                    || p.usage.is_stale(PRECOND_MAX_AGE, REFACTOR_COST_ITERATIONS)))
        {
            return Ok(());
        }
        self.ensure_newton()?;
        let parts = self.newton.as_mut().expect("built above");
        let mut u = vec![0.0; self.model.num_full()];
        if current {
            self.model.dofs.scatter(x, &mut u);
        }
        with_material!(&self.model.material, |mat| assembly::hessian(
            mat,
            &self.model.elements,
            ElementSet::All,
            &u,
            true,
            &parts.pattern,
            &mut parts.values,
            &mut self.buffers
        ));
        if !self.time.quasi_static {
            parts.add_mass(&self.model, 1.0 / (self.time.step * self.time.step));
        }
        if current {
            let mut spring_diag = vec![0.0; u.len()];
            for f in &self.model.forces {
                f.accumulate(t, &u, None, Some(&mut spring_diag));
            }
            parts.add_diagonal(&self.model, &spring_diag);
        }
        parts.factor_preconditioner()?;
        self.lbfgs_factorizations += 1;
        // The new factor moves into the preconditioner; the old one's buffer goes back to
        // Newton's parts, to be overwritten by their next factorisation.
        match &mut self.lbfgs {
            Some(p) => {
                std::mem::swap(&mut p.pre.chol, &mut parts.chol);
                p.usage.restart();
                p.failed = false;
                p.made_at.copy_from_slice(x);
            }
            None => {
                let empty = parts.chol.same_pattern();
                let chol = std::mem::replace(&mut parts.chol, empty);
                self.lbfgs = Some(LbfgsParts {
                    lbfgs: Lbfgs::new(self.model.dofs.num_free(), self.solver.lbfgs_memory),
                    pre: FactoredPreconditioner {
                        chol,
                        rotation: None,
                    },
                    usage: PreconditionerUse::default(),
                    failed: false,
                    made_at: x.to_vec(),
                    turn: if current {
                        BodyRotation::new(&self.model)
                    } else {
                        None
                    },
                    reuse: AgedReuse::default(),
                })
            }
        }
        Ok(())
    }

    /// Back at rest at time 0. The symbolic factorisation is kept; L-BFGS's pairs are dropped
    /// and a preconditioner that depends on the state is refactorised by the next step.
    pub fn reset(&mut self) {
        self.state.step = 0;
        self.state.time = 0.0;
        self.state.u.fill(0.0);
        self.state.v.fill(0.0);
        self.acceleration = None;
        if let Some(p) = &mut self.lbfgs {
            p.reuse = AgedReuse::default();
        }
        self.forces_changed();
    }

    /// Tells the simulator that `model.forces` changed (a force added, removed or given another
    /// stiffness): L-BFGS's current-state preconditioner, which holds the springs' stiffness, is
    /// refactorised by the next step, and its pairs are dropped.
    pub fn forces_changed(&mut self) {
        if let Some(p) = &mut self.lbfgs {
            p.lbfgs.reset();
            p.failed = true;
        }
    }

    /// How many times L-BFGS's preconditioner has been assembled and factorised.
    pub fn lbfgs_factorizations(&self) -> usize {
        self.lbfgs_factorizations
    }

    /// Solves one minimisation at time `t` and load factor `load`, from `x` (free DOFs).
    /// A step the scene's solver cannot finish is redone with the other one.
    fn solve(
        &mut self,
        x: &mut [f64],
        t: f64,
        predicted: &[f64],
        load: f64,
    ) -> Result<crate::optim::SolveStats, FemError> {
        let params = SolveParams {
            tolerance: self.solver.tolerance,
            max_iterations: self.solver.max_iterations,
            step: self.state.step + 1,
        };
        let inv_h2 = if self.time.quasi_static {
            0.0
        } else {
            1.0 / (self.time.step * self.time.step)
        };
        let first = match self.solver.method {
            SolverMethod::Newton => self.solve_newton(x, t, inv_h2, predicted, load, params),
            SolverMethod::Lbfgs => self.solve_lbfgs(x, t, inv_h2, predicted, load, params),
        };
        let spent = match first {
            Err(FemError::NotConverged { iterations, .. }) => iterations,
            Err(FemError::LineSearchFailed { iteration, .. }) => iteration + 1,
            other => return other,
        };
        // Each solver crawls where the other does not: L-BFGS where the energy curves far more
        // than its preconditioner says (strongly compressed elements), Newton with projected
        // Hessians through large rotations of the whole body, where the projection drops the
        // curvature that would turn it. Go on with the other one from where the first stopped,
        // counting the iterations spent: both accept only steps that lower the energy, so that
        // point is at least as good as the start, and often most of the way (a soft beam whose
        // root snaps through in one step: L-BFGS had the gradient down to 10⁻³ of its scale
        // after its 100 iterations; Newton from the step's start needed 60 more and 9 s).
        // The retry gets RETRY_BUDGET times the iteration cap: a step that needs it is a rare
        // one (a body toppling, a patch dragged far), and failing it ends the whole trajectory.
        let e = first.expect_err("errors only reach here");
        self.switched = true;
        let params = SolveParams {
            max_iterations: RETRY_BUDGET * params.max_iterations,
            ..params
        };
        let retry = match self.solver.method {
            SolverMethod::Newton => {
                tracing::info!("{e}; retrying the step with L-BFGS");
                self.solve_lbfgs(x, t, inv_h2, predicted, load, params)
            }
            SolverMethod::Lbfgs => {
                tracing::info!("{e}; retrying the step with Newton");
                self.solve_newton(x, t, inv_h2, predicted, load, params)
            }
        };
        // A retry that fails too is said as both solvers' failure, with every iteration spent:
        // "L-BFGS did not converge" alone reads as the scene's solver failing on its own.
        let both = match self.solver.method {
            SolverMethod::Newton => "Newton, then L-BFGS from where it stopped",
            SolverMethod::Lbfgs => "L-BFGS, then Newton from where it stopped",
        };
        match retry {
            Ok(mut s) => {
                s.iterations += spent;
                Ok(s)
            }
            Err(FemError::NotConverged {
                step,
                iterations,
                residual,
                tolerance,
                ..
            }) => Err(FemError::NotConverged {
                solver: both,
                step,
                iterations: iterations + spent,
                residual,
                tolerance,
            }),
            Err(FemError::LineSearchFailed {
                step, iteration, ..
            }) => Err(FemError::LineSearchFailed {
                solver: both,
                step,
                iteration: iteration + spent,
            }),
            Err(e) => Err(e),
        }
    }

    /// One minimisation by Newton with projected Hessians.
    fn solve_newton(
        &mut self,
        x: &mut [f64],
        t: f64,
        inv_h2: f64,
        predicted: &[f64],
        load: f64,
        params: SolveParams,
    ) -> Result<crate::optim::SolveStats, FemError> {
        self.ensure_newton()?;
        let mut obj = StepObjective::new(
            &self.model,
            &mut self.buffers,
            self.newton.as_mut(),
            t,
            inv_h2,
            predicted,
            load,
        );
        newton(&mut obj, x, params)
    }

    /// One minimisation by preconditioned L-BFGS; an aged preconditioner is refreshed once when
    /// the solve with it fails.
    fn solve_lbfgs(
        &mut self,
        x: &mut [f64],
        t: f64,
        inv_h2: f64,
        predicted: &[f64],
        load: f64,
        params: SolveParams,
    ) -> Result<crate::optim::SolveStats, FemError> {
        let current = self.solver.preconditioner == LbfgsPreconditioner::CurrentState;
        // Iterations of cut-short attempts, counted into the step's total.
        let mut spent = 0;
        // Where aged factors keep failing their first reuse, a step starts with a fresh one.
        let mut refresh = current
            && self
                .lbfgs
                .as_mut()
                .is_some_and(|p| p.usage.solves() > 0 && p.reuse.skips_aged());
        loop {
            self.ensure_lbfgs(x, t, refresh)?;
            let parts = self.lbfgs.as_mut().expect("built above");
            let fresh = parts.usage.solves() == 0;
            parts.pre.rotation = match &mut parts.turn {
                Some(turn) if !fresh => turn.between(&parts.made_at, x),
                _ => None,
            };
            // An aged factor gets the iterations a fresh one needed plus what a
            // refactorisation costs: once its extra iterations have cost that much, a fresh
            // factor at the current iterate would have been cheaper, whatever the rest of the
            // solve needs (L-BFGS goes on from there, nothing is lost). The cap used to be
            // twice the fresh count plus 4, which cut short the solve after one that a good
            // start had finished in 1 iteration at 6, and refactorised nearly every step: on
            // a training schedule of the catapult and of the suite's dinosaur 53 and 55
            // factorisations in 60 frames against 36 and 34 now (with the factor turned with
            // the body, above). Long first solves are cut sooner than before: the toppling
            // torus of the mesh suite refactorised 33 times instead of 18 at 10⁻⁶.
            let cap = if fresh || !current {
                params.max_iterations
            } else {
                params
                    .max_iterations
                    .min(parts.usage.fresh_iterations() + REFACTOR_COST_ITERATIONS)
            };
            let mut obj = StepObjective::new(
                &self.model,
                &mut self.buffers,
                None,
                t,
                inv_h2,
                predicted,
                load,
            );
            let attempt = SolveParams {
                max_iterations: cap,
                ..params
            };
            let mut result = parts.lbfgs.minimize(&mut obj, &mut parts.pre, x, attempt);
            match &mut result {
                Ok(s) => {
                    if !fresh {
                        parts.reuse.reuse_served();
                    }
                    parts.usage.record(s.iterations);
                    s.iterations += spent;
                }
                Err(e) => {
                    parts.failed = true;
                    spent += match *e {
                        FemError::NotConverged { iterations, .. } => iterations,
                        FemError::LineSearchFailed { iteration, .. } => iteration + 1,
                        _ => 0,
                    };
                }
            }
            let retry = matches!(
                result,
                Err(FemError::NotConverged { .. } | FemError::LineSearchFailed { .. })
            ) && current
                && !fresh;
            if !retry {
                return match result {
                    Err(FemError::NotConverged {
                        solver,
                        step,
                        residual,
                        tolerance,
                        ..
                    }) => Err(FemError::NotConverged {
                        solver,
                        step,
                        iterations: spent,
                        residual,
                        tolerance,
                    }),
                    other => other,
                };
            }
            if parts.usage.solves() == 1 {
                parts.reuse.first_reuse_failed();
            }
            refresh = true;
        }
    }

    /// Advances one time step (or one quasi-static frame) and reports it.
    pub fn step(&mut self) -> Result<StepReport, FemError> {
        let start = Instant::now();
        self.switched = false;
        let factorizations = self.lbfgs_factorizations;
        let h = self.time.step;
        // Times from the step count, not by accumulation, so frame times stay exact multiples.
        let t = (self.state.step + 1) as f64 * h;
        let nf = self.model.dofs.num_free();
        let mut x = vec![0.0; nf];
        self.model.dofs.gather(&self.state.u, &mut x);
        let predicted: Vec<f64> = if self.time.quasi_static {
            self.state.u.clone()
        } else {
            self.state
                .u
                .iter()
                .zip(&self.state.v)
                .map(|(u, v)| u + h * v)
                .collect()
        };
        match self.extrapolated_start(&predicted) {
            Some(guess) => x = guess,
            None => self.check_start(&x)?,
        }
        let mut load_steps = 0;
        let stats = match self.solve(&mut x, t, &predicted, 1.0) {
            Ok(s) => s,
            Err(
                e @ (FemError::NotConverged { .. }
                | FemError::LineSearchFailed { .. }
                | FemError::NonFinite { .. }),
            ) if self.time.quasi_static => {
                tracing::info!("direct static solve failed ({e}); stepping the load from rest");
                let (s, n) = self.load_stepping(&mut x, t, &predicted)?;
                load_steps = n;
                s
            }
            Err(e) => return Err(e),
        };
        let mut u_new = vec![0.0; self.model.num_full()];
        self.model.dofs.scatter(&x, &mut u_new);
        if u_new.iter().any(|v| !v.is_finite()) {
            return Err(FemError::NonFinite {
                what: "displacement",
                step: self.state.step + 1,
            });
        }
        if self.time.quasi_static {
            self.state.v.fill(0.0);
        } else {
            let mut a = match self.acceleration.take() {
                Some((_, a)) => a,
                None => vec![0.0; u_new.len()],
            };
            for i in 0..u_new.len() {
                let v = (u_new[i] - self.state.u[i]) / h;
                a[i] = (v - self.state.v[i]) / h;
                self.state.v[i] = v;
            }
            self.acceleration = Some((self.state.step + 1, a));
        }
        self.state.u = u_new;
        self.state.time = t;
        self.state.step += 1;
        let mut report = self.report();
        report.iterations = stats.iterations;
        report.relative_gradient = stats.relative_gradient;
        report.load_steps = load_steps;
        report.solver_switched = self.switched;
        report.preconditioner_factorised = self.lbfgs_factorizations > factorizations;
        report.wall_seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }

    /// The free DOFs of u_n + h u̇_n + h² ü_n (`predicted` is u_n + h u̇_n), when the last step
    /// left ü_n for this state and the elastic energy there is finite.
    fn extrapolated_start(&mut self, predicted: &[f64]) -> Option<Vec<f64>> {
        let h2 = self.time.step * self.time.step;
        let full: Vec<f64> = match &self.acceleration {
            Some((step, a)) if *step == self.state.step && !self.time.quasi_static => {
                predicted.iter().zip(a).map(|(p, a)| p + h2 * a).collect()
            }
            _ => return None,
        };
        let mut x = vec![0.0; self.model.dofs.num_free()];
        self.model.dofs.gather(&full, &mut x);
        let (_, e) = self.start_energy(&x);
        e.is_finite().then_some(x)
    }

    /// The full displacement of free DOFs `x` and its elastic energy.
    fn start_energy(&mut self, x: &[f64]) -> (Vec<f64>, f64) {
        let mut u = vec![0.0; self.model.num_full()];
        self.model.dofs.scatter(x, &mut u);
        let e = self.model.elastic_energy(&u, &mut self.buffers);
        (u, e)
    }

    /// Fails with a clear error when the current state is outside the material's domain.
    fn check_start(&mut self, x: &[f64]) -> Result<(), FemError> {
        let (u, e) = self.start_energy(x);
        if e.is_finite() {
            return Ok(());
        }
        match assembly::find_inverted(&self.model.elements, ElementSet::All, &u) {
            Some((element, det)) => Err(FemError::InvertedElement {
                element,
                det,
                material: self.model.material.name(),
            }),
            None => Err(FemError::NonFinite {
                what: "elastic energy",
                step: self.state.step + 1,
            }),
        }
    }

    /// Continuation in the load factor from rest: λ grows from 0 to 1 with adaptive increments,
    /// each solve starting from the previous equilibrium.
    fn load_stepping(
        &mut self,
        x: &mut [f64],
        t: f64,
        predicted: &[f64],
    ) -> Result<(crate::optim::SolveStats, usize), FemError> {
        let mut done = 0.0f64;
        let mut inc = 0.25f64;
        let mut solves = 0;
        let mut base = vec![0.0; x.len()];
        let mut total_iters = 0;
        loop {
            let target = (done + inc).min(1.0);
            let mut trial = base.clone();
            match self.solve(&mut trial, t, predicted, target) {
                Ok(s) => {
                    solves += 1;
                    total_iters += s.iterations;
                    base = trial;
                    done = target;
                    if done >= 1.0 {
                        x.copy_from_slice(&base);
                        let mut s = s;
                        s.iterations = total_iters;
                        return Ok((s, solves));
                    }
                    inc *= 2.0;
                }
                Err(
                    e @ (FemError::NotConverged { .. }
                    | FemError::LineSearchFailed { .. }
                    | FemError::NonFinite { .. }),
                ) => {
                    inc *= 0.5;
                    if inc < 1e-4 {
                        return Err(e);
                    }
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Energies and displacement of the current state.
    pub fn report(&mut self) -> StepReport {
        let u = &self.state.u;
        let elastic = self.model.elastic_energy(u, &mut self.buffers);
        let mut scratch = vec![0.0; u.len()];
        let kinetic = self
            .model
            .mass
            .half_norm_squared(&self.state.v, &mut scratch);
        let external = self.model.external_energy(u, self.state.time);
        let max_displacement = super::max_displacement(u);
        StepReport {
            step: self.state.step,
            time: self.state.time,
            elastic_energy: elastic,
            kinetic_energy: kinetic,
            external_energy: external,
            total_energy: elastic + kinetic + external,
            max_displacement,
            ..Default::default()
        }
    }
}
