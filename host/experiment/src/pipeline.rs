//! One experiment, whoever runs it — `tactile measure`, `tactile demo`, the daemon's jobs:
//! with a calibration applied, set the pressure, move to the start position, take the
//! camera's no-contact reference, run the indentations ([`super::run_indentation`]), then
//! write `curve.csv`, the fit and the plots ([`super::analysis`]), keeping `meta.json`
//! ([`RecordMeta`], one typed and versioned schema) up to date at every step. The frame
//! source is supplied by the caller as a function that builds a [`RadiusSource`] once the
//! reference can be taken, so a V4L2 camera
//! ([`super::camera_radius::CameraRadiusSource`]), hil-sim's in-process frames and the
//! daemon's live-feed wrapper are used the same way.

use std::time::Duration;

use protocol::{ChannelSet, StatusFlags, endpoints};

use super::analysis::{AnalysisError, write_curve_and_fit};
use super::record_meta::{FrameCounts, RecordMeta, RecordStatus};
use super::{ExperimentError, IndentationPlan, RadiusSource, run_indentation};
use crate::calibration::CalibrationRecord;
use crate::records::{RecordDir, RecordError, unix_now_s};
use fit::{FitPoint, LutModel, ModulusFit};
use link::{Link, LinkError, LinkStats};
use vision::px_per_mm::PxPerMmCalibration;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
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
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LutInfo {
    pub path: String,
    pub sha256: String,
    /// The setup's model file the table was augmented with (`tactile diagnose --apply`):
    /// its path, SHA-256 and contents.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<serde_json::Value>,
}

/// What an experiment produced.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ExperimentReport {
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
    /// The camera's latency applied to the frames and what the curve's two branches
    /// still imply (see [`crate::camera_latency`]).
    pub camera_timing: CameraTiming,
    pub notes: Vec<String>,
    /// The points the fit used (for a caller that plots or publishes them).
    #[serde(skip)]
    pub fit_points: Vec<FitPoint>,
}

/// The camera timing of a measurement.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CameraTiming {
    /// The calibration's latency, subtracted from host-stamped frame times (s).
    pub latency_applied_s: f64,
    /// The latency the loading and unloading branches still imply after that (s; `None`
    /// with the reason if it could not be estimated). On an elastic sample it should be
    /// near zero; on a viscoelastic one it includes the sample's own hysteresis.
    pub residual_latency_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_not_estimated: Option<String>,
}

/// Residual latency above which a measurement notes that the camera timing looks wrong.
pub const RESIDUAL_LATENCY_NOTE_S: f64 = 0.02;

/// The camera timing of a run's paired points.
pub fn camera_timing(
    latency_applied_s: f64,
    points: &[(u32, crate::pairing::PairedPoint)],
) -> CameraTiming {
    let curve: Vec<crate::camera_latency::CurvePoint> = points
        .iter()
        .map(|(cycle, p)| crate::camera_latency::CurvePoint {
            cycle: *cycle,
            t_s: p.t_s,
            u_s_mm: p.u_s_mm,
            a_mm: p.a_mm,
            phase: p.phase,
        })
        .collect();
    match crate::camera_latency::estimate_camera_latency(&curve) {
        Ok(e) => CameraTiming {
            latency_applied_s,
            residual_latency_s: Some(e.latency_s),
            residual_not_estimated: None,
        },
        Err(e) => CameraTiming {
            latency_applied_s,
            residual_latency_s: None,
            residual_not_estimated: Some(e.to_string()),
        },
    }
}

/// The camera scale stored in a calibration record.
pub fn px_per_mm_of(calibration: &CalibrationRecord) -> Result<PxPerMmCalibration, RunError> {
    let px_per_mm = calibration.px_per_mm.ok_or(RunError::NoCameraScale)?;
    Ok(PxPerMmCalibration::stored(
        px_per_mm,
        calibration.px_per_mm_sigma.unwrap_or(0.0),
        calibration.px_offset_px,
        calibration.lens_distortion_k_per_mm2,
    ))
}

/// Moves the stage to `target_mm` at `speed` and waits until it stops there.
pub fn move_stage_to(link: &mut Link, target_mm: f64, speed_mm_per_s: f64) -> Result<(), RunError> {
    let units = *link.units();
    let target = units.stage_steps(target_mm);
    link.start_stream(200, ChannelSet::ALL)?;
    link.call(endpoints::MoveStage {
        target_steps: target,
        speed_steps_per_s: (speed_mm_per_s * units.stage_steps_per_mm()).round() as u32,
        accel_steps_per_s2: (50.0 * units.stage_steps_per_mm()).round() as u32,
    })?;
    let start = host_clock::now_us();
    loop {
        link.receive_for(Duration::from_millis(50))?;
        if link.drain_samples().last().is_some_and(|s| {
            s.sample.stage_steps == Some(target)
                && !s.sample.status.contains(StatusFlags::STAGE_MOVING)
        }) {
            link.stop_stream()?;
            return Ok(());
        }
        if host_clock::now_us().saturating_sub(start) > 60_000_000 {
            return Err(RunError::Stage(target_mm));
        }
    }
}

/// Who runs the experiment and what else the record should say.
#[derive(Debug, Clone, Default)]
pub struct RunContext {
    /// `tactile`, `tactile daemon`, ...
    pub software: String,
    /// Where the calibration record was read from (none for a fresh in-memory one).
    pub calibration_path: Option<String>,
    /// The simulated bench's scenario, for simulated runs.
    pub scenario: Option<serde_json::Value>,
    /// The daemon's job number.
    pub job: Option<u64>,
    /// Time to let the pressure settle at the start position before the reference frame.
    pub settle: Duration,
}

/// What decides a failed run's status: `Failed` unless the caller knows better (the daemon
/// marks a run it stopped as `Partial`).
pub type FailureStatus<'a> = &'a dyn Fn(&ExperimentError) -> RecordStatus;

/// Runs one experiment. `make_radius` is called with the pressure set and the stage at the
/// start position (out of contact), to take the reference frame and start measuring.
#[allow(clippy::too_many_arguments)]
pub fn run_experiment<'a>(
    link: &mut Link,
    calibration: &CalibrationRecord,
    plan: &IndentationPlan,
    record: &RecordDir,
    model: &LutModel,
    lut: &LutInfo,
    context: &RunContext,
    progress: &indicatif::ProgressBar,
    failure_status: FailureStatus<'_>,
    make_radius: impl FnOnce(
        &mut Link,
        PxPerMmCalibration,
    ) -> Result<Box<dyn RadiusSource + 'a>, String>,
) -> Result<ExperimentReport, RunError> {
    let proximity =
        *calibration
            .proximity_at(plan.pressure_kpa)
            .ok_or_else(|| RunError::NoProximity {
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
    let mut meta = RecordMeta::new(link, calibration, plan, lut, context);
    meta.write(record)?;
    tracing::info!(pressure_kpa = plan.pressure_kpa, "setting pressure");
    link.call(endpoints::Vent { open: false })?;
    link.call(endpoints::SetLed {
        duty_per_10k: 10_000,
    })?;
    link.call(endpoints::SetPressure {
        setpoint_kpa: (plan.pressure_kpa + zero) as f32,
    })?;
    move_stage_to(link, plan.start_mm, plan.speed_mm_per_s.max(1.0))?;
    link.receive_for(context.settle)?;
    let radius = make_radius(link, px).map_err(RunError::Camera)?;
    let latency_s = calibration.camera_latency_s.unwrap_or(0.0);
    let mut radius = crate::camera_latency::LatencyCorrected::new(radius, latency_s);
    let sensors = crate::indentation::SampleCalibration {
        proximity: &proximity,
        manometer_zero_kpa: zero,
        load_scale: calibration.load_scale_at(plan.pressure_kpa).unwrap_or(1.0),
    };
    let run = run_indentation(link, &mut radius, plan, &sensors, record, progress);
    let stats = link.stats();
    let (unmeasured, dropped) = radius.failures();
    drop(radius);
    meta.link = Some(stats);
    meta.finished_unix_s = Some(unix_now_s());
    let result = match run {
        Ok(r) => r,
        Err(e) => {
            meta.status = failure_status(&e);
            // The pressure trace, for partial records too.
            if let Err(p) = fit::plots::write_pressure_trace(&record.dir) {
                meta.notes.push(format!("pressure trace not plotted: {p}"));
            }
            meta.write(record)?;
            return Err(e.into());
        }
    };
    let timing = camera_timing(latency_s, &result.points);
    if let Some(r) = timing.residual_latency_s
        && r.abs() > RESIDUAL_LATENCY_NOTE_S
    {
        meta.notes.push(format!(
            "the loading and unloading branches are offset as by a camera latency of {:.0} ms \
             (after the calibrated {:.0} ms): on an elastic sample, calibrate it with \
             `tactile calibrate camera-latency --record {}`; on a viscoelastic one this is \
             the sample's hysteresis",
            1000.0 * r,
            1000.0 * latency_s,
            record.dir.display()
        ));
    }
    meta.frames = Some(FrameCounts {
        measured: result.frames as u64,
        unmeasured,
        dropped,
    });
    let (fit, points, plot_problem) =
        match write_curve_and_fit(record, &result, plan.pressure_kpa, model) {
            Ok(r) => r,
            Err(e) => {
                meta.status = RecordStatus::FitFailed(e.to_string());
                meta.write(record)?;
                return Err(e.into());
            }
        };
    if let Some(p) = &plot_problem {
        meta.notes.push(format!("plots could not be written: {p}"));
    }
    meta.status = RecordStatus::Complete;
    meta.write(record)?;
    Ok(ExperimentReport {
        modulus_kpa: fit.modulus_kpa,
        ci95_kpa: fit.ci95_kpa,
        rms_residual_mm: fit.rms_residual_mm,
        record_dir: record.dir.display().to_string(),
        points: points.len(),
        fit_points: points,
        samples: result.samples,
        frames: result.frames,
        frames_unmeasured: unmeasured,
        frames_dropped: dropped,
        link: stats,
        camera_timing: timing,
        fit,
        notes: meta.notes.clone(),
    })
}

/// Indentations of the probe run of [`run_at_recommended_pressure`].
pub const PROBE_REPEATS: u32 = 1;

/// What the automatic pressure choice decided.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PressureChoice {
    /// The probe's pressure and its modulus estimate (with its 95 % interval).
    pub probe_kpa: f64,
    pub probe_modulus_kpa: f64,
    pub probe_ci95_kpa: [f64; 2],
    /// The chosen pressure and the predicted relative standard error there.
    pub chosen_kpa: f64,
    pub predicted_relative_se: f64,
    /// The pressures considered: the table's pressures with a proximity calibration.
    pub candidates: Vec<fit::PressureSensitivity>,
}

/// The file in the measurement's record that keeps the [`PressureChoice`].
pub const PRESSURE_CHOICE_FILE: &str = "pressure_choice.json";

/// The probe run of the automatic choice: `plan` with [`PROBE_REPEATS`] indentations.
pub fn probe_plan(plan: &IndentationPlan) -> IndentationPlan {
    IndentationPlan {
        repeats: PROBE_REPEATS,
        ..*plan
    }
}

/// The pressure to measure at after `probe` (run with [`probe_plan`] of `plan`): where the
/// table predicts the smallest error of the modulus (`fit::recommend_pressure`, with the
/// probe's residual noise and the main run's point density, `plan.repeats` times the
/// probe's), among the table's pressures that `calibration` has a proximity calibration
/// for and that `allowed` accepts (the caller's pressure limits).
pub fn choose_pressure(
    model: &LutModel,
    calibration: &CalibrationRecord,
    plan: &IndentationPlan,
    probe: &ExperimentReport,
    allowed: impl Fn(f64) -> bool,
) -> Result<PressureChoice, RunError> {
    let u_span = probe
        .fit_points
        .iter()
        .map(|p| p.u_s_mm)
        .fold(0.0, f64::max)
        - probe
            .fit_points
            .iter()
            .map(|p| p.u_s_mm)
            .fold(f64::INFINITY, f64::min);
    // the main run has `repeats` times the probe's points
    let density = (plan.repeats.max(1) as f64 / PROBE_REPEATS as f64) * probe.points as f64
        / u_span.max(1e-3);
    let (all, _) = fit::recommend_pressure(
        model,
        probe.modulus_kpa,
        probe.rms_residual_mm.max(1e-4),
        density,
    );
    let candidates: Vec<fit::PressureSensitivity> = all
        .into_iter()
        .filter(|s| allowed(s.p_air_kpa) && calibration.proximity_at(s.p_air_kpa).is_some())
        .collect();
    let best = candidates
        .iter()
        .min_by(|a, b| a.predicted_relative_se.total_cmp(&b.predicted_relative_se))
        .ok_or_else(|| RunError::NoProximity {
            pressure_kpa: plan.pressure_kpa,
            have: "no allowed table pressure with a proximity calibration".into(),
        })?;
    let choice = PressureChoice {
        probe_kpa: plan.pressure_kpa,
        probe_modulus_kpa: probe.modulus_kpa,
        probe_ci95_kpa: probe.ci95_kpa,
        chosen_kpa: best.p_air_kpa,
        predicted_relative_se: best.predicted_relative_se,
        candidates: candidates.clone(),
    };
    tracing::info!(
        probe_modulus_kpa = probe.modulus_kpa,
        chosen_kpa = choice.chosen_kpa,
        "pressure chosen"
    );
    Ok(choice)
}

/// The measurement's note about the choice (in its report).
pub fn choice_note(choice: &PressureChoice) -> String {
    format!(
        "pressure chosen automatically: {} kPa (predicted relative error {:.2} %), from a probe at {} kPa reading {:.1} kPa",
        choice.chosen_kpa,
        100.0 * choice.predicted_relative_se,
        choice.probe_kpa,
        choice.probe_modulus_kpa
    )
}

/// `--pressure auto`: a short probe indentation ([`probe_plan`]) at `plan.pressure_kpa`,
/// recorded in `probe_record`, fitted; then the experiment at the pressure
/// [`choose_pressure`] picks, its record keeping the choice ([`PRESSURE_CHOICE_FILE`]).
/// Stiff samples change the contact radius little at low pressure and need a higher one.
#[allow(clippy::too_many_arguments)]
pub fn run_at_recommended_pressure<'a>(
    link: &mut Link,
    calibration: &CalibrationRecord,
    plan: &IndentationPlan,
    probe_record: &RecordDir,
    record: &RecordDir,
    model: &LutModel,
    lut: &LutInfo,
    context: &RunContext,
    progress: &indicatif::ProgressBar,
    failure_status: FailureStatus<'_>,
    mut make_radius: impl FnMut(
        &mut Link,
        PxPerMmCalibration,
    ) -> Result<Box<dyn RadiusSource + 'a>, String>,
) -> Result<(ExperimentReport, PressureChoice), RunError> {
    let probe = run_experiment(
        link,
        calibration,
        &probe_plan(plan),
        probe_record,
        model,
        lut,
        context,
        progress,
        failure_status,
        &mut make_radius,
    )?;
    let choice = choose_pressure(model, calibration, plan, &probe, |_| true)?;
    record.write_json(PRESSURE_CHOICE_FILE, &choice)?;
    let main_plan = IndentationPlan {
        pressure_kpa: choice.chosen_kpa,
        ..*plan
    };
    let mut report = run_experiment(
        link,
        calibration,
        &main_plan,
        record,
        model,
        lut,
        context,
        progress,
        failure_status,
        &mut make_radius,
    )?;
    report.notes.push(choice_note(&choice));
    Ok((report, choice))
}
