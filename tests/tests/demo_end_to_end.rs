//! `tactile demo`'s pipeline end to end against hil-sim over a PTY (calibrate, measure,
//! fit, record). Each run takes ~10-25 s of real time (the bench runs in real time), so
//! these are ignored by default; run them in release:
//!
//! `cargo test -p system-tests --release --test demo_end_to_end -- --ignored --nocapture --test-threads=1`
//!
//! One at a time: each run is two real-time benches plus fem-core solves; run in parallel
//! on the shared 2-core machine (load average ~9) the simulated controller latched a fault
//! during the rigid sweep in both of two runs; one at a time, once in ~15 runs (with a
//! benchmark compiling alongside). Which fault is now named in the error.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use experiment::pipeline::RunError;
use experiment::simulated::{DemoError, DemoOptions, demo_scenario, run_demo_with};
use std::path::PathBuf;

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("tactile-e2e-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn options(name: &str, modulus: f64, repeats: u32) -> DemoOptions {
    DemoOptions {
        modulus_kpa: modulus,
        pressure_kpa: 6.0,
        seed: 3,
        scenario: None,
        out: Some(out_dir(name)),
        lut: None,
        repeats,
        progress: false,
        u_s_equals_h: false,
        firmware: None,
        finer_truth: false,
    }
}

/// Off-grid moduli between 20 and 400 kPa (the fit table's nodes are 6 per decade:
/// ..., 21.5, 31.6, 46.4, 68.1, 100, 146.8, 215.4, 316.2, 464.2, ...), each measured at a
/// pressure where a responds to E2 (6 kPa for soft, 15 kPa for the stiff one).
const DEMO_CASES: [(f64, f64); 5] = [
    (25.0, 6.0),
    (60.0, 6.0),
    (120.0, 6.0),
    (200.0, 6.0),
    (350.0, 15.0),
];

/// Runs the demo at every case: (modulus, estimate, interval).
fn demo_cases() -> Vec<(f64, f64, [f64; 2])> {
    DEMO_CASES
        .iter()
        .map(|&(modulus, pressure)| {
            let mut opts = options(&format!("e{modulus}"), modulus, 5);
            opts.pressure_kpa = pressure;
            let report = run_demo_with(demo_scenario(modulus, pressure, 3), &opts).unwrap();
            eprintln!(
                "E2 {modulus} kPa at {pressure} kPa: fit {:.2} kPa ({:+.2} %) [{:.2}, {:.2}], rms {:.4} mm, {} points, {:.1} s",
                report.modulus_kpa,
                100.0 * (report.modulus_kpa / modulus - 1.0),
                report.ci95_kpa[0],
                report.ci95_kpa[1],
                report.rms_residual_mm,
                report.points,
                report.elapsed_s
            );
            (modulus, report.modulus_kpa, report.ci95_kpa)
        })
        .collect()
}

/// The demo recovers the modulus within 2 %. The truth is a direct fem-core solve at the
/// true modulus on a mesh finer than the production table the fit uses, so the model's
/// discretisation error, the table's interpolation and the measurement are all in it
/// (measured: -0.1 .. +0.8 % over these cases, docs/results.md).
#[test]
#[ignore = "real-time hil-sim runs (~20 s each); release"]
fn demo_recovers_the_modulus_within_2_percent() {
    let failures: Vec<String> = demo_cases()
        .into_iter()
        .filter(|(modulus, estimate, _)| (estimate / modulus - 1.0).abs() >= 0.02)
        .map(|(modulus, estimate, _)| {
            format!(
                "E2 {modulus}: error {:+.2} %",
                100.0 * (estimate / modulus - 1.0)
            )
        })
        .collect();
    assert!(failures.is_empty(), "{failures:?}");
}

/// The 95 % interval covers the truth. Noise and the table's interpolation alone do not
/// cover it (at 200 kPa: +0.75 %, interval 200.03 .. 202.97 without the term): the
/// interval needs the model's discretisation term (`fit::discretisation`).
#[test]
#[ignore = "real-time hil-sim runs (~20 s each); release"]
fn the_interval_covers_the_truth() {
    let failures: Vec<String> = demo_cases()
        .into_iter()
        .filter(|(modulus, _, ci)| !(ci[0] <= *modulus && *modulus <= ci[1]))
        .map(|(modulus, _, ci)| {
            format!(
                "E2 {modulus}: interval [{:.2}, {:.2}] misses the truth",
                ci[0], ci[1]
            )
        })
        .collect();
    assert!(failures.is_empty(), "{failures:?}");
}

#[test]
#[ignore = "real-time hil-sim run (~25 s); release"]
fn corrupted_bytes_complete_with_the_loss_counted() {
    let mut scenario = demo_scenario(200.0, 6.0, 4);
    scenario.faults.byte_corruption_rate = 2e-5;
    let report = run_demo_with(scenario, &options("corrupt", 200.0, 2)).unwrap();
    eprintln!("{:?}", report.link);
    assert!(report.link.frame_errors > 0, "{:?}", report.link);
    assert!(report.link.blocks_lost > 0, "{:?}", report.link);
    let dir = PathBuf::from(&report.record_dir);
    for f in [
        "meta.json",
        "samples.csv",
        "frames.csv",
        "curve.csv",
        "fit.json",
    ] {
        assert!(dir.join(f).exists(), "{f}");
    }
}

#[test]
#[ignore = "real-time hil-sim run (~20 s); release"]
fn unplug_leaves_a_readable_partial_record() {
    let mut scenario = demo_scenario(200.0, 6.0, 5);
    // hil-sim's clock: the measurement bench runs fast until the host speaks, then in real
    // time; 4 s after start is during the indentations.
    scenario.faults.disconnect = Some(hil_sim::faults::Disconnect {
        at_s: 4.0,
        duration_s: None,
    });
    let opts = options("unplug", 200.0, 5);
    let err = run_demo_with(scenario, &opts).unwrap_err();
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(
        matches!(
            err,
            DemoError::Run(RunError::Experiment(_) | RunError::Link(_)) | DemoError::Link(_)
        ),
        "{msg}"
    );
    let dir = opts.out.unwrap();
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).unwrap()).unwrap();
    assert!(
        meta["status"].as_str().unwrap().starts_with("failed"),
        "{meta}"
    );
    let samples = std::fs::read_to_string(dir.join("samples.csv")).unwrap();
    assert!(
        samples.lines().count() > 100,
        "{} lines",
        samples.lines().count()
    );
    // every line complete (8 fields): nothing half-written
    assert!(samples.lines().all(|l| l.split(',').count() == 8));
}
