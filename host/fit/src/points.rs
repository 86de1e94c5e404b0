//! Measured points as the fit sees them, from the curve CSV (`crate::curve_csv`).

use crate::curve_csv::{CurveCsv, Phase};

/// One measured point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitPoint {
    pub u_s_mm: f64,
    pub a_mm: f64,
    pub p_air_kpa: f64,
    /// Replicate index (0 when the file has none).
    pub test: u32,
    pub load_n: Option<f64>,
}

/// Why a curve file cannot be fitted.
#[derive(Debug, thiserror::Error)]
pub enum PointsError {
    #[error("{file}: no internal pressure: give a p_air_kpa column or a '# p_air_kpa: <kPa>' line")]
    NoPressure { file: String },
    #[error("{file}: '# p_air_kpa: {value}' is not a number")]
    BadPressure { file: String, value: String },
    #[error("{file}: no loading points to fit")]
    Empty { file: String },
}

/// The loading points of a curve file (unloading rows are left out: the model is the
/// loading curve). The pressure is the file's `# p_air_kpa:` line (the set point, as a
/// record's curve.csv states it; its rows carry the manometer's noisy readings), else the
/// row's `p_air_kpa`.
pub fn points_from_curve_csv(curve: &CurveCsv, file: &str) -> Result<Vec<FitPoint>, PointsError> {
    let default_p = match curve.meta("p_air_kpa") {
        Some(v) => Some(
            v.trim()
                .parse::<f64>()
                .map_err(|_| PointsError::BadPressure {
                    file: file.to_string(),
                    value: v.to_string(),
                })?,
        ),
        None => None,
    };
    let mut out = Vec::new();
    for row in &curve.rows {
        if row.phase == Some(Phase::Unload) {
            continue;
        }
        let p = default_p
            .or(row.p_air_kpa)
            .ok_or_else(|| PointsError::NoPressure {
                file: file.to_string(),
            })?;
        out.push(FitPoint {
            u_s_mm: row.u_s_mm,
            a_mm: row.a_mm,
            p_air_kpa: p,
            test: row.test.unwrap_or(0),
            load_n: row.load_n,
        });
    }
    if out.is_empty() {
        return Err(PointsError::Empty {
            file: file.to_string(),
        });
    }
    Ok(out)
}

/// The points of a solved fem-core curve at its pressure, noise-free: the load steps in
/// contact with u_s at least `min_u_s_mm` (one replicate, with loads).
pub fn points_from_solved_curve(curve: &fem_core::Curve, min_u_s_mm: f64) -> Vec<FitPoint> {
    curve
        .points
        .iter()
        .filter(|pt| pt.u_s_mm >= min_u_s_mm && pt.a_mm > 0.0)
        .map(|pt| FitPoint {
            u_s_mm: pt.u_s_mm,
            a_mm: pt.a_mm,
            p_air_kpa: curve.params.pressure_kpa,
            test: 0,
            load_n: Some(pt.load_n),
        })
        .collect()
}
