//! The preview server of `svetlo serve`, from outside, as an attacker or a careless client
//! would use it: the token, loopback-only listening, paths outside the page, broken
//! WebSocket frames, and two pages at once while the render goes on.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(60);

/// A running `svetlo serve` and the address and token it printed; killed when dropped.
struct Served {
    child: Child,
    addr: SocketAddr,
    token: String,
    _dir: PathBuf,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn serve(name: &str, extra: &[&str]) -> Served {
    let dir = std::env::temp_dir().join(format!("svetlo-preview-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    let out = dir.join("s.exr");
    let mut args =
        vec!["serve", scene.to_str().unwrap(), "--width", "32", "--height", "32", "--spp", "100000", "--max-depth", "4", "-o", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let mut child = Command::new(env!("CARGO_BIN_EXE_svetlo")).args(&args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().expect("svetlo runs");
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    let url = loop {
        line.clear();
        if err.read_line(&mut line).unwrap_or(0) == 0 {
            break None;
        }
        if let Some(url) = line.trim().strip_prefix("preview: http://") {
            break Some(url.to_string());
        }
    };
    // From here the child is killed and reaped when `Served` drops, on every path.
    let mut served = Served { child, addr: "127.0.0.1:1".parse().unwrap(), token: String::new(), _dir: dir };
    let url = url.expect("svetlo serve exited without printing its address");
    let (addr, token) = url.split_once("/?token=").expect("address with token");
    (served.addr, served.token) = (addr.parse().unwrap(), token.to_string());
    // Keep draining stderr so that the server never blocks on a full pipe.
    std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()));
    served
}

fn connect(addr: SocketAddr) -> TcpStream {
    let s = TcpStream::connect(addr).expect("connects");
    s.set_read_timeout(Some(TIMEOUT)).unwrap();
    s
}

/// Status code and body of a raw request target (sent byte for byte, not normalised).
fn get(addr: SocketAddr, target: &str) -> (u16, String) {
    let mut s = connect(addr);
    // The server may answer (400) and close before an oversized request is all sent.
    let _ = write!(s, "GET {target} HTTP/1.1\r\nHost: {addr}\r\n\r\n");
    let mut bytes = Vec::new();
    let _ = s.read_to_end(&mut bytes);
    let resp = String::from_utf8_lossy(&bytes);
    let code = resp.get(9..12).and_then(|c| c.parse().ok()).unwrap_or(0);
    (code, resp.split_once("\r\n\r\n").map(|(_, b)| b.to_string()).unwrap_or_default())
}

#[test]
fn token_is_required_on_every_request() {
    let s = serve("token", &[]);
    let t = &s.token;
    assert_eq!(get(s.addr, &format!("/?token={t}")).0, 200);
    assert!(get(s.addr, &format!("/app.js?token={t}")).1.contains("WebSocket"));
    for target in ["/", "/app.js", "/style.css", "/ws", "/?token=", "/?token=00000000000000000000000000000000", "/?tok=x"] {
        let (code, body) = get(s.addr, target);
        assert_eq!(code, 403, "{target}");
        assert!(!body.contains("<html"), "{target}");
    }
    // A token differing in its last character, or with extra characters, is refused too.
    let mut wrong = t.clone();
    let last = if wrong.ends_with('0') { '1' } else { '0' };
    wrong.pop();
    wrong.push(last);
    assert_eq!(get(s.addr, &format!("/?token={wrong}")).0, 403);
    assert_eq!(get(s.addr, &format!("/?token={t}0")).0, 403);
    // The WebSocket needs the token as well.
    assert_eq!(get(s.addr, "/ws?token=nope").0, 403);
    // Other methods and malformed requests.
    let mut c = connect(s.addr);
    write!(c, "POST /?token={t} HTTP/1.1\r\n\r\n").unwrap();
    let mut r = String::new();
    c.read_to_string(&mut r).unwrap();
    assert!(r.starts_with("HTTP/1.1 405"), "{r}");
    let mut c = connect(s.addr);
    c.write_all(b"garbage\r\n\r\n").unwrap();
    let mut r = String::new();
    c.read_to_string(&mut r).unwrap();
    assert!(r.starts_with("HTTP/1.1 400"), "{r}");
}

#[test]
fn no_path_outside_the_page_can_be_read() {
    let s = serve("traversal", &[]);
    let t = &s.token;
    let secrets = ["[workspace]", "[package]", "root:x:", "svetlo-cli", "fn main"];
    for p in [
        "/../Cargo.toml",
        "/../../Cargo.toml",
        "/%2e%2e/Cargo.toml",
        "/%2E%2E%2FCargo.toml",
        "/..%2fCargo.toml",
        "/..%5cCargo.toml",
        "/..\\Cargo.toml",
        "/%252e%252e%252fCargo.toml",
        "/./app.js/../../Cargo.toml",
        "//etc/passwd",
        "/../../../../../../etc/passwd",
        "/assets/../main.rs",
        "/src/main.rs",
        "/app.js%00.html",
        "/%c0%ae%c0%ae/Cargo.toml",
    ] {
        let (code, body) = get(s.addr, &format!("{p}?token={t}"));
        assert_eq!(code, 404, "{p}");
        assert!(secrets.iter().all(|x| !body.contains(x)), "{p} leaked: {body}");
        // Without the token: refused before the path is looked at.
        assert_eq!(get(s.addr, p).0, 403, "{p}");
    }
}

#[test]
fn listens_on_loopback_only_by_default() {
    let s = serve("loopback", &[]);
    assert!(s.addr.ip().is_loopback(), "{}", s.addr);
    // The machine's own address on its network (found without sending a packet) is not served.
    let own = std::net::UdpSocket::bind("0.0.0.0:0").and_then(|u| u.connect("192.0.2.1:9").and_then(|_| u.local_addr()));
    match own {
        Ok(a) if !a.ip().is_loopback() && !a.ip().is_unspecified() => {
            let r = TcpStream::connect_timeout(&SocketAddr::new(a.ip(), s.addr.port()), Duration::from_secs(5));
            assert!(r.is_err(), "the preview answered on {}", a.ip());
        }
        _ => eprintln!("no non-loopback address on this machine: only the bound address was checked"),
    }
}

/// A WebSocket client: the handshake by hand, frames read as the server sends them.
struct Ws(TcpStream);

impl Ws {
    fn open(s: &Served) -> Ws {
        let mut c = connect(s.addr);
        write!(
            c,
            "GET /ws?token={} HTTP/1.1\r\nHost: {}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
            s.token, s.addr
        )
        .unwrap();
        let mut head = Vec::new();
        let mut b = [0u8];
        while !head.ends_with(b"\r\n\r\n") {
            c.read_exact(&mut b).unwrap();
            head.push(b[0]);
        }
        let head = String::from_utf8(head).unwrap();
        assert!(head.starts_with("HTTP/1.1 101"), "{head}");
        assert!(head.contains("Sec-WebSocket-Accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo="), "{head}");
        Ws(c)
    }

    /// (opcode, payload) of the next frame; `None` when the server closed the socket.
    fn next(&mut self) -> Option<(u8, Vec<u8>)> {
        let mut h = [0u8; 2];
        self.0.read_exact(&mut h).ok()?;
        let len = match h[1] & 0x7f {
            126 => {
                let mut b = [0u8; 2];
                self.0.read_exact(&mut b).ok()?;
                u16::from_be_bytes(b) as usize
            }
            127 => {
                let mut b = [0u8; 8];
                self.0.read_exact(&mut b).ok()?;
                u64::from_be_bytes(b) as usize
            }
            n => n as usize,
        };
        assert_eq!(h[1] & 0x80, 0, "server frames are not masked");
        let mut p = vec![0u8; len];
        self.0.read_exact(&mut p).ok()?;
        Some((h[0] & 0x0f, p))
    }

    /// The spp of the next image frame (skipping text), within the timeout.
    fn next_image_spp(&mut self) -> u32 {
        let t = Instant::now();
        while t.elapsed() < TIMEOUT {
            let (op, p) = self.next().expect("the connection stays open");
            if op == 2 {
                assert_eq!(&p[..4], b"SVF1");
                let (w, h) = (u32::from_le_bytes(p[8..12].try_into().unwrap()), u32::from_le_bytes(p[12..16].try_into().unwrap()));
                assert_eq!((w, h), (32, 32));
                assert_eq!(p.len(), 24 + 32 * 32 * 6, "half-float RGB");
                return u32::from_le_bytes(p[16..20].try_into().unwrap());
            }
        }
        panic!("no image within the timeout");
    }

    /// Read until the server's close frame; its status code.
    fn close_code(&mut self) -> u16 {
        while let Some((op, p)) = self.next() {
            if op == 8 {
                return u16::from_be_bytes([p[0], p[1]]);
            }
        }
        panic!("closed without a close frame");
    }
}

fn masked(first: u8, payload: &[u8]) -> Vec<u8> {
    let mask = [1u8, 2, 3, 4];
    let mut f = vec![first, 0x80 | payload.len() as u8];
    f.extend_from_slice(&mask);
    f.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
    f
}

#[test]
fn bad_frames_close_only_their_connection_and_two_pages_watch() {
    let s = serve("frames", &[]);
    let mut a = Ws::open(&s);
    let mut b = Ws::open(&s);
    let (op, hello) = a.next().unwrap();
    assert_eq!(op, 1);
    assert!(String::from_utf8(hello).unwrap().contains("\"type\":\"hello\""));
    let (sa, sb) = (a.next_image_spp(), b.next_image_spp());
    assert!(sa > 0 && sb > 0, "both pages get images");

    // Each bad client gets a close frame with the right code, then the socket ends.
    let mut huge = vec![0x81, 0x80 | 127];
    huge.extend_from_slice(&(1u64 << 40).to_be_bytes());
    let cases: Vec<(Vec<u8>, u16)> = vec![
        (vec![0x81, 0x03, b'a', b'b', b'c'], 1002),    // unmasked
        (huge, 1009),                                  // 1 TiB announced
        (masked(0x81, &[0xc3, 0x28]), 1007),           // not UTF-8
        (masked(0x01, b"frag"), 1003),                 // fragment
        (masked(0x82, b"bin"), 1003),                  // binary
        (masked(0xC1, b"rsv"), 1002),                  // reserved bit
        (masked(0x8F, b""), 1002),                     // unknown opcode
        (masked(0x89, &[0u8; 125])[..20].to_vec(), 0), // truncated, then dropped
    ];
    for (bytes, code) in cases {
        let mut bad = Ws::open(&s);
        bad.0.write_all(&bytes).unwrap();
        if code == 0 {
            drop(bad); // gone mid-frame
        } else {
            assert_eq!(bad.close_code(), code, "frame {:02x?}", &bytes[..2]);
            assert!(bad.next().is_none(), "closed after the close frame");
        }
    }
    // An oversized head and garbage on a fresh connection are refused as well.
    let (code, _) = get(s.addr, &format!("/?token={}&{}", s.token, "x".repeat(20_000)));
    assert!(code == 400 || code == 0, "oversized head: {code}");

    // The render and the good pages go on: newer images still arrive on both.
    let (sa2, sb2) = (a.next_image_spp(), b.next_image_spp());
    let (sa3, sb3) = (a.next_image_spp(), b.next_image_spp());
    assert!(sa3 > sa && sb3 > sb && sa2 <= sa3 && sb2 <= sb3, "the render went on: {sa} -> {sa3}, {sb} -> {sb3}");
    // A well-formed command from a page is taken (an unknown one is reported, not fatal).
    a.0.write_all(&masked(0x81, b"layer variance")).unwrap();
    a.0.write_all(&masked(0x89, b"ping")).unwrap();
    let t = Instant::now();
    let mut pong = false;
    while !pong && t.elapsed() < TIMEOUT {
        pong = a.next().expect("open").0 == 0xA;
    }
    assert!(pong, "ping answered");
    assert!(a.next_image_spp() > 0);
    // Closing politely gets a close back.
    a.0.write_all(&masked(0x88, &[3, 232])).unwrap();
    assert_eq!(a.close_code(), 1000);
}

/// With `--aov`, the page is offered the AOV layers after color and variance, and `layer NAME`
/// switches that page's frames to the named layer (the frame header carries its index).
#[test]
fn aov_layers_are_offered_and_selectable() {
    let s = serve("aov", &["--integrator", "path", "--aov", "direct=C <R.> L", "--aov-preset", "lecture"]);
    let mut a = Ws::open(&s);
    let (op, hello) = a.next().unwrap();
    assert_eq!(op, 1);
    let hello = String::from_utf8(hello).unwrap();
    assert!(hello.contains("\"layers\":[\"color\",\"variance\",\"direct\",\"local\",\"whitted\",\"cook\",\"radiosity\",\"rest\"]"), "{hello}");
    a.next_image_spp();
    a.0.write_all(&masked(0x81, b"layer cook")).unwrap();
    // The next frames come from layer 5 (cook); an unknown name is reported with the list.
    let t = Instant::now();
    let mut layer = None;
    while layer != Some(5) && t.elapsed() < TIMEOUT {
        let (op, p) = a.next().expect("open");
        if op == 2 {
            layer = Some(p[5]);
        }
    }
    assert_eq!(layer, Some(5), "frames of the chosen AOV");
    a.0.write_all(&masked(0x81, b"layer nope")).unwrap();
    let t = Instant::now();
    let mut said = String::new();
    while !said.contains("unknown layer") && t.elapsed() < TIMEOUT {
        let (op, p) = a.next().expect("open");
        if op == 1 {
            said = String::from_utf8(p).unwrap();
        }
    }
    assert!(said.contains("unknown layer") && said.contains("radiosity"), "{said}");
}

/// `svetlo render --tev`: a fake tev gets the image created once (32x32, R G B), then
/// updates that stay inside it; the render ends normally and tev's socket is closed.
#[test]
fn render_streams_to_a_fake_tev() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let fake = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.set_read_timeout(Some(TIMEOUT)).unwrap();
        let mut all = Vec::new();
        s.read_to_end(&mut all).unwrap();
        all
    });
    let dir = std::env::temp_dir().join(format!("svetlo-preview-{}-tev", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    let o = Command::new(env!("CARGO_BIN_EXE_svetlo"))
        .args(["render", scene.to_str().unwrap(), "--width", "32", "--height", "32", "--spp", "8", "--max-depth", "3"])
        .args(["-o", dir.join("t.exr").to_str().unwrap(), "--tev", &format!("127.0.0.1:{port}")])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let data = fake.join().unwrap();
    let (mut at, mut kinds) = (0usize, Vec::new());
    while at < data.len() {
        let len = u32::from_le_bytes(data[at..at + 4].try_into().unwrap()) as usize;
        assert!(len >= 5 && at + len <= data.len(), "packet length {len} at {at}");
        let body = &data[at + 5..at + len];
        let name_end = 1 + body[1..].iter().position(|&b| b == 0).unwrap();
        assert_eq!(&body[1..name_end], b"svetlo cornell-box path");
        let ints = |i: usize| i32::from_le_bytes(body[name_end + 1 + 4 * i..name_end + 5 + 4 * i].try_into().unwrap());
        match data[at + 4] {
            4 => assert_eq!((ints(0), ints(1), ints(2)), (32, 32, 3), "CreateImage 32x32 RGB"),
            6 => {
                // After the count and "R\0G\0B\0": x, y, w, h, then offsets and strides.
                let rect = &body[name_end + 1 + 4 + 6..];
                let r: Vec<i32> = (0..4).map(|i| i32::from_le_bytes(rect[4 * i..4 * i + 4].try_into().unwrap())).collect();
                assert_eq!(r, [0, 0, 32, 32], "one tile covers the 32x32 image");
                assert_eq!(rect.len(), 16 + 48 + 32 * 32 * 12, "header and the tile's floats");
            }
            k => panic!("packet type {k}"),
        }
        kinds.push(data[at + 4]);
        at += len;
    }
    assert_eq!(kinds.first(), Some(&4), "created first");
    assert_eq!(kinds.iter().filter(|&&k| k == 4).count(), 1, "created once");
    assert!(kinds.iter().filter(|&&k| k == 6).count() >= 1, "{kinds:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
