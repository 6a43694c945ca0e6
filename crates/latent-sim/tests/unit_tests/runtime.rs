//! The interactive API, the same on the reduced runtime and in full space: handles pull their
//! vertices toward their targets and let go, several at once; gravity, reset, read-back.

use fem_core::Vec3;
use latent_sim::model::Rows;
use latent_sim::{
    FullRuntime, Interactive, ReducedError, ReducedModel, ReducedRuntime, RuntimeError,
};

use super::models::{Kind, bar, build, build_with_rule, snapshot_basis, surface_rule, tip};

/// The bar's PCA model (every row) and its full-space simulator: one mesh, two simulators.
fn simulators(g: f64) -> (ReducedModel, FullRuntime) {
    let m = bar([6, 2, 2], g);
    let basis = snapshot_basis(&m, 12);
    let model = build(Kind::Pca, &m, &basis, Rows::All);
    let full = FullRuntime::from_model(&model).unwrap();
    (model, full)
}

/// The mean position of `vertices`.
fn centroid<S: Interactive>(sim: &mut S, vertices: &[usize]) -> Vec3 {
    let mut x = vec![0.0; 3 * sim.rest_positions().len()];
    sim.positions_into(&mut x).unwrap();
    vertices.iter().fold(Vec3::zeros(), |s, &v| {
        s + Vec3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2])
    }) / vertices.len() as f64
}

/// The largest distance of a vertex from its rest position.
fn max_displacement<S: Interactive>(sim: &mut S) -> f64 {
    let mut x = vec![0.0; 3 * sim.rest_positions().len()];
    sim.positions_into(&mut x).unwrap();
    x.chunks_exact(3)
        .zip(sim.rest_positions())
        .map(|(x, r)| (Vec3::new(x[0], x[1], x[2]) - r).norm())
        .fold(0.0, f64::max)
}

/// Moves each handle's target in a straight line from its start to its end over 30 steps, as
/// a hand drags, then holds it for 60.
fn drag<S: Interactive>(sim: &mut S, moves: &[(latent_sim::Handle, Vec3, Vec3)]) {
    for step in 1..=90 {
        let s = (step as f64 / 30.0).min(1.0);
        for &(h, from, to) in moves {
            sim.move_handle(h, (from + (to - from) * s).into()).unwrap();
        }
        sim.step().unwrap();
    }
}

/// Without gravity: grab the tip, lift its target 10 cm, let go.
fn drag_and_release<S: Interactive>(sim: &mut S, tip: &[usize], what: &str) {
    sim.set_gravity(false);
    let start = centroid(sim, tip);
    let h = sim.grab(tip, 400.0).unwrap();
    let target = start + Vec3::new(0.0, 0.1, 0.0);
    drag(sim, &[(h, start, target)]);
    let pulled = centroid(sim, tip);
    assert!(
        (pulled - target).norm() < 0.5 * (start - target).norm(),
        "{what}: the tip went from {start} to {pulled}, target {target}"
    );
    assert!(pulled.y > start.y + 0.03, "{what}: {pulled} from {start}");
    sim.release(h).unwrap();
    // Implicit Euler damps the bar's first bending mode (period about 1.4 s) by about a quarter
    // in 3 s: it swings about its rest shape, less and less.
    let (mut early_peak, mut late_peak, mut mean_height) = (0.0f64, 0.0f64, 0.0);
    for step in 0..300 {
        sim.step().unwrap();
        let d = max_displacement(sim);
        if step < 150 {
            early_peak = early_peak.max(d);
        } else {
            late_peak = late_peak.max(d);
            mean_height += centroid(sim, tip).y / 150.0;
        }
    }
    assert!(
        late_peak < 0.95 * early_peak,
        "{what}: the body swings up to {early_peak} from rest in the 1.5 s after the release, \
         {late_peak} in the 1.5 s after that"
    );
    assert!(
        (mean_height - start.y).abs() < 0.4 * (pulled.y - start.y),
        "{what}: the tip swings about {mean_height}, rest {}, pulled to {}",
        start.y,
        pulled.y
    );
    assert!(matches!(sim.release(h), Err(RuntimeError::UnknownHandle(g)) if g == h));
}

#[test]
fn a_handle_pulls_toward_its_target_and_the_body_returns_toward_rest_after_release() {
    let (model, mut full) = simulators(-9.81);
    let tip = tip(&model.full_space_model().unwrap());
    drag_and_release(&mut model.simulator().unwrap(), &tip, "reduced");
    drag_and_release(&mut full, &tip, "full");
}

/// Preparing the first grab ahead changes nothing of what follows: the same drag steps to the
/// same displacements bit for bit, with the patch compliance on (the model's default), and
/// preparing twice, or in full space, is harmless.
#[test]
fn preparing_the_first_grab_ahead_changes_no_step() {
    let (model, mut full) = simulators(-9.81);
    let tip = tip(&model.full_space_model().unwrap());
    let run = |prepare: bool| {
        let mut sim = model.simulator().unwrap();
        if prepare {
            sim.prepare_grab();
            sim.prepare_grab();
        }
        let start = centroid(&mut sim, &tip);
        let h = sim.grab(&tip, 400.0).unwrap();
        drag(&mut sim, &[(h, start, start + Vec3::new(0.0, 0.1, 0.0))]);
        let mut x = vec![0.0; 3 * sim.rest_positions().len()];
        sim.positions_into(&mut x).unwrap();
        x
    };
    let prepared = run(true);
    assert_eq!(prepared, run(false));
    assert!(prepared.iter().all(|x| x.is_finite()));
    full.prepare_grab();
    full.step().unwrap();
}

/// Two handles, the tip sideways and the middle down (stiffer: a beam is stiffer there);
/// releasing one leaves the other pulling.
fn two_handles<S: Interactive>(sim: &mut S, tip: &[usize], middle: [f64; 3], what: &str) {
    sim.set_gravity(false);
    let a = sim.grab(tip, 400.0).unwrap();
    let b = sim.grab_near(middle, 0.15, 4000.0).unwrap();
    assert_ne!(a, b);
    let tip0 = centroid(sim, tip);
    let middle = Vec3::from(middle);
    drag(
        sim,
        &[
            (a, tip0, tip0 + Vec3::new(0.0, 0.0, 0.08)),
            (b, middle, middle - Vec3::new(0.0, 0.05, 0.0)),
        ],
    );
    let near_middle: Vec<usize> = (0..sim.rest_positions().len())
        .filter(|&v| (sim.rest_positions()[v] - middle).norm() <= 0.15)
        .collect();
    let mid = centroid(sim, &near_middle);
    let up = centroid(sim, tip);
    assert!(up.z > tip0.z + 0.02, "{what}: tip at {up}");
    assert!(mid.y < middle.y - 0.02, "{what}: middle at {mid}");
    sim.release(b).unwrap();
    for _ in 0..60 {
        sim.step().unwrap();
    }
    assert!(
        centroid(sim, tip).z > tip0.z + 0.02,
        "{what}: the tip handle let go"
    );
    assert!(matches!(
        sim.release(b),
        Err(RuntimeError::UnknownHandle(_))
    ));
    sim.release(a).unwrap();
}

#[test]
fn two_handles_pull_at_once_and_release_independently() {
    let (model, mut full) = simulators(-9.81);
    let tip = tip(&model.full_space_model().unwrap());
    // The middle of the bar: the surface vertices around it are its cross-section's ring.
    let middle = [0.5, 0.1, 0.1];
    two_handles(&mut full, &tip, middle, "full");
    two_handles(&mut model.simulator().unwrap(), &tip, middle, "reduced");
}

/// A handle is its simulator's: on another one (of the same model, where the count of handles
/// is the same) it is refused, not taken for that simulator's own handle of the same number.
#[test]
fn a_handle_of_another_simulator_is_refused() {
    let (model, mut full) = simulators(-9.81);
    let mut reduced = model.simulator().unwrap();
    let mut other = model.simulator().unwrap();
    let n = full.rest_positions().len();
    let theirs = reduced.grab(&[n - 1], 10.0).unwrap();
    let own = other.grab(&[n - 1], 10.0).unwrap();
    assert_eq!(
        theirs.to_string(),
        own.to_string(),
        "both are the first handle"
    );
    assert_ne!(theirs, own);
    for r in [
        other.move_handle(theirs, [0.0; 3]),
        other.release(theirs),
        full.release(own),
    ] {
        let err = r.unwrap_err();
        assert!(matches!(err, RuntimeError::ForeignHandle(_)), "{err}");
        assert!(err.to_string().contains("another simulator"), "{err}");
    }
    other.release(own).unwrap();
    reduced.release(theirs).unwrap();
}

/// Errors of the interaction calls, the same for both simulators.
fn refusals<S: Interactive>(sim: &mut S, what: &str) {
    let n = sim.rest_positions().len();
    let released = sim.grab(&[n - 1], 10.0).unwrap();
    sim.release(released).unwrap();
    assert!(
        matches!(sim.release(released), Err(RuntimeError::UnknownHandle(h)) if h == released),
        "{what}"
    );
    assert!(matches!(sim.grab(&[], 1.0), Err(RuntimeError::NoVertices)));
    assert!(matches!(
        sim.grab(&[n], 1.0),
        Err(RuntimeError::NoSuchVertex { vertex, count }) if vertex == n && count == n
    ));
    assert!(matches!(
        sim.grab(&[0], -1.0),
        Err(RuntimeError::NotPositive { .. })
    ));
    assert!(matches!(
        sim.grab_near([5.0, 5.0, 5.0], 0.1, 1.0),
        Err(RuntimeError::NothingInReach { .. })
    ));
    // The message rounds what it names and says which surface it searched.
    let message = sim
        .grab_near([5.0, 1.0 / 3.0, 2e-7], 0.017043437257239995, 1.0)
        .unwrap_err()
        .to_string();
    let nearest = message
        .strip_prefix(
            "no surface vertex within 0.01704 of (5.000, 0.3333, 2.000e-7) where the surface is \
             now (deformed, not at rest); the nearest is ",
        )
        .and_then(|m| m.strip_suffix(" away: a larger radius, or a point nearer the body"))
        .and_then(|m| m.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("{message}"));
    // Every vertex lies within the unit cube, so the nearest is 4 to 5 away from x = 5.
    assert!((4.0..5.0).contains(&nearest), "{message}");
    assert!(matches!(
        sim.grab_near([f64::NAN, 0.0, 0.0], 0.1, 1.0),
        Err(RuntimeError::NotFinite { .. })
    ));
    let h = sim.grab(&[n - 1], 10.0).unwrap();
    assert!(matches!(
        sim.move_handle(h, [0.0, f64::INFINITY, 0.0]),
        Err(RuntimeError::NotFinite { .. })
    ));
    let mut short = vec![0.0f32; 5];
    assert!(matches!(
        sim.surface_positions_into(&mut short),
        Err(RuntimeError::BufferLength { .. })
    ));
    sim.release(h).unwrap();
}

#[test]
fn interaction_errors_are_typed() {
    let (model, mut full) = simulators(-9.81);
    refusals(&mut model.simulator().unwrap(), "reduced");
    refusals(&mut full, "full");
    // A force whose span ends before it starts is refused, naming the span.
    let mut backwards = super::models::tip_spring(&bar([6, 2, 2], -9.81), [0.0; 3], 0.5);
    backwards.start = 1.0;
    match full.add_force(backwards) {
        Err(e @ RuntimeError::ActiveSpan { .. }) => {
            assert!(e.to_string().contains("start = 1, end = 0.5"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    // So is an empty span, which would never act, at infinity too (a tester's was taken).
    for at in [0.5, f64::INFINITY] {
        let mut empty = super::models::tip_spring(&bar([6, 2, 2], -9.81), [0.0; 3], at);
        empty.start = at;
        assert!(
            matches!(full.add_force(empty), Err(RuntimeError::ActiveSpan { .. })),
            "an empty span at {at} taken"
        );
    }
    // A force whose span is over by now would never act: refused, saying whose clock spans are
    // on. One that ends later is taken.
    for _ in 0..5 {
        full.step().unwrap();
    }
    let now = full.time();
    for (end, refused) in [(now - 0.01, true), (now, true), (now + 1e-9, false)] {
        let late = super::models::tip_spring(&bar([6, 2, 2], -9.81), [0.0; 3], end);
        match full.add_force(late) {
            Err(e @ RuntimeError::SpanOver { .. }) if refused => {
                assert!(e.to_string().contains("simulation's clock"), "{e}")
            }
            Ok(h) if !refused => full.release(h).unwrap(),
            other => panic!("end {end} at t = {now}: {other:?}"),
        }
    }
    // A point load with a stiffness, which only springs have (as a scene's `[[force]]` says).
    let mut point = super::models::tip_spring(&bar([6, 2, 2], -9.81), [0.0; 3], 0.5);
    point.kind = latent_sim::ForceKind::Point;
    point.stiffness = 5.0;
    match full.add_force(point.clone()) {
        Err(e @ RuntimeError::PointStiffness(5.0)) => {
            assert!(e.to_string().contains("give it 0"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    point.stiffness = 0.0;
    // A point load a million times the force that strains the body by its size, and more, is
    // refused when added and when set; the limit itself is taken.
    let size = bar_diagonal();
    let limit = latent_sim::MAX_POINT_LOAD * model.material.youngs_modulus * size * size;
    let mut huge = point.clone();
    huge.keyframes[1][2] = -1e300;
    match full.add_force(huge) {
        Err(e @ RuntimeError::TooLarge { .. }) => {
            assert!(e.to_string().contains("give at most"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    let load = full.add_force(point.clone()).unwrap();
    assert!(matches!(
        full.set_load(load, [0.0, -1.01 * limit, 0.0]),
        Err(RuntimeError::TooLarge { .. })
    ));
    full.set_load(load, [0.0, -0.99 * limit, 0.0]).unwrap();
    full.release(load).unwrap();
    full.add_force(point).unwrap();
    // A spring a million times stiffer than the body at its size, and more, is refused by every
    // way of adding one (1e300 overflowed the energy at the next step); the limit itself is
    // taken.
    let mut reduced = model.simulator().unwrap();
    let body = model.material.youngs_modulus * bar_diagonal();
    let limit = latent_sim::MAX_SPRING_STIFFNESS * body;
    for stiffness in [1.01 * limit, 1e300, f64::MAX] {
        let mut spring = super::models::tip_spring(&bar([6, 2, 2], -9.81), [0.0; 3], 0.5);
        spring.stiffness = stiffness;
        for result in [
            reduced.grab(&[60], stiffness),
            reduced.grab_near([1.0, 0.1, 0.1], 0.05, stiffness),
            full.add_force(spring),
        ] {
            match result {
                Err(e @ RuntimeError::TooStiff { .. }) => {
                    let text = e.to_string();
                    // The limit as printed, written back, is taken (rounded up it was not).
                    let printed: f64 = text
                        .split("give at most ")
                        .nth(1)
                        .and_then(|t| t.split(' ').next())
                        .and_then(|t| t.parse().ok())
                        .unwrap_or_else(|| panic!("{text}"));
                    assert!(printed <= limit && printed > 0.999 * limit, "{text}");
                }
                other => panic!("{stiffness}: {other:?}"),
            }
        }
    }
    let h = reduced.grab(&[60], 0.999 * limit).unwrap();
    reduced.release(h).unwrap();
}

/// The bar's bounding-box diagonal (1 × 0.2 × 0.2 m).
fn bar_diagonal() -> f64 {
    (1.0f64 + 0.04 + 0.04).sqrt()
}

/// A vertex the mesh lists and no tet uses is no part of the body: grabbing it is refused (a
/// spring on it moved nothing), in full space as in a reduced model with every row.
#[test]
fn a_vertex_no_tet_uses_cannot_be_grabbed() {
    let mut m = bar([6, 2, 2], -9.81);
    let mut mesh = m.mesh.clone();
    mesh.vertices.push(Vec3::new(0.5, 1.0, 0.0));
    let loose = mesh.num_vertices() - 1;
    m = fem_core::integrator::FullSpaceModel::new(
        mesh,
        &super::material(),
        m.pinned.clone(),
        m.gravity,
        vec![],
    )
    .unwrap();
    let time = fem_core::integrator::TimeConfig {
        step: 0.01,
        frames: 10,
        quasi_static: false,
    };
    let mut full = FullRuntime::new(m, time, Default::default()).unwrap();
    for vertices in [vec![loose], vec![0, loose]] {
        match full.grab(&vertices, 10.0) {
            Err(e @ RuntimeError::NotInBody { vertex }) if vertex == loose => {
                assert!(e.to_string().contains("belongs to no tetrahedron"), "{e}")
            }
            other => panic!("{vertices:?}: {other:?}"),
        }
    }
    // Vertex 0 is pinned (the bar is clamped at x = 0): alone it moves nothing, and is refused;
    // beside a free vertex it is taken.
    match full.grab(&[0], 10.0) {
        Err(e @ RuntimeError::AllPinned { count: 1 }) => {
            assert!(e.to_string().contains("grab or load free vertices"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    let free = loose - 1;
    full.grab(&[0, free], 10.0).unwrap();
}

/// Under gravity, for 20 steps: the trajectory of the surface.
fn fall<S: Interactive>(sim: &mut S) -> Vec<Vec<f64>> {
    let mut buf = vec![0.0; 3 * sim.surface().vertices().len()];
    (0..20)
        .map(|_| {
            sim.step().unwrap();
            sim.surface_positions_into(&mut buf).unwrap();
            buf.clone()
        })
        .collect()
}

#[test]
fn reset_gravity_and_read_back() {
    let (model, mut full) = simulators(-9.81);
    let mut reduced = model.simulator().unwrap();
    // Reset gives a new simulator's trajectory, bit for bit.
    let first = fall(&mut reduced);
    reduced.reset();
    assert_eq!(reduced.steps(), 0);
    assert_eq!(fall(&mut reduced), first);
    let first_full = fall(&mut full);
    full.reset();
    assert_eq!(fall(&mut full), first_full);
    // Without gravity (or any force) a body at rest stays there.
    still(&mut reduced);
    still(&mut full);
    // The surface in f32 and f64 is the positions of the surface vertices, also while a handle
    // dents the patch it holds (the dent the basis lacks is in every read-back).
    reduced.set_gravity(true);
    for _ in 0..5 {
        reduced.step().unwrap();
    }
    let tip = tip(reduced.simulator().model());
    let before = centroid(&mut reduced, &tip);
    let h = reduced.grab(&tip, 400.0).unwrap();
    reduced
        .move_handle(h, (before + Vec3::new(0.0, 0.05, 0.0)).into())
        .unwrap();
    for grabbed in [false, true] {
        if grabbed {
            reduced.step().unwrap();
        }
        let mut all = vec![0.0; 3 * reduced.rest_positions().len()];
        reduced.positions_into(&mut all).unwrap();
        let ns = reduced.surface().vertices().len();
        let (mut s64, mut s32) = (vec![0.0f64; 3 * ns], vec![0.0f32; 3 * ns]);
        reduced.surface_positions_into(&mut s64).unwrap();
        reduced.surface_positions_into(&mut s32).unwrap();
        for (i, &v) in reduced.surface().vertices().iter().enumerate() {
            for c in 0..3 {
                let x = all[3 * v + c];
                assert!((s64[3 * i + c] - x).abs() <= 1e-14, "vertex {v}");
                assert!((s32[3 * i + c] as f64 - x).abs() <= 1e-7 * x.abs().max(1.0));
            }
        }
    }
    // Triangles index the surface vertices.
    let tris = reduced.surface().triangles();
    let ns = reduced.surface().vertices().len();
    assert!(!tris.is_empty() && tris.iter().flatten().all(|&i| (i as usize) < ns));
}

/// Reset, gravity off, ten steps: still at rest.
fn still<S: Interactive>(sim: &mut S) {
    sim.reset();
    sim.set_gravity(false);
    assert!(!sim.gravity());
    for _ in 0..10 {
        sim.step().unwrap();
    }
    assert!(max_displacement(sim) < 1e-12);
}

#[test]
fn a_model_with_the_rows_in_use_reads_its_surface_but_not_its_interior() {
    let m = bar([6, 2, 2], -9.81);
    let basis = snapshot_basis(&m, 8);
    let surface = m.mesh.surface_vertices();
    let rule = surface_rule(&m, 12);
    let model = build_with_rule(Kind::NeuralCubature, &m, &basis, Rows::Used, Some(&rule));
    let interior = (0..m.mesh.num_vertices())
        .find(|v| !surface.contains(v))
        .unwrap();
    assert!(!model.space.vertices.contains(&interior));
    let mut sim = model.simulator().unwrap();
    sim.step().unwrap();
    let mut x = vec![0.0; 3 * m.mesh.num_vertices()];
    assert!(matches!(
        sim.positions_into(&mut x),
        Err(RuntimeError::Reduced(ReducedError::NoBasisRows { vertex })) if vertex == interior
    ));
    assert!(matches!(
        sim.grab(&[interior], 10.0),
        Err(RuntimeError::Reduced(ReducedError::NoBasisRows { .. }))
    ));
    let mut surface = vec![0.0f32; 3 * sim.surface().vertices().len()];
    sim.surface_positions_into(&mut surface).unwrap();
    assert!(surface.iter().all(|x| x.is_finite()));
}

/// Gravity turned at run time, or in the model before its simulator is made, steps as a model
/// built under that gravity with the same basis: the reduced load is linear in the
/// acceleration. Full space the same, bit for bit.
#[test]
fn gravity_turned_steps_as_a_model_built_under_it() {
    let m = bar([6, 2, 2], -9.81);
    let basis = snapshot_basis(&m, 12);
    let model = build(Kind::Pca, &m, &basis, Rows::All);
    let sideways = [3.0, 4.0, -2.0];
    let mut turned_model = model.clone();
    turned_model.gravity = sideways;
    let under = build(
        Kind::Pca,
        &fem_core::integrator::FullSpaceModel::new(
            m.mesh.clone(),
            &turned_model.material,
            m.pinned.clone(),
            sideways.into(),
            vec![],
        )
        .unwrap(),
        &basis,
        Rows::All,
    );
    let expected = fall(&mut under.simulator().unwrap());
    let close = |a: &[Vec<f64>], what: &str| {
        for (a, b) in a.iter().flatten().zip(expected.iter().flatten()) {
            assert!((a - b).abs() <= 1e-12, "{what}: {a} against {b}");
        }
    };
    let mut sim = model.simulator().unwrap();
    assert_eq!(sim.gravity_acceleration(), [0.0, -9.81, 0.0]);
    sim.set_gravity_acceleration(sideways).unwrap();
    assert_eq!(sim.gravity_acceleration(), sideways);
    close(&fall(&mut sim), "turned at run time");
    close(
        &fall(&mut turned_model.simulator().unwrap()),
        "turned in the model",
    );
    // Off keeps the acceleration for when it is on again; a body at rest stays there.
    sim.reset();
    sim.set_gravity(false);
    still(&mut sim);
    assert_eq!(sim.gravity_acceleration(), sideways);
    assert!(matches!(
        sim.set_gravity_acceleration([0.0, f64::NAN, 0.0]),
        Err(RuntimeError::NotFinite { .. })
    ));
    let mut full = FullRuntime::from_model(&model).unwrap();
    full.set_gravity_acceleration(sideways).unwrap();
    assert_eq!(
        fall(&mut full),
        fall(&mut FullRuntime::from_model(&under).unwrap())
    );
}

/// A material changed after export is refused by the reduced simulator, which was made for the
/// old one, with what to do; full space steps it.
#[test]
fn a_material_changed_after_export_is_refused_with_what_to_do() {
    let (mut model, _) = simulators(-9.81);
    model.material.density *= 4.0;
    let e = model.simulator().unwrap_err().to_string();
    assert!(
        e.contains("not the one its reduced matrices were computed with")
            && e.contains("export the model again"),
        "{e}"
    );
    FullRuntime::from_model(&model).unwrap().step().unwrap();
}

/// A step says how far its solve got and which steps cost more: the reduced model's first
/// step builds its preconditioner, later ones reuse it; no step of a gentle fall falls back to
/// Newton; a solver held to two iterations does, reduced and in full space.
#[test]
fn a_step_says_how_far_it_solved_and_what_made_it_costly() {
    let (model, mut full) = simulators(-9.81);
    let mut sim = model.simulator().unwrap();
    let stats: Vec<_> = (0..5).map(|_| sim.step().unwrap()).collect();
    assert!(stats[0].preconditioner_rebuilt, "{:?}", stats[0]);
    assert!(!stats[1].preconditioner_rebuilt, "{:?}", stats[1]);
    for s in &stats {
        assert!(!s.newton_fallback, "{s:?}");
        assert!(
            s.relative_gradient <= model.solver.tolerance && s.iterations > 0,
            "{s:?}"
        );
    }
    let s = full.step().unwrap();
    let lbfgs = model.full_solver.method == fem_core::optim::SolverMethod::Lbfgs;
    assert_eq!(s.preconditioner_rebuilt, lbfgs, "{s:?}");
    assert!(!s.newton_fallback, "{s:?}");
    assert!(s.relative_gradient.is_finite(), "{s:?}");
    // L-BFGS held to two iterations at a time finishes a step to 1e-10 by rebuilding its
    // preconditioner at its iterate; with the rest state's, which a solve never rebuilds, it
    // cannot: Newton does, and the step says so.
    let mut capped = model.clone();
    (capped.solver.max_iterations, capped.solver.tolerance) = (2, 1e-10);
    let s = capped.simulator().unwrap().step().unwrap();
    assert!(s.preconditioner_rebuilt && !s.newton_fallback, "{s:?}");
    capped.preconditioning = latent_sim::Preconditioning::Rest;
    let s = capped.simulator().unwrap().step().unwrap();
    assert!(s.newton_fallback, "{s:?}");
    (
        capped.full_solver.max_iterations,
        capped.full_solver.tolerance,
    ) = (2, 1e-10);
    let s = FullRuntime::from_model(&capped).unwrap().step().unwrap();
    assert!(s.newton_fallback, "{s:?}");
}

/// Letting go moves nothing until the next step: the dent a spring makes outside the basis is
/// part of the state the last step computed (the default bar's patch jumped 5 cm back at
/// `release` before); the step after it moves the body, without the dent.
#[test]
fn releasing_a_handle_moves_nothing_before_the_next_step() {
    let (model, _) = simulators(-9.81);
    let mut sim = model.simulator().unwrap();
    sim.set_gravity(false);
    let tip = tip(sim.simulator().model());
    let start = centroid(&mut sim, &tip);
    let h = sim.grab(&tip, 4000.0).unwrap();
    drag(&mut sim, &[(h, start, start + Vec3::new(0.0, 0.1, 0.0))]);
    let mut held = vec![0.0; 3 * sim.surface().vertices().len()];
    sim.surface_positions_into(&mut held).unwrap();
    let mut all = vec![0.0; 3 * sim.rest_positions().len()];
    sim.positions_into(&mut all).unwrap();
    sim.release(h).unwrap();
    let mut after = held.clone();
    sim.surface_positions_into(&mut after).unwrap();
    assert_eq!(after, held);
    let mut all_after = all.clone();
    sim.positions_into(&mut all_after).unwrap();
    assert_eq!(all_after, all);
    sim.step().unwrap();
    sim.surface_positions_into(&mut after).unwrap();
    assert_ne!(after, held);
}

/// A clone steps as the original would, bit for bit, handles included: a program rolls back
/// to one. A handle made on either after the clone is unknown to the other.
#[test]
fn a_clone_steps_as_the_original_and_rolls_back() {
    let (model, full) = simulators(-9.81);
    let mut sim = model.simulator().unwrap();
    let tip = tip(sim.simulator().model());
    let start = centroid(&mut sim, &tip);
    let h = sim.grab(&tip, 4000.0).unwrap();
    let up = |sim: &mut ReducedRuntime, k: usize| {
        for i in 0..k {
            sim.move_handle(h, (start + Vec3::new(0.0, 0.002 * i as f64, 0.0)).into())
                .unwrap();
            sim.step().unwrap();
        }
        let mut x = vec![0.0; 3 * sim.rest_positions().len()];
        sim.positions_into(&mut x).unwrap();
        (x, sim.steps())
    };
    up(&mut sim, 12);
    let saved = sim.clone();
    let ahead = up(&mut sim, 20);
    let mut again = saved.clone();
    assert_eq!(up(&mut again, 20), ahead);
    // A grab after the copy is the copy's own.
    let mut other = saved.clone();
    let late = other.grab(&tip, 100.0).unwrap();
    assert!(matches!(
        sim.release(late),
        Err(RuntimeError::UnknownHandle(_))
    ));
    other.release(h).unwrap();
    let mut full_copy = full.clone();
    let mut full = full;
    assert_eq!(fall(&mut full_copy), fall(&mut full));
}

/// What a program reads back and sets per frame: a spring's target, the handles held, a point
/// load's force (the same steps as the load added with that value), the surface's velocities
/// ((x_n − x_{n−1})/h without springs), in full space too.
#[test]
fn targets_loads_handles_and_velocities() {
    let (model, full) = simulators(-9.81);
    let sim = model.simulator().unwrap();
    check_handles_and_velocities(sim, model.time_step, "reduced");
    check_handles_and_velocities(full, model.time_step, "full");
}

fn check_handles_and_velocities<S: Interactive + Clone>(mut sim: S, h: f64, what: &str) {
    let n = sim.surface().vertices().len();
    let (mut before, mut now, mut v) = (vec![0.0; 3 * n], vec![0.0; 3 * n], vec![0.0; 3 * n]);
    for _ in 0..3 {
        sim.surface_positions_into(&mut before).unwrap();
        sim.step().unwrap();
    }
    sim.surface_positions_into(&mut now).unwrap();
    sim.surface_velocities_into(&mut v).unwrap();
    let scale = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(scale > 0.0, "{what}: not moving");
    for ((x1, x0), v) in now.iter().zip(&before).zip(&v) {
        assert!(((x1 - x0) / h - v).abs() <= 1e-9 * scale, "{what}: {v}");
    }
    assert!(matches!(
        sim.surface_velocities_into(&mut [0.0; 2]),
        Err(RuntimeError::BufferLength { .. })
    ));
    let tip = tip_of(&sim);
    let spring = sim.grab(&tip, 400.0).unwrap();
    sim.move_handle(spring, [1.0, 0.3, 0.1]).unwrap();
    let target = sim.handle_target(spring).unwrap();
    assert!(
        (Vec3::from(target) - Vec3::new(1.0, 0.3, 0.1)).norm() < 1e-12,
        "{what}: {target:?}"
    );
    let mut load = super::models::tip_spring(&bar([6, 2, 2], -9.81), [0.0; 3], 0.5);
    (load.kind, load.stiffness, load.start, load.end) = (
        latent_sim::ForceKind::Point,
        0.0,
        f64::NEG_INFINITY,
        f64::INFINITY,
    );
    load.keyframes = vec![[0.0, 0.0, 0.0, 0.0]];
    let mut same = sim.clone();
    let point = sim.add_force(load.clone()).unwrap();
    assert_eq!(sim.handles(), vec![spring, point]);
    sim.set_load(point, [0.0, 0.0, 3.0]).unwrap();
    load.keyframes = vec![[0.0, 0.0, 0.0, 3.0]];
    same.add_force(load).unwrap();
    for _ in 0..3 {
        sim.step().unwrap();
        same.step().unwrap();
    }
    sim.surface_positions_into(&mut now).unwrap();
    same.surface_positions_into(&mut before).unwrap();
    assert_eq!(now, before, "{what}");
    assert!(matches!(
        sim.set_load(spring, [0.0; 3]),
        Err(RuntimeError::NotAPointLoad(_))
    ));
    assert!(matches!(
        sim.handle_target(point),
        Err(RuntimeError::NotASpring(_))
    ));
    sim.release(spring).unwrap();
    assert_eq!(sim.handles(), vec![point]);
}

/// The vertices at the bar's free end, from the rest positions.
fn tip_of<S: Interactive>(sim: &S) -> Vec<usize> {
    (0..sim.rest_positions().len())
        .filter(|&v| sim.rest_positions()[v].x > 0.999)
        .collect()
}
