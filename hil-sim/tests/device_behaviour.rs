//! The firmware's controller inside the simulated bench: pressure regulation against the
//! indentation disturbance, the safety supervisor, and reproducibility.

#![allow(clippy::unwrap_used)] // tests may unwrap

use std::path::Path;

use controller::safety::OVERPRESSURE_CLEAR_MARGIN_KPA;
use hil_sim::device::SimDevice;
use hil_sim::scenario::Scenario;
use protocol::FaultFlags;

/// A rigid-sample scenario (closed-form mechanics: the largest volume disturbance, since the
/// apex travels the whole stage travel) with the given extra TOML.
fn scenario(extra: &str) -> Scenario {
    let text = format!(
        r#"
        seed = 11
        {extra}
        [mechanics]
        source = "rigid"
        "#
    );
    Scenario::parse(&text, Path::new("test-scenario.toml")).unwrap()
}

fn hold_while_indenting(setpoint_kpa: f64) {
    let s = scenario(&format!(
        r#"
        [[programme]]
        at_s = 0.0
        request = {{ SetPressure = {{ setpoint_kpa = {setpoint_kpa:.1} }} }}
        [[programme]]
        at_s = 1.5
        indent_to_mm = 1.7
        speed_mm_per_s = 1.0
        "#
    ));
    let mut dev = SimDevice::new(s).unwrap();
    dev.set_camera_enabled(false);
    dev.record_truth();
    dev.run_until(6.0);
    let truth = dev.take_truth();
    // From settling (1.5 s: a 15 kPa step slews at 50 kPa/s and the loop settles in well
    // under a second) through the approach (1 mm at 1 mm/s), the 1.7 mm indentation and the
    // hold at depth.
    let window: Vec<_> = truth.iter().filter(|t| t.t_s >= 1.5).collect();
    let worst = window
        .iter()
        .map(|t| (t.pressure_kpa - setpoint_kpa).abs())
        .fold(0.0, f64::max);
    assert!(
        worst <= 0.02 * setpoint_kpa,
        "worst deviation {worst:.4} kPa at {setpoint_kpa} kPa"
    );
    // The indentation really happened and really disturbed the gas: the apex went up by
    // 1.7 mm and the shell lost tens of mm^3.
    let last = truth.last().unwrap();
    assert!(
        (last.contact.h_mm - 1.7).abs() < 1e-3,
        "{}",
        last.contact.h_mm
    );
    let v0 = window[0].contact.shell_volume_mm3;
    assert!(v0 - last.contact.shell_volume_mm3 > 30.0);
    assert_eq!(last.faults, 0);
    eprintln!("setpoint {setpoint_kpa} kPa: worst deviation {worst:.4} kPa");
}

#[test]
fn pid_holds_6_kpa_within_2_percent_while_indenting() {
    hold_while_indenting(6.0);
}

#[test]
fn pid_holds_15_kpa_within_2_percent_while_indenting() {
    hold_while_indenting(15.0);
}

#[test]
fn overpressure_trips_within_one_control_tick() {
    let s = scenario(
        r#"
        [faults]
        overpressure = { at_s = 1.0, rise_kpa = 12.0, duration_s = 0.005 }
        [[programme]]
        at_s = 0.0
        request = { SetPressure = { setpoint_kpa = 15.0 } }
        "#,
    );
    let mut dev = SimDevice::new(s).unwrap();
    dev.set_camera_enabled(false);
    dev.record_truth();
    dev.run_until(1.2);
    let truth = dev.take_truth();
    let limit = f64::from(controller::device_constants::OVERPRESSURE_LIMIT_KPA);
    // The first tick whose manometer reading is above the limit.
    let first = truth
        .iter()
        .position(|t| {
            f64::from(controller::device_constants::manometer_kpa(
                t.inputs.manometer_counts,
            )) > limit
        })
        .expect("the event must push the reading over the limit");
    let t = &truth[first];
    assert!(t.t_s >= 1.0);
    // Same tick: pump off, vent open, fault latched.
    assert_eq!(t.outputs.pump_duty_per_10k, 0, "pump still on at {}", t.t_s);
    assert!(t.outputs.vent_open);
    assert!(FaultFlags(t.faults).contains(FaultFlags::OVERPRESSURE));
    // Before it the pump ran and the vent was shut.
    assert!(!truth[first - 1].outputs.vent_open);
    // The vent then empties the shell; the fault stays latched.
    let end = truth.last().unwrap();
    assert!(end.pressure_kpa < limit - OVERPRESSURE_CLEAR_MARGIN_KPA as f64);
    assert!(end.pressure_kpa < 1.0, "{}", end.pressure_kpa);
    assert!(FaultFlags(end.faults).contains(FaultFlags::OVERPRESSURE));
}

#[test]
fn heartbeat_loss_stops_the_pump_and_the_stage() {
    // Explicit heartbeats until 1.0 s, then silence (the programme heartbeat is off).
    let s = scenario(
        r#"
        programme_heartbeat_s = 0.0
        [[programme]]
        at_s = 0.0
        request = { SetPressure = { setpoint_kpa = 6.0 } }
        [[programme]]
        at_s = 0.5
        indent_to_mm = 1.5
        speed_mm_per_s = 0.5
        [[programme]]
        at_s = 1.0
        request = "Heartbeat"
        "#,
    );
    let mut dev = SimDevice::new(s).unwrap();
    dev.set_camera_enabled(false);
    dev.record_truth();
    dev.run_until(3.0);
    let truth = dev.take_truth();
    let timeout_s = f64::from(controller::device_constants::HEARTBEAT_TIMEOUT_MS) * 1e-3;
    let trip = truth
        .iter()
        .find(|t| FaultFlags(t.faults).contains(FaultFlags::HEARTBEAT_LOST))
        .expect("heartbeat fault");
    // Trips one timeout after the last request (the clock's offset and ppm are small).
    assert!((trip.t_s - (1.0 + timeout_s)).abs() < 2e-3, "{}", trip.t_s);
    assert_eq!(trip.outputs.pump_duty_per_10k, 0);
    // The pump was regulating before the trip (it may idle for a moment while the indentation
    // compresses the shell, as the pump cannot suck) and never runs after it.
    assert!(
        truth
            .iter()
            .any(|t| t.t_s < trip.t_s && t.t_s > trip.t_s - 1.0 && t.outputs.pump_duty_per_10k > 0)
    );
    assert!(
        truth
            .iter()
            .filter(|t| t.t_s >= trip.t_s)
            .all(|t| t.outputs.pump_duty_per_10k == 0)
    );
    // The stage decelerates and stops short of its 1.5 mm target.
    let end = truth.last().unwrap();
    assert_eq!(end.outputs.stage.steps, 0);
    assert!(end.contact.h_mm < 1.5);
    assert!(!dev.controller().stage().is_moving());
}

#[test]
fn a_scenario_is_bit_for_bit_reproducible_from_its_seed() {
    let extra = r#"
        [faults]
        byte_corruption_rate = 0.001
        camera_drop_rate = 0.1
        [[programme]]
        at_s = 0.0
        request = { SetPressure = { setpoint_kpa = 6.0 } }
        [[programme]]
        at_s = 0.05
        request = { StartStream = { rate_hz = 2000, channels = 31 } }
        [[programme]]
        at_s = 0.1
        request = { SetLed = { duty_per_10k = 8000 } }
        [[programme]]
        at_s = 0.2
        indent_to_mm = 0.0
        speed_mm_per_s = 2.0
    "#;
    let run = |seed: u64| {
        let mut s = scenario(extra);
        s.seed = seed;
        let mut dev = SimDevice::new(s).unwrap();
        dev.run_until(0.7);
        let bytes = dev.take_tx_until(f64::INFINITY);
        let frames = dev.take_frames();
        (bytes, frames, dev.stats())
    };
    let (b1, f1, s1) = run(5);
    let (b2, f2, s2) = run(5);
    let (b3, _, _) = run(6);
    assert!(b1.len() > 10_000, "{}", b1.len());
    assert!(!f1.is_empty());
    assert_eq!(b1, b2);
    assert_eq!(f1, f2);
    assert_eq!(s1, s2);
    assert_ne!(b1, b3);
}

/// A bench behind the wall clock skips the frames that are already late instead of
/// rendering them, counts them, and renders every frame again once it has caught up.
#[test]
fn frames_behind_the_camera_deadline_are_skipped_and_counted() {
    let mut dev = SimDevice::new(scenario("")).unwrap();
    let fps = dev.scenario().camera.fps;
    // Half a second of frames that are all late (the deadline is ahead of them).
    dev.set_camera_deadline(Some(0.5));
    while dev.time_s() < 0.5 {
        dev.step();
    }
    let late = dev.take_frames();
    let stats = dev.stats();
    assert!(late.is_empty(), "{} late frames rendered", late.len());
    // 0.5 s at the scenario's frame rate, give or take the frame phase
    let expected = 0.5 * fps;
    assert!(
        (stats.frames_late as f64 - expected).abs() <= 1.0,
        "{} frames counted late, expected about {expected}",
        stats.frames_late
    );
    // Caught up: the next half second renders every frame.
    dev.set_camera_deadline(Some(0.5));
    while dev.time_s() < 1.0 {
        dev.step();
    }
    let on_time = dev.take_frames();
    assert!(
        (on_time.len() as f64 - 0.5 * fps).abs() <= 1.0,
        "{}",
        on_time.len()
    );
    assert!(on_time.iter().all(|f| f.timestamp_us >= 500_000));
    assert_eq!(dev.stats().frames_late, stats.frames_late);
}
