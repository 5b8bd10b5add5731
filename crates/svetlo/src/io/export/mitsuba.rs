//! The scene as Mitsuba 3 XML, in the plugins and parameters svetlo's Mitsuba reader (and
//! Mitsuba 3) understand.

use super::Files;
use crate::bsdf::material::{CoatedBase, MicrofacetKind, Roughness};
use crate::bsdf::Material;
use crate::camera::Projection;
use crate::error::Result;
use crate::film::Filter;
use crate::geometry::Geometry;
use crate::light::projector::ProjectorModel;
use crate::light::Light;
use crate::sampling::SamplerKind;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use crate::texture::{FilterMode, Texture, WrapMode};
use glam::{Affine2, Mat4};
use std::fmt::Write as _;

/// Text escaped for an XML attribute value.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;").replace('>', "&gt;")
}

fn rgb(c: Rgb) -> String {
    format!("{}, {}, {}", c.r, c.g, c.b)
}

/// A 4×4 matrix as Mitsuba's row-major `<matrix value>`.
fn matrix(m: &Mat4) -> String {
    let r = m.transpose().to_cols_array();
    r.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" ")
}

/// A uv transform as the 4×4 `to_uv` Mitsuba's reader takes apart again.
fn uv_matrix(a: &Affine2) -> Mat4 {
    let m = a.matrix2;
    Mat4::from_cols(m.x_axis.extend(0.0).extend(0.0), m.y_axis.extend(0.0).extend(0.0), glam::Vec4::Z, a.translation.extend(0.0).extend(1.0))
}

struct Writer<'a> {
    files: &'a mut Files,
    out: String,
}

impl Writer<'_> {
    fn line(&mut self, depth: usize, s: &str) {
        let _ = writeln!(self.out, "{}{s}", "    ".repeat(depth));
    }

    /// A colour parameter: `<rgb>` for a constant, a nested `<texture>` otherwise.
    fn color(&mut self, d: usize, name: &str, t: &Texture) -> Result<()> {
        match t {
            Texture::Constant(c) => {
                self.line(d, &format!(r#"<rgb name="{name}" value="{}"/>"#, rgb(*c)));
                Ok(())
            }
            _ => self.texture(d, name, t),
        }
    }

    /// A scalar parameter: `<float>` for a constant (its first channel), a texture otherwise.
    fn scalar(&mut self, d: usize, name: &str, t: &Texture) -> Result<()> {
        match t {
            Texture::Constant(c) => {
                self.line(d, &format!(r#"<float name="{name}" value="{}"/>"#, c.r));
                Ok(())
            }
            _ => self.texture(d, name, t),
        }
    }

    fn texture(&mut self, d: usize, name: &str, t: &Texture) -> Result<()> {
        let to_uv = |w: &mut Self, a: &Affine2| {
            if *a != Affine2::IDENTITY {
                w.line(d + 1, &format!(r#"<transform name="to_uv"><matrix value="{}"/></transform>"#, matrix(&uv_matrix(a))));
            }
        };
        match t {
            Texture::Constant(_) => self.color(d, name, t)?,
            Texture::Bitmap { image, filter, wrap, to_uv: a } => {
                let file = self.files.image(image)?;
                self.line(d, &format!(r#"<texture type="bitmap" name="{name}">"#));
                self.line(d + 1, &format!(r#"<string name="filename" value="{}"/>"#, esc(&file)));
                let f = match filter {
                    FilterMode::Nearest => "nearest",
                    FilterMode::Bilinear => "bilinear",
                };
                let w = match wrap {
                    WrapMode::Repeat => "repeat",
                    WrapMode::Mirror => "mirror",
                    WrapMode::Clamp => "clamp",
                };
                self.line(d + 1, &format!(r#"<string name="filter_type" value="{f}"/>"#));
                self.line(d + 1, &format!(r#"<string name="wrap_mode" value="{w}"/>"#));
                self.line(d + 1, r#"<boolean name="raw" value="true"/>"#);
                to_uv(self, a);
                self.line(d, "</texture>");
            }
            Texture::Checkerboard { color0, color1, to_uv: a } => {
                self.line(d, &format!(r#"<texture type="checkerboard" name="{name}">"#));
                self.line(d + 1, &format!(r#"<rgb name="color0" value="{}"/>"#, rgb(*color0)));
                self.line(d + 1, &format!(r#"<rgb name="color1" value="{}"/>"#, rgb(*color1)));
                to_uv(self, a);
                self.line(d, "</texture>");
            }
            Texture::Procedural(pt) => {
                // Mitsuba 3 has none of pbrt's procedural textures (nor a texture mix).
                let m = t.mean();
                self.files.warn(format!("{name}: pbrt's '{}' texture has no Mitsuba 3 equal: its mean {} is written as a constant", pt.pbrt_name(), rgb(m)));
                self.line(d, &format!(r#"<rgb name="{name}" value="{}"/>"#, rgb(m)));
            }
            Texture::MeshAttribute(_) | Texture::UnboundAttribute(_) => {
                self.files
                    .warn(format!("{name}: mesh_attribute textures are not exported (the meshes are written without their attributes): grey 0.5 is written"));
                self.line(d, &format!(r#"<rgb name="{name}" value="0.5"/>"#));
            }
        }
        Ok(())
    }

    fn roughness(&mut self, d: usize, r: &Roughness) -> Result<()> {
        let dist = match r.kind {
            MicrofacetKind::Beckmann => "beckmann",
            MicrofacetKind::Ggx => "ggx",
        };
        self.line(d, &format!(r#"<string name="distribution" value="{dist}"/>"#));
        self.scalar(d, "alpha_u", &r.alpha_u)?;
        self.scalar(d, "alpha_v", &r.alpha_v)
    }

    /// A `<bsdf>` element (with `id` at the top level).
    fn bsdf(&mut self, d: usize, m: &Material, id: Option<&str>) -> Result<()> {
        let id_attr = id.map(|i| format!(r#" id="{i}""#)).unwrap_or_default();
        let open = |w: &mut Self, ty: &str| w.line(d, &format!(r#"<bsdf type="{ty}"{id_attr}>"#));
        let ior = |w: &mut Self, eta: f32| {
            w.line(d + 1, &format!(r#"<float name="int_ior" value="{eta}"/>"#));
            w.line(d + 1, r#"<float name="ext_ior" value="1"/>"#);
        };
        match m {
            Material::Diffuse { reflectance } => {
                open(self, "diffuse");
                self.color(d + 1, "reflectance", reflectance)?;
            }
            Material::Conductor { eta, k, specular_reflectance, roughness } => {
                open(self, if roughness.is_some() { "roughconductor" } else { "conductor" });
                self.line(d + 1, &format!(r#"<rgb name="eta" value="{}"/>"#, rgb(*eta)));
                self.line(d + 1, &format!(r#"<rgb name="k" value="{}"/>"#, rgb(*k)));
                self.color(d + 1, "specular_reflectance", specular_reflectance)?;
                if let Some(r) = roughness {
                    self.roughness(d + 1, r)?;
                }
            }
            Material::Dielectric { eta, specular_reflectance, specular_transmittance, roughness } => {
                open(self, if roughness.is_some() { "roughdielectric" } else { "dielectric" });
                ior(self, *eta);
                self.color(d + 1, "specular_reflectance", specular_reflectance)?;
                self.color(d + 1, "specular_transmittance", specular_transmittance)?;
                if let Some(r) = roughness {
                    self.roughness(d + 1, r)?;
                }
            }
            Material::ThinDielectric { eta, specular_reflectance, specular_transmittance } => {
                open(self, "thindielectric");
                ior(self, *eta);
                self.color(d + 1, "specular_reflectance", specular_reflectance)?;
                self.color(d + 1, "specular_transmittance", specular_transmittance)?;
            }
            Material::Glass { eta, transmissivity } => {
                // Mitsuba 3 has no absorbing pane: its thindielectric with the normal
                // transmittance's share of a lossless pane's as the transmittance scale.
                self.files.warn("svetlo's glass is written as Mitsuba's thindielectric (no polarisation, absorption as a constant transmittance scale)");
                open(self, "thindielectric");
                ior(self, *eta);
                let scale = |t: f32| {
                    let pane = |tn: f32| crate::bsdf::glass::pane(1.0, *eta as f64, tn as f64).1;
                    (pane(t) / pane(1.0)) as f32
                };
                let s = Rgb::new(scale(transmissivity.r), scale(transmissivity.g), scale(transmissivity.b));
                self.line(d + 1, &format!(r#"<rgb name="specular_transmittance" value="{}"/>"#, rgb(s)));
            }
            Material::Plastic { diffuse_reflectance, specular_reflectance, eta, nonlinear, roughness } => {
                open(self, if roughness.is_some() { "roughplastic" } else { "plastic" });
                ior(self, *eta);
                self.color(d + 1, "diffuse_reflectance", diffuse_reflectance)?;
                self.color(d + 1, "specular_reflectance", specular_reflectance)?;
                self.line(d + 1, &format!(r#"<boolean name="nonlinear" value="{nonlinear}"/>"#));
                if let Some(r) = roughness {
                    self.roughness(d + 1, r)?;
                }
            }
            Material::TwoSided { front, back } => {
                open(self, "twosided");
                // One child when both sides are the same constant material (Debug is cheap
                // without bitmaps); both otherwise.
                self.bsdf(d + 1, front, None)?;
                let same = front.is_uniform() && back.is_uniform() && format!("{front:?}") == format!("{back:?}");
                if !same {
                    self.bsdf(d + 1, back, None)?;
                }
            }
            Material::Mask { opacity, inner } => {
                open(self, "mask");
                self.scalar(d + 1, "opacity", opacity)?;
                self.bsdf(d + 1, inner, None)?;
            }
            Material::Coated(c) => {
                // Mitsuba 3 has no stochastic layered BSDF: a plastic (or a conductor) stands in.
                match &c.base {
                    CoatedBase::Diffuse(t) => {
                        self.files.warn(format!(
                            "a pbrt-v4 coateddiffuse is written as Mitsuba's {} (no layered BSDF in Mitsuba 3; the coat's thickness and albedo are dropped)",
                            if c.roughness.is_some() { "roughplastic" } else { "plastic" }
                        ));
                        open(self, if c.roughness.is_some() { "roughplastic" } else { "plastic" });
                        ior(self, c.eta);
                        self.color(d + 1, "diffuse_reflectance", t)?;
                        if let Some(r) = &c.roughness {
                            self.roughness(d + 1, r)?;
                        }
                    }
                    CoatedBase::Conductor { eta, k, roughness } => {
                        self.files.warn("a pbrt-v4 coatedconductor is written as Mitsuba's conductor under no coat (no layered BSDF in Mitsuba 3)");
                        open(self, if roughness.is_some() { "roughconductor" } else { "conductor" });
                        self.line(d + 1, &format!(r#"<rgb name="eta" value="{}"/>"#, rgb(*eta / c.eta)));
                        self.line(d + 1, &format!(r#"<rgb name="k" value="{}"/>"#, rgb(*k / c.eta)));
                        if let Some(r) = roughness {
                            self.roughness(d + 1, r)?;
                        }
                    }
                }
            }
            Material::Mix { amount, a, b } => {
                open(self, "blendbsdf");
                self.scalar(d + 1, "weight", amount)?;
                self.bsdf(d + 1, a, None)?;
                self.bsdf(d + 1, b, None)?;
            }
            Material::DiffuseTransmission { reflectance, .. } => {
                self.files.warn("pbrt-v4's diffusetransmission has no Mitsuba 3 plugin: written as a diffuse of its reflectance (no transmission)");
                open(self, "diffuse");
                self.color(d + 1, "reflectance", reflectance)?;
            }
            Material::Null => open(self, "null"),
            Material::Principled(p) => {
                open(self, if p.thin { "principledthin" } else { "principled" });
                for (name, t) in p.textures() {
                    if name == "base_color" {
                        self.color(d + 1, name, t)?;
                    } else {
                        self.scalar(d + 1, name, t)?;
                    }
                }
                if !p.thin {
                    // Mitsuba's principled takes a constant IOR; `specular` was converted.
                    self.line(d + 1, &format!(r#"<float name="eta" value="{}"/>"#, p.eta.eval_f32(glam::Vec2::ZERO)));
                }
                let r = &p.rates;
                let rates: &[(&str, f32)] = if p.thin {
                    &[
                        ("diffuse_reflectance_sampling_rate", r.diffuse_reflection),
                        ("specular_reflectance_sampling_rate", r.specular),
                        ("specular_transmittance_sampling_rate", r.secondary),
                        ("diffuse_transmittance_sampling_rate", r.diffuse_transmission),
                    ]
                } else {
                    &[
                        ("diffuse_reflectance_sampling_rate", r.diffuse_reflection),
                        ("main_specular_sampling_rate", r.specular),
                        ("clearcoat_sampling_rate", r.secondary),
                    ]
                };
                for (name, v) in rates {
                    if *v != 1.0 {
                        self.line(d + 1, &format!(r#"<float name="{name}" value="{v}"/>"#));
                    }
                }
            }
            other => {
                self.files.warn(format!("material '{}' is svetlo's own (no Mitsuba 3 plugin): written as a grey diffuse", other.kind_name()));
                open(self, "diffuse");
            }
        }
        self.line(d, "</bsdf>");
        Ok(())
    }
}

pub(super) fn write(scene: &Scene, files: &mut Files) -> Result<String> {
    let mut w = Writer { files, out: String::new() };
    w.line(0, r#"<?xml version="1.0" encoding="utf-8"?>"#);
    w.line(0, "<!-- written by svetlo convert -->");
    w.line(0, r#"<scene version="3.0.0">"#);
    let s = &scene.settings;
    w.line(1, &format!(r#"<integrator type="{}">"#, esc(&s.integrator)));
    w.line(2, &format!(r#"<integer name="max_depth" value="{}"/>"#, s.max_depth));
    w.line(2, &format!(r#"<integer name="rr_depth" value="{}"/>"#, s.rr_depth));
    if s.hide_emitters {
        w.line(2, r#"<boolean name="hide_emitters" value="true"/>"#);
    }
    w.line(1, "</integrator>");

    let cam = &scene.camera;
    let (ty, extra) = match cam.projection {
        Projection::Perspective { fov_x_deg, aperture_radius, focus_distance } => {
            let mut e = format!(r#"<float name="fov" value="{fov_x_deg}"/><string name="fov_axis" value="x"/>"#);
            let _ = write!(e, r#"<float name="focus_distance" value="{focus_distance}"/>"#);
            if aperture_radius > 0.0 {
                let _ = write!(e, r#"<float name="aperture_radius" value="{aperture_radius}"/>"#);
                ("thinlens", e)
            } else {
                ("perspective", e)
            }
        }
        Projection::Orthographic => ("orthographic", String::new()),
    };
    w.line(1, &format!(r#"<sensor type="{ty}">"#));
    if !extra.is_empty() {
        w.line(2, &extra);
    }
    w.line(2, &format!(r#"<float name="near_clip" value="{}"/><float name="far_clip" value="{}"/>"#, cam.near_clip, cam.far_clip.min(1e30)));
    if cam.shutter_close > cam.shutter_open {
        w.line(2, &format!(r#"<float name="shutter_open" value="{}"/><float name="shutter_close" value="{}"/>"#, cam.shutter_open, cam.shutter_close));
    }
    w.line(2, &format!(r#"<transform name="to_world"><matrix value="{}"/></transform>"#, matrix(&cam.to_world)));
    let sampler = match s.sampler {
        SamplerKind::Independent => "independent",
        SamplerKind::Sobol => "sobol",
    };
    w.line(2, &format!(r#"<sampler type="{sampler}"><integer name="sample_count" value="{}"/><integer name="seed" value="{}"/></sampler>"#, s.spp, s.seed));
    w.line(2, r#"<film type="hdrfilm">"#);
    w.line(3, &format!(r#"<integer name="width" value="{}"/><integer name="height" value="{}"/>"#, cam.width, cam.height));
    w.line(
        3,
        &match s.filter {
            Filter::Box => r#"<rfilter type="box"/>"#.to_string(),
            Filter::Tent { radius } => format!(r#"<rfilter type="tent"><float name="radius" value="{radius}"/></rfilter>"#),
            Filter::Gaussian { stddev } => format!(r#"<rfilter type="gaussian"><float name="stddev" value="{stddev}"/></rfilter>"#),
        },
    );
    w.line(2, "</film>");
    w.line(1, "</sensor>");

    // Materials that shapes use, by index.
    let mut used = vec![false; scene.materials.len()];
    for sh in &scene.shapes {
        if let Some(u) = used.get_mut(sh.material as usize) {
            *u = true;
        }
    }
    for (i, m) in scene.materials.iter().enumerate() {
        if used[i] {
            w.bsdf(1, m, Some(&format!("mat{i}")))?;
        }
    }

    for sh in &scene.shapes {
        if matches!(&*sh.geometry, Geometry::SdfGrid(_)) {
            w.files.warn(format!("shape '{}': SDF grids are not exported; shape left out", sh.name));
            continue;
        }
        if sh.motion.is_some() {
            w.files.warn(format!("shape '{}' moves: written at its first pose (motion is not exported)", sh.name));
        }
        match &*sh.geometry {
            Geometry::Mesh(m) => {
                let file = w.files.mesh(m)?;
                w.line(1, r#"<shape type="ply">"#);
                w.line(2, &format!(r#"<string name="filename" value="{}"/>"#, esc(&file)));
                w.line(2, r#"<boolean name="flip_tex_coords" value="false"/>"#);
                if !super::has_normals(m) {
                    w.line(2, r#"<boolean name="face_normals" value="true"/>"#);
                }
            }
            Geometry::Sphere(sp) => {
                w.line(1, r#"<shape type="sphere">"#);
                w.line(2, &format!(r#"<point name="center" x="{}" y="{}" z="{}"/>"#, sp.center.x, sp.center.y, sp.center.z));
                w.line(2, &format!(r#"<float name="radius" value="{}"/>"#, sp.radius));
                if sp.flip_normals {
                    w.line(2, r#"<boolean name="flip_normals" value="true"/>"#);
                }
            }
            Geometry::SdfGrid(_) => {}
        }
        w.line(2, &format!(r#"<ref id="mat{}"/>"#, sh.material));
        if let Some(Light::Area(a)) = sh.light.and_then(|l| scene.lights.get(l as usize)) {
            w.line(2, r#"<emitter type="area">"#);
            w.color(3, "radiance", &a.radiance)?;
            w.line(2, "</emitter>");
        }
        w.line(1, "</shape>");
    }

    for l in &scene.lights {
        match l {
            Light::Area(_) => {}
            Light::Point { position: p, intensity } => {
                w.line(1, r#"<emitter type="point">"#);
                w.line(2, &format!(r#"<point name="position" x="{}" y="{}" z="{}"/>"#, p.x, p.y, p.z));
                w.line(2, &format!(r#"<rgb name="intensity" value="{}"/>"#, rgb(*intensity)));
                w.line(1, "</emitter>");
            }
            Light::Spot { position, frame, intensity, cutoff_angle, beam_width, texture, .. } => {
                let m = Mat4::from_cols(frame.s.extend(0.0), frame.t.extend(0.0), frame.n.extend(0.0), position.extend(1.0));
                w.line(1, r#"<emitter type="spot">"#);
                w.line(2, &format!(r#"<transform name="to_world"><matrix value="{}"/></transform>"#, matrix(&m)));
                w.line(2, &format!(r#"<rgb name="intensity" value="{}"/>"#, rgb(*intensity)));
                w.line(2, &format!(r#"<float name="cutoff_angle" value="{}"/>"#, cutoff_angle.to_degrees()));
                w.line(2, &format!(r#"<float name="beam_width" value="{}"/>"#, beam_width.to_degrees()));
                if let Some(t) = texture {
                    w.texture(2, "texture", t)?;
                }
                w.line(1, "</emitter>");
            }
            Light::Directional { direction: d, irradiance } => {
                w.line(1, r#"<emitter type="directional">"#);
                w.line(2, &format!(r#"<vector name="direction" x="{}" y="{}" z="{}"/>"#, d.x, d.y, d.z));
                w.line(2, &format!(r#"<rgb name="irradiance" value="{}"/>"#, rgb(*irradiance)));
                w.line(1, "</emitter>");
            }
            Light::Constant { radiance } => {
                w.line(1, r#"<emitter type="constant">"#);
                w.line(2, &format!(r#"<rgb name="radiance" value="{}"/>"#, rgb(*radiance)));
                w.line(1, "</emitter>");
            }
            Light::EnvMap(e) => {
                let file = w.files.image(&e.image)?;
                w.line(1, r#"<emitter type="envmap">"#);
                w.line(2, &format!(r#"<string name="filename" value="{}"/>"#, esc(&file)));
                w.line(2, &format!(r#"<float name="scale" value="{}"/>"#, e.scale));
                w.line(2, &format!(r#"<transform name="to_world"><matrix value="{}"/></transform>"#, matrix(&e.to_world)));
                w.line(1, "</emitter>");
            }
            Light::Projector(pr) => {
                let (iw, ih) = match &pr.irradiance {
                    Texture::Bitmap { image, .. } => (image.width, image.height),
                    _ => (0, 0),
                };
                w.line(1, r#"<emitter type="projector">"#);
                w.line(2, &format!(r#"<transform name="to_world"><matrix value="{}"/></transform>"#, matrix(&pr.to_world())));
                w.line(2, &format!(r#"<float name="fov" value="{}"/>"#, pr.fov_x_deg()));
                w.line(2, r#"<string name="fov_axis" value="x"/>"#);
                w.line(2, &format!(r#"<float name="scale" value="{}"/>"#, pr.scale));
                if pr.model == ProjectorModel::Intensity && iw > 0 {
                    w.files.warn("pbrt's projection light (the image is the intensity) is written as Mitsuba's projector with the irradiance image P cos³θ / π at texel centres (nearest texels, as pbrt)");
                    let image = std::sync::Arc::new(pr.image_for(ProjectorModel::Irradiance, iw, ih));
                    let t = Texture::Bitmap { image, filter: FilterMode::Nearest, wrap: WrapMode::Clamp, to_uv: Affine2::IDENTITY };
                    w.texture(2, "irradiance", &t)?;
                } else {
                    w.texture(2, "irradiance", &pr.irradiance)?;
                }
                w.line(1, "</emitter>");
            }
            Light::Goniometric(g) => {
                // Mitsuba 3 has no goniometric light: a point light of the same power.
                w.files.warn(
                    "Mitsuba 3 has no goniometric light: written as a point light of the same power (its mean intensity); the directional distribution is lost",
                );
                let i = g.intensity * (g.solid_angle_weight() / (4.0 * crate::math::PI));
                let p = g.position;
                w.line(1, r#"<emitter type="point">"#);
                w.line(2, &format!(r#"<point name="position" x="{}" y="{}" z="{}"/>"#, p.x, p.y, p.z));
                w.line(2, &format!(r#"<rgb name="intensity" value="{}"/>"#, rgb(i)));
                w.line(1, "</emitter>");
            }
            Light::Luminaire(_) => w.files.warn("an ies luminaire is not exported yet (its photometric file is not carried over); left out"),
        }
    }
    w.line(0, "</scene>");
    Ok(w.out)
}
