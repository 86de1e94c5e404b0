//! Raw counts to physical units with the constants the device reported in its handshake
//! ([`DeviceInfo`], firmware/src/device_constants.rs documents their derivation).

use protocol::DeviceInfo;

/// Converts streamed raw counts to volts, kPa, newtons and millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleUnits {
    volts_per_count: f64,
    manometer_zero_counts: f64,
    manometer_kpa_per_count: f64,
    load_counts_per_n: f64,
    stage_steps_per_mm: f64,
}

impl SampleUnits {
    pub fn new(info: &DeviceInfo) -> Self {
        Self {
            // U = counts / full_scale * vref
            volts_per_count: f64::from(info.adc_vref_mv)
                / 1000.0
                / f64::from(info.adc_full_scale_counts.max(1)),
            manometer_zero_counts: f64::from(info.manometer_zero_counts),
            manometer_kpa_per_count: f64::from(info.manometer_kpa_per_count),
            load_counts_per_n: f64::from(info.load_counts_per_n),
            stage_steps_per_mm: f64::from(info.stage_steps_per_mm),
        }
    }

    /// Proximity sensor voltage U.
    pub fn proximity_v(&self, counts: u16) -> f64 {
        f64::from(counts) * self.volts_per_count
    }

    /// Manometer gauge pressure (before the host's zero calibration).
    pub fn manometer_kpa(&self, counts: u16) -> f64 {
        (f64::from(counts) - self.manometer_zero_counts) * self.manometer_kpa_per_count
    }

    /// Load with the device's nominal scale (tare applied on the device).
    pub fn load_n(&self, counts: i32) -> f64 {
        f64::from(counts) / self.load_counts_per_n
    }

    /// Stage position.
    pub fn stage_mm(&self, steps: i32) -> f64 {
        f64::from(steps) / self.stage_steps_per_mm
    }

    /// Stage position in microsteps (rounded) for a position in mm.
    pub fn stage_steps(&self, mm: f64) -> i32 {
        (mm * self.stage_steps_per_mm).round() as i32
    }

    pub fn stage_steps_per_mm(&self) -> f64 {
        self.stage_steps_per_mm
    }
}
