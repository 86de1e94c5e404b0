//! Generalised least squares of the baseline or an augmented model: minimise the whitened
//! chi^2 = |L^-1 (a - f(ln E2, theta))|^2 (L the Cholesky factor of the noise covariance)
//! by Levenberg–Marquardt (Marquardt 1963) with forward-difference Jacobians and the
//! effect parameter kept in its allowed range. The parameter covariance is (J^T J)^-1 in
//! whitened units, inflated by max(1, chi^2/dof) when the fit is poor (the usual
//! scale-factor correction), and the 95 % interval of E2 is exp(ln E2 +- 1.96 se).
//!
//! [`fit_to`] with [`Objective::Joint`] minimises the joint chi^2 of the radius and the load instead
//! ([`super::joint`]), the same algorithm on the stacked whitened residuals.
//!
//! When the model already includes effects ([`Model::included`], added by the forward
//! selection), their parameters are fitted jointly with the modulus and the candidate's
//! parameter, each kept in its range, from the model's stored values.

use serde::Serialize;

use super::candidates::{Candidate, predict_with};
use super::data::Point;
use super::joint::JointWhitener;
use super::linalg;
use super::model::{Channel, Model};
use super::noise_model::Whitener;

/// Result of one fit.
#[derive(Debug, Clone, Serialize)]
pub struct GlsFit {
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    /// Effect parameter (0 for the baseline).
    pub theta: f64,
    pub theta_se: f64,
    /// Parameters of the model's included effects, refitted jointly (in the order of
    /// [`Model::included`]; empty for a model without them), and their standard errors.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub included: Vec<f64>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub included_se: Vec<f64>,
    pub chi2: f64,
    pub points: usize,
    pub parameters: usize,
    pub chi2_per_dof: f64,
    pub rms_residual_mm: f64,
    #[serde(skip)]
    pub residuals_mm: Vec<f64>,
    #[serde(skip)]
    pub whitened: Vec<f64>,
    /// Covariance of the fitted parameters, row-major, in the order ln E2, the
    /// candidate's parameter (when the fit has a candidate), the included effects'.
    #[serde(skip)]
    pub covariance: Vec<f64>,
    pub iterations: usize,
}

/// What a fit minimises: the radius channel's chi^2, the load channel's, or both channels'
/// joint chi^2.
#[derive(Debug, Clone, Copy)]
pub enum Objective<'w> {
    Radius(&'w Whitener),
    /// The load channel alone (its own whitener): parameters the load does not see (a
    /// camera's offset or scale) keep their starting values, their Jacobian column being
    /// zero.
    Load(&'w Whitener),
    Joint(&'w JointWhitener),
    /// One part of the joint chi^2 ([`JointWhitener::split`]): the radius by its own
    /// covariance, or the load given the radius.
    JointPart(&'w JointWhitener, JointPart),
}

/// The two independent parts of the joint chi^2.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointPart {
    Radius,
    LoadGivenRadius,
}

/// Fits `cand` (or the baseline) to the contact radius of `points[subset]` starting at
/// (e0, theta0).
#[allow(clippy::too_many_arguments)]
pub fn fit(
    model: &Model<'_>,
    cand: Option<&Candidate>,
    points: &[Point],
    subset: &[usize],
    whitener: &Whitener,
    e0: f64,
    theta0: f64,
    max_iterations: usize,
) -> Option<GlsFit> {
    fit_to(
        model,
        cand,
        points,
        subset,
        Objective::Radius(whitener),
        e0,
        theta0,
        max_iterations,
    )
}

/// Fits `cand` (or the baseline) to `points[subset]` under `objective` starting at
/// (e0, theta0). With [`Objective::Joint`] every point needs a load, and the result's chi^2,
/// points and whitened values are over both channels; `residuals_mm` and `rms_residual_mm`
/// are the radius's.
#[allow(clippy::too_many_arguments)]
pub fn fit_to(
    model: &Model<'_>,
    cand: Option<&Candidate>,
    points: &[Point],
    subset: &[usize],
    objective: Objective<'_>,
    e0: f64,
    theta0: f64,
    max_iterations: usize,
) -> Option<GlsFit> {
    let moduli = model.base.moduli_kpa();
    let (ln_lo, ln_hi) = (moduli[0].ln(), moduli[moduli.len() - 1].ln());
    // parameters: ln E2, the candidate's (if any), then the included effects'
    let c_off = usize::from(cand.is_some());
    let m = model.included.len();
    let k = 1 + c_off + m;
    let mut lo = vec![ln_lo];
    let mut hi = vec![ln_hi];
    let mut steps = vec![1e-3];
    for c in cand
        .iter()
        .map(|c| **c)
        .chain(model.included.iter().map(|(c, _)| *c))
    {
        let (_, l, h) = c.kind.parameter();
        lo.push(l);
        hi.push(h);
        steps.push(c.kind.step());
    }
    let n_all = points.len();
    let residual = |q: &[f64]| -> Option<(Vec<f64>, Vec<f64>)> {
        let e = q[0].exp();
        let th = if c_off == 1 { q[1] } else { 0.0 };
        let inc = &q[1 + c_off..];
        let mut r = vec![0.0; n_all];
        for &i in subset {
            let a = predict_with(model, inc, cand, e, th, &points[i], Channel::Radius);
            if !a.is_finite() {
                return None;
            }
            r[i] = points[i].a_mm - a;
        }
        // the load's residuals over all points (zero outside the subset)
        let load_residuals = || -> Option<Vec<f64>> {
            let mut r_p = vec![0.0; n_all];
            for &i in subset {
                let p = predict_with(model, inc, cand, e, th, &points[i], Channel::Load);
                let v = Channel::Load.measured(&points[i]) - p;
                if !v.is_finite() {
                    return None;
                }
                r_p[i] = v;
            }
            Some(r_p)
        };
        let w = match objective {
            Objective::Radius(whitener) => whitener.whiten(&r),
            Objective::Load(whitener) => whitener.whiten(&load_residuals()?),
            Objective::Joint(joint) | Objective::JointPart(joint, _) => {
                let w = joint.whiten(&r, &load_residuals()?);
                match objective {
                    Objective::JointPart(_, part) => {
                        let (radius, load) = joint.split(&w);
                        match part {
                            JointPart::Radius => radius,
                            JointPart::LoadGivenRadius => load,
                        }
                    }
                    _ => w,
                }
            }
        };
        Some((r, w))
    };
    let chi2 = |w: &[f64]| w.iter().map(|v| v * v).sum::<f64>();
    let mut q = vec![e0.ln().clamp(ln_lo, ln_hi)];
    if c_off == 1 {
        q.push(theta0.clamp(lo[1], hi[1]));
    }
    for (j, (_, t)) in model.included.iter().enumerate() {
        q.push(t.clamp(lo[1 + c_off + j], hi[1 + c_off + j]));
    }
    let (mut r, mut w) = residual(&q)?;
    let mut s = chi2(&w);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut jac: Vec<Vec<f64>> = Vec::new();
    for it in 0..max_iterations {
        iterations = it + 1;
        // Jacobian of the whitened prediction: -(d w / d q)
        jac.clear();
        for c in 0..k {
            let mut h = steps[c];
            let mut qp = q.clone();
            if qp[c] + h > hi[c] {
                h = -h;
            }
            qp[c] += h;
            let (_, wp) = residual(&qp)?;
            jac.push(w.iter().zip(&wp).map(|(a, b)| (a - b) / h).collect());
        }
        let mut jtj = vec![0.0; k * k];
        let mut jtr = vec![0.0; k];
        for a in 0..k {
            jtr[a] = linalg::dot(&jac[a], &w);
            for b in 0..k {
                jtj[a * k + b] = linalg::dot(&jac[a], &jac[b]);
            }
        }
        let mut improved = false;
        for _ in 0..12 {
            let mut m = jtj.clone();
            for a in 0..k {
                m[a * k + a] *= 1.0 + lambda;
                m[a * k + a] += 1e-12;
            }
            let Some(delta) = linalg::solve_spd(&m, k, &jtr) else {
                lambda *= 10.0;
                continue;
            };
            let qn: Vec<f64> = (0..k)
                .map(|c| (q[c] + delta[c]).clamp(lo[c], hi[c]))
                .collect();
            if let Some((rn, wn)) = residual(&qn) {
                let sn = chi2(&wn);
                if sn < s {
                    let rel = (s - sn) / s.max(1e-300);
                    q = qn;
                    r = rn;
                    w = wn;
                    s = sn;
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = rel > 1e-9;
                    break;
                }
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    // covariance from the final Jacobian
    let mut jtj = vec![0.0; k * k];
    for a in 0..k {
        for b in 0..k {
            jtj[a * k + b] = jac
                .get(a)
                .zip(jac.get(b))
                .map_or(0.0, |(x, y)| linalg::dot(x, y));
        }
    }
    let n = match objective {
        Objective::Radius(_) | Objective::Load(_) => subset.len(),
        Objective::Joint(joint) => joint.len(),
        Objective::JointPart(joint, _) => joint.len() / 2,
    };
    let dof = n.saturating_sub(k).max(1) as f64;
    let scale = (s / dof).max(1.0);
    let cov = linalg::inverse_spd(&jtj, k).unwrap_or_else(|| vec![f64::INFINITY; k * k]);
    let se_ln = (cov[0] * scale).sqrt();
    let se = |c: usize| (cov[c * k + c] * scale).sqrt();
    let theta_se = if c_off == 1 { se(1) } else { 0.0 };
    let rms =
        (subset.iter().map(|&i| r[i] * r[i]).sum::<f64>() / subset.len().max(1) as f64).sqrt();
    Some(GlsFit {
        modulus_kpa: q[0].exp(),
        ci95_kpa: [(q[0] - 1.96 * se_ln).exp(), (q[0] + 1.96 * se_ln).exp()],
        theta: if c_off == 1 { q[1] } else { 0.0 },
        theta_se,
        included: q[1 + c_off..].to_vec(),
        included_se: (1 + c_off..k).map(se).collect(),
        covariance: cov.iter().map(|c| c * scale).collect(),
        chi2: s,
        points: n,
        parameters: k,
        chi2_per_dof: s / dof,
        rms_residual_mm: rms,
        residuals_mm: r,
        whitened: w,
        iterations,
    })
}
