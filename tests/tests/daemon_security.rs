//! The daemon refuses what could drive the instrument by accident: requests without the
//! token or with a wrong one (401), with a foreign Host or Origin header (403: a web page in
//! the user's browser), with malformed, oversized or invalid bodies (400/413/415/422 with a
//! JSON error naming the field), and none of them changes anything on the device or in the
//! queue. A valid request afterwards works (the checks are not simply refusing all).

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use daemon::Client;
use system_tests::{start_test_daemon, temp_dir};

/// A refused-body case: path, body, extra headers, expected status.
type BodyCase<'a> = (&'a str, &'a str, &'a [(&'a str, &'a str)], u16);

/// One request written by hand, so every header is exactly what we say.
fn raw_http(addr: &str, request: &str) -> u16 {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    // The server may refuse before reading everything: a failed write is not the answer.
    let _ = s.write_all(request.as_bytes());
    let mut text = String::new();
    let _ = s.read_to_string(&mut text);
    text.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn refused_requests_change_nothing() {
    let dir = temp_dir("daemon-security");
    let (daemon, token_file) = start_test_daemon(&dir, 500);
    assert!(daemon.token_created);
    let addr = daemon.addr.to_string();
    let client = Client::from_token_file(&addr, &token_file).unwrap();
    let t0 = Instant::now();
    // Connected and the first status poll done.
    while client.status().unwrap().vent_open.is_none() {
        assert!(t0.elapsed() < Duration::from_secs(10), "never connected");
        std::thread::sleep(Duration::from_millis(50));
    }
    let before = client.status().unwrap();

    // No token, wrong token.
    let r = client.raw("GET", "/v1/status", None, &[], false).unwrap();
    assert_eq!(r.status, 401, "{}", r.body);
    assert!(r.body.contains("\"error\""), "JSON error body: {}", r.body);
    let r = client
        .raw("POST", "/v1/pressure", Some(r#"{"kpa":5}"#), &[], false)
        .unwrap();
    assert_eq!(r.status, 401);
    let wrong = Client::new(&addr, &"0".repeat(64));
    let r = wrong
        .raw("POST", "/v1/pressure", Some(r#"{"kpa":5}"#), &[], true)
        .unwrap();
    assert_eq!(r.status, 401);
    let r = wrong.raw("POST", "/v1/stop", Some(""), &[], true).unwrap();
    assert_eq!(r.status, 401);

    // Foreign Origin (with the right token: a browser page that somehow had it).
    for origin in ["http://evil.example", "null", "https://127.0.0.1:1"] {
        let r = client
            .raw(
                "POST",
                "/v1/pressure",
                Some(r#"{"kpa":5}"#),
                &[("Origin", origin)],
                true,
            )
            .unwrap();
        assert_eq!(r.status, 403, "Origin {origin}: {}", r.body);
    }
    // Our own origin is fine for a read.
    let own = format!("http://{addr}");
    let r = client
        .raw("GET", "/v1/status", None, &[("Origin", own.as_str())], true)
        .unwrap();
    assert_eq!(r.status, 200, "{}", r.body);

    // Foreign Host (DNS rebinding: the browser sends the attacker's name).
    let port = daemon.addr.port();
    let token = daemon.token.clone();
    let body = r#"{"kpa":5}"#;
    let req = |host: &str| {
        format!(
            "POST /v1/pressure HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {token}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
    };
    assert_eq!(raw_http(&addr, &req(&format!("evil.example:{port}"))), 403);
    assert_eq!(raw_http(&addr, &req("127.0.0.1:1")), 403);

    // Malformed and invalid bodies.
    let cases: &[BodyCase<'_>] = &[
        ("/v1/pressure", "{\"kpa\": ", &[], 400),
        ("/v1/pressure", "not json", &[], 400),
        ("/v1/pressure", r#"{"kpa":"high"}"#, &[], 422),
        ("/v1/pressure", r#"{"kpa":5,"extra":1}"#, &[], 422),
        ("/v1/pressure", r#"{"kpa":40}"#, &[], 422),
        ("/v1/pressure", r#"{"kpa":-1}"#, &[], 422),
        (
            "/v1/pressure",
            r#"{"kpa":5}"#,
            &[("Content-Type", "text/plain")],
            415,
        ),
        ("/v1/vent", r#"{"open":"yes"}"#, &[], 422),
        (
            "/v1/experiments",
            r#"{"pressure_kpa":6,"depth_mm":9,"repeats":0}"#,
            &[],
            422,
        ),
        ("/v1/experiments", r#"{"depth_mm":1}"#, &[], 422),
    ];
    for (path, body, headers, want) in cases {
        let r = client.raw("POST", path, Some(body), headers, true).unwrap();
        assert_eq!(r.status, *want, "{path} {body}: {}", r.body);
        let e: daemon::api::ApiError = serde_json::from_str(&r.body)
            .unwrap_or_else(|e| panic!("{path} {body}: not a JSON error ({e}): {}", r.body));
        assert!(!e.error.is_empty());
    }
    // The validation names every bad field.
    let r = client
        .raw(
            "POST",
            "/v1/experiments",
            Some(r#"{"pressure_kpa":6,"depth_mm":9,"repeats":0}"#),
            &[],
            true,
        )
        .unwrap();
    let e: daemon::api::ApiError = serde_json::from_str(&r.body).unwrap();
    let fields: Vec<&str> = e.fields.iter().map(|f| f.field.as_str()).collect();
    assert_eq!(fields, ["depth_mm", "repeats"], "{}", r.body);
    // Oversized body.
    // (by hand: the daemon may answer 413 and close before the whole body is sent, which a
    // client library reports as a broken connection)
    let big = format!("{{\"kpa\":5,\"pad\":\"{}\"}}", "x".repeat(64 * 1024));
    let request = format!(
        "POST /v1/pressure HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {token}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{big}",
        big.len()
    );
    assert_eq!(raw_http(&addr, &request), 413);
    // Path tricks.
    let r = client
        .raw("GET", "/v1/records/..%2F..%2Fetc/passwd", None, &[], true)
        .unwrap();
    assert!(r.status == 400 || r.status == 404, "{}", r.status);

    // Nothing changed: no job, regulator still off, vent as before.
    std::thread::sleep(Duration::from_millis(600));
    let after = client.status().unwrap();
    assert!(client.jobs().unwrap().is_empty());
    assert_eq!(after.setpoint_kpa, Some(0.0), "setpoint changed: {after:?}");
    assert_eq!(after.vent_open, before.vent_open);
    assert!(
        after.pressure_kpa.unwrap().abs() < 0.5,
        "pressure {:?}",
        after.pressure_kpa
    );

    // Positive control: the same request done right works.
    client.set_pressure(3.0).unwrap();
    let t0 = Instant::now();
    loop {
        let s = client.status().unwrap();
        if s.setpoint_kpa.is_some_and(|p| (p - 3.0).abs() < 0.05) {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "setpoint never 3 kPa: {s:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let r = client.stop().unwrap();
    assert!(r.acknowledged, "{r:?}");
    daemon.shutdown();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn non_loopback_needs_an_explicit_flag() {
    let dir = temp_dir("daemon-remote");
    let bench = hil_sim::bench::start(
        daemon::jobs::default_sim_scenario(&daemon::sim::sim_lut()),
        hil_sim::bench::BenchOptions::default(),
    )
    .unwrap();
    let options = daemon::DaemonOptions {
        source: daemon::DeviceSource::Sim {
            bench,
            scenario: Box::default(),
        },
        listen: "0.0.0.0:0".parse().unwrap(),
        allow_remote: false,
        token_file: dir.join("token"),
        records_dir: dir.join("records"),
        lut_path: daemon::sim::shipped_lut(),
        max_connections: daemon::listener::MAX_CONNECTIONS,
        device: daemon::DeviceConfig {
            idle_stream_hz: 100,
            link: link::LinkConfig::default(),
            camera: None,
            model: None,
        },
    };
    let e = daemon::start(options).unwrap_err();
    assert!(matches!(e, daemon::DaemonError::NotLoopback(_)), "{e}");
    assert!(
        !dir.join("token").exists(),
        "nothing created before refusing"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
