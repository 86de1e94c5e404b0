//! ADC0 (proximity) and ADC1 (manometer): 16 conversions per channel per tick, summed by
//! the library's oversampler into 16-bit counts.

use controller::device_constants::OVERSAMPLE_COUNT;
use controller::sampling::Oversampler;
use embassy_rp::Peri;
use embassy_rp::adc::{Adc, Blocking, Channel, Config};
use embassy_rp::gpio::Pull;
use embassy_rp::peripherals::{ADC, PIN_26, PIN_27};

pub struct AnalogInputs {
    adc: Adc<'static, Blocking>,
    proximity: Channel<'static>,
    manometer: Channel<'static>,
}

impl AnalogInputs {
    pub fn new(
        adc: Peri<'static, ADC>,
        gp26: Peri<'static, PIN_26>,
        gp27: Peri<'static, PIN_27>,
    ) -> Self {
        Self {
            adc: Adc::new_blocking(adc, Config::default()),
            proximity: Channel::new_pin(gp26, Pull::None),
            manometer: Channel::new_pin(gp27, Pull::None),
        }
    }

    /// One oversampled reading per channel, interleaved so both see the same instant on
    /// average (2 µs per conversion: 64 µs per tick).
    pub fn read(&mut self) -> (u16, u16) {
        let mut proximity = Oversampler::new();
        let mut manometer = Oversampler::new();
        for _ in 0..OVERSAMPLE_COUNT {
            // A failed conversion is skipped; the oversampler rescales the rest.
            if let Ok(raw) = self.adc.blocking_read(&mut self.proximity) {
                proximity.push(raw);
            }
            if let Ok(raw) = self.adc.blocking_read(&mut self.manometer) {
                manometer.push(raw);
            }
        }
        // A channel whose every conversion failed reads 0: out of the manometer's valid
        // range, so the safety supervisor trips rather than trusting a stale value.
        (proximity.take().unwrap_or(0), manometer.take().unwrap_or(0))
    }
}
