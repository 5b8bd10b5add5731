//! A client of tev's TCP protocol (<https://github.com/Tom94/tev>, `Ipc.h`): each method's
//! image is created in tev once, then after every pass the tiles whose pixels changed are
//! sent as `UpdateImageV3` packets (RGB interleaved, offsets 0, 1, 2 and stride 3).
//! Packets: `u32` length (including itself), `u8` type, payload; little-endian, strings
//! NUL-terminated.

use super::state::Session;
use std::collections::HashMap;
use std::io::{self, Write};
use std::net::TcpStream;
use std::sync::Arc;
use std::time::Duration;
use svetlo::film::Image;

pub const CREATE_IMAGE: u8 = 4;
pub const UPDATE_IMAGE_V3: u8 = 6;
/// Side of the tiles updates are cut into.
pub const TILE: usize = 128;

fn packet(kind: u8, body: &[u8]) -> Vec<u8> {
    let mut p = ((body.len() + 5) as u32).to_le_bytes().to_vec();
    p.push(kind);
    p.extend_from_slice(body);
    p
}

fn put_str(b: &mut Vec<u8>, s: &str) {
    // tev's strings end at the first NUL: keep names free of them.
    b.extend(s.bytes().filter(|&c| c != 0));
    b.push(0);
}

const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// `CreateImage`: an RGB image of this size, without taking the focus.
pub fn create_image(name: &str, width: u32, height: u32) -> Vec<u8> {
    let mut b = vec![0u8];
    put_str(&mut b, name);
    b.extend_from_slice(&(width as i32).to_le_bytes());
    b.extend_from_slice(&(height as i32).to_le_bytes());
    b.extend_from_slice(&(CHANNELS.len() as i32).to_le_bytes());
    for c in CHANNELS {
        put_str(&mut b, c);
    }
    packet(CREATE_IMAGE, &b)
}

/// `UpdateImageV3` of the rectangle `[x, x + w) x [y, y + h)` of `img`.
pub fn update_image(name: &str, img: &Image, x: usize, y: usize, w: usize, h: usize) -> Vec<u8> {
    let mut b = vec![0u8];
    put_str(&mut b, name);
    b.extend_from_slice(&(CHANNELS.len() as i32).to_le_bytes());
    for c in CHANNELS {
        put_str(&mut b, c);
    }
    for v in [x, y, w, h] {
        b.extend_from_slice(&(v as i32).to_le_bytes());
    }
    for off in 0..3i64 {
        b.extend_from_slice(&off.to_le_bytes());
    }
    for _ in 0..3 {
        b.extend_from_slice(&3i64.to_le_bytes());
    }
    b.reserve(w * h * 12);
    for row in y..y + h {
        for c in &img.data[row * img.width + x..row * img.width + x + w] {
            for k in 0..3 {
                b.extend_from_slice(&c[k].to_le_bytes());
            }
        }
    }
    packet(UPDATE_IMAGE_V3, &b)
}

/// One connection to tev, remembering what it holds so that only changes are sent.
pub struct TevStream<W: Write> {
    out: W,
    /// Per image name: its size and the pixels last sent.
    shown: HashMap<String, Image>,
}

impl<W: Write> TevStream<W> {
    pub fn new(out: W) -> Self {
        TevStream { out, shown: HashMap::new() }
    }

    /// Send `img` as `name`: created if new (or resized), then every tile that differs from
    /// what tev has. Returns the number of tiles sent.
    pub fn show(&mut self, name: &str, img: &Image) -> io::Result<usize> {
        let known = self.shown.get(name).filter(|o| o.width == img.width && o.height == img.height);
        let old = match known {
            Some(o) => Some(o),
            None => {
                self.out.write_all(&create_image(name, img.width as u32, img.height as u32))?;
                None
            }
        };
        let mut sent = 0;
        let mut packets = Vec::new();
        for ty in (0..img.height).step_by(TILE) {
            for tx in (0..img.width).step_by(TILE) {
                let (w, h) = (TILE.min(img.width - tx), TILE.min(img.height - ty));
                let changed = old.is_none_or(|o| {
                    (ty..ty + h).any(|r| o.data[r * o.width + tx..r * o.width + tx + w] != img.data[r * img.width + tx..r * img.width + tx + w])
                });
                if changed {
                    packets.push(update_image(name, img, tx, ty, w, h));
                    sent += 1;
                }
            }
        }
        for p in packets {
            self.out.write_all(&p)?;
        }
        self.out.flush()?;
        self.shown.insert(name.to_string(), img.clone());
        Ok(sent)
    }
}

/// Stream the session's images to tev at `addr` until the session shuts down or tev goes
/// away (then with a warning: the render goes on).
pub fn spawn(addr: String, session: Arc<Session>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let stream = match TcpStream::connect(&addr) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("warning: --tev {addr}: cannot connect ({e}); the render goes on without it");
                return;
            }
        };
        let _ = stream.set_write_timeout(Some(Duration::from_secs(10)));
        let mut tev = TevStream::new(io::BufWriter::new(stream));
        let mut seen = 0u64;
        let mut sent: HashMap<usize, (u64, u64)> = HashMap::new();
        loop {
            let (todo, version, shutdown) = {
                let s = session.wait_change(seen, Duration::from_millis(500));
                let todo: Vec<_> = s
                    .slots
                    .iter()
                    .enumerate()
                    .filter_map(|(i, sl)| {
                        let f = sl.frame.clone()?;
                        (sent.get(&i) != Some(&(s.run, sl.frame_version))).then(|| {
                            sent.insert(i, (s.run, sl.frame_version));
                            (format!("svetlo {} {}", session.info.scene, sl.method), f)
                        })
                    })
                    .collect();
                (todo, s.version, s.shutdown)
            };
            seen = version;
            for (name, f) in todo {
                if let Err(e) = tev.show(&name, f.color()) {
                    eprintln!("warning: --tev {addr}: {e}; no more updates to tev");
                    return;
                }
            }
            if shutdown {
                return;
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;
    use svetlo::Rgb;

    /// A fake tev: parses packets the way tev does and records what it was told.
    #[derive(Default, Debug)]
    struct FakeTev {
        images: HashMap<String, (i32, i32, Vec<String>)>,
        /// (image, x, y, w, h, the RGB values)
        updates: Vec<(String, i32, i32, i32, i32, Vec<f32>)>,
    }

    struct Reader<'a>(&'a [u8]);
    impl Reader<'_> {
        fn bytes(&mut self, n: usize) -> &[u8] {
            let (a, b) = self.0.split_at(n);
            self.0 = b;
            a
        }
        fn i32(&mut self) -> i32 {
            i32::from_le_bytes(self.bytes(4).try_into().unwrap())
        }
        fn i64(&mut self) -> i64 {
            i64::from_le_bytes(self.bytes(8).try_into().unwrap())
        }
        fn string(&mut self) -> String {
            let n = self.0.iter().position(|&b| b == 0).expect("NUL-terminated");
            let s = String::from_utf8(self.bytes(n).to_vec()).unwrap();
            self.bytes(1);
            s
        }
    }

    impl FakeTev {
        fn feed(&mut self, mut data: &[u8]) {
            while !data.is_empty() {
                let len = u32::from_le_bytes(data[..4].try_into().unwrap()) as usize;
                assert!(len >= 5 && len <= data.len(), "length {len} includes itself and fits");
                let mut r = Reader(&data[5..len]);
                match data[4] {
                    CREATE_IMAGE => {
                        assert_eq!(r.bytes(1), [0], "grab focus off");
                        let name = r.string();
                        let (w, h, n) = (r.i32(), r.i32(), r.i32());
                        let ch = (0..n).map(|_| r.string()).collect();
                        self.images.insert(name, (w, h, ch));
                    }
                    UPDATE_IMAGE_V3 => {
                        r.bytes(1);
                        let name = r.string();
                        let n = r.i32();
                        let ch: Vec<String> = (0..n).map(|_| r.string()).collect();
                        assert_eq!(ch, ["R", "G", "B"]);
                        let (x, y, w, h) = (r.i32(), r.i32(), r.i32(), r.i32());
                        let offsets: Vec<i64> = (0..n).map(|_| r.i64()).collect();
                        let strides: Vec<i64> = (0..n).map(|_| r.i64()).collect();
                        assert_eq!((offsets, strides), (vec![0, 1, 2], vec![3, 3, 3]));
                        let (iw, ih, _) = self.images.get(&name).expect("updates only created images");
                        assert!(x >= 0 && y >= 0 && x + w <= *iw && y + h <= *ih, "tile inside the image");
                        let vals: Vec<f32> = r.0.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
                        assert_eq!(vals.len(), (w * h * 3) as usize, "exactly the tile's data");
                        self.updates.push((name, x, y, w, h, vals));
                    }
                    t => panic!("unexpected packet type {t}"),
                }
                data = &data[len..];
            }
        }
    }

    fn gradient(w: usize, h: usize, k: f32) -> Image {
        Image::new(w, h, (0..w * h).map(|i| Rgb::new(i as f32 * k, 1.0, (i % w) as f32)).collect())
    }

    /// Through a real socket: tev gets the image created once, every tile, then only the
    /// tile that changed, each value where it belongs.
    #[test]
    fn fake_tev_receives_created_image_and_changed_tiles() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let fake = std::thread::spawn(move || {
            let (mut s, _) = listener.accept().unwrap();
            let mut all = Vec::new();
            s.read_to_end(&mut all).unwrap();
            let mut t = FakeTev::default();
            t.feed(&all);
            t
        });
        let (w, h) = (300, 140);
        let a = gradient(w, h, 0.5);
        let mut b = a.clone();
        b.data[135 * w + 290] = Rgb::new(9.0, 9.0, 9.0); // tile (2, 1)
        {
            let mut tev = TevStream::new(TcpStream::connect(addr).unwrap());
            assert_eq!(tev.show("svetlo cbox path", &a).unwrap(), 6, "3 x 2 tiles of 128");
            assert_eq!(tev.show("svetlo cbox path", &b).unwrap(), 1);
            assert_eq!(tev.show("svetlo cbox path", &b).unwrap(), 0, "nothing changed");
        }
        let t = fake.join().unwrap();
        assert_eq!(t.images["svetlo cbox path"], (300, 140, vec!["R".to_string(), "G".into(), "B".into()]));
        assert_eq!(t.updates.len(), 7);
        // The tiles of the first image cover it exactly, with its values.
        let mut seen = vec![0u32; w * h];
        for (_, x, y, tw, th, vals) in &t.updates[..6] {
            for j in 0..*th as usize {
                for i in 0..*tw as usize {
                    let (px, py) = (*x as usize + i, *y as usize + j);
                    seen[py * w + px] += 1;
                    let v = &vals[(j * *tw as usize + i) * 3..][..3];
                    assert_eq!(v, a.data[py * w + px].to_array());
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
        let (_, x, y, tw, th, vals) = &t.updates[6];
        assert_eq!((*x, *y, *tw, *th), (256, 128, 44, 12));
        assert_eq!(&vals[((135 - 128) * 44 + (290 - 256)) * 3..][..3], &[9.0, 9.0, 9.0]);
    }
}
