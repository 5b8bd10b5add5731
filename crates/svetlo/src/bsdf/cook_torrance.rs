//! Cook-Torrance (1982) in its original form: a Lambertian base plus
//! ks F(wo·h) D(h) G(wo, wi) / (4 cos θo cos θi), with Beckmann's distribution D, the
//! Torrance-Sparrow V-groove shadowing G = min(1, 2 cos θh cos θo / (wo·h),
//! 2 cos θh cos θi / (wo·h)) and the dielectric Fresnel reflectance F.
//!
//! The 1982 paper writes F D G / (π cos θo cos θi) with a Beckmann D that lacks the 1/π of
//! the normalised one: that lobe is 4 times the microfacet derivation's and can reflect
//! more than it receives. We use the normalised D (∫ D cos θh dω = 1) with the 4 of the
//! microfacet derivation (Walter et al. 2007); the V-groove G is a valid masking
//! function (Heitz 2014), so the lobe's albedo is at most F <= 1.

use super::fresnel;
use super::lobes::{beckmann_normal_pdf, mixture_pdf, sample_beckmann_normal, sample_mixture};
use super::{fresnel::reflect, BsdfSample, LobeFlags, TransportMode};
use crate::math::INV_PI;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct CookTorrance {
    pub diffuse_reflectance: Rgb,
    pub specular_reflectance: Rgb,
    /// Beckmann RMS slope m.
    pub alpha: f32,
    /// Interior / exterior index of refraction for the Fresnel term.
    pub eta: f32,
    pub specular_sampling_weight: f32,
}

/// Torrance-Sparrow V-groove shadowing and masking.
pub fn v_groove_g(wo: Vec3, wi: Vec3, h: Vec3) -> f32 {
    let oh = wo.dot(h);
    if oh <= 0.0 {
        return 0.0;
    }
    (2.0 * h.z * wo.z / oh).min(2.0 * h.z * wi.z / oh).clamp(0.0, 1.0)
}

impl CookTorrance {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::DIFFUSE_REFLECTION | LobeFlags::GLOSSY_REFLECTION
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        let h = (wo + wi).normalize();
        let a = self.alpha;
        // D(h) = pdf(h) / cos θh.
        let d = beckmann_normal_pdf(a, a, h) / h.z;
        let g = v_groove_g(wo, wi, h);
        let f = fresnel::dielectric(wo.dot(h), self.eta).0;
        let lobe = f * d * g / (4.0 * wo.z * wi.z);
        let lobe = if lobe.is_finite() { lobe } else { 0.0 };
        self.diffuse_reflectance * INV_PI + self.specular_reflectance * lobe
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        mixture_pdf(wo, wi, self.specular_sampling_weight, || {
            let h = (wo + wi).normalize();
            let oh = wo.dot(h);
            if oh <= 0.0 {
                return 0.0;
            }
            beckmann_normal_pdf(self.alpha, self.alpha, h) / (4.0 * oh)
        })
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        sample_mixture(
            wo,
            uc,
            u,
            self.specular_sampling_weight,
            |wo, u| Some(reflect(wo, sample_beckmann_normal(self.alpha, self.alpha, u))),
            |wi| self.eval(wo, wi, mode),
            |wi| self.pdf(wo, wi, mode),
        )
    }
}
