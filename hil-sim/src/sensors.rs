//! Sensor transfer functions of the bench, each with its noise and quantisation, producing
//! the raw values the firmware's board layer would read.
//!
//! - ADC (RP2040): 12-bit SAR, reference 3.3 V; each conversion is
//!   code = clamp(round(U / Vref * 4096 + n), 0, 4095), n ~ N(0, sigma_lsb^2); the board
//!   layer sums 16 conversions per tick with the firmware's own [`Oversampler`].
//! - Proximity sensor: U = A x^2 + B x + C (+ noise), with x the mirror's displacement towards
//!   the sensor measured from the unpressurised shell, x = u_s - inflation_apex (+ a hidden
//!   offset/drift). With respect to u_s alone this is again a parabola whose coefficients
//!   depend on the pressure, as the paper's per-pressure calibration finds.
//! - Manometer: ratiometric gauge sensor, V/Vs = 0.1 + 0.8 (g p + p_off + n) / 50 kPa,
//!   clipped to the sensor's output limits (2.5 %..97.5 % of supply, a typical saturation).
//! - Load cell through an HX711: counts = offset + k P + n, clipped to ±(2^23 - 1), one
//!   conversion every 1/rate seconds of the HX711's own oscillator.
//! - MCU clock: device time t_dev = offset + t (1 + drift_ppm 1e-6), t the host (true) time.

use controller::sampling::Oversampler;
use serde::{Deserialize, Serialize};

use crate::rng::SimRng;

/// ADC conversions summed per tick (the firmware's oversampling count).
pub const ADC_CONVERSIONS_PER_TICK: usize = controller::device_constants::OVERSAMPLE_COUNT as usize;

/// The RP2040's ADC.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdcConfig {
    pub vref_v: f64,
    /// Noise per conversion in 12-bit LSB (the RP2040 ADC's ENOB of ~9 bits is about 1.5
    /// LSB rms of noise).
    pub noise_lsb: f64,
}

impl Default for AdcConfig {
    fn default() -> Self {
        Self {
            vref_v: f64::from(controller::device_constants::ADC_VREF_MV) / 1000.0,
            noise_lsb: 1.5,
        }
    }
}

/// Converts a voltage 16 times and sums the codes through the firmware's oversampler.
pub fn adc_oversampled(voltage_v: f64, cfg: &AdcConfig, rng: &mut SimRng) -> u16 {
    let ideal = voltage_v / cfg.vref_v * 4096.0;
    let mut over = Oversampler::new();
    for _ in 0..ADC_CONVERSIONS_PER_TICK {
        let code = (ideal + rng.normal(cfg.noise_lsb))
            .round()
            .clamp(0.0, 4095.0);
        // In 0..=4095 by the clamp.
        over.push(code as u16);
    }
    over.take().unwrap_or(0)
}

/// The optical proximity sensor aimed at the apex mirror.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProximityConfig {
    /// U = A x^2 + B x + C, x in mm towards the sensor.
    pub a_v_per_mm2: f64,
    pub b_v_per_mm: f64,
    pub c_v: f64,
    /// Output noise (rms) before the ADC.
    pub noise_v: f64,
}

impl Default for ProximityConfig {
    fn default() -> Self {
        // A reflective sensor on its rising slope: 1.2 V at rest, ~0.85 V/mm, gently
        // saturating (monotonic over the 0..2.5 mm range: B + 2 A x > 0 there).
        Self {
            a_v_per_mm2: -0.12,
            b_v_per_mm: 0.85,
            c_v: 1.2,
            noise_v: 0.002,
        }
    }
}

impl ProximityConfig {
    /// Noise-free output voltage at mirror displacement `x_mm`.
    pub fn voltage_v(&self, x_mm: f64) -> f64 {
        self.a_v_per_mm2 * x_mm * x_mm + self.b_v_per_mm * x_mm + self.c_v
    }
}

/// The analog gauge-pressure sensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ManometerConfig {
    pub full_scale_kpa: f64,
    /// Gain error (1 = exact).
    pub gain: f64,
    /// Noise (rms) in kPa at the sensor output.
    pub noise_kpa: f64,
    /// Output clipping, fraction of supply.
    pub min_output_fraction: f64,
    pub max_output_fraction: f64,
}

impl Default for ManometerConfig {
    fn default() -> Self {
        Self {
            full_scale_kpa: 50.0,
            gain: 1.0,
            // 0.25 % FS total error band class sensor: ~0.02 kPa rms of noise.
            noise_kpa: 0.02,
            min_output_fraction: 0.025,
            max_output_fraction: 0.975,
        }
    }
}

impl ManometerConfig {
    /// Output as a fraction of supply for gauge pressure `p_kpa` (offset included in p).
    pub fn output_fraction(&self, p_kpa: f64) -> f64 {
        (0.1 + 0.8 * self.gain * p_kpa / self.full_scale_kpa)
            .clamp(self.min_output_fraction, self.max_output_fraction)
    }
}

/// Oversampled manometer counts for a ratiometric output fraction (the ADC reference is the
/// sensor supply, so the fraction maps to codes without Vref).
pub fn manometer_counts(fraction: f64, adc: &AdcConfig, rng: &mut SimRng) -> u16 {
    adc_oversampled(fraction * adc.vref_v, adc, rng)
}

/// The load cell and its HX711.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LoadCellConfig {
    /// Conversions per second (80 or 10).
    pub rate_sps: f64,
    /// Actual scale (the firmware reports a nominal 437 965 counts/N; real cells differ by
    /// a few per cent, which the host's rigid-sample sweep calibrates and removes).
    pub counts_per_n: f64,
    /// Bridge offset at zero load.
    pub offset_counts: f64,
    /// Noise (rms) in counts (HX711 at 80 SPS, gain 128: ~ 90 nV rms input noise).
    pub noise_counts: f64,
    /// Relative frequency error of the HX711's internal oscillator.
    pub rate_error: f64,
}

impl Default for LoadCellConfig {
    fn default() -> Self {
        Self {
            rate_sps: f64::from(controller::device_constants::LOAD_RATE_SPS),
            counts_per_n: 0.97 * f64::from(controller::device_constants::LOAD_COUNTS_PER_N),
            offset_counts: 41_000.0,
            noise_counts: 40.0,
            rate_error: 0.01,
        }
    }
}

impl LoadCellConfig {
    pub fn period_s(&self) -> f64 {
        1.0 / (self.rate_sps * (1.0 + self.rate_error))
    }

    /// One conversion at load `load_n`.
    pub fn counts(&self, load_n: f64, rng: &mut SimRng) -> i32 {
        let v = self.offset_counts + self.counts_per_n * load_n + rng.normal(self.noise_counts);
        // Clipped to the 24-bit range.
        v.round().clamp(-8_388_608.0, 8_388_607.0) as i32
    }
}

/// The microcontroller's crystal relative to host time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClockConfig {
    /// Device time at host time 0 (the device booted before the host's epoch).
    pub offset_us: f64,
    /// Crystal frequency error in parts per million (positive: device clock runs fast).
    pub drift_ppm: f64,
}

impl Default for ClockConfig {
    fn default() -> Self {
        Self {
            offset_us: 1_234_567.0,
            drift_ppm: 35.0,
        }
    }
}

impl ClockConfig {
    fn rate(&self) -> f64 {
        1.0 + self.drift_ppm * 1e-6
    }

    /// Device time (µs, fractional) at host time `t_s`.
    pub fn device_us(&self, t_s: f64) -> f64 {
        self.offset_us + t_s * 1e6 * self.rate()
    }

    /// Host time (s) at which the device clock reads `device_us`.
    pub fn host_s(&self, device_us: f64) -> f64 {
        (device_us - self.offset_us) / self.rate() * 1e-6
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use controller::device_constants::{MANOMETER_KPA_PER_COUNT, manometer_kpa};

    #[test]
    fn noiseless_adc_oversampling_quantises_to_sixteen_codes() {
        let cfg = AdcConfig {
            noise_lsb: 0.0,
            ..AdcConfig::default()
        };
        let mut rng = SimRng::new(1);
        // 1.65 V = code 2048 exactly; the sum of 16 is 32768.
        assert_eq!(adc_oversampled(1.65, &cfg, &mut rng), 32_768);
        assert_eq!(adc_oversampled(5.0, &cfg, &mut rng), 65_520);
        assert_eq!(adc_oversampled(-1.0, &cfg, &mut rng), 0);
    }

    #[test]
    fn dithered_adc_resolves_below_one_code() {
        // With 1.5 LSB of noise, the mean of many oversampled readings recovers a voltage
        // between codes: 2048.3 codes -> 32772.8 on the 16x scale. 400 readings of
        // 16 conversions have a standard error of 1.5*4/sqrt(400) = 0.3 counts.
        let cfg = AdcConfig::default();
        let mut rng = SimRng::new(2);
        let u = 2048.3 / 4096.0 * cfg.vref_v;
        let mean = (0..400)
            .map(|_| f64::from(adc_oversampled(u, &cfg, &mut rng)))
            .sum::<f64>()
            / 400.0;
        assert!((mean - 32_772.8).abs() < 1.5, "{mean}");
    }

    #[test]
    fn manometer_counts_decode_with_the_firmware_constants() {
        let adc = AdcConfig {
            noise_lsb: 0.0,
            ..AdcConfig::default()
        };
        let m = ManometerConfig {
            noise_kpa: 0.0,
            ..ManometerConfig::default()
        };
        let mut rng = SimRng::new(3);
        for p in [0.0, 6.0, 15.0, 20.0] {
            let counts = manometer_counts(m.output_fraction(p), &adc, &mut rng);
            // Quantisation of a 12-bit code is 16 counts = 0.0153 kPa; half of it plus the
            // 65535-vs-65536 scale difference bounds the error.
            let back = f64::from(manometer_kpa(counts));
            assert!(
                (back - p).abs() < 8.5 * f64::from(MANOMETER_KPA_PER_COUNT),
                "{p} -> {back}"
            );
        }
        // Saturates at 97.5 % of supply.
        assert!((m.output_fraction(100.0) - 0.975).abs() < 1e-12);
    }

    #[test]
    fn clock_maps_both_ways() {
        let c = ClockConfig::default();
        let t = 12.345;
        assert!((c.host_s(c.device_us(t)) - t).abs() < 1e-12);
        // 35 ppm over 100 s is 3.5 ms.
        assert!((c.device_us(100.0) - c.device_us(0.0) - 100.0035e6).abs() < 1e-3);
    }

    #[test]
    fn load_cell_counts_are_linear_and_clipped() {
        let l = LoadCellConfig {
            noise_counts: 0.0,
            ..LoadCellConfig::default()
        };
        let mut rng = SimRng::new(4);
        let c0 = l.counts(0.0, &mut rng);
        let c1 = l.counts(1.0, &mut rng);
        assert_eq!(c0, 41_000);
        assert!((f64::from(c1 - c0) - l.counts_per_n).abs() <= 1.0);
        assert_eq!(l.counts(1000.0, &mut rng), 8_388_607);
    }
}
