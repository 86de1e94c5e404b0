//! The daemon's automatic pressure choice (`"pressure_kpa": "auto"`) on the simulated bench:
//! a soft and a stiff sample are each probed at 6 kPa and measured at the calibrated
//! pressure the table predicts best for them; the stiff one at a higher pressure. The job,
//! the live curve and the record keep the choice (probe pressure and modulus, chosen
//! pressure, predicted error, candidates) and the estimate is near the simulated modulus.
//! Also the request's new fields over HTTP: per-field validation messages.
//!
//! The calibration is made once by the daemon's own simulated-bench routine (proximity at
//! 6, 10 and 15 kPa). Experiments run in real time: each job is a one-indentation probe and
//! a two-indentation measurement.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use daemon::api::{ExperimentRequest, Job, JobState, PressureSetting};
use daemon::{Client, DaemonHandle};
use experiment::record_meta::{RecordMeta, RecordStatus};
use system_tests::{temp_dir, wait_job};

fn shared_calibration() -> &'static Path {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let dir = temp_dir("daemon-auto-calibration");
        let scenario = daemon::jobs::default_sim_scenario(&daemon::sim::sim_lut());
        daemon::jobs::calibrate_sim(&scenario, &dir).unwrap();
        dir
    })
}

/// A calibrated daemon on a simulated bench whose sample has `modulus_kpa` (the mechanics
/// read from the fine table, the fit from the production one, as `tactile daemon --sim`).
fn bench(name: &str, modulus_kpa: f64) -> (DaemonHandle, Client, PathBuf) {
    let dir = temp_dir(name);
    let calibrations = dir.join("records/calibrations");
    std::fs::create_dir_all(&calibrations).unwrap();
    for f in std::fs::read_dir(shared_calibration()).unwrap() {
        let f = f.unwrap();
        std::fs::copy(f.path(), calibrations.join(f.file_name())).unwrap();
    }
    let mut scenario = daemon::jobs::default_sim_scenario(&daemon::sim::sim_lut());
    scenario.sample.modulus_kpa = modulus_kpa;
    let token_file = dir.join("token");
    let daemon = daemon::sim::start_sim_daemon(
        Some(scenario),
        std::net::SocketAddr::from(([127, 0, 0, 1], 0)),
        &dir.join("records"),
        &token_file,
        2000,
    )
    .unwrap();
    let client = Client::from_token_file(&daemon.addr.to_string(), &token_file).unwrap();
    let t0 = Instant::now();
    while !client.status().unwrap().connected {
        assert!(t0.elapsed() < Duration::from_secs(10), "never connected");
        std::thread::sleep(Duration::from_millis(50));
    }
    (daemon, client, dir)
}

/// An automatic-pressure experiment: the default probe, two indentations of 1.2 mm.
fn auto_request(label: String) -> ExperimentRequest {
    ExperimentRequest {
        pressure_kpa: PressureSetting::Auto,
        probe_pressure_kpa: None,
        start_mm: 0.8,
        depth_mm: 1.2,
        speed_mm_per_s: 2.0,
        repeats: 2,
        stream_rate_hz: 2000,
        label,
    }
}

/// What one automatic-pressure job on a sample of `modulus_kpa` gave.
struct AutoRun {
    chosen_kpa: f64,
    modulus_kpa: f64,
}

fn auto_run(name: &str, modulus_kpa: f64) -> AutoRun {
    let (daemon, client, dir) = bench(name, modulus_kpa);
    let request = auto_request(format!("auto, {modulus_kpa} kPa sample"));
    let job = client.submit(&request).unwrap();
    assert_eq!(job.experiment.as_ref(), Some(&request));
    let done = wait_job(&client, job.id, Duration::from_secs(120));
    assert_eq!(done.state, JobState::Complete, "{done:?}");
    let choice = done
        .pressure_choice
        .clone()
        .expect("the job keeps the choice");
    let fit = done.fit.expect("final fit");
    eprintln!(
        "{modulus_kpa} kPa sample: probe at {} kPa read {:.1} kPa [{:.1}, {:.1}]; chosen {} kPa \
         (predicted {:.2} %); E2 = {:.1} kPa [{:.1}, {:.1}], {} points; candidates {:?}",
        choice.probe_kpa,
        choice.probe_modulus_kpa,
        choice.probe_ci95_kpa[0],
        choice.probe_ci95_kpa[1],
        choice.chosen_kpa,
        100.0 * choice.predicted_relative_se,
        fit.modulus_kpa,
        fit.ci95_kpa[0],
        fit.ci95_kpa[1],
        fit.points,
        choice.candidates
    );
    // The probe ran at the default probe pressure; the choice is one of the calibrated table
    // pressures, the best predicted of them.
    assert_eq!(choice.probe_kpa, daemon::api::DEFAULT_PROBE_KPA);
    let candidates: Vec<f64> = choice.candidates.iter().map(|c| c.p_air_kpa).collect();
    assert_eq!(candidates, daemon::jobs::SIM_CALIBRATION_KPA, "{choice:?}");
    assert!(candidates.contains(&choice.chosen_kpa));
    assert!(
        choice
            .candidates
            .iter()
            .all(|c| c.predicted_relative_se >= choice.predicted_relative_se)
    );
    // The measurement, its final fit and the live curve are at the chosen pressure.
    assert_eq!(fit.p_air_kpa, choice.chosen_kpa);
    assert!(
        done.message.contains("chosen automatically"),
        "{}",
        done.message
    );
    let live: serde_json::Value =
        serde_json::from_str(&client.raw("GET", "/v1/live", None, &[], true).unwrap().body)
            .unwrap();
    assert_eq!(live["job"].as_u64(), Some(done.id));
    assert_eq!(live["pressure_kpa"].as_f64(), Some(choice.chosen_kpa));
    assert_eq!(live["fit"]["p_air_kpa"].as_f64(), Some(choice.chosen_kpa));
    assert_eq!(live["final_fit"].as_bool(), Some(true));
    // The record: the measurement at the chosen pressure, the probe inside it, the choice.
    let record_name = done.record.clone().unwrap();
    assert_eq!(choice.probe_record, format!("{record_name}/probe"));
    let record = dir.join("records").join(&record_name);
    let meta = RecordMeta::read(&record).unwrap();
    assert_eq!(meta.status, RecordStatus::Complete);
    assert_eq!(meta.plan.pressure_kpa, choice.chosen_kpa);
    assert_eq!(meta.plan.repeats, 2);
    let probe = RecordMeta::read(&record.join("probe")).unwrap();
    assert_eq!(probe.status, RecordStatus::Complete);
    assert_eq!(probe.plan.pressure_kpa, choice.probe_kpa);
    assert_eq!(probe.plan.repeats, experiment::pipeline::PROBE_REPEATS);
    assert!(record.join("probe/fit.json").exists());
    let stored: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(record.join(experiment::pipeline::PRESSURE_CHOICE_FILE)).unwrap(),
    )
    .unwrap();
    assert_eq!(stored["chosen_kpa"].as_f64(), Some(choice.chosen_kpa));
    assert_eq!(stored["probe_kpa"].as_f64(), Some(choice.probe_kpa));
    assert_eq!(
        stored["probe_modulus_kpa"].as_f64(),
        Some(choice.probe_modulus_kpa)
    );
    assert_eq!(
        stored["candidates"].as_array().map(Vec::len),
        Some(choice.candidates.len())
    );
    // The file is served like the record's other files, and the probe's record too.
    let get = |path: String| client.raw("GET", &path, None, &[], true).unwrap();
    let files = get(format!("/v1/records/{record_name}"));
    assert!(
        files.body.contains("pressure_choice.json"),
        "{}",
        files.body
    );
    let probe_files = get(format!("/v1/records/{record_name}/probe/"));
    assert!(
        probe_files.body.contains("fit.json"),
        "{}",
        probe_files.body
    );
    let probe_fit = get(format!("/v1/records/{record_name}/probe/fit.json"));
    let probe_fit: serde_json::Value = serde_json::from_str(&probe_fit.body).unwrap();
    assert_eq!(
        probe_fit["modulus_kpa"].as_f64(),
        Some(choice.probe_modulus_kpa)
    );
    daemon.shutdown();
    let _ = std::fs::remove_dir_all(&dir);
    AutoRun {
        chosen_kpa: choice.chosen_kpa,
        modulus_kpa: fit.modulus_kpa,
    }
}

/// A soft sample (a node of the tables' modulus axis): the table predicts its smallest error
/// at the lowest calibrated pressure, 6 kPa (0.0475 % vs 0.049 % at 10 kPa per unit point
/// density; every modulus from 10 to ~68 kPa prefers 6 kPa, so the probe's own error cannot
/// move the choice).
const SOFT_KPA: f64 = 46.42;
/// A stiff sample (the demo's stiff row): best at 15 kPa (0.12 % vs 0.16 % at 6 kPa at
/// 600-700 kPa; every modulus above ~100 kPa prefers 15 kPa). Not 1000 kPa: the production
/// table reads stiff samples slightly high and 1000 kPa is its upper limit.
const STIFF_KPA: f64 = 600.0;
/// The relative error allowed. The simulated sample is the converged table (the production
/// grid with the edge band) and the fit uses the production table (level 0), corrected to
/// the converged table: `docs/results.md` has the demo within a few tenths of a percent,
/// with 95 % intervals of ±0.8 to ±2 % from five indentations. Two indentations widen the
/// interval by sqrt(5/2) (to about ±2.9 % at 600 kPa), and the 600 kPa sample is between
/// the tables' 464 and 681 kPa nodes, so the bench interpolates its truth: 5 % covers the
/// bias plus the interval with a margin and still fails a measurement at the wrong
/// pressure's precision or with a wrong calibration (the 6 kPa parabola applied at 15 kPa
/// reads several percent off).
const TOLERANCE: f64 = 0.05;

#[test]
fn auto_pressure_measures_a_stiff_sample_at_a_higher_pressure_than_a_soft_one() {
    let (soft, stiff) = (SOFT_KPA, STIFF_KPA);
    let s = auto_run("daemon-auto-soft", soft);
    let h = auto_run("daemon-auto-stiff", stiff);
    assert!(
        h.chosen_kpa > s.chosen_kpa,
        "stiff at {} kPa, soft at {} kPa",
        h.chosen_kpa,
        s.chosen_kpa
    );
    for (truth, run) in [(soft, &s), (stiff, &h)] {
        let error = run.modulus_kpa / truth - 1.0;
        assert!(
            error.abs() < TOLERANCE,
            "{truth} kPa sample read {:.1} kPa ({:+.1} %)",
            run.modulus_kpa,
            100.0 * error
        );
    }
}

#[test]
fn the_automatic_choice_is_validated_per_field_over_http() {
    // No bench needed for validation: the default daemon refuses before queueing.
    let dir = temp_dir("daemon-auto-fields");
    let (daemon, token_file) = system_tests::start_test_daemon(&dir, 200);
    let client = Client::from_token_file(&daemon.addr.to_string(), &token_file).unwrap();
    let fields = |body: &str| {
        let r = client
            .raw("POST", "/v1/experiments", Some(body), &[], true)
            .unwrap();
        let e: daemon::api::ApiError = serde_json::from_str(&r.body)
            .unwrap_or_else(|e| panic!("{body}: not a JSON error ({e}): {}", r.body));
        (
            r.status,
            e.error,
            e.fields.into_iter().map(|f| f.field).collect::<Vec<_>>(),
        )
    };
    let (status, _, f) = fields(r#"{"pressure_kpa":"auto","probe_pressure_kpa":40}"#);
    assert_eq!((status, f), (422, vec!["probe_pressure_kpa".to_string()]));
    let (status, _, f) = fields(r#"{"pressure_kpa":6,"probe_pressure_kpa":6,"repeats":0}"#);
    assert_eq!(
        (status, f),
        (422, vec!["probe_pressure_kpa".into(), "repeats".into()])
    );
    // Not a number nor "auto": refused before validation, the message names the field.
    let (status, error, _) = fields(r#"{"pressure_kpa":"high"}"#);
    assert!(status == 422 && error.contains("pressure_kpa"), "{error}");
    let (status, error, _) = fields(r#"{"pressure_kpa":"auto","probe":6}"#);
    assert!(status == 422 && error.contains("probe"), "{error}");
    assert!(client.jobs().unwrap().is_empty());
    // Accepted, and answered as submitted.
    let r = client
        .raw(
            "POST",
            "/v1/experiments",
            Some(r#"{"pressure_kpa":"auto","probe_pressure_kpa":10,"repeats":1}"#),
            &[],
            true,
        )
        .unwrap();
    assert_eq!(r.status, 202, "{}", r.body);
    let job: Job = serde_json::from_str(&r.body).unwrap();
    let e = job.experiment.unwrap();
    assert_eq!(
        (e.pressure_kpa, e.probe_pressure_kpa),
        (PressureSetting::Auto, Some(10.0))
    );
    let _ = client.cancel(job.id);
    daemon.shutdown();
    let _ = std::fs::remove_dir_all(&dir);
}

/// An emergency stop during the probe: the job ends, and the experiment's own record says
/// so (the probe's metadata with the status `Failed` and a note pointing at `probe/`)
/// instead of being a folder without status.
#[test]
fn a_stop_during_the_probe_leaves_a_record_that_says_so() {
    let (daemon, client, dir) = bench("daemon-auto-stop", 200.0);
    let request = auto_request("auto, stopped in the probe".into());
    let job = client.submit(&request).unwrap();
    // wait until the probe is under way, then stop
    let t0 = Instant::now();
    loop {
        let j = client.job(job.id).unwrap();
        // the probe's indentation is under way (its message "probe at 6 kPa: indentation
        // 1/1"; progress only moves when an indentation ends)
        if j.pressure_choice.is_none()
            && j.message.contains("probe")
            && j.message.contains("indentation")
        {
            break;
        }
        assert!(!j.state.is_finished(), "finished before the stop: {j:?}");
        assert!(t0.elapsed() < Duration::from_secs(60), "no probe: {j:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
    client.stop().unwrap();
    let done = wait_job(&client, job.id, Duration::from_secs(60));
    assert_ne!(done.state, JobState::Complete, "{done:?}");
    assert!(done.pressure_choice.is_none(), "{done:?}");
    let record = dir.join("records").join(done.record.clone().unwrap());
    let meta = RecordMeta::read(&record).unwrap();
    assert!(
        matches!(&meta.status, RecordStatus::Failed(r) if r.contains("automatic pressure choice")),
        "{:?}",
        meta.status
    );
    assert!(
        meta.notes.iter().any(|n| n.contains("probe/")),
        "{:?}",
        meta.notes
    );
    assert!(record.join("probe/meta.json").exists());
    daemon.shutdown();
    let _ = std::fs::remove_dir_all(&dir);
}
