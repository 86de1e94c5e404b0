//! A first-order pneumatic plant for the controller's host tests: an isothermal ideal gas in
//! the volume V (dead volume of the tubing and pump head + the shell's inner volume).
//!
//! With p the gauge pressure, p_abs = p_atm + p, and every flow Q a volume flow at the
//! chamber's state, the ideal gas law at constant temperature (p_abs V = n R T) gives
//!
//! ```text
//! dp/dt = p_abs / V * (Q_pump - Q_leak - Q_vent) - p_abs / V * dV/dt
//! Q_pump = q * Q_free * max(0, 1 - p / p_stall)      diaphragm pump, flow falling linearly
//!                                                    with back pressure
//! dq/dt  = (duty - q) / tau_pump                     motor spin-up lag
//! Q_leak = c_leak * p,  Q_vent = c_vent * p          laminar leak and vent orifices
//! ```
//!
//! A sudden change of V (the shell indented) keeps p_abs V constant.
//! Parameters: a 200 mL/min micro diaphragm pump stalling at 60 kPa, 3 mL of gas
//! (0.5 mL shell + tubing and pump head), a leak that needs ~10 % duty at 6 kPa and ~30 % at
//! 15 kPa, a vent that empties the volume in ~20 ms, and a 30 ms pump spin-up lag.

#[derive(Debug, Clone)]
pub struct PneumaticPlant {
    pub p_atm_kpa: f64,
    pub volume_ml: f64,
    pub pump_free_flow_ml_per_s: f64,
    pub pump_stall_kpa: f64,
    pub pump_time_constant_s: f64,
    pub leak_ml_per_s_per_kpa: f64,
    pub vent_ml_per_s_per_kpa: f64,
    /// Gauge pressure.
    pub pressure_kpa: f64,
    /// Pump speed as a fraction of full speed (the lagged duty).
    pub pump_speed: f64,
}

impl Default for PneumaticPlant {
    fn default() -> Self {
        Self {
            p_atm_kpa: 101.325,
            volume_ml: 3.0,
            pump_free_flow_ml_per_s: 200.0 / 60.0,
            pump_stall_kpa: 60.0,
            pump_time_constant_s: 0.03,
            leak_ml_per_s_per_kpa: 0.05,
            vent_ml_per_s_per_kpa: 5.0,
            pressure_kpa: 0.0,
            pump_speed: 0.0,
        }
    }
}

impl PneumaticPlant {
    fn derivatives(&self, p: f64, q: f64, duty: f64, vent_open: bool) -> (f64, f64) {
        let p_abs = self.p_atm_kpa + p;
        let q_pump = q * self.pump_free_flow_ml_per_s * (1.0 - p / self.pump_stall_kpa).max(0.0);
        let q_leak = self.leak_ml_per_s_per_kpa * p;
        let q_vent = if vent_open {
            self.vent_ml_per_s_per_kpa * p
        } else {
            0.0
        };
        let dp = p_abs / self.volume_ml * (q_pump - q_leak - q_vent);
        let dq = (duty - q) / self.pump_time_constant_s;
        (dp, dq)
    }

    /// Advances `dt_s` with the pump at `duty` (0..1) and the vent as given (RK4 in 10
    /// sub-steps: the fastest rate, the open vent's ~170 /s, stays far inside RK4's
    /// stability region at 50 µs).
    pub fn step(&mut self, duty: f64, vent_open: bool, dt_s: f64) {
        let n = 10;
        let h = dt_s / n as f64;
        for _ in 0..n {
            let (p, q) = (self.pressure_kpa, self.pump_speed);
            let (k1p, k1q) = self.derivatives(p, q, duty, vent_open);
            let (k2p, k2q) =
                self.derivatives(p + 0.5 * h * k1p, q + 0.5 * h * k1q, duty, vent_open);
            let (k3p, k3q) =
                self.derivatives(p + 0.5 * h * k2p, q + 0.5 * h * k2q, duty, vent_open);
            let (k4p, k4q) = self.derivatives(p + h * k3p, q + h * k3q, duty, vent_open);
            self.pressure_kpa = p + h / 6.0 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p);
            self.pump_speed = q + h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q);
        }
    }

    /// Changes the gas volume suddenly (isothermal: p_abs V constant).
    pub fn set_volume_ml(&mut self, volume_ml: f64) {
        let p_abs = self.p_atm_kpa + self.pressure_kpa;
        self.pressure_kpa = p_abs * self.volume_ml / volume_ml - self.p_atm_kpa;
        self.volume_ml = volume_ml;
    }

    /// Steady-state duty that holds `p` against the leak (vent closed).
    pub fn holding_duty(&self, p: f64) -> f64 {
        self.leak_ml_per_s_per_kpa * p
            / (self.pump_free_flow_ml_per_s * (1.0 - p / self.pump_stall_kpa))
    }
}
