//! Every method on several held-out test trajectories, and a table of how its error spreads
//! over them (`cargo xtask run --trajectories N`, `cargo xtask suite --trajectories N`).
//!
//! The default test is one drag: one draw of a random patch, direction and stiffness. On a 30k-tet
//! figure its draw grabs the trunk just above the pinned base, and every reduced method ends
//! 7–9 % off where three more drags of the same family leave them at 0.6–2.4 %. A table over
//! several drags says which of the two a result is. Trajectory 0 stays the yardstick: its report
//! is where a plain `run` writes it, and the other trajectories' go beside it.

use std::path::Path;

use anyhow::{Result, bail};

use crate::pipeline::{Pipeline, Progress};
use crate::run::{MethodReport, RunOptions, run};
use crate::simulate::{Method, median};

/// The most test trajectories one call measures (`cargo xtask run --trajectories`, a scene's
/// `[test] schedules` for a plain `run`, Python's `run_trajectories`).
pub const MAX_TRAJECTORIES: usize = 64;

/// One method's error on each trajectory, and over them.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Spread {
    /// Serialised as its [`Method::name`].
    pub method: Method,
    /// The mean relative error on trajectory i, None where the method failed or did not run.
    pub errors: Vec<Option<f64>>,
    /// The mean of `errors`, None unless every trajectory has one.
    pub mean: Option<f64>,
    /// The largest error and its trajectory, over those with one.
    pub worst: Option<(usize, f64)>,
    /// The median of the method's speed-ups over the trajectories it completed.
    pub median_speedup: Option<f64>,
}

/// The spread of every method of `runs[0]` over `runs` (trajectory i's rows at index i).
pub fn spreads(runs: &[Vec<MethodReport>]) -> Vec<Spread> {
    let Some(first) = runs.first() else {
        return Vec::new();
    };
    first
        .iter()
        .map(|row| {
            let completed: Vec<Option<&MethodReport>> = runs
                .iter()
                .map(|rows| {
                    rows.iter()
                        .find(|r| r.method == row.method && r.failure.is_none())
                })
                .collect();
            let errors: Vec<Option<f64>> = completed
                .iter()
                .map(|r| r.map(|r| r.mean_rel_error))
                .collect();
            let mean = errors
                .iter()
                .copied()
                .sum::<Option<f64>>()
                .map(|s| s / errors.len() as f64);
            let worst = errors
                .iter()
                .enumerate()
                .filter_map(|(i, e)| e.map(|e| (i, e)))
                .max_by(|a, b| a.1.total_cmp(&b.1));
            let speedups: Vec<f64> = completed
                .iter()
                .flatten()
                .filter_map(|r| r.speedup)
                .collect();
            let median_speedup = (!speedups.is_empty()).then(|| median(&speedups));
            Spread {
                method: row.method,
                errors,
                mean,
                worst,
                median_speedup,
            }
        })
        .collect()
}

/// The folder of trajectory `i`'s report under `out`: `out` itself for trajectory 0 (where a
/// plain `run` writes it), `out/trajectory-i` for the others.
pub fn trajectory_dir(out: &Path, i: usize) -> std::path::PathBuf {
    if i == 0 {
        out.to_path_buf()
    } else {
        out.join(format!("trajectory-{i}"))
    }
}

/// Runs `opts.methods` on test trajectories 0..`count` ([`run`] for each, its report in
/// [`trajectory_dir`]), writes `trajectories.md` and `trajectories.json` to `opts.out`, and
/// returns every trajectory's rows (`opts.trajectory` is not used). `on_trajectory` is called
/// with the trajectory before each.
///
/// # Errors
/// When `count` is 0, or as [`run`]; the table then holds the trajectories before the one
/// that failed.
pub fn run_trajectories(
    pipeline: &mut Pipeline<'_>,
    opts: &RunOptions,
    count: usize,
    stage_progress: Progress<'_>,
    on_trajectory: &mut dyn FnMut(usize),
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<Vec<Vec<MethodReport>>> {
    if count == 0 {
        bail!(
            "{}: 0 test trajectories asked for; at least 1",
            pipeline.scene.source
        );
    }
    let mut runs = Vec::with_capacity(count);
    let outcome = run_more(
        pipeline,
        opts,
        &mut runs,
        count,
        stage_progress,
        on_trajectory,
        progress,
    );
    if !runs.is_empty() {
        write(&opts.out, &runs)?;
    }
    outcome.map(|()| runs)
}

/// Writes the table of `runs` (trajectory i's rows at index i) to `out/trajectories.md`, with
/// each trajectory's warnings under it ([`warnings`]), and to `out/trajectories.json`.
///
/// # Errors
/// When a file cannot be written.
pub fn write(out: &Path, runs: &[Vec<MethodReport>]) -> Result<()> {
    let table = spreads(runs);
    let text = markdown(&table) + &warnings(runs, 0);
    crate::output::write_file(&out.join("trajectories.md"), text.as_bytes())?;
    crate::output::write_file(
        &out.join("trajectories.json"),
        serde_json::to_string_pretty(&table)?.as_bytes(),
    )?;
    Ok(())
}

/// Runs `opts.methods` on test trajectories `runs.len()`..`count`, each one's report in
/// [`trajectory_dir`], appending its rows to `runs`.
///
/// # Errors
/// As [`run`]; `runs` then holds the trajectories before the one that failed.
pub fn run_more(
    pipeline: &mut Pipeline<'_>,
    opts: &RunOptions,
    runs: &mut Vec<Vec<MethodReport>>,
    count: usize,
    stage_progress: Progress<'_>,
    on_trajectory: &mut dyn FnMut(usize),
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<()> {
    for i in runs.len()..count {
        on_trajectory(i);
        let o = RunOptions {
            out: trajectory_dir(&opts.out, i),
            trajectory: i,
            ..opts.clone()
        };
        runs.push(run(pipeline, &o, stage_progress, progress)?);
    }
    Ok(())
}

/// The warnings and caveats of [`crate::trust::assess`] for trajectories `from`.. of `runs`,
/// each headed by its trajectory (empty where a run has none). The buckling of the scene's
/// gravity, what building the model warned of and how a step's time compares with full space,
/// the same for every trajectory, are said with trajectory 0's only.
pub fn warnings(runs: &[Vec<MethodReport>], from: usize) -> String {
    runs.iter()
        .enumerate()
        .skip(from)
        .map(|(i, rows)| {
            let mut rows = rows.clone();
            if i > 0 {
                rows.iter_mut().for_each(|r| {
                    r.buckling = None;
                    r.scene_warnings.clear();
                    r.basis_cap = None;
                    // How a step's time compares with full space is trajectory 0's to say.
                    r.speedup = None;
                });
            }
            crate::trust::assess(&rows).text(&format!("trajectory {i}, "))
        })
        .collect()
}

/// The table: per method, its error on each trajectory, their mean, the worst and the median
/// speed-up (full-space rows, whose error is zero by definition, left out).
pub fn markdown(table: &[Spread]) -> String {
    let count = table.first().map_or(0, |s| s.errors.len());
    let mut s = String::from("| method |");
    for i in 0..count {
        s += &format!(" trajectory {i} |");
    }
    s += " mean | worst | median speed-up |\n|---|";
    s += &"---:|".repeat(count + 3);
    s += "\n";
    let percent = |e: Option<f64>| e.map_or("—".into(), |e| format!("{:.2} %", 100.0 * e));
    for m in table.iter().filter(|m| !m.method.is_full()) {
        s += &format!("| {} |", m.method);
        for &e in &m.errors {
            s += &format!(" {} |", percent(e));
        }
        let worst = m
            .worst
            .map_or("—".into(), |(i, e)| format!("{:.2} % ({i})", 100.0 * e));
        let speedup = crate::run::speedup_cell(m.median_speedup, 0);
        s += &format!(" {} | {worst} | {speedup} |\n", percent(m.mean));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: Method, error: f64, speedup: f64) -> MethodReport {
        MethodReport {
            method,
            mean_rel_error: error,
            speedup: Some(speedup),
            ..Default::default()
        }
    }

    /// Errors per trajectory in order, the mean only where every trajectory has one, the worst
    /// with its index, the median speed-up of the completed runs; a failed run is a gap.
    #[test]
    fn spreads_follow_the_rows() {
        let failed = MethodReport {
            failure: Some("frame 4".into()),
            ..row(Method::NeuralCubature, 0.5, 900.0)
        };
        let runs = vec![
            vec![
                row(Method::Pca, 0.08, 4.0),
                row(Method::NeuralCubature, 0.09, 200.0),
            ],
            vec![row(Method::Pca, 0.01, 5.0), failed],
            vec![
                row(Method::Pca, 0.02, 6.0),
                row(Method::NeuralCubature, 0.03, 220.0),
            ],
            vec![
                row(Method::Pca, 0.03, 3.0),
                row(Method::NeuralCubature, 0.01, 180.0),
            ],
        ];
        let t = spreads(&runs);
        assert_eq!(t.len(), 2);
        assert_eq!(
            t[0].errors,
            [Some(0.08), Some(0.01), Some(0.02), Some(0.03)]
        );
        assert!((t[0].mean.unwrap() - 0.035).abs() < 1e-15);
        assert_eq!(t[0].worst, Some((0, 0.08)));
        assert_eq!(t[0].median_speedup, Some(4.5));
        assert_eq!(t[1].errors, [Some(0.09), None, Some(0.03), Some(0.01)]);
        assert_eq!(t[1].mean, None);
        assert_eq!(t[1].worst, Some((0, 0.09)));
        assert_eq!(t[1].median_speedup, Some(200.0));
        let md = markdown(&t);
        assert!(
            md.contains("| pca | 8.00 % | 1.00 % | 2.00 % | 3.00 % | 3.50 % | 8.00 % (0) | 4.5× |"),
            "{md}"
        );
        assert!(
            md.contains(
                "| neural-cubature | 9.00 % | — | 3.00 % | 1.00 % | — | 9.00 % (0) | 200× |"
            ),
            "{md}"
        );
        assert!(spreads(&[]).is_empty());
    }

    /// Each trajectory's warnings under its own heading, from the trajectory asked for on.
    #[test]
    fn warnings_name_their_trajectory() {
        let runs = vec![
            vec![row(Method::Pca, 0.01, 4.0)],
            vec![row(Method::Pca, 0.6, 4.0)],
            vec![row(Method::Pca, 0.02, 4.0)],
        ];
        let all = warnings(&runs, 0);
        assert!(all.contains("trajectory 1, not to be trusted:"), "{all}");
        assert!(
            !all.contains("trajectory 0,") && !all.contains("trajectory 2,"),
            "{all}"
        );
        assert_eq!(warnings(&runs, 2), "");
        // What the scene warns of, the same for every trajectory, is said with trajectory 0's.
        let said = MethodReport {
            scene_warnings: vec!["the pins hold the body at a single vertex".into()],
            ..row(Method::Pca, 0.01, 4.0)
        };
        let all = warnings(&[vec![said.clone()], vec![said]], 0);
        assert_eq!(all.matches("single vertex").count(), 1, "{all}");
        assert!(all.contains("trajectory 0, not to be trusted:"), "{all}");
    }

    #[test]
    fn trajectory_zero_is_where_run_writes() {
        let out = Path::new("out/x");
        assert_eq!(trajectory_dir(out, 0), out);
        assert_eq!(trajectory_dir(out, 2), out.join("trajectory-2"));
    }
}
