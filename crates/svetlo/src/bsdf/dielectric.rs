//! Dielectric interfaces (Mitsuba `dielectric`, `roughdielectric`, `thindielectric`).
//! `eta` = interior IOR / exterior IOR, the interior being on the -z side. Both sides
//! scatter. In radiance mode, refraction scales by 1/eta² of the crossing (the radiance
//! compression of Veach's thesis §5.2); importance is not scaled.

use super::fresnel::{self, reflect, refract};
use super::microfacet::Microfacet;
use super::{BsdfSample, LobeFlags, TransportMode};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[inline]
fn radiance_scale(mode: TransportMode, eta_ti: f32) -> f32 {
    match mode {
        TransportMode::Radiance => eta_ti * eta_ti,
        TransportMode::Importance => 1.0,
    }
}

/// A smooth interface: specular reflection with probability F, refraction otherwise.
#[derive(Clone, Copy, Debug)]
pub struct SmoothDielectric {
    pub eta: f32,
    pub specular_reflectance: Rgb,
    pub specular_transmittance: Rgb,
}

impl SmoothDielectric {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::SPECULAR_REFLECTION | LobeFlags::SPECULAR_TRANSMISSION
    }
    pub fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Rgb {
        Rgb::BLACK
    }
    pub fn pdf(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> f32 {
        0.0
    }
    pub fn sample(&self, wo: Vec3, uc: f32, _u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let (f, cos_t, eta_it, eta_ti) = fresnel::dielectric(wo.z, self.eta);
        if uc < f {
            let wi = fresnel::reflect_z(wo);
            // Chosen with probability F, which cancels the Fresnel factor of the weight.
            Some(BsdfSample { wi, f: self.specular_reflectance / wi.z.abs(), pdf: 1.0, lobe: LobeFlags::SPECULAR_REFLECTION, eta: 1.0 })
        } else {
            let wi = refract(wo, Vec3::Z, cos_t, eta_ti);
            if wi.z == 0.0 {
                return None;
            }
            let w = self.specular_transmittance * radiance_scale(mode, eta_ti);
            Some(BsdfSample { wi, f: w / wi.z.abs(), pdf: 1.0, lobe: LobeFlags::SPECULAR_TRANSMISSION, eta: eta_it })
        }
    }
}

/// Walter et al. 2007 microfacet dielectric, with visible-normal sampling and the lobe
/// chosen by the Fresnel reflectance of the sampled microfacet.
#[derive(Clone, Copy, Debug)]
pub struct RoughDielectric {
    pub distribution: Microfacet,
    pub eta: f32,
    pub specular_reflectance: Rgb,
    pub specular_transmittance: Rgb,
}

/// The generalised half vector of a (wo, wi) pair, oriented to +z, with the relative IOR
/// `eta` (other side / side of wo) and whether the pair is a reflection. None when the
/// microfacet would be seen from its back by either direction.
#[inline]
fn half_vector(wo: Vec3, wi: Vec3, eta_ext_int: f32) -> Option<(Vec3, f32, bool)> {
    let reflect = wo.z * wi.z > 0.0;
    let eta = if wo.z > 0.0 { eta_ext_int } else { 1.0 / eta_ext_int };
    let m = wo + wi * if reflect { 1.0 } else { eta };
    let len = m.length();
    if !super::positive_finite(len) {
        return None;
    }
    let m = m / len * m.z.signum();
    if wo.dot(m) * wo.z <= 0.0 || wi.dot(m) * wi.z <= 0.0 {
        return None;
    }
    Some((m, eta, reflect))
}

impl RoughDielectric {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::GLOSSY_REFLECTION | LobeFlags::GLOSSY_TRANSMISSION
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        if wo.z == 0.0 || wi.z == 0.0 {
            return Rgb::BLACK;
        }
        let Some((m, eta, reflect)) = half_vector(wo, wi, self.eta) else { return Rgb::BLACK };
        let md = &self.distribution;
        let d = md.d(m);
        let g = md.g(wo, wi, m);
        let (f, ..) = fresnel::dielectric(wo.dot(m), self.eta);
        if reflect {
            self.specular_reflectance * (f * d * g / (4.0 * wo.z.abs() * wi.z.abs()))
        } else {
            let (om, im) = (wo.dot(m), wi.dot(m));
            let denom = om + eta * im;
            let v = radiance_scale(mode, 1.0 / eta) * (1.0 - f) * d * g * eta * eta * (om * im).abs() / ((wo.z * wi.z).abs() * denom * denom);
            self.specular_transmittance * if v.is_finite() { v } else { 0.0 }
        }
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        if wo.z == 0.0 || wi.z == 0.0 {
            return 0.0;
        }
        let Some((m, eta, reflect)) = half_vector(wo, wi, self.eta) else { return 0.0 };
        let (om, im) = (wo.dot(m), wi.dot(m));
        // Jacobian of the map from microfacet normals to wi.
        let jac = if reflect { 1.0 / (4.0 * im.abs()) } else { eta * eta * im.abs() / ((om + eta * im) * (om + eta * im)) };
        let (f, ..) = fresnel::dielectric(om, self.eta);
        let p = self.distribution.pdf_visible(wo * wo.z.signum(), m) * if reflect { f } else { 1.0 - f } * jac;
        if p.is_finite() {
            p
        } else {
            0.0
        }
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let m = self.distribution.sample_visible(wo * wo.z.signum(), u);
        let (f, cos_t, eta_it, eta_ti) = fresnel::dielectric(wo.dot(m), self.eta);
        let (wi, lobe, eta) =
            if uc < f { (reflect(wo, m), LobeFlags::GLOSSY_REFLECTION, 1.0) } else { (refract(wo, m, cos_t, eta_ti), LobeFlags::GLOSSY_TRANSMISSION, eta_it) };
        let wi = wi.normalize_or_zero();
        // The sampled direction may land on the wrong side of the macrosurface.
        let is_reflection = wi.z * wo.z > 0.0;
        if wi.z == 0.0 || is_reflection != (lobe == LobeFlags::GLOSSY_REFLECTION) {
            return None;
        }
        let (f, pdf) = self.eval_pdf(wo, wi, mode);
        if !super::positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample { wi, f, pdf, lobe, eta })
    }

    /// ([`Self::eval`], [`Self::pdf`]) with the half vector, D, G1(wo) and the Fresnel term
    /// computed once: the same values as the two calls. (G1 is even in its direction, so the
    /// density's G1 of wo mirrored to +z is eval's G1 of wo.)
    pub(crate) fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        if wo.z == 0.0 || wi.z == 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        let Some((m, eta, reflect)) = half_vector(wo, wi, self.eta) else { return (Rgb::BLACK, 0.0) };
        let md = &self.distribution;
        let d = md.d(m);
        let g1o = md.g1(wo, m);
        let (om, im) = (wo.dot(m), wi.dot(m));
        let (f, ..) = fresnel::dielectric(om, self.eta);
        // The density.
        let jac = if reflect { 1.0 / (4.0 * im.abs()) } else { eta * eta * im.abs() / ((om + eta * im) * (om + eta * im)) };
        let p = Microfacet::pdf_visible_given(wo * wo.z.signum(), m, d, g1o) * if reflect { f } else { 1.0 - f } * jac;
        let pdf = if p.is_finite() { p } else { 0.0 };
        // The value.
        let g = g1o * md.g1(wi, m);
        let value = if reflect {
            self.specular_reflectance * (f * d * g / (4.0 * wo.z.abs() * wi.z.abs()))
        } else {
            let denom = om + eta * im;
            let v = radiance_scale(mode, 1.0 / eta) * (1.0 - f) * d * g * eta * eta * (om * im).abs() / ((wo.z * wi.z).abs() * denom * denom);
            self.specular_transmittance * if v.is_finite() { v } else { 0.0 }
        };
        (value, pdf)
    }
}

/// Mitsuba `thindielectric`: a thin slab whose internal reflections are summed in closed
/// form; transmitted light continues undeflected.
#[derive(Clone, Copy, Debug)]
pub struct ThinDielectric {
    pub eta: f32,
    pub specular_reflectance: Rgb,
    pub specular_transmittance: Rgb,
}

impl ThinDielectric {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::SPECULAR_REFLECTION | LobeFlags::SPECULAR_TRANSMISSION
    }
    pub fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Rgb {
        Rgb::BLACK
    }
    pub fn pdf(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> f32 {
        0.0
    }
    /// Total reflectance of the slab: R + T² R / (1 - R²) (geometric series of the
    /// internal bounces, both interfaces having reflectance R).
    pub fn reflectance(&self, cos: f32) -> f32 {
        let r = fresnel::dielectric(cos.abs(), self.eta).0;
        if r < 1.0 {
            let t = 1.0 - r;
            r + t * t * r / (1.0 - r * r)
        } else {
            1.0
        }
    }
    pub fn sample(&self, wo: Vec3, uc: f32, _u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let r = self.reflectance(wo.z);
        if uc < r {
            let wi = fresnel::reflect_z(wo);
            Some(BsdfSample { wi, f: self.specular_reflectance / wi.z.abs(), pdf: 1.0, lobe: LobeFlags::SPECULAR_REFLECTION, eta: 1.0 })
        } else {
            let wi = -wo;
            Some(BsdfSample { wi, f: self.specular_transmittance / wi.z.abs(), pdf: 1.0, lobe: LobeFlags::SPECULAR_TRANSMISSION, eta: 1.0 })
        }
    }
}
