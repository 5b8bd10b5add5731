//! Mitsuba's `.serialized` meshes (versions 3 and 4), read directly.
//!
//! A file holds one or more meshes one after another, each a little-endian u16 magic
//! 0x041C and u16 version followed by a zlib stream: u32 flags (0x1 vertex normals,
//! 0x2 uvs, 0x8 vertex colours, 0x10 face normals, 0x1000 f32 / 0x2000 f64 values), the
//! shape's name (v4, NUL-terminated), u64 vertex and triangle counts, then positions,
//! normals, uvs and colours per vertex and the triangles' indices (u32, or u64 where the
//! vertex count does not fit in 32 bits). A dictionary at the end gives where each mesh
//! starts (u64 offsets in v4, u32 in v3) and their count (u32, last). Uvs are stored as
//! Mitsuba uses them: no flip.

use super::mesh_files::LoadedMesh;
use crate::error::{Error, Result};
use crate::geometry::TriangleMesh;
use glam::{Vec2, Vec3};
use std::io::Read;
use std::path::Path;

const MAGIC: u16 = 0x041C;
const HAS_NORMALS: u32 = 0x1;
const HAS_UVS: u32 = 0x2;
const HAS_COLORS: u32 = 0x8;
const FACE_NORMALS: u32 = 0x10;
const SINGLE: u32 = 0x1000;
const DOUBLE: u32 = 0x2000;
/// Deflate expands at most ~1032x: a bound on the decompressed size that no valid file exceeds.
const MAX_RATIO: u64 = 1100;

fn bad(path: &Path, msg: impl Into<String>) -> Error {
    Error::Mesh { file: path.to_path_buf(), msg: msg.into() }
}

/// A little-endian cursor over the decompressed stream that fails with a typed error.
struct Cursor<'a> {
    data: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| bad(self.path, format!("truncated: {what} runs past the end of the data")))?;
        let s = &self.data[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
    /// `n` reals of `size` bytes (4 or 8) as f32.
    fn reals(&mut self, n: usize, size: usize, what: &str) -> Result<Vec<f32>> {
        let bytes = self.take(n.checked_mul(size).ok_or_else(|| bad(self.path, format!("{what}: count overflows")))?, what)?;
        Ok(if size == 4 {
            bytes.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes"))).collect()
        } else {
            bytes.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32).collect()
        })
    }
}

/// Byte offset of mesh `index` in the file (0 for the first; the dictionary for the others).
fn mesh_offset(data: &[u8], version: u16, index: u32, path: &Path) -> Result<usize> {
    if index == 0 {
        return Ok(0);
    }
    let n = data.len();
    let count = if n >= 4 { u32::from_le_bytes(data[n - 4..].try_into().expect("4 bytes")) } else { 0 };
    if index >= count {
        return Err(bad(path, format!("shape_index {index}: the file holds {count} meshes")));
    }
    let width = if version >= 4 { 8 } else { 4 };
    let table =
        (count as usize).checked_mul(width).and_then(|t| n.checked_sub(4 + t)).ok_or_else(|| bad(path, "the mesh dictionary is larger than the file"))?;
    let at = table + index as usize * width;
    let off = if width == 8 {
        u64::from_le_bytes(data[at..at + 8].try_into().expect("8 bytes"))
    } else {
        u32::from_le_bytes(data[at..at + 4].try_into().expect("4 bytes")) as u64
    };
    usize::try_from(off).ok().filter(|&o| o < n).ok_or_else(|| bad(path, format!("mesh {index} starts at byte {off}, past the end of the file")))
}

/// Read mesh `shape_index` of a `.serialized` file.
pub fn load_serialized(path: &Path, shape_index: u32) -> Result<LoadedMesh> {
    let data = std::fs::read(path).map_err(|e| Error::Io { file: path.to_path_buf(), source: e })?;
    let start = mesh_offset(&data, if data.len() >= 4 { u16::from_le_bytes([data[2], data[3]]) } else { 0 }, shape_index, path)?;
    let head = data.get(start..start + 4).ok_or_else(|| bad(path, "too short for a serialized mesh header"))?;
    let (magic, version) = (u16::from_le_bytes([head[0], head[1]]), u16::from_le_bytes([head[2], head[3]]));
    if magic != MAGIC {
        return Err(bad(path, format!("not a Mitsuba serialized mesh (magic 0x{magic:04x}, expected 0x041c)")));
    }
    if !(3..=4).contains(&version) {
        return Err(bad(path, format!("serialized mesh version {version} is not supported (3, 4)")));
    }
    let limit = (data.len() as u64).saturating_mul(MAX_RATIO);
    let mut raw = Vec::new();
    flate2::read::ZlibDecoder::new(&data[start + 4..]).take(limit).read_to_end(&mut raw).map_err(|e| bad(path, format!("zlib stream: {e}")))?;
    let mut c = Cursor { data: &raw, at: 0, path };
    let flags = c.u32("the flags")?;
    let size = match (flags & SINGLE != 0, flags & DOUBLE != 0) {
        (true, false) => 4,
        (false, true) => 8,
        _ => return Err(bad(path, format!("flags 0x{flags:x} name neither single nor double precision"))),
    };
    let mut warnings = Vec::new();
    if version >= 4 {
        let rest = &raw[c.at..];
        let len = rest.iter().position(|&b| b == 0).ok_or_else(|| bad(path, "the shape name is not terminated"))?;
        c.at += len + 1;
    }
    let nv = c.u64("the vertex count")?;
    let nt = c.u64("the triangle count")?;
    // Counts are checked against the data before anything is allocated for them.
    let per_vertex = size as u64 * (3 + 3 * (flags & HAS_NORMALS != 0) as u64 + 2 * (flags & HAS_UVS != 0) as u64 + 3 * (flags & HAS_COLORS != 0) as u64);
    let index_size: u64 = if nv > u32::MAX as u64 { 8 } else { 4 };
    let need = nv.checked_mul(per_vertex).and_then(|v| nt.checked_mul(3 * index_size).and_then(|t| v.checked_add(t)));
    if need.is_none_or(|n| n > (raw.len() - c.at) as u64) {
        return Err(bad(path, format!("{nv} vertices and {nt} triangles need more data than the file holds")));
    }
    let (nv, nt) = (nv as usize, nt as usize);
    let vec3s = |v: Vec<f32>| v.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect::<Vec<_>>();
    let mut mesh = TriangleMesh { positions: vec3s(c.reals(3 * nv, size, "positions")?), ..Default::default() };
    if flags & HAS_NORMALS != 0 {
        let n = vec3s(c.reals(3 * nv, size, "normals")?);
        if flags & FACE_NORMALS == 0 {
            mesh.normals = n.into_iter().map(|n| n.normalize_or_zero()).collect();
        }
    }
    if flags & HAS_UVS != 0 {
        mesh.uvs = c.reals(2 * nv, size, "uvs")?.chunks_exact(2).map(|t| Vec2::new(t[0], t[1])).collect();
    }
    if flags & HAS_COLORS != 0 {
        c.reals(3 * nv, size, "vertex colours")?;
        warnings.push(format!("{}: vertex colours ignored", path.display()));
    }
    mesh.indices.reserve(nt);
    for t in 0..nt {
        let mut tri = [0u32; 3];
        for k in &mut tri {
            let i = if index_size == 8 { c.u64("indices")? } else { c.u32("indices")? as u64 };
            if i >= nv as u64 {
                return Err(bad(path, format!("triangle {t} uses vertex {i} of {nv}")));
            }
            *k = i as u32;
        }
        mesh.indices.push(tri);
    }
    if mesh.positions.iter().any(|p| !p.is_finite()) {
        return Err(bad(path, "a vertex position is not finite"));
    }
    Ok(LoadedMesh { mesh, warnings })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A v4 file with `flags`, written as Mitsuba lays it out.
    fn write(path: &Path, flags: u32, positions: &[[f64; 3]], uvs: &[[f64; 2]], tris: &[[u32; 3]]) {
        let mut body = Vec::new();
        body.extend(flags.to_le_bytes());
        body.extend(b"mesh\0");
        body.extend((positions.len() as u64).to_le_bytes());
        body.extend((tris.len() as u64).to_le_bytes());
        let real = |b: &mut Vec<u8>, v: f64| if flags & SINGLE != 0 { b.extend((v as f32).to_le_bytes()) } else { b.extend(v.to_le_bytes()) };
        positions.iter().flatten().for_each(|&v| real(&mut body, v));
        uvs.iter().flatten().for_each(|&v| real(&mut body, v));
        tris.iter().flatten().for_each(|&i| body.extend(i.to_le_bytes()));
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&body).unwrap();
        let mut file = MAGIC.to_le_bytes().to_vec();
        file.extend(4u16.to_le_bytes());
        file.extend(z.finish().unwrap());
        file.extend(0u64.to_le_bytes());
        file.extend(1u32.to_le_bytes());
        std::fs::write(path, file).unwrap();
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("svetlo-serialized-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join(name)
    }

    #[test]
    fn reads_single_and_double_precision() {
        let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.5]];
        let uv = [[0.1, 0.9], [0.8, 0.7], [0.3, 0.2]];
        for flags in [SINGLE | HAS_UVS, DOUBLE | HAS_UVS] {
            let p = scratch(&format!("t{flags}.serialized"));
            write(&p, flags, &pos, &uv, &[[0, 1, 2]]);
            let m = load_serialized(&p, 0).unwrap().mesh;
            assert_eq!(m.positions[2], Vec3::new(0.0, 2.0, 0.5));
            assert_eq!(m.uvs[0], Vec2::new(0.1, 0.9), "uvs as stored");
            assert_eq!(m.indices, vec![[0, 1, 2]]);
        }
    }

    #[test]
    fn bad_files_are_typed_errors() {
        let p = scratch("bad.serialized");
        let err = |p: &Path| load_serialized(p, 0).err().map(|e| e.to_string()).unwrap_or_default();
        std::fs::write(&p, b"").unwrap();
        assert!(err(&p).contains("too short"), "{}", err(&p));
        std::fs::write(&p, [0x1Cu8, 0x04, 4, 0, 1, 2, 3]).unwrap();
        assert!(err(&p).contains("zlib"), "{}", err(&p));
        write(&p, SINGLE, &[[0.0; 3]; 3], &[], &[[0, 1, 5]]);
        assert!(err(&p).contains("vertex 5"), "{}", err(&p));
        write(&p, SINGLE | DOUBLE, &[[0.0; 3]; 3], &[], &[[0, 1, 2]]);
        assert!(err(&p).contains("precision"), "{}", err(&p));
        // An unknown version, and a mesh index past the dictionary.
        write(&p, SINGLE, &[[0.0; 3]; 3], &[], &[[0, 1, 2]]);
        let mut d = std::fs::read(&p).unwrap();
        d[2] = 9;
        std::fs::write(&p, &d).unwrap();
        assert!(err(&p).contains("version 9"), "{}", err(&p));
        assert!(load_serialized(&p, 3).is_err());
    }
}
