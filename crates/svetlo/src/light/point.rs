//! Point and spot lights (delta positions), with Mitsuba 3's semantics: `intensity` is the
//! radiant intensity (W/sr) at the center of the beam; the spot's profile is 1 inside
//! `beam_width`, falls linearly *in angle* to 0 at `cutoff_angle`
//! ((cutoff - θ) / (cutoff - beam_width)), and is 0 beyond. Defaults: cutoff 20°,
//! beam width 3/4 of the cutoff.

use super::Light;
use crate::math::{Frame, PI};
use crate::spectrum::Rgb;
use glam::{Mat4, Vec3};

/// Mitsuba 3's spot profile at cos θ from the spot's axis.
#[inline]
pub(super) fn spot_falloff(cos_theta: f32, cos_cutoff: f32, cos_beam: f32, cutoff_angle: f32, beam_width: f32) -> f32 {
    if cos_theta <= cos_cutoff {
        return 0.0;
    }
    if cos_theta >= cos_beam {
        return 1.0;
    }
    ((cutoff_angle - cos_theta.clamp(-1.0, 1.0).acos()) / (cutoff_angle - beam_width)).clamp(0.0, 1.0)
}

/// ∫ falloff dω over the sphere, in closed form: with a = beam width, b = cutoff,
/// 2π [ (1 - cos a) + ∫_a^b (b - θ)/(b - a) sin θ dθ ] = 2π [1 - (sin b - sin a) / (b - a)].
pub(super) fn spot_solid_angle(cutoff_angle: f32, beam_width: f32) -> f32 {
    let (a, b) = (beam_width as f64, cutoff_angle as f64);
    let w = if b - a > 1e-6 { 1.0 - (b.sin() - a.sin()) / (b - a) } else { 1.0 - b.cos() };
    (2.0 * std::f64::consts::PI * w) as f32
}

impl Light {
    /// A point light at `position` with radiant intensity `intensity` (W/sr).
    pub fn point(position: Vec3, intensity: Rgb) -> Light {
        Light::Point { position, intensity }
    }

    /// A Mitsuba `spot` light: at the origin of `to_world`, shining along its +z axis.
    /// Angles in degrees; `beam_width_deg` defaults to 3/4 of the cutoff and is clamped to it.
    pub fn spot(to_world: &Mat4, intensity: Rgb, cutoff_deg: f32, beam_width_deg: Option<f32>) -> Light {
        let cutoff_angle = cutoff_deg.to_radians();
        let beam_width = beam_width_deg.map_or(0.75 * cutoff_angle, |b| b.to_radians()).min(cutoff_angle);
        let position = to_world.transform_point3(Vec3::ZERO);
        let axis = to_world.transform_vector3(Vec3::Z).normalize_or_zero();
        let axis = if axis == Vec3::ZERO { Vec3::Z } else { axis };
        let frame = Frame::from_normal_tangent(axis, to_world.transform_vector3(Vec3::X));
        Light::Spot {
            position,
            frame,
            intensity,
            cos_cutoff: cutoff_angle.cos(),
            cos_beam: beam_width.cos(),
            cutoff_angle,
            tan_cutoff: cutoff_angle.tan(),
            beam_width,
            texture: None,
        }
    }

    /// The spot's profile toward world direction `w` (leaving the light); 1 for other lights.
    #[inline]
    pub fn spot_falloff(&self, w: Vec3) -> f32 {
        match *self {
            Light::Spot { frame, cos_cutoff, cos_beam, cutoff_angle, beam_width, .. } => {
                spot_falloff(frame.n.dot(w), cos_cutoff, cos_beam, cutoff_angle, beam_width)
            }
            _ => 1.0,
        }
    }

    /// Asks for the texels a textured spot's [`Light::sample_li`] from `p_ref` will read, ahead
    /// of it (a large projected texture's lookups wait on memory); a hint, for any light.
    #[inline]
    pub fn prefetch_li(&self, p_ref: Vec3) {
        if let Light::Spot { position, frame, tan_cutoff, texture: Some(tex), .. } = self {
            // `spot_intensity`'s mapping, whose uv does not depend on the direction's length.
            let l = frame.to_local(p_ref - *position);
            let k = 0.5 / (l.z * tan_cutoff);
            tex.prefetch(glam::Vec2::new(0.5 + l.x * k, 0.5 + l.y * k));
        }
    }

    /// Radiant intensity of a spot light (or a luminaire) toward world direction `w` (unit): the intensity times
    /// the falloff and, as Mitsuba 3 does, a texture projected over the cone: local direction
    /// (x, y, z) maps to uv = 1/2 + (x, y) / (2 z tan(cutoff)).
    pub fn spot_intensity(&self, w: Vec3) -> Rgb {
        match self {
            Light::Spot { .. } => self.spot_intensity_with::<false>(w),
            Light::Luminaire(l) => l.intensity(w),
            _ => Rgb::BLACK,
        }
    }

    /// [`Self::spot_intensity`] of a spot (black for other lights), its texture looked up by
    /// `Texture::eval_inline` where `INLINE` (the same value as `eval`).
    #[inline(always)]
    fn spot_intensity_with<const INLINE: bool>(&self, w: Vec3) -> Rgb {
        match self {
            Light::Spot { frame, intensity, texture, .. } => {
                let fall = self.spot_falloff(w);
                if fall <= 0.0 {
                    return Rgb::BLACK;
                }
                let mut i = *intensity * fall;
                if let (Some(tex), Light::Spot { tan_cutoff, .. }) = (texture, self) {
                    let l = frame.to_local(w);
                    let k = 0.5 / (l.z * tan_cutoff);
                    let uv = glam::Vec2::new(0.5 + l.x * k, 0.5 + l.y * k);
                    i *= if INLINE { tex.eval_inline(&uv.into()) } else { tex.eval(uv) };
                }
                i
            }
            _ => Rgb::BLACK,
        }
    }

    /// [`Light::sample_li`] of a spot from `p_ref` (None for other lights), inline at the call
    /// site with its texture's bilinear lookup too (`Texture::eval_inline`): for a caller's
    /// vector build (`direct`'s lockstep tiles), where its floors are single instructions.
    #[inline(always)]
    pub fn spot_sample_li_inline(&self, p_ref: Vec3) -> Option<super::LightSample> {
        let Light::Spot { position, .. } = self else { return None };
        let d = *position - p_ref;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let i = self.spot_intensity_with::<true>(-wi);
        if i.is_black() {
            return None;
        }
        Some(super::LightSample { wi, li: i / dist2, pdf: 1.0, p: *position, n: Vec3::ZERO, infinite: false })
    }
}

/// Uniform sphere pdf, for point lights' emission.
pub(super) const POINT_PDF_DIR: f32 = 1.0 / (4.0 * PI);
