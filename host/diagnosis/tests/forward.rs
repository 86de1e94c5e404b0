//! Forward selection (`diagnosis::forward`) on data generated from the shipped effect tables
//! with two hidden effects at once and known, injected noise (no FE solve: the table is the
//! truth here, so what is checked is the search — that the first effect's inclusion lets
//! the second be found with the same calibrated threshold, that an effect below its
//! detectable size is not named, and that clean data stays `none`). The hil-sim truth with
//! two effects (a real thinner layer solved by fem-core plus a proximity offset) is the
//! long check `system-tests --test diagnose_hidden_effects two_effects_from_the_bench_model`.
//!
//! Truth: E2 = 170 kPa (off the modulus nodes), 5 replicates at 6 and 15 kPa, 40 points per
//! replicate over u_s 0.15..1.15 mm; white noise 4 um on a and 1 mN on the load, per-test
//! offsets 2 um on a and 1 mN on the load (testkit's defaults, the demo's noise level).

use diagnosis::candidates::{Candidate, EffectKind};
use diagnosis::data::Point;
use diagnosis::model::Model;
use diagnosis::tables::shipped_tables;
use diagnosis::verdict::Verdict;
use diagnosis::{DiagnoseOptions, Diagnosis, diagnose};
use testkit::synthetic_curves::{SyntheticSpec, generate};

const TRUE_MODULUS_KPA: f64 = 170.0;

fn candidate(kind: EffectKind) -> Candidate {
    Candidate {
        kind,
        tau_h_mm: None,
    }
}

/// Points of the baseline with `truth` (effects at their sizes) included.
fn synthetic(model: &Model<'_>, truth: &[(EffectKind, f64)], seed: u64) -> Vec<Point> {
    let mut m = model.clone();
    m.included = truth.iter().map(|&(k, t)| (candidate(k), t)).collect();
    let spec = SyntheticSpec {
        modulus_kpa: TRUE_MODULUS_KPA,
        seed,
        ..SyntheticSpec::default()
    };
    generate(&m, None, |_| 0.0, &spec)
}

/// The default options but for the confidence reruns (they only concern the first effect's
/// confidence and cost 20 selections); the threshold and the held-out margin keep their
/// calibrated draws.
fn options() -> DiagnoseOptions {
    DiagnoseOptions {
        confidence_reruns: 0,
        ..DiagnoseOptions::default()
    }
}

fn run(truth: &[(EffectKind, f64)], seed: u64) -> Diagnosis {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let pts = synthetic(&model, truth, seed);
    let d = diagnose(&base, &effects, pts, &options()).expect("diagnose");
    eprintln!("{}", diagnosis::report::text(&d));
    d
}

fn names(d: &Diagnosis) -> Vec<String> {
    d.effects.iter().map(|e| e.effect.clone()).collect()
}

/// The value of `effect`'s parameter in the final model.
fn value(d: &Diagnosis, effect: EffectKind) -> Option<(f64, f64)> {
    let e = d.effects.iter().find(|e| e.effect == effect.name())?;
    let p = e.parameters.get(effect.parameter().0)?;
    Some((p.get("value")?.as_f64()?, p.get("se")?.as_f64()?))
}

/// Both effects named in either order, each parameter within 4 standard errors (a joint fit
/// of three parameters on ~400 correlated points: 4 se leaves room for the se's own
/// uncertainty from five replicates) or 25 % of its size, whichever is larger; the modulus
/// back within 3 % of the truth (the baseline's bias with two hidden effects is larger);
/// the final model's chi^2/dof below the baseline's.
fn check_pair(d: &Diagnosis, a: (EffectKind, f64), b: (EffectKind, f64)) {
    assert_eq!(d.verdict, Verdict::Effect, "first step verdict");
    let n = names(d);
    assert!(
        n.len() == 2 && n.contains(&a.0.name().to_string()) && n.contains(&b.0.name().to_string()),
        "effects named: {n:?}"
    );
    assert_eq!(
        d.effect.as_deref(),
        Some(n[0].as_str()),
        "effect is the first"
    );
    for (k, size) in [a, b] {
        let (v, se) = value(d, k).expect("parameter");
        assert!(
            (v - size).abs() < (4.0 * se).max(0.25 * size.abs()),
            "{}: {v:.4} +- {se:.4}, true {size}",
            k.name()
        );
    }
    let f = &d.forward;
    let e_after = f.modulus_after_kpa;
    assert!(
        (e_after / TRUE_MODULUS_KPA - 1.0).abs() < 0.03,
        "E2 after {e_after:.1} kPa (before {:.1})",
        f.modulus_before_kpa
    );
    let shrink = f.gap_shrink.expect("final gap");
    assert!(shrink > 1.0, "gap shrink {shrink:.3}");
    for s in &f.steps {
        assert!(
            s.gap_shrink > 1.0,
            "step {} gap shrink {:.3}",
            s.step,
            s.gap_shrink
        );
    }
}

#[test]
fn a_thinner_sample_and_a_displacement_offset_are_both_named() {
    let thin = (EffectKind::FiniteThickness, 1.5);
    let off = (EffectKind::DisplacementOffset, 0.04);
    let d = run(&[thin, off], 21);
    check_pair(&d, thin, off);
}

/// Friction (mu 0.3) with a 3 % camera scale, on the seed where step 1 goes wrong: the
/// camera scale fits the radius best but, without friction's load, fails its held-out
/// check, and relaxation is named first (with a radius offset after it). The look-ahead
/// from the scale finds friction at step 2 on its gain in the fit to both channels (its
/// radius gain, about 3, is below the radius threshold of 7: the scale absorbs what
/// friction does to the radius), and that pair explains both channels far better (score
/// 676 against 1401), so it is kept. Before later steps detected on both channels without
/// the radius gate, this seed named relaxation + radius offset: a wrong pair.
#[test]
fn friction_and_a_camera_scale_are_both_named() {
    let fr = (EffectKind::Friction, 0.3);
    let sc = (EffectKind::RadiusScale, 0.03);
    let d = run(&[fr, sc], 22);
    check_pair(&d, fr, sc);
    // friction came in on its gain over both channels, not on the radius's
    let at = d
        .forward
        .steps
        .iter()
        .position(|s| s.effect == "friction")
        .expect("friction's step");
    let step = &d.forward.steps[at];
    assert!(step.passed_on_both_channels, "{step:?}");
    assert!(step.delta_chi2 < step.threshold_chi2, "{step:?}");
    let (gain, threshold) = (
        step.joint_delta_chi2.expect("joint gain"),
        step.joint_threshold_chi2.expect("joint threshold"),
    );
    assert!(gain > threshold, "joint gain {gain} vs {threshold}");
    // the other effects that passed on both channels are listed, none of them in the model
    // already, each fitting both channels worse than friction (the step adds the best)
    let joint = step.joint_chi2.expect("friction's joint chi2");
    assert!(!step.also_passed_on_both_channels.is_empty());
    for alt in &step.also_passed_on_both_channels {
        assert!(
            !matches!(alt.effect.as_str(), "friction" | "radius_scale"),
            "{alt:?}"
        );
        assert!(alt.joint_chi2 > joint, "{alt:?} against friction's {joint}");
    }
    let json = serde_json::to_value(&d).expect("json");
    let listed = &json["forward"]["steps"][at]["also_passed_on_both_channels"];
    assert_eq!(
        listed.as_array().map(Vec::len),
        Some(step.also_passed_on_both_channels.len()),
        "{listed}"
    );
}

/// The same pair over more seeds and both friction sizes of the table's upper half.
#[test]
#[ignore = "about 8 min in release; cargo test --release -p diagnosis --features sim --test forward friction_and_a_camera_scale_over_seeds -- --ignored --exact --nocapture"]
fn friction_and_a_camera_scale_over_seeds() {
    let sc = (EffectKind::RadiusScale, 0.03);
    let failed: Vec<String> = [0.2, 0.3]
        .into_iter()
        .flat_map(|mu| (30..=35).map(move |seed| (mu, seed)))
        .filter_map(|(mu, seed)| {
            let fr = (EffectKind::Friction, mu);
            let d = run(&[fr, sc], seed);
            std::panic::catch_unwind(|| check_pair(&d, fr, sc))
                .err()
                .map(|_| format!("mu {mu} seed {seed}: {:?}", names(&d)))
        })
        .collect();
    assert!(failed.is_empty(), "{failed:?}");
}

/// Friction and a camera scale where step 1 alone goes wrong: no single effect explains
/// both channels (friction, the best over both, leaves a misfit: verdict `unexplained`;
/// the camera scale fits the radius best but, without the friction that raises the loads,
/// its modulus predicts them worse than the baseline). The search is then also tried from
/// the camera scale and from friction (the look-ahead, `forward::run`); each finds the
/// other effect next (friction behind the scale on its gain over both channels), and the
/// better-scoring pair (chi2 of both channels plus the threshold per effect: 678 from
/// friction, 685 from the scale, against 2519 for the baseline) is kept.
#[test]
fn friction_and_a_camera_scale_are_both_named_where_the_loads_kept_the_scale_out_of_step_one() {
    let fr = (EffectKind::Friction, 0.4);
    let sc = (EffectKind::RadiusScale, 0.03);
    let d = run(&[fr, sc], 25);
    check_pair(&d, fr, sc);
    let l = d
        .forward
        .look_ahead
        .as_ref()
        .expect("the look-ahead was tried");
    assert!(l.accepted, "{l:?}");
    assert!(
        matches!(l.tried.as_str(), "radius_scale" | "friction"),
        "{l:?}"
    );
    assert_eq!(d.effect.as_deref(), Some(l.tried.as_str()));
}

#[test]
fn a_second_effect_below_its_detectable_size_is_not_named() {
    // 1 um of displacement offset, half the minimum detectable offset at this noise (2.0 um:
    // the report's minimum detectable size, 80 % power at the threshold, on the clean data
    // of `clean_data_names_nothing`, with the converged baseline's small table-error term)
    let thin = (EffectKind::FiniteThickness, 1.5);
    let d = run(&[thin, (EffectKind::DisplacementOffset, 0.001)], 23);
    assert_eq!(names(&d), vec!["finite_thickness".to_string()]);
    assert_eq!(
        d.forward.stop.verdict,
        Verdict::None,
        "{}",
        d.forward.stop.reason
    );
}

#[test]
fn clean_data_names_nothing() {
    let d = run(&[], 24);
    assert_eq!(d.verdict, Verdict::None);
    assert!(d.effects.is_empty() && d.forward.steps.is_empty());
    // nothing named, nothing tried: the look-ahead replaces only a search that named something
    assert!(d.forward.look_ahead.is_none());
}

/// Loads that fall short of the baseline late in the travel while the radius is clean (what
/// a slow pressure leak the manometer does not see does to the load): no effect passes on
/// the radius, so nothing is named, and the baseline's load lack of fit makes the verdict
/// `unexplained` with the load windows that stand out (`LOAD_LACK_OF_FIT_LIMIT`). The same
/// seed without the load error is `clean_data_names_nothing`.
#[test]
fn loads_the_baseline_cannot_fit_are_unexplained_when_the_radius_names_nothing() {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let mut pts = synthetic(&model, &[], 24);
    // up to 4 % less load at the end of the travel at 15 kPa: ~30 mN at u_s = 1.15 mm,
    // 30 times the load noise (1 mN), so the rule's limit (chi2 per value 2.0) is far below
    for p in pts.iter_mut().filter(|p| p.p_air_kpa == 15.0) {
        let fraction = 0.04 * (p.u_s_mm - 0.15) / 1.0;
        p.load_n = p.load_n.map(|l| l * (1.0 - fraction));
    }
    let d = diagnose(&base, &effects, pts, &options()).expect("diagnose");
    eprintln!("{}", diagnosis::report::text(&d));
    assert_eq!(d.verdict, Verdict::Unexplained);
    assert!(d.effects.is_empty(), "effects named: {:?}", names(&d));
    let note = d
        .notes
        .iter()
        .find(|n| n.contains("fits the radius but not the load"))
        .expect("the load lack-of-fit note");
    assert!(
        note.contains("load at 15 kPa") && !note.contains("load at 6 kPa"),
        "the note names the 15 kPa load windows only: {note}"
    );
}

/// What the report lists when the radius and the load disagree under the final model
/// (`forward::both_channel_candidates`): on table data carrying friction behind a camera
/// scale, with the scale in the model, friction fitted to both channels explains both
/// within their noise at its true size; with the baseline alone no single candidate does
/// (the data need both effects), so the list cannot be a list of everything.
#[test]
fn friction_behind_a_camera_scale_explains_both_channels_once_the_scale_is_in() {
    use diagnosis::candidates::{library, predict};
    use diagnosis::forward::{BOTH_CHANNEL_LEVEL, both_channel_candidates};
    use diagnosis::load_channel::LoadChannel;
    use diagnosis::model::Channel;
    use diagnosis::noise_model::NoiseModel;
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let (mu, scale) = (0.3, 0.03);
    let pts = synthetic(
        &model,
        &[(EffectKind::Friction, mu), (EffectKind::RadiusScale, scale)],
        26,
    );
    let subset: Vec<usize> = (0..pts.len()).collect();
    let e = TRUE_MODULUS_KPA;
    let found_under = |m: &Model<'_>| {
        let r: Vec<f64> = pts
            .iter()
            .map(|p| p.a_mm - predict(m, None, e, 0.0, p, Channel::Radius))
            .collect();
        let noise = NoiseModel::estimate(m, &pts, &r, e);
        let lc = LoadChannel::new(m, &pts, &subset, e)
            .expect("a load channel")
            .with_joint(m, &noise, &pts, &subset, e);
        let joint = lc.joint.expect("a joint whitening");
        both_channel_candidates(m, &library(&model), &pts, &subset, &joint, e)
    };
    let mut with_scale = model.clone();
    with_scale.included = vec![(candidate(EffectKind::RadiusScale), scale)];
    let found = found_under(&with_scale);
    eprintln!("{found:#?}");
    assert!(found.iter().all(|b| b.p_value >= BOTH_CHANNEL_LEVEL));
    assert!(
        found.windows(2).all(|w| w[0].joint_chi2 <= w[1].joint_chi2),
        "best first"
    );
    let friction = found
        .iter()
        .find(|b| b.effect == "friction")
        .expect("friction explains both channels");
    let fitted = friction.parameters["friction_coefficient"]["value"]
        .as_f64()
        .expect("a fitted mu");
    // the table is the truth here: only the noise moves the fit (se about 0.01)
    assert!((fitted - mu).abs() < 0.05, "mu {fitted}");
    assert!(
        (friction.modulus_kpa / e - 1.0).abs() < 0.02,
        "{friction:?}"
    );
    // neither effect alone explains both channels
    let alone = found_under(&model);
    assert!(
        alone
            .iter()
            .all(|b| b.effect != "friction" && b.effect != "radius_scale"),
        "{alone:#?}"
    );
}
