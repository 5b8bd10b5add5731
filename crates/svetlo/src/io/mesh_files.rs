//! Wavefront OBJ and Stanford PLY meshes, read as Mitsuba 3 reads them: all objects of a file
//! form one mesh, polygons become triangle fans, OBJ texture coordinates have v flipped
//! (`flip_tex_coords`, default true for OBJ and false for PLY), and meshes without normals
//! get angle-weighted vertex normals unless face normals are asked for.

use crate::error::{Error, Result};
use crate::geometry::TriangleMesh;
use crate::math::lane::dot3;
use glam::{Vec2, Vec3};
use std::path::Path;

pub(super) fn mesh_err(path: &Path, msg: impl std::fmt::Display) -> Error {
    Error::Mesh { file: path.to_path_buf(), msg: msg.to_string() }
}

/// A mesh read from a file, with what was adapted on the way.
#[derive(Clone)]
pub struct LoadedMesh {
    pub mesh: TriangleMesh,
    pub warnings: Vec<String>,
    /// Further per-vertex and per-face values (PLY), for `mesh_attribute` textures.
    pub attributes: Vec<Attribute>,
}

/// Values a PLY file gives per vertex or per face beyond the geometry, named as Mitsuba
/// names them: `vertex_NAME` / `face_NAME`, where properties `NAME_0`, `NAME_1`, .. are the
/// channels of one attribute and `r g b` (or `red green blue`) those of `color`.
#[derive(Clone, Debug, PartialEq)]
pub struct Attribute {
    pub name: String,
    pub per_face: bool,
    /// One to three channels (one is grey).
    pub channels: usize,
    /// Per vertex, or per triangle (a polygon's value repeated on each of its triangles).
    pub values: Vec<crate::spectrum::Rgb>,
}

/// Group a PLY element's extra scalar properties into attributes: (name, the properties'
/// positions among the extras per channel, scale). 8-bit colours are scaled by 1/255.
fn group_attributes(names: &[(String, bool)]) -> Vec<(String, Vec<usize>, f32)> {
    // (name, (channel, position) per property, scale)
    type Group = (String, Vec<(usize, usize)>, f32);
    let mut groups: Vec<Group> = Vec::new();
    for (i, (n, uchar)) in names.iter().enumerate() {
        let (base, channel) = match n.as_str() {
            "r" | "red" => ("color".to_string(), 0),
            "g" | "green" => ("color".to_string(), 1),
            "b" | "blue" => ("color".to_string(), 2),
            "a" | "alpha" => continue,
            _ => match n.rsplit_once('_') {
                Some((b, d)) if !b.is_empty() && d.len() == 1 && d.as_bytes()[0].is_ascii_digit() => (b.to_string(), (d.as_bytes()[0] - b'0') as usize),
                _ => (n.clone(), 0),
            },
        };
        let scale = if *uchar && base == "color" { 1.0 / 255.0 } else { 1.0 };
        match groups.iter_mut().find(|g| g.0 == base) {
            Some(g) => g.1.push((channel, i)),
            None => groups.push((base, vec![(channel, i)], scale)),
        }
    }
    groups
        .into_iter()
        .map(|(n, mut ch, scale)| {
            ch.sort();
            (n, ch.into_iter().map(|c| c.1).take(3).collect(), scale)
        })
        .collect()
}

pub(super) fn attribute_values(extra: &[f32], channels: &[usize], scale: f32) -> crate::spectrum::Rgb {
    let c = |k: usize| channels.get(k).and_then(|&i| extra.get(i)).copied().unwrap_or(0.0) * scale;
    if channels.len() == 1 {
        crate::spectrum::Rgb::splat(c(0))
    } else {
        crate::spectrum::Rgb::new(c(0), c(1), c(2))
    }
}

/// Read an OBJ file. Materials (`mtllib`) are ignored: the scene file gives the BSDF.
pub fn load_obj(path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    load_obj_bytes(&crate::limits::read_file(path)?, path, flip_tex_coords)
}

/// Check an OBJ's face indices before the OBJ reader sees them (a relative index past the
/// first vertex overflows inside it), and its size against the memory budget.
fn check_obj(bytes: &[u8], path: &Path) -> Result<()> {
    // Vertices, texture coordinates and normals defined so far, and face corners in all.
    let (mut counts, mut corners) = ([0i64; 3], 0u64);
    let mut check = |ln: usize, tok: &mut dyn Iterator<Item = &str>| -> Result<()> {
        match tok.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("f") | Some("l") | Some("p") => {
                for corner in tok {
                    corners += 1;
                    for (k, idx) in slash_split(corner).enumerate().take(3) {
                        if idx.is_empty() && k > 0 {
                            continue;
                        }
                        let n = counts[k];
                        let ok = match idx.parse::<i64>() {
                            Ok(i) if i > 0 => i <= n,
                            Ok(i) if i < 0 => -i <= n,
                            _ => false,
                        };
                        if !ok {
                            let what = ["vertex", "texture coordinate", "normal"][k];
                            return Err(mesh_err(path, format!("line {}: {what} index '{idx}' is out of range ({n} defined so far)", ln + 1)));
                        }
                    }
                }
            }
            _ => {}
        }
        Ok(())
    };
    match std::str::from_utf8(bytes).ok().filter(|t| t.is_ascii()) {
        // ASCII text (the common case), split without decoding characters: the same words.
        Some(text) => {
            for (ln, line) in text.split('\n').enumerate() {
                check(ln, &mut AsciiWords::new(line))?;
            }
        }
        None => {
            for (ln, line) in bytes.split(|&b| b == b'\n').enumerate() {
                let line = String::from_utf8_lossy(line);
                check(ln, &mut line.split_whitespace())?;
            }
        }
    }
    // Unindexed, every corner may become its own vertex (position, normal, uv, index).
    let bytes_needed = corners.saturating_mul(4 + 32).saturating_add((counts[0] as u64 + counts[2] as u64) * 12 + counts[1] as u64 * 8);
    crate::limits::check(format!("{}: a mesh of {corners} face corners", path.display()), bytes_needed)
}

/// [`load_obj`] for a file held in memory; `path` names it in errors.
pub fn load_obj_bytes(bytes: &[u8], path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    check_obj(bytes, path)?;
    let models = match obj_single_object(bytes) {
        Some(mesh) => vec![tobj::Model::new(mesh, String::new())],
        None => {
            let mut reader = std::io::Cursor::new(bytes);
            let opts = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
            tobj::load_obj_buf(&mut reader, &opts, |_| Ok((Vec::new(), Default::default()))).map_err(|e| mesh_err(path, format!("invalid OBJ: {e}")))?.0
        }
    };
    let mut mesh = TriangleMesh::default();
    let mut warnings = Vec::new();
    let (mut all_uv, mut all_n) = (true, true);
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len() as u32;
        let nv = m.positions.len() / 3;
        mesh.positions.extend(m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        if m.normals.len() == 3 * nv {
            mesh.normals.extend(m.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2])));
        } else {
            all_n = false;
        }
        if m.texcoords.len() == 2 * nv {
            let flip = |v: f32| if flip_tex_coords { 1.0 - v } else { v };
            mesh.uvs.extend(m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], flip(t[1]))));
        } else {
            all_uv = false;
        }
        if m.indices.len() % 3 != 0 {
            return Err(mesh_err(path, "face list is not made of triangles after triangulation"));
        }
        for t in m.indices.chunks_exact(3) {
            let tri = [t[0] + base, t[1] + base, t[2] + base];
            if tri.iter().any(|&i| i >= base + nv as u32) {
                return Err(mesh_err(path, format!("face index {:?} out of range", t)));
            }
            mesh.indices.push(tri);
        }
    }
    if !all_n && !mesh.normals.is_empty() {
        warnings.push(format!("{}: some faces have normals and some not: normals recomputed", path.display()));
        mesh.normals.clear();
    }
    if !all_uv && !mesh.uvs.is_empty() {
        warnings.push(format!("{}: some faces have texture coordinates and some not: uvs dropped", path.display()));
        mesh.uvs.clear();
    }
    check_finite(path, &mesh)?;
    if mesh.indices.is_empty() {
        return Err(mesh_err(path, "the OBJ file has no faces"));
    }
    Ok(LoadedMesh { mesh, warnings, attributes: Vec::new() })
}

/// `char::is_whitespace` on ASCII (vertical tab included): how the OBJ reader splits words.
#[inline]
fn obj_space(b: u8) -> bool {
    b == b' ' || (b'\t'..=b'\r').contains(&b)
}

/// `s.split('/')`, found byte by byte: the same pieces ('/' is one byte, never inside a
/// character), without the general searcher's set-up for every corner of every face.
fn slash_split(s: &str) -> impl Iterator<Item = &str> {
    let mut rest = Some(s);
    std::iter::from_fn(move || {
        let r = rest?;
        match r.bytes().position(|c| c == b'/') {
            Some(k) => {
                rest = r.get(k + 1..);
                r.get(..k)
            }
            None => rest.take(),
        }
    })
}

/// The words of an ASCII line: `split_whitespace` without decoding characters.
struct AsciiWords<'a> {
    s: &'a str,
    i: usize,
}

impl<'a> AsciiWords<'a> {
    fn new(s: &'a str) -> Self {
        AsciiWords { s, i: 0 }
    }
}

impl<'a> Iterator for AsciiWords<'a> {
    type Item = &'a str;
    #[inline]
    fn next(&mut self) -> Option<&'a str> {
        let b = self.s.as_bytes();
        while self.i < b.len() && obj_space(b[self.i]) {
            self.i += 1;
        }
        if self.i == b.len() {
            return None;
        }
        let start = self.i;
        while self.i < b.len() && !obj_space(b[self.i]) {
            self.i += 1;
        }
        // Both ends sit on ASCII bytes, hence on character boundaries.
        self.s.get(start..self.i)
    }
}

/// The common OBJ file read without the general reader (`tobj`): ASCII, one object (no `o`
/// or `g` after the first face, no material change), positions of three coordinates, faces
/// (`f`) of three corners or more. It gives what `tobj` gives for such a file with the
/// options [`load_obj_bytes`] passes (a single index in order of first use of each
/// corner's position/uv/normal triple, polygons as fans, relative indices, the uvs and
/// normals of the whole file), and `None` for any other file or any line it would not read
/// the same way, which `tobj` then reads (or refuses) as before. No per-line allocation or
/// hashing: the corner triples of a position chain from it.
fn obj_single_object(bytes: &[u8]) -> Option<tobj::Mesh> {
    const MISSING: usize = usize::MAX;
    // ASCII, hence UTF-8.
    let text = std::str::from_utf8(bytes).ok().filter(|t| t.is_ascii())?;
    let (mut pos, mut tex, mut nor) = (Vec::<f32>::new(), Vec::<f32>::new(), Vec::<f32>::new());
    // Corners in the order tobj adds them (faces already fanned into triangles).
    let mut corners: Vec<[usize; 3]> = Vec::new();
    let mut face: Vec<[usize; 3]> = Vec::new();
    for line in text.split('\n') {
        let mut words = AsciiWords::new(line);
        let floats = |words: &mut dyn Iterator<Item = &str>, out: &mut Vec<f32>, n: usize| -> Option<()> {
            for _ in 0..n {
                out.push(words.next()?.parse::<f32>().ok()?);
            }
            Some(())
        };
        match words.next() {
            None | Some("#") => {}
            Some("v") => {
                floats(&mut words, &mut pos, 3)?;
                // A w or a colour: tobj's own rules.
                if words.next().is_some() {
                    return None;
                }
            }
            Some("vt") => floats(&mut words, &mut tex, 2)?,
            Some("vn") => floats(&mut words, &mut nor, 3)?,
            Some("f") => {
                face.clear();
                let sizes = [pos.len() / 3, tex.len() / 2, nor.len() / 3];
                for w in words {
                    let mut idx = [MISSING; 3];
                    for (k, part) in slash_split(w).enumerate() {
                        if part.is_empty() {
                            continue;
                        }
                        let x: isize = part.parse().ok()?;
                        *idx.get_mut(k)? = if x < 0 { (sizes[k] as isize + x) as usize } else { (x - 1) as usize };
                    }
                    face.push(idx);
                }
                match face.len() {
                    // Points and lines: tobj's options drop them.
                    1 | 2 => {}
                    0 => return None,
                    _ => {
                        for k in 2..face.len() {
                            corners.extend([face[0], face[k - 1], face[k]]);
                        }
                    }
                }
            }
            // A new object or group after faces: tobj starts another model.
            Some("o") | Some("g") if !corners.is_empty() => return None,
            // tobj reads a line as a face, of whatever arity.
            Some("l") => return None,
            // tobj's name rule; an empty name is its error. Names find no material (the
            // loader gives none), so no new model either.
            Some("usemtl") if line.split_once(' ').unwrap_or_default().1.trim().is_empty() => return None,
            _ => {}
        }
    }
    let mut mesh = tobj::Mesh::default();
    // For each position, the corners using it: (uv, normal, index, next with that position).
    let mut head = vec![u32::MAX; pos.len() / 3];
    let mut chain: Vec<(usize, usize, u32, u32)> = Vec::new();
    for &[v, vt, vn] in &corners {
        let h = head.get_mut(v)?;
        let mut at = *h;
        let found = loop {
            if at == u32::MAX {
                break None;
            }
            let e = chain[at as usize];
            if e.0 == vt && e.1 == vn {
                break Some(e.2);
            }
            at = e.3;
        };
        if let Some(i) = found {
            mesh.indices.push(i);
            continue;
        }
        let next = chain.len() as u32;
        chain.push((vt, vn, next, *h));
        *h = next;
        mesh.positions.extend_from_slice(&pos[3 * v..3 * v + 3]);
        if !tex.is_empty() && vt != MISSING {
            let at = vt.checked_mul(2)?;
            mesh.texcoords.extend_from_slice(tex.get(at..at.checked_add(2)?)?);
        }
        if !nor.is_empty() && vn != MISSING {
            let at = vn.checked_mul(3)?;
            mesh.normals.extend_from_slice(nor.get(at..at.checked_add(3)?)?);
        }
        mesh.indices.push(next);
    }
    Some(mesh)
}

/// Read a PLY file (ASCII or binary). Vertex properties x, y, z; optional nx, ny, nz; uvs as
/// u, v or texture_u, texture_v or s, t. Faces from `vertex_indices` or `vertex_index`.
pub fn load_ply(path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    load_ply_bytes(&crate::limits::read_file(path)?, path, flip_tex_coords)
}

/// The element counts a PLY header announces, checked before the PLY reader allocates for
/// them: a binary file must hold at least one byte per property of every element, a text
/// file two (a digit and a separator), and the parsed elements must fit the budget. Returns
/// each element's (count, properties) as the header declares them.
pub(super) fn check_ply_header(bytes: &[u8], path: &Path) -> Result<Vec<(u64, u64)>> {
    let end = bytes.windows(10).position(|w| w == b"end_header").ok_or_else(|| mesh_err(path, "invalid PLY: no end_header"))?;
    let header = String::from_utf8_lossy(&bytes[..end]);
    let ascii = header.lines().any(|l| l.trim().starts_with("format ascii"));
    // (count, properties) per element
    let mut elements: Vec<(u64, u64)> = Vec::new();
    for line in header.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.as_slice() {
            ["element", _, n] => {
                let n: u64 = n.parse().map_err(|_| mesh_err(path, format!("invalid PLY: element count '{n}'")))?;
                elements.push((n, 0));
            }
            ["property", ..] => {
                if let Some(e) = elements.last_mut() {
                    e.1 += 1;
                }
            }
            _ => {}
        }
    }
    let per_prop = if ascii { 2 } else { 1 };
    let min_len: u64 = elements.iter().map(|&(n, p)| n.saturating_mul(p * per_prop)).fold(0, u64::saturating_add);
    let data = (bytes.len() - end) as u64;
    if min_len > data {
        return Err(mesh_err(path, format!("invalid PLY: the header announces at least {min_len} bytes of elements, the file holds {data}")));
    }
    // Bounded by ~64 bytes per property of every element (vertices and faces are read into
    // fixed structs, face lists into vectors: less than that).
    let parsed: u64 = elements.iter().map(|&(n, p)| n.saturating_mul(64 * p + 64)).fold(0, u64::saturating_add);
    crate::limits::check(format!("{}: a PLY of {} elements", path.display(), elements.iter().map(|e| e.0).sum::<u64>()), parsed)?;
    Ok(elements)
}

/// Vertex properties a PLY mesh may give, in the order of [`PlyVertex::values`].
pub(super) const PLY_VERTEX_KEYS: [&str; 12] = ["x", "y", "z", "nx", "ny", "nz", "u", "v", "texture_u", "texture_v", "s", "t"];

/// One PLY vertex as the parser fills it: a fixed slot per known property (no map per
/// vertex), with a bit per slot set when the file gave it as a scalar.
struct PlyVertex {
    values: [f32; 12],
    set: u16,
    /// Other scalar properties, in the header's order (attributes).
    extra: Vec<f32>,
}

impl ply_rs_bw::ply::PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex { values: [0.0; 12], set: 0, extra: Vec::new() }
    }
    fn set_property(&mut self, key: &str, property: ply_rs_bw::ply::Property) -> ply_rs_bw::ply::PropertyAccessResult {
        use ply_rs_bw::ply::PropertyAccessResult;
        match (PLY_VERTEX_KEYS.iter().position(|k| *k == key), property.to_f32_lossy()) {
            (Some(i), Some(x)) => {
                self.values[i] = x;
                self.set |= 1 << i;
                PropertyAccessResult::Set
            }
            (None, Some(x)) => {
                self.extra.push(x);
                PropertyAccessResult::Set
            }
            _ => PropertyAccessResult::Ignored,
        }
    }
}

/// One PLY face: its index list (`vertex_indices`, else `vertex_index`).
struct PlyFace {
    indices: Option<ply_rs_bw::ply::Property>,
    index: Option<ply_rs_bw::ply::Property>,
    /// Scalar properties, in the header's order (attributes).
    extra: Vec<f32>,
}

impl ply_rs_bw::ply::PropertyAccess for PlyFace {
    fn new() -> Self {
        PlyFace { indices: None, index: None, extra: Vec::new() }
    }
    fn set_property(&mut self, key: &str, property: ply_rs_bw::ply::Property) -> ply_rs_bw::ply::PropertyAccessResult {
        match key {
            "vertex_indices" => self.indices = Some(property),
            "vertex_index" => self.index = Some(property),
            _ => match property.to_f32_lossy() {
                Some(x) => self.extra.push(x),
                None => return ply_rs_bw::ply::PropertyAccessResult::Ignored,
            },
        }
        ply_rs_bw::ply::PropertyAccessResult::Set
    }
}

/// Elements other than vertices and faces: read past, kept nowhere.
struct PlySkipped;

impl ply_rs_bw::ply::PropertyAccess for PlySkipped {
    fn new() -> Self {
        PlySkipped
    }
}

/// [`load_ply`] for a file held in memory; `path` names it in errors.
pub fn load_ply_bytes(bytes: &[u8], path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    use ply_rs_bw::parser::{Parser, Reader};
    let declared = check_ply_header(bytes, path)?;
    let mut reader = Reader::new(std::io::Cursor::new(bytes));
    let invalid = |e: ply_rs_bw::parser::ParseError| mesh_err(path, format!("invalid PLY: {e}"));
    let header = Parser::<PlySkipped>::new().read_header(&mut reader).map_err(invalid)?;
    let payload = reader.get_ref().position() as usize;
    if let Some(mesh) = super::ply_binary::read(bytes, &header, &declared, payload, path, flip_tex_coords) {
        return mesh;
    }
    read_ply_payload(reader, &header, path, flip_tex_coords)
}

/// [`load_ply_bytes`] without the binary fast path (what the fast path is tested against).
#[cfg(test)]
pub(super) fn load_ply_general(bytes: &[u8], path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    check_ply_header(bytes, path)?;
    let mut reader = ply_rs_bw::parser::Reader::new(std::io::Cursor::new(bytes));
    let header = ply_rs_bw::parser::Parser::<PlySkipped>::new().read_header(&mut reader).map_err(|e| mesh_err(path, format!("invalid PLY: {e}")))?;
    read_ply_payload(reader, &header, path, flip_tex_coords)
}

/// The general reader's payload: any layout, ASCII or binary.
fn read_ply_payload(
    mut reader: ply_rs_bw::parser::Reader<std::io::Cursor<&[u8]>>,
    header: &ply_rs_bw::ply::Header,
    path: &Path,
    flip_tex_coords: bool,
) -> Result<LoadedMesh> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::Property;
    let invalid = |e: ply_rs_bw::parser::ParseError| mesh_err(path, format!("invalid PLY: {e}"));
    let (mut verts, mut faces): (Option<Vec<PlyVertex>>, Option<Vec<PlyFace>>) = (None, None);
    let mut vertex_names: Vec<&str> = Vec::new();
    // The extra scalar properties of vertices and faces: (name, 8-bit).
    let extras = |def: &ply_rs_bw::ply::ElementDef, skip: &[&str]| -> Vec<(String, bool)> {
        use ply_rs_bw::ply::{PropertyType, ScalarType};
        def.properties
            .values()
            .filter(|p| !skip.contains(&p.name.as_str()))
            .filter_map(|p| match &p.data_type {
                PropertyType::Scalar(t) => Some((p.name.clone(), *t == ScalarType::UChar)),
                PropertyType::List(..) => None,
            })
            .collect()
    };
    let (mut vertex_extra, mut face_extra) = (Vec::new(), Vec::new());
    // Elements come in the header's order; each is read whole before the next.
    for def in header.elements.values() {
        match def.name.as_str() {
            "vertex" if verts.is_none() => {
                vertex_names = def.properties.keys().map(|k| k.as_str()).collect();
                vertex_extra = extras(def, &PLY_VERTEX_KEYS);
                verts = Some(Parser::<PlyVertex>::new().read_payload_for_element(&mut reader, def, header).map_err(invalid)?);
            }
            "face" if faces.is_none() => {
                face_extra = extras(def, &["vertex_indices", "vertex_index"]);
                faces = Some(Parser::<PlyFace>::new().read_payload_for_element(&mut reader, def, header).map_err(invalid)?)
            }
            _ => {
                Parser::<PlySkipped>::new().read_payload_for_element(&mut reader, def, header).map_err(invalid)?;
            }
        }
    }
    let verts = verts.ok_or_else(|| mesh_err(path, "no 'vertex' element"))?;
    let faces = faces.ok_or_else(|| mesh_err(path, "no 'face' element"))?;
    let mut mesh = TriangleMesh::default();
    let slot = |k: &str| PLY_VERTEX_KEYS.iter().position(|x| *x == k).unwrap_or(0);
    let declared = |k: &str| vertex_names.contains(&k);
    let uv_keys = [("u", "v"), ("texture_u", "texture_v"), ("s", "t")];
    let uv_key = uv_keys.iter().find(|(a, b)| declared(a) && declared(b));
    let has_n = declared("nx") && declared("ny") && declared("nz");
    mesh.positions.reserve(verts.len());
    for (i, v) in verts.iter().enumerate() {
        let get = |k: &str| {
            let s = slot(k);
            if v.set & (1 << s) != 0 {
                Ok(v.values[s])
            } else {
                Err(mesh_err(path, format!("vertex {i}: missing or non-scalar property '{k}'")))
            }
        };
        mesh.positions.push(Vec3::new(get("x")?, get("y")?, get("z")?));
        if has_n {
            mesh.normals.push(Vec3::new(get("nx")?, get("ny")?, get("nz")?));
        }
        if let Some((ku, kv)) = uv_key {
            let vv = get(kv)?;
            mesh.uvs.push(Vec2::new(get(ku)?, if flip_tex_coords { 1.0 - vv } else { vv }));
        }
    }
    let (vertex_groups, face_groups, mut attributes) = ply_attributes(&vertex_extra, &face_extra, verts.len());
    if !vertex_groups.is_empty() {
        for (i, v) in verts.iter().enumerate() {
            if v.extra.len() != vertex_extra.len() {
                return Err(mesh_err(path, format!("vertex {i}: {} attribute values, the header declares {}", v.extra.len(), vertex_extra.len())));
            }
            for (a, (_, ch, scale)) in attributes.iter_mut().zip(&vertex_groups) {
                a.values.push(attribute_values(&v.extra, ch, *scale));
            }
        }
    }
    let nv = mesh.positions.len() as i64;
    mesh.indices.reserve(faces.len());
    for (fi, f) in faces.iter().enumerate() {
        let list = f.indices.as_ref().or(f.index.as_ref()).ok_or_else(|| mesh_err(path, format!("face {fi}: no vertex_indices")))?;
        let idx: Vec<i64> = match list {
            Property::ListChar(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListUChar(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListShort(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListUShort(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListInt(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListUInt(l) => l.iter().map(|&x| x as i64).collect(),
            _ => return Err(mesh_err(path, format!("face {fi}: vertex indices are not an integer list"))),
        };
        push_fan(&mut mesh.indices, &idx, nv, fi, path)?;
        if !face_groups.is_empty() {
            if f.extra.len() != face_extra.len() {
                return Err(mesh_err(path, format!("face {fi}: {} attribute values, the header declares {}", f.extra.len(), face_extra.len())));
            }
            let first = vertex_groups.len();
            for (a, (_, ch, scale)) in attributes[first..].iter_mut().zip(&face_groups) {
                let v = attribute_values(&f.extra, ch, *scale);
                a.values.extend(std::iter::repeat_n(v, idx.len().saturating_sub(2)));
            }
        }
    }
    finish_ply(path, mesh, attributes)
}

/// The attributes of a PLY's extra vertex and face properties ((name, 8-bit) each, in the
/// header's order): each element's groups and the empty attributes, vertices' first.
type AttributeGroups = Vec<(String, Vec<usize>, f32)>;
pub(super) fn ply_attributes(
    vertex_extra: &[(String, bool)],
    face_extra: &[(String, bool)],
    vertices: usize,
) -> (AttributeGroups, AttributeGroups, Vec<Attribute>) {
    let vertex_groups = group_attributes(vertex_extra);
    let face_groups = group_attributes(face_extra);
    let attributes = vertex_groups
        .iter()
        .map(|(n, ch, _)| Attribute { name: format!("vertex_{n}"), per_face: false, channels: ch.len(), values: Vec::with_capacity(vertices) })
        .chain(face_groups.iter().map(|(n, ch, _)| Attribute { name: format!("face_{n}"), per_face: true, channels: ch.len(), values: Vec::new() }))
        .collect();
    (vertex_groups, face_groups, attributes)
}

/// Face `face`'s polygon `idx` as a fan of triangles around its first vertex, its indices
/// checked against the `nv` vertices.
pub(super) fn push_fan(indices: &mut Vec<[u32; 3]>, idx: &[i64], nv: i64, face: usize, path: &Path) -> Result<()> {
    if let Some(bad) = idx.iter().find(|&&i| i < 0 || i >= nv) {
        return Err(mesh_err(path, format!("face {face}: vertex index {bad} out of range (the mesh has {nv} vertices)")));
    }
    for k in 2..idx.len() {
        indices.push([idx[0] as u32, idx[k - 1] as u32, idx[k] as u32]);
    }
    Ok(())
}

/// A PLY mesh as read, checked.
pub(super) fn finish_ply(path: &Path, mesh: TriangleMesh, attributes: Vec<Attribute>) -> Result<LoadedMesh> {
    check_finite(path, &mesh)?;
    if mesh.indices.is_empty() {
        return Err(mesh_err(path, "the PLY file has no faces"));
    }
    Ok(LoadedMesh { mesh, warnings: Vec::new(), attributes })
}

fn check_finite(path: &Path, m: &TriangleMesh) -> Result<()> {
    if let Some(i) = m.positions.iter().position(|p| !p.is_finite()) {
        return Err(mesh_err(path, format!("vertex {} has a non-finite position {:?}", i, m.positions[i])));
    }
    if let Some(i) = m.uvs.iter().position(|p| !p.is_finite()) {
        return Err(mesh_err(path, format!("vertex {} has non-finite texture coordinates {:?}", i, m.uvs[i])));
    }
    Ok(())
}

/// Angle-weighted vertex normals (Thürmer and Wüthrich), Mitsuba's choice for meshes without
/// normals. Vertices that only touch degenerate triangles get a zero normal, which the mesh
/// treats as "use the geometric normal".
pub fn compute_vertex_normals(m: &mut TriangleMesh) {
    // Faces a chunk at a time: their edges gathered, their normals and corner cosines as vector
    // lanes, then the arc cosines (libm's bits, `math::acosf`: the call per corner was most of
    // this), then the sums in face order (the same additions in the same order).
    let mut acc = vec![Vec3::ZERO; m.positions.len()];
    let mut lanes = Box::new(FaceLanes { edges: [[[0.0; CHUNK]; 3]; 3], normals: [[0.0; CHUNK]; 3], angles: [[0.0; CHUNK]; 3] });
    for faces in m.indices.chunks(CHUNK) {
        for (j, t) in faces.iter().enumerate() {
            let p = t.map(|i| m.positions[i as usize]);
            for (e, v) in lanes.edges.iter_mut().zip([p[1] - p[0], p[2] - p[0], p[2] - p[1]]) {
                e[0][j] = v.x;
                e[1][j] = v.y;
                e[2][j] = v.z;
            }
        }
        lanes.corners(faces.len());
        for angles in &mut lanes.angles {
            crate::math::acosf::acosf_in_place(&mut angles[..faces.len()]);
        }
        let FaceLanes { normals, angles, .. } = &*lanes;
        for (j, t) in faces.iter().enumerate() {
            let n = Vec3::new(normals[0][j], normals[1][j], normals[2][j]);
            if n == Vec3::ZERO {
                continue;
            }
            for k in 0..3 {
                acc[t[k] as usize] += n * angles[k][j];
            }
        }
    }
    m.normals = acc.into_iter().map(|n| n.normalize_or_zero()).collect();
}

/// Faces per chunk of [`compute_vertex_normals`].
const CHUNK: usize = 256;

/// A chunk of faces as lanes, one array per component: the edges p1 - p0, p2 - p0, p2 - p1,
/// then the unit normals and the corners' cosines (and arc cosines), corner k of face j at
/// `angles[k][j]`.
struct FaceLanes {
    edges: [[[f32; CHUNK]; 3]; 3],
    normals: [[f32; CHUNK]; 3],
    angles: [[f32; CHUNK]; 3],
}

impl FaceLanes {
    /// The normals and clamped cosines of the first `n` faces, eight at a time where the CPU
    /// has AVX2.
    fn corners(&mut self, n: usize) {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::avx2() {
            // SAFETY: the CPU has AVX2.
            unsafe { self.corners_avx2(n) };
            return;
        }
        self.corners_lanes(n);
    }

    /// The same loop compiled for AVX2 (no FMA: every product and sum rounds as glam's do).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn corners_avx2(&mut self, n: usize) {
        self.corners_lanes(n);
    }

    /// glam's cross product, normalizations and dot products (`Vec3::normalize_or_zero`,
    /// `dot`), operation for operation. Each edge is normalized once: the corner at its other
    /// end sees its negation, which is the negated difference normalized, exactly (a zero's
    /// sign aside, which the dot products' values and acos(+-0) do not see).
    #[inline(always)]
    fn corners_lanes(&mut self, n: usize) {
        let FaceLanes { edges, normals, angles } = self;
        for j in 0..n.min(CHUNK) {
            let a = [edges[0][0][j], edges[0][1][j], edges[0][2][j]];
            let b = [edges[1][0][j], edges[1][1][j], edges[1][2][j]];
            let c = [edges[2][0][j], edges[2][1][j], edges[2][2][j]];
            let cross = [a[1] * b[2] - b[1] * a[2], a[2] * b[0] - b[2] * a[0], a[0] * b[1] - b[0] * a[1]];
            let normal = lane_normalize(cross);
            let (ua, ub, uc) = (lane_normalize(a), lane_normalize(b), lane_normalize(c));
            for k in 0..3 {
                normals[k][j] = normal[k];
            }
            let cosines = [dot3(ua, ub), dot3(uc, lane_neg(ua)), dot3(lane_neg(ub), lane_neg(uc))];
            for k in 0..3 {
                angles[k][j] = cosines[k].clamp(-1.0, 1.0);
            }
        }
    }
}

/// A lane's components negated (functions, not closures: these inline into the AVX2 copy).
#[inline(always)]
fn lane_neg(a: [f32; 3]) -> [f32; 3] {
    [-a[0], -a[1], -a[2]]
}

/// `Vec3::normalize_or_zero` on a lane's components.
#[inline(always)]
fn lane_normalize(v: [f32; 3]) -> [f32; 3] {
    let rcp = 1.0 / dot3(v, v).sqrt();
    if rcp.is_finite() && rcp > 0.0 {
        [v[0] * rcp, v[1] * rcp, v[2] * rcp]
    } else {
        [0.0; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What tobj reads with the options of `load_obj_bytes`, as one mesh (None: an error).
    fn tobj_mesh(text: &str) -> Option<Vec<tobj::Model>> {
        let opts = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
        tobj::load_obj_buf(&mut std::io::Cursor::new(text.as_bytes()), &opts, |_| Ok((Vec::new(), Default::default()))).ok().map(|m| m.0)
    }

    fn same(a: &tobj::Mesh, b: &tobj::Mesh) -> bool {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        bits(&a.positions) == bits(&b.positions) && bits(&a.normals) == bits(&b.normals) && bits(&a.texcoords) == bits(&b.texcoords) && a.indices == b.indices
    }

    /// The chunked vertex normals (edges normalized once, arc cosines as vector lanes) are the
    /// per-corner computation's bits, on a random mesh with degenerate and repeated triangles,
    /// where libm is glibc's (see `math::acosf`).
    #[test]
    fn vertex_normals_are_the_per_corner_ones() {
        #[cfg(all(target_arch = "x86_64", target_os = "linux", target_env = "gnu"))]
        {
            use crate::sampling::rng::Pcg32;
            let mut rng = Pcg32::new(5, 9);
            let mut m = TriangleMesh::default();
            for i in 0..3000 {
                let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                // Some vertices coincide (zero edges), some lie on a line with others.
                m.positions.push(match i % 50 {
                    7 => m.positions[i - 1],
                    8 => m.positions[i - 2] * 2.0 - m.positions[i - 3],
                    _ => v * 2.0 - 1.0,
                });
            }
            let pick = |rng: &mut Pcg32| (rng.next_f32() * 3000.0) as u32 % 3000;
            for i in 0..2000 {
                let t = [pick(&mut rng), pick(&mut rng), pick(&mut rng)];
                m.indices.push(t);
                if i % 9 == 0 {
                    m.indices.push([i % 3000, i % 3000 + 1, i % 3000 + 2]);
                    m.indices.push([t[1], t[1], t[0]]);
                }
            }
            let mut acc = vec![Vec3::ZERO; m.positions.len()];
            for t in &m.indices {
                let p = t.map(|i| m.positions[i as usize]);
                let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                if n == Vec3::ZERO {
                    continue;
                }
                for k in 0..3 {
                    let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
                    let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
                    acc[t[k] as usize] += n * e1.dot(e2).clamp(-1.0, 1.0).acos();
                }
            }
            let want: Vec<[u32; 3]> = acc.iter().map(|n| n.normalize_or_zero().to_array().map(f32::to_bits)).collect();
            compute_vertex_normals(&mut m);
            let got: Vec<[u32; 3]> = m.normals.iter().map(|n| n.to_array().map(f32::to_bits)).collect();
            assert!(got == want);
        }
    }

    /// The single-object reader gives tobj's mesh bit for bit where it reads a file, and
    /// leaves to tobj the files it does not read the same way.
    #[test]
    fn single_object_reader_is_tobj() {
        let header = "# comment\nmtllib none.mtl\no thing\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1e-3\nvt 0 0\nvt 1 0 0.5\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 0 -1 7\n";
        let read = [
            "f 1 2 3\nf 1 3 4\n",
            "f 1/1 2/2 3/3 4/4\n",
            "f 1/1/1 2/2/1 3/3/1\nf 1/1/2 3/3/2 4/4/2\nf 1/1/1 3/3/1 5/2/1\n",
            "usemtl red\ns off\nf -5//1 -4//1 -3//1 -2//1 -1//1\np 1\nf 1 2\nf 3\n",
            "f 1/1 2 3/3\r\nf\t2/2/1 \x0b 4/4/1 5/1/1\r\n",
            "g group\nf 1/-4/-2 2/-3/-1 3/-2/-2\n",
        ];
        for body in read {
            let text = format!("{header}{body}");
            let fast = obj_single_object(text.as_bytes()).unwrap_or_else(|| panic!("not read: {body:?}"));
            let slow = tobj_mesh(&text).expect("tobj reads it");
            assert_eq!(slow.len(), 1, "{body:?}");
            assert!(same(&fast, &slow[0].mesh), "{body:?}");
        }
        // Left to tobj: another object after faces, lines, w coordinates, vertex colours, an
        // empty face or material name, a face index tobj refuses, non-ASCII text.
        let left = [
            "f 1 2 3\no other\nf 1 3 4\n",
            "f 1 2 3\nl 1 2\n",
            "v 1 2 3 0.5\nf 1 2 3\n",
            "v 1 2 3 0.5 0.5 0.5\nf 1 2 3\n",
            "f\n",
            "usemtl\nf 1 2 3\n",
            "f 1 2 3/1/1/1\n",
            "f 1 2 x\n",
            "f 1 2 9\n",
            "# \u{e9}\nf 1 2 3\n",
        ];
        for body in left {
            assert!(obj_single_object(format!("{header}{body}").as_bytes()).is_none(), "{body:?}");
        }
    }

    #[test]
    fn slash_split_and_ascii_words_are_the_std_ones() {
        for t in ["", "/", "//", "1", "1/2/3", "1//3", "/2/", "15/1/1/", "\u{e9}/x/\u{2003}", "-1/-2"] {
            assert_eq!(slash_split(t).collect::<Vec<_>>(), t.split('/').collect::<Vec<_>>(), "{t:?}");
        }
        for t in ["", "   ", "f 1 2 3", "\tv  1.5\x0b2\x0c3\r", " vt 0 1 ", "#", "a\x1cb"] {
            assert_eq!(AsciiWords::new(t).collect::<Vec<_>>(), t.split_whitespace().collect::<Vec<_>>(), "{t:?}");
        }
    }

    /// The shared scenes' OBJ files: the same meshes as tobj's.
    #[test]
    fn single_object_reader_on_shared_meshes() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/mitsuba-data");
        let files = ["common/meshes/sphere.obj", "common/meshes/rectangle.obj", "tests/obj/rectangle_normals_uv.obj", "scenes/cbox/meshes/cbox_largebox.obj"];
        for f in files {
            let Ok(text) = std::fs::read_to_string(root.join(f)) else { continue };
            let slow = tobj_mesh(&text).expect("tobj reads it");
            if slow.len() == 1 {
                let fast = obj_single_object(text.as_bytes()).expect("single object");
                assert!(same(&fast, &slow[0].mesh), "{f}");
            }
        }
    }
}
