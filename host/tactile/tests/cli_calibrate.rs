//! `tactile calibrate` against hil-sim's emulated bench on a pseudo-terminal: the real
//! serial code path, the real firmware logic. The simulated sample is rigid (fem-core at
//! E2 = 1e7 kPa, mesh level -2), and hil-sim's proximity sensor is the parabola
//! U = A x^2 + B x + C in x = u_s - inflation apex (hil-sim/src/sensors.rs), so the
//! calibration's parabola in u_s is known exactly: A, B - 2 A d, A d^2 - B d + C with d the
//! apex inflation at the calibration pressure.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use experiment::calibration::CalibrationRecord;
use hil_sim::bench::{BenchOptions, start};
use hil_sim::mechanics_source::solve_curves;
use hil_sim::scenario::{MechanicsSource, Scenario};
use std::process::Command;

fn rigid_bench_scenario() -> Scenario {
    let mut s = Scenario {
        name: "cli-calibrate-rigid".into(),
        seed: 11,
        ..Scenario::default()
    };
    s.sample.modulus_kpa = experiment::calibration::RIGID_MODULUS_KPA;
    s.mechanics = MechanicsSource::Solve {
        pressures_kpa: vec![6.0],
        modulus_factors: vec![1.0],
        mesh_level: -2,
        steps: 40,
        max_depth_mm: 1.9,
        edge_band: false,
        finer_band: false,
    };
    s
}

fn tactile(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_tactile"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn calibrate_manometer_load_and_proximity_over_a_pty() {
    let scenario = rigid_bench_scenario();
    // the apex inflation d of the simulated shell at 6 kPa
    let d = solve_curves(&scenario).unwrap()[0].inflation_apex_mm;
    let prox = scenario.proximity.clone();
    let surface = scenario.stage.surface_mm;
    let bench = start(scenario, BenchOptions::default()).unwrap();
    let port = bench.pty_path().display().to_string();
    let dir = std::env::temp_dir().join(format!("tactile-cli-cal-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let dir_s = dir.display().to_string();

    let (ok, out, err) = tactile(&["calibrate", "--dir", &dir_s, "manometer", "--port", &port]);
    assert!(ok, "{out}{err}");
    assert!(out.contains("manometer zero"), "{out}");
    let (ok, out, err) = tactile(&["calibrate", "--dir", &dir_s, "load", "--port", &port]);
    assert!(ok, "{out}{err}");
    let start_mm = format!("{}", surface - 0.3);
    let end_mm = format!("{}", surface + 1.2);
    let (ok, out, err) = tactile(&[
        "calibrate",
        "--dir",
        &dir_s,
        "--json",
        "proximity",
        "--port",
        &port,
        "--pressure",
        "6",
        "--start",
        &start_mm,
        "--end",
        &end_mm,
        "--speed",
        "1",
        "--mesh-level",
        "-2",
    ]);
    assert!(ok, "{out}{err}");
    drop(bench);
    let record: CalibrationRecord = serde_json::from_str(out.trim()).unwrap();
    // every calibration of this run is in the newest record on disk
    let (_, latest) = experiment::calibration::load_latest(&dir).unwrap();
    assert_eq!(latest, record);
    // The manometer's zero: hil-sim's sensor has no offset by default; its noise is
    // 0.02 kPa rms, averaged over ~1000 samples, and the 16-bit count is 0.001 kPa.
    assert!(record.manometer_zero_kpa.abs() < 0.01, "{record:?}");
    // Tare residual: 80 SPS for 0.5 s of HX711 noise around zero.
    assert!(record.load_tare_residual_n.abs() < 0.002, "{record:?}");
    let cal = record.proximity_at(6.0).unwrap();
    let sweep = &record.proximity_sweeps[0];
    let (a, b, c) = (prox.a_v_per_mm2, prox.b_v_per_mm, prox.c_v);
    let truth = |u: f64| {
        let x = u - d;
        a * x * x + b * x + c
    };
    // Read back every true u_s in the calibrated range: the corrected calibration is
    // within 3 µm (ADC noise of 2 mV / 0.8 V/mm = 2.5 µm per sample, averaged by the fit;
    // the contact found to the 1 µm step of the hinge search).
    let mut worst_corrected: f64 = 0.0;
    let mut worst_paper: f64 = 0.0;
    for k in 1..=20 {
        let u = 0.05 * f64::from(k);
        let v = truth(u);
        worst_corrected = worst_corrected.max((cal.u_s_mm(v).unwrap() - u).abs());
        worst_paper =
            worst_paper.max((sweep.calibration_u_s_equals_h.u_s_mm(v).unwrap() - u).abs());
    }
    eprintln!(
        "corrected calibration worst u_s error {:.2} µm, u_s = h calibration {:.2} µm, reported difference {:.2} µm",
        worst_corrected * 1e3,
        worst_paper * 1e3,
        sweep.u_s_difference_max_mm * 1e3
    );
    assert!(worst_corrected < 0.003, "{worst_corrected}");
    // The paper's u_s = h is off by the shell's own compression (fem-core: ~20 µm at
    // 1 mm): the correction must matter and be reported.
    assert!(worst_paper > 0.010, "{worst_paper}");
    assert!(sweep.u_s_difference_max_mm > 0.010);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_calibrate_arguments_exit_with_code_2() {
    let out = Command::new(env!("CARGO_BIN_EXE_tactile"))
        .args([
            "calibrate",
            "camera",
            "--reference",
            "/nonexistent/ref.png",
            "--disc",
            "x.png:2",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/ref.png"), "{err}");
}
