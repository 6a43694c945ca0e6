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
/// then renamed over the target, so a reader never sees a half-written file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
