//! The load channel of the diagnosis (`diagnosis::load_channel`) on data generated from
//! the shipped effect tables with known, injected noise (no FE solve: the model is exact
//! here, so what is checked is the channel's noise estimate and its verdict between
//! candidates that the radius alone confuses).
//!
//! Truth: E2 = 170 kPa (off the modulus nodes), Coulomb friction mu = 0.3 from the friction
//! table, 5 replicates at 6 and 15 kPa; white noise 4 um on a and 1 mN on the load, and a
//! per-test offset of 2 um on a and 1 mN on the load.

use diagnosis::candidates::{Candidate, EffectKind, predict};
use diagnosis::data::Point;
use diagnosis::fitting::fit;
use diagnosis::load_channel::LoadChannel;
use diagnosis::model::{Channel, Model};
use diagnosis::noise_model::NoiseModel;
use diagnosis::tables::shipped_tables;
use testkit::synthetic_curves::{SyntheticSpec, generate};

const TRUE_MODULUS_KPA: f64 = 170.0;
const TRUE_MU: f64 = 0.3;

fn candidate(kind: EffectKind) -> Candidate {
    Candidate {
        kind,
        tau_h_mm: None,
    }
}

/// Points along u_s 0.15..1.15 mm, 40 per replicate, the truth being `truth` at `theta`.
fn synthetic(model: &Model<'_>, truth: Option<&Candidate>, theta: f64, seed: u64) -> Vec<Point> {
    let spec = SyntheticSpec {
        modulus_kpa: TRUE_MODULUS_KPA,
        seed,
        ..SyntheticSpec::default()
    };
    generate(model, truth.map(|c| (c, theta)), |_| 0.0, &spec)
}

#[test]
fn loads_tell_friction_from_a_camera_scale_that_fits_the_radius_alike() {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let friction = candidate(EffectKind::Friction);
    let scale = candidate(EffectKind::RadiusScale);

    // 1. the load noise estimated from the replicates of clean loads: the true model's
    //    chi^2 per load is near 1 (400 values whose variance is known: 2 sigma of a chi^2 on
    //    400 dof is +-0.14; the offsets estimated from 5 replicates (Jeffreys-inflated) and
    //    the table-error term the noise model adds on top make it smaller, and 5 replicates
    //    estimate the offset variance to within a factor ~2, hence the wide 0.5..1.3;
    //    measured 0.85)
    let clean = synthetic(&model, Some(&friction), TRUE_MU, 7);
    let all: Vec<usize> = (0..clean.len()).collect();
    let truth_residual: Vec<f64> = clean
        .iter()
        .map(|p| {
            Channel::Load.measured(p)
                - predict(
                    &model,
                    Some(&friction),
                    TRUE_MODULUS_KPA,
                    TRUE_MU,
                    p,
                    Channel::Load,
                )
        })
        .collect();
    let noise_load =
        NoiseModel::estimate_channel(&model, Channel::Load, &clean, &truth_residual, 170.0);
    let w = noise_load.whitener(&clean, &all).expect("load whitener");
    let chi2_per_load =
        w.whiten(&truth_residual).iter().map(|v| v * v).sum::<f64>() / all.len() as f64;
    assert!(
        (0.5..1.3).contains(&chi2_per_load),
        "true model's load chi2 per value {chi2_per_load:.3}"
    );

    // 2. fit friction and the camera scale on the radius alone; both explain a to within a
    //    few chi^2 of each other, the loads do not
    let r_a: Vec<f64> = clean
        .iter()
        .map(|p| p.a_mm - predict(&model, None, 170.0, 0.0, p, Channel::Radius))
        .collect();
    let noise_a = NoiseModel::estimate(&model, &clean, &r_a, 170.0);
    let wa = noise_a.whitener(&clean, &all).expect("radius whitener");
    let base_fit = fit(&model, None, &clean, &all, &wa, 170.0, 0.0, 40).expect("baseline fit");
    let load = LoadChannel::new(&model, &clean, &all, base_fit.modulus_kpa).expect("channel");
    let fit_f = fit(&model, Some(&friction), &clean, &all, &wa, 170.0, 0.1, 40).expect("fit");
    let fit_s = fit(&model, Some(&scale), &clean, &all, &wa, 170.0, 0.01, 40).expect("fit");
    let load_f = load
        .chi2(
            &model,
            Some(&friction),
            &clean,
            &all,
            fit_f.modulus_kpa,
            fit_f.theta,
        )
        .expect("load chi2");
    let load_s = load
        .chi2(
            &model,
            Some(&scale),
            &clean,
            &all,
            fit_s.modulus_kpa,
            fit_s.theta,
        )
        .expect("load chi2");
    eprintln!(
        "true-model load chi2/value {chi2_per_load:.3}; radius refit chi2: baseline {:.1}, friction {:.1} (mu {:.3} +- {:.3}), radius_scale {:.1}; load chi2: baseline {:.1}, friction {load_f:.1}, radius_scale {load_s:.1} ({} values)",
        base_fit.chi2,
        fit_f.chi2,
        fit_f.theta,
        fit_f.theta_se,
        fit_s.chi2,
        load.baseline_chi2,
        all.len()
    );
    // the friction refit recovers mu (se ~0.05 at this noise: within 3 se)
    assert!(
        (fit_f.theta - TRUE_MU).abs() < 0.15,
        "mu {:.3} +- {:.3}",
        fit_f.theta,
        fit_f.theta_se
    );
    // friction predicts the loads as well as the noise allows (per value near 1, as above);
    // the camera scale leaves friction's extra load unexplained: its chi^2 exceeds
    // friction's by far more than the ambiguity margin of 4
    let n = all.len() as f64;
    assert!(
        load_f / n < 1.5,
        "friction's load chi2 per value {:.3}",
        load_f / n
    );
    assert!(
        load_s - load_f > 50.0,
        "load chi2: friction {load_f:.1}, radius_scale {load_s:.1}"
    );
    // and the combined ranking (radius refit + load prediction) puts friction first
    assert!(
        fit_f.chi2 + load_f < fit_s.chi2 + load_s,
        "a: friction {:.1}, scale {:.1}; load: {load_f:.1}, {load_s:.1}",
        fit_f.chi2,
        fit_s.chi2
    );
}

#[test]
fn a_camera_scale_leaves_the_loads_alone() {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let scale = candidate(EffectKind::RadiusScale);
    let pts = synthetic(&model, Some(&scale), 0.03, 8);
    let all: Vec<usize> = (0..pts.len()).collect();
    // the baseline at the true modulus predicts the loads: a camera scale changes only a
    let load = LoadChannel::new(&model, &pts, &all, TRUE_MODULUS_KPA).expect("channel");
    let per_value = load.baseline_chi2 / all.len() as f64;
    assert!(
        (0.5..1.3).contains(&per_value),
        "baseline load chi2 per value {per_value:.3} (tolerance as in the friction test)"
    );
    // the scale candidate predicts the same loads as the baseline at any theta
    let with_scale = load
        .chi2(&model, Some(&scale), &pts, &all, TRUE_MODULUS_KPA, 0.03)
        .expect("load chi2");
    assert!((with_scale - load.baseline_chi2).abs() < 1e-9);
}
