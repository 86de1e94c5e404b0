//! Pressure PID (1 kHz), in the parallel form with derivative on measurement:
//!
//! ```text
//! u = clamp( Kff*r + Kp*e + I - Kd*dy_f/dt , u_min, u_max ),   e = r - y
//! I <- I + Ki*e*dt   (only while that does not push a saturated output further: anti-windup)
//! dy_f/dt: first-order low-pass (time constant tau_d) of the measurement's difference quotient
//! ```
//!
//! Bumpless behaviour:
//! - setpoint changes: the derivative acts on the measurement only, so a setpoint step gives
//!   no derivative kick (the pressure controller additionally slews the setpoint);
//! - gain changes: `I` is re-based so the unsaturated output is unchanged at the moment of
//!   the change (I_new = I_old + (Kp_old - Kp_new) e + (Kff_old - Kff_new) r
//!   - (Kd_old - Kd_new) dy_f);
//! - transfer from manual/off: [`Pid::start`] loads `I` with the current duty minus the
//!   feed-forward, so at zero error the output continues from the duty it took over.

use protocol::PidGains;

/// Time constant of the derivative's low-pass filter (5 ms: 5 samples at 1 kHz, well above
/// the loop's ~0.1 s dominant dynamics, so it costs little phase and blocks ADC noise).
pub const DERIVATIVE_FILTER_TAU_S: f32 = 0.005;

/// A PID controller with output limits, anti-windup and bumpless changes.
#[derive(Debug, Clone, Copy)]
pub struct Pid {
    gains: PidGains,
    out_min: f32,
    out_max: f32,
    integral: f32,
    prev_measurement: Option<f32>,
    derivative_filtered: f32,
    last_output: f32,
}

impl Pid {
    /// A controller with these gains and output limits (`out_min < out_max`).
    pub const fn new(gains: PidGains, out_min: f32, out_max: f32) -> Self {
        Self {
            gains,
            out_min,
            out_max,
            integral: 0.0,
            prev_measurement: None,
            derivative_filtered: 0.0,
            last_output: 0.0,
        }
    }

    pub fn gains(&self) -> PidGains {
        self.gains
    }

    /// The integral term in output units.
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// Output of the last [`Pid::update`].
    pub fn last_output(&self) -> f32 {
        self.last_output
    }

    /// Begins regulating from an actuator that is currently at `current_output` (bumpless
    /// transfer).
    pub fn start(&mut self, current_output: f32, setpoint: f32, measurement: f32) {
        let i = current_output - self.gains.feed_forward_per_kpa * setpoint;
        self.integral = clamp(i, self.out_min - self.out_max, self.out_max);
        self.prev_measurement = Some(measurement);
        self.derivative_filtered = 0.0;
        self.last_output = current_output;
    }

    /// Replaces the gains without a jump in the output (see the module docs).
    pub fn set_gains(&mut self, gains: PidGains, setpoint: f32, measurement: f32) {
        let old = self.gains;
        let error = setpoint - measurement;
        self.integral += (old.kp - gains.kp) * error
            + (old.feed_forward_per_kpa - gains.feed_forward_per_kpa) * setpoint
            - (old.kd - gains.kd) * self.derivative_filtered;
        self.integral = clamp(self.integral, self.out_min - self.out_max, self.out_max);
        self.gains = gains;
    }

    /// One control step of `dt_s` seconds; returns the output within the limits.
    pub fn update(&mut self, setpoint: f32, measurement: f32, dt_s: f32) -> f32 {
        let g = self.gains;
        let error = setpoint - measurement;
        if dt_s > 0.0 {
            let prev = self.prev_measurement.unwrap_or(measurement);
            let raw_derivative = (measurement - prev) / dt_s;
            let alpha = dt_s / (DERIVATIVE_FILTER_TAU_S + dt_s);
            self.derivative_filtered += alpha * (raw_derivative - self.derivative_filtered);
        }
        self.prev_measurement = Some(measurement);

        let without_integral =
            g.feed_forward_per_kpa * setpoint + g.kp * error - g.kd * self.derivative_filtered;
        let unsaturated = without_integral + self.integral;
        // Conditional integration: integrate unless the output is saturated and the error
        // would drive it further into saturation.
        let winding_up = (unsaturated >= self.out_max && error > 0.0)
            || (unsaturated <= self.out_min && error < 0.0);
        if !winding_up && dt_s > 0.0 {
            self.integral += g.ki * error * dt_s;
            self.integral = clamp(self.integral, self.out_min - self.out_max, self.out_max);
        }
        let output = clamp(without_integral + self.integral, self.out_min, self.out_max);
        self.last_output = output;
        output
    }
}

/// `value` limited to `lo..=hi`; NaN maps to `lo` (a safe pump-off output).
pub fn clamp(value: f32, lo: f32, hi: f32) -> f32 {
    if value.is_nan() || value < lo {
        lo
    } else if value > hi {
        hi
    } else {
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gains(kp: f32, ki: f32, kd: f32, ff: f32) -> PidGains {
        PidGains {
            kp,
            ki,
            kd,
            feed_forward_per_kpa: ff,
        }
    }

    #[test]
    fn proportional_integral_and_feed_forward_add_up() {
        let mut pid = Pid::new(gains(0.1, 2.0, 0.0, 0.01), 0.0, 1.0);
        pid.start(0.0, 10.0, 8.0);
        // I starts at -0.1 (= 0 - ff*r); first step: ff 0.1 + P 0.2 + I (-0.1 + 2*2*0.001).
        let u = pid.update(10.0, 8.0, 0.001);
        assert!((u - (0.1 + 0.2 - 0.1 + 0.004)).abs() < 1e-6, "{u}");
    }

    #[test]
    fn output_is_limited_and_integral_does_not_wind_up() {
        let mut pid = Pid::new(gains(0.5, 10.0, 0.0, 0.0), 0.0, 1.0);
        pid.start(0.0, 15.0, 0.0);
        for _ in 0..5000 {
            assert_eq!(pid.update(15.0, 0.0, 0.001), 1.0);
        }
        // Saturated for 5 s with a 15 kPa error: a naive integral would hold 750.
        assert!(pid.integral() <= 1.0, "integral {}", pid.integral());
        // Once the measurement passes the setpoint the output leaves saturation at once.
        let u = pid.update(15.0, 17.5, 0.001);
        assert!(u < 0.1, "{u}");
    }

    #[test]
    fn derivative_acts_on_measurement_not_setpoint() {
        let mut pid = Pid::new(gains(0.0, 0.0, 0.01, 0.0), -10.0, 10.0);
        pid.start(0.0, 5.0, 5.0);
        pid.update(5.0, 5.0, 0.001);
        // A setpoint step with the measurement constant: no derivative kick.
        assert_eq!(pid.update(15.0, 5.0, 0.001), 0.0);
        // A measurement rising at 1000 kPa/s pushes the output down (filtered).
        let u = pid.update(15.0, 6.0, 0.001);
        let alpha = 0.001 / (DERIVATIVE_FILTER_TAU_S + 0.001);
        assert!((u - (-0.01 * alpha * 1000.0)).abs() < 1e-4, "{u}");
    }

    #[test]
    fn gain_change_is_bumpless() {
        let mut pid = Pid::new(gains(0.2, 1.0, 0.001, 0.01), 0.0, 1.0);
        pid.start(0.3, 10.0, 9.0);
        for k in 0..50 {
            pid.update(10.0, 9.0 + k as f32 * 0.01, 0.001);
        }
        let before = pid.update(10.0, 9.5, 0.001);
        pid.set_gains(gains(0.6, 3.0, 0.004, 0.02), 10.0, 9.5);
        let after = pid.update(10.0, 9.5, 0.001);
        // Only the new integral increment (3.0*0.5*0.001) and the derivative filter's decay
        // separate the two outputs.
        assert!((after - before).abs() < 0.01, "{before} -> {after}");
    }

    #[test]
    fn transfer_from_manual_is_bumpless() {
        let mut pid = Pid::new(gains(0.3, 2.0, 0.0, 0.02), 0.0, 1.0);
        pid.start(0.42, 12.0, 12.0);
        let u = pid.update(12.0, 12.0, 0.001);
        assert!((u - 0.42).abs() < 1e-6, "{u}");
    }

    #[test]
    fn nan_measurement_gives_pump_off() {
        let mut pid = Pid::new(gains(0.3, 2.0, 0.0, 0.02), 0.0, 1.0);
        pid.start(0.0, 6.0, 0.0);
        assert_eq!(pid.update(6.0, f32::NAN, 0.001), 0.0);
    }
}
