//! How far the baseline effect table is from the solver it was built with: the simulated
//! truth of the diagnosis tests is a direct fem-core solve at an off-grid modulus, the
//! diagnosis reads the table interpolated in ln E2 (PCHIP) and u_s (PCHIP). This measures,
//! per load step, truth minus table at the truth's (E2, p_air, u_s), and, at the table's own
//! modulus nodes, the table's node curve minus a direct solve (staleness: zero when the table
//! was built with the current solver).
//!
//! `cargo test --release -p system-tests --test diagnose_table_error -- --ignored --nocapture`
//! (`DIAG_TABLES=DIR` reads the tables from DIR instead of the shipped ones).

use fem_core::{CurveParams, solve_curve};
use host::diagnosis::model::Surface;
use host::diagnosis::simulate::{TRUTH_MAX_DEPTH_MM, TRUTH_STEPS};
use host::diagnosis::tables::{
    EffectAxis, effect_base_params, read_effect_table, shipped_tables_dir, sub_table,
};

fn tables_dir() -> std::path::PathBuf {
    std::env::var("DIAG_TABLES")
        .map(Into::into)
        .unwrap_or_else(|_| shipped_tables_dir())
}

fn truth_params(e: f64, p: f64) -> CurveParams {
    CurveParams {
        sample_modulus_kpa: e,
        pressure_kpa: p,
        steps: TRUTH_STEPS,
        max_depth_mm: TRUTH_MAX_DEPTH_MM,
        ..effect_base_params()
    }
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
    let t = read_effect_table(&tables_dir().join(EffectAxis::Thickness.file_name()))
        .expect("measurement setup");
    let lut = sub_table(&t.lut, &t.axis.select(t.axis.base_value())).expect("measurement setup");
    let base =
        Surface::new(&lut, &fem_core::lut::EffectSelection::default()).expect("measurement setup");
    // staleness: at a table node the interpolation in E2 is exact
    let nodes = lut.grid.modulus_kpa.clone();
    for &e in nodes.iter().filter(|&&e| (140.0..220.0).contains(&e)) {
        for p in [6.0, 15.0] {
            compare(&base, e, p);
        }
    }
    // the off-grid truths of the tests
    for e in [170.0, 40.0] {
        for p in [6.0, 15.0] {
            compare(&base, e, p);
        }
    }
}

/// Largest differences between the tables in `DIAG_TABLES` and the shipped ones, per curve.
#[test]
#[ignore = "measurement: needs DIAG_TABLES=DIR with rebuilt tables; run with --release -- --ignored --nocapture"]
fn rebuilt_tables_against_shipped() {
    let Ok(dir) = std::env::var("DIAG_TABLES") else {
        println!("DIAG_TABLES not set: nothing to compare");
        return;
    };
    for axis in [
        EffectAxis::Thickness,
        EffectAxis::Stiffening,
        EffectAxis::Friction,
    ] {
        let Ok(new) = read_effect_table(&std::path::Path::new(&dir).join(axis.file_name())) else {
            continue;
        };
        let old = read_effect_table(&shipped_tables_dir().join(axis.file_name()))
            .expect("measurement setup");
        if new.lut.grid.modulus_kpa != old.lut.grid.modulus_kpa
            || new.lut.grid.pressure_kpa != old.lut.grid.pressure_kpa
            || axis.values_in(&new.lut.grid) != axis.values_in(&old.lut.grid)
        {
            println!("{}: different grids, not compared", axis.file_name());
            continue;
        }
        let (mut da, mut du, mut dn) = (0.0f64, 0.0f64, 0usize);
        for c in &new.lut.curves {
            let Some(o) = old.lut.curve(c.index) else {
                continue;
            };
            if c.a_mm.len() != o.a_mm.len() {
                dn += 1;
                continue;
            }
            for k in 0..c.a_mm.len() {
                da = da.max((c.a_mm[k] - o.a_mm[k]).abs());
                du = du.max((c.u_s_mm[k] - o.u_s_mm[k]).abs());
            }
        }
        println!(
            "{}: max |da| {da:.2e} mm, max |du_s| {du:.2e} mm, {dn} curves of different length",
            axis.file_name()
        );
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
    use host::diagnosis::model::Model;
    use host::diagnosis::noise_model::{LUT_ERROR_SCALE, table_error_knots};
    let t = read_effect_table(&tables_dir().join(EffectAxis::Thickness.file_name()))
        .expect("measurement setup");
    let lut = sub_table(&t.lut, &t.axis.select(t.axis.base_value())).expect("measurement setup");
    let model = Model::new(&lut, &[]).expect("measurement setup");
    let nodes = lut.grid.modulus_kpa.clone();
    let (mut sd, mut sl, mut lag, mut lag0) = (0.0, 0.0, 0.0, 0.0);
    let mut z2 = Vec::new();
    for k in 1..nodes.len() - 2 {
        let e = (nodes[k] * nodes[k + 1]).sqrt();
        for p in [6.0, 15.0] {
            let c = solve_curve(&truth_params(e, p)).expect("measurement setup");
            let Some((lo, hi)) = model.base.u_s_range_mm(e, p) else {
                continue;
            };
            let (knots, loo_rms) = table_error_knots(&model, e, p);
            let mut d = Vec::new();
            let (mut ed, mut el) = (0.0, 0.0);
            for q in c.points.iter().filter(|q| q.a_mm > 0.0) {
                if q.u_s_mm < lo || q.u_s_mm > hi {
                    continue;
                }
                let diff = q.a_mm - model.base.sample(e, p, q.u_s_mm).a_mm;
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
                if loo > 0.0 {
                    z2.push((diff / (LUT_ERROR_SCALE * loo)).powi(2));
                }
            }
            for w in d.windows(2) {
                lag += w[0] * w[1];
            }
            lag0 += ed;
            sd += ed;
            sl += el;
            println!(
                "E2 {e:7.2} p {p:4.1}: truth-table RMS {:.4} mm, LOO RMS {:.4} mm, ratio {:.2} ({} steps)",
                (ed / d.len().max(1) as f64).sqrt(),
                (el / d.len().max(1) as f64).sqrt(),
                (ed / el.max(1e-30)).sqrt(),
                d.len()
            );
        }
    }
    z2.sort_by(f64::total_cmp);
    println!(
        "overall: RMS ratio truth-table / LOO = {:.3} (LUT_ERROR_SCALE {LUT_ERROR_SCALE}); lag-1 correlation of truth-table {:.2}; \
         mean (diff / (scale LOO))^2 = {:.2}, median {:.2} over {} steps",
        (sd / sl).sqrt(),
        lag / lag0,
        z2.iter().sum::<f64>() / z2.len() as f64,
        z2[z2.len() / 2],
        z2.len()
    );
}

/// The pressure-offset candidate reads the baseline at p_air - p0, continued linearly from
/// the table's pressures: this compares direct solves at 4.5 and 13.5 kPa (a 1.5 kPa offset
/// of the 6 and 15 kPa set points) with that continuation, next to the effect itself
/// (a at the set point).
#[test]
#[ignore = "measurement (fem-core solves); run with --release -- --ignored --nocapture"]
fn pressure_continuation_error() {
    let t = read_effect_table(&tables_dir().join(EffectAxis::Thickness.file_name()))
        .expect("measurement setup");
    let lut = sub_table(&t.lut, &t.axis.select(t.axis.base_value())).expect("measurement setup");
    let base =
        Surface::new(&lut, &fem_core::lut::EffectSelection::default()).expect("measurement setup");
    for e in [146.8, 170.0] {
        for (p_set, p_true) in [(6.0, 4.5), (15.0, 13.5), (6.0, 5.5), (15.0, 14.5)] {
            let c = match solve_curve(&truth_params(e, p_true)) {
                Ok(c) => c,
                Err(err) => {
                    println!("E2 {e} p_true {p_true}: solve failed: {err}");
                    continue;
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
            println!(
                "E2 {e} p_true {p_true} (set {p_set}): RMS truth - continuation {:.4} mm, RMS effect (truth - set point) {:.4} mm",
                (s_err / n as f64).sqrt(),
                (s_eff / n as f64).sqrt()
            );
        }
    }
}
