//! Injected faults reach the firmware as a real bench's failures would, and its safety
//! supervisor reacts.

#![allow(clippy::unwrap_used)] // tests may unwrap

use std::path::Path;

use hil_sim::device::SimDevice;
use hil_sim::scenario::Scenario;
use protocol::{
    DeviceMessage, FaultFlags, FrameDecoder, MAX_FRAME_LEN, Reply, Request, RequestFrame,
    encode_frame,
};

fn device(extra: &str) -> SimDevice {
    let text = format!(
        r#"
        seed = 21
        {extra}
        [[programme]]
        at_s = 0.0
        request = {{ SetPressure = {{ setpoint_kpa = 6.0 }} }}
        [mechanics]
        source = "rigid"
        "#
    );
    let mut dev =
        SimDevice::new(Scenario::parse(&text, Path::new("faults.toml")).unwrap()).unwrap();
    dev.set_camera_enabled(false);
    dev.record_truth();
    dev
}

#[test]
fn a_saturated_manometer_latches_a_range_fault_and_vents() {
    let mut dev = device(
        "[faults]\nsensor_saturation = { at_s = 1.0, sensor = \"manometer\", rail = \"high\" }",
    );
    dev.run_until(1.5);
    let truth = dev.take_truth();
    let trip = truth
        .iter()
        .find(|t| t.faults != 0)
        .expect("a fault latches");
    // The very first tick at the rail: 97.5 % of supply is outside the 5..95 % window.
    assert!(trip.t_s >= 1.0 && trip.t_s < 1.0 + 1e-3, "{}", trip.t_s);
    assert!(FaultFlags(trip.faults).contains(FaultFlags::MANOMETER_RANGE));
    assert_eq!(trip.outputs.pump_duty_per_10k, 0);
    assert!(trip.outputs.vent_open);
    assert!(truth.last().unwrap().pressure_kpa < 0.5);
}

#[test]
fn a_stalled_pump_and_a_growing_leak_lose_the_pressure() {
    let mut dev = device("[faults]\npump_stall_at_s = 1.0");
    dev.run_until(3.0);
    let truth = dev.take_truth();
    let at = |t: f64| truth.iter().find(|x| x.t_s >= t).unwrap();
    assert!((at(0.99).pressure_kpa - 6.0).abs() < 0.2);
    // The controller drives the pump harder and harder; the bleed empties the shell with
    // the plant's time constant (~0.8 s).
    assert!(at(2.9).pressure_kpa < 1.0, "{}", at(2.9).pressure_kpa);
    assert!(at(2.9).outputs.pump_duty_per_10k > 5000);

    let mut dev = device("[faults]\nleak_increase = { at_s = 1.0, factor = 4.0 }");
    dev.run_until(4.0);
    let truth = dev.take_truth();
    let at = |t: f64| truth.iter().find(|x| x.t_s >= t).unwrap();
    // The PID compensates the fourfold leak with more duty and holds the setpoint.
    assert!(
        (at(3.9).pressure_kpa - 6.0).abs() < 0.12,
        "{}",
        at(3.9).pressure_kpa
    );
    assert!(at(3.9).outputs.pump_duty_per_10k > 2 * at(0.99).outputs.pump_duty_per_10k);
}

#[test]
fn corrupted_bytes_cost_frames_and_are_counted_by_the_device() {
    let mut dev = device("[faults]\nbyte_corruption_rate = 0.02");
    let mut decoder = FrameDecoder::<DeviceMessage>::new();
    let (mut acks, mut bad_frames) = (0, 0);
    let mut status = None;
    for i in 0..200u16 {
        let t = 0.01 * f64::from(i);
        dev.run_until(t);
        let mut buf = [0u8; MAX_FRAME_LEN];
        let request = if i == 199 {
            Request::GetStatus
        } else {
            Request::Ping {
                host_time_us: u64::from(i),
            }
        };
        let n = encode_frame(&RequestFrame { seq: i, request }, &mut buf).unwrap();
        dev.host_write(&buf[..n], t);
    }
    dev.run_until(2.1);
    for result in decoder.push(&dev.take_tx_until(f64::INFINITY)) {
        match result {
            Ok(DeviceMessage::Ack {
                reply: Reply::Status(s),
                ..
            }) => status = Some(s),
            Ok(DeviceMessage::Ack { .. }) => acks += 1,
            Ok(_) => {}
            Err(_) => bad_frames += 1,
        }
    }
    // ~16-byte request frames at 2 % per byte: ~28 % of requests are damaged; replies too.
    assert!(acks > 80 && acks < 190, "{acks} acks");
    assert!(bad_frames > 0);
    let stats = dev.stats();
    assert!(stats.bytes_corrupted > 0 && stats.rx_frame_errors > 0);
    if let Some(s) = status {
        assert!(s.rx_errors > 0);
    }
}
