//! The TetGen reader on malformed input: a pair of generated `.node` / `.ele` files with one of
//! the two mutated ends in a valid mesh or in a typed error that names the file it is about and
//! a line of that file — never a panic.

use std::path::Path;
use std::time::{Duration, Instant};

use fem_core::MeshError;
use fem_core::TetMesh;
use fem_core::io::parse_tetgen;
use fem_core::rng::SplitMix64;

use crate::mutate::{Mutation, random_mutation};
use crate::setup;
use crate::writers::box_of;

const NODE: &str = "fuzz-input.node";
const ELE: &str = "fuzz-input.ele";

/// `mesh` as TetGen writes it, numbered from `base`, with a comment, a point attribute, boundary
/// markers and region attributes when `extras`.
fn pair(mesh: &TetMesh, base: usize, extras: bool) -> (Vec<u8>, Vec<u8>) {
    use std::fmt::Write;
    let (a, m) = if extras { (1, 1) } else { (0, 0) };
    let mut node = format!("# generated\n{} 3 {a} {m}\n", mesh.num_vertices());
    for (i, p) in mesh.vertices.iter().enumerate() {
        write!(node, "{} {} {} {}", i + base, p.x, p.y, p.z).unwrap();
        node.push_str(if extras { " 2.5 1\n" } else { "\n" });
    }
    let mut ele = format!("{} 4 {m}\n", mesh.num_tets());
    for (i, t) in mesh.tets.iter().enumerate() {
        let [p, q, r, s] = t.map(|v| v + base);
        write!(ele, "{} {p} {q} {r} {s}", i + base).unwrap();
        ele.push_str(if extras { " 3\n" } else { "\n" });
    }
    (node.into_bytes(), ele.into_bytes())
}

fn lines(bytes: &[u8]) -> usize {
    1 + bytes.iter().filter(|&&b| b == b'\n').count()
}

/// `Err` describes a violation: anything but a valid mesh or a typed error about one of the two
/// files at one of its lines.
fn check(node: &[u8], ele: &[u8]) -> Result<(), String> {
    let (node_path, ele_path) = (Path::new(NODE), Path::new(ELE));
    match parse_tetgen(node, node_path, ele, ele_path) {
        Ok((mesh, _)) => {
            let n = mesh.num_vertices();
            let fine = mesh.vertices.iter().flatten().all(|c| c.is_finite())
                && mesh.tets.iter().flatten().all(|&i| i < n)
                && (0..mesh.num_tets()).all(|t| mesh.signed_volume(t) > 0.0);
            if fine {
                Ok(())
            } else {
                Err("a validated mesh is not usable".into())
            }
        }
        Err(MeshError::Parse { path, line, reason }) => {
            let within = if path == node_path {
                lines(node)
            } else if path == ele_path {
                lines(ele)
            } else {
                return Err(format!("a parse error names {}", path.display()));
            };
            if reason.trim().is_empty() || !(1..=within).contains(&line) {
                return Err(format!("parse error at line {line} of {within}: {reason}"));
            }
            Ok(())
        }
        Err(MeshError::Invalid { path, reason }) if path == ele_path => {
            for (at, _) in reason.match_indices("(line ") {
                let line = reason[at + 6..]
                    .split(')')
                    .next()
                    .and_then(|l| l.parse::<usize>().ok());
                if !line.is_some_and(|l| (1..=lines(ele)).contains(&l)) {
                    return Err(format!("validation error with a bad line: {reason}"));
                }
            }
            Ok(())
        }
        Err(e) => Err(format!("unexpected error: {e:?}")),
    }
}

#[test]
fn campaign_tetgen() {
    setup();
    let bases: Vec<(Vec<u8>, Vec<u8>)> = [[2, 1, 1], [3, 2, 1]]
        .into_iter()
        .flat_map(|cells| [(0, false), (1, true)].map(|(b, x)| pair(&box_of(cells), b, x)))
        .collect();
    for (node, ele) in &bases {
        assert_eq!(check(node, ele), Ok(()));
        assert!(parse_tetgen(node, Path::new(NODE), ele, Path::new(ELE)).is_ok());
    }
    let mut rng = SplitMix64::new(41);
    let (mut tried, mut valid) = (0, 0);
    let mut violations = Vec::new();
    let start = Instant::now();
    while tried < 1500 && start.elapsed() < Duration::from_secs(20) {
        let (node, ele) = &bases[rng.below(bases.len())];
        let mutate_node = rng.below(2) == 0;
        let edits: Vec<Mutation> = (0..1 + rng.below(3))
            .map(|_| random_mutation(&mut rng, false))
            .collect();
        let target = if mutate_node { node } else { ele };
        let mutated = edits.iter().fold(target.clone(), |b, m| m.apply(&b));
        if &mutated == target {
            continue;
        }
        tried += 1;
        let (n, e) = if mutate_node {
            (&mutated, ele)
        } else {
            (node, &mutated)
        };
        match std::panic::catch_unwind(|| check(n, e)) {
            Ok(Ok(())) => {
                if parse_tetgen(n, Path::new(NODE), e, Path::new(ELE)).is_ok() {
                    valid += 1;
                }
            }
            Ok(Err(v)) => violations.push(format!(
                "{v} (edits {edits:?} on the {})",
                if mutate_node { "node" } else { "ele" }
            )),
            Err(_) => violations.push(format!("panicked (edits {edits:?})")),
        }
    }
    println!(
        "TetGen: {tried} malformed pairs tried: {} ended in a typed error, {valid} still read as a valid mesh, {} violations",
        tried - valid - violations.len(),
        violations.len()
    );
    assert!(violations.is_empty(), "{}", violations.join("\n"));
    assert!(tried >= 100, "only {tried} inputs in the time budget");
}
