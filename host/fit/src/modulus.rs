//! The modulus estimate.
//!
//! **Estimate.** With x = ln E2, the model a_i(x) = A(x, p_i, u_i) from the table and the
//! residuals r_i = a_i^meas - a_i(x), minimise S(x) = sum r_i^2 (plus, with the load
//! channel, sum (w r^P_i)^2 with w = sigma_a / sigma_P from separate fits). A coarse scan
//! over the table's modulus nodes picks the bracket [E_(k-1), E_(k+1)] around the best
//! node; the points whose u_s every curve of the bracket reaches are kept (soft curves end
//! at smaller u_s), and Gauss–Newton steps dx = sum r_i J_i / sum J_i^2 with J_i =
//! dA/d ln E2 (the table's analytic PCHIP derivative) and step halving converge to the
//! continuous minimum. If it lands on an inner bracket edge the bracket moves and the fit
//! repeats.
//!
//! **95 % interval** (stated in [`ModulusFit::ci_method`]):
//! - residual model, always computed: sigma^2 = S / (n - 1), Var(x) = sigma^2 / sum J^2,
//!   inflated by n / n_eff with n_eff = n (1 - rho) / (1 + rho) from the lag-1
//!   autocorrelation rho of the residuals along each curve (an AR(1) model of the
//!   within-curve correlation), Student t with n_eff - 1 degrees of freedom;
//! - replicates (two or more `test` values with enough points): each replicate is fitted
//!   alone; the standard error of the mean of their ln E2 is sd / sqrt(m), Student t with
//!   m - 1 degrees of freedom. This captures run-to-run scatter whatever its correlation
//!   within a run. The interval uses the larger of the two standard errors;
//! - the table's interpolation in ln E2, added in quadrature: the points are fitted again
//!   with the table interpolated linearly in ln E2 between its nodes, and
//!   |ln E2(PCHIP) - ln E2(linear)| is taken as the half-width (a conservative bound:
//!   linear interpolation's error is second order in the node spacing, PCHIP's higher);
//! - the table's interpolation across p_air between pressure nodes, added in quadrature:
//!   the cubic through four inflated nodes estimates the error of the table's cubic at each
//!   point to leading order, projected on ln E2 (0 when every point lies at a pressure
//!   node).
//!
//! Model error (a wrong friction, thickness, ...) and calibration error are not in the
//! interval: they are systematic and are what the diagnosis looks for.

use serde::Serialize;

use super::model::LutModel;
use super::points::FitPoint;

/// Fit settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Add the load channel (P–u_s) to the objective when the points carry loads.
    pub use_load: bool,
    /// Gauss–Newton iteration limit per bracket.
    pub max_iterations: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            use_load: false,
            max_iterations: 40,
        }
    }
}

/// Why the fit failed.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error(
        "the best fit lies at the table's {} limit, E2 = {limit_kpa:.0} kPa: the sample is {} than the table covers (measure at another pressure, or use a table with a wider modulus range)",
        if *upper { "upper" } else { "lower" },
        if *upper { "stiffer" } else { "softer" }
    )]
    AtTableLimit { limit_kpa: f64, upper: bool },
    #[error("too few points to fit: {usable} usable of {total} (need at least 3)")]
    TooFewPoints { usable: usize, total: usize },
    #[error("pressure {p_air_kpa} kPa is outside the table's pressures {min_kpa}..{max_kpa} kPa")]
    PressureOutsideTable {
        p_air_kpa: f64,
        min_kpa: f64,
        max_kpa: f64,
    },
    #[error("no modulus in the table reaches the measured u_s range: {0}")]
    NoCoverage(String),
    #[error("table: {0}")]
    Lut(#[from] fem_core::lut::LutError),
    #[error("{points} points: the fit takes at most {MAX_FIT_POINTS}; thin or split the curve")]
    TooManyPoints { points: usize },
    #[error(
        "only {in_contact} of {total} points are in contact (a_mm > 0); an indentation curve needs at least 3"
    )]
    NoContact { in_contact: usize, total: usize },
    #[error(
        "the model does not describe this curve: RMS residual {rms_mm:.4} mm against a spread of a of {spread_mm:.4} mm (at most {MISFIT_FLOOR_MM} mm or half the spread is accepted); is it an a–u_s indentation curve at the stated pressure?"
    )]
    ModelMismatch { rms_mm: f64, spread_mm: f64 },
}

/// Most points one fit takes (memory and time grow linearly; a 6-repeat experiment at
/// 60 frames/s has a few thousand).
pub const MAX_FIT_POINTS: usize = 200_000;
/// Goodness-of-fit gate: an RMS radius residual up to this is always accepted (four times
/// the camera's typical 0.005 mm noise)...
pub const MISFIT_FLOOR_MM: f64 = 0.02;
/// ...and above it only while it is at most this fraction of the standard deviation of the
/// measured radii (the model explains at least 75 % of their variance). Noise that the
/// model cannot describe has a residual as large as its spread and is refused.
pub const MISFIT_FRACTION: f64 = 0.5;

/// How the interval was computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CiMethod {
    /// Residual variance with AR(1) within-curve correlation.
    ResidualAr1,
    /// Between-replicate scatter of per-replicate fits (it was the larger term).
    Replicates,
}

/// The single-pressure fit at one pressure of a joint fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PressureFit {
    pub p_air_kpa: f64,
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    pub points: usize,
    pub rms_residual_mm: f64,
}

/// The result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModulusFit {
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    /// RMS of the a residuals of the used points.
    pub rms_residual_mm: f64,
    pub ci_method: CiMethod,
    pub ci_description: String,
    pub points_used: usize,
    /// Points outside the u_s range the table covers near the estimate.
    pub points_excluded: usize,
    pub pressures_kpa: Vec<f64>,
    /// Fits at each pressure alone (when several were measured).
    pub per_pressure: Vec<PressureFit>,
    /// Per-replicate estimates (when replicates are present).
    pub replicate_moduli_kpa: Vec<f64>,
    /// Effective independent points after the AR(1) correction, and the lag-1 correlation.
    pub effective_points: f64,
    pub residual_lag1_correlation: f64,
    /// Standard errors of ln E2: residual model and replicates (0 if none).
    pub se_ln_modulus_residual: f64,
    pub se_ln_modulus_replicates: f64,
    pub iterations: usize,
    /// The same fit with the table interpolated linearly (instead of PCHIP) in ln E2
    /// between its nodes: the difference bounds the table's interpolation error.
    pub modulus_linear_interpolation_kpa: f64,
    /// Half-width (in ln E2) added in quadrature for the table's interpolation error.
    pub interpolation_half_width_ln: f64,
    /// Half-width (in ln E2) added in quadrature for the table's interpolation across p_air
    /// between its pressure nodes (0 when every point lies at a node).
    pub pressure_interpolation_half_width_ln: f64,
    /// The model's discretisation term (the estimated bias ln E - ln E(finer mesh)) when a
    /// finer table was available ([`crate::discretisation`]): subtracted from the estimate
    /// when the finer table is converged, else added in quadrature to the interval.
    pub discretisation_bias_ln: Option<f64>,
    /// The estimate before that correction (the table's own), when it was corrected.
    pub modulus_production_kpa: Option<f64>,
    /// The converged model's own error of a (its header's largest) projected on ln E2 and
    /// added in quadrature to the interval: the fit's table's own when that table is
    /// converged, else the finer reference's when the estimate was corrected to it.
    pub discretisation_residual_ln: Option<f64>,
    pub load_channel_used: bool,
    pub rms_residual_load_n: Option<f64>,
}

/// Core result of one least-squares fit.
#[derive(Debug, Clone)]
struct Core {
    x: f64,
    residuals: Vec<f64>,
    jacobian: Vec<f64>,
    used: Vec<usize>,
    excluded: usize,
    iterations: usize,
    rms_load: Option<f64>,
}

/// Student t quantile t_{0.975, dof}: exact table to 10 degrees of freedom, then the
/// Cornish–Fisher expansion (error < 1e-3).
pub fn t975(dof: f64) -> f64 {
    const TABLE: [f64; 10] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    ];
    if dof < 1.0 {
        return TABLE[0];
    }
    if dof <= 10.0 {
        // linear between integer degrees of freedom
        let k = dof.floor() as usize;
        let f = dof - k as f64;
        let lo = TABLE[k - 1];
        let hi = if k < 10 { TABLE[k] } else { TABLE[9] };
        return lo + f * (hi - lo);
    }
    let z: f64 = 1.959_964;
    let v = dof;
    z + (z.powi(3) + z) / (4.0 * v)
        + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * v * v)
        + (3.0 * z.powi(7) + 19.0 * z.powi(5) + 17.0 * z.powi(3) - 15.0 * z) / (384.0 * v.powi(3))
}

/// One point's a(ln E2) on one interval of the table's modulus axis.
///
/// The table interpolates in ln E2 with PCHIP (fem-core `lut::interp`), then linearly in
/// p_air: on each interval [x_k, x_k+1] a point's a(x) is one cubic Hermite polynomial
/// fixed by the values and slopes at the two nodes (for several pressure nodes, a weighted
/// sum of such cubics, again one). The table's own value and d a / d ln E2 at the nodes
/// (one query per node, shared by the two intervals meeting there) give that cubic, after
/// which every evaluation costs a few multiplications instead of a table query. A node
/// the table cannot answer there (its curve does not reach the point's u_s) falls back to
/// two queries inside the interval (value and slope at x_1, x_2: Hermite again).
#[derive(Debug, Clone, Copy)]
enum IntervalCubic {
    NotYet,
    /// Some bracketing curve does not reach the point's u_s.
    Unavailable,
    /// a(x) = y1 + d1 s + c2 s^2 + c3 s^3 with s = x - x1.
    Cubic {
        x1: f64,
        y1: f64,
        d1: f64,
        c2: f64,
        c3: f64,
    },
}

/// The table's (a, d a / d ln E2) of one point at one node.
#[derive(Debug, Clone, Copy)]
enum NodeValue {
    NotYet,
    Unavailable,
    At(f64, f64),
}

/// The cubic through (x1, y1) with slope d1 and (x2, y2) with slope d2.
fn hermite(x1: f64, y1: f64, d1: f64, x2: f64, y2: f64, d2: f64) -> IntervalCubic {
    let l = x2 - x1;
    let slope = (y2 - y1) / l;
    IntervalCubic::Cubic {
        x1,
        y1,
        d1,
        c2: (3.0 * slope - 2.0 * d1 - d2) / l,
        c3: (d1 + d2 - 2.0 * slope) / (l * l),
    }
}

struct Problem<'m, 'a> {
    model: &'m LutModel<'a>,
    points: &'m [FitPoint],
    /// Weight of load residuals (sigma_a / sigma_P), 0 without the load channel.
    load_weight: f64,
    /// ln of the table's modulus nodes.
    ln_nodes: Vec<f64>,
    /// cubics[interval * points.len() + point], filled on first use.
    cubics: std::cell::RefCell<Vec<IntervalCubic>>,
    /// node_values[node * points.len() + point], filled on first use.
    node_values: std::cell::RefCell<Vec<NodeValue>>,
    /// Interpolate linearly in ln E2 between the node values instead of the table's PCHIP
    /// (the interpolation-error check).
    linear: std::cell::Cell<bool>,
}

impl<'m, 'a> Problem<'m, 'a> {
    fn new(model: &'m LutModel<'a>, points: &'m [FitPoint], load_weight: f64) -> Self {
        let ln_nodes: Vec<f64> = model.moduli_kpa().iter().map(|e| e.ln()).collect();
        let cells = ln_nodes.len().saturating_sub(1) * points.len();
        Self {
            model,
            points,
            load_weight,
            cubics: std::cell::RefCell::new(vec![IntervalCubic::NotYet; cells]),
            node_values: std::cell::RefCell::new(vec![
                NodeValue::NotYet;
                ln_nodes.len() * points.len()
            ]),
            ln_nodes,
            linear: std::cell::Cell::new(false),
        }
    }

    /// The table's a and slope of point `i` at node `k`.
    fn node_value(&self, i: usize, k: usize) -> Option<(f64, f64)> {
        let cell = k * self.points.len() + i;
        let mut nodes = self.node_values.borrow_mut();
        if let NodeValue::NotYet = nodes[cell] {
            let p = &self.points[i];
            nodes[cell] = match self
                .model
                .sample(self.model.moduli_kpa()[k], p.p_air_kpa, p.u_s_mm)
            {
                Ok(s) => NodeValue::At(s.a_mm, s.da_dln_modulus_mm),
                Err(_) => NodeValue::Unavailable,
            };
        }
        match nodes[cell] {
            NodeValue::At(a, d) => Some((a, d)),
            _ => None,
        }
    }

    /// a and d a / d ln E2 of point `i` at ln E2 = `x` (inside the table).
    fn a_at(&self, i: usize, x: f64) -> Option<(f64, f64)> {
        let nodes = &self.ln_nodes;
        if nodes.len() < 2 || !(x >= nodes[0] && x <= nodes[nodes.len() - 1]) {
            return None;
        }
        let k = nodes.partition_point(|&v| v <= x).clamp(1, nodes.len() - 1) - 1;
        if self.linear.get()
            && let (Some((y1, _)), Some((y2, _))) =
                (self.node_value(i, k), self.node_value(i, k + 1))
        {
            let slope = (y2 - y1) / (nodes[k + 1] - nodes[k]);
            return Some((y1 + slope * (x - nodes[k]), slope));
        }
        let cell = k * self.points.len() + i;
        let known = self.cubics.borrow()[cell];
        let cubic = match known {
            IntervalCubic::NotYet => {
                let c = match (self.node_value(i, k), self.node_value(i, k + 1)) {
                    (Some((y1, d1)), Some((y2, d2))) => {
                        hermite(nodes[k], y1, d1, nodes[k + 1], y2, d2)
                    }
                    _ => {
                        let p = &self.points[i];
                        let h = nodes[k + 1] - nodes[k];
                        let (x1, x2) = (nodes[k] + h / 3.0, nodes[k] + 2.0 * h / 3.0);
                        match (
                            self.model.sample(x1.exp(), p.p_air_kpa, p.u_s_mm),
                            self.model.sample(x2.exp(), p.p_air_kpa, p.u_s_mm),
                        ) {
                            (Ok(s1), Ok(s2)) => hermite(
                                x1,
                                s1.a_mm,
                                s1.da_dln_modulus_mm,
                                x2,
                                s2.a_mm,
                                s2.da_dln_modulus_mm,
                            ),
                            _ => IntervalCubic::Unavailable,
                        }
                    }
                };
                self.cubics.borrow_mut()[cell] = c;
                c
            }
            c => c,
        };
        match cubic {
            IntervalCubic::Cubic { x1, y1, d1, c2, c3 } => {
                let s = x - x1;
                Some((
                    y1 + s * (d1 + s * (c2 + s * c3)),
                    d1 + s * (2.0 * c2 + 3.0 * s * c3),
                ))
            }
            _ => None,
        }
    }

    /// Sum of squared a residuals at x (no allocation).
    fn sum_sq_a(&self, x: f64, used: &[usize]) -> Option<f64> {
        let mut s = 0.0;
        for &i in used {
            let (a, _) = self.a_at(i, x)?;
            s += (self.points[i].a_mm - a).powi(2);
        }
        Some(s)
    }

    /// Residuals (a, then weighted load) and d a / d ln E2 at x for the points `used`.
    fn eval(&self, x: f64, used: &[usize], want_j: bool) -> Option<(Vec<f64>, Vec<f64>)> {
        let e = x.exp();
        let mut r = Vec::with_capacity(used.len() * 2);
        let mut j = Vec::with_capacity(if want_j { used.len() * 2 } else { 0 });
        if self.load_weight <= 0.0 {
            for &i in used {
                let (a, da) = self.a_at(i, x)?;
                r.push(self.points[i].a_mm - a);
                if want_j {
                    j.push(da);
                }
            }
            return Some((r, j));
        }
        let mut rl = Vec::new();
        let mut jl = Vec::new();
        for &i in used {
            let p = &self.points[i];
            let s = self.model.sample(e, p.p_air_kpa, p.u_s_mm).ok()?;
            r.push(p.a_mm - s.a_mm);
            if want_j {
                j.push(s.da_dln_modulus_mm);
            }
            if self.load_weight > 0.0
                && let Some(load) = p.load_n
            {
                rl.push(self.load_weight * (load - s.load_n));
                if want_j {
                    // dP/d ln E2 by a central difference inside the table
                    let h = 1e-4;
                    let (lo, hi) = self.ln_range();
                    let (xa, xb) = ((x - h).max(lo), (x + h).min(hi));
                    let pa = self.model.sample(xa.exp(), p.p_air_kpa, p.u_s_mm).ok()?;
                    let pb = self.model.sample(xb.exp(), p.p_air_kpa, p.u_s_mm).ok()?;
                    jl.push(self.load_weight * (pb.load_n - pa.load_n) / (xb - xa));
                }
            }
        }
        r.extend(rl);
        j.extend(jl);
        Some((r, j))
    }

    fn ln_range(&self) -> (f64, f64) {
        let m = self.model.moduli_kpa();
        (m[0].ln(), m[m.len() - 1].ln())
    }

    fn sum_sq(&self, x: f64, used: &[usize]) -> Option<f64> {
        if self.load_weight <= 0.0 {
            return self.sum_sq_a(x, used);
        }
        self.eval(x, used, false)
            .map(|(r, _)| r.iter().map(|v| v * v).sum())
    }

    /// Points whose u_s the whole modulus bracket covers.
    fn usable(
        &self,
        lo_kpa: f64,
        hi_kpa: f64,
        subset: &[usize],
    ) -> Result<(Vec<usize>, usize), FitError> {
        let mut ranges: Vec<(f64, (f64, f64))> = Vec::new();
        let mut used = Vec::new();
        let mut excluded = 0;
        for &i in subset {
            let p = &self.points[i];
            let range = match ranges.iter().find(|(q, _)| *q == p.p_air_kpa) {
                Some((_, r)) => *r,
                None => {
                    let r = self
                        .model
                        .common_u_s_range_mm(lo_kpa, hi_kpa, p.p_air_kpa)?;
                    ranges.push((p.p_air_kpa, r));
                    r
                }
            };
            if p.u_s_mm >= range.0 && p.u_s_mm <= range.1 && p.a_mm.is_finite() {
                used.push(i);
            } else {
                excluded += 1;
            }
        }
        Ok((used, excluded))
    }

    /// Least squares over `subset` of the points.
    fn solve(
        &self,
        subset: &[usize],
        max_iterations: usize,
        start_node: Option<usize>,
    ) -> Result<Core, FitError> {
        let nodes = self.model.moduli_kpa().to_vec();
        // coarse scan: mean square residual at each node over the points it covers
        let mut best: Option<(usize, f64)> = None;
        // (on at most ~16 evenly spread points: the scan only picks the bracket, and a
        // bracket one node off is corrected by the bracket moves below)
        let stride = subset.len().div_ceil(16).max(1);
        let scan: Vec<usize> = if start_node.is_some() {
            Vec::new()
        } else {
            subset.iter().step_by(stride).copied().collect()
        };
        if let Some(k) = start_node {
            best = Some((k.min(nodes.len() - 1), 0.0));
        }
        for k in (0..nodes.len()).filter(|_| start_node.is_none()) {
            let mut sum = 0.0;
            let mut n = 0usize;
            for &i in &scan {
                if let Some((a, _)) = self.node_value(i, k) {
                    sum += (self.points[i].a_mm - a).powi(2);
                    n += 1;
                }
            }
            // a node must explain most of the points to be a candidate
            if n * 2 >= scan.len() && n >= 3 {
                let ms = sum / n as f64;
                if best.is_none_or(|(_, b)| ms < b) {
                    best = Some((k, ms));
                }
            }
        }
        let Some((mut k, _)) = best else {
            return Err(FitError::NoCoverage(format!(
                "{} points, u_s up to {:.3} mm",
                subset.len(),
                subset
                    .iter()
                    .map(|&i| self.points[i].u_s_mm)
                    .fold(0.0, f64::max)
            )));
        };
        let mut total_iterations = 0;
        let mut last: Option<Core> = None;
        for _round in 0..4 {
            let k0 = k.saturating_sub(1);
            let k1 = (k + 1).min(nodes.len() - 1);
            let (lo, hi) = (nodes[k0].ln(), nodes[k1].ln());
            let (used, excluded) = self.usable(nodes[k0], nodes[k1], subset)?;
            if used.len() < 3 {
                return Err(FitError::TooFewPoints {
                    usable: used.len(),
                    total: subset.len(),
                });
            }
            let mut x = nodes[k].ln();
            let mut s = self.sum_sq(x, &used).unwrap_or(f64::INFINITY);
            for _ in 0..max_iterations {
                total_iterations += 1;
                let Some((r, j)) = self.eval(x, &used, true) else {
                    break;
                };
                let jj: f64 = j.iter().map(|v| v * v).sum();
                if jj <= 0.0 {
                    break;
                }
                let rj: f64 = r.iter().zip(&j).map(|(a, b)| a * b).sum();
                let mut step = rj / jj;
                let mut accepted = false;
                for _ in 0..30 {
                    let xn = (x + step).clamp(lo, hi);
                    if let Some(sn) = self.sum_sq(xn, &used)
                        && sn <= s
                    {
                        let moved = (xn - x).abs();
                        x = xn;
                        s = sn;
                        accepted = moved > 0.0;
                        break;
                    }
                    step *= 0.5;
                }
                if !accepted || step.abs() < 1e-9 {
                    break;
                }
            }
            let (residuals, jacobian) = self
                .eval(x, &used, true)
                .ok_or_else(|| FitError::NoCoverage("lost coverage at the estimate".into()))?;
            let rms_load = if self.load_weight > 0.0 {
                let nl = residuals.len() - used.len();
                (nl > 0).then(|| {
                    (residuals[used.len()..]
                        .iter()
                        .map(|v| (v / self.load_weight).powi(2))
                        .sum::<f64>()
                        / nl as f64)
                        .sqrt()
                })
            } else {
                None
            };
            let core = Core {
                x,
                residuals,
                jacobian,
                used,
                excluded,
                iterations: total_iterations,
                rms_load,
            };
            // on an inner bracket edge: move the bracket and refit
            let at_lo = (x - lo).abs() < 1e-9 && k0 > 0;
            let at_hi = (x - hi).abs() < 1e-9 && k1 < nodes.len() - 1;
            // on the table's outer edge the estimate is a clamp, not a minimum
            let first = nodes[0].ln();
            let final_node = nodes[nodes.len() - 1].ln();
            if (x - first).abs() < 1e-9 || (x - final_node).abs() < 1e-9 {
                let upper = (x - final_node).abs() < 1e-9;
                return Err(FitError::AtTableLimit {
                    limit_kpa: x.exp(),
                    upper,
                });
            }
            last = Some(core);
            if at_lo {
                k = k0;
            } else if at_hi {
                k = k1;
            } else {
                break;
            }
        }
        last.ok_or_else(|| FitError::NoCoverage("no bracket".into()))
    }
}

/// Lag-1 autocorrelation of the a residuals along each curve (points grouped by pressure
/// and replicate, ordered by u_s).
fn lag1_correlation(points: &[FitPoint], used: &[usize], residuals: &[f64]) -> f64 {
    let mut order: Vec<usize> = (0..used.len()).collect();
    order.sort_by(|&a, &b| {
        let (pa, pb) = (&points[used[a]], &points[used[b]]);
        pa.p_air_kpa
            .total_cmp(&pb.p_air_kpa)
            .then(pa.test.cmp(&pb.test))
            .then(pa.u_s_mm.total_cmp(&pb.u_s_mm))
    });
    let mean = residuals[..used.len()].iter().sum::<f64>() / used.len() as f64;
    let var: f64 = residuals[..used.len()]
        .iter()
        .map(|r| (r - mean).powi(2))
        .sum();
    if var <= 0.0 {
        return 0.0;
    }
    let mut cov = 0.0;
    for w in order.windows(2) {
        let (a, b) = (&points[used[w[0]]], &points[used[w[1]]]);
        if a.p_air_kpa == b.p_air_kpa && a.test == b.test {
            cov += (residuals[w[0]] - mean) * (residuals[w[1]] - mean);
        }
    }
    (cov / var).clamp(-0.99, 0.99)
}

/// The table's interpolation across p_air carried into ln E2: each used point's estimated
/// error of it, delta_i ([`LutModel::pressure_interpolation_error_mm`], 0 at a pressure node),
/// projected on the fit's sensitivity s_i = d a / d ln E2 at the estimate,
/// `|sum s_i delta_i| / sum s_i^2` (to first order, the shift of a least-squares fit of
/// ln E2 when every a_i moves by delta_i).
fn pressure_interpolation_ln(
    model: &LutModel<'_>,
    points: &[FitPoint],
    used: &[usize],
    modulus_kpa: f64,
) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for p in used.iter().map(|&i| &points[i]) {
        let Ok(s) = model.sample(modulus_kpa, p.p_air_kpa, p.u_s_mm) else {
            continue;
        };
        let slope = s.da_dln_modulus_mm;
        den += slope * slope;
        if let Some(delta) =
            model.pressure_interpolation_error_mm(modulus_kpa, p.p_air_kpa, p.u_s_mm)
        {
            num += slope * delta;
        }
    }
    if den > 0.0 { (num / den).abs() } else { 0.0 }
}

/// Fits E2 to `points` (any number of pressures and replicates).
pub fn fit_modulus(
    model: &LutModel<'_>,
    points: &[FitPoint],
    options: FitOptions,
) -> Result<ModulusFit, FitError> {
    if points.len() > MAX_FIT_POINTS {
        return Err(FitError::TooManyPoints {
            points: points.len(),
        });
    }
    let in_contact = points.iter().filter(|p| p.a_mm > 0.0).count();
    if in_contact < 3 {
        return Err(FitError::NoContact {
            in_contact,
            total: points.len(),
        });
    }
    let pressures_axis = model.pressures_kpa();
    let (pmin, pmax) = (pressures_axis[0], pressures_axis[pressures_axis.len() - 1]);
    let mut pressures: Vec<f64> = Vec::new();
    for p in points {
        if p.p_air_kpa < pmin || p.p_air_kpa > pmax {
            return Err(FitError::PressureOutsideTable {
                p_air_kpa: p.p_air_kpa,
                min_kpa: pmin,
                max_kpa: pmax,
            });
        }
        if !pressures.contains(&p.p_air_kpa) {
            model.check_pressure(p.p_air_kpa)?;
            pressures.push(p.p_air_kpa);
        }
    }
    pressures.sort_by(f64::total_cmp);
    // Points without a contact seen (a = 0: before contact, or a frame the vision declined)
    // are not measurements of a(u_s): the table has a > 0 wherever it is read.
    let all: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].a_mm > 0.0)
        .collect();
    let a_only = Problem::new(model, points, 0.0);
    let mut core = a_only.solve(&all, options.max_iterations, None)?;
    let n = core.used.len();
    let sigma_a = (core.residuals[..n].iter().map(|r| r * r).sum::<f64>()
        / (n.saturating_sub(1).max(1)) as f64)
        .sqrt();
    let mut load_used = false;
    if options.use_load
        && core
            .used
            .iter()
            .filter(|&&i| points[i].load_n.is_some())
            .count()
            >= 3
    {
        // sigma_P from the load residuals at the a-only estimate
        let e = core.x.exp();
        let mut sum = 0.0;
        let mut m = 0usize;
        for &i in &core.used {
            if let Some(load) = points[i].load_n
                && let Ok(s) = model.sample(e, points[i].p_air_kpa, points[i].u_s_mm)
            {
                sum += (load - s.load_n).powi(2);
                m += 1;
            }
        }
        let sigma_p = (sum / m.max(1) as f64).sqrt();
        if sigma_p > 0.0 && sigma_a > 0.0 {
            let with_load = Problem::new(model, points, sigma_a / sigma_p);
            core = with_load.solve(&all, options.max_iterations, None)?;
            load_used = true;
        }
    }
    let n = core.used.len();
    let sum_sq_a: f64 = core.residuals[..n].iter().map(|r| r * r).sum();
    let rms = (sum_sq_a / n as f64).sqrt();
    let spread = {
        let mean = core.used.iter().map(|&i| points[i].a_mm).sum::<f64>() / n as f64;
        (core
            .used
            .iter()
            .map(|&i| (points[i].a_mm - mean).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt()
    };
    if rms.is_nan() || rms > MISFIT_FLOOR_MM.max(MISFIT_FRACTION * spread) {
        return Err(FitError::ModelMismatch {
            rms_mm: rms,
            spread_mm: spread,
        });
    }
    let s_total: f64 = core.residuals.iter().map(|r| r * r).sum();
    let jj: f64 = core.jacobian.iter().map(|j| j * j).sum();
    let m_total = core.residuals.len();
    let sigma2 = s_total / (m_total.saturating_sub(1).max(1)) as f64;
    let rho = lag1_correlation(points, &core.used, &core.residuals).max(0.0);
    let n_eff = (n as f64 * (1.0 - rho) / (1.0 + rho)).clamp(2.0, n as f64);
    let se_resid = if jj > 0.0 {
        (sigma2 / jj * n as f64 / n_eff).sqrt()
    } else {
        f64::INFINITY
    };
    let half_resid = t975(n_eff - 1.0) * se_resid;

    // replicates
    let mut tests: Vec<u32> = points.iter().map(|p| p.test).collect();
    tests.sort_unstable();
    tests.dedup();
    let mut replicate_moduli = Vec::new();
    if tests.len() >= 2 {
        // the joint fit's problem (its cubics are reused), started at the node nearest
        // the joint estimate (a replicate is the same sample: no coarse scan needed)
        let problem = &a_only;
        let start = model
            .moduli_kpa()
            .iter()
            .enumerate()
            .min_by(|a, b| {
                (a.1.ln() - core.x)
                    .abs()
                    .total_cmp(&(b.1.ln() - core.x).abs())
            })
            .map(|(k, _)| k);
        for t in &tests {
            let subset: Vec<usize> = (0..points.len())
                .filter(|&i| points[i].test == *t)
                .collect();
            if subset.len() >= 3
                && let Ok(c) = problem.solve(&subset, options.max_iterations, start)
            {
                replicate_moduli.push(c.x.exp());
            }
        }
    }
    let (se_rep, half_rep) = if replicate_moduli.len() >= 2 {
        let m = replicate_moduli.len() as f64;
        let logs: Vec<f64> = replicate_moduli.iter().map(|e| e.ln()).collect();
        let mean = logs.iter().sum::<f64>() / m;
        let sd = (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (m - 1.0)).sqrt();
        let se = sd / m.sqrt();
        (se, t975(m - 1.0) * se)
    } else {
        (0.0, 0.0)
    };
    // Table interpolation: the same points fitted with the table interpolated linearly in
    // ln E2 between its nodes. Linear interpolation's error (second order in the node
    // spacing) is larger than PCHIP's, so |ln E_pchip - ln E_linear| is a conservative
    // estimate of the PCHIP table's interpolation error at this estimate; it is added in
    // quadrature to the statistical half-width (it is systematic: replicates share it).
    let nearest_node = |x: f64| {
        model
            .moduli_kpa()
            .iter()
            .enumerate()
            .min_by(|a, b| (a.1.ln() - x).abs().total_cmp(&(b.1.ln() - x).abs()))
            .map(|(k, _)| k)
    };
    a_only.linear.set(true);
    let x_linear = a_only
        .solve(&core.used, options.max_iterations, nearest_node(core.x))
        .map(|c| c.x)
        .unwrap_or(core.x);
    a_only.linear.set(false);
    let half_interp = (core.x - x_linear).abs();
    let half_pressure = pressure_interpolation_ln(model, points, &core.used, core.x.exp());
    let half_tables = half_interp.hypot(half_pressure);
    let tables_note = format!(
        "plus in quadrature the table interpolation terms |ln E(PCHIP) - ln E(linear in ln E2)| = {half_interp:.4} and, across p_air, {half_pressure:.4}"
    );
    let (half, method, description) = if half_rep > half_resid {
        (
            half_rep.hypot(half_tables),
            CiMethod::Replicates,
            format!(
                "between-replicate scatter of {} per-replicate fits (standard error of the mean ln E2, Student t with {} dof); larger than the residual-model interval; {tables_note}",
                replicate_moduli.len(),
                replicate_moduli.len() - 1,
            ),
        )
    } else {
        (
            half_resid.hypot(half_tables),
            CiMethod::ResidualAr1,
            format!(
                "residual variance with AR(1) within-curve correlation (lag-1 rho = {rho:.2}, {n_eff:.1} effective of {n} points, Student t){}; {tables_note}",
                if replicate_moduli.len() >= 2 {
                    "; larger than the between-replicate interval"
                } else {
                    ""
                }
            ),
        )
    };

    // per-pressure fits when several pressures were measured
    let mut per_pressure = Vec::new();
    if pressures.len() >= 2 {
        for &p in &pressures {
            let subset: Vec<usize> = (0..points.len())
                .filter(|&i| points[i].p_air_kpa == p)
                .collect();
            let sub_points: Vec<FitPoint> = subset.iter().map(|&i| points[i]).collect();
            if let Ok(f) = fit_modulus(
                model,
                &sub_points,
                FitOptions {
                    use_load: false,
                    ..options
                },
            ) {
                per_pressure.push(PressureFit {
                    p_air_kpa: p,
                    modulus_kpa: f.modulus_kpa,
                    ci95_kpa: f.ci95_kpa,
                    points: f.points_used,
                    rms_residual_mm: f.rms_residual_mm,
                });
            }
        }
    }

    Ok(ModulusFit {
        modulus_kpa: core.x.exp(),
        ci95_kpa: [(core.x - half).exp(), (core.x + half).exp()],
        rms_residual_mm: rms,
        ci_method: method,
        ci_description: description,
        points_used: n,
        points_excluded: core.excluded,
        pressures_kpa: pressures,
        per_pressure,
        replicate_moduli_kpa: replicate_moduli,
        effective_points: n_eff,
        residual_lag1_correlation: rho,
        se_ln_modulus_residual: se_resid,
        se_ln_modulus_replicates: se_rep,
        iterations: core.iterations,
        modulus_linear_interpolation_kpa: x_linear.exp(),
        interpolation_half_width_ln: half_interp,
        pressure_interpolation_half_width_ln: half_pressure,
        discretisation_bias_ln: None,
        modulus_production_kpa: None,
        discretisation_residual_ln: None,
        load_channel_used: load_used,
        rms_residual_load_n: core.rms_load,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The per-interval cubics reproduce the table's own interpolation (value and slope)
    /// to rounding: they are the same polynomial, obtained from the table's node values.
    #[test]
    fn interval_cubics_equal_the_table_interpolation() {
        let path =
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/fit_fixture.lut");
        let lut = fem_core::lut::read_lut(&path).unwrap().lut;
        let model = LutModel::new(&lut).unwrap();
        let points: Vec<FitPoint> = (0..60)
            .map(|k| FitPoint {
                u_s_mm: 0.05 + 0.03 * f64::from(k),
                a_mm: 1.0,
                p_air_kpa: [15.0, 6.0, 9.7][k as usize % 3],
                test: 0,
                load_n: None,
            })
            .collect();
        let problem = Problem::new(&model, &points, 0.0);
        let (lo, hi) = (10.0f64.ln(), 1000.0f64.ln());
        let mut compared = 0;
        let mut worst: f64 = 0.0;
        for m in 0..=200 {
            let x = lo + (hi - lo) * f64::from(m) / 200.0;
            for (i, p) in points.iter().enumerate() {
                let table = model.sample(x.exp(), p.p_air_kpa, p.u_s_mm);
                if let (Ok(t), Some((a, d))) = (&table, problem.a_at(i, x)) {
                    worst = worst
                        .max((t.a_mm - a).abs())
                        .max((t.da_dln_modulus_mm - d).abs() * 1e-2);
                    compared += 1;
                }
            }
        }
        eprintln!("{compared} compared, worst {worst:e}");
        assert!(compared > 5000, "{compared}");
        assert!(worst < 1e-9, "{worst}");
    }

    #[test]
    fn t_quantiles_match_tables() {
        // Published two-sided 95 % values (e.g. NIST/SEMATECH e-Handbook table 1.4.2.7.2).
        for (dof, t) in [
            (1.0, 12.706),
            (4.0, 2.776),
            (10.0, 2.228),
            (20.0, 2.086),
            (30.0, 2.042),
            (120.0, 1.980),
        ] {
            assert!(
                (t975(dof) - t).abs() < 2e-3,
                "dof {dof}: {} vs {t}",
                t975(dof)
            );
        }
    }
}
