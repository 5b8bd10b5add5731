//! Normalised Blinn-Phong: f = kd/π + ks (n+1)/(8π) cosⁿθh / max(cos θi, cos θo).
//!
//! The common normalisation (n+8)/(8π) without the denominator overshoots: its albedo at
//! normal incidence is n(n+8)/((n+2)(n+4)) > 1 for n > 4 (1.8 % at n = 100), so it fails
//! a white furnace. Dividing by max(cos θi, cos θo) (Neumann, Neumann and Szirmay-Kalos
//! 1999) bounds the albedo by ∫ (n+1)/(2π) cosⁿθh dωh (wo·h) <= 1 exactly, keeps the model
//! reciprocal, and at normal incidence is the usual normalised lobe. Sampling draws h with
//! density (n+1)/(2π) cosⁿθh and reflects wo about it.

use super::lobes::{around_axis, mixture_pdf, sample_mixture};
use super::{fresnel::reflect, BsdfSample, LobeFlags, TransportMode};
use crate::math::{INV_PI, PI};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct BlinnPhong {
    pub diffuse_reflectance: Rgb,
    pub specular_reflectance: Rgb,
    pub exponent: f32,
    pub specular_sampling_weight: f32,
}

impl BlinnPhong {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::DIFFUSE_REFLECTION | LobeFlags::GLOSSY_REFLECTION
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        let n = self.exponent;
        let h = (wo + wi).normalize();
        let lobe = (n + 1.0) / (8.0 * PI) * h.z.max(0.0).powf(n) / wo.z.max(wi.z);
        self.diffuse_reflectance * INV_PI + self.specular_reflectance * lobe
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        let n = self.exponent;
        mixture_pdf(wo, wi, self.specular_sampling_weight, || {
            let h = (wo + wi).normalize();
            let oh = wo.dot(h);
            if oh <= 0.0 || h.z <= 0.0 {
                return 0.0;
            }
            (n + 1.0) / (2.0 * PI) * h.z.powf(n) / (4.0 * oh)
        })
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let n = self.exponent;
        sample_mixture(
            wo,
            uc,
            u,
            self.specular_sampling_weight,
            |wo, u| {
                let h = around_axis(Vec3::Z, (1.0 - u.x).powf(1.0 / (n + 1.0)), 2.0 * PI * u.y);
                Some(reflect(wo, h))
            },
            |wi| self.eval(wo, wi, mode),
            |wi| self.pdf(wo, wi, mode),
        )
    }
}
