//! The stage cache against every scene field, both ways: a field a stage reads must change
//! that stage's key and its downstream stages' (or a changed scene would be served stale
//! artifacts), and a field it does not read must leave its artifact in use (or every edit would
//! recompute everything). A shared cache first holds every artifact of a base scene; each variant
//! edits one field, runs every stage on that cache and must recompute exactly the stages listed
//! for the field and load the others. The loaded ones must equal what the variant computes from
//! scratch in an empty cache: an unchanged key then provably stands for an unchanged artifact.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

mod common;
use common::scratch;

use fem_core::TetMesh;
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;
use pipeline::stage::Stage;

/// The base scene: a 5-cell beam, stages small enough to compute each a few dozen times.
const BASE: &str = r#"name = "keys"

[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [5, 1, 1] }

[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
density = 1000.0

[[pin]]
plane = { axis = "x", side = "min", tolerance = 1.0e-6 }

[gravity]
acceleration = [0.0, -9.81, 0.0]

[time]
step = 0.02
frames = 10

[solver]
tolerance = 1.0e-8

[training]
schedules = 3
frames_per_schedule = 6

[test]
frames_per_schedule = 8

[pca]
dimension = 5

[autoencoder]
latent_dim = 2
hidden = [8, 8]
epochs = 40
batch_size = 8

[cubature]
tolerance = 0.1
"#;

const SNAPSHOTS: Stage = Stage::Snapshots;
const PCA: Stage = Stage::Pca;
const TRAIN: Stage = Stage::Train;
const COMPLEMENT: Stage = Stage::Complement;
const CUBATURE: Stage = Stage::Cubature;
const NEURAL: Stage = Stage::CubatureNeural;
const REFERENCE: Stage = Stage::Reference;
const COVERAGE: Stage = Stage::Coverage;

/// Every stage with an artifact.
const ALL: &[Stage] = &[
    SNAPSHOTS, PCA, TRAIN, COMPLEMENT, CUBATURE, NEURAL, REFERENCE, COVERAGE,
];
/// What the training schedules feed: everything but the held-out reference.
const TRAINING: &[Stage] = &[
    SNAPSHOTS, PCA, TRAIN, COMPLEMENT, CUBATURE, NEURAL, COVERAGE,
];
/// The reference, and the rules whose held-out error is measured on it.
const TEST: &[Stage] = &[REFERENCE, CUBATURE, NEURAL];
const BASIS: &[Stage] = &[PCA, TRAIN, COMPLEMENT, CUBATURE, NEURAL, COVERAGE];
const NETWORK: &[Stage] = &[TRAIN, COMPLEMENT, NEURAL];
const RULES: &[Stage] = &[CUBATURE, NEURAL];
const NONE: &[Stage] = &[];

/// One edit of the base scene: `from` (present once) becomes `to`.
struct Variant {
    field: &'static str,
    from: &'static str,
    to: &'static str,
    /// The stages that must recompute.
    recomputes: &'static [Stage],
}

const fn v(
    field: &'static str,
    from: &'static str,
    to: &'static str,
    recomputes: &'static [Stage],
) -> Variant {
    Variant {
        field,
        from,
        to,
        recomputes,
    }
}

/// An edit that adds `line` to section `[header]`, right after its header.
macro_rules! add {
    ($header:literal, $line:literal) => {
        concat!("[", $header, "]\n", $line, "\n")
    };
}

/// Every field of every section, with the stages that recompute when it changes. No stage
/// reads the name, the scene's own trajectory (`[time] frames`, `[[force]]`), the reduced solver
/// but in `cubature-neural` (which steps `neural-cubature` on training schedules), nor how pins and meshes are given as long as they select the same vertices
/// and hold the same mesh. Four fields are keyed although the stage does not read them here
/// (marked below): those edits recompute for nothing, which is safe.
fn variants() -> Vec<Variant> {
    vec![
        v("name", "name = \"keys\"", "name = \"other\"", NONE),
        // [mesh]: the content is keyed, not how it is given.
        v(
            "mesh.generate.cells",
            "cells = [5, 1, 1]",
            "cells = [6, 1, 1]",
            ALL,
        ),
        v(
            "mesh.generate.origin",
            "cells = [5, 1, 1] }",
            "cells = [5, 1, 1], origin = [0.0, 0.5, 0.0] }",
            ALL,
        ),
        v(
            "mesh.generate.size",
            "size = [1.0, 0.2, 0.2]",
            "size = [1.0, 0.2, 0.25]",
            ALL,
        ),
        v(
            "mesh.scale",
            "cells = [5, 1, 1] }",
            "cells = [5, 1, 1] }\nscale = 0.9",
            ALL,
        ),
        // [material]
        v("material.youngs_modulus", "1.0e5", "2.0e5", ALL),
        v(
            "material.poisson_ratio",
            "poisson_ratio = 0.4",
            "poisson_ratio = 0.3",
            ALL,
        ),
        v("material.density", "1000.0", "1200.0", ALL),
        v(
            "material.model",
            add!("material", "model = \"neo-hookean\""),
            "",
            ALL,
        ),
        v(
            "material.mass",
            add!("material", "mass = \"consistent\""),
            "",
            ALL,
        ),
        // [[pin]]: the pinned vertices are keyed, not the selector that picks them.
        v("pin.plane.side", "side = \"min\"", "side = \"max\"", ALL),
        v(
            "pin.plane.tolerance",
            "tolerance = 1.0e-6 }",
            "tolerance = 1.0e-3 }",
            NONE,
        ),
        v(
            "gravity.acceleration",
            "[0.0, -9.81, 0.0]",
            "[0.0, -4.0, 0.0]",
            ALL,
        ),
        // [time]
        v("time.step", "step = 0.02", "step = 0.025", ALL),
        v("time.frames", "frames = 10", "frames = 30", NONE),
        v(
            "time.quasi_static",
            add!("time", "quasi_static = true"),
            "",
            ALL,
        ),
        // [solver]: the full-space solver makes the snapshots and the reference.
        v(
            "solver.method",
            add!("solver", "method = \"newton\""),
            "",
            ALL,
        ),
        // The training data is solved to 10⁻² whatever a tighter solver tolerance says.
        v(
            "solver.tolerance",
            "tolerance = 1.0e-8",
            "tolerance = 1.0e-9",
            TEST,
        ),
        v(
            "solver.tolerance (looser than the training data's)",
            "tolerance = 1.0e-8",
            "tolerance = 5.0e-2",
            ALL,
        ),
        v(
            "solver.max_iterations",
            add!("solver", "max_iterations = 60"),
            "",
            ALL,
        ),
        // Unread by Newton, the base scene's solver: keyed all the same.
        v(
            "solver.lbfgs_memory",
            add!("solver", "lbfgs_memory = 5"),
            "",
            ALL,
        ),
        v(
            "solver.preconditioner",
            add!("solver", "preconditioner = \"rest\""),
            "",
            ALL,
        ),
        // [reduced]: read when a reduced method runs, and by stage `cubature-neural`, which runs
        // `neural-cubature` on training schedules to choose its rule.
        v(
            "reduced.method",
            "[training]",
            "[reduced]\nmethod = \"newton\"\n\n[training]",
            &[NEURAL],
        ),
        v(
            "reduced.tolerance",
            "[training]",
            "[reduced]\ntolerance = 1.0e-5\n\n[training]",
            &[NEURAL],
        ),
        v(
            "reduced.preconditioner",
            "[training]",
            "[reduced]\npreconditioner = \"rest\"\n\n[training]",
            &[NEURAL],
        ),
        // What `auto` means, written out.
        v(
            "reduced.preconditioner",
            "[training]",
            "[reduced]\npreconditioner = \"current-state\"\n\n[training]",
            NONE,
        ),
        v(
            "reduced.onset_directions",
            "[training]",
            "[reduced]\nonset_directions = 3\n\n[training]",
            &[NEURAL],
        ),
        // The default under gravity, written out.
        v(
            "reduced.onset_directions",
            "[training]",
            "[reduced]\nonset_directions = 2\n\n[training]",
            NONE,
        ),
        v(
            "reduced.complement_directions",
            "[training]",
            "[reduced]\ncomplement_directions = 2\n\n[training]",
            &[Stage::CubatureNeural],
        ),
        v(
            "reduced.spring_compliance",
            "[training]",
            "[reduced]\nspring_compliance = false\n\n[training]",
            &[NEURAL],
        ),
        // [[force]]: the scene's own loads; stages use the generated schedules instead.
        v(
            "force",
            "[training]",
            "[[force]]\nkind = \"point\"\nselect = { plane = { axis = \"x\", side = \"max\" } }\n\
             keyframes = [[0.0, 0.0, -1.0, 0.0]]\n\n[training]",
            NONE,
        ),
        // [training]
        v(
            "training.schedules",
            "schedules = 3",
            "schedules = 4",
            TRAINING,
        ),
        v(
            "training.frames_per_schedule",
            "frames_per_schedule = 6",
            "frames_per_schedule = 7",
            TRAINING,
        ),
        v("training.seed", add!("training", "seed = 7"), "", TRAINING),
        v(
            "training.tolerance",
            add!("training", "tolerance = 1.0e-5"),
            "",
            TRAINING,
        ),
        // The default, written out: the looser of 10⁻² and `[solver] tolerance` (10⁻⁸ here).
        v(
            "training.tolerance (default)",
            add!("training", "tolerance = 1.0e-2"),
            "",
            NONE,
        ),
        v(
            "training.kinds",
            add!("training", "kinds = [\"drag\"]"),
            "",
            TRAINING,
        ),
        v(
            "training.offset",
            add!("training", "offset = [0.03, 0.12]"),
            "",
            TRAINING,
        ),
        v(
            "training.stiffness",
            add!("training", "stiffness = [0.4, 1.5]"),
            "",
            TRAINING,
        ),
        v(
            "training.patch_radius",
            add!("training", "patch_radius = 0.1"),
            "",
            TRAINING,
        ),
        v(
            "training.gravity_scale",
            add!("training", "gravity_scale = 0.5"),
            "",
            TRAINING,
        ),
        // [test]
        v(
            "test.frames_per_schedule",
            "frames_per_schedule = 8",
            "frames_per_schedule = 9",
            TEST,
        ),
        v("test.seed", add!("test", "seed = 11"), "", TEST),
        v("test.kinds", add!("test", "kinds = [\"pull\"]"), "", TEST),
        v(
            "test.offset",
            add!("test", "offset = [0.03, 0.12]"),
            "",
            TEST,
        ),
        v(
            "test.stiffness",
            add!("test", "stiffness = [0.4, 1.5]"),
            "",
            TEST,
        ),
        v(
            "test.patch_radius",
            add!("test", "patch_radius = 0.1"),
            "",
            TEST,
        ),
        v(
            "test.gravity_scale",
            add!("test", "gravity_scale = 0.5"),
            "",
            TEST,
        ),
        // The number of test trajectories does not change trajectory 0, and is not keyed with
        // it (`run --trajectories` raises it): every stage loads, and the check below finds
        // each loaded artifact equal to what the scene computes from scratch.
        v("test.schedules", add!("test", "schedules = 2"), "", NONE),
        // [pca]
        v("pca.dimension", "dimension = 5", "dimension = 4", BASIS),
        // A bound that `dimension` makes moot: keyed all the same.
        v(
            "pca.max_dimension",
            add!("pca", "max_dimension = 50"),
            "",
            BASIS,
        ),
        v(
            "pca.gravity_directions",
            add!("pca", "gravity_directions = 1"),
            "",
            BASIS,
        ),
        v(
            "pca.patch_responses",
            add!("pca", "patch_responses = 4"),
            "",
            BASIS,
        ),
        // The default written out.
        v(
            "pca.patch_responses",
            add!("pca", "patch_responses = 48"),
            "",
            NONE,
        ),
        // [autoencoder]
        v(
            "autoencoder.latent_dim",
            "latent_dim = 2",
            "latent_dim = 3",
            NETWORK,
        ),
        v(
            "autoencoder.hidden",
            "hidden = [8, 8]",
            "hidden = [8, 6]",
            NETWORK,
        ),
        v("autoencoder.epochs", "epochs = 40", "epochs = 30", NETWORK),
        v(
            "autoencoder.batch_size",
            "batch_size = 8",
            "batch_size = 6",
            NETWORK,
        ),
        v(
            "autoencoder.activation",
            add!("autoencoder", "activation = \"tanh\""),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.learning_rate",
            add!("autoencoder", "learning_rate = 0.002"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.seed",
            add!("autoencoder", "seed = 3"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.skip",
            add!("autoencoder", "skip = false"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.beta1",
            add!("autoencoder", "beta1 = 0.8"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.beta2",
            add!("autoencoder", "beta2 = 0.99"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.epsilon",
            add!("autoencoder", "epsilon = 1.0e-6"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.validation_fraction",
            add!("autoencoder", "validation_fraction = 0.2"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.patience",
            add!("autoencoder", "patience = 5"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.restarts",
            add!("autoencoder", "restarts = 2"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.anchor_origin",
            add!("autoencoder", "anchor_origin = false"),
            "",
            NETWORK,
        ),
        v(
            "autoencoder.input_scaling",
            add!("autoencoder", "input_scaling = false"),
            "",
            NETWORK,
        ),
        // [cubature]
        v(
            "cubature.tolerance",
            "tolerance = 0.1\n",
            "tolerance = 0.05\n",
            RULES,
        ),
        v(
            "cubature.max_elements",
            add!("cubature", "max_elements = 6"),
            "",
            RULES,
        ),
        v(
            "cubature.candidates",
            add!("cubature", "candidates = 5"),
            "",
            RULES,
        ),
        v(
            "cubature.max_poses",
            add!("cubature", "max_poses = 10"),
            "",
            RULES,
        ),
        v("cubature.seed", add!("cubature", "seed = 4"), "", RULES),
        // A limit the fit never reaches here, keyed all the same.
        v(
            "cubature.memory_limit_mb",
            add!("cubature", "memory_limit_mb = 1000"),
            "",
            RULES,
        ),
        v(
            "cubature.neural_tolerance",
            add!("cubature", "neural_tolerance = 0.05"),
            "",
            &[NEURAL],
        ),
    ]
}

/// The base text with `variant`'s edit: `from` replaced by `to`, or for an `add!` edit (`to`
/// empty) its line inserted after its section header.
fn edited(variant: &Variant) -> String {
    let (from, to) = if variant.to.is_empty() {
        let header = variant.from.lines().next().unwrap_or_default();
        (format!("{header}\n"), variant.from.to_string())
    } else {
        (variant.from.to_string(), variant.to.to_string())
    };
    assert_eq!(
        BASE.matches(&from).count(),
        1,
        "{}: {from:?} must occur once",
        variant.field
    );
    BASE.replacen(&from, &to, 1)
}

fn no_progress(_: usize, _: usize) {}

/// What the stages computed, without their timings.
#[derive(Debug, PartialEq)]
struct Artifacts {
    snapshots: Vec<f64>,
    pca: pca::PcaFit,
    train: nn::Autoencoder,
    complement: (Vec<f64>, Vec<f64>),
    cubature: (cubature::CubatureRule, f64),
    neural: (
        cubature::CubatureRule,
        f64,
        Option<pipeline::pipeline::RuleValidation>,
    ),
    reference: Vec<Vec<f64>>,
    coverage: pipeline::coverage::Coverage,
}

/// Runs every stage of `scene` on `cache`; returns each stage's artifact path and whether it was
/// loaded, and the artifacts.
fn run_stages(scene: &Scene, cache: &Path) -> (Vec<(Stage, PathBuf, bool)>, Artifacts) {
    let mut p = Pipeline::new(scene, cache).unwrap_or_else(|e| panic!("{e:#}"));
    macro_rules! ok {
        ($stage:expr) => {
            std::sync::Arc::unwrap_or_clone(
                $stage.unwrap_or_else(|e| panic!("{}: {e:#}", scene.source)),
            )
        };
    }
    let a = Artifacts {
        snapshots: ok!(p.snapshots(&no_progress)).data,
        pca: ok!(p.pca(&no_progress)),
        train: ok!(p.train(&no_progress)).model,
        complement: {
            let c = ok!(p.complement(&no_progress));
            (c.directions, c.singular_values)
        },
        cubature: {
            let c = ok!(p.cubature(&no_progress));
            (c.rule, c.held_out_error)
        },
        neural: {
            let c = ok!(p.cubature_neural(&no_progress));
            (c.rule, c.held_out_error, c.validation)
        },
        reference: ok!(p.reference(0, &no_progress)).frames,
        coverage: ok!(p.coverage(&no_progress)),
    };
    let outcomes = p
        .outcomes
        .iter()
        .map(|o| (o.stage, o.path.clone(), o.cached))
        .collect();
    (outcomes, a)
}

/// Whether `a` and `b` hold the same artifact of `stage` (by value: `Debug` would also show
/// bookkeeping such as a network's in-process version number).
fn same_artifact(a: &Artifacts, b: &Artifacts, stage: Stage) -> bool {
    match stage {
        SNAPSHOTS => a.snapshots == b.snapshots,
        PCA => a.pca == b.pca,
        TRAIN => a.train == b.train,
        COMPLEMENT => a.complement == b.complement,
        CUBATURE => a.cubature == b.cubature,
        NEURAL => a.neural == b.neural,
        REFERENCE => a.reference == b.reference,
        COVERAGE => a.coverage == b.coverage,
        _ => unreachable!("{stage}"),
    }
}

fn check(variant: &Variant, scene: &Scene, shared: &Path, base: &[(Stage, PathBuf, bool)]) {
    let what = variant.field;
    let (outcomes, loaded) = run_stages(scene, shared);
    let mut seen = BTreeSet::new();
    let mut recomputed = BTreeSet::new();
    for (stage, path, cached) in &outcomes {
        let (_, base_path, _) = base
            .iter()
            .find(|(s, _, _)| s == stage)
            .unwrap_or_else(|| panic!("{what}: stage {stage} not in the base run"));
        seen.insert(*stage);
        // A new key is a new file, computed; the same key is the base's file, loaded.
        assert_eq!(
            path != base_path,
            !cached,
            "{what}: {stage} at {}",
            path.display()
        );
        if path != base_path {
            recomputed.insert(*stage);
        }
    }
    assert_eq!(seen, ALL.iter().copied().collect(), "{what}: stages run");
    let expected: BTreeSet<Stage> = variant.recomputes.iter().copied().collect();
    assert_eq!(recomputed, expected, "{what}: stages recomputed");
    if recomputed.len() == ALL.len() {
        return;
    }
    // The loaded artifacts are what this scene computes from scratch.
    let (_, fresh) = run_stages(scene, &scratch(&format!("fresh-{what}")));
    for stage in ALL.iter().filter(|s| !recomputed.contains(*s)) {
        assert!(
            same_artifact(&fresh, &loaded, *stage),
            "{what}: the cached {stage} is not what this scene computes"
        );
    }
}

/// Runs `variants` against a cache holding the base scene's artifacts.
fn check_all(name: &str, variants: &[Variant]) {
    let shared = scratch(name);
    let base_scene = Scene::from_str(BASE, Path::new("."), "base").unwrap();
    let (base, _) = run_stages(&base_scene, &shared);
    assert!(base.iter().all(|(_, _, cached)| !cached));
    for variant in variants {
        let scene = Scene::from_str(&edited(variant), Path::new("."), variant.field)
            .unwrap_or_else(|e| panic!("{e:#}"));
        check(variant, &scene, &shared, &base);
    }
}

/// Splits the variants into groups that run as separate tests (in parallel).
fn group(sections: &[&str]) -> Vec<Variant> {
    variants()
        .into_iter()
        .filter(|v| sections.iter().any(|s| v.field.starts_with(s)))
        .collect()
}

#[test]
fn physics_fields_key_every_stage() {
    check_all(
        "physics",
        &group(&[
            "name",
            "mesh.",
            "material.",
            "pin.",
            "gravity",
            "time.",
            "solver.",
            "force",
        ]),
    );
}

#[test]
fn schedule_fields_key_their_stages() {
    check_all("schedules", &group(&["training.", "test."]));
}

#[test]
fn reduction_fields_key_their_stages() {
    check_all(
        "reduction",
        &group(&["reduced.", "pca.", "autoencoder.", "cubature."]),
    );
}

/// Every field of the scene's sections is one of the variants: a new field must be given its
/// place (the serialised defaults list them all).
#[test]
fn every_scene_field_has_a_variant() {
    let scene = Scene::from_str(BASE, Path::new("."), "base").unwrap();
    let value = serde_json::to_value(&scene).unwrap();
    let names: BTreeSet<String> = variants().iter().map(|v| v.field.to_string()).collect();
    let mut missing = Vec::new();
    for (section, body) in value.as_object().unwrap() {
        let fields: Vec<String> = match body {
            serde_json::Value::Object(m) => m.keys().map(|k| format!("{section}.{k}")).collect(),
            _ => vec![section.clone()],
        };
        for f in fields {
            let covered = names
                .iter()
                .any(|n| *n == f || n.starts_with(&format!("{f}.")));
            if !covered {
                missing.push(f);
            }
        }
    }
    assert!(
        missing.is_empty(),
        "scene fields with no variant: {missing:?}"
    );
}

/// Schedules left at their default length start later to reach the end of a longer test, so
/// the test's length keys the snapshots then, and only then: a test shorter than the schedules
/// changes nothing in them.
#[test]
fn a_shorter_test_does_not_key_default_length_snapshots() {
    let dir = scratch("test-length");
    let scene = |test_frames: usize| {
        let text = BASE
            .replace(
                "schedules = 3\nframes_per_schedule = 6\n",
                "schedules = 3\n",
            )
            .replace(
                "frames_per_schedule = 8",
                &format!("frames_per_schedule = {test_frames}"),
            );
        let scene = Scene::from_str(&text, Path::new("."), "base").unwrap();
        assert_eq!(scene.training.frames_per_schedule, None);
        scene
    };
    let key = |test_frames: usize| {
        Pipeline::new(&scene(test_frames), &dir)
            .unwrap()
            .snapshots_key()
    };
    let default = scene(8).training().frames_per_schedule;
    assert_eq!(key(default / 2), key(default - 1));
    assert_eq!(key(default / 2), key(default));
    assert_ne!(key(default), key(default + 1));
    assert_ne!(key(default + 1), key(default + 2));
}

/// The same box given as a mesh file: a path is not content, so nothing recomputes; a file
/// with one vertex moved, or with the same vertices and one tet fewer, is other content, so
/// everything does.
#[test]
fn a_mesh_file_is_keyed_by_its_content_not_its_path() {
    let dir = scratch("mesh-file");
    let shared = dir.join("cache");
    let base_scene = Scene::from_str(BASE, Path::new("."), "base").unwrap();
    let (base, _) = run_stages(&base_scene, &shared);
    let mesh = base_scene.build_model().unwrap().model.mesh;
    write_medit(&dir.join("beam.mesh"), &mesh);
    let from_file = BASE.replacen(
        "generate = { kind = \"box\", size = [1.0, 0.2, 0.2], cells = [5, 1, 1] }",
        "path = \"beam.mesh\"",
        1,
    );
    let scene = Scene::from_str(&from_file, &dir, "mesh.path").unwrap();
    check(
        &v("mesh.path (same content)", "", "", NONE),
        &scene,
        &shared,
        &base,
    );
    let mut moved = mesh.clone();
    let last = moved.num_vertices() - 1;
    moved.vertices[last].y += 0.01;
    write_medit(&dir.join("beam.mesh"), &moved);
    check(
        &v("mesh.path (one vertex moved)", "", "", ALL),
        &scene,
        &shared,
        &base,
    );
    // The same vertices, one tet fewer (one whose vertices other tets keep).
    let mut fewer = mesh.clone();
    let uses = |v: usize, tets: &[[usize; 4]]| tets.iter().filter(|t| t.contains(&v)).count();
    let t = (0..fewer.num_tets())
        .find(|&t| fewer.tets[t].iter().all(|&v| uses(v, &fewer.tets) > 1))
        .expect("a tet whose vertices other tets share");
    fewer.tets.remove(t);
    assert_eq!(fewer.vertices, mesh.vertices);
    write_medit(&dir.join("beam.mesh"), &fewer);
    check(
        &v("mesh.path (one tet fewer)", "", "", ALL),
        &scene,
        &shared,
        &base,
    );
}

fn write_medit(path: &Path, mesh: &TetMesh) {
    let mut s = format!(
        "MeshVersionFormatted 2\nDimension 3\nVertices\n{}\n",
        mesh.num_vertices()
    );
    for v in &mesh.vertices {
        s += &format!("{} {} {} 0\n", v.x, v.y, v.z);
    }
    s += &format!("Tetrahedra\n{}\n", mesh.num_tets());
    for t in &mesh.tets {
        s += &format!("{} {} {} {} 1\n", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1);
    }
    std::fs::write(path, s + "End\n").unwrap();
}
