//! Mesh readers (MEDIT `.mesh`, Gmsh `.msh` 2.2 ASCII and 4.1, legacy VTK ASCII and binary, VTK
//! XML `.vtu`, TetGen `.node` /
//! `.ele`) and writers (VTU frames with point data `displacement`, `.pvd` series) for ParaView.

pub mod gmsh;
pub mod medit;
pub mod tetgen;
pub mod vtk;
pub mod vtu;
pub mod vtu_reader;

use std::path::Path;

use crate::MeshError;
use crate::mesh::{TetMesh, ValidationReport, validate_located};

/// Largest vertex or element count a reader accepts before allocating.
pub const MAX_ENTITIES: usize = 50_000_000;

/// Reads a tetrahedral mesh, choosing the format by extension, and validates it. A tet that
/// validation refuses is named with its line in the file (text formats). A TetGen mesh is named
/// by either of its two files; both are read.
pub fn read_mesh(path: &Path) -> Result<(TetMesh, ValidationReport), MeshError> {
    let read = |path: &Path| {
        std::fs::read(path).map_err(|source| MeshError::Io {
            path: path.to_path_buf(),
            source,
        })
    };
    if let Format::TetGen = format_of(path)? {
        let (node, ele) = tetgen::pair_paths(path);
        // The file named is there and its other half is not: say what the other half is.
        let half = |other: &Path| {
            read(other).map_err(|e| match e {
                MeshError::Io { path: at, source }
                    if source.kind() == std::io::ErrorKind::NotFound && path.is_file() =>
                {
                    let reason = format!(
                        "no such file: a TetGen mesh is two files, and {} needs it beside it \
                         (TetGen writes both)",
                        path.display()
                    );
                    MeshError::Io {
                        path: at,
                        source: std::io::Error::new(source.kind(), reason),
                    }
                }
                other => other,
            })
        };
        return parse_tetgen(&half(&node)?, &node, &half(&ele)?, &ele);
    }
    parse_mesh(&read(path)?, path)
}

/// [`read_mesh`] on the content of a TetGen mesh's `.node` file (`node_path` names it in
/// errors) and `.ele` file (`ele_path`, which also names validation's errors).
pub fn parse_tetgen(
    node: &[u8],
    node_path: &Path,
    ele: &[u8],
    ele_path: &Path,
) -> Result<(TetMesh, ValidationReport), MeshError> {
    let (node, ele) = (String::from_utf8_lossy(node), String::from_utf8_lossy(ele));
    let mut mesh = tetgen::parse(&node, node_path, &ele, ele_path)?;
    let report = validate_located(&mut mesh, ele_path, &|t| tetgen::tet_line(&ele, t))?;
    Ok((mesh, report))
}

/// [`read_mesh`] on the content of a file: `path` chooses the format by its extension and names
/// the source in errors. A TetGen mesh is two files: see [`parse_tetgen`].
pub fn parse_mesh(bytes: &[u8], path: &Path) -> Result<(TetMesh, ValidationReport), MeshError> {
    let text = || String::from_utf8_lossy(bytes);
    let (mut mesh, line_of_tet): (TetMesh, Box<dyn Fn(usize) -> Option<usize>>) =
        match format_of(path)? {
            Format::Medit => (
                medit::parse(&text(), path)?,
                Box::new(move |t| medit::tet_line(&text(), t)),
            ),
            Format::Gmsh => (
                gmsh::parse_bytes(bytes, path)?,
                Box::new(|t| gmsh::tet_line(bytes, t)),
            ),
            // A binary file's lines are not the tets'.
            Format::Vtk if vtk::is_binary(bytes) => {
                (vtk::parse_bytes(bytes, path)?, Box::new(|_| None))
            }
            Format::Vtk => (
                vtk::parse(&text(), path)?,
                Box::new(move |t| vtk::tet_line(&text(), t)),
            ),
            Format::Vtu => (vtu_reader::parse(bytes, path)?, Box::new(|_| None)),
            Format::TetGen => {
                return Err(MeshError::Invalid {
                    path: path.to_path_buf(),
                    reason: "a TetGen mesh is two files, NAME.node and NAME.ele: read them \
                             together (read_mesh, parse_tetgen)"
                        .into(),
                });
            }
        };
    let report = validate_located(&mut mesh, path, &line_of_tet)?;
    Ok((mesh, report))
}

#[derive(Debug, Clone, Copy)]
enum Format {
    Medit,
    Gmsh,
    Vtk,
    Vtu,
    TetGen,
}

fn format_of(path: &Path) -> Result<Format, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("mesh") => Ok(Format::Medit),
        Some("msh") => Ok(Format::Gmsh),
        Some("vtk") => Ok(Format::Vtk),
        Some("vtu") => Ok(Format::Vtu),
        Some("node" | "ele") => Ok(Format::TetGen),
        ext => Err(MeshError::UnsupportedFormat {
            path: path.to_path_buf(),
            hint: unsupported_hint(ext),
        }),
    }
}

/// Whether [`read_mesh`] takes `path`'s format (by its extension), without reading it: the
/// error says what to do with a format it does not read (a surface mesh, say).
///
/// # Errors
/// [`MeshError::UnsupportedFormat`] with that advice.
pub fn check_format(path: &Path) -> Result<(), MeshError> {
    format_of(path).map(|_| ())
}

/// Whether [`read_mesh`] reads `path` by its extension, counting a TetGen pair once (by its
/// `.ele` file): for listing the meshes of a folder.
pub fn is_mesh_file(path: &Path) -> bool {
    let node = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("node"));
    format_of(path).is_ok() && !node
}

/// The bits of a binary number of 1 to 8 bytes in either byte order, zero-extended to 64: the
/// values and headers of binary VTK and `.vtu` files.
pub(crate) fn widened(bytes: &[u8], little_endian: bool) -> u64 {
    let mut v = [0u8; 8];
    let n = bytes.len();
    if little_endian {
        v[..n].copy_from_slice(bytes);
        u64::from_le_bytes(v)
    } else {
        v[8 - n..].copy_from_slice(bytes);
        u64::from_be_bytes(v)
    }
}

/// The `bits` of a signed integer of `size` bytes ([`widened`]), its sign carried to 64.
pub(crate) fn sign_extended(bits: u64, size: usize) -> i64 {
    // The value's top bit moved to the top, then shifted back with the sign.
    let shift = 64 - 8 * size as u32;
    ((bits << shift) as i64) >> shift
}

/// What a reader says of a file that holds other volume elements (`held`: "560 hexahedra") beside
/// its `tets` tetrahedra: read alone, the tetrahedra would be the body without those parts (a
/// tester's half-hexahedral grid was simulated half as wide, said by nothing but its unused
/// vertices).
pub(crate) fn other_volumes_problem(held: &str, tets: usize) -> String {
    format!(
        "the file holds {held} beside its {tets} tetrahedra: only tetrahedra are simulated, so \
         the body would lose those parts; mesh it with tetrahedra only (gmsh: no `Recombine`, \
         `Mesh.SubdivisionAlgorithm = 0`; TetGen and fTetWild write tetrahedra only)"
    )
}

/// Surface mesh formats, which no reader takes (the simulation needs tetrahedra).
const SURFACE_FORMATS: [&str; 6] = ["obj", "stl", "off", "ply", "poly", "smesh"];

/// Volume mesh formats no reader takes, each with its conversion in [`unsupported_hint`].
const UNREAD_VOLUME_FORMATS: [&str; 3] = ["meshb", "vtm", "pvtu"];

/// Whether `path`'s extension names a mesh format, read or not: to tell a mesh file given
/// where something else goes (a scene) from that other file.
pub fn names_a_mesh(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    format_of(path).is_ok()
        || ext.is_some_and(|e| {
            SURFACE_FORMATS.contains(&e.as_str()) || UNREAD_VOLUME_FORMATS.contains(&e.as_str())
        })
}

/// What to do with a file of extension `ext` that no reader takes.
fn unsupported_hint(ext: Option<&str>) -> String {
    const READ: &str = "this reads MEDIT .mesh, Gmsh .msh, VTK .vtk (legacy, ASCII or binary) and \
                        .vtu (XML) and TetGen .node/.ele";
    match ext {
        Some(e) if SURFACE_FORMATS.contains(&e) => format!(
            "a surface mesh: the simulation needs a tetrahedral (volume) mesh. Tetrahedralize it \
             first, e.g. `tetgen -pqg FILE` (writes FILE.1.mesh beside it; TetGen reads .off, \
             .ply, .stl, .poly and .smesh) or fTetWild (`FloatTetwild_bin -i FILE -o \
             out.msh`; it reads .obj, .off, .stl and .ply), then set [mesh] path to the result \
             ({READ})"
        ),
        Some("vtm" | "pvtu") => format!(
            "a VTK multiblock or parallel file, whose pieces are other files: merge them into \
             one .vtu (ParaView: Filters > Merge Blocks, then File > Save Data) ({READ})"
        ),
        Some("meshb") => format!(
            "binary MEDIT, which is not read: write ASCII .mesh instead (e.g. `meshio convert \
             FILE out.mesh`) ({READ})"
        ),
        _ => format!("{READ}; other formats convert with e.g. `meshio convert FILE out.msh`"),
    }
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, flushed to disk,
/// then renamed over the target, so a reader never sees a half-written file and a writer killed
/// part-way leaves the previous file in place (and at worst a stray `.NAME.*.tmp`, which
/// [`remove_stale_temporaries`] clears).
///
/// The temporary name is unique per process, call and time, so concurrent writers of the same
/// path (threads, or array jobs on a shared file system) never write into one temporary file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;

    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    // A file where a folder of the path should be: "File exists" from create_dir_all said
    // nothing of which.
    if let Some(file) = dir.ancestors().find(|a| a.is_file()) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotADirectory,
            format!("{} is a file, not a folder", file.display()),
        ));
    }
    std::fs::create_dir_all(dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let tmp = temporary_path(dir, &name);
    let result = (|| {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
        return result;
    }
    // Make the rename itself durable. Best effort: not every platform can open a directory.
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// A temporary file's path in `dir` for a file named `name`, `.NAME.PID-CALL-NANOS.tmp`:
/// unique per process, call and time, and one [`remove_stale_temporaries`] clears once its
/// writer is gone.
pub fn temporary_path(dir: &Path, name: &str) -> std::path::PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    dir.join(format!(
        ".{name}.{}-{}-{nanos:09}.tmp",
        std::process::id(),
        CALLS.fetch_add(1, Ordering::Relaxed)
    ))
}

/// Whether `name` is the name [`write_atomic`] gives its temporaries, `.NAME.PID-CALL-NANOS.tmp`
/// (NANOS nine digits): a user's own hidden `.notes.tmp` in the same folder is not one.
fn is_write_atomic_temporary(name: &str) -> bool {
    let Some(stem) = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp")) else {
        return false;
    };
    let Some((named, stamp)) = stem.rsplit_once('.') else {
        return false;
    };
    let parts: Vec<&str> = stamp.split('-').collect();
    let digits = |p: &str| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit());
    !named.is_empty()
        && matches!(parts[..], [pid, call, nanos] if digits(pid) && digits(call) && digits(nanos) && nanos.len() == 9)
}

/// Removes the temporaries of [`write_atomic`] (`.NAME.PID-CALL-NANOS.tmp`) in `dir` that were
/// last modified more than `older_than` ago: left behind by writers that were killed. A live
/// writer holds its temporary for the seconds one write takes, so an age test is safe even when
/// several processes share the folder (array jobs writing shards of one cache). Other files,
/// hidden `.tmp` files of other programs included, are left alone. Returns how many were
/// removed.
pub fn remove_stale_temporaries(
    dir: &Path,
    older_than: std::time::Duration,
) -> std::io::Result<usize> {
    let now = std::time::SystemTime::now();
    let mut removed = 0;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !(is_write_atomic_temporary(&name) && entry.file_type()?.is_file()) {
            continue;
        }
        let age = entry
            .metadata()?
            .modified()
            .ok()
            .and_then(|m| now.duration_since(m).ok());
        if age.is_some_and(|a| a > older_than) && std::fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    Ok(removed)
}

/// A fresh folder for a reader test's files, `fem-core-NAME-PID` in the system's temporary
/// folder.
#[cfg(test)]
pub(crate) fn test_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("fem-core-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[cfg(test)]
mod tests {
    use super::test_dir;

    /// A file where a folder of the path should be is named, not "File exists".
    #[test]
    fn a_file_in_the_way_of_a_folder_is_named() {
        let dir = test_dir("write-atomic");
        let file = dir.join("scene.toml");
        std::fs::write(&file, "x").unwrap();
        let err = super::write_atomic(&file.join("sub").join("a.ldm"), b"y").unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::NotADirectory);
        assert!(
            err.to_string()
                .contains("scene.toml is a file, not a folder"),
            "{err}"
        );
        super::write_atomic(&dir.join("sub").join("a.ldm"), b"y").unwrap();
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Only write_atomic's own temporaries are stale temporaries.
    #[test]
    fn stale_temporaries_are_only_write_atomic_s() {
        let dir = test_dir("stale-tmp");
        // Leave one behind as a killed writer would: its rename into a folder fails.
        std::fs::create_dir_all(dir.join("a.art")).unwrap();
        super::write_atomic(&dir.join("a.art"), b"x").unwrap_err();
        let ours: Vec<_> = std::fs::read_dir(&dir).unwrap().flatten().collect();
        assert_eq!(
            ours.len(),
            1,
            "write_atomic removes its temporary on failure"
        );
        for name in [
            ".a.art.123-0-000000042.tmp",
            ".notes.tmp",
            ".x.1-2-3.tmp",
            "a.1-2-000000003.tmp",
        ] {
            let hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
            std::fs::File::create(dir.join(name))
                .and_then(|f| f.set_modified(hour_ago))
                .unwrap();
        }
        let minute = std::time::Duration::from_secs(60);
        let removed = super::remove_stale_temporaries(&dir, minute).unwrap();
        assert_eq!(removed, 1);
        assert!(!dir.join(".a.art.123-0-000000042.tmp").exists());
        assert!(dir.join(".notes.tmp").exists() && dir.join(".x.1-2-3.tmp").exists());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A TetGen `.node` without its `.ele` says what is missing, and a missing `.node` named
    /// alone is the system's error.
    #[test]
    fn a_tetgen_half_alone_names_the_other() {
        let dir = test_dir("tetgen-half");
        let node = dir.join("part.1.node");
        std::fs::write(&node, "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n").unwrap();
        let err = super::read_mesh(&node).unwrap_err().to_string();
        assert!(err.contains("part.1.ele: no such file: a TetGen mesh is two files, and"));
        assert!(err.contains("part.1.node needs it beside it"), "{err}");
        let err = super::read_mesh(&dir.join("other.node"))
            .unwrap_err()
            .to_string();
        assert!(!err.contains("two files"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
