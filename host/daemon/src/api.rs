//! The API's request and response bodies and the live-feed events (JSON), shared by the
//! daemon and its clients. docs/daemon-api.md describes them with curl examples.

use serde::{Deserialize, Serialize};

/// The default address clients look for the daemon at.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:7878";

/// Largest request body accepted (bytes).
pub const MAX_BODY_BYTES: usize = 16 * 1024;

/// `POST /v1/pressure`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PressureRequest {
    /// Gauge setpoint in kPa (0 switches the regulator off).
    pub kpa: f64,
}

/// `POST /v1/vent`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VentRequest {
    pub open: bool,
}

fn default_start_mm() -> f64 {
    0.8
}
fn default_depth_mm() -> f64 {
    1.2
}
fn default_speed() -> f64 {
    2.0
}
fn default_repeats() -> u32 {
    3
}
fn default_rate() -> u16 {
    2000
}

/// The internal pressures an experiment may run at (kPa).
pub const EXPERIMENT_PRESSURE_KPA: std::ops::RangeInclusive<f64> = 0.5..=15.0;

/// The probe pressure of the automatic choice when the request names none (the paper's
/// working pressure).
pub const DEFAULT_PROBE_KPA: f64 = 6.0;

/// An experiment's internal pressure: a set point, or the automatic choice (`"auto"`: a
/// one-indentation probe, then the measurement at the calibrated pressure where the lookup
/// table predicts the smallest modulus error for the sample the probe found). In JSON a
/// number of kPa or the string `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PressureSetting {
    Kpa(f64),
    Auto,
}

impl From<f64> for PressureSetting {
    fn from(kpa: f64) -> Self {
        Self::Kpa(kpa)
    }
}

impl Serialize for PressureSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Kpa(v) => s.serialize_f64(*v),
            Self::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for PressureSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = PressureSetting;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a pressure in kPa or \"auto\"")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Self::Value, E> {
                Ok(PressureSetting::Kpa(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
                Ok(PressureSetting::Kpa(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
                Ok(PressureSetting::Kpa(v as f64))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
                if v.eq_ignore_ascii_case("auto") {
                    Ok(PressureSetting::Auto)
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Str(v), &self))
                }
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// `POST /v1/experiments`: an indentation experiment (see `experiment::IndentationPlan`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentRequest {
    /// Internal (shell) gauge pressure: kPa, or `"auto"`.
    pub pressure_kpa: PressureSetting,
    /// With `"pressure_kpa": "auto"`: the probe's pressure (default [`DEFAULT_PROBE_KPA`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_pressure_kpa: Option<f64>,
    /// Stage position where each cycle starts, mm from the stage's zero (above the sample).
    #[serde(default = "default_start_mm")]
    pub start_mm: f64,
    /// Travel of each indentation below `start_mm`.
    #[serde(default = "default_depth_mm")]
    pub depth_mm: f64,
    #[serde(default = "default_speed")]
    pub speed_mm_per_s: f64,
    #[serde(default = "default_repeats")]
    pub repeats: u32,
    #[serde(default = "default_rate")]
    pub stream_rate_hz: u16,
    /// Free text kept in the record.
    #[serde(default)]
    pub label: String,
}

/// A field that failed validation.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FieldError {
    pub field: String,
    pub reason: String,
}

impl ExperimentRequest {
    /// Checks every field against the instrument's limits; all problems at once.
    pub fn validate(&self) -> Result<(), Vec<FieldError>> {
        let mut errors = Vec::new();
        let mut check = |ok: bool, field: &str, reason: String| {
            if !ok {
                errors.push(FieldError {
                    field: field.into(),
                    reason,
                });
            }
        };
        let in_range = |p: f64| p.is_finite() && EXPERIMENT_PRESSURE_KPA.contains(&p);
        match (self.pressure_kpa, self.probe_pressure_kpa) {
            (PressureSetting::Kpa(p), probe) => {
                check(
                    in_range(p),
                    "pressure_kpa",
                    format!("{p} is outside 0.5..=15 kPa"),
                );
                check(
                    probe.is_none(),
                    "probe_pressure_kpa",
                    "only with \"pressure_kpa\": \"auto\"".into(),
                );
            }
            (PressureSetting::Auto, Some(p)) => check(
                in_range(p),
                "probe_pressure_kpa",
                format!("{p} is outside 0.5..=15 kPa"),
            ),
            (PressureSetting::Auto, None) => {}
        }
        check(
            self.start_mm.is_finite() && (-5.0..=20.0).contains(&self.start_mm),
            "start_mm",
            format!("{} is outside -5..=20 mm", self.start_mm),
        );
        check(
            self.depth_mm.is_finite() && self.depth_mm > 0.0 && self.depth_mm <= 3.0,
            "depth_mm",
            format!("{} is outside (0, 3] mm", self.depth_mm),
        );
        check(
            self.speed_mm_per_s.is_finite() && (0.05..=5.0).contains(&self.speed_mm_per_s),
            "speed_mm_per_s",
            format!("{} is outside 0.05..=5 mm/s", self.speed_mm_per_s),
        );
        check(
            (1..=50).contains(&self.repeats),
            "repeats",
            format!("{} is outside 1..=50", self.repeats),
        );
        check(
            (100..=2000).contains(&self.stream_rate_hz),
            "stream_rate_hz",
            format!("{} is outside 100..=2000 Hz", self.stream_rate_hz),
        );
        check(
            self.label.len() <= 200,
            "label",
            "longer than 200 characters".into(),
        );
        if errors.is_empty() {
            Ok(())
        } else {
            Err(errors)
        }
    }

    /// The pressure of the first run: the set one, or the automatic choice's probe.
    pub fn first_pressure_kpa(&self) -> f64 {
        match self.pressure_kpa {
            PressureSetting::Kpa(p) => p,
            PressureSetting::Auto => self.probe_pressure_kpa.unwrap_or(DEFAULT_PROBE_KPA),
        }
    }
}

/// The body of every 4xx/5xx answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ApiError {
    pub error: String,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fields: Vec<FieldError>,
}

/// A job's life.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Queued,
    Running,
    Complete,
    /// Ended early (device gone, fault, emergency stop, cancelled): the record is partial.
    Partial,
    Failed,
    Cancelled,
}

impl JobState {
    pub fn is_finished(self) -> bool {
        !matches!(self, JobState::Queued | JobState::Running)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobKind {
    Experiment,
    /// Simulated bench only: rigid-sample proximity and camera px/mm calibration.
    Calibration,
}

/// A modulus estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitSummary {
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    pub rms_residual_mm: f64,
    pub points: usize,
    /// Internal pressure the fit used.
    pub p_air_kpa: f64,
}

/// What the automatic pressure choice decided (also `pressure_choice.json` in the record).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PressureChoiceSummary {
    /// The probe: its pressure, its modulus estimate and interval, and its record (the
    /// experiment's record's `probe` folder).
    pub probe_kpa: f64,
    pub probe_modulus_kpa: f64,
    pub probe_ci95_kpa: [f64; 2],
    pub probe_record: String,
    /// The pressure the measurement runs at and the relative standard error of the modulus
    /// the table predicts there.
    pub chosen_kpa: f64,
    pub predicted_relative_se: f64,
    /// Every pressure considered: the table's pressures within the experiment range that
    /// the calibration covers.
    pub candidates: Vec<PressureCandidate>,
}

/// One pressure the automatic choice considered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PressureCandidate {
    pub p_air_kpa: f64,
    pub predicted_relative_se: f64,
    /// Largest apex displacement the table covers there for the probe's modulus.
    pub u_s_max_mm: f64,
}

/// One queued, running or finished job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Job {
    pub id: u64,
    pub kind: JobKind,
    pub state: JobState,
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub experiment: Option<ExperimentRequest>,
    /// Record directory name (under the records directory), once created.
    pub record: Option<String>,
    pub message: String,
    /// 0..1 while running.
    pub progress: f64,
    pub fit: Option<FitSummary>,
    /// An experiment with `"pressure_kpa": "auto"`, once its probe has chosen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pressure_choice: Option<PressureChoiceSummary>,
    pub submitted_unix_s: u64,
    pub finished_unix_s: Option<u64>,
}

/// A period the device was away.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkGap {
    pub lost_unix_ms: u64,
    pub restored_unix_ms: Option<u64>,
    pub gap_s: Option<f64>,
    pub reason: String,
    pub port_before: String,
    pub port_after: Option<String>,
}

/// What `GET /v1/status` answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct StatusReport {
    pub daemon_version: String,
    pub connected: bool,
    pub port: Option<String>,
    pub serial: Option<String>,
    pub firmware_version: Option<String>,
    pub protocol_version: Option<u8>,
    pub pressure_kpa: Option<f64>,
    pub setpoint_kpa: Option<f64>,
    pub pump_duty: Option<f64>,
    pub vent_open: Option<bool>,
    pub stage_mm: Option<f64>,
    pub stage_moving: Option<bool>,
    pub streaming: Option<bool>,
    /// Latched device faults (names).
    pub faults: Vec<String>,
    pub camera: String,
    pub current_job: Option<Job>,
    pub queue: Vec<Job>,
    pub gaps: Vec<LinkGap>,
    pub link: Option<LinkSummary>,
    pub emergency_stops: u64,
    pub last_error: Option<String>,
    pub records_dir: String,
    pub feed_clients: usize,
}

/// The link's counters (`link::LinkStats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub struct LinkSummary {
    pub requests: u64,
    pub retries: u64,
    pub blocks_received: u64,
    pub blocks_lost: u64,
    pub samples_received: u64,
    pub frame_errors: u64,
    pub stale_replies: u64,
    pub overrun_samples: u64,
    pub pings: u64,
}

impl From<link::LinkStats> for LinkSummary {
    fn from(s: link::LinkStats) -> Self {
        Self {
            requests: s.requests,
            retries: s.retries,
            blocks_received: s.blocks_received,
            blocks_lost: s.blocks_lost,
            samples_received: s.samples_received,
            frame_errors: s.frame_errors,
            stale_replies: s.stale_replies,
            overrun_samples: s.overrun_samples,
            pings: s.pings,
        }
    }
}

/// `POST /v1/stop` answer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StopReport {
    /// The stop frames were written to the device.
    pub sent: bool,
    /// The device acknowledged all of them.
    pub acknowledged: bool,
    /// From the request reaching the daemon to the frames written / acknowledged (ms).
    pub sent_after_ms: Option<f64>,
    pub acknowledged_after_ms: Option<f64>,
    /// A running job was cancelled.
    pub cancelled_job: Option<u64>,
}

/// One live-feed event (`GET /v1/events`, Server-Sent Events; the SSE event name is the
/// `type` field).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Event {
    /// A decimated sample (the newest of `n` raw ones).
    Sample {
        device_time_us: u64,
        /// Daemon's receive time, µs since the Unix epoch.
        received_unix_us: u64,
        n: u32,
        pressure_kpa: Option<f64>,
        stage_mm: Option<f64>,
        load_n: Option<f64>,
        /// Apex displacement (calibrated; during experiments).
        u_s_mm: Option<f64>,
        status: u16,
    },
    /// Contact radius of one camera frame (during experiments).
    Frame {
        host_time_us: f64,
        a_mm: f64,
    },
    /// A paired point of the a–u_s curve.
    Point {
        u_s_mm: f64,
        a_mm: f64,
        cycle: u32,
    },
    /// Running (or final) modulus fit.
    Fit {
        fit: FitSummary,
        /// Model a(u_s) at the estimate over the measured range: `[u_s_mm, a_mm]` pairs.
        model: Vec<[f64; 2]>,
        final_fit: bool,
    },
    Job {
        job: Job,
    },
    Link {
        connected: bool,
        port: Option<String>,
        message: String,
        gap: Option<LinkGap>,
    },
    Fault {
        latched: Vec<String>,
        new: Vec<String>,
    },
    /// Once a second: stream health.
    Stats {
        blocks_lost: u64,
        frame_errors: u64,
        samples_received: u64,
        frames_measured: u64,
        frames_dropped: u64,
    },
    EmergencyStop {
        acknowledged: bool,
    },
    /// This client fell behind and `skipped` events were dropped for it.
    Lagged {
        skipped: u64,
    },
}

impl Event {
    pub fn name(&self) -> &'static str {
        match self {
            Event::Sample { .. } => "sample",
            Event::Frame { .. } => "frame",
            Event::Point { .. } => "point",
            Event::Fit { .. } => "fit",
            Event::Job { .. } => "job",
            Event::Link { .. } => "link",
            Event::Fault { .. } => "fault",
            Event::Stats { .. } => "stats",
            Event::EmergencyStop { .. } => "emergency_stop",
            Event::Lagged { .. } => "lagged",
        }
    }
}

/// Names of the fault bits.
pub fn fault_names(flags: u16) -> Vec<String> {
    use protocol::FaultFlags as F;
    let table = [
        (F::OVERPRESSURE, "OVERPRESSURE"),
        (F::MANOMETER_RANGE, "MANOMETER_RANGE"),
        (F::MANOMETER_STUCK, "MANOMETER_STUCK"),
        (F::HEARTBEAT_LOST, "HEARTBEAT_LOST"),
        (F::LOAD_CELL_TIMEOUT, "LOAD_CELL_TIMEOUT"),
        (F::WATCHDOG_RESET, "WATCHDOG_RESET"),
    ];
    table
        .iter()
        .filter(|(bit, _)| flags & *bit != 0)
        .map(|(_, n)| (*n).to_string())
        .collect()
}

/// Milliseconds since the Unix epoch.
pub fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// Microseconds since the Unix epoch.
pub fn unix_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(json: &str) -> Result<ExperimentRequest, String> {
        serde_json::from_str(json).map_err(|e| e.to_string())
    }

    fn bad_fields(json: &str) -> Vec<String> {
        match request(json).map(|r| r.validate()) {
            Ok(Err(fields)) => fields.into_iter().map(|f| f.field).collect(),
            other => panic!("{json}: {other:?}"),
        }
    }

    #[test]
    fn the_pressure_is_a_number_or_auto() {
        let set = request(r#"{"pressure_kpa": 6}"#).unwrap();
        assert_eq!(set.pressure_kpa, PressureSetting::Kpa(6.0));
        assert_eq!((set.validate(), set.first_pressure_kpa()), (Ok(()), 6.0));
        let auto = request(r#"{"pressure_kpa": "auto"}"#).unwrap();
        assert_eq!(auto.pressure_kpa, PressureSetting::Auto);
        assert_eq!(auto.validate(), Ok(()));
        assert_eq!(auto.first_pressure_kpa(), DEFAULT_PROBE_KPA);
        let probe = request(r#"{"pressure_kpa": "AUTO", "probe_pressure_kpa": 10}"#).unwrap();
        assert_eq!(
            (probe.validate(), probe.first_pressure_kpa()),
            (Ok(()), 10.0)
        );
        // round trip: a set pressure stays a number, the choice the string
        let text = serde_json::to_string(&probe).unwrap();
        assert!(text.contains(r#""pressure_kpa":"auto""#), "{text}");
        assert_eq!(request(&text).unwrap(), probe);
        let text = serde_json::to_string(&set).unwrap();
        assert!(text.contains(r#""pressure_kpa":6.0"#), "{text}");
        assert!(!text.contains("probe_pressure_kpa"), "{text}");
    }

    #[test]
    fn other_words_and_unknown_fields_are_refused_by_name() {
        let e = request(r#"{"pressure_kpa": "high"}"#).unwrap_err();
        assert!(e.contains("\"auto\"") && e.contains("high"), "{e}");
        let e = request(r#"{"pressure_kpa": "auto", "probe_kpa": 6}"#).unwrap_err();
        assert!(e.contains("probe_kpa"), "{e}");
        assert!(
            request(r#"{"depth_mm": 1}"#)
                .unwrap_err()
                .contains("pressure_kpa")
        );
    }

    #[test]
    fn the_probe_pressure_is_checked_at_its_own_field() {
        assert_eq!(
            bad_fields(r#"{"pressure_kpa": "auto", "probe_pressure_kpa": 30}"#),
            ["probe_pressure_kpa"]
        );
        assert_eq!(
            bad_fields(r#"{"pressure_kpa": "auto", "probe_pressure_kpa": 0.2, "repeats": 0}"#),
            ["probe_pressure_kpa", "repeats"]
        );
        // a probe pressure belongs to the automatic choice only
        assert_eq!(
            bad_fields(r#"{"pressure_kpa": 6, "probe_pressure_kpa": 6}"#),
            ["probe_pressure_kpa"]
        );
        assert_eq!(
            bad_fields(r#"{"pressure_kpa": 40, "probe_pressure_kpa": 6}"#),
            ["pressure_kpa", "probe_pressure_kpa"]
        );
    }
}
