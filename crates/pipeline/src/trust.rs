//! When a run's result is not to be trusted: plain warnings from a run's report rows, each
//! naming the method, what was measured and what to change.

use crate::coverage::OUTSIDE_TRAINING;
use crate::run::MethodReport;

/// A reduced method whose trajectory is further than this from the full one (mean M-norm
/// relative error) is not a usable stand-in for it.
pub const UNTRUSTED_ERROR: f64 = 0.2;

/// A subspace whose best representation of the test trajectory is further than this from it
/// does not hold the test's motion: the training data missed it. Warned of only when the
/// method's own error is that large too: the displacement a reduced method reports adds the
/// dents its springs make outside the subspace, so it can be closer to the full trajectory than
/// the subspace is (AutoDef's bar: 3.7 % subspace error, `pca` 1.5 %).
pub const UNCOVERED_SUBSPACE_ERROR: f64 = 0.05;

/// Whether a reduced method drifts from the full trajectory: more than
/// [`UNCOVERED_SUBSPACE_ERROR`] off while its subspace holds the test four times better. Then
/// `run` measures how much the full trajectory itself amplifies a small error
/// ([`crate::run::sensitivity`]), which [`assess`] reports.
pub fn drifts(rows: &[MethodReport]) -> bool {
    rows.iter().any(|r| {
        !r.method.is_full()
            && r.mean_rel_error > UNCOVERED_SUBSPACE_ERROR
            && r.subspace_error <= r.mean_rel_error / 4.0
    })
}

/// A full trajectory that turns an error into twice as much or more by its end amplifies
/// errors.
pub const AMPLIFYING: f64 = 2.0;

/// What the full row's sensitivity says of the drifting methods.
fn sensitivity_warning(rows: &[MethodReport]) -> Option<String> {
    let s = rows.iter().find_map(|r| r.sensitivity)?;
    let pct = |x: f64| 100.0 * x;
    let changed = format!(
        "the full trajectory with its state changed by {:.0} % at t = {:.2} s ends {:.1} % from \
         the unchanged one ({:.1} % on average from then on)",
        pct(s.change),
        s.time,
        pct(s.last_error),
        pct(s.mean_error)
    );
    let steps: Vec<f64> = (rows.iter())
        .filter(|r| !r.method.is_full() && r.failure.is_none() && r.step_error > 0.0)
        .map(|r| r.step_error)
        .collect();
    let steps = match (
        steps.iter().copied().reduce(f64::min),
        steps.iter().copied().reduce(f64::max),
    ) {
        (Some(lo), Some(hi)) => format!("{:.1}–{:.1} %", pct(lo), pct(hi)),
        _ => "some".to_string(),
    };
    Some(if s.last_error >= AMPLIFYING * s.change {
        format!(
            "the test amplifies errors: {changed}. The reduced steps are each {steps} off (one-step \
             error), so every method drifts further than its subspace error says, and the \
             trajectory errors compare how each is perturbed more than how good it is: compare \
             the one-step errors, or test a gentler pull (`[test] stiffness`, `offset`)"
        )
    } else {
        format!(
            "the test does not amplify errors ({changed}): the drift comes from the reduced \
             steps themselves, each {steps} off (one-step error)"
        )
    })
}

/// What a run's figures say of its reduced methods, in row order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Assessment {
    /// Figures not to be trusted: a method that stopped, a subspace that misses the test, a
    /// trajectory over [`UNTRUSTED_ERROR`] off, one that left the training poses and ended over
    /// [`UNCOVERED_SUBSPACE_ERROR`] off, and what the test's own sensitivity says of them.
    pub untrusted: Vec<String>,
    /// Figures that held but may not hold elsewhere: a trajectory that left the training poses
    /// and still ended within [`UNCOVERED_SUBSPACE_ERROR`] of the full one.
    pub caveats: Vec<String>,
}

impl Assessment {
    /// The two lists as the text `run` and `suite` print under `heading` (e.g. a scene's name
    /// and a colon, or nothing): "not to be trusted" first; empty when both are.
    pub fn text(&self, heading: &str) -> String {
        let mut s = String::new();
        for (title, list) in [
            ("not to be trusted", &self.untrusted),
            ("held on this test, may not on others", &self.caveats),
        ] {
            if !list.is_empty() {
                s.push_str(&format!("\n{heading}{title}:\n"));
                for w in list {
                    s.push_str(&format!("- {w}\n"));
                }
            }
        }
        s
    }
}

/// Warnings and caveats for the reduced methods of a run; both empty when every method is
/// within [`UNTRUSTED_ERROR`], its subspace or its error within [`UNCOVERED_SUBSPACE_ERROR`] and
/// its trajectory within [`OUTSIDE_TRAINING`] of the training poses.
pub fn assess(rows: &[MethodReport]) -> Assessment {
    let mut out = Vec::new();
    let mut caveats = Vec::new();
    for r in rows.iter().filter(|r| !r.method.is_full()) {
        let pct = |x: f64| 100.0 * x;
        if let Some(f) = &r.failure {
            out.push(format!(
                "{}: stopped before the last frame ({f}); its figures cover the frames before",
                r.method
            ));
        }
        if r.subspace_error > UNCOVERED_SUBSPACE_ERROR
            && r.mean_rel_error > UNCOVERED_SUBSPACE_ERROR
        {
            out.push(format!(
                "{}: its subspace alone is {:.1} % from the test trajectory, so the training \
                 data does not cover the test's motion: add schedules or the test's kinds \
                 (`[training] schedules`, `kinds`), or keep more PCA coefficients (`[pca]`)",
                r.method,
                pct(r.subspace_error)
            ));
        }
        if r.training_distance > OUTSIDE_TRAINING {
            // A time no schedule reached: a body that keeps moving under gravity (sagging,
            // toppling) goes where the shorter schedules never took it.
            let what = if r.training_seconds > 0.0
                && r.training_distance_time > r.training_seconds + 1e-9
            {
                format!(
                    "later than any training schedule lasts ({:.2} s): longer schedules \
                     (`[training] frames_per_schedule`, at least the test's frames) reach such \
                     times",
                    r.training_seconds
                )
            } else {
                "add training schedules that reach such poses (`[training] schedules`, \
                 `kinds`, larger amplitudes)"
                    .to_string()
            };
            // Where the run has measured the trajectory close to the full one, say so: the
            // extrapolation held on this test, which is not the same as holding on the next.
            let held = if r.mean_rel_error <= UNCOVERED_SUBSPACE_ERROR {
                format!(
                    " (on this test it stays {:.1} % from the full trajectory: the \
                     extrapolation held here, a harder pull may not)",
                    pct(r.mean_rel_error)
                )
            } else {
                String::new()
            };
            let warning = format!(
                "{}: at t = {:.3} s its pose goes {:.0} % of its size beyond the training \
                 poses, so the decoder and the cubature rule extrapolate there{held}, {what}",
                r.method,
                r.training_distance_time,
                pct(r.training_distance)
            );
            if held.is_empty() {
                out.push(warning);
            } else {
                caveats.push(warning);
            }
        }
        if r.mean_rel_error > UNTRUSTED_ERROR {
            let why = if r.subspace_error <= r.mean_rel_error / 4.0 {
                format!(
                    "its subspace holds the test trajectory to {:.1} % and a single step from \
                     it is {:.1} % off, so the reduced dynamics drift away from the full ones \
                     (large rotations in a linear subspace, a decoder trained on too little): \
                     try the neural methods with a larger `[autoencoder] latent_dim` or \
                     `[reduced] complement_directions`, or more training schedules",
                    pct(r.subspace_error),
                    pct(r.step_error)
                )
            } else {
                "the subspace misses the motion (above)".to_string()
            };
            out.push(format!(
                "{}: {:.0} % from the full trajectory on average, not a stand-in for it; {why}",
                r.method,
                pct(r.mean_rel_error)
            ));
        }
    }
    out.extend(sensitivity_warning(rows));
    Assessment {
        untrusted: out,
        caveats,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::Method;

    fn row(method: Method, mean: f64, subspace: f64) -> MethodReport {
        MethodReport {
            method,
            mean_rel_error: mean,
            subspace_error: subspace,
            step_error: 0.07,
            ..Default::default()
        }
    }

    /// The full row's sensitivity becomes one warning, which says whether the test amplifies
    /// errors and quotes the reduced methods' one-step errors.
    #[test]
    fn a_measured_sensitivity_says_whether_the_test_amplifies() {
        let drifting = MethodReport {
            step_error: 0.004,
            ..row(Method::Pca, 0.12, 0.002)
        };
        let other = MethodReport {
            step_error: 0.02,
            ..row(Method::NeuralCubature, 0.3, 0.003)
        };
        assert!(drifts(std::slice::from_ref(&drifting)));
        assert!(!drifts(&[row(Method::Pca, 0.04, 0.002)]), "within 5 %");
        assert!(
            !drifts(&[row(Method::Pca, 0.12, 0.06)]),
            "the subspace misses it"
        );
        assert!(!drifts(&[row(Method::Full, 0.12, 0.0)]));
        let full = |last: f64| MethodReport {
            sensitivity: Some(crate::run::Sensitivity {
                time: 0.3,
                change: 0.01,
                mean_error: last / 2.0,
                last_error: last,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let rows = [full(0.051), drifting.clone(), other.clone()];
        let w = assess(&rows).untrusted;
        let last = w.last().unwrap();
        assert!(last.starts_with("the test amplifies errors"), "{last}");
        assert!(
            last.contains("ends 5.1 %") && last.contains("t = 0.30 s"),
            "{last}"
        );
        assert!(
            last.contains("0.4–2.0 %"),
            "the one-step errors' range: {last}"
        );
        let rows = [full(0.003), drifting, other];
        let w = assess(&rows).untrusted;
        let last = w.last().unwrap();
        assert!(
            last.starts_with("the test does not amplify errors"),
            "{last}"
        );
        assert!(
            !assess(&[row(Method::Full, 0.0, 0.0), row(Method::Pca, 0.01, 0.004)])
                .untrusted
                .iter()
                .any(|w| w.contains("amplif")),
            "no sensitivity measured, nothing said"
        );
    }

    #[test]
    fn each_untrusted_figure_gets_a_warning_naming_the_method_and_what_to_change() {
        let rows = [
            row(Method::Full, 0.0, 0.0),
            row(Method::FullLbfgs, 0.9, 0.9),
            row(Method::Pca, 0.01, 0.004),
            row(Method::PcaCubature, 0.92, 0.023),
            row(Method::Neural, 0.3, 0.22),
        ];
        let w = assess(&rows).untrusted;
        assert_eq!(w.len(), 3, "{w:#?}");
        assert!(w[0].starts_with("pca-cubature: 92 %"), "{}", w[0]);
        assert!(w[0].contains("drift") && w[0].contains("2.3 %"), "{}", w[0]);
        assert!(
            w[1].starts_with("neural: its subspace alone is 22.0 %"),
            "{}",
            w[1]
        );
        assert!(w[1].contains("`[training] schedules`"), "{}", w[1]);
        assert!(
            w[2].starts_with("neural: 30 %") && w[2].contains("misses"),
            "{}",
            w[2]
        );
        assert!(assess(&rows[..3]).untrusted.is_empty());
        // A method closer to the full trajectory than its subspace (the springs' dents) is
        // not warned of for the subspace.
        assert!(assess(&[row(Method::Pca, 0.02, 0.22)]).untrusted.is_empty());
        let far = MethodReport {
            training_distance: 0.8,
            training_distance_time: 0.25,
            ..row(Method::NeuralCubature, 0.03, 0.01)
        };
        // It held on this test: a caveat, not a warning.
        let a = assess(&[far]);
        assert!(a.untrusted.is_empty(), "{a:#?}");
        let w = a.caveats;
        assert_eq!(w.len(), 1, "{w:#?}");
        assert!(
            w[0].starts_with("neural-cubature: at t = 0.250 s its pose goes 80 %"),
            "{}",
            w[0]
        );
        assert!(w[0].contains("extrapolate"), "{}", w[0]);
        assert!(w[0].contains("`[training] schedules`"), "{}", w[0]);
        assert!(
            w[0].contains("it stays 3.0 % from the full trajectory"),
            "a measured small error is said: {}",
            w[0]
        );
        let far_and_off = MethodReport {
            training_distance: 0.8,
            training_distance_time: 0.25,
            ..row(Method::NeuralCubature, 0.12, 0.01)
        };
        let a = assess(std::slice::from_ref(&far_and_off));
        assert!(a.caveats.is_empty(), "{a:#?}");
        let w = a.untrusted;
        assert!(!w[0].contains("held here"), "{}", w[0]);
        let text = assess(&[far_and_off]).text("");
        assert!(
            text.starts_with("\nnot to be trusted:\n- neural-cubature"),
            "{text}"
        );
        // Far from training later than the schedules last: the schedules' length is named.
        let late = MethodReport {
            training_distance: 0.3,
            training_distance_time: 0.8,
            training_seconds: 0.6,
            ..row(Method::Pca, 0.03, 0.01)
        };
        let w = assess(&[late]).caveats;
        assert_eq!(w.len(), 1, "{w:#?}");
        assert!(
            w[0].contains("later than any training schedule lasts (0.60 s)")
                && w[0].contains("`[training] frames_per_schedule`"),
            "{}",
            w[0]
        );
    }
}
