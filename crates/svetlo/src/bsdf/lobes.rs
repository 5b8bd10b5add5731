//! What the classic two-lobe models (a diffuse base plus one glossy lobe: Phong, Blinn-Phong,
//! Cook-Torrance, Ward) share: choosing a lobe to sample, and the cosine-weighted base.

use super::{positive_finite, BsdfSample, LobeFlags};
use crate::math::warp;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// Probability of sampling the glossy lobe: its share of the mean reflectance (Mitsuba's
/// `specularSamplingWeight` default). Only the variance depends on it.
pub fn glossy_sampling_weight(diffuse: Rgb, specular: Rgb) -> f32 {
    let (d, s) = (diffuse.mean().max(0.0), specular.mean().max(0.0));
    if d + s > 0.0 {
        s / (d + s)
    } else {
        0.5
    }
}

/// Draw `wi` from the mixture: the glossy lobe's sampler with probability `p_glossy`, cosine
/// sampling otherwise; then report `f` and the mixture's `pdf` from the model's own
/// `eval` and `pdf` (so that the sample agrees with them by construction).
pub fn sample_mixture(
    wo: Vec3,
    uc: f32,
    u: Vec2,
    p_glossy: f32,
    glossy: impl Fn(Vec3, Vec2) -> Option<Vec3>,
    eval: impl Fn(Vec3) -> Rgb,
    pdf: impl Fn(Vec3) -> f32,
) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let (wi, lobe) =
        if uc < p_glossy { (glossy(wo, u)?, LobeFlags::GLOSSY_REFLECTION) } else { (warp::square_to_cosine_hemisphere(u), LobeFlags::DIFFUSE_REFLECTION) };
    if wi.z <= 0.0 {
        return None;
    }
    let pdf = pdf(wi);
    if !positive_finite(pdf) {
        return None;
    }
    Some(BsdfSample { wi, f: eval(wi), pdf, lobe, eta: 1.0 })
}

/// Mixture density: `p_glossy * glossy + (1 - p_glossy) * cos / pi`, upper hemisphere only.
#[inline]
pub fn mixture_pdf(wo: Vec3, wi: Vec3, p_glossy: f32, glossy_pdf: impl Fn() -> f32) -> f32 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    let g = if p_glossy > 0.0 { p_glossy * glossy_pdf() } else { 0.0 };
    g + (1.0 - p_glossy) * warp::square_to_cosine_hemisphere_pdf(wi)
}

/// A unit vector at polar angle acos(`cos_t`) and azimuth `phi` around the unit axis `axis`.
pub fn around_axis(axis: Vec3, cos_t: f32, phi: f32) -> Vec3 {
    let f = crate::math::Frame::from_normal(axis);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    f.to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t))
}

/// Normals distributed as Beckmann's D(m) cos(θm) with roughness (`ax`, `ay`): slopes are
/// Gaussian with variances ax²/2 and ay²/2 (the sampling Walter 2005 derived for Ward).
pub fn sample_beckmann_normal(ax: f32, ay: f32, u: Vec2) -> Vec3 {
    let r = (-(1.0 - u.x).max(1e-12).ln()).sqrt();
    let phi = 2.0 * crate::math::PI * u.y;
    let (sx, sy) = (ax * r * phi.cos(), ay * r * phi.sin());
    Vec3::new(-sx, -sy, 1.0).normalize()
}

/// Density of [`sample_beckmann_normal`] over normals (solid angle): D(m) cos θm.
pub fn beckmann_normal_pdf(ax: f32, ay: f32, m: Vec3) -> f32 {
    if m.z <= 0.0 {
        return 0.0;
    }
    let c2 = m.z * m.z;
    let e = ((m.x / ax).powi(2) + (m.y / ay).powi(2)) / c2;
    let p = (-e).exp() / (crate::math::PI * ax * ay * c2 * m.z);
    if p.is_finite() {
        p
    } else {
        0.0
    }
}
