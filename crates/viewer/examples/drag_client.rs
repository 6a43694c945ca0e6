//! A scripted client of a running viewer: drags the body as a person would and measures what
//! the page would get, method by method — the figures of `docs/viewer.md`.
//!
//! ```sh
//! cargo xtask view --scene data/beam6k.toml --port 8080 &
//! cargo run --release -p viewer --example drag_client -- 127.0.0.1:8080 [SECONDS] [METHOD…]
//! ```
//!
//! For each method (default: the current one, then `full`) it switches to it, waits a second,
//! grabs the surface vertex farthest from the pins where it is and moves the target up and down by a tenth
//! of the mesh's size at 60 messages a second (a mouse's rate) for SECONDS (default 10). Every
//! 0.25 s one move carries a `seq`; its latency is the time from sending it to receiving the
//! first frame of a step that includes it (the server's `applied` reply names that step).
//! It prints per method the steps per second, iterations per step, ms per step and real-time
//! factor the server reports during the drag, the frames per second received, and the latency.

use std::net::TcpStream;
use std::time::{Duration, Instant};

use pipeline::simulate::median;
use tungstenite::{Message, WebSocket};
use viewer::protocol::{Event, State, decode_frame, decode_mesh};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

struct Client {
    ws: WebSocket<TcpStream>,
    /// The surface positions of the latest frame.
    latest: Vec<f32>,
}

/// What arrived in one read.
enum Got {
    Event(Event),
    Frame { step: u64, at: Instant },
    Mesh(viewer::protocol::Mesh),
    Nothing,
}

impl Client {
    fn read(&mut self) -> Result<Got> {
        match self.ws.read() {
            Ok(Message::Text(t)) => Ok(Got::Event(serde_json::from_str(t.as_str())?)),
            Ok(Message::Binary(b)) => {
                let at = Instant::now();
                if let Some(f) = decode_frame(&b) {
                    self.latest = f.positions;
                    Ok(Got::Frame { step: f.step, at })
                } else if let Some(m) = decode_mesh(&b) {
                    Ok(Got::Mesh(m))
                } else {
                    Ok(Got::Nothing)
                }
            }
            Ok(Message::Close(_)) => Err("the server closed the connection".into()),
            Ok(_) => Ok(Got::Nothing),
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(Got::Nothing)
            }
            Err(e) => Err(e.into()),
        }
    }

    fn send(&mut self, text: String) -> Result<()> {
        Ok(self.ws.send(Message::text(text))?)
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(addr) = args.first() else {
        eprintln!("usage: drag_client HOST:PORT [SECONDS] [METHOD…]");
        std::process::exit(2);
    };
    let seconds: f64 = args.get(1).map_or(Ok(10.0), |s| s.parse())?;
    let stream = TcpStream::connect(addr)?;
    let (ws, _) = tungstenite::client(format!("ws://{addr}/ws"), stream)?;
    ws.get_ref()
        .set_read_timeout(Some(Duration::from_millis(1)))?;
    ws.get_ref().set_nodelay(true)?;
    let mut c = Client {
        ws,
        latest: Vec::new(),
    };
    let (mut hello, mut mesh) = (None, None);
    while hello.is_none() || mesh.is_none() {
        match c.read()? {
            Got::Event(e @ Event::Hello { .. }) => hello = Some(e),
            Got::Mesh(m) => mesh = Some(m),
            _ => {}
        }
    }
    let (
        Some(Event::Hello {
            scene,
            methods,
            method,
            time_step,
            surface_vertices,
            ..
        }),
        Some(mesh),
    ) = (hello, mesh)
    else {
        unreachable!()
    };
    let wanted: Vec<String> = if args.len() > 2 {
        args[2..].to_vec()
    } else {
        let mut w = vec![method.clone()];
        if method != "full" && methods.iter().any(|m| m == "full") {
            w.push("full".into());
        }
        w
    };
    // The grab: the surface vertex farthest from the pinned ones' centre.
    let rest = |i: usize| [0, 1, 2].map(|c| f64::from(mesh.rest[3 * i + c]));
    let anchor: Vec<usize> = if mesh.pinned.is_empty() {
        (0..surface_vertices).collect()
    } else {
        mesh.pinned.iter().map(|&p| p as usize).collect()
    };
    let centre = anchor.iter().fold([0.0; 3], |s, &i| {
        let r = rest(i);
        [s[0] + r[0], s[1] + r[1], s[2] + r[2]]
    });
    let centre = centre.map(|x| x / anchor.len() as f64);
    let dist = |a: [f64; 3], b: [f64; 3]| {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    let tip = (0..surface_vertices)
        .max_by(|&a, &b| dist(rest(a), centre).total_cmp(&dist(rest(b), centre)))
        .ok_or("no surface")?;
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for i in 0..surface_vertices {
        for (k, x) in rest(i).into_iter().enumerate() {
            lo[k] = lo[k].min(x);
            hi[k] = hi[k].max(x);
        }
    }
    let size = dist(lo, hi);
    println!(
        "{scene}: {surface_vertices} surface vertices, h = {} ms; dragging surface vertex {tip} \
         by ±{:.3} m at 60 moves/s for {seconds} s per method",
        time_step * 1e3,
        0.1 * size
    );
    println!(
        "\n| method | steps/s | iterations/step | ms/step | real-time factor | frames/s received | drag → frame latency (median, max) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for m in &wanted {
        measure(&mut c, m, tip, size, seconds)?;
    }
    Ok(())
}

fn measure(c: &mut Client, method: &str, tip: usize, size: f64, seconds: f64) -> Result<()> {
    c.send(format!(r#"{{"type":"method","name":"{method}"}}"#))?;
    let settle = Instant::now();
    while settle.elapsed() < Duration::from_secs(1) {
        if let Got::Event(Event::Error { message, .. }) = c.read()? {
            return Err(message.into());
        }
    }
    // Where the vertex is now (it sags under gravity), not where it rests.
    let at = [0, 1, 2].map(|k| f64::from(c.latest.get(3 * tip + k).copied().unwrap_or(f32::NAN)));
    c.send(format!(
        r#"{{"type":"grab","point":[{},{},{}]}}"#,
        at[0], at[1], at[2]
    ))?;
    let handle = loop {
        match c.read()? {
            Got::Event(Event::Grabbed { handle, .. }) => break handle,
            Got::Event(Event::Error { message, .. }) => return Err(message.into()),
            _ => {}
        }
    };
    let start = Instant::now();
    let (mut frames, mut states) = (0usize, Vec::<State>::new());
    let mut sent: Vec<(u64, Instant)> = Vec::new();
    let mut awaiting: Vec<(u64, Instant)> = Vec::new(); // (step, sent at)
    let mut latencies = Vec::new();
    let (mut next_move, mut seq) = (start, 0u64);
    let period = 2.0;
    while start.elapsed().as_secs_f64() < seconds {
        let now = Instant::now();
        if now >= next_move {
            let t = start.elapsed().as_secs_f64();
            let y = at[1] + 0.1 * size * (2.0 * std::f64::consts::PI * t / period).sin();
            let tag = if (t / 0.25).floor() as u64 > seq {
                seq = (t / 0.25).floor() as u64;
                sent.push((seq, now));
                format!(r#","seq":{seq}"#)
            } else {
                String::new()
            };
            c.send(format!(
                r#"{{"type":"move","handle":{handle},"target":[{},{y},{}]{tag}}}"#,
                at[0], at[2]
            ))?;
            next_move += Duration::from_secs_f64(1.0 / 60.0);
        }
        match c.read()? {
            Got::Frame { step, at } => {
                frames += 1;
                awaiting.retain(|&(s, sent_at)| {
                    if step >= s {
                        latencies.push((at - sent_at).as_secs_f64() * 1e3);
                        false
                    } else {
                        true
                    }
                });
            }
            Got::Event(Event::Applied { seq, step }) => {
                if let Some(&(_, sent_at)) = sent.iter().find(|(s, _)| *s == seq) {
                    awaiting.push((step, sent_at));
                }
            }
            // Skip the first second's states: the speed window then still holds the settling.
            Got::Event(Event::State(s)) if start.elapsed() > Duration::from_secs(1) => {
                states.push(s)
            }
            Got::Event(Event::Error { message, .. }) => eprintln!("error: {message}"),
            _ => {}
        }
    }
    let elapsed = start.elapsed().as_secs_f64();
    c.send(format!(r#"{{"type":"release","handle":{handle}}}"#))?;
    // NaN, not 0, when the server sent nothing to measure.
    let med = |v: &[f64]| if v.is_empty() { f64::NAN } else { median(v) };
    let pick = |f: fn(&State) -> f64| med(&states.iter().map(f).collect::<Vec<_>>());
    let sps = pick(|s| s.steps_per_second);
    let its = pick(|s| s.iterations_per_step);
    let ms = pick(|s| s.step_ms);
    let rtf = pick(|s| s.real_time_factor);
    let max_latency = latencies.iter().copied().fold(f64::NAN, f64::max);
    let samples = latencies.len();
    println!(
        "| {method} | {sps:.0} | {its:.1} | {ms:.2} | {rtf:.2} | {:.0} | {:.1} ms, {max_latency:.1} ms ({samples} moves) |",
        frames as f64 / elapsed,
        med(&latencies)
    );
    Ok(())
}
