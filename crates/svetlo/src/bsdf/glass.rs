//! svetlo's `glass`: a thin pane of clear glazing, as Radiance's `glass` models it. Light
//! passes undeflected (the pane's offset is neglected) or reflects specularly; between the
//! two faces it bounces any number of times, which sums in closed form, separately for the
//! s and p polarisations (averaging the Fresnel factor first, as `thindielectric` does,
//! understates transmission at oblique incidence: by 1.5 % at 60°, 3.8 % at 75°). The glass absorbs:
//! one pass along the normal keeps the fraction `transmissivity`, an oblique pass
//! transmissivity^(1/cos θt). Lighting designers know the pane by its normal
//! transmittance τn (the data sheet's light transmittance): [`transmissivity_from_normal`]
//! converts.

use super::{BsdfSample, LobeFlags, TransportMode};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// A thin pane: relative IOR `eta` of glass to the outside, and its per-channel internal
/// transmissivity along the normal (1 = no absorption).
#[derive(Clone, Copy, Debug)]
pub struct ThinGlass {
    pub eta: f32,
    pub transmissivity: Rgb,
}

/// Reflectance and transmittance (R, T) of a pane of relative IOR `eta` and normal
/// transmissivity `tn` for light at incidence cosine `cos_i`, with every internal bounce
/// and both polarisations: per polarisation, with interface reflectance r and one
/// oblique pass a = tn^(1/cos θt), T = (1−r)² a / (1 − r² a²), R = r + r (1−r)² a² / (1 − r² a²).
pub fn pane(cos_i: f64, eta: f64, tn: f64) -> (f64, f64) {
    let ci = cos_i.abs().min(1.0);
    let sin_t2 = (1.0 - ci * ci) / (eta * eta);
    if sin_t2 >= 1.0 || ci == 0.0 {
        return (1.0, 0.0);
    }
    let ct = (1.0 - sin_t2).sqrt();
    let rs = ((ci - eta * ct) / (ci + eta * ct)).powi(2);
    let rp = ((eta * ci - ct) / (eta * ci + ct)).powi(2);
    let a = if tn >= 1.0 { 1.0 } else { tn.max(0.0).powf(1.0 / ct) };
    let (mut r, mut t) = (0.0, 0.0);
    for x in [rs, rp] {
        let d = 1.0 - x * x * a * a;
        t += 0.5 * (1.0 - x) * (1.0 - x) * a / d;
        r += 0.5 * (x + x * (1.0 - x) * (1.0 - x) * a * a / d);
    }
    (r, t)
}

/// The internal transmissivity that gives a pane of relative IOR `eta` the normal
/// transmittance `tau_n`: the positive root of τn r² t² + (1−r)² t − τn = 0 (the normal
/// case of [`pane`], r = ((η−1)/(η+1))²). None where τn exceeds what a lossless pane
/// transmits, (1 − r)/(1 + r), or is negative.
pub fn transmissivity_from_normal(tau_n: f64, eta: f64) -> Option<f64> {
    let r = ((eta - 1.0) / (eta + 1.0)).powi(2);
    let lossless = (1.0 - r) / (1.0 + r);
    if !(0.0..=lossless * (1.0 + 1e-9)).contains(&tau_n) {
        return None;
    }
    if tau_n == 0.0 {
        return Some(0.0);
    }
    if r == 0.0 {
        return Some(tau_n);
    }
    let b = (1.0 - r) * (1.0 - r);
    Some((((b * b + 4.0 * r * r * tau_n * tau_n).sqrt() - b) / (2.0 * r * r * tau_n)).min(1.0))
}

impl ThinGlass {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::SPECULAR_REFLECTION | LobeFlags::SPECULAR_TRANSMISSION
    }
    pub fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Rgb {
        Rgb::BLACK
    }
    pub fn pdf(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> f32 {
        0.0
    }

    /// Per-channel (R, T) at incidence cosine `cos`.
    pub fn reflectance_transmittance(&self, cos: f32) -> (Rgb, Rgb) {
        let c = |tn: f32| pane(cos as f64, self.eta as f64, tn as f64);
        let (r, g, b) = (c(self.transmissivity.r), c(self.transmissivity.g), c(self.transmissivity.b));
        (Rgb::new(r.0 as f32, g.0 as f32, b.0 as f32), Rgb::new(r.1 as f32, g.1 as f32, b.1 as f32))
    }

    /// Probability of sampling the reflection: its share of the scattered luminance.
    pub fn reflection_probability(&self, cos: f32) -> f32 {
        let (r, t) = self.reflectance_transmittance(cos);
        let (lr, lt) = (r.luminance().max(0.0), t.luminance().max(0.0));
        if lr + lt > 0.0 {
            lr / (lr + lt)
        } else {
            0.0
        }
    }

    pub fn sample(&self, wo: Vec3, uc: f32, _u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let (r, t) = self.reflectance_transmittance(wo.z);
        let (lr, lt) = (r.luminance().max(0.0), t.luminance().max(0.0));
        if lr + lt <= 0.0 {
            return None;
        }
        let p = lr / (lr + lt);
        let (wi, w, prob, lobe) =
            if uc < p { (super::fresnel::reflect_z(wo), r, p, LobeFlags::SPECULAR_REFLECTION) } else { (-wo, t, 1.0 - p, LobeFlags::SPECULAR_TRANSMISSION) };
        if !super::positive_finite(prob) {
            return None;
        }
        Some(BsdfSample { wi, f: w / (prob * wi.z.abs()), pdf: 1.0, lobe, eta: 1.0 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lossless_pane_conserves_energy_and_inverts() {
        for c in [1.0, 0.8, 0.5, 0.2, 0.05] {
            let (r, t) = pane(c, 1.52, 1.0);
            assert!((r + t - 1.0).abs() < 1e-12, "cos {c}: R {r} + T {t}");
        }
        // Normal incidence: T = (1 − r)/(1 + r) for r = 0.0426 (n = 1.52).
        let r = (0.52f64 / 2.52).powi(2);
        assert!((pane(1.0, 1.52, 1.0).1 - (1.0 - r) / (1.0 + r)).abs() < 1e-12);
        for tau in [0.88, 0.5, 0.1] {
            let tn = transmissivity_from_normal(tau, 1.52).unwrap();
            assert!((pane(1.0, 1.52, tn).1 - tau).abs() < 1e-12, "{tau}: {tn}");
        }
        assert!(transmissivity_from_normal(0.95, 1.52).is_none());
        assert!(transmissivity_from_normal(-0.1, 1.52).is_none());
    }

    #[test]
    fn sampling_weights_are_r_and_t() {
        let g = ThinGlass { eta: 1.52, transmissivity: Rgb::new(0.9, 0.95, 1.0) };
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let (r, t) = g.reflectance_transmittance(0.8);
        let p = g.reflection_probability(0.8);
        let sr = g.sample(wo, 0.0, Vec2::ZERO, TransportMode::Radiance).unwrap();
        let st = g.sample(wo, 0.999, Vec2::ZERO, TransportMode::Radiance).unwrap();
        assert_eq!(sr.lobe, LobeFlags::SPECULAR_REFLECTION);
        assert_eq!(st.lobe, LobeFlags::SPECULAR_TRANSMISSION);
        assert!((sr.weight() * p - r).map(f32::abs).max_component() < 1e-6);
        assert!((st.weight() * (1.0 - p) - t).map(f32::abs).max_component() < 1e-6);
        assert!((st.wi + wo).length() < 1e-7);
    }
}
