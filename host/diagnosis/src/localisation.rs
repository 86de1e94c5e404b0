//! Where the baseline disagrees with the data.
//!
//! - Whitened residuals per channel x pressure x depth window: the Cholesky-whitened
//!   residuals are, under the noise model, independent N(0, 1) innovations in (test, u_s)
//!   order, so a window of n of them has mean ~ N(0, 1/n) and sum of squares ~ chi^2(n); a
//!   window is flagged when |z| = |mean| sqrt(n) > 3 or the chi^2 tail is below 1e-3. The
//!   load channel (P–u_s, when present) is standardised by its own replicate scatter (white
//!   deviations from the replicate-mean curve; a simpler noise model, stated).
//! - Apparent modulus per depth window and per pressure: the host's fit on each subset (a
//!   trend over depth or a gap between pressures locates the problem).
//! - Runs test (Wald–Wolfowitz) on the signs of the whitened residuals along each curve.
//! - Lack of fit: the whitened chi^2 against chi^2(n - 1) (the noise model comes from the
//!   replicate scatter, so this is the classical lack-of-fit test against pure error with
//!   the within-curve correlation taken into account).

use serde::Serialize;

use super::data::Point;
use super::stats::{chi2_sf, normal_sf, runs_test};

/// Number of depth windows per pressure.
pub const DEPTH_WINDOWS: usize = 4;

/// One channel x pressure x depth window.
#[derive(Debug, Clone, Serialize)]
pub struct Cell {
    pub channel: String,
    pub p_air_kpa: f64,
    pub u_s_range_mm: [f64; 2],
    pub points: usize,
    pub mean_whitened: f64,
    pub rms_whitened: f64,
    /// Mean raw residual (mm for a, N for P).
    pub mean_residual: f64,
    pub z: f64,
    pub chi2_p: f64,
    pub flagged: bool,
}

impl Cell {
    /// "load at 6 kPa, u_s 0.47..0.88 mm (z -4.1)": where the window lies and how far off.
    pub fn describe(&self) -> String {
        format!(
            "{} at {} kPa, u_s {:.2}..{:.2} mm (z {:+.1})",
            if self.channel == "a" {
                "radius"
            } else {
                "load"
            },
            self.p_air_kpa,
            self.u_s_range_mm[0],
            self.u_s_range_mm[1],
            self.z
        )
    }
}

/// Apparent modulus of one subset.
#[derive(Debug, Clone, Serialize)]
pub struct ApparentModulus {
    pub p_air_kpa: f64,
    pub u_s_range_mm: Option<[f64; 2]>,
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
}

#[derive(Debug, Clone, Serialize)]
pub struct RunsTest {
    pub runs: usize,
    pub expected: f64,
    pub z: f64,
    pub p_value: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct LackOfFit {
    pub chi2: f64,
    pub dof: usize,
    pub p_value: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Localisation {
    pub cells: Vec<Cell>,
    pub window_moduli: Vec<ApparentModulus>,
    pub pressure_moduli: Vec<ApparentModulus>,
    /// Slope of ln(apparent E2) per mm of u_s over the windows (all pressures pooled).
    pub modulus_trend_per_mm: Option<f64>,
    pub runs: RunsTest,
    pub lack_of_fit: LackOfFit,
}

fn windows_of(points: &[Point], idx: &[usize]) -> Vec<[f64; 2]> {
    let lo = idx
        .iter()
        .map(|&i| points[i].u_s_mm)
        .fold(f64::INFINITY, f64::min);
    let hi = idx
        .iter()
        .map(|&i| points[i].u_s_mm)
        .fold(f64::NEG_INFINITY, f64::max);
    let w = (hi - lo) / DEPTH_WINDOWS as f64;
    (0..DEPTH_WINDOWS)
        .map(|k| [lo + k as f64 * w, lo + (k + 1) as f64 * w])
        .collect()
}

fn in_window(u: f64, w: [f64; 2], last: bool) -> bool {
    u >= w[0] && (u < w[1] || (last && u <= w[1]))
}

fn cell(channel: &str, p: f64, w: [f64; 2], wv: &[f64], raw: &[f64]) -> Cell {
    let n = wv.len();
    let mean = wv.iter().sum::<f64>() / n.max(1) as f64;
    let ss: f64 = wv.iter().map(|v| v * v).sum();
    let z = mean * (n as f64).sqrt();
    let chi2_p = chi2_sf(ss, n as f64);
    Cell {
        channel: channel.into(),
        p_air_kpa: p,
        u_s_range_mm: w,
        points: n,
        mean_whitened: mean,
        rms_whitened: (ss / n.max(1) as f64).sqrt(),
        mean_residual: raw.iter().sum::<f64>() / n.max(1) as f64,
        z,
        chi2_p,
        flagged: n > 0 && (z.abs() > 3.0 || chi2_p < 1e-3),
    }
}

/// Whitened-residual cells of the a channel, the runs test and the lack-of-fit test.
/// `order` gives the point index of each whitened value `w`; `r` are raw residuals (mm).
pub fn a_channel(
    points: &[Point],
    order: &[usize],
    w: &[f64],
    r: &[f64],
) -> (Vec<Cell>, RunsTest, LackOfFit) {
    let mut cells = Vec::new();
    for (p, idx) in super::data::indices_by_pressure(points, order) {
        let wins = windows_of(points, &idx);
        for (k, win) in wins.iter().enumerate() {
            let last = k + 1 == wins.len();
            let (mut wv, mut raw) = (Vec::new(), Vec::new());
            for (j, &i) in order.iter().enumerate() {
                if points[i].p_air_kpa == p && in_window(points[i].u_s_mm, *win, last) {
                    wv.push(w[j]);
                    raw.push(r[i]);
                }
            }
            if !wv.is_empty() {
                cells.push(cell("a", p, *win, &wv, &raw));
            }
        }
    }
    // runs along each curve
    let mut seqs: Vec<Vec<bool>> = Vec::new();
    let mut last: Option<(f64, u32)> = None;
    for (j, &i) in order.iter().enumerate() {
        let key = (points[i].p_air_kpa, points[i].test);
        if last != Some(key) {
            seqs.push(Vec::new());
            last = Some(key);
        }
        if let Some(s) = seqs.last_mut() {
            s.push(w[j] >= 0.0);
        }
    }
    let (runs, expected, z) = runs_test(&seqs);
    let chi2: f64 = w.iter().map(|v| v * v).sum();
    let dof = w.len().saturating_sub(1).max(1);
    (
        cells,
        RunsTest {
            runs,
            expected,
            z,
            p_value: 1.0 - normal_sf(z), // one-sided: too few runs
        },
        LackOfFit {
            chi2,
            dof,
            p_value: chi2_sf(chi2, dof as f64),
        },
    )
}

/// Cells of the load channel: residuals `rl` (N, NaN where no load) standardised by the
/// scatter of replicate deviations from the replicate mean in u_s bins.
pub fn load_channel(points: &[Point], subset: &[usize], rl: &[f64]) -> Vec<Cell> {
    let mut cells = Vec::new();
    for p in super::data::pressures(points) {
        let idx: Vec<usize> = subset
            .iter()
            .copied()
            .filter(|&i| points[i].p_air_kpa == p && rl[i].is_finite())
            .collect();
        let tests = super::data::tests_at(points, p);
        if idx.len() < 8 || tests.len() < 2 {
            continue;
        }
        let wins = windows_of(points, &idx);
        // replicate scatter: deviations from the window-bin means over 12 bins
        let k = 12;
        let lo = wins[0][0];
        let hi = wins[wins.len() - 1][1];
        let bw = ((hi - lo) / k as f64).max(1e-12);
        let bin = |u: f64| (((u - lo) / bw) as usize).min(k - 1);
        let mut sums = vec![(0.0, 0usize); k];
        for &i in &idx {
            let b = bin(points[i].u_s_mm);
            sums[b].0 += rl[i];
            sums[b].1 += 1;
        }
        let m = tests.len() as f64;
        let var = idx
            .iter()
            .map(|&i| {
                let b = bin(points[i].u_s_mm);
                (rl[i] - sums[b].0 / sums[b].1 as f64).powi(2)
            })
            .sum::<f64>()
            / idx.len() as f64
            * m
            / (m - 1.0);
        let sd = var.sqrt().max(1e-12);
        for (kw, win) in wins.iter().enumerate() {
            let last = kw + 1 == wins.len();
            let sel: Vec<usize> = idx
                .iter()
                .copied()
                .filter(|&i| in_window(points[i].u_s_mm, *win, last))
                .collect();
            if sel.is_empty() {
                continue;
            }
            let wv: Vec<f64> = sel.iter().map(|&i| rl[i] / sd).collect();
            let raw: Vec<f64> = sel.iter().map(|&i| rl[i]).collect();
            // points within a curve are correlated here: use the mean of per-test means
            let mut c = cell("P", p, *win, &wv, &raw);
            let per_test: Vec<f64> = tests
                .iter()
                .filter_map(|t| {
                    let v: Vec<f64> = sel
                        .iter()
                        .filter(|&&i| points[i].test == *t)
                        .map(|&i| rl[i])
                        .collect();
                    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
                })
                .collect();
            if per_test.len() >= 2 {
                let mt = per_test.len() as f64;
                let mean = per_test.iter().sum::<f64>() / mt;
                let s =
                    (per_test.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (mt - 1.0)).sqrt();
                c.z = mean / (s / mt.sqrt()).max(1e-12);
                c.flagged = c.z.abs() > 4.0;
            }
            cells.push(c);
        }
    }
    cells
}

/// Windows for the apparent-modulus fits: (pressure, u_s range, point indices).
pub fn modulus_windows(points: &[Point], subset: &[usize]) -> Vec<(f64, [f64; 2], Vec<usize>)> {
    let mut out = Vec::new();
    for (p, idx) in super::data::indices_by_pressure(points, subset) {
        let wins = windows_of(points, &idx);
        for (k, w) in wins.iter().enumerate() {
            let last = k + 1 == wins.len();
            let sel: Vec<usize> = idx
                .iter()
                .copied()
                .filter(|&i| in_window(points[i].u_s_mm, *w, last))
                .collect();
            out.push((p, *w, sel));
        }
    }
    out
}

/// Least-squares slope of ln E2 against the window centre.
pub fn trend(moduli: &[ApparentModulus]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = moduli
        .iter()
        .filter_map(|m| {
            m.u_s_range_mm
                .map(|r| (0.5 * (r[0] + r[1]), m.modulus_kpa.ln()))
        })
        .collect();
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxx > 0.0).then(|| pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_names_its_channel_pressure_window_and_z() {
        let cell = Cell {
            channel: "P".into(),
            p_air_kpa: 6.0,
            u_s_range_mm: [0.471, 0.884],
            points: 64,
            mean_whitened: -1.27,
            rms_whitened: 1.58,
            mean_residual: -0.0031,
            z: -4.14,
            chi2_p: 1e-6,
            flagged: true,
        };
        assert_eq!(cell.describe(), "load at 6 kPa, u_s 0.47..0.88 mm (z -4.1)");
        let radius = Cell {
            channel: "a".into(),
            p_air_kpa: 15.0,
            z: 2.56,
            ..cell
        };
        assert_eq!(
            radius.describe(),
            "radius at 15 kPa, u_s 0.47..0.88 mm (z +2.6)"
        );
    }
}
