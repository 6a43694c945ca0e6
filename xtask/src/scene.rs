//! Scene files (TOML). Each section's struct belongs to the crate that uses it; a scene only
//! composes them. Unknown keys are errors, so a typo never goes unnoticed.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fem_core::FemError;
use fem_core::constraints::VertexSelection;
use fem_core::forces::ForceConfig;
use fem_core::integrator::{FullSpaceModel, GravityConfig, TimeConfig};
use fem_core::material::MaterialConfig;
use fem_core::mesh::{MeshConfig, ValidationReport};
use fem_core::optim::SolverConfig;
use fem_core::snapshots::{ScheduleConfig, ScheduleSection};
use pca::PcaConfig;

/// The built-in default scene, also shipped as `data/cantilever.toml`.
pub const DEFAULT_SCENE: &str = include_str!("../../data/cantilever.toml");

/// A scene: the mesh, its material and supports, the loads and how to integrate.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub name: String,
    pub mesh: MeshConfig,
    #[serde(default)]
    pub material: MaterialConfig,
    #[serde(default)]
    pub pin: Vec<VertexSelection>,
    #[serde(default)]
    pub gravity: GravityConfig,
    #[serde(default)]
    pub time: TimeConfig,
    #[serde(default)]
    pub solver: SolverConfig,
    #[serde(default)]
    pub force: Vec<ForceConfig>,
    /// Generated training schedules (stage `snapshots`).
    #[serde(default)]
    pub training: ScheduleSection,
    /// Held-out test trajectories (ground truth for errors).
    #[serde(default)]
    pub test: ScheduleSection,
    /// Dimension selection of the PCA basis (stage `pca`).
    #[serde(default)]
    pub pca: PcaConfig,
    /// Optimized cubature of the reduced elastic forces (stage `cubature`).
    #[serde(default)]
    pub cubature: cubature::CubatureConfig,
    /// The autoencoder on the PCA coefficients (stage `train`).
    #[serde(default)]
    pub autoencoder: nn::AutoencoderConfig,
    /// Folder that relative paths in the scene are resolved against.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// Where the scene came from, for messages.
    #[serde(skip)]
    pub source: String,
}

impl Scene {
    /// Reads and checks a scene file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read scene file {}", path.display()))?;
        let base = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        Self::from_str(&text, base, &path.display().to_string())
    }

    /// The built-in default scene (needs no file).
    pub fn builtin() -> Self {
        Self::from_str(
            DEFAULT_SCENE,
            &crate::project_root().join("data"),
            "<built-in cantilever>",
        )
        .expect("the built-in scene is valid")
    }

    /// Parses scene text; `source` names it in errors and `base_dir` anchors relative paths.
    pub fn from_str(text: &str, base_dir: &Path, source: &str) -> Result<Self> {
        let mut scene: Scene =
            toml::from_str(text).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
        scene.base_dir = base_dir.to_path_buf();
        scene.source = source.to_string();
        scene.check()?;
        Ok(scene)
    }

    /// Checks every section and reports all problems together.
    pub fn check(&self) -> Result<()> {
        let mut errors = Vec::new();
        if self.name.trim().is_empty() {
            errors.push(FemError::InvalidConfig {
                field: "name".into(),
                reason: "must not be empty".into(),
            });
        }
        self.material.check(&mut errors);
        self.time.check(&mut errors);
        self.solver.check(&mut errors);
        self.training().check("training", &mut errors);
        self.test().check("test", &mut errors);
        let mut cub_errors = Vec::new();
        self.cubature.check(&mut cub_errors);
        for e in cub_errors {
            errors.push(match e {
                cubature::CubatureError::InvalidConfig { field, reason } => {
                    FemError::InvalidConfig { field, reason }
                }
                other => FemError::InvalidConfig {
                    field: "cubature".into(),
                    reason: other.to_string(),
                },
            });
        }
        let mut nn_errors = Vec::new();
        self.autoencoder.check(&mut nn_errors);
        for e in nn_errors {
            errors.push(match e {
                nn::NnError::InvalidConfig { field, reason } => {
                    FemError::InvalidConfig { field, reason }
                }
                other => FemError::InvalidConfig {
                    field: "autoencoder".into(),
                    reason: other.to_string(),
                },
            });
        }
        let mut pca_errors = Vec::new();
        self.pca.check(&mut pca_errors);
        for e in pca_errors {
            errors.push(match e {
                pca::PcaError::InvalidConfig { field, reason } => {
                    FemError::InvalidConfig { field, reason }
                }
                other => FemError::InvalidConfig {
                    field: "pca".into(),
                    reason: other.to_string(),
                },
            });
        }
        if self.gravity.acceleration.iter().any(|g| !g.is_finite()) {
            errors.push(FemError::InvalidConfig {
                field: "gravity.acceleration".into(),
                reason: "must be finite".into(),
            });
        }
        match (&self.mesh.path, &self.mesh.generate) {
            (Some(_), None) | (None, Some(_)) => {}
            _ => errors.push(FemError::InvalidConfig {
                field: "mesh".into(),
                reason: "give exactly one of `path` and `generate`".into(),
            }),
        }
        if let Err(e) = FemError::collect(errors) {
            bail!("{}: invalid scene:\n{}", self.source, indent(&e));
        }
        Ok(())
    }

    /// The training schedule family, defaults filled in.
    pub fn training(&self) -> ScheduleConfig {
        self.training.resolve(ScheduleConfig::training())
    }

    /// The test schedule family, defaults filled in.
    pub fn test(&self) -> ScheduleConfig {
        self.test.resolve(ScheduleConfig::test())
    }

    /// Loads the mesh, selects pins and forces, and builds the full-space model.
    pub fn build_model(&self) -> Result<(FullSpaceModel, ValidationReport)> {
        let (mesh, report) = self
            .mesh
            .load(&self.base_dir)
            .map_err(|e| anyhow::anyhow!("{}: [mesh]: {e}", self.source))?;
        let mut errors = Vec::new();
        let mut pinned = Vec::new();
        for (i, p) in self.pin.iter().enumerate() {
            match p.select(&mesh, &format!("pin[{i}]")) {
                Ok(v) => pinned.extend(v),
                Err(e) => errors.push(e),
            }
        }
        pinned.sort_unstable();
        pinned.dedup();
        let mut forces = Vec::new();
        for (i, f) in self.force.iter().enumerate() {
            match f.resolve(&mesh, &format!("force[{i}]")) {
                Ok(f) => forces.push(f),
                Err(e) => errors.push(e),
            }
        }
        if let Err(e) = FemError::collect(errors) {
            bail!("{}: invalid scene:\n{}", self.source, indent(&e));
        }
        let model = FullSpaceModel::new(
            mesh,
            &self.material,
            pinned,
            self.gravity.acceleration.into(),
            forces,
        )
        .map_err(|e| anyhow::anyhow!("{}: {e}", self.source))?;
        Ok((model, report))
    }
}

fn indent(e: &FemError) -> String {
    match e {
        FemError::Many(list) => list
            .iter()
            .map(|e| format!("  - {e}"))
            .collect::<Vec<_>>()
            .join("\n"),
        e => format!("  - {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_scene_parses_and_builds() {
        let s = Scene::builtin();
        assert_eq!(s.name, "cantilever");
        let (model, _) = s.build_model().unwrap();
        assert!(!model.pinned.is_empty());
        assert_eq!(model.forces.len(), 1);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_named() {
        let bad = DEFAULT_SCENE.replace("poisson_ratio = 0.45", "poisson_ratio = 0.5\npoison = 1");
        let err = Scene::from_str(&bad, Path::new("."), "bad.toml").unwrap_err();
        assert!(err.to_string().contains("poison"), "{err}");
        let bad = DEFAULT_SCENE
            .replace("poisson_ratio = 0.45", "poisson_ratio = 0.5")
            .replace("step = 0.01", "step = -1.0");
        let err = Scene::from_str(&bad, Path::new("."), "bad.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("bad.toml"), "{err}");
        assert!(err.contains("material.poisson_ratio"), "{err}");
        assert!(err.contains("time.step"), "{err}");
    }

    #[test]
    fn pins_selecting_nothing_are_errors() {
        let bad = DEFAULT_SCENE.replace(
            "plane = { axis = \"x\", side = \"min\", tolerance = 1.0e-6 }",
            "sphere = { center = [9.0, 9.0, 9.0], radius = 0.1 }",
        );
        let s = Scene::from_str(&bad, Path::new("."), "bad.toml").unwrap();
        let err = s.build_model().unwrap_err().to_string();
        assert!(err.contains("pin[0]") && err.contains("no vertex"), "{err}");
    }
}
