//! Where the PCA basis misses the test's strain energy. For chosen frames of test trajectory 0,
//! the reference displacement u is projected on the scene's basis (Pu = UUᵀMu), and each
//! element's energy of the error is taken to second order: ψ_e(Pu) − ψ_e(u) − ∇ψ_e(u)·(Pu − u).
//! The example prints the error's share of the frame's elastic energy, and how it splits by
//! distance from the pinned vertices and from the test spring's patch. It also prints the share
//! the top 1 % of elements hold.
//!
//! A basis can hold a frame's displacement to a few percent in the mass norm and still miss half
//! of its strain energy, concentrated in a few elements. The Galerkin step answers in the energy's
//! norm, so such a basis moves the body less than the full step does (the 30k-tet figure's
//! default drag, docs/results-suite.md, stop 52).
//!
//! ```sh
//! cargo run --release -p pipeline --example projection_energy -- SCENE CACHE FRAME [FRAME ...]
//! ```

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use fem_core::Vec3;
use fem_core::material::Material;
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

/// Distance bands (fractions of the bounding-box diagonal) for the split.
const BANDS: [f64; 3] = [0.02, 0.06, 0.15];

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        bail!("usage: projection_energy SCENE CACHE FRAME [FRAME ...] (frames from 1)");
    }
    let scene = Scene::from_file(PathBuf::from(&args[0]))?;
    let mut p = Pipeline::new(&scene, PathBuf::from(&args[1]))?;
    let quiet = |_: usize, _: usize| {};
    let fit = p.pca(&quiet)?;
    let reference = p.reference(0, &quiet)?;
    let model = p.test_model(0)?;
    let (basis, elements, mesh) = (&fit.basis, &model.elements, &model.mesh);
    let (lo, hi) = mesh.bounding_box();
    let diagonal = (hi - lo).norm();
    let patch = model
        .forces
        .first()
        .map(|f| f.vertices.clone())
        .unwrap_or_default();
    let centre_of = |vertices: &[usize]| {
        vertices
            .iter()
            .fold(Vec3::zeros(), |s, &v| s + mesh.vertices[v])
            / vertices.len().max(1) as f64
    };
    let patch_centre = centre_of(&patch);
    // Each element's centroid, its band from the pins and from the patch.
    let band = |d: f64| {
        BANDS
            .iter()
            .position(|&b| d <= b * diagonal)
            .unwrap_or(BANDS.len())
    };
    let places: Vec<(usize, usize)> = elements
        .tets
        .iter()
        .map(|t| {
            let c = centre_of(t);
            let to_pins = model
                .pinned
                .iter()
                .map(|&v| (mesh.vertices[v] - c).norm())
                .fold(f64::INFINITY, f64::min);
            (band(to_pins), band((c - patch_centre).norm()))
        })
        .collect();
    println!(
        "{}: {} elements, k = {}, the test's patch of {} vertices; bands of {:?} × the diagonal \
         ({diagonal:.3} m), then the rest",
        scene.name,
        elements.len(),
        basis.k(),
        patch.len(),
        BANDS
    );
    for arg in &args[2..] {
        let frame: usize = arg.parse().with_context(|| format!("FRAME {arg:?}"))?;
        if frame == 0 || frame > reference.frames.len() {
            bail!(
                "frame {frame}: the reference has frames 1..={}",
                reference.frames.len()
            );
        }
        let u = &reference.frames[frame - 1];
        let mut q = vec![0.0; basis.k()];
        basis.project(u, &mut q);
        let mut pu = vec![0.0; u.len()];
        basis.reconstruct(&q, &mut pu);
        let n = model.num_full();
        let (mut full_u, mut full_pu) = (vec![0.0; n], vec![0.0; n]);
        model.dofs.scatter(u, &mut full_u);
        model.dofs.scatter(&pu, &mut full_pu);
        let mut remainders = vec![0.0; elements.len()];
        let mut energy = 0.0;
        fem_core::with_material!(model.material, |m| {
            for (e, r) in remainders.iter_mut().enumerate() {
                let (psi, gradient, _) = elements.energy_gradient(&m, e, &full_u, 1.0);
                let psi_pu =
                    elements.volume[e] * m.psi(&elements.deformation_gradient(e, &full_pu));
                let t = &elements.tets[e];
                let linear: f64 = (0..12)
                    .map(|i| {
                        gradient[i] * (full_pu[3 * t[i / 3] + i % 3] - full_u[3 * t[i / 3] + i % 3])
                    })
                    .sum();
                *r = psi_pu - psi - linear;
                energy += psi;
            }
        });
        let total: f64 = remainders.iter().sum();
        let (mut by_pins, mut by_patch) = ([0.0; BANDS.len() + 1], [0.0; BANDS.len() + 1]);
        for (r, &(pins, near)) in remainders.iter().zip(&places) {
            by_pins[pins] += r;
            by_patch[near] += r;
        }
        let mut sorted = remainders.clone();
        sorted.sort_by(|a, b| b.total_cmp(a));
        let top: f64 = sorted[..sorted.len().div_ceil(100)].iter().sum();
        let (error, size) = u.iter().zip(&pu).fold((0.0, 0.0), |(e, s), (a, b)| {
            (e + (a - b) * (a - b), s + a * a)
        });
        let shares = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{:.0} %", 100.0 * x / total))
                .collect::<Vec<_>>()
                .join(", ")
        };
        println!(
            "frame {frame}: |u − Pu| / |u| {:.2} %; the error's energy {:.3e} J, {:.1} % of the \
             frame's {energy:.3e} J; from the pins {}; from the patch {}; the top 1 % of \
             elements {:.0} %",
            100.0 * (error / size).sqrt(),
            total,
            100.0 * total / energy,
            shares(&by_pins),
            shares(&by_patch),
            100.0 * top / total
        );
    }
    Ok(())
}
