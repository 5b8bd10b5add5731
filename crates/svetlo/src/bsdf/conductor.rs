//! Conductors (Mitsuba `conductor` and `roughconductor`): Fresnel reflectance of a complex
//! IOR per RGB channel, scaled by `specular_reflectance`. Front side only.

use super::fresnel::{self, reflect};
use super::lane_samples::LaneSamples;
use super::microfacet::{self as mf, Microfacet, VisibleNormalLanes};
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
        self.sample_given(wo, u, || self.distribution.lambda(wo))
    }

    /// [`Self::sample`] with Λ(wo) from `lambda_o`: the same sample.
    #[inline]
    fn sample_given(&self, wo: Vec3, u: Vec2, lambda_o: impl FnOnce() -> f32) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let m = self.distribution.sample_visible(wo, u);
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
    /// (The path kernel runs eight at once: [`rough_conductor_lanes`].)
    pub(crate) fn eval_pdf_and_sample(&self, wo: Vec3, wi: Option<Vec3>, u: Vec2) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let mut lambda_o = None;
        let mut lambda = || *lambda_o.get_or_insert_with(|| self.distribution.lambda(wo));
        let nee = wi.map(|wi| self.eval_pdf_given(wo, wi, &mut lambda));
        (nee, self.sample_given(wo, u, lambda))
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

/// `N` lanes of Beckmann (or GGX) rough conductors for [`rough_conductor_lanes`] (or
/// [`rough_conductor_ggx_lanes`]), on the model's side
/// (as `Bsdf::side` mirrors them). Unused lanes keep the defaults (or earlier lanes' values).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RoughConductorLanes<const N: usize> {
    /// The roughness, `wo` (upper hemisphere) and the sample's numbers `u`.
    pub normals: VisibleNormalLanes<N>,
    /// Toward the light sample (local; below the surface where there is none).
    pub wi: [[f32; N]; 3],
    pub eta: [[f32; N]; 3],
    pub k: [[f32; N]; 3],
    pub specular_reflectance: [[f32; N]; 3],
}

impl<const N: usize> Default for RoughConductorLanes<N> {
    fn default() -> Self {
        RoughConductorLanes {
            normals: VisibleNormalLanes::default(),
            wi: [[0.0; N], [0.0; N], [-1.0; N]],
            eta: [[1.0; N]; 3],
            k: [[0.0; N]; 3],
            specular_reflectance: [[1.0; N]; 3],
        }
    }
}

impl<const N: usize> RoughConductorLanes<N> {
    /// Lane `l`: conductor `c` seen from `wo` (on its side, upper hemisphere), the light
    /// sample toward `wi` where there is one, the sample's numbers `u`.
    #[inline]
    pub(crate) fn set(&mut self, l: usize, c: &RoughConductor, wo: Vec3, wi: Option<Vec3>, u: Vec2) {
        let md = &c.distribution;
        let wi = wi.unwrap_or(Vec3::NEG_Z);
        let q = &mut self.normals;
        (q.alpha[0][l], q.alpha[1][l]) = (md.alpha_u, md.alpha_v);
        (q.u[0][l], q.u[1][l]) = (u.x, u.y);
        for k in 0..3 {
            q.v[k][l] = wo[k];
            self.wi[k][l] = wi[k];
            (self.eta[k][l], self.k[k][l], self.specular_reflectance[k][l]) = (c.eta[k], c.k[k], c.specular_reflectance[k]);
        }
    }
}

/// [`RoughConductor::eval_pdf_and_sample`] of `used` lanes at once: the visible normals
/// (`sample_visible_beckmann_lanes`), then for both directions (the light sample's and the
/// sample's) the half vector, D, G1 both ways, the densities and the Fresnel term, each
/// lane's operations those of the scalar routine, with selects for its branches. D's expf is
/// glibc's as vector lanes (`math::expf`), and the Fresnel channels that count (`d` not 0) are
/// packed eight f64 lanes a step, whichever lane and direction they come from: about three
/// lanes in eight are used, and a channel is five divisions and square roots. The same bits.
#[inline(always)]
pub(crate) fn rough_conductor_lanes<const N: usize>(q: &RoughConductorLanes<N>, used: usize) -> LaneSamples<N> {
    conductor_lanes::<N, false>(q, used)
}

/// [`rough_conductor_lanes`] of GGX rough conductors (`q.normals` holds their roughness,
/// `wo` and `u` likewise): the visible normals in closed form (`sample_visible_ggx_lanes`),
/// D and Λ GGX's. The same bits as the scalar routine.
#[inline(always)]
pub(crate) fn rough_conductor_ggx_lanes<const N: usize>(q: &RoughConductorLanes<N>, used: usize) -> LaneSamples<N> {
    conductor_lanes::<N, true>(q, used)
}

/// The body of [`rough_conductor_lanes`] (Beckmann) and [`rough_conductor_ggx_lanes`] (`GGX`).
#[inline(always)]
fn conductor_lanes<const N: usize, const GGX: bool>(q: &RoughConductorLanes<N>, used: usize) -> LaneSamples<N> {
    let b = &q.normals;
    let m = if GGX { mf::sample_visible_ggx_lanes(b, &std::array::from_fn(|l| l < used)) } else { mf::sample_visible_beckmann_lanes(b) };
    // Per direction (0: toward the light sample, 1: the sample's), as `eval_pdf_given`.
    let (mut wi, mut h) = ([[[0.0f32; N]; 3]; 2], [[[0.0f32; N]; 3]; 2]);
    let (mut x, mut c2, mut ok) = ([[0.0f32; N]; 2], [[0.0f32; N]; 2], [[false; N]; 2]);
    let mut lambda = [[0.0f32; N]; 3];
    for l in 0..N {
        let (ax, ay) = (b.alpha[0][l], b.alpha[1][l]);
        let wo = Vec3::new(b.v[0][l], b.v[1][l], b.v[2][l]);
        let ws = reflect(wo, Vec3::new(m[0][l], m[1][l], m[2][l]));
        let lambda_of = |w: Vec3| if GGX { mf::ggx_lambda(ax, ay, w) } else { mf::beckmann_lambda(ax, ay, w) };
        lambda[0][l] = lambda_of(wo);
        for (e, w) in [Vec3::new(q.wi[0][l], q.wi[1][l], q.wi[2][l]), ws].into_iter().enumerate() {
            let hh = (wo + w).normalize();
            if !GGX {
                (x[e][l], c2[e][l]) = mf::beckmann_d_exponent(ax, ay, hh);
            }
            lambda[1 + e][l] = lambda_of(w);
            ok[e][l] = !(wo.z <= 0.0 || w.z <= 0.0) && hh.z > 0.0;
            for k in 0..3 {
                wi[e][k][l] = w[k];
                h[e][k][l] = hh[k];
            }
        }
    }
    // D's e^x, only where D is asked for and m.z > 0 (`Microfacet::d`'s first test) and x is
    // not below -104 (`beckmann_d_exp`).
    let ex = if GGX { x } else { mf::beckmann_d_exp_lanes(&x, &ok, used) };
    let (mut scale, mut pdf, mut cos) = ([[0.0f32; N]; 2], [[0.0f32; N]; 2], [[0.0f32; N]; 2]);
    let mut fresnel = [[false; N]; 2];
    for l in 0..N {
        let (ax, ay) = (b.alpha[0][l], b.alpha[1][l]);
        let wo = Vec3::new(b.v[0][l], b.v[1][l], b.v[2][l]);
        for e in 0..2 {
            let w = Vec3::new(wi[e][0][l], wi[e][1][l], wi[e][2][l]);
            let hh = Vec3::new(h[e][0][l], h[e][1][l], h[e][2][l]);
            let d = if hh.z <= 0.0 {
                0.0
            } else if GGX {
                mf::ggx_d(ax, ay, hh)
            } else {
                mf::beckmann_d_of(ex[e][l], ax, ay, c2[e][l])
            };
            let g1o = Microfacet::g1_given(wo, hh, || lambda[0][l]);
            let wm = w.dot(hh);
            let p = if wm <= 0.0 { 0.0 } else { Microfacet::pdf_visible_given(wo, hh, d, g1o) / (4.0 * wm) };
            let g = g1o * Microfacet::g1_given(w, hh, || lambda[1 + e][l]);
            let valid = !(wo.z <= 0.0 || w.z <= 0.0);
            pdf[e][l] = if valid { p } else { 0.0 };
            scale[e][l] = d * g / (4.0 * wo.z * w.z);
            fresnel[e][l] = valid && d != 0.0;
            cos[e][l] = wo.dot(hh);
        }
    }
    // The Fresnel channels that count, packed: (lane, direction) pairs' three channels,
    // channel `a` at `a` of the flat rows (a row of eight f64 a step).
    const STEP: usize = 8;
    let mut fc = [[0.0f64; STEP]; 6];
    let mut fnk = [[[1.0f32; STEP]; 6]; 2];
    let mut at = [[0usize; N]; 2];
    let mut n = 0usize;
    {
        let (fc, [fn_, fk]) = (fc.as_flattened_mut(), fnk.each_mut().map(|r| r.as_flattened_mut()));
        for l in 0..used.min(N) {
            for e in 0..2 {
                if !fresnel[e][l] {
                    continue;
                }
                at[e][l] = n;
                let c = fresnel::conductor_cos(cos[e][l]);
                for k in 0..3 {
                    fc[n + k] = c;
                    (fn_[n + k], fk[n + k]) = (q.eta[k][l], q.k[k][l]);
                }
                n += 3;
            }
        }
    }
    let mut fr = [[0.0f32; STEP]; 6];
    for i in 0..n.div_ceil(STEP) {
        for j in 0..STEP {
            fr[i][j] = fresnel::conductor_channel(fc[i][j], fnk[0][i][j], fnk[1][i][j]);
        }
    }
    let fr = fr.as_flattened();
    let mut f = [[[0.0f32; N]; 3]; 2];
    for l in 0..used.min(N) {
        for e in 0..2 {
            if !fresnel[e][l] {
                continue;
            }
            for (k, row) in f[e].iter_mut().enumerate() {
                row[l] = fr[at[e][l] + k] * q.specular_reflectance[k][l] * scale[e][l];
            }
        }
    }
    let [nee_f, sf] = f;
    let sampled = std::array::from_fn(|l| wi[1][2][l] > 0.0 && super::positive_finite(pdf[1][l]));
    LaneSamples { nee_f, nee_pdf: pdf[0], sampled, glossy: [true; N], eta: [1.0; N], wi: wi[1], f: sf, pdf: pdf[1] }
}
