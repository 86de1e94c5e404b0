//! The tube travel against u_s, a check of a model fitted to the radius and the load.
//!
//! The stage's travel h is not a sensor of the probe: it is where the tube was driven. At a
//! measured apex displacement u_s the model predicts it, h(E2, p_air, u_s), and the effects
//! that change the sample or the shell (its thickness, friction, a manometer offset, ...)
//! change that prediction in their own way, while a camera's scale or offset leave it alone.
//! Behind a camera scale, friction and a manometer offset explain the radius and the load of
//! two pressures almost alike (docs/diagnosis.md, step 7); their travels differ by 5-15 um
//! at 6 and 15 kPa (170 kPa, mu 0.4), several times the travel's noise there.
//!
//! The residuals r = h - h_model(u_s) of a fitted model get the noise model of the other
//! channels ([`NoiseModel::estimate_channel`], estimated from the replicates: the u_s
//! errors enter through dh/du_s, the table's interpolation across E2 as its own term), and
//! their chi^2 over the whitened values is tested on as many degrees of freedom (the
//! parameters were fitted to the other channels). The travel shares the u_s errors with
//! the radius and the load; the test reads it on its own, not jointly with them.

use serde::Serialize;

use super::candidates::{Candidate, predict_with};
use super::data::Point;
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
    pub p_value: f64,
    /// RMS of h - h_model (mm).
    pub rms_residual_mm: f64,
}

/// The travel check of `model` with its included effects at `included` and `cand` at
/// `theta`, modulus `e`, over the points of `subset` that record a travel; `None` with fewer
/// than [`MIN_TRAVEL_POINTS`] of them or a noise model that cannot be whitened.
pub fn check(
    model: &Model<'_>,
    included: &[f64],
    cand: Option<&Candidate>,
    e: f64,
    theta: f64,
    points: &[Point],
    subset: &[usize],
) -> Option<TravelCheck> {
    let with_travel: Vec<Point> = subset
        .iter()
        .map(|&i| points[i])
        .filter(|p| p.h_mm.is_some_and(f64::is_finite))
        .collect();
    if with_travel.len() < MIN_TRAVEL_POINTS {
        return None;
    }
    let r: Vec<f64> = with_travel
        .iter()
        .map(|p| {
            Channel::Travel.measured(p)
                - predict_with(model, included, cand, e, theta, p, Channel::Travel)
        })
        .collect();
    if r.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let noise = NoiseModel::estimate_channel(model, Channel::Travel, &with_travel, &r, e);
    let all: Vec<usize> = (0..with_travel.len()).collect();
    let whitener = noise.whitener(&with_travel, &all)?;
    let chi2: f64 = whitener.whiten(&r).iter().map(|z| z * z).sum();
    let values = whitener.len();
    Some(TravelCheck {
        chi2,
        values,
        p_value: stats::chi2_sf(chi2, values as f64),
        rms_residual_mm: (r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64).sqrt(),
    })
}
