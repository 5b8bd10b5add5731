//! Shared test helpers. Here: reusable statistical test machinery for BSDFs (and any direction sampler with a pdf):
//! chi-square goodness of fit of samples against the pdf integrated over bins of the
//! sphere, agreement of `sample` with `eval`/`pdf`, reciprocity and white-furnace albedo.
#![allow(dead_code)]

pub mod lpe;
pub mod scenes;

use glam::{Vec2, Vec3};
use svetlo::bsdf::{Bsdf, BsdfModel, BsdfSample, TransportMode};
use svetlo::sampling::stats::chi2_sf;
use svetlo::sampling::Pcg32;
use svetlo::Rgb;

/// What the chi-square test needs of a scattering function: a model, or a whole `Bsdf` with
/// its wrappers (sides, mask, surface detail).
pub trait Scatter {
    fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample>;
    fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32;
    fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb;
}

impl Scatter for BsdfModel {
    fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        BsdfModel::sample(self, wo, uc, u, mode)
    }
    fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        BsdfModel::pdf(self, wo, wi, mode)
    }
    fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        BsdfModel::eval(self, wo, wi, mode)
    }
}

impl Scatter for Bsdf {
    fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        Bsdf::sample(self, wo, uc, u, mode)
    }
    fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        Bsdf::pdf(self, wo, wi, mode)
    }
    fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        Bsdf::eval(self, wo, wi, mode)
    }
}

pub const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Unit direction from (cos theta, phi).
pub fn dir(cos_t: f64, phi: f64) -> Vec3 {
    let s = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, cos_t as f32)
}

/// A direction at polar angle `theta_deg` from +z (negative cos for `back`), azimuth `phi_deg`.
pub fn dir_deg(theta_deg: f64, phi_deg: f64) -> Vec3 {
    dir(theta_deg.to_radians().cos(), phi_deg.to_radians())
}

/// Binning of the sphere in (cos theta, phi): cells of equal solid angle.
#[derive(Clone, Copy, Debug)]
pub struct SphereBins {
    pub n_cos: usize,
    pub n_phi: usize,
}

impl SphereBins {
    pub fn count(&self) -> usize {
        self.n_cos * self.n_phi
    }
    pub fn index(&self, w: Vec3) -> usize {
        let c = ((w.z as f64 + 1.0) * 0.5 * self.n_cos as f64).floor().clamp(0.0, (self.n_cos - 1) as f64) as usize;
        let mut phi = (w.y as f64).atan2(w.x as f64);
        if phi < 0.0 {
            phi += TWO_PI;
        }
        let p = (phi / TWO_PI * self.n_phi as f64).floor().clamp(0.0, (self.n_phi - 1) as f64) as usize;
        c * self.n_phi + p
    }
    /// The bin's rectangle [c0, c1] x [p0, p1] in (cos theta, phi).
    pub fn rect(&self, i: usize) -> [f64; 4] {
        let (c, p) = (i / self.n_phi, i % self.n_phi);
        let dc = 2.0 / self.n_cos as f64;
        let dp = TWO_PI / self.n_phi as f64;
        [-1.0 + c as f64 * dc, -1.0 + (c + 1) as f64 * dc, p as f64 * dp, (p + 1) as f64 * dp]
    }
}

/// 4-point Gauss-Legendre rule on [-1, 1].
const GL4: [(f64, f64); 4] = [
    (-0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
    (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
];

fn gl_rect(f: &impl Fn(f64, f64) -> f64, r: [f64; 4]) -> f64 {
    let (hc, mc) = (0.5 * (r[1] - r[0]), 0.5 * (r[1] + r[0]));
    let (hp, mp) = (0.5 * (r[3] - r[2]), 0.5 * (r[3] + r[2]));
    let mut s = 0.0;
    for &(x, wx) in &GL4 {
        for &(y, wy) in &GL4 {
            s += wx * wy * f(mc + hc * x, mp + hp * y);
        }
    }
    s * hc * hp
}

fn split4(r: [f64; 4]) -> [[f64; 4]; 4] {
    let (mc, mp) = (0.5 * (r[0] + r[1]), 0.5 * (r[2] + r[3]));
    [[r[0], mc, r[2], mp], [mc, r[1], r[2], mp], [r[0], mc, mp, r[3]], [mc, r[1], mp, r[3]]]
}

/// Adaptive quadrature over a rectangle: refine where the 4-children estimate disagrees
/// with the parent's. At least `min_depth` levels are forced so that narrow lobes inside a
/// bin are seen by some node.
fn adapt(f: &impl Fn(f64, f64) -> f64, r: [f64; 4], whole: f64, tol: f64, depth: u32) -> f64 {
    const MIN_DEPTH: u32 = 2;
    const MAX_DEPTH: u32 = 11;
    let kids = split4(r);
    let est: Vec<f64> = kids.iter().map(|&k| gl_rect(f, k)).collect();
    let sum: f64 = est.iter().sum();
    if depth >= MAX_DEPTH || (depth >= MIN_DEPTH && (sum - whole).abs() <= tol) {
        return sum;
    }
    kids.iter().zip(&est).map(|(&k, &e)| adapt(f, k, e, tol * 0.5, depth + 1)).sum()
}

/// ∫ over the bin's rectangle of f(cos theta, phi) d(cos theta) d(phi) (= solid angle).
pub fn integrate_bin(f: &impl Fn(f64, f64) -> f64, r: [f64; 4], tol: f64) -> f64 {
    let whole = gl_rect(f, r);
    adapt(f, r, whole, tol, 0)
}

#[derive(Debug, Clone)]
pub struct Chi2Outcome {
    pub p_value: f64,
    pub stat: f64,
    pub dof: usize,
    /// Non-delta samples whose returned `pdf`/`f` disagree with `pdf()`/`eval()`.
    pub mismatches: usize,
    pub first_mismatch: Option<String>,
    /// Samples in bins whose expected count is zero (a sample where pdf = 0).
    pub impossible: usize,
    /// ∫ pdf over the sphere: the continuous part's mass.
    pub pdf_mass: f64,
}

/// Goodness of fit of `model.sample(wo, ..)` against `model.pdf(wo, ..)`.
///
/// Continuous samples are histogrammed on `bins`; the expected count of a bin is
/// `n * ∫_bin pdf`. Delta-lobe samples and failed samples go to one extra cell whose
/// expected count is `n * (1 - ∫ pdf)`: the mass the pdf does not account for. Cells
/// expecting fewer than 5 samples are pooled (smallest first) before the statistic is formed.
pub fn chi2_test(model: &impl Scatter, wo: Vec3, mode: TransportMode, bins: SphereBins, n: usize, seed: u64) -> Chi2Outcome {
    let mut rng = Pcg32::new(seed, 0x5eed);
    let nb = bins.count();
    let mut observed = vec![0f64; nb + 1];
    let mut mismatches = 0;
    let mut first_mismatch = None;
    for _ in 0..n {
        let uc = rng.next_f32();
        let u = Vec2::new(rng.next_f32(), rng.next_f32());
        match model.sample(wo, uc, u, mode) {
            Some(s) if !s.lobe.is_specular() => {
                observed[bins.index(s.wi)] += 1.0;
                let p = model.pdf(wo, s.wi, mode);
                let f = model.eval(wo, s.wi, mode);
                let close = |a: f32, b: f32| (a - b).abs() <= 1e-3 * a.abs().max(b.abs()) + 1e-6;
                let ok = close(s.pdf, p) && close(s.f.r, f.r) && close(s.f.g, f.g) && close(s.f.b, f.b);
                if !ok {
                    mismatches += 1;
                    if first_mismatch.is_none() {
                        first_mismatch = Some(format!("wi {:?}: sample f {:?} pdf {} vs eval {:?} pdf {}", s.wi, s.f, s.pdf, f, p));
                    }
                }
            }
            _ => observed[nb] += 1.0,
        }
    }
    let pdf = |c: f64, phi: f64| model.pdf(wo, dir(c, phi), mode) as f64;
    let mut expected: Vec<f64> = (0..nb).map(|i| n as f64 * integrate_bin(&pdf, bins.rect(i), 1e-7)).collect();
    let mass: f64 = expected.iter().sum::<f64>() / n as f64;
    expected.push((n as f64 * (1.0 - mass)).max(0.0));

    // Pool cells with small expectation, smallest first, until each pool expects >= 5.
    let mut order: Vec<usize> = (0..=nb).collect();
    order.sort_by(|&a, &b| expected[a].partial_cmp(&expected[b]).unwrap());
    let mut cells: Vec<(f64, f64)> = Vec::new();
    let (mut pe, mut po) = (0.0, 0.0);
    let mut impossible = 0usize;
    for &i in &order {
        if expected[i] == 0.0 && observed[i] > 0.0 && i < nb {
            impossible += observed[i] as usize;
        }
        pe += expected[i];
        po += observed[i];
        if pe >= 5.0 {
            cells.push((po, pe));
            pe = 0.0;
            po = 0.0;
        }
    }
    if pe > 0.0 || po > 0.0 {
        match cells.last_mut() {
            Some(last) => {
                last.0 += po;
                last.1 += pe;
            }
            None => cells.push((po, pe)),
        }
    }
    let stat: f64 = cells
        .iter()
        .map(|&(o, e)| {
            if e > 0.0 {
                (o - e) * (o - e) / e
            } else if o > 0.0 {
                f64::INFINITY
            } else {
                0.0
            }
        })
        .sum();
    let dof = cells.len().saturating_sub(1).max(1);
    let p_value = if stat.is_finite() { chi2_sf(stat, dof as f64) } else { 0.0 };
    Chi2Outcome { p_value, stat, dof, mismatches, first_mismatch, impossible, pdf_mass: mass }
}

/// Monte Carlo estimate of the directional albedo ∫ f |cos| dwi from the sampler's
/// weights, with its standard error.
pub fn albedo(model: &BsdfModel, wo: Vec3, mode: TransportMode, n: usize, seed: u64) -> ([f64; 3], [f64; 3]) {
    let mut rng = Pcg32::new(seed, 0xa1bed0);
    let mut s = [0f64; 3];
    let mut s2 = [0f64; 3];
    for _ in 0..n {
        let uc = rng.next_f32();
        let u = Vec2::new(rng.next_f32(), rng.next_f32());
        if let Some(smp) = model.sample(wo, uc, u, mode) {
            let w = smp.weight();
            for (c, v) in [w.r, w.g, w.b].into_iter().enumerate() {
                s[c] += v as f64;
                s2[c] += (v as f64) * (v as f64);
            }
        }
    }
    let nf = n as f64;
    let mean = s.map(|x| x / nf);
    let mut se = [0f64; 3];
    for c in 0..3 {
        se[c] = ((s2[c] / nf - mean[c] * mean[c]).max(0.0) / (nf - 1.0)).sqrt();
    }
    (mean, se)
}

/// Uniformly distributed direction on the sphere.
pub fn uniform_dir(rng: &mut Pcg32) -> Vec3 {
    let z = 1.0 - 2.0 * rng.next_f64();
    dir(z, TWO_PI * rng.next_f64())
}
