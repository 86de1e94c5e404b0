//! The model's own discretisation error, carried into the modulus.
//!
//! - **The table is converged** (solved with the band of fine elements at the contact edge,
//!   `tactile lut build --edge-band`, as the shipped `fem-core/data/default.lut` is; its
//!   header records the band and its estimated error of a): the estimate is kept, and the
//!   table's own error, at most `max_um` of its header's `contact_radius_error` at any point,
//!   projects to at most `r = max_um sum_i |s_i| / sum_i s_i^2` in ln E2
//!   (`s_i = da/d ln E2` at the point), added to the interval in quadrature.
//! - **The table is a production-mesh table** (mesh level L without the band, such as
//!   `fem-core/data/default-production-mesh.lut`) and the same grid solved finer is at hand
//!   (level L+1, or the band): the two differ in the contact radius by the leading part of
//!   level L's discretisation error (all of it, to about 2 um along the surfaces and under a
//!   micrometre through the shell's wall, with the band). Projected on the fit's
//!   sensitivity to ln E2 at the estimate E, that difference is the bias it causes in the
//!   modulus, ln E(production model) - ln E(finer model), to first order:
//!
//!   `d = sum_i s_i (a_fine(E, p_i, u_i) - a(E, p_i, u_i)) / sum_i s_i^2`,
//!   `s_i = da/d ln E2 at (E, p_i, u_i)` (central difference, step 0.01 in ln E2).
//!
//!   (A sample whose true radii are the finer model's is fitted at E with the production
//!   model, so a(E) ~ a_fine(E_true) and a_fine(E) - a(E) ~ s (ln E - ln E_true).)
//!   With a converged finer table the estimate is corrected, E -> E exp(-d), the interval
//!   moves with it and the finer table's own error `r` is added as above; the per-pressure
//!   and per-replicate estimates are corrected the same way. With a plain finer mesh level
//!   the fit keeps its estimate and widens its interval by `|d|` in quadrature.

use fem_core::lut::Lut;

use crate::{FitError, FitOptions, FitPoint, LutModel, ModulusFit, fit_modulus};

/// Step in ln E2 of the central difference for the sensitivity.
const LN_STEP: f64 = 0.01;

/// Whether `fine` is `coarse`'s grid solved on a finer mesh: the same axes and base
/// parameters, and a higher mesh level, or the band of fine elements at the contact edge
/// (the converged contact radius) on a mesh level at least `coarse`'s where `coarse` has
/// none.
pub fn is_finer_version_of(fine: &Lut, coarse: &Lut) -> bool {
    let (f, c) = (&fine.grid, &coarse.grid);
    let mut f_base = f.base.clone();
    f_base.mesh_level = c.base.mesh_level;
    let finer = match (fine.edge_band.is_some(), coarse.edge_band.is_some()) {
        (true, false) => f.base.mesh_level >= c.base.mesh_level,
        (false, true) => false,
        _ => f.base.mesh_level > c.base.mesh_level,
    };
    finer && f.modulus_kpa == c.modulus_kpa && f.pressure_kpa == c.pressure_kpa && f_base == c.base
}

/// `s = da/d ln E2` at `(modulus_kpa, p)` (central difference), `None` where the table does
/// not cover the point.
fn sensitivity(model: &LutModel, modulus_kpa: f64, p: &FitPoint) -> Option<f64> {
    let (lo, hi) = (modulus_kpa * (-LN_STEP).exp(), modulus_kpa * LN_STEP.exp());
    let a_lo = model.sample(lo, p.p_air_kpa, p.u_s_mm).ok()?;
    let a_hi = model.sample(hi, p.p_air_kpa, p.u_s_mm).ok()?;
    Some((a_hi.a_mm - a_lo.a_mm) / (2.0 * LN_STEP))
}

/// The estimated bias of the production model's estimate, ln E(production) - ln E(finer),
/// at the points (see the module documentation); `None` if fewer than 3 points are covered
/// by both tables.
pub fn discretisation_bias_ln(
    model: &LutModel,
    fine: &LutModel,
    modulus_kpa: f64,
    points: &[FitPoint],
) -> Option<f64> {
    let (mut num, mut den, mut n) = (0.0, 0.0, 0usize);
    for p in points {
        let (Some(s), Ok(a), Ok(a_fine)) = (
            sensitivity(model, modulus_kpa, p),
            model.sample(modulus_kpa, p.p_air_kpa, p.u_s_mm),
            fine.sample(modulus_kpa, p.p_air_kpa, p.u_s_mm),
        ) else {
            continue;
        };
        num += s * (a_fine.a_mm - a.a_mm);
        den += s * s;
        n += 1;
    }
    (n >= 3 && den > 0.0).then(|| num / den)
}

/// Largest shift in ln E2 that an error of at most `error_mm` in a at every point can cause
/// in a fit at `modulus_kpa` (`error_mm sum |s_i| / sum s_i^2`); `None` if fewer than 3
/// points are covered.
pub fn projected_error_ln(
    model: &LutModel,
    modulus_kpa: f64,
    points: &[FitPoint],
    error_mm: f64,
) -> Option<f64> {
    let (mut sum_abs, mut den, mut n) = (0.0, 0.0, 0usize);
    for s in points
        .iter()
        .filter_map(|p| sensitivity(model, modulus_kpa, p))
    {
        sum_abs += s.abs();
        den += s * s;
        n += 1;
    }
    (n >= 3 && den > 0.0).then(|| error_mm * sum_abs / den)
}

/// Carries the model's discretisation error into `fit` (see the module documentation):
/// with a converged reference (`fine` has the edge band and an error estimate) the estimate
/// is corrected and the reference's own error widens the interval; otherwise the interval
/// is widened by the bias. Records the terms in `fit`.
pub fn apply_discretisation_term(
    fit: &mut ModulusFit,
    model: &LutModel,
    fine: &LutModel,
    points: &[FitPoint],
) {
    let Some(bias) = discretisation_bias_ln(model, fine, fit.modulus_kpa, points) else {
        return;
    };
    let (mut lo, mut hi) = (fit.ci95_kpa[0].ln(), fit.ci95_kpa[1].ln());
    fit.discretisation_bias_ln = Some(bias);
    let converged = fine.lut().edge_band.is_some();
    let reference_error = fine.lut().contact_radius_error.filter(|_| converged);
    let widen_by = match reference_error {
        Some(error) => {
            fit.modulus_production_kpa = Some(fit.modulus_kpa);
            fit.modulus_kpa *= (-bias).exp();
            lo -= bias;
            hi -= bias;
            let residual = projected_error_ln(fine, fit.modulus_kpa, points, error.max_um * 1e-3)
                .unwrap_or(bias.abs());
            fit.discretisation_residual_ln = Some(residual);
            correct_partial_estimates(fit, model, fine, points, error.max_um * 1e-3);
            fit.ci_description.push_str(&format!(
                "; corrected to the converged contact radius by {:+.4} in ln E2 (the model's discretisation bias), plus in quadrature the converged model's own error ({:.1} um in a at most) = {residual:.4}",
                -bias, error.max_um
            ));
            residual
        }
        None => {
            fit.ci_description.push_str(&format!(
                "; plus in quadrature the model's discretisation term |ln E - ln E(finer mesh)| = {:.4}",
                bias.abs()
            ));
            bias.abs()
        }
    };
    fit.ci95_kpa = widened([lo, hi], widen_by);
}

/// The interval `[lo, hi]` (in ln E2) with `term` added to its half-width in quadrature, in kPa.
fn widened([lo, hi]: [f64; 2], term: f64) -> [f64; 2] {
    let centre = 0.5 * (lo + hi);
    let half = (0.25 * (hi - lo).powi(2) + term * term).sqrt();
    [(centre - half).exp(), (centre + half).exp()]
}

/// The same correction for the fit's partial estimates, so that they stay comparable with
/// the corrected joint one: each pressure's estimate by the bias over that pressure's
/// points (its interval moved and widened by its own residual term), each replicate's by
/// the bias over all points at its modulus (replicates follow one plan, so their points
/// cover the same pressures and u_s).
fn correct_partial_estimates(
    fit: &mut ModulusFit,
    model: &LutModel,
    fine: &LutModel,
    points: &[FitPoint],
    error_mm: f64,
) {
    for pf in fit.per_pressure.iter_mut() {
        let at_p = points_at_pressure(points, pf.p_air_kpa);
        let Some(bias) = discretisation_bias_ln(model, fine, pf.modulus_kpa, &at_p) else {
            continue;
        };
        pf.modulus_kpa *= (-bias).exp();
        let residual = projected_error_ln(fine, pf.modulus_kpa, &at_p, error_mm).unwrap_or(0.0);
        let shifted = [pf.ci95_kpa[0].ln() - bias, pf.ci95_kpa[1].ln() - bias];
        pf.ci95_kpa = widened(shifted, residual);
    }
    for e in fit.replicate_moduli_kpa.iter_mut() {
        if let Some(bias) = discretisation_bias_ln(model, fine, *e, points) {
            *e *= (-bias).exp();
        }
    }
}

/// The points measured at `p_air_kpa` (a per-pressure estimate's own points).
fn points_at_pressure(points: &[FitPoint], p_air_kpa: f64) -> Vec<FitPoint> {
    points
        .iter()
        .filter(|q| q.p_air_kpa == p_air_kpa)
        .copied()
        .collect()
}

/// The table's own estimated error of a when it is converged (solved with the edge band and
/// its header records the estimate), `None` for a production-mesh table.
pub fn converged_error(lut: &Lut) -> Option<fem_core::discretisation::ContactRadiusError> {
    lut.contact_radius_error.filter(|_| lut.edge_band.is_some())
}

/// Carries a converged table's own error into `fit` (see the module documentation): the
/// estimate is kept and the interval widened in quadrature by that error projected on ln E2,
/// the per-pressure intervals by their own points' projection. Records the term in
/// `discretisation_residual_ln`.
pub fn apply_converged_table_error(
    fit: &mut ModulusFit,
    model: &LutModel,
    points: &[FitPoint],
    max_um: f64,
) {
    let Some(residual) = projected_error_ln(model, fit.modulus_kpa, points, max_um * 1e-3) else {
        return;
    };
    fit.discretisation_residual_ln = Some(residual);
    fit.ci95_kpa = widened([fit.ci95_kpa[0].ln(), fit.ci95_kpa[1].ln()], residual);
    for pf in fit.per_pressure.iter_mut() {
        let at_p = points_at_pressure(points, pf.p_air_kpa);
        if let Some(r) = projected_error_ln(model, pf.modulus_kpa, &at_p, max_um * 1e-3) {
            pf.ci95_kpa = widened([pf.ci95_kpa[0].ln(), pf.ci95_kpa[1].ln()], r);
        }
    }
    fit.ci_description.push_str(&format!(
        "; plus in quadrature the converged table's own error ({max_um:.1} um in a at most) = {residual:.4}"
    ));
}

/// The shipped converged table (`fem_core::shipped::default_lut_path`) if it is `lut`'s
/// grid on a finer mesh; `None` for any other table (a user's own grid has no such
/// estimate, and the converged table is not finer than itself).
pub fn shipped_finer_table(lut: &Lut) -> Option<Lut> {
    let fine = fem_core::lut::read_lut(&fem_core::shipped::default_lut_path()).ok()?;
    is_finer_version_of(&fine.lut, lut).then_some(fine.lut)
}

/// [`fit_modulus`], then the model's discretisation term: the table's own error when it is
/// converged ([`apply_converged_table_error`]), else the correction to the shipped converged
/// table when that is the model's table's grid solved finer ([`apply_discretisation_term`]).
/// The term is the tables' own (a model's augmentation is the same on both meshes, so it is
/// left out).
pub fn fit_modulus_with_model_error(
    model: &LutModel,
    points: &[FitPoint],
    options: FitOptions,
) -> Result<ModulusFit, FitError> {
    let mut fit = fit_modulus(model, points, options)?;
    let Ok(table) = LutModel::new(model.lut()) else {
        return Ok(fit);
    };
    if let Some(error) = converged_error(model.lut()) {
        apply_converged_table_error(&mut fit, &table, points, error.max_um);
    } else if let Some(fine) = shipped_finer_table(model.lut())
        && let Ok(fine_model) = LutModel::new(&fine)
    {
        apply_discretisation_term(&mut fit, &table, &fine_model, points);
    }
    Ok(fit)
}
