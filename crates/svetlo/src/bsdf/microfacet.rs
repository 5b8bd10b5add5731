//! Microfacet normal distributions (GGX / Trowbridge-Reitz and Beckmann), anisotropic
//! with `alpha_u` along the local x axis and `alpha_v` along y.
//!
//! Shadowing-masking is Smith's *separable* form G = G1(wo) G1(wi), as Mitsuba 3 uses, with
//! the exact Smith G1 of each distribution (Mitsuba approximates Beckmann's G1 by a
//! rational fit within 0.35 %; the exact form keeps the visible-normal pdf consistent with
//! its sampler). Sampling draws visible normals: Heitz 2018 for GGX, and for Beckmann the
//! slope-space method of Heitz and d'Eon 2014 with a safeguarded Newton inversion of the
//! slope CDF (as Jakob's improved routine does, but bracketed so that it always converges).

use super::material::MicrofacetKind;
use crate::math::PI;
use glam::{Vec2, Vec3};

/// Smallest roughness: below it, f32 cannot represent the lobe (Mitsuba clamps likewise).
pub const MIN_ALPHA: f32 = 1e-4;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Microfacet {
    pub kind: MicrofacetKind,
    pub alpha_u: f32,
    pub alpha_v: f32,
}

impl Microfacet {
    pub fn new(kind: MicrofacetKind, alpha_u: f32, alpha_v: f32) -> Self {
        let fix = |a: f32| if a.is_finite() { a.max(MIN_ALPHA) } else { 1.0 };
        Microfacet { kind, alpha_u: fix(alpha_u), alpha_v: fix(alpha_v) }
    }

    /// Normal distribution D(m), per unit projected area: ∫ D(m) cos θm dm = 1.
    pub fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let (ax, ay) = (self.alpha_u, self.alpha_v);
        let c2 = m.z * m.z;
        let e = (m.x / ax) * (m.x / ax) + (m.y / ay) * (m.y / ay);
        let r = match self.kind {
            MicrofacetKind::Beckmann => (-e / c2).exp() / (PI * ax * ay * c2 * c2),
            MicrofacetKind::Ggx => {
                let t = e + c2;
                1.0 / (PI * ax * ay * t * t)
            }
        };
        if r.is_finite() {
            r
        } else {
            0.0
        }
    }

    /// Smith's Λ(v): G1 = 1 / (1 + Λ).
    pub fn lambda(&self, v: Vec3) -> f32 {
        let xy = (self.alpha_u * v.x).powi(2) + (self.alpha_v * v.y).powi(2);
        if xy == 0.0 {
            return 0.0;
        }
        let a2t2 = xy / (v.z * v.z); // (alpha tan theta)^2 along v's azimuth
        match self.kind {
            MicrofacetKind::Ggx => 0.5 * ((1.0 + a2t2).sqrt() - 1.0),
            MicrofacetKind::Beckmann => {
                let a = 1.0 / (a2t2 as f64).sqrt();
                (0.5 * (-erfc(a) + (-a * a).exp() / (a * SQRT_PI))) as f32
            }
        }
    }

    /// Smith's masking of microfacet `m` seen from `v` (zero if `v` sees its back).
    #[inline]
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        1.0 / (1.0 + self.lambda(v))
    }

    /// Separable shadowing-masking G1(wo) G1(wi).
    #[inline]
    pub fn g(&self, wo: Vec3, wi: Vec3, m: Vec3) -> f32 {
        self.g1(wo, m) * self.g1(wi, m)
    }

    /// Density of [`Self::sample_visible`]: D(m) G1(v, m) max(0, v.m) / v.z, over
    /// microfacet normals (solid angle). `v` must be in the upper hemisphere.
    pub fn pdf_visible(&self, v: Vec3, m: Vec3) -> f32 {
        if v.z <= 0.0 {
            return 0.0;
        }
        let vm = v.dot(m);
        if vm <= 0.0 {
            return 0.0;
        }
        self.d(m) * self.g1(v, m) * vm / v.z
    }

    /// [`Self::pdf_visible`] given `d` = D(m) and `g1` = G1(v, m), which a caller that also
    /// evaluates the BSDF has computed already: the same value.
    #[inline]
    pub(crate) fn pdf_visible_given(v: Vec3, m: Vec3, d: f32, g1: f32) -> f32 {
        if v.z <= 0.0 {
            return 0.0;
        }
        let vm = v.dot(m);
        if vm <= 0.0 {
            return 0.0;
        }
        d * g1 * vm / v.z
    }

    /// Draw a microfacet normal visible from `v` (upper hemisphere), proportional to
    /// D(m) G1(v, m) max(0, v.m).
    pub fn sample_visible(&self, v: Vec3, u: Vec2) -> Vec3 {
        let s = VisibleSampler::new(self, v);
        s.combine(s.part_x(u.x), s.part_y(u.y))
    }
}

/// Visible-normal sampling for one direction `v`, split into what depends on `v` alone, on
/// `u.x` alone and on `u.y` alone, so that a quadrature over a grid of `u` (the coating
/// tables) evaluates the costly one-dimensional parts once per grid line.
/// [`Microfacet::sample_visible`] is these same pieces, so both agree bit for bit.
#[derive(Clone, Copy, Debug)]
pub(crate) enum VisibleSampler {
    /// Heitz 2018: in the stretched configuration the visible normals of GGX are the
    /// projection of a uniform disk onto a hemisphere, with the disk's far half squashed.
    /// `vh` is the stretched view, `t1`, `t2` the disk's axes.
    Ggx { alpha: (f32, f32), vh: Vec3, t1: Vec3, t2: Vec3, s: f32 },
    /// Heitz and d'Eon 2014: stretch to alpha = 1, sample the visible slopes there, rotate
    /// back to the azimuth of `v` and unstretch.
    Beckmann { alpha: (f32, f32), cos_t: f64, cos_phi: f32, sin_phi: f32 },
}

impl VisibleSampler {
    pub(crate) fn new(md: &Microfacet, v: Vec3) -> Self {
        let alpha = (md.alpha_u, md.alpha_v);
        match md.kind {
            MicrofacetKind::Ggx => {
                let vh = Vec3::new(md.alpha_u * v.x, md.alpha_v * v.y, v.z).normalize();
                let len2 = vh.x * vh.x + vh.y * vh.y;
                let t1 = if len2 > 0.0 { Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt() } else { Vec3::X };
                VisibleSampler::Ggx { alpha, vh, t1, t2: vh.cross(t1), s: 0.5 * (1.0 + vh.z) }
            }
            MicrofacetKind::Beckmann => {
                let vs = Vec3::new(md.alpha_u * v.x, md.alpha_v * v.y, v.z).normalize();
                let r = (vs.x * vs.x + vs.y * vs.y).sqrt();
                let (cos_phi, sin_phi) = if r > 0.0 { (vs.x / r, vs.y / r) } else { (1.0, 0.0) };
                VisibleSampler::Beckmann { alpha, cos_t: vs.z as f64, cos_phi, sin_phi }
            }
        }
    }

    /// What depends on `u.x` only: the disk radius (GGX) or the x slope (Beckmann).
    #[inline]
    pub(crate) fn part_x(&self, ux: f32) -> f32 {
        match *self {
            VisibleSampler::Ggx { .. } => ux.sqrt(),
            VisibleSampler::Beckmann { cos_t, .. } => beckmann_slope_x_11(cos_t, ux as f64) as f32,
        }
    }

    /// What depends on `u.y` only (and not on `v`): the disk angle's cosine and sine (GGX)
    /// or the y slope (Beckmann, second value unused).
    #[inline]
    pub(crate) fn part_y(&self, uy: f32) -> (f32, f32) {
        match *self {
            VisibleSampler::Ggx { .. } => {
                let phi = 2.0 * PI * uy;
                (phi.cos(), phi.sin())
            }
            VisibleSampler::Beckmann { .. } => (erfinv_approx(2.0 * uy as f64 - 1.0) as f32, 0.0),
        }
    }

    /// The microfacet normal from the two parts.
    #[inline]
    pub(crate) fn combine(&self, x: f32, y: (f32, f32)) -> Vec3 {
        match *self {
            VisibleSampler::Ggx { alpha, vh, t1, t2, s } => {
                let p1 = x * y.0;
                let mut p2 = x * y.1;
                p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
                let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
                Vec3::new(alpha.0 * nh.x, alpha.1 * nh.y, nh.z.max(1e-7)).normalize()
            }
            VisibleSampler::Beckmann { alpha, cos_phi, sin_phi, .. } => {
                let (sx, sy) = (x, y.0);
                let px = (cos_phi * sx - sin_phi * sy) * alpha.0;
                let py = (sin_phi * sx + cos_phi * sy) * alpha.1;
                let m = Vec3::new(-px, -py, 1.0).normalize();
                if m.is_finite() {
                    m
                } else {
                    Vec3::Z
                }
            }
        }
    }
}

const SQRT_PI: f64 = 1.772_453_850_905_516;

/// Complementary error function, fractional error below 1.2e-7 everywhere (Chebyshev
/// fit of Press et al., Numerical Recipes §6.2).
pub(crate) fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06 + t * (0.278_868_07 + t * (-1.135_203_98 + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * (-z * z + poly).exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Inverse error function: Giles' single-precision approximation (2010), relative error
/// a few 1e-7.
fn erfinv_approx(x: f64) -> f64 {
    let x = x.clamp(-1.0 + 1e-15, 1.0 - 1e-15);
    let mut w = -((1.0 - x) * (1.0 + x)).ln();
    let p = if w < 5.0 {
        w -= 2.5;
        [2.810_226_36e-8, 3.432_739_39e-7, -3.523_387_7e-6, -4.391_506_54e-6, 2.185_808_7e-4, -1.253_725_03e-3, -4.177_681_64e-3, 0.246_640_727, 1.501_409_41]
            .iter()
            .fold(0.0, |p, &c| c + p * w)
    } else {
        w = w.sqrt() - 3.0;
        [-2.002_142_57e-4, 1.009_505_58e-4, 1.349_343_22e-3, -3.673_428_44e-3, 5.739_507_73e-3, -7.622_461_3e-3, 9.438_870_47e-3, 1.001_674_06, 2.832_976_82]
            .iter()
            .fold(0.0, |p, &c| c + p * w)
    };
    p * x
}

/// The x slope of the alpha = 1 Beckmann distribution's visible normals seen at incidence
/// cosine `cos_t` (azimuth 0). It has density ∝ exp(-x²) (1 - x tanθ) on x < cot θ, whose
/// CDF is C(x) = erfc(-x)/2 + tanθ exp(-x²) / (2√π). The y slope is Gaussian with density
/// exp(-y²)/√π (the same CDF with tanθ = 0), whose inverse CDF is erfinv itself (Giles' fit
/// is accurate to f32 precision).
fn beckmann_slope_x_11(cos_t: f64, u1: f64) -> f64 {
    let cos_t = cos_t.clamp(1e-8, 1.0);
    let tan_t = (1.0 - cos_t * cos_t).max(0.0).sqrt() / cos_t;
    let x_max = if tan_t > 1e-8 { (1.0 / tan_t).min(8.0) } else { 8.0 };
    // Initial guess (Jakob 2014): exact at grazing incidence, good elsewhere, taken in the
    // erf domain between -1 and erf(cot θ).
    let u1c = u1.clamp(1e-12, 1.0 - 1e-12);
    let max_erf = 1.0 - erfc(x_max);
    let g = max_erf - (max_erf + 1.0) * (1.0 - erfc((-u1c.ln()).sqrt()));
    invert_slope_cdf(tan_t, u1, x_max, erfinv_approx(g))
}

/// Solve C(x) = u C(x_max) for x in [-8, x_max], with C as in [`beckmann_slope_x_11`]:
/// Newton steps from `guess`, kept inside a shrinking bracket (bisection when Newton
/// leaves it), so that it always converges.
fn invert_slope_cdf(tan_t: f64, u: f64, x_max: f64, guess: f64) -> f64 {
    // The CDF at x, given exp(-x²) (which the derivative shares).
    let cdf = |x: f64, e: f64| 0.5 * erfc(-x) + tan_t * e / (2.0 * SQRT_PI);
    let target = u.clamp(1e-12, 1.0 - 1e-12) * cdf(x_max, (-x_max * x_max).exp());
    let (mut lo, mut hi) = (-8.0f64, x_max);
    let mut x = if guess.is_finite() { guess.clamp(lo, hi) } else { 0.0f64.clamp(lo, hi) };
    for _ in 0..64 {
        let e = (-x * x).exp();
        let g = cdf(x, e) - target;
        if g > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        let dg = e / SQRT_PI * (1.0 - x * tan_t);
        let mut nx = if dg > 0.0 { x - g / dg } else { f64::NAN };
        if !(nx > lo && nx < hi) {
            nx = 0.5 * (lo + hi);
        }
        // Slopes end up in f32: 1e-7 is already below their resolution.
        if (nx - x).abs() < 1e-7 {
            return nx;
        }
        x = nx;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere_integral(f: impl Fn(Vec3) -> f64, n: usize) -> f64 {
        // Midpoint rule in (cos theta, phi) over the upper hemisphere.
        let mut s = 0.0;
        for i in 0..n {
            let z = (i as f64 + 0.5) / n as f64;
            for j in 0..2 * n {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / (2 * n) as f64;
                let r = (1.0 - z * z).sqrt();
                s += f(Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32));
            }
        }
        s * 2.0 * std::f64::consts::PI / (2 * n * n) as f64
    }

    #[test]
    fn erfc_known_values() {
        for &(x, v) in
            &[(0.0, 1.0), (0.5, 0.479_500_122_186_953_5), (1.0, 0.157_299_207_050_285_1), (2.0, 0.004_677_734_981_047_266), (-1.0, 1.842_700_792_949_715)]
        {
            assert!((erfc(x) - v).abs() / v < 2e-7, "erfc({x})");
        }
    }

    #[test]
    fn projected_area_normalised_and_visible_pdf_integrates_to_one() {
        for kind in [MicrofacetKind::Ggx, MicrofacetKind::Beckmann] {
            for &(au, av) in &[(0.3f32, 0.3f32), (0.5, 0.15), (0.9, 0.7)] {
                let md = Microfacet::new(kind, au, av);
                let a = sphere_integral(|m| (md.d(m) * m.z) as f64, 400);
                assert!((a - 1.0).abs() < 5e-3, "{kind:?} {au} {av}: ∫D cos = {a}");
                for v in [Vec3::Z, Vec3::new(0.6, 0.3, 0.742_57).normalize(), Vec3::new(-0.9, 0.1, 0.2).normalize()] {
                    let p = sphere_integral(|m| md.pdf_visible(v, m) as f64, 400);
                    assert!((p - 1.0).abs() < 5e-3, "{kind:?} {au} {av} v {v}: ∫pdf = {p}");
                }
            }
        }
    }
}
