//! `tactile run`: submit an experiment to the daemon and follow it to the end.

use std::process::ExitCode;

use clap::Args;
use daemon::api::{Event, ExperimentRequest, PressureSetting};

use super::status::DaemonAddr;

#[derive(Debug, Args)]
pub struct RunArgs {
    #[command(flatten)]
    daemon: DaemonAddr,
    /// Internal gauge pressure (kPa), or `auto`: a one-indentation probe (at
    /// --probe-pressure), then the measurement at the calibrated pressure where the modulus
    /// is measured best.
    #[arg(long, default_value = "6", value_parser = parse_pressure)]
    pressure: PressureSetting,
    /// The probe's pressure with `--pressure auto` (kPa; default 6).
    #[arg(long)]
    probe_pressure: Option<f64>,
    /// Stage position where each cycle starts (mm from the stage zero, above the sample).
    #[arg(long, default_value_t = 0.8)]
    start: f64,
    /// Indentation travel per cycle (mm).
    #[arg(long, default_value_t = 1.2)]
    depth: f64,
    /// Stage speed (mm/s).
    #[arg(long, default_value_t = 2.0)]
    speed: f64,
    /// Indentation cycles.
    #[arg(long, default_value_t = 3)]
    repeats: u32,
    /// Sample stream rate (Hz).
    #[arg(long, default_value_t = 2000)]
    rate: u16,
    /// Free text kept in the record.
    #[arg(long, default_value = "")]
    label: String,
    /// Calibrate first (simulated bench only).
    #[arg(long)]
    calibrate: bool,
    /// Submit and return at once (print the job as JSON).
    #[arg(long)]
    detach: bool,
}

/// `--pressure`: kPa or `auto`.
fn parse_pressure(text: &str) -> Result<PressureSetting, String> {
    if text.eq_ignore_ascii_case("auto") {
        return Ok(PressureSetting::Auto);
    }
    text.parse::<f64>()
        .map(PressureSetting::Kpa)
        .map_err(|_| format!("`{text}` is neither a pressure in kPa nor `auto`"))
}

pub fn run(args: RunArgs) -> ExitCode {
    let client = match args.daemon.client() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let request = ExperimentRequest {
        pressure_kpa: args.pressure,
        probe_pressure_kpa: args.probe_pressure,
        start_mm: args.start,
        depth_mm: args.depth,
        speed_mm_per_s: args.speed,
        repeats: args.repeats,
        stream_rate_hz: args.rate,
        label: args.label.clone(),
    };
    if let Err(fields) = request.validate() {
        for f in fields {
            eprintln!("error: {}: {}", f.field, f.reason);
        }
        return ExitCode::from(2);
    }
    // Subscribe before submitting so no event of the job is missed.
    let events = match client.events() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut ids = Vec::new();
    if args.calibrate {
        match client.calibrate() {
            Ok(j) => ids.push(j.id),
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    let job = match client.submit(&request) {
        Ok(j) => j,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    if args.detach {
        println!("{}", serde_json::to_string_pretty(&job).unwrap_or_default());
        return ExitCode::SUCCESS;
    }
    eprintln!("job {} queued", job.id);
    ids.push(job.id);
    let mut last_message = String::new();
    for event in events {
        match event {
            Ok(Event::Job { job: j }) if ids.contains(&j.id) => {
                let line = format!(
                    "job {} [{:>3.0} %] {:?}: {}",
                    j.id,
                    j.progress * 100.0,
                    j.state,
                    j.message
                );
                if line != last_message {
                    eprintln!("{line}");
                    last_message = line;
                }
                if j.id == job.id && j.state.is_finished() {
                    if let Some(f) = j.fit {
                        println!(
                            "E2 = {:.1} kPa (95 % CI {:.1} .. {:.1} kPa), residual RMS {:.4} mm, {} points",
                            f.modulus_kpa,
                            f.ci95_kpa[0],
                            f.ci95_kpa[1],
                            f.rms_residual_mm,
                            f.points
                        );
                    }
                    if let Some(r) = j.record {
                        println!("record: {r}");
                    }
                    return if j.state == daemon::JobState::Complete {
                        ExitCode::SUCCESS
                    } else {
                        ExitCode::FAILURE
                    };
                }
            }
            Ok(Event::Fit {
                fit,
                final_fit: false,
                ..
            }) => eprintln!(
                "  running fit: E2 = {:.1} kPa ({:.1} .. {:.1}), {} points",
                fit.modulus_kpa, fit.ci95_kpa[0], fit.ci95_kpa[1], fit.points
            ),
            Ok(Event::Link { message, .. }) => eprintln!("  link: {message}"),
            Ok(Event::Fault { latched, .. }) => eprintln!("  FAULT: {}", latched.join(", ")),
            Ok(_) => {}
            Err(e) => {
                eprintln!("error: live feed: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    eprintln!("error: the daemon closed the live feed");
    ExitCode::FAILURE
}
