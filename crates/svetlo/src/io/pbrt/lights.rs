//! pbrt-v4 lights. pbrt's RGB illuminant convention: an `rgb L [r g b]` is pbrt's
//! RGBIlluminantSpectrum (the sRGB colour times the colour space's D65 illuminant) divided by
//! the D65 illuminant's luminance, so on an sRGB film it reads back as (r, g, b): in svetlo's
//! RGB rendering it becomes linear Rec. 709 radiance (r, g, b) × `scale`, exactly. Every
//! other spectrum (blackbody, sampled, named) is divided by its own luminance as pbrt does,
//! so it keeps only its colour: luminance 1 × `scale`. `power` (area, point, spot) and
//! `illuminance` (distant, infinite) then rescale so that the light emits that much
//! (luminance-weighted, as pbrt's photometric normalisation). The film's `iso` and the
//! shutter's exposure time scale every light by pbrt's imaging ratio (iso/100 × exposure).

use super::lexer::Loc;
use super::params::ParamList;
use super::{AreaEmission, Loader};
use crate::error::Result;
use crate::geometry::Geometry;
use crate::io::spectra::SpectrumKind;
use crate::light::{EnvMap, Goniometric, Light, Projector};
use crate::math::PI;
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Mat4, Vec3};

impl Loader {
    /// An emitted spectrum: pbrt's convention (module notes) times `scale`.
    fn emitted(&self, p: &ParamList, name: &str, loc: &Loc) -> Result<Rgb> {
        let c = match p.spectrum(name)? {
            Some((v, l)) => self.spectrum_rgb(&v, SpectrumKind::Illuminant, l)?,
            // pbrt's default is the colour space's illuminant, luminance 1: white.
            None => Rgb::WHITE,
        };
        let scale = p.float("scale", 1.0)?;
        if !(scale >= 0.0 && scale.is_finite()) {
            return Err(loc.err(format!("light 'scale' must be non-negative, got {scale}")));
        }
        if !c.is_finite() || c.min_component() < 0.0 {
            return Err(loc.err(format!("light '{name}' must be finite and non-negative, got {c:?}")));
        }
        Ok(c * scale * self.imaging_ratio)
    }

    pub(super) fn light(&mut self, ty: &str, p: &ParamList, loc: &Loc) -> Result<()> {
        let m = self.gs.ctm[0];
        if !self.gs.ctm[0].abs_diff_eq(self.gs.ctm[1], 0.0) {
            self.warn(loc, "lights cannot move in svetlo: the start transform is used");
        }
        let light = match ty {
            "point" => {
                let mut i = self.emitted(p, "I", loc)?;
                let from = p.point3("from", Vec3::ZERO)?;
                if let Some(power) = p.opt_float("power")? {
                    i = rescale(i, power, 4.0 * PI);
                }
                Light::Point { position: m.transform_point3(from), intensity: i }
            }
            "spot" => {
                let mut i = self.emitted(p, "I", loc)?;
                let (from, to) = (p.point3("from", Vec3::ZERO)?, p.point3("to", Vec3::Z)?);
                let cone = p.float("coneangle", 30.0)?;
                let delta = p.float("conedelta", 5.0)?;
                if !(cone > 0.0 && cone <= 180.0 && delta >= 0.0) {
                    return Err(loc.err(format!("spot: need 0 < coneangle ({cone}) <= 180 and conedelta ({delta}) >= 0")));
                }
                let start = (cone - delta).max(1e-3);
                if let Some(power) = p.opt_float("power")? {
                    let (c0, c1) = (start.to_radians().cos(), cone.to_radians().cos());
                    i = rescale(i, power, 2.0 * PI * (1.0 - 0.5 * (c0 + c1)));
                }
                self.warn(
                    loc,
                    "spot: pbrt's smoothstep falloff between coneangle - conedelta and coneangle is rendered with svetlo's (Mitsuba's) linear-in-angle falloff",
                );
                let dir = (to - from).normalize_or_zero();
                if dir == Vec3::ZERO {
                    return Err(loc.err("spot: 'from' equals 'to'"));
                }
                let up = if dir.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
                let local =
                    Mat4::from_cols(up.cross(dir).normalize().extend(0.0), dir.cross(up.cross(dir).normalize()).extend(0.0), dir.extend(0.0), from.extend(1.0));
                Light::spot(&(m * local), i, cone, Some(start))
            }
            "distant" => {
                let mut l = self.emitted(p, "L", loc)?;
                let (from, to) = (p.point3("from", Vec3::ZERO)?, p.point3("to", Vec3::new(0.0, 0.0, 1.0))?);
                if let Some(e) = p.opt_float("illuminance")? {
                    l = rescale(l, e, 1.0);
                }
                let d = m.transform_vector3(to - from).normalize_or_zero();
                if d == Vec3::ZERO || !d.is_finite() {
                    return Err(loc.err("distant: 'from' equals 'to'"));
                }
                Light::Directional { direction: d, irradiance: l }
            }
            "infinite" => {
                if p.get("portal").is_some() {
                    self.warn(loc, "infinite: 'portal' ignored (plain importance sampling)");
                }
                match p.string("filename")?.map(str::to_string) {
                    None => {
                        let mut l = self.emitted(p, "L", loc)?;
                        if let Some(e) = p.opt_float("illuminance")? {
                            // Upper-hemisphere irradiance of constant radiance L is π L.
                            l = rescale(l, e, PI);
                        }
                        Light::Constant { radiance: l }
                    }
                    Some(file) => {
                        if p.get("L").is_some() {
                            return Err(loc.err("infinite: give either 'L' or 'filename', not both"));
                        }
                        let scale = p.float("scale", 1.0)? * self.imaging_ratio;
                        let path = self.resolve(&file, loc);
                        let img = self.bitmap(&path, true, loc)?;
                        if img.width != img.height {
                            return Err(loc.err(format!(
                                "infinite: '{file}' is {}x{}; pbrt-v4 environment maps are square (equal-area octahedral)",
                                img.width, img.height
                            )));
                        }
                        let latlong = super::camera::equal_area_to_latlong(&img);
                        let mut scale = scale;
                        if let Some(e) = p.opt_float("illuminance")? {
                            let up = super::camera::upper_irradiance(&img);
                            if up > 0.0 {
                                scale *= e / up;
                            }
                        }
                        Light::EnvMap(Box::new(EnvMap::new(std::sync::Arc::new(latlong), m * super::camera::LATLONG_FROM_PBRT, scale)))
                    }
                }
            }
            "goniometric" => self.goniometric(p, &m, loc)?,
            "projection" => self.projection(p, &m, loc)?,
            other => return Err(loc.err(format!("unknown light '{other}'"))),
        };
        self.warn_unused(&format!("LightSource \"{ty}\""), p);
        self.b.add_light(light);
        Ok(())
    }

    /// pbrt-v4's goniometric light (light/goniometric.rs): `I` × `scale` (pbrt's emitter
    /// convention) × the image's channel mean per texel; `power` rescales to that many watts
    /// (luminance), over the image's 4π × mean.
    fn goniometric(&mut self, p: &ParamList, m: &Mat4, loc: &Loc) -> Result<Light> {
        let mut i = self.emitted(p, "I", loc)?;
        let (values, res) = match p.string("filename")?.map(str::to_string) {
            None => {
                self.warn(loc, "goniometric: no 'filename'; it emits like a point light");
                (vec![1.0], 1)
            }
            Some(file) => {
                let path = self.resolve(&file, loc);
                let img = self.bitmap(&path, false, loc)?;
                if img.width != img.height {
                    return Err(loc.err(format!(
                        "goniometric: '{file}' is {}x{}; pbrt-v4's goniometric images are square (equal-area octahedral)",
                        img.width, img.height
                    )));
                }
                // pbrt keeps one channel: the mean of R, G and B.
                (img.texels().map(|c| ((c.r + c.g + c.b) / 3.0).max(0.0)).collect(), img.width)
            }
        };
        let to_world = *m * Goniometric::pbrt_swap_yz();
        let g = Goniometric::new(&to_world, i, values.clone(), res).ok_or_else(|| loc.err("goniometric: degenerate transform or image"))?;
        if let Some(power) = p.opt_float("power")? {
            if !(power >= 0.0 && power.is_finite()) {
                return Err(loc.err(format!("goniometric: 'power' must be non-negative, got {power}")));
            }
            if power > 0.0 {
                i = rescale(i, power, g.solid_angle_weight());
                let g = Goniometric::new(&to_world, i, values, res).ok_or_else(|| loc.err("goniometric: degenerate transform or image"))?;
                return Ok(Light::Goniometric(Box::new(g)));
            }
        }
        Ok(Light::Goniometric(Box::new(g)))
    }

    /// pbrt-v4's projection light (light/projector.rs, pbrt's model): the image is the
    /// radiant intensity × `scale`, `fov` (default 90°) across its shorter axis; `power`
    /// rescales to that many watts (luminance).
    fn projection(&mut self, p: &ParamList, m: &Mat4, loc: &Loc) -> Result<Light> {
        let file = p.string("filename")?.ok_or_else(|| loc.err("projection: needs \"string filename\""))?.to_string();
        let scale = p.float("scale", 1.0)?;
        if !(scale >= 0.0 && scale.is_finite()) {
            return Err(loc.err(format!("light 'scale' must be non-negative, got {scale}")));
        }
        let fov = p.float("fov", 90.0)?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(loc.err(format!("projection: 'fov' must be in (0, 180) degrees, got {fov}")));
        }
        let path = self.resolve(&file, loc);
        let img = self.bitmap(&path, false, loc)?;
        let scale = scale * self.imaging_ratio;
        let mut pr = Projector::pbrt(m, fov, img.clone(), scale).ok_or_else(|| loc.err("projection: degenerate transform"))?;
        if let Some(power) = p.opt_float("power")? {
            if !(power >= 0.0 && power.is_finite()) {
                return Err(loc.err(format!("projection: 'power' must be non-negative, got {power}")));
            }
            let unit = pr.unit_power();
            if power > 0.0 && unit > 0.0 {
                pr = Projector::pbrt(m, fov, img, power / unit).ok_or_else(|| loc.err("projection: degenerate transform"))?;
            }
        }
        Ok(Light::Projector(Box::new(pr)))
    }

    pub(super) fn area_light_source(&mut self, ty: &str, p: &ParamList, loc: &Loc) -> Result<()> {
        if ty != "diffuse" {
            return Err(loc.err(format!("unknown area light '{ty}' (pbrt-v4 has \"diffuse\")")));
        }
        let two_sided = p.bool("twosided", false)?;
        let power = p.opt_float("power")?;
        let radiance = match p.string("filename")?.map(str::to_string) {
            Some(file) => {
                if p.get("L").is_some() {
                    return Err(loc.err("diffuse area light: give either 'L' or 'filename', not both"));
                }
                let path = self.resolve(&file, loc);
                let image = self.bitmap(&path, false, loc)?;
                let s = p.float("scale", 1.0)? * self.imaging_ratio;
                let mut im = (*image).clone();
                for c in im.data_mut() {
                    *c *= s;
                }
                let to_uv = glam::Affine2::from_mat2_translation(glam::Mat2::from_diagonal(glam::Vec2::new(1.0, -1.0)), glam::Vec2::new(0.0, 1.0));
                Texture::Bitmap { image: std::sync::Arc::new(im), filter: crate::texture::FilterMode::Bilinear, wrap: crate::texture::WrapMode::Repeat, to_uv }
            }
            None => Texture::Constant(self.emitted(p, "L", loc)?),
        };
        if two_sided {
            self.warn(loc, "diffuse area light: 'twosided' is not supported yet; it emits on the front side only");
        }
        self.warn_unused("AreaLightSource \"diffuse\"", p);
        self.gs.area_light = Some(AreaEmission { radiance, two_sided, power, loc: loc.clone() });
        Ok(())
    }

    /// The radiance texture of an area light on `geometry`, scaled for `power` if given.
    pub(super) fn emission_for(&mut self, a: AreaEmission, geometry: &Geometry) -> Result<Texture> {
        let Some(power) = a.power else { return Ok(a.radiance) };
        let area = geometry.area();
        let sides = if a.two_sided { 2.0 } else { 1.0 };
        let y = a.radiance.mean().luminance();
        if !(area > 0.0 && y > 0.0) {
            return Ok(a.radiance);
        }
        let k = power / (PI * area * sides * y);
        Ok(match a.radiance {
            Texture::Constant(c) => Texture::Constant(c * k),
            Texture::Bitmap { image, filter, wrap, to_uv } => {
                let mut im = (*image).clone();
                for c in im.data_mut() {
                    *c *= k;
                }
                Texture::Bitmap { image: std::sync::Arc::new(im), filter, wrap, to_uv }
            }
            other => other,
        })
    }

    pub(super) fn add_two_sided_emitter(&mut self, geometry: Geometry, material: u32, emission: Option<Texture>, name: &str, a: &AreaEmission) -> Result<()> {
        if self.animation(&a.loc)?.is_some() {
            return Err(a.loc.err("an emitting shape cannot move (moving area lights are not supported)"));
        }
        self.b.add_shape(geometry, material, emission, name).map_err(|e| a.loc.err(e.to_string()))
    }
}

/// Scale `c` so that its luminance times `k_e` (the light's geometric factor) equals `target`.
fn rescale(c: Rgb, target: f32, k_e: f32) -> Rgb {
    let y = c.luminance() * k_e;
    if y > 0.0 {
        c * (target / y)
    } else {
        c
    }
}
