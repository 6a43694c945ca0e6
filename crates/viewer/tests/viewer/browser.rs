//! The page in headless Chromium, driven through the DevTools protocol: it loads from the
//! server, a real mouse drag on the canvas pulls the body, the HUD shows a steps/s figure, and a
//! body that falls away from where it started stays in view.
//! Without Chromium it says `skipping …` and passes (`.ci/run` installs Debian's `chromium`).
//!
//! `VIEWER_BROWSER_URL=http://127.0.0.1:PORT/` drives a server started elsewhere (e.g. `cargo
//! xtask view`) instead of the tiny beam, and `VIEWER_BROWSER_DRAG=PIXELS` drags that far up
//! (default 120); the screenshot path is printed either way.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tungstenite::{Message, WebSocket};
use viewer::{Method, Server, Session, Settings};

use crate::common::{falling_model, model};

type Result<T> = std::result::Result<T, String>;

/// The Chromium binary: `$CHROMIUM`, else the first of the usual names on the PATH.
fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).find_map(|dir| {
        [
            "chromium",
            "chromium-browser",
            "google-chrome",
            "google-chrome-stable",
        ]
        .iter()
        .map(|name| dir.join(name))
        .find(|p| p.is_file())
    })
}

/// A headless Chromium with its DevTools endpoint; killed on drop.
struct Browser {
    child: Child,
    cdp: Cdp,
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.cdp.call(None, "Browser.close", json!({}));
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(3) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Browser {
    fn start(binary: &Path, profile: &Path) -> Result<Self> {
        let mut child = Command::new(binary)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                // WebGL2 on the CPU: SwiftShader through ANGLE.
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--disable-quic",
                "--no-first-run",
                "--no-default-browser-check",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--disable-extensions",
                "--window-size=1280,800",
                "--remote-debugging-port=0",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", binary.display()))?;
        // Chromium logs freely on stderr: read it to the end on a thread, passing on the line
        // that names the DevTools endpoint.
        let stderr = child.stderr.take().ok_or("no stderr")?;
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(|l| l.ok()) {
                if let Some(at) = line.find("ws://") {
                    let _ = tx.send(line[at..].trim().to_string());
                }
            }
        });
        let endpoint = match rx.recv_timeout(Duration::from_secs(60)) {
            Ok(e) => e,
            Err(_) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err("Chromium printed no DevTools endpoint within 60 s".into());
            }
        };
        let cdp = Cdp::connect(&endpoint)?;
        Ok(Self { child, cdp })
    }
}

/// A DevTools protocol connection (the browser's, with pages attached in flat mode).
struct Cdp {
    ws: WebSocket<TcpStream>,
    next: u64,
}

impl Cdp {
    fn connect(endpoint: &str) -> Result<Self> {
        let host = endpoint
            .trim_start_matches("ws://")
            .split('/')
            .next()
            .ok_or("endpoint")?;
        let stream = TcpStream::connect(host).map_err(|e| format!("DevTools at {host}: {e}"))?;
        stream
            .set_read_timeout(Some(Duration::from_secs(30)))
            .map_err(|e| e.to_string())?;
        let (ws, _) =
            tungstenite::client(endpoint, stream).map_err(|e| format!("DevTools: {e}"))?;
        Ok(Self { ws, next: 1 })
    }

    /// Calls `method` (on the page of `session` when given) and returns its result.
    fn call(&mut self, session: Option<&str>, method: &str, params: Value) -> Result<Value> {
        let id = self.next;
        self.next += 1;
        let mut message = json!({ "id": id, "method": method, "params": params });
        if let Some(s) = session {
            message["sessionId"] = json!(s);
        }
        self.ws
            .send(Message::text(message.to_string()))
            .map_err(|e| format!("{method}: {e}"))?;
        loop {
            let reply = self.ws.read().map_err(|e| format!("{method}: {e}"))?;
            let Message::Text(text) = reply else { continue };
            let v: Value = serde_json::from_str(text.as_str()).map_err(|e| e.to_string())?;
            if v["id"] == json!(id) {
                if let Some(e) = v.get("error") {
                    return Err(format!("{method}: {e}"));
                }
                return Ok(v["result"].clone());
            }
        }
    }
}

/// A page attached in flat mode.
struct Page<'a> {
    cdp: &'a mut Cdp,
    session: String,
}

impl Page<'_> {
    fn call(&mut self, method: &str, params: Value) -> Result<Value> {
        self.cdp.call(Some(&self.session), method, params)
    }

    /// The value of a JavaScript expression on the page.
    fn eval(&mut self, expression: &str) -> Result<Value> {
        let r = self.call(
            "Runtime.evaluate",
            json!({ "expression": expression, "returnByValue": true }),
        )?;
        if let Some(e) = r.get("exceptionDetails") {
            return Err(format!("{expression}: {e}"));
        }
        Ok(r["result"]["value"].clone())
    }

    fn wait_for(&mut self, expression: &str, what: &str) -> Result<()> {
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(30) {
            if self.eval(expression)? == json!(true) {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        Err(format!("not {what} within 30 s"))
    }

    fn mouse(&mut self, kind: &str, x: f64, y: f64, buttons: u32) -> Result<()> {
        let button = if kind == "mouseMoved" && buttons == 0 {
            "none"
        } else {
            "left"
        };
        self.call(
            "Input.dispatchMouseEvent",
            json!({ "type": kind, "x": x, "y": y, "button": button, "buttons": buttons,
                    "clickCount": if kind == "mouseMoved" { 0 } else { 1 } }),
        )
        .map(drop)
    }

    /// Fingers at `points` (finger i has id i): `touchStart`, `touchMove`, or `touchEnd`
    /// with none left.
    fn touch(&mut self, kind: &str, points: &[[f64; 2]]) -> Result<()> {
        let points: Vec<Value> = points
            .iter()
            .enumerate()
            .map(|(id, p)| json!({ "x": p[0], "y": p[1], "id": id }))
            .collect();
        self.call(
            "Input.dispatchTouchEvent",
            json!({ "type": kind, "touchPoints": points }),
        )
        .map(drop)
    }

    /// Presses, moves to or lets go at (x, y) with `input`.
    fn press(&mut self, input: Input, x: f64, y: f64) -> Result<()> {
        match input {
            Input::Mouse => {
                self.mouse("mouseMoved", x, y, 0)?;
                self.mouse("mousePressed", x, y, 1)
            }
            Input::Finger => self.touch("touchStart", &[[x, y]]),
        }
    }

    fn move_to(&mut self, input: Input, x: f64, y: f64) -> Result<()> {
        match input {
            Input::Mouse => self.mouse("mouseMoved", x, y, 1),
            Input::Finger => self.touch("touchMove", &[[x, y]]),
        }
    }

    fn let_go(&mut self, input: Input, x: f64, y: f64) -> Result<()> {
        match input {
            Input::Mouse => self.mouse("mouseReleased", x, y, 0),
            Input::Finger => self.touch("touchEnd", &[]),
        }
    }
}

/// How the test drags: the mouse, or one finger on a touch screen.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Input {
    Mouse,
    Finger,
}

/// Two fingers spread from 100 to 200 pixels apart below the body: the camera comes twice as
/// close, and nothing is grabbed.
fn pinch(page: &mut Page<'_>) -> Result<()> {
    let distance = |page: &mut Page<'_>| -> Result<f64> {
        page.eval("viewerDebug.cameraDistance()")?
            .as_f64()
            .ok_or_else(|| "no camera distance".to_string())
    };
    let before = distance(page)?;
    let (x, y) = (640.0, 780.0);
    page.touch("touchStart", &[[x - 50.0, y], [x + 50.0, y]])?;
    for k in 1..=10 {
        let half = 50.0 + 5.0 * f64::from(k);
        page.touch("touchMove", &[[x - half, y], [x + half, y]])?;
    }
    page.touch("touchEnd", &[])?;
    let ratio = distance(page)? / before;
    if (ratio - 0.5).abs() > 1e-9 {
        return Err(format!(
            "a pinch from 100 to 200 pixels took the camera from {before} to {ratio} times that"
        ));
    }
    if page.eval("viewerDebug.handle()")? != Value::Null {
        return Err("the pinch grabbed the body".into());
    }
    Ok(())
}

fn point(v: &Value) -> Result<[f64; 3]> {
    let a = v.as_array().filter(|a| a.len() == 3).ok_or("a point")?;
    let c = |i: usize| a[i].as_f64().ok_or("a number");
    Ok([c(0)?, c(1)?, c(2)?])
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Standard base64 (the screenshot), without padding checks.
fn base64(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let (mut out, mut acc, mut bits) = (Vec::new(), 0u32, 0);
    for v in text.bytes().filter_map(value) {
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

/// Drags the body on the page with `input` through the DevTools protocol.
fn drag_on_the_page(input: Input) {
    let Some(binary) = chromium() else {
        tests::skip(
            "the viewer's browser test: no chromium on the PATH (apt-get install chromium, or \
             set CHROMIUM)",
        );
        return;
    };
    // Full space first: the drag's effect does not depend on the tiny model's subspace.
    let server = match std::env::var("VIEWER_BROWSER_URL") {
        Ok(_) => None,
        Err(_) => {
            let m = model();
            let methods = vec![
                Method::new(
                    "full",
                    latent_sim::FullRuntime::from_model(m).expect("full"),
                ),
                Method::new("pca", m.simulator().expect("reduced")),
            ];
            let session = Session::new(Settings::for_model(m), methods).expect("a session");
            Some(Server::bind("127.0.0.1:0", session).expect("a port"))
        }
    };
    let url = std::env::var("VIEWER_BROWSER_URL")
        .unwrap_or_else(|_| server.as_ref().map(Server::url).unwrap_or_default());
    let dir = tests::scratch_dir(&format!("viewer-browser-{input:?}"));
    // The test's own server is stopped with the page open, to see the page say so (a server
    // given by VIEWER_BROWSER_URL is not the test's to stop).
    let mut server = server;
    let ours = server.is_some();
    let mut stop = move || {
        if let Some(s) = server.take() {
            s.shutdown();
        }
    };
    let result = drive(
        &binary,
        &dir,
        &url,
        input,
        ours.then_some(&mut stop as &mut dyn FnMut()),
    );
    stop();
    if let Err(e) = result {
        panic!("{e}");
    }
}

#[test]
fn a_mouse_drag_on_the_page_pulls_the_body() {
    drag_on_the_page(Input::Mouse);
}

/// A touch screen: one finger grabs and pulls as the mouse does.
#[test]
fn a_finger_drag_on_the_page_pulls_the_body() {
    drag_on_the_page(Input::Finger);
}

/// Opens `url` in a 1280 × 800 page of `browser` (touch emulated for `Input::Finger`) and waits
/// until it shows the mesh and steps.
fn open_page<'a>(browser: &'a mut Browser, url: &str, input: Input) -> Result<Page<'a>> {
    let target = browser
        .cdp
        .call(None, "Target.createTarget", json!({ "url": "about:blank" }))?;
    let attached = browser.cdp.call(
        None,
        "Target.attachToTarget",
        json!({ "targetId": target["targetId"], "flatten": true }),
    )?;
    let session = attached["sessionId"]
        .as_str()
        .ok_or("no session id")?
        .to_string();
    let mut page = Page {
        cdp: &mut browser.cdp,
        session,
    };
    page.call(
        "Emulation.setDeviceMetricsOverride",
        json!({ "width": 1280, "height": 800, "deviceScaleFactor": 1, "mobile": false }),
    )?;
    if input == Input::Finger {
        page.call(
            "Emulation.setTouchEmulationEnabled",
            json!({ "enabled": true, "maxTouchPoints": 2 }),
        )?;
    }
    page.call("Page.navigate", json!({ "url": url }))?;
    page.wait_for(
        "Boolean(window.viewerDebug && viewerDebug.ready())",
        "the page showing the mesh",
    )?;
    page.wait_for("viewerDebug.state().steps_per_second > 0", "stepping")?;
    Ok(page)
}

/// A body that falls away from where it started stays in view: the camera frames every position
/// it has taken until the person moves the camera, and a turn of the wheel hands it over.
#[test]
fn a_falling_body_stays_in_view() {
    let Some(binary) = chromium() else {
        tests::skip(
            "the viewer's framing test: no chromium on the PATH (apt-get install chromium)",
        );
        return;
    };
    let m = falling_model();
    let methods = vec![Method::new(
        "full",
        latent_sim::FullRuntime::from_model(m).expect("full"),
    )];
    let session = Session::new(Settings::for_model(m), methods).expect("a session");
    let server = Server::bind("127.0.0.1:0", session).expect("a port");
    let dir = tests::scratch_dir("viewer-browser-falling");
    let result = watch_the_fall(&binary, &dir, &server.url());
    server.shutdown();
    if let Err(e) = result {
        panic!("{e}");
    }
}

/// The page draws the scene's up (against gravity) up: of the pinned vertices, which stay where
/// they are, the one highest along up is drawn above the lowest, for a scene with gravity
/// along −y and one along −z (a mesh made with z up, which a y-up camera laid on its side).
#[test]
fn the_scenes_up_is_drawn_up() {
    let Some(binary) = chromium() else {
        tests::skip("the viewer's up test: no chromium on the PATH (apt-get install chromium)");
        return;
    };
    for (m, axis, name) in [
        (falling_model(), 1, "y"),
        (crate::common::z_up_model(), 2, "z"),
    ] {
        let methods = vec![Method::new("pca", m.simulator().expect("a runtime"))];
        let session = Session::new(Settings::for_model(m), methods).expect("a session");
        let server = Server::bind("127.0.0.1:0", session).expect("a port");
        let dir = tests::scratch_dir(&format!("viewer-browser-up-{name}"));
        let result = (|| -> Result<Value> {
            let mut browser = Browser::start(&binary, &dir.join("profile"))?;
            let mut page = open_page(&mut browser, &server.url(), Input::Mouse)?;
            // Screen y grows downwards: the highest pinned vertex's minus the lowest's.
            page.eval(&format!(
                "(() => {{ const p = viewerDebug.pinned(); \
                 const along = (i) => viewerDebug.position(i)[{axis}]; \
                 const hi = p.reduce((a, b) => (along(b) > along(a) ? b : a)); \
                 const lo = p.reduce((a, b) => (along(b) < along(a) ? b : a)); \
                 return viewerDebug.screenOf(hi).y - viewerDebug.screenOf(lo).y; }})()"
            ))
        })();
        server.shutdown();
        let above = result.unwrap_or_else(|e| panic!("{name} up: {e}"));
        let pixels = above.as_f64().unwrap_or(f64::NAN);
        assert!(
            pixels < -20.0,
            "gravity along -{name}: the pinned vertex highest along {name} is drawn {pixels} px \
             below the lowest"
        );
    }
}

fn watch_the_fall(binary: &Path, dir: &Path, url: &str) -> Result<()> {
    let mut browser = Browser::start(binary, &dir.join("profile"))?;
    let mut page = open_page(&mut browser, url, Input::Mouse)?;
    let camera = |page: &mut Page<'_>| -> Result<f64> {
        page.eval("viewerDebug.cameraDistance()")?
            .as_f64()
            .ok_or_else(|| "no camera distance".to_string())
    };
    // Rest at y ∈ [0, 0.2]: framed as at rest, the view shows down to about y = −0.5; the body
    // falls until it hangs about a metre below.
    page.wait_for(
        "(() => { let low = Infinity; for (let i = 0; i < viewerDebug.vertexCount(); i++) \
         low = Math.min(low, viewerDebug.position(i)[1]); return low; })() < -0.7",
        "the body falling 0.7 m below where it rested",
    )?;
    // The body keeps falling and swinging; every vertex stays on the page.
    for _ in 0..10 {
        std::thread::sleep(Duration::from_millis(100));
        let outside = page.eval("viewerDebug.outsideView()")?;
        if outside != json!(0) {
            let n = page.eval("viewerDebug.vertexCount()")?;
            return Err(format!(
                "{outside} of {n} vertices are drawn outside the page"
            ));
        }
    }
    page.call(
        "Input.dispatchMouseEvent",
        json!({ "type": "mouseWheel", "x": 640, "y": 400, "deltaX": 0, "deltaY": 100 }),
    )?;
    page.wait_for(
        "viewerDebug.following() === false",
        "the camera handed over by the wheel",
    )?;
    let handed = camera(&mut page)?;
    std::thread::sleep(Duration::from_millis(500));
    let later = camera(&mut page)?;
    if later != handed {
        return Err(format!(
            "the camera moved from {handed} to {later} after the wheel handed it over"
        ));
    }
    Ok(())
}

fn drive(
    binary: &Path,
    dir: &Path,
    url: &str,
    input: Input,
    stop_server: Option<&mut dyn FnMut()>,
) -> Result<()> {
    let mut browser = Browser::start(binary, &dir.join("profile"))?;
    let mut page = open_page(&mut browser, url, input)?;
    if page.eval("viewerDebug.following()")? != json!(true) {
        return Err("the camera does not frame the body before anyone touched it".into());
    }
    // The server quotes keys between backticks, as the terminal does: the page shows them as
    // code, without the backticks, and never as markup.
    let shown = page.eval(
        "viewerDebug.say('larger pulls (`[training] offset`) reach `<b>such</b>` drags'); \
         [document.getElementById('message').textContent, \
          Array.from(document.querySelectorAll('#message code'), c => c.textContent)]",
    )?;
    let expected = json!([
        "larger pulls ([training] offset) reach <b>such</b> drags",
        ["[training] offset", "<b>such</b>"]
    ]);
    if shown != expected {
        return Err(format!(
            "a quoted message is shown as {shown}, not {expected}"
        ));
    }
    // A backtick without its pair stays one (a client's own text echoed in an error).
    let shown = page.eval(
        "viewerDebug.say('a `b` c `d'); \
         [document.getElementById('message').textContent, \
          Array.from(document.querySelectorAll('#message code'), c => c.textContent)]",
    )?;
    let expected = json!(["a b c `d", ["b"]]);
    if shown != expected {
        return Err(format!(
            "an odd backtick is shown as {shown}, not {expected}"
        ));
    }
    let candidate = page.eval("viewerDebug.grabCandidate()")?;
    let vertex = candidate["vertex"]
        .as_u64()
        .ok_or_else(|| format!("no surface vertex the mouse can pick on the page: {candidate}"))?;
    let (x, y) = (
        candidate["x"].as_f64().ok_or("x")?,
        candidate["y"].as_f64().ok_or("y")?,
    );
    let before = point(&page.eval(&format!("viewerDebug.position({vertex})"))?)?;
    page.press(input, x, y)?;
    if let Err(e) = page.wait_for("viewerDebug.handle() !== null", "a handle from the grab") {
        let said = page.eval("document.getElementById('message').textContent")?;
        return Err(format!("{e} ({input:?} at {x}, {y}; the page says {said})"));
    }
    if page.eval("viewerDebug.following()")? != json!(false) {
        return Err("the camera still follows the body after a grab".into());
    }
    let pixels: f64 = std::env::var("VIEWER_BROWSER_DRAG")
        .ok()
        .and_then(|p| p.parse().ok())
        .unwrap_or(120.0);
    for k in 1..=20 {
        page.move_to(input, x, y - pixels * f64::from(k) / 20.0)?;
        std::thread::sleep(Duration::from_millis(25));
    }
    std::thread::sleep(Duration::from_millis(1500));
    let during = point(&page.eval(&format!("viewerDebug.position({vertex})"))?)?;
    let aim = point(&page.eval("viewerDebug.target()")?)?;
    let shot = page.call("Page.captureScreenshot", json!({ "format": "png" }))?;
    let png = base64(shot["data"].as_str().ok_or("no screenshot data")?);
    let path = dir.join("viewer.png");
    std::fs::write(&path, &png).map_err(|e| format!("{}: {e}", path.display()))?;
    println!("screenshot: {}", path.display());
    let sps: f64 = page
        .eval("document.getElementById('sps').textContent")?
        .as_str()
        .and_then(|s| s.trim().parse().ok())
        .ok_or("the HUD shows no steps/s figure")?;
    let cost: f64 = page
        .eval("document.getElementById('cost').textContent")?
        .as_str()
        .and_then(|s| s.trim().parse().ok())
        .ok_or("the HUD shows no ms a step")?;
    let hud = page.eval("viewerDebug.hud()")?;
    page.let_go(input, x, y - pixels)?;
    page.wait_for(
        "viewerDebug.handle() === null && viewerDebug.state().handles === 0",
        "the handle released",
    )?;
    if input == Input::Finger {
        pinch(&mut page)?;
    }
    let moved = distance(during, before);
    let pulled = distance(aim, before);
    if !(pulled > 0.0 && moved > 0.25 * pulled) {
        return Err(format!(
            "the grabbed vertex {vertex} moved {moved:.4} m toward a target {pulled:.4} m away"
        ));
    }
    if !(sps > 0.0 && hud.as_str().is_some_and(|h| h.contains("steps/s"))) {
        return Err(format!("the HUD shows no steps/s figure: {hud}"));
    }
    if !(cost > 0.0 && cost.is_finite()) {
        return Err(format!("the HUD shows no cost of a step: {hud}"));
    }
    // With the server gone the page says so, shows no figures and offers no controls.
    if let Some(stop) = stop_server {
        stop();
        page.wait_for(
            "document.getElementById('status').textContent.startsWith('disconnected') \
             && document.getElementById('sps').textContent === '–' \
             && document.getElementById('cost').textContent === '–' \
             && document.getElementById('beyond').textContent === '–' \
             && document.getElementById('step').textContent === '–' \
             && document.getElementById('fps').textContent === '–' \
             && document.getElementById('pause').disabled \
             && document.getElementById('radius').disabled",
            "the page greyed out once the server stopped",
        )?;
        let shot = page.call("Page.captureScreenshot", json!({ "format": "png" }))?;
        let png = base64(shot["data"].as_str().ok_or("no screenshot data")?);
        let path = dir.join("viewer-disconnected.png");
        std::fs::write(&path, &png).map_err(|e| format!("{}: {e}", path.display()))?;
        println!("screenshot: {}", path.display());
    }
    Ok(())
}
