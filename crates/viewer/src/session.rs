//! One simulation shared by every connected client: its methods, the handles clients hold, and
//! the loop that steps it in real time on its own thread.
//!
//! The loop starts step k + 1 (counted from the last restart of the clock) once k·h of wall time
//! has passed, so simulated time follows wall time while a step takes less than h. When steps
//! take longer it steps back to back, reports the real-time factor it reaches, and never builds a
//! backlog of more than a quarter second (the clock restarts rather than racing to catch up).
//! Requests arrive on one channel and are applied between steps, in order; moves are coalesced:
//! only a handle's latest target before a step is applied.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use fem_core::Vec3;
use latent_sim::Handle;
use latent_sim::coverage::OUTSIDE_TRAINING;
use tungstenite::Bytes;

use crate::ViewerError;
use crate::protocol::{
    Event, MAX_HANDLES_PER_CLIENT, PROTOCOL_VERSION, Request, State, encode_frame, encode_mesh,
};
use crate::simulator::{Method, Settings};

/// The backlog of steps (in wall time) after which the clock restarts instead of catching up.
const MAX_BACKLOG: Duration = Duration::from_millis(250);
/// The longest time step or frame interval accepted.
const MAX_INTERVAL: Duration = Duration::from_secs(365 * 24 * 3600);
/// How often the state is sent when nothing changed.
const STATE_INTERVAL: Duration = Duration::from_millis(250);
/// The span of the speed figures.
const WINDOW: Duration = Duration::from_secs(1);

/// A message for one connection to send.
#[derive(Debug, Clone)]
pub(crate) enum Outgoing {
    Text(String),
    Binary(Bytes),
}

/// Where the simulation puts what one connection sends: events in order, and the latest frame
/// (a slow client skips frames instead of queueing them).
#[derive(Debug, Clone)]
pub(crate) struct Outbox {
    pub events: Sender<Outgoing>,
    pub frame: Arc<Mutex<Option<Bytes>>>,
}

impl Outbox {
    fn event(&self, event: &Event) {
        match serde_json::to_string(event) {
            // A closed connection is noticed by its own thread, which disconnects.
            Ok(text) => drop(self.events.send(Outgoing::Text(text))),
            Err(e) => tracing::error!("cannot serialise an event: {e}"),
        }
    }

    fn error(&self, request: Option<&str>, message: impl Into<String>) {
        self.event(&Event::Error {
            message: message.into(),
            request: request.map(str::to_string),
        });
    }
}

/// What a connection tells the simulation.
#[derive(Debug)]
pub(crate) enum Command {
    Connect { client: u64, outbox: Outbox },
    Request { client: u64, request: Request },
    Disconnect { client: u64 },
}

/// A handle a client holds.
#[derive(Debug, Clone, Copy)]
struct Held {
    id: u64,
    client: u64,
    handle: Handle,
}

/// A move waiting for the next step.
#[derive(Debug, Clone, Copy)]
struct PendingMove {
    id: u64,
    client: u64,
    target: [f64; 3],
    seq: Option<u64>,
}

/// A simulation session: named methods over one mesh, stepped by the server's simulation thread.
#[derive(Debug)]
pub struct Session {
    settings: Settings,
    methods: Vec<Method>,
    current: usize,
    centre: Vec3,
    /// The binary surface message every client gets after `hello`.
    mesh_message: Bytes,
    vertex_ids: Vec<usize>,
    triangles: usize,
    positions: Vec<f32>,
    clients: Vec<(u64, Outbox)>,
    held: Vec<Held>,
    next_handle: u64,
    moves: Vec<PendingMove>,
    paused: bool,
    gravity: bool,
    failure: Option<String>,
    /// The last step's distance beyond the training poses (None until a step of a reduced
    /// model with the ranges, and after a reset or a switch).
    beyond_training: Option<f64>,
    /// The real-time clock: step `since_anchor + 1` may start at `anchor + since_anchor·h`.
    anchor: Instant,
    since_anchor: u64,
    /// Steps of the last second (when, iterations, seconds), and since when they count.
    window: VecDeque<(Instant, usize, f64)>,
    window_start: Instant,
    dirty: bool,
    last_frame: Instant,
    last_state: Instant,
}

impl Session {
    /// A session over `methods`, starting with the first, running, gravity on.
    ///
    /// # Errors
    /// No method, two with one name, methods whose surfaces differ, a pinned vertex past the
    /// mesh, or a setting that is not positive and finite.
    pub fn new(settings: Settings, methods: Vec<Method>) -> Result<Self, ViewerError> {
        let first = methods.first().ok_or(ViewerError::NoMethods)?;
        for (what, value) in [
            ("time step", settings.time_step),
            ("radius", settings.radius),
            ("stiffness", settings.stiffness),
            ("max_radius", settings.max_radius),
            ("max_stiffness", settings.max_stiffness),
            ("max_reach", settings.max_reach),
            ("max_fps", settings.max_fps),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(ViewerError::Setting { what, value });
            }
        }
        let length = fem_core::Vec3::from(settings.up).norm();
        let unit = (length - 1.0).abs() <= 1e-6;
        if !unit {
            return Err(ViewerError::Up { length });
        }
        // The step and the frame interval as durations (a year at most).
        for (what, seconds) in [
            ("time step", settings.time_step),
            ("frame interval (1 / max_fps)", 1.0 / settings.max_fps),
        ] {
            if Duration::try_from_secs_f64(seconds).map_or(true, |d| d > MAX_INTERVAL) {
                return Err(ViewerError::Setting {
                    what,
                    value: seconds,
                });
            }
        }
        let surface = first.simulator.surface().clone();
        let rest = first.simulator.rest_positions().to_vec();
        for (i, m) in methods.iter().enumerate() {
            if methods[..i].iter().any(|o| o.name == m.name) {
                return Err(ViewerError::DuplicateMethod(m.name.clone()));
            }
            if m.simulator.surface().vertices() != surface.vertices()
                || m.simulator.rest_positions().len() != rest.len()
            {
                return Err(ViewerError::SurfaceMismatch {
                    first: first.name.clone(),
                    other: m.name.clone(),
                });
            }
        }
        if let Some(&vertex) = settings.pinned.iter().find(|&&v| v >= rest.len()) {
            return Err(ViewerError::PinnedVertex {
                vertex,
                count: rest.len(),
            });
        }
        let centre = rest.iter().fold(Vec3::zeros(), |s, x| s + x) / rest.len().max(1) as f64;
        let vertices = surface.vertices();
        let rest_f32: Vec<f32> = vertices
            .iter()
            .flat_map(|&v| [rest[v].x as f32, rest[v].y as f32, rest[v].z as f32])
            .collect();
        let pinned: Vec<u32> = settings
            .pinned
            .iter()
            .filter_map(|v| vertices.binary_search(v).ok().map(|i| i as u32))
            .collect();
        let now = Instant::now();
        Ok(Self {
            mesh_message: Bytes::from(encode_mesh(&rest_f32, surface.triangles(), &pinned)),
            vertex_ids: vertices.to_vec(),
            triangles: surface.triangles().len(),
            positions: rest_f32,
            settings,
            methods,
            current: 0,
            centre,
            clients: Vec::new(),
            held: Vec::new(),
            next_handle: 1,
            moves: Vec::new(),
            paused: false,
            gravity: true,
            failure: None,
            beyond_training: None,
            anchor: now,
            since_anchor: 0,
            window: VecDeque::new(),
            window_start: now,
            dirty: true,
            last_frame: now,
            last_state: now,
        })
    }

    /// The method names, in the order offered (the first is the one shown at the start).
    pub fn method_names(&self) -> Vec<String> {
        self.methods.iter().map(|m| m.name.clone()).collect()
    }

    /// The session's settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Stepping: not paused, not failed, and watched. With no client connected the body holds
    /// still, so that the first page to open sees it from rest (a body that falls under its
    /// weight had fallen long before anyone looked) and nobody's cores are spent on it.
    fn running(&self) -> bool {
        !self.paused && self.failure.is_none() && !self.clients.is_empty()
    }

    fn time_step(&self) -> Duration {
        Duration::from_secs_f64(self.settings.time_step)
    }

    /// Restarts the real-time clock and the speed window (after a pause, reset or switch).
    fn restart_clock(&mut self) {
        let now = Instant::now();
        self.anchor = now;
        self.since_anchor = 0;
        self.window.clear();
        self.window_start = now;
    }

    /// Steps in real time and serves requests until `stop` is set or every sender is gone.
    pub(crate) fn run(mut self, commands: Receiver<Command>, stop: &AtomicBool) {
        let h = self.time_step();
        let frame_gap = Duration::from_secs_f64(1.0 / self.settings.max_fps);
        self.restart_clock();
        while !stop.load(Ordering::Relaxed) {
            loop {
                match commands.try_recv() {
                    Ok(c) => self.command(c),
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => return,
                }
            }
            let now = Instant::now();
            let due = self.anchor + h.mul_f64(self.since_anchor as f64);
            if self.running() && now >= due {
                if now - due > MAX_BACKLOG {
                    self.anchor = now;
                    self.since_anchor = 0;
                }
                self.advance();
                self.publish(frame_gap);
                continue;
            }
            self.publish(frame_gap);
            let mut wake = self.last_state + STATE_INTERVAL;
            if self.running() {
                wake = wake.min(due);
            }
            if self.dirty {
                wake = wake.min(self.last_frame + frame_gap);
            }
            let wait = wake
                .saturating_duration_since(Instant::now())
                .min(Duration::from_millis(50));
            match commands.recv_timeout(wait) {
                Ok(c) => self.command(c),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }

    /// Sends the frame when one is due and the state when it is due.
    fn publish(&mut self, frame_gap: Duration) {
        let now = Instant::now();
        if self.dirty && now >= self.last_frame + frame_gap {
            self.send_frame();
        }
        if now >= self.last_state + STATE_INTERVAL {
            self.send_state();
        }
    }

    fn send_frame(&mut self) {
        let sim = &mut self.methods[self.current].simulator;
        if let Err(e) = sim.surface_positions_f32(&mut self.positions) {
            tracing::error!("cannot read the surface: {e}");
            return;
        }
        let frame = Bytes::from(encode_frame(
            sim.steps() as u64,
            sim.time(),
            &self.positions,
        ));
        for (_, outbox) in &self.clients {
            if let Ok(mut slot) = outbox.frame.lock() {
                *slot = Some(frame.clone());
            }
        }
        self.dirty = false;
        self.last_frame = Instant::now();
    }

    fn state(&mut self) -> State {
        let now = Instant::now();
        while self
            .window
            .front()
            .is_some_and(|&(t, _, _)| now.duration_since(t) > WINDOW)
        {
            self.window.pop_front();
        }
        let origin = now
            .checked_sub(WINDOW)
            .map_or(self.window_start, |t| t.max(self.window_start));
        let span = now.duration_since(origin).as_secs_f64();
        let steps = self.window.len() as f64;
        let (iterations, seconds) = self
            .window
            .iter()
            .fold((0, 0.0), |(i, s), &(_, it, sec)| (i + it, s + sec));
        let steps_per_second = if span > 0.0 { steps / span } else { 0.0 };
        let real_time_factor = steps_per_second * self.settings.time_step;
        let h_ms = self.settings.time_step * 1e3;
        let step_ms = if steps > 0.0 {
            1e3 * seconds / steps
        } else {
            0.0
        };
        // Settled: a quarter second of stepping, and within 5 % of the wall clock.
        let measured = span >= 0.25 && steps > 0.0;
        let real_time = self.running() && measured && real_time_factor >= 0.95;
        let status = if let Some(f) = &self.failure {
            format!("stopped: {f}; reset or switch method to go on")
        } else if self.paused {
            "paused".to_string()
        } else if !measured {
            "starting".to_string()
        } else if real_time {
            format!("real time: {steps_per_second:.0} steps/s at h = {h_ms} ms")
        } else {
            behind(
                real_time_factor,
                step_ms,
                h_ms,
                iterations as f64 / steps.max(1.0),
            )
        };
        let extrapolating =
            self.failure.is_none() && self.beyond_training.is_some_and(|b| b > OUTSIDE_TRAINING);
        let status = match self.beyond_training {
            Some(b) if extrapolating => {
                // While a drag holds the body, what reaches it; else the pose came from
                // elsewhere (a release, gravity switched), and there is no one setting to name.
                let remedy = if self.held.is_empty() {
                    ""
                } else {
                    " (larger training pulls, `[training] offset`, reach such drags)"
                };
                format!(
                    "{status}; the pose goes {:.0} % of its size beyond the training poses, \
                     where the model extrapolates{remedy}",
                    100.0 * b
                )
            }
            _ => status,
        };
        let sim = &self.methods[self.current].simulator;
        State {
            method: self.methods[self.current].name.clone(),
            step: sim.steps() as u64,
            time: sim.time(),
            paused: self.paused,
            gravity: self.gravity,
            steps_per_second,
            iterations_per_step: if steps > 0.0 {
                iterations as f64 / steps
            } else {
                0.0
            },
            step_ms,
            real_time_factor,
            real_time,
            status,
            failure: self.failure.clone(),
            beyond_training: self.beyond_training,
            extrapolating,
            clients: self.clients.len(),
            handles: self.held.len(),
        }
    }

    fn send_state(&mut self) {
        let event = Event::State(self.state());
        for (_, outbox) in &self.clients {
            outbox.event(&event);
        }
        self.last_state = Instant::now();
    }

    fn outbox(&self, client: u64) -> Option<&Outbox> {
        self.clients
            .iter()
            .find(|(id, _)| *id == client)
            .map(|(_, o)| o)
    }

    /// Applies the pending moves and takes one step.
    fn advance(&mut self) {
        let next_step = self.methods[self.current].simulator.steps() as u64 + 1;
        for m in std::mem::take(&mut self.moves) {
            let Some(held) = self.held.iter().find(|h| h.id == m.id) else {
                continue;
            };
            let result = self.methods[self.current]
                .simulator
                .move_handle(held.handle, m.target);
            if let Some(outbox) = self.outbox(m.client) {
                match (result, m.seq) {
                    (Ok(()), Some(seq)) => outbox.event(&Event::Applied {
                        seq,
                        step: next_step,
                    }),
                    (Ok(()), None) => {}
                    (Err(e), _) => outbox.error(Some("move"), e.to_string()),
                }
            }
        }
        let method = &mut self.methods[self.current];
        // A solver that panics is a failure like any other: the session stays up and can reset.
        let stepped = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            method.simulator.step().map_err(|e| e.to_string())
        }))
        .unwrap_or_else(|panic| {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic".into());
            Err(format!("the solver panicked: {what}"))
        });
        match stepped {
            Ok(stats) => {
                self.window
                    .push_back((Instant::now(), stats.iterations, stats.seconds));
                self.beyond_training = stats.beyond_training;
                self.since_anchor += 1;
                self.dirty = true;
            }
            Err(e) => {
                let message = format!("{} failed at step {next_step}: {e}", method.name);
                tracing::warn!("{message}");
                self.failure = Some(message);
                self.send_state();
            }
        }
    }

    fn command(&mut self, command: Command) {
        match command {
            Command::Connect { client, outbox } => {
                outbox.event(&Event::Hello {
                    protocol: PROTOCOL_VERSION,
                    scene: self.settings.scene.clone(),
                    methods: self.method_names(),
                    method: self.methods[self.current].name.clone(),
                    time_step: self.settings.time_step,
                    radius: self.settings.radius,
                    stiffness: self.settings.stiffness,
                    max_radius: self.settings.max_radius,
                    max_stiffness: self.settings.max_stiffness,
                    surface_vertices: self.vertex_ids.len(),
                    surface_triangles: self.triangles,
                    vertex_ids: self.vertex_ids.clone(),
                    up: self.settings.up,
                });
                drop(
                    outbox
                        .events
                        .send(Outgoing::Binary(self.mesh_message.clone())),
                );
                if self.clients.is_empty() {
                    // The first grab's factorisation now, while the page loads, not in the
                    // frame of the person's first drag (230 ms on a 30k-tet figure).
                    self.methods[self.current].simulator.prepare_grab();
                    // The clock stood still while nobody watched.
                    self.restart_clock();
                }
                self.clients.push((client, outbox));
                self.send_frame();
                self.send_state();
            }
            Command::Disconnect { client } => {
                self.clients.retain(|(id, _)| *id != client);
                self.moves.retain(|m| m.client != client);
                let (mine, others) = self.held.iter().partition(|h| h.client == client);
                self.held = others;
                let released: Vec<Held> = mine;
                for h in &released {
                    if let Err(e) = self.methods[self.current].simulator.release(h.handle) {
                        tracing::error!("releasing a disconnected client's handle: {e}");
                    }
                }
                if !released.is_empty() {
                    self.dirty = true;
                }
                self.send_state();
            }
            Command::Request { client, request } => {
                let kind = request.kind();
                if let Err(message) = self.request(client, request)
                    && let Some(outbox) = self.outbox(client)
                {
                    outbox.error(Some(kind), message);
                }
            }
        }
    }

    /// Applies one request; `Err` is the message of the error reply.
    fn request(&mut self, client: u64, request: Request) -> Result<(), String> {
        match request {
            Request::Grab {
                point,
                vertices,
                radius,
                stiffness,
            } => self.grab(client, point, vertices, radius, stiffness),
            Request::Move {
                handle,
                target,
                seq,
            } => {
                self.owned(client, handle)?;
                self.within_reach("target", target)?;
                let m = PendingMove {
                    id: handle,
                    client,
                    target,
                    seq,
                };
                match self.moves.iter_mut().find(|p| p.id == handle) {
                    Some(p) => {
                        // Superseded before it reached the simulation: acknowledge it with the
                        // one that replaces it.
                        if let (Some(old), None) = (p.seq, seq) {
                            *p = PendingMove {
                                seq: Some(old),
                                ..m
                            };
                        } else {
                            *p = m;
                        }
                    }
                    None => self.moves.push(m),
                }
                Ok(())
            }
            Request::Release { handle } => {
                let held = self.owned(client, handle)?;
                self.methods[self.current]
                    .simulator
                    .release(held.handle)
                    .map_err(|e| e.to_string())?;
                self.held.retain(|h| h.id != handle);
                self.moves.retain(|m| m.id != handle);
                self.dirty = true;
                if let Some(o) = self.outbox(client) {
                    o.event(&Event::Released {
                        handle,
                        reason: "released".into(),
                    });
                }
                Ok(())
            }
            Request::Method { name } => {
                let index = self
                    .methods
                    .iter()
                    .position(|m| m.name == name)
                    .ok_or_else(|| {
                        format!(
                            "no method {name:?} in this session; it has {}",
                            self.method_names().join(", ")
                        )
                    })?;
                self.switch(index);
                Ok(())
            }
            Request::Pause { paused } => {
                if self.paused && !paused {
                    self.restart_clock();
                }
                self.paused = paused;
                self.send_state();
                Ok(())
            }
            Request::Step {} => {
                if !self.paused {
                    return Err("single steps are for a paused session; pause first".into());
                }
                if let Some(f) = &self.failure {
                    return Err(format!("{f}; reset first"));
                }
                self.advance();
                self.send_frame();
                self.send_state();
                Ok(())
            }
            Request::Reset {} => {
                self.methods[self.current].simulator.reset();
                self.failure = None;
                self.beyond_training = None;
                self.restart_clock();
                self.dirty = true;
                self.send_state();
                Ok(())
            }
            Request::Gravity { enabled } => {
                self.gravity = enabled;
                self.methods[self.current].simulator.set_gravity(enabled);
                self.send_state();
                Ok(())
            }
        }
    }

    fn grab(
        &mut self,
        client: u64,
        point: Option<[f64; 3]>,
        vertices: Option<Vec<usize>>,
        radius: Option<f64>,
        stiffness: Option<f64>,
    ) -> Result<(), String> {
        if self.held.iter().filter(|h| h.client == client).count() >= MAX_HANDLES_PER_CLIENT {
            return Err(format!(
                "a client holds at most {MAX_HANDLES_PER_CLIENT} handles; release one first"
            ));
        }
        let s = &self.settings;
        let stiffness = bounded(
            "stiffness",
            stiffness.unwrap_or(s.stiffness),
            s.max_stiffness,
        )?;
        let sim = &mut self.methods[self.current].simulator;
        let (handle, count) = match (point, vertices) {
            (Some(point), None) => {
                let radius = bounded("radius", radius.unwrap_or(s.radius), s.max_radius)?;
                self.within_reach("point", point)?;
                let sim = &mut self.methods[self.current].simulator;
                let handle = sim
                    .grab_near(point, radius, stiffness)
                    .map_err(|e| e.to_string())?;
                sim.surface_positions_f32(&mut self.positions)
                    .map_err(|e| e.to_string())?;
                let p = Vec3::from(point);
                let count = self
                    .positions
                    .chunks_exact(3)
                    .filter(|x| {
                        let x = Vec3::new(x[0] as f64, x[1] as f64, x[2] as f64);
                        (x - p).norm() <= radius
                    })
                    .count();
                (handle, count)
            }
            (None, Some(vertices)) => {
                if radius.is_some() {
                    return Err("a grab of listed vertices takes no radius".into());
                }
                let handle = sim.grab(&vertices, stiffness).map_err(|e| e.to_string())?;
                let mut unique = vertices;
                unique.sort_unstable();
                unique.dedup();
                (handle, unique.len())
            }
            _ => return Err("a grab takes either a point or a list of vertices".into()),
        };
        let id = self.next_handle;
        self.next_handle += 1;
        self.held.push(Held { id, client, handle });
        if let Some(o) = self.outbox(client) {
            o.event(&Event::Grabbed {
                handle: id,
                vertices: count,
            });
        }
        Ok(())
    }

    /// The client's handle `id`.
    fn owned(&self, client: u64, id: u64) -> Result<Held, String> {
        self.held
            .iter()
            .find(|h| h.id == id && h.client == client)
            .copied()
            .ok_or_else(|| format!("no handle {id} held by this client"))
    }

    /// A finite point within the session's reach of the mesh's centre.
    fn within_reach(&self, what: &str, p: [f64; 3]) -> Result<(), String> {
        if !p.iter().all(|x| x.is_finite()) {
            return Err(format!("the {what} must be finite, got {p:?}"));
        }
        let d = (Vec3::from(p) - self.centre).norm();
        if d > self.settings.max_reach {
            return Err(format!(
                "the {what} is {d:.3} m from the mesh's centre; at most {:.3} m is accepted",
                self.settings.max_reach
            ));
        }
        Ok(())
    }

    /// Switches to method `index`: every handle released (their owners told), the new method
    /// from rest with the session's gravity.
    fn switch(&mut self, index: usize) {
        for h in std::mem::take(&mut self.held) {
            if let Err(e) = self.methods[self.current].simulator.release(h.handle) {
                tracing::error!("releasing handle {} on a method switch: {e}", h.id);
            }
            if let Some(o) = self.outbox(h.client) {
                o.event(&Event::Released {
                    handle: h.id,
                    reason: "method changed".into(),
                });
            }
        }
        self.moves.clear();
        self.current = index;
        let sim = &mut self.methods[index].simulator;
        sim.reset();
        sim.set_gravity(self.gravity);
        sim.prepare_grab();
        self.failure = None;
        self.beyond_training = None;
        self.restart_clock();
        self.dirty = true;
        self.send_state();
    }
}

/// `x` with four significant digits, without an exponent: 1.813, 1813, 0.001813.
fn four_digits(x: f64) -> String {
    let magnitude = if x == 0.0 || !x.is_finite() {
        0
    } else {
        x.abs().log10().floor() as i32
    };
    let decimals = (3 - magnitude).max(0) as usize;
    format!("{x:.decimals$}")
}

/// `value` when positive, finite and at most `max`.
fn bounded(what: &str, value: f64, max: f64) -> Result<f64, String> {
    if value.is_finite() && value > 0.0 && value <= max {
        Ok(value)
    } else {
        // A number a client sent, written as sent but in exponent form when it is huge or tiny
        // (1e300 in full is 301 digits).
        let got = if value != 0.0 && !(1e-4..1e7).contains(&value.abs()) {
            format!("{value:e}")
        } else {
            value.to_string()
        };
        Err(format!(
            "the {what} must be positive and at most {}, got {got}",
            four_digits(max)
        ))
    }
}

/// The status of a simulation behind the wall clock by `factor`, its steps taking `step_ms` of
/// an `h_ms` time step: a step longer than the time step is the method's cost; a shorter one
/// means the steps waited for a processor busy with other work (a tester's page said "a step
/// takes 5.4 ms, the time step is 10 ms" as if the step were the cause). Steps of
/// [`MANY_ITERATIONS`] solver iterations or more (`iterations` a step on average) are said to be
/// the pull's cost: full space under a hard drag took 103 a step, 1.2 s, with nothing saying why.
fn behind(factor: f64, step_ms: f64, h_ms: f64, iterations: f64) -> String {
    if step_ms >= h_ms && iterations >= MANY_ITERATIONS {
        return format!(
            "cannot keep real time: {factor:.2}× (a step takes {step_ms:.1} ms, the time step \
             is {h_ms} ms: {iterations:.0} solver iterations a step, which a hard pull costs; a \
             gentler one or a softer spring takes fewer)"
        );
    }
    if step_ms < h_ms {
        format!(
            "cannot keep real time: {factor:.2}× (a step takes {step_ms:.1} ms of the {h_ms} ms \
             time step: the steps wait for the processor, busy with other work)"
        )
    } else {
        format!(
            "cannot keep real time: {factor:.2}× (a step takes {step_ms:.1} ms, the time step \
             is {h_ms} ms)"
        )
    }
}

/// Solver iterations a step past which the status says the pull is what the steps cost: a
/// reduced step takes 2–9, full space's L-BFGS about 11 under a mild drag.
const MANY_ITERATIONS: f64 = 50.0;

#[cfg(test)]
mod tests {
    /// Behind the clock with steps shorter than the time step, the status blames the busy
    /// processor; with longer steps, the step.
    #[test]
    fn behind_the_clock_says_whether_the_step_or_the_machine_is_the_cause() {
        let busy = super::behind(0.93, 5.4, 10.0, 3.0);
        assert!(
            busy.contains("a step takes 5.4 ms of the 10 ms time step: the steps wait"),
            "{busy}"
        );
        let slow = super::behind(0.04, 134.0, 5.0, 11.0);
        assert_eq!(
            slow,
            "cannot keep real time: 0.04× (a step takes 134.0 ms, the time step is 5 ms)"
        );
        let pulled = super::behind(0.01, 1200.0, 10.0, 103.0);
        assert!(
            pulled.contains("103 solver iterations a step, which a hard pull costs"),
            "{pulled}"
        );
    }
}
