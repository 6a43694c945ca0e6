//! Full-space physics against the independent references in `shared/validation/beams/`
//! (scikit-fem, cross-checked by numpy and beam theory), run through the same `simulate` entry
//! point as `cargo xtask simulate`.

use std::path::Path;

use pipeline::pipeline::Pipeline;
use pipeline::scene::Scene;
use pipeline::simulate::{Method, SimulateOptions, SimulationResult, Trajectory, simulate};
use serde_json::Value;
use tests::{relative_difference, scratch_dir, shared_dir};

fn beam_scene(mesh: &Path, model: &str, g: f64, mass: &str, time: &str) -> Scene {
    let text = format!(
        r#"
name = "validation-beam"
[mesh]
path = "{}"
[material]
model = "{model}"
youngs_modulus = 1.0e8
poisson_ratio = 0.3
density = 1000.0
mass = "{mass}"
[[pin]]
plane = {{ axis = "x", side = "min", tolerance = 1.0e-9 }}
[gravity]
acceleration = [0.0, 0.0, {}]
[time]
{time}
[solver]
method = "newton"
tolerance = 1.0e-11
max_iterations = 200
"#,
        mesh.display(),
        -g
    );
    Scene::from_str(&text, Path::new("."), "validation scene").unwrap()
}

/// Runs `scene` in full space exactly as `cargo xtask simulate` does.
fn run(scene: &Scene, name: &str) -> SimulationResult {
    let out = scratch_dir(name);
    let opts = SimulateOptions {
        method: Method::Full,
        trajectory: Trajectory::Scene,
        out: out.clone(),
        frames: None,
        every: 0,
        solver: None,
    };
    let mut pipeline = Pipeline::new(scene, out.join("cache")).unwrap();
    simulate(&mut pipeline, &opts, &|_, _| {}, &mut |_, _| {}).unwrap()
}

fn vec3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    ]
}

#[test]
fn static_cantilever_tip_matches_reference_at_every_gravity_level() {
    let Some(shared) = shared_dir("the static cantilever against shared/validation/beams") else {
        return;
    };
    let beams = shared.join("validation/beams");
    let reference: Value =
        serde_json::from_str(&std::fs::read_to_string(beams.join("beam_reference.json")).unwrap())
            .unwrap();
    let meshes = reference["meshes"].as_object().unwrap();
    let mut checked = 0;
    for (name, data) in meshes {
        let mesh = beams.join(format!("{name}.mesh"));
        let p1 = &data["P1"];
        // Linear elasticity at g = 9.81.
        let lin = &p1["linear_g9.81"];
        let tip = lin["tip_centre_node"].as_u64().unwrap() as usize;
        let scene = beam_scene(
            &mesh,
            "linear",
            9.81,
            "lumped",
            "step = 1.0\nframes = 1\nquasi_static = true",
        );
        let r = run(&scene, &format!("static-linear-{name}"));
        let u = &r.final_displacement[3 * tip..3 * tip + 3];
        let rel = relative_difference(u, &vec3(&lin["tip_centre_u"]));
        println!("{name} linear: tip {u:?} relative error {rel:.2e}");
        assert!(rel < 1e-6, "{name} linear tip error {rel:.3e}");
        let energy = lin["strain_energy"].as_f64().unwrap();
        let ours = r.summary.steps.last().unwrap().elastic_energy;
        assert!((ours - energy).abs() < 1e-6 * energy, "{ours} vs {energy}");
        checked += 1;
        // Neo-Hookean at every gravity level, each solved from rest.
        for (key, case) in p1["neohookean"].as_object().unwrap() {
            let g = case["g"].as_f64().unwrap();
            let scene = beam_scene(
                &mesh,
                "neo-hookean",
                g,
                "lumped",
                "step = 1.0\nframes = 1\nquasi_static = true",
            );
            let r = run(&scene, &format!("static-nh-{name}-{key}"));
            let u = &r.final_displacement[3 * tip..3 * tip + 3];
            let rel = relative_difference(u, &vec3(&case["tip_centre_u"]));
            let last = r.summary.steps.last().unwrap();
            println!(
                "{name} neo-hookean {key}: tip {u:?} relative error {rel:.2e}, {} Newton iterations, {} load steps",
                last.iterations, last.load_steps
            );
            assert!(rel < 1e-6, "{name} {key} tip error {rel:.3e}");
            let energy = case["elastic_energy"].as_f64().unwrap();
            assert!(
                (last.elastic_energy - energy).abs() < 1e-6 * energy,
                "{} vs {energy}",
                last.elastic_energy
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 16);
}

#[test]
fn implicit_euler_trajectory_matches_reference() {
    let Some(shared) = shared_dir("the implicit Euler trajectory against shared/validation/beams")
    else {
        return;
    };
    let beams = shared.join("validation/beams");
    let reference: Value = serde_json::from_str(
        &std::fs::read_to_string(beams.join("dynamics_reference.json")).unwrap(),
    )
    .unwrap();
    let dt = reference["parameters"]["dt"].as_f64().unwrap();
    let steps = reference["parameters"]["steps"].as_u64().unwrap() as usize;
    for (key, run_ref) in reference["runs"].as_object().unwrap() {
        let mesh = beams.join(format!("{}.mesh", run_ref["mesh"].as_str().unwrap()));
        let g = run_ref["g"].as_f64().unwrap();
        let mass = run_ref["mass"].as_str().unwrap();
        let tip = run_ref["tip_centre_node"].as_u64().unwrap() as usize;
        let scene = beam_scene(
            &mesh,
            "neo-hookean",
            g,
            mass,
            &format!("step = {dt}\nframes = {steps}"),
        );
        let r = run(&scene, &format!("dynamics-{}", key.replace('|', "-")));
        let ref_steps = run_ref["steps"].as_array().unwrap();
        let mut worst: f64 = 0.0;
        for (ours, theirs) in r.summary.steps.iter().zip(ref_steps) {
            let ke = theirs["kinetic_energy"].as_f64().unwrap();
            let el = theirs["elastic_energy"].as_f64().unwrap();
            if theirs["step"].as_u64().unwrap() == 0 {
                continue;
            }
            worst = worst
                .max((ours.kinetic_energy - ke).abs() / ke.abs().max(1e-3 * el.abs()))
                .max((ours.elastic_energy - el).abs() / el.abs());
        }
        let last = &ref_steps[steps];
        let u = &r.final_displacement[3 * tip..3 * tip + 3];
        let rel = relative_difference(u, &vec3(&last["tip_centre_u"]));
        println!("{key}: final tip relative error {rel:.2e}, worst energy error {worst:.2e}");
        assert!(rel < 1e-6, "{key}: final tip error {rel:.3e}");
        assert!(worst < 1e-5, "{key}: energy error {worst:.3e}");
    }
}
