//! Statistics for the tests of samplers: the chi-square distribution's tail (p-values), the
//! normal CDF, and a chi-square goodness-of-fit test that pools sparse cells. Everything in
//! f64: the tails we ask for are small.

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

/// Complementary error function.
pub fn erfc(x: f64) -> f64 {
    if x >= 0.0 {
        gamma_q(0.5, x * x)
    } else {
        1.0 + gamma_p(0.5, x * x)
    }
}

/// Standard normal cumulative distribution Φ(z).
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * erfc(-z / std::f64::consts::SQRT_2)
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
/// reject a correct sampler with probability `family_alpha`.
pub fn sidak_alpha(family_alpha: f64, tests: usize) -> f64 {
    1.0 - (1.0 - family_alpha).powf(1.0 / tests.max(1) as f64)
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
    }

    #[test]
    fn normal_cdf_values() {
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-15);
        assert!((normal_cdf(1.959_963_985) - 0.975).abs() < 1e-9);
        assert!((normal_cdf(-3.0) - 0.001_349_898_031_630_094_6).abs() < 1e-12);
        assert!((erfc(1.0) - 0.157_299_207_050_285_13).abs() < 1e-13);
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
