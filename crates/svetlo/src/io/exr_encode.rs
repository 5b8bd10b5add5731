//! Writing OpenEXR files: single-part scanline images of 32-bit float channels, one line per
//! block, RLE-compressed (OpenEXR's byte split, delta predictor and run-length code; a line
//! that would grow is stored raw, as the format allows). Reading stays with the `exr` crate.
//!
//! Why our own writer: an image with AOV layers has tens of channels, and the general
//! writer spent more time compressing them than a short render takes to trace (its RLE
//! walks every byte through iterators); this one skips literal stretches eight bytes at a
//! time and takes the channels straight from the images, without copying them into planes.

use crate::error::{Error, Result};
use crate::spectrum::Rgb;

/// One channel of the file: component `component` (0 R, 1 G, 2 B) of each pixel of `data`,
/// rows top to bottom.
pub struct ExrChannel<'a> {
    pub name: String,
    pub data: &'a [Rgb],
    pub component: usize,
}

/// OpenEXR's compression code for RLE.
const RLE: u8 = 1;
/// Pixel type code of 32-bit floats.
const FLOAT: i32 = 2;
/// Longest run or literal one RLE token holds (the format's signed byte allows 128; OpenEXR
/// itself writes at most 127).
const MAX_RUN: usize = 127;
/// Shortest run worth a run token.
const MIN_RUN: usize = 3;

fn bad(msg: impl Into<String>) -> Error {
    Error::Image { file: "(EXR in memory)".into(), msg: msg.into() }
}

/// The bytes of an EXR file of `width` x `height` pixels holding `channels` (any order: the
/// file lists them sorted by name, as OpenEXR requires). Names must be distinct, non-empty,
/// without NUL bytes and at most 255 bytes long.
pub fn encode_exr_channels(width: usize, height: usize, channels: &[ExrChannel]) -> Result<Vec<u8>> {
    if width == 0 || height == 0 || width > i32::MAX as usize || height > i32::MAX as usize {
        return Err(bad(format!("cannot write a {width}x{height} EXR")));
    }
    let mut order: Vec<&ExrChannel> = channels.iter().collect();
    order.sort_by(|a, b| a.name.as_bytes().cmp(b.name.as_bytes()));
    for (i, c) in order.iter().enumerate() {
        if c.name.is_empty() || c.name.len() > 255 || c.name.contains('\0') {
            return Err(bad(format!("EXR channel name {:?} must be 1 to 255 bytes without NUL", c.name)));
        }
        if i > 0 && order[i - 1].name == c.name {
            return Err(bad(format!("EXR channel {} given twice", c.name)));
        }
        if c.data.len() != width * height || c.component > 2 {
            return Err(bad(format!("EXR channel {} does not match the {width}x{height} image", c.name)));
        }
    }
    // A block's size is an i32 in the file: a line of all channels must fit it.
    let line_bytes = order
        .len()
        .checked_mul(width * 4)
        .filter(|&n| n <= i32::MAX as usize)
        .ok_or_else(|| bad(format!("a {width}-pixel line of {} channels is too long for an EXR block", order.len())))?;
    let mut out = header(width, height, &order);
    let table = out.len();
    out.resize(table + 8 * height, 0);
    out.reserve(line_bytes.saturating_mul(height) / 2);
    let (mut raw, mut split, mut predicted, mut packed) =
        (vec![0u8; line_bytes], vec![0u8; line_bytes], vec![0u8; line_bytes], Vec::with_capacity(line_bytes + line_bytes / 64 + 2));
    for y in 0..height {
        for (c, dst) in order.iter().zip(raw.chunks_exact_mut(4 * width)) {
            let row = &c.data[y * width..(y + 1) * width];
            for (p, d) in row.iter().zip(dst.chunks_exact_mut(4)) {
                d.copy_from_slice(&p.to_array()[c.component].to_le_bytes());
            }
        }
        split_and_predict(&raw, &mut split, &mut predicted);
        packed.clear();
        rle(&predicted, &mut packed);
        let data: &[u8] = if packed.len() < raw.len() { &packed } else { &raw };
        let at = out.len() as u64;
        out[table + 8 * y..table + 8 * y + 8].copy_from_slice(&at.to_le_bytes());
        out.extend_from_slice(&(y as i32).to_le_bytes());
        out.extend_from_slice(&(data.len() as i32).to_le_bytes());
        out.extend_from_slice(data);
    }
    Ok(out)
}

/// Magic number, version and the header's attributes, up to its closing NUL.
fn header(width: usize, height: usize, channels: &[&ExrChannel]) -> Vec<u8> {
    let mut h = vec![0x76, 0x2f, 0x31, 0x01];
    // Version 2, single-part scanline; bit 10 when some name is longer than 31 bytes.
    let long_names = channels.iter().any(|c| c.name.len() > 31);
    h.extend_from_slice(&[2, if long_names { 0x04 } else { 0 }, 0, 0]);
    let mut list = Vec::new();
    for c in channels {
        list.extend_from_slice(c.name.as_bytes());
        list.push(0);
        list.extend_from_slice(&FLOAT.to_le_bytes());
        list.extend_from_slice(&[0, 0, 0, 0]); // pLinear, reserved
        list.extend_from_slice(&1i32.to_le_bytes()); // x sampling
        list.extend_from_slice(&1i32.to_le_bytes()); // y sampling
    }
    list.push(0);
    let window: Vec<u8> = [0i32, 0, width as i32 - 1, height as i32 - 1].iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut attr = |name: &str, ty: &str, value: &[u8]| {
        for s in [name, ty] {
            h.extend_from_slice(s.as_bytes());
            h.push(0);
        }
        h.extend_from_slice(&(value.len() as i32).to_le_bytes());
        h.extend_from_slice(value);
    };
    attr("channels", "chlist", &list);
    attr("compression", "compression", &[RLE]);
    attr("dataWindow", "box2i", &window);
    attr("displayWindow", "box2i", &window);
    attr("lineOrder", "lineOrder", &[0]); // increasing y
    attr("pixelAspectRatio", "float", &1f32.to_le_bytes());
    attr("screenWindowCenter", "v2f", &[0f32.to_le_bytes(), 0f32.to_le_bytes()].concat());
    attr("screenWindowWidth", "float", &1f32.to_le_bytes());
    h.push(0);
    h
}

/// OpenEXR's RLE preprocessing: the even bytes then the odd ones (floats' high and low
/// halves apart), each byte replaced by its difference to the one before it plus 128.
fn split_and_predict(raw: &[u8], split: &mut [u8], out: &mut [u8]) {
    let half = raw.len() / 2; // lines hold whole floats: the length is even
    let (lo, hi) = split.split_at_mut(half);
    for ((l, h), pair) in lo.iter_mut().zip(hi.iter_mut()).zip(raw.chunks_exact(2)) {
        *l = pair[0];
        *h = pair[1];
    }
    if let (Some(&first), Some(o)) = (split.first(), out.first_mut()) {
        *o = first;
    }
    for (o, w) in out.iter_mut().skip(1).zip(split.windows(2)) {
        *o = w[1].wrapping_sub(w[0]).wrapping_add(128);
    }
}

/// Run-length code: a run of `n` (3 to 127) equal bytes is `n - 1` and the byte; `n` bytes
/// without such a run are `-n` and the bytes.
fn rle(d: &[u8], out: &mut Vec<u8>) {
    let n = d.len();
    let (mut i, mut literal) = (0usize, 0usize);
    while i < n {
        // Skip eight bytes at once while no two neighbours are equal: no run starts there.
        while i + 9 <= n {
            let a = u64::from_le_bytes(d[i..i + 8].try_into().expect("eight bytes"));
            let b = u64::from_le_bytes(d[i + 1..i + 9].try_into().expect("eight bytes"));
            let x = a ^ b;
            // The lowest flagged byte is x's first zero byte: the first pair of equal neighbours.
            let zero = x.wrapping_sub(0x0101_0101_0101_0101) & !x & 0x8080_8080_8080_8080;
            if zero != 0 {
                i += (zero.trailing_zeros() / 8) as usize;
                break;
            }
            i += 8;
        }
        let mut run = 1;
        while i + run < n && run < MAX_RUN && d[i + run] == d[i] {
            run += 1;
        }
        if run >= MIN_RUN {
            flush_literal(&d[literal..i], out);
            out.push((run - 1) as u8);
            out.push(d[i]);
            i += run;
            literal = i;
        } else {
            i += run;
        }
    }
    flush_literal(&d[literal..n.max(literal)], out);
}

fn flush_literal(bytes: &[u8], out: &mut Vec<u8>) {
    for chunk in bytes.chunks(MAX_RUN) {
        out.push((-(chunk.len() as i32)) as u8);
        out.extend_from_slice(chunk);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OpenEXR's decoding of RLE (what a reader does), to check the coder's tokens.
    fn unrle(mut d: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        while let [c, rest @ ..] = d {
            let c = *c as i8;
            if c < 0 {
                let k = (-(c as i32)) as usize;
                out.extend_from_slice(&rest[..k]);
                d = &rest[k..];
            } else {
                out.extend(std::iter::repeat_n(rest[0], c as usize + 1));
                d = &rest[1..];
            }
        }
        out
    }

    #[test]
    fn rle_round_trips_runs_literals_and_their_borders() {
        let mut rng = 0x1234_5678u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        for len in [0usize, 1, 2, 3, 8, 9, 16, 127, 128, 129, 300, 1000] {
            for kind in 0..4 {
                let d: Vec<u8> = (0..len)
                    .map(|i| match kind {
                        0 => next() as u8,
                        1 => 7,
                        2 => ((i / 5) % 3) as u8, // runs of five
                        _ => (next() % 3) as u8,  // short accidental runs
                    })
                    .collect();
                let mut out = Vec::new();
                rle(&d, &mut out);
                assert_eq!(unrle(&out), d, "len {len} kind {kind}");
                if kind == 1 && len >= 3 {
                    assert!(out.len() <= 2 * len.div_ceil(MAX_RUN) + 4, "a constant line stays tiny");
                }
            }
        }
    }

    #[test]
    fn predictor_is_openexrs() {
        let raw = [10u8, 20, 30, 40, 50, 60];
        let (mut split, mut out) = ([0u8; 6], [0u8; 6]);
        split_and_predict(&raw, &mut split, &mut out);
        // Split: 10 30 50 | 20 40 60, then differences + 128.
        assert_eq!(out, [10, 148, 148, 98, 148, 148]); // 20 - 50 + 128 wraps to 98
    }

    #[test]
    fn the_exr_crate_reads_what_we_write() {
        let (w, h) = (37, 5);
        let img: Vec<Rgb> = (0..w * h).map(|i| if i % 7 == 0 { Rgb::BLACK } else { Rgb::new(i as f32 * 0.37, (i % 5) as f32, -1.5e-3 * i as f32) }).collect();
        let zeros = vec![Rgb::BLACK; w * h];
        let chans: Vec<ExrChannel> = [("R", &img, 0), ("G", &img, 1), ("B", &img, 2), ("layer_with_a_name_longer_than_31_bytes.R", &zeros, 0)]
            .into_iter()
            .map(|(n, d, c)| ExrChannel { name: n.into(), data: d, component: c })
            .collect();
        let bytes = encode_exr_channels(w, h, &chans).unwrap();
        assert!(bytes.len() < w * h * 16, "the lines are compressed, not stored raw");
        let dir = std::env::temp_dir().join(format!("svetlo-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.exr");
        std::fs::write(&p, &bytes).unwrap();
        let read = crate::io::image_io::read_exr_channels(&p).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        let names: Vec<&str> = read.iter().map(|c| c.0.as_str()).collect();
        assert_eq!(names, ["B", "G", "R", "layer_with_a_name_longer_than_31_bytes.R"]);
        for (name, data) in &read {
            let want: Vec<f32> = match name.as_str() {
                "R" => img.iter().map(|p| p.r).collect(),
                "G" => img.iter().map(|p| p.g).collect(),
                "B" => img.iter().map(|p| p.b).collect(),
                _ => vec![0.0; w * h],
            };
            assert_eq!(data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), "{name}");
        }
    }

    #[test]
    fn bad_channels_are_refused() {
        let d = vec![Rgb::BLACK; 4];
        let ch = |n: &str| ExrChannel { name: n.into(), data: &d, component: 0 };
        assert!(encode_exr_channels(2, 2, &[ch("A"), ch("A")]).is_err());
        assert!(encode_exr_channels(2, 2, &[ch("")]).is_err());
        assert!(encode_exr_channels(2, 2, &[ch("a\0b")]).is_err());
        assert!(encode_exr_channels(4, 2, &[ch("A")]).is_err());
        assert!(encode_exr_channels(0, 2, &[]).is_err());
    }
}
