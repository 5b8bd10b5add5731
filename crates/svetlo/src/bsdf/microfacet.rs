//! Microfacet normal distributions (GGX / Trowbridge-Reitz and Beckmann), anisotropic
//! with `alpha_u` along the local x axis and `alpha_v` along y.
//!
//! Shadowing-masking is Smith's *separable* form G = G1(wo) G1(wi), as Mitsuba 3 uses, with
//! the exact Smith G1 of each distribution (Mitsuba approximates Beckmann's G1 by a
//! rational fit within 0.35 %; the closed form, here evaluated in f32 to within 4e-7, keeps
//! the visible-normal pdf consistent with its sampler). Sampling draws visible normals:
//! Heitz 2018 for GGX, and for Beckmann the slope-space method of Heitz and d'Eon 2014 with
//! a safeguarded f32 Newton inversion of the slope CDF from Jakob's (2014) initial guess
//! (bracketed so that it always converges; see `SlopeX`).

use super::material::MicrofacetKind;
use crate::math::{approx, expf, PI};
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
        match self.kind {
            MicrofacetKind::Beckmann => {
                let (x, c2) = beckmann_d_exponent(ax, ay, m);
                beckmann_d_of(beckmann_d_exp(x), ax, ay, c2)
            }
            MicrofacetKind::Ggx => ggx_d(ax, ay, m),
        }
    }

    /// Smith's Λ(v): G1 = 1 / (1 + Λ).
    pub fn lambda(&self, v: Vec3) -> f32 {
        self.lambda_inline(v)
    }

    /// Smith's masking of microfacet `m` seen from `v` (zero if `v` sees its back).
    #[inline]
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        Self::g1_given(v, m, || self.lambda(v))
    }

    /// [`Self::g1`] with Λ(v) from `lambda` (a caller's, computed once for several `m`), asked
    /// only where `v` sees the front of `m`: the same value.
    #[inline]
    pub(crate) fn g1_given(v: Vec3, m: Vec3, lambda: impl FnOnce() -> f32) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        1.0 / (1.0 + lambda())
    }

    /// [`Self::lambda`] inlined (a vertex's Λ(wo), once per vertex).
    #[inline(always)]
    pub(crate) fn lambda_inline(&self, v: Vec3) -> f32 {
        let xy = (self.alpha_u * v.x).powi(2) + (self.alpha_v * v.y).powi(2);
        if xy == 0.0 {
            return 0.0;
        }
        let a2t2 = xy / (v.z * v.z); // (alpha tan theta)^2 along v's azimuth
        match self.kind {
            MicrofacetKind::Ggx => ggx_lambda_of(a2t2),
            MicrofacetKind::Beckmann => beckmann_lambda_of(a2t2),
        }
    }

    /// [`Self::g1`] inlined whole, Λ(v) included (a caller that runs two chains side by
    /// side).
    #[inline(always)]
    pub(crate) fn g1_inline(&self, v: Vec3, m: Vec3) -> f32 {
        Self::g1_given(v, m, || self.lambda_inline(v))
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
        // u.y's part first: it does not wait on u.x's (Beckmann's Newton iteration, whose
        // branches the CPU mispredicts), so it runs beside it.
        let y = s.part_y(u.y);
        s.combine(s.part_x(u.x), y)
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
    Beckmann { alpha: (f32, f32), slope: SlopeX, cos_phi: f32, sin_phi: f32 },
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
                VisibleSampler::Beckmann { alpha, slope: SlopeX::new(vs.z), cos_phi, sin_phi }
            }
        }
    }

    /// What depends on `u.x` only: the disk radius (GGX) or the x slope (Beckmann).
    #[inline]
    pub(crate) fn part_x(&self, ux: f32) -> f32 {
        match *self {
            VisibleSampler::Ggx { .. } => ux.sqrt(),
            VisibleSampler::Beckmann { ref slope, .. } => slope.sample(ux),
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
            VisibleSampler::Beckmann { .. } => (approx::erfinv(2.0 * uy - 1.0), 0.0),
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

const INV_SQRT_PI: f32 = 0.564_189_6;

/// GGX's D(m) of roughness (`ax`, `ay`) for m.z > 0 (0 where not finite), as
/// [`Microfacet::d`] and the path kernel's lanes take it (the test a select).
#[inline(always)]
pub(crate) fn ggx_d(ax: f32, ay: f32, m: Vec3) -> f32 {
    let c2 = m.z * m.z;
    let e = (m.x / ax) * (m.x / ax) + (m.y / ay) * (m.y / ay);
    let t = e + c2;
    let r = 1.0 / (PI * ax * ay * t * t);
    if r.is_finite() {
        r
    } else {
        0.0
    }
}

/// GGX's Smith Λ from (α tanθ)² along the direction's azimuth.
#[inline(always)]
fn ggx_lambda_of(a2t2: f32) -> f32 {
    0.5 * ((1.0 + a2t2).sqrt() - 1.0)
}

/// [`Microfacet::lambda`] of a GGX distribution of roughness (`ax`, `ay`), as vector lanes
/// run it (the test of its azimuth term a select).
#[inline(always)]
pub(crate) fn ggx_lambda(ax: f32, ay: f32, v: Vec3) -> f32 {
    let xy = (ax * v.x).powi(2) + (ay * v.y).powi(2);
    let a2t2 = xy / (v.z * v.z);
    if xy == 0.0 {
        0.0
    } else {
        ggx_lambda_of(a2t2)
    }
}

/// [`Microfacet::sample_visible`] of a GGX distribution for `N` lanes at once (roughness, `v`
/// and `u` as for Beckmann's): Heitz 2018's closed form, the same operations lane by lane
/// with selects for branches. The disk angle's cosine and sine (libm's, lane by lane) only
/// where `want` (other lanes' normals are unused). The same bits.
#[inline(always)]
pub(crate) fn sample_visible_ggx_lanes<const N: usize>(q: &VisibleNormalLanes<N>, want: &[bool; N]) -> [[f32; N]; 3] {
    let (mut cos, mut sin) = ([1.0f32; N], [0.0f32; N]);
    for l in 0..N {
        if want[l] {
            let phi = 2.0 * PI * q.u[1][l];
            (cos[l], sin[l]) = (phi.cos(), phi.sin());
        }
    }
    let mut m = [[0.0f32; N]; 3];
    for l in 0..N {
        let (ax, ay) = (q.alpha[0][l], q.alpha[1][l]);
        // `VisibleSampler::new`.
        let vh = Vec3::new(ax * q.v[0][l], ay * q.v[1][l], q.v[2][l]).normalize();
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt();
        let t1 = if len2 > 0.0 { t1 } else { Vec3::X };
        let (t2, s) = (vh.cross(t1), 0.5 * (1.0 + vh.z));
        // `combine`.
        let x = q.u[0][l].sqrt();
        let p1 = x * cos[l];
        let p2 = x * sin[l];
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        let n = Vec3::new(ax * nh.x, ay * nh.y, nh.z.max(1e-7)).normalize();
        for k in 0..3 {
            m[k][l] = n[k];
        }
    }
    m
}

/// Beckmann's D(m) (m.z > 0) in three steps, so that eight lanes can run the first and last
/// as vector code and only libm's expf lane by lane: the exponent -tan²θ/α² and cos²θ,
/// its e^x, the density.
#[inline(always)]
pub(crate) fn beckmann_d_exponent(ax: f32, ay: f32, m: Vec3) -> (f32, f32) {
    let c2 = m.z * m.z;
    let e = (m.x / ax) * (m.x / ax) + (m.y / ay) * (m.y / ay);
    (-e / c2, c2)
}

/// e^x of [`beckmann_d_exponent`]'s x. Below -104, e^x is under half the smallest subnormal:
/// libm's expf returns 0 there through its underflow path (an underflowing multiply and
/// errno: slow, and the common case for a light sample far off a smooth conductor's lobe).
#[inline(always)]
pub(crate) fn beckmann_d_exp(x: f32) -> f32 {
    if x < -104.0 {
        0.0
    } else {
        x.exp()
    }
}

/// [`beckmann_d_exp`] of two directions' exponents `x` of `N` lanes, where D is asked for
/// (`ok`, among the first `used` lanes; 0 elsewhere): glibc's expf as vector lanes, and
/// libm's lane by lane where one leaves glibc's main path (x <= -88 or NaN: rare). The same
/// bits. (`&`, not `&&`: a branch per lane kept the loop scalar.)
#[inline(always)]
pub(crate) fn beckmann_d_exp_lanes<const N: usize>(x: &[[f32; N]; 2], ok: &[[bool; N]; 2], used: usize) -> [[f32; N]; 2] {
    let (mut ex, mut off) = ([[0.0f32; N]; 2], [[false; N]; 2]);
    for e in 0..2 {
        for l in 0..N {
            let xe = x[e][l];
            // NaN is not below -104: the fallback below gives libm's NaN.
            let below = xe < -104.0;
            let want = (l < used) & ok[e][l] & !below;
            let v = expf::expf_main(xe);
            ex[e][l] = if want { v } else { 0.0 };
            off[e][l] = want & !expf::main_path(xe);
        }
    }
    if off.as_flattened().iter().fold(false, |a, &o| a | o) {
        for l in 0..used.min(N) {
            for e in 0..2 {
                if ok[e][l] {
                    ex[e][l] = beckmann_d_exp(x[e][l]);
                }
            }
        }
    }
    ex
}

/// D(m) from [`beckmann_d_exp`]'s e^x and cos²θ `c2` (0 where not finite).
#[inline(always)]
pub(crate) fn beckmann_d_of(ex: f32, ax: f32, ay: f32, c2: f32) -> f32 {
    let r = ex / (PI * ax * ay * c2 * c2);
    if r.is_finite() {
        r
    } else {
        0.0
    }
}

/// [`Microfacet::lambda`] of a Beckmann distribution of roughness (`ax`, `ay`), as vector
/// lanes run it (the test of its azimuth term a select).
#[inline(always)]
pub(crate) fn beckmann_lambda(ax: f32, ay: f32, v: Vec3) -> f32 {
    let xy = (ax * v.x).powi(2) + (ay * v.y).powi(2);
    let a2t2 = xy / (v.z * v.z);
    if xy == 0.0 {
        0.0
    } else {
        beckmann_lambda_of(a2t2)
    }
}

/// Beckmann's Smith Λ from (α tanθ)² along the direction's azimuth (not 0):
/// Λ = (e^{-a²} / (a √π) - erfc(a)) / 2, a = 1 / (α tanθ). The approximations' absolute
/// error (below 4e-7 in Λ) is what G1 = 1 / (1 + Λ) sees.
#[inline(always)]
pub(crate) fn beckmann_lambda_of(a2t2: f32) -> f32 {
    let a = 1.0 / a2t2.sqrt();
    let e = approx::exp(-a * a);
    (0.5 * (e * INV_SQRT_PI / a - approx::erfc_nonneg(a, e))).max(0.0)
}

/// `N` lanes' visible-normal draws for [`sample_visible_beckmann_lanes`] or
/// [`sample_visible_ggx_lanes`]: the roughness (`alpha_u`, `alpha_v`), the direction `v` and
/// the numbers `u`, per lane.
#[derive(Clone, Copy, Debug)]
pub(crate) struct VisibleNormalLanes<const N: usize> {
    pub alpha: [[f32; N]; 2],
    pub v: [[f32; N]; 3],
    pub u: [[f32; N]; 2],
}

impl<const N: usize> Default for VisibleNormalLanes<N> {
    /// Normal incidence at roughness 1 and u = 1/2 (unused lanes: the Newton loop settles
    /// them at once).
    fn default() -> Self {
        VisibleNormalLanes { alpha: [[1.0; N]; 2], v: [[0.0; N], [0.0; N], [1.0; N]], u: [[0.5; N]; 2] }
    }
}

/// [`Microfacet::sample_visible`] of a Beckmann distribution for `N` lanes at once: the
/// same operations lane by lane, with selects for branches, so that the lanes run as vector
/// lanes (one lane's Newton iteration is a chain of divisions that wait on each other). The
/// Newton loop runs while any lane goes on; a lane that the scalar loop would have left is
/// frozen where it stopped. The same bits.
#[inline(always)]
pub(crate) fn sample_visible_beckmann_lanes<const N: usize>(q: &VisibleNormalLanes<N>) -> [[f32; N]; 3] {
    // `VisibleSampler::new`.
    let (mut cos_phi, mut sin_phi) = ([0.0f32; N], [0.0f32; N]);
    let (mut tan_t, mut x_max, mut c_max, mut erf_max, mut fit) = ([0.0f32; N], [0.0f32; N], [0.0f32; N], [0.0f32; N], [0.0f32; N]);
    for l in 0..N {
        let vs = Vec3::new(q.alpha[0][l] * q.v[0][l], q.alpha[1][l] * q.v[1][l], q.v[2][l]).normalize();
        let r = (vs.x * vs.x + vs.y * vs.y).sqrt();
        cos_phi[l] = if r > 0.0 { vs.x / r } else { 1.0 };
        sin_phi[l] = if r > 0.0 { vs.y / r } else { 0.0 };
        let s = SlopeX::new(vs.z);
        (tan_t[l], x_max[l], c_max[l], erf_max[l], fit[l]) = (s.tan_t, s.x_max, s.c_max, s.erf_max, s.fit);
    }
    // `SlopeX::sample`'s start.
    let (mut target, mut tolerance, mut x, mut lo, mut hi) = ([0.0f32; N], [0.0f32; N], [0.0f32; N], [-8.0f32; N], x_max);
    for l in 0..N {
        let u = q.u[0][l].clamp(1e-7, 1.0 - 6e-8);
        let b = erf_max[l] - (1.0 + erf_max[l]) * approx::exp(fit[l] * approx::ln(1.0 - u));
        target[l] = u * c_max[l];
        tolerance[l] = SLOPE_CDF_TOLERANCE * c_max[l];
        let guess = approx::erfinv_branchless(b);
        // `clamp` as selects (its check of the bounds' order would keep the loop scalar).
        let g = if guess.is_finite() { guess } else { 0.0 };
        let g = if g < lo[l] { lo[l] } else { g };
        x[l] = if g > hi[l] { hi[l] } else { g };
    }
    // Its Newton loop.
    let mut going = [true; N];
    for _ in 0..32 {
        for l in 0..N {
            let xl = x[l];
            let e = approx::exp(-xl * xl);
            let r = approx::erfc_nonneg(if xl <= 0.0 { -xl } else { xl }, e);
            let erfc_neg_x = if xl <= 0.0 { r } else { 2.0 - r };
            let g = 0.5 * erfc_neg_x + 0.5 * INV_SQRT_PI * tan_t[l] * e - target[l];
            let settled = g.abs() < tolerance[l];
            let (nlo, nhi) = if g > 0.0 { (lo[l], xl) } else { (xl, hi[l]) };
            let dg = INV_SQRT_PI * e * (1.0 - xl * tan_t[l]);
            let nx = xl - g / dg;
            let nx = if !(nx > nlo && nx < nhi) { 0.5 * (nlo + nhi) } else { nx };
            let go = going[l] && !settled && nx != xl;
            x[l] = if go { nx } else { xl };
            lo[l] = if go { nlo } else { lo[l] };
            hi[l] = if go { nhi } else { hi[l] };
            going[l] = go;
        }
        // (A fold, not `any`: `any` stops at the first lane, tested one byte at a time.)
        if !going.iter().fold(false, |a, &g| a | g) {
            break;
        }
    }
    // `part_y` and `combine`.
    let mut m = [[0.0f32; N]; 3];
    for l in 0..N {
        let (sx, sy) = (x[l], approx::erfinv_branchless(2.0 * q.u[1][l] - 1.0));
        let px = (cos_phi[l] * sx - sin_phi[l] * sy) * q.alpha[0][l];
        let py = (sin_phi[l] * sx + cos_phi[l] * sy) * q.alpha[1][l];
        let n = Vec3::new(-px, -py, 1.0).normalize();
        let n = if n.is_finite() { n } else { Vec3::Z };
        (m[0][l], m[1][l], m[2][l]) = (n.x, n.y, n.z);
    }
    m
}

/// Sampler of the x slope of the alpha = 1 Beckmann distribution's visible normals seen at
/// incidence cosine `cos θ` (azimuth 0). That slope has density ∝ e^{-x²} (1 - x tanθ) on
/// x < cot θ, with CDF C(x) = erfc(-x)/2 + tanθ e^{-x²} / (2√π). (The y slope is Gaussian,
/// e^{-y²}/√π, whose inverse CDF is erfinv(2u - 1) itself.)
///
/// C is inverted by Newton's method in f32 over the approximations of [`approx`], from
/// Jakob's (2014) initial guess, kept inside a shrinking bracket (bisection where Newton
/// leaves it) so that it always converges. It stops once |C(x) - u C(x_max)| is below
/// [`SLOPE_CDF_TOLERANCE`] · C(x_max): the sampled CDF is then off by less than 1e-6
/// (with the approximations' own error), after 2.3 Newton steps on average.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlopeX {
    tan_t: f32,
    /// Upper end of the support, cot θ (at most 8: beyond, the mass is below 1e-28).
    x_max: f32,
    /// C(x_max): the normalisation.
    c_max: f32,
    /// erf(x_max), the initial guess's upper end in the erf domain.
    erf_max: f32,
    /// The guess's exponent, Jakob's fit in θ.
    fit: f32,
}

/// Residual of the slope CDF (relative to its total) at which the inversion stops.
const SLOPE_CDF_TOLERANCE: f32 = 3e-7;

impl SlopeX {
    /// (Always inlined: `sample_visible_beckmann_lanes` calls it per lane, and where LLVM kept
    /// it out of line, that first loop ran lane by lane instead of as vector code.)
    #[inline(always)]
    fn new(cos_t: f32) -> Self {
        let cos_t = cos_t.clamp(1e-6, 1.0);
        let tan_t = (1.0 - cos_t * cos_t).max(0.0).sqrt() / cos_t;
        let x_max = if tan_t * 8.0 > 1.0 { 1.0 / tan_t } else { 8.0 };
        let e_max = approx::exp(-x_max * x_max);
        let erfc_max = approx::erfc_nonneg(x_max, e_max);
        let c_max = 0.5 * (2.0 - erfc_max) + 0.5 * INV_SQRT_PI * tan_t * e_max;
        let theta = approx::acos_nonneg_coarse(cos_t);
        let fit = 1.0 + theta * (-0.876 + theta * (0.4265 - 0.0594 * theta));
        SlopeX { tan_t, x_max, c_max, erf_max: 1.0 - erfc_max, fit }
    }

    /// The slope at CDF value `u` in [0, 1].
    fn sample(&self, u: f32) -> f32 {
        let SlopeX { tan_t, x_max, c_max, erf_max, fit } = *self;
        let u = u.clamp(1e-7, 1.0 - 6e-8);
        // Jakob's guess in the erf domain: exact at normal and at grazing incidence.
        let b = erf_max - (1.0 + erf_max) * approx::exp(fit * approx::ln(1.0 - u));
        let target = u * c_max;
        let tolerance = SLOPE_CDF_TOLERANCE * c_max;
        let (mut lo, mut hi) = (-8.0f32, x_max);
        let guess = approx::erfinv(b);
        let mut x = if guess.is_finite() { guess.clamp(lo, hi) } else { 0.0f32.clamp(lo, hi) };
        for _ in 0..32 {
            let e = approx::exp(-x * x);
            let erfc_neg_x = if x <= 0.0 { approx::erfc_nonneg(-x, e) } else { 2.0 - approx::erfc_nonneg(x, e) };
            let g = 0.5 * erfc_neg_x + 0.5 * INV_SQRT_PI * tan_t * e - target;
            if g.abs() < tolerance {
                break;
            }
            if g > 0.0 {
                hi = x;
            } else {
                lo = x;
            }
            let dg = INV_SQRT_PI * e * (1.0 - x * tan_t);
            let mut nx = x - g / dg;
            if !(nx > lo && nx < hi) {
                nx = 0.5 * (lo + hi);
            }
            // The bracket has shrunk to the float's resolution.
            if nx == x {
                break;
            }
            x = nx;
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::stats::erfc as erfc64;

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

    /// The slope CDF in f64 (reference), with its support's end.
    fn slope_cdf_ref(cos_t: f64) -> (impl Fn(f64) -> f64, f64) {
        let tan_t = (1.0 - cos_t * cos_t).max(0.0).sqrt() / cos_t;
        let x_max = if tan_t * 8.0 > 1.0 { 1.0 / tan_t } else { 8.0 };
        let c = move |x: f64| 0.5 * erfc64(-x) + tan_t * (-x * x).exp() / (2.0 * std::f64::consts::PI.sqrt());
        (c, x_max)
    }

    /// Incidence cosines from normal to 0.001 (grazing), as f32 as the sampler takes them.
    const COS_THETAS: [f32; 9] = [1.0, 0.999, 0.95, 0.8, 0.5, 0.25, 0.1, 0.02, 0.001];

    /// Beckmann's D with its shortcut (libm's exp skipped below -104) is the full formula bit
    /// for bit, on both sides of the threshold: the smooth conductors of veach-mis and others,
    /// normal to grazing.
    #[test]
    fn beckmann_d_shortcut_keeps_the_bits() {
        let d_full = |md: &Microfacet, m: Vec3| {
            if m.z <= 0.0 {
                return 0.0;
            }
            let (ax, ay) = (md.alpha_u, md.alpha_v);
            let c2 = m.z * m.z;
            let e = (m.x / ax) * (m.x / ax) + (m.y / ay) * (m.y / ay);
            let r = (-e / c2).exp() / (PI * ax * ay * c2 * c2);
            if r.is_finite() {
                r
            } else {
                0.0
            }
        };
        let mut rng = crate::sampling::Pcg32::new(17, 5);
        let mut zero_d = 0;
        for (au, av) in [(0.01, 0.01), (0.05, 0.05), (0.1, 0.1), (0.25, 0.25), (0.01, 0.3), (1e-4, 1e-4)] {
            let md = Microfacet::new(MicrofacetKind::Beckmann, au, av);
            for i in 0..20_000 {
                let cos_t = COS_THETAS.get(i).copied().unwrap_or_else(|| rng.next_f32());
                let phi = 2.0 * PI * rng.next_f32();
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let v = Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
                assert_eq!(md.d(v).to_bits(), d_full(&md, v).to_bits(), "alpha ({au}, {av}), m {v}");
                zero_d += (md.d(v) == 0.0) as u32;
            }
        }
        // The shortcut was taken, and not always.
        assert!(zero_d > 1000 && zero_d < 110_000, "{zero_d}");
    }

    /// The sampled slope's CDF value (exact, f64) is the sample's u within 1.5e-6, over a
    /// dense grid of u including the tails, at every incidence.
    #[test]
    fn beckmann_slope_inverts_its_cdf() {
        for cos_t in COS_THETAS {
            let s = SlopeX::new(cos_t);
            let (c, x_max) = slope_cdf_ref(cos_t as f64);
            let total = c(x_max);
            let mut worst = 0.0f64;
            for i in 0..=20_000 {
                let u = (i as f32 / 20_000.0).clamp(1e-7, 1.0 - 6e-8);
                let x = s.sample(u);
                assert!(x.is_finite() && x <= x_max as f32 + 1e-6, "cos {cos_t} u {u}: slope {x} beyond {x_max}");
                worst = worst.max((c(x as f64) / total - u as f64).abs());
            }
            assert!(worst < 1.5e-6, "cos {cos_t}: CDF error {worst:e}");
        }
    }

    /// Chi-square of sampled slopes against the exact CDF, 100 equal-probability bins, at
    /// every incidence.
    #[test]
    fn beckmann_slope_chi_square() {
        let level = crate::sampling::stats::sidak_alpha(0.01, COS_THETAS.len());
        let mut rng = crate::sampling::Pcg32::new(17, 3);
        for cos_t in COS_THETAS {
            let s = SlopeX::new(cos_t);
            let (c, x_max) = slope_cdf_ref(cos_t as f64);
            let total = c(x_max);
            // Bin edges: the reference inverse of the CDF at k/100 by bisection.
            let nb = 100;
            let edges: Vec<f64> = (1..nb)
                .map(|k| {
                    let t = k as f64 / nb as f64 * total;
                    let (mut lo, mut hi) = (-9.0, x_max);
                    for _ in 0..80 {
                        let m = 0.5 * (lo + hi);
                        if c(m) > t {
                            hi = m
                        } else {
                            lo = m
                        }
                    }
                    0.5 * (lo + hi)
                })
                .collect();
            let n = 200_000;
            let mut counts = vec![0.0f64; nb];
            for _ in 0..n {
                let x = s.sample(rng.next_f32()) as f64;
                counts[edges.partition_point(|&e| e < x)] += 1.0;
            }
            let expected = vec![n as f64 / nb as f64; nb];
            let r = crate::sampling::stats::chi_square_test(&counts, &expected, 5.0);
            assert!(r.p_value > level, "cos {cos_t}: chi2 {} p {:e}", r.statistic, r.p_value);
        }
    }

    /// Chi-square of `sample_visible` against `pdf_visible` over the hemisphere of normals
    /// (bins in cos θm and φm, expected counts by integrating the pdf over each bin), at
    /// normal to grazing incidence, for isotropic and anisotropic roughness.
    #[test]
    fn visible_normals_chi_square() {
        let (nc, np, sub) = (12usize, 24usize, 12usize);
        let cases: Vec<(MicrofacetKind, f32, f32, Vec3)> = [MicrofacetKind::Beckmann, MicrofacetKind::Ggx]
            .into_iter()
            .flat_map(|k| {
                [(0.6f32, 0.6f32), (1.0, 0.3)].into_iter().flat_map(move |(au, av)| {
                    [0.0f32, 45.0, 80.0, 89.0].into_iter().map(move |deg| {
                        let t = deg.to_radians();
                        (k, au, av, Vec3::new(t.sin() * 0.8, t.sin() * 0.6, t.cos()).normalize())
                    })
                })
            })
            .collect();
        let level = crate::sampling::stats::sidak_alpha(0.01, cases.len());
        let mut rng = crate::sampling::Pcg32::new(29, 5);
        for (kind, au, av, v) in cases {
            let md = Microfacet::new(kind, au, av);
            let bin = |m: Vec3| {
                let ci = ((m.z.clamp(0.0, 1.0) * nc as f32) as usize).min(nc - 1);
                let phi = m.y.atan2(m.x) + PI;
                let pi = ((phi / (2.0 * PI) * np as f32) as usize).min(np - 1);
                ci * np + pi
            };
            let mut expected = vec![0.0f64; nc * np];
            for ci in 0..nc {
                for pj in 0..np {
                    let mut acc = 0.0f64;
                    for a in 0..sub {
                        let z = (ci as f64 + (a as f64 + 0.5) / sub as f64) / nc as f64;
                        for b in 0..sub {
                            let phi = 2.0 * std::f64::consts::PI * (pj as f64 + (b as f64 + 0.5) / sub as f64) / np as f64 - std::f64::consts::PI;
                            let r = (1.0 - z * z).sqrt();
                            acc += md.pdf_visible(v, Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)) as f64;
                        }
                    }
                    expected[ci * np + pj] = acc * (2.0 * std::f64::consts::PI / (nc * np * sub * sub) as f64);
                }
            }
            let n = 200_000;
            let mass: f64 = expected.iter().sum();
            assert!((mass - 1.0).abs() < 1e-2, "{kind:?} {au} {av} {v}: pdf mass {mass}");
            // Bins the midpoint rule finds empty may still hold a sliver of the support
            // (v.m > 0 cuts them at grazing incidence): they join the pooled cell.
            let expected: Vec<f64> = expected.iter().map(|e| (e / mass * n as f64).max(1e-9)).collect();
            let mut counts = vec![0.0f64; nc * np];
            for _ in 0..n {
                let m = md.sample_visible(v, Vec2::new(rng.next_f32(), rng.next_f32()));
                assert!(m.is_finite() && (m.length() - 1.0).abs() < 1e-4 && m.dot(v) > -1e-4, "{kind:?} {au} {av} {v}: sampled {m}");
                counts[bin(m)] += 1.0;
            }
            let r = crate::sampling::stats::chi_square_test(&counts, &expected, 5.0);
            assert!(r.p_value > level, "{kind:?} {au} {av} {v}: chi2 {} dof {} p {:e}", r.statistic, r.dof, r.p_value);
        }
    }

    /// `sample_visible_beckmann_lanes` compiled as the path kernel's AVX2 build compiles it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn beckmann_lanes_avx2(q: &VisibleNormalLanes<8>) -> [[f32; 8]; 3] {
        sample_visible_beckmann_lanes(q)
    }

    /// `sample_visible_beckmann_lanes` (eight lanes, as the baseline build and as the AVX2 one
    /// compile it) gives `sample_visible`'s bits lane by lane: roughness from its floor to
    /// beyond 1, anisotropic, incidence from normal to grazing (and below), the numbers' ends.
    #[test]
    fn beckmann_lanes_are_the_single_samples() {
        let mut rng = crate::sampling::Pcg32::new(23, 7);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let alphas = [MIN_ALPHA, 1e-3, 0.01, 0.1, 0.3, 0.5, 1.0, 2.0];
        let us = [0.0f32, 1e-9, 1e-7, 0.5, 1.0 - 6e-8, 1.0 - f32::EPSILON, 1.0];
        let cos_ts = [1.0f32, 0.999_999, 0.5, 1e-2, 1e-4, 1e-6, 1e-8, 0.0, -0.1];
        let mut grazing = 0;
        for batch in 0..20_000usize {
            let mut q = VisibleNormalLanes::<8>::default();
            let mut lanes = [(Microfacet::new(MicrofacetKind::Beckmann, 1.0, 1.0), Vec3::Z, Vec2::ZERO); 8];
            for (l, lane) in lanes.iter_mut().enumerate() {
                let i = batch * 8 + l;
                let (au, av) = match i % 3 {
                    0 => (alphas[i / 3 % alphas.len()], alphas[i / 24 % alphas.len()]),
                    1 => (f(MIN_ALPHA, 1.0), f(MIN_ALPHA, 1.0)),
                    _ => {
                        let a = f(0.01, 1.0);
                        (a, a)
                    }
                };
                let md = Microfacet::new(MicrofacetKind::Beckmann, au, av);
                let cos_t = if i % 4 == 0 { cos_ts[i / 4 % cos_ts.len()] } else { f(0.0, 1.0) };
                let phi = if i % 5 == 0 { 0.0 } else { f(0.0, 2.0 * PI) };
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let v = Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
                grazing += (cos_t < 1e-3) as usize;
                let u = if i % 3 == 0 { Vec2::new(us[i % us.len()], us[i / 7 % us.len()]) } else { Vec2::new(f(0.0, 1.0), f(0.0, 1.0)) };
                (q.alpha[0][l], q.alpha[1][l]) = (md.alpha_u, md.alpha_v);
                (q.v[0][l], q.v[1][l], q.v[2][l]) = (v.x, v.y, v.z);
                (q.u[0][l], q.u[1][l]) = (u.x, u.y);
                *lane = (md, v, u);
            }
            let m = sample_visible_beckmann_lanes(&q);
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::avx2() {
                // SAFETY: the CPU has AVX2.
                let a = unsafe { beckmann_lanes_avx2(&q) };
                assert_eq!(a.map(|r| r.map(f32::to_bits)), m.map(|r| r.map(f32::to_bits)), "batch {batch}: the AVX2 build differs");
            }
            for (l, &(md, v, u)) in lanes.iter().enumerate() {
                let one = md.sample_visible(v, u);
                let lane = Vec3::new(m[0][l], m[1][l], m[2][l]);
                assert_eq!(lane.to_array().map(f32::to_bits), one.to_array().map(f32::to_bits), "{md:?} v {v} u {u}: {lane} and {one}");
            }
        }
        assert!(grazing > 10_000, "{grazing} grazing lanes");
    }

    /// Smith's Λ of Beckmann against its f64 closed form, incidence from normal to grazing.
    #[test]
    fn beckmann_lambda_accuracy() {
        let md = Microfacet::new(MicrofacetKind::Beckmann, 0.7, 0.7);
        for i in 1..2000 {
            let z = i as f32 / 2000.0;
            let v = Vec3::new((1.0 - z * z).sqrt(), 0.0, z);
            let a = z as f64 / (0.7 * (1.0 - (z as f64).powi(2)).sqrt());
            let exact = 0.5 * (-erfc64(a) + (-a * a).exp() / (a * std::f64::consts::PI.sqrt()));
            let g1 = 1.0 / (1.0 + md.lambda(v) as f64);
            let g1_exact = 1.0 / (1.0 + exact);
            assert!((g1 - g1_exact).abs() < 1e-6 && (md.lambda(v) as f64 - exact).abs() < 1e-6 * exact.max(1.0), "z {z}: Λ {} vs {exact}", md.lambda(v));
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
