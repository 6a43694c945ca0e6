//! Scene files (TOML). Each section's struct belongs to the crate that uses it; a scene only
//! composes them. Unknown keys are errors, so a typo never goes unnoticed.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use fem_core::TetMesh;
use fem_core::constraints::VertexSelection;
use fem_core::forces::{ForceConfig, ForceKind};
use fem_core::integrator::{FullSpaceModel, GravityConfig, TimeConfig};
use fem_core::material::MaterialConfig;
use fem_core::mesh::NO_COMPONENT;
use fem_core::mesh::{MeshConfig, ValidationReport};
use fem_core::optim::SolverConfig;
use fem_core::snapshots::{GravityDirections, ScheduleConfig, ScheduleSection};
use fem_core::{FemError, four_digits};
use pca::PcaConfig;

/// The share of a body's extent along a pin plane's axis that [`Scene::build_model`]'s advice
/// (and the mesh suite's minimal scenes) pin: 2 %, the bottom of a standing body.
pub const WIDER_PIN: f64 = 0.02;

/// `x` (> 0) rounded up to four significant figures, as [`four_digits`] prints it; the smallest
/// positive normal number where `x` is not positive and finite.
fn up_to_four_figures(x: f64) -> f64 {
    if !(x.is_finite() && x > 0.0) {
        return f64::MIN_POSITIVE;
    }
    let unit = 10f64.powf(x.log10().floor() - 3.0);
    (x / unit).ceil() * unit
}

/// The share of a body's vertices that the radius [`Scene::build_model`]'s advice gives a `sphere`
/// pin holding the body at a point takes in (at least four).
pub const WIDER_SPHERE_SHARE: f64 = 0.02;

/// Pin planes that hold more than this share of a body's vertices are worth a word: a body
/// stands or hangs from a few percent of them, and a tester's fork made z-up and pinned at its
/// lowest y (the README's plane) lay on its side glued along it, 35 % of it held, and nothing
/// said so. A `box`, `sphere` or list of `indices` drawn around a whole part (one bell of a
/// dumbbell, 44 % of its vertices) holds what the user chose, and is not counted.
pub const MANY_PINNED: f64 = 0.25;

/// A body whose own weight would strain it by more than this (ρ g H / E, H its height along
/// gravity) cannot stand or hang as the solid it is modelled as: a 25 cm body of E = 10⁵ Pa
/// is at 0.025, a 2 m one at 0.2; a 15 m bunny whose file was in centimetres at 1.5.
pub const HEAVY_BODY: f64 = 0.25;

/// A body larger than this (m, its bounding box's diagonal) that its weight cannot carry is most
/// likely a mesh in centimetres or millimetres read as metres (a 25 cm part becomes 25 m); below
/// it, units are not suggested.
pub const UNIT_MISTAKE_SIZE: f64 = 3.0;

/// What a warning of a body its weight carries away says first when the body is `size` metres
/// across (its bounding box's diagonal) and larger than [`UNIT_MISTAKE_SIZE`]: that the mesh
/// may not be in metres. A tester's 10 cm mushroom read as 10 m (E = 10⁶ Pa, ρgH/E = 0.1) was
/// told only to take a modulus 56 times stiffer.
pub fn unit_hint(size: f64) -> Option<String> {
    (size > UNIT_MISTAKE_SIZE).then(|| {
        format!(
            "at {size:.1} m across, the mesh may not be in metres: set `[mesh] scale` (0.01 for \
             centimetres, 0.001 for millimetres)"
        )
    })
}

/// [`unit_hint`] as the start of a sentence ("At 14.0 m across, …").
pub fn unit_sentence(size: f64) -> Option<String> {
    unit_hint(size).map(|u| format!("A{}", &u[1..]))
}

/// Densities below this (kg/m³) are lighter than any solid a soft body is made of (foams start
/// at about 10, silica aerogel near 2): most often one written in g/cm³ (1.0 for water).
pub const LIGHT_DENSITY: f64 = 10.0;

/// Densities above this (kg/m³) are heavier than any element (osmium 22,590).
pub const HEAVY_DENSITY: f64 = 25_000.0;

/// What to say of a `[material] density` outside [[`LIGHT_DENSITY`], [`HEAVY_DENSITY`]]: the
/// body then swings about √1000 times faster or slower than meant, and the only other word of
/// it was a time step said to be too long for its swing.
pub fn density_warning(density: f64) -> Option<String> {
    if density < LIGHT_DENSITY {
        Some(format!(
            "`[material] density` = {density} kg/m³ is lighter than any solid (foams start at \
             about 10 kg/m³): a scene is in SI units, so a density in g/cm³ is 1000 times too \
             small (water is 1000 kg/m³, rubber about 1100), and a body 1000 times too light \
             swings about 30 times too fast"
        ))
    } else if density > HEAVY_DENSITY {
        Some(format!(
            "`[material] density` = {density} kg/m³ is heavier than any element (osmium is \
             22,590 kg/m³): a scene is in SI units (kg/m³; water is 1000)"
        ))
    } else {
        None
    }
}

/// What to say of a body that its own weight strains by more than [`HEAVY_BODY`]: most often a
/// mesh in other units than metres, else too soft a material. `extent` is the body's bounding
/// box size (metres).
pub fn weight_warning(scene: &Scene, extent: [f64; 3]) -> Option<String> {
    let g = scene.gravity.acceleration;
    let g_norm = scene.gravity.magnitude();
    if !scene.gravity.is_on() || !g_norm.is_finite() {
        return None;
    }
    let height: f64 = (0..3).map(|i| (g[i] / g_norm).abs() * extent[i]).sum();
    let m = &scene.material;
    let strain = m.density * g_norm * height / m.youngs_modulus;
    (strain > HEAVY_BODY).then(|| {
        // The bounding box's diagonal, as the fall and buckling warnings measure a body.
        let size = extent.iter().map(|x| x * x).sum::<f64>().sqrt();
        // The modulus at which ρgH/E comes to the limit is a floor: a body lying across
        // gravity bends far more than its height says (an advice follower's 1 m bar, 10 cm
        // tall, passed at 4e3 Pa and still fell 4.9 m; its fall line asked 1.3e7 Pa).
        // Rounded up to the figures printed, so that the value written back passes.
        let floor = up_to_four_figures(m.density * g_norm * height / HEAVY_BODY);
        let stiffer = format!(
            "a stiffer `[material] youngs_modulus` of at least {floor:.3e} Pa (where ρgH/E is \
             {HEAVY_BODY}; a slender body lying across gravity needs more, which `run`'s lines \
             measure from its sag)"
        );
        let remedy = match unit_sentence(size) {
            Some(units) => format!("{units}; else {stiffer}"),
            None => format!("{stiffer}, or pins that hold more of it, keep it up"),
        };
        // Sentence case.
        let mut chars = remedy.chars();
        let remedy: String = chars
            .next()
            .map_or(String::new(), |c| c.to_uppercase().chain(chars).collect());
        format!(
            "its own weight strains the body by about ρgH/E = {strain:.2} (ρ = {} kg/m³, g = \
             {g_norm:.2} m/s², H = {height:.3} m its height along gravity, E = {:.1e} Pa), more \
             than a solid carries: it will sag or collapse under gravity alone. {remedy}",
            m.density, m.youngs_modulus
        )
    })
}

/// Why `name` cannot name a scene, if it cannot: it becomes a folder name (`out/<name>`, the
/// cache in `out/<name>/cache`), so it must be one plain file name, not a path that would
/// write elsewhere.
fn name_problem(name: &str) -> Option<String> {
    if name.trim().is_empty() {
        return Some("must not be empty".into());
    }
    let path_like = name == "." || name == ".." || name.contains(['/', '\\']);
    (path_like || name.chars().any(char::is_control)).then(|| {
        format!(
            "got {name:?}; it names the output folder `out/<name>`, so it must be one plain file \
             name such as \"my-part\", without `/`, `\\` or control characters"
        )
    })
}

/// The built-in default scene, `crates/pipeline/scenes/cantilever.toml` (inside the crate, so
/// that a source package of the crate or of the Python module builds), linked as
/// `data/cantilever.toml` beside the other scenes.
pub const DEFAULT_SCENE: &str = include_str!("../scenes/cantilever.toml");

/// A scene: the mesh, its material and supports, the loads and how to integrate.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub name: String,
    pub mesh: MeshConfig,
    #[serde(default)]
    pub material: MaterialConfig,
    #[serde(default)]
    pub pin: Vec<VertexSelection>,
    #[serde(default)]
    pub gravity: GravityConfig,
    #[serde(default)]
    pub time: TimeConfig,
    #[serde(default)]
    pub solver: SolverConfig,
    /// The solver of the reduced methods (pca, pca-cubature, neural, neural-cubature).
    #[serde(default)]
    pub reduced: ReducedSolverConfig,
    #[serde(default)]
    pub force: Vec<ForceConfig>,
    /// Generated training schedules (stage `snapshots`).
    #[serde(default)]
    pub training: ScheduleSection,
    /// Held-out test trajectories (ground truth for errors).
    #[serde(default)]
    pub test: ScheduleSection,
    /// Dimension selection of the PCA basis (stage `pca`).
    #[serde(default)]
    pub pca: PcaConfig,
    /// Optimized cubature of the reduced elastic forces (stage `cubature`).
    #[serde(default)]
    pub cubature: cubature::CubatureConfig,
    /// The autoencoder on the PCA coefficients (stage `train`).
    #[serde(default)]
    pub autoencoder: nn::AutoencoderConfig,
    /// Folder that relative paths in the scene are resolved against.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// Where the scene came from, for messages.
    #[serde(skip)]
    pub source: String,
}

/// The `[reduced]` section belongs to latent-sim, which steps the reduced methods.
pub use latent_sim::ReducedSolverConfig;

impl Scene {
    /// Reads and checks a scene file.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        if fem_core::io::names_a_mesh(path) {
            let name = path.file_name().unwrap_or_default().to_string_lossy();
            bail!(
                "{} is a mesh file, not a scene: {}",
                path.display(),
                match fem_core::io::check_format(path) {
                    Ok(()) => format!(
                        "write a scene file (.toml) that names it, `[mesh] path = \"{name}\"` \
                         (the README's \"Your own mesh\" has the smallest one)"
                    ),
                    Err(e) => e.to_string(),
                }
            );
        }
        // The cause in the message itself: a program printing `{e}` showed only "cannot read".
        let cannot = |why: &dyn std::fmt::Display| {
            anyhow::anyhow!("cannot read scene file {}: {why}", path.display())
        };
        let bytes = std::fs::read(path).map_err(|e| cannot(&e))?;
        let text = String::from_utf8(bytes).map_err(|e| {
            let model = e.as_bytes().starts_with(latent_sim::model::file::MAGIC)
                || path.extension().is_some_and(|x| x == "ldm");
            cannot(&if model {
                "it is a model file, not a scene (a model file is loaded by \
                 `ReducedModel::load`, Python's `Model.load` or `view --model`)"
            } else {
                "it is not UTF-8 text: save the scene (TOML) as UTF-8"
            })
        })?;
        let base = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        Self::from_str(&text, base, &path.display().to_string())
    }

    /// The built-in default scene (needs no file).
    pub fn builtin() -> Self {
        Self::from_str(
            DEFAULT_SCENE,
            &crate::project_root().join("data"),
            "<built-in cantilever>",
        )
        .expect("the built-in scene is valid")
    }

    /// Parses scene text; `source` names it in errors and `base_dir` anchors relative paths.
    pub fn from_str(text: &str, base_dir: &Path, source: &str) -> Result<Self> {
        let mut scene = read_toml(text, source)?;
        scene.base_dir = base_dir.to_path_buf();
        scene.source = source.to_string();
        scene.check()?;
        Ok(scene)
    }

    /// Checks every section and reports all problems together.
    pub fn check(&self) -> Result<()> {
        let mut errors = Vec::new();
        if let Some(reason) = name_problem(&self.name) {
            errors.push(FemError::InvalidConfig {
                field: "name".into(),
                reason,
            });
        }
        self.material.check(&mut errors);
        self.time.check(&mut errors);
        if self.time.frames > fem_core::integrator::MAX_FRAMES {
            errors.push(FemError::InvalidConfig {
                field: "time.frames".into(),
                reason: format!(
                    "at most {} (each is a time step every method simulates), got {}",
                    fem_core::integrator::MAX_FRAMES,
                    self.time.frames
                ),
            });
        }
        self.solver.check(&mut errors);
        self.reduced.check(&mut errors);
        self.training().check("training", &mut errors);
        self.test().check("test", &mut errors);
        if let Some(t) = self.test.tolerance {
            errors.push(FemError::InvalidConfig {
                field: "test.tolerance".into(),
                reason: format!(
                    "got {t}, but the held-out test is solved to `[solver] tolerance` (as is every \
                     full-space run it is compared with); set that instead"
                ),
            });
        }
        if self.test.gravity == Some(GravityDirections::Any) {
            errors.push(FemError::InvalidConfig {
                field: "test.gravity".into(),
                reason: "the held-out test falls along the scene's gravity (`[gravity] \
                         acceleration`), as every method it measures does; `\"any\"` is for \
                         `[training]`"
                    .into(),
            });
        }
        if self.training.gravity == Some(GravityDirections::Any)
            && !(self.gravity.is_on() && self.training().gravity_scale > 0.0)
        {
            errors.push(FemError::InvalidConfig {
                field: "training.gravity".into(),
                reason: "`\"any\"` turns the scene's gravity, and the training data has none \
                         (`[gravity] acceleration`, `[training] gravity_scale`)"
                    .into(),
            });
        }
        let mut cub_errors = Vec::new();
        self.cubature.check(&mut cub_errors);
        for e in cub_errors {
            errors.push(match e {
                cubature::CubatureError::InvalidConfig { field, reason } => {
                    FemError::InvalidConfig { field, reason }
                }
                other => FemError::InvalidConfig {
                    field: "cubature".into(),
                    reason: other.to_string(),
                },
            });
        }
        let mut nn_errors = Vec::new();
        self.autoencoder.check(&mut nn_errors);
        for e in nn_errors {
            errors.push(match e {
                nn::NnError::InvalidConfig { field, reason } => {
                    FemError::InvalidConfig { field, reason }
                }
                other => FemError::InvalidConfig {
                    field: "autoencoder".into(),
                    reason: other.to_string(),
                },
            });
        }
        let mut pca_errors = Vec::new();
        self.pca.check(&mut pca_errors);
        let training = self.training();
        let poses = training
            .schedules
            .saturating_mul(training.frames_per_schedule);
        if let Some(k) = self.pca.dimension
            && k > poses
        {
            errors.push(FemError::InvalidConfig {
                field: "pca.dimension".into(),
                reason: format!(
                    "{k} is more than the {poses} training poses ([training] schedules × \
                     frames_per_schedule = {} × {}) can span: give at most {poses}, or more \
                     schedules or frames",
                    training.schedules, training.frames_per_schedule
                ),
            });
        }
        for e in pca_errors {
            errors.push(match e {
                pca::PcaError::InvalidConfig { field, reason } => {
                    FemError::InvalidConfig { field, reason }
                }
                other => FemError::InvalidConfig {
                    field: "pca".into(),
                    reason: other.to_string(),
                },
            });
        }
        if self.gravity.acceleration.iter().any(|g| !g.is_finite()) {
            errors.push(FemError::InvalidConfig {
                field: "gravity.acceleration".into(),
                reason: format!("must be finite, got {:?}", self.gravity.acceleration),
            });
        }
        self.mesh.check(&self.base_dir, &mut errors);
        for (i, p) in self.pin.iter().enumerate() {
            check_selection(p, &format!("pin[{i}]"), &mut errors);
        }
        for (i, f) in self.force.iter().enumerate() {
            check_force(f, &format!("force[{i}]"), &mut errors);
        }
        if self.pin.is_empty()
            && let Some(why) = self.unsupported_because()
        {
            errors.push(FemError::InvalidConfig {
                field: "pin".into(),
                reason: format!(
                    "the scene pins no vertex and no spring holds the body for the whole run, so {why}: add a [[pin]] section"
                ),
            });
        }
        if let Err(e) = FemError::collect(errors) {
            bail!("{}: invalid scene:\n{}", self.source, indent(&e));
        }
        Ok(())
    }

    /// Why the body needs support (pins, or a spring acting for the whole run), if it does:
    /// `None` for a dynamic scene without gravity (a free-floating body) or one held by a spring.
    fn unsupported_because(&self) -> Option<String> {
        if self.holding_spring().is_some() {
            None
        } else {
            self.unsupported_without_forces()
        }
    }

    /// The first `[[force]]` spring acting for the whole run, which holds a body no pin holds.
    fn holding_spring(&self) -> Option<usize> {
        (0..self.force.len()).find(|&i| self.holding_spring_at(i))
    }

    /// Whether `force[i]` is a spring acting for the whole run.
    fn holding_spring_at(&self, i: usize) -> bool {
        let f = &self.force[i];
        f.kind == ForceKind::Spring && f.start <= 0.0 && f.end.is_none_or(|e| e.is_infinite())
    }

    /// Where the training schedules and the test leave the scene's own `[[force]]` out (they
    /// pull, poke and drag with their own) and a spring alone held the body: what it does
    /// there, as an error to say before a stage falls freely for minutes (a tester's bar held
    /// by a spring fell 0.42 m in 0.3 s in every schedule and the test, its methods judged
    /// against that fall without a word).
    pub fn unsupported_in_stages(&self) -> Option<String> {
        if !self.pin.is_empty() {
            return None;
        }
        let spring = self.holding_spring()?;
        // Stages whose schedules all fall under no gravity leave a dynamic body floating.
        let weightless = self.training().gravity_scale == 0.0 && self.test().gravity_scale == 0.0;
        if weightless && !self.time.quasi_static {
            return None;
        }
        let why = self.unsupported_without_forces()?;
        Some(format!(
            "the scene pins no vertex and only force[{spring}]'s spring holds the body, but {}: \
             add a [[pin]] section (`simulate --method full` follows the scene's own forces \
             without the stages)",
            stages_drop_forces(&why)
        ))
    }

    /// Why the body needs support without any force, if it does.
    fn unsupported_without_forces(&self) -> Option<String> {
        if self.time.quasi_static {
            Some("a quasi-static solve has no equilibrium".into())
        } else if self.gravity.is_on() {
            Some(format!(
                "it falls freely under gravity {:?}",
                self.gravity.acceleration
            ))
        } else {
            None
        }
    }

    /// With a loaded mesh: every connected piece needs a pinned vertex when the body needs
    /// support (a pin that only selects vertices no tet uses holds nothing).
    /// `pieces` is [`TetMesh::vertex_components`].
    fn check_pieces(
        &self,
        mesh: &TetMesh,
        (piece, count): &(Vec<usize>, usize),
        pinned: &[usize],
        errors: &mut Vec<FemError>,
        warnings: &mut Vec<String>,
    ) {
        let (piece, count) = (piece.as_slice(), *count);
        if pinned.is_empty() {
            return; // reported by `check` (or selection errors), not again per piece
        }
        let Some(why) = self.unsupported_without_forces() else {
            return;
        };
        let mut held = vec![false; count];
        for &v in pinned {
            if let Some(h) = held.get_mut(piece[v]) {
                *h = true;
            }
        }
        // A spring acting for the whole run holds the pieces it grabs, in the scene's own
        // trajectory (`simulate`), and no other: before stop 76 one such spring anywhere let
        // every unpinned piece through. The stages pull with their own loads, so there only
        // the pins hold a piece.
        let mut by_spring = vec![None; count];
        for (i, f) in self.force.iter().enumerate() {
            if self.holding_spring_at(i)
                && let Ok(vertices) = f.select.select(mesh, &format!("force[{i}].select"))
            {
                for v in vertices {
                    if let Some(h) = by_spring.get_mut(piece[v]) {
                        h.get_or_insert(i);
                    }
                }
            }
        }
        for (c, spring) in by_spring.iter().enumerate() {
            if let (Some(i), false) = (spring, held[c]) {
                let line = format!(
                    "piece {} of the {count} disconnected pieces of the mesh is held by force[{i}]'s \
                     spring and no pin: {} (a [[pin]] that selects a vertex of it holds it in \
                     every stage)",
                    c + 1,
                    stages_drop_forces(&why)
                );
                crate::pipeline::warn_once(&format!("{}: {line}", self.source));
                warnings.push(line);
                held[c] = true;
            }
        }
        for (c, _) in held.iter().enumerate().filter(|(_, h)| !**h) {
            let members: Vec<usize> = (0..mesh.num_vertices())
                .filter(|&v| piece[v] == c)
                .collect();
            let centre = members
                .iter()
                .fold(fem_core::Vec3::zeros(), |s, &v| s + mesh.vertices[v])
                / members.len() as f64;
            let what = if count == 1 {
                "the mesh".to_string()
            } else {
                format!(
                    "piece {} of the {count} disconnected pieces of the mesh ({} vertices around ({:.3}, {:.3}, {:.3}))",
                    c + 1,
                    members.len(),
                    centre.x,
                    centre.y,
                    centre.z
                )
            };
            errors.push(FemError::InvalidConfig {
                field: "pin".into(),
                reason: format!(
                    "no pinned vertex holds {what} (pins on vertices no tet uses hold nothing), so {why}: add a [[pin]] that selects a vertex of it"
                ),
            });
        }
        let weight = self.gravity.is_on() && !self.time.quasi_static;
        let remedy = || self.wider_pin(mesh, piece, pinned);
        for line in loosely_held(mesh, pinned, piece, count, weight, &remedy) {
            crate::pipeline::warn_once(&format!("{}: {line}", self.source));
            warnings.push(line);
        }
    }

    /// What holds a body the pins hold at a point or along a line: the first pin plane that,
    /// with a tolerance of [`WIDER_PIN`] of the body's extent along its axis, holds more of the
    /// body's vertices than the pins do now and not all on one line, and how many; else the
    /// first sphere pin with the radius that takes in [`WIDER_SPHERE_SHARE`] of them; else the
    /// first box pin grown until it does; else a `box`. `piece` is
    /// [`TetMesh::vertex_components`]'s labels, `pinned` the pins' vertices.
    fn wider_pin(&self, mesh: &TetMesh, piece: &[usize], pinned: &[usize]) -> String {
        let (lo, hi) = mesh.bounding_box();
        let in_body = |v: &usize| of_body(piece, *v);
        let held_now = pinned.iter().filter(|v| in_body(v)).count();
        // How many of the body's vertices `selection` holds, where that is more than the pins
        // hold now and not all on one line.
        let holds_more = |selection: VertexSelection| {
            let at: Vec<fem_core::Vec3> = selection
                .select(mesh, "pin")
                .ok()?
                .into_iter()
                .filter(in_body)
                .map(|v| mesh.vertices[v])
                .collect();
            (at.len() > held_now && !collinear(&at)).then_some(at.len())
        };
        let wider = self.pin.iter().enumerate().find_map(|(i, p)| {
            let plane = p.plane.as_ref()?;
            let a = plane.axis.index();
            let tolerance = WIDER_PIN * (hi[a] - lo[a]);
            let mut wide = plane.clone();
            wide.tolerance = Some(tolerance);
            let held = holds_more(VertexSelection {
                plane: Some(wide),
                ..Default::default()
            })?;
            Some(format!(
                "pin[{i}]'s plane with `tolerance = {tolerance:.3e}` ({:.0} % of the body's \
                 extent along {}) holds {held} vertices, or a `box` holds it fixed",
                100.0 * WIDER_PIN,
                ["x", "y", "z"][a],
            ))
        });
        // A sphere pin around the point (a tester's, at a single vertex, was told of a plane's
        // tolerance it did not have): the radius that takes in the nearest
        // [`WIDER_SPHERE_SHARE`] of the body's vertices, and at least four, off one line.
        let body = (0..mesh.num_vertices()).filter(|v| in_body(v)).count();
        let want = ((WIDER_SPHERE_SHARE * body as f64).ceil() as usize).max(4);
        let sphere = || {
            self.pin.iter().enumerate().find_map(|(i, p)| {
                let c = fem_core::Vec3::from(p.sphere.as_ref()?.center);
                let mut near: Vec<(f64, usize)> = (0..mesh.num_vertices())
                    .filter(|v| in_body(v))
                    .map(|v| ((mesh.vertices[v] - c).norm(), v))
                    .collect();
                near.sort_by(|a, b| a.0.total_cmp(&b.0));
                // Rounded up to the four figures it is printed with, so that the radius as
                // written takes in the vertex it was chosen for, and every vertex it takes in
                // counted (a grid puts several at one distance).
                let radius = up_to_four_figures(near.get(want - 1)?.0);
                let at: Vec<fem_core::Vec3> = near
                    .iter()
                    .take_while(|&&(d, _)| d <= radius)
                    .map(|&(_, v)| mesh.vertices[v])
                    .collect();
                let held = at.len();
                (held > held_now && !collinear(&at)).then(|| {
                    format!(
                        "pin[{i}]'s sphere with `radius = {}` holds {held} vertices, or a `box` \
                         holds it fixed",
                        four_digits(radius)
                    )
                })
            })
        };
        // A box pin (an advice follower's caught four vertices on one line and was told to use
        // a `box`): the box grown on every side by 1 %, 2 %, 4 %, … of the body's diagonal,
        // its corners on a grid of a ten-thousandth of it (rounded outward, so that the box as
        // printed takes in what it was chosen for), until it holds more of the body off one line.
        let diagonal = (hi - lo).norm();
        let grid = 10f64.powf((1e-4 * diagonal).log10().floor());
        let decimals = (-grid.log10()).round().clamp(0.0, 17.0) as usize;
        // A corner as printed, and its value read back: what is counted is what is written.
        let corner = |v: [f64; 3], round: fn(f64) -> f64| {
            let text = v.map(|x| format!("{:.decimals$}", round(x / grid) * grid));
            let value = text.clone().map(|t| t.parse::<f64>().unwrap_or(f64::NAN));
            (format!("[{}]", text.join(", ")), value)
        };
        let boxed = || {
            if diagonal.is_nan() || diagonal <= 0.0 {
                return None;
            }
            self.pin.iter().enumerate().find_map(|(i, p)| {
                let b = p.aabb.as_ref()?;
                (0..8).find_map(|step| {
                    let grow = 0.01 * diagonal * f64::from(1u32 << step);
                    let (min_text, min) = corner(b.min.map(|x| x - grow), f64::floor);
                    let (max_text, max) = corner(b.max.map(|x| x + grow), f64::ceil);
                    let held = holds_more(VertexSelection {
                        aabb: Some(fem_core::constraints::BoxSelector { min, max }),
                        ..Default::default()
                    })?;
                    Some(format!(
                        "pin[{i}]'s `box` grown to `min = {min_text}, max = {max_text}` holds \
                         {held} vertices off one line"
                    ))
                })
            })
        };
        // A tester's mesh in millimetres read as metres was told of a 5 m tolerance before the
        // warning of its size, and a 5 m tolerance once `[mesh] scale` was set holds everything.
        let units = self.mesh.scale.is_none() && unit_hint((hi - lo).norm()).is_some();
        match wider.or_else(sphere).or_else(boxed) {
            Some(advice) if units => format!(
                "{advice} (lengths in metres as the mesh is read now: if it is not in metres and \
                 you set `[mesh] scale`, scale them, a sphere's centre and a box's corners \
                 too)"
            ),
            Some(advice) => advice,
            None => "a pin plane's larger `tolerance`, or a `box`, holds it fixed".to_string(),
        }
    }

    /// When the pin planes hold more than [`MANY_PINNED`] of the body's `body` vertices
    /// (`held`): what that makes of the body, and, where no pin plane lies across the mesh's
    /// tallest axis, that a mesh made standing on another axis is pinned there.
    fn many_pinned(&self, mesh: &TetMesh, body: usize, held: usize) -> Option<String> {
        if body == 0 || held as f64 <= MANY_PINNED * body as f64 {
            return None;
        }
        let (lo, hi) = mesh.bounding_box();
        let extent = hi - lo;
        let name = ["x", "y", "z"];
        let tallest = (0..3).max_by(|&a, &b| extent[a].total_cmp(&extent[b]))?;
        let planes: Vec<usize> = self
            .pin
            .iter()
            .filter_map(|p| p.plane.as_ref().map(|q| q.axis.index()))
            .collect();
        let turn = match planes.first() {
            Some(&a) if !planes.contains(&tallest) => format!(
                "; the mesh is tallest along {} ({} m, against {} m along {}): if it was made \
                 standing or hanging along {}, set the pin plane's `axis` and `[gravity]` to it",
                name[tallest],
                four_digits(extent[tallest]),
                four_digits(extent[a]),
                name[a],
                name[tallest]
            ),
            _ => String::new(),
        };
        Some(format!(
            "the pin planes hold {held} of the body's {body} vertices ({:.0} %), where a body \
             stands or hangs from a few percent of them: the rest moves as a body glued along a \
             whole side{turn}",
            100.0 * held as f64 / body as f64
        ))
    }

    /// With the mesh loaded: the pins must leave some vertex of the body free. `body` counts
    /// the body's vertices, `held` those the pins hold, `selected` each pin's.
    fn check_pinned_not_all(
        body: usize,
        held: usize,
        selected: &[usize],
        errors: &mut Vec<FemError>,
    ) {
        if body == 0 || held < body {
            return;
        }
        let counts: Vec<String> = selected
            .iter()
            .enumerate()
            .map(|(i, n)| format!("pin[{i}] selects {n}"))
            .collect();
        errors.push(FemError::InvalidConfig {
            field: "pin".into(),
            reason: format!(
                "the pins hold every one of the body's {body} vertices ({}), so nothing is left \
                 to move: select fewer (lengths, a plane's `tolerance` included, are in metres \
                 after `[mesh] scale`)",
                counts.join(", ")
            ),
        });
    }

    /// The training schedule family, defaults filled in. Its solves stop at `[training]
    /// tolerance`, by default the looser of [`fem_core::snapshots::TRAINING_TOLERANCE`] and
    /// `[solver] tolerance`.
    pub fn training(&self) -> ScheduleConfig {
        let mut cfg = self.training.resolve(ScheduleConfig::training());
        let solver = self.solver.tolerance;
        // An invalid `[solver] tolerance` is reported under its own name, not again here.
        if self.training.tolerance.is_none() && solver > 0.0 && solver < 1.0 {
            cfg.tolerance = cfg.tolerance.map(|t| t.max(solver));
        }
        cfg
    }

    /// The test schedule family, defaults filled in.
    pub fn test(&self) -> ScheduleConfig {
        self.test.resolve(ScheduleConfig::test())
    }

    /// Raises `[test] schedules` to at least `count`: how many test trajectories a plain `run`
    /// measures. Every index has its trajectory whatever the count (trajectory i depends only
    /// on the test's seed and i), and no cache key depends on it.
    pub fn raise_test_trajectories(&mut self, count: usize) {
        let have = self.test().schedules;
        self.test.schedules = Some(have.max(count));
    }

    /// Loads the mesh, selects pins and forces, and builds the full-space model.
    pub fn build_model(&self) -> Result<BuiltModel> {
        let (mesh, report) = self
            .mesh
            .load(&self.base_dir)
            .map_err(|e| anyhow::anyhow!("{}: [mesh]: {e}", self.source))?;
        let mut errors = Vec::new();
        let pieces = mesh.vertex_components();
        let in_body = |v: &&usize| of_body(&pieces.0, **v);
        let body = mesh.num_vertices() - report.unreferenced_vertices;
        let mut pinned = Vec::new();
        // Each pin's vertices of the body, and those of the pin planes.
        let (mut selected, mut by_planes) = (Vec::new(), Vec::new());
        for (i, p) in self.pin.iter().enumerate() {
            match p.select(&mesh, &format!("pin[{i}]")) {
                Ok(v) => {
                    selected.push(v.iter().filter(in_body).count());
                    if p.plane.is_some() {
                        by_planes.extend(v.iter().copied().filter(|v| in_body(&v)));
                    }
                    pinned.extend(v);
                }
                Err(e) => errors.push(e),
            }
        }
        pinned.sort_unstable();
        pinned.dedup();
        let held = pinned.iter().filter(in_body).count();
        if errors.is_empty() {
            Self::check_pinned_not_all(body, held, &selected, &mut errors);
        }
        let mut warnings = Vec::new();
        if errors.is_empty() {
            self.check_pieces(&mesh, &pieces, &pinned, &mut errors, &mut warnings);
        }
        by_planes.sort_unstable();
        by_planes.dedup();
        if errors.is_empty()
            && let Some(line) = self.many_pinned(&mesh, body, by_planes.len())
        {
            crate::pipeline::warn_once(&format!("{}: {line}", self.source));
            warnings.push(line);
        }
        let mut forces = Vec::new();
        for (i, f) in self.force.iter().enumerate() {
            match f.resolve(&mesh, &format!("force[{i}]")) {
                // Vertices no tet uses are left out, as for the pins: a spring's stiffness goes
                // to the body's vertices, and the runtime refuses the others.
                Ok(mut f) => {
                    // The runtime's limit, said before any stage runs.
                    let body =
                        latent_sim::body_stiffness(&mesh.vertices, self.material.youngs_modulus);
                    let limit = latent_sim::MAX_SPRING_STIFFNESS * body;
                    if f.kind == ForceKind::Spring && f.stiffness > limit {
                        let e = latent_sim::RuntimeError::TooStiff {
                            stiffness: f.stiffness,
                            body,
                            limit,
                        };
                        errors.push(FemError::InvalidConfig {
                            field: format!("force[{i}].stiffness"),
                            reason: e.to_string(),
                        });
                    }
                    // A point load's too: past it the first step failed its line search, a
                    // message that named no field.
                    let loads = f.keyframes.iter().map(|k| [k[1], k[2], k[3]]);
                    if f.kind == ForceKind::Point
                        && let Err(e) = latent_sim::check_point_load(
                            &mesh.vertices,
                            self.material.youngs_modulus,
                            loads,
                        )
                    {
                        errors.push(FemError::InvalidConfig {
                            field: format!("force[{i}].keyframes"),
                            reason: e.to_string(),
                        });
                    }
                    let selected = f.vertices.len();
                    f.vertices.retain(|v| in_body(&v));
                    let stray = selected - f.vertices.len();
                    if f.vertices.is_empty() {
                        errors.push(FemError::InvalidConfig {
                            field: format!("force[{i}].select"),
                            reason: format!(
                                "selects only vertices no tet uses ({stray}), which are no part \
                                 of the body: select vertices of the body"
                            ),
                        });
                    } else if f.vertices.iter().all(|v| pinned.binary_search(v).is_ok()) {
                        errors.push(FemError::InvalidConfig {
                            field: format!("force[{i}].select"),
                            reason: format!(
                                "selects only pinned vertices ({}): a force on them moves \
                                 nothing; select free vertices",
                                f.vertices.len()
                            ),
                        });
                    } else {
                        if stray > 0 {
                            crate::pipeline::warn_once(&format!(
                                "{}: force[{i}] selects {stray} vertices no tet uses; they are \
                                 left out of it",
                                self.source
                            ));
                        }
                        forces.push(f);
                    }
                }
                Err(e) => errors.push(e),
            }
        }
        if let Err(e) = FemError::collect(errors) {
            bail!("{}: invalid scene:\n{}", self.source, indent(&e));
        }
        let model = FullSpaceModel::new(
            mesh,
            &self.material,
            pinned,
            self.gravity.acceleration.into(),
            forces,
        )
        .map_err(|e| anyhow::anyhow!("{}: {e}", self.source))?;
        Ok(BuiltModel {
            model,
            validation: report,
            held_vertices: held,
            pin_vertices: selected,
            warnings,
        })
    }
}

/// Whether vertex `v` is part of the body: some tet uses it, so it has a piece among
/// [`TetMesh::vertex_components`]'s labels `piece` (pins and forces on other vertices hold and
/// pull nothing).
fn of_body(piece: &[usize], v: usize) -> bool {
    piece[v] != NO_COMPONENT
}

/// What [`Scene::build_model`] builds, and what it found on the way.
#[derive(Debug)]
pub struct BuiltModel {
    pub model: FullSpaceModel,
    /// What validating the mesh found (the body's vertices are the mesh's but its
    /// `unreferenced_vertices`).
    pub validation: ValidationReport,
    /// How many of the body's vertices the pins hold.
    pub held_vertices: usize,
    /// How many of the body's vertices each `[[pin]]` selects, in the scene's order (two pins
    /// may select the same vertex).
    pub pin_vertices: Vec<usize>,
    /// What the scene allows and a run should still say (pins that hold a piece at a point or
    /// along a line), each a sentence, already printed once.
    pub warnings: Vec<String>,
}

/// The pieces of a body that needs support which the pins hold at one point or along one line,
/// each a sentence: such a piece turns about them (a pin plane whose default tolerance caught
/// the one lowest vertex of a curved body hangs it like a pendulum). Allowed, since a hinge may
/// be meant, and said. `piece` and `count` are [`TetMesh::vertex_components`].
/// `weight`: whether gravity loads the body, so that one vertex would carry it all; `remedy`
/// what holds it instead (asked for only when a piece is so held: it selects the pins again).
fn loosely_held(
    mesh: &TetMesh,
    pinned: &[usize],
    piece: &[usize],
    count: usize,
    weight: bool,
    remedy: &dyn Fn() -> String,
) -> Vec<String> {
    let mut lines = Vec::new();
    for c in 0..count {
        let at: Vec<fem_core::Vec3> = pinned
            .iter()
            .filter(|&&v| piece.get(v) == Some(&c))
            .map(|&v| mesh.vertices[v])
            .collect();
        if at.is_empty() || !collinear(&at) {
            continue;
        }
        let what = if count == 1 {
            "the body".to_string()
        } else {
            format!("piece {} of the mesh's {count}", c + 1)
        };
        let (how, about) = if at.len() == 1 {
            ("at a single vertex".to_string(), "it")
        } else {
            (format!("by {} vertices on one line", at.len()), "that line")
        };
        // One vertex cannot carry a weight: a point load on a finite-element mesh stretches the
        // elements around it without limit (a bunny hung so stretched them 3.6× in 1 s under
        // gravity alone while the rest fell freely).
        let carried = if weight && at.len() == 1 {
            ", and one vertex cannot carry its weight: the elements around it stretch without \
             limit while the rest falls"
        } else {
            ""
        };
        lines.push(format!(
            "the pins hold {what} {how}, so it can turn about {about}{carried}; {}",
            remedy()
        ));
    }
    lines
}

/// Whether `points` lie on one line: one point, or all within 10⁻⁶ of their extent of the line
/// through the first and the point farthest from it.
fn collinear(points: &[fem_core::Vec3]) -> bool {
    let Some(&a) = points.first() else {
        return true;
    };
    let Some(&b) = points
        .iter()
        .max_by(|p, q| (*p - a).norm().total_cmp(&(*q - a).norm()))
    else {
        return true;
    };
    let axis = b - a;
    let extent = axis.norm();
    if extent == 0.0 {
        return true;
    }
    let axis = axis / extent;
    points.iter().all(|p| {
        let r = p - a;
        (r - axis * r.dot(&axis)).norm() <= 1e-6 * extent
    })
}

/// Why a spring that holds a body or a piece of it holds nothing in the stages, where `why`
/// (what the body does unheld) then happens.
fn stages_drop_forces(why: &str) -> String {
    format!(
        "the training schedules and the test pull, poke and drag with their own loads, not the \
         scene's [[force]] sections, so there {why}"
    )
}

/// Most unknown keys reported at once: the reading goes on past one by blanking it.
const MAX_UNKNOWN_KEYS_SAID: usize = 8;

/// Most unknown keys read past, of which the first [`MAX_UNKNOWN_KEYS_SAID`] in the file's order
/// are said: the reading meets them section by section in the scene's own order, not the file's.
const MAX_UNKNOWN_KEYS_READ: usize = 64;

/// Reads a scene's TOML; each error names its field and what to write where it can. An unknown
/// key (a typo) does not hide the ones after it: the reading goes on with the key read as the
/// one it was a slip for, or set aside, until another kind of error, so a scene with three
/// typos hears of all three at once.
fn read_toml(text: &str, source: &str) -> Result<Scene> {
    let mut read = text.to_string();
    let mut said = Vec::new();
    // Whether an entry was set aside (blanked), which may leave a field missing.
    let mut blanked = false;
    let mut more = false;
    loop {
        let e = match toml::from_str::<Scene>(&read) {
            Ok(scene) if said.is_empty() => return Ok(scene),
            Ok(_) => break,
            Err(e) => e,
        };
        // A field missing once a key is set aside was the key's, and a key read as another
        // that the scene gives too is a duplicate of the reading's making.
        if !said.is_empty()
            && ((blanked && e.message().starts_with("missing field"))
                || toml::de::DeTable::parse(&read).is_err())
        {
            break;
        }
        let field = e.span().and_then(|span| field_at(&read, span.start));
        let hint = e
            .span()
            .and_then(|span| parse_hint(&read, span.start, e.message(), field.as_deref()));
        // Said in the order of the file, not of the reading.
        let line = e
            .span()
            .map_or(usize::MAX, |span| read[..span.start].matches('\n').count());
        said.push((
            line,
            format!(
                "{source}: {}{e}{}",
                field.as_ref().map_or(String::new(), |f| format!("`{f}`: ")),
                match (&hint, e.span()) {
                    (Some(h), Some(span)) =>
                        format!("{}\n", h.said(&read, span.start, field.as_deref())),
                    _ => String::new(),
                }
            ),
        ));
        let Some(span) = e
            .span()
            .filter(|_| e.message().starts_with("unknown field `"))
        else {
            break;
        };
        if said.len() == MAX_UNKNOWN_KEYS_READ {
            more = true;
            break;
        }
        // The key read as the one it was near, else the entry set aside. Spaces keep every
        // later byte where it was; a key read as another of a different length shifts the
        // rest of its line, whose later errors (two typos in one inline table) then show the
        // key as read and a column off by the difference.
        let meant = match &hint {
            Some(Hint::Meant(key)) => Some(key.as_str()),
            _ => None,
        };
        match (meant, entry_at(&read, span.start)) {
            (Some(key), _) => read.replace_range(span, key),
            (None, Some(range)) => {
                blanked = true;
                let blank: String = read[range.clone()]
                    .chars()
                    .map(|c| if c == '\n' || c == '\r' { c } else { ' ' })
                    .collect();
                read.replace_range(range, &blank);
            }
            (None, None) => break,
        }
    }
    said.sort_by_key(|(line, _)| *line);
    more |= said.len() > MAX_UNKNOWN_KEYS_SAID;
    said.truncate(MAX_UNKNOWN_KEYS_SAID);
    let mut said: Vec<String> = said.into_iter().map(|(_, text)| text).collect();
    if more {
        said.push(format!(
            "{source}: and more: the reading stops at {MAX_UNKNOWN_KEYS_SAID} unknown keys"
        ));
    }
    bail!("{}", said.join("\n"))
}

/// What [`parse_hint`] found to write instead of a scene's mistake.
enum Hint {
    /// A key or a name a letter or two off this one the field takes.
    Meant(String),
    /// Arithmetic (`value`, as written) whose number is `result`.
    Arithmetic { value: String, result: f64 },
    /// Any other advice, in words.
    Said(String),
}

impl Hint {
    /// The hint in words, for an error at byte `at` of the scene `text` in `field`. Arithmetic
    /// in a field that counts (`frames = 10/3`) whose number is no count says so: the scene
    /// read again with the number in its place tells whether the field takes a whole number.
    fn said(&self, text: &str, at: usize, field: Option<&str>) -> String {
        let (value, x) = match self {
            Hint::Meant(key) => return format!("did you mean `{key}`?"),
            Hint::Said(words) => return words.clone(),
            Hint::Arithmetic { value, result } => (value.as_str(), *result),
        };
        let plain = format!("TOML does no arithmetic: write the number, {x} for `{value}`");
        let line_start = text[..at].rfind('\n').map_or(0, |i| i + 1);
        let Some(place) = text[line_start..].find(value).map(|i| line_start + i) else {
            return plain;
        };
        if x.fract() == 0.0 {
            return plain;
        }
        let mut tried = text.to_string();
        tried.replace_range(place..place + value.len(), &x.to_string());
        match toml::from_str::<Scene>(&tried) {
            Err(e)
                if e.message().starts_with("invalid type: floating point")
                    && e.span().is_some_and(|s| s.start == place) =>
            {
                // The nearest count, at least 1 (`1/3` is no 0 frames).
                let nearest = x.round().max(1.0);
                format!(
                    "TOML does no arithmetic, and {} takes a whole number: `{value}` is {x}; \
                     write a whole number such as {nearest}",
                    field.map_or("this field".to_string(), |f| format!("`{f}`")),
                )
            }
            _ => plain,
        }
    }
}

/// The bytes of the `key = value` entry whose key starts at byte `key_at` of a TOML text, with
/// the comma that joins it to its neighbours inside an inline table or array; None for a
/// table's header (`[unknown]`), whose keys run on to the next header.
fn entry_at(text: &str, key_at: usize) -> Option<std::ops::Range<usize>> {
    fn find(
        table: &toml::de::DeTable<'_>,
        text: &str,
        at: usize,
    ) -> Option<std::ops::Range<usize>> {
        table.iter().find_map(|(key, value)| {
            let (k, v) = (key.span(), value.span());
            if k.start == at {
                let inline = !matches!(value.get_ref(), toml::de::DeValue::Table(_))
                    || text.get(v.clone()).is_some_and(|t| t.starts_with('{'));
                return inline.then_some(k.start..v.end);
            }
            within(value.get_ref(), text, at)
        })
    }
    fn within(
        value: &toml::de::DeValue<'_>,
        text: &str,
        at: usize,
    ) -> Option<std::ops::Range<usize>> {
        match value {
            toml::de::DeValue::Table(t) => find(t, text, at),
            toml::de::DeValue::Array(a) => a.iter().find_map(|v| within(v.get_ref(), text, at)),
            _ => None,
        }
    }
    let root = toml::de::DeTable::parse(text).ok()?;
    let range = find(root.get_ref(), text, key_at)?;
    let after = &text[range.end..];
    let gap = after.len() - after.trim_start_matches([' ', '\t']).len();
    if after[gap..].starts_with(',') {
        return Some(range.start..range.end + gap + 1);
    }
    let before = text[..range.start].trim_end();
    Some(if before.ends_with(',') {
        before.len() - 1..range.end
    } else {
        range
    })
}

/// The dotted name (`material.poisson_ratio`, `pin[1].sphere.radius`) of the key or table
/// header at byte `offset` of a TOML text: TOML errors give a position, a user wants the field.
fn field_at(text: &str, offset: usize) -> Option<String> {
    let offset = (0..=offset.min(text.len()))
        .rev()
        .find(|&o| text.is_char_boundary(o))?;
    let line_start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[offset..].find('\n').map_or(text.len(), |i| offset + i);
    let line = &text[line_start..line_end];
    // `[name]` or `[[name]]` (the `index`-th of its array of tables).
    let header = |l: &str, counts: &mut std::collections::HashMap<String, usize>| {
        let l = l.split('#').next().unwrap_or_default().trim();
        if let Some(name) = l.strip_prefix("[[").and_then(|r| r.strip_suffix("]]")) {
            let name = name.trim().to_string();
            let n = counts.entry(name.clone()).or_default();
            *n += 1;
            Some(format!("{name}[{}]", *n - 1))
        } else {
            l.strip_prefix('[')
                .and_then(|r| r.strip_suffix(']'))
                .map(|name| name.trim().to_string())
        }
    };
    let mut counts = std::collections::HashMap::new();
    let mut section = None;
    for l in text[..line_start].lines() {
        if let Some(h) = header(l, &mut counts) {
            section = Some(h);
        }
    }
    if let Some(h) = header(line, &mut counts) {
        return Some(h.split('[').next().unwrap_or_default().to_string());
    }
    // A broken header (`[time`, `[[pin`) names no field, not the section before it either;
    // a line of a multi-line array (`  [0.3, 0.1],`) is no header.
    let opening = line.trim_start().trim_start_matches('[');
    if line.trim_start().starts_with('[')
        && opening.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_' || c == '"')
    {
        return None;
    }
    // Keys on the line up to the error, through inline tables: `a = { b = { c = 1 } }`.
    let col = offset - line_start;
    let bytes = line.as_bytes();
    let is_key = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b'-' || c == b'.';
    let (mut stack, mut last): (Vec<String>, Option<String>) = (Vec::new(), None);
    let (mut i, mut in_string) = (0, false);
    while i < bytes.len() && i <= col {
        let c = bytes[i];
        if in_string {
            in_string = c != b'"';
        } else if c == b'"' {
            in_string = true;
        } else if c == b'#' {
            break;
        } else if c == b'{' {
            stack.extend(last.take());
        } else if c == b'}' {
            last = stack.pop();
        } else if is_key(c) {
            let start = i;
            while i < bytes.len() && is_key(bytes[i]) {
                i += 1;
            }
            let rest = line[i..].trim_start();
            if rest.starts_with('=') && !rest.starts_with("==") {
                last = Some(line[start..i].to_string());
            }
            continue;
        }
        i += 1;
    }
    let parts: Vec<String> = section.into_iter().chain(stack).chain(last).collect();
    (!parts.is_empty()).then(|| parts.join("."))
}

/// What to write instead, for mistakes a person makes in a scene's TOML: a key or a name a
/// letter or two off one the field takes, a single `[pin]` where the list `[[pin]]` is meant,
/// a Unicode minus or a decimal comma pasted from a document, and arithmetic in a value
/// (`step = 1/60`, which TOML reads as an unquoted string).
fn parse_hint(text: &str, offset: usize, message: &str, field: Option<&str>) -> Option<Hint> {
    let unknown = ["unknown field `", "unknown variant `"]
        .iter()
        .find_map(|p| message.strip_prefix(p));
    if let Some(rest) = unknown {
        let (key, expected) = rest.split_once('`')?;
        // A key of a word's length, not a pasted paragraph (the distance costs its length
        // times each known key's).
        if key.chars().count() > 64 {
            return None;
        }
        let nearest = expected
            .split('`')
            .skip(1)
            .step_by(2)
            .map(|known| (edit_distance(key, known), known))
            .min()?;
        // A slip of a letter or two, not another word (`gravity_directions` is not
        // `onset_directions`).
        return (nearest.0 <= (key.chars().count() / 3).clamp(1, 2))
            .then(|| Hint::Meant(nearest.1.to_string()));
    }
    if message.starts_with("invalid type: map, expected a sequence") {
        // Only the scene's lists of tables, `[pin]` and `[force]`: a map for `pin.plane` or
        // `indices` is no `[[plane]]` or `[[indices]]`.
        let name = field.filter(|f| ["pin", "force"].contains(f))?;
        return Some(Hint::Said(format!(
            "write `[[{name}]]`, with doubled brackets: each is one entry of a list, and a \
             scene may have several"
        )));
    }
    let start = (0..=offset.min(text.len()))
        .rev()
        .find(|&o| text.is_char_boundary(o))?;
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next()?;
    let code = line.split('#').next()?;
    // A minus sign TOML does not read: a Unicode minus or dash pasted from a document, outside
    // a quoted string (where a dash is text).
    let mut quoted = false;
    if let Some(c) = code.chars().find(|&c| {
        quoted ^= c == '"';
        !quoted && ['\u{2212}', '\u{2013}', '\u{2014}'].contains(&c)
    }) {
        return Some(Hint::Said(format!(
            "write `-`, the ASCII minus, where `{c}` (U+{:04X}) stands: TOML reads no other \
             character as a sign",
            u32::from(c)
        )));
    }
    // Decimal commas in a list (`acceleration = [0,0, -9,81, 0,0]`), which TOML reads as more
    // values than the list takes: a comma between two digits names the first.
    if let Some(rest) = message.strip_prefix("invalid length ") {
        // Only a list longer than it should be: decimal commas add values.
        let number = |s: &str| {
            s.split(|c: char| !c.is_ascii_digit())
                .next()?
                .parse::<usize>()
                .ok()
        };
        let (got, expected) = (number(rest)?, number(rest.split_once("a list of ")?.1)?);
        if got <= expected {
            return None;
        }
        // The list the error is of: from its `[` to the end of its line (ASCII, so a byte after
        // a digit or a comma is a character's start).
        let from = (start - line_start).min(code.len());
        let list = &code[from..];
        let list = &list[..list.find(']').unwrap_or(list.len())];
        let b = list.as_bytes();
        // Outside quoted strings, where a comma is text.
        let quoted: Vec<bool> = b
            .iter()
            .scan(false, |q, &c| {
                *q ^= c == b'"';
                Some(*q)
            })
            .collect();
        let tight: Vec<usize> = (1..b.len().saturating_sub(1))
            .filter(|&i| {
                b[i] == b',' && !quoted[i] && b[i - 1].is_ascii_digit() && b[i + 1].is_ascii_digit()
            })
            .collect();
        // Read as decimal points, those commas must leave the length the list takes.
        if got - tight.len() != expected {
            return None;
        }
        let comma = *tight.first()?;
        let before = &list[..comma];
        let whole = &before[before.trim_end_matches(|c: char| c.is_ascii_digit()).len()..];
        let after = &list[comma + 1..];
        let fraction =
            &after[..after.len() - after.trim_start_matches(|c: char| c.is_ascii_digit()).len()];
        return Some(Hint::Said(format!(
            "decimal commas? TOML's decimal point is a dot, and a comma separates a list's \
             values: write `{whole}.{fraction}`, not `{whole},{fraction}`"
        )));
    }
    // A decimal comma (`poisson_ratio = 0,4`) outside an array, where a comma separates numbers.
    let value = code.split_once('=').map(|(_, v)| v.trim());
    if let Some((whole, fraction)) = value.and_then(|v| v.split_once(','))
        && !whole.is_empty()
        && whole
            .trim_start_matches('-')
            .chars()
            .all(|c| c.is_ascii_digit())
        && !fraction.is_empty()
        && fraction.starts_with(|c: char| c.is_ascii_digit())
        && {
            // Digits, then an exponent if any (`1,0e5`).
            let (digits, exponent) = fraction.split_at(
                fraction
                    .find(|c: char| !c.is_ascii_digit())
                    .unwrap_or(fraction.len()),
            );
            !digits.is_empty()
                && (exponent.is_empty()
                    || exponent
                        .strip_prefix(['e', 'E'])
                        .map(|e| e.trim_start_matches(['+', '-']))
                        .is_some_and(|e| !e.is_empty() && e.chars().all(|c| c.is_ascii_digit())))
        }
    {
        // Three digits after the comma may be thousands (`frames = 1,000`).
        let thousands = if fraction.len() == 3 && fraction.chars().all(|c| c.is_ascii_digit()) {
            format!(", or `{whole}{fraction}` if the comma separates thousands")
        } else {
            String::new()
        };
        return Some(Hint::Said(format!(
            "write `{whole}.{fraction}`: TOML's decimal point is a dot, never a comma{thousands}"
        )));
    }
    // The first `/` or `*` from the error to the end of its line, without a comment: TOML points
    // at the value (`step = 1/60`) or, inside an array, at the operator (`[0.0, -9.81/6, 0.0]`),
    // and the operators after it (`1/60/2`), left to right.
    let from = (start - line_start).min(code.len());
    let mut op_at = from + code[from..].find(['/', '*'])?;
    // The numbers on either side of it (ASCII, so byte offsets are characters).
    let number = |c: char| c.is_ascii_digit() || ".eE+-_".contains(c);
    let parse = |s: &str| s.replace('_', "").parse::<f64>().ok();
    let left = code[..op_at].trim_end();
    let a_from = left.rfind(|c: char| !number(c)).map_or(0, |i| {
        i + left[i..].chars().next().map_or(1, char::len_utf8)
    });
    let mut result = parse(&left[a_from..])?;
    let mut b_to;
    loop {
        let right = &code[op_at + 1..];
        let b_from = op_at + 1 + (right.len() - right.trim_start().len());
        b_to = b_from
            + code[b_from..]
                .find(|c: char| !number(c))
                .unwrap_or(code.len() - b_from);
        let b = parse(&code[b_from..b_to])?;
        result = if code[op_at..].starts_with('/') {
            result / b
        } else {
            result * b
        };
        let rest = &code[b_to..];
        let next = b_to + (rest.len() - rest.trim_start().len());
        match code[next..].chars().next() {
            Some('/' | '*') => op_at = next,
            _ => break,
        }
    }
    result.is_finite().then(|| Hint::Arithmetic {
        value: code[a_from..b_to].to_string(),
        result,
    })
}

/// The distance between two keys in slips of the hand: letters inserted, left out, mistyped
/// or two neighbours swapped (`lbgfs`), case aside (`LBFGS`); optimal string alignment.
fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().flat_map(char::to_lowercase).collect();
    let b: Vec<char> = b.chars().flat_map(char::to_lowercase).collect();
    // d[i][j]: the distance between a[..i] and b[..j].
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for j in 0..=b.len() {
        d[0][j] = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let mut best = (d[i - 1][j] + 1)
                .min(d[i][j - 1] + 1)
                .min(d[i - 1][j - 1] + usize::from(a[i - 1] != b[j - 1]));
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(d[i - 2][j - 2] + 1);
            }
            d[i][j] = best;
        }
    }
    d[a.len()][b.len()]
}

/// The checks of [`VertexSelection::select`] that need no mesh, so they are reported with the
/// rest of the scene's errors.
fn check_selection(sel: &VertexSelection, field: &str, errors: &mut Vec<FemError>) {
    let mut bad = |sub: &str, reason: String| {
        errors.push(FemError::InvalidConfig {
            field: format!("{field}{sub}"),
            reason,
        })
    };
    let given = [
        sel.plane.is_some(),
        sel.aabb.is_some(),
        sel.sphere.is_some(),
        sel.indices.is_some(),
    ]
    .iter()
    .filter(|b| **b)
    .count();
    if given != 1 {
        bad(
            "",
            format!("give exactly one of `plane`, `box`, `sphere`, `indices` ({given} given)"),
        );
        return;
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if let Some(t) = sel.plane.as_ref().and_then(|p| p.tolerance)
        && !(t.is_finite() && t >= 0.0)
    {
        bad(
            ".plane.tolerance",
            format!("must be a non-negative number, got {t}"),
        );
    }
    if let Some(b) = &sel.aabb
        && (!finite(&b.min) || !finite(&b.max) || (0..3).any(|i| b.min[i] > b.max[i]))
    {
        bad(
            ".box",
            format!(
                "needs finite min ≤ max on every axis, got min {:?} and max {:?}",
                b.min, b.max
            ),
        );
    }
    if let Some(s) = &sel.sphere
        && !(finite(&s.center) && s.radius.is_finite() && s.radius > 0.0)
    {
        bad(
            ".sphere",
            format!(
                "needs a finite center and a positive radius, got center {:?} and radius {}",
                s.center, s.radius
            ),
        );
    }
    if sel.indices.as_ref().is_some_and(Vec::is_empty) {
        bad(".indices", "is empty: it selects no vertex".into());
    }
}

/// The checks of [`ForceConfig::resolve`] that need no mesh.
fn check_force(f: &ForceConfig, field: &str, errors: &mut Vec<FemError>) {
    check_selection(&f.select, &format!("{field}.select"), errors);
    let mut bad = |sub: &str, reason: String| {
        errors.push(FemError::InvalidConfig {
            field: format!("{field}.{sub}"),
            reason,
        })
    };
    match (f.kind, f.stiffness) {
        (ForceKind::Spring, Some(k)) if !(k.is_finite() && k > 0.0) => {
            bad("stiffness", format!("must be positive, got {k}"));
        }
        (ForceKind::Spring, None) => bad("stiffness", "a spring needs a stiffness".into()),
        (ForceKind::Point, Some(_)) => bad("stiffness", "only springs have a stiffness".into()),
        _ => {}
    }
    if f.keyframes.is_empty() {
        bad("keyframes", "needs at least one [t, x, y, z]".into());
    }
    if f.keyframes.iter().flatten().any(|v| !v.is_finite()) {
        bad("keyframes", "values must be finite".into());
    }
    if f.keyframes.windows(2).any(|w| w[1][0] < w[0][0]) {
        bad("keyframes", "times must not decrease".into());
    }
    if !f.start.is_finite() {
        bad("start", format!("must be finite, got {}", f.start));
    }
    // An empty span (start = end) never acts: the runtime refuses it too.
    if let Some(end) = f.end
        && (end.is_nan() || end <= f.start)
    {
        bad(
            "end",
            format!("needs start < end, got {} and {end}", f.start),
        );
    }
}

fn indent(e: &FemError) -> String {
    match e {
        FemError::Many(list) => list
            .iter()
            .map(|e| format!("  - {e}"))
            .collect::<Vec<_>>()
            .join("\n"),
        e => format!("  - {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A body pinned at one vertex or along one edge is said to turn about it; three vertices
    /// off one line hold it.
    #[test]
    fn a_body_held_at_a_point_or_a_line_is_said_to_turn() {
        use fem_core::mesh::generate::{BoxSpec, box_mesh};
        let mesh = box_mesh(&BoxSpec {
            size: [1.0, 0.2, 0.2],
            cells: [4, 1, 1],
            ..Default::default()
        })
        .unwrap();
        let (piece, count) = mesh.vertex_components();
        let at_x0: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].x == 0.0)
            .collect();
        assert_eq!(at_x0.len(), 4);
        let held = |pinned: &[usize], weight| {
            loosely_held(&mesh, pinned, &piece, count, weight, &|| "R".into())
        };
        assert!(held(&at_x0, true).is_empty());
        let one = held(&at_x0[..1], true);
        assert_eq!(one.len(), 1);
        assert!(one[0].contains("the body at a single vertex"), "{one:?}");
        assert!(one[0].contains("cannot carry its weight"), "{one:?}");
        assert!(one[0].ends_with("; R"), "{one:?}");
        assert!(!held(&at_x0[..1], false)[0].contains("weight"));
        let edge: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].y == 0.0 && mesh.vertices[v].z == 0.0)
            .collect();
        let line = held(&edge, true);
        assert!(line[0].contains("by 5 vertices on one line"), "{line:?}");
        assert!(!line[0].contains("weight"), "{line:?}");
    }

    /// The advice for a body held at one vertex: the pin plane that holds 2 % of its extent,
    /// with its count, when that holds more of the body than the pins do; else a box.
    #[test]
    fn a_wider_pin_is_advised_only_where_it_holds_more() {
        let text = "name = \"w\"\n[mesh]\ngenerate = { kind = \"box\", size = [1.0, 0.2, \
                    0.2], cells = [4, 1, 1] }\n[[pin]]\nplane = { axis = \"x\", side = \"min\", \
                    tolerance = 0.0 }\n";
        let scene = Scene::from_str(text, Path::new("."), "w.toml").unwrap();
        let mesh = scene.build_model().unwrap().model.mesh;
        let (piece, _) = mesh.vertex_components();
        let face: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].x == 0.0)
            .collect();
        let one = scene.wider_pin(&mesh, &piece, &face[..1]);
        assert!(
            one.starts_with(
                "pin[0]'s plane with `tolerance = 2.000e-2` (2 % of the body's extent \
                             along x) holds 4 vertices"
            ),
            "{one}"
        );
        let all = scene.wider_pin(&mesh, &piece, &face);
        assert!(all.starts_with("a pin plane's larger `tolerance`"), "{all}");
        assert!(!one.contains("`[mesh] scale`"), "{one}");
        // The same bar 1,000 times larger (a file in millimetres read as metres): the length
        // advised is said to scale with `[mesh] scale`.
        let big = text.replace("size = [1.0, 0.2, 0.2]", "size = [1000.0, 200.0, 200.0]");
        let scene_mm = Scene::from_str(&big, Path::new("."), "w.toml").unwrap();
        let mesh_mm = scene_mm.build_model().unwrap().model.mesh;
        let one_mm = scene_mm.wider_pin(&mesh_mm, &piece, &face[..1]);
        assert!(
            one_mm.starts_with("pin[0]'s plane with `tolerance = 2.000e1`")
                && one_mm.ends_with(
                    "you set `[mesh] scale`, scale them, a sphere's centre and a box's corners \
                     too)"
                ),
            "{one_mm}"
        );
        // Not where no length is advised, nor once the scene sets a scale.
        let all_mm = scene_mm.wider_pin(&mesh_mm, &piece, &face);
        assert!(!all_mm.contains("`[mesh] scale`"), "{all_mm}");
        let scaled = big.replace("[[pin]]", "scale = 1.0\n[[pin]]");
        let scene_scaled = Scene::from_str(&scaled, Path::new("."), "w.toml").unwrap();
        let one_scaled = scene_scaled.wider_pin(&mesh_mm, &piece, &face[..1]);
        assert!(!one_scaled.contains("`[mesh] scale`"), "{one_scaled}");
        // A box pin along an edge (two vertices on one line): the box grown until it holds
        // more, off the line, and as printed, written back, it holds what was said; also off
        // the origin, at negative coordinates, where corners are rounded outward.
        for origin in [[0.0, 0.0, 0.0], [-3.65, -1.2, 0.35]] {
            let [x, y, z] = origin;
            let pin = format!(
                "box = {{ min = [{}, {}, {}], max = [{}, {}, {}] }}",
                x - 0.001,
                y - 0.001,
                z - 1.0,
                x + 0.001,
                y + 0.001,
                z + 1.0
            );
            let edge = text
                .replace(
                    "plane = { axis = \"x\", side = \"min\", tolerance = 0.0 }",
                    &pin,
                )
                .replace(
                    "cells = [4, 1, 1] }",
                    &format!("cells = [4, 1, 1], origin = [{x}, {y}, {z}] }}"),
                );
            let scene_edge = Scene::from_str(&edge, Path::new("."), "w.toml").unwrap();
            let mesh = scene_edge.build_model().unwrap().model.mesh;
            let (piece, _) = mesh.vertex_components();
            let on_edge: Vec<usize> = (0..mesh.num_vertices())
                .filter(|&v| mesh.vertices[v].x == x && mesh.vertices[v].y == y)
                .collect();
            assert_eq!(on_edge.len(), 2, "{origin:?}");
            let grown = scene_edge.wider_pin(&mesh, &piece, &on_edge);
            let printed = grown
                .strip_prefix("pin[0]'s `box` grown to `")
                .and_then(|r| r.split('`').next())
                .unwrap_or_else(|| panic!("{grown}"));
            let said: usize = grown
                .rsplit("holds ")
                .next()
                .and_then(|r| r.split(' ').next())
                .and_then(|n| n.parse().ok())
                .unwrap_or_else(|| panic!("{grown}"));
            assert!(
                said > 2 && grown.ends_with("vertices off one line"),
                "{grown}"
            );
            let written = edge.replace(&pin, &format!("box = {{ {printed} }}"));
            let rebuilt = Scene::from_str(&written, Path::new("."), "w.toml").unwrap();
            assert_eq!(
                rebuilt.build_model().unwrap().held_vertices,
                said,
                "{written}"
            );
        }
        // A sphere pin at one corner: the radius that takes in four vertices off one line (the
        // corner's three neighbours at 0.2, 0.2 and 0.25 m).
        let text = text.replace(
            "plane = { axis = \"x\", side = \"min\", tolerance = 0.0 }",
            "sphere = { center = [0.0, 0.0, 0.0], radius = 0.01 }",
        );
        let scene = Scene::from_str(&text, Path::new("."), "w.toml").unwrap();
        let corner: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| mesh.vertices[v].norm() == 0.0)
            .collect();
        let one = scene.wider_pin(&mesh, &piece, &corner);
        assert!(
            one.starts_with("pin[0]'s sphere with `radius = 0.2500` holds 4 vertices"),
            "{one}"
        );
        // At the middle of a face two cells across, four vertices lie at the fourth distance:
        // all five the radius takes in are counted.
        let text = text
            .replace("cells = [4, 1, 1]", "cells = [4, 2, 2]")
            .replace("center = [0.0, 0.0, 0.0]", "center = [0.0, 0.1, 0.1]");
        let scene = Scene::from_str(&text, Path::new("."), "w.toml").unwrap();
        let mesh = scene.build_model().unwrap().model.mesh;
        let (piece, _) = mesh.vertex_components();
        let centre: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| (mesh.vertices[v] - fem_core::Vec3::new(0.0, 0.1, 0.1)).norm() < 1e-12)
            .collect();
        let one = scene.wider_pin(&mesh, &piece, &centre);
        assert!(
            one.starts_with("pin[0]'s sphere with `radius = 0.1000` holds 5 vertices"),
            "{one}"
        );
        // The printed radius never falls short of the distance it was chosen for.
        assert_eq!(four_digits(up_to_four_figures(0.12344)), "0.1235");
        assert!(up_to_four_figures(0.12344) >= 0.12344);
        assert!(up_to_four_figures(0.1) >= 0.1);
    }

    /// A body its own weight would strain past [`HEAVY_BODY`] is said, with `[mesh] scale`
    /// first when it is larger than a soft part usually is: the built-in scene is far below
    /// it, the same bar 100 times larger above.
    #[test]
    fn a_body_too_heavy_for_its_stiffness_is_said() {
        let s = Scene::builtin();
        let model = s.build_model().unwrap().model;
        let (lo, hi) = model.mesh.bounding_box();
        let extent: [f64; 3] = (hi - lo).into();
        assert_eq!(weight_warning(&s, extent), None);
        let large = extent.map(|x| 100.0 * x);
        let w = weight_warning(&s, large).expect("a bar 100 times larger");
        assert!(w.contains("`[mesh] scale`"), "{w}");
        assert!(w.contains("youngs_modulus"), "{w}");
        // A body of its own size made 1,000 times softer: units are not what to change.
        let mut soft = s.clone();
        soft.material.youngs_modulus /= 1000.0;
        let w = weight_warning(&soft, extent).expect("a bar too soft to hold itself");
        assert!(!w.contains("`[mesh] scale`"), "{w}");
        assert!(w.contains("youngs_modulus"), "{w}");
        let mut weightless = s.clone();
        weightless.gravity.acceleration = [0.0; 3];
        assert_eq!(weight_warning(&weightless, large), None);
        // The height along gravity counts, not the size: a long, low body lying across it.
        let mut down = s.clone();
        down.gravity.acceleration = [0.0, -9.81, 0.0];
        assert_eq!(weight_warning(&down, [100.0, 0.1, 0.1]), None);
        assert!(weight_warning(&down, [0.1, 100.0, 0.1]).is_some());
    }

    /// A density written in g/cm³ (or far above any element) is said; every real solid's is not.
    #[test]
    fn a_density_in_other_units_is_said() {
        let w = density_warning(1.0).expect("1 kg/m³");
        assert!(
            w.contains("g/cm³") && w.contains("1000 times too small"),
            "{w}"
        );
        assert!(density_warning(30_000.0).is_some());
        for rho in [12.0, 30.0, 920.0, 1000.0, 1100.0, 7850.0, 19_300.0] {
            assert_eq!(density_warning(rho), None, "{rho}");
        }
        assert_eq!(unit_hint(UNIT_MISTAKE_SIZE), None);
        assert!(unit_hint(14.0).is_some_and(|h| h.starts_with("at 14.0 m across")));
    }

    #[test]
    fn builtin_scene_parses_and_builds() {
        let s = Scene::builtin();
        assert_eq!(s.name, "cantilever");
        let model = s.build_model().unwrap().model;
        assert!(!model.pinned.is_empty());
        assert_eq!(model.forces.len(), 1);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_named() {
        let bad = DEFAULT_SCENE.replace("poisson_ratio = 0.45", "poisson_ratio = 0.5\npoison = 1");
        let err = Scene::from_str(&bad, Path::new("."), "bad.toml").unwrap_err();
        assert!(err.to_string().contains("poison"), "{err}");
        let bad = DEFAULT_SCENE
            .replace("poisson_ratio = 0.45", "poisson_ratio = 0.5")
            .replace("step = 0.01", "step = -1.0");
        let err = Scene::from_str(&bad, Path::new("."), "bad.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("bad.toml"), "{err}");
        assert!(err.contains("material.poisson_ratio"), "{err}");
        assert!(err.contains("time.step"), "{err}");
    }

    /// A mesh file given where a scene goes is named as such, with the line that takes it.
    #[test]
    fn a_mesh_file_given_as_the_scene_is_named() {
        for file in ["bunny.mesh", "part.MSH", "a.node"] {
            let err = Scene::from_file(Path::new(file)).unwrap_err().to_string();
            assert!(err.contains("is a mesh file, not a scene"), "{err}");
            assert!(
                err.contains(&format!("`[mesh] path = \"{file}\"`")),
                "{err}"
            );
        }
        // A format no reader takes gets its own advice, not a `[mesh] path` that would fail.
        let err = Scene::from_file(Path::new("part.stl"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("is a mesh file, not a scene") && err.contains("tetgen"),
            "{err}"
        );
        assert!(!err.contains("[mesh] path = \"part.stl\""), "{err}");
    }

    /// The name becomes the folder `out/<name>`: a path in it would write elsewhere.
    #[test]
    fn a_name_that_is_a_path_is_refused() {
        let named = |name: &str| {
            let text =
                DEFAULT_SCENE.replacen("name = \"cantilever\"", &format!("name = {name:?}"), 1);
            Scene::from_str(&text, Path::new("."), "n.toml")
        };
        for bad in [
            "../../elsewhere",
            "/tmp/abs",
            "a\\b",
            "..",
            ".",
            "tab\there",
            " ",
        ] {
            let err = named(bad).unwrap_err().to_string();
            assert!(
                err.contains("n.toml") && err.contains("name"),
                "{bad:?}: {err}"
            );
        }
        for good in ["my-part", "bunny 2", "x.v2", "a:b"] {
            assert_eq!(named(good).unwrap().name, good);
        }
    }

    /// The training data's solves stop at 10⁻² unless the solver's own tolerance is looser or
    /// `[training] tolerance` says otherwise; the test trajectory keeps the solver's.
    #[test]
    fn training_solves_take_their_own_tolerance() {
        let with = |extra: &str| {
            Scene::from_str(
                &format!("{DEFAULT_SCENE}\n{extra}"),
                Path::new("."),
                "t.toml",
            )
        };
        let s = with("").unwrap();
        assert_eq!(s.training().tolerance, Some(1e-2));
        assert_eq!(s.test().tolerance, None);
        assert_eq!(s.training().solver(&s.solver).tolerance, 1e-2);
        assert_eq!(s.test().solver(&s.solver).tolerance, s.solver.tolerance);
        let s = with("[solver]\ntolerance = 5.0e-2\n").unwrap();
        assert_eq!(s.training().tolerance, Some(5e-2));
        let s = with("[training]\ntolerance = 1.0e-7\n").unwrap();
        assert_eq!(s.training().tolerance, Some(1e-7));
        for (extra, says) in [
            (
                "[test]\ntolerance = 1.0e-4\n",
                ["test.tolerance", "[solver] tolerance"],
            ),
            (
                "[training]\ntolerance = 0.0\n",
                ["training.tolerance", "t.toml"],
            ),
            (
                "[test]\ngravity = \"any\"\n",
                ["test.gravity", "[training]"],
            ),
            ("[training]\ngravity = \"sideways\"\n", ["`any`", "t.toml"]),
        ] {
            let err = with(extra).unwrap_err().to_string();
            assert!(says.iter().all(|s| err.contains(s)), "{err}");
        }
        let s = with("[training]\ngravity = \"any\"\n").unwrap();
        assert_eq!(s.training().gravity, GravityDirections::Any);
        assert_eq!(s.test().gravity, GravityDirections::Scene);
        let weightless = DEFAULT_SCENE.replace(
            "acceleration = [0.0, -9.81, 0.0]",
            "acceleration = [0.0, 0.0, 0.0]",
        );
        let err = Scene::from_str(
            &format!("{weightless}\n[training]\ngravity = \"any\"\n"),
            Path::new("."),
            "t.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("training.gravity") && err.contains("has none"),
            "{err}"
        );
        let err = with("[training]\ngravity = \"any\"\ngravity_scale = 0.0\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("gravity_scale"), "{err}");
    }

    #[test]
    fn linear_directions_default_to_none_and_are_bounded() {
        let reduced = Scene::builtin().reduced;
        assert_eq!(
            (reduced.onset_directions, reduced.complement_directions),
            (None, None)
        );
        for (field, max) in [("onset_directions", 32), ("complement_directions", 256)] {
            let with = |m: usize| format!("{DEFAULT_SCENE}\n[reduced]\n{field} = {m}\n");
            let s = Scene::from_str(&with(max), Path::new("."), "ok.toml").unwrap();
            let got = (s.reduced.onset_directions, s.reduced.complement_directions);
            assert!(
                got == (Some(max), None) || got == (None, Some(max)),
                "{field}: {got:?}"
            );
            let err = Scene::from_str(&with(max + 1), Path::new("."), "bad.toml")
                .unwrap_err()
                .to_string();
            assert!(err.contains(&format!("reduced.{field}")), "{err}");
        }
    }

    #[test]
    fn pins_selecting_nothing_are_errors() {
        let bad = DEFAULT_SCENE.replace(
            "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
            "sphere = { center = [9.0, 9.0, 9.0], radius = 0.1 }",
        );
        let s = Scene::from_str(&bad, Path::new("."), "bad.toml").unwrap();
        let err = s.build_model().unwrap_err().to_string();
        assert!(err.contains("pin[0]") && err.contains("no vertex"), "{err}");
    }
}
