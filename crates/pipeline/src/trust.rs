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

/// A method's error for whether it drifts ([`drifting`]) and whether a trajectory outside the
/// training poses held: the larger of its mean relative error and its space–time error. The
/// mean weighs every frame alike, so a trajectory that is close for most of the test and far
/// where the body moves most (a plate that starts to buckle under its own weight near the
/// test's end: `pca` 2.6 % on average, 5.8 % space–time, 7.3 % at the worst frame, while
/// `pca-cubature` was 0.7 %) reads better on it than it is. The other judgements (a method
/// [`UNTRUSTED_ERROR`] off, a rule that adds to it) keep the mean, which the tables show.
fn judged_error(r: &MethodReport) -> f64 {
    judged(r).0
}

/// [`judged_error`] and which of the two it is, for the line that gives it.
fn judged(r: &MethodReport) -> (f64, &'static str) {
    // As `f64::max`: a mean that is not a number gives way to the space–time error.
    if r.trajectory_error > r.mean_rel_error || r.mean_rel_error.is_nan() {
        (r.trajectory_error, "space–time")
    } else {
        (r.mean_rel_error, "on average")
    }
}

/// Whether a reduced method drifts from the full trajectory: more than
/// [`UNCOVERED_SUBSPACE_ERROR`] off (on average or space–time) while its subspace holds the
/// test four times better. Then `run` starts the full simulation from the method's own state
/// part way through ([`crate::run::restart`]; not where the reference itself gives way,
/// [`reference_gives_way`]), and [`assess`] says how much of the drift that
/// explains.
pub fn drifting(r: &MethodReport) -> bool {
    let error = judged_error(r);
    !r.method.is_full()
        && r.failure.is_none()
        && error > UNCOVERED_SUBSPACE_ERROR
        && r.subspace_error <= error / 4.0
}

/// A full simulation started from a drifting method's state that goes on to make at least
/// this share of the method's later error on its own: the test amplifies the method's early
/// error, and most of its drift is the full dynamics'.
pub const AMPLIFIED_SHARE: f64 = 0.5;

/// A full-space test trajectory that squeezes this share of the body's volume under half its
/// rest volume ([`crate::run::Compression`]) is outside what the scene's material models as a
/// solid. Measured with the suite's minimal scenes (ν = 0.45): a 60 cm generated figure of
/// StVK, whose arms gave way (elements inverted in 60 of the test's 100 frames, every reduced
/// method 33–39 % off), 3.9 %; AutoDef's six meshes at most 0.19 % (the armadillo, one crushed
/// sliver at det F = 0.02), the 30 cm figure with each material under 0.01 %.
pub const COLLAPSED_SHARE: f64 = 0.01;

/// A cubature method more than this many times as far from the full trajectory as the same
/// subspace over every element (and more than [`UNCOVERED_SUBSPACE_ERROR`] off) owes the
/// difference to its rule. On the AutoDef dinosaur's minimal scene
/// (`cargo xtask suite`) the 500-element rules stopped at the budget with 8–9 % force error:
/// `pca-cubature` 38 % against `pca`'s 26 %, `neural-cubature` 34 % against `neural`'s 21 %;
/// with a budget of 1,000 (2.5–3.1 %) `neural-cubature` came to 15 %, its mean over four test
/// drags 17 → 11 %, at 1.8 times the cost of a step.
pub const CUBATURE_EXCESS: f64 = 1.25;

/// Said between the scene's own warnings and the lines after them.
pub const SCENE_FIRST: &str = "the lines below measure the scene as written: where a line above \
                               names a mistake in it (its units, density or pins, a body its \
                               weight crushes), mend that first, which changes all of them";

/// How to keep more PCA coefficients, named so a person can write it (a tester read `[pca]`
/// alone and took the value from README), for whichever of the three rules the scene uses.
/// With the budget: on a tester's pipe whose rules the 500 elements had stopped, one 9 more took
/// `pca` from 4.8 to 3.0 % and `neural-cubature` from 4.3 to 6.5 % (3.1 % at 1,500 elements, a
/// step eight times dearer; stop 73).
const LARGER_PCA: &str = "in `[pca]`, one 9 more in `explained_energy`, a smaller \
                          `max_vertex_error` or a larger `dimension`, whichever rule the `pca` \
                          stage's line names, and a larger `max_dimension` where that line says \
                          it stopped the basis (where a cubature stage's line says the element \
                          budget stopped its rule, the cubature methods can lose what `pca` \
                          gains unless `[cubature] max_elements` grows too, at a dearer step)";

/// The remedy for a cubature rule that makes a method's error, in every warning that names it.
/// Which of the two settings stopped the fit is on the cubature stage's line: on a twisted
/// blade whose rule the 2 % tolerance had stopped at 197 elements, a budget of 1,000 changed
/// nothing and a tolerance of 0.5 % took `pca-cubature` from 3.8 to 0.95 %.
const LARGER_RULE: &str = "a larger rule narrows that: a smaller `[cubature] tolerance`, or a \
                           larger `max_elements` where the cubature stage's line says the \
                           element budget stopped it";

/// "a larger `[autoencoder] latent_dim`" with the value to try where the row says its d and k:
/// twice d, at most k, the PCA basis's size (a tester doubled d = 19 to 38, past k = 37, and
/// was refused). At d = k the latent space already holds the basis's span: a larger basis, then.
pub(crate) fn larger_latent(r: &MethodReport) -> String {
    match r.latent.map(|l| (l.latent_dim, l.pca_dim)) {
        Some((d, k)) if d >= k => format!(
            "a larger PCA basis (`[autoencoder] latent_dim` = {d} is already at least the \
             basis's {k} columns; the `pca` line names the rule that sets them)"
        ),
        Some((d, k)) => format!(
            "a larger `[autoencoder] latent_dim` (now {d}; {}, at most the PCA basis's {k})",
            (2 * d).min(k)
        ),
        None => "a larger `[autoencoder] latent_dim`".to_string(),
    }
}

/// For a neural method whose subspace misses the test at least twice as far as the PCA
/// basis's (the `pca` row's subspace error), how many times as far: its latent dimension, not
/// the basis, is then what to grow.
fn latent_short_of_pca(r: &MethodReport, rows: &[MethodReport]) -> Option<f64> {
    use crate::simulate::Method;
    if !r.method.is_neural() {
        return None;
    }
    let pca = rows.iter().find(|x| x.method == Method::Pca)?;
    (pca.subspace_error > 0.0 && r.subspace_error >= 2.0 * pca.subspace_error)
        .then(|| r.subspace_error / pca.subspace_error)
}

/// The method of the same subspace over every element, for a cubature method.
fn over_every_element(method: crate::simulate::Method) -> Option<crate::simulate::Method> {
    use crate::simulate::Method;
    match method {
        Method::PcaCubature => Some(Method::Pca),
        Method::NeuralCubature => Some(Method::Neural),
        _ => None,
    }
}

/// The row of the same subspace over every element, for a cubature method's row `r`, when it
/// ran without failing: what the cubature rule's share of `r`'s figures is measured against.
fn every_element_row<'a>(r: &MethodReport, rows: &'a [MethodReport]) -> Option<&'a MethodReport> {
    let every = over_every_element(r.method)?;
    rows.iter()
        .find(|x| x.method == every && x.failure.is_none())
}

/// The same subspace over every element for a cubature method's row, when it ran and its steps
/// are at most half as far off: then the rule, not the subspace, makes the steps' error.
fn rule_made_step_error<'a>(
    r: &MethodReport,
    rows: &'a [MethodReport],
) -> Option<&'a MethodReport> {
    // A step error of 0 is none measured (no step could be taken from the reference).
    every_element_row(r, rows).filter(|x| x.step_error > 0.0 && 2.0 * x.step_error <= r.step_error)
}

/// The advice for a cubature method whose rule, not its subspace, makes much of its error:
/// its error against the same subspace's over every element, when both ran.
fn cubature_warning(r: &MethodReport, rows: &[MethodReport]) -> Option<String> {
    let e = every_element_row(r, rows)?;
    let every = e.method;
    let excess = r.mean_rel_error - e.mean_rel_error;
    (r.failure.is_none()
        && r.mean_rel_error > UNCOVERED_SUBSPACE_ERROR
        && r.mean_rel_error > CUBATURE_EXCESS * e.mean_rel_error)
        .then(|| {
            format!(
                "{}: its cubature rule adds {:.0} percentage points: {:.1} % from the full \
                 trajectory against {:.1} % for {every} over every element; {LARGER_RULE} (a \
                 step then costs about in proportion to its elements)",
                r.method,
                100.0 * excess,
                100.0 * r.mean_rel_error,
                100.0 * e.mean_rel_error
            )
        })
}

/// Below [`UNCOVERED_SUBSPACE_ERROR`] a cubature method's figure is not one to distrust, but
/// where its rule makes most of it (more than [`RULE_SHARE_CAVEAT`] times the same subspace's
/// over every element, and at least [`RULE_CAVEAT_ERROR`]) that is worth knowing: a larger
/// rule is the cheap way closer. A twisted corotated blade: `pca-cubature` 3.8 % against
/// `pca`'s 0.96 %, said by nothing before.
fn cubature_caveat(r: &MethodReport, rows: &[MethodReport]) -> Option<String> {
    if cubature_warning(r, rows).is_some() || r.failure.is_some() {
        return None;
    }
    let e = every_element_row(r, rows)?;
    let every = e.method;
    (r.mean_rel_error >= RULE_CAVEAT_ERROR
        && r.mean_rel_error > RULE_SHARE_CAVEAT * e.mean_rel_error)
        .then(|| {
            format!(
                "{}: its cubature rule makes most of its error: {:.1} % from the full trajectory \
                 against {:.1} % for {every} over every element; {LARGER_RULE}",
                r.method,
                100.0 * r.mean_rel_error,
                100.0 * e.mean_rel_error
            )
        })
}

/// A reduced method's one-step error (the step from each reference frame) measured over fewer
/// frames than its trajectory's, because a step from the reference failed: the figure and the
/// comparisons built on it cover those frames only (a tester's sliver mesh under classic
/// Neo-Hookean: 8 of 100, said before only in the log).
fn partial_step_error(r: &MethodReport) -> Option<String> {
    let (measured, frames) = (r.step_frame_errors.len(), r.frame_errors.len());
    (!r.method.is_full() && r.failure.is_none() && measured < frames).then(|| {
        format!(
            "{}: its one-step error covers the first {measured} of {frames} frames: the step \
             to frame {} from the reference failed (the log says why), and the figure stands \
             for those frames only",
            r.method,
            measured + 1
        )
    })
}

/// A cubature method under [`UNCOVERED_SUBSPACE_ERROR`] off whose error is more than this
/// many times the same subspace's over every element, and at least [`RULE_CAVEAT_ERROR`], has
/// its rule named among what is worth knowing.
pub const RULE_SHARE_CAVEAT: f64 = 2.0;
pub const RULE_CAVEAT_ERROR: f64 = 0.01;

/// Whether the reference's compression (on the row that carries it) squeezes
/// [`COLLAPSED_SHARE`] of the body under half its volume: then `run` does not restart the
/// full simulation from drifting methods' states ([`crate::run::restart`]).
pub fn reference_gives_way(rows: &[MethodReport]) -> bool {
    rows.iter()
        .filter_map(|r| r.compression)
        .any(|c| c.gives_way())
}

/// The warning of the row that carries the reference's compression (the `full` row, or the
/// first row of a run without one) when the test trajectory squeezes a share of the body under
/// half its volume.
fn collapse_warning(r: &MethodReport) -> Option<String> {
    let c = r.compression.filter(crate::run::Compression::gives_way)?;
    let inverted = if c.inverted_frames > 0 {
        format!(
            ", and elements are inverted in {} of its frames",
            c.inverted_frames
        )
    } else {
        String::new()
    };
    let who = reference_subject(r);
    let why = if c.inversion_safe {
        "the body is too soft to carry its loads (stable Neo-Hookean resists inversion only as \
         strongly as its stiffness)"
    } else {
        "the material gives way there, which is past what it models as a solid (StVK softens \
         under strong compression; linear and corotated elasticity do not resist inversion)"
    };
    let remedy = keeps_it_solid(c.inversion_safe);
    Some(format!(
        "{who} squeezes {:.1} % of the body's volume under \
         half its rest volume at t = {:.2} s (its most compressed element to det F = {:.2} at \
         t = {:.2} s{inverted}): {why}, and the reduced methods are measured against that; \
         {remedy}",
        100.0 * c.squeezed_share,
        c.squeezed_time,
        c.volume_ratio,
        c.time
    ))
}

/// What keeps a body that gives way a solid, `inversion_safe` when its material is stable
/// Neo-Hookean already.
pub(crate) fn keeps_it_solid(inversion_safe: bool) -> &'static str {
    if inversion_safe {
        "a stiffer material (`youngs_modulus`), or lighter loads (`[gravity]`, the scene's \
         `[[force]]`s, `[test] stiffness`, `offset`), keep it a solid"
    } else {
        "a stiffer material (`youngs_modulus`) resists it, and stable Neo-Hookean \
         (`[material] model`) resists inversion"
    }
}

/// Who a warning on the reference's compression speaks of, by the row that carries it: on a
/// reduced method's row (a run without `full`) it is the reference's, not the method's.
fn reference_subject(r: &MethodReport) -> String {
    if r.method.is_full() {
        format!("{}: the full-space simulation of the test", r.method)
    } else {
        "the full-space reference of the test".to_string()
    }
}

/// The warning of the row that carries the reference's compression when the test trajectory
/// stretches an element past [`Compression::STRETCHED`](crate::run::Compression::STRETCHED):
/// the pins or the loads pull the body apart, which the volume alone does not show (a body
/// hung from one vertex keeps its elements' volumes while those at the vertex lengthen).
fn stretch_warning(r: &MethodReport) -> Option<String> {
    let c = r.compression.as_ref()?;
    let (stretch, time) = c.stretched?;
    let who = reference_subject(r);
    // Where its weight carries the body far ([`carried_by_weight`]'s test), the weight is what
    // stretches it: an advice follower's bar, 17 times stretched, stayed so with three times
    // the pinned vertices and a test pull ten times lighter; only the modulus helped.
    let weight = r.buckling.filter(|b| {
        b.size > 0.0
            && b.sag >= crate::run::Buckling::VALID_SAG * b.size
            && c.travel >= FAR_TRAVEL * b.size
    });
    let remedy = match weight {
        Some(b) if b.firm_modulus <= STIFFEST_MATERIAL => format!(
            "its own weight carries it far here (the linear response to gravity at rest moves \
             it {:.0} % of its size): a stiffer material (`[material] youngs_modulus` of {:.1e} \
             Pa or more) keeps it whole, or pins that hold more of it where they hold it by \
             little (a pin plane's `tolerance`, a `box`); a lighter pull does not reach its \
             weight",
            100.0 * b.sag / b.size,
            b.firm_modulus
        ),
        Some(b) => format!(
            "its own weight carries it far here (the linear response to gravity at rest moves \
             it {:.0} % of its size), and no material is stiff enough to stop it: pins that hold \
             more of it (a pin plane's `tolerance`, a `box`) or a lighter load (`[gravity]`) \
             keep it whole",
            100.0 * b.sag / b.size
        ),
        None => "more pinned vertices (a pin plane's `tolerance`, a `box`), a stiffer material \
                 (`youngs_modulus`) or lighter loads (the scene's `[[force]]`s, the test's own \
                 grab: `[test] stiffness`, `offset`) keep it whole"
            .to_string(),
    };
    Some(format!(
        "{who} stretches an element to {stretch:.1} times its length along one direction at \
         t = {time:.2} s: the pins or the loads pull the body apart, past what it models as a \
         solid (one vertex holding its weight, or loads far beyond its stiffness), and the \
         reduced methods are measured against that; {remedy}"
    ))
}

/// The warning of the row that carries the reference's compression when a linear material's
/// test turns or stretches the body past small strains ([`Compression::LINEAR_STRAIN`]): the
/// reduced methods may follow the reference closely, and the reference is not the body's
/// motion (linear elasticity grows a body that rotates).
///
/// [`Compression::LINEAR_STRAIN`]: crate::run::Compression::LINEAR_STRAIN
fn linear_warning(r: &MethodReport) -> Option<String> {
    past_small_strains(
        &reference_subject(r),
        r.compression.as_ref()?.linear_strain?,
        "the reference is not the body's motion, however close the reduced methods come to it",
    )
}

/// What to say of `who`, a simulation under the linear material, when the largest strain it
/// leaves out over its frames (`linear_strain`: [`Compression::linear_strain`]'s figure and
/// time) is [`Compression::LINEAR_STRAIN`] or more: `so` says what that makes of its frames.
/// Said by `run` of its reference and by `simulate` of its run.
///
/// [`Compression::linear_strain`]: crate::run::Compression::linear_strain
/// [`Compression::LINEAR_STRAIN`]: crate::run::Compression::LINEAR_STRAIN
pub(crate) fn past_small_strains(
    who: &str,
    (strain, time): (f64, f64),
    so: &str,
) -> Option<String> {
    (strain >= crate::run::Compression::LINEAR_STRAIN).then(|| {
        format!(
            "{who} turns or stretches the body past small strains under the linear material: \
             the strain it leaves out (½HᵀH of the Green strain, H = F − I) averages \
             {strain:.2} over the body at t = {time:.2} s, where linear elasticity lengthens a \
             body that only turns, so {so}; a nonlinear material (`[material] model = \
             \"stable-neo-hookean\"`, or \"corotated\" for the same stiffness at small \
             strains) models it"
        )
    })
}

/// What to say of the full-space steps on which the first solver (`method`, capped at
/// `[solver] max_iterations` = `max_iterations`) stopped short and the other one finished from
/// where it stopped: `switched` holds those steps' numbers (from 1) among `steps`. Said by
/// `run` of its reference and by `simulate` of a full-space run, whose times include both
/// solvers' work (a tester's `max_iterations = 3` switched on 26 steps of 30 without a word).
pub(crate) fn solver_switches(
    method: fem_core::optim::SolverMethod,
    max_iterations: usize,
    switched: &[usize],
    steps: usize,
) -> Option<String> {
    use fem_core::optim::SolverMethod;
    let first = switched.first()?;
    let (one, other) = match method {
        SolverMethod::Newton => ("Newton", "L-BFGS"),
        SolverMethod::Lbfgs => ("L-BFGS", "Newton"),
    };
    let which = match switched.len() {
        1 => format!("it from where it stopped, at step {first}"),
        _ => format!("each from where it stopped, the first at step {first}"),
    };
    Some(format!(
        "{one} stopped short of `[solver] tolerance` on {} of the {steps} steps (at `[solver] \
         max_iterations` = {max_iterations}, or where its line search failed), and {other} \
         finished {which}",
        switched.len()
    ))
}

/// The warning of the row that carries the buckling analysis when the body buckles under its
/// own weight as it is pinned ([`crate::run::Buckling::buckles`]): a plate standing on its
/// edge, a column too slender for its height. Under gravity its shape runs away from rest
/// along the buckling mode, growing from whatever small difference starts it, so the test
/// measures how each method follows an instability (a 27 cm plate: `pca` 3.5 times as far off
/// as `pca-cubature`, every method 5–6 % over a 2 s test, up to 40 % at its worst frame).
fn buckling_warning(r: &MethodReport) -> Option<String> {
    let b = r.buckling?;
    let load = b.buckles()?;
    // Unconverged, the load factor is an upper bound and the modulus a lower one.
    let (at_most, least) = if b.converged {
        ("", "")
    } else {
        ("at most ", "at least ")
    };
    // Twice the modulus at which it would just stand: near its buckling load a body still
    // sways far ([`crate::run::Buckling::MARGIN`]).
    let firm = b
        .standing_modulus
        .map(|e| (crate::run::Buckling::MARGIN * e, e));
    let modulus = |(firm, e): (f64, f64)| {
        format!(
            "`[material] youngs_modulus` of {firm:.2e} Pa or more, {} times the {least}{e:.2e} \
             Pa at which it would just stand",
            crate::run::Buckling::MARGIN
        )
    };
    // A modulus no material has is not offered as a remedy: the pins are what to change.
    let remedy = match firm {
        Some(f) if f.0 > STIFFEST_MATERIAL => format!(
            "pins where it buckles or a lighter load (`[gravity]`) keep it standing (no material \
             is stiff enough: it would take {}, past diamond's {STIFFEST_MATERIAL:.1e} Pa)",
            modulus(f)
        ),
        Some(f) => format!(
            "pins where it buckles, a stiffer material ({}) or a lighter load (`[gravity]`) keep \
             it standing",
            modulus(f)
        ),
        None => "pins where it buckles, a stiffer material or a lighter load (`[gravity]`) keep \
                 it standing"
            .to_string(),
    };
    let units = crate::scene::unit_hint(b.size).map_or(String::new(), |u| format!("{u}; else "));
    Some(format!(
        "{}: the body buckles under its own weight as it is pinned: {at_most}{:.2} times its \
         weight would buckle it (linearised at rest, where its weight sags it by {:.2e} m), so \
         under the scene's gravity its shape runs away from rest along a buckling mode, grown from \
         whatever small difference starts it, and the test measures how each method follows \
         that instability; {units}{remedy}",
        if r.method.is_full() {
            format!("{}", r.method)
        } else {
            "the full-space reference".to_string()
        },
        load,
        b.sag
    ))
}

/// The stiffest material's Young's modulus (diamond, about 1.2e12 Pa): a body that would
/// need more to stand is held too little by its pins, and a modulus past it is not advised (an
/// advice follower's bar pinned at one vertex was offered 6.6e14 Pa beside the pin line that
/// held it at once).
pub const STIFFEST_MATERIAL: f64 = 1.2e12;

/// A test trajectory that carries the body this share of its bounding-box diagonal or more
/// moves far beyond what its drag asks (target offsets of 2–10 % of the diagonal by default).
/// AutoDef's dinosaur on its feet, E = 10⁵ Pa, moves 41 cm over its 34 cm diagonal in the
/// test's second (44 cm under gravity alone by 0.8 s).
pub const FAR_TRAVEL: f64 = 0.25;

/// A test trajectory that carries the body this many times its bounding-box diagonal: further
/// than any swing about its pins reaches (a point no further than the diagonal from the pins
/// moves at most twice it), so the body stretched to several times its size or passed through
/// itself or its pins, which a simulation without contact lets it do. A soft coil spring whose
/// weight pushed its top plate 1.4 m down through its pinned base (9 times its height) was said
/// by nothing before, its methods 3–4 % off that motion.
pub const BEYOND_SWING: f64 = 2.0;

/// The share of the test's frames with an inverted element past which a body that its weight
/// carries far gives way as a whole, not under one crushed sliver at the drag's patch: a 50 cm
/// L-bracket that folds over inverts elements in 21 of 100 frames.
pub const GIVING_WAY_FRAMES: f64 = 0.1;

/// The compression and buckling of the reference when its own weight carries the body far over
/// the test: the linear sag at rest is [`Buckling::VALID_SAG`](crate::run::Buckling::VALID_SAG)
/// of its size or more and the test moves it [`FAR_TRAVEL`] of its size or more.
fn carried_by_weight(
    rows: &[MethodReport],
) -> Option<(&MethodReport, crate::run::Compression, crate::run::Buckling)> {
    let carrier = rows
        .iter()
        .find(|r| r.compression.is_some() && r.buckling.is_some())?;
    let (c, b) = (carrier.compression?, carrier.buckling?);
    (b.size > 0.0
        && b.sag >= crate::run::Buckling::VALID_SAG * b.size
        && c.travel >= FAR_TRAVEL * b.size)
        .then_some((carrier, c, b))
}

/// The warning on a test that the body's own weight carries far ([`carried_by_weight`]) when
/// either the full simulation gives way on the way (elements inverted in
/// [`GIVING_WAY_FRAMES`] of the frames, too little of the body for [`COLLAPSED_SHARE`]: the
/// L-bracket), or at least one drifting method's restart makes most of its drift
/// ([`AMPLIFIED_SHARE`]; AutoDef's dinosaur), or it squeezes [`COLLAPSED_SHARE`] of the body
/// (a tire standing on its edge), or it carries the body past [`BEYOND_SWING`]
/// times its size (a coil pushed through its base). The restart's own advice (a gentler pull) does
/// not reach the cause there, and is left out of it ([`restart_warning`]): it is the body's
/// weight, not the drag. A fall that is meant and stays a solid (the built-in cantilever drops
/// until it hangs) amplifies nothing and is not said.
fn fall_warning(rows: &[MethodReport]) -> Option<String> {
    let (carrier, c, b) = carried_by_weight(rows)?;
    let amplified: Vec<String> = rows
        .iter()
        .filter(|r| r.restart.is_some_and(|s| s.share() >= AMPLIFIED_SHARE))
        .map(|r| r.method.to_string())
        .collect();
    // Said by the collapse warning already where it squeezes enough of the body.
    let collapsed = c.gives_way();
    let gives_way =
        !collapsed && c.inverted_frames as f64 >= GIVING_WAY_FRAMES * c.frames.max(1) as f64;
    let through = c.travel >= BEYOND_SWING * b.size;
    // A reference that gives way gets no restarts (`run`), so it is said here by itself.
    if amplified.is_empty() && !gives_way && !through && !collapsed {
        return None;
    }
    let pct = |x: f64| 100.0 * x;
    let inverted = if gives_way {
        format!(
            "; it inverts elements in {} of the test's {} frames (det F down to {:.2} at t = \
             {:.2} s)",
            c.inverted_frames, c.frames, c.volume_ratio, c.time
        )
    } else {
        String::new()
    };
    let drift = match amplified.as_slice() {
        [] => String::new(),
        [one] => format!("{one} drifts"),
        [rest @ .., last] => format!("{} and {last} drift", rest.join(", ")),
    };
    let drift = if drift.is_empty() {
        drift
    } else {
        format!(
            "; the full dynamics of a body that falls or gives way turn small differences into \
             large ones, which is how {drift} (above)"
        )
    };
    let through = if through {
        format!(
            "; that is more than {BEYOND_SWING} times its size, beyond any swing about its pins: \
             it stretched that far or passed through itself or its pins (the simulation has no \
             contact), and the methods' errors are against that motion"
        )
    } else {
        String::new()
    };
    let meant = if c.inverted_frames > 0 || collapsed {
        ""
    } else {
        "; if the fall is meant, the one-step errors say more of each method than its \
         trajectory error"
    };
    // The units first, whatever the body should do.
    let stand = match crate::scene::unit_sentence(b.size) {
        Some(u) => format!("{u}. Else, if the body should stand as pinned"),
        None => "If the body should stand as pinned".to_string(),
    };
    let remedy = if b.firm_modulus > STIFFEST_MATERIAL {
        format!(
            "pins that hold more of it keep it up (no material is stiff enough: it would take \
             `[material] youngs_modulus` of {:.1e} Pa, past diamond's {STIFFEST_MATERIAL:.1e})",
            b.firm_modulus
        )
    } else {
        format!(
            "a stiffer material (`[material] youngs_modulus` of {:.1e} Pa or more) or pins \
             that hold more of it keep it up",
            b.firm_modulus
        )
    };
    Some(format!(
        "{who} moves the body up to {:.3} m at t = {:.2} s, {:.0} % of its {:.3} m \
         bounding-box diagonal, far beyond what the drag asks: its own weight carries it (the \
         linear response to gravity at rest already moves it {:.0} % of its size){through}\
         {inverted}{drift}. {stand}, {remedy}{meant}",
        c.travel,
        c.travel_time,
        pct(c.travel / b.size),
        b.size,
        pct(b.sag / b.size),
        who = reference_subject(carrier),
    ))
}

/// What the full simulation started from a drifting method's state says of its drift; where
/// the body's own weight carries it far (`falling`), the advice of a gentler pull is left to
/// [`fall_warning`], which names the cause.
fn restart_warning(r: &MethodReport, rows: &[MethodReport], falling: bool) -> Option<String> {
    let s = r.restart?;
    let pct = |x: f64| 100.0 * x;
    let restarted = format!(
        "the full simulation started from its state at t = {:.2} s, where it is {:.1} % off, \
         ends {:.1} % from the full trajectory ({:.1} % on average from then on, the method \
         {:.1} %)",
        s.time,
        pct(s.start_error),
        pct(s.last_error),
        pct(s.mean_error),
        pct(s.method_mean_error)
    );
    let gentler = if falling {
        " (the body's weight, not the drag, carries it far: below)"
    } else {
        ", and a gentler pull (`[test] stiffness`, `offset`) tests it where errors grow less"
    };
    Some(if s.share() >= AMPLIFIED_SHARE {
        format!(
            "{}: the test amplifies its error: {restarted}. Most of its drift is what the full \
             dynamics make of its early error: its one-step error ({:.2} %) says more of \
             its accuracy than its trajectory error does{gentler}",
            r.method,
            pct(r.step_error)
        )
    } else {
        // Where the same subspace over every element steps at most half as far off, the rule
        // makes the steps' error, not the subspace (a nearly incompressible finger:
        // `neural-cubature` 2.16 % a step, `neural` 0.20 %).
        let strained = r
            .projected_strain
            .filter(|&(x, _)| x >= STRAINED_PROJECTION);
        let buckles = rows.iter().any(|x| buckling_warning(x).is_some());
        let lowers = if let Some(every) = rule_made_step_error(r, rows) {
            format!(
                "most of it the cubature rule's: {} over every element steps {:.2} % off from \
                 the same states{}",
                every.method,
                pct(every.step_error),
                if cubature_warning(r, rows).is_some() {
                    " (below)".to_string()
                } else {
                    format!("; {LARGER_RULE}")
                }
            )
        } else if cubature_warning(r, rows).is_some() {
            // The same subspace over every element follows the trajectory far closer, though
            // its single steps are not half as far off: the rule, not the subspace (a tester's
            // bunny was told both "a larger subspace" and "the rule adds 11 points").
            "most of it the cubature rule's, whose trajectory the same subspace over every \
             element follows far closer (below)"
                .to_string()
        } else if let Some((ratio, time)) = strained {
            // A neural method whose latent space, not the PCA basis, misses the test: the
            // basis's advice left a tester's d = 2 where it was (7.06 → 7.37 %; d = 8: 4.16 %).
            let larger = match latent_short_of_pca(r, rows) {
                Some(times) => format!(
                    "{} (its subspace misses the test {times:.0} times as far as the PCA \
                     basis's)",
                    larger_latent(r)
                ),
                None => format!("a larger subspace ({LARGER_PCA})"),
            };
            format!(
                "and its subspace holds the reference only by straining it: the reference's \
                 pose at t = {time:.2} s, put in the subspace, carries {ratio:.1} times its \
                 elastic energy (a part turned further than a linear basis turns without \
                 stretching, or a body giving way), which a step that lowers the energy does \
                 not follow; training schedules that reach such poses (`[training] schedules`, \
                 `kinds`, `offset`) or {larger} hold them with less strain"
            )
        } else if buckles {
            // A body that buckles under its own weight: a step's small error decides where its
            // shape runs, and a subspace that already holds it is not what to change (a
            // tester's pretzel: subspace 0.13 %, steps 0.04–0.8 %, 51–69 % off by the end).
            format!(
                "in a body that buckles under its own weight (above): from states its subspace \
                 holds to {} %, the steps' small errors decide where its shape runs away, so \
                 keeping the body standing, not a larger subspace, is the change to make",
                fine_pct(r.subspace_error)
            )
        } else if r.step_error >= 4.0 * r.subspace_error {
            // A tester read "holds the test trajectory to 0.0 %" and then "each step is 0.24 %
            // off, which a larger subspace lowers" as a contradiction: both said.
            format!(
                "from states its subspace holds to {} %: the energy along what the subspace \
                 leaves out (stiffness the mass norm hardly sees), not its reach, sets where a \
                 step lands; a larger subspace takes in more of that stiffness ({LARGER_PCA}; \
                 for the neural methods also `[autoencoder] latent_dim`)",
                fine_pct(r.subspace_error)
            )
        } else {
            format!(
                "which a larger subspace lowers ({LARGER_PCA}; for the neural methods also \
                 `[autoencoder] latent_dim`)"
            )
        };
        format!(
            "{}: the drift is mostly the reduced steps' own: {restarted}, so most of it is \
             not the full dynamics' response to the method's early error; each step is \
             {:.2} % off (one-step error), {lowers}",
            r.method,
            pct(r.step_error)
        )
    })
}

/// The reference put in a method's subspace carrying this many times its own elastic energy
/// ([`MethodReport::projected_strain`]) explains a drift the subspace error does not: a tester's
/// chain whose grabbed link turned 29° was held to 1.1 % in the mass norm at up to 19 times the
/// energy, and each step landed 6–10 % off; on AutoDef's six meshes and four other new shapes
/// the ratio stayed within 1.0–1.53.
pub const STRAINED_PROJECTION: f64 = 3.0;

/// The caveat of a run where no reduced method steps faster than full space: a mesh whose
/// full simulation is already cheap, or whose motion needs nearly as many coordinates as it has
/// (a 496-tet sheet kept 252 of its 291; every reduced method stepped at 0.3–0.9×).
fn slower_than_full(rows: &[MethodReport]) -> Option<String> {
    // The methods that reached the last frame: a stopped one's time covers only part of it.
    let speedups: Vec<f64> = rows
        .iter()
        .filter(|r| !r.method.is_full() && r.failure.is_none())
        .map(|r| r.speedup)
        .collect::<Option<_>>()?;
    let fastest = speedups.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if speedups.is_empty() || fastest >= 1.0 {
        return None;
    }
    let slowest = speedups.iter().copied().fold(f64::INFINITY, f64::min);
    let range = span(slowest, fastest, 1);
    let free = rows.iter().find(|r| r.method.is_full()).map(|r| r.dim)?;
    let kept = rows
        .iter()
        .filter(|r| !r.method.is_full())
        .map(|r| r.dim)
        .max()?;
    Some(format!(
        "no reduced method steps faster than full space here ({range}× its speed): the full simulation has {free} free coordinates and the reduced ones keep up to \
         {kept}; reduction pays where a mesh's coordinates far outnumber what its motion needs \
         (thousands of vertices), so on a mesh this small full space is the one to use"
    ))
}

/// The speed-up over the faster full-space solver the project aims `neural-cubature` at
/// (issue 26's target); below it, a run's caveats say where the step goes.
pub const AIMED_SPEEDUP: f64 = 100.0;

/// Where `neural-cubature` steps faster than full space, but less than [`AIMED_SPEEDUP`] times:
/// where its step's time goes, and what makes it cheaper at a cost in error. A tester's chair,
/// sponge and plus (36, 58 and 18×) were told nothing of why; on the plus both rules had
/// stopped at the 500-element budget in 171 PCA coordinates.
fn short_of_speedup(rows: &[MethodReport]) -> Option<String> {
    use crate::simulate::Method;
    let n = rows
        .iter()
        .find(|r| r.method == Method::NeuralCubature && r.failure.is_none())?;
    let speedup = n.speedup?;
    // Far off, its accuracy is what the other lines are about.
    if !(1.0..AIMED_SPEEDUP).contains(&speedup) || judged_error(n) > UNCOVERED_SUBSPACE_ERROR {
        return None;
    }
    let full_ms = n.ms_per_step * speedup;
    let decoder = n.decode_ms + n.vjp_ms;
    let k = rows
        .iter()
        .find(|r| r.method == Method::Pca)
        .map(|r| format!(" in the {} PCA coordinates", r.dim))
        .unwrap_or_default();
    let digits = usize::from(speedup < 10.0);
    let budget = full_ms / AIMED_SPEEDUP;
    // Where the decoder alone takes longer than the aim allows a whole step, no smaller basis
    // or rule reaches it.
    let remedy = if decoder > 0.0 && decoder >= budget {
        format!(
            "The decoder alone takes longer than the {budget:.4} ms a step {AIMED_SPEEDUP:.0} \
             times faster would take: on a full step this cheap no smaller basis or rule \
             reaches it, and a larger mesh gains more, its full step dearer and the reduced \
             one about the same"
        )
    } else {
        "A smaller basis (the `pca` line's rule) or a smaller rule (a larger `[cubature] \
         tolerance`, a smaller `max_elements`) makes a step cheaper at a cost in error, which \
         `cargo xtask bench` sweeps; a larger mesh gains more, its full step dearer and the \
         reduced one about the same"
            .to_string()
    };
    Some(format!(
        "neural-cubature steps {speedup:.digits$}× faster than full space here, short of the \
         {AIMED_SPEEDUP:.0}× this project aims at: its {:.3} ms a step against full space's \
         {full_ms:.3} ms; the elastic terms take {:.3} ms over its {} elements{k} (each \
         element's force and stiffness projected to every coordinate, so their cost grows with \
         the elements times the square of the coordinates), the preconditioner {:.3} ms and the \
         decoder {decoder:.3} ms. {remedy}",
        n.ms_per_step, n.elastic_ms, n.cubature_elements, n.precond_ms,
    ))
}

/// What of `method` was fitted to the training poses and so extrapolates beyond them, as the
/// subject of "… there": the basis alone for `pca` (any pose in its span is exact, but the
/// span was chosen from those poses).
fn fitted_parts(method: crate::simulate::Method) -> &'static str {
    use crate::simulate::Method;
    match method {
        Method::PcaCubature => "the cubature rule extrapolates",
        Method::Neural => "the decoder extrapolates",
        Method::NeuralCubature => "the decoder and the cubature rule extrapolate",
        _ => "the basis, chosen from the training poses, may miss the motion",
    }
}

/// A fraction as a percentage with one decimal, two below 0.1 %, and "under 0.01" below that
/// (a subspace error "0.0 %" read as none at all).
fn fine_pct(x: f64) -> String {
    let p = 100.0 * x;
    if p < 0.01 {
        "under 0.01".to_string()
    } else if p < 0.1 {
        format!("{p:.2}")
    } else {
        format!("{p:.1}")
    }
}

/// `lo–hi` with `digits` decimals, or one figure where the two print the same.
fn span(lo: f64, hi: f64, digits: usize) -> String {
    let (lo, hi) = (format!("{lo:.digits$}"), format!("{hi:.digits$}"));
    if lo == hi { lo } else { format!("{lo}–{hi}") }
}

/// One caveat for the methods whose trajectories left the training poses and still held, all
/// given the same advice `what`: one method as "its pose", several as "their poses" with the
/// ranges of their times, distances and errors.
fn held_outside_caveat(rows: &[&MethodReport], what: &str) -> String {
    let range = |f: &dyn Fn(&MethodReport) -> f64, digits: usize, scale: f64| {
        let (lo, hi) = rows
            .iter()
            .map(|r| scale * f(r))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            });
        span(lo, hi, digits)
    };
    let names: Vec<String> = rows.iter().map(|r| r.method.to_string()).collect();
    let (goes, its, stays) = if rows.len() == 1 {
        ("its pose goes", "its", "it stays")
    } else {
        ("their poses go", "their", "they stay")
    };
    let fitted = match rows {
        [one] => fitted_parts(one.method).to_string(),
        _ => "what each fitted to the training poses (basis, decoder, cubature rule) \
              extrapolates"
            .to_string(),
    };
    format!(
        "{}: at t = {} s {goes} {} % of {its} size beyond the training poses, so {fitted} there \
         (on this test {stays} within {} % of the full trajectory, on average and space–time: \
         the extrapolation held here, a harder pull may not), {what}",
        names.join(", "),
        range(&|r| r.training_distance_time, 3, 1.0),
        range(&|r| r.training_distance, 0, 100.0),
        range(&judged_error, 1, 100.0),
    )
}

/// What a run's figures say of its reduced methods, in row order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Assessment {
    /// Figures not to be trusted: what building the model warned of, a full-space test that
    /// gives way ([`COLLAPSED_SHARE`]) or pulls the body apart, a body that buckles under its
    /// own weight as pinned or that its weight carries far ([`FAR_TRAVEL`]), a method that
    /// stopped, a subspace that misses the test, a trajectory over
    /// [`UNTRUSTED_ERROR`] off, one that left the training poses and ended over
    /// [`UNCOVERED_SUBSPACE_ERROR`] off (on average or space–time), and what the full
    /// simulation started from a drifting method's state says of its drift.
    pub untrusted: Vec<String>,
    /// What the figures do not say by themselves: a trajectory that left the training poses
    /// and still ended within [`UNCOVERED_SUBSPACE_ERROR`] of the full one (it held on this
    /// test, may not on others), or reduction that does not pay on this mesh.
    pub caveats: Vec<String>,
}

impl Assessment {
    /// The two lists as the text `run` and `suite` print under `heading` (e.g. a scene's name
    /// and a colon, or nothing): "not to be trusted" first; empty when both are.
    pub fn text(&self, heading: &str) -> String {
        let mut s = String::new();
        // The settings that keep more PCA coefficients are spelled out once: a tester's list
        // gave the same paragraph for each of four methods. (Only here: the lists themselves
        // keep every line whole, since a model's export keeps the lines of its own method.)
        let mut said = false;
        for (title, list) in [
            ("not to be trusted", &self.untrusted),
            ("worth knowing", &self.caveats),
        ] {
            if !list.is_empty() {
                s.push_str(&format!("\n{heading}{title}:\n"));
                for w in list {
                    let w = if w.contains(LARGER_PCA) && std::mem::replace(&mut said, true) {
                        w.replace(LARGER_PCA, "the settings said above")
                    } else {
                        w.clone()
                    };
                    s.push_str(&format!("- {w}\n"));
                }
            }
        }
        s
    }
}

/// A PCA basis that `[pca] max_dimension` stopped short of its rule ([`MethodReport::basis_cap`]):
/// the line, and whether it is a warning (a reduced method stopped, or ended over
/// [`UNCOVERED_SUBSPACE_ERROR`] off) or a caveat. Every reduced method works in that basis, and
/// none of the other lines' remedies reaches past the cap: on an advice follower's bar capped
/// at 8 coefficients, a 130 times stiffer material took `neural-cubature` from 4.8 to 13 % and
/// one 9 more in `explained_energy` changed nothing, where `max_dimension = 16` gave 2.6 %
/// (stop 77).
fn basis_cap_line(rows: &[MethodReport]) -> Option<(String, bool)> {
    let cap = rows.iter().find_map(|r| r.basis_cap.as_ref())?;
    let asks = match cap.wanted {
        Some(w) => format!("where {} asks for {w}", cap.rule),
        None => format!("short of {}", cap.rule),
    };
    let raise = match cap.wanted {
        Some(w) => format!("raise it to {w}"),
        None => "raise it".to_string(),
    };
    // The first of the farthest, in row order.
    let worst = rows.iter().filter(|r| !r.method.is_full()).reduce(|a, b| {
        if judged_error(b) > judged_error(a) {
            b
        } else {
            a
        }
    })?;
    let stopped = rows
        .iter()
        .find(|r| !r.method.is_full() && r.failure.is_some());
    let head = format!(
        "the PCA basis: `[pca] max_dimension` = {} stopped it at that many coefficients {asks}, \
         and every reduced method works in it",
        cap.max_dimension
    );
    if let Some(r) = stopped {
        return Some((
            format!(
                "{head}; with {} stopped before the last frame, {raise} first: every figure \
                 of the reduced methods here measures the capped basis",
                r.method
            ),
            true,
        ));
    }
    let (error, kind) = judged(worst);
    if error > UNCOVERED_SUBSPACE_ERROR {
        Some((
            format!(
                "{head}; with {} {:.1} % from the full trajectory ({kind}), {raise} first: \
                 every figure of the reduced methods here measures the capped basis",
                worst.method,
                100.0 * error
            ),
            true,
        ))
    } else {
        Some((
            format!(
                "{head}: every method held this test within {:.0} %; where another test is \
                 not held, {raise} first",
                100.0 * UNCOVERED_SUBSPACE_ERROR
            ),
            false,
        ))
    }
}

/// Warnings and caveats for the reduced methods of a run, after what building the model warned
/// of and the warnings on the reference (from the row that carries its compression and
/// buckling: the `full` row, or the first row without one): a test trajectory that squeezes
/// [`COLLAPSED_SHARE`] of the body under half its volume or pulls it apart, a linear material
/// turned past small strains, a body that buckles under its own weight as pinned, and
/// one that its own weight carries far while it gives way or amplifies a method's drift. Both
/// lists are empty when none of those holds and every method is within [`UNTRUSTED_ERROR`],
/// its subspace or its error within [`UNCOVERED_SUBSPACE_ERROR`], its trajectory within
/// [`OUTSIDE_TRAINING`] of the training poses, and no method drifts ([`drifting`]).
pub fn assess(rows: &[MethodReport]) -> Assessment {
    // What building the model warned of, on the row that carries the reference's analyses.
    let mut out: Vec<String> = rows
        .iter()
        .flat_map(|r| r.scene_warnings.iter().map(|w| format!("the scene: {w}")))
        .collect();
    let scene_lines = out.len();
    out.extend(rows.iter().filter_map(collapse_warning));
    out.extend(rows.iter().filter_map(stretch_warning));
    out.extend(rows.iter().filter_map(linear_warning));
    out.extend(rows.iter().filter_map(buckling_warning));
    // Before the methods' lines, whose remedies measure the capped basis.
    let capped = basis_cap_line(rows);
    if let Some((line, true)) = &capped {
        out.push(line.clone());
    }
    // Methods whose trajectory left the training poses and still held, with the advice.
    let mut held_outside: Vec<(&MethodReport, String)> = Vec::new();
    let falling = carried_by_weight(rows).is_some();
    let reference_collapsed = reference_gives_way(rows);
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
                 data does not cover the test's motion: add schedules (`[training] \
                 schedules`), the test's kind to `[training] kinds` where it is not there (the \
                 default kinds have a drag), or keep more PCA coefficients ({LARGER_PCA})",
                r.method,
                pct(r.subspace_error)
            ));
        }
        // A trajectory that carried a vertex further from the full one than any swing about
        // the pins reaches blew up: no training pose or extrapolation explains that (a paper
        // reproducer's one-element rule moved the X four times its size, and was told its
        // cubature rule extrapolated).
        let size = rows.iter().find_map(|x| x.buckling.map(|b| b.size));
        let blew_up = size.filter(|&s| s > 0.0 && r.max_vertex_error > BEYOND_SWING * s);
        if let Some(size) = blew_up {
            let remedy = if over_every_element(r.method).is_some() {
                format!(
                    "its cubature rule ({} element{}) may leave the body without stiffness \
                     along some directions: {LARGER_RULE}",
                    r.cubature_elements,
                    if r.cubature_elements == 1 { "" } else { "s" }
                )
            } else {
                "a smaller `[time] step` or a tighter `[reduced] tolerance` keeps its solves \
                 closer"
                    .to_string()
            };
            out.push(format!(
                "{}: a vertex ends up {:.3} m from its full-space position, {:.1} times the \
                 body's {size:.3} m bounding-box diagonal: the reduced trajectory blew up, \
                 which no training data explains; {remedy}",
                r.method,
                r.max_vertex_error,
                r.max_vertex_error / size
            ));
        }
        if blew_up.is_none() && r.training_distance > OUTSIDE_TRAINING {
            // A time no schedule reached: a body that keeps moving under gravity (sagging,
            // toppling) goes where the shorter schedules never took it.
            // The same subspace over every element kept within the training poses: the rule
            // takes the pose there, and more schedules do not bring it back (a tester's
            // 20-element rule: 35.0 → 34.4 % with twice the schedules, 1.05 % at 100 elements).
            // It must follow the full trajectory itself (one that lags stays within them for
            // that) and stay clearly nearer, at most half as far out.
            let every_stayed = every_element_row(r, rows).filter(|x| {
                x.training_distance <= OUTSIDE_TRAINING
                    && 2.0 * x.training_distance <= r.training_distance
                    && judged_error(x) <= UNCOVERED_SUBSPACE_ERROR
            });
            let what = if let Some(every) = every_stayed {
                format!(
                    "where {} over every element stays within them ({:.0} % at most): the \
                     cubature rule takes the pose there, not the training data; {LARGER_RULE}",
                    every.method,
                    pct(every.training_distance)
                )
            } else if r.training_seconds > 0.0
                && r.training_distance_time > r.training_seconds + 1e-9
            {
                format!(
                    "later than any training schedule lasts ({:.2} s): longer schedules \
                     (`[training] frames_per_schedule`, at least the test's frames) reach such \
                     times",
                    r.training_seconds
                )
            } else {
                "add training schedules that reach such poses (`[training] schedules`, the \
                 test's kind to `kinds` where it is not there, or larger amplitudes: the upper \
                 end of `offset`, a fraction of the bounding-box diagonal)"
                    .to_string()
            };
            // Where the run has measured the trajectory close to the full one, it is a caveat:
            // the extrapolation held on this test, which is not the same as holding on the
            // next (said once for the methods that share the advice, below).
            let held = judged_error(r) <= UNCOVERED_SUBSPACE_ERROR;
            if !held {
                // The figure that decided it, so that two methods side by side, one held and
                // one not, read as the one threshold (a puck's 3.2 % against 3.6 % on average).
                let (error, kind) = judged(r);
                out.push(format!(
                    "{}: at t = {:.3} s its pose goes {:.0} % of its size beyond the training \
                     poses, so {} there, and it is {:.1} % from the full trajectory ({kind}; \
                     past {:.0} % an extrapolation is not taken as held), {what}",
                    r.method,
                    r.training_distance_time,
                    pct(r.training_distance),
                    fitted_parts(r.method),
                    pct(error),
                    pct(UNCOVERED_SUBSPACE_ERROR)
                ));
            } else {
                held_outside.push((r, what));
            }
        }
        if r.mean_rel_error > UNTRUSTED_ERROR {
            let dynamics_drift = r.subspace_error <= r.mean_rel_error / 4.0;
            let why = if dynamics_drift && reference_collapsed {
                format!(
                    "its subspace holds the test trajectory to {} %, and the full simulation it \
                     is measured against gives way (above)",
                    fine_pct(r.subspace_error)
                )
            } else if dynamics_drift && r.restart.is_some() {
                format!(
                    "its subspace holds the test trajectory to {} %, so the trajectory drifts \
                     away (below)",
                    fine_pct(r.subspace_error)
                )
            } else if dynamics_drift {
                format!(
                    "its subspace holds the test trajectory to {} % and a single step from \
                     it is {:.1} % off, so the reduced dynamics drift away from the full ones \
                     (large rotations in a linear subspace, a decoder trained on too little): \
                     try the neural methods with a larger `[autoencoder] latent_dim` or \
                     `[reduced] complement_directions`, or more training schedules",
                    fine_pct(r.subspace_error),
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
        if let Some(e) = &r.restart_failed {
            out.push(format!(
                "{}: the full simulation started from its state part way through the test could \
                 not run ({e}), so how much of its drift the full dynamics would make is not \
                 measured",
                r.method
            ));
        }
        out.extend(restart_warning(r, rows, falling));
        out.extend(cubature_warning(r, rows));
    }
    // Said after the methods' restarts, whose amplification it explains.
    out.extend(fall_warning(rows));
    // A tester's mesh in millimetres read as metres was told to set `[mesh] scale`, then eight
    // lines to add training schedules: those measure the scene as written.
    if scene_lines > 0 && out.len() > scene_lines {
        out.insert(scene_lines, SCENE_FIRST.to_string());
    }
    let mut caveats: Vec<String> = slower_than_full(rows).into_iter().collect();
    caveats.extend(short_of_speedup(rows));
    if let Some((line, false)) = capped {
        caveats.push(line);
    }
    caveats.extend(rows.iter().filter_map(|r| cubature_caveat(r, rows)));
    caveats.extend(rows.iter().filter_map(partial_step_error));
    while let Some((_, what)) = held_outside.first() {
        let what = what.clone();
        let (group, rest): (Vec<_>, Vec<_>) =
            held_outside.into_iter().partition(|(_, w)| *w == what);
        held_outside = rest;
        caveats.push(held_outside_caveat(
            &group.iter().map(|(r, _)| *r).collect::<Vec<_>>(),
            &what,
        ));
    }
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

    /// `r` with a restart at 0.3 s from a state 0.7 % off, whose full simulation makes `mean`
    /// on average (twice that at the end) against the method's `method_mean` (0.5 at the end).
    fn with_restart(r: MethodReport, mean: f64, method_mean: f64) -> MethodReport {
        MethodReport {
            restart: Some(crate::run::Restart {
                time: 0.3,
                start_error: 0.007,
                mean_error: mean,
                last_error: 2.0 * mean,
                method_mean_error: method_mean,
                method_last_error: 0.5,
            }),
            ..r
        }
    }

    /// The scene's own warnings come first, then a line saying the methods' lines measure the
    /// scene as written; with no method line after them, or no scene warning, no such line.
    #[test]
    fn the_scenes_warnings_come_before_the_methods_lines() {
        let scene = |r: MethodReport| MethodReport {
            scene_warnings: vec!["the mesh is 3.076e2 m across".into()],
            ..r
        };
        let w = assess(&[
            scene(row(Method::Full, 0.0, 0.0)),
            row(Method::Pca, 0.25, 0.246),
        ])
        .untrusted;
        assert!(w.len() > 2, "{w:?}");
        assert!(w[0].starts_with("the scene: the mesh is"), "{w:?}");
        assert_eq!(w[1], SCENE_FIRST);
        assert!(w[2].starts_with("pca: "), "{w:?}");
        let alone = assess(&[
            scene(row(Method::Full, 0.0, 0.0)),
            row(Method::Pca, 0.001, 0.001),
        ])
        .untrusted;
        assert_eq!(alone.len(), 1, "{alone:?}");
        let methods =
            assess(&[row(Method::Full, 0.0, 0.0), row(Method::Pca, 0.25, 0.246)]).untrusted;
        assert!(!methods.is_empty() && !methods.contains(&SCENE_FIRST.to_string()));
    }

    /// A rule that makes most of a cubature method's error under the untrusted figure is worth
    /// knowing; under 1 %, or near the error over every element, it is not, and over 5 % the
    /// warning says it instead.
    #[test]
    fn a_rule_that_makes_most_of_a_small_error_is_worth_knowing() {
        let caveats = |pc: f64, pca: f64| {
            assess(&[
                row(Method::Pca, pca, 0.001),
                row(Method::PcaCubature, pc, 0.001),
            ])
            .caveats
            .into_iter()
            .filter(|c| c.contains("cubature rule"))
            .collect::<Vec<_>>()
        };
        let c = caveats(0.0381, 0.0096);
        assert_eq!(c.len(), 1, "{c:?}");
        assert!(
            c[0].starts_with(
                "pca-cubature: its cubature rule makes most of its error: 3.8 % from the full \
                 trajectory against 1.0 % for pca over every element; a larger rule"
            ),
            "{}",
            c[0]
        );
        assert!(caveats(0.009, 0.001).is_empty());
        assert!(caveats(0.03, 0.02).is_empty());
        assert!(caveats(0.08, 0.01).is_empty());
    }

    /// A linear material's test that turns the body past small strains is named on the
    /// full-space row with a nonlinear model to use; small strains, or no measure (another
    /// material), say nothing.
    #[test]
    fn a_linear_material_turned_far_is_named() {
        let full = |linear_strain: Option<(f64, f64)>| MethodReport {
            compression: Some(crate::run::Compression {
                volume_ratio: 0.9,
                time: 0.5,
                inverted_frames: 0,
                frames: 100,
                squeezed_share: 0.0,
                squeezed_time: 0.5,
                inversion_safe: false,
                travel: 0.1,
                travel_time: 0.5,
                stretched: None,
                linear_strain,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let method = row(Method::Pca, 0.002, 0.001);
        for quiet in [None, Some((0.049, 0.3))] {
            assert_eq!(
                assess(&[full(quiet), method.clone()]),
                Assessment::default()
            );
        }
        let said = assess(&[full(Some((0.12, 0.64))), method]).untrusted;
        assert_eq!(said.len(), 1, "{said:?}");
        assert!(
            said[0].starts_with("full: the full-space simulation of the test turns"),
            "{}",
            said[0]
        );
        assert!(
            said[0].contains("averages 0.12 over the body at t = 0.64 s"),
            "{}",
            said[0]
        );
        assert!(
            said[0].contains("model = \"stable-neo-hookean\""),
            "{}",
            said[0]
        );
    }

    /// The full-space row warns where its trajectory squeezes a share of the body under half
    /// its volume, and says when elements invert; one crushed sliver gets no warning.
    #[test]
    fn a_full_trajectory_that_collapses_is_named() {
        let full = |share: f64, ratio: f64, inverted_frames: usize| MethodReport {
            compression: Some(crate::run::Compression {
                volume_ratio: ratio,
                time: 0.75,
                inverted_frames,
                frames: 100,
                squeezed_share: share,
                squeezed_time: 0.5,
                inversion_safe: false,
                travel: 0.0,
                travel_time: 0.0,
                stretched: None,
                linear_strain: None,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let sliver = assess(&[full(1e-4, 0.02, 0), row(Method::Pca, 0.01, 0.005)]);
        assert_eq!(sliver, Assessment::default());
        let squeezed = assess(&[full(0.2, 0.39, 0)]).untrusted;
        assert_eq!(squeezed.len(), 1, "{squeezed:?}");
        assert!(squeezed[0].starts_with("full: "), "{}", squeezed[0]);
        let expected = "squeezes 20.0 % of the body's volume under half its rest volume at \
                        t = 0.50 s (its most compressed element to det F = 0.39 at t = 0.75 s)";
        assert!(squeezed[0].contains(expected), "{}", squeezed[0]);
        let inverted = assess(&[full(0.3, -1.1, 60)]).untrusted;
        let expected =
            "det F = -1.10 at t = 0.75 s, and elements are inverted in 60 of its frames)";
        assert!(inverted[0].contains(expected), "{}", inverted[0]);
        assert!(inverted[0].contains("`[material] model`"));
        // Of a stable Neo-Hookean body, only the stiffness and the loads are advised.
        let mut safe = full(0.3, -8.3, 95);
        if let Some(c) = &mut safe.compression {
            c.inversion_safe = true;
        }
        let soft = assess(&[safe]).untrusted;
        assert!(
            soft[0].contains("too soft to carry its loads"),
            "{}",
            soft[0]
        );
        assert!(!soft[0].contains("`[material] model`"), "{}", soft[0]);
        assert!(!soft[0].contains("StVK"), "{}", soft[0]);
        // A run without `full` carries the reference's compression on its first row: named as
        // the reference's, once.
        let first = MethodReport {
            compression: full(0.2, 0.39, 0).compression,
            ..row(Method::Pca, 0.01, 0.005)
        };
        let reduced = assess(&[first, row(Method::NeuralCubature, 0.01, 0.005)]).untrusted;
        assert_eq!(reduced.len(), 1, "{reduced:?}");
        assert!(
            reduced[0].starts_with("the full-space reference of the test squeezes 20.0 %"),
            "{}",
            reduced[0]
        );
        // A method that drifts from a reference that gives way is sent to that warning, not
        // told to grow its subspace; from a firm reference it is.
        let drifting = row(Method::NeuralCubature, 0.4, 0.01);
        assert!(reference_gives_way(&[full(0.2, 0.39, 0)]));
        assert!(!reference_gives_way(&[full(1e-4, 0.02, 0)]));
        let said = |reference| {
            assess(&[reference, drifting.clone()])
                .untrusted
                .into_iter()
                .find(|w| w.starts_with("neural-cubature: 40 % from the full trajectory"))
                .unwrap_or_default()
        };
        let collapsed = said(full(0.2, 0.39, 0));
        assert!(
            collapsed.ends_with(
                "its subspace holds the test trajectory to 1.0 %, and the full simulation it \
                 is measured against gives way (above)"
            ),
            "{collapsed}"
        );
        assert!(said(full(1e-4, 0.02, 0)).contains("`[autoencoder] latent_dim`"));
    }

    /// When every reduced method is slower than full space, a caveat says so with the sizes;
    /// `neural-cubature` faster, but short of [`AIMED_SPEEDUP`], gets where its step goes; at
    /// the aim, or in a run without a full-space row, none.
    #[test]
    fn reduction_that_does_not_pay_is_said() {
        let timed = |method, dim, speedup| MethodReport {
            dim,
            speedup,
            ..row(method, 0.01, 0.005)
        };
        let slow = [
            timed(Method::Full, 291, Some(1.0)),
            timed(Method::Pca, 252, Some(0.6)),
            timed(Method::NeuralCubature, 240, Some(0.3)),
        ];
        let w = assess(&slow).caveats;
        assert_eq!(w.len(), 1, "{w:#?}");
        assert!(
            w[0].starts_with("no reduced method steps faster than full space here (0.3–0.6×")
                && w[0].contains("291 free coordinates")
                && w[0].contains("keep up to 252"),
            "{}",
            w[0]
        );
        let mut one_fast = slow.clone();
        one_fast[2].speedup = Some(1.4);
        // Faster, yet short of the aim: where its step goes, and what makes it cheaper.
        let short = assess(&one_fast).caveats;
        assert_eq!(short.len(), 1, "{short:#?}");
        assert!(
            short[0].starts_with(
                "neural-cubature steps 1.4× faster than full space here, short of the 100×"
            ) && short[0].contains("elements in the 252 PCA coordinates")
                && short[0].contains("a larger `[cubature] tolerance`"),
            "{}",
            short[0]
        );
        // A decoder dearer than the aim's whole step: no smaller basis or rule is offered.
        one_fast[2].ms_per_step = 0.2;
        one_fast[2].decode_ms = 0.003;
        let cheap = assess(&one_fast).caveats;
        assert!(
            cheap[0].contains("The decoder alone takes longer than the 0.0028 ms")
                && !cheap[0].contains("A smaller basis"),
            "{}",
            cheap[0]
        );
        // Far off, its accuracy is what counts: nothing said of its speed.
        one_fast[2].mean_rel_error = 0.08;
        assert!(assess(&one_fast).caveats.is_empty());
        one_fast[2].mean_rel_error = 0.01;
        one_fast[2].speedup = Some(AIMED_SPEEDUP);
        assert!(assess(&one_fast).caveats.is_empty());
        let untimed = [timed(Method::Pca, 252, None)];
        assert!(assess(&untimed).caveats.is_empty());
        let one = assess(&slow[..2]).caveats;
        assert!(one[0].contains("here (0.6× its speed)"), "{}", one[0]);
    }

    /// A one-step error over fewer frames than the trajectory's is said with the count; one
    /// over every frame, or a full-space row, is not.
    #[test]
    fn a_partial_one_step_error_is_said() {
        let with = |method, steps: usize| MethodReport {
            frame_errors: vec![0.01; 100],
            step_frame_errors: vec![0.001; steps],
            ..row(method, 0.01, 0.005)
        };
        let c = assess(&[
            with(Method::Full, 0),
            with(Method::Pca, 8),
            with(Method::PcaCubature, 100),
        ])
        .caveats;
        assert_eq!(c.len(), 1, "{c:#?}");
        assert!(
            c[0].starts_with(
                "pca: its one-step error covers the first 8 of 100 frames: the step \
                              to frame 9 from the reference failed"
            ),
            "{}",
            c[0]
        );
    }

    /// A full trajectory that stretches an element past the limit is named, with the pins
    /// first among the remedies; no stretch, no warning.
    #[test]
    fn a_full_trajectory_that_pulls_the_body_apart_is_named() {
        let full = |stretched| MethodReport {
            compression: Some(crate::run::Compression {
                volume_ratio: 0.26,
                time: 0.75,
                inverted_frames: 0,
                frames: 100,
                squeezed_share: 1e-4,
                squeezed_time: 0.5,
                inversion_safe: true,
                travel: 0.0,
                travel_time: 0.0,
                stretched,
                linear_strain: None,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        assert_eq!(assess(&[full(None)]), Assessment::default());
        let pulled = assess(&[full(Some((4.6, 1.0)))]).untrusted;
        assert_eq!(pulled.len(), 1, "{pulled:?}");
        assert!(
            pulled[0].starts_with(
                "full: the full-space simulation of the test stretches an element to 4.6 times \
                 its length along one direction at t = 1.00 s"
            ),
            "{}",
            pulled[0]
        );
        assert!(
            pulled[0].contains("a pin plane's `tolerance`"),
            "{}",
            pulled[0]
        );
        // Where its weight carries it far, the weight is named and the modulus leads; the pins
        // and lighter pulls that did nothing are not offered.
        let stretch_line = |r: MethodReport| {
            assess(&[r])
                .untrusted
                .into_iter()
                .find(|w| w.contains("stretches an element"))
                .unwrap()
        };
        let heavy_row = || {
            let mut heavy = full(Some((17.0, 0.9)));
            if let Some(c) = &mut heavy.compression {
                c.travel = 4.9;
            }
            heavy.buckling = Some(crate::run::Buckling {
                load_factor: None,
                sag: 6.5,
                size: 1.01,
                standing_modulus: None,
                firm_modulus: 1.3e7,
                converged: true,
            });
            heavy
        };
        let by_weight = stretch_line(heavy_row());
        assert!(
            by_weight.contains(
                "its own weight carries it far here (the linear response to gravity at rest \
                 moves it 644 % of its size): a stiffer material (`[material] youngs_modulus` of \
                 1.3e7 Pa"
            ) && !by_weight.contains("`[test] stiffness`"),
            "{by_weight}"
        );
        // A body that only a modulus past any material's would hold: the pins and the load.
        let mut hopeless = heavy_row();
        if let Some(b) = &mut hopeless.buckling {
            b.firm_modulus = 6.6e14;
        }
        let w = stretch_line(hopeless);
        assert!(
            w.contains("no material is stiff enough to stop it: pins that hold more of it")
                && !w.contains("6.6e14"),
            "{w}"
        );
        // A body its weight hardly sags is not said to be stretched by it.
        let mut light = heavy_row();
        if let Some(b) = &mut light.buckling {
            b.sag = 0.01;
        }
        let w = stretch_line(light);
        assert!(!w.contains("its own weight carries"), "{w}");
    }

    /// A body whose buckling search stopped short is warned of when the bound it found is
    /// below 1, as an upper bound ("at most"); a thin stool that fell under its weight was not.
    #[test]
    fn an_unconverged_buckling_bound_below_one_is_told_as_a_bound() {
        let full = |converged: bool, load: f64| MethodReport {
            buckling: Some(crate::run::Buckling {
                load_factor: Some(load),
                sag: 0.004,
                size: 0.6,
                standing_modulus: Some(1e5 / load),
                firm_modulus: crate::run::Buckling::firm(1e5, 0.004, 0.6, Some(1e5 / load)),
                converged,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let said = |r: MethodReport| {
            assess(&[r])
                .untrusted
                .into_iter()
                .filter(|w| w.contains("buckles under its own weight"))
                .collect::<Vec<_>>()
        };
        let w = said(full(false, 0.255));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("at most 0.26 times its weight"), "{}", w[0]);
        assert!(w[0].contains("the at least 3.92e5 Pa"), "{}", w[0]);
        let w = said(full(true, 0.255));
        assert!(w[0].contains("pinned: 0.26 times its weight"), "{}", w[0]);
        assert!(said(full(false, 1.5)).is_empty());
    }

    /// A body whose weight carries it far over the test, where the full dynamics amplify a
    /// method's early error, is said once, with the modulus that firms it up; a fall that
    /// amplifies nothing, a body that moves little, or one its weight hardly sags, is not.
    #[test]
    fn a_body_that_falls_under_its_weight_and_amplifies_errors_is_named() {
        let full = |travel: f64, sag: f64| MethodReport {
            compression: Some(crate::run::Compression {
                volume_ratio: 0.8,
                time: 0.75,
                inverted_frames: 0,
                frames: 100,
                squeezed_share: 0.0,
                squeezed_time: 0.5,
                inversion_safe: false,
                travel,
                travel_time: 0.8,
                stretched: None,
                linear_strain: None,
            }),
            buckling: Some(crate::run::Buckling {
                load_factor: Some(0.52),
                sag,
                size: 0.34,
                standing_modulus: Some(1e5 / 0.52),
                firm_modulus: crate::run::Buckling::firm(1e5, sag, 0.34, Some(1e5 / 0.52)),
                converged: true,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let amplified = with_restart(row(Method::NeuralCubature, 0.34, 0.002), 0.45, 0.5);
        let own = with_restart(row(Method::Pca, 0.26, 0.001), 0.02, 0.5);
        let said = |rows: &[MethodReport]| {
            assess(rows)
                .untrusted
                .into_iter()
                .filter(|w| w.contains("its own weight carries it"))
                .collect::<Vec<_>>()
        };
        let w = said(&[full(0.44, 0.17), own.clone(), amplified.clone()]);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with(
                "full: the full-space simulation of the test moves the body up to 0.440 m at \
                 t = 0.80 s, 129 % of its 0.340 m bounding-box diagonal"
            ),
            "{}",
            w[0]
        );
        assert!(w[0].contains("moves it 50 % of its size"), "{}", w[0]);
        assert!(
            w[0].contains("which is how neural-cubature drifts (above)"),
            "{}",
            w[0]
        );
        assert!(
            w[0].contains("youngs_modulus` of 1.0e6 Pa or more"),
            "{}",
            w[0]
        );
        // A modulus no material has is not advised: the pins are (a bar held at one vertex).
        let mut one_vertex = full(0.44, 0.17);
        if let Some(b) = &mut one_vertex.buckling {
            b.firm_modulus = 6.6e14;
        }
        let w1 = said(&[one_vertex, amplified.clone()]);
        assert!(
            w1[0].contains(
                "pins that hold more of it keep it up (no material is stiff enough: it would \
                 take `[material] youngs_modulus` of 6.6e14 Pa, past diamond's 1.2e12)"
            ) && !w1[0].contains("a stiffer material"),
            "{}",
            w1[0]
        );
        // The restart's advice of a gentler pull gives way to the cause.
        let restart = assess(&[full(0.44, 0.17), amplified.clone()])
            .untrusted
            .into_iter()
            .find(|w| w.contains("the test amplifies its error"))
            .unwrap();
        assert!(!restart.contains("gentler pull"), "{restart}");
        assert!(
            restart.contains("the body's weight, not the drag"),
            "{restart}"
        );
        let pca = MethodReport {
            method: Method::Pca,
            ..amplified.clone()
        };
        let two = said(&[full(0.44, 0.17), amplified.clone(), pca]);
        assert!(
            two[0].contains("which is how neural-cubature and pca drift (above)"),
            "{}",
            two[0]
        );
        assert!(!w[0].contains("  "), "{}", w[0]);
        assert!(!w[0].contains("`[mesh] scale`"), "{}", w[0]);
        // The same fall 44 times larger (a part in centimetres read as metres): the units come
        // first, before a modulus 10 times stiffer.
        let mut large = full(0.44 * 44.0, 0.17 * 44.0);
        if let Some(b) = &mut large.buckling {
            b.size *= 44.0;
        }
        let w = said(&[large, amplified.clone()]);
        assert!(
            w[0].contains(
                ". At 15.0 m across, the mesh may not be in metres: set `[mesh] scale` (0.01 \
                 for centimetres, 0.001 for millimetres). Else, if the body should stand as \
                 pinned, a stiffer material"
            ),
            "{}",
            w[0]
        );
        // Not where the drift is the method's own, the body moves little, or its weight
        // hardly sags it.
        assert!(said(&[full(0.44, 0.17), own]).is_empty());
        assert!(said(&[full(0.05, 0.17), amplified.clone()]).is_empty());
        assert!(said(&[full(0.44, 0.01), amplified.clone()]).is_empty());
        // A body that inverts elements as it falls gives way: said without any drift, with no
        // fall that might be meant.
        let inverting = |share: f64| MethodReport {
            compression: Some(crate::run::Compression {
                inverted_frames: 21,
                volume_ratio: -0.42,
                squeezed_share: share,
                ..full(0.6, 0.17).compression.unwrap()
            }),
            ..full(0.6, 0.17)
        };
        let w = said(&[inverting(0.005)]);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains(
                "; it inverts elements in 21 of the test's 100 frames (det F down to -0.42 at \
                 t = 0.75 s). If the body should stand"
            ),
            "{}",
            w[0]
        );
        assert!(!w[0].contains("if the fall is meant"), "{}", w[0]);
        assert!(!w[0].contains("drift"), "{}", w[0]);
        // Where the collapse warning says the inversions, the fall is said without them (no
        // method is restarted on such a reference, so there is no drift to name); one crushed
        // sliver in a few frames is not a body giving way.
        let w = said(&[inverting(0.02)]);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("its own weight carries it"), "{}", w[0]);
        assert!(w[0].contains("`[material] youngs_modulus` of"), "{}", w[0]);
        assert!(!w[0].contains("it inverts elements"), "{}", w[0]);
        assert!(!w[0].contains("drift"), "{}", w[0]);
        let sliver = MethodReport {
            compression: Some(crate::run::Compression {
                inverted_frames: 3,
                ..inverting(0.005).compression.unwrap()
            }),
            ..inverting(0.005)
        };
        assert!(said(&[sliver]).is_empty());
        assert_eq!(said(&[inverting(0.02), amplified]).len(), 1);
        // Carried past twice its size (a coil's plate pushed down through its base) is said
        // though nothing drifts or inverts; a fall that only swings about the pins is not.
        let own = with_restart(row(Method::Pca, 0.26, 0.001), 0.02, 0.5);
        let w = said(&[full(0.69, 0.17), own.clone()]);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains(
                "more than 2 times its size, beyond any swing about its pins: it stretched that \
                 far or passed through itself or its pins"
            ),
            "{}",
            w[0]
        );
        assert!(said(&[full(0.67, 0.17), own]).is_empty());
    }

    /// A body that buckles under its own weight is said on the row that carries the analysis,
    /// with the modulus that would keep it standing; one that only sags far before its load
    /// factor (the estimate does not hold there), or hangs, or stands, is not.
    #[test]
    fn a_body_that_buckles_under_its_weight_is_named() {
        let with = |load_factor: Option<f64>, sag: f64| MethodReport {
            buckling: Some(crate::run::Buckling {
                load_factor,
                sag,
                size: 0.4,
                standing_modulus: load_factor.map(|l| 1e5 / l),
                firm_modulus: crate::run::Buckling::firm(
                    1e5,
                    sag,
                    0.4,
                    load_factor.map(|l| 1e5 / l),
                ),
                converged: true,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let w = assess(&[with(Some(0.5), 0.002)]).untrusted;
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with("full: the body buckles under its own weight"),
            "{}",
            w[0]
        );
        assert!(w[0].contains("0.50 times its weight"), "{}", w[0]);
        assert!(
            w[0].contains("youngs_modulus` of 4.00e5 Pa or more, 2 times the 2.00e5 Pa"),
            "{}",
            w[0]
        );
        // The modulus that firms a body up keeps the margin over its buckling modulus where
        // the sag alone asks for less.
        assert_eq!(crate::run::Buckling::firm(1e5, 0.002, 0.4, Some(2e5)), 4e5);
        assert!((crate::run::Buckling::firm(1e5, 0.2, 0.4, Some(2e5)) - 1e6).abs() < 1e-6);
        assert!(!w[0].contains("  "), "{}", w[0]);
        assert!(!w[0].contains("`[mesh] scale`"), "{}", w[0]);
        // A body that would need a modulus past any material's is told the pins and the load.
        let pinned_at_a_point = assess(&[with(Some(1e-8), 0.002)]).untrusted;
        assert!(
            pinned_at_a_point[0].contains(
                "pins where it buckles or a lighter load (`[gravity]`) keep it standing (no \
                 material is stiff enough: it would take `[material] youngs_modulus` of 2.00e13 Pa"
            ) && !pinned_at_a_point[0].contains("a stiffer material"),
            "{}",
            pinned_at_a_point[0]
        );
        let mut large = with(Some(0.5), 0.002);
        if let Some(b) = &mut large.buckling {
            b.size = 10.0;
        }
        let w = assess(&[large]).untrusted;
        assert!(
            w[0].contains("instability; at 10.0 m across, the mesh may not be in metres"),
            "{}",
            w[0]
        );
        for quiet in [
            with(Some(0.33), 1.2),
            with(Some(2.0), 0.002),
            with(None, 0.002),
        ] {
            assert_eq!(
                assess(std::slice::from_ref(&quiet)),
                Assessment::default(),
                "{quiet:?}"
            );
        }
    }

    /// A method close on average and far where the body moves most (a plate that starts to
    /// buckle near the test's end) drifts by its space–time error: its restart is measured and
    /// said, and a trajectory outside the training poses has not held.
    #[test]
    fn a_method_far_off_where_the_body_moves_most_drifts() {
        let plate = MethodReport {
            trajectory_error: 0.058,
            step_error: 0.0016,
            ..row(Method::Pca, 0.026, 0.0026)
        };
        assert!(drifting(&plate));
        assert!(!drifting(&MethodReport {
            trajectory_error: 0.02,
            ..plate.clone()
        }));
        let a = assess(&[with_restart(plate.clone(), 0.004, 0.03)]);
        assert!(a.caveats.is_empty(), "{a:#?}");
        assert_eq!(a.untrusted.len(), 1, "{a:#?}");
        assert!(
            a.untrusted[0].starts_with("pca: the drift is mostly the reduced steps' own"),
            "{a:#?}"
        );
        // Outside the training poses as well: not "held", whatever the mean says.
        let outside = MethodReport {
            training_distance: 0.23,
            training_distance_time: 0.9,
            ..plate
        };
        let a = assess(std::slice::from_ref(&outside));
        assert!(
            a.untrusted
                .iter()
                .any(|w| w.contains("beyond the training poses")),
            "{a:#?}"
        );
        assert!(a.caveats.iter().all(|w| !w.contains("held here")), "{a:#?}");
        let a = assess(&[MethodReport {
            trajectory_error: 0.03,
            ..outside
        }]);
        assert!(a.caveats.iter().any(|w| w.contains("held here")), "{a:#?}");
    }

    /// A drift of the steps' own, where the reference put in the subspace carries several
    /// times its energy, is blamed on that strain (a chain whose link turned), not on the
    /// subspace's size alone; a ratio near 1 keeps the plain advice.
    #[test]
    fn a_drift_from_a_strained_projection_says_so() {
        let chain = MethodReport {
            step_error: 0.033,
            ..row(Method::Pca, 0.16, 0.011)
        };
        let said = |strain: Option<(f64, f64)>| {
            let a = assess(&[with_restart(
                MethodReport {
                    projected_strain: strain,
                    ..chain.clone()
                },
                0.08,
                0.18,
            )]);
            a.untrusted
                .iter()
                .find(|w| w.contains("the drift is mostly the reduced steps' own"))
                .cloned()
                .unwrap_or_else(|| panic!("{a:#?}"))
        };
        let strained = said(Some((18.9, 0.36)));
        assert!(
            strained.contains("only by straining it")
                && strained.contains("at t = 0.36 s")
                && strained.contains("carries 18.9 times its elastic energy"),
            "{strained}"
        );
        for plain in [None, Some((1.53, 0.8)), Some((2.9, 0.5))] {
            let w = said(plain);
            assert!(
                !w.contains("straining") && w.contains("which a larger subspace lowers"),
                "{w}"
            );
        }
        assert!(
            strained.contains("a larger subspace (in `[pca]`"),
            "{strained}"
        );
        // A neural method whose latent space misses the test far more than the PCA basis: its
        // latent dimension, not the basis (a tester's d = 2 was sent to `[pca]`).
        let neural = with_restart(
            MethodReport {
                projected_strain: Some((18.9, 0.36)),
                ..MethodReport {
                    method: Method::Neural,
                    ..chain.clone()
                }
            },
            0.08,
            0.18,
        );
        let pca = MethodReport {
            subspace_error: 0.002,
            ..row(Method::Pca, 0.01, 0.002)
        };
        let a = assess(&[pca, neural]);
        let w = a
            .untrusted
            .iter()
            .find(|w| w.starts_with("neural:") && w.contains("only by straining it"))
            .unwrap_or_else(|| panic!("{a:#?}"));
        assert!(
            w.contains(
                "or a larger `[autoencoder] latent_dim` (its subspace misses the test 6 times"
            ),
            "{w}"
        );
        // With its d and k, the value to try, at most k; at d = k, the basis.
        let named = |(latent_dim, pca_dim)| {
            larger_latent(&MethodReport {
                latent: Some(crate::run::Latent {
                    latent_dim,
                    pca_dim,
                }),
                ..row(Method::Neural, 0.05, 0.012)
            })
        };
        assert_eq!(
            named((19, 37)),
            "a larger `[autoencoder] latent_dim` (now 19; 37, at most the PCA basis's 37)"
        );
        assert!(named((4, 37)).contains("(now 4; 8, at most"));
        assert!(
            named((37, 37)).starts_with(
                "a larger PCA basis (`[autoencoder] latent_dim` = 37 is already at least the \
                 basis's 37 columns"
            ),
            "{}",
            named((37, 37))
        );
        assert!(!w.contains("in `[pca]`"), "{w}");
    }

    /// A reduced trajectory that carries a vertex more than twice the body's size from the full
    /// one blew up: said so, with the rule named for a cubature method, and not called an
    /// extrapolation; one within that is not.
    #[test]
    fn a_reduced_trajectory_that_blows_up_is_not_called_an_extrapolation() {
        let full = MethodReport {
            buckling: Some(crate::run::Buckling {
                load_factor: None,
                sag: 0.01,
                size: 0.277,
                standing_modulus: None,
                firm_modulus: 1e6,
                converged: true,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let method = |max_vertex_error| MethodReport {
            max_vertex_error,
            cubature_elements: 1,
            training_distance: 0.94,
            training_distance_time: 0.5,
            ..row(Method::PcaCubature, 1.5, 0.01)
        };
        let w = assess(&[full.clone(), method(1.16)]).untrusted;
        let line = w
            .iter()
            .find(|l| l.contains("blew up"))
            .unwrap_or_else(|| panic!("{w:#?}"));
        assert!(
            line.starts_with(
                "pca-cubature: a vertex ends up 1.160 m from its full-space position, 4.2 times \
                 the body's 0.277 m bounding-box diagonal"
            ) && line.contains("its cubature rule (1 element) may leave"),
            "{line}"
        );
        assert!(w.iter().all(|l| !l.contains("extrapolates")), "{w:#?}");
        let held = assess(&[full, method(0.3)]).untrusted;
        assert!(held.iter().all(|l| !l.contains("blew up")), "{held:#?}");
        assert!(held.iter().any(|l| l.contains("extrapolates")), "{held:#?}");
    }

    /// The settings that keep more PCA coefficients are spelled out in the first printed line
    /// that advises them; the others point to it, while the lists keep each line whole.
    #[test]
    fn the_larger_basis_settings_are_spelled_out_once() {
        let rows = [
            row(Method::Full, 0.0, 0.0),
            row(Method::Pca, 0.25, 0.2),
            row(Method::PcaCubature, 0.25, 0.2),
            row(Method::Neural, 0.25, 0.2),
        ];
        let a = assess(&rows);
        let text = a.text("");
        assert_eq!(text.matches(LARGER_PCA).count(), 1, "{text}");
        assert_eq!(text.matches("the settings said above").count(), 2, "{text}");
        let first = text.find(LARGER_PCA).unwrap();
        let line = text.lines().find(|l| l.contains(LARGER_PCA)).unwrap();
        assert!(
            line.starts_with("- pca: ") && text[..first].contains("- pca: "),
            "{text}"
        );
        // The lists keep every line whole, for an export that keeps its method's lines.
        assert_eq!(
            a.untrusted
                .iter()
                .filter(|l| l.contains(LARGER_PCA))
                .count(),
            3,
            "{:#?}",
            a.untrusted
        );
    }

    /// A drift of the steps' own names its cause before "a larger subspace": the cubature rule
    /// where the same subspace over every element follows the test far closer (a tester's bunny
    /// was told both), a body that buckles under its weight where it does (a pretzel whose
    /// subspace held the test to 0.13 %).
    #[test]
    fn a_drift_of_the_steps_own_names_the_rule_or_the_buckling_first() {
        let own = |r: MethodReport| with_restart(r, 0.002, 0.2);
        let drift = |rows: &[MethodReport]| -> String {
            let a = assess(rows);
            a.untrusted
                .iter()
                .find(|w| w.contains("the drift is mostly the reduced steps' own"))
                .cloned()
                .unwrap_or_else(|| panic!("{a:#?}"))
        };
        // The bunny: pca-cubature 12 %, pca 1.4 %, their steps 0.9 and 0.6 % off.
        let pca = MethodReport {
            step_error: 0.006,
            ..row(Method::Pca, 0.014, 0.002)
        };
        let pc = MethodReport {
            step_error: 0.009,
            ..row(Method::PcaCubature, 0.12, 0.002)
        };
        let w = drift(&[pca, own(pc.clone())]);
        assert!(
            w.contains("most of it the cubature rule's") && !w.contains("larger subspace"),
            "{w}"
        );
        // The pretzel: a reference that buckles, steps 0.28 % off a subspace of 0.13 %.
        let full = MethodReport {
            buckling: Some(crate::run::Buckling {
                load_factor: Some(0.6),
                sag: 0.002,
                size: 0.4,
                standing_modulus: Some(1.7e5),
                firm_modulus: 3.4e5,
                converged: true,
            }),
            ..row(Method::Full, 0.0, 0.0)
        };
        let pca = MethodReport {
            step_error: 0.0028,
            ..row(Method::Pca, 0.26, 0.0013)
        };
        let w = drift(&[full, own(pca.clone())]);
        assert!(
            w.contains("in a body that buckles under its own weight (above)")
                && w.contains("holds to 0.1 %")
                && !w.contains("[pca]"),
            "{w}"
        );
        // Without the buckling, the plain advice.
        assert!(drift(&[own(pca)]).contains("which a larger subspace lowers"));
    }

    /// A drifting method's restart becomes its warning: whether the full dynamics make most of
    /// its drift from its early error, with its one-step error.
    #[test]
    fn a_restart_says_whether_the_test_amplifies_the_methods_error() {
        let drifting_row = MethodReport {
            step_error: 0.004,
            ..row(Method::Pca, 0.12, 0.002)
        };
        assert!(drifting(&drifting_row));
        assert!(!drifting(&row(Method::Pca, 0.04, 0.002)), "within 5 %");
        assert!(
            !drifting(&row(Method::Pca, 0.12, 0.06)),
            "the subspace misses it"
        );
        assert!(!drifting(&row(Method::Full, 0.12, 0.0)));
        assert!(
            !drifting(&MethodReport {
                failure: Some("frame 3: no".into()),
                ..drifting_row.clone()
            }),
            "a method that stopped is warned of as such"
        );
        let restarted = |mean: f64| with_restart(drifting_row.clone(), mean, 0.2);
        let w = assess(&[restarted(0.15)]).untrusted;
        assert_eq!(w.len(), 1, "{w:#?}");
        assert!(
            w[0].starts_with("pca: the test amplifies its error"),
            "{}",
            w[0]
        );
        assert!(
            w[0].contains("t = 0.30 s, where it is 0.7 % off, ends 30.0 %")
                && w[0].contains("the method 20.0 %")
                && w[0].contains("(0.40 %)"),
            "{}",
            w[0]
        );
        let w = assess(&[restarted(0.02)]).untrusted;
        assert!(
            w[0].starts_with("pca: the drift is mostly the reduced steps' own"),
            "{}",
            w[0]
        );
        assert!(
            w[0].ends_with(&format!(
                "which a larger subspace lowers ({LARGER_PCA}; for the neural methods also \
                 `[autoencoder] latent_dim`)"
            )),
            "{}",
            w[0]
        );
        assert!(!w[0].contains("from states its subspace holds"), "{}", w[0]);
        // A subspace that holds the frames ten times closer than a step lands (a tester's
        // mushroom: 0.02 % and 0.24 %) is said with both.
        let close = MethodReport {
            step_error: 0.0024,
            ..with_restart(row(Method::Pca, 0.12, 0.0002), 0.02, 0.2)
        };
        let w = assess(&[close]).untrusted;
        assert!(
            w.iter().any(|w| w.contains(
                "each step is 0.24 % off (one-step error), from states its subspace holds to \
                 0.02 %: the energy along what the subspace leaves out"
            )),
            "{w:?}"
        );
        // A cubature method whose subspace over every element steps at most half as far off:
        // the rule makes the steps' error, and the subspace is not blamed.
        let ruled = |every_step: f64| {
            let nc = with_restart(
                MethodReport {
                    step_error: 0.0216,
                    ..row(Method::NeuralCubature, 0.062, 0.002)
                },
                0.005,
                0.06,
            );
            let every = MethodReport {
                step_error: every_step,
                ..row(Method::Neural, 0.004, 0.002)
            };
            assess(&[every, nc]).untrusted
        };
        let w = ruled(0.002);
        let own = w.iter().find(|w| w.contains("reduced steps' own")).unwrap();
        assert!(own.ends_with("each step is 2.16 % off (one-step error), most of it the cubature rule's: neural over every element steps 0.20 % off from the same states (below)"), "{own}");
        // Its steps land ten times further off than its subspace holds the frames, but the same
        // subspace over every element follows the test 15 times closer (0.4 against 6.2 %):
        // the rule still, by its trajectory; likewise with no step error to compare.
        for every_step in [0.012, 0.0] {
            let w = ruled(every_step);
            let own = w.iter().find(|w| w.contains("reduced steps' own")).unwrap();
            assert!(
                own.contains("most of it the cubature rule's, whose trajectory")
                    && !own.contains("larger subspace"),
                "{own}"
            );
        }
        // Drifting by its space–time error with a mean under 5 %, so no rule warning follows:
        // the remedy is said in place of "(below)".
        let nc = with_restart(
            MethodReport {
                step_error: 0.0216,
                trajectory_error: 0.08,
                ..row(Method::NeuralCubature, 0.045, 0.002)
            },
            0.005,
            0.06,
        );
        let every = MethodReport {
            step_error: 0.002,
            ..row(Method::Neural, 0.004, 0.002)
        };
        let w = assess(&[every, nc]).untrusted;
        assert_eq!(w.len(), 1, "{w:#?}");
        assert!(w[0].ends_with("from the same states; a larger rule narrows that: a smaller `[cubature] tolerance`, or a larger `max_elements` where the cubature stage's line says the element budget stopped it"), "{}", w[0]);
        // The boundary: the full simulation making half the method's later error amplifies.
        let w = assess(&[restarted(AMPLIFIED_SHARE * 0.2)]).untrusted;
        assert!(w[0].contains("the test amplifies"), "{}", w[0]);
        let w = assess(&[restarted(0.99 * AMPLIFIED_SHARE * 0.2)]).untrusted;
        assert!(w[0].contains("mostly the reduced steps' own"), "{}", w[0]);
        assert!(
            assess(&[row(Method::Full, 0.0, 0.0), drifting_row])
                .untrusted
                .iter()
                .all(|w| !w.contains("started from its state")),
            "no restart measured, nothing said"
        );
    }

    /// Over 20 % off with a restart measured: the drift's advice is the restart's, not the
    /// generic one.
    #[test]
    fn an_untrusted_drift_with_a_restart_defers_to_it() {
        let r = with_restart(row(Method::NeuralCubature, 0.3, 0.003), 0.3, 0.35);
        let w = assess(&[r]).untrusted;
        assert_eq!(w.len(), 2, "{w:#?}");
        assert!(
            w[0].ends_with("so the trajectory drifts away (below)"),
            "{}",
            w[0]
        );
        assert!(
            w[1].starts_with("neural-cubature: the test amplifies"),
            "{}",
            w[1]
        );
    }

    /// A cubature method far behind the same subspace over every element is told to try a
    /// larger rule; close to it, or itself close to the full trajectory, it is not.
    #[test]
    fn a_rule_that_makes_the_error_is_named() {
        let advice = |every: f64, cubature: f64| {
            assess(&[
                row(Method::Neural, every, 0.001),
                row(Method::NeuralCubature, cubature, 0.001),
            ])
            .untrusted
            .into_iter()
            .filter(|w| w.contains("its cubature rule adds"))
            .collect::<Vec<_>>()
        };
        let w = advice(0.25, 0.33);
        assert_eq!(w.len(), 1, "{w:#?}");
        assert!(
            w[0].starts_with("neural-cubature: its cubature rule adds 8 percentage points: 33.0 %")
                && w[0].contains("against 25.0 % for neural over every element")
                && w[0].contains("a smaller `[cubature] tolerance`"),
            "{}",
            w[0]
        );
        // Within a quarter of the error over every element, or under 5 %: none.
        assert!(advice(0.25, 0.30).is_empty());
        assert!(advice(0.02, 0.045).is_empty());
        // A failed row on either side: nothing to compare.
        let failed = |r: MethodReport| MethodReport {
            failure: Some("no convergence".into()),
            ..r
        };
        for rows in [
            [
                failed(row(Method::Neural, 0.25, 0.001)),
                row(Method::NeuralCubature, 0.33, 0.001),
            ],
            [
                row(Method::Neural, 0.25, 0.001),
                failed(row(Method::NeuralCubature, 0.33, 0.001)),
            ],
        ] {
            let w = assess(&rows).untrusted;
            assert!(w.iter().all(|w| !w.contains("cubature rule")), "{w:#?}");
        }
        // Without the full rule's row there is nothing to compare with.
        let alone = assess(&[row(Method::PcaCubature, 0.3, 0.001)]).untrusted;
        assert!(
            alone.iter().all(|w| !w.contains("cubature rule")),
            "{alone:#?}"
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
        assert_eq!(w.len(), 4, "{w:#?}");
        assert!(w[0].starts_with("pca-cubature: 92 %"), "{}", w[0]);
        assert!(w[0].contains("drift") && w[0].contains("2.3 %"), "{}", w[0]);
        assert!(
            w[1].starts_with("pca-cubature: its cubature rule adds 91 percentage points"),
            "{}",
            w[1]
        );
        assert!(
            w[2].starts_with("neural: its subspace alone is 22.0 %"),
            "{}",
            w[2]
        );
        assert!(w[2].contains("`[training] schedules`"), "{}", w[2]);
        assert!(
            w[3].starts_with("neural: 30 %") && w[3].contains("misses"),
            "{}",
            w[3]
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
            w[0].contains("it stays within 3.0 % of the full trajectory"),
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
        // The figure that decided it, against the threshold.
        assert!(
            w[0].contains(
                "it is 12.0 % from the full trajectory (on average; past 5 % an \
                 extrapolation is not taken as held)"
            ),
            "{}",
            w[0]
        );
        let text = assess(std::slice::from_ref(&far_and_off)).text("");
        assert!(
            text.starts_with("\nnot to be trusted:\n- neural-cubature"),
            "{text}"
        );
        // Where the same subspace over every element stayed within the training poses, the
        // rule takes the pose there: a larger rule, not more schedules.
        let w = assess(&[row(Method::Neural, 0.01, 0.01), far_and_off]).untrusted;
        let line = w
            .iter()
            .find(|l| l.starts_with("neural-cubature: at t"))
            .unwrap_or_else(|| panic!("{w:#?}"));
        assert!(
            line.contains("where neural over every element stays within them (0 % at most)"),
            "{line}"
        );
        assert!(line.contains("`max_elements`"), "{line}");
        assert!(!line.contains("`[training] schedules`"), "{line}");
        // A restart that could not run is said, not only logged.
        let failed = MethodReport {
            restart_failed: Some("element 69 is inverted".into()),
            ..row(Method::PcaCubature, 0.3, 0.01)
        };
        let w = assess(&[failed]).untrusted;
        assert!(
            w.iter().any(|l| l.starts_with(
                "pca-cubature: the full simulation started from its \
                                            state part way through the test could not run \
                                            (element 69 is inverted)"
            )),
            "{w:#?}"
        );
        // Several methods given the same advice: one caveat naming them, with the ranges of
        // their figures; a method given other advice keeps its own.
        let held = |method, distance: f64, time: f64, error: f64, seconds: f64| MethodReport {
            training_distance: distance,
            training_distance_time: time,
            training_seconds: seconds,
            ..row(method, error, 0.01)
        };
        let w = assess(&[
            held(Method::Pca, 0.34, 0.18, 0.015, 0.0),
            held(Method::PcaCubature, 0.35, 0.18, 0.02, 0.0),
            held(Method::Neural, 0.3, 0.9, 0.018, 0.6),
            held(Method::NeuralCubature, 0.35, 0.2, 0.025, 0.0),
        ])
        .caveats;
        assert_eq!(w.len(), 2, "{w:#?}");
        assert!(
            w[0].starts_with(
                "pca, pca-cubature, neural-cubature: at t = 0.180–0.200 s their poses go \
                 34–35 % of their size beyond the training poses"
            ) && w[0].contains("they stay within 1.5–2.5 % of the full trajectory"),
            "{}",
            w[0]
        );
        assert!(
            w[1].starts_with("neural: at t = 0.900 s its pose goes 30 % of its size")
                && w[1].contains("later than any training schedule lasts"),
            "{}",
            w[1]
        );
        // Each method is said to extrapolate with what it has: `neural` no cubature rule, `pca`
        // neither a decoder nor a rule.
        assert!(
            w[1].contains("so the decoder extrapolates there"),
            "{}",
            w[1]
        );
        assert!(w[0].contains("(basis, decoder, cubature rule)"), "{}", w[0]);
        // Far from training later than the schedules last: the schedules' length is named.
        let late = MethodReport {
            training_distance: 0.3,
            training_distance_time: 0.8,
            training_seconds: 0.6,
            ..row(Method::Pca, 0.03, 0.01)
        };
        let w = assess(&[late]).caveats;
        assert_eq!(w.len(), 1, "{w:#?}");
        assert!(w[0].contains("so the basis, chosen from the training poses, may miss"));
        assert!(
            !w[0].contains("decoder") && !w[0].contains("cubature"),
            "{}",
            w[0]
        );
        assert!(
            w[0].contains("later than any training schedule lasts (0.60 s)")
                && w[0].contains("`[training] frames_per_schedule`"),
            "{}",
            w[0]
        );
    }

    /// A basis `max_dimension` stopped is named before the methods' lines where a method ends
    /// over 5 % off (with the count the rule asks for), as a caveat where every method held;
    /// nothing where the rule was met.
    #[test]
    fn a_basis_stopped_by_max_dimension_is_named_before_the_methods() {
        let capped = |r: MethodReport, wanted: Option<usize>| MethodReport {
            basis_cap: Some(crate::run::BasisCap {
                max_dimension: 8,
                rule: "`[pca] explained_energy` = 0.9999999".into(),
                wanted,
            }),
            ..r
        };
        let rows = [
            capped(row(Method::Full, 0.0, 0.0), Some(23)),
            row(Method::Pca, 0.25, 0.06),
        ];
        let w = assess(&rows).untrusted;
        assert!(w.len() >= 2, "{w:#?}");
        assert!(
            w[0].starts_with("the PCA basis: `[pca] max_dimension` = 8 stopped it")
                && w[0].contains("`[pca] explained_energy` = 0.9999999 asks for 23")
                && w[0].contains("pca 25.0 % from the full trajectory (on average)")
                && w[0].contains("raise it to 23 first: every figure of the reduced methods"),
            "{}",
            w[0]
        );
        assert!(w[1].starts_with("pca: "), "{w:#?}");
        // Two methods as far off: the first is named.
        let level = [
            capped(row(Method::Full, 0.0, 0.0), Some(23)),
            row(Method::Pca, 0.25, 0.06),
            row(Method::Neural, 0.25, 0.06),
        ];
        assert!(
            assess(&level).untrusted[0].contains("with pca 25.0 %"),
            "{:#?}",
            assess(&level).untrusted
        );
        // Every method within 5 %: a caveat, the count unknown (the vertex-error scan).
        let held = [
            capped(row(Method::Full, 0.0, 0.0), None),
            row(Method::Pca, 0.02, 0.01),
        ];
        let a = assess(&held);
        assert!(a.untrusted.is_empty(), "{:#?}", a.untrusted);
        assert_eq!(a.caveats.len(), 1, "{:#?}", a.caveats);
        assert!(
            a.caveats[0].contains("short of `[pca] explained_energy`")
                && a.caveats[0].contains("every method held this test within 5 %")
                && a.caveats[0].ends_with("raise it first"),
            "{}",
            a.caveats[0]
        );
        // A method that stopped makes it a warning whatever the others' errors.
        let stopped = [
            capped(row(Method::Full, 0.0, 0.0), Some(23)),
            MethodReport {
                failure: Some("non-finite energy".into()),
                ..row(Method::Neural, 0.01, 0.01)
            },
        ];
        let w = assess(&stopped).untrusted;
        assert!(
            w[0].contains("with neural stopped before the last frame"),
            "{w:#?}"
        );
        // A met rule says nothing.
        let met = [row(Method::Full, 0.0, 0.0), row(Method::Pca, 0.25, 0.06)];
        assert!(
            assess(&met)
                .untrusted
                .iter()
                .chain(&assess(&met).caveats)
                .all(|l| !l.contains("max_dimension` = 8")),
        );
    }
}
