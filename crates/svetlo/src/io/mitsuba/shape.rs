//! Shape plugins: parametric shapes (meshed, spheres analytic), mesh files, SDF grids, instances.

use super::props::{parse_f32, parse_transform};
use super::xml::Node;
use super::Loader;
use crate::error::{Error, Result};
use crate::geometry::{shapes, AnimatedTransform, Geometry, SdfGrid, SdfNormals, Sphere, TriangleMesh};
use crate::io::mesh_files::{self, LoadedMesh};
use crate::io::spectra::SpectrumKind;
use crate::math::Frame;
use crate::spectrum::Rgb;
use glam::{Mat3, Mat4, Vec3};

/// Is the linear part of `m` a uniform scale (any rotation allowed)? Returns the scale.
fn uniform_scale(m: &Mat4) -> Option<f32> {
    let l = Mat3::from_mat4(*m);
    let s = l.determinant().abs().cbrt();
    if s.is_nan() || s <= 0.0 {
        return None;
    }
    let q = l / s;
    let d = q.transpose() * q - Mat3::IDENTITY;
    (d.to_cols_array().iter().all(|v| v.abs() < 1e-4)).then_some(s)
}

impl<'a> Loader<'a> {
    /// Add the geometry of a `<shape>` (placed by `parent`, for instances) to the scene.
    pub(super) fn shape(&mut self, node: &'a Node, parent: Mat4) -> Result<()> {
        self.nested(node, |l| l.shape_plugin(node, parent))
    }

    fn shape_plugin(&mut self, node: &'a Node, parent: Mat4) -> Result<()> {
        let ty = node.type_()?;
        let animation = self.animation(node, parent)?;
        let to_world = match &animation {
            // The geometry is built in the pose of the first keyframe.
            Some(a) => a.reference(),
            None => parent * self.transform(node, "to_world")?.unwrap_or(Mat4::IDENTITY),
        };
        if ty == "instance" {
            if let Some(c) = node.children.iter().find(|c| c.tag == "animation") {
                return Err(c.loc.err("an instance cannot be animated; animate the shapes of its shapegroup"));
            }
            return self.instance(node, to_world);
        }
        self.shape_count += 1;
        let name = node.id().map(str::to_string).unwrap_or_else(|| format!("{ty}#{}", self.shape_count));

        // BSDF and emitter, inline or by reference.
        let (mut material, mut emission) = (None, None);
        for c in &node.children {
            let target = match c.tag.as_str() {
                "ref" if matches!(c.name(), Some("interior") | Some("exterior")) => {
                    return Err(c.loc.err("participating media (interior/exterior) are not supported"));
                }
                // Named or not (Mitsuba's writer emits `<ref name="bsdf" id=..>`): the target's kind decides.
                "ref" => self.lookup(c)?,
                "bsdf" | "emitter" | "medium" => c,
                _ => continue,
            };
            match target.tag.as_str() {
                "bsdf" => {
                    if material.is_some() {
                        return Err(c.loc.err(format!("shape '{name}' has more than one bsdf")));
                    }
                    material = Some(self.material_index(target)?);
                }
                "emitter" => {
                    if target.type_()? != "area" {
                        return Err(target.loc.err(format!("only area emitters can be attached to a shape, not '{}'", target.type_()?)));
                    }
                    if emission.is_some() {
                        return Err(c.loc.err(format!("shape '{name}' has more than one emitter")));
                    }
                    emission = Some(self.spectrum(target, "radiance", Rgb::WHITE, SpectrumKind::Illuminant)?);
                }
                "medium" => return Err(target.loc.err("participating media are not supported")),
                other => return Err(c.loc.err(format!("a <{other}> cannot be attached to a shape"))),
            }
        }
        let flip = self.boolean(node, "flip_normals", false)?;
        let mut attributes = Vec::new();
        let geometry = match ty {
            "sphere" => self.sphere(node, to_world, flip, emission.is_some(), &name)?,
            "rectangle" | "cube" | "disk" | "cylinder" => {
                let (mut m, local) = match ty {
                    "rectangle" => (shapes::rectangle(), Mat4::IDENTITY),
                    "cube" => (shapes::cube(), Mat4::IDENTITY),
                    "disk" => (shapes::disk(shapes::CIRCLE_SEGMENTS), Mat4::IDENTITY),
                    _ => (shapes::cylinder(shapes::CIRCLE_SEGMENTS), self.cylinder_frame(node)?),
                };
                m.transform(&(to_world * local));
                Geometry::Mesh(finish(m, flip))
            }
            "obj" | "ply" | "serialized" => {
                let path = self.file_prop(node)?;
                let (kind, param) = match ty {
                    "obj" => ("obj", u32::from(self.boolean(node, "flip_tex_coords", true)?)),
                    "ply" => ("ply", u32::from(self.boolean(node, "flip_tex_coords", false)?)),
                    _ => {
                        let index = self.int(node, "shape_index", 0)?;
                        ("serialized", u32::try_from(index).map_err(|_| node.loc.err(format!("shape_index must be non-negative, got {index}")))?)
                    }
                };
                let LoadedMesh { mut mesh, warnings, attributes: a } = self.mesh_file(path, kind, param)?;
                attributes = a;
                for w in warnings {
                    self.warn(w);
                }
                if self.boolean(node, "face_normals", false)? {
                    mesh.normals.clear();
                } else if mesh.normals.is_empty() {
                    mesh_files::compute_vertex_normals(&mut mesh);
                }
                mesh.transform(&to_world);
                Geometry::Mesh(finish(mesh, flip))
            }
            "shapegroup" => return Err(node.loc.err("a shapegroup cannot be nested inside another shape")),
            "sdfgrid" => {
                if emission.is_some() {
                    return Err(node.loc.err(format!("shape '{name}': an sdfgrid cannot be an area emitter (Mitsuba 3 does not support it either)")));
                }
                self.sdfgrid(node, to_world)?
            }
            "bsplinecurve" | "linearcurve" | "ellipsoids" | "ellipsoidsmesh" | "merge" => {
                self.warn(format!("{}:{}: shape type '{ty}' is not supported; shape '{name}' skipped", node.loc.file.display(), node.loc.line));
                return Ok(());
            }
            other => return Err(node.loc.err(format!("unknown shape type '{other}'"))),
        };
        let material = match material {
            Some(m) => m,
            None => self.default_material(),
        };
        let material = self.bind_attributes(node, material, &geometry, attributes, &name)?;
        match animation {
            Some(a) => {
                if emission.is_some() && !a.is_static() {
                    return Err(node.loc.err(format!("shape '{name}': an emitting shape cannot be animated (moving area lights are not supported)")));
                }
                self.b.add_animated_shape(geometry, material, emission, &name, a)
            }
            None => self.b.add_shape(geometry, material, emission, &name),
        }
    }

    /// The mesh in file `path` read by plugin `kind` (`obj`, `ply`: `param` is
    /// flip_tex_coords; `serialized`: the shape index), parsed on the first request and
    /// copied from the loader's cache on later ones.
    fn mesh_file(&mut self, path: std::path::PathBuf, kind: &'static str, param: u32) -> Result<LoadedMesh> {
        let key = (path, kind, param);
        if let Some(m) = self.mesh_files.get(&key) {
            return Ok((**m).clone());
        }
        let path = &key.0;
        let loaded = match kind {
            "obj" => mesh_files::load_obj(path, param != 0)?,
            "ply" => mesh_files::load_ply(path, param != 0)?,
            _ => crate::io::serialized::load_serialized(path, param)?,
        };
        let loaded = std::sync::Arc::new(loaded);
        self.mesh_files.insert(key, loaded.clone());
        Ok((*loaded).clone())
    }

    /// A material whose `mesh_attribute` textures read this shape's attributes: a copy of
    /// `material` bound to them, or `material` itself when it has none.
    fn bind_attributes(&mut self, node: &'a Node, material: u32, geometry: &Geometry, attributes: Vec<mesh_files::Attribute>, name: &str) -> Result<u32> {
        use crate::texture::{MeshAttribute, Texture};
        let Some(m) = self.b.material(material) else { return Ok(material) };
        let mut m = m.clone();
        let mut unbound = m.textures_mut().into_iter().filter(|t| matches!(t, Texture::UnboundAttribute(_))).peekable();
        if unbound.peek().is_none() {
            return Ok(material);
        }
        let Geometry::Mesh(mesh) = geometry else {
            return Err(node.loc.err(format!("shape '{name}': mesh_attribute textures need a mesh (a PLY file with the attributes)")));
        };
        let indices = std::sync::Arc::new(mesh.indices.clone());
        for t in unbound {
            let Texture::UnboundAttribute(want) = &*t else { continue };
            let Some(a) = attributes.iter().find(|a| &a.name == want) else {
                let have: Vec<&str> = attributes.iter().map(|a| a.name.as_str()).collect();
                return Err(node.loc.err(format!(
                    "shape '{name}': no mesh attribute '{want}' (the mesh has {})",
                    if have.is_empty() { "none".to_string() } else { have.join(", ") }
                )));
            };
            let expected = if a.per_face { mesh.indices.len() } else { mesh.positions.len() };
            if a.values.len() != expected {
                return Err(node.loc.err(format!(
                    "shape '{name}': attribute '{want}' has {} values for {expected} {}",
                    a.values.len(),
                    if a.per_face { "triangles" } else { "vertices" }
                )));
            }
            *t = Texture::MeshAttribute(std::sync::Arc::new(MeshAttribute {
                name: a.name.clone(),
                per_face: a.per_face,
                values: a.values.clone(),
                indices: indices.clone(),
            }));
        }
        Ok(self.b.add_material(m))
    }

    /// The svetlo extension for motion blur (Mitsuba 0.6's syntax):
    /// `<animation name="to_world">` holding `<transform time="..">` keyframes, in increasing
    /// time, in place of the shape's `<transform name="to_world">`. `parent` places it (instances).
    fn animation(&self, node: &'a Node, parent: Mat4) -> Result<Option<AnimatedTransform>> {
        let mut found: Option<AnimatedTransform> = None;
        for c in node.children.iter().filter(|c| c.tag == "animation") {
            if found.is_some() {
                return Err(c.loc.err("a shape has at most one <animation>"));
            }
            match c.name() {
                Some("to_world") => {}
                Some(other) => return Err(c.loc.err(format!("only to_world can be animated, not '{other}'"))),
                None => return Err(c.loc.err("<animation> needs name=\"to_world\"")),
            }
            if node.children.iter().any(|t| t.tag == "transform" && t.name() == Some("to_world")) {
                return Err(c.loc.err("a shape has either a to_world <transform> or an <animation>, not both"));
            }
            let mut keys = Vec::new();
            for k in &c.children {
                if k.tag != "transform" {
                    return Err(k.loc.err(format!("an <animation> holds <transform time=..> keyframes, not <{}>", k.tag)));
                }
                let time = parse_f32(k.req("time")?, &k.loc, "time")?;
                keys.push((time, parent * parse_transform(k)?));
            }
            let a = AnimatedTransform::new(&keys).map_err(|e| match e {
                Error::Invalid(msg) => c.loc.err(format!("<animation>: {msg}")),
                other => other,
            })?;
            found = Some(a);
        }
        Ok(found)
    }

    /// `<shape type="instance">`: copies the referenced shapegroup's shapes, transformed.
    fn instance(&mut self, node: &'a Node, to_world: Mat4) -> Result<()> {
        let r = node.children.iter().find(|c| c.tag == "ref").ok_or_else(|| node.loc.err("an instance needs a <ref id=...> to a shapegroup"))?;
        let group = self.lookup(r)?;
        if group.tag != "shape" || group.attr("type") != Some("shapegroup") {
            return Err(r.loc.err("an instance must reference a shape of type 'shapegroup'"));
        }
        for c in group.children.iter().filter(|c| c.tag == "shape") {
            self.shape(c, to_world)?;
        }
        Ok(())
    }

    /// Mitsuba's cylinder: from p0 to p1 with a radius, in the frame of `to_world`.
    fn cylinder_frame(&self, node: &'a Node) -> Result<Mat4> {
        let p0 = self.vec3(node, "p0")?.unwrap_or(Vec3::ZERO);
        let p1 = self.vec3(node, "p1")?.unwrap_or(Vec3::Z);
        let r = self.float(node, "radius", 1.0)?;
        let d = p1 - p0;
        let len = d.length();
        if !(len > 0.0 && r > 0.0) {
            return Err(node.loc.err(format!("cylinder needs p0 != p1 and radius > 0 (length {len}, radius {r})")));
        }
        let f = Frame::from_normal(d / len);
        let rot = Mat4::from_cols(f.s.extend(0.0), f.t.extend(0.0), f.n.extend(0.0), glam::Vec4::W);
        Ok(Mat4::from_translation(p0) * rot * Mat4::from_scale(Vec3::new(r, r, len)))
    }

    /// Mitsuba's `sdfgrid`: a one-channel `.vol` grid over the unit cube, placed by `to_world`.
    fn sdfgrid(&mut self, node: &'a Node, to_world: Mat4) -> Result<Geometry> {
        let normals = match self.string(node, "normals")?.unwrap_or("smooth") {
            "smooth" => SdfNormals::Smooth,
            "analytic" => SdfNormals::Analytic,
            other => return Err(node.loc.err(format!("sdfgrid normals must be 'smooth' or 'analytic', not '{other}'"))),
        };
        let path = self.file_prop(node)?;
        let grid = crate::io::vol::read_vol(&path)?;
        if grid.channels != 1 {
            return Err(Error::Scene { file: path, msg: format!("an SDF grid has one channel, this grid has {}", grid.channels) });
        }
        // The grid (4 bytes a sample) is held once; the voxel list is at most as large again.
        let g = SdfGrid::new(grid.res, grid.values, to_world, normals).map_err(|e| Error::Scene { file: path, msg: e })?;
        Ok(Geometry::SdfGrid(Box::new(g)))
    }

    fn sphere(&mut self, node: &'a Node, to_world: Mat4, flip: bool, emits: bool, name: &str) -> Result<Geometry> {
        let center = self.vec3(node, "center")?.unwrap_or(Vec3::ZERO);
        let radius = self.float(node, "radius", 1.0)?;
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(node.loc.err(format!("sphere radius must be positive, got {radius}")));
        }
        let object = to_world * Mat4::from_translation(center) * Mat4::from_scale(Vec3::splat(radius));
        let lin = Mat3::from_mat4(object);
        match uniform_scale(&object) {
            Some(s) if emits || (lin / s - Mat3::IDENTITY).to_cols_array().iter().all(|v| v.abs() < 1e-5) => {
                if (lin / s - Mat3::IDENTITY).to_cols_array().iter().any(|v| v.abs() >= 1e-5) {
                    self.warn(format!("sphere '{name}': emitting sphere kept analytic; the rotation of its uv frame is ignored"));
                }
                Ok(Geometry::Sphere(Sphere { center: object.w_axis.truncate(), radius: s, flip_normals: flip }))
            }
            _ => {
                // A rotated (or non-uniformly scaled) sphere: its uv frame (or shape) needs a mesh.
                self.warn(format!(
                    "sphere '{name}': rotated or non-uniformly scaled, tessellated ({} segments) to keep its shape and uv frame",
                    shapes::CIRCLE_SEGMENTS
                ));
                let mut m = shapes::uv_sphere(shapes::CIRCLE_SEGMENTS);
                m.transform(&object);
                Ok(Geometry::Mesh(finish(m, flip)))
            }
        }
    }
}

/// `flip_normals` on a mesh: reverse the winding and the shading normals.
fn finish(mut m: TriangleMesh, flip: bool) -> TriangleMesh {
    if flip {
        for t in &mut m.indices {
            t.swap(1, 2);
        }
        for n in &mut m.normals {
            *n = -*n;
        }
    }
    m
}
