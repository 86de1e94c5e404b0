//! Pneumatic plant: the air in the shell, the tubing and the tube (one lumped, isothermal
//! volume), fed by a diaphragm pump, bled by a leak and emptied by the vent valve.
//!
//! Equations (gauge pressure p, absolute p + p_atm, all flows as *free-air* volume flows,
//! i.e. the volume the moved gas occupies at atmospheric pressure):
//!
//! - isothermal ideal gas: (p + p_atm) V = n p_atm, with n the gas content in free-air mm^3;
//!   a change of V at constant n is Boyle's law p1 V1 = p2 V2 (absolute pressures);
//! - balance: dn/dt = Q_pump - Q_leak - Q_vent;
//! - pump (linear pump curve): Q_pump = s Q_0 max(0, 1 - p / p_stall), where the pump's
//!   speed s (a fraction of full speed) follows the duty d in 0..1 with the motor's spin-up
//!   lag, ds/dt = (d - s) / tau_pump;
//! - leak (laminar capillary/bleed, Hagen–Poiseuille): Q_leak = G_leak p;
//! - vent (turbulent orifice, Bernoulli): Q_vent = K_vent sign(p) sqrt(|p|) above the
//!   transition pressure p_t, and the laminar continuation K_vent p / sqrt(p_t) below it
//!   (so the flow and its derivative stay finite at p = 0).
//!
//! With the pump and leak alone and V fixed this is linear:
//! dp/dt = (p_atm / V) (d Q_0 - (d Q_0 / p_stall + G_leak) p), an exponential approach to
//! p_eq = d Q_0 / (d Q_0 / p_stall + G_leak) with tau = V / (p_atm (d Q_0 / p_stall + G_leak)).
//!
//! Integration: the pump speed's linear lag is solved exactly over each step, and the flow
//! uses its mean over the step; then exponential Euler on n (the flow is linearised around the
//! state at the start of each step and the linear ODE solved exactly), which is exact for the
//! linear case above at a constant speed and unconditionally stable for the stiff vent.
//!
//! This one model serves the emulated bench (hil-sim), the controller's host tests and the
//! link's loopback device, and the controller's default gains are tuned on it.

use serde::{Deserialize, Serialize};

/// Parameters of the pneumatic plant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PneumaticsConfig {
    /// Ambient (absolute) pressure.
    pub atmosphere_kpa: f64,
    /// Gas volume outside the shell: the tube around the camera, the tubing, the pump head
    /// and the manometer port (about 2.5 mL; with the ~0.47 mL shell about 3 mL in all).
    pub dead_volume_mm3: f64,
    /// Pump free-air flow at full duty and zero back pressure (200 mL/min: a small
    /// diaphragm pump of the kind used in cuff inflators).
    pub pump_free_flow_mm3_per_s: f64,
    /// Back pressure at which the pump's flow falls to zero.
    pub pump_stall_kpa: f64,
    /// Spin-up lag of the pump's motor (first order): a small brushed DC motor with its
    /// diaphragm reaches 63 % of a speed change in about 30 ms. 0 makes the speed follow the
    /// duty at once.
    pub pump_time_constant_s: f64,
    /// Laminar bleed/leak conductance (free-air mm^3/s per kPa gauge). The default (30) is a
    /// deliberate bleed of ~27 mL/min at 15 kPa, which lets the pressure fall when the
    /// indentation compresses the shell (the pump alone can only raise it).
    pub leak_conductance_mm3_per_s_per_kpa: f64,
    /// Vent orifice coefficient K_vent (free-air mm^3/s per sqrt(kPa)); the default is a
    /// 0.8 mm orifice with discharge coefficient 0.6 (about 2.8 L/min at 15 kPa).
    pub vent_coefficient_mm3_per_s_per_sqrt_kpa: f64,
    /// Pressure below which the vent flow is laminar (linear in p).
    pub vent_transition_kpa: f64,
}

impl Default for PneumaticsConfig {
    fn default() -> Self {
        Self {
            atmosphere_kpa: 101.325,
            dead_volume_mm3: 2500.0,
            pump_free_flow_mm3_per_s: 200.0 * 1000.0 / 60.0,
            pump_stall_kpa: 40.0,
            pump_time_constant_s: 0.03,
            leak_conductance_mm3_per_s_per_kpa: 30.0,
            // Q = Cd A sqrt(2 dp / rho) with dp = 1000 p_kpa Pa, rho = 1.2 kg/m^3:
            // 0.6 * 0.503e-6 m^2 * sqrt(2000 / 1.2) m/s = 1.23e-5 m^3/s per sqrt(kPa).
            vent_coefficient_mm3_per_s_per_sqrt_kpa: 12_300.0,
            vent_transition_kpa: 0.2,
        }
    }
}

/// What drives the plant during one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PneumaticDrive {
    /// Pump duty fraction 0..=1.
    pub pump_duty: f64,
    pub vent_open: bool,
    /// Multiplies the leak conductance (1 = nominal; a fault raises it).
    pub leak_scale: f64,
    /// A stalled pump delivers nothing whatever its duty.
    pub pump_stalled: bool,
}

impl Default for PneumaticDrive {
    fn default() -> Self {
        Self {
            pump_duty: 0.0,
            vent_open: false,
            leak_scale: 1.0,
            pump_stalled: false,
        }
    }
}

/// The pneumatic state: gas content, the current volume and the pump's speed.
#[derive(Debug, Clone)]
pub struct Pneumatics {
    cfg: PneumaticsConfig,
    /// Pump speed as a fraction of full speed (the lagged duty).
    pump_speed: f64,
    /// Gas content as free-air volume (mm^3 at atmospheric pressure).
    gas_free_mm3: f64,
    /// Current total volume: dead volume + shell inner volume.
    volume_mm3: f64,
}

impl Pneumatics {
    /// A plant at `gauge_kpa` with `shell_volume_mm3` inside the shell.
    pub fn new(cfg: PneumaticsConfig, shell_volume_mm3: f64, gauge_kpa: f64) -> Self {
        let volume_mm3 = cfg.dead_volume_mm3 + shell_volume_mm3;
        let gas_free_mm3 = (gauge_kpa + cfg.atmosphere_kpa) * volume_mm3 / cfg.atmosphere_kpa;
        Self {
            cfg,
            pump_speed: 0.0,
            gas_free_mm3,
            volume_mm3,
        }
    }

    /// The pump's speed as a fraction of full speed.
    pub fn pump_speed(&self) -> f64 {
        self.pump_speed
    }

    /// The steady duty that holds `gauge_kpa` against the nominal leak with the vent closed
    /// (the pump's flow equals the leak's), or `None` where even full duty cannot (the
    /// defaults top out at 29.4 kPa, where Q_0 (1 - p / p_stall) = G_leak p).
    pub fn holding_duty(&self, gauge_kpa: f64) -> Option<f64> {
        let c = &self.cfg;
        let factor = 1.0 - gauge_kpa / c.pump_stall_kpa;
        if factor <= 0.0 {
            return None;
        }
        let duty = c.leak_conductance_mm3_per_s_per_kpa * gauge_kpa
            / (c.pump_free_flow_mm3_per_s * factor);
        (duty <= 1.0).then_some(duty)
    }

    pub fn config(&self) -> &PneumaticsConfig {
        &self.cfg
    }

    /// Gauge pressure now.
    pub fn gauge_kpa(&self) -> f64 {
        self.gas_free_mm3 * self.cfg.atmosphere_kpa / self.volume_mm3 - self.cfg.atmosphere_kpa
    }

    pub fn volume_mm3(&self) -> f64 {
        self.volume_mm3
    }

    /// The shell's inner volume changed (indentation, inflation): the gas content is kept,
    /// so the pressure follows Boyle's law.
    pub fn set_shell_volume(&mut self, shell_volume_mm3: f64) {
        self.volume_mm3 = self.cfg.dead_volume_mm3 + shell_volume_mm3;
    }

    /// Sets the gauge pressure at the current volume (gas added or removed by force, e.g. a
    /// test driving the plant to an overpressure).
    pub fn set_gauge_kpa(&mut self, gauge_kpa: f64) {
        let atm = self.cfg.atmosphere_kpa;
        self.gas_free_mm3 = ((gauge_kpa + atm) * self.volume_mm3 / atm).max(0.0);
    }

    /// Adds (or with a negative value removes) gas, in free-air mm^3 (an injected event).
    pub fn add_gas(&mut self, free_mm3: f64) {
        self.gas_free_mm3 = (self.gas_free_mm3 + free_mm3).max(0.0);
    }

    /// Net inflow Q(p) (free-air mm^3/s) and dQ/dp with the pump at `pump_speed` (a fraction
    /// of full speed).
    pub fn net_flow(&self, p_kpa: f64, pump_speed: f64, drive: &PneumaticDrive) -> (f64, f64) {
        let c = &self.cfg;
        let mut q = 0.0;
        let mut dq = 0.0;
        if !drive.pump_stalled && pump_speed > 0.0 {
            let q0 = pump_speed.clamp(0.0, 1.0) * c.pump_free_flow_mm3_per_s;
            let factor = 1.0 - p_kpa / c.pump_stall_kpa;
            if factor > 0.0 {
                q += q0 * factor;
                dq -= q0 / c.pump_stall_kpa;
            }
        }
        let g = c.leak_conductance_mm3_per_s_per_kpa * drive.leak_scale.max(0.0);
        q -= g * p_kpa;
        dq -= g;
        if drive.vent_open {
            let k = c.vent_coefficient_mm3_per_s_per_sqrt_kpa;
            let pt = c.vent_transition_kpa;
            if p_kpa.abs() > pt {
                q -= k * p_kpa.signum() * p_kpa.abs().sqrt();
                dq -= 0.5 * k / p_kpa.abs().sqrt();
            } else {
                q -= k * p_kpa / pt.sqrt();
                dq -= k / pt.sqrt();
            }
        }
        (q, dq)
    }

    /// Advances the gas content by `dt_s` at the current volume (exponential Euler).
    pub fn step(&mut self, dt_s: f64, drive: &PneumaticDrive) {
        if dt_s <= 0.0 {
            return;
        }
        // Pump speed: s(t) = d + (s0 - d) e^(-t/tau); its mean over the step drives the flow.
        let duty = drive.pump_duty.clamp(0.0, 1.0);
        let s0 = self.pump_speed;
        let tau = self.cfg.pump_time_constant_s;
        let (speed_end, speed_mean) = if tau > 0.0 {
            let decay = (-dt_s / tau).exp();
            (
                duty + (s0 - duty) * decay,
                duty + (s0 - duty) * tau / dt_s * (1.0 - decay),
            )
        } else {
            (duty, duty)
        };
        self.pump_speed = speed_end;
        let p = self.gauge_kpa();
        let (q, dq_dp) = self.net_flow(p, speed_mean, drive);
        // d n / dt = Q(p(n)), dp/dn = p_atm / V.
        let j = dq_dp * self.cfg.atmosphere_kpa / self.volume_mm3;
        let x = j * dt_s;
        let dn = if x.abs() < 1e-9 {
            q * dt_s
        } else {
            q * x.exp_m1() / j
        };
        self.gas_free_mm3 = (self.gas_free_mm3 + dn).max(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sealed() -> PneumaticsConfig {
        PneumaticsConfig {
            leak_conductance_mm3_per_s_per_kpa: 0.0,
            ..PneumaticsConfig::default()
        }
    }

    fn without_lag() -> PneumaticsConfig {
        PneumaticsConfig {
            pump_time_constant_s: 0.0,
            ..PneumaticsConfig::default()
        }
    }

    #[test]
    fn sealed_isothermal_compression_follows_boyle() {
        let cfg = sealed();
        let atm = cfg.atmosphere_kpa;
        let mut p = Pneumatics::new(cfg, 470.0, 6.0);
        let v1 = p.volume_mm3();
        p.set_shell_volume(470.0 - 40.0);
        p.step(0.5, &PneumaticDrive::default());
        let v2 = p.volume_mm3();
        let expected = (6.0 + atm) * v1 / v2 - atm;
        // Boyle's law holds to rounding: nothing flows in a sealed, unpumped volume.
        assert!(
            (p.gauge_kpa() - expected).abs() < 1e-9,
            "{} vs {expected}",
            p.gauge_kpa()
        );
        // 40 mm^3 out of 2970 mm^3 raises 107.3 kPa absolute by 1.36 %: about 1.46 kPa.
        assert!((expected - 6.0 - 1.4645).abs() < 1e-3, "{expected}");
    }

    #[test]
    fn pump_against_leak_approaches_equilibrium_exponentially() {
        let cfg = without_lag();
        let atm = cfg.atmosphere_kpa;
        let q0 = 0.4 * cfg.pump_free_flow_mm3_per_s;
        let g = cfg.leak_conductance_mm3_per_s_per_kpa;
        let k = q0 / cfg.pump_stall_kpa + g;
        let p_eq = q0 / k;
        let mut p = Pneumatics::new(cfg, 470.0, 0.0);
        let tau = p.volume_mm3() / (atm * k);
        let drive = PneumaticDrive {
            pump_duty: 0.4,
            ..PneumaticDrive::default()
        };
        let dt = 5e-4;
        for i in 1..=4000 {
            p.step(dt, &drive);
            let t = i as f64 * dt;
            let closed = p_eq * (1.0 - (-t / tau).exp());
            // The linear ODE is solved exactly per step: only rounding separates them.
            assert!(
                (p.gauge_kpa() - closed).abs() < 1e-9,
                "t={t}: {} vs {closed}",
                p.gauge_kpa()
            );
        }
        // Sanity of the defaults: 40 % duty (1333 mm^3/s) against k = 1333/40 + 30 settles at
        // 21.05 kPa with tau = 2970 / (101.325 k) = 0.463 s.
        assert!((p_eq - 21.05).abs() < 0.01, "{p_eq}");
        assert!((tau - 0.463).abs() < 0.001, "{tau}");
    }

    #[test]
    fn vent_blowdown_matches_the_orifice_closed_form() {
        // dp/dt = -(p_atm/V) K sqrt(p) (leak off, above p_t): sqrt(p) falls linearly,
        // sqrt(p(t)) = sqrt(p0) - p_atm K t / (2 V) (V fixed).
        let cfg = sealed();
        let atm = cfg.atmosphere_kpa;
        let k = cfg.vent_coefficient_mm3_per_s_per_sqrt_kpa;
        let mut p = Pneumatics::new(cfg, 470.0, 15.0);
        let v = p.volume_mm3();
        let drive = PneumaticDrive {
            vent_open: true,
            ..PneumaticDrive::default()
        };
        let dt = 5e-5;
        let mut t = 0.0;
        while p.gauge_kpa() > 1.0 {
            p.step(dt, &drive);
            t += dt;
            let closed = (15.0f64.sqrt() - atm * k * t / (2.0 * v)).powi(2);
            // Exponential Euler on the linearised sqrt law: second order in dt per step;
            // 0.5 % of the pressure is far above its error and far below the effect.
            assert!(
                (p.gauge_kpa() - closed).abs() < 5e-3 * closed.max(1.0),
                "t={t}"
            );
        }
        // 15 kPa vents to 1 kPa in (sqrt(15) - 1) * 2 V / (p_atm K) = 13.7 ms.
        assert!((t - 0.0137).abs() < 5e-4, "{t}");
        for _ in 0..2000 {
            p.step(5e-4, &drive);
        }
        assert!(p.gauge_kpa().abs() < 1e-6);
    }

    #[test]
    fn stalled_pump_delivers_nothing() {
        let mut p = Pneumatics::new(PneumaticsConfig::default(), 470.0, 0.0);
        let drive = PneumaticDrive {
            pump_duty: 1.0,
            pump_stalled: true,
            ..PneumaticDrive::default()
        };
        p.step(1.0, &drive);
        assert_eq!(p.gauge_kpa(), 0.0);
    }

    #[test]
    fn pump_speed_follows_the_duty_with_its_spin_up_lag() {
        // Sealed volume, no back-pressure effect on the speed: the gas added by a duty step
        // from rest is Q_0 (1 - p/p_stall) integrated over s(t) = d (1 - e^(-t/tau)). Checked
        // on the speed itself, which the step solves exactly.
        let cfg = sealed();
        let tau = cfg.pump_time_constant_s;
        let mut p = Pneumatics::new(cfg, 470.0, 0.0);
        let drive = PneumaticDrive {
            pump_duty: 0.5,
            ..PneumaticDrive::default()
        };
        let dt = 1e-3;
        for i in 1..=200 {
            p.step(dt, &drive);
            let t = i as f64 * dt;
            let closed = 0.5 * (1.0 - (-t / tau).exp());
            // Exact per step up to rounding.
            assert!((p.pump_speed() - closed).abs() < 1e-12, "t={t}");
        }
        // After one time constant the speed is at 63 % of the step.
        let mut q = Pneumatics::new(sealed(), 470.0, 0.0);
        q.step(tau, &drive);
        assert!((q.pump_speed() - 0.5 * (1.0 - (-1.0f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn holding_duty_balances_pump_and_leak() {
        let p = Pneumatics::new(PneumaticsConfig::default(), 470.0, 0.0);
        for gauge in [6.0, 15.0, 25.0] {
            let d = p.holding_duty(gauge).expect("below stall");
            let (q, _) = p.net_flow(gauge, d, &PneumaticDrive::default());
            assert!(q.abs() < 1e-9, "{gauge} kPa: net flow {q}");
        }
        // 6 kPa: leak 180 mm^3/s against 3333 (1 - 6/40) = 2833 mm^3/s per unit duty.
        let d6 = p.holding_duty(6.0).expect("below stall");
        assert!((d6 - 180.0 / 2833.33).abs() < 1e-4, "{d6}");
        assert!(p.holding_duty(29.0).is_some());
        assert_eq!(p.holding_duty(30.0), None);
        assert_eq!(p.holding_duty(40.0), None);
    }
}
