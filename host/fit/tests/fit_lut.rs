//! The modulus fit against a real finite-element table (`tests/data/fit_fixture.lut`,
//! fem-core at mesh level -1; rebuild with the ignored test in `fixture_build.rs`):
//! - direct fem-core solves at off-grid moduli (so the table's interpolation bias is part
//!   of the error) are recovered within 1.5 %;
//! - noisy replicates drawn from the table at off-grid moduli: the estimate is unbiased and
//!   the 95 % interval covers the truth at close to its nominal rate;
//! - joint fits across pressures, the load channel and the pressure recommendation.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use fem_core::lut::{Lut, read_lut};
use fit::curve_csv::read_curve_csv;
use fit::{
    FitError, FitOptions, FitPoint, LutModel, fit_modulus, points_from_curve_csv,
    recommend_pressure,
};
use std::path::PathBuf;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn lut() -> Lut {
    read_lut(&data("fit_fixture.lut")).unwrap().lut
}

/// splitmix64 + Box–Muller: seeded standard normal deviates.
struct Normal(u64);
impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn next(&mut self) -> f64 {
        let (u1, u2) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// `tests` replicates of `n` points each, uniform in u_s over 5..95 % of the table's range
/// at (E2, p), a from the table plus N(0, sigma) noise; loads with 1 % noise.
fn synthetic(
    model: &LutModel,
    e: f64,
    p: f64,
    n: usize,
    tests: u32,
    sigma: f64,
    rng: &mut Normal,
) -> Vec<FitPoint> {
    let (lo, hi) = model.u_s_range_mm(e, p).unwrap();
    let (lo, hi) = (lo.max(0.0) + 0.05 * (hi - lo), hi - 0.05 * (hi - lo));
    let mut out = Vec::new();
    for t in 0..tests {
        for k in 0..n {
            let u = lo + (hi - lo) * (k as f64 + 0.5) / n as f64;
            let s = model.sample(e, p, u).unwrap();
            out.push(FitPoint {
                u_s_mm: u,
                a_mm: s.a_mm + sigma * rng.next(),
                p_air_kpa: p,
                test: t,
                load_n: Some(s.load_n * (1.0 + 0.01 * rng.next())),
            });
        }
    }
    out
}

#[test]
fn direct_fem_solves_at_off_grid_moduli_are_recovered() {
    let lut = lut();
    let model = LutModel::new(&lut).unwrap();
    for (e, p) in [
        (25.0, 6.0),
        (60.0, 6.0),
        (120.0, 6.0),
        (200.0, 6.0),
        (350.0, 6.0),
        (800.0, 6.0),
        (200.0, 15.0),
        (600.0, 15.0),
    ] {
        let path = data(&format!("fem_truth_E{e}_p{p}.csv"));
        let csv = read_curve_csv(&path).unwrap();
        let points = points_from_curve_csv(&csv, "truth").unwrap();
        let fit = fit_modulus(&model, &points, FitOptions::default()).unwrap();
        let err = fit.modulus_kpa / e - 1.0;
        eprintln!(
            "E {e} p {p}: fit {:.2} kPa ({:+.2} %), CI {:.2}..{:.2}, rms {:.5} mm, {} points",
            fit.modulus_kpa,
            100.0 * err,
            fit.ci95_kpa[0],
            fit.ci95_kpa[1],
            fit.rms_residual_mm,
            fit.points_used
        );
        // The only error source is the table's interpolation between nodes 47 % apart in
        // E2 (PCHIP in ln E2) and along 40 load steps in u_s (fixture: mesh level -1):
        // measured |error| <= 0.09 % up to 600 kPa and +0.36 % at 800 kPa, 6 kPa (beyond
        // the paper's working range for that pressure, where a barely depends on E2), so
        // 1.5 % leaves margin without hiding a broken interpolation (nearest-node would be
        // up to ~20 %); the interval (residual and table-interpolation terms) must cover.
        assert!(err.abs() < 0.015, "E {e} p {p}: {err}");
        assert!(fit.ci95_kpa[0] <= e && e <= fit.ci95_kpa[1], "{fit:?}");
        assert!(fit.ci95_kpa[0] <= fit.modulus_kpa && fit.modulus_kpa <= fit.ci95_kpa[1]);
    }
}

#[test]
fn noisy_replicates_are_unbiased_and_the_interval_covers_the_truth() {
    let lut = lut();
    let model = LutModel::new(&lut).unwrap();
    let mut rng = Normal(2024);
    let trials = 60;
    for &(e, p) in &[(37.0, 6.0), (180.0, 6.0), (420.0, 15.0)] {
        let mut covered = 0;
        let mut log_err_sum = 0.0;
        let mut widths = Vec::new();
        for _ in 0..trials {
            // 5 replicates x 40 frames, camera noise 0.01 mm (0.5 px at 50 px/mm)
            let pts = synthetic(&model, e, p, 40, 5, 0.01, &mut rng);
            let fit = fit_modulus(&model, &pts, FitOptions::default()).unwrap();
            log_err_sum += (fit.modulus_kpa / e).ln();
            if fit.ci95_kpa[0] <= e && e <= fit.ci95_kpa[1] {
                covered += 1;
            }
            widths.push((fit.ci95_kpa[1] - fit.ci95_kpa[0]) / e);
            assert_eq!(fit.replicate_moduli_kpa.len(), 5);
        }
        let bias = log_err_sum / trials as f64;
        let mean_width = widths.iter().sum::<f64>() / trials as f64;
        eprintln!(
            "E {e} p {p}: coverage {covered}/{trials}, mean bias {:+.3} %, mean CI width {:.2} %",
            100.0 * bias,
            100.0 * mean_width
        );
        // Nominal 95 %: with 60 trials a correct interval covers >= 52 times with
        // probability > 0.99 (binomial), so 52 is the threshold.
        assert!(covered >= 52, "coverage {covered}/{trials}");
        // Bias: the mean of 60 estimates has a standard error of (width/4)/sqrt(60); allow
        // 4 of those.
        assert!(
            bias.abs() < mean_width / 4.0 / (trials as f64).sqrt() * 4.0 + 1e-4,
            "bias {bias}"
        );
    }
}

#[test]
fn joint_fit_across_pressures_and_the_load_channel() {
    let lut = lut();
    let model = LutModel::new(&lut).unwrap();
    let mut rng = Normal(7);
    let e = 150.0;
    let mut pts = synthetic(&model, e, 6.0, 50, 1, 0.01, &mut rng);
    pts.extend(synthetic(&model, e, 15.0, 50, 1, 0.01, &mut rng));
    let fit = fit_modulus(&model, &pts, FitOptions::default()).unwrap();
    assert_eq!(fit.pressures_kpa, vec![6.0, 15.0]);
    assert_eq!(fit.per_pressure.len(), 2);
    // 100 points with 0.01 mm noise: the interval is a few percent wide; the estimate is
    // inside it and within 3 % of the truth.
    assert!((fit.modulus_kpa / e - 1.0).abs() < 0.03, "{fit:?}");
    for pf in &fit.per_pressure {
        assert!((pf.modulus_kpa / e - 1.0).abs() < 0.06, "{pf:?}");
    }
    let with_load = fit_modulus(
        &model,
        &pts,
        FitOptions {
            use_load: true,
            ..FitOptions::default()
        },
    )
    .unwrap();
    assert!(with_load.load_channel_used);
    assert!(with_load.rms_residual_load_n.unwrap() > 0.0);
    // loads carry independent information: the interval does not get wider
    assert!(
        (with_load.modulus_kpa / e - 1.0).abs() < 0.03,
        "{with_load:?}"
    );
    let w = |f: &fit::ModulusFit| f.ci95_kpa[1] - f.ci95_kpa[0];
    assert!(
        w(&with_load) <= w(&fit) * 1.05,
        "{} vs {}",
        w(&with_load),
        w(&fit)
    );
}

#[test]
fn predicted_sensitivity_matches_the_scatter_of_fits() {
    let lut = lut();
    let model = LutModel::new(&lut).unwrap();
    let e = 200.0;
    let sigma = 0.01;
    let n = 100;
    let (sens, best) = recommend_pressure(&model, e, sigma, 1.0);
    let best = best.unwrap();
    assert!(
        sens.iter()
            .all(|s| s.predicted_relative_se >= sens[best].predicted_relative_se)
    );
    let mut rng = Normal(99);
    for s in &sens {
        let (lo, hi) = model.u_s_range_mm(e, s.p_air_kpa).unwrap();
        let span = 0.9 * (hi - lo.max(0.0));
        let per_mm = n as f64 / span;
        let predicted = s.predicted_relative_se / per_mm.sqrt();
        let mut logs = Vec::new();
        for _ in 0..40 {
            let pts = synthetic(&model, e, s.p_air_kpa, n, 1, sigma, &mut rng);
            logs.push(
                fit_modulus(&model, &pts, FitOptions::default())
                    .unwrap()
                    .modulus_kpa
                    .ln(),
            );
        }
        let m = logs.iter().sum::<f64>() / logs.len() as f64;
        let sd =
            (logs.iter().map(|l| (l - m).powi(2)).sum::<f64>() / (logs.len() - 1) as f64).sqrt();
        eprintln!(
            "p {} kPa: predicted relative SE {:.4}, observed {:.4}",
            s.p_air_kpa, predicted, sd
        );
        // 40 trials estimate an SD within about +-25 % (chi-square, 95 %); the prediction
        // integrates over the whole covered range while the trials use 90 % of it: a
        // factor of 1.6 either way separates a right formula from a wrong one.
        assert!(
            sd / predicted < 1.6 && predicted / sd < 1.6,
            "p {}: {sd} vs {predicted}",
            s.p_air_kpa
        );
    }
}

#[test]
fn a_sample_beyond_the_table_is_refused_not_clamped() {
    // Radii 3 % below the stiffest curve's: a sample stiffer than the table covers. The
    // least-squares optimum lies beyond the last node, so an estimate there would only be
    // the clamp; the fit says which limit it hit instead.
    let lut = lut();
    let model = LutModel::new(&lut).unwrap();
    let top = *lut.grid.modulus_kpa.last().unwrap();
    let mut rng = Normal(11);
    let mut points = synthetic(&model, top, 6.0, 40, 3, 0.002, &mut rng);
    for p in &mut points {
        p.a_mm *= 0.97;
    }
    match fit_modulus(&model, &points, FitOptions::default()) {
        Err(FitError::AtTableLimit { upper, limit_kpa }) => {
            assert!(upper);
            assert!((limit_kpa / top - 1.0).abs() < 1e-9, "{limit_kpa}");
        }
        other => panic!("expected the upper-limit refusal, got {other:?}"),
    }
}
