//! Dielectric interfaces (Mitsuba `dielectric`, `roughdielectric`, `thindielectric`).
//! `eta` = interior IOR / exterior IOR, the interior being on the -z side. Both sides
//! scatter. In radiance mode, refraction scales by 1/eta² of the crossing (the radiance
//! compression of Veach's thesis §5.2); importance is not scaled.

use super::fresnel::{self, reflect, refract};
use super::lane_samples::LaneSamples;
use super::microfacet::{self as mf, Microfacet, VisibleNormalLanes};
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

/// `N` lanes of Beckmann rough dielectrics for [`rough_dielectric_lanes`]. Unused lanes keep
/// the defaults (or earlier lanes' values).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RoughDielectricLanes<const N: usize> {
    /// The roughness, `wo` mirrored to the upper hemisphere and the direction's numbers `u`.
    pub normals: VisibleNormalLanes<N>,
    /// `wo` itself (either side, not grazing).
    pub wo: [[f32; N]; 3],
    /// The lobe's number.
    pub uc: [f32; N],
    /// Toward the light sample (local; zero where there is none).
    pub wi: [[f32; N]; 3],
    pub eta: [f32; N],
    pub specular_reflectance: [[f32; N]; 3],
    pub specular_transmittance: [[f32; N]; 3],
}

impl<const N: usize> Default for RoughDielectricLanes<N> {
    fn default() -> Self {
        RoughDielectricLanes {
            normals: VisibleNormalLanes::default(),
            wo: [[0.0; N], [0.0; N], [1.0; N]],
            uc: [0.5; N],
            wi: [[0.0; N]; 3],
            eta: [1.5; N],
            specular_reflectance: [[1.0; N]; 3],
            specular_transmittance: [[1.0; N]; 3],
        }
    }
}

impl<const N: usize> RoughDielectricLanes<N> {
    /// Lane `l`: dielectric `d` seen from `wo` (wo.z not 0), the light sample toward `wi`
    /// where there is one, the lobe's number `uc` and the direction's `u`.
    #[inline]
    pub(crate) fn set(&mut self, l: usize, d: &RoughDielectric, wo: Vec3, wi: Option<Vec3>, uc: f32, u: Vec2) {
        let md = &d.distribution;
        let wi = wi.unwrap_or(Vec3::ZERO);
        let v = wo * wo.z.signum();
        let q = &mut self.normals;
        (q.alpha[0][l], q.alpha[1][l]) = (md.alpha_u, md.alpha_v);
        (q.u[0][l], q.u[1][l]) = (u.x, u.y);
        for k in 0..3 {
            (q.v[k][l], self.wo[k][l], self.wi[k][l]) = (v[k], wo[k], wi[k]);
            (self.specular_reflectance[k][l], self.specular_transmittance[k][l]) = (d.specular_reflectance[k], d.specular_transmittance[k]);
        }
        (self.uc[l], self.eta[l]) = (uc, d.eta);
    }
}

/// ([`RoughDielectric::eval_pdf`] toward `wi`, [`RoughDielectric::sample`]) in radiance mode
/// of `used` lanes at once: the visible normals (`sample_visible_beckmann_lanes`), the lobe by
/// their Fresnel term and the reflected or refracted direction, then for both directions the
/// generalised half vector, D, G1 both ways, the density and the value, each lane's
/// operations those of the scalar routines, with selects for their branches (D's expf as
/// `conductor::rough_conductor_lanes` takes it). The same bits.
#[inline(always)]
pub(crate) fn rough_dielectric_lanes<const N: usize>(q: &RoughDielectricLanes<N>, used: usize) -> LaneSamples<N> {
    let b = &q.normals;
    let m = mf::sample_visible_beckmann_lanes(b);
    // `sample`: the lobe and the direction.
    let (mut reflected, mut eta_s, mut ws) = ([false; N], [0.0f32; N], [[0.0f32; N]; 3]);
    for l in 0..N {
        let wo = Vec3::new(q.wo[0][l], q.wo[1][l], q.wo[2][l]);
        let mm = Vec3::new(m[0][l], m[1][l], m[2][l]);
        let (f, cos_t, eta_it, eta_ti) = fresnel::dielectric_lane(wo.dot(mm), q.eta[l]);
        let r = q.uc[l] < f;
        let (wr, wt) = (reflect(wo, mm), refract(wo, mm, cos_t, eta_ti));
        let w = Vec3::new(if r { wr.x } else { wt.x }, if r { wr.y } else { wt.y }, if r { wr.z } else { wt.z });
        // `normalize_or_zero`.
        let rcp = w.length_recip();
        let wn = w * rcp;
        let keep = rcp.is_finite() & (rcp > 0.0);
        for k in 0..3 {
            ws[k][l] = if keep { wn[k] } else { 0.0 };
        }
        reflected[l] = r;
        eta_s[l] = if r { 1.0 } else { eta_it };
    }
    // Per direction (0: toward the light sample, 1: the sample's), as `eval_pdf`.
    let mut h = [[[0.0f32; N]; 3]; 2];
    let (mut x, mut c2, mut ok, mut valid) = ([[0.0f32; N]; 2], [[0.0f32; N]; 2], [[false; N]; 2], [[false; N]; 2]);
    let mut lambda = [[0.0f32; N]; 3];
    for l in 0..N {
        let (ax, ay) = (b.alpha[0][l], b.alpha[1][l]);
        let wo = Vec3::new(q.wo[0][l], q.wo[1][l], q.wo[2][l]);
        lambda[0][l] = mf::beckmann_lambda(ax, ay, wo);
        for (e, w) in [Vec3::new(q.wi[0][l], q.wi[1][l], q.wi[2][l]), Vec3::new(ws[0][l], ws[1][l], ws[2][l])].into_iter().enumerate() {
            // `half_vector`.
            let refl = wo.z * w.z > 0.0;
            let eta = if wo.z > 0.0 { q.eta[l] } else { 1.0 / q.eta[l] };
            let hm = wo + w * if refl { 1.0 } else { eta };
            let len = hm.length();
            let hh = hm / len * hm.z.signum();
            let seen = !(wo.dot(hh) * wo.z <= 0.0 || w.dot(hh) * w.z <= 0.0);
            valid[e][l] = (wo.z != 0.0) & (w.z != 0.0) & super::positive_finite(len) & seen;
            (x[e][l], c2[e][l]) = mf::beckmann_d_exponent(ax, ay, hh);
            lambda[1 + e][l] = mf::beckmann_lambda(ax, ay, w);
            ok[e][l] = valid[e][l] & (hh.z > 0.0);
            for k in 0..3 {
                h[e][k][l] = hh[k];
            }
        }
    }
    let ex = mf::beckmann_d_exp_lanes(&x, &ok, used);
    // Direction by direction, lanes inner: with the directions inner, LLVM kept the loop
    // scalar.
    let (mut f, mut pdf) = ([[[0.0f32; N]; 3]; 2], [[0.0f32; N]; 2]);
    for (e, dir) in [&q.wi, &ws].into_iter().enumerate() {
        for l in 0..N {
            let (ax, ay) = (b.alpha[0][l], b.alpha[1][l]);
            let wo = Vec3::new(q.wo[0][l], q.wo[1][l], q.wo[2][l]);
            let v = Vec3::new(b.v[0][l], b.v[1][l], b.v[2][l]);
            let w = Vec3::new(dir[0][l], dir[1][l], dir[2][l]);
            let hh = Vec3::new(h[e][0][l], h[e][1][l], h[e][2][l]);
            let refl = wo.z * w.z > 0.0;
            let eta = if wo.z > 0.0 { q.eta[l] } else { 1.0 / q.eta[l] };
            let d = if hh.z <= 0.0 { 0.0 } else { mf::beckmann_d_of(ex[e][l], ax, ay, c2[e][l]) };
            let g1o = Microfacet::g1_given(wo, hh, || lambda[0][l]);
            let (om, im) = (wo.dot(hh), w.dot(hh));
            let fr = fresnel::dielectric_reflectance(om, q.eta[l]);
            // The density.
            let jac = if refl { 1.0 / (4.0 * im.abs()) } else { eta * eta * im.abs() / ((om + eta * im) * (om + eta * im)) };
            let p = Microfacet::pdf_visible_given(v, hh, d, g1o) * if refl { fr } else { 1.0 - fr } * jac;
            let p = if p.is_finite() { p } else { 0.0 };
            // The value.
            let g = g1o * Microfacet::g1_given(w, hh, || lambda[1 + e][l]);
            let sr = fr * d * g / (4.0 * wo.z.abs() * w.z.abs());
            let denom = om + eta * im;
            let inv = 1.0 / eta;
            let st = inv * inv * (1.0 - fr) * d * g * eta * eta * (om * im).abs() / ((wo.z * w.z).abs() * denom * denom);
            let st = if st.is_finite() { st } else { 0.0 };
            let ok = valid[e][l];
            for (k, row) in f[e].iter_mut().enumerate() {
                let (cr, ct) = (q.specular_reflectance[k][l] * sr, q.specular_transmittance[k][l] * st);
                let c = if refl { cr } else { ct };
                row[l] = if ok { c } else { 0.0 };
            }
            pdf[e][l] = if ok { p } else { 0.0 };
        }
    }
    let [nee_f, sf] = f;
    // `sample`'s tests: a direction off the macrosurface side of its lobe, or no density.
    let mut sampled = [false; N];
    for l in 0..N {
        let (woz, wz) = (q.wo[2][l], ws[2][l]);
        sampled[l] = (wz != 0.0) & ((wz * woz > 0.0) == reflected[l]) & super::positive_finite(pdf[1][l]);
    }
    LaneSamples { nee_f, nee_pdf: pdf[0], sampled, glossy: reflected, eta: eta_s, wi: ws, f: sf, pdf: pdf[1] }
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
