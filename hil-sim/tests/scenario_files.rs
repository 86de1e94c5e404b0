//! Every shipped scenario file parses and validates.

#![allow(clippy::unwrap_used)] // tests may unwrap

#[test]
fn shipped_scenarios_are_valid() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            hil_sim::scenario::Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 5, "{n} scenario files");
}

fn hil_sim(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_hil-sim"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn help_prints_the_usage_and_succeeds() {
    let out = hil_sim(&["--help"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stdout).contains("usage: hil-sim"));
    let out = hil_sim(&["--frobnicate"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--help"));
}

#[test]
fn an_oversized_camera_is_refused_before_any_allocation() {
    let dir = std::env::temp_dir().join(format!("hil-sim-camera-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("huge-camera.toml");
    // 60000 x 60000 would need 3.6 GB per frame.
    std::fs::write(&path, "[camera]\nwidth = 60000\nheight = 60000\n").unwrap();
    let err = hil_sim::scenario::Scenario::load(&path)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("huge-camera.toml") && err.contains("4096"),
        "{err}"
    );
    let out = hil_sim(&["--scenario", path.to_str().unwrap()]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).ok();
}
