//! Oren-Nayar (1994), the qualitative model, as Mitsuba 0.6's `roughdiffuse` with
//! `useFastApprox`: f = ρ/π (A + B max(0, cos(φi - φo)) sin α tan β), α = max(θi, θo),
//! β = min(θi, θo), A = 1 - σ²/(2(σ² + 0.33)), B = 0.45 σ²/(σ² + 0.09). The roughness is
//! given as Beckmann's RMS slope α_b and converted as Mitsuba does, σ = α_b / √2.
//! Cosine-weighted sampling.

use super::{BsdfSample, LobeFlags, TransportMode};
use crate::math::{warp, INV_PI};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct OrenNayar {
    pub reflectance: Rgb,
    /// σ, the standard deviation of the facet angle (radians).
    pub sigma: f32,
}

impl OrenNayar {
    /// From Mitsuba's `alpha` (RMS slope).
    pub fn from_alpha(reflectance: Rgb, alpha: f32) -> Self {
        OrenNayar { reflectance, sigma: alpha.max(0.0) * std::f32::consts::FRAC_1_SQRT_2 }
    }

    pub fn flags(&self) -> LobeFlags {
        LobeFlags::DIFFUSE_REFLECTION
    }

    /// The factor multiplying ρ/π.
    pub fn factor(&self, wo: Vec3, wi: Vec3) -> f32 {
        let s2 = self.sigma * self.sigma;
        let a = 1.0 - 0.5 * s2 / (s2 + 0.33);
        let b = 0.45 * s2 / (s2 + 0.09);
        let sin_i = (1.0 - wi.z * wi.z).max(0.0).sqrt();
        let sin_o = (1.0 - wo.z * wo.z).max(0.0).sqrt();
        let cos_dphi = if sin_i > 1e-4 && sin_o > 1e-4 { ((wi.x * wo.x + wi.y * wo.y) / (sin_i * sin_o)).clamp(-1.0, 1.0) } else { 0.0 };
        // α is the larger angle: sin α from the smaller cosine, tan β from the larger.
        let (sin_alpha, tan_beta) = if wi.z > wo.z { (sin_o, sin_i / wi.z) } else { (sin_i, sin_o / wo.z) };
        a + b * cos_dphi.max(0.0) * sin_alpha * tan_beta
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        self.reflectance * (INV_PI * self.factor(wo, wi))
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        warp::square_to_cosine_hemisphere_pdf(wi)
    }

    pub fn sample(&self, wo: Vec3, _uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = warp::square_to_cosine_hemisphere(u);
        let pdf = self.pdf(wo, wi, mode);
        if !super::positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample { wi, f: self.eval(wo, wi, mode), pdf, lobe: LobeFlags::DIFFUSE_REFLECTION, eta: 1.0 })
    }
}
