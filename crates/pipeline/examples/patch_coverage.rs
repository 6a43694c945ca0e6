//! Whether the test trajectory's subspace error is the grabbed patch's local deformation: the
//! mean relative M-norm error of the reference frames projected on the scene's PCA basis, on
//! that basis extended by the static responses A⁻¹Gᵀ to a unit load on P surface patches
//! spread over the body ([`Pipeline::patch_response_columns`], which the `pca` stage appends
//! at 3 % by default), and on a PCA basis of the snapshots with as many more columns (the
//! control). Set `[pca] patch_responses = 0` in the scene to start from the snapshots' basis
//! alone.
//!
//! ```sh
//! cargo run --release -p pipeline --example patch_coverage -- SCENE CACHE [P]
//! ```

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use pca::{PcaBasis, PcaConfig};
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!("usage: patch_coverage SCENE CACHE [P]");
    }
    let scene = Scene::from_file(PathBuf::from(&args[0]))?;
    let patches: usize = match args.get(2) {
        Some(a) => a.parse().context("P")?,
        None => 48,
    };
    let mut p = Pipeline::new(&scene, PathBuf::from(&args[1]))?;
    let none = |_: usize, _: usize| {};
    let snaps = p.snapshots(&none)?;
    let fit = p.pca(&none)?;
    let reference = p.reference(0, &none)?;
    let basis = &fit.basis;
    let mass = basis.mass().context("the basis has no mass")?;
    let error = |b: &PcaBasis| -> f64 {
        let (mut q, mut uh) = (vec![0.0; b.k()], vec![0.0; b.n()]);
        let mut sum = 0.0;
        let mut count = 0;
        for u in &reference.frames {
            b.project(u, &mut q);
            b.reconstruct(&q, &mut uh);
            let (mut e, mut t) = (0.0, 0.0);
            for ((a, h), m) in u.iter().zip(&uh).zip(mass) {
                e += m * (a - h) * (a - h);
                t += m * a * a;
            }
            if t > 0.0 {
                sum += (e / t).sqrt();
                count += 1;
            }
        }
        sum / count.max(1) as f64
    };
    println!(
        "PCA basis k = {}: mean subspace error {:.4e}",
        basis.k(),
        error(basis)
    );

    // The patches the training family's pulls would grab, spread over the surface in
    // farthest-point order (`[training] patches = "spread"`), one per schedule index.
    let directions = p.patch_response_columns(patches)?;
    if directions.is_empty() {
        bail!(
            "{}: every surface vertex is pinned, no patch to load",
            args[0]
        );
    }
    for min_new in [1e-1, 3e-2, 1e-2] {
        let (extended, _) = basis.extended(&directions, min_new)?;
        let added = extended.k() - basis.k();
        let s = faer::MatRef::from_column_major_slice(&snaps.data, snaps.dim, snaps.num_frames());
        let more = PcaBasis::fit(s, Some(mass), &PcaConfig::by_dimension(extended.k()), 3)?.basis;
        println!(
            "{patches} patches, new fraction ≥ {min_new}: + {added} response columns → {:.4e}; \
             PCA with k = {} instead → {:.4e}",
            error(&extended),
            more.k(),
            error(&more)
        );
    }
    Ok(())
}
