//! Wavefront OBJ and Stanford PLY meshes, read as Mitsuba 3 reads them: all objects of a file
//! form one mesh, polygons become triangle fans, OBJ texture coordinates have v flipped
//! (`flip_tex_coords`, default true for OBJ and false for PLY), and meshes without normals
//! get angle-weighted vertex normals unless face normals are asked for.

use crate::error::{Error, Result};
use crate::geometry::TriangleMesh;
use glam::{Vec2, Vec3};
use std::path::Path;

fn mesh_err(path: &Path, msg: impl std::fmt::Display) -> Error {
    Error::Mesh { file: path.to_path_buf(), msg: msg.to_string() }
}

/// A mesh read from a file, with what was adapted on the way.
pub struct LoadedMesh {
    pub mesh: TriangleMesh,
    pub warnings: Vec<String>,
}

/// Read an OBJ file. Materials (`mtllib`) are ignored: the scene file gives the BSDF.
pub fn load_obj(path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    let file = std::fs::File::open(path).map_err(|e| Error::Io { file: path.to_path_buf(), source: e })?;
    let mut reader = std::io::BufReader::new(file);
    let opts = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
    let (models, _) =
        tobj::load_obj_buf(&mut reader, &opts, |_| Ok((Vec::new(), Default::default()))).map_err(|e| mesh_err(path, format!("invalid OBJ: {e}")))?;
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
    Ok(LoadedMesh { mesh, warnings })
}

/// Read a PLY file (ASCII or binary). Vertex properties x, y, z; optional nx, ny, nz; uvs as
/// u, v or texture_u, texture_v or s, t. Faces from `vertex_indices` or `vertex_index`.
pub fn load_ply(path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    let file = std::fs::File::open(path).map_err(|e| Error::Io { file: path.to_path_buf(), source: e })?;
    load_ply_from_reader(&mut std::io::BufReader::new(file), path, flip_tex_coords)
}

/// [`load_ply`] from any reader (decompressed `.ply.gz` data, say); `path` names it in errors.
pub fn load_ply_from_reader(reader: &mut impl std::io::BufRead, path: &Path, flip_tex_coords: bool) -> Result<LoadedMesh> {
    use ply_rs_bw::ply::{DefaultElement, Property};
    let mut reader = reader;
    let parser = ply_rs_bw::parser::Parser::<DefaultElement>::new();
    let ply = parser.read_ply(&mut reader).map_err(|e| mesh_err(path, format!("invalid PLY: {e}")))?;
    let scalar = |e: &DefaultElement, k: &str| e.get(k).and_then(|p| p.to_f32_lossy());
    let verts = ply.payload.get("vertex").ok_or_else(|| mesh_err(path, "no 'vertex' element"))?;
    let faces = ply.payload.get("face").ok_or_else(|| mesh_err(path, "no 'face' element"))?;
    let mut mesh = TriangleMesh::default();
    let uv_keys = [("u", "v"), ("texture_u", "texture_v"), ("s", "t")];
    let uv_key = verts.first().and_then(|v| uv_keys.iter().find(|(a, b)| v.contains_key(*a) && v.contains_key(*b)));
    let has_n = verts.first().is_some_and(|v| v.contains_key("nx") && v.contains_key("ny") && v.contains_key("nz"));
    for (i, v) in verts.iter().enumerate() {
        let get = |k: &str| scalar(v, k).ok_or_else(|| mesh_err(path, format!("vertex {i}: missing or non-scalar property '{k}'")));
        mesh.positions.push(Vec3::new(get("x")?, get("y")?, get("z")?));
        if has_n {
            mesh.normals.push(Vec3::new(get("nx")?, get("ny")?, get("nz")?));
        }
        if let Some((ku, kv)) = uv_key {
            let vv = get(kv)?;
            mesh.uvs.push(Vec2::new(get(ku)?, if flip_tex_coords { 1.0 - vv } else { vv }));
        }
    }
    let nv = mesh.positions.len() as i64;
    for (fi, f) in faces.iter().enumerate() {
        let list = f.get("vertex_indices").or_else(|| f.get("vertex_index")).ok_or_else(|| mesh_err(path, format!("face {fi}: no vertex_indices")))?;
        let idx: Vec<i64> = match list {
            Property::ListChar(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListUChar(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListShort(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListUShort(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListInt(l) => l.iter().map(|&x| x as i64).collect(),
            Property::ListUInt(l) => l.iter().map(|&x| x as i64).collect(),
            _ => return Err(mesh_err(path, format!("face {fi}: vertex indices are not an integer list"))),
        };
        if let Some(bad) = idx.iter().find(|&&i| i < 0 || i >= nv) {
            return Err(mesh_err(path, format!("face {fi}: vertex index {bad} out of range (the mesh has {nv} vertices)")));
        }
        // Polygons become fans around their first vertex.
        for k in 2..idx.len() {
            mesh.indices.push([idx[0] as u32, idx[k - 1] as u32, idx[k] as u32]);
        }
    }
    check_finite(path, &mesh)?;
    if mesh.indices.is_empty() {
        return Err(mesh_err(path, "the PLY file has no faces"));
    }
    Ok(LoadedMesh { mesh, warnings: Vec::new() })
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
            let angle = e1.dot(e2).clamp(-1.0, 1.0).acos();
            acc[t[k] as usize] += n * angle;
        }
    }
    m.normals = acc.into_iter().map(|n| n.normalize_or_zero()).collect();
}
