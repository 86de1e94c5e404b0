//! Errors in the variable: u_s is measured with noise (the proximity sensor's white noise, a
//! tare error per indentation, a slow drift), and a curved model read at a noisy abscissa is
//! biased. With u_meas = u + d, d ~ N(0, sigma_u^2) and the true u spread evenly, the
//! expected measurement at u_meas is E[f(u_meas - d)] = f(u_meas) + f''(u_meas) sigma_u^2 / 2
//! + O(sigma_u^4) (the small-error expansion of Carroll, Ruppert, Stefanski & Crainiceanu,
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
    let f = |x: f64| channel.of(&model.base.sample(e, p, x));
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
