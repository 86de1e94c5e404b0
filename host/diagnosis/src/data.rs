//! The measured points of a diagnosis: loading rows of one or more curve CSVs, each with its
//! pressure and replicate. Replicates are the `test` column; files without one count as one
//! replicate each. Points are kept sorted by (pressure, replicate, u_s), the order the noise
//! model's covariance blocks and the runs test use.

use fit::curve_csv::{CurveCsv, Phase};

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
    /// The tube's travel from first contact (mm), where the data record it.
    pub h_mm: Option<f64>,
    /// `h_mm` is a stage position whose zero, the stage at first contact, is not known:
    /// the travel check fits it per indentation, a replicate at one pressure
    /// ([`crate::travel`]).
    pub h_zero_fitted: bool,
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
                // a record's stage position stands in for the travel, its zero (the
                // stage at first contact) unknown
                h_mm: row.h_mm.or(row.stage_mm),
                h_zero_fitted: row.h_mm.is_none() && row.stage_mm.is_some(),
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

/// The indices of `order` at each pressure (increasing; pressures without any left out),
/// in the order given.
pub fn indices_by_pressure(points: &[Point], order: &[usize]) -> Vec<(f64, Vec<usize>)> {
    pressures(points)
        .into_iter()
        .map(|p| {
            let idx: Vec<usize> = order
                .iter()
                .copied()
                .filter(|&i| points[i].p_air_kpa == p)
                .collect();
            (p, idx)
        })
        .filter(|(_, idx)| !idx.is_empty())
        .collect()
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
pub fn to_fit_points(points: &[Point]) -> Vec<fit::FitPoint> {
    points
        .iter()
        .map(|p| fit::FitPoint {
            u_s_mm: p.u_s_mm,
            a_mm: p.a_mm,
            p_air_kpa: p.p_air_kpa,
            test: p.test,
            load_n: p.load_n,
        })
        .collect()
}

/// Most points of one pressure the analysis takes as they are: its noise model whitens each
/// pressure's points with a dense Cholesky factor (memory n^2, time n^3), so beyond this
/// the points are binned first (see [`bin_points`]).
pub const MAX_POINTS_PER_PRESSURE: usize = 1200;

/// Bins each pressure with more than `max_per_pressure` points: consecutive points of one
/// replicate (in u_s order) are replaced by their mean (u_s, a, and load, time and travel
/// where every point of the bin has them), `k` points a bin with `k` the smallest that
/// brings the pressure within the limit (plus at most one partial bin per replicate). The noise model is then estimated from the bin
/// means, so it describes them (their white noise is 1/sqrt(k) of the points'). Memory
/// and time stay linear in the input. `points` must be sorted ([`sort_points`]); returns
/// the bin size used at each binned pressure.
pub fn bin_points(points: &mut Vec<Point>, max_per_pressure: usize) -> Vec<(f64, usize)> {
    let mut used = Vec::new();
    let mut out = Vec::with_capacity(points.len().min(max_per_pressure * 8));
    let mut start = 0;
    while start < points.len() {
        let p = points[start].p_air_kpa;
        let end = start + points[start..].partition_point(|q| q.p_air_kpa == p);
        let n = end - start;
        let k = n.div_ceil(max_per_pressure.max(1));
        if k <= 1 {
            out.extend_from_slice(&points[start..end]);
        } else {
            used.push((p, k));
            let mut s = start;
            while s < end {
                let test = points[s].test;
                let run_end = s + points[s..end].partition_point(|q| q.test == test);
                for bin in points[s..run_end].chunks(k) {
                    out.push(mean_point(bin));
                }
                s = run_end;
            }
        }
        start = end;
    }
    *points = out;
    used
}

fn mean_point(bin: &[Point]) -> Point {
    let m = bin.len() as f64;
    let mean = |f: &dyn Fn(&Point) -> f64| bin.iter().map(f).sum::<f64>() / m;
    let mean_opt = |f: &dyn Fn(&Point) -> Option<f64>| {
        bin.iter()
            .map(f)
            .sum::<Option<f64>>()
            .map(|total| total / m)
    };
    Point {
        u_s_mm: mean(&|q| q.u_s_mm),
        a_mm: mean(&|q| q.a_mm),
        p_air_kpa: bin[0].p_air_kpa,
        test: bin[0].test,
        load_n: mean_opt(&|q| q.load_n),
        t_s: mean_opt(&|q| q.t_s),
        h_mm: mean_opt(&|q| q.h_mm),
        h_zero_fitted: bin.iter().any(|q| q.h_zero_fitted),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(p: f64, test: u32, u: f64) -> Point {
        Point {
            u_s_mm: u,
            a_mm: 2.0 * u,
            p_air_kpa: p,
            test,
            load_n: Some(u),
            t_s: None,
            h_mm: Some(u),
            h_zero_fitted: false,
        }
    }

    #[test]
    fn binning_keeps_small_pressures_and_averages_within_a_replicate() {
        let mut pts: Vec<Point> = (0..10).map(|k| point(6.0, 0, k as f64)).collect();
        pts.extend((0..7).map(|k| point(6.0, 1, k as f64)));
        pts.extend((0..4).map(|k| point(15.0, 0, k as f64)));
        let used = bin_points(&mut pts, 6);
        // 17 points at 6 kPa need bins of 3; replicate 0 gives 4 bins (3,3,3,1), replicate 1
        // gives 3 (3,3,1); 15 kPa is within the limit and untouched.
        assert_eq!(used, vec![(6.0, 3)]);
        assert_eq!(pts.len(), 4 + 3 + 4);
        assert_eq!(pts[0].u_s_mm, 1.0);
        assert_eq!(pts[0].a_mm, 2.0);
        assert_eq!(pts[0].load_n, Some(1.0));
        assert_eq!(pts[3].u_s_mm, 9.0);
        assert_eq!(pts[3].t_s, None);
        assert!(pts[..7].iter().all(|q| q.p_air_kpa == 6.0));
        assert_eq!(pts[4].test, 1);
        assert_eq!(
            &pts[7..].iter().map(|q| q.u_s_mm).collect::<Vec<_>>(),
            &[0.0, 1.0, 2.0, 3.0]
        );
    }

    #[test]
    fn binning_bounds_every_pressure() {
        let mut pts: Vec<Point> = (0..20_000)
            .map(|k| point(6.0, (k / 5000) as u32, (k % 5000) as f64 * 1e-4))
            .collect();
        bin_points(&mut pts, MAX_POINTS_PER_PRESSURE);
        assert!(pts.len() <= MAX_POINTS_PER_PRESSURE, "{}", pts.len());
        assert!(pts.len() > MAX_POINTS_PER_PRESSURE / 2);
    }
}
