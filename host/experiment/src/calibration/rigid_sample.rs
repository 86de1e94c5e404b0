//! The apex displacement u_s on a rigid flat sample as a function of tube travel h, from
//! fem-core (the shell pressed on a sample of E2 = 1e7 kPa, i.e. 50 000 times stiffer than
//! the shell, which behaves as rigid).
//!
//! The paper calibrates the proximity sensor taking u_s = h on the rigid sample; the shell
//! wall's own deformation makes them differ (fem-core: u_s - h = 0.003..0.033 mm for
//! h = 0.2..1.9 mm at 6 kPa on the production mesh). [`RigidSampleCurve::u_s_mm`] maps the
//! stage travel beyond contact to the u_s the calibration should be fitted against.

use fem_core::{CurveParams, solve_curve};
use serde::{Deserialize, Serialize};

/// Sample modulus standing in for "rigid" (kPa).
pub const RIGID_MODULUS_KPA: f64 = 1.0e7;

/// u_s(h) on the rigid sample at one pressure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RigidSampleCurve {
    pub pressure_kpa: f64,
    pub mesh_level: i32,
    pub h_mm: Vec<f64>,
    pub u_s_mm: Vec<f64>,
    /// Outward apex displacement of the free shell inflated to `pressure_kpa` (fem-core
    /// stage 1): the proximity mirror moves with it, so a pressure error moves the reading.
    #[serde(default)]
    pub inflation_apex_mm: f64,
    /// The normal load on the rigid sample at each `h_mm` (N; empty in curves stored before
    /// it was kept): what the load cell should read, against which its scale is calibrated.
    #[serde(default)]
    pub load_n: Vec<f64>,
}

#[derive(Debug, thiserror::Error)]
pub enum RigidSampleError {
    #[error(
        "fem-core rigid-sample solve at {pressure_kpa} kPa (mesh level {mesh_level}): {reason}"
    )]
    Solve {
        pressure_kpa: f64,
        mesh_level: i32,
        reason: String,
    },
}

impl RigidSampleCurve {
    /// Solves the rigid-sample curve (`steps` equal steps to `max_depth_mm`). Production
    /// mesh (level 0) takes ~9-13 s of CPU, level -2 under a second.
    pub fn solve(
        pressure_kpa: f64,
        mesh_level: i32,
        steps: usize,
        max_depth_mm: f64,
    ) -> Result<Self, RigidSampleError> {
        let params = CurveParams {
            sample_modulus_kpa: RIGID_MODULUS_KPA,
            pressure_kpa,
            mesh_level,
            steps,
            max_depth_mm,
            ..CurveParams::default()
        };
        let curve = solve_curve(&params).map_err(|e| RigidSampleError::Solve {
            pressure_kpa,
            mesh_level,
            reason: e.to_string(),
        })?;
        Ok(Self {
            pressure_kpa,
            mesh_level,
            h_mm: curve.points.iter().map(|p| p.h_mm).collect(),
            u_s_mm: curve.points.iter().map(|p| p.u_s_mm).collect(),
            inflation_apex_mm: curve.inflation_apex_mm,
            load_n: curve.points.iter().map(|p| p.load_n).collect(),
        })
    }

    /// The load on the rigid sample at tube travel `h_mm` (piecewise linear between the
    /// solved steps); None outside them or without loads.
    pub fn load_n_at(&self, h_mm: f64) -> Option<f64> {
        let n = self.h_mm.len();
        if self.load_n.len() != n || n < 2 || h_mm < self.h_mm[0] || h_mm > self.h_mm[n - 1] {
            return None;
        }
        let k = self.h_mm.partition_point(|&x| x <= h_mm).clamp(1, n - 1) - 1;
        let t = (h_mm - self.h_mm[k]) / (self.h_mm[k + 1] - self.h_mm[k]);
        Some(self.load_n[k] + t * (self.load_n[k + 1] - self.load_n[k]))
    }

    /// u_s at tube travel `h_mm` (piecewise linear between the solved steps; u_s = h
    /// before contact, and beyond the last step u_s - h is held constant).
    pub fn u_s_mm(&self, h_mm: f64) -> f64 {
        let n = self.h_mm.len();
        if h_mm <= 0.0 || n < 2 {
            return h_mm;
        }
        if h_mm >= self.h_mm[n - 1] {
            return h_mm + (self.u_s_mm[n - 1] - self.h_mm[n - 1]);
        }
        let k = self.h_mm.partition_point(|&x| x <= h_mm).clamp(1, n - 1) - 1;
        let t = (h_mm - self.h_mm[k]) / (self.h_mm[k + 1] - self.h_mm[k]);
        self.u_s_mm[k] + t * (self.u_s_mm[k + 1] - self.u_s_mm[k])
    }

    /// d(apex inflation)/dp, as the secant apex / p at the solved pressure (mm/kPa).
    pub fn apex_mm_per_kpa(&self) -> f64 {
        if self.pressure_kpa > 0.0 {
            self.inflation_apex_mm / self.pressure_kpa
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_extends() {
        let c = RigidSampleCurve {
            pressure_kpa: 6.0,
            mesh_level: 0,
            h_mm: vec![0.0, 1.0, 2.0],
            u_s_mm: vec![0.0, 1.02, 2.04],
            inflation_apex_mm: 0.05,
            load_n: vec![0.0, 0.4, 1.0],
        };
        assert_eq!(c.u_s_mm(-0.1), -0.1);
        assert!((c.u_s_mm(0.5) - 0.51).abs() < 1e-12);
        assert!((c.u_s_mm(1.5) - 1.53).abs() < 1e-12);
        assert!((c.u_s_mm(3.0) - 3.04).abs() < 1e-12);
        assert!((c.load_n_at(1.5).unwrap_or(f64::NAN) - 0.7).abs() < 1e-12);
        assert_eq!(c.load_n_at(2.5), None);
    }
}
