//! Inlinable f32 approximations of transcendental functions for the samplers' inner loops
//! (libm's are out-of-line calls, and its f64 ones twice that). Each states its error bound
//! over its domain; the tests below check those bounds against f64 references.

// The coefficients are written as their sources give them (or with the digits of their f64
// fit); the f32 each literal rounds to is the one used.
#![allow(clippy::excessive_precision)]

use std::f32::consts::{LN_2, LOG2_E, SQRT_2};

/// 1.5 · 2²³: adding and subtracting it rounds an f32 below 2²² to the nearest integer
/// (SSE2 has no rounding instruction, and `f32::round` is a libm call there).
const ROUND_MAGIC: f32 = 12_582_912.0;

/// e^x, relative error below 1.5e-7 for x in (-87, 88]; exactly 0 for x <= -87 (where
/// e^x < 1.7e-38: the callers treat it as zero) and for NaN.
#[inline]
pub fn exp(x: f32) -> f32 {
    if x.is_nan() || x <= -87.0 {
        return 0.0;
    }
    let x = x.min(88.0);
    let t = x * LOG2_E + ROUND_MAGIC;
    let n = t - ROUND_MAGIC;
    // Cody-Waite reduction with ln 2 split in two: r in [-ln2/2, ln2/2] almost exactly.
    let r = (x - n * 0.693_145_751_953_125) - n * 1.428_606_765_330_187e-6;
    // Taylor to degree 7: truncation below 5e-9 on that interval.
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    // n in [-126, 127]: 2^n is a normal float. n is `t`'s low mantissa bits (t's ulp is 1),
    // read as an integer: `n as i32` saturates, which lanes of vector code ran one by one.
    let n_bits = t.to_bits().wrapping_sub(ROUND_MAGIC.to_bits());
    p * f32::from_bits(n_bits.wrapping_add(127) << 23)
}

/// ln x for x > 0, absolute error below 1.5e-7 · max(1, |ln x|); inputs below the smallest
/// normal float (zero, subnormals, NaN) are taken as that float (ln = -87.3).
#[inline]
pub fn ln(x: f32) -> f32 {
    let x = x.max(f32::MIN_POSITIVE);
    let bits = x.to_bits();
    let mut e = (bits >> 23) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    // ln m = 2 atanh(s), s = (m - 1) / (m + 1), |s| <= 0.172: its series to s⁹ is exact
    // to 1e-9.
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let lm = 2.0 * s * (1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0)))));
    e as f32 * LN_2 + lm
}

/// erfc(z) for z >= 0 given `e` = e^{-z²} (which callers usually need too): Abramowitz and
/// Stegun 7.1.26, erfc(z) = t P(t) e^{-z²} with t = 1 / (1 + p z). Absolute error below
/// 6e-7 in f32 (the fit's own is 1.5e-7); the relative error grows in the far tail, so use
/// it where absolute accuracy is what counts (CDFs normalised to about 1).
#[inline]
pub fn erfc_nonneg(z: f32, e: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    t * (0.254_829_592 + t * (-0.284_496_736 + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429)))) * e
}

/// Inverse error function on (-1, 1) (arguments are clamped to the floats inside):
/// Giles' single-precision fit (2010) over [`ln`]. erf of the result is within 2e-7 of `x`.
#[inline]
pub fn erfinv(x: f32) -> f32 {
    let x = x.clamp(-0.999_999_94, 0.999_999_94);
    let w = -ln((1.0 - x) * (1.0 + x));
    let p = if w < 5.0 {
        let w = w - 2.5;
        let mut p = 2.810_226_36e-8f32;
        for c in [3.432_739_39e-7, -3.523_387_7e-6, -4.391_506_54e-6, 2.185_808_7e-4, -1.253_725_03e-3, -4.177_681_64e-3, 0.246_640_727, 1.501_409_41] {
            p = c + p * w;
        }
        p
    } else {
        let w = w.sqrt() - 3.0;
        let mut p = -2.002_142_57e-4f32;
        for c in [1.009_505_58e-4, 1.349_343_22e-3, -3.673_428_44e-3, 5.739_507_73e-3, -7.622_461_3e-3, 9.438_870_47e-3, 1.001_674_06, 2.832_976_82] {
            p = c + p * w;
        }
        p
    };
    p * x
}

/// [`erfinv`] bit for bit, both of its fits computed and one selected: a loop of it over
/// SIMD lanes vectorises (the path kernel's Beckmann samples).
#[inline(always)]
pub fn erfinv_branchless(x: f32) -> f32 {
    let x = x.clamp(-0.999_999_94, 0.999_999_94);
    let w = -ln((1.0 - x) * (1.0 + x));
    let wc = w - 2.5;
    let mut pc = 2.810_226_36e-8f32;
    for c in [3.432_739_39e-7, -3.523_387_7e-6, -4.391_506_54e-6, 2.185_808_7e-4, -1.253_725_03e-3, -4.177_681_64e-3, 0.246_640_727, 1.501_409_41] {
        pc = c + pc * wc;
    }
    // Where `erfinv` takes the central fit, w may be a rounding below 0 (a NaN root, not used).
    let wt = w.sqrt() - 3.0;
    let mut pt = -2.002_142_57e-4f32;
    for c in [1.009_505_58e-4, 1.349_343_22e-3, -3.673_428_44e-3, 5.739_507_73e-3, -7.622_461_3e-3, 9.438_870_47e-3, 1.001_674_06, 2.832_976_82] {
        pt = c + pt * wt;
    }
    let p = if w < 5.0 { pc } else { pt };
    p * x
}

/// atan2(y, x) in [-π, π], absolute error below 3e-7 (0 where x = y = 0). The ratio of the
/// smaller to the larger magnitude is reduced below tan(π/8) (by atan t = π/4 +
/// atan((t - 1)/(t + 1)) above it), where a degree-9 odd polynomial fitted for this module
/// has relative error 2e-9; one division in all.
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (hi, lo) = (ax.max(ay), ax.min(ay));
    // Both zero, or a NaN (which max/min pass on only when both are NaN).
    if hi.is_nan() || hi <= 0.0 {
        return 0.0;
    }
    let big = lo > 0.414_213_57 * hi;
    let r = if big { (lo - hi) / (lo + hi) } else { lo / hi };
    let z = r * r;
    let p = -0.333_333_18 + z * (0.199_986_69 + z * (-0.142_474_49 + z * (0.106_237_66 - 0.061_561_62 * z)));
    let mut a = r + r * z * p;
    if big {
        a += std::f32::consts::FRAC_PI_4;
    }
    if ay > ax {
        a = std::f32::consts::FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = std::f32::consts::PI - a;
    }
    a.copysign(y)
}

/// [`atan2`] bit for bit, with selects in place of its branches: a loop of it over SIMD lanes
/// vectorises (the environment map's lookups of the path kernel's eight lanes).
#[inline(always)]
pub fn atan2_branchless(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (hi, lo) = (ax.max(ay), ax.min(ay));
    let none = hi.is_nan() || hi <= 0.0;
    let big = lo > 0.414_213_57 * hi;
    // The operands of `atan2`'s division on either branch, then that one division.
    let (num, den) = if big { (lo - hi, lo + hi) } else { (lo, hi) };
    let r = num / den;
    let z = r * r;
    let p = -0.333_333_18 + z * (0.199_986_69 + z * (-0.142_474_49 + z * (0.106_237_66 - 0.061_561_62 * z)));
    let a = r + r * z * p;
    let a = if big { a + std::f32::consts::FRAC_PI_4 } else { a };
    let a = if ay > ax { std::f32::consts::FRAC_PI_2 - a } else { a };
    let a = if x < 0.0 { std::f32::consts::PI - a } else { a };
    if none {
        0.0
    } else {
        a.copysign(y)
    }
}

/// acos x for x in [0, 1], absolute error below 7e-5 (Abramowitz and Stegun 4.4.45): for
/// initial guesses, not for results.
#[inline]
pub fn acos_nonneg_coarse(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    (1.0 - x).sqrt() * (1.570_728_8 + x * (-0.212_114_4 + x * (0.074_261_0 - 0.018_729_3 * x)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::stats::erfc as erfc64;

    #[test]
    fn exp_relative_error() {
        let mut worst = 0.0f64;
        for i in 0..=400_000 {
            let x = (-86.99 + 174.99 * i as f32 / 400_000.0).min(88.0);
            let r = (x as f64).exp();
            worst = worst.max(((exp(x) as f64 - r) / r).abs());
        }
        assert!(worst < 1.5e-7, "exp: relative error {worst:e}");
        assert_eq!(exp(-87.0), 0.0);
        assert_eq!(exp(-1e30), 0.0);
        assert_eq!(exp(f32::NAN), 0.0);
        assert_eq!(exp(0.0), 1.0);
    }

    /// `exp`'s power of two from the rounding sum's bits is the float-to-int conversion it
    /// replaced, on every float of (-87, 88] and beyond (infinities, NaN).
    #[test]
    fn exp_scale_bits_are_the_conversion() {
        let old = |x: f32| {
            if x.is_nan() || x <= -87.0 {
                return 0.0;
            }
            let x = x.min(88.0);
            let n = (x * LOG2_E + ROUND_MAGIC) - ROUND_MAGIC;
            let r = (x - n * 0.693_145_751_953_125) - n * 1.428_606_765_330_187e-6;
            let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
            p * f32::from_bits(((n as i32 + 127) as u32) << 23)
        };
        let mut checked = 0u32;
        for bits in (0..=u32::MAX).step_by(11) {
            let x = f32::from_bits(bits);
            if x > -90.0 && x < 90.0 || bits % 999 == 0 {
                assert_eq!(exp(x).to_bits(), old(x).to_bits(), "exp({x:e})");
                checked += 1;
            }
        }
        assert!(checked > 100_000_000);
        for x in [f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 88.0, -87.0, f32::MAX, f32::MIN] {
            assert_eq!(exp(x).to_bits(), old(x).to_bits(), "exp({x:e})");
        }
    }

    #[test]
    fn ln_error() {
        let mut worst = 0.0f64;
        for i in 1..=400_000 {
            // Geometric sweep over [1e-30, 1e30], and a dense one around 1.
            for x in [(1e-30f64 * 1e60f64.powf(i as f64 / 400_000.0)) as f32, 0.5 + i as f32 / 400_000.0] {
                let r = (x as f64).ln();
                worst = worst.max((ln(x) as f64 - r).abs() / r.abs().max(1.0));
            }
        }
        assert!(worst < 1.5e-7, "ln: error {worst:e}");
        assert_eq!(ln(1.0), 0.0);
    }

    #[test]
    fn erfc_absolute_error() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let z = 10.0 * i as f32 / 200_000.0;
            worst = worst.max((erfc_nonneg(z, exp(-z * z)) as f64 - erfc64(z as f64)).abs());
        }
        assert!(worst < 6e-7, "erfc: absolute error {worst:e}");
    }

    #[test]
    fn erfinv_inverts_erf() {
        let mut worst = 0.0f64;
        for i in 1..400_000 {
            let x = -1.0 + 2.0 * i as f32 / 400_000.0;
            let y = erfinv(x) as f64;
            worst = worst.max((1.0 - erfc64(y) - x as f64).abs());
        }
        // Close to ±1 as well: the smallest and largest floats inside.
        for x in [0.999_999_94f32, -0.999_999_94, 1.0 - 1e-6, 1e-30, 0.0] {
            let y = erfinv(x) as f64;
            worst = worst.max((1.0 - erfc64(y) - x as f64).abs());
        }
        assert!(worst < 2e-7, "erfinv: erf(erfinv(x)) - x up to {worst:e}");
        assert_eq!(erfinv(0.0), 0.0);
        assert_eq!(erfinv(0.3), -erfinv(-0.3));
    }

    #[test]
    fn atan2_absolute_error() {
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let t = -3.2 + 6.4 * i as f64 / 200_000.0;
            for r in [1.0f64, 1e-3, 37.0] {
                let (y, x) = ((r * t.sin()) as f32, (r * t.cos()) as f32);
                worst = worst.max((atan2(y, x) as f64 - (y as f64).atan2(x as f64)).abs());
            }
        }
        assert!(worst < 3e-7, "atan2: {worst:e}");
        assert_eq!(atan2(0.0, 0.0), 0.0);
        assert_eq!(atan2(0.0, 1.0), 0.0);
        assert!((atan2(0.0, -1.0) - std::f32::consts::PI).abs() < 1e-7);
        assert!((atan2(-1.0, 0.0) + std::f32::consts::FRAC_PI_2).abs() < 1e-7);
    }

    #[test]
    fn atan2_branchless_is_atan2() {
        let mut rng = crate::sampling::Pcg32::new(7, 1);
        let special = [0.0, -0.0, 1.0, -1.0, 0.414_213_57, -2.5e-39, 1e-45, 3e38, f32::INFINITY, f32::NEG_INFINITY, f32::NAN];
        let mut pairs: Vec<(f32, f32)> = special.iter().flat_map(|&y| special.iter().map(move |&x| (y, x))).collect();
        for _ in 0..200_000 {
            // Signs, magnitudes over many octaves, and ratios near the reduction's bounds.
            let (a, b) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
            let e = (rng.next_f32() * 40.0 - 20.0).exp2();
            pairs.push((a * e, b));
            pairs.push((a, a * (0.414_213_57 + (b - 0.5) * 1e-6)));
        }
        for (y, x) in pairs {
            let (s, b) = (atan2(y, x), atan2_branchless(y, x));
            assert!(s.to_bits() == b.to_bits(), "atan2({y:e}, {x:e}): {s:e} and {b:e}");
        }
    }

    #[test]
    fn erfinv_branchless_is_erfinv() {
        let mut rng = crate::sampling::Pcg32::new(7, 2);
        let mut xs = vec![0.0, -0.0, 1.0, -1.0, 0.999_999_94, -0.999_999_94, 2.0, -3.0, 1e-30, f32::INFINITY, f32::NEG_INFINITY, f32::NAN];
        for _ in 0..300_000 {
            // Uniform, near ±1 (the tail fit, and the fits' switch at w = 5), and near 0.
            let a = rng.next_f32() * 2.0 - 1.0;
            xs.push(a);
            xs.push(a.signum() * (1.0 - (rng.next_f32() * 24.0).exp2().recip()));
            xs.push(a * 1e-6);
        }
        for x in xs {
            let (s, b) = (erfinv(x), erfinv_branchless(x));
            assert!(s.to_bits() == b.to_bits(), "erfinv({x:e}): {s:e} and {b:e}");
        }
    }

    #[test]
    fn coarse_acos() {
        let worst = (0..=100_000).map(|i| i as f32 / 100_000.0).map(|x| (acos_nonneg_coarse(x) as f64 - (x as f64).acos()).abs()).fold(0.0, f64::max);
        assert!(worst < 7e-5, "acos: {worst:e}");
    }
}
