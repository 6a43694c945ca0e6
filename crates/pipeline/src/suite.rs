//! The mesh suite: a minimal scene (mesh, material, pins, gravity, time step and nothing else)
//! on each mesh of a folder, every method run from an empty cache, one table of the outcomes.
//! What a user who arrives with their own mesh gets from the defaults, measured.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use fem_core::TetMesh;
use fem_core::constraints::Axis;
use fem_core::material::MaterialModel;
use fem_core::mesh::generate::{BoxSpec, GeneratedShape, box_mesh};

use crate::pipeline::{Pipeline, Progress};
use crate::run::{MethodReport, RunOptions, run};
use crate::scene::Scene;
use crate::simulate::Method;
use crate::trajectories::{Spread, run_more, spreads};

/// The materials a suite cycles through, one per mesh in turn, so that every material runs on
/// some mesh.
pub const MATERIALS: [MaterialModel; 5] = [
    MaterialModel::StableNeoHookean,
    MaterialModel::NeoHookean,
    MaterialModel::Corotated,
    MaterialModel::Stvk,
    MaterialModel::Linear,
];

/// The methods the suite runs: both full-space solvers (the faster is the speed-ups' base; the
/// minimal scene's `full` is the default L-BFGS) and the four reduced methods.
pub const METHODS: [Method; 6] = [
    Method::Full,
    Method::FullNewton,
    Method::Pca,
    Method::PcaCubature,
    Method::Neural,
    Method::NeuralCubature,
];

/// The fraction of the mesh's height pinned at its bottom (AutoDef pinned the vertices within
/// a tolerance of the lowest plane; 2 % is the dinosaur's 5 mm of 25 cm): what a scene's
/// single-vertex pin is advised to widen to.
pub const PIN_FRACTION: f64 = crate::scene::WIDER_PIN;

/// A mesh of the suite: a file, or a shape generated in code (the long run's large meshes).
#[derive(Debug, Clone, PartialEq)]
pub enum SuiteMesh {
    File(PathBuf),
    Box {
        name: String,
        kind: GeneratedShape,
        size: [f64; 3],
        cells: [usize; 3],
    },
}

impl SuiteMesh {
    /// The mesh's name in the suite's table and folders: the file's stem (its format added where
    /// another format's file could share it), or the generated shape's name.
    pub fn name(&self) -> String {
        match self {
            // MEDIT files by their stem, as before; other formats with their extension, so
            // that `beam.mesh` and `beam.msh` in one folder run apart.
            SuiteMesh::File(path) => {
                let stem = path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "mesh".into());
                match path.extension().map(|e| e.to_string_lossy().to_lowercase()) {
                    Some(ext) if ext != "mesh" => format!("{stem}-{ext}"),
                    _ => stem,
                }
            }
            SuiteMesh::Box { name, .. } => name.clone(),
        }
    }

    /// The scene's `[mesh]` keys.
    /// The `[mesh]` section's keys; a file's coordinates times `scale` are metres.
    fn section(&self, scale: f64) -> String {
        match self {
            // Absolute, so that the scene file the suite writes beside its results reads it.
            SuiteMesh::File(path) => {
                format!(
                    "path = {:?}",
                    std::path::absolute(path)
                        .unwrap_or_else(|_| path.clone())
                        .display()
                        .to_string()
                ) + &if scale == 1.0 {
                    String::new()
                } else {
                    format!("\nscale = {scale:?}")
                }
            }
            SuiteMesh::Box {
                kind, size, cells, ..
            } => format!(
                "generate = {{ kind = {:?}, size = [{:?}, {:?}, {:?}], cells = [{}, {}, {}] }}",
                kind.name(),
                size[0],
                size[1],
                size[2],
                cells[0],
                cells[1],
                cells[2]
            ),
        }
    }

    /// The mesh: the file read, or the shape generated.
    ///
    /// # Errors
    /// When the file cannot be read or the spec is invalid.
    pub fn read(&self) -> Result<TetMesh> {
        match self {
            SuiteMesh::File(path) => Ok(read(path)?.0),
            SuiteMesh::Box {
                kind, size, cells, ..
            } => Ok(box_mesh(&BoxSpec {
                kind: *kind,
                size: *size,
                cells: *cells,
                ..Default::default()
            })?),
        }
    }
}

/// The generated meshes of the suite's long run (`cargo xtask suite --generated`): the default
/// scene's bar (3,321 vertices, 15,360 tets), a bar of 11,475 vertices and 58,800 tets, the
/// size at which defaults that do not scale stop (memory of the cubature fit, snapshot time),
/// and a figure 30 cm tall, the scale of AutoDef's meshes, whose arms and head swing about its
/// trunk (6,532 vertices, 30,078 tets: the size of the three-minute pipeline the project aims
/// at).
pub fn generated() -> Vec<SuiteMesh> {
    vec![
        SuiteMesh::Box {
            name: "bar-15k".into(),
            kind: GeneratedShape::Box,
            size: [1.0, 0.2, 0.2],
            cells: [40, 8, 8],
        },
        SuiteMesh::Box {
            name: "bar-60k".into(),
            kind: GeneratedShape::Box,
            size: [1.0, 0.28, 0.28],
            cells: [50, 14, 14],
        },
        SuiteMesh::Box {
            name: "figure-30k".into(),
            kind: GeneratedShape::Figure,
            size: [0.3, 0.3, 0.1],
            cells: [39, 39, 13],
        },
    ]
}

/// The minimal scene of a mesh file whose coordinates times `scale` are metres (`[mesh]
/// scale`): its material, Young's modulus `youngs_modulus`, the bottom [`PIN_FRACTION`] of its
/// height along `up` pinned, gravity along −`up`, h = 0.01 s; every other section at its
/// default.
pub fn minimal_scene(
    mesh: &Path,
    material: MaterialModel,
    youngs_modulus: f64,
    up: Axis,
    scale: f64,
) -> Result<Scene> {
    let mesh = SuiteMesh::File(mesh.to_path_buf());
    minimal_scene_of(&mesh.read()?, &mesh, material, youngs_modulus, up, scale)
}

fn read(mesh: &Path) -> Result<(TetMesh, fem_core::mesh::ValidationReport)> {
    fem_core::io::read_mesh(mesh).with_context(|| format!("cannot read mesh {}", mesh.display()))
}

/// [`minimal_scene`] of `mesh`, already read into `m`.
fn minimal_scene_of(
    m: &TetMesh,
    mesh: &SuiteMesh,
    material: MaterialModel,
    youngs_modulus: f64,
    up: Axis,
    scale: f64,
) -> Result<Scene> {
    let text = minimal_scene_text(m, mesh, material, youngs_modulus, up, scale)?;
    parse_minimal_scene(&text, mesh)
}

fn parse_minimal_scene(text: &str, mesh: &SuiteMesh) -> Result<Scene> {
    Scene::from_str(
        text,
        Path::new("."),
        &format!("minimal scene of {}", mesh.name()),
    )
}

/// The TOML of [`minimal_scene_of`], as the suite writes it beside each mesh's results.
fn minimal_scene_text(
    m: &TetMesh,
    mesh: &SuiteMesh,
    material: MaterialModel,
    youngs_modulus: f64,
    up: Axis,
    scale: f64,
) -> Result<String> {
    // The generated shapes are in metres whatever the files' unit.
    let scale = match mesh {
        SuiteMesh::File(_) => scale,
        _ => 1.0,
    };
    let (lo, hi) = m.bounding_box();
    let model = serde_json::to_value(material)?;
    let model = model.as_str().unwrap_or("stable-neo-hookean");
    let a = up.index();
    let mut gravity = [0.0; 3];
    gravity[a] = -9.81;
    let text = format!(
        "name = {name:?}\n\
         [mesh]\n{section}\n\
         [material]\nmodel = {model:?}\nyoungs_modulus = {youngs_modulus:e}\npoisson_ratio = 0.45\n\
         [[pin]]\nplane = {{ axis = \"{axis}\", side = \"min\", tolerance = {tol:e} }}\n\
         [gravity]\nacceleration = [{:?}, {:?}, {:?}]\n\
         [time]\nstep = 0.01\n",
        gravity[0],
        gravity[1],
        gravity[2],
        name = format!("{}-{model}", mesh.name()),
        section = mesh.section(scale),
        axis = ["x", "y", "z"][a],
        // The pin selects after the scale, in metres.
        tol = PIN_FRACTION * (hi[a] - lo[a]) * scale,
    );
    Ok(text)
}

/// The mesh files of folder `dir` that the readers take (`.mesh`, `.msh`, `.vtk`, and a TetGen
/// pair by its `.ele` file), sorted, leaving out (and saying so) those with more vertices than
/// `max_vertices`. A file that cannot be read is kept: its row says why, and the other meshes
/// run.
///
/// # Errors
/// When the folder cannot be read, or no mesh is left.
pub fn meshes(dir: &Path, max_vertices: Option<usize>) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| anyhow::anyhow!("cannot read mesh folder {}: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && fem_core::io::is_mesh_file(p))
        .collect();
    files.sort();
    if let Some(max) = max_vertices {
        let mut kept = Vec::new();
        for f in files {
            match fem_core::io::read_mesh(&f) {
                Ok((m, _)) if m.num_vertices() > max => tracing::warn!(
                    "suite: leaving out {}: {} vertices, above --max-vertices {max}",
                    f.display(),
                    m.num_vertices()
                ),
                _ => kept.push(f),
            }
        }
        files = kept;
    }
    if files.is_empty() {
        anyhow::bail!(
            "no mesh files to run in {} (.mesh, .msh, .vtk, .vtu or TetGen .node/.ele)",
            dir.display()
        );
    }
    Ok(files)
}

/// Writes `suite.md` and `suite.json` into `out`.
pub fn write(out: &Path, rows: &[SuiteRow]) -> Result<()> {
    crate::output::create_folder(out, "the output folder", "for the results")?;
    crate::output::write_file(&out.join("suite.md"), markdown(rows).as_bytes())?;
    let mut json = Vec::with_capacity(rows.len());
    for row in rows {
        let mut value = serde_json::to_value(row)?;
        value["methods"] = serde_json::Value::Array(crate::run::report_rows(&row.methods)?);
        json.push(value);
    }
    crate::output::write_file(
        &out.join("suite.json"),
        serde_json::to_string_pretty(&json)?.as_bytes(),
    )?;
    Ok(())
}

/// One mesh's outcome.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SuiteRow {
    pub scene: String,
    pub vertices: usize,
    pub tets: usize,
    /// The pipeline's wall time from an empty cache, every stage and every method's run.
    pub pipeline_seconds: f64,
    /// Every method's report row on test trajectory 0 (the yardstick), or why the pipeline
    /// stopped.
    pub methods: Vec<MethodReport>,
    /// With more than one test trajectory: every method's error on each
    /// ([`crate::trajectories`]), and the seconds the trajectories after the first took.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub trajectories: Vec<Spread>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trajectories_seconds: Option<f64>,
    /// Why a trajectory after the first stopped (its spread then has gaps from there on).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trajectories_failure: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
}

/// What the suite's pipelines call when a stage starts to compute and when one ends (a log
/// shows which stage a mesh's minutes go to); `StageHooks::none()` calls nothing.
#[derive(Clone, Copy)]
pub struct StageHooks<'h> {
    pub start: &'h dyn Fn(crate::stage::Stage),
    pub end: &'h dyn Fn(&crate::pipeline::StageOutcome),
}

impl std::fmt::Debug for StageHooks<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StageHooks").finish_non_exhaustive()
    }
}

impl StageHooks<'static> {
    pub fn none() -> Self {
        Self {
            start: &|_| {},
            end: &|_| {},
        }
    }
}

/// Runs the minimal scene of each mesh (material `MATERIALS[i % 5]`; a mesh file standing on
/// `up` with its coordinates times `scale` in metres, the generated shapes on y in metres) from
/// an empty cache under `out/<scene>/`, returning one row
/// a mesh; a scene whose pipeline fails gets a row saying why.
/// With `trajectories` above 1 every method also runs on test trajectories 1..`trajectories`
/// (after the pipeline's time is taken), and the row holds their spread.
pub fn run_suite(
    meshes: &[SuiteMesh],
    youngs_modulus: f64,
    up: Axis,
    scale: f64,
    trajectories: usize,
    out: &Path,
    progress: Progress<'_>,
    on_mesh: &mut dyn FnMut(&str),
    stages: StageHooks<'_>,
) -> Result<Vec<SuiteRow>> {
    let mut rows = Vec::new();
    for (i, mesh) in meshes.iter().enumerate() {
        // Read once here for the scene's pin height and the table's sizes; the pipeline reads
        // it again as the scene's mesh. One that cannot be read gets its row, as a pipeline
        // that stops does.
        let m = match mesh.read() {
            Ok(m) => m,
            Err(e) => {
                rows.push(SuiteRow {
                    scene: mesh.name(),
                    vertices: 0,
                    tets: 0,
                    pipeline_seconds: 0.0,
                    methods: Vec::new(),
                    trajectories: Vec::new(),
                    trajectories_seconds: None,
                    trajectories_failure: None,
                    failure: Some(format!("{e:#}")),
                });
                continue;
            }
        };
        // The shapes generated in code stand on y whatever the folder's files do.
        let up = match mesh {
            SuiteMesh::File(_) => up,
            _ => Axis::Y,
        };
        let material = MATERIALS[i % MATERIALS.len()];
        let text = minimal_scene_text(&m, mesh, material, youngs_modulus, up, scale)?;
        let scene = parse_minimal_scene(&text, mesh)?;
        on_mesh(&scene.name);
        let dir = out.join(&scene.name);
        // The scene as run, to run again (`cargo xtask run --scene <dir>/scene.toml`).
        crate::output::create_folder(&dir, "the mesh's output folder", "for its results")?;
        crate::output::write_file(&dir.join("scene.toml"), text.as_bytes())?;
        let cache = dir.join("cache");
        if cache.exists() {
            std::fs::remove_dir_all(&cache)
                .with_context(|| format!("cannot empty {}", cache.display()))?;
        }
        let start = Instant::now();
        let opts = RunOptions {
            out: dir.clone(),
            every: 0,
            methods: METHODS.to_vec(),
            trajectory: 0,
        };
        let mut pipeline = Pipeline::new(&scene, &cache);
        let outcome = match &mut pipeline {
            Ok(p) => {
                p.on_stage_start = Box::new(stages.start);
                p.on_stage = Box::new(stages.end);
                run(p, &opts, progress, &mut |_, _, _| {})
            }
            Err(e) => Err(anyhow::anyhow!("{e:#}")),
        };
        let pipeline_seconds = start.elapsed().as_secs_f64();
        let (methods, failure) = match outcome {
            Ok(m) => (m, None),
            Err(e) => (Vec::new(), Some(format!("{e:#}"))),
        };
        let (mut spread, mut trajectories_seconds, mut trajectories_failure) =
            (Vec::new(), None, None);
        if let (Ok(p), None, true) = (&mut pipeline, &failure, trajectories > 1) {
            let start = Instant::now();
            let mut runs = vec![methods.clone()];
            let more = run_more(
                p,
                &opts,
                &mut runs,
                trajectories,
                progress,
                &mut |_| {},
                &mut |_, _, _| {},
            );
            if let Err(e) = more {
                trajectories_failure = Some(format!("test trajectory {}: {e:#}", runs.len()));
            }
            // The trajectories a failure left out are gaps: no mean, the worst of the others.
            runs.resize(trajectories, Vec::new());
            crate::trajectories::write(&dir, &runs)?;
            spread = spreads(&runs);
            trajectories_seconds = Some(start.elapsed().as_secs_f64());
        }
        rows.push(SuiteRow {
            scene: scene.name.clone(),
            vertices: m.num_vertices(),
            tets: m.num_tets(),
            pipeline_seconds,
            methods,
            trajectories: spread,
            trajectories_seconds,
            trajectories_failure,
            failure,
        });
    }
    Ok(rows)
}

/// Where `neural` stands against `linear` on the error–cost plane (mean error, mean ms per
/// step): `ahead` when at least as good on both and better on one, `behind` the other way round,
/// otherwise on a frontier with it, saying which way. Errors within [`LEVEL_ERROR`] of each
/// other are level, and so are step times within what a run's own times move (10 %, as the
/// standing line's reasons say): a tester's neural-cubature at d = k, the PCA subspace's rule,
/// was called "behind" at 0.224 against 0.219 ms and 3.92 against 3.92 %.
pub fn standing(neural: &MethodReport, linear: &MethodReport) -> &'static str {
    if neural.failure.is_some() || linear.failure.is_some() {
        return "—";
    }
    let (t, u) = (neural.ms_per_step, linear.ms_per_step);
    let faster = if (t - u).abs() <= crate::run::STEP_TIME_SPREAD * t.max(u) {
        std::cmp::Ordering::Equal
    } else {
        t.total_cmp(&u)
    };
    let (a, b) = (neural.mean_rel_error, linear.mean_rel_error);
    let closer = if level(a, b) {
        std::cmp::Ordering::Equal
    } else {
        a.total_cmp(&b)
    };
    use std::cmp::Ordering::{Equal, Greater, Less};
    match (faster, closer) {
        (Equal, Equal) => "tied",
        (Less | Equal, Less | Equal) => "ahead",
        (Greater | Equal, Greater | Equal) => "behind",
        (Less, Greater) => "frontier: faster, less accurate",
        (Greater, Less) => "frontier: more accurate, slower",
    }
}

/// Two mean errors this close, relative to the larger, are level on the error–cost plane: a
/// tester's flag was called "more accurate" at 1.184 against 1.185 % off.
pub const LEVEL_ERROR: f64 = 0.01;

/// Whether errors `a` and `b` are level: within [`LEVEL_ERROR`] of the larger.
pub fn level(a: f64, b: f64) -> bool {
    (a - b).abs() <= LEVEL_ERROR * a.max(b)
}

/// The suite's table: per mesh, every reduced method's mean error (its space–time error in
/// parentheses) and speed-up, the pipeline's time from an empty cache, and where
/// `neural-cubature` stands against `pca-cubature` ([`standing`]).
pub fn markdown(rows: &[SuiteRow]) -> String {
    let reduced = [
        Method::Pca,
        Method::PcaCubature,
        Method::Neural,
        Method::NeuralCubature,
    ];
    let mut s = String::from("| scene | vertices | tets | pipeline s |");
    for m in reduced {
        s += &format!(" {m} error (space-time) | {m} speed-up |");
    }
    s += " neural-cubature against pca-cubature |";
    s += "\n|---|---:|---:|---:|";
    s += &"---:|---:|".repeat(reduced.len());
    s += "---|\n";
    for r in rows {
        if r.vertices == 0 {
            // A mesh that could not be read: no sizes and no pipeline (its line says why).
            s += &format!("| {} | — | — | — |", r.scene);
        } else {
            s += &format!(
                "| {} | {} | {} | {:.0} |",
                r.scene, r.vertices, r.tets, r.pipeline_seconds
            );
        }
        for m in reduced {
            match r.methods.iter().find(|x| x.method == m) {
                Some(x) => {
                    s += &format!(
                        " {:.1} % ({:.1} %) | {} |",
                        100.0 * x.mean_rel_error,
                        100.0 * x.trajectory_error,
                        crate::run::speedup_cell(x.speedup, 0)
                    )
                }
                None => s += " — | — |",
            }
        }
        let find = |m: Method| r.methods.iter().find(|x| x.method == m);
        match (find(Method::NeuralCubature), find(Method::PcaCubature)) {
            (Some(n), Some(p)) => s += &format!(" {} |", standing(n, p)),
            _ => s += " — |",
        }
        s += "\n";
    }
    // Below the table, not between its rows, which would end it there.
    for r in rows {
        if let Some(f) = &r.failure {
            s += &format!("\n{}: stopped: {f}\n", r.scene);
        }
    }
    s += &spread_markdown(rows);
    for r in rows {
        s += &crate::trust::assess(&r.methods).text(&format!("{}, ", r.scene));
    }
    s
}

/// With more than one test trajectory, a second table: per mesh and reduced method, the mean
/// error over the trajectories and the worst with its trajectory (empty with one trajectory).
fn spread_markdown(rows: &[SuiteRow]) -> String {
    let Some(count) = rows
        .iter()
        .map(|r| r.trajectories.first().map_or(0, |t| t.errors.len()))
        .max()
        .filter(|&n| n > 1)
    else {
        return String::new();
    };
    let reduced = [
        Method::Pca,
        Method::PcaCubature,
        Method::Neural,
        Method::NeuralCubature,
    ];
    let mut s = format!(
        "\nOn test trajectories 0..{count} (0 is the table's): the mean error, then the worst \
         and its trajectory. The warnings below are trajectory 0's; trajectory i's own are in \
         `<scene>/trajectory-<i>/report.md`.\n\n| scene | trajectories s |"
    );
    for m in reduced {
        s += &format!(" {m} |");
    }
    s += "\n|---|---:|";
    s += &"---|".repeat(reduced.len());
    s += "\n";
    for r in rows.iter().filter(|r| !r.trajectories.is_empty()) {
        s += &format!(
            "| {} | {:.0} |",
            r.scene,
            r.trajectories_seconds.unwrap_or(0.0)
        );
        for m in reduced {
            let cell =
                r.trajectories
                    .iter()
                    .find(|t| t.method == m)
                    .map_or("—".to_string(), |t| {
                        let mean = t.mean.map_or("—".into(), |e| format!("{:.1} %", 100.0 * e));
                        match t.worst {
                            Some((i, e)) => format!("{mean} ({:.1} % on {i})", 100.0 * e),
                            None => mean,
                        }
                    });
            s += &format!(" {cell} |");
        }
        s += "\n";
    }
    for r in rows {
        if let Some(f) = &r.trajectories_failure {
            s += &format!("\n{}: stopped at {f}\n", r.scene);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standing_reads_the_error_cost_plane() {
        let at = |ms: f64, error: f64| MethodReport {
            ms_per_step: ms,
            mean_rel_error: error,
            ..Default::default()
        };
        let p = at(0.1, 0.02);
        assert_eq!(standing(&at(0.1, 0.02), &p), "tied");
        // Errors within 1 % of each other are level: the step time decides.
        assert_eq!(standing(&at(0.1, 0.02015), &p), "tied");
        // So are step times within what a run's times move (10 %), but not past it.
        assert_eq!(standing(&at(0.102, 0.02), &p), "tied");
        assert_eq!(standing(&at(0.098, 0.02015), &p), "tied");
        assert_eq!(standing(&at(0.115, 0.02), &p), "behind");
        // Times within it, errors apart: the error decides.
        assert_eq!(standing(&at(0.095, 0.03), &p), "behind");
        assert_eq!(standing(&at(0.105, 0.01), &p), "ahead");
        assert_eq!(standing(&at(0.2, 0.01985), &p), "behind");
        assert_eq!(standing(&at(0.08, 0.02015), &p), "ahead");
        assert_eq!(standing(&at(0.08, 0.02), &p), "ahead");
        assert_eq!(standing(&at(0.1, 0.01), &p), "ahead");
        assert_eq!(standing(&at(0.2, 0.03), &p), "behind");
        assert_eq!(standing(&at(0.1, 0.03), &p), "behind");
        assert_eq!(
            standing(&at(0.05, 0.03), &p),
            "frontier: faster, less accurate"
        );
        assert_eq!(
            standing(&at(0.2, 0.01), &p),
            "frontier: more accurate, slower"
        );
        let failed = MethodReport {
            failure: Some("frame 3".into()),
            ..at(0.05, 0.01)
        };
        assert_eq!(standing(&failed, &p), "—");
    }

    /// `suite.json` holds `null`, not 0, for what a full-space row has none of, as
    /// `report.json` does; a reduced row keeps its figures.
    #[test]
    fn suite_json_holds_null_for_what_full_space_has_none_of() {
        let out = std::env::temp_dir().join(format!("suite-json-{}", std::process::id()));
        let method = |method, subspace_error| MethodReport {
            method,
            subspace_error,
            ..Default::default()
        };
        let row = SuiteRow {
            scene: "s".into(),
            vertices: 10,
            tets: 20,
            pipeline_seconds: 1.0,
            methods: vec![method(Method::Full, 0.0), method(Method::Pca, 0.25)],
            trajectories: Vec::new(),
            trajectories_seconds: None,
            trajectories_failure: None,
            failure: None,
        };
        write(&out, &[row]).unwrap();
        let text = std::fs::read_to_string(out.join("suite.json")).unwrap();
        let _ = std::fs::remove_dir_all(&out);
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        let methods = &json[0]["methods"];
        for key in crate::run::NOT_OF_FULL_SPACE {
            assert!(methods[0][key].is_null(), "{key}: {text}");
            assert!(methods[1][key].is_number(), "{key}: {text}");
        }
        assert_eq!(methods[1]["subspace_error"], 0.25);
    }

    /// A mesh whose pipeline stopped is said below the table, which stays one table (a note
    /// between its rows ended it there); a speed-up below 10× keeps a decimal.
    #[test]
    fn a_stopped_mesh_is_said_below_the_table() {
        let row = |scene: &str, failure: Option<&str>, speedup| SuiteRow {
            scene: scene.into(),
            vertices: 10,
            tets: 20,
            pipeline_seconds: 1.0,
            methods: vec![MethodReport {
                method: Method::Pca,
                mean_rel_error: 0.02,
                speedup,
                ..Default::default()
            }],
            trajectories: Vec::new(),
            trajectories_seconds: None,
            trajectories_failure: None,
            failure: failure.map(String::from),
        };
        let md = markdown(&[
            row("a", Some("stage pca: empty"), None),
            row("b", None, Some(0.42)),
            row("c", None, Some(123.4)),
        ]);
        let table: Vec<&str> = md.lines().take_while(|l| l.starts_with('|')).collect();
        assert_eq!(table.len(), 5, "{md}");
        assert!(
            table[3].starts_with("| b |") && table[3].contains("| 0.4× |"),
            "{md}"
        );
        assert!(table[4].contains("| 123× |"), "{md}");
        assert!(md.contains("\na: stopped: stage pca: empty\n"), "{md}");
    }

    /// The second table: a mean over every trajectory, the worst with its index, a gap where
    /// a trajectory stopped (no mean), and why it stopped; none with one trajectory.
    #[test]
    fn the_spread_table_shows_means_worsts_and_gaps() {
        let at = |method: Method, error: f64| MethodReport {
            method,
            mean_rel_error: error,
            speedup: Some(100.0),
            ..Default::default()
        };
        let row = |scene: &str, runs: &[Vec<MethodReport>], failure: Option<&str>| SuiteRow {
            scene: scene.into(),
            vertices: 10,
            tets: 20,
            pipeline_seconds: 1.0,
            methods: runs[0].clone(),
            trajectories: crate::trajectories::spreads(runs),
            trajectories_seconds: Some(2.0),
            trajectories_failure: failure.map(String::from),
            failure: None,
        };
        let whole = row(
            "a",
            &[
                vec![at(Method::Pca, 0.02), at(Method::NeuralCubature, 0.03)],
                vec![at(Method::Pca, 0.04), at(Method::NeuralCubature, 0.09)],
            ],
            None,
        );
        let cut = row(
            "b",
            &[vec![at(Method::Pca, 0.05)], Vec::new()],
            Some("test trajectory 1: diverged"),
        );
        let table = spread_markdown(&[whole.clone(), cut]);
        assert!(table.contains("On test trajectories 0..2"), "{table}");
        assert!(
            table.contains("`<scene>/trajectory-<i>/report.md`"),
            "{table}"
        );
        assert!(
            table.contains("| a | 2 | 3.0 % (4.0 % on 1) | — | — | 6.0 % (9.0 % on 1) |"),
            "{table}"
        );
        assert!(
            table.contains("| b | 2 | — (5.0 % on 0) | — | — | — |"),
            "{table}"
        );
        assert!(
            table.contains("b: stopped at test trajectory 1: diverged"),
            "{table}"
        );
        let single = SuiteRow {
            trajectories: Vec::new(),
            trajectories_seconds: None,
            ..whole
        };
        assert_eq!(spread_markdown(&[single]), "");
    }

    /// A folder's meshes in every readable format, a TetGen pair once; surface meshes and
    /// other files left out; names that keep `beam.mesh` and `beam.msh` apart.
    #[test]
    fn a_folder_lists_every_readable_mesh_once() {
        let dir = std::env::temp_dir().join(format!("suite-meshes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let medit = "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n\
                     0 1 0 0\n0 0 1 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n";
        let node = "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n";
        let files = [
            ("beam.mesh", medit),
            ("beam.msh", "not read here"),
            ("part.1.node", node),
            ("part.1.ele", "1 4 0\n1 1 2 3 4\n"),
            ("bunny.obj", "v 0 0 0\n"),
            ("notes.txt", "x"),
        ];
        for (name, text) in files {
            std::fs::write(dir.join(name), text).unwrap();
        }
        let found = meshes(&dir, None).unwrap();
        let names: Vec<String> = found
            .iter()
            .map(|p| SuiteMesh::File(p.clone()).name())
            .collect();
        assert_eq!(names, ["beam", "beam-msh", "part.1-ele"]);
        // Counting vertices reads them (the TetGen pair whole): a file that cannot be read is
        // kept for its row to say why, the others left out above the limit.
        assert_eq!(meshes(&dir, Some(4)).unwrap(), found);
        assert_eq!(meshes(&dir, Some(3)).unwrap(), [dir.join("beam.msh")]);
        std::fs::remove_file(dir.join("beam.msh")).unwrap();
        assert_eq!(meshes(&dir, Some(4)).unwrap().len(), 2);
        assert!(meshes(&dir, Some(3)).is_err());
        // The scene the suite writes names the mesh by its absolute path (to read it from the
        // results' folder), and parses.
        let mesh = SuiteMesh::File(PathBuf::from("beam.mesh"));
        let (m, _) = fem_core::io::read_mesh(&dir.join("beam.mesh")).unwrap();
        let text = minimal_scene_text(&m, &mesh, MATERIALS[0], 1e5, Axis::Y, 1.0).unwrap();
        let absolute = std::path::absolute("beam.mesh").unwrap();
        assert!(
            text.contains(&format!("path = {:?}", absolute.display().to_string())),
            "{text}"
        );
        let mesh = SuiteMesh::File(dir.join("beam.mesh"));
        let text = minimal_scene_text(&m, &mesh, MATERIALS[0], 1e5, Axis::Y, 1.0).unwrap();
        let scene = parse_minimal_scene(&text, &mesh).unwrap();
        assert_eq!(scene.name, "beam-stable-neo-hookean");
        // A folder of meshes in millimetres: the scene scales the mesh, its pin plane the same
        // bottom layer of vertices, now in metres.
        let mm = minimal_scene_text(&m, &mesh, MATERIALS[0], 1e5, Axis::Y, 1e-3).unwrap();
        assert!(mm.contains("\nscale = 0.001\n"), "{mm}");
        let pinned = |text: &str| {
            let scene = parse_minimal_scene(text, &mesh).unwrap();
            let model = scene.build_model().unwrap().model;
            (model.pinned.len(), model.mesh.bounding_box().1[1])
        };
        let ((metres, top), (millimetres, top_mm)) = (pinned(&text), pinned(&mm));
        assert_eq!(metres, millimetres);
        assert!((top_mm - 1e-3 * top).abs() <= 1e-12 * top, "{top} {top_mm}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The long run's meshes are the sizes their documentation gives, and their minimal scenes
    /// parse with the mesh generated in code, pinned at the bottom 2 % of the height.
    #[test]
    fn generated_meshes_have_their_sizes_and_minimal_scenes() {
        let sizes: Vec<(usize, usize)> = generated()
            .iter()
            .map(|g| {
                let m = g.read().unwrap();
                (m.num_vertices(), m.num_tets())
            })
            .collect();
        assert_eq!(sizes, [(3321, 15360), (11475, 58800), (6532, 30078)]);
        let bar = &generated()[1];
        let scene =
            minimal_scene_of(&bar.read().unwrap(), bar, MATERIALS[1], 1e5, Axis::Y, 1.0).unwrap();
        assert_eq!(scene.name, "bar-60k-neo-hookean");
        let model = scene.build_model().unwrap().model;
        assert_eq!(model.mesh.num_tets(), 58800);
        // The bottom layer of vertices (y = 0; 2 % of 0.28 m is above no other layer).
        assert_eq!(model.pinned.len(), 51 * 15);
        // The figure stands on the bottom layer of its trunk's disc.
        let figure = &generated()[2];
        let scene = minimal_scene_of(
            &figure.read().unwrap(),
            figure,
            MATERIALS[3],
            1e5,
            Axis::Y,
            1.0,
        )
        .unwrap();
        assert_eq!(scene.name, "figure-30k-stvk");
        let model = scene.build_model().unwrap().model;
        let base = model.mesh.vertices.iter().filter(|v| v.y == 0.0).count();
        assert_eq!(model.pinned.len(), base);
    }

    /// A mesh made with z up (`suite --up z`) is pinned at its lowest 2 % along z, with gravity
    /// along −z.
    #[test]
    fn a_folder_of_z_up_meshes_stands_on_z() {
        let bar = SuiteMesh::Box {
            name: "post".into(),
            kind: GeneratedShape::Box,
            size: [0.1, 0.1, 0.5],
            cells: [2, 2, 10],
        };
        let scene =
            minimal_scene_of(&bar.read().unwrap(), &bar, MATERIALS[0], 1e5, Axis::Z, 1.0).unwrap();
        assert_eq!(scene.gravity.acceleration, [0.0, 0.0, -9.81]);
        let model = scene.build_model().unwrap().model;
        let base = model.mesh.vertices.iter().filter(|v| v.z == 0.0).count();
        assert_eq!(base, 9);
        assert_eq!(model.pinned.len(), base);
    }
}
