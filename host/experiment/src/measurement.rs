//! One complete measurement (`tactile measure`): with stored calibrations applied, set the
//! pressure, take the camera's no-contact reference at the start position, run the
//! indentations ([`super::run_indentation`]), then write curve.csv, the fit and the plots
//! ([`super::analysis`]). The camera is supplied by the caller as a function that builds a
//! [`RadiusSource`] once the reference can be taken, so a V4L2 camera
//! ([`super::camera_radius::CameraRadiusSource`]) and hil-sim's in-process frames are used
//! the same way.

use std::time::Duration;

use protocol::{ChannelSet, Request, StatusFlags};

use super::analysis::{AnalysisError, write_curve_and_fit};
use super::{ExperimentError, IndentationPlan, RadiusSource, run_indentation};
use crate::calibration::CalibrationRecord;
use crate::records::{RecordDir, RecordError};
use fit::{LutModel, ModulusFit};
use host_clock;
use link::{Link, LinkError, LinkStats};
use vision::px_per_mm::PxPerMmCalibration;

#[derive(Debug, thiserror::Error)]
pub enum MeasureError {
    #[error(
        "calibration: no proximity calibration at {pressure_kpa} kPa (have: {have}); run `tactile calibrate proximity --pressure {pressure_kpa}`"
    )]
    NoProximity { pressure_kpa: f64, have: String },
    #[error("calibration: no camera px/mm; run `tactile calibrate camera`")]
    NoCameraScale,
    #[error("camera: {0}")]
    Camera(String),
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error(transparent)]
    Experiment(#[from] ExperimentError),
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    #[error("the stage did not reach the start position {0:.3} mm")]
    Stage(f64),
}

/// What the table is, for meta.json.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LutInfo {
    pub path: String,
    pub sha256: String,
}

/// What a measurement produced.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MeasurementReport {
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    pub rms_residual_mm: f64,
    pub record_dir: String,
    pub fit: ModulusFit,
    pub points: usize,
    pub samples: usize,
    pub frames: usize,
    pub frames_unmeasured: u64,
    pub frames_dropped: u64,
    pub link: LinkStats,
    pub notes: Vec<String>,
}

/// The camera scale stored in a calibration record.
pub fn px_per_mm_of(calibration: &CalibrationRecord) -> Result<PxPerMmCalibration, MeasureError> {
    let px_per_mm = calibration.px_per_mm.ok_or(MeasureError::NoCameraScale)?;
    Ok(PxPerMmCalibration {
        px_per_mm,
        px_per_mm_sigma: calibration.px_per_mm_sigma.unwrap_or(0.0),
        offset_px: calibration.px_offset_px,
        samples: 0,
    })
}

/// Moves the stage to `target_mm` at `speed` and waits until it stops there.
pub fn move_stage_to(
    link: &mut Link,
    target_mm: f64,
    speed_mm_per_s: f64,
) -> Result<(), MeasureError> {
    let units = *link.units();
    let target = units.stage_steps(target_mm);
    link.start_stream(200, ChannelSet::ALL)?;
    link.request(Request::MoveStage {
        target_steps: target,
        speed_steps_per_s: (speed_mm_per_s * units.stage_steps_per_mm()).round() as u32,
        accel_steps_per_s2: (50.0 * units.stage_steps_per_mm()).round() as u32,
    })?;
    let start = host_clock::now_us();
    loop {
        link.pump(Duration::from_millis(50))?;
        if link.drain_samples().last().is_some_and(|s| {
            s.sample.stage_steps == Some(target)
                && !s.sample.status.contains(StatusFlags::STAGE_MOVING)
        }) {
            link.stop_stream()?;
            return Ok(());
        }
        if host_clock::now_us().saturating_sub(start) > 60_000_000 {
            return Err(MeasureError::Stage(target_mm));
        }
    }
}

/// Runs the measurement. `make_radius` is called with the pressure set and the stage at
/// the start position (out of contact), to take the reference frame and start measuring.
#[allow(clippy::too_many_arguments)]
pub fn run_measurement<'a>(
    link: &mut Link,
    calibration: &CalibrationRecord,
    plan: &IndentationPlan,
    record: &RecordDir,
    model: &LutModel,
    lut: &LutInfo,
    progress: &indicatif::ProgressBar,
    make_radius: impl FnOnce(
        &mut Link,
        PxPerMmCalibration,
    ) -> Result<Box<dyn RadiusSource + 'a>, String>,
) -> Result<MeasurementReport, MeasureError> {
    let proximity =
        *calibration
            .proximity_at(plan.pressure_kpa)
            .ok_or_else(|| MeasureError::NoProximity {
                pressure_kpa: plan.pressure_kpa,
                have: calibration
                    .proximity
                    .iter()
                    .map(|c| format!("{} kPa", c.p_air_kpa))
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
    let px = px_per_mm_of(calibration)?;
    let zero = calibration.manometer_zero_kpa;
    let mut meta = serde_json::json!({
        "software": { "name": "tactile", "version": env!("CARGO_PKG_VERSION") },
        "protocol_version": link.info().protocol_version,
        "device": {
            "serial": link.info().serial.as_str(),
            "firmware_version": link.info().firmware_version.as_str(),
            "port": link.port_name(),
        },
        "lut": lut,
        "calibration": calibration,
        "plan": {
            "pressure_kpa": plan.pressure_kpa,
            "start_mm": plan.start_mm,
            "depth_mm": plan.depth_mm,
            "speed_mm_per_s": plan.speed_mm_per_s,
            "repeats": plan.repeats,
            "stream_rate_hz": plan.stream_rate_hz,
        },
        "status": "running",
    });
    record.write_json("meta.json", &meta)?;
    tracing::info!(pressure_kpa = plan.pressure_kpa, "setting pressure");
    link.request(Request::SetLed {
        duty_per_10k: 10_000,
    })?;
    link.request(Request::SetPressure {
        setpoint_kpa: (plan.pressure_kpa + zero) as f32,
    })?;
    move_stage_to(link, plan.start_mm, plan.speed_mm_per_s.max(1.0))?;
    link.pump(Duration::from_millis(1000))?;
    let mut radius = make_radius(link, px).map_err(MeasureError::Camera)?;
    let run = run_indentation(
        link,
        radius.as_mut(),
        plan,
        &proximity,
        zero,
        record,
        progress,
    );
    let stats = link.stats();
    let (unmeasured, dropped) = radius.failures();
    drop(radius);
    let result = match run {
        Ok(r) => r,
        Err(e) => {
            meta["status"] = serde_json::json!(format!("failed: {e}"));
            meta["link"] = serde_json::to_value(stats).unwrap_or_default();
            record.write_json("meta.json", &meta)?;
            return Err(e.into());
        }
    };
    let (fit, points, plot_problem) =
        write_curve_and_fit(record, &result, plan.pressure_kpa, model)?;
    meta["status"] = serde_json::json!("complete");
    meta["link"] = serde_json::to_value(stats).unwrap_or_default();
    meta["frames"] = serde_json::json!({
        "measured": result.frames, "unmeasured": unmeasured, "dropped": dropped
    });
    record.write_json("meta.json", &meta)?;
    let mut notes = Vec::new();
    if let Some(p) = plot_problem {
        notes.push(format!("plots could not be written: {p}"));
    }
    Ok(MeasurementReport {
        modulus_kpa: fit.modulus_kpa,
        ci95_kpa: fit.ci95_kpa,
        rms_residual_mm: fit.rms_residual_mm,
        record_dir: record.dir.display().to_string(),
        points: points.len(),
        samples: result.samples,
        frames: result.frames,
        frames_unmeasured: unmeasured,
        frames_dropped: dropped,
        link: stats,
        fit,
        notes,
    })
}
