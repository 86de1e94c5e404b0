//! `tactile diagnose` as a user runs it: bad input named, the documented JSON object, the
//! `unexplained` verdict, and the assumed noise model without replicates. The data are
//! generated from the shipped effect tables with known noise (no FE solve), written as
//! curve CSV files.

use std::path::{Path, PathBuf};
use std::process::Command;

use diagnosis::candidates::{Candidate, EffectKind};
use diagnosis::model::Model;
use diagnosis::tables::shipped_tables;
use testkit::synthetic_curves::{SyntheticSpec, generate};

fn tactile() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tactile"))
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "tactile-diagnose-cli-{}-{name}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// Curves at 6 and 15 kPa from the base table at 170 kPa with `effect` (a candidate at
/// theta) and `extra(u_s)` added to a; `replicates` per pressure; white noise 4 um on a,
/// 1 mN on the load, per-test offsets 2 um and 1 mN.
fn write_curves(
    path: &Path,
    effect: Option<(EffectKind, f64)>,
    extra: impl Fn(f64) -> f64,
    replicates: u32,
    seed: u64,
) {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    let cand = effect.map(|(kind, _)| Candidate {
        kind,
        tau_h_mm: None,
    });
    let truth = cand.as_ref().zip(effect.map(|e| e.1));
    let spec = SyntheticSpec {
        replicates,
        points_per_test: 45,
        u_s_range_mm: (0.1, 1.2),
        seed,
        ..SyntheticSpec::default()
    };
    let points = generate(&model, truth, extra, &spec);
    let text = diagnosis::simulate::to_curve_csv(&points, "diagnose_cli test").expect("csv");
    std::fs::write(path, text).expect("write csv");
}

/// Runs the diagnosis with `--json --out <file's dir>/out`.
fn diagnose_json(file: &Path) -> serde_json::Value {
    diagnose_json_with(file, &[])
}

/// [`diagnose_json`] with more arguments.
fn diagnose_json_with(file: &Path, more: &[&std::ffi::OsStr]) -> serde_json::Value {
    let out_dir = file.with_file_name("out");
    let out = tactile()
        .args(["diagnose", "--json", "--bootstrap", "100", "--reruns", "3"])
        .arg(file)
        .arg("--out")
        .arg(&out_dir)
        .args(more)
        .output()
        .expect("run tactile");
    assert!(
        out.status.success(),
        "tactile diagnose failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON object on stdout")
}

#[test]
fn a_missing_file_and_a_curve_without_pressure_are_named() {
    let out = tactile()
        .args(["diagnose", "/nonexistent/curve.csv"])
        .output()
        .expect("run tactile");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/curve.csv"), "{err}");

    let dir = scratch("nopressure");
    let file = dir.join("no-pressure.csv");
    std::fs::write(&file, "u_s_mm,a_mm\n0.1,0.5\n0.2,0.7\n0.3,0.9\n").expect("write");
    let out = tactile().arg("diagnose").arg(&file).output().expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no-pressure.csv") && err.contains("p_air_kpa"),
        "{err}"
    );
}

#[test]
fn a_bad_table_build_request_is_refused_before_any_solve() {
    let dir = scratch("build-tables");
    for (args, named) in [
        (vec!["--shard", "3/2"], "--shard"),
        (vec!["--shard", "one"], "--shard"),
        (vec!["--only", "thikness"], "thikness"),
    ] {
        let out = tactile()
            .arg("diagnose")
            .arg("--build-tables")
            .arg(&dir)
            .args(&args)
            .output()
            .expect("run tactile");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(named), "{args:?}: {err}");
        // nothing written
        assert_eq!(std::fs::read_dir(&dir).expect("dir").count(), 0, "{args:?}");
    }
}

/// `--anderson` reaches the effect tables' solver and is recorded in their description.
/// A shard past the last curve (index % 10000 == 9999: none of the few hundred) builds
/// the table's header without any solve, so the flag's wiring is checked in no time; the
/// mixed curves themselves are checked against plain ones in fem-core's tests.
#[test]
fn anderson_mixing_is_recorded_in_the_built_effect_tables() {
    let description = |anderson: bool| {
        let dir = scratch(if anderson { "mixed" } else { "plain" });
        let mut cmd = tactile();
        cmd.arg("diagnose").arg("--build-tables").arg(&dir).args([
            "--only",
            "stiffening",
            "--shard",
            "9999/10000",
        ]);
        if anderson {
            cmd.arg("--anderson");
        }
        let out = cmd.output().expect("run tactile");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let file = fem_core::lut::read_lut(&dir.join("effects-stiffening.shard-9999-of-10000.lut"))
            .expect("the written shard reads back");
        assert!(file.lut.curves.is_empty());
        file.lut.solver
    };
    let (plain, mixed) = (description(false), description(true));
    assert!(!plain.contains("Anderson"), "{plain}");
    assert!(mixed.contains("Anderson depth 5"), "{mixed}");
    // the same mesh, band and Newton tolerance (only the chord iterations differ)
    let discretisation = |d: &str| d.split(", stagnation limit").next().map(str::to_owned);
    assert_eq!(discretisation(&mixed), discretisation(&plain));
    // the flag belongs to --build-tables
    let out = tactile()
        .args(["diagnose", "--anderson", "curves.csv"])
        .output()
        .expect("run tactile");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--build-tables"));
}

#[test]
fn json_carries_the_documented_fields_and_names_a_camera_scale() {
    let dir = scratch("json");
    let file = dir.join("scale.csv");
    // a 3 % camera scale: ~0.03 mm at a = 1 mm, 7x the white noise
    write_curves(&file, Some((EffectKind::RadiusScale, 0.03)), |_| 0.0, 5, 3);
    let d = diagnose_json(&file);
    assert_eq!(d["verdict"], "effect", "{d:#}");
    assert_eq!(d["effect"], "radius_scale");
    // the curve file's h_mm is the travel from first contact: checked with no zero fitted;
    // a camera scale leaves the travel alone (p < 0.01 would be a 1 % event)
    let travel = &d["forward"]["travel"];
    assert_eq!(travel["fitted_zeros"], 0, "{travel:#}");
    assert!(travel["p_value"].as_f64().expect("p") >= 0.01, "{travel:#}");
    assert!(d["alternatives"].is_array());
    assert!(
        d["confidence"]
            .as_f64()
            .is_some_and(|c| (0.0..=1.0).contains(&c))
    );
    // the estimate is the injected scale within 3 standard errors
    let p = &d["parameters"]["radius_scale_minus_1"];
    let (v, se) = (
        p["value"].as_f64().expect("value"),
        p["se"].as_f64().expect("se"),
    );
    assert!((v - 0.03).abs() < 3.0 * se.max(1e-4), "{v} +- {se}");
    for k in ["baseline", "augmented"] {
        for f in ["modulus_kpa", "chi2_per_dof", "rms_residual_mm"] {
            assert!(d[k][f].as_f64().is_some(), "{k}.{f} missing");
        }
        assert_eq!(d[k]["ci95_kpa"].as_array().map(Vec::len), Some(2));
    }
    // the augmented model recovers the true modulus (within its interval, widened by the
    // half-width again for the table's interpolation error)
    let ci = &d["augmented"]["ci95_kpa"];
    let (lo, hi) = (ci[0].as_f64().expect("ci"), ci[1].as_f64().expect("ci"));
    let half = 0.5 * (hi - lo);
    assert!(lo - half < 170.0 && 170.0 < hi + half, "{lo} .. {hi}");
    assert!(d["gap_shrink"].as_f64().is_some_and(|g| g > 1.0));
    let cells = d["disagreement"].as_array().expect("disagreement");
    assert!(
        !cells.is_empty(),
        "a 3 % scale leaves flagged residual windows"
    );
    for c in cells {
        assert!(c["channel"].is_string() && c["p_air_kpa"].is_number());
        assert_eq!(c["u_s_range_mm"].as_array().map(Vec::len), Some(2));
    }
    assert!(
        d["load_channel"].is_object(),
        "loads present: the channel is used"
    );
    // the scale fitted to the radius and the load together: the same scale within 3 of its
    // standard errors (a camera scale leaves the loads alone, so they only pin E2 down)
    let j = &d["joint_fit"];
    assert_eq!(j["parameter"], "radius_scale_minus_1", "{j:#}");
    let (jv, jse) = (
        j["value"].as_f64().expect("joint value"),
        j["se"].as_f64().expect("joint se"),
    );
    assert!(
        (jv - 0.03).abs() < 3.0 * jse.max(1e-4),
        "joint {jv} +- {jse}"
    );
    assert_eq!(
        j["values"].as_u64(),
        d["points_used"].as_u64().map(|n| 2 * n)
    );
    // --out wrote the report, the same JSON and the residual plots of both channels
    let out = dir.join("out");
    let written: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("diagnosis.json")).expect("diagnosis.json"),
    )
    .expect("json");
    assert_eq!(written["verdict"], d["verdict"]);
    let svg = std::fs::read_to_string(out.join("residuals.svg")).expect("residuals.svg");
    assert_eq!(
        svg.matches("residual a (mm)").count(),
        2,
        "one panel per pressure"
    );
    assert_eq!(svg.matches("residual load P (mN)").count(), 2);
    let report = std::fs::read_to_string(out.join("report.txt")).expect("report.txt");
    assert!(
        report.contains("verdict: effect — radius_scale"),
        "{report}"
    );
}

#[test]
fn structure_no_candidate_explains_is_unexplained() {
    let dir = scratch("unexplained");
    let file = dir.join("wiggle.csv");
    // a ripple of 0.3 mm period, 0.02 mm amplitude, common to every replicate: not a
    // modulus change and not any candidate's signature
    let ripple = |u: f64| 0.02 * (2.0 * std::f64::consts::PI * u / 0.3).sin();
    write_curves(&file, None, ripple, 5, 4);
    let d = diagnose_json(&file);
    assert_eq!(d["verdict"], "unexplained", "{d:#}");
    assert!(d["effect"].is_null());
    let lof_p = d["localisation"]["lack_of_fit"]["p_value"]
        .as_f64()
        .expect("lack of fit");
    assert!(lof_p < 0.01, "lack-of-fit p {lof_p}");
}

#[test]
fn without_replicates_the_noise_model_is_assumed_and_said_so() {
    let dir = scratch("single");
    let file = dir.join("single.csv");
    write_curves(&file, None, |_| 0.0, 1, 5);
    let d = diagnose_json(&file);
    assert_eq!(d["noise_model_assumed"], true);
    let notes: Vec<&str> = d["notes"]
        .as_array()
        .expect("notes")
        .iter()
        .filter_map(serde_json::Value::as_str)
        .collect();
    assert!(
        notes.iter().any(|n| n.contains("assumed")),
        "no note says the noise model is assumed: {notes:?}"
    );
    // one replicate cannot estimate the load noise either: ranked on the radius alone
    assert!(d["load_channel"].is_null());
}

/// A record folder as `tactile measure` writes it: `curve.csv` with the manometer's reading
/// on every row (scattered around the set point) and the stage's position in place of the
/// travel (first contact at 0.8 mm plus a few um that differ between replicates), and
/// `meta.json` with the plan.
fn write_record(dir: &Path, curve: &fit::curve_csv::CurveCsv, pressure_kpa: f64, seed: u64) {
    use experiment::IndentationPlan;
    use experiment::calibration::CalibrationRecord;
    use experiment::pipeline::LutInfo;
    use experiment::record_meta::{
        DeviceMeta, RECORD_SCHEMA_VERSION, RecordMeta, RecordStatus, SoftwareInfo,
    };
    std::fs::create_dir_all(dir).expect("record dir");
    let mut state = seed;
    let mut rows = curve.rows.clone();
    for row in &mut rows {
        // +-0.05 kPa of manometer scatter, deterministic
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        row.p_air_kpa =
            Some(pressure_kpa + 0.1 * ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5));
        let contact_mm = 0.8 + 0.003 * f64::from(row.test.unwrap_or(0));
        row.stage_mm = row.h_mm.take().map(|h| h + contact_mm);
    }
    let measured = fit::curve_csv::CurveCsv {
        metadata: Vec::new(),
        rows,
    };
    fit::curve_csv::write_curve_csv(&dir.join("curve.csv"), &measured).expect("curve.csv");
    let meta = RecordMeta {
        schema_version: RECORD_SCHEMA_VERSION,
        software: SoftwareInfo {
            name: "tactile measure".into(),
            version: "0.1.0".into(),
        },
        protocol_version: 1,
        device: DeviceMeta {
            serial: "E6614C311B4A2C2D".into(),
            firmware_version: "0.1.0".into(),
            port: "/dev/ttyACM0".into(),
        },
        lut: LutInfo {
            path: "default.lut".into(),
            sha256: String::new(),
            model: None,
        },
        calibration: CalibrationRecord::new("E6614C311B4A2C2D", "0.1.0"),
        calibration_path: None,
        plan: IndentationPlan {
            pressure_kpa,
            start_mm: 0.8,
            depth_mm: 1.7,
            speed_mm_per_s: 2.0,
            repeats: 5,
            stream_rate_hz: 2000,
        },
        scenario: None,
        job: None,
        status: RecordStatus::Complete,
        started_unix_s: 0,
        finished_unix_s: None,
        link: None,
        frames: None,
        notes: Vec::new(),
    };
    std::fs::write(
        dir.join("meta.json"),
        serde_json::to_string(&meta).expect("meta"),
    )
    .expect("meta.json");
}

#[test]
fn record_folders_at_two_pressures_are_diagnosed_like_their_curves() {
    let dir = scratch("records");
    let file = dir.join("scale.csv");
    write_curves(&file, Some((EffectKind::RadiusScale, 0.03)), |_| 0.0, 5, 3);
    let all = fit::curve_csv::read_curve_csv(&file).expect("curves");
    for p in [6.0, 15.0] {
        let rows: Vec<_> = all
            .rows
            .iter()
            .filter(|r| r.p_air_kpa == Some(p))
            .cloned()
            .collect();
        assert!(!rows.is_empty());
        let curve = fit::curve_csv::CurveCsv {
            metadata: Vec::new(),
            rows,
        };
        write_record(&dir.join(format!("record-{p}")), &curve, p, p as u64);
    }
    let out = tactile()
        .args(["diagnose", "--json", "--bootstrap", "100", "--reruns", "3"])
        .arg(dir.join("record-6"))
        .arg(dir.join("record-15"))
        .output()
        .expect("run tactile");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let d: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    // the records' nominal pressures, not the scattered manometer readings, group the data
    assert_eq!(d["verdict"], "effect", "{d:#}");
    assert_eq!(d["effect"], "radius_scale");
    // the stage's position is checked as the travel with each indentation's zero fitted:
    // five replicates at each of two pressures; a camera scale leaves the travel alone,
    // so the named model's passes (p < 0.01 would be a 1 % event)
    let travel = &d["forward"]["travel"];
    assert_eq!(travel["fitted_zeros"], 10, "{travel:#}");
    assert!(travel["p_value"].as_f64().expect("p") >= 0.01, "{travel:#}");

    // a record still running has no curve to diagnose: named, exit 2
    let running = dir.join("record-6").join("meta.json");
    let text = std::fs::read_to_string(&running).expect("meta");
    std::fs::write(&running, text.replace("\"complete\"", "\"running\"")).expect("meta");
    let out = tactile()
        .arg("diagnose")
        .arg(dir.join("record-6"))
        .output()
        .expect("run tactile");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("record-6") && err.contains("running"), "{err}");
}

/// `tactile fit --json` of `curve` against `lut` (with `--model` if given): the modulus.
fn fit_json(curve: &Path, lut: &Path, model: Option<&Path>) -> serde_json::Value {
    let mut cmd = tactile();
    cmd.args(["fit", "--json"]).arg(curve).arg("--lut").arg(lut);
    if let Some(m) = model {
        cmd.arg("--model").arg(m);
    }
    let out = cmd.output().expect("run tactile");
    assert!(
        out.status.success(),
        "tactile fit failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

#[test]
fn an_applied_diagnosis_corrects_the_next_samples_modulus() {
    let dir = scratch("apply");
    // The baseline the data and the diagnosis share (the effect tables' base slice), as a
    // table file for `tactile fit --lut`.
    let (base, _) = shipped_tables().expect("shipped tables");
    let lut = dir.join("base.lut");
    fem_core::lut::write_lut(&lut, &base).expect("write base table");
    // This setup's sample is 3 mm thinner than the model assumes.
    let diagnosed = dir.join("diagnosed.csv");
    write_curves(
        &diagnosed,
        Some((EffectKind::FiniteThickness, 3.0)),
        |_| 0.0,
        5,
        11,
    );
    let model = dir.join("setup-model.json");
    let d = diagnose_json_with(&diagnosed, &["--apply".as_ref(), model.as_os_str()]);
    assert_eq!(d["effect"], "finite_thickness", "{d:#}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).expect("model file")).expect("json");
    assert_eq!(m["format"], "tactile-model");
    assert_eq!(m["effects"][0]["effect"], "finite_thickness");
    assert_eq!(m["effect_tables"].as_array().map(Vec::len), Some(1));
    // The next sample of the same setup (another seed, same thinner sample): the plain
    // table reads it too stiff, the model recovers it. The data are the same table's values
    // plus noise, so the corrected fit is limited by the diagnosed thickness's error (its
    // standard error in the model) and the fit's own scatter: within 1.5 %, against the
    // plain fit's bias of several percent.
    let next = dir.join("next.csv");
    write_curves(
        &next,
        Some((EffectKind::FiniteThickness, 3.0)),
        |_| 0.0,
        5,
        12,
    );
    let plain = fit_json(&next, &lut, None);
    let corrected = fit_json(&next, &lut, Some(&model));
    let e_plain = plain["modulus_kpa"].as_f64().expect("modulus");
    let e_model = corrected["modulus_kpa"].as_f64().expect("modulus");
    eprintln!("plain fit {e_plain:.1} kPa, with the model {e_model:.1} kPa (true 170)");
    assert!((e_plain / 170.0 - 1.0).abs() > 0.04, "plain fit {e_plain}");
    assert!(
        (e_model / 170.0 - 1.0).abs() < 0.015,
        "with the model {e_model}"
    );
    assert_eq!(
        corrected["model"]["effects"][0]["effect"],
        "finite_thickness"
    );
    assert!(
        corrected["model"]["sha256"]
            .as_str()
            .is_some_and(|s| s.len() == 64)
    );

    // A model file edited by hand is refused with the field named.
    let bad = dir.join("bad-model.json");
    std::fs::write(
        &bad,
        std::fs::read_to_string(&model)
            .expect("model")
            .replace("finite_thickness", "lens_distortion"),
    )
    .expect("write");
    let out = tactile()
        .args(["fit", "--model"])
        .arg(&bad)
        .arg(&next)
        .arg("--lut")
        .arg(&lut)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad-model.json")
            && err.contains("effects[0]")
            && err.contains("lens_distortion"),
        "{err}"
    );

    // Clean data: nothing named, nothing written, and the run says so.
    let clean = dir.join("clean.csv");
    write_curves(&clean, None, |_| 0.0, 5, 13);
    let none_model = dir.join("none-model.json");
    let out = tactile()
        .args(["diagnose", "--bootstrap", "100", "--reruns", "3"])
        .arg(&clean)
        .arg("--apply")
        .arg(&none_model)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(1));
    assert!(!none_model.exists());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no effect to add"));
}
