//! `tactile calibrate`: the calibrations against a connected controller, each run stored
//! as a new dated JSON record (`<dir>/calibration-<unix seconds>.json`) that starts from the
//! newest earlier record, so later runs (`tactile measure`) apply everything calibrated so far.

use clap::{Args, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use camera::read_gray_image;
use experiment::calibration::{
    CalibrationRecord, RigidSampleCurve, SweepPlan, fit_sweep, load_latest, manometer_zero_kpa,
    proximity_sweep, save_record, tare_load,
};
use link::{Link, LinkConfig, SerialTransport};
use vision::contact_radius::ContactRadiusConfig;
use vision::px_per_mm::PxPerMmCalibration;

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Directory of calibration records.
    #[arg(long, default_value = "calibration", global = true)]
    pub dir: PathBuf,
    /// Print the new record as JSON.
    #[arg(long, global = true)]
    pub json: bool,
    #[command(subcommand)]
    pub what: What,
}

#[derive(Debug, Subcommand)]
pub enum What {
    /// Manometer zero: the reading with the vent open.
    Manometer {
        /// Serial port of the controller.
        #[arg(long)]
        port: String,
    },
    /// Load-cell tare (out of contact), and the residual load after it.
    Load {
        #[arg(long)]
        port: String,
    },
    /// Proximity parabola per pressure from a sweep into a rigid flat sample, fitted
    /// against fem-core's rigid-sample u_s(h) (and, for comparison, u_s = h).
    Proximity {
        #[arg(long)]
        port: String,
        /// Internal pressure(s) in kPa (one sweep each).
        #[arg(long, required = true, num_args = 1..)]
        pressure: Vec<f64>,
        /// Stage position where the sweep starts, above the sample (mm).
        #[arg(long)]
        start: f64,
        /// Deepest stage position (mm); at most ~1.9 mm past contact.
        #[arg(long)]
        end: f64,
        /// Sweep speed (mm/s).
        #[arg(long, default_value_t = 0.5)]
        speed: f64,
        /// fem-core mesh level of the rigid-sample solve (0: production mesh, ~10 s).
        #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
        mesh_level: i32,
        /// Use the paper's u_s = h instead of fem-core's u_s(h).
        #[arg(long)]
        u_s_equals_h: bool,
    },
    /// The camera's latency (how late its frames are stamped) from a measurement record
    /// of an elastic sample: the loading and unloading branches of a(u_s) must coincide,
    /// and frames stamped late pull them apart. Later measurements subtract it.
    CameraLatency {
        /// A record of `tactile measure` (or the daemon) on an elastic sample, with full
        /// indentations at the same speed in and out.
        #[arg(long)]
        record: PathBuf,
    },
    /// Camera px/mm from frames of a reference disc of known radius.
    Camera {
        /// No-contact reference frame (PNG or PGM).
        #[arg(long)]
        reference: PathBuf,
        /// Frames of the disc (PNG or PGM), each followed by its radius: FILE:RADIUS_MM.
        #[arg(long = "disc", required = true, num_args = 1..)]
        discs: Vec<String>,
    },
}

fn connect(port: &str) -> Result<Link, String> {
    let transport = SerialTransport::open(port).map_err(|e| e.to_string())?;
    Link::connect(
        Box::new(transport),
        LinkConfig {
            // USB CDC on a busy host, or an emulated bench behind a loaded CPU: be patient
            request_timeout: Duration::from_millis(1000),
            ..LinkConfig::default()
        },
    )
    .map_err(|e| e.to_string())
}

fn base_record(dir: &std::path::Path, link: Option<&Link>) -> CalibrationRecord {
    let (serial, fw) = link.map_or((String::new(), String::new()), |l| {
        (
            l.info().serial.to_string(),
            l.info().firmware_version.to_string(),
        )
    });
    match load_latest(dir) {
        Ok((_, mut r)) if link.is_none() || r.device_serial == serial => {
            r.created_unix_s = experiment::records::unix_now_s();
            r
        }
        _ => CalibrationRecord::new(&serial, &fw),
    }
}

fn spinner(json: bool, msg: &str) -> indicatif::ProgressBar {
    if json {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_message(msg.to_string());
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

/// Returns a message for the user, or (error, exit code).
fn calibrate(args: &CalibrateArgs) -> Result<(CalibrationRecord, Vec<String>), (String, u8)> {
    let fail = |e: String| (e, 1u8);
    let mut lines = Vec::new();
    let record = match &args.what {
        What::Manometer { port } => {
            let mut link = connect(port).map_err(fail)?;
            let mut r = base_record(&args.dir, Some(&link));
            let bar = spinner(args.json, "manometer zero (vent open)");
            r.manometer_zero_kpa = manometer_zero_kpa(&mut link, Duration::from_millis(1000))
                .map_err(|e| fail(e.to_string()))?;
            bar.finish_and_clear();
            lines.push(format!(
                "manometer zero: {:.4} kPa (nominal reading with the vent open)",
                r.manometer_zero_kpa
            ));
            r
        }
        What::Load { port } => {
            let mut link = connect(port).map_err(fail)?;
            let mut r = base_record(&args.dir, Some(&link));
            let bar = spinner(args.json, "load tare");
            r.load_tare_residual_n = tare_load(&mut link).map_err(|e| fail(e.to_string()))?;
            bar.finish_and_clear();
            lines.push(format!(
                "load tared; residual {:.5} N over 0.5 s",
                r.load_tare_residual_n
            ));
            r
        }
        What::Proximity {
            port,
            pressure,
            start,
            end,
            speed,
            mesh_level,
            u_s_equals_h,
        } => {
            if end <= start || end.is_nan() || start.is_nan() {
                return Err((
                    format!("--end {end} must be deeper than --start {start}"),
                    2,
                ));
            }
            let mut link = connect(port).map_err(fail)?;
            let mut r = base_record(&args.dir, Some(&link));
            for &p in pressure {
                let rigid = if *u_s_equals_h {
                    None
                } else {
                    let bar = spinner(args.json, &format!("fem-core rigid sample at {p} kPa"));
                    let c = RigidSampleCurve::solve(p, *mesh_level, 40, 1.9)
                        .map_err(|e| fail(e.to_string()))?;
                    bar.finish_and_clear();
                    Some(c)
                };
                let bar = if args.json {
                    indicatif::ProgressBar::hidden()
                } else {
                    indicatif::ProgressBar::new((end * 1000.0).max(1.0) as u64)
                };
                let plan = SweepPlan {
                    pressure_kpa: p,
                    start_mm: *start,
                    end_mm: *end,
                    speed_mm_per_s: *speed,
                    contact_load_n: 0.005,
                };
                let data = proximity_sweep(&mut link, &plan, r.manometer_zero_kpa, &bar)
                    .map_err(|e| fail(e.to_string()))?;
                bar.finish_and_clear();
                let fit = fit_sweep(&data, plan.contact_load_n, rigid.as_ref())
                    .map_err(|e| fail(e.to_string()))?;
                let c = fit.calibration;
                lines.push(format!(
                    "{p} kPa: U = {:.5} u^2 + {:.5} u + {:.5} V, residual {:.2} mV ({:.4} mm), contact at {:.4} mm; u_s differs from u_s = h by up to {:.4} mm ({:+.2} % at the deepest point) [{}]; {}",
                    c.a_v_per_mm2,
                    c.b_v_per_mm,
                    c.c_v,
                    1000.0 * c.residual_rms_v,
                    c.residual_rms_mm,
                    fit.contact_mm,
                    fit.u_s_difference_max_mm,
                    100.0 * fit.u_s_difference_at_max_relative,
                    fit.rigid_u_s_source,
                    match fit.load_scale {
                        Some(s) => format!(
                            "load cell reads {s:.4} of fem-core's rigid-sample load with its nominal scale (loads are divided by it)"
                        ),
                        None => "load cell scale not calibrated (no fem-core rigid-sample load, or the cell read outside 0.8..1.25 of it: was the sample rigid?)".into(),
                    }
                ));
                r.set_proximity(&fit);
            }
            r
        }
        What::CameraLatency { record } => {
            let mut r = base_record(&args.dir, None);
            let est = experiment::camera_latency::estimate_from_record(record)
                .map_err(|e| (e.to_string(), 2u8))?;
            let total = est.total_s();
            r.camera_latency_s = Some(total);
            lines.push(format!(
                "camera latency: {:.1} ms ({:.1} ms applied when {} was measured, {:+.1} ms from \
                 its branches, {} µm apart; per indentation: {})",
                1000.0 * total,
                1000.0 * est.applied_s,
                record.display(),
                1000.0 * est.residual.latency_s,
                est.residual.branch_offset_um.round(),
                est.residual
                    .per_cycle_s
                    .iter()
                    .map(|t| format!("{:.1} ms", 1000.0 * (t + est.applied_s)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
            r
        }
        What::Camera { reference, discs } => {
            let mut r = base_record(&args.dir, None);
            let reference_img = read_gray_image(reference).map_err(|e| (e.to_string(), 2))?;
            let mut samples = Vec::new();
            for d in discs {
                let (file, radius) = d
                    .rsplit_once(':')
                    .ok_or_else(|| (format!("--disc {d}: expected FILE:RADIUS_MM"), 2u8))?;
                let radius_mm: f64 = radius.parse().map_err(|_| {
                    (
                        format!("--disc {d}: radius `{radius}` is not a number"),
                        2u8,
                    )
                })?;
                let img = read_gray_image(std::path::Path::new(file))
                    .map_err(|e| (e.to_string(), 2u8))?;
                let one = PxPerMmCalibration::from_frames(
                    &reference_img,
                    std::slice::from_ref(&img),
                    radius_mm,
                    &ContactRadiusConfig::default(),
                )
                .map_err(|e| (format!("{file}: {e}"), 2u8))?;
                samples.push((
                    radius_mm,
                    one.px_per_mm * radius_mm,
                    one.px_per_mm_sigma * radius_mm,
                ));
            }
            let cal = PxPerMmCalibration::from_measurements(&samples)
                .map_err(|e| (e.to_string(), 2u8))?;
            r.px_per_mm = Some(cal.px_per_mm);
            r.px_per_mm_sigma = Some(cal.px_per_mm_sigma);
            r.px_offset_px = cal.offset_px;
            r.lens_distortion_k_per_mm2 = cal
                .lens_distortion
                .filter(|d| d.corrected)
                .map(|d| d.k_per_mm2);
            lines.push(format!(
                "camera: {:.4} ± {:.4} px/mm{} from {} frame(s)",
                cal.px_per_mm,
                cal.px_per_mm_sigma,
                cal.offset_px
                    .map(|o| format!(", edge offset {o:.3} px"))
                    .unwrap_or_default(),
                samples.len()
            ));
            if let Some(d) = cal.lens_distortion {
                let largest = samples.iter().map(|s| s.0).fold(0.0, f64::max);
                lines.push(if d.significant() {
                    format!(
                        "camera: the discs' radii are not proportional to their size: a lens distortion k = {:.2e} ± {:.1e} /mm² (a radius r is seen at r (1 + k r²); {:+.2} % at {largest} mm); the scale and offset above are the fit with it, and measured radii are corrected for it (check the optics if it is larger than expected)",
                        d.k_per_mm2,
                        d.k_sigma_per_mm2,
                        100.0 * d.relative_at(largest)
                    )
                } else {
                    format!(
                        "camera: no lens distortion seen (k = {:.1e} ± {:.1e} /mm²)",
                        d.k_per_mm2, d.k_sigma_per_mm2
                    )
                });
            }
            r
        }
    };
    let path = save_record(&args.dir, &record).map_err(|e| fail(e.to_string()))?;
    lines.push(format!("saved {}", path.display()));
    Ok((record, lines))
}

pub fn run(args: CalibrateArgs) -> ExitCode {
    match calibrate(&args) {
        Ok((record, lines)) => {
            if args.json {
                println!("{}", serde_json::to_string(&record).unwrap_or_default());
            } else {
                for l in lines {
                    println!("{l}");
                }
            }
            ExitCode::SUCCESS
        }
        Err((e, code)) => {
            eprintln!("error: {e}");
            ExitCode::from(code)
        }
    }
}
