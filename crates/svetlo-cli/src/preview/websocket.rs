//! The WebSocket protocol (RFC 6455), as much as the preview needs: the opening handshake's
//! accept key, reading the page's short masked text frames with hard limits, and writing
//! unmasked text and binary frames. A frame that breaks the rules or the limits ends that
//! connection only (the caller closes it); nothing here can panic on what a client sends.

use std::io::{self, Read, Write};

/// The GUID every WebSocket server appends to the client's key (RFC 6455, 1.3).
const GUID: &str = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";

/// Longest message the page may send: its commands are a few dozen bytes.
pub const MAX_CLIENT_PAYLOAD: u64 = 4096;

/// `Sec-WebSocket-Accept` for a client's `Sec-WebSocket-Key`.
pub fn accept_key(key: &str) -> String {
    let mut s = key.trim().as_bytes().to_vec();
    s.extend_from_slice(GUID.as_bytes());
    base64(&sha1(&s))
}

/// What the page sent, after the protocol's bookkeeping.
#[derive(Debug, PartialEq, Eq)]
pub enum Incoming {
    Text(String),
    Ping(Vec<u8>),
    Pong,
    Close,
}

/// Why a connection must end: the status code to close it with (RFC 6455, 7.4.1) and a reason.
#[derive(Debug, PartialEq, Eq)]
pub struct Violation {
    pub code: u16,
    pub reason: &'static str,
}

/// Reading stopped: the peer went away (or a socket error), or it broke the protocol.
#[derive(Debug)]
pub enum ReadError {
    Closed,
    Protocol(Violation),
}

impl From<io::Error> for ReadError {
    fn from(_: io::Error) -> Self {
        ReadError::Closed
    }
}

fn violation(code: u16, reason: &'static str) -> ReadError {
    ReadError::Protocol(Violation { code, reason })
}

/// Read one frame from the client. Fragmented messages, unmasked frames, reserved bits,
/// unknown opcodes, binary data, payloads over [`MAX_CLIENT_PAYLOAD`] and text that is not
/// UTF-8 are violations; the payload is never allocated before its length is checked.
pub fn read_frame(r: &mut impl Read) -> Result<Incoming, ReadError> {
    let mut head = [0u8; 2];
    r.read_exact(&mut head)?;
    let (fin, rsv, opcode) = (head[0] & 0x80 != 0, head[0] & 0x70, head[0] & 0x0f);
    let masked = head[1] & 0x80 != 0;
    if rsv != 0 {
        return Err(violation(1002, "reserved bits set"));
    }
    if !masked {
        return Err(violation(1002, "client frames must be masked"));
    }
    let len = match head[1] & 0x7f {
        126 => {
            let mut b = [0u8; 2];
            r.read_exact(&mut b)?;
            u16::from_be_bytes(b) as u64
        }
        127 => {
            let mut b = [0u8; 8];
            r.read_exact(&mut b)?;
            u64::from_be_bytes(b)
        }
        n => n as u64,
    };
    let control = opcode & 0x8 != 0;
    if control && (len > 125 || !fin) {
        return Err(violation(1002, "control frames are short and unfragmented"));
    }
    if len > MAX_CLIENT_PAYLOAD {
        return Err(violation(1009, "message too big"));
    }
    let mut mask = [0u8; 4];
    r.read_exact(&mut mask)?;
    let mut payload = vec![0u8; len as usize];
    r.read_exact(&mut payload)?;
    for (i, b) in payload.iter_mut().enumerate() {
        *b ^= mask[i % 4];
    }
    match opcode {
        0x1 if fin => String::from_utf8(payload).map(Incoming::Text).map_err(|_| violation(1007, "text is not UTF-8")),
        0x0..=0x2 => Err(violation(1003, "fragmented and binary messages are not accepted")),
        0x8 => Ok(Incoming::Close),
        0x9 => Ok(Incoming::Ping(payload)),
        0xA => Ok(Incoming::Pong),
        _ => Err(violation(1002, "unknown opcode")),
    }
}

pub const OP_TEXT: u8 = 0x1;
pub const OP_BINARY: u8 = 0x2;
pub const OP_CLOSE: u8 = 0x8;
pub const OP_PONG: u8 = 0xA;

/// Write one unmasked, unfragmented frame (what a server sends).
pub fn write_frame(w: &mut impl Write, opcode: u8, payload: &[u8]) -> io::Result<()> {
    let mut head = Vec::with_capacity(10);
    head.push(0x80 | opcode);
    let n = payload.len();
    if n < 126 {
        head.push(n as u8);
    } else if n <= u16::MAX as usize {
        head.push(126);
        head.extend_from_slice(&(n as u16).to_be_bytes());
    } else {
        head.push(127);
        head.extend_from_slice(&(n as u64).to_be_bytes());
    }
    w.write_all(&head)?;
    w.write_all(payload)?;
    w.flush()
}

/// A close frame with a status code and reason.
pub fn write_close(w: &mut impl Write, code: u16, reason: &str) -> io::Result<()> {
    let mut p = code.to_be_bytes().to_vec();
    p.extend_from_slice(&reason.as_bytes()[..reason.len().min(120)]);
    write_frame(w, OP_CLOSE, &p)
}

/// SHA-1 (FIPS 180-4); the handshake needs it and nothing else does, so it lives here.
pub fn sha1(data: &[u8]) -> [u8; 20] {
    let mut h: [u32; 5] = [0x67452301, 0xEFCDAB89, 0x98BADCFE, 0x10325476, 0xC3D2E1F0];
    let mut msg = data.to_vec();
    let bits = (data.len() as u64).wrapping_mul(8);
    msg.push(0x80);
    while msg.len() % 64 != 56 {
        msg.push(0);
    }
    msg.extend_from_slice(&bits.to_be_bytes());
    for block in msg.chunks_exact(64) {
        let mut w = [0u32; 80];
        for (i, c) in block.chunks_exact(4).enumerate() {
            w[i] = u32::from_be_bytes([c[0], c[1], c[2], c[3]]);
        }
        for i in 16..80 {
            w[i] = (w[i - 3] ^ w[i - 8] ^ w[i - 14] ^ w[i - 16]).rotate_left(1);
        }
        let [mut a, mut b, mut c, mut d, mut e] = h;
        for (i, wi) in w.iter().enumerate() {
            let (f, k) = match i {
                0..=19 => ((b & c) | (!b & d), 0x5A827999),
                20..=39 => (b ^ c ^ d, 0x6ED9EBA1),
                40..=59 => ((b & c) | (b & d) | (c & d), 0x8F1BBCDC),
                _ => (b ^ c ^ d, 0xCA62C1D6),
            };
            let t = a.rotate_left(5).wrapping_add(f).wrapping_add(e).wrapping_add(k).wrapping_add(*wi);
            e = d;
            d = c;
            c = b.rotate_left(30);
            b = a;
            a = t;
        }
        for (x, y) in h.iter_mut().zip([a, b, c, d, e]) {
            *x = x.wrapping_add(y);
        }
    }
    let mut out = [0u8; 20];
    for (i, x) in h.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&x.to_be_bytes());
    }
    out
}

/// Standard base64 with padding.
pub fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for i in 0..4 {
            if i <= c.len() {
                s.push(A[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(b: &[u8]) -> String {
        b.iter().map(|x| format!("{x:02x}")).collect()
    }

    #[test]
    fn sha1_and_base64_match_known_values() {
        assert_eq!(hex(&sha1(b"")), "da39a3ee5e6b4b0d3255bfef95601890afd80709");
        assert_eq!(hex(&sha1(b"abc")), "a9993e364706816aba3e25717850c26c9cd0d89d");
        let long = b"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
        assert_eq!(hex(&sha1(long)), "84983e441c3bd26ebaae4aa1f95129e5e54670f1");
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
        // RFC 6455, section 1.3.
        assert_eq!(accept_key("dGhlIHNhbXBsZSBub25jZQ=="), "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=");
    }

    /// A client frame as a browser sends it.
    pub fn client_frame(opcode: u8, fin: bool, payload: &[u8]) -> Vec<u8> {
        let mask = [0x12, 0x34, 0x56, 0x78];
        let mut f = vec![if fin { 0x80 } else { 0 } | opcode];
        let n = payload.len();
        if n < 126 {
            f.push(0x80 | n as u8);
        } else if n <= 65535 {
            f.push(0x80 | 126);
            f.extend_from_slice(&(n as u16).to_be_bytes());
        } else {
            f.push(0x80 | 127);
            f.extend_from_slice(&(n as u64).to_be_bytes());
        }
        f.extend_from_slice(&mask);
        f.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        f
    }

    fn read(bytes: &[u8]) -> Result<Incoming, ReadError> {
        read_frame(&mut std::io::Cursor::new(bytes.to_vec()))
    }

    fn code(r: Result<Incoming, ReadError>) -> u16 {
        match r {
            Err(ReadError::Protocol(v)) => v.code,
            other => panic!("expected a violation, got {other:?}"),
        }
    }

    #[test]
    fn frames_are_read_within_limits() {
        assert_eq!(read(&client_frame(1, true, b"stop")).unwrap(), Incoming::Text("stop".into()));
        let long = "x".repeat(300);
        assert_eq!(read(&client_frame(1, true, long.as_bytes())).unwrap(), Incoming::Text(long));
        assert_eq!(read(&client_frame(9, true, b"hi")).unwrap(), Incoming::Ping(b"hi".to_vec()));
        assert_eq!(read(&client_frame(8, true, &[3, 232])).unwrap(), Incoming::Close);
        // Oversized: refused from the header alone (a 2^62-byte claim allocates nothing).
        let mut huge = vec![0x81, 0x80 | 127];
        huge.extend_from_slice(&(1u64 << 62).to_be_bytes());
        assert_eq!(code(read(&huge)), 1009);
        assert_eq!(code(read(&client_frame(1, true, &vec![b'a'; 5000]))), 1009);
        // Unmasked, reserved bits, fragments, binary, bad UTF-8, unknown opcode, long ping.
        assert_eq!(code(read(&[0x81, 0x02, b'h', b'i'])), 1002);
        let mut rsv = client_frame(1, true, b"x");
        rsv[0] |= 0x40;
        assert_eq!(code(read(&rsv)), 1002);
        assert_eq!(code(read(&client_frame(1, false, b"par"))), 1003);
        assert_eq!(code(read(&client_frame(0, true, b"t"))), 1003);
        assert_eq!(code(read(&client_frame(2, true, b"bin"))), 1003);
        assert_eq!(code(read(&client_frame(1, true, &[0xff, 0xfe]))), 1007);
        assert_eq!(code(read(&client_frame(0x5, true, b""))), 1002);
        assert_eq!(code(read(&client_frame(9, true, &[0; 126]))), 1002);
        // A truncated frame is an I/O end, not a panic.
        assert!(matches!(read(&client_frame(1, true, b"hello")[..5]), Err(ReadError::Closed)));
    }

    #[test]
    fn server_frames_encode_lengths() {
        for n in [0usize, 125, 126, 65535, 65536] {
            let mut out = Vec::new();
            write_frame(&mut out, OP_BINARY, &vec![7u8; n]).unwrap();
            let header = match n {
                0..=125 => 2,
                126..=65535 => 4,
                _ => 10,
            };
            assert_eq!(out.len(), header + n);
            assert_eq!(out[0], 0x82);
            assert_eq!(out[1] & 0x80, 0, "server frames are unmasked");
        }
    }
}
