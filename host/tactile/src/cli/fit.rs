//! `tactile fit CURVE.csv [--lut FILE] [--model FILE] [--json] [--load]`: the modulus of a
//! measured curve, with its 95 % interval, residual RMS and the recommended pressure; with
//! `--model`, against the table augmented with the effects a diagnosis found for this setup
//! (`tactile diagnose --apply`).
//! Exit codes: 0 success, 1 the fit failed, 2 bad input (file, CSV, table).

use clap::Args;
use diagnosis::applied::LoadedModel;
use fit::{FitOptions, LutModel, points_from_curve_csv, recommend_pressure};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct FitArgs {
    /// Measured curve (CSV: u_s_mm,a_mm[,load_n,p_air_kpa,t_s,phase,test]).
    pub curve: PathBuf,
    /// Lookup table (default: $TACTILE_LUT, else fem-core/data/default.lut).
    #[arg(long)]
    pub lut: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Add the load channel (P–u_s) to the fit when the curve has loads.
    #[arg(long)]
    pub load: bool,
    /// Model file of this setup (`tactile diagnose --apply`): fit with its effects.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
}

/// The table path used when none is given.
pub fn default_lut_path() -> PathBuf {
    std::env::var_os("TACTILE_LUT")
        .map(PathBuf::from)
        .unwrap_or_else(fem_core::shipped::default_lut_path)
}

pub fn run(args: FitArgs) -> ExitCode {
    let file = args.curve.display().to_string();
    let curve = match fit::curve_csv::read_curve_csv(&args.curve) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let points = match points_from_curve_csv(&curve, &file) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let lut_path = args.lut.unwrap_or_else(default_lut_path);
    let lut_file = match fem_core::lut::read_lut(&lut_path) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: lookup table {}: {e}", lut_path.display());
            return ExitCode::from(2);
        }
    };
    let setup = match args.model.as_deref().map(LoadedModel::load).transpose() {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: --model: {e}");
            return ExitCode::from(2);
        }
    };
    let augmentation = match setup.as_ref().map(LoadedModel::augmentation).transpose() {
        Ok(a) => a.unwrap_or_default(),
        Err(e) => {
            eprintln!("error: --model: {e}");
            return ExitCode::from(2);
        }
    };
    let model = match LutModel::with_augmentation(&lut_file.lut, augmentation) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: lookup table {}: {e}", lut_path.display());
            return ExitCode::from(2);
        }
    };
    let start = Instant::now();
    let fit = match fit::discretisation::fit_modulus_with_model_error(
        &model,
        &points,
        FitOptions {
            use_load: args.load,
            ..FitOptions::default()
        },
    ) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("error: {file}: {e}");
            return ExitCode::from(1);
        }
    };
    let fit_seconds = start.elapsed().as_secs_f64();
    let u_span = points.iter().map(|p| p.u_s_mm).fold(0.0, f64::max)
        - points
            .iter()
            .map(|p| p.u_s_mm)
            .fold(f64::INFINITY, f64::min);
    let density = fit.points_used as f64 / u_span.max(1e-3);
    let (sens, best) = recommend_pressure(
        &model,
        fit.modulus_kpa,
        fit.rms_residual_mm.max(1e-4),
        density,
    );
    let recommended = best.map(|i| sens[i].p_air_kpa);
    if args.json {
        let value = serde_json::json!({
            "modulus_kpa": fit.modulus_kpa,
            "ci95_kpa": fit.ci95_kpa,
            "rms_residual_mm": fit.rms_residual_mm,
            "fit": fit,
            "recommended_pressure_kpa": recommended,
            "pressure_sensitivity": sens,
            "lut": { "path": lut_path.display().to_string(), "sha256": lut_file.sha256 },
            "model": setup.as_ref().map(model_info),
            "fit_seconds": fit_seconds,
        });
        println!("{value}");
    } else {
        println!(
            "E2 = {:.1} kPa  (95 % CI {:.1} .. {:.1} kPa; {})",
            fit.modulus_kpa, fit.ci95_kpa[0], fit.ci95_kpa[1], fit.ci_description
        );
        println!(
            "residual RMS {:.4} mm over {} points ({} outside the table's u_s range){}",
            fit.rms_residual_mm,
            fit.points_used,
            fit.points_excluded,
            fit.rms_residual_load_n
                .map(|r| format!(", load residual RMS {r:.4} N"))
                .unwrap_or_default()
        );
        for p in &fit.per_pressure {
            println!(
                "  at {:.1} kPa alone: {:.1} kPa ({:.1} .. {:.1})",
                p.p_air_kpa, p.modulus_kpa, p.ci95_kpa[0], p.ci95_kpa[1]
            );
        }
        if let Some(m) = &setup {
            println!(
                "model {}: the table with {}",
                m.path.display(),
                m.file.summary()
            );
        }
        if let Some(p) = recommended {
            println!("recommended internal pressure for this modulus: {p} kPa");
        }
        println!("fit time {:.3} ms", fit_seconds * 1e3);
    }
    ExitCode::SUCCESS
}

/// What a result records of the model it was fitted with.
pub fn model_info(m: &LoadedModel) -> serde_json::Value {
    m.record()
}
