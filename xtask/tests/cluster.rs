//! `snapshots` as an array job runs it: one `xtask` process per index with only the scheduler's
//! variables set (no `--shard`), all writing into one cache, then `--merge`. The merged snapshots
//! must be the unsharded ones, for a Slurm job array and for a Kubernetes Indexed Job.

use std::path::Path;
use std::process::{Command, Stdio};

use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;
use pipeline::shard;
use tests::scratch_dir;

/// Five schedules over three shards: the shards hold 2, 2 and 1 of them.
const SCENE: &str = r#"
name = "shards"
mesh = { generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [5, 1, 1] } }
material = { youngs_modulus = 1.0e5, poisson_ratio = 0.4, density = 1000.0 }
pin = [{ plane = { axis = "x", side = "min" } }]
time = { step = 0.02, frames = 6 }
training = { schedules = 5, frames_per_schedule = 6 }
"#;
const SHARDS: usize = 3;

/// Every variable an array job could set, removed from each child so that the test's own
/// environment (a CI job inside an array, say) cannot leak in.
const ARRAY_VARIABLES: [&str; 6] = [
    shard::SLURM_ARRAY_TASK_ID,
    shard::SLURM_ARRAY_TASK_COUNT,
    shard::SLURM_ARRAY_TASK_MIN,
    shard::SLURM_ARRAY_TASK_STEP,
    shard::JOB_COMPLETION_INDEX,
    shard::SHARD_COUNT,
];

fn xtask(scene: &Path, cache: &Path, vars: &[(&str, String)], args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_xtask"));
    cmd.arg("snapshots")
        .arg("--scene")
        .arg(scene)
        .arg("--cache")
        .arg(cache)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    for v in ARRAY_VARIABLES {
        cmd.env_remove(v);
    }
    cmd.envs(vars.iter().map(|(k, v)| (k, v)));
    cmd
}

/// Starts one process per index with `vars(index)` (all at once, as the scheduler would), waits
/// for them, merges, and returns what each shard process printed.
fn run_array(
    scene: &Path,
    cache: &Path,
    vars: impl Fn(usize) -> Vec<(&'static str, String)>,
) -> Vec<String> {
    let children: Vec<_> = (0..SHARDS)
        .map(|i| xtask(scene, cache, &vars(i), &[]).spawn().unwrap())
        .collect();
    let printed = children
        .into_iter()
        .map(|child| {
            let out = child.wait_with_output().unwrap();
            let text = String::from_utf8_lossy(&out.stdout).into_owned();
            assert!(
                out.status.success(),
                "{text}{}",
                String::from_utf8_lossy(&out.stderr)
            );
            text
        })
        .collect();
    let shards = SHARDS.to_string();
    let merging = || {
        xtask(scene, cache, &[], &["--merge", &shards])
            .output()
            .unwrap()
    };
    let merge = merging();
    assert!(
        merge.status.success(),
        "{}",
        String::from_utf8_lossy(&merge.stderr)
    );
    let said = String::from_utf8_lossy(&merge.stdout);
    assert!(said.contains(&format!("merged {SHARDS} shards")), "{said}");
    // Merging again reads no shard: the merged snapshots are cached, and it says so.
    let again = merging();
    let said = String::from_utf8_lossy(&again.stdout);
    assert!(
        again.status.success() && said.contains("no shard was read"),
        "{said}"
    );
    printed
}

#[test]
fn array_jobs_shard_by_their_variables_and_merge_to_the_unsharded_snapshots() {
    let dir = scratch_dir("cluster");
    let scene_path = dir.join("shards.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let scene = Scene::from_file(&scene_path).unwrap();
    let whole = Pipeline::new(&scene, dir.join("unsharded"))
        .unwrap()
        .snapshots(&|_, _| {})
        .unwrap();
    assert_eq!(whole.schedules.len(), 5);

    let slurm = dir.join("slurm");
    let printed = run_array(&scene_path, &slurm, |i| {
        vec![
            // --array=1-3: Slurm numbers from the array's first index.
            (shard::SLURM_ARRAY_TASK_ID, (i + 1).to_string()),
            (shard::SLURM_ARRAY_TASK_MIN, "1".into()),
            (shard::SLURM_ARRAY_TASK_COUNT, SHARDS.to_string()),
        ]
    });
    for (i, text) in printed.iter().enumerate() {
        assert!(
            text.contains(&format!("shard {i}/{SHARDS} from the Slurm job array")),
            "{text}"
        );
    }
    let kubernetes = dir.join("kubernetes");
    run_array(&scene_path, &kubernetes, |i| {
        vec![
            (shard::JOB_COMPLETION_INDEX, i.to_string()),
            (shard::SHARD_COUNT, SHARDS.to_string()),
        ]
    });

    for cache in [slurm, kubernetes] {
        let mut p = Pipeline::new(&scene, &cache).unwrap();
        let merged = p.snapshots(&|_, _| {}).unwrap();
        assert!(
            p.outcomes.iter().all(|o| o.cached),
            "the merged artifact is the stage's"
        );
        assert_eq!(merged, whole, "{}", cache.display());
    }
}

#[test]
fn a_kubernetes_index_without_the_count_is_refused() {
    let dir = scratch_dir("cluster-no-count");
    let scene_path = dir.join("shards.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let out = xtask(
        &scene_path,
        &dir.join("cache"),
        &[(shard::JOB_COMPLETION_INDEX, "0".into())],
        &[],
    )
    .output()
    .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(shard::SHARD_COUNT), "{err}");
    let simulated = std::fs::read_dir(dir.join("cache"))
        .into_iter()
        .flatten()
        .flatten()
        .any(|e| e.file_name().to_string_lossy().starts_with("snapshots"));
    assert!(!simulated, "nothing is simulated");
}

/// A shard alone (`--shard 0/1`, or shards not merged yet) is not the snapshots the later
/// stages read: the whole set is simulated, and the process says why and how to merge.
#[test]
fn unmerged_shards_are_named_when_the_whole_set_is_simulated() {
    let dir = scratch_dir("cluster-unmerged");
    let scene_path = dir.join("shards.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let cache = dir.join("cache");
    let shard = xtask(&scene_path, &cache, &[], &["--shard", "0/2"])
        .output()
        .unwrap();
    assert!(shard.status.success());
    let whole = xtask(&scene_path, &cache, &[], &[]).output().unwrap();
    assert!(whole.status.success());
    let err = String::from_utf8_lossy(&whole.stderr);
    assert!(
        err.contains("holds 1 snapshot shard file but not the merged snapshots")
            && err.contains("--merge N"),
        "{err}"
    );
    // Once merged (or simulated whole, as here), nothing more is said.
    let again = xtask(&scene_path, &cache, &[], &[]).output().unwrap();
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(!err.contains("snapshot shard"), "{err}");
}

/// More shards than schedules: a shard past them holds none, is written all the same (the merge
/// reads every shard) and says so; the merge of them all is the unsharded set.
#[test]
fn a_shard_past_the_schedules_says_it_holds_none() {
    let dir = scratch_dir("cluster-empty-shard");
    let scene_path = dir.join("shards.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let cache = dir.join("cache");
    for index in 0..6 {
        let out = xtask(
            &scene_path,
            &cache,
            &[],
            &["--shard", &format!("{index}/6")],
        )
        .output()
        .unwrap();
        assert!(out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            err.contains("shard 5/6 holds no schedule: the scene trains on 5 schedules"),
            index == 5,
            "shard {index}/6: {err}"
        );
    }
    let merged = xtask(&scene_path, &cache, &[], &["--merge", "6"])
        .output()
        .unwrap();
    assert!(
        merged.status.success(),
        "{}",
        String::from_utf8_lossy(&merged.stderr)
    );
    let out = String::from_utf8_lossy(&merged.stdout);
    assert!(out.contains("merged 6 shards: 30 frames"), "{out}");
}
