//! Distribution functions the tests of the diagnosis need.
//!
//! - standard normal CDF via erfc (Numerical Recipes' Chebyshev erfc, |error| < 1.2e-7);
//! - chi-square upper tail by the Wilson–Hilferty cube-root normal approximation
//!   (chi2/k)^(1/3) ~ N(1 - 2/(9k), 2/(9k)) (good to ~1e-3 in p for k >= 10);
//! - the Wald–Wolfowitz runs test: for a sign sequence with n+ and n- values the number of
//!   runs has mean 2 n+ n- / n + 1 and variance (mu - 1)(mu - 2)/(n - 1); sequences are
//!   pooled by summing means and variances;
//! - a seeded Gaussian generator (xorshift64* + Box–Muller) for the bootstraps.

/// erfc(x), Numerical Recipes 6.2 (fractional error < 1.2e-7).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// Standard normal upper tail P(Z > z).
pub fn normal_sf(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Upper tail of chi-square with k degrees of freedom (Wilson–Hilferty).
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    if k <= 0.0 {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    let v = 2.0 / (9.0 * k);
    let z = ((x / k).cbrt() - (1.0 - v)) / v.sqrt();
    normal_sf(z)
}

/// Runs test over several sign sequences: (runs, expected, z). z < 0: fewer runs than
/// chance (structure).
pub fn runs_test(sequences: &[Vec<bool>]) -> (usize, f64, f64) {
    let (mut runs, mut mu_sum, mut var_sum) = (0usize, 0.0, 0.0);
    for s in sequences {
        if s.len() < 2 {
            continue;
        }
        let np = s.iter().filter(|&&b| b).count() as f64;
        let n = s.len() as f64;
        let nm = n - np;
        runs += 1 + s.windows(2).filter(|w| w[0] != w[1]).count();
        let mu = 2.0 * np * nm / n + 1.0;
        mu_sum += mu;
        var_sum += (mu - 1.0) * (mu - 2.0) / (n - 1.0);
    }
    let z = if var_sum > 0.0 {
        (runs as f64 - mu_sum) / var_sum.sqrt()
    } else {
        0.0
    };
    (runs, mu_sum, z)
}

/// Quantile q of a sample (linear between order statistics).
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let k = pos.floor() as usize;
    let f = pos - k as f64;
    if k + 1 < v.len() {
        v[k] + f * (v[k + 1] - v[k])
    } else {
        v[k]
    }
}

/// P(X >= k) for X ~ Binomial(n, p).
fn binomial_upper_tail(k: usize, n: usize, p: f64) -> f64 {
    if k == 0 {
        return 1.0;
    }
    // sum of the terms C(n, j) p^j (1 - p)^(n - j), j >= k, built from the j = k term in logs
    let ln_choose = |j: usize| -> f64 {
        (1..=j)
            .map(|i| ((n - j + i) as f64).ln() - (i as f64).ln())
            .sum()
    };
    (k..=n)
        .map(|j| (ln_choose(j) + j as f64 * p.ln() + (n - j) as f64 * (-p).ln_1p()).exp())
        .sum::<f64>()
        .min(1.0)
}

/// One-sided exact (Clopper–Pearson) confidence bounds at level `1 - alpha` for a rate
/// seen `k` times in `n` trials: the lower bound is the p at which P(X >= k) = alpha, the
/// upper the p at which P(X <= k) = alpha (Clopper & Pearson, Biometrika 26, 404, 1934).
/// Found by bisection (the tails are monotone in p). (0, 1) without trials.
pub fn binomial_bounds(k: usize, n: usize, alpha: f64) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let k = k.min(n);
    // the p in (0, 1) at which the upper tail P(X >= j), increasing with p, equals target
    let solve = |j: usize, target: f64| {
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if binomial_upper_tail(j, n, mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    let lower = if k == 0 { 0.0 } else { solve(k, alpha) };
    // P(X <= k) = alpha where P(X >= k + 1) = 1 - alpha
    let upper = if k == n {
        1.0
    } else {
        solve(k + 1, 1.0 - alpha)
    };
    (lower, upper)
}

/// Seeded Gaussian generator.
#[derive(Debug, Clone)]
pub struct Gauss {
    state: u64,
    spare: Option<f64>,
}

impl Gauss {
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            spare: None,
        }
    }

    fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// N(0, 1).
    pub fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let (u1, u2) = (self.uniform(), self.uniform());
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binomial_bounds_match_closed_forms_and_hand_solved_values() {
        // k = n and k = 0 have closed forms: alpha^(1/n) and 1 - alpha^(1/n)
        let (lo, hi) = binomial_bounds(20, 20, 0.05);
        assert!((lo - 0.05f64.powf(1.0 / 20.0)).abs() < 1e-9 && hi == 1.0);
        let (lo, hi) = binomial_bounds(0, 20, 0.05);
        assert!(lo == 0.0 && (hi - (1.0 - 0.05f64.powf(1.0 / 20.0))).abs() < 1e-9);
        // 1 of 10: the upper bound solves (1 - p)^10 + 10 p (1 - p)^9 = 0.05, p = 0.3942
        // (by hand), the lower one 1 - (1 - p)^10 = 0.05, p = 0.0051; 9 of 10 mirrors 1 of 10
        let (lo, hi) = binomial_bounds(1, 10, 0.05);
        assert!((hi - 0.3942).abs() < 1e-4, "{hi}");
        assert!((lo - 0.0051).abs() < 1e-4, "{lo}");
        let (lo, _) = binomial_bounds(9, 10, 0.05);
        assert!((lo - (1.0 - 0.3942)).abs() < 1e-4, "{lo}");
    }

    #[test]
    fn tails_match_published_values() {
        // Abramowitz & Stegun table 26.1: P(Z > 1.96) = 0.0250, P(Z > 1) = 0.1587.
        assert!((normal_sf(1.959_964) - 0.025).abs() < 1e-6);
        assert!((normal_sf(1.0) - 0.158_655).abs() < 1e-6);
        // chi-square table: chi2_{0.95}(10) = 18.307, chi2_{0.99}(100) = 135.807.
        assert!((chi2_sf(18.307, 10.0) - 0.05).abs() < 2e-3);
        assert!((chi2_sf(135.807, 100.0) - 0.01).abs() < 5e-4);
    }

    #[test]
    fn runs_of_an_alternating_and_a_blocked_sequence() {
        let alt: Vec<bool> = (0..20).map(|i| i % 2 == 0).collect();
        let (r, mu, z) = runs_test(&[alt]);
        assert_eq!(r, 20);
        assert!((mu - 11.0).abs() < 1e-12);
        assert!(z > 3.0);
        let block: Vec<bool> = (0..20).map(|i| i < 10).collect();
        let (r, _, z) = runs_test(&[block]);
        assert_eq!(r, 2);
        assert!(z < -3.0);
    }

    #[test]
    fn gaussian_generator_has_unit_variance() {
        let mut g = Gauss::new(3);
        let v: Vec<f64> = (0..20_000).map(|_| g.normal()).collect();
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let s2 = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64;
        // standard errors: 1/sqrt(20000) = 0.007 for the mean, 0.01 for the variance
        assert!(m.abs() < 0.03 && (s2 - 1.0).abs() < 0.04, "{m} {s2}");
    }
}
