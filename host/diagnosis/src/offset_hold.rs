//! Does a manometer offset hold over the indentation?
//!
//! A manometer that reads p0 high leaves the shell p0 below the set point from the first
//! frame to the last: the offset is one number for the whole travel. What mimics it from
//! outside the library changes as the tube travels: a slow leak lowers the pressure during
//! each indentation, so the pressure-offset candidate absorbs its mean in both channels
//! alike and the radius and the load agree (step 8's channel check cannot see it). Read
//! from the two halves of the travel, though, the leak's offset grows with depth.
//!
//! When the final model includes a pressure offset, each pressure's points are split at
//! their median u_s into a shallow and a deep half; the model is fitted to both channels of
//! each half (the joint covariance of that half alone, every parameter free), and the two
//! offsets are compared:
//!
//! z = (p0_deep - p0_shallow) / sqrt(se_shallow^2 + se_deep^2 + (f max |p0|)^2),
//!
//! f the pressure continuation's own error between the halves ([`HALF_ALLOWANCE`]). The
//! test joins the channel check's decision at the same Bonferroni level
//! ([`crate::consistency::test_level`]).

use serde::Serialize;

use super::candidates::EffectKind;
use super::data::{Point, indices_by_pressure};
use super::fitting::{Objective, fit_to};
use super::joint::JointWhitener;
use super::noise_model::NoiseModel;
use super::stats::normal_sf;

/// The pressure continuation's error in the offset read from one half of the travel
/// against the other (relative, 1 standard deviation): true manometer offsets read from
/// the shallow and the deep half differ by up to this much with nothing outside the
/// library (docs/diagnosis.md, step 8).
pub const HALF_ALLOWANCE: f64 = 0.1;

/// The offset read from the two halves of the travel.
#[derive(Debug, Clone, Serialize)]
pub struct OffsetHold {
    /// The u_s (mm) at which each pressure's points were split, per pressure (kPa).
    pub split_u_s_mm: Vec<(f64, f64)>,
    pub shallow_kpa: f64,
    pub shallow_se_kpa: f64,
    pub deep_kpa: f64,
    pub deep_se_kpa: f64,
    /// The continuation's error allowed (kPa, [`HALF_ALLOWANCE`] of the larger reading).
    pub allowance_kpa: f64,
    pub z: f64,
    pub p_value: f64,
}

/// The shallow and the deep half of `subset`: each pressure's points split at their median
/// u_s, with the split depths.
fn halves(points: &[Point], subset: &[usize]) -> (Vec<usize>, Vec<usize>, Vec<(f64, f64)>) {
    let (mut shallow, mut deep, mut split) = (Vec::new(), Vec::new(), Vec::new());
    for (p, idx) in indices_by_pressure(points, subset) {
        let mut u: Vec<f64> = idx.iter().map(|&i| points[i].u_s_mm).collect();
        u.sort_by(f64::total_cmp);
        let median = u[u.len() / 2];
        split.push((p, median));
        for i in idx {
            if points[i].u_s_mm < median {
                shallow.push(i);
            } else {
                deep.push(i);
            }
        }
    }
    shallow.sort_unstable();
    deep.sort_unstable();
    (shallow, deep, split)
}

/// Tests whether the pressure offset of `model` holds over the travel on `points[subset]`,
/// the channels' noise models `radius` and `load`, both channels' residuals `r_a`, `r_p`
/// at the joint fit (for the shared white u_s variance), the modulus starting at `e0`.
/// None when the model has no pressure offset or a half's fit fails.
pub fn check(
    model: &super::model::Model<'_>,
    points: &[Point],
    subset: &[usize],
    (radius, load): (&NoiseModel, &NoiseModel),
    (r_a, r_p): (&[f64], &[f64]),
    e0: f64,
) -> Option<OffsetHold> {
    let j = model
        .included
        .iter()
        .position(|(c, _)| c.kind == EffectKind::PressureOffset)?;
    let (shallow, deep, split_u_s_mm) = halves(points, subset);
    let read = |half: &[usize]| -> Option<(f64, f64)> {
        let joint = JointWhitener::new(radius, load, points, half, r_a, r_p)?;
        let f = fit_to(
            model,
            None,
            points,
            half,
            Objective::Joint(&joint),
            e0,
            0.0,
            40,
        )?;
        Some((*f.included.get(j)?, *f.included_se.get(j)?))
    };
    Some(compare(split_u_s_mm, read(&shallow)?, read(&deep)?))
}

/// The comparison of the offsets `(value, se)` read from the shallow and the deep half.
fn compare(
    split_u_s_mm: Vec<(f64, f64)>,
    (s, s_se): (f64, f64),
    (d, d_se): (f64, f64),
) -> OffsetHold {
    let allowance_kpa = HALF_ALLOWANCE * s.abs().max(d.abs());
    let z = (d - s)
        / (s_se * s_se + d_se * d_se + allowance_kpa * allowance_kpa)
            .sqrt()
            .max(1e-12);
    OffsetHold {
        split_u_s_mm,
        shallow_kpa: s,
        shallow_se_kpa: s_se,
        deep_kpa: d,
        deep_se_kpa: d_se,
        allowance_kpa,
        z,
        p_value: 2.0 * normal_sf(z.abs()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(u_s_mm: f64, p_air_kpa: f64) -> Point {
        Point {
            u_s_mm,
            a_mm: 1.0,
            p_air_kpa,
            test: 0,
            load_n: None,
            t_s: None,
            h_mm: None,
            h_zero_fitted: false,
        }
    }

    #[test]
    fn the_halves_are_compared_with_the_allowance_in_quadrature() {
        // the leak of the outside study (seed 2): 0.553 +- 0.079 shallow, 1.151 +- 0.020
        // deep; allowance 0.1 * 1.151 = 0.1151; z = 0.598 / sqrt(0.079^2 + 0.020^2 +
        // 0.1151^2) = 0.598 / 0.14103 = 4.240, two-sided p = 2.2e-5
        let leak = compare(Vec::new(), (0.553, 0.079), (1.151, 0.020));
        assert!((leak.allowance_kpa - 0.1151).abs() < 1e-12);
        assert!((leak.z - 4.240).abs() < 1e-3, "z {}", leak.z);
        assert!(
            (leak.p_value - 2.24e-5).abs() < 0.1e-5,
            "p {}",
            leak.p_value
        );
        // a true 2 kPa offset (a stale-calibration record): 1.958 +- 0.023 shallow, 1.962
        // +- 0.008 deep; the allowance dominates: z = 0.004 / 0.1976 = 0.020
        let offset = compare(Vec::new(), (1.958, 0.023), (1.962, 0.008));
        assert!((offset.z - 0.0202).abs() < 1e-3, "z {}", offset.z);
        assert!(offset.p_value > 0.98);
    }

    #[test]
    fn each_pressure_is_split_at_its_own_median_depth() {
        // 6 kPa reaches 1.0 mm, 15 kPa only 0.5 mm: each is halved at its own median
        let points: Vec<Point> = (1..=10)
            .map(|k| point(0.1 * k as f64, 6.0))
            .chain((1..=10).map(|k| point(0.05 * k as f64, 15.0)))
            .collect();
        let subset: Vec<usize> = (0..points.len()).collect();
        let (shallow, deep, split) = halves(&points, &subset);
        assert_eq!(split.len(), 2);
        assert!((split[0].1 - 0.6).abs() < 1e-12, "{split:?}");
        assert!((split[1].1 - 0.3).abs() < 1e-12, "{split:?}");
        assert_eq!(shallow, vec![0, 1, 2, 3, 4, 10, 11, 12, 13, 14]);
        assert_eq!(deep, vec![5, 6, 7, 8, 9, 15, 16, 17, 18, 19]);
    }
}
