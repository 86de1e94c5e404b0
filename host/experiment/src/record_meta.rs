//! `meta.json`, the description of one experiment record: who made it (software, device,
//! protocol), with what (table, calibration, plan, scenario) and how it ended (status, link
//! counters, frames). One typed schema, written and read by the same types; the
//! `schema_version` field changes whenever a field changes meaning.

use serde::{Deserialize, Serialize};

use super::IndentationPlan;
use super::pipeline::{LutInfo, RunContext};
use crate::calibration::CalibrationRecord;
use crate::records::{RecordDir, RecordError, unix_now_s};
use link::{Link, LinkStats};

/// The schema this build writes and reads.
pub const RECORD_SCHEMA_VERSION: u32 = 1;

/// The software that wrote a record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SoftwareInfo {
    pub name: String,
    pub version: String,
}

/// The controller a record was measured with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceMeta {
    pub serial: String,
    pub firmware_version: String,
    pub port: String,
}

/// Camera frames of a run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameCounts {
    /// Frames whose contact radius was measured.
    pub measured: u64,
    /// Frames that arrived but could not be measured.
    pub unmeasured: u64,
    /// Frames lost before they arrived (sequence gaps).
    pub dropped: u64,
}

/// How a record ended. Stored as one string: `running`, `complete`,
/// `complete; fit failed: REASON`, `failed: REASON`, `partial: REASON` (a run stopped on
/// purpose or by a lost link; everything received is kept).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum RecordStatus {
    Running,
    Complete,
    FitFailed(String),
    Failed(String),
    Partial(String),
}

impl From<RecordStatus> for String {
    fn from(s: RecordStatus) -> String {
        match s {
            RecordStatus::Running => "running".into(),
            RecordStatus::Complete => "complete".into(),
            RecordStatus::FitFailed(r) => format!("complete; fit failed: {r}"),
            RecordStatus::Failed(r) => format!("failed: {r}"),
            RecordStatus::Partial(r) => format!("partial: {r}"),
        }
    }
}

impl TryFrom<String> for RecordStatus {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        let reason = |prefix: &str| s.strip_prefix(prefix).map(str::to_string);
        match s.as_str() {
            "running" => Ok(Self::Running),
            "complete" => Ok(Self::Complete),
            _ => reason("complete; fit failed: ")
                .map(Self::FitFailed)
                .or_else(|| reason("failed: ").map(Self::Failed))
                .or_else(|| reason("partial: ").map(Self::Partial))
                .ok_or_else(|| format!("unknown record status {s:?}")),
        }
    }
}

/// The contents of `meta.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordMeta {
    pub schema_version: u32,
    pub software: SoftwareInfo,
    pub protocol_version: u8,
    pub device: DeviceMeta,
    pub lut: LutInfo,
    pub calibration: CalibrationRecord,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_path: Option<String>,
    pub plan: IndentationPlan,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<serde_json::Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub job: Option<u64>,
    pub status: RecordStatus,
    pub started_unix_s: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finished_unix_s: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<LinkStats>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<FrameCounts>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl RecordMeta {
    /// A running record's description, at the start of a run.
    pub fn new(
        link: &Link,
        calibration: &CalibrationRecord,
        plan: &IndentationPlan,
        lut: &LutInfo,
        context: &RunContext,
    ) -> Self {
        let info = link.info();
        Self {
            schema_version: RECORD_SCHEMA_VERSION,
            software: SoftwareInfo {
                name: if context.software.is_empty() {
                    "tactile".into()
                } else {
                    context.software.clone()
                },
                version: env!("CARGO_PKG_VERSION").into(),
            },
            protocol_version: info.protocol_version,
            device: DeviceMeta {
                serial: info.serial.as_str().into(),
                firmware_version: info.firmware_version.as_str().into(),
                port: link.port_name(),
            },
            lut: lut.clone(),
            calibration: calibration.clone(),
            calibration_path: context.calibration_path.clone(),
            plan: *plan,
            scenario: context.scenario.clone(),
            job: context.job,
            status: RecordStatus::Running,
            started_unix_s: unix_now_s(),
            finished_unix_s: None,
            link: None,
            frames: None,
            notes: Vec::new(),
        }
    }

    /// Writes `meta.json` (atomically, through the record).
    pub fn write(&self, record: &RecordDir) -> Result<(), RecordError> {
        record.write_json("meta.json", self).map(|_| ())
    }

    /// Reads a record's `meta.json`; the error names the file and the field.
    pub fn read(dir: &std::path::Path) -> Result<Self, RecordError> {
        let path = dir.join("meta.json");
        let text = std::fs::read_to_string(&path).map_err(|source| RecordError::Io {
            path: path.clone(),
            source,
        })?;
        let meta: Self = serde_json::from_str(&text).map_err(|e| RecordError::Encode {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        if meta.schema_version != RECORD_SCHEMA_VERSION {
            return Err(RecordError::Encode {
                path,
                reason: format!(
                    "record schema version {} (this build reads {RECORD_SCHEMA_VERSION})",
                    meta.schema_version
                ),
            });
        }
        Ok(meta)
    }
}

/// Why a record folder has no curve to analyse.
#[derive(Debug, thiserror::Error)]
pub enum RecordCurveError {
    #[error(transparent)]
    Meta(#[from] RecordError),
    #[error(
        "{dir}: the record's status is \"{status}\": only complete or partial records have a curve to analyse"
    )]
    NotFinished { dir: String, status: String },
    #[error(transparent)]
    Curve(#[from] fit::curve_csv::CurveCsvError),
}

/// The curve of a record folder: its `curve.csv`, at the record's nominal pressure (the
/// plan's set point from `meta.json`; the per-row manometer readings scatter around it, and
/// grouping by them would split one pressure into many). A record still running or failed
/// is refused by name.
pub fn record_curve_at_set_pressure(
    dir: &std::path::Path,
) -> Result<fit::curve_csv::CurveCsv, RecordCurveError> {
    let meta = RecordMeta::read(dir)?;
    if matches!(meta.status, RecordStatus::Running | RecordStatus::Failed(_)) {
        return Err(RecordCurveError::NotFinished {
            dir: dir.display().to_string(),
            status: String::from(meta.status),
        });
    }
    let mut curve = fit::curve_csv::read_curve_csv(&dir.join("curve.csv"))?;
    for row in &mut curve.rows {
        row.p_air_kpa = None;
    }
    curve.metadata.retain(|(k, _)| k != "p_air_kpa");
    curve
        .metadata
        .push(("p_air_kpa".into(), format!("{}", meta.plan.pressure_kpa)));
    Ok(curve)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_status_reads_back_as_written() {
        for s in [
            RecordStatus::Running,
            RecordStatus::Complete,
            RecordStatus::FitFailed("no contact".into()),
            RecordStatus::Failed("stage timeout".into()),
            RecordStatus::Partial("emergency stop".into()),
        ] {
            let text = serde_json::to_string(&s).unwrap_or_default();
            let back: RecordStatus = serde_json::from_str(&text).unwrap_or(RecordStatus::Running);
            assert_eq!(back, s, "{text}");
        }
        assert!(serde_json::from_str::<RecordStatus>("\"finished\"").is_err());
    }
}
