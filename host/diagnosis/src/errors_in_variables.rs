//! Errors in the variable: u_s is measured with noise (the proximity sensor's white noise, a
//! tare error per indentation, a slow drift), and a curved model read at a noisy abscissa is
//! biased. With u_meas = u + d, d ~ N(0, sigma_u^2) and the true u spread evenly, the
//! expected measurement at u_meas is E[f(u_meas - d)] = f(u_meas) + f''(u_meas) sigma_u^2 / 2,
//! to O(sigma_u^4) (the small-error expansion of Carroll, Ruppert, Stefanski & Crainiceanu,
//! *Measurement Error in Nonlinear Models*, 2nd ed. 2006, ch. 4). The bias is common to every
//! replicate, so the noise model (built from replicate deviations) cannot see it, and where
//! a(u_s) is steep and curved (soft samples, where the whole curve lies within u_s < 0.3 mm)
//! it is as large as the noise.
//!
//! The expectation is taken by three-point Gauss–Hermite quadrature (exact for cubics):
//! E[f(u - d)] = 2/3 f(u) + 1/6 [f(u + sqrt(3) sigma_u) + f(u - sqrt(3) sigma_u)], on the
//! baseline at the host's modulus estimate (a second-order term: the candidates' own
//! curvature differs from it by a fraction of itself), and the bias is removed from the
//! measured values before the fits.

use super::data::Point;
use super::model::{Channel, Model};

/// Bias E[f(u_meas - d)] - f(u_meas) of `channel` at `pt` for the baseline at modulus `e`,
/// u_s noise variance `var_u_mm2`; 0 where the quadrature would leave the u_s range `range`
/// of the table.
pub fn bias(
    model: &Model<'_>,
    channel: Channel,
    e: f64,
    pt: &Point,
    var_u_mm2: f64,
    range: (f64, f64),
) -> f64 {
    if var_u_mm2 <= 0.0 {
        return 0.0;
    }
    let step = (3.0 * var_u_mm2).sqrt();
    let (u, p) = (pt.u_s_mm, pt.p_air_kpa);
    if u - step < range.0 || u + step > range.1 {
        return 0.0;
    }
    gauss_hermite_bias(|x| channel.of(&model.base.sample(e, p, x)), u, var_u_mm2)
}

/// E[f(u - d)] - f(u) for d ~ N(0, var) by three-point Gauss–Hermite quadrature (nodes 0,
/// +-sqrt(3 var), weights 2/3, 1/6, 1/6).
pub fn gauss_hermite_bias(f: impl Fn(f64) -> f64, u: f64, var: f64) -> f64 {
    let step = (3.0 * var).sqrt();
    (f(u + step) + f(u - step) - 2.0 * f(u)) / 6.0
}

/// Removes the bias from the radius (and the load, when present) of every point, with the
/// u_s noise variance of its pressure from `var_u_at`; returns the largest |bias| of the
/// radius (mm) and of the load (N).
pub fn correct(
    model: &Model<'_>,
    e: f64,
    points: &mut [Point],
    var_u_at: impl Fn(f64) -> f64,
) -> (f64, f64) {
    let (mut worst_a, mut worst_load) = (0.0f64, 0.0f64);
    let mut ranges: Vec<(f64, Option<(f64, f64)>)> = Vec::new();
    for pt in points.iter_mut() {
        let range = match ranges.iter().find(|r| r.0 == pt.p_air_kpa) {
            Some(r) => r.1,
            None => {
                let r = model.base.u_s_range_mm(e, pt.p_air_kpa);
                ranges.push((pt.p_air_kpa, r));
                r
            }
        };
        let Some(range) = range else {
            continue;
        };
        let var = var_u_at(pt.p_air_kpa);
        let b = bias(model, Channel::Radius, e, pt, var, range);
        if b.is_finite() {
            pt.a_mm -= b;
            worst_a = worst_a.max(b.abs());
        }
        if let Some(l) = pt.load_n {
            let b = bias(model, Channel::Load, e, pt, var, range);
            if b.is_finite() {
                pt.load_n = Some(l - b);
                worst_load = worst_load.max(b.abs());
            }
        }
    }
    (worst_a, worst_load)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadrature_matches_closed_form_expectations() {
        // E[(u - d)^3] - u^3 = 3 u var for Gaussian d (odd moments vanish): exact for cubics
        let (u, var) = (0.4, 2.5e-5);
        let b = gauss_hermite_bias(|x| x * x * x, u, var);
        assert!((b - 3.0 * u * var).abs() < 1e-15, "{b}");
        // E[exp(u - d)] - exp(u) = exp(u) (exp(var/2) - 1); the 3-point rule's error is
        // O(var^2) relative: at var = 0.01 the difference is ~1e-5 of exp(u)
        let var = 0.01;
        let b = gauss_hermite_bias(f64::exp, 0.0, var);
        let exact = (0.5 * var).exp() - 1.0;
        assert!((b - exact).abs() < 2e-5, "{b} vs {exact}");
        // a square root (the shape of a(u_s) near first contact): concave, so negative,
        // and f'' var / 2 = -var / (8 u^1.5) to leading order
        let (u, var) = (0.05, 1e-5);
        let b = gauss_hermite_bias(f64::sqrt, u, var);
        let leading = -var / (8.0 * u.powf(1.5));
        assert!(
            b < 0.0 && (b - leading).abs() < 0.05 * leading.abs(),
            "{b} vs {leading}"
        );
    }
}
