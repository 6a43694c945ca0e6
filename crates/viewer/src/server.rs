//! The server: one thread accepting connections, one stepping the session, one per connection.
//!
//! A connection is either a plain HTTP request for one of the page's assets or a WebSocket at
//! `/ws`. Each WebSocket's thread alternates between reading (with a short timeout) and sending
//! what the simulation left for it: its events in order, then the latest frame. A connection
//! that sends garbage gets error replies; one that stalls for [`WRITE_TIMEOUT`] is dropped; when
//! one goes, the simulation releases its handles.

use std::io::ErrorKind;
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tungstenite::protocol::WebSocketConfig;
use tungstenite::protocol::frame::coding::CloseCode;
use tungstenite::protocol::{CloseFrame, WebSocket};
use tungstenite::{Message, error::CapacityError};

use crate::ViewerError;
use crate::http::{self, Head};
use crate::protocol::{Event, MAX_MESSAGE_BYTES, MAX_WIRE_MESSAGE, Request};
use crate::session::{Command, Outbox, Outgoing, Session};

/// Requests queued for the simulation; beyond this a client's message is refused as "busy".
const QUEUE: usize = 1024;
/// Connections served at once; more are answered 503.
const MAX_CONNECTIONS: usize = 64;
/// How long a connection's thread waits for a client's message before sending what is due.
const POLL: Duration = Duration::from_millis(2);
/// A client that does not take a message within this is dropped.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// The longest wait for a request's head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// The largest request head read.
const MAX_HEAD: usize = 8 * 1024;

/// A running viewer server. Dropping it (or [`Server::shutdown`]) stops its threads.
#[derive(Debug)]
pub struct Server {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

/// What every connection's thread shares.
#[derive(Debug, Clone)]
struct Context {
    commands: SyncSender<Command>,
    stop: Arc<AtomicBool>,
    /// Bound to loopback: only requests naming a loopback host are served (no DNS rebinding).
    loopback: bool,
    live: Arc<AtomicUsize>,
}

impl Server {
    /// Listens on `addr` (port 0 picks a free port) and starts stepping `session`.
    ///
    /// # Errors
    /// [`ViewerError::Bind`] when the address cannot be listened on, [`ViewerError::Thread`] when
    /// a thread cannot start.
    pub fn bind(addr: impl ToSocketAddrs, session: Session) -> Result<Self, ViewerError> {
        let name = addr
            .to_socket_addrs()
            .ok()
            .and_then(|mut a| a.next())
            .map_or_else(|| "the given address".to_string(), |a| a.to_string());
        let bind_error = |source| ViewerError::Bind {
            addr: name.clone(),
            source,
        };
        let listener = TcpListener::bind(addr).map_err(bind_error)?;
        Self::serve(listener, session)
    }

    /// Serves `session` on a listener bound already (e.g. to try one port, then another).
    ///
    /// # Errors
    /// [`ViewerError::Bind`] when the listener cannot be set up, [`ViewerError::Thread`] when a
    /// thread cannot start.
    pub fn serve(listener: TcpListener, session: Session) -> Result<Self, ViewerError> {
        let bind_error = |source| ViewerError::Bind {
            addr: "the listener".into(),
            source,
        };
        let local = listener.local_addr().map_err(bind_error)?;
        listener.set_nonblocking(true).map_err(bind_error)?;
        let stop = Arc::new(AtomicBool::new(false));
        let (commands, receiver) = mpsc::sync_channel(QUEUE);
        let sim_stop = Arc::clone(&stop);
        let simulation = std::thread::Builder::new()
            .name("viewer-simulation".into())
            .spawn(move || session.run(receiver, &sim_stop))
            .map_err(ViewerError::Thread)?;
        let context = Context {
            commands,
            stop: Arc::clone(&stop),
            loopback: local.ip().is_loopback(),
            live: Arc::new(AtomicUsize::new(0)),
        };
        let accept = std::thread::Builder::new()
            .name("viewer-accept".into())
            .spawn(move || accept_loop(&listener, &context))
            .map_err(ViewerError::Thread)?;
        tracing::info!("viewer listening on http://{local}/");
        Ok(Self {
            addr: local,
            stop,
            threads: vec![accept, simulation],
        })
    }

    /// The address it listens on (with the port chosen for port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's address, e.g. `http://127.0.0.1:8080/`.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// The WebSocket's address, e.g. `ws://127.0.0.1:8080/ws`.
    pub fn ws_url(&self) -> String {
        format!("ws://{}/ws", self.addr)
    }

    /// Serves until the process ends (or the simulation thread stops).
    pub fn wait(mut self) {
        for t in self.threads.drain(..) {
            if t.join().is_err() {
                tracing::error!("a viewer thread panicked");
            }
        }
    }

    /// Stops accepting, closes every connection and stops the simulation; returns when all
    /// threads have ended.
    pub fn shutdown(mut self) {
        self.stop_threads();
    }

    fn stop_threads(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            if t.join().is_err() {
                tracing::error!("a viewer thread panicked");
            }
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop_threads();
    }
}

fn accept_loop(listener: &TcpListener, context: &Context) {
    let next_client = AtomicU64::new(1);
    let mut connections: Vec<JoinHandle<()>> = Vec::new();
    while !context.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((mut stream, peer)) => {
                connections.retain(|c| !c.is_finished());
                if stream.set_nonblocking(false).is_err() {
                    continue;
                }
                if context.live.load(Ordering::Relaxed) >= MAX_CONNECTIONS {
                    let _ = http::status(&mut stream, 503, "Service Unavailable", "too many\n");
                    continue;
                }
                let client = next_client.fetch_add(1, Ordering::Relaxed);
                let ctx = context.clone();
                ctx.live.fetch_add(1, Ordering::Relaxed);
                let spawned = std::thread::Builder::new()
                    .name(format!("viewer-client-{client}"))
                    .spawn(move || {
                        connection(stream, client, &ctx);
                        ctx.live.fetch_sub(1, Ordering::Relaxed);
                    });
                match spawned {
                    Ok(t) => connections.push(t),
                    Err(e) => {
                        context.live.fetch_sub(1, Ordering::Relaxed);
                        tracing::error!("cannot serve {peer}: {e}");
                    }
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(e) => {
                tracing::warn!("accept: {e}");
                std::thread::sleep(Duration::from_millis(10));
            }
        }
    }
    for c in connections {
        let _ = c.join();
    }
}

/// Reads (without consuming) the request's head, up to its blank line.
fn peek_head(stream: &TcpStream) -> Option<Vec<u8>> {
    stream.set_read_timeout(Some(HEAD_TIMEOUT)).ok()?;
    let start = Instant::now();
    let mut buf = vec![0u8; MAX_HEAD];
    loop {
        let n = stream.peek(&mut buf).ok()?;
        if n == 0 {
            return None;
        }
        if let Some(end) = buf[..n].windows(4).position(|w| w == b"\r\n\r\n") {
            buf.truncate(end + 4);
            return Some(buf);
        }
        if n == buf.len() || start.elapsed() > HEAD_TIMEOUT {
            return None;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn connection(mut stream: TcpStream, client: u64, ctx: &Context) {
    if stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_err() {
        return;
    }
    let Some(bytes) = peek_head(&stream) else {
        let _ = http::status(&mut stream, 400, "Bad Request", "no request head\n");
        return;
    };
    let Some(head) = Head::parse(&bytes) else {
        let _ = http::status(&mut stream, 400, "Bad Request", "not an HTTP request\n");
        return;
    };
    let host = head.header("host").unwrap_or("");
    if ctx.loopback && !http::is_loopback_host(host) {
        let _ = http::status(
            &mut stream,
            403,
            "Forbidden",
            "this viewer listens on loopback and answers only to localhost\n",
        );
        return;
    }
    if head.path == "/ws" {
        // A refusal reads the head first, so the client reads the reply, not a reset.
        let mut refuse = |code, reason, extra, body| {
            let mut head_bytes = vec![0u8; bytes.len()];
            if std::io::Read::read_exact(&mut stream, &mut head_bytes).is_ok() {
                let _ = http::status_with(&mut stream, code, reason, extra, body);
            }
        };
        // A page from another site must not drive the session: same origin or no origin (a
        // script) only.
        if let Some(origin) = head.header("origin")
            && origin != format!("http://{host}")
        {
            return refuse(403, "Forbidden", "", "cross-origin WebSocket\n");
        }
        if !head.is_upgrade() {
            return refuse(426, "Upgrade Required", "", "a WebSocket\n");
        }
        // What the handshake needs, said to the client (the handshake's own failure is only
        // logged, and the connection closed without a reply); a version other than 13 gets
        // the version this server speaks (RFC 6455, 4.4).
        if head.header("sec-websocket-key").is_none_or(str::is_empty) {
            return refuse(
                400,
                "Bad Request",
                "",
                "a WebSocket upgrade needs a Sec-WebSocket-Key\n",
            );
        }
        if head.header("sec-websocket-version") != Some("13") {
            return refuse(
                426,
                "Upgrade Required",
                "Sec-WebSocket-Version: 13\r\n",
                "this server speaks WebSocket version 13\n",
            );
        }
        websocket(stream, client, ctx);
    } else {
        // Consume the head before answering, so the client reads the reply, not a reset.
        let mut head_bytes = vec![0u8; bytes.len()];
        if std::io::Read::read_exact(&mut stream, &mut head_bytes).is_ok() {
            let _ = http::respond(&mut stream, &head);
        }
    }
}

fn websocket(stream: TcpStream, client: u64, ctx: &Context) {
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_WIRE_MESSAGE))
        .max_frame_size(Some(MAX_WIRE_MESSAGE));
    let mut ws = match tungstenite::accept_with_config(stream, Some(config)) {
        Ok(ws) => ws,
        Err(e) => {
            tracing::debug!("WebSocket handshake with client {client}: {e}");
            return;
        }
    };
    if ws.get_ref().set_read_timeout(Some(POLL)).is_err()
        || ws.get_ref().set_write_timeout(Some(WRITE_TIMEOUT)).is_err()
    {
        return;
    }
    let _ = ws.get_ref().set_nodelay(true);
    let (events, inbox) = mpsc::channel();
    let frame = Arc::new(Mutex::new(None));
    let outbox = Outbox {
        events,
        frame: Arc::clone(&frame),
    };
    if ctx
        .commands
        .send(Command::Connect { client, outbox })
        .is_err()
    {
        return;
    }
    let unread = serve(&mut ws, client, ctx, &inbox, &frame);
    let _ = ctx.commands.send(Command::Disconnect { client });
    // After the session has let the client go (its handles released at once).
    if unread {
        linger(ws.get_mut());
    }
}

/// Whether an I/O error is a read timing out, not the connection failing.
fn timed_out(e: &tungstenite::Error) -> bool {
    matches!(e, tungstenite::Error::Io(io)
        if matches!(io.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut))
}

fn error_text(request: Option<&str>, message: String) -> Message {
    let event = Event::Error {
        message,
        request: request.map(str::to_string),
    };
    Message::text(serde_json::to_string(&event).unwrap_or_default())
}

/// The connection's loop, until the client leaves, the server stops or a write fails; true
/// when it closed on a message too long to read, whose rest the client may still be sending.
fn serve(
    ws: &mut WebSocket<TcpStream>,
    client: u64,
    ctx: &Context,
    inbox: &mpsc::Receiver<Outgoing>,
    frame: &Mutex<Option<tungstenite::Bytes>>,
) -> bool {
    loop {
        if ctx.stop.load(Ordering::Relaxed) {
            let _ = ws.close(Some(CloseFrame {
                code: CloseCode::Away,
                reason: "the server is stopping".into(),
            }));
            let _ = ws.flush();
            return false;
        }
        let reply = match ws.read() {
            Ok(Message::Text(text)) => request(text.as_str(), client, ctx),
            Ok(Message::Binary(_)) => Some(error_text(
                None,
                "binary messages are not accepted; send JSON text".into(),
            )),
            Ok(Message::Close(_)) => {
                // tungstenite has queued the closing reply; send it and stop.
                let _ = ws.flush();
                return false;
            }
            Ok(_) => None,
            Err(e) if timed_out(&e) => None,
            Err(tungstenite::Error::Utf8(_)) => Some(error_text(
                None,
                "a text message that is not UTF-8; send JSON text".into(),
            )),
            Err(tungstenite::Error::Capacity(CapacityError::MessageTooLong { size, max_size })) => {
                let _ = ws.close(Some(CloseFrame {
                    code: CloseCode::Size,
                    reason: format!("a message of {size} bytes; at most {max_size}").into(),
                }));
                let _ = ws.flush();
                return true;
            }
            Err(e) => {
                tracing::debug!("client {client}: {e}");
                return false;
            }
        };
        if let Some(reply) = reply
            && ws.send(reply).is_err()
        {
            return false;
        }
        while let Ok(out) = inbox.try_recv() {
            let message = match out {
                Outgoing::Text(t) => Message::text(t),
                Outgoing::Binary(b) => Message::Binary(b),
            };
            if ws.send(message).is_err() {
                return false;
            }
        }
        let latest = frame.lock().ok().and_then(|mut f| f.take());
        if let Some(bytes) = latest
            && ws.send(Message::Binary(bytes)).is_err()
        {
            return false;
        }
    }
}

/// After a close frame sent while the client may still be sending (the rest of a message too
/// long to read): no more writes, and what arrives is read and dropped for up to
/// [`LINGER`], so that the client reads the close frame. Closing with unread bytes makes the
/// kernel reset the connection, and a reset discards the frame on its way (a tester's 2 MiB
/// message got a reset, not code 1009).
fn linger(stream: &mut TcpStream) {
    let _ = stream.shutdown(std::net::Shutdown::Write);
    let start = Instant::now();
    let mut sink = [0u8; 16 * 1024];
    while start.elapsed() < LINGER {
        match std::io::Read::read(stream, &mut sink) {
            Ok(0) => return,
            Ok(_) => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => return,
        }
    }
}

/// How long [`linger`] reads what a client still sends after its connection was closed.
const LINGER: Duration = Duration::from_secs(2);

/// Reads one client message and queues it for the simulation; `Some` is the error reply.
fn request(text: &str, client: u64, ctx: &Context) -> Option<Message> {
    if text.len() > MAX_MESSAGE_BYTES {
        return Some(error_text(
            None,
            format!(
                "a message of {} bytes; at most {MAX_MESSAGE_BYTES} are read",
                text.len()
            ),
        ));
    }
    let request: Request = match serde_json::from_str(text) {
        Ok(r) => r,
        Err(e) => {
            // Its type, where the message has one, so that the reply names the request.
            let kind = serde_json::from_str::<serde_json::Value>(text)
                .ok()
                .and_then(|v| v.get("type")?.as_str().map(str::to_string));
            return Some(error_text(
                kind.as_deref(),
                format!("not a valid request: {e}"),
            ));
        }
    };
    let kind = request.kind();
    match ctx.commands.try_send(Command::Request { client, request }) {
        Ok(()) => None,
        Err(TrySendError::Full(_)) => Some(error_text(
            Some(kind),
            "the server is busy (its queue is full); the message was dropped".into(),
        )),
        Err(TrySendError::Disconnected(_)) => {
            Some(error_text(Some(kind), "the simulation has stopped".into()))
        }
    }
}
