//! The page's assets, compiled into the binary, and the little HTTP/1.1 the server speaks to
//! deliver them: GET or HEAD of a known path, one request per connection.

use std::io::Write;
use std::net::TcpStream;

/// The page and its script and style sheet.
const ASSETS: &[(&str, &str, &str)] = &[
    (
        "/",
        "text/html; charset=utf-8",
        include_str!("../assets/index.html"),
    ),
    (
        "/viewer.js",
        "text/javascript; charset=utf-8",
        include_str!("../assets/viewer.js"),
    ),
    (
        "/viewer.css",
        "text/css; charset=utf-8",
        include_str!("../assets/viewer.css"),
    ),
];

/// The start of a request: method, path (without query) and headers (names lower-case).
#[derive(Debug)]
pub(crate) struct Head {
    pub method: String,
    pub path: String,
    pub headers: Vec<(String, String)>,
}

impl Head {
    /// Parses the bytes up to the blank line; `None` when they are not an HTTP/1.x request.
    pub fn parse(bytes: &[u8]) -> Option<Self> {
        let text = std::str::from_utf8(bytes).ok()?;
        let mut lines = text.split("\r\n");
        let mut request = lines.next()?.split(' ');
        let (method, target, version) = (request.next()?, request.next()?, request.next()?);
        if !version.starts_with("HTTP/1.") || request.next().is_some() {
            return None;
        }
        let path = target.split(['?', '#']).next().unwrap_or(target);
        let headers = lines
            .take_while(|l| !l.is_empty())
            .filter_map(|l| {
                let (name, value) = l.split_once(':')?;
                Some((name.trim().to_ascii_lowercase(), value.trim().to_string()))
            })
            .collect();
        Some(Self {
            method: method.to_string(),
            path: path.to_string(),
            headers,
        })
    }

    /// The value of header `name` (lower-case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    /// Whether the request asks to become a WebSocket.
    pub fn is_upgrade(&self) -> bool {
        self.header("upgrade")
            .is_some_and(|v| v.eq_ignore_ascii_case("websocket"))
    }
}

/// Whether the host named in a `Host` header (with or without port) is this machine's loopback.
/// A malformed one (`[::1` without its bracket, a port that is not a number) is not.
pub(crate) fn is_loopback_host(host: &str) -> bool {
    let (name, port) = match host.strip_prefix('[') {
        Some(rest) => match rest.split_once(']') {
            Some(parts) => parts,
            None => return false,
        },
        None => host.split_at(host.find(':').unwrap_or(host.len())),
    };
    let port_ok = port.is_empty()
        || port
            .strip_prefix(':')
            .is_some_and(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()));
    port_ok
        && (name.eq_ignore_ascii_case("localhost")
            || name
                .parse::<std::net::IpAddr>()
                .is_ok_and(|ip| ip.is_loopback()))
}

/// Answers `head` with an asset, or 404 / 405.
pub(crate) fn respond(stream: &mut TcpStream, head: &Head) -> std::io::Result<()> {
    let body_too = match head.method.as_str() {
        "GET" => true,
        "HEAD" => false,
        _ => return status(stream, 405, "Method Not Allowed", "GET or HEAD only\n"),
    };
    let path = if head.path == "/index.html" {
        "/"
    } else {
        head.path.as_str()
    };
    let Some(&(_, content_type, body)) = ASSETS.iter().find(|(p, _, _)| *p == path) else {
        return status(stream, 404, "Not Found", "no such page\n");
    };
    let header = format!(
        "HTTP/1.1 200 OK\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n{}\r\n",
        body.len(),
        COMMON_HEADERS
    );
    stream.write_all(header.as_bytes())?;
    if body_too {
        stream.write_all(body.as_bytes())?;
    }
    stream.flush()
}

/// Every response: no caching (the page belongs to one build), nothing from elsewhere.
const COMMON_HEADERS: &str = "Cache-Control: no-store\r\nConnection: close\r\n\
X-Content-Type-Options: nosniff\r\nReferrer-Policy: no-referrer\r\n\
Content-Security-Policy: default-src 'self'; connect-src 'self'; img-src 'self' data:\r\n";

/// A plain-text status response.
pub(crate) fn status(
    stream: &mut TcpStream,
    code: u16,
    reason: &str,
    body: &str,
) -> std::io::Result<()> {
    status_with(stream, code, reason, "", body)
}

/// [`status`] with `extra` header lines (each ending in CRLF).
pub(crate) fn status_with(
    stream: &mut TcpStream,
    code: u16,
    reason: &str,
    extra: &str,
    body: &str,
) -> std::io::Result<()> {
    let text = format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: text/plain; charset=utf-8\r\n\
         Content-Length: {}\r\n{extra}{COMMON_HEADERS}\r\n{body}",
        body.len()
    );
    stream.write_all(text.as_bytes())?;
    stream.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heads_and_hosts() {
        let h =
            Head::parse(b"GET /ws?x=1 HTTP/1.1\r\nHost: localhost:80\r\nUpgrade: WebSocket\r\n")
                .expect("a request");
        assert_eq!((h.method.as_str(), h.path.as_str()), ("GET", "/ws"));
        assert!(h.is_upgrade());
        assert_eq!(h.header("host"), Some("localhost:80"));
        assert!(Head::parse(b"\x16\x03\x01garbage").is_none());
        assert!(Head::parse(b"GET / SPDY/3\r\n").is_none());
        for host in ["localhost:8080", "127.0.0.1:1", "[::1]:9", "127.0.0.1"] {
            assert!(is_loopback_host(host), "{host}");
        }
        for host in [
            "evil.example:8080",
            "10.0.0.1:80",
            "",
            "[fe80::1]:1",
            "[::1",
            "[::1]x",
            "localhost:",
            "localhost:80x",
        ] {
            assert!(!is_loopback_host(host), "{host}");
        }
    }
}
