//! Binary PLY files of the layout exporters write (scalar vertex properties, faces as one
//! integer index list plus scalars) read straight from their bytes. The general reader
//! (`ply_rs_bw`) calls a setter per property by name and allocates two vectors per face: on a
//! 1M-triangle mesh that was most of the file's reading. The mesh is the general reader's bit
//! for bit (tested against it); other layouts are left to it.

use super::mesh_files::{attribute_values, finish_ply, mesh_err, ply_attributes, push_fan, LoadedMesh, PLY_VERTEX_KEYS};
use crate::error::Result;
use crate::geometry::TriangleMesh;
use glam::{Vec2, Vec3};
use ply_rs_bw::ply::{ElementDef, Encoding, Header, PropertyType, ScalarType};
use std::path::Path;

/// A PLY scalar type (the reader's own is not `Copy`).
#[derive(Clone, Copy, PartialEq)]
enum Ty {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl From<&ScalarType> for Ty {
    fn from(t: &ScalarType) -> Ty {
        match t {
            ScalarType::Char => Ty::I8,
            ScalarType::UChar => Ty::U8,
            ScalarType::Short => Ty::I16,
            ScalarType::UShort => Ty::U16,
            ScalarType::Int => Ty::I32,
            ScalarType::UInt => Ty::U32,
            ScalarType::Float => Ty::F32,
            ScalarType::Double => Ty::F64,
        }
    }
}

/// Bytes per value.
fn size(t: Ty) -> usize {
    match t {
        Ty::I8 | Ty::U8 => 1,
        Ty::I16 | Ty::U16 => 2,
        Ty::I32 | Ty::U32 | Ty::F32 => 4,
        Ty::F64 => 8,
    }
}

/// The payload, read forward in one byte order; `None` past its end.
struct Payload<'a> {
    data: &'a [u8],
    at: usize,
    big: bool,
}

macro_rules! read_as {
    ($self:ident, $t:ty) => {{
        const N: usize = std::mem::size_of::<$t>();
        let b: [u8; N] = $self.data.get($self.at..$self.at + N)?.try_into().ok()?;
        $self.at += N;
        if $self.big {
            <$t>::from_be_bytes(b)
        } else {
            <$t>::from_le_bytes(b)
        }
    }};
}

impl Payload<'_> {
    /// A scalar as `Property::to_f32_lossy` converts it (what the general reader keeps).
    fn f32(&mut self, t: Ty) -> Option<f32> {
        Some(match t {
            Ty::I8 => f32::from(read_as!(self, i8)),
            Ty::U8 => f32::from(read_as!(self, u8)),
            Ty::I16 => f32::from(read_as!(self, i16)),
            Ty::U16 => f32::from(read_as!(self, u16)),
            Ty::I32 => read_as!(self, i32) as f32,
            Ty::U32 => read_as!(self, u32) as f32,
            Ty::F32 => read_as!(self, f32),
            Ty::F64 => read_as!(self, f64) as f32,
        })
    }

    /// An integer (list counts and vertex indices); floats are not read here.
    fn int(&mut self, t: Ty) -> Option<i64> {
        Some(match t {
            Ty::I8 => i64::from(read_as!(self, i8)),
            Ty::U8 => i64::from(read_as!(self, u8)),
            Ty::I16 => i64::from(read_as!(self, i16)),
            Ty::U16 => i64::from(read_as!(self, u16)),
            Ty::I32 => i64::from(read_as!(self, i32)),
            Ty::U32 => i64::from(read_as!(self, u32)),
            Ty::F32 | Ty::F64 => return None,
        })
    }

    fn left(&self) -> usize {
        self.data.len() - self.at
    }

    /// A vertex of three `float`s (x, y, z), as three `f32` reads give it.
    #[inline(always)]
    fn xyz(&mut self) -> Option<Vec3> {
        let b = self.data.get(self.at..self.at + 12)?;
        let big = self.big;
        let p = Vec3::new(f32::from_bits(word(b, 0, big)), f32::from_bits(word(b, 4, big)), f32::from_bits(word(b, 8, big)));
        self.at += 12;
        Some(p)
    }

    /// A face of the common layout (a `uchar` count, `int` or `uint` indices: `item`) when it is
    /// a triangle whose indices lie among the `nv` vertices, read as the general face loop reads
    /// it (the fan of a triangle is itself); `None`, reading nothing, for anything else, which
    /// that loop then reads (or refuses) as before.
    #[inline(always)]
    fn triangle(&mut self, item: Ty, nv: i64) -> Option<[u32; 3]> {
        let b = self.data.get(self.at..self.at + 13)?;
        if b[0] != 3 {
            return None;
        }
        let (big, signed) = (self.big, item == Ty::I32);
        let idx = [index(b, 1, big, signed), index(b, 5, big, signed), index(b, 9, big, signed)];
        if idx.iter().any(|&i| i < 0 || i >= nv) {
            return None;
        }
        self.at += 13;
        Some([idx[0] as u32, idx[1] as u32, idx[2] as u32])
    }
}

/// The four bytes of `b` at `at` as a word of the file's byte order (`b` holds them).
#[inline(always)]
fn word(b: &[u8], at: usize, big: bool) -> u32 {
    let w = [b[at], b[at + 1], b[at + 2], b[at + 3]];
    if big {
        u32::from_be_bytes(w)
    } else {
        u32::from_le_bytes(w)
    }
}

/// The index at `at` of `b`: `int` indices are signed (a negative one is out of range),
/// `uint` ones are not.
#[inline(always)]
fn index(b: &[u8], at: usize, big: bool, signed: bool) -> i64 {
    let u = word(b, at, big);
    if signed {
        i64::from(u as i32)
    } else {
        i64::from(u)
    }
}

/// Where a vertex property goes: a slot of [`PLY_VERTEX_KEYS`] or the extras, in order.
enum VertexField {
    Slot(usize, Ty),
    Extra(Ty),
}

/// A face property: the index list (count type, index type) or an extra scalar.
enum FaceField {
    Indices(Ty, Ty),
    Extra(Ty),
}

fn is_int(t: Ty) -> bool {
    !matches!(t, Ty::F32 | Ty::F64)
}

/// Scalar properties only: the bytes of one element.
fn fixed_size(def: &ElementDef) -> Option<usize> {
    def.properties.values().map(|p| if let PropertyType::Scalar(t) = &p.data_type { Some(size(t.into())) } else { None }).sum()
}

/// The mesh of a binary PLY whose header `header` (read by the general reader, whose element
/// and property counts `declared` gives as the file declares them) ends at byte `payload`;
/// `None` when the layout is one the general reader should read (ASCII, duplicate names,
/// list vertex properties, faces before vertices, float index lists, ...).
pub fn read(bytes: &[u8], header: &Header, declared: &[(u64, u64)], payload: usize, path: &Path, flip_tex_coords: bool) -> Option<Result<LoadedMesh>> {
    let big = match header.encoding {
        Encoding::BinaryLittleEndian => false,
        Encoding::BinaryBigEndian => true,
        Encoding::Ascii => return None,
    };
    // The general reader keys elements and properties by name: a repeated name collapses there.
    let defs: Vec<&ElementDef> = header.elements.values().collect();
    if defs.len() != declared.len() || defs.iter().zip(declared).any(|(d, &(n, p))| d.count as u64 != n || d.properties.len() as u64 != p) {
        return None;
    }
    let vi = defs.iter().position(|d| d.name == "vertex")?;
    let fi = defs.iter().position(|d| d.name == "face")?;
    if fi < vi {
        return None;
    }
    let vdef = defs[vi];
    let mut vfields = Vec::new();
    let mut vertex_extra = Vec::new();
    for p in vdef.properties.values() {
        let PropertyType::Scalar(t) = &p.data_type else { return None };
        let t = Ty::from(t);
        match PLY_VERTEX_KEYS.iter().position(|k| *k == p.name) {
            Some(i) => vfields.push(VertexField::Slot(i, t)),
            None => {
                vfields.push(VertexField::Extra(t));
                vertex_extra.push((p.name.clone(), t == Ty::U8));
            }
        }
    }
    let declared_key = |k: &str| vdef.properties.values().any(|p| p.name == k);
    if !["x", "y", "z"].iter().all(|k| declared_key(k)) {
        return None;
    }
    let fdef = defs[fi];
    let mut ffields = Vec::new();
    let mut face_extra = Vec::new();
    for p in fdef.properties.values() {
        match (p.name.as_str(), &p.data_type) {
            ("vertex_indices" | "vertex_index", PropertyType::List(c, i)) if is_int(c.into()) && is_int(i.into()) => {
                ffields.push(FaceField::Indices(c.into(), i.into()))
            }
            (_, PropertyType::Scalar(t)) if p.name != "vertex_indices" && p.name != "vertex_index" => {
                ffields.push(FaceField::Extra(t.into()));
                face_extra.push((p.name.clone(), Ty::from(t) == Ty::U8));
            }
            _ => return None,
        }
    }
    if ffields.iter().filter(|f| matches!(f, FaceField::Indices(..))).count() != 1 {
        return None;
    }
    // Other elements are skipped whole: they must have a fixed size.
    let mut skip = vec![0usize; defs.len()];
    for (k, d) in defs.iter().enumerate() {
        if k != vi && k != fi {
            skip[k] = fixed_size(d)?.checked_mul(d.count)?;
        }
    }

    let slot = |k: &str| PLY_VERTEX_KEYS.iter().position(|x| *x == k).unwrap_or(0);
    let has_n = ["nx", "ny", "nz"].iter().all(|k| declared_key(k));
    let uv = [("u", "v"), ("texture_u", "texture_v"), ("s", "t")].iter().find(|(a, b)| declared_key(a) && declared_key(b)).map(|(a, b)| (slot(a), slot(b)));
    let (x, y, z, nx, ny, nz) = (slot("x"), slot("y"), slot("z"), slot("nx"), slot("ny"), slot("nz"));

    // The layout most exporters write (positions alone; triangles as a `uchar` count and 32-bit
    // indices, nothing else per face) read a vertex and a face at a time: the field by field
    // reads were most of a 1M-triangle file's read.
    let xyz_only =
        matches!(vfields[..], [VertexField::Slot(a, Ty::F32), VertexField::Slot(b, Ty::F32), VertexField::Slot(c, Ty::F32)] if (a, b, c) == (x, y, z));
    let triangles = match ffields[..] {
        [FaceField::Indices(Ty::U8, item @ (Ty::I32 | Ty::U32))] => Some(item),
        _ => None,
    };

    let mut data = Payload { data: bytes.get(payload..)?, at: 0, big };
    let ends = |what: &str, i: usize, n: usize| mesh_err(path, format!("invalid PLY: the file ends inside {what} {i} of {n}"));
    let mut mesh = TriangleMesh::default();
    let (vertex_groups, face_groups, mut attributes) = ply_attributes(&vertex_extra, &face_extra, vdef.count);
    let mut extra = Vec::with_capacity(vertex_extra.len().max(face_extra.len()));
    for (k, d) in defs.iter().enumerate() {
        if k == vi {
            mesh.positions.reserve(d.count);
            for i in 0..d.count {
                if xyz_only {
                    let Some(p) = data.xyz() else { return Some(Err(ends("vertex", i, d.count))) };
                    mesh.positions.push(p);
                    continue;
                }
                let mut v = [0.0f32; 12];
                extra.clear();
                for f in &vfields {
                    let read = match *f {
                        VertexField::Slot(s, t) => data.f32(t).map(|a| v[s] = a),
                        VertexField::Extra(t) => data.f32(t).map(|a| extra.push(a)),
                    };
                    if read.is_none() {
                        return Some(Err(ends("vertex", i, d.count)));
                    }
                }
                mesh.positions.push(Vec3::new(v[x], v[y], v[z]));
                if has_n {
                    mesh.normals.push(Vec3::new(v[nx], v[ny], v[nz]));
                }
                if let Some((u, w)) = uv {
                    mesh.uvs.push(Vec2::new(v[u], if flip_tex_coords { 1.0 - v[w] } else { v[w] }));
                }
                for (a, (_, ch, scale)) in attributes.iter_mut().zip(&vertex_groups) {
                    a.values.push(attribute_values(&extra, ch, *scale));
                }
            }
        } else if k == fi {
            let nv = mesh.positions.len() as i64;
            let first = vertex_groups.len();
            let mut idx: Vec<i64> = Vec::new();
            mesh.indices.reserve(d.count);
            for i in 0..d.count {
                if let Some(item) = triangles {
                    if let Some(t) = data.triangle(item, nv) {
                        mesh.indices.push(t);
                        continue;
                    }
                }
                extra.clear();
                for f in &ffields {
                    match *f {
                        FaceField::Indices(count, item) => {
                            let Some(n) = data.int(count) else { return Some(Err(ends("face", i, d.count))) };
                            let n = match usize::try_from(n) {
                                Ok(n) if n.checked_mul(size(item)).is_some_and(|b| b <= data.left()) => n,
                                Ok(_) => return Some(Err(ends("face", i, d.count))),
                                Err(_) => return Some(Err(mesh_err(path, format!("invalid PLY: face {i}: a negative list length {n}")))),
                            };
                            idx.clear();
                            for _ in 0..n {
                                // In bounds: the list's bytes were checked above.
                                idx.push(data.int(item).unwrap_or(-1));
                            }
                        }
                        FaceField::Extra(t) => match data.f32(t) {
                            Some(a) => extra.push(a),
                            None => return Some(Err(ends("face", i, d.count))),
                        },
                    }
                }
                if let Err(e) = push_fan(&mut mesh.indices, &idx, nv, i, path) {
                    return Some(Err(e));
                }
                for (a, (_, ch, scale)) in attributes[first..].iter_mut().zip(&face_groups) {
                    let v = attribute_values(&extra, ch, *scale);
                    a.values.extend(std::iter::repeat_n(v, idx.len().saturating_sub(2)));
                }
            }
        } else {
            if skip[k] > data.left() {
                return Some(Err(ends(&format!("element '{}'", d.name), 0, d.count)));
            }
            data.at += skip[k];
        }
    }
    Some(finish_ply(path, mesh, attributes))
}

#[cfg(test)]
mod tests {
    use super::super::mesh_files::{load_ply_bytes, load_ply_general};
    use super::*;

    /// A small deterministic generator (xorshift64*).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
    }

    const TYPES: [(&str, Ty); 8] = [
        ("char", Ty::I8),
        ("uchar", Ty::U8),
        ("short", Ty::I16),
        ("ushort", Ty::U16),
        ("int", Ty::I32),
        ("uint", Ty::U32),
        ("float", Ty::F32),
        ("double", Ty::F64),
    ];

    /// Writes `v` as type `t` in the byte order, wrapping integers into range.
    fn put(out: &mut Vec<u8>, t: Ty, v: f64, big: bool) {
        macro_rules! w {
            ($x:expr) => {
                if big {
                    out.extend_from_slice(&$x.to_be_bytes())
                } else {
                    out.extend_from_slice(&$x.to_le_bytes())
                }
            };
        }
        match t {
            Ty::I8 => w!(v as i64 as i8),
            Ty::U8 => w!(v as i64 as u8),
            Ty::I16 => w!(v as i64 as i16),
            Ty::U16 => w!(v as i64 as u16),
            Ty::I32 => w!(v as i64 as i32),
            Ty::U32 => w!(v as i64 as u32),
            Ty::F32 => w!(v as f32),
            Ty::F64 => w!(v),
        }
    }

    /// A random binary PLY of the layouts the fast path reads: vertex properties of random
    /// types (positions, maybe normals, uvs under one of three names, colours, numbered and
    /// other extras), faces of 3-5 corners with random count and index types and extras,
    /// and fixed-size elements before, between and after.
    fn random_ply(rng: &mut Rng, big: bool) -> Vec<u8> {
        let ty = |rng: &mut Rng| TYPES[rng.below(8) as usize];
        let float_ty = |rng: &mut Rng| if rng.below(4) == 0 { ("double", Ty::F64) } else { ("float", Ty::F32) };
        let mut vprops: Vec<(String, &str, Ty)> = ["x", "y", "z"].iter().map(|n| (n.to_string(), float_ty(rng))).map(|(n, (s, t))| (n, s, t)).collect();
        if rng.below(2) == 0 {
            for n in ["nx", "ny", "nz"] {
                let (s, t) = float_ty(rng);
                vprops.push((n.into(), s, t));
            }
        }
        let uv = [("u", "v"), ("texture_u", "texture_v"), ("s", "t")];
        if rng.below(2) == 0 {
            let (a, b) = uv[rng.below(3) as usize];
            for n in [a, b] {
                let (s, t) = float_ty(rng);
                vprops.push((n.into(), s, t));
            }
        }
        for n in ["red", "green", "blue", "alpha", "quality", "w_0", "w_1", "nx"] {
            if rng.below(3) == 0 && !vprops.iter().any(|p| p.0 == n) {
                let (s, t) = ty(rng);
                vprops.push((n.into(), s, t));
            }
        }
        // Shuffle the vertex properties.
        for i in (1..vprops.len()).rev() {
            vprops.swap(i, rng.below(i as u64 + 1) as usize);
        }
        let int_types = [("uchar", Ty::U8), ("char", Ty::I8), ("ushort", Ty::U16), ("short", Ty::I16), ("int", Ty::I32), ("uint", Ty::U32)];
        let (count_name, count_ty) = int_types[rng.below(6) as usize];
        let nv = 3 + rng.below(40) as usize;
        let item_types: Vec<_> = int_types.iter().filter(|t| nv <= 127 || !matches!(t.1, Ty::I8 | Ty::U8)).collect();
        let (item_name, item_ty) = *item_types[rng.below(item_types.len() as u64) as usize];
        let index_name = if rng.below(2) == 0 { "vertex_indices" } else { "vertex_index" };
        let mut fprops: Vec<(String, &str, Ty)> = Vec::new();
        for n in ["r", "g", "b", "flags"] {
            if rng.below(3) == 0 {
                let (s, t) = ty(rng);
                fprops.push((n.into(), s, t));
            }
        }
        let list_at = rng.below(fprops.len() as u64 + 1) as usize;
        let nf = 1 + rng.below(30) as usize;
        let skip_count = rng.below(4) as usize;
        let skip_at = rng.below(3);
        let mut head = format!("ply\nformat {} 1.0\ncomment random\n", if big { "binary_big_endian" } else { "binary_little_endian" });
        let skip_head = format!("element edge {skip_count}\nproperty int vertex1\nproperty double weight\n");
        if skip_at == 0 {
            head += &skip_head;
        }
        head += &format!("element vertex {nv}\n");
        for (n, s, _) in &vprops {
            head += &format!("property {s} {n}\n");
        }
        if skip_at == 1 {
            head += &skip_head;
        }
        head += &format!("element face {nf}\n");
        for (k, (n, s, _)) in fprops.iter().enumerate() {
            if k == list_at {
                head += &format!("property list {count_name} {item_name} {index_name}\n");
            }
            head += &format!("property {s} {n}\n");
        }
        if list_at == fprops.len() {
            head += &format!("property list {count_name} {item_name} {index_name}\n");
        }
        if skip_at == 2 {
            head += &skip_head;
        }
        head += "end_header\n";
        let mut out = head.into_bytes();
        let value = |rng: &mut Rng, t: Ty| match t {
            Ty::F32 | Ty::F64 => (rng.below(2_000_001) as f64 - 1e6) * 1.37e-3 + (rng.below(1000) as f64) * 1e-9,
            _ => rng.below(300) as f64,
        };
        let skip = |out: &mut Vec<u8>, rng: &mut Rng| {
            for _ in 0..skip_count {
                put(out, Ty::I32, rng.below(100) as f64, big);
                put(out, Ty::F64, 0.5, big);
            }
        };
        if skip_at == 0 {
            skip(&mut out, rng);
        }
        for _ in 0..nv {
            for (_, _, t) in &vprops {
                let v = value(rng, *t);
                put(&mut out, *t, v, big);
            }
        }
        if skip_at == 1 {
            skip(&mut out, rng);
        }
        for _ in 0..nf {
            let list = |out: &mut Vec<u8>, rng: &mut Rng| {
                let n = 3 + rng.below(3) as usize;
                put(out, count_ty, n as f64, big);
                for _ in 0..n {
                    put(out, item_ty, rng.below(nv as u64) as f64, big);
                }
            };
            for (k, (_, _, t)) in fprops.iter().enumerate() {
                if k == list_at {
                    list(&mut out, rng);
                }
                let v = value(rng, *t);
                put(&mut out, *t, v, big);
            }
            if list_at == fprops.len() {
                list(&mut out, rng);
            }
        }
        if skip_at == 2 {
            skip(&mut out, rng);
        }
        out
    }

    fn same(a: &LoadedMesh, b: &LoadedMesh) -> bool {
        let bits3 = |v: &[Vec3]| v.iter().map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        let bits2 = |v: &[Vec2]| v.iter().map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        let (m, n) = (&a.mesh, &b.mesh);
        bits3(&m.positions) == bits3(&n.positions)
            && bits3(&m.normals) == bits3(&n.normals)
            && bits2(&m.uvs) == bits2(&n.uvs)
            && m.indices == n.indices
            && a.attributes.len() == b.attributes.len()
            && a.attributes.iter().zip(&b.attributes).all(|(x, y)| {
                x.name == y.name
                    && x.per_face == y.per_face
                    && x.channels == y.channels
                    && x.values.iter().map(|c| [c.r, c.g, c.b].map(f32::to_bits)).eq(y.values.iter().map(|c| [c.r, c.g, c.b].map(f32::to_bits)))
            })
    }

    fn fast(bytes: &[u8], flip: bool) -> Option<Result<LoadedMesh>> {
        let path = Path::new("t.ply");
        let declared = super::super::mesh_files::check_ply_header(bytes, path).ok()?;
        let mut reader = ply_rs_bw::parser::Reader::new(std::io::Cursor::new(bytes));
        let header = ply_rs_bw::parser::Parser::<ply_rs_bw::ply::DefaultElement>::new().read_header(&mut reader).ok()?;
        read(bytes, &header, &declared, reader.get_ref().position() as usize, path, flip)
    }

    /// Random layouts, both byte orders: the fast path reads each and gives the general
    /// reader's mesh and attributes bit for bit.
    #[test]
    fn binary_fast_path_is_the_general_reader() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for case in 0..400 {
            let big = case % 2 == 1;
            let bytes = random_ply(&mut rng, big);
            let flip = case % 3 == 0;
            let general = load_ply_general(&bytes, Path::new("t.ply"), flip).unwrap_or_else(|e| panic!("case {case}: {e}"));
            let quick = fast(&bytes, flip).unwrap_or_else(|| panic!("case {case}: not read by the fast path")).unwrap_or_else(|e| panic!("case {case}: {e}"));
            assert!(same(&quick, &general), "case {case}");
            assert!(same(&load_ply_bytes(&bytes, Path::new("t.ply"), flip).expect("reads"), &general), "case {case}");
        }
    }

    /// Cut short anywhere in the payload, a file is refused by both readers (or read the same
    /// where the cut only removes bytes past the elements); a bad index names the face.
    #[test]
    fn binary_fast_path_refuses_what_the_general_reader_refuses() {
        let mut rng = Rng(7);
        let mut refused_by_fast_path = 0;
        for case in 0..60 {
            let bytes = random_ply(&mut rng, case % 2 == 0);
            let start = bytes.windows(11).position(|w| w == b"end_header\n").expect("header") + 11;
            for cut in (start..bytes.len()).step_by(1 + (bytes.len() - start) / 23) {
                let short = &bytes[..cut];
                // The header's element counts refuse most cuts before either reader.
                let checked = super::super::mesh_files::check_ply_header(short, Path::new("t.ply")).is_ok();
                assert_eq!(fast(short, false).is_some(), checked, "case {case} cut {cut}");
                match (load_ply_bytes(short, Path::new("t.ply"), false), load_ply_general(short, Path::new("t.ply"), false)) {
                    (Err(e), Err(_)) => {
                        assert!(e.to_string().contains("t.ply"), "{e}");
                        refused_by_fast_path += usize::from(checked);
                    }
                    (Ok(a), Ok(b)) => assert!(same(&a, &b), "case {case} cut {cut}"),
                    (a, b) => panic!("case {case} cut {cut}: fast {:?}, general {:?}", a.err(), b.err()),
                }
            }
        }
        assert!(refused_by_fast_path > 200, "{refused_by_fast_path} cuts got past the header check");
        // Bytes of the payload overwritten (list lengths, indices, values): the same outcome.
        for case in 0..300 {
            let mut bytes = random_ply(&mut rng, case % 2 == 0);
            let start = bytes.windows(11).position(|w| w == b"end_header\n").expect("header") + 11;
            for _ in 0..1 + rng.below(4) {
                let at = start + rng.below((bytes.len() - start) as u64) as usize;
                bytes[at] = [0, 0xff, 0x80, 0x7f, rng.next() as u8][rng.below(5) as usize];
            }
            match (load_ply_bytes(&bytes, Path::new("t.ply"), false), load_ply_general(&bytes, Path::new("t.ply"), false)) {
                (Err(_), Err(_)) => {}
                (Ok(a), Ok(b)) => assert!(same(&a, &b), "case {case}"),
                (a, b) => panic!("mutated case {case}: fast {:?}, general {:?}", a.err(), b.err()),
            }
        }
        let head = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list char int vertex_indices\nend_header\n";
        let mut body: Vec<u8> = head.bytes().collect();
        body.extend(std::iter::repeat_n(0u8, 36));
        let mut bad = body.clone();
        bad.push(3);
        for i in [0i32, 1, 3] {
            bad.extend_from_slice(&i.to_le_bytes());
        }
        let e = fast(&bad, false).expect("fast layout").err().expect("refused").to_string();
        assert!(e.contains("face 0") && e.contains("out of range"), "{e}");
        let mut negative = body.clone();
        negative.push(0xff);
        let e = fast(&negative, false).expect("fast layout").err().expect("refused").to_string();
        assert!(e.contains("negative"), "{e}");
        assert!(load_ply_general(&negative, Path::new("t.ply"), false).is_err());
    }

    /// The common layout (x, y, z floats; a `uchar` count and `int` or `uint` indices), read a
    /// vertex and a triangle at a time, with quads, indices out of range or negative, list
    /// lengths of 0 and 255 and cuts among the triangles: the general reader's mesh or refusal.
    #[test]
    fn common_layout_is_the_general_reader() {
        let mut rng = Rng(11);
        for case in 0..200 {
            let (big, item) = (case % 2 == 0, if case % 4 < 2 { Ty::I32 } else { Ty::U32 });
            let (nv, nf) = (3 + rng.below(40) as usize, 1 + rng.below(60) as usize);
            let head = format!(
                "ply\nformat binary_{}_endian 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\nelement face {nf}\nproperty list uchar {} vertex_indices\nend_header\n",
                if big { "big" } else { "little" },
                if item == Ty::I32 { "int" } else { "uint" }
            );
            let mut bytes: Vec<u8> = head.into_bytes();
            for _ in 0..3 * nv {
                put(&mut bytes, Ty::F32, rng.below(1000) as f64 * 0.01 - 5.0, big);
            }
            for _ in 0..nf {
                let n = match rng.below(40) {
                    0 => 4,
                    1 if case % 5 == 0 => [0, 255][rng.below(2) as usize],
                    _ => 3,
                };
                put(&mut bytes, Ty::U8, n as f64, big);
                for _ in 0..n {
                    let i = match rng.below(200) {
                        0 if case % 3 == 0 => nv as f64,
                        1 if case % 3 == 0 => -1.0,
                        _ => rng.below(nv as u64) as f64,
                    };
                    put(&mut bytes, item, i, big);
                }
            }
            assert!(fast(&bytes, false).is_some(), "case {case}: not read by the fast path");
            let start = bytes.len() - 13 * nf.min(3);
            for end in [bytes.len(), start, start + 7] {
                let b = &bytes[..end];
                match (load_ply_bytes(b, Path::new("t.ply"), false), load_ply_general(b, Path::new("t.ply"), false)) {
                    (Err(_), Err(_)) => {}
                    (Ok(a), Ok(b)) => assert!(same(&a, &b), "case {case} end {end}"),
                    (a, b) => panic!("case {case} end {end}: fast {:?}, general {:?}", a.err(), b.err()),
                }
            }
        }
    }

    /// Layouts the fast path leaves to the general reader.
    #[test]
    fn other_layouts_go_to_the_general_reader() {
        let v = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
        let f = "element face 1\nproperty list uchar int vertex_indices\n";
        let cases = [
            format!("ply\nformat ascii 1.0\n{v}{f}end_header\n"),
            format!("ply\nformat binary_little_endian 1.0\n{f}{v}end_header\n"),
            format!("ply\nformat binary_little_endian 1.0\n{v}property float x\n{f}end_header\n"),
            format!("ply\nformat binary_little_endian 1.0\n{v}property list uchar float extra\n{f}end_header\n"),
            format!("ply\nformat binary_little_endian 1.0\n{v}element face 1\nproperty list uchar float vertex_indices\nend_header\n"),
            format!("ply\nformat binary_little_endian 1.0\n{v}{f}property list uchar int vertex_index\nend_header\n"),
            format!("ply\nformat binary_little_endian 1.0\n{v}{f}element other 1\nproperty list uchar int values\nend_header\n"),
            format!("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n{f}end_header\n"),
        ];
        for c in &cases {
            let mut bytes = c.clone().into_bytes();
            bytes.extend(std::iter::repeat_n(0u8, 64));
            assert!(fast(&bytes, false).is_none(), "{c}");
        }
    }
}
