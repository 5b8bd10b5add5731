//! The preview server: a thread per connection on std's TCP listener (no async runtime; a
//! preview has a handful of clients). Every request must carry the session's token; the page
//! and its scripts come from [`http::ASSETS`]; `/ws` upgrades to a WebSocket that carries the
//! state as JSON and the images as half-float frames, and takes the page's commands.

use super::http::{self, Request};
use super::state::{encode_frame, hello_json, status_json, Config, Mode, Session, SlotState};
use super::websocket::{self, Incoming, ReadError};
use anyhow::{Context, Result};
use std::io::Write;
use std::net::{IpAddr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Most connections served at once (the rest are dropped at accept).
const MAX_CONNECTIONS: usize = 64;
/// Shortest time between two updates to one page: at most 5 updates a second.
pub const MIN_UPDATE_INTERVAL: Duration = Duration::from_millis(200);
/// How long a request head or a write may take before the connection is dropped.
const IO_TIMEOUT: Duration = Duration::from_secs(10);

pub struct Server {
    pub addr: SocketAddr,
    pub token: String,
    open: Arc<AtomicUsize>,
}

impl Server {
    /// The address to open, token included.
    pub fn url(&self) -> String {
        format!("http://{}/?token={}", self.addr, self.token)
    }

    /// Wait (at most `grace`) for the pages to receive the last state after a shutdown.
    pub fn drain(&self, grace: Duration) {
        let t = Instant::now();
        while self.open.load(Ordering::SeqCst) > 0 && t.elapsed() < grace {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Listen on `bind:port` (port 0: any free one) and serve `session` from background threads.
pub fn start(bind: IpAddr, port: u16, session: Arc<Session>) -> Result<Server> {
    let listener = TcpListener::bind((bind, port)).with_context(|| format!("cannot listen on {bind}:{port}"))?;
    let addr = listener.local_addr()?;
    let token = http::new_token();
    let open = Arc::new(AtomicUsize::new(0));
    let (t, o) = (token.clone(), open.clone());
    std::thread::Builder::new().name("preview-accept".into()).spawn(move || accept_loop(listener, t, session, o))?;
    Ok(Server { addr, token, open })
}

fn accept_loop(listener: TcpListener, token: String, session: Arc<Session>, open: Arc<AtomicUsize>) {
    let active = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        if active.load(Ordering::SeqCst) >= MAX_CONNECTIONS {
            continue; // dropped: closes the socket
        }
        active.fetch_add(1, Ordering::SeqCst);
        let (token, session, active, open) = (token.clone(), session.clone(), active.clone(), open.clone());
        let spawned = std::thread::Builder::new().name("preview-conn".into()).spawn(move || {
            handle(stream, &token, &session, &open);
            active.fetch_sub(1, Ordering::SeqCst);
        });
        if spawned.is_err() {
            eprintln!("warning: preview: cannot start a connection thread");
        }
    }
}

fn handle(mut stream: TcpStream, token: &str, session: &Arc<Session>, open: &Arc<AtomicUsize>) {
    let _ = stream.set_read_timeout(Some(IO_TIMEOUT));
    let _ = stream.set_write_timeout(Some(IO_TIMEOUT));
    let _ = stream.set_nodelay(true);
    let req = match http::read_request(&mut stream) {
        Ok(Some(r)) => r,
        Ok(None) => {
            let _ = http::respond(&mut stream, "400 Bad Request", "text/plain", b"bad request\n");
            return;
        }
        Err(_) => return,
    };
    if !req.query_param("token").is_some_and(|t| http::same_token(t, token)) {
        let _ = http::respond(&mut stream, "403 Forbidden", "text/plain", b"forbidden: open the address with its token, as printed\n");
        return;
    }
    if req.method != "GET" {
        let _ = http::respond(&mut stream, "405 Method Not Allowed", "text/plain", b"only GET\n");
        return;
    }
    if req.path == "/ws" {
        open.fetch_add(1, Ordering::SeqCst);
        serve_websocket(stream, &req, session);
        open.fetch_sub(1, Ordering::SeqCst);
        return;
    }
    let _ = match http::asset(&req.path) {
        // The page names its scripts with the token (hex: nothing to escape).
        Some((ty, body)) => http::respond(&mut stream, "200 OK", ty, body.replace("__TOKEN__", token).as_bytes()),
        None => http::respond(&mut stream, "404 Not Found", "text/plain", b"not found\n"),
    };
}

/// What the reader of a page's connection tells its writer.
#[derive(Default)]
struct Connection {
    layer: AtomicUsize,
    resend: AtomicBool,
    closed: AtomicBool,
}

fn serve_websocket(mut stream: TcpStream, req: &Request, session: &Arc<Session>) {
    let key = req.header("sec-websocket-key");
    if !req.is_upgrade() || req.header("sec-websocket-version") != Some("13") || key.is_none() {
        let _ = http::respond(&mut stream, "400 Bad Request", "text/plain", b"expected a WebSocket (version 13) upgrade\n");
        return;
    }
    let accept = websocket::accept_key(key.unwrap_or(""));
    let head = format!("HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: {accept}\r\n\r\n");
    if stream.write_all(head.as_bytes()).is_err() {
        return;
    }
    // A page may sit idle for hours: only writes time out (a dead peer fails the writer,
    // which shuts the socket and so ends this read).
    let _ = stream.set_read_timeout(None);
    let Ok(out) = stream.try_clone() else { return };
    let out = Arc::new(Mutex::new(out));
    let conn = Arc::new(Connection::default());
    let writer = {
        let (out, conn, session) = (out.clone(), conn.clone(), session.clone());
        std::thread::Builder::new().name("preview-ws-write".into()).spawn(move || write_loop(&out, &conn, &session))
    };
    loop {
        match websocket::read_frame(&mut stream) {
            Ok(Incoming::Text(t)) => command(&t, session, &conn),
            Ok(Incoming::Ping(p)) => {
                if send(&out, websocket::OP_PONG, &p).is_err() {
                    break;
                }
            }
            Ok(Incoming::Pong) => {}
            Ok(Incoming::Close) => {
                let _ = with_stream(&out, |s| websocket::write_close(s, 1000, ""));
                break;
            }
            Err(ReadError::Protocol(v)) => {
                let _ = with_stream(&out, |s| websocket::write_close(s, v.code, v.reason));
                break;
            }
            Err(ReadError::Closed) => break,
        }
    }
    conn.closed.store(true, Ordering::SeqCst);
    let _ = stream.shutdown(Shutdown::Both);
    session.poke();
    if let Ok(w) = writer {
        let _ = w.join();
    }
}

fn with_stream<R>(out: &Mutex<TcpStream>, f: impl FnOnce(&mut TcpStream) -> std::io::Result<R>) -> std::io::Result<R> {
    let mut s = out.lock().unwrap_or_else(|e| e.into_inner());
    f(&mut s)
}

fn send(out: &Mutex<TcpStream>, opcode: u8, payload: &[u8]) -> std::io::Result<()> {
    with_stream(out, |s| websocket::write_frame(s, opcode, payload))
}

/// A page's command: `stop`, `layer NAME`, or (serve mode) `restart methods=a,b spp=N depth=D`.
fn command(text: &str, session: &Session, conn: &Connection) {
    let mut words = text.split_whitespace();
    match words.next() {
        Some("stop") => session.stop(),
        Some("layer") => match words.next().and_then(|l| session.info.layers.iter().position(|x| x == l)) {
            Some(i) => {
                conn.layer.store(i, Ordering::SeqCst);
                conn.resend.store(true, Ordering::SeqCst);
                session.poke();
            }
            None => session.say(format!("unknown layer in '{text}' (layers: {})", session.info.layers.join(", "))),
        },
        Some("restart") if session.info.mode == Mode::Serve => {
            let current = session.lock().config.clone();
            match parse_restart(words, &current) {
                Ok(c) => session.restart(c),
                Err(e) => session.say(e),
            }
        }
        Some("restart") => session.say("this render was started by 'svetlo render': restart it from the command line, or use 'svetlo serve'".into()),
        _ => session.say(format!("unknown command '{}'", text.chars().take(40).collect::<String>())),
    }
}

/// Most methods one comparison may hold.
const MAX_METHODS: usize = 4;

fn parse_restart<'a>(words: impl Iterator<Item = &'a str>, current: &Config) -> std::result::Result<Config, String> {
    let mut c = current.clone();
    for w in words {
        let (k, v) = w.split_once('=').ok_or_else(|| format!("expected key=value, got '{w}'"))?;
        match k {
            "methods" => {
                let m: Vec<String> = v.split(',').filter(|s| !s.is_empty()).map(str::to_string).collect();
                if m.is_empty() || m.len() > MAX_METHODS {
                    return Err(format!("between 1 and {MAX_METHODS} methods, got {}", m.len()));
                }
                for name in &m {
                    svetlo::methods::by_name(name).map_err(|e| e.to_string())?;
                }
                c.methods = m;
            }
            "spp" => c.spp = v.parse().ok().filter(|n| (1..=1 << 24).contains(n)).ok_or_else(|| format!("spp must be 1..16777216, got '{v}'"))?,
            "depth" => c.max_depth = v.parse().ok().filter(|d| (-1..=1024).contains(d)).ok_or_else(|| format!("depth must be -1..1024, got '{v}'"))?,
            _ => return Err(format!("unknown setting '{k}'")),
        }
    }
    Ok(c)
}

/// Send the hello, then the newest status and frames whenever they change, at a bounded rate.
fn write_loop(out: &Mutex<TcpStream>, conn: &Connection, session: &Session) {
    if send(out, websocket::OP_TEXT, hello_json(&session.info).as_bytes()).is_err() {
        return;
    }
    let mut seen = 0u64;
    // Per slot: (run, frame version, layer) last sent.
    let mut sent: Vec<(u64, u64, usize)> = Vec::new();
    let mut last = Instant::now().checked_sub(MIN_UPDATE_INTERVAL).unwrap_or_else(Instant::now);
    loop {
        let resend = conn.resend.load(Ordering::SeqCst);
        if !resend {
            drop(session.wait_change(seen, Duration::from_millis(500)));
        }
        if conn.closed.load(Ordering::SeqCst) {
            return;
        }
        let wait = MIN_UPDATE_INTERVAL.saturating_sub(last.elapsed());
        if !wait.is_zero() {
            std::thread::sleep(wait);
        }
        if resend {
            conn.resend.store(false, Ordering::SeqCst);
            sent.clear();
        }
        let layer = conn.layer.load(Ordering::SeqCst);
        let (status, frames, version, shutdown, run) = {
            let s = session.lock();
            // Unchanged: still send the status while a render runs (its progress and ETA move).
            let running = s.slots.iter().any(|sl| sl.state == SlotState::Running);
            if s.version == seen && !resend && !running {
                continue;
            }
            sent.resize(s.slots.len(), (0, 0, usize::MAX));
            let frames: Vec<_> = s
                .slots
                .iter()
                .enumerate()
                .filter_map(|(i, sl)| {
                    let f = sl.frame.clone()?;
                    let key = (s.run, sl.frame_version, layer);
                    (sent[i] != key).then(|| {
                        sent[i] = key;
                        (i, f)
                    })
                })
                .collect();
            (status_json(&s), frames, s.version, s.shutdown, s.run)
        };
        last = Instant::now();
        seen = version;
        // Frames first, so that a status that says "done" finds its image already there.
        for (i, f) in frames {
            if send(out, websocket::OP_BINARY, &encode_frame(&f, i, layer, run)).is_err() {
                return;
            }
        }
        if send(out, websocket::OP_TEXT, status.as_bytes()).is_err() {
            return;
        }
        if shutdown {
            let _ = with_stream(out, |s| websocket::write_close(s, 1001, "the render has ended"));
            if let Ok(s) = out.lock() {
                let _ = s.shutdown(Shutdown::Write);
            }
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restart_commands_are_checked() {
        let c = Config { methods: vec!["path".into()], spp: 16, max_depth: -1 };
        let p = |s: &str| parse_restart(s.split_whitespace(), &c);
        assert_eq!(p("methods=path,bdpt spp=8 depth=5").unwrap(), Config { methods: vec!["path".into(), "bdpt".into()], spp: 8, max_depth: 5 });
        assert_eq!(p("").unwrap(), c);
        assert!(p("methods=nope").unwrap_err().contains("unknown integrator"));
        assert!(p("methods=").is_err());
        assert!(p("methods=a,b,c,d,e").is_err());
        assert!(p("spp=0").is_err() && p("spp=x").is_err() && p("depth=-2").is_err());
        assert!(p("colour=red").is_err() && p("spp").is_err());
    }
}
