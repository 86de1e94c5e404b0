//! Camera scale calibration: px per mm from frames of a reference disc of known radius
//! (e.g. a rigid flat sample with a printed or machined disc, or rigid indenters of known
//! contact radius).
//!
//! One disc size: `k = mean(r_px) / r_mm`, standard error from the scatter over frames
//! (`s / sqrt(n) / r_mm`), or from the per-frame predicted errors for a single frame.
//! Several sizes: the straight line `r_px = k r_mm + b` by least squares (Montgomery,
//! *Introduction to Linear Regression*, eqs. 2.9-2.10 for the slope's standard error), so a
//! constant edge offset `b` (e.g. a meniscus ring around the contact) is separated from the
//! scale. Four or more sizes also test the line itself: a radial lens distortion sees a
//! radius r at r (1 + k r^2) (the first radial term of Brown's model, "Decentering
//! distortion of lenses", 1966), so `r_px = b + s r + c r^3` is fitted by weighted least
//! squares (weights 1/sigma^2 of each disc's measured radius, at least the edge estimator's
//! systematic error) and k = c / s reported with its standard error ([`LensDistortion`]);
//! when k is significant the calibration is the cubic's and
//! [`PxPerMmCalibration::px_to_mm`] undoes the distortion. A scale and an offset absorb such a distortion
//! over the radii a contact reaches, so the contact-radius curves alone cannot show it
//! (docs/diagnosis.md, limitations); the discs can.

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
    /// The radial lens distortion the discs show (four or more distinct radii).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lens_distortion: Option<LensDistortion>,
}

/// The first radial distortion term fitted through the discs: a radius r is seen at
/// r (1 + k r^2).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LensDistortion {
    /// k in 1/mm^2 (0: none).
    pub k_per_mm2: f64,
    /// Its standard error, from the discs' measurement errors (0 when read from a record).
    pub k_sigma_per_mm2: f64,
    /// Whether [`PxPerMmCalibration::px_to_mm`] undoes it: a significant distortion is
    /// corrected (the scale and offset are then the cubic fit's), one consistent with 0 is
    /// only reported.
    pub corrected: bool,
}

impl LensDistortion {
    /// Whether k differs from 0 by more than [`Self::SIGNIFICANT_Z`] standard errors.
    pub fn significant(&self) -> bool {
        self.k_sigma_per_mm2 > 0.0
            && (self.k_per_mm2 / self.k_sigma_per_mm2).abs() > Self::SIGNIFICANT_Z
    }

    /// |k| / se beyond which the distortion is reported as present (a two-sided normal
    /// test at p < 0.003).
    pub const SIGNIFICANT_Z: f64 = 3.0;

    /// The relative change of a radius r (mm) the distortion causes.
    pub fn relative_at(&self, r_mm: f64) -> f64 {
        self.k_per_mm2 * r_mm * r_mm
    }
}

/// Smallest per-disc standard error used as a weight (px): the edge estimator's own
/// systematic error, which its per-frame error prediction does not contain: hil-sim's
/// exactly scaled discs (1.2-3.4 mm at 50 px/mm, no distortion) measured by this crate with
/// their predicted errors alone (about 0.01 px) showed a "distortion" of 9e-5 /mm^2 at 4.8
/// standard errors; with this floor the same discs give 1.1 (`tests/tests/camera_discs.rs`).
/// The smallest distortion then seen at 3 standard errors changes a 3.4 mm radius by
/// about 0.3 %.
const SIGMA_FLOOR_PX: f64 = 0.05;

/// Fits `r_px = b + s r + c r^3` by weighted least squares to (radius_mm, radius_px,
/// sigma_px) samples; k = c / s with its standard error from (X^T W X)^-1.
fn lens_distortion(samples: &[(f64, f64, f64)]) -> Option<CubicFit> {
    let mut a = [[0.0; 3]; 3];
    let mut rhs = [0.0; 3];
    for &(r, px, sigma) in samples {
        let w = 1.0 / sigma.max(SIGMA_FLOOR_PX).powi(2);
        let x = [1.0, r, r * r * r];
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] += w * x[i] * x[j];
            }
            rhs[i] += w * x[i] * px;
        }
    }
    let [b, slope, c] = super::linear_solve::solve(a, rhs)?;
    let [_, _, var_c] = super::linear_solve::solve(a, [0.0, 0.0, 1.0])?;
    let [_, var_s, _] = super::linear_solve::solve(a, [0.0, 1.0, 0.0])?;
    if slope <= 0.0 || var_c < 0.0 {
        return None;
    }
    // residuals larger than the weights say (chi^2 per degree of freedom above 1) widen
    // the error by its square root (the Birge ratio)
    let dof = samples.len().saturating_sub(3);
    let chi2: f64 = samples
        .iter()
        .map(|&(r, px, sigma)| {
            ((px - b - slope * r - c * r * r * r) / sigma.max(SIGMA_FLOOR_PX)).powi(2)
        })
        .sum();
    let inflation = if dof > 0 {
        (chi2 / dof as f64).max(1.0).sqrt()
    } else {
        1.0
    };
    let mut distortion = LensDistortion {
        k_per_mm2: c / slope,
        k_sigma_per_mm2: inflation * var_c.sqrt() / slope,
        corrected: false,
    };
    distortion.corrected = distortion.significant();
    Some(CubicFit {
        offset_px: b,
        px_per_mm: slope,
        px_per_mm_sigma: inflation * var_s.max(0.0).sqrt(),
        distortion,
    })
}

/// `r_px = b + s r (1 + k r^2)` through the discs.
struct CubicFit {
    offset_px: f64,
    px_per_mm: f64,
    px_per_mm_sigma: f64,
    distortion: LensDistortion,
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
            let mut radii: Vec<f64> = samples.iter().map(|s| s.0).collect();
            radii.sort_by(f64::total_cmp);
            radii.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs());
            let line = Self {
                px_per_mm: k,
                px_per_mm_sigma: (sigma2 / sxx).sqrt(),
                offset_px: Some(b),
                samples: n,
                lens_distortion: None,
            };
            // a significant distortion is corrected: scale and offset from the cubic
            return Ok(
                match (radii.len() >= 4)
                    .then(|| lens_distortion(samples))
                    .flatten()
                {
                    Some(cubic) if cubic.distortion.corrected => Self {
                        px_per_mm: cubic.px_per_mm,
                        px_per_mm_sigma: cubic.px_per_mm_sigma,
                        offset_px: Some(cubic.offset_px),
                        lens_distortion: Some(cubic.distortion),
                        ..line
                    },
                    Some(cubic) => Self {
                        lens_distortion: Some(cubic.distortion),
                        ..line
                    },
                    None => line,
                },
            );
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
            lens_distortion: None,
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

    /// The radius in mm of an image radius in px: the line's inverse, or with a corrected
    /// lens distortion the root of `px = b + s r (1 + k r^2)` (Newton's method from the
    /// line's value; the cubic is monotonic where 1 + 3 k r^2 > 0).
    pub fn px_to_mm(&self, px: f64) -> f64 {
        let linear = (px - self.offset_px.unwrap_or(0.0)) / self.px_per_mm;
        let Some(d) = self
            .lens_distortion
            .filter(|d| d.corrected && d.k_per_mm2 != 0.0)
        else {
            return linear;
        };
        let k = d.k_per_mm2;
        let mut r = linear;
        for _ in 0..20 {
            let f = r * (1.0 + k * r * r) - linear;
            let df = 1.0 + 3.0 * k * r * r;
            if df <= 0.0 {
                return linear;
            }
            let step = f / df;
            r -= step;
            if step.abs() <= 1e-12 * r.abs().max(1.0) {
                break;
            }
        }
        r
    }

    /// A calibration read back from its stored parts (a record keeps the scale, its error,
    /// the offset and a corrected distortion).
    pub fn stored(
        px_per_mm: f64,
        px_per_mm_sigma: f64,
        offset_px: Option<f64>,
        lens_distortion_k_per_mm2: Option<f64>,
    ) -> Self {
        Self {
            px_per_mm,
            px_per_mm_sigma,
            offset_px,
            samples: 0,
            lens_distortion: lens_distortion_k_per_mm2.map(|k| LensDistortion {
                k_per_mm2: k,
                k_sigma_per_mm2: 0.0,
                corrected: true,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Discs of the demo's radii seen through a lens with distortion `k` at 50 px/mm and a
    /// 3 px edge offset, each radius with an error of `sigma` px (a fixed pattern of
    /// +-1 sigma, so the test does not depend on a random draw).
    fn discs(k: f64, sigma: f64) -> Vec<(f64, f64, f64)> {
        [1.2, 2.0, 2.8, 3.4, 1.6]
            .iter()
            .zip([1.0, -1.0, 1.0, -1.0, -1.0])
            .map(|(&r, e)| (r, 3.0 + 50.0 * r * (1.0 + k * r * r) + e * sigma, sigma))
            .collect()
    }

    #[test]
    fn a_lens_distortion_is_measured_from_the_discs() {
        let cal = PxPerMmCalibration::from_measurements(&discs(0.002, 0.05)).unwrap();
        let d = cal.lens_distortion.unwrap();
        // the truth within 3 standard errors, and clearly present
        assert!(
            (d.k_per_mm2 - 0.002).abs() < 3.0 * d.k_sigma_per_mm2,
            "{d:?}"
        );
        assert!(d.significant(), "{d:?}");
    }

    #[test]
    fn a_corrected_distortion_gives_back_the_true_radii() {
        let cal = PxPerMmCalibration::from_measurements(&discs(0.002, 0.05)).unwrap();
        assert!(cal.lens_distortion.unwrap().corrected);
        for r in [0.5, 1.0, 2.0, 3.0, 3.7] {
            let px = 3.0 + 50.0 * r * (1.0 + 0.002 * r * r);
            // the discs' errors (0.05 px at 50 px/mm) allow about 1 um
            assert!(
                (cal.px_to_mm(px) - r).abs() < 3e-3,
                "{r}: {}",
                cal.px_to_mm(px)
            );
        }
        // the line alone is off by up to 1.5 % at the largest radius
        let line = PxPerMmCalibration {
            lens_distortion: None,
            ..PxPerMmCalibration::from_measurements(&discs(0.002, 0.05)[..3]).unwrap()
        };
        let px = 3.0 + 50.0 * 3.7 * (1.0 + 0.002 * 3.7 * 3.7);
        assert!((line.px_to_mm(px) - 3.7).abs() > 0.01);
    }

    #[test]
    fn straight_discs_show_no_distortion() {
        let cal = PxPerMmCalibration::from_measurements(&discs(0.0, 0.05)).unwrap();
        let d = cal.lens_distortion.unwrap();
        assert!(!d.significant() && !d.corrected, "{d:?}");
        // the line is what the scale reports
        assert!((cal.px_per_mm - 50.0).abs() < 0.1, "{cal:?}");
    }

    #[test]
    fn three_disc_sizes_cannot_test_the_line() {
        let samples: Vec<_> = discs(0.002, 0.05).into_iter().take(3).collect();
        let cal = PxPerMmCalibration::from_measurements(&samples).unwrap();
        assert_eq!(cal.lens_distortion, None);
    }
}
