//! Fresnel reflectance of dielectric and conductor interfaces (unpolarized), plus the
//! reflection and refraction of directions about a (micro)normal.

use crate::spectrum::Rgb;
use glam::Vec3;

/// Exact unpolarized Fresnel reflectance of a dielectric interface.
///
/// `cos_i` is the cosine between the incident direction and the normal; its sign says
/// which side the direction is on (positive: outside). `eta` = interior IOR / exterior IOR.
/// Returns `(F, cos_t, eta_it, eta_ti)`: the reflectance, the signed cosine of the
/// transmitted direction (on the side opposite to the incident one; 0 under total
/// internal reflection), and the relative IORs transmitted/incident and incident/transmitted.
#[inline]
pub fn dielectric(cos_i: f32, eta: f32) -> (f32, f32, f32, f32) {
    let inv_eta = 1.0 / eta;
    // (The inside's 1 / (1 / eta) only there: outside one division.)
    let (eta_it, eta_ti) = if cos_i >= 0.0 { (eta, inv_eta) } else { (inv_eta, 1.0 / inv_eta) };
    dielectric_between(cos_i, eta, eta_it, eta_ti)
}

/// [`dielectric`] given `inv_eta` = 1 / eta and `inv_inv_eta` = 1 / inv_eta (computed once
/// for several calls: `eta_ti` of either side without a division in the chain).
#[inline(always)]
pub(crate) fn dielectric_given_inverses(cos_i: f32, eta: f32, inv_eta: f32, inv_inv_eta: f32) -> (f32, f32, f32, f32) {
    let (eta_it, eta_ti) = if cos_i >= 0.0 { (eta, inv_eta) } else { (inv_eta, inv_inv_eta) };
    dielectric_between(cos_i, eta, eta_it, eta_ti)
}

/// [`dielectric`] given the relative IORs of `cos_i`'s side, `eta_it` and `eta_ti` = 1 / eta_it.
#[inline(always)]
fn dielectric_between(cos_i: f32, eta: f32, eta_it: f32, eta_ti: f32) -> (f32, f32, f32, f32) {
    let outside = cos_i >= 0.0;
    if eta == 1.0 {
        return (0.0, -cos_i, 1.0, 1.0);
    }
    let ci = cos_i.abs().min(1.0);
    // Snell: sin_t = eta_ti * sin_i.
    let cos_t2 = 1.0 - eta_ti * eta_ti * (1.0 - ci * ci);
    if cos_t2 <= 0.0 {
        return (1.0, 0.0, eta_it, eta_ti);
    }
    let ct = cos_t2.sqrt();
    let rs = (ci - eta_it * ct) / (ci + eta_it * ct);
    let rp = (eta_it * ci - ct) / (eta_it * ci + ct);
    let f = 0.5 * (rs * rs + rp * rp);
    (f, if outside { -ct } else { ct }, eta_it, eta_ti)
}

/// [`dielectric`]'s reflectance alone, its branches as selects, so that a loop over lanes
/// that calls it runs as vector code (the rough plastic's lanes). The same bits.
#[inline(always)]
pub(crate) fn dielectric_reflectance(cos_i: f32, eta: f32) -> f32 {
    dielectric_lane(cos_i, eta).0
}

/// [`dielectric`] whole (reflectance, transmitted cosine, relative IORs), its branches as
/// selects: the rough dielectric's lanes. The same bits.
#[inline(always)]
pub(crate) fn dielectric_lane(cos_i: f32, eta: f32) -> (f32, f32, f32, f32) {
    let outside = cos_i >= 0.0;
    let eta_it = if outside { eta } else { 1.0 / eta };
    let eta_ti = 1.0 / eta_it;
    let ci = cos_i.abs().min(1.0);
    let cos_t2 = 1.0 - eta_ti * eta_ti * (1.0 - ci * ci);
    let ct = cos_t2.sqrt();
    let rs = (ci - eta_it * ct) / (ci + eta_it * ct);
    let rp = (eta_it * ci - ct) / (eta_it * ci + ct);
    let f = 0.5 * (rs * rs + rp * rp);
    let tir = cos_t2 <= 0.0;
    let f = if tir { 1.0 } else { f };
    let ct = if outside { -ct } else { ct };
    let ct = if tir { 0.0 } else { ct };
    let one = eta == 1.0;
    (if one { 0.0 } else { f }, if one { -cos_i } else { ct }, if one { 1.0 } else { eta_it }, if one { 1.0 } else { eta_ti })
}

/// Reflectance of a conductor with complex relative IOR `eta + i k` at incidence
/// cosine `cos_i` (>= 0), exact for unpolarized light. Evaluated in f64 per channel.
pub fn conductor(cos_i: f32, eta: Rgb, k: Rgb) -> Rgb {
    let c = conductor_cos(cos_i);
    Rgb::new(conductor_channel(c, eta.r, k.r), conductor_channel(c, eta.g, k.g), conductor_channel(c, eta.b, k.b))
}

/// [`conductor`]'s incidence cosine, as it computes it.
#[inline(always)]
pub(crate) fn conductor_cos(cos_i: f32) -> f64 {
    cos_i.clamp(0.0, 1.0) as f64
}

/// One channel of [`conductor`] at cosine `c` ([`conductor_cos`]): IOR `n + i kk`. (The
/// rough conductors' lanes run it over channels of several lanes at once.)
#[inline(always)]
pub(crate) fn conductor_channel(c: f64, n: f32, kk: f32) -> f32 {
    let (n, kk) = (n as f64, kk as f64);
    let sin2 = 1.0 - c * c;
    // eta^2 = (n^2 - k^2) + i 2nk; w = sqrt(eta^2 - sin^2) (principal root: the
    // transmitted wave decays into the metal).
    let e2 = (n * n - kk * kk, 2.0 * n * kk);
    let w = csqrt((e2.0 - sin2, e2.1));
    // r_s = (c - w) / (c + w), r_p = (eta^2 c - w) / (eta^2 c + w).
    let rs = cabs2(csub((c, 0.0), w)) / cabs2(cadd((c, 0.0), w)).max(1e-300);
    let e2c = (e2.0 * c, e2.1 * c);
    let rp = cabs2(csub(e2c, w)) / cabs2(cadd(e2c, w)).max(1e-300);
    (0.5 * (rs + rp)).clamp(0.0, 1.0) as f32
}

type C64 = (f64, f64);
#[inline]
fn cadd(a: C64, b: C64) -> C64 {
    (a.0 + b.0, a.1 + b.1)
}
#[inline]
fn csub(a: C64, b: C64) -> C64 {
    (a.0 - b.0, a.1 - b.1)
}
#[inline]
fn cabs2(a: C64) -> f64 {
    a.0 * a.0 + a.1 * a.1
}
/// Principal square root (non-negative real part).
#[inline(always)]
fn csqrt(z: C64) -> C64 {
    let r = cabs2(z).sqrt();
    let re = (0.5 * (r + z.0)).max(0.0).sqrt();
    let im = (0.5 * (r - z.0)).max(0.0).sqrt();
    (re, if z.1 < 0.0 { -im } else { im })
}

/// Diffuse Fresnel reflectance ("Fdr"): the fraction of uniform (cosine-weighted)
/// illumination reflected by a dielectric interface of relative IOR `eta`. Uses the
/// published fits Mitsuba uses: Egan and Hilgeman (1973) for eta < 1, d'Eon and Irving
/// (2011) otherwise, so that `plastic` matches Mitsuba's images.
pub fn diffuse_reflectance(eta: f32) -> f32 {
    if eta < 1.0 {
        -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta
    } else {
        let x = 1.0 / eta;
        let c = [0.919317f32, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881];
        c.iter().rev().fold(0.0, |acc, &ci| acc * x + ci)
    }
}

/// Mirror `w` about the local normal +z.
#[inline]
pub fn reflect_z(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

/// Mirror `w` about the unit vector `m`.
#[inline]
pub fn reflect(w: Vec3, m: Vec3) -> Vec3 {
    2.0 * w.dot(m) * m - w
}

/// Refract `w` through the microsurface with normal `m`, given `cos_t` and `eta_ti` as
/// returned by [`dielectric`] for `cos_i = w . m`.
#[inline]
pub fn refract(w: Vec3, m: Vec3, cos_t: f32, eta_ti: f32) -> Vec3 {
    m * (w.dot(m) * eta_ti + cos_t) - w * eta_ti
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random cosines and indices, plus both sides, grazing and normal incidence, total internal
    /// reflection, index 1 and cosines past ±1.
    fn select_form_cases() -> Vec<(f32, f32)> {
        let mut rng = crate::sampling::rng::Pcg32::new(5, 9);
        let mut cases: Vec<(f32, f32)> = (0..20_000).map(|_| (rng.next_f32() * 2.0 - 1.0, 0.5 + rng.next_f32() * 2.5)).collect();
        for c in [0.0, -0.0, 1.0, -1.0, 1.0 + 1e-6, -1.0 - 1e-6, 1e-7, -1e-7, 0.3, -0.3] {
            for eta in [1.0, 1.5, 1.0 / 1.5, 1.333, 2.4, 0.4] {
                cases.push((c, eta));
            }
        }
        cases
    }

    /// The select forms (`dielectric_lane`, and `dielectric_reflectance` built on it) give
    /// `dielectric`'s values bit for bit.
    #[test]
    fn select_forms_are_dielectrics() {
        let bits = |v: (f32, f32, f32, f32)| [v.0, v.1, v.2, v.3].map(f32::to_bits);
        for (c, eta) in select_form_cases() {
            assert_eq!(bits(dielectric_lane(c, eta)), bits(dielectric(c, eta)), "cos {c} eta {eta}");
            assert_eq!(dielectric_reflectance(c, eta).to_bits(), dielectric(c, eta).0.to_bits(), "cos {c} eta {eta}");
        }
    }

    /// Independent reference: Fresnel equations written with Snell angles in f64.
    fn fresnel_ref(cos_i: f64, n1: f64, n2: f64) -> f64 {
        let sin_t = n1 / n2 * (1.0 - cos_i * cos_i).sqrt();
        if sin_t >= 1.0 {
            return 1.0;
        }
        let cos_t = (1.0 - sin_t * sin_t).sqrt();
        let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
        let rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t);
        0.5 * (rs * rs + rp * rp)
    }

    #[test]
    fn dielectric_matches_reference_both_sides() {
        for &eta in &[1.33f32, 1.5, 2.4, 0.7] {
            for i in 0..=100 {
                let c = i as f32 / 100.0;
                let (f, ct, _, eta_ti) = dielectric(c, eta);
                let r = fresnel_ref(c as f64, 1.0, eta as f64);
                assert!((f as f64 - r).abs() < 2e-5, "eta {eta} cos {c}: {f} vs {r}");
                if f < 1.0 {
                    assert!(ct <= 0.0);
                    // Snell's law on the transmitted cosine.
                    let st = (1.0 - ct * ct).sqrt();
                    assert!((st - eta_ti * (1.0 - c * c).sqrt()).abs() < 1e-4);
                }
                let (fb, ctb, _, _) = dielectric(-c, eta);
                let rb = fresnel_ref(c as f64, eta as f64, 1.0);
                assert!((fb as f64 - rb).abs() < 2e-5);
                assert!(c == 0.0 || ctb >= 0.0);
            }
        }
    }

    #[test]
    fn total_internal_reflection_beyond_critical_angle() {
        let eta = 1.5f32;
        let crit = (1.0f32 - 1.0 / (eta * eta)).sqrt(); // cos of critical angle inside
        assert_eq!(dielectric(-(crit - 1e-3), eta).0, 1.0);
        assert!(dielectric(-(crit + 1e-3), eta).0 < 1.0);
        // Reciprocity of the interface: F seen from both sides of a refracted pair is equal.
        let (f, ct, _, _) = dielectric(0.6, eta);
        let (fb, _, _, _) = dielectric(ct, eta);
        assert!((f - fb).abs() < 1e-5);
    }

    #[test]
    fn conductor_reduces_to_dielectric_without_absorption_and_normal_incidence_known() {
        for i in 0..=20 {
            let c = i as f32 / 20.0;
            let fc = conductor(c, Rgb::splat(1.5), Rgb::BLACK).r;
            assert!((fc - dielectric(c, 1.5).0).abs() < 1e-5);
        }
        let (n, k) = (0.2f32, 3.9f32);
        let f = conductor(1.0, Rgb::splat(n), Rgb::splat(k)).g;
        let expect = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((f - expect).abs() < 1e-6);
        assert!((conductor(0.0, Rgb::splat(n), Rgb::splat(k)).r - 1.0).abs() < 1e-5);
    }

    #[test]
    fn fdr_against_numerical_integral() {
        // Fdr = 2 * int_0^1 F(mu) mu dmu, by a fine midpoint rule.
        for &eta in &[1.2f32, 1.5, 1.9, 1.0 / 1.5, 1.0 / 1.3] {
            let n = 20000;
            let mut s = 0.0f64;
            for i in 0..n {
                let mu = (i as f64 + 0.5) / n as f64;
                s += fresnel_ref(mu, 1.0, eta as f64) * mu;
            }
            let fdr = 2.0 * s / n as f64;
            let approx = diffuse_reflectance(eta) as f64;
            assert!((approx - fdr).abs() / fdr < 0.01, "eta {eta}: fit {approx} vs {fdr}");
        }
    }
}
