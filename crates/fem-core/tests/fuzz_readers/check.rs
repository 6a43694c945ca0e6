//! The property every mesh reader must have on any input: it ends in a valid mesh or in a typed
//! error that names the file, the line (in text files) and a reason. Shared with the cargo-fuzz
//! targets in `fuzz/`, which include this file by path.

use std::path::Path;

use fem_core::MeshError;
use fem_core::io::parse_mesh;

/// One of the mesh readers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reader {
    Medit,
    Gmsh,
    Vtk,
}

impl Reader {
    pub fn name(self) -> &'static str {
        match self {
            Reader::Medit => "medit",
            Reader::Gmsh => "gmsh",
            Reader::Vtk => "vtk",
        }
    }

    /// The file name errors should carry.
    pub fn path(self) -> &'static Path {
        Path::new(match self {
            Reader::Medit => "fuzz-input.mesh",
            Reader::Gmsh => "fuzz-input.msh",
            Reader::Vtk => "fuzz-input.vtk",
        })
    }
}

/// How a well-behaved reader ended on one input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Read and validated: a usable mesh.
    Valid,
    /// [`MeshError::Parse`] with file, line and reason.
    ParseError,
    /// Read, then refused by validation ([`MeshError::Invalid`] with file and reason).
    InvalidMesh,
}

/// Whether `bytes` is a Gmsh file whose header declares binary data (errors there carry byte
/// offsets instead of lines).
fn gmsh_binary(bytes: &[u8]) -> bool {
    let text = String::from_utf8_lossy(bytes.get(..bytes.len().min(200)).unwrap_or(bytes));
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    lines.next() == Some("$MeshFormat")
        && lines
            .next()
            .is_some_and(|l| l.split_whitespace().nth(1) == Some("1"))
}

/// Runs `reader` on `bytes`, then validation (exactly as `read_mesh` does), and checks the
/// result's shape. `Err` describes a
/// violation: anything but a valid mesh or a well-formed typed error.
pub fn check(reader: Reader, bytes: &[u8]) -> Result<Outcome, String> {
    let path = reader.path();
    let lines = 1 + bytes.iter().filter(|&&b| b == b'\n').count();
    let named = |e: &MeshError| {
        let shown = e.to_string();
        if shown.contains(&path.display().to_string()) {
            Ok(())
        } else {
            Err(format!("the message does not name the file: {shown}"))
        }
    };
    match parse_mesh(bytes, path) {
        Ok((mesh, _)) => {
            let n = mesh.num_vertices();
            if !mesh.vertices.iter().flatten().all(|c| c.is_finite()) {
                return Err("a validated mesh has a non-finite coordinate".into());
            }
            if !mesh.tets.iter().flatten().all(|&i| i < n) {
                return Err("a validated mesh has an index out of range".into());
            }
            if !(0..mesh.num_tets()).all(|t| mesh.signed_volume(t) > 0.0) {
                return Err("a validated mesh has a tet without positive volume".into());
            }
            Ok(Outcome::Valid)
        }
        Err(e @ MeshError::Invalid { .. }) => {
            named(&e)?;
            let MeshError::Invalid { path: p, reason } = &e else {
                unreachable!()
            };
            if p != path || reason.trim().is_empty() {
                return Err(format!("malformed validation error: {e:?}"));
            }
            // A refused tet's line, when given, lies in the file.
            for (at, _) in reason.match_indices("(line ") {
                let line = reason[at + 6..]
                    .split(')')
                    .next()
                    .and_then(|l| l.parse::<usize>().ok());
                if !line.is_some_and(|l| (1..=lines).contains(&l)) {
                    return Err(format!("validation error with a bad line: {e}"));
                }
            }
            Ok(Outcome::InvalidMesh)
        }
        Err(e @ MeshError::Parse { .. }) => {
            named(&e)?;
            let MeshError::Parse {
                path: p,
                line,
                reason,
            } = &e
            else {
                unreachable!()
            };
            if p != path || reason.trim().is_empty() {
                return Err(format!("malformed parse error: {e:?}"));
            }
            let binary = reader == Reader::Gmsh && gmsh_binary(bytes);
            let line_ok = if binary {
                *line <= lines
            } else {
                (1..=lines).contains(line)
            };
            if !line_ok {
                return Err(format!(
                    "parse error at line {line} of a {lines}-line {} input: {e}",
                    if binary { "binary" } else { "text" }
                ));
            }
            Ok(Outcome::ParseError)
        }
        Err(e) => Err(format!("parsing returned an unexpected error kind: {e:?}")),
    }
}
