//! `tactile fit` as a user runs it: JSON keys, and bad input -> exit code 2 with the file,
//! line and column named.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use std::path::PathBuf;
use std::process::Command;

fn tactile() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tactile"))
}

/// The fit crate's test data: its fixture table and direct-solve truth curves.
fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../fit/tests/data")
        .join(name)
}

fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("tactile-cli-fit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn json_output_has_the_documented_keys() {
    let out = tactile()
        .arg("fit")
        .arg(data("fem_truth_E200_p6.csv"))
        .arg("--lut")
        .arg(data("fit_fixture.lut"))
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let e = v["modulus_kpa"].as_f64().unwrap();
    assert!((e / 200.0 - 1.0).abs() < 0.015, "{e}");
    let ci = v["ci95_kpa"].as_array().unwrap();
    assert_eq!(ci.len(), 2);
    assert!(ci[0].as_f64().unwrap() <= e && e <= ci[1].as_f64().unwrap());
    assert!(v["rms_residual_mm"].as_f64().unwrap() >= 0.0);
    assert!(v["recommended_pressure_kpa"].as_f64().is_some());
}

/// `tactile fit` without `--lut` fits the shipped converged table directly: its own error
/// of a is in the interval (`discretisation_residual_ln`) and nothing is corrected; the
/// shipped production-mesh table is corrected to the converged one.
#[test]
fn the_default_table_is_the_converged_one_and_a_production_mesh_table_is_corrected() {
    let fit = |lut: Option<PathBuf>| {
        let mut cmd = tactile();
        cmd.arg("fit")
            .arg(data("fem_truth_E200_p6.csv"))
            .arg("--json")
            .env_remove("TACTILE_LUT")
            .env_remove("TACTILE_DATA_DIR");
        if let Some(lut) = lut {
            cmd.arg("--lut").arg(lut);
        }
        let out = cmd.output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let shipped = fit(None);
    let term = shipped["fit"]["discretisation_residual_ln"]
        .as_f64()
        .unwrap();
    // 3 um of a projected on ln E2 at 200 kPa / 6 kPa: a few tenths of a percent
    assert!((1e-3..0.05).contains(&term), "{term}");
    assert!(shipped["fit"]["modulus_production_kpa"].is_null());
    assert!(shipped["fit"]["discretisation_bias_ln"].is_null());

    let production_mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fem-core/data/default-production-mesh.lut");
    let corrected = fit(Some(production_mesh));
    let own = corrected["fit"]["modulus_production_kpa"].as_f64().unwrap();
    let bias = corrected["fit"]["discretisation_bias_ln"].as_f64().unwrap();
    let e = corrected["modulus_kpa"].as_f64().unwrap();
    // the estimate is the production-mesh table's own moved by the bias
    assert!(
        (e - own * (-bias).exp()).abs() < 1e-9 * e,
        "{e} {own} {bias}"
    );
}

#[test]
fn malformed_csv_names_line_and_column_and_exits_2() {
    let path = temp_file("bad.csv", "# p_air_kpa: 6\nu_s_mm,a_mm\n0.1,0.5\n0.2,abc\n");
    let out = tactile()
        .arg("fit")
        .arg(&path)
        .arg("--lut")
        .arg(data("fit_fixture.lut"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.csv:4"), "{err}");
    assert!(err.contains("a_mm"), "{err}");
}

#[test]
fn missing_pressure_and_missing_table_exit_2() {
    let path = temp_file("nop.csv", "u_s_mm,a_mm\n0.1,0.5\n0.2,0.7\n0.3,0.9\n");
    let out = tactile()
        .arg("fit")
        .arg(&path)
        .arg("--lut")
        .arg(data("fit_fixture.lut"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("p_air_kpa"));
    let out = tactile()
        .arg("fit")
        .arg(data("fem_truth_E200_p6.csv"))
        .arg("--lut")
        .arg("/nonexistent/table.lut")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/table.lut"));
}

#[test]
fn a_pressure_between_the_deflated_and_the_first_inflated_node_is_refused_with_the_tables_pressures()
 {
    // the direct-solve curve relabelled 3 kPa: the shipped table (0, 6, 10, ... kPa) would
    // read it on its straight line between 0 and 6 kPa, which is far off there
    let text = std::fs::read_to_string(data("fem_truth_E200_p6.csv")).unwrap();
    let relabelled: Vec<String> = text
        .lines()
        .map(|line| {
            if line.starts_with("# p_air_kpa") {
                "# p_air_kpa: 3".to_string()
            } else if line.starts_with('#') || line.starts_with("u_s_mm") {
                line.to_string()
            } else {
                let mut cols: Vec<&str> = line.split(',').collect();
                cols[3] = "3";
                cols.join(",")
            }
        })
        .collect();
    let path = temp_file("at3kpa.csv", &relabelled.join("\n"));
    let table = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fem-core/data/default.lut");
    let out = tactile()
        .arg("fit")
        .arg(&path)
        .arg("--lut")
        .arg(&table)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("at3kpa.csv"), "{err}");
    assert!(
        err.contains("p_air = 3 kPa") && err.contains("0, 6, 10, 15, 20, 30"),
        "{err}"
    );
}
