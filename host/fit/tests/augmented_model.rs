//! The table augmented with a setup's effects ([`fit::model::Augmentation`]): its values
//! are the table's read where the composition says (closed forms of the transformation),
//! and a fit with the augmentation recovers the modulus of data that carries the effects,
//! where the plain table's fit is biased.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use fem_core::lut::{Lut, read_lut};
use fit::model::{Augmentation, PhysicalDelta};
use fit::{FitOptions, FitPoint, LutModel, fit_modulus};
use std::path::PathBuf;

fn lut() -> Lut {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/fit_fixture.lut");
    read_lut(&path).unwrap().lut
}

/// A made-up physical delta, smooth in all three arguments.
#[derive(Debug)]
struct Bulge;
impl PhysicalDelta for Bulge {
    fn delta(&self, e: f64, p: f64, u: f64) -> (f64, f64) {
        (0.01 * u * u * (1.0 + 0.1 * e.ln()) + 0.001 * p, 0.02 * u)
    }
}

#[test]
fn augmented_values_are_the_tables_read_where_the_composition_says() {
    let lut = lut();
    let plain = LutModel::new(&lut).unwrap();
    let aug = LutModel::with_augmentation(
        &lut,
        Augmentation {
            pressure_offset_kpa: 0.5,
            displacement_offset_mm: 0.03,
            radius_offset_mm: 0.02,
            radius_scale: 0.04,
            physical: Some(Box::new(Bulge)),
            pressure_reference: None,
        },
    )
    .unwrap();
    for (e, p, u) in [(60.0, 8.0, 0.6), (150.0, 10.0, 1.1), (90.0, 12.0, 0.35)] {
        let base = plain.sample(e, p - 0.5, u - 0.03).unwrap();
        let (da, dp) = Bulge.delta(e, p - 0.5, u - 0.03);
        let s = aug.sample(e, p, u).unwrap();
        // round-off only: the same table values combined the same way
        assert!(
            (s.a_mm - (1.04 * (base.a_mm + da) + 0.02)).abs() < 1e-12,
            "{s:?}"
        );
        assert!((s.load_n - (base.load_n + dp)).abs() < 1e-12);
        assert_eq!(s.h_mm, base.h_mm);
        // d a / d ln E2: the table's plus the delta's (0.001 u^2 analytically), scaled;
        // the central difference of a quadratic-free term in ln E2 is exact to round-off
        let want = 1.04 * (base.da_dln_modulus_mm + 0.001 * (u - 0.03f64).powi(2));
        assert!((s.da_dln_modulus_mm - want).abs() < 1e-9, "{s:?}");
        let (lo, hi) = plain.u_s_range_mm(e, p - 0.5).unwrap();
        let (alo, ahi) = aug.u_s_range_mm(e, p).unwrap();
        assert!((alo - lo - 0.03).abs() < 1e-15 && (ahi - hi - 0.03).abs() < 1e-15);
    }
    assert!(plain.augmentation().is_identity());
    assert!(!aug.augmentation().is_identity());
}

#[test]
fn a_fit_with_the_setups_effects_recovers_the_modulus() {
    let lut = lut();
    let truth = LutModel::with_augmentation(
        &lut,
        Augmentation {
            displacement_offset_mm: 0.04,
            radius_scale: -0.03,
            ..Augmentation::default()
        },
    )
    .unwrap();
    let e_true = 120.0;
    let p = 6.0;
    let (lo, hi) = truth.u_s_range_mm(e_true, p).unwrap();
    let points: Vec<FitPoint> = (0..3)
        .flat_map(|test| {
            let truth = &truth;
            (0..40).map(move |k| {
                let u = lo + 0.1 + (hi - lo - 0.2) * (k as f64 + 0.5) / 40.0;
                FitPoint {
                    u_s_mm: u,
                    a_mm: truth.sample(e_true, p, u).unwrap().a_mm,
                    p_air_kpa: p,
                    test,
                    load_n: None,
                }
            })
        })
        .collect();
    let plain = fit_modulus(
        &LutModel::new(&lut).unwrap(),
        &points,
        FitOptions::default(),
    );
    let corrected = fit_modulus(&truth, &points, FitOptions::default()).unwrap();
    // exact data from the same model: only the optimiser's tolerance remains
    assert!(
        (corrected.modulus_kpa / e_true - 1.0).abs() < 1e-3,
        "{corrected:?}"
    );
    // the table alone reads such a setup far off (or not at all)
    if let Ok(plain) = plain {
        assert!((plain.modulus_kpa / e_true - 1.0).abs() > 0.05, "{plain:?}");
    }
}
