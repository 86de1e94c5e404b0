//! The link client against the real firmware controller in-process (`LoopbackDevice`), in
//! real time: handshake, version check, requests, stream loss counting, clock mapping,
//! unplug.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use link::{Link, LinkConfig, LinkError};
use protocol::{ChannelSet, PROTOCOL_VERSION, Reply, Request, endpoints};
use std::time::Duration;
use testkit::loopback_device::{LoopbackDevice, LoopbackFaults, SimpleBench};

fn device(faults: LoopbackFaults) -> Box<LoopbackDevice> {
    // device clock 3 s ahead of the link's epoch and 150 ppm fast
    Box::new(LoopbackDevice::new(
        Box::new(SimpleBench::new(7)),
        3_000_000,
        150.0,
        faults,
    ))
}

#[test]
fn handshake_reports_the_firmware_constants() {
    let link = Link::connect(device(LoopbackFaults::default()), LinkConfig::default()).unwrap();
    assert_eq!(link.info().protocol_version, PROTOCOL_VERSION);
    assert_eq!(
        link.info().stage_steps_per_mm,
        controller::device_constants::STAGE_STEPS_PER_MM
    );
    // 1600 steps/mm: 3200 steps is 2 mm
    assert_eq!(link.units().stage_mm(3200), 2.0);
    assert!(link.clock().is_ready());
}

#[test]
fn version_mismatch_names_both_versions() {
    let mut dev = device(LoopbackFaults::default());
    dev.speak_version = Some(PROTOCOL_VERSION + 1);
    let err = Link::connect(
        dev,
        LinkConfig {
            request_timeout: Duration::from_millis(50),
            retries: 1,
            ..LinkConfig::default()
        },
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, LinkError::VersionMismatch { host, device } if host == PROTOCOL_VERSION && device == PROTOCOL_VERSION + 1),
        "{msg}"
    );
    assert!(
        msg.contains(&format!("version {PROTOCOL_VERSION}"))
            && msg.contains(&format!("version {}", PROTOCOL_VERSION + 1)),
        "{msg}"
    );
}

#[test]
fn nack_is_an_error_naming_the_request() {
    let mut link = Link::connect(device(LoopbackFaults::default()), LinkConfig::default()).unwrap();
    // 50 kPa is above the firmware's 18 kPa setpoint limit
    let err = link
        .call(endpoints::SetPressure { setpoint_kpa: 50.0 })
        .unwrap_err();
    assert!(err.to_string().contains("SetPressure"), "{err}");
    // The typed call returns the reply's own type (the refused setpoint changed nothing);
    // the raw request returns the wire's Reply.
    let status: protocol::Status = link.call(endpoints::GetStatus).unwrap();
    assert_eq!(status.setpoint_kpa, 0.0);
    assert!(matches!(
        link.request(Request::GetStatus).unwrap(),
        Reply::Status(_)
    ));
}

#[test]
fn stream_at_2_khz_arrives_complete_and_clock_maps_device_time() {
    let mut link = Link::connect(device(LoopbackFaults::default()), LinkConfig::default()).unwrap();
    link.start_stream(2000, ChannelSet::ALL).unwrap();
    let t0 = host_clock::now_us();
    link.receive_for(Duration::from_millis(1500)).unwrap();
    link.stop_stream().unwrap();
    let samples = link.drain_samples();
    let stats = link.stats();
    assert_eq!(stats.blocks_lost, 0, "{stats:?}");
    // 1.5 s at 2 kHz = 3000 samples; the start/stop requests take a few ms each
    assert!(
        (2900..=3100).contains(&samples.len()),
        "{} samples",
        samples.len()
    );
    // device time steps of 500 µs, no gaps
    for w in samples.windows(2) {
        assert_eq!(w[1].sample.device_time_us - w[0].sample.device_time_us, 500);
    }
    // heartbeat pings kept the clock fit going; mapped times fall inside the pump window
    // (a sample is mapped within a millisecond or two of when it was taken)
    assert!(stats.pings >= 8 + 5, "{stats:?}");
    let first = samples[0].host_time_us;
    assert!(
        first > t0 as f64 - 20_000.0 && first < t0 as f64 + 50_000.0,
        "{first} vs {t0}"
    );
    let fit = link.clock().fit().unwrap();
    // 150 ppm injected. The loopback device runs in real time, so the round-trip midpoints
    // carry the machine's scheduling jitter (tens of µs idle, more on a loaded CI box). The
    // least-squares slope's standard error for n pings spread evenly over a span T is
    // sigma / (T sqrt(n / 12)) with sigma the fit's own residual RMS. Scheduling stalls make
    // the midpoint errors heavy-tailed rather than Gaussian (one run on a machine with a full
    // disk and two builds read 4.5 standard errors off), so allow 6 (never tighter than
    // 50 ppm, what an idle machine achieves).
    let span_us = 1.5e6;
    let n = fit.round_trips as f64;
    let se_ppm = fit.residual_rms_us / (span_us * (n / 12.0).sqrt()) * 1e6;
    let tolerance_ppm = (6.0 * se_ppm).max(50.0);
    assert!(
        (fit.drift_ppm - 150.0).abs() < tolerance_ppm,
        "{fit:?}, tolerance {tolerance_ppm:.1} ppm"
    );
}

#[test]
fn corrupted_bytes_are_counted_as_lost_blocks_not_errors() {
    let mut link = Link::connect(
        device(LoopbackFaults {
            corrupt_every_n_bytes: Some(5000),
            unplug_after_us: None,
        }),
        LinkConfig::default(),
    )
    .unwrap();
    link.start_stream(1000, ChannelSet::ALL).unwrap();
    link.receive_for(Duration::from_millis(800)).unwrap();
    link.stop_stream().unwrap();
    let stats = link.stats();
    assert!(stats.frame_errors > 0, "{stats:?}");
    assert!(stats.blocks_lost > 0, "{stats:?}");
    assert!(stats.blocks_received > 50, "{stats:?}");
}

#[test]
fn unplug_mid_stream_is_a_disconnect_and_keeps_what_arrived() {
    let mut link = Link::connect(
        device(LoopbackFaults {
            corrupt_every_n_bytes: None,
            unplug_after_us: Some(700_000),
        }),
        LinkConfig::default(),
    )
    .unwrap();
    link.start_stream(1000, ChannelSet::ALL).unwrap();
    let err = link.receive_for(Duration::from_secs(3)).unwrap_err();
    assert!(err.is_disconnect(), "{err}");
    assert!(err.to_string().contains("disconnected"), "{err}");
    let kept = link.drain_samples();
    assert!(kept.len() > 100, "{} samples kept", kept.len());
}

#[test]
fn pressure_setpoint_is_reached_with_heartbeats_from_the_pump_loop() {
    let mut link = Link::connect(device(LoopbackFaults::default()), LinkConfig::default()).unwrap();
    link.request(Request::SetPressure { setpoint_kpa: 6.0 })
        .unwrap();
    // 2 s > the 1 s heartbeat timeout: only the pump loop's pings keep the pump running
    link.receive_for(Duration::from_secs(2)).unwrap();
    let status = link.status().unwrap();
    assert!(status.faults.is_empty(), "{status:?}");
    assert!((status.pressure_kpa - 6.0).abs() < 0.5, "{status:?}");
    link.request(Request::PressureOff).unwrap();
}
