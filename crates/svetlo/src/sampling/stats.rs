//! Statistics for the tests of samplers and for comparing renders with references: the
//! chi-square distribution's tail (p-values), the normal distribution's CDF, tail and
//! inverse tail, a chi-square goodness-of-fit test that pools sparse cells, and Šidák's
//! correction for families of tests. Everything in f64: the tails we ask for are small.
//! This is the project's one home for these functions; tests use them from here too.

use std::f64::consts::PI;

/// ln Γ(x) for x > 0 (Lanczos approximation, g = 7, 9 terms; about 15 significant digits).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 - x) = π / sin(π x).
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularized lower incomplete gamma P(a, x) = γ(a, x) / Γ(a).
pub fn gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x < a + 1.0 {
        gamma_series(a, x)
    } else {
        1.0 - gamma_cf(a, x)
    }
}

/// Regularized upper incomplete gamma Q(a, x) = 1 - P(a, x), accurate in the far tail.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    if x < a + 1.0 {
        1.0 - gamma_series(a, x)
    } else {
        gamma_cf(a, x)
    }
}

/// P(a, x) by its power series (converges fast for x < a + 1).
fn gamma_series(a: f64, x: f64) -> f64 {
    let mut term = 1.0 / a;
    let mut sum = term;
    for n in 1..10_000 {
        term *= x / (a + n as f64);
        sum += term;
        if term.abs() < sum.abs() * 1e-16 {
            break;
        }
    }
    sum * (-x + a * x.ln() - ln_gamma(a)).exp()
}

/// Q(a, x) by its continued fraction, evaluated with the modified Lentz method (x >= a + 1).
fn gamma_cf(a: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / TINY;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..10_000 {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        if d.abs() < TINY {
            d = TINY;
        }
        c = b + an / c;
        if c.abs() < TINY {
            c = TINY;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-16 {
            break;
        }
    }
    (-x + a * x.ln() - ln_gamma(a)).exp() * h
}

/// Survival function of the chi-square distribution with `dof` degrees of freedom:
/// the probability of a statistic at least `x` (the p-value of a goodness-of-fit test).
pub fn chi2_sf(x: f64, dof: f64) -> f64 {
    gamma_q(0.5 * dof, 0.5 * x)
}

/// Complementary error function, accurate to about 1e-13 relative over the whole real line
/// (p-values near 1e-7 and below must be right): power series of erf below 2, Lentz's
/// evaluation of the continued fraction of erfc above.
pub fn erfc(x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x < 2.0 {
        // erf(x) = 2/sqrt(pi) sum_n (-1)^n x^(2n+1) / (n! (2n+1)); terms stay below ~20 here.
        let x2 = x * x;
        let mut t = x; // (-1)^n x^(2n+1) / n!
        let mut sum = x;
        for n in 1..200 {
            t *= -x2 / n as f64;
            let term = t / (2 * n + 1) as f64;
            sum += term;
            if term.abs() < 1e-17 * sum.abs() {
                break;
            }
        }
        return 1.0 - sum * std::f64::consts::FRAC_2_SQRT_PI;
    }
    if x > 27.3 {
        return 0.0; // below the smallest f64
    }
    // erfc(x) = exp(-x^2)/sqrt(pi) / (x + (1/2)/(x + 1/(x + (3/2)/(x + 2/(x + ...))))).
    const TINY: f64 = 1e-300;
    let mut f = x;
    let mut c = x;
    let mut d = 0.0f64;
    for n in 1..1000 {
        let a = n as f64 * 0.5;
        d = x + a * d;
        if d == 0.0 {
            d = TINY;
        }
        c = x + a / c;
        if c == 0.0 {
            c = TINY;
        }
        d = 1.0 / d;
        let delta = c * d;
        f *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    (-x * x).exp() / (f * std::f64::consts::PI.sqrt())
}

/// Standard normal cumulative distribution Φ(z).
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * erfc(-z / std::f64::consts::SQRT_2)
}

/// Standard normal tail P(Z > z) = 1 - Φ(z), accurate far into the tail (no cancellation).
pub fn normal_sf(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// The z with P(Z > z) = p, for p in (0, 1): bisection on [`normal_sf`] (which is monotone),
/// to full f64 precision.
pub fn normal_isf(p: f64) -> f64 {
    let (mut lo, mut hi) = (-40.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if normal_sf(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Two-sided p-value of a standard normal statistic: `2 (1 - Φ(|z|))`, without cancellation.
pub fn two_sided_p(z: f64) -> f64 {
    erfc(z.abs() / std::f64::consts::SQRT_2)
}

/// Outcome of a chi-square goodness-of-fit test.
#[derive(Clone, Copy, Debug)]
pub struct ChiSquare {
    pub statistic: f64,
    pub dof: usize,
    pub p_value: f64,
    /// Cells merged into one because their expected counts were small.
    pub pooled_cells: usize,
}

/// Pearson's chi-square test of observed counts against expected counts (same total).
/// Cells expecting fewer than `min_expected` events are pooled into one cell (the test's
/// chi-square approximation needs a few expected events per cell); if the pool is still
/// below the threshold it joins the smallest regular cell. An observation in a cell that
/// expects exactly nothing gives p = 0: the sampler produced an impossible event.
pub fn chi_square_test(observed: &[f64], expected: &[f64], min_expected: f64) -> ChiSquare {
    assert_eq!(observed.len(), expected.len());
    let mut cells: Vec<(f64, f64)> = Vec::new();
    let (mut pool_o, mut pool_e, mut pooled) = (0.0, 0.0, 0usize);
    for (&o, &e) in observed.iter().zip(expected) {
        if e <= 0.0 {
            if o > 0.0 {
                return ChiSquare { statistic: f64::INFINITY, dof: 0, p_value: 0.0, pooled_cells: 0 };
            }
            continue;
        }
        if e < min_expected {
            pool_o += o;
            pool_e += e;
            pooled += 1;
        } else {
            cells.push((o, e));
        }
    }
    if pool_e > 0.0 {
        if pool_e >= min_expected || cells.is_empty() {
            cells.push((pool_o, pool_e));
        } else {
            let i = (0..cells.len()).min_by(|&a, &b| cells[a].1.total_cmp(&cells[b].1)).unwrap_or(0);
            cells[i].0 += pool_o;
            cells[i].1 += pool_e;
        }
    }
    let statistic: f64 = cells.iter().map(|&(o, e)| (o - e) * (o - e) / e).sum();
    let dof = cells.len().saturating_sub(1);
    let p_value = if dof == 0 { 1.0 } else { chi2_sf(statistic, dof as f64) };
    ChiSquare { statistic, dof, p_value, pooled_cells: pooled }
}

/// Šidák-corrected per-test significance so that `tests` independent tests together
/// reject a correct sampler with probability `family_alpha`: `1 - (1 - family_alpha)^(1 / tests)`.
pub fn sidak_alpha(family_alpha: f64, tests: usize) -> f64 {
    // Through ln_1p / exp_m1: the direct formula loses digits to cancellation for large
    // `tests` (2.5e-7 relative at 1e8 tests).
    -((-family_alpha).ln_1p() / tests.max(1) as f64).exp_m1()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_function_values() {
        // Γ(5) = 24, Γ(1/2) = sqrt(pi), Γ(10.5) from tables.
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
        assert!((ln_gamma(0.5) - PI.sqrt().ln()).abs() < 1e-12);
        // Γ(10.5) = (19!! / 2^10) sqrt(pi).
        assert!((ln_gamma(10.5) - (654_729_075.0f64 / 1024.0 * PI.sqrt()).ln()).abs() < 1e-12);
    }

    #[test]
    fn chi2_quantiles_from_tables() {
        // Upper 5 % and 0.1 % points of the chi-square distribution (standard tables).
        for &(x, k, p) in &[(3.841_458_8, 1.0, 0.05), (18.307_038, 10.0, 0.05), (29.588_298, 10.0, 0.001), (124.342_11, 100.0, 0.05)] {
            let sf = chi2_sf(x, k);
            assert!((sf - p).abs() < 1e-6 * p.max(1e-3), "chi2_sf({x}, {k}) = {sf}, want {p}");
        }
        // dof 2: closed form exp(-x/2).
        assert!((chi2_sf(7.0, 2.0) - (-3.5f64).exp()).abs() < 1e-14);
        for &x in &[0.1, 1.0, 5.0, 30.0] {
            assert!((chi2_sf(x, 2.0) - (-x / 2.0f64).exp()).abs() < 1e-12);
        }
        // Tabulated quantiles: chi2(0.95; 10) = 18.307, chi2(0.99; 100) = 135.807.
        assert!((chi2_sf(18.307, 10.0) - 0.05).abs() < 1e-4);
        assert!((chi2_sf(135.807, 100.0) - 0.01).abs() < 1e-4);
    }

    #[test]
    fn normal_cdf_values() {
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-15);
        assert!((normal_cdf(1.959_963_985) - 0.975).abs() < 1e-9);
        assert!((normal_cdf(-3.0) - 0.001_349_898_031_630_094_6).abs() < 1e-12);
        assert!((erfc(1.0) - 0.157_299_207_050_285_13).abs() < 1e-13);
    }

    #[test]
    fn incomplete_gamma_values() {
        // Q(2.5, 1) and Q(5000, 5500) (= chi2_sf(11000, 10000), a 3.6e-12 tail at large dof)
        // from mpmath at 30 digits; P + Q = 1 on both sides of the series/fraction switch.
        assert!((gamma_q(2.5, 1.0) / 0.849_145_036_084_609_6 - 1.0).abs() < 1e-14);
        assert!((chi2_sf(11_000.0, 10_000.0) / 3.618_329_558_096_479e-12 - 1.0).abs() < 1e-10);
        assert!((chi2_sf(200.0, 100.0) / 1.178_450_072_097_942_2e-8 - 1.0).abs() < 1e-12);
        for &(a, x) in &[(0.5, 0.2), (2.5, 1.0), (2.5, 3.6), (40.0, 39.0), (40.0, 45.0)] {
            assert!((gamma_p(a, x) + gamma_q(a, x) - 1.0).abs() < 1e-14, "P + Q at ({a}, {x})");
        }
        assert_eq!(gamma_q(3.0, 0.0), 1.0);
        assert_eq!(gamma_p(3.0, 0.0), 0.0);
    }

    /// 2/sqrt(pi) * integral of exp(-t^2) from x to x+12 by composite Simpson (reference erfc).
    fn erfc_simpson(x: f64) -> f64 {
        let n = 40_000;
        let h = 12.0 / n as f64;
        let f = |t: f64| (-t * t).exp();
        let mut s = f(x) + f(x + 12.0);
        for i in 1..n {
            s += f(x + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0 * std::f64::consts::FRAC_2_SQRT_PI
    }

    #[test]
    fn erfc_matches_quadrature_and_known_values() {
        for x in [0.0, 0.1, 0.5, 1.0, 1.5, 1.99, 2.0, 2.01, 2.5, 3.0, 4.0, 5.0, 6.5, 8.0, 10.0] {
            let (a, b) = (erfc(x), erfc_simpson(x));
            assert!(((a - b) / b).abs() < 1e-10, "erfc({x}) = {a}, quadrature {b}");
        }
        // Published values (Abramowitz & Stegun table 7.1 and standard normal quantiles).
        assert!((erfc(1.0) - 0.157_299_207_050_285_1).abs() < 1e-15);
        assert!((erfc(3.0) / 2.209_049_699_858_544e-5 - 1.0).abs() < 1e-12);
        assert!((normal_cdf(1.959_963_984_540_054) - 0.975).abs() < 1e-14);
        assert!((erfc(-1.0) - (2.0 - 0.157_299_207_050_285_1)).abs() < 1e-15);
        assert_eq!(erfc(30.0), 0.0);
        assert_eq!(erfc(-30.0), 2.0);
        // Continuity at the switch between series and continued fraction.
        let (lo, hi) = (erfc(2.0 - 1e-12), erfc(2.0));
        assert!(((lo - hi) / hi).abs() < 1e-11);
        // Far tails (mpmath, 30 digits): p-values of 1e-12 and below keep their digits.
        assert!((erfc(5.0) / 1.537_459_794_428_034_8e-12 - 1.0).abs() < 1e-13);
        assert!((erfc(8.0) / 1.122_429_717_298_292_7e-29 - 1.0).abs() < 1e-13);
        assert!(erfc(f64::NAN).is_nan());
    }

    #[test]
    fn normal_tail_and_inverse() {
        assert!((normal_sf(1.959_964) - 0.025).abs() < 1e-6);
        assert!((normal_isf(0.001) - 3.090_232).abs() < 1e-5);
        assert!((normal_sf(-1.0) + normal_sf(1.0) - 1.0).abs() < 1e-15);
        assert!((two_sided_p(-1.959_963_984_540_054) - 0.05).abs() < 1e-14);
        for &p in &[1e-12, 1e-6, 0.01, 0.3, 0.5, 0.9] {
            let z = normal_isf(p);
            assert!((normal_sf(z) / p - 1.0).abs() < 1e-12, "normal_isf({p}) = {z}");
        }
    }

    #[test]
    fn sidak_alpha_matches_direct_formula() {
        let a = sidak_alpha(0.01, 100);
        assert!((a - (1.0 - 0.99f64.powf(0.01))).abs() < 1e-15);
        // 256x256 pixels: about 1.5e-7, as the README's alpha ~ 1e-7.
        let a = sidak_alpha(0.01, 256 * 256);
        assert!((a / 1.533_58e-7 - 1.0).abs() < 1e-4, "{a}");
        // 1e8 tests, where the direct formula is off by 2.5e-7 relative (mpmath value).
        let a = sidak_alpha(0.01, 100_000_000);
        assert!((a / 1.005_033_585_299_639_5e-10 - 1.0).abs() < 1e-13, "{a}");
    }

    #[test]
    fn chi_square_detects_and_accepts() {
        let e = vec![100.0; 10];
        let ok: Vec<f64> = vec![95.0, 104.0, 99.0, 110.0, 92.0, 101.0, 97.0, 103.0, 98.0, 101.0];
        assert!(chi_square_test(&ok, &e, 5.0).p_value > 0.5);
        let bad: Vec<f64> = vec![150.0, 50.0, 100.0, 100.0, 100.0, 100.0, 100.0, 100.0, 100.0, 100.0];
        assert!(chi_square_test(&bad, &e, 5.0).p_value < 1e-6);
        // An event where nothing was expected is impossible.
        assert_eq!(chi_square_test(&[1.0, 9.0], &[0.0, 10.0], 5.0).p_value, 0.0);
        // Sparse cells are pooled.
        let r = chi_square_test(&[1.0, 2.0, 3.0, 94.0], &[2.0, 2.0, 2.0, 94.0], 5.0);
        assert_eq!(r.pooled_cells, 3);
        assert_eq!(r.dof, 1);
    }
}
