//! Artifacts on disk: every damaged, outdated or foreign artifact is refused on load with a
//! message naming the command that rebuilds it, and a writer killed part-way leaves the previous
//! artifact loadable.
//!
//! - `every_corruption_of_every_artifact_type_is_detected`: the real artifacts of a tiny scene
//!   (snapshots, a snapshot shard, PCA, the autoencoder, cubature, the reference trajectory),
//!   each truncated at every header byte and along its payload, bit-flipped in every header bit
//!   and along its payload, padded, given another format version, stage, key or mesh; prints
//!   how many corrupted copies of each type were tried and detected.
//! - `a_killed_writer_leaves_the_previous_artifact`: re-runs this test binary as a child that
//!   writes large artifacts through the real `artifact::save` (atomic write) in a loop, kills
//!   it with SIGKILL as soon as a write is under way, and checks the target still loads whole.

use std::path::{Path, PathBuf};

mod common;
use common::scratch;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use pipeline::artifact::{self, ArtifactError, Expect, FORMAT_VERSION, fnv1a};
use pipeline::pipeline::{FittedCubature, Pipeline, Reference, TrainedModel};
use pipeline::scene::Scene;
use pipeline::stage::Stage;
use serde::de::DeserializeOwned;

const TINY: &str = r#"
name = "artifacts"
[mesh]
generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [4, 1, 1] }
[material]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
density = 1000.0
[[pin]]
plane = { axis = "x", side = "min" }
[time]
step = 0.02
frames = 6
[training]
schedules = 2
frames_per_schedule = 6
[test]
frames_per_schedule = 6
[pca]
dimension = 4
[autoencoder]
latent_dim = 2
hidden = [8]
epochs = 20
batch_size = 8
"#;

fn no_progress(_: usize, _: usize) {}

/// Stage and key of an artifact from its file name `<stage>-<key:016x>.art`.
fn stage_and_key(path: &Path) -> (Stage, u64) {
    let stem = path.file_stem().unwrap().to_string_lossy();
    let (stage, key) = stem.rsplit_once('-').unwrap();
    (
        stage.parse().unwrap(),
        u64::from_str_radix(key, 16).unwrap(),
    )
}

/// Length of the header of an artifact whose stage is named `stage` (everything before the
/// payload).
fn header_len(stage: &str) -> usize {
    8 + 4 + 2 + stage.len() + 5 * 8
}

/// Rewrites the header checksum so a deliberately edited header reads as written by a (foreign)
/// writer, not as corruption.
fn reseal(bytes: &mut [u8], header_len: usize) {
    let sum = fnv1a(&bytes[..header_len - 8]);
    bytes[header_len - 8..header_len].copy_from_slice(&sum.to_le_bytes());
}

/// The same header with stage name `to`, resealed.
fn restage(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    let mut out = bytes[..12].to_vec();
    out.extend((to.len() as u16).to_le_bytes());
    out.extend(to.as_bytes());
    out.extend(&bytes[14 + from.len()..]);
    reseal(&mut out, header_len(to));
    out
}

/// Corrupted copies of one artifact tried and detected.
#[derive(Debug, Default)]
struct Tally {
    tried: usize,
    detected: usize,
    missed: Vec<String>,
}

/// Loads every corruption of the good artifact at `good` as `T` and checks each is refused with
/// a message naming the file and the rebuild command.
fn corrupt_and_load<T: DeserializeOwned>(good: &Path, mesh: u64, other_mesh: u64) -> Tally {
    let (stage, key) = stage_and_key(good);
    let expect = Expect {
        stage,
        key: Some(key),
        mesh: Some(mesh),
    };
    let bytes = std::fs::read(good).unwrap();
    artifact::load::<T>(good, expect).expect("the good artifact loads");
    let header = header_len(stage.name());
    assert!(bytes.len() > header, "{stage}: no payload");
    let payload = bytes.len() - header;

    let mut cases: Vec<(String, Vec<u8>, Expect)> = Vec::new();
    // Truncated: at every header byte, along the payload, one byte short.
    for cut in (0..=header).chain((1..32).map(|k| header + k * payload / 32)) {
        cases.push((
            format!("truncated to {cut} bytes"),
            bytes[..cut].to_vec(),
            expect,
        ));
    }
    cases.push((
        "one byte short".into(),
        bytes[..bytes.len() - 1].to_vec(),
        expect,
    ));
    // Bit flips: every header bit, and 128 bits spread over the payload.
    for bit in 0..8 * header {
        let mut b = bytes.clone();
        b[bit / 8] ^= 1 << (bit % 8);
        cases.push((format!("header bit {bit} flipped"), b, expect));
    }
    for k in 0..128 {
        let at = header + (k * 7919) % payload;
        let mut b = bytes.clone();
        b[at] ^= 1 << (k % 8);
        cases.push((
            format!("payload byte {at} bit {} flipped", k % 8),
            b,
            expect,
        ));
    }
    // Padded.
    for extra in [1, 100] {
        let mut b = bytes.clone();
        b.extend(std::iter::repeat_n(0u8, extra));
        cases.push((format!("{extra} bytes appended"), b, expect));
    }
    // Another format version, as written by another build (consistent checksums).
    for version in [0, FORMAT_VERSION - 1, FORMAT_VERSION + 1, u32::MAX] {
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&version.to_le_bytes());
        reseal(&mut b, header);
        cases.push((format!("format version {version}"), b, expect));
    }
    // Another stage's artifact at this stage's path.
    for other in [Stage::Pca, Stage::Snapshots, Stage::Train, Stage::Reference] {
        if other != stage {
            cases.push((
                format!("stage `{other}`"),
                restage(&bytes, stage.name(), other.name()),
                expect,
            ));
        }
    }
    // Another mesh (a scene with another vertex count), other inputs.
    cases.push((
        "another mesh".into(),
        bytes.clone(),
        Expect {
            mesh: Some(other_mesh),
            ..expect
        },
    ));
    cases.push((
        "other inputs".into(),
        bytes.clone(),
        Expect {
            key: Some(key ^ 1),
            ..expect
        },
    ));
    // Not an artifact at all.
    cases.push(("empty".into(), Vec::new(), expect));
    cases.push(("text".into(), b"hello, world\n".repeat(10), expect));

    let path = good.with_extension("corrupt");
    let mut tally = Tally::default();
    for (what, b, expect) in cases {
        std::fs::write(&path, &b).unwrap();
        tally.tried += 1;
        match artifact::load::<T>(&path, expect) {
            Err(e @ ArtifactError::Invalid { .. }) => {
                let msg = e.to_string();
                assert!(msg.contains(&path.display().to_string()), "{msg}");
                assert!(
                    msg.contains(stage.rebuild_command()),
                    "{stage}, {what}: {msg}"
                );
                tally.detected += 1;
            }
            Err(e) => tally.missed.push(format!("{what}: unexpected error {e}")),
            Ok(_) => tally.missed.push(format!("{what}: loaded")),
        }
    }
    // A missing file.
    std::fs::remove_file(&path).unwrap();
    tally.tried += 1;
    match artifact::load::<T>(&path, expect) {
        Err(e @ ArtifactError::Io { .. }) => {
            assert!(e.to_string().contains(stage.rebuild_command()), "{e}");
            // The error's whole chain says the I/O error once.
            let chain = format!("{:#}", anyhow::Error::new(e));
            assert_eq!(chain.matches("(os error").count(), 1, "{chain}");
            tally.detected += 1;
        }
        other => tally
            .missed
            .push(format!("missing file: {:?}", other.map(|_| ()))),
    }
    tally
}

#[test]
fn every_corruption_of_every_artifact_type_is_detected() {
    let cache = scratch("corruption");
    let scene = Scene::from_str(TINY, Path::new("."), "tiny.toml").unwrap();
    let mut p = Pipeline::new(&scene, &cache).unwrap();
    p.snapshot_shard(0, 2, &no_progress).unwrap();
    p.pca(&no_progress).unwrap();
    p.train(&no_progress).unwrap();
    p.cubature(&no_progress).unwrap();
    p.reference(0, &no_progress).unwrap();
    let mesh = p.mesh_hash;
    // The same scene on a box with another vertex count.
    let other_scene = Scene::from_str(
        &TINY.replace("cells = [4, 1, 1]", "cells = [5, 1, 1]"),
        Path::new("."),
        "other.toml",
    )
    .unwrap();
    let other_mesh = Pipeline::new(&other_scene, scratch("other"))
        .unwrap()
        .mesh_hash;
    assert_ne!(mesh, other_mesh);

    let mut files: Vec<PathBuf> = std::fs::read_dir(&cache)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "art"))
        .collect();
    files.sort();
    let mut seen = Vec::new();
    let mut total = Tally::default();
    for file in &files {
        let (stage, _) = stage_and_key(file);
        let tally = match stage {
            Stage::Snapshots | Stage::SnapshotsShard => {
                corrupt_and_load::<fem_core::snapshots::SnapshotSet>(file, mesh, other_mesh)
            }
            Stage::Pca => corrupt_and_load::<pca::PcaFit>(file, mesh, other_mesh),
            Stage::Train => corrupt_and_load::<TrainedModel>(file, mesh, other_mesh),
            Stage::Cubature | Stage::CubatureNeural => {
                corrupt_and_load::<FittedCubature>(file, mesh, other_mesh)
            }
            Stage::Reference => corrupt_and_load::<Reference>(file, mesh, other_mesh),
            Stage::Coverage => {
                corrupt_and_load::<latent_sim::coverage::TrainingPoses>(file, mesh, other_mesh)
            }
            other => panic!("unexpected artifact {other}"),
        };
        println!(
            "artifact {stage:<16} ({:>7} bytes): {} corrupted copies tried, {} detected",
            std::fs::metadata(file).unwrap().len(),
            tally.tried,
            tally.detected
        );
        assert!(
            tally.missed.is_empty(),
            "{stage}: undetected: {:#?}",
            tally.missed
        );
        total.tried += tally.tried;
        total.detected += tally.detected;
        seen.push(stage);
    }
    println!(
        "artifacts: {} corrupted copies tried, {} detected",
        total.tried, total.detected
    );
    for stage in [
        Stage::Snapshots,
        Stage::SnapshotsShard,
        Stage::Pca,
        Stage::Train,
        Stage::Cubature,
        Stage::Reference,
    ] {
        assert!(seen.contains(&stage), "no {stage} artifact");
    }
    assert_eq!(total.tried, total.detected);

    // The pipeline itself: a corrupted cached artifact is recomputed, not used.
    let pca_file = files
        .iter()
        .find(|f| stage_and_key(f).0 == Stage::Pca)
        .unwrap();
    let mut b = std::fs::read(pca_file).unwrap();
    let last = b.len() - 1;
    b[last] ^= 0x10;
    std::fs::write(pca_file, &b).unwrap();
    let mut again = Pipeline::new(&scene, &cache).unwrap();
    again.pca(&no_progress).unwrap();
    let outcome = again
        .outcomes
        .iter()
        .find(|o| o.stage == Stage::Pca)
        .unwrap();
    assert!(!outcome.cached, "a corrupted artifact must be recomputed");
    let (stage, key) = stage_and_key(pca_file);
    artifact::load::<pca::PcaFit>(
        pca_file,
        Expect {
            stage,
            key: Some(key),
            mesh: Some(mesh),
        },
    )
    .expect("the recomputed artifact loads");
}

#[test]
fn rebuild_commands_name_real_commands() {
    for (stage, command) in [
        (Stage::Snapshots, "cargo xtask snapshots"),
        (Stage::SnapshotsShard, "cargo xtask snapshots --shard"),
        (Stage::Pca, "cargo xtask pca"),
        (Stage::Train, "cargo xtask train"),
        (Stage::Cubature, "cargo xtask cubature"),
        (
            Stage::CubatureNeural,
            "cargo xtask run --methods neural-cubature",
        ),
        (Stage::Complement, "cargo xtask run"),
        (Stage::Reference, "cargo xtask run"),
        (Stage::Coverage, "cargo xtask export"),
    ] {
        assert!(stage.rebuild_command().starts_with(command), "{stage}");
    }
}

/// What the killed writer writes: a marker and `LEN` copies of it, so a partial value is
/// recognisable even if it decoded.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct Big {
    marker: u64,
    data: Vec<f64>,
}

const BIG_LEN: usize = 2_000_000;
const BIG_STAGE: Stage = Stage::Snapshots;
const BIG_KEY: u64 = 0x5eed;
const BIG_MESH: u64 = 0x3e54;
const CHILD_ENV: &str = "XTASK_ARTIFACT_KILL_TEST_PATH";

fn big(marker: u64, len: usize) -> Big {
    Big {
        marker,
        data: vec![marker as f64; len],
    }
}

fn big_expect() -> Expect {
    Expect {
        stage: BIG_STAGE,
        key: Some(BIG_KEY),
        mesh: Some(BIG_MESH),
    }
}

/// A whole value of the writer: every entry equal to its marker, the full length (or the
/// previous artifact's).
fn is_whole(b: &Big) -> bool {
    let len_ok = if b.marker == u64::MAX {
        b.data.len() == 10
    } else {
        b.data.len() == BIG_LEN
    };
    len_ok && b.data.iter().all(|&x| x == b.marker as f64)
}

/// The writer: only does something when re-run by `a_killed_writer_leaves_the_previous_artifact`
/// with `CHILD_ENV` set. Writes large artifacts in a loop until killed (at most 20 s).
#[test]
fn killable_writer_child() {
    let Some(path) = std::env::var_os(CHILD_ENV) else {
        return;
    };
    let path = PathBuf::from(path);
    let start = Instant::now();
    let mut marker = 0;
    while start.elapsed() < Duration::from_secs(20) {
        artifact::save(&path, BIG_STAGE, BIG_KEY, BIG_MESH, &big(marker, BIG_LEN)).unwrap();
        marker += 1;
    }
}

/// Temporary files of the atomic writes in `dir` (`.NAME.*.tmp`).
fn temp_files(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.file_name()
                        .is_some_and(|n| n.to_string_lossy().ends_with(".tmp"))
                })
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_killed_writer_leaves_the_previous_artifact() {
    let trials = 4;
    let (mut mid_write, mut kept_previous, mut temps_refused) = (0, 0, 0);
    for trial in 0..trials {
        let dir = scratch(&format!("kill-{trial}"));
        let path = dir.join("snapshots-0000000000005eed.art");
        artifact::save(&path, BIG_STAGE, BIG_KEY, BIG_MESH, &big(u64::MAX, 10)).unwrap();
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args(["killable_writer_child", "--exact", "--test-threads=1"])
            .env(CHILD_ENV, &path)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // Kill as soon as a write is under way; later trials let a few writes complete first.
        let complete_first = [0, 0, 1, 2][trial];
        let started = Instant::now();
        let mut writes_seen = 0;
        loop {
            let writing = !temp_files(&dir).is_empty();
            if writing {
                writes_seen += 1;
                if writes_seen > complete_first {
                    break;
                }
                while !temp_files(&dir).is_empty() && started.elapsed() < Duration::from_secs(10) {
                    std::thread::sleep(Duration::from_micros(100));
                }
            }
            assert!(
                started.elapsed() < Duration::from_secs(15),
                "the writer never started writing"
            );
            std::thread::sleep(Duration::from_micros(100));
        }
        child.kill().unwrap(); // SIGKILL: no destructors, no cleanup
        child.wait().unwrap();

        // The target is whole: the previous artifact or one the child finished.
        let loaded: Big = artifact::load(&path, big_expect())
            .unwrap_or_else(|e| panic!("trial {trial}: the target does not load: {e}"));
        assert!(is_whole(&loaded), "trial {trial}: a partial value loaded");
        if loaded.marker == u64::MAX {
            kept_previous += 1;
        }
        // What the kill left behind is never the target, and a partial one does not load.
        let temps = temp_files(&dir);
        if !temps.is_empty() {
            mid_write += 1;
        }
        for t in temps {
            match artifact::load::<Big>(&t, big_expect()) {
                Ok(b) => assert!(is_whole(&b), "a partial temporary file loaded"),
                Err(e) => {
                    assert!(e.to_string().contains("truncated"), "{e}");
                    temps_refused += 1;
                }
            }
        }
    }
    println!(
        "killed writers: {trials} trials, {mid_write} killed mid-write, {kept_previous} kept the previous artifact, {temps_refused} partial temporary files refused; the target loaded whole every time"
    );
    assert!(mid_write >= 1, "no kill landed during a write");
    assert!(kept_previous >= 1, "no trial kept the previous artifact");
}

/// Temporaries that killed writers left in the cache are removed when a pipeline opens it, once
/// they are older than any live write; a temporary being written now and the artifacts stay.
#[test]
fn opening_the_cache_removes_temporaries_of_killed_writers() {
    let cache = scratch("stale-temporaries");
    let stale = cache.join(".snapshots-00000000000000aa.art.4242-0-000000001.tmp");
    let fresh = cache.join(".snapshots-00000000000000aa.art.4343-0-000000002.tmp");
    let artifact = cache.join("snapshots-00000000000000aa.art");
    for p in [&stale, &fresh, &artifact] {
        std::fs::write(p, b"partial").unwrap();
    }
    let old = std::time::SystemTime::now() - 2 * pipeline::pipeline::STALE_TEMPORARY_AGE;
    std::fs::File::options()
        .write(true)
        .open(&stale)
        .unwrap()
        .set_modified(old)
        .unwrap();
    let s = Scene::from_str(TINY, Path::new("."), "tiny.toml").unwrap();
    Pipeline::new(&s, &cache).unwrap();
    assert!(!stale.exists(), "a killed writer's temporary stayed");
    assert!(fresh.exists(), "a temporary that may be in use was removed");
    assert!(artifact.exists(), "an artifact was removed");
}
