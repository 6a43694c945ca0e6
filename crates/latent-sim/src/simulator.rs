//! The reduced implicit Euler time stepper, generic over the subspace.

use std::time::Instant;

use faer::Side;
use faer::linalg::solvers::Solve;
use fem_core::FemError;
use fem_core::assembly::AssemblyBuffers;
use fem_core::integrator::{FullSpaceModel, TimeConfig};
use fem_core::optim::{
    Lbfgs, NewtonSystem, Objective, Preconditioner, SolveParams, SolveStats, SolverConfig,
    SolverMethod, newton,
};
use fem_core::with_material;

use crate::reduced::{ReducedSpace, dot};
use crate::{ReducedError, Subspace};

/// Latent state: z, and the PCA coefficients q and their velocity q̇ carried between steps.
#[derive(Debug, Clone, PartialEq)]
pub struct ReducedState {
    pub step: usize,
    pub time: f64,
    pub z: Vec<f64>,
    pub q: Vec<f64>,
    pub qdot: Vec<f64>,
    /// (z_n − z_{n−1})/h: the next solve starts from z_n + h ż_n.
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
    /// Time building and factorising the preconditioner.
    pub precond_seconds: f64,
    /// Time decoding: the network's forward pass (q = decode(z)) and the partial decode Uq over
    /// the vertices the elastic energy touches.
    pub decode_seconds: f64,
    /// Time in the elastic energy and its reduced gradient over the (cubature) elements.
    pub elastic_seconds: f64,
    /// Time in the decoder's vector–Jacobian product Jᵀ ∂E/∂q.
    pub vjp_seconds: f64,
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

/// Time spent in each part of the objective, accumulated over one step.
#[derive(Debug, Clone, Copy, Default)]
struct Timers {
    decode: f64,
    elastic: f64,
    vjp: f64,
}

/// Dense SPD factor used as a preconditioner (z = P⁻¹ r).
#[derive(Debug)]
struct DenseFactor(faer::linalg::solvers::Llt<f64>);

impl Preconditioner for DenseFactor {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        z.copy_from_slice(r);
        let n = z.len();
        self.0
            .solve_in_place(faer::MatMut::from_column_major_slice_mut(z, n, 1));
    }
}

/// Factorises a symmetric d×d matrix (column-major), adding a growing diagonal shift when it is
/// only semidefinite.
fn factor_dense(a: &[f64], d: usize, what: &'static str) -> Result<DenseFactor, ReducedError> {
    let mean = (0..d).map(|i| a[i * d + i].abs()).sum::<f64>() / d.max(1) as f64;
    let mut shift = 0.0;
    for _ in 0..12 {
        let m =
            faer::Mat::<f64>::from_fn(d, d, |i, j| a[j * d + i] + if i == j { shift } else { 0.0 });
        if let Ok(llt) = m.llt(Side::Lower) {
            return Ok(DenseFactor(llt));
        }
        shift = if shift == 0.0 {
            1e-12 * mean.max(f64::MIN_POSITIVE)
        } else {
            shift * 10.0
        };
    }
    Err(ReducedError::NotPositiveDefinite { what })
}

/// Implicit Euler in a subspace.
#[derive(Debug)]
pub struct ReducedSimulator<S: Subspace> {
    pub model: FullSpaceModel,
    pub space: ReducedSpace,
    pub subspace: S,
    pub time: TimeConfig,
    pub solver: SolverConfig,
    pub state: ReducedState,
    work: Work,
    lbfgs: Lbfgs,
    /// For a linear subspace the preconditioner only changes when a force switches on or off:
    /// it is factorised for the active set recorded beside it.
    fixed_precond: Option<(Vec<bool>, DenseFactor)>,
}

/// Reusable buffers of one step.
#[derive(Debug)]
struct Work {
    u: Vec<f64>,
    grad_full: Vec<f64>,
    q: Vec<f64>,
    grad_q: Vec<f64>,
    tmp_q: Vec<f64>,
    predicted: Vec<f64>,
    jac: Vec<f64>,
    buffers: AssemblyBuffers,
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
                predicted: vec![0.0; k],
                jac: vec![0.0; k * d],
                buffers: AssemblyBuffers::default(),
                timers: Timers::default(),
            },
            lbfgs: Lbfgs::new(d, solver.lbfgs_memory),
            fixed_precond: None,
            model,
            space,
            subspace,
            time,
            solver,
        };
        Ok(sim)
    }

    /// Jᵀ (UᵀK₀U + UᵀMU/h² + Σ k_s/n U_vᵀU_v) J at the current z (d×d, column-major): every
    /// constant quadratic term of the step energy, including the springs active at time `t`
    /// (a stiff spring left out of the preconditioner stalls L-BFGS along its direction).
    fn preconditioner_matrix(&mut self, t: f64) -> Vec<f64> {
        let (k, d) = (self.space.k, self.subspace.latent_dim());
        let inv_h2 = self.inv_h2();
        let mut a: Vec<f64> = self
            .space
            .rest_stiffness
            .iter()
            .zip(&self.space.mass)
            .map(|(kk, m)| kk + inv_h2 * m)
            .collect();
        for f in &self.model.forces {
            if f.is_active(t) && f.stiffness > 0.0 {
                let s = f.stiffness / f.vertices.len() as f64;
                for &v in &f.vertices {
                    let r = self.space.vertex_rows(v);
                    for c in 0..3 {
                        let row = &r[c * k..(c + 1) * k];
                        for b in 0..k {
                            for i in 0..k {
                                a[b * k + i] += s * row[i] * row[b];
                            }
                        }
                    }
                }
            }
        }
        self.subspace.jacobian(&self.state.z, &mut self.work.jac);
        sandwich(&a, &self.work.jac, k, d)
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
        let params = SolveParams {
            tolerance: self.solver.tolerance,
            max_iterations: self.solver.max_iterations,
            step: self.state.step + 1,
        };
        let pstart = Instant::now();
        let mut varying = None;
        if self.solver.method == SolverMethod::Lbfgs {
            let d = self.subspace.latent_dim();
            if self.subspace.is_linear() {
                let active: Vec<bool> = self.model.forces.iter().map(|f| f.is_active(t)).collect();
                if self
                    .fixed_precond
                    .as_ref()
                    .is_none_or(|(a, _)| *a != active)
                {
                    let p = self.preconditioner_matrix(t);
                    self.fixed_precond = Some((active, factor_dense(&p, d, "preconditioner")?));
                }
            } else {
                let p = self.preconditioner_matrix(t);
                varying = Some(factor_dense(&p, d, "preconditioner")?);
            }
        }
        let precond_seconds = pstart.elapsed().as_secs_f64();
        // Warm start on the latent trajectory's tangent: the minimiser moves little from z_n + h ż_n
        // in smooth motion (AutoDef started at z_n).
        let mut z: Vec<f64> = if self.time.quasi_static {
            self.state.z.clone()
        } else {
            self.state
                .z
                .iter()
                .zip(&self.state.zdot)
                .map(|(z, v)| z + h * v)
                .collect()
        };
        let inv_h2 = self.inv_h2();
        let stats: SolveStats = {
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
            match self.solver.method {
                SolverMethod::Lbfgs => {
                    let pre = match varying.as_mut() {
                        Some(p) => p,
                        None => {
                            &mut self
                                .fixed_precond
                                .as_mut()
                                .expect("linear subspaces factor before the solve")
                                .1
                        }
                    };
                    let start_z = z.clone();
                    match self.lbfgs.minimize(&mut obj, pre, &mut z, params) {
                        Ok(s) => s,
                        // Where the energy curves far more than the rest-state preconditioner
                        // says (a nearly degenerate element along the subspace), L-BFGS crawls:
                        // redo the step with Newton on the reduced Hessian.
                        Err(
                            e @ (FemError::NotConverged { .. } | FemError::LineSearchFailed { .. }),
                        ) => {
                            tracing::info!("{e}; retrying the step with reduced Newton");
                            z.copy_from_slice(&start_z);
                            let mut s = newton(&mut obj, &mut z, params)?;
                            s.iterations += params.max_iterations;
                            s
                        }
                        Err(e) => return Err(e.into()),
                    }
                }
                SolverMethod::Newton => newton(&mut obj, &mut z, params)?,
            }
        };
        let mut q_new = vec![0.0; k];
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
        self.state.q = q_new;
        for (v, (new, old)) in self.state.zdot.iter_mut().zip(z.iter().zip(&self.state.z)) {
            *v = if self.time.quasi_static {
                0.0
            } else {
                (new - old) / h
            };
        }
        self.state.z = z;
        self.state.step += 1;
        self.state.time = t;
        Ok(ReducedStepReport {
            step: self.state.step,
            time: t,
            iterations: stats.iterations,
            relative_gradient: stats.relative_gradient,
            wall_seconds: start.elapsed().as_secs_f64(),
            precond_seconds,
            decode_seconds: self.work.timers.decode,
            elastic_seconds: self.work.timers.elastic,
            vjp_seconds: self.work.timers.vjp,
        })
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

    /// The next step's objective E(z) and its gradient (into `g`), for the current state: what
    /// [`step`](Self::step) minimises. For diagnostics and derivative checks.
    pub fn objective(&mut self, z: &[f64], g: &mut [f64]) -> f64 {
        let h = self.time.step;
        self.predict();
        let inv_h2 = self.inv_h2();
        let mut obj = StepObjective {
            model: &self.model,
            space: &self.space,
            subspace: &mut self.subspace,
            work: &mut self.work,
            t: (self.state.step + 1) as f64 * h,
            inv_h2,
            scale: 0.0,
            noise: 0.0,
        };
        obj.value_gradient(z, g)
    }

    /// The energies of the current state: elastic over the subspace's element set (the cubature
    /// rule when there is one, the energy the solver minimises), kinetic ½ q̇ᵀ(UᵀMU)q̇, and the
    /// potential of gravity and of the forces active now.
    pub fn energy(&mut self) -> ReducedEnergy {
        let (model, space, w) = (&self.model, &self.space, &mut self.work);
        space.decode_touched(&self.state.q, &mut w.u);
        let elastic = space.elastic_energy_gradient(
            model,
            &w.u,
            &mut w.grad_full,
            &mut w.grad_q,
            &mut w.buffers,
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
        for f in &model.forces {
            if f.is_active(self.state.time) {
                external += f.accumulate(self.state.time, &w.u, None, None);
            }
        }
        ReducedEnergy {
            elastic,
            kinetic,
            external,
            total: elastic + kinetic + external,
        }
    }

    /// The full displacement u = Uq of the current state (3 per vertex).
    pub fn full_displacement(&self) -> Vec<f64> {
        let mut u = vec![0.0; self.model.num_full()];
        self.space.reconstruct(&self.state.q, &mut u);
        u
    }
}

/// Bᵀ A B for A k×k and B k×d (column-major).
fn sandwich(a: &[f64], b: &[f64], k: usize, d: usize) -> Vec<f64> {
    let mut ab = vec![0.0; k * d];
    for j in 0..d {
        for l in 0..k {
            let blj = b[j * k + l];
            if blj != 0.0 {
                for i in 0..k {
                    ab[j * k + i] += a[l * k + i] * blj;
                }
            }
        }
    }
    let mut out = vec![0.0; d * d];
    for j in 0..d {
        for i in 0..d {
            out[j * d + i] = dot(&b[i * k..(i + 1) * k], &ab[j * k..(j + 1) * k]);
        }
    }
    out
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
        self.subspace.decode(z, &mut w.q);
        space.decode_touched(&w.q, &mut w.u);
        let t1 = Instant::now();
        let elastic = space.elastic_energy_gradient(
            model,
            &w.u,
            &mut w.grad_full,
            &mut w.grad_q,
            &mut w.buffers,
        );
        w.timers.decode += (t1 - t0).as_secs_f64();
        w.timers.elastic += t1.elapsed().as_secs_f64();
        let mut scale = norm(&w.grad_q);
        // Gravity (linear in q) and the active springs / point loads, through their rows only.
        let mut external = -dot(&space.gravity, &w.q);
        // tmp_q collects ∂(external)/∂q: −Uᵀf_g plus the projected force gradients.
        for (t, g) in w.tmp_q.iter_mut().zip(&space.gravity) {
            *t = -g;
        }
        for f in &model.forces {
            if !f.is_active(self.t) {
                continue;
            }
            for &v in &f.vertices {
                w.grad_full[3 * v..3 * v + 3].fill(0.0);
            }
            external += f.accumulate(self.t, &w.u, Some(&mut w.grad_full), None);
            space.project_vertices_add(&w.grad_full, &f.vertices, &mut w.tmp_q);
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
            let mut in_norm2 = 0.0;
            for i in 0..k {
                let mut m = 0.0;
                for j in 0..k {
                    m += space.mass[j * k + i] * w.tmp_q[j];
                }
                inertia += 0.5 * self.inv_h2 * w.tmp_q[i] * m;
                w.grad_q[i] += self.inv_h2 * m;
                in_norm2 += (self.inv_h2 * m).powi(2);
            }
            scale = scale.max(in_norm2.sqrt());
        }
        self.scale = scale;
        self.noise = 16.0
            * f64::EPSILON
            * (model.energy_scale + elastic.abs() + external.abs() + inertia.abs());
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
        let (model, space) = (self.model, self.space);
        let k = space.k;
        let dim = self.subspace.latent_dim();
        let w = &mut *self.work;
        self.subspace.decode(z, &mut w.q);
        space.decode_touched(&w.q, &mut w.u);
        self.subspace.jacobian(z, &mut w.jac);
        let mut hq = vec![0.0; k * k];
        let mut factor = None;
        for projected in [false, true] {
            with_material!(&model.material, |m| {
                space.project_hessian(
                    model,
                    m,
                    &space.elements,
                    &space.weights,
                    &w.u,
                    projected,
                    &mut hq,
                );
            });
            for i in 0..k * k {
                hq[i] += self.inv_h2 * space.mass[i];
            }
            for f in &model.forces {
                if f.is_active(self.t) {
                    let s = f.stiffness / f.vertices.len() as f64;
                    for &v in &f.vertices {
                        let r = space.vertex_rows(v);
                        for c in 0..3 {
                            let row = &r[c * k..(c + 1) * k];
                            for b in 0..k {
                                for a in 0..k {
                                    hq[b * k + a] += s * row[a] * row[b];
                                }
                            }
                        }
                    }
                }
            }
            let hz = sandwich(&hq, &w.jac, k, dim);
            if projected {
                factor = Some(factor_dense(&hz, dim, "Newton").map_err(|_| {
                    FemError::Factorization("reduced Hessian is not positive definite".into())
                })?);
            } else {
                let m = faer::Mat::<f64>::from_fn(dim, dim, |i, j| hz[j * dim + i]);
                if let Ok(llt) = m.llt(Side::Lower) {
                    factor = Some(DenseFactor(llt));
                    break;
                }
            }
        }
        let mut f = factor.expect("the projected attempt yields a factor or an error");
        for i in 0..dim {
            d[i] = -g[i];
        }
        let r = d.to_vec();
        f.apply(&r, d);
        Ok(())
    }
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}
