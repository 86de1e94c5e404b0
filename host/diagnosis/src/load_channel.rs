//! The load channel (P–u_s) in the selection: a cross-channel prediction check.
//!
//! The candidates are detected and fitted on the contact radius (a–u_s), where the bootstrap
//! threshold and the held-out check are calibrated. Effects that change a(u_s) alike can
//! differ in what they do to the load: friction between shell and sample makes the sample
//! carry more load at the same u_s, while a camera scale error changes only the image. Each
//! refitted candidate therefore predicts the load curve at its own (E2, theta), fitted on a
//! alone, and is scored by the whitened chi^2 of the measured loads against that prediction:
//! chi^2_P = |L_P^-1 (P_meas - P_cand)|^2, where L_P is the Cholesky factor of the load
//! channel's noise covariance, estimated from the replicates exactly as for the radius
//! ([`NoiseModel::estimate_channel`]: white, per-test offsets, smooth term, u_s noise through
//! dP/du_s, and the table's own interpolation error of the load column).
//!
//! Each refitted candidate is also fitted to the radius and the load together
//! ([`LoadChannel::with_joint`], [`super::joint`]: generalised least squares over both
//! channels, their covariance including the part the shared u_s reading makes common to
//! both), and the candidates that pass are ranked by that joint chi^2; the report gives the
//! joint fit's parameters beside the radius fit's. (Without the joint whitening, e.g. when
//! its covariance is not positive definite, they are ranked by chi^2_a + chi^2_P.) The load
//! channel never makes an effect out of nothing: detection stays with the calibrated
//! a-channel threshold.

use serde::Serialize;

use super::candidates::{Candidate, predict, predict_fit};
use super::data::Point;
use super::fitting::GlsFit;
use super::joint::JointWhitener;
use super::model::{Channel, Model};
use super::noise_model::{NoiseModel, PressureNoise, Whitener};

/// The load channel's noise model and the baseline's score on it.
#[derive(Debug, Clone)]
pub struct LoadChannel {
    pub noise: NoiseModel,
    pub whitener: Whitener,
    /// chi^2_P of the baseline GLS fit.
    pub baseline_chi2: f64,
    /// Whitening of both channels together ([`LoadChannel::with_joint`]).
    pub joint: Option<JointWhitener>,
}

/// Summary for the report.
#[derive(Debug, Clone, Serialize)]
pub struct LoadSummary {
    pub points: usize,
    pub baseline_chi2: f64,
    pub noise_model: Vec<PressureNoise>,
}

impl LoadChannel {
    /// Builds the channel when every used point has a load and some pressure has replicates
    /// (without replicates the load noise cannot be estimated, and an assumed model would
    /// decide between candidates on an unchecked scale): baseline residuals at modulus `e`.
    pub fn new(model: &Model<'_>, points: &[Point], subset: &[usize], e: f64) -> Option<Self> {
        if subset.is_empty()
            || subset
                .iter()
                .any(|&i| !points[i].load_n.is_some_and(f64::is_finite))
        {
            return None;
        }
        let r: Vec<f64> = points
            .iter()
            .map(|p| Channel::Load.measured(p) - predict(model, None, e, 0.0, p, Channel::Load))
            .collect();
        let noise = NoiseModel::estimate_channel(model, Channel::Load, points, &r, e);
        if noise.pressures.iter().all(|p| p.assumed) {
            return None;
        }
        let whitener = noise.whitener(points, subset)?;
        let mut lc = Self {
            noise,
            whitener,
            baseline_chi2: 0.0,
            joint: None,
        };
        lc.baseline_chi2 = lc.chi2(model, None, points, subset, e, 0.0)?;
        Some(lc)
    }

    /// Adds the joint whitening of both channels, from the radius channel's noise model
    /// `radius` and both channels' baseline residuals at modulus `e` (None when the joint covariance is not positive definite; the selection then
    /// ranks by the radius fit plus the load prediction).
    pub fn with_joint(
        mut self,
        model: &Model<'_>,
        radius: &NoiseModel,
        points: &[Point],
        subset: &[usize],
        e: f64,
    ) -> Self {
        let residual = |ch: Channel| -> Vec<f64> {
            points
                .iter()
                .map(|p| ch.measured(p) - predict(model, None, e, 0.0, p, ch))
                .collect()
        };
        let (r_a, r_p) = (residual(Channel::Radius), residual(Channel::Load));
        self.joint = JointWhitener::new(radius, &self.noise, points, subset, &r_a, &r_p);
        self
    }

    /// chi^2_P of `cand` (None: the baseline) at (E2 = `e`, `theta`) over `points[subset]`.
    pub fn chi2(
        &self,
        model: &Model<'_>,
        cand: Option<&Candidate>,
        points: &[Point],
        subset: &[usize],
        e: f64,
        theta: f64,
    ) -> Option<f64> {
        let mut r = vec![0.0; points.len()];
        for &i in subset {
            let v = Channel::Load.measured(&points[i])
                - predict(model, cand, e, theta, &points[i], Channel::Load);
            if !v.is_finite() {
                return None;
            }
            r[i] = v;
        }
        Some(self.whitener.whiten(&r).iter().map(|v| v * v).sum())
    }

    /// chi^2_P of fit `f` of `cand` (None: the model without a candidate) over
    /// `points[subset]`, at the fit's parameters including its refitted included effects.
    pub fn chi2_fit(
        &self,
        model: &Model<'_>,
        cand: Option<&Candidate>,
        points: &[Point],
        subset: &[usize],
        f: &GlsFit,
    ) -> Option<f64> {
        let mut r = vec![0.0; points.len()];
        for &i in subset {
            let v = Channel::Load.measured(&points[i])
                - predict_fit(model, cand, f, &points[i], Channel::Load);
            if !v.is_finite() {
                return None;
            }
            r[i] = v;
        }
        Some(self.whitener.whiten(&r).iter().map(|v| v * v).sum())
    }

    pub fn summary(&self) -> LoadSummary {
        LoadSummary {
            points: self.whitener.len(),
            baseline_chi2: self.baseline_chi2,
            noise_model: self.noise.pressures.clone(),
        }
    }
}
