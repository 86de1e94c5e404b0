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
use diagnosis::fitting::{Objective, fit, fit_to};
use diagnosis::joint::JointWhitener;
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

/// Curves at the true modulus whose u_s reading carries a white and a per-test error shared
/// by both channels (a and the load are the truth's at the true u_s), with small noise of
/// their own: the case the joint covariance is for.
fn with_shared_u_noise(
    model: &Model<'_>,
    truth: Option<&Candidate>,
    theta: f64,
    seed: u64,
) -> Vec<Point> {
    let spec = SyntheticSpec {
        modulus_kpa: TRUE_MODULUS_KPA,
        white_a_mm: 0.002,
        offset_a_mm: 0.001,
        white_load_n: 3e-4,
        offset_load_n: 3e-4,
        white_u_mm: 0.006,
        offset_u_mm: 0.004,
        seed,
        ..SyntheticSpec::default()
    };
    generate(model, truth.map(|c| (c, theta)), |_| 0.0, &spec)
}

/// Correlation of two equally long sequences.
fn correlation(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    let syy: f64 = y.iter().map(|b| (b - my).powi(2)).sum();
    sxy / (sxx * syy).sqrt()
}

#[test]
fn the_joint_covariance_accounts_for_the_shared_u_s_reading() {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let pts = with_shared_u_noise(&model, None, 0.0, 21);
    let all: Vec<usize> = (0..pts.len()).collect();
    let residual = |ch: Channel| -> Vec<f64> {
        pts.iter()
            .map(|p| ch.measured(p) - predict(&model, None, TRUE_MODULUS_KPA, 0.0, p, ch))
            .collect()
    };
    let (r_a, r_p) = (residual(Channel::Radius), residual(Channel::Load));
    let noise_a = NoiseModel::estimate(&model, &pts, &r_a, TRUE_MODULUS_KPA);
    let noise_p = NoiseModel::estimate_channel(&model, Channel::Load, &pts, &r_p, TRUE_MODULUS_KPA);
    // each channel whitened on its own: the shared u_s error leaves the two correlated
    let wa = noise_a.whitener(&pts, &all).expect("radius whitener");
    let wp = noise_p.whitener(&pts, &all).expect("load whitener");
    let separate = correlation(&wa.whiten(&r_a), &wp.whiten(&r_p));
    // both together: radius and load values of one block are the first and second half;
    // under a right model the whitened values are independent N(0, 1)
    let joint =
        JointWhitener::new(&noise_a, &noise_p, &pts, &all, &r_a, &r_p).expect("joint whitener");
    let z = joint.whiten(&r_a, &r_p);
    let per_pressure = pts.len() / 2;
    let (mut za, mut zp) = (Vec::new(), Vec::new());
    for block in z.chunks(2 * per_pressure) {
        za.extend_from_slice(&block[..per_pressure]);
        zp.extend_from_slice(&block[per_pressure..]);
    }
    // the split the consistency check uses gives the same two parts
    assert_eq!(joint.split(&z), (za.clone(), zp.clone()));
    let after = correlation(&za, &zp);
    eprintln!("shared white u_s: {:?}", joint.shared_white_u_mm);
    let chi2_per_value = z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64;
    eprintln!(
        "whitened radius-load correlation: separately {separate:.3}, jointly {after:.3}; joint chi2/value {chi2_per_value:.3} over {} values",
        z.len()
    );
    // the shared white u_s error, estimated from the products of the two channels'
    // within-test residuals: 6 um in the data; 200 points per pressure estimate a variance
    // to ~10 % (a standard deviation to ~5 %), hence 20 % (measured 6.5 and 5.8 um)
    for &(p, sigma) in &joint.shared_white_u_mm {
        assert!(
            (sigma / 0.006 - 1.0).abs() < 0.2,
            "{p} kPa: shared white u_s {sigma:.4} mm"
        );
    }
    // the shared part dominates both channels' own white noise here (6 um of u_s against
    // 2 um of a, 0.3 mN of load), so separately whitened values correlate strongly
    // (measured 0.95) ...
    assert!(
        separate > 0.8,
        "separately whitened correlation {separate:.3}"
    );
    // ... and jointly whitened much less. Not to zero: each channel's own noise model,
    // estimated from 5 replicates, splits its variance between a (or P) and u_s with large
    // errors (here 6 um of white noise in a for 2 um), so the conditional of the load given
    // the radius is not exact (measured 0.25; 0.16 with 10 replicates, 0.13 with 20)
    assert!(
        after.abs() < 0.35,
        "jointly whitened correlation {after:.3}"
    );
    // chi^2 per value of the true model near 1, as for the load channel alone above
    // (0.5..1.3; the overestimated own noise makes it smaller: measured 0.67)
    assert!(
        (0.5..1.3).contains(&chi2_per_value),
        "joint chi2 per value {chi2_per_value:.3}"
    );
}

#[test]
fn friction_fitted_to_both_channels_is_better_determined_than_from_the_radius() {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let friction = candidate(EffectKind::Friction);
    let scale = candidate(EffectKind::RadiusScale);
    let pts = with_shared_u_noise(&model, Some(&friction), TRUE_MU, 22);
    let all: Vec<usize> = (0..pts.len()).collect();
    let residual = |ch: Channel| -> Vec<f64> {
        pts.iter()
            .map(|p| ch.measured(p) - predict(&model, None, TRUE_MODULUS_KPA, 0.0, p, ch))
            .collect()
    };
    // the noise models as the diagnosis estimates them: from the baseline's residuals
    let noise_a = NoiseModel::estimate(&model, &pts, &residual(Channel::Radius), 170.0);
    let wa = noise_a.whitener(&pts, &all).expect("radius whitener");
    let load = LoadChannel::new(&model, &pts, &all, TRUE_MODULUS_KPA)
        .expect("channel")
        .with_joint(&model, &noise_a, &pts, &all, TRUE_MODULUS_KPA);
    let joint = load.joint.as_ref().expect("joint whitener");
    let radius_f = fit(&model, Some(&friction), &pts, &all, &wa, 170.0, 0.1, 40).expect("fit");
    let joint_f = fit_to(
        &model,
        Some(&friction),
        &pts,
        &all,
        Objective::Joint(joint),
        170.0,
        0.1,
        40,
    )
    .expect("fit");
    let joint_s = fit_to(
        &model,
        Some(&scale),
        &pts,
        &all,
        Objective::Joint(joint),
        170.0,
        0.01,
        40,
    )
    .expect("fit");
    eprintln!(
        "mu: radius fit {:.3} +- {:.3} (E2 {:.1}), joint fit {:.3} +- {:.3} (E2 {:.1} kPa, {:.1} .. {:.1}); joint chi2: friction {:.1}, radius_scale {:.1} over {} values",
        radius_f.theta,
        radius_f.theta_se,
        radius_f.modulus_kpa,
        joint_f.theta,
        joint_f.theta_se,
        joint_f.modulus_kpa,
        joint_f.ci95_kpa[0],
        joint_f.ci95_kpa[1],
        joint_f.chi2,
        joint_s.chi2,
        joint_f.points
    );
    assert_eq!(joint_f.points, 2 * pts.len());
    // the loads carry friction's information that the radius shares with E2: a smaller
    // standard error (the joint Fisher information includes the radius's) ...
    assert!(
        joint_f.theta_se < 0.8 * radius_f.theta_se,
        "se of mu: joint {:.4}, radius {:.4}",
        joint_f.theta_se,
        radius_f.theta_se
    );
    // ... and the truth within 3 of them, the modulus within its interval
    assert!(
        (joint_f.theta - TRUE_MU).abs() < 3.0 * joint_f.theta_se,
        "mu {:.3} +- {:.3}",
        joint_f.theta,
        joint_f.theta_se
    );
    assert!(
        joint_f.ci95_kpa[0] < TRUE_MODULUS_KPA && TRUE_MODULUS_KPA < joint_f.ci95_kpa[1],
        "E2 {:.1} ({:.1} .. {:.1})",
        joint_f.modulus_kpa,
        joint_f.ci95_kpa[0],
        joint_f.ci95_kpa[1]
    );
    // a camera scale fitted to both channels cannot make the loads friction's: far worse
    // than friction by more than the ambiguity margin of 4
    assert!(
        joint_s.chi2 - joint_f.chi2 > 50.0,
        "joint chi2: friction {:.1}, scale {:.1}",
        joint_f.chi2,
        joint_s.chi2
    );
}
