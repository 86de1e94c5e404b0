//! Dispatch: every Request variant gets exactly one Ack or Nack with its seq, and the
//! refusals named in `controller::dispatch`.

mod support;

use controller::device_constants::{
    ADC_FULL_SCALE_COUNTS, LOAD_COUNTS_PER_N, MANOMETER_KPA_PER_COUNT, MANOMETER_ZERO_COUNTS,
    STAGE_STEPS_PER_MM,
};
use controller::{Controller, ControllerConfig};
use protocol::{
    ChannelSet, DeviceMessage, FrameDecoder, MAX_FRAME_LEN, NackCode, PROTOCOL_VERSION, PidGains,
    PressureMode, Reply, Request, RequestFrame, encode_frame,
};
use support::Bench;

/// One instance of every variant (the match below fails to compile when a variant is
/// added, so this list cannot silently fall behind the protocol).
fn every_request() -> Vec<Request> {
    let all = vec![
        Request::Hello {
            host_protocol_version: PROTOCOL_VERSION,
        },
        Request::Ping { host_time_us: 42 },
        Request::Heartbeat,
        Request::SetPressure { setpoint_kpa: 6.0 },
        Request::PressureOff,
        Request::PumpManual { duty_per_10k: 2500 },
        Request::Vent { open: true },
        Request::SetPidGains(PidGains {
            kp: 0.5,
            ki: 0.4,
            kd: 0.01,
            feed_forward_per_kpa: 0.02,
        }),
        Request::StartStream {
            rate_hz: 1000,
            channels: ChannelSet::ALL,
        },
        Request::StopStream,
        Request::TareLoad,
        Request::MoveStage {
            target_steps: 1600,
            speed_steps_per_s: 1600,
            accel_steps_per_s2: 16_000,
        },
        Request::StopStage,
        Request::SetStageLimits {
            min_steps: -1000,
            max_steps: 100_000,
        },
        Request::SetStagePosition { position_steps: 0 },
        Request::ClearFault,
        Request::GetStatus,
        Request::SetLed { duty_per_10k: 5000 },
        Request::EnterBootloader,
    ];
    for r in &all {
        match r {
            Request::Hello { .. }
            | Request::Ping { .. }
            | Request::Heartbeat
            | Request::SetPressure { .. }
            | Request::PressureOff
            | Request::PumpManual { .. }
            | Request::Vent { .. }
            | Request::SetPidGains(_)
            | Request::StartStream { .. }
            | Request::StopStream
            | Request::TareLoad
            | Request::MoveStage { .. }
            | Request::StopStage
            | Request::SetStageLimits { .. }
            | Request::SetStagePosition { .. }
            | Request::ClearFault
            | Request::GetStatus
            | Request::SetLed { .. }
            | Request::EnterBootloader => {}
        }
    }
    all
}

#[test]
fn every_request_gets_exactly_one_reply_with_its_seq_over_the_wire() {
    let mut ctl = Controller::new(ControllerConfig::default());
    let mut decoder = FrameDecoder::<RequestFrame>::new();
    let mut now = 0u64;
    for (i, request) in every_request().into_iter().enumerate() {
        // 300 ms of ticks between requests (so a stopped stage is at rest again), with
        // load conversions so TareLoad has something to tare.
        for k in 0..600u16 {
            now += 500;
            ctl.tick(
                now,
                &controller::RawInputs {
                    proximity_counts: 100,
                    manometer_counts: MANOMETER_ZERO_COUNTS + (k % 3),
                    load_counts: Some(1000),
                },
            );
        }
        let seq = 1000 + i as u16 * 7;
        let mut wire = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(
            &RequestFrame {
                seq,
                request: request.clone(),
            },
            &mut wire,
        )
        .unwrap();
        let frames: Vec<_> = decoder.push(&wire[..n]).collect();
        assert_eq!(frames.len(), 1);
        let frame = frames.into_iter().next().unwrap().unwrap();
        let reply = ctl.handle(&frame, now);
        match &reply {
            DeviceMessage::Ack { seq: s, .. } => assert_eq!(*s, seq, "{request:?}"),
            other => panic!("{request:?} -> {other:?}"),
        }
        // The reply is not duplicated into the outgoing queue.
        while let Some(m) = ctl.poll_outgoing() {
            assert!(
                !matches!(m, DeviceMessage::Ack { .. } | DeviceMessage::Nack { .. }),
                "{m:?}"
            );
        }
        // It fits a frame.
        encode_frame(&reply, &mut wire).unwrap();
    }
    assert!(ctl.reboot_requested());
}

#[test]
fn hello_reports_the_conversion_constants() {
    let mut config = ControllerConfig::default();
    config.serial.push_str("E660C0D1C7A5B32F").unwrap();
    let mut bench = Bench::with_config(config);
    let Reply::Info(info) = bench.ack(Request::Hello {
        host_protocol_version: PROTOCOL_VERSION,
    }) else {
        panic!()
    };
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.serial.as_str(), "E660C0D1C7A5B32F");
    assert_eq!(info.firmware_version.as_str(), env!("CARGO_PKG_VERSION"));
    assert_eq!(info.adc_full_scale_counts, ADC_FULL_SCALE_COUNTS);
    assert_eq!(info.adc_vref_mv, 3300);
    assert_eq!(info.manometer_zero_counts, MANOMETER_ZERO_COUNTS);
    assert_eq!(info.manometer_kpa_per_count, MANOMETER_KPA_PER_COUNT);
    assert_eq!(info.load_counts_per_n, LOAD_COUNTS_PER_N);
    assert_eq!(info.stage_steps_per_mm, STAGE_STEPS_PER_MM);
    assert_eq!(info.control_period_us, 1000);
    assert_eq!(info.overpressure_limit_kpa, 20.0);
    assert_eq!(info.heartbeat_timeout_ms, 1000);
}

#[test]
fn version_mismatch_is_refused() {
    let mut bench = Bench::new();
    let reply = bench.request(Request::Hello {
        host_protocol_version: PROTOCOL_VERSION + 1,
    });
    assert!(matches!(
        reply,
        DeviceMessage::Nack {
            error: NackCode::VersionMismatch { device_version },
            ..
        } if device_version == PROTOCOL_VERSION
    ));
}

fn nack(bench: &mut Bench, request: Request) -> NackCode {
    match bench.request(request.clone()) {
        DeviceMessage::Nack { error, .. } => error,
        other => panic!("{request:?} accepted: {other:?}"),
    }
}

#[test]
fn out_of_range_parameters_are_refused_and_change_nothing() {
    let mut bench = Bench::new();
    let before = bench.ctl.status();
    for request in [
        Request::SetPressure { setpoint_kpa: -0.1 },
        Request::SetPressure { setpoint_kpa: 18.5 },
        Request::SetPressure {
            setpoint_kpa: f32::NAN,
        },
        Request::PumpManual {
            duty_per_10k: 10_001,
        },
        Request::SetLed {
            duty_per_10k: 10_001,
        },
        Request::SetPidGains(PidGains {
            kp: -1.0,
            ki: 0.0,
            kd: 0.0,
            feed_forward_per_kpa: 0.0,
        }),
        Request::SetPidGains(PidGains {
            kp: 1.0,
            ki: f32::INFINITY,
            kd: 0.0,
            feed_forward_per_kpa: 0.0,
        }),
        Request::StartStream {
            rate_hz: 0,
            channels: ChannelSet::ALL,
        },
        Request::StartStream {
            rate_hz: 2001,
            channels: ChannelSet::ALL,
        },
        Request::StartStream {
            rate_hz: 100,
            channels: ChannelSet(0x20),
        },
        Request::MoveStage {
            target_steps: 10,
            speed_steps_per_s: 0,
            accel_steps_per_s2: 100,
        },
        Request::MoveStage {
            target_steps: 10,
            speed_steps_per_s: 16_001,
            accel_steps_per_s2: 100,
        },
        Request::MoveStage {
            target_steps: 10,
            speed_steps_per_s: 100,
            accel_steps_per_s2: 160_001,
        },
        Request::SetStageLimits {
            min_steps: 10,
            max_steps: -10,
        },
    ] {
        assert_eq!(nack(&mut bench, request), NackCode::OutOfRange);
    }
    assert_eq!(bench.ctl.status(), before);
}

#[test]
fn stage_limit_and_busy_refusals() {
    let mut bench = Bench::new();
    bench.ack(Request::SetStageLimits {
        min_steps: -100,
        max_steps: 10_000,
    });
    assert_eq!(
        nack(
            &mut bench,
            Request::MoveStage {
                target_steps: 10_001,
                speed_steps_per_s: 1000,
                accel_steps_per_s2: 10_000
            }
        ),
        NackCode::StageLimit
    );
    assert_eq!(
        nack(
            &mut bench,
            Request::SetStagePosition {
                position_steps: -101
            }
        ),
        NackCode::StageLimit
    );
    bench.ack(Request::MoveStage {
        target_steps: 10_000,
        speed_steps_per_s: 1000,
        accel_steps_per_s2: 10_000,
    });
    bench.run_quiet_ms(50);
    assert_eq!(
        nack(&mut bench, Request::SetStagePosition { position_steps: 0 }),
        NackCode::Busy
    );
    assert_eq!(
        nack(
            &mut bench,
            Request::SetStageLimits {
                min_steps: 0,
                max_steps: 5
            }
        ),
        NackCode::Busy
    );
    assert_eq!(nack(&mut bench, Request::EnterBootloader), NackCode::Busy);
    bench.ack(Request::StopStage);
    bench.run_quiet_ms(300);
    // New limits that exclude the current position are refused.
    let pos = bench.ctl.stage().position_steps();
    assert!(pos > 10);
    assert_eq!(
        nack(
            &mut bench,
            Request::SetStageLimits {
                min_steps: 0,
                max_steps: 5
            }
        ),
        NackCode::StageLimit
    );
    // Homing at rest.
    bench.ack(Request::SetStagePosition { position_steps: 0 });
    assert_eq!(bench.ctl.stage().position_steps(), 0);
}

#[test]
fn pressure_requests_change_the_mode() {
    let mut bench = Bench::new();
    bench.ack(Request::PumpManual { duty_per_10k: 3000 });
    bench.tick();
    assert_eq!(bench.last.pump_duty_per_10k, 3000);
    assert_eq!(bench.ctl.pressure_mode(), PressureMode::Manual);
    // Manual -> regulating is bumpless: the first output continues from 3000.
    bench.ack(Request::SetPressure { setpoint_kpa: 6.0 });
    bench.tick();
    let jump = (i32::from(bench.last.pump_duty_per_10k) - 3000).abs();
    assert!(jump < 600, "{}", bench.last.pump_duty_per_10k);
    assert_eq!(bench.ctl.pressure_mode(), PressureMode::Regulating);
    bench.ack(Request::Vent { open: true });
    assert_eq!(bench.ctl.pressure_mode(), PressureMode::Off);
    bench.tick();
    assert!(bench.last.vent_open);
    assert_eq!(bench.last.pump_duty_per_10k, 0);
    bench.ack(Request::SetLed { duty_per_10k: 1234 });
    bench.ack(Request::PressureOff);
    bench.tick();
    assert_eq!(bench.last.led_duty_per_10k, 1234);
    assert!(bench.last.vent_open, "PressureOff keeps the vent");
    let Reply::Pong {
        host_time_us,
        device_time_us,
    } = bench.ack(Request::Ping { host_time_us: 7 })
    else {
        panic!()
    };
    assert_eq!((host_time_us, device_time_us), (7, bench.now_us));
}

#[test]
fn gains_change_is_reported_in_status() {
    let mut bench = Bench::new();
    let gains = PidGains {
        kp: 0.1,
        ki: 0.2,
        kd: 0.0,
        feed_forward_per_kpa: 0.0,
    };
    bench.ack(Request::SetPidGains(gains));
    let Reply::Status(status) = bench.ack(Request::GetStatus) else {
        panic!()
    };
    assert_eq!(status.gains, gains);
}

#[test]
fn enter_bootloader_acks_then_signals_the_board() {
    let mut bench = Bench::new();
    bench.ack(Request::PumpManual { duty_per_10k: 5000 });
    bench.tick();
    assert!(!bench.last.reboot_to_bootloader);
    let reply = bench.request(Request::EnterBootloader);
    assert!(matches!(
        reply,
        DeviceMessage::Ack {
            reply: Reply::Done,
            ..
        }
    ));
    let out = bench.tick();
    assert!(out.reboot_to_bootloader);
    assert_eq!(out.pump_duty_per_10k, 0);
}

#[test]
fn rx_errors_are_counted() {
    let mut bench = Bench::new();
    bench.ctl.note_rx_error();
    bench.ctl.note_rx_error();
    let Reply::Status(status) = bench.ack(Request::GetStatus) else {
        panic!()
    };
    assert_eq!(status.rx_errors, 2);
}
