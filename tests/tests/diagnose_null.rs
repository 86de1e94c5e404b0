//! False positives: clean data (no hidden effect; a converged solve of the sample at the
//! off-grid 170 kPa with correlated noise, diagnosed against the converged baseline) must
//! give verdict `none` in at least 95 % of seeds. The default suite runs 6 seeds and allows
//! 2: at the target rate of 5 %, P(>= 3 of 6) = 0.2 %, so it fails only on a rate well above
//! the target (a bound of 1 would fail 3.3 % of seed sets at the target rate; seeds 1-6
//! held two such seeds at 170 kPa with the Gaussian threshold alone, now one, seed 3). The
//! full check (>= 100 seeds, <= 5 %) is
//! `cargo test --release -p system-tests --test diagnose_null -- --ignored --nocapture`
//! (measured 3 of 100 at 170 kPa, 2 at 25 kPa, 4 at 20 kPa, 4 at 60 kPa:
//! host/diagnosis/src/null-false-positives.txt, docs/diagnosis.md, Limitations).
//! `NULL_SEEDS=N` runs the long check on fewer seeds (it then reports and fails, since the
//! criterion needs >= 100); `NULL_MODULUS_KPA=E` at another true modulus (default 170);
//! `NULL_WITHOUT_LOADS=1` drops the loads (the selection then reads the radius alone);
//! `NULL_NOISE=N` simulates at noise level N (default 1); `NULL_TRUTH=finer` solves the
//! sample one refinement finer than the tables (`SimSpec::finer_truth`).

use diagnosis::simulate::{SimSpec, simulate_with, truth_mechanics, truth_scenario};
use diagnosis::tables::shipped_tables;
use diagnosis::{DiagnoseOptions, diagnose};

/// The false positives and their descriptions, and the p-value of each seed's tube-travel
/// check under its final model (`diagnosis::travel`; the simulated bench records the
/// stage's travel).
fn false_positives(seeds: u64, modulus_kpa: f64) -> (usize, Vec<String>, Vec<f64>) {
    let (base, effects) = shipped_tables().expect("diagnosis test setup");
    let spec0 = SimSpec {
        modulus_kpa,
        noise: std::env::var("NULL_NOISE")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(1.0),
        finer_truth: std::env::var("NULL_TRUTH").is_ok_and(|v| v == "finer"),
        ..SimSpec::default()
    };
    let scenario = truth_scenario(&spec0);
    let mech = truth_mechanics(&scenario).expect("diagnosis test setup");
    let mut fp = 0;
    let mut labels = Vec::new();
    let mut travel_p = Vec::new();
    for seed in 1..=seeds {
        let spec = SimSpec {
            seed: 1000 + seed,
            ..spec0.clone()
        };
        let mut points = simulate_with(&spec, &scenario, &mech);
        if std::env::var_os("NULL_WITHOUT_LOADS").is_some() {
            for p in points.iter_mut() {
                p.load_n = None;
            }
        }
        let options = DiagnoseOptions {
            bootstrap: 200,
            confidence_reruns: 0,
            seed,
            ..DiagnoseOptions::default()
        };
        let d = diagnose(&base, &effects, points, &options).expect("diagnosis test setup");
        travel_p.extend(d.forward.travel.map(|t| t.p_value));
        if let Some(t) = d.forward.travel.filter(|t| t.p_value < 0.01) {
            println!(
                "  seed {seed}: the travel rejects the final model ({}): p {:.2e}, RMS {:.1} um",
                d.verdict.as_str(),
                t.p_value,
                t.rms_residual_mm * 1e3
            );
        }
        if d.verdict.as_str() != "none" {
            fp += 1;
            labels.push(format!(
                "seed {seed}: {} {:?}{} (baseline chi2/dof {:.2}; threshold {:.2}; {})",
                d.verdict.as_str(),
                d.effect,
                d.forward.consistency.as_ref().filter(|c| !c.agree).map_or(
                    String::new(),
                    |c| format!(
                        " [radius and load disagree under {}: E2 {:.1} vs {:.1} kPa, z {:+.2}]",
                        c.model, c.radius_modulus_kpa, c.load_given_radius_modulus_kpa, c.modulus_z
                    )
                ),
                d.baseline.chi2_per_dof,
                d.threshold.delta_chi2_95,
                d.candidates
                    .iter()
                    .filter(|c| c.passes_threshold)
                    .map(|c| format!(
                        "{} d {:.1} held-out gain {:.1} margin {:.1}",
                        c.label,
                        c.delta_chi2.unwrap_or(f64::NAN),
                        c.held_out.as_ref().map_or(f64::NAN, |h| h.gain()),
                        c.held_out.as_ref().map_or(f64::NAN, |h| h.margin_chi2)
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            ));
        }
    }
    (fp, labels, travel_p)
}

/// How often the travel check rejects the final model at the 5 % and the 1 % level.
fn travel_rejections(p_values: &[f64]) -> String {
    let below = |level: f64| p_values.iter().filter(|&&p| p < level).count();
    let mut sorted = p_values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let quantile = |q: f64| {
        sorted
            .get(((sorted.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    format!(
        "travel check under the final model: p < 0.05 in {} of {}, p < 0.01 in {} of {} \
         (p: smallest {:.3}, quartiles {:.2} / {:.2} / {:.2}; uniform if the check is exact)",
        below(0.05),
        p_values.len(),
        below(0.01),
        p_values.len(),
        quantile(0.0),
        quantile(0.25),
        quantile(0.5),
        quantile(0.75)
    )
}

#[test]
fn clean_data_rarely_names_an_effect() {
    let (fp, labels, travel_p) = false_positives(6, SimSpec::default().modulus_kpa);
    // every simulated record carries the stage's travel, so every seed gets its check
    assert_eq!(travel_p.len(), 6, "{}", travel_rejections(&travel_p));
    // at most 2 of 6: see the module docs (binomial at the 5 % target)
    assert!(fp <= 2, "{fp} of 6 false positives: {labels:?}");
}

#[test]
#[ignore = "100 diagnoses, about 2-4 min in release; cargo test --release -p system-tests --test diagnose_null -- --ignored --nocapture"]
fn false_positive_rate_over_100_seeds_is_at_most_5_percent() {
    let seeds: u64 = std::env::var("NULL_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100);
    let modulus_kpa: f64 = std::env::var("NULL_MODULUS_KPA")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(SimSpec::default().modulus_kpa);
    let (fp, labels, travel_p) = false_positives(seeds, modulus_kpa);
    let truth = if std::env::var("NULL_TRUTH").is_ok_and(|v| v == "finer") {
        " (truth solved one refinement finer than the tables)"
    } else {
        ""
    };
    println!("false positives at E2 = {modulus_kpa} kPa{truth}: {fp} of {seeds}:");
    println!("{}", travel_rejections(&travel_p));
    for l in &labels {
        println!("  {l}");
    }
    assert!(
        seeds >= 100 && fp * 20 <= seeds as usize,
        "{fp} of {seeds} false positives (the check needs >= 100 seeds)"
    );
}
