//! Proximity-sensor calibration (paper, "Sensor design and measurement technique"): on a
//! rigid sample the apex displacement u_s is known from the tube travel h, and the sensor
//! voltage follows the parabola U = A u_s^2 + B u_s + C, fitted by linear least squares
//! (normal equations in the monomials, centred for conditioning).
//!
//! The paper takes u_s = h on the rigid sample; the shell wall's own compression makes
//! u_s slightly smaller than h. [`ProximityCalibration::fit`] takes whatever u_s the caller
//! believes (h itself, or fem-core's rigid-contact u_s(h)); comparing the two fits is how
//! the difference is reported.

use serde::{Deserialize, Serialize};

use vision::linear_solve::solve;

/// The parabola and how well it fits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ProximityCalibration {
    pub p_air_kpa: f64,
    /// U = a_v_per_mm2 u_s^2 + b_v_per_mm u_s + c_v.
    pub a_v_per_mm2: f64,
    pub b_v_per_mm: f64,
    pub c_v: f64,
    /// RMS voltage residual.
    pub residual_rms_v: f64,
    /// The residual expressed as displacement (divided by the mean |dU/du_s|).
    pub residual_rms_mm: f64,
    pub points: usize,
    /// u_s range calibrated.
    pub u_s_min_mm: f64,
    pub u_s_max_mm: f64,
    /// How far the apex mirror moves outward per kPa of internal pressure (the shell's
    /// inflation; fem-core): readings at a pressure p other than `p_air_kpa` are corrected
    /// by + apex_mm_per_kpa (p - p_air_kpa) ([`Self::u_s_mm_at`]). 0: no correction.
    #[serde(default)]
    pub apex_mm_per_kpa: f64,
}

/// Why a calibration failed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ProximityError {
    #[error("proximity calibration needs at least 3 points with distinct u_s, got {0}")]
    TooFewPoints(usize),
    #[error("proximity calibration is singular (u_s does not vary)")]
    Singular,
    #[error("proximity parabola is not monotonic over the calibrated range")]
    NotMonotonic,
    #[error("voltage {volts:.4} V is outside the calibrated range")]
    OutOfRange { volts: f64 },
}

impl ProximityCalibration {
    /// Least-squares parabola through (u_s, U) pairs.
    pub fn fit(p_air_kpa: f64, pairs: &[(f64, f64)]) -> Result<Self, ProximityError> {
        if pairs.len() < 3 {
            return Err(ProximityError::TooFewPoints(pairs.len()));
        }
        let n = pairs.len() as f64;
        let uc = pairs.iter().map(|p| p.0).sum::<f64>() / n;
        let mut m = [[0.0; 3]; 3];
        let mut rhs = [0.0; 3];
        for &(u, v) in pairs {
            let x = u - uc;
            let phi = [x * x, x, 1.0];
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] += phi[i] * phi[j];
                }
                rhs[i] += phi[i] * v;
            }
        }
        let [ac, bc, cc] = solve(m, rhs).ok_or(ProximityError::Singular)?;
        if !(ac.is_finite() && bc.is_finite() && cc.is_finite()) {
            return Err(ProximityError::Singular);
        }
        // un-centre: a (u-uc)^2 + b (u-uc) + c
        let a = ac;
        let b = bc - 2.0 * ac * uc;
        let c = ac * uc * uc - bc * uc + cc;
        let u_min = pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let u_max = pairs.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let slope = |u: f64| 2.0 * a * u + b;
        if slope(u_min) * slope(u_max) <= 0.0 {
            return Err(ProximityError::NotMonotonic);
        }
        let rms_v = (pairs
            .iter()
            .map(|&(u, v)| (v - (a * u * u + b * u + c)).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        let mean_slope = ((slope(u_min).abs() + slope(u_max).abs()) / 2.0).max(1e-12);
        Ok(Self {
            p_air_kpa,
            a_v_per_mm2: a,
            b_v_per_mm: b,
            c_v: c,
            residual_rms_v: rms_v,
            residual_rms_mm: rms_v / mean_slope,
            points: pairs.len(),
            u_s_min_mm: u_min,
            u_s_max_mm: u_max,
            apex_mm_per_kpa: 0.0,
        })
    }

    /// U at u_s.
    pub fn volts(&self, u_s_mm: f64) -> f64 {
        (self.a_v_per_mm2 * u_s_mm + self.b_v_per_mm) * u_s_mm + self.c_v
    }

    /// u_s from U read at internal pressure `p_kpa`: the parabola's u_s plus the apex
    /// inflation difference to the calibration pressure.
    pub fn u_s_mm_at(&self, volts: f64, p_kpa: f64) -> Result<f64, ProximityError> {
        Ok(self.u_s_mm(volts)? + self.apex_mm_per_kpa * (p_kpa - self.p_air_kpa))
    }

    /// u_s from U: the root of the parabola inside the calibrated range (extended by 20 %
    /// of its span at either end).
    pub fn u_s_mm(&self, volts: f64) -> Result<f64, ProximityError> {
        let (a, b, c) = (self.a_v_per_mm2, self.b_v_per_mm, self.c_v - volts);
        let span = self.u_s_max_mm - self.u_s_min_mm;
        let (lo, hi) = (self.u_s_min_mm - 0.2 * span, self.u_s_max_mm + 0.2 * span);
        let roots: Vec<f64> = if a.abs() < 1e-12 {
            vec![-c / b]
        } else {
            let disc = b * b - 4.0 * a * c;
            if disc < 0.0 {
                return Err(ProximityError::OutOfRange { volts });
            }
            // numerically stable pair of roots
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            vec![q / a, c / q]
        };
        roots
            .into_iter()
            .filter(|u| u.is_finite() && *u >= lo && *u <= hi)
            .min_by(|x, y| {
                let mid = (self.u_s_min_mm + self.u_s_max_mm) / 2.0;
                (x - mid).abs().total_cmp(&(y - mid).abs())
            })
            .ok_or(ProximityError::OutOfRange { volts })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_parabola_and_inverts_it() {
        let (a, b, c) = (-0.12, -0.55, 2.4);
        let pairs: Vec<(f64, f64)> = (0..=20)
            .map(|k| {
                let u = k as f64 * 0.1;
                (u, a * u * u + b * u + c)
            })
            .collect();
        let cal = ProximityCalibration::fit(6.0, &pairs).unwrap();
        assert!((cal.a_v_per_mm2 - a).abs() < 1e-9);
        assert!((cal.b_v_per_mm - b).abs() < 1e-9);
        assert!((cal.c_v - c).abs() < 1e-9);
        assert!(cal.residual_rms_v < 1e-9);
        for &(u, v) in &pairs {
            assert!((cal.u_s_mm(v).unwrap() - u).abs() < 1e-9);
        }
    }

    #[test]
    fn too_few_or_degenerate_points_are_errors() {
        assert_eq!(
            ProximityCalibration::fit(6.0, &[(0.0, 1.0), (1.0, 2.0)]),
            Err(ProximityError::TooFewPoints(2))
        );
        assert!(ProximityCalibration::fit(6.0, &[(1.0, 1.0); 5]).is_err());
    }
}
