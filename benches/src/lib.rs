//! Criterion benchmarks, one group per stage, live in `benches/`; this library holds what they
//! share: where the reference meshes are, the generated test beam, and a fixed deformed state.

use std::path::PathBuf;

use fem_core::TetMesh;
use fem_core::element::Elements;
use fem_core::mesh::generate::{BoxSpec, GeneratedShape};

#[cfg(feature = "peers")]
pub mod peers;

/// The `shared/` folder beside the repository (or `$LATENT_SHARED_DIR`), if present; prints a
/// skip reason otherwise.
pub fn shared_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("LATENT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "skipping: {} not found (set LATENT_SHARED_DIR to the shared/ folder to run these benchmarks)",
            dir.display()
        );
        None
    }
}

/// `shared/meshes/<name>`, if present; prints a skip reason otherwise.
pub fn shared_mesh(name: &str) -> Option<PathBuf> {
    let path = shared_dir()?.join("meshes").join(name);
    if path.is_file() {
        Some(path)
    } else {
        eprintln!("skipping: {} not found", path.display());
        None
    }
}

/// `shared/meshes/<name>` read and validated, if present; prints a skip reason otherwise.
///
/// # Panics
///
/// When the file exists but cannot be read: a benchmark should not silently skip a broken mesh.
pub fn read_shared_mesh(name: &str) -> Option<TetMesh> {
    let path = shared_mesh(name)?;
    let (mesh, _) = fem_core::io::read_mesh(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    Some(mesh)
}

/// A 1 m × 0.1 m × 0.1 m beam of 100 × 10 × 10 = 10,000 vertices (48,114 tets).
pub fn beam_10k() -> BoxSpec {
    BoxSpec {
        kind: GeneratedShape::Box,
        size: [1.0, 0.1, 0.1],
        cells: [99, 9, 9],
        origin: [0.0; 3],
    }
}

/// A smooth, deterministic displacement field (full vector, 3 per vertex), scaled to the mesh:
/// with ξ = (X − X_min) / L and L the largest bounding-box extent,
/// u = 0.02 L (sin 3ξ_x, ξ_x cos 2ξ_y, ξ_x² / 2). Its displacement gradient stays below 0.06
/// per entry, so no element inverts, yet every element is strained (≈ 6 % at most).
pub fn smooth_displacement(mesh: &TetMesh) -> Vec<f64> {
    let (lo, hi) = mesh.bounding_box();
    let l = (hi - lo).max();
    let mut u = Vec::with_capacity(3 * mesh.num_vertices());
    for v in &mesh.vertices {
        let xi = (v - lo) / l;
        u.push(0.02 * l * (3.0 * xi.x).sin());
        u.push(0.02 * l * xi.x * (2.0 * xi.y).cos());
        u.push(0.02 * l * 0.5 * xi.x * xi.x);
    }
    u
}

/// Smallest and largest det F over all elements for the displacement `u`.
pub fn det_f_range(elements: &Elements, u: &[f64]) -> (f64, f64) {
    (0..elements.len())
        .map(|e| elements.deformation_gradient(e, u).determinant())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
            (lo.min(d), hi.max(d))
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fem_core::mesh::generate::box_mesh;

    #[test]
    fn beam_has_10k_vertices_and_the_deformation_strains_without_inverting() {
        let mesh = box_mesh(&beam_10k()).unwrap();
        assert_eq!(mesh.num_vertices(), 10_000);
        assert_eq!(mesh.num_tets(), 6 * 99 * 9 * 9);
        let elements = Elements::new(&mesh);
        let (lo, hi) = det_f_range(&elements, &smooth_displacement(&mesh));
        // u_x = 0.02 sin 3x stretches by up to 6 % near the root and compresses by up to 5.9 % at
        // the tip (cos 3 ≈ −0.99); the other terms change the volume much less.
        assert!(lo > 0.9 && lo < 0.96, "min det F = {lo}");
        assert!(hi > 1.04 && hi < 1.1, "max det F = {hi}");
    }
}
