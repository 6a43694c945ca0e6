//! The `[mesh]` section of a scene: a file to read or a box to generate.

use std::path::{Path, PathBuf};

use super::generate::{BoxSpec, box_mesh};
use super::{TetMesh, ValidationReport, validate};
use crate::FemError;

/// Exactly one of `path` (relative to the scene file) and `generate`.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshConfig {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generate: Option<BoxSpec>,
}

impl MeshConfig {
    /// The mesh file this section names, resolved against `base_dir`.
    pub fn resolved_path(&self, base_dir: &Path) -> Option<PathBuf> {
        self.path.as_ref().map(|p| base_dir.join(p))
    }

    /// Appends one error per problem that shows without reading or building the mesh: not
    /// exactly one of `path` and `generate`, a file that does not exist, an invalid box.
    pub fn check(&self, base_dir: &Path, errors: &mut Vec<FemError>) {
        match (&self.path, &self.generate) {
            (Some(_), None) => {
                let path = self.resolved_path(base_dir).expect("path is set");
                if !path.is_file() {
                    errors.push(FemError::InvalidConfig {
                        field: "mesh.path".into(),
                        reason: format!("no mesh file at {}", path.display()),
                    });
                }
            }
            (None, Some(spec)) => spec.check(errors),
            _ => errors.push(FemError::InvalidConfig {
                field: "mesh".into(),
                reason: "give exactly one of `path` and `generate`".into(),
            }),
        }
    }

    /// Reads or generates the mesh and validates it.
    pub fn load(&self, base_dir: &Path) -> Result<(TetMesh, ValidationReport), FemError> {
        match (&self.path, &self.generate) {
            (Some(_), None) => {
                let path = self.resolved_path(base_dir).expect("path is set");
                Ok(crate::io::read_mesh(&path)?)
            }
            (None, Some(spec)) => {
                let mut mesh = box_mesh(spec)?;
                let report = validate(&mut mesh, Path::new("<generated box>"))?;
                Ok((mesh, report))
            }
            _ => Err(FemError::InvalidConfig {
                field: "mesh".into(),
                reason: "give exactly one of `path` and `generate`".into(),
            }),
        }
    }
}
