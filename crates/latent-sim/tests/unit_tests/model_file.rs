//! The model file: a saved and loaded model steps bit for bit as the simulator built from the
//! stage products directly, and every damaged file is refused with the error of its damage.

use latent_sim::coverage::TrainingPoses;
use latent_sim::model::file::{HEADER_LEN, MAGIC};
use latent_sim::model::{FORMAT_VERSION, Rows, SubspaceParts};
use latent_sim::{
    AnyReducedSimulator, Augmented, Interactive, LinearSubspace, ModelFormatError, NeuralSubspace,
    ReducedModel, ReducedSimulator, ReducedSpace,
};
use proptest::prelude::*;

use super::models::{
    self, KINDS, Kind, bar, build, build_with_rule, rule, snapshot_basis, surface_rule, time,
    tip_spring,
};

/// The simulator of `kind` as the pipeline built it before models existed: the space of the
/// whole basis, the subspace, the forces in the model from the start.
fn direct(
    kind: Kind,
    m: &fem_core::integrator::FullSpaceModel,
    basis: &pca::PcaBasis,
) -> AnyReducedSimulator {
    let rule = matches!(kind, Kind::PcaCubature | Kind::NeuralCubature).then(|| rule(m));
    let space = ReducedSpace::new(m, basis, rule.as_ref()).unwrap();
    match kind {
        Kind::Pca | Kind::PcaCubature => AnyReducedSimulator::Linear(
            ReducedSimulator::new(
                m.clone(),
                space,
                LinearSubspace::new(basis.k()),
                time(1),
                models::solver(),
            )
            .unwrap(),
        ),
        Kind::Neural | Kind::NeuralCubature => {
            let sub = Augmented::with_directions(
                NeuralSubspace::new(models::autoencoder(basis.k())),
                &space,
                &time(1),
                2,
                &[],
            )
            .unwrap();
            AnyReducedSimulator::Neural(
                ReducedSimulator::new(m.clone(), space, sub, time(1), models::solver()).unwrap(),
            )
        }
    }
}

/// Steps `sim` and returns its new PCA coefficients.
fn step_q(sim: &mut AnyReducedSimulator) -> Vec<f64> {
    match sim {
        AnyReducedSimulator::Linear(s) => {
            s.step().unwrap();
            s.state.q.clone()
        }
        AnyReducedSimulator::Neural(s) => {
            s.step().unwrap();
            s.state.q.clone()
        }
    }
}

fn temp_path(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("latent-sim-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn a_saved_and_loaded_model_steps_bit_for_bit_like_the_simulator_of_its_stages() {
    let m = bar([6, 2, 2], -9.81);
    let basis = snapshot_basis(&m, 8);
    let mut forced = m.clone();
    forced.forces = vec![tip_spring(&m, [0.0, 0.1, 0.05], 0.08)];
    for kind in KINDS {
        let model = build(kind, &m, &basis, Rows::Used);
        let path = temp_path(&format!("{}.ldm", kind.name()));
        model.save(&path).unwrap();
        let loaded = ReducedModel::load(&path).unwrap();
        assert_eq!(loaded, model, "{}", kind.name());
        assert_eq!(loaded.to_bytes(), model.to_bytes(), "{}", kind.name());
        let mut reference = direct(kind, &forced, &basis);
        let mut runtime = loaded.simulator().unwrap();
        runtime.add_force(forced.forces[0].clone()).unwrap();
        for step in 1..=15 {
            let q = step_q(&mut reference);
            runtime.step().unwrap();
            let same = q
                .iter()
                .zip(runtime.coefficients())
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(
                same,
                "{}: step {step}: {q:?} vs {:?}",
                kind.name(),
                runtime.coefficients()
            );
        }
    }
}

#[test]
fn a_model_keeps_the_rows_in_use_and_the_neural_subspace_whole() {
    let m = bar([6, 2, 2], -9.81);
    let basis = snapshot_basis(&m, 8);
    let rule = surface_rule(&m, 12);
    let used = build_with_rule(Kind::NeuralCubature, &m, &basis, Rows::Used, Some(&rule));
    let all = build_with_rule(Kind::NeuralCubature, &m, &basis, Rows::All, Some(&rule));
    let surface = m.mesh.surface_vertices();
    assert_eq!(all.space.vertices.len(), m.mesh.num_vertices());
    assert!(surface.iter().all(|v| used.space.vertices.contains(v)));
    assert!(used.space.vertices.len() < all.space.vertices.len());
    assert!(used.to_bytes().len() < all.to_bytes().len());
    let SubspaceParts::Neural { directions, .. } = &used.subspace else {
        panic!("a neural model")
    };
    assert_eq!(directions.a_norms.len(), 2, "two onset directions kept");
    assert_eq!(used.latent_dim(), 5);
}

/// The surface is wound outward, and a file written before 2026-12-02, whose surface was wound
/// inward, loads with it turned outward.
#[test]
fn a_model_file_surface_faces_outward() {
    let m = bar([3, 1, 1], -9.81);
    let mut model = build(Kind::PcaCubature, &m, &snapshot_basis(&m, 4), Rows::Used);
    let volume: f64 = (0..m.mesh.num_tets())
        .map(|t| m.mesh.signed_volume(t))
        .sum();
    assert!((model.mesh.enclosed_volume(&model.surface) - volume).abs() < 1e-12);
    let outward = model.surface.clone();
    model.surface.iter_mut().for_each(|t| t.swap(0, 1));
    assert!(model.mesh.enclosed_volume(&model.surface) < 0.0);
    let loaded = ReducedModel::from_bytes(&model.to_bytes()).unwrap();
    assert!((loaded.mesh.enclosed_volume(&loaded.surface) - volume).abs() < 1e-12);
    assert!(
        loaded
            .surface
            .iter()
            .zip(&outward)
            .all(|(a, b)| (0..3).any(|r| [a[r], a[(r + 1) % 3], a[(r + 2) % 3]] == *b))
    );
}

/// A model file of the bar (PCA with cubature: small).
#[test]
fn a_model_with_its_training_ranges_says_how_far_each_step_leaves_them() {
    let m = bar([6, 2, 2], -9.81);
    let basis = snapshot_basis(&m, 8);
    let k = basis.k();
    let mut model = build(Kind::Pca, &m, &basis, Rows::Used);
    let mut rest = model.simulator().unwrap();
    assert_eq!(rest.step().unwrap().beyond_training, None);
    // Training poses that went a little way along the first two columns only.
    let mut poses = vec![0.0; 3 * k];
    poses[0] = 1e-3;
    poses[k + 1] = -1e-3;
    model.training = Some(TrainingPoses::new(k, poses));
    let loaded = ReducedModel::from_bytes(&model.to_bytes()).unwrap();
    assert_eq!(loaded, model);
    let mut sim = loaded.simulator().unwrap();
    sim.add_force(tip_spring(&m, [0.0, 0.3, 0.1], 0.2)).unwrap();
    let training = model.training.as_ref().unwrap();
    for _ in 0..5 {
        let beyond = sim.step().unwrap().beyond_training.unwrap();
        assert_eq!(beyond, training.distance(sim.coefficients()));
        assert_eq!(sim.beyond_training(), Some(beyond));
    }
    // Pulled far along every column, the pose lies mostly outside those ranges.
    assert!(
        sim.beyond_training().unwrap() > 0.5,
        "{:?}",
        sim.beyond_training()
    );
    // Ranges of another basis are refused, naming them.
    model.training = Some(TrainingPoses::new(k + 1, vec![0.0; k + 1]));
    let e = ReducedModel::from_bytes(&model.to_bytes()).unwrap_err();
    assert!(
        matches!(&e, ModelFormatError::Invalid { reason } if reason.contains("training ranges")),
        "{e}"
    );
}

fn file_bytes() -> Vec<u8> {
    let m = bar([3, 1, 1], -9.81);
    let mut model = build(Kind::PcaCubature, &m, &snapshot_basis(&m, 4), Rows::Used);
    // Training ranges, so that mutations reach their checks and the runtime's measure too.
    let k = model.space.k;
    model.training = Some(TrainingPoses::new(
        k,
        (0..2 * k).map(|i| 1e-3 * (i as f64 - k as f64)).collect(),
    ));
    model.to_bytes()
}

/// `bytes` with the header's checksum recomputed (after editing the header).
fn reseal_header(bytes: &mut [u8]) {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in &bytes[..28] {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    bytes[28..36].copy_from_slice(&h.to_le_bytes());
}

/// `payload` behind a header that announces and checksums it.
fn with_header(payload: &[u8]) -> Vec<u8> {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in payload {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    let mut bytes = MAGIC.to_vec();
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&h.to_le_bytes());
    bytes.extend_from_slice(&[0; 8]);
    reseal_header(&mut bytes);
    bytes.extend_from_slice(payload);
    bytes
}

#[test]
fn every_kind_of_damage_is_refused_with_its_own_error() {
    let bytes = file_bytes();
    assert!(ReducedModel::from_bytes(&bytes).is_ok());
    let err = |b: &[u8]| ReducedModel::from_bytes(b).unwrap_err();
    let len = bytes.len();
    // Truncation: in the magic, the version, the rest of the header, the payload, its last byte.
    for cut in [
        0,
        5,
        8,
        11,
        12,
        20,
        HEADER_LEN - 1,
        HEADER_LEN,
        HEADER_LEN + 1,
        len / 2,
        len - 1,
    ] {
        assert!(
            matches!(err(&bytes[..cut]), ModelFormatError::Truncated { .. }),
            "cut at {cut}: {}",
            err(&bytes[..cut])
        );
    }
    // Appended to.
    let mut longer = bytes.clone();
    longer.extend_from_slice(b"more");
    assert_eq!(err(&longer), ModelFormatError::TrailingBytes { extra: 4 });
    // Foreign: another tool's file, a stage artifact, text.
    for foreign in [
        &b"LATDYN\0a\x02\0\0\0"[..],
        b"{\"name\": \"cantilever\"}",
        b"\x7fELF",
    ] {
        assert_eq!(err(foreign), ModelFormatError::Foreign);
    }
    // Newer and older format versions, with an intact header.
    for (version, newer) in [(FORMAT_VERSION + 1, true), (u32::MAX, true), (0, false)] {
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&version.to_le_bytes());
        reseal_header(&mut b);
        let e = err(&b);
        let expected = if newer {
            ModelFormatError::NewerFormat {
                version,
                supported: FORMAT_VERSION,
            }
        } else {
            ModelFormatError::OlderFormat {
                version,
                supported: FORMAT_VERSION,
            }
        };
        assert_eq!(e, expected);
        assert!(e.to_string().contains(&version.to_string()), "{e}");
    }
    // A bit flipped anywhere in the header: the magic, the version, the lengths, the checksums.
    for i in 0..HEADER_LEN {
        for bit in 0..8 {
            let mut b = bytes.clone();
            b[i] ^= 1 << bit;
            let e = err(&b);
            let ok = match i {
                0..8 => e == ModelFormatError::Foreign,
                8..12 => matches!(
                    e,
                    ModelFormatError::NewerFormat { .. } | ModelFormatError::OlderFormat { .. }
                ),
                _ => e == ModelFormatError::HeaderCorrupted,
            };
            assert!(ok, "flip at byte {i} bit {bit}: {e}");
        }
    }
    // A bit flipped in the payload, at every 7th byte and every bit.
    for i in (HEADER_LEN..len).step_by(7) {
        for bit in 0..8 {
            let mut b = bytes.clone();
            b[i] ^= 1 << bit;
            assert_eq!(err(&b), ModelFormatError::PayloadCorrupted, "flip at {i}");
        }
    }
    // An intact header on a payload that is not a model, or has bytes left over.
    let payload = &bytes[HEADER_LEN..];
    assert!(matches!(
        err(&with_header(&payload[..payload.len() / 2])),
        ModelFormatError::Decode { .. }
    ));
    let mut padded = payload.to_vec();
    padded.push(0);
    assert!(matches!(
        err(&with_header(&padded)),
        ModelFormatError::Decode { .. }
    ));
    // A model that decodes but does not hold together.
    let mut model = ReducedModel::from_bytes(&bytes).unwrap();
    model.mesh.tets[0][2] = model.mesh.num_vertices();
    let e = err(&model.to_bytes());
    assert!(
        matches!(&e, ModelFormatError::Invalid { reason } if reason.contains("tet 0")),
        "{e}"
    );
    // The file's path is named when loading.
    let path = temp_path("damaged.ldm");
    std::fs::write(&path, &bytes[..len - 1]).unwrap();
    let e = ReducedModel::load(&path).unwrap_err();
    assert!(matches!(
        e.format(),
        Some(ModelFormatError::Truncated { .. })
    ));
    assert!(e.to_string().contains("damaged.ldm"), "{e}");
    // The cause is in the message, and not chained again (printed twice before).
    assert!(std::error::Error::source(&e).is_none());
    // Judged by the header and the file's length before the rest is read: a model with 64 GiB
    // appended (sparse), and a 64 GiB file that is not a model, are refused at once (the whole
    // file was read first, and ran out of memory).
    let huge = 64 << 30;
    let file = std::fs::File::create(&path).unwrap();
    std::io::Write::write_all(&mut &file, &bytes).unwrap();
    file.set_len(huge).unwrap();
    let e = ReducedModel::load(&path).unwrap_err();
    assert_eq!(
        e.format(),
        Some(&ModelFormatError::TrailingBytes {
            extra: huge - len as u64
        }),
        "{e}"
    );
    std::fs::File::create(&path).unwrap().set_len(huge).unwrap();
    let e = ReducedModel::load(&path).unwrap_err();
    assert_eq!(e.format(), Some(&ModelFormatError::Foreign), "{e}");
    std::fs::remove_file(&path).unwrap();
    // Not a regular file: refused before reading (a device or a pipe may never end).
    let dir = temp_path("a-folder.ldm");
    std::fs::create_dir_all(&dir).unwrap();
    let e = ReducedModel::load(&dir).unwrap_err();
    assert!(e.to_string().contains("not a regular file"), "{e}");
    #[cfg(unix)]
    {
        let e = ReducedModel::load(std::path::Path::new("/dev/zero")).unwrap_err();
        assert!(
            e.to_string()
                .contains("/dev/zero: cannot read: not a regular file"),
            "{e}"
        );
    }
}

/// Cases of [`mutated_files_never_panic`]: 48, or `PROPTEST_CASES` (`scripts/fuzz.sh model`
/// runs a long campaign this way where cargo-fuzz is missing).
fn mutation_cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(48)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(mutation_cases()))]

    /// Mutated files, and mutated payloads behind an intact header (reaching the decoder and
    /// the checks), never panic: they are refused, or decode into a model whose simulator is
    /// built or refused, and steps or fails, without a panic either.
    #[test]
    fn mutated_files_never_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..4), 1..6),
        behind_header in any::<bool>(),
    ) {
        let bytes = file_bytes();
        let mut data = if behind_header { bytes[HEADER_LEN..].to_vec() } else { bytes.clone() };
        for (at, value, how) in edits {
            if data.is_empty() {
                break;
            }
            let i = at.index(data.len());
            match how {
                0 => data[i] = value,
                1 => data[i] ^= 1 << (value % 8),
                2 => data.truncate(i),
                _ => data.insert(i, value),
            }
        }
        let mode = u8::from(behind_header);
        let input: Vec<u8> = std::iter::once(mode).chain(data).collect();
        super::load_check::check(&input);
    }
}

/// Writes the cargo-fuzz seeds of the `model` target (a whole file of each method's model and
/// a payload of the smallest) to `fuzz/seeds/model/`.
#[test]
#[ignore]
fn write_fuzz_seeds() {
    use std::path::PathBuf;
    let dir = std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")))
        .join("../../fuzz/seeds/model");
    std::fs::create_dir_all(&dir).unwrap();
    let m = bar([2, 1, 1], -9.81);
    let basis = snapshot_basis(&m, 3);
    for kind in KINDS {
        let file = build(kind, &m, &basis, Rows::Used).to_bytes();
        let seed: Vec<u8> = std::iter::once(0).chain(file.iter().copied()).collect();
        std::fs::write(dir.join(format!("{}.seed", kind.name())), seed).unwrap();
        if kind == Kind::Pca {
            let payload = std::iter::once(1).chain(file[HEADER_LEN..].iter().copied());
            std::fs::write(dir.join("pca-payload.seed"), payload.collect::<Vec<u8>>()).unwrap();
        }
    }
}
