//! The pressure's excursion around its set point during an indentation. The tables hold the
//! shell at a constant p_air; on the bench the indentation pushes the shell in, its volume
//! falls, and the trapped air's pressure rises until the bleed lets it back (the pump can
//! only raise it). The manometer records that excursion on every row of a record, a few
//! hundredths of a kPa, but the load at a given u_s grows by about 20 mN per kPa at
//! u_s 1.1 mm (170 kPa, 6 and 15 kPa): a 0.05 kPa excursion is 1 mN, a quarter of a per
//! cent of the load and many times the load's own noise.
//!
//! Each point is moved to the set point p0 with the baseline at the host's modulus
//! estimate: f(u, p0) = f(u, p0 + dp) - [b(u, p0 + dp) - b(u, p0)], b the baseline (its
//! change is the effect of the excursion to first order in dp; the sample's own departure
//! from the baseline changes it by a fraction of that fraction). The excursion dp is the
//! manometer's reading minus the set point, smoothed along each indentation by a
//! least-squares quadratic in u_s: a single reading carries the manometer's noise
//! (0.02 kPa on the simulated bench), which the smooth excursion does not.

use super::data::Point;
use super::model::{Channel, Model};

/// What the correction did, for the report.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ExcursionCorrection {
    /// Points with a nonzero reading to correct.
    pub points: usize,
    /// Range of the smoothed excursion (kPa).
    pub min_kpa: f64,
    pub max_kpa: f64,
    /// Largest change of the radius (mm) and of the load (N).
    pub worst_a_mm: f64,
    pub worst_load_n: f64,
}

/// The least-squares polynomial of degree up to 2 through (x, y) evaluated at each x: the
/// degree is lowered for fewer than 6 points (linear from 3, the mean below) or where the x
/// spread is nil.
pub fn smooth_quadratic(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n == 0 {
        return Vec::new();
    }
    let mean_x = x.iter().sum::<f64>() / n as f64;
    let spread = x.iter().map(|v| (v - mean_x).abs()).fold(0.0, f64::max);
    let degree = match n {
        _ if spread <= 0.0 => 0,
        0..=2 => 0,
        3..=5 => 1,
        _ => 2,
    };
    // centred and scaled abscissa keeps the normal equations well conditioned
    let t: Vec<f64> = x
        .iter()
        .map(|v| {
            if spread > 0.0 {
                (v - mean_x) / spread
            } else {
                0.0
            }
        })
        .collect();
    let k = degree + 1;
    let basis = |ti: f64, j: usize| ti.powi(j as i32);
    let mut ata = vec![0.0; k * k];
    let mut atb = vec![0.0; k];
    for (&ti, &yi) in t.iter().zip(y) {
        for r in 0..k {
            atb[r] += basis(ti, r) * yi;
            for c in 0..k {
                ata[r * k + c] += basis(ti, r) * basis(ti, c);
            }
        }
    }
    match super::linalg::solve_spd(&ata, k, &atb) {
        Some(coef) => t
            .iter()
            .map(|&ti| (0..k).map(|j| coef[j] * basis(ti, j)).sum())
            .collect(),
        None => vec![y.iter().sum::<f64>() / n as f64; n],
    }
}

/// Replaces each point's excursion by its smoothed value along its indentation (a replicate
/// at one set point; `points` sorted by pressure, replicate, u_s as [`super::data`] keeps
/// them).
pub fn smooth_excursions(points: &mut [Point]) {
    let mut start = 0;
    while start < points.len() {
        let (p, test) = (points[start].p_air_kpa, points[start].test);
        let end = start
            + points[start..]
                .iter()
                .position(|q| q.p_air_kpa != p || q.test != test)
                .unwrap_or(points.len() - start);
        let run = &mut points[start..end];
        if run.iter().any(|q| q.p_excursion_kpa != 0.0) {
            let x: Vec<f64> = run.iter().map(|q| q.u_s_mm).collect();
            let y: Vec<f64> = run.iter().map(|q| q.p_excursion_kpa).collect();
            for (q, s) in run.iter_mut().zip(smooth_quadratic(&x, &y)) {
                q.p_excursion_kpa = s;
            }
        }
        start = end;
    }
}

/// The baseline's change in `channel` from the set point `p` to `p + dp` at modulus `e` and
/// u_s `u`: read on each side of the set point from that side's own model (the table's
/// cubic above its first inflated pressure, the pressure reference below it), which a
/// difference across the set point would mix; NaN outside the table.
pub fn excursion_change(
    model: &Model<'_>,
    channel: Channel,
    e: f64,
    p: f64,
    u: f64,
    dp: f64,
) -> f64 {
    channel.of(&model.base.sample(e, (p + dp).max(0.0), u))
        - channel.of(&model.base.sample(e, p, u))
}

/// Smooths every point's excursion ([`smooth_excursions`]) and moves its radius and load to
/// the set point with the baseline at modulus `e`. Points without a reading are left as they
/// are.
pub fn correct(model: &Model<'_>, e: f64, points: &mut [Point]) -> ExcursionCorrection {
    smooth_excursions(points);
    let mut out = ExcursionCorrection {
        min_kpa: f64::INFINITY,
        max_kpa: f64::NEG_INFINITY,
        ..ExcursionCorrection::default()
    };
    for pt in points.iter_mut() {
        let dp = pt.p_excursion_kpa;
        if dp == 0.0 {
            continue;
        }
        out.points += 1;
        out.min_kpa = out.min_kpa.min(dp);
        out.max_kpa = out.max_kpa.max(dp);
        let da = excursion_change(model, Channel::Radius, e, pt.p_air_kpa, pt.u_s_mm, dp);
        if da.is_finite() {
            pt.a_mm -= da;
            out.worst_a_mm = out.worst_a_mm.max(da.abs());
        }
        if let Some(l) = pt.load_n {
            let dl = excursion_change(model, Channel::Load, e, pt.p_air_kpa, pt.u_s_mm, dp);
            if dl.is_finite() {
                pt.load_n = Some(l - dl);
                out.worst_load_n = out.worst_load_n.max(dl.abs());
            }
        }
    }
    if out.points == 0 {
        out.min_kpa = 0.0;
        out.max_kpa = 0.0;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quadratic_is_exact_on_a_quadratic_and_averages_noise() {
        let x: Vec<f64> = (0..40).map(|k| 0.04 * k as f64).collect();
        let f = |u: f64| 0.01 + 0.05 * u - 0.02 * u * u;
        let y: Vec<f64> = x.iter().map(|&u| f(u)).collect();
        for (s, &u) in smooth_quadratic(&x, &y).iter().zip(&x) {
            assert!((s - f(u)).abs() < 1e-14, "{s} vs {}", f(u));
        }
        // alternating +-0.02 (the manometer's noise) on a constant: the fit removes it to
        // within its projection on three basis functions, well under the noise itself
        let y: Vec<f64> = (0..40)
            .map(|k| 0.05 + if k % 2 == 0 { 0.02 } else { -0.02 })
            .collect();
        let s = smooth_quadratic(&x, &y);
        assert!(s.iter().all(|v| (v - 0.05).abs() < 0.002), "{s:?}");
        // too few points for a quadratic: a line, then the mean
        let s = smooth_quadratic(&[0.0, 1.0, 2.0], &[1.0, 2.0, 3.0]);
        assert!(
            s.iter()
                .zip([1.0, 2.0, 3.0])
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
        let s = smooth_quadratic(&[0.5, 0.5], &[1.0, 3.0]);
        assert!(s.iter().all(|v| (v - 2.0).abs() < 1e-12), "{s:?}");
    }

    /// Points read from the converged baseline at the set point plus a known excursion (a
    /// quadratic in u_s, with alternating manometer noise on the readings) come back, after
    /// the correction, to the baseline at the set point itself.
    #[test]
    fn points_at_an_excursion_are_moved_to_the_set_point() {
        let base = crate::tables::converged_baseline().expect("converged table");
        let model = Model::new(&base, &[]).expect("model");
        let (e, p0) = (170.0, 6.0);
        let excursion = |u: f64| 0.02 + 0.05 * u - 0.015 * u * u;
        let mut points: Vec<Point> = (1..36)
            .map(|k| {
                let u = 0.04 * k as f64;
                let dp = excursion(u);
                let s = model.base.sample(e, p0 + dp, u);
                let noise = if k % 2 == 0 { 0.02 } else { -0.02 };
                Point {
                    u_s_mm: u,
                    a_mm: s.a_mm,
                    p_air_kpa: p0,
                    p_excursion_kpa: dp + noise,
                    test: 0,
                    load_n: Some(s.load_n),
                    t_s: None,
                    h_mm: None,
                    h_zero_fitted: false,
                }
            })
            .collect();
        let before: Vec<Point> = points.clone();
        let c = correct(&model, e, &mut points);
        assert_eq!(c.points, points.len());
        // the excursion moves the deepest load by about 20 mN/kPa x 0.07 kPa
        assert!(c.worst_load_n > 1e-3, "{c:?}");
        for (k, (q, b)) in points.iter().zip(&before).enumerate() {
            // what the smoothing left of the +-0.02 kPa noise (most at the ends, where a
            // quadratic has its largest leverage)
            let smoothing_error = (q.p_excursion_kpa - excursion(0.04 * (k + 1) as f64)).abs();
            assert!(
                smoothing_error < 0.004,
                "u_s {}: {smoothing_error}",
                q.u_s_mm
            );
            // the residual is that error times the baseline's slopes in p_air (at most
            // 12.8 um and 25 mN per kPa on this curve; bounded by 15 and 30)
            let at_set = model.base.sample(e, p0, q.u_s_mm);
            assert!(
                (q.a_mm - at_set.a_mm).abs() <= 15e-3 * smoothing_error + 1e-9,
                "u_s {}: a {} vs {} (was {})",
                q.u_s_mm,
                q.a_mm,
                at_set.a_mm,
                b.a_mm
            );
            let l = q.load_n.expect("load");
            assert!(
                (l - at_set.load_n).abs() <= 30e-3 * smoothing_error + 1e-9,
                "u_s {}: load {l} vs {} (was {:?})",
                q.u_s_mm,
                at_set.load_n,
                b.load_n
            );
        }
    }
}
