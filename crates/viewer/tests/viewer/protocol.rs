//! The protocol of docs/viewer.md, driven by a Rust client on a port-0 server over the tiny beam.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fem_core::Vec3;
use fem_core::forces::ExternalForce;
use latent_sim::{Handle, Interactive, Real, RuntimeError, StepStats, Surface};
use tungstenite::Message;
use viewer::protocol::{Event, MAX_MESSAGE_BYTES};
use viewer::{Method, Session, Settings};

use crate::common::{Client, distance, falling_model, model, serve, session, tip};

#[test]
fn a_drag_pulls_the_vertex_to_the_target_and_the_body_relaxes_after_release() {
    let server = serve(session());
    let mut c = Client::connect(&server);
    // Full space: the tiny model's six PCA directions hold the tip's pull only roughly.
    c.send(r#"{"type":"method","name":"full"}"#);
    c.wait_until(
        |c| c.state.as_ref().is_some_and(|s| s.method == "full"),
        "full space",
    );
    // The free end's face, grabbed at its centre (its four corners within the radius) and
    // pulled up 0.2 m: the corner `v` has the same target offset.
    let (v, p) = tip();
    let centre = [p[0], 0.1, 0.1];
    let handle = c.grab(&format!(
        r#"{{"type":"grab","point":[{},{},{}],"radius":0.15}}"#,
        centre[0], centre[1], centre[2]
    ));
    let target = [p[0], p[1] + 0.2, p[2]];
    c.send(&format!(
        r#"{{"type":"move","handle":{handle},"target":[{},{},{}],"seq":7}}"#,
        centre[0],
        centre[1] + 0.2,
        centre[2]
    ));
    let applied = c.wait_event(|e| matches!(e, Event::Applied { .. }), "applied");
    let Event::Applied { seq, step } = applied else {
        unreachable!()
    };
    assert_eq!(seq, 7);
    // Halfway to the target within a few seconds of simulated pulling.
    c.wait_until(
        |c| c.step() >= step && distance(c.position(v), target) < 0.5 * distance(p, target),
        "the tip halfway to the target",
    );
    let pulled = distance(c.position(v), p);
    assert!(pulled > 0.1, "the tip moved {pulled} m");
    c.send(&format!(r#"{{"type":"release","handle":{handle}}}"#));
    c.wait_event(
        |e| matches!(e, Event::Released { handle: h, .. } if *h == handle),
        "released",
    );
    // Let go, the beam springs back through its rest shape.
    let start = Instant::now();
    let mut closest = f64::INFINITY;
    while start.elapsed() < Duration::from_secs(4) && closest > 0.3 * pulled {
        c.poll();
        closest = closest.min(distance(c.position(v), p));
    }
    assert!(
        closest < 0.3 * pulled,
        "after release the tip came back only to {closest} m from rest (pulled {pulled} m)"
    );
    server.shutdown();
}

#[test]
fn a_pull_beyond_the_training_poses_is_said_on_the_status_line() {
    let server = serve(session());
    let mut c = Client::connect(&server);
    c.wait_until(
        |c| {
            c.state
                .as_ref()
                .is_some_and(|s| s.beyond_training == Some(0.0))
        },
        "pca at rest, among its training poses",
    );
    // The free end pulled up far more than any training schedule pulled it.
    let (_, p) = tip();
    let handle = c.grab(&format!(
        r#"{{"type":"grab","point":[{},0.1,0.1],"radius":0.15}}"#,
        p[0]
    ));
    c.send(&format!(
        r#"{{"type":"move","handle":{handle},"target":[{},0.9,0.1]}}"#,
        p[0]
    ));
    c.wait_until(
        |c| {
            c.state.as_ref().is_some_and(|s| {
                s.beyond_training.is_some_and(|b| b > 0.1)
                    && s.extrapolating
                    && s.status.contains(
                        "of its size beyond the training poses, where the model extrapolates \
                         (larger training pulls",
                    )
            })
        },
        "the status saying the pose left the training poses",
    );
    // Full space has no training poses.
    c.send(r#"{"type":"method","name":"full"}"#);
    c.wait_until(
        |c| {
            c.state
                .as_ref()
                .is_some_and(|s| s.method == "full" && s.step > 0 && s.beyond_training.is_none())
        },
        "full space stepping",
    );
    let status = &c.state.as_ref().unwrap().status;
    assert!(!status.contains("training"), "{status}");
    server.shutdown();
}

#[test]
fn every_malformed_message_gets_an_error_and_the_session_steps_on() {
    let server = serve(session());
    let mut c = Client::connect(&server);
    let (_, p) = tip();
    let handle = c.grab(&format!(
        r#"{{"type":"grab","point":[{},{},{}]}}"#,
        p[0], p[1], p[2]
    ));
    let far = 1e300;
    let cases: Vec<(String, &str)> = vec![
        ("not json".into(), "not a valid request"),
        ("[1,2,3]".into(), "not a valid request"),
        (r#"{"type":"explode"}"#.into(), "unknown variant"),
        (r#"{"type":"move","handle":1}"#.into(), "missing field"),
        (r#"{"type":"reset","now":true}"#.into(), "unknown field"),
        (r#"{"type":"pause","paused":"yes"}"#.into(), "invalid type"),
        (
            format!(r#"{{"type":"move","handle":{handle},"target":[NaN,0,0]}}"#),
            "not a valid request",
        ),
        (
            format!(r#"{{"type":"move","handle":{handle},"target":[1e999,0,0]}}"#),
            "not a valid request",
        ),
        (
            format!(r#"{{"type":"move","handle":{handle},"target":[{far},0,0]}}"#),
            "from the mesh's centre",
        ),
        (
            r#"{"type":"move","handle":999,"target":[0,0,0]}"#.into(),
            "no handle 999",
        ),
        (r#"{"type":"release","handle":999}"#.into(), "no handle 999"),
        (
            r#"{"type":"grab","vertices":[100000000]}"#.into(),
            "does not exist",
        ),
        (r#"{"type":"grab","vertices":[-1]}"#.into(), "invalid value"),
        (
            r#"{"type":"grab","vertices":[]}"#.into(),
            "at least one vertex",
        ),
        (
            r#"{"type":"grab","point":[0,5,0],"radius":0.01}"#.into(),
            "no surface vertex within",
        ),
        (
            r#"{"type":"grab","point":[0,0,0],"radius":-1}"#.into(),
            "radius must be positive",
        ),
        (
            r#"{"type":"grab","point":[0,0,0],"stiffness":1e308}"#.into(),
            "stiffness must be positive and at most",
        ),
        (
            r#"{"type":"grab","point":[0,0,0],"stiffness":1e300}"#.into(),
            "got 1e300",
        ),
        (r#"{"type":"grab"}"#.into(), "either a point or a list"),
        (r#"{"type":"method","name":"magic"}"#.into(), "no method"),
        (r#"{"type":"step"}"#.into(), "pause first"),
        (
            format!(
                r#"{{"type":"reset","pad":"{}"}}"#,
                "x".repeat(MAX_MESSAGE_BYTES)
            ),
            "at most 65536",
        ),
    ];
    for (message, expected) in &cases {
        let reply = c.expect_error(message);
        assert!(
            reply.contains(expected),
            "{message:.80}: the reply {reply:?} does not say {expected:?}"
        );
    }
    // A bound is said in plain numbers, not as 1.8128e0.
    let reply = c.expect_error(r#"{"type":"grab","point":[0,0,0],"radius":-1}"#);
    assert!(!reply.contains("e0") && !reply.contains("e-"), "{reply}");
    // A message of a known type with a field that does not parse names its request.
    c.send(r#"{"type":"pause","paused":"yes"}"#);
    match c.wait_event(|e| matches!(e, Event::Error { .. }), "an error reply") {
        Event::Error { request, .. } => assert_eq!(request.as_deref(), Some("pause")),
        _ => unreachable!(),
    }
    // Binary and non-UTF-8 text frames.
    c.ws.send(Message::binary(vec![1u8, 2, 3])).expect("send");
    let reply = c.wait_event(|e| matches!(e, Event::Error { .. }), "binary reply");
    assert!(format!("{reply:?}").contains("binary messages"));
    let bad = tungstenite::protocol::frame::Frame::message(
        vec![0xffu8, 0xfe, 0x22],
        tungstenite::protocol::frame::coding::OpCode::Data(
            tungstenite::protocol::frame::coding::Data::Text,
        ),
        true,
    );
    c.ws.send(Message::Frame(bad)).expect("send");
    let reply = c.wait_event(|e| matches!(e, Event::Error { .. }), "utf-8 reply");
    assert!(format!("{reply:?}").contains("UTF-8"), "{reply:?}");
    // Messages far faster than it steps: the handle follows the last, the session goes on.
    let before = c.step();
    for i in 0..3000 {
        let y = p[1] + 0.1 * f64::from(i) / 3000.0;
        c.send(&format!(
            r#"{{"type":"move","handle":{handle},"target":[{},{y},{}]}}"#,
            p[0], p[2]
        ));
    }
    c.steps_on(5);
    assert!(c.step() >= before + 5);
    c.wait_until(
        |c| c.state.as_ref().is_some_and(|s| s.handles == 1),
        "state",
    );
    // Still serving requests: a release works.
    c.send(&format!(r#"{{"type":"release","handle":{handle}}}"#));
    c.wait_event(|e| matches!(e, Event::Released { .. }), "released");
    server.shutdown();
}

#[test]
fn a_message_too_large_to_buffer_closes_only_its_connection() {
    let server = serve(session());
    let mut big = Client::connect(&server);
    let mut other = Client::connect(&server);
    // The server reads what the client still sends after closing, so the whole message goes
    // out and the close frame arrives, with its code (a tester's got a reset instead).
    big.ws
        .send(Message::text("x".repeat(2 << 20)))
        .expect("the whole message is written");
    big.read_for(Duration::from_secs(2));
    assert!(
        big.closed,
        "the connection stays open after a 2 MiB message"
    );
    assert_eq!(big.close_code, Some(1009), "the close frame's code");
    other.steps_on(3);
    let mut again = Client::connect(&server);
    again.steps_on(3);
    server.shutdown();
}

/// Nobody watching, the body holds still: the first client sees it from rest, and one that
/// comes back finds it where the last one left it.
#[test]
fn the_session_steps_only_while_watched() {
    let server = serve(session());
    // At h = 0.02 s, half a second unwatched would have been 25 steps.
    std::thread::sleep(Duration::from_millis(500));
    let mut first = Client::connect(&server);
    first.wait_until(|c| c.state.is_some(), "a state");
    let at_connect = first.state.as_ref().map_or(0, |s| s.step);
    assert!(at_connect <= 3, "{at_connect} steps before anyone watched");
    first.wait_until(|c| c.step() >= 10, "ten steps while watched");
    let seen = first.step();
    drop(first);
    // Two seconds unwatched would be 100 more steps; a loaded machine may let the session
    // catch up a backlog of up to 0.25 s (12 steps) after the last frame seen.
    std::thread::sleep(Duration::from_secs(2));
    let mut again = Client::connect(&server);
    again.wait_until(|c| c.state.is_some(), "a state");
    let left = again.state.as_ref().map_or(0, |s| s.step);
    assert!(
        left <= seen + 25,
        "{left} steps after {seen} seen: it stepped unwatched"
    );
    std::thread::sleep(Duration::from_millis(500));
    again.read_for(Duration::from_millis(50));
    assert!(again.step() > left, "it steps again once watched");
    server.shutdown();
}

#[test]
fn a_client_that_disconnects_mid_drag_releases_its_handles() {
    let server = serve(session());
    let mut dragger = Client::connect(&server);
    let mut watcher = Client::connect(&server);
    let (_, p) = tip();
    let handle = dragger.grab(&format!(
        r#"{{"type":"grab","point":[{},{},{}]}}"#,
        p[0], p[1], p[2]
    ));
    // Another client cannot move or release it.
    let reply = watcher.expect_error(&format!(r#"{{"type":"release","handle":{handle}}}"#));
    assert!(reply.contains("no handle"), "{reply}");
    dragger.send(&format!(
        r#"{{"type":"move","handle":{handle},"target":[{},{},{}]}}"#,
        p[0],
        p[1] + 0.2,
        p[2]
    ));
    watcher.wait_until(
        |c| {
            c.state
                .as_ref()
                .is_some_and(|s| s.handles == 1 && s.clients == 2)
        },
        "one handle held",
    );
    drop(dragger);
    watcher.wait_until(
        |c| {
            c.state
                .as_ref()
                .is_some_and(|s| s.handles == 0 && s.clients == 1)
        },
        "the handle released",
    );
    server.shutdown();
}

#[test]
fn two_viewers_see_the_same_simulation() {
    let server = serve(session());
    let mut a = Client::connect(&server);
    let mut b = Client::connect(&server);
    let (_, p) = tip();
    let handle = a.grab(&format!(
        r#"{{"type":"grab","point":[{},{},{}]}}"#,
        p[0], p[1], p[2]
    ));
    a.send(&format!(
        r#"{{"type":"move","handle":{handle},"target":[{},{},{}]}}"#,
        p[0],
        p[1] + 0.2,
        p[2]
    ));
    let mut seen = std::collections::HashMap::new();
    let mut matched = 0;
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(2) {
        for c in [&mut a, &mut b] {
            c.poll();
            if let Some(f) = &c.frame {
                match seen.get(&f.step) {
                    None => {
                        seen.insert(f.step, f.positions.clone());
                    }
                    Some(other) if other != &f.positions => {
                        panic!("two clients got different positions at step {}", f.step)
                    }
                    Some(_) => matched += 1,
                }
            }
        }
    }
    assert!(matched > 20, "only {matched} frames seen by both");
    server.shutdown();
}

#[test]
fn pause_step_gravity_method_and_reset() {
    let server = serve(session());
    let mut c = Client::connect(&server);
    let state = |c: &Client| c.state.clone().expect("a state");
    c.send(r#"{"type":"pause","paused":true}"#);
    c.wait_until(|c| state(c).paused, "paused");
    c.read_for(Duration::from_millis(200));
    let at = c.step();
    c.read_for(Duration::from_millis(300));
    assert_eq!(c.step(), at, "a paused session stepped");
    c.send(r#"{"type":"step"}"#);
    c.wait_until(|c| c.step() == at + 1, "one step");
    c.send(r#"{"type":"gravity","enabled":false}"#);
    c.wait_until(|c| !state(c).gravity, "gravity off");
    let (_, p) = tip();
    let handle = c.grab(&format!(
        r#"{{"type":"grab","point":[{},{},{}]}}"#,
        p[0], p[1], p[2]
    ));
    c.send(r#"{"type":"method","name":"full"}"#);
    let released = c.wait_event(|e| matches!(e, Event::Released { .. }), "released");
    assert_eq!(
        released,
        Event::Released {
            handle,
            reason: "method changed".into()
        }
    );
    c.wait_until(|c| state(c).method == "full", "full space");
    assert!(!state(&c).gravity, "the switch kept gravity off");
    c.send(r#"{"type":"pause","paused":false}"#);
    c.wait_until(
        |c| !state(c).paused && c.step() > 3,
        "running in full space",
    );
    c.send(r#"{"type":"reset"}"#);
    c.wait_until(|c| c.step() < 3, "back at the start");
    server.shutdown();
}

/// A simulator that fails its steps while told to: a solver failure on demand (an error, or a
/// panic while `panic` is set too).
struct Flaky {
    inner: Box<dyn Interactive + Send>,
    fail: Arc<AtomicBool>,
    panic: Arc<AtomicBool>,
    /// How often the session prepared its first grab.
    prepared: Arc<std::sync::atomic::AtomicUsize>,
}

impl Interactive for Flaky {
    fn rest_positions(&self) -> &[Vec3] {
        self.inner.rest_positions()
    }
    fn surface(&self) -> &Surface {
        self.inner.surface()
    }
    fn steps(&self) -> usize {
        self.inner.steps()
    }
    fn time(&self) -> f64 {
        self.inner.time()
    }
    fn step(&mut self) -> Result<StepStats, RuntimeError> {
        if self.fail.load(Ordering::Relaxed) {
            assert!(!self.panic.load(Ordering::Relaxed), "a solver bug");
            return Err(fem_core::FemError::NotConverged {
                solver: "L-BFGS",
                step: self.inner.steps() + 1,
                iterations: 100,
                residual: 1.0,
                tolerance: 1e-6,
            }
            .into());
        }
        self.inner.step()
    }
    fn grab(&mut self, vertices: &[usize], stiffness: f64) -> Result<Handle, RuntimeError> {
        self.inner.grab(vertices, stiffness)
    }
    fn grab_near(&mut self, p: [f64; 3], r: f64, k: f64) -> Result<Handle, RuntimeError> {
        self.inner.grab_near(p, r, k)
    }
    fn move_handle(&mut self, h: Handle, t: [f64; 3]) -> Result<(), RuntimeError> {
        self.inner.move_handle(h, t)
    }
    fn release(&mut self, h: Handle) -> Result<(), RuntimeError> {
        self.inner.release(h)
    }
    fn add_force(&mut self, force: ExternalForce) -> Result<Handle, RuntimeError> {
        self.inner.add_force(force)
    }
    fn set_gravity(&mut self, enabled: bool) {
        self.inner.set_gravity(enabled);
    }
    fn gravity(&self) -> bool {
        self.inner.gravity()
    }
    fn set_gravity_acceleration(&mut self, g: [f64; 3]) -> Result<(), RuntimeError> {
        self.inner.set_gravity_acceleration(g)
    }
    fn handle_target(&mut self, handle: Handle) -> Result<[f64; 3], RuntimeError> {
        self.inner.handle_target(handle)
    }
    fn set_load(&mut self, handle: Handle, force: [f64; 3]) -> Result<(), RuntimeError> {
        self.inner.set_load(handle, force)
    }
    fn handles(&mut self) -> Vec<Handle> {
        self.inner.handles()
    }
    fn surface_velocities_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError> {
        self.inner.surface_velocities_into(out)
    }
    fn gravity_acceleration(&self) -> [f64; 3] {
        self.inner.gravity_acceleration()
    }
    fn reset(&mut self) {
        self.inner.reset();
    }
    fn prepare_grab(&mut self) {
        self.prepared.fetch_add(1, Ordering::Relaxed);
        self.inner.prepare_grab();
    }
    fn positions_into(&mut self, out: &mut [f64]) -> Result<(), RuntimeError> {
        self.inner.positions_into(out)
    }
    /// Through the inner simulator's `f32` read-back (a trait object has no generic one).
    fn surface_positions_into<T: Real>(&mut self, out: &mut [T]) -> Result<(), RuntimeError> {
        let mut f32s = vec![0.0; out.len()];
        self.inner.surface_positions_f32(&mut f32s)?;
        for (o, x) in out.iter_mut().zip(f32s) {
            *o = T::from_f64(f64::from(x));
        }
        Ok(())
    }
    fn surface_positions_f32(&mut self, out: &mut [f32]) -> Result<(), RuntimeError> {
        self.inner.surface_positions_f32(out)
    }
}

#[test]
fn a_solver_failure_is_shown_and_a_reset_goes_on() {
    let (fail, panic) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicBool::new(false)),
    );
    let prepared = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let flaky = Flaky {
        inner: Box::new(model().simulator().expect("a runtime")),
        fail: Arc::clone(&fail),
        panic: Arc::clone(&panic),
        prepared: Arc::clone(&prepared),
    };
    let session = Session::new(
        Settings::for_model(model()),
        vec![Method {
            name: "pca".into(),
            simulator: Box::new(flaky),
        }],
    )
    .expect("a session");
    let server = serve(session);
    let mut c = Client::connect(&server);
    c.steps_on(3);
    // The first client's arrival prepared the method's first grab, before any drag.
    assert_eq!(prepared.load(Ordering::Relaxed), 1);
    fail.store(true, Ordering::Relaxed);
    c.wait_until(
        |c| c.state.as_ref().is_some_and(|s| s.failure.is_some()),
        "the failure reported",
    );
    let s = c.state.clone().expect("a state");
    assert!(
        s.status.starts_with("stopped: pca failed at step"),
        "{}",
        s.status
    );
    assert!(s.status.contains("did not converge"), "{}", s.status);
    // The last good step's frame may still be on its way; after it, nothing moves.
    c.read_for(Duration::from_millis(300));
    let at = c.step();
    c.read_for(Duration::from_millis(300));
    assert_eq!(c.step(), at, "it stepped on after the failure");
    fail.store(false, Ordering::Relaxed);
    c.send(r#"{"type":"reset"}"#);
    c.wait_until(
        |c| c.state.as_ref().is_some_and(|s| s.failure.is_none()) && c.step() > 3,
        "stepping again after the reset",
    );
    // A solver that panics: the same, and the server goes on.
    panic.store(true, Ordering::Relaxed);
    fail.store(true, Ordering::Relaxed);
    c.wait_until(
        |c| c.state.as_ref().is_some_and(|s| s.failure.is_some()),
        "the panic reported",
    );
    let s = c.state.clone().expect("a state");
    assert!(
        s.status.contains("the solver panicked: a solver bug"),
        "{}",
        s.status
    );
    fail.store(false, Ordering::Relaxed);
    c.send(r#"{"type":"reset"}"#);
    c.wait_until(
        |c| c.state.as_ref().is_some_and(|s| s.failure.is_none()) && c.step() > 3,
        "stepping again after the second reset",
    );
    server.shutdown();
}

/// The grab spring starts at 10⁻² E·L, or stiffer where that could not hold the body's weight
/// when stretched by a fifth of its size: the tiny beam (1 × 0.2 × 0.2 m, 40 kg, E = 100 kPa)
/// without gravity gets 10⁻² E·L, under gravity M|g|/(0.2 L).
#[test]
fn the_grab_spring_holds_the_body_weight() {
    let size = (1.0f64 + 0.04 + 0.04).sqrt();
    let floating = Settings::for_model(model()).stiffness;
    assert!(
        (floating - 1e-2 * 1.0e5 * size).abs() < 1e-9 * floating,
        "{floating}"
    );
    let heavy = Settings::for_model(falling_model()).stiffness;
    let weight = 40.0 * 9.81;
    assert!(
        (heavy - weight / (0.2 * size)).abs() < 1e-9 * heavy,
        "{heavy} against {}",
        weight / (0.2 * size)
    );
}

/// `hello` says which way is up: against the scene's gravity, +y without any.
#[test]
fn hello_says_up_against_gravity() {
    use crate::common::z_up_model;
    assert_eq!(
        Settings::for_model(model()).up,
        [0.0, 1.0, 0.0],
        "no gravity"
    );
    assert_eq!(Settings::for_model(falling_model()).up, [0.0, 1.0, 0.0]);
    let m = z_up_model();
    assert_eq!(Settings::for_model(m).up, [0.0, 0.0, 1.0]);
    let methods = vec![Method::new("pca", m.simulator().expect("a runtime"))];
    let server = serve(Session::new(Settings::for_model(m), methods).expect("a session"));
    let hello = Client::connect(&server).hello;
    assert!(
        matches!(hello, Event::Hello { up, .. } if up == [0.0, 0.0, 1.0]),
        "{hello:?}"
    );
    server.shutdown();
}

#[test]
fn a_session_refuses_what_it_cannot_run() {
    let m = model();
    let reduced = || Method::new("pca", m.simulator().expect("a runtime"));
    let err = |settings: Settings, methods: Vec<Method>| {
        Session::new(settings, methods)
            .map(drop)
            .expect_err("refused")
            .to_string()
    };
    let ok = Settings::for_model(m);
    assert!(err(ok.clone(), vec![]).contains("at least one method"));
    assert!(err(ok.clone(), vec![reduced(), reduced()]).contains("two methods are named"));
    for (settings, what) in [
        (
            Settings {
                time_step: 0.0,
                ..ok.clone()
            },
            "time step",
        ),
        (
            Settings {
                time_step: 1e30,
                ..ok.clone()
            },
            "time step",
        ),
        (
            Settings {
                stiffness: f64::NAN,
                ..ok.clone()
            },
            "stiffness",
        ),
        (
            Settings {
                max_fps: 1e-30,
                ..ok.clone()
            },
            "frame interval",
        ),
        (
            Settings {
                pinned: vec![1 << 40],
                ..ok.clone()
            },
            "pinned vertex",
        ),
        (
            Settings {
                up: [0.0, 2.0, 0.0],
                ..ok.clone()
            },
            "up must be a unit vector, got one of length 2",
        ),
        (
            Settings {
                up: [f64::NAN, 1.0, 0.0],
                ..ok.clone()
            },
            "up must be a unit vector",
        ),
    ] {
        let e = err(settings, vec![reduced()]);
        assert!(e.contains(what), "{e}");
    }
    assert!(Session::new(ok, vec![reduced()]).is_ok());
}

/// The first line of the server's answer to a raw request.
fn status_line(server: &viewer::Server, request: &str) -> String {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(server.local_addr()).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    s.write_all(request.as_bytes()).expect("send");
    // Up to the end of the first line (a WebSocket's stream goes on).
    let (mut reply, mut byte) = (Vec::new(), [0u8]);
    while !reply.ends_with(b"\r\n") && s.read_exact(&mut byte).is_ok() {
        reply.push(byte[0]);
    }
    String::from_utf8_lossy(&reply).trim_end().to_string()
}

#[test]
fn the_page_is_served_to_loopback_only_and_same_origin_sockets_only() {
    let server = serve(session());
    let host = format!("127.0.0.1:{}", server.local_addr().port());
    let get = |path: &str, headers: &str| {
        status_line(
            &server,
            &format!("GET {path} HTTP/1.1\r\nHost: {host}\r\n{headers}\r\n"),
        )
    };
    for path in ["/", "/index.html", "/viewer.js", "/viewer.css"] {
        assert_eq!(get(path, ""), "HTTP/1.1 200 OK", "{path}");
    }
    assert_eq!(get("/secret", ""), "HTTP/1.1 404 Not Found");
    assert_eq!(get("/ws", ""), "HTTP/1.1 426 Upgrade Required");
    // An upgrade the handshake cannot take is answered, not dropped in silence.
    assert_eq!(
        get(
            "/ws",
            "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
        ),
        "HTTP/1.1 400 Bad Request"
    );
    assert_eq!(
        get(
            "/ws",
            "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 99\r\n\
             Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
        ),
        "HTTP/1.1 426 Upgrade Required"
    );
    // A Host header that does not parse is not taken for loopback.
    assert_eq!(
        status_line(&server, "GET / HTTP/1.1\r\nHost: [::1\r\n\r\n"),
        "HTTP/1.1 403 Forbidden"
    );
    let upgrade = "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n\
                   Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
    assert_eq!(
        get("/ws", &format!("{upgrade}Origin: http://evil.example\r\n")),
        "HTTP/1.1 403 Forbidden"
    );
    assert_eq!(
        get("/ws", &format!("{upgrade}Origin: http://{host}\r\n")),
        "HTTP/1.1 101 Switching Protocols"
    );
    assert_eq!(
        status_line(&server, "GET / HTTP/1.1\r\nHost: evil.example\r\n\r\n"),
        "HTTP/1.1 403 Forbidden"
    );
    assert_eq!(
        status_line(&server, "POST / HTTP/1.1\r\nHost: localhost\r\n\r\n"),
        "HTTP/1.1 405 Method Not Allowed"
    );
    assert_eq!(
        status_line(&server, "\x16\x03\x01 not http\r\n\r\n"),
        "HTTP/1.1 400 Bad Request"
    );
    // And it still serves a client.
    let mut c = Client::connect(&server);
    c.steps_on(2);
    server.shutdown();
}
