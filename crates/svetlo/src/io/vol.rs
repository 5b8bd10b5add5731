//! Mitsuba's `.vol` grid files (the `gridvolume` format, read here for `sdfgrid` shapes).
//!
//! Little-endian: the bytes `VOL` and version 3; i32 encoding (1: f32 values, the only one
//! Mitsuba 3 reads); i32 sample counts along x, y, z; i32 channel count; six f32 for the
//! bounding box (min xyz, max xyz); then the values, channels fastest, then x, y, z
//! (index ((z · ny + y) · nx + x) · channels + c).

use crate::error::{Error, Result};
use std::io::Read;
use std::path::Path;

pub const HEADER_BYTES: usize = 48;

/// A grid as the file gives it.
#[derive(Clone, Debug)]
pub struct VolGrid {
    /// Samples along x, y, z.
    pub res: [usize; 3],
    pub channels: usize,
    /// The bounding box the file states (min, max); `sdfgrid` ignores it (its grid spans
    /// the unit cube), as Mitsuba does.
    pub bbox: ([f32; 3], [f32; 3]),
    pub values: Vec<f32>,
}

fn bad(path: &Path, msg: impl Into<String>) -> Error {
    Error::Scene { file: path.to_path_buf(), msg: msg.into() }
}

/// Read a `.vol` file. Its header's sizes are checked against the file's length and the
/// memory budget before the values are allocated.
pub fn read_vol(path: &Path) -> Result<VolGrid> {
    let io = |e| Error::Io { file: path.to_path_buf(), source: e };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(bad(path, "is not a regular file; expected a .vol grid"));
    }
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut header = Vec::with_capacity(HEADER_BYTES);
    (&mut file).take(HEADER_BYTES as u64).read_to_end(&mut header).map_err(io)?;
    let header = parse_header(path, &header)?;
    let count = header.res.iter().chain([&header.channels]).try_fold(1u64, |a, &n| a.checked_mul(n as u64)).unwrap_or(u64::MAX);
    let bytes = count.saturating_mul(4);
    let available = meta.len().saturating_sub(HEADER_BYTES as u64);
    if bytes > available {
        return Err(bad(
            path,
            format!(
                "truncated: the header announces {}x{}x{} samples of {} channel(s) ({bytes} bytes of data) but the file has {available} bytes after its header",
                header.res[0], header.res[1], header.res[2], header.channels
            ),
        ));
    }
    crate::limits::check(format!("the grid of {}", path.display()), bytes)?;
    let mut data = Vec::with_capacity(bytes as usize);
    (&mut file).take(bytes).read_to_end(&mut data).map_err(io)?;
    if (data.len() as u64) < bytes {
        return Err(bad(path, format!("truncated: {} of {bytes} bytes of data", data.len())));
    }
    let values = data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    Ok(VolGrid { values, ..header })
}

/// The header of a `.vol` file (values left empty).
fn parse_header(path: &Path, h: &[u8]) -> Result<VolGrid> {
    if h.len() < 4 || &h[..3] != b"VOL" {
        return Err(bad(path, "not a .vol grid (no 'VOL' at the start)"));
    }
    if h[3] != 3 {
        return Err(bad(path, format!(".vol version {} (only version 3 is read)", h[3])));
    }
    if h.len() < HEADER_BYTES {
        return Err(bad(path, format!("truncated: the header needs {HEADER_BYTES} bytes, the file has {}", h.len())));
    }
    let i32_at = |i: usize| i32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
    let f32_at = |i: usize| f32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
    let encoding = i32_at(4);
    if encoding != 1 {
        return Err(bad(path, format!("grid encoding {encoding} is not supported (1: 32-bit floats)")));
    }
    let dims = [i32_at(8), i32_at(12), i32_at(16), i32_at(20)];
    if let Some(d) = dims.iter().find(|&&d| d <= 0) {
        return Err(bad(path, format!("sizes {}x{}x{} with {} channel(s): {d} is not a positive count", dims[0], dims[1], dims[2], dims[3])));
    }
    let bbox = ([f32_at(24), f32_at(28), f32_at(32)], [f32_at(36), f32_at(40), f32_at(44)]);
    Ok(VolGrid { res: [dims[0] as usize, dims[1] as usize, dims[2] as usize], channels: dims[3] as usize, bbox, values: Vec::new() })
}

/// The bytes of a `.vol` file holding `values` (one channel; tests and tools).
pub fn encode_vol(res: [usize; 3], values: &[f32]) -> Vec<u8> {
    let mut out = b"VOL\x03".to_vec();
    for v in [1, res[0] as i32, res[1] as i32, res[2] as i32, 1] {
        out.extend(v.to_le_bytes());
    }
    for v in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0] {
        out.extend(v.to_le_bytes());
    }
    for v in values {
        out.extend(v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("svetlo-vol-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn round_trips() {
        let values: Vec<f32> = (0..24).map(|i| i as f32 - 10.0).collect();
        let p = write("ok.vol", &encode_vol([2, 3, 4], &values));
        let g = read_vol(&p).unwrap();
        assert_eq!((g.res, g.channels), ([2, 3, 4], 1));
        assert_eq!(g.values, values);
        assert_eq!(g.bbox, ([0.0; 3], [1.0; 3]));
    }

    #[test]
    fn bad_files_are_typed_errors() {
        let good = encode_vol([2, 2, 2], &[1.0; 8]);
        let cases: Vec<(&str, Vec<u8>, &str)> = vec![
            ("empty.vol", Vec::new(), "no 'VOL'"),
            ("text.vol", b"hello world, not a grid at all....................".to_vec(), "no 'VOL'"),
            ("v2.vol", [b"VOL\x02".as_slice(), &good[4..]].concat(), "version 2"),
            ("short-header.vol", good[..20].to_vec(), "header needs 48"),
            ("truncated.vol", good[..good.len() - 1].to_vec(), "truncated"),
            ("f16.vol", [&good[..4], 2i32.to_le_bytes().as_slice(), &good[8..]].concat(), "encoding 2"),
            ("zero.vol", [&good[..8], 0i32.to_le_bytes().as_slice(), &good[12..]].concat(), "not a positive"),
            ("negative.vol", [&good[..16], (-5i32).to_le_bytes().as_slice(), &good[20..]].concat(), "not a positive"),
            // 2³¹ x 2³¹ x 2³¹ samples announced by a 56-byte file: refused before allocating.
            ("huge.vol", [&good[..8], &i32::MAX.to_le_bytes(), &i32::MAX.to_le_bytes(), &i32::MAX.to_le_bytes(), &good[20..]].concat(), "truncated"),
        ];
        for (name, bytes, want) in cases {
            let e = read_vol(&write(name, &bytes)).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains(name), "{name}: {e}");
        }
        let e = read_vol(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(e.contains("not a regular file"), "{e}");
    }
}
