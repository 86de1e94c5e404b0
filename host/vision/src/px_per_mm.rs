//! Camera scale calibration: px per mm from frames of a reference disc of known radius
//! (e.g. a rigid flat sample with a printed or machined disc, or rigid indenters of known
//! contact radius).
//!
//! One disc size: `k = mean(r_px) / r_mm`, standard error from the scatter over frames
//! (`s / sqrt(n) / r_mm`), or from the per-frame predicted errors for a single frame.
//! Several sizes: the straight line `r_px = k r_mm + b` by least squares (Montgomery,
//! *Introduction to Linear Regression*, eqs. 2.9-2.10 for the slope's standard error), so a
//! constant edge offset `b` (e.g. a meniscus ring around the contact) is separated from the
//! scale.

use super::contact_radius::{ContactRadiusConfig, ContactRadiusEstimator, VisionError};
use crate::GrayImage;

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PxPerMmCalibration {
    pub px_per_mm: f64,
    /// Standard error of `px_per_mm`.
    pub px_per_mm_sigma: f64,
    /// Edge offset in px (fitted only with two or more distinct disc radii).
    pub offset_px: Option<f64>,
    pub samples: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum PxPerMmError {
    #[error("no calibration frames")]
    NoSamples,
    #[error("disc radius {0} mm is not positive")]
    BadRadius(f64),
    #[error("calibration frame {index}: no contact disc found")]
    NoDisc { index: usize },
    #[error(transparent)]
    Vision(#[from] VisionError),
}

impl PxPerMmCalibration {
    /// From (radius_mm, radius_px, radius_sigma_px) triples.
    pub fn from_measurements(samples: &[(f64, f64, f64)]) -> Result<Self, PxPerMmError> {
        let n = samples.len();
        if n == 0 {
            return Err(PxPerMmError::NoSamples);
        }
        if let Some(&(r, _, _)) = samples.iter().find(|s| s.0.is_nan() || s.0 <= 0.0) {
            return Err(PxPerMmError::BadRadius(r));
        }
        let nf = n as f64;
        let mean_mm = samples.iter().map(|s| s.0).sum::<f64>() / nf;
        let mean_px = samples.iter().map(|s| s.1).sum::<f64>() / nf;
        let sxx: f64 = samples.iter().map(|s| (s.0 - mean_mm).powi(2)).sum();
        let distinct = sxx > 1e-12 * mean_mm * mean_mm * nf;
        if distinct && n >= 3 {
            let sxy: f64 = samples
                .iter()
                .map(|s| (s.0 - mean_mm) * (s.1 - mean_px))
                .sum();
            let k = sxy / sxx;
            let b = mean_px - k * mean_mm;
            let sse: f64 = samples.iter().map(|s| (s.1 - k * s.0 - b).powi(2)).sum();
            let sigma2 = sse / (nf - 2.0);
            return Ok(Self {
                px_per_mm: k,
                px_per_mm_sigma: (sigma2 / sxx).sqrt(),
                offset_px: Some(b),
                samples: n,
            });
        }
        let ratios: Vec<f64> = samples.iter().map(|s| s.1 / s.0).collect();
        let k = ratios.iter().sum::<f64>() / nf;
        let sigma = if n >= 2 {
            (ratios.iter().map(|r| (r - k).powi(2)).sum::<f64>() / (nf - 1.0)).sqrt() / nf.sqrt()
        } else {
            samples[0].2 / samples[0].0
        };
        Ok(Self {
            px_per_mm: k,
            px_per_mm_sigma: sigma,
            offset_px: None,
            samples: n,
        })
    }

    /// Measures each frame against the no-contact `reference` and calibrates.
    pub fn from_frames(
        reference: &GrayImage,
        frames: &[GrayImage],
        disc_radius_mm: f64,
        config: &ContactRadiusConfig,
    ) -> Result<Self, PxPerMmError> {
        if disc_radius_mm.is_nan() || disc_radius_mm <= 0.0 {
            return Err(PxPerMmError::BadRadius(disc_radius_mm));
        }
        let est = ContactRadiusEstimator::new(reference.clone(), config.clone())?;
        let mut samples = Vec::with_capacity(frames.len());
        for (index, f) in frames.iter().enumerate() {
            let m = est.measure(f)?;
            let disc = m.disc.ok_or(PxPerMmError::NoDisc { index })?;
            samples.push((disc_radius_mm, disc.radius_px, disc.radius_sigma_px));
        }
        Self::from_measurements(&samples)
    }

    pub fn px_to_mm(&self, px: f64) -> f64 {
        (px - self.offset_px.unwrap_or(0.0)) / self.px_per_mm
    }
}
