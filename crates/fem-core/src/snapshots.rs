//! Automatic training data (DESIGN §4): a seeded family of force schedules, each simulated in
//! full space, every frame's free-DOF displacement recorded.
//!
//! All loads are springs on random surface patches whose targets move by offsets given as
//! fractions of the bounding-box diagonal L, with stiffness in units of E·L (E the Young's
//! modulus), so the same defaults make sense on any mesh and material:
//! * `pull`: the target ramps to a random offset, holds, then the spring lets go;
//! * `poke`: a short, quick push of a small patch, released at once;
//! * `drag`: the target follows a random path through several keyframes, then lets go.
//!
//! Schedule `i` of a family depends only on (seed, i), so any subset (a shard) can be simulated
//! anywhere and merged.

use std::sync::Mutex;

use crate::forces::{ExternalForce, ForceKind};
use crate::integrator::{FullSpaceModel, MAX_FRAMES, Simulator, TimeConfig};
use crate::optim::SolverConfig;
use crate::rng::SplitMix64;
use crate::{FemError, Mat3, Vec3};

/// Kinds of generated schedules.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScheduleKind {
    Pull,
    Poke,
    Drag,
}

/// Where a family's schedules grab the surface.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PatchPlacement {
    /// Each schedule at a surface vertex drawn at random (the held-out tests: any patch a
    /// person might grab).
    #[default]
    Random,
    /// Schedule i at the i-th vertex of a farthest-point ordering of the surface (its start
    /// drawn from the seed): the patches of n schedules spread over the whole surface, so the
    /// data holds the response to a grab anywhere, not only where the draws fell (24 random
    /// draws on an X or a dinosaur leave whole limbs ungrabbed); distances within
    /// [`NEAR_PINS`] of the pins count longer, so patches lie closer together there.
    Spread,
}

/// Which way a family's schedules fall.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GravityDirections {
    /// Every schedule along the scene's gravity.
    #[default]
    Scene,
    /// Half the schedules (1, 2, 5, 6, 9, 10, …: never one that starts from the body's fall,
    /// [`LATER_EVERY`]) along a direction drawn from (seed, schedule), uniform over the
    /// sphere, at the scene's strength; the rest along the scene's: training data for a model
    /// whose program turns gravity at run time, which a model trained along one direction
    /// meets 40–90 % beyond its poses (the game loop example on four models).
    Any,
}

/// The `[training]` and `[test]` sections as written: every key optional, filled from
/// [`ScheduleConfig::training`] or [`ScheduleConfig::test`].
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduleSection {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedules: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_per_schedule: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinds: Option<Vec<ScheduleKind>>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "crate::exact::option"
    )]
    pub offset: Option<[f64; 2]>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "crate::exact::option"
    )]
    pub stiffness: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub patch_radius: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity_scale: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub patches: Option<PatchPlacement>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity: Option<GravityDirections>,
}

impl ScheduleSection {
    /// The complete configuration, taking unset keys from `defaults`.
    pub fn resolve(&self, defaults: ScheduleConfig) -> ScheduleConfig {
        ScheduleConfig {
            schedules: self.schedules.unwrap_or(defaults.schedules),
            frames_per_schedule: self
                .frames_per_schedule
                .unwrap_or(defaults.frames_per_schedule),
            seed: self.seed.unwrap_or(defaults.seed),
            kinds: self.kinds.clone().unwrap_or(defaults.kinds),
            offset: self.offset.unwrap_or(defaults.offset),
            stiffness: self.stiffness.unwrap_or(defaults.stiffness),
            patch_radius: self.patch_radius.unwrap_or(defaults.patch_radius),
            gravity_scale: self.gravity_scale.unwrap_or(defaults.gravity_scale),
            patches: self.patches.unwrap_or(defaults.patches),
            tolerance: self.tolerance.or(defaults.tolerance),
            gravity: self.gravity.unwrap_or(defaults.gravity),
        }
    }
}

/// A complete schedule family: how many, how long, which kinds and how strong.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScheduleConfig {
    /// Number of schedules (trajectories).
    pub schedules: usize,
    /// Time steps simulated per schedule.
    pub frames_per_schedule: usize,
    pub seed: u64,
    /// Kinds drawn from, uniformly.
    pub kinds: Vec<ScheduleKind>,
    /// Range of the target offset, as a fraction of the bounding-box diagonal.
    pub offset: [f64; 2],
    /// Range of the spring stiffness, as a multiple of the body's stiffness at the patch.
    pub stiffness: [f64; 2],
    /// Radius of a grabbed surface patch, as a fraction of the bounding-box diagonal.
    pub patch_radius: f64,
    /// Scales the scene's gravity (1 = as in the scene).
    pub gravity_scale: f64,
    /// Where the schedules grab the surface. Left out of the serialised form when random, so
    /// the cache keys of families from before the setting stay as they were.
    #[serde(default, skip_serializing_if = "is_random")]
    pub patches: PatchPlacement,
    /// The full-space solves' relative-gradient tolerance, when it differs from the solver's
    /// ([`Self::solver`]). Left out of the serialised form when unset, as for the test family.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// Which way the schedules fall. Left out of the serialised form along the scene's, so the
    /// cache keys of families from before the setting stay as they were.
    #[serde(default, skip_serializing_if = "is_scene")]
    pub gravity: GravityDirections,
}

/// The training family's default solve tolerance: training poses need not be solved to the
/// held-out test's 10⁻⁶, only so that what a subspace of them holds does not change (PCA keeps
/// 1 − 10⁻⁷ of their energy, a relative error of about 3·10⁻⁴ of their size; the tolerance is a
/// relative gradient, not a relative displacement, so the two are compared by what the pipeline
/// measured, not derived). Measured: on a 29k-tet torus a full-space step took 9.4 L-BFGS
/// iterations at 10⁻⁶, 6.2 at 10⁻⁴, 4.5 at 10⁻³ (its first three schedules alone: 6.0–7.4 at
/// 10⁻³, 3.9–4.9 at 10⁻²). From 10⁻⁴ to 10⁻³ the mesh suite's `pca` errors stayed the same to
/// 0.01 point on five meshes of six (the dinosaur 20.1 → 19.6 %); from 10⁻³ to 10⁻² they
/// stayed within 0.4 point (the bar 1.5 → 1.4 %, the dinosaur 19.6 → 19.2 %, the torus 5.15 →
/// 5.16 %, the toy 5.08 % both times; with 36 schedules the torus's `pca` was 2.72 % at 3·10⁻³
/// and at 10⁻²), the cubature rules and networks moved within a redraw's spread, the suite took
/// 4.3 min instead of 4.7 and the torus's snapshots 64 s instead of 83.
pub const TRAINING_TOLERANCE: f64 = 1e-2;

fn is_random(p: &PatchPlacement) -> bool {
    *p == PatchPlacement::Random
}

fn is_scene(g: &GravityDirections) -> bool {
    *g == GravityDirections::Scene
}

/// Mixed into the seed of the draws of a schedule's gravity, so that they leave its force's
/// draws as they were.
const GRAVITY_STREAM: u64 = 0x6772_6176_6974_7921;

impl ScheduleConfig {
    /// Defaults for training data: every kind, the drag included, since a person's drag (and
    /// the default test trajectory, another seed) is what the trained model will meet; with
    /// pulls and pokes alone, PCA of a minimal scene on an AutoDef mesh was 7 % from the test
    /// drag before any dynamics. 32 schedules rather than 24 (stop 46): on a 29k-tet toy
    /// `pca` went 5.08 → 2.74 % and `neural-cubature` 7.89 → 3.63 % from the test drag, its
    /// pipeline 160 → 176 s from an empty cache on 2 cores; 36 took it to 4.79 % at 189 s.
    pub fn training() -> Self {
        Self {
            schedules: 32,
            frames_per_schedule: 60,
            seed: 1,
            kinds: vec![ScheduleKind::Pull, ScheduleKind::Poke, ScheduleKind::Drag],
            offset: [0.02, 0.1],
            stiffness: [0.5, 2.0],
            patch_radius: 0.08,
            gravity_scale: 1.0,
            patches: PatchPlacement::Spread,
            tolerance: Some(TRAINING_TOLERANCE),
            gravity: GravityDirections::Scene,
        }
    }

    /// Defaults for held-out test trajectories: one drag with a seed training never used.
    pub fn test() -> Self {
        Self {
            schedules: 1,
            frames_per_schedule: 100,
            seed: 1_000_003,
            kinds: vec![ScheduleKind::Drag],
            patches: PatchPlacement::Random,
            tolerance: None,
            ..Self::training()
        }
    }

    pub fn check(&self, section: &str, errors: &mut Vec<FemError>) {
        let mut bad = |field: &str, reason: String| {
            errors.push(FemError::InvalidConfig {
                field: format!("{section}.{field}"),
                reason,
            })
        };
        if self.schedules == 0 {
            bad("schedules", "must be at least 1".into());
        }
        if self.frames_per_schedule == 0 {
            bad("frames_per_schedule", "must be at least 1".into());
        }
        if self.schedules > MAX_SCHEDULES {
            bad(
                "schedules",
                format!(
                    "at most {MAX_SCHEDULES} (each is a full-space simulation), got {}",
                    self.schedules
                ),
            );
        }
        if self.frames_per_schedule > MAX_FRAMES {
            bad(
                "frames_per_schedule",
                format!(
                    "at most {MAX_FRAMES} (each is a full-space time step), got {}",
                    self.frames_per_schedule
                ),
            );
        }
        if self.kinds.is_empty() {
            bad("kinds", "name at least one of pull, poke, drag".into());
        }
        for (name, r) in [("offset", self.offset), ("stiffness", self.stiffness)] {
            if !(r[0].is_finite() && r[1].is_finite() && r[0] > 0.0 && r[0] <= r[1]) {
                bad(name, format!("needs 0 < min ≤ max, got {r:?}"));
            }
        }
        if self.stiffness[1] > MAX_STIFFNESS_FACTOR {
            bad(
                "stiffness",
                format!(
                    "at most {MAX_STIFFNESS_FACTOR:e} times the body's own stiffness at the \
                     patch (a grip that much stiffer holds as rigidly as any), got {}",
                    self.stiffness[1]
                ),
            );
        }
        if !(self.patch_radius.is_finite() && self.patch_radius > 0.0) {
            bad(
                "patch_radius",
                format!("must be positive, got {}", self.patch_radius),
            );
        }
        if !(self.gravity_scale.is_finite() && self.gravity_scale >= 0.0) {
            bad(
                "gravity_scale",
                format!("must be non-negative, got {}", self.gravity_scale),
            );
        }
        if let Some(t) = self.tolerance
            && !(t.is_finite() && t > 0.0 && t < 1.0)
        {
            bad(
                "tolerance",
                format!("must be in (0, 1) (a relative gradient, e.g. 1e-3), got {t}"),
            );
        }
    }

    /// `base` with this family's tolerance, if it sets one (the pipeline's default for training
    /// data is the looser of [`TRAINING_TOLERANCE`] and the solver's own).
    pub fn solver(&self, base: &SolverConfig) -> SolverConfig {
        SolverConfig {
            tolerance: self.tolerance.unwrap_or(base.tolerance),
            ..base.clone()
        }
    }

    /// The gravitational acceleration schedule `index` falls with on `model` before
    /// `gravity_scale`: the scene's, or under [`GravityDirections::Any`] for `index` 1 and 2
    /// modulo [`LATER_EVERY`] the scene's strength along a direction drawn from (seed, index).
    pub fn gravity_of(&self, model: &FullSpaceModel, index: usize) -> Vec3 {
        match self.gravity {
            GravityDirections::Any if matches!(index % LATER_EVERY, 1 | 2) => {
                let d =
                    SplitMix64::for_item(self.seed ^ GRAVITY_STREAM, index as u64).unit_vector();
                Vec3::from(d) * model.gravity.norm()
            }
            _ => model.gravity,
        }
    }

    /// [`Self::gravity_of`] where it differs from `model`'s gravity (the schedule falls along
    /// a turned direction), else None.
    pub fn turned_gravity(&self, model: &FullSpaceModel, index: usize) -> Option<Vec3> {
        Some(self.gravity_of(model, index)).filter(|g| *g != model.gravity)
    }

    /// The surface vertices schedule `index` grabs on `model`'s mesh (those of its first and
    /// only force in [`schedule`](Self::schedule), without measuring the body's stiffness
    /// there), or `None` when every surface vertex is pinned.
    pub fn patch(&self, model: &FullSpaceModel, index: usize) -> Option<Vec<usize>> {
        self.grab(model, index).map(|g| g.vertices)
    }

    /// Schedule `index`'s draws up to its patch; the rest of its draws continue from `rng`.
    fn grab(&self, model: &FullSpaceModel, index: usize) -> Option<Grab> {
        let mut rng = SplitMix64::for_item(self.seed, index as u64);
        let mesh = &model.mesh;
        let (lo, hi) = mesh.bounding_box();
        let diag = (hi - lo).norm();
        let candidates: Vec<usize> = mesh
            .surface_vertices()
            .into_iter()
            .filter(|v| model.pinned.binary_search(v).is_err())
            .collect();
        if candidates.is_empty() {
            return None;
        }
        let kind = self.kinds[rng.below(self.kinds.len())];
        // Drawn in either placement, so that the other draws of schedule i do not depend on it.
        let drawn = candidates[rng.below(candidates.len())];
        let center = mesh.vertices[match self.patches {
            PatchPlacement::Random => drawn,
            PatchPlacement::Spread => {
                spread_vertex(mesh, &candidates, &model.pinned, self.seed, index)
            }
        }];
        let radius = match kind {
            ScheduleKind::Poke => 0.5 * self.patch_radius * diag,
            _ => self.patch_radius * diag,
        };
        let mut vertices: Vec<usize> = candidates
            .iter()
            .copied()
            .filter(|&v| (mesh.vertices[v] - center).norm() <= radius)
            .collect();
        if vertices.is_empty() {
            vertices.push(candidates[0]);
        }
        Some(Grab {
            kind,
            vertices,
            diag,
            rng,
        })
    }

    /// The forces of schedule `index` on `model`'s mesh, with time step `h`; `probe` measures
    /// the body's stiffness at a patch (see [`StiffnessProbe`]).
    pub fn schedule(
        &self,
        model: &FullSpaceModel,
        probe: &StiffnessProbe,
        index: usize,
        h: f64,
    ) -> Vec<ExternalForce> {
        let Some(Grab {
            kind,
            vertices,
            diag,
            mut rng,
        }) = self.grab(model, index)
        else {
            return Vec::new();
        };
        let duration = self.frames_per_schedule as f64 * h;
        let factor = rng.range(self.stiffness[0], self.stiffness[1]);
        let direction = rng.unit_vector();
        let stiffness = factor * probe.stiffness(model, &vertices, direction);
        // The first target offset goes along the probed direction.
        let mut first = Some(direction);
        let mut offset = |scale: f64| {
            let d = first.take().unwrap_or_else(|| rng.unit_vector());
            let m = rng.range(self.offset[0], self.offset[1]) * diag * scale;
            [d[0] * m, d[1] * m, d[2] * m]
        };
        let (keyframes, start, end) = match kind {
            ScheduleKind::Pull => {
                let o = offset(1.0);
                let ramp = duration * 0.3;
                let release = duration * 0.55;
                (
                    vec![[0.0, 0.0, 0.0, 0.0], [ramp, o[0], o[1], o[2]]],
                    0.0,
                    release,
                )
            }
            ScheduleKind::Poke => {
                let o = offset(0.5);
                let ramp = (3.0 * h).min(duration * 0.2);
                (
                    vec![[0.0, 0.0, 0.0, 0.0], [ramp, o[0], o[1], o[2]]],
                    0.0,
                    ramp * 2.0,
                )
            }
            ScheduleKind::Drag => {
                let mut k = vec![[0.0, 0.0, 0.0, 0.0]];
                for j in 1..=3 {
                    let o = offset(1.0);
                    k.push([duration * 0.18 * j as f64, o[0], o[1], o[2]]);
                }
                (k, 0.0, duration * 0.6)
            }
        };
        vec![ExternalForce {
            kind: ForceKind::Spring,
            vertices,
            stiffness,
            keyframes,
            start,
            end,
        }]
    }
}

/// A schedule's grab: its kind and patch, the body's bounding-box diagonal, and its random
/// draws from there on.
struct Grab {
    kind: ScheduleKind,
    vertices: Vec<usize>,
    diag: f64,
    rng: SplitMix64,
}

/// The `index`-th vertex (cyclically) of a farthest-point ordering of `candidates` (mesh
/// vertices), which starts at one drawn from `seed`: each vertex the furthest from those before,
/// distances scaled by [`pin_scales`] (longer near the pins).
fn spread_vertex(
    mesh: &crate::TetMesh,
    candidates: &[usize],
    pinned: &[usize],
    seed: u64,
    index: usize,
) -> usize {
    let n = candidates.len();
    let mut rng = SplitMix64::for_item(seed, u64::MAX);
    let mut current = rng.below(n);
    let mut nearest = vec![f64::INFINITY; n];
    let scale = pin_scales(mesh, candidates, pinned);
    for _ in 0..index % n {
        let p = mesh.vertices[candidates[current]];
        let mut far = (0, -1.0);
        for (i, d) in nearest.iter_mut().enumerate() {
            *d = d.min((mesh.vertices[candidates[i]] - p).norm_squared() / scale[i]);
            if *d > far.1 {
                far = (i, *d);
            }
        }
        current = far.0;
    }
    candidates[current]
}

/// Within this fraction of the bounding-box diagonal of the nearest pinned vertex,
/// [`PatchPlacement::Spread`] places patches closer together than elsewhere: next to a clamp a grab's
/// response is local (it dies out within about its distance to the clamp), so a patch there
/// says less of its neighbours than one far out, and the held-out test grabs anywhere. With
/// evenly spread patches, the worst of four test drags grabbed within 0.15 of the diagonal of
/// the pins on eight meshes of nine (0.04–0.15; an L-bracket's 29 % off, AutoDef's X high 20 %,
/// the others 2.8–7.6 %; the nearest training patch 0.02–0.08 of the diagonal away, as for the
/// other drags). With patches closer there ([`AT_PINS`]; this one setting tried, not tuned),
/// the mean over four drags of `neural-cubature` went 7.56 → 3.81 % on the bracket, 5.71 → 2.87
/// % on the X, 2.34 → 1.93, 3.22 → 2.59, 2.39 → 2.25 and 1.52 → 1.48 % on four more, 3.02 →
/// 3.03 % on the armadillo, 2.36 → 2.56 % on AutoDef's bar and 1.73 → 2.00 % on a ribbed finger
/// (stop 69; drag 0 moved by up to 0.71 point either way).
pub const NEAR_PINS: f64 = 0.25;

/// The spacing of [`PatchPlacement::Spread`]'s patches at the pins, as a share of their spacing
/// [`NEAR_PINS`] or further from them, squared: distances from a candidate at a distance l of
/// the pins count 1/√max(l/[`NEAR_PINS`], this) times as long (1.8 times at the pins, so about
/// three times as many patches per area there).
pub const AT_PINS: f64 = 0.32;

/// Each candidate's squared length scale in [`spread_vertex`]'s distances: max(l /
/// [`NEAR_PINS`], [`AT_PINS`]) up to 1, l its distance to the nearest pinned vertex as a share
/// of the bounding-box diagonal (1 everywhere when nothing is pinned).
fn pin_scales(mesh: &crate::TetMesh, candidates: &[usize], pinned: &[usize]) -> Vec<f64> {
    let (lo, hi) = mesh.bounding_box();
    let diag = (hi - lo).norm();
    if pinned.is_empty() || diag.is_nan() || diag <= 0.0 {
        return vec![1.0; candidates.len()];
    }
    candidates
        .iter()
        .map(|&c| {
            let x = mesh.vertices[c];
            let nearest = pinned
                .iter()
                .map(|&p| (mesh.vertices[p] - x).norm_squared())
                .fold(f64::INFINITY, f64::min);
            (nearest.sqrt() / diag / NEAR_PINS).clamp(AT_PINS, 1.0)
        })
        .collect()
}

/// The largest multiple of the body's stiffness at a patch a schedule's spring may take: the
/// defaults' springs (0.5–2 times it) came to 0.2–0.3 times E times the bounding-box diagonal
/// on the default bar, so this keeps every generated spring far below the runtime's limit of
/// 10⁶ times that (`latent_sim::MAX_SPRING_STIFFNESS`), which a test schedule over it would
/// otherwise meet only once the methods run.
pub const MAX_STIFFNESS_FACTOR: f64 = 1e4;

/// The most schedules a family may have: a thousand times the training default, days of
/// full-space simulation on a small mesh; a value past it is a typo.
pub const MAX_SCHEDULES: usize = 32_000;

/// The body's stiffness at a surface patch: A = K₀ + M/T² factorised once per mesh.
pub struct StiffnessProbe {
    chol: crate::sparse_cholesky::SparseCholesky,
}

impl std::fmt::Debug for StiffnessProbe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("StiffnessProbe")
    }
}

impl StiffnessProbe {
    /// Factorises K₀ + M/T² for `model`, T the time scale of a schedule.
    pub fn new(model: &FullSpaceModel, time_scale: f64) -> Result<Self, FemError> {
        let mut parts = crate::step_norm::rest_stiffness(model)?;
        parts.add_mass(model, 1.0 / (time_scale * time_scale));
        parts.factor()?;
        Ok(Self { chol: parts.chol })
    }

    /// 1 / (mean displacement along `direction` of `vertices` under a unit total load along it).
    pub fn stiffness(
        &self,
        model: &FullSpaceModel,
        vertices: &[usize],
        direction: [f64; 3],
    ) -> f64 {
        let mean = Vec3::from(direction).dot(&self.mean_response(model, vertices, direction));
        if mean > 0.0 { 1.0 / mean } else { 0.0 }
    }

    /// The patch's compliance G A⁻¹ Gᵀ (3×3, symmetric): column c is the mean displacement of
    /// `vertices` under a unit total load along axis c spread evenly over them (G averages the
    /// patch's vertices; pinned components take no load and do not move).
    pub fn patch_compliance(&self, model: &FullSpaceModel, vertices: &[usize]) -> Mat3 {
        self.patch_response(model, vertices).0
    }

    /// [`Self::patch_compliance`] and the displacements behind it: A⁻¹Gᵀ on the free DOFs,
    /// column-major (free DOFs × 3), column c the response to a unit total load along axis c
    /// spread evenly over `vertices`.
    pub fn patch_response(&self, model: &FullSpaceModel, vertices: &[usize]) -> (Mat3, Vec<f64>) {
        let n = model.dofs.num_free();
        let mut columns = vec![0.0; 3 * n];
        let mut c = Mat3::zeros();
        for axis in 0..3 {
            let mut load = [0.0; 3];
            load[axis] = 1.0;
            let x = &mut columns[axis * n..(axis + 1) * n];
            self.response(model, vertices, load, x);
            c.set_column(axis, &patch_mean(model, vertices, x));
        }
        ((c + c.transpose()) * 0.5, columns)
    }

    /// Mean displacement of `vertices` under the total load `load` spread evenly over them.
    fn mean_response(&self, model: &FullSpaceModel, vertices: &[usize], load: [f64; 3]) -> Vec3 {
        let mut x = vec![0.0; model.dofs.num_free()];
        self.response(model, vertices, load, &mut x);
        patch_mean(model, vertices, &x)
    }

    /// A⁻¹ times the total load `load` spread evenly over `vertices`, into `x` (free DOFs).
    fn response(&self, model: &FullSpaceModel, vertices: &[usize], load: [f64; 3], x: &mut [f64]) {
        x.fill(0.0);
        let share = 1.0 / vertices.len() as f64;
        for &v in vertices {
            for c in 0..3 {
                let r = model.dofs.index[3 * v + c];
                if r != crate::constraints::FIXED {
                    x[r] = load[c] * share;
                }
            }
        }
        self.chol.solve_in_place(x);
    }
}

/// The mean over `vertices` of the free-DOF displacement `x` (pinned components count as 0).
fn patch_mean(model: &FullSpaceModel, vertices: &[usize], x: &[f64]) -> Vec3 {
    let share = 1.0 / vertices.len() as f64;
    let mut mean = Vec3::zeros();
    for &v in vertices {
        for c in 0..3 {
            let r = model.dofs.index[3 * v + c];
            if r != crate::constraints::FIXED {
                mean[c] += x[r] * share;
            }
        }
    }
    mean
}

/// Free-DOF displacements of every frame of the simulated schedules, one column per frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SnapshotSet {
    /// Free DOFs per frame.
    pub dim: usize,
    /// Schedule indices in this set, increasing.
    pub schedules: Vec<usize>,
    /// Frames each schedule was to record.
    pub frames_per_schedule: usize,
    /// Frames recorded per schedule, in the order of `schedules`: `frames_per_schedule`, or fewer
    /// where the full-space solve failed partway (see `stopped`).
    pub frames: Vec<usize>,
    /// The schedules whose full-space solve failed, each with the error: the frames before it
    /// are kept, the rest of the schedule is not simulated.
    pub stopped: Vec<StoppedSchedule>,
    /// Why every [`LATER_EVERY`]th schedule starts from a [`MovingStart`] instead of rest, when
    /// they do (the pipeline's default when the test outlasts the schedules while the body is still
    /// moving under its weight).
    pub later_start: Option<String>,
    /// Column-major dim × Σ frames displacements, schedule after schedule.
    pub data: Vec<f64>,
}

/// A schedule whose full-space solve failed at step `frames + 1`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StoppedSchedule {
    pub index: usize,
    /// Frames recorded before the failure.
    pub frames: usize,
    /// The solver's error.
    pub error: String,
}

impl SnapshotSet {
    pub fn num_frames(&self) -> usize {
        self.frames.iter().sum()
    }

    /// Frame `j` (column) as a slice.
    pub fn frame(&self, j: usize) -> &[f64] {
        &self.data[j * self.dim..(j + 1) * self.dim]
    }

    /// Combines disjoint sets of the same family into one, ordered by schedule.
    pub fn merge(parts: Vec<SnapshotSet>) -> Result<SnapshotSet, String> {
        let first = parts.first().ok_or("no snapshot sets to merge")?;
        let (dim, fps) = (first.dim, first.frames_per_schedule);
        let mut blocks: Vec<(usize, &[f64])> = Vec::new();
        let mut stopped = Vec::new();
        for p in &parts {
            if p.dim != dim || p.frames_per_schedule != fps {
                return Err("shards come from different meshes or settings".into());
            }
            let mut start = 0;
            for (&s, &n) in p.schedules.iter().zip(&p.frames) {
                blocks.push((s, &p.data[start * dim..(start + n) * dim]));
                start += n;
            }
            stopped.extend(p.stopped.iter().cloned());
        }
        blocks.sort_by_key(|b| b.0);
        stopped.sort_by_key(|s: &StoppedSchedule| s.index);
        if blocks.windows(2).any(|w| w[0].0 == w[1].0) {
            return Err("a schedule appears in two shards".into());
        }
        Ok(SnapshotSet {
            dim,
            schedules: blocks.iter().map(|b| b.0).collect(),
            frames_per_schedule: fps,
            frames: blocks.iter().map(|b| b.1.len() / dim.max(1)).collect(),
            stopped,
            later_start: first.later_start.clone(),
            data: blocks.iter().flat_map(|b| b.1.iter().copied()).collect(),
        })
    }
}

/// Simulates one schedule from rest and returns its free-DOF displacement per frame.
pub fn simulate_schedule(
    model: &FullSpaceModel,
    forces: Vec<ExternalForce>,
    gravity_scale: f64,
    time: &TimeConfig,
    solver: &SolverConfig,
    frames: usize,
) -> Result<Vec<Vec<f64>>, FemError> {
    let mut out = Vec::with_capacity(frames);
    record_schedule(
        model,
        forces,
        None,
        gravity_scale,
        time,
        solver,
        frames,
        None,
        &mut out,
    )?;
    Ok(out)
}

/// Simulates one schedule from rest (or from `start`), appending each frame's free-DOF
/// displacement to `out`, so that the frames before a failed step are there for the caller.
/// `turned` is a gravitational acceleration in place of the model's, before `gravity_scale`.
#[allow(clippy::too_many_arguments)]
fn record_schedule(
    model: &FullSpaceModel,
    forces: Vec<ExternalForce>,
    turned: Option<Vec3>,
    gravity_scale: f64,
    time: &TimeConfig,
    solver: &SolverConfig,
    frames: usize,
    start: Option<&MovingStart>,
    out: &mut Vec<Vec<f64>>,
) -> Result<(), FemError> {
    let mut m = model.clone();
    m.forces = forces;
    if let Some(g) = turned {
        m.set_gravity(g);
    }
    m.scale_gravity(gravity_scale);
    let time = TimeConfig {
        frames,
        ..time.clone()
    };
    let mut sim = Simulator::new(m, time, solver.clone())?;
    if let Some(start) = start {
        sim.state.u.copy_from_slice(&start.u);
        sim.state.v.copy_from_slice(&start.v);
    }
    let mut free = vec![0.0; sim.model.dofs.num_free()];
    for _ in 0..frames {
        sim.step()?;
        sim.model.dofs.gather(&sim.state.u, &mut free);
        out.push(free.clone());
    }
    Ok(())
}

/// A schedule's frames, and the solve failure that ended it early, if one did.
type Recorded = (Vec<Vec<f64>>, Option<FemError>);

/// Simulates the schedules `shard.0, shard.0 + shard.1, …` of `config` in parallel.
/// `progress(done)` is called (from any thread) after each finished schedule, and with the count
/// so far before each one starts, so that a caller may stop the work between schedules.
pub fn generate(
    model: &FullSpaceModel,
    config: &ScheduleConfig,
    time: &TimeConfig,
    solver: &SolverConfig,
    shard: (usize, usize),
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SnapshotSet, FemError> {
    generate_from(model, config, time, solver, shard, None, progress)
}

/// One schedule in this many starts from a [`MovingStart`] when one is given (a quarter: on a
/// 27,324-tet beam swinging under gravity those schedules cost twice a schedule from rest, and
/// half of them made its snapshots 1.9× as long, a quarter 1.5×).
pub const LATER_EVERY: usize = 4;

/// A state the body passes through, unforced, later than a schedule's length: full-DOF
/// displacement and velocity.
#[derive(Debug, Clone, PartialEq)]
pub struct MovingStart {
    pub u: Vec<f64>,
    pub v: Vec<f64>,
}

/// Computes the state every fourth schedule starts from (None: they start from rest).
pub type LaterStart<'a> = &'a (dyn Fn() -> Result<Option<MovingStart>, FemError> + Sync);

/// [`generate`], with every fourth schedule (3, 7, 11, …) starting from the state `later`
/// computes instead of rest (its grab timed from there), so that the family covers times after
/// its own length. `later` runs as one task beside the schedules from rest (a full-space run of
/// the body falling, which on one core left the other idle), and the schedules that wait for it
/// start when it ends.
pub fn generate_from(
    model: &FullSpaceModel,
    config: &ScheduleConfig,
    time: &TimeConfig,
    solver: &SolverConfig,
    shard: (usize, usize),
    later: Option<LaterStart<'_>>,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SnapshotSet, FemError> {
    let (index, count) = shard;
    let schedules: Vec<usize> = (index..config.schedules).step_by(count.max(1)).collect();
    // Counted and reported under one lock, so the calls arrive in order and the last one is
    // `done == total`, where a progress bar finishes (a bare atomic count let two threads call
    // out of order).
    let done = Mutex::new(0);
    let probe = StiffnessProbe::new(model, config.frames_per_schedule as f64 * time.step)?;
    let solver = &config.solver(solver);
    let run = |s: usize, start: Option<&MovingStart>| -> Result<Recorded, FemError> {
        // The count so far, before the schedule: a caller that stops the work from its
        // progress report (by unwinding) stops it here, between schedules.
        progress(*done.lock().unwrap_or_else(|e| e.into_inner()));
        let forces = config.schedule(model, &probe, s, time.step);
        let mut frames = Vec::with_capacity(config.frames_per_schedule);
        let turned = config.turned_gravity(model, s);
        let r = record_schedule(
            model,
            forces,
            turned,
            config.gravity_scale,
            time,
            solver,
            config.frames_per_schedule,
            start,
            &mut frames,
        );
        let mut count = done.lock().unwrap_or_else(|e| e.into_inner());
        *count += 1;
        progress(*count);
        match r {
            Ok(()) => Ok((frames, None)),
            // A solve that fails partway (a grab that turns the body inside out, a
            // stagnating Newton solve far from rest) ends the schedule, not the family: the
            // frames before it are poses the full simulation reached.
            Err(e) if e.is_solve_failure() => Ok((frames, Some(e))),
            Err(e) => Err(FemError::Schedule {
                index: s,
                source: Box::new(e),
            }),
        }
    };
    let waits = |s: usize| later.is_some() && s % LATER_EVERY == LATER_EVERY - 1;
    let slots: Vec<Mutex<Option<Result<Recorded, FemError>>>> =
        schedules.iter().map(|_| Mutex::new(None)).collect();
    let store = |i: usize, r| *slots[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
    let (run, store, indices) = (&run, &store, &schedules);
    let mut failed = None;
    rayon::scope(|scope| {
        if let Some(compute) = later {
            let failed = &mut failed;
            // Spawned first: with two threads or more another one takes it at once (rayon's
            // thieves take the oldest job); on one it runs after the schedules from rest.
            scope.spawn(move |scope| match compute() {
                Ok(from) => {
                    for (i, &s) in indices.iter().enumerate().filter(|(_, s)| waits(**s)) {
                        let from = from.clone();
                        scope.spawn(move |_| store(i, run(s, from.as_ref())));
                    }
                }
                Err(e) => *failed = Some(e),
            });
        }
        for (i, &s) in indices.iter().enumerate().filter(|(_, s)| !waits(**s)) {
            scope.spawn(move |_| store(i, run(s, None)));
        }
    });
    if let Some(e) = failed {
        return Err(e);
    }
    let results = slots.into_iter().map(|slot| {
        slot.into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .expect("every schedule ran")
    });
    let dim = model.dofs.num_free();
    let mut data = Vec::with_capacity(dim * schedules.len() * config.frames_per_schedule);
    let mut recorded = Vec::with_capacity(schedules.len());
    let mut stopped = Vec::new();
    for (&s, r) in schedules.iter().zip(results) {
        let (frames, failure) = r?;
        recorded.push(frames.len());
        for frame in &frames {
            data.extend_from_slice(frame);
        }
        if let Some(e) = failure {
            stopped.push(StoppedSchedule {
                index: s,
                frames: frames.len(),
                error: e.to_string(),
            });
        }
    }
    Ok(SnapshotSet {
        dim,
        schedules,
        frames_per_schedule: config.frames_per_schedule,
        frames: recorded,
        stopped,
        later_start: None,
        data,
    })
}
