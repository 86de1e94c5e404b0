//! Every safety trip of the supervisor (`controller::safety`), its latching, its single report
//! and its clearing.

mod support;

use controller::device_constants::{MANOMETER_MAX_VALID_COUNTS, manometer_counts};
use controller::{ControllerConfig, Outputs, RawInputs};
use protocol::{DeviceMessage, FaultFlags, NackCode, PressureMode, Reply, Request, StatusFlags};
use support::{Bench, ManometerFault};

fn fault_reports(bench: &Bench) -> Vec<protocol::FaultReport> {
    bench
        .outgoing
        .iter()
        .filter_map(|m| match m {
            DeviceMessage::Fault(r) => Some(*r),
            _ => None,
        })
        .collect()
}

fn regulating_bench(setpoint: f32) -> Bench {
    let mut bench = Bench::new();
    bench.ack(Request::SetPressure {
        setpoint_kpa: setpoint,
    });
    bench.run_quiet_ms(500);
    assert!(bench.last.pump_duty_per_10k > 0);
    bench
}

#[test]
fn overpressure_stops_pump_and_opens_vent_in_the_same_tick() {
    let mut bench = regulating_bench(15.0);
    bench.ack(Request::MoveStage {
        target_steps: 100_000,
        speed_steps_per_s: 8000,
        accel_steps_per_s2: 40_000,
    });
    bench.run_quiet_ms(100);
    // One tick whose manometer reads just above the 20 kPa limit.
    let t = bench.now_us + 500;
    let out: Outputs = bench.ctl.tick(
        t,
        &RawInputs {
            proximity_counts: 0,
            manometer_counts: manometer_counts(20.05),
            load_counts: None,
        },
    );
    assert_eq!(
        out.pump_duty_per_10k, 0,
        "pump must stop in the tripping tick"
    );
    assert!(out.vent_open, "vent must open in the tripping tick");
    assert!(bench.ctl.faults().contains(FaultFlags::OVERPRESSURE));
    assert_eq!(bench.ctl.pressure_mode(), PressureMode::Off);
    // The stage decelerates (it does not keep going to its target).
    let target = bench.ctl.stage().target_steps();
    assert!(target < 100_000, "stage target {target}");
    // Reported exactly once.
    let report = bench.ctl.poll_outgoing();
    assert!(
        matches!(report, Some(DeviceMessage::Fault(r)) if r.new == FaultFlags(FaultFlags::OVERPRESSURE) && r.device_time_us == t),
        "{report:?}"
    );
    bench.run_quiet_ms(200);
    assert!(fault_reports(&bench).is_empty());
}

#[test]
fn just_below_the_limit_does_not_trip() {
    let mut bench = Bench::new();
    let out = bench.ctl.tick(
        500,
        &RawInputs {
            proximity_counts: 0,
            manometer_counts: manometer_counts(19.9),
            load_counts: None,
        },
    );
    assert!(bench.ctl.faults().is_empty());
    assert!(!out.vent_open);
}

#[test]
fn latched_until_cleared_and_cleared_only_when_the_cause_is_gone() {
    let mut bench = regulating_bench(15.0);
    // A pump running away: the plant is driven to 21 kPa by force.
    bench.plant.set_gauge_kpa(21.0);
    bench.tick();
    assert!(bench.last.vent_open);
    assert_eq!(bench.last.pump_duty_per_10k, 0);
    // While the pressure is still high, ClearFault keeps the fault.
    bench.plant.set_gauge_kpa(19.0); // inside the 2 kPa hysteresis
    bench.tick();
    let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
        panic!()
    };
    assert!(left.contains(FaultFlags::OVERPRESSURE));
    // Refused while latched: regulating, manual pump, stage moves, closing the vent.
    for req in [
        Request::SetPressure { setpoint_kpa: 6.0 },
        Request::PumpManual { duty_per_10k: 1000 },
        Request::MoveStage {
            target_steps: 10,
            speed_steps_per_s: 100,
            accel_steps_per_s2: 100,
        },
        Request::Vent { open: false },
    ] {
        assert!(matches!(
            bench.request(req),
            DeviceMessage::Nack {
                error: NackCode::Faulted,
                ..
            }
        ));
    }
    // The vent (opened by the trip) empties the shell; the latch holds meanwhile.
    bench.run_quiet_ms(300);
    assert!(bench.plant.gauge_kpa() < 1.0);
    assert!(bench.ctl.faults().contains(FaultFlags::OVERPRESSURE));
    assert!(bench.last.vent_open && bench.last.pump_duty_per_10k == 0);
    let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
        panic!()
    };
    assert!(left.is_empty(), "{left:?}");
    bench.tick();
    assert!(bench.ctl.faults().is_empty());
    // Works again.
    bench.ack(Request::SetPressure { setpoint_kpa: 6.0 });
    bench.run_quiet_ms(500);
    assert!((bench.plant.gauge_kpa() - 6.0).abs() < 0.12);
    assert!(!bench.last.vent_open);
}

#[test]
fn manometer_out_of_range_trips() {
    for counts in [0u16, 100, MANOMETER_MAX_VALID_COUNTS + 1, u16::MAX] {
        let mut bench = regulating_bench(6.0);
        bench.manometer_fault = ManometerFault::Fixed(counts);
        let out = bench.tick();
        assert!(
            bench.ctl.faults().contains(FaultFlags::MANOMETER_RANGE),
            "{counts}: {:?}",
            bench.ctl.faults()
        );
        assert_eq!(out.pump_duty_per_10k, 0);
        assert!(out.vent_open);
        // Cause present: stays latched through ClearFault.
        let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
            panic!()
        };
        assert!(left.contains(FaultFlags::MANOMETER_RANGE));
        // Sensor reconnected: clears.
        bench.manometer_fault = ManometerFault::None;
        bench.run_quiet_ms(10);
        let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
            panic!()
        };
        // A saturated-high reading also read as overpressure; with the shell vented both go.
        assert!(left.is_empty(), "{counts}: {left:?}");
    }
}

#[test]
fn stuck_manometer_trips_after_its_window_and_not_before() {
    let mut bench = regulating_bench(6.0);
    let frozen = manometer_counts(6.0);
    bench.manometer_fault = ManometerFault::Stuck(frozen);
    let stuck_ms = u64::from(ControllerConfig::default().manometer_stuck_ms);
    bench.run_quiet_ms(stuck_ms - 5);
    assert!(bench.ctl.faults().is_empty(), "tripped early");
    assert!(bench.last.pump_duty_per_10k > 0);
    bench.run_quiet_ms(10);
    assert!(bench.ctl.faults().contains(FaultFlags::MANOMETER_STUCK));
    assert_eq!(bench.last.pump_duty_per_10k, 0);
    let reports = fault_reports(&bench);
    assert_eq!(reports.len(), 1);
    assert_eq!(reports[0].new, FaultFlags(FaultFlags::MANOMETER_STUCK));
    // Still stuck: not clearable. Live again: clearable.
    let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
        panic!()
    };
    assert!(left.contains(FaultFlags::MANOMETER_STUCK));
    bench.manometer_fault = ManometerFault::None;
    bench.run_quiet_ms(5);
    let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
        panic!()
    };
    assert!(left.is_empty());
}

#[test]
fn heartbeat_timeout_stops_pump_and_stage() {
    let mut bench = regulating_bench(6.0);
    bench.ack(Request::MoveStage {
        target_steps: 100_000,
        speed_steps_per_s: 8000,
        accel_steps_per_s2: 40_000,
    });
    bench.run_quiet_ms(300);
    assert!(bench.ctl.stage().is_moving());
    // The host goes silent.
    bench.auto_heartbeat = false;
    let timeout_ms = u64::from(ControllerConfig::default().heartbeat_timeout_ms);
    // The last heartbeat was at most 200 ms ago; just before the timeout nothing happens.
    bench.run_quiet_ms(timeout_ms - 200 - 5);
    assert!(bench.ctl.faults().is_empty());
    bench.run_quiet_ms(210);
    assert!(bench.ctl.faults().contains(FaultFlags::HEARTBEAT_LOST));
    assert_eq!(bench.last.pump_duty_per_10k, 0);
    assert_eq!(bench.ctl.pressure_mode(), PressureMode::Off);
    // The stage decelerates at 40000 steps/s^2: 8000 steps/s stops within 0.2 s.
    bench.run_quiet_ms(250);
    assert!(!bench.ctl.stage().is_moving());
    assert!(bench.ctl.stage().position_steps() < 100_000);
    // Any request is a heartbeat again; the fault clears.
    let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
        panic!()
    };
    assert!(left.is_empty());
}

#[test]
fn a_quiet_host_trips_nothing_while_nothing_runs() {
    let mut bench = Bench::new();
    bench.auto_heartbeat = false;
    bench.run_quiet_ms(5000);
    assert!(bench.ctl.faults().is_empty());
    // A command-line tool asks for the status and exits.
    bench.ack(Request::GetStatus);
    bench.run_quiet_ms(5000);
    assert!(bench.ctl.faults().is_empty());
    // It starts the pump manually and exits: the heartbeat now guards the pump.
    bench.ack(Request::PumpManual { duty_per_10k: 500 });
    bench.run_quiet_ms(990);
    assert!(bench.ctl.faults().is_empty());
    assert_eq!(bench.last.pump_duty_per_10k, 500);
    bench.run_quiet_ms(20);
    assert!(bench.ctl.faults().contains(FaultFlags::HEARTBEAT_LOST));
    assert_eq!(bench.last.pump_duty_per_10k, 0);
}

#[test]
fn load_cell_timeout_is_armed_by_the_first_conversion() {
    let mut bench = Bench::new();
    bench.run_quiet_ms(2000);
    assert!(
        bench.ctl.faults().is_empty(),
        "no load cell fitted: no fault"
    );
    bench.load_period_us = Some(12_500);
    bench.run_quiet_ms(100);
    bench.load_period_us = None;
    // The last conversion came at most one 12.5 ms period before the silence began.
    bench.run_quiet_ms(780);
    assert!(bench.ctl.faults().is_empty());
    bench.run_quiet_ms(40);
    assert!(bench.ctl.faults().contains(FaultFlags::LOAD_CELL_TIMEOUT));
}

#[test]
fn watchdog_reset_is_reported_and_clearable() {
    let mut bench = Bench::new();
    bench.ctl.note_watchdog_reset(0);
    bench.tick();
    let reports = fault_reports(&bench);
    assert_eq!(reports.len(), 1);
    assert_eq!(reports[0].new, FaultFlags(FaultFlags::WATCHDOG_RESET));
    let Reply::FaultsRemaining(left) = bench.ack(Request::ClearFault) else {
        panic!()
    };
    assert!(left.is_empty());
}

#[test]
fn faults_show_in_every_sample_status() {
    let mut bench = Bench::new();
    bench.ack(Request::StartStream {
        rate_hz: 1000,
        channels: protocol::ChannelSet::ALL,
    });
    bench.run_quiet_ms(20);
    bench.plant.set_gauge_kpa(25.0);
    bench.run_quiet_ms(50);
    let reports = fault_reports(&bench);
    assert_eq!(reports.len(), 1);
    let trip_us = reports[0].device_time_us;
    let (mut before, mut after) = (0, 0);
    for m in &bench.outgoing {
        if let DeviceMessage::Samples(b) = m {
            for s in &b.samples {
                let faulted = s.status.contains(StatusFlags::FAULT);
                assert_eq!(faulted, s.device_time_us >= trip_us, "{s:?}");
                if faulted {
                    assert!(s.status.contains(StatusFlags::VENT_OPEN));
                    after += 1;
                } else {
                    before += 1;
                }
            }
        }
    }
    // 1 kHz for 20 ms before and ~50 ms after the trip (the last block may still be open).
    assert!(before >= 19 && after >= 40, "{before} {after}");
}

#[test]
fn stuck_check_can_be_disabled_for_noiseless_simulators() {
    let mut bench = Bench::with_config(ControllerConfig {
        manometer_stuck_ms: 0,
        ..ControllerConfig::default()
    });
    bench.manometer_fault = ManometerFault::Stuck(manometer_counts(0.0));
    bench.run_quiet_ms(2000);
    assert!(bench.ctl.faults().is_empty());
}
