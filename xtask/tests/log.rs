//! In a log, where no progress bar is drawn, a stage that computes says so when it starts: its
//! own line comes only when it ends, minutes later on a large mesh.

use std::path::Path;
use std::process::Command;

use tests::{TINY, scratch_dir};

/// `xtask ARGS… --scene S --cache DIR/cache` with the tiny beam written into `dir` as S: its
/// stdout, after checking that it succeeded.
fn xtask(dir: &Path, args: &[&str]) -> String {
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, TINY).unwrap();
    let mut command = Command::new(env!("CARGO_BIN_EXE_xtask"));
    command
        .args(args)
        .arg("--scene")
        .arg(&scene)
        .arg("--cache")
        .arg(dir.join("cache"));
    let out = command.output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

#[test]
fn a_log_says_which_stage_is_computing() {
    let dir = scratch_dir("xtask-log");
    let text = xtask(&dir, &["pipeline", "--until", "pca"]);
    // The basis starts first and says so of the snapshots it needs.
    for (stage, why) in [("snapshots", ", which pca needs"), ("pca", "")] {
        let started = text.find(&format!("{stage:>10}: computing{why}\n"));
        let ended = text.find(&format!("{stage:>10}: computed in"));
        assert!(
            started.is_some() && started < ended,
            "{stage} does not say it started before it ended:\n{text}"
        );
    }
    // Loaded from the cache, nothing computes.
    let again = xtask(&dir, &["pipeline", "--until", "pca"]);
    assert!(!again.contains("computing"), "{again}");
}

/// `run --methods full` computes the reference and nothing the reduced methods need.
#[test]
fn full_space_alone_computes_no_training_data() {
    let dir = scratch_dir("xtask-full-alone");
    let out = dir.join("out");
    let args = ["run", "--methods", "full", "--every", "0", "--out"];
    let text = xtask(&dir, &[&args[..], &[out.to_str().unwrap()]].concat());
    assert!(text.contains(" reference: computed"), "{text}");
    for stage in ["snapshots", "pca"] {
        assert!(!text.contains(&format!("{stage:>10}: comput")), "{text}");
    }
}

/// The suite's pipelines say in a log which stage they compute, as `run`'s do.
#[test]
fn the_suite_says_which_stage_is_computing() {
    let dir = scratch_dir("xtask-suite-log");
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    // A unit cube of five tets.
    let cube = "MeshVersionFormatted 1\nDimension 3\nVertices\n8\n\
                0 0 0 0\n1 0 0 0\n0 1 0 0\n1 1 0 0\n0 0 1 0\n1 0 1 0\n0 1 1 0\n1 1 1 0\n\
                Tetrahedra\n5\n1 2 3 5 0\n2 4 3 8 0\n2 5 6 8 0\n3 5 7 8 0\n2 3 5 8 0\nEnd\n";
    std::fs::write(meshes.join("cube.mesh"), cube).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["suite", "--meshes"])
        .arg(&meshes)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(" snapshots: computing, which pca needs\n"),
        "{text}"
    );
}

/// `bench`'s pipelines say in a log which stage they compute too.
#[test]
fn bench_says_which_stage_is_computing() {
    let dir = scratch_dir("xtask-bench-log");
    let out = dir.join("bench");
    let args = ["bench", "--repeats", "1", "--out"];
    let text = xtask(&dir, &[&args[..], &[out.to_str().unwrap()]].concat());
    assert!(
        text.contains(" snapshots: computing, which pca needs\n"),
        "{text}"
    );
}

/// A scene the model refuses (a pin that selects nothing) is said before any folder is made:
/// a tester's refused scene left an empty `out/SCENE`.
#[test]
fn a_refused_scene_leaves_no_output_folder() {
    let dir = scratch_dir("xtask-refused");
    let scene = dir.join("scene.toml");
    let plane = "plane = { axis = \"x\", side = \"min\" }";
    assert!(TINY.contains(plane));
    let far = TINY.replace(
        plane,
        "sphere = { center = [50.0, 0.0, 0.0], radius = 0.1 }",
    );
    std::fs::write(&scene, &far).unwrap();
    let out = dir.join("out");
    let run = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["run", "--every", "0", "--scene"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("selects no vertex"), "{err}");
    assert!(!out.exists(), "{} was made", out.display());
}
