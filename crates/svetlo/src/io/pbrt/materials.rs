//! pbrt-v4 materials and textures onto svetlo's [`Material`] and [`Texture`].
//!
//! Spectra become linear sRGB: `rgb` as given; sampled spectra and blackbodies reduced by
//! the CIE matching functions (io/spectra.rs); named metals (`metal-Ag-eta`, ...) from the
//! table svetlo shares with the Mitsuba loader; named glasses (`glass-BK7`, ...) as one IOR,
//! the mean of their Sellmeier dispersion at 610, 550 and 465 nm (about where the sRGB
//! primaries' luminous weights peak) since svetlo's dielectrics are not dispersive.
//! Roughness: `remaproughness` (default true) maps pbrt's roughness r to alpha = sqrt(r)
//! (pbrt-v4's TrowbridgeReitz RoughnessToAlpha); alphas below 1e-3 are smooth, as in pbrt.
//! Textures: pbrt's procedural ones (`bilerp`, `directionmix`, `dots`, `fbm`, `wrinkled`,
//! `windy`, `marble`) and textured `mix`/`scale` become [`Procedural`] (texture/procedural.rs,
//! with what is approximated); every 2-D texture takes pbrt's uv, spherical, cylindrical and
//! planar mappings, in the texture space of the CTM at the `Texture` directive. `ptex` is
//! not supported. pbrt-v4's source hands `dots`' "inside" to its outside-the-dots slot
//! (its Create passes inside, outside to a constructor taking outside, inside); svetlo
//! follows the parameters' names, so a pbrt-v4 render shows the two swapped.

use super::lexer::Loc;
use super::params::{ParamList, SpectrumValue};
use super::Loader;
use crate::bsdf::material::{CoatedBase, CoatedMaterial, MicrofacetKind, Roughness};
use crate::bsdf::Material;
use crate::error::Result;
use crate::io::spectra::{self, SpectrumKind};
use crate::spectrum::Rgb;
use crate::texture::{FilterMode, Mapping2D, Procedural, Texture, WrapMode};
use glam::{Affine2, Mat2, Vec2, Vec3};

/// Sellmeier coefficients (B1, B2, B3, C1, C2, C3; C in µm²) of pbrt-v4's named glasses
/// (Schott's catalogue).
const GLASSES: [(&str, [f64; 6]); 7] = [
    ("glass-BK7", [1.03961212, 0.231792344, 1.01046945, 0.00600069867, 0.0200179144, 103.560653]),
    ("glass-BAF10", [1.5851495, 0.143559385, 1.08521269, 0.00926681282, 0.0424489805, 105.613573]),
    ("glass-FK51A", [0.971247817, 0.216901417, 0.904651666, 0.00472301995, 0.0153575612, 168.68133]),
    ("glass-LASF9", [2.00029547, 0.298926886, 1.80691843, 0.0121426017, 0.0538736236, 156.530829]),
    ("glass-F5", [1.52481889, 0.187085527, 1.42729015, 0.011254756, 0.0588995392, 129.141675]),
    ("glass-F10", [1.62153902, 0.256287842, 1.64447552, 0.0122241457, 0.0595736775, 147.468793]),
    ("glass-F11", [1.73759695, 0.313747346, 1.89878101, 0.013188707, 0.0623068142, 155.23629]),
];

/// Refractive index of a Sellmeier glass at `nm`.
fn sellmeier(c: &[f64; 6], nm: f64) -> f64 {
    let l2 = (nm / 1000.0) * (nm / 1000.0);
    (1.0 + c[0] * l2 / (l2 - c[3]) + c[1] * l2 / (l2 - c[4]) + c[2] * l2 / (l2 - c[5])).sqrt()
}

/// One IOR for a named glass (see the module notes).
pub fn named_glass_ior(name: &str) -> Option<f32> {
    let c = GLASSES.iter().find(|(n, _)| *n == name)?.1;
    Some((([610.0, 550.0, 465.0].iter().map(|&l| sellmeier(&c, l)).sum::<f64>()) / 3.0) as f32)
}

/// pbrt-v4's named metals that svetlo's table holds.
fn named_metal(name: &str) -> Option<Rgb> {
    let rest = name.strip_prefix("metal-")?;
    let (metal, part) = rest.rsplit_once('-')?;
    let (eta, k) = spectra::named_conductor(metal)?;
    match part {
        "eta" => Some(eta),
        "k" => Some(k),
        _ => None,
    }
}

/// Planck's law (W·sr⁻¹·m⁻³) at `nm` for temperature `t` (K).
fn planck(nm: f64, t: f64) -> f64 {
    let (c, h, kb) = (299_792_458.0f64, 6.626_070_15e-34f64, 1.380_649e-23f64);
    let l = nm * 1e-9;
    2.0 * h * c * c / (l.powi(5) * ((h * c / (l * kb * t)).exp() - 1.0))
}

/// A blackbody's colour, normalised to luminance 1 (pbrt divides emitters by their
/// photometric value; only the chromaticity is left).
pub fn blackbody_rgb(t: f32) -> Rgb {
    let peak = planck(2.897_771_955e6 / t as f64, t as f64);
    let samples: Vec<(f32, f32)> = (360..=830).step_by(5).map(|l| (l as f32, (planck(l as f64, t as f64) / peak) as f32)).collect();
    normalise_luminance(spectra::sampled_to_rgb(&samples, SpectrumKind::Illuminant))
}

fn normalise_luminance(c: Rgb) -> Rgb {
    let y = c.luminance();
    if y > 0.0 {
        c / y
    } else {
        c
    }
}

impl Loader {
    /// A spectrum parameter as RGB; `illuminant`: pbrt's emitter convention (see lights.rs).
    pub(super) fn spectrum_rgb(&self, v: &SpectrumValue, kind: SpectrumKind, loc: &Loc) -> Result<Rgb> {
        Ok(match v {
            SpectrumValue::Rgb(c) => *c,
            SpectrumValue::Constant(x) => Rgb::splat(*x),
            SpectrumValue::Blackbody(t) => {
                if !(*t > 0.0 && t.is_finite()) {
                    return Err(loc.err(format!("blackbody temperature must be positive, got {t}")));
                }
                blackbody_rgb(*t)
            }
            SpectrumValue::Sampled(s) => {
                let c = spectra::sampled_to_rgb(s, kind);
                if kind == SpectrumKind::Illuminant {
                    normalise_luminance(c)
                } else {
                    c
                }
            }
            SpectrumValue::Named(n) => {
                if let Some(c) = named_metal(n) {
                    c
                } else if let Some(eta) = named_glass_ior(n) {
                    Rgb::splat(eta)
                } else if n == "stdillum-D65" {
                    Rgb::WHITE
                } else {
                    return Err(loc.err(format!("named spectrum '{n}' is not known (svetlo has metal-{{Ag,Al,Au,Cu,Cr}}-eta/k, glass-*, stdillum-D65)")));
                }
            }
        })
    }

    /// A colour parameter: a spectrum value or a named texture.
    fn color_param(&self, p: &ParamList, name: &str, default: Rgb, kind: SpectrumKind) -> Result<Texture> {
        if let Some((t, loc)) = p.texture_ref(name) {
            return self.color_textures.get(t).or_else(|| self.float_textures.get(t)).cloned().ok_or_else(|| loc.err(format!("no texture named '{t}'")));
        }
        match p.spectrum(name)? {
            Some((v, loc)) => Ok(Texture::Constant(self.spectrum_rgb(&v, kind, loc)?)),
            None => Ok(Texture::Constant(default)),
        }
    }

    /// A scalar parameter: a float or a named float texture.
    pub(super) fn float_param(&self, p: &ParamList, name: &str, default: f32) -> Result<Texture> {
        if let Some((t, loc)) = p.texture_ref(name) {
            return self.float_textures.get(t).cloned().ok_or_else(|| loc.err(format!("no float texture named '{t}'")));
        }
        Ok(Texture::Constant(Rgb::splat(p.float(name, default)?)))
    }

    /// A constant spectrum (eta, k): textures are reduced to their mean with a warning.
    fn constant_rgb(&mut self, p: &ParamList, name: &str, default: Rgb, loc: &Loc) -> Result<Rgb> {
        let t = self.color_param(p, name, default, SpectrumKind::Unbounded)?;
        if !t.is_constant() {
            self.warn(loc, format!("'{name}' must be constant in svetlo; the texture's mean is used"));
        }
        Ok(t.mean())
    }

    /// An IOR: a float, or a named glass spectrum.
    fn eta(&self, p: &ParamList, name: &str, default: f32) -> Result<f32> {
        match p.spectrum(name)? {
            Some((SpectrumValue::Constant(e), _)) => Ok(e),
            Some((v, loc)) => Ok(self.spectrum_rgb(&v, SpectrumKind::Unbounded, loc)?.mean()),
            None => Ok(default),
        }
    }

    /// `roughness` or `uroughness`/`vroughness` with pbrt's remapping; None when smooth.
    fn roughness(&self, p: &ParamList, prefix: &str, loc: &Loc) -> Result<Option<Roughness>> {
        let k = |s: &str| format!("{prefix}{s}");
        let r = self.float_param(p, &k("roughness"), 0.0)?;
        let u = if p.get(&k("uroughness")).is_some() { self.float_param(p, &k("uroughness"), 0.0)? } else { r.clone() };
        let v = if p.get(&k("vroughness")).is_some() { self.float_param(p, &k("vroughness"), 0.0)? } else { r };
        let remap = p.bool("remaproughness", true)?;
        let alpha = |t: Texture| -> Result<Texture> {
            match t {
                Texture::Constant(c) => Ok(Texture::Constant(if remap { Rgb::splat(c.r.max(0.0).sqrt()) } else { c })),
                other if !remap => Ok(other),
                _ => Err(loc.err("a roughness texture with remaproughness true is not supported yet (give alphas and remaproughness false)")),
            }
        };
        let (au, av) = (alpha(u)?, alpha(v)?);
        let smooth = |t: &Texture| matches!(t, Texture::Constant(c) if c.r < 1e-3);
        if smooth(&au) && smooth(&av) {
            return Ok(None);
        }
        Ok(Some(Roughness { kind: MicrofacetKind::Ggx, alpha_u: au, alpha_v: av }))
    }

    pub(super) fn make_material(&mut self, ty: &str, p: &ParamList, loc: &Loc) -> Result<u32> {
        let p = &super::merge(p, &self.gs.material_attrs.clone());
        let _ = p.get("type");
        for k in ["displacement", "normalmap"] {
            if p.get(k).is_some() {
                self.warn(loc, format!("material '{ty}': '{k}' is not supported; ignored"));
            }
        }
        let refl = SpectrumKind::Reflectance;
        let m = match ty {
            "diffuse" => Material::Diffuse { reflectance: self.color_param(p, "reflectance", Rgb::splat(0.5), refl)? },
            "conductor" => {
                let roughness = self.roughness(p, "", loc)?;
                let (eta, k) = self.conductor_ior(p, "", loc)?;
                Material::Conductor { eta, k, specular_reflectance: Texture::Constant(Rgb::WHITE), roughness }
            }
            "dielectric" => {
                let eta = self.eta(p, "eta", 1.5)?;
                let roughness = self.roughness(p, "", loc)?;
                let w = Texture::Constant(Rgb::WHITE);
                Material::Dielectric { eta, specular_reflectance: w.clone(), specular_transmittance: w, roughness }
            }
            "thindielectric" => {
                let w = Texture::Constant(Rgb::WHITE);
                Material::ThinDielectric { eta: self.eta(p, "eta", 1.5)?, specular_reflectance: w.clone(), specular_transmittance: w }
            }
            "coateddiffuse" | "coatedconductor" => {
                let diffuse = ty == "coateddiffuse";
                let pre = if diffuse { "" } else { "interface." };
                let eta = self.eta(p, &format!("{pre}eta"), 1.5)?;
                let roughness = self.roughness(p, pre, loc)?;
                let base = if diffuse {
                    CoatedBase::Diffuse(self.color_param(p, "reflectance", Rgb::splat(0.5), refl)?)
                } else {
                    let (eta, k) = self.conductor_ior(p, "conductor.", loc)?;
                    CoatedBase::Conductor { eta, k, roughness: self.roughness(p, "conductor.", loc)? }
                };
                let thickness = p.float("thickness", 0.01)?;
                let albedo = self.constant_rgb(p, "albedo", Rgb::BLACK, loc)?;
                let g = p.float("g", 0.0)?;
                let (max_depth, n_samples) = (p.int("maxdepth", 10)?, p.int("nsamples", 1)?);
                if !(thickness >= 0.0 && thickness.is_finite() && -1.0 < g && g < 1.0 && (0..=1000).contains(&max_depth) && (1..=1024).contains(&n_samples)) {
                    return Err(loc.err(format!(
                        "{ty}: need thickness >= 0 ({thickness}), -1 < g < 1 ({g}), 0 <= maxdepth <= 1000 ({max_depth}), 1 <= nsamples <= 1024 ({n_samples})"
                    )));
                }
                if albedo.max_component() > 1.0 || albedo.min_component() < 0.0 {
                    return Err(loc.err(format!("{ty}: albedo must be in [0, 1], got {albedo:?}")));
                }
                Material::Coated(Box::new(CoatedMaterial {
                    base,
                    eta,
                    roughness,
                    thickness,
                    albedo,
                    g,
                    max_depth: max_depth as u32,
                    n_samples: n_samples as u32,
                }))
            }
            "interface" | "none" | "" => Material::Null,
            "diffusetransmission" => {
                let scale = p.float("scale", 1.0)?;
                let scaled = |t: Texture| match t {
                    Texture::Constant(c) => Ok(Texture::Constant(c * scale)),
                    t if scale == 1.0 => Ok(t),
                    _ => Err(loc.err("diffusetransmission: 'scale' with textured reflectance or transmittance is not supported")),
                };
                Material::DiffuseTransmission {
                    reflectance: scaled(self.color_param(p, "reflectance", Rgb::splat(0.25), refl)?)?,
                    transmittance: scaled(self.color_param(p, "transmittance", Rgb::splat(0.25), refl)?)?,
                }
            }
            "mix" => {
                let names = p.strings("materials")?.ok_or_else(|| loc.err("mix needs \"string materials\" [ a b ]"))?;
                if names.len() != 2 {
                    return Err(loc.err(format!("mix needs two material names, got {}", names.len())));
                }
                let amount = self.float_param(p, "amount", 0.5)?;
                let index = |l: &Self, n: &str| l.named_materials.get(n).copied().ok_or_else(|| loc.err(format!("mix: no material named '{n}'")));
                let (ia, ib) = (index(self, &names[0])?, index(self, &names[1])?);
                self.warn_unused(&format!("Material \"{ty}\""), p);
                match amount {
                    Texture::Constant(c) if c.r <= 0.0 => return Ok(ia),
                    Texture::Constant(c) if c.r >= 1.0 => return Ok(ib),
                    _ => {}
                }
                // The parts as pbrt defines them (one-sided wrappers off), blended, then
                // wrapped once like any other reflecting material.
                let part = |l: &Self, i: u32| -> Result<Material> {
                    match l.b.material(i) {
                        Some(Material::TwoSided { front, .. }) => Ok((**front).clone()),
                        Some(Material::Null | Material::Mask { .. }) | None => {
                            Err(loc.err("mix: 'interface' materials and alpha inside a mix are not supported"))
                        }
                        Some(m) => Ok(m.clone()),
                    }
                };
                let (a, b) = (part(self, ia)?, part(self, ib)?);
                Material::Mix { amount, a: Box::new(a), b: Box::new(b) }
            }
            "measured" | "hair" | "subsurface" => {
                return Err(loc.err(format!("material '{ty}' is not supported yet")));
            }
            other => return Err(loc.err(format!("unknown material '{other}'"))),
        };
        self.warn_unused(&format!("Material \"{ty}\""), p);
        // pbrt's reflecting BSDFs act alike on both sides of a surface; svetlo's (Mitsuba's)
        // are one-sided unless wrapped.
        let m = match m {
            Material::Dielectric { .. } | Material::ThinDielectric { .. } | Material::DiffuseTransmission { .. } | Material::Null => m,
            other => Material::TwoSided { front: Box::new(other.clone()), back: Box::new(other) },
        };
        Ok(self.b.add_material(m))
    }

    /// A conductor's (eta, k): given, or from `reflectance` (pbrt-v4: eta 1, k = 2√r/√(1-r)),
    /// default copper. `prefix` is "conductor." inside coatedconductor.
    fn conductor_ior(&mut self, p: &ParamList, prefix: &str, loc: &Loc) -> Result<(Rgb, Rgb)> {
        let rname = format!("{prefix}reflectance");
        if p.get(&rname).is_some() {
            let r = self.constant_rgb(p, &rname, Rgb::WHITE, loc)?;
            let k = r.map(|x| {
                let x = x.clamp(0.0, 0.9999);
                2.0 * x.sqrt() / (1.0 - x).sqrt()
            });
            return Ok((Rgb::WHITE, k));
        }
        let (cu_eta, cu_k) = spectra::named_conductor("Cu").unwrap_or((Rgb::WHITE, Rgb::WHITE));
        let eta = self.constant_rgb(p, &format!("{prefix}eta"), cu_eta, loc)?;
        let k = self.constant_rgb(p, &format!("{prefix}k"), cu_k, loc)?;
        Ok((eta, k))
    }

    pub(super) fn make_texture(&mut self, name: &str, kind: &str, class: &str, p: &ParamList, loc: &Loc) -> Result<()> {
        let is_float = match kind {
            "float" => true,
            "spectrum" | "color" | "rgb" => false,
            other => return Err(loc.err(format!("Texture '{name}': type must be \"float\" or \"spectrum\", got \"{other}\""))),
        };
        let get = |l: &Loader, k: &str, d: f32| -> Result<Texture> {
            if is_float {
                l.float_param(p, k, d)
            } else {
                l.color_param(p, k, Rgb::splat(d), SpectrumKind::Reflectance)
            }
        };
        let to_uv = self.uv_mapping(p, loc)?;
        let mapping = self.mapping2d(p, loc)?;
        let world_to_texture = self.gs.ctm[0].inverse();
        let proc = |t: Procedural| Texture::Procedural(std::sync::Arc::new(t));
        let t = match class {
            "constant" => get(self, "value", 1.0)?,
            "imagemap" => {
                let file = p.string("filename")?.ok_or_else(|| loc.err("imagemap needs \"string filename\""))?.to_string();
                let path = self.resolve(&file, loc);
                let encoding = p.string("encoding")?.map(str::to_string);
                let linear_input = match encoding.as_deref() {
                    None | Some("sRGB") => false,
                    Some("linear") => true,
                    Some(other) => return Err(loc.err(format!("imagemap encoding '{other}' is not supported (sRGB, linear)"))),
                };
                let image = self.bitmap(&path, linear_input, loc)?;
                let scale = p.float("scale", 1.0)?;
                let invert = p.bool("invert", false)?;
                let wrap = match p.string("wrap")?.unwrap_or("repeat") {
                    "repeat" => WrapMode::Repeat,
                    "clamp" => WrapMode::Clamp,
                    "black" => {
                        self.warn(loc, "imagemap wrap \"black\" approximated by clamp");
                        WrapMode::Clamp
                    }
                    other => return Err(loc.err(format!("imagemap wrap '{other}' is not supported (repeat, clamp, black)"))),
                };
                let filter = match p.string("filter")?.unwrap_or("bilinear") {
                    "point" => FilterMode::Nearest,
                    _ => FilterMode::Bilinear,
                };
                let image = if scale != 1.0 || invert {
                    let mut b = (*image).clone();
                    for c in b.data_mut() {
                        *c *= scale;
                        if invert {
                            *c = c.map(|x| (1.0 - x).max(0.0));
                        }
                    }
                    std::sync::Arc::new(b)
                } else {
                    image
                };
                Texture::Bitmap { image, filter, wrap, to_uv }
            }
            "checkerboard" => {
                let dim = p.int("dimension", 2)?;
                if dim != 2 {
                    return Err(loc.err("checkerboard: only dimension 2 is supported yet"));
                }
                let (a, b) = (get(self, "tex1", 1.0)?, get(self, "tex2", 0.0)?);
                let (Texture::Constant(c0), Texture::Constant(c1)) = (a, b) else {
                    return Err(loc.err("checkerboard: textured tex1/tex2 are not supported yet"));
                };
                // pbrt's checks are unit squares in (s, t); svetlo's cells are half units.
                Texture::Checkerboard { color0: c0, color1: c1, to_uv: Affine2::from_scale(Vec2::splat(0.5)) * to_uv }
            }
            "scale" => {
                let (t, s) = (get(self, "tex", 1.0)?, self.float_param(p, "scale", 1.0)?);
                match (t, s) {
                    (Texture::Constant(a), Texture::Constant(b)) => Texture::Constant(a * b.r),
                    (Texture::Bitmap { image, filter, wrap, to_uv }, Texture::Constant(b)) => {
                        let mut im = (*image).clone();
                        for c in im.data_mut() {
                            *c *= b.r;
                        }
                        Texture::Bitmap { image: std::sync::Arc::new(im), filter, wrap, to_uv }
                    }
                    (Texture::Checkerboard { color0, color1, to_uv }, Texture::Constant(b)) => {
                        Texture::Checkerboard { color0: color0 * b.r, color1: color1 * b.r, to_uv }
                    }
                    (tex, scale) => proc(Procedural::Scale { tex, scale }),
                }
            }
            "mix" => {
                let (a, b, amt) = (get(self, "tex1", 0.0)?, get(self, "tex2", 1.0)?, self.float_param(p, "amount", 0.5)?);
                match (a, b, amt) {
                    (Texture::Constant(a), Texture::Constant(b), Texture::Constant(t)) => Texture::Constant(a * (1.0 - t.r) + b * t.r),
                    (tex1, tex2, amount) => proc(Procedural::Mix { tex1, tex2, amount }),
                }
            }
            "bilerp" => {
                let corner = |l: &Loader, k: &str, d: f32| -> Result<Rgb> {
                    match get(l, k, d)? {
                        Texture::Constant(c) => Ok(c),
                        _ => Err(loc.err(format!("bilerp: '{k}' must be a value, not a texture"))),
                    }
                };
                let (v00, v01, v10, v11) = (corner(self, "v00", 0.0)?, corner(self, "v01", 1.0)?, corner(self, "v10", 0.0)?, corner(self, "v11", 1.0)?);
                proc(Procedural::Bilerp { mapping: mapping.clone(), v00, v01, v10, v11 })
            }
            "directionmix" => {
                let (tex1, tex2) = (get(self, "tex1", 0.0)?, get(self, "tex2", 1.0)?);
                let dir = self.gs.ctm[0].transform_vector3(p.point3("dir", Vec3::Y)?).normalize_or_zero();
                if dir == Vec3::ZERO || !dir.is_finite() {
                    return Err(loc.err("directionmix: 'dir' must be a non-zero vector"));
                }
                proc(Procedural::DirectionMix { tex1, tex2, dir })
            }
            "dots" => {
                let (inside, outside) = (get(self, "inside", 1.0)?, get(self, "outside", 0.0)?);
                proc(Procedural::Dots { mapping: mapping.clone(), inside, outside })
            }
            "fbm" | "wrinkled" | "marble" => {
                let octaves = p.int("octaves", 8)?;
                let omega = p.float("roughness", 0.5)?;
                if !(0..=64).contains(&octaves) || !omega.is_finite() {
                    return Err(loc.err(format!("{class}: need 0 <= octaves <= 64 ({octaves}) and a finite roughness ({omega})")));
                }
                let octaves = octaves as u32;
                match class {
                    "fbm" => proc(Procedural::Fbm { world_to_texture, omega, octaves }),
                    "wrinkled" => proc(Procedural::Wrinkled { world_to_texture, omega, octaves }),
                    _ => {
                        if is_float {
                            return Err(loc.err("marble is a spectrum texture in pbrt-v4 (Texture \"name\" \"spectrum\" \"marble\")"));
                        }
                        let (scale, variation) = (p.float("scale", 1.0)?, p.float("variation", 0.2)?);
                        if !(scale.is_finite() && variation.is_finite()) {
                            return Err(loc.err(format!("marble: 'scale' ({scale}) and 'variation' ({variation}) must be finite")));
                        }
                        proc(Procedural::Marble { world_to_texture, omega, octaves, scale, variation })
                    }
                }
            }
            "windy" => proc(Procedural::Windy { world_to_texture }),
            "ptex" => {
                return Err(loc.err("texture 'ptex' is not supported (svetlo reads no Ptex files)"));
            }
            other => return Err(loc.err(format!("unknown texture class '{other}'"))),
        };
        if matches!(class, "fbm" | "wrinkled" | "windy" | "marble") {
            self.warn(loc, format!("texture '{class}': no ray differentials, so every octave is summed (pbrt fades those finer than a pixel)"));
        }
        // Images and checkerboards under a non-uv mapping: looked up at the mapping's (s, t).
        let t = match (&mapping, &t) {
            (Mapping2D::Uv { .. }, _) => t,
            (_, Texture::Bitmap { .. } | Texture::Checkerboard { .. }) => proc(Procedural::Mapped { mapping, inner: t }),
            _ => t,
        };
        self.warn_unused(&format!("Texture \"{name}\""), p);
        if is_float {
            self.float_textures.insert(name.to_string(), t);
        } else {
            self.color_textures.insert(name.to_string(), t);
        }
        Ok(())
    }

    /// pbrt's uv mapping (s = su u + du, t = sv v + dv) to svetlo's lookup, whose v = 0 is
    /// the image's top row where pbrt's t = 0 is its bottom. Under another mapping the
    /// lookup takes (s, t) as given ([`Self::mapping2d`] computes them).
    fn uv_mapping(&mut self, p: &ParamList, _loc: &Loc) -> Result<Affine2> {
        let uv = p.string("mapping")?.is_none_or(|m| m == "uv");
        let (su, sv, du, dv) =
            if uv { (p.float("uscale", 1.0)?, p.float("vscale", 1.0)?, p.float("udelta", 0.0)?, p.float("vdelta", 0.0)?) } else { (1.0, 1.0, 0.0, 0.0) };
        Ok(Affine2::from_mat2_translation(Mat2::from_diagonal(Vec2::new(su, -sv)), Vec2::new(du, 1.0 - dv)))
    }

    /// pbrt's 2-D mapping of a texture, in the texture space of the current CTM.
    fn mapping2d(&mut self, p: &ParamList, loc: &Loc) -> Result<Mapping2D> {
        let world_to_texture = self.gs.ctm[0].inverse();
        if !world_to_texture.is_finite() {
            return Err(loc.err("texture: the current transform is not invertible"));
        }
        Ok(match p.string("mapping")?.unwrap_or("uv") {
            "uv" => Mapping2D::Uv { su: p.float("uscale", 1.0)?, sv: p.float("vscale", 1.0)?, du: p.float("udelta", 0.0)?, dv: p.float("vdelta", 0.0)? },
            "spherical" => Mapping2D::Spherical { world_to_texture },
            "cylindrical" => Mapping2D::Cylindrical { world_to_texture },
            "planar" => Mapping2D::Planar {
                world_to_texture,
                v1: p.point3("v1", Vec3::X)?,
                v2: p.point3("v2", Vec3::Y)?,
                ds: p.float("udelta", 0.0)?,
                dt: p.float("vdelta", 0.0)?,
            },
            other => return Err(loc.err(format!("texture mapping '{other}' is unknown (uv, spherical, cylindrical, planar)"))),
        })
    }

    /// An image as linear RGB: 8- and 16-bit files are sRGB-decoded unless `linear` (then
    /// code / max, as stored); float files as they are. 8-bit colour files keep their codes
    /// (`read_bitmap`, as Mitsuba's bitmaps): a third of the memory, the same values.
    pub(super) fn bitmap(&mut self, path: &std::path::Path, linear: bool, loc: &Loc) -> Result<std::sync::Arc<crate::texture::Bitmap>> {
        let key = (path.to_path_buf(), linear);
        if let Some(b) = self.bitmaps.get(&key) {
            return Ok(b.clone());
        }
        if !path.exists() {
            return Err(loc.err(format!("image '{}' not found", path.display())));
        }
        let b = crate::io::image_io::read_bitmap(path, linear)?;
        if b.width == 0 || b.height == 0 || b.texels().any(|c| !c.is_finite()) {
            return Err(loc.err(format!("image '{}' is empty or not finite", path.display())));
        }
        let b = std::sync::Arc::new(b);
        self.bitmaps.insert(key, b.clone());
        Ok(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Sellmeier tables reproduce each glass's catalogue index at the d line (587.56 nm).
    #[test]
    fn glasses_match_their_catalogue_nd() {
        let nd = [
            ("glass-BK7", 1.5168),
            ("glass-BAF10", 1.6700),
            ("glass-FK51A", 1.4866),
            ("glass-LASF9", 1.8503),
            ("glass-F5", 1.6727),
            ("glass-F10", 1.7283),
            ("glass-F11", 1.7847),
        ];
        for (name, want) in nd {
            let c = GLASSES.iter().find(|g| g.0 == name).unwrap().1;
            let got = sellmeier(&c, 587.56);
            assert!((got - want).abs() < 2e-3, "{name}: {got} vs {want}");
            let mean = named_glass_ior(name).unwrap() as f64;
            assert!((mean - want).abs() < 0.02, "{name}: mean {mean}");
        }
    }

    #[test]
    fn blackbody_chromaticity() {
        // 6504 K is close to D65: nearly white in sRGB; 2700 K is warm.
        let w = blackbody_rgb(6504.0);
        assert!((w.luminance() - 1.0).abs() < 1e-4);
        assert!((w.r - w.b).abs() < 0.08 && (w.g - 1.0).abs() < 0.05, "{w:?}");
        let warm = blackbody_rgb(2700.0);
        assert!(warm.r > warm.g && warm.g > warm.b, "{warm:?}");
    }

    #[test]
    fn named_metals() {
        assert_eq!(named_metal("metal-Ag-eta"), spectra::named_conductor("Ag").map(|c| c.0));
        assert_eq!(named_metal("metal-Au-k"), spectra::named_conductor("Au").map(|c| c.1));
        assert!(named_metal("metal-Xx-k").is_none() && named_metal("metal-Ag-q").is_none());
    }
}
