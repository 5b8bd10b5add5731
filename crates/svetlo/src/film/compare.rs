//! Comparing a render with a reference: relative MSE, and Mitsuba 3's per-pixel Z-test
//! (the test its own render suite uses, see scenes/README.md in the shared folder).
//!
//! The Z-test asks, for every pixel channel, whether the render's mean `x` over `n` samples
//! could come from a distribution with the reference's mean `r` and per-sample variance `v`:
//! `z = |x - r| sqrt(n / v)`, two-sided p-value `p = 2 (1 - Phi(z))`. Each channel is tested at
//! the Šidák-corrected level `alpha = 1 - (1 - 0.01)^(1 / pixels)`, and the image passes when
//! at least 99.75 % of the channels have `p > alpha`. As in Mitsuba, everything is converted
//! to CIE XYZ first (the references' variances were computed in XYZ), and the variance is
//! clamped to at least 1e-4.

use crate::error::{Error, Result};
use crate::film::Image;
use crate::sampling::stats::{sidak_alpha, two_sided_p};
use crate::spectrum::Rgb;

/// Family-wise significance level of Mitsuba's render test.
pub const SIGNIFICANCE: f64 = 0.01;
/// Fraction of pixel channels that must pass for the image to pass.
pub const MIN_PASS_FRACTION: f64 = 0.9975;
/// Lower bound on the reference's per-sample variance (Mitsuba's sanitisation).
pub const MIN_VARIANCE: f32 = 1e-4;

fn check_size(a: &Image, b: &Image, what_a: &str, what_b: &str) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        return Err(Error::Invalid(format!("{what_a} is {}x{} but {what_b} is {}x{}", a.width, a.height, b.width, b.height)));
    }
    if a.data.is_empty() {
        return Err(Error::Invalid(format!("{what_a} is empty")));
    }
    Ok(())
}

/// Mean over pixels and RGB channels of `(x - r)^2 / (r^2 + 0.01)`.
pub fn rel_mse(img: &Image, reference: &Image) -> Result<f64> {
    check_size(img, reference, "the image", "the reference")?;
    let mut sum = 0.0f64;
    for (x, r) in img.data.iter().zip(&reference.data) {
        for k in 0..3 {
            let (x, r) = (x[k] as f64, r[k] as f64);
            sum += (x - r) * (x - r) / (r * r + 0.01);
        }
    }
    Ok(sum / (3 * img.data.len()) as f64)
}

/// The outcome of [`z_test`].
#[derive(Clone, Debug)]
pub struct ZTest {
    pub pass: bool,
    /// Fraction of pixel channels (XYZ) whose p-value exceeds `alpha`.
    pub fraction_passing: f64,
    /// Pixel channels tested and failing.
    pub channels: usize,
    pub failed: usize,
    /// Per-channel significance level (Šidák over the pixel count).
    pub alpha: f64,
    /// Smallest p-value over all channels.
    pub min_p: f64,
    /// Relative MSE in RGB, as [`rel_mse`].
    pub relmse: f64,
    pub mean_image: Rgb,
    pub mean_reference: Rgb,
    pub spp: u32,
}

/// Per pixel channel (XYZ, pixel-major) p-values of the render `img` (mean of `spp` samples)
/// against `reference` with per-sample variance `variance` (all linear RGB).
pub fn z_test_p_values(img: &Image, reference: &Image, variance: &Image, spp: u32) -> Result<Vec<f64>> {
    check_size(img, reference, "the image", "the reference")?;
    check_size(variance, reference, "the variance image", "the reference")?;
    if spp == 0 {
        return Err(Error::Settings("the Z-test needs the image's spp (at least 1)".into()));
    }
    let n = spp as f64;
    let mut p = Vec::with_capacity(3 * img.data.len());
    for ((x, r), v) in img.data.iter().zip(&reference.data).zip(&variance.data) {
        let (x, r, v) = (x.to_xyz(), r.to_xyz(), v.to_xyz());
        for k in 0..3 {
            let var = v[k].max(MIN_VARIANCE) as f64;
            let z = (x[k] as f64 - r[k] as f64).abs() * (n / var).sqrt();
            // A NaN in the render gives p = NaN, which fails below.
            p.push(two_sided_p(z));
        }
    }
    Ok(p)
}

/// Mitsuba's render test with its own levels ([`SIGNIFICANCE`], [`MIN_PASS_FRACTION`]).
pub fn z_test(img: &Image, reference: &Image, variance: &Image, spp: u32) -> Result<ZTest> {
    z_test_with(img, reference, variance, spp, SIGNIFICANCE, MIN_PASS_FRACTION)
}

/// The Z-test with a chosen family-wise `significance` and required passing fraction.
/// The Šidák correction counts pixels, as Mitsuba's test does (not pixel channels).
pub fn z_test_with(img: &Image, reference: &Image, variance: &Image, spp: u32, significance: f64, min_fraction: f64) -> Result<ZTest> {
    let p = z_test_p_values(img, reference, variance, spp)?;
    let alpha = sidak_alpha(significance, img.data.len());
    let passed = p.iter().filter(|&&p| p > alpha).count();
    let fraction_passing = passed as f64 / p.len() as f64;
    let min_p = p.iter().copied().fold(f64::INFINITY, |a, b| if b.is_nan() { a } else { a.min(b) });
    Ok(ZTest {
        pass: fraction_passing >= min_fraction,
        fraction_passing,
        channels: p.len(),
        failed: p.len() - passed,
        alpha,
        min_p,
        relmse: rel_mse(img, reference)?,
        mean_image: img.mean(),
        mean_reference: reference.mean(),
        spp,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    /// RGB -> XYZ matrix (columns from `Rgb::to_xyz`) and its inverse.
    fn xyz_to_rgb(c: [f32; 3]) -> Rgb {
        let cols = [Rgb::new(1.0, 0.0, 0.0).to_xyz(), Rgb::new(0.0, 1.0, 0.0).to_xyz(), Rgb::new(0.0, 0.0, 1.0).to_xyz()];
        let m = glam::DMat3::from_cols(
            glam::DVec3::new(cols[0][0] as f64, cols[0][1] as f64, cols[0][2] as f64),
            glam::DVec3::new(cols[1][0] as f64, cols[1][1] as f64, cols[1][2] as f64),
            glam::DVec3::new(cols[2][0] as f64, cols[2][1] as f64, cols[2][2] as f64),
        );
        let v = m.inverse() * glam::DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
        Rgb::new(v.x as f32, v.y as f32, v.z as f32)
    }

    fn normal(rng: &mut Pcg32) -> f64 {
        // Box-Muller; 1 - u keeps the log finite.
        let (u1, u2) = (1.0 - rng.next_f64(), rng.next_f64());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }

    /// A reference, its per-sample variance (defined in XYZ, stored in RGB as Mitsuba does, so
    /// possibly negative there) and a render of `spp` samples drawn from N(r, v/spp) in XYZ,
    /// with its mean shifted by `bias` (relative).
    fn synthetic(w: usize, h: usize, spp: u32, bias: f64, seed: u64) -> (Image, Image, Image) {
        let mut rng = Pcg32::new(seed, 7);
        let (mut img, mut reference, mut var) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..w * h {
            let r: [f64; 3] = std::array::from_fn(|_| 0.5 + 1.5 * rng.next_f64());
            let v: [f64; 3] = std::array::from_fn(|_| 0.01 + rng.next_f64());
            let x: [f64; 3] = std::array::from_fn(|k| r[k] * (1.0 + bias) + (v[k] / spp as f64).sqrt() * normal(&mut rng));
            reference.push(xyz_to_rgb(r.map(|c| c as f32)));
            var.push(xyz_to_rgb(v.map(|c| c as f32)));
            img.push(xyz_to_rgb(x.map(|c| c as f32)));
        }
        (Image::new(w, h, img), Image::new(w, h, reference), Image::new(w, h, var))
    }

    #[test]
    fn identical_images_pass() {
        let (_, r, v) = synthetic(16, 8, 4, 0.0, 1);
        let t = z_test(&r, &r, &v, 4).unwrap();
        assert!(t.pass);
        assert_eq!(t.failed, 0);
        assert_eq!(t.fraction_passing, 1.0);
        assert_eq!(t.relmse, 0.0);
        assert_eq!(t.channels, 16 * 8 * 3);
    }

    #[test]
    fn biased_image_fails() {
        // Means 10 % high at 256 spp: the shift is z = 0.1 r sqrt(256 / v) = 1.6 r / sqrt(v),
        // between 0.8 and 32 here, beyond the threshold (~4.4) for a good share of channels.
        let (x, r, v) = synthetic(32, 32, 256, 0.1, 2);
        let t = z_test(&x, &r, &v, 256).unwrap();
        assert!(!t.pass, "fraction passing {}", t.fraction_passing);
        assert!(t.fraction_passing < 0.9);
        // A straight scaling of the reference with a tiny variance fails everywhere.
        let scaled = Image::new(r.width, r.height, r.data.iter().map(|c| *c * 1.1).collect());
        let small = Image::filled(r.width, r.height, Rgb::splat(1e-4));
        let t = z_test(&scaled, &r, &small, 16).unwrap();
        assert!(!t.pass);
        assert_eq!(t.failed, t.channels);
    }

    #[test]
    fn unbiased_noisy_images_pass_at_the_advertised_rate() {
        // 20 independent renders: under the null hypothesis each fails with probability far
        // below 1e-9 (more than 0.25 % of 3072 channels at alpha ~ 1e-5), so all must pass.
        for seed in 0..20 {
            let (x, r, v) = synthetic(32, 32, 16, 0.0, 100 + seed);
            let t = z_test(&x, &r, &v, 16).unwrap();
            assert!(t.pass, "seed {seed}: fraction {} min p {}", t.fraction_passing, t.min_p);
        }
        // The p-values are uniform under the null: the share below 0.05 is 0.05 within
        // 5 standard deviations (false alarm ~ 6e-7), and a 10-bin chi-square (9 dof) stays
        // below 33.7 (p = 1e-4).
        let (x, r, v) = synthetic(64, 64, 16, 0.0, 5);
        let p = z_test_p_values(&x, &r, &v, 16).unwrap();
        let n = p.len() as f64;
        let below = p.iter().filter(|&&p| p < 0.05).count() as f64 / n;
        let sigma = (0.05f64 * 0.95 / n).sqrt();
        assert!((below - 0.05).abs() < 5.0 * sigma, "share below 0.05: {below}");
        let mut bins = [0usize; 10];
        for &p in &p {
            bins[((p * 10.0) as usize).min(9)] += 1;
        }
        let e = n / 10.0;
        let chi2: f64 = bins.iter().map(|&o| (o as f64 - e).powi(2) / e).sum();
        assert!(chi2 < 33.7, "chi2 {chi2}, bins {bins:?}");
    }

    #[test]
    fn rel_mse_matches_definition() {
        let r = Image::new(2, 1, vec![Rgb::new(0.0, 1.0, 2.0), Rgb::splat(0.1)]);
        let x = Image::new(2, 1, r.data.iter().map(|c| *c + 0.1).collect());
        let want = [0.0f64, 1.0, 2.0, 0.1, 0.1, 0.1].iter().map(|r| 0.01 / (r * r + 0.01)).sum::<f64>() / 6.0;
        assert!((rel_mse(&x, &r).unwrap() - want).abs() < 1e-6);
    }

    #[test]
    fn size_mismatch_and_zero_spp_are_errors() {
        let a = Image::filled(4, 4, Rgb::WHITE);
        let b = Image::filled(4, 3, Rgb::WHITE);
        assert!(rel_mse(&a, &b).is_err());
        assert!(z_test(&a, &a, &b, 4).is_err());
        assert!(z_test(&a, &b, &a, 4).is_err());
        assert!(z_test(&a, &a, &a, 0).is_err());
        let msg = rel_mse(&a, &b).unwrap_err().to_string();
        assert!(msg.contains("4x4") && msg.contains("4x3"), "{msg}");
    }

    #[test]
    fn nan_pixels_fail() {
        let r = Image::filled(4, 4, Rgb::splat(0.5));
        let v = Image::filled(4, 4, Rgb::splat(0.1));
        let mut x = r.clone();
        x.data[3] = Rgb::new(f32::NAN, 0.5, 0.5);
        let t = z_test(&x, &r, &v, 4).unwrap();
        assert_eq!(t.failed, 3, "a NaN in R spreads to X, Y and Z");
    }
}
