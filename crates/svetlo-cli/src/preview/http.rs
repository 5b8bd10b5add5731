//! The preview's HTTP side: read one request head with hard limits, check the token, and
//! answer from a fixed table of assets compiled into the binary. Paths are looked up as
//! exact strings and never touch the file system, so no spelling of `..` can reach a file.

use std::io::{self, Read, Write};

/// Longest request head accepted (request line and headers).
pub const MAX_HEAD: usize = 16 * 1024;

/// The page, compiled in: it works offline and cannot be changed on disk under a running server.
pub const ASSETS: &[(&str, &str, &str)] = &[
    ("/", "text/html; charset=utf-8", include_str!("assets/index.html")),
    ("/index.html", "text/html; charset=utf-8", include_str!("assets/index.html")),
    ("/app.js", "text/javascript; charset=utf-8", include_str!("assets/app.js")),
    ("/style.css", "text/css; charset=utf-8", include_str!("assets/style.css")),
];

/// The parts of a request the server looks at.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Request {
    pub method: String,
    /// The path before `?`, exactly as sent (not decoded).
    pub path: String,
    pub query: String,
    /// Header names in lower case.
    pub headers: Vec<(String, String)>,
}

impl Request {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }

    /// The value of `key` in the query string (tokens are URL-safe: no decoding needed).
    pub fn query_param(&self, key: &str) -> Option<&str> {
        self.query.split('&').find_map(|kv| kv.split_once('=').filter(|(k, _)| *k == key).map(|(_, v)| v))
    }

    /// Whether this asks to become a WebSocket.
    pub fn is_upgrade(&self) -> bool {
        self.header("upgrade").is_some_and(|v| v.eq_ignore_ascii_case("websocket"))
    }
}

/// Read and parse a request head; `Ok(None)` when the request is malformed or too long.
pub fn read_request(r: &mut impl Read) -> io::Result<Option<Request>> {
    let mut buf = Vec::with_capacity(1024);
    let mut byte = [0u8; 1];
    // Byte by byte: the head is small, and nothing past it (a WebSocket frame) is consumed.
    while !buf.ends_with(b"\r\n\r\n") {
        if buf.len() >= MAX_HEAD {
            return Ok(None);
        }
        if r.read(&mut byte)? == 0 {
            return Ok(None);
        }
        buf.push(byte[0]);
    }
    let Ok(text) = std::str::from_utf8(&buf) else { return Ok(None) };
    let mut lines = text.split("\r\n");
    let mut first = lines.next().unwrap_or("").split(' ');
    let (Some(method), Some(target), Some(version)) = (first.next(), first.next(), first.next()) else { return Ok(None) };
    if !version.starts_with("HTTP/1.") || first.next().is_some() {
        return Ok(None);
    }
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let mut headers = Vec::new();
    for line in lines.filter(|l| !l.is_empty()) {
        let Some((n, v)) = line.split_once(':') else { return Ok(None) };
        headers.push((n.trim().to_ascii_lowercase(), v.trim().to_string()));
    }
    Ok(Some(Request { method: method.to_string(), path: path.to_string(), query: query.to_string(), headers }))
}

/// Comparison whose time does not depend on where the strings differ.
pub fn same_token(given: &str, token: &str) -> bool {
    let (a, b) = (given.as_bytes(), token.as_bytes());
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Write a whole response and close (one request per connection).
pub fn respond(w: &mut impl Write, status: &str, content_type: &str, body: &[u8]) -> io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         X-Content-Type-Options: nosniff\r\nReferrer-Policy: no-referrer\r\n\
         Content-Security-Policy: default-src 'self'; connect-src 'self' ws: wss:; img-src 'self' data: blob:\r\nConnection: close\r\n\r\n",
        body.len()
    );
    w.write_all(head.as_bytes())?;
    w.write_all(body)?;
    w.flush()
}

/// The asset at exactly `path`.
pub fn asset(path: &str) -> Option<(&'static str, &'static str)> {
    ASSETS.iter().find(|(p, _, _)| *p == path).map(|(_, t, b)| (*t, *b))
}

/// A random token: 128 bits from the operating system's generator.
pub fn new_token() -> String {
    let mut bytes = [0u8; 16];
    let from_os = std::fs::File::open("/dev/urandom").and_then(|mut f| f.read_exact(&mut bytes)).is_ok();
    if !from_os {
        // No /dev/urandom (Windows): std's hasher keys are seeded from the OS generator.
        use std::hash::{BuildHasher, Hasher};
        for half in bytes.chunks_mut(8) {
            let mut h = std::collections::hash_map::RandomState::new().build_hasher();
            h.write_u128(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos()).unwrap_or(0));
            half.copy_from_slice(&h.finish().to_le_bytes());
        }
    }
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Option<Request> {
        read_request(&mut std::io::Cursor::new(s.as_bytes().to_vec())).unwrap()
    }

    #[test]
    fn requests_parse_and_limits_hold() {
        let r = parse("GET /app.js?token=ab&x=1 HTTP/1.1\r\nHost: a\r\nUpgrade: WebSocket\r\n\r\n").unwrap();
        assert_eq!((r.method.as_str(), r.path.as_str()), ("GET", "/app.js"));
        assert_eq!(r.query_param("token"), Some("ab"));
        assert_eq!(r.query_param("y"), None);
        assert!(r.is_upgrade());
        assert!(parse("GET / HTTP/1.1\r\n").is_none(), "unterminated head");
        assert!(parse("GET /\r\n\r\n").is_none(), "no version");
        assert!(parse("GET / HTTP/1.1\r\nbad header\r\n\r\n").is_none());
        let long = format!("GET / HTTP/1.1\r\nX: {}\r\n\r\n", "a".repeat(MAX_HEAD));
        assert!(parse(&long).is_none(), "oversized head");
    }

    #[test]
    fn tokens_are_random_and_compared_whole() {
        let (a, b) = (new_token(), new_token());
        assert_eq!(a.len(), 32);
        assert_ne!(a, b);
        assert!(same_token(&a, &a.clone()));
        assert!(!same_token(&a[..31], &a));
        assert!(!same_token(&b, &a));
        assert!(!same_token("", &a));
    }

    #[test]
    fn only_listed_assets_exist() {
        assert!(asset("/").is_some() && asset("/app.js").is_some());
        for p in ["/../Cargo.toml", "/%2e%2e/Cargo.toml", "/assets/app.js", "/app.js/", "//app.js", "/APP.JS", "/style.css%00"] {
            assert!(asset(p).is_none(), "{p}");
        }
    }
}
