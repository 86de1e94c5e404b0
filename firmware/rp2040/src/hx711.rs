//! HX711 24-bit bridge ADC, bit-banged: DOUT falls when a conversion is ready; 24 clock
//! pulses shift it out MSB first (two's complement), and a 25th selects channel A at gain
//! 128 for the next conversion. PD_SCK must not stay high for 60 µs (the chip would power
//! down), so the 25 pulses run inside a critical section (~50 µs).
//!
//! DOUT has a pull-up: with no HX711 fitted it never falls, no conversion is ever reported,
//! and the controller's load-cell timeout stays disarmed.

use controller::sampling::hx711_counts_from_bits;
use embassy_rp::gpio::{Input, Output};

use crate::shared::LOAD_CONVERSION;

/// Half a clock period: 1 µs at 125 MHz (datasheet: PD_SCK high and low >= 0.2 µs, data
/// valid 0.1 µs after the rising edge).
const HALF_PERIOD_CYCLES: u32 = 125;

pub struct Hx711 {
    dout: Input<'static>,
    sck: Output<'static>,
}

impl Hx711 {
    pub fn new(dout: Input<'static>, sck: Output<'static>) -> Self {
        Self { dout, sck }
    }

    /// Waits for the next conversion and reads it (signed counts).
    pub async fn read(&mut self) -> i32 {
        self.dout.wait_for_low().await;
        let raw = critical_section::with(|_| {
            let mut bits = 0u32;
            for _ in 0..24 {
                self.sck.set_high();
                cortex_m::asm::delay(HALF_PERIOD_CYCLES);
                bits = (bits << 1) | u32::from(self.dout.is_high());
                self.sck.set_low();
                cortex_m::asm::delay(HALF_PERIOD_CYCLES);
            }
            // 25th pulse: channel A, gain 128.
            self.sck.set_high();
            cortex_m::asm::delay(HALF_PERIOD_CYCLES);
            self.sck.set_low();
            bits
        });
        hx711_counts_from_bits(raw)
    }
}

#[embassy_executor::task]
pub async fn hx711_task(mut hx711: Hx711) {
    loop {
        let counts = hx711.read().await;
        LOAD_CONVERSION.lock(|c| c.set(Some(counts)));
    }
}
