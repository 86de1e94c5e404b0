//! The pressure PID on the pneumatic plant model (`pneumatic-plant`, the emulated bench's
//! own): step responses to the paper's two operating points, the same on plants that differ
//! from the nominal one, a broken-integral control case, and rejection of the sudden volume
//! change caused by indenting the shell.
//!
//! Acceptance, and why:
//! - settling band ±2 % of the setpoint: hil-sim's bench tests hold the pressure within 2 %
//!   while indenting, and the FE model's pressure grid is read at that precision;
//! - settling time <= 0.5 s from the command: the host waits for the pressure before an
//!   indentation that itself lasts ~1.7 s; the default gains settle in 0.14 s (6 kPa) and
//!   0.24 s (15 kPa) on this plant, so 0.5 s leaves a 2x margin for model changes
//!   (`default_gains_tolerate_plant_variations`); the plant's own open-loop time constant is
//!   ~0.4 s;
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
        final_kpa: bench.plant.gauge_kpa(),
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

/// The default gains on plants that differ from the nominal one as a real sensor may (another
/// pump, longer tubing, a tighter or leakier shell): every step still settles within 0.5 s, and
/// overshoots by at most 10 % (0.6 kPa at 6 kPa; at 15 kPa 1.5 kPa, still 3.5 kPa below the
/// overpressure trip). The pump's lag is what the loop's phase margin depends on most: at
/// 60 ms (twice the nominal) the 6 kPa step overshoots by ~20 %, so the variants stop at 45 ms.
#[test]
fn default_gains_tolerate_plant_variations() {
    use pneumatic_plant::{Pneumatics, PneumaticsConfig};
    let nominal = PneumaticsConfig::default();
    let with = |f: &dyn Fn(&mut PneumaticsConfig)| {
        let mut c = nominal.clone();
        f(&mut c);
        c
    };
    let variants = [
        ("pump lag 15 ms", with(&|c| c.pump_time_constant_s = 0.015)),
        ("pump lag 45 ms", with(&|c| c.pump_time_constant_s = 0.045)),
        ("dead volume -30 %", with(&|c| c.dead_volume_mm3 *= 0.7)),
        ("dead volume +50 %", with(&|c| c.dead_volume_mm3 *= 1.5)),
        (
            "leak x0.5",
            with(&|c| c.leak_conductance_mm3_per_s_per_kpa *= 0.5),
        ),
        (
            "leak x2",
            with(&|c| c.leak_conductance_mm3_per_s_per_kpa *= 2.0),
        ),
        (
            "pump flow -30 %",
            with(&|c| c.pump_free_flow_mm3_per_s *= 0.7),
        ),
        (
            "pump flow +30 %",
            with(&|c| c.pump_free_flow_mm3_per_s *= 1.3),
        ),
    ];
    let mut failures = Vec::new();
    for (name, cfg) in variants {
        for setpoint in [6.0, 15.0] {
            let mut bench = Bench::new();
            bench.plant = Pneumatics::new(cfg.clone(), support::SHELL_VOLUME_MM3, 0.0);
            bench.run_quiet_ms(50);
            let r = step_response(&mut bench, setpoint);
            println!(
                "{name}: 0 -> {setpoint} kPa settles (2 %) in {:.3} s, overshoot {:.2} %",
                r.settling_s, r.overshoot_pct
            );
            if r.settling_s > 0.5 || r.overshoot_pct > 10.0 {
                failures.push(format!(
                    "{name}, {setpoint} kPa: {:.3} s, {:.2} %",
                    r.settling_s, r.overshoot_pct
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Control case: with the integral and the feed-forward removed the loop cannot hold the
/// setpoint against the leak. Its steady offset is the proportional loop's textbook one
/// (holding duty / Kp: 0.216 / 0.9 = 0.24 kPa at 15 kPa), while the full controller's is
/// below a tenth of it: the regulation tests above measure the integral action, and a broken
/// integral would show here.
#[test]
fn proportional_only_keeps_the_textbook_offset() {
    let config = ControllerConfig {
        gains: PidGains {
            ki: 0.0,
            feed_forward_per_kpa: 0.0,
            ..DEFAULT_GAINS
        },
        ..ControllerConfig::default()
    };
    let mut bench = Bench::with_config(config);
    let r = step_response(&mut bench, 15.0);
    let expected_offset =
        bench.plant.holding_duty(r.final_kpa).expect("below stall") / f64::from(DEFAULT_GAINS.kp);
    let offset = 15.0 - r.final_kpa;
    // 0.01 kPa: ten times the manometer's quantisation (0.001 kPa a count) after 3 s.
    assert!(
        (offset - expected_offset).abs() < 0.01,
        "offset {offset}, expected {expected_offset}"
    );
    let mut full = Bench::new();
    let full_offset = (15.0 - step_response(&mut full, 15.0).final_kpa).abs();
    assert!(
        full_offset < 0.1 * offset,
        "PID offset {full_offset} vs P-only {offset}"
    );
}

#[test]
fn rejects_a_sudden_volume_shrink() {
    for setpoint in [6.0, 15.0] {
        let mut bench = Bench::new();
        step_response(&mut bench, setpoint);
        // The shell is indented: the gas volume shrinks by 2 % at once.
        let v = bench.plant.volume_mm3();
        let p_abs = bench.plant.config().atmosphere_kpa + bench.plant.gauge_kpa();
        let dead = bench.plant.config().dead_volume_mm3;
        bench.plant.set_shell_volume(v * 0.98 - dead);
        // Boyle: the jump is p_abs * (1/0.98 - 1), 2.2 kPa at 6 kPa, 2.4 kPa at 15 kPa.
        let jump = bench.plant.gauge_kpa() - setpoint;
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
        let holding = bench.plant.holding_duty(setpoint).expect("below stall") * 10_000.0;
        assert!(f64::from(min_duty) < 0.5 * holding, "min duty {min_duty}");
        assert!((bench.plant.gauge_kpa() - setpoint).abs() <= 0.02 * setpoint);
        assert_eq!(bench.ctl.faults(), FaultFlags(0));
    }
}

#[test]
fn regulating_again_after_pressure_off_recovers_quickly() {
    let mut bench = Bench::new();
    step_response(&mut bench, 15.0);
    bench.ack(Request::PressureOff);
    bench.run_quiet_ms(100);
    let dropped = bench.plant.gauge_kpa();
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
