//! A tiny trained model, sessions over it, and a WebSocket client that speaks the protocol.

use std::net::TcpStream;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use latent_sim::{FullRuntime, ReducedModel};
use pipeline::pipeline::Pipeline;
use pipeline::simulate::Method as PipelineMethod;
use tungstenite::{Message, WebSocket};
use viewer::protocol::{Event, Frame, State, decode_frame};
use viewer::{Method, Server, Session, Settings};

/// The tiny beam of the workspace's tests without gravity (so that it rests straight until
/// dragged), its PCA model built once per test run.
pub fn model() -> &'static ReducedModel {
    static MODEL: OnceLock<ReducedModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let text = format!(
            "{}\n[gravity]\nacceleration = [0.0, 0.0, 0.0]\n",
            tests::TINY
        );
        pca_model(&text, "viewer-model")
    })
}

/// The tiny beam of the workspace's tests under gravity: pinned at one end, it falls until it
/// hangs (for the view's framing).
pub fn falling_model() -> &'static ReducedModel {
    static MODEL: OnceLock<ReducedModel> = OnceLock::new();
    MODEL.get_or_init(|| pca_model(tests::TINY, "viewer-falling-model"))
}

/// The tiny beam under gravity along −z, as a mesh made with z up has it: the page draws z up.
pub fn z_up_model() -> &'static ReducedModel {
    static MODEL: OnceLock<ReducedModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let text = format!(
            "{}\n[gravity]\nacceleration = [0.0, 0.0, -9.81]\n",
            tests::TINY
        );
        pca_model(&text, "viewer-z-up-model")
    })
}

/// The `pca` model of scene `text`, its stages cached in the scratch folder `cache`.
fn pca_model(text: &str, cache: &str) -> ReducedModel {
    let scene = tests::scene(text);
    let cache = tests::scratch_dir(cache);
    let mut p = Pipeline::new(&scene, &cache).expect("a pipeline");
    pipeline::export::scene_model(
        &mut p,
        PipelineMethod::Pca,
        latent_sim::model::Rows::Used,
        &tests::no_progress,
    )
    .expect("the tiny model")
}

/// A session over the tiny model: `pca` and `full`.
pub fn session() -> Session {
    let m = model();
    let methods = vec![
        Method::new("pca", m.simulator().expect("a reduced runtime")),
        Method::new("full", FullRuntime::from_model(m).expect("a full runtime")),
    ];
    Session::new(Settings::for_model(m), methods).expect("a session")
}

/// A server on a free loopback port.
pub fn serve(session: Session) -> Server {
    Server::bind("127.0.0.1:0", session).expect("a free port on loopback")
}

/// The mesh index of the surface vertex farthest from the pinned end, and its rest position.
pub fn tip() -> (usize, [f64; 3]) {
    let m = model();
    let rest = &m.mesh.vertices;
    let v = (0..rest.len())
        .max_by(|&a, &b| rest[a].x.total_cmp(&rest[b].x))
        .expect("vertices");
    (v, [rest[v].x, rest[v].y, rest[v].z])
}

/// A protocol client: reads events and keeps the latest frame.
pub struct Client {
    pub ws: WebSocket<TcpStream>,
    pub hello: Event,
    pub vertex_ids: Vec<usize>,
    pub frame: Option<Frame>,
    pub state: Option<State>,
    pub closed: bool,
    /// The code of the server's close frame, when one came.
    pub close_code: Option<u16>,
}

impl Client {
    pub fn connect(server: &Server) -> Self {
        let stream = TcpStream::connect(server.local_addr()).expect("connect");
        let (ws, _) = tungstenite::client(server.ws_url(), stream).expect("handshake");
        ws.get_ref()
            .set_read_timeout(Some(Duration::from_millis(20)))
            .expect("timeout");
        let mut c = Self {
            ws,
            hello: Event::Error {
                message: String::new(),
                request: None,
            },
            vertex_ids: Vec::new(),
            frame: None,
            state: None,
            closed: false,
            close_code: None,
        };
        let hello = c.wait_event(|e| matches!(e, Event::Hello { .. }), "hello");
        if let Event::Hello { vertex_ids, .. } = &hello {
            c.vertex_ids = vertex_ids.clone();
        }
        c.hello = hello;
        c.wait_until(|c| c.frame.is_some(), "a first frame");
        c
    }

    pub fn send(&mut self, text: &str) {
        self.ws.send(Message::text(text)).expect("send");
    }

    /// Reads one message if one arrives soon; events are returned, frames and states kept.
    pub fn poll(&mut self) -> Option<Event> {
        match self.ws.read() {
            Ok(Message::Text(t)) => {
                let e: Event = serde_json::from_str(t.as_str()).expect("events are valid JSON");
                if let Event::State(s) = &e {
                    self.state = Some(s.clone());
                }
                Some(e)
            }
            Ok(Message::Binary(b)) => {
                if let Some(f) = decode_frame(&b) {
                    self.frame = Some(f);
                }
                None
            }
            Ok(Message::Close(frame)) => {
                self.closed = true;
                self.close_code = frame.map(|f| f.code.into());
                None
            }
            Ok(_) => None,
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                None
            }
            Err(_) => {
                self.closed = true;
                None
            }
        }
    }

    /// The first event matching `f` within 10 s.
    pub fn wait_event(&mut self, f: impl Fn(&Event) -> bool, what: &str) -> Event {
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            if let Some(e) = self.poll()
                && f(&e)
            {
                return e;
            }
            assert!(!self.closed, "connection closed waiting for {what}");
        }
        panic!("no {what} within 10 s");
    }

    /// Polls until `f` holds, within 10 s.
    pub fn wait_until(&mut self, f: impl Fn(&Self) -> bool, what: &str) {
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            if f(self) {
                return;
            }
            self.poll();
            assert!(!self.closed, "connection closed waiting for {what}");
        }
        panic!("not {what} within 10 s");
    }

    /// Keeps reading for `d`.
    pub fn read_for(&mut self, d: Duration) -> Vec<Event> {
        let start = Instant::now();
        let mut events = Vec::new();
        while start.elapsed() < d && !self.closed {
            events.extend(self.poll());
        }
        events
    }

    /// The error reply to the message just sent.
    pub fn expect_error(&mut self, text: &str) -> String {
        self.send(text);
        match self.wait_event(|e| matches!(e, Event::Error { .. }), "an error reply") {
            Event::Error { message, .. } => message,
            _ => unreachable!(),
        }
    }

    /// The position of mesh vertex `v` in the latest frame.
    pub fn position(&self, v: usize) -> [f64; 3] {
        let i = self.vertex_ids.binary_search(&v).expect("a surface vertex");
        let f = self.frame.as_ref().expect("a frame");
        [0, 1, 2].map(|c| f64::from(f.positions[3 * i + c]))
    }

    pub fn step(&self) -> u64 {
        self.frame.as_ref().map_or(0, |f| f.step)
    }

    /// Reads until the session has stepped `n` more times.
    pub fn steps_on(&mut self, n: u64) {
        let target = self.step() + n;
        self.wait_until(|c| c.step() >= target, "stepping on");
    }

    pub fn grab(&mut self, text: &str) -> u64 {
        self.send(text);
        match self.wait_event(
            |e| matches!(e, Event::Grabbed { .. } | Event::Error { .. }),
            "a grab reply",
        ) {
            Event::Grabbed { handle, .. } => handle,
            other => panic!("grab failed: {other:?}"),
        }
    }
}

pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
