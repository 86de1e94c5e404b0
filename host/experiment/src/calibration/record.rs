//! Calibration records: one JSON file per calibration run, named by its UTC time, in a
//! calibration directory; later runs load the newest one.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

use super::proximity::ProximityCalibration;

/// Everything one calibration run produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationRecord {
    /// UTC time of the run, seconds since the Unix epoch.
    pub created_unix_s: u64,
    pub device_serial: String,
    pub firmware_version: String,
    /// Proximity parabola per pressure, from u_s taken as fem-core's rigid-contact u_s(h)
    /// when available, else u_s = h.
    pub proximity: Vec<ProximityCalibration>,
    /// The same fit with u_s = h (the paper's assumption), for comparison.
    pub proximity_u_s_equals_h: Vec<ProximityCalibration>,
    /// Largest difference in u_s between the two calibrations over the calibrated range.
    pub u_s_vs_h_max_difference_mm: Option<f64>,
    /// How the rigid-sample u_s(h) was obtained.
    pub rigid_u_s_source: String,
    /// Camera scale.
    pub px_per_mm: Option<f64>,
    /// Manometer reading at zero gauge pressure (vent open).
    pub manometer_zero_kpa: f64,
    /// Load-cell reading after the device's tare (should be ~0).
    pub load_tare_residual_n: f64,
    /// The rigid-sample sweeps behind `proximity` (contact, both fits, their difference).
    #[serde(default)]
    pub proximity_sweeps: Vec<super::SweepFit>,
    /// Standard error of `px_per_mm`.
    #[serde(default)]
    pub px_per_mm_sigma: Option<f64>,
    /// Edge offset of the camera scale (r_px = px_per_mm r_mm + offset), when fitted.
    #[serde(default)]
    pub px_offset_px: Option<f64>,
    /// The lens distortion k (1/mm^2) the reference discs showed and the radii are
    /// corrected for: r_px = offset + px_per_mm r (1 + k r^2); absent when the discs were
    /// consistent with a straight line (`vision::px_per_mm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens_distortion_k_per_mm2: Option<f64>,
    /// How late the camera's frames are stamped after their exposure (s), subtracted
    /// from their host times before pairing (`tactile calibrate camera-latency`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_latency_s: Option<f64>,
}

impl CalibrationRecord {
    /// An empty record for `device_serial` created now.
    pub fn new(device_serial: &str, firmware_version: &str) -> Self {
        Self {
            created_unix_s: crate::records::unix_now_s(),
            device_serial: device_serial.to_string(),
            firmware_version: firmware_version.to_string(),
            proximity: Vec::new(),
            proximity_u_s_equals_h: Vec::new(),
            u_s_vs_h_max_difference_mm: None,
            rigid_u_s_source: String::new(),
            px_per_mm: None,
            manometer_zero_kpa: 0.0,
            load_tare_residual_n: 0.0,
            proximity_sweeps: Vec::new(),
            px_per_mm_sigma: None,
            px_offset_px: None,
            lens_distortion_k_per_mm2: None,
            camera_latency_s: None,
        }
    }

    /// Stores a sweep's result, replacing any earlier one at the same pressure.
    pub fn set_proximity(&mut self, fit: &super::SweepFit) {
        let p = fit.calibration.p_air_kpa;
        let same = |q: f64| (q - p).abs() < 1e-6;
        self.proximity.retain(|c| !same(c.p_air_kpa));
        self.proximity_u_s_equals_h.retain(|c| !same(c.p_air_kpa));
        self.proximity_sweeps
            .retain(|s| !same(s.calibration.p_air_kpa));
        self.proximity.push(fit.calibration);
        self.proximity_u_s_equals_h
            .push(fit.calibration_u_s_equals_h);
        self.proximity_sweeps.push(fit.clone());
        self.u_s_vs_h_max_difference_mm = self
            .proximity_sweeps
            .iter()
            .map(|s| s.u_s_difference_max_mm)
            .reduce(f64::max);
        self.rigid_u_s_source = fit.rigid_u_s_source.clone();
    }

    /// The proximity calibration at `p_air_kpa` (within 0.5 kPa).
    /// The load cell's scale ([`super::SweepFit::load_scale`]) from the rigid-sample sweep
    /// nearest to `p_air_kpa` (within 0.5 kPa, as [`Self::proximity_at`]); None when that
    /// sweep has none (the cell is then read with its nominal scale).
    pub fn load_scale_at(&self, p_air_kpa: f64) -> Option<f64> {
        self.proximity_sweeps
            .iter()
            .filter(|s| (s.calibration.p_air_kpa - p_air_kpa).abs() <= 0.5)
            .min_by(|a, b| {
                (a.calibration.p_air_kpa - p_air_kpa)
                    .abs()
                    .total_cmp(&(b.calibration.p_air_kpa - p_air_kpa).abs())
            })
            .and_then(|s| s.load_scale)
    }

    pub fn proximity_at(&self, p_air_kpa: f64) -> Option<&ProximityCalibration> {
        self.proximity
            .iter()
            .filter(|c| (c.p_air_kpa - p_air_kpa).abs() <= 0.5)
            .min_by(|a, b| {
                (a.p_air_kpa - p_air_kpa)
                    .abs()
                    .total_cmp(&(b.p_air_kpa - p_air_kpa).abs())
            })
    }
}

#[derive(Debug, thiserror::Error)]
pub enum CalibrationStoreError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a calibration record: {source}")]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error(
        "calibration folder {path}: {source}; run `tactile calibrate` first, or name a record with --calibration FILE"
    )]
    Folder {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {bytes} bytes is not a calibration record (at most {MAX_RECORD_BYTES})")]
    TooLarge { path: PathBuf, bytes: u64 },
    #[error("no calibration record in {0}: run `tactile calibrate` first")]
    None(PathBuf),
    #[error("no valid calibration record in {dir}: {}", rejected.join("; "))]
    NoneValid { dir: PathBuf, rejected: Vec<String> },
}

/// Writes `record` as `<dir>/calibration-<unix seconds>.json`; returns the path.
pub fn save_record(
    dir: &Path,
    record: &CalibrationRecord,
) -> Result<PathBuf, CalibrationStoreError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| CalibrationStoreError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let path = dir.join(format!("calibration-{}.json", record.created_unix_s));
    let text =
        serde_json::to_string_pretty(record).map_err(|source| CalibrationStoreError::Json {
            path: path.clone(),
            source,
        })?;
    std::fs::write(&path, text).map_err(io(&path))?;
    Ok(path)
}

/// The newest valid record in `dir` (by its time-stamped name). A newer file that cannot
/// be read or parsed is skipped with a warning naming it, so one truncated record does not
/// hide the valid ones before it; if none is valid the error names every rejected file.
pub fn load_latest(dir: &Path) -> Result<(PathBuf, CalibrationRecord), CalibrationStoreError> {
    let entries = std::fs::read_dir(dir).map_err(|source| CalibrationStoreError::Folder {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("calibration-") && n.ends_with(".json"))
        })
        .collect();
    files.sort();
    let mut rejected = Vec::new();
    while let Some(path) = files.pop() {
        match load_record(&path) {
            Ok(record) => {
                for reason in &rejected {
                    tracing::warn!("skipped calibration record {reason}");
                }
                return Ok((path, record));
            }
            Err(e) => rejected.push(e.to_string()),
        }
    }
    if rejected.is_empty() {
        Err(CalibrationStoreError::None(dir.to_path_buf()))
    } else {
        Err(CalibrationStoreError::NoneValid {
            dir: dir.to_path_buf(),
            rejected,
        })
    }
}

/// Largest calibration record read (a real one is a few kB).
pub const MAX_RECORD_BYTES: u64 = 4 << 20;

/// One record file.
pub fn load_record(path: &Path) -> Result<CalibrationRecord, CalibrationStoreError> {
    let io = |source| CalibrationStoreError::Io {
        path: path.to_path_buf(),
        source,
    };
    let size = std::fs::metadata(path).map_err(io)?.len();
    if size > MAX_RECORD_BYTES {
        return Err(CalibrationStoreError::TooLarge {
            path: path.to_path_buf(),
            bytes: size,
        });
    }
    let text =
        fem_core::input_file::read_limited_text(path, MAX_RECORD_BYTES, "a calibration record")
            .map_err(io)?;
    serde_json::from_str(&text).map_err(|source| CalibrationStoreError::Json {
        path: path.to_path_buf(),
        source,
    })
}
