//! Emitter plugins other than `area` (which belongs to its shape).

use super::xml::Node;
use super::Loader;
use crate::error::Result;
use crate::io::spectra::SpectrumKind;
use crate::light::{EnvMap, Light};
use crate::math::Frame;
use crate::spectrum::Rgb;
use glam::{Mat4, Vec3};

impl<'a> Loader<'a> {
    pub(super) fn emitter(&mut self, node: &'a Node) -> Result<()> {
        let ty = node.type_()?;
        let to_world = self.transform(node, "to_world")?;
        let il = SpectrumKind::Illuminant;
        let light = match ty {
            "point" => {
                let position = match (self.vec3(node, "position")?, to_world) {
                    (Some(_), Some(_)) => return Err(node.loc.err("point light: give 'position' or 'to_world', not both")),
                    (Some(p), None) => p,
                    (None, Some(m)) => m.w_axis.truncate(),
                    (None, None) => Vec3::ZERO,
                };
                Light::Point { position, intensity: self.constant_color(node, "intensity", Rgb::WHITE, il)? }
            }
            "spot" => {
                let m = to_world.unwrap_or(Mat4::IDENTITY);
                let cutoff = self.float(node, "cutoff_angle", 20.0)?;
                let beam = self.float(node, "beam_width", cutoff * 0.75)?;
                if !(cutoff > 0.0 && cutoff <= 180.0 && beam > 0.0 && beam <= cutoff) {
                    return Err(node.loc.err(format!("spot light: need 0 < beam_width ({beam}) <= cutoff_angle ({cutoff}) <= 180")));
                }
                let texture = match self.prop(node, "texture")? {
                    Some(t) => Some(self.texture(t, crate::io::spectra::SpectrumKind::Reflectance)?),
                    None => None,
                };
                let n = m.transform_vector3(Vec3::Z).normalize_or_zero();
                if n == Vec3::ZERO {
                    return Err(node.loc.err("spot light: degenerate to_world"));
                }
                let s = m.transform_vector3(Vec3::X);
                let frame = Frame::from_normal_tangent(n, s);
                let (cutoff, beam) = (cutoff.to_radians(), beam.to_radians());
                Light::Spot {
                    position: m.w_axis.truncate(),
                    frame,
                    intensity: self.constant_color(node, "intensity", Rgb::WHITE, il)?,
                    cos_cutoff: cutoff.cos(),
                    cos_beam: beam.cos(),
                    cutoff_angle: cutoff,
                    tan_cutoff: cutoff.tan(),
                    beam_width: beam,
                    texture,
                }
            }
            "directional" => {
                let d = match (self.vec3(node, "direction")?, to_world) {
                    (Some(_), Some(_)) => return Err(node.loc.err("directional light: give 'direction' or 'to_world', not both")),
                    (Some(d), None) => d,
                    (None, Some(m)) => m.transform_vector3(Vec3::Z),
                    (None, None) => Vec3::Z,
                };
                let direction = d.normalize_or_zero();
                if direction == Vec3::ZERO || !direction.is_finite() {
                    return Err(node.loc.err("directional light: zero direction"));
                }
                Light::Directional { direction, irradiance: self.constant_color(node, "irradiance", Rgb::WHITE, il)? }
            }
            "constant" => Light::Constant { radiance: self.constant_color(node, "radiance", Rgb::WHITE, il)? },
            "envmap" => {
                let path = self.file_prop(node)?;
                let scale = self.float(node, "scale", 1.0)?;
                if !(scale >= 0.0 && scale.is_finite()) {
                    return Err(node.loc.err(format!("envmap scale must be non-negative, got {scale}")));
                }
                let image = self.bitmap(&path, false)?;
                Light::EnvMap(Box::new(EnvMap::new(image, to_world.unwrap_or(Mat4::IDENTITY), scale)))
            }
            "ies" => self.luminaire(node, to_world)?,
            "cie_sky" => {
                // A CIE standard sky (photometry::sky), Z up, azimuth from +Y toward +X; the
                // sun's direct beam, when sun_illuminance (lx, normal to the beam) is given,
                // as a directional light beside it.
                let sky_type = self.int(node, "type", crate::photometry::sky::TRADITIONAL_OVERCAST as i64)?;
                let el = self.float(node, "sun_elevation", 45.0)? as f64;
                let az = self.float(node, "sun_azimuth", 180.0)? as f64;
                let mut sky =
                    crate::photometry::sky::CieSky::new(u32::try_from(sky_type).unwrap_or(0), el, az).map_err(|e| node.loc.err(format!("cie_sky: {e}")))?;
                let lz = self.float(node, "zenith_luminance", -1.0)? as f64;
                let eh = self.float(node, "horizontal_illuminance", -1.0)? as f64;
                sky.zenith_luminance = match (lz, eh) {
                    (l, e) if l >= 0.0 && e >= 0.0 => return Err(node.loc.err("cie_sky: give zenith_luminance or horizontal_illuminance, not both")),
                    (l, _) if l >= 0.0 && l.is_finite() => l,
                    (_, e) if e >= 0.0 && e.is_finite() => e / sky.horizontal_illuminance(),
                    (l, e) if l == -1.0 && e == -1.0 => 10_000.0 / sky.horizontal_illuminance(),
                    _ => return Err(node.loc.err("cie_sky: zenith_luminance and horizontal_illuminance must be non-negative")),
                };
                let width = self.int(node, "resolution", 512)?;
                if !(8..=8192).contains(&width) {
                    return Err(node.loc.err(format!("cie_sky: resolution {width} must be within 8-8192")));
                }
                let sun = self.float(node, "sun_illuminance", 0.0)? as f64;
                if !(sun >= 0.0 && sun.is_finite()) {
                    return Err(node.loc.err(format!("cie_sky: sun_illuminance must be non-negative, got {sun}")));
                }
                if sun > 0.0 {
                    let e = (sun / crate::photometry::LM_PER_W) as f32;
                    self.b.add_light(Light::Directional { direction: -crate::photometry::sky::direction(el, az), irradiance: Rgb::new(e, e, e) });
                }
                Light::EnvMap(Box::new(sky.env_map(width as usize)))
            }
            "projector" => {
                let m = to_world.unwrap_or(Mat4::IDENTITY);
                let irradiance = self.spectrum(node, "irradiance", Rgb::WHITE, il)?;
                // The image's aspect ratio shapes the frustum; a constant is square.
                let aspect = match &irradiance {
                    crate::texture::Texture::Bitmap { image, .. } => image.width as f32 / image.height as f32,
                    _ => 1.0,
                };
                let scale = self.float(node, "scale", 1.0)?;
                if !(scale >= 0.0 && scale.is_finite()) {
                    return Err(node.loc.err(format!("projector scale must be non-negative, got {scale}")));
                }
                // fov / fov_axis / focal_length as a sensor reads them (0 < fov < 180).
                let fov_x = self.fov_x(node, aspect)?;
                let p = crate::light::Projector::new(&m, fov_x, aspect, irradiance, scale).ok_or_else(|| node.loc.err("projector: degenerate to_world"))?;
                Light::Projector(Box::new(p))
            }
            "area" => return Err(node.loc.err("an area emitter must be attached to a shape")),
            other => return Err(node.loc.err(format!("unknown emitter type '{other}'"))),
        };
        self.b.add_light(light);
        Ok(())
    }
}
