//! The bench build's conversion constants, reported to the host in
//! [`protocol::DeviceInfo`] so it can convert raw counts (docs/hardware.md).
//!
//! - **ADC** (RP2040, 12-bit SAR, 3.3 V reference = the analog supply): every tick the board
//!   layer sums 16 conversions per channel ([`crate::sampling::Oversampler`]), giving 16-bit
//!   counts: U = counts / 65536 * 3.3 V. The reported full scale is 65535 (the u16 maximum);
//!   using it instead of 65536 in U = counts / full_scale * vref errs by 1.5e-5 relative.
//! - **Manometer**: a ratiometric 0–50 kPa gauge sensor powered from the same 3.3 V rail as
//!   the ADC reference (e.g. Honeywell ABP/NXP MPXV-class analog output, 10 %..90 % of supply
//!   over the range), so supply variations cancel:
//!   counts = 65536 * (0.1 + 0.8 * p / 50 kPa), hence
//!   p_kpa = (counts - 6554) * 50 / 52428.8 = (counts - 6554) * 9.5367e-4 kPa/count.
//!   Readings below 5 % or above 95 % of supply (outside about -3.1..53.1 kPa) are outside
//!   the sensor's output range: open wire, short or saturation.
//! - **Load cell**: a 500 g (4.903 N) bar cell, 1 mV/V rated output, through an HX711 at
//!   gain 128 (input range ±0.5 AVDD / 128, full scale ±2^23 counts). Excitation cancels:
//!   counts/N = 1e-3 * 128 * 2 * 2^23 / 4.903325 N = 437 965 counts/N (nominal; the host
//!   calibrates its own scale).
//! - **Stage**: 200 full steps/rev, 16 microsteps, 2 mm lead screw: 1600 microsteps/mm.

/// Period at which the board layer (and hil-sim) calls [`crate::Controller::tick`]: 2 kHz,
/// so the sample stream can run at its maximum rate of 2 kHz. The PID runs at 1 kHz
/// ([`CONTROL_PERIOD_US`]) on every second tick.
pub const TICK_PERIOD_US: u32 = 500;
/// Pressure control loop period (1 kHz).
pub const CONTROL_PERIOD_US: u32 = 1000;

/// Conversions summed per reading by the oversampler.
pub const OVERSAMPLE_COUNT: u32 = 16;
/// Full scale of the oversampled ADC counts as reported to the host.
pub const ADC_FULL_SCALE_COUNTS: u16 = 65535;
/// ADC reference voltage.
pub const ADC_VREF_MV: u16 = 3300;

/// Manometer output at 0 kPa gauge: 10 % of 65536 counts.
pub const MANOMETER_ZERO_COUNTS: u16 = 6554;
/// Manometer sensitivity: 50 kPa over 80 % of 65536 counts.
pub const MANOMETER_KPA_PER_COUNT: f32 = 50.0 / 52_428.8;
/// Lowest valid manometer reading (5 % of supply).
pub const MANOMETER_MIN_VALID_COUNTS: u16 = 3277;
/// Highest valid manometer reading (95 % of supply).
pub const MANOMETER_MAX_VALID_COUNTS: u16 = 62_259;

/// Nominal HX711 counts per newton (see the module docs).
pub const LOAD_COUNTS_PER_N: f32 = 437_965.0;
/// HX711 output data rate with its RATE pin high (80 SPS; low gives 10 SPS).
pub const LOAD_RATE_SPS: u16 = 80;

/// Stage microsteps per millimetre: 200 * 16 / 2 mm.
pub const STAGE_STEPS_PER_MM: f32 = 1600.0;
/// Fastest stage speed accepted by `MoveStage` (10 mm/s).
pub const STAGE_MAX_SPEED_STEPS_PER_S: u32 = 16_000;
/// Largest stage acceleration accepted by `MoveStage` (100 mm/s^2).
pub const STAGE_MAX_ACCEL_STEPS_PER_S2: u32 = 160_000;
/// Default soft limits, ±100 mm around the boot position until the host homes the stage.
pub const STAGE_DEFAULT_LIMIT_STEPS: i32 = 160_000;

/// Hard overpressure limit (the paper runs at 6 and 15 kPa).
pub const OVERPRESSURE_LIMIT_KPA: f32 = 20.0;
/// Highest setpoint accepted: 2 kPa of margin below the hard limit.
pub const MAX_SETPOINT_KPA: f32 = 18.0;
/// Heartbeat timeout: no request for this long while the pump runs or the stage moves
/// stops both.
pub const HEARTBEAT_TIMEOUT_MS: u32 = 1000;
/// A manometer reading that does not change by a single count for this long is stuck
/// (the sum of 16 conversions of a live 12-bit ADC always carries a few counts of noise).
pub const MANOMETER_STUCK_MS: u32 = 250;
/// The load cell has stopped converting when no conversion arrived for this long
/// (8 periods at 10 SPS); armed by the first conversion, so a bench without a load cell
/// never trips it.
pub const LOAD_CELL_TIMEOUT_MS: u32 = 800;

/// Converts oversampled manometer counts to gauge pressure.
pub fn manometer_kpa(counts: u16) -> f32 {
    (f32::from(counts) - f32::from(MANOMETER_ZERO_COUNTS)) * MANOMETER_KPA_PER_COUNT
}

/// Inverse of [`manometer_kpa`], rounded and saturated to the u16 range (for tests and
/// simulators that need to produce counts).
pub fn manometer_counts(pressure_kpa: f32) -> u16 {
    let counts = f32::from(MANOMETER_ZERO_COUNTS) + pressure_kpa / MANOMETER_KPA_PER_COUNT;
    if counts <= 0.0 {
        0
    } else if counts >= 65535.0 {
        u16::MAX
    } else {
        // In range by the checks above; `as` rounds towards zero, +0.5 rounds to nearest.
        (counts + 0.5) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manometer_transfer_matches_the_ratiometric_datasheet_form() {
        // 10 % of supply at 0 kPa, 90 % at 50 kPa.
        assert_eq!(manometer_counts(0.0), 6554);
        assert!((manometer_kpa(58_982) - 50.0).abs() < 2e-3);
        for p in [0.0f32, 6.0, 15.0, 20.0] {
            assert!((manometer_kpa(manometer_counts(p)) - p).abs() <= MANOMETER_KPA_PER_COUNT);
        }
        // The validity window spans about -3.1..53.1 kPa.
        assert!(manometer_kpa(MANOMETER_MIN_VALID_COUNTS) < -3.0);
        assert!(manometer_kpa(MANOMETER_MAX_VALID_COUNTS) > 53.0);
    }

    #[test]
    fn load_scale_follows_from_the_bridge_and_gain() {
        // 1 mV/V at 4.903325 N (500 g), gain 128, ±0.5 AVDD/128 <-> ±2^23.
        let counts_per_n = 1e-3 * 128.0 * 2.0 * 8_388_608.0 / 4.903_325;
        assert!((LOAD_COUNTS_PER_N - counts_per_n as f32).abs() < 1.0);
    }
}
