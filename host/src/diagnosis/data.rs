//! The measured points of a diagnosis: loading rows of one or more curve CSVs, each with its
//! pressure and replicate. Replicates are the `test` column; files without one count as one
//! replicate each. Points are kept sorted by (pressure, replicate, u_s), the order the noise
//! model's covariance blocks and the runs test use.

use crate::curve_csv::{CurveCsv, Phase};

/// One measured point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub u_s_mm: f64,
    pub a_mm: f64,
    pub p_air_kpa: f64,
    /// Replicate id (unique over all files).
    pub test: u32,
    pub load_n: Option<f64>,
    pub t_s: Option<f64>,
    pub h_mm: Option<f64>,
}

/// Why the curves cannot be diagnosed.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{file}: no internal pressure: give a p_air_kpa column or a '# p_air_kpa: <kPa>' line")]
    NoPressure { file: String },
    #[error("{file}: '# p_air_kpa: {value}' is not a number")]
    BadPressure { file: String, value: String },
    #[error("{file}: no loading points with contact (a_mm > 0)")]
    Empty { file: String },
}

/// Loading points with contact from `curves` (each with its file name for errors).
pub fn points_from_curves(curves: &[(String, CurveCsv)]) -> Result<Vec<Point>, DataError> {
    let mut out = Vec::new();
    for (k, (file, curve)) in curves.iter().enumerate() {
        let default_p = match curve.meta("p_air_kpa") {
            Some(v) => Some(
                v.trim()
                    .parse::<f64>()
                    .map_err(|_| DataError::BadPressure {
                        file: file.clone(),
                        value: v.to_string(),
                    })?,
            ),
            None => None,
        };
        let before = out.len();
        for row in &curve.rows {
            if row.phase == Some(Phase::Unload)
                || row.a_mm.is_nan()
                || row.a_mm <= 0.0
                || !row.u_s_mm.is_finite()
            {
                continue;
            }
            let p = row
                .p_air_kpa
                .or(default_p)
                .ok_or_else(|| DataError::NoPressure { file: file.clone() })?;
            out.push(Point {
                u_s_mm: row.u_s_mm,
                a_mm: row.a_mm,
                p_air_kpa: p,
                test: k as u32 * 10_000 + row.test.unwrap_or(0),
                load_n: row.load_n,
                t_s: row.t_s,
                h_mm: row.h_mm,
            });
        }
        if out.len() == before {
            return Err(DataError::Empty { file: file.clone() });
        }
    }
    sort_points(&mut out);
    Ok(out)
}

/// Sorts by (pressure, replicate, u_s).
pub fn sort_points(points: &mut [Point]) {
    points.sort_by(|a, b| {
        a.p_air_kpa
            .total_cmp(&b.p_air_kpa)
            .then(a.test.cmp(&b.test))
            .then(a.u_s_mm.total_cmp(&b.u_s_mm))
    });
}

/// Distinct pressures, increasing.
pub fn pressures(points: &[Point]) -> Vec<f64> {
    let mut v: Vec<f64> = points.iter().map(|p| p.p_air_kpa).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// Distinct replicate ids at pressure `p`.
pub fn tests_at(points: &[Point], p: f64) -> Vec<u32> {
    let mut v: Vec<u32> = points
        .iter()
        .filter(|q| q.p_air_kpa == p)
        .map(|q| q.test)
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// The host fit's view of points.
pub fn to_fit_points(points: &[Point]) -> Vec<crate::fit::FitPoint> {
    points
        .iter()
        .map(|p| crate::fit::FitPoint {
            u_s_mm: p.u_s_mm,
            a_mm: p.a_mm,
            p_air_kpa: p.p_air_kpa,
            test: p.test,
            load_n: p.load_n,
        })
        .collect()
}
