//! Pressure control: the pump's mode (off / regulating with the PID / manual duty) and the
//! vent valve.
//!
//! While regulating, the PID runs every [`CONTROL_PERIOD_US`] (1 kHz) whatever the tick
//! rate, and its setpoint is slewed towards the commanded one at a limited rate (a
//! bumpless setpoint change: the proportional term follows a ramp instead of a step, which
//! also keeps the overshoot of large steps small). Regulating starts from the measured
//! pressure and the pump's current duty (bumpless transfer).

use protocol::{PidGains, PressureMode};

use crate::device_constants::CONTROL_PERIOD_US;
use crate::pid::{Pid, clamp};

/// Longest control step the PID integrates at once (if ticks stall, e.g. under a debugger,
/// the integral must not jump).
const MAX_CONTROL_DT_S: f32 = 0.01;

/// The pump and vent state machine.
#[derive(Debug, Clone, Copy)]
pub struct PressureControl {
    mode: PressureMode,
    pid: Pid,
    /// Setpoint commanded by the host.
    setpoint_kpa: f32,
    /// Setpoint the PID is following (slewed towards `setpoint_kpa`).
    ramped_setpoint_kpa: f32,
    slew_kpa_per_s: f32,
    duty: f32,
    vent_open: bool,
    next_control_us: u64,
    last_control_us: u64,
}

impl PressureControl {
    pub const fn new(gains: PidGains, slew_kpa_per_s: f32) -> Self {
        Self {
            mode: PressureMode::Off,
            pid: Pid::new(gains, 0.0, 1.0),
            setpoint_kpa: 0.0,
            ramped_setpoint_kpa: 0.0,
            slew_kpa_per_s,
            duty: 0.0,
            vent_open: false,
            next_control_us: 0,
            last_control_us: 0,
        }
    }

    pub fn mode(&self) -> PressureMode {
        self.mode
    }

    /// Setpoint commanded by the host (0 when not regulating).
    pub fn setpoint_kpa(&self) -> f32 {
        self.setpoint_kpa
    }

    /// Setpoint the PID currently follows.
    pub fn ramped_setpoint_kpa(&self) -> f32 {
        self.ramped_setpoint_kpa
    }

    pub fn gains(&self) -> PidGains {
        self.pid.gains()
    }

    /// Pump duty as a fraction (0..=1).
    pub fn duty(&self) -> f32 {
        self.duty
    }

    /// Pump duty in 1/10000.
    pub fn duty_per_10k(&self) -> u16 {
        duty_per_10k(self.duty)
    }

    pub fn vent_open(&self) -> bool {
        self.vent_open
    }

    /// Regulates to `setpoint_kpa`; closes the vent (regulating against an open vent would
    /// only saturate the pump). The setpoint ramp starts at the measured pressure. From
    /// manual mode the transfer is bumpless (the PID continues from the manual duty); from
    /// off, the stopped pump's zero duty means nothing, so the PID starts from its
    /// feed-forward with an empty integral.
    pub fn regulate(&mut self, setpoint_kpa: f32, measured_kpa: f32, now_us: u64) {
        if self.mode != PressureMode::Regulating {
            self.ramped_setpoint_kpa = measured_kpa;
            let from_duty = if self.mode == PressureMode::Manual {
                self.duty
            } else {
                self.pid.gains().feed_forward_per_kpa * measured_kpa
            };
            self.pid.start(from_duty, measured_kpa, measured_kpa);
            self.mode = PressureMode::Regulating;
            self.next_control_us = now_us;
            self.last_control_us = now_us;
        }
        self.setpoint_kpa = setpoint_kpa;
        self.vent_open = false;
    }

    /// Pump off, regulation stopped; the vent keeps its state.
    pub fn off(&mut self) {
        self.mode = PressureMode::Off;
        self.duty = 0.0;
        self.setpoint_kpa = 0.0;
    }

    /// Open-loop pump duty (fraction 0..=1); stops regulation.
    pub fn manual(&mut self, duty: f32) {
        self.mode = PressureMode::Manual;
        self.duty = clamp(duty, 0.0, 1.0);
        self.setpoint_kpa = 0.0;
    }

    /// Opens or closes the vent. Opening it while regulating stops the regulation (pump
    /// off): the two contradict each other.
    pub fn set_vent(&mut self, open: bool) {
        self.vent_open = open;
        if open && self.mode == PressureMode::Regulating {
            self.off();
        }
    }

    /// Replaces the PID gains without a jump in the output.
    pub fn set_gains(&mut self, gains: PidGains, measured_kpa: f32) {
        self.pid
            .set_gains(gains, self.ramped_setpoint_kpa, measured_kpa);
    }

    /// Runs the PID when its period is due; returns the pump duty fraction to apply.
    pub fn tick(&mut self, now_us: u64, measured_kpa: f32) -> f32 {
        if self.mode == PressureMode::Regulating && now_us >= self.next_control_us {
            let dt_s =
                (now_us.saturating_sub(self.last_control_us) as f32 * 1e-6).min(MAX_CONTROL_DT_S);
            self.last_control_us = now_us;
            self.next_control_us += u64::from(CONTROL_PERIOD_US);
            if self.next_control_us <= now_us {
                self.next_control_us = now_us + u64::from(CONTROL_PERIOD_US);
            }
            let max_step = self.slew_kpa_per_s * dt_s;
            let gap = self.setpoint_kpa - self.ramped_setpoint_kpa;
            self.ramped_setpoint_kpa += clamp(gap, -max_step, max_step);
            self.duty = self
                .pid
                .update(self.ramped_setpoint_kpa, measured_kpa, dt_s);
        }
        self.duty
    }
}

/// A duty fraction in 1/10000, saturated to 0..=10000.
pub fn duty_per_10k(duty: f32) -> u16 {
    (clamp(duty, 0.0, 1.0) * 10_000.0 + 0.5) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    const GAINS: PidGains = PidGains {
        kp: 0.3,
        ki: 2.0,
        kd: 0.0,
        feed_forward_per_kpa: 0.02,
    };

    #[test]
    fn pid_runs_at_one_kilohertz_whatever_the_tick_rate() {
        let mut p = PressureControl::new(GAINS, 1000.0);
        p.regulate(10.0, 10.0, 0);
        // Constant 2 kPa error: the integral grows by ki*e*dt = 0.004 per PID step.
        let mut t = 0;
        let mut outputs = [0.0f32; 5];
        for out in &mut outputs {
            t += 500;
            let _ = p.tick(t, 8.0);
            t += 500;
            *out = p.tick(t, 8.0);
        }
        for w in outputs.windows(2) {
            assert!(((w[1] - w[0]) - 0.004).abs() < 1e-5, "{outputs:?}");
        }
    }

    #[test]
    fn setpoint_is_slewed() {
        let mut p = PressureControl::new(GAINS, 50.0);
        p.regulate(15.0, 0.0, 0);
        for k in 1..=100u64 {
            p.tick(k * 1000, 0.0);
        }
        // 100 ms at 50 kPa/s.
        assert!((p.ramped_setpoint_kpa() - 5.0).abs() < 1e-3);
    }

    #[test]
    fn venting_stops_regulation_and_off_keeps_the_vent() {
        let mut p = PressureControl::new(GAINS, 50.0);
        p.set_vent(true);
        p.regulate(6.0, 0.0, 0);
        assert!(!p.vent_open());
        p.set_vent(true);
        assert_eq!(p.mode(), PressureMode::Off);
        assert_eq!(p.duty(), 0.0);
        p.off();
        assert!(p.vent_open());
        p.manual(0.25);
        assert_eq!(p.duty_per_10k(), 2500);
        assert_eq!(p.tick(1000, 3.0), 0.25);
    }
}
