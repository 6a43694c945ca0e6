//! Scene validation: every bad key or value is a clear error naming the file and the field
//! (`material.poisson_ratio`, `pin[1].sphere`), and the problems of one scene are reported
//! together: the value checks when the scene is read, the checks that need the mesh (pins that
//! select nothing, pieces of the mesh nothing holds) when the model is built.

use std::io::Write;
use std::path::{Path, PathBuf};

mod common;
use common::scratch;

use fem_core::TetMesh;
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use pipeline::scene::Scene;

/// A small valid scene; each test edits one part of it.
const BASE: &str = r#"name = "beam"

[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [4, 1, 1] }

[material]
model = "stable-neo-hookean"
youngs_modulus = 1.0e5
poisson_ratio = 0.4
density = 1000.0

[[pin]]
plane = { axis = "x", side = "min", tolerance = 1.0e-6 }

[gravity]
acceleration = [0.0, -9.81, 0.0]

[time]
step = 0.01
frames = 10

[solver]
method = "newton"
tolerance = 1.0e-6

[[force]]
kind = "spring"
select = { sphere = { center = [1.0, 0.1, 0.1], radius = 0.15 } }
stiffness = 200.0
keyframes = [[0.0, 0.0, 0.0, 0.0], [0.3, 0.0, 0.1, 0.0]]
start = 0.0
end = 0.5
"#;

/// `BASE` with `from` (which must occur) replaced by `to`.
fn edit(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "BASE has no '{from}'");
    BASE.replacen(from, to, 1)
}

/// The error of reading `text` as `bad.toml`, failing the test if it is accepted.
fn read_error(text: &str) -> String {
    match Scene::from_str(text, Path::new("."), "bad.toml") {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => format!("{e:#}"),
    }
}

/// The error of building the model of the valid scene `text` read from `base`.
fn build_error(text: &str, base: &Path) -> String {
    let scene = Scene::from_str(text, base, "bad.toml")
        .unwrap_or_else(|e| panic!("the scene should read: {e:#}"));
    match scene.build_model() {
        Ok(_) => panic!("expected a model error for:\n{text}"),
        Err(e) => format!("{e:#}"),
    }
}

fn builds(text: &str, base: &Path) {
    let scene = Scene::from_str(text, base, "ok.toml").unwrap_or_else(|e| panic!("{e:#}"));
    scene.build_model().unwrap_or_else(|e| panic!("{e:#}"));
}

/// `err` names the file and each of `needles`.
fn assert_names(err: &str, needles: &[&str]) {
    assert!(err.contains("bad.toml"), "no file name in: {err}");
    for n in needles {
        assert!(err.contains(n), "'{n}' missing from: {err}");
    }
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

fn beam(cells: [usize; 3], origin: [f64; 3]) -> TetMesh {
    box_mesh(&BoxSpec {
        size: [1.0, 0.2, 0.2],
        cells,
        origin,
        ..Default::default()
    })
    .unwrap()
}

#[test]
fn the_base_scene_is_valid() {
    builds(BASE, Path::new("."));
}

/// The default PCA rule written out keys the stage as the default left out does.
#[test]
fn a_default_written_out_keys_as_left_out() {
    let scene = Scene::builtin();
    let mut written = scene.clone();
    written.pca.explained_energy = Some(pca::DEFAULT_EXPLAINED_ENERGY);
    let mut other = scene.clone();
    other.pca.explained_energy = Some(0.999);
    let key = |s: &Scene| {
        pipeline::pipeline::Pipeline::new(s, scratch("default-written-out"))
            .map(|p| p.pca_key())
            .unwrap()
    };
    assert_eq!(key(&scene), key(&written));
    assert_ne!(key(&scene), key(&other));
}

/// A scene changed in code is checked as a file's is, before a stage meets it (an empty list
/// of training kinds reached the snapshot generator as an index out of bounds).
#[test]
fn a_scene_changed_in_code_is_checked() {
    let mut scene = Scene::builtin();
    scene.training.kinds = Some(Vec::new());
    let Err(err) = pipeline::pipeline::Pipeline::new(&scene, scratch("changed-in-code")) else {
        panic!("an empty list of kinds is refused");
    };
    assert!(err.to_string().contains("training.kinds"), "{err}");
}

#[test]
fn unknown_keys_are_errors_naming_the_key_and_its_section() {
    let cases = [
        (
            edit("poisson_ratio = 0.4", "poisson_ratio = 0.4\npoison = 1"),
            "`material.poison`",
        ),
        (edit("[time]", "[tiem]"), "`tiem`"),
        (edit("frames = 10", "frames = 10\nfps = 30"), "`time.fps`"),
        (edit("[[pin]]", "[[pins]]"), "`pins`"),
        (
            edit(
                "tolerance = 1.0e-6 }",
                "tolerance = 1.0e-6, sid = \"max\" }",
            ),
            "`pin[0].plane.sid`",
        ),
        (
            edit("stiffness = 200.0", "stiffness = 200.0\nstifness = 1.0"),
            "`force[0].stifness`",
        ),
        (format!("nmae = \"x\"\n{BASE}"), "`nmae`"),
        (
            edit("cells = [4, 1, 1] }", "cells = [4, 1, 1], cell = 3 }"),
            "`mesh.generate.cell`",
        ),
    ];
    for (text, field) in cases {
        let err = read_error(&text);
        assert_names(&err, &[field, "unknown field"]);
    }
}

/// Common mistakes get what to write instead: a key or a name a letter or two off (and only
/// then), a single `[pin]` for the list `[[pin]]`, a Unicode minus, a decimal comma, and
/// arithmetic in a value, operators in a chain too.
#[test]
fn common_mistakes_say_what_to_write() {
    let cases = [
        (
            edit("youngs_modulus", "youngs_modulos"),
            "did you mean `youngs_modulus`?",
        ),
        (edit("frames = 10", "frams = 10"), "did you mean `frames`?"),
        (
            edit("\"stable-neo-hookean\"", "\"stable-neohookean\""),
            "did you mean `stable-neo-hookean`?",
        ),
        (
            edit("[[pin]]", "[pin]"),
            "write `[[pin]]`, with doubled brackets",
        ),
        (
            edit("[[force]]", "[force]"),
            "write `[[force]]`, with doubled brackets",
        ),
        (
            edit("step = 0.01", "step = 1/100"),
            "write the number, 0.01 for `1/100`",
        ),
        (
            edit("stiffness = 200.0", "stiffness = 2 * 100 # N/m"),
            "write the number, 200 for `2 * 100`",
        ),
        (
            edit("[0.0, -9.81, 0.0]", "[0.0, -9.81/6, 0.0]"),
            "write the number, -1.635 for `-9.81/6`",
        ),
        (
            edit("[0.0, -9.81, 0.0]", "[0.0, 0.0, -9.81 / 6]"),
            "write the number, -1.635 for `-9.81 / 6`",
        ),
        (
            edit("step = 0.01", "step = 1/50/2"),
            "write the number, 0.01 for `1/50/2`",
        ),
        (
            edit("frames = 10", "frames = 10/3"),
            "TOML does no arithmetic, and `time.frames` takes a whole number: `10/3` is \
             3.3333333333333335; write a whole number such as 3",
        ),
        (
            edit("frames = 10", "frames = 100/4"),
            "write the number, 25 for `100/4`",
        ),
        (
            edit("stiffness = 200.0", "stiffness = 4 * 100 / 2"),
            "write the number, 200 for `4 * 100 / 2`",
        ),
        (
            edit("[0.0, -9.81, 0.0]", "[0.0, \u{2212}9.81, 0.0]"),
            "write `-`, the ASCII minus, where `\u{2212}` (U+2212) stands",
        ),
        (
            edit("poisson_ratio = 0.4", "poisson_ratio = 0,4"),
            "write `0.4`: TOML's decimal point is a dot",
        ),
        (
            edit("youngs_modulus = 1.0e5", "youngs_modulus = 1,0e5"),
            "write `1.0e5`: TOML's decimal point is a dot",
        ),
        // In a list, decimal commas make more values than it takes (it was cut to three).
        (
            edit("[0.0, -9.81, 0.0]", "[0,0, -9,81, 0,0]"),
            "`gravity.acceleration`: TOML parse error",
        ),
        (
            edit("[0.0, -9.81, 0.0]", "[0,0, -9,81, 0,0]"),
            "invalid length 6, expected a list of 3 values\ndecimal commas? TOML's decimal point \
             is a dot, and a comma separates a list's values: write `0.0`, not `0,0`",
        ),
        (
            edit("[0.0, -9.81, 0.0]", "[0.0, -9.81, 0.0, 1.0]"),
            "invalid length 4, expected a list of 3 values",
        ),
        (
            edit("frames = 10", "frames = 1,000"),
            "write `1.000`: TOML's decimal point is a dot, never a comma, or `1000` if the comma \
             separates thousands",
        ),
    ];
    for (text, hint) in cases {
        assert_names(&read_error(&text), &[hint]);
    }
    // Only a list longer than it takes is hinted at, and only the list the error is of; a
    // string of other letters in it is read, not cut in the middle of a letter.
    for (from, to, length) in [
        ("cells = [4, 1, 1]", "cells = [6,1,1,1]", "invalid length 4"),
        ("size = [1.0, 0.2, 0.2]", "size = [1,2]", "invalid length 2"),
        (
            "acceleration = [0.0, -9.81, 0.0]",
            "acceleration = [0.0, -9.81, 0.0, \"é1,5\"]",
            "invalid",
        ),
        (
            "size = [1.0, 0.2, 0.2], cells = [4, 1, 1]",
            "size = [1,0, 0.2, 0.2], cells = [4, 1, 1, 1]",
            "invalid length 4",
        ),
    ] {
        let err = read_error(&edit(from, to));
        assert!(
            err.contains(length) && !err.contains("decimal commas"),
            "{err}"
        );
    }
    // An exponent is no thousands.
    let err = read_error(&edit("youngs_modulus = 1.0e5", "youngs_modulus = 1,0e5"));
    assert!(!err.contains("thousands"), "{err}");
    // A dash inside a quoted name is text, not a minus to mend.
    let err = read_error(&edit("name = \"beam\"", "name = \"beam \u{2013} two\" 2"));
    assert!(!err.contains("ASCII minus"), "{err}");
    // Swapped letters and another case are slips too.
    assert_names(
        &read_error(&edit("method = \"newton\"", "method = \"NEWTNO\"")),
        &["did you mean `newton`?"],
    );
    // A key far from every known one is not guessed at, nor one that is another word.
    for (from, to, field) in [
        ("frames = 10", "duration = 10", "`time.duration`"),
        ("frames = 10", "keyframes = 10", "`time.keyframes`"),
    ] {
        let err = read_error(&edit(from, to));
        assert_names(&err, &[field, "unknown field"]);
        assert!(!err.contains("did you mean"), "{err}");
    }
    // A table where a list is meant inside a pin is not told to be a list of tables.
    let err = read_error(&edit(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        "indices = { a = 1 }",
    ));
    assert!(!err.contains("doubled brackets"), "{err}");
}

/// A scene with several typos hears of each at once, inline tables' keys among them, with the
/// line of each and what to write; the reading stops at the first error of another kind, and a
/// field missing because a typo was set aside is not said.
#[test]
fn every_typo_is_said_at_once() {
    let text = edit("youngs_modulus", "youngs_modulos")
        .replacen("frames = 10", "frams = 10", 1)
        .replacen("radius = 0.15", "radus = 0.15", 1)
        .replacen("tolerance = 1.0e-6 }", "tolerence = 1.0e-6 }", 1);
    let err = read_error(&text);
    assert_names(
        &err,
        &[
            "`material.youngs_modulos`",
            "did you mean `youngs_modulus`?",
            "`pin[0].plane.tolerence`",
            "did you mean `tolerance`?",
            "`time.frams`",
            "did you mean `frames`?",
            "`force[0].select.sphere.radus`",
            "did you mean `radius`?",
        ],
    );
    // In the order of the file, each with its line.
    let at = |needle: &str| {
        err.find(needle)
            .unwrap_or_else(|| panic!("{needle}: {err}"))
    };
    assert!(
        at("line 8,") < at("line 13,")
            && at("line 13,") < at("line 20,")
            && at("line 20,") < at("line 28,"),
        "{err}"
    );
    assert!(!err.contains("missing field"), "{err}");
    // A wrong type met after a typo is said too, and ends the reading.
    let err = read_error(&edit("radius = 0.15", "radus = 0.15").replacen(
        "stiffness = 200.0",
        "stiffness = \"x\"",
        1,
    ));
    assert_names(
        &err,
        &["`force[0].select.sphere.radus`", "`force[0].stiffness`"],
    );
    // Past eight, the list says there may be more.
    let many: String = (0..9).map(|i| format!("unrelated_{i} = 1\n")).collect();
    let err = read_error(&edit("frames = 10\n", &format!("frames = 10\n{many}")));
    assert_names(
        &err,
        &[
            "`time.unrelated_7`",
            "and more: the reading stops at 8 unknown keys",
        ],
    );
    assert!(!err.contains("unrelated_8"), "{err}");
    // The first eight in the file's order, though the reading meets `[time]` before a
    // `[training]` written at the top.
    let err = read_error(
        &edit("frames = 10\n", &format!("frames = 10\n{many}"))
            .replace("[material]", "[training]\nschedulez = 3\n\n[material]"),
    );
    assert_names(
        &err,
        &["`training.schedulez`", "`time.unrelated_6`", "and more"],
    );
    assert!(!err.contains("unrelated_7"), "{err}");
    // A key read as the one it was a slip for, where that one is given too, is not the user's
    // duplicate.
    let err = read_error(&edit("frames = 10", "frames = 10\nframs = 20"));
    assert_names(&err, &["`time.frams`", "did you mean `frames`?"]);
    assert!(!err.contains("duplicate"), "{err}");
}

#[test]
fn wrong_types_are_errors_naming_the_field_and_line() {
    let cases = [
        (
            edit("poisson_ratio = 0.4", "poisson_ratio = \"abc\""),
            "`material.poisson_ratio`",
            "line 9",
        ),
        (
            edit("frames = 10", "frames = -3"),
            "`time.frames`",
            "line 20",
        ),
        (
            edit("frames = 10", "frames = 1.5"),
            "`time.frames`",
            "line 20",
        ),
        (
            edit("step = 0.01", "step = \"0.01\""),
            "`time.step`",
            "line 19",
        ),
        (
            edit("[0.0, -9.81, 0.0]", "[0.0, -9.81]"),
            "`gravity.acceleration`",
            "line 16",
        ),
        (
            edit("\"stable-neo-hookean\"", "\"rubber\""),
            "`material.model`",
            "line 7",
        ),
        (
            edit("axis = \"x\"", "axis = \"w\""),
            "`pin[0].plane.axis`",
            "line 13",
        ),
        (
            edit("radius = 0.15", "radius = \"big\""),
            "`force[0].select.sphere.radius`",
            "line 28",
        ),
        (edit("name = \"beam\"", "name = 5"), "`name`", "line 1"),
        (
            format!(
                "pin = 3\n{}",
                edit(
                    "[[pin]]\nplane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }\n",
                    ""
                )
            ),
            "`pin`",
            "line 1",
        ),
    ];
    for (text, field, line) in cases {
        let err = read_error(&text);
        assert_names(&err, &[field, line]);
    }
}

#[test]
fn out_of_range_values_are_reported_together() {
    let text = BASE
        .replace("youngs_modulus = 1.0e5", "youngs_modulus = -1.0")
        .replace("poisson_ratio = 0.4", "poisson_ratio = 0.5")
        .replace("density = 1000.0", "density = nan")
        .replace("step = 0.01", "step = 0.0")
        .replace("frames = 10", "frames = 0")
        .replace("tolerance = 1.0e-6\n", "tolerance = 2.0\n")
        .replace("[0.0, -9.81, 0.0]", "[0.0, nan, 0.0]")
        + "\n[reduced]\ntolerance = 0.0\n";
    let err = read_error(&text);
    assert_names(
        &err,
        &[
            "material.youngs_modulus",
            "material.poisson_ratio",
            "material.density",
            "time.step",
            "time.frames",
            "solver.tolerance",
            "reduced.tolerance",
            "gravity.acceleration",
        ],
    );
    assert_eq!(
        err.matches("\n  - ").count(),
        8,
        "one line per problem: {err}"
    );
    // A schedule's spring past 10⁴ times the patch's stiffness, which the runtime would refuse
    // only once the methods run.
    let err = read_error(&(BASE.to_string() + "\n[test]\nstiffness = [0.5, 1.0e5]\n"));
    assert_names(&err, &["test.stiffness", "at most 1e4 times"]);
    // Counts past what memory holds, refused when read (a tester's 10¹² schedules, 10¹¹ frames a
    // schedule, 10¹² L-BFGS pairs and 10⁸-wide layers aborted the process on an allocation).
    let text = edit("frames = 10", "frames = 100000000").replace(
        "tolerance = 1.0e-6\n",
        "tolerance = 1.0e-6\nlbfgs_memory = 1000000000000\n",
    ) + "\n[training]\nschedules = 1000000000000\nframes_per_schedule = 100000000000\n\
           \n[test]\nframes_per_schedule = 2000000\n\
           \n[autoencoder]\nhidden = [100000000, 100000000]\n";
    let err = read_error(&text);
    assert_names(
        &err,
        &[
            "time.frames",
            "solver.lbfgs_memory",
            "training.schedules",
            "training.frames_per_schedule",
            "test.frames_per_schedule",
            "autoencoder.hidden",
        ],
    );
    assert_eq!(
        err.matches("\n  - ").count(),
        6,
        "one line per problem: {err}"
    );
}

#[test]
fn poisson_ratio_time_step_and_material_bounds() {
    for bad in ["0.5", "0.7", "-0.1", "nan", "inf"] {
        let err = read_error(&edit(
            "poisson_ratio = 0.4",
            &format!("poisson_ratio = {bad}"),
        ));
        assert_names(&err, &["material.poisson_ratio", "[0, 0.5)"]);
    }
    for bad in ["0.0", "-0.01", "nan", "inf", "-inf"] {
        let err = read_error(&edit("step = 0.01", &format!("step = {bad}")));
        assert_names(&err, &["time.step", "positive"]);
    }
    for bad in ["0.0", "-1.0", "nan", "inf"] {
        let err = read_error(&edit(
            "youngs_modulus = 1.0e5",
            &format!("youngs_modulus = {bad}"),
        ));
        assert_names(&err, &["material.youngs_modulus"]);
        let err = read_error(&edit("density = 1000.0", &format!("density = {bad}")));
        assert_names(&err, &["material.density"]);
    }
}

#[test]
fn a_scene_without_support_needs_pins() {
    let pin = "[[pin]]\nplane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }\n";
    let unpinned = edit(pin, "");
    let err = read_error(&unpinned);
    assert_names(&err, &["`pin`", "pins no vertex", "falls freely"]);

    // Nothing pulls it down: a free-floating body is a valid scene.
    let floating = unpinned.replace("[0.0, -9.81, 0.0]", "[0.0, 0.0, 0.0]");
    builds(&floating, Path::new("."));
    // ... but a quasi-static one has no equilibrium.
    let err = read_error(&floating.replace("frames = 10", "frames = 10\nquasi_static = true"));
    assert_names(&err, &["`pin`", "quasi-static"]);
    // A spring acting for the whole run holds it, where the scene's own forces act
    // (`simulate`); the stages train and test with their own loads, and refuse it before
    // they simulate a free fall.
    let held = unpinned.replace("end = 0.5\n", "");
    builds(&held, Path::new("."));
    let scene = Scene::from_str(&held, Path::new("."), "bad.toml").unwrap();
    let mut p = pipeline::pipeline::Pipeline::new(&scene, scratch("held-by-a-spring")).unwrap();
    let err = format!("{:#}", p.snapshots(&|_, _| {}).unwrap_err());
    assert_names(
        &err,
        &[
            "only force[0]'s spring holds the body",
            "falls freely",
            "add a [[pin]]",
        ],
    );
    let err = format!("{:#}", p.test_model(0).unwrap_err());
    assert_names(&err, &["only force[0]'s spring holds the body"]);
    assert_eq!(p.model.forces.len(), 1);
    // Where neither the schedules nor the test fall under gravity, the body floats there.
    let weightless =
        format!("{held}\n[training]\ngravity_scale = 0.0\n\n[test]\ngravity_scale = 0.0\n");
    let scene = Scene::from_str(&weightless, Path::new("."), "bad.toml").unwrap();
    assert_eq!(scene.unsupported_in_stages(), None);
}

#[test]
fn pins_that_select_nothing_are_errors_reported_together() {
    let far = edit(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        "sphere = { center = [9.0, 9.0, 9.0], radius = 0.1 }\n\n[[pin]]\nindices = [3, 99999]",
    );
    let err = build_error(&far, Path::new("."));
    assert_names(
        &err,
        &["pin[0]", "selects no vertex", "pin[1].indices", "99999"],
    );
    // Where the body is, so that the user sees how far off the sphere was (the default bar).
    assert_names(&err, &["spans x 0 to 1.000, y 0 to 0.2000"]);

    let force = edit("center = [1.0, 0.1, 0.1]", "center = [5.0, 0.1, 0.1]");
    let err = build_error(&force, Path::new("."));
    assert_names(&err, &["force[0].select", "selects no vertex"]);
    // A spring the runtime would refuse is refused before any stage runs.
    let stiff = edit("stiffness = 200.0", "stiffness = 1.0e12");
    let err = build_error(&stiff, Path::new("."));
    assert_names(&err, &["force[0].stiffness", "give at most 1.039e11 N/m"]);
    builds(
        &edit("stiffness = 200.0", "stiffness = 1.0e11"),
        Path::new("."),
    );
    // The limit printed, written back, passes (printed rounded up, 1.010e11 for 1.00995e11,
    // it was refused with the same message).
    builds(
        &edit("stiffness = 200.0", "stiffness = 1.039e11"),
        Path::new("."),
    );
    // A point load the runtime would refuse, too (a tester's 1e300 N failed its first step with
    // a line-search message that named no field).
    let point = |load: &str| {
        edit("kind = \"spring\"", "kind = \"point\"")
            .replace("stiffness = 200.0\n", "")
            .replace("[0.3, 0.0, 0.1, 0.0]", &format!("[0.3, 0.0, {load}, 0.0]"))
    };
    let err = build_error(&point("1.0e300"), Path::new("."));
    assert_names(&err, &["force[0].keyframes", "give at most 1.080e11 N"]);
    builds(&point("1.0e11"), Path::new("."));
    // A force on pinned vertices only moves nothing.
    let on_pins = edit("center = [1.0, 0.1, 0.1]", "center = [0.0, 0.1, 0.1]");
    let err = build_error(&on_pins, Path::new("."));
    assert_names(&err, &["force[0].select", "only pinned vertices"]);
}

#[test]
fn selection_and_force_values_are_checked_when_read() {
    let plane = "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }";
    let cases = [
        (
            edit("tolerance = 1.0e-6 }", "tolerance = -1.0 }"),
            vec!["pin[0].plane.tolerance"],
        ),
        (
            edit(
                plane,
                "box = { min = [0.0, 0.0, 0.0], max = [-1.0, 1.0, 1.0] }",
            ),
            vec!["pin[0].box", "min ≤ max"],
        ),
        (
            edit(plane, "sphere = { center = [0.0, 0.0, 0.0], radius = 0.0 }"),
            vec!["pin[0].sphere", "positive radius"],
        ),
        (edit(plane, "indices = []"), vec!["pin[0].indices", "empty"]),
        (
            edit(plane, &format!("{plane}\nindices = [0]")),
            vec!["pin[0]", "exactly one", "2 given"],
        ),
        (
            edit("[[pin]]\n", "[[pin]]\n\n[[pin]]\n"),
            vec!["pin[0]", "0 given"],
        ),
        (
            edit("stiffness = 200.0\n", ""),
            vec!["force[0].stiffness", "needs a stiffness"],
        ),
        (
            edit("stiffness = 200.0", "stiffness = -5.0"),
            vec!["force[0].stiffness", "positive"],
        ),
        (
            edit("kind = \"spring\"", "kind = \"point\""),
            vec!["force[0].stiffness", "only springs"],
        ),
        (
            edit("[0.3, 0.0, 0.1, 0.0]", "[-0.3, 0.0, 0.1, 0.0]"),
            vec!["force[0].keyframes", "must not decrease"],
        ),
        (
            edit(
                "keyframes = [[0.0, 0.0, 0.0, 0.0], [0.3, 0.0, 0.1, 0.0]]",
                "keyframes = []",
            ),
            vec!["force[0].keyframes", "at least one"],
        ),
        (
            edit("end = 0.5", "end = -1.0"),
            vec!["force[0].end", "start < end"],
        ),
        (
            edit("end = 0.5", "end = 0.0"),
            vec!["force[0].end", "start < end, got 0 and 0"],
        ),
        (
            edit("radius = 0.15", "radius = -0.15"),
            vec!["force[0].select.sphere"],
        ),
    ];
    for (text, needles) in cases {
        let err = read_error(&text);
        assert_names(&err, &needles);
    }
    // All of a force's problems at once.
    let text = BASE
        .replace("stiffness = 200.0\n", "")
        .replace("end = 0.5", "end = -1.0")
        .replace("radius = 0.15", "radius = 0.0");
    let err = read_error(&text);
    assert_names(
        &err,
        &[
            "force[0].stiffness",
            "force[0].end",
            "force[0].select.sphere",
        ],
    );
}

#[test]
fn mesh_sections_are_checked_when_read() {
    let generate = "generate = { kind = \"box\", size = [1.0, 0.2, 0.2], cells = [4, 1, 1] }";
    let err = read_error(&edit(
        generate,
        &format!("{generate}\npath = \"beam.mesh\""),
    ));
    assert_names(&err, &["`mesh`", "exactly one"]);
    let err = read_error(&edit(generate, ""));
    assert_names(&err, &["`mesh`", "exactly one"]);
    let err = read_error(&edit(generate, "path = \"no/such/file.mesh\""));
    assert_names(&err, &["mesh.path", "no mesh file", "file.mesh"]);
    let err = read_error(&edit(
        "size = [1.0, 0.2, 0.2], cells = [4, 1, 1]",
        "size = [1.0, -0.2, 0.2], cells = [0, 1, 1]",
    ));
    assert_names(&err, &["mesh.generate.size[1]", "mesh.generate.cells[0]"]);
    let err = read_error(&edit(
        "cells = [4, 1, 1]",
        "cells = [100000, 100000, 100000]",
    ));
    assert_names(&err, &["mesh.generate.cells", "more than"]);
    let err = read_error(&edit(
        "cells = [4, 1, 1] }",
        "cells = [4, 1, 1] }\nscale = -0.001",
    ));
    assert_names(&err, &["mesh.scale", "positive finite factor", "-0.001"]);
}

#[test]
fn every_piece_of_a_disconnected_mesh_needs_a_pin() {
    let dir = scratch("pieces");
    let mut mesh = beam([4, 1, 1], [0.0, 0.0, 0.0]);
    let other = beam([2, 1, 1], [0.0, 1.0, 0.0]);
    let offset = mesh.num_vertices();
    mesh.vertices.extend(other.vertices);
    mesh.tets
        .extend(other.tets.iter().map(|t| t.map(|i| i + offset)));
    write_medit(&dir.join("two.mesh"), &mesh);
    let generate = "generate = { kind = \"box\", size = [1.0, 0.2, 0.2], cells = [4, 1, 1] }";
    let text = edit(generate, "path = \"two.mesh\"");
    // Both pieces touch x = 0: pinned.
    builds(&text, &dir);
    // Only the first touches the pin box.
    let one = text.replace(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        "box = { min = [-0.1, -0.1, -0.1], max = [0.1, 0.3, 0.3] }",
    );
    let err = build_error(&one, &dir);
    assert_names(
        &err,
        &[
            "`pin`",
            "piece 2 of the 2",
            "falls freely",
            "add a [[pin]] that selects",
        ],
    );
    // Without gravity the loose piece may float.
    builds(&one.replace("[0.0, -9.81, 0.0]", "[0.0, 0.0, 0.0]"), &dir);
    // A spring for the whole run on the pinned piece does not hold the other (it did before
    // stop 76: any such spring let every piece through).
    let err = build_error(&one.replace("end = 0.5\n", ""), &dir);
    assert_names(&err, &["piece 2 of the 2", "falls freely"]);
    // On the other piece, it holds it in the scene's own trajectory, and the stages, which
    // leave the scene's forces out, are warned of.
    let held = one
        .replace("end = 0.5\n", "")
        .replace("center = [1.0, 0.1, 0.1]", "center = [1.0, 1.1, 0.1]");
    let scene = Scene::from_str(&held, &dir, "ok.toml").unwrap();
    let built = scene.build_model().unwrap_or_else(|e| panic!("{e:#}"));
    assert!(
        built.warnings.iter().any(|w| w.contains("piece 2 of the 2 disconnected pieces of the mesh is held by force[0]'s spring and no pin")),
        "{:?}",
        built.warnings
    );
}

/// A broken table header is reported at its line, not under the section before it.
#[test]
fn a_broken_header_names_no_other_section() {
    let err = read_error(&edit("[time]", "[time"));
    assert!(err.contains("bad.toml") && err.contains("line 18"), "{err}");
    assert!(!err.contains("`gravity`"), "{err}");
    // A line of a multi-line array is no header: its error keeps the array's section.
    let err = read_error(&edit(
        "keyframes = [[0.0, 0.0, 0.0, 0.0], [0.3, 0.0, 0.1, 0.0]]",
        "keyframes = [\n  [0.0, 0.0, 0.0, 0.0],\n  [0.3, \"x\", 0.1, 0.0],\n]",
    ));
    assert!(err.contains("`force[0]"), "{err}");
}

#[test]
fn pins_that_hold_every_vertex_are_an_error() {
    let all = edit(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        "box = { min = [-0.1, -0.1, -0.1], max = [1.1, 0.3, 0.3] }",
    );
    let err = build_error(&all, Path::new("."));
    assert_names(
        &err,
        &[
            "`pin`",
            "every one of the body's 20 vertices",
            "pin[0] selects 20",
            "select fewer",
        ],
    );
    // A face left free (x = 1) is a body.
    builds(&all.replace("max = [1.1,", "max = [0.9,"), Path::new("."));
}

/// BASE's beam with one more vertex, which no tet uses, written to `dir/loose.mesh`: the
/// mesh, that vertex, and BASE reading the file.
fn beam_with_a_loose_vertex(dir: &Path) -> (TetMesh, usize, String) {
    let mut mesh = beam([4, 1, 1], [0.0, 0.0, 0.0]);
    mesh.vertices.push(fem_core::Vec3::new(-1.0, 0.0, 0.0));
    let loose = mesh.num_vertices() - 1;
    write_medit(&dir.join("loose.mesh"), &mesh);
    let text = edit(
        "generate = { kind = \"box\", size = [1.0, 0.2, 0.2], cells = [4, 1, 1] }",
        "path = \"loose.mesh\"",
    );
    (mesh, loose, text)
}

#[test]
fn pins_on_vertices_no_tet_uses_hold_nothing() {
    let dir = scratch("unreferenced");
    let (_, loose, text) = beam_with_a_loose_vertex(&dir);
    let text = text.replace(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        &format!("indices = [{loose}]"),
    );
    let err = build_error(&text, &dir);
    assert_names(&err, &["`pin`", "no pinned vertex holds the mesh"]);
}

/// A force's vertices no tet uses are left out of it, as for the pins (the runtime refuses them,
/// which stopped every reduced method of such a scene); a force on them alone is an error.
#[test]
fn forces_on_vertices_no_tet_uses_leave_them_out() {
    let dir = scratch("force-stray");
    let (mesh, loose, text) = beam_with_a_loose_vertex(&dir);
    let tip = (0..mesh.num_vertices())
        .find(|&v| mesh.vertices[v].x == 1.0)
        .unwrap();
    let both = text.replace(
        "select = { sphere = { center = [1.0, 0.1, 0.1], radius = 0.15 } }",
        &format!("select = {{ indices = [{tip}, {loose}] }}"),
    );
    let built = Scene::from_str(&both, &dir, "both.toml")
        .unwrap()
        .build_model()
        .unwrap();
    assert_eq!(built.model.forces[0].vertices, [tip]);
    let alone = text.replace(
        "select = { sphere = { center = [1.0, 0.1, 0.1], radius = 0.15 } }",
        &format!("select = {{ indices = [{loose}] }}"),
    );
    let err = build_error(&alone, &dir);
    assert_names(&err, &["force[0].select", "only vertices no tet uses"]);
}

/// The body's counts a built model reports, and the line `cargo xtask` prints first: a vertex
/// no tet uses is no part of the body, and a vertex two pins select is held once.
#[test]
fn the_body_line_counts_the_vertices_each_pin_holds() {
    let dir = scratch("body-line");
    let (mesh, loose, text) = beam_with_a_loose_vertex(&dir);
    let x_max = (0..mesh.num_vertices())
        .find(|&v| mesh.vertices[v].x == 1.0)
        .unwrap();
    let x_min = (0..mesh.num_vertices())
        .find(|&v| mesh.vertices[v].x == 0.0)
        .unwrap();
    let text = text + &format!("\n[[pin]]\nindices = [{loose}, {x_min}, {x_max}]\n");
    let scene = Scene::from_str(&text, &dir, "ok.toml").unwrap();
    let built = scene.build_model().unwrap();
    assert_eq!(built.validation.unreferenced_vertices, 1);
    assert_eq!(
        built.model.mesh.num_vertices() - built.validation.unreferenced_vertices,
        20
    );
    assert_eq!(built.pin_vertices, [4, 2]);
    assert_eq!(built.held_vertices, 5);
    let p = pipeline::pipeline::Pipeline::new(&scene, dir.join("cache")).unwrap();
    assert_eq!(
        p.body_summary(),
        format!(
            "{}: 20 vertices and {} tets, 1.000 × 0.200 × 0.200 m; the pins hold 5 of them, \
             25 % (pin[0] 4, pin[1] 2)",
            scene.source,
            mesh.num_tets()
        )
    );
}

#[test]
fn errors_from_files_name_the_file() {
    let dir = scratch("files");
    let path = dir.join("scene.toml");
    std::fs::write(&path, edit("poisson_ratio = 0.4", "poisson_ratio = 0.5")).unwrap();
    let err = format!("{:#}", Scene::from_file(&path).unwrap_err());
    assert!(err.contains(&path.display().to_string()), "{err}");
    assert!(err.contains("material.poisson_ratio"), "{err}");
    let missing = dir.join("missing.toml");
    let err = format!("{:#}", Scene::from_file(&missing).unwrap_err());
    assert!(err.contains("missing.toml"), "{err}");
    // A mesh path is relative to the scene file.
    std::fs::write(
        &path,
        edit(
            "generate = { kind = \"box\", size = [1.0, 0.2, 0.2], cells = [4, 1, 1] }",
            "path = \"beam.mesh\"",
        ),
    )
    .unwrap();
    let err = format!("{:#}", Scene::from_file(&path).unwrap_err());
    assert!(
        err.contains(&dir.join("beam.mesh").display().to_string()),
        "{err}"
    );
    write_medit(&dir.join("beam.mesh"), &beam([4, 1, 1], [0.0; 3]));
    Scene::from_file(&path).unwrap().build_model().unwrap();
}

/// A surface mesh is refused beside the scene's other errors (here the missing pin), with the
/// commands that tetrahedralize it; it used to wait until the pin was added.
#[test]
fn a_surface_mesh_is_said_with_the_other_errors() {
    let dir = scratch("surface");
    std::fs::write(dir.join("body.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let path = dir.join("scene.toml");
    std::fs::write(&path, "name = \"s\"\n[mesh]\npath = \"body.obj\"\n").unwrap();
    let err = format!("{:#}", Scene::from_file(&path).unwrap_err());
    assert!(err.contains("mesh.path"), "{err}");
    assert!(err.contains("a surface mesh"), "{err}");
    assert!(err.contains("tetgen -pqg"), "{err}");
    assert!(err.contains("add a [[pin]] section"), "{err}");
}

/// This package's folder, read when the test runs: `cargo test` sets `CARGO_MANIFEST_DIR` for
/// the test process too, so a copy of the checkout tested against the same build (`.ci/run`
/// does this) reads the copy's `data/` and looks for `shared/` beside the copy.
fn manifest_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")))
}

/// Every scene shipped in `data/` reads without error and builds its model. The mesh of some
/// lives in `shared/` beside the repository, which a user's clone does not have: such a scene
/// is then read with a generated box in place of its `[mesh]` section, so that every other field
/// is still checked, and only its model is skipped, with a printed line.
#[test]
fn every_shipped_scene_reads_and_builds() {
    let root = manifest_dir().join("../..");
    let dir = root.join("data");
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("data/ is in the repository")
        .map(|e| e.expect("data/ lists").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    scenes.sort();
    assert!(scenes.len() >= 2, "data/ holds scenes: {scenes:?}");
    // The built-in scene lives in the crate (a source package builds without data/), linked
    // from data/.
    assert_eq!(
        std::fs::read_to_string(dir.join("cantilever.toml")).expect("data/cantilever.toml"),
        pipeline::scene::DEFAULT_SCENE
    );
    let shared = root.join("../shared");
    let mut built = 0;
    for path in &scenes {
        let text = std::fs::read_to_string(path).expect("a shipped scene reads");
        let mut table: toml::Table =
            toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mesh = table
            .get("mesh")
            .and_then(|m| m.get("path"))
            .and_then(|p| p.as_str())
            .map(PathBuf::from);
        if let Some(mesh) = mesh.filter(|m| m.starts_with("../../shared") && !shared.is_dir()) {
            let stand_in: toml::Table = toml::from_str(
                r#"generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [2, 1, 1] }"#,
            )
            .unwrap();
            table.insert("mesh".into(), toml::Value::Table(stand_in));
            let text = toml::to_string(&table).unwrap();
            Scene::from_str(&text, &dir, &path.display().to_string()).unwrap_or_else(|e| {
                panic!("{} (its mesh replaced by a box): {e:#}", path.display())
            });
            let _ = writeln!(
                std::io::stderr(),
                "skipping the model of {}: its mesh {} is in shared/, not found at {}",
                path.display(),
                mesh.display(),
                shared.display()
            );
            continue;
        }
        let scene = Scene::from_file(path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        let model = scene
            .build_model()
            .unwrap_or_else(|e| panic!("{}: {e:#}", path.display()))
            .model;
        assert!(model.dofs.num_free() > 0, "{}", path.display());
        built += 1;
    }
    assert!(built >= 1, "no shipped scene built its model: {scenes:?}");
}

/// The warnings building `scene`'s model gives (cache folder `cache`).
fn model_warnings(scene: &Scene, cache: &Path) -> Vec<String> {
    pipeline::pipeline::Pipeline::new(scene, cache)
        .unwrap()
        .warnings
}

/// The one warning building `scene`'s model gives, checked to contain every needle.
fn only_warning(scene: &Scene, cache: &Path, needles: &[&str]) -> String {
    let w = model_warnings(scene, cache);
    assert_eq!(w.len(), 1, "{w:?}");
    for needle in needles {
        assert!(w[0].contains(needle), "{needle}: {}", w[0]);
    }
    w[0].clone()
}

/// What building the model warns of is kept for `run`'s list, first among the figures not to be
/// trusted: a body 3 m tall of E = 10⁵ Pa, which its own weight would crush.
#[test]
fn the_models_warnings_are_kept_for_the_report() {
    let dir = scratch("model-warnings");
    // BASE's bar is one cell thick, and said to be: its tets lock in bending.
    let thin = Scene::from_str(BASE, Path::new("."), "thin.toml").unwrap();
    only_warning(
        &thin,
        &dir.join("thin"),
        &["the body is about one element thick"],
    );
    // Two cells across, it is not; the rest of the test starts from there.
    let scene = |text: &str| {
        let text = text.replace("cells = [4, 1, 1]", "cells = [8, 2, 2]");
        Scene::from_str(&text, Path::new("."), "tall.toml").unwrap()
    };
    let quiet = model_warnings(&scene(BASE), &dir.join("a"));
    assert!(quiet.is_empty(), "{quiet:?}");
    let tall = scene(&edit("size = [1.0, 0.2, 0.2]", "size = [1.0, 3.0, 0.2]"));
    let w = only_warning(&tall, &dir.join("b"), &["ρgH/E = 0.29"]);
    // The modulus named brings ρgH/E to the limit, as a floor: 1000 · 9.81 · 3 / 0.25, rounded
    // up to the figures printed, so that written back it passes.
    assert!(
        w.contains("`[material] youngs_modulus` of at least 1.178e5 Pa (where ρgH/E is 0.25;"),
        "{w}"
    );
    let firmer = edit("size = [1.0, 0.2, 0.2]", "size = [1.0, 3.0, 0.2]")
        .replace("youngs_modulus = 1.0e5", "youngs_modulus = 1.178e5");
    assert!(firmer.contains("1.178e5"), "{firmer}");
    let quiet = model_warnings(&scene(&firmer), &dir.join("b2"));
    assert!(quiet.iter().all(|w| !w.contains("ρgH/E")), "{quiet:?}");
    let row = pipeline::run::MethodReport {
        scene_warnings: vec![w.clone()],
        ..Default::default()
    };
    let listed = pipeline::trust::assess(&[row]).untrusted;
    assert_eq!(listed.first(), Some(&format!("the scene: {w}")));
    // Pins that hold the body along one line (a hinge) are kept too: the run said nothing of
    // them once the stages had printed over the first warning.
    let hinge = scene(&edit(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        "box = { min = [-0.01, -0.01, -0.01], max = [0.01, 0.21, 0.01] }",
    ));
    let w = only_warning(&hinge, &dir.join("c"), &[]);
    assert!(
        w.starts_with("the pins hold the body by 3 vertices on one line"),
        "{w}"
    );
    // A pin plane across the bar's thickness holds a third of it, glued along a whole side:
    // said, with the bar's long axis (a mesh made standing along x).
    let side = scene(&edit(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        "plane = { axis = \"y\", side = \"min\", tolerance = 1.0e-6 }",
    ));
    only_warning(
        &side,
        &dir.join("d"),
        &[
            "the pin planes hold 27 of the body's 81 vertices (33 %)",
            "tallest along x (1.000 m, against 0.2000 m along y)",
            "set the pin plane's `axis` and `[gravity]` to it",
        ],
    );
    // Pinned across its long axis as the README's plane pins, it is not (`quiet`); nor is a
    // box drawn around the same third (a part the user chose to hold, as one bell of a
    // dumbbell).
    let part = scene(&edit(
        "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
        "box = { min = [-0.01, -0.01, -0.01], max = [1.01, 0.01, 0.21] }",
    ));
    let w = model_warnings(&part, &dir.join("e"));
    assert!(w.is_empty(), "{w:?}");
}

/// A scene file that cannot be read says why in the message itself (a program printing `{e}`
/// saw only "cannot read"), and a model file given as a scene is named as one.
#[test]
fn unreadable_scene_files_say_why() {
    let dir = std::env::temp_dir().join(format!("scene-unreadable-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let missing = Scene::from_file(dir.join("missing.toml")).unwrap_err();
    assert!(
        missing.to_string().contains("cannot read scene file")
            && missing.to_string().contains("os error"),
        "{missing}"
    );
    let model = dir.join("part.model");
    let mut bytes = b"LATDYNm\0".to_vec();
    bytes.extend([0xff, 0xfe, 0x00, 0x80]);
    std::fs::write(&model, bytes).unwrap();
    let err = Scene::from_file(&model).unwrap_err().to_string();
    assert!(
        err.contains("it is a model file") && err.contains("ReducedModel::load"),
        "{err}"
    );
    // A scene saved as UTF-16 (PowerShell's `>`) is told to be saved as UTF-8.
    let utf16 = dir.join("scene.toml");
    std::fs::write(&utf16, [0xff, 0xfe, b'n', 0, b'a', 0]).unwrap();
    let err = Scene::from_file(&utf16).unwrap_err().to_string();
    assert!(err.contains("save the scene (TOML) as UTF-8"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A fixed PCA dimension past what the training poses can span is refused before the
/// snapshots are computed, naming the field and the most it can be.
#[test]
fn a_pca_dimension_past_the_training_poses_is_refused() {
    let text = format!(
        "{BASE}\n[training]\nschedules = 4\nframes_per_schedule = 20\n\n[pca]\ndimension = 81\n"
    );
    let err = read_error(&text);
    assert_names(
        &err,
        &[
            "pca.dimension",
            "81 is more than the 80 training poses",
            "4 × 20",
            "at most 80",
        ],
    );
    builds(
        &text.replace("dimension = 81", "dimension = 80"),
        Path::new("."),
    );
    // Past the mesh's free coordinates (20 vertices, 4 pinned: 48), the stage says so.
    let scene = Scene::from_str(
        &text.replace("dimension = 81", "dimension = 60"),
        Path::new("."),
        "bad.toml",
    )
    .unwrap();
    let mut p = pipeline::pipeline::Pipeline::new(&scene, scratch("pca-past-the-mesh")).unwrap();
    let err = format!("{:#}", p.pca(&|_, _| {}).unwrap_err());
    assert_names(
        &err,
        &["`pca.dimension` = 60 is more than the mesh's 48 free coordinates"],
    );
}

/// The command a report offers for four drags names the scene file, quoted for a shell where
/// it must be (without `--scene` it ran the built-in scene), and none for the built-in scene.
#[test]
fn the_one_draw_command_names_the_scene_file() {
    let line = |source: &str| {
        let scene = Scene::from_str(BASE, Path::new("."), source).unwrap();
        pipeline::run::one_draw(&scene)
    };
    assert!(
        line("scenes/bar.toml")
            .contains("`cargo xtask run --scene scenes/bar.toml --trajectories 4`")
    );
    assert!(line("my bar.toml").contains("--scene 'my bar.toml' --trajectories 4"));
    assert!(line("it's.toml").contains(r"--scene 'it'\''s.toml'"));
    assert!(line("<built-in cantilever>").contains("`cargo xtask run --trajectories 4`"));
}
