//! Replays a script of interactions on a model file and prints the surface after every step, so
//! another driver of the same runtime (the Python module's tests) can check that it steps the
//! same trajectory.
//!
//! ```sh
//! cargo run --release -p latent-sim --example replay -- MODEL SCRIPT [--full]
//! ```
//!
//! The script has one action a line (`#` starts a comment); handles are numbered 0, 1, … in the
//! order they were grabbed:
//!
//! ```text
//! grab STIFFNESS V1 V2 …          grab mesh vertices
//! grab_near X Y Z RADIUS STIFFNESS
//! move HANDLE X Y Z
//! release HANDLE
//! gravity on|off
//! reset
//! step
//! ```
//!
//! After each `step` it prints one line: the step, the time, the solver iterations, then the
//! surface positions (x y z per surface vertex, in `Surface::vertices`' order), every number
//! in Rust's shortest form that reads back to the same `f64`. `--full` steps the model's mesh in
//! full space ([`FullRuntime`]) instead.

use latent_sim::{FullRuntime, Handle, Interactive, ReducedModel};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Prints an error as its message, not Rust's debug form of it.
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let paths: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let [model, script] = paths[..] else {
        eprintln!("usage: replay MODEL SCRIPT [--full]");
        std::process::exit(2);
    };
    let model = ReducedModel::load(model)?;
    let script = std::fs::read_to_string(script)
        .map_err(|e| format!("cannot read the script {script}: {e}"))?;
    if args.iter().any(|a| a == "--full") {
        replay(&mut FullRuntime::from_model(&model)?, &script)
    } else {
        replay(&mut model.simulator()?, &script)
    }
}

fn replay<S: Interactive>(sim: &mut S, script: &str) -> Result<()> {
    let mut handles: Vec<Handle> = Vec::new();
    let mut frame = vec![0.0f64; 3 * sim.surface().vertices().len()];
    let mut out = String::new();
    for (number, line) in script.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&action, args)) = words.split_first() else {
            continue;
        };
        let at = |e: String| format!("line {}: {e}", number + 1);
        let numbers = |n: usize| -> Result<Vec<f64>> {
            if args.len() < n {
                return Err(at(format!("{action} needs {n} numbers")).into());
            }
            Ok(args
                .iter()
                .map(|a| a.parse::<f64>())
                .collect::<std::result::Result<_, _>>()?)
        };
        let handle = |handles: &[Handle]| -> Result<Handle> {
            let i: usize = args
                .first()
                .ok_or_else(|| at("no handle".into()))?
                .parse()?;
            Ok(*handles.get(i).ok_or_else(|| at(format!("no handle {i}")))?)
        };
        match action {
            "grab" => {
                let stiffness = numbers(2)?[0];
                let vertices = args[1..]
                    .iter()
                    .map(|v| v.parse::<usize>())
                    .collect::<std::result::Result<Vec<_>, _>>()?;
                handles.push(sim.grab(&vertices, stiffness)?);
            }
            "grab_near" => {
                let v = numbers(5)?;
                handles.push(sim.grab_near([v[0], v[1], v[2]], v[3], v[4])?);
            }
            "move" => {
                let h = handle(&handles)?;
                let v = numbers(4)?;
                sim.move_handle(h, [v[1], v[2], v[3]])?;
            }
            "release" => sim.release(handle(&handles)?)?,
            "gravity" => sim.set_gravity(args.first() == Some(&"on")),
            "reset" => sim.reset(),
            "step" => {
                let s = sim.step()?;
                sim.surface_positions_into(&mut frame)?;
                out.push_str(&format!("{} {:?} {}", s.step, s.time, s.iterations));
                for x in &frame {
                    out.push_str(&format!(" {x:?}"));
                }
                out.push('\n');
            }
            other => return Err(at(format!("unknown action {other:?}")).into()),
        }
    }
    print!("{out}");
    Ok(())
}
