//! Mitsuba 3's `principled` and `principledthin`: Burley's Disney BSDF (2012, and its 2015
//! extension to transmission) as Mitsuba defines it, so that images agree with Mitsuba's.
//!
//! `principled` blends a diffuse base (Burley's diffuse with retro-reflection, optionally
//! flattened towards the Hanrahan-Krueger "fake subsurface"), a sheen, a GGX specular lobe
//! whose Fresnel term mixes a dielectric, a tinted Schlick and a metallic Schlick response,
//! a GGX refraction lobe (`spec_trans`) and a GTR1 clearcoat. `principledthin` is the thin
//! sheet: reflection and an undeflected rough transmission, plus diffuse transmission.
//!
//! Mitsuba's quirks are kept on purpose (the test scenes are rendered with them): the
//! clearcoat and the sheen lack the 1 / (4 cos cos) and 1 / π of a microfacet and a
//! Lambertian lobe, and the clearcoat's masking uses a fixed GGX roughness of 0.25.
//! Lobes are chosen with Mitsuba's probabilities; on the front side they do not depend on
//! the sampled microfacet except through the specular reflection/transmission split, which
//! is evaluated at the same microfacet that `pdf` recovers from (wo, wi), so `pdf` is the
//! exact density of `sample` and MIS is unbiased.

use super::fresnel::{self, reflect, refract};
use super::material::MicrofacetKind;
use super::microfacet::Microfacet;
use super::{positive_finite, BsdfModel, BsdfSample, LobeFlags, TransportMode};
use crate::math::{warp, INV_PI, PI};
use crate::spectrum::Rgb;
use crate::texture::{checker_parity, TexPoint, Texture};
use glam::{Affine2, Vec2, Vec3};
use std::sync::OnceLock;

/// Schlick's weight (1 - cos)^5, cos clamped to [0, 1].
#[inline]
fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Schlick's Fresnel approximation with normal reflectance `r0` at microfacet cosine `cos_i`
/// of an interface of relative IOR `eta`; from the optically denser side it uses the
/// transmitted angle (and is 1 under total internal reflection), as Mitsuba does.
fn schlick(r0: Rgb, cos_i: f32, eta: f32) -> Rgb {
    schlick_blend(r0, schlick_fresnel_weight(cos_i, eta))
}

/// [`schlick`]'s weight, which does not depend on `r0`: one for all of a point's Schlick terms.
#[inline]
fn schlick_fresnel_weight(cos_i: f32, eta: f32) -> f32 {
    schlick_fresnel_weight_given(cos_i, eta, 1.0 / eta)
}

/// [`schlick_fresnel_weight`] given `inv_eta` = 1 / eta.
#[inline(always)]
fn schlick_fresnel_weight_given(cos_i: f32, eta: f32, inv_eta: f32) -> f32 {
    let (eta_it, eta_ti) = if cos_i >= 0.0 { (eta, inv_eta) } else { (inv_eta, eta) };
    if eta_it > 1.0 {
        schlick_weight(cos_i.abs())
    } else {
        let cos_t2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti;
        schlick_weight(cos_t2.max(0.0).sqrt())
    }
}

/// [`schlick_fresnel_weight`] where `cos_i` >= 0 (the front of a microfacet wo sees): the
/// same value, 1 / eta only where eta <= 1.
#[inline]
fn schlick_fresnel_weight_front(cos_i: f32, eta: f32) -> f32 {
    if eta > 1.0 {
        schlick_weight(cos_i.abs())
    } else {
        let eta_ti = 1.0 / eta;
        let cos_t2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti;
        schlick_weight(cos_t2.max(0.0).sqrt())
    }
}

/// [`schlick`] given its weight `w`.
#[inline]
fn schlick_blend(r0: Rgb, w: f32) -> Rgb {
    r0 * (1.0 - w) + Rgb::splat(w)
}

/// Normal-incidence reflectance of a dielectric of relative IOR `eta`.
#[inline]
fn r0_of_eta(eta: f32) -> f32 {
    let r = (eta - 1.0) / (eta + 1.0);
    r * r
}

/// The base colour normalised to luminance 1 (white when black): the tint colour.
#[inline]
fn tint_of(base: Rgb) -> Rgb {
    let lum = base.luminance();
    if lum > 0.0 {
        base / lum
    } else {
        Rgb::WHITE
    }
}

/// Disney's GGX roughness from `roughness` and `anisotropic` (Burley 2012, clamped at 0.001).
pub fn disney_alphas(roughness: f32, anisotropic: f32) -> (f32, f32) {
    let r2 = roughness * roughness;
    let aspect = (1.0 - 0.9 * anisotropic).max(0.0).sqrt();
    ((r2 / aspect).max(1e-3), (r2 * aspect).max(1e-3))
}

/// Mitsuba's `specular` → `eta`: the IOR whose normal reflectance is 0.08 `specular`.
pub fn eta_from_specular(specular: f32) -> f32 {
    2.0 / (1.0 - (0.08 * specular).sqrt()) - 1.0
}

/// Burley's GTR1 ("generalised Trowbridge-Reitz", exponent 1) normal distribution of the
/// clearcoat, per unit projected area; `alpha` in (0, 1).
#[cfg(test)]
fn gtr1_d(alpha: f32, m: Vec3) -> f32 {
    let a2 = alpha * alpha;
    gtr1_d_given(a2, a2.ln(), m)
}

/// [`gtr1_d`] given alpha² and its logarithm (a point's, computed once).
#[inline]
fn gtr1_d_given(a2: f32, ln_a2: f32, m: Vec3) -> f32 {
    let r = (a2 - 1.0) / (PI * ln_a2 * (1.0 + (a2 - 1.0) * m.z * m.z));
    if r * m.z > 1e-20 {
        r
    } else {
        0.0
    }
}

/// GTR1 normals by inversion of its cos θ distribution (density D(m) cos θm).
fn gtr1_sample(alpha: f32, u: Vec2) -> Vec3 {
    let a2 = alpha * alpha;
    let phi = 2.0 * PI * u.x;
    let cos2 = ((1.0 - a2.powf(1.0 - u.y)) / (1.0 - a2)).clamp(0.0, 1.0);
    let sin = (1.0 - cos2).sqrt();
    Vec3::new(sin * phi.cos(), sin * phi.sin(), cos2.sqrt())
}

/// The density of [`gtr1_sample`]'s normals of roughness `alpha`.
#[cfg(test)]
fn gtr1_pdf(alpha: f32, m: Vec3) -> f32 {
    gtr1_pdf_given(gtr1_d(alpha, m), m)
}

/// The density of [`gtr1_sample`]'s normal `m`, given its D(m) `d`.
#[inline]
fn gtr1_pdf_given(d: f32, m: Vec3) -> f32 {
    if m.z < 0.0 {
        0.0
    } else {
        m.z * d
    }
}

/// Smith's GGX masking with a fixed isotropic `alpha` (the clearcoat's), zero where `v`
/// sees the back of `m`.
#[inline]
fn smith_ggx1(v: Vec3, m: Vec3, alpha: f32) -> f32 {
    if v.dot(m) * v.z <= 0.0 {
        return 0.0;
    }
    smith_ggx1_front(v, alpha)
}

/// [`smith_ggx1`] where `v` sees the front of the microfacet: a function of `v` alone.
#[inline]
fn smith_ggx1_front(v: Vec3, alpha: f32) -> f32 {
    if v.z == 1.0 {
        return 1.0;
    }
    let c2 = v.z * v.z;
    let t2 = (1.0 - c2) / c2;
    2.0 / (1.0 + (1.0 + alpha * alpha * t2).sqrt())
}

/// Burley's diffuse with retro-reflection, blended towards the fake subsurface term by
/// `flatness`; `cos_d` is the cosine between the half vector and either direction, `fi`
/// the Schlick weight of |`cos_i`| (wo's: a vertex's, computed once).
#[inline]
fn disney_diffuse_given(roughness: f32, flatness: f32, cos_o: f32, cos_i: f32, cos_d: f32, fi: f32) -> f32 {
    let fo = schlick_weight(cos_o.abs());
    let f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo);
    let rr = 2.0 * roughness * cos_d * cos_d;
    let f_retro = rr * (fo + fi + fo * fi * (rr - 1.0));
    if flatness <= 0.0 {
        return f_diff + f_retro;
    }
    let fss90 = 0.5 * rr;
    let fss = (1.0 + (fss90 - 1.0) * fo) * (1.0 + (fss90 - 1.0) * fi);
    let f_ss = 1.25 * (fss * (1.0 / (cos_o.abs() + cos_i.abs()) - 0.5) + 0.5);
    (f_diff + f_retro) * (1.0 - flatness) + f_ss * flatness
}

/// The sheen's colour: white tinted towards the base colour by `sheen_tint`.
#[inline]
fn sheen_color(base: Rgb, sheen_tint: f32) -> Rgb {
    Rgb::WHITE * (1.0 - sheen_tint) + tint_of(base) * sheen_tint
}

/// Is `m` a microfacet both directions see from its front, on the macrosurface side of
/// `wo` (reflection) or with `wi` on the other side (transmission)?
#[inline(always)]
fn compatible(m: Vec3, wo: Vec3, wi: Vec3, reflection: bool) -> bool {
    let m = m * wo.z.signum();
    wo.dot(m) > 0.0 && if reflection { wi.dot(m) > 0.0 } else { wi.dot(m) < 0.0 }
}

/// Probabilities with which lobes are sampled (Mitsuba's `*_sampling_rate` parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplingRates {
    pub diffuse_reflection: f32,
    /// `principled`: the main specular lobe (reflection and transmission together);
    /// `principledthin`: its specular reflection.
    pub specular: f32,
    /// `principled`: the clearcoat; `principledthin`: the specular transmission.
    pub secondary: f32,
    /// `principledthin` only: the diffuse transmission.
    pub diffuse_transmission: f32,
}

impl Default for SamplingRates {
    fn default() -> Self {
        SamplingRates { diffuse_reflection: 1.0, specular: 1.0, secondary: 1.0, diffuse_transmission: 1.0 }
    }
}

/// `principled` at one surface point (every parameter evaluated and clamped).
#[derive(Clone, Copy, Debug)]
pub struct Principled {
    pub base_color: Rgb,
    pub roughness: f32,
    /// GGX of the main specular lobes (from roughness and anisotropic).
    pub distribution: Microfacet,
    pub metallic: f32,
    pub spec_trans: f32,
    /// Interior / exterior IOR.
    pub eta: f32,
    pub spec_tint: f32,
    pub sheen: f32,
    pub sheen_tint: f32,
    pub flatness: f32,
    pub clearcoat: f32,
    /// GTR1 roughness of the clearcoat: 0.1 at gloss 0 to 0.001 at gloss 1.
    pub clearcoat_alpha: f32,
    pub rates: SamplingRates,
    /// What `eval_pdf` reads at every call, from the fields above when the model is built
    /// ([`Principled::derived`]).
    pub derived: PrincipledDerived,
}

/// The parts of [`Principled`] that depend on its parameters alone: computed once per
/// point, not at each evaluation (the same values).
#[derive(Clone, Copy, Debug, Default)]
pub struct PrincipledDerived {
    /// `tint_of(base_color)`.
    tint: Rgb,
    /// `sheen_color(base_color, sheen_tint)`.
    sheen_color: Rgb,
    /// The clearcoat's alpha² and its logarithm (where the clearcoat is positive).
    cc_a2: f32,
    cc_ln_a2: f32,
}

/// What a vertex's evaluations and its sample share: terms of `wo` and of the model (the
/// same values computed once per vertex, not in each evaluation; not kept in the model:
/// a bigger one is copied by `memcpy` in the path kernel).
#[derive(Clone, Copy, Debug)]
struct WoTerms {
    /// Smith's Λ(wo) of the main lobes' GGX.
    lambda: f32,
    /// The clearcoat's masking toward `wo` where it sees the microfacet's front (0 without
    /// a clearcoat: not read then).
    g_cc: f32,
    /// The diffuse's Schlick weight of |wo.z|.
    fi: f32,
    /// 1 / eta, and 1 / (1 / eta) (the Fresnel term's eta_ti seen from inside).
    inv_eta: f32,
    inv_inv_eta: f32,
    /// The specular Fresnel blend's weights: (1 - metallic) spec_tint and
    /// (1 - metallic) (1 - spec_tint).
    tinted_w: f32,
    dielectric_w: f32,
    /// The diffuse's brdf_weight / π, the sheen's sheen (1 - metallic), the clearcoat's
    /// 0.25 clearcoat.
    diffuse_w: f32,
    sheen_w: f32,
    cc_w: f32,
    /// `lobes(true, f)` where it does not depend on f: without refraction, and with a
    /// finite positive eta (f then in [0, 1]; 0 (1 - f) is 0 and the transmission ±0, a
    /// sign that no sum or comparison of the lobes sees).
    opaque_lobes: Option<PrincipledLobes>,
}

/// What a `principledthin` vertex's evaluations and its sample share: terms of `wo` alone,
/// Λ(wo) of each GGX computed where first read (an evaluation reads one of the two).
#[derive(Clone, Copy, Debug)]
struct ThinWoTerms {
    lambda_r: Option<f32>,
    lambda_t: Option<f32>,
    /// The diffuse's Schlick weight of |wo.z|.
    f_wo: f32,
}

/// Lobe probabilities of `principled` from one side, normalised.
#[derive(Clone, Copy, Debug)]
struct PrincipledLobes {
    diffuse: f32,
    clearcoat: f32,
    transmission: f32,
    reflection: f32,
}

impl Principled {
    /// [`PrincipledDerived`] of these parameters.
    pub fn derived(&self) -> PrincipledDerived {
        let cc_a2 = self.clearcoat_alpha * self.clearcoat_alpha;
        PrincipledDerived {
            tint: tint_of(self.base_color),
            sheen_color: sheen_color(self.base_color, self.sheen_tint),
            cc_a2,
            cc_ln_a2: if self.clearcoat > 0.0 { cc_a2.ln() } else { 0.0 },
        }
    }

    /// Weight of the diffuse base (the BRDF's dielectric part).
    #[inline]
    fn brdf_weight(&self) -> f32 {
        (1.0 - self.metallic) * (1.0 - self.spec_trans)
    }
    /// Weight of the refracting dielectric part.
    #[inline]
    fn bsdf_weight(&self) -> f32 {
        (1.0 - self.metallic) * self.spec_trans
    }

    pub fn flags(&self) -> LobeFlags {
        let f = LobeFlags::DIFFUSE_REFLECTION | LobeFlags::GLOSSY_REFLECTION;
        if self.bsdf_weight() > 0.0 {
            f | LobeFlags::GLOSSY_TRANSMISSION
        } else {
            f
        }
    }

    /// Mitsuba's lobe probabilities seen from `front` (or inside), with `f_dielectric` the
    /// dielectric Fresnel reflectance of the microfacet.
    fn lobes(&self, front: bool, f_dielectric: f32) -> PrincipledLobes {
        let bsdf = self.bsdf_weight();
        let r = &self.rates;
        let (reflection, transmission, clearcoat, diffuse) = if front {
            (
                r.specular * (1.0 - bsdf * (1.0 - f_dielectric)),
                r.specular * bsdf * (1.0 - f_dielectric),
                0.25 * self.clearcoat * r.secondary,
                self.brdf_weight() * r.diffuse_reflection,
            )
        } else {
            (f_dielectric, 1.0 - f_dielectric, 0.0, 0.0)
        };
        let total = reflection + transmission + clearcoat + diffuse;
        let k = if total > 0.0 { 1.0 / total } else { 0.0 };
        PrincipledLobes { diffuse: diffuse * k, clearcoat: clearcoat * k, transmission: transmission * k, reflection: reflection * k }
    }

    /// The generalised half vector of (wo, wi), oriented to +z, with the relative IOR of
    /// the crossing (other side over wo's side) and whether it is a reflection.
    #[inline(always)]
    fn half_vector(&self, wo: Vec3, wi: Vec3, t: &WoTerms) -> (Vec3, f32, bool) {
        let reflect = wo.z * wi.z > 0.0;
        let eta_path = if wo.z > 0.0 { self.eta } else { t.inv_eta };
        let h = wo + wi * if reflect { 1.0 } else { eta_path };
        let len = h.length();
        let h = if positive_finite(len) { h / len } else { Vec3::ZERO };
        (if h.z < 0.0 { -h } else { h }, eta_path, reflect)
    }

    /// The specular lobe's Fresnel term: on the front a blend of the dielectric, the tinted
    /// Schlick and the metallic Schlick responses; inside the plain dielectric one.
    fn fresnel(&self, f_dielectric: f32, cos_i: f32, front: bool) -> Rgb {
        if !front {
            return Rgb::splat(self.bsdf_weight() * f_dielectric);
        }
        let (m, t) = (self.metallic, self.spec_tint);
        let eta_it = if cos_i >= 0.0 { self.eta } else { 1.0 / self.eta };
        let metal = schlick(self.base_color, cos_i, self.eta) * m;
        let tinted = schlick(tint_of(self.base_color) * r0_of_eta(eta_it), cos_i, self.eta) * ((1.0 - m) * t);
        Rgb::splat((1.0 - m) * (1.0 - t) * f_dielectric) + metal + tinted
    }

    /// [`Self::fresnel`] on the front, given the Schlick weight `w` at `cos_i` and the
    /// derived tint: the same value.
    #[inline(always)]
    fn fresnel_front(&self, f_dielectric: f32, cos_i: f32, w: f32, t: &WoTerms) -> Rgb {
        let eta_it = if cos_i >= 0.0 { self.eta } else { t.inv_eta };
        let metal = schlick_blend(self.base_color, w) * self.metallic;
        let tinted = schlick_blend(self.derived.tint * r0_of_eta(eta_it), w) * t.tinted_w;
        Rgb::splat(t.dielectric_w * f_dielectric) + metal + tinted
    }

    /// `fresnel::dielectric(cos_i, self.eta)` given 1 / eta: the same bits.
    #[inline(always)]
    fn dielectric(&self, cos_i: f32, t: &WoTerms) -> (f32, f32, f32, f32) {
        fresnel::dielectric_given_inverses(cos_i, self.eta, t.inv_eta, t.inv_inv_eta)
    }

    /// [`Self::lobes`] on the front at `f_dielectric`, derived where they do not depend on it.
    #[inline(always)]
    fn lobes_at(&self, front: bool, f_dielectric: f32, t: &WoTerms) -> PrincipledLobes {
        match t.opaque_lobes {
            Some(p) => p,
            None => self.lobes(front, f_dielectric),
        }
    }

    /// The value toward `wi` ([`Self::eval_pdf`]'s first part).
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        self.eval_pdf(wo, wi, mode).0
    }

    /// The density of `sample` toward `wi` ([`Self::eval_pdf`]'s second part).
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        self.eval_pdf(wo, wi, mode).1
    }

    /// The value and the density toward `wi`: the half vector, the dielectric Fresnel term,
    /// D, G1 and the clearcoat's GTR1 D computed once for both (G1 toward `wo` is the same
    /// for `wo` and the `-wo` that the density reads).
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        self.eval_pdf_with(wo, wi, mode, &self.wo_terms(wo))
    }

    #[inline]
    fn wo_terms(&self, wo: Vec3) -> WoTerms {
        let inv_eta = 1.0 / self.eta;
        WoTerms {
            lambda: self.distribution.lambda_inline(wo),
            g_cc: if self.clearcoat > 0.0 { smith_ggx1_front(wo, 0.25) } else { 0.0 },
            fi: schlick_weight(wo.z.abs()),
            inv_eta,
            inv_inv_eta: 1.0 / inv_eta,
            tinted_w: (1.0 - self.metallic) * self.spec_tint,
            dielectric_w: (1.0 - self.metallic) * (1.0 - self.spec_tint),
            diffuse_w: self.brdf_weight() * INV_PI,
            sheen_w: self.sheen * (1.0 - self.metallic),
            cc_w: 0.25 * self.clearcoat,
            opaque_lobes: (self.bsdf_weight() == 0.0 && self.eta.is_finite() && self.eta > 0.0).then(|| self.lobes(true, 0.0)),
        }
    }

    /// ([`Self::eval_pdf`] toward `wi` where given, [`Self::sample`]): the same bits, the
    /// terms of `wo` computed once for both (the path kernel's vertex).
    pub fn eval_pdf_and_sample(&self, wo: Vec3, wi: Option<Vec3>, uc: f32, u: Vec2, mode: TransportMode) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let t = self.wo_terms(wo);
        let Some(wi) = wi else { return (None, self.sample_with(wo, uc, u, mode, &t)) };
        // Both evaluations in one pass, their chains side by side (the same bits).
        match self.sample_direction(wo, uc, u, &t) {
            Some((ws, lobe, eta)) => {
                let [nee, (f, pdf)] = self.eval_pdf_lanes(wo, [wi, ws], mode, &t);
                (Some(nee), positive_finite(pdf).then_some(BsdfSample { wi: ws, f, pdf, lobe, eta }))
            }
            None => (Some(self.eval_pdf_with(wo, wi, mode, &t)), None),
        }
    }

    /// [`Self::eval_pdf_with`] toward each of `wi`: each the same operations in the same
    /// order (the same bits), taken stage by stage across the directions so that their
    /// latency chains overlap.
    #[inline(always)]
    fn eval_pdf_lanes<const N: usize>(&self, wo: Vec3, wi: [Vec3; N], mode: TransportMode, t: &WoTerms) -> [(Rgb, f32); N] {
        let none = [(Rgb::BLACK, 0.0); N];
        let ci = wo.z;
        let front = ci > 0.0;
        let (bsdf, brdf) = (self.bsdf_weight(), self.brdf_weight());
        if ci == 0.0 || (!front && bsdf <= 0.0) {
            return none;
        }
        let hv: [(Vec3, f32, bool); N] = std::array::from_fn(|k| self.half_vector(wo, wi[k], t));
        let live: [bool; N] = std::array::from_fn(|k| wi[k].z != 0.0 && hv[k].0 != Vec3::ZERO);
        let (mut oh, mut ih, mut f_d) = ([0.0f32; N], [0.0f32; N], [0.0f32; N]);
        for k in 0..N {
            (oh[k], ih[k]) = (wo.dot(hv[k].0), wi[k].dot(hv[k].0));
            f_d[k] = self.dielectric(oh[k], t).0;
        }
        let p: [PrincipledLobes; N] = std::array::from_fn(|k| self.lobes_at(front, f_d[k], t));
        let ok: [bool; N] = std::array::from_fn(|k| live[k] && compatible(hv[k].0, wo, wi[k], hv[k].2));
        let md = &self.distribution;
        let mut dg = [(0.0f32, 0.0f32, 0.0f32); N];
        for k in 0..N {
            if ok[k] {
                let h = hv[k].0;
                dg[k] = (md.d(h), Microfacet::g1_given(wo, h, || t.lambda), md.g1_inline(wi[k], h));
            }
        }
        let jacobian: [f32; N] = std::array::from_fn(|k| {
            let (_, eta_path, reflect) = hv[k];
            let (oh, ih) = (oh[k], ih[k]);
            if reflect {
                (1.0 / (4.0 * ih)).abs()
            } else {
                (eta_path * eta_path * ih / ((oh + eta_path * ih) * (oh + eta_path * ih))).abs()
            }
        });
        let (mut value, mut pdf) = ([Rgb::BLACK; N], [0.0f32; N]);
        let dv = &self.derived;
        // Reflection: the Schlick weight, the specular lobe, the clearcoat's D.
        let w: [f32; N] = std::array::from_fn(|k| {
            if hv[k].2 && ok[k] && front && (f_d[k] > 0.0 || self.clearcoat > 0.0) {
                schlick_fresnel_weight_given(oh[k], self.eta, t.inv_eta)
            } else {
                0.0
            }
        });
        for k in 0..N {
            if hv[k].2 && ok[k] && f_d[k] > 0.0 {
                let (d, g1o, g1i) = dg[k];
                let f = if front { self.fresnel_front(f_d[k], oh[k], w[k], t) } else { self.fresnel(f_d[k], oh[k], front) };
                value[k] += f * (d * (g1o * g1i) / (4.0 * ci.abs() * wi[k].z.abs()));
            }
        }
        let d_cc: [f32; N] = std::array::from_fn(|k| {
            if hv[k].2 && ok[k] && front && (self.clearcoat > 0.0 || p[k].clearcoat > 0.0) {
                gtr1_d_given(dv.cc_a2, dv.cc_ln_a2, hv[k].0)
            } else {
                0.0
            }
        });
        if front {
            for k in 0..N {
                if hv[k].2 && ok[k] && self.clearcoat > 0.0 {
                    let h = hv[k].0;
                    let f_cc = schlick_blend(Rgb::splat(0.04), w[k]).r;
                    let g_cc_o = if wo.dot(h) * wo.z <= 0.0 { 0.0 } else { t.g_cc };
                    let g_cc = g_cc_o * smith_ggx1(wi[k], h, 0.25);
                    value[k] += Rgb::splat(t.cc_w * f_cc * d_cc[k] * g_cc);
                }
            }
            if brdf > 0.0 {
                for k in 0..N {
                    if hv[k].2 {
                        value[k] += self.base_color * (t.diffuse_w * disney_diffuse_given(self.roughness, self.flatness, wi[k].z, ci, ih[k], t.fi));
                    }
                }
            }
            if self.sheen > 0.0 && self.metallic < 1.0 {
                for k in 0..N {
                    if hv[k].2 {
                        value[k] += dv.sheen_color * (t.sheen_w * schlick_weight(ih[k].abs()));
                    }
                }
            }
        }
        for k in 0..N {
            let (h, eta_path, reflect) = hv[k];
            let (d, g1o, g1i) = dg[k];
            let visible = || Microfacet::pdf_visible_given(wo * ci.signum(), h, d, g1o);
            if reflect {
                if ok[k] {
                    if p[k].reflection > 0.0 {
                        pdf[k] += p[k].reflection * visible() * jacobian[k];
                    }
                    if p[k].clearcoat > 0.0 {
                        pdf[k] += p[k].clearcoat * gtr1_pdf_given(d_cc[k], h) * jacobian[k];
                    }
                }
                pdf[k] += p[k].diffuse * warp::square_to_cosine_hemisphere_pdf(if front { wi[k] } else { -wi[k] });
            } else if ok[k] {
                if bsdf > 0.0 && f_d[k] < 1.0 {
                    let scale = match mode {
                        TransportMode::Radiance => 1.0 / (eta_path * eta_path),
                        TransportMode::Importance => 1.0,
                    };
                    let (oh, ih) = (oh[k], ih[k]);
                    let denom = oh + eta_path * ih;
                    let tr = scale * (1.0 - f_d[k]) * d * (g1o * g1i) * eta_path * eta_path * oh * ih / (ci * denom * denom);
                    let tr = (tr / wi[k].z).abs();
                    if tr.is_finite() {
                        value[k] += self.base_color.sqrt() * (bsdf * tr);
                    }
                }
                if p[k].transmission > 0.0 {
                    pdf[k] += p[k].transmission * visible() * jacobian[k];
                }
            }
        }
        std::array::from_fn(|k| if live[k] { (value[k], if pdf[k].is_finite() { pdf[k] } else { 0.0 }) } else { none[k] })
    }

    /// [`Self::eval_pdf`] given the terms of `wo`: [`Self::eval_pdf_lanes`] of one direction.
    fn eval_pdf_with(&self, wo: Vec3, wi: Vec3, mode: TransportMode, t: &WoTerms) -> (Rgb, f32) {
        let [r] = self.eval_pdf_lanes(wo, [wi], mode, t);
        r
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        self.sample_with(wo, uc, u, mode, &self.wo_terms(wo))
    }

    /// [`Self::sample`] given the terms of `wo`.
    fn sample_with(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode, t: &WoTerms) -> Option<BsdfSample> {
        let (wi, lobe, eta) = self.sample_direction(wo, uc, u, t)?;
        let (f, pdf) = self.eval_pdf_with(wo, wi, mode, t);
        if !positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample { wi, f, pdf, lobe, eta })
    }

    /// [`Self::sample`]'s direction, lobe and relative IOR, before its evaluation.
    #[inline(always)]
    fn sample_direction(&self, wo: Vec3, uc: f32, u: Vec2, t: &WoTerms) -> Option<(Vec3, LobeFlags, f32)> {
        let ci = wo.z;
        if ci == 0.0 {
            return None;
        }
        let front = ci > 0.0;
        if !front && self.bsdf_weight() <= 0.0 {
            return None;
        }
        let visible = || self.distribution.sample_visible(wo * ci.signum(), u);
        let picked = match t.opaque_lobes {
            // Without refraction, m only where the chosen lobe reads it.
            Some(p) => self.pick(wo, uc, u, &p, visible, |m| self.dielectric(wo.dot(m), t)),
            None => {
                let m = visible();
                let fr = self.dielectric(wo.dot(m), t);
                self.pick(wo, uc, u, &self.lobes(front, fr.0), || m, |_| fr)
            }
        };
        let (wi, lobe, eta) = picked?;
        let reflects = wi.z * ci > 0.0;
        if wi.z == 0.0 || reflects == lobe.contains(LobeFlags::TRANSMISSION) {
            return None;
        }
        Some((wi, lobe, eta))
    }

    /// [`Self::sample`]'s lobe by `uc` among `p`, and its direction: `m` gives the visible
    /// normal and `fr` its `fresnel::dielectric` (read by the specular lobes alone).
    #[inline(always)]
    fn pick(
        &self,
        wo: Vec3,
        uc: f32,
        u: Vec2,
        p: &PrincipledLobes,
        m: impl FnOnce() -> Vec3,
        fr: impl FnOnce(Vec3) -> (f32, f32, f32, f32),
    ) -> Option<(Vec3, LobeFlags, f32)> {
        Some(if uc < p.diffuse {
            (warp::square_to_cosine_hemisphere(u), LobeFlags::DIFFUSE_REFLECTION, 1.0)
        } else if uc < p.diffuse + p.clearcoat {
            let m = gtr1_sample(self.clearcoat_alpha, u);
            let wi = reflect(wo, m);
            if !compatible(m, wo, wi, true) {
                return None;
            }
            (wi, LobeFlags::GLOSSY_REFLECTION, 1.0)
        } else if uc < p.diffuse + p.clearcoat + p.transmission {
            let m = m();
            let (_, cos_t, eta_it, eta_ti) = fr(m);
            let wi = refract(wo, m, cos_t, eta_ti).normalize_or_zero();
            if !compatible(m, wo, wi, false) {
                return None;
            }
            (wi, LobeFlags::GLOSSY_TRANSMISSION, eta_it)
        } else {
            let m = m();
            let wi = reflect(wo, m);
            if !compatible(m, wo, wi, true) {
                return None;
            }
            (wi, LobeFlags::GLOSSY_REFLECTION, 1.0)
        })
    }

    /// What radiosity takes for this surface: the base colour times the diffuse weight.
    pub fn diffuse_albedo(&self) -> Rgb {
        self.base_color * self.brdf_weight()
    }
}

/// `principledthin` at one surface point. The sheet is the same from both sides: both
/// directions are mirrored to the side of `wo` first.
#[derive(Clone, Copy, Debug)]
pub struct PrincipledThin {
    pub base_color: Rgb,
    pub roughness: f32,
    /// GGX of the specular reflection.
    pub distribution: Microfacet,
    /// GGX of the specular transmission: roughness scaled by (0.65 eta - 0.35) (Burley
    /// 2015, figure 15).
    pub transmission_distribution: Microfacet,
    pub spec_trans: f32,
    /// Diffuse transmission, in [0, 1] (Mitsuba's `diff_trans` / 2).
    pub diff_trans: f32,
    pub eta: f32,
    pub spec_tint: f32,
    pub sheen: f32,
    pub sheen_tint: f32,
    pub flatness: f32,
    pub rates: SamplingRates,
    /// What `eval_pdf` reads at every call, from the fields above when the model is built
    /// ([`PrincipledThin::derived`]).
    pub derived: PrincipledThinDerived,
}

/// The parts of [`PrincipledThin`] that depend on its parameters alone: computed once per
/// point, not at each evaluation (the same values).
#[derive(Clone, Copy, Debug, Default)]
pub struct PrincipledThinDerived {
    /// The tinted Schlick term's normal reflectance, `tint_of(base_color) * r0_of_eta(eta)`.
    tint_r0: Rgb,
    /// `sheen_color(base_color, sheen_tint)`.
    sheen_color: Rgb,
    /// `lobes()`.
    lobes: [f32; 4],
}

impl PrincipledThin {
    /// [`PrincipledThinDerived`] of these parameters.
    pub fn derived(&self) -> PrincipledThinDerived {
        PrincipledThinDerived {
            tint_r0: tint_of(self.base_color) * r0_of_eta(self.eta),
            sheen_color: sheen_color(self.base_color, self.sheen_tint),
            lobes: self.lobes(),
        }
    }

    pub fn flags(&self) -> LobeFlags {
        LobeFlags::DIFFUSE_REFLECTION | LobeFlags::DIFFUSE_TRANSMISSION | LobeFlags::GLOSSY_REFLECTION | LobeFlags::GLOSSY_TRANSMISSION
    }

    /// (specular reflection, specular transmission, diffuse reflection, diffuse
    /// transmission), normalised.
    fn lobes(&self) -> [f32; 4] {
        let r = &self.rates;
        let (st, dt) = (self.spec_trans, self.diff_trans);
        let p = [st * r.specular * 0.5, st * r.secondary * 0.5, r.diffuse_reflection * (1.0 - st) * (1.0 - dt), r.diffuse_transmission * (1.0 - st) * dt];
        let total: f32 = p.iter().sum();
        let k = if total > 0.0 { 1.0 / total } else { 0.0 };
        p.map(|x| x * k)
    }

    /// Both directions mirrored to wo's side, and the half vector of wo and wi mirrored
    /// to that side (transmission is a reflection turned through the sheet).
    #[inline]
    fn frame(wo: Vec3, wi: Vec3) -> (Vec3, Vec3, Vec3) {
        let s = wo.z.signum();
        let (o, i) = (wo * s, wi * s);
        let h = (o + Vec3::new(i.x, i.y, i.z.abs())).normalize_or_zero();
        (o, i, h)
    }

    /// The value toward `wi` ([`Self::eval_pdf`]'s first part).
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        self.eval_pdf(wo, wi, mode).0
    }

    /// The density of `sample` toward `wi` ([`Self::eval_pdf`]'s second part).
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        self.eval_pdf(wo, wi, mode).1
    }

    /// The value and the density toward `wi`: the frame, D and G1 toward `wo` computed
    /// once for both.
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> (Rgb, f32) {
        self.eval_pdf_with(wo, wi, &mut self.wo_terms(wo))
    }

    #[inline]
    fn wo_terms(&self, wo: Vec3) -> ThinWoTerms {
        ThinWoTerms { lambda_r: None, lambda_t: None, f_wo: schlick_weight(wo.z.abs()) }
    }

    /// ([`Self::eval_pdf`] toward `wi` where given, [`Self::sample`]): the same bits, the
    /// terms of `wo` computed once for both (the path kernel's vertex).
    pub fn eval_pdf_and_sample(&self, wo: Vec3, wi: Option<Vec3>, uc: f32, u: Vec2) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let mut t = self.wo_terms(wo);
        let Some(wi) = wi else { return (None, self.sample_with(wo, uc, u, &mut t)) };
        // Both evaluations in one pass, their chains side by side (the same bits).
        match self.sample_direction(wo, uc, u) {
            Some((ws, lobe)) => {
                let [nee, (f, pdf)] = self.eval_pdf_lanes(wo, [wi, ws], &mut t);
                (Some(nee), positive_finite(pdf).then_some(BsdfSample { wi: ws, f, pdf, lobe, eta: 1.0 }))
            }
            None => (Some(self.eval_pdf_with(wo, wi, &mut t)), None),
        }
    }

    /// [`Self::eval_pdf_with`] toward each of `wi`: each the same operations in the same
    /// order (the same bits), taken stage by stage across the directions so that their
    /// latency chains overlap.
    #[inline(always)]
    fn eval_pdf_lanes<const N: usize>(&self, wo: Vec3, wi: [Vec3; N], t: &mut ThinWoTerms) -> [(Rgb, f32); N] {
        let none = [(Rgb::BLACK, 0.0); N];
        if wo.z == 0.0 {
            return none;
        }
        let fr: [(Vec3, Vec3, Vec3); N] = std::array::from_fn(|k| Self::frame(wo, wi[k]));
        let live: [bool; N] = std::array::from_fn(|k| wi[k].z != 0.0 && fr[k].2 != Vec3::ZERO);
        let (st, dt) = (self.spec_trans, self.diff_trans);
        let dv = &self.derived;
        let [p_sr, p_st, p_dr, p_dt] = dv.lobes;
        let reflect: [bool; N] = std::array::from_fn(|k| fr[k].1.z > 0.0);
        let ok: [bool; N] = std::array::from_fn(|k| live[k] && compatible(fr[k].2, fr[k].0, fr[k].1, reflect[k]));
        let mut dg = [(0.0f32, 0.0f32); N];
        for k in 0..N {
            let (o, _, h) = fr[k];
            let (p_spec, md, lambda) =
                if reflect[k] { (p_sr, &self.distribution, &mut t.lambda_r) } else { (p_st, &self.transmission_distribution, &mut t.lambda_t) };
            if ok[k] && (st > 0.0 || p_spec > 0.0) {
                dg[k] = (md.d(h), Microfacet::g1_given(o, h, || *lambda.get_or_insert_with(|| md.lambda(o))));
            }
        }
        let mut value = [Rgb::BLACK; N];
        if st > 0.0 {
            for k in 0..N {
                if ok[k] {
                    let (o, i, h) = fr[k];
                    let (ci, co) = (o.z, i.z);
                    let md = if reflect[k] { &self.distribution } else { &self.transmission_distribution };
                    let (d, g1o) = dg[k];
                    let oh = o.dot(h);
                    let f_d = fresnel::dielectric(oh, self.eta).0;
                    let kk = st * d * (g1o * md.g1_inline(i, h)) / (4.0 * ci * co.abs());
                    if reflect[k] {
                        // oh > 0 where ok.
                        let tinted = schlick_blend(dv.tint_r0, schlick_fresnel_weight_front(oh, self.eta));
                        value[k] += (Rgb::splat(f_d) * (1.0 - self.spec_tint) + tinted * self.spec_tint) * kk;
                    } else {
                        value[k] += self.base_color * ((1.0 - f_d) * kk);
                    }
                }
            }
        }
        if st < 1.0 {
            for k in 0..N {
                let (o, i, h) = fr[k];
                let (ci, co) = (o.z, i.z);
                if reflect[k] && dt < 1.0 {
                    let ih = h.dot(i);
                    let w = (1.0 - st) * (1.0 - dt);
                    value[k] += self.base_color * (w * INV_PI * disney_diffuse_given(self.roughness, self.flatness, co, ci, ih, t.f_wo));
                    if self.sheen > 0.0 {
                        value[k] += dv.sheen_color * (self.sheen * w * schlick_weight(ih.abs()));
                    }
                } else if !reflect[k] && dt > 0.0 {
                    value[k] += self.base_color * ((1.0 - st) * dt * INV_PI);
                }
            }
        }
        // (A loop, not `from_fn`: for one direction LLVM left that closure out of line.)
        let mut out = none;
        for k in (0..N).filter(|&k| live[k]) {
            let (o, i, h) = fr[k];
            let p_spec = if reflect[k] { p_sr } else { p_st };
            let mut pdf = 0.0;
            if p_spec > 0.0 && ok[k] {
                let ir = Vec3::new(i.x, i.y, i.z.abs());
                pdf += p_spec * Microfacet::pdf_visible_given(o, h, dg[k].0, dg[k].1) / (4.0 * ir.dot(h)).abs();
            }
            pdf += if reflect[k] { p_dr } else { p_dt } * i.z.abs() * INV_PI;
            out[k] = (value[k], if pdf.is_finite() { pdf } else { 0.0 });
        }
        out
    }

    /// [`Self::eval_pdf`] given the terms of `wo` (Λ filled in where first read):
    /// [`Self::eval_pdf_lanes`] of one direction.
    fn eval_pdf_with(&self, wo: Vec3, wi: Vec3, t: &mut ThinWoTerms) -> (Rgb, f32) {
        let [r] = self.eval_pdf_lanes(wo, [wi], t);
        r
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        self.sample_with(wo, uc, u, &mut self.wo_terms(wo))
    }

    /// [`Self::sample`] given the terms of `wo`.
    fn sample_with(&self, wo: Vec3, uc: f32, u: Vec2, t: &mut ThinWoTerms) -> Option<BsdfSample> {
        let (wi, lobe) = self.sample_direction(wo, uc, u)?;
        let (f, pdf) = self.eval_pdf_with(wo, wi, t);
        if !positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample { wi, f, pdf, lobe, eta: 1.0 })
    }

    /// [`Self::sample`]'s direction and lobe, before its evaluation.
    #[inline(always)]
    fn sample_direction(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<(Vec3, LobeFlags)> {
        if wo.z == 0.0 {
            return None;
        }
        let s = wo.z.signum();
        let o = wo * s;
        let [p_sr, p_st, p_dr, _] = self.derived.lobes;
        let (i, lobe) = if uc < p_sr {
            let m = self.distribution.sample_visible(o, u);
            let i = reflect(o, m);
            if i.z <= 0.0 || !compatible(m, o, i, true) {
                return None;
            }
            (i, LobeFlags::GLOSSY_REFLECTION)
        } else if uc < p_sr + p_st {
            let m = self.transmission_distribution.sample_visible(o, u);
            let r = reflect(o, m);
            let i = Vec3::new(r.x, r.y, -r.z);
            if i.z >= 0.0 || !compatible(m, o, i, false) {
                return None;
            }
            (i, LobeFlags::GLOSSY_TRANSMISSION)
        } else if uc < p_sr + p_st + p_dr {
            (warp::square_to_cosine_hemisphere(u), LobeFlags::DIFFUSE_REFLECTION)
        } else {
            (-warp::square_to_cosine_hemisphere(u), LobeFlags::DIFFUSE_TRANSMISSION)
        };
        if i.z == 0.0 {
            return None;
        }
        Some((i * s, lobe))
    }

    /// What radiosity takes for this surface: the base colour times the diffuse
    /// reflection's weight.
    pub fn diffuse_albedo(&self) -> Rgb {
        self.base_color * ((1.0 - self.spec_trans) * (1.0 - self.diff_trans))
    }
}

/// The scene's description of a `principled` or `principledthin` material: every
/// parameter a texture (scalar ones read as Mitsuba's `eval_1`).
#[derive(Clone, Debug)]
pub struct PrincipledMaterial {
    /// `principledthin` rather than `principled`.
    pub thin: bool,
    pub base_color: Texture,
    pub roughness: Texture,
    pub anisotropic: Texture,
    pub metallic: Texture,
    pub spec_trans: Texture,
    pub spec_tint: Texture,
    pub sheen: Texture,
    pub sheen_tint: Texture,
    pub flatness: Texture,
    pub clearcoat: Texture,
    pub clearcoat_gloss: Texture,
    /// `principledthin`: diffuse transmission in [0, 2].
    pub diff_trans: Texture,
    /// Interior / exterior IOR (Mitsuba's `principled` takes a constant; `specular` is
    /// converted by [`eta_from_specular`] when the scene is read).
    pub eta: Texture,
    pub rates: SamplingRates,
    /// The models `at` copies where every parameter is a constant or a checkerboard: built
    /// at the first `at` from the fields above (set them before; `textures_mut` clears it).
    pub table: ModelTable,
}

/// [`PrincipledMaterial::at`]'s models by checkerboard parities: the textures of one
/// `to_uv` share one test, so a point's model is one of 2^groups, each built once by the
/// same code from the values the textures take there (the same bits as evaluating each).
#[derive(Debug, Default)]
pub struct ModelTable(OnceLock<Option<Box<Table>>>);

#[derive(Debug)]
struct Table {
    /// Distinct `to_uv` of the checkerboards (group g is bit g of a model's index).
    to_uv: Vec<Affine2>,
    models: Vec<PrincipledAt>,
}

/// At most 8 models: more groups fall back to evaluating the textures.
const TABLE_GROUPS: usize = 3;

impl Clone for ModelTable {
    /// Empty: a clone's fields may be changed before its first `at`.
    fn clone(&self) -> Self {
        ModelTable::default()
    }
}

impl Table {
    fn build(m: &PrincipledMaterial) -> Option<Box<Table>> {
        let mut to_uv: Vec<Affine2> = Vec::new();
        let key = |a: &Affine2| a.to_cols_array().map(f32::to_bits);
        // Every field `at_with` may read (`textures` leaves out those Mitsuba's variant lacks).
        let all = [
            &m.base_color,
            &m.roughness,
            &m.anisotropic,
            &m.metallic,
            &m.spec_trans,
            &m.spec_tint,
            &m.sheen,
            &m.sheen_tint,
            &m.flatness,
            &m.clearcoat,
            &m.clearcoat_gloss,
            &m.diff_trans,
            &m.eta,
        ];
        for t in all {
            match t {
                Texture::Constant(_) => {}
                Texture::Checkerboard { to_uv: a, .. } => {
                    if !to_uv.iter().any(|b| key(b) == key(a)) {
                        to_uv.push(*a);
                    }
                }
                _ => return None,
            }
        }
        if to_uv.is_empty() || to_uv.len() > TABLE_GROUPS {
            return None;
        }
        // Group of a checkerboard (found above); its test's outcome in model `i`.
        let parity = |a: &Affine2, i: usize| to_uv.iter().position(|b| key(b) == key(a)).is_some_and(|g| (i >> g) & 1 == 1);
        let models = (0..1usize << to_uv.len())
            .map(|i| {
                // `eval_f32` and `eval` of the checkerboard where its test gives `parity`.
                let f = |t: &Texture| match t {
                    Texture::Constant(c) => c.r,
                    Texture::Checkerboard { color0, color1, to_uv } => (if parity(to_uv, i) { color1 } else { color0 }).luminance(),
                    _ => f32::NAN,
                };
                let rgb = |t: &Texture| match t {
                    Texture::Constant(c) => *c,
                    Texture::Checkerboard { color0, color1, to_uv } => {
                        if parity(to_uv, i) {
                            *color0
                        } else {
                            *color1
                        }
                    }
                    _ => Rgb::splat(f32::NAN),
                };
                m.at_with(f, rgb)
            })
            .collect();
        Some(Box::new(Table { to_uv, models }))
    }

    #[inline]
    fn at(&self, uv: Vec2) -> Option<PrincipledAt> {
        let mut i = 0;
        for (g, a) in self.to_uv.iter().enumerate() {
            i |= usize::from(checker_parity(a, uv)) << g;
        }
        self.models.get(i).copied()
    }
}

impl Default for PrincipledMaterial {
    /// Mitsuba's defaults.
    fn default() -> Self {
        let c = |v: f32| Texture::Constant(Rgb::splat(v));
        PrincipledMaterial {
            thin: false,
            base_color: c(0.5),
            roughness: c(0.5),
            anisotropic: c(0.0),
            metallic: c(0.0),
            spec_trans: c(0.0),
            spec_tint: c(0.0),
            sheen: c(0.0),
            sheen_tint: c(0.0),
            flatness: c(0.0),
            clearcoat: c(0.0),
            clearcoat_gloss: c(0.0),
            diff_trans: c(0.0),
            eta: c(eta_from_specular(0.5)),
            rates: SamplingRates::default(),
            table: ModelTable::default(),
        }
    }
}

impl PrincipledMaterial {
    /// The parameters as textures, with their names (the loader and the exporters).
    pub fn textures(&self) -> Vec<(&'static str, &Texture)> {
        let mut v = vec![
            ("base_color", &self.base_color),
            ("roughness", &self.roughness),
            ("anisotropic", &self.anisotropic),
            ("spec_trans", &self.spec_trans),
            ("spec_tint", &self.spec_tint),
            ("sheen", &self.sheen),
            ("sheen_tint", &self.sheen_tint),
            ("flatness", &self.flatness),
        ];
        if self.thin {
            v.extend([("diff_trans", &self.diff_trans), ("eta", &self.eta)]);
        } else {
            v.extend([("metallic", &self.metallic), ("clearcoat", &self.clearcoat), ("clearcoat_gloss", &self.clearcoat_gloss)]);
        }
        v
    }

    pub fn textures_mut(&mut self) -> Vec<&mut Texture> {
        self.table = ModelTable::default();
        vec![
            &mut self.base_color,
            &mut self.roughness,
            &mut self.anisotropic,
            &mut self.metallic,
            &mut self.spec_trans,
            &mut self.spec_tint,
            &mut self.sheen,
            &mut self.sheen_tint,
            &mut self.flatness,
            &mut self.clearcoat,
            &mut self.clearcoat_gloss,
            &mut self.diff_trans,
            &mut self.eta,
        ]
    }

    pub fn is_uniform(&self) -> bool {
        self.textures().iter().all(|(_, t)| t.is_constant())
    }

    /// The model at one point: textures evaluated, weights clamped to their ranges.
    pub fn model(&self, p: TexPoint) -> BsdfModel {
        self.at(p).into_model()
    }

    /// [`Self::model`] unboxed (the path kernel keeps it in a lane's slot).
    #[inline]
    pub fn at(&self, p: TexPoint) -> PrincipledAt {
        if let Some(m) = self.table.0.get_or_init(|| Table::build(self)).as_ref().and_then(|t| t.at(p.uv)) {
            return m;
        }
        self.at_evaluated(p)
    }

    /// [`Self::at`] with each texture evaluated (what the table holds, per point).
    #[inline]
    pub fn at_evaluated(&self, p: TexPoint) -> PrincipledAt {
        self.at_with(|t| t.eval_f32_inline(&p), |t| t.eval(p))
    }

    /// The model from the parameters' values: `f` a float texture's, `rgb` the base colour's.
    #[inline(always)]
    fn at_with(&self, f: impl Fn(&Texture) -> f32, rgb: impl Fn(&Texture) -> Rgb) -> PrincipledAt {
        let unit = |t: &Texture| {
            let v = f(t);
            if v.is_nan() {
                0.0
            } else {
                v.clamp(0.0, 1.0)
            }
        };
        let base_color = rgb(&self.base_color).clamp(0.0, 1.0);
        let roughness = unit(&self.roughness);
        let anisotropic = unit(&self.anisotropic);
        let spec_trans = unit(&self.spec_trans);
        let eta = f(&self.eta);
        // Textured IORs cannot be checked when the scene is read: keep them usable.
        let eta = if eta > 0.0 && eta.is_finite() { eta } else { 1.0 };
        let (ax, ay) = disney_alphas(roughness, anisotropic);
        let distribution = Microfacet::new(MicrofacetKind::Ggx, ax, ay);
        if self.thin {
            let (tx, ty) = disney_alphas((0.65 * eta - 0.35) * roughness, anisotropic);
            let dt = f(&self.diff_trans);
            let mut m = PrincipledThin {
                base_color,
                roughness,
                distribution,
                transmission_distribution: Microfacet::new(MicrofacetKind::Ggx, tx, ty),
                spec_trans,
                diff_trans: if dt.is_nan() { 0.0 } else { (0.5 * dt).clamp(0.0, 1.0) },
                eta,
                spec_tint: unit(&self.spec_tint),
                sheen: unit(&self.sheen),
                sheen_tint: unit(&self.sheen_tint),
                flatness: unit(&self.flatness),
                rates: self.rates,
                derived: PrincipledThinDerived::default(),
            };
            m.derived = m.derived();
            PrincipledAt::Thin(m)
        } else {
            // Mitsuba: an IOR of exactly 1 does not refract plausibly.
            let eta = if eta == 1.0 && !matches!(self.spec_trans, Texture::Constant(c) if c.r == 0.0) { 1.001 } else { eta };
            let mut m = Principled {
                base_color,
                roughness,
                distribution,
                metallic: unit(&self.metallic),
                spec_trans,
                eta,
                spec_tint: unit(&self.spec_tint),
                sheen: unit(&self.sheen),
                sheen_tint: unit(&self.sheen_tint),
                flatness: unit(&self.flatness),
                clearcoat: unit(&self.clearcoat),
                clearcoat_alpha: 0.1 + (0.001 - 0.1) * unit(&self.clearcoat_gloss),
                rates: self.rates,
                derived: PrincipledDerived::default(),
            };
            m.derived = m.derived();
            PrincipledAt::Full(m)
        }
    }
}

/// A `principled` or `principledthin` model at one point, unboxed ([`PrincipledMaterial::at`]).
#[derive(Clone, Copy, Debug)]
pub enum PrincipledAt {
    Full(Principled),
    Thin(PrincipledThin),
}

impl PrincipledAt {
    /// The boxed model ([`PrincipledMaterial::model`]).
    pub fn into_model(self) -> BsdfModel {
        match self {
            PrincipledAt::Full(m) => BsdfModel::Principled(Box::new(m)),
            PrincipledAt::Thin(m) => BsdfModel::PrincipledThin(Box::new(m)),
        }
    }

    pub fn flags(&self) -> LobeFlags {
        match self {
            PrincipledAt::Full(m) => m.flags(),
            PrincipledAt::Thin(m) => m.flags(),
        }
    }

    /// `Bsdf::new(self.into_model()).eval_pdf_and_sample(..)` (one-sided, opaque, no surface
    /// detail), the same bits without building the `Bsdf`: the front model takes `wo` where
    /// it is on the front or the model transmits (`Bsdf::side`); else nothing scatters.
    #[inline]
    pub fn eval_pdf_and_sample(&self, wo: Vec3, wi: Option<Vec3>, uc: f32, u: Vec2, mode: TransportMode) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let (nee, s) = match self {
            PrincipledAt::Full(m) if wo.z >= 0.0 || m.flags().intersects(LobeFlags::TRANSMISSION) => m.eval_pdf_and_sample(wo, wi, uc, u, mode),
            PrincipledAt::Thin(m) => m.eval_pdf_and_sample(wo, wi, uc, u),
            PrincipledAt::Full(_) => return (wi.map(|_| (Rgb::BLACK, 0.0)), None),
        };
        super::Bsdf::finish_conductor(1.0, false, nee, s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Principled`'s evaluation and sample as they were before the derived weights, the
    /// reciprocals of eta and the lobes without refraction: what the new ones must give.
    mod reference {
        use super::*;

        impl Principled {
            pub(super) fn ref_eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
                self.ref_eval_pdf_with(wo, wi, mode, &self.wo_terms(wo))
            }

            fn ref_half_vector(&self, wo: Vec3, wi: Vec3) -> (Vec3, f32, bool) {
                let reflect = wo.z * wi.z > 0.0;
                let eta_path = if wo.z > 0.0 { self.eta } else { 1.0 / self.eta };
                let h = wo + wi * if reflect { 1.0 } else { eta_path };
                let len = h.length();
                let h = if positive_finite(len) { h / len } else { Vec3::ZERO };
                (if h.z < 0.0 { -h } else { h }, eta_path, reflect)
            }

            fn ref_fresnel_front(&self, f_dielectric: f32, cos_i: f32, w: f32) -> Rgb {
                let (m, t) = (self.metallic, self.spec_tint);
                let eta_it = if cos_i >= 0.0 { self.eta } else { 1.0 / self.eta };
                let metal = schlick_blend(self.base_color, w) * m;
                let tinted = schlick_blend(self.derived.tint * r0_of_eta(eta_it), w) * ((1.0 - m) * t);
                Rgb::splat((1.0 - m) * (1.0 - t) * f_dielectric) + metal + tinted
            }

            /// The evaluation before the derived weights (round 17), verbatim.
            fn ref_eval_pdf_with(&self, wo: Vec3, wi: Vec3, mode: TransportMode, t: &WoTerms) -> (Rgb, f32) {
                let (ci, co) = (wo.z, wi.z);
                if ci == 0.0 || co == 0.0 {
                    return (Rgb::BLACK, 0.0);
                }
                let front = ci > 0.0;
                let (bsdf, brdf) = (self.bsdf_weight(), self.brdf_weight());
                if !front && bsdf <= 0.0 {
                    return (Rgb::BLACK, 0.0);
                }
                let (h, eta_path, reflect) = self.ref_half_vector(wo, wi);
                if h == Vec3::ZERO {
                    return (Rgb::BLACK, 0.0);
                }
                let (oh, ih) = (wo.dot(h), wi.dot(h));
                let f_d = fresnel::dielectric(oh, self.eta).0;
                let p = self.lobes(front, f_d);
                let md = &self.distribution;
                let ok = compatible(h, wo, wi, reflect);
                // D(h), G1(wo) and G1(wi), where either half wants them.
                let (d, g1o, g1i) = if ok { (md.d(h), Microfacet::g1_given(wo, h, || t.lambda), md.g1(wi, h)) } else { (0.0, 0.0, 0.0) };
                let visible = || Microfacet::pdf_visible_given(wo * ci.signum(), h, d, g1o);
                let jacobian =
                    if reflect { (1.0 / (4.0 * ih)).abs() } else { (eta_path * eta_path * ih / ((oh + eta_path * ih) * (oh + eta_path * ih))).abs() };
                let mut value = Rgb::BLACK;
                let mut pdf = 0.0;
                if reflect {
                    // The Schlick weight of the specular and the clearcoat Fresnel terms (same cosine).
                    let w = if ok && front && (f_d > 0.0 || self.clearcoat > 0.0) { schlick_fresnel_weight(oh, self.eta) } else { 0.0 };
                    if ok && f_d > 0.0 {
                        let f = if front { self.ref_fresnel_front(f_d, oh, w) } else { self.fresnel(f_d, oh, front) };
                        value += f * (d * (g1o * g1i) / (4.0 * ci.abs() * co.abs()));
                    }
                    let dv = &self.derived;
                    let d_cc = if ok && front && (self.clearcoat > 0.0 || p.clearcoat > 0.0) { gtr1_d_given(dv.cc_a2, dv.cc_ln_a2, h) } else { 0.0 };
                    if front {
                        if ok && self.clearcoat > 0.0 {
                            let f_cc = schlick_blend(Rgb::splat(0.04), w).r;
                            let g_cc_o = if wo.dot(h) * wo.z <= 0.0 { 0.0 } else { t.g_cc };
                            let g_cc = g_cc_o * smith_ggx1(wi, h, 0.25);
                            value += Rgb::splat(0.25 * self.clearcoat * f_cc * d_cc * g_cc);
                        }
                        if brdf > 0.0 {
                            value +=
                                self.base_color * (brdf * INV_PI * disney_diffuse_given(self.roughness, self.flatness, co, ci, ih, schlick_weight(ci.abs())));
                        }
                        if self.sheen > 0.0 && self.metallic < 1.0 {
                            value += dv.sheen_color * (self.sheen * (1.0 - self.metallic) * schlick_weight(ih.abs()));
                        }
                    }
                    if ok {
                        if p.reflection > 0.0 {
                            pdf += p.reflection * visible() * jacobian;
                        }
                        if p.clearcoat > 0.0 {
                            pdf += p.clearcoat * gtr1_pdf_given(d_cc, h) * jacobian;
                        }
                    }
                    pdf += p.diffuse * warp::square_to_cosine_hemisphere_pdf(if front { wi } else { -wi });
                } else if ok {
                    if bsdf > 0.0 && f_d < 1.0 {
                        let scale = match mode {
                            TransportMode::Radiance => 1.0 / (eta_path * eta_path),
                            TransportMode::Importance => 1.0,
                        };
                        let denom = oh + eta_path * ih;
                        let t = scale * (1.0 - f_d) * d * (g1o * g1i) * eta_path * eta_path * oh * ih / (ci * denom * denom);
                        let t = (t / co).abs();
                        if t.is_finite() {
                            value += self.base_color.sqrt() * (bsdf * t);
                        }
                    }
                    if p.transmission > 0.0 {
                        pdf += p.transmission * visible() * jacobian;
                    }
                }
                (value, if pdf.is_finite() { pdf } else { 0.0 })
            }

            /// The sample before the derived weights (round 17), verbatim.
            pub(super) fn ref_sample_with(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode, t: &WoTerms) -> Option<BsdfSample> {
                let ci = wo.z;
                if ci == 0.0 {
                    return None;
                }
                let front = ci > 0.0;
                if !front && self.bsdf_weight() <= 0.0 {
                    return None;
                }
                let m = self.distribution.sample_visible(wo * ci.signum(), u);
                let (f_d, cos_t, eta_it, eta_ti) = fresnel::dielectric(wo.dot(m), self.eta);
                let p = self.lobes(front, f_d);
                let (wi, lobe, eta) = if uc < p.diffuse {
                    (warp::square_to_cosine_hemisphere(u), LobeFlags::DIFFUSE_REFLECTION, 1.0)
                } else if uc < p.diffuse + p.clearcoat {
                    let m = gtr1_sample(self.clearcoat_alpha, u);
                    let wi = reflect(wo, m);
                    if !compatible(m, wo, wi, true) {
                        return None;
                    }
                    (wi, LobeFlags::GLOSSY_REFLECTION, 1.0)
                } else if uc < p.diffuse + p.clearcoat + p.transmission {
                    let wi = refract(wo, m, cos_t, eta_ti).normalize_or_zero();
                    if !compatible(m, wo, wi, false) {
                        return None;
                    }
                    (wi, LobeFlags::GLOSSY_TRANSMISSION, eta_it)
                } else {
                    let wi = reflect(wo, m);
                    if !compatible(m, wo, wi, true) {
                        return None;
                    }
                    (wi, LobeFlags::GLOSSY_REFLECTION, 1.0)
                };
                let reflects = wi.z * ci > 0.0;
                if wi.z == 0.0 || reflects == lobe.contains(LobeFlags::TRANSMISSION) {
                    return None;
                }
                let (f, pdf) = self.ref_eval_pdf_with(wo, wi, mode, t);
                if !positive_finite(pdf) {
                    return None;
                }
                Some(BsdfSample { wi, f, pdf, lobe, eta })
            }
        }
    }

    #[test]
    fn specular_half_is_eta_1_5() {
        // Burley: specular 0.5 is a normal reflectance of 4 %, i.e. IOR 1.5.
        assert!((eta_from_specular(0.5) - 1.5).abs() < 1e-6);
        assert!((r0_of_eta(eta_from_specular(0.7)) - 0.08 * 0.7).abs() < 1e-6);
    }

    #[test]
    fn gtr1_is_normalised_and_sampled_by_its_pdf() {
        // ∫ D(m) cos θm dm = 1, and the sampler inverts its cos θ distribution: the
        // probability of cos θ below that of the sample drawn with u.y is 1 - u.y (Mitsuba's
        // mapping runs from the pole at u.y = 0; midpoint rule).
        let mass_below = |alpha: f32, c_max: f64| -> f64 {
            let n = 400_000;
            (0..n)
                .map(|k| {
                    let c = (k as f64 + 0.5) / n as f64 * c_max;
                    2.0 * std::f64::consts::PI * gtr1_pdf(alpha, Vec3::new((1.0 - c * c).sqrt() as f32, 0.0, c as f32)) as f64 * c_max / n as f64
                })
                .sum()
        };
        for alpha in [0.05f32, 0.1, 0.3] {
            let total = mass_below(alpha, 1.0);
            assert!((total - 1.0).abs() < 2e-3, "alpha {alpha}: {total}");
            for uy in [0.2f32, 0.5, 0.8] {
                let m = gtr1_sample(alpha, Vec2::new(0.3, uy));
                assert!((m.length() - 1.0).abs() < 1e-5 && m.z > 0.0);
                let below = mass_below(alpha, m.z as f64);
                assert!((below - (1.0 - uy as f64)).abs() < 2e-3, "alpha {alpha} u {uy}: {below}");
            }
        }
    }

    /// The fused evaluation (`eval_pdf`: `sample` and the path kernel's
    /// `Bsdf::eval_pdf_and_sample` use it) gives the bits of `eval` and `pdf` called apart,
    /// and a sample's value and density are `eval`'s and `pdf`'s toward its direction:
    /// `principled` and `principledthin` with every parameter a checkerboard (the float ones
    /// read as `eval_1`: colours swapped, luminance), at many points, in both modes, with
    /// random and mirror directions on both sides and grazing ones.
    #[test]
    fn shared_wo_terms_give_the_separate_calls_bits() {
        use super::super::Bsdf;
        use crate::sampling::rng::Pcg32;
        let mut rng = Pcg32::new(19, 7);
        let checker = |rng: &mut Pcg32, lo: f32, hi: f32| {
            let mut v = || lo + (hi - lo) * rng.next_f32();
            let (a, b) = (v(), v());
            let scale = 1.0 + 30.0 * rng.next_f32();
            Texture::Checkerboard { color0: Rgb::splat(a), color1: Rgb::splat(b), to_uv: glam::Affine2::from_scale(Vec2::splat(scale)) }
        };
        let dir = |rng: &mut Pcg32| warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let bits = |(f, pdf): (Rgb, f32)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits());
        let sample_bits = |s: Option<BsdfSample>| s.map(|s| (s.wi.to_array().map(f32::to_bits), bits((s.f, s.pdf)), s.lobe, s.eta.to_bits()));
        let grazing = [Vec3::new(1.0, 0.0, 1e-4).normalize(), Vec3::new(0.0, -1.0, -1e-4).normalize(), Vec3::Z, -Vec3::Z];
        let (mut samples, mut specular, mut transmitted) = (0, 0, 0);
        for k in 0..120 {
            let thin = k % 3 == 2;
            let mut m = PrincipledMaterial { thin, ..Default::default() };
            m.base_color =
                Texture::Checkerboard { color0: Rgb::new(0.2, 0.8, 0.1), color1: Rgb::new(0.9, 0.3, 0.5), to_uv: glam::Affine2::from_scale(Vec2::splat(7.0)) };
            for t in [&mut m.roughness, &mut m.anisotropic, &mut m.metallic, &mut m.spec_trans, &mut m.spec_tint, &mut m.sheen, &mut m.sheen_tint] {
                *t = checker(&mut rng, -0.1, 1.1);
            }
            m.flatness = checker(&mut rng, -0.2, 1.0);
            m.clearcoat = checker(&mut rng, -0.1, 1.0);
            m.clearcoat_gloss = checker(&mut rng, 0.0, 1.0);
            m.diff_trans = checker(&mut rng, 0.0, 2.2);
            m.eta = checker(&mut rng, 1.0, 2.0);
            if k % 7 == 0 {
                m.rates = SamplingRates { diffuse_reflection: 0.3, specular: 2.0, secondary: 0.5, diffuse_transmission: 0.0 };
            }
            for _ in 0..8 {
                let at = m.at(Vec2::new(rng.next_f32(), rng.next_f32()).into());
                let model = at.into_model();
                // One-sided, two-sided (the back mirrored) and masked.
                let bsdf = match k % 4 {
                    1 => Bsdf { back: Some(model.clone()), ..Bsdf::new(model.clone()) },
                    3 => Bsdf { opacity: 0.7, ..Bsdf::new(model.clone()) },
                    _ => Bsdf::new(model.clone()),
                };
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let mut pairs: Vec<(Vec3, Vec3)> = (0..60).map(|_| (dir(&mut rng), dir(&mut rng))).collect();
                    pairs.extend(grazing.iter().flat_map(|&a| grazing.iter().map(move |&c| (a, c))));
                    pairs.extend((0..20).map(|_| dir(&mut rng)).map(|w| (w, fresnel::reflect_z(w))));
                    for (wo, wi) in pairs {
                        let (uc, u) = (rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()));
                        let (nee, s) = bsdf.eval_pdf_and_sample(wo, Some(wi), uc, u, mode);
                        assert_eq!(nee.map(bits), Some(bits((bsdf.eval(wo, wi, mode), bsdf.pdf(wo, wi, mode)))), "{model:?} {mode:?} {wo} {wi}");
                        assert_eq!(sample_bits(s), sample_bits(bsdf.sample(wo, uc, u, mode)), "{model:?} {mode:?} {wo} {uc} {u}");
                        // The path kernel's route without a `Bsdf` (one-sided and opaque).
                        if k % 2 == 0 {
                            let (at_nee, at_s) = at.eval_pdf_and_sample(wo, Some(wi), uc, u, mode);
                            assert_eq!(at_nee.map(bits), nee.map(bits), "{model:?} {mode:?} {wo} {wi}");
                            assert_eq!(sample_bits(at_s), sample_bits(s), "{model:?} {mode:?} {wo} {uc} {u}");
                            assert_eq!(at.eval_pdf_and_sample(wo, None, uc, u, mode).0.map(bits), None);
                        }
                        // The sample's value and density are those toward its direction.
                        if let Some(s) = model.sample(wo, uc, u, mode) {
                            assert_eq!(bits((s.f, s.pdf)), bits((model.eval(wo, s.wi, mode), model.pdf(wo, s.wi, mode))), "{model:?} {mode:?} {wo} {uc} {u}");
                            samples += 1;
                            specular += usize::from(s.lobe.contains(LobeFlags::GLOSSY_REFLECTION));
                            transmitted += usize::from(s.lobe.contains(LobeFlags::TRANSMISSION));
                        }
                    }
                }
            }
        }
        assert!(samples > 50_000 && specular > 10_000 && transmitted > 5_000, "{samples} samples, {specular} specular, {transmitted} transmitted");
    }

    /// The `k`th random model of the bit-for-bit tests, from numbers `v(lo, hi)`: parameters
    /// a little outside their ranges too, every third opaque, IOR 1, near 1, below and above
    /// it, every seventh with its own sampling rates.
    fn random_model(k: usize, v: &mut impl FnMut(f32, f32) -> f32) -> Principled {
        let c = |x: f32| Texture::Constant(Rgb::splat(x));
        let mut m = PrincipledMaterial { base_color: Texture::Constant(Rgb::new(v(0.0, 1.0), v(0.0, 1.0), v(0.0, 1.0))), ..Default::default() };
        for t in
            [&mut m.roughness, &mut m.anisotropic, &mut m.metallic, &mut m.spec_tint, &mut m.sheen, &mut m.sheen_tint, &mut m.clearcoat, &mut m.clearcoat_gloss]
        {
            *t = c(v(-0.1, 1.1));
        }
        m.flatness = c(if k.is_multiple_of(2) { 0.0 } else { v(-0.2, 1.0) });
        m.spec_trans = c(if k.is_multiple_of(3) { 0.0 } else { v(-0.1, 1.1) });
        m.eta = c(match k % 11 {
            0 => 1.0,
            1 => 1.0 + v(0.0, 1e-3),
            2 => v(0.5, 1.0),
            _ => v(1.0, 2.5),
        });
        if k.is_multiple_of(7) {
            m.rates = SamplingRates { diffuse_reflection: v(0.0, 2.0), specular: v(0.0, 2.0), secondary: v(0.0, 2.0), diffuse_transmission: 0.0 };
        }
        let PrincipledAt::Full(model) = m.at_evaluated(Vec2::ZERO.into()) else { unreachable!("not thin") };
        model
    }

    /// The evaluation and the sample with the derived weights, reciprocals of eta and lobes
    /// without refraction give the bits of the code before them (`reference`), for random
    /// models (a third opaque, some of IOR 1 or near it), directions on both sides, grazing
    /// and mirror ones, and sample numbers.
    #[test]
    fn derived_terms_give_the_reference_bits() {
        use crate::sampling::rng::Pcg32;
        let mut rng = Pcg32::new(23, 5);
        let mut v = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let bits = |(f, pdf): (Rgb, f32)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits());
        let sample_bits = |s: Option<BsdfSample>| s.map(|s| (s.wi.to_array().map(f32::to_bits), bits((s.f, s.pdf)), s.lobe, s.eta.to_bits()));
        let grazing = [Vec3::new(1.0, 0.0, 1e-4).normalize(), Vec3::new(0.0, -1.0, -1e-4).normalize(), Vec3::Z, -Vec3::Z];
        let (mut opaque, mut samples) = (0, 0);
        for k in 0..600 {
            let model = random_model(k, &mut v);
            opaque += usize::from(model.wo_terms(Vec3::Z).opaque_lobes.is_some());
            let mut pairs: Vec<(Vec3, Vec3)> = (0..200)
                .map(|_| {
                    (warp::square_to_uniform_sphere(Vec2::new(v(0.0, 1.0), v(0.0, 1.0))), warp::square_to_uniform_sphere(Vec2::new(v(0.0, 1.0), v(0.0, 1.0))))
                })
                .collect();
            pairs.extend(grazing.iter().flat_map(|&a| grazing.iter().map(move |&c| (a, c))));
            pairs.extend((0..20).map(|_| warp::square_to_uniform_sphere(Vec2::new(v(0.0, 1.0), v(0.0, 1.0)))).map(|w| (w, fresnel::reflect_z(w))));
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                for &(wo, wi) in &pairs {
                    let (uc, u) = (v(0.0, 1.0), Vec2::new(v(0.0, 1.0), v(0.0, 1.0)));
                    let want = bits(model.ref_eval_pdf(wo, wi, mode));
                    assert_eq!(bits(model.eval_pdf(wo, wi, mode)), want, "{model:?} {mode:?} {wo} {wi}");
                    let want_s = sample_bits(model.ref_sample_with(wo, uc, u, mode, &model.wo_terms(wo)));
                    assert_eq!(sample_bits(model.sample(wo, uc, u, mode)), want_s, "{model:?} {mode:?} {wo} {uc} {u}");
                    let (nee, s) = model.eval_pdf_and_sample(wo, Some(wi), uc, u, mode);
                    assert_eq!((nee.map(bits), sample_bits(s)), (Some(want), want_s), "{model:?} {mode:?} {wo} {wi} {uc} {u}");
                    samples += usize::from(want_s.is_some());
                }
            }
        }
        assert!(opaque > 150 && samples > 150_000, "{opaque} opaque models, {samples} samples");
    }

    /// Directions evaluated side by side (`eval_pdf_lanes`: the light sample's and the
    /// sample's in `eval_pdf_and_sample`) give each one's `eval_pdf_with` bits (one
    /// direction alone; `derived_terms_give_the_reference_bits` checks that against the
    /// earlier code), so neither direction's result depends on the other: random
    /// models (a third opaque, some of IOR 1 or near it or below 1), directions on both
    /// sides, grazing, in the tangent plane, mirror and sampled ones, both modes.
    #[test]
    fn paired_evaluations_give_the_single_bits() {
        use crate::sampling::rng::Pcg32;
        let mut rng = Pcg32::new(41, 3);
        let mut v = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let bits = |(f, pdf): (Rgb, f32)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits());
        let special = [Vec3::new(1.0, 0.0, 1e-4).normalize(), Vec3::new(0.0, -1.0, -1e-4).normalize(), Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.6, -0.8, 0.0)];
        let (mut sampled, mut nonzero) = (0, 0);
        for k in 0..600 {
            let model = random_model(k, &mut v);
            let dir = |v: &mut dyn FnMut(f32, f32) -> f32| warp::square_to_uniform_sphere(Vec2::new(v(0.0, 1.0), v(0.0, 1.0)));
            let mut wos: Vec<Vec3> = (0..60).map(|_| dir(&mut v)).collect();
            wos.extend(special);
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                for &wo in &wos {
                    let t = model.wo_terms(wo);
                    let (uc, u) = (v(0.0, 1.0), Vec2::new(v(0.0, 1.0), v(0.0, 1.0)));
                    let mut dirs = vec![dir(&mut v), dir(&mut v), fresnel::reflect_z(wo), -wo];
                    dirs.extend(special);
                    if let Some((ws, _, _)) = model.sample_direction(wo, uc, u, &t) {
                        dirs.push(ws);
                        sampled += 1;
                    }
                    let a = dirs[(k + 3 * dirs.len()) % dirs.len()];
                    for &b in &dirs {
                        let want = [bits(model.eval_pdf_with(wo, a, mode, &t)), bits(model.eval_pdf_with(wo, b, mode, &t))];
                        assert_eq!(model.eval_pdf_lanes(wo, [a, b], mode, &t).map(bits), want, "{model:?} {mode:?} {wo} {a} {b}");
                        assert_eq!(model.eval_pdf_lanes(wo, [b], mode, &t).map(bits), [want[1]], "{model:?} {mode:?} {wo} {b}");
                        nonzero += usize::from(want[1].3 != 0);
                    }
                }
            }
        }
        assert!(sampled > 50_000 && nonzero > 200_000, "{sampled} sampled, {nonzero} with a density");
    }

    /// [`paired_evaluations_give_the_single_bits`] for `principledthin`: random sheets
    /// (some all specular, some all diffuse, IOR below and above 1), Λ filled in by either
    /// evaluation first.
    #[test]
    fn thin_paired_evaluations_give_the_single_bits() {
        use crate::sampling::rng::Pcg32;
        let mut rng = Pcg32::new(43, 1);
        let mut v = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let c = |x: f32| Texture::Constant(Rgb::splat(x));
        let bits = |(f, pdf): (Rgb, f32)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits());
        let special = [Vec3::new(1.0, 0.0, 1e-4).normalize(), Vec3::new(0.0, -1.0, -1e-4).normalize(), Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.6, -0.8, 0.0)];
        let (mut sampled, mut nonzero) = (0, 0);
        for k in 0..600 {
            let mut m = PrincipledMaterial { thin: true, base_color: Texture::Constant(Rgb::new(v(0.0, 1.0), v(0.0, 1.0), v(0.0, 1.0))), ..Default::default() };
            for t in [&mut m.roughness, &mut m.anisotropic, &mut m.spec_tint, &mut m.sheen, &mut m.sheen_tint] {
                *t = c(v(-0.1, 1.1));
            }
            m.flatness = c(if k % 2 == 0 { 0.0 } else { v(-0.2, 1.0) });
            m.spec_trans = c(match k % 5 {
                0 => 0.0,
                1 => 1.0,
                _ => v(-0.1, 1.1),
            });
            m.diff_trans = c(v(0.0, 2.2));
            m.eta = c(if k % 4 == 0 { v(0.5, 1.0) } else { v(1.0, 2.5) });
            if k % 7 == 0 {
                m.rates = SamplingRates { diffuse_reflection: v(0.0, 2.0), specular: v(0.0, 2.0), secondary: v(0.0, 2.0), diffuse_transmission: v(0.0, 2.0) };
            }
            let PrincipledAt::Thin(model) = m.at_evaluated(Vec2::ZERO.into()) else { unreachable!("thin") };
            let dir = |v: &mut dyn FnMut(f32, f32) -> f32| warp::square_to_uniform_sphere(Vec2::new(v(0.0, 1.0), v(0.0, 1.0)));
            let mut wos: Vec<Vec3> = (0..60).map(|_| dir(&mut v)).collect();
            wos.extend(special);
            for &wo in &wos {
                let (uc, u) = (v(0.0, 1.0), Vec2::new(v(0.0, 1.0), v(0.0, 1.0)));
                let mut dirs = vec![dir(&mut v), dir(&mut v), fresnel::reflect_z(wo), -wo];
                dirs.extend(special);
                if let Some((ws, _)) = model.sample_direction(wo, uc, u) {
                    dirs.push(ws);
                    sampled += 1;
                }
                let a = dirs[k % dirs.len()];
                for &b in &dirs {
                    let want = [bits(model.eval_pdf_with(wo, a, &mut model.wo_terms(wo))), bits(model.eval_pdf_with(wo, b, &mut model.wo_terms(wo)))];
                    assert_eq!(model.eval_pdf_lanes(wo, [a, b], &mut model.wo_terms(wo)).map(bits), want, "{model:?} {wo} {a} {b}");
                    // Terms of wo shared with an evaluation before.
                    let mut t = model.wo_terms(wo);
                    model.eval_pdf_with(wo, b, &mut t);
                    assert_eq!(model.eval_pdf_lanes(wo, [a, b], &mut t).map(bits), want, "{model:?} {wo} {a} {b}");
                    assert_eq!(model.eval_pdf_lanes(wo, [b], &mut model.wo_terms(wo)).map(bits), [want[1]], "{model:?} {wo} {b}");
                    nonzero += usize::from(want[1].3 != 0);
                }
            }
        }
        assert!(sampled > 25_000 && nonzero > 150_000, "{sampled} sampled, {nonzero} with a density");
    }

    /// The table's models are those of the textures evaluated at each point, bit for bit
    /// (Debug prints every float's shortest round-trip form): the three bsdf_spheres
    /// textured scenes' materials and random mixes of constants and checkerboards sharing
    /// up to four `to_uv` (four falls back), both variants, IOR 1 included.
    #[test]
    fn table_models_are_the_evaluated_models() {
        use crate::sampling::rng::Pcg32;
        let mut rng = Pcg32::new(5, 11);
        let scales = [25.0, 12.5, 7.0, 3.0];
        let cb = |c0: f32, c1: f32, s: f32| Texture::Checkerboard {
            color0: Rgb::splat(c0),
            color1: Rgb::splat(c1),
            to_uv: glam::Affine2::from_scale(Vec2::splat(s)),
        };
        let mut scene1 = PrincipledMaterial { base_color: Texture::Constant(Rgb::new(0.2, 0.8, 0.1)), roughness: Texture::from(0.15), ..Default::default() };
        (scene1.anisotropic, scene1.metallic, scene1.clearcoat, scene1.sheen) =
            (cb(0.05, 0.8, 25.0), cb(0.7, 0.1, 25.0), cb(0.9, 0.1, 12.5), cb(0.2, 0.9, 12.5));
        let mut thin =
            PrincipledMaterial { thin: true, base_color: Texture::Constant(Rgb::new(0.7, 0.1, 0.1)), eta: Texture::from(1.33), ..Default::default() };
        (thin.anisotropic, thin.spec_trans, thin.diff_trans, thin.sheen) = (cb(0.05, 0.8, 25.0), cb(0.2, 0.8, 25.0), cb(0.4, 1.4, 12.5), cb(0.1, 0.8, 12.5));
        let mut materials = vec![scene1, thin];
        let (mut tabled, mut fallback) = (0, 0);
        for k in 0..200 {
            let mut m = PrincipledMaterial { thin: k % 3 == 2, ..Default::default() };
            let groups = 1 + k % 4;
            let param = |rng: &mut Pcg32, lo: f32, hi: f32| {
                let constant = rng.next_f32() < 0.4;
                let scale = scales[(rng.next_u32() as usize) % groups];
                let mut v = || lo + (hi - lo) * rng.next_f32();
                if constant {
                    Texture::from(v())
                } else {
                    cb(v(), v(), scale)
                }
            };
            for t in [&mut m.roughness, &mut m.anisotropic, &mut m.metallic, &mut m.spec_trans, &mut m.spec_tint, &mut m.sheen, &mut m.sheen_tint] {
                *t = param(&mut rng, -0.1, 1.1);
            }
            m.flatness = param(&mut rng, -0.2, 1.0);
            m.clearcoat = param(&mut rng, -0.1, 1.0);
            m.clearcoat_gloss = param(&mut rng, 0.0, 1.0);
            m.diff_trans = param(&mut rng, 0.0, 2.2);
            m.eta = if k % 5 == 0 { Texture::from(1.0) } else { param(&mut rng, 0.9, 2.0) };
            if k % 4 == 1 {
                m.base_color = Texture::Checkerboard {
                    color0: Rgb::new(0.2, 0.8, 0.1),
                    color1: Rgb::new(0.9, 0.3, 1.5),
                    to_uv: glam::Affine2::from_scale(Vec2::splat(scales[0])),
                };
            }
            materials.push(m);
        }
        for m in &materials {
            for i in 0..400 {
                // Random points, and points on the checkers' edges.
                let uv = if i % 4 == 0 {
                    Vec2::new((rng.next_u32() % 200) as f32 / 50.0, (rng.next_u32() % 200) as f32 / 25.0 - 2.0)
                } else {
                    Vec2::new(rng.next_f32() * 4.0 - 2.0, rng.next_f32() * 4.0 - 2.0)
                };
                let p = TexPoint::from(uv);
                assert_eq!(format!("{:?}", m.at(p)), format!("{:?}", m.at_evaluated(p)), "{uv}");
            }
            match m.table.0.get() {
                Some(Some(_)) => tabled += 1,
                _ => fallback += 1,
            }
        }
        assert!(tabled > 100 && fallback > 20, "{tabled} tabled, {fallback} fallback");
        // A clone starts empty; `textures_mut` empties the table.
        let mut m = materials[0].clone();
        assert!(m.table.0.get().is_none());
        let p = TexPoint::from(Vec2::new(0.01, 0.01));
        m.at(p);
        *m.textures_mut()[0] = Texture::from(0.9);
        assert_eq!(format!("{:?}", m.at(p)), format!("{:?}", m.at_evaluated(p)));
    }

    #[test]
    fn float_checkerboard_is_the_swapped_colour_checkerboard_luminance() {
        let (c0, c1) = (Rgb::new(0.05, 0.3, 0.7), Rgb::new(0.8, 0.1, 0.2));
        let to_uv = glam::Affine2::from_scale(Vec2::new(25.0, 12.5));
        let t = Texture::Checkerboard { color0: c0, color1: c1, to_uv };
        let swapped = Texture::Checkerboard { color0: c1, color1: c0, to_uv };
        let mut rng = crate::sampling::rng::Pcg32::new(3, 1);
        for _ in 0..20_000 {
            let uv = Vec2::new(rng.next_f32() * 3.0 - 1.0, rng.next_f32() * 3.0 - 1.0);
            assert_eq!(t.eval_f32(uv).to_bits(), swapped.eval(uv).luminance().to_bits(), "{uv}");
        }
    }

    #[test]
    fn schlick_is_r0_at_normal_incidence_and_one_at_grazing() {
        let r0 = Rgb::new(0.1, 0.5, 0.9);
        let n = schlick(r0, 1.0, 1.5);
        assert!((n - r0).map(f32::abs).max_component() < 1e-6);
        assert!((schlick(r0, 1e-6, 1.5) - Rgb::WHITE).map(f32::abs).max_component() < 1e-4);
        // From inside past the critical angle: total internal reflection.
        assert_eq!(schlick(r0, -0.3, 1.5), Rgb::WHITE);
    }
}
