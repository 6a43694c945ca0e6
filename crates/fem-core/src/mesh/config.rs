//! The `[mesh]` section of a scene: a file to read or a box to generate.

use std::path::{Path, PathBuf};

use super::generate::{BoxSpec, box_mesh};
use super::{TetMesh, ValidationReport, validate};
use crate::FemError;

/// Exactly one of `path` (relative to the scene file) and `generate`, and an optional `scale`.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshConfig {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generate: Option<BoxSpec>,
    /// Multiplies every coordinate as the mesh is read or generated: 0.001 for a mesh in
    /// millimetres, 0.01 in centimetres. A scene is in SI units (metres, Pa, kg/m³), so every
    /// other length in it (pin tolerances and planes, spheres) is in the scaled mesh's metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
}

/// A body whose bounding-box diagonal is outside this range (metres) is worth a warning: its
/// coordinates are likely in other units than the scene's SI ones.
pub const PLAUSIBLE_SIZE: (f64, f64) = (1e-3, 50.0);

/// What to say of a body `diagonal` metres across, when that is outside [`PLAUSIBLE_SIZE`].
pub fn size_warning(diagonal: f64) -> Option<String> {
    let (small, large) = PLAUSIBLE_SIZE;
    let hint = if diagonal > large {
        "if its coordinates are millimetres, set `[mesh] scale = 0.001` (centimetres: 0.01)"
    } else if diagonal < small {
        "if its coordinates are in larger units, set `[mesh] scale` to the metres per unit"
    } else {
        return None;
    };
    Some(format!(
        "the mesh is {diagonal:.3e} m across (its bounding box's diagonal). A scene is in SI \
         units (metres, Pa, kg/m³), so it is simulated as a body of that size: {hint}"
    ))
}

impl MeshConfig {
    /// The mesh file this section names, resolved against `base_dir`.
    pub fn resolved_path(&self, base_dir: &Path) -> Option<PathBuf> {
        self.path.as_ref().map(|p| base_dir.join(p))
    }

    /// Appends one error per problem that shows without reading or building the mesh: not
    /// exactly one of `path` and `generate`, a file that does not exist or is of a format no
    /// reader takes, an invalid box.
    pub fn check(&self, base_dir: &Path, errors: &mut Vec<FemError>) {
        match (&self.path, &self.generate) {
            (Some(given), None) => {
                let path = self.resolved_path(base_dir).expect("path is set");
                if !path.is_file() {
                    errors.push(FemError::InvalidConfig {
                        field: "mesh.path".into(),
                        reason: format!(
                            "no mesh file at {}{}",
                            path.display(),
                            if given.is_relative() {
                                " (a relative path is taken from the scene file's folder)"
                            } else {
                                ""
                            }
                        ),
                    });
                } else if let Err(e) = crate::io::check_format(&path) {
                    // Said beside the scene's other errors, not after them are mended.
                    errors.push(FemError::InvalidConfig {
                        field: "mesh.path".into(),
                        reason: e.to_string(),
                    });
                }
            }
            (None, Some(spec)) => spec.check(errors),
            _ => errors.push(FemError::InvalidConfig {
                field: "mesh".into(),
                reason: "give exactly one of `path` and `generate`".into(),
            }),
        }
        if let Err(e) = self.checked_scale() {
            errors.push(e);
        }
    }

    /// The factor `scale` multiplies coordinates by (1 when absent), or the error naming it.
    fn checked_scale(&self) -> Result<f64, FemError> {
        match self.scale {
            None => Ok(1.0),
            Some(scale) if scale.is_finite() && scale > 0.0 => Ok(scale),
            Some(scale) => Err(FemError::InvalidConfig {
                field: "mesh.scale".into(),
                reason: format!(
                    "must be a positive finite factor (0.001 for a mesh in millimetres), got \
                     {scale}"
                ),
            }),
        }
    }

    /// Reads or generates the mesh, validates it and applies `scale`.
    pub fn load(&self, base_dir: &Path) -> Result<(TetMesh, ValidationReport), FemError> {
        let scale = self.checked_scale()?;
        let (mut mesh, report) = self.load_unscaled(base_dir)?;
        // × 1 is exact: an unscaled mesh keeps its coordinates, and its cache keys, bit for bit.
        for v in &mut mesh.vertices {
            *v *= scale;
        }
        Ok((mesh, report))
    }

    fn load_unscaled(&self, base_dir: &Path) -> Result<(TetMesh, ValidationReport), FemError> {
        match (&self.path, &self.generate) {
            (Some(_), None) => {
                let path = self.resolved_path(base_dir).expect("path is set");
                Ok(crate::io::read_mesh(&path)?)
            }
            (None, Some(spec)) => {
                let mut mesh = box_mesh(spec)?;
                let report = validate(&mut mesh, Path::new("<generated mesh>"))?;
                Ok((mesh, report))
            }
            _ => Err(FemError::InvalidConfig {
                field: "mesh".into(),
                reason: "give exactly one of `path` and `generate`".into(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxed(scale: Option<f64>) -> MeshConfig {
        MeshConfig {
            generate: Some(BoxSpec {
                kind: Default::default(),
                size: [300.0, 100.0, 100.0],
                cells: [3, 1, 1],
                origin: [0.0; 3],
            }),
            scale,
            ..Default::default()
        }
    }

    #[test]
    fn scale_multiplies_every_coordinate() {
        let (plain, _) = boxed(None).load(Path::new(".")).unwrap();
        let (mm, _) = boxed(Some(0.001)).load(Path::new(".")).unwrap();
        assert_eq!(plain.tets, mm.tets);
        for (a, b) in plain.vertices.iter().zip(&mm.vertices) {
            assert!((a * 0.001 - b).norm() <= 1e-15 * a.norm().max(1.0));
        }
        let (lo, hi) = mm.bounding_box();
        assert!(((hi - lo).norm() - (0.3f64.powi(2) + 0.02).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_scale_that_is_not_a_positive_factor_is_named() {
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let mut errors = Vec::new();
            boxed(Some(bad)).check(Path::new("."), &mut errors);
            let text: Vec<String> = errors.iter().map(|e| e.to_string()).collect();
            assert_eq!(errors.len(), 1, "{bad}: {text:?}");
            assert!(text[0].contains("mesh.scale"), "{text:?}");
            assert!(boxed(Some(bad)).load(Path::new(".")).is_err());
        }
    }

    #[test]
    fn sizes_far_from_a_body_in_metres_are_warned_of() {
        let big = size_warning(331.7).unwrap();
        assert!(big.contains("`[mesh] scale = 0.001`"), "{big}");
        assert!(size_warning(2e-4).unwrap().contains("`[mesh] scale`"));
        for fine in [0.3, 1.7, 20.0] {
            assert_eq!(size_warning(fine), None, "{fine}");
        }
    }
}
