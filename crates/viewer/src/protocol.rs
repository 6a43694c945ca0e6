//! The messages between a page (or any client) and the server, over one WebSocket at `/ws`
//! (`docs/viewer.md` is the reference with examples).
//!
//! Client → server: JSON text, one [`Request`] per message, tagged by `"type"`. Server → client:
//! JSON text [`Event`]s, and two binary messages, the surface [`mesh`](encode_mesh) once after
//! `hello` and position [`frames`](encode_frame) as the simulation advances. Binary numbers are
//! little-endian; positions are `f32`.

use serde::{Deserialize, Serialize};

/// The protocol's version, in `hello`.
pub const PROTOCOL_VERSION: u32 = 1;

/// The largest text message the server reads; a longer one gets an error reply. (Messages above
/// [`MAX_WIRE_MESSAGE`] close the connection: the WebSocket layer refuses to buffer them.)
pub const MAX_MESSAGE_BYTES: usize = 64 * 1024;

/// The largest message the WebSocket layer buffers before closing the connection (code 1009).
pub const MAX_WIRE_MESSAGE: usize = 1024 * 1024;

/// The most handles one client may hold at once.
pub const MAX_HANDLES_PER_CLIENT: usize = 8;

/// Kind tag (first `u32`) of the binary surface message.
pub const MESH_KIND: u32 = 1;
/// Kind tag (first `u32`) of the binary position frame.
pub const FRAME_KIND: u32 = 2;
/// Bytes before the positions of a frame: kind, vertex count (`u32` each), step, time (`f64`).
pub const FRAME_HEADER_BYTES: usize = 24;

/// +y: the direction drawn up when the scene has no gravity.
pub(crate) const Y_UP: [f64; 3] = [0.0, 1.0, 0.0];

fn y_up() -> [f64; 3] {
    Y_UP
}

/// A client's message.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Request {
    /// Grabs with a spring either the surface vertices within `radius` of `point` (as the page
    /// does) or the listed `vertices` (mesh indices). `radius` and `stiffness` default to the
    /// session's (in `hello`).
    Grab {
        #[serde(default)]
        point: Option<[f64; 3]>,
        #[serde(default)]
        vertices: Option<Vec<usize>>,
        #[serde(default)]
        radius: Option<f64>,
        #[serde(default)]
        stiffness: Option<f64>,
    },
    /// Moves a handle's target (m, world coordinates). With `seq`, the server answers
    /// [`Event::Applied`] once the move is in the simulation.
    Move {
        handle: u64,
        target: [f64; 3],
        #[serde(default)]
        seq: Option<u64>,
    },
    /// Lets go of a handle.
    Release { handle: u64 },
    /// Switches to another method (one of `hello`'s `methods`); it starts from rest and every
    /// handle is released.
    Method { name: String },
    /// Stops or resumes stepping.
    Pause { paused: bool },
    /// One step, while paused. (Braced, like every request, so that unknown fields are refused.)
    Step {},
    /// Back to rest at time 0 (handles stay); clears a solver failure.
    Reset {},
    /// Gravity on or off.
    Gravity { enabled: bool },
}

impl Request {
    /// The `type` tag, for error replies.
    pub fn kind(&self) -> &'static str {
        match self {
            Request::Grab { .. } => "grab",
            Request::Move { .. } => "move",
            Request::Release { .. } => "release",
            Request::Method { .. } => "method",
            Request::Pause { .. } => "pause",
            Request::Step {} => "step",
            Request::Reset {} => "reset",
            Request::Gravity { .. } => "gravity",
        }
    }
}

/// What the server reports, as JSON text.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Event {
    /// First message on a connection: what the session is.
    Hello {
        protocol: u32,
        scene: String,
        /// The methods a client can switch among, and the current one.
        methods: Vec<String>,
        method: String,
        /// Seconds of simulated time per step.
        time_step: f64,
        /// The grab defaults and the largest stiffness and radius accepted.
        radius: f64,
        stiffness: f64,
        max_radius: f64,
        max_stiffness: f64,
        /// Surface vertices and triangles (the sizes of the binary mesh message that follows).
        surface_vertices: usize,
        surface_triangles: usize,
        /// The mesh indices of the surface vertices, in frame order.
        vertex_ids: Vec<usize>,
        /// The direction to draw up (a unit vector, against the scene's gravity; +y without, and
        /// from a server that does not send it).
        #[serde(default = "y_up")]
        up: [f64; 3],
    },
    /// The simulation's state and speed, a few times a second and after every change.
    State(State),
    /// A grab succeeded: the handle to move and release, and how many vertices it holds.
    Grabbed { handle: u64, vertices: usize },
    /// A handle is gone: released on request or by a method switch.
    Released { handle: u64, reason: String },
    /// A move with `seq` is in the simulation: the first frame with `step` ≥ this shows it.
    Applied { seq: u64, step: u64 },
    /// A message could not be applied; the session goes on. `request` is its type when known.
    Error {
        message: String,
        #[serde(default)]
        request: Option<String>,
    },
}

/// The simulation's state and measured speed.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
pub struct State {
    pub method: String,
    /// Steps taken since the last reset or method switch, and the simulated time.
    pub step: u64,
    pub time: f64,
    pub paused: bool,
    pub gravity: bool,
    /// Over the last second of stepping: steps per wall second, solver iterations per step,
    /// mean wall milliseconds per step, and simulated seconds per wall second.
    pub steps_per_second: f64,
    pub iterations_per_step: f64,
    pub step_ms: f64,
    pub real_time_factor: f64,
    /// True while running at the scene's time step in real time; false when the steps take
    /// longer than the time step (the status then says by how much).
    pub real_time: bool,
    /// A sentence for the page's status line.
    pub status: String,
    /// The solver failure that stopped the simulation, until a reset or a method switch.
    pub failure: Option<String>,
    /// How far the last step's pose lies beyond the model's training poses, relative to its
    /// size (`latent_sim::StepStats::beyond_training`): above 0.1 the model extrapolates and
    /// the status line says so. None in full space, before a step and for a model without
    /// the ranges.
    #[serde(default)]
    pub beyond_training: Option<f64>,
    /// `beyond_training` above `latent_sim::coverage::OUTSIDE_TRAINING` (0.1) and no failure:
    /// the page shows the status line in amber.
    #[serde(default)]
    pub extrapolating: bool,
    /// Connected clients and handles held.
    pub clients: usize,
    pub handles: usize,
}

/// The surface message: kind [`MESH_KIND`], vertex count n, triangle count m, pinned count p
/// (`u32` each), then the rest positions (3n `f32`), the triangles (3m `u32`, indices into the
/// surface's vertices) and the pinned surface vertices (p `u32`, same indices).
pub fn encode_mesh(rest: &[f32], triangles: &[[u32; 3]], pinned: &[u32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 + 4 * (rest.len() + 3 * triangles.len() + pinned.len()));
    for x in [
        MESH_KIND,
        (rest.len() / 3) as u32,
        triangles.len() as u32,
        pinned.len() as u32,
    ] {
        out.extend_from_slice(&x.to_le_bytes());
    }
    for x in rest {
        out.extend_from_slice(&x.to_le_bytes());
    }
    for x in triangles.iter().flatten().chain(pinned) {
        out.extend_from_slice(&x.to_le_bytes());
    }
    out
}

/// A position frame: kind [`FRAME_KIND`] and vertex count n (`u32`), the step and simulated
/// time (`f64`), then the surface positions (3n `f32`, in `hello`'s `vertex_ids` order).
pub fn encode_frame(step: u64, time: f64, positions: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(FRAME_HEADER_BYTES + 4 * positions.len());
    out.extend_from_slice(&FRAME_KIND.to_le_bytes());
    out.extend_from_slice(&((positions.len() / 3) as u32).to_le_bytes());
    out.extend_from_slice(&(step as f64).to_le_bytes());
    out.extend_from_slice(&time.to_le_bytes());
    for x in positions {
        out.extend_from_slice(&x.to_le_bytes());
    }
    out
}

/// A decoded position frame (for clients written in Rust: tests, scripts).
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub step: u64,
    pub time: f64,
    pub positions: Vec<f32>,
}

/// Reads a binary message as a position frame; `None` for anything else (e.g. the mesh).
pub fn decode_frame(bytes: &[u8]) -> Option<Frame> {
    let u32_at = |i: usize| Some(u32::from_le_bytes(bytes.get(i..i + 4)?.try_into().ok()?));
    let f64_at = |i: usize| Some(f64::from_le_bytes(bytes.get(i..i + 8)?.try_into().ok()?));
    if u32_at(0)? != FRAME_KIND {
        return None;
    }
    let n = u32_at(4)? as usize;
    let data = bytes.get(FRAME_HEADER_BYTES..)?;
    if data.len() != 12 * n {
        return None;
    }
    Some(Frame {
        step: f64_at(8)? as u64,
        time: f64_at(16)?,
        positions: data
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
    })
}

/// A decoded surface message.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Rest positions, 3 per surface vertex.
    pub rest: Vec<f32>,
    pub triangles: Vec<[u32; 3]>,
    /// Pinned surface vertices (indices into the surface's vertices).
    pub pinned: Vec<u32>,
}

/// Reads a binary message as the surface message; `None` for anything else.
pub fn decode_mesh(bytes: &[u8]) -> Option<Mesh> {
    let u32_at = |i: usize| Some(u32::from_le_bytes(bytes.get(i..i + 4)?.try_into().ok()?));
    if u32_at(0)? != MESH_KIND {
        return None;
    }
    let (n, m, p) = (
        u32_at(4)? as usize,
        u32_at(8)? as usize,
        u32_at(12)? as usize,
    );
    if bytes.len() != 16 + 4 * (3 * n + 3 * m + p) {
        return None;
    }
    let words: Vec<[u8; 4]> = bytes[16..]
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    let (rest, rest_words) = words.split_at(3 * n);
    let (triangles, pinned) = rest_words.split_at(3 * m);
    Some(Mesh {
        rest: rest.iter().map(|w| f32::from_le_bytes(*w)).collect(),
        triangles: triangles
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|c| u32::from_le_bytes(t[c])))
            .collect(),
        pinned: pinned.iter().map(|w| u32::from_le_bytes(*w)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_round_trip() {
        let p = [1.0f32, -2.5, 3.25, 0.0, 1e-3, 7.0];
        let f = decode_frame(&encode_frame(42, 0.21, &p)).expect("a frame");
        assert_eq!((f.step, f.time, &f.positions[..]), (42, 0.21, &p[..]));
        assert!(decode_frame(&encode_mesh(&p, &[[0, 1, 0]], &[])).is_none());
        let mesh = decode_mesh(&encode_mesh(&p, &[[0, 1, 0]], &[1])).expect("a mesh");
        assert_eq!(
            (&mesh.rest[..], &mesh.triangles[..], &mesh.pinned[..]),
            (&p[..], &[[0, 1, 0]][..], &[1][..])
        );
        assert!(decode_mesh(&encode_frame(1, 0.0, &p)).is_none());
        assert!(decode_frame(&encode_frame(1, 0.0, &p)[..30]).is_none());
    }

    #[test]
    fn requests_read_as_documented() {
        let r: Request = serde_json::from_str(r#"{"type":"move","handle":3,"target":[0,1,2.5]}"#)
            .expect("valid");
        assert_eq!(
            r,
            Request::Move {
                handle: 3,
                target: [0.0, 1.0, 2.5],
                seq: None
            }
        );
        assert!(serde_json::from_str::<Request>(r#"{"type":"step","extra":1}"#).is_err());
        assert!(serde_json::from_str::<Request>(r#"{"type":"move","handle":3}"#).is_err());
    }
}
