//! Where a subspace loses the test trajectory: for each reference frame u, its projection
//! û = U Uᵀ M u on the scene's PCA basis, with the relative M-norm error ‖û − u‖_M / ‖u‖_M and
//! the elastic energies V(u) and V(û). A projection close in displacement but far above in
//! energy means the subspace can hold the shape only with strain the full body does not have:
//! a Galerkin step then resists the motion.
//!
//! ```sh
//! cargo run --release -p pipeline --example energy_gap -- SCENE [CACHE]
//! ```

use std::path::PathBuf;

use anyhow::{Result, bail};
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        bail!("usage: energy_gap SCENE [CACHE]");
    };
    let scene = Scene::from_file(PathBuf::from(path))?;
    let cache = args.get(1).map(PathBuf::from).unwrap_or_else(|| {
        pipeline::project_root()
            .join("out")
            .join(&scene.name)
            .join("cache")
    });
    let mut p = Pipeline::new(&scene, &cache)?;
    let none = |_: usize, _: usize| {};
    let fit = p.pca(&none)?;
    let reference = p.reference(0, &none)?;
    let model = &p.model;
    let basis = &fit.basis;
    let (nf, n) = (model.dofs.num_free(), model.num_full());
    let mut buf = fem_core::assembly::AssemblyBuffers::default();
    let mut scratch = vec![0.0; n];
    let (mut q, mut uh) = (vec![0.0; basis.k()], vec![0.0; nf]);
    println!("frame | |u| max | rel M error | V(u) | V(proj u) | ratio");
    for (i, u) in reference.frames.iter().enumerate() {
        if i % 10 != 9 {
            continue;
        }
        basis.project(u, &mut q);
        basis.reconstruct(&q, &mut uh);
        let (mut full, mut proj) = (vec![0.0; n], vec![0.0; n]);
        model.dofs.scatter(u, &mut full);
        model.dofs.scatter(&uh, &mut proj);
        let diff: Vec<f64> = full.iter().zip(&proj).map(|(a, b)| a - b).collect();
        let rel = (model.mass.half_norm_squared(&diff, &mut scratch)
            / model.mass.half_norm_squared(&full, &mut scratch))
        .sqrt();
        let (vu, vp) = (
            model.elastic_energy(&full, &mut buf),
            model.elastic_energy(&proj, &mut buf),
        );
        let umax = full
            .chunks(3)
            .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
            .fold(0.0, f64::max);
        println!(
            "{} | {umax:.4} | {:.2} % | {vu:.4e} | {vp:.4e} | {:.2}",
            i + 1,
            100.0 * rel,
            vp / vu
        );
    }
    Ok(())
}
