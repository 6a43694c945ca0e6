//! `cargo xtask stress`: where each method breaks. Every method runs the held-out trajectory
//! under conditions far from the scene's (tiny and huge time steps, soft and stiff materials,
//! nearly incompressible material, forces beyond the training range, a long free run) and each
//! pair ends in `stable` (`"status": "ok"` in `stress.json`; with its error against full space under the
//! same condition, which is reported, not judged), `error` (a typed failure, reported) or
//! `diverged` (non-finite or unbounded state, or energy that rose
//! during the free run).
//!
//! The subspaces, autoencoder and cubature rules are the scene's own (trained once, at the
//! scene's parameters); only the simulation's physics changes, as a user changing a parameter
//! at run time would do.

use std::path::Path;

use anyhow::{Result, bail};
use fem_core::integrator::FullSpaceModel;

use crate::pipeline::{Pipeline, Progress};
use crate::scene::Scene;
use crate::simulate::{Method, Runner, solver_for, write_json};

/// One perturbation of the scene.
#[derive(Debug, Clone, PartialEq)]
pub enum Condition {
    /// The scene as it is.
    Base,
    /// Time step h (s).
    TimeStep(f64),
    /// Young's modulus multiplied by this factor.
    Stiffness(f64),
    /// Poisson ratio.
    Poisson(f64),
    /// The test trajectory's target offsets multiplied by this factor (forces beyond the
    /// training range).
    Forces(f64),
    /// The test trajectory, then free motion (no external force) up to this many steps in all:
    /// total energy must never rise after the release.
    FreeRun(usize),
}

impl Condition {
    pub fn label(&self) -> String {
        match self {
            Condition::Base => "base".into(),
            Condition::TimeStep(h) => format!("h = {h:e} s"),
            Condition::Stiffness(f) => format!("E × {f}"),
            Condition::Poisson(nu) => format!("ν = {nu}"),
            Condition::Forces(f) => format!("forces × {f}"),
            Condition::FreeRun(n) => format!("free run, {n} steps"),
        }
    }

    /// The conditions `cargo xtask stress` runs by default.
    pub fn defaults(free_steps: usize) -> Vec<Condition> {
        vec![
            Condition::Base,
            Condition::TimeStep(1e-4),
            Condition::TimeStep(1e-3),
            Condition::TimeStep(0.1),
            Condition::Stiffness(0.01),
            Condition::Stiffness(100.0),
            Condition::Poisson(0.495),
            Condition::Forces(3.0),
            Condition::FreeRun(free_steps),
        ]
    }

    /// The scene under this condition; its source names the condition, so that a warning the
    /// varied scene draws (a body E × 0.01 cannot carry) is not taken for the user's scene's.
    fn apply(&self, scene: &Scene) -> Scene {
        let mut s = scene.clone();
        if !matches!(self, Condition::Base | Condition::FreeRun(_)) {
            s.source = format!(
                "{} under the stress condition {}",
                scene.source,
                self.label()
            );
        }
        match *self {
            Condition::Base | Condition::FreeRun(_) => {}
            Condition::TimeStep(h) => s.time.step = h,
            Condition::Stiffness(f) => s.material.youngs_modulus *= f,
            Condition::Poisson(nu) => s.material.poisson_ratio = nu,
            Condition::Forces(f) => {
                let test = scene.test();
                s.test.offset = Some([test.offset[0] * f, test.offset[1] * f]);
            }
        }
        s
    }
}

/// How one method fared under one condition.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "status", rename_all = "lowercase")]
pub enum Outcome {
    /// Finite and bounded throughout; `mean_rel_error` against full space under the same
    /// condition (absent when full space itself failed).
    Ok {
        mean_rel_error: Option<f64>,
        max_displacement: f64,
    },
    /// The method stopped with a typed error at `step`.
    Error { step: usize, message: String },
    /// A non-finite or unbounded state, or total energy rising in the free run.
    Diverged { step: usize, reason: String },
}

impl Outcome {
    pub fn cell(&self) -> String {
        match self {
            Outcome::Ok {
                mean_rel_error: Some(e),
                ..
            } => format!("stable ({e:.1e})"),
            Outcome::Ok { .. } => "stable".into(),
            Outcome::Error { step, .. } => format!("error @{step}"),
            Outcome::Diverged { step, .. } => format!("diverged @{step}"),
        }
    }

    pub fn is_ok(&self) -> bool {
        matches!(self, Outcome::Ok { .. })
    }
}

/// One cell of the table.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StressResult {
    /// Serialised as its [`Method::name`].
    pub method: Method,
    pub condition: String,
    #[serde(flatten)]
    pub outcome: Outcome,
}

/// One line: method, condition and outcome, with the error's message or why it diverged.
impl std::fmt::Display for StressResult {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let detail = match &self.outcome {
            Outcome::Error { message, .. } => format!(": {message}"),
            Outcome::Diverged { reason, .. } => format!(": {reason}"),
            Outcome::Ok { .. } => String::new(),
        };
        write!(
            f,
            "{:>16} | {:<20} | {}{detail}",
            self.method,
            self.condition,
            self.outcome.cell()
        )
    }
}

/// A state counts as unbounded when a vertex moves more than this many bounding-box diagonals.
pub const UNBOUNDED_DIAGONALS: f64 = 10.0;

/// Relative slack allowed on "energy never rises": the solvers stop at a finite tolerance, so
/// each step's energy is only known to about this fraction of the energy scale E·V.
pub const ENERGY_SLACK: f64 = 1e-6;

/// The free run solves every step to at most this relative gradient, whatever the method's own
/// tolerance: the check above needs energies that precise. At the reduced methods' default
/// 1e-4, the catapult's neural-cubature free run, whose energy falls from −0.42 to −0.48 J over
/// 1,900 steps, has 313 steps that rise by up to 5.4e-5 J (1e-4 of the total): solver noise,
/// gone at 1e-6, not a gain of the dynamics.
pub const FREE_RUN_TOLERANCE: f64 = 1e-6;

/// Runs every method under every condition.
pub fn stress(
    base: &mut Pipeline<'_>,
    methods: &[Method],
    conditions: &[Condition],
    trajectory: usize,
    stage_progress: Progress<'_>,
    on_result: &mut dyn FnMut(&StressResult),
) -> Result<Vec<StressResult>> {
    let base_scene = base.scene.clone();
    if let Some(n) = conditions.iter().find_map(|c| match c {
        Condition::FreeRun(n) if *n > fem_core::integrator::MAX_FRAMES => Some(n),
        _ => None,
    }) {
        bail!(
            "a free run of {n} steps is more than the {} a trajectory may have",
            fem_core::integrator::MAX_FRAMES
        );
    }
    let mut results = Vec::new();
    for c in conditions {
        let scene = c.apply(&base_scene);
        let model = Pipeline::new(&scene, &base.cache)?.test_model(trajectory)?;
        let frames = scene.test().frames_per_schedule;
        let steps = match c {
            Condition::FreeRun(n) => (*n).max(frames),
            _ => frames,
        };
        // Full space under the same condition first: the others' error is measured against it.
        let mut reference: Option<Vec<Vec<f64>>> = None;
        for &method in methods {
            // `full` already is the scene's solver: as in `run`, a method forcing it is skipped.
            if method.repeats_full(methods, base_scene.solver.method) {
                continue;
            }
            let (outcome, trace) = run_one(
                base,
                &scene,
                method,
                model.clone(),
                steps,
                matches!(c, Condition::FreeRun(_)).then_some(frames),
                reference.as_deref(),
                stage_progress,
            )?;
            if method == Method::Full && outcome.is_ok() {
                reference = Some(trace);
            }
            let r = StressResult {
                method,
                condition: c.label(),
                outcome,
            };
            on_result(&r);
            results.push(r);
        }
    }
    Ok(results)
}

/// Simulates one method for `steps` steps; with `release = Some(n)`, external forces are
/// switched off after step n and total energy is checked step by step from then on.
/// Returns the outcome and the displacements (every step) for use as a reference.
#[allow(clippy::too_many_arguments)]
fn run_one(
    base: &mut Pipeline<'_>,
    scene: &Scene,
    method: Method,
    mut model: FullSpaceModel,
    steps: usize,
    release: Option<usize>,
    reference: Option<&[Vec<f64>]>,
    stage_progress: Progress<'_>,
) -> Result<(Outcome, Vec<Vec<f64>>)> {
    if let Some(n) = release {
        let end = n as f64 * scene.time.step;
        for f in &mut model.forces {
            f.end = f.end.min(end);
        }
    }
    let (lo, hi) = model.mesh.bounding_box();
    let diagonal = (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt();
    let energy_scale = model.energy_scale;
    let time = fem_core::integrator::TimeConfig {
        frames: steps,
        ..scene.time.clone()
    };
    let mut solver = solver_for(scene, method);
    if release.is_some() {
        solver.tolerance = solver.tolerance.min(FREE_RUN_TOLERANCE);
    }
    let runner = Runner::new(
        base,
        method,
        model,
        &scene.material,
        time,
        solver,
        stage_progress,
    );
    let mut runner = match runner {
        Ok(r) => r,
        Err(e) => {
            let outcome = Outcome::Error {
                step: 0,
                message: format!("{e:#}"),
            };
            return Ok((outcome, Vec::new()));
        }
    };
    let mut trace = Vec::with_capacity(steps);
    let mut errors = Vec::new();
    let mut max_displacement: f64 = 0.0;
    let mut last_energy = f64::INFINITY;
    for step in 1..=steps {
        if let Err(e) = runner.step() {
            let message = format!("{e:#}");
            let outcome = if message.contains("non-finite") {
                Outcome::Diverged {
                    step,
                    reason: message,
                }
            } else {
                Outcome::Error { step, message }
            };
            return Ok((outcome, trace));
        }
        let u = runner.displacement();
        let largest = fem_core::integrator::max_displacement(&u);
        if !largest.is_finite() || largest > UNBOUNDED_DIAGONALS * diagonal {
            let reason = format!(
                "displacement {largest:.3e} exceeds {UNBOUNDED_DIAGONALS} bounding-box diagonals"
            );
            return Ok((Outcome::Diverged { step, reason }, trace));
        }
        max_displacement = max_displacement.max(largest);
        if let Some(n) = release
            && step > n
        {
            let e = runner.total_energy();
            if !e.is_finite() {
                let reason = "non-finite energy".to_string();
                return Ok((Outcome::Diverged { step, reason }, trace));
            }
            if e > last_energy + ENERGY_SLACK * energy_scale {
                let reason = format!(
                    "total energy rose from {last_energy:.9e} to {e:.9e} J after the release"
                );
                return Ok((Outcome::Diverged { step, reason }, trace));
            }
            last_energy = e;
        }
        if let Some(r) = reference.and_then(|r| r.get(step - 1)) {
            errors.push(runner.model().mass.relative_error(&u, r).unwrap_or(0.0));
        }
        trace.push(u);
    }
    let mean_rel_error =
        (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64);
    Ok((
        Outcome::Ok {
            mean_rel_error,
            max_displacement,
        },
        trace,
    ))
}

/// The results as a markdown table: one row per method, one column per condition.
pub fn markdown(results: &[StressResult]) -> String {
    let mut conditions: Vec<&str> = Vec::new();
    let mut methods: Vec<Method> = Vec::new();
    for r in results {
        if !conditions.contains(&r.condition.as_str()) {
            conditions.push(&r.condition);
        }
        if !methods.contains(&r.method) {
            methods.push(r.method);
        }
    }
    let mut s = format!("| method | {} |\n|---|", conditions.join(" | "));
    s.push_str(&"---|".repeat(conditions.len()));
    s.push('\n');
    for m in methods {
        s.push_str(&format!("| {m} |"));
        for c in &conditions {
            let cell = results
                .iter()
                .find(|r| r.method == m && r.condition == *c)
                .map(|r| r.outcome.cell())
                .unwrap_or_default();
            s.push_str(&format!(" {cell} |"));
        }
        s.push('\n');
    }
    s
}

/// Writes `stress.json` and `stress.md` into `out`.
pub fn write(out: &Path, results: &[StressResult]) -> Result<()> {
    write_json(&out.join("stress.json"), &results)?;
    crate::output::write_file(&out.join("stress.md"), markdown(results).as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A varied scene says which condition it is under (its warnings are the variant's), and
    /// the unvaried ones keep the user's scene's name.
    #[test]
    fn a_varied_scene_names_its_condition() {
        let scene = Scene::builtin();
        let soft = Condition::Stiffness(0.01).apply(&scene);
        assert_eq!(
            soft.source,
            format!("{} under the stress condition E × 0.01", scene.source)
        );
        assert_eq!(
            soft.material.youngs_modulus,
            scene.material.youngs_modulus * 0.01
        );
        for c in [Condition::Base, Condition::FreeRun(10)] {
            assert_eq!(c.apply(&scene).source, scene.source);
        }
    }
}
