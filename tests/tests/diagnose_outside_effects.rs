//! The simulation of effects outside the diagnosis's library (`simulate::Outside`): what
//! the camera and the shell see under them, checked against the same seed without them
//! (the noise draws are the same, so the difference is the effect alone).

use diagnosis::simulate::{Outside, SimSpec, simulate};

fn spec(outside: Option<Outside>) -> SimSpec {
    SimSpec {
        outside,
        seed: 11,
        ..SimSpec::default()
    }
}

#[test]
fn a_lens_distortion_grows_with_the_cube_of_the_radius() {
    let k = 0.002;
    let plain = simulate(&spec(None)).expect("simulation");
    let distorted =
        simulate(&spec(Some(Outside::LensDistortion { k_per_mm2: k }))).expect("simulation");
    assert_eq!(plain.len(), distorted.len());
    let mut largest: f64 = 0.0;
    for (p, d) in plain.iter().zip(&distorted) {
        assert_eq!(p.u_s_mm, d.u_s_mm);
        assert_eq!(p.load_n, d.load_n);
        // seen = a (1 + k a^2) + noise, plain = a + noise: the difference is k a^3, with a
        // read off the noisy plain radius (white 4 um + offsets: 3 k a^2 times ~10 um is
        // below 1e-3 mm at a = 4 mm)
        let expected = k * p.a_mm.powi(3);
        assert!(
            (d.a_mm - p.a_mm - expected).abs() < 1e-3,
            "a {}: {} vs {expected}",
            p.a_mm,
            d.a_mm - p.a_mm
        );
        largest = largest.max(d.a_mm - p.a_mm);
    }
    // the deepest radii (about 3.7 mm) grow by about 0.1 mm
    assert!(largest > 0.08, "largest growth {largest} mm");
}

#[test]
fn a_pressure_leak_softens_the_shell_as_the_indentation_goes_on() {
    let plain = simulate(&spec(None)).expect("simulation");
    let leaking =
        simulate(&spec(Some(Outside::PressureLeak { kpa_per_s: 0.5 }))).expect("simulation");
    assert_eq!(plain.len(), leaking.len());
    let load = |p: &diagnosis::data::Point| p.load_n.unwrap_or(f64::NAN);
    // the first frame after contact: the pressure has barely moved (1/30 s at 0.5 kPa/s)
    let first = (&plain[0], &leaking[0]);
    assert!((load(first.1) - load(first.0)).abs() < 1e-3 * load(first.0).abs().max(1e-3));
    // the last frame of each indentation, 0.9 kPa below the set point: a softer shell
    // carries less of the tube's travel, so the apex moves further and the load is lower
    for (p, l) in plain.iter().zip(&leaking) {
        if p.t_s.is_some_and(|t| t > 1.7) {
            assert!(l.u_s_mm > p.u_s_mm, "{p:?} vs {l:?}");
            assert!(load(l) < load(p), "{p:?} vs {l:?}");
        }
    }
}

/// The diagnosis of `points` as the other diagnosis tests run it (200 bootstrap draws, no
/// confidence reruns).
fn diagnose_points(points: Vec<diagnosis::data::Point>, seed: u64) -> diagnosis::Diagnosis {
    let (base, effects) = diagnosis::tables::shipped_tables().expect("diagnosis test setup");
    let options = diagnosis::DiagnoseOptions {
        bootstrap: 200,
        confidence_reruns: 0,
        seed,
        ..diagnosis::DiagnoseOptions::default()
    };
    diagnosis::diagnose(&base, &effects, points, &options).expect("diagnosis test setup")
}

/// The diagnosis of `points` (seed `seed`), which must be `unexplained` with nothing named
/// because the radius and the load disagree under the final model: the channel check and
/// the report's text.
fn unexplained_by_the_channel_check(
    points: Vec<diagnosis::data::Point>,
    seed: u64,
) -> (diagnosis::consistency::ChannelConsistency, String) {
    let d = diagnose_points(points, seed);
    let text = diagnosis::report::text(&d);
    assert_eq!(d.verdict.as_str(), "unexplained", "{text}");
    assert!(d.effect.is_none() && d.effects.is_empty(), "{text}");
    let c = d
        .forward
        .consistency
        .clone()
        .expect("loads with replicates");
    assert!(!c.agree, "{text}");
    (c, text)
}

/// A leak of 0.6 kPa/s simulated with seed `seed` (the outside study's data), diagnosed
/// with seed 1 as that study does: `unexplained` by the channel check.
fn leak_of_0_6_kpa_per_s_unexplained(
    seed: u64,
) -> (diagnosis::consistency::ChannelConsistency, String) {
    let points = simulate(&SimSpec {
        seed,
        ..spec(Some(Outside::PressureLeak { kpa_per_s: 0.6 }))
    })
    .expect("diagnosis test setup");
    unexplained_by_the_channel_check(points, 1)
}

/// A library effect `kind` of `size` hidden in data of seed `seed` (diagnosed with the
/// same seed): named first, with the radius and the load agreeing under the final model.
fn named_with_the_channels_in_agreement(
    kind: diagnosis::candidates::EffectKind,
    size: f64,
    seed: u64,
) -> (diagnosis::consistency::ChannelConsistency, String) {
    let points = simulate(&SimSpec {
        hidden: Some(diagnosis::simulate::Hidden { kind, size }),
        seed,
        ..spec(None)
    })
    .expect("diagnosis test setup");
    let d = diagnose_points(points, seed);
    let text = diagnosis::report::text(&d);
    assert_eq!(d.effect.as_deref(), Some(kind.name()), "{text}");
    let c = d
        .forward
        .consistency
        .clone()
        .expect("loads with replicates");
    assert!(c.agree, "{text}");
    (c, text)
}

/// PG_t, the two channels' misfit with every parameter shared within the tables' errors,
/// beyond its draws' 99th percentile with p below the check's level, and the report's line
/// under the verdict saying so.
fn no_single_set_of_parameters_fits_both(
    c: &diagnosis::consistency::ChannelConsistency,
    text: &str,
) {
    let level = c.level();
    assert!(
        c.tolerant_p_value < level && c.tolerant_statistic > c.tolerant_statistic_99,
        "{text}"
    );
    assert!(
        text.contains(
            "no single set of parameters fits both, even with the tables' own errors allowed"
        ),
        "{text}"
    );
}

#[test]
fn a_lens_distortion_is_unexplained_not_a_camera_scale() {
    // k = 0.002/mm^2: +0.8 % at a = 2 mm, +2.7 % at 3.7 mm. On the radius alone a camera
    // scale with a stiffer sample absorbs most of it (the selection adds radius_scale), but
    // the load, which the camera does not touch, wants the true modulus: the channels'
    // best fits under that model are incompatible, so nothing may be named
    let points = simulate(&spec(Some(Outside::LensDistortion { k_per_mm2: 0.002 })))
        .expect("diagnosis test setup");
    let (c, text) = unexplained_by_the_channel_check(points, 11);
    assert!(c.modulus_p_value < 0.01, "{text}");
    // the scale-corrected radius reads the sample stiffer than the load does (true 170 kPa;
    // measured 187 and 193 kPa from the radius, 166-171 from the load given the radius in
    // seeds 1 and 2)
    assert!(
        c.radius_modulus_kpa > c.load_given_radius_modulus_kpa,
        "{text}"
    );
    // the load alone, which no camera effect touches, stays near the truth: within 5 %
    // (its 95 % interval here is about +-2 %; measured 170.0 and 172.5 kPa)
    assert!((c.load_modulus_kpa - 170.0).abs() < 8.5, "{text}");
    assert!(
        text.contains("no effect of the library reconciles"),
        "{text}"
    );
    // with every parameter shared the two parts fit no model either, even with the tables'
    // errors allowed (a camera scale has none, so PG_t is PG here): beyond the draws' 99th
    // percentile (measured 24-84 against 11-12 at K = 0.002 in three seeds of the outside
    // study), and the report says so under the verdict
    no_single_set_of_parameters_fits_both(&c, &text);
}

#[test]
fn a_camera_scale_alone_keeps_the_channels_in_agreement() {
    // the contrast: a true scale error of 3 % changes the radius only, in proportion, and
    // the model with radius_scale reconciles both channels
    named_with_the_channels_in_agreement(diagnosis::candidates::EffectKind::RadiusScale, 0.03, 11);
}

#[test]
fn a_leak_that_the_library_absorbs_only_with_different_parameters_per_channel_is_unexplained() {
    // 0.6 kPa/s: the shell's true pressure falls along each indentation, by up to 1 kPa at
    // the end of the travel. On seed 1 the selection absorbs it as a thinner sample, a
    // camera scale and a manometer offset, whose moduli from the radius and from the load
    // given the radius agree (z within +-1), but no single set of parameters fits both
    // channels even with the tables' own errors allowed: PG_t came out at 25.1 against a
    // 99th percentile of 13.0 of its drawn null distribution (PG 52.2 without the
    // allowances; docs/results.md, "Diagnosis: effects outside the library")
    let (c, text) = leak_of_0_6_kpa_per_s_unexplained(1);
    // the whole model rejects it, not its modulus: the allowances only lower the statistic
    // (PG_t <= PG), and PG_t is still above its draws' 99th percentile with p below the
    // level
    let level = c.level();
    assert!(c.modulus_p_value >= level, "{text}");
    assert!(c.tolerant_statistic <= c.statistic + 1e-9, "{text}");
    no_single_set_of_parameters_fits_both(&c, &text);
}

#[test]
fn a_leak_read_as_a_manometer_offset_is_unexplained_because_the_offset_does_not_hold() {
    // 0.6 kPa/s, seed 2: the selection absorbs the leak as a camera scale and a manometer
    // offset of about 1 kPa, and within the pressure continuation's allowances both the
    // moduli and PG_t accept that model in both channels (PG_t 1.5 against 11.3 in the
    // outside study). But a manometer offset is one number for the whole travel, and the
    // leak's pressure keeps falling: read from the deep half of each indentation the offset
    // came out at 1.15 +- 0.02 kPa, from the shallow half 0.55 +- 0.08
    let (c, text) = leak_of_0_6_kpa_per_s_unexplained(2);
    let level = c.level();
    let hold = c
        .offset_hold
        .as_ref()
        .expect("a pressure offset in the model");
    assert!(hold.p_value < level, "{text}");
    // the offset grows with depth, as the falling pressure does, by more than the
    // continuation's allowance (measured 0.60 kPa against 0.12)
    assert!(
        hold.deep_kpa - hold.shallow_kpa > hold.allowance_kpa,
        "{text}"
    );
    assert!(
        text.contains("the manometer offset does not hold over the travel"),
        "{text}"
    );
}

#[test]
fn a_true_manometer_offset_holds_over_the_travel() {
    // the contrast: the manometer reads 2 kPa high, so the shell holds 4 and 13 kPa under
    // the 6 and 15 kPa set points for the whole travel. The offset is named, and read from
    // either half of the travel it is the same (measured 1.96 +- 0.02 deep and 2.00, the
    // candidate's upper bound, shallow; 1.91-1.99 deep in three seeds)
    let (c, text) = named_with_the_channels_in_agreement(
        diagnosis::candidates::EffectKind::PressureOffset,
        2.0,
        1,
    );
    let hold = c
        .offset_hold
        .as_ref()
        .expect("a pressure offset in the model");
    assert!(hold.p_value >= c.level(), "{text}");
    // each half within 0.15 kPa of the truth: the pressure continuation's largest error in
    // the deep half over the three seeds measured was 0.09 kPa (its standard error 0.02-0.04)
    assert!((hold.deep_kpa - 2.0).abs() < 0.15, "{text}");
    assert!((hold.shallow_kpa - 2.0).abs() < 0.15, "{text}");
}
