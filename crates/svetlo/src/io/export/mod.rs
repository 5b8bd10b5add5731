//! Writing a loaded scene in either format svetlo reads (`svetlo convert`): the in-memory
//! [`Scene`] is the interchange, so every reader feeds both writers. Meshes are written in
//! world space as binary PLY files and bitmaps as EXR files, into a folder beside the scene
//! file (`<stem>_files/`), which the scene references by relative names.
//!
//! What one format cannot hold is approximated or left out, and each such case is returned
//! as a warning (a pbrt-v4 layered material in Mitsuba XML becomes a plastic, a Mitsuba
//! Beckmann lobe in pbrt a GGX one, and so on).

mod mitsuba;
mod pbrt;

use crate::error::{Error, Result};
use crate::geometry::TriangleMesh;
use crate::io::SceneFormat;
use crate::scene::Scene;
use crate::texture::Bitmap;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Write `scene` to `out` in `format`, with its meshes and images in `<stem>_files/` beside
/// it. Returns what could not be carried over exactly.
pub fn export_scene(scene: &Scene, out: &Path, format: SceneFormat) -> Result<Vec<String>> {
    let mut files = Files::new(out)?;
    let text = match format {
        SceneFormat::Mitsuba => mitsuba::write(scene, &mut files)?,
        SceneFormat::Pbrt => pbrt::write(scene, &mut files)?,
    };
    crate::io::image_io::write_atomic(out, text.as_bytes())?;
    Ok(files.warnings)
}

/// The side files of an export and the warnings gathered while writing.
struct Files {
    /// The folder for meshes and images, and its name relative to the scene file.
    dir: PathBuf,
    rel: String,
    created: bool,
    meshes: usize,
    /// Bitmaps already written, by identity (a shared texture is written once).
    /// By the image's address; the image is held so that its address cannot be reused by
    /// another (exporters also write images they build on the fly).
    images: HashMap<usize, (Arc<Bitmap>, String)>,
    warnings: Vec<String>,
}

impl Files {
    fn new(out: &Path) -> Result<Files> {
        let name = out.file_name().and_then(|n| n.to_str()).ok_or_else(|| Error::Settings(format!("'{}' names no file", out.display())))?;
        let stem = name.split('.').next().filter(|s| !s.is_empty()).unwrap_or("scene");
        let rel = format!("{stem}_files");
        let dir = out.parent().unwrap_or(Path::new("")).join(&rel);
        Ok(Files { dir, rel, created: false, meshes: 0, images: HashMap::new(), warnings: Vec::new() })
    }

    fn warn(&mut self, msg: impl Into<String>) {
        self.warnings.push(msg.into());
    }

    fn ensure_dir(&mut self) -> Result<()> {
        if !self.created {
            std::fs::create_dir_all(&self.dir).map_err(|e| Error::Io { file: self.dir.clone(), source: e })?;
            self.created = true;
        }
        Ok(())
    }

    /// Write a mesh as PLY; its name relative to the scene file.
    fn mesh(&mut self, mesh: &TriangleMesh) -> Result<String> {
        self.ensure_dir()?;
        let name = format!("mesh{:04}.ply", self.meshes);
        self.meshes += 1;
        crate::io::image_io::write_atomic(&self.dir.join(&name), &ply_bytes(mesh))?;
        Ok(format!("{}/{name}", self.rel))
    }

    /// Write a bitmap as EXR (linear, as svetlo holds it), once per bitmap.
    fn image(&mut self, image: &Arc<Bitmap>) -> Result<String> {
        let key = Arc::as_ptr(image) as usize;
        if let Some((_, n)) = self.images.get(&key) {
            return Ok(n.clone());
        }
        self.ensure_dir()?;
        let name = format!("image{:04}.exr", self.images.len());
        let img = crate::film::Image::new(image.width, image.height, image.data().to_vec());
        crate::io::image_io::write_exr(&self.dir.join(&name), &img)?;
        let rel = format!("{}/{name}", self.rel);
        self.images.insert(key, (image.clone(), rel.clone()));
        Ok(rel)
    }
}

/// A mesh as binary little-endian PLY: positions, normals and uvs when present, triangles.
fn ply_bytes(m: &TriangleMesh) -> Vec<u8> {
    let has_n = m.normals.len() == m.positions.len() && !m.normals.is_empty();
    let has_uv = m.uvs.len() == m.positions.len() && !m.uvs.is_empty();
    let mut h = format!("ply\nformat binary_little_endian 1.0\ncomment svetlo export\nelement vertex {}\n", m.positions.len());
    h += "property float x\nproperty float y\nproperty float z\n";
    if has_n {
        h += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    if has_uv {
        h += "property float u\nproperty float v\n";
    }
    h += &format!("element face {}\nproperty list uchar int vertex_indices\nend_header\n", m.indices.len());
    let mut out = h.into_bytes();
    let per_vertex = 12 + if has_n { 12 } else { 0 } + if has_uv { 8 } else { 0 };
    out.reserve(m.positions.len() * per_vertex + m.indices.len() * 13);
    for i in 0..m.positions.len() {
        let mut put = |v: f32| out.extend_from_slice(&v.to_le_bytes());
        let p = m.positions[i];
        put(p.x);
        put(p.y);
        put(p.z);
        if has_n {
            let n = m.normals[i];
            put(n.x);
            put(n.y);
            put(n.z);
        }
        if has_uv {
            put(m.uvs[i].x);
            put(m.uvs[i].y);
        }
    }
    for t in &m.indices {
        out.push(3);
        for &i in t {
            out.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    out
}

/// Does the mesh carry per-vertex shading normals?
fn has_normals(m: &TriangleMesh) -> bool {
    !m.normals.is_empty() && m.normals.len() == m.positions.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Vec2, Vec3};

    /// A mesh written as PLY reads back bit for bit through the project's PLY reader.
    #[test]
    fn ply_round_trips() {
        let mesh = TriangleMesh {
            positions: vec![Vec3::new(0.0, 0.1, -2.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.3, 1.0, 1e-7)],
            normals: vec![Vec3::Z, Vec3::Y, Vec3::X],
            uvs: vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.25), Vec2::new(0.5, 1.0)],
            indices: vec![[0, 1, 2], [2, 1, 0]],
        };
        let back = crate::io::mesh_files::load_ply_bytes(&ply_bytes(&mesh), Path::new("t.ply"), false).expect("read").mesh;
        assert_eq!(back.positions, mesh.positions);
        assert_eq!(back.normals, mesh.normals);
        assert_eq!(back.uvs, mesh.uvs);
        assert_eq!(back.indices, mesh.indices);
    }
}
