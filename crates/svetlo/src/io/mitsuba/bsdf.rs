//! BSDF plugins -> [`Material`].

use super::xml::Node;
use super::Loader;
use crate::bsdf::material::{MicrofacetKind, Roughness};
use crate::bsdf::principled::{eta_from_specular, PrincipledMaterial, SamplingRates};
use crate::bsdf::Material;
use crate::error::Result;
use crate::io::spectra::{self, SpectrumKind};
use crate::spectrum::Rgb;
use crate::texture::Texture;

impl<'a> Loader<'a> {
    /// The material index of a `<bsdf>` element; one with an id is built once and shared.
    pub(super) fn material_index(&mut self, node: &'a Node) -> Result<u32> {
        if let Some(id) = node.id() {
            if let Some(&i) = self.materials_by_id.get(id) {
                return Ok(i);
            }
        }
        let m = self.bsdf(node)?;
        let i = self.b.add_material(m);
        if let Some(id) = node.id() {
            self.materials_by_id.insert(id, i);
        }
        Ok(i)
    }

    /// Mitsuba's default when a shape has no BSDF: diffuse, reflectance 0.5.
    pub(super) fn default_material(&mut self) -> u32 {
        *self.default_material.get_or_insert_with(|| self.b.add_material(Material::default()))
    }

    /// Nested BSDFs of a BSDF (inline or by reference).
    fn child_bsdfs(&self, node: &'a Node) -> Result<Vec<&'a Node>> {
        let mut out = Vec::new();
        for c in &node.children {
            match c.tag.as_str() {
                "bsdf" => out.push(c),
                // Named or not (`<ref name="bsdf_0" id=..>`): the target's kind decides.
                "ref" => {
                    let t = self.lookup(c)?;
                    if t.tag == "bsdf" {
                        out.push(t);
                    }
                }
                _ => {}
            }
        }
        Ok(out)
    }

    /// The texture nested in a BSDF whatever its name (bumpmap's height), inline or by reference.
    fn nested_texture(&self, node: &'a Node) -> Result<Option<&'a Node>> {
        for c in &node.children {
            let t = match c.tag.as_str() {
                "texture" => c,
                "ref" => self.lookup(c)?,
                _ => continue,
            };
            if t.tag == "texture" {
                self.queried.borrow_mut().note(node, Some(c));
                return Ok(Some(t));
            }
        }
        Ok(None)
    }

    fn one_child(&self, node: &'a Node) -> Result<&'a Node> {
        let kids = self.child_bsdfs(node)?;
        match kids.as_slice() {
            [one] => Ok(one),
            _ => Err(node.loc.err(format!("bsdf '{}' needs exactly one nested bsdf, found {}", node.attr("type").unwrap_or("?"), kids.len()))),
        }
    }

    /// An index of refraction: a number or one of Mitsuba's named materials.
    fn ior(&self, node: &'a Node, name: &str, default: f32) -> Result<f32> {
        let Some(p) = self.prop(node, name)? else { return Ok(default) };
        let v = match p.tag.as_str() {
            "float" | "integer" => super::props::parse_f32(p.req("value")?, &p.loc, name)?,
            "string" => {
                let s = p.req("value")?;
                spectra::named_ior(s).ok_or_else(|| {
                    p.loc.err(format!(
                        "unknown index of refraction '{s}' (e.g. vacuum, air, water, bk7, glass, fused quartz, acrylic glass, polypropylene, diamond)"
                    ))
                })?
            }
            t => return Err(p.loc.err(format!("{name}: expected a <float> or <string>, got <{t}>"))),
        };
        if !(v > 0.0 && v.is_finite()) {
            return Err(p.loc.err(format!("{name}: index of refraction must be positive, got {v}")));
        }
        Ok(v)
    }

    fn eta(&self, node: &'a Node, int_default: f32) -> Result<f32> {
        Ok(self.ior(node, "int_ior", int_default)? / self.ior(node, "ext_ior", 1.000277)?)
    }

    fn roughness(&mut self, node: &'a Node) -> Result<Roughness> {
        let kind = match self.string(node, "distribution")?.unwrap_or("beckmann") {
            "beckmann" => MicrofacetKind::Beckmann,
            "ggx" => MicrofacetKind::Ggx,
            o => return Err(node.loc.err(format!("distribution '{o}' is not beckmann or ggx"))),
        };
        let (alpha_u, alpha_v) = if self.prop(node, "alpha")?.is_some() {
            let a = self.float_texture(node, "alpha", 0.1)?;
            (a.clone(), a)
        } else {
            (self.float_texture(node, "alpha_u", 0.1)?, self.float_texture(node, "alpha_v", 0.1)?)
        };
        for a in [&alpha_u, &alpha_v] {
            if let crate::texture::Texture::Constant(c) = a {
                if !(c.r >= 0.0 && c.r.is_finite()) {
                    return Err(node.loc.err(format!("roughness alpha must be non-negative, got {}", c.r)));
                }
            }
        }
        Ok(Roughness { kind, alpha_u, alpha_v })
    }

    /// Mitsuba's `principled` (`thin` false) or `principledthin`: every parameter a float
    /// or a texture; constants outside their ranges are errors, textures are clamped when
    /// evaluated.
    fn principled(&mut self, node: &'a Node, thin: bool) -> Result<PrincipledMaterial> {
        let mut m = PrincipledMaterial { thin, ..PrincipledMaterial::default() };
        m.base_color = self.spectrum(node, "base_color", Rgb::splat(0.5), SpectrumKind::Reflectance)?;
        let ty = if thin { "principledthin" } else { "principled" };
        let weight = |l: &mut Self, name: &str, default: f32, max: f32| -> Result<Texture> {
            let t = l.float_texture(node, name, default)?;
            if let Texture::Constant(c) = &t {
                if !(0.0..=max).contains(&c.r) {
                    let at = l.prop(node, name)?.map_or(&node.loc, |p| &p.loc);
                    return Err(at.err(format!("{ty}: '{name}' must lie in [0, {max}], got {}", c.r)));
                }
            }
            Ok(t)
        };
        m.roughness = weight(self, "roughness", 0.5, 1.0)?;
        m.anisotropic = weight(self, "anisotropic", 0.0, 1.0)?;
        m.spec_trans = weight(self, "spec_trans", 0.0, 1.0)?;
        m.spec_tint = weight(self, "spec_tint", 0.0, 1.0)?;
        m.sheen = weight(self, "sheen", 0.0, 1.0)?;
        m.sheen_tint = weight(self, "sheen_tint", 0.0, 1.0)?;
        m.flatness = weight(self, "flatness", 0.0, 1.0)?;
        let rate = |l: &Self, name: &str| -> Result<f32> {
            let v = l.float(node, name, 1.0)?;
            if !(v >= 0.0 && v.is_finite()) {
                let at = l.prop(node, name)?.map_or(&node.loc, |p| &p.loc);
                return Err(at.err(format!("{ty}: '{name}' must be a finite non-negative number, got {v}")));
            }
            Ok(v)
        };
        let bad_eta = |l: &Self, v: f32| -> Result<()> {
            if v > 0.0 && v.is_finite() {
                return Ok(());
            }
            let at = l.prop(node, "eta")?.map_or(&node.loc, |p| &p.loc);
            Err(at.err(format!("{ty}: 'eta' (interior / exterior IOR) must be positive and finite, got {v}")))
        };
        if thin {
            m.diff_trans = weight(self, "diff_trans", 0.0, 2.0)?;
            m.eta = self.float_texture(node, "eta", 1.5)?;
            if let Texture::Constant(c) = &m.eta {
                bad_eta(self, c.r)?;
            }
            m.rates = SamplingRates {
                diffuse_reflection: rate(self, "diffuse_reflectance_sampling_rate")?,
                specular: rate(self, "specular_reflectance_sampling_rate")?,
                secondary: rate(self, "specular_transmittance_sampling_rate")?,
                diffuse_transmission: rate(self, "diffuse_transmittance_sampling_rate")?,
            };
        } else {
            m.metallic = weight(self, "metallic", 0.0, 1.0)?;
            m.clearcoat = weight(self, "clearcoat", 0.0, 1.0)?;
            m.clearcoat_gloss = weight(self, "clearcoat_gloss", 0.0, 1.0)?;
            let refracts = !matches!(&m.spec_trans, Texture::Constant(c) if c.r == 0.0);
            let eta = match (self.opt_float(node, "eta")?, self.opt_float(node, "specular")?) {
                (Some(_), Some(_)) => return Err(node.loc.err("principled: give either 'eta' or 'specular', not both")),
                (Some(eta), None) => {
                    bad_eta(self, eta)?;
                    eta
                }
                (None, specular) => {
                    let s = specular.unwrap_or(0.5);
                    // sqrt(0.08 s) is the normal reflectance's square root: below 1.
                    if !(0.0..12.5).contains(&s) {
                        let at = self.prop(node, "specular")?.map_or(&node.loc, |p| &p.loc);
                        return Err(at.err(format!("principled: 'specular' must lie in [0, 12.5), got {s}")));
                    }
                    // Mitsuba: zero specular (eta 1) cannot refract plausibly.
                    eta_from_specular(if refracts && s == 0.0 { 1e-3 } else { s })
                }
            };
            m.eta = Texture::Constant(Rgb::splat(eta));
            m.rates = SamplingRates {
                diffuse_reflection: rate(self, "diffuse_reflectance_sampling_rate")?,
                specular: rate(self, "main_specular_sampling_rate")?,
                secondary: rate(self, "clearcoat_sampling_rate")?,
                diffuse_transmission: 1.0,
            };
        }
        Ok(m)
    }

    /// A `<bsdf>` element as a material, nested BSDFs included.
    pub(super) fn bsdf(&mut self, node: &'a Node) -> Result<Material> {
        self.nested(node, |l| l.bsdf_plugin(node))
    }

    fn bsdf_plugin(&mut self, node: &'a Node) -> Result<Material> {
        let ty = node.type_()?;
        let white = Rgb::WHITE;
        let refl = SpectrumKind::Reflectance;
        if let Some(m) = self.classic_bsdf(node, ty)? {
            return Ok(m);
        }
        Ok(match ty {
            "diffuse" => Material::Diffuse { reflectance: self.spectrum(node, "reflectance", Rgb::splat(0.5), refl)? },
            "conductor" | "roughconductor" => {
                let specular_reflectance = self.spectrum(node, "specular_reflectance", white, refl)?;
                let material = self.string(node, "material")?;
                let (eta, k) = if self.prop(node, "eta")?.is_some() || self.prop(node, "k")?.is_some() {
                    if material.is_some() {
                        return Err(node.loc.err("give either 'material' or 'eta'/'k', not both"));
                    }
                    let eta = self.constant_color(node, "eta", Rgb::BLACK, SpectrumKind::Unbounded)?;
                    let k = self.constant_color(node, "k", Rgb::WHITE, SpectrumKind::Unbounded)?;
                    (eta, k)
                } else {
                    let m = material.unwrap_or("none");
                    spectra::named_conductor(m).ok_or_else(|| node.loc.err(format!("unknown conductor material '{m}' (none, Ag, Al, Au, Cu, Cr)")))?
                };
                let roughness = if ty == "roughconductor" { Some(self.roughness(node)?) } else { None };
                Material::Conductor { eta, k, specular_reflectance, roughness }
            }
            "dielectric" | "roughdielectric" => {
                let eta = self.eta(node, 1.5046)?;
                let specular_reflectance = self.spectrum(node, "specular_reflectance", white, refl)?;
                let specular_transmittance = self.spectrum(node, "specular_transmittance", white, refl)?;
                let roughness = if ty == "roughdielectric" { Some(self.roughness(node)?) } else { None };
                Material::Dielectric { eta, specular_reflectance, specular_transmittance, roughness }
            }
            "thindielectric" => Material::ThinDielectric {
                eta: self.eta(node, 1.5046)?,
                specular_reflectance: self.spectrum(node, "specular_reflectance", white, refl)?,
                specular_transmittance: self.spectrum(node, "specular_transmittance", white, refl)?,
            },
            "glass" => {
                // svetlo's thin pane (Radiance's glass): the normal transmittance τn of a data
                // sheet, or the internal transmissivity directly; neither: lossless.
                let eta = self.eta(node, 1.52)?;
                let has = |w: &Self, n: &str| w.prop(node, n).map(|p| p.is_some());
                let transmissivity = match (has(self, "transmittance")?, has(self, "transmissivity")?) {
                    (true, true) => return Err(node.loc.err("glass: give 'transmittance' (normal) or 'transmissivity', not both")),
                    (true, false) => {
                        let tau = self.constant_color(node, "transmittance", Rgb::WHITE, SpectrumKind::Reflectance)?;
                        let conv = |t: f32| {
                            crate::bsdf::glass::transmissivity_from_normal(t as f64, eta as f64).map(|x| x as f32).ok_or_else(|| {
                                let r = ((eta - 1.0) / (eta + 1.0)).powi(2);
                                node.loc.err(format!(
                                    "glass: normal transmittance {t} is outside 0..{:.4}, what a lossless pane of index {eta} transmits",
                                    (1.0 - r) / (1.0 + r)
                                ))
                            })
                        };
                        Rgb::new(conv(tau.r)?, conv(tau.g)?, conv(tau.b)?)
                    }
                    (false, _) => {
                        let t = self.constant_color(node, "transmissivity", Rgb::WHITE, SpectrumKind::Reflectance)?;
                        if ![t.r, t.g, t.b].iter().all(|x| (0.0..=1.0).contains(x)) {
                            return Err(node.loc.err(format!("glass: transmissivity must lie in 0..1, got {t:?}")));
                        }
                        t
                    }
                };
                Material::Glass { eta, transmissivity }
            }
            "plastic" | "roughplastic" => {
                let roughness = if ty == "roughplastic" {
                    let r = self.roughness(node)?;
                    if self.prop(node, "alpha_u")?.is_some() {
                        self.warn(format!("{}:{}: roughplastic is isotropic; alpha_u/alpha_v used as given", node.loc.file.display(), node.loc.line));
                    }
                    Some(r)
                } else {
                    None
                };
                Material::Plastic {
                    diffuse_reflectance: self.spectrum(node, "diffuse_reflectance", Rgb::splat(0.5), refl)?,
                    specular_reflectance: self.spectrum(node, "specular_reflectance", white, refl)?,
                    eta: self.eta(node, 1.49)?,
                    nonlinear: self.boolean(node, "nonlinear", false)?,
                    roughness,
                }
            }
            "twosided" => {
                let kids = self.child_bsdfs(node)?;
                match kids.as_slice() {
                    [one] => {
                        let m = self.bsdf(one)?;
                        Material::TwoSided { front: Box::new(m.clone()), back: Box::new(m) }
                    }
                    [f, b] => Material::TwoSided { front: Box::new(self.bsdf(f)?), back: Box::new(self.bsdf(b)?) },
                    _ => return Err(node.loc.err(format!("twosided needs one or two nested bsdfs, found {}", kids.len()))),
                }
            }
            "mask" => {
                let opacity = self.float_texture(node, "opacity", 0.5)?;
                let inner = self.one_child(node)?;
                Material::Mask { opacity, inner: Box::new(self.bsdf(inner)?) }
            }
            "null" => Material::Null,
            "normalmap" => {
                let inner = self.one_child(node)?;
                let tex = self.prop(node, "normalmap")?.ok_or_else(|| node.loc.err("normalmap needs a texture named 'normalmap'"))?;
                if tex.tag != "texture" {
                    return Err(tex.loc.err("normalmap: 'normalmap' must be a texture (a bitmap of tangent-space normals)"));
                }
                let normals = self.texture(tex, SpectrumKind::Unbounded)?;
                // Stored as 0.5 (n + 1): a texel outside [0, 1] or one that is no direction
                // (all channels 0.5) is not a normal map (an sRGB-decoded one, or a height map).
                // Read in place: a decoded copy of a 2048² 8-bit map is 48 MB (kept) and a
                // fifth of a small scene's load.
                let texels = || -> Box<dyn Iterator<Item = Rgb> + '_> {
                    match &normals {
                        crate::texture::Texture::Bitmap { image, .. } => Box::new(image.texels()),
                        crate::texture::Texture::Constant(c) => Box::new(std::iter::once(*c)),
                        _ => Box::new(std::iter::empty()),
                    }
                };
                // An 8-bit map's channels are its code table's values: none is outside where
                // none of those is, and the texels need no scan.
                let in_table = match &normals {
                    crate::texture::Texture::Bitmap { image, .. } => image.channel_bounds().is_some_and(|(lo, hi)| lo >= -1e-4 && hi <= 1.0001),
                    _ => false,
                };
                if !in_table {
                    if let Some((i, c)) = texels().enumerate().find(|(_, c)| c.min_component() < -1e-4 || c.max_component() > 1.0001) {
                        return Err(tex.loc.err(format!("normalmap: texel {i} is {c:?}, outside [0, 1]: not a normal map")));
                    }
                }
                let flat = |c: Rgb| (c.r - 0.5).abs() < 1e-3 && (c.g - 0.5).abs() < 1e-3 && (c.b - 0.5).abs() < 1e-3;
                if texels().next().is_some() && texels().all(flat) {
                    return Err(tex.loc.err("normalmap: every texel is (0.5, 0.5, 0.5), no direction: not a normal map"));
                }
                Material::NormalMap { normals, inner: Box::new(self.bsdf(inner)?) }
            }
            "bumpmap" => {
                let inner = self.one_child(node)?;
                let tex = self.nested_texture(node)?.ok_or_else(|| node.loc.err("bumpmap needs a nested height texture"))?;
                let height = self.texture(tex, SpectrumKind::Unbounded)?;
                let scale = self.float(node, "scale", 1.0)?;
                if !scale.is_finite() {
                    return Err(node.loc.err(format!("bumpmap: scale must be finite, got {scale}")));
                }
                Material::BumpMap { height, scale, inner: Box::new(self.bsdf(inner)?) }
            }
            "blendbsdf" => {
                let kids = self.child_bsdfs(node)?;
                let [a, b] = kids.as_slice() else {
                    return Err(node.loc.err(format!("blendbsdf needs exactly two nested bsdfs, found {}", kids.len())));
                };
                let weight = self.float_texture(node, "weight", 0.5)?;
                if let crate::texture::Texture::Constant(c) = &weight {
                    if !(0.0..=1.0).contains(&c.r) {
                        return Err(node.loc.err(format!("blendbsdf: weight must lie in [0, 1], got {}", c.r)));
                    }
                }
                Material::Blend { weight, a: Box::new(self.bsdf(a)?), b: Box::new(self.bsdf(b)?) }
            }
            "principled" | "principledthin" => Material::Principled(Box::new(self.principled(node, ty == "principledthin")?)),
            "hair" | "measured" | "pplastic" | "polarizer" | "retarder" | "circular" | "roughcoating" | "coating" | "difftrans" => {
                return Err(node.loc.err(format!("bsdf type '{ty}' is not supported")));
            }
            other => return Err(node.loc.err(format!("unknown bsdf type '{other}'"))),
        })
    }
}
