//! Conductors (Mitsuba `conductor` and `roughconductor`): Fresnel reflectance of a complex
//! IOR per RGB channel, scaled by `specular_reflectance`. Front side only.

use super::fresnel::{self, reflect};
use super::microfacet::Microfacet;
use super::{BsdfSample, LobeFlags, TransportMode};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// A perfect mirror with conductor Fresnel reflectance (a delta lobe).
#[derive(Clone, Copy, Debug)]
pub struct SmoothConductor {
    pub eta: Rgb,
    pub k: Rgb,
    pub specular_reflectance: Rgb,
}

impl SmoothConductor {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::SPECULAR_REFLECTION
    }
    pub fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Rgb {
        Rgb::BLACK
    }
    pub fn pdf(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> f32 {
        0.0
    }
    pub fn sample(&self, wo: Vec3, _uc: f32, _u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = fresnel::reflect_z(wo);
        let weight = fresnel::conductor(wo.z, self.eta, self.k) * self.specular_reflectance;
        Some(BsdfSample { wi, f: weight / wi.z, pdf: 1.0, lobe: LobeFlags::SPECULAR_REFLECTION, eta: 1.0 })
    }
}

/// Microfacet conductor: f = F(wo.m) D(m) G(wo, wi) / (4 cos_o cos_i), visible-normal sampling.
#[derive(Clone, Copy, Debug)]
pub struct RoughConductor {
    pub distribution: Microfacet,
    pub eta: Rgb,
    pub k: Rgb,
    pub specular_reflectance: Rgb,
}

impl RoughConductor {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::GLOSSY_REFLECTION
    }
    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        let m = (wo + wi).normalize();
        let md = &self.distribution;
        let d = md.d(m);
        if d == 0.0 {
            return Rgb::BLACK;
        }
        let g = md.g(wo, wi, m);
        fresnel::conductor(wo.dot(m), self.eta, self.k) * self.specular_reflectance * (d * g / (4.0 * wo.z * wi.z))
    }
    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let m = (wo + wi).normalize();
        let wm = wi.dot(m);
        if wm <= 0.0 {
            return 0.0;
        }
        // Visible-normal density times the Jacobian of reflection, 1 / (4 wi.m).
        self.distribution.pdf_visible(wo, m) / (4.0 * wm)
    }
    pub fn sample(&self, wo: Vec3, _uc: f32, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        self.sample_given(wo, u, None, || self.distribution.lambda(wo))
    }

    /// [`Self::sample`] with Λ(wo) from `lambda_o`, and the visible normal `sample_visible`
    /// draws for `wo` and `u` from `m` where given: the same sample.
    #[inline]
    fn sample_given(&self, wo: Vec3, u: Vec2, m: Option<Vec3>, lambda_o: impl FnOnce() -> f32) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let m = m.unwrap_or_else(|| self.distribution.sample_visible(wo, u));
        let wi = reflect(wo, m);
        if wi.z <= 0.0 {
            return None;
        }
        let (f, pdf) = self.eval_pdf_given(wo, wi, lambda_o);
        if !super::positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample { wi, f, pdf, lobe: LobeFlags::GLOSSY_REFLECTION, eta: 1.0 })
    }

    /// ([`Self::eval_pdf`] toward `wi` where given, [`Self::sample`]): the same bits, with
    /// Λ(wo), which both need, computed once (a path vertex's light sample and continuation).
    /// `m`: the visible normal `sample_visible` draws for `wo` and `u`, where the caller has
    /// drawn it (the path kernel, eight lanes at once).
    pub(crate) fn eval_pdf_and_sample(&self, wo: Vec3, wi: Option<Vec3>, u: Vec2, m: Option<Vec3>) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let mut lambda_o = None;
        let mut lambda = || *lambda_o.get_or_insert_with(|| self.distribution.lambda(wo));
        let nee = wi.map(|wi| self.eval_pdf_given(wo, wi, &mut lambda));
        (nee, self.sample_given(wo, u, m, lambda))
    }

    /// ([`Self::eval`], [`Self::pdf`]) with the half vector, D and G1(wo) computed once: the
    /// same values as the two calls.
    pub(crate) fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        self.eval_pdf_given(wo, wi, || self.distribution.lambda(wo))
    }

    /// [`Self::eval_pdf`] with Λ(wo) from `lambda_o`.
    #[inline]
    fn eval_pdf_given(&self, wo: Vec3, wi: Vec3, lambda_o: impl FnOnce() -> f32) -> (Rgb, f32) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        let m = (wo + wi).normalize();
        let md = &self.distribution;
        let d = md.d(m);
        let g1o = Microfacet::g1_given(wo, m, lambda_o);
        let wm = wi.dot(m);
        let pdf = if wm <= 0.0 { 0.0 } else { Microfacet::pdf_visible_given(wo, m, d, g1o) / (4.0 * wm) };
        if d == 0.0 {
            return (Rgb::BLACK, pdf);
        }
        let g = g1o * md.g1(wi, m);
        (fresnel::conductor(wo.dot(m), self.eta, self.k) * self.specular_reflectance * (d * g / (4.0 * wo.z * wi.z)), pdf)
    }
}
