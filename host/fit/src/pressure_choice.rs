//! Which internal pressure measures a given modulus best.
//!
//! For a point at u_s the modulus information is (d a / d ln E2)^2 / sigma_a^2 (Fisher
//! information of one a measurement with noise sigma_a). Over an indentation sampled
//! uniformly in u_s with density rho_u (points per mm) up to the largest u_s the table
//! reaches at that pressure, the information is rho_u / sigma_a^2 * integral of
//! (da/dlnE)^2 du_s, and the predicted standard error of ln E2 is its inverse square root.
//! The recommended pressure is the table pressure with the smallest predicted error.

use serde::Serialize;

use super::model::LutModel;

/// Predicted sensitivity at one pressure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PressureSensitivity {
    pub p_air_kpa: f64,
    /// u_s range the table covers at this (E2, p_air).
    pub u_s_max_mm: f64,
    /// RMS of |d a / d ln E2| over that range (mm).
    pub rms_da_dln_modulus_mm: f64,
    /// Predicted relative standard error of E2 for `points_per_mm` points with noise
    /// `sigma_a_mm`.
    pub predicted_relative_se: f64,
}

/// Sensitivities at every table pressure and the index of the best, for a sample of
/// modulus `modulus_kpa`, camera noise `sigma_a_mm` and `points_per_mm` points.
pub fn recommend_pressure(
    model: &LutModel<'_>,
    modulus_kpa: f64,
    sigma_a_mm: f64,
    points_per_mm: f64,
) -> (Vec<PressureSensitivity>, Option<usize>) {
    let mut out = Vec::new();
    for &p in model.pressures_kpa() {
        let Ok((lo, hi)) = model.u_s_range_mm(modulus_kpa, p) else {
            continue;
        };
        let lo = lo.max(0.0);
        if hi <= lo {
            continue;
        }
        let n = 64;
        let mut integral = 0.0;
        let mut sum_sq = 0.0;
        let du = (hi - lo) / n as f64;
        for k in 0..n {
            let u = lo + (k as f64 + 0.5) * du;
            if let Ok(s) = model.sample(modulus_kpa, p, u) {
                integral += s.da_dln_modulus_mm.powi(2) * du;
                sum_sq += s.da_dln_modulus_mm.powi(2);
            }
        }
        let info = points_per_mm * integral / (sigma_a_mm * sigma_a_mm);
        out.push(PressureSensitivity {
            p_air_kpa: p,
            u_s_max_mm: hi,
            rms_da_dln_modulus_mm: (sum_sq / n as f64).sqrt(),
            predicted_relative_se: if info > 0.0 {
                1.0 / info.sqrt()
            } else {
                f64::INFINITY
            },
        });
    }
    let best = out
        .iter()
        .enumerate()
        .min_by(|a, b| {
            a.1.predicted_relative_se
                .total_cmp(&b.1.predicted_relative_se)
        })
        .map(|(i, _)| i);
    (out, best)
}
