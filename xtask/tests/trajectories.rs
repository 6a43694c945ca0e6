//! `cargo xtask run` and the test trajectories a scene asks for: `[test] schedules` above 1 runs
//! them all, `--trajectory i` runs any one (trajectory i does not depend on the count), and a
//! count a plain run will not take is refused naming the field.

use std::ffi::OsStr;
use std::path::Path;
use std::process::Command;

use tests::{TINY, scratch_dir};

/// `xtask COMMAND --scene S --cache DIR/cache` with `scene` written into `dir` as S, then
/// `args`: its exit status and output (stdout, then stderr).
fn xtask(dir: &Path, scene: &str, command: &str, args: &[&OsStr]) -> (bool, String) {
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .arg(command)
        .arg("--scene")
        .arg(&path)
        .arg("--cache")
        .arg(dir.join("cache"))
        .args(args)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// `xtask run` on `scene` (written into `dir`), pca only, no frames; its exit status and output.
fn run(dir: &Path, scene: &str, args: &[&str]) -> (bool, String) {
    let out = dir.join("out");
    let mut all: Vec<&OsStr> = vec!["--out".as_ref(), out.as_os_str()];
    all.extend(
        ["--every", "0", "--methods", "full,pca"]
            .iter()
            .chain(args)
            .map(OsStr::new),
    );
    xtask(dir, scene, "run", &all)
}

fn pca_errors(report: &Path) -> Vec<f64> {
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    let pca = rows["methods"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["method"] == "pca")
        .unwrap();
    pca["frame_errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_f64().unwrap())
        .collect()
}

#[test]
fn a_scene_asking_for_several_test_trajectories_gets_them_and_any_one_runs() {
    let dir = scratch_dir("xtask-trajectories");
    let several = TINY.replace(
        "[test]\nframes_per_schedule = 12",
        "[test]\nframes_per_schedule = 12\nschedules = 3",
    );
    assert_ne!(several, TINY, "TINY's [test] section moved");
    let (ok, text) = run(&dir, &several, &[]);
    assert!(ok, "{text}");
    // Having run three, it does not suggest running four as if it had run one.
    assert!(!text.contains("one draw of the test family"), "{text}");
    let out = dir.join("out");
    let table = std::fs::read_to_string(out.join("trajectories.md")).unwrap();
    assert!(table.contains("trajectory 2"), "{table}");
    let third = pca_errors(&out.join("trajectory-2").join("report.json"));
    // Each stage once, this trajectory's reference among them.
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("trajectory-2").join("report.json")).unwrap(),
    )
    .unwrap();
    let stages: Vec<&str> = report["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["stage"].as_str().unwrap())
        .collect();
    let mut unique = stages.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), stages.len(), "{stages:?}");
    assert!(stages.contains(&"reference"), "{stages:?}");
    assert_eq!(report["trajectory"], 2);

    // The plain scene (one test schedule) runs trajectory 2 by name, to the same errors.
    let (ok, text) = run(&dir, TINY, &["--trajectory", "2"]);
    assert!(ok, "{text}");
    assert!(text.contains("one draw of the test family"), "{text}");
    assert_eq!(pca_errors(&out.join("report.json")), third);
    // Each method's run says when it ends, in a log too, where no bar is drawn.
    assert!(text.contains("       pca: 12 steps in "), "{text}");
    // With `--every 0` no frame is written, and no empty folder per method is left.
    assert!(!out.join("pca").exists() && !out.join("full").exists());

    let (ok, text) = run(
        &dir,
        &several.replace("schedules = 3", "schedules = 65"),
        &[],
    );
    assert!(!ok);
    assert!(text.contains("[test] schedules = 65"), "{text}");
}

/// A file where the output folder should be is refused before any stage runs.
#[test]
fn an_output_path_that_is_a_file_is_refused_at_once() {
    let dir = scratch_dir("xtask-out-file");
    std::fs::write(dir.join("out"), "not a folder").unwrap();
    let (ok, text) = run(&dir, TINY, &[]);
    assert!(!ok, "{text}");
    assert!(text.contains("is a file, not a folder"), "{text}");
    assert!(!dir.join("cache").exists(), "a stage ran: {text}");
}

/// A method named twice is refused before any stage runs; it used to be measured twice.
#[test]
fn a_method_named_twice_is_refused_at_once() {
    let dir = scratch_dir("xtask-method-twice");
    let (ok, text) = run(&dir, TINY, &["--methods", "pca"]);
    assert!(!ok, "{text}");
    assert!(
        text.contains("--methods names pca twice; name each method once"),
        "{text}"
    );
    assert!(!dir.join("cache").exists(), "a stage ran: {text}");
}

/// A cache path that is a file is said plainly, before any stage.
#[test]
fn a_cache_path_that_is_a_file_is_refused() {
    let dir = scratch_dir("xtask-cache-file");
    std::fs::write(dir.join("cache"), "not a folder").unwrap();
    let (ok, text) = run(&dir, TINY, &[]);
    assert!(!ok, "{text}");
    assert!(text.contains("is a file, not a folder"), "{text}");
}

/// `export --out` naming a folder is refused before any stage runs, with the file path to give.
#[test]
fn export_to_a_folder_is_refused_at_once() {
    let dir = scratch_dir("xtask-export-folder");
    // A folder, and one not made yet written as one (it failed after every stage).
    let new = dir.join("models").into_os_string().into_string().unwrap() + "/";
    for out in [dir.as_os_str(), new.as_ref()] {
        let args: Vec<&OsStr> = vec!["--method".as_ref(), "pca".as_ref(), "--out".as_ref(), out];
        let (ok, text) = xtask(&dir, TINY, "export", &args);
        assert!(!ok, "{text}");
        assert!(
            text.contains("names a folder: give the model file's path"),
            "{text}"
        );
        assert!(!dir.join("cache").exists(), "a stage ran: {text}");
    }
}

/// `export` offers only the methods that have a model: a full-space one is refused by the
/// command line itself, with the reduced ones listed.
#[test]
fn export_refuses_a_full_space_method_at_once() {
    let dir = scratch_dir("xtask-export-full");
    let args: Vec<&OsStr> = vec!["--method".as_ref(), "full".as_ref()];
    let (ok, text) = xtask(&dir, TINY, "export", &args);
    assert!(!ok, "{text}");
    assert!(text.contains("invalid value 'full'"), "{text}");
    assert!(text.contains("neural-cubature"), "{text}");
    assert!(!dir.join("cache").exists(), "a stage ran: {text}");
}

/// Flags that contradict each other or cannot be taken are refused naming the flag, before any
/// stage runs: a solver against a method that names its own, a negative count, a sweep that
/// times nothing.
#[test]
fn contradicting_or_impossible_flags_name_the_flag() {
    let dir = scratch_dir("xtask-flags");
    for (command, args, says) in [
        (
            "simulate",
            &["--method", "full-lbfgs", "--solver", "newton"][..],
            "`--solver newton` contradicts `--method full-lbfgs`",
        ),
        ("simulate", &["--every", "-1"][..], "'--every <EVERY>'"),
        ("bench", &["--repeats", "0"][..], "'--repeats <REPEATS>'"),
        ("bench", &["--tolerances", "-1"][..], "(`--tolerances`)"),
        ("snapshots", &["--merge", "0"][..], "'--merge <N>'"),
        ("snapshots", &["--shard", "-1/3"][..], "--shard takes I/N"),
    ] {
        let args: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
        let (ok, text) = xtask(&dir, TINY, command, &args);
        assert!(!ok, "{command} {args:?}: {text}");
        assert!(text.contains(says), "{command} {args:?}: {text}");
        let cached = std::fs::read_dir(dir.join("cache")).map_or(0, |d| d.count());
        assert_eq!(cached, 0, "a stage ran: {text}");
    }
}

/// `bench` builds a pipeline per variant over one cache: each stage artifact is said once,
/// when first computed or loaded, not again by every variant that shares it.
#[test]
fn bench_says_each_stage_once() {
    let dir = scratch_dir("xtask-bench-stages");
    let out = dir.join("out");
    let args: Vec<&OsStr> = vec![
        "--out".as_ref(),
        out.as_os_str(),
        "--repeats".as_ref(),
        "1".as_ref(),
    ];
    let (ok, text) = xtask(&dir, TINY, "bench", &args);
    assert!(ok, "{text}");
    let artifacts: Vec<&str> = text
        .lines()
        .filter_map(|l| l.split_once(" → ").map(|(_, path)| path))
        .chain(text.lines().filter_map(|l| {
            let (_, rest) = l.split_once("unchanged, skipped (")?;
            rest.strip_suffix(')')
        }))
        .collect();
    assert!(artifacts.len() > 5, "{text}");
    let unique: std::collections::HashSet<_> = artifacts.iter().collect();
    assert_eq!(unique.len(), artifacts.len(), "{text}");
}

/// `simulate` without `--out` writes under out/SCENE/simulate/METHOD, so the frames `run`
/// wrote in out/SCENE/METHOD stay as they were (it used to write over them, and `--every 0`
/// removed them).
#[test]
fn simulate_leaves_the_frames_of_run_alone() {
    let dir = scratch_dir("xtask-simulate-default");
    let name = format!("simulate-default-{}", std::process::id());
    let scene = TINY.replace("name = \"tiny\"", &format!("name = \"{name}\""));
    assert_ne!(scene, TINY, "TINY's name moved");
    // The default folders are in out/ where the command runs (the project, or the copy whose
    // tests reuse its build): removed however the test ends.
    let out = pipeline::output_root().join("out").join(&name);
    struct Removed<'a>(&'a Path);
    impl Drop for Removed<'_> {
        fn drop(&mut self) {
            std::fs::remove_dir_all(self.0).ok();
        }
    }
    let _removed = Removed(&out);
    let run_series = out.join("pca").join("series.pvd");
    let args: Vec<&OsStr> = ["--every", "1", "--methods", "full,pca"]
        .iter()
        .map(OsStr::new)
        .collect();
    let (ok, text) = xtask(&dir, &scene, "run", &args);
    assert!(ok, "{text}");
    let before = std::fs::read(&run_series).unwrap();
    let args: Vec<&OsStr> = ["--method", "pca", "--frames", "3", "--every", "0"]
        .iter()
        .map(OsStr::new)
        .collect();
    let (ok, text) = xtask(&dir, &scene, "simulate", &args);
    assert!(ok, "{text}");
    assert!(
        out.join("simulate/pca/summary.json").exists(),
        "no summary in out/SCENE/simulate/pca: {text}"
    );
    assert_eq!(
        std::fs::read(&run_series).ok().as_ref(),
        Some(&before),
        "run's frames changed: {text}"
    );
}

/// Output into a pipe closed early (`cargo xtask … | head`) ends the command quietly, as other
/// command-line tools end, not with a panic at its next line.
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_the_command_without_a_panic() {
    use std::io::Read;
    let dir = scratch_dir("xtask-closed-pipe");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, TINY).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["pipeline", "--until", "snapshots", "--scene"])
        .arg(&scene)
        .arg("--cache")
        .arg(dir.join("cache"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The reading end closed before the command prints its first line.
    drop(child.stdout.take());
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    child.wait().unwrap();
    assert!(
        !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
        "{stderr}"
    );
}
