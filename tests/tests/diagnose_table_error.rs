//! How far a baseline table is from the solver it was built with: the simulated
//! truth of the diagnosis tests is a direct fem-core solve at an off-grid modulus, the
//! diagnosis reads the table interpolated in ln E2 (PCHIP) and u_s (PCHIP). This measures,
//! per load step, truth minus table at the truth's (E2, p_air, u_s), and, at the table's own
//! modulus nodes, the table's node curve minus a direct solve (staleness: zero when the table
//! was built with the current solver).
//!
//! `cargo test --release -p system-tests --test diagnose_table_error -- --ignored --nocapture`
//! (`DIAG_TABLES=DIR` reads the tables from DIR instead of the shipped ones, e.g. tables
//! rebuilt with `tactile diagnose --build-tables DIR`). These measure the production table
//! (`default-production-mesh.lut`: the production mesh, no edge band) against solves at its settings; `loo_calibration` with `DIAG_CONVERGED=1`
//! measures the diagnosis's converged baseline (`default.lut`) against converged
//! solves (the edge band), as the simulated truth is made.

use diagnosis::model::Surface;
use diagnosis::tables::{
    EFFECT_MAX_DEPTH_MM, EFFECT_STEPS, EffectAxis, converged_baseline, effect_base_params,
    production_baseline, read_effect_table, shipped_tables_dir,
};
use fem_core::{Curve, CurveParams, solve_curve};

/// Steps of the truths at the effect tables' settings: their 0.05 mm of travel, to 1.95 mm.
const COARSE_TRUTH_STEPS: usize = EFFECT_STEPS - 1; // the thickness table's

fn tables_dir() -> std::path::PathBuf {
    std::env::var("DIAG_TABLES")
        .map(Into::into)
        .unwrap_or_else(|_| shipped_tables_dir())
}

fn truth_params(e: f64, p: f64) -> CurveParams {
    CurveParams {
        sample_modulus_kpa: e,
        pressure_kpa: p,
        steps: COARSE_TRUTH_STEPS,
        max_depth_mm: EFFECT_MAX_DEPTH_MM * COARSE_TRUTH_STEPS as f64 / EFFECT_STEPS as f64,
        ..effect_base_params()
    }
}

/// A converged solve at (E2, p_air): the simulated truth's settings
/// (`diagnosis::simulate::truth_curves` for a sample without table effects).
fn converged_truth(e: f64, p: f64) -> Curve {
    fem_core::Simulation::new(&diagnosis::simulate::truth_params(e, p))
        .with_edge_band()
        .solve()
        .expect("measurement setup")
        .curve
}

/// Largest |truth - table| (mm) over the steps of one (E2, p_air), printing each step.
fn compare(base: &Surface<'_>, e: f64, p: f64) -> f64 {
    let c = solve_curve(&truth_params(e, p)).expect("measurement setup");
    let mut worst: f64 = 0.0;
    let mut sum2 = 0.0;
    let mut n = 0;
    for q in c.points.iter().filter(|q| q.a_mm > 0.0) {
        let Some((lo, hi)) = base.u_s_range_mm(e, p) else {
            continue;
        };
        if q.u_s_mm < lo || q.u_s_mm > hi {
            continue;
        }
        let t = base.sample(e, p, q.u_s_mm).a_mm;
        let d = q.a_mm - t;
        println!(
            "  E2 {e:6.1} p {p:4.1} h {:4.2} u_s {:6.4} a_truth {:6.4} a_table {:6.4} diff {:+7.4}",
            q.h_mm, q.u_s_mm, q.a_mm, t, d
        );
        worst = worst.max(d.abs());
        sum2 += d * d;
        n += 1;
    }
    println!(
        "E2 {e} kPa p_air {p} kPa: RMS {:.4} mm, worst {:.4} mm over {n} steps",
        (sum2 / n.max(1) as f64).sqrt(),
        worst
    );
    worst
}

#[test]
#[ignore = "measurement (fem-core solves, ~1 min in release); run with --release -- --ignored --nocapture"]
fn truth_minus_table_per_step() {
    let lut = production_baseline().expect("measurement setup");
    let base =
        Surface::new(&lut, &fem_core::lut::EffectSelection::default()).expect("measurement setup");
    // staleness: at a table node the interpolation in E2 is exact, so a direct solve must
    // match the table to the solver's own path dependence (step cuts move curves by at most
    // 1e-4 mm, measured over the 78 default-table curves); a stale table (a solver change
    // since the build) moved a by up to 0.023 mm
    let nodes = lut.grid.modulus_kpa.clone();
    for &e in nodes.iter().filter(|&&e| (140.0..220.0).contains(&e)) {
        for p in [6.0, 15.0] {
            let worst = compare(&base, e, p);
            assert!(
                worst < 1e-4,
                "E2 {e} p {p}: table node differs by {worst} mm"
            );
        }
    }
    // the off-grid truths of the tests: interpolation across E2 (measured worst 13 um at
    // 170 kPa, 22 um at 40 kPa); 0.03 mm bounds that, and stays below the effects the
    // diagnosis must see (a 3 mm thinner sample moves a by ~0.05 mm)
    for e in [170.0, 40.0] {
        for p in [6.0, 15.0] {
            let worst = compare(&base, e, p);
            assert!(worst < 0.03, "E2 {e} p {p}: truth - table {worst} mm");
        }
    }
}

/// Calibration of the noise model's table-error scale: direct solves at the geometric
/// midpoints between the modulus nodes (where interpolation is worst), truth minus table per
/// load step against the leave-one-out error at the same u_s; prints the RMS ratio
/// (the scale `LUT_ERROR_SCALE` should match it) and the lag-1 correlation of the
/// step-to-step differences.
#[test]
#[ignore = "measurement (40 fem-core solves, ~1-2 min in release); run with --release -- --ignored --nocapture"]
fn loo_calibration() {
    use diagnosis::model::Channel;
    use diagnosis::model::Model;
    use diagnosis::noise_model::{table_error_knots_of, table_error_sigma};
    let converged = std::env::var_os("DIAG_CONVERGED").is_some();
    let lut = if converged {
        converged_baseline().expect("measurement setup")
    } else {
        production_baseline().expect("measurement setup")
    };
    let model = Model::new(&lut, &[]).expect("measurement setup");
    let nodes = lut.grid.modulus_kpa.clone();
    // `LOO_MODULI_KPA=25,40` measures at those moduli instead of the midpoints (the
    // assertions below then do not apply: they are about the midpoints the scale was
    // calibrated on)
    let chosen: Option<Vec<f64>> = std::env::var("LOO_MODULI_KPA").ok().map(|s| {
        s.split(',')
            .map(|x| x.trim().parse().expect("LOO_MODULI_KPA: numbers in kPa"))
            .collect()
    });
    let moduli = chosen.clone().unwrap_or_else(|| {
        (1..nodes.len() - 2)
            .map(|k| (nodes[k] * nodes[k + 1]).sqrt())
            .collect()
    });
    // `LOO_CHANNEL=load|travel` measures that channel instead of the contact radius (the
    // assertions below are about the radius)
    let channel = match std::env::var("LOO_CHANNEL").as_deref() {
        Ok("load") => Channel::Load,
        Ok("travel") => Channel::Travel,
        Ok("radius") | Err(_) => Channel::Radius,
        Ok(other) => panic!("LOO_CHANNEL: radius, load or travel, not {other}"),
    };
    let truth_value = |q: &fem_core::CurvePoint| match channel {
        Channel::Radius => q.a_mm,
        Channel::Load => q.load_n,
        Channel::Travel => q.h_mm,
    };
    println!("channel: {channel:?}");
    let unit = if channel == Channel::Load { "N" } else { "mm" };
    let (mut sd, mut sl, mut lag, mut lag0) = (0.0, 0.0, 0.0, 0.0);
    // the standardised steps with where they are: (z^2, E2, p_air, h, u_s, diff, sigma)
    let mut steps: Vec<(f64, f64, f64, f64, f64, f64, f64)> = Vec::new();
    // truth minus table per (modulus, pressure) keyed by the load step's travel h (in
    // 1e-6 mm): their correlation across the two pressures at equal h
    let mut by_step: Vec<(f64, f64, i64, f64)> = Vec::new();
    for &e in &moduli {
        for p in [6.0, 15.0] {
            let c = if converged {
                converged_truth(e, p)
            } else {
                solve_curve(&truth_params(e, p)).expect("measurement setup")
            };
            let Some((lo, hi)) = model.base.u_s_range_mm(e, p) else {
                continue;
            };
            let (knots, loo_rms) = table_error_knots_of(&model, channel, e, p);
            let mut d = Vec::new();
            let (mut ed, mut el) = (0.0, 0.0);
            for q in c.points.iter().filter(|q| q.a_mm > 0.0) {
                if q.u_s_mm < lo || q.u_s_mm > hi {
                    continue;
                }
                let diff = truth_value(q) - channel.of(&model.base.sample(e, p, q.u_s_mm));
                by_step.push((e, p, (q.h_mm * 1e6).round() as i64, diff));
                // the knot nearest to the step (the knots are the steps' u_s interpolated
                // between the nodes)
                let Some(k) = (0..knots.len()).min_by(|&a, &b| {
                    (knots[a] - q.u_s_mm)
                        .abs()
                        .total_cmp(&(knots[b] - q.u_s_mm).abs())
                }) else {
                    continue;
                };
                let loo = loo_rms[k];
                d.push(diff);
                ed += diff * diff;
                el += loo * loo;
                let sigma = table_error_sigma(&model, channel, e, loo);
                if sigma > 0.0 {
                    let z = (diff / sigma).powi(2);
                    steps.push((z, e, p, q.h_mm, q.u_s_mm, diff, sigma));
                }
            }
            let mut lag_curve = 0.0;
            for w in d.windows(2) {
                lag += w[0] * w[1];
                lag_curve += w[0] * w[1];
            }
            lag0 += ed;
            sd += ed;
            sl += el;
            println!(
                "E2 {e:7.2} p {p:4.1}: truth-table RMS {:.5} {unit}, LOO RMS {:.5} {unit}, ratio {:.2} (scale {:.2}; {} steps; lag-1 correlation {:+.2})",
                (ed / d.len().max(1) as f64).sqrt(),
                (el / d.len().max(1) as f64).sqrt(),
                (ed / el.max(1e-30)).sqrt(),
                // the channel's scale (its floor is negligible next to 1 mm)
                table_error_sigma(&model, channel, e, 1.0),
                d.len(),
                lag_curve / ed.max(1e-30)
            );
        }
    }
    let (mut s66, mut s77, mut s67) = (0.0, 0.0, 0.0);
    for &(e, p, h, d) in by_step.iter().filter(|x| x.1 == 6.0) {
        if let Some(&(_, _, _, d15)) = by_step.iter().find(|x| x.0 == e && x.1 != p && x.2 == h) {
            s66 += d * d;
            s77 += d15 * d15;
            s67 += d * d15;
        }
    }
    println!(
        "correlation of truth - table between 6 and 15 kPa at equal travel: {:.2}",
        s67 / (s66 * s77).sqrt().max(1e-30)
    );
    // largest first
    steps.sort_by(|a, b| b.0.total_cmp(&a.0));
    let z2: Vec<f64> = steps.iter().rev().map(|s| s.0).collect(); // ascending
    for &(z, e, p, h, u, diff, sigma) in steps.iter().take(8) {
        println!(
            "largest (diff / sigma)^2 {z:8.1}: E2 {e:7.2} p {p:4.1} h {h:.4} mm u_s {u:.4} mm, truth-table {:+.5} {unit}, sigma {:.5} {unit}",
            diff, sigma
        );
    }
    println!(
        "overall: RMS ratio truth-table / LOO = {:.3} (scale per modulus: noise_model::table_error_sigma); lag-1 correlation of truth-table {:.2}; \
         mean (diff / sigma)^2 (sigma: scaled LOO with the floor) = {:.2}, median {:.2} over {} steps",
        (sd / sl).sqrt(),
        lag / lag0,
        z2.iter().sum::<f64>() / z2.len() as f64,
        z2[z2.len() / 2],
        z2.len()
    );
    // the scale is an envelope over the per-modulus ratios (a margin for the heavy tails:
    // noise_model::LUT_ERROR_SCALE), so the standardised table error has a mean square
    // below 1 but not far below: under 0.25 the term would be inflated ~2x in sigma
    // everywhere, over 1 it would underweight the table error on average
    let mean_z2 = z2.iter().sum::<f64>() / z2.len() as f64;
    if chosen.is_some() || channel != Channel::Radius {
        return;
    }
    if converged {
        // the converged scale and floor are an envelope over the largest per-curve ratios
        // (noise_model::CONVERGED_LUT_ERROR_SCALE), so most curves sit far inside it: the
        // mean square must stay below 1
        assert!(mean_z2 < 1.0, "mean z^2 {mean_z2}");
        return;
    }
    assert!((0.25..1.0).contains(&mean_z2), "mean z^2 {mean_z2}");
    // the error alternates between steps (measured lag-1 correlation -0.39): the reason it
    // lives on independent knots, not on a smooth correlated term
    assert!(lag / lag0 < 0.0, "lag-1 correlation {}", lag / lag0);
}

/// The pressure-offset candidate reads the baseline at p_air - p0 from the table (which has
/// 1 kPa pressure steps around 6 and 15 kPa): this compares direct solves at 4.5 and 13.5 kPa
/// (a 1.5 kPa offset of the 6 and 15 kPa set points) with that reading, next to the effect
/// itself (a at the set point).
#[test]
#[ignore = "measurement (fem-core solves); run with --release -- --ignored --nocapture"]
fn pressure_continuation_error() {
    use diagnosis::model::Model;
    let t = read_effect_table(&tables_dir().join(EffectAxis::Thickness.file_name()))
        .expect("measurement setup");
    // `DIAG_CONVERGED=1`: the converged baseline, read between its pressure nodes through
    // the thickness table (`Surface::with_pressure_reference`), against converged solves
    let converged = std::env::var_os("DIAG_CONVERGED").is_some();
    let lut = if converged {
        converged_baseline().expect("measurement setup")
    } else {
        production_baseline().expect("measurement setup")
    };
    let effects = [t.clone()];
    let model = Model::new(&lut, &effects).expect("measurement setup");
    assert_eq!(model.base.has_pressure_reference(), converged);
    let base = model.base.clone();
    let mut failures = Vec::new();
    for e in [146.8, 170.0] {
        for (p_set, p_true) in [(6.0, 4.5), (15.0, 13.5), (6.0, 5.5), (15.0, 14.5)] {
            let c = if converged {
                converged_truth(e, p_true)
            } else {
                match solve_curve(&truth_params(e, p_true)) {
                    Ok(c) => c,
                    Err(err) => {
                        println!("E2 {e} p_true {p_true}: solve failed: {err}");
                        continue;
                    }
                }
            };
            let (mut s_err, mut s_eff, mut n) = (0.0, 0.0, 0);
            for q in c.points.iter().filter(|q| q.a_mm > 0.0 && q.u_s_mm > 0.05) {
                let cont = base.sample(e, p_true, q.u_s_mm).a_mm;
                let at_set = base.sample(e, p_set, q.u_s_mm).a_mm;
                s_err += (q.a_mm - cont).powi(2);
                s_eff += (q.a_mm - at_set).powi(2);
                n += 1;
                println!(
                    "  E2 {e} p {p_true}: u_s {:.3} truth {:.4} continued {:.4} at set point {:.4}",
                    q.u_s_mm, q.a_mm, cont, at_set
                );
            }
            let (rms_err, rms_eff) = ((s_err / n as f64).sqrt(), (s_eff / n as f64).sqrt());
            println!(
                "E2 {e} p_true {p_true} (set {p_set}): RMS truth - table {rms_err:.4} mm, RMS effect (truth - set point) {rms_eff:.4} mm"
            );
            // At a table node (146.8 kPa) the baseline read at the true pressure must be far
            // closer to the truth than the effect is large (before the 1 kPa pressure steps the
            // continuation missed by as much as the effect: 0.019 vs 0.020 mm); measured
            // 0.0002 / 0.0005 mm vs 0.016 / 0.006 mm, so a tenth has margin. Off-grid (170 kPa)
            // the E2 interpolation error dominates (4.5 kPa: 0.0147 mm, worst at the last two
            // steps near the table's u_s end), which `truth_minus_table_per_step` bounds and
            // the noise model carries: printed, not asserted here.
            // With the converged baseline (`DIAG_CONVERGED=1`): below 6 kPa (the first
            // inflated node) the change from the set point comes from the thickness table
            // (production mesh), averaged along u_s. At 4.5 kPa it is within 1.4 um of the
            // converged change up to u_s 1.4 mm (the mesh level -2 table: 0.8-3.7 um); beyond,
            // where the 4.5 kPa shell starts to give way (u_s 1.42-1.71 mm), it misses by
            // +5 to +52 um (level -2: +2.5 to +41), which sets the RMS: 0.0194 mm against
            // an effect of 0.042 mm, 0.46 of it (level -2: 0.0136 mm, 0.32). Between 10 and
            // 15 kPa it is the converged table's own chord (0.0008 / 0.0003 mm against
            // 0.018 / 0.0059 mm at 13.5 / 14.5 kPa, 0.04-0.05 of the effect). The bounds
            // guard those shares.
            // A converged table cannot be checked below its solves' own path dependence
            // (the noise model's floor, ~1 um): at 14.5 kPa the table rebuilt with other
            // load steps gave 0.0006 mm against an effect of 0.0060 mm.
            let share = if converged && p_true < 6.0 { 0.5 } else { 0.1 };
            let floor = if converged {
                diagnosis::noise_model::CONVERGED_LUT_ERROR_FLOOR_MM
            } else {
                0.0
            };
            if e == 146.8 && rms_err >= (share * rms_eff).max(floor) {
                failures.push(format!(
                    "E2 {e} p {p_true}: {rms_err:.4} vs effect {rms_eff:.4} mm"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
