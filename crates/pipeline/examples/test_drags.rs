//! Where the test trajectories and the training schedules grab the body: for each test
//! trajectory its patch's centre and size, the spring's stiffness and its target keyframes; for
//! each training schedule its kind (by its keyframes: two for a pull or a poke, four for a drag),
//! patch, stiffness and largest offset. A test whose patch no training schedule grabbed the same
//! way is where the reduced methods have the least data (the 30k-tet figure's trajectory 0 pushes
//! its trunk just above the pinned base by up to 4 cm, where the training data has one pull).
//!
//! ```sh
//! cargo run --release -p pipeline --example test_drags -- SCENE CACHE [TRAJECTORIES]
//! ```

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!("usage: test_drags SCENE CACHE [TRAJECTORIES]");
    }
    let mut scene = Scene::from_file(PathBuf::from(&args[0]))?;
    if let Some(n) = args.get(2) {
        scene.raise_test_trajectories(n.parse().context("TRAJECTORIES")?);
    }
    let p = Pipeline::new(&scene, PathBuf::from(&args[1]))?;
    let x = &p.model.mesh.vertices;
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for v in x {
        for c in 0..3 {
            lo[c] = lo[c].min(v[c]);
            hi[c] = hi[c].max(v[c]);
        }
    }
    println!("box {lo:.3?} .. {hi:.3?}");
    for t in 0..scene.test().schedules {
        let model = p.test_model(t)?;
        for f in &model.forces {
            let n = f.vertices.len() as f64;
            let mut c = [0.0; 3];
            for &v in &f.vertices {
                for (a, ca) in c.iter_mut().enumerate() {
                    *ca += x[v][a] / n;
                }
            }
            println!(
                "test {t}: {} vertices at {c:.3?}, stiffness {:.3e}, until {:.2} s",
                f.vertices.len(),
                f.stiffness,
                f.end
            );
            for k in &f.keyframes {
                let m = (k[1] * k[1] + k[2] * k[2] + k[3] * k[3]).sqrt();
                println!("   t {:.2}: offset {:.4?} (|{m:.4}|)", k[0], &k[1..]);
            }
        }
    }
    let family = scene.training();
    let probe = fem_core::snapshots::StiffnessProbe::new(
        &p.model,
        family.frames_per_schedule as f64 * scene.time.step,
    )?;
    for i in 0..family.schedules {
        for f in family.schedule(&p.model, &probe, i, scene.time.step) {
            let n = f.vertices.len() as f64;
            let mut c = [0.0; 3];
            for &v in &f.vertices {
                for (a, ca) in c.iter_mut().enumerate() {
                    *ca += x[v][a] / n;
                }
            }
            let m = f
                .keyframes
                .iter()
                .map(|k| (k[1] * k[1] + k[2] * k[2] + k[3] * k[3]).sqrt())
                .fold(0.0, f64::max);
            println!(
                "train {i}: {} keyframes, {} vertices at {c:.3?}, stiffness {:.3e}, largest offset {m:.4}",
                f.keyframes.len(),
                f.vertices.len(),
                f.stiffness
            );
        }
    }
    Ok(())
}
