//! Mesh readers (MEDIT `.mesh`, Gmsh `.msh` 2.2 ASCII and 4.1, legacy VTK) and writers
//! (VTU frames with point data `displacement`, `.pvd` series) for ParaView.

pub mod gmsh;
pub mod medit;
pub mod vtk;
pub mod vtu;

use std::path::Path;

use crate::MeshError;
use crate::mesh::{TetMesh, ValidationReport, validate};

/// Largest vertex or element count a reader accepts before allocating.
pub const MAX_ENTITIES: usize = 50_000_000;

/// Reads a tetrahedral mesh, choosing the format by extension, and validates it.
pub fn read_mesh(path: &Path) -> Result<(TetMesh, ValidationReport), MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let mut mesh = match ext.as_deref() {
        Some("mesh") => medit::read(path)?,
        Some("msh") => gmsh::read(path)?,
        Some("vtk") => vtk::read(path)?,
        _ => {
            return Err(MeshError::UnsupportedFormat {
                path: path.to_path_buf(),
            });
        }
    };
    let report = validate(&mut mesh, path)?;
    Ok((mesh, report))
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, flushed to disk,
/// then renamed over the target, so a reader never sees a half-written file and a writer killed
/// part-way leaves the previous file in place (and at worst a stray `.NAME.*.tmp`).
///
/// The temporary name is unique per process, call and time, so concurrent writers of the same
/// path (threads, or array jobs on a shared file system) never write into one temporary file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    use std::sync::atomic::{AtomicU64, Ordering};
    static CALLS: AtomicU64 = AtomicU64::new(0);

    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let tmp = dir.join(format!(
        ".{name}.{}-{}-{nanos:09}.tmp",
        std::process::id(),
        CALLS.fetch_add(1, Ordering::Relaxed)
    ));
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
