//! `tactile radius`, `tactile devices` and `tactile flash --uf2-out` as a user runs them.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use camera::{encode_gray_jpeg, write_pgm, write_png};
use std::process::Command;
use testkit::{SyntheticDisc, SyntheticScene};

fn tactile() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tactile"))
}

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("vision_cli_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn radius_json_reports_each_frame() {
    let dir = tmp("radius");
    let mut scene = SyntheticScene::typical();
    write_pgm(&dir.join("ref.pgm"), &scene.render(false, 1)).unwrap();
    scene.disc = Some(SyntheticDisc::circle([320.0, 240.0], 70.0));
    write_pgm(&dir.join("f1.pgm"), &scene.render(true, 2)).unwrap();
    scene.disc = Some(SyntheticDisc::circle([320.0, 240.0], 120.0));
    write_png(&dir.join("f2.png"), &scene.render(true, 3)).unwrap();
    write_pgm(&dir.join("f3.pgm"), &scene.render(false, 4)).unwrap();
    let out = tactile()
        .args(["radius", "--json", "--reference"])
        .arg(dir.join("ref.pgm"))
        .arg(dir.join("f1.pgm"))
        .arg(dir.join("f2.png"))
        .arg(dir.join("f3.pgm"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 3);
    // One frame's standard error is ~0.05 px here; 0.2 px leaves room.
    assert!((rows[0]["radius_px"].as_f64().unwrap() - 70.0).abs() < 0.2);
    assert!((rows[1]["radius_px"].as_f64().unwrap() - 120.0).abs() < 0.2);
    for r in &rows[..2] {
        assert_eq!(r["contact"], true);
        assert!(r["center_px"].as_array().unwrap().len() == 2);
        assert!(r["ellipse"]["semi_major_px"].as_f64().unwrap() > 0.0);
        assert!(r["quality"].as_f64().unwrap() > 0.5);
    }
    assert_eq!(rows[2]["contact"], false);
    assert!(rows[2]["radius_px"].is_null());
    assert!(String::from_utf8_lossy(&out.stderr).contains("ms per frame"));
}

#[test]
fn radius_reads_an_mjpeg_stream_with_its_first_frame_as_reference() {
    let dir = tmp("mjpeg");
    let mut scene = SyntheticScene::typical();
    let mut stream = encode_gray_jpeg(&scene.render(false, 1), 92);
    scene.disc = Some(SyntheticDisc::circle([321.0, 239.0], 90.0));
    stream.extend(encode_gray_jpeg(&scene.render(true, 2), 92));
    std::fs::write(dir.join("rec.mjpeg"), &stream).unwrap();
    let out = tactile()
        .args(["radius", "--json"])
        .arg(dir.join("rec.mjpeg"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(rows[0]["contact"], false, "the reference itself");
    // JPEG quantisation adds edge error; 0.3 px.
    let r = rows[1]["radius_px"].as_f64().unwrap();
    assert!((r - 90.0).abs() < 0.3, "{r}");
}

#[test]
fn bad_input_exits_with_code_2_naming_the_file() {
    let dir = tmp("bad");
    std::fs::write(dir.join("junk.pgm"), b"P5 10 10 255\n\x00").unwrap();
    let out = tactile()
        .arg("radius")
        .arg(dir.join("junk.pgm"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("junk.pgm") && err.contains("raster"), "{err}");
    let out = tactile()
        .args(["flash", "/nonexistent/fw.elf"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/fw.elf"));
}

#[test]
fn a_missing_camera_is_named_with_the_devices_that_exist() {
    let out = tactile()
        .args(["radius", "--camera", "/nonexistent/video9", "--count", "3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/nonexistent/video9") && err.contains("video devices present"),
        "{err}"
    );
    // frames and a camera together are refused before anything is opened
    let out = tactile()
        .args(["radius", "frame.pgm", "--camera", "/dev/video0"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    // --count without --camera too
    let out = tactile()
        .args(["radius", "frame.pgm", "--count", "3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn devices_lists_without_panicking_where_usb_is_absent() {
    let out = tactile().args(["devices", "--json"]).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["serial_ports"].is_array() && v["usb"].is_array());
    // Without /dev/bus/usb the note says so instead of panicking.
    if !std::path::Path::new("/dev/bus/usb").exists() {
        assert!(
            v["usb_note"]
                .as_str()
                .is_some_and(|n| n.contains("no USB access")),
            "{v}"
        );
    }
}

/// `tactile calibrate camera` with four disc sizes seen through a lens with radial
/// distortion (an image radius 50 px/mm r (1 + k r^2), k = 0.003 /mm^2: +3.5 % at 3.4 mm)
/// on the testkit's frames (blur, noise, vignetting): the distortion is found, stored in
/// the record and the scale is the cubic fit's; undistorted discs store none.
#[test]
fn camera_calibration_finds_and_stores_a_lens_distortion() {
    for (k, name) in [(0.003, "distorted"), (0.0, "straight")] {
        let dir = tmp(&format!("calibrate_{name}"));
        let mut scene = SyntheticScene::typical();
        write_pgm(&dir.join("ref.pgm"), &scene.render(false, 1)).unwrap();
        let mut args: Vec<String> = vec![
            "calibrate".into(),
            "--dir".into(),
            dir.join("cal").display().to_string(),
            "camera".into(),
            "--reference".into(),
            dir.join("ref.pgm").display().to_string(),
            "--disc".into(),
        ];
        for (i, r) in [1.2f64, 2.0, 2.8, 3.4].into_iter().enumerate() {
            scene.disc = Some(SyntheticDisc::circle(
                [320.0, 240.0],
                50.0 * r * (1.0 + k * r * r),
            ));
            let file = dir.join(format!("disc{i}.pgm"));
            write_pgm(&file, &scene.render(true, 10 + i as u64)).unwrap();
            args.push(format!("{}:{r}", file.display()));
        }
        let out = tactile().args(&args).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        eprintln!("{name}: {stdout}");
        assert!(
            out.status.success(),
            "{stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let record = std::fs::read_dir(dir.join("cal"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|x| x == "json"))
            .unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&record).unwrap()).unwrap();
        let stored = json
            .get("lens_distortion_k_per_mm2")
            .and_then(|v| v.as_f64());
        let scale = json["px_per_mm"].as_f64().unwrap();
        if k > 0.0 {
            // the edge estimator's error on these frames (~0.05-0.1 px) allows k within
            // about 10 %; the scale is the cubic's, not the line's (~53 px/mm here)
            let got = stored.unwrap_or_else(|| panic!("no distortion stored: {stdout}"));
            assert!((got - k).abs() < 0.3 * k, "k {got}: {stdout}");
            assert!((scale - 50.0).abs() < 0.5, "scale {scale}: {stdout}");
            assert!(stdout.contains("lens distortion"), "{stdout}");
        } else {
            assert_eq!(stored, None, "{stdout}");
            assert!(stdout.contains("no lens distortion seen"), "{stdout}");
            assert!((scale - 50.0).abs() < 0.5, "scale {scale}: {stdout}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
