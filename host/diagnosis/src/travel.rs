//! The tube travel against u_s, a check of a model fitted to the radius and the load.
//!
//! The stage's travel h is not a sensor of the probe: it is where the tube was driven. At a
//! measured apex displacement u_s the model predicts it, h(E2, p_air, u_s), and the effects
//! that change the sample or the shell (its thickness, friction, a manometer offset, ...)
//! change that prediction in their own way, while a camera's scale or offset leave it alone.
//! Behind a camera scale, friction and a manometer offset explain the radius and the load of
//! two pressures almost alike (docs/diagnosis.md, step 7); their travels differ by 5-15 um
//! at 6 and 15 kPa (170 kPa, mu 0.4), though most of that is a shift of the modulus and
//! the offset that their joint fit's uncertainty allows (step 8).
//!
//! The residuals r = h - h_model(u_s) of a fitted model get the noise model of the other
//! channels ([`NoiseModel::estimate_channel`], estimated from the replicates: the u_s
//! errors enter through dh/du_s, the table's interpolation across E2 as its own term),
//! plus the uncertainty of the parameters fitted to the other channels, S C S^T with
//! S = dh/dq (the modulus in ln E2 and each effect's parameter) and C their covariance
//! from that fit. With w = L^-1 r and V = L^-1 S L_c (L the noise model's Cholesky factor,
//! L_c C's), Woodbury gives
//!
//! chi^2 = |w|^2 - w^T V (I + V^T V)^-1 V^T w,
//!
//! tested on as many degrees of freedom as values (no parameter is fitted to the travel).
//! The travel shares the u_s errors with the radius and the load; the test reads it on its
//! own, not jointly with them.
//!
//! A bench record holds the stage's position, not the travel: its zero, the stage where
//! the shell first touches the sample, is not measured ([`Point::h_zero_fitted`]). Each
//! such indentation's zero (a replicate at one pressure: the inflated apex meets the
//! sample at another stage position at each) is then a free offset c_t: with
//! Q = I - V (I + V^T V)^-1 V^T (the whitened inverse covariance above) and Z the whitened
//! indicators of those indentations, the offsets are profiled out,
//!
//! chi^2 = w^T Q w - (Z^T Q w)^T (Z^T Q Z)^-1 (Z^T Q w),
//!
//! on as many degrees of freedom as values less one per fitted zero (the residuals minus
//! each indentation's mean also feed the noise model, whose own offsets the zeros absorb).

use serde::Serialize;

use super::candidates::{Candidate, predict_with};
use super::data::Point;
use super::linalg;
use super::model::{Channel, Model};
use super::noise_model::NoiseModel;
use super::stats;

/// Fewest points with a recorded travel for the check.
pub const MIN_TRAVEL_POINTS: usize = 20;

/// The travel under one fitted model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TravelCheck {
    pub chi2: f64,
    pub values: usize,
    /// Indentations (a replicate at one pressure) whose travel zero was fitted (records of
    /// the stage's position).
    pub fitted_zeros: usize,
    pub p_value: f64,
    /// RMS of h - h_model (mm).
    pub rms_residual_mm: f64,
}

/// A fitted parameter of the model whose travel is checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parameter {
    LnModulus,
    /// The candidate's parameter.
    Theta,
    /// The included effect `j`'s (in the order of [`Model::included`]).
    Included(usize),
}

/// The covariance of the fitted parameters (row-major, [`crate::fitting::GlsFit::covariance`])
/// and which parameter each row is.
#[derive(Debug, Clone, Default)]
pub struct FittedCovariance {
    pub order: Vec<Parameter>,
    pub matrix: Vec<f64>,
}

impl FittedCovariance {
    /// The covariance of `fit`, a fit with a candidate (`with_theta`) or without;
    /// `theta_as` renames the candidate's parameter as an included effect's (when the checked
    /// model includes the candidate). Empty when `fit` carries no covariance of that size.
    pub fn of(fit: &crate::fitting::GlsFit, with_theta: bool, theta_as: Option<usize>) -> Self {
        let mut order = vec![Parameter::LnModulus];
        if with_theta {
            order.push(theta_as.map_or(Parameter::Theta, Parameter::Included));
        }
        order.extend((0..fit.included.len()).map(Parameter::Included));
        let k = order.len();
        if fit.covariance.len() != k * k {
            return Self::default();
        }
        Self {
            order,
            matrix: fit.covariance.clone(),
        }
    }
}

/// A model fitted to the other channels, as the travel check reads it.
#[derive(Debug, Clone, Copy)]
pub struct FittedModel<'a> {
    /// The included effects' parameters (in the order of [`Model::included`]).
    pub included: &'a [f64],
    /// A candidate on top of them, with its parameter `theta`.
    pub cand: Option<&'a Candidate>,
    pub theta: f64,
    pub modulus_kpa: f64,
    pub covariance: &'a FittedCovariance,
}

/// The travel check of `model` at the fitted parameters `fitted`, over the points of
/// `subset` that record a travel; `None` with fewer than [`MIN_TRAVEL_POINTS`] of them or
/// a noise model that cannot be whitened.
pub fn check(
    model: &Model<'_>,
    fitted: &FittedModel<'_>,
    points: &[Point],
    subset: &[usize],
) -> Option<TravelCheck> {
    let FittedModel {
        included,
        cand,
        theta,
        modulus_kpa: e,
        covariance: cov,
    } = *fitted;
    let with_travel: Vec<Point> = subset
        .iter()
        .map(|&i| points[i])
        .filter(|p| p.h_mm.is_some_and(f64::is_finite))
        .collect();
    if with_travel.len() < MIN_TRAVEL_POINTS {
        return None;
    }
    let h_of = |included: &[f64], e: f64, theta: f64, p: &Point| {
        predict_with(model, included, cand, e, theta, p, Channel::Travel)
    };
    let mut r: Vec<f64> = with_travel
        .iter()
        .map(|p| Channel::Travel.measured(p) - h_of(included, e, theta, p))
        .collect();
    if r.iter().any(|x| !x.is_finite()) {
        return None;
    }
    // the indentations whose zero is fitted (a replicate at one pressure: the inflated
    // shell meets the sample at another stage position at each), each as its points'
    // indicator; their residuals less their mean (the chi^2 below does not depend on it)
    let indentation = |p: &Point| (p.test, p.p_air_kpa.to_bits());
    let mut zero_tests: Vec<(u32, u64)> = with_travel
        .iter()
        .filter(|p| p.h_zero_fitted)
        .map(indentation)
        .collect();
    zero_tests.sort_unstable();
    zero_tests.dedup();
    let indicators: Vec<Vec<f64>> = zero_tests
        .iter()
        .map(|&t| {
            with_travel
                .iter()
                .map(|p| {
                    if p.h_zero_fitted && indentation(p) == t {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    for z in &indicators {
        let n: f64 = z.iter().sum();
        let mean = r.iter().zip(z).map(|(x, zi)| x * zi).sum::<f64>() / n;
        for (x, zi) in r.iter_mut().zip(z) {
            *x -= mean * zi;
        }
    }
    // each fitted parameter's sensitivity dh/dq (central differences of step d)
    let step = |q: Parameter| match q {
        Parameter::LnModulus => 0.01,
        Parameter::Theta => cand.map_or(0.0, |c| c.kind.step()),
        Parameter::Included(j) => model
            .included
            .get(j)
            .filter(|_| j < included.len())
            .map_or(0.0, |(c, _)| c.kind.step()),
    };
    let shifted = |q: Parameter, x: f64, p: &Point| {
        let (mut inc, mut e_q, mut theta_q) = (included.to_vec(), e, theta);
        match q {
            Parameter::LnModulus => e_q *= x.exp(),
            Parameter::Theta => theta_q += x,
            Parameter::Included(j) => inc[j] += x,
        }
        h_of(&inc, e_q, theta_q, p)
    };
    let sensitivity = |q: Parameter| -> Vec<f64> {
        let d = step(q);
        with_travel
            .iter()
            .map(|p| {
                if d > 0.0 {
                    (shifted(q, d, p) - shifted(q, -d, p)) / (2.0 * d)
                } else {
                    0.0
                }
            })
            .collect()
    };
    // S L_c: the parameters' covariance S C S^T as a low-rank term
    let k = cov.order.len();
    let mut columns: Vec<Vec<f64>> = Vec::new();
    if k > 0
        && cov.matrix.len() == k * k
        && let Some(lc) = linalg::cholesky(&cov.matrix, k)
    {
        let s: Vec<Vec<f64>> = cov.order.iter().map(|&q| sensitivity(q)).collect();
        for b in 0..k {
            columns.push(
                (0..with_travel.len())
                    .map(|i| (b..k).map(|a| s[a][i] * lc[a * k + b]).sum())
                    .collect(),
            );
        }
    }
    if columns.iter().flatten().any(|x| !x.is_finite()) {
        return None;
    }
    let noise = NoiseModel::estimate_channel(model, Channel::Travel, &with_travel, &r, e);
    let all: Vec<usize> = (0..with_travel.len()).collect();
    let whitener = noise.whitener(&with_travel, &all)?;
    let w = whitener.whiten(&r);
    let v: Vec<Vec<f64>> = columns.iter().map(|c| whitener.whiten(c)).collect();
    let k = v.len();
    let mut gram = vec![0.0; k * k];
    for a in 0..k {
        for b in 0..k {
            gram[a * k + b] = linalg::dot(&v[a], &v[b]) + if a == b { 1.0 } else { 0.0 };
        }
    }
    // x^T Q y with Q = I - V (I + V^T V)^-1 V^T (Woodbury)
    let q_form = |x: &[f64], y: &[f64]| -> Option<f64> {
        let mut out = linalg::dot(x, y);
        if k > 0 {
            let vy: Vec<f64> = v.iter().map(|va| linalg::dot(va, y)).collect();
            let vx: Vec<f64> = v.iter().map(|va| linalg::dot(va, x)).collect();
            out -= linalg::dot(&vx, &linalg::solve_spd(&gram, k, &vy)?);
        }
        Some(out)
    };
    let mut chi2 = q_form(&w, &w)?;
    let zw: Vec<Vec<f64>> = indicators.iter().map(|z| whitener.whiten(z)).collect();
    let m = zw.len();
    if m > 0 {
        let mut g = vec![0.0; m * m];
        let mut b = vec![0.0; m];
        for i in 0..m {
            for j in 0..m {
                g[i * m + j] = q_form(&zw[i], &zw[j])?;
            }
            b[i] = q_form(&zw[i], &w)?;
        }
        chi2 -= linalg::dot(&b, &linalg::solve_spd(&g, m, &b)?);
    }
    let values = whitener.len();
    let dof = values.saturating_sub(m).max(1);
    Some(TravelCheck {
        chi2,
        values,
        fitted_zeros: m,
        p_value: stats::chi2_sf(chi2, dof as f64),
        rms_residual_mm: (r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64).sqrt(),
    })
}
