//! Diagnosis on hidden-effect data from hil-sim (the effect is switched on only in the
//! simulated truth: fem-core solves at the true sample, hil-sim's effect code, correlated
//! noise; see `diagnosis::simulate`), at off-grid moduli (170 kPa; 40 kPa for strain
//! stiffening, which only soft samples show). For each effect at its "clear" size the workflow must name it
//! (or an ambiguity group containing it) and the augmented model must shrink the gap
//! (chi^2 per dof) by more than 10 %.
//!
//! The default suite runs three cheap cases (one physical from a table, one hereditary, one
//! measurement effect) and one pair (a thinner sample with a displacement offset: the
//! forward selection must name both); every effect, and the pair of friction with a camera
//! scale, run with
//! `cargo test --release -p system-tests --test diagnose_hidden_effects -- --ignored`
//! (`HIDDEN_EFFECTS=pressure_offset,friction` checks only those effects).

use diagnosis::candidates::EffectKind;
use diagnosis::simulate::{Hidden, SimSpec, simulate, sizes, truth_modulus_kpa};
use diagnosis::tables::shipped_tables;
use diagnosis::{DiagnoseOptions, diagnose};

fn tables() -> (fem_core::lut::Lut, Vec<diagnosis::tables::EffectTable>) {
    shipped_tables().expect("diagnosis test setup")
}

/// The diagnosis as these tests run it: 200 bootstrap replicates, no confidence reruns.
fn diagnose_seeded(
    base: &fem_core::lut::Lut,
    effects: &[diagnosis::tables::EffectTable],
    points: Vec<diagnosis::data::Point>,
    seed: u64,
) -> diagnosis::Diagnosis {
    let options = DiagnoseOptions {
        bootstrap: 200,
        confidence_reruns: 0,
        seed,
        ..DiagnoseOptions::default()
    };
    diagnose(base, effects, points, &options).expect("diagnosis test setup")
}

fn check(kind: EffectKind, seed: u64) {
    let (base, effects) = tables();
    let size = sizes(kind)[1];
    let points = simulate(&SimSpec {
        modulus_kpa: truth_modulus_kpa(Some(kind)),
        hidden: Some(Hidden { kind, size }),
        seed,
        ..SimSpec::default()
    })
    .expect("diagnosis test setup");
    let d = diagnose_seeded(&base, &effects, points, seed);
    let named = d.effect.as_deref() == Some(kind.name())
        || d.ambiguity_group.iter().any(|g| g == kind.name());
    assert!(
        named,
        "{} at {size}: verdict {:?}, effect {:?}, group {:?}\n{}",
        kind.name(),
        d.verdict,
        d.effect,
        d.ambiguity_group,
        diagnosis::report::text(&d)
    );
    // the gap must shrink, beyond chance: the chi^2 improvement exceeds the bootstrap
    // threshold (the 95th percentile of the largest improvement any candidate gets on data
    // without an effect) and the held-out points are predicted better. (chi^2 per dof falls
    // by only 3-10 % for the small measurement effects, because it is dominated by the
    // noise model's table-error term, so a fixed shrink factor is not the criterion.)
    let shrink = d.gap_shrink.expect("diagnosis test setup");
    assert!(shrink > 1.0, "{}: gap shrink {shrink}", kind.name());
    let aug = d.augmented.expect("diagnosis test setup");
    assert!(
        d.baseline.chi2 - aug.chi2 > d.threshold.delta_chi2_95,
        "{}: chi2 {} -> {}, threshold {}",
        kind.name(),
        d.baseline.chi2,
        aug.chi2,
        d.threshold.delta_chi2_95
    );
    if let (Some(b), Some(a)) = (
        d.baseline.held_out_chi2_per_point,
        aug.held_out_chi2_per_point,
    ) {
        assert!(a < b, "{}: held-out chi2/point {b} -> {a}", kind.name());
    }
}

#[test]
fn thinner_sample_is_named_and_the_gap_shrinks() {
    check(EffectKind::FiniteThickness, 11);
}

#[test]
fn viscoelastic_relaxation_is_named_and_the_gap_shrinks() {
    check(EffectKind::Viscoelastic, 12);
}

#[test]
fn camera_radius_offset_is_named_and_the_gap_shrinks() {
    check(EffectKind::RadiusOffset, 13);
}

#[test]
#[ignore = "about 16 min in release (converged truths, level-1 friction solves); cargo test --release -p system-tests --test diagnose_hidden_effects -- --ignored --nocapture"]
fn every_effect_at_a_clear_size_is_named_and_the_gap_shrinks() {
    // every effect is checked (a failure is reported, not the end of the run)
    // HIDDEN_EFFECTS=name,name runs only those effects (with their usual seeds)
    let only = std::env::var("HIDDEN_EFFECTS").ok();
    let failed: Vec<&str> = EffectKind::ALL
        .into_iter()
        .enumerate()
        .filter(|(_, kind)| {
            only.as_deref()
                .is_none_or(|o| o.split(',').any(|n| n.trim() == kind.name()))
        })
        .filter(|&(k, kind)| std::panic::catch_unwind(|| check(kind, 100 + k as u64)).is_err())
        .map(|(_, kind)| kind.name())
        .collect();
    assert!(failed.is_empty(), "not named or no gap shrink: {failed:?}");
}

/// Two hidden effects at once: the forward selection must name both (in either order), the
/// final model must shrink the gap further than the first effect alone, and each named
/// parameter must lie within 4 standard errors or 30 % of its true size (a joint fit of
/// three parameters on data whose truth is a direct solve, not the table the model reads:
/// the table-error term and the parameter correlation widen the scatter beyond the
/// table-generated case of `diagnosis/tests/forward.rs`).
fn check_pair(a: Hidden, b: Hidden, seed: u64) {
    let (base, effects) = tables();
    let points = simulate(&SimSpec {
        modulus_kpa: 170.0,
        hidden: Some(a),
        also_hidden: vec![b],
        seed,
        ..SimSpec::default()
    })
    .expect("diagnosis test setup");
    let d = diagnose_seeded(&base, &effects, points, seed);
    let text = diagnosis::report::text(&d);
    eprintln!("{text}");
    let names: Vec<&str> = d.effects.iter().map(|e| e.effect.as_str()).collect();
    assert!(
        names.len() == 2 && names.contains(&a.kind.name()) && names.contains(&b.kind.name()),
        "named {names:?}\n{text}"
    );
    assert_eq!(d.effect.as_deref(), Some(names[0]));
    for h in [a, b] {
        let p = d
            .effects
            .iter()
            .find(|e| e.effect == h.kind.name())
            .and_then(|e| e.parameters.get(h.kind.parameter().0))
            .expect("diagnosis test setup");
        let (v, se) = (
            p.get("value")
                .and_then(serde_json::Value::as_f64)
                .unwrap_or(f64::NAN),
            p.get("se")
                .and_then(serde_json::Value::as_f64)
                .unwrap_or(f64::NAN),
        );
        assert!(
            (v - h.size).abs() < (4.0 * se).max(0.3 * h.size.abs()),
            "{}: {v:.4} +- {se:.4}, true {}",
            h.kind.name(),
            h.size
        );
    }
    let first = d.gap_shrink.expect("diagnosis test setup");
    let all = d.forward.gap_shrink.expect("diagnosis test setup");
    assert!(
        all > first,
        "gap shrink {first:.3} with the first, {all:.3} with both"
    );
}

#[test]
fn a_thinner_sample_with_a_displacement_offset_names_both() {
    check_pair(
        Hidden {
            kind: EffectKind::FiniteThickness,
            size: 1.5,
        },
        Hidden {
            kind: EffectKind::DisplacementOffset,
            size: 0.04,
        },
        31,
    );
}

#[test]
// On the converged friction truth (a frictional band solve at the exact mu), the camera
// scale absorbs friction's change of the radius and friction is found at step 2 on its gain
// in the fit to both channels (docs/diagnosis.md, Method, step 7); over seeds, the study
// of `scripts/diagnosis_pair_study.sh` (docs/results.md).
#[ignore = "about 4 min in release (friction truth solves); cargo test --release -p system-tests --test diagnose_hidden_effects friction_with -- --ignored --nocapture"]
fn friction_with_a_camera_scale_names_both() {
    check_pair(
        Hidden {
            kind: EffectKind::Friction,
            size: 0.4,
        },
        Hidden {
            kind: EffectKind::RadiusScale,
            size: 0.03,
        },
        32,
    );
}
