//! The pressure PID on the pneumatic plant model (support/plant.rs): step responses to the
//! paper's two operating points, a broken-integral control case, and rejection of the
//! sudden volume change caused by indenting the shell.
//!
//! Acceptance, and why:
//! - settling band ±2 % of the setpoint: hil-sim's bench tests hold the pressure within 2 %
//!   while indenting, and the FE model's pressure grid is read at that precision;
//! - settling time <= 0.5 s from the command: the host waits for the pressure before an
//!   indentation that itself lasts ~1.7 s; the default gains settle in 0.11 s (6 kPa) and
//!   0.22 s (15 kPa) on this plant, so 0.5 s leaves a 2x margin for model changes while a
//!   loop without integral action never settles (`proportional_only_misses_the_band`) and
//!   the plant's own open-loop time constant is ~0.4 s;
//! - overshoot <= 5 %: at 15 kPa that is 15.75 kPa, keeping 4 kPa of margin below the 20 kPa
//!   overpressure trip with the shell's stiffness changing by no more than the 2 % band.

mod support;

use controller::ControllerConfig;
use controller::controller::DEFAULT_GAINS;
use protocol::{FaultFlags, PidGains, Request};
use support::Bench;

struct StepResponse {
    settling_s: f64,
    overshoot_pct: f64,
    final_kpa: f64,
    max_kpa: f64,
}

/// Commands `setpoint` at t = 0 and runs 3 s; settling is the last time the pressure was
/// outside the ±2 % band.
fn step_response(bench: &mut Bench, setpoint: f64) -> StepResponse {
    let start = bench.now_us;
    bench.ack(Request::SetPressure {
        setpoint_kpa: setpoint as f32,
    });
    let band = 0.02 * setpoint;
    let mut last_outside_us = start;
    let mut max_kpa = f64::MIN;
    bench.run_ms(3000, |t, p, _| {
        if (p - setpoint).abs() > band {
            last_outside_us = t;
        }
        max_kpa = max_kpa.max(p);
    });
    StepResponse {
        settling_s: (last_outside_us - start) as f64 * 1e-6,
        overshoot_pct: ((max_kpa - setpoint) / setpoint * 100.0).max(0.0),
        final_kpa: bench.plant.pressure_kpa,
        max_kpa,
    }
}

fn assert_step(setpoint: f64) {
    let mut bench = Bench::new();
    bench.run_quiet_ms(50);
    let r = step_response(&mut bench, setpoint);
    println!(
        "step 0 -> {setpoint} kPa: settling (2 %) {:.3} s, overshoot {:.2} %, peak {:.3} kPa, final {:.3} kPa",
        r.settling_s, r.overshoot_pct, r.max_kpa, r.final_kpa
    );
    assert!(r.settling_s <= 0.5, "settling {:.3} s", r.settling_s);
    assert!(r.overshoot_pct <= 5.0, "overshoot {:.2} %", r.overshoot_pct);
    assert!((r.final_kpa - setpoint).abs() <= 0.02 * setpoint);
    assert!(bench.ctl.faults().is_empty(), "{:?}", bench.ctl.faults());
}

#[test]
fn holds_6_kpa() {
    assert_step(6.0);
}

#[test]
fn holds_15_kpa() {
    assert_step(15.0);
}

#[test]
fn setpoint_change_6_to_15_kpa_is_bumpless() {
    let mut bench = Bench::new();
    step_response(&mut bench, 6.0);
    let duty_before = bench.last.pump_duty_per_10k;
    bench.ack(Request::SetPressure { setpoint_kpa: 15.0 });
    let out = bench.tick();
    // The setpoint slews at 100 kPa/s: one tick later the duty has moved by no more than
    // Kp * 100 kPa/s * 1 ms = 0.06 of full scale (600/10000) plus the derivative's share of
    // the ADC noise; an unslewed 9 kPa step would have saturated the pump (Kp * 9 = 5.4).
    let jump = (i32::from(out.pump_duty_per_10k) - i32::from(duty_before)).abs();
    assert!(jump <= 800, "duty jumped by {jump}/10000");
    let r = step_response(&mut bench, 15.0);
    println!(
        "step 6 -> 15 kPa: settling {:.3} s, overshoot {:.2} %",
        r.settling_s, r.overshoot_pct
    );
    assert!(r.settling_s <= 0.5 && r.overshoot_pct <= 5.0);
}

/// Control case: with the integral (and feed-forward) removed the loop cannot hold the
/// setpoint against the leak, and the same acceptance test fails. This is what makes the
/// assertions above able to catch a broken PID.
#[test]
fn proportional_only_misses_the_band() {
    let config = ControllerConfig {
        gains: PidGains {
            ki: 0.0,
            feed_forward_per_kpa: 0.0,
            ..DEFAULT_GAINS
        },
        ..ControllerConfig::default()
    };
    let mut bench = Bench::with_config(config);
    let r = step_response(&mut bench, 6.0);
    // Offset = holding duty / Kp = 0.1 / 0.6 kPa = 0.17 kPa = 2.8 % of 6 kPa.
    let expected_offset = bench.plant.holding_duty(r.final_kpa) / f64::from(DEFAULT_GAINS.kp);
    assert!(
        ((6.0 - r.final_kpa) - expected_offset).abs() < 0.05,
        "{}",
        r.final_kpa
    );
    assert!(r.settling_s > 1.0);
}

#[test]
fn rejects_a_sudden_volume_shrink() {
    for setpoint in [6.0, 15.0] {
        let mut bench = Bench::new();
        step_response(&mut bench, setpoint);
        // The shell is indented: the gas volume shrinks by 2 % at once.
        let v = bench.plant.volume_ml;
        let p_abs = bench.plant.p_atm_kpa + bench.plant.pressure_kpa;
        bench.plant.set_volume_ml(v * 0.98);
        // Boyle: the jump is p_abs * (1/0.98 - 1), 2.2 kPa at 6 kPa, 2.4 kPa at 15 kPa.
        let jump = bench.plant.pressure_kpa - setpoint;
        assert!((jump - p_abs * (1.0 / 0.98 - 1.0)).abs() < 0.05 * p_abs * 0.0204);
        let start = bench.now_us;
        let mut last_outside_us = start;
        let mut min_duty = u16::MAX;
        bench.run_ms(2000, |t, p, out| {
            if (p - setpoint).abs() > 0.02 * setpoint {
                last_outside_us = t;
            }
            min_duty = min_duty.min(out.pump_duty_per_10k);
        });
        let recovery_s = (last_outside_us - start) as f64 * 1e-6;
        println!(
            "volume -2 % at {setpoint} kPa: jump {jump:.2} kPa, back within 2 % after {recovery_s:.3} s"
        );
        // The pump can only stop (not suck): recovery relies on the leak, whose time
        // constant at 15 kPa is V/(p_abs*c_leak) ~ 0.5 s for the full offset; 1.5 s allows
        // the integral to unwind too.
        assert!(recovery_s <= 1.5, "recovery {recovery_s:.3} s");
        // The controller reacted: the pump was throttled well below its holding duty.
        let holding = bench.plant.holding_duty(setpoint) * 10_000.0;
        assert!(f64::from(min_duty) < 0.5 * holding, "min duty {min_duty}");
        assert!((bench.plant.pressure_kpa - setpoint).abs() <= 0.02 * setpoint);
        assert_eq!(bench.ctl.faults(), FaultFlags(0));
    }
}

#[test]
fn regulating_again_after_pressure_off_recovers_quickly() {
    let mut bench = Bench::new();
    step_response(&mut bench, 15.0);
    bench.ack(Request::PressureOff);
    bench.run_quiet_ms(100);
    let dropped = bench.plant.pressure_kpa;
    assert!(dropped < 14.0, "{dropped}");
    // Back to 15 kPa from ~13 kPa: the PID starts from its feed-forward (settles in 0.07 s
    // here). A PID that took over the stopped pump's zero duty "bumplessly" would start
    // with an integral of -Kff*13 kPa and creep back at Ki/Kp (0.37 s here): 0.2 s tells
    // them apart.
    let r = step_response(&mut bench, 15.0);
    println!(
        "re-regulating from {dropped:.2} kPa: settling {:.3} s",
        r.settling_s
    );
    assert!(
        r.settling_s <= 0.2 && r.overshoot_pct <= 5.0,
        "{:.3} s",
        r.settling_s
    );
}
