//! The discretisation term of the fit's interval: the shipped production table and its
//! finer-mesh twin, and the term predicting the bias that fitting the production model to
//! finer-mesh data actually shows.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use fem_core::lut::read_lut;
use fit::discretisation::{
    discretisation_bias_ln, fit_modulus_with_model_error, is_finer_version_of,
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
fn the_shipped_fine_table_is_the_production_grid_converged() {
    let coarse = read_lut(&fem_core::shipped::default_lut_path())
        .unwrap()
        .lut;
    let fine = read_lut(&fem_core::shipped::fine_lut_path()).unwrap().lut;
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
    let coarse = read_lut(&fem_core::shipped::default_lut_path())
        .unwrap()
        .lut;
    let fine = read_lut(&fem_core::shipped::fine_lut_path()).unwrap().lut;
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
        // With the term, the interval covers the finer-mesh truth.
        let widened = fit_modulus_with_model_error(&model, &data, FitOptions::default()).unwrap();
        assert!(widened.discretisation_bias_ln.is_some());
        assert!(
            widened.ci95_kpa[0] <= e && e <= widened.ci95_kpa[1],
            "E2 {e}: {:?}",
            widened.ci95_kpa
        );
    }
}
