//! Mesh readers on malformed input: every input ends in a valid mesh or in a typed error that
//! names the file, the line (text formats) and the reason — never a panic, never an allocation
//! sized by a count the file cannot back.
//!
//! - `campaign_*`: seeded structured mutations (truncation, bit flips, numbers replaced by huge,
//!   negative, non-finite or malformed ones, lines deleted, repeated or swapped) of small meshes
//!   written here in every format and of the real meshes in `shared/` when present; each prints
//!   how many malformed inputs it tried and how they ended.
//! - `props`: the same property under proptest (with shrinking to a minimal failing edit list).
//! - `binary_formats`: seeded mutations of legacy VTK `BINARY` and `.vtu` (zlib-compressed
//!   inline base64, appended raw) files, 2,000 each.
//! - `defects`: degenerate, duplicate, inverted, repeated-vertex and disconnected tets,
//!   unreferenced vertices, NaN/inf/overflowing coordinates, out-of-range indices and huge counts,
//!   written in every format and read through `read_mesh` from real files.
//!
//! The whole binary runs under an allocator capped at [`HEAP_LIMIT`]: a reader that reserves
//! memory for a declared count (up to `MAX_ENTITIES` = 5·10⁷ entries, gigabytes) before checking
//! it against the file aborts the run instead of passing unnoticed.
//!
//! Longer runs: `cargo test -p fem-core --release --test fuzz_readers -- --ignored --nocapture`
//! (`FUZZ_SECONDS` per reader, default 60); coverage-guided fuzzing: `scripts/fuzz.sh`.

mod binary_formats;
mod check;
mod mutate;
mod tetgen;
mod writers;

use std::io::Write;
use std::path::PathBuf;
use std::sync::Once;
use std::time::{Duration, Instant};

use check::{Outcome, Reader, check};
use fem_core::rng::SplitMix64;
use mutate::{Mutation, random_mutation};
use writers::Format;

#[global_allocator]
static ALLOC: cap::Cap<std::alloc::System> = cap::Cap::new(std::alloc::System, usize::MAX);

/// Live heap the whole test binary may use. The largest input here is under 1 MB; a reader that
/// trusted a count of `MAX_ENTITIES` vertices would ask for 1.2 GB at once.
const HEAP_LIMIT: usize = 768 << 20;

/// Caps the heap.
fn setup() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        ALLOC
            .set_limit(HEAP_LIMIT)
            .expect("the tests start below the heap limit");
    });
}

/// This package's folder, read when the test runs (`cargo test` sets `CARGO_MANIFEST_DIR` for
/// the test process too), so a copy of the checkout tested against the same build (`.ci/run`)
/// looks beside the copy, not beside the checkout that compiled the binary.
fn manifest_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")))
}

/// The `shared/` folder beside the repository (or `$LATENT_SHARED_DIR`): found, or where it was
/// looked for.
fn shared_dir() -> Result<PathBuf, PathBuf> {
    let dir = std::env::var_os("LATENT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest_dir().join("../../../shared"));
    if dir.is_dir() { Ok(dir) } else { Err(dir) }
}

/// Prints `skipping <reason>` as one line on the terminal, through the stderr handle itself:
/// the harness captures `eprintln!` and shows it only for failed tests.
fn skip(reason: &str) {
    let _ = writeln!(std::io::stderr(), "skipping {reason}");
}

/// Which reader takes each format.
fn reader_of(format: Format) -> Reader {
    match format {
        Format::Medit => Reader::Medit,
        Format::Gmsh22 | Format::Gmsh41Ascii | Format::Gmsh41Binary => Reader::Gmsh,
        Format::Vtk42 | Format::Vtk51 => Reader::Vtk,
    }
}

/// The reader variants counted separately: each reader, and the Gmsh reader by the kind of file
/// it starts from (2.2 and 4.1 have a parser each, 4.1 ASCII and binary share one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Variant {
    Medit,
    Gmsh22,
    Gmsh41Ascii,
    Gmsh41Binary,
    Vtk,
}

impl Variant {
    const ALL: [Variant; 5] = [
        Variant::Medit,
        Variant::Gmsh22,
        Variant::Gmsh41Ascii,
        Variant::Gmsh41Binary,
        Variant::Vtk,
    ];

    fn reader(self) -> Reader {
        match self {
            Variant::Medit => Reader::Medit,
            Variant::Gmsh22 | Variant::Gmsh41Ascii | Variant::Gmsh41Binary => Reader::Gmsh,
            Variant::Vtk => Reader::Vtk,
        }
    }

    fn label(self) -> &'static str {
        match self {
            Variant::Medit => "MEDIT",
            Variant::Gmsh22 => "Gmsh 2.2",
            Variant::Gmsh41Ascii => "Gmsh 4.1 ASCII",
            Variant::Gmsh41Binary => "Gmsh 4.1 binary",
            Variant::Vtk => "legacy VTK",
        }
    }

    /// The variant of a valid input of `reader` (Gmsh files by their `$MeshFormat` line).
    fn of(reader: Reader, bytes: &[u8]) -> Variant {
        match reader {
            Reader::Medit => Variant::Medit,
            Reader::Vtk => Variant::Vtk,
            Reader::Gmsh => {
                let head = String::from_utf8_lossy(&bytes[..bytes.len().min(100)]).into_owned();
                let fields: Vec<&str> = head
                    .lines()
                    .nth(1)
                    .unwrap_or("")
                    .split_whitespace()
                    .collect();
                match fields[..] {
                    [v, ..] if v.starts_with('2') => Variant::Gmsh22,
                    [_, "1", ..] => Variant::Gmsh41Binary,
                    _ => Variant::Gmsh41Ascii,
                }
            }
        }
    }
}

/// A named valid input.
#[derive(Debug, Clone)]
struct Base {
    name: String,
    bytes: Vec<u8>,
    variant: Variant,
}

impl Base {
    fn binary(&self) -> bool {
        self.variant == Variant::Gmsh41Binary
    }
}

/// Valid inputs of `reader` generated here: two box meshes in each of its formats, and a CRLF
/// copy of the text ones.
fn generated_bases(reader: Reader) -> Vec<Base> {
    let mut out = Vec::new();
    for format in Format::ALL.into_iter().filter(|&f| reader_of(f) == reader) {
        for cells in [[2, 1, 1], [3, 2, 1]] {
            let bytes = format.write(&writers::box_of(cells));
            let variant = Variant::of(reader, &bytes);
            let name = format!("{}-{}x{}x{}", format.name(), cells[0], cells[1], cells[2]);
            if variant != Variant::Gmsh41Binary && cells[0] == 2 {
                let crlf = String::from_utf8(bytes.clone())
                    .unwrap()
                    .replace('\n', "\r\n");
                out.push(Base {
                    name: format!("{name}-crlf"),
                    bytes: crlf.into_bytes(),
                    variant,
                });
            }
            out.push(Base {
                name,
                bytes,
                variant,
            });
        }
    }
    out
}

/// The real meshes of `shared/` that `reader` takes (empty, with a printed reason, without it).
fn shared_bases(reader: Reader) -> Vec<Base> {
    let shared = match shared_dir() {
        Ok(dir) => dir,
        Err(dir) => {
            skip(&format!(
                "the shared meshes for the {} reader (generated ones only): {} not found \
                 (set LATENT_SHARED_DIR to the shared/ folder to use them)",
                reader.name(),
                dir.display()
            ));
            return Vec::new();
        }
    };
    let ext = match reader {
        Reader::Medit => "mesh",
        Reader::Gmsh => "msh",
        Reader::Vtk => "vtk",
    };
    let mut files = Vec::new();
    for dir in ["meshes", "validation/readers", "validation/beams"] {
        if let Ok(entries) = std::fs::read_dir(shared.join(dir)) {
            files.extend(
                entries
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| p.extension().is_some_and(|e| e == ext)),
            );
        }
    }
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            Base {
                name: p.file_name().unwrap().to_string_lossy().into_owned(),
                variant: Variant::of(reader, &bytes),
                bytes,
            }
        })
        .collect()
}

/// The generated and shared inputs of `variant`.
fn bases(variant: Variant) -> (Vec<Base>, Vec<Base>) {
    let reader = variant.reader();
    let keep = |b: &Base| b.variant == variant;
    (
        generated_bases(reader).into_iter().filter(keep).collect(),
        shared_bases(reader).into_iter().filter(keep).collect(),
    )
}

/// How a campaign's inputs ended.
#[derive(Debug, Default)]
struct Tally {
    tried: usize,
    valid: usize,
    parse_errors: usize,
    invalid_meshes: usize,
    /// Panics and malformed errors, with how to reproduce them.
    violations: Vec<String>,
    slowest: Duration,
}

impl Tally {
    fn typed_errors(&self) -> usize {
        self.parse_errors + self.invalid_meshes
    }

    fn record(&mut self, reader: Reader, bytes: &[u8], describe: &dyn Fn() -> String) {
        self.tried += 1;
        let start = Instant::now();
        let result = std::panic::catch_unwind(|| check(reader, bytes));
        let elapsed = start.elapsed();
        self.slowest = self.slowest.max(elapsed);
        // Reading is linear: tens of ms for the largest file here, so a pass that rescans the
        // file per entry (seconds) stands out even on a busy machine.
        let limit = Duration::from_millis(100) + Duration::from_micros(5) * bytes.len() as u32;
        if elapsed > limit {
            let what = format!(
                "took {:.0} ms for {} bytes (limit {:.0} ms)",
                elapsed.as_secs_f64() * 1e3,
                bytes.len(),
                limit.as_secs_f64() * 1e3
            );
            self.violation(reader, bytes, &what, describe);
        }
        match result {
            Ok(Ok(Outcome::Valid)) => self.valid += 1,
            Ok(Ok(Outcome::ParseError)) => self.parse_errors += 1,
            Ok(Ok(Outcome::InvalidMesh)) => self.invalid_meshes += 1,
            Ok(Err(violation)) => self.violation(reader, bytes, &violation, describe),
            Err(_) => self.violation(reader, bytes, "panicked", describe),
        }
    }

    fn violation(
        &mut self,
        reader: Reader,
        bytes: &[u8],
        what: &str,
        describe: &dyn Fn() -> String,
    ) {
        let dir = std::env::temp_dir().join("fem-core-fuzz-failures");
        let _ = std::fs::create_dir_all(&dir);
        let file = dir.join(format!(
            "{}-{:016x}.{}",
            reader.name(),
            fnv1a(bytes),
            reader.path().extension().unwrap().to_string_lossy()
        ));
        let _ = std::fs::write(&file, bytes);
        self.violations.push(format!(
            "{what} ({}); input saved to {}",
            describe(),
            file.display()
        ));
    }

    fn report(&self, label: &str) {
        println!(
            "{label}: {} malformed inputs tried: {} ended in a typed error ({} parse errors, {} refused by validation), {} still read as a valid mesh, {} panics or malformed errors; slowest {:.1} ms",
            self.tried,
            self.typed_errors(),
            self.parse_errors,
            self.invalid_meshes,
            self.valid,
            self.violations.len(),
            self.slowest.as_secs_f64() * 1e3
        );
        assert!(
            self.violations.is_empty(),
            "{label}: {} inputs did not end in Ok or a typed error:\n{}",
            self.violations.len(),
            self.violations
                .iter()
                .take(10)
                .cloned()
                .collect::<Vec<_>>()
                .join("\n")
        );
        assert_eq!(
            self.typed_errors() + self.valid,
            self.tried,
            "{label}: every input ends in Ok or a typed error"
        );
    }
}

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Applies 1–3 random mutations to random bases until `count` inputs differ from their base
/// or `budget` runs out.
fn campaign(
    reader: Reader,
    bases: &[Base],
    count: usize,
    budget: Duration,
    seed: u64,
    tally: &mut Tally,
) {
    if bases.is_empty() {
        return;
    }
    let start = Instant::now();
    let mut rng = SplitMix64::new(seed);
    let mut case = 0u64;
    while tally.tried < count && start.elapsed() < budget {
        case += 1;
        let base = &bases[rng.below(bases.len())];
        let edits: Vec<Mutation> = (0..1 + rng.below(3))
            .map(|_| random_mutation(&mut rng, base.binary()))
            .collect();
        let bytes = edits.iter().fold(base.bytes.clone(), |b, m| m.apply(&b));
        if bytes == base.bytes {
            continue;
        }
        tally.record(reader, &bytes, &|| {
            format!(
                "base {}, seed {seed}, case {case}, edits {edits:?}",
                base.name
            )
        });
    }
}

/// The default campaign of one reader variant: a couple of thousand inputs from the generated
/// meshes, a couple of dozen from each shared mesh (20–800 kB, so each takes milliseconds).
fn default_campaign(variant: Variant, seed: u64) {
    setup();
    let reader = variant.reader();
    let (generated, shared) = bases(variant);
    for base in &generated {
        assert_eq!(
            check(reader, &base.bytes),
            Ok(Outcome::Valid),
            "{}",
            base.name
        );
    }
    let mut tally = Tally::default();
    campaign(
        reader,
        &generated,
        1500,
        Duration::from_secs(20),
        seed,
        &mut tally,
    );
    for (i, base) in shared.iter().enumerate() {
        let target = tally.tried + 25;
        campaign(
            reader,
            std::slice::from_ref(base),
            target,
            Duration::from_secs(5),
            seed + 1 + i as u64,
            &mut tally,
        );
    }
    tally.report(variant.label());
}

/// The cap is live: without it the huge-count tests could not fail.
#[test]
fn the_heap_cap_refuses_a_huge_reservation() {
    setup();
    assert!(Vec::<u8>::new().try_reserve(HEAP_LIMIT + 1).is_err());
    assert!(Vec::<u8>::new().try_reserve(1 << 20).is_ok());
}

#[test]
fn campaign_medit() {
    default_campaign(Variant::Medit, 1);
}

#[test]
fn campaign_gmsh22() {
    default_campaign(Variant::Gmsh22, 2);
}

#[test]
fn campaign_gmsh41_ascii() {
    default_campaign(Variant::Gmsh41Ascii, 3);
}

#[test]
fn campaign_gmsh41_binary() {
    default_campaign(Variant::Gmsh41Binary, 4);
}

#[test]
fn campaign_vtk() {
    default_campaign(Variant::Vtk, 5);
}

/// `FUZZ_SECONDS` (default 60) of mutations per reader variant, over the generated and shared meshes.
#[test]
#[ignore = "long: run with --ignored --nocapture"]
fn long_campaign() {
    setup();
    let seconds: u64 = std::env::var("FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let seed = std::env::var("FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(7, |d| d.as_secs())
        });
    println!("long campaign: {seconds} s per reader, FUZZ_SEED={seed}");
    for variant in Variant::ALL {
        let (mut all, shared) = bases(variant);
        all.extend(shared);
        let mut tally = Tally::default();
        campaign(
            variant.reader(),
            &all,
            usize::MAX,
            Duration::from_secs(seconds),
            seed,
            &mut tally,
        );
        tally.report(variant.label());
    }
}

mod props {
    use super::*;
    use proptest::prelude::*;

    fn mutation() -> impl Strategy<Value = Mutation> {
        let tokens = mutate::replacement_tokens();
        let words = mutate::replacement_words();
        prop_oneof![
            any::<u64>().prop_map(|per_mille| Mutation::Truncate { per_mille }),
            (any::<u64>(), 0u8..8).prop_map(|(at, bit)| Mutation::FlipBit { at, bit }),
            (any::<u64>(), any::<u8>()).prop_map(|(at, byte)| Mutation::SetByte { at, byte }),
            (any::<u64>(), prop::sample::select(tokens.clone()))
                .prop_map(|(token, with)| Mutation::ReplaceToken { token, with }),
            (any::<u64>(), prop::sample::select(tokens))
                .prop_map(|(token, with)| Mutation::ReplaceToken { token, with }),
            any::<u64>().prop_map(|line| Mutation::DeleteLine { line }),
            any::<u64>().prop_map(|line| Mutation::DuplicateLine { line }),
            (any::<u64>(), any::<u64>()).prop_map(|(a, b)| Mutation::SwapLines { a, b }),
            (any::<u64>(), any::<u64>()).prop_map(|(at, len)| Mutation::DeleteRange { at, len }),
            (any::<u64>(), "[ -~]{1,12}").prop_map(|(at, text)| Mutation::Insert { at, text }),
            (any::<u64>(), prop::sample::select(words))
                .prop_map(|(at, word)| Mutation::OverwriteWord { at, word }),
        ]
    }

    fn holds(reader: Reader, base: usize, edits: &[Mutation]) -> Result<(), TestCaseError> {
        setup();
        let bases = generated_bases(reader);
        let base = &bases[base % bases.len()];
        let bytes = edits.iter().fold(base.bytes.clone(), |b, m| m.apply(&b));
        let result = std::panic::catch_unwind(|| check(reader, &bytes));
        match result {
            Ok(Ok(_)) => Ok(()),
            Ok(Err(violation)) => Err(TestCaseError::fail(format!("{}: {violation}", base.name))),
            Err(_) => Err(TestCaseError::fail(format!("{}: panicked", base.name))),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn mutated_medit_ends_in_a_mesh_or_a_typed_error(
            base in any::<usize>(), edits in prop::collection::vec(mutation(), 1..4)
        ) {
            holds(Reader::Medit, base, &edits)?;
        }

        #[test]
        fn mutated_gmsh_ends_in_a_mesh_or_a_typed_error(
            base in any::<usize>(), edits in prop::collection::vec(mutation(), 1..4)
        ) {
            holds(Reader::Gmsh, base, &edits)?;
        }

        #[test]
        fn mutated_vtk_ends_in_a_mesh_or_a_typed_error(
            base in any::<usize>(), edits in prop::collection::vec(mutation(), 1..4)
        ) {
            holds(Reader::Vtk, base, &edits)?;
        }
    }
}

mod defects;

/// Writes the seed corpus of the cargo-fuzz targets (`fuzz/seeds/<target>/`).
#[test]
#[ignore = "writes files into fuzz/seeds"]
fn write_fuzz_seeds() {
    let root = manifest_dir().join("../../fuzz/seeds");
    for (target, formats) in fuzz_targets() {
        let dir = root.join(target);
        std::fs::create_dir_all(&dir).unwrap();
        for format in formats {
            for cells in [[1, 1, 1], [2, 1, 1]] {
                let name = format!(
                    "{}-{}x{}x{}.{}",
                    format.name(),
                    cells[0],
                    cells[1],
                    cells[2],
                    format.extension()
                );
                std::fs::write(dir.join(name), format.write(&writers::box_of(cells))).unwrap();
            }
        }
    }
}

/// The cargo-fuzz targets and the formats their seeds are written in.
fn fuzz_targets() -> [(&'static str, Vec<Format>); 4] {
    [
        ("medit", vec![Format::Medit]),
        ("gmsh_v22", vec![Format::Gmsh22]),
        ("gmsh_v41", vec![Format::Gmsh41Ascii, Format::Gmsh41Binary]),
        ("vtk", vec![Format::Vtk42, Format::Vtk51]),
    ]
}

/// The committed seeds are valid inputs of their target's reader, so fuzzing starts from files
/// that get all the way through it.
#[test]
fn fuzz_seeds_are_valid_meshes() {
    setup();
    let root = manifest_dir().join("../../fuzz/seeds");
    if !root.is_dir() {
        skip(&format!("the fuzz seeds: {} not found", root.display()));
        return;
    }
    for (target, formats) in fuzz_targets() {
        let reader = reader_of(formats[0]);
        let mut seeds = 0;
        for entry in std::fs::read_dir(root.join(target)).unwrap() {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(
                check(reader, &bytes),
                Ok(Outcome::Valid),
                "{}",
                path.display()
            );
            seeds += 1;
        }
        assert!(seeds >= 2, "{target}: {seeds} seeds");
    }
}
