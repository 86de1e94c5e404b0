//! After the indentations: the record's `curve.csv` (`fit::curve_csv`), the fit against
//! the table (`fit.json`) and the plots, shared by `tactile measure` and `tactile demo`.

use std::path::Path;

use super::IndentationResult;
use crate::records::{RecordDir, RecordError};
use fit::curve_csv::{CurveCsv, CurveCsvError, CurveRow, write_curve_csv};
use fit::{FitError, FitOptions, FitPoint, LutModel, ModulusFit};

#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error("curve: {0}")]
    Curve(#[from] CurveCsvError),
    #[error("fit: {0}")]
    Fit(#[from] FitError),
}

/// The fit's points: both phases, in contact (a > 0, u_s > 0), at the nominal pressure.
///
/// Both phases: the model is elastic (no hysteresis), and at equal loading and unloading
/// speeds a camera-to-stream timing lag shifts the two phases in opposite directions, so it
/// cancels to first order (loading alone is biased by it).
pub fn fit_points(result: &IndentationResult, pressure_kpa: f64) -> Vec<FitPoint> {
    result
        .points
        .iter()
        .filter(|(_, p)| p.a_mm > 0.0 && p.u_s_mm > 0.0)
        .map(|(t, p)| FitPoint {
            u_s_mm: p.u_s_mm,
            a_mm: p.a_mm,
            p_air_kpa: pressure_kpa,
            test: *t,
            load_n: p.load_n,
        })
        .collect()
}

/// Writes `curve.csv`, fits, writes `fit.json` and the plots (`samples.csv` must already
/// be complete for the pressure trace). Returns the fit, its points and any plot problem
/// (plots failing do not fail the experiment).
pub fn write_curve_and_fit(
    record: &RecordDir,
    result: &IndentationResult,
    pressure_kpa: f64,
    model: &LutModel,
) -> Result<(ModulusFit, Vec<FitPoint>, Option<fit::plots::PlotError>), AnalysisError> {
    let rows: Vec<CurveRow> = result
        .points
        .iter()
        .map(|(t, p)| CurveRow {
            u_s_mm: p.u_s_mm,
            a_mm: p.a_mm,
            load_n: p.load_n,
            p_air_kpa: Some(p.p_air_kpa),
            t_s: Some(p.t_s),
            phase: Some(p.phase),
            test: Some(*t),
            h_mm: None,
            stage_mm: Some(p.stage_mm),
            volume_mm3: None,
        })
        .collect();
    write_curve_csv(
        &record.path("curve.csv"),
        &CurveCsv {
            metadata: vec![("p_air_kpa".into(), format!("{pressure_kpa}"))],
            rows,
        },
    )?;
    let points = fit_points(result, pressure_kpa);
    let fit =
        fit::discretisation::fit_modulus_with_model_error(model, &points, FitOptions::default())?;
    record.write_json("fit.json", &fit)?;
    let plots = write_plots(&record.dir, model, &points, &fit).err();
    Ok((fit, points, plots))
}

fn write_plots(
    dir: &Path,
    model: &LutModel,
    points: &[FitPoint],
    fit: &ModulusFit,
) -> Result<(), fit::plots::PlotError> {
    fit::plots::write_fit_plots(dir, model, points, fit)?;
    fit::plots::write_pressure_trace(dir).map(|_| ())
}
