//! Injected faults: what goes wrong on the bench at scripted times, announced to nobody.
//!
//! - link: each byte in either direction is independently dropped with probability
//!   `byte_drop_rate` or has one random bit flipped with probability `byte_corruption_rate`;
//!   a disconnect window discards all traffic both ways (as a pulled USB cable does to the
//!   data; the PTY itself stays open so the host can carry on after the window);
//! - pneumatics: the leak conductance multiplied by `factor` from a time on; the pump stalls
//!   (delivers nothing whatever its duty) from a time on; an overpressure event injects gas so
//!   that the pressure rises by `rise_kpa` within `duration_s` (e.g. the shell squeezed or
//!   the tubing pinched);
//! - sensors: a sensor's output stuck at its upper or lower rail from a time on;
//! - camera: frames dropped at random with probability `camera_drop_rate` (the frame's
//!   sequence number is skipped, as V4L2 reports it).

use serde::{Deserialize, Serialize};

/// A leak that grows at a time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LeakIncrease {
    pub at_s: f64,
    pub factor: f64,
}

/// A sudden pressure rise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OverpressureEvent {
    pub at_s: f64,
    pub rise_kpa: f64,
    pub duration_s: f64,
}

/// Which sensor saturates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SaturatedSensor {
    Manometer,
    Proximity,
}

/// Which rail it sticks to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Rail {
    High,
    Low,
}

/// A sensor stuck at a rail from a time on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSaturation {
    pub at_s: f64,
    pub sensor: SaturatedSensor,
    pub rail: Rail,
}

/// A window during which the link carries nothing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Disconnect {
    pub at_s: f64,
    /// How long; `None`: for ever.
    pub duration_s: Option<f64>,
}

/// Every injected fault; none by default.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FaultsConfig {
    pub byte_corruption_rate: f64,
    pub byte_drop_rate: f64,
    pub disconnect: Option<Disconnect>,
    pub leak_increase: Option<LeakIncrease>,
    pub pump_stall_at_s: Option<f64>,
    pub sensor_saturation: Option<SensorSaturation>,
    pub camera_drop_rate: f64,
    pub overpressure: Option<OverpressureEvent>,
}

impl FaultsConfig {
    /// Leak multiplier at time `t_s`.
    pub fn leak_scale(&self, t_s: f64) -> f64 {
        match self.leak_increase {
            Some(l) if t_s >= l.at_s => l.factor,
            _ => 1.0,
        }
    }

    pub fn pump_stalled(&self, t_s: f64) -> bool {
        self.pump_stall_at_s.is_some_and(|at| t_s >= at)
    }

    /// The rail `sensor` is stuck at, at time `t_s`.
    pub fn saturation(&self, sensor: SaturatedSensor, t_s: f64) -> Option<Rail> {
        self.sensor_saturation
            .filter(|s| s.sensor == sensor && t_s >= s.at_s)
            .map(|s| s.rail)
    }

    pub fn disconnected(&self, t_s: f64) -> bool {
        self.disconnect
            .is_some_and(|d| t_s >= d.at_s && d.duration_s.is_none_or(|len| t_s < d.at_s + len))
    }

    /// Fraction of the overpressure rise delivered during [t0, t1).
    pub fn overpressure_fraction(&self, t0_s: f64, t1_s: f64) -> Option<(f64, f64)> {
        let e = self.overpressure?;
        let len = e.duration_s.max(1e-9);
        let a = ((t0_s - e.at_s) / len).clamp(0.0, 1.0);
        let b = ((t1_s - e.at_s) / len).clamp(0.0, 1.0);
        (b > a).then_some((b - a, e.rise_kpa))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedules_switch_at_their_times() {
        let f = FaultsConfig {
            leak_increase: Some(LeakIncrease {
                at_s: 1.0,
                factor: 4.0,
            }),
            pump_stall_at_s: Some(2.0),
            disconnect: Some(Disconnect {
                at_s: 3.0,
                duration_s: Some(0.5),
            }),
            overpressure: Some(OverpressureEvent {
                at_s: 5.0,
                rise_kpa: 10.0,
                duration_s: 0.01,
            }),
            ..FaultsConfig::default()
        };
        assert_eq!(f.leak_scale(0.5), 1.0);
        assert_eq!(f.leak_scale(1.0), 4.0);
        assert!(!f.pump_stalled(1.9) && f.pump_stalled(2.0));
        assert!(!f.disconnected(2.9) && f.disconnected(3.2) && !f.disconnected(3.5));
        assert_eq!(f.overpressure_fraction(4.0, 4.5), None);
        let (frac, rise) = f.overpressure_fraction(4.999, 5.005).unwrap_or_default();
        assert!((frac - 0.5).abs() < 1e-9 && rise == 10.0);
    }
}
