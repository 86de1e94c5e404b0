//! `tactile measure`: one experiment on the real bench — stored calibrations applied,
//! `--repeats` indentations at `--pressure`, frames from a V4L2 camera, the record written
//! and the modulus printed with its interval.

use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use camera::{V4l2Config, V4l2Source};
use diagnosis::applied::LoadedModel;
use experiment::IndentationPlan;
use experiment::calibration::{CalibrationRecord, load_latest, load_record};
use experiment::camera_radius::{CameraRadiusSource, capture_reference};
use experiment::pipeline::{LutInfo, RunContext, run_experiment};
use experiment::record_meta::RecordStatus;
use experiment::records::{RecordDir, unix_now_s, utc_stamp};
use fit::LutModel;
use link::{Link, LinkConfig, SerialTransport};

#[derive(Debug, Args)]
pub struct MeasureArgs {
    /// Serial port of the controller.
    #[arg(long)]
    pub port: String,
    /// V4L2 camera device (e.g. /dev/video0).
    #[arg(long)]
    pub camera: PathBuf,
    /// Internal pressure (kPa), or `auto`: a one-indentation probe at 6 kPa, then the
    /// measurement at the calibrated table pressure where the modulus is measured best.
    #[arg(long, default_value = "6", value_parser = parse_pressure)]
    pub pressure: PressureArg,
    /// Stage position where each indentation starts, above the sample (mm).
    #[arg(long)]
    pub start: f64,
    /// Stage travel of each indentation (mm).
    #[arg(long, default_value_t = 1.7)]
    pub depth: f64,
    /// Stage speed (mm/s).
    #[arg(long, default_value_t = 2.0)]
    pub speed: f64,
    /// Indentations.
    #[arg(long, default_value_t = 5)]
    pub repeats: u32,
    /// Sample stream rate (Hz).
    #[arg(long, default_value_t = 2000)]
    pub rate: u16,
    /// Record directory (default: records/measure-<UTC time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Directory of calibration records (the newest is applied).
    #[arg(long, default_value = "calibration")]
    pub calibration_dir: PathBuf,
    /// A specific calibration record instead of the newest in --calibration-dir.
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Lookup table for the fit (default: fem-core/data/default.lut of this source tree).
    #[arg(long)]
    pub lut: Option<PathBuf>,
    /// Model file of this setup (`tactile diagnose --apply`): the fit uses the table with
    /// its effects, and the record keeps the model.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// The shipped converged table next to this crate.
pub fn default_lut_path() -> PathBuf {
    fem_core::shipped::default_lut_path()
}

fn load_calibration(args: &MeasureArgs) -> Result<(PathBuf, CalibrationRecord), String> {
    match &args.calibration {
        Some(p) => Ok((p.clone(), load_record(p).map_err(|e| e.to_string())?)),
        None => load_latest(&args.calibration_dir).map_err(|e| e.to_string()),
    }
}

/// `--pressure`: a set point or the automatic choice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PressureArg {
    Kpa(f64),
    Auto,
}

/// The probe pressure of `--pressure auto` (the paper's working pressure).
const AUTO_PROBE_KPA: f64 = 6.0;

fn parse_pressure(text: &str) -> Result<PressureArg, String> {
    if text.eq_ignore_ascii_case("auto") {
        return Ok(PressureArg::Auto);
    }
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(PressureArg::Kpa(v)),
        _ => Err(format!(
            "`{text}` is neither a pressure in kPa (>= 0) nor `auto`"
        )),
    }
}

pub fn run(args: MeasureArgs) -> ExitCode {
    let input = |e: String| {
        eprintln!("error: {e}");
        ExitCode::from(2)
    };
    let (cal_path, calibration) = match load_calibration(&args) {
        Ok(c) => c,
        Err(e) => return input(e),
    };
    let lut_path = args.lut.clone().unwrap_or_else(default_lut_path);
    let lut_file = match fem_core::lut::read_lut(&lut_path) {
        Ok(f) => f,
        Err(e) => return input(format!("lookup table {}: {e}", lut_path.display())),
    };
    let setup = match args.model.as_deref().map(LoadedModel::load).transpose() {
        Ok(m) => m,
        Err(e) => return input(format!("--model: {e}")),
    };
    let augmentation = match setup.as_ref().map(LoadedModel::augmentation).transpose() {
        Ok(a) => a.unwrap_or_default(),
        Err(e) => return input(format!("--model: {e}")),
    };
    let model = match LutModel::with_augmentation(&lut_file.lut, augmentation) {
        Ok(m) => m,
        Err(e) => return input(format!("lookup table {}: {e}", lut_path.display())),
    };
    // a set point the fit would refuse is refused before anything is measured
    if let PressureArg::Kpa(p) = args.pressure
        && let Err(e) = model.check_pressure(p)
    {
        return input(format!("--pressure: {e}"));
    }
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("records").join(format!("measure-{}", utc_stamp(unix_now_s())))
    });
    let fail = |e: String| {
        eprintln!("error: {e}");
        ExitCode::from(1)
    };
    let transport = match SerialTransport::open(&args.port) {
        Ok(t) => t,
        Err(e) => return fail(e.to_string()),
    };
    let mut link = match Link::connect(
        Box::new(transport),
        LinkConfig {
            // USB CDC on a busy host, or an emulated bench behind a loaded CPU: be patient
            request_timeout: Duration::from_millis(1000),
            ..LinkConfig::default()
        },
    ) {
        Ok(l) => l,
        Err(e) => return fail(e.to_string()),
    };
    // The record folder is made once the controller answers, and removed again if the
    // run fails before anything was written to it.
    let record = match RecordDir::create(&out) {
        Ok(r) => r,
        Err(e) => return input(e.to_string()),
    };
    tracing::info!(calibration = %cal_path.display(), lut = %lut_path.display(), "measuring");
    let plan = IndentationPlan {
        pressure_kpa: match args.pressure {
            PressureArg::Kpa(p) => p,
            PressureArg::Auto => AUTO_PROBE_KPA,
        },
        start_mm: args.start,
        depth_mm: args.depth,
        speed_mm_per_s: args.speed,
        repeats: args.repeats,
        stream_rate_hz: args.rate,
    };
    let progress = if args.json {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(u64::from(args.repeats))
    };
    let camera = args.camera.clone();
    let lut = LutInfo {
        path: lut_path.display().to_string(),
        sha256: lut_file.sha256.clone(),
        model: setup.as_ref().map(super::fit::model_info),
    };
    let context = RunContext {
        software: "tactile measure".into(),
        calibration_path: Some(cal_path.display().to_string()),
        scenario: None,
        job: None,
        settle: Duration::from_millis(1000),
    };
    let make_radius = |_link: &mut Link, px| {
        let mut source = V4l2Source::open(&V4l2Config {
            device: Some(camera.clone()),
            ..V4l2Config::default()
        })
        .map_err(|e| e.to_string())?;
        let reference = capture_reference(&mut source, 10).map_err(|e| e.to_string())?;
        let s = CameraRadiusSource::start(source, reference, px).map_err(|e| e.to_string())?;
        Ok(Box::new(s) as Box<dyn experiment::RadiusSource>)
    };
    let failed = |e: &experiment::ExperimentError| RecordStatus::Failed(e.to_string());
    let result = match args.pressure {
        PressureArg::Kpa(_) => run_experiment(
            &mut link,
            &calibration,
            &plan,
            &record,
            &model,
            &lut,
            &context,
            &progress,
            &failed,
            make_radius,
        ),
        PressureArg::Auto => match RecordDir::create(&out.join("probe")) {
            Ok(probe) => experiment::pipeline::run_at_recommended_pressure(
                &mut link,
                &calibration,
                &plan,
                &probe,
                &record,
                &model,
                &lut,
                &context,
                &progress,
                &failed,
                make_radius,
            )
            .map(|(report, _)| report),
            Err(e) => Err(e.into()),
        },
    };
    progress.finish_and_clear();
    match result {
        Ok(report) => {
            if args.json {
                println!("{}", serde_json::to_string(&report).unwrap_or_default());
            } else {
                super::print_modulus_summary(
                    report.modulus_kpa,
                    report.ci95_kpa,
                    report.rms_residual_mm,
                    &report.record_dir,
                    &report.notes,
                );
                if let Some(m) = &setup {
                    println!(
                        "fitted with the setup's model {}: {}",
                        m.path.display(),
                        m.file.summary()
                    );
                }
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            let empty = std::fs::read_dir(&out).is_ok_and(|mut d| d.next().is_none());
            if empty && std::fs::remove_dir(&out).is_ok() {
                fail(format!("{e} (nothing was recorded)"))
            } else {
                fail(format!("{e} (partial record: {})", out.display()))
            }
        }
    }
}
