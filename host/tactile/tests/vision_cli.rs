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
