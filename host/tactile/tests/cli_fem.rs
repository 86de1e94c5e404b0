//! `tactile fem curve` as a user runs it: Anderson mixing of Newton's chord iterations
//! (`--anderson`) is recorded in the curve file and leaves the curve where it was, and the
//! travel column reads as the nominal steps.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use std::path::{Path, PathBuf};
use std::process::Command;

fn solve(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out_path = dir.join(name);
    let out = Command::new(env!("CARGO_BIN_EXE_tactile"))
        .args(["fem", "curve", "--modulus", "200", "--pressure", "6"])
        .args(["--mesh-level", "-2", "--steps", "6", "--depth", "0.6"])
        .args(extra)
        .arg("--out")
        .arg(&out_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out_path
}

#[test]
fn anderson_mixing_is_recorded_and_reaches_the_same_curve() {
    let dir = std::env::temp_dir().join(format!("tactile-cli-fem-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let plain = fit::curve_csv::read_curve_csv(&solve(&dir, "plain.csv", &[])).unwrap();
    let mixed = fit::curve_csv::read_curve_csv(&solve(&dir, "mixed.csv", &["--anderson"])).unwrap();
    assert_eq!(plain.meta("anderson_depth"), None);
    assert_eq!(
        mixed.meta("anderson_depth"),
        Some(fem_core::simulation::ANDERSON_DEPTH.to_string().as_str())
    );
    assert_eq!(plain.rows.len(), mixed.rows.len());
    // Newton stops at a relative residual of 1e-9 either way: the equilibria agree far
    // below a micrometre (the coarse mesh's own error in a is tens of micrometres)
    for (p, m) in plain.rows.iter().zip(&mixed.rows) {
        assert_eq!(p.h_mm, m.h_mm);
        assert!((p.a_mm - m.a_mm).abs() < 1e-5, "h {:?}: a", p.h_mm);
        assert!((p.u_s_mm - m.u_s_mm).abs() < 1e-6, "h {:?}: u_s", p.h_mm);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The travel column holds each step's nominal travel as written by hand (0.3, not the
/// 0.30000000000000004 that summing 0.1 mm increments gives).
#[test]
fn the_travel_column_prints_the_nominal_steps() {
    let dir = std::env::temp_dir().join(format!("tactile-cli-fem-h-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(solve(&dir, "curve.csv", &[])).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = header.iter().position(|&c| c == "h_mm").unwrap();
    let travel: Vec<String> = lines
        .map(|l| l.split(',').nth(column).unwrap().to_owned())
        .collect();
    assert_eq!(travel, ["0", "0.1", "0.2", "0.3", "0.4", "0.5", "0.6"]);
    std::fs::remove_dir_all(&dir).ok();
}
