//! Mitsuba's `plastic` and `roughplastic`: a diffuse base under a dielectric coating.
//!
//! Light enters the coating with probability 1 - F (or the rough interface's transmittance
//! t), scatters diffusely in the base, and bounces between base and coating; the internal
//! reflectance of the coating (Fdr_int) gives the geometric series 1 / (1 - Fdr_int), or,
//! with `nonlinear`, 1 / (1 - R Fdr_int), which tints multiply-bounced light. The 1/eta²
//! accounts for the solid-angle compression through the interface. Same formulas as
//! Mitsuba 3, so that images agree. Front side only.

use super::fresnel;
use super::lane_samples::LaneSamples;
use super::material::MicrofacetKind;
use super::microfacet::{self as mf, Microfacet, VisibleNormalLanes, VisibleSampler};
use super::{BsdfSample, LobeFlags, TransportMode};
use crate::math::{lane, warp, INV_PI};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

/// Probability of sampling the coating's specular lobe: the specular and diffuse shares
/// (`specular`, `diffuse`: the light each lobe gets), weighted by the sampling weight.
fn specular_probability(specular: f32, diffuse: f32, weight: f32) -> f32 {
    let ps = specular * weight;
    let pd = diffuse * (1.0 - weight);
    if ps + pd > 0.0 {
        ps / (ps + pd)
    } else {
        0.0
    }
}

/// Probability of sampling the specular lobe, before the Fresnel term: Mitsuba's
/// s_mean / (d_mean + s_mean) from the mean reflectances.
pub fn specular_sampling_weight(diffuse_mean: f32, specular_mean: f32) -> f32 {
    let s = specular_mean.max(0.0);
    let d = diffuse_mean.max(0.0);
    if s + d > 0.0 {
        s / (s + d)
    } else {
        0.5
    }
}

/// Diffuse reflectance corrected for the internal bounces under the coating.
#[inline]
fn base_albedo(diffuse: Rgb, internal: f32, nonlinear: bool) -> Rgb {
    let denom = if nonlinear { Rgb::WHITE - diffuse * internal } else { Rgb::splat(1.0 - internal) };
    Rgb::new(diffuse.r / denom.r, diffuse.g / denom.g, diffuse.b / denom.b)
}

/// Smooth coating: a delta specular lobe plus the diffuse base.
#[derive(Clone, Copy, Debug)]
pub struct SmoothPlastic {
    pub diffuse_reflectance: Rgb,
    pub specular_reflectance: Rgb,
    pub eta: f32,
    pub nonlinear: bool,
    pub specular_sampling_weight: f32,
}

impl SmoothPlastic {
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::SPECULAR_REFLECTION | LobeFlags::DIFFUSE_REFLECTION
    }
    pub(crate) fn prob_specular(&self, f_o: f32) -> f32 {
        specular_probability(f_o, 1.0 - f_o, self.specular_sampling_weight)
    }
    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        let f_o = fresnel::dielectric(wo.z, self.eta).0;
        let f_i = fresnel::dielectric(wi.z, self.eta).0;
        let fdr_int = fresnel::diffuse_reflectance(1.0 / self.eta);
        base_albedo(self.diffuse_reflectance, fdr_int, self.nonlinear) * ((1.0 - f_o) * (1.0 - f_i) * INV_PI / (self.eta * self.eta))
    }
    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let f_o = fresnel::dielectric(wo.z, self.eta).0;
        (1.0 - self.prob_specular(f_o)) * warp::square_to_cosine_hemisphere_pdf(wi)
    }
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let f_o = fresnel::dielectric(wo.z, self.eta).0;
        let ps = self.prob_specular(f_o);
        if uc < ps {
            let wi = fresnel::reflect_z(wo);
            let weight = self.specular_reflectance * (f_o / ps);
            return Some(BsdfSample { wi, f: weight / wi.z, pdf: 1.0, lobe: LobeFlags::SPECULAR_REFLECTION, eta: 1.0 });
        }
        let wi = warp::square_to_cosine_hemisphere(u);
        let pdf = self.pdf(wo, wi, mode);
        if !super::positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample { wi, f: self.eval(wo, wi, mode), pdf, lobe: LobeFlags::DIFFUSE_REFLECTION, eta: 1.0 })
    }
    /// Hemispherical average of the diffuse lobe's albedo (for radiosity).
    pub fn diffuse_albedo(&self) -> Rgb {
        let t = 1.0 - fresnel::diffuse_reflectance(self.eta);
        base_albedo(self.diffuse_reflectance, fresnel::diffuse_reflectance(1.0 / self.eta), self.nonlinear) * (t * t / (self.eta * self.eta))
    }
}

/// Resolution of the transmittance table over cos θ (Mitsuba's MI_ROUGH_TRANSMITTANCE_RES).
pub const TRANSMITTANCE_RES: usize = 64;

/// Precomputed integrals of a rough interface of given roughness and IOR.
#[derive(Debug)]
pub struct CoatingTables {
    /// Directional transmittance into the coating, t(cos θ) at cos θ = i / (RES - 1).
    pub transmittance: [f32; TRANSMITTANCE_RES],
    /// Hemispherical (cosine-weighted) internal reflectance of the coating seen from inside.
    pub internal_reflectance: f32,
    /// Hemispherical (cosine-weighted) average of `transmittance`.
    pub mean_transmittance: f32,
}

impl CoatingTables {
    /// Linear interpolation in the table, as Mitsuba's `lerp_gather`.
    #[inline]
    pub fn transmittance_at(&self, cos: f32) -> f32 {
        let x = cos.clamp(0.0, 1.0) * (TRANSMITTANCE_RES - 1) as f32;
        let i = (x as usize).min(TRANSMITTANCE_RES - 2);
        let w = x - i as f32;
        self.transmittance[i] * (1.0 - w) + self.transmittance[i + 1] * w
    }

    /// Integrate the interface's albedos by Gauss-Legendre quadrature over the visible-
    /// normal sample space (the integrands are then smooth apart from total internal
    /// reflection), as Mitsuba does.
    pub fn compute(kind: MicrofacetKind, alpha: f32, eta: f32) -> CoatingTables {
        let md = Microfacet::new(kind, alpha, alpha);
        let mus: Vec<f32> = (0..TRANSMITTANCE_RES).map(|i| (i as f32 / (TRANSMITTANCE_RES - 1) as f32).max(1e-6)).collect();
        let dir = |mu: f32| Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
        let gl_out = gauss_legendre(32);
        let gl_in = gauss_legendre(128);
        let ext: Vec<f64> = mus.par_iter().map(|&mu| interface_albedo(&md, dir(mu), eta, false, &gl_out)).collect();
        let mut transmittance = [0.0f32; TRANSMITTANCE_RES];
        for (t, e) in transmittance.iter_mut().zip(&ext) {
            *t = *e as f32;
        }
        // Mitsuba averages over the linspace points (not a trapezoid rule); kept so that
        // the diffuse brightness matches its images.
        let n = TRANSMITTANCE_RES as f64;
        let internal = 2.0 * mus.par_iter().map(|&mu| interface_albedo(&md, dir(mu), 1.0 / eta, true, &gl_in) * mu as f64).sum::<f64>() / n;
        let mean_t = 2.0 * mus.iter().zip(&transmittance).map(|(&mu, &t)| t as f64 * mu as f64).sum::<f64>() / n;
        CoatingTables { transmittance, internal_reflectance: internal as f32, mean_transmittance: mean_t as f32 }
    }

    /// The tables for this coating, computed once per process and roughness (quantised to
    /// ~1e-4 relative, which bounds the cache for textured roughness).
    pub fn get(kind: MicrofacetKind, alpha: f32, eta: f32) -> &'static CoatingTables {
        thread_local! {
            static LOCAL: RefCell<HashMap<TableKey, &'static CoatingTables>> = RefCell::new(HashMap::new());
        }
        let (key, alpha) = table_key(kind, alpha, eta);
        if let Some(t) = LOCAL.with(|l| l.borrow().get(&key).copied()) {
            return t;
        }
        let t = {
            let mut g = global_tables().lock().unwrap_or_else(|e| e.into_inner());
            // Leaked on purpose: a handful of small tables live as long as the process.
            *g.entry(key).or_insert_with(|| Box::leak(Box::new(CoatingTables::compute(kind, alpha, eta))))
        };
        LOCAL.with(|l| l.borrow_mut().insert(key, t));
        t
    }
}

type TableKey = (u8, u32, u32);

/// The key of a coating's tables and the roughness they are computed for.
fn table_key(kind: MicrofacetKind, alpha: f32, eta: f32) -> (TableKey, f32) {
    let alpha = f32::from_bits(alpha.max(super::microfacet::MIN_ALPHA).to_bits() & !0x3ff);
    ((kind as u8, alpha.to_bits(), eta.to_bits()), alpha)
}

/// Every thread's tables, built once per process.
fn global_tables() -> &'static Mutex<HashMap<TableKey, &'static CoatingTables>> {
    static GLOBAL: OnceLock<Mutex<HashMap<TableKey, &'static CoatingTables>>> = OnceLock::new();
    GLOBAL.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The tables of this coating if some thread built them already.
#[cfg(test)]
pub(crate) fn cached_tables(kind: MicrofacetKind, alpha: f32, eta: f32) -> Option<&'static CoatingTables> {
    global_tables().lock().unwrap_or_else(|e| e.into_inner()).get(&table_key(kind, alpha, eta).0).copied()
}

/// ∫ over visible normals of (1 - F) G1(wt) (transmission) or F G1(wr) (reflection) for
/// incident direction `v`: the directional albedo of that lobe of a rough interface.
/// The sampler's one-dimensional parts are evaluated once per grid line (the same values
/// `sample_visible` would give at each node).
///
/// For an isotropic Beckmann surface and `v` in the xz plane, the y slope is odd in
/// `u.y - 1/2` and the integrand even in it (it mirrors across the plane of incidence), so
/// the nodes' mirrored halves are summed as one, doubled: half the evaluations, the same
/// integral up to the nodes' rounding.
fn interface_albedo(md: &Microfacet, v: Vec3, eta: f32, reflection: bool, gl: &[(f64, f64)]) -> f64 {
    let mirrored = md.kind == MicrofacetKind::Beckmann && md.alpha_u == md.alpha_v && v.y == 0.0 && gl.len().is_multiple_of(2);
    interface_albedo_grid(md, v, eta, reflection, gl, mirrored)
}

fn interface_albedo_grid(md: &Microfacet, v: Vec3, eta: f32, reflection: bool, gl: &[(f64, f64)], mirrored: bool) -> f64 {
    let sampler = VisibleSampler::new(md, v);
    let node = |x: f64| (0.5 * x + 0.5) as f32;
    let ys: Vec<((f32, f32), f64)> = if mirrored {
        gl[..gl.len() / 2].iter().map(|&(y, wy)| (sampler.part_y(node(y)), 2.0 * wy)).collect()
    } else {
        gl.iter().map(|&(y, wy)| (sampler.part_y(node(y)), wy)).collect()
    };
    let mut acc = 0.0f64;
    for &(x, wx) in gl {
        let px = sampler.part_x(node(x));
        for &(py, wy) in &ys {
            let m = sampler.combine(px, py);
            acc += interface_term(md, v, m, eta, reflection) as f64 * wx * wy;
        }
    }
    acc * 0.25
}

/// The integrand of [`interface_albedo`] at microfacet normal `m`.
#[inline]
fn interface_term(md: &Microfacet, v: Vec3, m: Vec3, eta: f32, reflection: bool) -> f32 {
    let (f, cos_t, _, eta_ti) = fresnel::dielectric(v.dot(m), eta);
    if reflection {
        let w = fresnel::reflect(v, m);
        if w.z > 0.0 {
            f * md.g1(w, m)
        } else {
            0.0
        }
    } else {
        let w = fresnel::refract(v, m, cos_t, eta_ti);
        if w.z < 0.0 {
            (1.0 - f) * md.g1(w, m)
        } else {
            0.0
        }
    }
}

/// Gauss-Legendre nodes and weights on [-1, 1] (Newton's method on P_n).
pub(crate) fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // Recurrence for P_n(x) and its derivative.
            let (mut p0, mut p1) = (1.0f64, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            // p1 = P_n(x), p0 = P_{n-1}(x).
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        out.push((x, 2.0 / ((1.0 - x * x) * dp * dp)));
    }
    out
}

/// Rough coating over the diffuse base (isotropic roughness, as Mitsuba's `roughplastic`).
#[derive(Clone, Copy, Debug)]
pub struct RoughPlastic {
    pub distribution: Microfacet,
    pub diffuse_reflectance: Rgb,
    pub specular_reflectance: Rgb,
    pub eta: f32,
    pub nonlinear: bool,
    pub specular_sampling_weight: f32,
    pub tables: &'static CoatingTables,
    /// The base's albedo under the coating (`base_albedo`) and INV_PI / eta², of the fields
    /// above, made by `new`: each vertex (and the path kernel's lanes) read them, not three
    /// divisions and one more.
    base: Rgb,
    base_scale: f32,
}

impl RoughPlastic {
    pub fn new(
        kind: MicrofacetKind,
        alpha: f32,
        diffuse_reflectance: Rgb,
        specular_reflectance: Rgb,
        eta: f32,
        nonlinear: bool,
        specular_sampling_weight: f32,
    ) -> Self {
        let distribution = Microfacet::new(kind, alpha, alpha);
        let tables = CoatingTables::get(kind, distribution.alpha_u, eta);
        let base = base_albedo(diffuse_reflectance, tables.internal_reflectance, nonlinear);
        let base_scale = INV_PI / (eta * eta);
        RoughPlastic { distribution, diffuse_reflectance, specular_reflectance, eta, nonlinear, specular_sampling_weight, tables, base, base_scale }
    }
    /// Build the coating tables that [`Self::new`] will look up for this roughness and IOR
    /// (once per process): at scene load, as Mitsuba builds them when it loads the plugin,
    /// rather than at the first hit, inside the render.
    pub fn prepare_tables(kind: MicrofacetKind, alpha: f32, eta: f32) {
        CoatingTables::get(kind, Microfacet::new(kind, alpha, alpha).alpha_u, eta);
    }
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::GLOSSY_REFLECTION | LobeFlags::DIFFUSE_REFLECTION
    }
    fn prob_specular(&self, t_o: f32) -> f32 {
        specular_probability(1.0 - t_o, t_o, self.specular_sampling_weight)
    }
    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        let h = (wo + wi).normalize();
        let md = &self.distribution;
        let f = fresnel::dielectric(wo.dot(h), self.eta).0;
        let spec = self.specular_reflectance * (f * md.d(h) * md.g(wo, wi, h) / (4.0 * wo.z * wi.z));
        let t = self.tables;
        let diff = self.base * (self.base_scale * t.transmittance_at(wo.z) * t.transmittance_at(wi.z));
        spec + diff
    }
    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let ps = self.prob_specular(self.tables.transmittance_at(wo.z));
        let h = (wo + wi).normalize();
        let hi = wi.dot(h);
        let spec = if hi > 0.0 { self.distribution.pdf_visible(wo, h) / (4.0 * hi) } else { 0.0 };
        ps * spec + (1.0 - ps) * warp::square_to_cosine_hemisphere_pdf(wi)
    }
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let ps = self.prob_specular(self.tables.transmittance_at(wo.z));
        let (wi, lobe) = if uc < ps {
            let m = self.distribution.sample_visible(wo, u);
            (fresnel::reflect(wo, m), LobeFlags::GLOSSY_REFLECTION)
        } else {
            (warp::square_to_cosine_hemisphere(u), LobeFlags::DIFFUSE_REFLECTION)
        };
        if wi.z <= 0.0 {
            return None;
        }
        let (f, pdf) = self.eval_pdf(wo, wi);
        if !super::positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample { wi, f, pdf, lobe, eta: 1.0 })
    }
    /// ([`Self::eval`], [`Self::pdf`]) with the half vector, D, G1(wo) and the coating's
    /// transmittance toward `wo` computed once: the same values as the two calls.
    pub(crate) fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        let h = (wo + wi).normalize();
        let md = &self.distribution;
        let (d, g1o) = (md.d(h), md.g1(wo, h));
        let t = self.tables;
        let t_o = t.transmittance_at(wo.z);
        let ps = self.prob_specular(t_o);
        let hi = wi.dot(h);
        let spec_pdf = if hi > 0.0 { Microfacet::pdf_visible_given(wo, h, d, g1o) / (4.0 * hi) } else { 0.0 };
        let pdf = ps * spec_pdf + (1.0 - ps) * warp::square_to_cosine_hemisphere_pdf(wi);
        let f = fresnel::dielectric(wo.dot(h), self.eta).0;
        let spec = self.specular_reflectance * (f * d * (g1o * md.g1(wi, h)) / (4.0 * wo.z * wi.z));
        let diff = self.base * (self.base_scale * t_o * t.transmittance_at(wi.z));
        (spec + diff, pdf)
    }
    /// Hemispherical average of the diffuse lobe's albedo (for radiosity).
    pub fn diffuse_albedo(&self) -> Rgb {
        let t = self.tables;
        base_albedo(self.diffuse_reflectance, t.internal_reflectance, self.nonlinear) * (t.mean_transmittance * t.mean_transmittance / (self.eta * self.eta))
    }
}

/// No coating: the transmittance table of a group's unused lanes.
static NO_TABLE: [f32; TRANSMITTANCE_RES] = [0.0; TRANSMITTANCE_RES];

/// [`CoatingTables::transmittance_at`] of each lane's table `t` at `cos`, as vector lanes
/// run it: the index and weight, then the two entries lane by lane (loads only: AVX2 has no
/// gather LLVM takes for them, and the arithmetic around them stayed scalar), then the
/// blend. The index's float-to-integer conversion goes through `i32` (the clamped `x` is in
/// [0, 63] or NaN, which both conversions take to 0): the same index, weight and sum.
#[inline(always)]
fn transmittance_lanes<const N: usize>(t: &[&[f32; TRANSMITTANCE_RES]; N], cos: &[f32; N]) -> [f32; N] {
    let (mut x, mut i) = ([0.0f32; N], [0usize; N]);
    for l in 0..N {
        x[l] = cos[l].clamp(0.0, 1.0) * (TRANSMITTANCE_RES - 1) as f32;
        i[l] = (x[l] as i32).clamp(0, TRANSMITTANCE_RES as i32 - 2) as usize;
    }
    let (mut a, mut b) = ([0.0f32; N], [0.0f32; N]);
    for l in 0..N {
        (a[l], b[l]) = (t[l][i[l]], t[l][i[l] + 1]);
    }
    std::array::from_fn(|l| {
        let w = x[l] - i[l] as f32;
        a[l] * (1.0 - w) + b[l] * w
    })
}

/// [`specular_probability`] with its test as a select.
#[inline(always)]
fn specular_probability_lane(specular: f32, diffuse: f32, weight: f32) -> f32 {
    let ps = specular * weight;
    let pd = diffuse * (1.0 - weight);
    let p = ps / (ps + pd);
    if ps + pd > 0.0 {
        p
    } else {
        0.0
    }
}

/// `N` lanes of Beckmann (or GGX) rough plastics for [`rough_plastic_lanes`] (or
/// [`rough_plastic_ggx_lanes`]), on the model's side (as
/// `Bsdf::side` mirrors them). Unused lanes keep the defaults (or earlier lanes' values).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RoughPlasticLanes<const N: usize> {
    /// The roughness, `wo` (upper hemisphere) and the direction's numbers `u`.
    pub normals: VisibleNormalLanes<N>,
    /// The lobe's number.
    pub uc: [f32; N],
    /// Toward the light sample (local; below the surface where there is none).
    pub wi: [[f32; N]; 3],
    pub eta: [f32; N],
    pub sampling_weight: [f32; N],
    pub specular_reflectance: [[f32; N]; 3],
    /// The base's albedo under the coating (`base_albedo`) and INV_PI / eta².
    pub base: [[f32; N]; 3],
    pub base_scale: [f32; N],
    pub transmittance: [&'static [f32; TRANSMITTANCE_RES]; N],
}

impl<const N: usize> Default for RoughPlasticLanes<N> {
    fn default() -> Self {
        RoughPlasticLanes {
            normals: VisibleNormalLanes::default(),
            uc: [0.5; N],
            wi: [[0.0; N], [0.0; N], [-1.0; N]],
            eta: [1.5; N],
            sampling_weight: [0.5; N],
            specular_reflectance: [[1.0; N]; 3],
            base: [[0.0; N]; 3],
            base_scale: [0.0; N],
            transmittance: [&NO_TABLE; N],
        }
    }
}

impl<const N: usize> RoughPlasticLanes<N> {
    /// Lane `l`: plastic `p` seen from `wo` (on its side, upper hemisphere), the light sample
    /// toward `wi` where there is one, the lobe's number `uc` and the direction's `u`.
    #[inline]
    pub(crate) fn set(&mut self, l: usize, p: &RoughPlastic, wo: Vec3, wi: Option<Vec3>, uc: f32, u: Vec2) {
        let md = &p.distribution;
        let wi = wi.unwrap_or(Vec3::NEG_Z);
        let q = &mut self.normals;
        (q.alpha[0][l], q.alpha[1][l]) = (md.alpha_u, md.alpha_v);
        (q.u[0][l], q.u[1][l]) = (u.x, u.y);
        for k in 0..3 {
            q.v[k][l] = wo[k];
            self.wi[k][l] = wi[k];
            (self.specular_reflectance[k][l], self.base[k][l]) = (p.specular_reflectance[k], p.base[k]);
        }
        (self.uc[l], self.eta[l], self.sampling_weight[l]) = (uc, p.eta, p.specular_sampling_weight);
        self.base_scale[l] = p.base_scale;
        self.transmittance[l] = &p.tables.transmittance;
    }
}

/// ([`RoughPlastic::eval_pdf`] toward `wi`, [`RoughPlastic::sample`]) of `used` lanes at
/// once: the lobe's choice, the glossy lanes' visible normals
/// (`sample_visible_beckmann_lanes`) or the cosine-weighted directions, then for both
/// directions the half vector, D, G1 both ways, the densities, the coating's Fresnel term
/// and transmittances, each lane's operations those of the scalar routines, with selects for
/// their branches (D's expf as `conductor::rough_conductor_lanes` takes it). The same bits.
#[inline(always)]
pub(crate) fn rough_plastic_lanes<const N: usize>(q: &RoughPlasticLanes<N>, used: usize) -> LaneSamples<N> {
    plastic_lanes::<N, false>(q, used)
}

/// [`rough_plastic_lanes`] of GGX rough plastics (`q.normals` holds their roughness, `wo`
/// and `u` likewise): the visible normals in closed form (`sample_visible_ggx_lanes`), D
/// and Λ GGX's. The same bits as the scalar routines.
#[inline(always)]
pub(crate) fn rough_plastic_ggx_lanes<const N: usize>(q: &RoughPlasticLanes<N>, used: usize) -> LaneSamples<N> {
    plastic_lanes::<N, true>(q, used)
}

/// The body of [`rough_plastic_lanes`] (Beckmann) and [`rough_plastic_ggx_lanes`] (`GGX`).
#[inline(always)]
fn plastic_lanes<const N: usize, const GGX: bool>(q: &RoughPlasticLanes<N>, used: usize) -> LaneSamples<N> {
    let b = &q.normals;
    // `sample`'s start: the transmittance toward wo and the lobe. Lanes that take the
    // diffuse lobe draw no normal: they ask the Newton loop for an idle lane's, which
    // settles at once.
    let t_o = transmittance_lanes(&q.transmittance, &b.v[2]);
    let (mut ps, mut glossy, mut want) = ([0.0f32; N], [false; N], [false; N]);
    let (idle, mut draw) = (VisibleNormalLanes::<N>::default(), *b);
    for l in 0..N {
        ps[l] = specular_probability_lane(1.0 - t_o[l], t_o[l], q.sampling_weight[l]);
        glossy[l] = q.uc[l] < ps[l];
        let g = glossy[l] & (l < used);
        want[l] = g;
        if GGX {
            continue;
        }
        for k in 0..2 {
            draw.alpha[k][l] = if g { b.alpha[k][l] } else { idle.alpha[k][l] };
            draw.u[k][l] = if g { b.u[k][l] } else { idle.u[k][l] };
        }
        for k in 0..3 {
            draw.v[k][l] = if g { b.v[k][l] } else { idle.v[k][l] };
        }
    }
    let any_glossy = glossy[..used.min(N)].iter().fold(false, |a, &g| a | g);
    let m = if !any_glossy {
        [[0.0; N], [0.0; N], [1.0; N]]
    } else if GGX {
        mf::sample_visible_ggx_lanes(b, &want)
    } else {
        mf::sample_visible_beckmann_lanes(&draw)
    };
    // Per direction (0: toward the light sample, 1: the sample's), as `eval_pdf`.
    let (mut wi, mut h) = ([[[0.0f32; N]; 3]; 2], [[[0.0f32; N]; 3]; 2]);
    let (mut x, mut c2, mut ok) = ([[0.0f32; N]; 2], [[0.0f32; N]; 2], [[false; N]; 2]);
    let mut lambda = [[0.0f32; N]; 3];
    for l in 0..N {
        let (ax, ay) = (b.alpha[0][l], b.alpha[1][l]);
        let wo = Vec3::new(b.v[0][l], b.v[1][l], b.v[2][l]);
        let r = fresnel::reflect(wo, Vec3::new(m[0][l], m[1][l], m[2][l]));
        let c = lane::cosine_hemisphere(b.u[0][l], b.u[1][l]);
        let ws = if glossy[l] { r } else { Vec3::from_array(c) };
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
    // D's e^x where D is asked for, as `rough_conductor_lanes` (Beckmann's).
    let ex = if GGX { x } else { mf::beckmann_d_exp_lanes(&x, &ok, used) };
    let t_i = [transmittance_lanes(&q.transmittance, &wi[0][2]), transmittance_lanes(&q.transmittance, &wi[1][2])];
    let (mut f, mut pdf) = ([[[0.0f32; N]; 3]; 2], [[0.0f32; N]; 2]);
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
            let hi = w.dot(hh);
            let spec_pdf = if hi > 0.0 { Microfacet::pdf_visible_given(wo, hh, d, g1o) / (4.0 * hi) } else { 0.0 };
            let p = ps[l] * spec_pdf + (1.0 - ps[l]) * warp::square_to_cosine_hemisphere_pdf(w);
            let fr = fresnel::dielectric_reflectance(wo.dot(hh), q.eta[l]);
            let spec = fr * d * (g1o * Microfacet::g1_given(w, hh, || lambda[1 + e][l])) / (4.0 * wo.z * w.z);
            let diff = q.base_scale[l] * t_o[l] * t_i[e][l];
            let valid = !(wo.z <= 0.0 || w.z <= 0.0);
            for (k, row) in f[e].iter_mut().enumerate() {
                let v = q.specular_reflectance[k][l] * spec + q.base[k][l] * diff;
                row[l] = if valid { v } else { 0.0 };
            }
            pdf[e][l] = if valid { p } else { 0.0 };
        }
    }
    let [nee_f, sf] = f;
    let sampled = std::array::from_fn(|l| wi[1][2][l] > 0.0 && super::positive_finite(pdf[1][l]));
    LaneSamples { nee_f, nee_pdf: pdf[0], sampled, glossy, eta: [1.0; N], wi: wi[1], f: sf, pdf: pdf[1] }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let gl = gauss_legendre(8);
        let w: f64 = gl.iter().map(|p| p.1).sum();
        assert!((w - 2.0).abs() < 1e-12);
        // Exact up to degree 15.
        let i: f64 = gl.iter().map(|&(x, w)| w * x.powi(14)).sum();
        assert!((i - 2.0 / 15.0).abs() < 1e-12);
    }

    #[test]
    fn mirrored_beckmann_grid_is_the_full_one() {
        // The halved grid must give the full grid's integral: it fails if the y slope is
        // not odd about the middle node or the integrand not mirror-symmetric.
        for &(alpha, eta) in &[(0.05f32, 1.5f32), (0.3, 1.5), (0.7, 1.33), (0.3, 1.0 / 1.5)] {
            let md = Microfacet::new(MicrofacetKind::Beckmann, alpha, alpha);
            for (gl, reflection) in [(gauss_legendre(32), false), (gauss_legendre(128), true)] {
                for mu in [1e-3f32, 0.2, 0.6, 0.97] {
                    let v = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                    let (half, full) = (interface_albedo_grid(&md, v, eta, reflection, &gl, true), interface_albedo_grid(&md, v, eta, reflection, &gl, false));
                    assert!((half - full).abs() <= 2e-6 * full.abs().max(1e-3), "alpha {alpha} eta {eta} mu {mu}: {half} vs {full}");
                }
            }
            // GGX's disk warp is not mirror-symmetric in u.y: it keeps the full grid.
            let ggx = Microfacet::new(MicrofacetKind::Ggx, alpha, alpha);
            let v = Vec3::new(0.8, 0.0, 0.6);
            let gl = gauss_legendre(32);
            assert_eq!(interface_albedo(&ggx, v, eta, false, &gl).to_bits(), interface_albedo_grid(&ggx, v, eta, false, &gl, false).to_bits());
        }
    }

    #[test]
    fn coating_tables_approach_smooth_interface() {
        // A nearly smooth coating transmits 1 - F(cos) and its internal reflectance is
        // the diffuse Fresnel reflectance (up to Mitsuba's linspace averaging).
        let t = CoatingTables::compute(MicrofacetKind::Ggx, 1e-3, 1.5);
        for i in [8usize, 20, 40, 63] {
            let mu = i as f32 / 63.0;
            let expect = 1.0 - fresnel::dielectric(mu, 1.5).0;
            assert!((t.transmittance[i] - expect).abs() < 2e-3, "mu {mu}: {} vs {expect}", t.transmittance[i]);
        }
        let fdr = fresnel::diffuse_reflectance(1.0 / 1.5);
        assert!((t.internal_reflectance - fdr).abs() < 0.03, "{} vs {fdr}", t.internal_reflectance);
    }

    #[test]
    fn interface_albedo_grid_equals_sample_visible_at_every_node() {
        // The grid evaluates the sampler's parts once per line; the sum must be the one
        // that sampling each node afresh gives, bit for bit (the tables, hence images, are
        // unchanged by that saving).
        let gl = gauss_legendre(16);
        for kind in [MicrofacetKind::Ggx, MicrofacetKind::Beckmann] {
            let md = Microfacet::new(kind, 0.23, 0.23);
            for &(mu, eta, reflection) in &[(1e-6f32, 1.5f32, false), (0.3, 1.5, false), (0.8, 1.0 / 1.5, true), (1.0, 1.0 / 1.33, true)] {
                let v = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
                let mut direct = 0.0f64;
                for &(x, wx) in &gl {
                    for &(y, wy) in &gl {
                        let m = md.sample_visible(v, Vec2::new((0.5 * x + 0.5) as f32, (0.5 * y + 0.5) as f32));
                        direct += interface_term(&md, v, m, eta, reflection) as f64 * wx * wy;
                    }
                }
                let grid = interface_albedo_grid(&md, v, eta, reflection, &gl, false);
                assert_eq!(grid.to_bits(), (direct * 0.25).to_bits(), "{kind:?} mu {mu} eta {eta}");
                assert!(grid > 0.0 && grid <= 1.0 + 1e-6, "{kind:?} mu {mu}: albedo {grid}");
            }
        }
    }
}
