//! The scene as a pbrt-v4 file, written so that svetlo's pbrt reader (and pbrt-v4) read it
//! back as the same scene: the inverse of each mapping in `io/pbrt/` (camera handedness,
//! fov on the shorter axis, maxdepth in bounces, uv conventions of textures).

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
use crate::texture::{Bitmap, FilterMode, Mapping2D, Procedural, Texture, WrapMode};
use glam::{Affine2, Mat4, Vec2, Vec3};
use std::fmt::Write as _;
use std::sync::Arc;

/// Side of the equal-area square an environment map is resampled to, at most.
const MAX_ENVMAP_SIDE: usize = 1024;

fn q(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "/").replace('"', ""))
}

fn rgb(c: Rgb) -> String {
    format!("[ {} {} {} ]", c.r, c.g, c.b)
}

fn cols(m: &Mat4) -> String {
    m.to_cols_array().iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" ")
}

struct Writer<'a> {
    files: &'a mut Files,
    out: String,
    textures: usize,
    /// Named materials written for the parts of mixes.
    parts: usize,
    /// Warnings already given once (per kind).
    said: std::collections::HashSet<&'static str>,
}

impl Writer<'_> {
    fn once(&mut self, key: &'static str, msg: &str) {
        if self.said.insert(key) {
            self.files.warn(msg);
        }
    }

    /// pbrt's uv mapping (uscale, vscale, udelta, vdelta) for svetlo's lookup transform: the
    /// inverse of the reader's `uv_mapping` (pbrt's t runs up the image, svetlo's v down).
    fn uv_params(&mut self, a: &Affine2) -> String {
        let m = a.matrix2;
        if m.x_axis.y != 0.0 || m.y_axis.x != 0.0 {
            self.once("uvrot", "a rotated or sheared texture transform has no pbrt-v4 uv mapping: its scale is kept");
        }
        let (su, sv, du, dv) = (m.x_axis.x, -m.y_axis.y, a.translation.x, 1.0 - a.translation.y);
        format!(r#""float uscale" {su} "float vscale" {sv} "float udelta" {du} "float vdelta" {dv}"#)
    }

    /// Define a named texture; its name.
    fn texture(&mut self, t: &Texture, float: bool) -> Result<String> {
        let name = format!("tex{}", self.textures);
        self.textures += 1;
        let kind = if float { "float" } else { "spectrum" };
        let (body, ctm) = self.texture_body(t, float)?;
        if let Some(m) = ctm {
            // The texture space is the CTM at the directive.
            let _ = writeln!(self.out, "AttributeBegin\n  Transform [ {} ]\n  Texture \"{name}\" \"{kind}\" {body}\nAttributeEnd", cols(&m));
        } else {
            let _ = writeln!(self.out, "Texture \"{name}\" \"{kind}\" {body}");
        }
        Ok(name)
    }

    /// A texture's class and parameters, and the texture space it needs (world from texture).
    fn texture_body(&mut self, t: &Texture, float: bool) -> Result<(String, Option<Mat4>)> {
        let body = match t {
            Texture::Constant(c) => {
                if float {
                    format!(r#""constant" "float value" {}"#, c.r)
                } else {
                    format!(r#""constant" "rgb value" {}"#, rgb(*c))
                }
            }
            Texture::Bitmap { image, filter, wrap, to_uv } => {
                let file = self.files.image(image)?;
                let wrap = match wrap {
                    WrapMode::Repeat => "repeat",
                    WrapMode::Clamp => "clamp",
                    WrapMode::Mirror => {
                        self.once("mirror", "pbrt-v4 has no mirrored texture wrap: 'repeat' is written");
                        "repeat"
                    }
                };
                let filter = match filter {
                    FilterMode::Nearest => "point",
                    FilterMode::Bilinear => "bilinear",
                };
                let uv = self.uv_params(to_uv);
                format!(r#""imagemap" "string filename" {} "string encoding" "linear" "string wrap" "{wrap}" "string filter" "{filter}" {uv}"#, q(&file))
            }
            Texture::Checkerboard { color0, color1, to_uv } => {
                // The reader scales pbrt's unit checks to svetlo's half-unit cells.
                let uv = self.uv_params(&(Affine2::from_scale(Vec2::splat(2.0)) * *to_uv));
                if float {
                    format!(r#""checkerboard" "float tex1" {} "float tex2" {} {uv}"#, color0.r, color1.r)
                } else {
                    format!(r#""checkerboard" "rgb tex1" {} "rgb tex2" {} {uv}"#, rgb(*color0), rgb(*color1))
                }
            }
            Texture::Procedural(pt) => return self.procedural(pt, float),
            Texture::MeshAttribute(_) | Texture::UnboundAttribute(_) => {
                self.once(
                    "mesh_attribute",
                    "mesh_attribute textures have no pbrt-v4 form here (the meshes are written without their attributes): grey 0.5 is written",
                );
                if float {
                    r#""constant" "float value" 0.5"#.to_string()
                } else {
                    r#""constant" "rgb value" [0.5 0.5 0.5]"#.to_string()
                }
            }
        };
        Ok((body, None))
    }

    /// A 2-D mapping's parameters, and the texture space (world from texture) it needs.
    fn mapping(m: &Mapping2D) -> (String, Option<Mat4>) {
        match m {
            Mapping2D::Uv { su, sv, du, dv } => (format!(r#""float uscale" {su} "float vscale" {sv} "float udelta" {du} "float vdelta" {dv}"#), None),
            Mapping2D::Spherical { world_to_texture } => (r#""string mapping" "spherical""#.to_string(), Some(world_to_texture.inverse())),
            Mapping2D::Cylindrical { world_to_texture } => (r#""string mapping" "cylindrical""#.to_string(), Some(world_to_texture.inverse())),
            Mapping2D::Planar { world_to_texture, v1, v2, ds, dt } => (
                format!(
                    r#""string mapping" "planar" "vector3 v1" [ {} {} {} ] "vector3 v2" [ {} {} {} ] "float udelta" {ds} "float vdelta" {dt}"#,
                    v1.x, v1.y, v1.z, v2.x, v2.y, v2.z
                ),
                Some(world_to_texture.inverse()),
            ),
        }
    }

    /// A texture parameter `name` of a float or spectrum texture.
    fn param(&mut self, name: &str, t: &Texture, float: bool) -> Result<String> {
        if float {
            self.scalar(name, t)
        } else {
            self.color(name, t)
        }
    }

    /// pbrt's own procedural textures: the body of the `Texture` line, and its texture space.
    fn procedural(&mut self, pt: &Procedural, float: bool) -> Result<(String, Option<Mat4>)> {
        let val = |c: Rgb| if float { format!("{}", c.r) } else { rgb(c) };
        let ty = if float { "float" } else { "rgb" };
        Ok(match pt {
            Procedural::Bilerp { mapping, v00, v01, v10, v11 } => {
                let (m, ctm) = Self::mapping(mapping);
                (format!(r#""bilerp" "{ty} v00" {} "{ty} v01" {} "{ty} v10" {} "{ty} v11" {} {m}"#, val(*v00), val(*v01), val(*v10), val(*v11)), ctm)
            }
            Procedural::DirectionMix { tex1, tex2, dir } => {
                let (a, b) = (self.param("tex1", tex1, float)?, self.param("tex2", tex2, float)?);
                (format!(r#""directionmix" {a} {b} "vector3 dir" [ {} {} {} ]"#, dir.x, dir.y, dir.z), None)
            }
            Procedural::Dots { mapping, inside, outside } => {
                let (a, b) = (self.param("inside", inside, float)?, self.param("outside", outside, float)?);
                let (m, ctm) = Self::mapping(mapping);
                (format!(r#""dots" {a} {b} {m}"#), ctm)
            }
            Procedural::Fbm { world_to_texture, omega, octaves } => {
                (format!(r#""fbm" "float roughness" {omega} "integer octaves" {octaves}"#), Some(world_to_texture.inverse()))
            }
            Procedural::Wrinkled { world_to_texture, omega, octaves } => {
                (format!(r#""wrinkled" "float roughness" {omega} "integer octaves" {octaves}"#), Some(world_to_texture.inverse()))
            }
            Procedural::Windy { world_to_texture } => (r#""windy""#.to_string(), Some(world_to_texture.inverse())),
            Procedural::Marble { world_to_texture, omega, octaves, scale, variation } => (
                format!(r#""marble" "float roughness" {omega} "integer octaves" {octaves} "float scale" {scale} "float variation" {variation}"#),
                Some(world_to_texture.inverse()),
            ),
            Procedural::Mix { tex1, tex2, amount } => {
                let (a, b, c) = (self.param("tex1", tex1, float)?, self.param("tex2", tex2, float)?, self.scalar("amount", amount)?);
                (format!(r#""mix" {a} {b} {c}"#), None)
            }
            Procedural::Scale { tex, scale } => {
                let (a, b) = (self.param("tex", tex, float)?, self.scalar("scale", scale)?);
                (format!(r#""scale" {a} {b}"#), None)
            }
            Procedural::Mapped { mapping, inner } => {
                // The inner texture's own uv transform is pbrt's identity uv mapping (the
                // reader's flip); the mapping's parameters replace it.
                let (body, _) = self.texture_body(inner, float)?;
                let identity = Affine2::from_mat2_translation(glam::Mat2::from_diagonal(Vec2::new(1.0, -1.0)), Vec2::new(0.0, 1.0));
                let id = self.uv_params(&identity);
                let (m, ctm) = Self::mapping(mapping);
                (body.replace(&id, &m), ctm)
            }
        })
    }

    fn color(&mut self, name: &str, t: &Texture) -> Result<String> {
        Ok(match t {
            Texture::Constant(c) => format!(r#""rgb {name}" {}"#, rgb(*c)),
            _ => format!(r#""texture {name}" "{}""#, self.texture(t, false)?),
        })
    }

    fn scalar(&mut self, name: &str, t: &Texture) -> Result<String> {
        Ok(match t {
            Texture::Constant(c) => format!(r#""float {name}" {}"#, c.r),
            _ => format!(r#""texture {name}" "{}""#, self.texture(t, true)?),
        })
    }

    fn roughness(&mut self, prefix: &str, r: &Option<Roughness>) -> Result<String> {
        let Some(r) = r else { return Ok(format!(r#""float {prefix}roughness" 0"#)) };
        if r.kind == MicrofacetKind::Beckmann {
            self.once("beckmann", "pbrt-v4 has only the GGX (Trowbridge-Reitz) microfacet distribution: Beckmann lobes are written as GGX of the same alpha");
        }
        Ok(format!("{} {}", self.scalar(&format!("{prefix}uroughness"), &r.alpha_u)?, self.scalar(&format!("{prefix}vroughness"), &r.alpha_v)?))
    }

    fn white(&mut self, what: &str, t: &Texture) {
        if !matches!(t, Texture::Constant(c) if *c == Rgb::WHITE) {
            self.files.warn(format!("pbrt-v4 has no '{what}' scale: it is dropped"));
        }
    }

    /// The parameters of a material ("string type" first), and the opacity of a mask (pbrt's
    /// shape `alpha`).
    fn material(&mut self, m: &Material) -> Result<(String, Option<Texture>)> {
        let s = match m {
            Material::Diffuse { reflectance } => format!(r#""string type" "diffuse" {}"#, self.color("reflectance", reflectance)?),
            Material::Conductor { eta, k, specular_reflectance, roughness } => {
                self.white("specular_reflectance", specular_reflectance);
                let r = self.roughness("", roughness)?;
                format!(r#""string type" "conductor" "rgb eta" {} "rgb k" {} {r} "bool remaproughness" false"#, rgb(*eta), rgb(*k))
            }
            Material::Dielectric { eta, specular_reflectance, specular_transmittance, roughness } => {
                self.white("specular_reflectance", specular_reflectance);
                self.white("specular_transmittance", specular_transmittance);
                let r = self.roughness("", roughness)?;
                format!(r#""string type" "dielectric" "float eta" {eta} {r} "bool remaproughness" false"#)
            }
            Material::ThinDielectric { eta, specular_reflectance, specular_transmittance } => {
                self.white("specular_reflectance", specular_reflectance);
                self.white("specular_transmittance", specular_transmittance);
                format!(r#""string type" "thindielectric" "float eta" {eta}"#)
            }
            Material::Glass { eta, .. } => {
                self.once("glass", "svetlo's glass is written as pbrt-v4's thindielectric (no absorption, no polarisation)");
                format!(r#""string type" "thindielectric" "float eta" {eta}"#)
            }
            Material::Plastic { diffuse_reflectance, specular_reflectance, eta, roughness, .. } => {
                self.once(
                    "plastic",
                    "Mitsuba's plastic has no pbrt-v4 equal: it is written as coateddiffuse (a layered model with its own internal scattering)",
                );
                self.white("specular_reflectance", specular_reflectance);
                let r = self.roughness("", roughness)?;
                format!(
                    r#""string type" "coateddiffuse" {} "float eta" {eta} {r} "bool remaproughness" false"#,
                    self.color("reflectance", diffuse_reflectance)?
                )
            }
            Material::TwoSided { front, back } => {
                if front.kind_name() != back.kind_name() {
                    self.files.warn(format!(
                        "pbrt-v4 materials are the same on both sides: twosided({}, {}) is written as its front",
                        front.kind_name(),
                        back.kind_name()
                    ));
                }
                return self.material(front);
            }
            Material::Mask { opacity, inner } => {
                let (s, _) = self.material(inner)?;
                return Ok((s, Some(opacity.clone())));
            }
            Material::Coated(c) => {
                let (ty, pre) = match c.base {
                    CoatedBase::Diffuse(_) => ("coateddiffuse", ""),
                    CoatedBase::Conductor { .. } => ("coatedconductor", "interface."),
                };
                let mut s = format!(r#""string type" "{ty}" "float {pre}eta" {} {}"#, c.eta, self.roughness(pre, &c.roughness)?);
                match &c.base {
                    CoatedBase::Diffuse(t) => s += &format!(" {}", self.color("reflectance", t)?),
                    CoatedBase::Conductor { eta, k, roughness } => {
                        s += &format!(r#" "rgb conductor.eta" {} "rgb conductor.k" {} {}"#, rgb(*eta), rgb(*k), self.roughness("conductor.", roughness)?)
                    }
                }
                let _ = write!(
                    s,
                    r#" "float thickness" {} "rgb albedo" {} "float g" {} "integer maxdepth" {} "integer nsamples" {} "bool remaproughness" false"#,
                    c.thickness,
                    rgb(c.albedo),
                    c.g,
                    c.max_depth,
                    c.n_samples
                );
                s
            }
            Material::DiffuseTransmission { reflectance, transmittance } => {
                format!(r#""string type" "diffusetransmission" {} {}"#, self.color("reflectance", reflectance)?, self.color("transmittance", transmittance)?)
            }
            Material::Mix { amount, a, b } => {
                // The parts as named materials of their own, defined first.
                let mut names = Vec::new();
                for part in [a, b] {
                    let (params, _) = self.material(part)?;
                    let name = format!("part{}", self.parts);
                    self.parts += 1;
                    let _ = writeln!(self.out, "MakeNamedMaterial \"{name}\" {params}");
                    names.push(name);
                }
                format!(r#""string type" "mix" "string materials" [ "{}" "{}" ] {}"#, names[0], names[1], self.scalar("amount", amount)?)
            }
            Material::Null => r#""string type" "interface""#.to_string(),
            Material::Principled(p) => {
                // pbrt-v4 has no Disney BSDF: its diffuse base is what carries over best.
                self.files.warn(format!(
                    "Mitsuba's {} has no pbrt-v4 equal: written as a diffuse of its base_color (specular, sheen, clearcoat and transmission are dropped)",
                    if p.thin { "principledthin" } else { "principled" }
                ));
                format!(r#""string type" "diffuse" {}"#, self.color("reflectance", &p.base_color)?)
            }
            other => {
                self.files.warn(format!("material '{}' has no pbrt-v4 equal: written as a grey diffuse", other.kind_name()));
                r#""string type" "diffuse""#.to_string()
            }
        };
        Ok((s, None))
    }

    /// An environment map resampled to pbrt-v4's equal-area square, in the light's frame.
    fn envmap(&mut self, e: &crate::light::EnvMap) -> Result<String> {
        let n = (e.image.height.next_power_of_two()).clamp(16, MAX_ENVMAP_SIDE);
        let scale = if e.scale > 0.0 { e.scale } else { 1.0 };
        let mut data = Vec::with_capacity(n * n);
        for y in 0..n {
            for x in 0..n {
                let uv = Vec2::new((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
                let local = crate::io::pbrt::camera::equal_area_square_to_sphere(uv);
                let world = e.to_world.transform_vector3(local).normalize_or_zero();
                data.push(e.eval(world) / scale);
            }
        }
        self.once("envmap", "environment maps are resampled to pbrt-v4's equal-area octahedral parameterisation (not bit-exact)");
        self.files.image(&Arc::new(Bitmap::new(n, n, data)))
    }
}

pub(super) fn write(scene: &Scene, files: &mut Files) -> Result<String> {
    let mut w = Writer { files, out: String::new(), textures: 0, parts: 0, said: Default::default() };
    w.out += "# written by svetlo convert\n";
    let cam = &scene.camera;
    let aspect = cam.width as f32 / cam.height as f32;
    // The reader: camera to world = inverse(CTM) · diag(-1, 1, 1) (pbrt's +x is the image's
    // right, svetlo's its left), and an orthographic film scaled by its screen window.
    let (camera_to_world, params) = match cam.projection {
        Projection::Perspective { fov_x_deg, aperture_radius, focus_distance } => {
            let t = (0.5 * fov_x_deg.to_radians()).tan();
            let fov = if aspect > 1.0 { 2.0 * (t / aspect).atan().to_degrees() } else { fov_x_deg };
            let mut s = format!(r#""perspective" "float fov" {fov}"#);
            if aperture_radius > 0.0 {
                let _ = write!(s, r#" "float lensradius" {aperture_radius} "float focaldistance" {focus_distance}"#);
            }
            (cam.to_world, s)
        }
        Projection::Orthographic => {
            let sx = cam.to_world.x_axis.truncate().length();
            let unscaled = cam.to_world * Mat4::from_scale(Vec3::new(1.0 / sx, 1.0 / sx, 1.0));
            (unscaled, format!(r#""orthographic" "float screenwindow" [ {} {} {} {} ]"#, -sx, sx, -sx / aspect, sx / aspect))
        }
    };
    let ctm = (camera_to_world * Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0))).inverse();
    let _ = writeln!(w.out, "Transform [ {} ]", cols(&ctm));
    let _ = writeln!(w.out, "Camera {params}");
    if cam.shutter_close > cam.shutter_open {
        w.once("shutter", "the camera's shutter interval is not exported (motion is not exported)");
    }
    let _ = writeln!(w.out, r#"Film "rgb" "integer xresolution" {} "integer yresolution" {} "string filename" "render.exr""#, cam.width, cam.height);
    let s = &scene.settings;
    let _ = writeln!(
        w.out,
        "PixelFilter {}",
        match s.filter {
            Filter::Box => r#""box" "float xradius" 0.5 "float yradius" 0.5"#.to_string(),
            Filter::Tent { radius } => format!(r#""triangle" "float xradius" {radius} "float yradius" {radius}"#),
            Filter::Gaussian { stddev } => format!(r#""gaussian" "float sigma" {stddev} "float xradius" {r} "float yradius" {r}"#, r = 3.0 * stddev),
        }
    );
    let sampler = match s.sampler {
        SamplerKind::Independent => "independent",
        SamplerKind::Sobol => "zsobol",
    };
    let _ = writeln!(w.out, r#"Sampler "{sampler}" "integer pixelsamples" {} "integer seed" {}"#, s.spp, s.seed);
    let integrator = match s.integrator.as_str() {
        "path" => "path",
        "bdpt" => "bdpt",
        "pssmlt" | "mlt" => "mlt",
        "sppm" => "sppm",
        "light" | "ptracer" => "lightpath",
        other => {
            w.files.warn(format!("integrator '{other}' has no pbrt-v4 equal: 'path' is written"));
            "path"
        }
    };
    // pbrt counts bounces: svetlo's depth (segments) - 1; unbounded stays -1.
    let maxdepth = if s.max_depth < 0 { -1 } else { s.max_depth - 1 };
    let _ = writeln!(w.out, r#"Integrator "{integrator}" "integer maxdepth" {maxdepth}"#);
    w.out += "\nWorldBegin\n\n";

    for l in &scene.lights {
        match l {
            Light::Area(_) => {}
            Light::Point { position: p, intensity } => {
                let _ = writeln!(w.out, r#"LightSource "point" "rgb I" {} "point3 from" [ {} {} {} ]"#, rgb(*intensity), p.x, p.y, p.z);
            }
            Light::Spot { position: p, frame, intensity, cutoff_angle, beam_width, texture, .. } => {
                if texture.is_some() {
                    w.files.warn("a spot light's projected texture has no pbrt-v4 equal: left out");
                }
                w.once("spot", "spot lights: pbrt-v4 falls off by smoothstep, svetlo (Mitsuba) linearly in angle; the cone angles are kept");
                let to = *p + frame.n;
                let (cone, beam) = (cutoff_angle.to_degrees(), beam_width.to_degrees());
                let _ = writeln!(
                    w.out,
                    r#"LightSource "spot" "rgb I" {} "point3 from" [ {} {} {} ] "point3 to" [ {} {} {} ] "float coneangle" {cone} "float conedelta" {}"#,
                    rgb(*intensity),
                    p.x,
                    p.y,
                    p.z,
                    to.x,
                    to.y,
                    to.z,
                    cone - beam
                );
            }
            Light::Directional { direction: d, irradiance } => {
                let _ =
                    writeln!(w.out, r#"LightSource "distant" "rgb L" {} "point3 from" [ 0 0 0 ] "point3 to" [ {} {} {} ]"#, rgb(*irradiance), d.x, d.y, d.z);
            }
            Light::Constant { radiance } => {
                let _ = writeln!(w.out, r#"LightSource "infinite" "rgb L" {}"#, rgb(*radiance));
            }
            Light::EnvMap(e) => {
                let file = w.envmap(e)?;
                let _ = writeln!(w.out, "AttributeBegin\n  ConcatTransform [ {} ]", cols(&e.to_world));
                let _ = writeln!(w.out, r#"  LightSource "infinite" "string filename" {} "float scale" {}"#, q(&file), e.scale);
                w.out += "AttributeEnd\n";
            }
            Light::Projector(pr) => {
                // pbrt's projection: image = intensity / scale; its frame is the projector's
                // with x negated; fov across the shorter axis.
                let (iw, ih) = match &pr.irradiance {
                    Texture::Bitmap { image, .. } => (image.width, image.height),
                    _ => ((64.0 * pr.aspect().max(1.0)).round() as usize, (64.0 / pr.aspect().min(1.0)).round() as usize),
                };
                if pr.model == ProjectorModel::Irradiance {
                    w.once("projector", "Mitsuba's projector (irradiance E, I = π E / cos³θ) is written as pbrt's projection with the intensity image π E / cos³θ at texel centres (pbrt looks it up nearest)");
                }
                let img = Arc::new(pr.image_for(ProjectorModel::Intensity, iw.max(1), ih.max(1)));
                let file = w.files.image(&img)?;
                let tan_short = (0.5 * pr.fov_x_deg().to_radians()).tan() / pr.aspect().max(1.0);
                let fov = 2.0 * tan_short.atan().to_degrees();
                let ctm = pr.to_world() * Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
                let _ = writeln!(w.out, "AttributeBegin\n  ConcatTransform [ {} ]", cols(&ctm));
                let _ = writeln!(w.out, r#"  LightSource "projection" "string filename" {} "float fov" {fov} "float scale" {}"#, q(&file), pr.scale);
                w.out += "AttributeEnd\n";
            }
            Light::Goniometric(g) => {
                // The reader composes CTM · swapYZ; swapYZ is its own inverse.
                let ctm = g.to_world() * crate::light::Goniometric::pbrt_swap_yz();
                let img = Arc::new(Bitmap::new(g.res, g.res, g.values.iter().map(|&v| Rgb::splat(v)).collect()));
                let file = w.files.image(&img)?;
                let _ = writeln!(w.out, "AttributeBegin\n  ConcatTransform [ {} ]", cols(&ctm));
                let _ = writeln!(w.out, r#"  LightSource "goniometric" "rgb I" {} "string filename" {}"#, rgb(g.intensity), q(&file));
                w.out += "AttributeEnd\n";
            }
            Light::Luminaire(_) => w.files.warn("an ies luminaire is not exported yet (its photometric file is not carried over); left out"),
        }
    }

    // Materials that shapes use, by index.
    let mut used = vec![false; scene.materials.len()];
    for sh in &scene.shapes {
        if let Some(u) = used.get_mut(sh.material as usize) {
            *u = true;
        }
    }
    let mut alpha: Vec<Option<Texture>> = vec![None; scene.materials.len()];
    for (i, m) in scene.materials.iter().enumerate() {
        if !used[i] {
            continue;
        }
        if !matches!(
            m,
            Material::TwoSided { .. }
                | Material::Dielectric { .. }
                | Material::ThinDielectric { .. }
                | Material::Glass { .. }
                | Material::DiffuseTransmission { .. }
                | Material::Null
                | Material::Mask { .. }
        ) {
            w.once("onesided", "Mitsuba's one-sided BSDFs become pbrt-v4's, which scatter alike on both sides");
        }
        let (params, a) = w.material(m)?;
        alpha[i] = a;
        let _ = writeln!(w.out, "MakeNamedMaterial \"mat{i}\" {params}");
    }
    w.out += "\n";

    for sh in &scene.shapes {
        if matches!(&*sh.geometry, Geometry::SdfGrid(_)) {
            w.files.warn(format!("shape '{}': pbrt-v4 has no SDF grid shape; shape left out", sh.name));
            continue;
        }
        if sh.motion.is_some() {
            w.files.warn(format!("shape '{}' moves: written at its first pose (motion is not exported)", sh.name));
        }
        let alpha_param = match alpha.get(sh.material as usize).cloned().flatten() {
            Some(t) => format!(" {}", w.scalar("alpha", &t)?),
            None => String::new(),
        };
        w.out += "AttributeBegin\n";
        let _ = writeln!(w.out, "  NamedMaterial \"mat{}\"", sh.material);
        if let Some(Light::Area(a)) = sh.light.and_then(|l| scene.lights.get(l as usize)) {
            let radiance = match &a.radiance {
                Texture::Constant(c) => *c,
                t => {
                    w.files.warn(format!("shape '{}': a textured emitter is written with its mean radiance", sh.name));
                    t.mean()
                }
            };
            let _ = writeln!(w.out, r#"  AreaLightSource "diffuse" "rgb L" {}"#, rgb(radiance));
        }
        match &*sh.geometry {
            Geometry::Mesh(m) => {
                let file = w.files.mesh(m)?;
                let _ = writeln!(w.out, r#"  Shape "plymesh" "string filename" {}{alpha_param}"#, q(&file));
            }
            Geometry::Sphere(sp) => {
                let _ = writeln!(w.out, "  Translate {} {} {}", sp.center.x, sp.center.y, sp.center.z);
                if sp.flip_normals {
                    w.out += "  ReverseOrientation\n";
                }
                let _ = writeln!(w.out, r#"  Shape "sphere" "float radius" {}{alpha_param}"#, sp.radius);
            }
            Geometry::SdfGrid(_) => {}
        }
        w.out += "AttributeEnd\n";
    }
    Ok(w.out)
}
