//! The modified Phong model of Lafortune and Willems (1994), Mitsuba 0.6's `phong`:
//! f = kd/π + ks (n+2)/(2π) cosⁿα, with α the angle between `wi` and the mirror direction
//! of `wo`. Reciprocal, and with kd + ks <= 1 it conserves energy (the glossy lobe's albedo
//! is at most 1, reached at normal incidence). Sampling mixes cosine sampling with the
//! density (n+1)/(2π) cosⁿα around the mirror direction (directions below the horizon are
//! rejected, which the mixture pdf accounts for by leaving that mass out).

use super::lobes::{around_axis, mixture_pdf, sample_mixture};
use super::{fresnel::reflect_z, BsdfSample, LobeFlags, TransportMode};
use crate::math::{INV_PI, PI};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Phong {
    pub diffuse_reflectance: Rgb,
    pub specular_reflectance: Rgb,
    pub exponent: f32,
    /// Probability of sampling the glossy lobe.
    pub specular_sampling_weight: f32,
}

impl Phong {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::DIFFUSE_REFLECTION | LobeFlags::GLOSSY_REFLECTION
    }

    #[inline]
    fn cos_alpha(wo: Vec3, wi: Vec3) -> f32 {
        reflect_z(wo).dot(wi)
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        let n = self.exponent;
        let ca = Self::cos_alpha(wo, wi);
        let lobe = if ca > 0.0 { (n + 2.0) / (2.0 * PI) * ca.powf(n) } else { 0.0 };
        self.diffuse_reflectance * INV_PI + self.specular_reflectance * lobe
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        let n = self.exponent;
        mixture_pdf(wo, wi, self.specular_sampling_weight, || {
            let ca = Self::cos_alpha(wo, wi);
            if ca > 0.0 {
                (n + 1.0) / (2.0 * PI) * ca.powf(n)
            } else {
                0.0
            }
        })
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let n = self.exponent;
        sample_mixture(
            wo,
            uc,
            u,
            self.specular_sampling_weight,
            |wo, u| Some(around_axis(reflect_z(wo), (1.0 - u.x).powf(1.0 / (n + 1.0)), 2.0 * PI * u.y)),
            |wi| self.eval(wo, wi, mode),
            |wi| self.pdf(wo, wi, mode),
        )
    }
}
