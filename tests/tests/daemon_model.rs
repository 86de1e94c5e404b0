//! The daemon with a setup's model file (`tactile daemon --model`, written by `tactile
//! diagnose --apply`): the simulated bench's camera reads radii 4 % large (an effect its
//! calibration with reference discs does not see, as a lens focused on another plane
//! would); with the model's `radius_scale` the daemon's fit recovers the sample's modulus,
//! and the record keeps the model. The same record's curve fitted without the model shows
//! the bias the model removes.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use std::time::Duration;

use daemon::Client;
use daemon::api::{ExperimentRequest, JobState};
use diagnosis::applied::{AppliedEffect, DiagnosisSource, ModelFile};
use fit::{FitOptions, LutModel, fit_modulus, points_from_curve_csv};
use system_tests::{temp_dir, wait_job};

#[test]
fn a_model_files_camera_scale_corrects_the_daemons_modulus() {
    let dir = temp_dir("daemon-model");
    let mut scenario = daemon::jobs::default_sim_scenario(&daemon::sim::sim_lut());
    let truth_kpa = scenario.sample.modulus_kpa;
    // calibrated on the bench as it is (the reference discs do not see the scale)
    let calibrations = dir.join("records/calibrations");
    std::fs::create_dir_all(&calibrations).unwrap();
    daemon::jobs::calibrate_sim(&scenario, &calibrations).unwrap();
    scenario.effects.camera_radius_scale = 1.04;
    let model = dir.join("setup-model.json");
    ModelFile::new(
        vec![AppliedEffect {
            effect: "radius_scale".into(),
            parameter: "radius_scale_minus_1".into(),
            value: 0.04,
            se: Some(0.002),
        }],
        &[],
        DiagnosisSource {
            inputs: vec!["(written by the test)".into()],
            baseline: "the production table".into(),
            modulus_before_kpa: None,
            modulus_after_kpa: None,
        },
    )
    .unwrap()
    .write(&model)
    .unwrap();
    let token_file = dir.join("token");
    let handle = daemon::sim::start_sim_daemon_with_model(
        Some(scenario),
        std::net::SocketAddr::from(([127, 0, 0, 1], 0)),
        &dir.join("records"),
        &token_file,
        200,
        &model,
    )
    .unwrap();
    let client = Client::from_token_file(&handle.addr.to_string(), &token_file).unwrap();
    let t0 = std::time::Instant::now();
    while !client.status().unwrap().connected {
        assert!(t0.elapsed() < Duration::from_secs(10), "never connected");
        std::thread::sleep(Duration::from_millis(50));
    }
    let job = client
        .submit(&ExperimentRequest {
            pressure_kpa: 6.0.into(),
            probe_pressure_kpa: None,
            start_mm: 0.8,
            depth_mm: 1.7,
            speed_mm_per_s: 2.0,
            repeats: 3,
            stream_rate_hz: 2000,
            label: "model test".into(),
        })
        .unwrap();
    let done = wait_job(&client, job.id, Duration::from_secs(90));
    assert_eq!(done.state, JobState::Complete, "{done:?}");
    let with_model = done.fit.expect("final fit").modulus_kpa;
    let record = dir.join("records").join(done.record.unwrap());
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(record.join("meta.json")).unwrap()).unwrap();
    assert_eq!(
        meta["lut"]["model"]["effects"][0]["effect"], "radius_scale",
        "{meta:#}"
    );
    assert_eq!(
        meta["lut"]["model"]["sha256"].as_str().map(str::len),
        Some(64)
    );
    // The same points against the table alone.
    let curve = fit::curve_csv::read_curve_csv(&record.join("curve.csv")).unwrap();
    let points = points_from_curve_csv(&curve, "curve.csv").unwrap();
    let lut = fem_core::lut::read_lut(&daemon::sim::shipped_lut())
        .unwrap()
        .lut;
    let plain = fit_modulus(
        &LutModel::new(&lut).unwrap(),
        &points,
        FitOptions::default(),
    )
    .unwrap()
    .modulus_kpa;
    println!("true {truth_kpa} kPa: with the model {with_model:.1}, without {plain:.1}");
    handle.shutdown();
    // With the model the daemon's own accuracy remains (about 1 % at 200 kPa, results.md),
    // plus the run's scatter: 3 %. Without it a 4 % radius reads as a much softer sample.
    assert!(
        (with_model / truth_kpa - 1.0).abs() < 0.03,
        "with the model {with_model} kPa"
    );
    assert!(
        (plain / truth_kpa - 1.0).abs() > 0.1,
        "without the model {plain} kPa"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
