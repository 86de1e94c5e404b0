//! The discretisation term of the fit: the shipped production-mesh table and its converged
//! twin (the shipped `default.lut`), the term predicting the bias that fitting the
//! production model to converged data actually shows, the correction it makes, and the
//! converged table's own error in its interval.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use fem_core::lut::read_lut;
use fit::discretisation::{
    apply_discretisation_term, converged_error, discretisation_bias_ln,
    fit_modulus_with_model_error, is_finer_version_of, projected_error_ln,
};
use fit::{FitOptions, FitPoint, LutModel, fit_modulus};

/// Noise-free points of `model` at (E2, p): 3 replicates of 40 points over 5..95 % of u_s.
fn points(model: &LutModel, e: f64, p: f64) -> Vec<FitPoint> {
    let (lo, hi) = model.u_s_range_mm(e, p).unwrap();
    let (lo, hi) = (lo.max(0.0) + 0.05 * (hi - lo), hi - 0.05 * (hi - lo));
    (0..3)
        .flat_map(|t| (0..40).map(move |k| (t, lo + (hi - lo) * (k as f64 + 0.5) / 40.0)))
        .map(|(t, u)| FitPoint {
            u_s_mm: u,
            a_mm: model.sample(e, p, u).unwrap().a_mm,
            p_air_kpa: p,
            test: t,
            load_n: None,
        })
        .collect()
}

#[test]
fn the_shipped_table_is_the_production_mesh_grid_converged() {
    let coarse = read_lut(&fem_core::shipped::production_mesh_lut_path())
        .unwrap()
        .lut;
    let fine = read_lut(&fem_core::shipped::default_lut_path())
        .unwrap()
        .lut;
    assert!(is_finer_version_of(&fine, &coarse));
    assert!(!is_finer_version_of(&coarse, &fine));
    assert!(!is_finer_version_of(&coarse, &coarse));
    // the converged contact radius (the edge band) on the same mesh level is finer than
    // the plain mesh, not the other way round
    let mut banded = coarse.clone();
    banded.edge_band = Some(fem_core::edge_band::EdgeBand::CONVERGED);
    assert!(is_finer_version_of(&banded, &coarse));
    assert!(!is_finer_version_of(&coarse, &banded));
    assert!(!is_finer_version_of(&banded, &banded));
    // nor is a band table of another grid
    banded.grid.modulus_kpa.pop();
    assert!(!is_finer_version_of(&banded, &coarse));
}

#[test]
fn the_term_predicts_the_bias_of_fitting_finer_mesh_data() {
    let coarse = read_lut(&fem_core::shipped::production_mesh_lut_path())
        .unwrap()
        .lut;
    let fine = read_lut(&fem_core::shipped::default_lut_path())
        .unwrap()
        .lut;
    let (model, fine_model) = (
        LutModel::new(&coarse).unwrap(),
        LutModel::new(&fine).unwrap(),
    );
    // On-grid moduli, so neither table interpolates in E2 and the difference is the mesh's.
    for (e, p) in [(215.4, 6.0), (681.3, 15.0), (46.42, 6.0)] {
        let data = points(&fine_model, e, p);
        let fit = fit_modulus(&model, &data, FitOptions::default()).unwrap();
        let actual = (fit.modulus_kpa / e).ln(); // the production model's bias
        let predicted =
            discretisation_bias_ln(&model, &fine_model, fit.modulus_kpa, &data).unwrap();
        eprintln!(
            "E2 {e} p {p}: fit {:.2} kPa, actual bias {actual:+.4}, predicted {predicted:+.4}",
            fit.modulus_kpa
        );
        // A one-step linearisation of a smooth least-squares problem: the prediction
        // matches the actual shift to a fraction of itself (or 0.2 % where both are tiny).
        assert!(
            (predicted - actual).abs() <= 0.3 * actual.abs() + 0.002,
            "E2 {e}: predicted {predicted:+.4}, actual {actual:+.4}"
        );
        // With the term the estimate is corrected to the converged model (the shipped finer
        // table has the edge band): what remains is the linearisation's share of the bias
        // (the tolerance above), and the interval covers the converged truth.
        let corrected = fit_modulus_with_model_error(&model, &data, FitOptions::default()).unwrap();
        assert!(corrected.discretisation_bias_ln.is_some());
        assert_eq!(corrected.modulus_production_kpa, Some(fit.modulus_kpa));
        let remaining = (corrected.modulus_kpa / e).ln();
        assert!(
            remaining.abs() <= 0.3 * actual.abs() + 0.002,
            "E2 {e}: corrected {:.2} kPa ({remaining:+.4})",
            corrected.modulus_kpa
        );
        assert!(
            corrected.ci95_kpa[0] <= e && e <= corrected.ci95_kpa[1],
            "E2 {e}: {:?}",
            corrected.ci95_kpa
        );
    }
}

/// The shipped production table and its "converged" twin with every modulus label 2 %
/// higher (the band and its error estimate set): data made of the twin fit 2 % low with the
/// production table.
fn production_and_relabelled_twin() -> (fem_core::lut::Lut, fem_core::lut::Lut) {
    let coarse = read_lut(&fem_core::shipped::production_mesh_lut_path())
        .unwrap()
        .lut;
    let mut twin = coarse.clone();
    twin.grid.modulus_kpa.iter_mut().for_each(|e| *e *= 1.02);
    twin.edge_band = Some(fem_core::edge_band::EdgeBand::CONVERGED);
    twin.contact_radius_error = Some(fem_core::discretisation::EDGE_BAND);
    (coarse, twin)
}

/// The correction itself, on a known bias: a "converged" twin whose curves are the
/// production table's with every modulus label 2 % higher, so that its a at E2 is the
/// production table's at E2 / 1.02 and data made of it fit 2 % low with the production
/// table. The correction must restore E2, and a plain finer twin (no band) must only widen
/// the interval.
#[test]
fn a_converged_twin_corrects_the_estimate_and_a_plain_one_widens_the_interval() {
    let (coarse, twin) = production_and_relabelled_twin();
    let (model, twin_model) = (
        LutModel::new(&coarse).unwrap(),
        LutModel::new(&twin).unwrap(),
    );
    for (e, p) in [(150.0, 6.0), (500.0, 15.0)] {
        let data = points(&twin_model, e, p);
        let production = fit_modulus(&model, &data, FitOptions::default()).unwrap();
        assert!((production.modulus_kpa / (e / 1.02) - 1.0).abs() < 1e-3);
        let mut corrected = production.clone();
        apply_discretisation_term(&mut corrected, &model, &twin_model, &data);
        let bias = corrected.discretisation_bias_ln.unwrap();
        eprintln!(
            "E2 {e}: production {:.2}, corrected {:.2} kPa, bias {bias:+.4}, residual term {:.4}",
            production.modulus_kpa,
            corrected.modulus_kpa,
            corrected.discretisation_residual_ln.unwrap()
        );
        // a pure relabelling is linear in ln E2 to the table's interpolation: the
        // first-order correction restores E2 to 0.1 % (the bias itself is 2 %)
        assert!((corrected.modulus_kpa / e - 1.0).abs() < 1e-3);
        assert!(corrected.ci95_kpa[0] <= e && e <= corrected.ci95_kpa[1]);
        // the interval moved with the estimate and widened by the twin's own error
        let width = |f: &fit::ModulusFit| (f.ci95_kpa[1] / f.ci95_kpa[0]).ln();
        assert!(width(&corrected) > width(&production));

        // the same twin without the band is not converged: estimate kept, interval widened
        // by the bias
        let mut plain_twin = twin.clone();
        plain_twin.edge_band = None;
        let plain_model = LutModel::new(&plain_twin).unwrap();
        let mut widened = production.clone();
        apply_discretisation_term(&mut widened, &model, &plain_model, &data);
        assert_eq!(widened.modulus_kpa, production.modulus_kpa);
        assert_eq!(widened.modulus_production_kpa, None);
        // half-width at least |bias| (in quadrature with the fit's own)
        assert!(width(&widened) >= 2.0 * bias.abs());
    }
}

/// The partial estimates follow the joint one: with the relabelled twin above (a known 2 %
/// bias), data at 6 and 15 kPa with 3 replicates each; after the correction every
/// per-pressure and per-replicate estimate is back at E2 to 0.1 %, as the joint one is.
#[test]
fn per_pressure_and_replicate_estimates_are_corrected_too() {
    let (coarse, twin) = production_and_relabelled_twin();
    let (model, twin_model) = (
        LutModel::new(&coarse).unwrap(),
        LutModel::new(&twin).unwrap(),
    );
    let e = 300.0;
    let mut data = points(&twin_model, e, 6.0);
    data.extend(points(&twin_model, e, 15.0));
    let production = fit_modulus(&model, &data, FitOptions::default()).unwrap();
    assert_eq!(production.per_pressure.len(), 2);
    assert_eq!(production.replicate_moduli_kpa.len(), 3);
    // uncorrected, every partial estimate carries the 2 % bias
    for pf in &production.per_pressure {
        assert!((pf.modulus_kpa / (e / 1.02) - 1.0).abs() < 1e-3, "{pf:?}");
    }
    let mut corrected = production.clone();
    apply_discretisation_term(&mut corrected, &model, &twin_model, &data);
    assert!((corrected.modulus_kpa / e - 1.0).abs() < 1e-3);
    for (pf, before) in corrected.per_pressure.iter().zip(&production.per_pressure) {
        assert!((pf.modulus_kpa / e - 1.0).abs() < 1e-3, "{pf:?}");
        assert!(pf.ci95_kpa[0] <= e && e <= pf.ci95_kpa[1], "{pf:?}");
        // moved with the estimate, and no narrower
        let width = |c: [f64; 2]| (c[1] / c[0]).ln();
        assert!(width(pf.ci95_kpa) >= width(before.ci95_kpa) - 1e-12);
    }
    for r in &corrected.replicate_moduli_kpa {
        assert!((r / e - 1.0).abs() < 1e-3, "{r}");
    }
}

/// The shipped table is converged: a fit with it keeps its estimate (no correction, no
/// finer table), and its interval is the fit's own widened in quadrature by the table's
/// own largest error of a (its header's `contact_radius_error`) projected on ln E2, at the
/// joint and the per-pressure estimates.
#[test]
fn a_converged_table_keeps_its_estimate_and_adds_its_own_error() {
    let table = read_lut(&fem_core::shipped::default_lut_path())
        .unwrap()
        .lut;
    let error = converged_error(&table).expect("the shipped table is converged");
    assert_eq!(error, fem_core::discretisation::EDGE_BAND);
    let model = LutModel::new(&table).unwrap();
    // between nodes, at both of the tool's pressures
    let e = 300.0;
    let mut data = points(&model, e, 6.0);
    data.extend(points(&model, e, 15.0));
    let plain = fit_modulus(&model, &data, FitOptions::default()).unwrap();
    let with_error = fit_modulus_with_model_error(&model, &data, FitOptions::default()).unwrap();
    assert_eq!(with_error.modulus_kpa, plain.modulus_kpa);
    assert_eq!(with_error.discretisation_bias_ln, None);
    assert_eq!(with_error.modulus_production_kpa, None);
    let term = with_error.discretisation_residual_ln.unwrap();
    let expected =
        projected_error_ln(&model, plain.modulus_kpa, &data, error.max_um * 1e-3).unwrap();
    assert_eq!(term, expected);
    // the half-width in ln E2 grows in quadrature by exactly the term
    let half = |c: [f64; 2]| 0.5 * (c[1] / c[0]).ln();
    let (before, after) = (half(plain.ci95_kpa), half(with_error.ci95_kpa));
    assert!((after * after - before * before - term * term).abs() < 1e-12 * (1.0 + after * after));
    // 3 um against a sensitivity of a few tens of um per unit ln E2 at 300 kPa: a term of
    // a few tenths of a percent to a few percent, not zero and not the whole range
    assert!((1e-3..0.1).contains(&term), "term {term}");
    for (pf, before) in with_error.per_pressure.iter().zip(&plain.per_pressure) {
        assert_eq!(pf.modulus_kpa, before.modulus_kpa);
        assert!(half(pf.ci95_kpa) > half(before.ci95_kpa), "{pf:?}");
    }
    let named = format!("converged table's own error ({:.1} um", error.max_um);
    assert!(with_error.ci_description.contains(&named), "{named}");
}
